"""The per-sample checks of an IMU stream in one compiled pass.

:func:`scan_imu` runs ``_core.scan_imu`` (``cpp/include/insnav/ins/imu_scan.hpp``,
the GIL released) over ``t`` [s], ``dtheta_b`` (N, 3) [rad] and ``dv_b``
(N, 3) [m/s]: the first non-finite sample of each array, the first decreasing
and the first not increasing time, the count of repeated times, the nominal
interval ``dt0`` [s], the first sample over the angular-rate and
specific-force limits, the gaps and the sum of ``dv_b``.  Indices are -1 when
there is none.  The callers (:mod:`insnav.filters.sanitize`,
:func:`insnav.filters._setup.imu_arrays`, :mod:`insnav.data.checks`) build
their messages from them.

Inside :func:`insnav.run` the same arrays are checked by the sanitizer, the
unit checks and the runner; :func:`scan_memo` keeps one result per set of
arrays for the duration of the run (keyed by the arrays' memory, which the
memo keeps alive), so the stream is read once.
"""
from __future__ import annotations

import contextlib
import contextvars
import math

import numpy as np

__all__ = ["scan_imu", "scan_memo"]

_MEMO: contextvars.ContextVar[dict | None] = contextvars.ContextVar("insnav_imu_scan_memo", default=None)
_INF = math.inf


@contextlib.contextmanager
def scan_memo():
    """Within the block, :func:`scan_imu` computes each stream's scan once
    (the arrays must not be modified inside the block)."""
    token = _MEMO.set({})
    try:
        yield
    finally:
        _MEMO.reset(token)


def _key(a: np.ndarray) -> tuple:
    return a.__array_interface__["data"][0], a.shape, a.strides, a.dtype.str


def scan_imu(t: np.ndarray, dtheta_b: np.ndarray, dv_b: np.ndarray, *, t0: float | None = None,
             max_rate_rps: float | None = None, max_accel_mps2: float | None = None,
             gap_factor: float | None = None) -> dict:
    """One pass of the IMU input checks (module docstring).

    Parameters
    ----------
    t : ndarray (N,)
        Sample times [s], float64.
    dtheta_b, dv_b : ndarray (N, 3)
        Angular [rad] and velocity [m/s] increments, float64, C order.
    t0 : float, optional
        Start of the first interval [s].
    max_rate_rps, max_accel_mps2 : float, optional
        Limits of ``|dtheta|/dt`` [rad/s] and ``|dv|/dt`` [m/s^2]; None: not tested.
    gap_factor : float, optional
        A sample interval over ``gap_factor * dt0`` is a gap; None: not counted.

    Returns
    -------
    dict
        ``nonfinite_t``, ``nonfinite_dtheta``, ``nonfinite_dv``, ``decrease``,
        ``not_increasing``, ``rate``, ``accel`` (first sample index or -1),
        ``repeats``, ``gaps`` (counts), ``dt0``, ``max_gap_s`` [s], ``dv_sum`` [m/s].
        With no limit given, a memoised scan made with limits may be returned
        (its limit-independent entries are the same).
    """
    from . import _core

    limits = (t0, max_rate_rps, max_accel_mps2, gap_factor)
    memo = _MEMO.get()
    key = None
    if memo is not None:
        key = (_key(t), _key(dtheta_b), _key(dv_b))
        hit = memo.get(key)
        if hit is not None and (hit[1] == limits or limits == (None,) * 4):
            return hit[2]
    res = _core.scan_imu(t, dtheta_b, dv_b, math.nan if t0 is None else float(t0),
                         _INF if max_rate_rps is None else float(max_rate_rps),
                         _INF if max_accel_mps2 is None else float(max_accel_mps2),
                         _INF if gap_factor is None else float(gap_factor))
    if memo is not None:
        memo[key] = ((t, dtheta_b, dv_b), limits, res)  # the arrays kept alive: their addresses stay theirs
    return res
