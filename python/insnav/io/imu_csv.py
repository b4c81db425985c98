"""IMU CSV files: one reader for every insnav loader (``--format csv`` and
``--format rinex``) that maps columns, units, axes and the time base to SI
increments in the body frame.

IMU file (:class:`ImuCsvFormat`)
--------------------------------
One sample per line, fields separated by ``delimiter`` (``,``).  ``columns``
names the fields in file order: ``t`` (time, see ``time``) or ``tick_ms``
(an IMU counter in ms, needs a str2str tag file), ``ax ay az`` (accelerometer),
``gx gy gz`` (gyro), ``_`` (ignored); or it is a table ``{role: header name}``
(e.g. ``{t = "time", ax = "acc_x", ...}``) matched against the header line.
With no time column at all, ``rate_hz`` gives the times:
``t_k = time_offset_s + k / rate_hz``.  Blank lines and lines starting with
``#`` are skipped; the first remaining line is a header (skipped) when its
first field is not a number.  Options:

==================  ==========================================================
``time``            ``gps_s`` (s since 1980-01-06), ``gps_sow`` (GPS seconds
                    of week; the week is ``gps_week`` or the observation
                    file's), ``gpst_unix_s`` (RTKLIB ``gtime_t`` style: GPS
                    time counted from 1970-01-01, e.g. the rtklibexplorer
                    ``*_sf.csv``), ``unix_utc_s`` (POSIX time, UTC: leap
                    seconds added, :func:`gps_minus_utc_s`) or ``relative``
                    (the user's own clock, the same as the GNSS file's)
``time_unit``       ``s``, ``ms``, ``us`` or ``ns`` (of the time column)
``time_offset_s``   added to every IMU time [s] (a known logging delay)
``acc_unit``        ``mps2`` (also ``m/s^2``) or ``g`` (standard gravity
                    9.80665 m/s^2)
``gyro_unit``       ``rps`` (also ``rad``, ``rad/s``) or ``dps`` (``deg``, ``deg/s``)
``samples``         ``rate`` (``rates``: specific force and angular rate at
                    ``t``, integrated to increments with the trapezoidal rule
                    over ``(t_prev, t]``; the first sample only starts the
                    integration), ``mean_rate`` (the mean rate over
                    ``(t_prev, t]``: increment = rate x dt, exact) or
                    ``increment`` (``increments``: velocity and angle
                    increments over ``(t_prev, t]`` in the rate unit times
                    seconds: m/s or g s, rad or deg)
``axes``            the directions of the sensor's x, y, z axes in the body:
                    three letters from F/B (forward/back), R/L (right/left),
                    D/U (down/up), e.g. ``FRD`` (default), ``FLU``, ``RFU``;
                    a left-handed triad is an error
``mount_rpy_deg``   3-2-1 Euler angles of those axes relative to the body FRD
                    axes [deg]: ``x_b = C(mount) A(axes) x_imu`` with ``C`` the
                    same DCM as the attitude ``C_nb``
``rate_hz``         nominal sample rate [Hz]: the times when there is no time
                    column; otherwise checked against the median interval
                    (within 10 %: a wrong ``time_unit`` shows there)
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

Errors
------
A problem with a file raises :class:`ImuFileError`, a ``ValueError`` whose
message names the file, the 1-based line (the byte offset for the binary tag
file) and what was wrong; a bad format option a
:class:`~insnav.config.ConfigError` naming the key.
"""
from __future__ import annotations

from ..errors import close_matches

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import _core
from .._median import median, percentile  # np.median/np.percentile without numpy.ma
from ..config import ConfigError
from ..data.dataset import ImuData, RowOrigin
from ..data.textio import read_bytes
from ..gnss.gpstime import SECONDS_PER_WEEK, gps_seconds_from_calendar
from ..units import DEG, G0

__all__ = ["ImuFileError", "ImuCsvFormat", "ImuSamples", "Str2strTag", "read_str2str_tag", "tick_time_map",
           "read_imu_csv", "axes_matrix", "gps_minus_utc_s", "GPST_UNIX_OFFSET_S", "canonical_choice", "CsvLineParser",
           "SampleConverter", "TimeFields"]

#: GPS seconds since 1980-01-06 of 1970-01-01 in GPS time: ``t_gps = t_gtime - 315964800`` [s]
GPST_UNIX_OFFSET_S = int(round(-gps_seconds_from_calendar(1970, 1, 1)))
_TAG_MAGIC = b"TIMETAG RTKLIB"
_TAG_HEADER = 64          # bytes before u32 time, f64 sec
_TAG_FIRST_RECORD = 76    # 64 + 4 + 8


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


