"""Galileo and BeiDou broadcast ephemerides (Kepler elements, like GPS LNAV).

Both systems broadcast the 16 quasi-Keplerian elements of IS-GPS-200 Table
20-IV; :func:`insnav.gnss.ephemeris.sat_position_velocity` is evaluated with
each system's constants:

==========  ======================  ======================  ===================
system      GM [m^3/s^2]            Omega_e [rad/s]         F [s/sqrt(m)]
==========  ======================  ======================  ===================
Galileo     3.986004418e14          7.2921151467e-5         -4.442807309e-10
BeiDou      3.986004418e14          7.2921150e-5            -4.442807309e-10
==========  ======================  ======================  ===================

(Galileo OS SIS ICD 2.1, Table 58 and 5.1.4; BDS-SIS-ICD-B1I 3.0, 5.2.4.10
and 5.2.4.12.)

Time
----
* Galileo System Time is steered to GPS time (the GGTO offset of a few ns is
  not applied: it is common to all Galileo satellites and goes into the
  inter-system bias).  The GST week counts from 1999-08-22 (GPS week 1024);
  RINEX already gives the week aligned with the GPS week.  ``toe`` is
  resolved against ``toc`` to the nearest week either way.
* BeiDou Time: BDT = GPST - 14 s, BDT week 0 = GPS week 1356 (2006-01-01).
  ``toc``/``toe`` are stored as continuous GPS seconds; ``toe_sow`` keeps the
  broadcast BDT seconds of week (it enters the node longitude term).

BeiDou GEO satellites (PRN 1-5 and 59-63) use the special transformation of
BDS-SIS-ICD-B1I 3.0, 5.2.4.12 (Table 5-11): the orbit is computed in an
inertial-like frame with ``Omega_k = Omega_0 + Omega_dot t_k - Omega_e t_oe``,
then rotated by ``R_X(-5 deg)`` and ``R_Z(Omega_e t_k)`` (:func:`bds_geo_position_velocity`;
velocity is the analytic derivative).

Group delays (single-frequency users; subtract from the clock offset)
---------------------------------------------------------------------
* Galileo: the clock of an I/NAV record is the E1/E5b dual-frequency clock,
  of an F/NAV record the E1/E5a clock (RINEX "data sources" bits 9 / 8).
  E1: ``- BGD(E1,E5b)`` (I/NAV) or ``- BGD(E1,E5a)`` (F/NAV); E5a: ``-
  (f_E1/f_E5a)^2 BGD(E1,E5a)``; E5b: ``- (f_E1/f_E5b)^2 BGD(E1,E5b)``
  (OS SIS ICD 2.1, 5.1.5).  E1 users prefer I/NAV records.
* BeiDou D1/D2 clocks refer to B3I: B1I ``- T_GD1``, B2I ``- T_GD2``, B3I
  none (BDS-SIS-ICD-B1I 3.0, 5.2.4.10).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .ephemeris import Ephemerides, SatPosVel, sat_position_velocity

__all__ = ["GM_GAL", "OMEGA_E_GAL", "F_REL_GAL", "GM_BDS", "OMEGA_E_BDS", "F_REL_BDS", "BDT_GPST_OFFSET_S",
           "BDT_WEEK_OFFSET", "GST_WEEK_OFFSET", "KeplerEphemerides", "is_bds_geo", "bds_geo_position_velocity",
           "kepler_position_velocity", "galileo_clock_band", "FREQ_HZ"]

GM_GAL = 3.986004418e14
OMEGA_E_GAL = 7.2921151467e-5
F_REL_GAL = -4.442807309e-10
GM_BDS = 3.986004418e14
OMEGA_E_BDS = 7.2921150e-5
F_REL_BDS = -4.442807309e-10
#: GPST - BDT [s] (BDS-SIS-ICD-B1I 3.0, 4.2)
BDT_GPST_OFFSET_S = 14.0
#: GPS week of BDT week 0 (2006-01-01)
BDT_WEEK_OFFSET = 1356
#: GPS week of GST week 0 (1999-08-22)
GST_WEEK_OFFSET = 1024
#: inclination of the GEO transformation, BDS ICD 5.2.4.12 [rad]
_GEO_TILT = np.deg2rad(-5.0)

#: carrier frequencies [Hz] by (system, RINEX band digit)
FREQ_HZ = {
    ("G", "1"): 1575.42e6, ("G", "2"): 1227.60e6, ("G", "5"): 1176.45e6,
    ("E", "1"): 1575.42e6, ("E", "5"): 1176.45e6, ("E", "7"): 1207.14e6, ("E", "8"): 1191.795e6,
    ("E", "6"): 1278.75e6,
    ("C", "2"): 1561.098e6, ("C", "7"): 1207.14e6, ("C", "6"): 1268.52e6, ("C", "1"): 1575.42e6,
    ("C", "5"): 1176.45e6,
    # QZSS L1/L2/L5 as GPS (IS-QZSS-PNT 3.1.1)
    ("J", "1"): 1575.42e6, ("J", "2"): 1227.60e6, ("J", "5"): 1176.45e6,
}


@dataclass
class KeplerEphemerides(Ephemerides):
    """Galileo or BeiDou records: the GPS fields plus the second group delay and the data source.

    The attributes below are in addition to those of :class:`insnav.gnss.ephemeris.Ephemerides`.

    Attributes
    ----------
    tgd : Galileo BGD(E1,E5a) [s]; BeiDou T_GD1 (B1I) [s]
    tgd2 : Galileo BGD(E1,E5b) [s]; BeiDou T_GD2 (B2I) [s]
    data_source : Galileo RINEX "data sources" bit field (0 for BeiDou)
    iode : Galileo IODnav; BeiDou AODE
    iodc : BeiDou AODC (0 for Galileo)
    toc, toe : GPS seconds since 1980-01-06 (converted from GST / BDT)
    toe_sow : broadcast t_oe in seconds of the system's week [s]
    """

    tgd2: np.ndarray
    data_source: np.ndarray

    @classmethod
    def from_columns(cls, cols: dict) -> "KeplerEphemerides":
        return cls(**{f.name: cols[f.name] for f in fields(cls)})

    @classmethod
    def empty(cls) -> "KeplerEphemerides":
        return cls(**{f.name: np.zeros(0) for f in fields(cls)})

    def to_columns(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def subset(self, idx) -> "KeplerEphemerides":
        return KeplerEphemerides(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    def concat(self, other: "KeplerEphemerides") -> "KeplerEphemerides":
        return KeplerEphemerides(**{f.name: np.concatenate([getattr(self, f.name), getattr(other, f.name)])
                                    for f in fields(self)})


def is_bds_geo(prn) -> np.ndarray:
    """True for BeiDou GEO satellites: PRN 1-5 and 59-63 (BDS-SIS-ICD-B1I 3.0, 5.2.4.12)."""
    p = np.asarray(prn)
    return ((p >= 1) & (p <= 5)) | ((p >= 59) & (p <= 63))


def bds_geo_position_velocity(eph: KeplerEphemerides, idx, t_gps_s) -> SatPosVel:
    """BeiDou GEO position/velocity, BDS-SIS-ICD-B1I 3.0 Table 5-11.

    ``X_K = R_Z(Omega_e t_k) R_X(-5 deg) X_GK`` with ``X_GK`` the Kepler
    position for ``Omega_k = Omega_0 + Omega_dot t_k - Omega_e t_oe`` (no
    ``- Omega_e t_k``: an inertial-like frame), ``R_X(phi) = [[1,0,0],[0,c,s],[0,-s,c]]``,
    ``R_Z(phi) = [[c,s,0],[-s,c,0],[0,0,1]]``.  Velocity:
    ``V_K = R_Z R_X V_GK + Omega_e [Y_K, -X_K, 0]`` (derivative of ``R_Z``).
    """
    idx = np.atleast_1d(np.asarray(idx, np.int64))
    t = np.broadcast_to(np.asarray(t_gps_s, float), idx.shape)
    sub = eph.subset(idx)
    # fold - Omega_e t_oe into Omega_0 and evaluate with omega_e = 0: the node is then
    # Omega_0 + Omega_dot t_k - Omega_e t_oe and its rate Omega_dot (the GK frame)
    sub.omega0 = sub.omega0 - OMEGA_E_BDS * sub.toe_sow
    pv = sat_position_velocity(sub, np.arange(idx.size), t, gm=GM_BDS, omega_e=0.0)
    tk = t - sub.toe
    cx, sx = np.cos(_GEO_TILT), np.sin(_GEO_TILT)
    th = OMEGA_E_BDS * tk
    cz, sz = np.cos(th), np.sin(th)

    def rot(v):
        w0, w1, w2 = v[:, 0], cx * v[:, 1] + sx * v[:, 2], -sx * v[:, 1] + cx * v[:, 2]
        return np.stack([cz * w0 + sz * w1, -sz * w0 + cz * w1, w2], -1)

    r = rot(pv.r_e)
    v = rot(pv.v_e)
    v[:, 0] += OMEGA_E_BDS * r[:, 1]
    v[:, 1] -= OMEGA_E_BDS * r[:, 0]
    return SatPosVel(r, v, pv.E, pv.E_dot)


def kepler_position_velocity(eph: KeplerEphemerides, idx, t_gps_s, system: str) -> SatPosVel:
    """ECEF position/velocity of Galileo (``system='E'``) or BeiDou (``'C'``, GEO handled) records."""
    idx = np.atleast_1d(np.asarray(idx, np.int64))
    t = np.broadcast_to(np.asarray(t_gps_s, float), idx.shape)
    if system == "E":
        return sat_position_velocity(eph, idx, t, gm=GM_GAL, omega_e=OMEGA_E_GAL)
    if system != "C":
        raise ValueError(f"kepler_position_velocity: system {system!r} is not Galileo or BeiDou")
    out = sat_position_velocity(eph, idx, t, gm=GM_BDS, omega_e=OMEGA_E_BDS)
    geo = is_bds_geo(eph.prn[idx])
    if geo.any():
        g = bds_geo_position_velocity(eph, idx[geo], t[geo])
        out.r_e[geo], out.v_e[geo], out.E[geo], out.E_dot[geo] = g.r_e, g.v_e, g.E, g.E_dot
    return out


def galileo_clock_band(data_source) -> np.ndarray:
    """Second frequency of a Galileo record's clock: 7 (E1/E5b: I/NAV, bit 9), 5 (E1/E5a: F/NAV, bit 8).

    Files without bits 8/9 (RINEX 3.02) fall back on the message: I/NAV (bits 0, 2) -> 7, F/NAV (bit 1) -> 5.
    """
    ds = np.asarray(data_source, float)
    ds = np.where(np.isfinite(ds), ds, 0).astype(np.int64)
    band = np.where(ds & 512, 7, np.where(ds & 256, 5, np.where(ds & 5, 7, np.where(ds & 2, 5, 7))))
    return band.astype(np.int64)
