"""Delayed GNSS records (seed 001): three ways to use late fixes.

Each GNSS record has a time of validity ``t_valid`` and an arrival time
``t_arrival`` (``Dataset.gnss``; the simulator delays fixes by whole epochs
with the scenario's ``gnss.delay_p``).  :func:`run_delayed` runs one of

``"kf"``
    The ordinary closed-loop EKF fed the records in arrival order, each
    applied as if it were valid when it arrives (the naive use; seed 001's
    "KF" column).
``"rdkf"``
    Seed 001's random-delay Kalman filter (Pan, Zhao, Li 2022, eqs. (4)-(21)):
    it does not know ``t_valid``; it keeps the error state of the last
    ``s + 1`` GNSS epochs and weights the possible delays with the known
    probabilities ``p`` (``cpp/include/insnav/filter/random_delay_kf.hpp``).
``"exact"``
    Exact processing with the time tag: checkpoints of the whole engine
    state every ``checkpoint_interval_s`` in a fixed ring; a late record
    restores the checkpoint before its ``t_valid`` and the IMU data since are
    re-processed with every record received so far at its own time
    (``cpp/include/insnav/engine/delay_engine.hpp``).  Records older than
    the history (``max_history_s``, bounded by the ring) are refused, counted
    in ``summary["refused_too_old"]`` and reported with a ``RuntimeWarning``.

All three return a real-time :class:`insnav.Solution`: the output at time t
uses only the records that arrived by t.

The records are the *arrival stream* (seed 001 eq. (4)): a fix that arrives at
two epochs is two records with the same ``t_valid`` and different
``t_arrival`` (``insnav.run`` keeps both; see
:func:`insnav.filters.sanitize.sanitize_gnss`).  The stack of the random-delay
KF shifts at every epoch of the receiver's epoch grid
(:func:`receiver_epochs`), also at an epoch where nothing arrives, so that
block ``i`` always means "``i`` epochs ago".
"""
from __future__ import annotations

import dataclasses
import warnings
from types import SimpleNamespace

import numpy as np

from .. import _core
from .._validate import check_finite
from ..config import ConfigError, ImuNoise, RunConfig
from ..registry import filter_names
from ..units import DEG
from ._setup import (engine_config, imu_arrays, init_vector, initial_imu_correction, initial_state,
                     loose_initial_sigmas, raise_if_nonfinite)
from ._assemble import nav_solution
from .loose import loose_gnss_rows
from .solution import GNSS_STATUS, Solution

DELAY_FILTERS = tuple(n for n in filter_names("loose") if n in ("kf", "rdkf", "exact"))
#: status codes of :attr:`Solution.gnss_status` for the delay filters (all of them)
DELAY_GNSS_STATUS = GNSS_STATUS
MAX_DELAY_EPOCHS = 4  # RandomDelayKf<Layout15, S> is instantiated for S = 1..4


def scenario_delay_p(dataset) -> np.ndarray:
    """The delay distribution ``p`` of the dataset's scenario (``[1.0]`` if none)."""
    p = _scenario_delay_p(dataset)
    return np.ones(1) if p is None else p


def _scenario_delay_p(dataset) -> np.ndarray | None:
    sc = getattr(dataset, "scenario", None) or {}
    p = (sc.get("gnss") or {}).get("delay_p")
    return None if p is None else np.asarray(p, dtype=float)


def arrival_delay_p(t_valid, t_arrival, epochs) -> np.ndarray:
    """``P(delay = i epochs)`` estimated from the records' own times: the
    fraction of records that arrive ``i`` receiver epochs (``epochs``, from
    :func:`receiver_epochs`, which holds every record time) after the epoch of
    their time of validity, i = 0..s with s the largest delay seen, at most
    ``MAX_DELAY_EPOCHS`` (a record later than that counts as s: the random-delay
    KF's longest modelled delay).  ``[1.0]`` without records: no delay."""
    tv, ta = np.asarray(t_valid, float), np.asarray(t_arrival, float)
    e = np.round(np.asarray(epochs, float), 9)
    if tv.size == 0 or e.size == 0:
        return np.ones(1)
    iv = np.searchsorted(e, np.round(tv, 9))
    ia = np.searchsorted(e, np.round(ta, 9))
    d = np.clip(ia - iv, 0, MAX_DELAY_EPOCHS)
    counts = np.bincount(d, minlength=1)[: d.max() + 1].astype(float)
    return counts / counts.sum()


