"""Broadcast ephemeris vs precise products, analytic derivatives, Constellation."""

import numpy as np
import pytest

from insnav.gnss import Constellation, read_rinex_nav
from insnav.gnss.ephemeris import (
    C_LIGHT, OMEGA_E_DOT, sat_clock, sat_position_velocity, select_ephemeris,
    tk_from_seconds_of_week, transmit_states,
)
from insnav.gnss.gpstime import gps_seconds_from_calendar, week_tow
from insnav.gnss.sp3 import read_rinex_clk, read_sp3

from conftest import SHARED_DATA as DATA  # ../shared/data beside the repo, or $INSNAV_SHARED_DATA
EPH = DATA / "ephemeris_sp3_2021-118"


@pytest.fixture(scope="module")
def brdc():
    p = EPH / "brdc1180.21n"
    if not p.exists():
        pytest.skip(f"shared data not available: {p} (set INSNAV_SHARED_DATA or put ../shared/data beside the repo)")
    return read_rinex_nav(p)


def test_orbit_vs_code_sp3(brdc):
    s = read_sp3(EPH / "COD0MGXFIN_20211180000_01D_05M_ORB.SP3")
    gps = [k for k, name in enumerate(s.sats) if name.startswith("G")]
    prn = np.array([int(s.sats[k][1:]) for k in gps])
    T = np.repeat(s.t_gps_s, prn.size)
    P = np.tile(prn, s.t_gps_s.size)
    ref = s.r_e[:, gps].reshape(-1, 3)
    idx = select_ephemeris(brdc.eph, P, T)
    ok = (idx >= 0) & np.isfinite(ref[:, 0])
    assert ok.sum() > 2000
    err = np.linalg.norm(sat_position_velocity(brdc.eph, idx[ok], T[ok]).r_e - ref[ok], axis=1)
    assert np.median(err) < 2.5  # measured 1.55 m
    assert np.percentile(err, 95) < 4.0  # measured 2.39 m
    assert np.median(err) > 0.5  # a perfect match would mean we compared the wrong thing


def test_clock_vs_code_clk(brdc):
    """Broadcast polynomial WITHOUT the relativistic term vs CODE 30-s clocks (both exclude it)."""
    c = read_rinex_clk(EPH / "COD0MGXFIN_20211180000_01D_30S_CLK.CLK")
    prns = np.array([p for p in range(1, 33) if f"G{p:02d}" in c.sats])
    assert prns.size >= 28
    cols = [c.sats.index(f"G{p:02d}") for p in prns]
    T = np.repeat(c.t_gps_s, prns.size)
    P = np.tile(prns, c.t_gps_s.size)
    ref = c.clock_s[:, cols].reshape(-1)
    idx = select_ephemeris(brdc.eph, P, T)
    ok = (idx >= 0) & np.isfinite(ref)
    d = C_LIGHT * (sat_clock(brdc.eph, idx[ok], T[ok], relativistic=False).bias_s - ref[ok])
    d -= d.mean()
    assert np.std(d) < 1.0  # measured 0.53 m (mean -0.29 m removed)
    # with the relativistic term the agreement is clearly worse (up to ~14 m periodic)
    d_rel = C_LIGHT * (sat_clock(brdc.eph, idx[ok], T[ok], relativistic=True).bias_s - ref[ok])
    assert np.std(d_rel - d_rel.mean()) > 2.0 * np.std(d)


def test_velocity_and_clock_drift_vs_finite_difference(brdc):
    rng = np.random.default_rng(1)
    idx = rng.integers(0, len(brdc.eph), 200)
    t = brdc.eph.toe[idx] + rng.uniform(-7000.0, 7000.0, idx.size)
    h = 0.5
    pv = sat_position_velocity(brdc.eph, idx, t)
    fd = (sat_position_velocity(brdc.eph, idx, t + h).r_e - sat_position_velocity(brdc.eph, idx, t - h).r_e) / (2 * h)
    assert np.max(np.abs(pv.v_e - fd)) < 1e-3  # m/s
    assert np.all(np.linalg.norm(pv.v_e, axis=1) > 2000.0)  # ECEF speed of GPS ~ 3 km/s
    for rel in (False, True):
        ck = sat_clock(brdc.eph, idx, t, relativistic=rel)
        fdc = (sat_clock(brdc.eph, idx, t + h, relativistic=rel).bias_s
               - sat_clock(brdc.eph, idx, t - h, relativistic=rel).bias_s) / (2 * h)
        assert np.max(np.abs(C_LIGHT * (ck.drift_s_s - fdc))) < 1e-6  # m/s
    ck_t = sat_clock(brdc.eph, idx, t, tgd=True)
    np.testing.assert_allclose(ck.bias_s - ck_t.bias_s, brdc.eph.tgd[idx])


