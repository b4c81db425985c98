"""GNSS position fixes from a user's files: a CSV with mapped columns and
units, an RTKLIB ``.pos`` solution, or NMEA 0183 GGA + RMC (+ GST) sentences
(:func:`read_gnss`, chosen by ``format`` or the file suffix), and writers for
``.pos`` and NMEA (round trips, exporting a simulation).

Every reader returns :class:`GnssRecords`: antenna position (ellipsoidal
height), NED velocity (NaN where the file has none), 1-sigma, and the file
line of each record; times are GPS seconds after ``t_ref_s`` (GPS time since
1980-01-06, or the user's own clock with ``time = "relative"``).

Formats
-------
* **CSV** (:class:`GnssFileFormat`): ``columns`` names the fields in file
  order (roles ``t lat lon h vn ve vd vu sigma_n sigma_e sigma_d sigma_u
  sigma_h sigma_vn sigma_ve sigma_vd sigma_v q _``) or is a table
  ``{role: header name}``.  Time options as the IMU CSV's
  (:mod:`insnav.io.imu_csv`); ``angle_unit`` deg | rad; ``height``
  ellipsoidal | msl (``h = H + geoid_undulation_m``); sigma columns or fixed
  ``sigma_pos_m`` / ``sigma_vel_mps``.
* **RTKLIB .pos** (``rtkpost``/``rnx2rtkp``/``rtknavi`` output, RTKLIB
  manual app. B.5): the ``%`` header's column names locate
  ``latitude(deg) longitude(deg) height(m)`` (or ``x-ecef(m) ...``), ``Q``,
  ``sdn sde sdu`` (sigmas), ``vn ve vu`` and ``sdvn sdve sdvu`` when present.
  Time ``yyyy/mm/dd hh:mm:ss.sss`` or ``week tow``, GPST (a ``UTC`` header:
  leap seconds added).  ``quality_max`` keeps the records with ``Q <=`` it
  (1 fix, 2 float, 4 DGPS, 5 single).
* **NMEA 0183** (NMEA 0183 v4.10 sec. 6.3): ``$--GGA`` (UTC time of day,
  position, fix quality, MSL altitude and geoid separation), ``$--RMC``
  (date, speed over ground [knots], course [deg true]: horizontal velocity,
  the vertical NaN) and ``$--GST`` (1-sigma of latitude, longitude and
  altitude [m]) of any talker.  Every sentence's checksum is verified; a bad
  or missing one, or a malformed field, is a :class:`GnssFileError` naming
  the file and the line.  Quality 0 (no fix) records are dropped.  UTC ->
  GPS time with the leap seconds of :func:`insnav.io.imu_csv.gps_minus_utc_s`.

Velocity lag (every format): ``velocity_lag_s`` = tau > 0 says the velocity
column of the record tagged t describes the antenna at t - tau (a receiver's
navigation filter smooths and delays its velocity); the reader takes the
velocity of the record tagged t from the column at t + tau
(:func:`shift_velocity`).  :func:`estimate_velocity_lag` measures tau from
the file's own positions.
"""
from __future__ import annotations

from ..errors import close_matches

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import earth
from ..config import ConfigError
from ..data.textio import read_bytes
from ..gnss.gpstime import SECONDS_PER_WEEK, gps_seconds_from_calendar
from ..units import DEG, RAD2DEG
from .imu_csv import _CHOICES as _IMU_CHOICES, _TIME_SCALE, _split_time, canonical_choice, time_base_ref_s
from .imu_csv import gps_minus_utc_s

__all__ = ["GnssFileError", "GnssFileFormat", "GnssRecords", "read_gnss", "read_gnss_csv", "read_pos",
           "read_pos_records", "shift_velocity", "estimate_velocity_lag", "velocity_lag_warning", "MAX_VELOCITY_LAG_S", "read_rtklib_pos", "read_nmea", "write_pos", "write_nmea", "nmea_checksum", "KNOT_MPS"]

#: the largest absolute velocity_lag_s accepted [s] (a receiver's velocity filter lags by tenths of a second; a
#: larger value is a time-tag or unit mistake, not a lag)
MAX_VELOCITY_LAG_S = 2.0

#: knot -> m/s (1852 m per hour)
KNOT_MPS = 1852.0 / 3600.0

_ROLES = ("t", "lat", "lon", "h", "vn", "ve", "vd", "vu", "sigma_n", "sigma_e", "sigma_d", "sigma_u", "sigma_h",
          "sigma_vn", "sigma_ve", "sigma_vd", "sigma_v", "q", "_")
_FORMATS = ("auto", "csv", "pos", "nmea")
_SUFFIX_FORMAT = {".csv": "csv", ".txt": "csv", ".pos": "pos", ".nmea": "nmea", ".nma": "nmea", ".gga": "nmea",
                  ".log": "nmea"}


class GnssFileError(ValueError):
    """A malformed GNSS file; the message names the file, the 1-based line and what was wrong."""

    def __init__(self, path, line, what):
        self.path = os.fspath(path)
        self.line = line
        self.what = what
        where = f"{self.path}, line {line}" if line is not None else self.path
        super().__init__(f"{where}: {what}")


def _three(v, key, source, prefix):
    if v is None:
        return None
    try:
        a = np.broadcast_to(np.asarray(v, dtype=float), (3,)).copy()
    except (TypeError, ValueError):
        a = np.full(3, np.nan)
    if isinstance(v, (bool, str)) or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ConfigError(f"{source}: {prefix}{key}: bad value {v!r}; allowed: a number > 0 or 3 (N, E, D)")
    return a


