"""Atmospheric delay models for single-frequency GPS L1: Klobuchar and Saastamoinen.

Both return a delay in metres that *adds* to the geometric range in the
pseudorange model ``P = rho + c dt_rx - c dt_sv + I + T``.
"""
from __future__ import annotations

import numpy as np

from .ephemeris import C_LIGHT

__all__ = ["KLOBUCHAR_DEFAULT_ALPHA", "KLOBUCHAR_DEFAULT_BETA", "klobuchar_coefficients", "klobuchar_delay",
           "saastamoinen_delay", "standard_atmosphere"]

#: Klobuchar coefficients used when a navigation file broadcasts none: the GPS broadcast of 2004-01-01,
#: RTKLIB's ``ion_default`` (rtkcmn.c ``ionmodel``), alpha_n [s/semicircle^n], beta_n [s/semicircle^n].
KLOBUCHAR_DEFAULT_ALPHA = (0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06)
KLOBUCHAR_DEFAULT_BETA = (0.1167e+06, -0.2294e+06, -0.1311e+06, 0.1049e+07)


def klobuchar_coefficients(nav):
    """The Klobuchar coefficients of ``nav`` (``ion_alpha``, ``ion_beta``), or the defaults.

    A navigation file without ``IONOSPHERIC CORR GPSA/GPSB`` (RINEX 3) or ``ION ALPHA/BETA`` (RINEX 2), or
    with all eight zero, gets :data:`KLOBUCHAR_DEFAULT_ALPHA` / :data:`KLOBUCHAR_DEFAULT_BETA` (as RTKLIB
    does) and an :class:`insnav.errors.InsnavWarning` naming the file: leaving the ionosphere out would bias
    every pseudorange by its 2-30 m delay.

    Returns
    -------
    alpha, beta : ndarray (4,)
    default : bool
        True when the defaults stand in.
    """
    alpha, beta = getattr(nav, "ion_alpha", None), getattr(nav, "ion_beta", None)
    if alpha is not None and beta is not None and (np.any(np.asarray(alpha) != 0) or np.any(np.asarray(beta) != 0)):
        return np.asarray(alpha, float), np.asarray(beta, float), False
    import warnings

    from ..errors import InsnavWarning

    warnings.warn(f"{getattr(nav, 'path', 'the navigation data')}: no Klobuchar coefficients (IONOSPHERIC CORR "
                  "GPSA/GPSB or ION ALPHA/BETA); the ionosphere is modelled with the defaults of RTKLIB "
                  "(the broadcast of 2004-01-01)", InsnavWarning, stacklevel=3)
    return np.array(KLOBUCHAR_DEFAULT_ALPHA), np.array(KLOBUCHAR_DEFAULT_BETA), True


def klobuchar_delay(t_gps_s, lat, lon, el, az, alpha, beta):
    """GPS L1 ionospheric group delay, Klobuchar model, IS-GPS-200 20.3.3.5.2.5 (Figure 20-4).

    Parameters
    ----------
    t_gps_s : array_like
        GPS time of reception [s] (since 1980-01-06, or seconds of week;
        only the time of day matters).
    lat, lon : array_like
        Receiver geodetic latitude and longitude [rad].
    el, az : array_like
        Satellite elevation and azimuth [rad].
    alpha, beta : array_like, shape (4,)
        Broadcast coefficients alpha_n [s/semicircle^n] and beta_n
        [s/semicircle^n] (RINEX ``ION ALPHA``/``ION BETA`` or ``GPSA``/``GPSB``).

    Returns
    -------
    ndarray
        Delay on L1 [m].  Physical range: the vertical delay is at least
        5 ns (1.5 m), times the obliquity factor F in [1, 3.08]: between about
        1.5 m and about 150 m for any coefficients a real broadcast uses
        (typically 2-30 m).

    Notes
    -----
    Follows Figure 20-4 literally, in semicircles: earth-centred angle
    ``psi = 0.0137/(E + 0.11) - 0.022``; ionospheric pierce point latitude
    clipped to +/-0.416; geomagnetic latitude ``phi_m = phi_i + 0.064
    cos(lambda_i - 1.617)``; local time ``t = 4.32e4 lambda_i + t_GPS`` mod
    86400; ``F = 1 + 16 (0.53 - E)^3``; amplitude and period clipped at 0
    and 72000 s; ``T_iono = F (5e-9 + AMP (1 - x^2/2 + x^4/24))`` for
    ``|x| < 1.57``, else ``F 5e-9``.
    """
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    E = np.asarray(el, dtype=float) / np.pi  # semicircles
    A = np.asarray(az, dtype=float)
    phi_u = np.asarray(lat, dtype=float) / np.pi
    lam_u = np.asarray(lon, dtype=float) / np.pi
    psi = 0.0137 / (E + 0.11) - 0.022
    phi_i = np.clip(phi_u + psi * np.cos(A), -0.416, 0.416)
    lam_i = lam_u + psi * np.sin(A) / np.cos(phi_i * np.pi)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * np.pi)
    t = np.mod(4.32e4 * lam_i + np.asarray(t_gps_s, dtype=float), 86400.0)
    F = 1.0 + 16.0 * (0.53 - E) ** 3
    pm = phi_m[..., None] ** np.arange(4)
    amp = np.maximum(np.sum(alpha * pm, axis=-1), 0.0)
    per = np.maximum(np.sum(beta * pm, axis=-1), 72000.0)
    x = 2.0 * np.pi * (t - 50400.0) / per
    night = 5.0e-9
    day = night + amp * (1.0 - x * x / 2.0 + x**4 / 24.0)
    T = F * np.where(np.abs(x) < 1.57, day, night)
    return C_LIGHT * T


