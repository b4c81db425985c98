"""Carrier-phase simulator (insnav.sim.gnss_rtk) and the RINEX 3 writer (insnav.gnss.rinex_write).

Checks: double-differenced phase against an independent geometric computation
(1e-6 m), RINEX observation and navigation round trips through insnav's own
readers, the slip statistics against the configured rate, the urban-canyon
mask, and RTKLIB reading and fixing the written files.
"""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from insnav import earth
from insnav.gnss.ephemeris import C_LIGHT, OMEGA_E_DOT, rotate_earth
from insnav.sim import ScenarioError, load_scenario, simulate_rtk
from insnav.sim.scenario import resolve_raw


def _scenario(preset: str, duration_s: float = 60.0, **rtk):
    """A preset shortened to ``duration_s`` (one straight segment after a turn), ``[gnss_rtk]`` keys replaced."""
    raw, _ = resolve_raw(preset)
    raw["motion"]["segments"] = [{"duration_s": duration_s / 2, "target_speed_mps": 12.0},
                                 {"duration_s": duration_s / 2, "heading_change_deg": 90.0}]
    raw["initial"]["speed_mps"] = 5.0
    raw["gnss_rtk"].update(rtk)
    return raw


_QUIET = dict(sigma_code_m=0.0, sigma_phase_m=0.0, sigma_doppler_hz=0.0)


def _pairs(rover, base):
    """Row indices (i_rover, i_base) of the same epoch and satellite."""
    kr = {(int(e), s, int(p)): i for i, (e, s, p) in enumerate(zip(rover.epoch, rover.system, rover.prn))}
    ir, ib = [], []
    for j, (e, s, p) in enumerate(zip(base.epoch, base.system, base.prn)):
        i = kr.get((int(e), s, int(p)))
        if i is not None:
            ir.append(i)
            ib.append(j)
    return np.array(ir), np.array(ib)


def _geometry(nav, t_rx_gps, r_rx_e, system, prn):
    """rho - c dt_s recomputed independently: geometric states at t (no light time), own light-time
    iteration and Sagnac rotation (IS-GPS-200 20.3.3.4.3.3.2)."""
    tau = np.full(t_rx_gps.size, 0.07)
    for _ in range(6):
        st = nav.sat_states(t_rx_gps - tau, system=system, prn=prn)
        r_s = rotate_earth(st.r_e, OMEGA_E_DOT * tau)
        tau = np.linalg.norm(r_s - r_rx_e, axis=1) / C_LIGHT
    st = nav.sat_states(t_rx_gps - tau, system=system, prn=prn)
    r_s = rotate_earth(st.r_e, OMEGA_E_DOT * tau)
    return np.linalg.norm(r_s - r_rx_e, axis=1) - st.clock_bias_m


def test_double_difference_phase_equals_geometry_plus_modelled_terms(tmp_path):
    sim = simulate_rtk(_scenario("rtk-open-sky-car", 60.0, **_QUIET), seed=3)
    from insnav.gnss.rinex import read_rinex_nav

    sim.write(tmp_path)
    nav = read_rinex_nav(tmp_path / "nav.rnx", systems="GE")  # what any RINEX user gets
    r, b = sim.rover, sim.base
    ir, ib = _pairs(r, b)
    assert ir.size > 500
    g_r = _geometry(nav, r.t_rx_gps_s[r.epoch[ir]], r.r_e[r.epoch[ir]], r.system[ir], r.prn[ir])
    g_b = _geometry(nav, b.t_rx_gps_s[b.epoch[ib]], b.r_e[b.epoch[ib]], b.system[ib], b.prn[ib])
    sd_geom = g_r - g_b
    n_checked = 0
    for k in range(r.phase_cyc.shape[1]):
        lam = r.wavelength_m[ir, k]
        sd_phase_m = lam * (r.phase_cyc[ir, k] - b.phase_cyc[ib, k])
        sd_amb = r.ambiguity_cyc[ir, k] - b.ambiguity_cyc[ib, k]
        q = r.iono_freq_factor[ir, k]
        sd_terms = (-q * (r.iono_l1_m[ir] - b.iono_l1_m[ib]) + (r.tropo_m[ir] - b.tropo_m[ib])
                    + (r.mp_phase_m[ir, k] - b.mp_phase_m[ib, k]))
        ep = r.epoch[ir]
        for e in np.unique(ep):
            for s in ("G", "E"):
                rows = np.flatnonzero((ep == e) & (r.system[ir] == s) & np.isfinite(lam))
                if rows.size < 2:
                    continue
                ref = rows[np.argmax(r.el[ir[rows]])]
                oth = rows[rows != ref]
                dd_phase = sd_phase_m[oth] - sd_phase_m[ref]
                dd_geom = sd_geom[oth] - sd_geom[ref]
                dd_expect = lam[oth] * (sd_amb[oth] - sd_amb[ref]) + sd_terms[oth] - sd_terms[ref]
                np.testing.assert_allclose(dd_phase - dd_geom, dd_expect, rtol=0, atol=1e-6)
                n_checked += oth.size
    assert n_checked > 1000
    # the modelled terms are really there: DD iono + tropo + multipath of order mm-cm, not zero
    assert np.std(r.mp_phase_m[ir, 0]) > 1e-3