# --------------------------------------------------------------------------- time systems

#: UTC dates from which GPS - UTC grew by one second (IERS Bulletin C; GPS = UTC on 1980-01-06).
_LEAP_DATES = ((1981, 7, 1), (1982, 7, 1), (1983, 7, 1), (1985, 7, 1), (1988, 1, 1), (1990, 1, 1), (1991, 1, 1),
               (1992, 7, 1), (1993, 7, 1), (1994, 7, 1), (1996, 1, 1), (1997, 7, 1), (1999, 1, 1), (2006, 1, 1),
               (2009, 1, 1), (2012, 7, 1), (2015, 7, 1), (2017, 1, 1))
#: the same instants as UTC seconds since 1980-01-06 (calendar arithmetic, no leap seconds)
_LEAP_UTC_S = np.array([gps_seconds_from_calendar(*d) for d in _LEAP_DATES])


def gps_minus_utc_s(t_utc_s) -> np.ndarray:
    """GPS - UTC [s] (leap seconds, 18 since 2017-01-01) at a UTC time
    counted in calendar seconds since 1980-01-06 (IERS Bulletin C)."""
    return np.searchsorted(_LEAP_UTC_S, np.asarray(t_utc_s, float), side="right").astype(float)


# --------------------------------------------------------------------------- IMU CSV

_ROLES = ("t", "tick_ms", "ax", "ay", "az", "gx", "gy", "gz", "_")
_ALLOWED_COLUMNS = _ROLES
#: canonical value -> accepted spellings
_CHOICES = dict(time={"gps_s": (), "gps_sow": (), "gpst_unix_s": (), "unix_utc_s": (), "relative": ()},
                time_unit={"s": (), "ms": (), "us": (), "ns": ()},
                acc_unit={"mps2": ("m/s^2", "m/s2"), "g": ()},
                gyro_unit={"rps": ("rad", "rad/s"), "dps": ("deg", "deg/s")},
                samples={"rate": ("rates",), "mean_rate": ("mean_rates",), "increment": ("increments",)})
_TIME_SCALE = {"s": 1, "ms": 1000, "us": 1_000_000, "ns": 1_000_000_000}
_AXIS_DIR = {"F": (0, 1.0), "B": (0, -1.0), "R": (1, 1.0), "L": (1, -1.0), "D": (2, 1.0), "U": (2, -1.0)}


def canonical_choice(value, choices: dict, key: str, source: str):
    """The canonical spelling of ``value`` among ``choices`` (value -> aliases);
    a ConfigError naming ``key`` and every allowed spelling otherwise."""
    for canon, aliases in choices.items():
        if value == canon or value in aliases:
            return canon
    allowed = ", ".join(choices)
    aliases = [a for al in choices.values() for a in al]
    raise ConfigError(f"{source}: {key}: bad value {value!r}; allowed: {allowed}"
                      + (f" (also written {', '.join(aliases)})" if aliases else ""))


def axes_matrix(axes: str) -> np.ndarray:
    """(3, 3) ``A`` with ``x_FRD = A x_sensor`` for sensor axes named by three
    letters (F/B, R/L, D/U): column ``i`` is the body direction of sensor axis ``i``.

    Raises
    ------
    ValueError
        Not three letters naming three different body axes, or a left-handed triad.
    """
    s = str(axes).upper()
    if len(s) != 3 or any(c not in _AXIS_DIR for c in s) or len({_AXIS_DIR[c][0] for c in s}) != 3:
        raise ValueError(f"bad axes {axes!r}: three letters from F/B, R/L, D/U naming three different axes "
                         "(e.g. FRD, FLU, RFU)")
    A = np.zeros((3, 3))
    for i, c in enumerate(s):
        k, sign = _AXIS_DIR[c]
        A[k, i] = sign
    if np.linalg.det(A) < 0:
        raise ValueError(f"bad axes {axes!r}: a left-handed triad (x cross y must be z); check the sign of one axis")
    return A


