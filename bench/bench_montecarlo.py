"""Benchmark: 100 Monte Carlo runs of the 175 s seed 001 scenario (100 Hz IMU,
10 Hz GNSS) through three filters (kf, rdkf, exact), median of 3 repeats.

    python bench/bench_montecarlo.py [--runs 100] [--workers 2] [--repeats 3] [--scenario seed001-high]

Target: <= 20 s on 2 cores.  Prints the per-run serial cost too so a
loaded machine can be told apart from a slow runner.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import insnav


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="seed001-high")
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    filters = ("kf", "rdkf", "exact")
    cmd = "python bench/bench_montecarlo.py " + " ".join(sys.argv[1:] if argv is None else argv)
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        insnav.montecarlo(args.scenario, filters, runs=args.runs, seed=0, workers=args.workers, progress=False)
        times.append(time.perf_counter() - t0)
    run_one = sys.modules["insnav.analysis.montecarlo"].run_one
    Task = sys.modules["insnav.analysis.montecarlo"].Task
    t0 = time.perf_counter()
    for i in range(5):
        run_one(Task(i, args.scenario, filters, 100 + i, i, 5.0))
    per_run = (time.perf_counter() - t0) / 5
    try:
        load = os.getloadavg()[0]
    except OSError:  # pragma: no cover
        load = float("nan")
    print(f"command: {cmd.strip()}")
    print(f"{args.runs} runs x {len(filters)} filters ({','.join(filters)}) of {args.scenario}, "
          f"{args.workers} workers: median {statistics.median(times):.2f} s over {args.repeats} "
          f"(all: {', '.join(f'{t:.2f}' for t in times)}); target <= 20 s")
    print(f"serial cost per run (simulate + 3 filters + metrics): {per_run * 1e3:.0f} ms; "
          f"CPUs available {len(os.sched_getaffinity(0))}, 1-min load average {load:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
