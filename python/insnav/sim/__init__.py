"""The insnav simulator: exact truth, IMU increments with errors, GNSS fixes, raw GNSS and carrier phase.

Main entry point :func:`simulate`; scenarios are TOML files
(:mod:`insnav.sim.scenario`), presets ship in ``insnav/scenarios``
(:func:`list_presets`).

Random streams: one ``numpy.random.SeedSequence(seed)`` is split into
independent children for the gyro, the accelerometer, GNSS fix noise, GNSS
delays, raw-GNSS noise, the receiver clock, the odometer and the carrier-phase
simulation (:mod:`insnav.sim.gnss_rtk`, rover and base RINEX 3 files;
:func:`simulate_rtk` runs it alone), so switching one part on or off does not
change the random numbers of the others.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data.dataset import Dataset, GnssFixes, ImuData, ImuErrors, Truth
from .scenario import Scenario, ScenarioError, list_presets, load_scenario
from ..units import wrap_deg

__all__ = ["simulate", "simulate_to", "simulate_rtk", "load_scenario", "list_presets", "Scenario", "ScenarioError",
           "truth_from_state", "wrap_deg"]

# appending keeps every earlier stream's seed (SeedSequence.spawn children are positional)
_STREAMS = ("gyro", "accel", "gnss", "delay", "gnss_raw", "clock", "odometer", "rtk")


def sample_count(t0: float, t_end: float, rate: float) -> int:
    """The number of sample times ``t0 + k / rate`` <= t_end (1 ns tolerance)."""
    return int(np.floor((t_end - t0) * rate + 1e-6)) + 1


def sample_times(t0: float, t_end: float, rate: float, k0: int = 0, k1: int | None = None) -> np.ndarray:
    """``t0 + k / rate`` for k = k0..k1-1 (default: every k while <= t_end, 1 ns tolerance)."""
    if k1 is None:
        k1 = sample_count(t0, t_end, rate)
    return t0 + np.arange(k0, k1) / rate


def truth_from_state(st: dict) -> Truth:
    """Convert :meth:`Trajectory.state` output (SI) to a :class:`Truth` (degrees)."""
    eul = np.degrees(st["euler"])
    return Truth(t=st["t"], lat_deg=np.degrees(st["lat"]), lon_deg=np.degrees(st["lon"]),
                 h_m=st["h"], v_n=st["v_n"], roll_deg=eul[:, 0], pitch_deg=eul[:, 1],
                 yaw_deg=wrap_deg(eul[:, 2]), f_ib_b=st["f_ib_b"], omega_ib_b=st["omega_ib_b"])


#: stages :func:`simulate` reports to its ``progress`` callable
SIMULATE_STAGES = ("IMU increments", "IMU errors", "truth", "GNSS fixes", "raw GNSS", "odometer", "carrier phase")


def simulate(scenario, seed: int | None = None, *, constellation=None,
             with_truth: bool = True, progress=None) -> Dataset:
    """Simulate a scenario.

    Parameters
    ----------
    scenario : str, Path, dict or Scenario
        Preset name (``insnav scenarios`` lists them), TOML file, parsed
        dictionary or :class:`Scenario`.
    seed : int, optional
        Random seed (default: the scenario's ``seed`` key, else 0).  The same
        seed always gives the same dataset.
    constellation : insnav.gnss.constellation.Constellation, optional
        Overrides ``gnss_raw.constellation``.
    with_truth : bool
        Compute the truth table at ``truth.rate_hz`` (the IMU increments are
        computed from the analytic truth either way).
    progress : callable, optional
        Called as ``progress(done, total)`` after each of the
        :data:`SIMULATE_STAGES` (``insnav simulate`` draws a bar with it).

    Returns
    -------
    Dataset

    See Also
    --------
    simulate_to : the same dataset written to a folder block by block, in
        memory bounded by the block length instead of the scenario's.
    """
    sim = _Simulation(scenario, seed)
    n_stages = len(SIMULATE_STAGES)

    def done(stage: str) -> None:
        if progress is not None:
            progress(SIMULATE_STAGES.index(stage) + 1, n_stages)

    imu, imu_errors = sim.imu_block(0, sim.n_imu)
    done("IMU increments")
    done("IMU errors")
    truth = sim.truth_block(0, sim.n_truth) if with_truth else None
    done("truth")
    return sim.dataset(imu, imu_errors, truth, constellation, done)


def simulate_to(directory, scenario, seed: int | None = None, *, overwrite: bool = False,
                block_s: float = 60.0, constellation=None, progress=None) -> tuple[Dataset, int, int]:
    """Simulate a scenario straight into a dataset folder, block by block.

    The folder equals ``simulate(scenario, seed).save(directory)`` byte for
    byte, but the IMU, truth, IMU-error and GNSS-fix tables are computed and
    appended ``block_s`` seconds at a time, so memory does not grow with the
    scenario's length: one block of rows (the block written is released
    before the next is computed), the temporaries of
    :meth:`~insnav.sim.trajectory.Trajectory.imu_increments` and
    :meth:`~insnav.sim.trajectory.Trajectory.state`, bounded by their own
    chunks (``IMU_CHUNK`` intervals, ``STATE_CHUNK`` times), a few 600 s
    chunks of the trajectory's 0.05 s position grid
    (:class:`insnav.sim.trajectory.Trajectory`) and one chunk of each
    Gauss-Markov bias recursion (``GM_CHUNK`` rows,
    :class:`insnav.sim.imu.SensorErrorStream`).  Still computed
    whole: the raw GNSS, odometer and carrier-phase tables, and the GNSS
    fixes of the ``"one_per_epoch"`` delay model
    (:class:`insnav.sim.gnss_loose.GnssFixStream`).

    Parameters
    ----------
    directory : str or Path
        The dataset folder to write (atomically, as :meth:`Dataset.save`).
    scenario, seed, constellation
        As :func:`simulate`.
    overwrite : bool
        Replace an existing insnav dataset folder.
    block_s : float
        Length of a block [s].  The default 60 s (12,000 rows at 200 Hz)
        holds about 5 MB of tables; 600 s blocks held 50 MB more for the
        same CPU time (bench/simulate_day.py).
    progress : callable, optional
        ``progress(done, total)`` after each stage and each block.

    Returns
    -------
    dataset : Dataset
        The dataset without its IMU, truth, IMU-error and GNSS-fix rows
        (empty tables; the IMU-error constants are set).
    n_imu : int
        The number of IMU samples written.
    n_gnss : int
        The number of GNSS-fix records written.
    """
    from ..data.dataset import check_replaceable, write_csv

    if not block_s > 0:
        raise ValueError(f"simulate_to: block_s must be > 0 s (got {block_s!r})")
    check_replaceable(Path(directory), overwrite)
    sim = _Simulation(scenario, seed)
    n_imu, n_truth = sim.n_imu, sim.n_truth
    blk_imu = max(1, int(round(block_s * sim.sc.imu_rate)))
    blk_truth = max(1, int(round(block_s * sim.sc.truth_rate)))
    n_blocks = -(-n_imu // blk_imu) + -(-n_truth // blk_truth)
    total = len(SIMULATE_STAGES) - 3 + n_blocks
    count = [0]

    def step(_stage=None) -> None:
        count[0] += 1
        if progress is not None:
            progress(count[0], total)

    no_imu, no_errors = sim.imu_block(0, 0)  # no rows: the IMU-error constants for dataset.json
    fixes = sim.gnss_stream()
    ds = sim.dataset(no_imu, no_errors, None, constellation, step, with_gnss=False)
    n_gnss = [0]

    def write_tables(folder: Path) -> None:
        # the tables side by side, block i of each covering about the same time: the trajectory's position
        # grid is then integrated once, forward (it keeps a few chunks, insnav.sim.trajectory)
        n_blk = max(-(-n_imu // blk_imu), -(-n_truth // blk_truth), 1)
        e0 = fixes.k_lo
        for i in range(n_blk):
            k0 = i * blk_imu
            if k0 < n_imu:
                imu, errs = sim.imu_block(k0, min(n_imu, k0 + blk_imu))
                write_csv(folder / "imu.csv", ImuData.COLUMNS, imu.to_array(), append=k0 > 0)
                write_csv(folder / "imu_errors.csv", ImuErrors.COLUMNS, errs.to_array(), append=k0 > 0)
                del imu, errs  # written: not held while the next table is computed
                step()
            i0 = i * blk_truth
            if i0 < n_truth:
                tr = sim.truth_block(i0, min(n_truth, i0 + blk_truth))
                write_csv(folder / "truth.csv", Truth.COLUMNS, tr.to_array(), append=i0 > 0)
                del tr
                step()
            e1 = fixes.k_hi if i == n_blk - 1 else fixes.epoch_index(sim.sc.t0 + (i + 1) * block_s)
            gnss = fixes.block(e0, e1)
            write_csv(folder / "gnss.csv", GnssFixes.COLUMNS, gnss.to_array(), append=i > 0)
            n_gnss[0] += len(gnss)
            del gnss
            e0 = e1
        step("GNSS fixes")

    ds.save(directory, overwrite=overwrite, write_tables=write_tables)
    return ds, n_imu - 1, n_gnss[0]


class _Simulation:
    """One scenario and seed: the trajectory, the random streams and the table blocks.

    The IMU errors come from :class:`insnav.sim.imu.SensorErrorStream`, so
    any split of the samples into blocks gives the same numbers.
    """

    def __init__(self, scenario, seed):
        from .imu import SensorErrorStream
        from .trajectory import Trajectory

        sc = load_scenario(scenario, seed=seed)
        children = np.random.SeedSequence(sc.seed).spawn(len(_STREAMS))
        self.rngs = {k: np.random.default_rng(c) for k, c in zip(_STREAMS, children)}
        self.sc, self.traj = sc, Trajectory(sc)
        # sample k at t0 + k / rate, made block by block (a day at 200 Hz would hold 138 MB of times)
        self.n_imu = sample_count(sc.t0, sc.t_end, sc.imu_rate)
        self.n_truth = sample_count(sc.t0, sc.t_end, sc.truth_rate)
        dt = 1.0 / sc.imu_rate
        # row 0 of each realisation is the state at t0; the increment ending at sample k uses row k
        self.gyro = SensorErrorStream(sc.gyro, self.n_imu, dt, self.rngs["gyro"])
        self.accel = SensorErrorStream(sc.accel, self.n_imu, dt, self.rngs["accel"])
        self.error_step = max(1, int(round(sc.imu_rate / sc.errors_rate)))

    def imu_block(self, k0: int, k1: int) -> tuple[ImuData, ImuErrors]:
        """The IMU increments ending at samples [max(k0, 1), k1) and the IMU-error rows in [k0, k1)."""
        from .imu import apply_errors

        sc, dt = self.sc, 1.0 / self.sc.imu_rate
        gb, gn = self.gyro.rows(k0, k1)
        ab, an = self.accel.rows(k0, k1)
        j0 = min(max(k0, 1), max(k1, 1))
        t = sample_times(sc.t0, sc.t_end, sc.imu_rate, j0 - 1, k1)  # samples j0-1 .. k1-1
        if k1 > j0:
            dtheta, dv = self.traj.imu_increments(t, nodes=sc.quadrature_nodes)
        else:
            dtheta = dv = np.empty((0, 3))
        s = j0 - k0
        imu = ImuData(t[1:].copy(),
                      apply_errors(dtheta, self.gyro.realisation(gb[s:]), gn[s:], dt),
                      apply_errors(dv, self.accel.realisation(ab[s:]), an[s:], dt))
        sel = np.arange(-(-k0 // self.error_step) * self.error_step, k1, self.error_step)
        errs = ImuErrors(sc.t0 + sel / sc.imu_rate, gb[sel - k0], ab[sel - k0], self.gyro.scale, self.accel.scale,
                         self.gyro.misalignment, self.accel.misalignment)
        return imu, errs

    def truth_block(self, i0: int, i1: int) -> Truth:
        """The truth rows [i0, i1) at ``truth.rate_hz``."""
        sc = self.sc
        return truth_from_state(self.traj.state(sample_times(sc.t0, sc.t_end, sc.truth_rate, i0, i1)))

    def gnss_stream(self):
        """The GNSS fixes, epoch block by epoch block (:class:`insnav.sim.gnss_loose.GnssFixStream`)."""
        from .gnss_loose import GnssFixStream

        return GnssFixStream(self.traj, self.sc.gnss, self.rngs["gnss"], self.rngs["delay"])

    def dataset(self, imu, imu_errors, truth, constellation, done, with_gnss: bool = True) -> Dataset:
        """The dataset around the given IMU tables: the GNSS, odometer and carrier-phase parts.

        ``with_gnss=False``: no GNSS fixes (an empty table; :func:`simulate_to` writes them block by block)."""
        from .gnss_loose import _no_fixes
        from .imu import imu_model_dict

        sc, traj, rngs = self.sc, self.traj, self.rngs
        initial = truth_from_state(traj.state(np.array([sc.t0]))).state_at(0)
        gcfg = sc.gnss
        if gcfg["enabled"] and with_gnss:
            fixes = self.gnss_stream()
            gnss = fixes.block(fixes.k_lo, fixes.k_hi)
        else:
            gnss = _no_fixes()
        if with_gnss:
            done("GNSS fixes")
        gnss_raw = None
        if sc.gnss_raw["enabled"]:
            from .gnss_raw import simulate_gnss_raw

            gnss_raw = simulate_gnss_raw(traj, sc.gnss_raw, gcfg["lever_arm_b"], sc.gps_time_offset_s,
                                         rngs["gnss_raw"], rngs["clock"], constellation=constellation)
        done("raw GNSS")
        odometer = None
        if sc.odometer is not None:
            from .odometer import simulate_odometer

            odometer = simulate_odometer(traj, sc.odometer, rngs["odometer"])
        done("odometer")
        rtk = None
        if sc.gnss_rtk is not None:
            from .gnss_rtk import simulate_rtk_obs

            rtk = simulate_rtk_obs(traj, sc.gnss_rtk, gcfg["lever_arm_b"], sc.gps_time_offset_s, rngs["rtk"])
        done("carrier phase")
        raw = dict(sc.raw)
        raw["seed"] = int(sc.seed)
        return Dataset(imu=imu, gnss=gnss, truth=truth, gnss_raw=gnss_raw, imu_errors=imu_errors,
                       scenario=raw, lever_arm_b=np.array(gcfg["lever_arm_b"], float),
                       initial=initial, t0=sc.t0, gps_time_offset_s=sc.gps_time_offset_s,
                       imu_model=imu_model_dict(sc.gyro, sc.accel, sc.imu_rate), name=sc.name,
                       seed=int(sc.seed), odometer=odometer, initial_is_truth=True, rtk=rtk)


def simulate_rtk(scenario, seed: int | None = None):
    """Only the carrier-phase part of :func:`simulate` (no IMU): the same rover and base observations.

    The ``rtk`` random stream is the same child of the seed as in
    :func:`simulate`, so ``simulate_rtk(s, k)`` equals ``simulate(s, k).rtk``
    (a faster path for Monte Carlo runs of RTK engines).

    Returns
    -------
    insnav.sim.gnss_rtk.RtkSimulation

    Raises
    ------
    ScenarioError
        The scenario has no ``[gnss_rtk]`` table.
    """
    from .gnss_rtk import simulate_rtk_obs
    from .trajectory import Trajectory

    sc = load_scenario(scenario, seed=seed)
    if sc.gnss_rtk is None:
        raise ScenarioError(f"scenario {sc.source or sc.name}: no [gnss_rtk] table (carrier-phase simulation); "
                            "presets with one: " + ", ".join(p for p in list_presets() if p.startswith("rtk-")))
    children = np.random.SeedSequence(sc.seed).spawn(len(_STREAMS))
    rng = np.random.default_rng(children[_STREAMS.index("rtk")])
    return simulate_rtk_obs(Trajectory(sc), sc.gnss_rtk, sc.gnss["lever_arm_b"], sc.gps_time_offset_s, rng)
