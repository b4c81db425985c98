"""The whole-record course checks as they were before the block-wise rewrite
(``insnav.data.checks``: ``_gnss_course``, ``gyro_course_slope``,
``_course_samples``, ``estimate_time_offset``), kept verbatim as the reference
the bounded implementation is compared with (tests/test_course_checks_bounded.py)."""
from __future__ import annotations

import numpy as np

from insnav._median import median
from insnav.data.checks import _R_EARTH_M, TimeOffset, _heading_at, _heading_grid, _scanned


def _gnss_course(gnss):
    """Time-ordered GNSS times [s], horizontal velocity (N, E) [m/s] and
    whether some of it came from the positions.

    The reported velocity where it is finite; where it is not (KF-GINS and
    many RTK files carry positions only), the central difference of the
    positions over about 2 s, ``(p[k+j] - p[k-j]) / (t[k+j] - t[k-j])`` with
    ``j`` fixes ~1 s, which is centred on ``t[k]`` (no time shift)."""
    gt = np.asarray(gnss.t_valid, float)
    v = np.array(np.asarray(gnss.v_n, float)[:, :2])
    order = np.argsort(gt, kind="stable")
    gt, v = gt[order], v[order]
    missing = ~np.all(np.isfinite(v), axis=1)
    from_positions = bool(missing.any())
    if from_positions and gt.size >= 3:
        j = max(1, int(round(1.0 / max(median(np.diff(gt)), 1e-3))))
        j = min(j, (gt.size - 1) // 2)
        lat = np.radians(np.asarray(gnss.lat_deg, float)[order])
        lon = np.radians(np.asarray(gnss.lon_deg, float)[order])
        n_m = lat * _R_EARTH_M
        e_m = np.unwrap(lon) * _R_EARTH_M * np.cos(lat)
        with np.errstate(invalid="ignore", divide="ignore"):
            span = gt[2 * j:] - gt[:-2 * j]
            no_gap = span <= 3.0 * 2 * j * median(np.diff(gt))
            vp = np.full_like(v, np.nan)
            vp[j:-j, 0] = np.where(no_gap, (n_m[2 * j:] - n_m[:-2 * j]) / span, np.nan)
            vp[j:-j, 1] = np.where(no_gap, (e_m[2 * j:] - e_m[:-2 * j]) / span, np.nan)
        v[missing] = vp[missing]
    return gt, v, from_positions


def gyro_course_slope(t, dtheta_b, dv_b, gnss, *, min_speed_mps: float = 3.0, min_turn_deg: float = 45.0):
    """The regression of :func:`check_gyro_against_gnss`: ``(slope, consistent
    with 1, degrees of turns, course from positions)``, or None without
    enough turns at speed."""
    t, dtheta_b, dv_b, scan = _scanned(t, dtheta_b, dv_b)
    if t.size < 3 or len(gnss) < 3 or scan is None or not np.isfinite(np.asarray(gnss.t_valid, float)).all():
        return None
    gt, v, from_positions = _gnss_course(gnss)
    speed = np.hypot(v[:, 0], v[:, 1])
    course = np.arctan2(v[:, 1], v[:, 0])
    # ~1 s intervals (the course of a 10 Hz receiver is noisy fix to fix)
    step = max(1, int(round(1.0 / max(median(np.diff(gt)), 1e-3))))
    sel = np.arange(0, gt.size, step)
    gt, v, speed, course = gt[sel], v[sel], speed[sel], course[sel]
    # the heading the gyros integrate about the vertical, at the fixes (the shared 10 Hz grid)
    grid = _heading_grid(t, dtheta_b, scan)
    if grid is None:
        return None
    g_at = _heading_at(grid, gt)
    with np.errstate(invalid="ignore"):
        fast = (speed[:-1] > min_speed_mps) & (speed[1:] > min_speed_mps) & np.all(np.isfinite(v[:, :2]), axis=1)[1:] \
            & np.all(np.isfinite(v[:, :2]), axis=1)[:-1] & np.isfinite(g_at[:-1]) & np.isfinite(g_at[1:]) \
            & (np.diff(gt) < 5.0 * step * 0.1 + 2.0)
    dc = (np.diff(course) + np.pi) % (2 * np.pi) - np.pi
    dg = np.diff(g_at)
    dc, dg = dc[fast], dg[fast]
    # evidence: the turning the gyros saw (low noise; the course of a noisy or slow
    # receiver adds up to many degrees even on a straight line)
    if dg.size < 5 or np.sum(np.abs(dg)) < np.radians(min_turn_deg):
        return None
    # the course is the noisy one: regress it on the gyro, slope = 1 / (d course / d gyro)
    inv = float(np.dot(dg, dc) / np.dot(dg, dg))
    res = dc - inv * dg
    se = float(np.sqrt(np.dot(res, res) / max(dg.size - 1, 1) / np.dot(dg, dg)))
    slope = 1.0 / inv if inv != 0 else np.inf
    return slope, abs(inv - 1.0) < 5.0 * se, float(np.degrees(np.sum(np.abs(dc)))), from_positions


def _course_samples(gnss, interval_s: float):
    """GNSS course samples for :func:`estimate_time_offset`: ``(lo, hi, course
    [rad], speed [m/s])``, time ordered, or None with fewer than 3.

    With velocities (at least half the fixes): the course of each fix with
    one, ``lo = hi = t``.  Without (positions only): the chord between fixes
    ``j`` apart (``j`` fixes ~ ``interval_s``), ``lo = t[k]``, ``hi = t[k+j]``:
    its direction is the mean heading over the chord, compared with the mean
    of the gyro heading over the same span.  (The central difference over
    ``t[k-j]..t[k+j]`` is the tangent at the chord's arc-length midpoint, not
    at ``t[k]``; decelerating into turns it biased the lag by 0.3 s.)"""
    t = np.asarray(gnss.t_valid, float)
    order = np.argsort(t, kind="stable")
    t = t[order]
    v = np.asarray(gnss.v_n, float)[order, :2]
    has_v = np.all(np.isfinite(v), axis=1) & np.isfinite(t)
    if has_v.sum() >= 0.5 * t.size:
        t, v = t[has_v], v[has_v]
        if t.size < 3:
            return None
        return t, t, np.arctan2(v[:, 1], v[:, 0]), np.hypot(v[:, 0], v[:, 1])
    lat = np.radians(np.asarray(gnss.lat_deg, float)[order])
    lon = np.radians(np.asarray(gnss.lon_deg, float)[order])
    ok = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon)
    t, lat, lon = t[ok], lat[ok], lon[ok]
    if t.size < 4:
        return None
    dt = median(np.diff(t))
    j = min(max(1, int(round(interval_s / max(dt, 1e-3)))), t.size - 1)
    n_m = lat * _R_EARTH_M
    e_m = np.unwrap(lon) * _R_EARTH_M * np.cos(lat)
    lo, hi = t[:-j], t[j:]
    dn, de = n_m[j:] - n_m[:-j], e_m[j:] - e_m[:-j]
    span = hi - lo
    keep = (span > 0) & (span <= 3.0 * j * dt)
    if keep.sum() < 3:
        return None
    lo, hi, dn, de, span = lo[keep], hi[keep], dn[keep], de[keep], span[keep]
    return lo, hi, np.arctan2(de, dn), np.hypot(dn, de) / span


