"""Vehicle constraints in the loose engine (NHC, odometer, ZUPT/ZARU):
physics that could fail, the standstill detector's false alarms, and bad
configuration as one-line errors."""
from __future__ import annotations

import numpy as np
import pytest

import insnav
from insnav.analysis import errors
from insnav.config import ConfigError, Constraints, RunConfig, config_from_dict

OUTAGE = (500.0, 620.0)  # car-mems-outage120


@pytest.fixture(scope="module")
def car():
    return insnav.simulate("car-mems-outage120", seed=3)


_CAR_RUNS: dict = {}


def _car_run(car, cfg: RunConfig):
    """insnav.run(car, config=cfg), computed once per worker and configuration: several tests
    read the same deterministic run of the module's car (the plain EKF, the forward and smoothed
    EKF and RB-UKF); none modifies it.  test_no_constraints_is_the_plain_run computes its two
    runs afresh."""
    key = (id(car), repr(cfg))
    if key not in _CAR_RUNS:
        _CAR_RUNS[key] = (car, insnav.run(car, config=cfg))  # (the dataset kept alive: its id stays unique)
    return _CAR_RUNS[key][1]


@pytest.fixture(scope="module", autouse=True)
def _free_car_runs():
    """The cached full-output runs of the 900 s drive freed when the module's tests are done."""
    yield
    _CAR_RUNS.clear()


@pytest.fixture(scope="module")
def slip_free():
    """``slip_free(k)``: car-mems-outage120 with seed k and a truth that holds NHC exactly
    (slip and bounce off), simulated once per module (the exact-NHC tests share seeds 0-3)."""
    import dataclasses

    from insnav.sim.scenario import load_scenario

    cache: dict = {}

    def get(k: int):
        if k not in cache:
            sc = dataclasses.replace(load_scenario("car-mems-outage120", seed=k), lateral_slip=0.0,
                                     vertical_bounce=0.0)
            cache[k] = insnav.simulate(sc, seed=k)
        return cache[k]

    return get


def _run(ds, use, **kw):
    return insnav.run(ds, config=RunConfig(filter="ekf", init_seed=3, constraints=Constraints(use=use, **kw)))


def _body_velocity_error(sol, ds):
    """Solution minus truth velocity in body axes (forward, lateral, down) [m/s] at the solution times."""
    from insnav import _core
    from insnav.units import DEG

    tr = ds.truth
    v_t = np.column_stack([np.interp(sol.t, tr.t, tr.v_n[:, i]) for i in range(3)])
    out = np.empty((len(sol.t), 3))
    for k in range(len(sol.t)):
        C_nb = np.asarray(_core.rotation.dcm_from_euler(np.array([sol.roll_deg[k], sol.pitch_deg[k],
                                                                   sol.yaw_deg[k]]) * DEG))
        out[k] = C_nb.T @ (sol.v_n[k] - v_t[k])
    return out


def test_no_constraints_is_the_plain_run(car):
    """An empty [constraints] table changes nothing (same engine path, no event)."""
    a = insnav.run(car, "ekf", init_seed=3)
    b = _run(car, [])
    np.testing.assert_array_equal(a.lat_deg, b.lat_deg)
    assert "constraints" not in b.summary


def test_nhc_holds_the_lateral_velocity_in_an_outage(car):
    """120 s without GNSS: without aiding the body-lateral velocity error grows
    (gyro bias -> heading error -> the speed leaks sideways); NHC keeps it at
    the level of the simulated slip (0.05 m/s RMS)."""
    free = insnav.run(car, "ekf", init_seed=3, output_decimation=200)
    nhc = insnav.run(car, config=RunConfig(filter="ekf", init_seed=3, output_decimation=200,
                                           constraints=Constraints(use=["nhc"])))
    inside = (free.t > OUTAGE[0] + 60) & (free.t < OUTAGE[1])
    lat_free = np.abs(_body_velocity_error(free, car)[inside, 1]).max()
    lat_nhc = np.abs(_body_velocity_error(nhc, car)[inside, 1]).max()
    assert lat_nhc < 0.1 and lat_nhc < 0.25 * lat_free, (lat_nhc, lat_free)
    c = nhc.summary["constraints"]
    # nhc_rate_hz = 1 (default): one NHC update per second of the 900 s drive
    assert 899 <= c["events"] <= 900 and c["updates"] >= c["events"] - 1 and c["rejected"] == 0


