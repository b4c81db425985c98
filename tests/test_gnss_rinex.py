"""RINEX / SP3 / CLK readers: real files and malformed temp files."""

import numpy as np
import pytest

from insnav.gnss import RinexError, read_rinex_nav, read_rinex_obs
from insnav.gnss.gpstime import gps_seconds_from_calendar, week_tow
from insnav.gnss.sp3 import read_rinex_clk, read_sp3

from conftest import SHARED_DATA as DATA  # ../shared/data beside the repo, or $INSNAV_SHARED_DATA


def need(*parts):
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"shared data not available: {p} (set INSNAV_SHARED_DATA or put ../shared/data beside the repo)")
    return p


# --------------------------------------------------------------------- synthetic files
NAV2_HEADER = (
    "     2              NAVIGATION DATA                         RINEX VERSION / TYPE\n"
    "    0.9313D-08  0.1490D-07 -0.5960D-07 -0.1192D-06          ION ALPHA           \n"
    "    0.8806D+05  0.4915D+05 -0.1311D+06 -0.3277D+06          ION BETA            \n"
    "                                                            END OF HEADER       \n"
)
NAV2_RECORD = (
    " 6 21  4 28 17 59 44.0 0.109337270260D-04 0.329691829393D-11 0.000000000000D+00\n"
    "    0.310000000000D+02-0.968750000000D+02 0.369765402213D-08 0.256518534901D+00\n"
    "   -0.510737299919D-05 0.225707876962D-02 0.122226774692D-04 0.515375527000D+04\n"
    "    0.323984000000D+06 0.167638063431D-07-0.294507412083D+01-0.298023223877D-07\n"
    "    0.983895632254D+00 0.158375000000D+03-0.983603167134D+00-0.758853037846D-08\n"
    "   -0.732173355102D-10 0.100000000000D+01 0.215500000000D+04 0.000000000000D+00\n"
    "    0.200000000000D+01 0.000000000000D+00 0.419095158577D-08 0.310000000000D+02\n"
    "    0.322932000000D+06 0.400000000000D+01 0.000000000000D+00 0.000000000000D+00\n"
)


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_nav2_synthetic_parses_d_exponents(tmp_path):
    nav = read_rinex_nav(write(tmp_path, "ok.21n", NAV2_HEADER + NAV2_RECORD))
    e = nav.eph
    assert len(e) == 1 and e.prn[0] == 6
    assert e.sqrt_a[0] == pytest.approx(5153.75527)
    assert e.e[0] == pytest.approx(0.225707876962e-2)
    assert e.toc[0] == gps_seconds_from_calendar(2021, 4, 28, 17, 59, 44.0)
    assert week_tow(e.toe[0]) == (2155, 323984.0)
    assert e.fit_s[0] == 4 * 3600.0
    np.testing.assert_allclose(nav.ion_alpha, [0.9313e-8, 0.1490e-7, -0.5960e-7, -0.1192e-6])
    np.testing.assert_allclose(nav.ion_beta, [0.8806e5, 0.4915e5, -0.1311e6, -0.3277e6])


def test_nav_malformed_header_names_line(tmp_path):
    bad = NAV2_HEADER.replace("0.1490D-07", "0.14x0D-07")
    with pytest.raises(RinexError, match=r"line 2: bad number '0\.14x0D-07' for ION ALPHA") as ei:
        read_rinex_nav(write(tmp_path, "badhdr.21n", bad))
    assert ei.value.line == 2 and "badhdr.21n" in str(ei.value)
    with pytest.raises(RinexError, match="line 1: malformed header"):
        read_rinex_nav(write(tmp_path, "nover.21n", "garbage\n" + NAV2_HEADER))
    with pytest.raises(RinexError, match=r"line 4: unexpected end of file while reading the header"):
        read_rinex_nav(write(tmp_path, "noend.21n", "".join(NAV2_HEADER.splitlines(keepends=True)[:3])))


