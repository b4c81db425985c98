"""Seed 000 Table 1 (seed000-sim, Monte Carlo) and the Table 3 analogue
(seed000-car, four outages), EKF vs RB-UKF (and UKF).  Writes docs/results/seed000.md.

    python3 bench/seed000_tables.py [--runs 50] [--car-runs 20] [--workers 2]

Run i (i = 1..runs) simulates the scenario with seed i (new IMU noise, GNSS noise
and, for the car, new turn-on biases) and starts every filter from the same
initial error drawn with init_seed = i; the filters see identical data.
The errors are solution minus truth at every 200 Hz output sample.

Definitions (the paper gives none; t_r is the time of the first GNSS fix after
the outage, t_o the start of the outage):
* error at the end of the outage: |error| at the last output sample before t_r,
  i.e. what the first update has to remove (pre-outage error plus outage drift);
* max error after recovery: max |error| over the window W = [t_r, t_end], where
  the first fix at t_r is already applied in the sample at t_r.  Table 1:
  t_end = end of the run (150 s; the paper does not state its window); we also give the max over the
  first 10 s, which isolates the recovery transient.  Car: t_end = start of the
  next outage (or the end of the run), 130-210 s later;
* band: 1.5 x the EKF's RMS error over [t_o - 30 s, t_o) of the same run (one band
  per run and axis, shared by all filters, so a filter is not rewarded for having
  been worse before the outage);
* reconvergence time: the first time t >= t_r from which |error| stays within the
  band for at least 5 s without leaving it, minus t_r; 0 when the error never
  leaves the band in the first 5 s after the first update; not reconverged
  (counted separately, excluded from the mean; in the paired tests counted as
  the slower of its pair, a right-censored value at least W - 5 s, with the
  larger Wilcoxon p of it ranked above every observed difference and set to
  that bound) when no 5 s stretch inside the band exists in W.  'needed time' is the fraction of runs with a reconvergence
  time > 0, i.e. whose error was outside the band in the first 5 s after t_r;
* attitude error: solution minus truth roll, pitch, yaw [deg]; position error:
  horizontal sqrt(dN^2 + dE^2) [m]; velocity error: horizontal [m/s].
"""
from __future__ import annotations

import argparse
import pickle
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from _stamps import with_stamp  # noqa: E402
from insnav.analysis.paired import ALPHA, paired as paired_test  # noqa: E402

FILTERS = ("ekf", "rbukf", "ukf")
AXES = ("roll", "pitch", "yaw")
HOLD_S = 5.0
BAND = 1.5
PRE_S = 30.0
EARLY_S = 10.0
PAPER_T1 = {"ekf": ([1.1684, 0.6907, 1.2991], [15, 5, 9]), "rbukf": ([0.4405, 0.5321, 1.2917], [1, 2, 9])}
PAPER_T3 = {"ekf": dict(vel=[0.41, 0.56, 0.39, 1.35], pos=[19.9, 51.2, 15.0, 53.9], reconv=[72, 105, 70, 85]),
            "rbukf": dict(vel=[0.27, 0.35, 0.39, 0.40], pos=[5.4, 4.0, 5.9, 7.3], reconv=[25, 6, 5, 6])}


