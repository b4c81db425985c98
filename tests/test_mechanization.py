"""Strapdown mechanization against analytic motions."""
from __future__ import annotations

import numpy as np
import pytest

import insnav
from insnav import earth
from imu_exact import euler_to_quat, quat_conj, quat_mul, quat_to_dcm, stationary_rotating

DEG = np.pi / 180


def _position_error_m(traj, lat_deg, lon_deg, h):
    r = earth.geodetic_to_ecef(traj.lat_deg[-1] * DEG, traj.lon_deg[-1] * DEG, traj.h_m[-1])
    r0 = earth.geodetic_to_ecef(lat_deg * DEG, lon_deg * DEG, h)
    return float(np.linalg.norm(r - r0))


def _attitude_error_rad(traj, q_true):
    q = np.array([euler_to_quat(np.array([traj.roll_deg[-1], traj.pitch_deg[-1], traj.yaw_deg[-1]]) * DEG)])
    dq = quat_mul(q, quat_conj(q_true[-1:]))[0]
    return float(2 * np.linalg.norm(dq[1:]) * np.sign(dq[0]))


@pytest.mark.parametrize("lat_deg", [0.0, 30.0, 60.0, 85.0, -45.0])
def test_stationary_one_hour(lat_deg):
    """Exact Earth-rate and gravity increments: < 1 mm and < 1e-6 rad after 1 h at 100 Hz."""
    h, lon = 120.0, 10.0
    rpy0 = np.array([2.0, -3.0, 40.0])
    q0 = euler_to_quat(rpy0 * DEG)
    one = lambda tt: np.broadcast_to(np.array([1.0, 0, 0, 0]), np.shape(tt) + (4,))
    zero = lambda tt: np.zeros(np.shape(tt) + (4,))
    t, dth, dv, q_true = stationary_rotating(lat_deg * DEG, h, q0, one, zero, 3600.0, 100.0)
    init = insnav.NavState(lat_deg, lon, h, [0, 0, 0], *rpy0)
    traj = insnav.mechanize(t, dth, dv, init, t0=0.0)
    assert _position_error_m(traj, lat_deg, lon, h) < 1e-3
    assert abs(_attitude_error_rad(traj, q_true)) < 1e-6
    assert np.abs(traj.v_n).max() < 1e-5


def _coning(beta, Omega):
    s, c = np.sin(beta / 2), np.cos(beta / 2)

    def q_fn(tt):
        tt = np.asarray(tt)
        return np.stack([np.full_like(tt, c), np.zeros_like(tt), s * np.cos(Omega * tt), s * np.sin(Omega * tt)], -1)

    def qdot_fn(tt):
        tt = np.asarray(tt)
        return np.stack([np.zeros_like(tt), np.zeros_like(tt), -s * Omega * np.sin(Omega * tt),
                         s * Omega * np.cos(Omega * tt)], -1)

    return q_fn, qdot_fn


def test_coning_correction_gains_10x():
    """Classic coning (1 deg half-angle at 4 Hz, 100 Hz IMU): the two-sample correction cuts the 60 s attitude error >= 10x."""
    q_fn, qdot_fn = _coning(1.0 * DEG, 2 * np.pi * 4.0)
    lat, h = 45.0, 0.0
    q0 = euler_to_quat(np.array([0.0, 0.0, 0.0]))
    t, dth, dv, q_true = stationary_rotating(lat * DEG, h, q0, q_fn, qdot_fn, 60.0, 100.0)
    from insnav._core import rotation
    rpy0 = rotation.euler_from_dcm(quat_to_dcm(q_fn(0.0))) / DEG   # true attitude at t0 = 0
    init = insnav.NavState(lat, 0.0, h, [0, 0, 0], *rpy0)
    with_c = abs(_attitude_error_rad(insnav.mechanize(t, dth, dv, init, t0=0.0), q_true))
    without = abs(_attitude_error_rad(insnav.mechanize(t, dth, dv, init, t0=0.0, coning=False), q_true))
    assert without > 1e-4          # the uncorrected coning drift is real (~ rad/h level)
    assert with_c * 10 < without


def _sculling_increments(A, B, f_hz, rate, T, lat, h=0.0):
    """Roll oscillation phi = A sin(Om t) in phase with an East acceleration B sin(Om t):
    the classic sculling motion.  Exact increments by Gauss-Legendre quadrature of
    omega_ib_b and f_ib_b = C_bn (dv_n/dt + (2 omega_ie + omega_en) x v_n - g_n)."""
    from imu_exact import GL_W, GL_X
    Om = 2 * np.pi * f_hz
    dt = 1.0 / rate
    t = np.arange(1, int(T * rate) + 1) * dt
    tq = (t[:, None] - dt) + 0.5 * dt * (GL_X[None, :] + 1.0)
    phi, phid = A * np.sin(Om * tq), A * Om * np.cos(Om * tq)
    z = np.zeros_like(tq)
    v = np.stack([z, -(B / Om) * np.cos(Om * tq), z], -1)
    a = np.stack([z, B * np.sin(Om * tq), z], -1)
    w_ie, w_en = earth.omega_ie_n(lat), earth.omega_en_n(lat, h, v)
    f_n = a + np.cross(2 * w_ie + w_en, v) - np.array([0, 0, earth.gravity(lat, h)])
    c, s = np.cos(phi), np.sin(phi)
    to_b = lambda u: np.stack([u[..., 0], c * u[..., 1] + s * u[..., 2], -s * u[..., 1] + c * u[..., 2]], -1)
    w_b = np.stack([phid, z, z], -1) + to_b(w_ie + w_en)
    wq = 0.5 * dt * GL_W
    v_end = -(B / Om) * np.cos(Om * T)
    return t, np.einsum("nqk,q->nk", w_b, wq), np.einsum("nqk,q->nk", to_b(f_n), wq), -(B / Om), v_end