@dataclass
class GnssFileFormat:
    """How to read a GNSS file (the ``[gnss]`` table; see the module docstring).
    Units are in the attribute names.

    Attributes
    ----------
    format : {'auto', 'csv', 'pos', 'nmea'}
        ``auto``: by suffix (``.pos``; ``.nmea``/``.nma``/``.gga``/``.log``; else CSV).
    columns : list or dict (CSV)
    delimiter : str (CSV)
    time, time_unit, time_offset_s, gps_week : the time column (CSV; ``time_offset_s`` for every format)
    angle_unit : {'deg', 'rad'} or None
        CSV latitude/longitude; None: degrees, and fixes that all look like
        radians are an error (:func:`insnav.data.checks.check_latlon_radians`).
    height : {'ellipsoidal', 'msl'}
    geoid_undulation_m : float or None
        Geoid height N [m]: ``h = H_msl + N`` (CSV with ``height = "msl"``;
        NMEA: overrides the GGA geoid separation).
    sigma_pos_m, sigma_vel_mps : number, 3 numbers (N, E, D) or None
        Fixed 1-sigma; they override the file's sigmas.
    min_sigma_pos_m : float
        Floor of every position sigma [m] (RTK sigmas of 1 cm are optimistic).
    quality_max : int or None
        ``.pos``: keep records with ``Q <= quality_max``.
    velocity : bool
        Read the file's velocities (False: position only).
    date : str or None
        NMEA without RMC: the UTC date of the first sentence, ``"YYYY-MM-DD"``.
    decimate : int
        Keep every k-th fix (after the quality filter): e.g. 4 turns 4 Hz into
        1 Hz, leaving the others to evaluate the INS between fixes.
    velocity_lag_s : float
        Lag tau [s] of the velocity column behind the positions: the velocity
        of the record tagged t describes the antenna at t - tau (positive:
        late).  The reader re-times the column onto the position tags
        (:func:`shift_velocity`, on every record, before ``decimate``);
        ``|tau| <= MAX_VELOCITY_LAG_S``.  0: as tagged.
    """

    format: str = "auto"
    columns: object = ("t", "lat", "lon", "h", "sigma_n", "sigma_e", "sigma_d")
    delimiter: str = ","
    time: str = "gps_s"
    time_unit: str = "s"
    time_offset_s: float = 0.0
    gps_week: int | None = None
    angle_unit: str | None = None
    height: str = "ellipsoidal"
    geoid_undulation_m: float | None = None
    sigma_pos_m: object = None
    sigma_vel_mps: object = None
    min_sigma_pos_m: float = 0.0
    quality_max: int | None = None
    velocity: bool = True
    date: str | None = None
    decimate: int = 1
    velocity_lag_s: float = 0.0

    def validate(self, source: str = "gnss format", prefix: str = "gnss.") -> "GnssFileFormat":
        """Check every option (ConfigError naming ``prefix`` + key); returns self."""
        def bad(key, allowed):
            raise ConfigError(f"{source}: {prefix}{key}: bad value {getattr(self, key)!r}; allowed: {allowed}")

        if self.format not in _FORMATS:
            bad("format", ", ".join(_FORMATS))
        cols = self.columns
        if isinstance(cols, dict):
            for role, name in cols.items():
                if role not in _ROLES or role == "_":
                    raise ConfigError(f"{source}: {prefix}columns: unknown role {role!r}; allowed: "
                                      f"{', '.join(r for r in _ROLES if r != '_')}")
                if not isinstance(name, str):
                    raise ConfigError(f"{source}: {prefix}columns.{role}: bad value {name!r}; allowed: a header name")
            roles = tuple(cols)
        elif isinstance(cols, (list, tuple)) and all(isinstance(c, str) for c in cols):
            roles = tuple(cols)
            for c in roles:
                if c not in _ROLES:
                    close = close_matches(c, _ROLES)
                    raise ConfigError(f"{source}: {prefix}columns: unknown column {c!r}"
                                      + (f" (did you mean {close[0]!r}?)" if close else "")
                                      + f"; allowed: {', '.join(_ROLES)}")
            self.columns = roles
        else:
            bad("columns", "a list of roles in file order, or a table role = header name")
        for r in set(roles) - {"_"}:
            if roles.count(r) > 1:
                raise ConfigError(f"{source}: {prefix}columns {list(roles)} names {r!r} twice")
        if self.format in ("auto", "csv"):
            missing = [r for r in ("t", "lat", "lon", "h") if r not in roles]
            if missing and (self.format == "csv" or cols != GnssFileFormat.columns):
                raise ConfigError(f"{source}: {prefix}columns {list(roles)} lacks {', '.join(missing)}")
        self.time = canonical_choice(self.time, _IMU_CHOICES["time"], prefix + "time", source)
        self.time_unit = canonical_choice(self.time_unit, _IMU_CHOICES["time_unit"], prefix + "time_unit", source)
        if self.angle_unit is not None:
            self.angle_unit = canonical_choice(self.angle_unit, {"deg": ("degrees",), "rad": ("radians",)},
                                               prefix + "angle_unit", source)
        self.height = canonical_choice(self.height, {"ellipsoidal": ("ellipsoid",), "msl": ("geoid", "orthometric")},
                                       prefix + "height", source)
        if not (isinstance(self.delimiter, str) and len(self.delimiter) == 1):
            bad("delimiter", "one character")
        for key in ("time_offset_s", "geoid_undulation_m", "min_sigma_pos_m"):
            v = getattr(self, key)
            if v is None and key == "geoid_undulation_m":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                bad(key, "a finite number")
        if self.min_sigma_pos_m < 0:
            bad("min_sigma_pos_m", ">= 0 [m]")
        v = self.velocity_lag_s
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not abs(v) <= MAX_VELOCITY_LAG_S:
            bad("velocity_lag_s", f"a number of seconds within +-{MAX_VELOCITY_LAG_S:g} (the lag of the velocity "
                "column behind the positions; positive: the velocity describes the antenna that much earlier)")
        self.sigma_pos_m = _three(self.sigma_pos_m, "sigma_pos_m", source, prefix)
        self.sigma_vel_mps = _three(self.sigma_vel_mps, "sigma_vel_mps", source, prefix)
        v = self.decimate
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            bad("decimate", "an integer >= 1")
        for key in ("quality_max", "gps_week"):
            v = getattr(self, key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
                bad(key, "an integer >= 0")
        if not isinstance(self.velocity, bool):
            bad("velocity", "true or false")
        if self.date is not None:
            try:
                y, m, d = (int(x) for x in str(self.date).split("-"))
                gps_seconds_from_calendar(y, m, d)
            except ValueError:
                bad("date", '"YYYY-MM-DD"')
        return self

    def resolved_format(self, path) -> str:
        if self.format != "auto":
            return self.format
        return _SUFFIX_FORMAT.get(Path(os.fspath(path)).suffix.lower(), "csv")


@dataclass
class GnssRecords:
    """GNSS fixes as read (SI, antenna), before the dataset's time axis.

    Attributes
    ----------
    t_ref_s : float
        Whole seconds that ``t_s`` counts from: GPS time [s since
        1980-01-06], or the user's clock (``time_base == "relative"``).
    t_s : (N,) [s]
    lat_deg, lon_deg, h_m : (N,) antenna position (ellipsoidal height) [deg, deg, m]
    v_n : (N, 3) NED velocity [m/s] (NaN: none)
    sigma_pos_n : (N, 3) 1-sigma N, E, D [m]
    sigma_vel_n : (N, 3) [m/s] (NaN: none)
    quality : (N,) int (RTKLIB Q or NMEA fix quality; 0 when the file has none)
    lines : (N,) 1-based file line of each record
    path : str
    format : str
    time_base : {'gps', 'relative'}
    info : dict
    """

    t_ref_s: float
    t_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    v_n: np.ndarray
    sigma_pos_n: np.ndarray
    sigma_vel_n: np.ndarray
    quality: np.ndarray
    lines: np.ndarray
    path: str
    format: str
    time_base: str = "gps"
    info: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.t_s)

    def take(self, m) -> "GnssRecords":
        return GnssRecords(self.t_ref_s, self.t_s[m], self.lat_deg[m], self.lon_deg[m], self.h_m[m], self.v_n[m],
                           self.sigma_pos_n[m], self.sigma_vel_n[m], self.quality[m], self.lines[m], self.path,
                           self.format, self.time_base, dict(self.info))