def test_week_crossover(brdc):
    assert tk_from_seconds_of_week(100.0, 604700.0) == 200.0
    assert tk_from_seconds_of_week(604700.0, 100.0) == -200.0
    # an ephemeris re-referenced to 20 s before a week boundary, evaluated across it
    cols = brdc.eph.subset(np.array([0])).to_columns()
    wk = week_tow(cols["toe"][0])[0]
    cols["toe"] = np.array([(wk + 1) * 604800.0 - 20.0])
    cols["toe_sow"] = np.array([604780.0])
    cols["toc"] = cols["toe"].copy()
    from insnav.gnss.ephemeris import Ephemerides
    e = Ephemerides.from_columns(cols)
    t = cols["toe"][0] + np.array([19.0, 21.0])  # straddles the boundary
    pv = sat_position_velocity(e, np.array([0, 0]), t)
    step = pv.r_e[1] - pv.r_e[0]
    np.testing.assert_allclose(step, 0.5 * (pv.v_e[0] + pv.v_e[1]) * 2.0, atol=1e-3)
    assert select_ephemeris(e, [e.prn[0]], [t[1]])[0] == 0


def test_selection_rules(brdc):
    e = brdc.eph
    t = gps_seconds_from_calendar(2021, 4, 28, 20, 0, 0.0)
    idx = select_ephemeris(e, np.arange(1, 33), t)
    assert np.all(idx >= 0)
    assert np.all(np.abs(e.toe[idx] - t) <= 0.5 * e.fit_s[idx])
    assert np.all(np.abs(e.toe[idx] - t) <= 16.0)  # nearest toe: 20:00 (or 19:59:44)
    # far outside any fit interval -> -1
    assert select_ephemeris(e, [5], [t + 86400.0 * 3])[0] == -1
    assert select_ephemeris(e, [5], [t + 86400.0 * 3], check_fit=False)[0] >= 0


def test_transmit_time_and_sagnac(brdc):
    t_rx = gps_seconds_from_calendar(2021, 4, 28, 20, 0, 0.0)
    r_rx = np.array([4157177.0, 671230.0, 4774767.0])
    idx = select_ephemeris(brdc.eph, np.arange(1, 33), t_rx)
    ts = transmit_states(brdc.eph, idx, t_rx, r_rx)
    # self-consistency: tau = |R3(w tau) r_sat(t_rx - tau) - r_rx| / c
    pv = sat_position_velocity(brdc.eph, idx, t_rx - ts.tau_s)
    th = OMEGA_E_DOT * ts.tau_s
    r_rot = np.stack([np.cos(th) * pv.r_e[:, 0] + np.sin(th) * pv.r_e[:, 1],
                      -np.sin(th) * pv.r_e[:, 0] + np.cos(th) * pv.r_e[:, 1], pv.r_e[:, 2]], -1)
    np.testing.assert_allclose(ts.r_e, r_rot, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(ts.r_e - r_rx, axis=1) / C_LIGHT, ts.tau_s, atol=1e-11)
    assert np.all((ts.tau_s > 0.064) & (ts.tau_s < 0.12))  # zenith ~67 ms, Earth-limb ~ 110 ms
    # the Sagnac rotation moves satellites by w * tau * |r_xy| <= 7.3e-5 * 0.11 * 2.66e7 = 213 m
    shift = np.linalg.norm(ts.r_e - pv.r_e, axis=1)
    assert np.all(shift > 10.0) and np.all(shift < 215.0)


def test_constellation_nominal_and_broadcast(brdc):
    nom = Constellation.nominal()
    from insnav.gnss._nominal_elements import T_REF_GPS_S
    s = nom.sat_states(T_REF_GPS_S)
    assert s.prn.size == 31 and s.r_e.shape == (31, 3)   # PRN 11 left out (duplicate of PRN 10's elements)
    d = np.linalg.norm(s.r_e[:, None, :] - s.r_e[None, :, :], axis=-1) + np.eye(31) * 1e9
    assert d.min() > 1e5                                    # no two satellites at one point in the sky
    b = Constellation.from_rinex_nav(EPH / "brdc1180.21n").sat_states(T_REF_GPS_S, s.prn)
    idx_nom = np.argsort(s.prn)
    np.testing.assert_allclose(s.r_e, b.r_e[idx_nom], atol=1e-6)  # same elements at the reference time
    np.testing.assert_allclose(s.clock_bias_m, b.clock_bias_m[idx_nom], atol=1e-6)


