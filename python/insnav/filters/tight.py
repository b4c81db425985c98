"""Tightly coupled GNSS/INS (seed 003, Xu et al. 2012): 17-state
filters on pseudorange and pseudorange rate; with several constellations
(GPS + GLONASS / Galileo / BeiDou) 20 states: + one inter-system bias [m]
per non-GPS system (``LayoutTightMulti``, ``cpp/include/insnav/filter/layout.hpp``).

Layout choice (``RunConfig.layout``, the TOML's top-level ``layout``: 17 or
20; the default chooses): 17 states when every satellite row is
GPS (so every GPS-only result, seed 003's included, is unchanged), 20 when
any row is of another system.  The ISB states start from the data (median
pseudorange offset of each system against GPS at the initial position, 0
when a system has no row in the first epochs) with a 1-sigma of
``init_sigma_isb`` = 100 m, and are random walks of PSD ``isb_psd``
(1e-4 m^2/s: 0.6 m in an hour).  Robust update: ``cfg.robust``
(:class:`insnav.config.Robust`).

Python owns the geometry (:mod:`insnav.gnss.tight_inputs`: satellite
positions, velocities and clocks, elevation mask, best-GDOP selection,
per-satellite sigmas, corrections), computed for all epochs at once and
handed to the C++ loop (``cpp/include/insnav/engine/tight_engine.hpp``) in
one call as flat arrays.  The receiver clock model (Layout17 states 15, 16:
bias [m], drift [m/s]) is :mod:`insnav.gnss.clock`'s: TCXO defaults, or a
simulator dataset's own clock densities.

:func:`run_tight` is what ``insnav.run(ds, coupling="tight")`` calls.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .. import _core
from .._median import median
from ..config import ConfigError, ImuNoise, RunConfig
from ..gnss.clock import clock_psd_option
from ..gnss.systems import SYSTEMS, system_index
from ..gnss.tight_inputs import MAX_SATS, TightInputs
from ._setup import (TIGHT_ELEVATION_MASK_DEG, EngineArgs, engine_config, imu_arrays, init_vector, initial_clock,
                     initial_imu_correction, initial_state, raise_if_nonfinite, tight_inputs_for)
from ._assemble import nav_solution
from .loose import put_selfcal, selfcal_setup
from .solution import Solution

__all__ = ["TightSolution", "run_tight", "initial_isb", "tight_engine_args", "tdcp_phase"]


@dataclass
class TightSolution(Solution):
    """:class:`insnav.filters.Solution` plus the tight-coupling outputs.

    Per epoch: ``gnss_t``, ``nis``, ``gnss_status`` (as the loose solution),
    ``rows`` (measurement rows used), ``clock_jump_m``.  Per satellite row
    (``inputs`` order): ``innovation`` (M, 2) INS-predicted minus measured
    pseudorange [m] and rate [m/s] before the update, ``sat_flag`` (M, 2).
    Per output sample: ``clock_bias_m``, ``clock_drift_mps`` (estimated
    receiver clock), ``sigma_clock`` (N, 2), and with 20 states ``isb_m``,
    ``sigma_isb`` (N, 3).  ``summary``: ``layout`` (with the self-calibration
    states), ``state_layout`` (17 or 20: the run's ``layout`` key), ``systems``, and the
    robust step's ``rejected_sats``, ``downweighted_sats``,
    ``flagged_epochs``, ``clock_jumps``.
    """

    clock_bias_m: np.ndarray = None
    clock_drift_mps: np.ndarray = None
    sigma_clock: np.ndarray = None
    rows: np.ndarray = None
    inputs: TightInputs | None = None
    #: (N, 3) inter-system biases of GLONASS, Galileo, BeiDou [m] (20-state runs; None with 17)
    isb_m: np.ndarray = None
    sigma_isb: np.ndarray = None
    #: (M, 2) per satellite row, pseudorange / rate: -1 absent, 0 used, 1 down-weighted (IGG-III), 2 rejected
    sat_flag: np.ndarray = None
    #: (E,) receiver clock jump moved into the clock estimate at each epoch [m] (0: none)
    clock_jump_m: np.ndarray = None
    #: TDCP runs (``[tdcp]``): (M,) INS-predicted minus measured phase change [m] before the update (NaN: no row)
    tdcp_residual_m: np.ndarray = None
    #: (M,) -1 absent, 0 used, 1 slip by LLI, 2 slip by the INS-predicted test, 3 rejected by the chi-square
    tdcp_flag: np.ndarray = None
    #: (E,) TDCP rows used per epoch
    tdcp_rows: np.ndarray = None


def run_tight(dataset, cfg: RunConfig | None = None, *, inputs: TightInputs | None = None,
              elevation_mask_deg: float = TIGHT_ELEVATION_MASK_DEG, max_sats: int = MAX_SATS, clock_psd=None,
              init_sigma_clock=(30.0, 1.0), clock0=None, use_pseudorange: bool = True,
              use_rate: bool = True, layout=None, isb_psd: float = 1e-4, init_sigma_isb: float = 100.0,
              isb0=None) -> TightSolution:
    """Closed-loop tightly coupled run over a dataset (EKF, RB-UKF or UKF, 17 or 20 states).

    Parameters
    ----------
    dataset : insnav.Dataset or :class:`insnav.io.rinex_dataset.RinexDataset`
        IMU increments, initial state, lever arm, IMU model; the GNSS data come
        from ``inputs`` if given, else from ``dataset.tight_inputs`` (a real-data
        loader sets it) or ``dataset.gnss_raw`` (simulator).
    cfg : RunConfig
        ``filter``, initial sigmas/perturbation, IMU noise, gate, propagation
        step, output decimation, UT parameters, ``layout`` (17, 20; the
        default 15: chosen from the data, see ``layout`` below).
    elevation_mask_deg, max_sats : satellite selection for ``gnss_raw`` input.
    clock_psd : (bias [m^2/s], drift [m^2/s^3]), optional; default :func:`insnav.gnss.clock.clock_model`.
    init_sigma_clock : 1-sigma of the initial clock bias [m] and drift [m/s].
    clock0 : (bias, drift), optional; default from the first epoch at the initial state.
    layout : {None, "auto", 17, 20}
        20 (``LayoutTightMulti``): + inter-system biases of R, E, C; "auto": 20
        when any row is not GPS, else 17.  (With 17, non-GPS rows would share
        the GPS clock: only for data whose ISBs were removed.)  None (default):
        ``cfg.layout`` when it is 17 or 20, else "auto".  ``summary["state_layout"]``
        is the one the run used (the ``layout`` key of the resolved configuration).
    isb_psd : float
        ISB random-walk PSD [m^2/s] (20 states).
    init_sigma_isb : float
        1-sigma of the initial ISBs [m].
    isb0 : 3 floats, optional
        Initial ISBs of R, E, C [m]; default :func:`initial_isb` from the data.

    Returns
    -------
    TightSolution
    """
    cfg = dataclasses.replace(cfg or RunConfig(), coupling="tight")
    cfg.validate()
    t, dth, dv = imu_arrays(dataset)
    a = tight_engine_args(dataset, cfg, inputs=inputs, elevation_mask_deg=elevation_mask_deg, max_sats=max_sats,
                          clock_psd=clock_psd, init_sigma_clock=init_sigma_clock, clock0=clock0,
                          use_pseudorange=use_pseudorange, use_rate=use_rate, layout=layout, isb_psd=isb_psd,
                          init_sigma_isb=init_sigma_isb, isb0=isb0)
    inputs, n, ep_t, sys_idx, clock0, isb0, robust = a.inputs, a.layout, a.epoch_t, a.system, a.clock0, a.isb0, a.robust
    qb, qd = a.clock_psd
    core_cfg = dict(a.config)
    if cfg.smooth:
        core_cfg["smooth"] = True
    phase = None
    if cfg.tdcp.enabled:  # time-differenced carrier phase (meas/tdcp.hpp)
        phase = tdcp_phase(inputs, cfg)
        core_cfg.update(cfg.tdcp.as_core_dict())
    extra = {} if phase is None else dict(phase=phase)
    if cfg.constraints.standstill_q_scale != 1.0:  # the standstill level of Q (engine/tight_engine.hpp)
        from .constraints import standstill_at

        still = standstill_at(dataset, cfg.constraints, t, dth, dv, ep_t)
        extra["epoch_still"] = still.astype(np.uint8)
        core_cfg["standstill_q_scale"] = float(cfg.constraints.standstill_q_scale)
    out = _core.run_tight(cfg.filter, t, dth, dv, ep_t, inputs.epoch_start.astype(np.int64),
                          a.sats, a.init, a.P0, a.imu_correction, np.asarray(clock0, float), a.imu_model, core_cfg,
                          layout=n, system=sys_idx, isb0=None if n == 17 else np.asarray(isb0, float), prn=a.prn,
                          **extra)
    sig = out["sigma"]
    systems = sorted(set(np.asarray(inputs.system).tolist()), key=SYSTEMS.index)
    sol, _ = nav_solution(
        out, TightSolution, gnss_t=ep_t, innovation=out["sat_residual"], nis=out["nis"], gnss_status=out["status"],
        log_det_s=out["log_det_s"],
        summary=dict(filter=cfg.filter, coupling="tight", layout=n, state_layout=n, systems="".join(systems),
                     updates=int(out["updates"]), rejected=int(out["rejected"]), gate_reopened=int(out["gate_reopened"]),
                     gate_outage_accepted=int(out["gate_outage_accepted"]),
                     cholesky_repairs=int(out["cholesky_repairs"]), gnss_records=int(ep_t.size),
                     sat_rows=int(len(inputs.prn)), clock0=tuple(clock0), clock_psd=(float(qb), float(qd)),
                     robust_screening=bool(robust["robust_screening"]), rejected_sats=int(out["rejected_sats"]),
                     fde_excluded=int(out["fde_excluded"]), cusum_alarms=int(out["cusum_alarms"]),
                     cusum_excluded=int(out["cusum_excluded"]),
                     variance_inflated_epochs=tuple(int(v) for v in out["variance_inflated"]),
                     downweighted_sats=int(out["downweighted_sats"]), flagged_epochs=int(out["flagged_epochs"]),
                     clock_jumps=int(out["clock_jumps"])),
        clock_bias_m=out["clock"][:, 0], clock_drift_mps=out["clock"][:, 1], sigma_clock=sig[:, 15:17],
        rows=out["rows"], inputs=inputs, sat_flag=out["sat_flag"], clock_jump_m=out["clock_jump"])
    if cfg.tdcp.enabled:
        sol.tdcp_residual_m, sol.tdcp_flag, sol.tdcp_rows = out["tdcp_residual"], out["tdcp_flag"], out["tdcp_rows"]
        sol.summary.update(tdcp=True, tdcp_used=int(out["tdcp_used"]), tdcp_rejected=int(out["tdcp_rejected"]),
                           tdcp_slips_lli=int(out["tdcp_slips_lli"]), tdcp_slips_ins=int(out["tdcp_slips_ins"]),
                           tdcp_updates=int(out["tdcp_updates"]))
    if cfg.adaptive_q_window:  # the adaptive process-noise factors at the end (velocity, angle random walk)
        sol.summary["process_noise_scale"] = [float(x) for x in out["process_noise_scale"]]
    put_selfcal(sol, out, cfg)
    if a.P0.shape[0] != n:  # the self-calibration states extend the core layout
        sol.summary["layout"] = int(a.P0.shape[0])
    if n == 20:
        sol.isb_m = out["isb"]
        sol.sigma_isb = sig[:, 17:20]
        sol.summary["isb0"] = tuple(float(v) for v in isb0)
    if cfg.smooth:  # RTS backward pass: navigation rows, clock and ISBs (filters/smoothing.py)
        from .smoothing import smoothed_rows

        smoothed_rows(sol, out, cfg.filter)
    raise_if_nonfinite(sol, cfg.filter)
    return sol


@dataclass
class TightEngineArgs(EngineArgs):
    """The tight engine's set-up (:func:`tight_engine_args`): what ``_core.run_tight``
    and ``_core.TightNavigator`` take, plus the inputs it was built from."""

    clock0: tuple
    clock_psd: tuple
    isb0: np.ndarray | None
    inputs: TightInputs
    epoch_t: np.ndarray
    system: np.ndarray
    sats: np.ndarray
    prn: np.ndarray | None
    robust: dict


def scaled_sigmas(inputs: TightInputs, cfg: RunConfig) -> TightInputs:
    """``inputs`` with the pseudorange and rate sigmas multiplied by insnav tune's
    factors ``gnss_pos_sigma_scale`` / ``gnss_vel_sigma_scale`` (itself when both are 1)."""
    if cfg.gnss_pos_sigma_scale == 1.0 and cfg.gnss_vel_sigma_scale == 1.0:
        return inputs
    sats = np.array(inputs.sats, float)
    sats[:, 10] *= cfg.gnss_pos_sigma_scale
    sats[:, 11] *= cfg.gnss_vel_sigma_scale
    return dataclasses.replace(inputs, sats=sats)


def tight_engine_args(dataset, cfg: RunConfig, *, inputs: TightInputs | None = None,
                      elevation_mask_deg: float = TIGHT_ELEVATION_MASK_DEG, max_sats: int = MAX_SATS, clock_psd=None,
                      init_sigma_clock=(30.0, 1.0), clock0=None, use_pseudorange: bool = True,
                      use_rate: bool = True, layout=None, isb_psd: float = 1e-4, init_sigma_isb: float = 100.0,
                      isb0=None) -> TightEngineArgs:
    """The tight engine's set-up from a dataset, a run config and :func:`run_tight`'s
    options (the same meaning): the batch run and the push API
    (:class:`insnav.filters.navigator.TightNavigator`) start from it alike."""
    inputs = scaled_sigmas(tight_inputs_for(dataset, inputs, elevation_mask_deg=elevation_mask_deg,
                                            max_sats=max_sats), cfg)
    init, sig0 = initial_state(dataset, cfg)  # the draw (if any) from default_rng(cfg.init_seed)
    noise = cfg.imu or ImuNoise.from_dataset_model(dataset.imu_model)
    model = noise.as_core_dict()
    qb, qd = clock_psd_option(clock_psd, dataset)
    model["clock_bias_psd"] = float(qb)
    model["clock_drift_psd"] = float(qd)
    sys_idx = system_index(inputs.system) if len(inputs.prn) else np.zeros(0, np.int64)
    if layout is None:
        layout = cfg.layout if cfg.layout in (17, 20) else "auto"
    if layout == "auto":
        layout = 20 if np.any(sys_idx != 0) else 17
    if layout not in (17, 20):
        raise ValueError(f"run_tight: layout {layout!r}; allowed: 'auto', 17, 20")
    n = int(layout)
    p0 = np.zeros(n)
    p0[:9] = sig0
    # the initial IMU-bias estimate and sigmas of the run config (e.g. the RINEX loader's gyro bias from the
    # standstill before the start, insnav.io.rinex_dataset); the noise model's bias sigmas otherwise
    p0[9:12] = noise.acc_bias_sigma if cfg.init_sigma_acc_bias_mps2 is None else cfg.init_sigma_acc_bias_mps2
    p0[12:15] = noise.gyro_bias_sigma if cfg.init_sigma_gyro_bias_radps is None else cfg.init_sigma_gyro_bias_radps
    p0[15:17] = init_sigma_clock
    if n == 20:
        model["isb_psd"] = float(isb_psd)
        p0[17:20] = init_sigma_isb
    if cfg.selfcal and n != 17:
        key = "time.estimate_offset" if cfg.time.estimate_offset else "lever_arm.estimate"
        raise ConfigError(f"config key '{key}': bad value True; allowed: false with several constellations "
                          f"(the self-calibration states extend the 17-state GPS-only layout; systems in the data: "
                          f"{''.join(sorted(set(np.asarray(inputs.system).tolist())))})")
    sc_sigmas, sc_model, sc_cfg = selfcal_setup(cfg)  # time offset / lever arm states (after the 17)
    p0 = np.append(p0, sc_sigmas)
    model.update(sc_model)
    P0 = np.diag(p0 ** 2)
    if clock0 is None:
        clock0 = initial_clock(inputs, dataset, cfg, init)
    if n == 20 and isb0 is None:
        isb0 = initial_isb(inputs, dataset, cfg, init, sys_idx)
    ep_t = np.asarray(inputs.epoch_t, float)
    robust = cfg.robust.as_core_dict(dataset)
    core_cfg = engine_config(dataset, cfg, ep_t, n + len(sc_sigmas), use_pseudorange=bool(use_pseudorange),
                             use_rate=bool(use_rate), **robust, **sc_cfg)
    if cfg.pr_gm_sigma_m > 0.0:  # Gauss-Markov pseudorange error states (meas/pseudorange_gm.hpp)
        core_cfg.update(pr_gm_sigma_m=float(cfg.pr_gm_sigma_m), pr_gm_tau_s=float(cfg.pr_gm_tau_s),
                        pr_gm_max_gap_s=float(cfg.pr_gm_max_gap_s))
    if cfg.adaptive_q_window:  # adaptive process noise (filter/adaptive_noise.hpp, engine/tight_engine.hpp)
        core_cfg.update(adaptive_q_window=int(cfg.adaptive_q_window), adaptive_q_min=float(cfg.adaptive_q_min),
                        adaptive_q_max=float(cfg.adaptive_q_max))
    return TightEngineArgs(layout=n, init=init_vector(dataset, init), P0=P0,
                           imu_correction=initial_imu_correction(cfg),
                           imu_model=model, config=core_cfg, clock0=tuple(clock0), clock_psd=(float(qb), float(qd)),
                           isb0=None if isb0 is None else np.asarray(isb0, float), inputs=inputs, epoch_t=ep_t,
                           system=sys_idx, sats=np.ascontiguousarray(inputs.sats, float).reshape(-1, 12),
                           prn=np.asarray(inputs.prn, np.int64) if len(inputs.prn) else None, robust=robust)


def tdcp_phase(inputs: TightInputs, cfg: RunConfig) -> np.ndarray:
    """The ``(M, 4)`` carrier-phase rows of ``_core.run_tight`` for a TDCP run: the
    inputs' phase, wavelength and LLI with the sigma of ``cfg.tdcp.sigma_phase_m``
    / sin(elevation) (floor 5 deg)."""
    phase = getattr(inputs, "phase", None)
    if phase is None:
        raise ValueError("tdcp: the tight inputs carry no carrier phase (TightInputs.phase); load RINEX data "
                         "(insnav.io.rinex_dataset.load_rinex, `insnav run --format rinex`) or set it with "
                         "insnav.gnss.tdcp.phase_rows")
    phase = np.array(phase, float, copy=True)
    if phase.shape != (len(inputs.prn), 4):
        raise ValueError(f"tdcp: TightInputs.phase has shape {phase.shape}; expected ({len(inputs.prn)}, 4)")
    el = np.radians(np.maximum(np.asarray(inputs.elevation_deg, float), 5.0))
    phase[:, 2] = cfg.tdcp.sigma_phase_m / np.sin(el)
    return np.ascontiguousarray(phase)


def initial_isb(inputs: TightInputs, dataset, cfg: RunConfig, init, sys_idx=None) -> np.ndarray:
    """Initial inter-system biases of R, E, C [m]: in the first epoch where GPS
    and the system are both seen (within the first 60 s of data), the median
    pseudorange offset (measured minus range plus satellite clock at the
    initial antenna position) of the system minus that of GPS; 0 for a system
    not seen with GPS."""
    from ._setup import antenna_at_init

    sys_idx = system_index(inputs.system) if sys_idx is None else np.asarray(sys_idx)
    r_ant, _ = antenna_at_init(dataset, cfg, init)
    out = np.zeros(3)
    done = np.zeros(3, bool)
    t_first = inputs.epoch_t[0] if inputs.epoch_t.size else 0.0
    for e in range(inputs.epoch_t.size):
        if inputs.epoch_t[e] > t_first + 60.0 or done.all():
            break
        a, b = inputs.epoch_start[e], inputs.epoch_start[e + 1]
        s, k = inputs.sats[a:b], sys_idx[a:b]
        off = s[:, 0] - (np.linalg.norm(s[:, 2:5] - r_ant, axis=1) - s[:, 8])
        g = (k == 0) & np.isfinite(off)
        if not g.any():
            continue
        for j in range(1, 4):
            m = (k == j) & np.isfinite(off)
            if not done[j - 1] and m.any():
                out[j - 1] = float(median(off[m]) - median(off[g]))  # np.median without numpy.ma
                done[j - 1] = True
    return out
