"""Single point positioning (insnav.gnss.spp), pseudorange weighting (insnav.gnss.weighting),
RAIM FDE, the spp filter and CLI, and the smartLoc urban run.

Simulated epochs: exact geometry (satellites on a 26 560 km sphere seen above
10 deg from a receiver near Berlin), pseudoranges built from the solver's own
model, so a noise-free epoch must give the position to far below a millimetre.
"""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from insnav import earth
from insnav.config import ConfigError
from insnav.gnss.spp import SppOptions, chi2_quantile, solve_spp
from insnav.gnss.tight_inputs import TightInputs, pseudorange_sigma
from insnav.gnss.weighting import Weighting, sigma_cn0, sigma_rtklib

R_RX = earth.geodetic_to_ecef(math.radians(52.51), math.radians(13.37), 60.0)
V_RX = np.array([3.0, -4.0, 1.0])
R_SAT = 26_560e3


def _sky(rng, n, el_min_deg=10.0):
    """n satellites above el_min: ECEF position, velocity, elevation [rad]."""
    lat, lon, _ = earth.ecef_to_geodetic(R_RX)
    C_en = earth.C_en(lat, lon)
    out_r, out_el = [], []
    while len(out_r) < n:
        az = rng.uniform(0, 2 * np.pi)
        el = math.radians(rng.uniform(el_min_deg, 88.0))
        u_n = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), -math.sin(el)])
        u_e = C_en @ u_n
        # distance along u_e to the sphere of radius R_SAT
        b = R_RX @ u_e
        d = -b + math.sqrt(b * b - (R_RX @ R_RX - R_SAT ** 2))
        out_r.append(R_RX + d * u_e)
        out_el.append(el)
    r = np.array(out_r)
    v = rng.normal(0, 2500.0, (n, 3))
    return r, v, np.array(out_el)


def _epochs(rng, n_epochs, n_sats, *, systems=None, isb=None, sigma_zenith=1.0, noise=True, clock=1234.5,
            fault=None, rate_fault=None):
    """TightInputs of simulated epochs (fault: (epoch-independent) bias [m] on one random row per epoch)."""
    rows, t_row, prn, el_all, sys_all, faulty = [], [], [], [], [], []
    for e in range(n_epochs):
        r_s, v_s, el = _sky(rng, n_sats)
        sysr = np.array(["G"] * n_sats if systems is None else systems(n_sats, rng), dtype="<U1")
        d = r_s - R_RX
        rng_m = np.linalg.norm(d, axis=1)
        u = d / rng_m[:, None]
        clk_s = rng.normal(0, 1e4, n_sats)
        sig = pseudorange_sigma(el, sigma_zenith)
        sigr = pseudorange_sigma(el, 0.1 * sigma_zenith)
        b = clock + np.array([0.0 if s == "G" else (isb or {}).get(s, 0.0) for s in sysr])
        pr = rng_m + b - clk_s + (rng.normal(0, 1, n_sats) * sig if noise else 0.0)
        drift, clkdot = 0.7, rng.normal(0, 10, n_sats)
        prr = np.einsum("ij,ij->i", u, v_s - V_RX) + drift - clkdot + (rng.normal(0, 1, n_sats) * sigr if noise else 0)
        k_f = -1
        if fault is not None:
            k_f = int(rng.integers(n_sats))
            pr[k_f] += fault
        if rate_fault is not None:
            k_f = int(rng.integers(n_sats))
            prr[k_f] += rate_fault
        rows.append(np.column_stack([pr, prr, r_s, v_s, clk_s, clkdot, sig, sigr]))
        t_row += [float(e)] * n_sats
        prn += list(range(1, n_sats + 1))
        el_all.append(np.degrees(el))
        sys_all.append(sysr)
        faulty.append(k_f)
    inp = TightInputs.from_rows(t_row, prn, np.vstack(rows), np.concatenate(el_all), system=np.concatenate(sys_all))
    return inp, np.array(faulty)


R0 = R_RX + np.array([3000.0, -2000.0, 1500.0])


def test_noise_free_position_velocity_exact():
    inp, _ = _epochs(np.random.default_rng(1), 20, 7, noise=False)
    sp = solve_spp(inp, R0)
    assert sp.solved.all()
    assert np.abs(sp.r_e - R_RX).max() < 1e-3  # mm
    assert np.abs(sp.clock_bias_m - 1234.5).max() < 1e-3
    assert np.abs(sp.v_e - V_RX).max() < 1e-6
    assert np.abs(sp.clock_drift_mps - 0.7).max() < 1e-6
    assert (sp.raim_status == 0).all() and sp.chi2.max() < 1e-6
    assert np.all((sp.pdop > 1.0) & (sp.pdop < 10.0)) and np.all(sp.hdop <= sp.pdop)


def test_noisy_rms_error_over_sigma_is_one():
    inp, _ = _epochs(np.random.default_rng(2), 1500, 8)
    sp = solve_spp(inp, R0, raim=False)
    err = sp.r_e - R_RX
    nees = np.einsum("ki,kij,kj->k", err, np.linalg.inv(sp.cov_r_e), err)
    assert 0.9 < nees.mean() / 3.0 < 1.1
    lat, lon, _ = earth.ecef_to_geodetic(R_RX)
    err_n = err @ earth.C_en(lat, lon)
    z = err_n / sp.sigma_pos_n_m
    assert np.all(np.abs(np.sqrt(np.mean(z ** 2, axis=0)) - 1.0) < 0.08)
    ev = sp.v_e - V_RX
    zv = np.einsum("ki,kij,kj->k", ev, np.linalg.inv(sp.cov_v_e), ev)
    assert 0.9 < zv.mean() / 3.0 < 1.1
    # the global test statistic follows chi^2(n - 4): mean = dof
    assert abs(np.mean(sp.chi2) / 4.0 - 1.0) < 0.1


