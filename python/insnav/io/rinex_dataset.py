"""Real GNSS + IMU data for the tightly coupled filter.

A RINEX observation + navigation file pair, an IMU file (a generic CSV, or a
raw log time-tagged by RTKLIB ``str2str``) and, optionally, an RTKLIB ``.pos``
reference become a :class:`RinexDataset` that :func:`insnav.filters.tight.run_tight`
and ``insnav.run(ds, config=cfg)`` accept, plus a :class:`~insnav.config.RunConfig`
suited to it (:func:`load_rinex`).  ``insnav run --format rinex`` calls
:func:`load_rinex_run`.

Time axis
---------
Dataset time is **GPS seconds of week** of the week of the first observation
epoch (as for the KF-GINS loader): ``t_gps = t + gps_time_offset_s`` with
``gps_time_offset_s = 604800 * week``.  The solution CSV therefore has GPS
seconds of week in its ``t`` column and ``insnav evaluate SOL REF.pos`` can
compare it with an RTKLIB reference directly.

IMU file (generic CSV, :class:`ImuCsvFormat`)
---------------------------------------------
One sample per line, fields separated by ``delimiter`` (``,``).  ``columns``
names the fields in file order: ``t`` (time, see ``time``) or ``tick_ms``
(an IMU counter in ms, needs a str2str tag file), ``ax ay az`` (accelerometer),
``gx gy gz`` (gyro), ``_`` (ignored).  Blank lines and lines starting with
``#`` are skipped; the first remaining line is a header (skipped) when its
first field is not a number.  Options:

==================  ==========================================================
``time``            ``gps_s`` (s since 1980-01-06), ``gps_sow`` (GPS seconds
                    of week; the week is the observation file's), or
                    ``gpst_unix_s`` (RTKLIB ``gtime_t`` style: GPS time counted
                    from 1970-01-01, e.g. the rtklibexplorer ``*_sf.csv``)
``acc_unit``        ``mps2`` or ``g`` (standard gravity 9.80665 m/s^2)
``gyro_unit``       ``rps`` or ``dps``
``samples``         ``rate`` (specific force and angular rate at ``t``,
                    integrated to increments with the trapezoidal rule over
                    ``(t_prev, t]``; the first sample only starts the
                    integration) or ``increment`` (velocity and angle
                    increments over ``(t_prev, t]`` in the rate unit times
                    seconds: m/s or g s, rad or deg)
``mount_rpy_deg``   3-2-1 Euler angles of the IMU sensor axes relative to the
                    body FRD axes [deg]: ``x_b = C(mount) x_imu`` with ``C``
                    the same DCM as the attitude ``C_nb``
``time_offset_s``   added to every IMU time [s] (a known logging delay)
==================  ==========================================================

Raw str2str logs (``tick_ms`` column + ``IMU.csv.tag``)
-------------------------------------------------------
RTKLIB ``str2str`` writes, beside a logged stream, a binary time-tag file: a
64-byte header (``"TIMETAG RTKLIB ..."``, the last 4 bytes the PC tick at
opening), ``u32 time`` and ``f64 sec`` (GPST at opening, ``gtime_t`` style),
then ``(u32 tick [ms since opening], u32 fpos [bytes written])`` per write.
The IMU's own ``tick_ms`` counter is the sample clock; the tag gives the PC
arrival time (GPST) of every byte.  :func:`tick_time_map` maps the counter to
GPS time as the **lower envelope** of ``arrival - tick`` (a straight line
through the minima over ``window_s`` windows, shifted below all of them): a
sample's time is its arrival time at the smallest latency seen, and the line's
slope is the rate difference of the IMU and PC clocks.  A log starts at an
arbitrary byte, so the first line is always dropped; a last line without a
newline is dropped too.  When the CSV's line endings were converted from
``\\r\\n`` to ``\\n`` after logging (e.g. by git), the tag's byte count exceeds
the file size by exactly the number of lines; this is detected and allowed,
any other size mismatch is an error.

Initial state
-------------
Position and velocity from a single-point fix (:func:`single_point_solution`:
least squares over the pseudoranges and Dopplers of one epoch, needs 4
satellites) at the start epoch, or given.  Roll and pitch from the mean
specific force over ``level_window_s`` before the start (accelerometer
levelling).  Heading: a consumer gyro cannot gyrocompass (Earth rate,
4e-3 deg/s, is far below its bias), so ``init_yaw_deg`` is either given or
``"course"``: the run then starts at the first epoch at which the single-point
horizontal speed has stayed above ``course_min_speed_mps`` for
``course_window_s``, and the yaw is the course over ground of the mean
Doppler velocity of that window.  This assumes the body x axis points along
the direction of travel (true for a car, roughly true for a handheld unit
carried in front of the walker), and it drops the data before the start.

Errors
------
Every problem with an input file raises :class:`ImuFileError` (or the
:class:`insnav.gnss.RinexError` of the RINEX/``.pos`` readers), a
``ValueError`` whose message names the file, the 1-based line (the byte
offset for the binary tag file) and what was wrong.
"""
from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import _core, earth
from ..config import ConfigError, RunConfig, config_from_dict
from ..data.dataset import Dataset, GnssFixes, ImuData, RowOrigin, Truth
from ..gnss.gpstime import SECONDS_PER_WEEK, gps_seconds_from_calendar
from ..data.nav import NavState
from ..units import DEG, G0, RAD2DEG

__all__ = ["ImuFileError", "ImuCsvFormat", "Str2strTag", "read_str2str_tag", "read_imu_csv", "ImuSamples",
           "tick_time_map", "SinglePoint", "single_point_solution", "rtklib_truth", "RinexOptions",
           "RinexDataset", "load_rinex", "load_rinex_run", "CONSUMER_MEMS_MODEL", "GPST_UNIX_OFFSET_S"]

#: GPS seconds since 1980-01-06 of 1970-01-01 in GPS time: ``t_gps = t_gtime - 315964800`` [s]
GPST_UNIX_OFFSET_S = int(round(-gps_seconds_from_calendar(1970, 1, 1)))
_TAG_MAGIC = b"TIMETAG RTKLIB"
_TAG_HEADER = 64          # bytes before u32 time, f64 sec
_TAG_FIRST_RECORD = 76    # 64 + 4 + 8

#: Default filter IMU model for a consumer MEMS IMU (SI, keys of
#: :func:`insnav.sim.imu.imu_model_dict` read by ``ImuNoise.from_dataset_model``):
#: white noise 4x a good consumer part's datasheet (0.0038 deg/s/sqrt(Hz),
#: 70 ug/sqrt(Hz), e.g. TDK ICM-42688; the factor covers handling vibration),
#: turn-on biases 0.3 deg/s and 30 mg (uncalibrated, 1-sigma, nearly constant
#: over a run: Gauss-Markov with 3600 s).
CONSUMER_MEMS_MODEL = dict(gyro_arw=4 * 0.0038 * DEG, accel_vrw=4 * 70e-6 * G0,
                           gyro_bias_total_sigma=0.3 * DEG, accel_bias_total_sigma=30e-3 * G0,
                           gyro_scale_sigma=1e-3, accel_scale_sigma=1e-3)


