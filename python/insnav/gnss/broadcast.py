"""One entry point for the broadcast states of GPS, GLONASS, Galileo, BeiDou and QZSS satellites.

:func:`transmit_states_multi` (also ``NavData.transmit_states``) is the
multi-system counterpart of :func:`insnav.gnss.ephemeris.transmit_states`,
with the same conventions (module docstring of :mod:`insnav.gnss.ephemeris`):

* input: receive time ``t_rx`` in true GPS time, an approximate receiver
  ECEF position, and the satellites as RINEX identifiers (``'G05'``,
  ``'R12'``, ``'E11'``, ``'C05'``) or as ``system``/``prn`` arrays;
* light-time iteration and Sagnac rotation: the satellite position and
  velocity at transmission are returned in the ECEF frame at reception
  (rotation by ``OMEGA_E_DOT tau`` about z for every system), so the
  geometric range is ``|r_e - r_rx_e|``;
* satellite clock at transmission, in GPS time: ``clock_bias_s`` is
  ``dt_sv`` such that ``P = |r_e - r_rx_e| + c dt_rx - c clock_bias_s + I + T``.
  It contains the relativistic term ``F e sqrt(A) sin E`` for GPS, Galileo
  and BeiDou (each system's ``F``) and none for GLONASS (already in the
  broadcast clock), and the group delay of the chosen signal (``codes``;
  :data:`GROUP_DELAY_NOTES`).  GLONASS and BeiDou clocks are relative to
  their system times (GLONASS time, BDT = GPST - 14 s already applied to the
  epochs, not the sub-microsecond system offsets): the remaining
  inter-system offsets are common to all satellites of a system and belong
  to the receiver's inter-system bias.

Ephemeris selection is at ``t_rx``: GPS and BeiDou/Galileo nearest ``toe``
inside the fit interval (4 h for Galileo/BeiDou), healthy only; Galileo from
the message whose clock matches the signal (E1: I/NAV first, then F/NAV;
E5a: F/NAV; E5b: I/NAV); GLONASS nearest ``t_b`` within 30 min.  Rows
without a usable record have ``valid = False`` and NaN states.

GPS rows are computed by :func:`insnav.gnss.ephemeris.transmit_states`
itself, so GPS results are bit-identical to the GPS-only code.  QZSS rows
(``'J01'``...) go through the same GPS functions on the QZSS table
``nav.eph_j``: the QZSS LNAV message, orbit and clock algorithms, constants
(WGS-84 mu, Earth rate, F) and time (QZSST steered to GPST) are GPS's
(IS-QZSS-PNT 4.1.2, 4.2), the geostationary QZS-3 included (unlike BeiDou
GEO).  Its group delay is T_GD as for GPS.

Observation codes (``codes``): a dict ``{system: RINEX code}`` (default
:data:`DEFAULT_CODES`) or one code per row.  Supported: GPS C1* (``- T_GD``)
and C2* (``- gamma T_GD``); GLONASS C1*/C2* (no group delay; wavelength of
the satellite's FDMA channel); Galileo C1*, C5*, C7*; BeiDou C2*/C1I/C1Q
(B1I, ``- T_GD1``), C7* (B2I, ``- T_GD2``), C6* (B3I, none).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import _core
from .._median import unique
from .ephemeris import (C_LIGHT, OMEGA_E_DOT, kepler_table, rotate_earth, sat_clock, select_ephemeris,
                        transmit_states)
from .galbds import (
    F_REL_BDS,
    F_REL_GAL,
    FREQ_HZ,
    GM_BDS,
    GM_GAL,
    OMEGA_E_BDS,
    OMEGA_E_GAL,
    galileo_clock_band,
    is_bds_geo,
    kepler_position_velocity,
)
from .glonass import (A_E_GLO, GM_GLO, J2_GLO, OMEGA_E_GLO, glonass_clock, glonass_position_velocity,
                      glonass_table, select_glonass)

__all__ = ["DEFAULT_CODES", "MultiStates", "parse_sat_ids", "signal_wavelength", "select_multi",
           "sat_states_multi", "transmit_states_multi"]

#: default observation code per system (single-frequency L1/E1/G1/B1I users)
DEFAULT_CODES = {"G": "C1C", "R": "C1C", "E": "C1C", "C": "C2I", "J": "C1C"}
#: GPS L1/L2 group delay ratio gamma = (f_L1 / f_L2)^2, IS-GPS-200 20.3.3.3.3.2
_GAMMA_GPS = (1575.42 / 1227.60) ** 2

GROUP_DELAY_NOTES = """\
GPS   C1*: -T_GD; C2*: -gamma T_GD (IS-GPS-200 20.3.3.3.3.2)
QZSS  as GPS (IS-QZSS-PNT 4.1.2.3)
GLO   none (clock refers to G1/G2 as broadcast; the L1/L2 delay difference of RINEX 3.05 is not used)
GAL   C1*: -BGD(E1,E5b) with I/NAV, -BGD(E1,E5a) with F/NAV; C5*: -(f1/f5a)^2 BGD(E1,E5a); C7*: -(f1/f5b)^2 BGD(E1,E5b)
BDS   C2*/C1I/C1Q (B1I): -T_GD1; C7* (B2I): -T_GD2; C6* (B3I): none (BDS-SIS-ICD-B1I 3.0, 5.2.4.10)
"""


class MultiStates(NamedTuple):
    """Satellite states for a set of (system, prn) rows, in GPS time; NaN where ``valid`` is False."""

    r_e: np.ndarray  #: (k, 3) position [m] (ECEF at reception for transmit states, at t for sat_states)
    v_e: np.ndarray  #: (k, 3) velocity [m/s], same frame
    clock_bias_s: np.ndarray  #: (k,) dt_sv [s]: relativistic term and the signal's group delay included
    clock_drift_s_s: np.ndarray  #: (k,) d(dt_sv)/dt [s/s]
    t_tx_gps_s: np.ndarray  #: (k,) transmit time (= t for sat_states) [s]
    tau_s: np.ndarray  #: (k,) signal travel time (0 for sat_states) [s]
    range_m: np.ndarray  #: (k,) ``|r_e - r_rx_e|`` (NaN for sat_states) [m]
    valid: np.ndarray  #: (k,) bool, a usable ephemeris record was found
    eph_idx: np.ndarray  #: (k,) row in the system's table of ``NavData`` (-1: none)
    system: np.ndarray  #: (k,) one-letter system code
    prn: np.ndarray  #: (k,) int
    wavelength_m: np.ndarray  #: (k,) carrier wavelength of the signal (GLONASS: FDMA channel) [m]
    group_delay_s: np.ndarray  #: (k,) group delay subtracted from the clock [s]

    @property
    def clock_bias_m(self) -> np.ndarray:
        """``c dt_sv`` [m]."""
        return C_LIGHT * self.clock_bias_s

    @property
    def clock_drift_mps(self) -> np.ndarray:
        """``c d(dt_sv)/dt`` [m/s]."""
        return C_LIGHT * self.clock_drift_s_s


def parse_sat_ids(sat_ids=None, system=None, prn=None):
    """(system letters, prns) from RINEX identifiers ``'G05'`` or from the two arrays."""
    if sat_ids is not None:
        ids = np.atleast_1d(np.asarray(sat_ids, dtype=str))
        sys_a = np.array([s[:1] for s in ids], dtype="<U1")
        try:
            prn_a = np.array([int(s[1:].strip()) for s in ids], dtype=np.int64)
        except ValueError:
            raise ValueError(f"satellite identifiers must look like 'G05', got {list(ids[:5])}") from None
        return sys_a, prn_a
    if system is None or prn is None:
        raise ValueError("give sat_ids or both system and prn")
    prn_a = np.atleast_1d(np.asarray(prn, dtype=np.int64))
    sys_a = np.broadcast_to(np.asarray(system, dtype="<U1"), prn_a.shape).copy()
    return sys_a, prn_a


def _codes_per_row(sys_a, codes):
    if codes is None:
        codes = DEFAULT_CODES
    if isinstance(codes, dict):
        merged = dict(DEFAULT_CODES)
        merged.update(codes)
        return np.array([merged.get(s, "") for s in sys_a], dtype="<U3")
    out = np.broadcast_to(np.asarray(codes, dtype="<U3"), sys_a.shape).copy()
    return out


def _band(system: str, code: str) -> str:
    """RINEX band digit of a code, with RINEX 3.02 BeiDou C1I/C1Q (B1I) mapped to band 2."""
    b = code[1:2]
    if system == "C" and b == "1" and code[2:3] in ("I", "Q"):
        return "2"
    return b


def _bands(system, code) -> np.ndarray:
    """:func:`_band` of every row at once: (k,) ``<U1`` band digits ('' for a code shorter than 2)."""
    sys_a = np.atleast_1d(np.asarray(system, dtype="<U1"))
    chars = np.ascontiguousarray(np.broadcast_to(np.asarray(code, dtype="<U3"), sys_a.shape)).view("<U1")
    chars = chars.reshape(sys_a.shape + (3,))
    b = chars[..., 1].copy()
    b[(sys_a == "C") & (b == "1") & ((chars[..., 2] == "I") | (chars[..., 2] == "Q"))] = "2"
    return b


def signal_wavelength(system, code, freq_k=None) -> np.ndarray:
    """Carrier wavelength [m] of each row's signal (GLONASS: FDMA channel ``freq_k``; NaN if unknown)."""
    sys_a = np.atleast_1d(np.asarray(system, dtype="<U1"))
    k = np.zeros(sys_a.shape) if freq_k is None else np.broadcast_to(np.asarray(freq_k, float), sys_a.shape)
    bands = _bands(sys_a, code)
    out = np.full(sys_a.shape, np.nan)
    glo = sys_a == "R"
    ok1 = glo & (bands == "1") & (np.abs(k) <= 20)
    ok2 = glo & (bands == "2") & (np.abs(k) <= 20)
    out[ok1] = C_LIGHT / (1602.0e6 + k[ok1] * 0.5625e6)
    out[ok2] = C_LIGHT / (1246.0e6 + k[ok2] * 0.4375e6)
    for s in unique(sys_a):  # the systems present only: two string comparisons per band otherwise
        if s == "R":
            continue
        is_s = sys_a == s
        for (s_f, b), f in FREQ_HZ.items():
            if s_f == s:
                m = is_s & (bands == b)
                if m.any():
                    out[m] = C_LIGHT / f
    return out


