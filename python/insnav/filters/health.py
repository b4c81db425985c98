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
    :data:`FAR_TOO_OPTIMISTIC` (10): then a warning.  The ratio sees only the
    records the innovation gate let through, so when the gate rejected more
    than :data:`MAX_REJECTED_SHARE` (1 %) of the records it decided on (a
    consistent filter's gate, at the 0.9999 quantile, rejects 0.01 %; a tight
    epoch whose rows the robust screening all removed counts as rejected) the
    verdict is at least ``optimistic`` and a warning says so: fixes noisier
    than their sigma are otherwise rejected out of the ratio and read as
    ``consistent``.
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

The per-row tests (sigmas, positions, steps, speeds, heights) are one
compiled pass over the solution's columns as they are, strided views included
(``_core.scan_solution``, ``cpp/include/insnav/engine/solution_scan.hpp``);
``tests/test_tight_walk_faults.py`` checks it against the numpy expressions
of the definitions above.
"""
from __future__ import annotations

import numpy as np

from .._median import diff_median

__all__ = ["assess", "CONSISTENT_FACTOR", "FAR_TOO_OPTIMISTIC", "MAX_REJECTED_SHARE", "MAX_STEP_M", "MAX_SPEED_MPS",
           "HEIGHT_RANGE_M"]

#: NIS ratio band of the verdict ``consistent``: [1/f, f]
CONSISTENT_FACTOR = 3.0
#: NIS ratio above which the configured noise is far too small (a warning)
FAR_TOO_OPTIMISTIC = 10.0
#: Share of the gate's decisions (applied + rejected records) above which the rejections
#: themselves make the verdict at least ``optimistic`` (the gate's quantile rejects 1e-4)
MAX_REJECTED_SHARE = 0.01
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
_REJECTED = 2  # RecordStatus.REJECTED_BY_GATE


def _record_rows(sol) -> np.ndarray:
    rows = getattr(sol, "rows", None)
    if rows is not None and np.shape(rows) == np.shape(sol.gnss_t):
        return np.asarray(rows, float)
    inn = np.asarray(sol.innovation, float)
    if inn.ndim == 2 and inn.shape[0] == np.size(sol.gnss_t):
        return np.isfinite(inn).sum(axis=1).astype(float)
    return np.full(np.size(sol.gnss_t), np.nan)


#: the 1-sigma blocks tested for a broken covariance, in this order
_SIGMA_BLOCKS = ("sigma_pos_n_m", "sigma_vel_n_mps", "sigma_att_deg")


def _f64(a, shape) -> np.ndarray:
    """``a`` as float64 of ``shape`` without a copy when it already is (strided views pass as they are)."""
    a = np.asarray(a)
    if a.dtype != np.float64:
        a = a.astype(np.float64)
    return a.reshape(shape) if a.shape != shape else a


def _scan_rows(sol, t) -> dict:
    """:func:`insnav._core.scan_solution` over the solution's rows (one pass, the GIL released)."""
    from .. import _core

    n = len(t)
    sigmas = []
    for name in _SIGMA_BLOCKS:
        s = getattr(sol, name, None)
        sigmas.append(_f64(s, (n, 3)) if s is not None and np.size(s) else np.ones((n, 3)))
    return _core.scan_solution(_f64(sol.lat_deg, (n,)), _f64(sol.lon_deg, (n,)), _f64(sol.h_m, (n,)),
                               _f64(sol.v_n, (n, 3)), sigmas, float(HEIGHT_RANGE_M[0]), float(HEIGHT_RANGE_M[1]),
                               _R_EARTH_M)