class ImuFileError(ValueError):
    """A malformed IMU CSV or str2str tag file.

    Attributes
    ----------
    path : str
    line : int or None
        1-based line (CSV) or byte offset (tag file, ``unit="byte"``).
    what : str
    """

    def __init__(self, path, line, what, unit="line"):
        self.path = os.fspath(path)
        self.line = line
        self.what = what
        where = f"{self.path}, {unit} {line}" if line is not None else self.path
        super().__init__(f"{where}: {what}")


# --------------------------------------------------------------------------- IMU CSV

_ALLOWED_COLUMNS = ("t", "tick_ms", "ax", "ay", "az", "gx", "gy", "gz", "_")
_CHOICES = dict(time=("gps_s", "gps_sow", "gpst_unix_s"), acc_unit=("mps2", "g"), gyro_unit=("rps", "dps"),
                samples=("rate", "increment"))


@dataclass
class ImuCsvFormat:
    """How to read an IMU CSV (see the module docstring for each option)."""

    columns: tuple = ("t", "ax", "ay", "az", "gx", "gy", "gz")
    time: str = "gps_s"
    acc_unit: str = "mps2"
    gyro_unit: str = "rps"
    samples: str = "rate"
    mount_rpy_deg: tuple = (0.0, 0.0, 0.0)
    time_offset_s: float = 0.0
    delimiter: str = ","

    def validate(self, source: str = "imu format") -> "ImuCsvFormat":
        cols = tuple(self.columns)
        for c in cols:
            if c not in _ALLOWED_COLUMNS:
                raise ConfigError(f"{source}: imu_columns: unknown column {c!r}; "
                                  f"allowed: {', '.join(_ALLOWED_COLUMNS)}")
        for c in ("ax", "ay", "az", "gx", "gy", "gz"):
            if cols.count(c) != 1:
                raise ConfigError(f"{source}: imu_columns {list(cols)} must name {c!r} exactly once")
        if cols.count("t") + cols.count("tick_ms") != 1:
            raise ConfigError(f"{source}: imu_columns {list(cols)} must have exactly one of 't' or 'tick_ms'")
        for key, allowed in _CHOICES.items():
            if getattr(self, key) not in allowed:
                raise ConfigError(f"{source}: imu_{key}: bad value {getattr(self, key)!r}; "
                                  f"allowed: {', '.join(allowed)}")
        m = np.asarray(self.mount_rpy_deg, dtype=float)
        if m.shape != (3,) or not np.all(np.isfinite(m)):
            raise ConfigError(f"{source}: imu_mount_rpy_deg: bad value {self.mount_rpy_deg!r}; allowed: 3 angles [deg]")
        if not (isinstance(self.delimiter, str) and len(self.delimiter) == 1):
            raise ConfigError(f"{source}: imu_delimiter: bad value {self.delimiter!r}; allowed: one character")
        if not math.isfinite(float(self.time_offset_s)):
            raise ConfigError(f"{source}: imu_time_offset_s: bad value {self.time_offset_s!r}")
        self.columns = cols
        return self

    @property
    def uses_tick(self) -> bool:
        return "tick_ms" in self.columns

    def C_b_imu(self) -> np.ndarray:
        """(3, 3) rotation IMU sensor axes -> body FRD: ``x_b = C x_imu``."""
        return np.asarray(_core.rotation.dcm_from_euler(np.asarray(self.mount_rpy_deg, float) * DEG))


@dataclass
class ImuSamples:
    """IMU samples as read (rotated into the body frame, SI), before integration.

    Attributes
    ----------
    t_ref_gps_s : float
        GPS time [s since 1980-01-06] that ``t_s`` counts from (a whole second,
        or the tag file's start), so that sample intervals keep full precision.
    t_s : (N,) sample time after ``t_ref_gps_s`` [s]
    acc_b : (N, 3) specific force [m/s^2] (``samples == "rate"``) or velocity increment [m/s]
    gyro_b : (N, 3) angular rate [rad/s] or angle increment [rad]
    samples : {'rate', 'increment'}
    lines : (N,) 1-based file line of each sample
    path : str
    info : dict
        ``lines_dropped`` (partial first/last lines of a str2str log) and, for a
        tagged log, the tick -> GPS time fit (see :func:`tick_time_map`).
    """

    t_ref_gps_s: float
    t_s: np.ndarray
    acc_b: np.ndarray
    gyro_b: np.ndarray
    samples: str
    lines: np.ndarray
    path: str
    info: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.t_s)

    @property
    def t_gps_s(self) -> np.ndarray:
        """(N,) sample time, GPS seconds since 1980-01-06 [s] (about 0.2 us resolution)."""
        return self.t_ref_gps_s + self.t_s

    @property
    def rate_hz(self) -> float:
        """Mean sample rate [Hz]."""
        return (len(self.t_s) - 1) / float(self.t_s[-1] - self.t_s[0]) if len(self) > 1 else float("nan")

    def to_increments(self, t_offset_s: float = 0.0) -> ImuData:
        """:class:`insnav.data.dataset.ImuData` with time ``t_gps_s - t_offset_s``.

        Rates are integrated with the trapezoidal rule over each interval
        ``(t[k-1], t[k]]`` (exact for a rate that varies linearly between
        samples), so the first sample yields no increment.
        """
        t = (self.t_ref_gps_s - t_offset_s) + self.t_s
        if self.samples == "increment":
            return ImuData(t.copy(), self.gyro_b.copy(), self.acc_b.copy(),
                           origin=RowOrigin(self.path, lines=self.lines.copy()))
        dt = np.diff(t)[:, None]
        dth = 0.5 * (self.gyro_b[1:] + self.gyro_b[:-1]) * dt
        dv = 0.5 * (self.acc_b[1:] + self.acc_b[:-1]) * dt
        return ImuData(t[1:].copy(), dth, dv, origin=RowOrigin(self.path, lines=self.lines[1:].copy()))


@dataclass
class Str2strTag:
    """An RTKLIB str2str time-tag file (see the module docstring).

    Attributes
    ----------
    path : str
    t_start_gps_s : float
        GPS time at which the log was opened (tick 0) [s since 1980-01-06].
    tick_ms : (K,) int64 PC milliseconds since opening of each write
    fpos : (K,) int64 bytes of the stream written up to and including that write
    """

    path: str
    t_start_gps_s: float
    tick_ms: np.ndarray
    fpos: np.ndarray


