"""IMU simulation: ideal increments from the analytic truth, then the error model.

Ideal increments are Gauss-Legendre integrals of ``omega_ib_b`` and
``f_ib_b`` over each sample interval ``(t - dt, t]`` (see
:meth:`insnav.sim.trajectory.Trajectory.imu_increments`): a real gyro outputs
exactly the integral of the angular rate, so no mechanization is run
backwards and the simulator can test the mechanization.

Error model, per sensor triad (gyro: rad/s, accelerometer: m/s^2), applied to
the rate ``x`` (Groves 2013, eqs. (4.16)-(4.18)):

    x_meas = (I + diag(s) + M) x + b(t) + w(t)
    b(t) = b_const + b_turn_on + b_GM(t) + b_RW(t)

* ``b_const`` deterministic, ``b_turn_on ~ N(0, bias_sigma^2)`` once per run;
* ``b_GM``: first-order Gauss-Markov, ``db = -b/tau dt + sigma sqrt(2/tau) dW``,
  discretised exactly (``phi = exp(-dt/tau)``), started stationary;
* ``b_RW``: random walk, ``db = q dW``, starting at 0;
* ``w``: white noise of density ``N`` (ARW rad/sqrt(s), VRW (m/s)/sqrt(s)); the
  increment noise is ``N(0, N^2 dt)``;
* ``s`` scale-factor errors, ``M`` misalignment (zero diagonal).

For increments: ``dx_meas = (I + diag(s) + M) dx + b(t_k) dt + n_k``, the bias
being held at its value at the end of the interval.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scenario import SensorErrors


@dataclass
class SensorRealisation:
    """The injected errors of one triad (SI): ``bias`` (N, 3) at the IMU sample times."""

    bias: np.ndarray
    scale: np.ndarray
    misalignment: np.ndarray
    turn_on_bias: np.ndarray


def _ar1(phi: float, x0: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``x_k = phi x_{k-1} + e_k`` for k = 1..N (rows of ``e``), vectorised by blocks.

    Within a block of length L, ``x_j = phi^j (x_0 + sum_{i<=j} phi^-i e_i)``;
    L is chosen so that ``phi^-L <= e^8`` which keeps the rounding error at
    the 1e-12 level.
    """
    n = e.shape[0]
    out = np.empty_like(e)
    if phi <= 0.0:
        return e.copy()
    lam = -np.log(phi)
    L = n if lam == 0.0 else max(1, min(n, int(8.0 / lam)))
    j = np.arange(1, L + 1, dtype=float)
    pw_pos = np.exp(-lam * j)[:, None]  # phi^j
    pw_neg = np.exp(lam * j)[:, None]  # phi^-j
    state = np.asarray(x0, dtype=float)
    for s in range(0, n, L):
        m = min(L, n - s)
        acc = np.cumsum(e[s:s + m] * pw_neg[:m], axis=0)
        out[s:s + m] = pw_pos[:m] * (state[None, :] + acc)
        state = out[s + m - 1]
    return out


def simulate_sensor_errors(err: SensorErrors, n: int, dt: float,
                           rng: np.random.Generator) -> tuple[SensorRealisation, np.ndarray]:
    """Draw one realisation of a triad's errors.

    Parameters
    ----------
    err : SensorErrors
        Error model (SI).
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    rng : numpy.random.Generator

    Returns
    -------
    realisation : SensorRealisation
        Bias at the ``n`` sample times, scale factors, misalignment.
    noise : ndarray, shape (n, 3)
        White-noise increments [rad or m/s] (``N(0, N^2 dt)``).
    """
    # draw order is fixed so that a seed always gives the same numbers
    turn_on = err.bias_sigma * rng.standard_normal(3)
    scale = err.scale + err.scale_sigma * rng.standard_normal(3)
    M = err.misalignment.copy()
    off = ~np.eye(3, dtype=bool)
    M[off] += err.misalignment_sigma * rng.standard_normal(6)
    bias = np.empty((n, 3))
    bias[:] = err.bias + turn_on
    for ax in range(3):
        sig, tau = err.gm_sigma[ax], err.gm_tau[ax]
        if sig > 0 and np.isfinite(tau):
            phi = np.exp(-dt / tau)
            x0 = sig * rng.standard_normal(1)
            e = (sig * np.sqrt(1.0 - phi * phi)) * rng.standard_normal((n - 1, 1))
            gm = np.empty((n, 1))
            gm[0] = x0
            if n > 1:
                gm[1:] = _ar1(phi, x0, e)
            bias[:, ax] += gm[:, 0]
    if np.any(err.bias_rw > 0):
        steps = err.bias_rw * np.sqrt(dt) * rng.standard_normal((n, 3))
        steps[0] = 0.0
        bias += np.cumsum(steps, axis=0)
    if np.any(err.noise_density > 0):
        noise = err.noise_density * np.sqrt(dt) * rng.standard_normal((n, 3))
    else:
        noise = np.zeros((n, 3))
    return SensorRealisation(bias, scale, M, turn_on), noise


