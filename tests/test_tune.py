"""Noise tuning by the innovation likelihood (insnav.calib.tune, ``insnav tune``).

* On a linear-Gaussian toy (a constant-velocity model written here), the
  tuner's likelihood equals the joint Gaussian density of all measurements
  (prediction-error decomposition, Schweppe 1965), and its search recovers
  the process and measurement noise within 10 %, as the EM algorithm
  (Shumway & Stoffer 1982, written here) does.
* The engines' ln det S: at a fix one IMU sample after the start, S is
  P0 + R of the position and velocity rows (EKF and RB-UKF, loose).
* The tuned TOML loads back as the tuned settings and runs with ``insnav run``.
* Bad input: one-line errors.
"""
from __future__ import annotations

import dataclasses
import math

import tomllib
from pathlib import Path

import numpy as np
import pytest

import insnav
from insnav.calib.tune import (innovation_log_likelihood, nelder_mead_log, scaled_config, solution_log_likelihood,
                               tune)
from insnav.cli import main
from insnav.config import ConfigError, ImuNoise, RunConfig, load_config
from insnav.data.dataset import ImuData

DT = 1.0
Q_TRUE, R_TRUE = 0.04, 1.0  # white-acceleration PSD [m^2/s^3], position noise variance [m^2]


def _cv_q(q):
    """Discrete process noise of the constant-velocity model (white acceleration of PSD q)."""
    return (q * DT ** 3 / 3.0, q * DT ** 2 / 2.0, q * DT)


def _simulate(n, seed=3):
    rng = np.random.default_rng(seed)
    q11, q12, q22 = _cv_q(Q_TRUE)
    L = np.linalg.cholesky(np.array([[q11, q12], [q12, q22]]))
    x = np.zeros(2)
    y = np.empty(n)
    for k in range(n):
        x = np.array([x[0] + DT * x[1], x[1]]) + L @ rng.standard_normal(2)
        y[k] = x[0] + math.sqrt(R_TRUE) * rng.standard_normal()
    return y


def _kf(y, q, r, smooth=False):
    """Kalman filter of the CV model on position measurements y, in plain floats:
    per step the innovation's NIS and ln S; with ``smooth`` also the RTS
    smoother's E[x_k], Cov[x_k] and Cov[x_k, x_{k-1}] (Shumway & Stoffer 1982, eqs. (A.1)-(A.3))."""
    q11, q12, q22 = _cv_q(q)
    x0, x1, p00, p01, p11 = 0.0, 0.0, 100.0, 0.0, 100.0
    nis, lds, filt = [], [], []
    for yk in y:
        # predict
        a0, a1 = x0 + DT * x1, x1
        b00 = p00 + 2 * DT * p01 + DT * DT * p11 + q11
        b01 = p01 + DT * p11 + q12
        b11 = p11 + q22
        s = b00 + r
        nu = yk - a0
        nis.append(nu * nu / s)
        lds.append(math.log(s))
        k0, k1 = b00 / s, b01 / s
        x0, x1 = a0 + k0 * nu, a1 + k1 * nu
        p00, p01, p11 = b00 - k0 * b00, b01 - k0 * b01, b11 - k1 * b01
        filt.append((a0, a1, b00, b01, b11, x0, x1, p00, p01, p11))
    if not smooth:
        return np.array(nis), np.array(lds)
    n = len(y)
    xs = np.zeros((n, 2))
    Ps = np.zeros((n, 2, 2))
    C = np.zeros((n, 2, 2))  # Cov[x_k, x_{k-1} | all]
    f = filt[-1]
    xs[-1] = f[5:7]
    Ps[-1] = [[f[7], f[8]], [f[8], f[9]]]
    F = np.array([[1.0, DT], [0.0, 1.0]])
    for k in range(n - 2, -1, -1):
        fk, fn = filt[k], filt[k + 1]
        Pf = np.array([[fk[7], fk[8]], [fk[8], fk[9]]])
        Pp = np.array([[fn[2], fn[3]], [fn[3], fn[4]]])
        J = Pf @ F.T @ np.linalg.inv(Pp)
        xs[k] = np.array(fk[5:7]) + J @ (xs[k + 1] - np.array(fn[0:2]))
        Ps[k] = Pf + J @ (Ps[k + 1] - Pp) @ J.T
        C[k + 1] = Ps[k + 1] @ J.T
    return np.array(nis), np.array(lds), xs, Ps, C