def read_str2str_tag(path) -> Str2strTag:
    """Read an RTKLIB str2str ``.tag`` file.

    Raises
    ------
    ImuFileError
        Naming the file and the byte offset: not a tag file, truncated, or
        ticks / file positions that go backwards.
    """
    path = os.fspath(path)
    try:
        b = Path(path).read_bytes()
    except OSError as exc:
        raise ImuFileError(path, None, f"cannot read the tag file ({exc.strerror})") from None
    if len(b) < _TAG_FIRST_RECORD or not b.startswith(_TAG_MAGIC):
        raise ImuFileError(path, 0, f"not an RTKLIB str2str time-tag file (expected a {_TAG_FIRST_RECORD}-byte "
                           f"header starting with {_TAG_MAGIC.decode()!r}; file has {len(b)} bytes)", unit="byte")
    time_time = int(np.frombuffer(b, "<u4", 1, _TAG_HEADER)[0])
    time_sec = float(np.frombuffer(b, "<f8", 1, _TAG_HEADER + 4)[0])
    if not (math.isfinite(time_sec) and 0.0 <= time_sec < 1.0) or time_time < GPST_UNIX_OFFSET_S:
        raise ImuFileError(path, _TAG_HEADER, f"bad start time {time_time} + {time_sec!r} s (expected GPST seconds "
                           "since 1970 after 1980 and a fraction in [0, 1))", unit="byte")
    n_rec, rest = divmod(len(b) - _TAG_FIRST_RECORD, 8)
    if rest:
        raise ImuFileError(path, _TAG_FIRST_RECORD + 8 * n_rec, f"truncated record ({rest} of 8 bytes)", unit="byte")
    if n_rec == 0:
        raise ImuFileError(path, _TAG_FIRST_RECORD, "no (tick, fpos) records", unit="byte")
    rec = np.frombuffer(b, "<u4", 2 * n_rec, _TAG_FIRST_RECORD).reshape(-1, 2).astype(np.int64)
    for col, name in ((0, "tick"), (1, "file position")):
        bad = np.flatnonzero(np.diff(rec[:, col]) < 0)
        if bad.size:
            k = int(bad[0]) + 1
            raise ImuFileError(path, _TAG_FIRST_RECORD + 8 * k + 4 * col,
                               f"{name} {rec[k, col]} goes backwards (previous record: {rec[k - 1, col]})",
                               unit="byte")
    return Str2strTag(path, time_time + time_sec - GPST_UNIX_OFFSET_S, rec[:, 0], rec[:, 1])


def tick_time_map(tick_s, arrival_gps_s, window_s: float = 2.0, max_drift_ppm: float = 1000.0):
    """GPS time of IMU counter values from their PC arrival times (lower envelope).

    Parameters
    ----------
    tick_s : (N,) IMU counter [s], increasing
    arrival_gps_s : (N,) PC arrival time of each sample [s] (GPS time, or the
        time after a reference such as the tag start; the result counts from it too)
    window_s : float
        Window for the minima the envelope line is fitted through [s].
    max_drift_ppm : float
        Largest plausible rate difference of the two clocks [ppm].

    Returns
    -------
    t_gps_s : (N,) [s]
    info : dict
        ``drift_ppm`` (slope), ``latency_median_ms``, ``latency_p95_ms``,
        ``latency_max_ms`` (arrival minus the mapped time).

    Raises
    ------
    ValueError
        When the slope exceeds ``max_drift_ppm`` (the tag does not belong to the log).
    """
    tick_s = np.asarray(tick_s, float)
    x = tick_s - tick_s[0]
    y = np.asarray(arrival_gps_s, float) - tick_s
    y0 = float(np.min(y))
    y = y - y0
    win = np.floor(x / window_s).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, np.diff(win) != 0])
    xm = np.empty(starts.size)
    ym = np.empty(starts.size)
    for j, (a, b) in enumerate(zip(starts, np.r_[starts[1:], x.size])):
        k = a + int(np.argmin(y[a:b]))
        xm[j], ym[j] = x[k], y[k]
    if xm.size >= 2 and np.ptp(xm) > 0:
        slope, icpt = np.polyfit(xm, ym, 1)
    else:
        slope, icpt = 0.0, 0.0
    if abs(slope) * 1e6 > max_drift_ppm:
        raise ValueError(f"IMU counter and tag arrival times drift apart by {slope * 1e6:.0f} ppm "
                         f"(more than {max_drift_ppm:g} ppm): the tag file does not belong to this log")
    icpt += float(np.min(y - (slope * x + icpt)))  # shift below every sample: a lower envelope
    t = tick_s + y0 + icpt + slope * x
    lat = (np.asarray(arrival_gps_s, float) - t) * 1e3
    return t, dict(drift_ppm=float(slope * 1e6), latency_median_ms=float(np.median(lat)),
                   latency_p95_ms=float(np.percentile(lat, 95)), latency_max_ms=float(lat.max()))


