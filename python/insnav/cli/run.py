"""``insnav run``: a filter over a dataset directory or KF-GINS files."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .._atomic import atomic_write_text
from .._median import median
from ..errors import UserError, seed_arg
from .._toml import table_toml, toml_value
from ..config import ConfigError, RunConfig, load_config
from ..registry import FILTERS

EXAMPLES = """examples:
  insnav run run3 --filter rbukf --out run3-rbukf.csv      # beside the dataset folder, not inside it
  insnav run run3 --coupling tight --filter ekf --config my.toml --out sol.csv
  insnav run --format kfgins --config kf-gins.yaml [--imu IMU.txt --gnss GNSS.txt] --out sol.csv
  insnav run --format rinex --obs F.obs --nav F.nav --imu IMU.csv [--imu-tag IMU.csv.tag] \
             [--config run.toml] --coupling tight --filter ekf --out sol.csv
  insnav run --format csv --imu imu.csv --gnss gnss.csv|fixes.pos|fixes.nmea --config run.toml --out sol.csv

--format csv: your own IMU CSV and GNSS fixes (a CSV, an RTKLIB .pos or NMEA GGA+RMC+GST),
loosely coupled.  The [imu] and [gnss] tables of --config map the columns and units (time
base, rad|deg, rates|increments, m/s^2|g, FRD|FLU|RFU axes; lat/lon deg|rad, ellipsoidal|msl
height, sigmas) and give the IMU noise model ([imu] grade = consumer|industrial|tactical|
navigation, or the noise keys).  Units are checked first; the initial state comes from the
alignment (levelling, gyrocompassing or the GNSS course once moving) unless [initial] gives it,
and is printed with its sigmas (docs/formats.md).

  insnav run --filter spp --format rinex --obs F.obs --nav F.nav [--config run.toml] --out spp.csv
  insnav run --filter rtk --format rinex --obs ROVER.obs --base BASE.obs --nav F.nav [--base-pos X,Y,Z] \
             [--config run.toml] --out rtk.pos

--filter spp: GNSS-only single point positioning (no IMU): weighted least squares over every
system with ephemerides, one inter-system bias per further system, velocity from Doppler,
RAIM fault detection and exclusion; [gnss] (weighting model legacy|rtklib|cn0, masks, system
factors, systems) and [spp] (raim, raim_alpha, ...) tables of --config.  Beside --out:
<out>.spp.csv (clock, inter-system biases, drift, DOPs, RAIM status per epoch).

--format rinex: real GNSS data (RINEX 2/3 obs + nav: GPS, and GLONASS, Galileo, BeiDou with
[rinex] systems or [gnss] systems; the start uses GPS) and an IMU CSV;
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
    from ..io.input_formats import INPUT_FORMATS

    p.add_argument("--format", choices=tuple(INPUT_FORMATS), default="insnav",
                   help="; ".join(f"{f.name}: {f.summary}" for f in INPUT_FORMATS.values()))
    p.add_argument("--filter", default=None, metavar="NAME",
                   help="default: the config's, else ekf.  "
                        + "; ".join(f"{n} ({'/'.join(s.couplings)}, {s.paper}): {s.summary}" for n, s in FILTERS.items()))
    p.add_argument("--coupling", choices=("loose", "tight", "gnss", "rtk"), default=None,
                   help="gnss: GNSS only (filter spp; the only coupling it has, chosen by --filter spp); "
                        "rtk: tight RTK/INS of the dataset's IMU with --obs ROVER --base BASE --nav NAV (carrier "
                        "phase; the TOML's [rtk] and [rtk_engine] tables; writes <out>.rtk.pos and <out>.rtk.csv "
                        "per rover epoch with the fix status, ratio and slips)")
    p.add_argument("--config", help="insnav TOML run configuration (with a [rinex] table for --format rinex), "
                   "or the KF-GINS YAML with --format kfgins")
    p.add_argument("--imu", help="KF-GINS IMU file (overrides the YAML's imupath); with --format rinex or csv the "
                   "IMU CSV")
    p.add_argument("--obs", help="RINEX 2/3 observation file (--format rinex)")
    p.add_argument("--nav", help="RINEX 2/3 GPS navigation file (--format rinex); with --filter spp several, "
                   "comma-separated (e.g. brdc1580.16n,brdc1580.16g), or a mixed RINEX 3 file")
    p.add_argument("--base", help="--filter rtk: the base station's RINEX observation file")
    p.add_argument("--base-pos", metavar="X,Y,Z|LAT,LON,H",
                   help="--filter rtk: base antenna reference point, ECEF [m] or lat_deg,lon_deg,h_m (default: "
                        "the TOML's [rtk] base_position_*, else the base header's APPROX POSITION + antenna delta)")
    p.add_argument("--imu-tag", help="RTKLIB str2str time tag of the IMU log (--format rinex or csv with a tick_ms "
                   "column; default IMU.tag)")
    p.add_argument("--gnss", help="KF-GINS GNSS file (overrides the YAML's gnsspath); with --format csv the GNSS fixes "
                   "(.csv, RTKLIB .pos or NMEA .nmea; [gnss] format overrides the suffix)")
    p.add_argument("--constraints", default=None, metavar="LIST",
                   help="vehicle constraints, comma-separated from nhc (no lateral/vertical velocity), odo "
                        "(odometer speed, the dataset's odometer.csv), zupt (zero velocity and angular rate while "
                        "standing still); settings in the config's [constraints] table; loose ekf/rbukf/ukf")
    p.add_argument("--smooth", action="store_true",
                   help="post-process with the RTS smoother (ekf, rbukf, ukf; loose, tight or --coupling rtk; "
                        "also with --tdcp; rtk: fixed epochs kept fixed): every row from all the data")
    p.add_argument("--tdcp", action="store_true",
                   help="tight ekf on RINEX data: add time-differenced carrier-phase rows (rover only, no base; "
                        "settings in the config's [tdcp] table)")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="an option of the filter's family (the config's [options] table; repeatable), VALUE a "
                        "TOML value: e.g. elevation_mask_deg=15 (tight on a simulated dataset; RINEX: [rinex] "
                        "elevation_mask_deg), particles=500 (seed 004), delay_p=[0.7,0.3] (delay filters)")
    p.add_argument("--seed", type=seed_arg, default=None, help="seed of the initial-error draw (init_seed)")
    p.add_argument("--out", default=None,
                   help="solution file; the suffix chooses the format: .csv (text), .npz (numpy), .parquet "
                        "(needs pyarrow).  Beside it: <out>.innovations.csv (per GNSS record: status, NIS, rows, "
                        "loose innovation), for tight <out>.residuals.csv (per satellite) and <out>.config.toml "
                        "(the run's configuration).  Required, except with --format kfgins: then the YAML's "
                        "outputpath gets KF-GINS's own files (as --out-format kfgins), as KF-GINS does")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing --out file that insnav did not write (a solution and its sidecars "
                        "from an earlier run are replaced without it); an input of the run is never replaced")
    p.add_argument("--run-config", default=None, metavar="TOML",
                   help="with --format kfgins (whose --config is the KF-GINS YAML): an insnav TOML run "
                        "configuration whose keys override the YAML's (sanitize limits, gating, constraints...)")
    p.add_argument("--output-rate", type=float, default=None, metavar="HZ",
                   help="write a row every k-th IMU sample, k = IMU rate / HZ (an integer; e.g. 10 or 1 [Hz] at "
                        "200 Hz); the filter still runs at every sample.  Default: every sample")
    p.add_argument("--stream", choices=("auto", "on", "off"), default="auto",
                   help="--format kfgins or csv: read, filter and write the IMU file block by block, without "
                        "holding the file or the solution in memory (the loose ekf/rbukf/ukf forward run; the same "
                        "CSV, Parquet and KF-GINS files as the whole-file run byte for byte, the same npz arrays "
                        "bit for bit).  auto (default): whenever the run allows it (not --smooth, --constraints, "
                        "self-calibration states, --option, TDCP or a str2str tick_ms IMU log), on: the same, "
                        "with a note when it cannot, off: read the IMU file whole.  A plain KF-GINS GNSS file's fixes are "
                        "read back from it a block at a time (their times held; the file must not change "
                        "during the run), a compressed one's and --format csv's are held whole")
    p.add_argument("--columns", default=None, metavar="GROUPS",
                   help="column groups to write, comma separated: nav (t_s, position, velocity, attitude), "
                        "sigma (their 1-sigma), bias (IMU biases and scale factors).  Default: all")
    p.add_argument("--out-format", choices=("insnav", "kfgins"), default="insnav",
                   help="kfgins: --out is a folder that gets KF_GINS_Navresult.nav, KF_GINS_IMU_ERR.txt, KF_GINS_STD.txt "
                        "exactly as KF-GINS writes them (week sow lat lon h vN vE vD roll pitch yaw; sow, "
                        "gyro bias deg/h, acc bias mGal, scale factors ppm)")
    p.add_argument("--csv-precision", choices=("resolution", "exact"), default="resolution",
                   help="CSV numbers: rounded to each column's resolution (1 ns, ~1 um, ...; docs/formats.md), "
                        "or exact: the shortest text that reads back as the same double (about twice the size)")
    p.add_argument("--quiet", "-q", action="store_true",
                   help="no progress bar (shown on a terminal only, for runs longer than about 2 s)")
    p.add_argument("--timings", action="store_true",
                   help="print the wall time of each stage (read, filter, write) to stderr")
    p.add_argument("--allow-free-inertial", action="store_true",
                   help="accept a run that used no GNSS update, or had more than 20 %% of them rejected by the "
                        "innovation gate (otherwise an error: wrong units, time bases or sigmas are the usual cause)")
    p.add_argument("--allow-unhealthy", action="store_true",
                   help="write a solution whose health check failed (a broken covariance, a km-scale jump; "
                        "otherwise exit status 2 and nothing written)")
    p.set_defaults(func=cmd_run)