def apply_errors(dx: np.ndarray, real: SensorRealisation, noise: np.ndarray,
                 dt: float) -> np.ndarray:
    """Corrupt ideal increments ``dx`` (N, 3): ``(I + diag(s) + M) dx + b dt + n``."""
    T = np.eye(3) + np.diag(real.scale) + real.misalignment
    out = real.bias * dt
    out += noise
    for i in range(3):  # column-wise: (N,3) @ (3,3) is slow in NumPy for tiny inner sizes
        for j in range(3):
            if T[i, j] != 0.0:
                out[:, i] += T[i, j] * dx[:, j]
    return out


def imu_model_dict(gyro: SensorErrors, accel: SensorErrors, imu_rate: float) -> dict:
    """The IMU noise/bias model in SI, for deriving a filter configuration.

    Keys (each a list of 3 floats, one per body axis, unless noted):

    ``rate_hz``
        IMU sample rate [Hz] (float).
    ``gyro_arw``
        Angle random walk [rad/sqrt(s)] (white rate noise density).
    ``accel_vrw``
        Velocity random walk [(m/s)/sqrt(s)].
    ``gyro_bias``, ``accel_bias``
        Deterministic constant bias [rad/s], [m/s^2].
    ``gyro_bias_sigma``, ``accel_bias_sigma``
        1-sigma of the random constant (turn-on) bias [rad/s], [m/s^2].
    ``gyro_gm_sigma``, ``accel_gm_sigma``
        Steady-state 1-sigma of the Gauss-Markov bias [rad/s], [m/s^2].
    ``gyro_gm_tau``, ``accel_gm_tau``
        Its correlation time [s] (``inf`` when there is none).
    ``gyro_bias_rw``, ``accel_bias_rw``
        Bias random walk [rad/s/sqrt(s)], [m/s^2/sqrt(s)].
    ``gyro_scale_sigma``, ``accel_scale_sigma``
        1-sigma of the random scale-factor error [-]; ``gyro_scale`` /
        ``accel_scale`` the deterministic part.
    ``gyro_misalignment_sigma``, ``accel_misalignment_sigma``
        1-sigma of each random off-diagonal misalignment [rad] (float).
    ``gyro_bias_total_sigma``, ``accel_bias_total_sigma``
        ``sqrt(bias^2 + bias_sigma^2 + gm_sigma^2)``: a sensible initial
        1-sigma of a filter's bias states [rad/s], [m/s^2].
    """
    def tri(p, e: SensorErrors):
        return {
            f"{p}_bias": e.bias.tolist(), f"{p}_bias_sigma": e.bias_sigma.tolist(),
            f"{p}_gm_sigma": e.gm_sigma.tolist(), f"{p}_gm_tau": e.gm_tau.tolist(),
            f"{p}_bias_rw": e.bias_rw.tolist(), f"{p}_scale": e.scale.tolist(),
            f"{p}_scale_sigma": e.scale_sigma.tolist(),
            f"{p}_misalignment_sigma": float(e.misalignment_sigma),
            f"{p}_bias_total_sigma": np.sqrt(e.bias ** 2 + e.bias_sigma ** 2
                                             + e.gm_sigma ** 2).tolist(),
        }
    d = {"rate_hz": float(imu_rate), "gyro_arw": gyro.noise_density.tolist(),
         "accel_vrw": accel.noise_density.tolist()}
    d.update(tri("gyro", gyro))
    d.update(tri("accel", accel))
    return d