def _time_after(tokens, ref_int: int) -> np.ndarray:
    """Decimal time strings minus the integer ``ref_int`` without losing digits to a 1e9-sized float."""
    out = np.empty(len(tokens))
    for i, tok in enumerate(tokens):
        whole, dot, frac = tok.strip().partition(".")
        if whole.isdigit() and (not frac or frac.isdigit()):
            out[i] = (int(whole) - ref_int) + (float("0." + frac) if frac else 0.0)
        else:  # exponent or sign: plain float
            out[i] = float(tok) - ref_int
    return out


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def read_imu_csv(path, fmt: ImuCsvFormat | None = None, *, tag=None, week: int | None = None) -> ImuSamples:
    """Read an IMU CSV (see the module docstring) into body-frame SI samples.

    Parameters
    ----------
    path : path
    fmt : ImuCsvFormat
    tag : path or Str2strTag, optional
        The str2str time tag, required with a ``tick_ms`` column (default:
        ``path + ".tag"``).
    week : int, optional
        GPS week for ``time = "gps_sow"`` (required then).

    Returns
    -------
    ImuSamples

    Raises
    ------
    ImuFileError
        Naming the file and the 1-based line: wrong number of fields, a bad
        or non-finite number, time not increasing; tag problems (byte offset).
    """
    fmt = (fmt or ImuCsvFormat()).validate()
    path = os.fspath(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ImuFileError(path, None, f"cannot read the IMU file ({exc.strerror})") from None
    tagged = fmt.uses_tick
    if fmt.time == "gps_sow" and not tagged and week is None:
        raise ValueError(f"{path}: imu time 'gps_sow' needs the GPS week (from the observation file)")
    parts = raw.split(b"\n")
    complete_last = raw.endswith(b"\n")
    if complete_last:
        parts = parts[:-1]
    ncol = len(fmt.columns)
    idx = {c: fmt.columns.index(c) for c in fmt.columns if c != "_"}
    tcol = idx["tick_ms"] if tagged else idx["t"]
    acc_cols = [idx[c] for c in ("ax", "ay", "az")]
    gyr_cols = [idx[c] for c in ("gx", "gy", "gz")]
    want = [tcol] + acc_cols + gyr_cols
    names = ["tick_ms" if tagged else "t", "ax", "ay", "az", "gx", "gy", "gz"]
    rows, lines, ends, t_tok = [], [], [], []
    dropped = []
    pos = 0
    header_allowed = True
    delim = fmt.delimiter
    for i, b in enumerate(parts):
        lineno = i + 1
        pos += len(b) + 1
        if tagged and (i == 0 or (i == len(parts) - 1 and not complete_last)):
            dropped.append(lineno)  # a str2str log starts and may end mid-line
            continue
        try:
            s = b.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ImuFileError(path, lineno, "not ASCII text (binary data in a CSV?)") from None
        if not s or s.startswith("#"):
            continue
        tok = s.split(delim)
        if header_allowed:
            header_allowed = False
            if not _is_number(tok[0].strip()):
                continue
        if len(tok) != ncol:
            raise ImuFileError(path, lineno, f"expected {ncol} {delim!r}-separated fields "
                               f"({', '.join(fmt.columns)}), found {len(tok)}")
        vals = []
        for j, name in zip(want, names):
            try:
                v = float(tok[j])
            except ValueError:
                raise ImuFileError(path, lineno, f"bad number {tok[j].strip()!r} in field {j + 1} ({name})") from None
            if not math.isfinite(v):
                raise ImuFileError(path, lineno, f"non-finite value {tok[j].strip()!r} in field {j + 1} ({name})")
            vals.append(v)
        rows.append(vals)
        t_tok.append(tok[tcol])
        lines.append(lineno)
        ends.append(pos)
    if len(rows) < 2:
        raise ImuFileError(path, None, f"fewer than 2 IMU samples ({len(rows)})")
    a = np.asarray(rows, dtype=float)
    lines = np.asarray(lines, dtype=np.int64)
    t = a[:, 0]
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        what = "tick" if tagged else "time"
        raise ImuFileError(path, int(lines[k]), f"{what} {float(t[k])!r} does not increase (line "
                           f"{int(lines[k - 1])}: {float(t[k - 1])!r})")
    info = dict(lines_dropped=dropped)
    if tagged:
        if not isinstance(tag, Str2strTag):
            tag = read_str2str_tag(tag if tag is not None else path + ".tag")
        n_lf = raw.count(b"\n")
        size = len(raw)
        last = int(tag.fpos[-1])
        if last == size:
            crlf_added = 0
        elif last == size + n_lf and b"\r" not in raw:
            crlf_added = 1  # the log had \r\n line ends, converted to \n afterwards
        else:
            raise ImuFileError(tag.path, None, f"the tag covers {last} bytes but {path} has {size} bytes "
                               f"({n_lf} lines): not the time tag of this file")
        end_bytes = np.asarray(ends, dtype=np.int64) + crlf_added * lines  # byte after each line's newline
        k = np.minimum(np.searchsorted(tag.fpos, end_bytes), tag.fpos.size - 1)  # first write holding the line
        arrival = tag.tick_ms[k] / 1000.0  # after the tag start
        try:
            t, fit = tick_time_map((t - t[0]) / 1000.0, arrival)
        except ValueError as exc:
            raise ImuFileError(tag.path, None, f"{exc} ({path})") from None
        info.update(fit, tag=tag.path, crlf_converted=bool(crlf_added), t_start_gps_s=tag.t_start_gps_s)
        t_ref = tag.t_start_gps_s
    else:
        ref_int = int(math.floor(t[0]))
        t = _time_after(t_tok, ref_int)
        t_ref = float(ref_int)
        if fmt.time == "gpst_unix_s":
            t_ref = float(ref_int - GPST_UNIX_OFFSET_S)
        elif fmt.time == "gps_sow":
            t_ref = float(ref_int + SECONDS_PER_WEEK * int(week))
    t = t + float(fmt.time_offset_s)
    k_acc = G0 if fmt.acc_unit == "g" else 1.0
    k_gyr = DEG if fmt.gyro_unit == "dps" else 1.0
    C = fmt.C_b_imu()
    acc_b = (a[:, 1:4] * k_acc) @ C.T
    gyro_b = (a[:, 4:7] * k_gyr) @ C.T
    return ImuSamples(t_ref, t, acc_b, gyro_b, fmt.samples, lines, path, info)


# --------------------------------------------------------------------------- single-point solution


@dataclass
class SinglePoint:
    """Per-epoch single-point (GNSS-only) solution of a :class:`~insnav.gnss.tight_inputs.TightInputs`.

    Attributes
    ----------
    t : (E,) epoch time (dataset time) [s]
    r_e : (E, 3) antenna ECEF position [m] (NaN: fewer than 4 pseudoranges)
    clock_bias_m : (E,)
    v_e : (E, 3) antenna ECEF velocity [m/s] (NaN: fewer than 4 Dopplers)
    clock_drift_mps : (E,)
    n_sats : (E,) pseudoranges used
    sigma_pos_n_m, sigma_vel_n_mps : (E, 3) 1-sigma N, E, D from the
        least-squares covariance with the inputs' sigmas [m], [m/s]
    pdop : (E,)
    """

    t: np.ndarray
    r_e: np.ndarray
    clock_bias_m: np.ndarray
    v_e: np.ndarray
    clock_drift_mps: np.ndarray
    n_sats: np.ndarray
    sigma_pos_n_m: np.ndarray
    sigma_vel_n_mps: np.ndarray
    pdop: np.ndarray

    def llh(self):
        """(lat [rad], lon [rad], h [m]) arrays."""
        return earth.ecef_to_geodetic(self.r_e)

    def v_n(self) -> np.ndarray:
        lat, lon, _ = self.llh()
        return earth.ecef_to_ned_vector(lat, lon, self.v_e)


def single_point_solution(inputs, r0_e, *, min_sats: int = 4, iterations: int = 10) -> SinglePoint:
    """Weighted least-squares position/clock and velocity/drift per epoch.

    Uses exactly the rows the tight filter receives (same satellites,
    corrections and sigmas).  Model (``TightInputs.sats`` columns)::

        rho  = |r_s - r| + b - clk_s                 (Gauss-Newton from r0_e)
        rhod = u . (v_s - v) + d - clkdot_s          (linear once r is known)

    Parameters
    ----------
    inputs : insnav.gnss.tight_inputs.TightInputs
    r0_e : (3,) starting ECEF position [m]
    min_sats : int
        Epochs with fewer usable rows give NaN (4 unknowns each).

    Returns
    -------
    SinglePoint
    """
    E = inputs.epoch_t.size
    r_out = np.full((E, 3), np.nan)
    v_out = np.full((E, 3), np.nan)
    b_out = np.full(E, np.nan)
    d_out = np.full(E, np.nan)
    sp = np.full((E, 3), np.nan)
    sv = np.full((E, 3), np.nan)
    pdop = np.full(E, np.nan)
    n_used = np.zeros(E, np.int64)
    x = np.append(np.asarray(r0_e, float), 0.0)
    for e in range(E):
        s = inputs.sats[inputs.epoch_start[e]:inputs.epoch_start[e + 1]]
        s = s[np.isfinite(s[:, 0])]
        n_used[e] = len(s)
        if len(s) < min_sats:
            continue
        w = 1.0 / s[:, 10]
        ok = False
        for _ in range(iterations):
            d = s[:, 2:5] - x[:3]
            rng = np.linalg.norm(d, axis=1)
            u = d / rng[:, None]
            H = np.column_stack([-u, np.ones(len(s))])
            y = s[:, 0] - (rng - s[:, 8] + x[3])
            dx = np.linalg.lstsq(H * w[:, None], y * w, rcond=None)[0]
            x = x + dx
            if np.linalg.norm(dx[:3]) < 1e-4:
                ok = True
                break
        if not ok or not np.all(np.isfinite(x)):
            x = np.append(np.asarray(r0_e, float), 0.0)
            continue
        d = s[:, 2:5] - x[:3]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        H = np.column_stack([-u, np.ones(len(s))])
        lat, lon, _ = earth.ecef_to_geodetic(x[:3])
        C_ne = earth.C_en(lat, lon).T
        Q = np.linalg.inv((H * (w ** 2)[:, None]).T @ H)
        Hn = np.column_stack([-(u @ C_ne.T), np.ones(len(s))])
        Qn = np.linalg.inv(Hn.T @ Hn)
        r_out[e], b_out[e] = x[:3], x[3]
        sp[e] = np.sqrt(np.diag(C_ne @ Q[:3, :3] @ C_ne.T))
        pdop[e] = math.sqrt(np.trace(Qn[:3, :3]))
        m = np.isfinite(s[:, 1])
        if m.sum() >= min_sats:
            wr = 1.0 / s[m, 11]
            y = s[m, 1] - np.einsum("ij,ij->i", u[m], s[m, 5:8]) + s[m, 9]
            sol = np.linalg.lstsq(H[m] * wr[:, None], y * wr, rcond=None)[0]
            v_out[e], d_out[e] = sol[:3], sol[3]
            Qv = np.linalg.inv((H[m] * (wr ** 2)[:, None]).T @ H[m])
            sv[e] = np.sqrt(np.diag(C_ne @ Qv[:3, :3] @ C_ne.T))
    return SinglePoint(inputs.epoch_t.copy(), r_out, b_out, v_out, d_out, n_used, sp, sv, pdop)


# --------------------------------------------------------------------------- reference


def rtklib_truth(ref, t_offset_gps_s: float, quality_max: int | None = None) -> Truth:
    """An RTKLIB ``.pos`` solution as a :class:`~insnav.data.dataset.Truth` (no attitude).

    Parameters
    ----------
    ref : path or insnav.gnss.measurements.RtklibPos
    t_offset_gps_s : float
        GPS time of dataset time 0 [s since 1980-01-06] (``604800 * week``
        for GPS seconds of week).
    quality_max : int, optional
        Keep records with ``Q <= quality_max`` (1: fix only, 2: fix and float).

    Returns
    -------
    Truth
        Antenna position and velocity (NaN velocity when the file has none),
        attitude NaN; ``truth.quality`` holds Q.
    """
    from ..gnss.measurements import read_rtklib_pos

    if not hasattr(ref, "r_e"):
        ref = read_rtklib_pos(ref)
    keep = np.ones(len(ref.t_gps_s), bool) if quality_max is None else ref.q <= quality_max
    lat, lon, h = earth.ecef_to_geodetic(ref.r_e[keep])
    v_n = earth.ecef_to_ned_vector(lat, lon, ref.v_e[keep])
    nan = np.full(int(keep.sum()), np.nan)
    tr = Truth(ref.t_gps_s[keep] - t_offset_gps_s, lat * RAD2DEG, lon * RAD2DEG, h, v_n, nan, nan.copy(), nan.copy())
    tr.quality = np.asarray(ref.q)[keep]
    return tr


# --------------------------------------------------------------------------- options and loader


@dataclass
class RinexOptions:
    """Options of :func:`load_rinex` (the ``[rinex]`` table of a run TOML).

    Attributes (units in the names)
    ----------
    imu_columns, imu_time, imu_acc_unit, imu_gyro_unit, imu_samples,
    imu_mount_rpy_deg, imu_time_offset_s, imu_delimiter :
        The IMU CSV format (:class:`ImuCsvFormat` without the ``imu_`` prefix).
    imu_tag : str or None
        str2str tag file (``tick_ms`` column); None: ``IMU + ".tag"``.
    lever_arm_b : 3 floats
        IMU -> antenna, body FRD [m].
    elevation_mask_deg, iono, tropo, sigma_pr_zenith_m, sigma_prr_zenith_mps, use_cn0 :
        GNSS inputs (:func:`insnav.gnss.tight_inputs.tight_inputs_from_rinex`).
    systems : str
        Systems of the tight inputs, letters of "GREC" with G (default "G"):
        the start (single-point fix, course) uses GPS; with more systems the
        tight filter gets every system's rows and runs with inter-system bias
        states (``LayoutTightMulti``).  Files given as paths are read with
        these systems; already read ObsData/NavData are used as they are.
    start_s, end_s : float
        Span to use, seconds after the first observation epoch (end None: all).
    init_position : "spp" or [lat_deg, lon_deg, h_m] (antenna)
    init_velocity : "doppler", "zero" or [vn, ve, vd] [m/s]
    init_yaw_deg : "course" or a number [deg]
    init_yaw_sigma_deg : float or None (None: 20 with "course", 10 given)
    course_min_speed_mps, course_window_s : the "course" start rule
    level_window_s : accelerometer levelling window before the start [s]
    reference : str or None
        RTKLIB ``.pos`` reference (becomes ``dataset.truth``).
    """

    imu_columns: tuple = ("t", "ax", "ay", "az", "gx", "gy", "gz")
    imu_time: str = "gps_s"
    imu_acc_unit: str = "mps2"
    imu_gyro_unit: str = "rps"
    imu_samples: str = "rate"
    imu_mount_rpy_deg: tuple = (0.0, 0.0, 0.0)
    imu_time_offset_s: float = 0.0
    imu_delimiter: str = ","
    imu_tag: str | None = None
    lever_arm_b: tuple = (0.0, 0.0, 0.0)
    elevation_mask_deg: float = 10.0
    iono: bool = True
    tropo: bool = True
    sigma_pr_zenith_m: float = 3.0
    sigma_prr_zenith_mps: float = 0.3
    use_cn0: bool = True
    systems: str = "G"
    start_s: float = 0.0
    end_s: float | None = None
    init_position: object = "spp"
    init_velocity: object = "doppler"
    init_yaw_deg: object = "course"
    init_yaw_sigma_deg: float | None = None
    course_min_speed_mps: float = 0.8
    course_window_s: float = 1.0
    level_window_s: float = 1.0
    reference: str | None = None

    def imu_format(self) -> ImuCsvFormat:
        return ImuCsvFormat(tuple(self.imu_columns), self.imu_time, self.imu_acc_unit, self.imu_gyro_unit,
                            self.imu_samples, tuple(self.imu_mount_rpy_deg), float(self.imu_time_offset_s),
                            self.imu_delimiter)

    @classmethod
    def from_dict(cls, d: dict, source: str = "[rinex]") -> "RinexOptions":
        """Options from a TOML table; unknown keys and bad values raise ConfigError naming them."""
        names = {f.name for f in dataclasses.fields(cls)}
        for k in d:
            if k not in names:
                raise ConfigError(f"{source}: unknown key 'rinex.{k}'; known keys: {', '.join(sorted(names))}")
        opt = cls(**d)
        return opt.validate(source)

    def validate(self, source: str = "rinex options") -> "RinexOptions":
        def bad(key, allowed):
            raise ConfigError(f"{source}: key 'rinex.{key}': bad value {getattr(self, key)!r}; allowed: {allowed}")

        self.imu_format().validate(source)
        if not (isinstance(self.systems, str) and "G" in self.systems and set(self.systems) <= set("GREC")
                and len(set(self.systems)) == len(self.systems)):
            bad("systems", 'letters of "GREC" including G (GPS is the clock reference), e.g. "GEC"')
        for key in ("iono", "tropo", "use_cn0"):
            if not isinstance(getattr(self, key), bool):
                bad(key, "true or false")
        for key in ("elevation_mask_deg", "sigma_pr_zenith_m", "sigma_prr_zenith_mps", "start_s",
                    "course_min_speed_mps", "course_window_s", "level_window_s", "end_s", "init_yaw_sigma_deg"):
            v = getattr(self, key)
            if v is None and key in ("end_s", "init_yaw_sigma_deg"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                bad(key, "a finite number")
        for key in ("sigma_pr_zenith_m", "sigma_prr_zenith_mps", "course_window_s", "level_window_s"):
            if not getattr(self, key) > 0:
                bad(key, "> 0")
        if self.end_s is not None and not self.end_s > self.start_s:
            bad("end_s", f"> start_s ({self.start_s})")
        la = np.asarray(self.lever_arm_b, dtype=float) if not isinstance(self.lever_arm_b, str) else np.zeros(0)
        if la.shape != (3,) or not np.all(np.isfinite(la)):
            bad("lever_arm_b", "3 finite values [m]")
        for key, word, n in (("init_position", "spp", 3), ("init_velocity", ("doppler", "zero"), 3)):
            v = getattr(self, key)
            words = (word,) if isinstance(word, str) else word
            if isinstance(v, str):
                if v not in words:
                    bad(key, " or ".join(f'"{w}"' for w in words) + f" or {n} numbers")
            else:
                try:
                    a = np.asarray(v, dtype=float)
                except (TypeError, ValueError):
                    a = np.zeros(0)
                if a.shape != (n,) or not np.all(np.isfinite(a)):
                    bad(key, " or ".join(f'"{w}"' for w in words) + f" or {n} numbers")
        v = self.init_yaw_deg
        if isinstance(v, str) and v != "course" or (not isinstance(v, str) and (
                isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v))):
            bad("init_yaw_deg", '"course" or a number [deg]')
        return self


@dataclass
class RinexDataset(Dataset):
    """A :class:`~insnav.data.dataset.Dataset` built from real files (tight coupling).

    Extra attributes
    ----------------
    tight_inputs : insnav.gnss.tight_inputs.TightInputs
        Per-epoch satellite rows (read by :func:`insnav.filters.tight.run_tight`).
    spp : SinglePoint
        GNSS-only single-point solution of the same rows (all epochs).
    info : dict
        Counts and choices (satellites, IMU rate, time-tag fit, start rule).
    options : RinexOptions
        The loader options used.

    ``gnss`` holds the single-point fixes after ``t0`` (so loose coupling runs
    too); ``truth`` the RTKLIB reference (antenna, no attitude) when given.
    """

    tight_inputs: object = None
    spp: SinglePoint | None = None
    info: dict = field(default_factory=dict)
    options: RinexOptions | None = None


def _level(f_b_mean) -> tuple[float, float]:
    """(roll, pitch) [rad] from a mean specific force in FRD (at rest f_b = C_bn (0, 0, -g))."""
    fx, fy, fz = f_b_mean
    return math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))


