"""Readers and writers for the KF-GINS text formats (i2Nav-WHU/KF-GINS).

Formats (whitespace separated, one record per line, no header):

* IMU file: ``sow dtheta_x dtheta_y dtheta_z dvel_x dvel_y dvel_z`` [s, rad,
  m/s], increments over the preceding sample interval, body FRD (KF-GINS
  uses the first ``imudatalen`` = 7 columns; extra columns are ignored);
* GNSS-RTK file: ``sow lat lon h std_N std_E std_D`` [s, deg, deg, m, m]
  (antenna phase centre); a 13-column variant adds ``vN vE vD std_vN std_vE
  std_vD`` [m/s];
* ``.nav`` solution/truth: ``week sow lat lon h vN vE vD roll pitch yaw``
  [-, s, deg, deg, m, m/s, deg];
* YAML configuration (``kf-gins.yaml``): read by :func:`read_kfgins_config`
  into SI values.

Files ending in ``.xz``, ``.gz`` or ``.bz2`` are decompressed transparently.
Malformed input raises ``ValueError("<file>:<line>: <reason>")`` (1-based):
wrong column count (an incomplete last line is flagged as a truncated file),
non-numeric fields, NaN/inf in the IMU file or in a GNSS time, decreasing IMU
time.  Repeated IMU times pass and are handled by :mod:`insnav.filters.sanitize` (an
exact duplicate is dropped and counted).  The returned data carry the file
line of each row (``origin``) for later messages.
The readers parse the text with the compiled reader (:mod:`insnav.data.textio`,
two threads); an uncompressed IMU file is memory-mapped and parsed straight
into ``t``, ``dtheta_b`` and ``dv_b`` (the 76 MB KF-GINS IMU file in about
0.1 s; from the ``.xz`` about 1.3 s, the decompression).
"""
from __future__ import annotations

from ..errors import close_matches

import bz2
import gzip
import lzma
import math
from pathlib import Path

import numpy as np

from .._imu_scan import scan_imu
from ..data.dataset import GnssFixes, ImuData, RowOrigin, Truth, check_finite_rows
from ..data.textio import count_columns, file_bytes, parse_numeric, read_bytes
from ..units import DEG, PPM

HOUR = 3600.0  #: h -> s
MGAL = 1e-5  #: mGal -> m/s^2

IMU_COLUMNS = ("sow", "dtheta_x", "dtheta_y", "dtheta_z", "dvel_x", "dvel_y", "dvel_z")

__all__ = ["read_kfgins_imu", "write_kfgins_imu", "read_kfgins_gnss", "write_kfgins_gnss",
           "read_kfgins_nav", "write_kfgins_nav", "read_kfgins_config", "read_text", "write_kfgins_solution",
           "KFGINS_NAV_FILE", "KFGINS_IMU_ERR_FILE",
           "KFGINS_STD_FILE"]

#: the file names KF-GINS gives its results in ``outputpath`` (src/kf_gins.cpp)
KFGINS_NAV_FILE = "KF_GINS_Navresult.nav"
KFGINS_IMU_ERR_FILE = "KF_GINS_IMU_ERR.txt"
KFGINS_STD_FILE = "KF_GINS_STD.txt"


def read_text(path) -> str:
    """Whole file as text, decompressing ``.xz``/``.gz``/``.bz2`` (a truncated
    compressed file: one-line ``ValueError`` naming it)."""
    return read_bytes(path).decode("utf-8", errors="replace")


def _read_rows(path, ncols=None, keep=None, names=None, min_cols=None, groups=None):
    """(rows, RowOrigin, ncols) of a whitespace-separated KF-GINS text file:
    the C++ reader, lines counted as it parses (rows: a tuple of arrays with ``groups``)."""
    with file_bytes(path) as data:
        n = ncols or count_columns(data, path)
        if min_cols is not None and n < min_cols:
            return None, None, n
        a, lines = parse_numeric(data, n, str(path), comma=False, keep=keep, names=names, groups=groups)
    return a, RowOrigin(str(path), 1, lines), n


def _read_table(path, ncols, min_cols=None):
    return _read_rows(path, ncols)[0]


