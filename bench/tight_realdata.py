"""Tight coupling on real data (rtklibexplorer walk_0827): measurement model and solution vs RTK.

1. The tight filter's per-epoch satellite inputs exactly as
   ``insnav.gnss.tight_inputs.tight_inputs_from_rinex`` hands them to the C++ loop (GPS LNAV
   broadcast orbits/clocks, transmit time + Sagnac, T_GD, receiver-clock-corrected
   reception time, Klobuchar + Saastamoinen, 10 deg mask): pseudorange and Doppler
   (pseudorange-rate) residuals against the RTK reference trajectory (per-epoch
   median removed = receiver clock / drift).
2. The IMU log's time tag (str2str) and a check of the PC clock against GPST
   through the u-blox log's own tag; a scan of an extra IMU time offset.
3. The tightly coupled EKF and RB-UKF (``insnav.io.rinex_dataset.load_rinex_run``
   with ``tests/data/walk_0827.toml``, i.e. what ``insnav run --format rinex`` does)
   against the RTK reference: horizontal RMS / max over RTK-fix epochs and all
   epochs, beside a GNSS-only single-point solution from the same pseudoranges,
   a loose EKF on those fixes, the author's filtered IMU file and free inertial.

Reproduce (from the repository root, with ../shared/data beside the repo)::

    python3 bench/tight_realdata.py --out docs/results/tight_realdata.md
"""
from __future__ import annotations

import argparse
import dataclasses
import struct
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

import insnav  # noqa: E402
from _common import git_commit  # noqa: E402
from insnav import _core, earth  # noqa: E402
from insnav.gnss import read_rinex_nav, read_rinex_obs  # noqa: E402
from insnav.io.gnss_files import read_rtklib_pos  # noqa: E402
from insnav.io.rinex_dataset import GPST_UNIX_OFFSET_S, load_rinex, load_rinex_run  # noqa: E402
from insnav.filters.tight import run_tight
from insnav.gnss.tight_inputs import tight_inputs_from_rinex  # noqa: E402
from _stamps import with_stamp  # noqa: E402

COMMAND = "python3 bench/tight_realdata.py --out docs/results/tight_realdata.md"
CONFIG = ROOT / "tests" / "data" / "walk_0827.toml"
DEG = np.pi / 180.0


def residuals(inp, t0, ref):
    ep = inp.row_epoch
    t = inp.epoch_t[ep] + t0
    r = np.column_stack([np.interp(t, ref.t_gps_s, ref.r_e[:, i]) for i in range(3)])
    v = np.column_stack([np.interp(t, ref.t_gps_s, ref.v_e[:, i]) for i in range(3)])
    s = inp.sats
    d = s[:, 2:5] - r
    rng = np.linalg.norm(d, axis=1)
    u = d / rng[:, None]
    pr = s[:, 0] - (rng - s[:, 8])
    rr = s[:, 1] - (np.einsum("ij,ij->i", u, s[:, 5:8] - v) - s[:, 9])
    out = []
    for x in (pr, rr):
        y = x.copy()
        for e in np.unique(ep):
            m = ep == e
            y[m] = np.where(m.sum() >= 2, x[m] - np.nanmedian(x[m]), np.nan)
        out.append(y)
    return out


def stats(x):
    x = x[np.isfinite(x)]
    return f"{x.size} | {np.std(x):.2f} | {np.sqrt(np.mean(x ** 2)):.2f} | {np.max(np.abs(x)):.2f}"


def ubx_rawx_latency(ubx_path):
    """PC arrival (str2str tag, GPST) minus the GPST epoch of each u-blox RXM-RAWX message [s]."""
    tag = Path(str(ubx_path) + ".tag").read_bytes()
    t_start = struct.unpack("<I", tag[64:68])[0] + struct.unpack("<d", tag[68:76])[0] - GPST_UNIX_OFFSET_S
    rec = np.frombuffer(tag, "<u4", offset=76).reshape(-1, 2).astype(np.int64)
    u = Path(ubx_path).read_bytes()
    out = []
    i = u.find(b"\xb5\x62\x02\x15")
    while i >= 0:
        n = struct.unpack("<H", u[i + 4:i + 6])[0]
        tow, week = struct.unpack("<dH", u[i + 6:i + 16])
        end = i + 8 + n  # header 6 + payload + checksum 2
        k = int(np.searchsorted(rec[:, 1], end))
        if k < len(rec):
            out.append(t_start + rec[k, 0] / 1000.0 - (week * 604800.0 + tow))
        i = u.find(b"\xb5\x62\x02\x15", end)
    return np.asarray(out)


