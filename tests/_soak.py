"""The soak scenario of bench/soak.py and cpp/tests/test_soak.cpp as an insnav
Dataset, and its run through the Python API with the process RSS sampled
(tests/test_soak.py runs 20 min of it; bench/soak.py the 24 h).

A vehicle parked at 34.25 N, 108.95 E, 400 m turning through a full circle
about its vertical (10 deg/s for 36 s) every 5 min; MEMS errors (ARW 0.2
deg/sqrt(h), VRW 0.1 m/s/sqrt(h), biases 30 deg/h and 5 mg); GNSS 1 Hz (1 m,
0.05 m/s) with a 60 s outage every 10 min.
"""
from __future__ import annotations

import resource
import threading
import time

import numpy as np

DEG = np.pi / 180.0


def rss_kb() -> int:
    with open("/proc/self/status") as f:
        for ln in f:
            if ln.startswith("VmRSS:"):
                return int(ln.split()[1])
    return 0


def make_dataset(hours: float, seed: int = 9, rate: float = 200.0, chunk: int = 2_000_000):
    """The soak scenario as an insnav Dataset (numpy, chunked; truth = the fixed position)."""
    from insnav.data.dataset import Dataset, GnssFixes, ImuData
    from insnav.earth import radii
    from insnav.data.nav import NavState

    lat, lon, h = 34.25 * DEG, 108.95 * DEG, 400.0
    W = 7.292115e-5
    s2 = np.sin(lat) ** 2
    g = 9.7803253359 * (1 + 0.00193185265241 * s2) / np.sqrt(1 - 0.00669437999013 * s2)
    g *= 1 - 2 / 6378137.0 * (1 + 1 / 298.257223563 + 0.00344978600308 - 2 / 298.257223563 * s2) * h
    n = int(hours * 3600 * rate)
    dt = 1.0 / rate
    rng = np.random.default_rng(seed)
    arw, vrw = 0.2 * DEG / 60.0, 0.1 / 60.0
    bg = np.array([30.0, -20.0, 25.0]) * DEG / 3600.0
    ba = np.array([5e-3, -4e-3, 3e-3]) * 9.80665
    t = np.arange(1, n + 1) * dt
    dth = np.empty((n, 3))
    dv = np.empty((n, 3))
    period, turn, wz = 300.0, 36.0, 10.0 * DEG
    for s in range(0, n, chunk):
        tm = t[s:s + chunk] - 0.5 * dt
        r = np.mod(tm, period)
        psi = np.mod(np.minimum(r, turn) * wz, 2 * np.pi)
        yr = np.where(r < turn, wz, 0.0)
        k = len(tm)
        dth[s:s + k, 0] = (W * np.cos(lat) * np.cos(psi) + bg[0]) * dt
        dth[s:s + k, 1] = (-W * np.cos(lat) * np.sin(psi) + bg[1]) * dt
        dth[s:s + k, 2] = (-W * np.sin(lat) + yr + bg[2]) * dt
        dth[s:s + k] += arw * np.sqrt(dt) * rng.standard_normal((k, 3))
        dv[s:s + k] = (np.array([0.0, 0.0, -g]) + ba) * dt + vrw * np.sqrt(dt) * rng.standard_normal((k, 3))
    tg = np.arange(1, int(hours * 3600) + 1, dtype=float)
    tg = tg[~(np.mod(tg, 600.0) > 540.0)]
    m = len(tg)
    R_M, R_N = radii(lat)
    sig_p, sig_v = 1.0, 0.05
    e = rng.standard_normal((m, 3)) * sig_p
    gnss = GnssFixes(tg, tg.copy(), np.degrees(lat + e[:, 0] / (R_M + h)),
                     np.degrees(lon + e[:, 1] / ((R_N + h) * np.cos(lat))), h - e[:, 2],
                     rng.standard_normal((m, 3)) * sig_v, np.full((m, 3), sig_p), np.full((m, 3), sig_v))
    model = dict(gyro_arw=[arw] * 3, accel_vrw=[vrw] * 3, gyro_bias_total_sigma=[30 * DEG / 3600] * 3,
                 accel_bias_total_sigma=[5e-3 * 9.80665] * 3, gyro_scale_sigma=[1e-7] * 3,
                 accel_scale_sigma=[1e-7] * 3)
    ds = Dataset(imu=ImuData(t, dth, dv), gnss=gnss, truth=None, gnss_raw=None, imu_errors=None, scenario={},
                 lever_arm_b=np.zeros(3), initial=NavState(np.degrees(lat), np.degrees(lon), h, np.zeros(3),
                                                           0.2, -0.2, 0.5),
                 t0=0.0, gps_time_offset_s=0.0, imu_model=model, name="soak")
    return ds, (lat, lon, h)


def python_soak(hours: float, filters=("ekf", "rbukf")) -> list[dict]:
    import insnav
    from insnav.earth import radii

    t0 = time.time()
    ds, (lat, lon, h) = make_dataset(hours)
    gen_s = time.time() - t0
    out = []
    for flt in filters:
        samples = []
        stop = threading.Event()

        def sample():
            while not stop.is_set():
                samples.append(rss_kb())
                stop.wait(0.5)

        th = threading.Thread(target=sample, daemon=True)
        rss0 = rss_kb()
        t1 = time.time()
        th.start()
        sol = insnav.run(ds, filter=flt, gate_chi2=22.46, output_decimation=200, init_error=False,
                         propagation_interval_s=0.02)
        stop.set()
        th.join()
        run_s = time.time() - t1
        R_M, R_N = radii(lat)
        en = (np.radians(sol.lat_deg) - lat) * (R_M + h)
        ee = (np.radians(sol.lon_deg) - lon) * (R_N + h) * np.cos(lat)
        ed = sol.h_m - h
        err = np.sqrt(en ** 2 + ee ** 2 + ed ** 2)
        sig = np.column_stack([sol.sigma_pos_n_m, sol.sigma_vel_n_mps, sol.sigma_att_deg])
        mid = samples[len(samples) // 10:] or samples
        out.append(dict(filter=flt, hours=hours, imu_samples=len(ds.imu), gnss=len(ds.gnss), gen_s=gen_s, run_s=run_s,
                        rows=len(sol), finite=bool(np.isfinite(sol.to_array()).all()),
                        sigma_positive=bool((sig > 0).all()), max_err_m=float(err.max()),
                        rms_err_m=float(np.sqrt(np.mean(err ** 2))), summary=sol.summary,
                        rss_before_kb=rss0, rss_min_run_kb=min(mid) if mid else 0,
                        rss_max_run_kb=max(mid) if mid else 0, n_rss=len(samples),
                        peak_rss_kb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))
        del sol
    return out
