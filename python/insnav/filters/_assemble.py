"""One output assembler for the closed-loop runners (loose, tight, delay,
particle): the engine's navigation rows (``cpp/bindings/outputs.hpp``: ``t``,
``llh`` and ``rpy`` in radians, ``v_n``, ``sigma`` in layout order, SI,
``imu_err``) become a :class:`insnav.filters.solution.Solution` (or a
subclass) in the solution's units, converted once, in place, in one compiled
pass (``_core.nav_rows_to_degrees``) that also finds the first non-finite row.
"""
from __future__ import annotations

from .. import _core
from .solution import Solution

__all__ = ["nav_solution"]


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
