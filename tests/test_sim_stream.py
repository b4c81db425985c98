"""The simulator block by block: the same numbers as one whole-array pass, bit for bit.

``insnav simulate`` writes its tables block by block (insnav.sim.simulate_to) so that a day at
200 Hz fits in bounded memory; a seed must still give the same dataset whatever the blocks.
"""
import filecmp

import numpy as np
import pytest

from insnav.sim import simulate, simulate_to
from insnav.sim.imu import SensorErrorStream, _ar1, simulate_sensor_errors
from insnav.sim.scenario import SensorErrors, load_scenario
from insnav.sim.trajectory import Trajectory


def _errors(gm_tau, bias_rw, noise):
    return SensorErrors(bias=np.array([1e-3, 2e-3, -1e-3]), bias_sigma=np.full(3, 1e-4),
                        gm_sigma=np.array([1e-4, 2e-4, 0.0]), gm_tau=np.array(gm_tau, float),
                        bias_rw=np.array(bias_rw, float), noise_density=np.array(noise, float),
                        scale=np.zeros(3), scale_sigma=np.full(3, 1e-4), misalignment=np.zeros((3, 3)),
                        misalignment_sigma=1e-4)


def _reference_draw(err, n, dt, rng):
    """The whole-array draw written out directly (the documented draw order, one array per stream)."""
    turn_on = err.bias_sigma * rng.standard_normal(3)
    scale = err.scale + err.scale_sigma * rng.standard_normal(3)
    M = err.misalignment.copy()
    M[~np.eye(3, dtype=bool)] += err.misalignment_sigma * rng.standard_normal(6)
    bias = np.empty((n, 3))
    bias[:] = err.bias + turn_on
    for ax in range(3):
        sig, tau = err.gm_sigma[ax], err.gm_tau[ax]
        if sig > 0 and np.isfinite(tau):
            phi = np.exp(-dt / tau)
            x0 = sig * rng.standard_normal(1)
            e = (sig * np.sqrt(1.0 - phi * phi)) * rng.standard_normal((n - 1, 1))
            gm = np.concatenate([x0, _ar1(phi, x0, e)[:, 0]])
            bias[:, ax] += gm
    if np.any(err.bias_rw > 0):
        steps = err.bias_rw * np.sqrt(dt) * rng.standard_normal((n, 3))
        steps[0] = 0.0
        bias += np.cumsum(steps, axis=0)
    noise = err.noise_density * np.sqrt(dt) * rng.standard_normal((n, 3))
    return bias, noise, scale, M


@pytest.mark.parametrize("gm_tau, n", [([0.3, 0.1, 1.0], 2001), ([3600.0, 100.0, np.inf], 5001), ([0.05] * 3, 1)])
def test_sensor_error_stream_equals_the_whole_draw_in_any_blocks(gm_tau, n):
    """Random block lengths (across the Gauss-Markov recursion's own blocks of 8 tau / dt samples),
    the same bias and noise rows, bit for bit, and the generator left where the whole draw leaves it."""
    err, dt = _errors(gm_tau, [1e-5, 0.0, 1e-5], [1e-3] * 3), 0.01
    rng_ref = np.random.default_rng(7)
    bias, noise, scale, M = _reference_draw(err, n, dt, rng_ref)
    rng = np.random.default_rng(7)
    stream = SensorErrorStream(err, n, dt, rng)
    blocks, k, cut = [], 0, np.random.default_rng(1)
    while k < n:
        k1 = min(n, k + int(cut.integers(1, max(2, n // 7))))
        blocks.append(stream.rows(k, k1))
        k = k1
    assert np.array_equal(np.concatenate([b for b, _ in blocks]), bias)
    assert np.array_equal(np.concatenate([w for _, w in blocks]), noise)
    assert np.array_equal(stream.scale, scale) and np.array_equal(stream.misalignment, M)
    assert np.array_equal(rng.standard_normal(5), rng_ref.standard_normal(5))
    real, noise2 = simulate_sensor_errors(err, n, dt, np.random.default_rng(7))
    assert np.array_equal(real.bias, bias) and np.array_equal(noise2, noise)


def test_sensor_error_stream_serves_rows_once_in_order():
    stream = SensorErrorStream(_errors([1.0] * 3, [0.0] * 3, [1e-3] * 3), 100, 0.01, np.random.default_rng(0))
    stream.rows(0, 10)
    with pytest.raises(ValueError, match="expected rows from 10"):
        stream.rows(0, 10)
    with pytest.raises(ValueError, match="up to 100"):
        stream.rows(10, 101)


def test_position_grid_integrated_in_chunks_equals_one_pass():
    """The trajectory's grid integration in chunks of 777 intervals equals the default chunking, bit for bit
    (car-mems: turns, grades, wheel slip and bounce)."""
    traj = Trajectory(load_scenario("car-mems"))
    grids = (traj._hg, traj._latg, traj._long, traj._lat_dot_g, traj._lon_dot_g)
    ref = [g.copy() for g in grids]
    traj._integrate_position(chunk=len(traj._grid))  # one chunk: the whole grid
    assert all(np.array_equal(a, b) for a, b in zip(ref, (traj._hg, traj._latg, traj._long, traj._lat_dot_g,
                                                          traj._lon_dot_g)))
    traj._integrate_position(chunk=777)
    assert all(np.array_equal(a, b) for a, b in zip(ref, (traj._hg, traj._latg, traj._long, traj._lat_dot_g,
                                                          traj._lon_dot_g)))


def test_simulate_to_writes_the_saved_whole_dataset_byte_for_byte(tmp_path):
    """Blocks of 37.3 s (not a multiple of any rate) against simulate(...).save(...)."""
    whole = simulate("car-mems", seed=3)
    whole.save(tmp_path / "whole")
    ds, n_imu, n_gnss = simulate_to(tmp_path / "blocks", "car-mems", seed=3, block_s=37.3)
    assert n_imu == len(whole.imu) == 180_000
    files = sorted(p.name for p in (tmp_path / "whole").iterdir())
    assert files == sorted(p.name for p in (tmp_path / "blocks").iterdir())
    assert "imu.csv" in files and "truth.csv" in files and "imu_errors.csv" in files
    for f in files:
        assert filecmp.cmp(tmp_path / "whole" / f, tmp_path / "blocks" / f, shallow=False), f
    assert len(ds.imu) == 0 and len(ds.gnss) == 0 and n_gnss == len(whole.gnss) == 9000


def test_simulate_to_refuses_a_foreign_folder_before_simulating(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError):
        simulate_to(tmp_path, "car-mems", overwrite=True)
    assert (tmp_path / "notes.txt").read_text() == "mine"
    with pytest.raises(ValueError, match="block_s"):
        simulate_to(tmp_path / "x", "car-mems", block_s=0.0)
