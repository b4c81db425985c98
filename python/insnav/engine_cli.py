"""``insnav run``: a filter over a dataset directory or KF-GINS files."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ._atomic import atomic_write_text
from .cli import UserError
from .config import FILTERS, ConfigError, RunConfig, load_config

EXAMPLES = """examples:
  insnav run run3 --filter rbukf --out run3/solution.csv
  insnav run run3 --coupling tight --filter ekf --config my.toml --out sol.csv
  insnav run --format kfgins --config kf-gins.yaml [--imu IMU.txt --gnss GNSS.txt] --out sol.csv

The solution CSV has the columns t, lat_deg, lon_deg, h_m, vn, ve, vd (m/s NED),
roll_deg, pitch_deg, yaw_deg, their 1-sigma (sigma_n_m ... sigma_yaw_deg) and the
estimated IMU errors (acc_bias_*_mps2, gyro_bias_*_dph, *_scale_*_ppm).  The resolved
configuration is written beside it as <out>.config.toml so the run can be repeated
with --config.  Config keys (TOML, units in the names): see docs/formats.md."""


def add_run_parser(sub) -> None:
    p = sub.add_parser("run", help="run a filter over a dataset (insnav directory or KF-GINS files)",
                       description="Run a closed-loop GNSS/INS filter.", epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", nargs="?", help="dataset directory written by `insnav simulate` (insnav format)")
    p.add_argument("--format", choices=("insnav", "kfgins"), default="insnav")
    p.add_argument("--filter", default=None, help=f"one of {', '.join(FILTERS)} (default: config or ekf)")
    p.add_argument("--coupling", choices=("loose", "tight"), default=None)
    p.add_argument("--config", help="insnav TOML run configuration, or the KF-GINS YAML with --format kfgins")
    p.add_argument("--imu", help="KF-GINS IMU file (overrides the YAML's imupath)")
    p.add_argument("--gnss", help="KF-GINS GNSS file (overrides the YAML's gnsspath)")
    p.add_argument("--seed", type=int, default=None, help="seed of the initial-error draw (init_seed)")
    p.add_argument("--out", required=True, help="solution CSV to write")
    p.set_defaults(func=cmd_run)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(float(x)) for x in v) + "]"
    if isinstance(v, float) and not np.isfinite(v):
        return "inf" if v > 0 else "nan"
    return repr(float(v)) if isinstance(v, float) else str(v)


def resolved_config_toml(cfg: RunConfig) -> str:
    """The configuration as TOML (SI imu values under [imu_si], informational)."""
    import dataclasses

    lines = ["# insnav resolved run configuration"]
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if f.name == "imu" or v is None:
            continue
        lines.append(f"{f.name} = {_toml_value(v)}")
    if cfg.imu is not None:
        from .config import _USER_UNITS

        lines.append("\n[imu]")
        for key, (fld, factor) in _USER_UNITS.items():
            if key in ("acc_vrw_ug_per_sqrt_hz",):
                continue
            lines.append(f"{key} = {_toml_value(np.asarray(getattr(cfg.imu, fld)) / factor)}")
    return "\n".join(lines) + "\n"


def cmd_run(args) -> int:
    import insnav

    try:
        if args.format == "kfgins":
            if not args.config:
                raise UserError("--format kfgins needs --config KF-GINS.yaml")
            from .io.kfgins_dataset import load_kfgins

            ds, cfg = load_kfgins(args.config, args.imu, args.gnss)
        else:
            if not args.dataset:
                raise UserError("give a dataset directory (or --format kfgins --config FILE)")
            if not Path(args.dataset).is_dir():
                raise UserError(f"dataset directory not found: {args.dataset}")
            ds = insnav.load_dataset(args.dataset)
            cfg = load_config(args.config) if args.config else RunConfig()
        if args.seed is not None:
            cfg.init_seed = args.seed
        sol = insnav.run(ds, filter=args.filter, coupling=args.coupling, config=cfg)
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    out = Path(args.out)
    sol.save_csv(out)
    cfg.filter = sol.summary.get("filter", cfg.filter)
    atomic_write_text(out.with_suffix(out.suffix + ".config.toml"), resolved_config_toml(cfg))
    s = sol.summary
    print(f"{out}: {len(sol)} rows, filter {s.get('filter')}, {s.get('coupling')} coupling, "
          f"{s.get('updates')} updates, {s.get('rejected', 0)} rejected, "
          f"{s.get('cholesky_repairs', 0)} covariance repairs")
    return 0
