"""Dataset directory: save/load round trip, atomic write, CLI."""
import os

import numpy as np
import pytest

import insnav.sim as sim
from insnav.data.dataset import load_dataset, read_csv, ImuData


def test_save_load_roundtrip(tmp_path):
    ds = sim.simulate("seed003-1sat", seed=4)
    out = ds.save(tmp_path / "d")
    names = sorted(os.listdir(out))
    assert names == ["dataset.json", "gnss.csv", "gnss_raw.csv", "imu.csv", "imu_errors.csv",
                     "scenario.toml", "truth.csv"]
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".")]  # no temp dir left
    back = load_dataset(out)
    assert np.array_equal(back.imu.dtheta_b, ds.imu.dtheta_b)
    assert np.array_equal(back.imu.t, ds.imu.t)
    assert np.array_equal(back.truth.lat_deg, ds.truth.lat_deg)
    assert np.array_equal(back.gnss.t_arrival, ds.gnss.t_arrival)
    assert np.array_equal(back.gnss_raw.pseudorange_m, ds.gnss_raw.pseudorange_m)
    assert np.array_equal(back.gnss_raw.prn, ds.gnss_raw.prn)
    assert np.array_equal(back.imu_errors.gyro_bias, ds.imu_errors.gyro_bias)
    assert np.array_equal(back.initial.v_n, ds.initial.v_n)
    assert (back.initial.lat_deg, back.initial.yaw_deg) == (ds.initial.lat_deg, ds.initial.yaw_deg)
    assert back.t0 == ds.t0 and back.gps_time_offset_s == ds.gps_time_offset_s
    assert back.imu_model == ds.imu_model
    assert back.scenario["seed"] == 4
    # the resolved scenario reproduces the dataset
    again = sim.simulate(out / "scenario.toml")
    assert np.array_equal(again.imu.dv_b, ds.imu.dv_b)
    with pytest.raises(FileExistsError):
        ds.save(out)
    ds.save(out, overwrite=True)
    assert load_dataset(out).name == "seed003-1sat"


def test_bad_csv_reports_file_and_line(tmp_path):
    p = tmp_path / "imu.csv"
    p.write_text(",".join(ImuData.COLUMNS) + "\n0.01,1,2,3,4,5,6\n0.02,1,2,x,4,5,6\n")
    with pytest.raises(ValueError, match=r"imu\.csv:3: not a number: 'x'"):
        read_csv(p, ImuData.COLUMNS)
    p.write_text(",".join(ImuData.COLUMNS) + "\n0.01,1,2,3,4,5,6\n0.02,1,2,3,4,5\n")
    with pytest.raises(ValueError, match=r"imu\.csv:3: expected 7 columns, found 6"):
        read_csv(p, ImuData.COLUMNS)
    p.write_text("t,a\n1,2\n")
    with pytest.raises(ValueError, match=r"imu\.csv:1: unexpected header"):
        read_csv(p, ImuData.COLUMNS)