def _check_code(s, code):
    b = _band(s, code)
    ok = {"G": ("1", "2"), "R": ("1", "2"), "E": ("1", "5", "7"), "C": ("2", "7", "6"), "J": ("1", "2")}[s]
    if b not in ok:
        raise ValueError(f"observation code {code!r} of system {s}: no broadcast group delay model "
                         f"(supported bands {', '.join(ok)})")


def _check_codes(sys_a, code_a):
    """ValueError for a code of G/R/E/C without a group delay model (other systems: no record, invalid)."""
    for s in unique(sys_a):
        if s in "GRECJ" and len(s) == 1:
            for c in unique(code_a[sys_a == s]):
                _check_code(s, c)


def select_multi(nav, system, prn, t_gps_s, codes=None):
    """Row in ``nav``'s table of each (system, prn) at ``t_gps_s`` for the signal ``codes``; -1 if none.

    Returns
    -------
    (k,) int: index into ``nav.eph`` (G), ``nav.eph_r`` (R), ``nav.eph_e`` (E), ``nav.eph_c`` (C) or
    ``nav.eph_j`` (J).
    """
    sys_a = np.atleast_1d(np.asarray(system, dtype="<U1"))
    prn_a = np.broadcast_to(np.asarray(prn, np.int64), sys_a.shape)
    t = np.broadcast_to(np.asarray(t_gps_s, float), sys_a.shape)
    code_a = _codes_per_row(sys_a, codes)
    idx = np.full(sys_a.shape, -1, np.int64)
    for s in unique(sys_a):
        m = sys_a == s
        if s == "G":
            if len(nav.eph):
                idx[m] = select_ephemeris(nav.eph, prn_a[m], t[m])
        elif s == "R":
            if len(nav.eph_r):
                idx[m] = select_glonass(nav.eph_r, prn_a[m], t[m])
        elif s == "C":
            if len(nav.eph_c):
                idx[m] = select_ephemeris(nav.eph_c, prn_a[m], t[m])
        elif s == "J":
            if len(_eph_j(nav)):
                idx[m] = select_ephemeris(nav.eph_j, prn_a[m], t[m])
        elif s == "E":
            if not len(nav.eph_e):
                continue
            band_rec = galileo_clock_band(nav.eph_e.data_source)
            rows = np.flatnonzero(m)
            bands = _bands(np.full(rows.size, "E"), code_a[rows])
            for b_sig, prefs in (("1", (7, 5)), ("5", (5,)), ("7", (7,))):
                r = rows[bands == b_sig]
                for b_rec in prefs:
                    r = r[idx[r] < 0]
                    if r.size == 0:
                        break
                    sub_rows = np.flatnonzero(band_rec == b_rec)
                    if sub_rows.size == 0:
                        continue
                    if hasattr(_core, "select_nearest_record"):  # the subset's selection, without building it
                        e = nav.eph_e
                        usable = (np.asarray(e.health) == 0) & (band_rec == b_rec)
                        idx[r] = _core.select_nearest_record(
                            np.asarray(e.prn, np.int64), usable.astype(np.uint8), np.asarray(e.toe, float),
                            0.5 * np.asarray(e.fit_s, float) + 1e-6, np.ascontiguousarray(prn_a[r], np.int64),
                            np.ascontiguousarray(t[r], float))
                        continue
                    j = select_ephemeris(nav.eph_e.subset(sub_rows), prn_a[r], t[r])
                    idx[r] = np.where(j >= 0, sub_rows[np.maximum(j, 0)], -1)
    return idx


