"""The ``insnav`` command line on a small simulated dataset: every
subcommand exits 0 with sensible numbers, user errors exit 2 with one line
naming the problem and no traceback, ``--help`` shows an example and units,
and the demo writes its report.

Most calls go through :func:`insnav.cli.main` in this process (fast); a few go
through ``python -m insnav`` to check the real exit status and stderr.
"""
from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import insnav
from insnav.cli import main

# 60 s of the seed 000 Table 1 motion (pitch 10 deg / 12 s, roll 15 deg / 8 s, a
# 60 deg turn), 200 Hz MEMS IMU, 1 Hz GPS (5 m horizontal) lost from 30 to 40 s.
SHORT_SCENARIO = """\
extends = "seed000-sim"
name = "cli-short"
description = "60 s of the seed000-sim motion, GPS lost 30-40 s"

[[motion.segments]]
duration_s = 40.0
[[motion.segments]]
label = "turn +60 deg"
duration_s = 20.0
heading_change_deg = 60.0

[[motion.oscillations]]
axis = "pitch"
amp_deg = 10.0
period_s = 12.0
start_s = 0.0
end_s = 60.0

[[motion.oscillations]]
axis = "roll"
amp_deg = 15.0
period_s = 8.0
start_s = 0.0
end_s = 60.0

[gnss]
outages = [[30.0, 40.0]]
"""
DURATION_S, IMU_HZ, OUTAGE = 60.0, 200.0, (30.0, 40.0)

# the solution CSV header as documented in docs/formats.md and `insnav run --help`
SOLUTION_HEADER = (
    "t_s,lat_deg,lon_deg,h_m,vn_mps,ve_mps,vd_mps,roll_deg,pitch_deg,yaw_deg,"
    "sigma_n_m,sigma_e_m,sigma_d_m,sigma_vn_mps,sigma_ve_mps,sigma_vd_mps,"
    "sigma_roll_deg,sigma_pitch_deg,sigma_yaw_deg,"
    "acc_bias_x_mps2,acc_bias_y_mps2,acc_bias_z_mps2,gyro_bias_x_dph,gyro_bias_y_dph,gyro_bias_z_dph,"
    "acc_scale_x_ppm,acc_scale_y_ppm,acc_scale_z_ppm,gyro_scale_x_ppm,gyro_scale_y_ppm,gyro_scale_z_ppm")


