"""The self-calibration states (``[time] estimate_offset``, ``[lever_arm]
estimate``; ``cpp/include/insnav/filter/layout.hpp``, docs/algorithms.md
section 21): exact reduction to the runs without them, recovery of an
injected time offset and lever arm on a short simulated drive, the outputs,
and bad configuration as one-line errors.  The H columns are checked against
numerical derivatives in ``cpp/tests/test_selfcal_jacobian.cpp``."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import insnav
import insnav.sim as sim
from insnav.config import ConfigError, LeverArmEstimation, RunConfig, TimeOffset, config_from_dict


def _short_car(seed: int, lever_arm_b=(0.0, 0.0, 0.0), t_end_s: float = 130.0):
    """car-mems cut after its first left turn (~110 s: a stop, accelerations, a 90 deg turn), RTK-grade fixes."""
    segs, tot = [], 0.0
    for seg in sim.load_scenario("car-mems").raw["motion"]["segments"]:
        if tot >= t_end_s:
            break
        segs.append(seg)
        tot += float(seg["duration_s"])
    sc = {"extends": "car-mems", "name": "selfcal-short", "motion": {"segments": segs},
          "gnss": {"rate_hz": 5.0, "sigma_h_m": 0.02, "sigma_v_m": 0.04, "sigma_vel_mps": 0.02,
                   "lever_arm_b_m": list(lever_arm_b)}}
    return sim.simulate(sc, seed=seed)


def _retag(ds, t_d):
    """Fixes tagged t_d late: the fix tagged t holds the antenna at t - t_d."""
    g = ds.gnss
    return dataclasses.replace(ds, gnss=dataclasses.replace(g, t_valid=g.t_valid + t_d, t_arrival=g.t_arrival + t_d))


@pytest.fixture(scope="module")
def car():
    return _short_car(seed=3)


def _same(a, b):
    for f in ("t", "lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "pitch_deg", "yaw_deg", "sigma_pos_n_m"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


def test_options_off_give_the_plain_solution_bit_for_bit(car):
    """Both tables present but off: the 15-state run, every row identical (not close)."""
    a = insnav.run(car)
    b = insnav.run(car, time=TimeOffset(estimate_offset=False, offset_sigma_ms=5.0),
                   lever_arm={"estimate": False, "sigma_m": 0.1})
    _same(a, b)
    assert b.time_offset_s is None and b.lever_arm_b_m is None and b.summary["layout"] == 15


def test_states_with_a_tiny_prior_reduce_to_the_plain_run(car):
    """Exact reduction: a time offset of prior sigma 1e-6 ms and a lever arm of 1e-9 m add columns whose
    states cannot move: the solution equals the 15-state run to 1e-9 (not bit for bit: more states,
    other round-off), and the estimates stay at their initial values."""
    a = insnav.run(car)
    b = insnav.run(car, time={"estimate_offset": True, "offset_sigma_ms": 1e-6},
                   lever_arm={"estimate": True, "sigma_m": 1e-9})
    assert b.summary["layout"] == 19
    np.testing.assert_allclose(b.lat_deg, a.lat_deg, rtol=0, atol=1e-12)  # 1e-12 deg = 0.1 um
    np.testing.assert_allclose(b.v_n, a.v_n, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.yaw_deg, a.yaw_deg, rtol=0, atol=1e-9)
    assert np.abs(b.time_offset_s).max() < 1e-10
    np.testing.assert_allclose(b.lever_arm_b_m, np.broadcast_to(car.lever_arm_b, b.lever_arm_b_m.shape), atol=1e-12)


def test_zero_offset_cost_is_the_estimate_error_times_the_speed(car):
    """At a true offset of zero the state's whole cost is its estimation error: the fix tagged t is
    applied at t - t_d^, so the INS is pulled v t_d^ along the track (docs/algorithms.md section 21).
    The horizontal error with the state minus the error without it equals v_n t_d^(t) to 5 % rms
    (the extra error itself is 7 cm on this short drive, the residual 1 mm: any other difference,
    e.g. a wrongly propagated covariance, would show in it), and t_d^ stays within 3 sigma of the
    truth (0)."""
    tr = car.truth
    a = insnav.run(car)
    b = insnav.run(car, time={"estimate_offset": True})
    deg = np.pi / 180.0

    def en(s):
        lat, lon = np.interp(tr.t, s.t, s.lat_deg), np.interp(tr.t, s.t, s.lon_deg)
        return np.column_stack([(lat - tr.lat_deg) * deg * 6.371e6,
                                (lon - tr.lon_deg) * deg * 6.371e6 * np.cos(tr.lat_deg[0] * deg)])

    m = tr.t > 20.0  # after the initial stop (t_d unobservable there)
    extra = (en(b) - en(a))[m]
    shift = tr.v_n[m, :2] * np.interp(tr.t, b.t, b.time_offset_s)[m, None]
    rms = lambda x: float(np.sqrt(np.mean(np.sum(x ** 2, axis=1))))  # noqa: E731
    print(f"extra {rms(extra):.4f} m, v t_d^ {rms(shift):.4f} m, residual {rms(extra - shift):.5f} m")
    assert rms(extra) > 0.01  # the cost is there to explain (RTK-grade fixes, t_d^ of a few ms)
    assert rms(extra - shift) < 0.05 * rms(extra)
    z = b.time_offset_s[b.t > 20.0] / b.sigma_time_offset_s[b.t > 20.0]
    assert np.max(np.abs(z)) < 3.0


def test_auto_at_zero_offset_returns_the_plain_run_bit_for_bit(car):
    """``estimate_offset = "auto"`` at a true offset of zero (docs/algorithms.md section 21): the Wald
    statistic t_d^ / sigma of the run with the state is below the 1 % threshold (2.576), so the run
    without the state comes back, every row identical, with the test in the summary."""
    a = insnav.run(car)
    b = insnav.run(car, time={"estimate_offset": "auto"})
    _same(a, b)
    test = b.summary["time_offset_test"]
    print(test)
    assert b.time_offset_s is None and b.summary["layout"] == 15
    assert not test["state_kept"] and test["threshold_z"] == pytest.approx(2.5758293, abs=1e-6)
    assert abs(test["z"]) < test["threshold_z"]
    assert test["z"] == pytest.approx(test["estimate_ms"] / test["sigma_ms"], rel=1e-12)


def test_auto_with_an_offset_keeps_the_state(car):
    """A 100 ms offset: "auto" keeps the run with the state (bit for bit the estimate_offset = true run),
    the estimate within 3 sigma of the truth and |z| far above the threshold."""
    ds = _retag(car, 0.1)
    full = insnav.run(ds, time={"estimate_offset": True}, max_time_offset_s=np.inf)
    auto = insnav.run(ds, time={"estimate_offset": "auto"}, max_time_offset_s=np.inf)
    _same(full, auto)
    np.testing.assert_array_equal(auto.time_offset_s, full.time_offset_s)
    test = auto.summary["time_offset_test"]
    print(test)
    assert test["state_kept"] and auto.summary["layout"] == 16
    assert abs(test["estimate_ms"] - 100.0) < 3 * test["sigma_ms"]
    assert abs(test["z"]) > 10 * test["threshold_z"]


def test_auto_false_alarm_sets_the_threshold(car):
    """auto_false_alarm = 0.5: the two-sided normal quantile 0.674 (|z| > 0.674 half of the time under
    t_d = 0); the zero-offset drive's |z| of 1.4 then keeps the state."""
    sol = insnav.run(car, time={"estimate_offset": "auto", "auto_false_alarm": 0.5})
    test = sol.summary["time_offset_test"]
    print(test)
    assert test["threshold_z"] == pytest.approx(0.6744898, abs=1e-6)
    assert test["state_kept"] == (abs(test["z"]) > 0.6744898) and sol.summary["layout"] == (16 if test["state_kept"] else 15)
    assert abs(test["z"]) > 0.6744898
    tiny = insnav.run(car, time={"estimate_offset": "auto", "auto_false_alarm": 1e-20}).summary["time_offset_test"]
    assert tiny["threshold_z"] == pytest.approx(9.33604, abs=1e-4) and not tiny["state_kept"]  # no 1 - 5e-21 round-off


