"""``insnav run --filter rtk`` without numpy (insnav.cli.rtk_fast, insnav/gnss/rtk_rinex.hpp) against the
usual path (``INSNAV_RTK_FASTPATH=0``): the same files (byte for byte but a number's last printed digit,
_assert_same_up_to_the_last_digit), the same summary line, the same
one-line errors and exit codes; and the fast path really runs without importing numpy."""
from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import pytest

from insnav.gnss._rtk_keys import RTK_DEFAULTS
from insnav.gnss.rtk import RtkOptions

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data"))
TOMLS = sorted((ROOT / "bench" / "rtk").glob("*.toml"))
_M = DATA / "matrtklib_static_septentrio"
_W = DATA / "euref_wettzell_wtzr_wtzz"
_S = DATA / "instinct_spirent_rtk_dynamic_SIMULATED"
#: setting prefix -> (rover, base, nav files)
_FILES = {
    "matrtklib": (_M / "rover.obs", _M / "base.obs", [_M / "base.nav"]),
    "wtzr": (_W / "WTZZ00DEU_R_20201770000_01D_30S_MO_120epoch.rnx", _W / "WTZR00DEU_R_20201770000_01D_30S_MO_120epoch.rnx",
             [_W / "ESBC00DNK_R_20201770000_01D_MN.rnx", _W / "ESBC00DNK_R_20201770000_01D_RN.rnx"]),
    "spirent": (_S / "iono-Klob_tropo-Saast" / "Rover-dynamic_MO_Spirent.obs",
                _S / "iono-Klob_tropo-Saast" / "Base-static_MO_Spirent.obs",
                [_S / "RINEX_GN_Spirent.23N", _S / "RINEX_EN_Spirent.23L"]),
}
#: what a child prints after the command: whether numpy was imported, and the status
_PROBE = ("import sys; from insnav.cli import main; rc = main(sys.argv[1:]); "
          "print('NUMPY', 'numpy' in sys.modules, rc)")


def _files(name):
    rover, base, nav = _FILES[name.split("_")[0]]
    if not all(p.exists() for p in (rover, base, *nav)):
        pytest.skip(f"shared data for {name} absent (set INSNAV_SHARED_DATA; {rover.parent})")
    return rover, base, nav


def _run(args, cwd: Path, fast: bool):
    """(exit status, stdout lines without the probe line, stderr, numpy imported) of ``insnav`` in a child."""
    env = dict(os.environ, INSNAV_RTK_FASTPATH="1" if fast else "0")
    p = subprocess.run([sys.executable, "-c", _PROBE, *map(str, args)], cwd=cwd, env=env, capture_output=True,
                       text=True)
    lines = p.stdout.splitlines()
    probe = [ln for ln in lines if ln.startswith("NUMPY ")]
    numpy_loaded = probe[-1].split()[1] == "True" if probe else None
    rc = int(probe[-1].split()[2]) if probe else p.returncode  # main's status (the probe itself exits 0)
    return rc, [ln for ln in lines if not ln.startswith("NUMPY ")], p.stderr, numpy_loaded


def _rtk_args(rover, base, nav, toml, out="sol.pos"):
    return ["run", "--filter", "rtk", "--format", "rinex", "--obs", rover, "--base", base, "--nav",
            ",".join(map(str, nav)), "--config", toml, "--out", out, "--quiet"]


def test_rtk_keys_are_the_dataclass_fields_in_order():
    assert [(f.name, f.default) for f in dataclasses.fields(RtkOptions)] == list(RTK_DEFAULTS.items())


def _params():
    out = []
    for p in TOMLS:
        slow = not p.stem.startswith("matrtklib_l1_")  # dual-frequency and the other data: several seconds each
        out.append(pytest.param(p, id=p.stem, marks=[pytest.mark.slow] if slow else []))
    return out


@pytest.mark.parametrize("toml", _params())
def test_fast_path_writes_the_files_of_the_usual_path(toml, tmp_path):
    rover, base, nav = _files(toml.stem)
    systems = next(ln.split("=")[1].strip().strip('"') for ln in toml.read_text().splitlines()
                   if ln.startswith("systems"))
    runs = {}
    for fast in (True, False):
        d = tmp_path / ("fast" if fast else "usual")
        d.mkdir()
        runs[fast] = _run(_rtk_args(rover, base, nav, toml), d, fast)
        assert runs[fast][0] == 0, runs[fast][2]
    assert runs[True][1] == runs[False][1]  # the summary line
    assert runs[True][2] == runs[False][2]  # stderr (nothing)
    assert runs[True][1][0].startswith("sol.pos: ")
    for suffix in ("", ".rtk.csv", ".config.toml"):
        a = (tmp_path / "fast" / f"sol.pos{suffix}").read_text()
        b = (tmp_path / "usual" / f"sol.pos{suffix}").read_text()
        _assert_same_up_to_the_last_digit(a, b, f"sol.pos{suffix}")
    assert sorted(os.listdir(tmp_path / "fast")) == sorted(os.listdir(tmp_path / "usual"))
    assert runs[False][3] is True  # the usual path imports numpy
    # GPS and QZSS settings run without numpy; the others take the usual path (numpy imported)
    assert runs[True][3] is (not set(systems) <= set("GJ"))
    n_lines = len((tmp_path / "fast" / "sol.pos").read_text().splitlines())
    assert n_lines > 6 + 50  # header + rows: the comparison compared solutions