def _call(argv) -> tuple[int, str, str]:
    """``insnav ARGV`` in this process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse: --help, --version, usage errors
            rc = exc.code if isinstance(exc.code, int) else 1
    return rc, out.getvalue(), err.getvalue()


def _user_error(argv, *needles) -> str:
    """The call fails with status 2 and a single stderr line containing every needle."""
    rc, out, err = _call(argv)
    lines = err.strip().splitlines()
    assert rc == 2, (rc, out, err)
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"insnav {argv[0]}: error: "), err
    for n in needles:
        assert str(n) in lines[0], (n, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("cli")


@pytest.fixture(scope="module")
def scenario_file(work) -> Path:
    p = work / "short.toml"
    p.write_text(SHORT_SCENARIO, encoding="utf-8")
    return p


@pytest.fixture(scope="module")
def dataset(work, scenario_file):
    """``insnav simulate`` of the short scenario: (directory, stdout)."""
    d = work / "ds"
    rc, out, err = _call(["simulate", scenario_file, "--seed", "3", "--out", d])
    assert rc == 0, err
    return d, out


@pytest.fixture(scope="module")
def solution(work, dataset):
    """``insnav run`` with RB-UKF and init seed 4: (csv path, stdout)."""
    out = work / "sol.csv"
    rc, stdout, err = _call(["run", dataset[0], "--filter", "rbukf", "--seed", "4", "--out", out])
    assert rc == 0, err
    return out, stdout


def _csv(path: Path) -> tuple[list, np.ndarray]:
    with open(path, encoding="utf-8") as f:
        header = f.readline().strip().split(",")
    return header, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def _horizontal_error_m(sol_csv: Path, truth_csv: Path) -> np.ndarray:
    """Horizontal position error from the two CSV files, computed here from
    WGS-84 radii at the rows with the same time (independent of insnav.analysis)."""
    hs, s = _csv(sol_csv)
    ht, t = _csv(truth_csv)
    ks = np.rint(s[:, hs.index("t_s")] * IMU_HZ).astype(int)
    kt = np.rint(t[:, ht.index("t_s")] * IMU_HZ).astype(int)
    common, i_s, i_t = np.intersect1d(ks, kt, return_indices=True)
    assert len(common) == len(ks)  # truth at every solution time
    a, e2 = 6378137.0, 6.69437999014e-3
    lat = np.radians(t[i_t, ht.index("lat_deg")])
    h = t[i_t, ht.index("h_m")]
    w = 1.0 - e2 * np.sin(lat) ** 2
    r_m, r_n = a * (1.0 - e2) / w ** 1.5, a / np.sqrt(w)
    dn = np.radians(s[i_s, hs.index("lat_deg")] - t[i_t, ht.index("lat_deg")]) * (r_m + h)
    de = np.radians(s[i_s, hs.index("lon_deg")] - t[i_t, ht.index("lon_deg")]) * (r_n + h) * np.cos(lat)
    return np.hypot(dn, de)


# --- version and help ----------------------------------------------------------------
def test_version():
    rc, out, _ = _call(["--version"])
    assert rc == 0 and out.strip() == f"insnav {insnav.__version__}"


UNIT = re.compile(r"\[(?:s|m|m/s|deg|Hz|1/s)\]|\bm/s\b|\bdeg/h\b")
@pytest.mark.parametrize("command", [
    "", "demo", "run", "evaluate", "compare", "bench",
    "simulate", "scenarios"])
def test_help_shows_an_example_and_units(command):
    rc, out, _ = _call([command, "--help"] if command else ["--help"])
    assert rc == 0
    assert re.search(r"(?i)\bexamples?:", out), out
    assert f"insnav {command}".strip() in out.split("xample", 1)[1]  # the example is a real command line
    assert UNIT.search(out), out


# --- the subcommands on a short simulated dataset ---------------------------------------
def test_scenarios_lists_every_preset_with_its_duration():
    from insnav.sim import list_presets

    rc, out, _ = _call(["scenarios"])
    assert rc == 0
    rows = {line.split()[0]: line for line in out.strip().splitlines()}
    assert sorted(rows) == list_presets()
    assert re.search(r"\b150\.0 s\b", rows["seed000-sim"]) and re.search(r"\b175\.0 s\b", rows["seed001-low"])
    rc, out, _ = _call(["scenarios", "seed000-sim"])
    doc = tomllib.loads(out)
    assert rc == 0 and doc["name"] == "seed000-sim" and doc["imu"]["rate_hz"] == 200.0


def test_simulate_writes_the_short_scenario(dataset, work, scenario_file):
    d, out = dataset
    for f in ("imu.csv", "gnss.csv", "truth.csv", "imu_errors.csv", "scenario.toml", "dataset.json"):
        assert (d / f).is_file(), f
    hi, imu = _csv(d / "imu.csv")
    assert len(imu) == int(DURATION_S * IMU_HZ)
    np.testing.assert_allclose(np.diff(imu[:, hi.index("t_s")]), 1.0 / IMU_HZ, atol=1e-9)
    hg, gnss = _csv(d / "gnss.csv")
    tg = gnss[:, hg.index("t_valid_s")]
    assert not np.any((tg > OUTAGE[0]) & (tg < OUTAGE[1]))  # the outage is honoured
    assert len(tg) == pytest.approx(DURATION_S - (OUTAGE[1] - OUTAGE[0]), abs=2)  # 1 Hz otherwise
    assert f"{len(imu)} IMU samples, {len(tg)} GNSS fixes" in out and "cli-short (seed 3)" in out
    # the same seed gives the same files; --overwrite is required to replace them
    d2 = work / "ds-again"
    assert _call(["simulate", scenario_file, "--seed", "3", "--out", d2])[0] == 0
    assert (d2 / "imu.csv").read_bytes() == (d / "imu.csv").read_bytes()
    assert (d2 / "gnss.csv").read_bytes() == (d / "gnss.csv").read_bytes()
    _user_error(["simulate", scenario_file, "--out", d2], str(d2), "--overwrite")


def test_run_writes_the_documented_csv_and_a_config_that_repeats_it(solution, dataset, work):
    sol, out = solution
    header, a = _csv(sol)
    assert ",".join(header) == SOLUTION_HEADER
    assert len(a) == int(DURATION_S * IMU_HZ)
    n_fixes = len(_csv(dataset[0] / "gnss.csv")[1])
    assert f"{len(a)} rows, filter rbukf, loose coupling; GNSS: {n_fixes} records, {n_fixes} updates used, 0 rejected" in out
    # 1-sigma columns: positive; the north position sigma grows through the outage
    # (free inertial, MEMS IMU) and drops again at the first fix after it
    hs = header.index("sigma_n_m")
    assert np.all(a[:, hs:hs + 9] > 0)
    sig_n = dict(zip(np.rint(a[:, 0] * IMU_HZ).astype(int), a[:, hs]))
    at = lambda t_s: sig_n[int(round(t_s * IMU_HZ))]  # noqa: E731
    assert at(OUTAGE[1] - 0.5) > 1.5 * at(OUTAGE[0] + 0.5) > at(OUTAGE[0] - 0.5)
    assert at(OUTAGE[1] + 1.5) < 0.8 * at(OUTAGE[1] - 0.5)
    cfg_path = Path(str(sol) + ".config.toml")
    cfg = tomllib.loads(cfg_path.read_text(encoding="utf-8"))
    assert cfg["filter"] == "rbukf" and cfg["init_seed"] == 4
    # fed back with --config (no --filter, no --seed): the same solution, byte for byte
    sol2 = work / "sol-again.csv"
    assert _call(["run", dataset[0], "--config", cfg_path, "--out", sol2])[0] == 0
    assert sol2.read_bytes() == sol.read_bytes()


def test_run_config_with_imu_units_round_trips(dataset, work):
    user = work / "user.toml"
    user.write_text('filter = "ekf"\ninit_seed = 2\ngate_chi2 = 22.46\n\n[imu]\n'
                    "gyro_arw_deg_per_sqrt_h = 0.4\nacc_vrw_m_per_s_per_sqrt_h = 0.1\n"
                    "gyro_bias_sigma_deg_per_h = [20.0, 20.0, 25.0]\nacc_bias_sigma_mg = 5.0\n", encoding="utf-8")
    s1, s2 = work / "u1.csv", work / "u2.csv"
    assert _call(["run", dataset[0], "--config", user, "--out", s1])[0] == 0
    resolved = Path(str(s1) + ".config.toml")
    imu = tomllib.loads(resolved.read_text(encoding="utf-8"))["imu"]
    assert imu["gyro_arw_deg_per_sqrt_h"] == pytest.approx([0.4] * 3, rel=1e-12)
    assert imu["gyro_bias_sigma_deg_per_h"] == pytest.approx([20.0, 20.0, 25.0], rel=1e-12)
    assert imu["acc_bias_sigma_mg"] == pytest.approx([5.0] * 3, rel=1e-12)
    assert _call(["run", dataset[0], "--config", resolved, "--out", s2])[0] == 0
    np.testing.assert_allclose(_csv(s2)[1], _csv(s1)[1], rtol=0, atol=1e-9)


def test_evaluate_numbers_match_an_independent_computation(solution, dataset):
    sol, _ = solution
    d = dataset[0]
    rc, out, _ = _call(["evaluate", sol, d, "--json", "--outages", f"{OUTAGE[0]:g}:{OUTAGE[1]:g}"])
    assert rc == 0
    res = json.loads(out)
    hz = _horizontal_error_m(sol, d / "truth.csv")
    assert res["samples"] == len(hz)
    assert res["horizontal_rms_m"] == pytest.approx(np.sqrt(np.mean(hz ** 2)), rel=1e-3)
    assert res["horizontal_max_m"] == pytest.approx(hz.max(), rel=1e-3)
    # 5 m (1 sigma) GPS fixes at 1 Hz: metre-level, not millimetres and not tens of metres
    assert 0.3 < res["horizontal_rms_m"] < 8.0
    assert all(0.2 < c < 3.0 for c in res["consistency"]["pos_n_m"])  # rms(error / sigma) near 1
    (o,) = res["outages"]
    assert (o["start_s"], o["end_s"]) == OUTAGE
    t = np.arange(1, len(hz) + 1) / IMU_HZ
    inside = (t >= OUTAGE[0]) & (t <= OUTAGE[1])
    assert o["max_horizontal_inside_m"] == pytest.approx(hz[inside].max(), rel=1e-3)
    assert math.isfinite(o["reconvergence_s"]) and 0 <= o["reconvergence_s"] <= DURATION_S - OUTAGE[1]
    # the table form prints the same figures with units
    rc, out, _ = _call(["evaluate", sol, d / "truth.csv"])
    assert rc == 0 and f"horizontal RMS {res['horizontal_rms_m']:.4g} m" in out
    assert re.search(r"^position +\[m\] N/E/D: RMS ", out, re.M)
    assert re.search(r"^attitude +\[deg\] roll/pitch/yaw: RMS ", out, re.M)


def test_compare_json_on_a_scenario_file(scenario_file):
    rc, out, err = _call(["compare", scenario_file, "--filters", "ekf,rbukf", "--runs", "2", "--workers", "1",
                          "--seed", "5", "--json", "--compact"])
    assert rc == 0, err
    res = json.loads(out)
    assert res["filters"] == ["ekf", "rbukf"] and res["runs"] == 2 and res["backend"] == "local"
    assert len({(r["sim_seed"], r["init_seed"]) for r in res["per_run"]}) == 2
    for f in ("ekf", "rbukf"):
        for r in res["per_run"]:
            m = r["metrics"][f]
            assert 0.2 < m["pos_n_rmse_m"] < 8.0 and 0.01 < m["vel_n_rmse_mps"] < 1.0
            assert m["pos_n_max_m"] >= m["pos_n_rmse_m"]
            assert m["updates"] == pytest.approx(DURATION_S - (OUTAGE[1] - OUTAGE[0]), abs=2)
    # EKF and RB-UKF see the same data: their errors agree closely (seed 000, Table 1)
    e, u = (res["summary"][f]["pos_n_rmse_m"]["mean"] for f in ("ekf", "rbukf"))
    assert u == pytest.approx(e, rel=0.1)


def test_demo_quick_writes_the_report(work):
    out_dir = work / "demo"
    rc, out, err = _call(["demo", "--quick", "--out", out_dir])
    assert rc == 0, err
    report = (out_dir / "report.md").read_text(encoding="utf-8")
    head = "| filter | time [s] | pos RMS N/E/D [m] | att RMS r/p/y [deg] |"
    assert head in report and head in out
    rows = {line.split("|")[1].strip(): line.split("|")[2:-1] for line in report.splitlines()
            if re.match(r"\| (ekf|rbukf|ukf) \|", line)}
    assert sorted(rows) == ["ekf", "rbukf", "ukf"]
    for f, cells in rows.items():
        pos = [float(x) for x in cells[1].split("/")]
        att = [float(x) for x in cells[2].split("/")]
        assert all(0.1 < p < 10.0 for p in pos), (f, pos)  # 5 m / 10 m GPS, a 40 s outage
        assert all(0.0 < x < 5.0 for x in att), (f, att)
    pngs = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", report)
    assert len(pngs) >= 3
    for name in pngs:
        data = (out_dir / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    assert "insnav demo --seed 1 --quick" in report
    # every PNG the demo writes is linked from report.md, and the HTML report of the RB-UKF run is there
    assert sorted(pngs) == sorted(p.name for p in out_dir.glob("*.png"))
    page = out_dir / "seed000-rbukf-report" / "report.html"
    assert page.is_file() and f"({page.parent.name}/report.html)" in report
    assert page.read_text().count("data:image/png;base64,") == 6
    # the README's command run again replaces its own folder; a user's folder of the same file names
    # is refused, its files untouched
    assert _call(["demo", "--quick", "--out", out_dir])[0] == 0
    mine = work / "mine"
    mine.mkdir()
    (mine / "report.md").write_text("my notes\n")
    rc, _, err = _call(["demo", "--quick", "--out", mine])
    assert rc == 2 and "holds no report.md of an earlier insnav demo" in err, err
    assert [p.name for p in mine.iterdir()] == ["report.md"] and (mine / "report.md").read_text() == "my notes\n"


def test_demo_without_matplotlib_is_one_line(work, monkeypatch):
    for m in [k for k in sys.modules if k == "matplotlib" or k.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, m)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    _user_error(["demo", "--quick", "--out", work / "demo-nomatplotlib"], "matplotlib", "insnav[plot]")


def test_bench_quick(scenario_file):
    rc, out, err = _call(["bench", "--quick", "--repeats", "3", "--mech-duration-s", "60",
                          "--scenario", scenario_file, "--json"])
    assert rc == 0, err
    res = json.loads(out)
    m = res["mechanization"]
    assert m["samples"] == 12000 and m["duration_s"] == pytest.approx(60.0) and len(m["times_s"]) == 3
    assert m["samples_per_s"] == pytest.approx(m["samples"] / m["median_s"])
    assert m["x_real_time"] == pytest.approx(m["samples_per_s"] / IMU_HZ)
    # the C++ loop does 1-3 M samples/s on one core; a median under 5e4 would mean a
    # per-sample Python loop (or a machine too loaded for any figure to mean anything)
    assert m["samples_per_s"] > 5e4
    assert res["scenario"]["duration_s"] == pytest.approx(DURATION_S, abs=0.01)
    assert res["scenario"]["imu_samples"] == int(DURATION_S * IMU_HZ)
    for f in ("ekf", "rbukf"):
        r = res["filters"][f]
        assert r["x_real_time"] == pytest.approx(DURATION_S / r["median_s"], rel=1e-3)
        assert r["x_real_time"] > 10 and 0.3 < r["horizontal_rms_m"] < 8.0
    assert res["command"] == f"insnav bench --quick --repeats 3 --scenario {scenario_file} --mech-duration-s 60 --json"
    # the text form: one table row per filter and the command that reproduces it
    rc, out, _ = _call(["bench", "--repeats", "1", "--mech-duration-s", "5", "--scenario", scenario_file,
                        "--filters", "ekf"])
    assert rc == 0 and re.search(r"^ekf +\d+\.\d{3} +\d+ ", out, re.M)
    assert out.strip().splitlines()[-1] == f"command: insnav bench --repeats 1 --scenario {scenario_file} " \
                                           "--filters ekf --mech-duration-s 5"


# --- user errors: exit 2, one line naming the problem ---------------------------------
@pytest.mark.parametrize("toml, needles", [
    ('filtr = "ekf"\n', ["unknown key 'filtr'", "did you mean 'filter'"]),
    ('zzz = 1\n', ["unknown key 'zzz'", "known keys", "gate_chi2"]),
    ('filter = "kalman"\n', ["'filter'", "'kalman'", "rbukf"]),
    ("gate_chi2 = -1.0\n", ["'gate_chi2'", "-1.0"]),
    ("init_sigma_pos_m = [1.0, 2.0]\n", ["'init_sigma_pos_m'", "3 finite values"]),
    ("[imu]\nacc_bias_sigma_mg = -5\n", ["'imu.acc_bias_sigma_mg'", "-5"]),
    ("[imu]\ngyro_bias_sigma_dph = 5\n", ["unknown key 'imu.gyro_bias_sigma_dph'",
                                          "did you mean 'gyro_bias_sigma_deg_per_h'"]),
    ("filter = \n", ["not valid TOML", "line 1"]),
])
def test_bad_config_is_one_line_naming_the_key(dataset, work, toml, needles):
    cfg = work / "bad.toml"
    cfg.write_text(toml, encoding="utf-8")
    _user_error(["run", dataset[0], "--config", cfg, "--out", work / "never.csv"], str(cfg), *needles)
    assert not (work / "never.csv").exists()


def test_bad_init_seed_names_the_key(dataset, work):
    cfg = work / "seed.toml"
    cfg.write_text("init_seed = -1\n", encoding="utf-8")
    _user_error(["run", dataset[0], "--config", cfg, "--out", work / "never.csv"], "init_seed")


def test_missing_files_and_directories(dataset, solution, work):
    _user_error(["run", work / "no-such-dir", "--out", work / "x.csv"], "dataset directory not found",
                work / "no-such-dir")
    _user_error(["run", dataset[0], "--config", work / "no-such.toml", "--out", work / "x.csv"], "no-such.toml")
    broken = work / "broken-ds"
    broken.mkdir()
    for f in dataset[0].iterdir():
        if f.name != "imu.csv":
            (broken / f.name).write_bytes(f.read_bytes())
    _user_error(["run", broken, "--out", work / "x.csv"], broken / "imu.csv")
    _user_error(["evaluate", work / "no-such.csv", dataset[0]], "not found", work / "no-such.csv")
    _user_error(["evaluate", solution[0], work / "no-truth"], "not found", work / "no-truth")
    # an output path that is a directory (was an IsADirectoryError traceback)
    _user_error(["run", dataset[0], "--out", work], str(work))


def test_bad_values_on_the_command_line(solution, dataset):
    _user_error(["evaluate", solution[0], dataset[0], "--outages", "30-40"], "--outages", "30-40")
    _user_error(["evaluate", solution[0], dataset[0], "--outages", "40:30"], "--outages", "40:30")
    # a file that is not a solution: the header check names the file, line 1 and the missing columns
    _user_error(["evaluate", dataset[0] / "imu.csv", dataset[0]], str(dataset[0] / "imu.csv") + ":1", "lat_deg")
    _user_error(["bench", "--filters", "upf"], "upf", "ekf, rbukf, ukf")
    _user_error(["bench", "--repeats", "0"], "--repeats")
    _user_error(["compare", "seed001-low", "--runs", "1", "--delay-p", "0.7;0.3"], "--delay-p")


@pytest.mark.parametrize("argv", [["simulate", "no-such-preset", "--out", "x"],
                                  ["compare", "no-such-preset", "--runs", "1"],
                                  ["bench", "--scenario", "no-such-preset"]])
def test_unknown_scenario_lists_the_presets(argv):
    from insnav.sim import list_presets

    line = _user_error(argv, "no-such-preset")
    for p in list_presets():
        assert p in line


# --- the real executable: exit status and stderr ------------------------------------------
def _python_m(*args, cwd):
    env = dict(os.environ)  # PYTHONPATH passes through: the source tree under test
    return subprocess.run([sys.executable, "-m", "insnav", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=cwd, timeout=120)


def test_python_m_insnav_exit_status_and_stderr(dataset, tmp_path):
    p = _python_m("--version", cwd=tmp_path)
    assert p.returncode == 0 and p.stdout.strip() == f"insnav {insnav.__version__}"
    bad = tmp_path / "bad.toml"
    bad.write_text("use_velocity = 3\n", encoding="utf-8")
    for args, needle in ((("run", tmp_path / "missing", "--out", "x.csv"), "dataset directory not found"),
                         (("run", dataset[0], "--config", bad, "--out", "x.csv"), "'use_velocity'"),
                         (("simulate", dataset[0] / "scenario.toml", "--out", dataset[0]), "--overwrite")):
        p = _python_m(*args, cwd=tmp_path)
        assert p.returncode == 2, p.stderr
        assert "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
        assert needle in p.stderr and p.stdout == ""
    p = _python_m("run", "--filter", cwd=tmp_path)  # argparse usage error: status 2, usage on stderr
    assert p.returncode == 2 and "Traceback" not in p.stderr and "usage: insnav run" in p.stderr


def test_every_registered_filter_is_in_the_help_and_the_config():
    """One registry (insnav.registry) feeds the CLI help, the config check and
    compare: every name appears in ``run --help``, a config accepts it with its
    couplings and refuses it with the others."""
    from insnav.config import ConfigError, config_from_dict
    from insnav.registry import FILTERS

    rc, out, _ = _call(["run", "--help"])
    help_text = " ".join(out.split())
    for name, spec in FILTERS.items():
        assert f"{name} (" in help_text, name
        for coupling in ("loose", "tight"):
            if coupling in spec.couplings:
                assert config_from_dict({"filter": name, "coupling": coupling}).filter == name
            else:
                with pytest.raises(ConfigError, match="coupling"):
                    config_from_dict({"filter": name, "coupling": coupling})
    with pytest.raises(ValueError, match="known: ekf, rbukf, ukf, kf, rdkf, exact"):
        insnav.montecarlo("seed001-low", ("ekf", "kalman"), runs=1)


def test_rdkf_run_writes_a_config_that_repeats_it(dataset, work):
    """``--filter rdkf`` writes a *.config.toml that load_config accepts and
    that reproduces the run; asking it to couple tightly is a one-line error."""
    out = work / "sol-rdkf.csv"
    rc, stdout, err = _call(["run", dataset[0], "--filter", "rdkf", "--out", out])
    assert rc == 0, err
    cfg_path = Path(str(out) + ".config.toml")
    assert insnav.config.load_config(cfg_path).filter == "rdkf"
    again = work / "sol-rdkf-again.csv"
    assert _call(["run", dataset[0], "--config", cfg_path, "--out", again])[0] == 0
    assert again.read_bytes() == out.read_bytes()
    _user_error(["run", dataset[0], "--filter", "rdkf", "--coupling", "tight", "--out", work / "x.csv"],
                "rdkf", "loosely coupled only")


def test_command_line_process_uses_one_openblas_thread(tmp_path):
    """The CLI sets OPENBLAS_NUM_THREADS=1 before numpy starts its busy-waiting
    pool, unless the user set it; in a process that imported numpy already it
    changes nothing."""
    import os
    import subprocess
    import sys

    code = ("import os, sys; from insnav.cli import _single_threaded_blas; _single_threaded_blas(); "
            "print(os.environ.get('OPENBLAS_NUM_THREADS'))")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    run = lambda e: subprocess.run([sys.executable, "-c", code], env=e, capture_output=True,  # noqa: E731
                                   text=True, check=True).stdout.strip()
    assert run(env) == "1"
    assert run({**env, "OPENBLAS_NUM_THREADS": "4"}) == "4"
    code_after_numpy = "import numpy; " + code
    assert subprocess.run([sys.executable, "-c", code_after_numpy], env=env, capture_output=True, text=True,
                          check=True).stdout.strip() == "None"