def _finish(rec: GnssRecords, fmt: GnssFileFormat) -> GnssRecords:
    """Fixed sigmas, the sigma floor, the velocity switch and the time offset (every format)."""
    if fmt.sigma_pos_m is not None:
        rec.sigma_pos_n = np.tile(fmt.sigma_pos_m, (len(rec), 1))
    if fmt.sigma_vel_mps is not None:
        rec.sigma_vel_n = np.where(np.isfinite(rec.v_n), np.tile(fmt.sigma_vel_mps, (len(rec), 1)), np.nan)
    if fmt.min_sigma_pos_m > 0:
        rec.sigma_pos_n = np.maximum(rec.sigma_pos_n, fmt.min_sigma_pos_m)
    if not fmt.velocity:
        rec.v_n = np.full((len(rec), 3), np.nan)
        rec.sigma_vel_n = np.full((len(rec), 3), np.nan)
    rec.t_s = rec.t_s + float(fmt.time_offset_s)
    if len(rec) >= 3 and np.any(np.isfinite(rec.v_n)):
        _check_increasing(rec)
        if fmt.velocity_lag_s != 0.0:
            rec.v_n, rec.sigma_vel_n = shift_velocity(rec.t_s, rec.v_n, rec.sigma_vel_n, float(fmt.velocity_lag_s))
            rec.info["velocity_lag_s"] = float(fmt.velocity_lag_s)
        # what lag the (re-timed) velocities still show against the positions (insnav run warns)
        rec.info["velocity_lag_check"] = estimate_velocity_lag(rec.t_s, rec.lat_deg, rec.lon_deg, rec.h_m, rec.v_n)
    if fmt.decimate > 1:
        rec = rec.take(np.arange(0, len(rec), fmt.decimate))
    if len(rec) == 0:
        raise GnssFileError(rec.path, None, "no usable GNSS fix" + (f" with Q <= {fmt.quality_max}"
                                                                     if fmt.quality_max is not None else ""))
    nosig = np.flatnonzero(~np.all(np.isfinite(rec.sigma_pos_n), axis=1))
    if nosig.size:
        raise GnssFileError(rec.path, int(rec.lines[nosig[0]]), "no position sigma for this fix: give sigma "
                            "columns (or GST sentences), or a fixed [gnss] sigma_pos_m")
    _check_increasing(rec)
    return rec


def _check_increasing(rec: GnssRecords) -> None:
    d = np.diff(rec.t_s)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        raise GnssFileError(rec.path, int(rec.lines[k]), f"time does not increase (line {int(rec.lines[k - 1])})")


