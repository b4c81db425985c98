"""Inputs of ``insnav run --filter rtk`` / ``--coupling rtk`` refused before the run, with one line.

* A base position far from the base receiver.  Every rover position of an RTK run is the base
  position plus the baseline, so a mistyped ``--base-pos`` (or ``[rtk] base_position_*``, or
  another station's file) would shift the whole solution by as much with exit status 0; a base
  some hundred km off also made the engine search float ambiguities for minutes.  The base position
  is checked against the code-only least-squares fix of the base's own pseudoranges (RTKLIB pntpos
  without its atmosphere models; :func:`insnav.gnss.rtk.receiver_code_fix`), which lands within tens of
  metres of the known antenna.
* A GNSS-only run's TOML asking for a smoother or TDCP (which the command-line options of the same
  meaning are refused for)."""
from __future__ import annotations

import re

import numpy as np
import pytest

from insnav import earth
from insnav.cli import main
from insnav.gnss import rtk
from insnav.gnss.rinex import read_nav_multi


def _matrtklib(shared_data):
    d = shared_data / "matrtklib_static_septentrio"
    if not d.is_dir():
        pytest.skip("MatRTKLIB static data not in ../shared/data")
    return d


def _llh(p):
    return [float(v) for v in p.read_text().split()]


def _ecef(lat_deg, lon_deg, h_m):
    return np.asarray(earth.geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), h_m), float).ravel()


def _north_of(llh, metres):
    """The geodetic point ``metres`` north of ``llh`` (lat, lon [deg], h [m]) on the ellipsoid."""
    r_e = _ecef(*llh)
    lat, lon = np.radians(llh[0]), np.radians(llh[1])
    north_e = np.array([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)])
    return r_e + metres * north_e


def test_code_fix_of_the_base_lands_near_its_known_antenna_and_the_check_follows_the_tolerance(shared_data):
    d = _matrtklib(shared_data)
    base = rtk.read_phase_obs(d / "base.obs", "GREC")
    nav = read_nav_multi([d / "base.nav"], "GREC")
    rs, clk = rtk.transmit_states(nav, base.epoch_t_gps_s[base.epoch], base.system, base.prn, rtk._first_code(base))
    rb = _ecef(*_llh(d / "base_position.txt"))
    start = _north_of(_llh(d / "base_position.txt"), 1.0e6)  # Gauss-Newton from 1000 km away
    fix, n, _ = rtk.receiver_code_fix(base, rs, clk, start)
    assert n == 10
    dist = np.linalg.norm(fix - rb)
    assert dist < 100.0, dist  # no ionosphere or troposphere model: tens of metres
    tol = rtk.BASE_POSITION_TOLERANCE_M
    # within the tolerance less the fix's own error: accepted; beyond it plus that error: refused
    rtk.check_base_position(base, _north_of(_llh(d / "base_position.txt"), tol - dist - 1.0), rs, clk, "test")
    with pytest.raises(rtk.RtkInputError, match=r"base\.obs: the base position \(test: .* is \d+ m from where"):
        rtk.check_base_position(base, _north_of(_llh(d / "base_position.txt"), tol + dist + 1.0), rs, clk, "test")


def _rtk_argv(d, out, *extra):
    return ["run", "--filter", "rtk", "--format", "rinex", "--obs", str(d / "rover.obs"), "--base",
            str(d / "base.obs"), "--nav", str(d / "base.nav"), "--out", str(out), *map(str, extra)]


@pytest.mark.parametrize("where", ["--base-pos", "toml", "toml-gps"])
@pytest.mark.parametrize("off_m", [1.0e4, 1.0e6])
def test_a_base_position_far_off_is_refused_with_one_line_and_no_file(shared_data, tmp_path, capsys, where, off_m,
                                                                       monkeypatch):
    """10 km and 1000 km north of the known base: status 2, one line naming the base file, where the
    position came from and the distance; no file written (before: exit 0 with every epoch 10 km off,
    or a run of several minutes at 1000 km).  ``toml-gps``: GPS only, the command line's numpy-free
    path, which leaves a typed base position to the checked path."""
    d = _matrtklib(shared_data)
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", "1")
    lat, lon, h = (float(v) for v in earth.ecef_to_geodetic(_north_of(_llh(d / "base_position.txt"), off_m)))
    llh = f"{np.degrees(lat):.9f},{np.degrees(lon):.9f},{h:.4f}"
    out = tmp_path / "out" / "sol.pos"
    toml = tmp_path / "run.toml"
    if where == "--base-pos":
        extra, source = ("--base-pos", llh), "--base-pos"
    else:
        toml.write_text(("[rtk]\n" + ('systems = "G"\n' if where == "toml-gps" else "")
                         + f"base_position_llh = [{llh}]\n"))
        extra, source = ("--config", toml), f"{toml}: key 'rtk.base_position_llh'"
    rc = main(_rtk_argv(d, out, *extra))
    err = capsys.readouterr().err
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"insnav run: error: {d / 'base.obs'}: the base position ({source}: "), err
    m = re.search(r" is ([0-9.]+) (m|km) from where the base's own pseudoranges put the receiver", err)
    assert m, err
    dist = float(m.group(1)) * (1e3 if m.group(2) == "km" else 1.0)
    assert abs(dist - off_m) < 100.0, err  # the code fix's own error: tens of metres
    assert not out.parent.exists() or list(out.parent.iterdir()) == []