def receiver_epochs(t_valid, t_arrival, period_s: float | None = None) -> np.ndarray:
    """The receiver's GNSS epoch grid [s], sorted.

    Every time of validity and arrival time of the records, plus the epochs of
    the grid at which no record is valid nor arrives: inside a gap longer than
    1.5 periods between consecutive record times, the missing epochs are
    inserted at the period's spacing.  The random-delay KF shifts its stack at
    each of them (seed 001 eqs. (5)-(7): one step of the stacked state per
    epoch, whether or not a measurement arrives).

    Parameters
    ----------
    t_valid, t_arrival : array_like
        Record times [s].
    period_s : float, optional
        GNSS epoch period [s]; default: the median spacing of the distinct
        record times (validity and arrival together).

    Returns
    -------
    ndarray
        Epoch times [s], rounded to 1e-9 s.
    """
    tv = np.asarray(t_valid, float)
    times = np.unique(np.round(np.concatenate([tv, np.asarray(t_arrival, float)]), 9))
    if times.size < 2:
        return times
    if period_s is None:
        period_s = float(np.median(np.diff(times)))
    if not period_s > 0:
        return times
    gaps = np.diff(times)
    fill = np.flatnonzero(gaps > 1.5 * period_s)
    extra = [times[i] + period_s * np.arange(1, int(round(gaps[i] / period_s)))
             for i in fill]
    if not extra:
        return times
    return np.unique(np.round(np.concatenate([times, *extra]), 9))


def _arrival_counts(rec: np.ndarray, epochs: np.ndarray, t_start: float, t_end: float) -> dict:
    """What the filter receives: per receiver epoch the number of records that
    arrive there, and per epoch the number of records valid there (how often
    that epoch's fix arrives), over the epochs inside the IMU span."""
    tol = 1e-6
    inside = (epochs > t_start + tol) & (epochs <= t_end + tol)
    got = (rec[:, 1] > t_start + tol) & (rec[:, 1] <= t_end + tol)
    e = np.round(epochs, 9)

    def per_epoch(times):
        i = np.clip(np.searchsorted(e, np.round(times, 9) - tol), 0, max(e.size - 1, 0))
        on = np.abs(e[i] - times) < tol if e.size else np.zeros(0, bool)
        return np.bincount(i[on], minlength=e.size)

    n_arr = per_epoch(rec[got, 1])[inside]
    # a fix valid at an epoch whose arrival could still fall inside the span
    last_valid = rec[got, 0].max() if got.any() else -np.inf
    valid_span = inside & (epochs <= last_valid + tol)
    n_fix = per_epoch(rec[got, 0])[valid_span]
    return dict(receiver_epochs=int(inside.sum()),
                epoch_arrivals=np.bincount(n_arr).tolist() if n_arr.size else [],
                fix_arrivals=np.bincount(n_fix).tolist() if n_fix.size else [])


def scenario_gnss_period_s(dataset) -> float | None:
    """The GNSS epoch period [s] of the dataset's scenario (``1 / gnss.rate_hz``), or
    None (then :func:`receiver_epochs` takes it from the record times)."""
    sc = getattr(dataset, "scenario", None) or {}
    rate = (sc.get("gnss") or {}).get("rate_hz")
    try:
        return 1.0 / float(rate) if rate and float(rate) > 0 else None
    except (TypeError, ValueError):
        return None


def run_delayed(dataset, filter: str = "rdkf", *, delay_p=None, config: RunConfig | None = None,
                max_history_s: float = 1.0, checkpoint_interval_s: float | None = None,
                sanitize: bool | dict = True, checks: bool = True, **overrides) -> Solution:
    """Closed-loop loose GNSS/INS run with delayed GNSS records.

    Parameters
    ----------
    dataset : insnav.Dataset
        Uses ``gnss.t_valid`` and ``gnss.t_arrival``.
    filter : {'kf', 'rdkf', 'exact'}
        See the module docstring.
    delay_p : sequence of float, optional
        ``P(delay = i epochs)``, i = 0..s, s <= 4 (rdkf only).  Default: the
        scenario's ``gnss.delay_p``; without one, the distribution of the
        records' own delays (:func:`arrival_delay_p`; ``summary["delay_p_source"]``).
    config : RunConfig, optional
        Initial state/sigmas, IMU noise, lever arm, gating, output rate (its
        ``filter``/``coupling`` fields are ignored: the EKF, loose).
    max_history_s : float
        exact: refuse records older than this [s].
    checkpoint_interval_s : float, optional
        exact: checkpoint spacing [s] (default: the median GNSS interval).
        History = min(max_history_s, 63 checkpoint_interval_s).
    sanitize, checks : bool
        As :func:`insnav.run`, which this calls (input repair and checks first).
    **overrides
        Any :class:`RunConfig` field.

    Returns
    -------
    Solution
        ``gnss_status`` etc. are in the dataset's record order;
        ``summary`` adds ``delay_p``, ``refused_too_old``, ``replays``,
        ``replayed_samples``, ``filter_updates``, ``history_s`` and (rdkf,
        exact) what the filter received: ``receiver_epochs`` (epochs of the
        grid inside the IMU span), ``epoch_arrivals[j]`` (epochs at which
        ``j`` records arrived) and ``fix_arrivals[j]`` (epochs whose fix
        arrived ``j`` times).
    """
    if filter not in DELAY_FILTERS:
        raise ValueError(f"run_delayed: filter {filter!r}; allowed: {', '.join(DELAY_FILTERS)}")
    from . import run

    return run(dataset, filter, "loose", config, sanitize=sanitize, checks=checks, delay_p=delay_p,
               max_history_s=max_history_s, checkpoint_interval_s=checkpoint_interval_s, **overrides)


