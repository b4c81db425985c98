"""Vehicle constraints as timed events for the loose engine
(``cpp/include/insnav/engine/loose_engine.hpp``, ``meas/vehicle.hpp``).

Events, from :class:`insnav.config.Constraints`:

* ``nhc``: the lateral and vertical velocity of the rear-axle point are zero
  (non-holonomic constraint, Shin 2001 sec. 4.3), at ``nhc_rate_hz`` (default
  1 Hz alone, each odometer update with ``odo``): every k-th event of the
  ``rate_hz`` grid or of the odometer updates, ``k = round(grid / nhc rate)``;
* ``odo``: at each odometer sample (decimated to ``rate_hz``), its speed,
  applied at the middle of its counting interval (the count is the mean over
  the interval), with the NHC rows in the same update on NHC's ticks;
* ``zupt``: where the standstill detector (``ins/standstill.hpp``, the SHOE
  statistic of Skog et al. 2010 over ``zupt_window_s``) is below
  ``zupt_threshold`` at an event time, a zero-velocity and zero-angular-rate
  update replaces NHC / odometer there; with ``zupt`` alone, events at
  ``rate_hz`` where the IMU stands still.  With the odometer on, standstill
  also needs its speed below ``ZUPT_ODO_SPEED_MPS``: the IMU statistic alone
  cannot tell a car cruising straight at constant speed on a smooth road from
  one standing still (both: specific force = gravity, no rotation).

With ``standstill_q_scale`` != 1 the detector's state changes on the same
grid are events too (``STILL``: stationary from here on, ``MOVING``: moving
from here on; the first grid event carries ``STILL`` when the run starts at
rest): the loose engine's standstill level of the process noise
(``engine/loose_engine.hpp``) holds from each to the next.  Only the changes
are sent, so a run that never stands still has the events it had without.
"""
from __future__ import annotations

import numpy as np

from .. import _core
from ..units import DEG, DEG_PER_H

__all__ = ["NHC", "ODO", "ZUPT", "ZARU", "STILL", "MOVING", "constraint_events", "engine_keys",
           "rear_axle_lever_arm", "standstill_at"]

NHC, ODO, ZUPT, ZARU, STILL, MOVING = 1, 2, 4, 8, 16, 32  # ConstraintKind flags of loose_engine.hpp
#: odometer speed below which the vehicle may be standing still [m/s]
ZUPT_ODO_SPEED_MPS = 0.05


def standstill_statistic(dataset, c, t: np.ndarray, dth: np.ndarray, dv: np.ndarray) -> np.ndarray:
    """The standstill detector's statistic T at every IMU sample (``ins/standstill.hpp``, the SHOE
    statistic of Skog et al. 2010, eq. (10), over ``zupt_window_s``; +inf until the window is full)."""
    rate = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 100.0
    window = int(np.clip(round(c.zupt_window_s * rate), 2, 512))
    return np.asarray(_core.standstill_statistic(t, dth, dv, float(dataset.t0), window, float(c.zupt_sigma_f_mps2),
                                                 float(c.zupt_sigma_w_dps) * DEG))


