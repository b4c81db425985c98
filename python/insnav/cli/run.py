"""``insnav run``: a filter over a dataset directory or KF-GINS files."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .._atomic import atomic_write_text
from ..errors import UserError
from ..config import ConfigError, RunConfig, load_config
from ..registry import FILTERS

EXAMPLES = """examples:
  insnav run run3 --filter rbukf --out run3-rbukf.csv      # beside the dataset folder, not inside it
  insnav run run3 --coupling tight --filter ekf --config my.toml --out sol.csv
  insnav run --format kfgins --config kf-gins.yaml [--imu IMU.txt --gnss GNSS.txt] --out sol.csv
  insnav run --format rinex --obs F.obs --nav F.nav --imu IMU.csv [--imu-tag IMU.csv.tag] \
             [--config run.toml] --coupling tight --filter ekf --out sol.csv

--format rinex: real GPS L1 C/A data (RINEX 2/3 obs + nav, LNAV ephemerides) and an IMU CSV;
the [rinex] table of --config says how to read the IMU file (columns, units g|mps2 and
dps|rps, rates or increments, time gps_s|gps_sow|gpst_unix_s or an IMU tick counter with an
RTKLIB str2str .tag file), the mounting rotation and lever arm and the initial heading
(docs/formats.md).  Times in the solution are then GPS seconds of week, so
`insnav evaluate sol.csv REFERENCE.pos` compares it with an RTKLIB solution.