def delay_engine_args(dataset, cfg: RunConfig, delay_p=None, imu=None) -> SimpleNamespace:
    """The compiled delay engine's arguments for ``dataset`` under ``cfg``, shared by
    :func:`run_delay` and the push API (:class:`insnav.DelayNavigator`): the records
    in arrival order (``rec`` (M, 14): t_valid, t_arrival, lat, lon [rad], h [m],
    v_n [m/s], position and velocity 1-sigma) and ``order`` (record index of each
    row), the receiver ``epochs`` [s], the initial state vector ``init``, ``P0``,
    the IMU correction and model, the engine ``config`` dict, the delay
    probabilities ``p`` (``delay_p``; else the scenario's ``gnss.delay_p``; else
    :func:`arrival_delay_p` of the records' own times), and ``summary`` (filter,
    layout, what the filter receives), ``p_source`` ("option", "scenario" or
    "arrival times")."""
    t = imu[0] if imu is not None else imu_arrays(dataset)[0]
    g = dataset.gnss
    m = len(g)
    if m:
        # the sigmas with insnav tune's factors, as the loose filters weight them (loose_gnss_rows: by time)
        sigmas = np.empty((m, 6))
        sigmas[np.argsort(np.asarray(g.t_valid, float), kind="stable")] = loose_gnss_rows(g, cfg)[:, 7:13]
        rec = np.column_stack([g.t_valid, g.t_arrival, g.lat_deg * DEG, g.lon_deg * DEG, g.h_m, g.v_n,
                               sigmas]).astype(float)
        check_finite(rec[:, [0, 1, 8, 9, 10]], "gnss (times/position sigma)")
        if np.any(rec[:, 1] < rec[:, 0] - 1e-9):
            raise ValueError("gnss: a record arrives before its time of validity (t_arrival < t_valid)")
        rec[:, 1] = np.maximum(rec[:, 1], rec[:, 0])
        # arrival order; ties keep the time-of-validity order
        order = np.lexsort((rec[:, 0], rec[:, 1]))
        rec = np.ascontiguousarray(rec[order])
    else:
        rec = np.zeros((0, 14))
        order = np.zeros(0, int)

    rng = np.random.default_rng(cfg.init_seed)
    init, sig0 = initial_state(dataset, cfg, rng)
    noise = cfg.imu or ImuNoise.from_dataset_model(dataset.imu_model)
    n = cfg.layout
    P0 = np.diag(loose_initial_sigmas(sig0, noise, n, cfg) ** 2)
    tv_unique = np.unique(g.t_valid) if m else np.zeros(0)
    period = float(np.median(np.diff(tv_unique))) if len(tv_unique) > 1 else 1.0
    core_cfg = engine_config(dataset, cfg, tv_unique, n, use_position=cfg.use_position,
                             use_velocity=cfg.use_velocity)
    summary = dict(filter=cfg.filter, coupling="loose", layout=n, gnss_records=m)
    epochs = receiver_epochs(rec[:, 0], rec[:, 1], scenario_gnss_period_s(dataset))
    summary.update(_arrival_counts(rec, epochs, float(dataset.t0), float(t[-1]) if t.size else float(dataset.t0)))
    if delay_p is not None:
        p, p_source = delay_probabilities(delay_p), "option"
    elif (p := _scenario_delay_p(dataset)) is not None:
        p_source = "scenario"
    else:  # measured, not assumed: p = [1] would model delayed records as on time
        p, p_source = arrival_delay_p(rec[:, 0], rec[:, 1], epochs), "arrival times"
    return SimpleNamespace(rec=rec, order=order, epochs=epochs, init=init_vector(dataset, init), P0=P0,
                           imu_correction=initial_imu_correction(cfg), imu_model=noise.as_core_dict(),
                           config=core_cfg, p=p, p_source=p_source, layout=n, period_s=period, summary=summary)


