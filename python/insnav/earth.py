"""WGS-84 Earth model, vectorised over NumPy arrays.

Frames: ``e`` = ECEF (WGS-84), ``n`` = local North-East-Down.  SI units:
latitude/longitude in rad, heights in m (above the ellipsoid).

This mirrors ``cpp/include/insnav/earth/wgs84.hpp`` (the C++ core used in the
hot path); ``tests/test_earth.py`` checks that both agree.

References
----------
NIMA TR8350.2, *Department of Defense World Geodetic System 1984*, 3rd ed.
P. D. Groves, *Principles of GNSS, Inertial, and Multisensor Integrated
Navigation Systems*, 2nd ed., ch. 2.
"""
from __future__ import annotations

import numpy as np

#: Semi-major axis [m].
A = 6378137.0
#: Flattening [-].
F = 1.0 / 298.257223563
#: Semi-minor axis [m].
B = A * (1.0 - F)
#: First eccentricity squared [-].
E2 = F * (2.0 - F)
#: Earth rotation rate [rad/s].
OMEGA_IE = 7.292115e-5
#: Earth gravitational constant GM [m^3/s^2].
GM = 3.986004418e14
#: Somigliana normal gravity at the equator and the pole [m/s^2].
GAMMA_E = 9.7803253359
GAMMA_P = 9.8321849378
#: Somigliana constant k = (b*gamma_p)/(a*gamma_e) - 1.
SOMIGLIANA_K = 0.00193185265241
#: m = omega^2 a^2 b / GM.
M_RATIO = OMEGA_IE**2 * A**2 * B / GM



def radii(lat):
    """Meridian and prime-vertical radii of curvature.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude [rad].

    Returns
    -------
    R_M, R_N : ndarray
        Meridian (north-south) and prime-vertical (east-west) radii [m].
    """
    s2 = np.sin(lat) ** 2
    w = 1.0 - E2 * s2
    R_N = A / np.sqrt(w)
    R_M = R_N * (1.0 - E2) / w
    return R_M, R_N


def gravity(lat, h):
    """Normal gravity magnitude, Somigliana with the second-order height term.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude [rad].
    h : array_like
        Height above the ellipsoid [m].

    Returns
    -------
    ndarray
        Normal gravity [m/s^2], positive down (the NED gravity vector is
        ``[0, 0, g]``).
    """
    s2 = np.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / np.sqrt(1.0 - E2 * s2)
    return g0 * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h * h / (A * A))


def omega_ie_n(lat):
    """Earth rotation rate in NED [rad/s], shape ``(..., 3)``."""
    lat = np.asarray(lat, dtype=float)
    z = np.zeros_like(lat)
    return np.stack([OMEGA_IE * np.cos(lat), z, -OMEGA_IE * np.sin(lat)], axis=-1)


def omega_en_n(lat, h, v_n):
    """Transport rate (rotation of NED relative to ECEF) in NED [rad/s].

    Parameters
    ----------
    lat, h : array_like
        Latitude [rad] and height [m].
    v_n : array_like, shape (..., 3)
        Velocity relative to the Earth in NED [m/s].
    """
    v_n = np.asarray(v_n, dtype=float)
    R_M, R_N = radii(lat)
    vN, vE = v_n[..., 0], v_n[..., 1]
    return np.stack(
        [vE / (R_N + h), -vN / (R_M + h), -vE * np.tan(lat) / (R_N + h)], axis=-1
    )


def geodetic_to_ecef(lat, lon, h):
    """Geodetic (lat [rad], lon [rad], h [m]) to ECEF position ``r_e`` [m], shape ``(..., 3)``."""
    lat = np.asarray(lat, dtype=float)
    _, R_N = radii(lat)
    cl = np.cos(lat)
    return np.stack(
        [
            (R_N + h) * cl * np.cos(lon),
            (R_N + h) * cl * np.sin(lon),
            (R_N * (1.0 - E2) + h) * np.sin(lat),
        ],
        axis=-1,
    )


def ecef_to_geodetic(r_e):
    """ECEF position [m], shape ``(..., 3)``, to geodetic ``(lat, lon, h)`` [rad, rad, m].

    Fixed-point iteration on latitude written so that it stays well
    conditioned at the poles (height from ``p cos(lat) + z sin(lat) - a^2/N``
    rather than ``p / cos(lat) - N``).  Converges to < 1e-9 m for heights
    from -1e4 m to 1e7 m.
    """
    r_e = np.asarray(r_e, dtype=float)
    x, y, z = r_e[..., 0], r_e[..., 1], r_e[..., 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, p * (1.0 - E2))
    for _ in range(8):
        s, c = np.sin(lat), np.cos(lat)
        N = A / np.sqrt(1.0 - E2 * s * s)
        h = p * c + z * s - A * A / N
        lat = np.arctan2(z, p * (1.0 - E2 * N / (N + h)))
    s, c = np.sin(lat), np.cos(lat)
    N = A / np.sqrt(1.0 - E2 * s * s)
    h = p * c + z * s - A * A / N
    return lat, lon, h


def C_en(lat, lon):
    """DCM from NED to ECEF, ``r_e = C_en @ r_n``; shape ``(..., 3, 3)``."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    C = np.empty(np.broadcast(lat, lon).shape + (3, 3))
    C[..., 0, 0] = -sl * co
    C[..., 0, 1] = -so
    C[..., 0, 2] = -cl * co
    C[..., 1, 0] = -sl * so
    C[..., 1, 1] = co
    C[..., 1, 2] = -cl * so
    C[..., 2, 0] = cl
    C[..., 2, 1] = 0.0
    C[..., 2, 2] = -sl
    return C


def ned_to_ecef_vector(lat, lon, v_n):
    """Rotate NED vectors into ECEF: ``v_e = C_en v_n``."""
    return np.einsum("...ij,...j->...i", C_en(lat, lon), np.asarray(v_n, dtype=float))


def ecef_to_ned_vector(lat, lon, v_e):
    """Rotate ECEF vectors into NED: ``v_n = C_en^T v_e``."""
    return np.einsum("...ji,...j->...i", C_en(lat, lon), np.asarray(v_e, dtype=float))
