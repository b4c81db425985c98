"""Adaptive process noise of the tight EKF (``adaptive_q_window`` with coupling tight): the loose
EKF's form (``cpp/include/insnav/filter/adaptive_noise.hpp``, AdaptiveProcessNoise; Mohamed &
Schwarz 1999, *Adaptive Kalman filtering for INS/GPS*, J. Geodesy 73: Q^ = K C_v K' over a window
of updates, here one scale per block of the configured Q, matched against K S K' = P- - P+).

* Off: ``adaptive_q_window = 0`` and a window longer than the run (never full) give the plain tight
  filter bit for bit.
* Bounds: the factors reach adaptive_q_min when the configured Q is far too large.
* Estimate: on a simulated tight drive (pseudoranges and rates, the filter's IMU model family equal
  to the simulated one) the factor falls with the configured excess; the configured true Q is NOT
  a fixed point within 15 % there (a strict xfail with the measured figures).
* The keys reach the tight runner through run(), TOML and the CLI; filters that cannot take them
  are refused with a one-line error.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import insnav
import insnav.sim as sim
from insnav import _core
from insnav.config import ConfigError, ImuNoise, RunConfig, load_config
from insnav.filters.tight import run_tight, tight_engine_args

from test_adaptive_r import MOVER

FIELDS = ("t", "lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "yaw_deg", "sigma_pos_n_m", "sigma_vel_n_mps",
          "innovation", "nis", "log_det_s", "clock_bias_m")


def tight_mover():
    """The adaptive-R mover (a car, 225 s, Gauss-Markov IMU biases only: the filter's bias model is
    the simulated one) with seed 003's raw GPS: up to 8 satellites, 3 m / 0.05 m/s, no windows."""
    base = sim.simulate("seed003-4sat", seed=0, with_truth=False).scenario
    sc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in base.items()}
    sc.update(name="adaptive-q-tight-mover", motion=MOVER["motion"], imu=MOVER["imu"])
    sc["gnss_raw"] = dict(sc["gnss_raw"], windows=[], max_sats=8, sigma_pr_m=3.0, sigma_prr_mps=0.05)
    return sc


@pytest.fixture(scope="module")
def mover():
    ds = sim.simulate(tight_mover(), seed=3)
    return ds, ImuNoise.from_dataset_model(ds.imu_model)


def _scaled(noise: ImuNoise, s_var: float) -> ImuNoise:
    """The IMU noise with the velocity and angle random walk variances times s_var."""
    r = float(np.sqrt(s_var))
    return dataclasses.replace(noise, acc_vrw=[x * r for x in noise.acc_vrw],
                               gyro_arw=[x * r for x in noise.gyro_arw])


def test_off_and_a_window_never_full_give_the_plain_tight_filter(mover):
    ds, noise = mover
    cfg = RunConfig(filter="ekf", coupling="tight", imu=noise)
    plain = insnav.run(ds, config=cfg)
    assert 100 < len(plain.gnss_t) < 256 and plain.summary["updates"] > 100
    assert "process_noise_scale" not in plain.summary
    for w in (0, 256):
        sol = insnav.run(ds, config=dataclasses.replace(cfg, adaptive_q_window=w))
        for k in FIELDS:
            assert np.array_equal(getattr(sol, k), getattr(plain, k), equal_nan=True), (w, k)
    on = insnav.run(ds, config=dataclasses.replace(cfg, adaptive_q_window=256))
    assert on.summary["process_noise_scale"] == [1.0, 1.0]
    # a window that fills changes the solution (the option reaches the engine)
    short = insnav.run(ds, config=dataclasses.replace(cfg, adaptive_q_window=10))
    assert not np.array_equal(short.sigma_pos_n_m, plain.sigma_pos_n_m)


def test_factors_stay_within_and_reach_the_bounds(mover):
    """Q 1e4x too large: the epoch corrections are far smaller than K S K' predicts, the factors sit at
    the lower bound (window 20, bounds 0.25 and 4)."""
    ds, noise = mover
    cfg = RunConfig(filter="ekf", coupling="tight", imu=_scaled(noise, 1e4), adaptive_q_window=20,
                    adaptive_q_min=0.25, adaptive_q_max=4.0)
    f = insnav.run(ds, config=cfg).summary["process_noise_scale"]
    assert f == [0.25, 0.25], f


def test_the_factor_falls_with_the_configured_excess(mover):
    """Window 100 (about two windows in the run): a Q configured 1e4x too large is scaled down by more
    than 10x (measured 0.072, 0.051), the true Q by far less (measured 0.64, 0.66): the factor
    follows the configured excess."""
    ds, noise = mover
    f = {s: insnav.run(ds, config=RunConfig(filter="ekf", coupling="tight", imu=_scaled(noise, s),
                                            adaptive_q_window=100, adaptive_q_min=0.01, adaptive_q_max=100.0))
         .summary["process_noise_scale"] for s in (1.0, 1e4)}
    assert max(f[1e4]) < 0.1 and min(f[1.0]) > 0.5, f


