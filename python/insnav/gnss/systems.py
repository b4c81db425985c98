"""GNSS constellations: one-letter RINEX system codes and their index.

The index is the one the C++ tight measurement uses for a satellite's system
(``SatObservation::system``): GPS is the reference clock, every other system
gets an inter-system bias state of the tight layout.

References
----------
RINEX 3.05 (IGS/RTCM RINEX WG, 2020), sec. 3.5: satellite numbers ``snn``,
``s`` = G (GPS), R (GLONASS), E (Galileo), C (BeiDou), J (QZSS), S (SBAS).
"""
from __future__ import annotations

import numpy as np

from .._median import unique

__all__ = ["SYSTEMS", "SYSTEM_NAMES", "SPP_SYSTEMS", "CLOCK_SYSTEM", "system_index", "clock_system_index", "sat_id"]

#: systems with a receiver clock of their own, in the order of their index (GPS first: the reference clock)
SYSTEMS = ("G", "R", "E", "C")
SYSTEM_NAMES = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "C": "BeiDou", "J": "QZSS"}
_INDEX = {s: k for k, s in enumerate(SYSTEMS)}
#: systems whose satellites share another system's receiver clock: QZSS uses GPS's (QZSST is steered to
#: GPST and QZSS L1 C/A, L2C, L5 are GPS's signals on GPS's frequencies, IS-QZSS-PNT 3.1.1 and 4.2; RTKLIB's
#: pntpos.c estimates no QZSS clock either)
CLOCK_SYSTEM = {"J": "G"}
#: systems single point positioning takes (the ``[gnss] systems`` letters)
SPP_SYSTEMS = SYSTEMS + tuple(CLOCK_SYSTEM)


def system_index(system) -> np.ndarray:
    """Index into :data:`SYSTEMS` of each one-letter code (array in, int array out).

    Raises ValueError naming the first unknown code.
    """
    codes = np.atleast_1d(np.asarray(system, dtype="<U1"))
    out = np.empty(codes.shape, np.int64)
    for s in unique(codes):
        if s not in _INDEX:
            raise ValueError(f"unknown GNSS system {s!r} (known: {', '.join(SYSTEMS)})")
        out[codes == s] = _INDEX[s]
    return out


def clock_system_index(system) -> np.ndarray:
    """Index into :data:`SYSTEMS` of the receiver clock of each row's system (QZSS: GPS's, :data:`CLOCK_SYSTEM`)."""
    codes = np.atleast_1d(np.asarray(system, dtype="<U1"))
    for s, clock in CLOCK_SYSTEM.items():
        codes = np.where(codes == s, clock, codes)
    return system_index(codes)


def sat_id(system, prn) -> np.ndarray:
    """RINEX satellite identifiers ``'G05'``, ``'E11'``... of (system, prn) arrays."""
    systems = np.atleast_1d(np.asarray(system, dtype="<U1"))
    prns = np.atleast_1d(np.asarray(prn, dtype=np.int64))
    return np.array([f"{s}{int(p):02d}" for s, p in zip(systems, prns)], dtype="<U3")
