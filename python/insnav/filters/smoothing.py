"""The RTS smoother's result on the output rows (``smooth=True``, ``--smooth``).

The C++ forward pass records every filter epoch and the backward pass
(``cpp/include/insnav/filter/rts_smoother.hpp``) returns, per epoch k, the
smoothed error ``s_k`` of the post-feedback nominal ``m_k`` and its sigma.
Between two epochs the output rows are the nominal INS corrected by the
filter's running estimate (zero after every feedback; after an epoch without
feedback, e.g. in an outage, the propagated mean of a sigma-point filter).
The smoothed row is that row corrected by the difference: ``s_k - r_k``
just after epoch k (``r_k`` what remains of ``x_k`` after feedback), and
``s_{k+1} + x_{k+1} - xp_{k+1}`` just before epoch k+1 (``x_{k+1}``
counted when it was fed back; ``xp`` the predicted mean), interpolated
linearly in time in between (the error dynamics are slow against the 0.1-1 s
between epochs); for the EKF ``r`` and ``xp`` are zero.  The correction is
applied as a feedback would: position, velocity, and
``C_nb <- dcm(psi) C_nb``.
Tight runs: the receiver clock bias and drift (and the inter-system biases
of a 20-state run) likewise, ``b <- b - d_b``.  IMU biases and scale factors
stay the filtered ones.  Rows after the last epoch (no data after them) and
their sigmas are the filtered ones.
"""
from __future__ import annotations

import numpy as np

from .. import _core
from ..units import DEG, RAD2DEG

__all__ = ["smoothed_rows"]

#: state columns of the clock (Layout17 / LayoutTightMulti: 15 bias [m], 16 drift [m/s]) and ISBs (17-19 [m])
_CLOCK, _ISB = [15, 16], [17, 18, 19]
_ROWS = ("lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "pitch_deg", "yaw_deg")


def euler_sigmas_from_psi(P_psi, pitch, yaw):
    """1-sigmas [rad] (n, 3) of roll, pitch, yaw from the covariance (n, 3, 3) [rad^2] of the attitude
    error angles psi about N, E, D, at ``pitch``, ``yaw`` (n,) [rad]: ``A^-1 P A^-T`` with
    ``A^-1 = [[cy/cp, sy/cp, 0], [-sy, cy, 0], [cy tp, sy tp, 1]]``, the numpy form of
    ``euler_sigmas_from_psi`` in ``cpp/include/insnav/ins/nav_error.hpp`` (the derivation there)."""
    sp, cp, sy, cy = np.sin(pitch), np.cos(pitch), np.sin(yaw), np.cos(yaw)
    cp = np.where(np.abs(cp) < 1e-9, np.copysign(1e-9, cp), cp)
    z, o = np.zeros_like(cp), np.ones_like(cp)
    A_inv = np.stack([np.stack([cy / cp, sy / cp, z], -1), np.stack([-sy, cy, z], -1),
                      np.stack([cy * sp / cp, sy * sp / cp, o], -1)], -2)
    P_e = A_inv @ np.asarray(P_psi, float) @ np.swapaxes(A_inv, -1, -2)
    return np.sqrt(np.maximum(np.diagonal(P_e, axis1=-2, axis2=-1), 0.0))


def smoothed_rows(sol, out: dict, filter_name: str = "ekf", sigma=None) -> None:
    """Replace the navigation rows and sigmas of ``sol`` by the smoothed ones (in place).

    Parameters
    ----------
    sol : Solution or TightSolution
        The forward run's solution; with ``clock_bias_m`` (tight) the receiver
        clock, and with ``isb_m`` the inter-system biases, are smoothed too.
    out : dict
        The engine's result with the ``smooth_*`` arrays (``smoother_run.hpp``).
    filter_name : str
        For the summary's method.
    sigma : ndarray (n, >= 9), optional
        The array whose columns 0-8 ``sol``'s position [m], velocity [m/s] and
        attitude [deg] sigmas are views of (the loose engine's): the smoothed
        sigmas are then written into it in place (no new (n, 9) array).
    """
    te = np.asarray(out["smooth_t"], float)
    cols = list(range(9))
    extra = []
    if getattr(sol, "clock_bias_m", None) is not None:
        cols += _CLOCK
        extra += [sol.clock_bias_m, sol.clock_drift_mps]
        if getattr(sol, "isb_m", None) is not None:
            cols += _ISB
            extra += [sol.isb_m[:, j] for j in range(3)]
    d = np.ascontiguousarray(np.asarray(out["smooth_d"], float)[:, cols])  # position, velocity, attitude (clock, ISB)
    d_end = np.ascontiguousarray(np.asarray(out["smooth_d_end"], float)[:, cols])  # before the epoch's feedback
    sig = np.ascontiguousarray(np.asarray(out["smooth_sigma"], float)[:, cols])
    # corrected in place (any strides, e.g. the columns of the engine's llh): no copy of float64 rows
    rows = [np.require(getattr(sol, k), float, ["W"]) for k in _ROWS]
    t = np.asarray(sol.t, float)
    if "smooth_P_att" in out:  # the rows' attitude sigmas are of their Euler angles: psi's covariance mapped
        yaw = np.unwrap(np.asarray(rows[6], float), period=360.0)  # at each epoch's (filtered) attitude
        sig[:, 6:9] = euler_sigmas_from_psi(np.asarray(out["smooth_P_att"], float),
                                            np.interp(te, t, rows[5]) * DEG, np.interp(te, t, yaw) * DEG)
    sig[:, 6:9] *= RAD2DEG  # the rows' attitude sigma unit
    ex = np.column_stack(extra).astype(float) if extra else None
    # rows after the last epoch: no data after them, the smoothed rows and sigmas are the filtered ones
    n_in = int(np.searchsorted(t, te[-1] + 1e-9, side="right"))
    in_place = sigma is not None and ex is None
    if in_place:  # the views sol.sigma_* see the smoothed sigmas; rows from n_in on keep the filtered ones
        sg = sigma[:, :9]
    else:
        sg = np.empty((len(t), len(cols)))
    _core.smooth_rows(t[:n_in], *(r[:n_in] for r in rows), te, d, d_end, sig, sg[:n_in],
                      None if ex is None else ex[:n_in])
    for k, r in zip(_ROWS, rows):
        setattr(sol, k, r)
    if not in_place:
        sg[n_in:, :9] = np.column_stack([sol.sigma_pos_n_m[n_in:], sol.sigma_vel_n_mps[n_in:],
                                         sol.sigma_att_deg[n_in:]])
        if ex is not None:
            sg[n_in:, 9:11] = sol.sigma_clock[n_in:]
            if ex.shape[1] > 2:
                sg[n_in:, 11:14] = sol.sigma_isb[n_in:]
        sol.sigma_pos_n_m = sg[:, 0:3]
        sol.sigma_vel_n_mps = sg[:, 3:6]
        sol.sigma_att_deg = sg[:, 6:9]
    if ex is not None:
        sol.clock_bias_m, sol.clock_drift_mps, sol.sigma_clock = ex[:, 0], ex[:, 1], sg[:, 9:11]
        if ex.shape[1] > 2:
            sol.isb_m, sol.sigma_isb = ex[:, 2:5], sg[:, 11:14]
    method = "RTS (EKF)" if filter_name == "ekf" else f"unscented RTS, Sarkka 2008 ({filter_name})"
    sol.summary["smoother"] = dict(method=method, epochs=int(len(te)),
                                   gain_failures=int(out.get("smooth_gain_failures", 0)))