def test_residual_ionosphere_and_troposphere_scale_with_the_baseline():
    # between-receiver delays divided by (baseline x mapping) are unit Gauss-Markov processes x ppm
    from insnav.sim.gnss_rtk import iono_mapping

    sim = simulate_rtk(_scenario("rtk-open-sky-car", 200.0, iono_ppm=2.0, tropo_ppm=0.5, iono_tau_s=20.0,
                                 tropo_tau_s=20.0, saastamoinen=False), seed=8)
    r, b = sim.rover, sim.base
    ir, ib = _pairs(r, b)
    d = np.linalg.norm(r.r_e[r.epoch[ir]] - sim.base_r_e, axis=1)
    x_i = (r.iono_l1_m[ir] - b.iono_l1_m[ib]) / (1e-6 * d * iono_mapping(r.el[ir]))
    x_t = (r.tropo_m[ir] - b.tropo_m[ib]) / (1e-6 * d / np.sin(r.el[ir]))
    assert abs(np.std(x_i) / 2.0 - 1.0) < 0.15 and abs(np.mean(x_i)) < 0.4
    assert abs(np.std(x_t) / 0.5 - 1.0) < 0.15
    assert d.max() > 2000.0


def test_doppler_is_minus_the_phase_rate():
    # D = -d(rho + b - c dt_s)/dt / lambda: the central difference of the phase (cycles) over +-1 s
    raw = _scenario("rtk-open-sky-car", 40.0, multipath_phase_m=0.0, multipath_code_m=0.0, **_QUIET)
    # constant velocity: the 2 s difference cannot follow the jerk of a manoeuvre, wheel slip or bounce
    raw["motion"].update(lateral_slip_mps=0.0, vertical_bounce_mps=0.0, segments=[{"duration_s": 40.0}])
    raw["initial"]["speed_mps"] = 15.0
    sim = simulate_rtk(raw, seed=6)
    r = sim.rover
    key = np.char.add(r.system, r.prn.astype(str))
    worst = 0.0
    for sat in np.unique(key):
        rows = np.flatnonzero(key == sat)
        ok = (np.diff(r.epoch[rows])[1:] == 1) & (np.diff(r.epoch[rows])[:-1] == 1)
        for k in range(2):
            lam = r.wavelength_m[rows[1:-1], k]
            # the receiver clock's white frequency noise moves the phase but not the drift d the Doppler
            # carries (it cancels between satellites): compare without the clock terms
            e0, e1, e2 = r.epoch[rows[:-2]], r.epoch[rows[1:-1]], r.epoch[rows[2:]]
            rate = (r.phase_cyc[rows[2:], k] - r.phase_cyc[rows[:-2], k]) / 2.0 \
                - (r.clock_bias_m[e2] - r.clock_bias_m[e0]) / 2.0 / lam
            dop = r.doppler_hz[rows[1:-1], k] + r.clock_drift_mps[e1] / lam
            same = r.ambiguity_cyc[rows[2:], k] == r.ambiguity_cyc[rows[:-2], k]
            m = ok & same & np.isfinite(lam)
            worst = max(worst, float(np.max(np.abs(rate[m] + dop[m]), initial=0.0)))
    assert worst < 0.02, worst  # the rest: curvature over 2 s, ionosphere rate


