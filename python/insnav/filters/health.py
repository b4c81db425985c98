"""The health verdict of a run (``Solution.summary["health"]``).

Every run ends with a few numbers a script can trust without a reference:

consistency
    The GNSS records' normalized innovation squared against its expectation:
    for a consistent filter ``E[NIS] = m``, the record's row count
    (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4.2), so the ratio
    ``r = sum(NIS) / sum(m)`` over the applied records is about 1.  The verdict
    word: ``consistent`` for ``1/3 <= r <= 3`` (:data:`CONSISTENT_FACTOR`),
    ``optimistic`` above (the configured IMU noise or GNSS sigmas are too
    small), ``pessimistic`` below, ``far too optimistic`` above
    :data:`FAR_TOO_OPTIMISTIC` (10): then a warning.
broken covariance
    A 1-sigma column that is not finite or not positive (a covariance that
    lost positive definiteness): unhealthy.
km-scale jump
    A position that is not finite, a step between two output rows longer
    than :data:`MAX_STEP_M` (1 km), a speed above :data:`MAX_SPEED_MPS`
    (1 km/s) or a height outside :data:`HEIGHT_RANGE_M`: unhealthy.
GNSS span
    When the GNSS records end more than ``max(10 s, 10 GNSS intervals)``
    before the IMU, the rest of the run is free inertial: a warning.

``insnav run`` prints the verdict and exits with status 2 and a one-line
reason when the run is unhealthy (``--allow-unhealthy`` writes it anyway).
"""
from __future__ import annotations

import numpy as np

__all__ = ["assess", "CONSISTENT_FACTOR", "FAR_TOO_OPTIMISTIC", "MAX_STEP_M", "MAX_SPEED_MPS", "HEIGHT_RANGE_M"]

#: NIS ratio band of the verdict ``consistent``: [1/f, f]
CONSISTENT_FACTOR = 3.0
#: NIS ratio above which the configured noise is far too small (a warning)
FAR_TOO_OPTIMISTIC = 10.0
#: longest position step between two output rows [m]
MAX_STEP_M = 1000.0
#: highest speed [m/s]
MAX_SPEED_MPS = 1000.0
#: plausible heights [m] (the input checks' limits, insnav.config.SANITIZE_DEFAULTS)
HEIGHT_RANGE_M = (-2000.0, 100_000.0)
#: a GNSS span that ends this long before the IMU (at least) is reported [s]
MIN_TAIL_S = 10.0

_R_EARTH_M = 6_371_000.0
_APPLIED = 1  # RecordStatus.APPLIED


def _record_rows(sol) -> np.ndarray:
    rows = getattr(sol, "rows", None)
    if rows is not None and np.shape(rows) == np.shape(sol.gnss_t):
        return np.asarray(rows, float)
    inn = np.asarray(sol.innovation, float)
    if inn.ndim == 2 and inn.shape[0] == np.size(sol.gnss_t):
        return np.isfinite(inn).sum(axis=1).astype(float)
    return np.full(np.size(sol.gnss_t), np.nan)