def estimate_time_offset(t, dtheta_b, dv_b, gnss, *, max_lag_s: float = 40.0, interval_s: float = 1.0,
                         min_speed_mps: float = 0.5, min_turn_deg: float = 90.0,
                         max_pairs: int = 4000) -> TimeOffset | None:
    """The lag between the gyro heading and the GNSS course, from the turns.

    The gyros' rotation about the vertical (the mean specific-force direction,
    as in :func:`check_gyro_against_gnss`; a near-level vehicle's heading
    rate) is integrated once onto a 10 Hz grid
    (``_core.rotation_about_at``); for each candidate lag ``L`` the heading
    change ``g(t_b - L) - g(t_a - L)`` over pairs of fixes ``interval_s``
    apart (the mean over the chord of a positions-only file,
    :func:`_course_samples`) is correlated with the GNSS course change
    ``c(t_b) - c(t_a)``
    (weights ``speed^2``: the course error is ``sigma_v / speed``).  The
    correlation is searched over ``-max_lag_s..max_lag_s`` on a 1 s grid,
    then on 0.1 s steps around its maximum, and refined by a parabola through
    the best three (cross-correlation time-delay estimation with sub-sample
    interpolation; Knapp & Carter 1976, IEEE Trans. ASSP 24(4)).  The course
    is the reported GNSS velocity's (a tight run: the single-point fixes'
    Doppler velocity), or the chords' between the positions.

    Returns None with fewer than 20 pairs at speed or less than
    ``min_turn_deg`` of turning.
    """
    t, dtheta_b, dv_b, scan = _scanned(t, dtheta_b, dv_b)
    if t.size < 3 or len(gnss) < 3 or scan is None:
        return None
    samples = _course_samples(gnss, interval_s)
    if samples is None:
        return None
    lo, hi, course, speed = samples
    tm = 0.5 * (lo + hi)
    # pairs (a, b): b the first sample at least interval_s after a; no gaps
    a = np.arange(tm.size)
    b = np.searchsorted(tm, tm + interval_s - 1e-6)
    keep = b < tm.size
    a, b = a[keep], b[keep]
    keep = (tm[b] - tm[a] <= 2.0 * interval_s) & (speed[a] > min_speed_mps) & (speed[b] > min_speed_mps)
    a, b = a[keep], b[keep]
    if a.size > max_pairs:
        pick = np.linspace(0, a.size - 1, max_pairs).round().astype(np.int64)
        a, b = a[pick], b[pick]
    if a.size < 20:
        return None
    dc = (course[b] - course[a] + np.pi) % (2 * np.pi) - np.pi
    w = np.minimum(np.minimum(speed[a], speed[b]), 30.0) ** 2
    hg = _heading_grid(t, dtheta_b, scan)  # interpolated by index arithmetic (no search per query)
    if hg is None:
        return None
    x0, h, g_grid = hg
    n_grid = g_grid.size
    wdc = w * dc
    dg_grid = np.diff(g_grid)
    chords = bool(np.any(hi > lo))
    if chords:  # the integral of the heading (trapezoid): a chord's course is the heading's mean over it
        gi_grid = np.concatenate([[0.0], np.cumsum(0.5 * h * (g_grid[1:] + g_grid[:-1]))])
        dgi_grid = np.diff(gi_grid)

    def at(q, f, df):
        u = (q - x0) * (1.0 / h)
        i = u.astype(np.int64)  # truncation = floor inside the grid; outside: NaN below
        np.clip(i, 0, n_grid - 2, out=i)
        out = f[i] + (u - i) * df[i]
        out[(u < 0.0) | (u > n_grid - 1)] = np.nan
        return out

    def heading(k, lags):
        """The gyro heading of samples k at the lags: at the fix, or averaged over the chord."""
        if not chords:
            return at(lo[k] - lags, g_grid, dg_grid)
        return (at(hi[k] - lags, gi_grid, dgi_grid) - at(lo[k] - lags, gi_grid, dgi_grid)) / (hi[k] - lo[k])

    def corr(lags, sub=slice(None)):
        lags = np.asarray(lags, float)[:, None]
        ab = np.concatenate([a[sub], b[sub]])
        used, pos = np.unique(ab, return_inverse=True)  # a sample ends one pair and starts the next: once
        hk = heading(used, lags)
        dg = hk[:, pos[ab.size // 2:]] - hk[:, pos[:ab.size // 2]]
        m = np.isfinite(dg)
        dg = np.where(m, dg, 0.0)
        ww = w[sub]
        sxy = dg @ wdc[sub]
        sxx = np.einsum("ij,ij,j->i", dg, dg, ww)
        syy = m @ (ww * dc[sub] ** 2)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = sxy / np.sqrt(sxx * syy)
        r[m.sum(axis=1) < max(20, ww.size // 2)] = np.nan  # most pairs outside the IMU span: no verdict
        return r, dg, m

    coarse = np.arange(-max_lag_s, max_lag_s + 1e-9, 1.0)  # the correlation's main lobe is several s wide
    rc, _, _ = corr(coarse, slice(None, None, max(1, -(-a.size // 300))))  # the coarse search on <= 300 pairs
    if not np.isfinite(rc).any():
        return None
    j = int(np.nanargmax(rc))
    fine_step = 0.1
    fine = coarse[j] + np.arange(-1.1, 1.1 + 1e-9, fine_step)
    rf, dgf, mf = corr(fine, slice(None, None, max(1, -(-a.size // 1500))))  # on <= 1500 pairs
    k = int(np.nanargmax(rf))
    lag = float(fine[k])
    if 0 < k < fine.size - 1 and np.isfinite(rf[k - 1]) and np.isfinite(rf[k + 1]):
        den = rf[k - 1] - 2.0 * rf[k] + rf[k + 1]
        if den < 0:
            lag += 0.5 * (rf[k - 1] - rf[k + 1]) / den * fine_step
    # the turning seen (the pairs overlap when the fixes come faster than interval_s)
    tas = tm[a][::max(1, -(-a.size // 1500))]
    turn_deg = float(np.degrees(np.sum(np.abs(dgf[k][mf[k]]))) * median(np.diff(tas)) / interval_s)
    if turn_deg < min_turn_deg:
        return None
    # the highest other local maximum of the coarse correlation, outside the main lobe
    rr = np.where(np.isfinite(rc), rc, -np.inf)
    peaks = np.flatnonzero((rr[1:-1] >= rr[:-2]) & (rr[1:-1] >= rr[2:])) + 1
    left, right = j, j  # the main lobe: downhill from the maximum on both sides
    while left > 0 and rr[left - 1] <= rr[left]:
        left -= 1
    while right < rr.size - 1 and rr[right + 1] <= rr[right]:
        right += 1
    others = [rr[p] for p in peaks if p < left or p > right]
    r_second = float(max(others)) if others else float("nan")
    r_zero = float(corr([0.0])[0][0])
    return TimeOffset(lag, float(rf[k]), r_zero, r_second, int(a.size), turn_deg)
