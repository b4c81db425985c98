"""What ``insnav evaluate`` / ``report`` / ``compare`` do with inputs that used to give wrong figures
with exit status 0, or cost a file.

* A gap in the solution (epochs without a solution, as RTKLIB leaves out of a ``.pos``) was filled
  with a straight line and scored: the comparison now leaves out the times inside a gap.
* A truth with rows without a time or position, or whose time does not increase, was interpolated
  anyway (attitude figures over the first rows only, NaN totals; 130 m errors from swapped blocks):
  one line naming the file and line now, for every kind of truth (truth.csv, rtk_truth.csv, RTKLIB
  .pos, KF-GINS .nav).
* ``evaluate --out`` replaced any insnav file (another solution, the solution's own ``.rtk.csv``
  and ``.config.toml``, which it reads): it replaces an earlier evaluation only.
* A malformed ``<sol>.rtk.csv`` gave an IndexError or numpy's list of lines.
* A GNSS-only RTK solution written as ``.csv`` was compared with the IMU-centre truth ("do not
  overlap") where the same run as ``.pos`` used the antenna truth.
* ``compare --filters rtk`` was offered and could not run.

Data: the ``rtk-open-sky-car`` simulator preset (600 s), simulated in about a second."""
from __future__ import annotations

import json

import numpy as np
import pytest

from insnav.cli import main


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("eval_inputs") / "sim"
    assert main(["simulate", "rtk-open-sky-car", "--out", str(d), "-q"]) == 0
    return d


def _gnss_rtk(d, out):
    return main(["run", "--filter", "rtk", "--format", "rinex", "--obs", str(d / "rover.obs"), "--base",
                 str(d / "base.obs"), "--nav", str(d / "nav.rnx"), "--out", str(out), "-q"])