def cli_options(pairs) -> dict:
    """The ``--option KEY=VALUE`` pairs as a dict (VALUE read as a TOML value, else as text)."""
    out = {}
    if not pairs:
        return out
    import tomllib

    for pair in pairs:
        key, sep, text = pair.partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise UserError(f"--option {pair}: expected KEY=VALUE (e.g. elevation_mask_deg=15)")
        try:
            out[key] = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = text.strip()
    return out


def resolved_config_toml(cfg: RunConfig, tables: dict | None = None) -> str:
    """The resolved configuration of a run as TOML (``<out>.config.toml``): the run keys
    and tables of ``cfg``, then the family's and the input format's own ``tables``
    (name -> a dataclass such as RinexOptions, Weighting, SppOptions, RtkOptions, or a
    dict).  A GNSS-only run (``coupling = "gnss"``) writes its filter and coupling only,
    then its tables: it reads nothing else."""
    import dataclasses

    lines = ["# insnav resolved run configuration"]
    extra = "".join(_table_toml(name, obj) for name, obj in (tables or {}).items() if obj is not None)
    if cfg.coupling == "gnss":
        return "\n".join(lines + [f"filter = {toml_value(cfg.filter)}", f"coupling = {toml_value(cfg.coupling)}"]) \
            + "\n" + extra
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        if f.name in ("imu", "constraints", "robust", "tdcp", "sanitize", "time", "lever_arm", "options") or v is None:
            continue
        lines.append(f"{f.name} = {toml_value(v)}")
    if cfg.sanitize:
        lines.append("\n[sanitize]")
        lines += [f"{k} = {toml_value(v)}" for k, v in cfg.sanitize.items()]
    if cfg.constraints.use or cfg.constraints.standstill_q_scale != 1.0:  # the standstill level needs no `use`
        lines.append("\n[constraints]")
        for f in dataclasses.fields(cfg.constraints):
            v = getattr(cfg.constraints, f.name)
            if f.name == "use":
                lines.append("use = [" + ", ".join(f'"{u}"' for u in v) + "]")
            elif v is None:
                continue
            else:
                lines.append(f"{f.name} = {toml_value(v)}")
    from ..config import _SELFCAL_TABLES, Robust

    for name, cls in _SELFCAL_TABLES:
        if getattr(cfg, name) != cls():  # the self-calibration tables, when not the defaults
            lines.append(_table_toml(name, getattr(cfg, name)).rstrip("\n"))
    if cfg.coupling == "tight" or cfg.robust != Robust():
        lines.append("\n[robust]")
        lines += [f"{f.name} = {toml_value(getattr(cfg.robust, f.name))}" for f in dataclasses.fields(cfg.robust)
                  if getattr(cfg.robust, f.name) is not None]  # screening unset: the default (on, or the preset's)
    if cfg.options:
        from .._toml import dumps_toml

        lines.append("\n" + dumps_toml({"options": cfg.options}).strip("\n"))
    if cfg.tdcp.enabled:
        lines.append("\n[tdcp]")
        lines += [f"{f.name} = {toml_value(getattr(cfg.tdcp, f.name))}" for f in dataclasses.fields(cfg.tdcp)]
    if cfg.imu is not None:
        from ..config import _USER_UNITS

        lines.append("\n[imu]")
        for key, (fld, factor) in _USER_UNITS.items():
            if key in ("acc_vrw_ug_per_sqrt_hz",):
                continue
            lines.append(f"{key} = {toml_value(np.asarray(getattr(cfg.imu, fld)) / factor)}")
    return "\n".join(lines) + "\n" + extra


