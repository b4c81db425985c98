"""GNSS fault injection and detection scoring.

Each ``inject_*`` function returns a *new* dataset (the input is not
modified) and the ground-truth list of the faulty records, one dict each::

    {"kind": "position_jump", "index": i, "t": t_valid, "magnitude": 37.2, "unit": "m"}

``index`` is the record's row in ``ds.gnss`` (loose) or its epoch index in
``np.unique(ds.gnss_raw.t)`` (tight, the ``gnss_t`` of a tight solution).
:func:`score` compares them with a solution's ``gnss_status`` (2 = rejected by
the NIS gate) and counts detections, misses and false alarms.

Fault models
------------
position jump
    A displacement of the reported antenna position of one record (or
    ``duration`` consecutive records) in a uniformly random 3-D direction, its
    length uniform in ``magnitude_m`` (default 10-100 m).
velocity spike
    A velocity error of one record, random direction, length uniform in
    ``magnitude_mps`` (default 1-10 m/s).
pseudorange ramp
    One satellite's pseudorange grows by ``rate_mps`` per second from
    ``t_start`` over ``duration_s`` (a slowly drifting multipath or satellite
    clock fault); the pseudorange rate is left untouched, as a receiver's
    Doppler would be.
"""
from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ..earth import radii
from ..units import DEG

__all__ = ["inject_position_jumps", "inject_velocity_spikes", "inject_pseudorange_ramp", "score",
           "CHI2_999"]

#: 0.999 quantiles of the chi-square distribution by degrees of freedom (the NIS
#: gate thresholds: 6 = loose position + velocity, 3 = position only).
CHI2_999 = {1: 10.83, 2: 13.82, 3: 16.27, 4: 18.47, 5: 20.52, 6: 22.46, 7: 24.32, 8: 26.12, 9: 27.88,
            10: 29.59, 12: 32.91, 14: 36.12, 16: 39.25, 18: 42.31, 20: 45.31, 24: 51.18, 32: 62.49}


def _pick(n_records: int, n: int, t, t_min: float, rng, spacing: int) -> np.ndarray:
    """n distinct record indices with t >= t_min, at least ``spacing`` records apart."""
    cand = np.flatnonzero(np.asarray(t) >= t_min)
    if cand.size == 0:
        raise ValueError(f"no GNSS record after t_min={t_min}")
    cand = cand[:: max(1, spacing)]
    n = min(n, cand.size)
    return np.sort(rng.choice(cand, size=n, replace=False))


