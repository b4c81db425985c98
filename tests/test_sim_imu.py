"""IMU error model statistics."""
import numpy as np
import pytest

import insnav.sim as sim
from insnav.sim.imu import _ar1, simulate_sensor_errors
from insnav.sim.scenario import DEG_PER_SQRT_H, UG_PER_SQRT_HZ, SensorErrors


def _errors(**kw):
    z = np.zeros(3)
    base = dict(bias=z, bias_sigma=z, gm_sigma=z, gm_tau=np.full(3, np.inf), bias_rw=z,
                noise_density=z, scale=z, scale_sigma=z, misalignment=np.zeros((3, 3)),
                misalignment_sigma=0.0)
    base.update(kw)
    return SensorErrors(**base)


def allan_deviation(rate, dt, m):
    """Non-overlapping Allan deviation of a rate series at tau = m dt."""
    n = rate.shape[0] // m
    avg = rate[: n * m].reshape(n, m, -1).mean(axis=1)
    return np.sqrt(0.5 * np.mean(np.diff(avg, axis=0) ** 2, axis=0))


def _still_scenario(gyro, accel, rate_hz=100.0, duration=3600.0):
    return {"name": "still", "initial": {"lat_deg": 30.0, "lon_deg": 114.0, "h_m": 0.0},
            "motion": {"segments": [{"duration_s": duration}]},
            "imu": {"rate_hz": rate_hz, "gyro": gyro, "accel": accel},
            "gnss": {"enabled": False}}


def test_allan_deviation_matches_arw_and_vrw():
    arw_dpsh, vrw = 0.2, 60.0  # deg/sqrt(h), ug/sqrt(Hz)
    sc = _still_scenario({"arw_deg_per_sqrth": arw_dpsh}, {"vrw_ug_per_sqrthz": vrw})
    ds = sim.simulate(sc, seed=11, with_truth=False)
    clean = sim.simulate({**sc, "imu": {"rate_hz": 100.0}}, seed=11, with_truth=False)
    dt = 0.01
    w = (ds.imu.dtheta_b - clean.imu.dtheta_b) / dt
    f = (ds.imu.dv_b - clean.imu.dv_b) / dt
    ad_g = allan_deviation(w, dt, 100)  # tau = 1 s: sigma = N / sqrt(tau)
    ad_a = allan_deviation(f, dt, 100)
    assert np.all(np.abs(ad_g / (arw_dpsh * DEG_PER_SQRT_H) - 1) < 0.10), ad_g
    assert np.all(np.abs(ad_a / (vrw * UG_PER_SQRT_HZ) - 1) < 0.10), ad_a


def test_white_per_sample_sigma():
    sc = _still_scenario({"white_dph": 300.0}, {"white_mg": 2.0}, rate_hz=200.0, duration=200.0)
    ds = sim.simulate(sc, seed=2, with_truth=False)
    clean = sim.simulate({**sc, "imu": {"rate_hz": 200.0}}, seed=2, with_truth=False)
    w = (ds.imu.dtheta_b - clean.imu.dtheta_b) * 200.0
    f = (ds.imu.dv_b - clean.imu.dv_b) * 200.0
    assert np.allclose(w.std(axis=0), np.radians(300.0) / 3600.0, rtol=0.02)
    assert np.allclose(f.std(axis=0), 2e-3 * 9.80665, rtol=0.02)


def test_gauss_markov_sigma_and_correlation():
    sigma, tau, dt, n = 2.0, 5.0, 0.01, 400_000
    err = _errors(gm_sigma=np.full(3, sigma), gm_tau=np.full(3, tau))
    real, _ = simulate_sensor_errors(err, n, dt, np.random.default_rng(4))
    b = real.bias
    assert np.all(np.abs(b.std(axis=0) / sigma - 1) < 0.08)  # 4000 s / 5 s: ~800 correlation times
    lag = int(tau / dt)
    rho = np.mean(b[:-lag] * b[lag:], axis=0) / b.var(axis=0)
    assert np.all(np.abs(rho - np.exp(-1)) < 0.06)


def test_ar1_blocks_match_recursion():
    rng = np.random.default_rng(0)
    e = rng.standard_normal((5000, 2))
    phi = np.exp(-0.01)
    x = np.zeros(2)
    ref = np.empty_like(e)
    for k in range(e.shape[0]):
        x = phi * x + e[k]
        ref[k] = x
    assert np.allclose(_ar1(phi, np.zeros(2), e), ref, atol=1e-10)


def test_constant_bias_scale_misalignment_and_saved_errors():
    sc = _still_scenario({"bias_dph": [10.0, -20.0, 30.0], "scale_ppm": [1000.0, 0.0, 0.0]},
                         {"bias_mg": [1.0, 2.0, -3.0],
                          "misalignment_mrad": [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]},
                         duration=10.0)
    ds = sim.simulate(sc, seed=1)
    clean = sim.simulate({**sc, "imu": {"rate_hz": 100.0}}, seed=1)
    dt = 0.01
    dw = (ds.imu.dtheta_b - clean.imu.dtheta_b) / dt
    expect_w = np.radians([10.0, -20.0, 30.0]) / 3600.0
    expect_w = expect_w + np.array([1e-3, 0, 0]) * clean.imu.dtheta_b[:, 0:1].mean() / dt
    assert np.allclose(dw.mean(axis=0), expect_w, rtol=1e-6, atol=1e-12)
    df = (ds.imu.dv_b - clean.imu.dv_b) / dt
    expect_f = np.array([1.0, 2.0, -3.0]) * 9.80665e-3
    expect_f[0] += 1e-3 * clean.imu.dv_b[:, 1].mean() / dt  # M[0,1] * f_y
    assert np.allclose(df.mean(axis=0), expect_f, rtol=1e-6, atol=1e-9)
    assert np.allclose(ds.imu_errors.gyro_bias, np.radians([10.0, -20.0, 30.0]) / 3600.0)
    assert ds.imu_errors.gyro_scale[0] == pytest.approx(1e-3)
    assert ds.imu_errors.accel_misalignment[0, 1] == pytest.approx(1e-3)


def test_seed_reproducible_and_streams_independent():
    a = sim.simulate("seed000-sim", seed=5)
    b = sim.simulate("seed000-sim", seed=5)
    c = sim.simulate("seed000-sim", seed=6)
    assert np.array_equal(a.imu.dtheta_b, b.imu.dtheta_b)
    assert np.array_equal(a.gnss.lat_deg, b.gnss.lat_deg)
    assert not np.array_equal(a.imu.dtheta_b, c.imu.dtheta_b)
    m = a.imu_model
    assert m["gyro_bias"] == pytest.approx(np.radians([20.0, -20.0, 20.0]) / 3600.0)
    assert m["gyro_arw"][0] == pytest.approx(np.radians(300.0 / 3600.0) * np.sqrt(1 / 200.0))