def antenna_errors(sol, ds, ref, t_gps_offset, keep=None):
    """Solution antenna position/velocity minus the RTK reference at the reference epochs (NED, m and m/s)."""
    tr = ref.t_gps_s - t_gps_offset
    m = (tr >= sol.t[0]) & (tr <= sol.t[-1])
    if keep is not None:
        m &= keep
    t = tr[m]
    lat = np.interp(t, sol.t, sol.lat_deg) * DEG
    lon = np.interp(t, sol.t, sol.lon_deg) * DEG
    h = np.interp(t, sol.t, sol.h_m)
    yaw = np.interp(t, sol.t, np.unwrap(sol.yaw_deg * DEG))
    rpy = np.column_stack([np.interp(t, sol.t, sol.roll_deg) * DEG, np.interp(t, sol.t, sol.pitch_deg) * DEG, yaw])
    lever_n = np.array([np.asarray(_core.rotation.dcm_from_euler(a)) @ ds.lever_arm_b for a in rpy])
    r = earth.geodetic_to_ecef(lat, lon, h) + earth.ned_to_ecef_vector(lat, lon, lever_n)
    v_n = np.column_stack([np.interp(t, sol.t, sol.v_n[:, i]) for i in range(3)])
    lat0, lon0, _ = earth.ecef_to_geodetic(ref.r_e[m][0])
    e = earth.ecef_to_ned_vector(lat0, lon0, r - ref.r_e[m])
    ev = v_n - earth.ecef_to_ned_vector(lat0, lon0, ref.v_e[m])
    sig = np.column_stack([np.interp(t, sol.t, sol.sigma_pos_n_m[:, i]) for i in range(3)])
    return t, e, ev, ref.q[m], sig


def hstats(e, q):
    """(fix RMS, fix max, all RMS, all max, RMS around the mean offset, mean offset N, E) horizontal [m]."""
    hz = np.hypot(e[:, 0], e[:, 1])
    f = q == 1
    d = e[:, :2] - e[:, :2].mean(axis=0)
    return (np.sqrt(np.mean(hz[f] ** 2)), hz[f].max(), np.sqrt(np.mean(hz ** 2)), hz.max(),
            np.sqrt(np.mean(np.sum(d ** 2, axis=1))), *e[:, :2].mean(axis=0))