@dataclass
class ImuCsvFormat:
    """How to read an IMU CSV (see the module docstring for each option).

    The first eight fields keep their order (``RinexOptions.imu_format``)."""

    columns: tuple = ("t", "ax", "ay", "az", "gx", "gy", "gz")
    time: str = "gps_s"
    acc_unit: str = "mps2"
    gyro_unit: str = "rps"
    samples: str = "rate"
    mount_rpy_deg: tuple = (0.0, 0.0, 0.0)
    time_offset_s: float = 0.0
    delimiter: str = ","
    axes: str = "FRD"
    time_unit: str = "s"
    gps_week: int | None = None
    rate_hz: float | None = None

    def validate(self, source: str = "imu format", prefix: str = "imu_") -> "ImuCsvFormat":
        """Check every option (``prefix`` + field name in the messages) and
        canonicalise the spellings; returns self."""
        cols = self.columns
        if isinstance(cols, dict):
            for role, name in cols.items():
                if role not in _ROLES or role == "_":
                    raise ConfigError(f"{source}: {prefix}columns: unknown role {role!r}; allowed: "
                                      f"{', '.join(r for r in _ROLES if r != '_')}")
                if not isinstance(name, str) or not name:
                    raise ConfigError(f"{source}: {prefix}columns.{role}: bad value {name!r}; allowed: a header name")
            roles = tuple(cols)
        else:
            if isinstance(cols, str) or not isinstance(cols, (list, tuple)) \
                    or not all(isinstance(c, str) for c in cols):
                raise ConfigError(f"{source}: {prefix}columns: bad value {cols!r}; allowed: a list of "
                                  f"{', '.join(_ROLES)} in file order, or a table role = header name")
            cols = roles = tuple(cols)
            for c in cols:
                if c not in _ROLES:
                    close = close_matches(c, _ROLES)
                    raise ConfigError(f"{source}: {prefix}columns: unknown column {c!r}"
                                      + (f" (did you mean {close[0]!r}?)" if close else "")
                                      + f"; allowed: {', '.join(_ROLES)}")
        for c in ("ax", "ay", "az", "gx", "gy", "gz"):
            if roles.count(c) != 1:
                raise ConfigError(f"{source}: {prefix}columns {list(roles)} must name {c!r} exactly once")
        n_time = roles.count("t") + roles.count("tick_ms")
        if n_time > 1 or (n_time == 0 and self.rate_hz is None):
            raise ConfigError(f"{source}: {prefix}columns {list(roles)} must have exactly one of 't' or 'tick_ms' "
                              f"(or none and {prefix}rate_hz)")
        for key, choices in _CHOICES.items():
            setattr(self, key, canonical_choice(getattr(self, key), choices, prefix + key, source))
        try:
            m = np.asarray(self.mount_rpy_deg, dtype=float) if not isinstance(self.mount_rpy_deg, str) else np.zeros(0)
        except (TypeError, ValueError):  # a table or a nested list where 3 angles belong
            m = np.zeros(0)
        if m.shape != (3,) or not np.all(np.isfinite(m)):
            raise ConfigError(f"{source}: {prefix}mount_rpy_deg: bad value {self.mount_rpy_deg!r}; "
                              "allowed: 3 angles [deg]")
        try:
            axes_matrix(self.axes)
        except ValueError as exc:
            raise ConfigError(f"{source}: {prefix}axes: {exc}") from None
        self.axes = str(self.axes).upper()
        if not (isinstance(self.delimiter, str) and len(self.delimiter) == 1):
            raise ConfigError(f"{source}: {prefix}delimiter: bad value {self.delimiter!r}; allowed: one character")
        v = self.time_offset_s
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ConfigError(f"{source}: {prefix}time_offset_s: bad value {v!r}; allowed: a finite number [s]")
        v = self.rate_hz
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v)
                                                                                            and v > 0)):
            raise ConfigError(f"{source}: {prefix}rate_hz: bad value {v!r}; allowed: a number > 0 [Hz]")
        v = self.gps_week
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
            raise ConfigError(f"{source}: {prefix}gps_week: bad value {v!r}; allowed: a full GPS week number >= 0")
        self.columns = cols
        return self

    @property
    def roles(self) -> tuple:
        return tuple(self.columns)

    @property
    def uses_tick(self) -> bool:
        return "tick_ms" in self.roles

    def C_b_imu(self) -> np.ndarray:
        """(3, 3) rotation IMU sensor axes -> body FRD: ``x_b = C(mount) A(axes) x_imu``."""
        C = np.asarray(_core.rotation.dcm_from_euler(np.asarray(self.mount_rpy_deg, float) * DEG))
        return C @ axes_matrix(self.axes)


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
    samples : {'rate', 'mean_rate', 'increment'}
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
        samples), mean rates times the interval; either way the first sample
        yields no increment.
        """
        t = (self.t_ref_gps_s - t_offset_s) + self.t_s
        if self.samples == "increment":
            return ImuData(t.copy(), self.gyro_b.copy(), self.acc_b.copy(),
                           origin=RowOrigin(self.path, lines=self.lines.copy()))
        # intervals from the times after t_ref (~1e-16 s resolution), not from t (seconds of
        # week have 6e-11 s steps: 1e-8 of a 5 ms interval)
        dt = np.diff(self.t_s)[:, None]
        if self.samples == "mean_rate":  # the mean rate over (t[k-1], t[k]]: exact
            dth, dv = self.gyro_b[1:] * dt, self.acc_b[1:] * dt
        else:
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
        b = read_bytes(path)
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
    return t, dict(drift_ppm=float(slope * 1e6), latency_median_ms=median(lat),
                   latency_p95_ms=percentile(lat, 95), latency_max_ms=float(lat.max()))


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


_GYRO_WORDS = ("gyro", "dtheta", "omega", "angvel", "ang_vel", "angular", "rad_s", "radps", "dps", "deg_s")
_ACC_WORDS = ("acc", "dv_", "dvel", "specific", "mps2", "m_s2", "m/s^2")


def _sensor_of(name: str) -> str | None:
    """'gyro', 'acc' or None (not recognised, or both) for a header name."""
    n = name.strip().lower()
    g, a = any(w in n for w in _GYRO_WORDS), any(w in n for w in _ACC_WORDS)
    return "gyro" if g and not a else "acc" if a and not g else None


def _header_contradiction(tok, cols, samples: str) -> str | None:
    """What a header line skipped by a positional ``columns`` mapping says against it: a column mapped
    as an accelerometer axis whose name is a gyro's (or the reverse), or increments (``dtheta_*``,
    ``dv_*``, insnav's own imu.csv) read as rates.  None when the names do not contradict it."""
    if cols is None or len(tok) != len(cols):
        return None
    for j, (role, name) in enumerate(zip(cols, tok)):
        want = "acc" if role in ("ax", "ay", "az") else "gyro" if role in ("gx", "gy", "gz") else None
        got = _sensor_of(name)
        if want and got and got != want:
            return (f"the header names field {j + 1} {name.strip()!r}, a {'gyro' if got == 'gyro' else 'n accelerometer'} "
                    f"column, but the columns mapping {list(cols)} reads it as {role!r}: set the [imu] columns "
                    "(an insnav dataset's imu.csv: --format insnav)")
        if want and samples == "rate" and name.strip().lower().startswith(("dtheta", "dv_")):
            return (f"the header names field {j + 1} {name.strip()!r}, an increment, but samples = 'rate': set "
                    "samples = \"increment\" (an insnav dataset's imu.csv: --format insnav)")
    return None


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def time_base_ref_s(time: str, ref_s: int, t_first_s: float, week: int | None = None) -> float:
    """GPS time [s] of the whole-second reference ``ref_s`` of a file's times
    (:func:`_split_time`) in the time base ``time``: ``gpst_unix_s`` (GPS
    seconds counted from 1970), ``unix_utc_s`` (UTC: the leap seconds of
    :func:`gps_minus_utc_s` at the first sample, ``ref_s + t_first_s``, added),
    ``gps_sow`` (seconds of GPS week ``week``) or ``gps_s`` / ``relative`` (as
    they are).  Shared by the IMU and the GNSS CSV readers."""
    if time == "gpst_unix_s":
        return float(ref_s - GPST_UNIX_OFFSET_S)
    if time == "unix_utc_s":
        t_ref = float(ref_s - GPST_UNIX_OFFSET_S)
        return t_ref + float(gps_minus_utc_s(t_ref + t_first_s))
    if time == "gps_sow":
        return float(ref_s + SECONDS_PER_WEEK * int(week))
    return float(ref_s)


