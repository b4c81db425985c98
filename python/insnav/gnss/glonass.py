"""GLONASS FDMA broadcast ephemeris: state-vector integration and clock.

The GLONASS navigation message gives, at the reference time ``t_b``, the
satellite position, velocity and the luni-solar acceleration in the
Earth-fixed PZ-90 frame.  The position at ``t`` (``|t - t_b| <= 15 min``) is
obtained by integrating the equations of motion of GLONASS ICD Ed. 5.1
(2008), Appendix A.3.1.2, in the rotating frame, with the 4th-order
Runge-Kutta method (same appendix)::

    dx/dt  = vx
    dvx/dt = -mu/r^3 x - 3/2 J2 mu a_e^2 / r^5 x (1 - 5 z^2/r^2) + w^2 x + 2 w vy + ax_ls
    dvy/dt = -mu/r^3 y - 3/2 J2 mu a_e^2 / r^5 y (1 - 5 z^2/r^2) + w^2 y - 2 w vx + ay_ls
    dvz/dt = -mu/r^3 z - 3/2 J2 mu a_e^2 / r^5 z (3 - 5 z^2/r^2)                + az_ls

(``J2 = -C20``; the luni-solar accelerations are held constant over the
interval, as the ICD allows).  Every satellite's interval is cut into the
same number of equal steps of at most ``step_s`` (default 60 s), so the whole
batch is integrated in one vectorised loop.

Frames and time
---------------
* PZ-90.11 is treated as WGS-84/ITRF: since the PZ-90.11 realisation
  (2014) the transformation parameters to ITRF2008 are at the centimetre
  level (IERS/GLONASS ICD Ed. 5.1 amendments; RTKLIB does the same), far
  below the broadcast orbit error of a few metres.
* GLONASS time is UTC(SU) + 3 h; RINEX gives the record epoch ``t_b`` in UTC,
  which is converted to GPS time with the leap seconds (the header's
  ``LEAP SECONDS`` or :func:`gps_utc_leap_seconds`).  All times here are
  GPS seconds since 1980-01-06 (``t_gps_s``).
* Clock: RINEX stores ``-tau_n`` and ``+gamma_n`` (ICD Ed. 5.1, 3.3.3:
  ``t_GLONASS = t_k + tau_c - tau_n(t_b) + gamma_n(t_b) (t - t_b)``), so the
  satellite clock offset is ``dt_sv(t) = -tau_n + gamma_n (t - t_b)`` [s]
  relative to GLONASS system time.  The difference between GLONASS system
  time and GPS time (``tau_GPS``, tens of ns) is not applied: it is common
  to all GLONASS satellites and is absorbed by the inter-system bias state.
  No relativistic term is added (it is part of the broadcast clock, ICD
  3.3.3).
* FDMA: each satellite transmits on its channel ``k`` (-7..+6):
  ``f_G1 = 1602 MHz + k 0.5625 MHz`` (ICD Ed. 5.1, 3.3.1.1); :func:`g1_frequency`.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .._median import unique

__all__ = ["GM_GLO", "A_E_GLO", "J2_GLO", "OMEGA_E_GLO", "GlonassEphemerides", "g1_frequency",
           "g1_wavelength", "glonass_derivatives", "glonass_integrate", "glonass_position_velocity",
           "glonass_clock", "select_glonass", "gps_utc_leap_seconds", "MAX_AGE_GLO_S"]

#: PZ-90 geocentric gravitational constant, ICD Ed. 5.1 Table 3.2 [m^3/s^2]
GM_GLO = 398600.4418e9
#: PZ-90 equatorial radius, ICD Ed. 5.1 Table 3.2 [m]
A_E_GLO = 6378136.0
#: second zonal harmonic J2 = -C20, ICD Ed. 5.1 Table 3.2 [-]
J2_GLO = 1082625.75e-9
#: Earth rotation rate, ICD Ed. 5.1 Table 3.2 [rad/s]
OMEGA_E_GLO = 7.292115e-5
#: RINEX records are every 30 min; the ICD validity interval is ``|t - t_b| <= 15 min``.  Selection
#: accepts the nearest record up to this age (RTKLIB's MAXDTOE_GLO) [s]
MAX_AGE_GLO_S = 1800.0
#: G1 centre frequency and channel spacing, ICD Ed. 5.1 3.3.1.1 [Hz]
G1_BASE_HZ = 1602.0e6
G1_STEP_HZ = 0.5625e6
_C = 299792458.0

def _leap_table():
    from .gpstime import gps_seconds_from_calendar

    dates = [(1981, 7, 1), (1982, 7, 1), (1983, 7, 1), (1985, 7, 1), (1988, 1, 1), (1990, 1, 1), (1991, 1, 1),
             (1992, 7, 1), (1993, 7, 1), (1994, 7, 1), (1996, 1, 1), (1997, 7, 1), (1999, 1, 1), (2006, 1, 1),
             (2009, 1, 1), (2012, 7, 1), (2015, 7, 1), (2017, 1, 1)]
    # IERS Bulletin C dates (extend when a leap second is announced); the n-th step (UTC midnight)
    # sets GPS - UTC = n and happens at GPS calendar time midnight + n s
    return np.array([gps_seconds_from_calendar(y, m, d) + k + 1 for k, (y, m, d) in enumerate(dates)]), \
        np.arange(1, len(dates) + 1, dtype=float)


def gps_utc_leap_seconds(t_gps_s):
    """GPS - UTC [s] at GPS time ``t_gps_s`` (IERS Bulletin C table; 17 s in 2016, 18 s from 2017-01-01)."""
    steps, vals = _leap_table()
    k = np.searchsorted(steps, np.asarray(t_gps_s, float), side="right")
    out = np.where(k > 0, vals[np.maximum(k - 1, 0)], 0.0)
    return float(out) if np.ndim(out) == 0 else out


def g1_frequency(k):
    """G1 carrier frequency of FDMA channel ``k`` [Hz] (ICD Ed. 5.1 3.3.1.1)."""
    return G1_BASE_HZ + np.asarray(k, float) * G1_STEP_HZ


def g1_wavelength(k):
    """G1 carrier wavelength of FDMA channel ``k`` [m]."""
    return _C / g1_frequency(k)


@dataclass
class GlonassEphemerides:
    """Table of GLONASS broadcast records (one row per record), SI units.

    Attributes
    ----------
    prn : (n,) int, slot number
    tb : (n,) reference time ``t_b`` as GPS seconds since 1980-01-06 [s]
    clock_bias : (n,) ``-tau_n`` [s] (RINEX "SV clock bias")
    gamma_n : (n,) relative frequency bias ``+gamma_n`` [-]
    x, y, z : (n,) PZ-90 position at ``t_b`` [m]
    vx, vy, vz : (n,) velocity [m/s]
    ax, ay, az : (n,) luni-solar acceleration [m/s^2]
    health : (n,) 0 = healthy (RINEX: MSB of B_n)
    freq_k : (n,) int FDMA channel number (-7..+6)
    age : (n,) age of operational information E_n [days]
    tk : (n,) message frame time as read (seconds of the UTC week or day) [s]
    """

    prn: np.ndarray
    tb: np.ndarray
    clock_bias: np.ndarray
    gamma_n: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    vz: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    az: np.ndarray
    health: np.ndarray
    freq_k: np.ndarray
    age: np.ndarray
    tk: np.ndarray

    def __post_init__(self):
        n = None
        for f in fields(self):
            a = np.atleast_1d(np.asarray(getattr(self, f.name)))
            a = a.astype(np.int64) if f.name in ("prn", "freq_k") else a.astype(float)
            if n is None:
                n = a.shape[0]
            elif a.shape != (n,):
                raise ValueError(f"GlonassEphemerides.{f.name} has shape {a.shape}, expected ({n},)")
            setattr(self, f.name, a)

    def __len__(self):
        return int(self.prn.shape[0])

    @classmethod
    def from_columns(cls, cols: dict) -> "GlonassEphemerides":
        return cls(**{f.name: cols[f.name] for f in fields(cls)})

    @classmethod
    def empty(cls) -> "GlonassEphemerides":
        return cls(**{f.name: np.zeros(0) for f in fields(cls)})

    def to_columns(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def subset(self, idx) -> "GlonassEphemerides":
        return GlonassEphemerides(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    def concat(self, other: "GlonassEphemerides") -> "GlonassEphemerides":
        return GlonassEphemerides(**{f.name: np.concatenate([getattr(self, f.name), getattr(other, f.name)])
                                     for f in fields(self)})

    def channel(self, prn) -> np.ndarray:
        """FDMA channel of each slot ``prn`` (from its latest record); -99 if the slot has no record."""
        prn = np.atleast_1d(np.asarray(prn, np.int64))
        out = np.full(prn.shape, -99, np.int64)
        for p in unique(prn):
            rows = np.flatnonzero(self.prn == p)
            if rows.size:
                out[prn == p] = self.freq_k[rows[np.argmax(self.tb[rows])]]
        return out


def glonass_derivatives(s, a_ls):
    """Right-hand side of the GLONASS equations of motion (ICD Ed. 5.1 A.3.1.2), vectorised.

    Parameters
    ----------
    s : (k, 6) state ``[x y z vx vy vz]`` in PZ-90 [m, m/s]
    a_ls : (k, 3) luni-solar acceleration [m/s^2]

    Returns
    -------
    (k, 6) time derivative [m/s, m/s^2]
    """
    x, y, z = s[:, 0], s[:, 1], s[:, 2]
    vx, vy = s[:, 3], s[:, 4]
    r2 = x * x + y * y + z * z
    r = np.sqrt(r2)
    mu_r3 = GM_GLO / (r2 * r)
    j = 1.5 * J2_GLO * GM_GLO * A_E_GLO**2 / (r2 * r2 * r)
    q = 5.0 * z * z / r2
    w2 = OMEGA_E_GLO**2
    out = np.empty_like(s)
    out[:, 0:3] = s[:, 3:6]
    out[:, 3] = -mu_r3 * x - j * x * (1.0 - q) + w2 * x + 2.0 * OMEGA_E_GLO * vy + a_ls[:, 0]
    out[:, 4] = -mu_r3 * y - j * y * (1.0 - q) + w2 * y - 2.0 * OMEGA_E_GLO * vx + a_ls[:, 1]
    out[:, 5] = -mu_r3 * z - j * z * (3.0 - q) + a_ls[:, 2]
    return out


def glonass_integrate(s0, a_ls, dt, step_s: float = 60.0):
    """Integrate the equations of motion from ``t_b`` over ``dt`` by classical RK4.

    Parameters
    ----------
    s0 : (k, 6) state at ``t_b`` [m, m/s]
    a_ls : (k, 3) luni-solar acceleration, constant [m/s^2]
    dt : (k,) ``t - t_b`` [s] (either sign)
    step_s : float
        Largest step [s]; every row uses ``n = ceil(max|dt| / step_s)`` equal steps ``dt / n``.

    Returns
    -------
    (k, 6) state at ``t_b + dt``
    """
    s = np.array(s0, dtype=float, copy=True).reshape(-1, 6)
    a_ls = np.broadcast_to(np.asarray(a_ls, float), (s.shape[0], 3))
    dt = np.broadcast_to(np.asarray(dt, float), (s.shape[0],))
    if s.shape[0] == 0:
        return s
    n = int(np.ceil(np.max(np.abs(dt)) / float(step_s))) if np.max(np.abs(dt)) > 0 else 0
    if n == 0:
        return s
    h = (dt / n)[:, None]
    for _ in range(n):
        k1 = glonass_derivatives(s, a_ls)
        k2 = glonass_derivatives(s + 0.5 * h * k1, a_ls)
        k3 = glonass_derivatives(s + 0.5 * h * k2, a_ls)
        k4 = glonass_derivatives(s + h * k3, a_ls)
        s = s + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return s


def glonass_position_velocity(eph: GlonassEphemerides, idx, t_gps_s, step_s: float = 60.0):
    """PZ-90 (= ECEF, see module notes) position [m] and velocity [m/s] at ``t_gps_s``.

    Parameters
    ----------
    eph : GlonassEphemerides
    idx : (k,) int rows of ``eph``
    t_gps_s : (k,) or scalar evaluation time, GPS seconds [s]
    step_s : largest RK4 step [s]

    Returns
    -------
    r_e, v_e : (k, 3) arrays in the ECEF frame at ``t_gps_s``
    """
    idx = np.atleast_1d(np.asarray(idx, np.int64))
    t = np.broadcast_to(np.asarray(t_gps_s, float), idx.shape)
    g = lambda name: getattr(eph, name)[idx]  # noqa: E731
    s0 = np.column_stack([g("x"), g("y"), g("z"), g("vx"), g("vy"), g("vz")])
    a = np.column_stack([g("ax"), g("ay"), g("az")])
    s = glonass_integrate(s0, a, t - g("tb"), step_s)
    return s[:, 0:3], s[:, 3:6]


#: columns of :func:`glonass_table` (the order of ``GlonassCols`` in insnav/gnss/broadcast_orbit.hpp)
GLONASS_TABLE_COLUMNS = ("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "tb", "clock_bias", "gamma_n")


def glonass_table(eph: GlonassEphemerides) -> np.ndarray:
    """(records, 12) table of the compiled GLONASS orbit code (:data:`GLONASS_TABLE_COLUMNS`)."""
    t = np.empty((len(eph), len(GLONASS_TABLE_COLUMNS)))
    for j, name in enumerate(GLONASS_TABLE_COLUMNS):
        t[:, j] = getattr(eph, name)
    return t


def glonass_clock(eph: GlonassEphemerides, idx, t_gps_s):
    """Satellite clock offset ``dt_sv = -tau_n + gamma_n (t - t_b)`` [s] and drift ``gamma_n`` [s/s]."""
    idx = np.atleast_1d(np.asarray(idx, np.int64))
    t = np.broadcast_to(np.asarray(t_gps_s, float), idx.shape)
    gam = eph.gamma_n[idx]
    return eph.clock_bias[idx] + gam * (t - eph.tb[idx]), gam.copy()


def select_glonass(eph: GlonassEphemerides, prn, t_gps_s, *, healthy_only=True, max_age_s=MAX_AGE_GLO_S):
    """Row of the nearest-``t_b`` (healthy) record of each (slot, time); -1 if none within ``max_age_s``.

    Ties go to the record that appears last (as :func:`insnav.gnss.ephemeris.select_ephemeris`).
    """
    from .. import _core

    prn_a, t_a = np.broadcast_arrays(np.atleast_1d(np.asarray(prn, np.int64)),
                                     np.atleast_1d(np.asarray(t_gps_s, float)))
    if hasattr(_core, "select_nearest_record"):  # insnav/gnss/ephemeris_selection.hpp: the loop below in C++
        usable = np.asarray(eph.health) == 0 if healthy_only else np.ones(len(eph), bool)
        idx = _core.select_nearest_record(np.asarray(eph.prn, np.int64), usable.astype(np.uint8),
                                          np.asarray(eph.tb, float), np.full(len(eph), float(max_age_s)),
                                          prn_a.reshape(-1), t_a.reshape(-1))
        return idx.reshape(prn_a.shape)
    return _select_glonass_numpy(eph, prn_a, t_a, healthy_only, max_age_s)


def _select_glonass_numpy(eph, prn_a, t_a, healthy_only, max_age_s):
    """The loop of :func:`select_glonass` in numpy (the reference of the compiled selection)."""
    out = np.full(prn_a.shape, -1, np.int64)
    for p in unique(prn_a):
        rows = np.flatnonzero(eph.prn == p)
        if healthy_only:
            rows = rows[eph.health[rows] == 0]
        if rows.size == 0:
            continue
        sel = np.flatnonzero(prn_a == p)
        dt = np.abs(t_a[sel, None] - eph.tb[rows][None, :])
        cost = np.where(dt <= max_age_s, dt, np.inf)
        j = cost.shape[1] - 1 - np.argmin(cost[:, ::-1], axis=1)
        good = np.isfinite(cost[np.arange(sel.size), j])
        out[sel[good]] = rows[j[good]]
    return out
