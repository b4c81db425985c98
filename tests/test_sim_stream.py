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


@pytest.mark.parametrize("chunk", [1, 37, 500])
def test_gauss_markov_rows_in_chunks_hold_one_chunk_and_equal_the_whole_draw(chunk, monkeypatch):
    """A correlation time whose recursion block (8 tau / dt = 8e6 samples) is longer than the record: the
    rows are computed ``GM_CHUNK`` at a time (the running sum of the block carried over), bit for bit the
    whole draw, and the rows held never exceed one chunk (they did grow with the record: 9 MB a day)."""
    import insnav.sim.imu as imu_mod

    monkeypatch.setattr(imu_mod, "GM_CHUNK", chunk)
    n, dt = 3001, 0.01
    err = _errors([1e4, 10.0, np.inf], [0.0] * 3, [1e-3] * 3)
    bias, noise, _, _ = _reference_draw(err, n, dt, np.random.default_rng(3))
    stream = SensorErrorStream(err, n, dt, np.random.default_rng(3))
    rows, k, held = [], 0, 0
    for k1 in (1, 2, 700, 701, 2999, n):
        rows.append(stream.rows(k, k1)[0])
        held = max(held, max(len(g.vals) for g in stream._gm if g is not None))
        k = k1
    assert np.array_equal(np.concatenate(rows), bias)
    assert held <= chunk


def test_sensor_error_stream_serves_rows_once_in_order():
    stream = SensorErrorStream(_errors([1.0] * 3, [0.0] * 3, [1e-3] * 3), 100, 0.01, np.random.default_rng(0))
    stream.rows(0, 10)
    with pytest.raises(ValueError, match="expected rows from 10"):
        stream.rows(0, 10)
    with pytest.raises(ValueError, match="up to 100"):
        stream.rows(10, 101)


def _short_drive(tmp_path, name="short", cruise_s=10.0, delay_p="[0.6, 0.3, 0.1]"):
    """car-mems (slip, bounce, odometer) shortened: 3 s still, 4 s speeding up, then cruising; GNSS at
    10 Hz, each fix delayed by 0, 1 or 2 epochs on its own."""
    f = tmp_path / f"{name}.toml"
    f.write_text(f"""extends = "car-mems"
name = "{name}"
[gnss]
delay_p = {delay_p}
delay_model = "independent"
[motion]
transition_s = 1.0
[[motion.segments]]
duration_s = 3.0
[[motion.segments]]
duration_s = 4.0
target_speed_mps = 8.0
[[motion.segments]]
duration_s = {cruise_s}
turn_rate_dps = 3.0
""")
    return f


def _grid_written_out(traj, grid_step=0.05):
    """The grid as one array: np.linspace, every breakpoint, sorted, points within 1 us merged, t_end last."""
    sc = traj.sc
    n = max(1, int(np.ceil((sc.t_end - sc.t0) / grid_step - 1e-9)))
    g = np.unique(np.concatenate([np.linspace(sc.t0, sc.t_end, n + 1), traj._bps]))
    g = g[np.concatenate([[True], np.diff(g) > 1e-6])]
    g[-1] = sc.t_end
    return g


