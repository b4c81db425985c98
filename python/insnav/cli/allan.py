"""``insnav allan``: Allan-variance noise identification of a static IMU log."""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import numpy as np

from ..analysis.allan_plot import _MARK, allan_figure, read_curve_csv
from ..analysis.allan_plot import term_cells
from ..analysis.allan_plot import units as _units
from ..errors import UserError

EXAMPLES = """examples:
  insnav allan static_24h.txt                                   # KF-GINS text (sow, dtheta, dvel)
  insnav allan run1                                             # an insnav dataset folder (its imu.csv)
  insnav allan imu.csv --format csv --config run.toml --out-dir imu-allan   # your CSV, mapped by [imu]
  insnav allan imu.csv --format rinex --config walk.toml        # the [rinex] table's IMU columns

The IMU must be at rest (a static log, ideally 2-24 h): the overlapping Allan deviation of
every gyro and accelerometer axis is computed (octave-spaced tau, --per-octave for more),
and the IEEE Std 952 terms are fitted by weighted least squares with 95 % intervals:
quantisation Q, angle/velocity random walk N, bias instability B, rate random walk K, rate
ramp R.  Units: gyro deg/sqrt(h), deg/h, deg/h/sqrt(h), deg/h/h, arcsec; accel m/s/sqrt(h),
mg, mg/sqrt(h), mg/h, m/s.

--out-dir gets allan.png (the curves, the fit and the intervals), allan.csv (tau and the
deviations), allan_terms.txt (the table printed) and imu_noise.toml: the [imu] noise keys for
`insnav run --config` (ARW/VRW, bias instability as a Gauss-Markov bias, rate random walk;
docs/algorithms.md).  A log shorter than 9 s (tau above 1 s), a moving IMU (specific force
of successive 1 s averages changing by more than 0.05 m/s^2 rms) and gaps in the sampling are
refused with one line."""

#: tau = 1 s needs this many independent clusters (25 % estimate error, IEEE Std 952 Annex C.4: 1/sqrt(2(K-1)))
MIN_CLUSTERS = 9
#: below this duration the slopes >= 0 (bias instability, rate random walk, ramp) are poorly resolved [s]
SHORT_LOG_S = 2 * 3600.0

OUT_FILES = ("allan.png", "allan.csv", "allan_terms.txt", "imu_noise.toml")


def add_allan_parser(sub) -> None:
    p = sub.add_parser("allan", help="Allan-variance noise identification of a static IMU log -> [imu] noise TOML",
                       description="Overlapping Allan deviation per axis, IEEE Std 952 noise terms with "
                                   "confidence intervals, a plot and the filter's [imu] noise keys.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("imu", metavar="IMU_FILE", help="IMU log: KF-GINS text, an insnav dataset folder or its imu.csv, "
                   "or (with --format csv|rinex and --config) your own CSV")
    p.add_argument("--format", choices=("auto", "kfgins", "insnav", "csv", "rinex"), default="auto",
                   help="auto: a folder is an insnav dataset, a file with the header t_s,dtheta_x_rad,... its "
                        "imu.csv, else KF-GINS 7-column text")
    p.add_argument("--config", help="--format csv: a run TOML whose [imu] table maps the columns and units; "
                   "--format rinex: one with a [rinex] table (docs/formats.md)")
    p.add_argument("--imu-tag", help="str2str time tag of a raw log with a tick_ms column (--format csv|rinex)")
    p.add_argument("--out-dir", default=None,
                   help="folder of the outputs (default: <IMU_FILE name>-allan in the current folder)")
    p.add_argument("--per-octave", type=int, default=1, metavar="K",
                   help="averaging times per octave (1: tau0, 2 tau0, 4 tau0, ...; up to 16 for a denser curve)")
    p.add_argument("--no-plot", action="store_true", help="no allan.png (no matplotlib needed)")
    p.add_argument("--allow-motion", action="store_true",
                   help="analyse a log whose specific force shows motion (the noise terms are then wrong)")
    p.add_argument("--allow-gaps", action="store_true",
                   help="analyse a log with gaps or irregular sampling as if uniformly sampled")
    p.add_argument("--overwrite", action="store_true",
                   help="replace files in --out-dir that an earlier `insnav allan` did not write")
    p.add_argument("--threads", type=int, default=0, help="threads for the axes (default: all cores)")
    p.set_defaults(func=cmd_allan)