def read_kfgins_imu(path, ncols: int | None = None) -> ImuData:
    """Read a KF-GINS IMU text file.

    Parameters
    ----------
    path : str or Path
    ncols : int, optional
        Columns per line (default: those of the first line, at least 7);
        only the first 7 are used.

    Returns
    -------
    ImuData
        ``t`` = GPS seconds of week [s], increments [rad], [m/s].
    """
    # parsed straight into t, dtheta_b and dv_b (no (N, 7) table to split and copy)
    parts, origin, n = _read_rows(path, ncols, keep=7, names=IMU_COLUMNS, min_cols=7, groups=(1, 3, 3))
    if n < 7:
        raise ValueError(f"{path}:1: expected at least 7 columns (sow, dtheta xyz, dvel xyz), "
                         f"found {n}")
    t, dth, dv = parts
    if t.size == 0:
        raise ValueError(f"{path}:1: no IMU records (an empty file, or only blank and comment lines)")
    scan = scan_imu(t, dth, dv)  # one compiled pass for both checks below
    if scan["nonfinite_t"] >= 0 or scan["nonfinite_dtheta"] >= 0 or scan["nonfinite_dv"] >= 0:
        check_finite_rows(parts, origin, IMU_COLUMNS)  # the message: file, line, value and column
    # decreasing time is an error; equal times (duplicated records) are left to
    # insnav.filters.sanitize.sanitize_imu, which drops exact duplicates and counts them
    i = scan["decrease"]
    if i >= 0:
        raise ValueError(f"{origin.where(i)}: time {float(t[i])!r} does not increase "
                         f"(previous record at {float(t[i - 1])!r}, line {origin.line(i - 1)})")
    return ImuData(t, dth, dv, origin=origin)


def write_kfgins_imu(path, imu: ImuData) -> None:
    """Write ``imu`` as a 7-column KF-GINS IMU file (``t`` written as seconds of week)."""
    a = np.column_stack([imu.t, imu.dtheta_b, imu.dv_b])
    _write(path, a, "%.9f" + " %.15e" * 6)


def read_kfgins_gnss(path, *, compact: bool = False) -> GnssFixes:
    """Read a KF-GINS GNSS file (7 columns, or 13 with velocity).

    Parameters
    ----------
    path : str or Path
    compact : bool
        Hold each value once (the block-by-block run, which only reads the
        fixes): ``t_arrival`` is the ``t_valid`` array itself and the 7-column
        file's ``v_n``/``sigma_vel_n`` are read-only NaN views of one row, so a
        day of 1 Hz fixes takes 7 float64 per record instead of 14.

    Returns
    -------
    GnssFixes
        ``t_valid = t_arrival`` = sow; ``v_n``/``sigma_vel_n`` NaN for the
        7-column file.
    """
    data = read_bytes(path)
    n = count_columns(data, path)
    if n not in (7, 13):
        raise ValueError(f"{path}:1: expected 7 or 13 columns (sow lat lon h std_N std_E std_D"
                         f" [vN vE vD std_vN std_vE std_vD]), found {n}")
    a, lines = parse_numeric(data, n, str(path), comma=False)
    origin = RowOrigin(str(path), 1, lines)
    check_finite_rows(a[:, :1], origin, ("sow",))
    k = a.shape[0]
    if compact:
        t = a[:, 0].copy()
        nan3 = np.broadcast_to(np.full(3, np.nan), (k, 3))
        v, sv = (a[:, 7:10].copy(), a[:, 10:13].copy()) if n == 13 else (nan3, nan3)
        return GnssFixes(t, t, a[:, 1].copy(), a[:, 2].copy(), a[:, 3].copy(), v, a[:, 4:7].copy(), sv,
                         origin=origin)
    v = a[:, 7:10] if n == 13 else np.full((k, 3), np.nan)
    sv = a[:, 10:13] if n == 13 else np.full((k, 3), np.nan)
    return GnssFixes(a[:, 0].copy(), a[:, 0].copy(), a[:, 1].copy(), a[:, 2].copy(),
                     a[:, 3].copy(), v.copy(), a[:, 4:7].copy(), sv.copy(), origin=origin)


