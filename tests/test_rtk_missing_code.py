"""A satellite with carrier phase but without its code on a frequency (a blank ``C1C`` field, RINEX's
"missing"): its ambiguity is initialised from the geometry, which must carry the single-differenced
receiver clock that the code-initialised ambiguities carry (gnss/rtk.hpp and engine/rtk_ins_engine.hpp
``init_amb``).  Without it, once that satellite was the reference, every double difference held the
clock (up to 300 km): on WTZZ - WTZR with G05's C1C blanked, 0 of 120 epochs fixed, errors up to
290 m and 3160 "outlier" resets, exit 0, where RTKLIB fixes 118 of 120."""
from __future__ import annotations

import numpy as np
import pytest

from insnav.cli import main

from conftest import SHARED_DATA

W = SHARED_DATA / "euref_wettzell_wtzr_wtzz"
ROVER = W / "WTZZ00DEU_R_20201770000_01D_30S_MO_120epoch.rnx"
BASE = W / "WTZR00DEU_R_20201770000_01D_30S_MO_120epoch.rnx"
NAV = W / "ESBC00DNK_R_20201770000_01D_MN.rnx"
BASE_POS = "4075580.3564,931854.0647,4801568.3345"  # WTZR antenna point (ECEF [m])

pytestmark = pytest.mark.skipif(not W.is_dir(), reason=f"shared data not found: {W}")


def _blank_code(src, dst, sat: str, obs_type: str):
    """``src`` with the ``obs_type`` field of every ``sat`` line blanked (16 spaces)."""
    lines = src.read_text().splitlines()
    types = next(ln for ln in lines if ln.startswith(sat[0]) and "SYS / # / OBS TYPES" in ln).split()[2:]
    k = types.index(obs_type)
    out = [ln[:3 + 16 * k] + " " * 16 + ln[3 + 16 * (k + 1):] if ln.startswith(sat) else ln for ln in lines]
    dst.write_text("\n".join(out) + "\n")
    return dst


