"""RTKLIB .pos files: the header's height kind is honoured (mean sea level
needs a geoid undulation), a record with a missing field is refused, and both
.pos readers (fixes and reference) are one."""
import subprocess
import sys

import numpy as np
import pytest

from insnav.config import ConfigError
from insnav.io.gnss_files import GnssFileError, GnssFileFormat, read_pos, read_rtklib_pos, write_pos

T0 = 2_000 * 604_800.0 + 345_600.0  # GPS seconds


def _pos(path, height_kind="ellipsoidal", n=20):
    k = np.arange(n)
    write_pos(path, T0 + k, 30.5 + 1e-6 * k, 114.3 + 1e-6 * k, 20.0 + 0.01 * k, sigma_pos_n=np.full((n, 3), 0.02),
              v_n=np.zeros((n, 3)), sigma_vel_n=np.full((n, 3), 0.01))
    text = path.read_text()
    path.write_text(text.replace("height=WGS84/ellipsoidal", f"height=WGS84/{height_kind}"))
    return path


def test_geodetic_header_is_msl_refused_without_undulation_and_used_with_it(tmp_path):
    ell = read_pos(_pos(tmp_path / "ell.pos"))
    msl = _pos(tmp_path / "msl.pos", "geodetic")
    for read in (lambda: read_pos(msl), lambda: read_rtklib_pos(msl)):
        with pytest.raises(ConfigError, match=r"msl\.pos:2: the header says height=WGS84/geodetic .*"
                                              r"geoid_undulation_m"):
            read()
    n_m = -16.5  # geoid height: h = H + N
    got = read_pos(msl, GnssFileFormat(format="pos", geoid_undulation_m=n_m))
    np.testing.assert_allclose(got.h_m, ell.h_m + n_m, atol=1e-9)
    assert got.info["height"] == "geodetic" and ell.info["height"] == "ellipsoidal"
    ref_e, ref_m = read_rtklib_pos(tmp_path / "ell.pos"), read_rtklib_pos(msl, geoid_undulation_m=n_m)
    from insnav import earth

    _, _, h_e = earth.ecef_to_geodetic(ref_e.r_e)
    _, _, h_m = earth.ecef_to_geodetic(ref_m.r_e)
    np.testing.assert_allclose(h_m, h_e + n_m, atol=1e-6)
    # the config saying msl for a file whose header says ellipsoidal: a contradiction, not a 2nd undulation
    with pytest.raises(ConfigError, match="header says height=WGS84/ellipsoidal"):
        read_pos(tmp_path / "ell.pos", GnssFileFormat(format="pos", height="msl", geoid_undulation_m=n_m))


def test_other_datum_is_refused(tmp_path):
    p = _pos(tmp_path / "tokyo.pos")
    p.write_text(p.read_text().replace("height=WGS84/", "height=Tokyo/"))
    with pytest.raises(GnssFileError, match="tokyo.pos, line 2: .*datum Tokyo"):
        read_pos(p)


def test_both_readers_agree_and_the_reference_reader_is_the_fixes_reader(tmp_path):
    p = _pos(tmp_path / "a.pos")
    fixes, ref = read_pos(p), read_rtklib_pos(p)
    from insnav import earth

    lat, lon, h = earth.ecef_to_geodetic(ref.r_e)
    np.testing.assert_allclose(ref.t_gps_s, fixes.t_ref_s + fixes.t_s, atol=1e-6)
    np.testing.assert_allclose(np.rad2deg(lat), fixes.lat_deg, atol=1e-10)
    np.testing.assert_allclose(np.rad2deg(lon), fixes.lon_deg, atol=1e-10)
    np.testing.assert_allclose(h, fixes.h_m, atol=1e-6)


@pytest.mark.parametrize("drop", [2, 3, 4])  # latitude, longitude, height
def test_a_record_with_a_missing_field_is_refused_naming_its_line(tmp_path, drop):
    p = _pos(tmp_path / "m.pos")
    lines = p.read_text().splitlines()
    f = lines[10].split()
    del f[drop]
    lines[10] = " ".join(f)
    p.write_text("\n".join(lines) + "\n")
    for read in (read_pos, read_rtklib_pos):
        with pytest.raises(GnssFileError, match=r"m\.pos, line 11: 23 fields where the header has 24"):
            read(p)


def test_evaluate_refuses_the_msl_reference_and_the_short_line(tmp_path):
    """`insnav evaluate` reads a .pos reference through the same reader."""
    sol = tmp_path / "sol.csv"
    rows = [f"{T0 % 604_800.0 + k:.3f},30.5,114.3,20,0,0,0,0,0,0" for k in range(20)]
    sol.write_text("t_s,lat_deg,lon_deg,h_m,vn_mps,ve_mps,vd_mps,roll_deg,pitch_deg,yaw_deg\n" + "\n".join(rows) + "\n")
    short = _pos(tmp_path / "short.pos")
    lines = short.read_text().splitlines()
    f = lines[10].split()
    del f[3]  # the longitude: the height would be read as a longitude of 20 deg (1601 deg on the walk)
    lines[10] = " ".join(f)
    short.write_text("\n".join(lines) + "\n")
    for ref, needle in ((_pos(tmp_path / "msl.pos", "geodetic"), "height=WGS84/geodetic"),
                        (short, "short.pos, line 11: 23 fields")):
        r = subprocess.run([sys.executable, "-m", "insnav", "evaluate", str(sol), str(ref)],
                           capture_output=True, text=True)
        assert r.returncode == 2 and needle in r.stderr and len(r.stderr.splitlines()) == 1, r.stderr
    r = subprocess.run([sys.executable, "-m", "insnav", "evaluate", str(sol), str(tmp_path / "ell.pos")]
                       if _pos(tmp_path / "ell.pos") else [], capture_output=True, text=True)
    assert r.returncode == 0 and "20 samples compared" in r.stdout, r.stderr


def test_kfgins_yaml_true_is_not_a_number(tmp_path):
    from insnav.io.kfgins import read_kfgins_config

    y = tmp_path / "k.yaml"
    y.write_text("imupath: imu.txt\ngnsspath: gnss.txt\nantlever: [true, 0.0, 0.1]\n")
    with pytest.raises(ValueError, match="k.yaml: key 'antlever': expected a list of 3 numbers, got \\[True"):
        read_kfgins_config(y)