def test_inter_system_bias_recovered():
    def two(n, rng):
        s = np.array(["G"] * n)
        s[rng.choice(n, n // 2, replace=False)] = "R"
        return s

    inp, _ = _epochs(np.random.default_rng(3), 10, 10, systems=two, isb={"R": -87.25}, noise=False)
    sp = solve_spp(inp, R0)
    assert np.abs(sp.r_e - R_RX).max() < 1e-3
    assert np.abs(sp.isb_m[:, 1] + 87.25).max() < 1e-3 and np.all(sp.isb_m[:, 0] == 0)
    assert np.all(np.isnan(sp.isb_m[:, 2:]))  # Galileo, BeiDou absent
    assert (sp.ref_system == "G").all()
    # no GPS at an epoch: the first system present is the reference clock
    inp_r, _ = _epochs(np.random.default_rng(7), 3, 6, systems=lambda n, rng: np.array(["R"] * n), noise=False)
    sp_r = solve_spp(inp_r, R0)
    assert (sp_r.ref_system == "R").all() and np.abs(sp_r.r_e - R_RX).max() < 1e-3
    assert np.all(np.isnan(sp_r.isb_m[:, 0])) and np.all(sp_r.isb_m[:, 1] == 0)
    # with noise: ISB error within its sigma on average (rms(error/sigma) ~ 1)
    inp, _ = _epochs(np.random.default_rng(4), 800, 10, systems=two, isb={"R": -87.25})
    sp = solve_spp(inp, R0, raim=False)
    z = (sp.isb_m[:, 1] + 87.25) / sp.sigma_isb_m[:, 1]
    assert abs(np.sqrt(np.mean(z ** 2)) - 1.0) < 0.1
    # ignoring the ISB would cost metres: the solver's one extra unknown is what removes it
    sp_one = solve_spp(TightInputs(inp.epoch_t, inp.epoch_start, inp.sats, inp.prn, inp.elevation_deg), R0,
                       raim=False)
    assert np.median(np.linalg.norm(sp_one.r_e - R_RX, axis=1)) > 3 * np.median(np.linalg.norm(sp.r_e - R_RX, axis=1))


@pytest.mark.parametrize("n_sats", [8, 10, 12])
def test_raim_detects_and_excludes_a_50m_fault(n_sats):
    inp, faulty = _epochs(np.random.default_rng(10 + n_sats), 400, n_sats, fault=50.0)
    sp = solve_spp(inp, R0)
    start = inp.epoch_start[:-1]
    excluded_right = np.array([sp.row_excluded[start[e] + faulty[e]] for e in range(len(faulty))])
    assert np.mean(excluded_right) >= 0.99
    assert np.mean(sp.raim_status == 1) >= 0.99
    ok = excluded_right & (sp.n_excluded == 1)
    assert np.mean(ok) >= 0.97  # almost never a second (wrong) exclusion
    # after the exclusion the position is as good as a fault-free epoch
    err = np.linalg.norm(sp.r_e - R_RX, axis=1)
    sp_off = solve_spp(inp, R0, raim=False)
    assert np.median(err) < 0.5 * np.median(np.linalg.norm(sp_off.r_e - R_RX, axis=1))
    # no fault: false alarms at about alpha
    inp0, _ = _epochs(np.random.default_rng(20 + n_sats), 400, n_sats)
    sp0 = solve_spp(inp0, R0)
    assert np.mean(sp0.raim_status != 0) < 0.01


def test_a_pseudorange_thousands_of_km_off_is_left_out_not_the_epoch():
    """A pseudorange written as 100 m (20 000 km off) keeps Gauss-Newton from converging on the full set;
    the row whose omission fits best is left out (RTKLIB raim_fde) and RAIM judges the rest: every epoch
    solved, the faulty row the one excluded, the same solution from the C++ solver and the numpy loop."""
    from insnav.gnss.spp import _solve_spp_python

    inp, faulty = _epochs(np.random.default_rng(3), 60, 9, fault=-2.0e7)
    n_off = solve_spp(inp, R0, raim=False).solved.sum()
    assert n_off < 6  # the full fit diverges
    sp = solve_spp(inp, R0)
    assert_same_solution(sp, _solve_spp_python(inp, R0))
    start = inp.epoch_start[:-1]
    assert all(sp.row_excluded[start[e] + faulty[e]] for e in range(len(faulty)))
    assert sp.solved.all() and (sp.n_excluded == 1).all() and (sp.raim_status == 1).all()
    clean, _ = _epochs(np.random.default_rng(3), 60, 9)  # the same draws without the fault
    err = np.linalg.norm(sp.r_e - R_RX, axis=1)
    assert np.median(err) < 2.0 * np.median(np.linalg.norm(solve_spp(clean, R0).r_e - R_RX, axis=1))
    # with RAIM off, or no exclusion allowed, nothing is left out: the same epochs as without RAIM
    assert solve_spp(inp, R0, options=SppOptions(max_exclusions=0)).solved.sum() == n_off


def test_rate_fde_excludes_a_doppler_fault():
    inp, faulty = _epochs(np.random.default_rng(30), 300, 10, rate_fault=5.0)  # 5 m/s; sigmas 0.1-0.4 m/s
    sp = solve_spp(inp, R0)
    start = inp.epoch_start[:-1]
    hit = np.array([sp.rate_row_excluded[start[e] + faulty[e]] for e in range(len(faulty))])
    assert np.mean(hit) >= 0.99 and (sp.n_excluded == 0).mean() > 0.98  # the pseudoranges are clean
    ev = np.linalg.norm(sp.v_e - V_RX, axis=1)
    ev_off = np.linalg.norm(solve_spp(inp, R0, raim=False).v_e - V_RX, axis=1)
    assert np.median(ev) < 0.3 * np.median(ev_off)


def test_raim_leaves_too_little_redundancy_untested():
    inp, _ = _epochs(np.random.default_rng(5), 5, 4, fault=50.0)
    sp = solve_spp(inp, R0)
    assert (sp.raim_status == 3).all() and sp.solved.all() and (sp.n_excluded == 0).all()
    inp, _ = _epochs(np.random.default_rng(6), 50, 5, fault=500.0)
    sp = solve_spp(inp, R0)
    # one degree of freedom: detected, but no exclusion is possible (it would leave nothing to test)
    assert np.mean(sp.raim_status == 2) > 0.9 and (sp.n_excluded == 0).all()


def test_chi2_quantiles():
    # tabulated values (e.g. RTKLIB's chisqr table for alpha = 0.001)
    for dof, q in ((1, 10.828), (2, 13.816), (5, 20.515), (10, 29.588), (30, 59.703)):
        assert chi2_quantile(0.999, dof) == pytest.approx(q, abs=1.5e-3)
    assert chi2_quantile(0.95, 1) == pytest.approx(3.8415, abs=1e-4)


# --------------------------------------------------------------------------- weighting


def test_weighting_models_analytic():
    el = np.radians([30.0, 90.0, 2.0])
    # RTKLIB eq. (E.6.24) with a = b = 0.3 m: sqrt(0.09 + 0.09 / sin^2 el); floor at 5 deg
    s = sigma_rtklib(el)
    assert s[0] == pytest.approx(math.sqrt(0.09 + 0.09 / 0.25), rel=1e-12)
    assert s[1] == pytest.approx(math.sqrt(0.18), rel=1e-12)
    assert s[2] == pytest.approx(math.sqrt(0.09 + 0.09 / math.sin(math.radians(5.0)) ** 2), rel=1e-12)
    assert sigma_rtklib(el[:1], exponent=1.0)[0] == pytest.approx(math.sqrt(0.09 + 0.18), rel=1e-12)  # pntpos.c
    # C/N0 model: b = 3 m at 45 dB-Hz, sqrt(10) more per 10 dB less
    c = sigma_cn0(np.array([45.0, 35.0, np.nan]))
    assert c[0] == pytest.approx(math.sqrt(0.09 + 9.0), rel=1e-12)
    assert c[1] == pytest.approx(math.sqrt(0.09 + 90.0), rel=1e-12)
    assert c[2] == c[0]
    w = Weighting(model="rtklib").validate()
    spr, sprr = w.sigmas(np.radians([30.0, 30.0]), None, np.array(["G", "R"]))
    assert spr[1] / spr[0] == pytest.approx(1.5)  # RTKLIB EFACT_GLO
    assert sprr[1] / sprr[0] == pytest.approx(1.5)
    # legacy: exactly today's sigmas
    el2 = np.radians([12.0, 40.0, 70.0])
    cn0 = np.array([30.0, 48.0, np.nan])
    spr, sprr = Weighting().validate().sigmas(el2, cn0, np.array(["G"] * 3), sigma_pr_zenith_m=3.0,
                                              sigma_prr_zenith_mps=0.3)
    assert np.array_equal(spr, pseudorange_sigma(el2, 3.0, cn0))
    assert np.array_equal(sprr, pseudorange_sigma(el2, 0.3, cn0))
    assert Weighting().validate().is_default and not Weighting(cn0_mask_dbhz=30.0).validate().is_default


def test_weighting_masks():
    w = Weighting(cn0_mask_dbhz=30.0, elevation_mask_deg=15.0, systems=["G"]).validate()
    keep = w.mask(np.radians([10.0, 20.0, 20.0, 20.0, 20.0]), np.array([45.0, 29.0, np.nan, 35.0, 35.0]),
                  np.array(["G", "G", "G", "G", "R"]))
    assert keep.tolist() == [False, False, True, True, False]
    # elevation mask None: the [rinex] value
    assert Weighting().validate().mask(np.radians([9.0, 11.0]), None, np.array(["G", "G"]),
                                       elevation_mask_deg=10.0).tolist() == [False, True]


@pytest.mark.parametrize("table, cls, match", [
    ({"modle": "rtklib"}, Weighting, r"unknown key 'gnss\.modle' \(did you mean 'gnss\.model'\?\)"),
    ({"model": "sigma"}, Weighting, r"key 'gnss\.model': bad value 'sigma'; allowed: \"legacy\""),
    ({"system_factors": {"X": 2.0}}, Weighting, r"gnss\.system_factors"),
    ({"rtklib_a_m": -1.0}, Weighting, r"gnss\.rtklib_a_m.*>= 0"),
    ({"systems": ["G", "Q"]}, Weighting, r"gnss\.systems"),
    ({"raim_alpha": 2.0}, SppOptions, r"spp\.raim_alpha"),
    ({"raim": "yes"}, SppOptions, r"spp\.raim': bad value 'yes'; allowed: true or false"),
    ({"riam": True}, SppOptions, r"unknown key 'spp\.riam' \(did you mean 'spp\.raim'\?\)"),
])
def test_bad_config_keys_are_one_line_errors(table, cls, match):
    with pytest.raises(ConfigError, match=match) as ei:
        cls.from_dict(table, "run.toml")
    assert "\n" not in str(ei.value) and str(ei.value).startswith("run.toml: ")


# --------------------------------------------------------------------------- registry and run()


def test_registry_and_run_on_a_simulated_dataset():
    """insnav.run(ds, filter="spp") on the simulator's raw observations: the antenna position
    (truth + C_nb lever arm) within the solver's own sigmas."""
    import insnav
    from conftest import short_tight_dataset
    from insnav.registry import FILTERS

    assert FILTERS["spp"].couplings == ("gnss",)
    ds = short_tight_dataset(60.0)
    sol = insnav.run(ds, filter="spp")
    assert sol.summary["coupling"] == "gnss" and len(sol) > 10 and sol.summary["filter"] == "spp"
    tr = ds.truth
    k = np.searchsorted(tr.t, sol.t)
    assert np.abs(tr.t[k] - sol.t).max() < 1e-6
    from insnav import _core

    lever = np.asarray(ds.lever_arm_b, float)
    err = []
    for i, j in enumerate(k):
        lat, lon = math.radians(tr.lat_deg[j]), math.radians(tr.lon_deg[j])
        C_nb = np.asarray(_core.rotation.dcm_from_euler(np.radians([tr.roll_deg[j], tr.pitch_deg[j], tr.yaw_deg[j]])))
        r_ant = earth.geodetic_to_ecef(lat, lon, tr.h_m[j]) + earth.C_en(lat, lon) @ (C_nb @ lever)
        r_sol = earth.geodetic_to_ecef(math.radians(sol.lat_deg[i]), math.radians(sol.lon_deg[i]), sol.h_m[i])
        err.append(earth.C_en(lat, lon).T @ (r_sol - r_ant))
    z = np.array(err) / sol.sigma_pos_n_m
    rms = np.sqrt(np.mean(z ** 2, axis=0))
    assert np.all(rms < 1.5) and np.all(rms > 0.5), rms


# --------------------------------------------------------------------------- real data


SMARTLOC = "smartloc_berlin_potsdamer_platz"


@pytest.fixture(scope="module")
def smartloc(shared_data):
    d = shared_data / SMARTLOC
    if not (d / "Berlin_Potsdamer_Platz.obs").is_file():
        pytest.skip(f"{d} not found (the smartLoc data set)")
    return d



@pytest.mark.parametrize("case", ["smartloc", "walk"])
def test_sat_states_row_by_row(shared_data, case):
    """The satellite states of a row do not depend on the other rows of the call, to the last bit.

    ``spp_inputs_from_rinex`` evaluates the states once at the receiver time tags to find the rows with an
    ephemeris and takes its first clock iteration from those rows (no second evaluation); that gives the
    inputs of a separate call on the kept rows only if every row is computed on its own.
    """
    from insnav.gnss.gpstime import SECONDS_PER_WEEK
    from insnav.gnss.spp import _obs_system, _sat_states, read_nav_multi, read_obs_multi
    from insnav.io.rinex_dataset import _approx_position

    if case == "smartloc":
        d, systems = shared_data / SMARTLOC, "GR"
        obs_p, nav_p = d / "Berlin_Potsdamer_Platz.obs", [d / "brdc1580.16n", d / "brdc1580.16g"]
    else:
        d, systems = shared_data / "rtklibexplorer_walk_0827" / "rinex_derived", "GEC"
        obs_p, nav_p = d / "gnss_1730.obs", [d / "gnss_1730.nav"]
    if not obs_p.is_file():
        pytest.skip(f"{obs_p} not found")
    obs, nav = read_obs_multi(obs_p, systems), read_nav_multi(nav_p, systems)
    r0 = _approx_position(obs, nav, SECONDS_PER_WEEK * int(obs.epoch_week[0]))
    system = _obs_system(obs)
    rows = np.flatnonzero(np.isfinite(obs.C1))
    t = np.asarray(obs.t_gps_s, float)
    full = _sat_states(nav, system[rows], obs.prn[rows], t[rows], r0, obs, rows)
    keep = full["valid"]
    assert 0 < keep.sum() < keep.size or keep.all()
    kept = rows[keep]
    part = _sat_states(nav, system[kept], obs.prn[kept], t[kept], r0, obs, kept)
    assert set(part) == set(full)
    for k, v in part.items():
        assert v.tobytes() == full[k][keep].tobytes(), k
    assert set(system[kept]) == set(systems)

def _real_case(shared_data, case):
    from insnav.gnss.gpstime import SECONDS_PER_WEEK
    from insnav.gnss.spp import read_nav_multi, read_obs_multi
    from insnav.io.rinex_dataset import _approx_position

    if case == "smartloc":
        d, systems = shared_data / SMARTLOC, "GR"
        obs_p, nav_p = d / "Berlin_Potsdamer_Platz.obs", [d / "brdc1580.16n", d / "brdc1580.16g"]
    else:
        d, systems = shared_data / "rtklibexplorer_walk_0827" / "rinex_derived", "GEC"
        obs_p, nav_p = d / "gnss_1730.obs", [d / "gnss_1730.nav"]
    if not obs_p.is_file():
        pytest.skip(f"{obs_p} not found")
    obs, nav = read_obs_multi(obs_p, systems), read_nav_multi(nav_p, systems)
    t_week0 = SECONDS_PER_WEEK * int(obs.epoch_week[0])
    return obs, nav, t_week0, _approx_position(obs, nav, t_week0)


@pytest.mark.parametrize("case", ["smartloc", "walk"])
def test_carried_states_equal_evaluated_ones(shared_data, case):
    """States at transmission carried to a new reception time and receiver position (second-order
    expansion, insnav.gnss.tight_inputs.carry_transmit_states) equal the ephemeris evaluated there.

    Shifts as in use: a receiver clock estimate (up to 1 ms) and a start position moved by metres to
    a kilometre.  Bound 2e-7 m: the evaluation itself is reproducible only to ~5e-8 m between times
    1e-7 s apart (its iterations stop at tolerances); the clocks to 1e-17 s (3 nm).  A shift beyond
    CARRY_MAX_S is evaluated again, to the last bit."""
    from insnav.gnss.spp import _obs_system, _propagate_states, _sat_states
    from insnav.gnss.tight_inputs import CARRY_MAX_S

    obs, nav, _, r0 = _real_case(shared_data, case)
    system, prn = _obs_system(obs), np.asarray(obs.prn)
    rows = np.flatnonzero(np.isfinite(obs.C1))
    t = np.asarray(obs.t_gps_s, float)
    s0 = _sat_states(nav, system[rows], prn[rows], t[rows], r0, obs, rows)
    keep = s0["valid"]
    rows, s0 = rows[keep], {k: v[keep] for k, v in s0.items()}
    u = np.array([0.6, -0.3, 0.74])
    for dt_s, dr_m in [(1e-3, 0.0), (-4.6e-4, 30.0), (1e-7, 5.0), (5e-3, 1000.0)]:
        t1, r1 = t[rows] - dt_s, r0 + dr_m * u
        ev = _sat_states(nav, system[rows], prn[rows], t1, r1, obs, rows)
        ca = _propagate_states(s0, t1, r1, nav, system[rows], prn[rows], obs, rows)
        assert np.max(np.abs(ca["r_e"] - ev["r_e"])) < 2e-7
        assert np.max(np.abs(ca["range_m"] - ev["range_m"])) < 1e-7
        assert np.max(np.abs(ca["v_e"] - ev["v_e"])) < (2e-7 if abs(dt_s) <= 1e-3 else 1e-6)  # m/s
        assert np.max(np.abs(ca["clock_bias_s"] - ev["clock_bias_s"])) < 1e-17
        assert np.max(np.abs(ca["tau_s"] - ev["tau_s"])) < 1e-15
        assert np.array_equal(ca["t_tx_gps_s"], t1 - ca["tau_s"])
    far = t[rows] - 2.0 * CARRY_MAX_S
    ev = _sat_states(nav, system[rows], prn[rows], far, r0, obs, rows)
    ca = _propagate_states(s0, far, r0, nav, system[rows], prn[rows], obs, rows)
    for k, v in ev.items():
        assert v.tobytes() == ca[k].tobytes(), k


@pytest.mark.parametrize("case", ["smartloc", "walk"])
def test_second_pass_reusing_states_equals_a_fresh_pass(shared_data, case):
    """The second SPP pass (from the first pass's median position) carries the first pass's satellite
    states instead of evaluating the ephemerides again: the same rows, satellite columns within 2e-7 m,
    and the same solutions to 1e-6 m with the same RAIM statuses and exclusions."""
    from insnav.gnss.spp import _spp_inputs_from_rinex

    obs, nav, t_week0, r0 = _real_case(shared_data, case)
    systems = "GR" if case == "smartloc" else "GEC"
    w = Weighting(systems=list(systems))
    _, _, prior = _spp_inputs_from_rinex(obs, nav, t_week0, r0, weighting=w)
    r1 = r0 + np.array([12.0, -7.0, 9.0])
    a, cn0_a, _ = _spp_inputs_from_rinex(obs, nav, t_week0, r1, weighting=w, prior=prior)
    b, cn0_b, _ = _spp_inputs_from_rinex(obs, nav, t_week0, r1, weighting=w)
    assert np.array_equal(a.prn, b.prn) and np.array_equal(a.system, b.system)
    assert np.array_equal(a.epoch_start, b.epoch_start) and np.array_equal(cn0_a, cn0_b)
    np.testing.assert_allclose(a.epoch_t, b.epoch_t, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(a.sats[:, :2], b.sats[:, :2])
    np.testing.assert_allclose(a.sats[:, 2:5], b.sats[:, 2:5], rtol=0, atol=2e-7)
    np.testing.assert_allclose(a.sats[:, 5:8], b.sats[:, 5:8], rtol=0, atol=2e-7)
    np.testing.assert_allclose(a.sats[:, 8:], b.sats[:, 8:], rtol=0, atol=1e-7)
    sa, sb = solve_spp(a, r1), solve_spp(b, r1)
    assert np.array_equal(sa.raim_status, sb.raim_status) and np.array_equal(sa.row_excluded, sb.row_excluded)
    np.testing.assert_allclose(sa.r_e[sa.solved], sb.r_e[sb.solved], rtol=0, atol=1e-6)
    np.testing.assert_allclose(sa.v_e[sa.solved], sb.v_e[sb.solved], rtol=0, atol=1e-6)


@pytest.mark.parametrize("systems", ["G", "GEC"])
def test_tight_rows_from_carried_states_equal_fresh_ones(shared_data, systems):
    """The tight filter's rows from a second start position (insnav.io.rinex_dataset.load_rinex) carry
    the first call's satellite states: the same rows as a fresh call, satellite columns within 2e-7 m."""
    from insnav.gnss.tight_inputs import tight_inputs_from_rinex

    obs, nav, t_week0, r0 = _real_case(shared_data, "walk")
    keep = {}
    tight_inputs_from_rinex(obs, nav, t_week0, r0, systems=systems, _keep=keep)
    assert set(keep) == {"rows", "tag", "final"}
    r1 = r0 + np.array([-20.0, 11.0, 4.0])
    a = tight_inputs_from_rinex(obs, nav, t_week0, r1, systems=systems, _prior=keep)
    b = tight_inputs_from_rinex(obs, nav, t_week0, r1, systems=systems)
    assert np.array_equal(a.prn, b.prn) and np.array_equal(a.system, b.system)
    assert np.array_equal(a.epoch_start, b.epoch_start)
    np.testing.assert_allclose(a.epoch_t, b.epoch_t, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(a.sats[:, :2], b.sats[:, :2])
    np.testing.assert_allclose(a.sats[:, 2:8], b.sats[:, 2:8], rtol=0, atol=2e-7)
    np.testing.assert_allclose(a.sats[:, 8:], b.sats[:, 8:], rtol=0, atol=1e-7)


def _bench():
    import _smartloc  # tests/_smartloc.py (bench/spp_smartloc.py tabulates the same evaluation)

    return _smartloc


def test_smartloc_gps_spp_percentiles_below_documented_bounds(smartloc):
    """docs/results/spp_smartloc.md: deep urban, heavy NLOS.  Bounds ~1.5x the measured values."""
    b = _bench()
    res = b.evaluate(smartloc, systems="G", model="legacy", raim=False)
    assert res["epochs_solved"] >= 1300
    assert res["p50_m"] < b.BOUNDS["G"]["p50_m"] and res["p95_m"] < b.BOUNDS["G"]["p95_m"]
    res_raim = b.evaluate(smartloc, systems="G", model="legacy", raim=True)
    assert res_raim["rows_excluded"] > 0
    assert res_raim["p50_m"] < b.BOUNDS["G"]["p50_m"]


def test_walk_spp_inputs_and_start_up_solution_unchanged(shared_data):
    """The builder gives today's rows on GPS data, and the start-up solver today's fixes (the old code in
    tests/_spp_reference.py)."""
    d = shared_data / "rtklibexplorer_walk_0827" / "rinex_derived"
    if not (d / "gnss_1730.obs").is_file():
        pytest.skip(f"{d} not found")
    from _spp_reference import old_single_point

    from insnav.gnss import read_rinex_nav, read_rinex_obs
    from insnav.gnss.spp import spp_inputs_from_rinex
    from insnav.gnss.tight_inputs import tight_inputs_from_rinex
    from insnav.io.rinex_dataset import _approx_position, single_point_solution

    obs, nav = read_rinex_obs(d / "gnss_1730.obs"), read_rinex_nav(d / "gnss_1730.nav")
    t0 = 604800 * int(obs.epoch_week[0])
    r0 = _approx_position(obs, nav, t0)
    a = tight_inputs_from_rinex(obs, nav, t0, r0, max_sats=0)
    b, cn0 = spp_inputs_from_rinex(obs, nav, t0, r0)
    assert np.array_equal(a.sats, b.sats, equal_nan=True) and np.array_equal(a.prn, b.prn)
    assert np.array_equal(a.epoch_t, b.epoch_t) and cn0.shape == a.prn.shape and np.isfinite(cn0).all()
    ref = old_single_point(a, r0)
    new = single_point_solution(a, r0)
    for k, v in ref.items():
        np.testing.assert_allclose(getattr(new, k), v, rtol=0, atol=1e-6, err_msg=k)


def test_cli_spp_on_smartloc(smartloc, tmp_path):
    out = tmp_path / "spp.csv"
    cfg = tmp_path / "spp.toml"
    cfg.write_text('[gnss]\nmodel = "cn0"\ncn0_mask_dbhz = 20.0\n[spp]\nraim = true\n')
    r = subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "spp", "--format", "rinex", "--obs",
                        str(smartloc / "Berlin_Potsdamer_Platz.obs"), "--nav", str(smartloc / "brdc1580.16n"),
                        "--config", str(cfg), "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "epochs solved, filter spp" in r.stdout
    from insnav.filters.solution import load_solution

    sol = load_solution(out)
    assert len(sol) > 1300 and np.isnan(sol.yaw_deg).all() and np.all(sol.sigma_pos_n_m > 0)
    assert abs(np.nanmedian(sol.lat_deg) - 52.51) < 0.02
    head = (tmp_path / "spp.csv.spp.csv").read_text().splitlines()[0].split(",")
    assert "isb_R_m" in head and "raim_status" in head
    # the innovations file's rows: the degrees of freedom of the RAIM chi-square (its threshold's), the
    # clock to 0.1 mm in the table
    from insnav.gnss.spp import chi2_quantile

    table = np.genfromtxt(tmp_path / "spp.csv.spp.csv", delimiter=",", names=True)
    inn = np.genfromtxt(tmp_path / "spp.csv.innovations.csv", delimiter=",", names=True, usecols=(0, 3, 4))
    ok = np.isfinite(table["chi2_threshold"])
    assert ok.sum() > 1300 and inn["rows"].max() > 4
    thr = np.array([chi2_quantile(0.999, int(d)) for d in inn["rows"][ok]])
    np.testing.assert_allclose(thr, table["chi2_threshold"][ok], rtol=1e-5)  # %.6g in the file
    clk = (tmp_path / "spp.csv.spp.csv").read_text().splitlines()[1].split(",")[head.index("clock_bias_m")]
    assert len(clk.split(".")[1]) == 4, clk
    text = (tmp_path / "spp.csv.config.toml").read_text()
    assert 'model = "cn0"' in text and "[spp]" in text
    # the resolved configuration runs again to the same result
    out2 = tmp_path / "spp2.csv"
    r = subprocess.run([sys.executable, "-m", "insnav", "run", "--format", "rinex", "--obs",
                        str(smartloc / "Berlin_Potsdamer_Platz.obs"), "--nav", str(smartloc / "brdc1580.16n"),
                        "--config", str(tmp_path / "spp.csv.config.toml"), "--out", str(out2)],  # filter from it
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert np.array_equal(load_solution(out2).lat_deg, sol.lat_deg)


def test_cli_nav_without_klobuchar_is_one_warning_line(smartloc, tmp_path):
    """The smartLoc run with the coefficients cut from its navigation file: one line
    ``warning: <file>: no Klobuchar coefficients ...`` (not Python's warning form), exit 0, and the solution
    of the defaults -- not that of no ionosphere (1.5-30 m a row)."""
    nav = tmp_path / "noion.16n"
    nav.write_text("".join(ln for ln in (smartloc / "brdc1580.16n").read_text().splitlines(True)
                           if "ION ALPHA" not in ln and "ION BETA" not in ln))
    outs = {}
    for name, nav_p in (("bare", nav), ("broadcast", smartloc / "brdc1580.16n")):
        out = tmp_path / f"{name}.csv"
        r = subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "spp", "--format", "rinex", "--obs",
                            str(smartloc / "Berlin_Potsdamer_Platz.obs"), "--nav", str(nav_p), "--out", str(out)],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        warn = [ln for ln in r.stderr.splitlines() if "Klobuchar" in ln]
        if name == "bare":
            assert warn == [f"warning: {nav}: no Klobuchar coefficients (IONOSPHERIC CORR GPSA/GPSB or ION ALPHA/BETA); "
                            "the ionosphere is modelled with the defaults of RTKLIB (the broadcast of 2004-01-01)"]
        else:
            assert warn == []
        assert "Warning" not in r.stderr
        outs[name] = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(1, 2, 3))
    dh = outs["bare"][:, 2] - outs["broadcast"][:, 2]
    assert outs["bare"].shape == outs["broadcast"].shape and 0.0 < np.median(np.abs(dh)) < 10.0


def test_cli_spp_bad_key_and_missing_nav_are_one_line_errors(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text('[gnss]\nweighting = "rtklib"\n')
    r = subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "spp", "--format", "rinex", "--obs",
                        "x.obs", "--nav", "x.nav", "--config", str(cfg), "--out", str(tmp_path / "o.csv")],
                       capture_output=True, text=True)
    assert r.returncode != 0
    err = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(err) == 1 and "unknown key 'gnss.weighting'" in err[0] and str(cfg) in err[0]
    r = subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "spp", "--format", "rinex", "--obs",
                        "x.obs", "--out", str(tmp_path / "o.csv")], capture_output=True, text=True)
    err = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode != 0 and len(err) == 1 and "--nav" in err[0]