def reconv_time(t, err, t_r, threshold, hold_s=HOLD_S):
    """Reconvergence time as defined in the module docstring (strict hold: a
    stretch that reaches the end of the window counts only if it lasts hold_s)."""
    ok = np.abs(err) <= threshold
    if not ok.any():
        return np.nan
    # starts and ends (inclusive) of the runs of ok samples
    d = np.diff(np.concatenate([[0], ok.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)  # ends: first bad index after the run
    for s, e in zip(starts, ends):
        t_end = t[e] if e < len(t) else t[-1]
        if t_end - t[s] >= hold_s - 1e-9:
            return float(t[s] - t_r)
    return np.nan


def one_run(args):
    scenario, seed = args
    import insnav
    from insnav.analysis import errors, rms

    ds = insnav.simulate(scenario, seed=seed)
    outages = [tuple(o) for o in ds.scenario["gnss"]["outages"]]
    gt = np.asarray(ds.gnss.t_valid)
    errs = {f: errors(insnav.run(ds, filter=f, init_seed=seed), ds.truth) for f in FILTERS}
    t = errs["ekf"]["t"]
    hor = lambda x: np.hypot(x[:, 0], x[:, 1])  # noqa: E731
    res = {}
    for f, e in errs.items():
        per = []
        hz, vh = hor(e["pos_n_m"]), hor(e["vel_n_mps"])
        hz_ekf, att_ekf = hor(errs["ekf"]["pos_n_m"]), errs["ekf"]["att_deg"]
        for k, (a, b) in enumerate(outages):
            t_r = float(gt[gt >= b - 1e-9][0])  # first fix after the outage
            t_end = outages[k + 1][0] if k + 1 < len(outages) else t[-1]
            pre = (t >= a - PRE_S) & (t < a)
            win = (t >= t_r - 1e-9) & (t < t_end + 1e-9)
            early = win & (t <= t_r + EARLY_S)
            i_end = np.flatnonzero(t < t_r - 1e-9)[-1]  # last sample before the first fix
            band_att = BAND * rms(att_ekf[pre])
            band_pos = BAND * rms(hz_ekf[pre])
            att = e["att_deg"]
            tw = t[win]
            per.append(dict(
                t_r=t_r,
                att_end=np.abs(att[i_end]), att_max=np.abs(att[win]).max(axis=0),
                att_max_early=np.abs(att[early]).max(axis=0),
                att_t_max=tw[np.abs(att[win]).argmax(axis=0)] - t_r,
                att_band=band_att,
                att_left=np.array([bool((np.abs(att[win, i]) > band_att[i]).any()) for i in range(3)]),
                att_reconv=np.array([reconv_time(tw, att[win, i], t_r, band_att[i]) for i in range(3)]),
                pos_end=float(hz[i_end]), pos_max=float(hz[win].max()), pos_max_early=float(hz[early].max()),
                vel_end=float(vh[i_end]), vel_max=float(vh[win].max()),
                pos_band=float(band_pos), pos_left=bool((hz[win] > band_pos).any()),
                pos_reconv=reconv_time(tw, hz[win], t_r, band_pos),
                reconv_bound=float(t_end - t_r - HOLD_S)))  # the least time of a run that never reconverged
        res[f] = per
    return res


HEADINGS = (10.0, 30.0, 60.0, 90.0)
#: fixed bands for the heading sweep (the pre-outage error depends on H)
HEAD_BAND = dict(roll=0.5, pitch=0.5, yaw=2.0, pos=10.0)


def heading_run(args):
    """seed000-heading (or seed000-sim) with the filters started from the true
    state but the yaw off by +-H (random sign per run) and roll/pitch by
    N(0, 0.5 deg); initial yaw sigma H.  Same data and same initial error for
    the three filters."""
    scenario, H, seed = args
    import copy as _copy

    import insnav
    from insnav.analysis import errors
    from insnav.data.nav import NavState

    ds = insnav.simulate(scenario, seed=seed)
    rng = np.random.default_rng([seed, int(H)])
    s0 = ds.initial
    d = _copy.copy(ds)
    yaw = (s0.yaw_deg + rng.choice([-1.0, 1.0]) * H + 180.0) % 360.0 - 180.0
    d.initial = NavState(s0.lat_deg, s0.lon_deg, s0.h_m, s0.v_n, s0.roll_deg + 0.5 * rng.standard_normal(),
                         s0.pitch_deg + 0.5 * rng.standard_normal(), yaw)
    a, b = [tuple(o) for o in ds.scenario["gnss"]["outages"]][0]
    gt = np.asarray(ds.gnss.t_valid)
    t_r = float(gt[gt >= b - 1e-9][0])
    res = {}
    for f in FILTERS:
        e = errors(insnav.run(d, filter=f, init_error=False, init_sigma_att_deg=[0.5, 0.5, H],
                              output_decimation=4), ds.truth)
        t, att = e["t"], np.abs(e["att_deg"])
        hz = np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])
        pre = t < a
        bad = np.flatnonzero((att[:, 2] >= HEAD_BAND["yaw"]) & pre)
        conv = float(t[bad[-1] + 1]) if bad.size else 0.0  # yaw within 2 deg from then on, before the outage
        win = t >= t_r - 1e-9
        tw = t[win]
        res[f] = dict(
            yaw_conv=conv if conv < a - 1e-9 else np.nan,
            yaw_pre=float(np.sqrt(np.mean(e["att_deg"][(t > 20.0) & pre, 2] ** 2))),
            att_end=att[np.flatnonzero(t < t_r - 1e-9)[-1]],
            att_max=att[win].max(axis=0), pos_max=float(hz[win].max()),
            att_reconv=np.array([reconv_time(tw, att[win, i], t_r, HEAD_BAND[ax]) for i, ax in enumerate(AXES)]),
            pos_reconv=reconv_time(tw, hz[win], t_r, HEAD_BAND["pos"]),
            z_yaw=float(np.sqrt(np.mean((e["att_deg"][t > 5.0, 2] / e["sigma_att_deg"][t > 5.0, 2]) ** 2))))
    return res