def test_rtk_ins_refuses_a_base_position_far_off_before_the_run(shared_data, tmp_path, capsys):
    """``--coupling rtk`` shares the check (:func:`insnav.gnss.rtk.prepare_rtk_rows`)."""
    import insnav
    from insnav.sim.scenario import resolve_raw

    d = _matrtklib(shared_data)
    raw, _ = resolve_raw("seed000-sim")
    raw["motion"]["segments"] = [{"duration_s": 5.0}]
    raw["motion"].pop("oscillations", None)
    raw["gnss"]["outages"] = []
    ds = insnav.simulate(raw, seed=1).save(tmp_path / "ds")
    lat, lon, h = (float(v) for v in earth.ecef_to_geodetic(_north_of(_llh(d / "base_position.txt"), 1.0e6)))
    out = tmp_path / "sol.csv"
    rc = main(["run", str(ds), "--coupling", "rtk", "--obs", str(d / "rover.obs"), "--base", str(d / "base.obs"),
               "--nav", str(d / "base.nav"), "--base-pos", f"{np.degrees(lat)},{np.degrees(lon)},{h}",
               "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert "the base position (--base-pos: " in err and " is 1000.0 km from where" in err, err
    assert not list(tmp_path.glob("sol.csv*"))


@pytest.mark.parametrize("fast", ["1", "0"])
@pytest.mark.parametrize("key, text", [("smooth", "smooth = true\n"), ("tdcp.enabled", "[tdcp]\nenabled = true\n")])
def test_gnss_only_rtk_refuses_the_tomls_smoother_and_tdcp_as_it_refuses_the_options(shared_data, tmp_path, capsys,
                                                                                    monkeypatch, fast, key, text):
    """``--smooth`` and ``--tdcp`` are refused for a GNSS-only filter; ``smooth = true`` or ``[tdcp]
    enabled = true`` in its TOML were silently ignored (status 0, a filtered solution where a smoothed
    one was asked for).  Now one line naming the file and the key on either command-line path, no file;
    ``smooth = false`` runs."""
    d = _matrtklib(shared_data)
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", fast)
    toml = tmp_path / "run.toml"
    rtk_table = '[rtk]\nsystems = "G"\nfrequencies = 1\nar_mode = "instantaneous"\n'
    toml.write_text(text + rtk_table)
    before = toml.read_bytes()
    out = tmp_path / "out" / "sol.pos"
    assert main(_rtk_argv(d, out, "--config", toml)) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"insnav run: error: {toml}: key '{key}': --filter rtk is GNSS only and has no "), err
    assert len(err.splitlines()) == 1 and toml.read_bytes() == before and not out.parent.exists()
    toml.write_text(text.replace("true", "false") + rtk_table)
    assert main(_rtk_argv(d, out, "--config", toml)) == 0, capsys.readouterr().err
    assert out.read_bytes().startswith(b"% program   : insnav rtk\n")


@pytest.mark.parametrize("fast", ["1", "0"])
@pytest.mark.parametrize("text, key, hint", [
    ("elevation_mask_deg = 40.0\n", "elevation_mask_deg",
     "; did you mean 'rtk.elevation_mask_deg' (a key of the [rtk] table)?"),
    ("[rtkk]\nsystems = \"G\"\n", "rtkk", "; did you mean 'rtk'?"),
    ("bogus_top = 1\n", "bogus_top", "; known keys: coupling, filter, rtk, smooth, tdcp")])
def test_a_key_gnss_only_rtk_does_not_read_is_one_line_naming_it(shared_data, tmp_path, capsys, monkeypatch, fast,
                                                                  text, key, hint):
    """A top-level ``elevation_mask_deg`` (the INS filters' key; RTK's is ``[rtk] elevation_mask_deg``),
    a misspelt table or an unknown key in a TOML saying ``filter = "rtk"`` ran with exit status 0 and
    the key ignored (the 40 deg mask dropped, the resolved config saying 15).  Now one line naming the
    file and the key, on either command-line path, and no file; a TOML naming another filter (an
    RTK/INS run's) is still read for its ``[rtk]`` table alone."""
    d = _matrtklib(shared_data)
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", fast)
    toml = tmp_path / "run.toml"
    toml.write_text('filter = "rtk"\n' + text)
    out = tmp_path / "out" / "sol.pos"
    assert main(_rtk_argv(d, out, "--config", toml)) == 2
    assert capsys.readouterr().err == (f"insnav run: error: {toml}: key '{key}' is not read by filter 'rtk' "
                                       f"(it reads [rtk]){hint}\n")
    assert not out.parent.exists()
    toml.write_text('filter = "ekf"\ncoupling = "rtk"\n' + text + '[imu]\n[rtk]\nsystems = "G"\nfrequencies = 1\n')
    assert main(_rtk_argv(d, out, "--config", toml)) == 0, capsys.readouterr().err


@pytest.mark.parametrize("fast", ["1", "0"])
@pytest.mark.parametrize("text, message", [
    # a TOML integer past the engine's int: a raw pybind11 cast error; past the 120 ambiguity states: all float
    ("[rtk]\nmax_outage_epochs = 1000000000000\n",
     "key 'rtk.max_outage_epochs': bad value 1000000000000; allowed: an integer in [0, 1000000]"),
    ("[rtk]\nmin_fix_ambiguities = 500\n",
     "key 'rtk.min_fix_ambiguities': bad value 500; allowed: an integer in [1, 120]"),
    # both base keys: the latitude/longitude silently won over the ECEF position
    ("[rtk]\nbase_position_ecef_m = [-3962108.7, 3381309.5, 3668678.6]\nbase_position_llh = [35.13, 136.97, 104.8]\n",
     "keys 'rtk.base_position_ecef_m' and 'rtk.base_position_llh' both given; keep one (the base antenna reference "
     "point)"),
    # a coupling other than gnss was read by no one (written back as "gnss")
    ('coupling = "banana"\n', "key 'coupling': bad value 'banana'; allowed: \"gnss\" (filter 'rtk' is GNSS only)"),
    ('filter = "rtk"\ncoupling = "rtk"\n', "key 'coupling': bad value 'rtk'; allowed: \"gnss\" (filter 'rtk' is GNSS "
     "only); RTK/INS (the IMU with carrier phase) is --filter ekf --coupling rtk"),
    # [tdcp] that is not a table, or its settings: accepted and ignored
    ("tdcp = 5\n", "key 'tdcp': bad value 5; allowed: a [tdcp] table (and --filter rtk is GNSS only: it has no TDCP "
     "update)"),
    ("[tdcp]\nsigma_phase_m = 0.5\n", "key 'tdcp.sigma_phase_m': --filter rtk is GNSS only and has no TDCP update "
     "(an IMU run's key): remove the [tdcp] table"),
])
def test_gnss_only_rtk_refuses_what_it_would_misread_with_one_line(shared_data, tmp_path, capsys, monkeypatch, fast,
                                                                   text, message):
    d = _matrtklib(shared_data)
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", fast)
    toml = tmp_path / "run.toml"
    toml.write_text(text)
    out = tmp_path / "out" / "sol.pos"
    assert main(_rtk_argv(d, out, "--config", toml)) == 2
    assert capsys.readouterr().err == f"insnav run: error: {toml}: {message}\n"
    assert not out.parent.exists()


def _binary(tmp_path):
    """A file that is not UTF-8 text (a compiled module, a zipped folder given by mistake)."""
    p = tmp_path / "run.toml"
    p.write_bytes(b"\x7fELF\x02\x01\x01" + bytes(range(128, 256)) + b"\n[rtk]\n")
    return p


@pytest.mark.parametrize("fast", ["1", "0"])
def test_a_binary_config_is_one_line_naming_the_file(shared_data, tmp_path, capsys, monkeypatch, fast):
    """tomllib raises UnicodeDecodeError, not TOMLDecodeError, for bytes that are not UTF-8: the
    readers printed "'utf-8' codec can't decode byte 0x80 in position 7" without the file's name.
    Every TOML reader now goes through :func:`insnav.config.read_toml`."""
    from insnav.config import ConfigError, load_config, read_toml

    d = _matrtklib(shared_data)
    toml = _binary(tmp_path)
    msg = f"{toml}: not valid TOML: not UTF-8 text (byte 0x80 at offset 7)"
    for read in (read_toml, load_config):
        with pytest.raises(ConfigError) as e:
            read(toml)
        assert str(e.value) == msg
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", fast)
    out = tmp_path / "out" / "sol.pos"
    argvs = [_rtk_argv(d, out, "--config", toml),
             ["run", "--filter", "spp", "--format", "rinex", "--obs", d / "rover.obs", "--nav", d / "base.nav",
              "--config", toml, "--out", tmp_path / "out" / "spp.csv"],
             ["run", "--format", "rinex", "--imu", d / "base_position.txt", "--obs", d / "rover.obs", "--nav",
              d / "base.nav", "--config", toml, "--out", tmp_path / "out" / "sol.csv"],
             ["allan", d / "base_position.txt", "--format", "csv", "--config", toml, "--out-dir", tmp_path / "out"]]
    for argv in argvs:
        rc = main([str(a) for a in argv])
        err = capsys.readouterr().err
        assert rc == 2 and err == f"insnav {argv[0]}: error: {msg}\n", (argv, err)
    assert not out.parent.exists()


def test_a_folder_given_as_a_rinex_file_is_named_a_folder(shared_data, tmp_path, capsys):
    """``--nav FOLDER`` said "cannot read file (No such file or directory)" of a folder that exists."""
    from insnav.data.textio import read_bytes

    d = _matrtklib(shared_data)
    with pytest.raises(IsADirectoryError) as e:
        read_bytes(tmp_path)
    assert e.value.strerror == "Is a directory" and e.value.filename == str(tmp_path)
    for i, role in enumerate(("--nav", "--base")):
        argv = _rtk_argv(d, tmp_path / "sol.pos")
        argv[argv.index(role) + 1] = str(tmp_path)
        assert main(argv) == 2
        assert capsys.readouterr().err == f"insnav run: error: {tmp_path}: cannot read file (Is a directory)\n"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fast", ["1", "0"])
def test_a_nav_file_of_a_system_left_out_is_skipped_beside_one_of_the_systems_used(shared_data, tmp_path, capsys,
                                                                                   monkeypatch, fast):
    """``--nav GPS.23N,GAL.23L`` with ``systems = "G"`` (or ``"E"``) stopped with "malformed header" of the
    valid file of the other system; now that file is skipped, and the run is the one given the used
    system's file alone, byte for byte.  With no file of a system used, one line names the first file."""
    d = shared_data / "instinct_spirent_rtk_dynamic_SIMULATED"
    if not d.is_dir():
        pytest.skip("Spirent RTK data not in ../shared/data")
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", fast)
    gps, gal = d / "RINEX_GN_Spirent.23N", d / "RINEX_EN_Spirent.23L"
    nav = read_nav_multi([gps, gal], "G")
    assert len(nav.eph) > 0 and len(nav.eph_e) == 0
    for systems, own in (("G", gps), ("E", gal)):
        toml = tmp_path / f"{systems}.toml"
        toml.write_text(f'[rtk]\nsystems = "{systems}"\n')
        outs = []
        for navs in (f"{gps},{gal}", str(own)):
            out = tmp_path / f"{systems}-{len(outs)}" / "sol.pos"
            argv = ["run", "--filter", "rtk", "--format", "rinex",
                    "--obs", d / "iono-Klob_tropo-Saast" / "Rover-dynamic_MO_Spirent.obs",
                    "--base", d / "iono-Klob_tropo-Saast" / "Base-static_MO_Spirent.obs",
                    "--nav", navs, "--config", toml, "--out", out, "--quiet"]
            assert main([str(a) for a in argv]) == 0, capsys.readouterr().err
            outs.append(out.read_bytes())
        assert outs[0] == outs[1] and outs[0].count(b"\n") > 600
    toml = tmp_path / "C.toml"
    toml.write_text('[rtk]\nsystems = "C"\n')
    argv[argv.index("--nav") + 1], argv[argv.index("--config") + 1] = f"{gps},{gal}", toml
    assert main([str(a) for a in argv]) == 2
    assert capsys.readouterr().err == (f"insnav run: error: {gps}, line 1: a navigation file of system 'G' only, "
                                       "and the run uses the systems 'C': give a navigation file of one of them\n")