def _em(y, q, r, iters):
    """EM for the scalar factors q (on the known CV structure of Q) and r (Shumway & Stoffer 1982)."""
    F = np.array([[1.0, DT], [0.0, 1.0]])
    q11, q12, q22 = _cv_q(1.0)
    Q1inv = np.linalg.inv(np.array([[q11, q12], [q12, q22]]))
    for _ in range(iters):
        _, _, xs, Ps, C = _kf(y, q, r, smooth=True)
        r = float(np.mean((y - xs[:, 0]) ** 2 + Ps[:, 0, 0]))
        acc = 0.0
        for k in range(1, len(y)):
            d = xs[k] - F @ xs[k - 1]
            A = np.outer(d, d) + Ps[k] - F @ C[k].T - C[k] @ F.T + F @ Ps[k - 1] @ F.T
            acc += np.trace(Q1inv @ A)
        q = acc / (2.0 * (len(y) - 1))
    return q, r


def test_toy_likelihood_is_the_joint_gaussian_density():
    """sum over the Kalman innovations of -(nu^2/S + ln S + ln 2 pi)/2 equals ln N(y; 0, Sigma_y) of
    all measurements at once, Sigma_y built from the model (prediction-error decomposition)."""
    y = _simulate(40)
    q, r = 0.07, 0.6
    nis, lds = _kf(y, q, r)
    ll = innovation_log_likelihood(nis, lds, np.ones(len(y)))
    # joint covariance: x_0 ~ N(0, 100 I), x_k = F x_{k-1} + w_k, y_k = x_k[0] + v_k (k >= 1)
    n = len(y)
    F = np.array([[1.0, DT], [0.0, 1.0]])
    Qd = np.array([[_cv_q(q)[0], _cv_q(q)[1]], [_cv_q(q)[1], _cv_q(q)[2]]])
    P = [None] * (n + 1)
    P[0] = 100.0 * np.eye(2)
    for k in range(1, n + 1):
        P[k] = F @ P[k - 1] @ F.T + Qd
    Sig = np.empty((n, n))
    for i in range(1, n + 1):
        for j in range(i, n + 1):  # Cov[x_j, x_i] = F^(j-i) P_i
            c = (np.linalg.matrix_power(F, j - i) @ P[i])[0, 0]
            Sig[i - 1, j - 1] = Sig[j - 1, i - 1] = c
    Sig += r * np.eye(n)
    sign, logdet = np.linalg.slogdet(Sig)
    direct = -0.5 * (y @ np.linalg.solve(Sig, y) + logdet + n * math.log(2 * math.pi))
    assert sign > 0
    assert ll == pytest.approx(direct, rel=1e-10, abs=1e-8)


def test_toy_tuning_recovers_q_and_r_like_em():
    """From q and r wrong by 10x up and down, the tuner's Nelder-Mead in log space finds both within
    10 % of the truth, and within 2 % of the EM estimate (both are the maximum-likelihood estimate)."""
    y = _simulate(2000)

    def neg_ll(theta):
        nis, lds = _kf(y, math.exp(theta[0]), math.exp(theta[1]))
        return -innovation_log_likelihood(nis, lds, np.ones(len(y)))

    theta, f, evals, _ = nelder_mead_log(neg_ll, [math.log(10 * Q_TRUE), math.log(0.1 * R_TRUE)],
                                         max_evals=200, xtol=1e-3, ftol=1e-4)
    q_t, r_t = math.exp(theta[0]), math.exp(theta[1])
    assert q_t == pytest.approx(Q_TRUE, rel=0.10)
    assert r_t == pytest.approx(R_TRUE, rel=0.10)
    q_em, r_em = _em(y, Q_TRUE, R_TRUE, iters=30)  # EM from the truth: its fixed point, the MLE
    assert q_t == pytest.approx(q_em, rel=0.02)
    assert r_t == pytest.approx(r_em, rel=0.02)
    assert evals < 200


