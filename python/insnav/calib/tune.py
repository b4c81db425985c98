"""Automatic noise tuning by the innovation likelihood (``insnav tune``).

The filter's noise settings are multiplied by scale factors ``s_j``
(:data:`PARAMETERS`: IMU noise densities, bias instabilities, the GNSS
sigmas (loose: the vertical position sigma apart too), the vehicle-constraint sigmas), and the factors that maximise the
innovation log-likelihood of the data are searched for:

    ln L(s) = sum_k -1/2 (nu_k' S_k^-1 nu_k + ln det S_k + m_k ln 2 pi)

over the GNSS records (and constraint events) k of a run with those settings:
nu_k is the innovation (m_k rows) and S_k its covariance as the filter
predicts them.  For a linear-Gaussian model this is the exact log-likelihood
of the measurements (prediction-error decomposition, Schweppe 1965), the
basis of adaptive noise identification by maximum likelihood (Mehra 1970,
IEEE TAC 15(2), Sec. IV; Maybeck 1982, *Stochastic Models, Estimation and
Control* Vol. 2, ch. 10, eqs. (10-17)-(10-20)); for the EKF and the RB-UKF
it is the usual approximation through their linearised update.  The
engines return ``nis`` = nu' S^-1 nu and ``log_det_s`` = ln det S per record
(``Solution.nis``, ``Solution.log_det_s``), so one run gives ln L(s).

Search: Nelder-Mead (Nelder & Mead 1965, Comput. J. 7; coefficients 1, 2,
1/2, 1/2 as in Lagarias et al. 1998, SIAM J. Optim. 9) over theta = ln s,
each theta_j kept within ln 1e-3 .. ln 1e3: no gradients (a run is not
differentiable in s, e.g. through the gate), scale-free in log space.  Coarse
to fine (:func:`_search`): first one common factor per group (IMU noise, GNSS
sigmas, constraint sigmas), then every factor, then restarts from the best
point.  Each evaluation is one C++ run over the tuning segment with the GIL
released and output rows at 1 Hz only.

Robustness: beyond the chi-square 1 - 1e-4 quantile c of its rows (where the
innovation gate rejects), a record's NIS is replaced by Huber's loss
2 sqrt(c NIS) - c of its Mahalanobis distance (Huber 1964, Ann. Math.
Statist. 35(1)): a few outliers do not set the noise, and a setting cannot
gain by having the gate reject records (the loss still grows as S shrinks).

Hold-out: the factors are tuned on the first ``1 - holdout`` of the IMU time
span (the IMU arrays cut there; later records are outside the run) and the
comparison of the hand and the tuned settings (:func:`holdout_report`) uses
the records and the reference epochs after it, from runs over all the data.
``split="blocks"`` interleaves the two parts instead (:func:`block_intervals`):
data whose segment kinds (a walk's walking and its final standstill) are not
spread over the time span then have each kind in both parts.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..config import ConfigError, ImuNoise, RunConfig

__all__ = ["PARAMETERS", "TuneResult", "innovation_log_likelihood", "solution_log_likelihood", "nelder_mead_log",
           "scaled_config", "default_parameters", "tune", "holdout_report", "innovation_lag1", "tuned_toml_dict",
           "split_time", "LOG_SCALE_BOUND", "ReferenceModel", "reference_errors", "SPLITS", "block_intervals",
           "in_intervals"]

LOG_2PI = math.log(2.0 * math.pi)
#: each ln s_j is kept within +-this (scale factors 1e-3 .. 1e3)
LOG_SCALE_BOUND = math.log(1e3)
#: records above this chi-square quantile of their rows enter the likelihood clipped at it
TRIM_PROB = 1.0 - 1e-4

#: fewest innovation records (GNSS and constraint epochs) per tuned factor in the tuning segment.  A
#: variance from n independent rows has a relative standard error sqrt(2 / n); 5 loose records (30 rows)
#: give 26 % per factor.  Below it the likelihood's maximum is wherever a record or two put it (one fix
#: gave "tuned" scales of 20x and a held-out rms(error/sigma) of 39)
MIN_RECORDS_PER_FACTOR = 5

#: tunable scale factors: name -> what they multiply
PARAMETERS = {
    "gyro_arw": "gyro angle random walk, all axes ([imu] gyro_arw_deg_per_sqrt_h)",
    "acc_vrw": "accelerometer velocity random walk, all axes ([imu] acc_vrw_m_per_s_per_sqrt_h)",
    "gyro_bias": "gyro bias instability: sigma of the Gauss-Markov bias (its driving noise with it), all axes "
                 "([imu] gyro_bias_sigma_deg_per_h)",
    "acc_bias": "accelerometer bias instability, all axes ([imu] acc_bias_sigma_mg)",
    "gnss_pos": "GNSS sigmas of the data: loose position, tight pseudorange (gnss_pos_sigma_scale)",
    "gnss_vel": "GNSS sigmas of the data: loose velocity, tight pseudorange rate (gnss_vel_sigma_scale)",
    "gnss_pos_v": "loose only: the vertical position sigma, on top of gnss_pos (gnss_pos_v_sigma_scale)",
    "gnss_pos_speed": "loose only: the motion-dependent term of the position sigma, per unit of the fix's speed "
                      "(gnss_pos_sigma_per_speed_s; > 0 in the base settings)",
    "gnss_vel_speed": "loose only: the motion-dependent term of the velocity sigma (gnss_vel_sigma_per_speed; > 0 "
                      "in the base settings)",
    "nhc": "non-holonomic constraint sigma ([constraints] sigma_nhc_mps)",
    "odo": "odometer speed sigma ([constraints] sigma_odo_mps)",
    "zupt": "zero-velocity and zero-angular-rate sigmas ([constraints] sigma_zupt_mps, sigma_zaru_dph)",
    "standstill_q": "standstill level of the velocity and angle random walks ([constraints] standstill_q_scale)",
    "pr_gm_sigma": "tight EKF: stationary sigma of the Gauss-Markov pseudorange errors (pr_gm_sigma_m; the block on)",
    "pr_gm_tau": "tight EKF: correlation time of the Gauss-Markov pseudorange errors (pr_gm_tau_s; the block on)",
}

#: filters whose engines return ln det S (the linear-update filters)
FILTERS = ("ekf", "rbukf")


# --------------------------------------------------------------------------- the likelihood

def innovation_log_likelihood(nis, log_det_s, rows, nis_cap=None) -> float:
    """``sum_k -(nis_k + log_det_s_k + rows_k ln 2 pi) / 2`` over the records
    with finite values and at least one row (Mehra 1970, Sec. IV).

    Parameters
    ----------
    nis : (K,) nu' S^-1 nu of each record [-]
    log_det_s : (K,) ln det S [ln of the product of the rows' units squared]
    rows : (K,) int, rows m_k of each record
    nis_cap : float or (K,) array, optional
        Huber's loss beyond this NIS (the robust likelihood of the tuner):
        ``nis`` replaced by ``2 sqrt(c nis) - c`` where ``nis > c`` (Huber
        1964, on the Mahalanobis distance ``sqrt(nis)``): an outlier counts
        linearly in its distance, not quadratically, and a small ``S`` still
        costs (a plain clip would let ln det S -> -inf win).
    """
    nis = np.asarray(nis, float)
    ld = np.asarray(log_det_s, float)
    m = np.asarray(rows, float)
    ok = np.isfinite(nis) & np.isfinite(ld) & (m > 0)
    q = nis[ok]
    if nis_cap is not None:
        cap = np.broadcast_to(np.asarray(nis_cap, float), nis.shape)[ok]
        big = q > cap
        q = np.where(big, 2.0 * np.sqrt(np.where(big, cap * q, 0.0)) - cap, q)
    return float(-0.5 * np.sum(q + ld[ok] + m[ok] * LOG_2PI))


def _gnss_rows(sol) -> np.ndarray:
    rows = getattr(sol, "rows", None)
    if rows is not None:  # tight: measurement rows of each epoch
        return np.asarray(rows, float)
    inn = np.asarray(sol.innovation, float)
    return np.isfinite(inn).sum(axis=1).astype(float) if inn.size else np.zeros(0)


def _constraint_rows(kinds) -> np.ndarray:
    """Rows of each vehicle-constraint event (loose_engine.hpp ConstraintKind): NHC 2, odometer 1,
    standstill: ZUPT 3 + ZARU 3 (instead of NHC / odometer)."""
    k = np.asarray(kinds, np.int64)
    still = 3 * ((k & 4) > 0) + 3 * ((k & 8) > 0)
    return np.where(still > 0, still, 2 * ((k & 1) > 0) + ((k & 2) > 0)).astype(float)


def _caps(rows) -> np.ndarray:
    from ..gnss.spp import chi2_quantile

    rows = np.asarray(rows, float)
    out = np.full(rows.shape, np.inf)
    for m in np.unique(rows[np.isfinite(rows) & (rows > 0)]):
        out[rows == m] = chi2_quantile(TRIM_PROB, int(m))
    return out


def solution_log_likelihood(sol, t_from=-np.inf, t_to=np.inf, trim: bool = True,
                            intervals=None) -> tuple[float, int]:
    """(ln L, records) of a run's innovations: the GNSS records with an
    innovation covariance (applied or rejected by the gate) with time of
    validity in [t_from, t_to), and the vehicle-constraint events likewise;
    ``intervals`` ([(a, b), ...] [s], optional): only those inside one of them.

    ``trim``: Huber's loss beyond the chi-square 1 - 1e-4 quantile of the record's rows
    (:func:`innovation_log_likelihood`).
    """
    from ..filters.solution import RecordStatus

    if getattr(sol, "log_det_s", None) is None:
        raise ValueError("the solution has no ln det S (only the loose and tight ekf / rbukf runs give it)")
    total, n = 0.0, 0
    streams = [(sol.gnss_t, sol.gnss_status, sol.nis, sol.log_det_s, _gnss_rows(sol))]
    if getattr(sol, "constraint_log_det_s", None) is not None:
        streams.append((sol.constraint_t, sol.constraint_status, sol.constraint_nis, sol.constraint_log_det_s,
                        _constraint_rows(sol.constraint_kinds)))
    for t, st, nis, ld, rows in streams:
        t, st = np.asarray(t, float), np.asarray(st)
        keep = (t >= t_from) & (t < t_to) & ((st == RecordStatus.APPLIED) | (st == RecordStatus.REJECTED_BY_GATE))
        if intervals is not None:
            keep &= in_intervals(t, intervals)
        if not keep.any():
            continue
        r = rows[keep]
        total += innovation_log_likelihood(np.asarray(nis)[keep], np.asarray(ld)[keep], r,
                                           _caps(r) if trim else None)
        n += int(keep.sum())
    return total, n


# --------------------------------------------------------------------------- the search

def nelder_mead_log(fun, x0, step=math.log(3.0), *, max_evals: int = 120, xtol: float = 0.01, ftol: float = 0.01,
                    bound: float = LOG_SCALE_BOUND):
    """Minimise ``fun(theta)`` over log-scale factors by Nelder-Mead.

    Nelder & Mead (1965) with the standard coefficients (reflection 1,
    expansion 2, contraction 1/2, shrink 1/2; Lagarias et al. 1998), the
    initial simplex ``x0 + step e_j``, every point clipped to ``+-bound``.
    Stops when the simplex spans less than ``xtol`` in every coordinate and
    less than ``ftol`` in ``fun``, or after ``max_evals`` evaluations.

    Returns
    -------
    (theta_best, f_best, evaluations, history) ; history: list of (theta, f)
    """
    x0 = np.asarray(x0, float)
    n = x0.size
    hist = []

    def f(x):
        x = np.clip(x, -bound, bound)
        v = float(fun(x))
        if not math.isfinite(v):
            v = math.inf
        hist.append((x.copy(), v))
        return x, v

    pts = [f(x0)]
    for j in range(n):
        e = np.zeros(n)
        e[j] = step if x0[j] + step <= bound else -step
        pts.append(f(x0 + e))
    while len(hist) < max_evals:
        pts.sort(key=lambda p: p[1])
        xs = np.array([p[0] for p in pts])
        fs = np.array([p[1] for p in pts])
        if np.max(np.abs(xs[1:] - xs[0])) <= xtol and fs[-1] - fs[0] <= ftol:
            break
        c = xs[:-1].mean(axis=0)
        xr, fr = f(c + (c - xs[-1]))
        if fr < fs[0]:
            if len(hist) >= max_evals:
                pts[-1] = (xr, fr)
                break
            xe, fe = f(c + 2.0 * (c - xs[-1]))
            pts[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < fs[-2]:
            pts[-1] = (xr, fr)
        else:
            if len(hist) >= max_evals:
                break
            if fr < fs[-1]:  # outside contraction
                xc, fc = f(c + 0.5 * (xr - c))
                ok = fc <= fr
            else:  # inside contraction
                xc, fc = f(c + 0.5 * (xs[-1] - c))
                ok = fc < fs[-1]
            if ok:
                pts[-1] = (xc, fc)
            else:  # shrink towards the best point
                new = [pts[0]]
                for p in pts[1:]:
                    if len(hist) >= max_evals:
                        new.append(p)
                        continue
                    new.append(f(xs[0] + 0.5 * (p[0] - xs[0])))
                pts = new
    best = min(hist, key=lambda p: p[1])
    return best[0], best[1], len(hist), hist


#: the groups of the coarse first stage of the search (one common factor each)
GROUPS = (("gyro_arw", "acc_vrw", "gyro_bias", "acc_bias"),
          ("gnss_pos", "gnss_vel", "gnss_pos_v", "gnss_pos_speed", "gnss_vel_speed"),
          ("nhc", "odo", "zupt"))


def _search(objective, names, x0, step, budget, xtol, used):
    """Coarse to fine: Nelder-Mead over one common ln-factor per group of
    :data:`GROUPS` (the overall level of the IMU noise, of the GNSS sigmas, of
    the constraint sigmas: the usual error of a hand setting, 2-3 dimensions),
    then over every factor from there, then restarts from the best point with
    a fresh simplex (step halved each time) while they gain more than 0.01 in
    ln L and the budget of evaluations (``used()`` counts them) lasts.
    Restarts are the standard remedy for a simplex that collapsed along a
    ridge (e.g. gyro white noise against gyro bias instability)."""
    n0 = used()
    best = [np.asarray(x0, float), math.inf]

    def left():
        return budget - (used() - n0)

    def run(fun, x, st, evals, tol):
        th, f, _, _ = nelder_mead_log(fun, x, step=st, max_evals=evals, xtol=tol, ftol=0.01)
        return th, f

    groups = [[names.index(p) for p in g if p in names] for g in GROUPS]
    groups = [g for g in groups if g]
    x = np.asarray(x0, float).copy()
    if len(groups) < len(names) and left() > 4 * (len(groups) + 1) + 2 * len(names):
        def coarse(z):
            y = x.copy()
            for gi, g in enumerate(groups):
                y[g] = x[g] + z[gi]
            return objective(y)

        z, f = run(coarse, np.zeros(len(groups)), math.log(4.0), min(left() // 3, 15 * len(groups)), 0.05)
        for gi, g in enumerate(groups):
            x[g] += z[gi]
        best = [x.copy(), f]
    st = step
    while left() > len(names) + 2:
        th, f = run(objective, best[0], st, left(), xtol)
        gain = best[1] - f
        if f < best[1]:
            best = [th, f]
        if not gain > 0.01:
            break
        st = max(0.5 * st, 4 * xtol)
    return best


# --------------------------------------------------------------------------- the settings

def base_noise(dataset, cfg: RunConfig) -> ImuNoise:
    """The IMU noise model a run with ``cfg`` uses (the config's, else the dataset's)."""
    return dataclasses.replace(cfg.imu) if cfg.imu is not None else ImuNoise.from_dataset_model(dataset.imu_model)


def default_parameters(dataset, cfg: RunConfig) -> list[str]:
    """The factors tuned by default: the four IMU terms, the GNSS position (pseudorange)
    sigma, the velocity (rate) sigma when the data have it, loose with position
    rows the vertical position sigma (``gnss_pos_v``) and, where the base
    settings have them (> 0), the motion-dependent terms of the position and
    velocity sigmas (``gnss_pos_speed``, ``gnss_vel_speed``), the sigmas of the
    constraints in use, and for a tight run with Gauss-Markov pseudorange
    states (``pr_gm_sigma_m > 0``) their sigma and correlation time."""
    names = ["gyro_arw", "acc_vrw", "gyro_bias", "acc_bias", "gnss_pos"]
    if cfg.use_velocity and _has_velocity(dataset, cfg):
        names.append("gnss_vel")
    if cfg.coupling == "loose" and cfg.use_position:
        names.append("gnss_pos_v")
        if cfg.gnss_pos_sigma_per_speed_s > 0:
            names.append("gnss_pos_speed")
    if cfg.coupling == "loose" and "gnss_vel" in names and cfg.gnss_vel_sigma_per_speed > 0:
        names.append("gnss_vel_speed")
    names += [c for c in ("nhc", "odo", "zupt") if c in cfg.constraints.use]
    if cfg.constraints.standstill_q_scale != 1.0:
        names.append("standstill_q")
    if cfg.coupling == "tight" and cfg.pr_gm_sigma_m > 0:
        names += ["pr_gm_sigma", "pr_gm_tau"]
    return names


def _has_velocity(dataset, cfg) -> bool:
    if cfg.coupling == "tight":
        inp = getattr(dataset, "tight_inputs", None)
        return inp is None or bool(np.isfinite(np.asarray(inp.sats)[:, 1]).any())
    g = dataset.gnss
    return len(g) > 0 and bool(np.isfinite(np.asarray(g.v_n)).any() and np.isfinite(np.asarray(g.sigma_vel_n)).any())


def scaled_config(cfg: RunConfig, noise: ImuNoise, scales: dict) -> RunConfig:
    """A copy of ``cfg`` with the noise of :data:`PARAMETERS` multiplied by ``scales`` (name -> factor)."""
    unknown = [k for k in scales if k not in PARAMETERS]
    if unknown:
        raise ConfigError(f"unknown tuning parameter {unknown[0]!r}; known: {', '.join(PARAMETERS)}")
    c = dataclasses.replace(cfg, imu=dataclasses.replace(noise), constraints=dataclasses.replace(cfg.constraints))
    n = c.imu

    def mul(v, s):
        return (np.asarray(v, float) * s).tolist()

    s = scales.get
    if "gyro_arw" in scales:
        n.gyro_arw = mul(noise.gyro_arw, s("gyro_arw"))
    if "acc_vrw" in scales:
        n.acc_vrw = mul(noise.acc_vrw, s("acc_vrw"))
    if "gyro_bias" in scales:
        n.gyro_bias_sigma = mul(noise.gyro_bias_sigma, s("gyro_bias"))
        n.gyro_bias_rw = mul(noise.gyro_bias_rw, s("gyro_bias"))
    if "acc_bias" in scales:
        n.acc_bias_sigma = mul(noise.acc_bias_sigma, s("acc_bias"))
        n.acc_bias_rw = mul(noise.acc_bias_rw, s("acc_bias"))
    if "gnss_pos" in scales:
        c.gnss_pos_sigma_scale = float(cfg.gnss_pos_sigma_scale * s("gnss_pos"))
    if "gnss_vel" in scales:
        c.gnss_vel_sigma_scale = float(cfg.gnss_vel_sigma_scale * s("gnss_vel"))
    if "gnss_pos_v" in scales:
        c.gnss_pos_v_sigma_scale = float(cfg.gnss_pos_v_sigma_scale * s("gnss_pos_v"))
    if "gnss_pos_speed" in scales:
        c.gnss_pos_sigma_per_speed_s = float(cfg.gnss_pos_sigma_per_speed_s * s("gnss_pos_speed"))
    if "gnss_vel_speed" in scales:
        c.gnss_vel_sigma_per_speed = float(cfg.gnss_vel_sigma_per_speed * s("gnss_vel_speed"))
    k = c.constraints
    if "nhc" in scales:
        k.sigma_nhc_mps = float(cfg.constraints.sigma_nhc_mps * s("nhc"))
    if "odo" in scales:
        k.sigma_odo_mps = float(cfg.constraints.odo_sigma_mps(cfg.layout) * s("odo"))
    if "zupt" in scales:
        k.sigma_zupt_mps = float(cfg.constraints.sigma_zupt_mps * s("zupt"))
        k.sigma_zaru_dph = float(cfg.constraints.sigma_zaru_dph * s("zupt"))
    if "standstill_q" in scales:
        k.standstill_q_scale = float(cfg.constraints.standstill_q_scale * s("standstill_q"))
    if "pr_gm_sigma" in scales:
        c.pr_gm_sigma_m = float(cfg.pr_gm_sigma_m * s("pr_gm_sigma"))
    if "pr_gm_tau" in scales:
        c.pr_gm_tau_s = float(cfg.pr_gm_tau_s * s("pr_gm_tau"))
    return c


def _plain_robust(robust):
    """The ``[robust]`` settings of a tight run while tuning, and of the tuned run: no per-satellite
    screening, fault exclusion or CUSUM.  They remove or down-weight rows depending on the noise
    setting, and ln L over different rows is not comparable (with them on, a tiny pseudorange sigma
    won on the real walk by screening out all but the easy rows); their thresholds are multiples of
    the sigmas, so the tuned sigmas are only right without them.  Huber's loss per epoch
    (:func:`innovation_log_likelihood`) keeps a few outliers from setting the noise."""
    return dataclasses.replace(robust, screening=False, fde_max_sats=0, cusum_h=0.0)


def split_time(dataset, holdout: float) -> float:
    """The time [s] that ends the tuning segment: the first ``1 - holdout`` of the IMU span."""
    if isinstance(holdout, bool) or not isinstance(holdout, (int, float)) or not (0.0 <= holdout < 0.9):
        raise ConfigError(f"holdout {holdout!r}: expected a fraction of the data in [0, 0.9) (0: no hold-out)")
    t = np.asarray(dataset.imu.t, float)
    if t.size < 2:
        raise ConfigError("the dataset has fewer than 2 IMU samples")
    return float(t[-1]) if holdout == 0 else float(t[0] + (1.0 - holdout) * (t[-1] - t[0]))


#: the ways the data are split into a tuning and a held-out part (:func:`tune`'s ``split``)
SPLITS = ("tail", "blocks")


def block_intervals(dataset, holdout: float, block_s: float) -> tuple[list, list]:
    """Interleaved tuning and held-out intervals [s] of ``split = "blocks"``:
    the IMU span cut into consecutive blocks of ``block_s`` seconds (the last
    one shorter), the first ``1 - holdout`` of each block for the tuning, the
    rest held out (blocked cross-validation of a time series: Snijders 1988,
    in *On Model Uncertainty and its Statistical Implications*, pp. 56-69;
    Bergmeir & Benitez 2012, Inf. Sci. 191).  Every kind of segment longer
    than a block (a walk's standstill and its walking) then has a share in
    both parts, which the tail split does not give when the data end with a
    segment of a kind they did not contain before.

    Returns
    -------
    (tuning, heldout) : lists of (t_start, t_end) [s], half-open [a, b)
    """
    split_time(dataset, holdout)  # the same checks of holdout
    if isinstance(block_s, bool) or not isinstance(block_s, (int, float)) or not (math.isfinite(block_s)
                                                                                  and block_s > 0):
        raise ConfigError(f"block_s {block_s!r}: expected a block length > 0 [s]")
    t = np.asarray(dataset.imu.t, float)
    t0, t1 = float(t[0]), float(t[-1])
    tun, held = [], []
    a = t0
    while a < t1:
        b = min(a + float(block_s), t1)
        m = a + (1.0 - holdout) * (b - a)
        tun.append((a, m))
        if holdout > 0:
            held.append((m, b if b < t1 else math.inf))
        a = b
    return tun, held


def in_intervals(t, intervals) -> np.ndarray:
    """Boolean mask of the times ``t`` inside any of the half-open ``intervals`` [(a, b), ...]."""
    t = np.asarray(t, float)
    m = np.zeros(t.shape, bool)
    for a, b in intervals:
        m |= (t >= a) & (t < b)
    return m


def _cut(dataset, t_end: float):
    """The dataset with its IMU samples after ``t_end`` left out."""
    from ..data.dataset import ImuData

    imu = dataset.imu
    k = int(np.searchsorted(np.asarray(imu.t), t_end, side="right"))
    if k >= len(imu.t):
        return dataset
    return dataclasses.replace(dataset, imu=ImuData(imu.t[:k], imu.dtheta_b[:k], imu.dv_b[:k]))


# --------------------------------------------------------------------------- tuning

@dataclass
class TuneResult:
    """What :func:`tune` found.

    Attributes
    ----------
    names : list of str
        The tuned factors (:data:`PARAMETERS`).
    scales : dict
        name -> factor on the base settings (1 = unchanged).
    base, tuned : RunConfig
        The settings before and after (``tuned.imu`` complete).
    log_likelihood_base, log_likelihood_tuned : float
        ln L over the tuning segment's records.
    records : int
        Records in the tuning segment's likelihood.
    runs : int
        Evaluations of ln L the search used (each one filter run per dataset).
    seconds : float
        Wall time of the search [s] (the first, sanitizing step included).
    t_split : float or tuple of float
        End of the tuning segment [s] (dataset time); hold-out after it (one per
        dataset when several were given).
    holdout : float
    history : list of (dict of scales, ln L, records)
    """

    names: list
    scales: dict
    base: RunConfig
    tuned: RunConfig
    log_likelihood_base: float
    log_likelihood_tuned: float
    records: int
    runs: int
    seconds: float
    t_split: float
    holdout: float
    history: list = field(default_factory=list, repr=False)
    #: ``split`` of :func:`tune`, and the held-out intervals [(a, b), ...] [s] of the first dataset
    #: (tail: one, [t_split, inf)); the tuning intervals likewise
    split: str = "tail"
    heldout: list = field(default_factory=list)
    tuning: list = field(default_factory=list)
    #: ``[time] estimate_offset = "auto"``: the test that settled it before the search (the base
    #: settings with the state, on the first dataset's tuning segment, the whole of it with the blocks
    #: split; insnav.filters._run_offset_auto), after which
    #: every run and the written file carry true or false; None otherwise
    time_offset_test: dict | None = None


def tune(dataset, config=None, *, filter: str | None = None, coupling: str | None = None, params=None,
         holdout: float = 0.3, max_runs: int = 80, start=None, xtol: float = 0.01, step: float = math.log(3.0),
         progress=None, split: str = "tail", block_s: float = 20.0) -> TuneResult:
    """Tune the noise scale factors of a loose or tight EKF / RB-UKF run by
    maximising the innovation log-likelihood over the first ``1 - holdout``
    of the data (module docstring).

    Parameters
    ----------
    dataset : insnav.Dataset (or a CSV / RINEX / KF-GINS dataset), or a list of them
        Several datasets (e.g. drives with the same sensors) are tuned
        together: ln L is the sum of their ln L (independent data), each
        split by ``holdout`` of its own.
    config : RunConfig, dict or TOML path, optional
        The base (hand) settings; the factors multiply them.
    filter : {'ekf', 'rbukf'}, optional
    coupling : {'loose', 'tight'}, optional
    params : list of str, optional
        Factors to tune (:data:`PARAMETERS`); default :func:`default_parameters`.
    holdout : float
        Share of the data (the end of the IMU span) left out of the tuning, in [0, 0.9).
    max_runs : int
        Evaluations of ln L the search may use (>= 2 * factors + 2; one filter
        run per dataset each).
    start : dict, optional
        Starting factors (name -> factor; default 1 for each).
    xtol : float
        Convergence: the simplex spans less than this in every ln s_j (0.01: 1 %).
    step : float
        Initial simplex step in ln s (ln 3).
    progress : callable, optional
        Called with (run, scales, ln L) after every run.
    split : {'tail', 'blocks'}
        ``tail``: the last ``holdout`` of the IMU span is held out and the
        tuning runs end at the split (the IMU cut there).  ``blocks``:
        interleaved blocks (:func:`block_intervals`, ``block_s`` long, the
        last ``holdout`` of each held out): the tuning runs go over all the
        data, every record applied as in use, and ln L sums only the records
        of the tuning intervals (the held-out records' innovations, and any
        reference, stay out of the objective).
    block_s : float
        Block length [s] of ``split = "blocks"``.

    Returns
    -------
    TuneResult
    """
    from ..filters import _as_config
    from ..filters.sanitize import sanitize_dataset
    from ..registry import filter_spec

    t_start = time.perf_counter()
    cfg = _as_config(config)
    if filter is not None:
        cfg.filter = filter
    if coupling is not None:
        cfg.coupling = coupling
    cfg.validate()
    if cfg.filter not in FILTERS or cfg.coupling not in ("loose", "tight"):
        raise ConfigError(f"filter {cfg.filter!r} with {cfg.coupling} coupling cannot be tuned: the tuner needs the "
                          f"innovation covariance, which the loose and tight {' and '.join(FILTERS)} return")
    smooth = cfg.smooth  # the user's: back in base and tuned, so the report runs as the written file does
    cfg.smooth = False  # the smoother does not change the forward innovations
    datasets = list(dataset) if isinstance(dataset, (list, tuple)) else [dataset]
    if not datasets:
        raise ConfigError("no dataset to tune on")
    splits = [split_time(d, holdout) for d in datasets]
    if split not in SPLITS:
        raise ConfigError(f"split {split!r}: expected one of {', '.join(SPLITS)}")
    blocks = [block_intervals(d, holdout, block_s) for d in datasets] if split == "blocks" else None
    names = list(params) if params is not None else default_parameters(datasets[0], cfg)
    bad = [p for p in names if p not in PARAMETERS]
    if bad:
        raise ConfigError(f"unknown tuning parameter {bad[0]!r}; known: {', '.join(PARAMETERS)}")
    if not names:
        raise ConfigError("no parameter to tune")
    if "gnss_pos_v" in names and cfg.coupling != "loose":
        raise ConfigError(f"tuning parameter 'gnss_pos_v' scales the vertical sigma of loose position fixes; "
                          f"not with {cfg.coupling} coupling")
    for c, key in (("gnss_pos_speed", "gnss_pos_sigma_per_speed_s"), ("gnss_vel_speed", "gnss_vel_sigma_per_speed")):
        if c in names and not (cfg.coupling == "loose" and getattr(cfg, key) > 0):
            raise ConfigError(f"tuning parameter {c!r} scales {key}: it needs loose coupling and {key} > 0 in the "
                              "base settings (a factor on 0 stays 0)")
    for c in ("nhc", "odo", "zupt"):
        if c in names and c not in cfg.constraints.use:
            raise ConfigError(f"tuning parameter {c!r} needs the {c} constraint in use (--constraints / "
                              "[constraints] use)")
    for c in ("pr_gm_sigma", "pr_gm_tau"):
        if c in names and not (cfg.coupling == "tight" and cfg.pr_gm_sigma_m > 0):
            raise ConfigError(f"tuning parameter {c!r} needs the tight EKF's Gauss-Markov pseudorange states on "
                              "(pr_gm_sigma_m > 0)")
    if isinstance(max_runs, bool) or not isinstance(max_runs, (int, np.integer)) or max_runs < 2 * len(names) + 2:
        raise ConfigError(f"max_runs {max_runs!r}: at least {2 * len(names) + 2} for {len(names)} factors")
    start = dict(start or {})
    for k, v in start.items():
        if k not in names or not (isinstance(v, (int, float)) and v > 0 and math.isfinite(v)):
            raise ConfigError(f"start factor {k!r} = {v!r}: a factor > 0 of a tuned parameter ({', '.join(names)})")

    datasets = [sanitize_dataset(d, {**cfg.sanitize} or True)[0] for d in datasets]
    noise = base_noise(datasets[0], cfg)
    segs = [_cut(d, t) for d, t in zip(datasets, splits)] if blocks is None else datasets
    spec = filter_spec(cfg.filter)
    options = spec.options_class(cfg.coupling)(**cfg.options)  # the config's [options], as insnav.run
    offset_test = None
    if cfg.time.estimate_offset == "auto":  # settled once, so every run (tuning, report, the file) is one model
        from ..filters import _run_offset_auto

        probe = dataclasses.replace(cfg, imu=noise)  # on the tuning segment (tail split): not the held-out data
        offset_test = _run_offset_auto(spec, segs[0], probe, options).summary["time_offset_test"]
        cfg.time = dataclasses.replace(cfg.time, estimate_offset=bool(offset_test["state_kept"]))
    seg = segs[0]
    dt = float(np.median(np.diff(np.asarray(seg.imu.t[:1000], float)))) if len(seg.imu.t) > 2 else 1.0
    decim = max(1, int(round(1.0 / dt))) if dt > 0 else 1
    history = []

    def loglik(scales: dict) -> float:
        c = scaled_config(cfg, noise, scales)
        c.output_decimation = decim
        if c.coupling == "tight":
            c.robust = _plain_robust(c.robust)
        ll, n = 0.0, 0
        for i, (sg, ts) in enumerate(zip(segs, splits)):
            try:
                sol = spec.run(c.coupling, sg, c, options)
            except (ValueError, FloatingPointError, RuntimeError):
                ll, n = -math.inf, 0  # a setting the filter cannot run with (e.g. a covariance gone non-finite)
                break
            if blocks is None:
                lk, nk = solution_log_likelihood(sol, t_to=ts + 1e-9)
            else:
                lk, nk = solution_log_likelihood(sol, intervals=blocks[i][0])
            ll, n = ll + lk, n + nk
        history.append((dict(scales), ll, n))
        if progress is not None:
            progress(len(history), dict(scales), ll)
        return ll

    def objective(theta):
        return -loglik({k: float(math.exp(v)) for k, v in zip(names, theta)})

    base_scales = {k: 1.0 for k in names}
    ll_base = loglik(base_scales)
    n_base, n_need = history[0][2], MIN_RECORDS_PER_FACTOR * len(names)
    where = f"before t = {splits[0]:.3f} s" if blocks is None else "in its blocks"
    if n_base == 0:
        raise ConfigError(f"no GNSS record with an innovation covariance in the tuning segment ({where})")
    if n_base < n_need:
        raise ConfigError(f"{n_base} GNSS or constraint records with an innovation in the tuning segment ({where}): "
                          f"too few to tune {len(names)} factors (at least {MIN_RECORDS_PER_FACTOR} per factor, "
                          f"{n_need}); give a longer recording, fewer --params or a smaller --holdout")
    x0 = np.array([math.log(start.get(k, 1.0)) for k in names])
    _search(objective, names, x0, step, max_runs - 1, xtol, lambda: len(history))
    # the search's evaluations are in history (the base run too); pick the best of all
    best_scales, ll_best, n_best = max(history, key=lambda h: h[1])
    if not math.isfinite(ll_best) or n_best == 0:
        raise ConfigError(f"no GNSS record with an innovation covariance in the tuning segment ({where})")
    tuned = scaled_config(cfg, noise, best_scales)
    if tuned.coupling == "tight":  # run as tuned (_plain_robust)
        tuned.robust = _plain_robust(tuned.robust)
    tuned.smooth = smooth
    base = dataclasses.replace(cfg, imu=noise, smooth=smooth)
    return TuneResult(names=names, scales=best_scales, base=base, tuned=tuned, log_likelihood_base=ll_base,
                      log_likelihood_tuned=ll_best, records=n_best, runs=len(history),
                      seconds=time.perf_counter() - t_start,
                      t_split=splits[0] if len(splits) == 1 else tuple(splits), holdout=float(holdout), history=history,
                      split=split, heldout=[(splits[0], math.inf)] if blocks is None else blocks[0][1],
                      tuning=[(-math.inf, splits[0])] if blocks is None else blocks[0][0],
                      time_offset_test=offset_test)


# --------------------------------------------------------------------------- the report

def innovation_lag1(sol, t_from: float = -np.inf, t_to: float = np.inf, intervals=None) -> tuple[float, float]:
    """Lag-1 autocorrelation of the innovations of the applied GNSS records in
    [t_from, t_to): (position or pseudorange rows, velocity or pseudorange-rate
    rows), each the mean over the sequences (loose: the N, E, D components;
    tight: one sequence per satellite) weighted by their pairs; NaN without one.
    ``intervals`` ([(a, b), ...] [s]): one sequence per interval and component
    (no pair across two intervals).

    The innovations of a filter whose model is right are white (Kailath 1968;
    Mehra 1970, Sec. III, the basis of its adaptive tuning): about 0, within
    +-2 / sqrt(pairs).  Clearly positive values mean measurement errors (or
    unmodelled states) correlated from one record to the next, e.g. slowly
    varying pseudorange errors: the innovation likelihood then sees only
    their record-to-record part, the tuned sigmas fit that, and the filter is
    overconfident on anything slower (docs/algorithms.md section 20).
    """
    from ..filters.solution import RecordStatus

    t = np.asarray(getattr(sol, "gnss_t", ()), float)
    inn = np.asarray(getattr(sol, "innovation", np.zeros((0, 6))), float)
    if inn.ndim != 2 or not t.size:
        return (math.nan, math.nan)
    ap_all = (np.asarray(sol.gnss_status) == RecordStatus.APPLIED) & (t >= t_from) & (t < t_to)
    seqs = ([], [])
    inputs = getattr(sol, "inputs", None)
    for a, b in ([(-np.inf, np.inf)] if intervals is None else intervals):
        ap = ap_all & (t >= a) & (t < b)
        if inputs is not None and inn.shape == (len(inputs.prn), 2):  # tight: rows per satellite
            start = np.asarray(inputs.epoch_start)
            epoch = np.repeat(np.arange(len(start) - 1), np.diff(start))
            ep_t = np.asarray(inputs.epoch_t, float)
            # epochs of the applied records (gnss_t: one record per epoch)
            ok_t = set(np.round(t[ap], 6))
            keep = np.array([round(float(x), 6) in ok_t for x in ep_t])[epoch]
            prn = np.asarray(inputs.prn)
            for p in np.unique(prn):
                m = keep & (prn == p)
                for c in (0, 1):
                    seqs[c].append(inn[m, c])
        elif inn.shape[0] == t.size and inn.shape[1] >= 6:
            for c in range(6):
                seqs[c // 3].append(inn[ap, c])
    out = []
    for group in seqs:
        num = den = 0.0
        for y in group:
            y = y[np.isfinite(y)]
            if y.size < 3:
                continue
            d = y - y.mean()
            var = float(d @ d)
            if var <= 0.0:
                continue
            num += (y.size - 1) * float(d[:-1] @ d[1:]) / var
            den += y.size - 1
        out.append(num / den if den else math.nan)
    return (out[0], out[1])


@dataclass
class ReferenceModel:
    """What a reference trajectory describes, and how well (:func:`reference_errors`).

    Attributes
    ----------
    lever_arm_b : (3,) [m]
        IMU centre -> the point the reference describes, body FRD (zeros: the
        IMU centre; a GNSS solution: the antenna, ``lever_arm_b`` of the run).
    t : (M,) [s] or None
        Times of the sigma arrays below (the solution's time base); None: they
        are constant (shape (3,)).
    sigma_pos_n_m : (M, 3) or (3,) [m]
        1-sigma of the reference's own position error, N, E, D (e.g. an RTKLIB
        ``.pos`` file's ``sdn sde sdu`` columns); zeros: an exact reference.
    sigma_vel_n_mps : (M, 3) or (3,) [m/s]
        The same for its velocity (``.pos``: ``sdvn sdve sdvu``).
    velocity_lag_s : float [s]
        The reference's velocity at time t describes the point at t - lag (a
        receiver's smoothed velocity, ``[gnss] velocity_lag_s``): its velocity
        column is read ``lag`` later.
    omega_t : (K,) [s] and omega_ib_b_radps : (K, 3) [rad/s], or None
        Angular rate (body FRD) for the lever arm's velocity term
        ``C_nb (omega_ib_b x l_b)``; None: left out.
    source : str
        Where the sigmas come from (for the reports).
    """

    lever_arm_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    t: np.ndarray | None = None
    sigma_pos_n_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sigma_vel_n_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity_lag_s: float = 0.0
    omega_t: np.ndarray | None = None
    omega_ib_b_radps: np.ndarray | None = None
    source: str = ""

    @staticmethod
    def omega_from_imu(imu) -> tuple[np.ndarray, np.ndarray]:
        """(t, omega_ib_b) [s, rad/s] from an :class:`~insnav.data.dataset.ImuData`'s
        angle increments (each over its interval, taken at the interval's middle)."""
        t = np.asarray(imu.t, float)
        dt = np.diff(t, prepend=t[0] - np.median(np.diff(t)))
        return t - 0.5 * dt, np.asarray(imu.dtheta_b, float) / dt[:, None]

    def _at(self, x, t) -> np.ndarray:
        x = np.asarray(x, float)
        if self.t is None or x.ndim == 1:
            return np.broadcast_to(x, (len(t), 3)).copy()
        return np.column_stack([np.interp(t, np.asarray(self.t, float), x[:, i]) for i in range(3)])


def pos_reference_model(pos, ds, velocity_lag_s: float = 0.0) -> ReferenceModel:
    """An RTKLIB ``.pos`` as a reference of the antenna of ``ds`` (lever arm ``ds.lever_arm_b``): its own
    sigmas from its sdn/sde/sdu and sdvn/sdve/sdvu columns at each epoch, its velocity column lagging by
    ``velocity_lag_s`` [s], the angular rate of the lever arm's velocity term from the IMU's angle
    increments (times in the dataset's time base: GPS time minus ``ds.gps_time_offset_s``)."""
    from ..io.gnss_files import read_pos_records

    rec = read_pos_records(pos)
    t = rec.t_ref_s + np.asarray(rec.t_s, float) - float(ds.gps_time_offset_s)
    w_t, w_b = ReferenceModel.omega_from_imu(ds.imu)
    return ReferenceModel(lever_arm_b=np.asarray(ds.lever_arm_b, float), t=t,
                          sigma_pos_n_m=np.asarray(rec.sigma_pos_n, float),
                          sigma_vel_n_mps=np.asarray(rec.sigma_vel_n, float), velocity_lag_s=float(velocity_lag_s),
                          omega_t=w_t, omega_ib_b_radps=w_b,
                          source="the `.pos` file's own sdn, sde, sdu and sdvn, sdve, sdvu columns at each epoch")


def unseen_reference_epochs(reference, gnss_t) -> np.ndarray | None:
    """The reference epochs [s] that are not GNSS fix times of the run (1 ms), or None when no epoch is
    (a reference independent of the fixes): a reference made of the same solution as the fixes, e.g. the
    ``.pos`` the loose filter reads with ``[gnss] decimate``, is checked at the epochs the filter did not see."""
    t_ref = np.round(np.asarray(reference.t, float), 3)
    seen = np.isin(t_ref, np.round(np.asarray(gnss_t, float), 3))
    return np.setdiff1d(t_ref, t_ref[seen]) if seen.any() else None


def reference_errors(sol, reference, model: ReferenceModel | None = None, t=None) -> dict:
    """Errors of a solution against a reference that describes another point
    and has its own noise, and the variance a consistent filter predicts for them.

    ``sol``: a solution (``t``, ``lat_deg``, ..., ``sigma_pos_n_m``,
    ``sigma_vel_n_mps``, interpolated linearly in time); ``reference``: a
    Truth-like trajectory; ``model``: :class:`ReferenceModel`; ``t``: the
    reference epochs to use [s] (default all; those outside the solution's
    span are dropped).

    With the reference ``r = x_a + w`` (``x_a``: the true position of the point
    it describes, ``x_a = x + C_nb l_b``; ``w``: its own error, of variance
    ``sigma_ref^2``, independent of the filter's), the solution's point
    ``x_hat_a = x_hat + C_nb_hat l_b`` has the error
    ``e = x_hat_a - r = (x_hat - x) - w`` (the attitude error's share
    ``d(C_nb) l_b = -(C_nb l_b) x psi`` left out: at most ``|l_b|`` times the
    attitude sigma, returned as ``lever_sigma_max_m``), so for a consistent
    filter ``E[e^2] = sigma_filter^2 + sigma_ref^2`` per axis and
    ``E[(e / sqrt(sigma_filter^2 + sigma_ref^2))^2] = 1``.  The velocity
    likewise: the solution's ``v_hat + C_nb_hat (omega_ib_b x l_b)`` at
    ``t - velocity_lag_s`` against the reference's velocity column at its epoch
    ``t`` (the solution is moved, not the reference: interpolating the
    reference between its epochs would average its noise and change
    ``sigma_ref``).

    Returns a dict: ``t``; ``pos_n_m``, ``vel_n_mps`` (N, 3) the errors of the
    solution's point (velocity NaN where ``t - velocity_lag_s`` is before the
    solution); ``sigma_filter_pos``, ``sigma_filter_vel``, ``sigma_ref_pos``,
    ``sigma_ref_vel`` (N, 3); ``lever_sigma_max_m``.
    """
    from ..analysis.evaluate import _solution_at
    from ..analysis.metrics import errors
    from ..sim.trajectory import rotate_b_to_n

    model = model or ReferenceModel()
    tr = np.asarray(reference.t, float)
    t = tr if t is None else np.asarray(t, float)
    t = t[(t >= sol.t[0]) & (t <= sol.t[-1]) & (t >= tr[0]) & (t <= tr[-1])]
    at = _solution_at(sol, t)
    e = errors(at, reference)
    n = len(t)
    l_b = np.asarray(model.lever_arm_b, float).reshape(3)

    def euler(a):
        return np.radians(np.column_stack([a.roll_deg, a.pitch_deg, a.yaw_deg]))

    l_n = rotate_b_to_n(euler(at), np.tile(l_b, (n, 1)))
    # velocity: the solution at t - lag against the reference's column at t
    lag = float(model.velocity_lag_s)
    tv = t - lag
    okv = tv >= sol.t[0]
    vel = np.full((n, 3), np.nan)
    sig_fv = np.full((n, 3), np.nan)
    if okv.any():
        atv = _solution_at(sol, tv[okv])
        v_ant = np.asarray(atv.v_n, float)
        if model.omega_t is not None and np.any(l_b != 0.0):
            w_b = np.column_stack([np.interp(tv[okv], model.omega_t, model.omega_ib_b_radps[:, i])
                                   for i in range(3)])
            v_ant = v_ant + rotate_b_to_n(euler(atv), np.cross(w_b, l_b))
        v_ref = np.column_stack([np.interp(t[okv], tr, np.asarray(reference.v_n, float)[:, i]) for i in range(3)])
        vel[okv] = v_ant - v_ref
        sig_fv[okv] = np.asarray(atv.sigma_vel_n_mps, float)
    sig_att = np.asarray(getattr(at, "sigma_att_deg", np.zeros((n, 3))), float)
    return dict(
        t=t, pos_n_m=e["pos_n_m"] + l_n, vel_n_mps=vel,
        sigma_filter_pos=np.asarray(e["sigma_pos_n_m"], float), sigma_filter_vel=sig_fv,
        sigma_ref_pos=model._at(model.sigma_pos_n_m, t), sigma_ref_vel=model._at(model.sigma_vel_n_mps, t),
        lever_sigma_max_m=float(np.linalg.norm(l_b) * np.max(np.radians(sig_att), initial=0.0)))


def _rms_ratio(x, s) -> list:
    ok = np.all(np.isfinite(x), axis=1) & np.all(s > 0, axis=1)
    return np.sqrt(np.mean((x[ok] / s[ok]) ** 2, axis=0)).tolist() if ok.sum() >= 2 else [math.nan] * 3


def holdout_report(sol, reference=None, t_from: float = -np.inf, t_to: float = np.inf, keep_t=None,
                   reference_model: ReferenceModel | None = None, intervals=None) -> dict:
    """Consistency and error figures of ``sol`` over [t_from, t_to).

    Returns a dict: ``records`` and ``nis_per_row`` (mean NIS over the mean
    rows of the applied GNSS records: 1 for a consistent filter),
    ``log_likelihood_per_record``, ``innovation_lag1`` (:func:`innovation_lag1`:
    0 for white innovations); with a ``reference`` (a Truth-like
    trajectory of the IMU centre in the solution's time base), ``epochs``,
    ``hor_rms_m``, ``rms_3d_m`` and ``nees`` = rms(error/sigma) per axis of
    ``pos_n_m`` (N, E, D), ``vel_n_mps``, ``att_deg`` (roll, pitch, yaw),
    where the reference has them, and ``nees_demeaned`` the same with each
    axis's mean error over the epochs removed first (the time-varying part:
    a constant offset of the reference, or a constant error the innovations
    cannot see, left out).  ``keep_t``: only the reference epochs in this set
    of times (e.g. the epochs whose fixes the filter did not see).
    ``intervals``: [(a, b), ...] [s], only the records and epochs inside one
    of them as well (the held-out blocks of ``tune(split="blocks")``,
    :attr:`TuneResult.heldout`); the innovation lag-1 pools the intervals'
    sequences (no pair across a gap).

    ``nees_total``: rms(e / sqrt(sigma_filter^2 + sigma_ref^2)) per axis of
    ``pos_n_m`` and ``vel_n_mps``, with e the error of the solution's point
    that the reference describes (:func:`reference_errors` with
    ``reference_model``: lever arm, the reference's velocity lag and its own
    sigmas): 1 for a consistent filter whatever the reference's noise, where
    ``nees`` (IMU centre, the filter's sigma alone) is
    ``sqrt(1 + (b^2 + sigma_ref^2) / sigma^2)``.  Without a ``reference_model``
    (an exact reference of the IMU centre) the two are equal.
    ``reference_sigma_pos_m``, ``reference_sigma_vel_mps``: rms of the
    reference's sigmas per axis over the epochs; ``reference_variance_share_pos``:
    the mean of sigma_ref^2 / (sigma_filter^2 + sigma_ref^2) per position axis
    (near 1: the figure tests the reference more than the filter);
    ``lever_sigma_max_m``: the neglected attitude share (:func:`reference_errors`).
    """
    from ..analysis.metrics import errors
    from ..filters.solution import RecordStatus

    out = {}
    t = np.asarray(sol.gnss_t, float)
    ap = (np.asarray(sol.gnss_status) == RecordStatus.APPLIED) & (t >= t_from) & (t < t_to)
    if intervals is not None:
        ap &= in_intervals(t, intervals)
    rows = _gnss_rows(sol)[ap]
    nis = np.asarray(sol.nis, float)[ap]
    out["records"] = int(ap.sum())
    out["nis_per_row"] = float(np.sum(nis) / np.sum(rows)) if rows.size and np.sum(rows) > 0 else math.nan
    ll, n = solution_log_likelihood(sol, t_from, t_to, intervals=intervals)
    out["log_likelihood_per_record"] = ll / n if n else math.nan
    out["innovation_lag1"] = innovation_lag1(sol, t_from, t_to, intervals=intervals)
    if reference is None:
        return out
    tr = np.asarray(reference.t, float)
    m = (tr >= max(t_from, sol.t[0])) & (tr < min(t_to, sol.t[-1]))
    if intervals is not None:
        m &= in_intervals(tr, intervals)
    if keep_t is not None:
        m &= np.isin(np.round(tr, 3), np.round(np.asarray(keep_t, float), 3))
    from ..analysis.evaluate import _solution_at

    at = _solution_at(sol, tr[m])
    e = errors(at, reference)
    out["epochs"] = int(len(e["t"]))
    if not len(e["t"]):
        return out
    hz = np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])
    out["hor_rms_m"] = float(np.sqrt(np.mean(hz ** 2)))
    out["rms_3d_m"] = float(np.sqrt(np.mean(np.sum(e["pos_n_m"] ** 2, axis=1))))
    out["nees"], out["nees_demeaned"] = {}, {}
    for k in ("pos_n_m", "vel_n_mps", "att_deg"):
        x, s = e[k], e.get("sigma_" + k)
        if s is None:
            continue
        ok = np.all(np.isfinite(x), axis=1) & np.all(s > 0, axis=1)
        if ok.sum() < 2:
            continue
        out["nees"][k] = np.sqrt(np.mean((x[ok] / s[ok]) ** 2, axis=0)).tolist()
        out["nees_demeaned"][k] = np.sqrt(np.mean(((x[ok] - x[ok].mean(axis=0)) / s[ok]) ** 2, axis=0)).tolist()
    r = reference_errors(sol, reference, reference_model, tr[m])
    out["nees_total"] = {}
    for k, kind in (("pos_n_m", "pos"), ("vel_n_mps", "vel")):
        if k not in out["nees"]:
            continue
        total = np.sqrt(r["sigma_filter_" + kind] ** 2 + r["sigma_ref_" + kind] ** 2)
        out["nees_total"][k] = _rms_ratio(r[k], total)
    out["reference_sigma_pos_m"] = np.sqrt(np.mean(r["sigma_ref_pos"] ** 2, axis=0)).tolist()
    sv = r["sigma_ref_vel"]
    fin = np.isfinite(sv)
    out["reference_sigma_vel_mps"] = [float(np.sqrt(np.mean(sv[fin[:, i], i] ** 2))) if fin[:, i].any() else math.nan
                                      for i in range(3)]
    out["lever_sigma_max_m"] = r["lever_sigma_max_m"]
    sp2 = r["sigma_ref_pos"] ** 2
    out["reference_variance_share_pos"] = np.mean(sp2 / (r["sigma_filter_pos"] ** 2 + sp2), axis=0).tolist()
    return out


def _user_noise(noise: ImuNoise) -> dict:
    """The ``[imu]`` noise keys in user units (every one, so a loader need not fill in any)."""
    from ..config import _USER_UNITS

    d = {}
    for key, (fld, factor) in _USER_UNITS.items():
        if key == "acc_vrw_ug_per_sqrt_hz":
            continue
        d[key] = [float(v) / factor for v in getattr(noise, fld)]
    return d


def tuned_toml_dict(base: dict | None, result: TuneResult) -> dict:
    """The base TOML (as a dict; its other keys and tables kept) with the
    tuned settings written in: every ``[imu]`` noise key, the GNSS sigma
    scales (loose: the vertical one too, and the motion-dependent terms where
    they are on), ``filter`` and ``coupling``, and the constraint sigmas that were
    tuned, and for tight coupling the ``[robust]`` keys it was tuned with
    (screening, fault exclusion and CUSUM off).  ``insnav run --config``
    (``--run-config`` with ``--format kfgins``) then runs with it.  ``[time]
    estimate_offset = "auto"`` is written as the value the tuning settled it to
    (``result.time_offset_test``), so the file runs the tuned model."""
    from ..config import _USER_UNITS

    d = {k: (dict(v) if isinstance(v, dict) else v) for k, v in (base or {}).items()}
    cfg = result.tuned
    d["filter"], d["coupling"] = cfg.filter, cfg.coupling
    d["gnss_pos_sigma_scale"] = float(cfg.gnss_pos_sigma_scale)
    d["gnss_vel_sigma_scale"] = float(cfg.gnss_vel_sigma_scale)
    if cfg.coupling == "loose":
        d["gnss_pos_v_sigma_scale"] = float(cfg.gnss_pos_v_sigma_scale)
        for key in ("gnss_pos_sigma_per_speed_s", "gnss_vel_sigma_per_speed"):
            if getattr(cfg, key) > 0 or key in d:
                d[key] = float(getattr(cfg, key))
    if cfg.pr_gm_sigma_m > 0:  # the Gauss-Markov pseudorange states (tuned or as given)
        d["pr_gm_sigma_m"], d["pr_gm_tau_s"] = float(cfg.pr_gm_sigma_m), float(cfg.pr_gm_tau_s)
        d["pr_gm_max_gap_s"] = float(cfg.pr_gm_max_gap_s)
    if result.time_offset_test is not None:
        d["time"] = {**d.get("time", {}), "estimate_offset": bool(cfg.time.estimate_offset)}
    imu = {k: v for k, v in d.get("imu", {}).items() if k not in _USER_UNITS}
    imu.update(_user_noise(cfg.imu))
    d["imu"] = imu
    if cfg.coupling == "tight":  # as tuned (_plain_robust)
        rob = dict(d.get("robust", {}))
        rob.update(screening=False, fde_max_sats=0, cusum_h=0.0)
        d["robust"] = rob
    tuned_constraints = [p for p in ("nhc", "odo", "zupt", "standstill_q") if p in result.names]
    if tuned_constraints or cfg.constraints.use or cfg.constraints.standstill_q_scale != 1.0:
        con = dict(d.get("constraints", {}))
        con["use"] = list(cfg.constraints.use)
        if "nhc" in result.names:
            con["sigma_nhc_mps"] = float(cfg.constraints.sigma_nhc_mps)
        if "odo" in result.names:
            con["sigma_odo_mps"] = float(cfg.constraints.sigma_odo_mps)
        if "zupt" in result.names:
            con["sigma_zupt_mps"] = float(cfg.constraints.sigma_zupt_mps)
            con["sigma_zaru_dph"] = float(cfg.constraints.sigma_zaru_dph)
        if cfg.constraints.standstill_q_scale != 1.0:
            con["standstill_q_scale"] = float(cfg.constraints.standstill_q_scale)
        d["constraints"] = con
    return d
