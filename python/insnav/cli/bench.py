"""``insnav bench``: throughput figures a user can reproduce right after install.

* strapdown mechanization through the batch API (:func:`insnav.mechanize`,
  the whole loop in C++): samples/s and x real time on 1 h of 200 Hz IMU
  increments (5 min with ``--quick``);
* closed-loop loosely coupled filters (:func:`insnav.run`, input checks
  included, EKF and RB-UKF by default) on a simulated scenario (``seed000-car``:
  900 s at 200 Hz, 10 Hz GNSS; ``seed000-sim``, 150 s, with ``--quick``):
  time per run, x real time and time per IMU sample, with the horizontal
  position RMS as a check that the runs did their job.

Every figure is the median over ``--repeats`` runs measured side by side in
one process; the printout ends with the command that reproduces it, the CPUs
available and the load average (a loaded machine gives lower figures).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import numpy as np

from ..errors import seed_arg

LOOSE_FILTERS = ("ekf", "rbukf", "ukf")
IMU_RATE_HZ = 200.0
DEFAULTS = dict(mech_duration_s=3600.0, scenario="seed000-car", repeats=5)
QUICK = dict(mech_duration_s=300.0, scenario="seed000-sim", repeats=3)

EXAMPLES = """examples:
  insnav bench                      # 1 h of 200 Hz mechanization, EKF and RB-UKF on seed000-car (~10 s)
  insnav bench --quick              # 5 min of mechanization, seed000-sim (~2 s)
  insnav bench --filters ekf,rbukf,ukf --repeats 9 --json > bench.json