def standard_atmosphere(h, humidity=0.7):
    """Pressure [hPa], temperature [K] and water-vapour pressure [hPa] of a standard atmosphere.

    ``P = 1013.25 (1 - 2.2557e-5 h)^5.2568``, ``T = 288.15 - 6.5e-3 h``,
    ``e = 6.108 RH exp((17.15 T - 4684)/(T - 38.45))`` (as in RTKLIB
    ``tropmodel``; Berg 1948 lapse model, Magnus-type saturation pressure).
    Heights are clipped to [0, 11000] m.
    """
    h = np.clip(np.asarray(h, dtype=float), 0.0, 11000.0)
    P = 1013.25 * (1.0 - 2.2557e-5 * h) ** 5.2568
    T = 288.15 - 6.5e-3 * h
    e = 6.108 * humidity * np.exp((17.15 * T - 4684.0) / (T - 38.45))
    return P, T, e


#: Saastamoinen (1973) correction term B [hPa] as a function of station height [km].
_SAAST_B_H_KM = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0])
_SAAST_B_HPA = np.array([1.156, 1.079, 1.006, 0.938, 0.874, 0.813, 0.757, 0.654, 0.563])


def saastamoinen_delay(lat, h, el, *, humidity=0.7, pressure_hpa=None, temperature_k=None, b_term=True):
    """Tropospheric slant delay, Saastamoinen model with a standard atmosphere.

    ``T = 0.002277 / cos z [P / D + (1255/T + 0.05) e - B tan^2 z]``,
    ``z = pi/2 - el``, ``D = 1 - 0.00266 cos 2phi - 0.00028 h_km`` (the
    gravity factor of Davis et al. 1985; the constant becomes 0.0022768 in
    the hydrostatic term), ``B(h)`` from Saastamoinen's table (1.156 hPa at
    sea level).  The small ``delta R`` term (< 0.13 m above 10 deg) is not
    applied.  ``b_term=False`` gives the RTKLIB ``tropmodel`` form (no
    ``B tan^2 z``), which is 0.5 m too large at 5 deg elevation.

    References: J. Saastamoinen, "Atmospheric correction for the troposphere
    and stratosphere in radio ranging of satellites", Geophysical Monograph
    15, AGU, 1972, and Bull. Geod. 107, 1973; J. L. Davis et al., Radio
    Science 20(6), 1985.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude [rad].
    h : array_like
        Ellipsoidal height [m] (used as orthometric; the geoid undulation
        of at most ~100 m changes the delay by < 3 cm).
    el : array_like
        Elevation [rad]; values <= 0 give NaN.
    humidity : float
        Relative humidity [0..1] of the standard atmosphere.
    pressure_hpa, temperature_k : array_like, optional
        Override the standard-atmosphere pressure [hPa] / temperature [K].
    b_term : bool
        Include ``- B tan^2 z``.

    Returns
    -------
    ndarray
        Slant delay [m]: about 2.43 m at zenith at sea level (2.31 m
        hydrostatic + 0.12 m wet at 70 % humidity, 15 deg C).
    """
    P, T, e = standard_atmosphere(h, humidity)
    if pressure_hpa is not None:
        P = np.asarray(pressure_hpa, dtype=float)
    if temperature_k is not None:
        T = np.asarray(temperature_k, dtype=float)
    el = np.asarray(el, dtype=float)
    cosz = np.where(el > 0.0, np.sin(el), np.nan)
    hk = np.clip(np.asarray(h, dtype=float), 0.0, 11000.0) / 1e3
    D = 1.0 - 0.00266 * np.cos(2.0 * np.asarray(lat, dtype=float)) - 0.00028 * hk
    bracket = P / D + (1255.0 / T + 0.05) * e
    if b_term:
        tan2z = (np.cos(el) / cosz) ** 2
        bracket = bracket - np.interp(hk, _SAAST_B_H_KM, _SAAST_B_HPA) * tan2z
    return 0.002277 * bracket / cosz
