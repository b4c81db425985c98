"""Noise tuning by the innovation likelihood (``insnav tune``, insnav.calib.tune): does it find
the true noise, and does it help on real data?

1. Simulation (a car, insnav's simulator; the filter's model family matches the simulated
   errors): from noise settings wrong by 10x up and 10x down (every factor), the tuned factors
   against the truth (1), and rms(error/sigma) per axis on the held-out 30 % pooled over the
   seeds, before and after.  Targets: factors within 25 %, rms(error/sigma) within 0.85-1.15.
2. Real data, hand settings against tuned (tuned on the first 70 %, reported on the last 30 %):
   the KF-GINS track (loose EKF, 21 states, KF-GINS's YAML noise as the hand settings; also the
   time of the tuning), the rtklibexplorer walk loosely coupled on the RTK .pos and tightly
   coupled on the RINEX (tests/data/walk_0827_loose.toml, tests/data/walk_0827.toml).  Targets: held-out
   error no worse than the hand settings', and consistency (mean NIS per row, rms(error/sigma))
   within 0.7-1.3 where the hand settings are outside it.  The loose walk and the KF-GINS track also
   with the innovation-based adaptive measurement noise (``adaptive_r_window``, off by default); the
   loose and the tight walk with the adaptive process noise (``adaptive_q_window``, off by default), and
   with the walker's standstill modelled: the standstill detector (ins/standstill.hpp) over the walk's IMU
   against the `.pos` speed, ZUPT / ZARU updates (loose) and the standstill level of the process noise
   (``[constraints] standstill_q_scale``, off by default; ``--only walk-still`` runs just these sections).

Reproduce (from the repository root, with ../shared/data beside the repo)::

    python3 bench/tune_check.py --out docs/results/tune.md
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import insnav  # noqa: E402
from _common import git_commit  # noqa: E402
from _stamps import with_stamp  # noqa: E402
from insnav.calib.tune import (ReferenceModel, _cut, holdout_report, scaled_config, solution_log_likelihood,  # noqa: E402
                               tune)
from insnav.filters.loose import run_loose  # noqa: E402
from insnav.config import ImuNoise, RunConfig  # noqa: E402

COMMAND = "python3 bench/tune_check.py --out docs/results/tune.md"
DATA = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data"))
HOLDOUT = 0.3

#: the simulated car: a 15 min town drive (90-degree turns every 16 s at 12 m/s: the heading is
#: observed all along, so gyro white noise and gyro bias instability can be told apart), a MEMS IMU
#: whose biases are purely first-order Gauss-Markov (no turn-on constant: the filter's bias model is
#: then the simulated one, so the true factors are all 1), RTK-grade GNSS at 1 Hz
_SEGMENTS = [{"label": "standstill", "duration_s": 10.0}, {"duration_s": 8.0, "target_speed_mps": 12.0}]
for _i in range(56):
    _SEGMENTS += [{"duration_s": 8.0}, {"duration_s": 8.0, "heading_change_deg": 90.0 if _i % 2 == 0 else -90.0}]
SIM = {
    "extends": "seed000-car", "name": "tune-town",
    "description": "town drive, MEMS IMU 200 Hz (Gauss-Markov biases), GNSS 1 Hz 2 cm / 1 cm/s",
    "run": {"gate_prob": 0.9999},
    "motion": {"transition_s": 1.0, "segments": _SEGMENTS},
    "imu": {"rate_hz": 200.0,
            "gyro": {"bias_sigma_dph": 0.0, "gm_sigma_dph": 10.0, "gm_tau_s": 120.0, "arw_deg_per_sqrth": 0.5},
            "accel": {"bias_sigma_mg": 0.0, "gm_sigma_mg": 2.0, "gm_tau_s": 120.0, "vrw_mps_per_sqrth": 0.3}},
    "gnss": {"rate_hz": 1.0, "sigma_h_m": 0.02, "sigma_v_m": 0.04, "sigma_vel_mps": 0.01, "outages": []},
}
AXES = {"pos_n_m": ("N", "E", "D"), "vel_n_mps": ("vN", "vE", "vD"), "att_deg": ("roll", "pitch", "yaw")}


def fmt(x, nd=3):
    return "-" if x is None or not np.isfinite(x) else f"{x:.{nd}f}"


def errs_over(sol, truth, t_from):
    """(error, sigma) per quantity at the truth epochs after t_from (NED / roll, pitch, yaw)."""
    from insnav.analysis.evaluate import _solution_at
    from insnav.analysis.metrics import errors

    tr = np.asarray(truth.t)
    m = (tr >= t_from) & (tr <= sol.t[-1])
    e = errors(_solution_at(sol, tr[m]), truth)
    return {k: (e[k], e["sigma_" + k]) for k in AXES}


def pooled_nees(parts):
    """rms(error/sigma) per axis over the concatenated (error, sigma) pieces."""
    out = {}
    for k in AXES:
        x = np.concatenate([p[k][0] / p[k][1] for p in parts])
        out[k] = np.sqrt(np.mean(x ** 2, axis=0))
    return out


# --------------------------------------------------------------------------- 1. simulation

def simulation(seeds, max_runs, lines, verdicts):
    names = ["gyro_arw", "acc_vrw", "gyro_bias", "acc_bias", "gnss_pos", "gnss_vel"]
    lines += ["## 1. Simulation: a car, settings wrong by 10x", "",
              f"Scenario (`SIM` in this script, from `seed000-car`): a 15 min town drive at 12 m/s with a 90 deg "
              f"turn every 16 s (the heading is observed all along, so gyro white noise and gyro bias instability "
              f"can be told apart; on seed000-car's long straights they cannot: the likelihood is then flat along "
              f"their trade-off), 200 Hz MEMS IMU with ARW 0.5 deg/sqrt(h), VRW 0.3 m/s/sqrt(h), Gauss-Markov "
              f"biases 10 deg/h and 2 mg (tau 120 s, no turn-on constant: the filter's bias model is then the "
              f"simulated one), RTK-grade GNSS at 1 Hz with white noise 2 cm horizontal, 4 cm vertical, 1 cm/s "
              f"(sigmas in the data equal to it).  The true factors are all 1 (the filter's model from the "
              f"simulator's, `ImuNoise.from_dataset_model`).  Loose EKF, 15 states, gate on.  "
              f"{len(seeds)} drives (seeds {', '.join(map(str, seeds))}) tuned together (their ln L summed: a "
              f"Gauss-Markov sigma is only as well determined as the number of correlation times in the data), "
              f"each on its first {1 - HOLDOUT:.0%}; every factor starting at 10, then at 0.1; at most {max_runs} "
              f"evaluations (each {len(seeds)} runs).  Reported on the last {HOLDOUT:.0%} of each drive.", ""]
    dss = [insnav.simulate(SIM, seed=s) for s in seeds]
    truth_noise = ImuNoise.from_dataset_model(dss[0].imu_model)
    cfg0 = RunConfig(filter="ekf", imu=truth_noise)
    rows, parts, nis, timing, lls = {}, {}, {}, [], {}

    def holdout(key, c, t_splits):
        parts[key], nis[key] = [], []
        for ds, ts in zip(dss, t_splits):
            sol = insnav.run(ds, config=dataclasses.replace(c))
            parts[key].append(errs_over(sol, ds.truth, ts))
            nis[key].append(holdout_report(sol, None, t_from=ts)["nis_per_row"])

    for start, f in (("10x", 10.0), ("0.1x", 0.1)):
        wrong = scaled_config(cfg0, truth_noise, {n: f for n in names})
        t0 = time.perf_counter()
        res = tune(dss, wrong, params=names, holdout=HOLDOUT, max_runs=max_runs)
        timing.append((time.perf_counter() - t0, res.runs))
        rows[start] = {n: res.scales[n] * f for n in names}  # tuned factor on the truth
        lls[start] = (res.log_likelihood_base, res.log_likelihood_tuned)
        splits = res.t_split if isinstance(res.t_split, tuple) else (res.t_split,)
        holdout((start,), wrong, splits)
        holdout(("tuned", start), res.tuned, splits)
    lls["truth"] = sum(solution_log_likelihood(run_loose(_cut(ds, ts), dataclasses.replace(cfg0)), t_to=ts + 1e-9)[0]
                       for ds, ts in zip(dss, splits))
    holdout(("truth",), cfg0, splits)
    lines += ["Tuned factor on the truth (1 = found the simulated noise; target within 0.75-1.25) and ln L of "
              "the tuning segments:", "",
              "| start | " + " | ".join(names) + " | within 25 % | ln L start -> tuned (truth) |",
              "|---" * (len(names) + 3) + "|"]
    allin = True
    for start, sc in rows.items():
        ok = all(0.75 <= v <= 1.25 for v in sc.values())
        allin &= ok
        lines.append(f"| {start} | " + " | ".join(f"{sc[n]:.3f}" for n in names) + f" | {'yes' if ok else 'no'} | "
                     f"{lls[start][0]:.1f} -> {lls[start][1]:.1f} ({lls['truth']:.1f}) |")
    worst = {n: max(abs(rows[k][n] - 1.0) for k in rows) for n in names}
    lines += ["", "Largest deviation from 1 per factor: " + ", ".join(f"{n} {100 * v:.0f} %" for n, v in worst.items())
              + ".", ""]
    lines += [f"rms(error/sigma) on the held-out {HOLDOUT:.0%}, pooled over the drives (target 0.85-1.15 after "
              "tuning), and the mean NIS per row of the held-out GNSS records:", "",
              "| settings | " + " | ".join(a for k in AXES for a in AXES[k]) + " | NIS/row | all within 0.85-1.15 |",
              "|---" * 12 + "|"]
    label = {("truth",): "true noise", ("10x",): "start 10x", ("0.1x",): "start 0.1x",
             ("tuned", "10x"): "tuned from 10x", ("tuned", "0.1x"): "tuned from 0.1x"}
    tuned_ok = True
    for key in label:
        r = pooled_nees(parts[key])
        vals = np.concatenate([r[k] for k in AXES])
        ok = bool(np.all((vals >= 0.85) & (vals <= 1.15)))
        if key[0] == "tuned":
            tuned_ok &= ok
        lines.append(f"| {label[key]} | " + " | ".join(f"{v:.2f}" for v in vals)
                     + f" | {np.mean(nis[key]):.2f} | {'yes' if ok else 'no'} |")
    lines += ["", "Tuning: " + "; ".join(f"{r} evaluations x {len(seeds)} runs in {t:.0f} s" for t, r in timing)
              + f" (1-min load average {os.getloadavg()[0]:.1f} on 2 cores).", ""]
    verdicts.append(("simulation: tuned factors within 25 % of the truth (both starts)",
                     "met" if allin else "NOT met"))
    verdicts.append(("simulation: rms(error/sigma) within 0.85-1.15 on every axis after tuning",
                     "met" if tuned_ok else "NOT met"))


# --------------------------------------------------------------------------- 2. real data

def total_rows(hand, tuned, cols=None) -> list:
    """The rows of the consistency against the reference's point and its own noise (``nees_total``)."""
    out = []
    for k, ax in AXES.items():
        if k not in tuned.get("nees_total", {}):
            continue
        vals = [", ".join(f"{v:.2f}" for v in r["nees_total"][k]) for r in (cols or (hand, tuned))]
        out.append(f"| rms(err/sqrt(sigma^2 + sigma_ref^2)) {', '.join(ax)}, the reference's point | "
                   + " | ".join(vals) + " |")
    return out


