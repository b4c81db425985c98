"""KF-GINS text formats: readers on the shared data, writers round trip, error messages."""

import sys

import numpy as np
import pytest

import insnav.sim as sim
from conftest import SHARED_DATA, require_module  # ../shared/data beside the repo, or $INSNAV_SHARED_DATA
from insnav.io import kfgins

DATA = SHARED_DATA / "kfgins"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason=f"KF-GINS shared data not found at {DATA}")


@needs_data
def test_read_real_gnss_and_config():
    g = kfgins.read_kfgins_gnss(DATA / "real" / "GNSS-RTK.txt")
    assert len(g) == 3413 and g.t_valid[0] == 456250.0 and g.t_valid[-1] == 459662.0
    assert g.lat_deg[0] == pytest.approx(30.4447858054)
    assert np.allclose(g.sigma_pos_n[0], [0.010, 0.009, 0.019])
    assert np.all(np.isnan(g.v_n))
    c = kfgins.read_kfgins_config(DATA / "real" / "kf-gins.yaml")
    assert c["imudatarate_hz"] == 200.0 and c["starttime_s"] == 456300.0
    assert np.allclose(c["antlever_b_m"], [0.136, -0.301, -0.184])
    assert c["imunoise"]["arw_rad_per_sqrts"][0] == pytest.approx(np.radians(0.003) / 60.0)
    assert c["imunoise"]["abstd_mps2"][0] == pytest.approx(15e-5)
    assert c["imunoise"]["corrtime_s"] == 4 * 3600.0


@needs_data
def test_read_sim_imu_xz_and_truth():
    imu = kfgins.read_kfgins_imu(DATA / "sim" / "Leador-A15-sim.txt.xz")
    assert len(imu) == 682400
    assert imu.t[0] == pytest.approx(456250.004412029)
    assert np.allclose(np.diff(imu.t[:1000]), 0.005)
    assert np.allclose(imu.dv_b[0], [-0.001767030500, -0.000744447304, -0.048924959380])
    # gravity: the mean z increment at standstill is about -g dt
    assert imu.dv_b[:2000, 2].mean() / 0.005 == pytest.approx(-9.79, abs=0.02)
    tr, week = kfgins.read_kfgins_nav(DATA / "sim" / "truth-sim.nav.xz", return_week=True)
    assert len(tr) == 682400 and week[0] == 0
    assert tr.yaw_deg[0] == pytest.approx(176.36712688)
    c = kfgins.read_kfgins_config(DATA / "sim" / "kf-gins-sim.yaml")
    assert np.allclose(np.degrees(c["initpos"][:2]), [30.4447858349, 114.4718661070])


def test_writers_roundtrip(tmp_path):
    ds = sim.simulate("seed001-low", seed=1)
    kfgins.write_kfgins_imu(tmp_path / "imu.txt.xz", ds.imu)
    imu = kfgins.read_kfgins_imu(tmp_path / "imu.txt.xz")
    assert np.allclose(imu.dtheta_b, ds.imu.dtheta_b, rtol=1e-14, atol=1e-20)
    assert np.allclose(imu.t, ds.imu.t, atol=1e-9)
    kfgins.write_kfgins_gnss(tmp_path / "gnss.txt", ds.gnss, with_velocity=True)
    g = kfgins.read_kfgins_gnss(tmp_path / "gnss.txt")
    assert np.allclose(g.lat_deg, ds.gnss.lat_deg, atol=1e-10) and np.allclose(g.v_n, ds.gnss.v_n,
                                                                              atol=1e-5)
    kfgins.write_kfgins_nav(tmp_path / "t.nav", ds.truth)
    tr = kfgins.read_kfgins_nav(tmp_path / "t.nav")
    assert np.allclose(tr.h_m, ds.truth.h_m, atol=1e-5)
    assert np.allclose(tr.yaw_deg, ds.truth.yaw_deg, atol=1e-8)


