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
* Why not: the filter's predicted correction covariance K S K' is right (the ratio |dx_b|^2 /
  tr(K S K')_bb at the configured Q is 1 within 10 % over eight simulation seeds), but on this drive
  it hardly depends on the configured random walks (they make 1.5 % of the epoch-to-epoch growth of
  tr P- of the velocity, 6 % of the attitude: Q x 0.1 .. x 10 moves the ratio by 4-7 %), so the
  windowed factor has nothing that pulls it back to 1 and compounds one drive's ratio window after
  window (``bench/tight_prior_consistency.py``).
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
    the simulated one) with seed 003's raw GPS: up to 8 satellites, 3 m / 0.05 m/s, no windows.  It
    starts standing, as the adaptive-R mover (seed 003's initial state is an aircraft at 150 m/s)."""
    base = sim.simulate("seed003-4sat", seed=0, with_truth=False).scenario
    sc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in base.items()}
    sc.update(name="adaptive-q-tight-mover", motion=MOVER["motion"], imu=MOVER["imu"])
    sc["initial"] = dict(sc["initial"], speed_mps=0.0)
    sc["gnss_raw"] = dict(sc["gnss_raw"], windows=[], max_sats=8, sigma_pr_m=3.0, sigma_prr_mps=0.05)
    return sc


@pytest.fixture(scope="module")
def mover():
    ds = sim.simulate(tight_mover(), seed=3)
    return ds, ImuNoise.from_dataset_model(ds.imu_model)


#: initial state exact, small initial sigmas: the start-up corrections weigh no more than the later ones
SMALL_P0 = dict(filter="ekf", coupling="tight", init_error=False, init_sigma_pos_m=[0.5, 0.5, 0.5],
                init_sigma_vel_mps=[0.01, 0.01, 0.01], init_sigma_att_deg=[0.01, 0.01, 0.01])


def ratio_at_configured_q(ds, noise: ImuNoise, n_epochs: int = 200) -> list:
    """AdaptiveProcessNoise's windowed ratio sum |dx_b|^2 / sum tr(P- - P+)_bb (velocity, attitude)
    over the first ``n_epochs`` GNSS epochs with every record at factor 1, i.e. the filter with the
    configured Q: the run cut just after epoch ``n_epochs`` with the window ``n_epochs``, whose first
    fill is the last epoch (``SMALL_P0`` set-up)."""
    t_g = np.unique(ds.gnss_raw.t)
    n = int(np.searchsorted(ds.imu.t, t_g[n_epochs - 1] + 0.5))
    imu = dataclasses.replace(ds.imu, t=ds.imu.t[:n], dtheta_b=ds.imu.dtheta_b[:n], dv_b=ds.imu.dv_b[:n])
    cfg = RunConfig(**SMALL_P0, imu=noise, adaptive_q_window=n_epochs, adaptive_q_min=1e-3, adaptive_q_max=1e3)
    sol = insnav.run(dataclasses.replace(ds, imu=imu), config=cfg)
    assert sol.summary["updates"] == n_epochs  # every epoch applied: the window filled at the last one
    return sol.summary["process_noise_scale"]


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
    than 10x (measured 0.072, 0.050), the true Q by far less (measured 0.67, 0.60): the factor
    follows the configured excess."""
    ds, noise = mover
    f = {s: insnav.run(ds, config=RunConfig(filter="ekf", coupling="tight", imu=_scaled(noise, s),
                                            adaptive_q_window=100, adaptive_q_min=0.01, adaptive_q_max=100.0))
         .summary["process_noise_scale"] for s in (1.0, 1e4)}
    assert max(f[1e4]) < 0.1 and min(f[1.0]) > 0.5, f


@pytest.mark.xfail(strict=True, reason="measured 0.67, 0.60 on this drive: the factor is not identifiable here "
                   "(the random walks are 1.5 % / 6 % of the P- growth) and compounds this drive's low ratio at "
                   "the true Q (0.85, 0.87; 0.98, 0.99 over eight seeds; see the docstrings)")
def test_the_configured_true_q_is_a_fixed_point(mover):
    """With the simulated IMU noise configured (true scale 1), both factors within 15 % of 1 (window
    100), as on the loose mover (tests/test_adaptive_q.py: 0.94, 1.04).  It does NOT hold on this
    tight drive: 0.67, 0.60, and about the same with Q configured 1e-4x to 4x the truth (0.70, 0.64
    .. 0.64, 0.53).  Not a wrong model (bench/tight_prior_consistency.py, on this drive): the prior
    NEES of the velocity is 3.1-3.3 (3 expected) after the first 10 epochs, of the clock drift
    0.7-1.2 (1), the Doppler innovation less its velocity and clock-drift parts from the truth has
    the simulated sigma (0.048 for 0.05 m/s), and the P- the adaptive class reads agrees with the
    push API's covariance at the epoch time (the ratio
    below from the truth and the engine's agree to 1 %).  Two properties make the factor miss:

    * this drive's ratio |dx_b|^2 / tr(P- - P+)_bb at the true Q is low, 0.85 (velocity) and 0.87
      (attitude) over 200 epochs; over simulation seeds 1-8 it is 0.98 +- 0.02 and 0.99 +- 0.03
      (test_the_correction_covariance_is_right_but_blind_to_the_random_walks);
    * the ratio hardly moves with the factor (the random walks are 1.5 % of the epoch-to-epoch growth
      of tr P- of the velocity, 6 % of the attitude; the rest is the Gauss-Markov biases and the
      attitude errors seen through g), so the windowed factor sum a_j |dx_j|^2 / sum tr_j is the
      ratio times the mean of the earlier factors: 0.85 compounded over the 2.3 window turnovers of
      the run is 0.69.  Over seeds 1-8 the factors spread 0.67 .. 1.18 (velocity) and 0.60 .. 1.32
      (attitude).  On a long run the factor random-walks (window 20: 0.25, 0.26 at the bound here).

    Kept as a strict xfail: it flips when the estimate is made identifiable (e.g. matched against
    the random walks' own share of K S K'), not by a change of the filter's model."""
    ds, noise = mover
    f = insnav.run(ds, config=RunConfig(filter="ekf", coupling="tight", imu=noise, adaptive_q_window=100,
                                        adaptive_q_min=0.01, adaptive_q_max=100.0)).summary["process_noise_scale"]
    assert abs(f[0] - 1.0) < 0.15 and abs(f[1] - 1.0) < 0.15, f


@pytest.mark.slow
def test_the_correction_covariance_is_right_but_blind_to_the_random_walks(mover):
    """What the adaptive factor matches, the ratio |dx_b|^2 / tr(P- - P+)_bb of AdaptiveProcessNoise
    at the configured (true) Q over 200 epochs (initial state exact, small initial sigmas):

    * over simulation seeds 1-8 its mean is within 10 % of 1 for the velocity and the attitude
      (measured 0.975 +- 0.023, 0.993 +- 0.028), each seed within 0.8-1.25 (0.854 .. 1.039, 0.869 ..
      1.066): the filter's K S K' is right, the Doppler rows included;
    * on seed 3 the random walks configured x 10 instead of x 0.1 (100x apart) move it by less than
      10 % (measured velocity 0.861 -> 0.825, attitude 0.881 -> 0.823): it carries almost nothing
      about the random walks on this drive, so the factor cannot be found from it."""
    ds3, noise3 = mover
    r = []
    for seed in range(1, 9):
        ds = ds3 if seed == 3 else sim.simulate(tight_mover(), seed=seed)
        r.append(ratio_at_configured_q(ds, ImuNoise.from_dataset_model(ds.imu_model)))
    r = np.array(r)
    assert np.all(np.abs(r.mean(axis=0) - 1.0) < 0.1), r
    assert np.all((r > 0.8) & (r < 1.25)), r
    lo, hi = (np.array(ratio_at_configured_q(ds3, _scaled(noise3, s))) for s in (0.1, 10.0))
    assert np.all(np.abs(hi / lo - 1.0) < 0.1), (lo, hi)


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