@pytest.mark.xfail(strict=True, reason="measured 0.64, 0.66 on this drive: the tight EKF's epoch corrections "
                   "are about 2/3 of K S K' with the true Q configured (see the docstring)")
def test_the_configured_true_q_is_a_fixed_point(mover):
    """With the simulated IMU noise configured (true scale 1), both factors within 15 % of 1 (window
    100), as on the loose mover (tests/test_adaptive_q.py: 0.94, 1.04).  It does NOT hold on this
    tight drive: 0.64, 0.66, and about the same with Q configured 1e-4x to 4x the truth (0.66 ..
    0.60): the ratio |dx_b|^2 / tr(K S K')_bb is about 2/3 whatever the random walks, i.e. the velocity
    and attitude corrections are not driven by them here, and the multiplicative window (factor x
    ratio each window) then walks the factor down to adaptive_q_min on a long run (window 20: at the
    bound 0.25 for every configured scale).  Kept as a strict xfail: it flips when that is fixed."""
    ds, noise = mover
    f = insnav.run(ds, config=RunConfig(filter="ekf", coupling="tight", imu=noise, adaptive_q_window=100,
                                        adaptive_q_min=0.01, adaptive_q_max=100.0)).summary["process_noise_scale"]
    assert abs(f[0] - 1.0) < 0.15 and abs(f[1] - 1.0) < 0.15, f


def test_keys_validation_and_the_refused_filters(mover, tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("filter = \"ekf\"\ncoupling = \"tight\"\nadaptive_q_window = 30\nadaptive_q_min = 0.1\n"
                 "adaptive_q_max = 10.0\n")
    cfg = load_config(p)
    assert (cfg.coupling, cfg.adaptive_q_window, cfg.adaptive_q_min, cfg.adaptive_q_max) == ("tight", 30, 0.1, 10.0)
    cfg.validate()
    for bad in (dict(filter="rbukf"), dict(filter="ukf"), dict(filter="upf"), dict(coupling="rtk")):
        with pytest.raises(ConfigError, match="adaptive_q_window"):
            dataclasses.replace(cfg, **bad).validate()
    # the engine binding refuses a filter without a scalable Q (one line, naming the key)
    ds, noise = mover
    a = tight_engine_args(ds, RunConfig(filter="ekf", coupling="tight", imu=noise, adaptive_q_window=10))
    from insnav.filters._setup import imu_arrays

    t, dth, dv = imu_arrays(ds)
    args = (t, dth, dv, a.epoch_t, a.inputs.epoch_start.astype(np.int64), a.sats, a.init, a.P0, a.imu_correction,
            np.asarray(a.clock0, float), a.imu_model)
    with pytest.raises(ValueError, match=r"^adaptive_q_window > 0: the EKF only"):
        _core.run_tight("ukf", *args, a.config, layout=a.layout, system=a.system, prn=a.prn)
    out = _core.run_tight("ekf", *args, a.config, layout=a.layout, system=a.system, prn=a.prn)
    assert len(out["process_noise_scale"]) == 2
    with pytest.raises(ValueError, match="adaptive_q_min"):
        _core.run_tight("ekf", *args, dict(a.config, adaptive_q_min=0.0), layout=a.layout, system=a.system,
                        prn=a.prn)


def test_cli_and_run_reach_the_tight_runner(mover, tmp_path):
    """``insnav run <dataset> --coupling tight --config c.toml``: the window in the TOML changes the
    solution file against the same run without it (and a window 0 does not) and is written back in
    the resolved configuration; run_tight with the same keys reports factors within the bounds."""
    from insnav.cli import main

    ds, _ = mover
    d = tmp_path / "ds"
    ds.save(d)
    files = {}
    for tag, extra in (("plain", ""), ("zero", "adaptive_q_window = 0\n"),
                       ("adaptive", "adaptive_q_window = 10\nadaptive_q_min = 0.2\n")):
        c = tmp_path / f"{tag}.toml"
        c.write_text(extra)
        out = tmp_path / f"{tag}.csv"
        assert main(["run", str(d), "--coupling", "tight", "--filter", "ekf", "--config", str(c), "-q",
                     "--out", str(out)]) == 0
        files[tag] = out
    assert files["zero"].read_bytes() == files["plain"].read_bytes()
    assert files["adaptive"].read_bytes() != files["plain"].read_bytes()
    text = (tmp_path / "adaptive.csv.config.toml").read_text()
    assert "adaptive_q_window = 10" in text and "adaptive_q_min = 0.2" in text
    sol = run_tight(ds, RunConfig(filter="ekf", adaptive_q_window=10, adaptive_q_min=0.2))
    f = sol.summary["process_noise_scale"]
    assert all(0.2 <= x <= 20.0 for x in f) and f != [1.0, 1.0]
