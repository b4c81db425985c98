"""The files beside ``--out`` are the last run's set: a sidecar an earlier run to the same name wrote and
this run does not (the per-satellite residuals of a tight run, before a loose one) is removed with the
renames, not left to be read as this run's (``insnav report`` drew the tight run's residuals for the
loose solution).  A file insnav did not write is never removed."""
from __future__ import annotations

import pytest

from insnav._atomic import atomic_write_text, output_set
from insnav.cli import main

from conftest import short_tight_dataset


def _ours(path) -> bool:
    return path.read_text().startswith("ours")


def test_replaces_removes_the_stale_files_that_are_ours_at_commit_only(tmp_path):
    written, stale, foreign = tmp_path / "a.csv", tmp_path / "a.csv.residuals.csv", tmp_path / "a.csv.rtk.pos"
    for p in (written, stale):
        p.write_text("ours, old\n")
    foreign.write_text("RTKLIB's\n")
    with pytest.raises(RuntimeError):  # a failed command: nothing written, nothing removed
        with output_set() as s:
            s.replaces([written, stale, foreign], _ours)
            atomic_write_text(written, "ours, new\n")
            raise RuntimeError("disk full")
    assert written.read_text() == "ours, old\n" and stale.exists() and foreign.exists()
    with output_set() as s:
        s.replaces([written, stale, foreign, tmp_path / "absent.csv"], _ours)
        atomic_write_text(written, "ours, new\n")
        assert stale.exists()  # removed with the renames, not before
    assert written.read_text() == "ours, new\n" and not stale.exists() and foreign.read_text() == "RTKLIB's\n"


def test_a_loose_run_after_a_tight_one_leaves_no_residuals_of_the_tight_run(tmp_path, capsys):
    d = tmp_path / "ds"
    short_tight_dataset(60.0).save(d)
    out = tmp_path / "sol.csv"
    assert main(["run", str(d), "--coupling", "tight", "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    residuals = tmp_path / "sol.csv.residuals.csv"
    assert residuals.stat().st_size > 100
    assert main(["run", str(d), "--coupling", "loose", "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("sol")) == [
        "sol.csv", "sol.csv.config.toml", "sol.csv.innovations.csv"]
    assert 'coupling = "loose"' in (tmp_path / "sol.csv.config.toml").read_text()