def test_nav_malformed_record_names_line(tmp_path):
    lines = NAV2_RECORD.splitlines(keepends=True)
    lines[2] = lines[2].replace("0.122226774692D-04", "0.12222677469?D-04")
    with pytest.raises(RinexError, match=r"line 7: bad number '0\.12222677469\?D-04'") as ei:
        read_rinex_nav(write(tmp_path, "badrec.21n", NAV2_HEADER + "".join(lines)))
    assert ei.value.line == 7
    # truncated record: unexpected end of file, with the record's start line
    trunc = NAV2_HEADER + "".join(NAV2_RECORD.splitlines(keepends=True)[:5])
    with pytest.raises(RinexError, match=r"line 10: unexpected end of file .*record started on line 5"):
        read_rinex_nav(write(tmp_path, "trunc.21n", trunc))
    # garbage epoch
    with pytest.raises(RinexError, match=r"line 5: bad integer .xx. for satellite number"):
        read_rinex_nav(write(tmp_path, "badep.21n", NAV2_HEADER + "xx" + NAV2_RECORD[2:]))


def assert_same_nav(a, b):
    """Every table of two NavData the same to the last bit (NaN where NaN)."""
    import dataclasses

    for name in ("eph", "eph_r", "eph_e", "eph_c"):
        x, y = getattr(a, name), getattr(b, name)
        for f in dataclasses.fields(x):
            u, v = getattr(x, f.name), getattr(y, f.name)
            if isinstance(u, np.ndarray):
                assert u.dtype == v.dtype, (name, f.name)
                np.testing.assert_array_equal(u, v, err_msg=f"{name}.{f.name}")
            else:
                assert u == v, (name, f.name)
    for name in ("version", "n_skipped", "skipped_by_system", "leap_seconds"):
        assert getattr(a, name, None) == getattr(b, name, None), name
    for name in ("ion_alpha", "ion_beta"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def _nav_python(path, systems):
    """read_rinex_nav through its record loop alone (the compiled scanner switched off)."""
    from insnav.gnss import rinex

    saved = rinex._nav_records_core
    rinex._nav_records_core = lambda *a: None
    try:
        return read_rinex_nav(path, systems=systems)
    finally:
        rinex._nav_records_core = saved


@pytest.mark.parametrize("parts", [
    ("smartloc_berlin_potsdamer_platz", "brdc1580.16n"),  # RINEX 2 GPS
    ("smartloc_berlin_potsdamer_platz", "brdc1580.16g"),  # RINEX 2 GLONASS
    ("smartloc_berlin_potsdamer_platz", "BRDC00WRD_U_20161580000_01D_MN.rnx"),
    ("euref_wettzell_wtzr_wtzz", "ESBC00DNK_R_20201770000_01D_MN.rnx"),
    ("rtklibexplorer_walk_0827", "rinex_derived", "gnss_1730.nav"),
    ("matrtklib_static_septentrio", "base.nav"),
    ("instinct_spirent_rtk_dynamic_SIMULATED", "RINEX_GN_Spirent.23N"),
])
def test_nav_real_files_compiled_equal_python_reference(parts):
    """The compiled record scanner (insnav/io/rinex_nav.hpp) gives the record loop's tables to the last bit."""
    from insnav import _core

    p = need(*parts)
    for systems in ("G", "GREC"):
        a = read_rinex_nav(p, systems=systems)
        assert_same_nav(a, _nav_python(p, systems))
        assert len(a.eph) + len(a.eph_r) + len(a.eph_e) + len(a.eph_c) > 0
    body_from = next(i for i, ln in enumerate(p.read_text().splitlines()) if "END OF HEADER" in ln) + 1
    body = "\n".join(p.read_text().splitlines()[body_from:])
    assert _core.scan_rinex_nav_body(body, a.version >= 3, "16g" in p.name, "GREC") is not None  # no fallback


def test_nav_compiled_scanner_leaves_odd_records_to_the_python_loop(tmp_path):
    """Blank fields, a blank line, lower-case and D exponents: read by the scanner, the same tables; a bad
    number, a truncated record, sqrt(A) <= 0: the scanner gives up and the loop names the line."""
    from insnav import _core

    lines = NAV2_RECORD.splitlines(keepends=True)
    odd = lines[:]
    odd[3] = odd[3].replace("0.167638063431D-07", "                  ")  # blank field
    odd[4] = odd[4].replace("0.983895632254D+00", "0.983895632254d+00").replace("0.158375000000D+03",
                                                                                "0.158375000000E+03")
    text = NAV2_HEADER + "".join(odd) + "\n" + NAV2_RECORD.replace(" 6 21", "12 21", 1)
    p = write(tmp_path, "odd.21n", text)
    assert _core.scan_rinex_nav_body("\n".join(text.splitlines()[4:]), False, False, "G") is not None
    a = read_rinex_nav(p)
    assert_same_nav(a, _nav_python(p, "G"))
    assert a.eph.prn.tolist() == [6, 12]
    assert a.eph.cic[0] == 0.0 and a.eph.i0[0] == 0.983895632254 and a.eph.crc[0] == 158.375
    bad = lines[:]
    bad[2] = bad[2].replace("0.122226774692D-04", "0.12222677469?D-04")
    body = "\n".join((NAV2_HEADER + "".join(bad)).splitlines()[4:])
    assert _core.scan_rinex_nav_body(body, False, False, "G") is None
    with pytest.raises(RinexError, match=r"line 7: bad number '0\.12222677469\?D-04'"):
        read_rinex_nav(write(tmp_path, "bad.21n", NAV2_HEADER + "".join(bad)))
    neg = NAV2_RECORD.replace("0.515375527000D+04", "-.515375527000D+04")
    with pytest.raises(RinexError, match=r"line \d+: bad record: G06 record starting on line 5 has sqrt\(A\) <= 0"):
        read_rinex_nav(write(tmp_path, "neg.21n", NAV2_HEADER + neg))


def _obs2(types, sats_obs, t=(21, 4, 28, 18, 0, 0.0), flag=0, clk="  .000123456"):
    """Build a RINEX 2.11 observation file (one epoch + an event epoch)."""
    h = ["     2.11           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE"]
    for k in range(0, len(types), 9):
        chunk = types[k:k + 9]
        n = f"{len(types):6d}" if k == 0 else " " * 6
        h.append((n + "".join(f"{c:>6s}" for c in chunk)).ljust(60) + "# / TYPES OF OBSERV")
    h.append(" " * 60 + "END OF HEADER")
    sats = list(sats_obs)
    ep = f" {t[0]:02d} {t[1]:2d} {t[2]:2d} {t[3]:2d} {t[4]:2d}{t[5]:11.7f}  {flag}{len(sats):3d}"
    body = []
    for k in range(0, len(sats), 12):
        ids = "".join(sats[k:k + 12])
        head = ep if k == 0 else " " * 32
        line = (head + ids).ljust(68)
        if k == 0:
            line += clk
        body.append(line)
    for s in sats:
        vals = sats_obs[s]
        for k in range(0, len(types), 5):
            body.append("".join("" .ljust(16) if v is None else f"{v:14.3f}  " for v in vals[k:k + 5]).rstrip())
    # an event epoch (flag 4) with one special record, then a second normal epoch
    body.append(" 21  4 28 18  0  1.0000000  4  1")
    body.append("THIS IS A COMMENT".ljust(60) + "COMMENT")
    return "\n".join(h + body) + "\n"


def test_obs2_continuations_and_missing(tmp_path):
    types = ["C1", "L1", "D1", "S1", "P2", "L2", "C2", "S2", "D2", "C5"]  # 10 types: 2 header lines, 2 obs lines
    sats = {}
    for k in range(13):  # 13 satellites: two satellite-list lines
        sid = f"G{k + 1:2d}" if k != 5 else "R07"
        vals = [2.0e7 + k, 1.0e8 + k, -100.0 - k, 40.0 + k, None, None, None, None, None, 1.0]
        sats[sid] = vals
    sats["G 1"][2] = None  # missing Doppler
    text = _obs2(types, sats)
    obs = read_rinex_obs(write(tmp_path, "o.21o", text))
    assert obs.codes == {"C1": "C1", "L1": "L1", "D1": "D1", "S1": "S1"}
    assert obs.epoch_t_gps_s.size == 1
    assert obs.clock_offset_s[0] == pytest.approx(0.000123456)
    assert list(obs.prn) == [1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12, 13]  # R07 skipped
    assert obs.C1[0] == 2.0e7 and obs.C1[-1] == 2.0e7 + 12
    assert np.isnan(obs.D1[0]) and obs.D1[1] == -101.0
    assert obs.S1[5] == 46.0
    wk, tow = week_tow(gps_seconds_from_calendar(2021, 4, 28, 18, 0, 0.0))
    assert obs.week[0] == wk and obs.tow[0] == tow
    # malformed observation value -> line number of that line
    bad = text.replace(f"{1.0e8 + 3:14.3f}", "   1e8x00.000", 1)
    with pytest.raises(RinexError, match=r"line \d+: bad number") as ei:
        read_rinex_obs(write(tmp_path, "bad.21o", bad))
    assert bad.splitlines()[ei.value.line - 1].find("1e8x00") >= 0
    # truncated: epoch announces 13 satellites
    cut = "\n".join(text.splitlines()[:12]) + "\n"
    with pytest.raises(RinexError, match="unexpected end of file"):
        read_rinex_obs(write(tmp_path, "cut.21o", cut))


OBS3 = """\
     3.04           OBSERVATION DATA    M: Mixed            RINEX VERSION / TYPE
G   14 C1C L1C D1C S1C C2X L2X D2X S2X C5X L5X D5X S5X C1W  SYS / # / OBS TYPES
       S1W                                                  SYS / # / OBS TYPES
E    4 C1X L1X D1X S1X                                      SYS / # / OBS TYPES
                                                            END OF HEADER
> 2021 04 28 18 00  0.0000000  0  3      -0.000012345678
G05  20576396.770   108129693.934        1064.326          51.000
E11  21534103.024    84504436.889          72.229          48.000
G12  22235408.974   116847854.2201      -1375.564          44.000    22235413.299
> 2021 04 28 18 00  1.0000000  4  1
EVENT COMMENT                                               COMMENT
> 2021 04 28 18 00  2.0000000  0  1
G05  20576400.000                                          50.000
"""


#: every array and table of an ObsData (compared to the last bit between the two record parsers)
_OBS_ARRAYS = ("epoch_t_gps_s", "epoch_week", "epoch_tow", "epoch_flag", "clock_offset_s", "epoch", "t_gps_s",
               "week", "tow", "prn", "C1", "L1", "D1", "S1", "system", "lli1", "approx_r_e")


def assert_same_obs(a, b):
    """Same dtype, shape and bytes of every array (NaN payloads included), same tables."""
    for f in _OBS_ARRAYS:
        x, y = getattr(a, f), getattr(b, f)
        if x is None or y is None:
            assert x is None and y is None, f
            continue
        x, y = np.asarray(x), np.asarray(y)
        assert (x.dtype, x.shape) == (y.dtype, y.shape), f
        assert x.tobytes() == y.tobytes(), f
    assert (a.version, a.codes, a.codes_by_system, a.glonass_channels) == \
        (b.version, b.codes, b.codes_by_system, b.glonass_channels)


# RINEX 3 records: the edge cases of the format (0.000, blanks, a line ending inside a field, LLI and
# signal-strength digits, an event with its special records, a flag-6 epoch, a blank line, a BeiDou
# satellite of a system not asked for) for the compiled parser against the Python reference
def _f(v="", lli=" ", ssi=" "):
    """One 16-character observation field: F14.3 (or the text given), LLI, signal strength."""
    return (f"{v:14.3f}" if isinstance(v, float) else f"{v:>14}") + lli + ssi


OBS3_EDGES = "".join([
    "     3.04           OBSERVATION DATA    M: Mixed            RINEX VERSION / TYPE\n",
    "G    4 C1C L1C D1C S1C                                      SYS / # / OBS TYPES\n",
    "E    4 C1X L1X D1X S1X                                      SYS / # / OBS TYPES\n",
    "C    4 C2I L2I D2I S2I                                      SYS / # / OBS TYPES\n",
    "      100.0000     -200.0000      300.0000                  APPROX POSITION XYZ\n",
    "                                                            END OF HEADER\n",
    "> 2021 04 28 18 00  0.0000000  0  4      -0.000012345678\n",
    "G05" + _f(20576396.770, " ", "7") + _f(108129693.934, "1", "5") + _f(1064.326, " ", "6") + _f(51.0) + "\n",
    "G07" + _f(0.0) + _f(0.0) + _f(0.0) + _f(0.0) + "\n",
    "E11" + _f(21534103.024) + _f(84504436.889, "2") + "\n",
    "C06" + _f(38000000.0) + _f("1.9e8") + _f("-100.5") + _f("33.0")[:10] + "\n",
    "\n",
    "> 2021 04 28 18 00  1.0000000  4  2\n",
    "EVENT COMMENT                                               COMMENT\n",
    "SECOND COMMENT                                              COMMENT\n",
    "> 2021 04 28 18 00  1.5000000  6  1\n",
    "G05" + _f(20576398.0) + _f(108129695.0) + "\n",
    "> 2021 04 28 18 00  2.0000000  1  2\n",
    "G05" + _f(20576400.0) + _f() + _f() + _f(50.0) + "\n",
    "G12" + _f("2.22354090D+07") + "\n",
])


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_obs3_compiled_records_equal_python_reference(tmp_path, newline):
    from insnav.gnss import rinex

    p = tmp_path / "e.rnx"
    p.write_bytes(OBS3_EDGES.replace("\n", newline).encode())
    for systems in ("G", "GE", "GREC"):
        a, b = rinex._read_obs(p, systems, compiled=True), rinex._read_obs(p, systems, compiled=False)
        assert_same_obs(a, b)
    a = read_rinex_obs(p, systems="GEC")
    np.testing.assert_array_equal(a.prn, [5, 7, 11, 6, 5, 12])  # the flag-6 epoch dropped, the event skipped
    # a 0.000 phase stays as written (both parsers); a 0.000 pseudorange is a missing one (ObsData)
    assert np.isnan(a.C1[1]) and a.L1[1] == 0.0
    assert a.L1[0] == 108129693.934 and list(a.lli1) == [1, 0, 2, 0, 0, 0]
    assert np.isnan(a.D1[2]) and a.L1[3] == 1.9e8 and a.C1[5] == 2.2235409e7
    assert a.epoch_flag.tolist() == [0, 1] and np.isnan(a.clock_offset_s[1])
    # compressed: the same numbers
    import gzip

    g = tmp_path / "e.rnx.gz"
    g.write_bytes(gzip.compress(p.read_bytes()))
    assert_same_obs(read_rinex_obs(g, systems="GEC"), rinex._read_obs(p, "GEC", compiled=False))
    # a malformed observation: the same file, line and value from both
    bad = OBS3_EDGES.replace("84504436.889", "84504x36.889")
    q = write(tmp_path, "bad.rnx", bad)
    for compiled in (True, False):
        with pytest.raises(RinexError, match=r"bad\.rnx, line 10: bad number '84504x36\.889' for observation L1X"):
            rinex._read_obs(q, "GE", compiled=compiled)


def test_obs2_compiled_records_equal_python_reference(tmp_path):
    """RINEX 2.11: two satellite-list lines, two observation lines per satellite, blanks, a 0.000, an LLI
    digit, a blank system letter (GPS), an event; compiled and Python records parsers give the same bits."""
    from insnav.gnss import rinex

    types = ["C1", "L1", "D1", "S1", "P2", "L2", "C2", "S2", "D2", "C5"]
    sats = {}
    for k in range(13):
        sid = f"G{k + 1:2d}" if k not in (5, 7) else ("R07" if k == 5 else f" {k + 1:2d}")
        sats[sid] = [2.0e7 + k, 1.0e8 + k, None if k == 0 else -100.0 - k, 40.0 + k, None, 0.0, 2.0e7, None, 1.0, 3.0]
    text = _obs2(types, sats)
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith(f"{2.0e7 + 2:14.3f}"))
    lines[k] = lines[k][:30] + "1" + lines[k][31:]  # LLI of L1 of G03
    p = write(tmp_path, "o.21o", "\n".join(lines) + "\n")
    for systems in ("G", "GR", "GREC"):
        assert_same_obs(rinex._read_obs(p, systems, compiled=True), rinex._read_obs(p, systems, compiled=False))
    a = read_rinex_obs(p, systems="GR")
    assert a.lli1.tolist().count(1) == 1 and a.lli1[2] == 1 and 8 in a.prn.tolist() and a.L1[0] == 1.0e8
    bad = text.replace(f"{1.0e8 + 3:14.3f}", "   1e8x00.000", 1)
    q = write(tmp_path, "bad.21o", bad)
    for compiled in (True, False):
        with pytest.raises(RinexError, match=r"line \d+: bad number '1e8x00\.000' for observation L1") as ei:
            rinex._read_obs(q, "G", compiled=compiled)
        assert bad.splitlines()[ei.value.line - 1].find("1e8x00") >= 0


