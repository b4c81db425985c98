"""The run set-up every filter family shares: the initial state (optionally
perturbed, Monte Carlo style), the IMU arrays, and the outage cycle."""
from __future__ import annotations

import numpy as np

from .._validate import as_float_array, check_finite, check_increasing
from ..config import RunConfig
from ..data.nav import NavState
from ..earth import radii
from ..registry import filter_spec
from ..units import DEG

__all__ = ["initial_state", "imu_arrays", "outage_cycle_period"]


def initial_state(dataset, cfg: RunConfig, rng: np.random.Generator) -> tuple[NavState, np.ndarray]:
    """Initial state (optionally perturbed, Monte Carlo style) and its 15/21 sigmas."""
    s0: NavState = dataset.initial
    sp = np.asarray(cfg.init_sigma_pos_m, float)
    sv = np.asarray(cfg.init_sigma_vel_mps, float)
    sa = np.asarray(cfg.init_sigma_att_deg, float)
    lat, lon, h = s0.lat_deg * DEG, s0.lon_deg * DEG, s0.h_m
    v = s0.v_n.copy()
    rpy = np.array([s0.roll_deg, s0.pitch_deg, s0.yaw_deg])
    if cfg.init_error:
        dp, dv, da = rng.standard_normal(3) * sp, rng.standard_normal(3) * sv, rng.standard_normal(3) * sa
        R_M, R_N = radii(lat)
        lat, lon, h = lat + dp[0] / (R_M + h), lon + dp[1] / ((R_N + h) * np.cos(lat)), h - dp[2]
        v = v + dv
        rpy = rpy + da
    state = NavState(lat / DEG, lon / DEG, h, v, *rpy)
    return state, np.concatenate([sp, sv, sa * DEG])


def imu_arrays(dataset, *, check_nonfinite: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], dtheta_b (N,3) [rad], dv_b (N,3) [m/s]) as float arrays, times increasing after t0."""
    imu = dataset.imu
    t = as_float_array(imu.t, "imu.t")
    dth = as_float_array(imu.dtheta_b, "imu.dtheta_b", (3,))
    dv = as_float_array(imu.dv_b, "imu.dv_b", (3,))
    if check_nonfinite:
        for a, name in ((t, "imu.t"), (dth, "imu.dtheta_b"), (dv, "imu.dv_b")):
            check_finite(a, name)
    check_increasing(t, "imu.t", t0=float(dataset.t0))
    return t, dth, dv


def outage_cycle_period(filter_name: str, cycle_s: float) -> float:
    """The engine's ``cycle_period``: ``cycle_s`` (one GNSS period) times the
    filter's ``outage_cycle_factor`` (:mod:`insnav.registry`)."""
    return float(cycle_s) * filter_spec(filter_name).outage_cycle_factor