def _csv_tables_toml(tables: dict, has_imu_table: bool) -> str:
    """The file-mapping keys of ``--format csv`` (``[imu]`` mapping, ``[gnss]``,
    ``[initial]``, ``[align]``) after the resolved run keys, whose last table is ``[imu]``."""
    import numpy as _np

    def val(v):
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + "}"
        if isinstance(v, _np.ndarray):
            v = v.tolist()
        return toml_value(list(v) if isinstance(v, tuple) else v)

    out = [] if has_imu_table else ["\n[imu]"]
    out += [f"{k} = {val(v)}" for k, v in tables.get("imu", {}).items()]
    for name in ("gnss", "initial", "align"):
        t = tables.get(name) or {}
        if t:
            out.append(f"\n[{name}]")
            out += [f"{k} = {val(v)}" for k, v in t.items()]
    return "\n".join(out) + "\n"


def output_decimation(t, rate_hz: float) -> int:
    """k of ``--output-rate``: the IMU rate (median interval of ``t`` [s]) over
    ``rate_hz`` [Hz], which must be a whole number (within 0.1 %)."""
    t = np.asarray(t, float)
    if t.size < 2:
        return 1
    imu_hz = 1.0 / median(np.diff(t))
    k = imu_hz / float(rate_hz)
    if k < 1.0 - 1e-3 or abs(k - round(k)) > 1e-3 * k:
        ok = [r for r in (100, 50, 20, 10, 5, 2, 1, 0.5, 0.1) if r <= imu_hz + 1e-9
              and abs(imu_hz / r - round(imu_hz / r)) <= 1e-3 * imu_hz / r]
        raise UserError(f"--output-rate {rate_hz:g}: the IMU rate {imu_hz:.6g} Hz is not a whole multiple of it; "
                        f"use e.g. {', '.join(f'{r:g}' for r in ok[:4])} [Hz]")
    return max(1, int(round(k)))


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


_table_toml = table_toml  # insnav._toml (the RTK command line writes its table without numpy too)


def _rtk_table(opt, base_e) -> dict:
    """The ``[rtk]`` table of a resolved configuration: the RtkOptions a run used and the base
    position it was given (ECEF [m]; None: the base header's, found again on a re-run)."""
    import dataclasses

    table = {f.name: getattr(opt, f.name) for f in dataclasses.fields(opt)}
    if base_e is not None:
        table["base_position_ecef_m"] = [float(v) for v in np.asarray(base_e, float).ravel()]
    return table


def _input_paths(args) -> list:
    """Every file the run reads (those given, and a KF-GINS YAML's data files)."""
    paths = [args.dataset, args.imu, args.gnss, args.obs, getattr(args, "base", None), args.imu_tag, args.config,
             args.run_config]
    paths += [n for n in (args.nav or "").split(",") if n]
    if args.imu:
        paths += [args.imu + ".tag", str(Path(args.imu).with_suffix(".tag"))]
    if args.format == "kfgins" and args.config:
        from ..io.kfgins import read_kfgins_config

        try:
            y = read_kfgins_config(args.config)
        except (OSError, ValueError):
            y = {}  # reported by the loader
        paths += [y.get("imupath"), y.get("gnsspath")]
    return paths


def _run_outputs(out: Path, kfgins_folder: bool, sidecars: tuple = ()) -> list[Path]:
    """Every file ``insnav run`` may write for ``--out``."""
    from ..filters.solution import innovations_path, residuals_path

    if kfgins_folder:
        from ..io.kfgins import KFGINS_IMU_ERR_FILE, KFGINS_NAV_FILE, KFGINS_STD_FILE

        base = out / KFGINS_NAV_FILE
        files = [base, out / KFGINS_IMU_ERR_FILE, out / KFGINS_STD_FILE]
    else:
        base, files = out, [out]
    files += [innovations_path(base), residuals_path(base), base.with_suffix(base.suffix + ".config.toml")]
    files += [base.with_suffix(base.suffix + side) for side in sidecars]  # a GNSS-only filter's table, RTK/INS's
    return files


def check_run_outputs(args, out: Path, kfgins_folder: bool, sidecars: tuple = ()) -> None:
    """Before the run: no output is an input, none replaces a file insnav did
    not write (unless --overwrite), the folder is writable, and a .parquet
    output has pyarrow (one-line errors, not after minutes of filtering)."""
    from .._outputs import check_outputs, input_files

    check_outputs(_run_outputs(out, kfgins_folder, sidecars), input_files(*_input_paths(args)),
                  overwrite=getattr(args, "overwrite", False))
    if out.suffix.lower() == ".parquet" and not kfgins_folder:
        from ..filters.solution import _parquet

        try:
            _parquet()
        except ImportError as exc:
            raise UserError(f"--out {out}: {exc}") from None


def _check_gnss_only_args(args, name: str, needs: tuple, usage: str) -> None:
    """The arguments of a GNSS-only filter (spp, rtk): RINEX input with ``needs``,
    and none of the IMU / dataset options (a one-line UserError naming them)."""
    if args.format != "rinex":
        raise UserError(f"--filter {name} reads RINEX files: give --format rinex {usage}")
    missing = [n for n in needs if not getattr(args, n)]
    if missing:
        raise UserError(f"--filter {name} needs " + ", ".join(f"--{n}" for n in missing))
    unused = [f"--{n.replace('_', '-')}" for n in ("imu", "imu_tag", "gnss", "constraints", "output_rate",
                                                   "run_config")
              if getattr(args, n, None)] + (["--smooth"] if args.smooth else []) + (["--tdcp"] if args.tdcp else [])
    if "base" not in needs:  # spp: no base receiver
        unused += [flag for flag, v in (("--base", args.base), ("--base-pos", args.base_pos)) if v is not None]
    if args.dataset:
        unused.append("a dataset directory")
    if args.coupling not in (None, "gnss"):
        unused.append(f"--coupling {args.coupling}")
    if unused:
        raise UserError(f"--filter {name} is GNSS only and does not use {', '.join(unused)}")
    if args.config:  # the TOML's requests of the same things: refused as the options are, not ignored
        from ..config import read_toml

        d = read_toml(args.config)
        tdcp = d.get("tdcp")
        if tdcp is not None and not isinstance(tdcp, dict):
            raise UserError(f"{args.config}: key 'tdcp': bad value {tdcp!r}; allowed: a [tdcp] table (and --filter "
                            f"{name} is GNSS only: it has no TDCP update)")
        settings = [k for k in (tdcp or {}) if k != "enabled"]
        if settings and tdcp.get("enabled", False) is False:
            raise UserError(f"{args.config}: key 'tdcp.{settings[0]}': --filter {name} is GNSS only and has no "
                            "TDCP update (an IMU run's key): remove the [tdcp] table")
        for key, on in (("smooth", d.get("smooth", False)),
                        ("tdcp.enabled", tdcp.get("enabled", False) if isinstance(tdcp, dict) else False)):
            if on is not False:
                raise UserError(f"{args.config}: key '{key}': --filter {name} is GNSS only and has no "
                                f"{'smoother' if key == 'smooth' else 'TDCP update'} (an IMU run's key): "
                                "remove it or set it to false")