def test_reader_errors_name_file_and_line(tmp_path):
    p = tmp_path / "imu.txt"
    p.write_text("1.0 0 0 0 0 0 0\n1.005 0 0 0 0 0 0\n1.010 0 0 oops 0 0 0\n")
    with pytest.raises(ValueError, match=r"imu\.txt:3: not a number: 'oops'"):
        kfgins.read_kfgins_imu(p)
    p.write_text("1.0 0 0 0 0 0 0\n1.005 0 0 0 0 0\n")
    with pytest.raises(ValueError, match=r"imu\.txt:2: expected 7 columns, found 6"):
        kfgins.read_kfgins_imu(p)
    p.write_text("1.0 0 0 0 0 0 0\n0.9 0 0 0 0 0 0\n")
    with pytest.raises(ValueError, match=r"imu\.txt:2: time .* does not increase"):
        kfgins.read_kfgins_imu(p)
    q = tmp_path / "g.txt"
    q.write_text("1 2 3 4 5\n")
    with pytest.raises(ValueError, match=r"g\.txt:1: expected 7 or 13 columns"):
        kfgins.read_kfgins_gnss(q)


_YAML_CASES = [
    'imupath: "./a b.txt"\nimudatalen: 7\nstarttime: 456300\nendtime: -1\n',
    "initpos: [ 30.4447858349, 114.4718661070, 21.0972 ]   # deg deg m\ninitgyrbias: [ 0, 0, 0 ]\nx: []\n",
    "imunoise:\n  arw: [0.003, 0.003, 0.003]          # [deg/sqrt(hr)]\n  corrtime: 4.0\n\nantlever: [ 0.136, -0.301, -0.184 ]\n",
    "a: +5\nb: -0\nc: 1.5e+3\nd: 3.\ne: 'single'\nempty:\nnext: 1\n",
]
#: outside the subset: PyYAML decides (a YAML 1.1 string "1e3", octal, a plain string, a '#' without a
#: space, tabs, a flow mapping, a second nesting level, a document marker, an escape)
_YAML_OTHER = ["a: 1e3\n", "a: 010\n", "a: plain text\n", "a: 5#x\n", "a:\n\tb: 1\n", "a: {b: 1}\n",
               "a:\n  b:\n    c: 1\n", "---\na: 1\n", 'a: "x\\ty"\n', "a: [1, x]\n", "a: 1\n  b: 2\n",
               "a:\n  b: 1\n   c: 2\n", "a: true\n", "a: ~\n", "a: .5\n",
               "# only a comment\n\n"]


@pytest.mark.parametrize("text", _YAML_CASES + ([p.read_text() for p in sorted(DATA.glob("*/*.yaml"))]
                                                 if DATA.is_dir() else []))
def test_plain_yaml_reads_what_pyyaml_reads(text):
    """The KF-GINS subset read without importing PyYAML gives yaml.safe_load's values and types."""
    yaml = require_module("yaml", "yaml")
    got, want = kfgins._plain_yaml(text), yaml.safe_load(text)
    assert got is not None
    assert got == want and repr(got) == repr(want)


@pytest.mark.parametrize("text", _YAML_OTHER)
def test_plain_yaml_leaves_the_rest_to_pyyaml(text):
    assert kfgins._plain_yaml(text) is None


def test_without_pyyaml_kfgins_yaml_reads_and_the_rest_names_the_file(tmp_path, monkeypatch):
    """No PyYAML (not a dependency): KF-GINS's own flat YAML still reads; a file
    beyond it is a one-line error naming the file and what to install."""
    monkeypatch.setitem(sys.modules, "yaml", None)  # import yaml raises ImportError
    good = tmp_path / "kf.yaml"
    good.write_text("imudatarate: 200\ninitpos: [30.0, 114.0, 20.0]\nimunoise:\n  arw: [0.003, 0.003, 0.003]\n")
    cfg = kfgins.read_kfgins_config(good)
    assert cfg["imudatarate_hz"] == 200 and cfg["initpos"][2] == 20.0
    bad = tmp_path / "flow.yaml"
    bad.write_text("imunoise: {arw: 0.003}\n")
    with pytest.raises(ValueError, match=r"flow\.yaml: .*needs PyYAML") as exc:
        kfgins.read_kfgins_config(bad)
    assert len(str(exc.value).splitlines()) == 1


