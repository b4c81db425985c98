"""GLONASS / Galileo / BeiDou broadcast ephemerides, multi-system RINEX reading and the
multi-system entry point, checked against precise orbits/clocks, an ICD worked example, the
geostationary geometry of BeiDou GEOs and real observations."""

import numpy as np
import pytest

from insnav import earth
from insnav.gnss import RinexError, read_rinex_nav, read_rinex_obs, transmit_states
from insnav.gnss.broadcast import sat_states_multi, select_multi, transmit_states_multi
from insnav.gnss.ephemeris import C_LIGHT, select_ephemeris
from insnav.gnss.galbds import kepler_position_velocity
from insnav.gnss.glonass import glonass_integrate, glonass_position_velocity, gps_utc_leap_seconds
from insnav.gnss.gpstime import gps_seconds_from_calendar
from insnav.gnss.sp3 import read_rinex_clk, read_sp3

from conftest import SHARED_DATA as DATA

R3 = ("ephemeris_sp3_2021-118", "rinex3_2023-073")
SMARTLOC = "smartloc_berlin_potsdamer_platz"
WALK = "rtklibexplorer_walk_0827"


def need(*parts):
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"shared data not available: {p} (set INSNAV_SHARED_DATA)")
    return p


@pytest.fixture(scope="module")
def nav23():
    return read_rinex_nav(need(*R3, "BRDC00WRD_S_20230730000_01D_MN.rnx"), systems="GREC")


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------- reading
def test_mixed_rinex3_nav_all_systems(nav23):
    n = nav23
    assert (len(n.eph), len(n.eph_r), len(n.eph_e), len(n.eph_c)) == (4, 6, 38, 4)
    assert n.skipped_by_system == {"J": 4} and n.n_skipped == 4 and n.systems == "GREC"
    # GLONASS R01 00:15 UTC record: km -> m, channel +1; no LEAP SECONDS in the header -> 18 s (2023)
    i = np.flatnonzero(n.eph_r.prn == 1)[0]
    assert n.eph_r.tb[i] == gps_seconds_from_calendar(2023, 3, 14, 0, 15, 0.0) + 18.0
    assert n.eph_r.x[i] == pytest.approx(5763751.464844) and n.eph_r.vy[i] == pytest.approx(2693.783760071)
    assert n.eph_r.az[i] == pytest.approx(-2.793967723846e-6)
    assert n.eph_r.clock_bias[i] == pytest.approx(2.470612525940e-05)
    np.testing.assert_array_equal(n.eph_r.channel([1, 2, 3]), [1, -4, -99])
    # Galileo: I/NAV (517) and F/NAV (258) records, BGDs
    assert set(n.eph_e.data_source) == {517.0, 258.0}
    fnav = n.eph_e.data_source == 258
    assert np.all(n.eph_e.tgd2[fnav] == 0.0) and np.all(n.eph_e.tgd[fnav] != 0.0)
    # BeiDou: epochs in BDT -> GPS + 14 s, toe (BDT week 897, 172800 s) = toc here
    assert n.eph_c.toc[0] == gps_seconds_from_calendar(2023, 3, 14) + 14.0
    np.testing.assert_array_equal(n.eph_c.toe, n.eph_c.toc)
    assert n.eph_c.tgd[1] == pytest.approx(8.2e-9) and n.eph_c.tgd2[1] == pytest.approx(-1.4e-9)


def test_rinex2_glonass_nav_and_merge():
    g = read_rinex_nav(need(SMARTLOC, "brdc1580.16g"))
    assert g.leap_seconds == 17.0 and len(g.eph) == 0 and len(g.eph_r) > 500
    assert g.eph_r.tb[0] == gps_seconds_from_calendar(2016, 6, 6, 0, 15, 0.0) + 17.0
    assert g.eph_r.x[0] == pytest.approx(-6553426.26953) and g.eph_r.freq_k[0] == 1
    n = read_rinex_nav(need(SMARTLOC, "brdc1580.16n")).merge(g)
    assert n.systems == "GR" and len(n.eph_r) == len(g.eph_r)
    assert gps_utc_leap_seconds(gps_seconds_from_calendar(2016, 6, 6)) == 17.0
    assert gps_utc_leap_seconds(gps_seconds_from_calendar(2017, 1, 2)) == 18.0


NAV3_HEADER = (
    "     3.04           N: GNSS NAV DATA    M: MIXED            RINEX VERSION / TYPE\n"
    "    18                                                      LEAP SECONDS        \n"
    "                                                            END OF HEADER       \n"
)