def test_rinex_obs_round_trip(tmp_path):
    from insnav.gnss.rinex import read_rinex_obs

    sim = simulate_rtk(_scenario("rtk-open-sky-car", 40.0, slip_rate_per_h=600.0), seed=5)
    files = sim.write(tmp_path / "new" / "dir")  # made with its parents
    assert sorted(p.name for p in (tmp_path / "new" / "dir").iterdir()) == [
        "base.obs", "nav.rnx", "rover.obs", "rtk_truth.csv"]
    before = files["rover"].read_bytes()
    with pytest.raises(FileExistsError, match=r"rover\.obs: exists \(overwrite_ok=False\)"):
        sim.write(tmp_path / "new" / "dir", overwrite_ok=False)
    assert files["rover"].read_bytes() == before
    with pytest.raises(NotADirectoryError, match="not a directory"):
        sim.write(files["nav"])
    r = sim.rover
    for codes, k in ((None, 0), ({"G": ("C2W",), "E": ("C5Q",)}, 1)):
        obs = read_rinex_obs(files["rover"], systems="GE", codes=codes)
        np.testing.assert_array_equal(obs.epoch_t_gps_s, r.t_tag_gps_s)
        # rows: the writer sorts by satellite id within an epoch
        order = np.lexsort((r.sat_id, r.epoch))
        assert list(obs.sat_id) == list(r.sat_id[order])
        for mine, got in ((r.code_m, obs.C1), (r.phase_cyc, obs.L1), (r.doppler_hz, obs.D1), (r.cn0_dbhz, obs.S1)):
            np.testing.assert_allclose(got, mine[order, k], rtol=0, atol=5.0001e-4)
    np.testing.assert_allclose(obs.approx_r_e, r.r_e[0], atol=5.1e-5)
    # LLI column after each phase value (reader-independent parse of the fixed columns)
    lli_file = []
    for line in files["rover"].read_text().splitlines()[1:]:
        if line[:1] in "GE" and line[1:3].isdigit():
            lli_file.append([int(line[3 + 16 * c + 14]) if len(line) > 3 + 16 * c + 14
                             and line[3 + 16 * c + 14] != " " else 0 for c in (1, 5)])
    lli_file = np.array(lli_file)
    np.testing.assert_array_equal(lli_file, r.lli[order])
    assert r.lli.sum() > 5


def test_rinex_nav_round_trip_reproduces_satellites():
    from insnav.gnss.constellation import Constellation
    from insnav.gnss.ephemeris import sat_position_velocity
    from insnav.gnss.rinex import read_rinex_nav
    from insnav.gnss.rinex_write import write_rinex_nav
    from insnav.gnss.walker import walker_constellation
    from insnav.sim.gnss_rtk import rtk_navdata

    import tempfile
    from pathlib import Path

    t0 = 2155 * 604800.0 + 345600.0
    nav = rtk_navdata(t0, ("G", "E"))
    with tempfile.TemporaryDirectory() as d:
        p = write_rinex_nav(Path(d) / "nav.rnx", nav.eph, nav.eph_e, ion_alpha=nav.ion_alpha, ion_beta=nav.ion_beta)
        back = read_rinex_nav(p, systems="GE")
    np.testing.assert_array_equal(back.ion_alpha, nav.ion_alpha)
    t = t0 + np.array([0.0, 1234.5, 3600.0, 7100.0])
    # the raw-GNSS simulation's constellations (GPS constants, not rounded) against the file read back
    cons = {"G": Constellation.nominal(t0_gps_s=t0), "E": walker_constellation("E", t0)}
    for s, c in cons.items():
        prn = np.asarray(c.prns)
        for tk in t:
            pv = sat_position_velocity(c.eph, np.arange(prn.size), np.full(prn.size, tk))
            st = back.sat_states(tk, system=s, prn=prn)
            assert st.valid.all()
            assert np.max(np.linalg.norm(st.r_e - pv.r_e, axis=1)) < 1e-3
            assert np.max(np.linalg.norm(st.v_e - pv.v_e, axis=1)) < 1e-6
            mem = nav.sat_states(tk, system=s, prn=prn)
            assert np.max(np.abs(mem.r_e - st.r_e)) < 1e-6  # the simulator's own satellites, exactly
            assert np.max(np.abs(mem.clock_bias_m - st.clock_bias_m)) < 1e-6


