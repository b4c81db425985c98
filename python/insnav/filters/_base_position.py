"""The base position of an RTK run (``--base-pos``, ``[rtk] base_position_ecef_m`` /
``base_position_llh``), shared by :mod:`insnav.filters.rtk`, the command line and :func:`insnav.run`
(a module of its own: insnav.filters.rtk imports insnav.filters, whose run() reads the key too)."""
from __future__ import annotations

import numpy as np

from .. import earth
from ..config import ConfigError

__all__ = ["parse_base_position", "pop_base_position"]

_BASE_KEYS = ("base_position_ecef_m", "base_position_llh")


def parse_base_position(value, source: str = "--base-pos") -> np.ndarray:
    """ECEF [m] from ``"x,y,z"`` (ECEF metres) or ``"lat_deg,lon_deg,h_m"`` (a list or a string)."""
    try:
        v = [float(x) for x in (value.split(",") if isinstance(value, str) else value)]
    except (TypeError, ValueError):
        raise ConfigError(f"{source}: bad position {value!r}; give x,y,z [m] (ECEF) or lat_deg,lon_deg,h_m") \
            from None
    if len(v) != 3 or not np.all(np.isfinite(v)):
        raise ConfigError(f"{source}: bad position {value!r}; give three finite numbers")
    if abs(v[0]) <= 90.0 and abs(v[1]) <= 360.0 and abs(v[2]) < 1.0e5:  # geodetic
        return np.asarray(earth.geodetic_to_ecef(np.radians(v[0]), np.radians(v[1]), v[2]), float).ravel()
    if not (6.0e6 < np.linalg.norm(v) < 7.0e6):
        raise ConfigError(f"{source}: position {value!r} is neither ECEF (|r| near 6371 km) nor lat,lon,h")
    return np.asarray(v, float)


def pop_base_position(t: dict, source: str | None) -> tuple:
    """(ECEF [m] or None, where it came from or None): the base position key of the ``[rtk]`` table
    ``t`` (a dict, the key removed); both keys given is a one-line ConfigError naming them."""
    given = [k for k in _BASE_KEYS if k in t]
    where = f"{source}: " if source else ""
    if len(given) > 1:  # the latitude/longitude silently won before
        raise ConfigError(f"{where}keys 'rtk.{given[0]}' and 'rtk.{given[1]}' both given; keep one "
                          "(the base antenna reference point)")
    if not given:
        return None, None
    key = f"{where}key 'rtk.{given[0]}'"
    return parse_base_position(t.pop(given[0]), key), key
