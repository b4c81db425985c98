"""Loosely coupled runs (EKF, RB-UKF, UKF; seed 000): GNSS position and
velocity fixes on the 15- or 21-state layout (16 states: the 15 and the
odometer scale factor, with the vehicle constraints' ``odo_scale``).

The whole IMU loop runs in C++ with the GIL released
(``cpp/include/insnav/engine/loose_engine.hpp``); this module converts units,
builds the initial state and covariance, and validates inputs once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _core
from .._validate import check_finite
from ..config import ImuNoise, RunConfig
from ..units import DEG
from ._setup import (EngineArgs, engine_config, imu_arrays, init_vector, initial_imu_correction, initial_state,
                     loose_initial_sigmas, raise_if_nonfinite)
from ._assemble import nav_solution
from .solution import Solution

__all__ = ["run_loose", "loose_engine_args", "LooseEngineArgs", "selfcal_setup", "put_selfcal"]


def selfcal_setup(cfg: RunConfig) -> tuple[np.ndarray, dict, dict]:
    """The self-calibration states of a run (``[lever_arm] estimate``, ``[time]
    estimate_offset``; ``cpp/include/insnav/filter/layout.hpp``): their initial
    1-sigma in layout order (lever arm [m] x 3, then time offset [s]), the IMU
    model keys (random-walk PSDs, SI) and the engine-config keys.  Empty when off."""
    sig, model, core = [], {}, {}
    if cfg.lever_arm.estimate:
        sig += [float(cfg.lever_arm.sigma_m)] * 3
        model["lever_arm_psd"] = float(cfg.lever_arm.psd_m2_per_s)
        core["estimate_lever_arm"] = True
    if cfg.lever_arm.estimate_odometer:  # Layout18OdoLever (never with the two others: RunConfig.validate)
        sig += [float(cfg.lever_arm.odometer_sigma_m)] * 3
        model["lever_arm_psd"] = float(cfg.lever_arm.psd_m2_per_s)
        core["estimate_odo_lever_arm"] = True
    if cfg.time.estimate_offset:
        sig.append(float(cfg.time.offset_sigma_ms) * 1e-3)
        model["time_offset_psd"] = float(cfg.time.offset_psd_ms2_per_s) * 1e-6
        core["estimate_time_offset"] = True
        core["time_offset0_s"] = float(cfg.time.initial_offset_ms) * 1e-3
    return np.asarray(sig, float), model, core


def put_selfcal(sol, out: dict, cfg: RunConfig) -> None:
    """The time-offset and lever-arm estimates of a run's core output into the
    solution (per row, SI) and their last values into ``summary``."""
    if "time_offset" in out:
        sol.time_offset_s, sol.sigma_time_offset_s = out["time_offset"][:, 0], out["time_offset"][:, 1]
        if len(sol.t):
            sol.summary["time_offset_ms"] = float(sol.time_offset_s[-1] * 1e3)
            sol.summary["sigma_time_offset_ms"] = float(sol.sigma_time_offset_s[-1] * 1e3)
    if "odo_lever" in out:
        sol.odo_lever_arm_b_m, sol.sigma_odo_lever_arm_b_m = out["odo_lever"][:, :3], out["odo_lever"][:, 3:]
        if len(sol.t):
            sol.summary["odo_lever_arm_b_m"] = [float(v) for v in sol.odo_lever_arm_b_m[-1]]
            sol.summary["sigma_odo_lever_arm_b_m"] = [float(v) for v in sol.sigma_odo_lever_arm_b_m[-1]]
    if "lever_arm" in out:
        sol.lever_arm_b_m, sol.sigma_lever_arm_b_m = out["lever_arm"][:, :3], out["lever_arm"][:, 3:]
        if len(sol.t):
            sol.summary["lever_arm_b_m"] = [float(v) for v in sol.lever_arm_b_m[-1]]
            sol.summary["sigma_lever_arm_b_m"] = [float(v) for v in sol.sigma_lever_arm_b_m[-1]]


def fix_speed_mps(rows) -> np.ndarray:
    """Horizontal speed [m/s] of each row of a loose GNSS table (``[t, lat, lon
    (rad), h, v_n (3), ...]``, sorted by time): the fix's own velocity where it
    has one, else the central difference of the neighbouring fixes' positions
    (one-sided at the ends; 0 for a single fix).  Spherical-Earth metres
    (radius 6378137 m): a speed for a noise model, not for navigation."""
    rows = np.asarray(rows, float)
    v = np.hypot(rows[:, 4], rows[:, 5])
    miss = ~np.isfinite(v)
    if miss.any():
        if len(rows) < 2:
            v[miss] = 0.0
        else:
            r, t = 6378137.0, rows[:, 0]
            with np.errstate(invalid="ignore", divide="ignore"):
                vh = r * np.hypot(_gradient(rows[:, 1], t), _gradient(rows[:, 2], t) * np.cos(rows[:, 1]))
            v[miss] = np.where(np.isfinite(vh[miss]), vh[miss], 0.0)
    return v


def _gradient(f: np.ndarray, t: np.ndarray) -> np.ndarray:
    """df/dt: the second-order central difference of unequal spacing at interior points (numpy.gradient's
    formula; used always, where numpy.gradient takes another when every spacing of its input is equal,
    so that each value depends on its neighbours alone and the block-by-block run's slices give the
    whole table's values), first-order one-sided at the ends.  At least 2 points."""
    g = np.empty_like(f)
    h = np.diff(t)
    g[0] = (f[1] - f[0]) / h[0]
    g[-1] = (f[-1] - f[-2]) / h[-1]
    if f.size > 2:
        h0, h1 = h[:-1], h[1:]
        g[1:-1] = (h0 ** 2 * f[2:] - h1 ** 2 * f[:-2] + (h1 ** 2 - h0 ** 2) * f[1:-1]) / (h0 * h1 * (h0 + h1))
    return g


def loose_gnss_rows(g, cfg: RunConfig) -> np.ndarray:
    """The loose engine's GNSS table from fixes ``g``: one row per fix sorted by
    time (stable), ``[t, lat, lon (rad), h (m), v_n (3, m/s), sigma_pos_n (3, m),
    sigma_vel_n (3, m/s)]``, the sigmas multiplied by ``insnav tune``'s factors
    (``gnss_pos_sigma_scale``, ``gnss_vel_sigma_scale`` and, on the down axis,
    ``gnss_pos_v_sigma_scale``), with the motion-dependent term
    ``gnss_pos_sigma_per_speed_s`` / ``gnss_vel_sigma_per_speed`` times the
    fix's horizontal speed added in quadrature (before the vertical factor;
    :class:`insnav.config.RunConfig`).  Shared by the batch run and the
    block-by-block stream (:mod:`insnav.filters.stream`), whose rows must be
    the same."""
    if not len(g):
        return np.zeros((0, 13))
    rows = np.column_stack([g.t_valid, np.asarray(g.lat_deg) * DEG, np.asarray(g.lon_deg) * DEG, g.h_m, g.v_n,
                            g.sigma_pos_n, g.sigma_vel_n]).astype(float)
    rows = np.ascontiguousarray(rows[np.argsort(rows[:, 0], kind="stable")])
    if has_speed_terms(cfg):
        apply_sigma_factors(rows, cfg, fix_speed_mps(rows))
    else:
        apply_sigma_factors(rows, cfg)
    check_finite(rows[:, [0, 7, 8, 9]], "gnss (time/position sigma)")
    return rows


def has_speed_terms(cfg: RunConfig) -> bool:
    """Whether the fixes' sigmas grow with speed (``gnss_pos_sigma_per_speed_s`` or
    ``gnss_vel_sigma_per_speed`` > 0)."""
    return cfg.gnss_pos_sigma_per_speed_s > 0.0 or cfg.gnss_vel_sigma_per_speed > 0.0


def apply_sigma_factors(rows: np.ndarray, cfg: RunConfig, speed_mps=None) -> None:
    """The config's GNSS sigma factors on loose GNSS table rows, in place (:func:`loose_gnss_rows`;
    the push API's fixes, :class:`insnav.Navigator`, one row at a time): the scales, the
    motion-dependent terms times ``speed_mps`` (each row's horizontal speed [m/s]; needed when
    :func:`has_speed_terms`) in quadrature, then the vertical factor."""
    if cfg.gnss_pos_sigma_scale != 1.0 or cfg.gnss_vel_sigma_scale != 1.0:
        rows[:, 7:10] *= cfg.gnss_pos_sigma_scale
        rows[:, 10:13] *= cfg.gnss_vel_sigma_scale
    k_pos, k_vel = float(cfg.gnss_pos_sigma_per_speed_s), float(cfg.gnss_vel_sigma_per_speed)
    if k_pos > 0.0 or k_vel > 0.0:
        speed = np.asarray(speed_mps, float)
        rows[:, 7:10] = np.hypot(rows[:, 7:10], (k_pos * speed)[:, None])
        rows[:, 10:13] = np.hypot(rows[:, 10:13], (k_vel * speed)[:, None])  # NaN (no velocity) stays NaN
    if cfg.gnss_pos_v_sigma_scale != 1.0:
        rows[:, 9] *= cfg.gnss_pos_v_sigma_scale


def run_loose(dataset, cfg: RunConfig) -> Solution:
    """Closed-loop loosely coupled run (``cfg.filter`` in ekf, rbukf, ukf;
    ``cfg.layout`` 15 or 21); :func:`insnav.run` is the public entry."""
    t, dth, dv = imu_arrays(dataset)

    gnss = loose_gnss_rows(dataset.gnss, cfg)
    gnss_t = gnss[:, 0].copy()

    a = loose_engine_args(dataset, cfg, gnss_t, (t, dth, dv))
    n, n_core, odo_state = cfg.layout, a.layout, a.odo_state
    events, ev_counts, core_cfg = a.events, a.ev_counts, a.config
    if cfg.smooth:
        core_cfg["smooth"] = True
    out = _core.run_loose(cfg.filter, n_core, t, dth, dv, gnss, a.init, a.P0, a.imu_correction, a.imu_model,
                          core_cfg, events)
    # unit conversions in place (the arrays are ours) in one compiled pass over the rows,
    # which also finds the first non-finite row (raise_if_nonfinite below)
    sig = out["sigma"]
    sol, nonfinite = nav_solution(
        out, gnss_t=gnss_t, innovation=out["innovation"], nis=out["nis"], gnss_status=out["status"],
        log_det_s=out["log_det_s"],
        summary=dict(filter=cfg.filter, coupling=cfg.coupling, layout=n_core, updates=int(out["updates"]),
                     rejected=int(out["rejected"]), gate_reopened=int(out["gate_reopened"]),
                     gate_outage_accepted=int(out["gate_outage_accepted"]),
                     cholesky_repairs=int(out["cholesky_repairs"]), gnss_records=len(gnss_t)))
    if cfg.imu_error_sigmas:  # layout order [.. df_b dw_b (s_a s_g)] is the imu_err column order
        sol.sigma_imu_err = np.zeros((len(sol.t), 12))
        sol.sigma_imu_err[:, :n - 9] = sig[:, 9:n]
    if events is not None:
        sol.summary["constraints"] = dict(use=list(cfg.constraints.use), events=len(events), **ev_counts,
                                          updates=int(out["constraint_updates"]),
                                          rejected=int(out["constraint_rejected"]))
        sol.constraint_t, sol.constraint_kinds = events[:, 0], events[:, 1].astype(np.int8)
        sol.constraint_nis, sol.constraint_status = out["constraint_nis"], out["constraint_status"]
        sol.constraint_log_det_s = out["constraint_log_det_s"]
    sol.gnss_sigma = out["meas_sigma"]
    if cfg.adaptive_q_window:  # the adaptive process-noise factors at the end (velocity, angle random walk)
        sol.summary["process_noise_scale"] = [float(x) for x in out["process_noise_scale"]]
    put_selfcal(sol, out, cfg)
    if a.P0.shape[0] != n_core:  # the self-calibration states extend the core layout
        sol.summary["layout"] = int(a.P0.shape[0])
    if odo_state:
        sol.odo_scale, sol.sigma_odo_scale = out["odo_scale"][:, 0], out["odo_scale"][:, 1]
        if len(sol.t):
            sol.summary["constraints"]["odo_scale_ppm"] = float(sol.odo_scale[-1] * 1e6)
            sol.summary["constraints"]["sigma_odo_scale_ppm"] = float(sol.sigma_odo_scale[-1] * 1e6)
    if cfg.smooth:
        from .smoothing import smoothed_rows

        smoothed_rows(sol, out, cfg.filter, sigma=sig)
    if nonfinite or cfg.smooth:  # the message (row and time), or the smoothed rows' check
        raise_if_nonfinite(sol, cfg.filter)
    return sol


@dataclass
class LooseEngineArgs(EngineArgs):
    """What the loose engine is built from (``_core.run_loose`` and
    ``_core.LooseNavigator`` take the same): the core layout, initial state
    vector (:func:`init_vector`), P0, initial IMU correction, IMU model and
    engine config dicts, and the vehicle-constraint events (None without)."""

    odo_state: bool
    events: np.ndarray | None = None
    ev_counts: dict | None = None


def loose_engine_args(dataset, cfg: RunConfig, record_t: np.ndarray, imu=None) -> LooseEngineArgs:
    """The loose engine's set-up from a dataset and a run config: initial state
    and covariance, IMU model, engine config (outage cycle from the spacing of
    ``record_t`` [s]) and, with ``imu`` = (t, dtheta_b, dv_b) and
    ``[constraints]``, the constraint events (the push API leaves them to the caller)."""
    init, sig0 = initial_state(dataset, cfg)  # the draw (if any) from default_rng(cfg.init_seed)
    noise = cfg.imu or ImuNoise.from_dataset_model(dataset.imu_model)
    n = cfg.layout
    sig_states = loose_initial_sigmas(sig0, noise, n, cfg)
    core_model = noise.as_core_dict()
    # the odometer scale factor as a 16th state (Layout16Odo, [constraints] odo_scale)
    odo_state = bool(cfg.constraints.use) and cfg.constraints.odo_scale_state(n)
    n_core = n
    if odo_state:
        c = cfg.constraints
        n_core = 16
        sig_states = np.append(sig_states, float(c.odo_scale_sigma))
        core_model.update(odo_scale_sigma=float(c.odo_scale_sigma),
                          odo_scale_tau=np.inf if c.odo_scale_tau_s is None else float(c.odo_scale_tau_s))
    sc_sigmas, sc_model, sc_cfg = selfcal_setup(cfg)  # time offset / lever arm states (after the 15)
    sig_states = np.append(sig_states, sc_sigmas)
    core_model.update(sc_model)
    core_cfg = engine_config(dataset, cfg, record_t, n_core + len(sc_sigmas), use_position=cfg.use_position,
                             use_velocity=cfg.use_velocity,
                             # Solution keeps the position, velocity and attitude sigmas, and the IMU errors' if asked
                             sigma_columns=n_core if cfg.imu_error_sigmas else 9, **sc_cfg)
    if cfg.adaptive_r_window:  # adaptive measurement noise of the fixes (filter/adaptive_noise.hpp)
        core_cfg.update(adaptive_r_window=int(cfg.adaptive_r_window),
                        adaptive_r_min_fraction=float(cfg.adaptive_r_min_fraction))
    if cfg.adaptive_q_window:  # adaptive process noise (filter/adaptive_noise.hpp, engine/loose_engine.hpp)
        core_cfg.update(adaptive_q_window=int(cfg.adaptive_q_window), adaptive_q_min=float(cfg.adaptive_q_min),
                        adaptive_q_max=float(cfg.adaptive_q_max))
    events, ev_counts = None, None
    if cfg.constraints.use or cfg.constraints.standstill_q_scale != 1.0:  # vehicle constraints, standstill level
        from .constraints import constraint_events, engine_keys  # of Q (filters/constraints.py)

        if imu is not None:
            events, ev_counts = constraint_events(dataset, cfg.constraints, *imu)
        core_cfg.update(engine_keys(dataset, cfg.constraints, n))
    return LooseEngineArgs(layout=n_core, init=init_vector(dataset, init), P0=np.diag(sig_states ** 2),
                           imu_correction=initial_imu_correction(cfg), imu_model=core_model, config=core_cfg,
                           odo_state=odo_state, events=events, ev_counts=ev_counts)