def consistency_figures(rep) -> list:
    """(name, value) of the figures the verdicts judge: NIS/row, rms(e/sqrt(sigma^2 + sigma_ref^2)) of the
    position and velocity (expectation 1 for a consistent filter against this reference, see
    ``reference_note``), rms(err/sigma) of the attitude (an exact reference where it has one)."""
    cons = [("NIS/row", rep["nis_per_row"])]
    for k, ax in AXES.items():
        src = rep.get("nees_total", {}) if k in ("pos_n_m", "vel_n_mps") else rep.get("nees", {})
        if k in src:
            name = "rms(err/sigma_total)" if k in ("pos_n_m", "vel_n_mps") else "rms(err/sigma)"
            cons += [(f"{name} {n}", v) for n, v in zip(ax, src[k])]
    return cons


def reference_note(model, rep) -> str:
    """The sentence that states the consistency figure's reference model, with the figures it used."""
    l_b = np.asarray(model.lever_arm_b, float)
    sp, sv = rep.get("reference_sigma_pos_m"), rep.get("reference_sigma_vel_mps")
    return ("Consistency against this reference (`ReferenceModel`, docs/algorithms.md section 20): the reference "
            "is r = x_a + w, x_a the true point it describes (here "
            + (f"the antenna, lever arm l_b = [{', '.join(f'{v:g}' for v in l_b)}] m from the IMU centre"
               if np.any(l_b != 0) else "the IMU centre")
            + ") and w its own error of variance sigma_ref^2 (" + model.source + "; rms over the held-out epochs "
            f"N, E, D {', '.join(f'{100 * v:.1f}' for v in sp)} cm, vN, vE, vD "
            f"{', '.join('-' if not np.isfinite(v) else f'{100 * v:.1f}' for v in sv)} cm/s), independent of the "
            "filter's error; the solution's point x_hat + C_nb l_b (velocity v_hat + C_nb (omega_ib_b x l_b)"
            + (f", taken velocity_lag_s = {model.velocity_lag_s:g} s before the reference epoch, whose velocity "
               "column describes that time" if model.velocity_lag_s else "")
            + ") then has the error e = (x_hat - x) - w, and a consistent filter gives E[e^2] = sigma^2 + "
            "sigma_ref^2 per axis, so E[(e / sqrt(sigma^2 + sigma_ref^2))^2] = 1: the rows "
            "rms(err/sqrt(sigma^2 + sigma_ref^2)), which the verdicts use (the attitude share of C_nb l_b is left "
            f"out: at most |l_b| times the attitude sigma, {1000 * rep.get('lever_sigma_max_m', 0.0):.1f} mm here).  "
            "The rows rms(err/sigma) are the IMU centre against the reference as it is, with the filter's sigma "
            "alone: their expectation for a consistent filter is sqrt(1 + (b^2 + sigma_ref^2) / sigma^2) (b the "
            "lever arm in NED), not 1.  Share of the reference in the predicted position variance, sigma_ref^2 / "
            "(sigma^2 + sigma_ref^2) averaged over the epochs, tuned run: N, E, D "
            + ", ".join(f"{v:.2f}" for v in rep.get("reference_variance_share_pos", [np.nan] * 3))
            + " (near 1: the position figures test the reference more than the filter).")


def compare(title, ds, cfg, reference, lines, verdicts, *, max_runs, keep_t=None, note="", timing=False,
            reference_model=None):
    """Tune on the first 70 %, report hand vs tuned on the last 30 %."""
    load0 = os.getloadavg()[0]
    res = tune(ds, cfg, holdout=HOLDOUT, max_runs=max_runs)
    load1 = os.getloadavg()[0]
    reps = []
    for c in (res.base, res.tuned):
        sol = insnav.run(ds, config=dataclasses.replace(c))
        reps.append(holdout_report(sol, reference, t_from=res.t_split, keep_t=keep_t,
                                   reference_model=reference_model))
    hand, tuned = reps
    lines += [f"### {title}", "", note, "",
              f"Tuned ({res.tuned.filter}, {res.tuned.coupling}) on t < {res.t_split:.1f} s: {res.runs} runs, "
              f"{res.seconds:.1f} s (1-min load average {load0:.1f} -> {load1:.1f} on 2 cores); ln L "
              f"{res.log_likelihood_base:.1f} -> {res.log_likelihood_tuned:.1f} over {res.records} records.  "
              "Factors: " + ", ".join(f"{n} x {v:.3g}" for n, v in res.scales.items()) + ".", "",
              "| held out (last 30 %) | hand | tuned |", "|---|---|---|",
              f"| GNSS records applied | {hand['records']} | {tuned['records']} |",
              f"| mean NIS per row (1 = consistent) | {fmt(hand['nis_per_row'], 2)} | {fmt(tuned['nis_per_row'], 2)} |",
              f"| ln L per record | {fmt(hand['log_likelihood_per_record'], 2)} | "
              f"{fmt(tuned['log_likelihood_per_record'], 2)} |",
              "| innovation lag-1 autocorrelation, position / velocity rows (0: white) | "
              + " | ".join(", ".join(f"{v:.2f}" for v in r["innovation_lag1"]) for r in (hand, tuned)) + " |"]
    if reference is not None:
        lines += [f"| reference epochs | {hand.get('epochs', 0)} | {tuned.get('epochs', 0)} |",
                  f"| horizontal RMS error [m] | {fmt(hand.get('hor_rms_m'), 4)} | {fmt(tuned.get('hor_rms_m'), 4)} |",
                  f"| 3-D RMS error [m] | {fmt(hand.get('rms_3d_m'), 4)} | {fmt(tuned.get('rms_3d_m'), 4)} |"]
        for key, note in (("nees", ""), ("nees_demeaned", ", each axis's mean error removed")):
            for k, ax in AXES.items():
                a, b = hand.get(key, {}).get(k), tuned.get(key, {}).get(k)
                if a is None:
                    continue
                lines.append(f"| rms(err/sigma) {', '.join(ax)}{note} | {', '.join(f'{v:.2f}' for v in a)} | "
                             f"{', '.join(f'{v:.2f}' for v in b)} |")
        lines += total_rows(hand, tuned)
    lines.append("")
    if reference is not None and reference_model is not None:
        lines += [reference_note(reference_model, tuned), ""]
    # verdicts
    if reference is not None and "hor_rms_m" in hand:
        r = tuned["hor_rms_m"] / hand["hor_rms_m"]
        verdicts.append((f"{title}: held-out horizontal error, tuned / hand = {r:.3f} (target <= 1)",
                         "met" if r <= 1.0 else "NOT met"))
    cons = [(n, x, y) for (n, x), (_, y) in zip(consistency_figures(hand), consistency_figures(tuned))]
    outside = [(n, x, y) for n, x, y in cons if not 0.7 <= x <= 1.3]
    fixed = [(n, x, y) for n, x, y in outside if 0.7 <= y <= 1.3]
    worse = [(n, x, y) for n, x, y in cons if 0.7 <= x <= 1.3 and not 0.7 <= y <= 1.3]
    verdicts.append((f"{title}: figures within 0.7-1.3 with the hand settings and outside after tuning: "
                     + ("; ".join(f"{n} {x:.2f} -> {y:.2f}" for n, x, y in worse) if worse else "none"),
                     "none" if not worse else f"{len(worse)} worse"))
    if outside:
        verdicts.append((f"{title}: consistency brought within 0.7-1.3 where the hand settings are outside it: "
                         f"{len(fixed)} of {len(outside)} ("
                         + "; ".join(f"{n} {x:.2f} -> {y:.2f}" for n, x, y in outside) + ")",
                         "met" if len(fixed) == len(outside) else "NOT met"))
    else:
        verdicts.append((f"{title}: hand settings already within 0.7-1.3 on every figure", "n/a"))
    if timing:
        verdicts.append((f"{title}: {res.runs} runs in {res.seconds:.1f} s (target: a few dozen runs in under a "
                         "minute)", "met" if res.seconds < 60.0 and res.runs >= 24 else "NOT met"))
    return res, hand, tuned


def kfgins(lines, verdicts, max_runs):
    from insnav.io.kfgins import read_kfgins_nav
    from insnav.io.kfgins_dataset import load_kfgins

    d = DATA / "kfgins" / "sim"
    if not d.is_dir():
        lines += ["### KF-GINS track", "", f"not run: {d} not found", ""]
        return
    ds, cfg = load_kfgins(d / "kf-gins-sim.yaml", d / "Leador-A15-sim.txt.xz", d / "GNSS-RTK-sim.txt", layout=21)
    truth = read_kfgins_nav(d / "truth-sim.nav.xz")
    res, hand, tuned = compare(
        "KF-GINS track (loose EKF-21)", ds, cfg, truth, lines, verdicts, max_runs=max_runs, timing=True,
        reference_model=ReferenceModel(source="the truth file of the IMU centre, taken as exact: sigma_ref = 0"),
        note="`../shared/data/kfgins/sim`: the real KF-GINS RTK track (1 Hz) with a synthesised 200 Hz "
             "navigation-grade IMU, 56 min; hand settings = KF-GINS's YAML (`insnav run --format kfgins`); "
             "reference = its truth file (every IMU epoch after the split).")
    # the adaptive measurement noise (walk_loose_adaptive) on this track: hand and tuned settings with the window
    rows = []
    for n in ADAPTIVE_WINDOWS:
        for label, c, base in (("hand", res.base, hand), ("tuned", res.tuned, tuned)):
            r = holdout_report(insnav.run(ds, config=dataclasses.replace(c, adaptive_r_window=n)), truth,
                               t_from=res.t_split)
            fg = [r["nis_per_row"]] + list(r["nees"]["pos_n_m"]) + list(r["nees"]["vel_n_mps"])
            rows.append((n, label, fg, r["hor_rms_m"] / base["hor_rms_m"]))
    lines += ["The same held-out figures with the adaptive measurement noise (`adaptive_r_window` N; section on "
              "the loose walk below): NIS/row, rms(err/sigma) N, E, D, vN, vE, vD, and the horizontal error "
              "against the same settings without it.", "",
              "| N | settings + adaptive R | NIS/row, N, E, D, vN, vE, vD | within 0.7-1.3 (of 7) | horizontal error "
              "/ without |", "|---|---|---|---|---|"]
    lines += [f"| {n} | {label} | {', '.join(f'{v:.2f}' for v in fg)} | {sum(0.7 <= v <= 1.3 for v in fg)} | "
              f"{ratio:.3f} |" for n, label, fg, ratio in rows]
    worst = max(ratio for *_, ratio in rows)
    lines += ["", f"Largest held-out horizontal error ratio with the adaptive R on this track: {worst:.3f}.", ""]