def _group_delay(nav, s, idx, code_a):
    """Group delay [s] of each row (system ``s``, valid ``idx``) for its code."""
    out = np.zeros(idx.shape)
    bands = _bands(np.full(len(code_a), s), code_a)
    if s == "G":
        tgd = nav.eph.tgd[idx]
        out = np.where(bands == "2", _GAMMA_GPS * tgd, tgd)
    elif s == "J":
        tgd = nav.eph_j.tgd[idx]
        out = np.where(bands == "2", _GAMMA_GPS * tgd, tgd)
    elif s == "E":
        e = nav.eph_e
        rec_band = galileo_clock_band(e.data_source[idx])
        bgd = np.where(rec_band == 5, e.tgd[idx], e.tgd2[idx])  # BGD of the record's clock pair
        f1 = FREQ_HZ[("E", "1")]
        ratio = np.where(bands == "5", (f1 / FREQ_HZ[("E", "5")]) ** 2,
                         np.where(bands == "7", (f1 / FREQ_HZ[("E", "7")]) ** 2, 1.0))
        out = ratio * bgd
    elif s == "C":
        c = nav.eph_c
        out = np.where(bands == "2", c.tgd[idx], np.where(bands == "7", c.tgd2[idx], 0.0))
    return out


def _state_at(nav, s, idx, t, relativistic=True):
    """(r_e, v_e, clock bias [s], drift [s/s]) of system ``s`` rows ``idx`` at GPS time ``t`` (ECEF at t)."""
    if s in "GJ":
        from .ephemeris import sat_position_velocity

        eph = nav.eph if s == "G" else nav.eph_j
        pv = sat_position_velocity(eph, idx, t)
        ck = sat_clock(eph, idx, t, relativistic=relativistic, E=pv.E, E_dot=pv.E_dot)
        return pv.r_e, pv.v_e, ck.bias_s, ck.drift_s_s
    if s == "R":
        r, v = glonass_position_velocity(nav.eph_r, idx, t)
        b, d = glonass_clock(nav.eph_r, idx, t)
        return r, v, b, d
    e = nav.eph_e if s == "E" else nav.eph_c
    pv = kepler_position_velocity(e, idx, t, s)
    ck = sat_clock(e, idx, t, relativistic=relativistic, E=pv.E, E_dot=pv.E_dot,
                   f_rel=F_REL_GAL if s == "E" else F_REL_BDS)
    return pv.r_e, pv.v_e, ck.bias_s, ck.drift_s_s