def _record(nav_path, sat):
    """The record of ``sat`` (first line + continuation lines) from a real file."""
    lines = nav_path.read_text().splitlines(keepends=True)
    k = next(i for i, l in enumerate(lines) if l.startswith(sat))
    j = k + 1
    while j < len(lines) and lines[j][:1] == " ":
        j += 1
    return lines[k:j]


def test_rinex3_nav_bad_input(tmp_path):
    src = need(*R3, "BRDC00WRD_S_20230730000_01D_MN.rnx")
    e01, r01, c06 = _record(src, "E01"), _record(src, "R01"), _record(src, "C06")
    ok = read_rinex_nav(write(tmp_path, "ok.rnx", NAV3_HEADER + "".join(e01 + r01 + c06)), systems="GREC")
    assert (len(ok.eph_e), len(ok.eph_r), len(ok.eph_c)) == (1, 1, 1) and ok.leap_seconds == 18.0
    # truncated Galileo record followed by another record: the missing line is named
    with pytest.raises(RinexError, match=r"trunc\.rnx, line 11: bad record: broadcast orbit line 7 of E01 "
                                         r"\(record started on line 4\) missing"):
        read_rinex_nav(write(tmp_path, "trunc.rnx", NAV3_HEADER + "".join(e01[:7] + r01)), systems="E")
    # truncated at the end of the file
    with pytest.raises(RinexError, match=r"eof\.rnx, line 11: unexpected end of file while reading broadcast "
                                         r"orbit line 7 of C06"):
        read_rinex_nav(write(tmp_path, "eof.rnx", NAV3_HEADER + "".join(c06[:7])), systems="C")
    # an unknown system letter is skipped and counted; a record start that is no letter cannot be delimited
    x = "".join(e01).replace("E01", "X01", 1)
    n = read_rinex_nav(write(tmp_path, "x.rnx", NAV3_HEADER + x + "".join(r01)), systems="GREC")
    assert n.skipped_by_system == {"X": 1} and len(n.eph_r) == 1
    with pytest.raises(RinexError, match=r"bad\.rnx, line 4: bad record: cannot delimit the record"):
        read_rinex_nav(write(tmp_path, "bad.rnx", NAV3_HEADER + "".join(e01).replace("E01", "#01", 1)),
                       systems="E")
    # GLONASS: impossible frequency channel, bad number
    bad_k = "".join(r01).replace(" 1.000000000000e+00\n", "-9.000000000000e+00\n", 1)
    with pytest.raises(RinexError, match=r"k\.rnx, line 6: bad record: R01 record starting on line 4 has frequency channel -9"):
        read_rinex_nav(write(tmp_path, "k.rnx", NAV3_HEADER + bad_k), systems="R")
    bad_n = "".join(r01).replace("1.183432617188e+04", "1.18343261?188e+04")
    with pytest.raises(RinexError, match=r"n\.rnx, line 6: bad number '1\.18343261\?188e\+04'"):
        read_rinex_nav(write(tmp_path, "n.rnx", NAV3_HEADER + bad_n), systems="R")
    # a GLONASS-only file asked for GPS
    hdr_r = NAV3_HEADER.replace("M: MIXED ", "R: GLONASS")
    with pytest.raises(RinexError, match=r"line 1: a navigation file of system 'R' only, and the run uses the systems 'G'"):
        read_rinex_nav(write(tmp_path, "r.rnx", hdr_r + "".join(r01)))
    # Galileo week given as a GST week (GPS week - 1024) or BeiDou week as GPS week: same toe (resolved by toc)
    gst = "".join(e01).replace("2.253000000000e+03", "1.229000000000e+03")
    n_gst = read_rinex_nav(write(tmp_path, "gst.rnx", NAV3_HEADER + gst), systems="E")
    assert n_gst.eph_e.toe[0] == ok.eph_e.toe[0] and n_gst.eph_e.toe_sow[0] == 172200.0
    # RINEX 2 GLONASS: a truncated record names the record's start line
    g2 = need(SMARTLOC, "brdc1580.16g").read_text().splitlines(keepends=True)
    with pytest.raises(RinexError, match=r"g2\.16g, line 11: unexpected end of file while reading broadcast orbit "
                                         r"line 3 of R01 \(record started on line 8\)"):
        read_rinex_nav(write(tmp_path, "g2.16g", "".join(g2[:10])))
    with pytest.raises(ValueError, match="systems='GX'"):
        read_rinex_nav(write(tmp_path, "ok2.rnx", NAV3_HEADER), systems="GX")