def delay_probabilities(delay_p) -> np.ndarray:
    """The option ``delay_p`` as an array: 1..5 probabilities p_0..p_s of a delay of
    0..s epochs, each in [0, 1], summing to 1 (seed 001 eq. (4)); else a one-line ConfigError."""
    try:
        p = np.asarray(delay_p, dtype=float)
    except (TypeError, ValueError):
        p = np.full(0, np.nan)
    if isinstance(delay_p, (str, bytes)) or p.ndim != 1 or not 1 <= p.size <= MAX_DELAY_EPOCHS + 1 \
            or not np.all((p >= 0.0) & (p <= 1.0)) or abs(float(p.sum()) - 1.0) > 1e-9:
        raise ConfigError(f"option 'delay_p' = {delay_p!r}: allowed: 1..{MAX_DELAY_EPOCHS + 1} probabilities "
                          "p_0..p_s of a delay of 0..s epochs, each in [0, 1], summing to 1 (seed 001 eq. (4))")
    return p


def check_rdkf(p: np.ndarray, layout: int) -> None:
    """The random-delay KF's instantiations: 1..5 probabilities, the 15-state layout."""
    if p.ndim != 1 or not 1 <= p.size <= MAX_DELAY_EPOCHS + 1:
        raise ValueError(f"delay_p: expected 1..{MAX_DELAY_EPOCHS + 1} probabilities, got {p!r}")
    if layout != 15:
        raise ValueError("rdkf: only the 15-state layout is available")


def run_delay(dataset, cfg: RunConfig, *, delay_p=None, max_history_s: float = 1.0,
              checkpoint_interval_s: float | None = None) -> Solution:
    """The registry's runner (``insnav.run(ds, "kf" | "rdkf" | "exact")``): ``cfg.filter``
    over the arrival stream; the options as :func:`run_delayed`'s."""
    filter = cfg.filter
    if filter not in DELAY_FILTERS:
        raise ValueError(f"run_delay: filter {filter!r}; allowed: {', '.join(DELAY_FILTERS)}")
    cfg = dataclasses.replace(cfg, coupling="loose")
    cfg.validate()

    t, dth, dv = imu_arrays(dataset)
    a = delay_engine_args(dataset, cfg, delay_p, (t, dth, dv))
    rec, order, epochs, n, core_cfg, summary = a.rec, a.order, a.epochs, a.layout, a.config, a.summary
    init_vec, P0, noise_d, p = a.init, a.P0, a.imu_model, a.p
    t_valid_sorted = rec[:, 0]
    if filter == "kf":
        gnss13 = np.ascontiguousarray(np.delete(rec, 0, axis=1))  # t := t_arrival
        out = _core.run_loose("ekf", n, t, dth, dv, gnss13, init_vec, P0, a.imu_correction, noise_d, core_cfg)
    else:
        if filter == "rdkf":
            check_rdkf(p, n)
            summary["delay_p"] = p.tolist()
            summary["delay_p_source"] = a.p_source
        else:
            if checkpoint_interval_s is not None and not (isinstance(checkpoint_interval_s, (int, float))
                                                          and 0.0 < checkpoint_interval_s < float("inf")):
                raise ConfigError(f"option 'checkpoint_interval_s' = {checkpoint_interval_s!r}: allowed: a number "
                                  "> 0 [s] (absent: the GNSS period)")
            core_cfg.update(max_history_s=float(max_history_s),
                            checkpoint_interval=float(checkpoint_interval_s or a.period_s))
        out = _core.run_delay(filter, n, t, dth, dv, rec, epochs, init_vec, P0, a.imu_correction, noise_d,
                              core_cfg, p if filter == "rdkf" else np.ones(1))
        for k in ("refused_too_old", "replays", "replayed_samples", "filter_updates", "history_s",
                  "max_delay_epochs"):
            if k in out:
                summary[k] = out[k]
    inv = np.empty_like(order)
    inv[order] = np.arange(len(order))
    summary.update(updates=int(out["updates"]), rejected=int(out["rejected"]), gate_reopened=int(out["gate_reopened"]), gate_outage_accepted=int(out["gate_outage_accepted"]),
                   cholesky_repairs=int(out["cholesky_repairs"]))
    sol, _ = nav_solution(out, gnss_t=t_valid_sorted[inv], innovation=out["innovation"][inv], nis=out["nis"][inv],
                          gnss_status=out["status"][inv], summary=summary)
    if summary.get("refused_too_old", 0):
        warnings.warn(f"exact: {summary['refused_too_old']} GNSS record(s) arrived more than the history "
                      f"({summary['history_s']:.3g} s) after their time of validity and were not used",
                      RuntimeWarning, stacklevel=2)
    raise_if_nonfinite(sol, filter)
    return sol