@pytest.mark.parametrize("filt", ["ekf", "rbukf"])
def test_exact_nhc_keeps_the_linearised_filters_consistent_in_an_outage(slip_free, filt):
    """A truth that holds NHC exactly (slip and bounce off) and an exact, frequent
    constraint (0.001 m/s at 10 Hz), 4 seeds: rms(error / sigma) of the
    horizontal position and velocity over the 120 s outage in [0.3, 1.5], and
    the median of the outage's max horizontal error under 0.25 of the run
    without constraint.  The update linear in H leaves out the attitude x
    velocity error product of the NHC rows (0.02 m/s at 0.3 deg and 4 m/s, 20
    sigma; meas/vehicle.hpp).  Without its covariance in R the EKF read 2.1 / 1.9
    (position N / E), 2.1 / 2.0 (velocity), max-error ratio about 0.8; with it
    but as white noise at 10 Hz 0.6 / 0.55 and about 0.4; scaled by the events
    in its correlation time 0.57 / 0.47 and 0.15."""
    ratios, worst = [], []
    for k in range(4):
        ds = slip_free(k)
        hmax = []
        for cons in (Constraints(use=["nhc"], sigma_nhc_mps=0.001, rate_hz=10.0, nhc_rate_hz=10.0), None):
            kw = dict(constraints=cons) if cons else {}
            e = errors(insnav.run(ds, config=RunConfig(filter=filt, init_seed=k, **kw)), ds.truth)
            m = (e["t"] > OUTAGE[0]) & (e["t"] < OUTAGE[1])
            hmax.append(np.hypot(e["pos_n_m"][m, 0], e["pos_n_m"][m, 1]).max())
            if cons:
                ratios.append(np.concatenate([e["pos_n_m"][m, :2] / e["sigma_pos_n_m"][m, :2],
                                              e["vel_n_mps"][m, :2] / e["sigma_vel_n_mps"][m, :2]], axis=1))
        worst.append(hmax[0] / hmax[1])
    q = np.sqrt(np.mean(np.square(np.concatenate(ratios)), axis=0))
    assert np.all(q > 0.3) and np.all(q < 1.5), q
    assert np.median(worst) < 0.25, worst


def test_second_order_noise_as_white_noise_is_averaged_away(slip_free):
    """``second_order_corr_s = 0`` adds the attitude x velocity product's
    covariance as white noise: ten exact-NHC events a second average it down
    and the outage drift comes back (measured on four slip-free runs: 31-75 m
    against 10-41 m with the default 1 s)."""
    for k in (0, 2):
        ds = slip_free(k)
        mx = []
        for corr in (0.0, 1.0):
            cons = Constraints(use=["nhc"], sigma_nhc_mps=0.001, nhc_rate_hz=10.0, second_order_corr_s=corr)
            e = errors(insnav.run(ds, config=RunConfig(filter="ekf", init_seed=k, output_decimation=20,
                                                       constraints=cons)), ds.truth)
            m = (e["t"] > OUTAGE[0]) & (e["t"] < OUTAGE[1])
            mx.append(np.hypot(*e["pos_n_m"][m, :2].T).max())
        assert mx[0] > 1.5 * mx[1], (k, mx)


def test_odometer_bounds_the_along_track_drift(car):
    """NHC + odometer in the 120 s outage: max horizontal error within 5 % of
    the free-inertial EKF's and under 10 m."""
    def max_in(sol):
        e = errors(sol, car.truth)
        t = e["t"]
        return np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])[(t >= OUTAGE[0]) & (t <= OUTAGE[1])].max()

    # (the plain run: test_no_constraints_is_the_plain_run checks it equals an empty [constraints] table)
    free, odo = max_in(_car_run(car, RunConfig(filter="ekf", init_seed=3))), max_in(_run(car, ["nhc", "odo"]))
    assert odo < 10.0 and odo < 0.05 * free, (odo, free)