OBS3 = """\
     3.04           OBSERVATION DATA    M: Mixed            RINEX VERSION / TYPE
G    4 C1C L1C D1C S1C                                      SYS / # / OBS TYPES
R    4 C1P L1P D1P S1P                                      SYS / # / OBS TYPES
E    4 C1X L1X D1X S1X                                      SYS / # / OBS TYPES
C    8 C6I L6I D6I S6I C2I L2I D2I S2I                      SYS / # / OBS TYPES
  2 R01  1 R02 -4                                           GLONASS SLOT / FRQ #
                                                            END OF HEADER
> 2023 03 14 00 00  0.0000000  0  4
G01  20000000.000   105000000.000       100.000          45.000
R02  21000000.000   112000000.000      -200.000          40.000
E11  22000000.000   115000000.000       300.000          41.000
C06  38000000.000   190000000.000       400.000          30.000    37000000.000   180000000.000       500.000          33.000
"""


def test_rinex3_obs_four_systems_and_bad_input(tmp_path):
    p = write(tmp_path, "o.rnx", OBS3)
    o = read_rinex_obs(p, systems="GREC")
    np.testing.assert_array_equal(o.sat_id, ["G01", "R02", "E11", "C06"])
    assert o.codes_by_system["R"]["C1"] == "C1P" and o.codes_by_system["E"]["D1"] == "D1X"
    assert o.codes_by_system["C"] == {"C1": "C2I", "L1": "L2I", "D1": "D2I", "S1": "S2I"}  # B1I before B3I
    np.testing.assert_array_equal(o.C1, [2.0e7, 2.1e7, 2.2e7, 3.7e7])
    np.testing.assert_array_equal(o.D1, [100.0, -200.0, 300.0, 500.0])
    assert o.glonass_channels == {1: 1, 2: -4}
    np.testing.assert_array_equal(o.pseudorange_code(), ["C1C", "C1P", "C1X", "C2I"])
    # wavelengths: GLONASS from the header's channel (R02: k = -4), BeiDou B1I
    np.testing.assert_allclose(o.wavelength_m(), C_LIGHT / np.array([1575.42e6, 1602e6 - 4 * 0.5625e6, 1575.42e6,
                                                                      1561.098e6]))
    # preference override: B3I
    o6 = read_rinex_obs(p, systems="C", codes={"C": ("C6I",)})
    assert o6.C1[0] == 3.8e7 and o6.S1[0] == 30.0
    # default stays GPS only
    assert list(read_rinex_obs(p).system) == ["G"]
    # missing observation types of a requested system: header line named
    bad = OBS3.replace("E    4 C1X L1X D1X S1X", "E    5 C1X L1X D1X S1X")
    with pytest.raises(RinexError, match=r"b\.rnx, line 4: malformed header: SYS / # / OBS TYPES of E announces "
                                         r"5 types, lists 4"):
        read_rinex_obs(write(tmp_path, "b.rnx", bad), systems="GE")
    assert read_rinex_obs(tmp_path / "b.rnx", systems="G").C1[0] == 2.0e7  # not asked for: not checked
    # observation of an undeclared system / truncated epoch
    with pytest.raises(RinexError, match=r"u\.rnx, line 12: bad record: satellite 'J01' of an undeclared"):
        read_rinex_obs(write(tmp_path, "u.rnx", OBS3.replace("C06 ", "J01 ")), systems="GREC")
    with pytest.raises(RinexError, match=r"t\.rnx, line 11: unexpected end of file while reading the satellites"):
        read_rinex_obs(write(tmp_path, "t.rnx", "\n".join(OBS3.splitlines()[:10]) + "\n"), systems="GREC")