def _assert_same_up_to_the_last_digit(a: str, b: str, name: str):
    """The two files' text is the same except that a number may differ by one unit in its last printed
    digit.  The usual path computes part of its inputs with numpy, whose vectorised math functions may differ
    from the C library's in the last bit (numpy 2.4, np.exp: 4620 of 1e5 values, measured here), so a
    value that falls on a rounding boundary prints differently (a ratio 23.59 against 23.58, measured)."""
    import re

    la, lb = a.splitlines(), b.splitlines()
    assert len(la) == len(lb), f"{name}: {len(la)} against {len(lb)} lines"
    num = re.compile(r"-?\d+\.(\d+)")
    for i, (x, y) in enumerate(zip(la, lb)):
        if x == y:
            continue
        tx, ty = re.split(r"([,\s]+)", x), re.split(r"([,\s]+)", y)
        assert len(tx) == len(ty), f"{name} line {i + 1}: {x!r} against {y!r}"
        for u, v in zip(tx, ty):
            if u == v:
                continue
            mu, mv = num.fullmatch(u), num.fullmatch(v)
            assert mu and mv and len(mu.group(1)) == len(mv.group(1)), f"{name} line {i + 1}: {u!r} against {v!r}"
            assert abs(float(u) - float(v)) <= 1.000001 * 10.0 ** -len(mu.group(1)), \
                f"{name} line {i + 1}: {u} against {v}"


def _bad_input_cases(tmp_path, rover, base, nav, toml):
    good = toml.read_text()
    bad_key = tmp_path / "bad_key.toml"
    bad_key.write_text(good.replace("ratio_threshold", "ratio_treshold"))
    bad_type = tmp_path / "bad_type.toml"
    bad_type.write_text(good.replace("frequencies = 1", 'frequencies = "one"'))
    bad_range = tmp_path / "bad_range.toml"
    bad_range.write_text(good.replace("ratio_threshold = 3.0", "ratio_threshold = 0.5"))
    corrupt = tmp_path / "rover_corrupt.obs"
    lines = rover.read_text().splitlines(keepends=True)
    k = [i for i, ln in enumerate(lines) if ln.startswith(">")][2]  # the third epoch line: a letter in its year
    lines[k] = lines[k][:2] + "2O24" + lines[k][6:]
    corrupt.write_text("".join(lines))
    return {
        "bad_key": _rtk_args(rover, base, nav, bad_key),
        "bad_type": _rtk_args(rover, base, nav, bad_type),
        "bad_range": _rtk_args(rover, base, nav, bad_range),
        "missing_obs": _rtk_args(tmp_path / "no_such.obs", base, nav, toml),
        "missing_config": _rtk_args(rover, base, nav, tmp_path / "no_such.toml"),
        "corrupt_rinex": _rtk_args(corrupt, base, nav, toml),
    }


def test_bad_input_gives_the_usual_message_and_status(tmp_path):
    toml = ROOT / "bench" / "rtk" / "matrtklib_l1_g_inst.toml"
    rover, base, nav = _files(toml.stem)
    cases = _bad_input_cases(tmp_path, rover, base, nav, toml)
    for name, args in cases.items():
        got = {}
        for fast in (True, False):
            d = tmp_path / f"{name}_{'fast' if fast else 'usual'}"
            d.mkdir()
            got[fast] = _run(args, d, fast)
            assert os.listdir(d) == [], f"{name}: a file was written"
        assert got[True][0] == got[False][0] == 2, (name, got)
        assert got[True][2] == got[False][2], name
        assert len(got[True][2].strip().splitlines()) == 1 and got[True][2].startswith("insnav run: error: "), \
            (name, got[True][2])
    assert ", line " in got[True][2] and "2O24" in got[True][2]  # the last case: the reader names the line


def test_other_options_take_the_usual_path(tmp_path):
    toml = ROOT / "bench" / "rtk" / "matrtklib_l1_g_inst.toml"
    rover, base, nav = _files(toml.stem)
    # --timings and a .csv solution are not covered: the usual path runs (numpy imported), exit 0
    for extra, out in ((["--timings"], "sol.pos"), ([], "sol.csv")):
        args = _rtk_args(rover, base, nav, toml, out) + extra
        rc, lines, err, numpy_loaded = _run(args, tmp_path, True)
        assert rc == 0, err
        assert numpy_loaded is True
        assert (tmp_path / out).stat().st_size > 0