def test_obs_events_blank_date_and_redeclared_types(tmp_path):
    """Epoch flag 4 is followed by header lines (RINEX 3.05 Sec. 5.2.1, RINEX 2.11 Sec. 7.7).  An event
    with a blank date (RINEX 3.05 Table A13) is skipped; a repeat of the header's types is accepted; a
    different list (the columns after it would be misread) is refused by both parsers, naming the line."""
    from insnav.gnss import rinex

    event = "> 2021 04 28 18 00  1.0000000  4  1\nEVENT COMMENT" + " " * 47 + "COMMENT\n"
    blank_date = OBS3.replace(event, ">" + " " * 30 + "4  1\nEVENT COMMENT" + " " * 47 + "COMMENT\n")
    assert blank_date != OBS3
    same_types = OBS3.replace(event, "> 2021 04 28 18 00  1.0000000  4  1\n"
                              "E    4 C1X L1X D1X S1X                                      SYS / # / OBS TYPES\n")
    head, tail = same_types.split("END OF HEADER", 1)
    changed = head + "END OF HEADER" + tail.replace("E    4 C1X L1X D1X S1X", "E    4 L1X C1X D1X S1X")
    ref = rinex._read_obs(write(tmp_path, "ref.rnx", OBS3), "GE", compiled=False)
    for compiled in (True, False):
        for name, text in (("blank.rnx", blank_date), ("same.rnx", same_types)):
            o = rinex._read_obs(write(tmp_path, name, text), "GE", compiled=compiled)
            assert_same_obs(o, ref)
            assert o.epoch_t_gps_s.size == 2 and o.C1[-1] == 20576400.0
        with pytest.raises(RinexError, match=r"changed\.rnx, line 11: the event on line 10 re-declares the "
                                             r"observation types of E .*split the file before line 10"):
            rinex._read_obs(write(tmp_path, "changed.rnx", changed), "GE", compiled=compiled)
    # RINEX 2.11: the one list of types swapped by an event (C1 L1 -> L1 C1)
    types = ["C1", "L1", "D1", "S1"]
    text = _obs2(types, {"G05": [2.0e7, 1.0e8, -100.0, 40.0]})
    swap = text.replace(" 21  4 28 18  0  1.0000000  4  1\n" + "THIS IS A COMMENT".ljust(60) + "COMMENT",
                        " 21  4 28 18  0  1.0000000  4  1\n" + "     4    L1    C1    D1    S1".ljust(60)
                        + "# / TYPES OF OBSERV")
    assert swap != text
    ev_line = swap.splitlines().index(" 21  4 28 18  0  1.0000000  4  1") + 1
    for compiled in (True, False):
        assert rinex._read_obs(write(tmp_path, "o.21o", text), "G", compiled=compiled).C1.tolist() == [2.0e7]
        with pytest.raises(RinexError, match=rf"line {ev_line + 1}: the event on line {ev_line} re-declares the "
                                             r"observation types of G"):
            rinex._read_obs(write(tmp_path, "swap.21o", swap), "G", compiled=compiled)


