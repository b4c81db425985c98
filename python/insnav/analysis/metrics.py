"""Error analysis of a solution against truth: NED errors, RMS, max, reconvergence."""
from __future__ import annotations

import numpy as np

from ..earth import radii
from ..units import DEG, wrap_deg


def unwrapped_deg(x) -> np.ndarray:
    """Angles [deg] unwrapped for interpolation across +-180 deg over the finite values (a NaN
    left in place, not carried forward as ``np.unwrap`` would)."""
    x = np.asarray(x, float).copy()
    fin = np.isfinite(x)
    x[fin] = np.unwrap(x[fin], period=360.0)
    return x


def errors(sol, truth) -> dict:
    """Solution minus truth at the solution times (truth interpolated linearly in time).

    Returns a dict of arrays: ``t``, ``pos_n_m`` (N, 3) NED, ``vel_n_mps`` (N, 3),
    ``att_deg`` (N, 3) roll/pitch/yaw differences (yaw wrapped to +-180), and
    the solution's 1-sigma arrays when present.
    """
    t = np.asarray(sol.t)
    tt = np.asarray(truth.t)
    if t[0] < tt[0] - 1e-9 or t[-1] > tt[-1] + 1e-9:
        keep = (t >= tt[0] - 1e-9) & (t <= tt[-1] + 1e-9)
    else:
        keep = np.ones(len(t), bool)
    if not keep.any():
        raise ValueError(f"the solution ({t[0]:.3f} to {t[-1]:.3f} s) and the truth ({tt[0]:.3f} to {tt[-1]:.3f} s) "
                         "do not overlap in time (are both in the same time base, e.g. GPS seconds of week?)")
    t = t[keep]

    def at(x):
        x = np.asarray(x)
        if x.ndim == 1:
            return np.interp(t, tt, x)
        return np.column_stack([np.interp(t, tt, x[:, i]) for i in range(x.shape[1])])

    lat_t, h_t = at(truth.lat_deg) * DEG, at(truth.h_m)
    R_M, R_N = radii(lat_t)
    lat, h = np.asarray(sol.lat_deg)[keep] * DEG, np.asarray(sol.h_m)[keep]
    dlon = wrap_deg(np.asarray(sol.lon_deg, float)[keep] - at(unwrapped_deg(truth.lon_deg))) * DEG  # 242.5 = -117.5
    pos = np.column_stack([(lat - lat_t) * (R_M + h_t), dlon * (R_N + h_t) * np.cos(lat_t), -(h - h_t)])
    vel = np.asarray(sol.v_n)[keep] - at(truth.v_n)
    yaw_t = unwrapped_deg(truth.yaw_deg)
    att = np.column_stack([wrap_deg(np.asarray(sol.roll_deg)[keep] - at(truth.roll_deg)),
                           wrap_deg(np.asarray(sol.pitch_deg)[keep] - at(truth.pitch_deg)),
                           wrap_deg(np.asarray(sol.yaw_deg)[keep] - np.interp(t, tt, yaw_t))])
    out = dict(t=t, pos_n_m=pos, vel_n_mps=vel, att_deg=att)
    for k in ("sigma_pos_n_m", "sigma_vel_n_mps", "sigma_att_deg"):
        if hasattr(sol, k):
            out[k] = np.asarray(getattr(sol, k))[keep]
    return out


def rms(x, axis=0):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def reconvergence_time(t, err, t_recover, threshold, hold_s=5.0):
    """Time after ``t_recover`` until ``|err|`` stays below ``threshold`` for ``hold_s``.

    Definition used in the results: the first time t >= t_recover from which
    ``|err| <= threshold`` holds for at least ``hold_s`` seconds, minus t_recover.
    Returns NaN if it never reconverges, and when the only run within the band
    reaches the end of the data before ``hold_s`` has passed (censored: the
    data do not show it holding).
    """
    t = np.asarray(t)
    e = np.abs(np.asarray(err))
    sel = t >= t_recover
    ts, es = t[sel], e[sel]
    ok = es <= threshold
    if not ok.any():
        return float("nan")
    # start of the last violation before a hold_s-long run of ok samples
    bad_idx = np.flatnonzero(~ok)
    for i in range(len(ts)):
        if not ok[i]:
            continue
        nxt = bad_idx[bad_idx > i]
        end_t = ts[nxt[0]] if len(nxt) else ts[-1]
        if end_t - ts[i] >= hold_s:
            return float(ts[i] - t_recover)
    return float("nan")


def recovery_metrics(err: dict, t_recover: float, thresholds: dict, hold_s: float = 5.0,
                     window_s: float | None = None) -> dict:
    """Max error after a GNSS recovery and reconvergence time, per quantity and axis.

    Parameters
    ----------
    err : dict
        Output of :func:`errors`.
    t_recover : float
        Time GNSS returns [s].
    thresholds : dict
        ``{"pos_n_m": (3,), "vel_n_mps": (3,), "att_deg": (3,)}``: the band
        that defines reconvergence (see :func:`reconvergence_time`).
    window_s : float, optional
        Only look at ``[t_recover, t_recover + window_s]`` (default: to the end).

    Returns
    -------
    dict
        ``{key: {"max": (3,), "reconv_s": (3,)}}``.
    """
    t = err["t"]
    sel = t >= t_recover
    if window_s is not None:
        sel &= t <= t_recover + window_s
    out = {}
    for key, thr in thresholds.items():
        e = err[key]
        out[key] = {"max": np.abs(e[sel]).max(axis=0),
                    "reconv_s": np.array([reconvergence_time(t[sel], e[sel, i], t_recover, thr[i], hold_s)
                                          for i in range(3)])}
    return out
