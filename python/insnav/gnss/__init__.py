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
import importlib

# public name -> submodule that defines it, loaded on first access (PEP 562): a command
# imports only the modules it runs (the RTK command reads RINEX and computes orbits; it
# does not load the simulator's Constellation)
_LAZY = {
    "Constellation": "constellation", "SatStates": "constellation",
    "Ephemerides": "ephemeris", "sat_clock": "ephemeris", "sat_position_velocity": "ephemeris",
    "select_ephemeris": "ephemeris", "transmit_states": "ephemeris",
    "NavData": "rinex", "ObsData": "rinex", "RinexError": "rinex", "read_rinex_nav": "rinex",
    "read_rinex_obs": "rinex",
    "MultiStates": "broadcast", "sat_states_multi": "broadcast", "transmit_states_multi": "broadcast",
}
#: the submodules this package used to import eagerly: ``insnav.gnss.rinex`` etc. stay
#: reachable as attributes after a bare ``import insnav.gnss``
_SUBMODULES = ("constellation", "ephemeris", "rinex", "broadcast", "gpstime", "glonass", "galbds")

__all__ = [
    "Constellation", "SatStates", "Ephemerides", "sat_clock", "sat_position_velocity",
    "select_ephemeris", "transmit_states", "NavData", "ObsData", "RinexError",
    "read_rinex_nav", "read_rinex_obs", "MultiStates", "sat_states_multi", "transmit_states_multi",
]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(f"{__name__}.{name}")
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__) | set(_SUBMODULES))
