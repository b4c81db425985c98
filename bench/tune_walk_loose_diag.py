"""Why does the tuned loose EKF look over-confident on the held-out rtklibexplorer walk?

The walk section of bench/tune_check.py (docs/results/tune.md) tunes the loose EKF on the first
70 % of the walk (tests/data/walk_0827_loose.toml, 1 RTK fix in 4 to the filter) and measures
rms(error/sigma) against the RTK ``.pos`` at the epochs the filter did not see.  This script
prints the figures that tell the candidate causes apart (nothing here changes that metric):

1. innovations per segment: the tuning part and the held-out part, the held-out part split into
   its walking and its final standstill; mean NIS per row, per row kind (approximate: S_ii from
   the sigma the run reports just before the record, plus R_ii), lag-1 autocorrelation per row
   (white innovations: within +-2/sqrt(n); Mehra 1970, Sec. III);
2. rms(error/sigma) per axis, along / cross track, and by the time since the last fix;
3. the comparison itself: the reference is the antenna (the solution the IMU centre; the 5 cm
   lever arm left in), its velocity column is the receiver's, 0.132 s behind its positions
   (``[gnss] velocity_lag_s``), and it has the noise of the fixes the filter saw (the same
   receiver and solution).  A consistent filter compared with a reference e_ref = b + w
   (b: the lever arm C_nb l_b, w: white noise of variance R, independent of the filter's error) has
   E[(e/sigma)^2] = 1 + (b^2 + R) / sigma^2 per axis; that expectation, with R the tuned
   measurement variance of the same data (the median data sigma times the tuned factors), is
   printed beside the measured figure;
4. the reference's own noise: the ``.pos`` at the standstill (std and autocorrelation at
   0.25-1 s: the unseen epochs share the error of the neighbouring seen fixes when it is
   correlated) and its velocity column against the central differences of its positions.

Run (from the repository root, ../shared/data beside the repo; about 10 s)::

    python3 bench/tune_walk_loose_diag.py [--params gyro_arw,acc_vrw,...]
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import sys
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

import insnav  # noqa: E402
from insnav.analysis.evaluate import _solution_at  # noqa: E402
from insnav.analysis.metrics import errors  # noqa: E402
from insnav.calib.tune import holdout_report, tune  # noqa: E402
from insnav.filters.solution import RecordStatus  # noqa: E402
from insnav.io.rinex_dataset import rtklib_truth  # noqa: E402
from insnav.sim.trajectory import rotate_b_to_n  # noqa: E402

DATA = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data"))
HOLDOUT = 0.3
STILL_MPS = 0.2  # the reference's horizontal speed below which the walker stands


def f2(x):
    return "[" + ", ".join("-" if not np.isfinite(v) else f"{v:.2f}" for v in np.atleast_1d(x)) + "]"


def lag1(y):
    y = np.asarray(y, float)
    y = y[np.isfinite(y)]
    if y.size < 3:
        return np.nan
    d = y - y.mean()
    return float(d[:-1] @ d[1:] / (d @ d)) if d @ d > 0 else np.nan


def load():
    w = DATA / "rtklibexplorer_walk_0827"
    if not w.is_dir():
        raise SystemExit(f"{w} not found")
    d = tomllib.loads((ROOT / "tests" / "data" / "walk_0827_loose.toml").read_text())
    pos = w / "raw" / "gnss_1730_sf.pos"
    ds, cfg = insnav.load_csv_dataset(w / "raw" / "imu_1730.csv", pos, d)
    ref = rtklib_truth(str(pos), ds.gps_time_offset_s)
    return ds, cfg, ref, float(d["gnss"]["velocity_lag_s"])


def innovations(sol, ds, c, mask):
    """Per-row-kind NIS (S_ii ~ P_ii before the record + R_ii) and lag-1 per row of the applied records."""
    t = np.asarray(sol.gnss_t, float)
    ap = (np.asarray(sol.gnss_status) == RecordStatus.APPLIED) & mask(t)
    inn = np.asarray(sol.innovation, float)[ap]
    k = np.clip(np.searchsorted(sol.t, t[ap] - 1e-6) - 1, 0, len(sol.t) - 1)
    o = np.argsort(np.asarray(ds.gnss.t_valid), kind="stable")
    r_p = np.asarray(ds.gnss.sigma_pos_n, float)[o][ap] * c.gnss_pos_sigma_scale
    r_p[:, 2] *= getattr(c, "gnss_pos_v_sigma_scale", 1.0)
    r_v = np.asarray(ds.gnss.sigma_vel_n, float)[o][ap] * c.gnss_vel_sigma_scale
    s = np.column_stack([np.asarray(sol.sigma_pos_n_m)[k] ** 2 + r_p ** 2,
                         np.asarray(sol.sigma_vel_n_mps)[k] ** 2 + r_v ** 2])
    nis = np.nanmean(inn ** 2 / s, axis=0)
    return int(ap.sum()), nis, np.array([lag1(inn[:, i]) for i in range(6)]), np.sqrt(np.nanmean(inn ** 2, axis=0))


def comparison(sol, ref, ref_retimed, m, lever_b, seen, r_pos, r_vel):
    """rms(error/sigma) per axis four ways, along / cross track, by time since the last fix, and the
    expectation of a consistent filter against this reference."""
    tr = np.asarray(ref.t, float)
    at = _solution_at(sol, tr[m])
    e, er = errors(at, ref), errors(at, ref_retimed)
    eul = np.radians(np.column_stack([at.roll_deg, at.pitch_deg, at.yaw_deg]))
    lever_n = rotate_b_to_n(eul, np.tile(lever_b, (len(eul), 1)))
    sp, sv = e["sigma_pos_n_m"], e["sigma_vel_n_mps"]
    z = lambda x, s: np.sqrt(np.mean((x / s) ** 2, axis=0))  # noqa: E731
    out = dict(
        pos=z(e["pos_n_m"], sp), pos_antenna=z(e["pos_n_m"] + lever_n, sp),
        vel=z(e["vel_n_mps"], sv), vel_retimed=z(er["vel_n_mps"], sv),
        # a consistent filter against a reference with the lever arm left in and white noise of variance R
        pos_expected=np.sqrt(np.mean(1.0 + (lever_n ** 2 + r_pos ** 2) / sp ** 2, axis=0)),
        pos_expected_antenna=np.sqrt(np.mean(1.0 + r_pos ** 2 / sp ** 2, axis=0)),
        vel_expected_retimed=np.sqrt(np.mean(1.0 + r_vel ** 2 / sv ** 2, axis=0)),
        hor_rms=float(np.sqrt(np.mean(np.sum(e["pos_n_m"][:, :2] ** 2, axis=1)))),
        hor_rms_antenna=float(np.sqrt(np.mean(np.sum((e["pos_n_m"] + lever_n)[:, :2] ** 2, axis=1)))),
        sigma_pos=np.sqrt(np.mean(sp ** 2, axis=0)), sigma_vel=np.sqrt(np.mean(sv ** 2, axis=0)))
    v = np.asarray(ref.v_n, float)[m]
    walking = np.hypot(v[:, 0], v[:, 1]) > STILL_MPS
    hd = np.arctan2(v[:, 1], v[:, 0])
    sh = np.sqrt(0.5 * (sp[:, 0] ** 2 + sp[:, 1] ** 2))
    for key, ep in (("track", e["pos_n_m"]), ("track_antenna", e["pos_n_m"] + lever_n)) if walking.any() else ():
        along = np.cos(hd) * ep[:, 0] + np.sin(hd) * ep[:, 1]
        cross = -np.sin(hd) * ep[:, 0] + np.cos(hd) * ep[:, 1]
        out[key] = (np.sqrt(np.mean(along[walking] ** 2)), np.sqrt(np.mean(cross[walking] ** 2)),
                    np.sqrt(np.mean((along / sh)[walking] ** 2)), np.sqrt(np.mean((cross / sh)[walking] ** 2)))
    k = np.clip(np.searchsorted(seen, e["t"] + 1e-6) - 1, 0, len(seen) - 1)
    dt = np.round(e["t"] - seen[k], 2)
    out["by_dt"] = []
    for q in sorted(set(dt.tolist())):
        mm = dt == q
        if mm.sum() >= 5:
            out["by_dt"].append((q, int(mm.sum()), z((e["pos_n_m"] + lever_n)[mm], sp[mm]),
                                 z(er["vel_n_mps"][mm], sv[mm]),
                                 np.sqrt(np.mean(er["vel_n_mps"][mm] ** 2, axis=0)), np.mean(sv[mm], axis=0)))
    return out


def retimed(ref, lag_s):
    """The reference with its velocity column read ``lag_s`` later (as the filter's inputs)."""
    tr = np.asarray(ref.t, float)
    out = copy.copy(ref)
    out.v_n = np.column_stack([np.interp(tr + lag_s, tr, np.asarray(ref.v_n)[:, i]) for i in range(3)])
    return out


def standstill_start(ref, t_from):
    """The time after ``t_from`` from which the reference stands still to its end [s] (inf: never)."""
    tr = np.asarray(ref.t, float)
    speed = np.hypot(np.asarray(ref.v_n)[:, 0], np.asarray(ref.v_n)[:, 1])
    moving = tr[(tr >= t_from) & (speed > STILL_MPS)]
    return float(moving[-1]) + 0.5 if moving.size else float(t_from)


def expectation(sol, ds, cfg, run_cfg, ref, lag_s, t_from, t_to=np.inf):
    """For tune_check: rms(error/sigma) per axis over [t_from, t_to) at the unseen epochs as measured (the
    metric), with the solution's antenna point and the re-timed reference velocity, and as expected for a
    consistent filter against this reference (section 3 of the module docstring), with ``run_cfg``'s
    GNSS sigmas (the data's times its factors) as the reference's noise."""
    tr = np.asarray(ref.t, float)
    seen = np.sort(np.asarray(ds.gnss.t_valid, float))
    unseen = np.setdiff1d(np.round(tr, 3), np.round(seen, 3))
    m = np.isin(np.round(tr, 3), unseen) & (tr >= max(t_from, sol.t[0])) & (tr < min(t_to, sol.t[-1]))
    sig_p = np.nanmedian(np.asarray(ds.gnss.sigma_pos_n, float), axis=0) * run_cfg.gnss_pos_sigma_scale
    sig_p[2] *= run_cfg.gnss_pos_v_sigma_scale
    sig_v = np.nanmedian(np.asarray(ds.gnss.sigma_vel_n, float), axis=0) * run_cfg.gnss_vel_sigma_scale
    return comparison(sol, ref, retimed(ref, lag_s), m, np.asarray(cfg.lever_arm_b, float), seen, sig_p, sig_v)


def expectation_lines(ds, cfg, ref, res, lag_s) -> list:
    """Markdown for bench/tune_check.py's walk section: the tuned run's held-out rms(error/sigma) beside
    what a consistent filter would show against this reference, and the innovations while walking and
    standing in the held-out part."""
    from insnav.calib.tune import holdout_report as report

    sol = insnav.run(ds, config=dataclasses.replace(res.tuned))
    x = expectation(sol, ds, cfg, res.tuned, ref, lag_s, res.t_split)
    t_still = standstill_start(ref, res.t_split)
    walk, still = report(sol, None, res.t_split, t_still), report(sol, None, t_still)
    tr = np.asarray(ref.t, float)
    tr0 = float(tr[0])
    speed = np.hypot(np.asarray(ref.v_n)[:, 0], np.asarray(ref.v_n)[:, 1])
    tuning = (tr >= float(np.asarray(ds.imu.t)[0])) & (tr < res.t_split)
    still_s = float(np.sum(speed[tuning] < STILL_MPS) * np.median(np.diff(tr)))
    j = lambda v: ", ".join(f"{a:.2f}" for a in v)  # noqa: E731
    return [f"Against this reference a consistent filter does not give rms(err/sigma) = 1 "
            f"(`bench/tune_walk_loose_diag.py`): the reference is the antenna, the solution the IMU centre (the "
            f"lever arm C_nb l_b = b left in), and the reference has the noise of the fixes themselves (the same "
            f"receiver solution; variance R = the tuned measurement sigmas), so E[(e/sigma)^2] = 1 + (b^2 + R) / "
            f"sigma^2 per axis; its velocity column also lags its positions by velocity_lag_s = {lag_s:g} s.  The "
            f"tuned run on the held-out part:", "",
            "| rms(err/sigma) of the tuned run, held out | N, E, D | vN, vE, vD |", "|---|---|---|",
            f"| measured (the metric above) | {j(x['pos'])} | {j(x['vel'])} |",
            f"| a consistent filter against this reference, expected | {j(x['pos_expected'])} | - |",
            f"| measured, solution's antenna point / reference velocity read {lag_s:g} s later | "
            f"{j(x['pos_antenna'])} | {j(x['vel_retimed'])} |",
            f"| a consistent filter, expected, same | {j(x['pos_expected_antenna'])} | "
            f"{j(x['vel_expected_retimed'])} |", "",
            f"The held-out part ends standing still (from {t_still - tr0:.1f} s after the first `.pos` epoch; the "
            f"tuning part has {still_s:.1f} s of {res.t_split - float(np.asarray(ds.imu.t)[0]):.1f} s below "
            f"{STILL_MPS:g} m/s): mean NIS per row of the tuned run {walk['nis_per_row']:.2f} over its "
            f"{walk['records']} walking records, {still['nis_per_row']:.2f} over its {still['records']} standing "
            f"ones.", ""]


def reference_noise(ref, lag_s):
    tr = np.asarray(ref.t, float)
    v = np.asarray(ref.v_n, float)
    lat, lon, h = np.radians(ref.lat_deg), np.radians(ref.lon_deg), np.asarray(ref.h_m, float)
    r_e = 6371000.0
    p = np.column_stack([(lat - lat[0]) * r_e, (lon - lon[0]) * r_e * np.cos(lat[0]), -(h - h[0])])
    speed = np.hypot(v[:, 0], v[:, 1])
    # the longest standstill run
    still = speed < STILL_MPS
    best, cur, start = (0, 0), 0, 0
    for i, s in enumerate(still):
        if s:
            if cur == 0:
                start = i
            cur += 1
            if cur > best[1] - best[0]:
                best = (start, i + 1)
        else:
            cur = 0
    a, b = best
    print(f"\n4. The reference's own noise.  Longest standstill in the .pos: {tr[b - 1] - tr[a]:.1f} s "
          f"({b - a} epochs at 4 Hz):")
    for lab, x in (("N", p[a:b, 0]), ("E", p[a:b, 1]), ("D", p[a:b, 2]), ("vN", v[a:b, 0]), ("vE", v[a:b, 1]),
                   ("vD", v[a:b, 2])):
        x = x - x.mean()
        ac = [float(x[:-j] @ x[j:] / (x @ x)) for j in (1, 2, 3, 4)]
        print(f"   {lab:2s}: std {x.std():.4f}, autocorrelation at 0.25, 0.5, 0.75, 1 s {f2(ac)}")
    cd = (p[2:] - p[:-2]) / (tr[2:, None] - tr[:-2, None])
    walking = speed[1:-1] > STILL_MPS
    for lag in (0.0, lag_s):
        vi = np.column_stack([np.interp(tr[1:-1] + lag, tr, v[:, i]) for i in range(3)])
        print(f"   velocity column read {lag:.3f} s later minus the central differences of the positions, walking: "
              f"rms N, E, D {f2(np.sqrt(np.mean((vi - cd)[walking] ** 2, axis=0)))} m/s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--params", default=None, help="comma-separated factors to tune (default: the tuner's)")
    ap.add_argument("--max-runs", type=int, default=60)
    args = ap.parse_args(argv)
    ds, cfg, ref, lag_s = load()
    tr = np.asarray(ref.t, float)
    ref_retimed = retimed(ref, lag_s)
    seen = np.sort(np.asarray(ds.gnss.t_valid, float))
    unseen = np.setdiff1d(np.round(tr, 3), np.round(seen, 3))
    lever_b = np.asarray(cfg.lever_arm_b, float)
    res = tune(ds, cfg, holdout=HOLDOUT, max_runs=args.max_runs,
               params=args.params.split(",") if args.params else None)
    split = res.t_split
    t_still = standstill_start(ref, split)
    t0 = float(tr[0])
    print(f"Tuned on t < {split - t0:.1f} s (reference time from the first .pos epoch; IMU from "
          f"{ds.imu.t[0] - t0:.1f} to {ds.imu.t[-1] - t0:.1f} s); the held-out part is walking until "
          f"{t_still - t0:.1f} s, then standing.  Factors: "
          + ", ".join(f"{k} x {v:.3g}" for k, v in res.scales.items()) + f"; ln L {res.log_likelihood_base:.1f} -> "
          f"{res.log_likelihood_tuned:.1f}.")
    segs = (("tuning", -np.inf, split), ("held-out", split, np.inf), ("  walking", split, t_still),
            ("  standing", t_still, np.inf))
    runs = {}
    for name, c in (("hand", res.base), ("tuned", res.tuned)):
        runs[name] = (c, insnav.run(ds, config=dataclasses.replace(c)))
    print("\n1. Innovations (applied records).  NIS/row: the engine's; per row kind: approximate (S_ii from the "
          "sigma just before the record + R_ii); lag-1 per row N, E, D, vN, vE, vD (white: 0 +- 2/sqrt(n))")
    for name, (c, sol) in runs.items():
        for seg, a, b in segs:
            r = holdout_report(sol, None, t_from=a, t_to=b)
            n, nis, l1, rms = innovations(sol, ds, c, lambda t: (t >= a) & (t < b))
            print(f"   {name:5s} {seg:10s} n {n:3d}  NIS/row {r['nis_per_row']:.2f}  per row pos {f2(nis[:3])} "
                  f"vel {f2(nis[3:])}  lag-1 {f2(l1)}  rms innovation pos {f2(rms[:3])} m vel {f2(rms[3:])} m/s")
    print("\n2-3. rms(error/sigma) against the .pos at the unseen epochs, per axis N, E, D (the metric of "
          "tune_check: 'as is'), and the same with the solution's antenna point (+ C_nb l_b) and with the "
          "reference velocity read velocity_lag_s later (as the filter's own inputs); 'expected': a consistent "
          "filter against this reference (lever arm and the tuned measurement noise R of the data)")
    r_pos = np.nanmedian(np.asarray(ds.gnss.sigma_pos_n, float), axis=0) * res.tuned.gnss_pos_sigma_scale
    r_pos[2] *= res.tuned.gnss_pos_v_sigma_scale
    r_vel = np.nanmedian(np.asarray(ds.gnss.sigma_vel_n, float), axis=0) * res.tuned.gnss_vel_sigma_scale
    for name, (c, sol) in runs.items():
        for seg, a, b in segs:
            m = np.isin(np.round(tr, 3), unseen) & (tr >= max(a, sol.t[0])) & (tr < min(b, sol.t[-1]))
            x = comparison(sol, ref, ref_retimed, m, lever_b, seen, r_pos, r_vel)
            print(f"   {name:5s} {seg:10s} epochs {int(m.sum()):3d}  hor RMS {x['hor_rms']:.4f} m (antenna point "
                  f"{x['hor_rms_antenna']:.4f})  sigma pos {f2(x['sigma_pos'] * 100)} cm  "
                  f"vel {f2(x['sigma_vel'] * 100)} cm/s")
            print(f"        pos as is {f2(x['pos'])}  expected {f2(x['pos_expected'])} | "
                  f"antenna point {f2(x['pos_antenna'])}"
                  f"  expected {f2(x['pos_expected_antenna'])}")
            print(f"        vel as is {f2(x['vel'])} | re-timed {f2(x['vel_retimed'])}  expected "
                  f"{f2(x['vel_expected_retimed'])}")
            if seg in ("tuning", "held-out"):
                for key in ("track", "track_antenna"):
                    al, cr, zal, zcr = x[key]
                    print(f"        along / cross track ({'antenna point' if key.endswith('antenna') else 'as is'}, "
                          f"walking): {al:.3f} / {cr:.3f} m, rms(error/sigma) {zal:.2f} / {zcr:.2f}")
                for q, n, zp, zv, rv, sv in x["by_dt"]:
                    print(f"        {q:.2f} s after a fix (n {n:3d}): pos (antenna) {f2(zp)}  vel (re-timed) {f2(zv)}, "
                          f"rms vel error {f2(rv * 100)} cm/s vs sigma {f2(sv * 100)}")
    reference_noise(ref, lag_s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
