"""``insnav simulate`` and ``insnav scenarios`` subcommands (wired in by :mod:`insnav.cli`)."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..errors import seed_arg


def add_simulate_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="simulate a scenario into a dataset directory",
        description="Simulate a preset (see 'insnav scenarios') or a scenario TOML file and write\n"
        "a dataset directory (imu.csv, gnss.csv, truth.csv, imu_errors.csv, gnss_raw.csv for\n"
        "tight presets, scenario.toml, dataset.json) that 'insnav run' reads; presets with carrier\n"
        "phase (rtk-open-sky-car, rtk-urban-car) also write RINEX 3 rover.obs, base.obs, nav.rnx\n"
        "and rtk_truth.csv (the rover antenna per epoch) for RTK engines such as RTKLIB.\n"
        "Files carry the unit in every column name: t_s [s], dtheta_x_rad, dv_x_mps [m/s], lat_deg, h_m [m].\n"
        "Example: insnav simulate seed000-sim --seed 1 --out data/seed000-sim",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", nargs="?", help="preset name or path to a scenario .toml file")
    p.add_argument("--from-truth", metavar="FILE", default=None,
                   help="instead of a scenario: synthesise IMU increments from a sampled truth trajectory file\n"
                   "(Spirent SimGEN motion CSV: quintic Hermite position, cubic-spline attitude; see\n"
                   "docs/algorithms.md) and write imu.csv, truth.csv, imu_errors.csv, dataset.json")
    p.add_argument("--imu-grade", default=None,
                   help="with --from-truth: IMU grade of the injected errors (navigation, tactical, industrial,\n"
                   "consumer) or 'exact' (no error); default industrial")
    p.add_argument("--imu-rate-hz", type=float, default=None,
                   help="with --from-truth: IMU rate [Hz], 1 to 10000 (default 100)")
    p.add_argument("--seed", type=seed_arg, default=None, help="random seed (default: the scenario's)")
    p.add_argument("--out", required=True, help="dataset directory to write")
    p.add_argument("--overwrite", action="store_true", help="replace an existing insnav dataset folder (never a folder holding other files)")
    p.add_argument("--quiet", "-q", action="store_true",
                   help="no progress bar (shown on a terminal only, for simulations longer than about 2 s)")
    p.set_defaults(func=cmd_simulate)


def add_scenarios_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "scenarios", help="list the preset scenarios",
        description="List the preset scenarios shipped with insnav (name, duration [s], what it is).\n"
        "With NAME, print its TOML (units in every key: lat_deg, duration_s, gyro_bias_deg_per_h, ...).\n"
        "Example: insnav scenarios seed000-sim > my-scenario.toml",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", nargs="?", help="print this preset's TOML file")
    p.set_defaults(func=cmd_scenarios)


def cmd_simulate(args) -> int:
    from . import simulate_to

    from ..data.dataset import check_replaceable

    out = Path(args.out)
    if (args.scenario is None) == (args.from_truth is None):
        raise SystemExit("insnav simulate: give either a scenario or --from-truth FILE (not both)")
    if args.from_truth is None and (args.imu_grade is not None or args.imu_rate_hz is not None):
        given = "--imu-grade" if args.imu_grade is not None else "--imu-rate-hz"
        raise SystemExit(f"insnav simulate: {given} is an option of --from-truth; a scenario sets its IMU in its "
                         "[imu] table (grade, rate_hz)")
    check_replaceable(out, args.overwrite)  # before the simulation: fail fast, never touch a user's folder
    if args.from_truth is not None:
        from .from_truth import simulate_from_truth

        grade = "industrial" if args.imu_grade is None else args.imu_grade
        rate = 100.0 if args.imu_rate_hz is None else args.imu_rate_hz
        ds = simulate_from_truth(args.from_truth, grade, imu_rate_hz=rate, seed=0 if args.seed is None else args.seed)
        ds.save(out, overwrite=args.overwrite)
        print(f"{ds.name} (IMU grade {grade}, seed {ds.seed}): {len(ds.imu)} IMU samples at "
              f"{rate:g} Hz, {len(ds.truth)} truth epochs -> {out}")
        return 0
    from .._progress import Progress

    scenario = _check_disk_space(args.scenario, args.seed, out)  # parsed once, here
    bar = Progress(f"insnav simulate {args.scenario}", unit=" steps")
    bar.enabled = bar.enabled and not args.quiet
    try:
        t = time.perf_counter()
        # block by block: memory bounded by the block, not by the scenario's length
        ds, n_imu, n_gnss = simulate_to(out, scenario, overwrite=args.overwrite, progress=bar)
        t_sim = time.perf_counter() - t
    finally:
        bar.close()
    raw = "" if ds.gnss_raw is None else f", {len(ds.gnss_raw)} raw GNSS observations"
    if ds.rtk is not None:
        n_r, n_c = ds.rtk.common_counts()
        raw += (f", carrier phase of rover and base (RINEX 3 rover.obs, base.obs, nav.rnx; "
                f"{n_c.min()}-{n_c.max()} common satellites)")
    print(f"{ds.name} (seed {ds.seed}): {n_imu} IMU samples, {n_gnss} GNSS fixes{raw}; "
          f"simulated and written in {t_sim:.2f} s -> {out}")
    return 0


#: lower bounds of the bytes of one CSV row of imu.csv, truth.csv and imu_errors.csv (measured on
#: seed000-sim at 200 Hz: 143, 220 and 116 bytes), so that the estimate never refuses a run that fits
_ROW_BYTES = {"imu": 100, "truth": 150, "imu_errors": 80}


def _check_disk_space(scenario, seed, out: Path):
    """The parsed scenario (its ``seed`` overridden by ``seed`` when given); refused, before anything
    is written, when its tables cannot fit on the disk of ``out`` (a misplaced exponent in
    ``duration_s`` would otherwise run for years, filling it)."""
    import shutil

    from .scenario import ScenarioError, load_scenario

    sc = load_scenario(scenario, seed=seed)
    need = sc.duration * (sc.imu_rate * _ROW_BYTES["imu"] + sc.truth_rate * _ROW_BYTES["truth"]
                          + sc.errors_rate * _ROW_BYTES["imu_errors"])
    where = out.resolve().parent
    while not where.exists():
        where = where.parent
    free = shutil.disk_usage(where).free
    if need > free:
        raise ScenarioError(f"{scenario}: {sc.duration:.6g} s at {sc.imu_rate:g} Hz would write "
                         f"at least {need / 1e9:.3g} GB, more than the {free / 1e9:.3g} GB free in {where} "
                         "(check [[motion.segments]] duration_s and [imu] rate_hz)")
    return sc


def cmd_scenarios(args) -> int:
    from .scenario import list_presets, load_scenario, preset_path

    if getattr(args, "name", None):
        sys.stdout.write(preset_path(args.name).read_text(encoding="utf-8"))
        return 0
    names = list_presets()
    width = max(len(n) for n in names)
    for n in names:
        sc = load_scenario(n)
        print(f"{n:<{width}}  {sc.duration:7.1f} s  {sc.description}")
    return 0