def _epochs_in(inp, t_lo, t_hi):
    """Sub-:class:`TightInputs` with the epochs ``t_lo < t <= t_hi``."""
    from ..gnss.tight_inputs import TightInputs

    m = (inp.epoch_t > t_lo) & (inp.epoch_t <= t_hi)
    e = np.flatnonzero(m)
    if e.size == 0:
        return TightInputs(np.zeros(0), np.zeros(1, np.int64), np.zeros((0, 12)), np.zeros(0, np.int64),
                           np.zeros(0), dict(inp.info))
    a, b = inp.epoch_start[e[0]], inp.epoch_start[e[-1] + 1]
    return TightInputs(inp.epoch_t[e].copy(), (inp.epoch_start[e[0]:e[-1] + 2] - a).astype(np.int64),
                       inp.sats[a:b].copy(), inp.prn[a:b].copy(), inp.elevation_deg[a:b].copy(), dict(inp.info),
                       inp.system[a:b].copy())


def _approx_position(obs, nav, t_week0):
    """Approximate receiver position: the header's, else a bootstrap from the centroid of the satellites."""
    from ..gnss.tight_inputs import tight_inputs_from_rinex

    r = getattr(obs, "approx_r_e", None)
    if r is not None and np.all(np.isfinite(r)) and np.linalg.norm(r) > 6.0e6:
        return np.asarray(r, float)
    from ..gnss.ephemeris import sat_position_velocity, select_ephemeris

    gps = np.asarray(getattr(obs, "system", np.full(np.shape(obs.prn), "G"))) == "G"  # multi-system obs
    idx = select_ephemeris(nav.eph, obs.prn[gps], obs.t_gps_s[gps])
    ok = idx >= 0
    if not ok.any():
        raise ValueError(f"{obs.path}: no observation has a GPS ephemeris in {getattr(nav, 'path', 'the nav file')}")
    rs = sat_position_velocity(nav.eph, idx[ok], obs.t_gps_s[gps][ok]).r_e
    c = rs.mean(axis=0)
    r0 = c / np.linalg.norm(c) * earth.A
    for _ in range(2):  # rough inputs -> single point -> again
        inp = tight_inputs_from_rinex(obs, nav, t_week0, r0, elevation_mask_deg=-90.0, iono=False, tropo=False)
        spp = single_point_solution(inp, r0)
        good = np.isfinite(spp.r_e[:, 0])
        if not good.any():
            raise ValueError(f"{obs.path}: no epoch with 4 GPS satellites for a first position fix")
        r0 = np.median(spp.r_e[good], axis=0)
    return r0