def test_obs_repeated_epoch_is_skipped_with_one_warning(tmp_path):
    """An epoch at the time of the one before it (overlapping files merged): both parsers keep the first and
    skip the repeat whole -- the file reads as without it -- and warn once, naming the repeat's line."""
    from insnav.errors import InsnavWarning
    from insnav.gnss import rinex

    last = "> 2021 04 28 18 00  2.0000000  0  1\nG05  20576400.000                                          50.000\n"
    assert OBS3.endswith(last)
    twice = OBS3 + last.replace("20576400.000", "20576499.000")
    ref = rinex._read_obs(write(tmp_path, "ref.rnx", OBS3), "GE", compiled=False)
    n_lines = len(OBS3.splitlines())
    for compiled in (True, False):
        with pytest.warns(InsnavWarning, match=rf"twice\.rnx, line {n_lines + 1}: this epoch repeats the time of the "
                                               r"one before it; the first is kept, the repeats skipped"):
            o = rinex._read_obs(write(tmp_path, "twice.rnx", twice), "GE", compiled=compiled)
        assert_same_obs(o, ref)
        assert o.C1[-1] == 20576400.0
    # RINEX 2.11: the same epoch written three times -> one warning counting the two repeats
    text = _obs2(["C1", "L1", "D1", "S1"], {"G05": [2.0e7, 1.0e8, -100.0, 40.0]})
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith(" 21  4 28 18  0  0.0000000"))
    epoch = lines[k:k + 2]
    thrice = "\n".join(lines[:k + 2] + epoch + epoch + lines[k + 2:]) + "\n"
    for compiled in (True, False):
        with pytest.warns(InsnavWarning, match=rf"line {k + 3}: .* \(and 1 more epochs do\)"):
            o = rinex._read_obs(write(tmp_path, "thrice.21o", thrice), "G", compiled=compiled)
        assert o.epoch_t_gps_s.size == 1 and o.C1.tolist() == [2.0e7]


