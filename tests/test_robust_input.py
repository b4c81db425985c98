"""Bad input: every reader fault gives a clear error naming file,
line and reason, or a documented repair counted in ``summary["sanitize"]``."""
from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

import insnav
from insnav.config import ConfigError, config_from_dict, load_config
from insnav.data.dataset import ImuData, load_dataset
from insnav.io import kfgins
from insnav.filters.sanitize import sanitize_gnss, sanitize_imu


@pytest.fixture(scope="module")
def ds():
    return insnav.simulate("seed000-sim", seed=1)


@pytest.fixture(scope="module")
def ds_dir(ds, tmp_path_factory):
    return ds.save(tmp_path_factory.mktemp("rob") / "ds")


def _copy(ds_dir, tmp_path):
    d = tmp_path / "ds"
    shutil.copytree(ds_dir, d)
    return d


def _edit_line(path, lineno, fn):
    lines = path.read_text().split("\n")
    lines[lineno - 1] = fn(lines[lineno - 1])
    path.write_text("\n".join(lines))


@pytest.mark.parametrize("fault, pattern", [
    (lambda ln: ln.replace(ln.split(",")[2], "nan"), r"imu\.csv:7: non-finite value nan in column 'dtheta_y_rad'"),
    (lambda ln: ln.replace(ln.split(",")[4], "inf"), r"imu\.csv:7: non-finite value inf in column 'dv_x_mps'"),
    (lambda ln: ln.replace(ln.split(",")[1], "1.2.3"), r"imu\.csv:7: not a number: '1\.2\.3'"),
    (lambda ln: ",".join(ln.split(",")[:5]), r"imu\.csv:7: expected 7 columns, found 5"),
])
def test_dataset_reader_errors_name_file_and_line(ds_dir, tmp_path, fault, pattern):
    d = _copy(ds_dir, tmp_path)
    _edit_line(d / "imu.csv", 7, fault)
    with pytest.raises(ValueError, match=pattern):
        load_dataset(d)