def shift_velocity(t_s, v_n, sigma_vel_n, lag_s: float, max_gap_factor: float = 1.5):
    """Re-time a velocity column that lags its positions.

    The velocity of record k (tagged ``t_s[k]``) is taken from the column at
    ``t_s[k] + lag_s`` by linear interpolation between the two records that
    bracket that time, each component separately; its sigma is the larger of
    the two records' sigmas.  Where that time lies outside the file, or the
    bracketing records are more than ``max_gap_factor`` median intervals apart
    (a gap), or one of them has no velocity, the record's velocity (and its
    sigma) become NaN: the record keeps its position.

    Parameters
    ----------
    t_s : (N,) record times [s], strictly increasing
    v_n : (N, 3) velocity column, NED [m/s] (NaN: none)
    sigma_vel_n : (N, 3) its 1-sigma [m/s]
    lag_s : float
        Lag tau [s] of the column behind the positions: the value tagged t
        describes the antenna at t - tau (``[gnss] velocity_lag_s``).
    max_gap_factor : float
        Largest bracket, in median record intervals, interpolated across.

    Returns
    -------
    v_n, sigma_vel_n : (N, 3) the re-timed velocity and its sigma [m/s]

    Notes
    -----
    Linear interpolation of a smooth velocity between records dt apart errs by
    at most ``dt^2 abs(v'') / 8`` (0.8 mm/s for 4 Hz records and 0.1 m/s^3 of jerk).
    """
    t = np.asarray(t_s, float)
    v = np.asarray(v_n, float)
    sv = np.asarray(sigma_vel_n, float)
    n = len(t)
    out_v = np.full_like(v, np.nan)
    out_s = np.full_like(sv, np.nan)
    if n < 2:
        return out_v, out_s
    tq = t + float(lag_s)
    j = np.searchsorted(t, tq, side="right") - 1  # t[j] <= tq < t[j + 1]
    exact = (j >= 0) & (t[np.clip(j, 0, n - 1)] == tq)
    j = np.clip(j, 0, n - 2)
    t0, t1 = t[j], t[j + 1]
    inside = (tq >= t[0]) & (tq <= t[-1])
    gap = (t1 - t0) > max_gap_factor * float(np.median(np.diff(t)))
    ok = inside & (~gap | exact)
    w = np.where(ok, (tq - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)[:, None]
    vi = (1.0 - w) * v[j] + w * v[j + 1]
    si = np.maximum(sv[j], sv[j + 1])
    for end, at in ((0, w[:, 0] == 0.0), (1, w[:, 0] == 1.0)):  # on a record: that record alone (its
        vi[at] = v[j[at] + end]                                    # neighbour may have no velocity)
        si[at] = sv[j[at] + end]
    out_v[ok] = vi[ok]
    out_s[ok] = si[ok]
    return out_v, out_s


def estimate_velocity_lag(t_s, lat_deg, lon_deg, h_m, v_n, *, max_lag_s: float = 0.5, step_s: float = 0.002,
                          min_speed_mps: float = 0.3, min_points: int = 20, max_points: int = 20000) -> dict | None:
    """Measure the lag of a velocity column behind its own positions.

    The horizontal velocity from central differences of the positions over
    two record intervals, ``(r[k+1] - r[k-1]) / (t[k+1] - t[k-1])`` (centred
    on ``t[k]``: no lag of its own; its error from the curvature of the path
    is ``dt^2 a' / 6``), is compared with the velocity column read at
    ``t[k] + tau`` (:func:`shift_velocity` interpolation) over a grid of tau in
    ``[-max_lag_s, max_lag_s]`` (10 ``step_s`` apart, then ``step_s`` apart
    around the best); the tau of the least rms difference (refined by a
    parabola through its grid neighbours) is the lag, the value to give
    ``[gnss] velocity_lag_s``.  Only records on a regular spacing (both
    intervals within 1 % of the median) moving faster than ``min_speed_mps``
    take part (at most ``max_points`` of them, evenly spread).

    Parameters
    ----------
    t_s : (N,) [s], increasing;  lat_deg, lon_deg : (N,) [deg];  h_m : (N,) [m]
    v_n : (N, 3) NED velocity column [m/s] (NaN: none)

    Returns
    -------
    dict or None
        ``lag_s`` [s], ``rms_at_lag_mps`` and ``rms_as_tagged_mps`` (rms
        horizontal difference [m/s] at tau = lag and at tau = 0),
        ``points``; None when fewer than ``min_points`` records qualify.
    """
    t = np.asarray(t_s, float)
    v = np.asarray(v_n, float)
    if len(t) < min_points + 2 or not np.any(np.isfinite(v[:, :2])):
        return None
    lat = np.radians(np.asarray(lat_deg, float))
    lon = np.radians(np.asarray(lon_deg, float))
    h = np.asarray(h_m, float)
    R_M, R_N = earth.radii(lat)
    north = (lat - lat[0]) * (R_M + h)
    east = (lon - lon[0]) * (R_N + h) * np.cos(lat)
    dt = np.diff(t)
    med = float(np.median(dt))
    reg = np.abs(dt - med) <= 0.01 * med
    ok = reg[1:] & reg[:-1]
    dt2 = t[2:] - t[:-2]
    v_d = np.column_stack([(north[2:] - north[:-2]) / dt2, (east[2:] - east[:-2]) / dt2])
    ok &= np.hypot(v_d[:, 0], v_d[:, 1]) > min_speed_mps
    ok &= np.all(np.isfinite(v[1:-1, :2]), axis=1)
    idx = np.flatnonzero(ok) + 1  # record index of each central difference
    v_d = v_d[ok]
    # only the records whose column reads are inside the file for every tau of the grid
    keep = (t[idx] - max_lag_s >= t[0]) & (t[idx] + max_lag_s <= t[-1])
    idx, v_d = idx[keep], v_d[keep]
    if len(idx) < min_points:
        return None
    if len(idx) > max_points:
        sub = np.linspace(0, len(idx) - 1, max_points).astype(int)
        idx, v_d = idx[sub], v_d[sub]

    def rms(tau):
        vi = np.column_stack([np.interp(t[idx] + tau, t, v[:, j]) for j in range(2)])
        d = np.sum((vi - v_d) ** 2, axis=1)
        d = d[np.isfinite(d)]
        return float(np.sqrt(np.mean(d))) if d.size else np.inf

    coarse = np.arange(-max_lag_s, max_lag_s + 5.0 * step_s, 10.0 * step_s)
    best = float(coarse[int(np.argmin([rms(tau) for tau in coarse]))])
    taus = np.arange(best - 10.0 * step_s, best + 10.5 * step_s, step_s)
    r = np.array([rms(tau) for tau in taus])
    k = int(np.argmin(r))
    lag = float(taus[k])
    if 0 < k < len(taus) - 1 and np.all(np.isfinite(r[k - 1:k + 2])):
        den = r[k - 1] - 2.0 * r[k] + r[k + 1]
        if den > 0:
            lag += 0.5 * step_s * (r[k - 1] - r[k + 1]) / den
    return dict(lag_s=float(lag), rms_at_lag_mps=rms(lag), rms_as_tagged_mps=rms(0.0), points=int(len(idx)))


def velocity_lag_warning(rec: GnssRecords, *, min_lag_s: float = 0.05, min_ratio: float = 1.5) -> str | None:
    """A one-line warning when the records' velocities (after ``[gnss] velocity_lag_s``) visibly lag
    their positions: a measured lag (:func:`estimate_velocity_lag`) of at least ``min_lag_s`` that
    shrinks the rms velocity-position difference ``min_ratio`` times or more; else None."""
    chk = rec.info.get("velocity_lag_check")
    if not chk or abs(chk["lag_s"]) < min_lag_s or not chk["rms_as_tagged_mps"] >= min_ratio * chk["rms_at_lag_mps"]:
        return None
    total = rec.info.get("velocity_lag_s", 0.0) + chk["lag_s"]
    return (f"{rec.path}: the velocity column lags its own positions by {1e3 * chk['lag_s']:.0f} ms (rms "
            f"horizontal velocity - position differences {chk['rms_as_tagged_mps']:.3f} m/s as read, "
            f"{chk['rms_at_lag_mps']:.3f} m/s re-timed, {chk['points']} fixes); set [gnss] velocity_lag_s = "
            f"{total:.3f}")


def read_gnss(path, fmt: GnssFileFormat | None = None) -> GnssRecords:
    """Read GNSS fixes in the format ``fmt.format`` (or chosen by suffix)."""
    fmt = (fmt or GnssFileFormat()).validate()
    kind = fmt.resolved_format(path)
    reader = {"csv": read_gnss_csv, "pos": read_pos, "nmea": read_nmea}[kind]
    return reader(path, fmt)


def _text_lines(path):
    path = os.fspath(path)
    try:
        raw = read_bytes(path)
    except OSError as exc:
        raise GnssFileError(path, None, f"cannot read the GNSS file ({exc.strerror})") from None
    try:
        return raw.decode("ascii").splitlines()
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise GnssFileError(path, line, "not ASCII text (a binary log?)") from None


# --------------------------------------------------------------------------- CSV


def read_gnss_csv(path, fmt: GnssFileFormat | None = None) -> GnssRecords:
    """A CSV of fixes with the columns and units of ``fmt`` (module docstring)."""
    fmt = (fmt or GnssFileFormat(format="csv")).validate()
    path = os.fspath(path)
    lines_txt = _text_lines(path)
    cols = None if isinstance(fmt.columns, dict) else tuple(fmt.columns)
    rows, lines, t_tok = [], [], []
    first = True
    delim = fmt.delimiter
    for i, s in enumerate(lines_txt):
        s = s.strip()
        if not s or s.startswith("#"):
            continue
        tok = [x.strip() for x in s.split(delim)]
        if first:
            first = False
            try:
                float(tok[0])
                is_header = False
            except ValueError:
                is_header = True
            if isinstance(fmt.columns, dict):
                if not is_header:
                    raise GnssFileError(path, i + 1, "no header line, but the columns are mapped by header name")
                names = [x.strip('"') for x in tok]
                roles = ["_"] * len(names)
                for role, name in fmt.columns.items():
                    if name not in names:
                        close = close_matches(name, names)
                        raise GnssFileError(path, i + 1, f"header has no column {name!r} (for {role})"
                                            + (f"; did you mean {close[0]!r}?" if close else "")
                                            + f"; header: {delim.join(names)}")
                    roles[names.index(name)] = role
                cols = tuple(roles)
                missing = [r for r in ("t", "lat", "lon", "h") if r not in cols]
                if missing:
                    raise ConfigError(f"gnss.columns: no mapping for {', '.join(missing)}")
                continue
            if is_header:
                continue
        if len(tok) != len(cols):
            raise GnssFileError(path, i + 1, f"expected {len(cols)} {delim!r}-separated fields "
                                f"({', '.join(cols)}), found {len(tok)}")
        vals = []
        for j, role in enumerate(cols):
            if role == "_":
                vals.append(np.nan)
                continue
            try:
                v = float(tok[j]) if tok[j] != "" or role not in ("vn", "ve", "vd", "vu") else np.nan
            except ValueError:
                raise GnssFileError(path, i + 1, f"bad number {tok[j]!r} in field {j + 1} ({role})") from None
            if not math.isfinite(v) and role in ("t", "lat", "lon", "h"):
                raise GnssFileError(path, i + 1, f"non-finite value {tok[j]!r} in field {j + 1} ({role})")
            vals.append(v)
        rows.append(vals)
        t_tok.append(tok[cols.index("t")])
        lines.append(i + 1)
    if not rows:
        raise GnssFileError(path, None, "no GNSS fix")
    a = np.asarray(rows, float)
    col = {r: a[:, cols.index(r)] for r in cols if r != "_"}
    n = len(a)
    ref_s, t = _split_time(t_tok, _TIME_SCALE[fmt.time_unit])
    time_base = "gps"
    if fmt.time == "gps_sow" and fmt.gps_week is None:
        raise ConfigError(f"{path}: gnss.time = 'gps_sow' needs gnss.gps_week (the full GPS week)")
    t_ref = time_base_ref_s(fmt.time, ref_s, float(t[0]), fmt.gps_week)
    if fmt.time == "relative":
        time_base = "relative"
    lat, lon = col["lat"], col["lon"]
    if fmt.angle_unit == "rad":
        lat, lon = lat * RAD2DEG, lon * RAD2DEG
    h = col["h"]
    if fmt.height == "msl":
        if fmt.geoid_undulation_m is None:
            raise ConfigError(f"{path}: gnss.height = 'msl' needs gnss.geoid_undulation_m (the geoid height N "
                              "[m] at the site, h = H + N)")
        h = h + fmt.geoid_undulation_m
    nan3 = np.full((n, 3), np.nan)
    v = nan3.copy()
    for k, r in enumerate(("vn", "ve", "vd")):
        if r in col:
            v[:, k] = col[r]
    if "vu" in col:
        v[:, 2] = -col["vu"]
    if ("vn" in col) != ("ve" in col):
        raise ConfigError(f"{path}: gnss.columns: give both vn and ve (or neither)")
    if "vn" in col and "vd" not in col and "vu" not in col:
        raise ConfigError(f"{path}: gnss.columns: velocity needs vd or vu too (the loose filter uses 3-D velocity)")
    sp = nan3.copy()
    if "sigma_h" in col:
        sp[:, 0] = sp[:, 1] = col["sigma_h"]
    for k, r in enumerate(("sigma_n", "sigma_e", "sigma_d")):
        if r in col:
            sp[:, k] = col[r]
    if "sigma_u" in col:
        sp[:, 2] = col["sigma_u"]
    sv = nan3.copy()
    if "sigma_v" in col:
        sv[:] = col["sigma_v"][:, None]
    for k, r in enumerate(("sigma_vn", "sigma_ve", "sigma_vd")):
        if r in col:
            sv[:, k] = col[r]
    if np.any(np.isfinite(v)) and fmt.sigma_vel_mps is None and not np.any(np.isfinite(sv)) and fmt.velocity:
        raise ConfigError(f"{path}: velocity columns but no velocity sigma: add sigma_vn/sigma_ve/sigma_vd (or "
                          "sigma_v) columns or a fixed gnss.sigma_vel_mps")
    sv = np.where(np.isfinite(v), sv, np.nan)
    q = col["q"].astype(np.int64) if "q" in col else np.zeros(n, np.int64)
    rec = GnssRecords(t_ref, t, lat, lon, h, v, sp, sv, q, np.asarray(lines, np.int64), path, "csv", time_base)
    if fmt.quality_max is not None and "q" in col:
        rec = rec.take(q <= fmt.quality_max)
    return _finish(rec, fmt)


# --------------------------------------------------------------------------- RTKLIB .pos

_POS_DEFAULT_HEADER = ["GPST", "latitude(deg)", "longitude(deg)", "height(m)", "Q", "ns", "sdn(m)", "sde(m)",
                       "sdu(m)", "sdne(m)", "sdeu(m)", "sdun(m)", "age(s)", "ratio"]


def read_pos(path, fmt: GnssFileFormat | None = None) -> GnssRecords:
    """An RTKLIB solution file (module docstring); sigmas ``sdn sde sdu``."""
    fmt = (fmt or GnssFileFormat(format="pos")).validate()
    rec = read_pos_records(path, fmt)
    if fmt.quality_max is not None:
        rec = rec.take(rec.quality <= fmt.quality_max)
    return _finish(rec, fmt)


#: ``% (lat/lon/height=WGS84/ellipsoidal,...)``: the datum and height kind RTKLIB's outsolhead writes
_POS_HEIGHT = None


def read_pos_records(path, fmt: GnssFileFormat | None = None) -> GnssRecords:
    """The records of an RTKLIB ``.pos`` file as read (ellipsoidal heights,
    GPST), before :func:`read_pos`'s sigma, quality and time-offset steps; also
    the reader of :func:`read_rtklib_pos`.

    The header is honoured: the column names (every record must have as many
    fields as the header names, the time taking two), GPST or UTC time, and
    the ``lat/lon/height=DATUM/HEIGHT`` comment that RTKLIB writes (``outsolhead``):
    ``ellipsoidal`` heights are used as they are; ``geodetic`` heights (above
    mean sea level, RTKLIB option ``out-height=geodetic``) get
    ``fmt.geoid_undulation_m`` added (``h = H + N``) and are refused without
    it; a datum other than WGS84 is refused.

    Raises
    ------
    GnssFileError
        Naming the file and line.
    ConfigError
        MSL heights (header or ``fmt.height``) without ``geoid_undulation_m``.
    """
    import re

    global _POS_HEIGHT
    if _POS_HEIGHT is None:
        _POS_HEIGHT = re.compile(r"height=([A-Za-z0-9]+)/([A-Za-z]+)")
    fmt = (fmt or GnssFileFormat(format="pos")).validate()
    path = os.fspath(path)
    header = None
    datum = height_kind = None
    height_line = 0
    t_l, rows, lines = [], [], []
    utc = False
    nfields = None  # fields of a record: the header's names + 1 (date and time are two fields, GPST one name)
    for i, line in enumerate(_text_lines(path)):
        s = line.strip()
        if not s:
            continue
        if s.startswith("%"):
            tok = s[1:].split()
            m = _POS_HEIGHT.search(s)
            if m and height_kind is None:
                datum, height_kind, height_line = m[1], m[2].lower(), i + 1
                if datum.upper() != "WGS84":
                    raise GnssFileError(path, i + 1, f"the header says height={m[1]}/{m[2]}: datum {m[1]} is not "
                                        "supported (RTKLIB option out-datum=wgs84)")
                if height_kind not in ("ellipsoidal", "geodetic"):
                    raise GnssFileError(path, i + 1, f"the header says height={m[1]}/{m[2]}: expected ellipsoidal "
                                        "or geodetic")
            if tok and tok[0] in ("GPST", "UTC", "JST") and len(tok) > 3:
                header = tok
                nfields = len(tok) + 1
                utc = tok[0] == "UTC"
                if tok[0] == "JST":
                    raise GnssFileError(path, i + 1, "JST time is not supported (use GPST or UTC output)")
                if "latitude(d'\")" in tok or any("latitude(d'" in x for x in tok):
                    raise GnssFileError(path, i + 1, "latitude/longitude in deg-min-sec are not supported "
                                        "(RTKLIB option out-solformat=llh with out-degform=deg)")
            continue
        h = header or _POS_DEFAULT_HEADER
        p = s.split()
        if nfields is None:  # no header: every record like the first
            nfields = len(p)
        if len(p) != nfields:
            where = "header has" if header else "first record has"
            raise GnssFileError(path, i + 1, f"{len(p)} fields where the {where} {nfields} (expected "
                                f"{' '.join(h[:5])} ...): a missing or extra field")
        try:
            if "/" in p[0]:
                y, mo, d = (int(x) for x in p[0].split("/"))
                hh, mi, ss = p[1].split(":")
                t_l.append((gps_seconds_from_calendar(y, mo, d, int(hh), int(mi), 0.0), float(ss)))
            else:
                t_l.append((float(int(p[0])) * SECONDS_PER_WEEK, float(p[1])))
            vals = {name: float(p[j + 1]) for j, name in enumerate(h[1:], start=1) if j + 1 < len(p)}
        except (ValueError, IndexError):
            raise GnssFileError(path, i + 1, f"bad RTKLIB solution line (expected {' '.join(h[:5])} ...)") from None
        rows.append(vals)
        lines.append(i + 1)
    if not rows:
        raise GnssFileError(path, None, "no solution records")
    h = header or _POS_DEFAULT_HEADER
    n = len(rows)

    def col(name, default=np.nan):
        return np.array([r.get(name, default) for r in rows], float)

    if "latitude(deg)" in h:
        lat, lon, hgt = col("latitude(deg)"), col("longitude(deg)"), col("height(m)")
        sp = np.column_stack([col("sdn(m)"), col("sde(m)"), col("sdu(m)")])
    elif "x-ecef(m)" in h:
        r_e = np.column_stack([col("x-ecef(m)"), col("y-ecef(m)"), col("z-ecef(m)")])
        la, lo, hgt = earth.ecef_to_geodetic(r_e)
        lat, lon = la * RAD2DEG, lo * RAD2DEG
        sx = np.column_stack([col("sdx(m)"), col("sdy(m)"), col("sdz(m)")])
        sp = np.empty((n, 3))
        for k in range(n):  # diagonal ECEF variances -> NED
            C = earth.C_en(la[k], lo[k]).T
            sp[k] = np.sqrt(np.diag(C @ np.diag(sx[k] ** 2) @ C.T))
        height_kind = "ellipsoidal"  # ECEF: no height kind
    else:
        raise GnssFileError(path, None, f"no latitude(deg) or x-ecef(m) column in the header ({' '.join(h)})")
    bad = np.flatnonzero(~(np.isfinite(lat) & np.isfinite(lon) & np.isfinite(hgt)))
    if bad.size:
        raise GnssFileError(path, lines[bad[0]], "missing position fields")
    bad = np.flatnonzero((np.abs(lat) > 90.0) | (np.abs(lon) > 360.0))
    if bad.size:
        k = int(bad[0])
        raise GnssFileError(path, lines[k], f"latitude {lat[k]:g} / longitude {lon[k]:g} deg out of range "
                            "(a missing field?)")
    q = col("Q", 0).astype(np.int64)
    v = np.full((n, 3), np.nan)
    sv = np.full((n, 3), np.nan)
    if "vn(m/s)" in h:
        v = np.column_stack([col("vn(m/s)"), col("ve(m/s)"), -col("vu(m/s)")])
        sv = np.column_stack([col("sdvn"), col("sdve"), col("sdvu")])
    t_int = np.array([a for a, _ in t_l])
    t_frac = np.array([b for _, b in t_l])
    ref = float(t_int[0])
    t = (t_int - ref) + t_frac
    if utc:
        ref += float(gps_minus_utc_s(ref + t[0]))
    if height_kind == "geodetic":
        if fmt.geoid_undulation_m is None:
            raise ConfigError(f"{path}:{height_line}: the header says height=WGS84/geodetic (above mean sea level, "
                              "RTKLIB out-height=geodetic): give [gnss] geoid_undulation_m (the geoid height N "
                              "[m] there: h = H + N), or output ellipsoidal heights")
        hgt = hgt + fmt.geoid_undulation_m
    elif fmt.height == "msl":
        if height_kind == "ellipsoidal":
            raise ConfigError(f"{path}:{height_line}: gnss.height = 'msl', but the header says "
                              "height=WGS84/ellipsoidal: remove gnss.height (the file's heights are ellipsoidal)")
        if fmt.geoid_undulation_m is None:
            raise ConfigError(f"{path}: gnss.height = 'msl' needs gnss.geoid_undulation_m")
        hgt = hgt + fmt.geoid_undulation_m
    return GnssRecords(ref, t, lat, lon, hgt, v, sp, sv, q, np.asarray(lines, np.int64), path, "pos",
                       info=dict(time_system="UTC" if utc else "GPST",
                                 height="geodetic" if height_kind == "geodetic" else "ellipsoidal",
                                 q_counts={int(k): int((q == k).sum()) for k in np.unique(q)}))


def read_rtklib_pos(path, geoid_undulation_m: float | None = None):
    """Read an RTKLIB solution file (``GPST|UTC latitude(deg) longitude(deg)
    height(m) Q ...`` or ``x-ecef(m) ...``) as a reference.

    The reader is :func:`read_pos_records` (the fixes reader's): the header's
    columns, time system (UTC converted to GPST) and height kind are honoured;
    ``height=WGS84/geodetic`` (mean sea level) needs ``geoid_undulation_m``
    (the geoid height N [m]: ``h = H + N``).  Velocity columns ``vn ve vu``
    (m/s), when present, are converted to ECEF.

    Returns
    -------
    insnav.gnss.measurements.RtklibPos
        ``t_gps_s``, ``r_e``, ``v_e``, ``q`` and ``lines`` (the file line of each record).

    Raises
    ------
    GnssFileError
        (a ValueError) On a line that cannot be parsed (file path and line number).
    insnav.config.ConfigError
        MSL heights without ``geoid_undulation_m``.
    """
    from ..gnss.measurements import RtklibPos

    rec = read_pos_records(path, GnssFileFormat(format="pos", geoid_undulation_m=geoid_undulation_m))
    lat, lon = np.deg2rad(rec.lat_deg), np.deg2rad(rec.lon_deg)
    r_e = earth.geodetic_to_ecef(lat, lon, rec.h_m)
    v_e = earth.ned_to_ecef_vector(lat, lon, rec.v_n)
    return RtklibPos(rec.t_ref_s + rec.t_s, r_e, v_e, np.asarray(rec.quality), np.asarray(rec.lines))


def write_pos(path, t_gps_s, lat_deg, lon_deg, h_m, sigma_pos_n=None, v_n=None, sigma_vel_n=None, q=None,
              ns: int = 10) -> Path:
    """Write fixes as an RTKLIB ``.pos`` file (GPST calendar time to 1 ms,
    lat/lon 9 decimals of a degree, height and sigmas 4 decimals of a metre,
    velocities 5 decimals, in the columns of ``rtkpost`` with velocity output)."""
    import datetime as _dt

    n = len(t_gps_s)
    sp = np.zeros((n, 3)) if sigma_pos_n is None else np.asarray(sigma_pos_n, float)
    q = np.ones(n, int) if q is None else np.asarray(q, int)
    hdr = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  "
           "sdne(m)  sdeu(m)  sdun(m) age(s)  ratio")
    if v_n is not None:
        hdr += "    vn(m/s)    ve(m/s)    vu(m/s)      sdvn     sdve     sdvu    sdvne    sdveu    sdvun"
    out = ["% program   : insnav", "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,"
           "6:ppp,ns=# of satellites)", hdr]
    for k in range(n):
        ms = int(round(float(t_gps_s[k]) * 1000.0))
        days, msd = divmod(ms, 86_400_000)
        d = _dt.date(1980, 1, 6) + _dt.timedelta(days=int(days))
        hh, rem = divmod(msd, 3_600_000)
        mi, rem = divmod(rem, 60_000)
        line = (f"{d.year:04d}/{d.month:02d}/{d.day:02d} {hh:02d}:{mi:02d}:{rem / 1000:06.3f} "
                f"{lat_deg[k]:14.9f} {lon_deg[k]:14.9f} {h_m[k]:10.4f} {q[k]:3d} {ns:3d} "
                f"{sp[k, 0]:8.4f} {sp[k, 1]:8.4f} {sp[k, 2]:8.4f} {0.0:8.4f} {0.0:8.4f} {0.0:8.4f} {0.0:6.2f} "
                f"{0.0:6.1f}")
        if v_n is not None:
            v = np.asarray(v_n[k], float)
            s = np.zeros(3) if sigma_vel_n is None else np.asarray(sigma_vel_n[k], float)
            line += (f" {v[0]:10.5f} {v[1]:10.5f} {-v[2]:10.5f} {s[0]:9.5f} {s[1]:9.5f} {s[2]:9.5f} "
                     f"{0.0:8.5f} {0.0:8.5f} {0.0:8.5f}")
        out.append(line)
    p = Path(path)
    p.write_text("\n".join(out) + "\n", encoding="ascii")
    return p


