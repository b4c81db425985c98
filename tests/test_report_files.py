"""``insnav report`` and ``evaluate`` never cost a file, and read what ``run``
reads and writes: the report is written into a temporary folder renamed at
the end (a failed write leaves no PNG without its report.html and an earlier
report as it was), refuses a folder that is an input or not a report (unless
``--overwrite``); ``--gnss`` takes the .pos / NMEA files ``run`` takes;
KF-GINS ``.nav`` results (insnav's own ``--out-format kfgins`` and KF-GINS's)
are solutions for ``evaluate``, ``report`` and ``load_solution``."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import insnav
from insnav.cli import main

pytest.importorskip("matplotlib", reason="insnav report needs matplotlib")


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    from insnav.sim.scenario import resolve_raw

    raw, _ = resolve_raw("seed000-sim")
    raw["motion"]["segments"] = [{"duration_s": 30.0}]
    raw["motion"].pop("oscillations", None)
    raw["gnss"]["outages"] = [[12.0, 18.0]]
    d = tmp_path_factory.mktemp("rep")
    ds_dir = insnav.simulate(raw, seed=1).save(d / "ds")
    assert main(["run", str(ds_dir), "--out", str(d / "sol.csv"), "-q"]) == 0
    assert main(["run", str(ds_dir), "--out", str(d / "kf"), "--out-format", "kfgins", "-q"]) == 0
    return d, ds_dir


def _run(capsys, *argv):
    rc = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return rc, out, err


def _tree(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())} if folder.is_dir() else None


def test_report_replaces_an_earlier_report_and_refuses_other_folders(work, tmp_path, capsys):
    d, ds_dir = work
    sol = d / "sol.csv"
    out = tmp_path / "rep"
    rc, _, err = _run(capsys, "report", sol, "--truth", ds_dir, "--out", out)
    assert rc == 0, err
    first = _tree(out)
    assert "report.html" in first and "track.png" in first
    rc, _, err = _run(capsys, "report", sol, "--gnss", ds_dir, "--out", out)  # no truth: fewer figures
    assert rc == 0, err
    second = _tree(out)
    assert second != first and set(second) <= set(first) and "report.html" in second
    assert [p.name for p in tmp_path.iterdir()] == ["rep"]  # no temporary folder left beside it
    # a user's folder: refused before any work, untouched; --overwrite writes the report files into it
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "thesis.tex").write_text("\\documentclass{article}")
    rc, _, err = _run(capsys, "report", sol, "--truth", ds_dir, "--out", mine)
    assert rc == 2 and "is not an insnav report folder" in err and "--overwrite" in err, err
    assert _tree(mine) == {"thesis.tex": b"\\documentclass{article}"}
    rc, _, err = _run(capsys, "report", sol, "--truth", ds_dir, "--out", mine, "--overwrite")
    assert rc == 0 and _tree(mine)["thesis.tex"] == b"\\documentclass{article}" and "report.html" in _tree(mine)
    # an input, even with --overwrite: the dataset folder, or a folder holding the solution as report.html
    before = _tree(ds_dir)
    rc, _, err = _run(capsys, "report", sol, "--gnss", ds_dir, "--out", ds_dir, "--overwrite")
    assert rc == 2 and "is an input of this report" in err and _tree(ds_dir) == before, err
    odd = tmp_path / "odd"
    odd.mkdir()
    (odd / "report.html").symlink_to(sol)
    rc, _, err = _run(capsys, "report", sol, "--out", odd, "--overwrite")
    assert rc == 2 and "is an input of this report" in err, err


def _report_with_file_size_limit(capsys, limit, *argv):
    """``insnav report`` with no file allowed past ``limit`` bytes (RLIMIT_FSIZE:
    EFBIG, as ENOSPC on a full disk), the limit lifted again afterwards."""
    import resource
    import signal

    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        return _run(capsys, "report", *argv)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old)


def test_a_failed_report_leaves_no_figure_and_the_earlier_report(work, tmp_path, capsys):
    """The page inlines every figure, so it is the largest file: a size limit
    between the largest PNG and the page fails it after the PNGs were made."""
    d, ds_dir = work
    out = tmp_path / "rep"
    rc, _, err = _run(capsys, "report", d / "sol.csv", "--truth", ds_dir, "--out", tmp_path / "probe")
    assert rc == 0, err
    probe = _tree(tmp_path / "probe")
    largest_png = max(len(b) for k, b in probe.items() if k.endswith(".png"))
    assert len(probe["report.html"]) > largest_png + 2000
    for earlier in (False, True):
        if earlier:
            (tmp_path / "probe").rename(out)
        before = _tree(out)
        rc, _, err = _report_with_file_size_limit(capsys, largest_png + 1000, d / "sol.csv", "--truth", ds_dir,
                                                  "--out", out)
        assert rc == 2 and "File too large" in err and len(err.strip().splitlines()) == 1, err
        assert _tree(out) == before  # nothing (no PNG without its page), or the earlier report byte for byte
        assert sorted(p.name for p in tmp_path.iterdir()) == (["rep"] if earlier else ["probe"])


def test_report_gnss_takes_the_pos_file_run_takes(work, tmp_path, capsys):
    from insnav.analysis.report import _read_fixes
    from insnav.data.dataset import load_dataset
    from insnav.io.gnss_files import write_pos

    d, ds_dir = work
    g = load_dataset(ds_dir).gnss
    week = 2300
    pos = write_pos(tmp_path / "fixes.pos", week * 604_800.0 + g.t_valid, g.lat_deg, g.lon_deg, g.h_m,
                    sigma_pos_n=g.sigma_pos_n, v_n=g.v_n, sigma_vel_n=g.sigma_vel_n)
    a, b = _read_fixes(ds_dir / "gnss.csv"), _read_fixes(pos)
    np.testing.assert_allclose(b.t, a.t, atol=6e-4)  # .pos time: 1 ms; seconds of week as the solution has them
    np.testing.assert_allclose(b.lat_deg, a.lat_deg, atol=1e-9)
    np.testing.assert_allclose(b.h_m, a.h_m, atol=1e-4)
    np.testing.assert_allclose(b.sigma_pos_n, a.sigma_pos_n, atol=1e-4)
    rc, out, err = _run(capsys, "report", d / "sol.csv", "--gnss", pos, "--out", tmp_path / "r")
    assert rc == 0 and (tmp_path / "r" / "report.html").is_file(), err


def test_kfgins_nav_results_are_solutions(work, capsys):
    """insnav's own --out-format kfgins result reads back as the CSV solution
    of the same run (to the KF-GINS layout's 9 decimals), sigmas and IMU
    errors from the files beside it; evaluate and report take it."""
    from insnav.filters.solution import load_solution

    d, ds_dir = work
    a, b = load_solution(d / "sol.csv"), load_solution(d / "kf" / "KF_GINS_Navresult.nav")
    np.testing.assert_allclose(b.t, a.t, atol=1e-9)
    np.testing.assert_allclose(b.lat_deg, a.lat_deg, atol=1e-9)
    np.testing.assert_allclose(b.v_n, a.v_n, atol=1e-6)
    np.testing.assert_allclose(b.yaw_deg, a.yaw_deg, atol=1e-6)
    np.testing.assert_allclose(b.sigma_pos_n_m, a.sigma_pos_n_m, atol=1e-6)
    np.testing.assert_allclose(b.acc_bias_mps2, a.acc_bias_mps2, atol=1e-8)
    np.testing.assert_allclose(b.gyro_bias_rps, a.gyro_bias_rps, atol=1e-11)
    assert len(b.gnss_t) == len(a.gnss_t) > 0  # its innovations sidecar
    rc, out_csv, err = _run(capsys, "evaluate", d / "sol.csv", ds_dir, "--json")
    rc2, out_nav, err2 = _run(capsys, "evaluate", d / "kf" / "KF_GINS_Navresult.nav", ds_dir, "--json")
    assert rc == rc2 == 0, (err, err2)
    ea, eb = json.loads(out_csv), json.loads(out_nav)
    np.testing.assert_allclose(eb["rms"]["pos_n_m"], ea["rms"]["pos_n_m"], rtol=1e-6)
    rc, _, err = _run(capsys, "report", d / "kf" / "KF_GINS_Navresult.nav", "--truth", ds_dir)
    assert rc == 0 and (d / "kf" / "KF_GINS_Navresult.nav-report" / "report.html").is_file(), err


def test_kfgins_own_result_is_a_solution(shared_data):
    """KF-GINS's own result file (its "%-15.9lf " layout, week 0) reads as a solution."""
    from insnav.filters.solution import load_solution
    from insnav.io.kfgins import read_kfgins_nav

    nav = shared_data / "kfgins" / "sim" / "kfgins_results" / "KF_GINS_Navresult_outage4_10Hz.nav.xz"
    if not nav.is_file():
        pytest.skip(f"{nav} not found")
    s, t = load_solution(nav), read_kfgins_nav(nav)
    assert len(s.t) > 1000 and np.all(np.diff(s.t) > 0) and np.isnan(s.sigma_pos_n_m).all()
    np.testing.assert_array_equal(s.lat_deg, t.lat_deg)
    np.testing.assert_array_equal(s.v_n, t.v_n)
    np.testing.assert_array_equal(s.yaw_deg, t.yaw_deg)


def test_evaluate_out_never_replaces_an_input_or_a_users_file(work, tmp_path, capsys):
    d, ds_dir = work
    sol = d / "sol.csv"
    before = sol.read_bytes()
    for target in (sol, d / "sol.csv.innovations.csv", ds_dir / "truth.csv"):
        rc, _, err = _run(capsys, "evaluate", sol, ds_dir, "--out", target, "--overwrite")
        assert rc == 2 and "is an input of this evaluation" in err, err
    assert sol.read_bytes() == before
    notes = tmp_path / "notes.json"
    notes.write_text('{"mine": 1}\n')
    rc, _, err = _run(capsys, "evaluate", sol, ds_dir, "--out", notes)
    assert rc == 2 and "not a file insnav wrote" in err and notes.read_text() == '{"mine": 1}\n', err
    ev = tmp_path / "ev.json"
    rc, printed, err = _run(capsys, "evaluate", sol, ds_dir, "--out", ev, "--json")
    assert rc == 0 and json.loads(ev.read_text()) == json.loads(printed), err
    rc, _, err = _run(capsys, "evaluate", sol, ds_dir, "--out", ev, "--outages", "12:18")  # its own file: replaced
    assert rc == 0 and json.loads(ev.read_text())["outages"][0]["start_s"] == 12.0, err