def _split_time(tokens, scale: int) -> tuple[int, np.ndarray]:
    """(ref [whole s], times after ref [s]) of decimal time strings in units of 1/scale s,
    keeping every digit (a 1e9-sized float would lose them)."""
    ref_int = int(math.floor(float(tokens[0])))
    t = _time_after(tokens, ref_int)  # units after ref_int
    ref_s, rem = divmod(ref_int, scale)
    return ref_s, (t + rem) / scale


def _header_columns(path, lineno, tok, mapping: dict, delim: str) -> tuple:
    """File-order roles from a header line and a ``{role: header name}`` table."""
    names = [x.strip().strip('"') for x in tok]
    roles = ["_"] * len(names)
    for role, name in mapping.items():
        if name not in names:
            close = close_matches(name, names)
            raise ImuFileError(path, lineno, f"header has no column {name!r} (for {role})"
                               + (f"; did you mean {close[0]!r}?" if close else "")
                               + f"; header: {delim.join(names)}")
        roles[names.index(name)] = role
    return tuple(roles)


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
        GPS week for ``time = "gps_sow"`` when ``fmt.gps_week`` is None (one is required then).

    Returns
    -------
    ImuSamples
        ``t_ref_gps_s`` is GPS time except with ``time = "relative"``
        (``info["time_base"]`` says which).

    Raises
    ------
    ImuFileError
        Naming the file and the 1-based line: wrong number of fields, a bad
        or non-finite number, time not increasing, a header without a mapped
        column, a sample rate that contradicts ``rate_hz``; tag problems (byte offset).
    """
    fmt = (fmt or ImuCsvFormat()).validate()
    path = os.fspath(path)
    try:
        raw = read_bytes(path)
    except OSError as exc:
        raise ImuFileError(path, None, f"cannot read the IMU file ({exc.strerror})") from None
    tagged = fmt.uses_tick
    week = fmt.gps_week if fmt.gps_week is not None else week  # the mapping's own week wins
    if fmt.time == "gps_sow" and not tagged and week is None:
        raise ValueError(f"{path}: imu time 'gps_sow' needs the GPS week (gps_week, or the observation file's)")
    complete_last = raw.endswith(b"\n")
    n_lines = raw.count(b"\n") + (0 if complete_last or not raw else 1)
    parser = CsvLineParser(path, fmt)
    # a str2str log starts and may end mid-line: its first and (unfinished) last lines are dropped
    drop = (0, n_lines - 1 if not complete_last else -1) if tagged else ()
    a, lines, t_tok, ends = parser.feed(raw, 1, drop=drop, ends=tagged)
    if len(a) < 2:
        raise ImuFileError(path, None, f"fewer than 2 IMU samples ({len(a)})")
    if t_tok is None:  # no time column: t_k = k / rate_hz
        a = np.column_stack([np.arange(len(a), dtype=float), a])
    t = a[:, 0]
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        raise ImuFileError(path, int(lines[k]), parser.not_increasing(t[k], lines[k - 1], t[k - 1]))
    info = dict(lines_dropped=[i + 1 for i in dict.fromkeys(drop) if i >= 0], time_base="gps")
    conv = SampleConverter(path, fmt, week)
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
        conv.t_ref = tag.t_start_gps_s
    else:
        t = conv.times(t_tok, t)
        wrong_rate = conv.rate_mismatch(t)
        if wrong_rate:
            raise ImuFileError(path, None, wrong_rate)
        info["time_base"] = conv.time_base
    t = t + float(fmt.time_offset_s)
    acc_b, gyro_b = conv.body(a)
    return ImuSamples(conv.t_ref, t, acc_b, gyro_b, fmt.samples, lines, path, info)


#: 10^9: the time fields' integer part is kept as two int64 halves (hi 10^9 + lo) below 10^27
_E9 = 1_000_000_000


class TimeFields:
    """The time fields of parsed rows, held as :func:`_time_after` reads them
    (so that no text is kept): ``value`` the field as ``float()`` reads it;
    for a plain decimal ``digits[.digits]`` (``kind`` 1) the integer part
    ``hi 10^9 + lo`` and the fraction ``frac`` (``float("0.digits")``);
    ``kind`` 2 (more than 27 integer digits) the text itself (``tokens``:
    row -> text); ``kind`` 0 anything else (``value`` is used)."""

    def __init__(self, value, hi, lo, frac, kind, tokens=None):
        self.value, self.hi, self.lo, self.frac, self.kind = value, hi, lo, frac, kind
        self.tokens = tokens or {}

    def __len__(self) -> int:
        return len(self.value)

    @classmethod
    def from_tokens(cls, tokens, value=None) -> "TimeFields":
        """From the fields' text (``value``: their ``float()``, computed when None)."""
        n = len(tokens)
        hi, lo = np.zeros(n, np.int64), np.zeros(n, np.int64)
        frac, kind = np.zeros(n), np.zeros(n, np.uint8)
        extra = {}
        for i, tok in enumerate(tokens):
            whole, _, fr = tok.strip().partition(".")
            if whole.isdigit() and (not fr or fr.isdigit()):  # as _time_after
                if len(whole) <= 27:
                    hi[i], lo[i] = divmod(int(whole), _E9)
                    frac[i] = float("0." + fr) if fr else 0.0
                    kind[i] = 1
                else:
                    extra[i], kind[i] = tok, 2
        value = np.array([float(t) for t in tokens]) if value is None else np.asarray(value, float)
        return cls(value, hi, lo, frac, kind, extra)

    @classmethod
    def concat(cls, parts) -> "TimeFields":
        tokens, k = {}, 0
        for p in parts:
            tokens.update({k + i: t for i, t in p.tokens.items()})
            k += len(p)
        return cls(*(np.concatenate([getattr(p, a) for p in parts]) for a in ("value", "hi", "lo", "frac", "kind")),
                   tokens)

    def after(self, ref_int: int) -> np.ndarray:
        """The times minus the integer ``ref_int``, equal bit for bit to
        :func:`_time_after` of the fields' text."""
        out = self.value - float(ref_int)  # kind 0: float(tok) - ref_int
        plain = np.flatnonzero(self.kind == 1)
        if plain.size:
            ref_hi, ref_lo = divmod(int(ref_int), _E9)
            dh = None
            if abs(ref_hi) < 2 ** 62:
                dh = self.hi[plain] - np.int64(ref_hi)  # |hi| < 10^18: no overflow
                if np.abs(dh).max() > 9 * _E9:
                    dh = None
            if dh is not None:  # the exact integer difference in int64, then one rounding (as int + float)
                d = dh * _E9 + (self.lo[plain] - np.int64(ref_lo))
                out[plain] = d.astype(float) + self.frac[plain]
            else:
                for i in plain:
                    out[i] = (int(self.hi[i]) * _E9 + int(self.lo[i]) - ref_int) + float(self.frac[i])
        for i, tok in self.tokens.items():
            out[i] = _time_after([tok], ref_int)[0]
        return out