# --------------------------------------------------------------------------- reading

def _first_data_line(path: Path) -> str:
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("utf-8", "replace").strip()
            if line and not line.startswith("#"):
                return line
    return ""


def read_rates(path, fmt: str = "auto", config=None, imu_tag=None) -> dict:
    """The IMU log as rates: ``t_s`` (n,), ``gyro_radps`` (n, 3), ``acc_mps2``
    (n, 3), ``lines`` (n,) file lines (or None), ``path``.  Increments are
    divided by the median interval (their sum is then the integrated angle and
    velocity, exactly); rate samples are used as they are (no integration).
    """
    from ..config import ConfigError

    p = Path(path)
    if not p.exists():
        raise UserError(f"{p}: no such file or folder")
    if fmt == "auto":
        if p.is_dir():
            fmt = "insnav"
        else:
            first = _first_data_line(p)
            fmt = "insnav" if first.replace(" ", "").startswith("t_s,dtheta_x_rad") else "kfgins"
    try:
        if fmt in ("csv", "rinex"):
            samples = _read_mapped(p, fmt, config, imu_tag)
            t = samples.t_s
            if samples.samples == "increment":
                tau0 = _median_interval(t, str(p))
                with np.errstate(over="ignore"):  # an overflow is named by check_log
                    return dict(t_s=t, gyro_radps=samples.gyro_b / tau0, acc_mps2=samples.acc_b / tau0,
                                lines=samples.lines, path=str(p))
            return dict(t_s=t, gyro_radps=samples.gyro_b, acc_mps2=samples.acc_b, lines=samples.lines, path=str(p))
        if fmt == "insnav":
            from ..data.dataset import ImuData, check_finite_rows, read_csv

            f = p / "imu.csv" if p.is_dir() else p
            if not f.is_file():
                raise UserError(f"{f}: no such file (an insnav dataset folder holds imu.csv)")
            a, origin = read_csv(f, ImuData.COLUMNS, return_origin=True)
            check_finite_rows(a, origin, ImuData.COLUMNS)
            imu = ImuData.from_array(a)
            imu.origin = origin
            path_s = str(f)
        elif fmt == "kfgins":
            from ..io.kfgins import read_kfgins_imu

            if p.is_dir():
                raise UserError(f"{p}: a folder; --format kfgins reads a KF-GINS IMU text file")
            imu = read_kfgins_imu(p)
            path_s = str(p)
        else:
            raise UserError(f"--format {fmt}: unknown")
    except (ValueError, ConfigError, OSError) as exc:
        if isinstance(exc, UserError):
            raise
        raise UserError(str(exc).splitlines()[0]) from None
    t = np.asarray(imu.t, float)
    tau0 = _median_interval(t, path_s)
    lines = imu.origin.all_lines(len(t)) if imu.origin is not None else None
    with np.errstate(over="ignore"):  # an overflow is named by check_log
        return dict(t_s=t, gyro_radps=imu.dtheta_b / tau0, acc_mps2=imu.dv_b / tau0, lines=lines, path=path_s)


def _interval_error(path: str, tau0: float) -> UserError:
    return UserError(f"{path}: median sample interval {tau0:.6g} s: the time tags repeat (or decrease) at most "
                     "samples; the Allan variance needs the IMU's own sampling times")


def _median_interval(t, path: str) -> float:
    """The median sample interval [s] of increments (NaN for fewer than 2 samples: check_log names that);
    a one-line error naming the file when it is not positive (every time tag repeated)."""
    if t.size < 2:
        return math.nan
    tau0 = float(np.median(np.diff(t)))
    if not tau0 > 0:
        raise _interval_error(path, tau0)
    return tau0


