"""QZSS (system J): broadcast orbits by the GPS algorithm checked against an independent Kepler
orbit, the RINEX 3 navigation records of both readers, QZS-3's geostationary position, real
pseudoranges against the GPS receiver clock, single point positioning and RTK with QZSS.

IS-QZSS-PNT (Cabinet Office, Japan): the QZSS LNAV message, orbit and clock algorithms are
GPS's (IS-GPS-200 20.3.3.4.3), on GPS's L1/L2/L5 frequencies, in QZSS time steered to GPST.
"""
from __future__ import annotations

import numpy as np
import pytest

from insnav import earth
from insnav.gnss.broadcast import sat_states_multi, transmit_states_multi
from insnav.gnss.ephemeris import Ephemerides
from insnav.gnss.rinex import NavData, read_rinex_nav

from conftest import SHARED_DATA as DATA

MU = 3.986005e14  # WGS-84 GM of IS-GPS-200 / IS-QZSS-PNT [m^3/s^2]
OMEGA_E = 7.2921151467e-5  # [rad/s]
GAMMA = (1575.42 / 1227.60) ** 2
MATRTKLIB = "matrtklib_static_septentrio"


def _qzo_record(prn: int, **over) -> dict:
    """One LNAV record of a quasi-zenith orbit (QZS-2-like: a = 42 164 km, e = 0.075, i = 41 deg)."""
    toe = 2320 * 604800.0 + 118800.0
    r = dict(prn=prn, toc=toe, af0=-3.9e-7, af1=-1.1e-13, af2=0.0, iode=129.0, crs=0.0, delta_n=0.0, m0=0.457,
             cuc=0.0, e=0.0755, cus=0.0, sqrt_a=6493.16, toe=toe, toe_sow=118800.0, cic=0.0, omega0=-0.312, cis=0.0,
             i0=0.7082, crc=0.0, omega=-1.584, omega_dot=-2.88e-9, idot=0.0, week=2320.0, sv_accuracy=2.0,
             health=0.0, tgd=1.4e-9, iodc=897.0, fit_s=7200.0)
    r.update(over)
    return {k: np.array([v]) for k, v in r.items()}


def _kepler_ecef(rec: dict, t: float) -> np.ndarray:
    """The unperturbed Kepler orbit of ``rec`` at GPS time ``t``, written out here (IS-GPS-200 Table 20-IV
    without the harmonic corrections, which the record sets to zero)."""
    g = {k: float(v[0]) for k, v in rec.items()}
    a = g["sqrt_a"] ** 2
    tk = t - g["toe"]
    n = np.sqrt(MU / a ** 3) + g["delta_n"]
    M = g["m0"] + n * tk
    E = M
    for _ in range(50):
        E = E - (E - g["e"] * np.sin(E) - M) / (1.0 - g["e"] * np.cos(E))
    nu = np.arctan2(np.sqrt(1.0 - g["e"] ** 2) * np.sin(E), np.cos(E) - g["e"])
    u = nu + g["omega"]
    r = a * (1.0 - g["e"] * np.cos(E))
    i = g["i0"] + g["idot"] * tk
    node = g["omega0"] + (g["omega_dot"] - OMEGA_E) * tk - OMEGA_E * g["toe_sow"]
    x, y = r * np.cos(u), r * np.sin(u)
    return np.array([x * np.cos(node) - y * np.cos(i) * np.sin(node),
                     x * np.sin(node) + y * np.cos(i) * np.cos(node), y * np.sin(i)])


def test_qzss_orbit_is_the_gps_algorithm_and_matches_an_independent_kepler_orbit():
    rec = _qzo_record(2)
    empty = Ephemerides.from_columns({k: np.zeros(0) for k in rec})
    nav = NavData("synthetic", 3.04, Ephemerides.from_columns(_qzo_record(2)), eph_j=Ephemerides.from_columns(rec))
    assert nav.systems == "GJ" and len(NavData("x", 3.04, empty).eph_j) == 0
    t = rec["toe"][0] + np.array([-3000.0, -1200.0, 0.0, 900.0, 3500.0])
    st = sat_states_multi(nav, t, ["J02"] * t.size, relativistic=False, group_delay=False)
    assert st.valid.all()
    for k in range(t.size):
        assert np.linalg.norm(st.r_e[k] - _kepler_ecef(rec, t[k])) < 1e-6
    # the same record as a GPS satellite: bit-identical states, T_GD (L1) and gamma T_GD (L2) alike
    for code in ("C1C", "C2L"):
        j = transmit_states_multi(nav, t, [3.0e6, -4.0e6, 3.5e6], ["J02"] * t.size, codes={"J": code, "G": code})
        g = transmit_states_multi(nav, t, [3.0e6, -4.0e6, 3.5e6], ["G02"] * t.size, codes={"J": code, "G": code})
        assert np.array_equal(j.r_e, g.r_e) and np.array_equal(j.v_e, g.v_e)
        assert np.array_equal(j.clock_bias_s, g.clock_bias_s)
        gd = rec["tgd"][0] * (GAMMA if code == "C2L" else 1.0)
        assert np.allclose(j.group_delay_s, gd, rtol=1e-15, atol=0)
        assert np.allclose(j.wavelength_m, 299792458.0 / (1575.42e6 if code == "C1C" else 1227.60e6))
    # outside the 2 h fit interval of the flag 0 (here 1.1 h from toe): no record
    late = sat_states_multi(nav, rec["toe"][0] + 3960.0, ["J02"])
    assert not late.valid[0]