def test_an_output_naming_an_input_is_refused_and_the_input_kept(tmp_path):
    toml = ROOT / "bench" / "rtk" / "matrtklib_l1_g_inst.toml"
    rover, base, nav = _files(toml.stem)
    for fast in (True, False):
        d = tmp_path / ("fast" if fast else "usual")
        d.mkdir()
        nav_pos = d / "nav.pos"  # a navigation file whose name ends in .pos, given as --out too
        nav_pos.write_bytes(nav[0].read_bytes())
        rc, lines, err, _ = _run(_rtk_args(rover, base, [nav_pos], toml, out=nav_pos), d, fast)
        assert rc == 2 and err.startswith("insnav run: error: --out ") and "is an input of this run" in err, err
        assert nav_pos.read_bytes() == nav[0].read_bytes()
        assert sorted(os.listdir(d)) == ["nav.pos"]
        # a .pos another program wrote (RTKLIB's own result) is kept: one line, the bytes unchanged,
        # no file beside it; with --overwrite it is replaced
        theirs = b"% program   : RTKPOST ver.2.4.3 b34\n% an older solution\n"
        (d / "old.pos").write_bytes(theirs)
        rc, lines, err, _ = _run(_rtk_args(rover, base, [nav_pos], toml, out="old.pos"), d, fast)
        assert rc == 2 and err == (f"insnav run: error: old.pos exists and is not a file insnav wrote: not "
                                   "replaced (choose another --out, or --overwrite to replace it)\n"), err
        assert (d / "old.pos").read_bytes() == theirs
        assert sorted(os.listdir(d)) == ["nav.pos", "old.pos"]
        rc, lines, err, _ = _run(_rtk_args(rover, base, [nav_pos], toml, out="old.pos") + ["--overwrite"], d, fast)
        assert rc == 0, err
        first = (d / "old.pos").read_bytes()
        assert first.startswith(b"% program   : insnav rtk\n") and first.count(b"\n") > 300
        # the .pos insnav wrote (and its sidecars) is replaced without --overwrite
        (d / "old.pos").write_bytes(first.replace(b"% inp file", b"% older file", 1))
        rc, lines, err, _ = _run(_rtk_args(rover, base, [nav_pos], toml, out="old.pos"), d, fast)
        assert rc == 0, err
        assert (d / "old.pos").read_bytes() == first
        # a user's file under a sidecar's name is kept too
        (d / "new.pos.rtk.csv").write_bytes(b"my,notes\n")
        rc, lines, err, _ = _run(_rtk_args(rover, base, [nav_pos], toml, out="new.pos"), d, fast)
        assert rc == 2 and "new.pos.rtk.csv exists and is not a file insnav wrote" in err, err
        assert (d / "new.pos.rtk.csv").read_bytes() == b"my,notes\n" and not (d / "new.pos").exists()


def test_a_copied_nav_file_with_cr_line_ends_is_left_to_the_usual_path(tmp_path):
    toml = ROOT / "bench" / "rtk" / "matrtklib_l1_g_inst.toml"
    rover, base, nav = _files(toml.stem)
    crlf = tmp_path / "base_crlf.nav"
    crlf.write_bytes(nav[0].read_bytes().replace(b"\r\n", b"\n").replace(b"\n", b"\r\n"))
    res = {}
    for fast in (True, False):
        d = tmp_path / ("fast" if fast else "usual")
        d.mkdir()
        res[fast] = _run(_rtk_args(rover, base, [crlf], toml), d, fast)
    assert res[True][0] == res[False][0]
    assert res[True][1] == res[False][1]
    if res[True][0] == 0:
        for suffix in ("", ".rtk.csv", ".config.toml"):
            assert (tmp_path / "fast" / f"sol.pos{suffix}").read_bytes() == \
                (tmp_path / "usual" / f"sol.pos{suffix}").read_bytes()


def test_ctrl_c_while_writing_leaves_no_file(tmp_path, monkeypatch, capsys):
    import insnav._atomic as atomic
    from insnav.cli import main

    toml = ROOT / "bench" / "rtk" / "matrtklib_l1_g_inst.toml"
    rover, base, nav = _files(toml.stem)
    real, calls = atomic.atomic_write_text, []

    def interrupted_on_the_second_file(path, text):
        calls.append(Path(path).name)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(path, text)

    monkeypatch.setattr(atomic, "atomic_write_text", interrupted_on_the_second_file)
    from insnav import _core

    real_run, runs = _core.rtk_rinex_files, []
    monkeypatch.setattr(_core, "rtk_rinex_files", lambda *a: runs.append(1) or real_run(*a))
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", "1")
    out = tmp_path / "run" / "sol.pos"
    rc = main([str(a) for a in _rtk_args(rover, base, nav, toml, out)])
    assert rc == 130
    assert capsys.readouterr().err == "insnav run: interrupted\n"
    assert runs == [1]  # the fast path ran
    assert calls == ["sol.pos", "sol.pos.rtk.csv"]
    assert os.listdir(out.parent) == []  # neither the first file nor a temporary one is left
