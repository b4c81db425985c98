"""GPS LNAV broadcast ephemeris: satellite position, velocity and clock.

Implements IS-GPS-200 (rev. N) section 20.3.3.4.3, Table 20-IV (user
algorithm for the ephemeris), the analytic time derivative of it for the
satellite velocity, and section 20.3.3.3.3.1 (SV clock correction, with the
relativistic term ``F e sqrt(A) sin E`` of eq. in 20.3.3.3.3.1 and the L1 C/A
group delay ``T_GD`` of 20.3.3.3.3.2 as an option).

Everything is vectorised: :func:`sat_position_velocity` and :func:`sat_clock`
take arrays of times and of ephemeris row indices of equal length.

Signal transmit time and Earth rotation
---------------------------------------
:func:`transmit_states` is the convention the tight-coupling filter and the
simulator share.  Given a receive time ``t_rx`` (true GPS time, i.e. receiver
clock error already removed), an approximate receiver position ``r_rx_e`` in
the ECEF frame *at reception* and a satellite, it

1. iterates the geometric signal travel time ``tau`` (start 0.075 s):
   ``t_tx = t_rx - tau``; satellite ECEF state at ``t_tx`` from the ephemeris;
2. rotates that state from the ECEF frame at transmission into the ECEF frame
   at reception (Sagnac / Earth-rotation correction), a rotation about z by
   ``theta = OMEGA_E_DOT * tau``::

       r_sat_e(rx frame) = R3(theta) r_sat_e(t_tx),   R3(theta) = [[ c, s, 0],
       v_sat_e(rx frame) = R3(theta) v_sat_e(t_tx)                 [-s, c, 0],
                                                                    [ 0, 0, 1]]

   (R3 is the frame rotation, so the satellite appears rotated *westwards*);
3. sets ``tau = |r_sat_e(rx frame) - r_rx_e| / c`` and repeats until ``tau``
   changes by less than 1e-12 s (2-3 iterations).

The returned ``r_e``/``v_e`` are therefore already in the ECEF frame at the
reception time: the geometric range is simply ``|r_e - r_rx_e|`` with no
further Sagnac term, and the range rate is ``u . (v_e - v_rx_e)`` with ``u``
the receiver-to-satellite unit vector.  Satellite clock (bias, drift) is
evaluated at ``t_tx``.  Pseudorange model: ``P = |r_e - r_rx_e| + c dt_rx -
clock_bias_m + iono + tropo``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from .. import _core
from .._median import unique
from .gpstime import wrap_week_seconds

#: WGS-84 value of GM used by GPS, IS-GPS-200 Table 20-IV [m^3/s^2].
GM_GPS = 3.986005e14
#: WGS-84 Earth rotation rate used by GPS, IS-GPS-200 Table 20-IV [rad/s].
OMEGA_E_DOT = 7.2921151467e-5
#: Speed of light, IS-GPS-200 20.3.4.3 [m/s].
C_LIGHT = 299792458.0
#: Relativistic constant F = -2 sqrt(GM)/c^2, IS-GPS-200 20.3.3.3.3.1 [s/sqrt(m)].
F_REL = -4.442807633e-10
#: Default curve-fit interval when a record gives 0 (IS-GPS-200 20.3.4.4) [s].
DEFAULT_FIT_S = 4.0 * 3600.0

_ELEMENT_FIELDS = (
    "prn", "toc", "af0", "af1", "af2", "iode", "crs", "delta_n", "m0", "cuc", "e",
    "cus", "sqrt_a", "toe", "toe_sow", "cic", "omega0", "cis", "i0", "crc", "omega",
    "omega_dot", "idot", "week", "sv_accuracy", "health", "tgd", "iodc", "fit_s",
)


@dataclass
class Ephemerides:
    """A table of GPS LNAV ephemerides (one row per broadcast record).

    All attributes are 1-D arrays of equal length.  Units SI, angles in rad
    (RINEX already stores rad and rad/s, IS-GPS-200 uses semicircles).

    Attributes
    ----------
    prn : int array
    toc : clock reference time as ``t_gps_s`` [s]
    af0, af1, af2 : clock polynomial [s, s/s, s/s^2]
    iode, iodc : issue of data
    crs, crc : radius harmonic corrections [m]
    cuc, cus, cic, cis : latitude / inclination harmonic corrections [rad]
    delta_n : mean motion difference [rad/s]
    m0, omega0, i0, omega : angles at reference time [rad]
    e : eccentricity [-]
    sqrt_a : square root of the semi-major axis [sqrt(m)]
    toe : ephemeris reference time as ``t_gps_s`` [s] (continuous, used for ``tk``)
    toe_sow : ephemeris reference time in seconds of its week [s] (the
        broadcast ``t_oe``, used in the longitude-of-node term ``- OMEGA_E_DOT t_oe``)
    omega_dot, idot : rates [rad/s]
    week : full GPS week of ``toe``
    sv_accuracy : URA [m]
    health : SV health word (0 = healthy)
    tgd : L1/L2 group delay T_GD [s]
    fit_s : curve-fit interval [s]
    """

    prn: np.ndarray
    toc: np.ndarray
    af0: np.ndarray
    af1: np.ndarray
    af2: np.ndarray
    iode: np.ndarray
    crs: np.ndarray
    delta_n: np.ndarray
    m0: np.ndarray
    cuc: np.ndarray
    e: np.ndarray
    cus: np.ndarray
    sqrt_a: np.ndarray
    toe: np.ndarray
    toe_sow: np.ndarray
    cic: np.ndarray
    omega0: np.ndarray
    cis: np.ndarray
    i0: np.ndarray
    crc: np.ndarray
    omega: np.ndarray
    omega_dot: np.ndarray
    idot: np.ndarray
    week: np.ndarray
    sv_accuracy: np.ndarray
    health: np.ndarray
    tgd: np.ndarray
    iodc: np.ndarray
    fit_s: np.ndarray

    def __post_init__(self):
        n = None
        for f in fields(self):
            a = np.atleast_1d(np.asarray(getattr(self, f.name)))
            a = a.astype(np.int64) if f.name == "prn" else a.astype(float)
            if n is None:
                n = a.shape[0]
            elif a.shape != (n,):
                raise ValueError(f"Ephemerides.{f.name} has shape {a.shape}, expected ({n},)")
            setattr(self, f.name, a)

    def __len__(self):
        return int(self.prn.shape[0])

    @classmethod
    def from_columns(cls, cols: dict) -> "Ephemerides":
        """Build from a mapping ``field name -> sequence``."""
        return cls(**{k: cols[k] for k in _ELEMENT_FIELDS})

    def to_columns(self) -> dict:
        """Mapping ``field name -> array`` (the inverse of :meth:`from_columns`)."""
        return {k: getattr(self, k) for k in _ELEMENT_FIELDS}

    def subset(self, idx) -> "Ephemerides":
        """Rows ``idx`` (index array or boolean mask) as a new table."""
        return Ephemerides(**{k: getattr(self, k)[idx] for k in _ELEMENT_FIELDS})


class SatPosVel(NamedTuple):
    """Satellite ECEF state from the broadcast ephemeris."""

    r_e: np.ndarray  #: (k, 3) position [m], ECEF at the evaluation time
    v_e: np.ndarray  #: (k, 3) velocity relative to ECEF [m/s]
    E: np.ndarray  #: (k,) eccentric anomaly [rad]
    E_dot: np.ndarray  #: (k,) its rate [rad/s]


def _kepler(M, e, iters=10):
    """Solve Kepler's equation ``M = E - e sin E`` by Newton iteration (vectorised)."""
    E = M.copy()
    for _ in range(iters):
        dE = (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
        E = E - dE
        if np.all(np.abs(dE) < 1e-14):
            break
    return E


def sat_position_velocity(eph: Ephemerides, idx, t_gps_s, *, gm: float = GM_GPS,
                          omega_e: float = OMEGA_E_DOT) -> SatPosVel:
    """Satellite ECEF position and velocity, IS-GPS-200 Table 20-IV.

    Parameters
    ----------
    eph : Ephemerides
    idx : int array_like, shape (k,)
        Row of ``eph`` to use for each evaluation (see :func:`select_ephemeris`).
    t_gps_s : array_like, shape (k,) or scalar
        GPS system time of evaluation, seconds since 1980-01-06 [s].  For a
        pseudorange this is the transmit time (see :func:`transmit_states`).
    gm, omega_e : float
        Gravitational constant [m^3/s^2] and Earth rotation rate [rad/s] of
        the system's ICD (defaults: GPS).  Galileo (OS SIS ICD 2.1, Table 58)
        and BeiDou MEO/IGSO (BDS-SIS-ICD-B1I 3.0, 5.2.4.12) use the same
        algorithm with their own constants (:mod:`insnav.gnss.galbds`).

    Returns
    -------
    SatPosVel
        ``r_e`` [m] and ``v_e`` [m/s] in the ECEF frame at ``t_gps_s``.

    Notes
    -----
    ``tk = t - toe`` is a plain difference because both are continuous GPS
    seconds (the week crossover of 20.3.3.4.3 is implicit).  Velocity is the
    analytic time derivative of every line of Table 20-IV (``E_dot = n /
    (1 - e cos E)``, ``nu_dot = E_dot sqrt(1-e^2)/(1 - e cos E)``, then the
    derivatives of the corrected argument of latitude, radius and
    inclination, and ``Omega_dot - OMEGA_E_DOT`` for the node), not a finite
    difference.
    """
    idx = np.atleast_1d(np.asarray(idx, dtype=np.int64))
    t = np.broadcast_to(np.asarray(t_gps_s, dtype=float), idx.shape)
    g = lambda name: getattr(eph, name)[idx]  # noqa: E731
    A = g("sqrt_a") ** 2
    n0 = np.sqrt(gm / A**3)
    tk = t - g("toe")
    n = n0 + g("delta_n")
    M = g("m0") + n * tk
    e = g("e")
    E = _kepler(M, e)
    sE, cE = np.sin(E), np.cos(E)
    one_m_ecE = 1.0 - e * cE
    sq = np.sqrt(1.0 - e * e)
    nu = np.arctan2(sq * sE, cE - e)
    phi = nu + g("omega")
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    du = g("cus") * s2 + g("cuc") * c2
    dr = g("crs") * s2 + g("crc") * c2
    di = g("cis") * s2 + g("cic") * c2
    u = phi + du
    r = A * one_m_ecE + dr
    i = g("i0") + di + g("idot") * tk
    xp, yp = r * np.cos(u), r * np.sin(u)
    Om = g("omega0") + (g("omega_dot") - omega_e) * tk - omega_e * g("toe_sow")
    cO, sO, ci, si = np.cos(Om), np.sin(Om), np.cos(i), np.sin(i)
    x = xp * cO - yp * ci * sO
    y = xp * sO + yp * ci * cO
    z = yp * si

    # Analytic derivatives.
    E_dot = n / one_m_ecE
    nu_dot = E_dot * sq / one_m_ecE
    phi_dot = nu_dot
    u_dot = phi_dot * (1.0 + 2.0 * (g("cus") * c2 - g("cuc") * s2))
    r_dot = A * e * sE * E_dot + 2.0 * phi_dot * (g("crs") * c2 - g("crc") * s2)
    i_dot = g("idot") + 2.0 * phi_dot * (g("cis") * c2 - g("cic") * s2)
    Om_dot = g("omega_dot") - omega_e
    xp_dot = r_dot * np.cos(u) - yp * u_dot
    yp_dot = r_dot * np.sin(u) + xp * u_dot
    vx = xp_dot * cO - yp_dot * ci * sO + yp * si * i_dot * sO - y * Om_dot
    vy = xp_dot * sO + yp_dot * ci * cO - yp * si * i_dot * cO + x * Om_dot
    vz = yp_dot * si + yp * ci * i_dot
    return SatPosVel(np.stack([x, y, z], -1), np.stack([vx, vy, vz], -1), E, E_dot)


class SatClock(NamedTuple):
    """Satellite clock correction."""

    bias_s: np.ndarray  #: (k,) dt_sv [s]; GPS time t = t_sv - dt_sv (IS-GPS-200 20.3.3.3.3.1)
    drift_s_s: np.ndarray  #: (k,) d(dt_sv)/dt [s/s]
    relativistic_s: np.ndarray  #: (k,) the relativistic term included in bias_s (0 if excluded) [s]


def sat_clock(eph: Ephemerides, idx, t_gps_s, *, relativistic=True, tgd=False, E=None, E_dot=None,
              f_rel: float = F_REL) -> SatClock:
    """Satellite clock offset ``dt_sv``, IS-GPS-200 20.3.3.3.3.1.

    ``dt_sv = af0 + af1 (t - toc) + af2 (t - toc)^2 + dt_r`` with the
    relativistic term ``dt_r = F e sqrt(A) sin E``; optionally minus ``T_GD``
    (20.3.3.3.3.2, single-frequency L1 C/A user).  GPS time = SV time - dt_sv,
    so the pseudorange model contains ``- c dt_sv``.

    Parameters
    ----------
    eph, idx, t_gps_s : as in :func:`sat_position_velocity`.
    relativistic : bool
        Include ``dt_r`` (True for pseudorange modelling; False to compare with
        precise SP3/CLK clocks, which exclude it).
    tgd : bool
        Subtract ``T_GD`` (L1 C/A single-frequency correction).
    E, E_dot : array_like, optional
        Eccentric anomaly [rad] and rate [rad/s] if already computed (needed
        when ``relativistic`` for a non-GPS table: the default recomputes
        them with the GPS constants).
    f_rel : float
        Relativistic constant ``-2 sqrt(GM)/c^2`` of the system [s/sqrt(m)].

    Returns
    -------
    SatClock
        ``bias_s`` [s], ``drift_s_s`` [s/s] (analytic derivative, including
        ``F e sqrt(A) cos E E_dot`` when ``relativistic``), ``relativistic_s`` [s].
    """
    idx = np.atleast_1d(np.asarray(idx, dtype=np.int64))
    t = np.broadcast_to(np.asarray(t_gps_s, dtype=float), idx.shape)
    dt = t - eph.toc[idx]
    af0, af1, af2 = eph.af0[idx], eph.af1[idx], eph.af2[idx]
    bias = af0 + af1 * dt + af2 * dt * dt
    drift = af1 + 2.0 * af2 * dt
    rel = np.zeros_like(bias)
    if relativistic:
        if E is None or E_dot is None:
            pv = sat_position_velocity(eph, idx, t)
            E, E_dot = pv.E, pv.E_dot
        k = f_rel * eph.e[idx] * eph.sqrt_a[idx]
        rel = k * np.sin(E)
        bias = bias + rel
        drift = drift + k * np.cos(E) * E_dot
    if tgd:
        bias = bias - eph.tgd[idx]
    return SatClock(bias, drift, rel)


def select_ephemeris(eph: Ephemerides, prn, t_gps_s, *, healthy_only=True, check_fit=True, max_age_s=None):
    """Index of the ephemeris to use for each (prn, time) pair.

    The rule is the usual post-processing one: among the records of that
    PRN which are healthy (``health == 0``) and whose fit interval contains
    ``t`` (``|t - toe| <= fit_s / 2``, IS-GPS-200 20.3.4.4), take the one with
    the nearest ``toe``; ties go to the record that appears last.

    Parameters
    ----------
    eph : Ephemerides
    prn : int array_like, shape (k,) or scalar
    t_gps_s : array_like, shape (k,) or scalar [s]
    healthy_only : bool
    check_fit : bool
        Enforce the fit-interval validity window.
    max_age_s : float, optional
        Replace the fit-interval window by ``|t - toe| <= max_age_s`` [s].

    Returns
    -------
    ndarray of int, shape (k,)
        Row index into ``eph``, or -1 where no usable record exists.
    """
    prn_a, t_a = np.broadcast_arrays(np.atleast_1d(np.asarray(prn, dtype=np.int64)),
                                     np.atleast_1d(np.asarray(t_gps_s, dtype=float)))
    if hasattr(_core, "select_nearest_record"):  # insnav/gnss/ephemeris_selection.hpp: the loop below in C++
        if max_age_s is not None:
            window = np.full(len(eph), float(max_age_s))
        elif check_fit:
            window = 0.5 * np.asarray(eph.fit_s, float) + 1e-6
        else:
            window = np.full(len(eph), np.inf)
        usable = np.asarray(eph.health) == 0 if healthy_only else np.ones(len(eph), bool)
        idx = _core.select_nearest_record(np.asarray(eph.prn, np.int64), usable.astype(np.uint8),
                                          np.asarray(eph.toe, float), window, prn_a.reshape(-1), t_a.reshape(-1))
        return idx.reshape(prn_a.shape)
    return _select_ephemeris_numpy(eph, prn_a, t_a, healthy_only, check_fit, max_age_s)


def _select_ephemeris_numpy(eph, prn_a, t_a, healthy_only, check_fit, max_age_s):
    """The loop of :func:`select_ephemeris` in numpy (the reference of the compiled selection)."""
    out = np.full(prn_a.shape, -1, dtype=np.int64)
    for p in unique(prn_a):
        rows = np.nonzero(eph.prn == p)[0]
        if healthy_only:
            rows = rows[eph.health[rows] == 0]
        if rows.size == 0:
            continue
        sel = np.nonzero(prn_a == p)[0]
        dt = np.abs(t_a[sel, None] - eph.toe[rows][None, :])  # (ks, nr)
        if max_age_s is not None:
            ok = dt <= max_age_s
        elif check_fit:
            ok = dt <= 0.5 * eph.fit_s[rows][None, :] + 1e-6
        else:
            ok = np.ones_like(dt, dtype=bool)
        cost = np.where(ok, dt, np.inf)
        # ties -> last record: search reversed
        j = cost.shape[1] - 1 - np.argmin(cost[:, ::-1], axis=1)
        good = np.isfinite(cost[np.arange(sel.size), j])
        out[sel[good]] = rows[j[good]]
    return out


class TransmitStates(NamedTuple):
    """Satellite states at signal transmission, in the ECEF frame at reception."""

    r_e: np.ndarray  #: (k, 3) [m]
    v_e: np.ndarray  #: (k, 3) [m/s]
    clock_bias_s: np.ndarray  #: (k,) dt_sv at t_tx [s] (relativistic included; TGD per option)
    clock_drift_s_s: np.ndarray  #: (k,) [s/s]
    t_tx_gps_s: np.ndarray  #: (k,) transmit time [s]
    tau_s: np.ndarray  #: (k,) geometric signal travel time [s]
    range_m: np.ndarray  #: (k,) geometric range ``|r_e - r_rx_e|`` [m]


def rotate_earth(r_e, theta):
    """Apply the frame rotation R3(theta) (about z) to ECEF vectors, shape (k, 3).

    Used for the Sagnac correction: a vector fixed in the ECEF frame at time
    ``t`` expressed in the ECEF frame at ``t + theta / OMEGA_E_DOT``.
    """
    r_e = np.asarray(r_e, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    out = np.empty(np.broadcast_shapes(r_e.shape, np.shape(theta) + (3,)))
    out[..., 0] = c * r_e[..., 0] + s * r_e[..., 1]
    out[..., 1] = -s * r_e[..., 0] + c * r_e[..., 1]
    out[..., 2] = r_e[..., 2]
    return out


def transmit_states(eph: Ephemerides, idx, t_rx_gps_s, r_rx_e, *, tgd=False, tol_s=1e-12, max_iter=10) -> TransmitStates:
    """Light-time and Sagnac-corrected satellite states (see module docstring).

    Parameters
    ----------
    eph : Ephemerides
    idx : int array_like, shape (k,)
        Ephemeris rows (e.g. from :func:`select_ephemeris` at ``t_rx``).
    t_rx_gps_s : array_like, shape (k,) or scalar
        Receive time, true GPS time [s].
    r_rx_e : array_like, shape (3,) or (k, 3)
        Approximate receiver ECEF position [m] (an error of 1 km changes
        the satellite position by < 4 mm along track).
    tgd : bool
        Subtract T_GD from the clock bias.

    Returns
    -------
    TransmitStates
        Satellite position/velocity at ``t_tx`` rotated into the ECEF frame at
        ``t_rx``, clock at ``t_tx``, ``t_tx``, ``tau`` and the geometric range.
    """
    idx = np.atleast_1d(np.asarray(idx, dtype=np.int64))
    t_rx = np.broadcast_to(np.asarray(t_rx_gps_s, dtype=float), idx.shape)
    r_rx = np.broadcast_to(np.asarray(r_rx_e, dtype=float), idx.shape + (3,))
    if idx.ndim == 1 and idx.size and hasattr(_core, "transmit_states_kepler"):
        r, v, bias, drift, t_tx, tau, rng = _core.transmit_states_kepler(
            kepler_table(eph), idx, t_rx, r_rx, GM_GPS, OMEGA_E_DOT, F_REL, 0.0, tol_s, max_iter)
        if tgd:
            bias = bias - eph.tgd[idx]
        return TransmitStates(r, v, bias, drift, t_tx, tau, rng)
    return _transmit_states_numpy(eph, idx, t_rx, r_rx, tgd=tgd, tol_s=tol_s, max_iter=max_iter)


#: columns of :func:`kepler_table` (the order of ``KeplerCols`` in insnav/gnss/broadcast_orbit.hpp)
KEPLER_TABLE_COLUMNS = ("sqrt_a", "toe", "delta_n", "m0", "e", "omega", "cus", "cuc", "crs", "crc", "cis", "cic",
                        "i0", "idot", "omega0", "omega_dot", "toe_sow", "toc", "af0", "af1", "af2")


def kepler_table(eph: Ephemerides, geo=None) -> np.ndarray:
    """(records, 22) element table of the compiled orbit code: :data:`KEPLER_TABLE_COLUMNS`, then the
    BeiDou GEO flag (``geo``, default 0)."""
    t = np.empty((len(eph), len(KEPLER_TABLE_COLUMNS) + 1))
    for j, name in enumerate(KEPLER_TABLE_COLUMNS):
        t[:, j] = getattr(eph, name)
    t[:, -1] = 0.0 if geo is None else np.asarray(geo, float)
    return t


def _transmit_states_numpy(eph: Ephemerides, idx, t_rx, r_rx, *, tgd=False, tol_s=1e-12,
                           max_iter=10) -> TransmitStates:
    """:func:`transmit_states` in numpy (the reference of the compiled code)."""
    tau = np.full(idx.shape, 0.075)
    for _ in range(max_iter):
        t_tx = t_rx - tau
        pv = sat_position_velocity(eph, idx, t_tx)
        r = rotate_earth(pv.r_e, OMEGA_E_DOT * tau)
        rng = np.linalg.norm(r - r_rx, axis=-1)
        tau_new = rng / C_LIGHT
        done = np.all(np.abs(tau_new - tau) < tol_s)
        tau = tau_new
        if done:
            break
    t_tx = t_rx - tau
    pv = sat_position_velocity(eph, idx, t_tx)
    theta = OMEGA_E_DOT * tau
    r = rotate_earth(pv.r_e, theta)
    v = rotate_earth(pv.v_e, theta)
    clk = sat_clock(eph, idx, t_tx, relativistic=True, tgd=tgd, E=pv.E, E_dot=pv.E_dot)
    rng = np.linalg.norm(r - r_rx, axis=-1)
    return TransmitStates(r, v, clk.bias_s, clk.drift_s_s, t_tx, tau, rng)


def tk_from_seconds_of_week(t_sow, toe_sow):
    """``tk`` from seconds of week with the IS-GPS-200 20.3.3.4.3 crossover rule [s]."""
    return wrap_week_seconds(np.asarray(t_sow, dtype=float) - np.asarray(toe_sow, dtype=float))
