"""Initial alignment (insnav.ins.align): levelling within the accelerometer-bias
limit, gyrocompassing within its own limit for a navigation-grade IMU, the
heading from GNSS velocity for a MEMS IMU, static-start detection, and the
named IMU grades."""
import numpy as np
import pytest

import insnav
from insnav.ins.align import IMU_GRADES, align, gyrocompass, imu_grade, level, static_interval
from insnav.sim.scenario import resolve_raw

G = 9.80665


def _wrap(d):
    return (d + 180.0) % 360.0 - 180.0


def _att_error(a, truth):
    k = int(np.argmin(np.abs(truth.t - a.t_s)))
    return np.array([a.roll_deg - truth.roll_deg[k], a.pitch_deg - truth.pitch_deg[k],
                     _wrap(a.yaw_deg - truth.yaw_deg[k])])


def test_level_and_gyrocompass_are_exact_without_errors():
    """Analytic case: the ideal specific force and Earth rate of a known attitude."""
    lat = np.radians(34.0)
    for rpy in ([0.1, -0.2, 0.7], [-0.3, 0.25, -2.5], [0.0, 0.0, 3.0]):
        r, p, y = rpy
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        C_nb = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array(
            [[cp, sp * sr, sp * cr], [0, cr, -sr], [-sp, cp * sr, cp * cr]])
        f_b = C_nb.T @ np.array([0.0, 0.0, -G])
        w_b = C_nb.T @ (7.292115e-5 * np.array([np.cos(lat), 0.0, -np.sin(lat)]))
        rr, pp = level(f_b)
        assert rr == pytest.approx(r, abs=1e-12) and pp == pytest.approx(p, abs=1e-12)
        assert _wrap(np.degrees(gyrocompass(w_b, rr, pp) - y)) == pytest.approx(0.0, abs=1e-9)


def _nav_grade(raw):
    raw["imu"]["gyro"] = {"bias_sigma_dph": 0.01, "arw_deg_per_sqrth": 0.002}
    raw["imu"]["accel"] = {"bias_sigma_mg": 0.025, "vrw_mps_per_sqrth": 0.002}
    return raw


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_navigation_grade_gyrocompasses(seed):
    raw, _ = resolve_raw("seed000-car")  # 20 s standstill, then drives
    ds = insnav.simulate(_nav_grade(raw), seed=seed)
    gr = IMU_GRADES["navigation"]
    a = align(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b, ds.gnss, gyro_bias_sigma=gr["gyro_bias_sigma"],
              gyro_arw=gr["gyro_arw"], accel_bias_sigma=gr["accel_bias_sigma"])
    assert a.heading_source == "gyrocompass"
    assert 15.0 < a.static_s <= 20.0 and a.t_s <= ds.t0 + 20.0  # before the car moves
    e = _att_error(a, ds.truth)
    # levelling limit b_a / g (2x), gyrocompassing limit from its own sigma (3x)
    assert np.all(np.abs(e[:2]) < 2 * np.degrees(gr["accel_bias_sigma"] / G) + 1e-3), e
    assert abs(e[2]) < 3 * a.sigma_att_deg[2] and a.sigma_att_deg[2] < 0.2, (e, a.sigma_att_deg)
    np.testing.assert_array_equal(a.v_n_mps, 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_mems_heading_from_gnss_velocity(seed):
    ds = insnav.simulate("seed000-car", seed=seed)  # 30 deg/h gyro: gyrocompassing useless
    a = align(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b, ds.gnss, gyro_bias_sigma=30 * np.pi / 180 / 3600,
              gyro_arw=0.2 * np.pi / 180 / 60, accel_bias_sigma=5e-3 * G)
    assert a.heading_source == "gnss_velocity"
    assert a.t_s < ds.t0 + 20.0 + 10.0  # within the first 10 s of motion
    e = _att_error(a, ds.truth)
    assert abs(e[2]) < 2.0, e
    assert np.all(np.abs(e[:2]) < 2 * np.degrees(5e-3) + 0.2), e  # levelling limit + the carried drift
    k = int(np.argmin(np.abs(ds.truth.t - a.t_s)))
    assert np.linalg.norm(a.v_n_mps - ds.truth.v_n[k]) < 4 * 0.15 + 0.05


def test_static_interval_ends_when_the_car_starts():
    ds = insnav.simulate("seed000-car", seed=5)
    _, k = static_interval(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b)
    assert 19.0 <= ds.imu.t[k - 1] - ds.t0 <= 20.0


def test_imu_grades():
    assert set(IMU_GRADES) == {"consumer", "industrial", "tactical", "navigation"}
    order = ["navigation", "tactical", "industrial", "consumer"]
    for key in ("gyro_bias_sigma", "gyro_arw", "accel_bias_sigma", "accel_vrw"):
        vals = [IMU_GRADES[g][key] for g in order]
        assert all(a < b for a, b in zip(vals, vals[1:])), key
    with pytest.raises(ValueError, match="did you mean 'tactical'"):
        imu_grade("tactial")


def test_dataset_noise_model_from_grade_or_error(tmp_path):
    """dataset.json without an IMU model is an error naming the keys; with
    imu_grade the grade's numbers are used; a misspelt imu_model key is named
    with a suggestion; both keys at once are refused."""
    import json

    from insnav.data.dataset import load_dataset

    out = insnav.simulate("seed000-sim", seed=1).save(tmp_path / "ds")
    meta_path = out / "dataset.json"
    meta = json.loads(meta_path.read_text())
    model = meta.pop("imu_model")
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="no IMU noise model.*imu_grade"):
        insnav.run(load_dataset(out))
    meta["imu_grade"] = "tactical"
    meta_path.write_text(json.dumps(meta))
    ds = load_dataset(out)
    assert ds.imu_model["gyro_gm_sigma"][0] == pytest.approx(IMU_GRADES["tactical"]["gyro_bias_sigma"])
    assert insnav.run(ds).summary["updates"] > 50
    meta["imu_grade"] = "tactial"
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"dataset.json.*did you mean 'tactical'"):
        load_dataset(out)
    meta["imu_grade"] = "tactical"
    meta["imu_model"] = model
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="not both"):
        load_dataset(out)
    del meta["imu_grade"]
    model["gyro_arw_typo"] = model.pop("gyro_arw")
    meta["imu_model"] = model
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="did you mean 'gyro_arw'"):
        insnav.run(load_dataset(out))