@pytest.mark.parametrize("file_sys, ts, refused", [
    ("M", "GPS", None), ("M", "GAL", None), ("E", "   ", None), ("G", "   ", None), ("J", "   ", None),
    ("M", "GLO", "'GLO': the epochs"), ("R", "   ", "'GLO' \\(the default of a RINEX file of system 'R'"),
    ("C", "   ", "'BDT' \\(the default"), ("M", "BDT", "'BDT': the epochs")])
def test_obs_time_system_default_of_the_file_system(tmp_path, file_sys, ts, refused):
    """RINEX 3.05 Table A2: a blank TIME OF FIRST OBS time system is the default of the file's system
    (GLO for GLONASS: UTC, 18 s from GPS time in 2020; BDT: 14 s).  The epochs are read as GPS time, so
    GPS, GAL and QZS (steered to it) are read; any other is refused naming the line, by the observation
    reader (compiled and Python) and by the carrier-phase reader of RTK."""
    from insnav.gnss import rinex
    from insnav.gnss.rtk import read_phase_obs

    head = OBS3.splitlines(True)
    head[0] = head[0][:40] + file_sys + head[0][41:]
    first = f"  2021     4    28    18     0    0.0000000     {ts}".ljust(60) + "TIME OF FIRST OBS\n"
    text = "".join(head[:4] + [first] + head[4:])
    p = write(tmp_path, "t.rnx", text)
    readers = [lambda: rinex._read_obs(p, "GE", compiled=True), lambda: rinex._read_obs(p, "GE", compiled=False),
               lambda: read_phase_obs(p, "GE")]
    for read in readers:
        if refused is None:
            assert read().epoch_t_gps_s.size == 2
        else:
            with pytest.raises(RinexError, match=rf"t\.rnx, line 5: unsupported time system {refused}"):
                read()