@pytest.mark.parametrize("t_d_ms", [-150.0, 80.0])
def test_time_offset_recovered_on_a_short_drive(t_d_ms):
    """An injected offset on 110 s of driving (one turn): the estimate within 2 ms and 3 sigma, and the
    horizontal position error far below the run that ignores the offset."""
    ds = _retag(_short_car(seed=5), t_d_ms * 1e-3)
    sol = insnav.run(ds, time={"estimate_offset": True, "offset_sigma_ms": 250.0})
    est, sig = sol.time_offset_s[-1], sol.sigma_time_offset_s[-1]
    err = est - t_d_ms * 1e-3
    print(f"t_d {t_d_ms:+.0f} ms: estimate {1e3 * est:+.3f} ms, sigma {1e3 * sig:.3f} ms, "
          f"summary {sol.summary['time_offset_ms']:+.3f} ms, layout {sol.summary['layout']}")
    assert sol.summary["layout"] == 16
    assert abs(err) < 2e-3 and abs(err) < 3 * sig
    assert sig < 0.01 * 0.25  # from 250 ms to below 2.5 ms
    tr = ds.truth

    def hor(s):
        m = (tr.t > s.t[0] + 30) & (tr.t <= s.t[-1])
        dn = (np.interp(tr.t[m], s.t, s.lat_deg) - tr.lat_deg[m]) * np.pi / 180 * 6.37e6
        de = (np.interp(tr.t[m], s.t, s.lon_deg) - tr.lon_deg[m]) * np.pi / 180 * 6.37e6 * np.cos(tr.lat_deg[0] * np.pi / 180)
        return float(np.sqrt(np.mean(dn ** 2 + de ** 2)))

    plain = insnav.run(ds)
    assert hor(sol) < 0.5 * hor(plain)