def test_robust_likelihood_is_huber_beyond_the_cap():
    """Beyond the cap c the NIS counts as 2 sqrt(c nis) - c (continuous at c, linear in the distance), and
    a shrinking S still loses: the robust ln L of an outlier falls as S -> 0 (a plain clip would rise)."""
    nis = np.array([1.0, 400.0, np.nan])
    ld = np.array([0.5, 0.5, 0.5])
    rows = np.array([1, 1, 1])
    c = 15.1
    assert innovation_log_likelihood(nis, ld, rows, nis_cap=c) == pytest.approx(
        -0.5 * (1.0 + 2 * math.sqrt(c * 400.0) - c + 1.0 + 2 * math.log(2 * math.pi)))
    assert innovation_log_likelihood([c], [0.0], [1], nis_cap=c) == pytest.approx(
        innovation_log_likelihood([c], [0.0], [1]))
    y = 1.0
    ll = [innovation_log_likelihood([y * y / s], [math.log(s)], [1], nis_cap=c) for s in (1e-2, 1e-4, 1e-6)]
    assert ll[0] > ll[1] > ll[2]


def _first_fix_dataset(seconds=20.0):
    ds = insnav.simulate("seed000-sim", seed=2)
    k = np.searchsorted(ds.imu.t, ds.t0 + seconds)
    ds = dataclasses.replace(ds, imu=ImuData(ds.imu.t[:k], ds.imu.dtheta_b[:k], ds.imu.dv_b[:k]))
    g = ds.gnss
    t = g.t_valid.copy()
    t[0] = ds.imu.t[0]  # the first fix at the first IMU sample: P there is P0 (one 5 ms step)
    ds.gnss.t_valid = t
    if hasattr(g, "t_arrival"):
        g.t_arrival = np.maximum(g.t_arrival, t)
    return ds


@pytest.mark.parametrize("filt", ["ekf", "rbukf"])
def test_engine_log_det_s_is_p0_plus_r(filt):
    """ln det S of the first fix (one IMU sample after the start, zero lever arm): the position and
    velocity rows of P0 plus R (with the GNSS sigma factors), to the propagation over 5 ms."""
    ds = _first_fix_dataset()
    cfg = RunConfig(filter=filt, init_error=False, gnss_pos_sigma_scale=2.0, gnss_vel_sigma_scale=0.5,
                    init_sigma_pos_m=[3.0, 4.0, 5.0], init_sigma_vel_mps=[0.2, 0.3, 0.4], gate_prob=0.0)
    sol = insnav.run(ds, config=cfg)
    assert np.all(np.isfinite(sol.log_det_s[sol.gnss_status == 1]))
    p0 = np.r_[np.square(cfg.init_sigma_pos_m), np.square(cfg.init_sigma_vel_mps)]
    r = np.r_[np.square(2.0 * ds.gnss.sigma_pos_n[0]), np.square(0.5 * ds.gnss.sigma_vel_n[0])]
    assert sol.gnss_status[0] == 1
    assert sol.log_det_s[0] == pytest.approx(np.sum(np.log(p0 + r)), abs=1e-4)
    ll, n = solution_log_likelihood(sol, t_to=ds.gnss.t_valid[0] + 1e-6)
    assert n == 1
    assert ll == pytest.approx(-0.5 * (sol.nis[0] + sol.log_det_s[0] + 6 * math.log(2 * math.pi)))


def test_scaled_config_multiplies_the_named_noise():
    noise = ImuNoise(gyro_bias_rw=[1e-6] * 3)
    c = scaled_config(RunConfig(gnss_pos_sigma_scale=2.0), noise, dict(gyro_arw=3.0, acc_bias=0.5, gnss_pos=1.5,
                                                                       gyro_bias=2.0))
    assert np.allclose(c.imu.gyro_arw, 3.0 * np.asarray(noise.gyro_arw))
    assert np.allclose(c.imu.acc_bias_sigma, 0.5 * np.asarray(noise.acc_bias_sigma))
    assert np.allclose(c.imu.gyro_bias_rw, 2e-6)
    assert np.allclose(c.imu.acc_vrw, noise.acc_vrw)
    assert c.gnss_pos_sigma_scale == 3.0 and c.gnss_vel_sigma_scale == 1.0
    assert noise.gyro_arw == [1e-4] * 3  # the base is not changed


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("tune") / "sim"
    ds = insnav.simulate("seed000-sim", seed=1)
    ds.save(d)
    return d


