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
  (counted separately, excluded from the mean) when no 5 s stretch inside the
  band exists in W.  'needed time' is the fraction of runs with a reconvergence
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
                pos_reconv=reconv_time(tw, hz[win], t_r, band_pos)))
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


def paired(a, b):
    """EKF minus RB-UKF per run: (mean, std, standard error, fraction where RB-UKF is lower)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    d = d[np.isfinite(d)]
    if len(d) == 0:
        return np.nan, np.nan, np.nan, np.nan
    return d.mean(), d.std(), d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else np.nan, (d > 0).mean()


def verdict(mean, se):
    if not np.isfinite(se) or se == 0:
        return "identical" if mean == 0 else "n/a"
    if mean > 2 * se:
        return "RB-UKF lower (> 2 SE)"
    if mean < -2 * se:
        return "EKF lower (> 2 SE)"
    return "no significant difference (within 2 SE)"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--car-runs", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
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
        wall = time.time() - t0
        with open(a.raw, "wb") as fh:
            pickle.dump(dict(sim=sim, car=car, head=head, head_straight=head_straight, wall=wall, t_sim=t_sim,
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
         f"--car-runs {a.car_runs} --workers {a.workers}",
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
    L += ["### Paired comparison, EKF minus RB-UKF per run (positive: RB-UKF better)", "",
          "| quantity | mean diff | std | standard error | RB-UKF lower in | verdict |", "|---|---|---|---|---|---|"]
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
    verdicts = {}
    for name, x, y, d in checks:
        m, s, se, frac = paired(x, y)
        v = verdict(m, se)
        verdicts[name] = (m, se, v)
        L.append(f"| {name} | {m:+.{d}f} | {s:.{d}f} | {se:.{d}f} | {frac:.2f} | {v} |")
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
    L += ["", "### Paired comparison, EKF minus RB-UKF per run and outage", "",
          "| outage | quantity | mean diff | std | standard error | RB-UKF lower in | verdict |",
          "|---|---|---|---|---|---|---|"]
    car_verdicts = []
    for k in range(4):
        for key, name, d in (("vel_max", "max vel error [m/s]", 4), ("pos_max", "max pos error [m]", 3),
                             ("pos_reconv", "pos reconvergence [s]", 2)):
            m, s, se, frac = paired(arr(car, "ekf", key, k), arr(car, "rbukf", key, k))
            v = verdict(m, se)
            car_verdicts.append(v)
            L.append(f"| {k + 1} | {name} | {m:+.{d}f} | {s:.{d}f} | {se:.{d}f} | {frac:.2f} | {v} |")

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
    rp_gain = [hsum[(H, "att_max", i)] for H in big for i in (0, 1)]
    rp_better = all(m > 0 and frac > 0.5 for m, frac, _ in rp_gain)
    pitch_gain = [hsum[(H, "att_max", 1)] for H in HEADINGS]
    grows = all(b[0] >= a[0] - 0.02 for a, b in zip(pitch_gain, pitch_gain[1:])) and pitch_gain[-1][0] > 0.1
    pitch_txt = ", ".join(f"{H:.0f} deg: {m:+.2f} deg of {base:.2f} ({frac:.0%} of runs)"
                          for H, (m, frac, base) in zip(HEADINGS, pitch_gain))

    # ---- reading ---------------------------------------------------------------------------------
    def vtxt(name, d=4):
        m, se, v = verdicts[name]
        return f"{m:+.{d}f} ± {se:.{d}f} SE, {v}"

    n_rb_better = sum(v.startswith("RB-UKF") for v in car_verdicts)
    n_ekf_better = sum(v.startswith("EKF") for v in car_verdicts)
    ekf_att = arr(sim, "ekf", "att_max").mean(axis=0)
    att_end = arr(sim, "ekf", "att_end").mean(axis=0)
    pre_rms = (arr(sim, "ekf", "att_band") / BAND).mean(axis=0)
    rel = np.abs([verdicts[f"max {ax} error 90-150 s [deg]"][0] for ax in AXES]) / ekf_att
    needed = [(arr(sim, f, "att_reconv")[:, i] > 0).mean() for f in ("ekf",) for i in range(3)]
    rc_mean = np.nanmean(arr(sim, "ekf", "att_reconv"), axis=0)
    car_dpos = max(abs(paired(arr(car, "ekf", "pos_max", k), arr(car, "rbukf", "pos_max", k))[0]) for k in range(4))
    car_dvel = max(abs(paired(arr(car, "ekf", "vel_max", k), arr(car, "rbukf", "vel_max", k))[0]) for k in range(4))
    car_pos = [arr(car, "ekf", "pos_max", k).mean() for k in range(4)]
    car_vel = [arr(car, "ekf", "vel_max", k).mean() for k in range(4)]
    car_rc = [np.nanmean(arr(car, "ekf", "pos_reconv", k)) for k in range(4)]
    f2 = lambda x, d=2: "/".join(f"{y:.{d}f}" for y in x)  # noqa: E731
    car_band = [arr(car, "ekf", "pos_band", k).mean() for k in range(4)]
    worse = [f"outage {k + 1} {q} ({o:.2f} vs {p})" for k in range(4)
             for q, o, p in (("velocity", car_vel[k], PAPER_T3["rbukf"]["vel"][k]),
                             ("position", car_pos[k], PAPER_T3["rbukf"]["pos"][k])) if o >= p]
    rb_cmp = ("below its RB-UKF (0.27/0.35/0.39/0.40 m/s, 5.4/4.0/5.9/7.3 m)" if not worse else
              "below its RB-UKF (0.27/0.35/0.39/0.40 m/s, 5.4/4.0/5.9/7.3 m) except " + ", ".join(worse))
    # ---- verdicts ----------------------------------------------------------------------------------
    v_t1 = "not reproduced" if not any(v.startswith("RB-UKF") for k, (m_, se_, v) in verdicts.items()
                                       if "90-150" in k) else "partly reproduced"
    verdict_rows = [
        "## Verdicts", "",
        "| paper's claim | verdict | evidence |", "|---|---|---|",
        f"| Table 1: after the outage the RB-UKF's max roll/pitch errors are below the EKF's | **{v_t1}** on the "
        f"paper's own scenario; **{'reproduced' if rp_better else 'partly reproduced'}** with a large initial "
        f"heading error | seed000-sim: the two filters differ by at most {float(dmax.max()):.4f} deg (attitude "
        "errors stay in the small-angle regime, see the reading); seed000-heading: the RB-UKF's "
        f"max roll/pitch after recovery is lower for H >= 60 deg (max pitch after recovery, EKF minus RB-UKF, "
        f"median over runs, of the EKF's median, for H = {pitch_txt}) |",
        "| Table 1: the RB-UKF reconverges faster | **not reproduced** on the paper's scenario; see the heading "
        "tables for the large-error case | paired reconvergence differences within 2 SE on seed000-sim |",
        f"| the nonlinear model matters when attitude errors are large | **{'reproduced' if grows else 'partly reproduced'}** "
        "| the RB-UKF's advantage in max pitch after recovery grows with the initial heading error (row above); "
        "at 10 deg the filters are equal |",
        f"| Table 3 (car): the RB-UKF's position errors after the outages are several times smaller | **not "
        f"reproduced** | {n_rb_better} of 12 paired car comparisons favour the RB-UKF by > 2 SE; the largest mean "
        f"difference is {car_dpos * 1000:.2f} mm |",
        "| the RB-UKF update costs 41.7 % fewer flops than the UKF's | **reproduced** | docs/results/flops.md "
        "(paper-form saving measured with callgrind) |", ""]
    i_v = L.index("VERDICTS_PLACEHOLDER")
    L[i_v:i_v + 1] = verdict_rows

    L += ["", "## Reading: where we agree with the paper and where not", "",
          "The paper's expectation: after GPS returns, the RB-UKF's max attitude and position errors are below "
          "the EKF's and it reconverges faster.  **Our measurements disagree: on both simulated scenarios the "
          "RB-UKF and the EKF recover identically** (to about a hundredth of a degree and a millimetre), so "
          "none of the paper's gaps appears.  The evidence, axis by axis:", "",
          f"* **Table 1, max attitude error after recovery.**  Over {N} runs the two filters differ by at most "
          f"{float(dmax.max()):.4f} deg in any run and axis.  Paired EKF - RB-UKF (mean ± standard error): "
          f"roll {vtxt('max roll error 90-150 s [deg]')}, pitch {vtxt('max pitch error 90-150 s [deg]')}, "
          f"yaw {vtxt('max yaw error 90-150 s [deg]')}.  Where a difference is resolvable it is in the EKF's "
          f"favour and {100 * rel.max():.1f} % or less of the error itself, i.e. of no practical size.  "
          f"The paper has EKF roll/pitch 1.17/0.69 deg against RB-UKF 0.44/0.53 deg; our EKF has "
          f"{f2(ekf_att[:2])} deg (mean over runs), already at or below the paper's RB-UKF.  Yaw is the one "
          f"axis where our level ({ekf_att[2]:.2f} ± {arr(sim, 'ekf', 'att_max')[:, 2].std():.2f} deg) is "
          "close to the paper's (1.30/1.29 deg, where the two filters are also equal).",
          f"* **Why the filters coincide here.**  The RB-UKF differs from the EKF only through the nonlinearity "
          "of the Euler-platform-error-angle model (seed 000 eqs. (1)-(5)), whose extra terms are of second "
          "order in the attitude error psi.  At the end of our outage the attitude error is "
          f"{f2(att_end)} deg (roll/pitch/yaw, mean), about its pre-outage level (EKF RMS over the 30 s before "
          f"the outage: {f2(pre_rms)} deg): the 40 s outage adds little attitude error.  The largest value in "
          f"any run is {psi_max:.2f} deg, so psi^2/2 <= {second:.3f} deg, an upper bound on what the linear "
          f"model can get wrong, consistent with the observed differences (<= {float(dmax.max()):.3f} deg).  "
          "The sigma points sit at sqrt(n + lambda) = sqrt(3) sigma (about 2 deg in yaw), also in the "
          "small-angle regime.  The scenario implements the paper's numbers (20 deg/h gyro bias, 300 deg/h "
          "gyro white noise read as per-sample noise at 200 Hz, i.e. ARW 0.35 deg/sqrt(h); "
          "`seed000-sim.toml`); the paper's EKF roll error of 1.17 deg after recovery implies much larger "
          "attitude errors at reacquisition than these parameters give us, and the paper does not say how "
          "its noise was applied.  We did not change the scenario to reproduce the paper.",
          f"* **Reconvergence (attitude).**  With our band (1.5 x the pre-outage EKF RMS) the error is outside "
          f"the band right after the first update in {f2(100 * np.array(needed), 0)} % of the runs "
          f"(roll/pitch/yaw, EKF); mean reconvergence {f2(rc_mean, 1)} s for both filters, against 15/5/9 s "
          "(EKF) and 1/2/9 s (RB-UKF) in the paper.  Paired differences: roll "
          f"{vtxt('roll reconvergence [s]', 3)}; pitch {vtxt('pitch reconvergence [s]', 3)}; yaw "
          f"{vtxt('yaw reconvergence [s]', 3)}.",
          "* **Position after recovery (Table 1 scenario).**  The first fixes remove most of the outage drift "
          f"(horizontal error {arr(sim, 'ekf', 'pos_end').mean():.1f} m at the end of the outage, max "
          f"{arr(sim, 'ekf', 'pos_max').mean():.1f} m after it) for both filters: paired max difference "
          f"{vtxt('max horizontal position error 90-150 s [m]')} m; reconvergence "
          f"{vtxt('position reconvergence [s]', 3)} s.",
          "* **The max over 90-150 s is mostly not a recovery transient**: its median time lies in or just "
          "after the 60 deg turn (see 'when the max happens'), where tilt and accelerometer bias become "
          "separable.  The 90-100 s column isolates the transient and shows the same equality of the filters.",
          f"* **Table 3 analogue (car).**  Of 12 paired comparisons (4 outages x max velocity, max position, "
          f"reconvergence) {n_rb_better} favour the RB-UKF by more than 2 SE, {n_ekf_better} the EKF; the "
          f"largest mean difference is {car_dpos * 1000:.2f} mm in max position and {car_dvel * 1000:.3f} mm/s "
          "in max velocity, i.e. the filters are identical in practice.  Our EKF's max errors after the four "
          f"recoveries ({f2(car_vel)} m/s, {f2(car_pos, 1)} m) are far below the paper's EKF "
          "(0.41/0.56/0.39/1.35 m/s, 19.9/51.2/15.0/53.9 m) and " + rb_cmp + ".  Position reconvergence takes "
          f"{f2(car_rc, 0)} s for both filters (paper: EKF 72/105/70/85 s, RB-UKF 25/6/5/6 s); our band is "
          f"tight ({f2(car_band)} m: 1.5 x the pre-outage RMS with 10 Hz GNSS).  Possible reasons for the much "
          "smaller errors (not tested here): in the simulation the IMU errors are exactly of the kind the "
          "filter models and the 20-40 s drift stays in the linear regime; the real car of the paper has "
          "unmodelled errors (lever arm, scale factors, vibration, GPS multipath).",
          f"* **UKF.**  The augmented UKF equals the RB-UKF to {ukf_rb:.1e} (deg or m) in every run, as "
          "expected: the loose measurement is linear, where the unscented update is exact.",
          "", "In short: the paper's claim that the RB-UKF recovers faster and with smaller errors than the EKF "
          "is not reproduced on our simulation of its scenarios.  It is not refuted either: by the second-order "
          "argument above a gap needs attitude errors of degrees at reacquisition, and with the paper's stated "
          "IMU parameters, as we read them, our outages leave the errors where the EKF's linearisation error is "
          "negligible.", "",
          "**Where the nonlinear model does matter: a large initial heading error** (section above).  With the "
          "heading off by 30-90 deg and a trajectory that makes it observable, the RB-UKF propagates the "
          "non-Gaussian yaw uncertainty through the Euler-platform-error-angle model and converges with smaller "
          "roll/pitch disturbances, so its roll/pitch errors after the outage are smaller too, the paper's "
          "Table 1 pattern.  From a straight start (the heading not observable) no filter can use the model's "
          "advantage until the first turn, and both stay overconfident in yaw (rms(yaw err / sigma) > 1): with "
          "a heading that uncertain, a Gaussian filter is the wrong tool at any order; the heading should come "
          "from an alignment step (insnav.ins.align) or a particle filter.", ""]
    out = Path(a.out)
    text = "\n".join(L) + "\n"
    out.write_text(with_stamp(text, out))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
