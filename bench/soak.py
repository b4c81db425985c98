"""Soak run: 24 h at 200 Hz with periodic GNSS outages.

Two parts, same scenario (``cpp/tests/test_soak.cpp``): a vehicle parked at
34.25 N, 108.95 E, 400 m turning through a full circle about its vertical
(10 deg/s for 36 s) every 5 min; MEMS errors (ARW 0.2 deg/sqrt(h), VRW
0.1 m/s/sqrt(h), biases 30 deg/h and 5 mg); GNSS 1 Hz (1 m, 0.05 m/s) with a
60 s outage every 10 min.

1. C++: ``test_soak <hours>`` built in Release and under ASan + UBSan; it checks
   after every filter step (propagate, cycle end, update) that P is finite,
   symmetric and positive definite (EKF and RB-UKF), and reports the maximum
   position error and the peak RSS.
2. Python API: the same data generated with numpy (in chunks) and run through
   ``insnav.run`` (EKF and RB-UKF, 1 Hz output) while a thread samples the
   process RSS every 0.5 s (the C++ loop releases the GIL): RSS must stay
   flat during the run; every sigma output finite and positive; no NaN.

    python bench/soak.py [--hours 24] [--skip-asan] [--skip-python]
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEG = np.pi / 180.0


def build_and_run_cpp(hours: float, sanitize: bool) -> str:
    b = REPO / "build" / ("soak-asan" if sanitize else "soak-release")
    args = ["cmake", "-S", str(REPO), "-B", str(b), "-DINSNAV_BUILD_EXAMPLES=ON"]
    args += ["-DINSNAV_SANITIZE=ON", "-DCMAKE_BUILD_TYPE=RelWithDebInfo"] if sanitize else \
        ["-DCMAKE_BUILD_TYPE=Release"]
    subprocess.run(args, check=True, capture_output=True, text=True)
    subprocess.run(["cmake", "--build", str(b), "-j2", "--target", "test_soak"], check=True, capture_output=True,
                   text=True)
    exe = next(b.rglob("test_soak"))
    t0 = time.time()
    res = subprocess.run([str(exe), str(hours)], capture_output=True, text=True)
    out = res.stdout + res.stderr
    return f"[{'ASan+UBSan' if sanitize else 'Release'}, {time.time() - t0:.0f} s, exit {res.returncode}]\n{out}"


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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--skip-asan", action="store_true")
    ap.add_argument("--skip-cpp", action="store_true")
    ap.add_argument("--skip-python", action="store_true")
    a = ap.parse_args(argv)
    if not a.skip_cpp:
        print(build_and_run_cpp(a.hours, sanitize=False), flush=True)
        if not a.skip_asan:
            print(build_and_run_cpp(a.hours, sanitize=True), flush=True)
    if not a.skip_python:
        for r in python_soak(a.hours):
            print(r, flush=True)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