def test_rinex2_mixed_obs_glonass_doppler_fdma():
    """smartLoc RINEX 2.11 G+R: Doppler -> range rate with each GLONASS satellite's FDMA wavelength.

    Against the ground-truth trajectory (velocity by central differences), per-epoch GPS receiver
    drift removed: the per-satellite median residual of GLONASS is near zero with the FDMA
    wavelengths and clearly biased (tenths of m/s, proportional to k * range rate) with a common
    k = 0 wavelength -- a check that the channel of each satellite is the right one.
    """
    obs = read_rinex_obs(need(SMARTLOC, "Berlin_Potsdamer_Platz.obs"), systems="GR")
    assert set(obs.system) == {"G", "R"} and obs.codes_by_system["R"]["C1"] == "C1"
    nav = read_rinex_nav(need(SMARTLOC, "brdc1580.16n")).merge(read_rinex_nav(need(SMARTLOC, "brdc1580.16g")))
    gt = np.array([[float(x) for x in ln.split()[1:5]]
                   for ln in need(SMARTLOC, "Berlin_Potsdamer_Platz_GT.txt").read_text().splitlines()
                   if ln.startswith("point3")])
    t_rel = obs.t_gps_s - obs.epoch_t_gps_s[0]
    j = np.clip(np.searchsorted(gt[:, 0], t_rel), 1, len(gt) - 2)
    r = gt[j, 1:4]
    v = (gt[j + 1, 1:4] - gt[j - 1, 1:4]) / (gt[j + 1, 0] - gt[j - 1, 0])[:, None]
    ts = transmit_states_multi(nav, obs.t_gps_s, r, system=obs.system, prn=obs.prn, codes=obs.pseudorange_code())
    assert ts.valid.mean() > 0.95
    np.testing.assert_array_equal(obs.wavelength_m(nav)[ts.valid], ts.wavelength_m[ts.valid])
    d = ts.r_e - r
    u = d / np.linalg.norm(d, axis=1)[:, None]
    model = np.sum(u * (ts.v_e - v), axis=1) - ts.clock_drift_mps
    glo = obs.system == "R"

    def per_sat_medians(lam):
        rr = -lam * obs.D1 - model
        res = rr.copy()
        for e in np.unique(obs.epoch):
            k = (obs.epoch == e) & ts.valid
            res[k] -= np.nanmedian(rr[k & ~glo])
        out = []
        for p in np.unique(obs.prn[glo]):
            k = glo & (obs.prn == p) & np.isfinite(res)
            if k.sum() > 50:
                out.append(np.median(res[k]))
        return np.abs(out)

    good = per_sat_medians(ts.wavelength_m)
    lam0 = np.where(glo, C_LIGHT / 1602.0e6, ts.wavelength_m)
    wrong = per_sat_medians(lam0)
    assert good.size >= 6
    assert good.mean() < 0.15 and good.max() < 0.3  # measured 0.07 / 0.21 m/s
    assert wrong.mean() > 0.3  # measured 0.49 m/s


# --------------------------------------------------------------------- GLONASS orbit
def test_glonass_rk4_icd_example():
    """GLONASS CDMA ICD (2016) Appendix J worked example, t_b = 11700 s -> t_i = 12300 s.

    The published result (x, y, z) = (7523.174853, -10506.962176, 21999.239866) km, (vx, vy, vz)
    = (0.95012609, 2.85568710, 1.04068137) km/s is reproduced to ~1 cm / 4e-5 m/s by RK4 when the
    example's luni-solar accelerations (0, 1.7e-9, -5.41e-9) km/s^2 are not applied; applying them
    moves the result by 1/2 a dt^2 (0.31 m in y, 0.97 m in z), as gnsstk and INSTINCT find against
    the same example.  Step size 60 s vs 1 s: < 1 mm.
    """
    s0 = np.array([[7003.008789e3, -12206.626953e3, 21280.765625e3, 0.7835417e3, 2.8042530e3, 1.3525150e3]])
    ref = np.array([7523.174853e3, -10506.962176e3, 21999.239866e3, 0.95012609e3, 2.85568710e3, 1.04068137e3])
    s60 = glonass_integrate(s0, np.zeros((1, 3)), 600.0, 60.0)[0]
    assert np.linalg.norm(s60[:3] - ref[:3]) < 0.02 and np.linalg.norm(s60[3:] - ref[3:]) < 1e-4
    s1 = glonass_integrate(s0, np.zeros((1, 3)), 600.0, 1.0)[0]
    assert np.linalg.norm(s60[:3] - s1[:3]) < 1e-3
    a = np.array([[0.0, 1.7e-6, -5.41e-6]])
    sa = glonass_integrate(s0, a, 600.0, 60.0)[0]
    np.testing.assert_allclose(sa[:3] - s60[:3], 0.5 * a[0] * 600.0**2, atol=0.01)
    # backwards integration returns to the start
    back = glonass_integrate(sa[None, :], a, -600.0, 60.0)[0]
    assert np.linalg.norm(back[:3] - s0[0, :3]) < 1e-3 and np.linalg.norm(back[3:] - s0[0, 3:]) < 1e-6


def test_glonass_rk4_step_convergence_on_real_records(nav23):
    e = nav23.eph_r
    idx = np.arange(len(e))
    t = e.tb + 900.0  # the end of the ICD validity interval
    r60, v60 = glonass_position_velocity(e, idx, t, step_s=60.0)
    r1, v1 = glonass_position_velocity(e, idx, t, step_s=1.0)
    assert np.max(np.linalg.norm(r60 - r1, axis=1)) < 1e-3
    assert np.max(np.linalg.norm(v60 - v1, axis=1)) < 1e-6


