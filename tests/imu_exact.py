"""Exact IMU increments of analytic motions, for mechanization tests.

Increments are Gauss-Legendre integrals of the true angular rate and
specific force over each IMU interval (what an ideal IMU outputs), computed
independently of the mechanization.
"""
from __future__ import annotations

import numpy as np

from insnav import earth

GL_X, GL_W = np.polynomial.legendre.leggauss(6)


def quat_mul(p, q):
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([pw * qw - px * qx - py * qy - pz * qz,
                     pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw], axis=-1)


def quat_conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_dcm(q):
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def euler_to_quat(rpy):
    r, p, y = (0.5 * np.asarray(rpy, dtype=float))
    sr, cr, sp, cp, sy, cy = np.sin(r), np.cos(r), np.sin(p), np.cos(p), np.sin(y), np.cos(y)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def stationary_rotating(lat, h, q0, q_fn, qdot_fn, t_end, rate_hz):
    """A body fixed in position on the Earth whose attitude is q_nb(t) = q0 * q(t).

    Returns t, dtheta_b, dv_b and the true q_nb at each sample.
    """
    dt = 1.0 / rate_hz
    n = int(round(t_end * rate_hz))
    t = np.arange(1, n + 1) * dt
    # quadrature nodes in every interval
    tq = (t[:, None] - dt) + 0.5 * dt * (GL_X[None, :] + 1.0)
    q = quat_mul(np.broadcast_to(q0, tq.shape + (4,)), q_fn(tq))
    qdot = quat_mul(np.broadcast_to(q0, tq.shape + (4,)), qdot_fn(tq))
    omega_nb_b = 2.0 * quat_mul(quat_conj(q), qdot)[..., 1:]
    C_bn = np.swapaxes(quat_to_dcm(q), -1, -2)
    w_ie = earth.omega_ie_n(lat)
    g_n = np.array([0.0, 0.0, earth.gravity(lat, h)])
    omega_ib_b = omega_nb_b + C_bn @ w_ie
    f_ib_b = C_bn @ (-g_n)   # stationary: f = -g (normal gravity includes the centrifugal term)
    wq = 0.5 * dt * GL_W
    dtheta = np.einsum("nqk,q->nk", omega_ib_b, wq)
    dv = np.einsum("nqk,q->nk", f_ib_b, wq)
    q_true = quat_mul(np.broadcast_to(q0, (n, 4)), q_fn(t))
    return t, dtheta, dv, q_true