def test_cli_tune_writes_a_toml_that_runs(sim_dir, tmp_path, capsys):
    out = tmp_path / "tuned.toml"
    rc = main(["tune", str(sim_dir), "--params", "gyro_arw,gnss_pos", "--max-runs", "12", "--holdout", "0.3",
               "--out", str(out), "-q"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "mean NIS per row" in text and "rms(err/sigma) position" in text
    cfg = load_config(out)
    first = out.read_text().splitlines()[1]  # "#   gyro_arw x <factor>"
    f = float(first.split(" x ")[1])
    ds = insnav.load_dataset(sim_dir)
    base = ImuNoise.from_dataset_model(ds.imu_model)
    assert np.allclose(cfg.imu.gyro_arw, f * np.asarray(base.gyro_arw), rtol=1e-4)
    assert np.allclose(cfg.imu.acc_vrw, base.acc_vrw, rtol=1e-12)
    assert np.allclose(cfg.imu.gyro_bias_tau, base.gyro_bias_tau, rtol=1e-12)
    assert cfg.gnss_pos_sigma_scale > 0 and cfg.gnss_vel_sigma_scale == 1.0
    sol_csv = tmp_path / "sol.csv"
    assert main(["run", str(sim_dir), "--config", str(out), "--out", str(sol_csv), "-q"]) == 0
    resolved = (tmp_path / "sol.csv.config.toml").read_text()
    assert f"gnss_pos_sigma_scale = {cfg.gnss_pos_sigma_scale!r}" in resolved
    # a second tune replaces its own file without --overwrite
    assert main(["tune", str(sim_dir), "--params", "gnss_pos", "--max-runs", "6", "--out", str(out), "-q"]) == 0


def test_tune_api_round_trip_exact(sim_dir):
    """The TOML's user-unit values read back as the tuned SI settings (1e-12)."""
    from insnav._toml import dumps_toml
    from insnav.calib.tune import tuned_toml_dict
    from insnav.config import config_from_dict
    import tomllib

    ds = insnav.load_dataset(sim_dir)
    res = tune(ds, RunConfig(), params=["gyro_arw", "acc_vrw"], max_runs=8, holdout=0.5)
    assert res.runs <= 8 and res.log_likelihood_tuned >= res.log_likelihood_base
    back = config_from_dict(tomllib.loads(dumps_toml(tuned_toml_dict({}, res))))
    for f in dataclasses.fields(ImuNoise):
        assert np.allclose(getattr(back.imu, f.name), getattr(res.tuned.imu, f.name), rtol=1e-12, atol=0)


@pytest.mark.parametrize("argv, msg", [
    (["--holdout", "1.5"], "--holdout 1.5: expected a fraction of the data in [0, 0.9)"),
    (["--params", "gyro_arw,gyro_awr"], "unknown tuning parameter 'gyro_awr'"),
    (["--params", "nhc"], "tuning parameter 'nhc' needs the nhc constraint"),
    (["--max-runs", "3"], "max_runs 3: at least"),
    (["--out", "x.csv"], "the tuned configuration is a TOML file"),
    (["--block-s", "10"], "--block-s 10: the block length of --split blocks"),
])
def test_cli_bad_input_one_line(sim_dir, tmp_path, capsys, argv, msg):
    args = ["tune", str(sim_dir), "--out", str(tmp_path / "t.toml"), "-q"] + argv
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err, err


def test_bad_config_keys_one_line(sim_dir, tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("gnss_pos_sigma_scale = -1.0\n")
    assert main(["tune", str(sim_dir), "--config", str(bad), "--out", str(tmp_path / "t.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "gnss_pos_sigma_scale" in err and "> 0" in err
    bad.write_text("[imu]\ngyro_arw_deg_per_sqrt_hr = 0.1\n")
    assert main(["tune", str(sim_dir), "--config", str(bad), "--out", str(tmp_path / "t.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unknown key 'imu.gyro_arw_deg_per_sqrt_hr'" in err
    with pytest.raises(ConfigError, match="tuner needs the innovation covariance"):
        tune(insnav.load_dataset(sim_dir), RunConfig(filter="ukf"), max_runs=20)


def test_tight_engine_log_det_s_and_tuning():
    """Tight EKF: ln det S of the first epoch (moved to the first IMU sample) is that of
    blockdiag(U P_pos U' + P_cb 1 1' + R_pr, U P_vel U' + P_cd 1 1' + R_prr), U the receiver-to-satellite
    unit vectors in NED; and the tuner runs tight, with the robust row screening off in the tuned settings."""
    from conftest import short_tight_dataset
    from insnav import earth
    from insnav.filters._setup import tight_inputs_for
    from insnav.filters.tight import run_tight
    from insnav.units import DEG

    ds = short_tight_dataset(60.0)
    inp = tight_inputs_for(ds, None, elevation_mask_deg=10.0, max_sats=8)
    ep_t = inp.epoch_t.copy()
    ep_t[0] = ds.imu.t[0]
    inp = dataclasses.replace(inp, epoch_t=ep_t)
    cfg = RunConfig(filter="ekf", coupling="tight", init_error=False, gate_prob=0.0,
                    init_sigma_pos_m=[3.0, 4.0, 5.0], init_sigma_vel_mps=[0.2, 0.3, 0.4],
                    gnss_pos_sigma_scale=1.5, gnss_vel_sigma_scale=0.7)
    sol = run_tight(ds, cfg, inputs=inp, init_sigma_clock=(30.0, 1.0))
    assert sol.gnss_status[0] == 1
    a, b = inp.epoch_start[0], inp.epoch_start[1]
    s = inp.sats[a:b]
    s0 = ds.initial
    r = earth.geodetic_to_ecef(s0.lat_deg * DEG, s0.lon_deg * DEG, s0.h_m)
    u_e = (s[:, 2:5] - r) / np.linalg.norm(s[:, 2:5] - r, axis=1)[:, None]
    U = earth.ecef_to_ned_vector(s0.lat_deg * DEG, s0.lon_deg * DEG, u_e)
    blocks = []
    for col, p_nav, p_clk, f in ((0, np.square(cfg.init_sigma_pos_m), 30.0 ** 2, 1.5),
                                 (1, np.square(cfg.init_sigma_vel_mps), 1.0 ** 2, 0.7)):
        k = np.isfinite(s[:, col])
        Uk = U[k]
        blocks.append(Uk @ np.diag(p_nav) @ Uk.T + p_clk + np.diag(np.square(f * s[k, 10 + col])))
    expect = sum(np.linalg.slogdet(B)[1] for B in blocks)
    assert sol.rows[0] == sum(B.shape[0] for B in blocks)
    # to the propagation over the first IMU interval (1e-4 of ln det S per row here); a factor left out
    # of R (1.5 or 0.7) would move it by ~0.7 per row
    assert sol.log_det_s[0] == pytest.approx(expect, abs=5e-3)

    res = tune(ds, RunConfig(filter="ekf", coupling="tight"), params=["gnss_pos", "gnss_vel"], max_runs=10)
    assert res.log_likelihood_tuned >= res.log_likelihood_base
    assert res.tuned.robust.screening is False and res.tuned.robust.fde_max_sats == 0


def test_innovation_whiteness_flags_correlated_fix_errors():
    """innovation_lag1 (Mehra 1970, Sec. III: the innovations of a right model are white): about 0
    (within 3 / sqrt(pairs)) for seed000-sim's white fix errors; clearly positive (> 0.5) when the
    fixes' position error is instead slowly varying (first-order Gauss-Markov, 3 m, 60 s) under
    the same white sigmas.  Exact on a hand-made sequence: +-1 alternating, n values, gives the
    sample autocorrelation sum d_k d_k+1 / sum d_k^2 = -(n - 1) / n."""
    from insnav.calib.tune import innovation_lag1
    from insnav.earth import radii

    ds = insnav.simulate("seed000-sim", seed=4)
    white = innovation_lag1(insnav.run(ds, "ekf"))
    pairs = 3 * (np.count_nonzero(np.isfinite(ds.gnss.lat_deg)) - 1)
    print("white", white, "pairs", pairs)
    assert abs(white[0]) < 3.0 / math.sqrt(pairs) and abs(white[1]) < 3.0 / math.sqrt(pairs)
    rng = np.random.default_rng(1)
    g = ds.gnss
    t = np.asarray(g.t_valid, float)
    phi = np.exp(-np.diff(t, prepend=t[0]) / 60.0)
    e = np.zeros((t.size, 3))
    e[0] = 3.0 * rng.standard_normal(3)
    for k in range(1, t.size):
        e[k] = phi[k] * e[k - 1] + 3.0 * math.sqrt(1 - phi[k] ** 2) * rng.standard_normal(3)
    # the fixes: the antenna's true track plus the slow error only (their white noise replaced by it)
    tr = ds.truth
    lat0, lon0 = (np.interp(t, tr.t, getattr(tr, k)) for k in ("lat_deg", "lon_deg"))
    lat0 = lat0 + (g.lat_deg - np.interp(t, tr.t, tr.lat_deg)).mean()  # keep the lever arm's mean
    lon0 = lon0 + (g.lon_deg - np.interp(t, tr.t, tr.lon_deg)).mean()
    R_M, R_N = radii(np.deg2rad(lat0))
    lat = lat0 + np.rad2deg(e[:, 0] / (R_M + g.h_m))
    lon = lon0 + np.rad2deg(e[:, 1] / ((R_N + g.h_m) * np.cos(np.deg2rad(lat0))))
    h = np.interp(t, tr.t, tr.h_m) + (g.h_m - np.interp(t, tr.t, tr.h_m)).mean() - e[:, 2]
    biased = dataclasses.replace(ds, gnss=dataclasses.replace(g, lat_deg=lat, lon_deg=lon, h_m=h))
    corr = innovation_lag1(insnav.run(biased, "ekf"))
    print("correlated", corr)
    assert corr[0] > 0.5

    class _Sol:  # one component alternating +-1
        gnss_t = np.arange(10.0)
        gnss_status = np.ones(10, np.int8)
        innovation = np.column_stack([np.tile([1.0, -1.0], 5), np.full((10, 5), np.nan)])

    lag = innovation_lag1(_Sol())
    assert lag[0] == pytest.approx(-0.9, abs=1e-12) and math.isnan(lag[1])


def test_tune_without_gnss_records_is_one_line_with_one_prefix(tmp_path, capsys):
    """A dataset without GNSS records (``simulate --from-truth`` writes an IMU-only dataset): before,
    ``insnav tune: error: insnav tune: no GNSS record ...``."""
    import insnav
    from insnav.sim.scenario import resolve_raw

    raw, _ = resolve_raw("seed000-sim")
    raw["motion"]["segments"] = [{"duration_s": 20.0}]
    raw["motion"].pop("oscillations", None)
    raw["gnss"]["outages"] = [[0.0, 30.0]]
    ds = insnav.simulate(raw, seed=1).save(tmp_path / "ds")
    out = tmp_path / "tuned.toml"
    from insnav.cli import main

    assert main(["tune", str(ds), "--max-runs", "16", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("insnav tune: error: no GNSS record with an innovation covariance in the tuning "
                          "segment"), err
    assert len(err.splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("fixes, message", [
    (2, r"^insnav tune: error: 2 GNSS or constraint records with an innovation in the tuning segment \(before t = "
        r"[0-9.]+ s\): too few to tune 7 factors \(at least 5 per factor, 35\)"),
    (60, r"^insnav tune: error: .*: no GNSS record in the held-out segment \(30% of the data\)"),
])
def test_tune_refuses_too_few_records_before_writing(tmp_path, capsys, fixes, message):
    """One or two GNSS fixes were "tuned" (scales of 20x, held-out rms(error/sigma) 39) and written with
    status 0; a held-out part without a record wrote a TOML nothing had checked.  Both are one line, no
    file (calib.tune.MIN_RECORDS_PER_FACTOR)."""
    import re

    import insnav
    from insnav.cli import main

    ds = insnav.simulate("seed000-sim", seed=1).save(tmp_path / "ds")
    lines = (ds / "gnss.csv").read_text().splitlines()
    (ds / "gnss.csv").write_text("\n".join(lines[:1 + fixes]) + "\n")  # the first fixes only
    out = tmp_path / "tuned.toml"
    assert main(["tune", str(ds), "--max-runs", "16", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert re.match(message, err) and len(err.splitlines()) == 1 and not out.exists(), err


def test_tune_cli_refuses_a_repeated_param_and_tight_without_pseudoranges(tmp_path, capsys):
    """'--params gyro_arw,gyro_arw' reported 2 factors for one; --coupling tight on a dataset of loose fixes
    only ran every search step into 'no GNSS record with an innovation covariance'."""
    import insnav
    from insnav.cli import main

    ds = insnav.simulate("seed000-sim", seed=1).save(tmp_path / "ds")
    out = tmp_path / "tuned.toml"
    assert main(["tune", str(ds), "--params", "gyro_arw,gyro_arw", "--out", str(out), "--quiet"]) == 2
    assert capsys.readouterr().err == ("insnav tune: error: --params gyro_arw,gyro_arw: 'gyro_arw' given twice\n")
    assert main(["tune", str(ds), "--coupling", "tight", "--out", str(out), "--quiet"]) == 2
    assert capsys.readouterr().err == (f"insnav tune: error: {ds}: no raw GNSS data (gnss_raw.csv, or RINEX with "
                                       "--format rinex): tight coupling tunes on pseudorange innovations\n")
    assert not out.exists()


def test_tune_keeps_the_users_smoothing_for_the_report_and_the_file(sim_dir, tmp_path, capsys):
    """smooth = true: the likelihood is the forward filter's (the same factors as without it), but the
    base and tuned settings keep smoothing, so the printed held-out figures are the smoothed run's, the
    run the written file makes."""
    ds = insnav.load_dataset(sim_dir)
    kw = dict(params=["gyro_arw", "gnss_pos"], max_runs=8, holdout=0.3)
    fwd, smo = tune(ds, RunConfig(), **kw), tune(ds, RunConfig(smooth=True), **kw)
    assert smo.scales == fwd.scales and smo.log_likelihood_tuned == fwd.log_likelihood_tuned
    assert smo.tuned.smooth and smo.base.smooth and not fwd.tuned.smooth
    base = tmp_path / "base.toml"
    base.write_text("smooth = true\n")
    out = tmp_path / "tuned.toml"
    assert main(["tune", str(sim_dir), "--config", str(base), "--params", "gyro_arw,gnss_pos", "--max-runs", "8",
                 "--out", str(out), "-q"]) == 0
    printed = capsys.readouterr().out
    assert "the held-out figures are of the smoothed solution" in printed
    row = next(ln for ln in printed.splitlines() if ln.startswith("horizontal RMS error"))
    reported = float(row.split()[-1])
    sol = insnav.run(ds, config=str(out))
    from insnav.calib.tune import holdout_report

    assert "smoother" in sol.summary  # the file runs the smoother
    assert holdout_report(sol, ds.truth, t_from=smo.t_split)["hor_rms_m"] == pytest.approx(reported, abs=6e-5)


@pytest.mark.slow
def test_cli_reference_that_is_the_fixes_is_checked_where_the_filter_did_not_see_it(shared_data, tmp_path, capsys):
    """--reference = the .pos the loose filter reads (one fix in four, `[gnss] decimate = 4`): the held-out
    reference epochs are those that were not fixes of the run, and the .pos's own sigmas and the lever arm
    give the "antenna, sigma_ref" rows (insnav.calib.tune.pos_reference_model)."""
    from insnav.calib.tune import unseen_reference_epochs
    from insnav.analysis.evaluate import _read_truth

    w = shared_data / "rtklibexplorer_walk_0827" / "raw"
    pos = w / "gnss_1730_sf.pos"
    cfg_path = Path(__file__).resolve().parent / "data" / "walk_0827_loose.toml"
    out = tmp_path / "t.toml"
    assert main(["tune", "--format", "csv", "--imu", str(w / "imu_1730.csv"), "--gnss", str(pos), "--config",
                 str(cfg_path), "--reference", str(pos), "--params", "gnss_pos,gnss_vel", "--max-runs", "8",
                 "--out", str(out), "-q"]) == 0
    printed = capsys.readouterr().out
    ds, _ = insnav.load_csv_dataset(w / "imu_1730.csv", pos, tomllib.loads(cfg_path.read_text()))
    ref = _read_truth(str(pos))
    unseen = unseen_reference_epochs(ref, ds.gnss.t_valid)
    assert unseen is not None and 0 < len(unseen) < len(ref.t)
    assert f"left out ({len(ref.t) - len(unseen)} of {len(ref.t)})" in printed
    t_split = float(printed.split("held out: t >= ")[1].split(" s")[0])
    want = int(np.sum((unseen >= t_split) & (unseen < ds.imu.t[-1])))
    row = next(ln for ln in printed.splitlines() if ln.startswith("reference epochs  "))  # the table row
    assert int(row.split()[-1]) == want
    assert "rms(err/sigma) position N,E,D, antenna, sigma_ref" in printed
