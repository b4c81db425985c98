"""The RTS smoother's result on the output rows (``smooth=True``, ``--smooth``).

The C++ forward pass records every filter epoch and the backward pass
(``cpp/include/insnav/filter/rts_smoother.hpp``) returns, per epoch k, the
smoothed error ``s_k`` of the post-feedback nominal ``m_k`` and its sigma.
Between two epochs the output rows are the nominal INS (the EKF's state is
zero after every feedback); its error goes from ``s_k`` at ``t_k`` to the
smoothed error of the pre-feedback nominal at ``t_{k+1}``,
``s_{k+1} + x_{k+1}`` when ``x_{k+1}`` was fed back, and is interpolated
linearly in time in between (the error dynamics are slow against the 0.1-1 s
between epochs).  The smoothed row is the nominal corrected by that error,
as a feedback would: position, velocity, and ``C_nb <- dcm(psi) C_nb``.
IMU biases and scale factors stay the filtered ones.
"""
from __future__ import annotations

import numpy as np

from .. import _core
from ..units import RAD2DEG

__all__ = ["smoothed_rows"]


def smoothed_rows(sol, out: dict, filter_name: str = "ekf") -> None:
    """Replace the navigation rows and sigmas of ``sol`` by the smoothed ones (in place)."""
    te = np.ascontiguousarray(out["smooth_t"], float)
    s = np.ascontiguousarray(np.asarray(out["smooth_s"], float)[:, :9])  # position, velocity, attitude
    s_end = np.ascontiguousarray(s + np.asarray(out["smooth_x_fed"], float)[:, :9])  # before feedback
    sig = np.ascontiguousarray(np.asarray(out["smooth_sigma"], float)[:, :9])
    cols = [np.array(sol.lat_deg, float), np.array(sol.lon_deg, float), np.array(sol.h_m, float),
            np.array(sol.v_n, float), np.array(sol.roll_deg, float), np.array(sol.pitch_deg, float),
            np.array(sol.yaw_deg, float)]
    sg = np.empty((len(sol.t), 9))
    _core.smooth_rows(np.asarray(sol.t, float), *cols, te, s, s_end, sig, sg)
    sol.lat_deg, sol.lon_deg, sol.h_m, sol.v_n, sol.roll_deg, sol.pitch_deg, sol.yaw_deg = cols
    sol.sigma_pos_n_m = sg[:, 0:3]
    sol.sigma_vel_n_mps = sg[:, 3:6]
    sol.sigma_att_deg = sg[:, 6:9] * RAD2DEG
    method = "RTS (EKF)" if filter_name == "ekf" else f"unscented RTS, Sarkka 2008 ({filter_name})"
    sol.summary["smoother"] = dict(method=method, epochs=int(len(te)),
                                   gain_failures=int(out.get("smooth_gain_failures", 0)))