@pytest.mark.parametrize("text, msg", [
    ('filtr = "spp"\n', "key 'filtr' is not read by filter 'spp' (it reads [rinex], [gnss] and [spp]); did you "
                         "mean 'filter'?"),
    ("elevation_mask_deg = 30.0\n", "key 'elevation_mask_deg' is not read by filter 'spp' (it reads [rinex], "
                                    "[gnss] and [spp]); did you mean 'rinex.elevation_mask_deg' (a key of the "
                                    "[rinex] table)?")])
def test_cli_spp_a_key_it_does_not_read_is_one_line(tmp_path, capsys, text, msg):
    """A misspelt top-level key or a table key at the top level ran with exit status 0 and the key
    ignored; the TOML of another filter (an INS run's) is still read for the spp tables alone."""
    from insnav.cli import main

    cfg = tmp_path / "run.toml"
    cfg.write_text('filter = "spp"\n' * ("filtr" not in text) + text)
    argv = ["run", "--filter", "spp", "--format", "rinex", "--obs", "x.obs", "--nav", "x.nav", "--config", str(cfg),
            "--out", str(tmp_path / "o.csv")]
    assert main(argv) == 2
    assert capsys.readouterr().err == f"insnav run: error: {cfg}: {msg}\n"
    cfg.write_text('filter = "ekf"\n' + text.replace("filtr", "x_unused"))
    assert main(argv) == 2
    assert "x.obs" in capsys.readouterr().err  # past the TOML: the missing observation file is the error


