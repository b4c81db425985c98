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

import numpy as np

from ..data.dataset import Dataset, GnssFixes, ImuData, ImuErrors, Truth
from .scenario import Scenario, ScenarioError, list_presets, load_scenario
from ..units import wrap_deg

__all__ = ["simulate", "simulate_rtk", "load_scenario", "list_presets", "Scenario", "ScenarioError",
           "truth_from_state", "wrap_deg"]

# appending keeps every earlier stream's seed (SeedSequence.spawn children are positional)
_STREAMS = ("gyro", "accel", "gnss", "delay", "gnss_raw", "clock", "odometer", "rtk")


def sample_times(t0: float, t_end: float, rate: float) -> np.ndarray:
    """``t0 + k / rate`` for k = 0.. while <= t_end (1 ns tolerance)."""
    n = int(np.floor((t_end - t0) * rate + 1e-6))
    return t0 + np.arange(n + 1) / rate


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
    """
    from .gnss_loose import simulate_gnss_fixes
    from .imu import apply_errors, imu_model_dict, simulate_sensor_errors
    from .trajectory import Trajectory

    sc = load_scenario(scenario, seed=seed)
    children = np.random.SeedSequence(sc.seed).spawn(len(_STREAMS))
    rngs = {k: np.random.default_rng(c) for k, c in zip(_STREAMS, children)}
    traj = Trajectory(sc)
    n_stages = len(SIMULATE_STAGES)

    def done(stage: str) -> None:
        if progress is not None:
            progress(SIMULATE_STAGES.index(stage) + 1, n_stages)

    dt = 1.0 / sc.imu_rate
    t_imu = sample_times(sc.t0, sc.t_end, sc.imu_rate)
    dtheta, dv = traj.imu_increments(t_imu, nodes=sc.quadrature_nodes)
    done("IMU increments")
    n = dtheta.shape[0]
    g_real, g_noise = simulate_sensor_errors(sc.gyro, n + 1, dt, rngs["gyro"])
    a_real, a_noise = simulate_sensor_errors(sc.accel, n + 1, dt, rngs["accel"])
    # row 0 of each realisation is the state at t0; increments use rows 1..n
    g_real_s = type(g_real)(g_real.bias[1:], g_real.scale, g_real.misalignment, g_real.turn_on_bias)
    a_real_s = type(a_real)(a_real.bias[1:], a_real.scale, a_real.misalignment, a_real.turn_on_bias)
    dtheta_m = apply_errors(dtheta, g_real_s, g_noise[1:], dt)
    dv_m = apply_errors(dv, a_real_s, a_noise[1:], dt)
    imu = ImuData(t_imu[1:].copy(), dtheta_m, dv_m)

    step = max(1, int(round(sc.imu_rate / sc.errors_rate)))
    sel = np.arange(0, n + 1, step)
    imu_errors = ImuErrors(t_imu[sel], g_real.bias[sel], a_real.bias[sel], g_real.scale,
                           a_real.scale, g_real.misalignment, a_real.misalignment)
    done("IMU errors")

    truth = None
    if with_truth:
        t_truth = sample_times(sc.t0, sc.t_end, sc.truth_rate)
        truth = truth_from_state(traj.state(t_truth))
    st0 = traj.state(np.array([sc.t0]))
    tr0 = truth_from_state(st0)
    initial = tr0.state_at(0)
    done("truth")

    gcfg = sc.gnss
    if gcfg["enabled"]:
        gnss = simulate_gnss_fixes(traj, gcfg, rngs["gnss"], rngs["delay"])
    else:
        z = np.empty(0)
        gnss = GnssFixes(z, z, z, z, z, np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))
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
