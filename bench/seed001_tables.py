"""Reproduce seed 001 (Pan, Zhao, Li 2022) Tables 1 and 2 and the error-spike
figures: N/E position and velocity RMSE of (a) the KF that uses delayed fixes
as if current, (b) the random-delay KF, (c) exact time-tagged processing, on
seed001-low and seed001-high, 100 Monte Carlo runs each.

    python bench/seed001_tables.py [--runs 100] [--seed 2022] [--workers N] [--out docs/results]

Writes ``seed001.md`` and ``seed001_{low,high}_north.png`` (+ ``_east``) into --out.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import insnav
from insnav.analysis import errors

FILTERS = ("kf", "rdkf", "exact")
LABEL = {"kf": "(a) KF, delayed fixes used as current", "rdkf": "(b) random-delay KF (seed 001)",
         "exact": "(c) exact, time-tagged re-processing"}
# seed 001 Tables 1 and 2: N pos [m], E pos [m], N vel [m/s], E vel [m/s]
PAPER = {
    "seed001-low": {"kf": (0.3319, 0.1189, 0.00145, 0.00162), "liu2020": (0.1504, 0.1104, 0.00100, 0.00116),
                    "rdkf": (0.0817, 0.0838, 0.00117, 0.00097)},
    "seed001-high": {"kf": (5.3419, 0.8367, 0.0143, 0.0170), "liu2020": (1.4983, 0.9181, 0.8051, 0.2786),
                     "rdkf": (0.5458, 0.4068, 0.0043, 0.0030)},
}
METRICS = ("pos_n_rmse_m", "pos_e_rmse_m", "vel_n_rmse_mps", "vel_e_rmse_mps")


def fmt(x):
    return f"{x:.4f}" if x >= 0.01 else f"{x:.5f}"


def table(res, scen):
    p = PAPER[scen]
    lines = ["| method | N pos RMSE [m] | E pos RMSE [m] | N vel RMSE [m/s] | E vel RMSE [m/s] |",
             "|---|---|---|---|---|"]
    for f in FILTERS:
        s = res.summary[f]
        cells = [f"{fmt(s[m]['mean'])} ± {fmt(s[m]['std'])}" for m in METRICS]
        lines.append(f"| ours {LABEL[f]} | " + " | ".join(cells) + " |")
    lines.append("| paper KF | " + " | ".join(fmt(v) for v in p["kf"]) + " |")
    lines.append("| paper ref. method (Liu 2020) | " + " | ".join(fmt(v) for v in p["liu2020"]) + " |")
    lines.append("| paper random-delay KF | " + " | ".join(fmt(v) for v in p["rdkf"]) + " |")
    return "\n".join(lines)


def ratios(res, scen):
    s = res.summary
    r = lambda a, b, m: s[a][m]["mean"] / s[b][m]["mean"]  # noqa: E731
    p = PAPER[scen]
    return dict(kf_rdkf_n=r("kf", "rdkf", "pos_n_rmse_m"), kf_rdkf_e=r("kf", "rdkf", "pos_e_rmse_m"),
                kf_exact_n=r("kf", "exact", "pos_n_rmse_m"), rdkf_exact_n=r("rdkf", "exact", "pos_n_rmse_m"),
                paper_n=p["kf"][0] / p["rdkf"][0], paper_e=p["kf"][1] / p["rdkf"][1])


def spike_plot(scen, seed, out_dir: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ds = insnav.simulate(scen, seed=seed)
    errs = {f: errors(insnav.run(ds, f, init_seed=seed), ds.truth) for f in FILTERS}
    paths = []
    for axis, name in ((0, "north"), (1, "east")):
        fig, ax = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
        for f, c in zip(FILTERS, ("tab:red", "tab:blue", "tab:green")):
            e = errs[f]
            ax[0].plot(e["t"], e["pos_n_m"][:, axis], c, lw=0.7, label=LABEL[f])
            ax[1].plot(e["t"], e["vel_n_mps"][:, axis], c, lw=0.7, label=LABEL[f])
        ax[0].set_ylabel(f"{name} position error [m]")
        ax[1].set_ylabel(f"{name} velocity error [m/s]")
        ax[1].set_xlabel("time [s]")
        ax[0].set_title(f"{scen} (delay p = {ds.scenario['gnss']['delay_p']}), one run, seed {seed}")
        ax[0].legend(loc="upper left", fontsize=8)
        for a in ax:
            a.grid(alpha=0.3)
        fig.tight_layout()
        p = out_dir / f"seed001_{scen.split('-')[1]}_{name}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
    return paths


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=2022)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", default="docs/results")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cmd = "python bench/seed001_tables.py " + " ".join(sys.argv[1:] if argv is None else argv)
    results, rat, plots = {}, {}, {}
    for scen in ("seed001-low", "seed001-high"):
        t0 = time.perf_counter()
        results[scen] = insnav.montecarlo(scen, FILTERS, runs=args.runs, seed=args.seed, workers=args.workers)
        print(f"{scen}: {time.perf_counter() - t0:.1f} s")
        print(results[scen].table())
        rat[scen] = ratios(results[scen], scen)
        plots[scen] = spike_plot(scen, seed=1, out_dir=out)
    text = REPORT.format(
        cmd=cmd.strip(), runs=args.runs, seed=args.seed,
        table_low=table(results["seed001-low"], "seed001-low"),
        table_high=table(results["seed001-high"], "seed001-high"),
        **{f"low_{k}": v for k, v in rat["seed001-low"].items()},
        **{f"high_{k}": v for k, v in rat["seed001-high"].items()},
        high_rd_max=results["seed001-high"].summary["rdkf"]["pos_n_max_m"]["mean"],
        high_kf_max=results["seed001-high"].summary["kf"]["pos_n_max_m"]["mean"],
        high_ex_max=results["seed001-high"].summary["exact"]["pos_n_max_m"]["mean"],
    )
    (out / "seed001.md").write_text(text)
    print(f"wrote {out / 'seed001.md'} and {', '.join(str(p) for v in plots.values() for p in v)}")
    return 0


REPORT = """# Seed 001: random-delay Kalman filter, reproduced (Tables 1 and 2)