def test_gnss_table_reaches_the_tight_inputs(shared_data, tmp_path):
    """[gnss] in a --format rinex run TOML changes the rows' sigmas (and only then)."""
    d = shared_data / "rtklibexplorer_walk_0827"
    if not (d / "rinex_derived" / "gnss_1730.obs").is_file():
        pytest.skip(f"{d} not found")
    from insnav.io.rinex_dataset import load_rinex_run

    rinex = ('[rinex]\nimu_columns = ["ax", "ay", "az", "gx", "gy", "gz", "tick_ms"]\nimu_acc_unit = "g"\n'
             'imu_gyro_unit = "dps"\nimu_mount_rpy_deg = [180.0, 0.0, -90.0]\nend_s = 40.0\n')
    files = (d / "rinex_derived" / "gnss_1730.obs", d / "rinex_derived" / "gnss_1730.nav", d / "raw" / "imu_1730.csv")
    base = tmp_path / "base.toml"
    base.write_text(rinex)
    ds0, _ = load_rinex_run(*files, base)
    legacy = tmp_path / "legacy.toml"
    legacy.write_text(rinex + '[gnss]\nmodel = "legacy"\n')
    ds1, _ = load_rinex_run(*files, legacy)
    assert np.array_equal(ds0.tight_inputs.sats, ds1.tight_inputs.sats, equal_nan=True)
    rt = tmp_path / "rtklib.toml"
    rt.write_text(rinex + '[gnss]\nmodel = "rtklib"\n')
    ds2, _ = load_rinex_run(*files, rt)
    i2 = ds2.tight_inputs
    assert np.allclose(i2.sats[:, 10], sigma_rtklib(np.radians(i2.elevation_deg)), rtol=1e-12)
    # the same rows and measurements; the satellite states move by millimetres only (the approximate
    # position, from the differently weighted single-point fixes, enters the light time)
    assert np.array_equal(i2.prn, ds0.tight_inputs.prn) and np.array_equal(i2.sats[:, :2], ds0.tight_inputs.sats[:, :2],
                                                                             equal_nan=True)
    assert np.allclose(i2.sats[:, 2:10], ds0.tight_inputs.sats[:, 2:10], rtol=0, atol=0.05)
    bad = tmp_path / "bad.toml"
    bad.write_text(rinex + '[gnss]\nmodel = "rtklib"\nrtklib_c_m = 1.0\n')
    with pytest.raises(ConfigError, match=r"bad\.toml: unknown key 'gnss\.rtklib_c_m'"):
        load_rinex_run(*files, bad)