def test_zupt_on_a_standing_car_bounds_velocity():
    """A car parked for the last 20 s of car-mems with GNSS off there: ZUPT
    keeps the velocity error at the noise level while the free INS drifts."""
    ds = insnav.simulate("car-mems", seed=2)
    t_end = float(ds.imu.t[-1])
    ds.gnss = _cut(ds.gnss, t_end - 20.0)
    cfg = dict(filter="ekf", init_seed=2, output_decimation=20)
    free = insnav.run(ds, config=RunConfig(**cfg))
    z = insnav.run(ds, config=RunConfig(**cfg, constraints=Constraints(use=["zupt"])))
    last = z.t > t_end - 2.0
    v_true = np.column_stack([np.interp(z.t, ds.truth.t, ds.truth.v_n[:, i]) for i in range(3)])
    assert np.abs(v_true[last]).max() < 1e-6  # the car stands still there
    assert np.abs(z.v_n[last]).max() < 0.02
    assert np.abs(free.v_n[last]).max() > 5 * np.abs(z.v_n[last]).max()
    assert z.summary["constraints"]["zupt"] > 100


def _cut(g, t_max):
    import copy

    g2 = copy.copy(g)
    keep = g.t_valid < t_max
    for f in ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n"):
        setattr(g2, f, getattr(g, f)[keep])
    return g2


def test_standstill_detector_false_alarms_on_moving_samples(car):
    """The IMU statistic alone flags some constant-speed cruising as standing
    (measured: under 2 %); with the odometer's speed as well, none."""
    from insnav import _core

    imu = car.imu
    T = np.asarray(_core.standstill_statistic(imu.t, imu.dtheta_b, imu.dv_b, car.t0, 40, 0.02, 2e-3))
    speed = np.linalg.norm(np.column_stack([np.interp(imu.t, car.truth.t, car.truth.v_n[:, i]) for i in range(3)]),
                           axis=1)
    moving, standing = speed > 0.5, speed < 1e-3
    fa = np.mean(T[moving] < 18.0)
    odo = np.interp(imu.t, car.odometer.t, car.odometer.speed_mps)
    fa_odo = np.mean((T < 18.0)[moving] & (np.abs(odo[moving]) < 0.05))
    assert fa < 0.02 and fa_odo == 0.0, (fa, fa_odo)
    assert np.mean(T[standing] < 18.0) > 0.8


def test_nhc_rate_decimates_the_nhc_rows_only(car):
    """``nhc_rate_hz``: NHC on every k-th event of the grid (10 Hz odometer
    updates or the 10 Hz ZUPT grid), k = rate / nhc_rate; the odometer keeps
    every one of its updates.  Default: 1 Hz alone, every odometer update
    with the odometer."""
    from insnav.filters.constraints import NHC, ODO, constraint_events

    imu = car.imu
    for kw, k_odo, k_alone in ((dict(), 1, 10), (dict(nhc_rate_hz=10.0), 1, 1), (dict(nhc_rate_hz=1.0), 10, 10),
                               (dict(nhc_rate_hz=2.0), 5, 5)):
        ev, n = constraint_events(car, Constraints(use=["nhc", "odo"], **kw).validate(), imu.t, imu.dtheta_b, imu.dv_b)
        kinds = ev[:, 1].astype(int)
        assert np.all(kinds & ODO) and len(ev) >= 8990, len(ev)
        np.testing.assert_array_equal(np.flatnonzero(kinds & NHC), np.arange(0, len(ev), k_odo))
        ev1, _ = constraint_events(car, Constraints(use=["nhc"], **kw).validate(), imu.t, imu.dtheta_b, imu.dv_b)
        assert np.all(ev1[:, 1] == NHC)
        assert np.allclose(np.diff(ev1[:, 0]), k_alone / 10.0)


