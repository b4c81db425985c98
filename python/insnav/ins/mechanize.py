"""Free-inertial strapdown mechanization over whole arrays (batch API)."""
from __future__ import annotations

import numpy as np

from .. import _core
from .._validate import as_float_array, check_finite, check_increasing
from ..data.nav import NavState, Trajectory


def mechanize(t, dtheta_b, dv_b, initial: NavState, t0: float | None = None,
              *, coning: bool = True, sculling: bool = True) -> Trajectory:
    """Integrate IMU increments from an initial state (no aiding).

    The whole loop runs in C++ with the GIL released (NED mechanization with
    two-sample coning and sculling corrections, see
    ``cpp/include/insnav/ins/mechanization.hpp``).

    Parameters
    ----------
    t : array_like (N,)
        End time of each IMU interval [s], strictly increasing.
    dtheta_b : array_like (N, 3)
        Angular increments over ``(t[i-1], t[i]]`` in the body frame (FRD) [rad].
    dv_b : array_like (N, 3)
        Velocity (specific-force) increments over the same intervals [m/s].
    initial : NavState
        State at ``t0``.
    t0 : float, optional
        Time of ``initial`` [s]; the first interval is ``(t0, t[0]]``.
        Default: ``t[0] - (t[1] - t[0])``.
    coning, sculling : bool
        Switch the two-sample corrections (for studies; keep them on).

    Returns
    -------
    Trajectory
        One row per IMU sample (the state at ``t[i]``).

    Raises
    ------
    ValueError
        On bad shapes, non-finite values or non-increasing time, naming the
        first offending sample.
    FloatingPointError
        When finite inputs still give a non-finite state (an absurdly long
        interval, e.g. a time in the wrong unit), naming the first such sample.
    """
    t = as_float_array(t, "t")
    dtheta_b = as_float_array(dtheta_b, "dtheta_b", (3,))
    dv_b = as_float_array(dv_b, "dv_b", (3,))
    n = len(t)
    if len(dtheta_b) != n or len(dv_b) != n:
        raise ValueError(f"t, dtheta_b and dv_b must have the same length, got {n}, {len(dtheta_b)}, {len(dv_b)}")
    if n == 0:
        raise ValueError("no IMU samples")
    if t0 is None:
        if n < 2:
            raise ValueError("t0 is required with a single IMU sample")
        t0 = float(t[0] - (t[1] - t[0]))
    if not np.isfinite(t0):
        raise ValueError(f"t0: not finite ({t0!r})")
    # the C++ loop checks every sample as it goes (finite, strictly increasing
    # time) and stops at the first bad one; the checks below then name it
    out = _core.mechanize(t, dtheta_b, dv_b, float(t0), initial.pos_llh, initial.v_n, initial.rpy,
                          coning, sculling)
    if out["bad_sample"] >= 0:
        for arr, name in ((t, "t"), (dtheta_b, "dtheta_b"), (dv_b, "dv_b")):
            check_finite(arr, name)
        check_increasing(t, "t", t0=float(t0))
        raise AssertionError(f"mechanize: sample {out['bad_sample']} refused by the C++ loop")  # unreachable
    finite = (np.isfinite(out["lat_deg"]) & np.isfinite(out["lon_deg"]) & np.isfinite(out["h_m"])
              & np.isfinite(out["v_n"]).all(axis=1))
    if not finite.all():  # finite inputs, but an interval so long that the state overflows
        i = int(np.argmin(finite))
        dt = t[i] - (t[i - 1] if i > 0 else float(t0))
        raise FloatingPointError(f"mechanize: the state is not finite from sample {i} (t = {float(t[i]):.9g} s, interval "
                                 f"{float(dt):.6g} s from the previous time): is t in seconds, and t0 the time of "
                                 "the initial state?")
    return Trajectory(t=t.copy(), lat_deg=out["lat_deg"], lon_deg=out["lon_deg"], h_m=out["h_m"],
                      v_n=out["v_n"], roll_deg=out["roll_deg"], pitch_deg=out["pitch_deg"],
                      yaw_deg=out["yaw_deg"])