def load_rinex(obs, nav, imu, options: RinexOptions | dict | None = None, *, imu_tag=None,
               reference=None) -> tuple[RinexDataset, RunConfig]:
    """Build a dataset and a run configuration from RINEX + IMU (+ reference) files.

    Parameters
    ----------
    obs, nav : path or insnav.gnss.ObsData / NavData
        RINEX 2/3 observation and navigation files (GPS L1 C/A, LNAV).
    imu : path
        IMU CSV (format: ``options``).
    options : RinexOptions or dict (the ``[rinex]`` TOML table)
    imu_tag : path, optional
        Overrides ``options.imu_tag``.
    reference : path, optional
        RTKLIB ``.pos``; overrides ``options.reference``.

    Returns
    -------
    dataset : RinexDataset
        Dataset time = GPS seconds of week (see the module docstring).
    config : RunConfig
        ``coupling="tight"``, ``filter="ekf"``, ``init_error=False`` and initial
        sigmas from the single-point covariance and the start rule.

    Raises
    ------
    ImuFileError, insnav.gnss.RinexError
        Malformed files (file and line).
    ValueError
        No usable start epoch, no IMU data over the GNSS span.
    """
    from ..gnss import read_rinex_nav, read_rinex_obs
    from ..gnss.tight_inputs import tight_inputs_from_rinex

    if options is None:
        opt = RinexOptions().validate()
    elif isinstance(options, dict):
        opt = RinexOptions.from_dict(options)
    else:
        opt = options.validate()
    if imu_tag is not None:
        opt.imu_tag = os.path.abspath(imu_tag)
    if reference is not None:
        opt.reference = os.path.abspath(reference)
    if not hasattr(obs, "C1"):
        obs = read_rinex_obs(obs, systems=opt.systems)
    if not hasattr(nav, "eph"):
        nav = read_rinex_nav(nav, systems=opt.systems)
    if obs.epoch_t_gps_s.size == 0:
        raise ValueError(f"{obs.path}: no observation epochs")
    week = int(obs.epoch_week[0])
    t_week0 = SECONDS_PER_WEEK * week
    fmt = opt.imu_format().validate()
    samples = read_imu_csv(imu, fmt, tag=opt.imu_tag, week=week)

    r0 = _approx_position(obs, nav, t_week0)
    kw = dict(elevation_mask_deg=opt.elevation_mask_deg, iono=opt.iono, tropo=opt.tropo,
              sigma_pr_zenith_m=opt.sigma_pr_zenith_m, sigma_prr_zenith_mps=opt.sigma_prr_zenith_mps,
              use_cn0=opt.use_cn0)
    inp = tight_inputs_from_rinex(obs, nav, t_week0, r0, **kw)
    spp = single_point_solution(inp, r0)
    good = np.isfinite(spp.r_e[:, 0])
    if good.any():  # recompute light time / elevation / atmosphere at the data's own position
        r0 = np.median(spp.r_e[good], axis=0)
        inp = tight_inputs_from_rinex(obs, nav, t_week0, r0, **kw)
        spp = single_point_solution(inp, r0)
        good = np.isfinite(spp.r_e[:, 0])

    t_first = float(obs.epoch_t_gps_s[0] - t_week0)
    imu_t = (samples.t_ref_gps_s - t_week0) + samples.t_s
    t_lo = max(t_first + opt.start_s, float(imu_t[1]) + opt.level_window_s
               if opt.init_yaw_deg == "course" else float(imu_t[1]))
    t_hi = float(imu_t[-1]) if opt.end_s is None else min(float(imu_t[-1]), t_first + opt.end_s)
    t_last = float(obs.epoch_t_gps_s[-1] - t_week0)
    if imu_t[-1] <= t_first or imu_t[0] >= t_last:
        raise ValueError(f"{samples.path}: the IMU data (GPS seconds of week {week}: {imu_t[0]:.3f} to "
                         f"{imu_t[-1]:.3f}) do not overlap the observations in {obs.path} ({t_first:.3f} to "
                         f"{t_last:.3f}); check the IMU time column and imu_time")
    v_n_spp = spp.v_n()
    speed = np.hypot(v_n_spp[:, 0], v_n_spp[:, 1])
    cand = np.flatnonzero(good & (spp.t >= t_lo) & (spp.t < t_hi))
    if cand.size == 0:
        raise ValueError(f"{obs.path}: no epoch with a single-point fix (4 GPS satellites with ephemeris) "
                         f"between {t_lo - t_first:.1f} s and {t_hi - t_first:.1f} s after the first epoch "
                         f"and inside the IMU data ({samples.path})")
    start_rule = "first fix"
    yaw_sigma = 10.0 if opt.init_yaw_sigma_deg is None else float(opt.init_yaw_sigma_deg)
    if opt.init_yaw_deg == "course":
        k0 = None
        for k in cand:
            w = (spp.t > spp.t[k] - opt.course_window_s - 1e-6) & (spp.t <= spp.t[k])
            if spp.t[k] - opt.course_window_s < t_lo - 1e-6:
                continue
            ok_w = good[w] & np.isfinite(speed[w])
            if ok_w.all() and np.all(speed[w] >= opt.course_min_speed_mps):
                k0 = int(k)
                break
        if k0 is None:
            raise ValueError(f"{obs.path}: init_yaw_deg = \"course\": the single-point speed never stays above "
                             f"{opt.course_min_speed_mps} m/s for {opt.course_window_s} s; give init_yaw_deg")
        w = (spp.t > spp.t[k0] - opt.course_window_s - 1e-6) & (spp.t <= spp.t[k0])
        vm = v_n_spp[w].mean(axis=0)
        yaw0 = math.degrees(math.atan2(vm[1], vm[0]))
        start_rule = (f"course: first {opt.course_window_s:g} s with single-point speed >= "
                      f"{opt.course_min_speed_mps:g} m/s")
        yaw_sigma = 20.0 if opt.init_yaw_sigma_deg is None else float(opt.init_yaw_sigma_deg)
    else:
        k0 = int(cand[0])
        yaw0 = float(opt.init_yaw_deg)
    t_ep = float(spp.t[k0])
    i0 = int(np.searchsorted(imu_t, t_ep, side="right")) - 1  # last IMU sample at or before the epoch
    if i0 < 1:
        raise ValueError(f"{samples.path}: the IMU data start after the start epoch ({t_ep:.3f} s of week)")
    t0 = float(imu_t[i0])

    # levelling: mean specific force over level_window_s before t0 (after it if the data start later)
    imu = samples.to_increments(t_week0)
    lw = (imu.t > t0 - opt.level_window_s) & (imu.t <= t0)
    if lw.sum() < 3:
        lw = (imu.t > t0) & (imu.t <= t0 + opt.level_window_s)
    dt_imu = np.diff(imu.t, prepend=imu.t[0] - imu.dt)
    f_mean = imu.dv_b[lw].sum(axis=0) / dt_imu[lw].sum()
    roll0, pitch0 = _level(f_mean)

    lever = np.asarray(opt.lever_arm_b, float)
    if isinstance(opt.init_position, str):
        lat_a, lon_a, h_a = earth.ecef_to_geodetic(spp.r_e[k0])
        sig_pos = np.maximum(spp.sigma_pos_n_m[k0], 1.0)
    else:
        lat_a, lon_a, h_a = opt.init_position[0] * DEG, opt.init_position[1] * DEG, float(opt.init_position[2])
        sig_pos = np.array([1.0, 1.0, 1.0])
    if isinstance(opt.init_velocity, str):
        v0 = v_n_spp[k0].copy() if opt.init_velocity == "doppler" else np.zeros(3)
        sig_vel = (np.maximum(spp.sigma_vel_n_mps[k0], 0.1) if opt.init_velocity == "doppler"
                   else np.full(3, 0.1))
        if opt.init_velocity == "doppler" and not np.all(np.isfinite(v0)):
            v0, sig_vel = np.zeros(3), np.full(3, 1.0)
    else:
        v0, sig_vel = np.asarray(opt.init_velocity, float), np.full(3, 0.1)
    # antenna -> IMU centre
    C_nb = np.asarray(_core.rotation.dcm_from_euler(np.array([roll0, pitch0, yaw0 * DEG])))
    r_imu = earth.geodetic_to_ecef(lat_a, lon_a, h_a) - earth.C_en(lat_a, lon_a) @ (C_nb @ lever)
    lat0, lon0, h0 = earth.ecef_to_geodetic(r_imu)
    initial = NavState(lat0 * RAD2DEG, lon0 * RAD2DEG, h0, v0, roll0 * RAD2DEG, pitch0 * RAD2DEG, yaw0)

    sel = (imu.t > t0) & (imu.t <= t_hi)
    origin = imu.origin.take(sel, len(imu.t))
    imu = ImuData(imu.t[sel], imu.dtheta_b[sel], imu.dv_b[sel], origin=origin)
    if opt.systems != "G":  # every system's rows for the filter (ISB states); the start above is GPS
        inp = tight_inputs_from_rinex(obs, nav, t_week0, r0, systems=opt.systems, **kw)
    inp_run = _epochs_in(inp, t0, float(imu.t[-1]))
    g = np.flatnonzero(good & (spp.t > t0) & (spp.t <= float(imu.t[-1])))
    lat_g, lon_g, h_g = earth.ecef_to_geodetic(spp.r_e[g])
    gnss = GnssFixes(spp.t[g], spp.t[g], lat_g * RAD2DEG, lon_g * RAD2DEG, h_g, v_n_spp[g],
                     spp.sigma_pos_n_m[g], spp.sigma_vel_n_mps[g])
    truth = None
    if opt.reference:
        truth = rtklib_truth(opt.reference, t_week0)
    n = inp_run.n_sats()
    info = dict(obs=str(obs.path), nav=str(getattr(nav, "path", "")), imu=samples.path, week=week,
                imu_samples=len(samples), imu_rate_hz=samples.rate_hz, imu_time=samples.info,
                gps_prns_observed=sorted(int(p) for p in np.unique(np.asarray(obs.prn)[
                    np.asarray(getattr(obs, "system", np.full(len(obs.prn), "G"))) == "G"])),
                gps_prns_with_ephemeris=sorted(int(p) for p in np.unique(nav.eph.prn)),
                prns_used=sorted(int(p) for p in np.unique(inp_run.prn[inp_run.system == "G"])),
                sats_used=sorted(set(f"{s}{int(p):02d}" for s, p in zip(inp_run.system, inp_run.prn))),
                sats_per_epoch=(int(n.min()), int(np.median(n)), int(n.max())) if n.size else (0, 0, 0),
                start_rule=start_rule, start_s_after_first_epoch=t0 - t_first, approx_r_e=r0.tolist(),
                f_level_mps2=f_mean.tolist())
    ds = RinexDataset(imu=imu, gnss=gnss, truth=truth, gnss_raw=None, imu_errors=None,
                      scenario={"rinex": dict(obs=str(obs.path), imu=samples.path)}, lever_arm_b=lever,
                      initial=initial, t0=t0, gps_time_offset_s=float(t_week0), imu_model=dict(CONSUMER_MEMS_MODEL),
                      name=Path(str(obs.path)).stem, tight_inputs=inp_run, spp=spp, info=info, options=opt)
    moving = opt.init_yaw_deg == "course" or np.linalg.norm(v0) > 0.3
    cfg = RunConfig(filter="ekf", coupling="tight", init_error=False,
                    init_sigma_pos_m=np.asarray(sig_pos, float).tolist(),
                    init_sigma_vel_mps=np.asarray(sig_vel, float).tolist(),
                    init_sigma_att_deg=[3.0 if moving else 1.0, 3.0 if moving else 1.0, yaw_sigma])
    return ds, cfg