# --------------------------------------------------------------------- vs precise products
def _compare_sp3(nav, sp3, clk, sats):
    t = sp3.t_gps_s
    out = {}
    for sat in sats:
        st = sat_states_multi(nav, t, [sat] * t.size, relativistic=False, group_delay=False)
        j = sp3.index(sat)
        err = np.linalg.norm(st.r_e - sp3.r_e[:, j], axis=1)
        ck = C_LIGHT * (st.clock_bias_s - clk.clock(sat, t)) if sat in clk.sats else np.full(t.size, np.nan)
        out[sat] = (st.valid, err, ck)
    return out


def test_orbits_and_clocks_vs_code_rapid_2023(nav23):
    """Broadcast G/R/E vs CODE rapid SP3 (00:00-00:10) and CLK (00:00), 2023-03-14.

    Measured 3-D orbit errors: G 0.7-1.5 m, E 0.8-0.9 m, R 2.8-3.4 m.  Clocks: SP3/CLK clocks refer
    to the ionosphere-free combination and to a GPS-based time scale, so each system has a common
    offset (E -2.2 m, R +6.3 m here); after removing it the spread is G 0.05 m, E 0.1 m, R 1.6 m
    (GLONASS inter-frequency biases).
    """
    sp3 = read_sp3(need(*R3, "COD0OPSRAP_20230730000_01D_05M_ORB.SP3"))
    clk = read_rinex_clk(need(*R3, "COD0OPSRAP_20230730000_01D_30S_CLK.CLK"))
    res = _compare_sp3(nav23, sp3, clk, ["G01", "G02", "R01", "R02", "E01", "E02"])
    bound_orbit = {"G": 3.0, "E": 2.5, "R": 8.0}
    bound_clock_spread = {"G": 1.0, "E": 1.0, "R": 5.0}
    for s in "GRE":
        valid = np.concatenate([v[0] for k, v in res.items() if k[0] == s])
        err = np.concatenate([v[1] for k, v in res.items() if k[0] == s])
        ck = np.concatenate([v[2] for k, v in res.items() if k[0] == s])
        assert valid.all()
        assert err.max() < bound_orbit[s], (s, err)
        ck = ck[np.isfinite(ck)]
        assert ck.size >= 2 and np.std(ck) < bound_clock_spread[s], (s, ck)
        assert abs(np.mean(ck)) < 20.0  # system time / datum offset: metres, not microseconds


def test_velocity_and_drift_vs_finite_difference_all_systems(nav23):
    walk = read_rinex_nav(need(WALK, "rinex_derived", "gnss_1730.nav"), systems="GREC")
    smart = read_rinex_nav(need(SMARTLOC, "BRDC00WRD_U_20161580000_01D_MN.rnx"), systems="GREC")
    # times away from the midpoints between records (where the selected record changes)
    cases = [(nav23, "G01", nav23.eph.toe[0] - 3000.0), (nav23, "R01", nav23.eph_r.tb[0] + 500.0),
             (nav23, "E02", nav23.eph_e.toe[2] + 820.0), (nav23, "C06", nav23.eph_c.toe[1] + 700.0),
             (walk, "C22", walk.eph_c.toe[walk.eph_c.prn == 22][0] + 60.0),
             (smart, "C01", smart.eph_c.toe[smart.eph_c.prn == 1][0] + 1800.0),
             (smart, "C05", smart.eph_c.toe[smart.eph_c.prn == 5][0] - 1800.0)]
    h = 0.5
    for nav, sat, t in cases:
        st = sat_states_multi(nav, [t - h, t, t + h], [sat] * 3)
        assert st.valid.all(), sat
        v_fd = (st.r_e[2] - st.r_e[0]) / (2 * h)
        assert np.linalg.norm(st.v_e[1] - v_fd) < 2e-3, (sat, st.v_e[1] - v_fd)
        d_fd = (st.clock_bias_s[2] - st.clock_bias_s[0]) / (2 * h)
        assert abs(st.clock_drift_s_s[1] - d_fd) < 1e-14, sat


# --------------------------------------------------------------------- BeiDou GEO
#: published orbital slots of the BDS-2 GEOs in 2016 [deg E] (CSNO, BDS constellation status)
_GEO_SLOTS = {1: 140.0, 2: 80.0, 3: 110.5, 4: 160.0, 5: 58.75}


