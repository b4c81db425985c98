"""Innovation-based adaptive measurement noise of the loose GNSS rows (``adaptive_r_window``,
``cpp/include/insnav/filter/adaptive_noise.hpp``; Mohamed & Schwarz 1999, *Adaptive Kalman filtering
for INS/GPS*, J. Geodesy 73: R = C_v - H P- H' over a window of innovations).

* Off: ``adaptive_r_window = 0`` runs the configured R; a window longer than the run (never full) goes
  through the adaptive code with the factor 1 and gives the same solution bit for bit; the per-record
  sigmas the update used (``Solution.gnss_sigma``) are the configured ones.
* Noise 4x smaller than configured (sigma; 16x in variance) on a simulated mover that ends standing:
  the adapted variance comes to the simulated one (mean over the records after the first window
  within 0.75-1.33 of it per block of rows) and the filter becomes consistent (NIS per row within
  0.8-1.25, rms(error/sigma) of the position and velocity within 0.7-1.45), where the configured R
  leaves it underconfident (NIS per row below 0.3).
* Noise 4x larger than configured: R stays at the configured value (the upper clamp; the adaptive
  form never inflates R) once the first fix (the initial covariance's H P- H') has left the window.
* The keys: TOML, validation (loose EKF / RB-UKF only, window 0..256, fraction in (0, 1]).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import insnav
from insnav.calib.tune import holdout_report
from insnav.config import ConfigError, ImuNoise, RunConfig, load_config
from insnav.filters.loose import loose_gnss_rows

#: a mover that turns for 120 s at 1.5 m/s and then stands for 100 s; tactical-grade IMU; fixes at 1 Hz
#: with 2 cm / 2 cm/s white noise, the data's sigmas equal to it
_SEGMENTS = [{"label": "standstill", "duration_s": 5.0}, {"duration_s": 4.0, "target_speed_mps": 1.5}]
for _i in range(10):
    _SEGMENTS += [{"duration_s": 6.0, "heading_change_deg": 90.0 if _i % 2 == 0 else -90.0}, {"duration_s": 6.0}]
_SEGMENTS += [{"duration_s": 3.0, "target_speed_mps": 0.0}, {"label": "standstill", "duration_s": 100.0}]
SIGMA_POS_M, SIGMA_VEL_MPS = 0.02, 0.02
MOVER = {"extends": "seed000-car", "name": "adaptive-r-mover", "run": {"gate_prob": 0.9999},
         "motion": {"transition_s": 1.0, "segments": _SEGMENTS},
         "imu": {"rate_hz": 100.0,
                 "gyro": {"bias_sigma_dph": 0.0, "gm_sigma_dph": 3.0, "gm_tau_s": 300.0, "arw_deg_per_sqrth": 0.1},
                 "accel": {"bias_sigma_mg": 0.0, "gm_sigma_mg": 0.5, "gm_tau_s": 300.0, "vrw_mps_per_sqrth": 0.05}},
         "gnss": {"rate_hz": 1.0, "sigma_h_m": SIGMA_POS_M, "sigma_v_m": SIGMA_POS_M,
                  "sigma_vel_mps": SIGMA_VEL_MPS, "outages": []}}
WINDOW = 50


@pytest.fixture(scope="module")
def mover():
    ds = insnav.simulate(MOVER, seed=3)
    return ds, ImuNoise.from_dataset_model(ds.imu_model)


def _configured_sigma(ds, cfg) -> np.ndarray:
    """The configured 1-sigma of each record's rows (N, E, D, vN, vE, vD) in the engine's order."""
    return loose_gnss_rows(ds.gnss, cfg)[:, 7:13]


def test_off_and_a_window_never_full_give_the_configured_solution(mover):
    ds, noise = mover
    cfg = RunConfig(filter="ekf", imu=noise)
    off = insnav.run(ds, config=dataclasses.replace(cfg))
    # more records than the run has: the window never fills, the factor is 1 on every row
    never = insnav.run(ds, config=dataclasses.replace(cfg, adaptive_r_window=256))
    assert len(ds.gnss.t_valid) < 256
    for f in ("t", "lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "yaw_deg", "sigma_pos_n_m", "innovation", "nis"):
        assert np.array_equal(getattr(off, f), getattr(never, f), equal_nan=True), f
    used = off.gnss_status == 1
    assert used.sum() > 150
    assert np.array_equal(off.gnss_sigma[used], _configured_sigma(ds, cfg)[used])
    assert np.array_equal(never.gnss_sigma, off.gnss_sigma, equal_nan=True)


def test_noise_smaller_than_configured_is_found_and_the_filter_becomes_consistent(mover):
    """True sigma 1/4 of the configured one.  Tolerance of the adapted variance: with H P- H' about
    R/5, a window of 50 records estimates R with a standard deviation of about sqrt(2/50) 1.2 R =
    0.24 R, and the mean over some 130 overlapping windows (about 3 independent ones) per row and over
    3 rows about 0.08 R; 0.75-1.33 is 3 of those.  Consistency: the run with the true R gives
    rms(error/sigma) 0.9-1.25 on this scenario (errors correlated over tens of seconds: few
    independent values per axis), and the window's own estimation noise makes the filter overconfident
    by about 2/N (1 + H P- H'/R)^2 = 6 % in variance (E[R / R^] > 1 for a noisy R^; 25 % with
    N = 20): rms(error/sigma) within 0.7-1.45, NIS per row within 0.8-1.25 (seeds 3, 4, 5: 1.05-1.12)."""
    ds, noise = mover
    cfg = RunConfig(filter="ekf", imu=noise, gnss_pos_sigma_scale=4.0, gnss_vel_sigma_scale=4.0)
    fixed = insnav.run(ds, config=dataclasses.replace(cfg))
    adapt = insnav.run(ds, config=dataclasses.replace(cfg, adaptive_r_window=WINDOW))
    conf = _configured_sigma(ds, cfg)
    assert conf[:, :3] == pytest.approx(4.0 * SIGMA_POS_M) and conf[:, 3:] == pytest.approx(4.0 * SIGMA_VEL_MPS)
    used = adapt.gnss_status == 1
    after = used & (np.arange(len(used)) >= 2 * WINDOW)
    var = adapt.gnss_sigma[after] ** 2
    for rows, true_sigma in ((slice(0, 3), SIGMA_POS_M), (slice(3, 6), SIGMA_VEL_MPS)):
        ratio = var[:, rows].mean() / true_sigma ** 2
        assert 0.75 < ratio < 1.33, (rows, ratio)
    assert np.all(adapt.gnss_sigma[used] <= conf[used])  # never above the configured R
    t_from = float(adapt.gnss_t[2 * WINDOW])
    r_fixed, r_adapt = holdout_report(fixed, ds.truth, t_from), holdout_report(adapt, ds.truth, t_from)
    assert r_fixed["nis_per_row"] < 0.3  # 1/16 for the configured R alone; H P- H' adds a little
    assert 0.8 < r_adapt["nis_per_row"] < 1.25, r_adapt["nis_per_row"]
    for k in ("pos_n_m", "vel_n_mps"):
        v = np.asarray(r_adapt["nees"][k])
        assert np.all((v > 0.7) & (v < 1.45)), (k, v)
        assert max(r_fixed["nees"][k]) < 0.85, (k, r_fixed["nees"][k])  # underconfident without it


def test_noise_larger_than_configured_keeps_the_configured_r(mover):
    """True sigma 4x the configured one: the windows' innovations exceed H P- H' + R, the factor is
    clamped at 1 (documented: the adaptive form never inflates R; the innovation gate and the tuner's
    factors handle noise above the configured) on every record whose window no longer holds the first
    fix.  The window that holds it can go to the floor: the first fix's H P- H' is the initial
    covariance's (2 m), one sample of y^2 - H P- H' with a spread of metres^2 that outweighs the
    window's millimetres^2 (a limit of the unweighted windowed estimate, measured here: at most the
    N records from the N-th on)."""
    ds, noise = mover
    cfg = RunConfig(filter="ekf", imu=noise, gnss_pos_sigma_scale=0.25, gnss_vel_sigma_scale=0.25, gate_prob=0.0)
    adapt = insnav.run(ds, config=dataclasses.replace(cfg, adaptive_r_window=WINDOW))
    used = adapt.gnss_status == 1
    assert used.sum() > 150
    conf = _configured_sigma(ds, cfg)
    k = np.arange(len(used))
    late = used & (k >= 2 * WINDOW)
    assert np.array_equal(adapt.gnss_sigma[late], conf[late])
    early = used & (k < 2 * WINDOW)
    assert np.all(adapt.gnss_sigma[early] <= conf[early])
    assert np.mean(adapt.gnss_sigma[used] == conf[used]) > 0.98
    assert holdout_report(adapt, ds.truth, float(adapt.gnss_t[0]))["nis_per_row"] > 4.0  # the noise is larger


def test_rbukf_adapts_too_and_the_min_fraction_clamps(mover):
    """RB-UKF: the same estimate (its update is linear in H).  A lower clamp above the true ratio
    (1/16) holds the adapted variance at that fraction of the configured one."""
    ds, noise = mover
    cfg = RunConfig(filter="rbukf", imu=noise, gnss_pos_sigma_scale=4.0, gnss_vel_sigma_scale=4.0,
                    adaptive_r_window=WINDOW, adaptive_r_min_fraction=0.25)
    sol = insnav.run(ds, config=cfg)
    conf = _configured_sigma(ds, cfg)
    used = (sol.gnss_status == 1) & (np.arange(len(sol.gnss_status)) >= 2 * WINDOW)
    f = (sol.gnss_sigma[used] / conf[used]) ** 2
    assert f.min() == pytest.approx(0.25, rel=1e-12) and np.mean(np.isclose(f, 0.25, rtol=1e-12)) > 0.5
    assert f.max() <= 1.0


def test_keys_from_toml_and_validation(tmp_path):
    p = tmp_path / "run.toml"
    p.write_text("filter = \"ekf\"\nadaptive_r_window = 30\nadaptive_r_min_fraction = 0.05\n")
    cfg = load_config(p)
    assert (cfg.adaptive_r_window, cfg.adaptive_r_min_fraction) == (30, 0.05)
    assert RunConfig().adaptive_r_window == 0  # off by default
    for bad in (dict(adaptive_r_window=-1), dict(adaptive_r_window=257), dict(adaptive_r_window=2.5),
                dict(adaptive_r_window=True), dict(adaptive_r_min_fraction=0.0),
                dict(adaptive_r_min_fraction=1.5), dict(adaptive_r_min_fraction=math.nan),
                dict(adaptive_r_window=10, filter="ukf"), dict(adaptive_r_window=10, coupling="tight")):
        with pytest.raises(ConfigError, match="adaptive_r"):
            RunConfig(**bad).validate()
