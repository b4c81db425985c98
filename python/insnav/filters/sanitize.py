"""Input sanitation before a run: check the IMU and GNSS streams, repair what
can be repaired without inventing information, refuse the rest.

:func:`insnav.run` calls both functions (``sanitize=True``, the default) and
puts the merged report into ``Solution.summary["sanitize"]``.  On clean data
nothing is changed and every count is zero.

Policy
------
Every repair is counted in the report; every refusal is a ``ValueError`` whose
message names the sample and, when the data came from a reader
(``ImuData.origin`` / ``GnssFixes.origin``), the file and 1-based line.

IMU (:func:`sanitize_imu`), nominal interval ``dt0`` = median sample interval:

===================================  ==========================================
non-finite value                     refused
``|dtheta|/dt > max_rate_rps`` or    refused (a corrupted record: no sensor
``|dv|/dt > max_accel_mps2``         measures it)
time decreases                       refused (naming both lines)
repeated time, identical record      dropped (``imu_duplicates_dropped``)
repeated time, different record      refused (which one is right is unknown)
gap ``dt > gap_factor * dt0`` and    bridged (``imu_gaps_bridged``), see below
``dt <= max_gap_s``
gap ``dt > max_gap_s``               refused
===================================  ==========================================

A gap is bridged in one of two ways, chosen per gap from the sample after it.
An IMU that *accumulates* over a dropout delivers an increment covering the
whole gap; a logger that *lost* records delivers one covering only ``dt0``.
With the specific force magnitude of the neighbouring samples ``f_ref`` (it
is never far from g for a vehicle on or near the Earth) the sample's
``|dv|/dt`` and ``|dv|/dt0`` are compared with ``f_ref``; the closer one
(in ratio) decides:

* accumulated: the sample is kept as it is; the engine integrates it over the
  whole gap at a constant rate (``imu_gaps_accumulated``);
* lost: the missing interval is filled with samples at the nominal rate
  whose angular rate and specific force are interpolated linearly between
  the samples on either side (``imu_samples_inserted``).  The lost data are
  unknown; the filter's process noise over a gap of at most ``max_gap_s`` is
  what covers the interpolation error.

GNSS fixes (:func:`sanitize_gnss`): a fix is an independent observation, so
a bad one is dropped (it then acts like a short outage) rather than refused:

=====================================  ========================================
non-finite time, position or position  dropped (``gnss_invalid_dropped``)
sigma, sigma <= 0 or > MAX_SIGMA_M
(1e5 m: no information, and its
square overflows the filter),
latitude outside [-90, 90], longitude
outside [-180, 360], height outside
[``min_h_m``, ``max_h_m``]
non-finite or non-positive velocity    velocity removed, position kept
or velocity sigma (some, not all       (``gnss_velocity_removed``)
NaN), a speed over MAX_SPEED_MPS
(1e4 m/s) or a sigma over
MAX_SIGMA_MPS (1e5 m/s)
out of time order                      sorted (``gnss_reordered``)
repeated time of validity              first kept, rest dropped
                                       (``gnss_duplicates_dropped``)
repeated time of validity, different   kept for the delay filters
arrival time (``arrivals=True``)       (``gnss_repeat_arrivals_kept``)
=====================================  ========================================

The delay filters (seed 001: ``kf``, ``rdkf``, ``exact``) receive the
*arrival stream*: in the paper's model (seed 001 eq. (4)) the receiver gets
one measurement per epoch, ``y_k = z_(k - tau_k)``, so one fix can arrive at
two epochs (probability ``p_0 p_1`` for ``p = [p_0, p_1]``) and another at
none.  A second record with the same time of validity and a *different*
arrival time is then a legitimate second arrival, not a duplicate; only a
record that repeats both times is dropped (``arrivals=True``).  The on-time
filters use the time of validity only, for which such a record would count
the same fix twice.

A fix that is well formed but wrong (a jump, a spike) is the NIS gate's job
(``RunConfig.gate_chi2``), not this module's.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..data.dataset import GnssFixes, ImuData, RowOrigin, column
from ..config import SANITIZE_DEFAULTS
from .._imu_scan import scan_imu

__all__ = ["sanitize_imu", "sanitize_gnss", "sanitize_gnss_blocks", "DEFAULTS"]


#: Default limits.  ``max_rate_rps`` = 2000 deg/s and ``max_accel_mps2`` = 100 g are
#: beyond the full scale of automotive, aerial and tactical IMUs; ``max_gap_s``
#: is 0.1 s (20 samples at 200 Hz).
DEFAULTS = SANITIZE_DEFAULTS  # the run config's [sanitize] table overrides them (insnav.config)


def _where(origin: RowOrigin | None, source: str, i: int) -> str:
    if origin is not None:
        return f"{origin.where(i)} (sample {i})"
    return f"{source}: sample {i}"


def _imu_report() -> dict:
    return dict(imu_samples_in=0, imu_samples_out=0, imu_duplicates_dropped=0, imu_gaps_bridged=0,
                imu_gaps_accumulated=0, imu_samples_inserted=0, imu_max_gap_s=0.0)


def sanitize_imu(imu: ImuData, *, max_gap_s: float = DEFAULTS["max_gap_s"],
                 gap_factor: float = DEFAULTS["gap_factor"],
                 max_rate_rps: float = DEFAULTS["max_rate_rps"],
                 max_accel_mps2: float = DEFAULTS["max_accel_mps2"],
                 source: str = "imu", t0: float | None = None) -> tuple[ImuData, dict]:
    """Check and repair an IMU increment stream (policy in the module docstring).

    Parameters
    ----------
    imu : ImuData
    max_gap_s : float
        Longest gap [s] that is bridged; a longer one is refused.
    gap_factor : float
        An interval longer than ``gap_factor`` times the nominal one is a gap.
    max_rate_rps : float
        Largest plausible angular rate ``|dtheta|/dt`` [rad/s].
    max_accel_mps2 : float
        Largest plausible specific force ``|dv|/dt`` [m/s^2].
    source : str
        Name used in messages when ``imu.origin`` is not set.
    t0 : float, optional
        Start time of the first interval (the dataset's ``t0``) [s].

    Returns
    -------
    ImuData
        The input object itself when nothing was changed.
    dict
        Counts (see the module docstring) and ``imu_max_gap_s``.

    Raises
    ------
    ValueError
        Naming the sample (and file:line) and the reason.
    """
    rep = _imu_report()
    origin = imu.origin
    t = np.ascontiguousarray(imu.t, dtype=float).reshape(-1)
    dth = np.ascontiguousarray(imu.dtheta_b, dtype=float)
    dv = np.ascontiguousarray(imu.dv_b, dtype=float)
    n = len(t)
    if dth.shape != (n, 3) or dv.shape != (n, 3):
        raise ValueError(f"{source}: expected t (N,), dtheta_b (N, 3), dv_b (N, 3); got {t.shape}, "
                         f"{dth.shape}, {dv.shape}")
    rep["imu_samples_in"] = rep["imu_samples_out"] = n
    if n == 0:
        return imu, rep
    limits = dict(t0=t0, max_rate_rps=max_rate_rps, max_accel_mps2=max_accel_mps2, gap_factor=gap_factor)
    # one compiled pass: the first bad sample of each kind (insnav/_imu_scan.py)
    scan = scan_imu(t, dth, dv, **limits)
    for arr, name, key in ((t, "time", "nonfinite_t"), (dth, "dtheta_b", "nonfinite_dtheta"),
                           (dv, "dv_b", "nonfinite_dv")):
        i = scan[key]
        if i >= 0:
            raise ValueError(f"{_where(origin, source, i)}: non-finite {name}: {arr[i]!r}")
    i = scan["decrease"]
    if i >= 0:
        raise ValueError(f"{_where(origin, source, i)}: time {float(t[i])!r} decreases (previous sample "
                         f"{_where(origin, source, i - 1)} at {float(t[i - 1])!r})")
    if scan["repeats"]:
        d = np.diff(t)
        dup = np.flatnonzero(d == 0) + 1
        same = (dth[dup] == dth[dup - 1]).all(axis=1) & (dv[dup] == dv[dup - 1]).all(axis=1)
        if not same.all():
            i = int(dup[np.argmax(~same)])
            raise ValueError(f"{_where(origin, source, i)}: repeated time {float(t[i])!r} with a different record "
                             f"than {_where(origin, source, i - 1)} (which one is right is unknown)")
        keep = np.ones(n, bool)
        keep[dup] = False
        rep["imu_duplicates_dropped"] = int(dup.size)
        t, dth, dv = t[keep], dth[keep], dv[keep]
        if origin is not None:
            origin = origin.take(keep, n)
        n = len(t)
        scan = scan_imu(t, dth, dv, **limits)  # rates and gaps over the intervals without the repeats

    # the nominal interval dt0: the median interval, else the first one from t0 (scan_imu)
    dt0 = scan["dt0"]
    if dt0 > 0:
        def dt_of(i):  # the sample's own interval; the first one from t0 when given, else the nominal one
            return float(t[i] - t[i - 1]) if i > 0 else (float(t[0] - t0) if (t0 is not None and t[0] > t0) else dt0)

        # absurd values: rates over the sample's own interval, but never over more
        # than the nominal one (an accumulated gap sample is judged by its mean rate)
        for x, lim, what, unit, key in ((dth, max_rate_rps, "angular rate |dtheta|/dt", "rad/s", "rate"),
                                        (dv, max_accel_mps2, "specific force |dv|/dt", "m/s^2", "accel")):
            i = scan[key]
            if i >= 0:
                with np.errstate(over="ignore"):  # 1e308 components: the norm is inf, the message says so
                    val = float(np.linalg.norm(x[i]) / dt_of(i))
                raise ValueError(f"{_where(origin, source, i)}: {what} = {val:.6g} {unit} exceeds the "
                                 f"physical limit {lim:.6g} {unit} (corrupted record?)")
        if scan["gaps"]:
            dts = np.empty(n)
            dts[1:] = np.diff(t)
            dts[0] = dt_of(0)
            gaps = np.flatnonzero(dts[1:] > gap_factor * dt0) + 1
            rep["imu_max_gap_s"] = float(dts[gaps].max())
            too_long = dts[gaps] > max_gap_s
            if too_long.any():
                i = int(gaps[np.argmax(too_long)])
                raise ValueError(f"{_where(origin, source, i)}: IMU gap of {dts[i]:.6g} s after t={float(t[i - 1])!r} "
                                 f"is longer than max_gap_s={max_gap_s:g} s (nominal interval {dt0:.6g} s; a longer limit: "
                                 "[sanitize] max_gap_s in the run config)")
            t, dth, dv, origin, rep = _bridge(t, dth, dv, dts, gaps, dt0, origin, rep)
    rep["imu_samples_out"] = len(t)
    changed = rep["imu_duplicates_dropped"] or rep["imu_samples_inserted"]
    if not changed:
        return imu, rep
    return ImuData(t, dth, dv, origin=origin), rep


def _bridge(t, dth, dv, dts, gaps, dt0, origin, rep):
    """Bridge each gap (module docstring): keep accumulated samples, fill lost ones."""
    n = len(t)
    spec = np.sqrt(np.einsum("ij,ij->i", dv, dv)) / dts  # specific force magnitude [m/s^2]
    pieces_t, pieces_th, pieces_v, pieces_ln = [], [], [], []
    lines = origin.all_lines(n) if origin is not None else None
    start = 0
    for k in gaps:
        lo, hi = max(0, k - 5), min(n, k + 6)
        nb = [j for j in range(lo, hi) if j != k and not dts[j] > 1.5 * dt0]
        f_ref = float(np.median(spec[nb])) if nb else 0.0
        f_acc = np.linalg.norm(dv[k]) / dts[k]   # the sample covers the whole gap
        f_lost = np.linalg.norm(dv[k]) / dt0     # the sample covers dt0 only
        rep["imu_gaps_bridged"] += 1
        if f_ref > 0 and abs(np.log(max(f_acc, 1e-300) / f_ref)) < abs(np.log(max(f_lost, 1e-300) / f_ref)):
            rep["imu_gaps_accumulated"] += 1
            continue
        # lost: fill (t[k-1], t[k] - dt0] with m samples of interpolated rate
        span = dts[k] - dt0
        m = max(1, int(round(span / dt0)))
        ti = t[k - 1] + span * np.arange(1, m + 1) / m
        w_prev, w_next = dth[k - 1] / dts[k - 1], dth[k] / dt0
        f_prev, f_next = dv[k - 1] / dts[k - 1], dv[k] / dt0
        # linear in time between the interval mid-points of the samples either side
        h = span / m
        mid_prev, mid_next = t[k - 1] - 0.5 * dts[k - 1], t[k] - 0.5 * dt0
        s = ((t[k - 1] + (np.arange(1, m + 1) - 0.5) * h - mid_prev) / (mid_next - mid_prev))[:, None]
        pieces_t += [t[start:k], ti]
        pieces_th += [dth[start:k], h * ((1 - s) * w_prev + s * w_next)]
        pieces_v += [dv[start:k], h * ((1 - s) * f_prev + s * f_next)]
        if lines is not None:
            pieces_ln += [lines[start:k], np.zeros(m, np.int64)]
        rep["imu_samples_inserted"] += m
        start = k
    if start == 0:
        return t, dth, dv, origin, rep
    pieces_t.append(t[start:])
    pieces_th.append(dth[start:])
    pieces_v.append(dv[start:])
    if lines is not None:
        pieces_ln.append(lines[start:])
        origin = RowOrigin(origin.source, origin.first_line, np.concatenate(pieces_ln))
    return np.concatenate(pieces_t), np.concatenate(pieces_th), np.concatenate(pieces_v), origin, rep


#: a GNSS position sigma [m] / velocity sigma [m/s] above this carries no information (and its square,
#: near 1e155, overflows the covariance): the fix (the velocity) is dropped like a non-finite one
MAX_SIGMA_M = 1e5
MAX_SIGMA_MPS = 1e5
#: a reported speed above this [m/s] (beyond low Earth orbit) is not a measurement
MAX_SPEED_MPS = 1e4


#: fixes checked at a time by :func:`sanitize_gnss_blocks`
GNSS_SANITIZE_BLOCK = 1 << 12
#: the most file lines (sample indices) of dropped records the report lists
_DROPPED_LINES_SHOWN = 20
#: the fixes' columns the sanitizers read
_GNSS_COLUMNS = ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n")


def _gnss_columns(g: GnssFixes, n: int) -> dict:
    """The fixes' columns as float64 arrays (views of ``g``'s arrays when they are float64 already)."""
    cols = {f: column(getattr(g, f)) for f in _GNSS_COLUMNS}  # a column read on demand: a block at a time
    for f in ("v_n", "sigma_pos_n", "sigma_vel_n"):
        cols[f] = cols[f].reshape(n, 3)
    return cols


def _gnss_block_masks(cols: dict, a: int, b: int, min_h_m: float, max_h_m: float):
    """``(t, ok, bad_vel)`` of fixes a .. b - 1: the tests of a fix and of its velocity, the one copy
    :func:`sanitize_gnss` (whole record) and :func:`sanitize_gnss_blocks` (a block at a time) share."""
    t, lat, lon, h, v, sp, sv = (cols[f][a:b] for f in ("t_valid", "lat_deg", "lon_deg", "h_m", "v_n",
                                                        "sigma_pos_n", "sigma_vel_n"))
    with np.errstate(invalid="ignore"):
        ok = (np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)
              & np.isfinite(sp).all(axis=1) & (sp > 0).all(axis=1) & (sp <= MAX_SIGMA_M).all(axis=1)
              & (np.abs(lat) <= 90.0) & (lon >= -180.0) & (lon <= 360.0) & (h >= min_h_m) & (h <= max_h_m))
        vel_any = np.isfinite(v).any(axis=1) | np.isfinite(sv).any(axis=1)
        vel_ok = (np.isfinite(v).all(axis=1) & np.isfinite(sv).all(axis=1) & (sv > 0).all(axis=1)
                  & (sv <= MAX_SIGMA_MPS).all(axis=1) & (np.abs(v) <= MAX_SPEED_MPS).all(axis=1))
    return t, ok, ok & vel_any & ~vel_ok


def sanitize_gnss(g: GnssFixes, *, min_h_m: float = DEFAULTS["min_h_m"], max_h_m: float = DEFAULTS["max_h_m"],
                  source: str = "gnss", arrivals: bool = False) -> tuple[GnssFixes, dict]:
    """Check and repair loosely coupled GNSS fixes (policy in the module docstring).

    Parameters
    ----------
    g : GnssFixes
    min_h_m, max_h_m : float
        Plausible height range [m].
    source : str
        Name used in messages when ``g.origin`` is not set.
    arrivals : bool
        The records are an arrival stream (the delay filters): a repeated time
        of validity with a different arrival time is kept as a second arrival
        (seed 001 eq. (4)); only repeats of both times are dropped.

    Returns
    -------
    GnssFixes
        Sorted by ``t_valid`` (then ``t_arrival``); the input object itself
        when nothing was changed.
    dict
        ``gnss_records_in``, ``gnss_records_out``, ``gnss_invalid_dropped``,
        ``gnss_velocity_removed``, ``gnss_reordered``, ``gnss_duplicates_dropped``,
        ``gnss_repeat_arrivals_kept`` and ``gnss_dropped_lines`` (file lines, or sample indices, of the first
        20 records dropped).
    """
    n = len(g)
    rep = dict(gnss_records_in=n, gnss_records_out=n, gnss_invalid_dropped=0, gnss_velocity_removed=0,
               gnss_reordered=0, gnss_duplicates_dropped=0, gnss_repeat_arrivals_kept=0, gnss_dropped_lines=[])
    if n == 0:
        return g, rep
    cols = _gnss_columns(g, n)
    t, ok, bad_vel = _gnss_block_masks(cols, 0, n, min_h_m, max_h_m)
    ta, lat, lon, h, sp = (cols[f] for f in ("t_arrival", "lat_deg", "lon_deg", "h_m", "sigma_pos_n"))
    v, sv = cols["v_n"], cols["sigma_vel_n"]
    changed = False
    if bad_vel.any():
        v, sv = v.copy(), sv.copy()  # the input's own arrays stay as they are
        v[bad_vel] = np.nan
        sv[bad_vel] = np.nan
        rep["gnss_velocity_removed"] = int(bad_vel.sum())
        changed = True
    lines = g.origin.all_lines(n) if g.origin is not None else np.arange(n)
    dropped = ~ok
    rep["gnss_invalid_dropped"] = int(dropped.sum())
    idx = np.flatnonzero(ok)
    if arrivals:  # by time of validity, then arrival (stable for ties of both)
        order = idx[np.lexsort((ta[idx], t[idx]))]
    else:
        order = idx[np.argsort(t[idx], kind="stable")]
    rep["gnss_reordered"] = int((order != idx).sum())
    ts = t[order]
    dup = np.concatenate([[False], np.diff(ts) == 0]) if len(ts) else np.zeros(0, bool)
    if arrivals and len(ts):
        repeat = dup & np.concatenate([[False], np.diff(ta[order]) != 0])
        rep["gnss_repeat_arrivals_kept"] = int(repeat.sum())
        dup &= ~repeat
    rep["gnss_duplicates_dropped"] = int(dup.sum())
    all_dropped = np.concatenate([np.flatnonzero(dropped), order[dup]])
    rep["gnss_dropped_lines"] = sorted(int(lines[i]) for i in all_dropped)[:_DROPPED_LINES_SHOWN]
    order = order[~dup]
    rep["gnss_records_out"] = len(order)
    if not (changed or len(order) != n or (order != np.arange(n)).any()):
        return g, rep
    origin = g.origin.take(order, n) if g.origin is not None else None
    out = GnssFixes(t[order], ta[order], lat[order], lon[order], h[order], v[order], sp[order], sv[order],
                    origin=origin)
    return out, rep


def sanitize_gnss_blocks(g: GnssFixes, *, min_h_m: float = DEFAULTS["min_h_m"],
                         max_h_m: float = DEFAULTS["max_h_m"], source: str = "gnss",
                         block: int | None = None) -> tuple[GnssFixes, dict]:
    """:func:`sanitize_gnss` (on-time filters: ``arrivals=False``) a block of
    ``block`` fixes at a time, for the block-by-block run
    (:mod:`insnav.filters.stream`) on a day of fixes: the same fixes (values,
    dtypes, file lines) and the same report, without its whole-record
    temporaries (copies of the velocity columns, masks, sort order).

    Memory beyond the input: one block's temporaries, two masks of one bool
    per fix, and the output arrays only when a fix is dropped or a velocity
    removed (nothing changed: the input object itself, as
    :func:`sanitize_gnss` returns it).  The valid fixes must be in time
    order (ties allowed: the first is kept, the rest dropped as duplicates,
    as the stable sort of :func:`sanitize_gnss` leaves them); a valid fix
    earlier than the one before hands the record to :func:`sanitize_gnss`
    itself (it sorts them), so the result is its result in every case.

    Parameters
    ----------
    g : GnssFixes
    min_h_m, max_h_m : float
        Plausible height range [m].
    source : str
        Name used in messages when ``g.origin`` is not set.
    block : int, optional
        Fixes per block (default :data:`GNSS_SANITIZE_BLOCK`; any size >= 1 gives the same result).

    Returns
    -------
    GnssFixes, dict
        As :func:`sanitize_gnss` with ``arrivals=False``.
    """
    n = len(g)
    rep = dict(gnss_records_in=n, gnss_records_out=n, gnss_invalid_dropped=0, gnss_velocity_removed=0,
               gnss_reordered=0, gnss_duplicates_dropped=0, gnss_repeat_arrivals_kept=0, gnss_dropped_lines=[])
    if n == 0:
        return g, rep
    block = max(1, int(GNSS_SANITIZE_BLOCK if block is None else block))
    cols = _gnss_columns(g, n)
    keep = np.zeros(n, bool)
    bad_vel = None  # allocated at the first fix whose velocity is removed
    t_last = None  # the time of the last valid fix so far [s]
    shown: list[int] = []  # the smallest file lines (sample indices) of the dropped records
    for a in range(0, n, block):
        b = min(n, a + block)
        t, ok, bv = _gnss_block_masks(cols, a, b, min_h_m, max_h_m)
        ts = t[ok]
        if ts.size:
            if (t_last is not None and ts[0] < t_last) or bool((ts[1:] < ts[:-1]).any()):
                return sanitize_gnss(g, min_h_m=min_h_m, max_h_m=max_h_m, source=source)  # out of time order
            dup = np.empty(ts.size, bool)
            dup[0] = t_last is not None and ts[0] == t_last
            np.equal(ts[1:], ts[:-1], out=dup[1:])
            t_last = float(ts[-1])
        else:
            dup = np.zeros(0, bool)
        kept = np.flatnonzero(ok)
        keep[a + kept[~dup]] = True
        rep["gnss_invalid_dropped"] += int(b - a - ts.size)
        rep["gnss_duplicates_dropped"] += int(dup.sum())
        if bv.any():
            if bad_vel is None:
                bad_vel = np.zeros(n, bool)
            bad_vel[a:b] = bv
            rep["gnss_velocity_removed"] += int(bv.sum())
        gone = a + np.concatenate([np.flatnonzero(~ok), kept[dup]])
        if gone.size:
            ln = (np.asarray([g.origin.line(int(i)) for i in gone[np.argsort(gone)][:_DROPPED_LINES_SHOWN]])
                  if g.origin is not None and g.origin.lines is None else
                  (g.origin.all_lines(n)[gone] if g.origin is not None else gone))
            shown = sorted(shown + [int(x) for x in ln])[:_DROPPED_LINES_SHOWN]
    rep["gnss_dropped_lines"] = shown
    m = int(keep.sum())
    rep["gnss_records_out"] = m
    if m == n and bad_vel is None:
        return g, rep
    out = dict(t_valid=np.empty(m), t_arrival=np.empty(m), lat_deg=np.empty(m), lon_deg=np.empty(m),
               h_m=np.empty(m), v_n=np.empty((m, 3)), sigma_pos_n=np.empty((m, 3)), sigma_vel_n=np.empty((m, 3)))
    lines = (np.empty(m, np.int64) if g.origin is not None else None)
    k = 0
    for a in range(0, n, block):
        b = min(n, a + block)
        kb = keep[a:b]
        j = k + int(kb.sum())
        for f, dst in out.items():
            x = cols[f][a:b][kb]
            if bad_vel is not None and f in ("v_n", "sigma_vel_n"):
                x[bad_vel[a:b][kb]] = np.nan
            dst[k:j] = x
        if lines is not None:
            lines[k:j] = g.origin.all_lines(n)[a:b][kb] if g.origin.lines is not None else \
                g.origin.first_line + a + np.flatnonzero(kb)
        k = j
    origin = RowOrigin(g.origin.source, g.origin.first_line, lines) if g.origin is not None else None
    return GnssFixes(**out, origin=origin), rep


def sanitize_dataset(dataset, options: dict | bool | None = True, *, arrivals: bool = False):
    """Both sanitizers on a :class:`insnav.Dataset`: ``(dataset', report)``.

    ``options`` (a dict) overrides :data:`DEFAULTS`; the dataset is returned
    unchanged (the same object) when nothing had to be repaired.  ``arrivals``:
    the GNSS records are an arrival stream (the delay filters; see
    :func:`sanitize_gnss`).
    """
    opts = dict(DEFAULTS)
    if isinstance(options, dict):
        unknown = set(options) - set(DEFAULTS)
        if unknown:
            raise TypeError(f"sanitize: unknown option(s) {sorted(unknown)}; known: {sorted(DEFAULTS)}")
        opts.update(options)
    imu, r1 = sanitize_imu(dataset.imu, max_gap_s=opts["max_gap_s"], gap_factor=opts["gap_factor"],
                           max_rate_rps=opts["max_rate_rps"], max_accel_mps2=opts["max_accel_mps2"],
                           source="imu", t0=float(dataset.t0))
    gnss, r2 = sanitize_gnss(dataset.gnss, min_h_m=opts["min_h_m"], max_h_m=opts["max_h_m"], source="gnss",
                             arrivals=arrivals)
    rep = {**r1, **r2}
    if imu is dataset.imu and gnss is dataset.gnss:
        return dataset, rep
    return dataclasses.replace(dataset, imu=imu, gnss=gnss), rep