@pytest.mark.parametrize("parts", [
    ("rtklibexplorer_walk_0827", "rinex_derived", "gnss_1730.obs"),
    ("euref_wettzell_wtzr_wtzz", "WTZR00DEU_R_20201770000_01D_30S_MO_120epoch.rnx"),
    ("matrtklib_static_septentrio", "rover.obs"),
    ("instinct_spirent_rtk_dynamic_SIMULATED", "iono-Klob_tropo-Saast", "Rover-dynamic_MO_Spirent.obs"),
    ("smartloc_berlin_potsdamer_platz", "Berlin_Potsdamer_Platz.obs"),  # RINEX 2.11
])
def test_obs_real_files_compiled_equal_python_reference(parts):
    """The RINEX 3 files and the RINEX 2.11 file of the shared data: every observation the same to the last bit."""
    from insnav.gnss import rinex

    p = need(*parts)
    for systems in ("G", "GREC"):
        a, b = rinex._read_obs(p, systems, compiled=True), rinex._read_obs(p, systems, compiled=False)
        assert a.prn.size > 1000 and np.isfinite(a.C1).mean() > 0.5
        assert_same_obs(a, b)


def test_obs3_types_continuation_flags_clock(tmp_path):
    obs = read_rinex_obs(write(tmp_path, "o.rnx", OBS3))
    assert obs.codes["C1"] == "C1C" and obs.codes["D1"] == "D1C"
    np.testing.assert_array_equal(obs.prn, [5, 12, 5])
    np.testing.assert_array_equal(obs.epoch, [0, 0, 1])
    assert obs.epoch_t_gps_s[1] - obs.epoch_t_gps_s[0] == 2.0
    assert obs.clock_offset_s[0] == pytest.approx(-1.2345678e-5)
    assert np.isnan(obs.clock_offset_s[1])
    assert obs.L1[1] == 116847854.220 and obs.D1[1] == -1375.564
    assert np.isnan(obs.L1[2]) and np.isnan(obs.D1[2]) and obs.S1[2] == 50.0
    bad = OBS3.replace("> 2021 04 28 18 00  2.0000000", "> 2021 04 28 18 0x  2.0000000")
    with pytest.raises(RinexError, match=r"line 12: bad record: cannot parse epoch line"):
        read_rinex_obs(write(tmp_path, "b.rnx", bad))
    bad = OBS3.replace("E11 ", "X11 ")
    with pytest.raises(RinexError, match=r"line 8: bad record: satellite 'X11'"):
        read_rinex_obs(write(tmp_path, "c.rnx", bad))
    bad = OBS3.replace("G   14 C1C", "G   1x C1C")
    with pytest.raises(RinexError, match=r"line 2: bad integer"):
        read_rinex_obs(write(tmp_path, "d.rnx", bad))