@pytest.mark.parametrize("frac_s", [0.37, -0.5])
def test_rinex_representable_keeps_the_orbit_for_a_fractional_start(frac_s):
    # toe/toc moved to whole seconds, t_oe made the seconds of week of toe: the same orbit and clock
    from insnav.gnss.constellation import Constellation
    from insnav.gnss.ephemeris import Ephemerides, sat_clock, sat_position_velocity
    from insnav.gnss.rinex_write import rinex_representable

    t0 = 2155 * 604800.0 + 345600.0 + frac_s
    eph = Constellation.nominal(t0_gps_s=t0).eph
    rep = Ephemerides.from_columns(rinex_representable(eph.to_columns()))
    assert np.all(rep.toe == np.round(rep.toe)) and np.all(rep.toc == np.round(rep.toc))
    assert np.any(np.abs(rep.toe_sow - eph.toe_sow) > 1.0)  # the nominal set's t_oe did not match its toe
    idx = np.arange(len(eph))
    for tk in t0 + np.array([0.0, 900.0, 5400.0]):
        a = sat_position_velocity(eph, idx, np.full(idx.size, tk))
        b = sat_position_velocity(rep, idx, np.full(idx.size, tk))
        assert np.max(np.linalg.norm(a.r_e - b.r_e, axis=1)) < 1e-3
        ca = sat_clock(eph, idx, np.full(idx.size, tk), relativistic=True, E=a.E, E_dot=a.E_dot)
        cb = sat_clock(rep, idx, np.full(idx.size, tk), relativistic=True, E=b.E, E_dot=b.E_dot)
        assert np.max(np.abs(ca.bias_s - cb.bias_s)) * C_LIGHT < 1e-3


def test_navigation_records_every_2h_describe_one_orbit():
    # a 5 h scenario: three records per satellite, each valid +-2 h, one continuous orbit and clock
    from insnav.gnss.constellation import Constellation
    from insnav.gnss.ephemeris import sat_position_velocity
    from insnav.sim.gnss_rtk import rtk_navdata

    t0 = 2155 * 604800.0 + 345600.0
    nav = rtk_navdata(t0, ("G", "E"), duration_s=5 * 3600.0)
    assert len(nav.eph) == 3 * np.unique(nav.eph.prn).size
    assert np.unique(nav.eph_e.toe).size == 3
    c = Constellation.nominal(t0_gps_s=t0)
    prn = np.asarray(c.prns)
    for tk in t0 + np.array([3599.0, 3601.0, 4.9 * 3600.0]):
        pv = sat_position_velocity(c.eph, np.arange(prn.size), np.full(prn.size, tk))
        st = nav.sat_states(tk, system="G", prn=prn)
        assert st.valid.all()
        assert np.max(np.linalg.norm(st.r_e - pv.r_e, axis=1)) < 1e-3


def test_slip_count_matches_configured_rate():
    rate_h = 720.0  # per satellite and signal: p = 1 - exp(-0.2) = 0.181 per 1 s epoch
    sim = simulate_rtk(_scenario("rtk-open-sky-car", 100.0, slip_rate_per_h=rate_h, slip_lli_prob=0.5,
                                 slip_max_cycles=3), seed=11)
    r = sim.rover
    p = 1.0 - np.exp(-rate_h / 3600.0)
    # opportunities: every (satellite, signal) row whose previous epoch also had it (same arc)
    key = np.char.add(r.system, r.prn.astype(str))
    n_opp, n_slip, n_flag, jumps_ok = 0, 0, 0, True
    for sat in np.unique(key):
        rows = np.flatnonzero(key == sat)
        cont = np.diff(r.epoch[rows]) == 1
        for k in range(2):
            n_opp += int(cont.sum())
            sl = r.slip[rows[1:], k]
            assert not r.slip[rows[0], k]
            n_slip += int(sl[cont].sum())
            n_flag += int((r.lli[rows[1:], k][cont] & sl[cont]).sum())
            dn = np.diff(r.ambiguity_cyc[rows, k])[cont]
            jumps_ok &= bool(np.array_equal(dn != 0, sl[cont])) and bool(np.all(np.abs(dn) <= 3))
    assert jumps_ok
    sd = np.sqrt(n_opp * p * (1 - p))
    assert abs(n_slip - n_opp * p) < 4 * sd, (n_slip, n_opp * p, sd)
    assert abs(n_flag - 0.5 * n_slip) < 4 * np.sqrt(0.25 * n_slip)
    # no slips configured -> none, base never slips by default
    assert sim.base.slip.sum() == 0
    quiet = simulate_rtk(_scenario("rtk-open-sky-car", 30.0, slip_rate_per_h=0.0), seed=11)
    assert quiet.rover.slip.sum() == 0 and quiet.rover.lli.sum() == 0