def pos_reference_model(pos, ds, cfg, lag_s) -> ReferenceModel:
    """The RTK ``.pos`` as a reference of the antenna (insnav.calib.tune.pos_reference_model)."""
    from insnav.calib.tune import pos_reference_model as model

    return model(pos, ds, lag_s)


def walk_loose(lines, verdicts, max_runs, only_still=False):
    from insnav.io.rinex_dataset import rtklib_truth

    w = DATA / "rtklibexplorer_walk_0827"
    if not w.is_dir():
        lines += ["### Walk, loose", "", f"not run: {w} not found", ""]
        return
    d = tomllib.loads((ROOT / "tests" / "data" / "walk_0827_loose.toml").read_text())
    pos = w / "raw" / "gnss_1730_sf.pos"
    ds, cfg = insnav.load_csv_dataset(w / "raw" / "imu_1730.csv", pos, d)
    ref = rtklib_truth(str(pos), ds.gps_time_offset_s)
    seen = np.asarray(ds.gnss.t_valid)
    unseen = np.setdiff1d(np.round(np.asarray(ref.t), 3), np.round(seen, 3))
    model = pos_reference_model(pos, ds, cfg, float(d["gnss"]["velocity_lag_s"]))
    res, hand, _ = compare("rtklibexplorer walk, loose on the RTK .pos (EKF)", ds, cfg, ref, lines, verdicts,
                        max_runs=max_runs, keep_t=unseen, reference_model=model,
                        note="`tests/data/walk_0827_loose.toml` (consumer grade, `[gnss] decimate = 4`: 1 fix in 4 "
                             "to the filter, position sigma floor 5 cm, velocity sigma 0.1 m/s) as the hand settings; "
                             "reference = the RTK `.pos` at the epochs the filter did not see (the antenna).")
    from tune_walk_loose_diag import expectation_lines

    if not only_still:
        lines += expectation_lines(ds, cfg, ref, res, float(d["gnss"]["velocity_lag_s"]))
        lines += walking_standing(ds, ref, res, unseen, model, pos)
        lines += innovation_budget(ds, ref, res)
        lines += walk_loose_variants(d, w, ref, unseen, model, max_runs)
        lines += walk_loose_adaptive(ds, ref, unseen, model, res, max_runs, verdicts)
        lines += walk_loose_adaptive_q(ds, ref, unseen, model, res, max_runs, verdicts)
    lines += walk_standstill_detector(ds, cfg, ref)
    lines += walk_standstill(ds, cfg, ref, unseen, model, res, max_runs, verdicts, "loose", hand)


def walking_standing(ds, ref, res, unseen, model, pos) -> list:
    """The held-out consistency figures split into the walking part and the final standstill, with the
    reference's own scatter while standing against its stated sigmas."""
    from insnav.io.gnss_files import read_pos_records
    from tune_walk_loose_diag import STILL_MPS, standstill_start

    t_still = standstill_start(ref, res.t_split)
    from insnav.calib.tune import reference_errors

    reps = {}
    for name, c in (("hand", res.base), ("tuned", res.tuned)):
        sol = insnav.run(ds, config=dataclasses.replace(c))
        for seg, a, b in (("walking", res.t_split, t_still), ("standing", t_still, np.inf)):
            reps[name, seg] = holdout_report(sol, ref, a, b, keep_t=unseen, reference_model=model)
    tr = np.asarray(ref.t, float)
    standing = reference_errors(sol, ref, model, tr[np.isin(np.round(tr, 3), unseen) & (tr >= t_still)])
    j = lambda v: ", ".join(f"{x:.2f}" for x in v)  # noqa: E731
    out = [f"The held-out figures split at the standstill ({t_still - float(np.asarray(ref.t)[0]):.1f} s after the "
           "first `.pos` epoch; reference epochs the filter did not see):", "",
           "| held out | GNSS records | NIS/row | rms(err/sqrt(sigma^2 + sigma_ref^2)) N, E, D | vN, vE, vD |",
           "|---|---|---|---|---|"]
    for (name, seg), r in reps.items():
        out.append(f"| {name}, {seg} | {r['records']} | {r['nis_per_row']:.2f} | {j(r['nees_total']['pos_n_m'])} | "
                   f"{j(r['nees_total']['vel_n_mps'])} |")
    rec = read_pos_records(pos)
    t = rec.t_ref_s + np.asarray(rec.t_s, float) - ds.gps_time_offset_s
    m = t >= t_still
    lat, lon, h = np.radians(rec.lat_deg[m]), np.radians(rec.lon_deg[m]), np.asarray(rec.h_m[m], float)
    p = np.column_stack([(lat - lat.mean()) * 6371000.0, (lon - lon.mean()) * 6371000.0 * np.cos(lat.mean()),
                         -(h - h.mean())])
    sd_p, sd_v = p.std(axis=0), np.asarray(rec.v_n[m], float).std(axis=0)
    st_p = np.sqrt(np.mean(np.asarray(rec.sigma_pos_n[m], float) ** 2, axis=0))
    st_v = np.sqrt(np.nanmean(np.asarray(rec.sigma_vel_n[m], float) ** 2, axis=0))
    tw, ts = reps["tuned", "walking"], reps["tuned", "standing"]
    # a consistent filter with the tuned run's standing sigmas, against a reference whose error has the scatter
    # above but sigma_ref = its stated sigma: E[e^2] = sigma^2 + scatter^2, so the figure is
    # sqrt(mean(sigma^2 + scatter^2) / mean(sigma^2 + stated^2)) per axis
    cons_p = np.sqrt(np.mean(standing["sigma_filter_pos"] ** 2 + sd_p ** 2, axis=0)
                     / np.mean(standing["sigma_filter_pos"] ** 2 + standing["sigma_ref_pos"] ** 2, axis=0))
    cons_v = np.sqrt(np.nanmean(standing["sigma_filter_vel"] ** 2 + sd_v ** 2, axis=0)
                     / np.nanmean(standing["sigma_filter_vel"] ** 2 + standing["sigma_ref_vel"] ** 2, axis=0))
    figs = lambda r: [r["nis_per_row"]] + r["nees_total"]["pos_n_m"] + r["nees_total"]["vel_n_mps"]  # noqa: E731
    n_in = lambda r: sum(0.7 <= v <= 1.3 for v in figs(r))  # noqa: E731
    out += ["", f"Walking, the tuned run has {n_in(tw)} of 7 figures within 0.7-1.3; standing, {n_in(ts)} of 7 "
            f"(largest {max(figs(ts)):.2f}): there it is underconfident against this reference.  While the walker "
            f"stands (speed below {STILL_MPS:g} m/s), the `.pos` positions scatter by N, E, D {j(100 * sd_p)} cm and "
            "its "
            f"velocities by {j(100 * sd_v)} cm/s (standard deviation over the {int(m.sum())} epochs), against its "
            f"stated sigmas {j(100 * st_p)} cm and {j(100 * st_v)} cm/s, which sigma_ref uses; the filter's position "
            "rows have the 5 cm floor times the tuned factor, and its process noise was tuned on walking only (the "
            "tuning part has no standstill).  Neither noise model describes a walker standing still.  With the "
            "reference's actual scatter, a consistent filter with the tuned run's standing sigmas would show "
            f"N, E, D {j(cons_p)} and vN, vE, vD {j(cons_v)} there (sqrt((sigma^2 + scatter^2) / (sigma^2 + "
            "sigma_ref^2)), averaged over the standing epochs): the reference's stated sigmas alone hold the "
            "standing figures below 1 by that much.", ""]
    return out


def innovation_budget(ds, ref, res) -> list:
    """The tuned run's GNSS innovations per row, walking and standing, against what the filter predicts for
    them: sqrt(R) (the fix's sigma as the run uses it) and the filter's own sigma just before the record
    (sqrt of the diagonal of P-; S = H P- H' + R)."""
    from insnav.analysis.evaluate import _solution_at
    from insnav.filters.loose import loose_gnss_rows
    from tune_walk_loose_diag import standstill_start

    sol = insnav.run(ds, config=dataclasses.replace(res.tuned))
    rows = loose_gnss_rows(ds.gnss, res.tuned)
    t = np.asarray(sol.gnss_t, float)
    t_still = standstill_start(ref, res.t_split)
    out = ["The tuned run's innovations against their predicted parts (rms over the records; position N, E, D "
           "[cm], velocity vN, vE, vD [cm/s]):", "",
           "| records | n | innovation, position | sqrt(R) | filter sigma before the record | innovation, velocity | "
           "sqrt(R) | filter sigma before the record |", "|---|---|---|---|---|---|---|---|"]
    j = lambda v: ", ".join(f"{100 * x:.1f}" for x in v)  # noqa: E731
    stand = None
    for name, m in (("tuning part (walking)", t < res.t_split),
                    ("held out, walking", (t >= res.t_split) & (t < t_still)), ("held out, standing", t >= t_still)):
        if not m.any():
            continue
        inn = np.asarray(sol.innovation, float)[m]
        r = rows[np.searchsorted(rows[:, 0], t[m]), 7:13]
        at = _solution_at(sol, t[m] - 1e-3)
        p = np.column_stack([at.sigma_pos_n_m, at.sigma_vel_n_mps])
        rms = lambda x: np.sqrt(np.nanmean(x ** 2, axis=0))  # noqa: E731
        a, b, c = rms(inn), rms(r), rms(p)
        out.append(f"| {name} | {int(m.sum())} | {j(a[:3])} | {j(b[:3])} | {j(c[:3])} | {j(a[3:])} | {j(b[3:])} | "
                   f"{j(c[3:])} |")
        if name == "held out, standing":
            stand = (a, b, c)
    if stand is not None:
        a, b, c = stand
        pred = np.sqrt(b ** 2 + c ** 2)
        out += ["", f"Standing, the innovations are {j(a[:3])} cm and {j(a[3:])} cm/s rms, where the filter predicts "
                f"sqrt(R + P-) = {j(pred[:3])} cm and {j(pred[3:])} cm/s (the fixes themselves scatter by millimetres "
                "there: the innovations are the filter's own error before the record, its error after the last fix "
                "and the INS's drift over the second since).  Its R is the walking level on every row (a constant "
                "factor on a constant sigma: the `.pos` "
                "sigmas do not change when the walker stops), "
                + (f"larger than the innovations on the velocity rows ({j(b[3:])} cm/s), "
                   if np.all(b[3:] > a[3:]) else "")
                + "and P- follows the process noise tuned on walking (the IMU's errors while walking: gait, hand "
                "swing).  The variants below give R a motion-dependent term and the tuner standing data; the "
                "process noise stays one constant setting for both (insnav has no motion-dependent process noise).",
                ""]
    return out