def test_smartloc_gps_glonass(smartloc):
    """GPS+GLONASS (RINEX 2 .16n + .16g): more satellites, every epoch solved, a GLONASS-GPS
    inter-system bias that stays constant within its own sigma, and errors below the documented bounds."""
    b = _bench()
    nav = b.nav_for(smartloc, "GR")
    if nav is None:
        pytest.skip("the navigation reader of this commit reads no GLONASS ephemerides")
    from insnav.filters.spp import run_spp_rinex

    obs = b.read_obs(smartloc, "GR")
    sol = run_spp_rinex(obs, nav, spp=dict(raim=False))
    sp = sol.spp
    assert sol.summary["systems"] == "GR" and sp.solved.mean() > 0.99
    sol_g = run_spp_rinex(b.read_obs(smartloc, "G"), b.nav_for(smartloc, "G"), spp=dict(raim=False))
    assert np.mean(sp.n_used[sp.solved]) > 1.5 * np.mean(sol_g.spp.n_used[sol_g.spp.solved])
    isb = sp.isb_m[sp.solved, 1]
    assert abs(np.median(isb)) < 30.0
    assert np.std(isb) < 2.0 * np.median(sp.sigma_isb_m[sp.solved, 1])
    assert (sp.ref_system[sp.solved] == "G").all()
    # the rows are those of the multi-system tight_inputs_from_rinex; only GLONASS sigmas differ (x 1.5)
    from insnav.gnss.spp import spp_inputs_from_rinex
    from insnav.gnss.tight_inputs import tight_inputs_from_rinex

    r0 = np.asarray(sp.info["approx_r_e"])
    t0 = sp.info["t_week0_gps_s"]
    a = tight_inputs_from_rinex(obs, nav, t0, r0, max_sats=0, systems="GR")
    c, _ = spp_inputs_from_rinex(obs, nav, t0, r0)
    assert np.array_equal(a.prn, c.prn) and np.array_equal(a.system, c.system)
    assert np.array_equal(a.sats[:, :10], c.sats[:, :10], equal_nan=True)
    np.testing.assert_allclose(c.sats[:, 10:] / a.sats[:, 10:], np.where(a.system == "R", 1.5, 1.0)[:, None] *
                               np.ones((1, 2)), rtol=1e-12)
    res = b.evaluate(smartloc, "GR", "legacy", False, obs=obs, nav=nav)
    assert res["p50_m"] < b.BOUNDS["GR"]["p50_m"] and res["p95_m"] < b.BOUNDS["GR"]["p95_m"]
    assert res["rms_m"] < b.evaluate(smartloc, "G", "legacy", False)["rms_m"]


