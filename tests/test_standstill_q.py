"""Standstill level of the process noise of the loose EKF (``[constraints] standstill_q_scale``,
``cpp/include/insnav/engine/loose_engine.hpp``): while the standstill detector (``ins/standstill.hpp``,
the SHOE statistic of Skog et al. 2010, eq. (10)) says the IMU stands still, the velocity and angle
random walk PSDs are multiplied by the factor.

* Off: with the factor 1 the detector's STILL / MOVING events change nothing, bit for bit.
* Exact: at a standstill that lasts the whole run, the factor s gives the run whose configured
  velocity and angle random walks are sqrt(s) times larger (the Q it claims to scale, and only it).
* The events: STILL where a standstill starts, MOVING where it ends, none on data that never stand.
* Tight EKF (one detector state per epoch, ``engine/tight_engine.hpp``): every epoch flagged moving
  is the run without the level, bit for bit; the detector's flags lower the standing sigmas.
* The keys: TOML, validation (loose and tight EKF only, > 0), the tuner's factor ``standstill_q``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import insnav
from insnav.config import ConfigError, Constraints, ImuNoise, RunConfig, load_config
from insnav.filters import constraints as constraints_mod

from test_adaptive_r import MOVER

#: the event builder itself (the tests below patch the module's name)
EVENTS = constraints_mod.constraint_events
FIELDS = ("t", "lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "pitch_deg", "yaw_deg", "sigma_pos_n_m",
          "sigma_vel_n_mps", "sigma_att_deg", "innovation", "nis", "log_det_s")


@pytest.fixture(scope="module")
def mover():
    ds = insnav.simulate(MOVER, seed=3)
    return ds, ImuNoise.from_dataset_model(ds.imu_model)


def _with_events(monkeypatch, make):
    """Make insnav.run use the events ``make(original_events)`` (filters/constraints.py)."""
    def patched(dataset, c, *imu):
        ev, counts = EVENTS(dataset, c, *imu)
        return np.ascontiguousarray(make(ev, dataset, c, imu)), counts

    monkeypatch.setattr(constraints_mod, "constraint_events", patched)


def test_events_mark_where_the_detector_state_changes(mover):
    """STILL / MOVING exactly where the detector's state on the event grid changes (the detector's own
    state: on this simulated IMU without vibration it also calls the straight constant-speed legs
    stationary, the limit ins/standstill.hpp states), nothing else without ``zupt`` in use, and no
    events at all when the detector never says stationary."""
    ds, noise = mover
    t, dth, dv = (np.asarray(a, float) for a in (ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b))
    c = Constraints(standstill_q_scale=0.1)
    ev, counts = constraints_mod.constraint_events(ds, c, t, dth, dv)
    k = ev[:, 1].astype(int)
    assert np.all((k == constraints_mod.STILL) | (k == constraints_mod.MOVING))
    grid = np.arange(float(ds.t0) + 1.0 / c.rate_hz, t[-1] + 1e-9, 1.0 / c.rate_hz)
    still = constraints_mod.standstill_at(ds, c, t, dth, dv, grid)
    change = still != np.concatenate([[False], still[:-1]])
    assert np.array_equal(ev[:, 0], grid[change])
    assert np.array_equal(k == constraints_mod.STILL, still[change])
    assert k[0] == constraints_mod.STILL and ev[0, 0] < float(ds.t0) + 0.5  # the mover starts standing
    assert k[-1] == constraints_mod.STILL and ev[-1, 0] < t[-1] - 95.0  # and ends with 100 s standing
    assert 0.2 < counts["standstill_fraction_of_samples"] < 1.0
    ev2, _ = constraints_mod.constraint_events(ds, dataclasses.replace(c, zupt_threshold=1e-9), t, dth, dv)
    assert len(ev2) == 0


def test_scale_one_ignores_the_still_and_moving_events_bit_for_bit(mover, monkeypatch):
    """The same event times (the STILL / MOVING bits on, or the events with no kind at all: both close
    the filter cycle at the same instants) with the factor 1: identical runs."""
    ds, noise = mover
    cfg = RunConfig(filter="ekf", imu=noise, constraints=Constraints(use=["zupt"]))

    def with_bits(ev, dataset, c, imu):
        return EVENTS(dataset, dataclasses.replace(c, standstill_q_scale=0.5), *imu)[0]

    def without_bits(ev, dataset, c, imu):
        e = with_bits(ev, dataset, c, imu).copy()
        e[:, 1] = e[:, 1].astype(int) & ~(constraints_mod.STILL | constraints_mod.MOVING)
        return e

    _with_events(monkeypatch, with_bits)
    a = insnav.run(ds, config=dataclasses.replace(cfg))
    _with_events(monkeypatch, without_bits)
    b = insnav.run(ds, config=dataclasses.replace(cfg))
    assert np.any((a.constraint_kinds & (constraints_mod.STILL | constraints_mod.MOVING)) != 0)
    for k in FIELDS:
        assert np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True), k
    # and with the level on, the run differs (the events are not ignored)
    monkeypatch.undo()
    c = insnav.run(ds, config=dataclasses.replace(cfg, constraints=Constraints(use=["zupt"], standstill_q_scale=0.5)))
    assert not np.array_equal(c.sigma_vel_n_mps, b.sigma_vel_n_mps)


@pytest.mark.parametrize("s", [0.04, 9.0])
def test_the_factor_scales_exactly_the_velocity_and_angle_random_walks(mover, monkeypatch, s):
    """One STILL event just after the start (1e-9 s: the level holds from there to the end) against the
    configured velocity and angle random walks times sqrt(s) with an event of no kind at the same time:
    the same run to rounding (the only difference: Q over the first 1e-9 s)."""
    ds, noise = mover
    t0 = float(ds.t0)

    def one(kind):
        return lambda ev, dataset, c, imu: np.array([[t0 + 1e-9, float(kind), np.nan]])

    _with_events(monkeypatch, one(constraints_mod.STILL))
    a = insnav.run(ds, config=RunConfig(filter="ekf", imu=noise, constraints=Constraints(standstill_q_scale=s)))
    r = float(np.sqrt(s))
    scaled = dataclasses.replace(noise, acc_vrw=[x * r for x in noise.acc_vrw], gyro_arw=[x * r for x in noise.gyro_arw])
    _with_events(monkeypatch, one(0))
    b = insnav.run(ds, config=RunConfig(filter="ekf", imu=scaled, constraints=Constraints(standstill_q_scale=s)))
    plain = insnav.run(ds, config=RunConfig(filter="ekf", imu=noise, constraints=Constraints(standstill_q_scale=s)))
    for k in ("sigma_pos_n_m", "sigma_vel_n_mps", "sigma_att_deg", "nis", "log_det_s"):
        x, y = getattr(a, k), getattr(b, k)
        assert np.allclose(x, y, rtol=1e-7, atol=0, equal_nan=True), k
        # the factor changed them: far from the run with the configured noise (ln det S: by 0.05 or more)
        if k == "log_det_s":
            assert np.nanmax(np.abs(x - getattr(plain, k))) > 0.05, k
        else:
            assert np.nanmax(np.abs(x / getattr(plain, k) - 1.0)) > 0.01, k
    assert np.allclose(a.lat_deg, b.lat_deg, rtol=0, atol=1e-12)


def test_keys_validation_and_the_tuner_factor(tmp_path, mover):
    p = tmp_path / "c.toml"
    p.write_text('filter = "ekf"\n[constraints]\nuse = ["zupt"]\nstandstill_q_scale = 0.2\n')
    cfg = load_config(p)
    assert cfg.constraints.standstill_q_scale == 0.2
    assert Constraints().standstill_q_scale == 1.0  # off by default
    for bad in (0.0, -1.0, float("inf"), True):
        with pytest.raises(ConfigError, match="standstill_q_scale"):
            RunConfig(filter="ekf", constraints=Constraints(standstill_q_scale=bad)).validate()
    for kw in (dict(filter="rbukf"), dict(filter="ukf", coupling="tight")):
        with pytest.raises(ConfigError, match="standstill_q_scale"):
            RunConfig(**kw, constraints=Constraints(standstill_q_scale=0.5)).validate()
    from insnav.calib.tune import default_parameters, scaled_config, tuned_toml_dict, TuneResult  # noqa: F401

    ds, noise = mover
    base = RunConfig(filter="ekf", imu=noise, constraints=Constraints(standstill_q_scale=0.5))
    assert "standstill_q" in default_parameters(ds, base)
    assert "standstill_q" not in default_parameters(ds, RunConfig(filter="ekf", imu=noise))
    assert scaled_config(base, noise, {"standstill_q": 0.1}).constraints.standstill_q_scale == pytest.approx(0.05)


def test_tight_flags_moving_is_the_plain_run_and_standing_flags_lower_the_sigmas(monkeypatch):
    from insnav.filters.tight import run_tight
    from test_adaptive_q_tight import tight_mover

    ds = insnav.simulate(tight_mover(), seed=1)
    noise = ImuNoise.from_dataset_model(ds.imu_model)
    cfg = RunConfig(filter="ekf", imu=noise, coupling="tight")
    plain = run_tight(ds, dataclasses.replace(cfg))
    level = dataclasses.replace(cfg, constraints=Constraints(standstill_q_scale=0.01))
    det = run_tight(ds, dataclasses.replace(level))
    monkeypatch.setattr(constraints_mod, "standstill_at", lambda dataset, c, t, dth, dv, times: np.zeros(len(times), bool))
    never = run_tight(ds, dataclasses.replace(level))
    for k in FIELDS + ("clock_bias_m",):
        assert np.array_equal(getattr(never, k), getattr(plain, k), equal_nan=True), k
    # the mover stands for its last 100 s: there the level (0.01) lowers the velocity and attitude sigmas
    # (by 3.4 % and 3.3 % in the median: on this drive the pseudorange rates hold the velocity, and the
    # random walks make a small part of P-'s growth, test_adaptive_q_tight.py), never raises them
    last = det.t > float(ds.imu.t[-1]) - 50.0
    for k in ("sigma_vel_n_mps", "sigma_att_deg"):
        r = getattr(det, k)[last] / getattr(plain, k)[last]
        assert np.median(r) < 0.98 and r.max() < 1.0, (k, np.median(r), r.max())


def test_the_level_alone_is_saved_streamed_whole_and_refused_by_the_push_api(tmp_path, mover):
    """``standstill_q_scale`` without a ``use`` entry: the resolved config keeps it (re-running it is
    the same filter), the block-by-block stream falls back to the whole run (its events come from the
    whole IMU record), and the push API, which has no detector, refuses it."""
    from insnav.cli.run import resolved_config_toml
    from insnav.filters.navigator import Navigator, TightNavigator
    from insnav.filters.stream import stream_unsupported

    ds, noise = mover
    cfg = RunConfig(filter="ekf", imu=noise, constraints=Constraints(standstill_q_scale=0.05))
    cfg.validate()
    p = tmp_path / "saved.toml"
    p.write_text(resolved_config_toml(cfg))
    again = load_config(p)
    assert again.constraints.standstill_q_scale == 0.05 and again.constraints.use == []
    a, b = insnav.run(ds, config=cfg), insnav.run(ds, config=again)
    plain = insnav.run(ds, config=RunConfig(filter="ekf", imu=noise))
    assert np.array_equal(a.sigma_vel_n_mps, b.sigma_vel_n_mps)
    assert np.nanmax(np.abs(a.sigma_vel_n_mps - plain.sigma_vel_n_mps)) > 1e-6  # the level did something
    assert "standstill" in stream_unsupported(cfg, out_suffix=".csv")
    assert stream_unsupported(RunConfig(filter="ekf", imu=noise), out_suffix=".csv") is None
    with pytest.raises(ValueError, match="standstill_q_scale"):
        Navigator.from_dataset(ds, cfg)
    with pytest.raises(ValueError, match="standstill_q_scale"):
        TightNavigator.from_dataset(ds, dataclasses.replace(cfg, coupling="tight"))
    from insnav.config import Tdcp

    with pytest.raises(ValueError, match=r"\[tdcp\]"):  # TDCP rows: built by the batch run only
        TightNavigator.from_dataset(ds, RunConfig(filter="ekf", coupling="tight", tdcp=Tdcp(enabled=True)))