def test_urban_mask_removes_exactly_the_satellites_below_it():
    from insnav.gnss.geometry import elevation_azimuth
    from insnav.sim.gnss_raw import urban_canyon_mask
    from insnav.sim.trajectory import Trajectory

    raw = _scenario("rtk-urban-car", 80.0)
    sc = load_scenario(raw, seed=2)
    sim = simulate_rtk(sc)
    r, cfg, nav = sim.rover, sc.gnss_rtk, sim.nav
    heading = Trajectory(sc).state(r.t_tag_gps_s - sc.gps_time_offset_s)["euler"][:, 2]
    prn = np.unique(nav.eph.prn)
    n_removed = 0
    for e in range(r.t_tag_gps_s.size):
        st = nav.transmit_states(np.full(prn.size, r.t_rx_gps_s[e]), r.r_e[e], system="G", prn=prn)
        el, az = elevation_azimuth(r.r_e[e], st.r_e)
        mask = np.maximum(cfg["elevation_mask"], urban_canyon_mask(az - heading[e], cfg["urban_canyon"]["mask_across"],
                                                                   cfg["urban_canyon"]["mask_along"]))
        expected = set(prn[el >= mask].tolist())
        got = set(r.prn[r.epoch == e].tolist())
        assert got == expected, e
        n_removed += int(((el >= cfg["elevation_mask"]) & (el < mask)).sum())
    assert n_removed > r.t_tag_gps_s.size // 4  # the canyon hides satellites the 15 deg mask alone keeps
    n_r, n_c = sim.common_counts()
    assert n_r.max() <= 8 and n_c.min() >= 4


def test_bad_rtk_table_names_the_key():
    raw = _scenario("rtk-urban-car", 20.0)
    raw["gnss_rtk"]["systems"] = ["C"]
    with pytest.raises(ScenarioError, match="gnss_rtk.systems"):
        load_scenario(raw)
    raw = _scenario("rtk-urban-car", 20.0)
    raw["gnss_rtk"]["signals"] = {"G": ["1C", "1W"]}
    with pytest.raises(ScenarioError, match="gnss_rtk.signals.G"):
        load_scenario(raw)
    raw = _scenario("rtk-urban-car", 20.0)
    raw["gnss_rtk"]["base"] = {"offset_ned_m": [1.0, 2.0, 3.0], "lat_deg": 10.0}
    with pytest.raises(ScenarioError, match="gnss_rtk.base"):
        load_scenario(raw)


def test_simulate_and_simulate_rtk_agree_and_cli_writes_rinex(tmp_path):
    from insnav._toml import dumps_toml
    from insnav.cli import main
    from insnav.data.dataset import load_dataset
    from insnav.gnss.rinex import read_rinex_obs

    raw = _scenario("rtk-urban-car", 20.0)
    path = tmp_path / "short.toml"
    path.write_text(dumps_toml(raw), encoding="utf-8")
    out = tmp_path / "ds"
    assert main(["simulate", str(path), "--seed", "4", "--out", str(out), "-q"]) == 0
    for f in ("rover.obs", "base.obs", "nav.rnx", "rtk_truth.csv", "imu.csv"):
        assert (out / f).is_file(), f
    alone = simulate_rtk(raw, seed=4)
    obs = read_rinex_obs(out / "base.obs")
    order = np.lexsort((alone.base.sat_id, alone.base.epoch))
    np.testing.assert_allclose(obs.L1, alone.base.phase_cyc[order, 0], atol=5.0001e-4)
    assert len(load_dataset(out).imu) == 2000
    # the folder holds only files insnav wrote: --overwrite may replace it
    assert main(["simulate", str(path), "--seed", "4", "--out", str(out), "-q", "--overwrite"]) == 0


