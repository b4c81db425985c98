"""WGS-84 model and rotations: published values, round trips, C++ == Python."""
from __future__ import annotations

import numpy as np
import pytest

from insnav import _core, earth

DEG = np.pi / 180


def test_gravity_published_values():
    # NIMA TR8350.2: normal gravity on the ellipsoid at the equator and the pole
    assert earth.gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert earth.gravity(np.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert _core.earth.gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert _core.earth.gravity(np.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    # free-air gradient about -3.086e-6 /s^2 at mid latitude
    grad = (earth.gravity(0.8, 1000.0) - earth.gravity(0.8, 0.0)) / 1000.0
    assert grad == pytest.approx(-3.086e-6, rel=3e-3)


def test_radii_known_values():
    R_M, R_N = earth.radii(np.array([0.0, np.pi / 2]))
    assert R_N[0] == pytest.approx(6378137.0, abs=1e-6)           # a at the equator
    assert R_M[0] == pytest.approx(6335439.327, abs=1e-3)         # a (1 - e2)
    assert R_N[1] == pytest.approx(R_M[1], abs=1e-6)              # equal at the pole (a^2 / b)
    assert R_N[1] == pytest.approx(6378137.0**2 / 6356752.314245, abs=1e-3)


def test_geodetic_ecef_round_trip_everywhere():
    rng = np.random.default_rng(1)
    lat = rng.uniform(-np.pi / 2, np.pi / 2, 50000)
    lat[:100] = np.pi / 2
    lat[100:200] = -np.pi / 2
    lat[200:300] = np.pi / 2 - 1e-10
    lon = rng.uniform(-np.pi, np.pi, lat.size)
    h = rng.uniform(-1000.0, 1e6, lat.size)
    h[::7] = -1000.0
    h[1::7] = 1e6
    r = earth.geodetic_to_ecef(lat, lon, h)
    lat2, lon2, h2 = earth.ecef_to_geodetic(r)
    r2 = earth.geodetic_to_ecef(lat2, lon2, h2)
    assert np.abs(r2 - r).max() < 1e-6
    assert np.abs(h2 - h).max() < 1e-6
    for i in range(0, 2000, 97):  # the C++ twin agrees
        llh = _core.earth.ecef_to_geodetic(r[i])
        assert abs(llh[2] - h[i]) < 1e-6 and abs(llh[0] - lat[i]) < 1e-12
        assert np.allclose(_core.earth.geodetic_to_ecef(lat[i], lon[i], h[i]), r[i], atol=1e-7, rtol=0)


def test_C_en_and_rates_match_cpp():
    for lat, lon in [(0.3, 1.0), (-1.2, -2.5), (1.5, 0.1)]:
        assert np.allclose(earth.C_en(lat, lon), _core.earth.C_en(lat, lon), atol=1e-15)
        v = np.array([12.0, -7.0, 0.5])
        assert np.allclose(earth.omega_en_n(lat, 300.0, v), _core.earth.omega_en_n(lat, 300.0, v), rtol=1e-14)
        assert np.allclose(earth.omega_ie_n(lat), _core.earth.omega_ie_n(lat), rtol=1e-15)
    # the NED down axis is the negative ellipsoid normal: C_en[:, 2] = -r_e/|r_e| at the equator
    assert np.allclose(earth.C_en(0.0, 0.4)[:, 2], -np.array([np.cos(0.4), np.sin(0.4), 0.0]))


def test_euler_dcm_round_trip_near_gimbal_lock():
    R = _core.rotation
    rng = np.random.default_rng(2)
    worst = 0.0
    for k in range(3000):
        pitch = rng.uniform(-np.pi / 2, np.pi / 2)
        if k % 3 == 0:
            pitch = np.sign(rng.uniform(-1, 1)) * (np.pi / 2 - 10.0 ** -rng.uniform(1, 12))
        rpy = np.array([rng.uniform(-np.pi, np.pi), pitch, rng.uniform(-np.pi, np.pi)])
        C = R.dcm_from_euler(rpy)
        worst = max(worst, np.abs(R.dcm_from_euler(R.euler_from_dcm(C)) - C).max())
        # away from the lock the angles themselves come back
        if abs(pitch) < np.pi / 2 - 1e-3:
            assert np.allclose(R.euler_from_dcm(C), rpy, atol=1e-12)
    assert worst < 1e-9


def test_rotation_vector_small_angle_series():
    R = _core.rotation
    for a in [0.0, 1e-15, 1e-9, 1e-5, 9.99e-5, 1.0001e-4, 0.3, 3.0]:
        phi = np.array([0.2, -0.7, 0.4]) / np.linalg.norm([0.2, -0.7, 0.4]) * a
        q = R.quat_from_rotvec(phi)
        assert np.isclose(np.linalg.norm(q), 1.0, atol=1e-15)
        assert np.allclose(R.rotvec_from_quat(q), phi, atol=1e-16 + 1e-14 * a)
        # Rodrigues closed form
        if a > 1e-3:
            k = phi / a
            K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            C = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
            assert np.allclose(R.dcm_from_rotvec(phi), C, atol=1e-14)