def test_nhc_at_one_hertz_drifts_less_than_white_noise_at_ten_hertz():
    """The simulated slip and bounce (sinusoids of 1.5-6.3 s and 0.35-1.3 s
    periods, 0.05 / 0.03 m/s RMS) are correlated over seconds.  NHC updates
    with a tight sigma (0.02 m/s) treated as white noise at 10 Hz count each
    second's slip ten times: in the 30 s outage the horizontal error is
    larger than with the same sigma at 1 Hz in every run (measured 1.4-4.3 m
    against 2.6-9.6 m over six runs; here two of them) and leaves its sigmas
    more (pooled rms(error / sigma) about 0.7 at 1 Hz, 1.2 at 10 Hz)."""
    a, b = 500.0, 530.0
    z, mx = {1.0: [], 10.0: []}, {1.0: [], 10.0: []}
    for seed in (0, 5):
        ds = insnav.simulate("car-mems-outage30", seed=seed)
        for rate in (1.0, 10.0):
            sol = insnav.run(ds, config=RunConfig(filter="ekf", init_seed=seed, output_decimation=20, constraints=
                                                  Constraints(use=["nhc"], sigma_nhc_mps=0.02, nhc_rate_hz=rate)))
            e = errors(sol, ds.truth)
            inside = (e["t"] >= a) & (e["t"] <= b)
            z[rate].append(e["pos_n_m"][inside, :2] / e["sigma_pos_n_m"][inside, :2])
            mx[rate].append(np.hypot(*e["pos_n_m"][inside, :2].T).max())
    assert np.all(np.array(mx[1.0]) < 0.7 * np.array(mx[10.0])), mx
    rms = {r: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for r, v in z.items()}
    assert rms[1.0] < 1.0 and rms[10.0] > 1.4 * rms[1.0], rms


@pytest.mark.parametrize("table, needle", [
    ({"use": ["nhc", "wheel"]}, "constraints.use"),
    ({"use": ["nhc"], "sigma_nhc_mps": -0.1}, "constraints.sigma_nhc_mps"),
    ({"use": ["nhc"], "rate": 10}, "unknown key 'constraints.rate'"),
    ({"use": ["nhc"], "lever_arm_b_m": [1, 2]}, "constraints.lever_arm_b_m"),
    ({"use": ["nhc"], "nhc_rate_hz": 20.0}, "constraints.nhc_rate_hz"),
    ({"use": ["nhc"], "nhc_rate_hz": 0.0}, "constraints.nhc_rate_hz"),
    ({"use": ["nhc"], "second_order_corr_s": -1.0}, "constraints.second_order_corr_s"),
])
def test_bad_constraint_config_names_the_key(table, needle):
    with pytest.raises(ConfigError, match=needle.replace(".", r"\.")):
        config_from_dict({"constraints": table})


def test_constraints_need_loose_ekf_rbukf_ukf_and_an_odometer(car):
    with pytest.raises(ConfigError, match="with ekf loose, rbukf loose, ukf loose only"):
        config_from_dict({"filter": "upf", "coupling": "tight", "constraints": {"use": ["nhc"]}})
    ds = insnav.simulate("seed000-sim", seed=1)  # no odometer
    with pytest.raises(ValueError, match="odometer"):
        insnav.run(ds, config=RunConfig(constraints=Constraints(use=["odo"])))


def test_cli_constraints_flag_and_config_round_trip(car, tmp_path):
    from insnav.cli import main
    from insnav.config import load_config

    car.save(tmp_path / "car")
    out = tmp_path / "sol.csv"
    assert main(["run", str(tmp_path / "car"), "--constraints", "nhc,odo", "--out", str(out)]) == 0
    cfg = load_config(str(out) + ".config.toml")
    assert cfg.constraints.use == ["nhc", "odo"]
    again = tmp_path / "again.csv"
    assert main(["run", str(tmp_path / "car"), "--config", str(out) + ".config.toml", "--out", str(again)]) == 0
    assert again.read_bytes() == out.read_bytes()
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "insnav", "run", str(tmp_path / "car"), "--constraints", "nhc,wheels",
                        "--out", str(tmp_path / "x.csv")], capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "constraints.use" in r.stderr


