"""No way to lose a user's files, and one-line errors: --overwrite replaces
only an insnav dataset folder holding nothing else; outputs follow the umask;
JSON carries null, not Infinity; a closed pipe exits quietly; an error is one
line with exit code 2 (the traceback with --debug)."""
import json
import os
import stat
import subprocess
import sys

import numpy as np
import pytest

import insnav
from insnav.data.dataset import check_replaceable, load_dataset


def _cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "insnav", *args], capture_output=True, text=True, timeout=300, **kw)


@pytest.fixture(scope="module")
def small():
    from insnav.sim.scenario import resolve_raw

    raw, _ = resolve_raw("seed000-sim")
    raw["motion"]["segments"] = [{"duration_s": 20.0}]
    raw["motion"].pop("oscillations", None)
    raw["gnss"]["outages"] = []
    return insnav.simulate(raw, seed=1)


def test_overwrite_never_deletes_a_users_folder(tmp_path, small):
    thesis = tmp_path / "thesis"
    (thesis / "figures").mkdir(parents=True)
    (thesis / "thesis.tex").write_text("\\\\documentclass{article}")
    r = _cli("simulate", "seed000-sim", "--out", str(thesis), "--overwrite")
    assert r.returncode == 2 and "not an insnav dataset" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert (thesis / "thesis.tex").is_file() and (thesis / "figures").is_dir()
    # an insnav dataset is replaced; one with a user's file in it is not
    ds_dir = small.save(tmp_path / "ds")
    small.save(ds_dir, overwrite=True)
    (ds_dir / "solution.csv").write_text("t_s\n1\n")
    with pytest.raises(FileExistsError, match="did not write.*solution.csv"):
        small.save(ds_dir, overwrite=True)
    assert (ds_dir / "solution.csv").is_file()
    with pytest.raises(FileExistsError, match="exists"):
        check_replaceable(ds_dir, overwrite=False)


def test_outputs_follow_the_umask_and_json_has_no_infinity(tmp_path, small):
    old = os.umask(0o022)
    try:
        out = small.save(tmp_path / "ds")
        sol = insnav.run(load_dataset(out))
        sol.save_csv(tmp_path / "sol.csv")
    finally:
        os.umask(old)
    assert stat.S_IMODE(out.stat().st_mode) == 0o755
    assert stat.S_IMODE((out / "imu.csv").stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "sol.csv").stat().st_mode) == 0o644
    text = (out / "dataset.json").read_text()
    assert "Infinity" not in text and "NaN" not in text
    json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    # the infinite correlation times come back as inf
    back = load_dataset(out)
    assert np.all(np.isinf(back.imu_model["gyro_gm_tau"])) == np.all(np.isinf(small.imu_model["gyro_gm_tau"]))


def test_closed_pipe_is_quiet():
    r = subprocess.run(f"{sys.executable} -m insnav scenarios | head -n 1", shell=True, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and "Broken pipe" not in r.stderr and "Traceback" not in r.stderr


def test_errors_are_one_line_with_exit_code_2(tmp_path, small):
    d = small.save(tmp_path / "ms")
    imu = (d / "imu.csv").read_text().splitlines()
    rows = [imu[0]] + [",".join([repr(float(r.split(",")[0]) * 1000.0)] + r.split(",")[1:]) for r in imu[1:]]
    (d / "imu.csv").write_text("\n".join(rows) + "\n")  # IMU time in ms
    r = _cli("run", str(d), "--out", str(tmp_path / "sol.csv"))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "imu" in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "sol.csv").exists()
    r = _cli("--debug", "run", str(d), "--out", str(tmp_path / "sol.csv"))
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_rejected_run_is_an_error_unless_allowed(tmp_path, small):
    """Every fix 200 m off (a datum or lever-arm blunder) with the innovation
    gate on: all updates are rejected, so the run exits 2 with the reason and
    writes no solution, unless --allow-free-inertial.  --out on a folder fails
    before the run."""
    d = small.save(tmp_path / "off")
    lines = (d / "gnss.csv").read_text().splitlines()
    dlat = 200.0 / 6.37e6 * 180.0 / np.pi
    off = [lines[0]] + [",".join(r.split(",")[:2] + [repr(float(r.split(",")[2]) + dlat)] + r.split(",")[3:])
                        for r in lines[1:]]
    (d / "gnss.csv").write_text("\n".join(off) + "\n")
    cfg = tmp_path / "gate.toml"
    cfg.write_text("gate_chi2 = 22.5\n")  # chi-square, 6 rows, 0.999
    r = _cli("run", str(d), "--config", str(cfg), "--out", str(tmp_path / "sol.csv"))
    assert r.returncode == 2 and "rejected by the innovation gate" in r.stderr, (r.stdout, r.stderr)
    assert not (tmp_path / "sol.csv").exists()
    r = _cli("run", str(d), "--config", str(cfg), "--out", str(tmp_path / "sol.csv"), "--allow-free-inertial")
    assert r.returncode == 0 and "rejected by the gate" in r.stdout and (tmp_path / "sol.csv").is_file()
    out_dir = tmp_path / "a_folder"
    out_dir.mkdir()
    r = _cli("run", str(d), "--out", str(out_dir))
    assert r.returncode == 2 and "is a folder" in r.stderr


def test_run_takes_a_config_dict_or_toml_and_evaluate_needs_an_overlap(tmp_path):
    """insnav.run(ds, config=dict | TOML path) is the same run as with a
    RunConfig; a truth on another time base is one clear error."""
    import copy

    import numpy as np

    import insnav
    from insnav.config import RunConfig

    ds = insnav.simulate("seed001-low", seed=1)
    ref = insnav.run(ds, config=RunConfig(filter="rbukf", init_seed=2))
    a = insnav.run(ds, config={"filter": "rbukf", "init_seed": 2})
    (tmp_path / "run.toml").write_text('filter = "rbukf"\ninit_seed = 2\n')
    b = insnav.run(ds, config=tmp_path / "run.toml")
    np.testing.assert_array_equal(a.lat_deg, ref.lat_deg)
    np.testing.assert_array_equal(b.lat_deg, ref.lat_deg)
    tr = copy.copy(ds.truth)
    tr.t = tr.t + 1e5
    with pytest.raises(ValueError, match="do not overlap in time"):
        insnav.evaluate(ref, tr)