def test_beidou_geo_is_geostationary():
    """BDS GEO transform (BDS-SIS-ICD-B1I 3.0 Table 5-11) on the smartLoc 2016 broadcast records.

    Each GEO must sit at |r| = 42164 km +- 50 km, within 3 deg of the equator and 0.5 deg of its
    slot, with an ECEF speed below 100 m/s (a 1-2 deg inclination gives up to ~90 m/s north-south;
    treating the GEO as a MEO, i.e. without the -5 deg / Omega_e t_k rotations, gives km/s and a
    wrong longitude -- checked too).
    """
    nav = read_rinex_nav(need(SMARTLOC, "BRDC00WRD_U_20161580000_01D_MN.rnx"), systems="C")
    seen = 0
    for prn, slot in _GEO_SLOTS.items():
        rows = np.flatnonzero(nav.eph_c.prn == prn)
        assert rows.size, prn
        t = nav.eph_c.toe[rows[0]] + np.array([-1800.0, 0.0, 1800.0])
        st = sat_states_multi(nav, t, [f"C{prn:02d}"] * 3)
        assert st.valid.all()
        for r, v in zip(st.r_e, st.v_e):
            lat, lon, _ = earth.ecef_to_geodetic(r)
            assert abs(np.linalg.norm(r) - 42164.0e3) < 50.0e3, prn
            assert abs(np.degrees(lat)) < 3.0, prn
            assert abs(np.degrees(lon) - slot) < 0.5, (prn, np.degrees(lon))
            assert np.linalg.norm(v) < 100.0, (prn, np.linalg.norm(v))
        # the MEO formula on the same record: not geostationary
        from insnav.gnss.ephemeris import sat_position_velocity
        from insnav.gnss.galbds import GM_BDS, OMEGA_E_BDS

        pv = sat_position_velocity(nav.eph_c, np.repeat(rows[:1], 3), t, gm=GM_BDS, omega_e=OMEGA_E_BDS)
        assert np.max(np.linalg.norm(pv.r_e - st.r_e, axis=1)) > 1000.0e3, prn
        seen += 1
    assert seen == 5
    # kepler_position_velocity dispatches GEO rows to the GEO transform
    idx = np.flatnonzero(np.isin(nav.eph_c.prn, [1, 11]))[:2]
    pv = kepler_position_velocity(nav.eph_c, idx, nav.eph_c.toe[idx], "C")
    assert np.linalg.norm(pv.v_e[nav.eph_c.prn[idx] == 1][0]) < 100.0


# --------------------------------------------------------------------- the entry point
def test_entry_point_gps_bit_identical_and_light_time(nav23):
    nav = read_rinex_nav(need("ephemeris_sp3_2021-118", "brdc1180.21n"))
    t = gps_seconds_from_calendar(2021, 4, 28, 20, 0, 0.0) + np.arange(5) * 30.0
    prn = np.array([1, 3, 6, 8, 14])
    r_rx = np.array([4027893.9, 307045.6, 4919474.9])
    ref = transmit_states(nav.eph, select_ephemeris(nav.eph, prn, t), t, r_rx, tgd=True)
    got = nav.transmit_states(t, r_rx, [f"G{p:02d}" for p in prn])
    for a, b in ((got.r_e, ref.r_e), (got.v_e, ref.v_e), (got.clock_bias_s, ref.clock_bias_s),
                 (got.clock_drift_s_s, ref.clock_drift_s_s), (got.tau_s, ref.tau_s), (got.range_m, ref.range_m)):
        np.testing.assert_array_equal(a, b)
    # all systems: the range equals c tau (light time solved) and rows without a record are flagged
    t2 = gps_seconds_from_calendar(2023, 3, 14, 0, 5, 0.0)
    ids = ["G01", "R01", "R02", "E01", "E02", "C06", "G30", "R24"]
    ts = nav23.transmit_states(t2, r_rx, ids)
    np.testing.assert_array_equal(ts.valid, [True] * 6 + [False, False])
    np.testing.assert_allclose(ts.range_m[:6], C_LIGHT * ts.tau_s[:6], rtol=0, atol=1e-6)
    assert np.all(np.isnan(ts.r_e[6:])) and np.all(ts.eph_idx[6:] == -1)
    # GLONASS wavelength from the FDMA channel (R01 k=+1, R02 k=-4)
    np.testing.assert_allclose(ts.wavelength_m[1:3], C_LIGHT / (1602e6 + np.array([1, -4]) * 0.5625e6))
    # GLONASS clock: no relativistic term, -tau_n + gamma_n (t - t_b)
    i = ts.eph_idx[1]
    assert ts.clock_bias_s[1] == pytest.approx(nav23.eph_r.clock_bias[i] + nav23.eph_r.gamma_n[i]
                                               * (ts.t_tx_gps_s[1] - nav23.eph_r.tb[i]), abs=1e-15)