def test_lever_arm_recovered_on_a_short_drive():
    """A 1.5 m lever arm, the filter starting from zero (sigma 1 m): after one turn the horizontal
    components within 10 cm and 3 sigma (the full drive: docs/results/selfcal_states.md)."""
    l_true = np.array([1.0, 0.5, -1.0])
    ds = _short_car(seed=6, lever_arm_b=l_true)
    sol = insnav.run(ds, lever_arm_b=[0.0, 0.0, 0.0], lever_arm=LeverArmEstimation(estimate=True, sigma_m=1.0))
    est, sig = sol.lever_arm_b_m[-1], sol.sigma_lever_arm_b_m[-1]
    print(f"lever arm {est} m, sigma {sig} m")
    assert sol.summary["layout"] == 18
    assert np.all(np.abs(est[:2] - l_true[:2]) < 0.1)
    assert np.all(np.abs(est - l_true) < 3 * sig + 1e-3)


def test_lever_arm_estimate_does_not_shrink_towards_zero():
    """The filter's error is linear in the state error, not in the truth: the same drive and noise with a
    vertical lever arm of 0 and of -3 m (antenna 3 m above the IMU), each run started at its truth, end
    with estimates 3 m apart (within 10 %).  The velocity rows' lever-arm columns take a low-passed rate
    without the current increment (engine/closed_loop.hpp, omega_ib_b_lever); with the increment's own
    rate, whose gyro white noise the residual also holds, this level drive kept 0.31 of the 3 m (an
    errors-in-variables bias towards zero)."""
    est = []
    for lz in (0.0, -3.0):
        ds = _short_car(seed=8, lever_arm_b=(0.0, 0.0, lz))
        sol = insnav.run(ds, lever_arm={"estimate": True, "sigma_m": 1.0})
        est.append(float(sol.lever_arm_b_m[-1, 2]))
    kept = (est[1] - est[0]) / -3.0
    print(f"l_z estimates {est} m: kept share {kept:.3f}")
    assert kept == pytest.approx(1.0, abs=0.1)


def _rocking_car(seed: int, lever_arm_b):
    """_short_car with roll and pitch excitation (5 deg at 6 s and 8 s periods): the lever arm observable
    on all three axes (omega_x, omega_y x l in the velocity rows; docs/algorithms.md section 21)."""
    segs = sim.load_scenario("car-mems").raw["motion"]["segments"][:4]
    t_end = sum(float(s["duration_s"]) for s in segs)
    osc = [{"axis": "roll", "amp_deg": 5.0, "period_s": 6.0, "start_s": 20.0, "end_s": t_end},
           {"axis": "pitch", "amp_deg": 5.0, "period_s": 8.0, "start_s": 20.0, "end_s": t_end}]
    sc = {"extends": "car-mems", "name": "selfcal-rocking", "motion": {"segments": segs, "oscillations": osc},
          "gnss": {"rate_hz": 5.0, "sigma_h_m": 0.02, "sigma_v_m": 0.04, "sigma_vel_mps": 0.02,
                   "lever_arm_b_m": list(lever_arm_b)}}
    return sim.simulate(sc, seed=seed)