def _compiled_delimiter(delim: str) -> bool:
    """The compiled reader takes tab and printable ASCII delimiters that are no character of a number
    (it parses a field's number in place, up to the delimiter)."""
    return delim == "\t" or (" " <= delim <= "~" and not delim.isalnum() and delim not in ".+-")


class CsvLineParser:
    """The line-by-line part of :func:`read_imu_csv` (blank and ``#`` lines,
    the header, the field count, the numbers), fed the file's lines in one
    piece (:func:`read_imu_csv`) or block by block
    (:func:`insnav.filters.stream.imu_csv_blocks`): the header and the column
    mapping found in the first block hold for the next ones.

    The lines after the header are read by the compiled reader
    (``_core.parse_csv``, ``cpp/include/insnav/io/text_table.hpp``
    ``parse_csv_fields``: ``std::from_chars``, correctly rounded like
    ``float()``) up to any line it does not take exactly as this reader does
    (a bad or non-finite number, a wrong field count, non-ASCII bytes, rare
    whitespace, a form such as ``1_000`` or an over/underflow); that line is
    read here (which raises the error naming the file and line, or takes it),
    and the compiled reader goes on after it.  The values are the same bit for
    bit; ``compiled = False`` reads every line here."""

    def __init__(self, path: str, fmt: ImuCsvFormat, compiled: bool = True):
        self.path, self.fmt = path, fmt
        self.tagged = fmt.uses_tick
        self.by_header = isinstance(fmt.columns, dict)
        self.cols = None if self.by_header else tuple(fmt.columns)
        self.header_allowed = True
        self.want = None  # the fields of the time (if any) and ax..gz, their names
        self._parse_csv = getattr(_core, "parse_csv", None) if compiled and _compiled_delimiter(fmt.delimiter) \
            else None

    def _layout(self) -> None:
        cols = self.cols
        idx = {c: cols.index(c) for c in cols if c != "_"}
        self.tcol = idx["tick_ms"] if self.tagged else idx.get("t")
        self.want = ([] if self.tcol is None else [self.tcol]) + [idx[c] for c in ("ax", "ay", "az", "gx", "gy", "gz")]
        self.names = ([] if self.tcol is None else ["tick_ms" if self.tagged else "t"]) + \
            ["ax", "ay", "az", "gx", "gy", "gz"]
        self.ncol = len(cols)

    def not_increasing(self, t_k, line_prev, t_prev) -> str:
        what = "tick" if self.tagged else "time"
        return f"{what} {float(t_k)!r} does not increase (line {int(line_prev)}: {float(t_prev)!r})"

    def _line(self, b, lineno: int):
        """One line read here: None (skipped: blank, ``#``, the header) or
        (values, the time field's text or None)."""
        path, delim = self.path, self.fmt.delimiter
        try:
            s = b.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ImuFileError(path, lineno, "not ASCII text (binary data in a CSV?)") from None
        if not s or s.startswith("#"):
            return None
        tok = s.split(delim)
        if self.header_allowed:
            self.header_allowed = False
            if self.by_header:
                if _is_number(tok[0].strip()):
                    raise ImuFileError(path, lineno, "no header line, but the columns are mapped by header name")
                self.cols = _header_columns(path, lineno, tok, self.fmt.columns, delim)
                return None
            if not _is_number(tok[0].strip()):
                what = _header_contradiction(tok, self.cols, self.fmt.samples)
                if what:
                    raise ImuFileError(path, lineno, what)
                return None
        if self.cols is None:
            raise ImuFileError(path, lineno, "no header line before the data")
        if self.want is None:
            self._layout()
        if len(tok) != self.ncol:
            raise ImuFileError(path, lineno, f"expected {self.ncol} {delim!r}-separated fields "
                               f"({', '.join(self.cols)}), found {len(tok)}")
        vals = []
        for j, name in zip(self.want, self.names):
            try:
                v = float(tok[j])
            except ValueError:
                raise ImuFileError(path, lineno, f"bad number {tok[j].strip()!r} in field {j + 1} ({name})") \
                    from None
            if not math.isfinite(v):
                raise ImuFileError(path, lineno, f"non-finite value {tok[j].strip()!r} in field {j + 1} "
                                   f"({name})")
            vals.append(v)
        return vals, (tok[self.tcol] if self.tcol is not None else None)

    def feed(self, parts, first_line: int, *, drop=(), ends: bool = False, pos: int = 0):
        """Parse ``parts``: the lines as a list of bytes without their newline,
        or as one bytes-like text (its lines; a last ``\\n`` ends the last line
        and starts none); the first is file line ``first_line``; the line
        indices in ``drop`` are skipped.

        Returns
        -------
        values : (n, 6 or 7) ndarray
            The time (when a column has it) and ax ay az gx gy gz as written.
        lines : (n,) int64
            Their 1-based file lines.
        t_tok : TimeFields or None
            The time fields (None: no time column).
        ends : list of int or None
            With ``ends``: the byte after each row's newline (``pos`` bytes before ``parts``).
        """
        if isinstance(parts, (list, tuple)):
            buf = b"\n".join(parts) + b"\n" if parts else b""
        else:
            buf = parts if isinstance(parts, (bytes, bytearray)) else bytes(parts)
        size = len(buf)
        closed = size > 0 and buf[size - 1:] == b"\n"  # the last line has its newline
        n = buf.count(b"\n") + (0 if closed or not size else 1)
        drop = sorted({i for i in drop if 0 <= i < n})
        nl = None  # the byte after each line (its newline, or the end)
        if drop or ends:
            nl = np.flatnonzero(np.frombuffer(buf, np.uint8) == 10)
            if not closed and size:
                nl = np.append(nl, size)
        segs = []  # (values, line indices, TimeFields or None), in file order
        rows, idx, toks = [], [], []  # rows read here, not yet in segs

        def flush():
            if rows:
                t = TimeFields.from_tokens(toks, [r[0] for r in rows]) if self.tcol is not None else None
                segs.append((np.asarray(rows, dtype=float), np.asarray(idx, dtype=np.int64), t))
                rows.clear(), idx.clear(), toks.clear()

        off, i, nd = 0, 0, 0  # the byte of line i
        while i < n:
            while nd < len(drop) and drop[nd] < i:
                nd += 1
            if self._parse_csv is not None and not self.header_allowed and self.cols is not None \
                    and not (nd < len(drop) and drop[nd] == i):
                if self.want is None:
                    self._layout()
                stop = drop[nd] if nd < len(drop) else n  # the compiled run ends before a dropped line
                view = buf if stop == n else memoryview(buf)[:int(nl[stop - 1]) + 1]
                flush()
                vals, li, split, taken, stop_pos = self._parse_csv(view, off, self.fmt.delimiter, self.ncol, self.want,
                                                                   0 if self.tcol is not None else -1)
                if len(vals):
                    t = TimeFields(vals[:, 0], *split) if split is not None else None
                    segs.append((vals, li + i, t))
                if stop_pos is None:
                    i, off = stop, len(view)
                    continue
                i, off = i + taken, stop_pos
            e = buf.find(b"\n", off)
            e = size if e < 0 else e
            if not (nd < len(drop) and drop[nd] == i):
                got = self._line(bytes(buf[off:e]), first_line + i)  # raises the error, or reads what the
                if got is not None:                                  # compiled reader did not
                    rows.append(got[0])
                    idx.append(i)
                    toks.append(got[1])
            off = e + 1
            i += 1
        flush()
        width = 6 if (self.want is not None and self.tcol is None) else 7
        timed = self.want is None or self.tcol is not None
        if segs:
            a = segs[0][0] if len(segs) == 1 else np.concatenate([s[0] for s in segs])
            li = segs[0][1] if len(segs) == 1 else np.concatenate([s[1] for s in segs])
            t_tok = TimeFields.concat([s[2] for s in segs]) if self.tcol is not None else None
        else:
            a, li = np.zeros((0, width)), np.zeros(0, np.int64)
            t_tok = TimeFields.from_tokens([]) if timed else None
        end_pos = (pos + nl[li] + 1).tolist() if ends else None
        return a, li + first_line, t_tok, end_pos