def _check_ins_run_tables(args) -> None:
    """Before an INS run: what it would ignore without a word is a one-line UserError.  ``--base`` /
    ``--base-pos`` and the TOML's ``[rtk]`` / ``[rtk_engine]`` tables without RTK/INS (``--coupling
    rtk``); ``[rinex] systems`` with it (RTK/INS reads ``[rtk] systems``); ``[tdcp]`` settings with
    TDCP off (neither ``--tdcp`` nor ``[tdcp] enabled = true``)."""
    toml = args.run_config if args.format == "kfgins" else args.config
    d = {}
    if toml:
        from ..config import read_toml

        try:
            d = read_toml(toml)
        except ConfigError:
            d = {}  # reported by the loader, with its own message
    coupling = args.coupling or d.get("coupling")
    rin = d.get("rinex")
    if coupling == "rtk" and args.format == "rinex" and isinstance(rin, dict) and "systems" in rin:  # ignored before
        raise UserError(f"{toml}: key 'rinex.systems' is not read by RTK/INS (--coupling rtk): its satellites are "
                        "[rtk] systems (default \"GREC\"); write systems in the [rtk] table")
    if coupling != "rtk":
        given = [f for f, v in (("--base", args.base), ("--base-pos", args.base_pos)) if v is not None]
        this = f"this run's coupling is '{coupling}'" if coupling else "this run has no coupling = \"rtk\""
        if given:
            raise UserError(f"{' and '.join(given)}: read by RTK runs only (--filter rtk, or --coupling rtk with "
                            f"--obs/--base/--nav); {this}")
        for table in ("rtk", "rtk_engine"):
            if table in d and args.format != "kfgins":  # --run-config refuses them itself
                raise UserError(f"{toml}: [{table}] is read by RTK runs only (--filter rtk, or --coupling rtk); "
                                f"{this}: remove the table")
    tdcp = d.get("tdcp")
    if isinstance(tdcp, dict) and not args.tdcp and tdcp.get("enabled", False) is False:
        settings = [k for k in tdcp if k != "enabled"]
        if settings:  # dropped from the run and from <out>.config.toml before
            raise UserError(f"{toml}: key 'tdcp.{settings[0]}': TDCP is off (neither --tdcp nor [tdcp] enabled = "
                            "true), so the setting would be ignored: enable TDCP or remove it")


def _spp_run(args):
    """``--filter spp``: the inputs (RINEX observations and navigation, the TOML's [rinex],
    [gnss], [spp] tables), the files beside --out and the summary line."""
    from ..filters.spp import load_spp_run, write_spp_table

    def write(sol, out):
        write_spp_table(sol.spp, out.with_suffix(out.suffix + ".spp.csv"))
        return dict(rinex=sol.rinex_options, gnss=sol.weighting, spp=sol.spp_options)

    def line(sol, out):
        s = sol.summary
        if s["solved"] == 0:
            raise UserError(f"{args.obs}: no epoch could be solved ({s['epochs']} epochs; too few satellites with "
                            "ephemerides above the masks?)")
        return (f"{out}: {s['solved']} of {s['epochs']} epochs solved, filter spp ({s['systems']}, weighting "
                f"{s['weighting']}, RAIM {'on' if sol.spp_options.raim else 'off'}); RAIM: {s['raim_passed']} "
                f"passed, {s['raim_excluded_epochs']} after excluding {s['rows_excluded']} rows, {s['raim_failed']} "
                f"failed, {s['raim_untested']} untested")

    given = _gnss_only_options(args, "spp", ("spp_options", "weighting"))
    ds, opts = load_spp_run(args.obs, [p for p in args.nav.split(",") if p], args.config,
                            spp=given.get("spp_options"), gnss=given.get("weighting"))
    return ds, opts, write, line


def _gnss_only_options(args, name: str, keys: tuple) -> dict:
    """``--option KEY={...}`` of a GNSS-only filter: tables of keys over the TOML's own
    (spp: ``spp_options`` over ``[spp]``, ``weighting`` over ``[gnss]``; rtk: ``rtk_options`` over
    ``[rtk]``); any other key, or a value that is not a table, is a one-line error."""
    given = cli_options(args.option)
    for k, v in given.items():
        if k not in keys:
            raise UserError(f"--option {k}: --filter {name} reads {' and '.join(keys)} only (tables of keys, "
                            f"e.g. --option '{keys[0]}={{...}}')")
        if not isinstance(v, dict):
            raise UserError(f"--option {k}: bad value {v!r}; allowed: a table of keys, e.g. --option '{k}={{...}}'")
    return given


def _rtk_run(args):
    """``--filter rtk``: the inputs (rover, base, navigation, the TOML's [rtk] table and the
    base position), the files beside --out (``<out>.rtk.csv``; an --out ending in .pos gets
    RTKLIB's layout) and the summary line."""
    from ..filters.rtk import load_rtk_run
    from ..gnss.rtk import write_rtk_table

    def write(sol, out):
        write_rtk_table(sol.rtk, out.with_suffix(out.suffix + ".rtk.csv"))
        return dict(rtk=_rtk_table(sol.rtk_options, ds.base_position_e_m))

    def line(sol, out):
        c, o = sol.rtk.counts(), sol.rtk_options
        if c["epochs"] == c["n_none"]:
            raise UserError(f"{args.obs}: no epoch could be solved ({c['epochs']} epochs; no common satellites "
                            "above the mask with ephemerides?)")
        slips = sum(v for k, v in c.items() if k.startswith("slips_"))
        return (f"{out}: {c['epochs']} epochs, {c['n_fixed']} fixed ({100.0 * c['fix_rate']:.1f} %), {c['n_float']} "
                f"float, {c['n_dgps']} dgps, {c['n_none']} none; filter rtk ({o.mode}, {o.ar_mode}, {o.systems}, "
                f"{o.frequencies} frequencies); {slips} cycle slips detected")

    given = _gnss_only_options(args, "rtk", ("rtk_options",))
    ds, opts = load_rtk_run(args.obs, args.base, [p for p in args.nav.split(",") if p], args.config,
                            base_pos=args.base_pos, rtk=given.get("rtk_options"))
    return ds, opts, write, line


#: the GNSS-only filters of ``insnav run``: the arguments they need, their usage, an --out
#: example, the file beside --out, and the function reading their inputs
_GNSS_ONLY = {
    "spp": (("obs", "nav"), "--obs OBS --nav NAV", "spp.csv", ".spp.csv", _spp_run,
            "--filter spp writes --out-format insnav only"),
    "rtk": (("obs", "base", "nav"), "--obs ROVER --base BASE --nav NAV", "rtk.pos", ".rtk.csv", _rtk_run,
            "--filter rtk writes --out-format insnav (or RTKLIB's layout with an --out ending in .pos)"),
}