def row(name, e, ev, q, extra=""):
    s = hstats(e, q)
    vh = np.sqrt(np.mean(ev[:, 0] ** 2 + ev[:, 1] ** 2)) if ev is not None else float("nan")
    vs = f"{vh:.2f}" if np.isfinite(vh) else "-"
    return (f"| {name} | {int((q == 1).sum())} / {len(q)} | {s[0]:.2f} | {s[1]:.2f} | {s[2]:.2f} | {s[3]:.2f} | "
            f"{s[5]:+.1f}, {s[6]:+.1f} | {s[4]:.2f} | {vs} |{extra}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared/data")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    wall0 = time.perf_counter()
    d = a.data / "rtklibexplorer_walk_0827"
    obs_path, nav_path = d / "rinex_derived/gnss_1730.obs", d / "rinex_derived/gnss_1730.nav"
    imu_path, pos_path = d / "raw/imu_1730.csv", d / "raw/gnss_1730_sf.pos"
    obs = read_rinex_obs(obs_path)
    nav = read_rinex_nav(nav_path)
    ref = read_rtklib_pos(pos_path)
    # the .pos height column is the height above mean sea level of the receiver's NAV-PVT (+21.39 m
    # above the ellipsoidal height; bench/walk_reference_check.py): the reference is the same NAV-PVT
    # with its ellipsoidal height (latitude, longitude, quality and velocity are the .pos ones)
    from walk_reference_check import nav_pvt_as_reference, read_nav_pvt

    pvt = read_nav_pvt(d / "raw/gnss_1730.ubx")
    pvt_ref = nav_pvt_as_reference(pvt, int(ref.t_gps_s[0] // 604800.0))
    msl_above_ellipsoid_m = float(np.mean(pvt["h_msl_m"] - pvt["h_m"]))
    assert pvt_ref.t_gps_s.shape == ref.t_gps_s.shape and np.allclose(pvt_ref.t_gps_s, ref.t_gps_s, atol=0.02), \
        "NAV-PVT and .pos epochs differ"
    ref = ref._replace(r_e=pvt_ref.r_e)

    # ---------------------------------------------------------------- 1. residuals of the measurement model
    t0 = float(obs.epoch_t_gps_s[0])
    r0 = ref.r_e[0]
    lines = []
    gps_prns = np.unique(obs.prn)
    eph_prns = np.unique(nav.eph.prn)
    for iono_tropo in (True, False):
        inp = tight_inputs_from_rinex(obs, nav, t0, r0, iono=iono_tropo, tropo=iono_tropo, elevation_mask_deg=10.0)
        pr, rr = residuals(inp, t0, ref)
        n = inp.n_sats()
        lines.append(f"| {'Klobuchar + Saastamoinen' if iono_tropo else 'no atmosphere model'} | "
                     f"{n.min()}-{n.max()} (median {int(np.median(n))}) | {stats(pr)} | {stats(rr)} |")
        if iono_tropo:
            per_prn = [f"| G{p:02d} | {np.mean(inp.elevation_deg[inp.prn == p]):.1f} | "
                       f"{np.nanmean(pr[inp.prn == p]):+.2f} | {np.nanstd(pr[inp.prn == p]):.2f} | "
                       f"{np.nanstd(rr[inp.prn == p]):.3f} |" for p in np.unique(inp.prn)]

    # ---------------------------------------------------------------- 2. the run as `insnav run --format rinex`
    ds, cfg = load_rinex_run(obs, nav, imu_path, CONFIG, reference=pos_path)
    info, it = ds.info, ds.info["imu_time"]
    off = ds.gps_time_offset_s
    t_first = float(obs.epoch_t_gps_s[0] - off)
    inp = ds.tight_inputs
    n_sat = inp.n_sats()
    counts = {k: int((n_sat == k).sum()) for k in np.unique(n_sat)}
    short = np.flatnonzero(n_sat < len(info["prns_used"]))
    missing = sorted({int(p) for e in short for p in set(info["prns_used"]) - set(
        inp.prn[inp.epoch_start[e]:inp.epoch_start[e + 1]].tolist())})
    short_txt = (f" (G{', G'.join(f'{p:02d}' for p in missing)} missing at {inp.epoch_t[short[0]] - t_first:.1f}-"
                 f"{inp.epoch_t[short[-1]] - t_first:.1f} s)") if short.size else ""
    rawx = ubx_rawx_latency(d / "raw/gnss_1730.ubx")

    sols, timing = {}, {}
    for f in ("ekf", "rbukf"):
        c = dataclasses.replace(cfg, filter=f)
        t = time.perf_counter()
        sols[f] = insnav.run(ds, config=c)
        timing[f] = time.perf_counter() - t
    free = run_tight(ds, cfg, use_pseudorange=False, use_rate=False)
    loose = insnav.run(ds, config=dataclasses.replace(cfg, coupling="loose"))
    rin = dict(tomllib_table(CONFIG))
    sf_opts = dict(rin, imu_columns=["t", "ax", "ay", "az", "gx", "gy", "gz", "_", "_", "_", "_"],
                   imu_time="gpst_unix_s", imu_gyro_unit="rps")
    ds_sf, cfg_sf = load_rinex(obs, nav, d / "raw/imu_1730_sf.csv", sf_opts, reference=pos_path)
    sol_sf = run_tight(ds_sf, cfg_sf)

    res = {}
    for name, s, dd in (("ekf", sols["ekf"], ds), ("rbukf", sols["rbukf"], ds), ("sf", sol_sf, ds_sf),
                        ("loose", loose, ds), ("free", free, ds)):
        res[name] = antenna_errors(s, dd, ref, off)
    # single point over the same span, at its own epochs (the reference interpolated to them)
    spp = ds.spp
    g = np.isfinite(spp.r_e[:, 0]) & (spp.t > ds.t0) & (spp.t <= ds.imu.t[-1])
    tg = spp.t[g] + off
    R = np.column_stack([np.interp(tg, ref.t_gps_s, ref.r_e[:, i]) for i in range(3)])
    V = np.column_stack([np.interp(tg, ref.t_gps_s, ref.v_e[:, i]) for i in range(3)])
    qg = ref.q[np.clip(np.searchsorted(ref.t_gps_s, tg - 0.01), 0, len(ref.q) - 1)]
    lat0, lon0, _ = earth.ecef_to_geodetic(R[0])
    e_spp = earth.ecef_to_ned_vector(lat0, lon0, spp.r_e[g] - R)
    ev_spp = earth.ecef_to_ned_vector(lat0, lon0, spp.v_e[g] - V)

    t_e, e_ekf, ev_ekf, q_ekf, sig_ekf = res["ekf"]
    table = [
        row("tight EKF (raw IMU log + tag)", e_ekf, ev_ekf, q_ekf),
        row("tight RB-UKF (raw IMU log + tag)", res["rbukf"][1], res["rbukf"][2], res["rbukf"][3]),
        row("tight EKF, author's filtered `imu_1730_sf.csv`", res["sf"][1], res["sf"][2], res["sf"][3]),
        row("loose EKF on the single-point fixes", res["loose"][1], res["loose"][2], res["loose"][3]),
        row("GNSS only: single point, same pseudoranges/Dopplers", e_spp, ev_spp, qg),
    ]
    hz_free = np.hypot(res["free"][1][:, 0], res["free"][1][:, 1])
    tf = res["free"][0] - res["free"][0][0]
    free_at = {s: hz_free[min(np.searchsorted(tf, s), len(tf) - 1)] for s in (5, 10, 30, 60)}
    cons = np.sqrt(np.mean((e_ekf / sig_ekf) ** 2, axis=0))
    d_ekf, d_spp = float(np.mean(e_ekf[:, 2])), float(np.mean(e_spp[:, 2]))
    i0 = int(np.searchsorted(ref.t_gps_s, ds.t0 + off))
    v0 = earth.ecef_to_ned_vector(lat0, lon0, ref.v_e[i0])
    yaw_err0 = (ds.initial.yaw_deg - np.degrees(np.arctan2(v0[1], v0[0])) + 180.0) % 360.0 - 180.0
    hz_ekf = np.hypot(e_ekf[:, 0], e_ekf[:, 1])
    sig_h_end = np.hypot(*sig_ekf[-1, :2])

    # ---------------------------------------------------------------- 3. IMU time offset scan (tight EKF)
    scan, scan_nis, scan_vel = [], [], []
    for dt in (-0.2, -0.1, -0.05, -0.02, 0.0, 0.02, 0.05, 0.1, 0.2):
        ds_o, cfg_o = load_rinex(obs, nav, imu_path, dict(rin, imu_time_offset_s=dt), reference=pos_path)
        s = run_tight(ds_o, cfg_o)
        ok = s.gnss_status == 1
        _, e_o, ev_o, q_o, _ = antenna_errors(s, ds_o, ref, off)
        vh = np.sqrt(np.mean(ev_o[:, 0] ** 2 + ev_o[:, 1] ** 2))
        scan_nis.append((np.mean(s.nis[ok]), dt))
        scan_vel.append((vh, dt))
        scan.append(f"| {dt:+.2f} | {np.mean(s.nis[ok]):.3f} | {np.sqrt(np.nanmean(s.innovation[:, 1] ** 2)):.3f} | "
                    f"{vh:.3f} | {hstats(e_o, q_o)[4]:.2f} |")
    wall = time.perf_counter() - wall0

    prn_list = ", ".join(f"G{p:02d}" for p in info["prns_used"])
    md = f"""# Tight coupling on real data: rtklibexplorer walk_0827

Generated by `bench/tight_realdata.py` at commit `{git_commit()}`.  Reproduce: `{COMMAND}` ({wall:.0f} s on the shared 2-core machine).

The same run from the command line (the bench reads the same `tests/data/walk_0827.toml`):

```
D=../shared/data/rtklibexplorer_walk_0827
insnav run --format rinex --obs $D/rinex_derived/gnss_1730.obs --nav $D/rinex_derived/gnss_1730.nav \\
    --imu $D/raw/imu_1730.csv --config tests/data/walk_0827.toml --coupling tight --filter ekf --out walk_sol.csv
insnav evaluate walk_sol.csv $D/raw/gnss_1730_sf.pos               # all RTK epochs
insnav evaluate walk_sol.csv $D/raw/gnss_1730_sf.pos --quality 1   # RTK fix epochs only
```

(`insnav evaluate` compares the IMU centre with the RTK antenna position, i.e. without
the 5 cm lever arm that the table below applies; its numbers differ by a few centimetres.)

Data: `../shared/data/rtklibexplorer_walk_0827` (u-blox RINEX 3.04 obs/nav made with
convbin, raw IMU log `imu_1730.csv` with its str2str time tag, RTK reference
`gnss_1730_sf.pos`, 536 epochs at 4 Hz, about 134 s: standing for about 12 s, walking
in tight turns in a backyard (about 18 m x 20 m) at 1.2-1.4 m/s until about 113 s, then
standing; RTK fix until 85 s, float after).  The .pos `height` column is the receiver's
NAV-PVT height above mean sea level ({msl_above_ellipsoid_m:+.2f} m above the ellipsoidal
height), so every comparison below takes the NAV-PVT ellipsoidal height instead; the
horizontal reference is the .pos as published, which sits about 8 m from every
single-point solution (the RTK base, `bench/walk_reference_check.py`,
[tight_multignss.md](tight_multignss.md)).

## What the GPS data allow

* GPS satellites observed: {len(gps_prns)} ({', '.join(f'G{p:02d}' for p in gps_prns)}).
* GPS LNAV ephemerides in the nav file: {len(eph_prns)} ({', '.join(f'G{p:02d}' for p in eph_prns)});
  the rest of the nav file is Galileo and BeiDou, which the insnav readers skip (GPS LNAV only).
* So the tight filter uses {len(info['prns_used'])} satellites ({prn_list}), per epoch:
  {', '.join(f'{k} satellites in {v} epochs' for k, v in counts.items())}{short_txt}.
  Their elevations are 32-65 deg: all fairly high, so the vertical geometry is poor
  (the single-point height is {updown(d_spp)} on average).

## Residuals of the tight measurement model against the RTK reference

Per-satellite residual = measured - predicted at the RTK antenna position/velocity,
with exactly the satellite inputs the tight filter receives; the per-epoch median is
removed (receiver clock bias / drift).  Sigmas: std, RMS, max over all rows.

| model | satellites per epoch | PR rows | PR std [m] | PR RMS [m] | PR max [m] | rate rows | rate std [m/s] | rate RMS [m/s] | rate max [m/s] |
|---|---|---|---|---|---|---|---|---|---|
{chr(10).join(lines)}

Per satellite (with the atmosphere models):

| PRN | mean elevation [deg] | PR mean [m] | PR std [m] | rate std [m/s] |
|---|---|---|---|---|
{chr(10).join(per_prn)}

The expected figures for a plain model are about 4 m (pseudorange) and 0.5 m/s
(Doppler) (data README).  With 4 satellites the per-epoch median absorbs part of the
error, so these stds are slightly optimistic.  What matters below: the pseudorange
error of each satellite is almost a constant over the 2 minutes (PR std 0.3-0.7 m
around a mean of up to -7.8 m for G23): a bias, not white noise.

## IMU log and time alignment

* `imu_1730.csv` is read directly (`insnav.io.rinex_dataset.read_imu_csv` with a
  `tick_ms` column): {info['imu_samples']} samples (the partial first and last lines dropped),
  {info['imu_rate_hz']:.2f} Hz mean rate (IMU counter steps 6-9 ms), g and deg/s converted to SI, rotated
  into the body frame with the author's mounting rpy = [180, 0, -90] deg, rates integrated
  to increments with the trapezoidal rule.  The author's `imu_1730_sf.csv` (already
  GPST-stamped) is zero-phase low-pass filtered (10 Hz / 5 Hz cutoffs designed for 100 Hz
  while the IMU runs at 152 Hz): a non-causal filter whose output is not white-noise
  sensor data, so it is used only as a cross-check (table below).
* Time: the str2str tag gives each written chunk's PC arrival time (GPST); the IMU's own
  millisecond counter is mapped to GPST as the lower envelope of arrival minus counter
  (`tick_time_map`).  The log had `\\r\\n` line ends that were converted to `\\n` later
  (the tag counts {it['crlf_converted'] and 'exactly one extra byte per line' or 'no extra bytes'}; detected and allowed).
  Fit: clock rate difference {it['drift_ppm']:.1f} ppm; arrival latency above the envelope median
  {it['latency_median_ms']:.1f} ms, 95 % {it['latency_p95_ms']:.1f} ms, max {it['latency_max_ms']:.0f} ms (the first chunk).
* Is the PC clock GPST?  The u-blox log has its own str2str tag on the same PC: each
  RXM-RAWX message arrives {rawx.min() * 1e3:.0f}-{rawx.max() * 1e3:.0f} ms (median {np.median(rawx) * 1e3:.0f} ms) after its
  GPST epoch, so the PC clock is within a few tens of ms of GPST (not offset by the 18 s
  of UTC), and the IMU samples carry GPST to about that.
* An extra IMU time offset added to the tag-derived time (tight EKF, `imu_time_offset_s`):
  the mean NIS is smallest at {min(scan_nis)[1]:+.2f} s, the horizontal velocity error against the RTK
  velocity at {min(scan_vel)[1]:+.2f} s; both change little within +-0.1 s, so the tag-derived time is
  right to about 0.1 s, which is what the data can tell (position is insensitive to it):

| IMU time offset [s] | mean NIS | rate innovation RMS [m/s] | horizontal velocity error RMS [m/s] | horizontal error around its mean, RMS [m] |
|---|---|---|---|---|
{chr(10).join(scan)}

## Tightly coupled solution against the RTK reference

Start: `init_yaw_deg = "course"` - the consumer gyro cannot gyrocompass, so the run
starts when the single-point speed has stayed above 0.8 m/s for 1 s
({info['start_s_after_first_epoch']:.2f} s after the first epoch) with the course over ground as heading
(initial yaw {ds.initial.yaw_deg:.1f} deg, 1-sigma {cfg.init_sigma_att_deg[2]:.0f} deg), roll/pitch from the mean
specific force over the preceding second, position/velocity from the single-point fix there.
The epochs before (standing) are not in the solution.  Filter: 17 states (position,
velocity, attitude, accelerometer and gyro biases, receiver clock bias and drift), IMU noise
`CONSUMER_MEMS_MODEL` (4x the datasheet white noise of a good consumer part, turn-on biases
0.3 deg/s and 30 mg), pseudorange sigma 3 m / sin(el) and rate sigma 0.3 m/s / sin(el),
both scaled by C/N0, no gate.  All numbers are at the reference epochs, for the antenna
(IMU centre + lever arm).

The single point has no solution at the epochs with 3 satellites; it is compared at its own
epochs, the filters at the reference epochs inside their span.

| solution | RTK fix / all epochs | horizontal RMS, fix [m] | max, fix [m] | horizontal RMS, all [m] | max, all [m] | mean offset N, E [m] | RMS around the mean offset, all [m] | horizontal velocity RMS, all [m/s] |
|---|---|---|---|---|---|---|---|---|
{chr(10).join(table)}

Free inertial (the same start, no GNSS update): horizontal error
{free_at[5]:.1f} m after 5 s, {free_at[10]:.0f} m after 10 s, {free_at[30]:.0f} m after 30 s, {free_at[60]:.0f} m after 60 s.

Run time of the filter over the {ds.imu.t[-1] - ds.t0:.0f} s ({len(ds.imu.t)} IMU samples, {inp.epoch_t.size} epochs):
EKF {timing['ekf']:.2f} s, RB-UKF {timing['rbukf']:.2f} s (sanitizer included).

Consistency of the tight EKF: rms(error / sigma) N, E, D = {cons[0]:.1f}, {cons[1]:.1f}, {cons[2]:.1f};
horizontal 1-sigma at the end {sig_h_end:.2f} m against an error of {hz_ekf[-1]:.1f} m.

## Discussion

* **The absolute error is the single-point error.**  With exactly 4 satellites the
  pseudoranges determine position and clock with no redundancy, so the per-satellite
  pseudorange biases (up to -7.8 m for G23, above) map one to one into a position offset
  of about {np.hypot(*hstats(e_ekf, q_ekf)[5:7]):.1f} m horizontally (and {updown(d_ekf)} on average).  The IMU cannot
  remove a bias, and the tight filter, the loose filter and the single-point solution share
  it.  That is the horizontal RMS of about {hstats(e_ekf, q_ekf)[2]:.1f} m in the table; fix-only and all
  epochs agree because the RTK float/fix status has nothing to do with the L1 pseudoranges.
* **The shape of the walk is good.**  Around that constant offset the tight solution follows
  the RTK track to {hstats(e_ekf, q_ekf)[4]:.2f} m RMS and the velocity to {np.sqrt(np.mean(ev_ekf[:, 0] ** 2 + ev_ekf[:, 1] ** 2)):.2f} m/s: the Dopplers give
  velocity at 4 Hz, the IMU bridges between epochs and through the turns.  The single-point
  solution is noisier around its offset (table) and its Doppler velocity noisier still.
* **EKF and RB-UKF agree** to centimetres: the initial heading is {yaw_err0:+.0f} deg from the RTK
  course (a handheld unit is not always pointed along the path) and the heading is observable
  through the tight turns, so the linearisation is not the limit; the 4-satellite geometry is.
* **The filter is overconfident** (rms(error/sigma) far above 1 horizontally): it treats the
  pseudorange errors as white at 4 Hz, averages them, and its horizontal position sigma
  shrinks to {sig_h_end:.1f} m while the bias stays.  The innovations cannot show it: with no
  redundancy the biases go into position and clock, and the mean NIS ({dict((t, v) for v, t in scan_nis)[0.0]:.2f} for about 8 rows
  per epoch) says the innovations are much *smaller* than the modelled sigmas.  Satellite bias states or a time-correlated (Gauss-Markov)
  pseudorange error model would fix the consistency; with 4 satellites they would not be
  observable, so the error would stay.
* **Free inertial** with this consumer IMU is useless after a few seconds (tens of metres
  in 10 s, over a kilometre in a minute): the accuracy comes from GNSS, the IMU gives shape,
  smoothness and attitude.
* The author's low-pass-filtered IMU file gives the same numbers as the raw log: at this
  accuracy the filter does not see the difference.

## Done

* `python/insnav/io/rinex_dataset.py`: `load_rinex` / `load_rinex_run` build a dataset
  that `run_tight` and `insnav.run(..., coupling="tight")` accept from RINEX 2/3 GPS obs + nav,
  an IMU CSV (generic: time + rates or increments, g | m/s^2 and deg/s | rad/s, mounting
  rotation, lever arm; or a raw str2str log with its `.tag`), an initial state from a
  single-point fix (heading given or from the course once walking) and an optional RTKLIB
  `.pos` reference as truth.  Errors name the file and line (tag file: byte).
* `insnav run --format rinex --obs --nav --imu [--imu-tag] [--config]` and
  `insnav evaluate SOL REF.pos [--quality 1]`.
* This result: tight EKF and RB-UKF on the walk against the RTK reference, fix-only and all
  epochs, beside single point, loose and free inertial.

## Not done

* **Galileo** (7 ephemerides in the nav file) would give up to 11 satellites with GPS and a
  geometry with redundancy; it needs a Galileo nav/obs reader (same Keplerian algorithm,
  GST, BGD, E1 signal) that insnav does not have.  BeiDou likewise (8 ephemerides).
* The standing epochs before the start (about 16 s) are not in the solution: the
  heading is unknown until the walker moves.  A backward pass or a start with a large yaw
  sigma (RB-UKF) would cover them.
* No satellite-bias or correlated-error states, no zero-velocity updates while standing
  (the author's own loose filter uses them), no carrier phase.
* Week rollover inside a run is not handled (dataset time is GPS seconds of week).
"""
    print(md)
    if a.out:
        a.out.write_text(with_stamp(md, a.out))


def updown(d_m):
    """'x m too low/high' from a mean Down error [m]."""
    return f"{abs(d_m):.1f} m too {'low' if d_m > 0 else 'high'}"


def tomllib_table(path):
    import tomllib

    with open(path, "rb") as f:
        return tomllib.load(f).get("rinex", {})


if __name__ == "__main__":
    main()
