"""Gauss-Markov pseudorange error states of the tight EKF
(cpp/include/insnav/meas/pseudorange_gm.hpp; Gelb 1974, Table 3.8-1).

- sigma = 0 is the filter without the block, bit for bit; a vanishing sigma
  (1e-6 m) differs from it by less than 1e-12 relative (the exact reduction);
- the folded update (H' = H_x + D G, R' = R + D P_e D^T, then the block's
  posterior) equals the joint Kalman update of [x; b] with the +1 column of
  the pseudorange rows (and none in the Doppler rows);
- on a simulation whose pseudoranges carry injected Gauss-Markov errors, the
  filter with the block (true sigma and tau) is consistent (position
  rms(error/sigma) in 0.7-1.3) where the white-noise filter with the same
  total variance is not.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import insnav.sim as sim
from insnav import _core
from insnav.analysis import errors, rms
from insnav.config import ConfigError, RunConfig
from insnav.filters._setup import tight_inputs_for
from insnav.filters.tight import run_tight
from conftest import first_segments

GM_SIGMA_M, GM_TAU_S, WHITE_SIGMA_M = 4.0, 45.0, 1.0


def _scenario(duration=240.0):
    base = sim.simulate("seed003-4sat", seed=0, with_truth=False).scenario
    sc = first_segments({k: (dict(v) if isinstance(v, dict) else v) for k, v in base.items()}, duration)
    sc["gnss_raw"] = dict(sc["gnss_raw"], windows=[], max_sats=8, sigma_pr_m=WHITE_SIGMA_M, sigma_prr_mps=0.05)
    return sc


@pytest.fixture(scope="module")
def sc():
    return _scenario()


def _inject_gm(inputs, seed, sigma_m=GM_SIGMA_M, tau_s=GM_TAU_S):
    """The inputs with a first-order Gauss-Markov error per satellite added to
    the pseudoranges (exact discretisation, stationary start)."""
    rng = np.random.default_rng(seed)
    sats = np.array(inputs.sats, float)
    state: dict[int, tuple[float, float]] = {}
    for e, t in enumerate(inputs.epoch_t):
        for j in range(inputs.epoch_start[e], inputs.epoch_start[e + 1]):
            prn = int(inputs.prn[j])
            if prn in state:
                b, t0 = state[prn]
                a = np.exp(-(t - t0) / tau_s)
                b = a * b + sigma_m * np.sqrt(1.0 - a * a) * rng.standard_normal()
            else:
                b = sigma_m * rng.standard_normal()
            state[prn] = (b, t)
            sats[j, 0] += b
    return dataclasses.replace(inputs, sats=sats)


def test_sigma_zero_is_the_filter_without_the_block(sc):
    ds = sim.simulate(sc, seed=3)
    plain = run_tight(ds, RunConfig(filter="ekf", init_seed=3))
    off = run_tight(ds, RunConfig(filter="ekf", init_seed=3, pr_gm_sigma_m=0.0, pr_gm_tau_s=30.0))
    for name in ("lat_deg", "lon_deg", "h_m", "v_n"):
        assert np.array_equal(getattr(plain, name), getattr(off, name))
    assert np.array_equal(plain.sigma_pos_n_m, off.sigma_pos_n_m)
    assert np.array_equal(plain.nis, off.nis, equal_nan=True)
    # a vanishing Gauss-Markov sigma: the same filter to round-off
    tiny = run_tight(ds, RunConfig(filter="ekf", init_seed=3, pr_gm_sigma_m=1e-6, pr_gm_tau_s=30.0))
    for name in ("lat_deg", "lon_deg"):
        assert np.max(np.abs(getattr(tiny, name) - getattr(plain, name))) < 1e-10  # deg: < 1e-5 m
    assert np.max(np.abs(tiny.h_m - plain.h_m)) < 1e-5
    assert np.max(np.abs(tiny.v_n - plain.v_n)) < 1e-6
    assert np.max(np.abs(tiny.sigma_pos_n_m - plain.sigma_pos_n_m) / plain.sigma_pos_n_m) < 1e-9
    ok = np.isfinite(plain.nis)
    assert np.max(np.abs(tiny.nis[ok] - plain.nis[ok]) / np.maximum(plain.nis[ok], 1e-3)) < 1e-6


def test_fold_equals_the_joint_update():
    """PseudorangeGmBlock::fold + the EKF update + joint_posterior against the
    joint Kalman update of [x; b] (H_joint = [H_x, D]), on random numbers."""
    rng = np.random.default_rng(1)
    n, nb, m = 17, 5, 9
    A = rng.standard_normal((n + nb, n + nb))
    P = A @ A.T + 0.5 * np.eye(n + nb)
    Hx = rng.standard_normal((m, n))
    R = np.diag(rng.uniform(0.5, 2.0, m))
    y = rng.standard_normal(m)
    row_slot = np.array([0, -1, 2, -1, 1, 4, -1, 3, -1], np.int32)  # -1: a Doppler row
    out = _core.pseudorange_gm_fold_check(P[:n, :n], P[:n, n:], P[n:, n:], Hx, R, y, row_slot)
    D = np.zeros((m, nb))
    for r, s in enumerate(row_slot):
        if s >= 0:
            D[r, s] = 1.0
    H = np.hstack([Hx, D])
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    x = K @ y
    Pp = P - K @ S @ K.T
    assert np.isclose(out["nis"], y @ np.linalg.solve(S, y), rtol=1e-10)
    assert np.allclose(out["x"], x[:n], atol=1e-10)
    assert np.allclose(out["xb"], x[n:], atol=1e-10)
    assert np.allclose(out["Pxx"], Pp[:n, :n], atol=1e-10)
    assert np.allclose(out["Pxb"], Pp[:n, n:], atol=1e-10)
    assert np.allclose(out["Pbb"], Pp[n:, n:], atol=1e-10)


def _consistency(sol, truth, t0=60.0):
    e = errors(sol, truth)
    w = e["t"] > t0
    return e["pos_n_m"][w] / e["sigma_pos_n_m"][w]


def test_gauss_markov_errors_need_the_block(sc):
    """Injected Gauss-Markov errors (sigma 4 m, tau 45 s) plus 1 m white noise
    on the pseudoranges (Doppler rows unchanged), pooled over twenty runs: with
    the block (true sigma and tau) position rms(error/sigma) is within 0.7-1.3
    on every axis; the white-noise filter with the same total variance per row
    (sqrt(1 + 16) m) is over-confident (above 2 on every axis, five runs).

    Many runs: a 240 s run holds only a few correlation times, and single-run
    ratios spread from 0.2 to 2.3 (seeds 21-30 pooled gave N 1.40, seeds
    31-50 N 0.98)."""
    z_gm, z_white = [], []
    for seed in range(31, 51):
        ds = sim.simulate(sc, seed=seed)
        inputs = _inject_gm(tight_inputs_for(ds, elevation_mask_deg=10.0, max_sats=8), seed)
        gm = run_tight(ds, RunConfig(filter="ekf", init_seed=seed, pr_gm_sigma_m=GM_SIGMA_M, pr_gm_tau_s=GM_TAU_S),
                       inputs=inputs)
        z_gm.append(_consistency(gm, ds.truth))
        if seed < 36:
            s = np.array(inputs.sats, float)
            s[:, 10] = np.sqrt(s[:, 10] ** 2 + GM_SIGMA_M ** 2)
            white = run_tight(ds, RunConfig(filter="ekf", init_seed=seed), inputs=dataclasses.replace(inputs, sats=s))
            z_white.append(_consistency(white, ds.truth))
    r_gm = rms(np.concatenate(z_gm))
    r_white = rms(np.concatenate(z_white))
    assert np.all((r_gm > 0.7) & (r_gm < 1.3)), r_gm
    assert np.all(r_white > 2.0), r_white


def test_config_errors():
    with pytest.raises(ConfigError, match="pr_gm_sigma_m"):
        RunConfig(coupling="tight", filter="rbukf", pr_gm_sigma_m=2.0).validate()
    with pytest.raises(ConfigError, match="pr_gm_tau_s"):
        RunConfig(coupling="tight", filter="ekf", pr_gm_sigma_m=2.0, pr_gm_tau_s=0.0).validate()
    with pytest.raises(ConfigError, match="pr_gm_sigma_m"):
        RunConfig(coupling="tight", filter="ekf", pr_gm_sigma_m=2.0, smooth=True).validate()


def test_tuner_factors(sc):
    """insnav tune: the Gauss-Markov sigma and tau are factors of a tight run with the block on (and only
    then), scaled in log space like the others and written to the tuned TOML."""
    from insnav.calib.tune import TuneResult, default_parameters, scaled_config, tune, tuned_toml_dict
    from insnav.config import ImuNoise

    ds = sim.simulate(sc, seed=5)
    on = RunConfig(coupling="tight", filter="ekf", pr_gm_sigma_m=2.0, pr_gm_tau_s=40.0)
    assert default_parameters(ds, on)[-2:] == ["pr_gm_sigma", "pr_gm_tau"]
    assert "pr_gm_sigma" not in default_parameters(ds, RunConfig(coupling="tight", filter="ekf"))
    c = scaled_config(on, ImuNoise.from_dataset_model(ds.imu_model), {"pr_gm_sigma": 1.5, "pr_gm_tau": 0.5})
    assert (c.pr_gm_sigma_m, c.pr_gm_tau_s) == (3.0, 20.0)
    d = tuned_toml_dict({}, TuneResult(names=["pr_gm_sigma"], scales={}, base=on, tuned=c, log_likelihood_base=0.0,
                                       log_likelihood_tuned=0.0, records=1, runs=1, seconds=0.0, t_split=0.0,
                                       holdout=0.3))
    assert (d["pr_gm_sigma_m"], d["pr_gm_tau_s"]) == (3.0, 20.0)
    with pytest.raises(ConfigError, match="pr_gm_sigma"):
        tune(ds, RunConfig(coupling="tight", filter="ekf"), params=["gnss_pos", "pr_gm_sigma"], max_runs=10)


def _drop_epochs(inputs, t0, t1):
    """The inputs without the epochs in (t0, t1) [s] (a GNSS outage)."""
    keep_ep = ~((inputs.epoch_t > t0) & (inputs.epoch_t < t1))
    counts = np.diff(inputs.epoch_start)
    rows = np.repeat(keep_ep, counts)
    start = np.concatenate([[0], np.cumsum(counts[keep_ep])]).astype(np.int64)
    sub = dict(epoch_t=np.asarray(inputs.epoch_t)[keep_ep], epoch_start=start, sats=np.asarray(inputs.sats)[rows],
               prn=np.asarray(inputs.prn)[rows], elevation_deg=np.asarray(inputs.elevation_deg)[rows],
               system=np.asarray(inputs.system)[rows])
    return dataclasses.replace(inputs, **sub)


def test_outage_cycles_carry_the_block(sc):
    """Over a 20 s GNSS outage the engine closes a filter cycle every second;
    the block's cross-covariance is carried over each (P_xb <- Phi P_xb).  The
    EKF's propagation does not depend on where the cycles end, so the run
    equals the one whose cycle spans the whole outage (cycle_period_s 1000 s)
    to round-off."""
    ds = sim.simulate(sc, seed=6)
    inputs = _drop_epochs(_inject_gm(tight_inputs_for(ds, elevation_mask_deg=10.0, max_sats=8), 6), 120.0, 141.0)
    runs = [run_tight(ds, RunConfig(filter="ekf", init_seed=6, pr_gm_sigma_m=GM_SIGMA_M, pr_gm_tau_s=GM_TAU_S,
                                    cycle_period_s=p), inputs=inputs) for p in (1.0, 1000.0)]
    e = [errors(r, ds.truth)["pos_n_m"] for r in runs]
    assert np.max(np.abs(e[0] - e[1])) < 1e-6
    assert np.max(np.abs(runs[0].sigma_pos_n_m - runs[1].sigma_pos_n_m)) < 1e-6
    assert np.max(np.abs(e[0])) > 1.0  # (the comparison is not of zeros)


def test_push_api_refuses_the_block(sc):
    """The Gauss-Markov states run in the batch run only: the push API says so in one line."""
    from insnav.filters.navigator import TightNavigator

    ds = sim.simulate(sc, seed=5)
    with pytest.raises(ValueError, match="pr_gm_sigma_m: .*batch tight run only"):
        TightNavigator.from_dataset(ds, RunConfig(coupling="tight", filter="ekf", pr_gm_sigma_m=2.0))