#: the loose walk's variants (walk_loose_variants): the `.pos` sigma floor replaced by motion-dependent sigmas,
#: sigma^2 = (s sigma_data)^2 + (k |v_h|)^2 per axis: the `.pos` position sigmas as they are (1 cm), k_pos 0.04 s
#: (5 cm at 1.25 m/s: the floor while walking), velocity 0.02 m/s + 0.08 |v_h| (0.1 m/s at 1.25 m/s)
SPEED_SIGMAS = {"min_sigma_pos_m": 0.0, "sigma_vel_mps": 0.02, "gnss_pos_sigma_per_speed_s": 0.04,
                "gnss_vel_sigma_per_speed": 0.08}
#: block lengths [s] of the interleaved split: the final standstill is about 19 s, so blocks of 10 s put it
#: in both parts (3 s held out per block), blocks of 20 s about once
WALK_BLOCKS_S = (10.0, 20.0)


def walk_loose_variants(d, w, ref, unseen, model, max_runs) -> list:
    """Hand and tuned held-out figures of the loose walk with the split interleaved (tune(split="blocks")) and
    with the motion-dependent GNSS sigmas (SPEED_SIGMAS) instead of the floor; each its own hand settings (the
    TOML with the change) and tuning (same budget as above)."""
    from tune_walk_loose_diag import standstill_start

    pos = w / "raw" / "gnss_1730_sf.pos"
    d_speed = {k: (dict(v) if isinstance(v, dict) else v) for k, v in d.items()}
    d_speed["gnss"].update(min_sigma_pos_m=SPEED_SIGMAS["min_sigma_pos_m"], sigma_vel_mps=SPEED_SIGMAS["sigma_vel_mps"])
    d_speed.update({k: v for k, v in SPEED_SIGMAS.items() if k.startswith("gnss_")})
    sets = {"floor 5 cm (the TOML)": insnav.load_csv_dataset(w / "raw" / "imu_1730.csv", pos, d),
            "motion-dependent sigmas": insnav.load_csv_dataset(w / "raw" / "imu_1730.csv", pos, d_speed)}
    figs = lambda r: [r["nis_per_row"]] + r["nees_total"]["pos_n_m"] + r["nees_total"]["vel_n_mps"]  # noqa: E731
    j = lambda v: ", ".join(f"{x:.2f}" for x in v)  # noqa: E731
    out = ["Variants (each tuned as above, its hand settings the TOML with the change; the held-out figures over "
           "the held-out records and unseen reference epochs of its own split): the GNSS sigmas either floored "
           "(the TOML) or motion-dependent (sigma^2 = (s sigma_data)^2 + (k |v_h|)^2, `gnss_pos_sigma_per_speed_s` "
           f"{SPEED_SIGMAS['gnss_pos_sigma_per_speed_s']:g} s on the `.pos` position sigmas without a floor, "
           f"velocity {SPEED_SIGMAS['sigma_vel_mps']:g} m/s and `gnss_vel_sigma_per_speed` "
           f"{SPEED_SIGMAS['gnss_vel_sigma_per_speed']:g}: about the floor while walking, the receiver's own "
           "sigma standing; the tuner adds the factors gnss_pos_speed and gnss_vel_speed), and the split either "
           "the tail (the last 30 %: the final standstill only in the held-out part) or interleaved blocks "
           f"(`tune(split=\"blocks\")`, blocks of {' and '.join(f'{b:g}' for b in WALK_BLOCKS_S)} s, the last "
           "30 % of each held out: the standstill in both parts, each part the data's mix of walking and "
           "standing).  Figures: NIS/row, rms(err/sigma_total) N, E, D, vN, vE, vD.", "",
           "| GNSS sigmas | split | held-out records walking / standing | hand | tuned | within 0.7-1.3 hand / "
           "tuned | tuned NIS/row walking / standing | horizontal error tuned / hand |",
           "|---|---|---|---|---|---|---|---|"]
    done = []
    for label, (ds, cfg) in sets.items():
        for split, block in [("tail", None)] + [("blocks", b) for b in WALK_BLOCKS_S]:
            kw = {} if block is None else dict(split="blocks", block_s=block)
            res = tune(ds, cfg, holdout=HOLDOUT, max_runs=max_runs, **kw)
            t_still = standstill_start(ref, float(np.asarray(ref.t)[0]) + 100.0)
            reps = []
            for c in (res.base, res.tuned):
                sol = insnav.run(ds, config=dataclasses.replace(c))
                reps.append([holdout_report(sol, ref, a, b, keep_t=unseen, reference_model=model,
                                            intervals=res.heldout)
                             for a, b in ((-np.inf, np.inf), (-np.inf, t_still), (t_still, np.inf))])
            (h, _, _), (tu, tw, ts) = reps
            n_in = lambda r: sum(0.7 <= v <= 1.3 for v in figs(r))  # noqa: E731
            done.append(dict(label=label, block=block, hand=figs(h), tuned=figs(tu), n=n_in(tu),
                             ratio=tu["hor_rms_m"] / h["hor_rms_m"], standing_nis=ts["nis_per_row"]))
            out.append(f"| {label} | {split if block is None else f'blocks of {block:g} s'} | {tw['records']} / "
                       f"{ts['records']} | {j(figs(h))} | {j(figs(tu))} | {n_in(h)} / {n_in(tu)} | "
                       f"{tw['nis_per_row']:.2f} / {ts['nis_per_row']:.2f} | {tu['hor_rms_m'] / h['hor_rms_m']:.3f} |")
    ok = [v for v in done if v["n"] == 7 and v["ratio"] <= 1.0]
    blk = [v for v in done if v["block"] is not None]
    vd_high = [v for v in blk if v["tuned"][6] > 1.3]
    name = lambda v: v["label"] + ", " + ("tail" if v["block"] is None else f"blocks of {v['block']:g} s")  # noqa: E731
    nis_st = ", ".join(f"{v['standing_nis']:.2f}" for v in done)
    out += ["", f"{len(ok)} of {len(done)} variants have every tuned figure within 0.7-1.3 with a held-out error no "
            "worse than their hand settings'" + (": " + "; ".join(name(v) for v in ok) if ok else "")
            + f".  Tuned NIS/row of the standing held-out records: {nis_st} (in the table's order).  With the tail "
            "split the tuning part has no standstill, so the likelihood does not identify the standing level of the "
            "motion-dependent sigmas; with the interleaved split the held-out part is mostly walking, and the tuned "
            f"vD figure is above 1.3 in {len(vd_high)} of {len(blk)} such variants (the tuner sees the "
            "innovations, not the reference).", ""]
    return out


#: windows [GNSS records per row] of the adaptive measurement noise tried on the loose walk (the final
#: standstill has about 18 held-out records: a window of 5 or 10 adapts inside it)
ADAPTIVE_WINDOWS = (5, 10, 20)


def walk_loose_adaptive(ds, ref, unseen, model, res, max_runs, verdicts) -> list:
    """The loose walk with the innovation-based adaptive measurement noise (``adaptive_r_window``,
    cpp/include/insnav/filter/adaptive_noise.hpp): the TOML with the window (hand + adaptive R) and its
    own tuning (tuned + adaptive R, the tuner running with the window on), and the tail tuning's factors
    above with the window switched on afterwards; the held-out figures as in the variants table, the
    horizontal error against the plain hand settings' (the TOML), and the adapted variance / the
    configured one on the held-out standing records (position rows, velocity rows)."""
    from insnav.filters.loose import loose_gnss_rows
    from tune_walk_loose_diag import standstill_start

    t_still = standstill_start(ref, res.t_split)
    figs = lambda r: [r["nis_per_row"]] + r["nees_total"]["pos_n_m"] + r["nees_total"]["vel_n_mps"]  # noqa: E731
    n_in = lambda v: sum(0.7 <= x <= 1.3 for x in v)  # noqa: E731
    j = lambda v: ", ".join(f"{x:.2f}" for x in v)  # noqa: E731

    def report(c):
        sol = insnav.run(ds, config=dataclasses.replace(c))
        reps = [holdout_report(sol, ref, a, b, keep_t=unseen, reference_model=model)
                for a, b in ((res.t_split, np.inf), (res.t_split, t_still), (t_still, np.inf))]
        conf = loose_gnss_rows(ds.gnss, c)[:, 7:13]
        t = np.asarray(sol.gnss_t, float)
        m = (t >= t_still) & (np.asarray(sol.gnss_status) == 1)
        f = (np.asarray(sol.gnss_sigma)[m] / conf[m]) ** 2
        return reps, (float(np.nanmean(f[:, :3])), float(np.nanmean(f[:, 3:])))

    (plain_hand, _, _), _ = report(res.base)
    (plain_tuned, _, _), _ = report(res.tuned)
    hand_fig = figs(plain_hand)
    out = ["The loose walk with the innovation-based adaptive measurement noise (`adaptive_r_window` N, "
           "cpp/include/insnav/filter/adaptive_noise.hpp; Mohamed & Schwarz 1999: each GNSS row's configured "
           "variance times clamp(sum(nu^2 - H P- H') / sum(R), 0.01, 1) over the last N applied fixes, so never "
           "above the configured R).  Rows: hand + adaptive R (the TOML with the window) against its own tuning "
           "(the tuner running with the window, same split and budget as above), and the tail tuning's factors "
           "above with the window switched on afterwards.  Figures: NIS/row, rms(err/sigma_total) N, E, D, vN, "
           "vE, vD over the held-out part; the error ratio is against the plain hand settings (the TOML, "
           f"horizontal RMS {plain_hand['hor_rms_m']:.4f} m; plain tuned {plain_tuned['hor_rms_m']:.4f} m).", "",
           "| N | settings | held out: figures | within 0.7-1.3 (of 7) | hand's outside brought within | walking / "
           "standing NIS/row | standing rms(err/sigma_total) N, E, D, vN, vE, vD | adapted / configured variance "
           "standing, pos / vel | horizontal error / plain hand |", "|---|---|---|---|---|---|---|---|---|"]
    best, nis_ws = None, []
    for n in ADAPTIVE_WINDOWS:
        r_a = tune(ds, dataclasses.replace(res.base, adaptive_r_window=n), holdout=HOLDOUT, max_runs=max_runs)
        for label, c in (("hand + adaptive R", r_a.base), ("tuned + adaptive R (retuned)", r_a.tuned),
                         ("tail-tuned factors + adaptive R", dataclasses.replace(res.tuned, adaptive_r_window=n))):
            (a, wk, st), (fp, fv) = report(c)
            fg = figs(a)
            outside = [i for i, x in enumerate(hand_fig) if not 0.7 <= x <= 1.3]
            fixed = sum(0.7 <= fg[i] <= 1.3 for i in outside)
            ratio = a["hor_rms_m"] / plain_hand["hor_rms_m"]
            out.append(f"| {n} | {label} | {j(fg)} | {n_in(fg)} | {fixed} of {len(outside)} | "
                       f"{wk['nis_per_row']:.2f} / {st['nis_per_row']:.2f} | {j(figs(st)[1:])} | {fp:.2f} / {fv:.2f} "
                       f"| {ratio:.3f} |")
            nis_ws.append((wk["nis_per_row"], st["nis_per_row"], ratio))
            if label != "hand + adaptive R":
                cand = (n_in(fg), -ratio, n, label, fg, ratio)
                best = cand if best is None or cand[:2] > best[:2] else best
    n_best, _, n, label, fg, ratio = best
    ok = n_best == 7 and ratio <= 1.0
    within_err = [x for x in nis_ws if x[2] <= 1.0]
    out += ["", f"Best adaptive variant: N = {n}, {label}: {n_best} of 7 figures within 0.7-1.3 ({j(fg)}), "
            f"horizontal error {ratio:.3f} x the plain hand settings'.  Over the {len(nis_ws)} rows the walking "
            f"NIS/row is {min(x[0] for x in nis_ws):.2f}-{max(x[0] for x in nis_ws):.2f} and the standing one "
            f"{min(x[1] for x in nis_ws):.2f}-{max(x[1] for x in nis_ws):.2f}; the {len(within_err)} rows with an "
            "error no worse than the plain hand settings' are the retuned ones"
            + (f" (standing NIS/row {', '.join(f'{x[1]:.2f}' for x in within_err)})" if within_err else "")
            + ".  Standing, the adapted variance goes towards its floor and the standing NIS stays well below 1: "
            "there the innovations are smaller than H P- H' alone (the table of the innovations above: P- "
            "follows the process noise tuned on walking), and R is all the adaptive form can lower.  Walking, "
            "H P- H' is several times R, so y^2 - H P- H' is a small difference of large numbers: over a short "
            "window its noise is about sqrt(2/N) (1 + H P- H'/R) R, the factor often reaches its floor, and the "
            "runs on the hand or the tail-tuned factors become overconfident while walking (their walking NIS/row "
            "above 1) with a larger error; the retuned runs keep the error but not the consistency.", ""]
    verdicts.append((f"rtklibexplorer walk, loose: adaptive measurement noise (best of N = "
                     f"{', '.join(map(str, ADAPTIVE_WINDOWS))}): every figure within 0.7-1.3 with the held-out error "
                     f"<= the hand settings' ({n_best} of 7; error ratio {ratio:.3f})", "met" if ok else "NOT met"))
    return out