# --------------------------------------------------------------------------- NMEA 0183


def nmea_checksum(body: str) -> str:
    """The two-hex-digit XOR checksum of the characters between ``$`` and ``*``."""
    c = 0
    for ch in body.encode("ascii"):
        c ^= ch
    return f"{c:02X}"


def _nmea_angle(v: str, hemi: str, deg_digits: int, what: str):
    if not v:
        return np.nan
    if hemi not in ("N", "S", "E", "W"):
        raise ValueError(f"bad {what} hemisphere {hemi!r} (N/S, E/W)")
    d = int(v[:deg_digits])
    m = float(v[deg_digits:])
    if not 0.0 <= m < 60.0:
        raise ValueError(f"bad {what} minutes {v[deg_digits:]!r}")
    a = d + m / 60.0
    return -a if hemi in ("S", "W") else a


def _tod(v: str) -> float:
    if len(v) < 6:
        raise ValueError(f"bad UTC time {v!r} (hhmmss.ss)")
    hh, mm, ss = int(v[0:2]), int(v[2:4]), float(v[4:])
    if hh > 23 or mm > 59 or not 0 <= ss < 61:
        raise ValueError(f"bad UTC time {v!r} (hhmmss.ss)")
    return hh * 3600.0 + mm * 60.0 + ss


