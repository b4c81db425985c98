"""One output assembler for every runner.

* :func:`nav_solution`, the closed-loop runners (loose, tight, delay, particle,
  RTK/INS): the engine's navigation rows (``cpp/bindings/outputs.hpp``: ``t``,
  ``llh`` and ``rpy`` in radians, ``v_n``, ``sigma`` in layout order, SI,
  ``imu_err``) become a :class:`insnav.filters.solution.Solution` (or a
  subclass) in the solution's units, converted once, in place, in one compiled
  pass (``_core.nav_rows_to_degrees``) that also finds the first non-finite row.
* :func:`gnss_solution`, the GNSS-only runners (spp, rtk): antenna positions
  (ECEF) with NED velocity and sigmas become a Solution whose attitude and IMU
  error columns are NaN (there is no IMU).
"""
from __future__ import annotations

import numpy as np

from .. import _core
from .solution import Solution

__all__ = ["nav_solution", "gnss_solution"]


def nav_solution(out: dict, cls=Solution, **fields) -> tuple[Solution, bool]:
    """The navigation rows of an engine result ``out`` as a ``cls`` instance.

    Parameters
    ----------
    out : dict
        The engine's result (its ``llh``, ``rpy`` and ``sigma`` arrays are
        converted to degrees in place: they are the caller's own).
    cls : type
        :class:`Solution` or a subclass (``TightSolution``, ...).
    **fields
        The other fields of ``cls`` (``gnss_t``, ``innovation``, ``nis``,
        ``gnss_status``, ``summary``, clock, ...).

    Returns
    -------
    (Solution, bool)
        The solution, and whether some row has a non-finite latitude or
        velocity (``raise_if_nonfinite`` then names it).
    """
    llh, rpy, sig, err, v_n = out["llh"], out["rpy"], out["sigma"], out["imu_err"], out["v_n"]
    _, nonfinite = _core.nav_rows_to_degrees(llh, rpy, sig, 6, v_n)
    sol = cls(t=out["t"], lat_deg=llh[:, 0], lon_deg=llh[:, 1], h_m=llh[:, 2], v_n=v_n,
              roll_deg=rpy[:, 0], pitch_deg=rpy[:, 1], yaw_deg=rpy[:, 2],
              sigma_pos_n_m=sig[:, 0:3], sigma_vel_n_mps=sig[:, 3:6], sigma_att_deg=sig[:, 6:9],
              acc_bias_mps2=err[:, 0:3], gyro_bias_rps=err[:, 3:6], acc_scale=err[:, 6:9],
              gyro_scale=err[:, 9:12], **fields)
    return sol, bool(nonfinite)


def gnss_solution(t, r_e, v_n, sigma_pos_n_m, sigma_vel_n_mps, *, gnss_t, nis, gnss_status,
                  summary: dict) -> Solution:
    """A GNSS-only solution (no IMU): one row per solved epoch.

    Parameters
    ----------
    t : (N,) array
        Time of each solved epoch [s].
    r_e : (N, 3) array
        Antenna position, ECEF [m] (WGS-84; geodetic latitude, longitude and
        ellipsoidal height in the solution).
    v_n, sigma_pos_n_m, sigma_vel_n_mps : (N, 3) arrays
        NED velocity [m/s] and the 1-sigma of position [m] and velocity [m/s]
        (NaN where the filter has none).
    gnss_t, nis, gnss_status : (E,) arrays
        Per epoch, solved or not: time [s], test statistic, :class:`RecordStatus`
        or fix status.
    summary : dict
        The run's counts.

    Returns
    -------
    Solution
        Attitude, its sigma and the IMU-error columns NaN; ``innovation`` (E, 6) NaN.
    """
    from .. import earth
    from ..units import RAD2DEG

    n = len(t)
    lat, lon, h = earth.ecef_to_geodetic(r_e) if n else (np.zeros(0),) * 3
    nan = np.full(n, np.nan)
    nan3 = np.full((n, 3), np.nan)
    return Solution(t=t, lat_deg=lat * RAD2DEG, lon_deg=lon * RAD2DEG, h_m=h, v_n=v_n, roll_deg=nan,
                    pitch_deg=nan.copy(), yaw_deg=nan.copy(), sigma_pos_n_m=sigma_pos_n_m,
                    sigma_vel_n_mps=sigma_vel_n_mps, sigma_att_deg=nan3, acc_bias_mps2=nan3.copy(),
                    gyro_bias_rps=nan3.copy(), acc_scale=nan3.copy(), gyro_scale=nan3.copy(), gnss_t=gnss_t,
                    innovation=np.full((len(gnss_t), 6), np.nan), nis=nis, gnss_status=gnss_status,
                    summary=summary)