The solution has the columns t_s, lat_deg, lon_deg, h_m, vn_mps, ve_mps, vd_mps (NED, m/s),
roll_deg, pitch_deg, yaw_deg (group nav), their 1-sigma (sigma_n_m ... sigma_yaw_deg; group
sigma) and the estimated IMU errors (acc_bias_*_mps2, gyro_bias_*_dph, *_scale_*_ppm; group
bias).  The resolved configuration is written beside it as <out>.config.toml so the run
can be repeated with --config.  Config keys (TOML, units in the names): see docs/formats.md."""


def add_run_parser(sub) -> None:
    p = sub.add_parser("run", help="run a filter over a dataset (insnav directory, KF-GINS files or RINEX + IMU CSV)",
                       description="Run a closed-loop GNSS/INS filter.", epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dataset", nargs="?", help="dataset directory written by `insnav simulate` (insnav format)")
    p.add_argument("--format", choices=("insnav", "kfgins", "rinex"), default="insnav")
    p.add_argument("--filter", default=None, metavar="NAME",
                   help="default: the config's, else ekf.  "
                        + "; ".join(f"{n} ({'/'.join(s.couplings)}, {s.paper}): {s.summary}" for n, s in FILTERS.items()))
    p.add_argument("--coupling", choices=("loose", "tight"), default=None)
    p.add_argument("--config", help="insnav TOML run configuration (with a [rinex] table for --format rinex), "
                   "or the KF-GINS YAML with --format kfgins")
    p.add_argument("--imu", help="KF-GINS IMU file (overrides the YAML's imupath); with --format rinex the IMU CSV")
    p.add_argument("--obs", help="RINEX 2/3 observation file (--format rinex)")
    p.add_argument("--nav", help="RINEX 2/3 GPS navigation file (--format rinex)")
    p.add_argument("--imu-tag", help="RTKLIB str2str time tag of the IMU log (--format rinex with a tick_ms "
                   "column; default IMU.tag)")
    p.add_argument("--gnss", help="KF-GINS GNSS file (overrides the YAML's gnsspath)")
    p.add_argument("--seed", type=int, default=None, help="seed of the initial-error draw (init_seed)")
    p.add_argument("--out", required=True,
                   help="solution file; the suffix chooses the format: .csv (text), .npz (numpy), .parquet "
                        "(needs pyarrow).  Beside it: <out>.innovations.csv (per GNSS record: status, NIS, "
                        "innovation) and <out>.config.toml (the run's configuration)")
    p.add_argument("--csv-precision", choices=("resolution", "exact"), default="resolution",
                   help="CSV numbers: rounded to each column's resolution (1 ns, ~1 um, ...; docs/formats.md), "
                        "or exact: the shortest text that reads back as the same double (about twice the size)")
    p.add_argument("--timings", action="store_true",
                   help="print the wall time of each stage (read, filter, write) to stderr")
    p.add_argument("--allow-free-inertial", action="store_true",
                   help="accept a run that used no GNSS update, or had more than 20 %% of them rejected by the "
                        "innovation gate (otherwise an error: wrong units, time bases or sigmas are the usual cause)")
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
        from ..config import _USER_UNITS

        lines.append("\n[imu]")
        for key, (fld, factor) in _USER_UNITS.items():
            if key in ("acc_vrw_ug_per_sqrt_hz",):
                continue
            lines.append(f"{key} = {_toml_value(np.asarray(getattr(cfg.imu, fld)) / factor)}")
    return "\n".join(lines) + "\n"


def _rinex_table_toml(opt) -> str:
    """The ``[rinex]`` table of the resolved configuration (loader options)."""
    import dataclasses

    lines = ["\n[rinex]"]
    for f in dataclasses.fields(opt):
        v = getattr(opt, f.name)
        if v is None:
            continue
        if isinstance(v, (list, tuple)) and v and isinstance(v[0], str):
            lines.append(f"{f.name} = [" + ", ".join(_toml_value(x) for x in v) + "]")
        else:
            lines.append(f"{f.name} = {_toml_value(v)}")
    return "\n".join(lines) + "\n"


#: share of GNSS updates the innovation gate may reject before a run counts as failed
MAX_REJECTED_SHARE = 0.2


class _Stages:
    """Wall time of the named stages of a run [s] (``--timings``)."""

    def __init__(self):
        import time

        self._clock = time.perf_counter
        self.t_last = self._clock()
        self.times: dict[str, float] = {}

    def done(self, name: str) -> None:
        now = self._clock()
        self.times[name] = self.times.get(name, 0.0) + now - self.t_last
        self.t_last = now

    def line(self) -> str:
        return "timings [s]: " + ", ".join(f"{k} {v:.3f}" for k, v in self.times.items())


def cmd_run(args) -> int:
    import insnav

    stages = _Stages()

    out = Path(args.out)
    if out.is_dir():  # fail before the run, not after it
        raise UserError(f"--out {out} is a folder: give a file name, e.g. {out / 'solution.csv'}")
    from ..filters.solution import FORMATS

    if out.suffix.lower() not in FORMATS:
        raise UserError(f"--out {out}: unknown format {out.suffix!r}; use one of {', '.join(FORMATS)}")
    rinex_opts = None
    try:
        if args.format == "rinex":
            missing = [n for n in ("obs", "nav", "imu") if not getattr(args, n)]
            if missing:
                raise UserError("--format rinex needs " + ", ".join(f"--{n}" for n in missing))
            if args.dataset:
                raise UserError("--format rinex reads --obs/--nav/--imu; do not give a dataset directory")
            from ..io.rinex_dataset import load_rinex_run

            ds, cfg = load_rinex_run(args.obs, args.nav, args.imu, args.config, imu_tag=args.imu_tag)
            rinex_opts = ds.options
        elif args.format == "kfgins":
            if not args.config:
                raise UserError("--format kfgins needs --config KF-GINS.yaml")
            from ..io.kfgins_dataset import load_kfgins

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
        stages.done("read")
        sol = insnav.run(ds, filter=args.filter, coupling=args.coupling, config=cfg)
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    s = sol.summary
    used, rejected = int(s.get("updates", 0)), int(s.get("rejected", 0))
    records = int(s.get("gnss_records", len(getattr(ds, "gnss", ())) or 0))
    san = s.get("sanitize") or {}
    dropped = int(san.get("gnss_invalid_dropped", 0) or 0) + int(san.get("gnss_duplicates_dropped", 0) or 0)
    if not args.allow_free_inertial:
        if rejected > MAX_REJECTED_SHARE * (used + rejected):
            raise UserError(f"{rejected} of {used + rejected} GNSS updates were rejected by the innovation gate "
                            f"(> {MAX_REJECTED_SHARE:.0%}): the fixes and the IMU disagree; check units, lever arm "
                            "and sigmas (--allow-free-inertial to accept the run)")
        if used == 0:
            raise UserError(f"no GNSS update was used ({records} records, {dropped} dropped): the run is free "
                            "inertial; check the GNSS time base, sigmas and units (--allow-free-inertial to "
                            "accept it)")
    stages.done("filter")
    from ..filters.solution import write_innovations

    sol.save(out, precision=args.csv_precision)
    write_innovations(sol, out)
    cfg.filter = sol.summary.get("filter", cfg.filter)
    text = resolved_config_toml(cfg)
    if rinex_opts is not None:
        text += _rinex_table_toml(rinex_opts)
    atomic_write_text(out.with_suffix(out.suffix + ".config.toml"), text)
    print(f"{out}: {len(sol)} rows, filter {s.get('filter')}, {s.get('coupling')} coupling; GNSS: {records} "
          f"records, {used} updates used, {rejected} rejected by the gate, {dropped} dropped by the input checks; "
          f"{s.get('cholesky_repairs', 0)} covariance repairs")
    stages.done("write")
    if args.timings:
        import sys

        print(stages.line(), file=sys.stderr)
    return 0