def test_empty_and_missing_files(tmp_path):
    with pytest.raises(RinexError, match="line 1: unexpected end of file"):
        read_rinex_obs(write(tmp_path, "empty.rnx", ""))
    with pytest.raises(RinexError, match="cannot read file"):
        read_rinex_nav(tmp_path / "does_not_exist.rnx")


# --------------------------------------------------------------------- real files
def test_real_nav_files():
    nav = read_rinex_nav(need("ephemeris_sp3_2021-118", "brdc1180.21n"))
    assert len(nav.eph) == 105 and set(nav.eph.prn) == set(range(1, 33))
    nav3 = read_rinex_nav(need("ephemeris_sp3_2021-118", "rinex3_2023-073", "BRDC00WRD_S_20230730000_01D_MN.rnx"))
    assert len(nav3.eph) == 4 and nav3.n_skipped == 52  # 4 C + 38 E + 4 J + 6 R records skipped
    assert nav3.ion_alpha is None
    spir = read_rinex_nav(need("instinct_spirent_rtk_dynamic_SIMULATED", "RINEX_GN_Spirent.23N"))
    assert spir.version == 3.04 and spir.ion_alpha[0] == pytest.approx(4.6566e-9)
    assert np.all(week_tow(spir.eph.toe)[0] == 2244)


