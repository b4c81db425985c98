"""Allan variance (insnav.calib.allan, _core.overlapping_avar) and ``insnav allan``.

The overlapping Allan deviation against the definition evaluated with plain
numpy from cluster means (NIST SP 1065, eq. (11)) and against allantools;
white rate noise follows N / sqrt(tau) and a random-walk rate
K sqrt(tau / 3) (IEEE Std 952-1997, eqs. (C.10), (C.15)) within their
chi-square intervals; the weighted least-squares fit recovers N and K from
their sum; the chi-square quantiles against tables; bad logs (too short,
moving, with gaps) get one line naming the file; the [imu] snippet loads
through the run-configuration loader with the fitted values.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from conftest import require_module
from insnav.calib import allan as al
from insnav.cli import main


def _reference_oavar(y: np.ndarray, m: int) -> float:
    """1/2 mean of (ybar_{i+m} - ybar_i)^2 over every start i: cluster means
    from an extended-precision cumulative sum of the raw samples (no centring)."""
    c = np.concatenate([[0.0], np.cumsum(y.astype(np.longdouble))])
    means = (c[m:] - c[:-m]) / m  # mean of y[i : i + m] for every i
    d = means[m:] - means[:-m]
    return float(np.mean(d * d) / 2)


def test_oadev_equals_numpy_reference_and_allantools():
    allantools = require_module("allantools", "allantools")

    rng = np.random.default_rng(3)
    n, tau0 = 6000, 0.005
    y = np.column_stack([0.3 + 1e-3 * rng.standard_normal(n),                      # offset + white
                         9.8 + 0.02 * rng.standard_normal(n) + np.cumsum(1e-4 * rng.standard_normal(n))])
    curve = al.allan_deviation(y, tau0, per_octave=4)
    assert curve.m[0] == 1 and curve.m[-1] <= n // 2 and np.all(np.diff(curve.m) > 0)
    assert np.array_equal(curve.terms, n + 1 - 2 * curve.m)
    ref = np.array([[_reference_oavar(y[:, a], int(m)) for a in range(2)] for m in curve.m])
    assert np.max(np.abs(curve.adev ** 2 / ref - 1)) < 1e-9
    for a in range(2):
        taus, adev, _, ns = allantools.oadev(y[:, a], rate=1 / tau0, data_type="freq", taus=curve.tau_s)
        keep = np.isin(np.round(taus / tau0).astype(int), curve.m)
        ours = curve.adev[np.isin(curve.m, np.round(taus / tau0).astype(int)), a]
        assert keep.sum() >= curve.m.size - 1  # allantools drops the last single-term m
        assert np.max(np.abs(ours / adev[keep] - 1)) < 1e-9


def _chi2_band(edf, p=0.99999):  # every tau and axis inside: 1e-5 each (Bonferroni over ~50)
    lo = np.array([al.chi2_ppf((1 - p) / 2, e) for e in edf]) / edf
    hi = np.array([al.chi2_ppf(1 - (1 - p) / 2, e) for e in edf]) / edf
    return lo, hi


def test_white_rate_noise_follows_N_over_sqrt_tau():
    N, tau0, n = 2e-3, 0.01, 2 ** 18
    y = al.simulate_ieee952(n, tau0, N=N, axes=3, rng=1)
    c = al.allan_deviation(y, tau0, max_m=n // 9)
    lo, hi = _chi2_band(c.edf(0))
    ratio = c.adev ** 2 / (N ** 2 / c.tau_s)[:, None]  # sigma^2(tau) = N^2 / tau
    assert np.all((ratio > lo[:, None]) & (ratio < hi[:, None])), ratio
    assert abs(np.mean(ratio[0]) - 1) < 0.01


def test_random_walk_rate_follows_K_sqrt_tau_over_3():
    K, tau0, n = 1e-4, 0.01, 2 ** 18
    y = al.simulate_ieee952(n, tau0, K=K, axes=3, rng=2)
    c = al.allan_deviation(y, tau0, max_m=n // 9)
    # exact for the sampled walk: K^2 tau / 3 + K^2 tau0 / (6 m)
    expect = K ** 2 * c.tau_s / 3 + K ** 2 * tau0 / (6 * c.m)
    lo, hi = _chi2_band(c.edf(-2))
    ratio = c.adev ** 2 / expect[:, None]
    assert np.all((ratio > lo[:, None]) & (ratio < hi[:, None])), ratio
    assert abs(np.mean(ratio[0]) - 1) < 0.02


def test_fit_recovers_white_noise_and_rate_random_walk_from_their_sum():
    # ADEV crossing at sqrt(3) N / K = 17 s, 5.8 h of data: the random walk dominates 1.5 decades of tau
    # (over 20 seeds: K within 4 % rms, 11 % at worst; the 95 % interval held K in 19 of 20; 99 % here)
    N, K, tau0, n = 1e-3, 1e-4, 0.01, 2 ** 21
    y = al.simulate_ieee952(n, tau0, N=N, K=K, axes=2, rng=4)
    c = al.allan_deviation(y, tau0, per_octave=2)
    for a in range(2):
        f = al.fit_allan(c, a, confidence=0.99)
        assert abs(f.coef["N"] / N - 1) < 0.01
        assert abs(f.coef["K"] / K - 1) < 0.10
        assert f.ci["K"][0] < K < f.ci["K"][1] and f.ci["K"][1] / f.ci["K"][0] < 1.5
        # what the fit puts into the absent terms stays far below the curve
        for k in ("Q", "B", "R"):
            p, fac = al.TERMS[k]
            share = fac * f.coef[k] ** 2 * c.tau_s ** p / (c.adev[:, a] ** 2)
            assert np.max(share) < 0.1, (k, share)


def test_chi2_quantiles_against_tables():
    # Abramowitz & Stegun, Table 26.8
    assert al.chi2_ppf(0.025, 10) == pytest.approx(3.24697, abs=1e-4)
    assert al.chi2_ppf(0.975, 10) == pytest.approx(20.4832, abs=1e-4)
    assert al.chi2_ppf(0.05, 1) == pytest.approx(0.00393214, rel=1e-4)
    assert al.chi2_ppf(0.95, 100) == pytest.approx(124.342, abs=1e-3)


def test_gauss_markov_peak_constants():
    # first-order Gauss-Markov: the Allan deviation peaks at 0.618 sigma at tau = 1.89 T (IEEE Std 952, C.21)
    x_peak, peak = al.GM_PEAK
    assert x_peak == pytest.approx(1.89, abs=0.01) and peak == pytest.approx(0.618, abs=0.001)
    # and the sampled process has it: AR(1) of T = 2 s at 100 Hz, 6 h
    tau0, T, sigma, n = 0.01, 2.0, 1e-3, 2 ** 21
    rng = np.random.default_rng(5)
    phi = math.exp(-tau0 / T)
    from insnav.sim.imu import _ar1

    e = sigma * math.sqrt(1 - phi * phi) * rng.standard_normal((n, 1))
    b = _ar1(phi, np.array([sigma * rng.standard_normal()]), e)
    c = al.allan_deviation(b, tau0, per_octave=8, max_m=int(20 * T / tau0))
    i = int(np.argmax(c.adev[:, 0]))
    assert c.tau_s[i] / T == pytest.approx(x_peak, rel=0.15)
    assert c.adev[i, 0] / sigma == pytest.approx(peak, rel=0.03)


def _write_kfgins(path, t, gyro_radps, acc_mps2):
    dt = np.median(np.diff(t))
    a = np.column_stack([t, gyro_radps * dt, acc_mps2 * dt])
    np.savetxt(path, a, fmt="%.9f" + " %.15e" * 6)


def _static_log(seconds, rate_hz=100.0, seed=0, N_g=3e-4, N_a=2e-3):
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    tau0 = 1.0 / rate_hz
    t = 100000.0 + tau0 * np.arange(1, n + 1)
    g = np.array([0.0, 0.0, 7.29e-5]) + N_g / math.sqrt(tau0) * rng.standard_normal((n, 3))
    f = np.array([0.0, 0.0, -9.80665]) + N_a / math.sqrt(tau0) * rng.standard_normal((n, 3))
    return t, g, f


def _run(capsys, argv):
    rc = main(argv)
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_short_log_is_refused_naming_the_file(tmp_path, capsys):
    p = tmp_path / "five_seconds.txt"
    _write_kfgins(p, *_static_log(5.0, rate_hz=200.0))
    rc, out, err = _run(capsys, ["allan", str(p), "--out-dir", str(tmp_path / "o"), "--no-plot"])
    assert rc == 2 and err.count("\n") == 1
    assert str(p) in err and "log too short for tau above 1 s" in err and "5 s of data" in err
    assert not (tmp_path / "o").exists()


def test_moving_log_is_flagged_by_its_specific_force(tmp_path, capsys):
    t, g, f = _static_log(120.0)
    f[:, 0] += 0.5 * np.sin(2 * np.pi * t / 7.0)  # 0.5 m/s^2 of forward acceleration, 7 s period
    p = tmp_path / "drive.txt"
    _write_kfgins(p, t, g, f)
    rc, out, err = _run(capsys, ["allan", str(p), "--out-dir", str(tmp_path / "o"), "--no-plot"])
    assert rc == 2 and err.count("\n") == 1
    assert str(p) in err and "not static" in err and "threshold 0.05 m/s^2" in err and "axis x" in err
    # the same noise at rest passes the check (statistic ~ VRW / sqrt(1 s) = 0.002 m/s^2)
    st = al.check_static(_static_log(120.0)[2], 0.01)
    assert st["static"] and st["stat_mps2"] < 0.005


def test_gaps_in_the_sampling_are_flagged(tmp_path, capsys):
    t, g, f = _static_log(60.0)
    keep = np.ones(t.size, bool)
    keep[3000:3010] = False  # 0.1 s missing
    p = tmp_path / "gappy.txt"
    _write_kfgins(p, t[keep], g[keep], f[keep])
    rc, out, err = _run(capsys, ["allan", str(p), "--out-dir", str(tmp_path / "o"), "--no-plot"])
    assert rc == 2 and err.count("\n") == 1
    assert str(p) in err and "1 gap(s)" in err and "line 3001" in err and "--allow-gaps" in err


def test_cli_outputs_and_toml_snippet_round_trip(tmp_path, capsys):
    from insnav.config import load_config
    require_module("matplotlib", "plot")
    N_g, N_a = 3e-4, 2e-3
    p = tmp_path / "static.txt"
    _write_kfgins(p, *_static_log(600.0, N_g=N_g, N_a=N_a))
    out = tmp_path / "res"
    rc, text, err = _run(capsys, ["allan", str(p), "--out-dir", str(out)])
    assert rc == 0, err
    assert (out / "allan.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "gyro_x" in (out / "allan_terms.txt").read_text() and "gyro_arw_deg_per_sqrt_h" in text
    assert "10 min of data" in text  # the short-log note
    cfg = load_config(out / "imu_noise.toml")
    # ARW / VRW: the simulated white noise, within 2 % (10 min of data)
    assert np.allclose(cfg.imu.gyro_arw, N_g, rtol=0.02) and np.allclose(cfg.imu.acc_vrw, N_a, rtol=0.02)
    # the loaded SI values are the fit's, through the snippet's units and 4 significant digits
    from insnav.cli.allan import read_rates

    d = read_rates(p)
    curve = al.allan_deviation([d["gyro_radps"], d["acc_mps2"]], float(np.median(np.diff(d["t_s"]))))
    fits = [al.fit_allan(curve, a) for a in range(6)]
    assert np.allclose(cfg.imu.gyro_arw, [f.coef["N"] for f in fits[:3]], rtol=5e-4, atol=0)
    assert np.allclose(cfg.imu.acc_vrw, [f.coef["N"] for f in fits[3:]], rtol=5e-4, atol=0)
    assert np.allclose(cfg.imu.gyro_bias_rw, [f.coef["K"] for f in fits[:3]], rtol=5e-4, atol=1e-30)
    assert np.allclose(cfg.imu.acc_bias_rw, [f.coef["K"] for f in fits[3:]], rtol=5e-4, atol=1e-30)
    c = np.genfromtxt(out / "allan.csv", delimiter=",", skip_header=2)
    assert c.shape == (curve.tau_s.size, 9) and np.allclose(c[:, 0], curve.tau_s)
    # a second run into the same folder replaces its own files; a foreign file there is kept
    rc, _, err = _run(capsys, ["allan", str(p), "--out-dir", str(out), "--no-plot"])
    assert rc == 0, err
    (out / "allan.csv").write_text("mine\n")
    rc, _, err = _run(capsys, ["allan", str(p), "--out-dir", str(out), "--no-plot"])
    assert rc == 2 and "not replaced" in err and (out / "allan.csv").read_text() == "mine\n"
    # each output is checked by its own first bytes: a user's file beside an earlier allan.csv is kept
    rc, _, err = _run(capsys, ["allan", str(p), "--out-dir", str(out), "--overwrite"])
    assert rc == 0, err
    assert b"tEXtSoftware\x00insnav allan" in (out / "allan.png").read_bytes()[:200]
    rc, _, err = _run(capsys, ["allan", str(p), "--out-dir", str(out)])
    assert rc == 0, err  # its own four files, the plot included, are replaced
    for name in ("allan_terms.txt", "imu_noise.toml", "allan.png"):
        (out / name).write_text("my notes\n")
        rc, _, err = _run(capsys, ["allan", str(p), "--out-dir", str(out), "--no-plot"])
        assert rc == 2 and err == (f"insnav allan: error: {out / name} exists and was not written by insnav "
                                   "allan: not replaced (another --out-dir, or --overwrite)\n"), err
        assert (out / name).read_text() == "my notes\n"
        (out / name).unlink()


def test_repeated_time_tags_are_one_line_naming_the_file(tmp_path, capsys):
    """Every time tag written twice: the median interval is 0 (before: 'ZeroDivisionError: float
    division by zero' after two RuntimeWarnings, with --allow-gaps)."""
    t, g, f = _static_log(60.0)
    t = np.repeat(t[::2], 2)
    p = tmp_path / "dup.txt"
    _write_kfgins(p, t, g, f)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rc, out, err = _run(capsys, ["allan", str(p), "--out-dir", str(tmp_path / "o"), "--no-plot", "--allow-gaps"])
    assert rc == 2 and err == (f"insnav allan: error: {p}: median sample interval 0 s: the time tags repeat (or "
                               "decrease) at most samples; the Allan variance needs the IMU's own sampling times\n")


def test_a_header_that_contradicts_the_columns_mapping_is_refused(tmp_path, capsys):
    """An insnav imu.csv (t_s, dtheta_*, dv_*) read with --format csv and a TOML without a columns mapping
    was read as t, ax..az, gx..gz rates: gyro N 0.0287 deg/sqrt(h) for 0.3, status 0."""
    t, g, f = _static_log(60.0)
    dt = 0.01
    p = tmp_path / "imu.csv"
    np.savetxt(p, np.column_stack([t, g * dt, f * dt]), delimiter=",", fmt="%.12g",
               header="t_s,dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_mps,dv_y_mps,dv_z_mps", comments="")
    cfg = tmp_path / "noise.toml"
    cfg.write_text("[imu]\ngyro_arw_deg_per_sqrt_h = 0.3\n")
    rc, out, err = _run(capsys, ["allan", str(p), "--format", "csv", "--config", str(cfg), "--out-dir",
                                 str(tmp_path / "o"), "--no-plot"])
    assert rc == 2 and err == (f"insnav allan: error: {p}, line 1: the header names field 2 'dtheta_x_rad', a gyro "
                               "column, but the columns mapping ['t', 'ax', 'ay', 'az', 'gx', 'gy', 'gz'] reads it "
                               "as 'ax': set the [imu] columns (an insnav dataset's imu.csv: --format insnav)\n"), err
    # mapped right, the same file gives the simulated noise
    cfg.write_text('[imu]\ncolumns = ["t", "gx", "gy", "gz", "ax", "ay", "az"]\nsamples = "increment"\n')
    rc, out, err = _run(capsys, ["allan", str(p), "--format", "csv", "--config", str(cfg), "--out-dir",
                                 str(tmp_path / "o"), "--no-plot", "--allow-motion"])
    assert rc == 0, err
    from insnav.config import load_config

    assert np.allclose(load_config(tmp_path / "o" / "imu_noise.toml").imu.gyro_arw, 3e-4, rtol=0.05)


def test_an_increment_that_overflows_as_a_rate_names_its_line(tmp_path, capsys):
    """dv_x = 1e308 divided by the 0.01 s interval is inf: before, two RuntimeWarnings and 'non-finite rate
    sample at row 499 (axes from 3)', naming neither the file nor the line."""
    t, g, f = _static_log(60.0)
    p = tmp_path / "huge.txt"
    _write_kfgins(p, t, g, f)
    lines = p.read_text().splitlines()
    fields = lines[500].split()
    fields[4] = "1e308"
    lines[500] = " ".join(fields)
    p.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rc, out, err = _run(capsys, ["allan", str(p), "--out-dir", str(tmp_path / "o"), "--no-plot", "--allow-motion"])
    assert rc == 2 and err.startswith(f"insnav allan: error: {p}, line 501: the accelerometer sample is not a finite "
                                      "number below 10000 m/s^2 as a rate (inf, ") and err.endswith("): a corrupted "
                                                                                       "record?\n"), err


def test_an_absurd_finite_rate_names_its_line_before_the_sums_overflow(tmp_path, capsys):
    """A rate of 1e308 (finite) leaked numpy's overflow warning and was reported as 'not static ... inf
    m/s^2' (with --allow-motion: "fewer than 2 usable averaging times", naming nothing).  A KF-GINS folder
    given to --format kfgins said "[Errno None] Is a directory"."""
    t, g, f = _static_log(60.0)
    f[700, 1] = 1e308 * 0.01  # an increment that is 1e306 m/s: 1e308 m/s^2 as a rate
    p = tmp_path / "big.txt"
    _write_kfgins(p, t, g, f)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rc, out, err = _run(capsys, ["allan", str(p), "--out-dir", str(tmp_path / "o"), "--no-plot", "--allow-motion"])
    assert rc == 2 and err.startswith(f"insnav allan: error: {p}, line 701: the accelerometer sample is not a finite "
                                      "number below 10000 m/s^2 as a rate"), err
    rc, out, err = _run(capsys, ["allan", str(tmp_path), "--format", "kfgins", "--out-dir", str(tmp_path / "o2"),
                                 "--no-plot"])
    assert rc == 2 and err == f"insnav allan: error: {tmp_path}: a folder; --format kfgins reads a KF-GINS IMU text file\n"


def test_gauss_markov_time_is_left_out_when_the_curve_has_no_minimum_inside_the_log():
    """White rate noise and flicker only (no rate random walk): the fitted Allan deviation still falls at
    the longest averaging time, so tau_min is the log's length (1 h gave T = 866 s, 2 h 1731 s for the
    same process).  The Gauss-Markov keys are now left out with a note.  With a rate random walk the
    minimum is inside the log and T = tau_min / 1.89 is written."""
    from insnav.units import DEG_PER_H, DEG_PER_SQRT_H

    tau0 = 0.1
    n = int(3600 / tau0)
    y = al.simulate_ieee952(n, tau0, N=0.05 * DEG_PER_SQRT_H, B=1.0 * DEG_PER_H, axes=3, rng=3)
    fits = [al.fit_allan(al.allan_deviation(y, tau0), i) for i in range(3)]
    assert all(f.coef["B"] > 0 and not f.tau_min_inside for f in fits)
    assert all(al.gauss_markov_from_fit(f) == (0.0, math.inf) for f in fits)
    toml = al.imu_noise_toml(fits, fits)
    assert "gyro_bias_tau_s =" not in toml and "acc_bias_tau_s =" not in toml
    assert "no Allan-deviation minimum inside it" in toml
    y = al.simulate_ieee952(n, tau0, N=0.05 * DEG_PER_SQRT_H, B=1.0 * DEG_PER_H, K=20.0 * DEG_PER_H / 60.0, axes=1,
                            rng=4)
    f = al.fit_allan(al.allan_deviation(y, tau0), 0)
    assert f.tau_min_inside and f.tau_min_s < 0.5 * f.tau_s[-1]
    sigma, T = al.gauss_markov_from_fit(f)
    assert sigma > 0 and T == pytest.approx(f.tau_min_s / al.GM_PEAK[0])


def test_an_unresolved_white_noise_is_written_as_its_upper_bound_not_zero():
    """A very short log of white noise: the fit can put it all in quantisation and leave N at 0, which
    the TOML wrote as gyro_arw = 0 (no white process noise on that axis; insnav run took it).  Now the
    axis gets N's upper bound, with a comment."""
    tau0 = 1.0
    for seed in range(50):
        y = al.simulate_ieee952(12, tau0, N=1e-3, axes=3, rng=seed)
        fits = [al.fit_allan(al.allan_deviation(y, tau0), i) for i in range(3)]
        if any(not f.coef["N"] > 0 for f in fits):
            break
    else:
        pytest.fail("no fit left N unresolved")
    toml = al.imu_noise_toml(fits, fits)
    line = next(ln for ln in toml.splitlines() if ln.startswith("gyro_arw_deg_per_sqrt_h"))
    vals = [float(v) for v in line.split("=")[1].strip(" []").split(",")]
    assert all(v > 0 for v in vals), line
    assert "white noise not resolved by the fit: its upper bound written" in toml


def test_report_of_the_allan_folder_given_as_dot(tmp_path, capsys, monkeypatch):
    """``insnav report --allan .`` (or ``allan.csv`` from inside the folder) stopped on "PosixPath('.')
    has an empty name"; the report goes beside the folder, named after it."""
    require_module("matplotlib", "plot")
    t, g, f = _static_log(60.0)
    p = tmp_path / "static.txt"
    _write_kfgins(p, t, g, f)
    out = tmp_path / "noise"
    rc, _, err = _run(capsys, ["allan", str(p), "--out-dir", str(out), "--no-plot"])
    assert rc == 0, err
    monkeypatch.chdir(out)
    for arg, name in ((".", "noise"), ("allan.csv", "allan.csv")):
        rc, stdout, err = _run(capsys, ["report", "--allan", arg])
        assert rc == 0, err
        assert f"IMU noise of {name}<" in (tmp_path / "noise-report" / "report.html").read_text()