def pvt_reference_model(x, ds, cfg, w) -> ReferenceModel:
    """The shifted NAV-PVT track as a reference of the antenna: its own error is the error of the shift (1-sigma:
    the sample standard deviation of the GPS, Galileo and BeiDou single-point offsets from NAV-PVT, per axis) and
    NAV-PVT's own accuracy (hAcc / sqrt(2) per horizontal axis, vAcc); velocity: the receiver's, whose sigma is
    the `.pos` file's sdvn, sdve, sdvu (the same receiver velocities) and whose lag is the walk's velocity_lag_s."""
    from insnav.io.gnss_files import read_pos_records

    comp = x["comp"]
    offs = np.array([comp[k]["mean_neu"] for k in comp if k.endswith("- NAV-PVT") and k.startswith("insnav SPP ")
                     and "+" not in k])
    s_neu = offs.std(axis=0, ddof=1)
    pvt = x["pvt"]
    week_s = x["week"] * 604800.0
    t_pvt = week_s + np.asarray(pvt["tow_s"], float) - ds.gps_time_offset_s
    h = np.asarray(pvt["h_acc_m"], float) / np.sqrt(2.0)
    sig_p = np.sqrt(np.column_stack([h, h, np.asarray(pvt["v_acc_m"], float)]) ** 2 + s_neu ** 2)
    rec = read_pos_records(w / "raw" / "gnss_1730_sf.pos")
    t_pos = rec.t_ref_s + np.asarray(rec.t_s, float) - ds.gps_time_offset_s
    sig_v = np.column_stack([np.interp(t_pvt, t_pos, np.asarray(rec.sigma_vel_n, float)[:, i]) for i in range(3)])
    lag = float(tomllib.loads((ROOT / "tests" / "data" / "walk_0827_loose.toml").read_text())["gnss"]["velocity_lag_s"])
    w_t, w_b = ReferenceModel.omega_from_imu(ds.imu)
    return ReferenceModel(lever_arm_b=np.asarray(ds.lever_arm_b, float), t=t_pvt, sigma_pos_n_m=sig_p,
                          sigma_vel_n_mps=sig_v, velocity_lag_s=lag, omega_t=w_t, omega_ib_b_radps=w_b,
                          source=f"the shift's uncertainty, the sample standard deviation of the {len(offs)} "
                                 f"single-system offsets N, E, U {', '.join(f'{v:.2f}' for v in s_neu)} m, with "
                                 "NAV-PVT's hAcc / sqrt(2) and vAcc; velocity: the `.pos` file's sdvn, sdve, sdvu "
                                 "of the same receiver velocities")


def walk_tight(lines, verdicts, max_runs, gm=True, only_still=False):
    """The tight walk: hand against tuned, the adaptive process noise (walk_tight_adaptive_q) and, with gm,
    the Gauss-Markov pseudorange states (walk_tight_gm)."""
    from insnav.io.rinex_dataset import load_rinex_run, rtklib_truth

    w = DATA / "rtklibexplorer_walk_0827"
    if not w.is_dir():
        lines += ["### Walk, tight", "", f"not run: {w} not found", ""]
        return
    from walk_reference_check import reference_experiment

    ds, cfg = load_rinex_run(w / "rinex_derived" / "gnss_1730.obs", w / "rinex_derived" / "gnss_1730.nav",
                             w / "raw" / "imu_1730.csv", ROOT / "tests" / "data" / "walk_0827.toml")
    cfg = dataclasses.replace(cfg, coupling="tight", filter="ekf")
    # the RTK .pos is offset by its base (about +5.8 N, +5.6 E, +9.1 U m, docs/results/tight_multignss.md):
    # the reference is the receiver's NAV-PVT track (ellipsoidal height) moved by the mean GPS + Galileo +
    # BeiDou single-point offset, as in tight_multignss.md
    x = reference_experiment(DATA)
    ref = rtklib_truth(x["pvt_shifted"], ds.gps_time_offset_s)
    sh = x["shift_neu"]
    model = pvt_reference_model(x, ds, cfg, w)
    res = compare("rtklibexplorer walk, tight on the RINEX (EKF)", ds, cfg, ref, lines, verdicts, max_runs=max_runs,
                  reference_model=model,
                  note="`tests/data/walk_0827.toml` (GPS L1 pseudorange and Doppler, the loader's consumer MEMS model "
                       "and pseudorange weighting) as the hand settings.  Reference: the RTK `.pos` sits about 8 m "
                       "from every single-point solution because of its base (docs/results/tight_multignss.md), so "
                       "the reference here is the receiver's NAV-PVT track moved by the mean GPS + Galileo + BeiDou "
                       f"single-point offset (N, E, U {sh[0]:+.2f}, {sh[1]:+.2f}, {sh[2]:+.2f} m; known to a few "
                       "metres, the spread of the single-system offsets).  Tuned and run with the `[robust]` row "
                       "screening off (docs/algorithms.md section 20), the hand settings with it on.")
    res, hand, tuned = res
    pr = res.scales.get("gnss_pos", float("nan"))
    lag = tuned["innovation_lag1"][0]
    over = max(tuned["nees"]["pos_n_m"])
    over_var = max(tuned["nees_demeaned"]["pos_n_m"])
    over_tot = max(tuned["nees_total"]["pos_n_m"])
    white = abs(lag) < 0.2
    lines += [f"The tuned pseudorange sigma is {pr:.3g} x the hand one; the tuned run's pseudorange innovations have "
              f"a lag-1 autocorrelation of {lag:.2f} ({'white' if white else 'NOT white'}: 0 for a right model, "
              "Mehra 1970)"
              + ("." if white else
                 ": the per-satellite pseudorange errors of this walk vary slowly (docs/results/tight_multignss.md), "
                 "and the innovation likelihood of a white-noise model sees only their record-to-record part, which "
                 "the tuned sigmas fit.")
              + f"  Largest tuned rms(err/sigma) of the position: {over:.2f} absolute (against the reference as it "
              f"is, {'above' if over > 1.3 else 'within'} 1.3; with the reference's own uncertainty, "
              f"rms(err/sqrt(sigma^2 + sigma_ref^2)) {over_tot:.2f}, but the reference's share of that variance is "
              f"{max(tuned['reference_variance_share_pos']):.2f} here), {over_var:.2f} with "
              f"the mean error removed (the reference's offset, constant, removed with it: "
              f"{'overconfident' if over_var > 1.3 else 'within 1.3'} on the error's variation over the held-out "
              "part)."
              + ("" if white or over_var <= 1.3 else
                 "  Consistency there needs time-correlated (Gauss-Markov) pseudorange error states: the next "
                 "section tunes them."), ""]
    if not only_still:
        lines += walk_tight_adaptive_q(ds, ref, model, res, hand, max_runs, verdicts)
    lines += walk_standstill(ds, cfg, ref, None, model, res, max_runs, verdicts, "tight", hand)
    if gm and not only_still:
        walk_tight_gm(ds, cfg, ref, lines, verdicts, max(200, max_runs), res, tuned, model)


#: starting point of the Gauss-Markov pseudorange states on the walk (the tuner scales both)
GM_START_SIGMA_M, GM_START_TAU_S = 3.0, 60.0


#: correlation times [s] held fixed (a prior of zero width) in the experiment of fixed_tau_lines
FIXED_TAUS_S = (10.0, 30.0, 120.0)