def test_real_obs_rinex2_smartloc():
    obs = read_rinex_obs(need("smartloc_berlin_potsdamer_platz", "Berlin_Potsdamer_Platz.obs"))
    assert obs.version == 2.11 and obs.codes["C1"] == "C1"
    assert obs.prn[0] == 12 and obs.C1[0] == 19834589.652 and obs.S1[0] == 49.0 and obs.D1[0] == 221.941
    assert np.all(np.diff(obs.epoch_t_gps_s) > 0)


def test_sp3_clk_readers():
    s = read_sp3(need("ephemeris_sp3_2021-118", "COD0MGXFIN_20211180000_01D_05M_ORB.SP3"))
    assert s.r_e.shape == (73, 116, 3)
    j = s.index("G01")
    np.testing.assert_allclose(s.r_e[0, j], [13287682.546, -15491926.575, 16545690.647])
    assert s.clock_s[0, j] == pytest.approx(703.963460e-6)
    # Lagrange interpolation reproduces a node exactly and a mid point to < 1 cm
    t_mid = s.t_gps_s[30] + 150.0
    p = s.position("G01", [s.t_gps_s[30], t_mid])
    np.testing.assert_allclose(p[0], s.r_e[30, j], atol=1e-6)
    p9 = s.position("G01", [t_mid], order=8)
    assert np.linalg.norm(p[1] - p9[0]) < 0.01
    c = read_rinex_clk(need("ephemeris_sp3_2021-118", "COD0MGXFIN_20211180000_01D_30S_CLK.CLK"))
    assert c.clock_s.shape[0] == 121
    assert c.clock("G01", [gps_seconds_from_calendar(2021, 4, 28, 19, 30, 0.0)])[0] == pytest.approx(0.703906926273e-3)