def test_lever_arm_with_roll_and_pitch_excitation_is_consistent():
    """A 1.5 m lever arm on 100 s of rocking drive, the filter from zero (sigma 1 m): every component
    within 4 cm (3 cm on these seeds; the full drive: docs/results/selfcal_states.md), and rms(error / sigma) over 3 seeds x 3 axes below 1.5 (the filter's sigma tells the
    truth where the motion makes all three components observable)."""
    l_true = np.array([1.0, 0.5, -1.0])
    z, errs = [], []
    for seed in (11, 12, 13):
        ds = _rocking_car(seed, l_true)
        sol = insnav.run(ds, lever_arm_b=[0.0, 0.0, 0.0], lever_arm={"estimate": True, "sigma_m": 1.0})
        e = sol.lever_arm_b_m[-1] - l_true
        errs.append(e)
        z.append(e / sol.sigma_lever_arm_b_m[-1])
        print(f"seed {seed}: error {np.round(100 * e, 2)} cm, sigma {np.round(100 * sol.sigma_lever_arm_b_m[-1], 2)} cm")
    rz = float(np.sqrt(np.mean(np.square(z))))
    print(f"rms(error / sigma) {rz:.2f}")
    assert np.max(np.abs(errs)) < 0.04
    assert 0.3 < rz < 1.5


def test_odometer_lever_arm_moves_to_the_non_slipping_point(car):
    """NHC only: the simulator's car does not slip sideways at the IMU (lever arm 0).  Started from the
    rear-axle guess [-1.3, 0, 0.4] m (sigma 1 m), the forward component, seen in the turn (w_z l_x),
    ends within 0.3 m of 0 and inside 3 sigma, and the sigma has shrunk below half its prior."""
    from insnav.config import Constraints

    con = Constraints(use=["nhc"], lever_arm_b_m=[-1.3, 0.0, 0.4])
    sol = insnav.run(car, constraints=con, lever_arm={"estimate_odometer": True, "odometer_sigma_m": 1.0})
    est, sig = sol.odo_lever_arm_b_m[-1], sol.sigma_odo_lever_arm_b_m[-1]
    print(f"odometer lever arm {est} m, sigma {sig} m")
    assert sol.summary["layout"] == 18
    np.testing.assert_allclose(sol.odo_lever_arm_b_m[0], [-1.3, 0.0, 0.4], atol=0.05)
    assert abs(est[0]) < 0.3 and abs(est[0]) < 3 * sig[0] and sig[0] < 0.5


def test_solution_file_keeps_the_estimates(car, tmp_path):
    sol = insnav.run(_retag(car, 0.05), time={"estimate_offset": True}, lever_arm={"estimate": True},
                     output_decimation=50)
    p = sol.save(tmp_path / "s.csv")
    back = insnav.load_solution(p)
    np.testing.assert_allclose(back.time_offset_s, sol.time_offset_s, atol=1e-9)
    np.testing.assert_allclose(back.sigma_time_offset_s, sol.sigma_time_offset_s, atol=1e-9)
    np.testing.assert_allclose(back.lever_arm_b_m, sol.lever_arm_b_m, atol=1e-6)
    np.testing.assert_allclose(back.sigma_lever_arm_b_m, sol.sigma_lever_arm_b_m, atol=1e-6)