def heading_tables(rows_by_h, title):
    """Median per filter and paired EKF - RB-UKF statistics per heading error."""
    L = [f"### {title}", "",
         "| H [deg] | filter | yaw within 2 deg after [s] (not before the outage) | yaw RMS 20-50 s [deg] | "
         "at end of outage: roll / pitch / yaw [deg] | max after recovery: roll / pitch / yaw [deg] | "
         "max hor. pos after recovery [m] | reconvergence roll / pitch / yaw / pos [s] | rms(yaw err / sigma) |",
         "|---|---|---|---|---|---|---|---|---|"]
    med = lambda x: np.nanmedian(np.asarray(x, float), axis=0)  # noqa: E731
    for H, rows in rows_by_h.items():
        for f in FILTERS:
            g = lambda k: [r[f][k] for r in rows]  # noqa: E731
            conv = np.asarray(g("yaw_conv"), float)
            rc = np.asarray(g("att_reconv"), float)
            L.append(f"| {H:.0f} | {f} | {np.nanmedian(conv) if np.isfinite(conv).any() else float('nan'):.0f} "
                     f"({int(np.isnan(conv).sum())} of {len(conv)}) | {med(g('yaw_pre')):.2f} | "
                     f"{' / '.join(f'{x:.2f}' for x in med(g('att_end')))} | "
                     f"{' / '.join(f'{x:.2f}' for x in med(g('att_max')))} | {med(g('pos_max')):.2f} | "
                     f"{' / '.join(f'{x:.0f}' for x in np.nanmedian(rc, axis=0))} / {med(g('pos_reconv')):.0f} | "
                     f"{med(g('z_yaw')):.2f} |")
    L += ["", "Paired per run, EKF minus RB-UKF (positive: RB-UKF better); median difference and the share "
          "of runs where the RB-UKF is lower:", "",
          "| H [deg] | max roll after recovery | max pitch after recovery | max yaw after recovery | "
          "max hor. pos after recovery | yaw RMS 20-50 s | pitch reconvergence |", "|---|---|---|---|---|---|---|"]
    summary = {}
    for H, rows in rows_by_h.items():
        cells = []
        for key, i in (("att_max", 0), ("att_max", 1), ("att_max", 2), ("pos_max", None), ("yaw_pre", None),
                       ("att_reconv", 1)):
            x = np.array([r["ekf"][key] if i is None else r["ekf"][key][i] for r in rows], float)
            y = np.array([r["rbukf"][key] if i is None else r["rbukf"][key][i] for r in rows], float)
            ok = np.isfinite(x) & np.isfinite(y)
            dd = x[ok] - y[ok]
            cells.append(f"{np.median(dd):+.3f} ({np.mean(dd > 0):.0%})" if dd.size else "n/a")
            summary[(H, key, i)] = (float(np.median(dd)) if dd.size else np.nan,
                                    float(np.mean(dd > 0)) if dd.size else np.nan,
                                    float(np.median(x[ok])) if dd.size else np.nan)
        L.append(f"| {H:.0f} | " + " | ".join(cells) + " |")
    return L, summary


def git_rev():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).resolve().parents[1]).stdout.strip() or "?"
    except OSError:
        return "?"


def ms(x, d=3):
    x = np.asarray(x, float)
    return f"{np.nanmean(x):.{d}f} ± {np.nanstd(x):.{d}f}"


def reconv_cell(x, d=1):
    """mean ± std over the runs that reconverged, with the count that did not."""
    x = np.asarray(x, float)
    bad = int(np.isnan(x).sum())
    if bad == len(x):
        return f"none of {len(x)}"
    s = f"{np.nanmean(x):.{d}f} ± {np.nanstd(x):.{d}f}"
    return s + (f" ({bad} not)" if bad else "")


def mean_diff(a, b):
    """EKF minus RB-UKF per run: (mean, std, standard error, fraction where RB-UKF is lower)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d = d[np.isfinite(d)]
    if len(d) == 0:
        return np.nan, np.nan, np.nan, np.nan
    return d.mean(), d.std(), d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else np.nan, (d > 0).mean()


def test_cells(ekf, rbukf, d=4, censored=False, bound=None):
    """Paired test "RB-UKF (A) lower than EKF (B)": cells for the comparison tables and the verdict.
    ``censored``: NaN is a reconvergence time beyond the window, slower than every observed one
    (the window is the same for both filters and every run), not a run to leave out; ``bound`` (per
    run) the least such a time can be (the window less the hold time): the verdict keeps the larger
    Wilcoxon p of the censored runs ranked at the top and at their bound."""
    r = paired_test(rbukf, ekf, nan_is_worst=censored, censor_bound=bound if censored else None)
    lo, hi = r.median_diff_ci
    return r, (f"{r.median_diff:+.{d}f} ({lo:+.{d}f} .. {hi:+.{d}f}) | {r.wins}/{r.n} | {r.p_sign:.2g} | "
               f"{r.p_wilcoxon:.2g} | {r.verdict()}")


TEST_HEAD = ("median RB-UKF - EKF (95 % CI) | RB-UKF lower in | sign test p | Wilcoxon p | verdict")


def calib_scenario(rate_hz):
    """seed000-sim with the paper's white noise read as 1-sigma per sample at ``rate_hz``
    (200 Hz: the plain reading, the IMU rate; 1 Hz: per 1-s filter cycle), expressed as the
    per-sample sigma at the simulator's 200 Hz: sigma_200 = sigma * sqrt(200 / rate_hz)."""
    k = float(np.sqrt(200.0 / rate_hz))
    return {"extends": "seed000-sim", "imu": {"gyro": {"white_dph": 300.0 * k}, "accel": {"white_mg": 2.0 * k}}}


#: calibration sweep of what seed 000 leaves open: how its white noise is applied, and the
#: initial attitude sigma [deg] the filters start from (drawn error = that sigma)
CAL_RATES = (200.0, 10.0, 1.0, 0.5, 0.25)
CAL_ATT = ((0.5, 0.5, 1.0), (2.0, 2.0, 1.0), (5.0, 5.0, 2.0))