def fixed_tau_lines(ds, cfg, ref, model, white, hand) -> list:
    """The Gauss-Markov walk with the correlation time held at FIXED_TAUS_S (every other factor tuned as
    above, from the white-noise tuning's factors): does a prior on tau keep the hand held-out error?"""
    from insnav.calib.tune import default_parameters

    rows = []
    for tau in FIXED_TAUS_S:
        c = dataclasses.replace(cfg, pr_gm_sigma_m=GM_START_SIGMA_M, pr_gm_tau_s=tau)
        names = [p for p in default_parameters(ds, c) if p != "pr_gm_tau"]
        res = tune(ds, c, params=names, holdout=HOLDOUT, max_runs=200,
                   start={k: v for k, v in white.scales.items() if k in names})
        r = holdout_report(insnav.run(ds, config=dataclasses.replace(res.tuned)), ref, t_from=res.t_split,
                           reference_model=model)
        figs = [r["nis_per_row"]] + r["nees_total"]["pos_n_m"] + r["nees_total"]["vel_n_mps"]
        rows.append(f"| {tau:g} | {res.tuned.pr_gm_sigma_m:.2f} | {res.log_likelihood_tuned:.1f} | "
                    f"{r['innovation_lag1'][0]:.2f} | {r['hor_rms_m']:.4f} "
                    f"({r['hor_rms_m'] / hand['hor_rms_m']:.3f}) | "
                    f"{r['nis_per_row']:.2f} | {', '.join(f'{v:.2f}' for v in r['nees_total']['pos_n_m'])} | "
                    f"{', '.join(f'{v:.2f}' for v in r['nees_total']['vel_n_mps'])} | "
                    f"{', '.join(f'{v:.2f}' for v in r['nees_demeaned']['pos_n_m'])} | "
                    f"{sum(0.7 <= v <= 1.3 for v in figs)} of 7 |")
    return ["A prior on the correlation time, here of zero width: tau held at each value below, every other factor "
            "tuned as above (200 runs, from the white-noise tuning's factors); held-out figures (horizontal error "
            "with its ratio to the hand settings').", "",
            "| tau [s] | tuned sigma [m] | ln L (tuning part) | innovation lag-1, pseudorange rows | "
            "horizontal RMS error [m] (/ hand) | NIS/row | rms(err/sigma_total) N, E, D | vN, vE, vD | "
            "rms(err/sigma) N, E, D, mean error removed | NIS/row and sigma_total figures within 0.7-1.3 |",
            "|---|---|---|---|---|---|---|---|---|---|"] + rows + [""]


def walk_tight_gm(ds, cfg, ref, lines, verdicts, max_runs, white, white_report, model):
    """The tight walk tuned with per-satellite Gauss-Markov pseudorange error states (docs/algorithms.md,
    "Gauss-Markov pseudorange errors"), the search started from the white-noise tuning's factors
    (``white``); the hand settings stay today's (no such states)."""
    cfg_gm = dataclasses.replace(cfg, pr_gm_sigma_m=GM_START_SIGMA_M, pr_gm_tau_s=GM_START_TAU_S)
    title = "rtklibexplorer walk, tight on the RINEX (EKF), Gauss-Markov pseudorange states"
    load0 = os.getloadavg()[0]
    res = tune(ds, cfg_gm, holdout=HOLDOUT, max_runs=max_runs, start=dict(white.scales))
    reps = [holdout_report(insnav.run(ds, config=dataclasses.replace(c)), ref, t_from=res.t_split,
                           reference_model=model) for c in (cfg, res.tuned)]
    hand, tuned = reps
    t = res.tuned
    lines += [f"### {title}", "",
              "As above, with one first-order Gauss-Markov pseudorange error state per satellite (`pr_gm_sigma_m`, "
              f"`pr_gm_tau_s`, starting at {GM_START_SIGMA_M:g} m and {GM_START_TAU_S:g} s; the factors pr_gm_sigma "
              "and pr_gm_tau), the search started from the white-noise tuning's factors above.  The hand column is "
              "the hand settings of the section above (no such states, `[robust]` screening on).", "",
              f"Tuned on t < {res.t_split:.1f} s: {res.runs} runs, {res.seconds:.1f} s (1-min load average "
              f"{load0:.1f} on 2 cores); ln L {res.log_likelihood_base:.1f} -> {res.log_likelihood_tuned:.1f} over "
              f"{res.records} records (white-noise tuning: {white.log_likelihood_tuned:.1f}).  Factors: "
              + ", ".join(f"{n} x {v:.3g}" for n, v in res.scales.items())
              + f": sigma {t.pr_gm_sigma_m:.3g} m, tau {t.pr_gm_tau_s:.3g} s.", "",
              "| held out (last 30 %) | hand | white-noise tuned | Gauss-Markov tuned |", "|---|---|---|---|"]
    rows = [("mean NIS per row (1 = consistent)", lambda r: fmt(r["nis_per_row"], 2)),
            ("ln L per record", lambda r: fmt(r["log_likelihood_per_record"], 2)),
            ("innovation lag-1 autocorrelation, pseudorange / rate rows",
             lambda r: ", ".join(f"{v:.2f}" for v in r["innovation_lag1"])),
            ("horizontal RMS error [m]", lambda r: fmt(r.get("hor_rms_m"), 4)),
            ("3-D RMS error [m]", lambda r: fmt(r.get("rms_3d_m"), 4))]
    rows += [(f"rms(err/sigma) {', '.join(ax)}", lambda r, k=k: ", ".join(f"{v:.2f}" for v in r["nees"][k]))
             for k, ax in AXES.items() if k in tuned.get("nees", {})]
    rows += [(f"rms(err/sigma) {', '.join(ax)}, each axis's mean error removed",
              lambda r, k=k: ", ".join(f"{v:.2f}" for v in r["nees_demeaned"][k]))
             for k, ax in AXES.items() if k in tuned.get("nees_demeaned", {})]
    lines += [f"| {name} | {f(hand)} | {f(white_report)} | {f(tuned)} |" for name, f in rows]
    lines += total_rows(hand, tuned, (hand, white_report, tuned))
    lines.append("")
    cons = [(n, v) for n, v in consistency_figures(tuned) if not n.startswith("rms(err/sigma) ")]
    inside = [n for n, v in cons if 0.7 <= v <= 1.3]
    r = tuned["hor_rms_m"] / hand["hor_rms_m"]
    verdicts.append((f"{title}: held-out horizontal error, tuned / hand = {r:.3f} (target <= 1)",
                     "met" if r <= 1.0 else "NOT met"))
    lines += fixed_tau_lines(ds, cfg, ref, model, white, hand)
    verdicts.append((f"{title}: NIS/row and position and velocity rms(err/sigma_total) within 0.7-1.3: "
                     f"{len(inside)} of "
                     f"{len(cons)} (" + "; ".join(f"{n} {v:.2f}" for n, v in cons) + ")",
                     "met" if len(inside) == len(cons) else "NOT met"))


#: windows of the adaptive process noise on the loose and the tight walk [applied fixes / epochs]
ADAPTIVE_Q_WINDOWS = (10, 20, 40)


def best_adaptive_q(best, n_figures, n_outside, coupling, hand_name, verdicts) -> list:
    """The best adaptive-Q variant's sentence and its verdict row (the walk, loose or tight).

    ``best``: (hand's outside figures brought within, or -1 when the error ratio is above 1; figures
    within; -ratio; N; label; figures; error ratio), the largest first three of the variants."""
    fixed_best, n_best, _, n, label, fg, ratio = best
    fg = ", ".join(f"{x:.2f}" for x in fg)
    verdicts.append((f"rtklibexplorer walk, {coupling}: adaptive process noise (best of N = "
                     f"{', '.join(map(str, ADAPTIVE_Q_WINDOWS))}): the hand settings' figures outside 0.7-1.3 "
                     f"brought within with the held-out error <= the hand settings' ({max(fixed_best, 0)} of "
                     f"{n_outside}; {n_best} of {n_figures} within; error ratio {ratio:.3f})",
                     "met" if fixed_best == n_outside and ratio <= 1.0 else "NOT met"))
    return ["", f"Best adaptive-Q variant (most of the hand settings' outside figures brought within at a held-out "
            f"error no worse than the hand settings'): N = {n}, {label}: {n_best} of {n_figures} figures within "
            f"0.7-1.3 ({fg}), {max(fixed_best, 0)} of the hand settings' {n_outside} outside ones, "
            f"horizontal error {ratio:.3f} x {hand_name}.", ""]


def walk_loose_adaptive_q(ds, ref, unseen, model, res, max_runs, verdicts) -> list:
    """The loose walk with the adaptive process noise (``adaptive_q_window``, cpp/include/insnav/filter/
    adaptive_noise.hpp; Mohamed & Schwarz 1999: the velocity and angle random walk variances times
    clamp(sum a_j |dx_b|^2 / sum tr(P- - P+)_bb, adaptive_q_min, adaptive_q_max) over the last N fixes):
    rows as in the adaptive-R table (hand + adaptive Q, its own tuning, the tail tuning's factors with the
    window on), the same held-out figures and verdict."""
    from tune_walk_loose_diag import standstill_start

    t_still = standstill_start(ref, res.t_split)
    figs = lambda r: [r["nis_per_row"]] + r["nees_total"]["pos_n_m"] + r["nees_total"]["vel_n_mps"]  # noqa: E731
    n_in = lambda v: sum(0.7 <= x <= 1.3 for x in v)  # noqa: E731
    j = lambda v: ", ".join(f"{x:.2f}" for x in v)  # noqa: E731

    def report(c):
        sol = insnav.run(ds, config=c)
        return [holdout_report(sol, ref, a, b, keep_t=unseen, reference_model=model)
                for a, b in ((res.t_split, np.inf), (res.t_split, t_still), (t_still, np.inf))]

    plain_hand, _, _ = report(res.base)
    hand_fig = figs(plain_hand)
    outside = [i for i, x in enumerate(hand_fig) if not 0.7 <= x <= 1.3]
    b = res.base
    out = ["The loose walk with the adaptive process noise (`adaptive_q_window` N, cpp/include/insnav/filter/"
           "adaptive_noise.hpp; Mohamed & Schwarz 1999, Q^ = K C_v K' over the window: the configured "
           "velocity and angle random walk variances each times clamp(sum a_j |dx_b|^2 / sum tr(P- - P+)_bb, "
           f"{b.adaptive_q_min:g}, {b.adaptive_q_max:g}) over the last N applied fixes, dx the update's state "
           "correction, a_j the factor it ran with).  Rows and figures as in the adaptive-R table; the "
           "error ratio is against the plain hand settings (horizontal RMS "
           f"{plain_hand['hor_rms_m']:.4f} m).", "",
           "| N | settings | held out: figures | within 0.7-1.3 (of 7) | hand's outside brought within | walking / "
           "standing NIS/row | standing rms(err/sigma_total) N, E, D, vN, vE, vD | horizontal error / plain hand |",
           "|---|---|---|---|---|---|---|---|"]
    best = None
    for n in ADAPTIVE_Q_WINDOWS:
        r_a = tune(ds, dataclasses.replace(res.base, adaptive_q_window=n), holdout=HOLDOUT, max_runs=max_runs)
        for label, c in (("hand + adaptive Q", r_a.base), ("tuned + adaptive Q (retuned)", r_a.tuned),
                         ("tail-tuned factors + adaptive Q", dataclasses.replace(res.tuned, adaptive_q_window=n))):
            a, wk, st = report(c)
            fg = figs(a)
            fixed = sum(0.7 <= fg[i] <= 1.3 for i in outside)
            ratio = a["hor_rms_m"] / plain_hand["hor_rms_m"]
            out.append(f"| {n} | {label} | {j(fg)} | {n_in(fg)} | {fixed} of {len(outside)} | "
                       f"{wk['nis_per_row']:.2f} / {st['nis_per_row']:.2f} | {j(figs(st)[1:])} | {ratio:.3f} |")
            if label != "hand + adaptive Q":
                cand = (fixed if ratio <= 1.0 else -1, n_in(fg), -ratio, n, label, fg, ratio)
                best = cand if best is None or cand[:3] > best[:3] else best
    return out + best_adaptive_q(best, 7, len(outside), "loose", "the plain hand settings'", verdicts)