def _unit_vectors(rng, n):
    u = rng.standard_normal((n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _copy_gnss(ds):
    g = copy.deepcopy(ds.gnss)
    return dataclasses.replace(ds, gnss=g), g


def inject_position_jumps(ds, n: int = 20, magnitude_m=(10.0, 100.0), *, duration: int = 1, t_min=None,
                          spacing: int = 20, seed: int = 0):
    """Add ``n`` position jumps to the loose GNSS fixes.

    Parameters
    ----------
    ds : insnav.Dataset
    n : int
        Number of faults (fewer if the data are short).
    magnitude_m : (low, high)
        Jump length, uniform [m].
    duration : int
        Consecutive records affected by each jump.
    t_min : float, optional
        Earliest fault time [s] (default: 10 % into the GNSS data, after convergence).
    spacing : int
        Minimum number of records between two faults.
    seed : int

    Returns
    -------
    (Dataset, list of dict)
    """
    rng = np.random.default_rng(seed)
    out, g = _copy_gnss(ds)
    t = g.t_valid
    if t_min is None:
        t_min = t[0] + 0.1 * (t[-1] - t[0])
    idx = _pick(len(t), n, t, t_min, rng, max(spacing, duration + 1))
    mag = rng.uniform(*magnitude_m, size=len(idx))
    d_n = _unit_vectors(rng, len(idx)) * mag[:, None]  # N, E, D [m]
    faults = []
    for i, dn in zip(idx, d_n):
        for j in range(i, min(i + duration, len(t))):
            R_M, R_N = radii(g.lat_deg[j] * DEG)
            g.lat_deg[j] += dn[0] / (R_M + g.h_m[j]) / DEG
            g.lon_deg[j] += dn[1] / ((R_N + g.h_m[j]) * np.cos(g.lat_deg[j] * DEG)) / DEG
            g.h_m[j] -= dn[2]
            faults.append(dict(kind="position_jump", index=int(j), t=float(t[j]),
                               magnitude=float(np.linalg.norm(dn)), unit="m"))
    return out, faults


def inject_velocity_spikes(ds, n: int = 20, magnitude_mps=(1.0, 10.0), *, t_min=None, spacing: int = 20,
                           seed: int = 0):
    """Add ``n`` single-record velocity spikes to the loose GNSS fixes (see
    :func:`inject_position_jumps` for the parameters).  Records without
    velocity are not chosen."""
    rng = np.random.default_rng(seed)
    out, g = _copy_gnss(ds)
    t = g.t_valid
    if t_min is None:
        t_min = t[0] + 0.1 * (t[-1] - t[0])
    has_vel = np.isfinite(g.v_n).all(axis=1)
    tt = np.where(has_vel, t, -np.inf)
    idx = _pick(len(t), n, tt, t_min, rng, spacing)
    mag = rng.uniform(*magnitude_mps, size=len(idx))
    dv = _unit_vectors(rng, len(idx)) * mag[:, None]
    g.v_n[idx] += dv
    faults = [dict(kind="velocity_spike", index=int(i), t=float(t[i]), magnitude=float(m), unit="m/s")
              for i, m in zip(idx, mag)]
    return out, faults


def inject_pseudorange_ramp(ds, *, prn: int | None = None, t_start: float | None = None,
                            duration_s: float = 120.0, rate_mps: float = 1.0, seed: int = 0):
    """Add a pseudorange ramp to one satellite of ``ds.gnss_raw``.

    Parameters
    ----------
    prn : int, optional
        The satellite (default: the one seen in the most epochs).
    t_start : float, optional
        Start of the ramp [s] (default: centred in the longest stretch of
        epochs, without outage, in which the satellite is seen).
    duration_s : float
        Length of the ramp [s]; after it the error disappears.
    rate_mps : float
        Growth of the pseudorange error [m/s].

    Returns
    -------
    (Dataset, list of dict)
        One fault per epoch in which the satellite is affected, ``index`` = the
        epoch index, ``magnitude`` = the pseudorange error at that epoch [m].
    """
    if ds.gnss_raw is None:
        raise ValueError("inject_pseudorange_ramp: the dataset has no gnss_raw")
    raw = copy.deepcopy(ds.gnss_raw)
    out = dataclasses.replace(ds, gnss_raw=raw)
    epochs = np.unique(raw.t)
    if prn is None:
        prns, counts = np.unique(raw.prn, return_counts=True)
        prn = int(prns[np.argmax(counts)])
    if t_start is None:  # centre the ramp in the longest stretch of epochs that see the satellite
        seen = np.isin(epochs, raw.t[raw.prn == prn])
        if not seen.any():
            raise ValueError(f"inject_pseudorange_ramp: PRN {prn} is not in gnss_raw")
        dt = float(np.median(np.diff(epochs))) if len(epochs) > 1 else 1.0
        # runs of consecutive seen epochs without a time gap (outage)
        brk = np.flatnonzero(~seen[1:] | ~seen[:-1] | (np.diff(epochs) > 1.5 * dt)) + 1
        best, best_len = 0, 0.0
        for a, b in zip(np.r_[0, brk], np.r_[brk, len(epochs)]):
            if seen[a] and epochs[b - 1] - epochs[a] > best_len:
                best, best_len = a, epochs[b - 1] - epochs[a]
        t_start = float(epochs[best] + max(0.0, (best_len - duration_s) / 2.0))
    sel = (raw.prn == prn) & (raw.t >= t_start) & (raw.t <= t_start + duration_s)
    err = rate_mps * (raw.t[sel] - t_start)
    raw.pseudorange_m[sel] += err
    ep_idx = np.searchsorted(epochs, raw.t[sel])
    faults = [dict(kind="pseudorange_ramp", index=int(e), t=float(tt), magnitude=float(m), unit="m", prn=int(prn))
              for e, tt, m in zip(ep_idx, raw.t[sel], err)]
    return out, faults


def score(sol, faults, *, min_magnitude: float = 0.0, settle_records: int = 0) -> dict:
    """Detection statistics of a solution against the injected faults.

    A fault is *detected* when its record's status is 2 (rejected by the
    gate) and *missed* when it was applied (1); records the filter never
    used (outage, before the start) are left out.  A *false alarm* is a
    rejected record that holds no fault.  Faults smaller than
    ``min_magnitude`` are ignored (neither detection nor miss; rejecting
    them is not a false alarm either).  ``settle_records`` clean records
    after each fault are excluded from the false-alarm count (the filter
    may still be pulled by a missed fault).

    Returns
    -------
    dict
        ``injected``, ``detected``, ``missed``, ``false_alarms``,
        ``clean_records`` (used records without a fault),
        ``detection_rate``, ``false_alarm_rate``.
    """
    st = np.asarray(sol.gnss_status)
    gt = np.asarray(sol.gnss_t)
    faulty = np.zeros(len(st), bool)
    counted = np.zeros(len(st), bool)
    excluded = np.zeros(len(st), bool)
    for f in faults:
        # map by time (the solution's records may be a sorted/sanitized copy)
        j = int(np.searchsorted(gt, f["t"]))
        if j >= len(gt) or abs(gt[j] - f["t"]) > 1e-6:
            continue
        faulty[j] = True
        if f["magnitude"] >= min_magnitude:
            counted[j] = True
        excluded[j + 1: j + 1 + settle_records] = True
    used = (st == 1) | (st == 2)
    det = int((counted & used & (st == 2)).sum())
    miss = int((counted & used & (st == 1)).sum())
    clean = used & ~faulty & ~excluded
    fa = int((clean & (st == 2)).sum())
    inj = det + miss
    return dict(injected=inj, detected=det, missed=miss, false_alarms=fa, clean_records=int(clean.sum()),
                detection_rate=det / inj if inj else float("nan"),
                false_alarm_rate=fa / clean.sum() if clean.sum() else float("nan"))
