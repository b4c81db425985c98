"""GNSS geometry for insnav (pure NumPy/SciPy).

Python owns the GNSS geometry; the C++ filters receive per-epoch arrays.

Modules
-------
gpstime       GPS seconds since 1980-01-06 <-> calendar, week/seconds of week
rinex         RINEX 2.x/3.x nav (G, R, E, C) and observation readers (:class:`RinexError`)
ephemeris     IS-GPS-200 LNAV orbit/clock, ephemeris selection, transmit-time solver
glonass       GLONASS FDMA state-vector RK4 orbit, clock, FDMA frequencies, leap seconds
galbds        Galileo / BeiDou Kepler constants, BeiDou GEO transform, group delays
broadcast     one multi-system entry point: :func:`transmit_states_multi`, :func:`sat_states_multi`
sp3           SP3-c/d orbits (Lagrange interpolation) and RINEX clock files
geometry      elevation/azimuth, masks, line of sight, DOP, best-GDOP subset
corrections   Klobuchar ionosphere, Saastamoinen troposphere
constellation :class:`Constellation` (broadcast or nominal) for the simulator
"""
from .constellation import Constellation, SatStates
from .ephemeris import (
    Ephemerides,
    sat_clock,
    sat_position_velocity,
    select_ephemeris,
    transmit_states,
)
from .rinex import NavData, ObsData, RinexError, read_rinex_nav, read_rinex_obs
from .broadcast import MultiStates, sat_states_multi, transmit_states_multi

__all__ = [
    "Constellation", "SatStates", "Ephemerides", "sat_clock", "sat_position_velocity",
    "select_ephemeris", "transmit_states", "NavData", "ObsData", "RinexError",
    "read_rinex_nav", "read_rinex_obs", "MultiStates", "sat_states_multi", "transmit_states_multi",
]