class SampleConverter:
    """The time base, units and axes of :class:`ImuCsvFormat` applied to parsed
    values (:class:`CsvLineParser`), the whole file at once or block by block:
    the time reference (the first time field's whole second, so that sample
    intervals keep full precision) is fixed by the first call of :meth:`times`."""

    def __init__(self, path: str, fmt: ImuCsvFormat, week: int | None):
        self.path, self.fmt, self.week = path, fmt, week
        self.t_ref = None  # GPS (or relative) time the sample times count from [s]
        self._ref = None  # (whole time units subtracted from the fields, remainder, whole seconds)
        self.time_base = "relative" if fmt.time == "relative" else "gps"
        self.k_acc = G0 if fmt.acc_unit == "g" else 1.0
        self.k_gyr = DEG if fmt.gyro_unit == "dps" else 1.0
        self.C = fmt.C_b_imu()

    def times(self, t_tok, t_counter) -> np.ndarray:
        """Sample times after :attr:`t_ref` [s] (before ``time_offset_s``): from the time fields
        ``t_tok``, or with no time column from the sample counter ``t_counter`` and ``rate_hz``."""
        fmt = self.fmt
        if t_tok is None:
            ref_s, t = 0, t_counter / float(fmt.rate_hz)
        else:
            scale = _TIME_SCALE[fmt.time_unit]
            if not isinstance(t_tok, TimeFields):
                t_tok = TimeFields.from_tokens(list(t_tok))
            if self._ref is None:
                ref_int = int(math.floor(float(t_tok.value[0])))
                self._ref = (ref_int,) + divmod(ref_int, scale)
            ref_int, ref_s, rem = self._ref
            t = (t_tok.after(ref_int) + rem) / scale  # as _split_time
        if self.t_ref is None:
            self.t_ref = time_base_ref_s(fmt.time, ref_s, float(t[0]), self.week)
        return t

    def rate_mismatch(self, t) -> str | None:
        """The message when the median interval of ``t`` contradicts ``rate_hz`` (None: it agrees)."""
        fmt = self.fmt
        if fmt.rate_hz is None or len(t) <= 2 or self._ref is None:
            return None
        med = float(np.median(np.diff(t)))
        if abs(med * fmt.rate_hz - 1.0) > 0.1:
            return (f"median sample interval {med:.6g} s ({1 / med:.6g} Hz) with time_unit = {fmt.time_unit!r}, "
                    f"but rate_hz = {fmt.rate_hz:g}: wrong time_unit or rate_hz")
        return None

    def body(self, a) -> tuple[np.ndarray, np.ndarray]:
        """(specific force or velocity increments, angular rates or angle increments) in the body
        frame, SI, from the values' last six columns (ax ay az gx gy gz as written)."""
        acc_b = (a[:, -6:-3] * self.k_acc) @ self.C.T
        gyro_b = (a[:, -3:] * self.k_gyr) @ self.C.T
        return acc_b, gyro_b