def test_sculling_correction_gains_10x():
    """Sculling (0.2 deg roll, 5 m/s^2 lateral, 5 Hz, 100 Hz IMU): the corrections cut the 60 s velocity error >= 10x."""
    lat = 30.0
    t, dth, dv, v0, v_end = _sculling_increments(0.2 * DEG, 5.0, 5.0, 100.0, 60.0, lat * DEG)
    init = insnav.NavState(lat, 0.0, 0.0, [0, v0, 0], 0.0, 0.0, 0.0)
    truth = np.array([0.0, v_end, 0.0])
    with_s = np.abs(insnav.mechanize(t, dth, dv, init, t0=0.0).v_n[-1] - truth).max()
    without = np.abs(insnav.mechanize(t, dth, dv, init, t0=0.0, sculling=False).v_n[-1] - truth).max()
    assert without > 5e-3          # the rectified sculling error is real
    assert with_s * 10 < without


def test_variable_rate_matches_fixed_rate():
    """The same motion sampled at 200 Hz and at a jittered ~200 Hz gives the same end state (< 1 mm)."""
    q_fn, qdot_fn = _coning(0.5 * DEG, 2 * np.pi * 1.0)
    q0 = euler_to_quat(np.zeros(3))
    t, dth, dv, q_true = stationary_rotating(0.5, 0.0, q0, q_fn, qdot_fn, 20.0, 200.0)
    init = insnav.NavState(0.5 / DEG, 0.0, 0.0, [0, 0, 0], 0.0, 0.0, 0.0)
    # merge pairs of samples -> 100 Hz increments are sums
    t2, dth2, dv2 = t[1::2], dth[0::2] + dth[1::2], dv[0::2] + dv[1::2]
    a = insnav.mechanize(t, dth, dv, init, t0=0.0)
    b = insnav.mechanize(t2, dth2, dv2, init, t0=0.0)
    assert abs(a.h_m[-1] - b.h_m[-1]) < 1e-3
    assert np.abs(a.v_n[-1] - b.v_n[-1]).max() < 1e-4


class TestBadInput:
    def _ok(self):
        n = 10
        return np.arange(1, n + 1) * 0.01, np.zeros((n, 3)), np.tile([0, 0, -0.098], (n, 1))

    def test_nan_names_sample(self):
        t, dth, dv = self._ok()
        dv[7, 1] = np.nan
        with pytest.raises(ValueError, match=r"dv_b: non-finite value at sample 7"):
            insnav.mechanize(t, dth, dv, insnav.NavState(0, 0, 0), t0=0.0)

    def test_time_not_increasing(self):
        t, dth, dv = self._ok()
        t[5] = t[4]
        with pytest.raises(ValueError, match=r"not strictly increasing at sample 5"):
            insnav.mechanize(t, dth, dv, insnav.NavState(0, 0, 0), t0=0.0)

    def test_shape(self):
        t, dth, dv = self._ok()
        with pytest.raises(ValueError, match=r"dtheta_b: expected shape \(N, 3\)"):
            insnav.mechanize(t, dth[:, :2], dv, insnav.NavState(0, 0, 0), t0=0.0)

    def test_first_sample_before_t0(self):
        t, dth, dv = self._ok()
        with pytest.raises(ValueError, match=r"sample 0 .* not after the initial time"):
            insnav.mechanize(t, dth, dv, insnav.NavState(0, 0, 0), t0=1.0)

    def test_bad_initial_state(self):
        with pytest.raises(ValueError, match="lat_deg"):
            insnav.NavState(95.0, 0.0, 0.0)
        with pytest.raises(ValueError, match="h_m must be finite"):
            insnav.NavState(10.0, 0.0, float("nan"))


def test_an_overflowing_interval_is_an_error_not_a_nan():
    """Finite inputs whose first interval is absurd (t0 = -1e300 s) overflow
    the state: an error naming the sample and the interval, never a NaN track."""
    init = insnav.NavState(30.0, 114.0, 20.0, [0, 0, 0], 0, 0, 0)
    with pytest.raises(FloatingPointError, match=r"sample 0 \(t = 0 s, interval 1e\+300 s"):
        insnav.mechanize(np.array([0.0]), np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), init, t0=-1e300)
