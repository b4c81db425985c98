"""GPS time helpers.

Time inside :mod:`insnav.gnss` is a float number of GPS seconds since the GPS
epoch 1980-01-06 00:00:00 GPS time (``t_gps_s``).  It is continuous across
week boundaries, so the week-crossover logic of IS-GPS-200 section
20.3.3.4.3 (``tk`` wrapped into +/-302400 s) reduces to a plain difference of
two ``t_gps_s`` values; :func:`wrap_week_seconds` is provided for code that
works with seconds of week.

Float64 seconds since 1980 have a resolution of about 0.2 microseconds
(0.06 m of light travel) around the year 2025, which is ample for code
pseudoranges and ephemeris evaluation.  Carrier-phase work needing better
should carry (week, seconds of week) separately; the readers return both.
"""
from __future__ import annotations

import numpy as np

#: Seconds in a GPS week [s].
SECONDS_PER_WEEK = 604800.0
#: Half a GPS week [s] (IS-GPS-200 20.3.3.4.3 crossover threshold).
HALF_WEEK = 302400.0
#: Days from 0000-03-01 (proleptic Gregorian) to 1980-01-06.
_GPS_EPOCH_DAYS = None  # filled below


def _days_from_civil(y, m, d):
    """Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's algorithm)."""
    y = np.asarray(y, dtype=np.int64)
    m = np.asarray(m, dtype=np.int64)
    d = np.asarray(d, dtype=np.int64)
    y = y - (m <= 2)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    mp = (m + 9) % 12
    doy = (153 * mp + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


_GPS_EPOCH_DAYS = int(_days_from_civil(1980, 1, 6))


def gps_seconds_from_calendar(year, month, day, hour=0, minute=0, second=0.0):
    """GPS seconds since 1980-01-06 from a calendar date expressed in GPS time.

    Parameters
    ----------
    year, month, day, hour, minute : int or array_like
        Calendar fields (four-digit year).
    second : float or array_like
        Seconds of the minute [s].

    Returns
    -------
    float or ndarray
        ``t_gps_s`` [s].  No leap seconds are applied: the input must already
        be GPS time (as RINEX GPS records and SP3 files with time system GPS are).
    """
    if all(type(v) is int for v in (year, month, day, hour, minute)) and type(second) in (int, float):
        # one epoch of a reader: the same arithmetic in Python scalars (no numpy scalar per operation)
        y = year - (month <= 2)
        era = y // 400
        yoe = y - era * 400
        doe = yoe * 365 + yoe // 4 - yoe // 100 + (153 * ((month + 9) % 12) + 2) // 5 + day - 1
        days = era * 146097 + doe - 719468 - _GPS_EPOCH_DAYS
        return days * 86400.0 + hour * 3600.0 + minute * 60.0 + float(second)
    days = _days_from_civil(year, month, day) - _GPS_EPOCH_DAYS
    out = days * 86400.0 + np.asarray(hour) * 3600.0 + np.asarray(minute) * 60.0 + np.asarray(second, dtype=float)
    return float(out) if np.ndim(out) == 0 else out


def week_tow(t_gps_s):
    """Split ``t_gps_s`` [s] into (GPS week, seconds of week [s])."""
    t = np.asarray(t_gps_s, dtype=float)
    week = np.floor(t / SECONDS_PER_WEEK)
    tow = t - week * SECONDS_PER_WEEK
    if np.ndim(t) == 0:
        return int(week), float(tow)
    return week.astype(np.int64), tow


def gps_seconds_from_week_tow(week, tow):
    """``t_gps_s`` [s] from a full (not modulo-1024) GPS week and seconds of week [s]."""
    return np.asarray(week, dtype=float) * SECONDS_PER_WEEK + np.asarray(tow, dtype=float)


def wrap_week_seconds(dt):
    """Wrap a time difference in seconds of week into [-302400, 302400) s.

    This is the IS-GPS-200 20.3.3.4.3 rule for ``tk = t - toe`` when ``t`` and
    ``toe`` are seconds of week: add or subtract 604800 s at a week crossover.
    """
    dt = np.asarray(dt, dtype=float)
    return (dt + HALF_WEEK) % SECONDS_PER_WEEK - HALF_WEEK