def _matrtklib():
    d = DATA / MATRTKLIB
    if not (d / "base.nav").is_file():
        pytest.skip(f"{d} not found (the MatRTKLIB static pair; set INSNAV_SHARED_DATA)")
    return d


def _llh(p):
    lat, lon, h = np.loadtxt(p)
    return np.asarray(earth.geodetic_to_ecef(np.radians(lat), np.radians(lon), h), float).ravel()


def test_qzss_navigation_records_of_both_readers_and_qzs3_geostationary(monkeypatch):
    d = _matrtklib()
    nav = read_rinex_nav(d / "base.nav", systems="GRECJ")
    assert nav.systems == "GRECJ" and nav.eph_j.prn.tolist() == [2, 3, 7]
    assert np.all(nav.eph_j.health == 0) and np.all(nav.eph_j.fit_s == 7200.0)  # L1C/B bit masked; flag 0: 2 h
    assert read_rinex_nav(d / "base.nav", systems="GREC").skipped_by_system == {"J": 3}
    # the record loop (without the compiled scanner) reads the same table
    import insnav.gnss.rinex as rinex

    monkeypatch.setattr(rinex, "_nav_records_core", lambda *a, **k: None)
    slow = read_rinex_nav(d / "base.nav", systems="GRECJ")
    for k, v in nav.eph_j.to_columns().items():
        assert np.array_equal(v, getattr(slow.eph_j, k), equal_nan=True), k
    # J07 is QZS-3, geostationary over 127 deg E (a = 42 164 km, e ~ 0, i ~ 0)
    t = nav.eph_j.toe[2] + np.arange(-3600.0, 3601.0, 600.0)
    st = sat_states_multi(nav, t, ["J07"] * t.size)
    lat, lon, h = earth.ecef_to_geodetic(st.r_e)
    assert np.all(np.abs(np.degrees(lat)) < 0.5)
    assert np.all(np.abs(np.degrees(lon) - 127.0) < 0.5)
    assert np.all(np.abs(np.linalg.norm(st.r_e, axis=1) - 42_164e3) < 30e3)


def test_qzss_pseudoranges_agree_with_the_gps_receiver_clock():
    """Real QZSS L1 C/A code at the known antenna position, with the receiver clock taken from the GPS
    rows of each epoch: residuals at the metre level (a wrong time scale, orbit or clock would be km),
    which is what sharing the GPS clock in single point positioning rests on."""
    from insnav.gnss.spp import read_nav_multi, read_obs_multi, spp_inputs_from_rinex
    from insnav.gnss.weighting import Weighting

    d = _matrtklib()
    r_true = _llh(d / "rover_position.txt")
    obs, nav = read_obs_multi(d / "rover.obs", "GJ"), read_nav_multi(d / "base.nav", "GJ")
    inp, _ = spp_inputs_from_rinex(obs, nav, 0.0, r_true, weighting=Weighting(systems=["G", "J"]))
    s = inp.sats
    res = s[:, 0] - np.linalg.norm(s[:, 2:5] - r_true, axis=1) + s[:, 8]
    ep = np.searchsorted(np.asarray(inp.epoch_start), np.arange(res.size), side="right") - 1
    sysr = np.asarray(inp.system)
    clock = np.array([np.median(res[(ep == e) & (sysr == "G")]) for e in range(inp.epoch_t.size)])
    r = res - clock[ep]
    j = sysr == "J"
    assert j.sum() >= 2 * inp.epoch_t.size  # two QZSS satellites above the mask all along
    assert abs(np.mean(r[j])) < 1.5 and np.max(np.abs(r[j])) < 5.0
    assert np.std(r[j]) < np.std(r[sysr == "G"])


def test_spp_with_qzss_uses_the_gps_clock_and_improves_gps_alone(tmp_path):
    from insnav.filters.spp import run_spp_rinex

    d = _matrtklib()
    r_true = _llh(d / "rover_position.txt")
    err = {}
    for systems in (["G"], ["G", "J"]):
        sol = run_spp_rinex(d / "rover.obs", [d / "base.nav"], gnss=dict(systems=systems))
        sp = sol.spp
        err["".join(systems)] = np.median(np.linalg.norm(sp.r_e[sp.solved] - r_true, axis=1))
        if systems == ["G", "J"]:
            assert sol.summary["systems"] == "GJ"
            assert np.all(np.isnan(sp.isb_m[sp.solved][:, 1:]))  # no inter-system bias: J on the GPS clock
            n_used_gj = np.median(sp.n_used)
        else:
            n_used_g = np.median(sp.n_used)
    assert n_used_gj >= n_used_g + 2
    assert err["GJ"] < 3.0 and err["GJ"] < err["G"]  # 1.8 m against 4.3 m (GPS alone)
