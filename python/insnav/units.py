"""Unit conversion factors (multiply a value in the named unit to get SI) and angle wrapping.

The only definitions in the package (``insnav`` is SI inside; units appear
at the edges: files, configs, printed tables).  ``RAD2DEG`` goes the other way.
"""
from __future__ import annotations

import math

DEG = math.pi / 180.0                #: deg -> rad
RAD2DEG = 180.0 / math.pi            #: rad -> deg
HOUR = 3600.0                        #: h -> s
G0 = 9.80665                         #: standard gravity, defines mg and ug [m/s^2]
MG = 1e-3 * G0                       #: mg -> m/s^2
DEG_PER_H = DEG / HOUR               #: deg/h -> rad/s
DEG_PER_SQRT_H = DEG / 60.0          #: deg/sqrt(h) -> rad/sqrt(s)
MPS_PER_SQRT_H = 1.0 / 60.0          #: (m/s)/sqrt(h) -> (m/s)/sqrt(s)
UG_PER_SQRT_HZ = 1e-6 * G0           #: ug/sqrt(Hz) -> (m/s^2)/sqrt(Hz) = (m/s)/sqrt(s)
PPM = 1e-6                           #: ppm -> [-]



def wrap_deg(a):
    """Wrap angles [deg] to (-180, 180]."""
    import numpy as np

    return -np.mod(-np.asarray(a, float) + 180.0, 360.0) + 180.0


__all__ = ["wrap_deg", "DEG", "RAD2DEG", "HOUR", "G0", "MG", "DEG_PER_H", "DEG_PER_SQRT_H", "MPS_PER_SQRT_H",
           "UG_PER_SQRT_HZ", "PPM"]