def calib_run(args):
    """EKF and RB-UKF max attitude error over 90-150 s and its reconvergence, one setting and seed."""
    rate, att, seed = args
    import insnav
    from insnav.analysis import errors, rms

    ds = insnav.simulate(calib_scenario(rate), seed=seed)
    res = {}
    errs = {f: errors(insnav.run(ds, filter=f, init_seed=seed, init_sigma_att_deg=list(att)), ds.truth)
            for f in ("ekf", "rbukf")}
    gt = np.asarray(ds.gnss.t_valid)
    t_r = float(gt[gt >= 90.0 - 1e-9][0])
    t = errs["ekf"]["t"]
    pre = (t >= 50.0 - PRE_S) & (t < 50.0)
    band = BAND * rms(errs["ekf"]["att_deg"][pre])
    win = t >= t_r - 1e-9
    for f, e in errs.items():
        att_e = e["att_deg"]
        res[f] = dict(att_max=np.abs(att_e[win]).max(axis=0),
                      att_reconv=np.array([reconv_time(t[win], att_e[win, i], t_r, band[i]) for i in range(3)]),
                      reconv_bound=float(t[-1] - t_r - HOLD_S))
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--car-runs", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cal-runs", type=int, default=8,
                    help="runs per setting of the calibration sweep (the closest setting then gets --runs)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs" / "results" / "seed000.md"))
    ap.add_argument("--raw", default="/tmp/seed000_raw.pkl",
                    help="per-run metrics are pickled here (and read back with --render-only)")
    ap.add_argument("--render-only", action="store_true",
                    help="write the document from --raw without running the Monte Carlo again")
    a = ap.parse_args(argv)
    if a.render_only:
        with open(a.raw, "rb") as fh:
            raw = pickle.load(fh)
        sim, car, wall, t_sim = raw["sim"], raw["car"], raw["wall"], raw["t_sim"]
        head, head_straight = raw["head"], raw["head_straight"]
        calib, calib_full, cal_runs = raw["calib"], raw["calib_full"], raw["cal_runs"]
        rev = raw.get("rev", "?")
        a.runs, a.car_runs, a.workers = raw["runs"], raw["car_runs"], raw["workers"]
    else:
        t0 = time.time()
        with ProcessPoolExecutor(a.workers) as ex:
            sim = list(ex.map(one_run, [("seed000-sim", s) for s in range(1, a.runs + 1)]))
            t_sim = time.time() - t0
            car = list(ex.map(one_run, [("seed000-car", s) for s in range(1, a.car_runs + 1)]))
            head = {H: list(ex.map(heading_run, [("seed000-heading", H, s) for s in range(1, a.runs + 1)]))
                    for H in HEADINGS}
            head_straight = {60.0: list(ex.map(heading_run, [("seed000-sim", 60.0, s)
                                                             for s in range(1, a.runs + 1)]))}
            cal_runs = a.cal_runs
            calib = {(R, att): list(ex.map(calib_run, [(R, att, s) for s in range(1, cal_runs + 1)]))
                     for R in CAL_RATES for att in CAL_ATT}
            pe = np.array(PAPER_T1["ekf"][0])
            best = min(calib, key=lambda key: np.sqrt(np.mean(np.log(
                np.mean([r["ekf"]["att_max"] for r in calib[key]], axis=0) / pe) ** 2)))
            calib_full = list(ex.map(calib_run, [(best[0], best[1], s) for s in range(1, a.runs + 1)]))
        wall = time.time() - t0
        with open(a.raw, "wb") as fh:
            pickle.dump(dict(sim=sim, car=car, head=head, head_straight=head_straight, wall=wall, t_sim=t_sim,
                             calib=calib, calib_full=calib_full, cal_runs=cal_runs,
                             runs=a.runs, car_runs=a.car_runs, workers=a.workers, rev=git_rev()), fh)
        rev = git_rev()
    N = a.runs

    def arr(rows, f, key, k=0):
        return np.array([r[f][k][key] for r in rows])

    defs = __doc__[__doc__.index("Definitions"):].strip()
    L = ["# Seed 000: EKF vs RB-UKF after GNSS outages (Table 1 and Table 3 analogues)", "",
         "Reproduce (%.0f s wall with %d worker processes on the shared 2-core machine, which other jobs were "
         "using at the same time; %.0f s of it for Table 1):" % (wall, a.workers, t_sim), "",
         "```sh",
         f"cd insnav && python3 bench/seed000_tables.py --runs {a.runs} "
         f"--car-runs {a.car_runs} --cal-runs {cal_runs} --workers {a.workers}",
         "```", "",
         "(`--render-only` rewrites this document from the per-run metrics the run pickled to `--raw`, "
         "without running the Monte Carlo again.)", "",
         f"Monte Carlo run at commit {rev} with `bench/seed000_tables.py`; the scenarios are the presets "
         "`seed000-sim` and `seed000-car` (`python/insnav/scenarios/*.toml`, their comments say what the paper "
         "gives and what was chosen here).  Filters: `ekf`, `rbukf`, `ukf` with the default `RunConfig` "
         "(15 states, IMU noise model from the simulator, UT alpha = 1, beta = 2, kappa = 3 - n).  "
         "Each run i uses simulator seed i and initial-error seed i; all filters see the same data.", "",
         "VERDICTS_PLACEHOLDER",
         "## Definitions", "", defs, "",
         f"## Table 1: seed000-sim, {N} Monte Carlo runs, GPS lost 50-90 s", "",
         "The paper's values are from its single simulation run.  Ours: mean ± std over the runs.  "
         "Reconvergence: mean ± std over the runs that reconverged; "
         "'needed time' = fraction of runs with reconvergence time > 0.", "",
         "| filter | axis | max error after recovery [deg] (paper) | ours: max 90-150 s [deg] | max 90-100 s [deg] "
         "| at end of outage [deg] | reconvergence [s] (paper) | ours: reconvergence [s] | needed time | band [deg] |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    for f in FILTERS:
        am, ae, aend = arr(sim, f, "att_max"), arr(sim, f, "att_max_early"), arr(sim, f, "att_end")
        ar, ab = arr(sim, f, "att_reconv"), arr(sim, f, "att_band")
        for i, ax in enumerate(AXES):
            pm = f"{PAPER_T1[f][0][i]}" if f in PAPER_T1 else "-"
            pr = f"{PAPER_T1[f][1][i]}" if f in PAPER_T1 else "-"
            L.append(f"| {f} | {ax} | {pm} | {ms(am[:, i])} | {ms(ae[:, i])} | {ms(aend[:, i])} | {pr} | "
                     f"{reconv_cell(ar[:, i])} | {(ar[:, i] > 0).mean():.2f} | {ms(ab[:, i])} |")
    L += ["", "Position (horizontal) after the same recovery (the paper gives no number for Table 1):", "",
          "| filter | at end of outage [m] | max 90-150 s [m] | max 90-100 s [m] | reconvergence [s] | needed time "
          "| band [m] |", "|---|---|---|---|---|---|---|"]
    for f in FILTERS:
        L.append(f"| {f} | {ms(arr(sim, f, 'pos_end'), 2)} | {ms(arr(sim, f, 'pos_max'), 2)} | "
                 f"{ms(arr(sim, f, 'pos_max_early'), 2)} | {reconv_cell(arr(sim, f, 'pos_reconv'))} | "
                 f"{(arr(sim, f, 'pos_reconv') > 0).mean():.2f} | {ms(arr(sim, f, 'pos_band'), 2)} |")
    # time of the max
    tmax = arr(sim, "ekf", "att_t_max")
    L += ["", "When the max over 90-150 s happens (EKF; seconds after recovery, median [10 %, 90 %] over runs): " +
          ", ".join(f"{ax} {np.median(tmax[:, i]):.1f} [{np.percentile(tmax[:, i], 10):.1f}, "
                    f"{np.percentile(tmax[:, i], 90):.1f}]" for i, ax in enumerate(AXES)) +
          ".  The scenario turns by 60 deg at 100-120 s (10-30 s after recovery).", ""]
    # paired comparison
    L += ["### Paired comparison per run: RB-UKF (A) against EKF (B)", "",
          f"Exact sign test and Wilcoxon signed-rank test (two-sided); verdict at alpha = {ALPHA} on the Wilcoxon "
          "p-value: reproduced = RB-UKF significantly lower, opposite = significantly higher.", "",
          "| quantity | " + TEST_HEAD + " |", "|---|---|---|---|---|---|"]
    checks = []
    for i, ax in enumerate(AXES):
        checks.append((f"max {ax} error 90-150 s [deg]", arr(sim, "ekf", "att_max")[:, i],
                       arr(sim, "rbukf", "att_max")[:, i], 4))
    for i, ax in enumerate(AXES):
        checks.append((f"max {ax} error 90-100 s [deg]", arr(sim, "ekf", "att_max_early")[:, i],
                       arr(sim, "rbukf", "att_max_early")[:, i], 4))
    for i, ax in enumerate(AXES):
        checks.append((f"{ax} reconvergence [s]", arr(sim, "ekf", "att_reconv")[:, i],
                       arr(sim, "rbukf", "att_reconv")[:, i], 3))
    checks.append(("max horizontal position error 90-150 s [m]", arr(sim, "ekf", "pos_max"),
                   arr(sim, "rbukf", "pos_max"), 4))
    checks.append(("position reconvergence [s]", arr(sim, "ekf", "pos_reconv"), arr(sim, "rbukf", "pos_reconv"), 3))
    verdicts, tests = {}, {}
    for name, x, y, d in checks:
        m, s, se, frac = mean_diff(x, y)
        r, cells = test_cells(x, y, d, censored="reconvergence" in name, bound=arr(sim, "ekf", "reconv_bound"))
        verdicts[name] = (m, se, r.verdict())
        tests[name] = r
        L.append(f"| {name} | {cells} |")
    # nonlinearity size
    aend_all = np.concatenate([arr(sim, f, "att_end") for f in ("ekf", "rbukf")])
    psi_max = float(aend_all.max())
    second = np.degrees(np.radians(psi_max) ** 2 / 2)
    dmax = np.abs(arr(sim, "ekf", "att_max") - arr(sim, "rbukf", "att_max"))
    ukf_rb = max(float(np.nanmax(np.abs(arr(sim, "ukf", k) - arr(sim, "rbukf", k))))
                 for k in ("att_max", "pos_max"))

    # ---- car -------------------------------------------------------------------------------------
    C = a.car_runs
    L += ["", f"## Table 3 analogue: seed000-car, {C} Monte Carlo runs, four outages 20/40/20/40 s", "",
          "Simulated car (the paper's is a real drive with a FOG-INS/DGPS reference).  Outages 150-170, 300-340, "
          "480-500, 650-690 s; each window runs to the next outage.  Ours: mean ± std over the runs; paper: "
          "its one drive.", "",
          "| filter | outage | max vel error [m/s] (paper) | ours | max pos error [m] (paper) | ours "
          "| pos at end of outage [m] | pos reconvergence [s] (paper) | ours | needed time | band [m] |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    for f in FILTERS:
        for k, dur in enumerate((20, 40, 20, 40)):
            P = PAPER_T3.get(f)
            pv, pp, pr = (f"{P['vel'][k]}", f"{P['pos'][k]}", f"{P['reconv'][k]}") if P else ("-", "-", "-")
            L.append(f"| {f} | {k + 1} ({dur} s) | {pv} | {ms(arr(car, f, 'vel_max', k), 3)} | {pp} | "
                     f"{ms(arr(car, f, 'pos_max', k), 2)} | {ms(arr(car, f, 'pos_end', k), 2)} | {pr} | "
                     f"{reconv_cell(arr(car, f, 'pos_reconv', k))} | {(arr(car, f, 'pos_reconv', k) > 0).mean():.2f} | "
                     f"{ms(arr(car, f, 'pos_band', k), 2)} |")
    L += ["", "### Paired comparison per run and outage: RB-UKF (A) against EKF (B)", "",
          "| outage | quantity | " + TEST_HEAD + " |", "|---|---|---|---|---|---|---|"]
    car_verdicts, car_tests = [], {}
    for k in range(4):
        for key, name, d in (("vel_max", "max vel error [m/s]", 4), ("pos_max", "max pos error [m]", 3),
                             ("pos_reconv", "pos reconvergence [s]", 2)):
            r, cells = test_cells(arr(car, "ekf", key, k), arr(car, "rbukf", key, k), d, censored=key == "pos_reconv",
                                  bound=arr(car, "ekf", "reconv_bound", k))
            car_verdicts.append(r.verdict())
            car_tests[(k, key)] = r
            L.append(f"| {k + 1} | {name} | {cells} |")

    # ---- large heading error ------------------------------------------------------------------------
    L += ["", f"## Large initial heading error: seed000-heading, {N} runs per H", "",
          "The filters start from the true state with the yaw off by +-H (random sign per run), roll and pitch "
          "off by N(0, 0.5 deg), and an initial yaw sigma of H; the three filters get the same data and the same "
          "initial error.  `seed000-heading` has the paper's Table 1 sensors, GPS and outage (50-90 s) with the "
          "rolling produced by coordinated weaving turns, so the heading is observable before the outage.  "
          f"Medians over the runs.  Reconvergence: first time after the first fix from which the error stays "
          f"5 s inside {HEAD_BAND['roll']}/{HEAD_BAND['pitch']}/{HEAD_BAND['yaw']} deg (roll/pitch/yaw) and "
          f"{HEAD_BAND['pos']} m.", ""]
    hl, hsum = heading_tables(head, "Weaving turns (heading observable)")
    L += hl
    sl, ssum = heading_tables(head_straight, "The same from seed000-sim's straight start (heading not observable "
                                             "before its turn at 100 s)")
    L += [""] + sl
    big = [H for H in HEADINGS if H >= 60.0]

    # ---- reading ---------------------------------------------------------------------------------
    def vtxt(name, d=4):
        m, se, v = verdicts[name]
        return f"{m:+.{d}f} ± {se:.{d}f} SE, {v}"

    n_rb_better = sum(v == "reproduced" for v in car_verdicts)
    n_ekf_better = sum(v == "opposite" for v in car_verdicts)
    ekf_att = arr(sim, "ekf", "att_max").mean(axis=0)
    att_end = arr(sim, "ekf", "att_end").mean(axis=0)
    pre_rms = (arr(sim, "ekf", "att_band") / BAND).mean(axis=0)
    rel = np.abs([verdicts[f"max {ax} error 90-150 s [deg]"][0] for ax in AXES]) / ekf_att
    needed = [(arr(sim, f, "att_reconv")[:, i] > 0).mean() for f in ("ekf",) for i in range(3)]
    rc_mean = np.nanmean(arr(sim, "ekf", "att_reconv"), axis=0)
    car_dpos = max(abs(mean_diff(arr(car, "ekf", "pos_max", k), arr(car, "rbukf", "pos_max", k))[0]) for k in range(4))
    car_dvel = max(abs(mean_diff(arr(car, "ekf", "vel_max", k), arr(car, "rbukf", "vel_max", k))[0]) for k in range(4))
    car_pos = [arr(car, "ekf", "pos_max", k).mean() for k in range(4)]
    car_vel = [arr(car, "ekf", "vel_max", k).mean() for k in range(4)]
    car_rc = [np.nanmean(arr(car, "ekf", "pos_reconv", k)) for k in range(4)]
    f2 = lambda x, d=2: "/".join(f"{y:.{d}f}" for y in x)  # noqa: E731
    car_band = [arr(car, "ekf", "pos_band", k).mean() for k in range(4)]
    worse = [f"outage {k + 1} {q} ({o:.2f} vs {p})" for k in range(4)
             for q, o, p in (("velocity", car_vel[k], PAPER_T3["rbukf"]["vel"][k]),
                             ("position", car_pos[k], PAPER_T3["rbukf"]["pos"][k])) if o >= p]
    rb_cmp = ("ours are below the paper's RB-UKF (0.27/0.35/0.39/0.40 m/s, 5.4/4.0/5.9/7.3 m)"
              + (" except " + ", ".join(worse) if worse else ""))
    # ---- calibration of the EKF baseline (Table 1) --------------------------------------------
    paper_ekf = np.array(PAPER_T1["ekf"][0])
    cal_mean = {key: np.mean([r["ekf"]["att_max"] for r in rows], axis=0) for key, rows in calib.items()}
    cal_dist = {key: float(np.sqrt(np.mean(np.log(m / paper_ekf) ** 2))) for key, m in cal_mean.items()}
    best = min(cal_dist, key=cal_dist.get)
    L += ["", "## Calibrating the EKF baseline of Table 1", "",
          "Seed 000 leaves open how its white noise is applied (300 deg/h and 2 mg \"1 sigma\": per 200 Hz "
          "sample, as the preset reads it, or per longer interval) and the initial attitude error of its "
          "filters.  Sweep: the white noise as 1-sigma per sample at R Hz (simulated at 200 Hz with "
          "sigma x sqrt(200 / R); the filters' noise model follows the simulator), crossed with the initial "
          f"attitude sigma (the drawn initial error has that sigma); {cal_runs} runs per setting (seeds 1..{cal_runs}).  "
          "Distance to the paper's EKF: RMS over roll/pitch/yaw of log(ours / paper) of the mean max error "
          "over 90-150 s.", "",
          "| noise per sample at R [Hz] | initial attitude sigma roll/pitch/yaw [deg] | EKF max roll / pitch / yaw "
          "90-150 s [deg] (paper 1.1684 / 0.6907 / 1.2991) | RB-UKF max roll / pitch / yaw [deg] | distance |",
          "|---|---|---|---|---|"]
    for key, rows in calib.items():
        rb = np.mean([r["rbukf"]["att_max"] for r in rows], axis=0)
        mark = " **(closest)**" if key == best else ""
        L.append(f"| {key[0]:g} | {' / '.join(f'{x:g}' for x in key[1])} | {f2(cal_mean[key], 3)} | {f2(rb, 3)} | "
                 f"{cal_dist[key]:.3f}{mark} |")
    L += ["", f"The closest setting (R = {best[0]:g} Hz, initial attitude sigma "
          f"{' / '.join(f'{x:g}' for x in best[1])} deg) was then run {len(calib_full)} times (seeds 1..{len(calib_full)}); "
          "the verdicts give both the plain reading (the preset) and this calibrated setting.", ""]
    cal_tests = {}
    L += ["| quantity (calibrated setting) | EKF mean | RB-UKF mean | " + TEST_HEAD + " |",
          "|---|---|---|---|---|---|---|---|"]
    for i, ax in enumerate(AXES):
        for key, label, d in (("att_max", f"max {ax} error 90-150 s [deg]", 4), ("att_reconv", f"{ax} reconvergence [s]", 2)):
            x = np.array([r["ekf"][key][i] for r in calib_full], float)
            y = np.array([r["rbukf"][key][i] for r in calib_full], float)
            r, cells = test_cells(x, y, d, censored=key == "att_reconv",
                                  bound=np.array([r["ekf"]["reconv_bound"] for r in calib_full], float))
            cal_tests[(key, i)] = r
            L.append(f"| {label} | {np.nanmean(x):.{d}f} | {np.nanmean(y):.{d}f} | {cells} |")

    # ---- verdicts ----------------------------------------------------------------------------------
    def vrow(claim, r, unit):
        return f"| {claim} | **{r.verdict()}** | {r.evidence(unit)} |"

    verdict_rows = [
        "## Verdicts", "",
        f"Every row is a paired comparison over runs with the same data and initial error for both filters: "
        "\"A better than B\" with A = RB-UKF and B = EKF, exact two-sided sign test and Wilcoxon signed-rank "
        "test, the median difference A - B with its distribution-free 95 % interval and the ratio of means "
        "B / A with a bootstrap 95 % interval (`insnav.analysis.paired`).  Wording by the Wilcoxon p-value at "
        f"alpha = {ALPHA}: **reproduced** (RB-UKF significantly lower), **opposite** (significantly higher), "
        "**not significant**.  \"Plain reading\": the preset `seed000-sim` (noise per 200 Hz sample); "
        "\"calibrated\": the sweep setting whose EKF is closest to the paper's (section \"Calibrating the EKF "
        "baseline\").", "",
        "| paper's claim | verdict | evidence |", "|---|---|---|"]
    for i, ax in enumerate(AXES):
        verdict_rows.append(vrow(f"Table 1, plain reading: the RB-UKF's max {ax} error after recovery (90-150 s) "
                                 "is below the EKF's", tests[f"max {ax} error 90-150 s [deg]"], "deg"))
        verdict_rows.append(vrow(f"Table 1, calibrated (R = {best[0]:g} Hz, attitude sigma "
                                 f"{'/'.join(f'{x:g}' for x in best[1])} deg): the same for {ax}",
                                 cal_tests[("att_max", i)], "deg"))
    for i, ax in enumerate(AXES):
        verdict_rows.append(vrow(f"Table 1, plain reading: the RB-UKF reconverges faster in {ax}",
                                 tests[f"{ax} reconvergence [s]"], "s"))
        verdict_rows.append(vrow(f"Table 1, calibrated: the RB-UKF reconverges faster in {ax}",
                                 cal_tests[("att_reconv", i)], "s"))
    for H in big:
        for i, ax in ((0, "roll"), (1, "pitch")):
            x = np.array([r["ekf"]["att_max"][i] for r in head[H]], float)
            y = np.array([r["rbukf"]["att_max"][i] for r in head[H]], float)
            verdict_rows.append(vrow(f"(not in the paper) initial heading error {H:.0f} deg, weaving turns: the "
                                     f"RB-UKF's max {ax} error after recovery is below the EKF's",
                                     paired_test(y, x), "deg"))
    for k in range(4):
        verdict_rows.append(vrow(f"Table 3 analogue (simulated car), outage {k + 1}: the RB-UKF's max position "
                                 "error after recovery is below the EKF's", car_tests[(k, "pos_max")], "m"))
        verdict_rows.append(vrow(f"Table 3 analogue, outage {k + 1}: the RB-UKF's position reconverges faster",
                                 car_tests[(k, "pos_reconv")], "s"))
    verdict_rows += [
        "| Table 3: matching the paper's EKF on the car | not attempted | the paper's car errors come from a "
        "real drive whose unmodelled errors (lever arm, scale factors, vibration, multipath) the paper does not "
        "quantify, so there is no parameter of our simulated car to calibrate against them |",
        "| the RB-UKF update costs 41.7 % fewer flops than the UKF's | see docs/results/flops.md | deterministic "
        "instruction counts; the verdict is computed there |", ""]
    i_v = L.index("VERDICTS_PLACEHOLDER")
    L[i_v:i_v + 1] = verdict_rows

    L += ["", "## Reading", "",
          f"* **Size of the differences.**  Over {N} runs of the plain reading the two filters' max attitude "
          f"errors after recovery differ by at most {float(dmax.max()):.4f} deg in any run and axis; mean "
          f"paired EKF - RB-UKF (± standard error): roll {vtxt('max roll error 90-150 s [deg]')}, pitch "
          f"{vtxt('max pitch error 90-150 s [deg]')}, yaw {vtxt('max yaw error 90-150 s [deg]')}, at most "
          f"{100 * rel.max():.1f} % of the EKF's error.  Our EKF's mean max roll/pitch/yaw: {f2(ekf_att)} deg; the "
          "paper: EKF 1.17/0.69/1.30 deg, RB-UKF 0.44/0.53/1.29 deg.",
          "* **Why the nonlinear model can only matter for large attitude errors.**  The RB-UKF differs from the "
          "EKF only through the nonlinearity of the Euler-platform-error-angle model (seed 000 eqs. (1)-(5)), "
          "whose extra terms are of second order in the attitude error psi.  At the end of the outage the "
          f"attitude error is {f2(att_end)} deg (roll/pitch/yaw, mean; EKF RMS over the 30 s before the outage: "
          f"{f2(pre_rms)} deg); the largest value in any run is {psi_max:.2f} deg, so psi^2/2 <= {second:.3f} deg "
          f"bounds what the linear model can get wrong (observed differences <= {float(dmax.max()):.3f} deg).  "
          "The calibration sweep shows how far the paper's open parameters move the EKF towards its figures; "
          "the calibrated rows of the verdicts judge the claim there.",
          f"* **Reconvergence (attitude, plain reading).**  With our band (1.5 x the pre-outage EKF RMS) the "
          f"error is outside the band right after the first update in {f2(100 * np.array(needed), 0)} % of the "
          f"runs (roll/pitch/yaw, EKF); EKF mean reconvergence {f2(rc_mean, 1)} s, against 15/5/9 s (EKF) and "
          "1/2/9 s (RB-UKF) in the paper.",
          "* **Position after recovery (Table 1 scenario).**  Horizontal error "
          f"{arr(sim, 'ekf', 'pos_end').mean():.1f} m at the end of the outage, max "
          f"{arr(sim, 'ekf', 'pos_max').mean():.1f} m after it (EKF means); paired EKF - RB-UKF "
          f"{vtxt('max horizontal position error 90-150 s [m]')} m; reconvergence "
          f"{vtxt('position reconvergence [s]', 3)} s.",
          "* **The max over 90-150 s is mostly not a recovery transient**: see 'when the max happens' (the "
          "scenario turns by 60 deg at 100-120 s); the 90-100 s column isolates the transient.",
          f"* **Table 3 analogue (car).**  Of 12 paired comparisons (4 outages x max velocity, max position, "
          f"reconvergence) {n_rb_better} are significant for the RB-UKF and {n_ekf_better} for the EKF; the "
          f"largest mean difference is {car_dpos * 1000:.2f} mm in max position and {car_dvel * 1000:.3f} mm/s in "
          f"max velocity.  Our EKF's max errors after the four recoveries ({f2(car_vel)} m/s, {f2(car_pos, 1)} m) "
          "against the paper's EKF (0.41/0.56/0.39/1.35 m/s, 19.9/51.2/15.0/53.9 m); " + rb_cmp +
          f".  Position reconvergence of our EKF: {f2(car_rc, 0)} s (paper: EKF 72/105/70/85 s, RB-UKF "
          f"25/6/5/6 s); band {f2(car_band)} m (1.5 x the pre-outage RMS with 10 Hz GNSS).",
          f"* **UKF.**  The augmented UKF equals the RB-UKF to {ukf_rb:.1e} (deg or m) in every run: the loose "
          "measurement is linear, where the unscented update is exact.",
          "* **Large initial heading error** (section above; not in the paper): the verdict rows for H >= 60 deg "
          "test whether the nonlinear model helps where attitude errors are large.  From a straight start (the "
          "heading not observable before the turn) the yaw consistency column shows rms(yaw err / sigma) per "
          "filter; a heading that uncertain should come from an alignment step (insnav.ins.align) or a particle "
          "filter.", ""]
    out = Path(a.out)
    text = "\n".join(L) + "\n"
    out.write_text(with_stamp(text, out))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
