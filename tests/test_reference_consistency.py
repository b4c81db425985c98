"""Consistency against a reference that describes another point and has its own noise
(insnav.calib.tune.reference_errors, holdout_report's ``nees_total``).

A reference r = x + C_nb l_b + w (the antenna, with white noise w of a known
sigma_ref; its velocity column lagging by velocity_lag_s) and a consistent
filter (its IMU-centre error drawn with its own sigma): the statistic
rms(e / sqrt(sigma_filter^2 + sigma_ref^2)) of the solution's antenna point is
1 (E[e^2] = sigma_filter^2 + sigma_ref^2), while the IMU-centre statistic
rms(e / sigma_filter) is sqrt(1 + (b^2 + sigma_ref^2) / sigma_filter^2) per
axis, and checked against that value too.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from insnav.calib.tune import ReferenceModel, _rms_ratio, holdout_report, reference_errors
from insnav.data.dataset import Truth
from insnav.earth import radii
from insnav.sim.trajectory import rotate_b_to_n

N = 20000
LAT0, LON0, H0 = np.radians(40.0), np.radians(-105.0), 1600.0
LEVER_B = np.array([0.3, -0.2, -0.4])  # IMU -> antenna, body FRD [m]
LAG_S = 0.132
SIG_REF_POS = np.array([0.010, 0.012, 0.020])  # the reference's own noise [m]
SIG_REF_VEL = np.array([0.05, 0.04, 0.06])  # [m/s]
# rms(e/sigma) of N samples: standard error about 1/sqrt(2 N) = 0.005; the tolerance is 6 of them
TOL = 0.03


def _walk(t):
    """A circle of radius 20 m at 1.2 m/s, the body's heading along the track and a 0.8 rad/s yaw sway
    (the lever arm's velocity term C_nb (omega x l) then matters): NED position [m], velocity [m/s],
    Euler [rad], omega_ib_b [rad/s] (Earth rate left out)."""
    w = 1.2 / 20.0
    a_sw, f_sw = 0.2, 4.0  # sway: a sin(f t) [rad]
    p = np.column_stack([20 * np.sin(w * t), 20 * (1 - np.cos(w * t)), np.zeros_like(t)])
    v = np.column_stack([1.2 * np.cos(w * t), 1.2 * np.sin(w * t), np.zeros_like(t)])
    yaw = w * t + a_sw * np.sin(f_sw * t)
    eul = np.column_stack([np.zeros_like(t), np.zeros_like(t), yaw])
    omega = np.column_stack([np.zeros_like(t), np.zeros_like(t), w + a_sw * f_sw * np.cos(f_sw * t)])
    return p, v, eul, omega


def _geo(p_n):
    r_m, r_n = radii(LAT0)
    lat = LAT0 + p_n[:, 0] / (r_m + H0)
    lon = LON0 + p_n[:, 1] / ((r_n + H0) * np.cos(LAT0))
    return np.degrees(lat), np.degrees(lon), H0 - p_n[:, 2]


def _case(seed=7):
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 0.25
    p, v, eul, omega = _walk(t)
    # the reference: the antenna (+ its own noise), its velocity column the antenna velocity LAG_S earlier
    p_ant = p + rotate_b_to_n(eul, np.tile(LEVER_B, (N, 1)))
    _, v_early, eul_early, om_early = _walk(t - LAG_S)
    v_ant_early = v_early + rotate_b_to_n(eul_early, np.cross(om_early, LEVER_B))
    lat, lon, h = _geo(p_ant + SIG_REF_POS * rng.standard_normal((N, 3)))
    nan = np.full(N, np.nan)
    ref = Truth(t, lat, lon, h, v_ant_early + SIG_REF_VEL * rng.standard_normal((N, 3)), nan, nan, nan)
    # a consistent filter, output at the reference epochs and LAG_S before them (the velocity is compared
    # there): sigmas varying over time, independent errors drawn with them
    ts = np.sort(np.concatenate([t, t - LAG_S]))
    ps, vs, euls, omegas = _walk(ts)
    sig_ps = np.column_stack([0.02 + 0.015 * np.sin(0.01 * ts) ** 2] * 2 + [0.03 + 0.0 * ts])
    sig_vs = np.column_stack([0.03 + 0.02 * np.cos(0.007 * ts) ** 2] * 3)
    lat, lon, h = _geo(ps + sig_ps * rng.standard_normal((2 * N, 3)))
    sol = SimpleNamespace(t=ts, lat_deg=lat, lon_deg=lon, h_m=h, v_n=vs + sig_vs * rng.standard_normal((2 * N, 3)),
                          roll_deg=np.degrees(euls[:, 0]), pitch_deg=np.degrees(euls[:, 1]),
                          yaw_deg=np.degrees(euls[:, 2]), sigma_pos_n_m=sig_ps, sigma_vel_n_mps=sig_vs,
                          sigma_att_deg=np.full((2 * N, 3), 0.5))
    model = ReferenceModel(lever_arm_b=LEVER_B, sigma_pos_n_m=SIG_REF_POS, sigma_vel_n_mps=SIG_REF_VEL,
                           velocity_lag_s=LAG_S, omega_t=ts, omega_ib_b_radps=omegas)
    sig_p = np.column_stack([0.02 + 0.015 * np.sin(0.01 * t) ** 2] * 2 + [0.03 + 0.0 * t])
    return sol, ref, model, eul, sig_p


def test_total_variance_statistic_is_one_for_a_consistent_filter():
    sol, ref, model, eul, sig_p = _case()
    r = reference_errors(sol, ref, model)
    pos = _rms_ratio(r["pos_n_m"], np.hypot(r["sigma_filter_pos"], r["sigma_ref_pos"]))
    vel = _rms_ratio(r["vel_n_mps"], np.hypot(r["sigma_filter_vel"], r["sigma_ref_vel"]))
    assert np.all(np.abs(np.array(pos) - 1.0) < TOL), pos
    assert np.all(np.abs(np.array(vel) - 1.0) < TOL), vel
    assert np.isfinite(r["vel_n_mps"]).all()  # the solution starts LAG_S before the reference
    # cut the solution at the first reference epoch: that epoch has no solution LAG_S before it
    cut = SimpleNamespace(**{k: v[1:] for k, v in vars(sol).items()})
    r1 = reference_errors(cut, ref, model)
    assert np.isnan(r1["vel_n_mps"][0]).all() and np.isfinite(r1["vel_n_mps"][1:]).all()
    # the neglected attitude share: |l_b| x the largest attitude sigma
    assert abs(r["lever_sigma_max_m"] - np.linalg.norm(LEVER_B) * np.radians(0.5)) < 1e-12


def test_raw_statistic_is_not_one_and_matches_its_expectation():
    sol, ref, model, eul, sig_p = _case()
    raw = reference_errors(sol, ref, ReferenceModel())  # IMU centre, no reference noise, no re-timing
    pos = np.array(_rms_ratio(raw["pos_n_m"], raw["sigma_filter_pos"]))
    vel = np.array(_rms_ratio(raw["vel_n_mps"], raw["sigma_filter_vel"]))
    assert np.all(pos > 1.3) and np.all(vel > 1.3), (pos, vel)
    # E[(e/sigma)^2] = 1 + (b^2 + sigma_ref^2) / sigma^2 per axis (b = C_nb l_b)
    b = rotate_b_to_n(eul, np.tile(LEVER_B, (N, 1)))
    expected = np.sqrt(np.mean(1.0 + (b ** 2 + SIG_REF_POS ** 2) / sig_p ** 2, axis=0))
    assert np.all(np.abs(pos / expected - 1.0) < TOL), (pos, expected)
    # each correction alone is not enough: without the reference's noise, or without the lever arm
    no_noise = reference_errors(sol, ref, ReferenceModel(lever_arm_b=LEVER_B, velocity_lag_s=LAG_S,
                                                        omega_t=model.omega_t,
                                                        omega_ib_b_radps=model.omega_ib_b_radps))
    assert np.all(np.array(_rms_ratio(no_noise["pos_n_m"], no_noise["sigma_filter_pos"])) > 1.05)
    no_lever = reference_errors(sol, ref, ReferenceModel(sigma_pos_n_m=SIG_REF_POS, sigma_vel_n_mps=SIG_REF_VEL,
                                                        velocity_lag_s=LAG_S))
    tot = np.hypot(no_lever["sigma_filter_pos"], no_lever["sigma_ref_pos"])
    assert max(_rms_ratio(no_lever["pos_n_m"], tot)) > 2.0


def test_default_model_reduces_to_the_plain_errors():
    """An exact reference of the IMU centre (ReferenceModel()): the errors are insnav.analysis.metrics.errors's,
    so nees_total equals the raw rms(error/sigma) (holdout_report's nees)."""
    from insnav.analysis.evaluate import _solution_at
    from insnav.analysis.metrics import errors

    sol, ref, model, eul, sig_p = _case()
    r = reference_errors(sol, ref, ReferenceModel())
    e = errors(_solution_at(sol, r["t"]), ref)
    np.testing.assert_array_equal(r["pos_n_m"], e["pos_n_m"])
    np.testing.assert_array_equal(r["vel_n_mps"], e["vel_n_mps"])
    assert not np.any(r["sigma_ref_pos"]) and not np.any(r["sigma_ref_vel"]) and r["lever_sigma_max_m"] == 0.0


def test_holdout_report_uses_the_reference_model():
    """holdout_report: nees_total is the statistic above (1 within TOL for the consistent filter), nees the raw
    IMU-centre one; the reference's share of the predicted variance is sigma_ref^2 / (sigma^2 + sigma_ref^2)."""
    sol, ref, model, eul, sig_p = _case()
    sol.gnss_t, sol.gnss_status, sol.nis = np.zeros(0), np.zeros(0, int), np.zeros(0)
    sol.log_det_s, sol.innovation = np.zeros(0), np.zeros((0, 6))
    rep = holdout_report(sol, ref, t_from=0.0, reference_model=model)
    assert np.all(np.abs(np.array(rep["nees_total"]["pos_n_m"]) - 1.0) < TOL), rep["nees_total"]
    assert np.all(np.abs(np.array(rep["nees_total"]["vel_n_mps"]) - 1.0) < TOL), rep["nees_total"]
    assert min(rep["nees"]["pos_n_m"]) > 1.3
    share = np.mean(SIG_REF_POS ** 2 / (sig_p ** 2 + SIG_REF_POS ** 2), axis=0)
    np.testing.assert_allclose(rep["reference_variance_share_pos"], share, rtol=1e-3)
    np.testing.assert_allclose(rep["reference_sigma_pos_m"], SIG_REF_POS, rtol=1e-12)