def read_nmea(path, fmt: GnssFileFormat | None = None) -> GnssRecords:
    """GGA + RMC (+ GST) sentences (module docstring)."""
    fmt = (fmt or GnssFileFormat(format="nmea")).validate()
    path = os.fspath(path)
    ep: dict = {}  # (day index, tod) -> record
    order = []
    day = None  # UTC calendar seconds since 1980 of 00:00 of the current date
    pending = []
    last_tod = None
    if fmt.date is not None:
        y, m, d = (int(x) for x in fmt.date.split("-"))
        day = gps_seconds_from_calendar(y, m, d)
    n_sent = dict(GGA=0, RMC=0, GST=0, other=0)
    for i, line in enumerate(_text_lines(path)):
        s = line.strip()
        if not s:
            continue
        ln = i + 1
        if not s.startswith("$"):
            raise GnssFileError(path, ln, f"not an NMEA sentence (no leading '$'): {s[:30]!r}")
        star = s.rfind("*")
        if star < 0 or len(s) - star - 1 != 2:
            raise GnssFileError(path, ln, f"NMEA sentence without a checksum ('*hh' at the end): {s[:30]!r}")
        body, cs = s[1:star], s[star + 1:].upper()
        want = nmea_checksum(body)
        if cs != want:
            raise GnssFileError(path, ln, f"bad NMEA checksum *{cs} (computed *{want}) in {s[:12]!r}")
        f = body.split(",")
        kind = f[0][-3:] if len(f[0]) == 5 else ""
        try:
            if kind == "GGA":
                n_sent["GGA"] += 1
                if len(f) < 12:
                    raise ValueError(f"{len(f)} fields, expected at least 12")
                tod = _tod(f[1])
                quality = int(f[6]) if f[6] else 0
                rec = dict(tod=tod, line=ln, q=quality, lat=_nmea_angle(f[2], f[3], 2, "latitude"),
                           lon=_nmea_angle(f[4], f[5], 3, "longitude"),
                           alt=float(f[9]) if f[9] else np.nan, N=float(f[11]) if f[11] else np.nan)
                if abs(rec["lat"]) > 90 or abs(rec["lon"]) > 180:
                    raise ValueError("latitude/longitude out of range")
            elif kind == "RMC":
                n_sent["RMC"] += 1
                if len(f) < 10:
                    raise ValueError(f"{len(f)} fields, expected at least 10")
                tod = _tod(f[1])
                dd = f[9]
                if len(dd) != 6 or not dd.isdigit():
                    raise ValueError(f"bad date {dd!r} (ddmmyy)")
                yy = int(dd[4:6])
                dday = gps_seconds_from_calendar(2000 + yy if yy < 80 else 1900 + yy, int(dd[2:4]), int(dd[0:2]))
                spd = float(f[7]) * KNOT_MPS if f[7] else np.nan
                crs = float(f[8]) * DEG if f[8] else (0.0 if spd == 0.0 else np.nan)
                rec = dict(tod=tod, line=ln, day=dday, ok=f[2] == "A",
                           vn=spd * math.cos(crs) if f[2] == "A" else np.nan,
                           ve=spd * math.sin(crs) if f[2] == "A" else np.nan)
            elif kind == "GST":
                n_sent["GST"] += 1
                if len(f) < 9:
                    raise ValueError(f"{len(f)} fields, expected 9")
                tod = _tod(f[1])
                rec = dict(tod=tod, line=ln, sd=[float(x) if x else np.nan for x in f[6:9]])
            else:
                n_sent["other"] += 1
                continue
        except ValueError as exc:
            raise GnssFileError(path, ln, f"bad {f[0]} sentence: {exc}") from None
        # the date: RMC sets it; the time of day going back by more than 12 h is a new day
        if kind == "RMC":
            if day is None:
                for r in pending:  # sentences before the first RMC: its date, or the day before
                    r["day"] = rec["day"] - (86400.0 if r["tod"] > rec["tod"] + 43200.0 else 0.0)
                pending = []
            day = rec["day"]
        elif day is not None and last_tod is not None and tod < last_tod - 43200.0:
            day += 86400.0
        last_tod = tod
        key_day = rec.get("day", day)
        r = dict(rec)
        r["kind"] = kind
        r["day"] = key_day
        if key_day is None:
            pending.append(r)
        order.append(r)
    if any(r["day"] is None for r in order):
        raise GnssFileError(path, None, "no RMC sentence gives the date: set [gnss] date = \"YYYY-MM-DD\" (UTC)")
    for r in order:
        key = (r["day"], round(r["tod"], 3))
        e = ep.setdefault(key, {})
        e.setdefault(r["kind"], r)
    keys = sorted(k for k, e in ep.items() if "GGA" in e and e["GGA"]["q"] > 0)
    if not keys:
        raise GnssFileError(path, None, f"no GGA sentence with a fix (GGA {n_sent['GGA']}, RMC {n_sent['RMC']})")
    n = len(keys)
    t_utc = np.array([k[0] + k[1] for k in keys])
    gga = [ep[k]["GGA"] for k in keys]
    lat = np.array([g["lat"] for g in gga])
    lon = np.array([g["lon"] for g in gga])
    alt = np.array([g["alt"] for g in gga])
    und = np.array([g["N"] for g in gga])
    lines = np.array([g["line"] for g in gga], np.int64)
    if fmt.geoid_undulation_m is not None:
        und = np.full(n, float(fmt.geoid_undulation_m))
    bad = np.flatnonzero(~np.isfinite(und) | ~np.isfinite(alt) | ~np.isfinite(lat) | ~np.isfinite(lon))
    if bad.size:
        k = bad[0]
        what = ("no geoid separation (GGA field 11): set [gnss] geoid_undulation_m" if not np.isfinite(und[k])
                else "empty position field in a GGA with a fix")
        raise GnssFileError(path, int(lines[k]), what)
    v = np.full((n, 3), np.nan)
    sp = np.full((n, 3), np.nan)
    for j, k in enumerate(keys):
        e = ep[k]
        if "RMC" in e and e["RMC"]["ok"]:
            v[j, :2] = e["RMC"]["vn"], e["RMC"]["ve"]
        if "GST" in e:
            sp[j] = e["GST"]["sd"]
    leap = gps_minus_utc_s(t_utc[0])
    ref = float(math.floor(t_utc[0])) + float(leap)
    t = t_utc - math.floor(t_utc[0])
    rec = GnssRecords(ref, t, lat, lon, alt + und, v, sp, np.full((n, 3), np.nan),
                      np.array([g["q"] for g in gga], np.int64), lines, path, "nmea",
                      info=dict(sentences=n_sent, leap_seconds=float(leap)))
    return _finish(rec, fmt)