def write_kfgins_gnss(path, fixes: GnssFixes, with_velocity: bool = False) -> None:
    """Write fixes as a KF-GINS GNSS file (time of validity; 13 columns with velocity)."""
    cols = [fixes.t_valid, fixes.lat_deg, fixes.lon_deg, fixes.h_m, fixes.sigma_pos_n]
    fmt = "%.3f %.10f %.10f %.4f %.4f %.4f %.4f"
    if with_velocity:
        cols += [fixes.v_n, fixes.sigma_vel_n]
        fmt += " %.5f %.5f %.5f %.5f %.5f %.5f"
    _write(path, np.column_stack(cols), fmt)


def read_kfgins_nav(path, return_week: bool = False):
    """Read a KF-GINS ``.nav`` file (solution or truth).

    Returns
    -------
    Truth
        ``t`` = sow; ``f_ib_b``/``omega_ib_b`` are None; ``origin`` the file line of each row.
    week : ndarray (N,), only with ``return_week=True``
    """
    a, origin, _ = _read_rows(path, 11)
    tr = Truth(a[:, 1].copy(), a[:, 2].copy(), a[:, 3].copy(), a[:, 4].copy(), a[:, 5:8].copy(),
               a[:, 8].copy(), a[:, 9].copy(), a[:, 10].copy())
    tr.origin = origin
    return (tr, a[:, 0].astype(np.int64)) if return_week else tr


def write_kfgins_nav(path, truth, week: int = 0) -> None:
    """Write a :class:`Truth` (or :class:`insnav.Trajectory`) as a KF-GINS ``.nav`` file."""
    n = len(truth.t)
    a = np.column_stack([np.full(n, week), truth.t, truth.lat_deg, truth.lon_deg, truth.h_m,
                         truth.v_n, truth.roll_deg, truth.pitch_deg, truth.yaw_deg])
    _write(path, a, "%d %.9f %.11f %.11f %.5f %.6f %.6f %.6f %.8f %.8f %.8f")


def write_kfgins_solution(folder, sol, week: int = 0) -> tuple[Path, ...]:
    """Write a solution in the KF-GINS result layout, so that scripts written
    for KF-GINS read it unchanged: ``KF_GINS_Navresult.nav`` (``week sow lat
    lon h vN vE vD roll pitch yaw`` [-, s, deg, deg, m, m/s, deg]) and
    ``KF_GINS_IMU_ERR.txt`` (``sow``, gyro bias [deg/h], accelerometer bias
    [mGal], gyro and accelerometer scale factors [ppm]) and, when the solution
    carries the IMU-error sigmas (``sol.sigma_imu_err``, run config
    ``imu_error_sigmas``), ``KF_GINS_STD.txt`` (``sow``, 1-sigma of position
    N/E/D [m], velocity [m/s], attitude [deg], gyro bias [deg/h], accelerometer
    bias [mGal], gyro and accelerometer scale factors [ppm]: 22 columns, KF-GINS's
    ``writeSTD``), every value as KF-GINS's ``FileSaver`` prints it
    (``"%-15.9lf "``, src/fileio/filesaver.cc; the week is 0 as KF-GINS writes
    it).  The files are written as one (:func:`insnav._atomic.output_set`): all
    or, on an error, none of them, older files untouched.

    Parameters
    ----------
    folder : str or Path
        Created if missing.
    sol : insnav.Solution
    week : int
        GPS week written in the first column.

    Returns
    -------
    tuple of Path
        The ``.nav`` and the IMU-error file (and the STD file when written).
    """
    from ..data.textio import write_text_columns
    from .._atomic import output_set

    folder = Path(folder)
    with output_set():  # all or none of the files (older ones untouched on an error)
        return tuple(write_text_columns(folder / name, "", cols, [KFGINS_DECIMALS] * len(cols), **KFGINS_TEXT_FORMAT)
                     for name, cols in kfgins_tables(sol, week))


#: KF-GINS's ``FileSaver`` text: ``"%-15.9lf "`` (src/fileio/filesaver.cc), as ``_core.write_table`` options
KFGINS_TEXT_FORMAT = dict(sep=" ", width=15, trim_zeros=False, trailing_sep=True)
KFGINS_DECIMALS = 9


