"""Estimated between-receiver ionosphere of the RTK engine (``[rtk] iono = "estimate"``).

The simulator (insnav.sim.gnss_rtk) gives every rover-base pair of a satellite a known residual
ionosphere ``iono_ppm 1e-6 d M(el) x(t)`` (x a unit Gauss-Markov process), so the engine's
single-differenced ionosphere states can be checked against the truth: rms(error / sigma) near 1
of the double differences (the observable part) on a 25-30 km baseline, and the float solution
against the variance-only model (the default, which ignores the ionosphere with its sigma 0).  With no ionosphere, the states stay at zero and
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
    tmp_path.mkdir(parents=True, exist_ok=True)
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
    """A 25-30 km baseline, 2 ppm of residual ionosphere (DD 12 cm rms on L1), 240 s."""
    return simulate_rtk(_scenario(20.0, 2.0, 240.0), seed=4)


def test_estimated_dd_ionosphere_follows_the_simulated_one(medium, tmp_path):
    """The double-differenced ionosphere (the observable part of the states) against the truth, with the
    filter told the simulated noise and ionosphere (sigma 2 ppm, tau): rms(error / sigma) near 1."""
    sim = medium
    g = sim.config
    sol = _run(sim, tmp_path, record_iono=True, iono="estimate", iono_sigma_per_10km_m=g["iono_ppm"] * 0.01,
               iono_tau_s=g["iono_tau"], **rtk_noise_options(g))
    truth_sd = _true_sd_iono(sim)
    sd, dd, dd_sig = sol.info["iono_m"], sol.info["iono_dd_m"], sol.info["iono_dd_sigma_m"]
    # the reference of each system and epoch: a satellite with a state but no double difference
    truth_dd = np.full_like(dd, np.nan)
    for e in range(dd.shape[0]):
        for sys in (0, 2):
            keys = np.arange(sys * 64, sys * 64 + 64)
            ref = keys[np.isfinite(sd[e, keys]) & ~np.isfinite(dd[e, keys])]
            if ref.size == 1:
                truth_dd[e, keys] = truth_sd[e, keys] - truth_sd[e, ref[0]]
    ok = np.isfinite(dd) & np.isfinite(truth_dd)
    ok[:30] = False  # the first 30 s: mostly the prior
    assert ok.sum() > 2000
    z = (dd - truth_dd)[ok] / dd_sig[ok]
    rms_z = float(np.sqrt(np.mean(z ** 2)))
    rms_truth = float(np.sqrt(np.mean(truth_dd[ok] ** 2)))
    rms_err = float(np.sqrt(np.mean((dd - truth_dd)[ok] ** 2)))
    assert rms_truth > 0.08  # a real ionosphere to follow
    assert 0.6 < rms_z < 1.5, rms_z
    # without fixed integers the float DD ionosphere is only weakly separated from the ambiguities
    # (code minus phase): better than assuming none, far from the millimetres of a fixed solution
    assert rms_err < 0.9 * rms_truth, (rms_err, rms_truth)


def test_medium_baseline_float_is_consistent_where_the_variance_model_is_not(medium, tmp_path):
    """25-30 km, 2 ppm, 240 s: no engine fixes yet (as RTKLIB's est-stec, bench/rtk_iono.py), but the
    estimated ionosphere keeps the float solution accurate and its covariance honest, where the
    default variance model (sigma 0: no ionosphere) is metres off and over-confident."""
    sim = medium
    est = _run(sim, tmp_path / "est", iono="estimate")
    var = _run(sim, tmp_path / "var")  # the default: iono = "variance", sigma 0

    def float_stats(sol):
        i = np.searchsorted(sim.rover.t_tag_gps_s, sol.t_gps_s - 1e-3)
        d = (sol.r_float_e - sim.rover.r_e[i])[60:]
        z2 = np.einsum("ni,nij,nj->n", d, np.linalg.inv(sol.P_r[60:]), d)
        return float(np.median(np.linalg.norm(d, axis=1))), float(np.sqrt(np.mean(z2) / 3.0))

    med_est, z_est = float_stats(est)
    med_var, z_var = float_stats(var)
    e_est = _errors(est, sim)
    assert not np.any((est.status == 1) & (e_est > 0.05))  # no wrong fix
    assert med_est < 0.4 and med_est < 0.2 * med_var, (med_est, med_var)
    assert z_est < 2.0 and z_var > 10.0, (z_est, z_var)


def test_zero_ionosphere_estimate_stays_at_zero_and_matches_no_iono_states(tmp_path):
    """1.4-2 km, no ionosphere: the states stay near 0 and the fixes match the engine without them.
    Tolerance 2.5 cm between the two fixed solutions: with the ionosphere estimated, the fixed position
    rests on the DD ionosphere from the two frequencies' phases, whose noise the ionosphere-free-like
    combination amplifies about 3x (Springer Handbook of GNSS eq. (20.36)); with a prior of 1e-5 m per
    10 km the states are pinned to 0 and the two engines agree to 1 mm (the exact reduction)."""
    sim = simulate_rtk(_scenario(1.0, 0.0, 200.0), seed=3)
    off = _run(sim, tmp_path / "off", iono="off")
    est = _run(sim, tmp_path / "est", record_iono=True, iono="estimate")
    pinned = _run(sim, tmp_path / "pin", iono="estimate", iono_sigma_per_10km_m=1e-5)
    assert np.mean(off.status == 1) > 0.95 and np.mean(est.status == 1) > 0.93  # measured 1.0 and 0.950
    both = (off.status == 1) & (est.status == 1)
    d = np.linalg.norm(est.r_e[both] - off.r_e[both], axis=1)
    assert np.max(d) < 0.025, np.max(d)
    assert np.max(_errors(est, sim)[est.status == 1]) < 0.05
    np.testing.assert_array_equal(pinned.status, off.status)
    assert np.max(np.linalg.norm(pinned.r_e - off.r_e, axis=1)) < 1e-3
    io, sg = est.info["iono_m"], est.info["iono_sigma_m"]
    i = np.isfinite(io)
    assert i.sum() > 1000
    assert np.sqrt(np.mean(io[i] ** 2)) < 0.01
    assert np.sqrt(np.mean((io[i] / sg[i]) ** 2)) < 1.0  # within the prior: rms(state / sigma) below 1


def test_iono_options_are_checked():
    from insnav.config import ConfigError

    with pytest.raises(ConfigError, match="rtk.iono'"):
        RtkOptions.from_dict({"iono": "est-stec"})
    with pytest.raises(ConfigError, match="iono_sigma_per_10km_m"):
        RtkOptions.from_dict({"iono": "estimate", "iono_sigma_per_10km_m": 0.0})
    assert RtkOptions.from_dict({"iono": "estimate"}).core_dict()["iono_sigma_per_10km_m"] == 0.03
    assert RtkOptions.from_dict({}).core_dict()["iono_sigma_per_10km_m"] == 0.0
    assert RtkOptions.from_dict({}).core_dict()["iono_mode"] == 1
    from insnav.filters.rtk_ins import rtk_ins_options

    # RTK/INS: the ionosphere states by default (filters/rtk_ins.py RTK_INS_DEFAULTS), the same checks
    assert rtk_ins_options({}).core_dict()["iono_mode"] == 2
    assert rtk_ins_options({}).core_dict()["iono_sigma_per_10km_m"] == 0.03
    with pytest.raises(ConfigError, match="iono_sigma_per_10km_m"):
        rtk_ins_options({"iono_sigma_per_10km_m": 0.0})
    assert rtk_ins_options({"iono": "off"}).core_dict()["iono_mode"] == 0