Pan, Zhao, Li (2022), *Random Delay Kalman Filtering of GNSS/INS Integrated
Navigation* (digest: `/work/shared/docs/seed-digest.md`, section 001).

Command (writes this file and the figures):

    {cmd}

{runs} Monte Carlo runs per scenario, master seed {seed} (run i uses
`SeedSequence({seed}).spawn({runs})[i]` for the simulation and the initial
error; the numbers do not depend on the worker count).  Scenarios
`seed001-low` (p = [0.7, 0.3]) and `seed001-high` (p = [0.2, 0.4, 0.2, 0.2]):
the paper's 175 s vehicle route, 100 Hz IMU, 10 Hz GNSS; the IMU and GNSS
noise are our choice because the paper gives none (tactical-grade IMU, RTK-like
fixes 0.05 m / 0.01 m/s; see `python/insnav/scenarios/seed001-low.toml`).
RMSE over time of the real-time IMU-rate output after the first 5 s
(initial convergence), per run; the table gives the mean over runs ± the
standard deviation over runs (the paper reports the average RMSE).

The three methods (same data, same EKF, same tuning):

* **(a) KF** — the closed-loop EKF given each fix when it *arrives*, as if it
  were valid then (`insnav.run(ds, "kf")`).
* **(b) random-delay KF** — seed 001 eqs. (4)-(21) on the closed-loop error
  state (`insnav.run(ds, "rdkf")`, `cpp/include/insnav/filter/random_delay_kf.hpp`):
  stacked error state of the last s + 1 GNSS epochs (15 (s + 1) states,
  s = 1 or 3 here), the received fix compared with the INS solution stored at
  each of those epochs, weighted by p, gain with the spread term.  It does not
  use the time tag.
* **(c) exact** — the fix applied at its time of validity by restoring a
  checkpoint and re-processing the IMU data since (`insnav.run(ds, "exact")`,
  `cpp/include/insnav/engine/delay_engine.hpp`; history 1 s, checkpoints every
  0.1 s in a 64-entry ring).  Not in the paper: real receivers time-tag fixes.

## Table 1 — low delay, p = [0.7, 0.3]

{table_low}

## Table 2 — high delay, p = [0.2, 0.4, 0.2, 0.2]

{table_high}

## Improvement factors (north position RMSE, mean over runs)

| | KF / random-delay KF | KF / exact | random-delay KF / exact | paper KF / random-delay KF |
|---|---|---|---|---|
| low delay | {low_kf_rdkf_n:.1f}x (east {low_kf_rdkf_e:.1f}x) | {low_kf_exact_n:.0f}x | {low_rdkf_exact_n:.1f}x | {low_paper_n:.1f}x (east {low_paper_e:.1f}x) |
| high delay | {high_kf_rdkf_n:.1f}x (east {high_kf_rdkf_e:.1f}x) | {high_kf_exact_n:.0f}x | {high_rdkf_exact_n:.1f}x | {high_paper_n:.1f}x (east {high_paper_e:.1f}x) |