def _read_mapped(p: Path, fmt: str, config, imu_tag):
    """--format csv|rinex: the IMU CSV mapped by the config's [imu] or [rinex] table."""
    from ..config import ConfigError, read_toml
    from ..io.imu_csv import ImuCsvFormat, read_imu_csv

    if not config:
        raise UserError(f"--format {fmt} needs --config (a TOML whose "
                        f"{'[imu]' if fmt == 'csv' else '[rinex]'} table maps the IMU columns and units)")
    d = read_toml(config)  # one line naming the file: unreadable, not TOML, not UTF-8
    base = os.path.dirname(os.path.abspath(config))
    if fmt == "csv":
        from ..io.csv_dataset import IMU_FORMAT_KEYS, IMU_KEYS, _table

        imu_d = _table(d, "imu", IMU_KEYS, str(config))
        imf = ImuCsvFormat(**{k: v for k, v in imu_d.items() if k in IMU_FORMAT_KEYS})
        imf.validate(str(config), prefix="imu.")
        tag = imu_tag if imu_tag is not None else imu_d.get("tag")
    else:
        from ..io.rinex_dataset import RinexOptions

        rin = d.get("rinex", {})
        if not isinstance(rin, dict):
            raise ConfigError(f"{config}: key 'rinex': bad value {rin!r}; allowed: a table")
        opt = RinexOptions.from_dict(rin, str(config))
        imf = opt.imu_format()
        tag = imu_tag if imu_tag is not None else getattr(opt, "imu_tag", None)
    if isinstance(tag, str) and not os.path.isabs(tag):
        tag = os.path.join(base, tag)
    if tag is None and imf.uses_tick:
        for cand in (Path(str(p) + ".tag"), p.with_suffix(".tag")):
            if cand.is_file():
                tag = str(cand)
                break
    return read_imu_csv(p, imf, tag=tag)


# --------------------------------------------------------------------------- checks

#: rates beyond any IMU's range (a tactical gyro's is a few thousand deg/s, a MEMS accelerometer's
#: a few hundred g): such a sample is a corrupted record, refused before the Allan sums overflow
MAX_RATE_RADPS = 1.0e3
MAX_SPECIFIC_FORCE_MPS2 = 1.0e4


def check_log(d: dict, *, allow_gaps: bool = False, allow_motion: bool = False) -> tuple[float, list[str]]:
    """Sampling, length and rest checks of :func:`read_rates` output: the sample
    interval tau0 [s] and notes to print; a one-line UserError naming the file
    for a log that cannot give a meaningful Allan analysis."""
    from ..calib.allan import check_sampling, check_static

    path, t = d["path"], d["t_s"]
    n = t.size
    if n < 4:
        raise UserError(f"{path}: {n} IMU samples: an Allan analysis needs a long static log")
    for what, a, limit, unit in (("gyro", d["gyro_radps"], MAX_RATE_RADPS, "rad/s"),
                                 ("accelerometer", d["acc_mps2"], MAX_SPECIFIC_FORCE_MPS2, "m/s^2")):
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1) | np.any(np.abs(a) > limit, axis=1))
        if bad.size:  # e.g. an increment of 1e308 divided by the interval, or a rate of 1e308
            i = int(bad[0])
            at = f", line {int(d['lines'][i])}" if d.get("lines") is not None else f", sample {i + 1}"
            raise UserError(f"{path}{at}: the {what} sample is not a finite number below {limit:g} {unit} as a rate "
                            f"({', '.join(f'{v:.6g}' for v in a[i])}): a corrupted record?")
    s = check_sampling(t)
    tau0 = s["tau0_s"]
    if not tau0 > 0:  # rate samples (read_rates did not need the interval)
        raise _interval_error(path, tau0)
    notes = []
    if not s["uniform"]:
        if s["gaps"].size:
            i = int(s["gaps"][0])
            line = f", line {int(d['lines'][i + 1])}" if d.get("lines") is not None else ""
            what = (f"{s['gaps'].size} gap(s) or repeated times in the sampling (first after t = {t[i]:.6f} s{line}: "
                    f"interval {t[i + 1] - t[i]:.6g} s, median {tau0:.6g} s)")
        else:
            what = f"irregular sampling (interval jitter {100 * s['jitter']:.2g} % rms of the median {tau0:.6g} s)"
        if not allow_gaps:
            raise UserError(f"{path}: {what}; the Allan variance needs uniform sampling: analyse a gap-free "
                            "stretch, or --allow-gaps to treat the samples as uniform")
        notes.append(f"note: {what}; analysed as uniform (--allow-gaps)")
    T = n * tau0
    if T < MIN_CLUSTERS * 1.0:
        raise UserError(f"{path}: log too short for tau above 1 s: {T:.3g} s of data ({n} samples at "
                        f"{1 / tau0:.4g} Hz); tau = 1 s needs at least {MIN_CLUSTERS} s ({MIN_CLUSTERS} clusters), "
                        "and bias instability and rate random walk need hours of static data")
    if T < SHORT_LOG_S:
        notes.append(f"note: {T / 60:.3g} min of data: tau is resolved up to {T / MIN_CLUSTERS:.3g} s; bias "
                     "instability, rate random walk and ramp need a 2-24 h static log")
    st = check_static(d["acc_mps2"], tau0)
    if not st["static"]:
        what = (f"not static: the specific force of successive 1 s averages changes by {st['stat_mps2']:.3g} m/s^2 "
                f"rms on axis {'xyz'[st['axis']]} (threshold {st['threshold_mps2']:g} m/s^2 for an IMU at rest; "
                f"largest change {st['worst_t_s']:.0f} s after the start)")
        if not allow_motion:
            raise UserError(f"{path}: {what}; the Allan variance of a moving IMU measures the motion, not the "
                            "sensor noise (--allow-motion to analyse it anyway)")
        notes.append(f"note: {what}; analysed anyway (--allow-motion)")
    return tau0, notes