def test_group_delays_and_galileo_message_choice(nav23):
    t = gps_seconds_from_calendar(2023, 3, 14, 0, 5, 0.0)
    e = nav23.eph_e
    r_rx = np.array([4027893.9, 307045.6, 4919474.9])
    k = {}
    for code in ("C1C", "C5Q", "C7Q"):
        idx = select_multi(nav23, ["E"], [1], t, codes=[code])[0]
        k[code] = idx
        st = nav23.transmit_states(t, r_rx, ["E01"], codes={"E": code})
        nogd = nav23.transmit_states(t, r_rx, ["E01"], codes={"E": code}, group_delay=False)
        gd = nogd.clock_bias_s[0] - st.clock_bias_s[0]
        if code == "C1C":  # I/NAV, BGD(E1,E5b)
            assert e.data_source[idx] == 517 and gd == pytest.approx(e.tgd2[idx], abs=1e-18)
        elif code == "C5Q":  # F/NAV, (f1/f5a)^2 BGD(E1,E5a)
            assert e.data_source[idx] == 258 and gd == pytest.approx((1575.42 / 1176.45) ** 2 * e.tgd[idx], abs=1e-18)
        else:  # I/NAV, (f1/f5b)^2 BGD(E1,E5b)
            assert e.data_source[idx] == 517 and gd == pytest.approx((1575.42 / 1207.14) ** 2 * e.tgd2[idx], abs=1e-18)
    # BeiDou: B1I -> T_GD1, B2I -> T_GD2, B3I -> none
    c = nav23.eph_c
    for code, expect in (("C2I", "tgd"), ("C7I", "tgd2"), ("C6I", None)):
        st = nav23.sat_states(t, ["C06"], codes={"C": code})
        i = st.eph_idx[0]
        assert st.group_delay_s[0] == (0.0 if expect is None else getattr(c, expect)[i])
    # GPS: L1 -> T_GD, L2 -> gamma T_GD
    g1 = nav23.sat_states(t + 7200.0, ["G01"], codes={"G": "C1C"})
    g2 = nav23.sat_states(t + 7200.0, ["G01"], codes={"G": "C2W"})
    assert g2.group_delay_s[0] == pytest.approx((77.0 / 60.0) ** 2 * g1.group_delay_s[0], rel=1e-12)
    assert g1.group_delay_s[0] == nav23.eph.tgd[g1.eph_idx[0]] != 0.0
    with pytest.raises(ValueError, match="C5X"):
        nav23.sat_states(t, ["C06"], codes={"C": "C5X"})


def test_tight_inputs_multi_system_on_real_walk():
    """walk_0827 (u-blox, GPS L1 C/A + Galileo E1 + BeiDou B3I): residuals against the RTK reference.

    GPS-only stays identical; with systems="GEC" each system's pseudorange residual (per-epoch GPS
    clock removed) has a std of 4-6 m (measured G 4.0, E 5.7, C 5.1 m) and its Doppler residual a
    std of 0.2-0.3 m/s with a median near 0 -- the signs, wavelengths and the BeiDou/Galileo
    satellite velocities are right.
    """
    from insnav.io.gnss_files import read_rtklib_pos
    from insnav.gnss.tight_inputs import tight_inputs_from_rinex

    obs = read_rinex_obs(need(WALK, "rinex_derived", "gnss_1730.obs"), systems="GREC")
    obs_g = read_rinex_obs(need(WALK, "rinex_derived", "gnss_1730.obs"))
    nav = read_rinex_nav(need(WALK, "rinex_derived", "gnss_1730.nav"), systems="GREC")
    t0 = np.floor(obs.epoch_t_gps_s[0] / 604800.0) * 604800.0
    a = tight_inputs_from_rinex(obs_g, nav, t0, obs.approx_r_e)
    b = tight_inputs_from_rinex(obs, nav, t0, obs.approx_r_e)
    np.testing.assert_array_equal(a.sats, b.sats)
    assert set(b.system) == {"G"}
    m = tight_inputs_from_rinex(obs, nav, t0, obs.approx_r_e, systems="GEC", max_sats=99)
    n_sys = {s: int((m.system == s).sum()) for s in "GEC"}
    assert n_sys["E"] > 1000 and n_sys["C"] > 1000
    pos = read_rtklib_pos(need(WALK, "raw", "gnss_1730_sf.pos"))
    t = m.epoch_t[m.row_epoch] + t0
    j = np.clip(np.searchsorted(pos.t_gps_s, t - 0.01), 0, pos.t_gps_s.size - 1)
    d = m.sats[:, 2:5] - pos.r_e[j]
    rng = np.linalg.norm(d, axis=1)
    u = d / rng[:, None]
    pr = m.sats[:, 0] - (rng - m.sats[:, 8])
    rr = m.sats[:, 1] - (np.sum(u * (m.sats[:, 5:8] - pos.v_e[j]), axis=1) - m.sats[:, 9])
    for e in np.unique(m.row_epoch):
        k = m.row_epoch == e
        g = k & (m.system == "G")
        pr[k] -= np.median(pr[g]) if g.any() else np.nan
        rr[k] -= np.median(rr[g]) if g.any() else np.nan
    for s in "GEC":
        k = (m.system == s) & np.isfinite(pr)
        assert np.std(pr[k]) < 8.0, s
        assert abs(np.median(pr[k])) < 10.0, s  # inter-system bias: metres
        kr = k & np.isfinite(rr)
        assert np.std(rr[kr]) < 0.5 and abs(np.median(rr[kr])) < 0.05, s