def test_tight_time_offset_short():
    """Tight EKF (seed003-4sat's 10 m pseudoranges and Doppler, 120 s): an offset of +100 ms re-tagged
    onto the epochs is recovered within 3 sigma, the sigma down from 250 ms to below 30 ms."""
    from conftest import short_tight_dataset

    ds = short_tight_dataset()
    raw = ds.gnss_raw
    ds = dataclasses.replace(ds, gnss_raw=dataclasses.replace(raw, t=np.asarray(raw.t) + 0.1))
    sol = insnav.run(ds, coupling="tight", time={"estimate_offset": True, "offset_sigma_ms": 250.0})
    est, sig = sol.time_offset_s[-1], sol.sigma_time_offset_s[-1]
    print(f"tight: estimate {1e3 * est:+.2f} ms, sigma {1e3 * sig:.2f} ms, layout {sol.summary['layout']}")
    assert sol.summary["layout"] == 18
    assert abs(est - 0.1) < 3 * sig and sig < 0.03
    auto = insnav.run(ds, coupling="tight", time={"estimate_offset": "auto", "offset_sigma_ms": 250.0})
    assert auto.summary["time_offset_test"]["state_kept"]  # z = 0.1 / sigma > 3.3 > 2.576
    np.testing.assert_array_equal(auto.time_offset_s, sol.time_offset_s)


@pytest.mark.parametrize("d, key", [
    ({"time": {"estimate_ofset": True}}, "'time.estimate_ofset'"),
    ({"time": {"offset_sigma_ms": -1.0}}, "'time.offset_sigma_ms'"),
    ({"time": {"estimate_offset": "yes"}}, "'time.estimate_offset'"),
    ({"time": {"estimate_offset": "auto", "auto_false_alarm": 0.0}}, "'time.auto_false_alarm'"),
    ({"time": {"estimate_offset": "auto", "auto_false_alarm": 0.7}}, "'time.auto_false_alarm'"),
    ({"time": {"estimate_offset": "auto"}, "layout": 21}, "'time.estimate_offset'"),
    ({"time": {"estimate_offset": True}, "filter": "rbukf"}, "'time.estimate_offset'"),
    ({"time": {"estimate_offset": True}, "layout": 21}, "'time.estimate_offset'"),
    ({"time": {"estimate_offset": True}, "smooth": True}, "'time.estimate_offset'"),
    ({"lever_arm": {"estimate": True}, "filter": "ukf"}, "'lever_arm.estimate'"),
    ({"lever_arm": {"sigma_m": 0.0}}, "'lever_arm.sigma_m'"),
    ({"lever_arm": {"psd_m2_per_s": float("nan")}}, "'lever_arm.psd_m2_per_s'"),
    ({"lever_arm": 3}, "'lever_arm'"),
    ({"lever_arm": {"estimate": True}, "constraints": {"use": ["odo"]}}, "'lever_arm.estimate'"),
    ({"lever_arm": {"estimate_odometer": True}}, "'lever_arm.estimate_odometer'"),
    ({"lever_arm": {"estimate_odometer": True, "estimate": True}, "constraints": {"use": ["nhc"]}},
     "'lever_arm.estimate_odometer'"),
    ({"lever_arm": {"estimate_odometer": True}, "constraints": {"use": ["nhc"]}, "coupling": "tight"},
     "'constraints.use'"),
])
def test_bad_configuration_is_one_line_naming_the_key(d, key):
    with pytest.raises(ConfigError) as e:
        config_from_dict(d, source="run.toml")
    msg = str(e.value)
    print(msg)
    assert key in msg and "\n" not in msg and msg.startswith("run.toml")


def test_python_api_checks_the_same(car):
    with pytest.raises(ConfigError, match="'time.estimate_offset'.*ekf loose, ekf tight"):
        insnav.run(car, filter="ukf", time={"estimate_offset": True})
    with pytest.raises(ConfigError, match="'time.estimate_offset'"):
        RunConfig(filter="exact", time=TimeOffset(estimate_offset=True)).validate()