@pytest.mark.parametrize("filt", ["ekf", "rbukf", "ukf"])
def test_smoother_bridges_an_outage_consistently(car, filt):
    """The RTS smoother (smooth=True; the unscented RTS smoother for the RB-UKF
    and UKF) on the 120 s outage: the max horizontal error inside it drops by
    more than 10x, the smoothed sigmas are consistent with the errors
    (rms(error / sigma) in 0.6-1.4 per axis), and the last row, with no
    measurement after it, is the filtered one."""
    fwd = _car_run(car, RunConfig(filter=filt, init_seed=3))
    sm = _car_run(car, RunConfig(filter=filt, init_seed=3, smooth=True))

    def max_in(sol):
        e = errors(sol, car.truth)
        t = e["t"]
        return np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])[(t >= OUTAGE[0]) & (t <= OUTAGE[1])].max()

    assert max_in(sm) < 0.1 * max_in(fwd), (max_in(sm), max_in(fwd))
    e = errors(sm, car.truth)
    cons = np.sqrt(np.mean((e["pos_n_m"] / e["sigma_pos_n_m"]) ** 2, axis=0))
    assert np.all((cons > 0.6) & (cons < 1.4)), cons
    assert sm.lat_deg[-1] == pytest.approx(fwd.lat_deg[-1], abs=1e-12)
    assert sm.sigma_pos_n_m[-1] == pytest.approx(fwd.sigma_pos_n_m[-1], rel=1e-9)
    assert sm.summary["smoother"]["gain_failures"] == 0
    with pytest.raises(ConfigError, match="smooth"):
        RunConfig(filter="upf", coupling="tight", smooth=True).validate()


def test_unscented_and_ekf_smoothers_agree_on_a_near_linear_problem(car):
    """Same data, same start: the smoothed RB-UKF and EKF solutions differ by
    far less than either's forward error in the outage (the error dynamics are
    nearly linear for a MEMS car over 120 s)."""
    sol = {(f, s): _car_run(car, RunConfig(filter=f, init_seed=3, smooth=s))
           for f in ("ekf", "rbukf") for s in (False, True)}
    t = sol[("ekf", True)].t
    inside = (t >= OUTAGE[0]) & (t <= OUTAGE[1])
    e_fwd = errors(sol[("ekf", False)], car.truth)
    fwd_max = np.hypot(e_fwd["pos_n_m"][:, 0], e_fwd["pos_n_m"][:, 1])[inside].max()
    a, b = errors(sol[("ekf", True)], car.truth), errors(sol[("rbukf", True)], car.truth)
    diff = np.hypot(*(a["pos_n_m"][:, :2] - b["pos_n_m"][:, :2]).T)[inside].max()
    assert diff < 0.05 * fwd_max, (diff, fwd_max)


def test_smoothed_rows_do_not_depend_on_how_the_rows_are_split():
    """_core.smooth_rows works on blocks of rows on two threads, each finding its
    epoch interval by bisection: the same rows one at a time give the same numbers."""
    from insnav import _core

    rng = np.random.default_rng(3)
    n, E = 30_000, 301
    t = np.linspace(0.0, 300.0, n)
    te = np.linspace(0.0, 300.0, E)
    s, s_end, sig = (rng.normal(scale=1e-3, size=(E, 9)) for _ in range(3))
    base = [np.full(n, 30.0), np.full(n, 114.0), np.full(n, 20.0), rng.normal(size=(n, 3)),
            rng.normal(size=n), rng.normal(size=n), rng.uniform(-180, 180, n)]
    whole = [a.copy() for a in base]
    sig_whole = np.empty((n, 9))
    _core.smooth_rows(t, *whole, te, s, s_end, np.abs(sig), sig_whole)
    for i in rng.choice(n, 300, replace=False):
        one = [np.ascontiguousarray(a[i:i + 1]) for a in base]
        sig_one = np.empty((1, 9))
        _core.smooth_rows(t[i:i + 1], *one, te, s, s_end, np.abs(sig), sig_one)
        for a, b in zip(whole, one):
            assert np.array_equal(a[i:i + 1], b)
        assert np.array_equal(sig_whole[i], sig_one[0])