def test_cli_tight_run_repeats_the_gnss_table(shared_data, tmp_path):
    """A --format rinex tight run with [gnss] writes it into <out>.config.toml."""
    d = shared_data / "rtklibexplorer_walk_0827"
    if not (d / "rinex_derived" / "gnss_1730.obs").is_file():
        pytest.skip(f"{d} not found")
    cfg = tmp_path / "run.toml"
    cfg.write_text('[rinex]\nimu_columns = ["ax", "ay", "az", "gx", "gy", "gz", "tick_ms"]\nimu_acc_unit = "g"\n'
                   'imu_gyro_unit = "dps"\nimu_mount_rpy_deg = [180.0, 0.0, -90.0]\nend_s = 40.0\n'
                   '[gnss]\nmodel = "cn0"\n')
    out = tmp_path / "sol.csv"
    r = subprocess.run([sys.executable, "-m", "insnav", "run", "--format", "rinex", "--obs",
                        str(d / "rinex_derived" / "gnss_1730.obs"), "--nav", str(d / "rinex_derived" / "gnss_1730.nav"),
                        "--imu", str(d / "raw" / "imu_1730.csv"), "--config", str(cfg), "--coupling", "tight",
                        "--out", str(out), "--allow-free-inertial"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "sol.csv.config.toml").read_text()
    assert "[gnss]" in text and 'model = "cn0"' in text


# --------------------------------------------------------------------- compiled solver = numpy reference


def assert_same_solution(a, b, pos_atol_m=1e-6):
    """Two SppSolutions equal: positions to ``pos_atol_m`` [m] (velocities to 1e-6 m/s), the other
    floats to a relative 1e-8, counts, statuses and exclusions exactly."""
    from dataclasses import fields

    for f in fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "info":
            continue
        x, y = np.asarray(x), np.asarray(y)
        assert x.shape == y.shape and x.dtype == y.dtype, f.name
        if x.dtype.kind == "f":
            np.testing.assert_array_equal(np.isnan(x), np.isnan(y), err_msg=f.name)
            if f.name in ("r_e", "clock_bias_m", "isb_m"):
                np.testing.assert_allclose(x, y, rtol=0, atol=pos_atol_m, err_msg=f.name)
            elif f.name in ("v_e", "clock_drift_mps"):
                np.testing.assert_allclose(x, y, rtol=0, atol=1e-6, err_msg=f.name)
            else:
                np.testing.assert_allclose(x, y, rtol=1e-8, atol=1e-12, err_msg=f.name)
        else:
            np.testing.assert_array_equal(x, y, err_msg=f.name)


@pytest.mark.parametrize("raim", [True, False])
def test_compiled_solver_equals_numpy_reference_simulated(raim):
    """The C++ solver (insnav/gnss/spp_solver.hpp) against the numpy loop on four systems with
    inter-system biases, 60 m pseudorange faults and 30 m/s rate faults (exclusions on both)."""
    from insnav.gnss.spp import _solve_spp_python

    rng = np.random.default_rng(11)

    def systems(n, r):
        return r.choice(["G", "R", "E", "C"], n)

    inp, _ = _epochs(rng, 40, 12, systems=systems, isb={"R": 30.0, "E": -12.0, "C": 55.0}, fault=60.0)
    inp2, _ = _epochs(rng, 20, 9, rate_fault=30.0)
    for data in (inp, inp2):
        a = solve_spp(data, R0, raim=raim)
        b = _solve_spp_python(data, R0, raim=raim)
        assert_same_solution(a, b)
        if raim:
            assert a.n_excluded.sum() + a.n_rate_excluded.sum() > 0
    # options reach the compiled solver: no velocity, at most one exclusion, a cold start
    opt = SppOptions(velocity=False, max_exclusions=1, min_sats=5)
    assert_same_solution(solve_spp(inp, R0, options=opt, warm_start=False),
                         _solve_spp_python(inp, R0, options=opt, warm_start=False))


def test_compiled_solver_equals_numpy_reference_on_real_data(smartloc, shared_data):
    """smartLoc GPS + GLONASS (urban, RAIM excludes rows) and the u-blox walk GPS + Galileo + BeiDou:
    the compiled solver gives the numpy loop's solution, positions to 1e-6 m."""
    from insnav.gnss.spp import _solve_spp_python, read_nav_multi, read_obs_multi, spp_inputs_from_rinex
    from insnav.io.rinex_dataset import _approx_position

    walk = shared_data / "rtklibexplorer_walk_0827" / "rinex_derived"
    cases = [(smartloc / "Berlin_Potsdamer_Platz.obs", [smartloc / "brdc1580.16n", smartloc / "brdc1580.16g"])]
    if (walk / "gnss_1730.obs").is_file():
        cases.append((walk / "gnss_1730.obs", [walk / "gnss_1730.nav"]))
    for obs_p, nav_p in cases:
        obs, nav = read_obs_multi(obs_p), read_nav_multi(nav_p)
        t0 = 604800 * int(obs.epoch_week[0])
        r0 = _approx_position(obs, nav, t0)
        inp, _ = spp_inputs_from_rinex(obs, nav, t0, r0)
        a = solve_spp(inp, r0)
        b = _solve_spp_python(inp, r0)
        assert a.solved.sum() > 0.9 * len(a)
        assert_same_solution(a, b)
