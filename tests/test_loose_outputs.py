"""The output path of the loosely coupled run (its in-place speed-ups): the unit
conversions done in place in insnav.run and the ``sigma_columns`` key of
``_core.run_loose`` give exactly the numbers of the plain formulas."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import insnav
import insnav.filters.loose
import insnav.sim as sim
from insnav import _core

RAD2DEG = 180.0 / np.pi


@pytest.fixture(scope="module")
def ds():
    """seed000-sim (150 s, 200 Hz, GNSS 1 Hz with an outage) with a 0.5 m lever arm."""
    sc = copy.deepcopy(sim.simulate("seed000-sim", seed=0, with_truth=False).scenario)
    sc["gnss"]["lever_arm_b_m"] = [0.3, -0.2, -0.4]
    return insnav.simulate(sc, seed=3)


class _Capture:
    """insnav._core with run_loose's arguments and raw result kept."""

    def __init__(self, module):
        self.module = module

    def run_loose(self, *args):
        self.args = args
        self.out = self.module.run_loose(*args)
        self.raw = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.out.items()}
        return self.out

    def __getattr__(self, name):
        return getattr(self.module, name)


@pytest.mark.parametrize("filt,layout", [("ekf", 21), ("rbukf", 15)])
def test_solution_equals_plain_conversions(ds, filt, layout, monkeypatch):
    cap = _Capture(_core)
    monkeypatch.setattr(insnav.filters.loose, "_core", cap)
    sol = insnav.run(ds, filter=filt, layout=layout)
    raw = cap.raw
    np.testing.assert_array_equal(sol.lat_deg, raw["llh"][:, 0] * RAD2DEG)
    np.testing.assert_array_equal(sol.lon_deg, raw["llh"][:, 1] * RAD2DEG)
    np.testing.assert_array_equal(sol.h_m, raw["llh"][:, 2])
    np.testing.assert_array_equal(sol.roll_deg, raw["rpy"][:, 0] * RAD2DEG)
    np.testing.assert_array_equal(sol.yaw_deg, raw["rpy"][:, 2] * RAD2DEG)
    np.testing.assert_array_equal(sol.sigma_pos_n_m, raw["sigma"][:, 0:3])
    np.testing.assert_array_equal(sol.sigma_vel_n_mps, raw["sigma"][:, 3:6])
    np.testing.assert_array_equal(sol.sigma_att_deg, raw["sigma"][:, 6:9] * RAD2DEG)
    np.testing.assert_array_equal(sol.gyro_scale, raw["imu_err"][:, 9:12])

    # sigma_columns: the leading columns of the full sigma array, everything else identical
    args = list(cap.args)  # ..., imu_model, config, constraints
    head, config, constraints = args[:-2], args[-2], args[-1]
    full = _core.run_loose(*head, {**config, "sigma_columns": 0}, constraints)
    assert full["sigma"].shape[1] == args[1]
    for k in (9, 3):
        part = _core.run_loose(*head, {**config, "sigma_columns": k}, constraints)
        assert part["sigma"].shape == (len(full["t"]), k)
        np.testing.assert_array_equal(part["sigma"], full["sigma"][:, :k])
        for key in ("t", "llh", "v_n", "rpy", "imu_err", "innovation", "nis", "status"):
            np.testing.assert_array_equal(part[key], full[key])
