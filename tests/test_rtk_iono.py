"""Estimated between-receiver ionosphere of the RTK engine (``[rtk] iono = "estimate"``).

The simulator (insnav.sim.gnss_rtk) gives every rover-base pair of a satellite a known residual
ionosphere ``iono_ppm 1e-6 d M(el) x(t)`` (x a unit Gauss-Markov process), so the engine's
single-differenced ionosphere states can be checked against the truth: rms(error / sigma) near 1
on a 20-30 km baseline, and the fixed solution against the variance-only model (the default,
which ignores the ionosphere with its sigma 0).  With no ionosphere, the states stay at zero and
the solution is the one of the engine without them.  The H columns are checked against numerical
derivatives in cpp/tests/test_rtk.cpp.
"""
from __future__ import annotations

import numpy as np
import pytest

from insnav.gnss.rtk import RtkOptions, solve_rtk
from insnav.sim import simulate_rtk
from insnav.sim.gnss_rtk import rtk_noise_options
from insnav.sim.scenario import resolve_raw

_SYS_INDEX = {"G": 0, "R": 1, "E": 2, "C": 3, "J": 4}


def _scenario(base_km: float, iono_ppm: float, duration_s: float):
    raw, _ = resolve_raw("rtk-open-sky-car")
    raw["gnss_rtk"]["base"] = {"offset_ned_m": [-1e3 * base_km, -1e3 * base_km, 0.0]}
    raw["gnss_rtk"]["iono_ppm"] = float(iono_ppm)
    raw["motion"]["segments"] = [{"duration_s": duration_s / 2, "target_speed_mps": 12.0},
                                 {"duration_s": duration_s / 2, "heading_change_deg": 90.0}]
    raw["initial"]["speed_mps"] = 5.0
    return raw


def _run(sim, tmp_path, nf=2, record_iono=False, **extra):
    files = sim.write(tmp_path)
    cfg = dict(mode="kinematic", ar_mode="continuous", systems="GE", frequencies=nf, elevation_mask_deg=10.0)
    cfg.update(extra)
    return solve_rtk(str(files["rover"]), str(files["base"]), str(files["nav"]), options=RtkOptions.from_dict(cfg),
                     record_iono=record_iono)


def _errors(sol, sim):
    i = np.searchsorted(sim.rover.t_tag_gps_s, sol.t_gps_s - 1e-3)
    return np.linalg.norm(sol.r_e - sim.rover.r_e[i], axis=1)


def _true_sd_iono(sim):
    """(epoch, satellite key) -> the simulated rover - base ionosphere on L1 [m]."""
    r, b = sim.rover, sim.base
    truth = np.full((r.t_tag_gps_s.size, 320), np.nan)
    kb = {(int(e), s, int(p)): j for j, (e, s, p) in enumerate(zip(b.epoch, b.system, b.prn))}
    for i, (e, s, p) in enumerate(zip(r.epoch, r.system, r.prn)):
        j = kb.get((int(e), s, int(p)))
        if j is not None:
            truth[int(e), _SYS_INDEX[s] * 64 + int(p)] = r.iono_l1_m[i] - b.iono_l1_m[j]
    return truth


@pytest.fixture(scope="module")
def medium():
    """A 25-30 km baseline, 2 ppm of residual ionosphere (5-18 cm on L1), 240 s."""
    return simulate_rtk(_scenario(20.0, 2.0, 240.0), seed=4)


def test_estimated_sd_ionosphere_follows_the_simulated_one(medium, tmp_path):
    sim = medium
    g = sim.config
    noise = rtk_noise_options(g)
    sol = _run(sim, tmp_path, record_iono=True, iono="estimate", iono_sigma_per_10km_m=g["iono_ppm"] * 0.01,
               iono_tau_s=g["iono_tau"], **noise)
    truth = _true_sd_iono(sim)
    est, sig = sol.info["iono_m"], sol.info["iono_sigma_m"]
    ok = np.isfinite(est) & np.isfinite(truth)
    ok[:30] = False  # the first 30 s: the prior
    assert ok.sum() > 2000
    z = (est - truth)[ok] / sig[ok]
    rms_z = float(np.sqrt(np.mean(z ** 2)))
    err = np.abs(est - truth)[ok]
    assert 0.5 < rms_z < 1.6, rms_z
    assert np.sqrt(np.mean(truth[ok] ** 2)) > 0.04  # a real ionosphere to follow: 4 cm rms or more
    assert np.sqrt(np.mean(err ** 2)) < 0.015, np.sqrt(np.mean(err ** 2))


def test_medium_baseline_fixes_right_where_the_variance_model_does_not(medium, tmp_path):
    sim = medium
    est = _run(sim, tmp_path / "est", iono="estimate")
    var = _run(sim, tmp_path / "var")  # the default: iono = "variance", sigma 0
    e_est, e_var = _errors(est, sim), _errors(var, sim)
    fx_est, fx_var = est.status == 1, var.status == 1
    good_est = np.sum(fx_est & (e_est < 0.05))
    good_var = np.sum(fx_var & (e_var < 0.05))
    assert fx_est.mean() > 0.8, fx_est.mean()
    assert np.max(e_est[fx_est]) < 0.05  # no wrong fix
    assert np.sqrt(np.mean(e_est[fx_est] ** 2)) < 0.02
    # the variance-only model either fixes wrong or fixes far less
    assert np.sum(fx_var & (e_var > 0.05)) > 0 or good_var < 0.5 * good_est, (good_var, good_est)


def test_zero_ionosphere_estimate_stays_at_zero_and_matches_no_iono_states(tmp_path):
    sim = simulate_rtk(_scenario(2.0, 0.0, 120.0), seed=2)
    off = _run(sim, tmp_path / "off", iono="off")
    est = _run(sim, tmp_path / "est", record_iono=True, iono="estimate")
    both = (off.status == 1) & (est.status == 1)
    assert both.mean() > 0.9
    assert abs(np.mean(est.status == 1) - np.mean(off.status == 1)) < 0.05
    # the same integers: fixed positions within 5 mm (the ionosphere states, prior 3 mm at 3 km, only
    # reweight the float solution)
    d = np.linalg.norm(est.r_e[both] - off.r_e[both], axis=1)
    assert np.max(d) < 0.005, np.max(d)
    i = np.isfinite(est.info["iono_m"])
    assert i.sum() > 1000
    assert np.sqrt(np.mean(est.info["iono_m"][i] ** 2)) < 0.003
    assert np.max(np.abs(est.info["iono_m"][i]) / est.info["iono_sigma_m"][i]) < 5.0


def test_iono_options_are_checked():
    from insnav.config import ConfigError

    with pytest.raises(ConfigError, match="rtk.iono'"):
        RtkOptions.from_dict({"iono": "est-stec"})
    with pytest.raises(ConfigError, match="iono_sigma_per_10km_m"):
        RtkOptions.from_dict({"iono": "estimate", "iono_sigma_per_10km_m": 0.0})
    assert RtkOptions.from_dict({"iono": "estimate"}).core_dict()["iono_sigma_per_10km_m"] == 0.03
    assert RtkOptions.from_dict({}).core_dict()["iono_sigma_per_10km_m"] == 0.0
    assert RtkOptions.from_dict({}).core_dict()["iono_mode"] == 1