@pytest.mark.parametrize("edit, pattern", [
    (lambda m: m["initial"].pop("lat_deg"), r"dataset\.json: initial: lat_deg missing"),
    (lambda m: m["initial"].__setitem__("v_n_mps", [0, 0]), r"dataset\.json: initial: v_n_mps must be 3 numbers"),
    (lambda m: m["initial"].__setitem__("yaw_deg", "x"), r"dataset\.json: initial: could not convert.*'x'"),
    (lambda m: m.pop("initial"), r"dataset\.json: 'initial' missing"),
    (lambda m: m.pop("t0_s"), r"dataset\.json: t0_s .* missing"),
    (lambda m: m.__setitem__("lever_arm_b_m", [1, 2]), r"dataset\.json: lever_arm_b_m must be 3 numbers"),
])
def test_dataset_json_initial_state_errors_name_file_and_key(ds_dir, tmp_path, edit, pattern):
    import json

    d = _copy(ds_dir, tmp_path)
    meta = json.loads((d / "dataset.json").read_text())
    edit(meta)
    (d / "dataset.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=pattern):
        load_dataset(d)


def test_truncated_file_is_named(ds_dir, tmp_path):
    d = _copy(ds_dir, tmp_path)
    text = (d / "imu.csv").read_text()
    (d / "imu.csv").write_text(text[: len(text) // 2 - 5])
    with pytest.raises(ValueError, match=r"imu\.csv:\d+: expected 7 columns, found \d .*truncated"):
        load_dataset(d)


def test_blank_lines_keep_line_numbers(ds_dir, tmp_path):
    d = _copy(ds_dir, tmp_path)
    lines = (d / "imu.csv").read_text().split("\n")
    lines.insert(3, "")
    lines[9] = lines[9].replace(lines[9].split(",")[3], "nan")  # file line 10
    (d / "imu.csv").write_text("\n".join(lines))
    with pytest.raises(ValueError, match=r"imu\.csv:10: non-finite"):
        load_dataset(d)


def test_duplicate_imu_record_dropped_and_counted(ds, ds_dir, tmp_path):
    d = _copy(ds_dir, tmp_path)
    lines = (d / "imu.csv").read_text().split("\n")
    lines.insert(101, lines[100])
    (d / "imu.csv").write_text("\n".join(lines))
    bad = load_dataset(d)
    sol = insnav.run(bad, init_error=False)
    clean = insnav.run(ds, init_error=False)
    assert sol.summary["sanitize"]["imu_duplicates_dropped"] == 1
    assert clean.summary["sanitize"]["imu_duplicates_dropped"] == 0
    assert np.allclose(sol.lat_deg, clean.lat_deg, atol=1e-9, rtol=0)


def test_decreasing_and_conflicting_times_refused_with_lines(ds_dir, tmp_path):
    d = _copy(ds_dir, tmp_path)
    lines = (d / "imu.csv").read_text().split("\n")
    lines[50], lines[51] = lines[51], lines[50]  # file lines 51, 52 swapped
    (d / "imu.csv").write_text("\n".join(lines))
    with pytest.raises(ValueError, match=r"imu\.csv:52 \(sample 50\): time .* decreases .*imu\.csv:51"):
        insnav.run(load_dataset(d))
    d2 = _copy(ds_dir, tmp_path / "b")
    lines = (d2 / "imu.csv").read_text().split("\n")
    parts = lines[30].split(",")
    parts[1] = "0.5"
    lines.insert(31, ",".join(parts))  # same time, different increments
    (d2 / "imu.csv").write_text("\n".join(lines))
    with pytest.raises(ValueError, match=r"imu\.csv:32 \(sample 30\): repeated time .* different record"):
        insnav.run(load_dataset(d2))


def test_imu_gap_bridged_or_refused(ds):
    imu = ds.imu
    keep = np.ones(len(imu), bool)
    keep[2000:2010] = False  # 50 ms lost
    gap = ImuData(imu.t[keep], imu.dtheta_b[keep], imu.dv_b[keep])
    out, rep = sanitize_imu(gap, t0=ds.t0)
    assert rep["imu_gaps_bridged"] == 1 and rep["imu_samples_inserted"] == 10
    assert np.allclose(out.t, imu.t)
    # interpolated increments are close to the lost ones (smooth motion)
    assert np.abs(out.dv_b[2000:2010] - imu.dv_b[2000:2010]).max() < 1e-3
    sol = insnav.run(dataclasses.replace(ds, imu=gap), init_error=False)
    ref = insnav.run(ds, init_error=False)
    assert sol.summary["sanitize"]["imu_samples_inserted"] == 10
    assert np.abs(sol.h_m[-1] - ref.h_m[-1]) < 0.05
    # an IMU that accumulates over the dropout: kept as is
    dth, dv = imu.dtheta_b.copy(), imu.dv_b.copy()
    dth[2010], dv[2010] = imu.dtheta_b[2000:2011].sum(0), imu.dv_b[2000:2011].sum(0)
    acc = ImuData(imu.t[keep], dth[keep], dv[keep])
    out, rep = sanitize_imu(acc, t0=ds.t0)
    assert rep["imu_gaps_accumulated"] == 1 and rep["imu_samples_inserted"] == 0 and out is acc
    # longer than the limit: refused
    keep[3000:3100] = False
    with pytest.raises(ValueError, match=r"imu: sample \d+: IMU gap of 0\.5.* longer than max_gap_s=0\.1"):
        sanitize_imu(ImuData(imu.t[keep], imu.dtheta_b[keep], imu.dv_b[keep]))
    out, rep = sanitize_imu(ImuData(imu.t[keep], imu.dtheta_b[keep], imu.dv_b[keep]), max_gap_s=1.0)
    assert rep["imu_gaps_bridged"] == 2


def test_absurd_imu_value_refused_with_line(ds_dir, tmp_path):
    d = _copy(ds_dir, tmp_path)
    _edit_line(d / "imu.csv", 41, lambda ln: ln.replace(ln.split(",")[3], "3.0"))  # 600 rad/s
    with pytest.raises(ValueError, match=r"imu\.csv:41 \(sample 39\): angular rate .* exceeds the physical limit"):
        insnav.run(load_dataset(d))
    d = _copy(ds_dir, tmp_path / "b")
    _edit_line(d / "imu.csv", 41, lambda ln: ln.replace(ln.split(",")[6], "-1e6"))
    with pytest.raises(ValueError, match=r"imu\.csv:41 \(sample 39\): specific force"):
        insnav.run(load_dataset(d))


def test_gnss_bad_records_dropped_and_counted(ds, ds_dir, tmp_path):
    d = _copy(ds_dir, tmp_path)
    p = d / "gnss.csv"
    lines = p.read_text().split("\n")
    parts = lines[10].split(",")
    parts[2] = "nan"  # lat of file line 11
    lines[10] = ",".join(parts)
    parts = lines[20].split(",")
    parts[8] = "-1"  # sigma_n of line 21
    lines[20] = ",".join(parts)
    parts = lines[30].split(",")
    parts[5] = "nan"  # vn of line 31: velocity removed, position kept
    lines[30] = ",".join(parts)
    lines.insert(41, lines[40])  # duplicate of line 41
    lines[50], lines[51] = lines[51], lines[50]  # out of order
    p.write_text("\n".join(lines))
    sol = insnav.run(load_dataset(d), init_error=False)
    r = sol.summary["sanitize"]
    assert r["gnss_invalid_dropped"] == 2 and r["gnss_duplicates_dropped"] == 1
    assert r["gnss_velocity_removed"] == 1 and r["gnss_reordered"] >= 1
    assert r["gnss_dropped_lines"][:2] == [11, 21]
    assert len(sol.gnss_t) == len(ds.gnss) - 2 and np.all(np.diff(sol.gnss_t) > 0)
    assert np.isfinite(sol.lat_deg).all()


def test_gnss_out_of_range(ds):
    g = type(ds.gnss).from_array(ds.gnss.to_array())
    g.lat_deg[3] = 91.0
    g.h_m[4] = 1e7
    out, rep = sanitize_gnss(g)
    assert rep["gnss_invalid_dropped"] == 2 and len(out) == len(g) - 2
    out, rep = sanitize_gnss(ds.gnss)
    assert out is ds.gnss and rep["gnss_invalid_dropped"] == 0


def test_sanitize_off_keeps_old_behaviour(ds):
    imu = ds.imu
    t = imu.t.copy()
    t[10] = t[9]
    bad = dataclasses.replace(ds, imu=ImuData(t, imu.dtheta_b, imu.dv_b))
    with pytest.raises(ValueError, match=r"imu\.t: time not strictly increasing at sample 10"):
        insnav.run(bad, sanitize=False)
    with pytest.raises(TypeError, match="unknown option"):
        insnav.run(ds, sanitize={"max_gap": 1})


def test_kfgins_reader_faults(ds, tmp_path):
    p = tmp_path / "imu.txt"
    kfgins.write_kfgins_imu(p, ImuData(ds.imu.t[:50], ds.imu.dtheta_b[:50], ds.imu.dv_b[:50]))
    lines = p.read_text().split("\n")
    lines.insert(10, lines[9])  # duplicate record: passes the reader, dropped by sanitize
    p.write_text("\n".join(lines))
    imu = kfgins.read_kfgins_imu(p)
    out, rep = sanitize_imu(imu)
    assert len(imu) == 51 and rep["imu_duplicates_dropped"] == 1 and len(out) == 50
    lines[20] = lines[20].replace(lines[20].split()[2], "nan")
    p.write_text("\n".join(lines))
    with pytest.raises(ValueError, match=r"imu\.txt:21: non-finite value nan in column 'dtheta_y'"):
        kfgins.read_kfgins_imu(p)
    p.write_text("1 0 0 0 0 0 0\n2 0 0 0 0 0 0\n3 0 0 0 0 0 0\n2 0 0 0 0 0 0\n")
    with pytest.raises(ValueError, match=r"imu\.txt:4: time 2\.0 does not increase \(previous record at 3\.0, line 3\)"):
        kfgins.read_kfgins_imu(p)
    p.write_text("1 0 0 0 0 0 0\n2 0 0 0 0 0 0\n3 0 0 0 0 0 1e3\n")
    with pytest.raises(ValueError, match=r"imu\.txt:3 \(sample 2\): specific force"):
        sanitize_imu(kfgins.read_kfgins_imu(p))
    y = tmp_path / "kf-gins.yaml"
    y.write_text("imupath: a\nstarttime: [1, 2]\n")
    with pytest.raises(ValueError, match=r"kf-gins\.yaml: key 'starttime': expected a finite number"):
        kfgins.read_kfgins_config(y)


@pytest.mark.parametrize("text, pattern", [
    ("gate_chi2 = nan\n", r"run\.toml: config key 'gate_chi2': bad value nan"),
    ("gate_chi2 = 'high'\n", r"run\.toml: config key 'gate_chi2'"),
    ("init_error = 1\n", r"run\.toml: config key 'init_error'"),
    ("imu = 3\n", r"run\.toml: key 'imu'"),
    ("cycle_period_s = -1.0\n", r"config key 'cycle_period_s'"),
    ("output_decimation = 2.5\n", r"config key 'output_decimation'"),
    ("[imu]\ngyro_arw_deg_per_sqrt_h = 'x'\n", r"key 'imu.gyro_arw_deg_per_sqrt_h'"),
    ("[imu]\nacc_bias_rw_mg_per_sqrt_h = \"0.2\"\n", r"key 'imu.acc_bias_rw_mg_per_sqrt_h': bad value '0.2'"),
    ("[imu]\ngyro_arw_deg_per_sqrt_h = [0.1, true, 0.1]\n", r"key 'imu.gyro_arw_deg_per_sqrt_h': bad value"),
    ("[imu]\ngyro_bias_tau_s = 0\n", r"key 'imu.gyro_bias_tau_s': bad value 0; allowed: finite values > 0 \[s\]$"),
    ("[imu]\nacc_scale_tau_s = [100, -1, 100]\n", r"key 'imu.acc_scale_tau_s': bad value \[100, -1, 100\]"),
    ("filter = \n", r"run\.toml: not valid TOML"),
])
def test_run_config_errors(tmp_path, text, pattern):
    p = tmp_path / "run.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=pattern):
        load_config(p)


def test_run_config_valid_unchanged():
    cfg = config_from_dict({"gate_chi2": 22.46, "filter": "rbukf", "lever_arm_b": [0.1, 0.0, -0.2]})
    assert cfg.gate_chi2 == 22.46 and cfg.filter == "rbukf"


def test_max_gap_is_reachable_from_the_toml(tmp_path):
    """An IMU gap longer than the default 0.1 s is refused with a message that
    names the TOML key; [sanitize] max_gap_s in the config lets the run through
    (the gap is bridged), and a bad value is an error naming the key."""
    import dataclasses

    import insnav
    from insnav.config import config_from_dict
    from insnav.data.dataset import ImuData

    ds = insnav.simulate("seed000-sim", seed=1)
    imu = ds.imu
    keep = np.ones(len(imu.t), bool)
    keep[1000:1030] = False  # a 0.15 s gap at 200 Hz
    imu2 = ImuData(imu.t[keep], imu.dtheta_b[keep], imu.dv_b[keep])
    d2 = dataclasses.replace(ds, imu=imu2)
    with pytest.raises(ValueError, match=r"max_gap_s=0\.1 s.*\[sanitize\] max_gap_s"):
        insnav.run(d2, "ekf")
    sol = insnav.run(d2, config=config_from_dict({"filter": "ekf", "sanitize": {"max_gap_s": 0.5}}))
    assert sol.summary["sanitize"]["imu_gaps_bridged"] >= 1
    with pytest.raises(ConfigError, match=r"sanitize\.max_gap_s"):
        config_from_dict({"sanitize": {"max_gap_s": -1}})
    with pytest.raises(ConfigError, match=r"unknown key 'sanitize\.max_gap'"):
        config_from_dict({"sanitize": {"max_gap": 1}})