def _json(capsys, *argv):
    capsys.readouterr()
    assert main(["evaluate", *map(str, argv), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_a_gap_in_the_solution_is_not_scored(sim, tmp_path, capsys):
    """60 epochs removed from a 600-epoch .pos: 540 compared (was 600, the gap drawn as a line), and
    the figures are those of the full solution at the same epochs."""
    full = tmp_path / "full.pos"
    assert _gnss_rtk(sim, full) == 0
    lines = full.read_text().splitlines(keepends=True)
    head = [ln for ln in lines if ln.startswith("%")]
    body = [ln for ln in lines if not ln.startswith("%")]
    assert len(body) == 600
    gap = tmp_path / "gap.pos"
    gap.write_text("".join(head + body[:300] + body[360:]))
    r_gap, r_full = _json(capsys, gap, sim), _json(capsys, full, sim)
    assert r_full["samples"] == 600 and r_gap["samples"] == 540
    assert r_gap["by_status"]["fixed"]["samples"] == 540
    # the kept epochs are compared exactly as in the full run: the same largest error or a smaller one
    assert r_gap["by_status"]["fixed"]["max_3d_m"] <= r_full["by_status"]["fixed"]["max_3d_m"] + 1e-12


@pytest.mark.parametrize("edit, message", [
    (lambda a: a.__setitem__(slice(5000, 5010), np.nan), "truth.csv:5002: a truth row without a finite time and "
                                                          "position (10 such rows)"),
    (lambda a: a.__setitem__(slice(100, 200), a[200:300].copy()), "truth.csv:202: the truth's time does not increase"),
])
def test_a_truth_with_bad_rows_is_refused_naming_the_line(sim, tmp_path, capsys, edit, message):
    sol = tmp_path / "sol.csv"
    assert main(["run", str(sim), "--filter", "ekf", "--out", str(sol), "-q"]) == 0
    bad = tmp_path / "bad"
    bad.mkdir()
    text = (sim / "truth.csv").read_text().splitlines()
    a = np.array([[float(x) for x in ln.split(",")] for ln in text[1:]])
    edit(a)
    np.savetxt(bad / "truth.csv", a, delimiter=",", header=text[0], comments="", fmt="%.12g")
    capsys.readouterr()
    for truth in (bad, bad / "truth.csv"):
        assert main(["evaluate", str(sol), str(truth)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"insnav evaluate: error: {bad / 'truth.csv'}:") and message in err, err
        assert len(err.splitlines()) == 1


@pytest.fixture(scope="module")
def rtk_pos(sim, tmp_path_factory):
    pos = tmp_path_factory.mktemp("eval_rtk") / "rtk.pos"
    assert _gnss_rtk(sim, pos) == 0
    return pos


def _truth_files(sim, d):
    """The sim's antenna truth as an rtk_truth.csv, an RTKLIB .pos and a KF-GINS .nav, each with its
    rows 100..199 and 200..299 swapped, and the line of the first row out of order."""
    from insnav.analysis.evaluate import _rtk_truth
    from insnav.io.gnss_files import write_pos
    from insnav.io.kfgins import write_kfgins_nav

    text = (sim / "rtk_truth.csv").read_text().splitlines(keepends=True)
    swap = np.r_[0:100, 200:300, 100:200, 300:len(text) - 1]
    (d / "rtk_truth.csv").write_text(text[0] + "".join(text[1 + k] for k in swap))
    tr = _rtk_truth(sim / "rtk_truth.csv")
    t_gps = np.array([float(ln.split(",")[0]) for ln in text[1:]])
    write_pos(d / "t.pos", t_gps[swap], tr.lat_deg[swap], tr.lon_deg[swap], tr.h_m[swap])
    tr.t, tr.lat_deg, tr.lon_deg, tr.h_m = tr.t[swap], tr.lat_deg[swap], tr.lon_deg[swap], tr.h_m[swap]
    write_kfgins_nav(d / "t.nav", tr, week=int(t_gps[0] // 604800))
    # line of row 200 (its time earlier than row 199's): 1 header line in the csv, 3 in the .pos, 0 in the .nav
    return {d / "rtk_truth.csv": 202, d / "t.pos": 204, d / "t.nav": 201}


def test_every_kind_of_truth_out_of_time_order_is_refused_naming_the_line(sim, rtk_pos, tmp_path, capsys):
    """An rtk_truth.csv, RTKLIB .pos or KF-GINS .nav truth whose rows are out of time order was
    interpolated as it was (np.interp assumes increasing times: 2358 m instead of 0.015 m, exit 0); only
    an insnav truth.csv was checked.  Every kind now gets the truth.csv's one line."""
    capsys.readouterr()
    for truth, line in _truth_files(sim, tmp_path).items():
        assert main(["evaluate", str(rtk_pos), str(truth)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"insnav evaluate: error: {truth}:{line}: the truth's time does not increase ("), err
        assert "sort the rows by time" in err and len(err.splitlines()) == 1, err


def test_a_non_finite_rtk_truth_row_names_its_line(sim, rtk_pos, tmp_path, capsys):
    text = (sim / "rtk_truth.csv").read_text().splitlines(keepends=True)
    cells = text[101].split(",")
    cells[2] = "nan"
    text[101] = ",".join(cells)
    bad = tmp_path / "rtk_truth.csv"
    bad.write_text("".join(text))
    capsys.readouterr()
    assert main(["evaluate", str(rtk_pos), str(bad)]) == 2
    assert capsys.readouterr().err == (f"insnav evaluate: error: {bad}:102: a truth row without a finite time and "
                                       "position (1 such rows): remove them\n")
    assert _json(capsys, rtk_pos, sim / "rtk_truth.csv")["rms_3d_m"] < 0.05  # the file as simulated: accepted


def test_evaluate_out_replaces_an_earlier_evaluation_only(sim, tmp_path, capsys):
    sol = tmp_path / "s.csv"
    other = tmp_path / "other.csv"
    for out in (sol, other):
        assert main(["run", str(sim), "--filter", "ekf", "--coupling", "rtk", "--obs", str(sim / "rover.obs"),
                     "--base", str(sim / "base.obs"), "--nav", str(sim / "nav.rnx"), "--out", str(out), "-q"]) == 0
    capsys.readouterr()
    for target, why in ((other, "is an insnav solution, not an evaluation"),
                        (tmp_path / "s.csv.rtk.csv", "is an input of this evaluation"),
                        (tmp_path / "s.csv.config.toml", "is an input of this evaluation")):
        before = target.read_bytes()
        assert main(["evaluate", str(sol), str(sim), "--out", str(target)]) == 2
        assert why in capsys.readouterr().err
        assert target.read_bytes() == before
    ev = tmp_path / "ev.json"
    assert main(["evaluate", str(sol), str(sim), "--out", str(ev)]) == 0
    assert main(["evaluate", str(sol), str(sim), "--out", str(ev)]) == 0  # an earlier evaluation: replaced
    assert json.loads(ev.read_text())["fix_rate"] == 1.0


@pytest.mark.parametrize("text, message", [
    ("", ":1: not an insnav rtk table"),
    ("t_gps_s,status,ratio,n_fix\n", ": no rows (the header only)"),
    ('{"a": 1}\n{"b": 2}\n', ":1: not an insnav rtk table"),
])
def test_a_malformed_rtk_sidecar_is_one_line_naming_it(sim, tmp_path, capsys, text, message):
    sol = tmp_path / "e.csv"
    assert main(["run", str(sim), "--filter", "ekf", "--out", str(sol), "-q"]) == 0
    side = tmp_path / "e.csv.rtk.csv"
    side.write_text(text)
    capsys.readouterr()
    assert main(["evaluate", str(sol), str(sim)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"insnav evaluate: error: {side}") and message in err and len(err.splitlines()) == 1, err


def test_a_gnss_only_rtk_csv_uses_the_antenna_truth_as_its_pos_does(sim, tmp_path, capsys):
    pos, csv = tmp_path / "g.pos", tmp_path / "g.csv"
    assert _gnss_rtk(sim, pos) == 0 and _gnss_rtk(sim, csv) == 0
    r_pos, r_csv = _json(capsys, pos, sim), _json(capsys, csv, sim)
    assert r_csv["samples"] == r_pos["samples"] == 600
    assert abs(r_csv["rms_3d_m"] - r_pos["rms_3d_m"]) < 1e-3 and r_csv["rms_3d_m"] < 0.05


def test_compare_refuses_a_gnss_only_filter(capsys):
    assert main(["compare", "rtk-open-sky-car", "--filters", "rtk", "--runs", "1"]) == 2
    assert "filter 'rtk' is GNSS only" in capsys.readouterr().err


def test_tune_reads_its_reference_before_the_search(sim, tmp_path, capsys):
    """A missing or unreadable ``--reference`` stopped ``insnav tune`` only after its whole search (80
    filter runs), as "cannot read the GNSS file"; it is now one line naming the option, at once."""
    import time

    capsys.readouterr()
    t0 = time.perf_counter()
    assert main(["tune", str(sim), "--reference", str(tmp_path / "none.pos"), "--out", str(tmp_path / "t.toml"),
                 "-q"]) == 2
    assert capsys.readouterr().err == f"insnav tune: error: --reference {tmp_path / 'none.pos'}: not found\n"
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n1,2\n")
    assert main(["tune", str(sim), "--reference", str(bad), "--out", str(tmp_path / "t.toml"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"insnav tune: error: --reference {bad}: {bad}:1: unexpected header"), err
    assert time.perf_counter() - t0 < 20.0  # no search ran (it takes minutes on this drive)
    assert not (tmp_path / "t.toml").exists()


def test_an_rtk_pos_gets_the_slip_counts_of_its_sidecar(tmp_path):
    """An insnav rtk ``.pos`` keeps its Q as the fix status and takes the slip counts of its
    ``<pos>.rtk.csv`` (the report's "cycle slips detected" row): the column sums."""
    from insnav.analysis.evaluate import _read_solution
    from insnav.gnss.rtk import RTK_COLUMNS

    pos = tmp_path / "rtk.pos"
    pos.write_text("%  GPST latitude(deg) longitude(deg) height(m) Q ns sdn(m) sde(m) sdu(m) sdne(m) sdeu(m) sdun(m) "
                   "age(s) ratio\n"
                   "2023/01/08 10:00:00.000 48.780736061 9.173352757 319.8347 2 7 0.01 0.01 0.02 0 0 0 0.00 0.0\n"
                   "2023/01/08 10:00:01.000 48.780783021 9.173350630 319.9041 1 7 0.01 0.01 0.02 0 0 0 0.00 5.1\n")
    slips = [[1, 0, 2, 0, 0, 0], [0, 3, 0, 1, 0, 4]]
    rows = [f"{t},{q},1.0,5,6,7,0.000,4.0,5.0,6.0," + ",".join(map(str, s)) for t, q, s in
            ((100.0, 2, slips[0]), (101.0, 1, slips[1]))]
    (tmp_path / "rtk.pos.rtk.csv").write_text(",".join(RTK_COLUMNS) + "\n" + "\n".join(rows) + "\n")
    sol = _read_solution(pos)
    assert list(sol.fix_status) == [2, 1]
    assert sol.slip_counts == dict(lli=1, geometry_free=3, melbourne_wuebbena=2, doppler=1, gap=0, outlier=4)
    (tmp_path / "rtk.pos.rtk.csv").unlink()
    assert getattr(_read_solution(pos), "slip_counts", None) is None


def test_quality_with_a_truth_that_has_none_is_refused(sim, rtk_pos, capsys):
    """--quality was accepted and ignored with an rtk_truth.csv or x,y,z truth (refused for a dataset folder)."""
    r_e = ",".join((sim / "rtk_truth.csv").read_text().splitlines()[1].split(",")[1:4])
    capsys.readouterr()
    for truth in (sim / "rtk_truth.csv", sim, r_e):
        assert main(["evaluate", str(rtk_pos), str(truth), "--quality", "1"]) == 2
        assert capsys.readouterr().err == "insnav evaluate: error: --quality applies to an RTKLIB .pos truth only\n"
    assert _json(capsys, rtk_pos, rtk_pos, "--quality", "1")["samples"] == 600  # a .pos truth takes it