def cmd_run_gnss_only(args, stages) -> int:
    """``insnav run --filter spp|rtk``: a GNSS-only filter over RINEX files (no IMU), run as
    ``insnav.run(inputs, filter, "gnss", **options)``.

    Beside --out: ``<out>.spp.csv`` (spp: clock, biases, DOPs, RAIM per epoch) or
    ``<out>.rtk.csv`` (rtk: status, ratio, fixed ambiguities, slips per epoch), the
    innovations (spp) and ``<out>.config.toml``, all or none.  ``rtk`` with an --out
    ending in ``.pos`` writes RTKLIB's .pos layout.
    """
    import insnav
    from .._atomic import output_set
    from ..filters.solution import FORMATS, write_innovations

    name = args.filter
    needs, usage, example, sidecar, inputs, only_insnav = _GNSS_ONLY[name]
    _check_gnss_only_args(args, name, needs, usage)
    if args.out_format != "insnav":
        raise UserError(only_insnav)
    if args.out is None:
        raise UserError(f"--out is required (a solution file such as {example})")
    out = Path(args.out)
    if out.is_dir():
        raise UserError(f"--out {out} is a folder: give a file name, e.g. {out / example}")
    pos = name == "rtk" and out.suffix.lower() == ".pos"
    if not pos and out.suffix.lower() not in FORMATS:
        raise UserError(f"--out {out}: unknown format {out.suffix!r}; use {'.pos or ' if name == 'rtk' else ''}"
                        f"one of {', '.join(FORMATS)}")
    # rtk: an RTKLIB-layout .pos insnav wrote names it in its first line and is replaced; one
    # another program wrote (RTKLIB's own result) only with --overwrite
    check_run_outputs(args, out, kfgins_folder=False, sidecars=(sidecar,))
    groups = None if args.columns is None else [g.strip() for g in args.columns.split(",") if g.strip()]
    try:
        ds, opts, write, line = inputs(args)
        cfg = RunConfig(filter=name, coupling="gnss")
        sol = insnav.run(ds, config=cfg, **opts)
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    stages.done("filter")
    text = line(sol, out)
    from .._outputs import insnav_output_kind

    with output_set() as files:  # every file or, on an error (a full disk, Ctrl-C), none; older files untouched
        files.replaces(_run_outputs(out, False, (sidecar,)), insnav_output_kind)  # an earlier run's other sidecars
        if pos:
            from ..gnss.rtk import write_rtklib_pos

            write_rtklib_pos(sol.rtk, out)
        else:
            sol.save(out, columns=groups, precision=args.csv_precision)
        if name == "spp":
            write_innovations(sol, out)
        tables = write(sol, out)
        atomic_write_text(out.with_suffix(out.suffix + ".config.toml"), resolved_config_toml(cfg, tables))
    print(text)
    stages.done("write")
    if args.timings:
        import sys

        print(stages.line(), file=sys.stderr)
    return 0


