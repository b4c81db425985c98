"""Nominal Galileo and BeiDou MEO constellations for the simulator: Walker
delta patterns written as broadcast-style (LNAV-form) element sets, so that
:class:`insnav.gnss.constellation.Constellation` and
:func:`insnav.gnss.ephemeris.transmit_states` evaluate them like the GPS
nominal set (circular orbits: ``e = 0``, no harmonic corrections, no
``IDOT``; ``OMEGA_DOT`` the J2 node regression).

Walker delta T/P/F (Walker 1984, "Satellite constellations", J. British
Interplanetary Society 37:559-572): ``T`` satellites in ``P`` planes of
equal inclination; plane ``p`` has right ascension ``2 pi p / P``, satellite
``s`` of it the argument of latitude ``2 pi s / (T/P) + 2 pi F p / T``.

* Galileo: Walker 24/3/1, a = 29 600 km, i = 56 deg (Galileo OS SIS ICD
  issue 2.0, 2021, sec. 5.1 / the reference constellation of the Galileo
  programme); PRN E01-E24.
* BeiDou-3 MEO: Walker 24/3/1, a = 21 528 km, i = 55 deg (BeiDou ICD B1C
  3.0, 2019, sec. 3 "space constellation"); PRN C19-C42 (the BDS-3 MEO
  range; the GEO/IGSO satellites are left out).

The broadcast orbit model is evaluated with the GPS constants (IS-GPS-200
Table 20-IV) for every system; the simulator hands the filter the
satellite states it computed, so the small differences of the Galileo/BeiDou
constants do not enter any comparison.  Plane phases are offset per system
(``RAAN0_RAD``) so that the three constellations do not share planes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["WALKER", "walker_elements", "walker_constellation"]

_MU = 3.986005e14          # IS-GPS-200 [m^3/s^2]
_J2 = 1.0826269e-3
_RE = 6378137.0

#: system letter -> (T, P, F, semi-major axis [m], inclination [deg], first PRN, RAAN offset [rad])
WALKER = {
    "E": (24, 3, 1, 29_600e3, 56.0, 1, 0.35),
    "C": (24, 3, 1, 21_528e3, 55.0, 19, 1.2),
}


def walker_elements(system: str, template: dict, t_ref_gps_s: float) -> dict:
    """LNAV-form element columns of the Walker constellation of ``system``.

    Parameters
    ----------
    system : {"E", "C"}
    template : dict
        Columns of any Ephemerides (``to_columns()``); only the field names and
        the dtype of ``prn`` are taken, so a table with more fields works too.
    t_ref_gps_s : float
        ``toe``/``toc`` [GPS s since 1980-01-06]; the elements hold at that time.
    """
    if system not in WALKER:
        raise ValueError(f"no nominal Walker constellation for system {system!r} (known: {', '.join(WALKER)})")
    T, P, F, a, inc_deg, prn0, raan0 = WALKER[system]
    inc = np.deg2rad(inc_deg)
    n_sat = T // P
    p = np.repeat(np.arange(P), n_sat)
    s = np.tile(np.arange(n_sat), P)
    u = 2 * np.pi * s / n_sat + 2 * np.pi * F * p / T          # argument of latitude at toe
    n0 = np.sqrt(_MU / a ** 3)
    raan_dot = -1.5 * n0 * _J2 * (_RE / a) ** 2 * np.cos(inc)  # J2 node regression [rad/s]
    cols = {}
    for k, v in template.items():
        cols[k] = np.zeros(T, dtype=np.asarray(v).dtype if np.asarray(v).dtype.kind in "iub" else float)
    toe_sow = float(np.mod(t_ref_gps_s, 604800.0))
    cols.update(prn=np.arange(prn0, prn0 + T).astype(np.asarray(template["prn"]).dtype), toc=np.full(T, t_ref_gps_s),
                toe=np.full(T, t_ref_gps_s), toe_sow=np.full(T, toe_sow), sqrt_a=np.full(T, np.sqrt(a)),
                e=np.zeros(T), i0=np.full(T, inc), m0=np.mod(u + np.pi, 2 * np.pi) - np.pi, omega=np.zeros(T),
                omega0=np.mod(raan0 + 2 * np.pi * p / P + np.pi, 2 * np.pi) - np.pi,
                omega_dot=np.full(T, raan_dot), week=np.full(T, np.floor(t_ref_gps_s / 604800.0)),
                af0=1e-5 * np.sin(np.arange(T) * 1.7 + prn0), af1=np.zeros(T), af2=np.zeros(T),
                fit_s=np.full(T, 14400.0), sv_accuracy=np.full(T, 2.0), health=np.zeros(T))
    if "system" in cols:  # a table that carries the system letter (multi-system ephemerides)
        cols["system"] = np.full(T, system)
    return cols


def walker_constellation(system: str, t0_gps_s: float):
    """Nominal Walker :class:`~insnav.gnss.constellation.Constellation` of ``system`` ("E" or "C")
    with its elements at ``t0_gps_s`` (no validity window, like the GPS nominal set)."""
    from .constellation import Constellation
    from .ephemeris import Ephemerides

    template = Constellation.nominal(t0_gps_s=t0_gps_s).eph.to_columns()
    return Constellation(Ephemerides.from_columns(walker_elements(system, template, float(t0_gps_s))),
                         nominal=True)