def assess(sol, imu_t_end: float | None = None, *, scan: dict | None = None, n_rows: int | None = None,
           records: dict | None = None) -> dict:
    """The health verdict of a solution (module docstring).

    Parameters
    ----------
    sol : Solution
        Its rows, sigmas and GNSS record table (``gnss_t``, ``nis``, ``gnss_status``).
    imu_t_end : float, optional
        Time of the last IMU sample [s]; default the last output row.
    scan : dict, optional
        The ``_core.scan_solution`` result of the rows, when they are not in
        ``sol`` (a run written block by block, :mod:`insnav.filters.stream`,
        merges its blocks' scans; it passes only scans without a bad row).
    n_rows : int, optional
        The row count with ``scan`` (default ``len(sol.t)``).
    records : dict, optional
        The GNSS records' statistics, when their arrays are not in ``sol``
        (a run written block by block writes them as it goes): ``nis_sum``
        and ``rows_sum`` of the applied records with a finite NIS and rows,
        ``applied`` and ``rejected`` (counts: applied, rejected by the gate)
        and ``applied_t_max`` [s]; ``sol.gnss_t`` still
        holds every record's time.

    Returns
    -------
    dict
        ``healthy`` (bool), ``reason`` (one line, "" when healthy), ``warnings``
        (list of one-line strings), ``nis_ratio`` (mean NIS over its
        expectation, NaN without applied records), ``rejected_share`` (the
        gate's rejected records over its decisions), ``consistency`` (verdict
        word), ``max_step_m``, ``max_speed_mps``, ``gnss_tail_s`` (IMU time
        after the last GNSS record [s]).
    """
    out: dict = dict(healthy=True, reason="", warnings=[])
    reasons: list[str] = []
    t = np.asarray(sol.t, float)
    if records is None:
        status = np.asarray(sol.gnss_status)
        nis = np.asarray(sol.nis, float)
        rows = _record_rows(sol)
        ok = (status == _APPLIED) & np.isfinite(nis) & np.isfinite(rows) & (rows > 0)
        ratio = float(nis[ok].sum() / rows[ok].sum()) if ok.any() else float("nan")
        n_applied, n_rejected = int(np.sum(status == _APPLIED)), int(np.sum(status == _REJECTED))
    else:
        ratio = float(records["nis_sum"] / records["rows_sum"]) if records["rows_sum"] > 0 else float("nan")
        n_applied, n_rejected = int(records["applied"]), int(records["rejected"])
    out["nis_ratio"] = ratio
    decided = n_applied + n_rejected
    share = n_rejected / decided if decided else 0.0
    out["rejected_share"] = share
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
    if share > MAX_REJECTED_SHARE:
        if word not in ("optimistic", "far too optimistic"):
            word = "optimistic"
        out["warnings"].append(f"the innovation gate (or a tight run's robust screening, every row of the epoch) "
                               f"rejected {n_rejected} of {decided} GNSS records ({100.0 * share:.3g} %; 0.01 % "
                               "when the model is consistent): the GNSS sigmas or the IMU noise are too small for "
                               f"these data, or the records hold outliers; the NIS ratio {ratio:.3g} sees only the "
                               "applied ones")
    out["consistency"] = word
    if word == "far too optimistic":
        out["warnings"].append(f"the GNSS innovations are {ratio:.3g} times their expected size (mean NIS / rows; "
                               "about 1 when consistent): the configured IMU noise or GNSS sigmas are far too small")
    # broken covariance, km-scale jumps: one compiled pass over the rows (engine/solution_scan.hpp)
    sc = _scan_rows(sol, t) if scan is None else scan
    n_all = len(t) if n_rows is None else int(n_rows)
    for b, name in enumerate(_SIGMA_BLOCKS):
        i = sc["first_bad_sigma"][b]
        if i >= 0:
            value = np.asarray(getattr(sol, name), float)[i, sc["first_bad_sigma_col"][b]]
            reasons.append(f"broken covariance: {name} is {value:.3g} at t = {t[i]:.3f} s "
                           f"({sc['bad_sigma_rows'][b]} of {n_all} rows)")
            break
    if sc["first_nonfinite_pos"] >= 0:
        reasons.append(f"position not finite from t = {t[sc['first_nonfinite_pos']]:.3f} s")
    out["max_step_m"] = float(sc["max_step_m"]) if sc["any_finite_step"] else 0.0
    out["max_speed_mps"] = float(sc["max_speed_mps"]) if sc["any_finite_speed"] else 0.0
    if out["max_step_m"] > MAX_STEP_M:
        i = sc["max_step_row"]
        reasons.append(f"km-scale jump: the position moves {sc['max_step_m'] / 1000:.3g} km between t = "
                       f"{t[i]:.3f} and {t[i + 1]:.3f} s")
    elif out["max_speed_mps"] > MAX_SPEED_MPS:
        i = sc["max_speed_row"]
        reasons.append(f"km-scale jump: speed {sc['max_speed_mps']:.4g} m/s at t = {t[i]:.3f} s")
    elif sc["first_height_out"] >= 0:
        i = sc["first_height_out"]
        lo, hi = HEIGHT_RANGE_M
        reasons.append(f"km-scale jump: height {float(sol.h_m[i]):.4g} m at t = {t[i]:.3f} s "
                       f"(outside {lo:g} .. {hi:g} m)")
    # GNSS span
    gt = np.asarray(sol.gnss_t, float)
    if records is None:
        used = gt[status == _APPLIED] if status.shape == gt.shape else gt
        used_any, used_max = bool(used.size), (float(used.max()) if used.size else float("nan"))
    else:
        used_any, used_max = records["applied"] > 0, float(records["applied_t_max"])
    t_end = float(imu_t_end) if imu_t_end is not None else (float(t[-1]) if len(t) else float("nan"))
    tail = t_end - used_max if used_any and np.isfinite(t_end) else 0.0
    out["gnss_tail_s"] = max(0.0, tail)
    dt = diff_median(gt) if gt.size > 1 else 1.0  # a block of intervals at a time (a day of 10 Hz fixes)
    if tail > max(MIN_TAIL_S, 10.0 * dt):
        out["warnings"].append(f"the GNSS updates end {tail:.1f} s before the IMU (last at t = {used_max:.3f} s): "
                               "the rest of the solution is free inertial")
    if reasons:
        out["healthy"] = False
        out["reason"] = "; ".join(reasons)
    return out