def walk_tight_adaptive_q(ds, ref, model, res, hand, max_runs, verdicts) -> list:
    """The tight walk with the adaptive process noise of the EKF (``adaptive_q_window``, the loose walk's
    form, cpp/include/insnav/filter/adaptive_noise.hpp; Mohamed & Schwarz 1999, K C_v K' against K S K' over
    the last N applied epochs): per window N (ADAPTIVE_Q_WINDOWS) the hand settings with the window on, the
    settings tuned with the window on (tuned as the other variants: first 70 %), and the white-noise tuning's
    factors with the window on; the held-out consistency figures of ``compare`` (NIS/row, rms(err/
    sigma_total) N, E, D, vN, vE, vD) and the horizontal error against the hand settings' (``hand``,
    compare's held-out report of ``res.base``); verdict: the best variant against the target."""
    cons = lambda r: consistency_figures(r)  # noqa: E731
    j = lambda v: ", ".join(f"{x:.2f}" for x in v)  # noqa: E731
    hand_c = cons(hand)
    names = [n for n, _ in hand_c]
    outside = [i for i, (_, x) in enumerate(hand_c) if not 0.7 <= x <= 1.3]
    b = res.base
    out = ["The tight walk with the adaptive process noise (`adaptive_q_window` N, the loose walk's form: the "
           "configured velocity and angle random walk variances each times clamp(sum a_j |dx_b|^2 / sum "
           f"tr(P- - P+)_bb, {b.adaptive_q_min:g}, {b.adaptive_q_max:g}) over the last N applied epochs, dx the "
           "epoch's state correction, a_j the factor it ran with).  Figures on the held-out 30 %: "
           + ", ".join(names) + f"; the error ratio is against the hand settings above (horizontal RMS "
           f"{hand['hor_rms_m']:.4f} m, figures {j(x for _, x in hand_c)}).", "",
           "| N | settings | held out: figures | within 0.7-1.3 (of " + str(len(hand_c)) + ") | hand's outside "
           "brought within | final Q factors vel, att | horizontal error / hand |", "|---|---|---|---|---|---|---|"]
    best = None
    for n in ADAPTIVE_Q_WINDOWS:
        r_a = tune(ds, dataclasses.replace(res.base, adaptive_q_window=n), holdout=HOLDOUT, max_runs=max_runs)
        for label, c in (("hand + adaptive Q", r_a.base), ("tuned + adaptive Q (retuned)", r_a.tuned),
                         ("tail-tuned factors + adaptive Q", dataclasses.replace(res.tuned, adaptive_q_window=n))):
            sol = insnav.run(ds, config=dataclasses.replace(c))
            a = holdout_report(sol, ref, t_from=res.t_split, reference_model=model)
            fg = [x for _, x in cons(a)]
            n_in = sum(0.7 <= x <= 1.3 for x in fg)
            fixed = sum(0.7 <= fg[i] <= 1.3 for i in outside)
            ratio = a["hor_rms_m"] / hand["hor_rms_m"]
            qf = sol.summary.get("process_noise_scale", [np.nan, np.nan])
            out.append(f"| {n} | {label} | {j(fg)} | {n_in} | {fixed} of {len(outside)} | {j(qf)} | {ratio:.3f} |")
            if label != "hand + adaptive Q":
                cand = (fixed if ratio <= 1.0 else -1, n_in, -ratio, n, label, fg, ratio)
                best = cand if best is None or cand[:3] > best[:3] else best
    return out + best_adaptive_q(best, len(hand_c), len(outside), "tight", "the hand settings'", verdicts)


# --------------------------------------------------------------------------- the walker's standstill

#: the standstill detector's threshold on the walk (ins/standstill.hpp, with its default window and per-sample
#: sigmas): this consumer IMU's per-sample noise is above the defaults' 0.02 m/s^2 and 0.115 deg/s, so its
#: statistic at rest has a median of about 34 instead of 6 and the default threshold 18 finds no standstill;
#: 100 is about 3x that median, as 18 is 3x the white-noise mean (the walking statistic stays above 10^4)
WALK_ZUPT_THRESHOLD = 100.0
#: standstill levels of the process noise shown as a sensitivity (walk_standstill): chosen on the held-out
#: part, so not the verdict's; the verdict uses the level fixed before the run (standstill_level)
STANDSTILL_Q_GRID = (0.3, 0.1, 0.03, 0.01)
#: the bias-instability factor of the diagnostic row of walk_standstill (the whole run, not a setting)
DIAG_BIAS_FACTOR = 0.01


def standstill_level(res) -> float:
    """The a-priori standstill level of the tuned process noise: back to the hand (the sensor's) velocity and
    angle random walk variances, the geometric mean of the two, 1 / (f_acc_vrw f_gyro_arw) (the tuned factors
    are on the sigmas).  The tail split's tuning part has no standstill, so its likelihood cannot tune the
    level (the factor standstill_q is flat there); the tuned excess over the sensor's noise is gait and hand
    swing, which a walker standing still does not have."""
    return 1.0 / (res.scales.get("acc_vrw", 1.0) * res.scales.get("gyro_arw", 1.0))


def walk_standstill_detector(ds, cfg, ref) -> list:
    """The SHOE statistic (ins/standstill.hpp) over the walk's IMU: the detected standing time with the
    default threshold and WALK_ZUPT_THRESHOLD against the `.pos` speed below STILL_MPS."""
    from insnav.filters.constraints import standstill_statistic
    from tune_walk_loose_diag import STILL_MPS

    t, dth, dv = (np.asarray(a, float) for a in (ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b))
    c = cfg.constraints
    T = standstill_statistic(ds, c, t, dth, dv)
    tr = np.asarray(ref.t, float)
    inside = (tr >= t[0] + c.zupt_window_s) & (tr <= t[-1])
    sp = np.hypot(ref.v_n[:, 0], ref.v_n[:, 1])
    still_ref = inside & (sp < STILL_MPS)
    dt_ref = float(np.median(np.diff(tr)))
    dt = float(np.median(np.diff(t)))
    Tr = T[np.clip(np.searchsorted(t, tr, side="right") - 1, 0, t.size - 1)]
    rows = []
    for g in (c.zupt_threshold, WALK_ZUPT_THRESHOLD):
        det = Tr < g
        rows.append(f"| {g:g} | {float(np.sum(T < g)) * dt:.1f} | {int((det & still_ref).sum())} | "
                    f"{int((det & inside & ~still_ref).sum())} | {int((~det & still_ref).sum())} |")
    q = lambda m, p: np.percentile(Tr[m], p)  # noqa: E731
    return [f"The standstill detector (`ins/standstill.hpp`, the SHOE statistic of Skog et al. 2010, window "
            f"{c.zupt_window_s:g} s, per-sample sigmas {c.zupt_sigma_f_mps2:g} m/s^2 and {c.zupt_sigma_w_dps:g} "
            f"deg/s, the defaults) over the walk's IMU ({t[-1] - t[0]:.1f} s): the `.pos` has "
            f"{int(still_ref.sum())} epochs ({still_ref.sum() * dt_ref:.1f} s) below {STILL_MPS:g} m/s inside the "
            "IMU's span, all in the final standstill (the first standstill of the `.pos` ends before the IMU log "
            f"starts).  Statistic at those epochs: median {q(still_ref, 50):.0f} (5 % {q(still_ref, 5):.0f}); at "
            f"the walking ones: smallest {Tr[inside & ~still_ref].min():.0f}, 1 % {q(inside & ~still_ref, 1):.0f}.  "
            f"The default threshold {c.zupt_threshold:g} (3x the white-noise mean 6) finds nothing: this consumer "
            "IMU's noise at rest is above the default per-sample sigmas; the threshold "
            f"{WALK_ZUPT_THRESHOLD:g} (about 3x the median at rest, the window and sigmas unchanged) is the one "
            "used below.", "",
            "| threshold | detected standing [s of IMU samples] | `.pos` standing epochs detected | walking epochs "
            "detected (false alarms) | standing epochs missed |", "|---|---|---|---|---|"] + rows + [""]


