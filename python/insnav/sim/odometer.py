"""Wheel odometer of a road vehicle: forward speed of the rear-axle centre.

The constrained point is at ``lever_arm_b`` from the IMU (body FRD); the
vehicle frame is taken aligned with the body frame (the simulator's cars
carry the IMU aligned).  Its velocity in body axes is (Groves 2013,
eq. (16.22))

    v_p_b = C_bn v_n + omega_nb_b x l_b

and the odometer measures the forward component ``v_p_b[0]``.  Sensor model:

* distance counted in ticks: ``ticks(t) = floor((1 + k) s(t) n_t)``, with
  ``s(t)`` the integrated forward distance [m], ``n_t`` ticks per metre and
  ``k`` the scale-factor error (``scale_error_ppm`` plus a random constant of
  ``scale_error_sigma_ppm``); reported speed over each interval
  ``(ticks(t_k) - ticks(t_k-1)) / (n_t dt)`` (quantisation step
  ``1 / (n_t dt)``: 0.02 m/s at 500 ticks/m and 10 Hz, 0.4 m/s for a bare
  25 ticks/m ABS ring);
* plus white noise ``sigma_mps``.

``ticks_per_m = 0`` turns the quantisation off.
"""
from __future__ import annotations

import numpy as np

from ..data.dataset import Odometer
from .trajectory import Trajectory, rotate_n_to_b

#: truth samples per odometer interval for the distance integral (Simpson's rule)
_SUBSTEPS = 16


def forward_speed(traj: Trajectory, t, lever_arm_b) -> np.ndarray:
    """True forward speed of the point at ``lever_arm_b`` (body FRD) [m/s]."""
    st = traj.state(np.asarray(t, float), exact_position=False)
    v_b = rotate_n_to_b(st["euler"], st["v_n"])
    v_b += np.cross(st["omega_nb_b"], np.broadcast_to(np.asarray(lever_arm_b, float), v_b.shape))
    return v_b[:, 0]


def simulate_odometer(traj: Trajectory, cfg: dict, rng: np.random.Generator) -> Odometer:
    """Simulate the odometer for the ``[odometer]`` configuration ``cfg`` (SI dict)."""
    sc = traj.sc
    dt = 1.0 / cfg["rate"]
    n = int(np.floor((sc.t_end - sc.t0) / dt + 1e-9))
    t = sc.t0 + dt * np.arange(n + 1)
    # distance: Simpson's rule on _SUBSTEPS (even) sub-intervals of each interval
    m = _SUBSTEPS
    tf = sc.t0 + (dt / m) * np.arange(n * m + 1)
    v = forward_speed(traj, tf, cfg["lever_arm_b"])
    w = np.ones(m + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    seg = v[:-1].reshape(n, m)
    seg = np.concatenate([seg, v[m::m][:, None]], axis=1)
    ds = (seg * w).sum(axis=1) * (dt / m) / 3.0
    s = np.concatenate([[0.0], np.cumsum(ds)])
    k = cfg["scale_error"] + cfg["scale_error_sigma"] * rng.standard_normal()
    if cfg["ticks_per_m"] > 0:
        ticks = np.floor((1.0 + k) * s * cfg["ticks_per_m"])
        speed = np.diff(ticks) / (cfg["ticks_per_m"] * dt)
    else:
        speed = (1.0 + k) * np.diff(s) / dt
    speed = speed + cfg["sigma"] * rng.standard_normal(n)
    return Odometer(t[1:].copy(), speed, scale_error=float(k))
