"""One initial-state policy for every format: a state the user gives is taken
as given; only the simulator's exact truth is perturbed by default (init_error
= "auto"), as a real alignment would be.  And dataset.json keys are checked."""
from __future__ import annotations

import json

import numpy as np
import pytest

import insnav
from insnav.config import ConfigError, RunConfig


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    ds = insnav.simulate("seed000-sim", seed=7)
    d = ds.save(tmp_path_factory.mktemp("pol") / "ds")
    return ds, d


def _first_row_offset_m(sol, initial) -> float:
    """Horizontal distance [m] of the first output row from the given initial state (5 ms later)."""
    dn = (sol.lat_deg[0] - initial.lat_deg) * np.pi / 180 * 6.37e6
    de = (sol.lon_deg[0] - initial.lon_deg) * np.pi / 180 * 6.37e6 * np.cos(np.radians(initial.lat_deg))
    v = np.hypot(*initial.v_n[:2])
    return float(np.hypot(dn, de) - v * (sol.t[0] - 0.0))


def test_user_state_is_taken_as_given_and_simulated_truth_is_perturbed(saved):
    ds, d = saved
    assert ds.initial_is_truth and insnav.load_dataset(d).initial_is_truth
    drawn = insnav.run(ds, filter="ekf", init_seed=1)
    assert abs(_first_row_offset_m(drawn, ds.initial)) > 0.1  # a 2 m-sigma draw, not the truth
    meta = json.loads((d / "dataset.json").read_text())
    meta["initial_is_truth"] = False  # what a user's own dataset.json says (or omits)
    (d / "dataset.json").write_text(json.dumps(meta))
    user = insnav.load_dataset(d)
    given = insnav.run(user, filter="ekf", init_seed=1)
    assert abs(_first_row_offset_m(given, user.initial)) < 0.01
    del meta["initial_is_truth"]
    (d / "dataset.json").write_text(json.dumps(meta))
    assert not insnav.load_dataset(d).initial_is_truth
    forced = insnav.run(user, filter="ekf", init_seed=1, init_error=True)  # asked for: drawn
    np.testing.assert_allclose(forced.lat_deg[:10], drawn.lat_deg[:10], rtol=0, atol=1e-12)
    with pytest.raises(ConfigError, match="init_error"):
        RunConfig(init_error="sometimes").validate()


@pytest.mark.parametrize("edit, needle", [
    (lambda m: m.update(imu_modle=m.pop("imu_model")), "unknown key 'imu_modle'; did you mean 'imu_model'"),
    (lambda m: m["initial"].update(lat=m["initial"].pop("lat_deg")), "unknown key 'initial.lat'"),
    (lambda m: m.update(initial_is_truth="yes"), "initial_is_truth must be true or false"),
])
def test_dataset_json_keys_are_checked(saved, tmp_path, edit, needle):
    ds, _ = saved
    d = ds.save(tmp_path / "x")
    meta = json.loads((d / "dataset.json").read_text())
    edit(meta)
    (d / "dataset.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=needle) as exc:
        insnav.load_dataset(d)
    assert "dataset.json" in str(exc.value)


def test_every_run_checks_positions_against_velocities(saved):
    """insnav.run on any dataset: fixes whose longitude moves against the
    reported east velocity (a flipped sign after the first fix) are refused
    before the filter, in one line naming the cause."""
    import copy

    ds, _ = saved
    bad = copy.deepcopy(ds)
    lon0 = bad.gnss.lon_deg[0]
    bad.gnss.lon_deg = 2 * lon0 - np.asarray(bad.gnss.lon_deg)  # mirrored about the first fix
    with pytest.raises(ValueError, match="longitude sign looks flipped"):
        insnav.run(bad, filter="ekf")
