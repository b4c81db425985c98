"""Simulator truth: self-consistency, free-inertial reproduction, scenario errors."""
import numpy as np
import pytest

import insnav.sim as sim
from insnav import earth
from insnav.sim.scenario import ScenarioError, load_scenario, resolve_raw
from insnav.sim.trajectory import Trajectory, rotate_n_to_b


def _error_free(preset):
    raw, _ = resolve_raw(preset)
    raw["imu"].pop("gyro", None)
    raw["imu"].pop("accel", None)
    return raw


def _ned_error_m(lat_deg, lon_deg, h, lat_ref, lon_ref, h_ref):
    lat = np.radians(lat_ref)
    R_M, R_N = earth.radii(lat)
    dn = np.radians(lat_deg - lat_ref) * (R_M + h_ref)
    de = np.radians(lon_deg - lon_ref) * (R_N + h_ref) * np.cos(lat)
    return np.sqrt(dn ** 2 + de ** 2 + (h - h_ref) ** 2)


@pytest.mark.parametrize("preset", ["seed000-sim", "seed003-4sat"])
def test_velocity_is_derivative_of_position(preset):
    traj = Trajectory(load_scenario(preset))
    t = np.linspace(traj.t0 + 1.0, traj.t_end - 1.0, 400)
    d = 1e-3
    lat_p, lon_p, h_p = traj.position(t + d)
    lat_m, lon_m, h_m = traj.position(t - d)
    lat, _, h = traj.position(t)
    R_M, R_N = earth.radii(lat)
    v_fd = np.stack([(lat_p - lat_m) / (2 * d) * (R_M + h),
                     (lon_p - lon_m) / (2 * d) * (R_N + h) * np.cos(lat),
                     -(h_p - h_m) / (2 * d)], axis=-1)
    v = traj.kinematics(t).v_n
    # central difference error ~ d^2/6 * jerk, plus rounding ~ 1e-9 m / 1e-3 s
    assert np.max(np.abs(v_fd - v)) < 2e-5


def test_position_integration_converges():
    sc = load_scenario("seed001-low")
    t = np.linspace(sc.t0, sc.t_end, 50)
    a = np.stack(Trajectory(sc, grid_step=0.05).position(t), -1)
    b = np.stack(Trajectory(sc, grid_step=0.01).position(t), -1)
    dn = (a[:, 0] - b[:, 0]) * 6.4e6
    de = (a[:, 1] - b[:, 1]) * 6.4e6
    assert np.max(np.abs(dn)) < 1e-6 and np.max(np.abs(de)) < 1e-6
    assert np.max(np.abs(a[:, 2] - b[:, 2])) < 1e-6


def test_acceleration_and_euler_rates_are_derivatives():
    traj = Trajectory(load_scenario("seed003-4sat"))  # coordinated turns, climbs
    t = np.linspace(1.0, traj.t_end - 1.0, 500)
    d = 1e-4
    kp, km, k0 = traj.kinematics(t + d), traj.kinematics(t - d), traj.kinematics(t)
    assert np.max(np.abs((kp.v_n - km.v_n) / (2 * d) - k0.a_n)) < 1e-5
    assert np.max(np.abs((kp.euler - km.euler) / (2 * d) - k0.euler_rate)) < 1e-7


def test_attitude_matches_integrated_angular_rate():
    """Integrate C_nb' = C_nb [omega_nb_b x] (from f/omega truth) and compare with the Euler angles."""
    traj = Trajectory(load_scenario("seed000-sim"))
    t = np.arange(0.0, 150.0 + 1e-9, 0.002)
    st = traj.state(t, exact_position=False)
    w_in_b = rotate_n_to_b(st["euler"], earth.omega_ie_n(st["lat"])
                           + earth.omega_en_n(st["lat"], st["h"], st["v_n"]))
    omega_nb_b = st["omega_ib_b"] - w_in_b

    def dcm(e):
        r, p, y = e
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                         [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                         [-sp, cp * sr, cp * cr]])

    C = dcm(st["euler"][0])
    worst = 0.0
    for k in range(1, len(t)):
        # rotation vector over the step: trapezoid of omega_nb_b (2nd order)
        phi = 0.5 * (omega_nb_b[k - 1] + omega_nb_b[k]) * (t[k] - t[k - 1])
        a = np.linalg.norm(phi)
        K = np.array([[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]])
        R = np.eye(3) + (np.sin(a) / a if a > 0 else 1.0) * K + \
            ((1 - np.cos(a)) / a ** 2 if a > 0 else 0.5) * K @ K
        C = C @ R
        if k % 5000 == 0:
            E = C.T @ dcm(st["euler"][k])
            worst = max(worst, np.linalg.norm([E[2, 1], E[0, 2], E[1, 0]]))
    assert worst < 1e-5  # rad, after 150 s of 15 deg / 8 s rolling


def test_commanded_changes_are_reached():
    traj = Trajectory(load_scenario("seed001-low"))
    k = traj.kinematics(np.array([0.0, 40.5, 55.5, 172.5, 175.0]))
    speed = np.linalg.norm(k.v_n, axis=1)
    assert speed[0] == pytest.approx(10.0, abs=1e-12)
    assert speed[1] == pytest.approx(10.0, abs=1e-9)
    # start east (90 deg), +90 deg turn -> south; -30, +30, -90 deg -> east again
    assert abs(np.degrees(k.euler[2, 2])) == pytest.approx(180.0, abs=1e-9)
    assert speed[3] == pytest.approx(0.0, abs=1e-9) and speed[4] == pytest.approx(0.0, abs=1e-9)
    assert np.degrees(k.euler[4, 2]) == pytest.approx(90.0, abs=1e-9)