def kfgins_tables(sol, week: int = 0) -> list:
    """The files of :func:`write_kfgins_solution` and their columns: ``[(file name,
    [(column, array (N,), unit factor), ...]), ...]`` for ``KF_GINS_Navresult.nav``,
    ``KF_GINS_IMU_ERR.txt`` and, when ``sol.sigma_imu_err`` is not None,
    ``KF_GINS_STD.txt`` (the arrays are views of the solution's; the value
    written is factor x array).  Shared by the whole-file writer and the
    block-by-block one (:mod:`insnav.filters.stream`), whose files must be the same."""
    from ..units import RAD2DEG

    n = len(sol.t)
    wk = np.full(n, float(week))
    v_n = np.asarray(sol.v_n)
    nav = [("week", wk, 1.0), ("sow", sol.t, 1.0), ("lat", sol.lat_deg, 1.0), ("lon", sol.lon_deg, 1.0),
           ("h", sol.h_m, 1.0)] + [(f"v{j}", v_n[:, j], 1.0) for j in range(3)] + \
        [("roll", sol.roll_deg, 1.0), ("pitch", sol.pitch_deg, 1.0), ("yaw", sol.yaw_deg, 1.0)]
    gb, ab = np.asarray(sol.gyro_bias_rps), np.asarray(sol.acc_bias_mps2)
    gs, as_ = np.asarray(sol.gyro_scale), np.asarray(sol.acc_scale)
    err = [("sow", sol.t, 1.0)] + [("gb", gb[:, j], RAD2DEG * HOUR) for j in range(3)] + \
        [("ab", ab[:, j], 1.0 / MGAL) for j in range(3)] + [("gs", gs[:, j], 1.0 / PPM) for j in range(3)] + \
        [("as", as_[:, j], 1.0 / PPM) for j in range(3)]
    tables = [(KFGINS_NAV_FILE, nav), (KFGINS_IMU_ERR_FILE, err)]
    if getattr(sol, "sigma_imu_err", None) is None:
        return tables
    se = np.asarray(sol.sigma_imu_err, float)
    sp, sv, sa = (np.asarray(x, float) for x in (sol.sigma_pos_n_m, sol.sigma_vel_n_mps, sol.sigma_att_deg))
    std = [("sow", sol.t, 1.0)] + [(f"sp{j}", sp[:, j], 1.0) for j in range(3)] + \
        [(f"sv{j}", sv[:, j], 1.0) for j in range(3)] + [(f"sa{j}", sa[:, j], 1.0) for j in range(3)] + \
        [(f"sgb{j}", se[:, 3 + j], RAD2DEG * HOUR) for j in range(3)] + \
        [(f"sab{j}", se[:, j], 1.0 / MGAL) for j in range(3)] + \
        [(f"sgs{j}", se[:, 9 + j], 1.0 / PPM) for j in range(3)] + [(f"sas{j}", se[:, 6 + j], 1.0 / PPM) for j in range(3)]
    return tables + [(KFGINS_STD_FILE, std)]


def _write(path, a, fmt):
    p = Path(path)
    opener = {".xz": lzma.open, ".gz": gzip.open, ".bz2": bz2.open}.get(p.suffix.lower())
    row = fmt + "\n"
    chunk = 100_000
    f = opener(p, "wt", encoding="ascii") if opener else open(p, "w", encoding="ascii")
    with f:
        for s in range(0, a.shape[0], chunk):
            blk = a[s:s + chunk]
            f.write((row * blk.shape[0]) % tuple(blk.ravel().tolist()))