# --------------------------------------------------------------------------- outputs

def terms_table(fits_g, fits_a) -> str:
    """The fitted terms with their intervals, one row per axis, user units."""
    from ..calib.allan import TERMS

    u = _units()
    head = ["axis"] + [f"{k} [{u[k][0][0]} | {u[k][1][0]}]" for k in TERMS]
    rows = [[axis, *cells] for axis, cells in term_cells(fits_g, fits_a)]
    widths = [max(len(r[i]) for r in [head] + rows) for i in range(len(head))]
    out = ["  ".join(h.ljust(w) for h, w in zip(head, widths))]
    out += ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows]
    conf = fits_g[0].confidence if fits_g else 0.95
    out.append(f"(value ({100 * conf:g} % interval); '< x': not resolved by this log (below twice its standard "
               "deviation), x its upper bound; '-': zero in the fit; gyro | accel units)")
    return "\n".join(out) + "\n"


def curve_csv(curve, path_in: str) -> str:
    """tau, cluster size, independent clusters and the deviation of each axis (gyro deg/h, accel mg)."""
    from ..units import DEG_PER_H, MG

    cols = ["tau_s", "m", "clusters"] + [f"adev_{a}_dph" for a in "xyz"] + [f"adev_{a}_mg" for a in "xyz"]
    lines = [f"{_MARK} {path_in}", ",".join(cols)]
    scale = np.array([1 / DEG_PER_H] * 3 + [1 / MG] * 3)
    for i in range(curve.tau_s.size):
        v = curve.adev[i] * scale
        lines.append(f"{curve.tau_s[i]:.9g},{curve.m[i]},{curve.clusters[i]}," + ",".join(f"{x:.6g}" for x in v))
    return "\n".join(lines) + "\n"


def plot_allan(path, curve, fits_g, fits_a, title: str) -> None:
    """allan.png: :func:`allan_figure` written atomically."""
    from .._atomic import atomic_write_with

    data = allan_figure(curve, fits_g, fits_a, title)
    atomic_write_with(path, lambda tmp: Path(tmp).write_bytes(data))