# --------------------------------------------------------------------- compiled orbits
def _both_paths(monkeypatch, fn):
    """fn() with the compiled orbit code, then with the numpy reference (the compiled functions hidden)."""
    import types

    from insnav.gnss import broadcast, ephemeris

    got = fn()
    with monkeypatch.context() as m:
        m.setattr(broadcast, "_core", types.SimpleNamespace())
        m.setattr(ephemeris, "_core", types.SimpleNamespace())
        ref = fn()
    return got, ref


def _assert_states_close(got, ref):
    """Positions to 1 um, velocities to 1 nm/s, clocks to 1e-17 s (1e-8 m), light time to 1e-12 s (its
    convergence tolerance: the numpy iteration evaluates the orbit at t_rx - tau in GPS seconds since 1980,
    resolved to 2.4e-7 s)."""
    np.testing.assert_array_equal(got.valid, ref.valid)
    np.testing.assert_allclose(got.r_e, ref.r_e, rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.v_e, ref.v_e, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.clock_bias_s, ref.clock_bias_s, rtol=0, atol=1e-17)
    np.testing.assert_allclose(got.clock_drift_s_s, ref.clock_drift_s_s, rtol=0, atol=1e-20)
    np.testing.assert_allclose(got.tau_s, ref.tau_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.range_m, ref.range_m, rtol=0, atol=1e-6)


def test_compiled_transmit_states_equal_the_numpy_reference(nav23, monkeypatch):
    """insnav/gnss/broadcast_orbit.hpp against the numpy code of ephemeris / galbds / glonass: the
    satellites of the 2023 mixed file (2 per system: GPS, GLONASS, Galileo, BeiDou) over 4 h, and the five
    BeiDou GEOs of the 2016 file (Table 5-11 transform)."""
    t0 = gps_seconds_from_calendar(2023, 3, 14, 0, 5, 0.0)
    ids = [f"{s}{p:02d}" for s, n in (("G", 32), ("R", 24), ("E", 36), ("C", 46)) for p in range(1, n + 1)]
    t = np.repeat(t0 + np.arange(0.0, 4 * 3600.0, 900.0), len(ids))
    ids_all = np.tile(ids, t.size // len(ids))
    r_rx = np.array([4027893.9, 307045.6, 4919474.9])
    got, ref = _both_paths(monkeypatch, lambda: nav23.transmit_states(t, r_rx, ids_all))
    assert got.valid.sum() > 50 and set(np.unique(got.system[got.valid])) == {"G", "R", "E", "C"}
    _assert_states_close(got, ref)
    nav16 = read_rinex_nav(need(SMARTLOC, "BRDC00WRD_U_20161580000_01D_MN.rnx"), systems="C")
    ids16, t16 = [], []
    for prn in list(_GEO_SLOTS) + [6, 11]:  # the GEOs, an IGSO and a MEO
        toe = nav16.eph_c.toe[np.flatnonzero(nav16.eph_c.prn == prn)[0]]
        ids16 += [f"C{prn:02d}"] * 3
        t16 += list(toe + np.array([-1800.0, 0.0, 1800.0]))
    got, ref = _both_paths(monkeypatch, lambda: nav16.transmit_states(np.array(t16), r_rx, ids16))
    assert got.valid.all()
    _assert_states_close(got, ref)