def test_cli_simulate_and_scenarios(tmp_path, capsys):
    from insnav.cli import main

    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    assert "seed000-sim" in out and "seed004-uav" in out
    assert main(["simulate", "seed001-low", "--seed", "3", "--out", str(tmp_path / "x")]) == 0
    assert load_dataset(tmp_path / "x").seed == 3
    assert main(["simulate", "nope", "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err
    assert "unknown preset 'nope'" in err and "seed001-high" in err


@pytest.mark.parametrize("edit, msg", [
    (lambda m: m["imu_model"].update(gyro_arw=[-1.0, 0.0, 0.0]),
     "key 'imu_model.gyro_arw': bad value [-1.0, 0.0, 0.0]; allowed: finite numbers >= 0"),
    (lambda m: m["imu_model"].update(gyro_gm_tau=[0.0, None, None]),
     "key 'imu_model.gyro_gm_tau': bad value [0.0, None, None]; allowed: numbers > 0 or null (infinite)"),
    (lambda m: m.update(gps_time_offset_s=None), "key 'gps_time_offset_s': expected a finite number, got None")])
def test_a_dataset_json_value_no_imu_or_clock_can_have_is_one_line_naming_the_key(tmp_path, edit, msg):
    """A negative ``gyro_arw`` in dataset.json ran with exit status 0 (and another NIS); a null
    ``gps_time_offset_s`` gave "TypeError: float() argument ..." naming neither file nor key.  Signed
    entries (the constant biases) stay signed."""
    import json

    from conftest import short_tight_dataset
    from insnav.data.dataset import load_dataset

    d = tmp_path / "ds"
    short_tight_dataset(20.0).save(d)
    meta = json.loads((d / "dataset.json").read_text())
    meta["imu_model"]["gyro_bias"] = [1e-5, -1e-5, 0.0]  # a constant bias: either sign
    (d / "dataset.json").write_text(json.dumps(meta))
    assert load_dataset(d).imu_model["gyro_bias"] == [1e-5, -1e-5, 0.0]
    edit(meta)
    (d / "dataset.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError) as e:
        load_dataset(d)
    assert str(e.value) == f"{d / 'dataset.json'}: {msg}"


def test_scenario_paths_seeds_and_preset_names(tmp_path, monkeypatch):
    """A child's relative [gnss_raw] constellation is the child's folder's (it was read from the
    parent's), and made absolute so that the dataset's scenario.toml repeats; a seed above 2**53
    is exact (it was rounded through a float, two seeds gave one dataset); a folder named like a
    preset does not hide the preset, and a folder given as the scenario is named as one."""
    from insnav.sim.scenario import ScenarioError, load_scenario, resolve_raw

    (tmp_path / "base").mkdir()
    (tmp_path / "proj").mkdir()
    (tmp_path / "base" / "parent.toml").write_text('name = "parent"\n[gnss_raw]\nconstellation = "p.21n"\n')
    (tmp_path / "proj" / "child.toml").write_text('extends = "../base/parent.toml"\n[gnss_raw]\n'
                                                  'constellation = "c.21n"\n')
    raw, _ = resolve_raw(tmp_path / "proj" / "child.toml")
    assert raw["gnss_raw"]["constellation"] == str((tmp_path / "proj" / "c.21n").resolve())
    raw, _ = resolve_raw(tmp_path / "base" / "parent.toml")
    assert raw["gnss_raw"]["constellation"] == str((tmp_path / "base" / "p.21n").resolve())
    big = 2 ** 53 + 1
    assert load_scenario("seed000-sim", seed=big).seed == big
    assert load_scenario({"extends": "seed000-sim", "seed": big}).seed == big
    monkeypatch.chdir(tmp_path)
    (tmp_path / "seed000-sim").mkdir()
    assert load_scenario("seed000-sim").name == "seed000-sim"
    with pytest.raises(ScenarioError, match="scenario file 'proj' is a directory"):
        load_scenario("proj")


def test_overwrite_through_a_symlink_and_from_inside_the_dataset(tmp_path, monkeypatch):
    """--out a symlink to a dataset with --overwrite left a hidden ``.lnk.old-PID`` link (rmtree cannot
    remove a symlink); --out . inside the dataset gave the raw "[Errno 16] Device or resource busy"."""
    ds = sim.simulate("seed003-1sat", seed=4)
    target = ds.save(tmp_path / "tgt")
    link = tmp_path / "lnk"
    link.symlink_to(target, target_is_directory=True)
    ds.save(link, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lnk", "tgt"]  # the link replaced, its target kept
    assert not link.is_symlink() and load_dataset(link).name == load_dataset(target).name == "seed003-1sat"
    monkeypatch.chdir(target)
    with pytest.raises(FileExistsError, match=r"^\. is the current folder: not replaced from inside; run from "
                                              r"outside it or choose another --out$"):
        ds.save(".", overwrite=True)
    assert sorted(os.listdir(tmp_path)) == ["lnk", "tgt"] and (target / "imu.csv").is_file()
