"""Road-vehicle simulation: body-frame slip and bounce velocities stay exact
(derivatives, free-inertial reproduction), have the configured RMS and vanish
at standstill; the wheel odometer measures the rear-axle forward speed with
its scale factor and quantisation; odometer data survive a save/load."""
import numpy as np
import pytest

import insnav.sim as sim
from insnav import earth
from insnav.data.dataset import load_dataset
from insnav.sim.odometer import forward_speed, simulate_odometer
from insnav.sim.scenario import ScenarioError, load_scenario, resolve_raw
from insnav.sim.trajectory import Trajectory, rotate_n_to_b


@pytest.fixture(scope="module")
def car():
    return Trajectory(load_scenario("car-mems", seed=3))


def test_velocity_and_acceleration_are_derivatives(car):
    t = np.linspace(car.t0 + 1.0, car.t_end - 1.0, 600)
    d = 1e-4
    kp, km, k0 = car.kinematics(t + d), car.kinematics(t - d), car.kinematics(t)
    # bounce up to 18 rad/s: central-difference error ~ d^2 w^3 v / 6 ~ 1e-8
    assert np.max(np.abs((kp.v_n - km.v_n) / (2 * d) - k0.a_n)) < 1e-5
    lat_p, lon_p, h_p = car.position(t + d)
    lat_m, lon_m, h_m = car.position(t - d)
    lat, _, h = car.position(t)
    R_M, R_N = earth.radii(lat)
    v_fd = np.stack([(lat_p - lat_m) / (2 * d) * (R_M + h), (lon_p - lon_m) / (2 * d) * (R_N + h) * np.cos(lat),
                     -(h_p - h_m) / (2 * d)], axis=-1)
    assert np.max(np.abs(v_fd - k0.v_n)) < 1e-4


def test_slip_and_bounce_rms_and_standstill(car):
    t = np.arange(car.t0, car.t_end, 0.01)
    st = car.state(t, exact_position=False)
    v_b = rotate_n_to_b(st["euler"], st["v_n"])
    speed = np.linalg.norm(st["v_n"], axis=1)
    fast = speed > 12.0  # q(V) > 0.85
    assert 0.85 * 0.05 < np.sqrt(np.mean(v_b[fast, 1] ** 2)) < 1.1 * 0.05
    assert 0.85 * 0.03 < np.sqrt(np.mean(v_b[fast, 2] ** 2)) < 1.1 * 0.03
    parked = speed < 1e-9
    assert parked.sum() > 1000 and np.max(np.abs(v_b[parked])) < 1e-12


def test_free_inertial_reproduces_truth():
    raw, _ = resolve_raw("car-mems")
    raw["imu"].pop("gyro", None)
    raw["imu"].pop("accel", None)
    raw["motion"]["segments"] = raw["motion"]["segments"][:8]  # 230 s: start, turns, hills
    ds = sim.simulate(raw, seed=3)
    import insnav

    sol = insnav.mechanize(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b, ds.initial, ds.t0)
    T = ds.truth
    lat = np.radians(T.lat_deg[1:])
    R_M, R_N = earth.radii(lat)
    dn = np.radians(sol.lat_deg - T.lat_deg[1:]) * R_M
    de = np.radians(sol.lon_deg - T.lon_deg[1:]) * R_N * np.cos(lat)
    err = np.sqrt(dn ** 2 + de ** 2 + (sol.h_m - T.h_m[1:]) ** 2)
    assert err.max() < 0.05  # 230 s of error-free increments through slip and bounce
    assert np.max(np.abs(sol.v_n - T.v_n[1:])) < 1e-3


def test_odometer_model(car):
    cfg = dict(car.sc.odometer)
    la = cfg["lever_arm_b"]
    # ideal: the mean forward speed over each interval
    ideal = simulate_odometer(car, dict(cfg, ticks_per_m=0.0, scale_error_sigma=0.0, sigma=0.0),
                              np.random.default_rng(0))
    dt = 1.0 / cfg["rate"]
    ref = forward_speed(car, ideal.t - 0.5 * dt, la)
    assert np.max(np.abs(ideal.speed_mps - ref)) < 5e-3  # midpoint vs interval mean (accelerations < 2 m/s^2)
    # quantisation: the counted distance never differs from the true one by a tick
    q = simulate_odometer(car, dict(cfg, scale_error_sigma=0.0, sigma=0.0), np.random.default_rng(0))
    step = 1.0 / (cfg["ticks_per_m"] * dt)
    assert np.max(np.abs(np.cumsum(q.speed_mps - ideal.speed_mps) * dt)) <= 1.0 / cfg["ticks_per_m"] + 1e-9
    assert np.max(np.abs(q.speed_mps - ideal.speed_mps)) <= step + 1e-9
    # scale factor: the total distance carries (1 + k)
    k = 0.004
    s = simulate_odometer(car, dict(cfg, ticks_per_m=0.0, scale_error=k, scale_error_sigma=0.0, sigma=0.0),
                          np.random.default_rng(0))
    assert s.speed_mps.sum() / ideal.speed_mps.sum() == pytest.approx(1 + k, rel=1e-12)
    # the lever arm: at the rear axle, a left turn at 6 m/s ... the point moves with the body
    # (forward speed of a point 1.3 m behind differs from the IMU's only through omega x l)
    assert np.max(np.abs(forward_speed(car, ideal.t, la) - forward_speed(car, ideal.t, [0, 0, 0]))) < 0.05


def test_odometer_saved_and_loaded(tmp_path):
    raw, _ = resolve_raw("car-mems")
    raw["motion"]["segments"] = raw["motion"]["segments"][:3]
    ds = sim.simulate(raw, seed=1)
    assert ds.odometer is not None and len(ds.odometer) == int(round((ds.imu.t[-1] - ds.t0) * 10))
    out = ds.save(tmp_path / "car")
    back = load_dataset(out)
    np.testing.assert_array_equal(back.odometer.t, ds.odometer.t)
    np.testing.assert_array_equal(back.odometer.speed_mps, ds.odometer.speed_mps)


def test_bad_odometer_keys():
    raw, _ = resolve_raw("car-mems")
    raw["odometer"]["tick_per_m"] = 3
    with pytest.raises(ScenarioError, match="odometer.tick_per_m"):
        load_scenario(raw)
    raw, _ = resolve_raw("car-mems")
    raw["motion"]["lateral_slip_mps"] = -1
    with pytest.raises(ScenarioError, match="motion.lateral_slip_mps"):
        load_scenario(raw)