def write_nmea(path, t_gps_s, lat_deg, lon_deg, h_m, sigma_pos_n=None, v_n=None, *, undulation_m: float = 0.0,
               talker: str = "GN", quality: int = 1, n_sats: int = 10, hdop: float = 1.0) -> Path:
    """Write fixes as NMEA 0183 GGA + RMC (+ GST when sigmas are given), one
    epoch per group, UTC time to 0.01 s, lat/lon to 1e-7 minute, altitude
    (MSL = h - undulation) to 1 mm, speed to 0.001 knot, course to 0.01 deg,
    sigmas to 1 mm."""
    import datetime as _dt

    out = []
    for k in range(len(t_gps_s)):
        t_gps = float(t_gps_s[k])
        t_utc = t_gps - float(gps_minus_utc_s(t_gps - 18.0))
        cs = int(round(t_utc * 100.0))
        days, csd = divmod(cs, 8_640_000)
        d = _dt.date(1980, 1, 6) + _dt.timedelta(days=int(days))
        hh, rem = divmod(csd, 360_000)
        mi, rem = divmod(rem, 6000)
        tod = f"{hh:02d}{mi:02d}{rem / 100:05.2f}"
        la, lo = float(lat_deg[k]), float(lon_deg[k])
        la_s = f"{int(abs(la)):02d}{(abs(la) - int(abs(la))) * 60:010.7f},{'N' if la >= 0 else 'S'}"
        lo_s = f"{int(abs(lo)):03d}{(abs(lo) - int(abs(lo))) * 60:010.7f},{'E' if lo >= 0 else 'W'}"
        alt = float(h_m[k]) - undulation_m
        body = (f"{talker}GGA,{tod},{la_s},{lo_s},{quality},{n_sats:02d},{hdop:.1f},{alt:.3f},M,"
                f"{undulation_m:.3f},M,,")
        out.append(f"${body}*{nmea_checksum(body)}")
        if v_n is not None:
            vn, ve = float(v_n[k][0]), float(v_n[k][1])
            spd = math.hypot(vn, ve) / KNOT_MPS
            crs = math.degrees(math.atan2(ve, vn)) % 360.0
            body = (f"{talker}RMC,{tod},A,{la_s},{lo_s},{spd:.3f},{crs:.2f},{d.day:02d}{d.month:02d}"
                    f"{d.year % 100:02d},,,A")
            out.append(f"${body}*{nmea_checksum(body)}")
        if sigma_pos_n is not None:
            s = np.asarray(sigma_pos_n[k], float)
            body = f"{talker}GST,{tod},{float(np.hypot(s[0], s[1])):.3f},,,,{s[0]:.3f},{s[1]:.3f},{s[2]:.3f}"
            out.append(f"${body}*{nmea_checksum(body)}")
    p = Path(path)
    p.write_text("\r\n".join(out) + "\r\n", encoding="ascii")
    return p
