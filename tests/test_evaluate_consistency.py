"""insnav evaluate flags sigmas that do not describe the errors: rms(error/sigma)
per axis outside 0.5-2 (analysis.evaluate.CONSISTENCY_BOUNDS)."""
from __future__ import annotations

import copy
import subprocess
import sys

import numpy as np
import pytest

import insnav
from insnav.analysis.evaluate import CONSISTENCY_BOUNDS, consistency_flags, evaluate


@pytest.fixture(scope="module")
def run():
    ds = insnav.simulate("seed000-sim", seed=2)
    return ds, insnav.run(ds, filter="ekf")


def test_a_consistent_ekf_is_not_flagged_and_shrunk_sigmas_are(run):
    ds, sol = run
    res = evaluate(sol, ds.truth)
    pos = res["consistency"]["pos_n_m"]
    assert all(CONSISTENCY_BOUNDS[0] < c < CONSISTENCY_BOUNDS[1] for c in pos)
    assert "pos_n_m" not in res["consistency_flags"]
    # the same errors with sigmas 5x too small: every position axis 5x larger, flagged overconfident
    shrunk = copy.copy(sol)
    shrunk.sigma_pos_n_m = sol.sigma_pos_n_m / 5.0
    res5 = evaluate(shrunk, ds.truth)
    np.testing.assert_allclose(res5["consistency"]["pos_n_m"], 5.0 * np.asarray(pos), rtol=1e-12)
    flagged = res5["consistency_flags"]["pos_n_m"]
    assert [i for i, _, _ in flagged] == [i for i in range(3) if 5.0 * pos[i] > CONSISTENCY_BOUNDS[1]]
    assert all(kind == "overconfident" for _, _, kind in flagged)


def test_flags_name_the_axis_and_the_direction():
    flags = consistency_flags({"pos_n_m": [3.3, 7.3, 1.0], "vel_n_mps": [0.4, 1.0, 2.0]})
    assert flags == {"pos_n_m": [(0, 3.3, "overconfident"), (1, 7.3, "overconfident")],
                     "vel_n_mps": [(0, 0.4, "pessimistic")]}


def test_cli_prints_one_warning_line_per_flagged_quantity(run, tmp_path):
    ds, sol = run
    shrunk = copy.copy(sol)
    shrunk.sigma_pos_n_m = sol.sigma_pos_n_m / 50.0
    shrunk.save(tmp_path / "sol.csv")
    ds.save(tmp_path / "ds")
    out = subprocess.run([sys.executable, "-m", "insnav", "evaluate", str(tmp_path / "sol.csv"),
                          str(tmp_path / "ds")], capture_output=True, text=True, check=True).stdout
    warn = [ln for ln in out.splitlines() if ln.startswith("WARNING: position")]
    assert len(warn) == 1 and warn[0].count("overconfident") == 3, out  # N, E and D, on one line


@pytest.mark.parametrize("text, msg", [
    ("34.25,108.95,nan", "bad position [34.25, 108.95, nan]; give three finite numbers"),
    ("400,108.95,400", "position [400.0, 108.95, 400.0] is neither ECEF (|r| near 6371 km) nor lat,lon,h")])
def test_a_point_truth_that_is_no_place_on_earth_is_refused(text, msg):
    """``insnav evaluate SOL 34.25,108.95,nan`` printed "3-D RMS nan m" with exit status 0, and a latitude
    of 400 deg read as ECEF a 6.38e6 m error; the point is checked as ``--base-pos`` is."""
    from insnav.analysis.evaluate import static_truth
    from insnav.config import ConfigError

    with pytest.raises(ConfigError) as e:
        static_truth(text, np.arange(3.0))
    assert str(e.value) == f"truth {text!r}: {msg}"
    t = static_truth("34.25,108.95,400", np.arange(3.0))
    assert t.lat_deg[0] == 34.25 and t.h_m[2] == 400.0


def test_a_solution_or_truth_with_no_rows_is_one_line_naming_it(tmp_path, capsys):
    """A CSV with its header line only: evaluate and report stopped with "IndexError: index 0 is out of
    bounds" (the first epoch of an empty array), naming no file."""
    from insnav.cli import main
    from insnav.data.dataset import Truth

    sol = tmp_path / "sol.csv"
    sol.write_text("t_s,lat_deg,lon_deg,h_m,vn_mps,ve_mps,vd_mps,roll_deg,pitch_deg,yaw_deg\n")
    truth = tmp_path / "truth.csv"
    truth.write_text(",".join(Truth.COLUMNS) + "\n")
    for argv, name in ((["evaluate", sol, "34.25,108.95,400"], sol), (["report", sol, "--out", tmp_path / "r"], sol)):
        assert main([str(a) for a in argv]) == 2
        assert capsys.readouterr().err == f"insnav {argv[0]}: error: {name}: no rows\n"
    sol.write_text(sol.read_text() + "0,34.25,108.95,400,0,0,0,0,0,0\n1,34.25,108.95,400,0,0,0,0,0,0\n")
    assert main(["evaluate", str(sol), str(truth)]) == 2
    assert capsys.readouterr().err == f"insnav evaluate: error: {truth}: no rows\n"
    assert not (tmp_path / "r").exists()