def standstill_at(dataset, c, t: np.ndarray, dth: np.ndarray, dv: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The detector's state (True: stationary, T < ``zupt_threshold``) at the last IMU sample at or
    before each of ``times`` (False before the first sample); the tight engine's per-epoch flags of the
    standstill level of the process noise (``engine/tight_engine.hpp``)."""
    T = standstill_statistic(dataset, c, t, dth, dv)
    idx = np.searchsorted(t, np.asarray(times, float), side="right") - 1
    return (idx >= 0) & (T[np.maximum(idx, 0)] < c.zupt_threshold)


def constraint_events(dataset, c, t: np.ndarray, dth: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, dict]:
    """(k, 3) events ``[t_s, kinds, speed_mps]`` sorted by time, and counts per kind."""
    use = set(c.use)
    t0, t1 = float(dataset.t0), float(t[-1])
    if "odo" in use:
        odo = getattr(dataset, "odometer", None)
        if odo is None or len(odo.t) == 0:
            raise ValueError("constraints: 'odo' needs the dataset's odometer (odometer.csv: t_s, speed_mps)")
        ot = np.asarray(odo.t, float)
        sp = np.asarray(odo.speed_mps, float)
        mid = ot - 0.5 * np.diff(np.concatenate([[ot[0] - (ot[1] - ot[0] if ot.size > 1 else 0.1)], ot]))
        period = float(np.median(np.diff(ot))) if ot.size > 1 else 1.0 / c.rate_hz
        step = max(1, int(round(1.0 / (c.rate_hz * period))))
        keep = np.zeros(ot.size, bool)
        keep[::step] = True
        keep &= (mid > t0) & (mid <= t1) & np.isfinite(sp)
        times, speed = mid[keep], sp[keep]
        kinds = np.full(times.size, ODO, np.int64)
        grid_hz = 1.0 / (period * step)
    else:
        times = np.arange(t0 + 1.0 / c.rate_hz, t1 + 1e-9, 1.0 / c.rate_hz)
        speed = np.full(times.size, np.nan)
        kinds = np.zeros(times.size, np.int64)
        grid_hz = c.rate_hz
    if "nhc" in use:  # every k-th event of the grid: NHC at nhc_rate_hz
        kinds[::max(1, int(round(grid_hz / c.nhc_rate(grid_hz))))] |= NHC
    counts = {}
    level = float(c.standstill_q_scale) != 1.0  # the standstill level of the process noise
    if "zupt" in use or level:
        T = standstill_statistic(dataset, c, t, dth, dv)
        idx = np.searchsorted(t, times, side="right") - 1
        still = (idx >= 0) & (T[np.maximum(idx, 0)] < c.zupt_threshold)
        if "odo" in use:
            still &= np.abs(speed) < ZUPT_ODO_SPEED_MPS
        if "zupt" in use:
            kinds[still] = ZUPT | ZARU
            speed[still] = np.nan
        if level:  # the detector's state changes (the first event: stationary or not yet known)
            change = still != np.concatenate([[False], still[:-1]])
            kinds[change & still] |= STILL
            kinds[change & ~still] |= MOVING
        counts["standstill_fraction_of_samples"] = float(np.mean(T < c.zupt_threshold))
    sel = kinds != 0
    ev = np.column_stack([times[sel], kinds[sel].astype(float), speed[sel]])
    k = kinds[sel]
    counts.update(nhc=int(np.sum((k & NHC) > 0)), odo=int(np.sum((k & ODO) > 0)), zupt=int(np.sum((k & ZUPT) > 0)))
    return np.ascontiguousarray(ev), counts


def rear_axle_lever_arm(dataset, c) -> np.ndarray:
    """IMU -> the constrained point (the rear-axle centre of a real car), body FRD [m]: the config's, else zero.

    Zero, not the simulator's odometer lever arm: the simulator's car
    trajectories hold the non-holonomic constraint (and the slip and bounce)
    at the IMU itself (``sim/trajectory.py``, ``_VehicleMotion``); the
    odometer's rear axle then moves sideways by ``omega x l`` in turns.
    """
    return np.zeros(3) if c.lever_arm_b_m is None else np.asarray(c.lever_arm_b_m, float)


def engine_keys(dataset, c, layout: int = 15) -> dict:
    """The loose engine's config keys of the constraints (SI); ``layout`` the run's (15 or 21),
    for the odometer sigma's default (with or without the scale-factor state)."""
    C_vb = np.asarray(_core.rotation.dcm_from_euler(np.asarray(c.mounting_rpy_deg, float) * DEG))
    return dict(vehicle_lever_arm_b=rear_axle_lever_arm(dataset, c), vehicle_C_bv=C_vb.T.ravel().copy(),
                sigma_nhc_mps=float(c.sigma_nhc_mps), sigma_odo_mps=c.odo_sigma_mps(layout),
                sigma_zupt_mps=float(c.sigma_zupt_mps), sigma_zaru_radps=float(c.sigma_zaru_dph) * DEG_PER_H,
                constraint_gate_chi2=float(c.gate_chi2), second_order_corr_s=float(c.second_order_corr_s),
                **({} if c.standstill_q_scale == 1.0 else {"standstill_q_scale": float(c.standstill_q_scale)}))