def assess(sol, imu_t_end: float | None = None) -> dict:
    """The health verdict of a solution (module docstring).

    Parameters
    ----------
    sol : Solution
        Its rows, sigmas and GNSS record table (``gnss_t``, ``nis``, ``gnss_status``).
    imu_t_end : float, optional
        Time of the last IMU sample [s]; default the last output row.

    Returns
    -------
    dict
        ``healthy`` (bool), ``reason`` (one line, "" when healthy), ``warnings``
        (list of one-line strings), ``nis_ratio`` (mean NIS over its
        expectation, NaN without applied records), ``consistency`` (verdict
        word), ``max_step_m``, ``max_speed_mps``, ``gnss_tail_s`` (IMU time
        after the last GNSS record [s]).
    """
    out: dict = dict(healthy=True, reason="", warnings=[])
    reasons: list[str] = []
    t = np.asarray(sol.t, float)
    status = np.asarray(sol.gnss_status)
    nis = np.asarray(sol.nis, float)
    rows = _record_rows(sol)
    ok = (status == _APPLIED) & np.isfinite(nis) & np.isfinite(rows) & (rows > 0)
    ratio = float(nis[ok].sum() / rows[ok].sum()) if ok.any() else float("nan")
    out["nis_ratio"] = ratio
    if not np.isfinite(ratio):
        word = "untested"
    elif ratio > FAR_TOO_OPTIMISTIC:
        word = "far too optimistic"
    elif ratio > CONSISTENT_FACTOR:
        word = "optimistic"
    elif ratio < 1.0 / CONSISTENT_FACTOR:
        word = "pessimistic"
    else:
        word = "consistent"
    out["consistency"] = word
    if word == "far too optimistic":
        out["warnings"].append(f"the GNSS innovations are {ratio:.3g} times their expected size (mean NIS / rows; "
                               "about 1 when consistent): the configured IMU noise or GNSS sigmas are far too small")
    # broken covariance
    for name in ("sigma_pos_n_m", "sigma_vel_n_mps", "sigma_att_deg"):
        s = np.asarray(getattr(sol, name, np.zeros((0, 3))), float)
        bad = ~(np.isfinite(s) & (s > 0))
        if s.size and bad.any():
            i = int(np.flatnonzero(bad.any(axis=1))[0])
            reasons.append(f"broken covariance: {name} is {s[i][bad[i]][0]:.3g} at t = {t[i]:.3f} s "
                           f"({int(bad.any(axis=1).sum())} of {len(s)} rows)")
            break
    # km-scale jumps
    lat = np.radians(np.asarray(sol.lat_deg, float))
    lon = np.radians(np.asarray(sol.lon_deg, float))
    h = np.asarray(sol.h_m, float)
    finite = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        reasons.append(f"position not finite from t = {t[i]:.3f} s")
    step = np.zeros(0)
    if len(t) > 1:
        dn = np.diff(lat) * _R_EARTH_M
        de = np.diff(lon) * _R_EARTH_M * np.cos(lat[:-1])
        step = np.sqrt(dn ** 2 + de ** 2 + np.diff(h) ** 2)
    out["max_step_m"] = float(np.nanmax(step)) if step.size and np.isfinite(step).any() else 0.0
    speed = np.linalg.norm(np.asarray(sol.v_n, float), axis=1) if len(t) else np.zeros(0)
    out["max_speed_mps"] = float(np.nanmax(speed)) if speed.size and np.isfinite(speed).any() else 0.0
    if out["max_step_m"] > MAX_STEP_M:
        i = int(np.nanargmax(step))
        reasons.append(f"km-scale jump: the position moves {step[i] / 1000:.3g} km between t = {t[i]:.3f} and "
                       f"{t[i + 1]:.3f} s")
    elif out["max_speed_mps"] > MAX_SPEED_MPS:
        i = int(np.nanargmax(speed))
        reasons.append(f"km-scale jump: speed {speed[i]:.4g} m/s at t = {t[i]:.3f} s")
    elif finite.any():
        lo, hi = HEIGHT_RANGE_M
        out_h = finite & ((h < lo) | (h > hi))
        if out_h.any():
            i = int(np.flatnonzero(out_h)[0])
            reasons.append(f"km-scale jump: height {h[i]:.4g} m at t = {t[i]:.3f} s (outside {lo:g} .. {hi:g} m)")
    # GNSS span
    gt = np.asarray(sol.gnss_t, float)
    used = gt[status == _APPLIED] if status.shape == gt.shape else gt
    t_end = float(imu_t_end) if imu_t_end is not None else (float(t[-1]) if len(t) else float("nan"))
    tail = t_end - float(used.max()) if used.size and np.isfinite(t_end) else 0.0
    out["gnss_tail_s"] = max(0.0, tail)
    dt = float(np.median(np.diff(gt))) if gt.size > 1 else 1.0
    if tail > max(MIN_TAIL_S, 10.0 * dt):
        out["warnings"].append(f"the GNSS updates end {tail:.1f} s before the IMU (last at t = {used.max():.3f} s): "
                               "the rest of the solution is free inertial")
    if reasons:
        out["healthy"] = False
        out["reason"] = "; ".join(reasons)
    return out