def _empty_states(k, sys_a, prn_a):
    nan = np.full(k, np.nan)
    return dict(r_e=np.full((k, 3), np.nan), v_e=np.full((k, 3), np.nan), clock_bias_s=nan.copy(),
                clock_drift_s_s=nan.copy(), t_tx_gps_s=nan.copy(), tau_s=nan.copy(), range_m=nan.copy(),
                valid=np.zeros(k, bool), eph_idx=np.full(k, -1, np.int64), system=sys_a, prn=prn_a,
                wavelength_m=nan.copy(), group_delay_s=np.zeros(k))


def _eph_j(nav):
    """The QZSS table of ``nav`` (empty for navigation data without one)."""
    e = getattr(nav, "eph_j", None)
    return () if e is None else e


def _wavelength_rows(nav, s, idx, code_a):
    k = nav.eph_r.freq_k[idx] if s == "R" else None
    return signal_wavelength(np.full(idx.shape, s), code_a, k)


def sat_states_multi(nav, t_gps_s, sat_ids=None, *, system=None, prn=None, codes=None, relativistic=True,
                     group_delay=True) -> MultiStates:
    """Geometric satellite states at GPS time ``t_gps_s`` (ECEF frame at that time, no light time).

    For comparisons with precise orbits/clocks use ``relativistic=False, group_delay=False``
    (SP3/CLK clocks exclude the periodic relativistic term and refer to the
    ionosphere-free combination the broadcast clocks are defined for).
    """
    sys_a, prn_a = parse_sat_ids(sat_ids, system, prn)
    k = sys_a.size
    t = np.broadcast_to(np.asarray(t_gps_s, float), (k,)).astype(float)
    code_a = _codes_per_row(sys_a, codes)
    _check_codes(sys_a, code_a)
    out = _empty_states(k, sys_a, prn_a)
    idx = select_multi(nav, sys_a, prn_a, t, code_a)
    out["eph_idx"] = idx
    out["t_tx_gps_s"] = t.copy()
    out["tau_s"] = np.zeros(k)
    for s in unique(sys_a):
        rows = np.flatnonzero((sys_a == s) & (idx >= 0))
        if rows.size == 0:
            continue
        r, v, b, d = _state_at(nav, s, idx[rows], t[rows], relativistic)
        gd = _group_delay(nav, s, idx[rows], code_a[rows]) if group_delay else np.zeros(rows.size)
        out["r_e"][rows], out["v_e"][rows] = r, v
        out["clock_bias_s"][rows], out["clock_drift_s_s"][rows] = b - gd, d
        out["group_delay_s"][rows] = gd
        out["valid"][rows] = True
        out["wavelength_m"][rows] = _wavelength_rows(nav, s, idx[rows], code_a[rows])
    return MultiStates(**out)