@pytest.mark.slow
def test_position_grid_in_chunks_equals_one_pass_and_holds_a_few_chunks(tmp_path):
    """Chunks of 77 and of 10 grid steps against one chunk (the whole grid, one pass): the same grid as the
    whole-array construction and the same positions (quadrature from the grid and Hermite interpolation),
    bit for bit (car-mems shortened: a turn, wheel slip and bounce); forward queries keep at most three
    chunks, and asking again for an evicted early chunk recomputes the same numbers."""
    sc = load_scenario(_short_drive(tmp_path, cruise_s=60.0))
    whole = Trajectory(sc, chunk_steps=10**9)
    assert whole._n_chunks == 1
    t = np.sort(np.random.default_rng(5).uniform(sc.t0, sc.t_end, 3001))
    t[0], t[-1] = sc.t0, sc.t_end
    ref = [np.array(whole.position(t)), np.array(whole.position(t, exact=False))]
    assert np.array_equal(whole.grid(), _grid_written_out(whole))
    for k in (77, 10):
        traj = Trajectory(sc, chunk_steps=k)
        assert traj._n_chunks == -(-1340 // k)
        assert np.array_equal(traj.grid(), whole.grid())
        for i0 in range(0, t.size, 250):  # forward, in blocks, as insnav simulate asks
            sl = slice(i0, i0 + 250)
            assert np.array_equal(np.array(traj.position(t[sl])), ref[0][:, sl])
            assert len(traj._cache) <= 3 and max(len(v[0]) for v in traj._cache.values()) <= k + 2
        assert np.array_equal(np.array(traj.position(t[::-1], exact=False)), ref[1][:, ::-1])
        assert np.array_equal(np.array(traj.position(t[:40])), ref[0][:, :40])


def _whole_draw_fixes(traj, cfg, rng_noise, rng_delay):
    """The GNSS fixes drawn whole (the documented order: all position noise, then all velocity noise, then
    one delay per fix), written out directly."""
    from insnav.sim.gnss_loose import antenna_state, gnss_epochs, in_windows

    t = gnss_epochs(traj.sc.t0, traj.sc.t_end, cfg["first_epoch"], cfg["rate"])
    t = t[~in_windows(t, cfg["outages"])]
    lat, lon, h, v_n, _, _ = antenna_state(traj, t, cfg["lever_arm_b"])
    sig_pos = np.array([cfg["sigma_h"], cfg["sigma_h"], cfg["sigma_v"]])
    e_pos = sig_pos * rng_noise.standard_normal((t.size, 3))
    e_vel = cfg["sigma_vel"] * rng_noise.standard_normal((t.size, 3))
    from insnav import earth

    R_M, R_N = earth.radii(lat)
    delay = rng_delay.choice(cfg["delay_p"].size, size=t.size, p=cfg["delay_p"])
    return (t, np.round(t + delay / cfg["rate"], 9), np.degrees(lat + e_pos[:, 0] / (R_M + h)),
            np.degrees(lon + e_pos[:, 1] / ((R_N + h) * np.cos(lat))), h - e_pos[:, 2], v_n + e_vel)


def test_gnss_fix_stream_equals_the_whole_draw_in_odd_blocks(tmp_path):
    """Epoch blocks of 0 to 36 epochs (empty ones too) across an outage: the same fixes, noise and delays
    as the whole draw, bit for bit, and an out-of-order block is refused."""
    from insnav.sim.gnss_loose import GnssFixStream

    sc = load_scenario(_short_drive(tmp_path, cruise_s=30.0), seed=4)
    cfg = dict(sc.gnss, outages=[(5.0, 7.25)])
    traj = Trajectory(sc)
    ref = _whole_draw_fixes(traj, cfg, np.random.default_rng(1), np.random.default_rng(2))
    stream = GnssFixStream(traj, cfg, np.random.default_rng(1), np.random.default_rng(2))
    assert stream.k_hi - stream.k_lo == 370 and stream.n_received == ref[0].size == 370 - 22  # 0.1 .. 37 s
    blocks, a, cut = [], stream.k_lo, np.random.default_rng(3)
    while a < stream.k_hi:
        b = min(stream.k_hi, a + int(cut.integers(0, 37)))
        blocks.append(stream.block(a, b))
        a = b
    got = [np.concatenate([getattr(x, f) for x in blocks]) for f in ("t_valid", "t_arrival", "lat_deg", "lon_deg",
                                                                      "h_m", "v_n")]
    assert all(np.array_equal(g, r) for g, r in zip(got, ref))
    assert np.any(got[1] > got[0])  # delays were drawn
    with pytest.raises(ValueError, match="expected epochs from"):
        stream.block(stream.k_lo, stream.k_hi)


@pytest.mark.slow
@pytest.mark.parametrize("block_s", [0.07, 0.25, 1.37])
def test_simulate_to_in_odd_blocks_writes_the_saved_whole_dataset(tmp_path, block_s):
    """Blocks shorter than the GNSS period (0.07 s: most hold no epoch), splitting the epochs (0.25 s) and
    not a multiple of any rate (1.37 s), with delayed fixes and the odometer: every file equals
    simulate(...).save(...) byte for byte."""
    f = _short_drive(tmp_path)
    whole = simulate(f, seed=3)
    whole.save(tmp_path / "whole")
    ds, n_imu, n_gnss = simulate_to(tmp_path / "blocks", f, seed=3, block_s=block_s)
    assert n_imu == len(whole.imu) == 3400 and n_gnss == len(whole.gnss) == 170
    files = sorted(p.name for p in (tmp_path / "whole").iterdir())
    assert files == sorted(p.name for p in (tmp_path / "blocks").iterdir()) and "gnss.csv" in files
    for name in files:
        assert filecmp.cmp(tmp_path / "whole" / name, tmp_path / "blocks" / name, shallow=False), name


@pytest.mark.slow
def test_simulate_to_holds_one_block_whatever_the_length(tmp_path, monkeypatch):
    """A drive of 2 blocks and one of 20 blocks (10 s each, and a last one of 0.5 s): the largest table
    block written and the position-grid chunks held are the same size (the blocks do not grow with the
    drive's length)."""
    import insnav.data.dataset as dataset_mod
    import insnav.sim.trajectory as trajectory_mod

    written = {}
    real_write = dataset_mod.write_csv

    def spy(path, columns, data, *args, **kw):
        written.setdefault(path.name, []).append(np.asarray(data).shape[0])
        return real_write(path, columns, data, *args, **kw)

    held = []
    real_chunk = trajectory_mod.Trajectory._chunk

    def chunk_spy(self, c):
        out = real_chunk(self, c)
        held.append(sum(v[0].size for v in self._cache.values()))
        return out

    monkeypatch.setattr(dataset_mod, "write_csv", spy)
    monkeypatch.setattr(trajectory_mod.Trajectory, "_chunk", chunk_spy)
    biggest = {}
    for n_blocks in (2, 20):
        written.clear()
        held.clear()
        f = _short_drive(tmp_path, f"d{n_blocks}", cruise_s=10.0 * n_blocks - 6.5)  # 20.5 s, 200.5 s
        simulate_to(tmp_path / f"out{n_blocks}", f, seed=1, block_s=10.0)
        assert len(written["imu.csv"]) == n_blocks + 1 and len(written["gnss.csv"]) == n_blocks + 1
        streamed = ("imu.csv", "imu_errors.csv", "truth.csv", "gnss.csv")  # (the odometer's is written whole)
        biggest[n_blocks] = ({k: max(written[k]) for k in streamed}, max(held))
    assert biggest[2][0] == biggest[20][0] and biggest[2][0]["imu.csv"] == 2000 and biggest[2][0]["gnss.csv"] == 100
    assert biggest[20][1] <= 3 * 12_002  # three 600 s chunks of the grid at most


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


def test_imu_increments_and_state_in_chunks_equal_one_piece(tmp_path):
    """Every interval's quadrature and every time's state on its own: chunks of 7 and 300 give the numbers
    of one piece bit for bit (car-mems shortened: a turn, wheel slip and bounce), the state of unsorted
    times too (computed in one piece)."""
    traj = Trajectory(load_scenario(_short_drive(tmp_path, cruise_s=10.0)))
    t_imu = traj.t0 + np.arange(3001) / 200.0  # 15 s at 200 Hz
    ref = traj.imu_increments(t_imu, chunk=10**9)
    t = np.sort(np.random.default_rng(2).uniform(traj.t0, traj.t_end, 2000))
    ref_st = [traj.state(t, chunk=10**9), traj.state(t, exact_position=False, chunk=10**9)]
    for chunk in (7, 300):
        got = traj.imu_increments(t_imu, chunk=chunk)
        assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
        for exact, r in zip((True, False), ref_st):
            st = traj.state(t, exact_position=exact, chunk=chunk)
            assert st.keys() == r.keys() and all(np.array_equal(st[k], r[k]) for k in r)
    back = traj.state(t[::-1], chunk=7)
    assert all(np.array_equal(back[k], ref_st[0][k][::-1]) for k in ref_st[0])


def _traced_peak(f):
    """Bytes traced by tracemalloc above the start at the peak of ``f()``, and ``f()``'s result."""
    import tracemalloc

    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        out = f()
        return tracemalloc.get_traced_memory()[1] - start, out
    finally:
        tracemalloc.stop()


def test_imu_increments_temporaries_do_not_grow_with_the_intervals(tmp_path, monkeypatch):
    """The temporaries of the quadrature (about 60 arrays of chunk x nodes values) are bounded by
    ``IMU_CHUNK``: the traced peak above the two (N, 3) outputs is the same for 1024 and 4096 intervals
    (it was 150 MB for a 600 s block at 200 Hz, computed in one piece)."""
    import insnav.sim.trajectory as trajectory_mod

    monkeypatch.setattr(trajectory_mod, "IMU_CHUNK", 256)
    traj = Trajectory(load_scenario(_short_drive(tmp_path, cruise_s=20.0)))
    traj.position(np.array([traj.t0, traj.t_end]))  # the grid integrated (one chunk) beforehand
    extra = []
    for n in (1024, 4096):
        t_imu = traj.t0 + np.arange(n + 1) / 200.0
        peak, (dtheta, dv) = _traced_peak(lambda: traj.imu_increments(t_imu))
        assert dtheta.shape == (n, 3)
        extra.append(peak - dtheta.nbytes - dv.nbytes)
    assert 0 < extra[1] <= extra[0] + 4096 and extra[0] < 60 * 3 * 256 * 3 * 8


@pytest.mark.slow
def test_simulate_to_releases_each_block_and_holds_no_more_as_blocks_go_by(tmp_path, monkeypatch):
    """20 blocks of 10 s: after each step no block of rows computed for a table is still alive (it is
    written, then released before the next one is computed: the whole-block tables were held beside
    the next block), and the traced memory held between blocks grows by less than a tenth of one
    block's tables (480 kB) from the third block to the last."""
    import tracemalloc
    import weakref

    import insnav.sim as sim_mod

    made = []
    for name in ("imu_block", "truth_block"):
        real = getattr(sim_mod._Simulation, name)

        def spy(self, *a, _real=real):
            out = _real(self, *a)
            made.extend(weakref.ref(x) for x in (out if isinstance(out, tuple) else (out,)) if x.t.size)
            return out  # (the empty IMU tables of the setup: held by the returned dataset)

        monkeypatch.setattr(sim_mod._Simulation, name, spy)
    alive, held = [], []

    def progress(k, n):
        alive.append(sum(r() is not None for r in made))
        held.append(tracemalloc.get_traced_memory()[0])

    f = _short_drive(tmp_path, "d20", cruise_s=10.0 * 20 - 6.5)
    tracemalloc.start()
    try:
        simulate_to(tmp_path / "out", f, seed=1, block_s=10.0, progress=progress)
    finally:
        tracemalloc.stop()
    assert len(made) == 3 * 21 and len(alive) == 3 + 2 * 21 + 1  # the stages, IMU and truth blocks, GNSS
    assert max(alive) == 0
    block_steps = np.array(held[3:-1])  # after each IMU and truth block
    assert block_steps[-1] - block_steps[4] < 48_000


def test_a_scenario_larger_than_the_free_disk_is_refused_before_writing(tmp_path, capsys, monkeypatch):
    """A misplaced exponent (duration_s = 1e12) ran for ever, filling the disk block by block: the
    estimate (at least 100 + 150 + 80 bytes per IMU, truth and IMU-error row) is compared with the
    free space of --out's disk before anything is written."""
    import collections
    import shutil

    from insnav.cli import main

    toml = tmp_path / "long.toml"
    toml.write_text('extends = "seed000-sim"\n[[motion.segments]]\nduration_s = 1e12\n')
    out = tmp_path / "out"
    assert main(["simulate", str(toml), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"insnav simulate: error: {toml}: 1e+12 s at 200 Hz would write at least 5.08e+07 GB, more "
                          f"than the ") and err.endswith(f"GB free in {tmp_path} (check [[motion.segments]] "
                                                         "duration_s and [imu] rate_hz)"), err
    assert "\n" not in err and sorted(p.name for p in tmp_path.iterdir()) == ["long.toml"]
    # the bound: 150 s at 200 Hz needs at least 150 * (200 * 100 + 200 * 150 + 10 * 80) = 7.62 MB
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(1, 1, 7_600_000))
    assert main(["simulate", "seed000-sim", "--out", str(out), "-q"]) == 2
    assert "would write at least 0.00762 GB, more than the 0.0076 GB free" in capsys.readouterr().err
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(1, 1, 7_700_000))
    assert main(["simulate", "seed000-sim", "--out", str(out), "-q"]) == 0 and (out / "imu.csv").exists()