def load_rinex_run(obs, nav, imu, config_path=None, *, imu_tag=None, reference=None):
    """:func:`load_rinex` with a run TOML (``insnav run --format rinex``).

    The TOML holds the usual run keys (``docs/formats.md``) plus a ``[rinex]``
    table (:class:`RinexOptions`).  Run keys it sets override the loader's
    suggestions (initial sigmas, ``init_error = false``); a top-level
    ``lever_arm_b`` is also used as the dataset's lever arm.  Relative paths in
    the table (``imu_tag``, ``reference``) are relative to the TOML file.

    Returns
    -------
    (RinexDataset, RunConfig)
    """
    d = {}
    source = "run configuration"
    if config_path is not None:
        source = os.fspath(config_path)
        try:
            with open(config_path, "rb") as f:
                d = tomllib.load(f)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    rin = d.pop("rinex", {})
    if not isinstance(rin, dict):
        raise ConfigError(f"{source}: key 'rinex': bad value {rin!r}; allowed: a table")
    if "lever_arm_b" in d and "lever_arm_b" not in rin:
        rin = dict(rin, lever_arm_b=d["lever_arm_b"])
    for key in ("imu_tag", "reference"):
        if isinstance(rin.get(key), str) and config_path is not None and not os.path.isabs(rin[key]):
            rin = dict(rin, **{key: os.path.join(os.path.dirname(os.path.abspath(config_path)), rin[key])})
    opt = RinexOptions.from_dict(rin, source)
    ds, cfg = load_rinex(obs, nav, imu, opt, imu_tag=imu_tag, reference=reference)
    base = {k: v for k, v in dataclasses.asdict(cfg).items() if v is not None and k != "imu"}
    base.update(d)
    return ds, config_from_dict(base, source=source)