Units: mechanization in samples/s and x real time (at 200 Hz); filters in seconds per run,
x real time (scenario duration / run time) and microseconds per IMU sample; horizontal
position RMS against the simulated truth in m.  All figures are medians over --repeats."""


def add_bench_parser(sub) -> None:
    """``insnav bench``: registered by :mod:`insnav.cli`."""
    p = sub.add_parser("bench", help="throughput of the mechanization and the filters on this machine",
                       description="Measure mechanization samples/s [1/s] and filter time per run [s] "
                       "and x real time.", epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="shorter data and 3 repeats (a few seconds)")
    p.add_argument("--repeats", type=int, default=None,
                   help=f"repeats per figure, the median is reported (default: {DEFAULTS['repeats']}, "
                   f"--quick {QUICK['repeats']})")
    p.add_argument("--scenario", default=None,
                   help=f"preset or scenario TOML for the filters (default: {DEFAULTS['scenario']}, "
                   f"--quick {QUICK['scenario']})")
    p.add_argument("--filters", default="ekf,rbukf",
                   help=f"comma-separated loose filters, from {', '.join(LOOSE_FILTERS)} (default: %(default)s)")
    p.add_argument("--mech-duration-s", dest="mech_duration_s", type=float, default=None,
                   help=f"mechanization data length at {IMU_RATE_HZ:g} Hz [s] "
                   f"(default: {DEFAULTS['mech_duration_s']:g}, --quick {QUICK['mech_duration_s']:g})")
    p.add_argument("--seed", type=seed_arg, default=1, help="simulation seed (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=cmd_bench)


def _command(args, repeats: int) -> str:
    """The command line that reproduces these figures (shell-quoted)."""
    from shlex import quote

    cmd = ["insnav bench"]
    if args.quick:
        cmd.append("--quick")
    cmd.append(f"--repeats {repeats}")
    if args.scenario is not None:
        cmd.append(f"--scenario {quote(str(args.scenario))}")
    if args.filters != "ekf,rbukf":
        cmd.append(f"--filters {quote(args.filters)}")
    if args.mech_duration_s is not None:
        cmd.append(f"--mech-duration-s {args.mech_duration_s:g}")
    if args.seed != 1:
        cmd.append(f"--seed {args.seed}")
    if args.json:
        cmd.append("--json")
    return " ".join(cmd)


def _median_time(fn, repeats: int) -> tuple[float, list]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times


def bench_mechanization(duration_s: float, repeats: int) -> dict:
    """Median time of :func:`insnav.mechanize` over ``duration_s`` of 200 Hz increments.

    The increments are a smooth synthetic motion (slow coning about all axes,
    1 g specific force), the same data as ``bench/bench_mechanization.py``.
    """
    from ..ins.mechanize import mechanize
    from ..data.nav import NavState

    n = int(round(duration_s * IMU_RATE_HZ))
    dt = 1.0 / IMU_RATE_HZ
    t = np.arange(1, n + 1) * dt
    dtheta_b = np.column_stack([0.01 * np.sin(0.5 * t), 0.02 * np.cos(0.3 * t), np.full(n, 0.05)]) * dt  # rad
    dv_b = np.column_stack([0.3 * np.sin(0.1 * t), np.full(n, 0.2), np.full(n, -9.8)]) * dt  # m/s
    init = NavState(0.6 * 180 / np.pi, 2.0 * 180 / np.pi, 100.0, [10.0, 0.0, 0.0])
    mechanize(t[:100], dtheta_b[:100], dv_b[:100], init, t0=0.0)  # warm-up (first-call costs)
    med, times = _median_time(lambda: mechanize(t, dtheta_b, dv_b, init, t0=0.0), repeats)
    return dict(imu_rate_hz=IMU_RATE_HZ, duration_s=n * dt, samples=n, median_s=med, times_s=times,
                samples_per_s=n / med, x_real_time=n * dt / med)


def bench_filters(scenario, filters, repeats: int, seed: int) -> tuple[dict, dict]:
    """Simulate ``scenario`` once, then time :func:`insnav.run` per filter (medians)."""
    from ..filters import sanitize  # noqa: F401  (imported before timing: first-call costs)
    from ..analysis.metrics import errors
    from ..filters import run
    from ..sim import simulate

    t0 = time.perf_counter()
    ds = simulate(scenario, seed=seed)
    sim_s = time.perf_counter() - t0
    duration = float(ds.imu.t[-1] - ds.t0)
    n_imu = len(ds.imu.t)
    info = dict(name=ds.name, duration_s=duration, imu_samples=n_imu, imu_rate_hz=n_imu / duration,
                gnss_fixes=len(ds.gnss), simulate_s=sim_s, seed=seed)
    out = {}
    for f in filters:
        sols = []
        med, times = _median_time(lambda: sols.append(run(ds, f, init_seed=seed)), repeats)
        e = errors(sols[-1], ds.truth)
        hz = np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])
        out[f] = dict(median_s=med, times_s=times, x_real_time=duration / med, us_per_imu_sample=med / n_imu * 1e6,
                      horizontal_rms_m=float(np.sqrt(np.mean(hz ** 2))))
    return info, out


def cmd_bench(args) -> int:
    from .. import __version__
    from ..errors import UserError

    base = QUICK if args.quick else DEFAULTS
    repeats = base["repeats"] if args.repeats is None else args.repeats
    mech_s = base["mech_duration_s"] if args.mech_duration_s is None else args.mech_duration_s
    scenario = base["scenario"] if args.scenario is None else args.scenario
    filters = tuple(f.strip() for f in args.filters.split(",") if f.strip())
    if repeats < 1:
        raise UserError(f"--repeats must be >= 1, got {repeats}")
    if not (np.isfinite(mech_s) and mech_s * IMU_RATE_HZ >= 2):
        raise UserError(f"--mech-duration-s must be at least {2 / IMU_RATE_HZ:g} s, got {mech_s:g}")
    bad = [f for f in filters if f not in LOOSE_FILTERS]
    if bad or not filters:
        raise UserError(f"--filters: unknown or tight-only filter(s) {', '.join(bad) or '(none given)'}; "
                        f"choose from {', '.join(LOOSE_FILTERS)}")
    from ..sim.scenario import load_scenario

    load_scenario(scenario)  # a bad scenario fails now, not after the mechanization figures
    command = _command(args, repeats)
    mech = bench_mechanization(mech_s, repeats)
    scen, filt = bench_filters(scenario, filters, repeats, args.seed)
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):  # pragma: no cover (Windows)
        load = float("nan")
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        cpus = os.cpu_count() or 1
    res = dict(command=command, insnav_version=__version__, numpy_version=np.__version__,
               python=platform.python_version(), machine=platform.machine(), cpus_available=cpus,
               load_avg_1min=load, repeats=repeats, mechanization=mech, scenario=scen, filters=filt)
    if args.json:
        from .._atomic import json_safe
        print(json.dumps(json_safe(res), indent=2, allow_nan=False))
        return 0
    print(f"insnav {__version__} bench: {cpus} CPU(s) available, 1-min load average {load:.2f}; "
          f"medians over {repeats} repeat(s)")
    print(f"mechanization (insnav.mechanize, {mech['duration_s'] / 60:g} min of {IMU_RATE_HZ:g} Hz = "
          f"{mech['samples']} samples): {mech['samples_per_s'] / 1e6:.2f} M samples/s, "
          f"{mech['median_s']:.3f} s, {mech['x_real_time']:.0f}x real time")
    print(f"scenario {scen['name']} (seed {scen['seed']}): {scen['duration_s']:g} s, {scen['imu_samples']} IMU samples "
          f"at {scen['imu_rate_hz']:.0f} Hz, {scen['gnss_fixes']} GNSS fixes; simulated in {scen['simulate_s']:.2f} s")
    print(f"{'filter':8s} {'time/run [s]':>13s} {'x real time':>12s} {'us/IMU sample':>14s} {'horiz. RMS [m]':>15s}")
    for f, r in filt.items():
        print(f"{f:8s} {r['median_s']:13.3f} {r['x_real_time']:12.0f} {r['us_per_imu_sample']:14.2f} "
              f"{r['horizontal_rms_m']:15.2f}")
    print(f"command: {command}")
    return 0