def _mechanize_or_skip():
    try:
        import insnav._core  # noqa: F401
    except ImportError as exc:
        pytest.skip(f"insnav._core not importable ({exc}); build with 'make dev'")
    import insnav

    return insnav.mechanize


@pytest.mark.parametrize("preset,limit", [("seed000-sim", 0.05), ("seed001-low", 0.1)])
def test_free_inertial_reproduces_truth(preset, limit):
    mechanize = _mechanize_or_skip()
    ds = sim.simulate(_error_free(preset))
    sol = mechanize(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b, ds.initial, ds.t0)
    T = ds.truth
    assert np.allclose(T.t[1:], sol.t)
    err = _ned_error_m(sol.lat_deg, sol.lon_deg, sol.h_m, T.lat_deg[1:], T.lon_deg[1:], T.h_m[1:])
    assert err[-1] < limit and err.max() < limit
    assert np.max(np.abs(sol.v_n - T.v_n[1:])) < 1e-3


def test_bad_scenario_names_key():
    raw, _ = resolve_raw("seed001-low")
    raw["motion"]["segments"][3]["turn_rate_dps"] = "fast"
    with pytest.raises(ScenarioError, match=r"motion\.segments\[3\]\.turn_rate_dps.*expected a number"):
        load_scenario(raw)
    raw, _ = resolve_raw("seed001-low")
    raw["imu"]["gyro"]["arw_dph"] = 1.0
    with pytest.raises(ScenarioError, match=r"imu\.gyro\.arw_dph.*unknown key.*arw_deg_per_sqrth"):
        load_scenario(raw)
    raw, _ = resolve_raw("seed001-low")
    raw["gnss"]["delay_p"] = [0.5, 0.4]
    with pytest.raises(ScenarioError, match=r"gnss\.delay_p.*sum to 1"):
        load_scenario(raw)
    raw, _ = resolve_raw("seed001-low")
    del raw["initial"]["lat_deg"]
    with pytest.raises(ScenarioError, match=r"initial\.lat_deg.*missing"):
        load_scenario(raw)
    raw, _ = resolve_raw("seed001-low")
    raw["motion"]["segments"][1]["target_speed_mps"] = 20.0
    raw["motion"]["segments"][1]["accel_mps2"] = 1.0
    with pytest.raises(ScenarioError, match=r"motion\.segments\[1\]\.target_speed_mps.*conflicts"):
        load_scenario(raw)
    raw, _ = resolve_raw("seed001-low")
    raw["run"]["gate_chi2"] = 20.0  # only run defaults of the data belong in a preset
    with pytest.raises(ScenarioError, match=r"run\.gate_chi2.*unknown key.*gate_prob"):
        load_scenario(raw)
    raw, _ = resolve_raw("seed001-low")
    raw["run"]["gate_prob"] = 1.0
    with pytest.raises(ScenarioError, match=r"run\.gate_prob"):
        load_scenario(raw)


def test_paper_presets_run_ungated_and_round_trip(tmp_path):
    """The seed-paper presets carry ``[run] gate_prob = 0`` (the papers' filters
    have no innovation gate), through a saved dataset folder too; a preset
    without it gets insnav's default gate (car-mems sets it explicitly)."""
    for name in ("seed000-sim", "seed000-heading", "seed000-car", "seed001-low", "seed001-high"):
        assert resolve_raw(name)[0]["run"] == {"gate_prob": 0.0}, name
    for name in ("seed003-1sat", "seed004-uav"):  # tight: no per-satellite screening either
        assert resolve_raw(name)[0]["run"] == {"gate_prob": 0.0, "robust_screening": False}, name
    assert resolve_raw("car-mems-outage30")[0]["run"] == {"gate_prob": 0.9999}
    assert "run" not in resolve_raw("urban-multignss")[0]
    import insnav
    ds = insnav.simulate({"extends": "seed001-low", "motion": {"segments": [{"duration_s": 20.0}]}}, seed=1)
    back = insnav.load_dataset(ds.save(tmp_path / "d"))
    assert back.scenario["run"] == {"gate_prob": 0.0}


def test_bad_toml_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[initial]\nlat_deg = 30\nlon_deg = 114\nh_m = 10\n[[motion.segments]]\n"
                 "duration_s = -5\n")
    with pytest.raises(ScenarioError, match=r"bad\.toml.*motion\.segments\[0\]\.duration_s.*> 0"):
        load_scenario(p)


def test_unknown_preset_lists_known():
    with pytest.raises(ScenarioError, match=r"unknown preset 'nope'.*seed000-sim.*seed004-uav"):
        load_scenario("nope")


def test_presets_listed_and_loadable():
    names = sim.list_presets()
    for n in ["seed000-sim", "seed000-car", "seed001-low", "seed001-high", "seed003-4sat",
              "seed003-3sat", "seed003-1sat", "seed004-uav"]:
        assert n in names
        load_scenario(n)
    sc = load_scenario("seed004-uav")
    assert np.degrees(sc.lat0) == pytest.approx(34.2) and sc.duration == 1800.0
    assert load_scenario("seed001-high").gnss["delay_p"].tolist() == [0.2, 0.4, 0.2, 0.2]