@pytest.mark.skipif(shutil.which("rnx2rtkp") is None, reason="RTKLIB rnx2rtkp not installed (apt-get install rtklib)")
def test_rtklib_reads_the_files_and_fixes(tmp_path):
    from insnav.io.gnss_files import read_rtklib_pos

    sim = simulate_rtk(_scenario("rtk-open-sky-car", 60.0), seed=1)
    files = sim.write(tmp_path)
    conf = tmp_path / "k.conf"
    conf.write_text("pos1-posmode=kinematic\npos1-frequency=l1\npos1-navsys=9\npos1-elmask=10\n"
                    "pos2-armode=continuous\npos2-arthres=3\nout-solformat=llh\nant2-postype=rinexhead\n")
    pos = tmp_path / "out.pos"
    subprocess.run(["rnx2rtkp", "-k", str(conf), "-o", str(pos), str(files["rover"]), str(files["base"]),
                    str(files["nav"])], check=True, capture_output=True, timeout=120)
    sol = read_rtklib_pos(pos)
    assert sol.t_gps_s.size == sim.rover.t_tag_gps_s.size
    i = np.searchsorted(sim.rover.t_tag_gps_s, sol.t_gps_s - 1e-3)
    err = np.linalg.norm(sol.r_e - sim.rover.r_e[i], axis=1)
    fixed = sol.q == 1
    assert fixed.mean() > 0.8
    assert np.max(err[fixed]) < 0.05
    lat, lon, h = earth.ecef_to_geodetic(sim.rover.r_e[:1])
    assert abs(h[0] - earth.ecef_to_geodetic(sol.r_e[:1])[2][0]) < 0.1


def test_rtk_noise_options_reproduce_the_simulated_noise_model():
    """rtk_noise_options against the simulator's own error model: the engines' zero-difference phase variance
    a^2 + b^2 / sin^2 el equals sigma_L^2 w(el)^2 at every elevation (exact), code_phase_ratio^2 times it
    equals (sigma_P^2 + sigma_mp,P^2) w(el)^2, and the ambiguity walk q [cycles^2/s] matches the variance of
    the one-epoch increments of the simulator's Gauss-Markov phase multipath (rover plus base scale)
    to the first-order term 1 - exp(-dt / tau) ~ dt / tau (2.5 % at dt / tau = 0.05) and the sampling error."""
    from insnav.sim.gnss_rtk import F_L1_HZ, elevation_weight, gauss_markov, rtk_noise_options

    g = load_scenario("rtk-urban-car").gnss_rtk
    o = rtk_noise_options(g)
    el = np.radians(np.linspace(5.0, 90.0, 50))
    w2 = elevation_weight(el) ** 2
    var_l = o["sigma_phase_a_m"] ** 2 + o["sigma_phase_b_m"] ** 2 / np.sin(el) ** 2
    np.testing.assert_allclose(var_l, g["sigma_phase"] ** 2 * w2, rtol=1e-12)
    np.testing.assert_allclose(o["code_phase_ratio"] ** 2 * var_l,
                               (g["sigma_code"] ** 2 + g["multipath_code"] ** 2) * w2, rtol=1e-12)
    assert o["code_correlation_time_s"] == g["multipath_tau"]
    rng = np.random.default_rng(5)
    x = gauss_markov(4000, (200,), 1.0, g["multipath_tau"], rng)
    sd = g["multipath_phase"] * np.sqrt(1.0 + g["base_multipath_scale"] ** 2) * x  # single difference, zenith
    var_step = np.var(np.diff(sd, axis=0)) / (C_LIGHT / F_L1_HZ) ** 2
    assert abs(var_step / o["amb_psd_cycles2ps"] - 1.0) < 0.05, (var_step, o["amb_psd_cycles2ps"])
    with pytest.raises(ValueError, match="sigma_phase_m"):
        rtk_noise_options(dict(g, sigma_phase=0.0))


@pytest.mark.parametrize("gps_week, leap", [(1600, 15), (2200, 18)])
def test_the_nav_header_gives_the_leap_seconds_of_the_scenario_date(tmp_path, gps_week, leap):
    """nav.rnx said 18 LEAP SECONDS whatever the date; GPS - UTC was 15 s in 2010 (week 1600)."""
    raw = _scenario("rtk-open-sky-car", 4.0)
    raw.setdefault("time", {}).update(gps_week=gps_week, gps_tow_s=345600.0)
    simulate_rtk(raw, seed=1).write(tmp_path)
    head = (tmp_path / "nav.rnx").read_text().split("END OF HEADER")[0].splitlines()
    assert [ln[:6] for ln in head if ln[60:].strip() == "LEAP SECONDS"] == [f"{leap:6d}"]