## Error spikes

![north, low delay](seed001_low_north.png)
![north, high delay](seed001_high_north.png)

(`seed001_low_east.png`, `seed001_high_east.png`: the same for east.)  One run
(seed 1).  With fixes trusted at 0.05 m, the naive KF follows the *delayed*
track: its north error is a lag of about v x (mean delay) while the vehicle
heads north (up to ~3 m at 20 m/s and a 1.4-epoch mean delay), going to zero
on the east-bound legs, and its velocity error is about a x delay whenever
the speed or heading changes (the paper's "spikes").  The random-delay KF
compares the fix with the p-weighted mean of the INS solutions stored at the
possible epochs and de-weights it by their spread, so the lag disappears; the
exact engine's error is the on-time EKF's.  Mean of the per-run maximum north
error, high delay: KF {high_kf_max:.2f} m, random-delay KF {high_rd_max:.3f} m,
exact {high_ex_max:.3f} m.

## Ours against the paper

* **The ordering and the size of the effect reproduce.**  The random-delay KF
  cuts the north position RMSE of the naive KF by {low_kf_rdkf_n:.0f}x (low)
  and {high_kf_rdkf_n:.0f}x (high); the paper reports {low_paper_n:.1f}x and
  {high_paper_n:.1f}x.  The factor grows with the delay in both.
* **Why our factors are larger.**  The absolute numbers depend on sensor and
  receiver noise the paper does not give.  Our naive-KF errors are within a
  factor of 4 of the paper's (they are set by speed x delay; the route timing
  and heading per leg are ours), but our
  random-delay KF and exact errors are smaller than the paper's random-delay KF
  (0.08 / 0.55 m): with RTK-like 0.05 m fixes every 0.1 s and a tactical IMU
  the estimate between fixes is very good, so removing the delay error leaves
  little.  A noisier receiver would raise (b) and (c) and lower the factors.
  The paper's east-position KF error is smaller than its north one; ours is
  larger (our route spends more time at speed heading east after the +90 deg
  turn; the paper gives no timings, ours are in `seed001-low.toml`).
* **The paper's velocity numbers are not all consistent.**  Its Table 2 gives
  the reference method (Liu 2020) a north velocity RMSE of 0.81 m/s, 50 times
  its KF, and its Table 1 velocity RMSEs (0.001 m/s) are below what a 0.01 m/s
  receiver allows after closed-loop fusion; we do not reproduce the Liu 2020
  column (not requested).  Our KF velocity error is 10-40x the others'
  because a late velocity fix is wrong by acceleration x delay.
* **Exact processing is better than the random-delay KF** by
  {low_rdkf_exact_n:.1f}x (low) and {high_rdkf_exact_n:.1f}x (high) on north
  position, and equals the on-time EKF: when the receiver time-tags its fixes
  (all do), re-processing is the right tool; the random-delay KF is for links
  that lose the tag.  Its cost: 1 to 3 epochs of IMU re-processed per late fix
  (about 0.6 to 1.7x the normal mechanization work here).
* **The random-delay KF has a heavy tail.**  Its per-run RMSE spread is about
  its mean: most runs are at 0.01-0.04 m, a few (about 1 in 30) show a
  transient of up to ~0.9 m.  Not investigated yet; a likely cause is a stretch
  where the realised delays differ from p for several epochs in a row, which
  the p-weighted innovation cannot see.
* **Formulation notes.**  The paper's stacked transition blockdiag(Phi_k ..
  Phi_k-s) and noise blockdiag(Q .. Q) are implemented as the shift of a
  stack of the same trajectory (newest block propagated, the others copied),
  for which the copies carry no new noise: Qbar = blockdiag(Q, 0 ..).  The
  spread term of eq. (17) is evaluated with the full-state (not error-state)
  predicted measurements, which is what makes it large for a moving vehicle.
  The P update is eq. (15) at the optimal gain, equal to eq. (21) and
  symmetric by construction.  With p = [1] the filter is the EKF to 1e-8 m
  (tests/test_delay.py, cpp/tests/test_delay.cpp).
"""

if __name__ == "__main__":
    sys.exit(main())