def test_a_run_config_asking_for_the_self_calibration_states_over_a_kfgins_yaml(tmp_path):
    """``--format kfgins`` loads the YAML as the 21-state model with its initial scale factors.  A
    ``--run-config`` with ``[time] estimate_offset = "auto"`` said "bad value True; allowed: false with
    layout = 21" (the value it echoed was not the one given, no file named); with ``layout = 15`` added,
    "config key 'init_acc_scale': bad value [0.0, 0.0, 0.0]; allowed: absent", a key the user never
    wrote.  Now the first names the file, the value and the remedy, and the second runs: the YAML's zero
    initial scale factors do not apply to the 15-state layout.  A non-zero one is refused, naming it."""
    from insnav.cli.run import _overlay_run_config
    from insnav.errors import UserError

    def kfgins_cfg(scale=0.0):
        return RunConfig(layout=21, init_acc_scale=[scale] * 3, init_gyro_scale=[0.0] * 3,
                         init_sigma_acc_scale=[1e-3] * 3, init_sigma_gyro_scale=[1e-3] * 3)

    a = tmp_path / "a.toml"
    a.write_text('[time]\nestimate_offset = "auto"\n')
    with pytest.raises(UserError, match=rf"--run-config {a}: config key 'time.estimate_offset': bad value 'auto'; "
                                        r"allowed: false with layout = 21 .*set layout = 15"):
        _overlay_run_config(kfgins_cfg(), a)
    b = tmp_path / "b.toml"
    b.write_text('layout = 15\n[time]\nestimate_offset = "auto"\n')
    cfg = _overlay_run_config(kfgins_cfg(), b)
    assert cfg.layout == 15 and cfg.time.estimate_offset == "auto"
    assert cfg.init_acc_scale is None and cfg.init_sigma_gyro_scale is None
    with pytest.raises(UserError, match=r"layout = 15 has no scale-factor states, but the KF-GINS YAML gives "
                                        r"initaccscale = \[0.001, 0.001, 0.001\]"):
        _overlay_run_config(kfgins_cfg(1e-3), b)


def test_the_command_line_prints_the_estimated_lever_arms(car, tmp_path, capsys):
    """``[lever_arm] estimate_odometer``: the run computed the odometer lever arm and the command line
    lost it (no column, no line).  It now prints the last estimate and its 1-sigma, as the API's
    summary holds them."""
    from insnav.cli import main

    d = car.save(tmp_path / "car")
    toml = tmp_path / "odo.toml"
    toml.write_text('[constraints]\nuse = ["nhc"]\nlever_arm_b_m = [-1.3, 0.0, 0.4]\n'
                    '[lever_arm]\nestimate_odometer = true\nodometer_sigma_m = 1.0\n')
    capsys.readouterr()
    assert main(["run", str(d), "--config", str(toml), "--out", str(tmp_path / "s.csv"), "-q"]) == 0
    out = capsys.readouterr().out
    from insnav.config import Constraints

    sol = insnav.run(car, constraints=Constraints(use=["nhc"], lever_arm_b_m=[-1.3, 0.0, 0.4]),
                     lever_arm={"estimate_odometer": True, "odometer_sigma_m": 1.0})
    est, sig = sol.summary["odo_lever_arm_b_m"], sol.summary["sigma_odo_lever_arm_b_m"]
    want = (f"odometer lever arm (body x, y, z): {', '.join(f'{v:+.3f}' for v in est)} +- "
            f"{', '.join(f'{v:.3f}' for v in sig)} m")
    assert want in out, out


def test_tune_settles_auto_once_and_writes_it(car):
    """``[time] estimate_offset = "auto"`` under ``tune``: settled by the test before the search (on the
    base settings), so the tuning runs, the report runs and the written file carry one model; the file
    says true or false, and the base likelihood is that of the settled model."""
    from insnav.calib.tune import tune, tuned_toml_dict
    from insnav.config import RunConfig, TimeOffset

    for ds, kept in ((car, False), (_retag(car, 0.1), True)):
        cfg = RunConfig(time=TimeOffset(estimate_offset="auto"), max_time_offset_s=np.inf)
        res = tune(ds, cfg, params=["gnss_pos", "gnss_vel"], max_runs=8, holdout=0.3)
        assert res.time_offset_test is not None and res.time_offset_test["state_kept"] is kept
        assert res.tuned.time.estimate_offset is kept and res.base.time.estimate_offset is kept
        assert tuned_toml_dict({"time": {"estimate_offset": "auto"}}, res)["time"]["estimate_offset"] is kept
        settled = dataclasses.replace(cfg, time=TimeOffset(estimate_offset=kept))
        ref = tune(ds, settled, params=["gnss_pos", "gnss_vel"], max_runs=8, holdout=0.3)
        assert ref.time_offset_test is None
        assert res.log_likelihood_base == ref.log_likelihood_base
        assert res.scales == ref.scales