def transmit_states_multi(nav, t_rx_gps_s, r_rx_e, sat_ids=None, *, system=None, prn=None, codes=None,
                          group_delay=True, tol_s=1e-12, max_iter=10) -> MultiStates:
    """Light-time and Sagnac-corrected states of GPS/GLONASS/Galileo/BeiDou/QZSS satellites.

    Parameters
    ----------
    nav : insnav.gnss.NavData
        From :func:`insnav.gnss.read_rinex_nav` with the systems wanted
        (``systems="GREC"``), possibly merged (:meth:`NavData.merge`).
    t_rx_gps_s : (k,) or scalar
        Receive time, true GPS time [s] (receiver clock error removed).
    r_rx_e : (3,) or (k, 3)
        Approximate receiver ECEF position [m].
    sat_ids : (k,) str, optional
        RINEX satellite identifiers ``'G05'``, ``'R12'``...; or give ``system`` and ``prn``.
    system : (k,) or str, prn : (k,) int
    codes : dict or (k,) str, optional
        Observation code per system (default :data:`DEFAULT_CODES`) or per
        row; selects the group delay and, for Galileo, the message (I/NAV or F/NAV).
    group_delay : bool
        Subtract the signal's group delay (T_GD/BGD) from the clock.

    Returns
    -------
    MultiStates
        Position/velocity at transmission in the ECEF frame at reception,
        clock at transmission (``clock_bias_s`` [s] / ``clock_bias_m`` [m],
        relativistic term included where the system uses it), ``t_tx``,
        ``tau``, geometric range, ``valid``, ``wavelength_m`` (GLONASS: FDMA).
        GPS rows are exactly :func:`insnav.gnss.ephemeris.transmit_states` (with ``tgd``).
    """
    sys_a, prn_a = parse_sat_ids(sat_ids, system, prn)
    k = sys_a.size
    t_rx = np.broadcast_to(np.asarray(t_rx_gps_s, float), (k,)).astype(float)
    r_rx = np.broadcast_to(np.asarray(r_rx_e, float), (k, 3))
    code_a = _codes_per_row(sys_a, codes)
    _check_codes(sys_a, code_a)
    out = _empty_states(k, sys_a, prn_a)
    idx = select_multi(nav, sys_a, prn_a, t_rx, code_a)
    out["eph_idx"] = idx
    for s in unique(sys_a):
        rows = np.flatnonzero((sys_a == s) & (idx >= 0))
        if rows.size == 0:
            continue
        ii = idx[rows]
        gd = _group_delay(nav, s, ii, code_a[rows]) if group_delay else np.zeros(rows.size)
        if s == "G":
            l1 = _bands(np.full(rows.size, "G"), code_a[rows]) == "1"
            if group_delay and l1.all():  # exactly the GPS-only arithmetic (bias - T_GD)
                ts = transmit_states(nav.eph, ii, t_rx[rows], r_rx[rows], tgd=True)
                bias = ts.clock_bias_s
            else:
                ts = transmit_states(nav.eph, ii, t_rx[rows], r_rx[rows], tgd=False)
                bias = ts.clock_bias_s - gd
            r, v, drift, t_tx, tau, rng = ts.r_e, ts.v_e, ts.clock_drift_s_s, ts.t_tx_gps_s, ts.tau_s, ts.range_m
        elif s == "J":  # the GPS algorithm on the QZSS table
            ts = transmit_states(nav.eph_j, ii, t_rx[rows], r_rx[rows], tgd=False)
            bias = ts.clock_bias_s - gd
            r, v, drift, t_tx, tau, rng = ts.r_e, ts.v_e, ts.clock_drift_s_s, ts.t_tx_gps_s, ts.tau_s, ts.range_m
        elif s in "EC" and hasattr(_core, "transmit_states_kepler"):
            e = nav.eph_e if s == "E" else nav.eph_c
            gm, om, f_rel = (GM_GAL, OMEGA_E_GAL, F_REL_GAL) if s == "E" else (GM_BDS, OMEGA_E_BDS, F_REL_BDS)
            table = kepler_table(e, is_bds_geo(e.prn) if s == "C" else None)
            r, v, b, drift, t_tx, tau, rng = _core.transmit_states_kepler(table, ii, t_rx[rows], r_rx[rows], gm, om,
                                                                          f_rel, OMEGA_E_BDS, tol_s, max_iter)
            bias = b - gd
        elif s == "R" and hasattr(_core, "transmit_states_glonass"):
            # 1.5 J2 GM a_e^2 with the operations of glonass.glonass_derivatives
            j2_term = 1.5 * J2_GLO * GM_GLO * A_E_GLO**2
            r, v, b, drift, t_tx, tau, rng = _core.transmit_states_glonass(
                glonass_table(nav.eph_r), ii, t_rx[rows], r_rx[rows], GM_GLO, j2_term, OMEGA_E_GLO, 60.0, tol_s,
                max_iter)
            bias = b - gd
        else:
            tau = np.full(rows.size, 0.075)
            rr = r_rx[rows]
            for _ in range(max_iter):
                r0, _v0, _b, _d = _state_at(nav, s, ii, t_rx[rows] - tau)
                rng = np.linalg.norm(rotate_earth(r0, OMEGA_E_DOT * tau) - rr, axis=-1)
                tau_new = rng / C_LIGHT
                done = np.all(np.abs(tau_new - tau) < tol_s)
                tau = tau_new
                if done:
                    break
            t_tx = t_rx[rows] - tau
            r0, v0, b, drift = _state_at(nav, s, ii, t_tx)
            theta = OMEGA_E_DOT * tau
            r, v = rotate_earth(r0, theta), rotate_earth(v0, theta)
            rng = np.linalg.norm(r - rr, axis=-1)
            bias = b - gd
        out["r_e"][rows], out["v_e"][rows] = r, v
        out["clock_bias_s"][rows], out["clock_drift_s_s"][rows] = bias, drift
        out["t_tx_gps_s"][rows], out["tau_s"][rows], out["range_m"][rows] = t_tx, tau, rng
        out["group_delay_s"][rows] = gd
        out["valid"][rows] = True
        out["wavelength_m"][rows] = _wavelength_rows(nav, s, ii, code_a[rows])
    return MultiStates(**out)
