"""Noise tuning by the innovation likelihood (``insnav tune``, insnav.calib.tune): does it find
the true noise, and does it help on real data?

1. Simulation (a car, insnav's simulator; the filter's model family matches the simulated
   errors): from noise settings wrong by 10x up and 10x down (every factor), the tuned factors
   against the truth (1), and rms(error/sigma) per axis on the held-out 30 % pooled over the
   seeds, before and after.  Targets: factors within 25 %, rms(error/sigma) within 0.85-1.15.
2. Real data, hand settings against tuned (tuned on the first 70 %, reported on the last 30 %):
   the KF-GINS track (loose EKF, 21 states, KF-GINS's YAML noise as the hand settings; also the
   time of the tuning), the rtklibexplorer walk loosely coupled on the RTK .pos and tightly
   coupled on the RINEX (bench/walk_0827_loose.toml, bench/walk_0827.toml).  Targets: held-out
   error no worse than the hand settings', and consistency (mean NIS per row, rms(error/sigma))
   within 0.7-1.3 where the hand settings are outside it.

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
from insnav.calib.tune import holdout_report, scaled_config, tune  # noqa: E402
from insnav.config import ImuNoise, RunConfig  # noqa: E402

COMMAND = "python3 bench/tune_check.py --out docs/results/tune.md"
DATA = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data"))
HOLDOUT = 0.3

#: the simulated car: seed000-car's 900 s drive without outages, 10 Hz GNSS; biases purely first-order
#: Gauss-Markov (no turn-on constant), so the filter's bias model is the simulated one and the true
#: factors are all 1
SIM = {
    "extends": "seed000-car", "name": "tune-car",
    "description": "car, MEMS IMU 200 Hz (Gauss-Markov biases), GNSS 10 Hz 0.5 m / 0.05 m/s",
    "run": {"gate_prob": 0.9999},
    "imu": {"rate_hz": 200.0,
            "gyro": {"bias_sigma_dph": 0.0, "gm_sigma_dph": 10.0, "gm_tau_s": 300.0, "arw_deg_per_sqrth": 0.2},
            "accel": {"bias_sigma_mg": 0.0, "gm_sigma_mg": 2.0, "gm_tau_s": 300.0, "vrw_mps_per_sqrth": 0.1}},
    "gnss": {"rate_hz": 10.0, "sigma_h_m": 0.5, "sigma_v_m": 1.0, "sigma_vel_mps": 0.05, "outages": []},
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
              f"Scenario: `seed000-car`'s 900 s drive without outages (stops, turns, a U-turn, grades), 200 Hz MEMS "
              f"IMU with ARW 0.2 deg/sqrt(h), VRW 0.1 m/s/sqrt(h), Gauss-Markov biases 10 deg/h and 2 mg (tau 300 s, "
              f"no turn-on constant: the filter's bias model is then the simulated one), GNSS 10 Hz with white "
              f"noise 0.5 m horizontal, 1 m vertical, 0.05 m/s, sigmas in the data equal to it.  The true factors "
              f"are all 1 (the filter's model from the simulator's, `ImuNoise.from_dataset_model`).  Loose EKF, "
              f"15 states, gate on.  Every factor starts at 10 (or 0.1); tuned on the first "
              f"{1 - HOLDOUT:.0%} of each run (at most {max_runs} runs), reported on the last {HOLDOUT:.0%}.  "
              f"Seeds {', '.join(map(str, seeds))}.", ""]
    rows = {}
    parts = {("truth",): [], ("10x",): [], ("0.1x",): [], ("tuned", "10x"): [], ("tuned", "0.1x"): []}
    nis = {k: [] for k in parts}
    timing = []
    for seed in seeds:
        ds = insnav.simulate(SIM, seed=seed)
        truth_noise = ImuNoise.from_dataset_model(ds.imu_model)
        cfg0 = RunConfig(filter="ekf", imu=truth_noise)
        for start, f in (("10x", 10.0), ("0.1x", 0.1)):
            wrong = scaled_config(cfg0, truth_noise, {n: f for n in names})
            t0 = time.perf_counter()
            res = tune(ds, wrong, params=names, holdout=HOLDOUT, max_runs=max_runs)
            timing.append((time.perf_counter() - t0, res.runs))
            rows[(seed, start)] = {n: res.scales[n] * f for n in names}  # tuned factor on the truth
            for key, c in (((start,), wrong), (("tuned", start), res.tuned)):
                sol = insnav.run(ds, config=dataclasses.replace(c))
                parts[key].append(errs_over(sol, ds.truth, res.t_split))
                nis[key].append(holdout_report(sol, None, t_from=res.t_split)["nis_per_row"])
        sol = insnav.run(ds, config=dataclasses.replace(cfg0))
        parts[("truth",)].append(errs_over(sol, ds.truth, res.t_split))
        nis[("truth",)].append(holdout_report(sol, None, t_from=res.t_split)["nis_per_row"])
    lines += ["Tuned factor on the truth (1 = found the simulated noise; target within 0.75-1.25):", "",
              "| seed | start | " + " | ".join(names) + " | within 25 % |", "|---" * (len(names) + 3) + "|"]
    allin = True
    for (seed, start), sc in rows.items():
        ok = all(0.75 <= v <= 1.25 for v in sc.values())
        allin &= ok
        lines.append(f"| {seed} | {start} | " + " | ".join(f"{sc[n]:.3f}" for n in names) + f" | {'yes' if ok else 'no'} |")
    worst = {n: max(abs(rows[k][n] - 1.0) for k in rows) for n in names}
    lines += ["", "Largest deviation from 1 per factor: " + ", ".join(f"{n} {100 * v:.0f} %" for n, v in worst.items())
              + ".", ""]
    lines += [f"rms(error/sigma) on the held-out {HOLDOUT:.0%}, pooled over the seeds (target 0.85-1.15 after "
              "tuning), and the mean NIS per row of the held-out GNSS records:", "",
              "| settings | " + " | ".join(a for k in AXES for a in AXES[k]) + " | NIS/row | all within 0.85-1.15 |",
              "|---" * 12 + "|"]
    label = {("truth",): "true noise", ("10x",): "start 10x", ("0.1x",): "start 0.1x",
             ("tuned", "10x"): "tuned from 10x", ("tuned", "0.1x"): "tuned from 0.1x"}
    tuned_ok = True
    for key in parts:
        r = pooled_nees(parts[key])
        vals = np.concatenate([r[k] for k in AXES])
        ok = bool(np.all((vals >= 0.85) & (vals <= 1.15)))
        if key[0] == "tuned":
            tuned_ok &= ok
        lines.append(f"| {label[key]} | " + " | ".join(f"{v:.2f}" for v in vals)
                     + f" | {np.mean(nis[key]):.2f} | {'yes' if ok else 'no'} |")
    mean_t = np.mean([t for t, _ in timing])
    mean_r = np.mean([r for _, r in timing])
    lines += ["", f"Tuning: {mean_r:.0f} runs and {mean_t:.1f} s per tuning on average (15 min of data, 70 % of "
              "it per run).", ""]
    verdicts.append(("simulation: tuned factors within 25 % of the truth (every seed, both starts)",
                     "met" if allin else "NOT met"))
    verdicts.append(("simulation: rms(error/sigma) within 0.85-1.15 on every axis after tuning",
                     "met" if tuned_ok else "NOT met"))


# --------------------------------------------------------------------------- 2. real data

def compare(title, ds, cfg, reference, lines, verdicts, *, max_runs, keep_t=None, note="", timing=False):
    """Tune on the first 70 %, report hand vs tuned on the last 30 %."""
    load0 = os.getloadavg()[0]
    res = tune(ds, cfg, holdout=HOLDOUT, max_runs=max_runs)
    load1 = os.getloadavg()[0]
    reps = []
    for c in (res.base, res.tuned):
        sol = insnav.run(ds, config=dataclasses.replace(c))
        reps.append(holdout_report(sol, reference, t_from=res.t_split, keep_t=keep_t))
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
              f"{fmt(tuned['log_likelihood_per_record'], 2)} |"]
    if reference is not None:
        lines += [f"| reference epochs | {hand.get('epochs', 0)} | {tuned.get('epochs', 0)} |",
                  f"| horizontal RMS error [m] | {fmt(hand.get('hor_rms_m'), 4)} | {fmt(tuned.get('hor_rms_m'), 4)} |",
                  f"| 3-D RMS error [m] | {fmt(hand.get('rms_3d_m'), 4)} | {fmt(tuned.get('rms_3d_m'), 4)} |"]
        for k, ax in AXES.items():
            a, b = hand.get("nees", {}).get(k), tuned.get("nees", {}).get(k)
            if a is None:
                continue
            lines.append(f"| rms(err/sigma) {', '.join(ax)} | {', '.join(f'{v:.2f}' for v in a)} | "
                         f"{', '.join(f'{v:.2f}' for v in b)} |")
    lines.append("")
    # verdicts
    if reference is not None and "hor_rms_m" in hand:
        r = tuned["hor_rms_m"] / hand["hor_rms_m"]
        verdicts.append((f"{title}: held-out horizontal error, tuned / hand = {r:.3f} (target <= 1)",
                         "met" if r <= 1.0 else "NOT met"))
    cons = [("NIS/row", hand["nis_per_row"], tuned["nis_per_row"])]
    for k, ax in AXES.items():
        a, b = hand.get("nees", {}).get(k), tuned.get("nees", {}).get(k)
        if a is not None:
            cons += [(f"rms(err/sigma) {n}", x, y) for n, x, y in zip(ax, a, b)]
    outside = [(n, x, y) for n, x, y in cons if not 0.7 <= x <= 1.3]
    fixed = [(n, x, y) for n, x, y in outside if 0.7 <= y <= 1.3]
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
    return res


def kfgins(lines, verdicts, max_runs):
    from insnav.io.kfgins import read_kfgins_nav
    from insnav.io.kfgins_dataset import load_kfgins

    d = DATA / "kfgins" / "sim"
    if not d.is_dir():
        lines += ["### KF-GINS track", "", f"not run: {d} not found", ""]
        return
    ds, cfg = load_kfgins(d / "kf-gins-sim.yaml", d / "Leador-A15-sim.txt.xz", d / "GNSS-RTK-sim.txt", layout=21)
    truth = read_kfgins_nav(d / "truth-sim.nav.xz")
    compare("KF-GINS track (loose EKF-21)", ds, cfg, truth, lines, verdicts, max_runs=max_runs, timing=True,
            note="`../shared/data/kfgins/sim`: the real KF-GINS RTK track (1 Hz) with a synthesised 200 Hz "
                 "navigation-grade IMU, 56 min; hand settings = KF-GINS's YAML (`insnav run --format kfgins`); "
                 "reference = its truth file (every IMU epoch after the split).")


def walk_loose(lines, verdicts, max_runs):
    from insnav.io.rinex_dataset import rtklib_truth

    w = DATA / "rtklibexplorer_walk_0827"
    if not w.is_dir():
        lines += ["### Walk, loose", "", f"not run: {w} not found", ""]
        return
    d = tomllib.loads((ROOT / "bench" / "walk_0827_loose.toml").read_text())
    pos = w / "raw" / "gnss_1730_sf.pos"
    ds, cfg = insnav.load_csv_dataset(w / "raw" / "imu_1730.csv", pos, d)
    ref = rtklib_truth(str(pos), ds.gps_time_offset_s)
    seen = np.asarray(ds.gnss.t_valid)
    unseen = np.setdiff1d(np.round(np.asarray(ref.t), 3), np.round(seen, 3))
    compare("rtklibexplorer walk, loose on the RTK .pos (EKF)", ds, cfg, ref, lines, verdicts, max_runs=max_runs,
            keep_t=unseen,
            note="`bench/walk_0827_loose.toml` (consumer grade, `[gnss] decimate = 4`: 1 fix in 4 to the filter, "
                 "position sigma floor 5 cm, velocity sigma 0.1 m/s) as the hand settings; reference = the RTK "
                 "`.pos` at the epochs the filter did not see (antenna position; the 5 cm lever arm is left in).")


def walk_tight(lines, verdicts, max_runs):
    from insnav.io.rinex_dataset import load_rinex_run, rtklib_truth

    w = DATA / "rtklibexplorer_walk_0827"
    if not w.is_dir():
        lines += ["### Walk, tight", "", f"not run: {w} not found", ""]
        return
    ds, cfg = load_rinex_run(w / "rinex_derived" / "gnss_1730.obs", w / "rinex_derived" / "gnss_1730.nav",
                             w / "raw" / "imu_1730.csv", ROOT / "bench" / "walk_0827.toml")
    cfg = dataclasses.replace(cfg, coupling="tight", filter="ekf")
    ref = rtklib_truth(str(w / "raw" / "gnss_1730_sf.pos"), ds.gps_time_offset_s)
    compare("rtklibexplorer walk, tight on the RINEX (EKF)", ds, cfg, ref, lines, verdicts, max_runs=max_runs,
            note="`bench/walk_0827.toml` (GPS L1 pseudorange and Doppler, the loader's consumer MEMS model and "
                 "pseudorange weighting) as the hand settings; reference = the RTK `.pos` (an independent "
                 "carrier-phase solution).")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=None)
    ap.add_argument("--seeds", type=int, default=3, help="simulated runs (default %(default)s)")
    ap.add_argument("--max-runs", type=int, default=150, help="runs per tuning in the simulation")
    ap.add_argument("--real-max-runs", type=int, default=60, help="runs per tuning on the real data")
    ap.add_argument("--skip-sim", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    lines = ["# Noise tuning by the innovation likelihood (`insnav tune`)", "",
             f"Commit `{git_commit()}`; command `{COMMAND}`"
             + ("" if argv is None and len(sys.argv) <= 3 else f" (this run: `{' '.join(sys.argv[1:])}`)") + ".", "",
             "The tuner (docs/algorithms.md section 19) multiplies the noise settings by factors (gyro_arw, acc_vrw, "
             "gyro_bias, acc_bias: all axes of each; gnss_pos, gnss_vel: the data's GNSS sigmas) and maximises "
             "the innovation log-likelihood sum_k -(nu' S^-1 nu + ln det S)/2 of the first 70 % of the data by "
             "Nelder-Mead in log space, one C++ run per evaluation.  The last 30 % are held out: hand (or wrong) "
             "and tuned settings run over all the data and are compared there.", ""]
    verdicts = []
    if not args.skip_sim:
        simulation(list(range(1, args.seeds + 1)), args.max_runs, lines, verdicts)
    lines += ["## 2. Real data: hand settings against tuned", ""]
    kfgins(lines, verdicts, args.real_max_runs)
    walk_loose(lines, verdicts, args.real_max_runs)
    walk_tight(lines, verdicts, args.real_max_runs)
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