def test_constellation_nominal_any_time_no_data():
    nom = Constellation.nominal()
    t = gps_seconds_from_calendar(2035, 7, 1, 12, 0, 0.0)  # 14 years after the elements
    s = nom.sat_states(t)
    rad = np.linalg.norm(s.r_e, axis=1)
    assert s.prn.size == 31 and np.all((rad > 2.58e7) & (rad < 2.74e7))  # a (1 +/- e), e < 0.03; PRN 11 left out
    speed = np.linalg.norm(s.v_e, axis=1)
    assert np.all((speed > 2.5e3) & (speed < 4.2e3))
    # deterministic and re-referencable: sky at t0 + x equals reference sky at T_REF + x
    from insnav.gnss._nominal_elements import T_REF_GPS_S
    a = Constellation.nominal(t).sat_states(t + 300.0, [3, 17])
    b = Constellation.nominal().sat_states(T_REF_GPS_S + 300.0, [3, 17])
    np.testing.assert_array_equal(a.r_e, b.r_e)
    np.testing.assert_array_equal(a.clock_drift_mps, b.clock_drift_mps)
    # a receiver anywhere sees >= 4 satellites above 10 deg at any time
    from insnav import earth
    from insnav.gnss.geometry import elevation_azimuth
    rng = np.random.default_rng(0)
    for _ in range(20):
        lat, lon = np.arcsin(rng.uniform(-1, 1)), rng.uniform(-np.pi, np.pi)
        r = earth.geodetic_to_ecef(lat, lon, 0.0)
        st = nom.transmit_states(t + rng.uniform(0, 86400 * 30), r)
        el, _ = elevation_azimuth(r, st.r_e)
        assert np.sum(el > np.deg2rad(10)) >= 4


@pytest.mark.parametrize("parts, systems", [
    (("smartloc_berlin_potsdamer_platz", "brdc1580.16n"), "G"),
    (("smartloc_berlin_potsdamer_platz", "brdc1580.16g"), "R"),
    (("euref_wettzell_wtzr_wtzz", "ESBC00DNK_R_20201770000_01D_MN.rnx"), "GREC"),
])
def test_compiled_record_selection_equals_numpy_reference(parts, systems):
    """insnav/gnss/ephemeris_selection.hpp against the numpy loops of select_ephemeris / select_glonass: the
    same record for every (satellite, time), over the day and beyond its ends, at ties (times half-way between
    two references) and with each option."""
    from insnav.gnss import ephemeris as E
    from insnav.gnss import glonass as G

    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"shared data not available: {p}")
    nav = read_rinex_nav(p, systems=systems)
    rng = np.random.default_rng(5)
    for tab, t_ref, kind in ((nav.eph, "toe", "kepler"), (nav.eph_e, "toe", "kepler"), (nav.eph_c, "toe", "kepler"),
                             (nav.eph_r, "tb", "glonass")):
        if tab is None or len(tab) == 0:
            continue
        ref = np.asarray(getattr(tab, t_ref), float)
        prn = np.concatenate([rng.choice(np.append(np.unique(tab.prn), 99), 3000), tab.prn[:-1]])
        mid = 0.5 * (ref[:-1] + ref[1:])  # half-way between records: ties where the satellite is the same
        t = np.concatenate([rng.uniform(ref.min() - 4 * 3600, ref.max() + 4 * 3600, 3000), mid])
        if kind == "kepler":
            for kw in (dict(), dict(healthy_only=False), dict(check_fit=False), dict(max_age_s=7200)):
                got = E.select_ephemeris(tab, prn, t, **kw)
                want = E._select_ephemeris_numpy(tab, prn, t, kw.get("healthy_only", True), kw.get("check_fit", True),
                                                 kw.get("max_age_s"))
                np.testing.assert_array_equal(got, want)
                assert (got >= 0).sum() > 1000
        else:
            for kw in (dict(), dict(healthy_only=False, max_age_s=900.0)):
                got = G.select_glonass(tab, prn, t, **kw)
                want = G._select_glonass_numpy(tab, prn, t, kw.get("healthy_only", True),
                                               kw.get("max_age_s", G.MAX_AGE_GLO_S))
                np.testing.assert_array_equal(got, want)
                assert (got >= 0).sum() > 1000