def _run(tmp_path, capsys, rover, name):
    out = tmp_path / f"{name}.pos"
    assert main(["run", "--filter", "rtk", "--format", "rinex", "--obs", str(rover), "--base", str(BASE),
                 "--nav", str(NAV), "--base-pos", BASE_POS, "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    a = np.loadtxt(out, comments="%", usecols=(2, 3, 4, 5))
    return a[:, :3], a[:, 3].astype(int)


@pytest.mark.parametrize("fastpath", ["1", "0"])
def test_a_satellite_without_l1_code_leaves_the_solution_as_it_was(tmp_path, capsys, monkeypatch, fastpath):
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", fastpath)
    rover = _blank_code(ROVER, tmp_path / "rover.rnx", "G05", "C1C")
    assert "G05" in rover.read_text() and rover.read_text() != ROVER.read_text()
    pos, q = _run(tmp_path, capsys, rover, "blank")
    pos0, q0 = _run(tmp_path, capsys, ROVER, "as_recorded")
    assert np.all(q0 == 1) and np.all(q == 1) and q.size == 120
    # lat, lon [deg] and h [m]: within 1 mm of the run on the file as recorded
    dn = np.radians(pos[:, 0] - pos0[:, 0]) * 6.37e6
    de = np.radians(pos[:, 1] - pos0[:, 1]) * 6.37e6 * np.cos(np.radians(pos0[:, 0]))
    assert np.abs(dn).max() < 1e-3 and np.abs(de).max() < 1e-3 and np.abs(pos[:, 2] - pos0[:, 2]).max() < 1e-3


def test_a_zero_pseudorange_is_a_missing_one_for_spp(tmp_path, capsys):
    """G05's C1C written as 0.000 (as some writers mark a missing observation): before, SPP stopped with
    "no epoch could be solved" (every epoch held G05's 0 m as a measurement).  Now the run equals the one
    on the file with the field blank, and every epoch is solved."""
    zero = tmp_path / "zero.rnx"
    lines = _blank_code(ROVER, tmp_path / "blank.rnx", "G05", "C1C").read_text().splitlines()
    types = next(ln for ln in lines if ln.startswith("G") and "SYS / # / OBS TYPES" in ln).split()[2:]
    k = types.index("C1C")
    zero.write_text("\n".join(ln[:3 + 16 * k] + f"{0.0:14.3f}  " + ln[3 + 16 * (k + 1):] if ln.startswith("G05")
                              else ln for ln in lines) + "\n")
    assert "         0.000  " in zero.read_text()
    out = {}
    for name, f in (("blank", tmp_path / "blank.rnx"), ("zero", zero)):
        out[name] = tmp_path / f"{name}.csv"
        assert main(["run", "--filter", "spp", "--format", "rinex", "--obs", str(f), "--nav", str(NAV), "--out",
                     str(out[name])]) == 0
        assert "120 of 120 epochs solved" in capsys.readouterr().out
    a, b = (np.genfromtxt(out[n], delimiter=",", names=True) for n in ("blank", "zero"))
    for col in ("lat_deg", "lon_deg", "h_m"):
        np.testing.assert_array_equal(a[col], b[col])


@pytest.mark.parametrize("system", ["E", "C"])
def test_a_zero_approx_position_without_gps_is_bootstrapped_from_the_other_systems(tmp_path, capsys, system):
    """APPROX POSITION XYZ written as zeros (unknown) and a Galileo-only or BeiDou-only run: the start
    position was bootstrapped from GPS satellites only, so the run stopped with "no observation has a GPS
    ephemeris".  Now it starts from the centroid of the run's own satellites: every epoch solved, each
    within 1 mm of the run on the file with the header's position."""
    lines = ROVER.read_text().splitlines()
    zero = tmp_path / "zero.rnx"
    zero.write_text("\n".join(f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}".ljust(60) + "APPROX POSITION XYZ"
                              if ln[60:].startswith("APPROX POSITION XYZ") else ln for ln in lines) + "\n")
    assert zero.read_text() != ROVER.read_text()
    cfg = tmp_path / "sys.toml"
    cfg.write_text(f'[gnss]\nsystems = ["{system}"]\n')
    out = {}
    for name, f in (("header", ROVER), ("zero", zero)):
        out[name] = tmp_path / f"{name}.csv"
        assert main(["run", "--filter", "spp", "--format", "rinex", "--obs", str(f), "--nav", str(NAV), "--config",
                     str(cfg), "--out", str(out[name])]) == 0
        assert f"120 of 120 epochs solved, filter spp ({system}," in capsys.readouterr().out
    a, b = (np.genfromtxt(out[n], delimiter=",", names=True) for n in ("header", "zero"))
    assert np.abs(a["h_m"] - b["h_m"]).max() < 1e-3
    assert np.abs(a["lat_deg"] - b["lat_deg"]).max() * 1.11e5 < 1e-3
    assert np.abs(a["lon_deg"] - b["lon_deg"]).max() * 0.73e5 < 1e-3


@pytest.mark.parametrize("fastpath", ["1", "0"])
def test_a_repeated_rover_epoch_gives_no_repeated_row(tmp_path, capsys, monkeypatch, fastpath):
    """An epoch written twice in the rover file: before, the solution had 121 rows with one time twice.
    Now one warning line names the repeat, and the solution equals the one on the file as recorded."""
    monkeypatch.setenv("INSNAV_RTK_FASTPATH", fastpath)
    lines = ROVER.read_text().splitlines()
    starts = [i for i, ln in enumerate(lines) if ln.startswith("> ")]
    a, b = starts[3], starts[4]
    twice = tmp_path / "twice.rnx"
    twice.write_text("\n".join(lines[:b] + lines[a:b] + lines[b:]) + "\n")
    pos0, q0 = _run(tmp_path, capsys, ROVER, "as_recorded")
    out = tmp_path / "twice.pos"
    assert main(["run", "--filter", "rtk", "--format", "rinex", "--obs", str(twice), "--base", str(BASE),
                 "--nav", str(NAV), "--base-pos", BASE_POS, "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert f"warning: {twice}, line {b + 1}: this epoch repeats the time of the one before it" in err
    pos = np.loadtxt(out, comments="%", usecols=(2, 3, 4))
    assert pos.shape == pos0.shape == (120, 3)
    np.testing.assert_array_equal(pos, pos0)