def _vec(cfg, key, path, n=3, table=""):
    """The YAML list ``key`` (in the mapping ``table``, e.g. ``imunoise.``) as n finite
    floats; a standard deviation or a noise density (``*std``, the ``imunoise`` keys)
    must be >= 0 (KF-GINS squares it: a sign error would pass unseen)."""
    v = cfg.get(key)
    if v is None:
        return None
    if isinstance(v, list):  # 3e-3 is a string to PyYAML (YAML 1.1) but a number to yaml-cpp, so to KF-GINS
        v = [_yaml_cpp_number(x) for x in v]
    if not (isinstance(v, list) and len(v) == n
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):  # YAML true is not 1
        raise ValueError(f"{path}: key '{table}{key}': expected a list of {n} numbers, got {v!r}")
    a = np.array(v, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{path}: key '{table}{key}': expected {n} finite numbers, got {v!r}")
    if (key.endswith("std") or table == "imunoise.") and np.any(a < 0):
        raise ValueError(f"{path}: key '{table}{key}': a standard deviation or noise density must be >= 0, "
                         f"got {v!r}")
    return a


def _yaml_cpp_number(x):
    """``x``, or the float of a string yaml-cpp reads as a number (``3e-3``, which PyYAML's
    YAML 1.1 resolver leaves a string); any other string stays one."""
    if isinstance(x, str):
        import re

        if re.fullmatch(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?", x.strip()):
            return float(x)
    return x


def _num(cfg, key, default, path):
    v = _yaml_cpp_number(cfg.get(key, default))
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{path}: key '{key}': expected a finite number, got {v!r}")
    return float(v)


def _imudatalen(cfg, path) -> int:
    """``imudatalen``: the columns per IMU line, an integer >= 7 (time, 3 angle and 3 velocity
    increments; KF-GINS ignores the columns after them)."""
    v = _num(cfg, "imudatalen", 7, path)
    if v != int(v) or v < 7:
        raise ValueError(f"{path}: key 'imudatalen': {v:g}; expected an integer >= 7 (time, 3 angle and 3 "
                         "velocity increments per IMU line)")
    return int(v)


def _initpos(cfg, path):
    """``initpos`` [lat deg, lon deg, h m] in [rad, rad, m] (None when absent), within the Earth's ranges."""
    v = _vec(cfg, "initpos", path)
    if v is None:
        return None
    if not (abs(v[0]) <= 90.0 and -180.0 <= v[1] <= 360.0 and -1.0e4 < v[2] < 1.0e7):
        raise ValueError(f"{path}: key 'initpos': {list(map(float, v))}; expected latitude [deg] within +-90, "
                         "longitude [deg] and height [m]")
    return v * np.array([DEG, DEG, 1.0])


def _corrtime_s(noise, path) -> float:
    """``imunoise.corrtime`` [h] in seconds (NaN when absent): the Gauss-Markov correlation time of the
    biases and scale factors, > 0 (KF-GINS divides by it)."""
    if "corrtime" not in noise:
        return float("nan")
    v = _num(noise, "corrtime", float("nan"), path)
    if not v > 0:
        raise ValueError(f"{path}: key 'imunoise.corrtime': {v:g} h; expected a correlation time > 0 [h]")
    return v * HOUR


#: every key of KF-GINS's configuration file (KF-GINS dataset/kf-gins.yaml and
#: src/kf_gins.cpp loadConfig); ``imunoise`` is a table of :data:`KFGINS_NOISE_KEYS`
KFGINS_KEYS = ("imupath", "gnsspath", "outputpath", "imudatalen", "imudatarate", "starttime", "endtime",
               "initpos", "initvel", "initatt", "initgyrbias", "initaccbias", "initgyrscale", "initaccscale",
               "initposstd", "initvelstd", "initattstd", "initbgstd", "initbastd", "initsgstd", "initsastd",
               "imunoise", "antlever")
KFGINS_NOISE_KEYS = ("arw", "vrw", "gbstd", "abstd", "gsstd", "asstd", "corrtime")


def _unknown_keys(keys, known, where: str, p) -> None:
    """A one-line error for the first key not in ``known``, with a suggestion."""
    for k in keys:
        if k not in known:
            close = close_matches(str(k), known)
            hint = f"; did you mean '{close[0]}'?" if close else f"; known keys: {', '.join(known)}"
            raise ValueError(f"{p}: unknown key '{where}{k}'{hint}")


def read_kfgins_config(path) -> dict:
    """Read a KF-GINS YAML configuration into SI values.

    Returns
    -------
    dict
        ``imupath``, ``gnsspath``, ``outputpath`` (resolved relative to the
        YAML file), ``imudatalen``, ``imudatarate_hz``, ``starttime_s``,
        ``endtime_s`` (None for -1), ``initpos`` ``[lat rad, lon rad, h m]``,
        ``initvel_n_mps``, ``initatt_rad`` (roll, pitch, yaw), ``initgyrbias_radps``,
        ``initaccbias_mps2``, ``initgyrscale``, ``initaccscale`` [-],
        ``initposstd_m``, ``initvelstd_mps``, ``initattstd_rad``, optional
        ``initbgstd_radps``/``initbastd_mps2``/``initsgstd``/``initsastd``,
        ``imunoise`` with ``arw_rad_per_sqrts``, ``vrw_mps_per_sqrts``,
        ``gbstd_radps``, ``abstd_mps2``, ``gsstd``, ``asstd`` [-],
        ``corrtime_s``; ``antlever_b_m``; ``raw`` (the parsed YAML).
    """
    p = Path(path)
    text = read_text(p)
    cfg = _plain_yaml(text)  # KF-GINS's own files; anything else goes to PyYAML (~13 ms to import and parse)
    try:
        if cfg is None:
            import yaml

            cfg = yaml.safe_load(text)
    except ImportError:
        raise ValueError(f"{p}: more than KF-GINS's flat YAML (key: value, [a, b] lists of numbers, one nesting "
                         f"level): reading it needs PyYAML (pip install pyyaml)") from None
    except Exception as exc:  # yaml.YAMLError
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else 1
        raise ValueError(f"{p}:{line}: invalid YAML: {getattr(exc, 'problem', exc)}") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"{p}:1: expected a mapping of keys")
    _unknown_keys(cfg, KFGINS_KEYS, "", p)
    if isinstance(cfg.get("imunoise"), dict):
        _unknown_keys(cfg["imunoise"], KFGINS_NOISE_KEYS, "imunoise.", p)
    base = p.parent

    def path_of(k):
        v = cfg.get(k)
        return None if v is None else str((base / str(v)).resolve())

    def scaled(k, f):
        v = _vec(cfg, k, p)
        return None if v is None else v * f

    noise = cfg.get("imunoise") or {}
    if not isinstance(noise, dict):
        raise ValueError(f"{p}: key 'imunoise': expected a mapping")
    out = {
        "imupath": path_of("imupath"), "gnsspath": path_of("gnsspath"),
        "outputpath": path_of("outputpath"),
        "imudatalen": _imudatalen(cfg, p),
        "imudatarate_hz": _num(cfg, "imudatarate", 200, p),
        "starttime_s": _num(cfg, "starttime", 0.0, p),
        "endtime_s": None if _num(cfg, "endtime", -1, p) < 0 else _num(cfg, "endtime", -1, p),
        "initpos": _initpos(cfg, p),
        "initvel_n_mps": _vec(cfg, "initvel", p),
        "initatt_rad": scaled("initatt", DEG),
        "initgyrbias_radps": scaled("initgyrbias", DEG / HOUR),
        "initaccbias_mps2": scaled("initaccbias", MGAL),
        "initgyrscale": scaled("initgyrscale", PPM),
        "initaccscale": scaled("initaccscale", PPM),
        "initposstd_m": _vec(cfg, "initposstd", p),
        "initvelstd_mps": _vec(cfg, "initvelstd", p),
        "initattstd_rad": scaled("initattstd", DEG),
        "initbgstd_radps": scaled("initbgstd", DEG / HOUR),
        "initbastd_mps2": scaled("initbastd", MGAL),
        "initsgstd": scaled("initsgstd", PPM),
        "initsastd": scaled("initsastd", PPM),
        "imunoise": {
            "arw_rad_per_sqrts": None if _vec(noise, "arw", p, table="imunoise.") is None else
            _vec(noise, "arw", p, table="imunoise.") * DEG / math.sqrt(HOUR),
            "vrw_mps_per_sqrts": None if _vec(noise, "vrw", p, table="imunoise.") is None else
            _vec(noise, "vrw", p, table="imunoise.") / math.sqrt(HOUR),
            "gbstd_radps": None if _vec(noise, "gbstd", p, table="imunoise.") is None else
            _vec(noise, "gbstd", p, table="imunoise.") * DEG / HOUR,
            "abstd_mps2": None if _vec(noise, "abstd", p, table="imunoise.") is None else
            _vec(noise, "abstd", p, table="imunoise.") * MGAL,
            "gsstd": None if _vec(noise, "gsstd", p, table="imunoise.") is None else _vec(noise, "gsstd", p, table="imunoise.") * PPM,
            "asstd": None if _vec(noise, "asstd", p, table="imunoise.") is None else _vec(noise, "asstd", p, table="imunoise.") * PPM,
            "corrtime_s": _corrtime_s(noise, p),
        },
        "antlever_b_m": _vec(cfg, "antlever", p),
        "raw": cfg,
    }
    if out["endtime_s"] is not None and out["endtime_s"] <= out["starttime_s"]:
        raise ValueError(f"{p}: key 'endtime': {out['endtime_s']:g} is not after 'starttime' "
                         f"{out['starttime_s']:g} (-1: to the end of the IMU file)")
    from ..data.checks import lever_arm_problem

    problem = None if out["antlever_b_m"] is None else lever_arm_problem(out["antlever_b_m"])
    if problem:
        raise ValueError(f"{p}: key 'antlever': {out['antlever_b_m'].tolist()}: {problem}")
    return out


_YAML_INT = r"[-+]?(?:0|[1-9][0-9]*)"
_YAML_FLOAT = r"[-+]?[0-9]+\.[0-9]*(?:[eE][-+][0-9]+)?"
_YAML_NUM = f"(?:{_YAML_FLOAT}|{_YAML_INT})"
_YAML_LINE = None


def _plain_yaml(text: str) -> dict | None:
    """The YAML of KF-GINS's configuration files read without PyYAML, or None
    when ``text`` is anything more than that subset (PyYAML then reads it).

    The subset, line by line: blank lines and ``#`` comments; ``key:`` opening
    a mapping of the indented lines below it (one level); ``key: value`` with a
    decimal integer, a float with a decimal point (PyYAML's YAML 1.1 resolver:
    ``1e3`` would be a string there, so it is left to PyYAML), a quoted string
    without quotes, backslashes or ``#`` inside, or a ``[...]`` list of such
    numbers; a comment after a value starts with whitespace.  Within it the
    result is what ``yaml.safe_load`` returns (tests/test_io_kfgins.py)."""
    import re

    global _YAML_LINE
    if _YAML_LINE is None:
        value = (rf"(?P<int>{_YAML_INT})|(?P<float>{_YAML_FLOAT})|\"(?P<dq>[^\"\\#]*)\"|'(?P<sq>[^'\\#]*)'"
                 rf"|\[\s*(?P<list>{_YAML_NUM}(?:\s*,\s*{_YAML_NUM})*)?\s*\]")
        _YAML_LINE = re.compile(rf"(?P<indent> *)(?P<key>[A-Za-z_][A-Za-z0-9_]*):(?:[ ]+(?:{value}))?(?:[ ]+#.*)?[ ]*")
    num = re.compile(_YAML_NUM)
    out: dict = {}
    table: dict | None = None  # the mapping the indented lines go to
    indent = None
    for line in text.splitlines():
        stripped = line.lstrip(" ")
        if not stripped or stripped.startswith("#"):
            continue
        m = _YAML_LINE.fullmatch(line)
        if m is None:
            return None
        k = m["key"]
        if m["indent"]:
            if table is None or (indent is not None and m["indent"] != indent):
                return None
            indent, tgt = m["indent"], table
        else:
            table, indent, tgt = None, None, out
        if m["int"] is not None:
            tgt[k] = int(m["int"])
        elif m["float"] is not None:
            tgt[k] = float(m["float"])
        elif m["dq"] is not None or m["sq"] is not None:
            tgt[k] = m["dq"] if m["dq"] is not None else m["sq"]
        elif "[" in line.split("#", 1)[0]:
            items = num.findall(m["list"] or "")
            tgt[k] = [float(x) if "." in x else int(x) for x in items]
        elif tgt is out:  # "key:" alone: a mapping follows (None when nothing is indented under it)
            out[k] = None
            table = out[k] = {}
        else:
            return None
    for k, v in list(out.items()):  # "key:" with nothing indented under it is null in YAML
        if v == {}:
            out[k] = None
    return out or None  # no key at all: PyYAML's None and the caller's message