def walk_standstill(ds, cfg, ref, unseen, model, res, max_runs, verdicts, coupling, hand_rep=None) -> list:
    """The walk with the standstill modelled (loose: ZUPT / ZARU updates while the detector says stationary,
    ``[constraints] use = ["zupt"]``; both: the standstill level of the process noise, ``standstill_q_scale``,
    engine/loose_engine.hpp and engine/tight_engine.hpp): rows tuned as ``compare`` (same split and budget),
    held-out figures of ``consistency_figures``, the walking / standing split at the final standstill, the
    error against the hand settings (and, loose, hand + ZUPT); verdict on the a-priori level
    (standstill_level)."""
    from tune_walk_loose_diag import standstill_start

    t_still = standstill_start(ref, res.t_split)
    kw = dict(keep_t=unseen) if unseen is not None else {}
    cons = lambda r: [x for _, x in consistency_figures(r)]  # noqa: E731
    j = lambda v: ", ".join(f"{x:.2f}" for x in v)  # noqa: E731

    def report(c):
        sol = insnav.run(ds, config=dataclasses.replace(c))
        return [holdout_report(sol, ref, a, b, reference_model=model, **kw)
                for a, b in ((res.t_split, np.inf), (res.t_split, t_still), (t_still, np.inf))]

    hand = hand_rep or report(res.base)[0]
    hand_c = cons(hand)
    outside = [i for i, x in enumerate(hand_c) if not 0.7 <= x <= 1.3]
    con = dataclasses.replace(res.base.constraints, zupt_threshold=WALK_ZUPT_THRESHOLD)
    with_level = lambda c, s: dataclasses.replace(c, constraints=dataclasses.replace(  # noqa: E731
        c.constraints, standstill_q_scale=s))
    rows = []
    if coupling == "loose":
        zcon = dataclasses.replace(con, use=["zupt"])
        hz = dataclasses.replace(res.base, constraints=zcon)
        rz = tune(ds, hz, holdout=HOLDOUT, max_runs=max_runs)
        s0 = standstill_level(rz)
        rows += [("hand + ZUPT", hz, None), ("tuned with ZUPT (retuned)", rz.tuned, None),
                 ("tail-tuned factors + ZUPT", dataclasses.replace(res.tuned, constraints=zcon), None),
                 (f"tuned with ZUPT + standstill level {s0:.3g} (a priori)", with_level(rz.tuned, s0), "verdict")]
        rows += [(f"tuned with ZUPT + standstill level {s:g} (sensitivity)", with_level(rz.tuned, s), None)
                 for s in STANDSTILL_Q_GRID]
        # what holds P- up at rest: the bias instabilities (their Gauss-Markov driving noise), here cut over the
        # whole run (a diagnostic, not a setting: the walking part gets overconfident)
        diag = scaled_config(rz.tuned, rz.tuned.imu, {"gyro_bias": DIAG_BIAS_FACTOR, "acc_bias": DIAG_BIAS_FACTOR})
        rows.append((f"diagnostic: tuned with ZUPT + level {min(STANDSTILL_Q_GRID):g}, bias instabilities x "
                     f"{DIAG_BIAS_FACTOR:g} over the whole run", with_level(diag, min(STANDSTILL_Q_GRID)), "diag"))
        base_t = rz
    else:
        base_t = res
        s0 = standstill_level(res)
        tcon = dataclasses.replace(res.tuned.constraints, zupt_threshold=WALK_ZUPT_THRESHOLD)
        tuned = dataclasses.replace(res.tuned, constraints=tcon)
        rows += [(f"tuned + standstill level {s0:.3g} (a priori)", with_level(tuned, s0), "verdict")]
        rows += [(f"tuned + standstill level {s:g} (sensitivity)", with_level(tuned, s), None)
                 for s in STANDSTILL_Q_GRID]
    # the tuner with the level as a factor (started at the a-priori level): the tail split cannot move it
    start = with_level(base_t.base, s0)
    rq = tune(ds, start, holdout=HOLDOUT, max_runs=max_runs)
    rows.append((f"tuned with the level as a factor (started at {s0:.3g}; tuned level "
                 f"{rq.tuned.constraints.standstill_q_scale:.3g})", rq.tuned, None))
    hz_rep = None
    out_rows, best, level_figs, diag_figs = [], None, {}, None
    for label, c, role in rows:
        a, wk, st = report(c)
        if "standstill level" in label or label.startswith("tuned with ZUPT (retuned)") or label == "tuned (no level)":
            level_figs[label] = cons(a) + [wk["nis_per_row"], st["nis_per_row"]] + cons(st)[1:7]
        if role == "diag":
            diag_figs = (cons(a), st["nis_per_row"], cons(st)[1:7], wk["nis_per_row"])
            diag_ratio = a["hor_rms_m"] / hand["hor_rms_m"]
        if label == "hand + ZUPT":
            hz_rep = a
        fg = cons(a)
        n_in = sum(0.7 <= x <= 1.3 for x in fg)
        fixed = sum(0.7 <= fg[i] <= 1.3 for i in outside)
        ratio = a["hor_rms_m"] / hand["hor_rms_m"]
        rz_ = "" if hz_rep is None else f" | {a['hor_rms_m'] / hz_rep['hor_rms_m']:.3f}"
        out_rows.append(f"| {label} | {j(fg)} | {n_in} | {fixed} of {len(outside)} | "
                        f"{wk['nis_per_row']:.2f} / {st['nis_per_row']:.2f} | {j(cons(st)[1:7])} | {ratio:.3f}"
                        + (rz_ if coupling == "loose" else "") + " |")
        if role == "verdict":
            best = (label, fg, n_in, fixed, ratio)
    title = f"rtklibexplorer walk, {coupling}: the walker's standstill modelled"
    head = ["| settings | held out: figures | within 0.7-1.3 (of " + str(len(hand_c)) + ") | hand's outside brought "
            "within | walking / standing NIS/row | standing rms(err/sigma_total) N, E, D, vN, vE, vD | horizontal "
            "error / hand" + (" | / hand + ZUPT |" if coupling == "loose" else " |"),
            "|---" * (7 + (coupling == "loose")) + "|"]
    intro = [f"The {coupling} walk with the walker's standstill modelled: "
             + ("ZUPT and ZARU updates (`[constraints] use = [\"zupt\"]`, 10 Hz, meas/vehicle.hpp) while the "
                f"detector (threshold {WALK_ZUPT_THRESHOLD:g}) says stationary, and " if coupling == "loose" else
                f"(no ZUPT: the tight engine takes no constraint events) the detector (threshold "
                f"{WALK_ZUPT_THRESHOLD:g}) at each epoch and ")
             + "the standstill level of the process noise (`[constraints] standstill_q_scale` s: the velocity and "
             "angle random walk PSDs times s while stationary; engine/" + coupling + "_engine.hpp).  Tuned as above "
             "(the last 30 % held out, same budget).  The a-priori level s = 1 / (f_acc_vrw f_gyro_arw) of the "
             "tuning's factors returns the standing random walks to the hand (sensor) level: the tuned excess is "
             "gait and hand swing (`standstill_level` in this script); the tuning part has no standstill, so the "
             "likelihood cannot tune s (last row: the tuner with s as a factor).  Figures: "
             + ", ".join(n for n, _ in consistency_figures(hand)) + f"; hand: {j(hand_c)}"
             + (f"; the error ratios against the hand settings (horizontal RMS {hand['hor_rms_m']:.4f} m)"
                + (" and hand + ZUPT" if coupling == "loose" else "")) + ".", ""]
    label, fg, n_in, fixed, ratio = best
    met = fixed == len(outside) and n_in == len(fg) and ratio <= 1.0
    verdicts.append((f"{title} ({label}): every figure within 0.7-1.3 ({n_in} of {len(fg)}; the hand settings' "
                     f"outside ones {fixed} of {len(outside)}) with the held-out error <= the hand settings' (ratio "
                     f"{ratio:.3f})", "met" if met else "NOT met"))
    spread = (max(abs(x - y) for v in level_figs.values() for w in level_figs.values() for x, y in zip(v, w))
              if len(level_figs) > 1 else float("nan"))
    why = (f"  Over the standstill levels {j(sorted(set([s0] + list(STANDSTILL_Q_GRID))))} the figures (held out, "
           f"walking / standing NIS/row, standing figures) move by at most {spread:.2f}: the velocity and angle "
           "random walks are not what keeps P- above the innovations at rest here"
           + ("; ZUPT pins the velocity at 10 Hz" if coupling == "loose" else
              "; the pseudorange rates hold the velocity (the random walks are a small part of P-'s growth, "
              "tests/test_adaptive_q_tight.py)") + ".")
    if diag_figs is not None:
        fa, ns, fs, nw = diag_figs
        why += (f"  With the bias instabilities x {DIAG_BIAS_FACTOR:g} over the whole run (diagnostic row) the standing "
                f"NIS/row is {ns:.2f} and the standing figures {j(fs)} (walking NIS/row {nw:.2f}, held-out error "
                f"{diag_ratio:.3f} x the hand settings'): the Gauss-Markov bias driving noise tuned on walking holds "
                "P- up at rest more than the random walks do (cut over the whole run it also makes the walking part "
                "overconfident); a standstill level of the bias PSDs is not implemented.")
    return intro + head + out_rows + ["", f"A-priori level: {label}: {n_in} of {len(fg)} figures within 0.7-1.3 "
                                      f"({j(fg)}), horizontal error {ratio:.3f} x the hand settings'." + why, ""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=None)
    ap.add_argument("--seeds", type=int, default=4, help="simulated drives tuned together (default %(default)s)")
    ap.add_argument("--max-runs", type=int, default=200, help="evaluations per tuning in the simulation")
    ap.add_argument("--real-max-runs", type=int, default=60, help="runs per tuning on the real data")
    ap.add_argument("--skip-sim", action="store_true")
    ap.add_argument("--only", choices=("walk-loose", "walk-tight", "walk-tight-q", "walk-still"), default=None,
                    help="run only that real-data section (no simulation, no KF-GINS; for development); "
                         "walk-tight-q: the tight walk without its Gauss-Markov section; walk-still: the loose and "
                         "tight walk's hand / tuned comparison and the standstill sections only")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    lines = ["# Noise tuning by the innovation likelihood (`insnav tune`)", "",
             f"Commit `{git_commit()}`; command `{COMMAND}`"
             + ("" if argv is None and len(sys.argv) <= 3 else f" (this run: `{' '.join(sys.argv[1:])}`)") + ".", "",
             "The tuner (docs/algorithms.md section 20) multiplies the noise settings by factors (gyro_arw, acc_vrw, "
             "gyro_bias, acc_bias: all axes of each; gnss_pos, gnss_vel: the data's GNSS sigmas) and maximises "
             "the innovation log-likelihood sum_k -(nu' S^-1 nu + ln det S)/2 of the first 70 % of the data by "
             "Nelder-Mead in log space, one C++ run per evaluation.  The last 30 % are held out: hand (or wrong) "
             "and tuned settings run over all the data and are compared there.", ""]
    verdicts = []
    if not args.skip_sim and not args.only:
        simulation(list(range(1, args.seeds + 1)), args.max_runs, lines, verdicts)
    lines += ["## 2. Real data: hand settings against tuned", ""]
    if not args.only:
        kfgins(lines, verdicts, args.real_max_runs)
    still = args.only == "walk-still"
    if args.only in (None, "walk-loose", "walk-still"):
        walk_loose(lines, verdicts, args.real_max_runs, only_still=still)
    if args.only in (None, "walk-tight", "walk-tight-q", "walk-still"):
        walk_tight(lines, verdicts, args.real_max_runs, gm=args.only != "walk-tight-q", only_still=still)
    lines += ["## Verdicts", "", "| target | verdict |", "|---|---|"]
    lines += [f"| {t} | {v} |" for t, v in verdicts]
    lines += ["", f"Whole script: {time.perf_counter() - t0:.0f} s."]
    text = "\n".join(lines) + "\n"
    if args.out:
        Path(args.out).write_text(with_stamp(text, args.out))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