@needs_data
@pytest.mark.parametrize("value", ["-1", "0"])
def test_a_correlation_time_that_is_no_time_is_one_line_naming_the_key(tmp_path, value):
    """``imunoise.corrtime: -1`` ran with exit status 0 and a resolved config that its own re-run
    refused (a tau of -3600 s); 0 stopped mid-run with a FloatingPointError (F = -1/tau)."""
    text = (DATA / "real" / "kf-gins.yaml").read_text()
    lines = [f"  corrtime: {value}" if ln.strip().startswith("corrtime:") else ln for ln in text.splitlines()]
    bad = tmp_path / "kf.yaml"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError) as e:
        kfgins.read_kfgins_config(bad)
    assert str(e.value) == f"{bad}: key 'imunoise.corrtime': {value} h; expected a correlation time > 0 [h]"


@needs_data
@pytest.mark.parametrize("key, value, msg", [
    ("imudatalen", "3", "key 'imudatalen': 3; expected an integer >= 7"),
    ("imudatalen", "7.5", "key 'imudatalen': 7.5; expected an integer >= 7"),
    ("initpos", "[300.44, 114.47, 21.0]", "key 'initpos': [300.44, 114.47, 21.0]; expected latitude [deg] within +-90"),
    # a negative sigma was squared into a positive one; a NaN failed the run late, naming no key
    ("initposstd", "[-0.005, 0.004, 0.008]", "key 'initposstd': a standard deviation or noise density must be >= 0"),
    ("initvel", "[.nan, 0.0, 0.0]", "key 'initvel': expected 3 finite numbers")])
def test_a_yaml_value_no_kfgins_run_can_have_is_one_line_naming_the_key(tmp_path, key, value, msg):
    """``imudatalen: 3`` stopped in the text parser ("need 0 < keep <= ncols", naming no key), 7.5 ran;
    a latitude of 300 deg was refused by the navigation state, naming neither the YAML nor the key."""
    text = (DATA / "real" / "kf-gins.yaml").read_text()
    lines = [f"{key}: {value}" if ln.startswith(f"{key}:") else ln for ln in text.splitlines()]
    assert any(ln.startswith(f"{key}: {value}") for ln in lines)
    bad = tmp_path / "kf.yaml"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError) as e:
        kfgins.read_kfgins_config(bad)
    assert str(e.value).startswith(f"{bad}: {msg}")


@needs_data
def test_imunoise_keys_are_checked_and_read_as_kfgins_reads_them(tmp_path):
    """imunoise: a negative density is refused naming 'imunoise.arw'; 3e-3 (a string to PyYAML's
    YAML 1.1, a number to yaml-cpp and so to KF-GINS) is the number 0.003."""
    text = (DATA / "real" / "kf-gins.yaml").read_text()
    import re

    arw = re.search(r"^( +arw: *)\[([^\]]*)\]", text, re.M)
    assert arw is not None
    good = kfgins.read_kfgins_config(DATA / "real" / "kf-gins.yaml")["imunoise"]["arw_rad_per_sqrts"]
    values = [float(x) for x in arw.group(2).split(",")]
    sci = tmp_path / "sci.yaml"
    sci.write_text(text.replace(arw.group(0), arw.group(1) + "[" + ", ".join(f"{v:e}" for v in values) + "]"))
    np.testing.assert_allclose(kfgins.read_kfgins_config(sci)["imunoise"]["arw_rad_per_sqrts"], good, rtol=1e-12)
    neg = tmp_path / "neg.yaml"
    neg.write_text(text.replace(arw.group(0), arw.group(1) + "[" + ", ".join(str(-v) for v in values) + "]"))
    with pytest.raises(ValueError, match=r"neg.yaml: key 'imunoise.arw': a standard deviation or noise density "
                                         r"must be >= 0"):
        kfgins.read_kfgins_config(neg)