def _written_by_allan(f: Path) -> bool:
    """Whether ``f`` (one of :data:`OUT_FILES`) holds an earlier ``insnav allan`` output, by its own first
    bytes: each file is checked, so a hand-edited imu_noise.toml beside an allan.csv is not replaced."""
    import re
    import stat

    from ..analysis.allan_plot import PNG_SOFTWARE

    try:
        if not stat.S_ISREG(os.stat(f).st_mode):  # a FIFO would block the read
            return False
        with open(f, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    if f.name == "allan.csv":
        return head.startswith(_MARK.encode())
    if f.name == "imu_noise.toml":
        return head.startswith(b"# IMU noise identified by insnav allan")
    if f.name == "allan_terms.txt":
        return re.match(rb"[^\n]*: \d+ samples at [^\n]* Hz, [^\n]*; overlapping Allan deviation at ", head) is not None
    return head.startswith(b"\x89PNG") and PNG_SOFTWARE.encode() in head


def _check_out_dir(out: Path, inputs: list, overwrite: bool) -> None:
    from .._outputs import check_writable, input_files

    ins = input_files(*inputs)
    for name in OUT_FILES:
        f = out / name
        if not f.exists():
            continue
        from .._outputs import file_id

        if file_id(f) in ins:
            raise UserError(f"--out-dir {out}: {f} is an input of this analysis: choose another --out-dir")
        if f.is_dir():
            raise UserError(f"--out-dir {out}: {f} is a folder")
        if not overwrite and not _written_by_allan(f):
            raise UserError(f"{f} exists and was not written by insnav allan: not replaced (another --out-dir, or "
                            "--overwrite)")
    if out.exists() and not out.is_dir():
        raise UserError(f"--out-dir {out} is a file: give a folder")
    check_writable(out if out.exists() else out.parent if str(out.parent) else Path("."))


def cmd_allan(args) -> int:
    import time

    from ..calib.allan import allan_deviation, fit_allan, imu_noise_toml

    if not args.no_plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise UserError("insnav allan draws allan.png with matplotlib: pip install 'insnav[plot]' "
                            "(or --no-plot)") from None
    if not 1 <= args.per_octave <= 16:
        raise UserError(f"--per-octave {args.per_octave}: allowed 1..16")
    imu_path = Path(args.imu)
    out = Path(args.out_dir) if args.out_dir else Path(f"{imu_path.name.rstrip('/') or 'imu'}-allan")
    inputs = [args.imu, args.config, args.imu_tag] + ([str(imu_path / "imu.csv")] if imu_path.is_dir() else [])
    _check_out_dir(out, inputs, args.overwrite)

    d = read_rates(imu_path, args.format, args.config, args.imu_tag)
    tau0, notes = check_log(d, allow_gaps=args.allow_gaps, allow_motion=args.allow_motion)
    axes = ("gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")
    c0 = time.perf_counter()
    curve = allan_deviation([d["gyro_radps"], d["acc_mps2"]], tau0, per_octave=args.per_octave, axes=axes,
                            threads=args.threads)
    t_adev = time.perf_counter() - c0
    fits = [fit_allan(curve, a) for a in range(6)]
    fits_g, fits_a = fits[:3], fits[3:]
    n = d["t_s"].size
    head = (f"{d['path']}: {n} samples at {1 / tau0:.6g} Hz, {n * tau0 / 3600:.3g} h; overlapping Allan deviation "
            f"at {curve.tau_s.size} averaging times {curve.tau_s[0]:.3g}..{curve.tau_s[-1]:.4g} s in {t_adev:.2f} s")
    table = terms_table(fits_g, fits_a)
    toml = imu_noise_toml(fits_g, fits_a, source=d["path"])
    from .._atomic import atomic_write_text, output_set

    out.mkdir(parents=True, exist_ok=True)
    with output_set():
        atomic_write_text(out / "allan.csv", curve_csv(curve, d["path"]))
        atomic_write_text(out / "allan_terms.txt", head + "\n" + "\n".join(notes) + ("\n" if notes else "") + table)
        atomic_write_text(out / "imu_noise.toml", toml)
        if not args.no_plot:
            plot_allan(out / "allan.png", curve, fits_g, fits_a, head)
    print(head)
    for note in notes:
        print(note)
    print(table, end="")
    print(f"-> {out}/: " + ", ".join(f for f in OUT_FILES if not (args.no_plot and f.endswith(".png"))))
    print(toml, end="")
    return 0