def _overlay_run_config(cfg: RunConfig, path) -> RunConfig:
    """``cfg`` with the keys present in the insnav TOML ``path`` replaced (validated as a whole)."""
    import dataclasses
    import tomllib

    from ..config import config_from_dict, read_toml

    try:
        with open(path, "rb") as f:
            d = tomllib.load(f)
    except OSError as exc:
        raise UserError(f"--run-config {path}: {exc.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        read_toml(path)  # its one-line message naming the file
    for key in ("rtk", "rtk_engine"):
        if key in d:
            raise UserError(f"--run-config {path}: [{key}] is read by RTK runs (--format rinex --coupling rtk), "
                            "not by a KF-GINS run")
    given = config_from_dict(d, source=str(path))  # unknown keys / bad values: one line naming the file
    for key in d:
        if key == "imu" and cfg.imu is not None:  # the keys given override the YAML's noise, the others stay
            from ..config import _USER_UNITS

            noise = dataclasses.replace(cfg.imu)
            for k in d["imu"]:
                fld = _USER_UNITS[k][0]
                setattr(noise, fld, getattr(given.imu, fld))
            cfg.imu = noise
        else:
            setattr(cfg, key, getattr(given, key))
    if cfg.layout == 15:
        # the 15-state layout has no scale-factor states: the KF-GINS YAML's initial scale factors and
        # their sigmas (initaccscale, initgyrscale, initsastd, initsgstd) do not apply; zero ones are
        # dropped, a non-zero initial scale factor is refused (it would be silently left out)
        for key, yaml_key in (("init_acc_scale", "initaccscale"), ("init_gyro_scale", "initgyrscale")):
            v = getattr(cfg, key)
            if key not in d and v is not None:
                if np.any(np.asarray(v, float) != 0.0):
                    raise UserError(f"--run-config {path}: layout = 15 has no scale-factor states, but the KF-GINS "
                                    f"YAML gives {yaml_key} = {[float(x) for x in np.asarray(v, float)]}: use layout = 21")
                setattr(cfg, key, None)
        for key in ("init_sigma_acc_scale", "init_sigma_gyro_scale"):
            if key not in d:
                setattr(cfg, key, None)
    try:
        return dataclasses.replace(cfg).validate()
    except ConfigError as exc:
        raise UserError(f"--run-config {path}: {exc}") from None


def _outside_imu_span(sol, ds) -> tuple[int, int]:
    """GNSS records outside the IMU's time span, and how many of them the
    loader left out (KF-GINS: before ``starttime`` or after the IMU file); the
    others are those the filter marked ``RecordStatus.OUTSIDE_IMU_SPAN``."""
    from ..filters.solution import RecordStatus

    status = getattr(sol, "gnss_status", None)
    records = getattr(sol, "records", None)  # a run written block by block: its records' running counts
    if records is not None:
        n = int(records["outside"])
    else:
        n = int(np.count_nonzero(np.asarray(status) == RecordStatus.OUTSIDE_IMU_SPAN)) if status is not None else 0
    scenario = getattr(ds, "scenario", None)
    cut = int(scenario.get("gnss_outside_imu_span", 0)) if isinstance(scenario, dict) else 0
    return n + cut, cut


def _rtk_ins_inputs(args, ds, cfg: RunConfig):
    """``--coupling rtk``: the IMU dataset with --obs/--base/--nav (an RtkInsDataset) and the run options:
    the TOML's ``[rtk]`` table over the RTK/INS defaults, then ``[options] rtk_options`` and
    ``--option rtk_options={...}`` over the table (taken out of ``cfg.options``); ``[rtk_engine]``;
    the base position.  Each is checked here, a bad key named with its file or option."""
    from ..filters.rtk import parse_base_position, pop_base_position
    from ..filters.rtk_ins import MOVED_TO_RTK, RtkInsDataset, check_engine, deprecated_conflict, rtk_ins_options

    missing = [n for n in ("obs", "base", "nav") if not getattr(args, n)]
    if missing:
        raise UserError("--coupling rtk needs " + ", ".join(f"--{n}" for n in missing)
                        + " (rover and base RINEX observations, navigation file(s))")
    rtk, eng, base_e, source = {}, {}, None, None
    base_keys = ("base_position_ecef_m", "base_position_llh")
    if args.config:
        from ..config import read_toml

        d = read_toml(args.config)
        rtk, eng = d.get("rtk", {}), check_engine(d.get("rtk_engine", {}), str(args.config))
        if not isinstance(rtk, dict):
            raise UserError(f"{args.config}: key 'rtk': bad value {rtk!r}; allowed: an [rtk] table")
        rtk = dict(rtk)
        base_e, source = pop_base_position(rtk, str(args.config))
        for k in MOVED_TO_RTK:
            if k in rtk and k in eng:
                raise UserError(deprecated_conflict(k, str(args.config)))
        rtk_ins_options(rtk, str(args.config))  # a bad key named with its file
    given = cfg.options.pop("rtk_options", None)
    if given is not None:
        where = "[options] / --option rtk_options"
        if not isinstance(given, dict):
            raise UserError(f"{where}: bad value {given!r}; allowed: a table of [rtk] keys, "
                            "e.g. --option 'rtk_options={ar_mode=\"off\"}'")
        if set(given) & set(base_keys):
            raise UserError(f"{where}: give the base position with --base-pos or the [rtk] table")
        rtk = {**rtk, **given}
        rtk_ins_options(rtk, where)
    if args.base_pos is not None:
        base_e, source = parse_base_position(args.base_pos), "--base-pos"
    ds = RtkInsDataset(ds, args.obs, args.base, [p for p in args.nav.split(",") if p], base_e, source)
    return ds, dict(rtk_options=rtk, engine=eng)


def _cli_config(args, cfg: RunConfig) -> RunConfig:
    """The run configuration with the command line's settings (all but --output-rate)."""
    if args.format == "kfgins" and args.run_config:
        cfg = _overlay_run_config(cfg, args.run_config)
    if args.seed is not None:
        cfg.init_seed = args.seed
    cfg.options = {**cfg.options, **cli_options(args.option)}
    if args.smooth:
        cfg.smooth = True
    if args.tdcp:
        cfg.tdcp.enabled = True
    if args.constraints is not None:
        cfg.constraints.use = [c.strip() for c in args.constraints.split(",") if c.strip()]
    if args.out_format == "kfgins":
        cfg.imu_error_sigmas = True  # KF_GINS_STD.txt
    return cfg


def _remove_empty(dirs) -> None:
    """Remove the folders a failed run created (deepest first), while they are empty."""
    for d in dirs:
        try:
            d.rmdir()
        except OSError:
            break


def _try_stream(args, out: Path, groups):
    """``--format kfgins`` or ``--format csv`` with CSV, npz, Parquet or KF-GINS-layout output: the loose forward
    run block by block
    (:mod:`insnav.filters.stream`: neither the IMU file nor the solution held in memory).  Returns (StreamResult,
    folders made), or None when the run takes the batch path (a one-line note
    on stderr says why, unless the run simply is not one the stream does and
    ``--stream on`` was not asked)."""
    import sys

    from ..filters.stream import Fallback, stream_csv_loose, stream_loose_csv, stream_unsupported
    from ..registry import FILTERS

    def note(why: str) -> None:
        print(f"note: the IMU file is read whole, not block by block: {why}", file=sys.stderr)

    def configure(cfg):
        cfg = _cli_config(args, cfg)
        if args.filter is not None:
            cfg.filter = args.filter
        if args.coupling is not None:
            cfg.coupling = args.coupling
        cfg.validate()
        return cfg

    if not args.config:
        return None
    try:
        if args.format == "csv":
            from ..io.csv_dataset import csv_inputs, csv_run_config
            from ..io.input_formats import input_format

            input_format("csv").check(args)
            inp = csv_inputs(args.imu, args.gnss, args.config, imu_tag=getattr(args, "imu_tag", None))
            cfg = configure(csv_run_config(inp))  # the filter before the alignment (its sigmas come later)
        else:
            from ..io.kfgins_dataset import kfgins_stream_inputs

            inp = kfgins_stream_inputs(args.config, args.imu, args.gnss)
            cfg = configure(inp["config"])
    except (OSError, ValueError):
        return None  # the batch path reports it, with its own message
    if cfg.filter not in FILTERS or cfg.coupling not in FILTERS[cfg.filter].couplings:
        return None
    why = stream_unsupported(cfg, out_suffix=out.suffix, out_format=args.out_format)
    if why is None and args.format == "csv":
        from ..filters.stream import csv_stream_unsupported

        why = csv_stream_unsupported(inp)
    if why is not None:
        if args.stream == "on" or cfg.smooth:
            note(why)
        return None
    first = out if args.out_format == "kfgins" else out.parent  # the folder the temporary files go to
    made = [d for d in (first, *first.parents) if not d.exists()]  # removed again if the run fails
    first.mkdir(parents=True, exist_ok=True)
    from .._progress import Progress

    bar = Progress(f"insnav run {cfg.filter}", unit="B") if not args.quiet else None
    try:
        if args.format == "csv":
            res = stream_csv_loose(inp, args.imu, out, configure=configure, columns=groups,
                                   precision=args.csv_precision, output_rate_hz=args.output_rate,
                                   set_decimation=output_decimation, progress=bar, out_format=args.out_format)
        else:
            y = inp["yaml"]
            res = stream_loose_csv(inp["dataset"], inp["imu_path"], cfg, out, imu_ncols=y["imudatalen"],
                                   start_s=y["starttime_s"], end_s=y["endtime_s"], gnss_raw=inp["gnss"],
                                   columns=groups, precision=args.csv_precision, output_rate_hz=args.output_rate,
                                   set_decimation=output_decimation, progress=bar, out_format=args.out_format)
    except Fallback as exc:
        if bar is not None:
            bar.close()
        _remove_empty(made)
        if args.stream == "on" or not exc.batch_names_it:  # else the batch path's error is the one line
            note(str(exc))
        return None
    except BaseException:
        _remove_empty(made)
        raise
    finally:
        if bar is not None:
            bar.close()
    s = res.solution.summary
    used, rejected = int(s.get("updates", 0)), int(s.get("rejected", 0))
    if not args.allow_free_inertial and (used == 0 or rejected > MAX_REJECTED_SHARE * (used + rejected)):
        res.discard()  # the batch path gives the message (and the hint from the whole IMU)
        _remove_empty(made)
        return None
    return res, made


def cmd_run(args) -> int:
    import insnav

    stages = _Stages()
    if args.filter is None and args.format == "rinex" and args.config:  # filter = "spp" in the TOML
        import tomllib

        try:
            with open(args.config, "rb") as f:
                f_toml = tomllib.load(f).get("filter")
                if f_toml in ("spp", "rtk"):
                    args.filter = f_toml
        except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
            pass  # reported by the loader
    if args.filter in _GNSS_ONLY:
        return cmd_run_gnss_only(args, stages)

    if args.run_config is not None and args.format != "kfgins":
        raise UserError("--run-config goes with --format kfgins (otherwise the insnav TOML is --config)")
    _check_ins_run_tables(args)
    if args.out is None:
        if args.format != "kfgins":
            raise UserError("--out is required (a solution file such as sol.csv)")
        if not args.config:
            raise UserError("--format kfgins needs --config KF-GINS.yaml")
        from ..io.kfgins import read_kfgins_config

        try:
            outputpath = read_kfgins_config(args.config)["outputpath"]
        except (OSError, ValueError) as exc:
            raise UserError(str(exc)) from None
        if outputpath is None:
            raise UserError(f"{args.config}: no --out and no 'outputpath' key: give one of them")
        args.out, args.out_format = outputpath, "kfgins"
    out = Path(args.out)
    from ..filters.solution import FORMATS, Solution

    groups = None
    if args.columns is not None:
        groups = [g.strip() for g in args.columns.split(",") if g.strip()]
        bad = [g for g in groups if g not in Solution.COLUMN_GROUPS]
        if bad or not groups:
            raise UserError(f"--columns {args.columns}: unknown group {', '.join(map(repr, bad)) or '(none)'}; "
                            f"use any of {','.join(Solution.COLUMN_GROUPS)}")
    if args.out_format == "kfgins":
        if out.exists() and not out.is_dir():
            raise UserError(f"--out {out}: with --out-format kfgins, --out is a folder (it gets "
                            "KF_GINS_Navresult.nav and KF_GINS_IMU_ERR.txt)")
        if groups is not None:
            raise UserError("--columns does not apply to --out-format kfgins (its files have fixed columns)")
    else:
        if out.is_dir():  # fail before the run, not after it
            raise UserError(f"--out {out} is a folder: give a file name, e.g. {out / 'solution.csv'}")
        if out.suffix.lower() not in FORMATS:
            raise UserError(f"--out {out}: unknown format {out.suffix!r}; use one of {', '.join(FORMATS)}")
    if args.output_rate is not None and not (args.output_rate > 0 and np.isfinite(args.output_rate)):
        raise UserError(f"--output-rate {args.output_rate}: expected a rate > 0 [Hz]")
    # RTK/INS (the only coupling with a --base) also writes <out>.rtk.pos and <out>.rtk.csv
    check_run_outputs(args, out, kfgins_folder=args.out_format == "kfgins",
                      sidecars=(".rtk.pos", ".rtk.csv") if getattr(args, "base", None) else ())
    streamed = None
    if args.format in ("kfgins", "csv") and getattr(args, "stream", "auto") != "off":
        streamed = _try_stream(args, out, groups)
    elif getattr(args, "stream", "auto") == "on":
        import sys

        print(f"note: the IMU file is read whole, not block by block: --format {args.format} (block by block: "
              "--format kfgins and --format csv)", file=sys.stderr)
    try:
        if streamed is not None:
            return _finish_run(args, out, groups, stages, streamed)
    finally:
        if streamed is not None:  # renamed into place when the run succeeded; else removed here
            streamed[0].discard()
    try:
        from ..io.input_formats import input_format

        fmt = input_format(args.format)
        try:
            fmt.check(args)
        except ValueError as exc:
            raise UserError(str(exc)) from None
        loaded = fmt.load(args)
        ds, cfg = loaded.dataset, loaded.config
        rinex_opts, csv_tables = loaded.tables.get("rinex"), loaded.tables.get("csv")
        if csv_tables is not None:
            print(ds.info["initial_state"])
            import sys

            for w in ds.info.get("warnings", ()):  # e.g. velocities that lag their positions ([gnss] velocity_lag_s)
                print(f"warning: {w}", file=sys.stderr)
        cfg = _cli_config(args, cfg)
        if args.output_rate is not None:
            cfg.output_decimation = output_decimation(ds.imu.t, args.output_rate)
        run_opts, base_e = {}, None
        fix_systems = ds.info.get("fix_systems", "G") if rinex_opts is not None else None
        if fix_systems is not None and fix_systems != rinex_opts.systems and (args.coupling or cfg.coupling) == "loose":
            import sys

            print(f"note: the loose filter reads single-point fixes of {fix_systems} (the start's); [rinex] systems = "
                  f"\"{rinex_opts.systems}\" gives the tight filter its other rows", file=sys.stderr)
        if (args.coupling or cfg.coupling) == "rtk":
            ds, run_opts = _rtk_ins_inputs(args, ds, cfg)
            base_e = ds.base_position_e_m
        stages.done("read")
        from .._progress import reporting

        with reporting(f"insnav run {args.filter or cfg.filter}", enabled=not args.quiet):
            sol = insnav.run(ds, filter=args.filter, coupling=args.coupling, config=cfg, **run_opts)
    except ConfigError as exc:
        msg = str(exc)
        if args.config and str(args.config) not in msg:  # a key of the file, or one the flags made wrong
            msg += f" (set in {args.config} or on the command line)"
        raise UserError(msg) from None
    return _report_and_write(args, out, groups, stages, sol, ds, cfg, rinex_opts, csv_tables,
                             run_opts=run_opts, base_e=base_e)


def _finish_run(args, out: Path, groups, stages, streamed) -> int:
    """The end of a run made block by block: its timings, then the checks, files and report of any run."""
    res, made = streamed
    stages.times.update(read=res.timings["read"], filter=res.timings["filter"])
    stages.t_last = stages._clock()
    stages.times["write"] = res.timings["write"]
    csv_tables = None
    info = getattr(res.dataset, "info", None)
    if args.format == "csv" and info is not None:  # as the batch path prints them (before its run)
        import sys

        print(info["initial_state"])
        for w in info.get("warnings", ()):
            print(f"warning: {w}", file=sys.stderr)
        csv_tables = info["tables"]
    return _report_and_write(args, out, groups, stages, res.solution, res.dataset, res.config, None, csv_tables,
                             streamed_files=res.files, made=made)


def _report_and_write(args, out: Path, groups, stages, sol, ds, cfg, rinex_opts, csv_tables, *, streamed_files=None,
                      made=None, run_opts=None, base_e=None) -> int:
    """The run's checks (gate, free inertial, health), its files (all or none) and its report line;
    ``streamed_files``: the (temporary file, destination) pairs of a run written block by block;
    ``run_opts`` / ``base_e``: an RTK/INS run's keywords and the base position it was given."""
    run_opts = run_opts or {}
    s = sol.summary
    used, rejected = int(s.get("updates", 0)), int(s.get("rejected", 0))
    records = int(s.get("gnss_records", len(getattr(ds, "gnss", ())) or 0))
    outside, cut = _outside_imu_span(sol, ds)
    records += cut  # the records the loader left out count too
    weighting = getattr(ds, "weighting", None)
    gate_failed = not args.allow_free_inertial and rejected > MAX_REJECTED_SHARE * (used + rejected)
    if gate_failed:  # what the data point to: a time offset, a mirrored track, the initial yaw
        from ..data.checks import disagreement_hint

        hint = disagreement_hint(ds)
    del ds  # the IMU arrays are not needed any more: their memory goes before the output is written
    san = s.get("sanitize") or {}
    dropped = int(san.get("gnss_invalid_dropped", 0) or 0) + int(san.get("gnss_duplicates_dropped", 0) or 0)
    if not args.allow_free_inertial:
        if gate_failed:
            raise UserError(f"{rejected} of {used + rejected} GNSS updates were rejected by the innovation gate "
                            f"(> {MAX_REJECTED_SHARE:.0%}): the fixes and the IMU disagree; {hint} "
                            "(--allow-free-inertial to accept the run)")
        if used == 0:
            raise UserError(f"no GNSS update was used ({records} records, {dropped} dropped): the run is free "
                            "inertial; check the GNSS time base, sigmas and units (--allow-free-inertial to "
                            "accept it)")
    health = s.get("health") or {}
    if health and not health.get("healthy", True) and not args.allow_unhealthy:
        raise UserError(f"unhealthy solution: {health['reason']} (--allow-unhealthy to write it)")
    stages.done("filter")
    from ..filters.solution import write_innovations

    from .._atomic import output_set
    from .._outputs import insnav_output_kind

    first = out if args.out_format == "kfgins" else out.parent
    made = list(made or ()) + [d for d in (first, *first.parents) if not d.exists()]  # removed if the writes fail
    try:
        # every file of the run or, on an error (a full disk, Ctrl-C), none: each is written to a
        # temporary file beside its destination and all are renamed into place at the end
        with output_set() as files:
            files.replaces(_run_outputs(out, args.out_format == "kfgins", (".rtk.pos", ".rtk.csv")),
                           insnav_output_kind)  # an earlier run's sidecars this run does not write: removed
            if streamed_files is not None:  # written block by block (filters/stream.py): renamed with the rest
                from .._atomic import _finish

                for tmp, dest in streamed_files:
                    _finish(tmp, dest)
                base = streamed_files[0][1]  # the solution file, or the KF-GINS .nav
            elif args.out_format == "kfgins":
                from ..io.kfgins import write_kfgins_solution

                out.mkdir(parents=True, exist_ok=True)
                base = write_kfgins_solution(out, sol)[0]
            else:
                sol.save(out, columns=groups, precision=args.csv_precision)
                base = out
            if streamed_files is None:  # a run written block by block wrote its sidecar as it went
                write_innovations(sol, base)
            if getattr(sol, "rtk", None) is not None and s.get("coupling") == "rtk":  # RTK/INS: per rover epoch
                from ..gnss.rtk import write_rtk_table, write_rtklib_pos

                write_rtklib_pos(sol.rtk, base.with_suffix(base.suffix + ".rtk.pos"), program="insnav rtk/ins")
                write_rtk_table(sol.rtk, base.with_suffix(base.suffix + ".rtk.csv"), t_solution_s=sol.gnss_t)
            cfg.filter = sol.summary.get("filter", cfg.filter)
            cfg.coupling = sol.summary.get("coupling", cfg.coupling)
            cfg.layout = s.get("state_layout", cfg.layout)  # a tight run's 17 or 20, chosen from the data
            tables = {}
            if rinex_opts is not None:
                tables["rinex"] = rinex_opts
                if weighting is not None and not weighting.is_default:
                    tables["gnss"] = weighting
            if cfg.coupling == "rtk":  # RTK/INS: the [rtk] options it ran with and the engine keys given
                tables["rtk"] = _rtk_table(sol.rtk_options, base_e)
                from ..filters.rtk_ins import MOVED_TO_RTK  # in [rtk] now (the resolved options above)

                tables["rtk_engine"] = {k: v for k, v in (run_opts.get("engine") or {}).items()
                                        if k not in MOVED_TO_RTK} or None
            text = resolved_config_toml(cfg, tables)
            if csv_tables is not None:
                text += _csv_tables_toml(csv_tables, cfg.imu is not None)
            atomic_write_text(base.with_suffix(base.suffix + ".config.toml"), text)
    except BaseException:
        for d in made:  # the folders this run created, when the failed write left them empty
            try:
                d.rmdir()
            except OSError:
                break
        raise
    print(f"{out}: {len(sol)} rows, filter {s.get('filter')}, {s.get('coupling')} coupling; GNSS: {records} "
          f"records" + (f" ({outside} outside the run's IMU time span, not used)" if outside else "")
          + f", {used} updates used, {rejected} rejected by the gate"
          + (f" ({s['gate_reopened']} applied anyway with the covariance scaled after a run of rejections, gate_reopen_after)"
             if s.get("gate_reopened") else "")
          + f", {dropped} dropped by the input checks; "
          f"{s.get('cholesky_repairs', 0)} covariance repairs"
          + (f"; robust: {s.get('rejected_sats', 0)} satellite-epochs rejected, {s.get('downweighted_sats', 0)} "
             f"down-weighted ({s.get('flagged_epochs', 0)} epochs flagged), {s.get('clock_jumps', 0)} clock jumps"
             if s.get("robust_screening") or s.get("clock_jumps") else "")
          + (f"; {s['fde_excluded']} satellite-epochs excluded by FDE, {s.get('cusum_alarms', 0)} CUSUM alarms"
             if s.get("robust_screening") else "")
          + (f"; {s['gate_outage_accepted']} records after outages accepted by the outage-aware gate"
             if s.get("gate_outage_accepted") else "")
          + (f"; TDCP: {s['tdcp_used']} rows used in {s['tdcp_updates']} epochs, {s['tdcp_rejected']} rejected by "
             f"the chi-square, slips {s['tdcp_slips_lli']} by LLI and {s['tdcp_slips_ins']} by the INS-predicted test"
             if s.get("tdcp") else ""))
    if "time_offset_test" in s:  # [time] estimate_offset = "auto" (docs/algorithms.md section 21)
        tt = s["time_offset_test"]
        print(f"time offset: {tt['estimate_ms']:+.2f} +- {tt['sigma_ms']:.2f} ms, |t_d / sigma| {abs(tt['z']):.2f} "
              f"{'>' if tt['state_kept'] else '<='} {tt['threshold_z']:.2f}: the run "
              + ("with the state kept" if tt["state_kept"] else "without the state kept (estimate_offset = \"auto\")"))
    elif "time_offset_ms" in s:
        print(f"time offset: {s['time_offset_ms']:+.2f} +- {s['sigma_time_offset_ms']:.2f} ms")
    for key, what in (("lever_arm_b_m", "GNSS lever arm"), ("odo_lever_arm_b_m", "odometer lever arm")):
        if key in s:  # [lever_arm] estimate / estimate_odometer: the last estimate (body FRD)
            print(f"{what} (body x, y, z): {', '.join(f'{v:+.3f}' for v in s[key])} +- "
                  f"{', '.join(f'{v:.3f}' for v in s['sigma_' + key])} m")
    if health:
        import sys

        print(f"health: {'ok' if health['healthy'] else 'UNHEALTHY (' + health['reason'] + ')'}; consistency "
              f"{health['consistency']} (mean NIS / rows {health['nis_ratio']:.3g}; consistent within "
              f"1/3 .. 3)")
        for w in health.get("warnings", ()):
            print(f"warning: {w}", file=sys.stderr)
    stages.done("write")
    if args.timings:
        import sys

        print(stages.line(), file=sys.stderr)
    return 0
