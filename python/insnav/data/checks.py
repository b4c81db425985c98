"""Unit and sanity checks of the input before a filter runs.

Each check raises :class:`DataCheckError` (a ``ValueError``) with one line
that names the file (``source``), the column and the evidence, e.g.::

    imu.csv: dv_*: median |f| = 1.00 m/s^2 over 12000 samples, expected ~9.8 (the increments look like g, not m/s)

What is checked (the wrong-unit cases users actually hit):

* **specific force** at its median over the run ~ g (a car or robot spends
  most of its time near 1 g; aircraft too): ``dv`` in g (median 1.0), in
  cm/s or ft/s, or the wrong sample interval, give a median far from g;
* **axes**: the mean specific force points up, i.e. along -z of FRD (FLU or
  RFU data read as FRD put it along +z);
* **angular rate** plausible for a vehicle: a median ``|omega|`` above
  1 rad/s (57 deg/s sustained) means degrees (x 57.3) or a rate written as an
  increment;
* **GNSS positions**: latitude/longitude in range; the first fix within
  ``max_start_distance_m`` of the stated initial position (radians instead of
  degrees, a flipped longitude sign: thousands of km); no jump of more than
  ``min_jump_m`` between fixes faster than ``max_speed_mps``; position
  sigmas > 0;
* **gyro units and axes against the GNSS course**: the heading change the
  gyros integrate about the vertical (the mean specific-force direction) over
  each fast GNSS interval, regressed on the GNSS course change: slope 1 for
  rad, 57.3 for degrees, -1 for gyro axes of the other handedness than the
  accelerometers';
* **time bases**: the GNSS fixes overlap the IMU's time span.

Used by the file loaders before the alignment (:mod:`insnav.io.csv_dataset`),
with two more that need to know what the user stated:

* **lat/lon radians** read as degrees (:func:`check_latlon_radians`: every
  fix within +-pi/2, +-pi when the unit was not stated);
* **positions against the velocity columns** (:func:`check_gnss_velocity`):
  a flipped latitude or longitude sign moves the fixes against the reported
  velocity, radians read as degrees 57.3x slower.
"""
from __future__ import annotations

import contextlib
import contextvars
import dataclasses

import numpy as np

from .._median import _diffs, median
from .dataset import column
from .._median import stream_median as _stream_median
from ..units import DEG, G0


class DataCheckError(ValueError):
    """Input that cannot be right (units, signs, time bases)."""


#: a GNSS position sigma above this [m] is refused (insnav.filters.sanitize drops such fixes first)
MAX_GNSS_SIGMA_M = 1e5

#: how to map z-up axes (check_imu): naming one candidate made RFU data read as FLU, 90 deg off in yaw
_AXES_HINT = "map the axes in the input settings: z up with x forward is FLU, with x right RFU"

#: check_imu judges the medians on at most this many evenly spread samples (the
#: verdicts have factor-2 margins; a 56-min 200 Hz log then takes ~10 ms, not ~90)
CHECK_IMU_MAX_SAMPLES = 50_000


def check_imu(t, dtheta_b, dv_b, *, source: str = "imu", acc_label: str = "dv_*", gyro_label: str = "dtheta_*",
              fixes: dict | None = None) -> None:
    """Specific force and angular rate magnitudes plausible for SI increments.

    ``acc_label`` / ``gyro_label`` name the columns in the messages (a loader
    passes the user's file columns); ``fixes`` maps a cause (``acc_g``,
    ``t_ms``, ``dv_mm``, ``dv_cm``, ``dv_rate``, ``dv_increment``, ``axes``,
    ``gyro_deg``, ``dtheta_rate``) to the setting that fixes it, appended to
    the message (e.g. ``'set [imu] acc_unit = "g"'``).
    """
    fixes = fixes or {}

    def fix(cause):
        return f"; {fixes[cause]}" if cause in fixes else ""

    t, dtheta_b, dv_b, scan = _scanned(t, dtheta_b, dv_b)
    if t.size < 3 or scan is None:
        return  # non-finite samples: the finite-value checks (sanitize, run) name them
    idx = np.arange(1, t.size, max(1, (t.size - 1) // CHECK_IMU_MAX_SAMPLES))
    dt = t[idx] - t[idx - 1]
    ok = dt > 0  # repeated or decreasing times are the time check's business (sanitize, run)
    if ok.sum() < 2:
        return
    idx, dt = idx[ok], dt[ok]
    dtm = median(dt)
    dvs, dths = dv_b[idx], dtheta_b[idx]
    f = np.sqrt(np.einsum("ij,ij->i", dvs, dvs)) / dt
    w = np.sqrt(np.einsum("ij,ij->i", dths, dths)) / dt
    fm, wm = median(f), median(w)
    n = f.size
    if not 0.5 * G0 < fm < 2.0 * G0:
        hint = ""
        if 0.5 < fm < 2.0:
            hint = " (the increments look like g, not m/s" + fix("acc_g") + ")"
        elif 0.5 * G0 < fm * 1000 < 2 * G0:
            hint = " (t looks like milliseconds, or dv is in mm/s" + fix("t_ms") + ")"
        elif 0.5 * G0 < fm / 1000 < 2 * G0:
            hint = " (dv looks like mm/s, or t like kiloseconds" + fix("dv_mm") + ")"
        elif 0.5 * G0 < fm / 100 < 2 * G0:
            hint = " (dv looks like cm/s" + fix("dv_cm") + ")"
        elif 0.5 * G0 < fm * dtm < 2 * G0:
            hint = " (dv looks like a specific force in m/s^2, not an increment in m/s" + fix("dv_rate") + ")"
        elif 0.5 * G0 < fm / dtm < 2 * G0:
            hint = " (the values look like increments over the sample interval, not rates" + fix("dv_increment") + ")"
        raise DataCheckError(f"{source}: {acc_label}: median |f| = {fm:.4g} m/s^2 over {n} samples, expected "
                             f"~{G0:.1f}{hint}")
    f_mean = np.array(scan["dv_sum"])  # sum of dv_b over the samples
    up = f_mean / max(np.linalg.norm(f_mean), 1e-12)  # at rest the specific force points up
    if up[2] > 0.7:
        raise DataCheckError(f"{source}: {acc_label}: the mean specific force points along +z "
                             f"({up.round(3).tolist()}), i.e. down in FRD: the IMU is upside down, or FLU/RFU axes "
                             f"are read as FRD ({fixes.get('axes', _AXES_HINT)})")
    if wm > 1.0:
        hint = ""
        if wm * DEG < 1.0:
            hint = " (the increments look like degrees, not radians" + fix("gyro_deg") + ")"
        elif wm * dtm < 1.0:
            hint = " (dtheta looks like an angular rate in rad/s, not an increment in rad" + fix("dtheta_rate") + ")"
        raise DataCheckError(f"{source}: {gyro_label}: median |omega| = {wm:.4g} rad/s ({np.degrees(wm):.4g} deg/s) "
                             f"over {n} samples, implausible for a vehicle{hint}")


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


_R_EARTH_M = 6_371_000.0


def _down_b(scan) -> np.ndarray:
    """The body-frame down axis: minus the mean specific-force direction (a
    vehicle spends most of its time near level)."""
    f = np.array(scan["dv_sum"])  # sum of dv_b over the samples
    return -f / max(np.linalg.norm(f), 1e-12)


#: grid step of the gyro heading shared by the course checks [s]
_HEADING_GRID_S = 0.1
#: the grid step in use [s]: _HEADING_GRID_S, or wider for an IMU record summed over wider windows
#: (:func:`heading_grid_step`)
_GRID_STEP = contextvars.ContextVar("insnav_heading_grid_s", default=_HEADING_GRID_S)


@contextlib.contextmanager
def heading_grid_step(step_s: float):
    """The course checks' heading grid at ``step_s`` [s] instead of
    ``_HEADING_GRID_S`` inside the block: the block-by-block run's checks on
    an IMU record summed to 5 Hz, 2.5 Hz, ... (``insnav.filters.stream``) keep
    one grid point per row, so the grid, like the record, does not grow with
    the recording's length."""
    token = _GRID_STEP.set(float(step_s))
    try:
        yield
    finally:
        _GRID_STEP.reset(token)


def _heading_grid(t, dtheta_b, scan):
    """The rotation about the body's mean-down axis [rad] on a uniform
    ``_HEADING_GRID_S`` grid from ``t[0]`` (:func:`heading_grid_step`: wider): ``(x0, h, g)``, or None when not
    finite.  One compiled pass over the samples (``_core.rotation_about_at``),
    memoised with the IMU scan inside :func:`insnav.run`
    (:func:`insnav._imu_scan.scan_memo`): the slope check, the time-offset
    estimate and the failure hints share it."""
    from .. import _core
    from .._imu_scan import _MEMO, _key

    h = _GRID_STEP.get()
    memo = _MEMO.get()
    key = ("heading_grid", _key(t), _key(dtheta_b), h) if memo is not None else None
    if key is not None and key in memo:
        return memo[key][1]
    x0 = float(t[0])
    grid = x0 + h * np.arange(int((t[-1] - x0) / h) + 1)
    g = _core.rotation_about_at(t, dtheta_b, _down_b(scan), grid)
    res = (x0, h, g) if grid.size >= 2 and np.isfinite(g).all() else None
    if key is not None:
        memo[key] = ((t, dtheta_b), res)  # the arrays kept alive: their addresses stay theirs
    return res


def _heading_at(grid, q):
    """Linear interpolation of :func:`_heading_grid` at times ``q`` (NaN outside)."""
    x0, h, g = grid
    u = (np.asarray(q, float) - x0) * (1.0 / h)
    i = u.astype(np.int64)  # truncation = floor inside the grid; outside: NaN below
    np.clip(i, 0, g.size - 2, out=i)
    out = g[i] + (u - i) * (g[i + 1] - g[i])
    out[(u < 0.0) | (u > g.size - 1)] = np.nan
    return out


def check_gyro_against_gnss(t, dtheta_b, dv_b, gnss, *, source: str = "imu", min_speed_mps: float = 3.0,
                            min_turn_deg: float = 45.0, gyro_label: str = "dtheta_*",
                            fixes: dict | None = None) -> float | None:
    """Slope of the gyro heading change on the GNSS course change (1 when right).

    The course is the reported GNSS velocity's, or (no velocity columns) the
    positions' central difference.  Returns the slope, or None when the run
    turns less than ``min_turn_deg`` at speed (nothing to compare).  Raises
    :class:`DataCheckError` when the slope says degrees (> 10) or a mirrored
    turn (< -0.5: inverted gyro axes, or a flipped latitude / longitude sign
    of course-from-positions), or is otherwise far from 1 (outside 0.5..2).
    """
    fit = gyro_course_slope(t, dtheta_b, dv_b, gnss, min_speed_mps=min_speed_mps, min_turn_deg=min_turn_deg)
    if fit is None:
        return None
    slope, consistent, turn_deg, from_positions = fit
    if consistent:
        return slope
    fixes = fixes or {}
    if slope > 10.0 and 0.5 < slope / np.degrees(1.0) < 2.0:
        raise DataCheckError(f"{source}: {gyro_label}: the gyros turn {slope:.1f}x the GNSS course over "
                             f"{turn_deg:.0f} deg of turns: the increments look like degrees, "
                             f"not radians" + (f"; {fixes['gyro_deg']}" if "gyro_deg" in fixes else ""))
    if slope < -0.5:
        flip = (" or the GNSS longitude (or latitude) sign is flipped (the track is mirrored; west and south are "
                "negative)") if from_positions else ""
        raise DataCheckError(f"{source}: {gyro_label}: the gyros turn opposite to the GNSS course (slope "
                             f"{slope:.2f}): the gyro axes look inverted relative to the accelerometers'"
                             + (f", {fixes['inverted']}" if "inverted" in fixes else "") + flip)
    if not 0.5 < slope < 2.0:
        raise DataCheckError(f"{source}: {gyro_label}: the gyro heading change is {slope:.2f}x the GNSS course change "
                             f"over {turn_deg:.0f} deg of turns (expected 1): wrong units, "
                             f"scale or axes")
    return slope


#: fixes the course checks (:func:`gyro_course_slope`, :func:`estimate_time_offset`) take at a time: their
#: temporaries are a few arrays of this many rows (about 3 MB), whatever the record's length (a record out
#: of time order is first sorted: an index of 8 bytes per fix).  A record of at most this many fixes is
#: taken in one block, so its figures are those of whole-record arrays bit for bit
COURSE_CHECK_BLOCK = 1 << 14
class _TimeOrdered:
    """The fixes of ``gnss`` in time order (stable: the order of ``np.argsort(t, kind="stable")``), read
    ``block`` rows at a time.  In time order already (the usual case): no copy of a whole column."""

    def __init__(self, gnss, block: int | None = None):
        self.g = gnss
        self.t = np.asarray(gnss.t_valid, float)
        self.n = int(self.t.shape[0])
        self.block = max(8, int(COURSE_CHECK_BLOCK if block is None else block))
        self.order = None if _in_time_order(self.t, self.block) else np.argsort(self.t, kind="stable")

    def rows(self, *fields):
        """``(a, [rows a .. b-1 of each field])`` per block; fields ``t`` [s], ``v`` (north, east) [m/s],
        ``lat``, ``lon`` [rad]."""
        v_n = column(self.g.v_n) if "v" in fields else None
        for a in range(0, self.n, self.block):
            b = min(self.n, a + self.block)
            idx = slice(a, b) if self.order is None else self.order[a:b]
            out = []
            for f in fields:
                if f == "t":
                    out.append(self.t[idx])
                elif f == "v":
                    out.append(v_n[idx, :2])
                else:
                    out.append(np.radians(column(getattr(self.g, f + "_deg"))[idx]))
            yield a, out

    def all_finite_t(self) -> bool:
        return all(bool(np.isfinite(t).all()) for _, (t,) in self.rows("t"))


class _Unwrap:
    """``np.unwrap`` (period 2 pi) of a sequence given in consecutive chunks: the same values (its
    corrections' running sum carried from chunk to chunk, as ``cumsum`` adds them one by one)."""

    def __init__(self):
        self.prev = None
        self.s = None

    def __call__(self, p):
        if not p.size:
            return p.copy()
        dd = np.diff(p) if self.prev is None else np.diff(np.concatenate([self.prev, p]))
        high = np.pi
        low = -high
        ddmod = np.mod(dd - low, 2 * np.pi) + low
        np.copyto(ddmod, high, where=(ddmod == low) & (dd > 0))
        ph = ddmod - dd
        np.copyto(ph, 0, where=abs(dd) < high)
        up = np.array(p, copy=True)
        if self.prev is None:
            cs = ph.cumsum()
            up[1:] = p[1:] + cs
        else:
            cs = np.concatenate([self.s, ph]).cumsum()[1:]
            up[:] = p + cs
        self.s = cs[-1:] if cs.size else np.zeros(1)  # a first chunk of one value: no correction yet
        self.prev = p[-1:]
        return up


def _course_rows(fx: _TimeOrdered, dt_med: float, from_positions: bool):
    """:func:`_gnss_course` a block of rows at a time: ``(a, t [s], v (north, east) [m/s])`` of rows
    a .. b-1 in time order, the velocity from the positions' central difference where it is not finite
    (the ``j`` rows before and after a block carried over; its output lags ``j`` rows behind the reads)."""
    n = fx.n
    if not from_positions:
        for a, (gt, v) in fx.rows("t", "v"):
            yield a, gt, np.array(v)
        return
    j = min(max(1, int(round(1.0 / max(dt_med, 1e-3)))), (n - 1) // 2)
    lim = 3.0 * 2 * j * dt_med
    unwrap = _Unwrap()
    w = None  # (first row, t, v, north, east) of the rows kept: those not yet given and the j before them
    e0 = 0  # the next row to give
    for a, (gt, v, lat, lon) in fx.rows("t", "v", "lat", "lon"):
        n_m = lat * _R_EARTH_M
        e_m = unwrap(lon) * _R_EARTH_M * np.cos(lat)
        if w is None:
            w = (a, gt, v, n_m, e_m)
        else:
            w = (w[0],) + tuple(np.concatenate([x, y]) for x, y in zip(w[1:], (gt, v, n_m, e_m)))
        w0, wt, wv, wn, we = w
        b = a + len(gt)
        e1 = b if b == n else max(e0, b - j)
        if e1 > e0:
            ks = np.arange(e0, e1)
            out_v = np.array(wv[e0 - w0:e1 - w0])
            missing = ~np.all(np.isfinite(out_v), axis=1)
            if missing.any():
                vp = np.full_like(out_v, np.nan)
                c = (ks >= j) & (ks < n - j)
                ki = ks[c] - w0
                with np.errstate(invalid="ignore", divide="ignore"):
                    span = wt[ki + j] - wt[ki - j]
                    no_gap = span <= lim
                    vp[c, 0] = np.where(no_gap, (wn[ki + j] - wn[ki - j]) / span, np.nan)
                    vp[c, 1] = np.where(no_gap, (we[ki + j] - we[ki - j]) / span, np.nan)
                out_v[missing] = vp[missing]
            yield e0, wt[e0 - w0:e1 - w0], out_v
            e0 = e1
        k0 = max(w0, e0 - j)
        w = (k0,) + tuple(x[k0 - w0:] for x in w[1:])


def _slope_pairs(fx: _TimeOrdered, grid, dt_med: float, from_positions: bool, min_speed_mps: float):
    """:func:`gyro_course_slope`'s course and gyro heading changes ``(dc, dg)`` [rad] over the fast
    intervals between fixes ``step`` apart (~1 s), a block at a time (the last fix of a block carried)."""
    step = max(1, int(round(1.0 / max(dt_med, 1e-3))))
    prev = None
    for a, gt, v in _course_rows(fx, dt_med, from_positions):
        sel = np.arange(-(-a // step) * step, a + len(gt), step) - a  # the rows whose index is a multiple of step
        gt, v = gt[sel], v[sel]
        speed = np.hypot(v[:, 0], v[:, 1])
        course = np.arctan2(v[:, 1], v[:, 0])
        g_at = _heading_at(grid, gt)
        if prev is not None:
            gt, v, speed, course, g_at = (np.concatenate([x, y]) for x, y in zip(prev, (gt, v, speed, course, g_at)))
        prev = (gt[-1:], v[-1:], speed[-1:], course[-1:], g_at[-1:])
        if gt.size < 2:
            continue
        with np.errstate(invalid="ignore"):
            fast = (speed[:-1] > min_speed_mps) & (speed[1:] > min_speed_mps) \
                & np.all(np.isfinite(v[:, :2]), axis=1)[1:] \
                & np.all(np.isfinite(v[:, :2]), axis=1)[:-1] & np.isfinite(g_at[:-1]) & np.isfinite(g_at[1:]) \
                & (np.diff(gt) < 5.0 * step * 0.1 + 2.0)
        dc = (np.diff(course) + np.pi) % (2 * np.pi) - np.pi
        dg = np.diff(g_at)
        yield dc[fast], dg[fast]


def _any_missing_v(fx: _TimeOrdered) -> bool:
    return any(not bool(np.all(np.isfinite(v))) for _, (v,) in fx.rows("v"))


def _course_sample_blocks(fx: _TimeOrdered, interval_s: float):
    """:func:`_course_samples` a block at a time: ``None`` (fewer than 3 samples, as it), or a callable
    returning a fresh iterator of ``(lo, hi, course, speed)`` blocks in time order."""
    n_v = 0
    for _, (t, v) in fx.rows("t", "v"):
        n_v += int(np.count_nonzero(np.all(np.isfinite(v), axis=1) & np.isfinite(t)))
    if n_v >= 0.5 * fx.n:
        if n_v < 3:
            return None

        def with_velocity():
            for _, (t, v) in fx.rows("t", "v"):
                has_v = np.all(np.isfinite(v), axis=1) & np.isfinite(t)
                t, v = t[has_v], v[has_v]
                if t.size:
                    yield t, t, np.arctan2(v[:, 1], v[:, 0]), np.hypot(v[:, 0], v[:, 1])
        return with_velocity

    def ok_rows():
        for _, (t, lat, lon) in fx.rows("t", "lat", "lon"):
            ok = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon)
            yield t[ok], lat[ok], lon[ok]

    n_ok = sum(x[0].size for x in ok_rows())
    if n_ok < 4:
        return None
    dt = _stream_median(lambda: _diffs(x[0] for x in ok_rows()))
    j = min(max(1, int(round(interval_s / max(dt, 1e-3)))), n_ok - 1)

    def chords():
        unwrap = _Unwrap()
        w = None  # the last j rows (t, north, east)
        for t, lat, lon in ok_rows():
            n_m = lat * _R_EARTH_M
            e_m = unwrap(lon) * _R_EARTH_M * np.cos(lat)
            w = (t, n_m, e_m) if w is None else tuple(np.concatenate([x, y]) for x, y in zip(w, (t, n_m, e_m)))
            wt, wn, we = w
            if wt.size > j:
                lo, hi = wt[:-j], wt[j:]
                dn, de = wn[j:] - wn[:-j], we[j:] - we[:-j]
                span = hi - lo
                keep = (span > 0) & (span <= 3.0 * j * dt)
                if keep.any():
                    lo, hi, dn, de, span = lo[keep], hi[keep], dn[keep], de[keep], span[keep]
                    yield lo, hi, np.arctan2(de, dn), np.hypot(dn, de) / span
                w = tuple(x[-j:] for x in w)

    if sum(x[0].size for x in chords()) < 3:
        return None
    return chords


def _offset_pairs(blocks, interval_s: float, min_speed_mps: float, max_pairs: int):
    """:func:`estimate_time_offset`'s pairs of course samples ``(a, b)`` (``b`` the first sample at least
    ``interval_s`` after ``a``, within ``2 interval_s``, both at speed), evenly thinned to ``max_pairs``
    as it does, found a block at a time (the next blocks read ahead as far as ``interval_s`` needs):
    ``(lo, hi, course, speed)`` of the samples the pairs use and ``(a, b)`` as indices into them (in
    order, so the figures are those of the whole-record arrays), or None without a pair."""

    def pairs():
        """(first sample's index, samples of the block and those after it it needs, a, b local)."""
        buf, base = [], 0  # the blocks read and not yet paired; the global index of the first
        it = blocks()
        done = False
        while True:
            while not done and (not buf or _tm_last(buf) < _tm_last(buf[:1]) + interval_s):
                try:
                    buf.append(next(it))
                except StopIteration:
                    done = True
            if not buf:
                return
            cur = len(buf[0][0])
            s = tuple(np.concatenate([x[f] for x in buf]) if len(buf) > 1 else buf[0][f] for f in range(4))
            tm = 0.5 * (s[0] + s[1])
            a = np.arange(cur)
            b = np.searchsorted(tm, tm[:cur] + interval_s - 1e-6)
            keep = b < tm.size
            a, b = a[keep], b[keep]
            keep = (tm[b] - tm[a] <= 2.0 * interval_s) & (s[3][a] > min_speed_mps) & (s[3][b] > min_speed_mps)
            yield base, s, a[keep], b[keep]
            base += cur
            buf.pop(0)

    total = sum(a.size for _, _, a, _ in pairs())
    if total == 0:
        return None
    pick = np.linspace(0, total - 1, max_pairs).round().astype(np.int64) if total > max_pairs else None
    ga, gb, rows, vals = [], [], [], []
    rank = 0
    for base, s, a, b in pairs():
        if pick is not None:
            sel = pick[(pick >= rank) & (pick < rank + a.size)] - rank
            rank += a.size
            a, b = a[sel], b[sel]
        if a.size:
            ga.append(base + a)
            gb.append(base + b)
            used = np.concatenate([a, b])
            rows.append(base + used)
            vals.append(np.column_stack([x[used] for x in s]))
    ga, gb = np.concatenate(ga), np.concatenate(gb)
    rows, vals = np.concatenate(rows), np.concatenate(vals)
    order = np.argsort(rows, kind="stable")
    rows, vals = rows[order], vals[order]
    first = np.flatnonzero(np.concatenate([[True], rows[1:] != rows[:-1]]))
    rows, vals = rows[first], vals[first]
    return tuple(np.ascontiguousarray(vals[:, f]) for f in range(4)), np.searchsorted(rows, ga), \
        np.searchsorted(rows, gb)


def _tm_last(buf) -> float:
    """The mid time of the last sample of the last block in ``buf``."""
    lo, hi = buf[-1][0], buf[-1][1]
    return 0.5 * (lo[-1] + hi[-1])


def gyro_course_slope(t, dtheta_b, dv_b, gnss, *, min_speed_mps: float = 3.0, min_turn_deg: float = 45.0,
                      block: int | None = None):
    """The regression of :func:`check_gyro_against_gnss`: ``(slope, consistent
    with 1, degrees of turns, course from positions)``, or None without
    enough turns at speed.

    The fixes are taken ``block`` (:data:`COURSE_CHECK_BLOCK`) at a time in
    time order (:func:`_course_rows`), the regression's sums added block by
    block (a second pass for the residuals): the temporaries do not grow with
    the record.  A record of at most ``block`` fixes gives the figures of
    whole-record arrays bit for bit; a longer one's sums are added in another
    order (about 1e-16 relative)."""
    t, dtheta_b, dv_b, scan = _scanned(t, dtheta_b, dv_b)
    if t.size < 3 or len(gnss) < 3 or scan is None:
        return None
    fx = _TimeOrdered(gnss, block)
    if not fx.all_finite_t():
        return None
    dt_med = _stream_median(lambda: _diffs(x[0] for _, x in fx.rows("t")))  # the fixes' interval
    from_positions = _any_missing_v(fx)
    # the heading the gyros integrate about the vertical, at the fixes (the shared 10 Hz grid)
    grid = _heading_grid(t, dtheta_b, scan)
    if grid is None:
        return None
    # evidence: the turning the gyros saw (low noise; the course of a noisy or slow
    # receiver adds up to many degrees even on a straight line)
    m, abs_dg, gc, gg = 0, 0.0, 0.0, 0.0
    for dc, dg in _slope_pairs(fx, grid, dt_med, from_positions, min_speed_mps):
        m += dg.size
        abs_dg += float(np.sum(np.abs(dg)))
        gc += float(np.dot(dg, dc))
        gg += float(np.dot(dg, dg))
    if m < 5 or abs_dg < np.radians(min_turn_deg):
        return None
    # the course is the noisy one: regress it on the gyro, slope = 1 / (d course / d gyro)
    inv = float(gc / gg)
    rr, abs_dc = 0.0, 0.0
    for dc, dg in _slope_pairs(fx, grid, dt_med, from_positions, min_speed_mps):
        res = dc - inv * dg
        rr += float(np.dot(res, res))
        abs_dc += float(np.sum(np.abs(dc)))
    se = float(np.sqrt(rr / max(m - 1, 1) / gg))
    slope = 1.0 / inv if inv != 0 else np.inf
    return slope, abs(inv - 1.0) < 5.0 * se, float(np.degrees(abs_dc)), from_positions


@dataclasses.dataclass(frozen=True)
class TimeOffset:
    """The IMU/GNSS time offset seen in the turns (:func:`estimate_time_offset`).

    Attributes
    ----------
    lag_s : float
        How much later [s] the same turn appears in the GNSS course than in the
        gyros (> 0: the GNSS time stamps are late, or the IMU's early).
    r_peak, r_zero : float
        Correlation of the GNSS course changes with the gyro heading changes
        at ``lag_s`` and at no lag.
    r_second : float
        The highest other local maximum of the correlation (periodic motion
        makes one lag as good as another); NaN when there is none.
    pairs : int
        Course changes compared.
    turn_deg : float
        Their turning [deg].
    """

    lag_s: float
    r_peak: float
    r_zero: float
    r_second: float
    pairs: int
    turn_deg: float

    @property
    def ambiguous(self) -> bool:
        """Another lag fits almost as well (periodic motion), no lag at all fits almost as well
        (seed000-sim's pitch/roll oscillations with 5 m fixes: 0.56 at 1 s, 0.54 unshifted), or
        none fits well."""
        if self.r_peak < TIME_OFFSET_MIN_R:
            return True
        if np.isfinite(self.r_second) and self.r_second > TIME_OFFSET_MAX_SECOND * self.r_peak:
            return True
        # the peak must beat the unshifted correlation by more than the estimates' scatter:
        # Fisher z, 3 standard errors of a difference of two correlations over the same pairs
        if np.isfinite(self.r_zero) and self.pairs > 3:
            gain = np.arctanh(min(self.r_peak, 0.999999)) - np.arctanh(min(self.r_zero, 0.999999))
            return bool(gain < 3.0 * np.sqrt(2.0 / (self.pairs - 3)))
        return False


#: the correlation a lag must reach to be believed, and the share of it a second peak may not reach
TIME_OFFSET_MIN_R = 0.5
TIME_OFFSET_MAX_SECOND = 0.9
#: default largest IMU/GNSS time offset accepted before a run [s] (RunConfig.max_time_offset_s): the
#: handheld walk (rtklibexplorer walk_0827) shows its GNSS course 0.46-0.62 s ahead of the phone's heading
#: (a walker's path turns before the phone does: the filter's NIS puts the IMU time within 0.1 s), and a
#: 1 s offset must be caught
MAX_TIME_OFFSET_S = 0.8


def time_offset_cause(lag_s: float) -> str:
    """The usual cause of an IMU/GNSS time offset of ``lag_s`` [s], as ``": ...?"``.

    GPS - UTC was 10-18 s over the last decades (18 s since 2017), TAI - GPS is
    19 s and TAI - UTC 37 s; the tolerance of 0.7 s covers the bias of the
    course-against-heading estimate on a handheld walk (:data:`MAX_TIME_OFFSET_S`)."""
    a = abs(lag_s)
    if 36.3 < a < 37.7:
        return ": TAI vs UTC time stamps?"
    if 18.3 < a < 19.7:
        return ": TAI vs GPS time stamps, or GPS-UTC leap seconds?"
    if 9.3 < a <= 18.3:
        return ": GPS-UTC leap seconds?"
    if abs(a - round(a)) < 0.2:
        return ": a whole-second time stamp error?"
    return ": a logging latency?"


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
                         max_pairs: int = 4000, block: int | None = None) -> TimeOffset | None:
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

    The course samples and their pairs are found ``block``
    (:data:`COURSE_CHECK_BLOCK`) fixes at a time in time order
    (:func:`_course_sample_blocks`, :func:`_offset_pairs`), and only the
    samples of the at most ``max_pairs`` pairs are kept: the temporaries do
    not grow with the record, and the figures are those of whole-record
    arrays bit for bit.

    Returns None with fewer than 20 pairs at speed or less than
    ``min_turn_deg`` of turning.
    """
    t, dtheta_b, dv_b, scan = _scanned(t, dtheta_b, dv_b)
    if t.size < 3 or len(gnss) < 3 or scan is None:
        return None
    blocks = _course_sample_blocks(_TimeOrdered(gnss, block), interval_s)
    if blocks is None:
        return None
    # pairs (a, b): b the first sample at least interval_s after a; no gaps; at most max_pairs, evenly
    # spread (found a block at a time: the samples the pairs use, a and b indices into them)
    got = _offset_pairs(blocks, interval_s, min_speed_mps, max_pairs)
    if got is None:
        return None
    (lo, hi, course, speed), a, b = got
    tm = 0.5 * (lo + hi)
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


def check_time_offset(t, dtheta_b, dv_b, gnss, *, max_offset_s: float = MAX_TIME_OFFSET_S,
                      source: str = "imu", gnss_source: str = "gnss", fix: str | None = None) -> TimeOffset | None:
    """Refuse IMU and GNSS time bases that disagree by more than ``max_offset_s`` [s].

    :func:`estimate_time_offset` over the run; an unambiguous lag beyond the
    limit raises :class:`DataCheckError` naming it, the likely cause (GPS-UTC
    leap seconds for 10-19 s, TAI for 19 / 37 s, whole seconds) and ``fix``
    (the loader's key that shifts a time base), and the ``max_time_offset_s``
    key that accepts it.  Returns the estimate (None: too few turns).
    """
    if not max_offset_s < np.inf:
        return None
    est = estimate_time_offset(t, dtheta_b, dv_b, gnss)
    if est is None or est.ambiguous or abs(est.lag_s) <= max_offset_s:
        return est
    lag = est.lag_s
    raise DataCheckError(
        f"{gnss_source}: GNSS is {abs(lag):.1f} s {'behind' if lag > 0 else 'ahead of'} the IMU ({source})"
        f"{time_offset_cause(lag)} (the same turns come {abs(lag):.2f} s {'later' if lag > 0 else 'earlier'} in the "
        f"GNSS course than in the gyros: correlation {est.r_peak:.2f}, {est.r_zero:.2f} unshifted, {est.pairs} course "
        f"changes, {est.turn_deg:.0f} deg of turns); shift the IMU times by {lag:+.2f} s" + (f" ({fix})" if fix else "")
        + f", or raise max_time_offset_s (now {max_offset_s:g} s; inf: no check)")


def lateral_axis_correlation(t, dtheta_b, dv_b, gnss, *, min_speed_mps: float = 1.0,
                             interval_s: float = 1.0) -> tuple[float, float, int] | None:
    """Correlation of the body x and y specific force with the centripetal
    acceleration of the GNSS track, ``speed * d(course)/dt`` (to the right in
    a right turn), over ~``interval_s`` windows: ``(r_x, r_y, windows)``.

    In FRD, +y is right: ``r_y`` near 1 and ``r_x`` near 0 (0.72-0.94 and
    ``|r_x| < 0.25`` on the walk, the KF-GINS track and the car presets).  An IMU
    whose x axis points right (RFU read as FLU) puts it on ``r_x``.  None with
    fewer than 20 windows at speed or less than 0.2 m/s^2 of centripetal
    acceleration rms."""
    t, dtheta_b, dv_b, scan = _scanned(t, dtheta_b, dv_b)
    if t.size < 3 or len(gnss) < 3 or scan is None:
        return None
    samples = _course_samples(gnss, interval_s)
    if samples is None:
        return None
    lo, hi, course, speed = samples
    tm = 0.5 * (lo + hi)
    b = np.searchsorted(tm, tm + interval_s - 1e-6)
    a = np.flatnonzero(b < tm.size)
    b = b[a]
    span = tm[b] - tm[a]
    ok = (span > 0) & (span <= 2.0 * interval_s) & (speed[a] > min_speed_mps) & (speed[b] > min_speed_mps)
    a, b, span = a[ok], b[ok], span[ok]
    if a.size < 20:
        return None
    dc = (course[b] - course[a] + np.pi) % (2 * np.pi) - np.pi
    a_lat = 0.5 * (speed[a] + speed[b]) * dc / span
    if np.sqrt(np.mean(a_lat ** 2)) < 0.2:
        return None
    from .. import _core

    # the mean specific force over each window: the velocity increments summed about x and y
    # (rotation_about_at integrates any (N, 3) increments along an axis)
    f = []
    for axis in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        c = _core.rotation_about_at(t, dv_b, axis, np.concatenate([tm[a], tm[b]]))
        f.append((c[a.size:] - c[:a.size]) / span)
    good = np.isfinite(f[0]) & np.isfinite(f[1])
    if good.sum() < 20:
        return None
    y = a_lat[good] - a_lat[good].mean()
    r = []
    for fx in f:
        x = fx[good] - fx[good].mean()
        den = np.sqrt(np.dot(x, x) * np.dot(y, y))
        r.append(float(np.dot(x, y) / den) if den > 0 else 0.0)
    return r[0], r[1], int(good.sum())


def check_heading_axes(t, dtheta_b, dv_b, gnss, *, source: str = "imu", fix: str | None = None):
    """Refuse body axes whose x is not forward when the heading is to come from
    the GNSS course: the centripetal acceleration of the turns must be along
    +y (right, FRD), not along x (an IMU whose x points right or left: RFU or
    LBU read as FLU, a 90 deg error in every heading) nor along -y.  Returns
    :func:`lateral_axis_correlation` (None: too little turning to tell)."""
    res = lateral_axis_correlation(t, dtheta_b, dv_b, gnss)
    if res is None:
        return None
    r_x, r_y, n = res
    how = f"(correlation of the specific force with the track's centripetal acceleration over {n} windows: " \
          f"x {r_x:+.2f}, y {r_y:+.2f})"
    tail = f"; {fix}" if fix else ""
    if abs(r_x) > 0.5 and abs(r_x) > 2.0 * abs(r_y):
        side = "right" if r_x > 0 else "left"
        raise DataCheckError(f"{source}: the turns push the IMU along body {'+' if r_x > 0 else '-'}x, not +y "
                             f"{how}: its x axis points {side}, not forward (e.g. RFU data read as FLU), which "
                             f"turns the heading from the GNSS course by 90 deg{tail}")
    if r_y < -0.5 and abs(r_x) < 0.5 * abs(r_y):
        raise DataCheckError(f"{source}: the turns push the IMU along body -y, not +y {how}: its x axis points "
                             f"backwards (a 180 deg heading error){tail}")
    return res


#: a lag the failure hints name (below MAX_TIME_OFFSET_S: a run that failed for another reason does not
#: blame the walk's 0.46-0.62 s course-against-heading lag)
HINT_TIME_OFFSET_S = 0.5


def disagreement_hint(dataset) -> str:
    """What the data say about GNSS fixes and an IMU that disagree (a run
    whose innovation gate rejected too many records), as a clause of a message.

    In order: an IMU/GNSS time offset over :data:`HINT_TIME_OFFSET_S`
    (:func:`estimate_time_offset`); a GNSS track that turns opposite to the
    gyros (a flipped longitude or latitude sign, or inverted gyro axes;
    :func:`gyro_course_slope`); an initial yaw more than 30 deg from the GNSS
    course (the course at the first fast fixes against the initial yaw carried
    to them by the gyros, :func:`initial_yaw_offset_deg`).  Falls back to the
    generic "check units, lever arm and sigmas"."""
    imu, gnss = dataset.imu, dataset.gnss
    hints = []
    try:
        if len(gnss) >= 3:
            est = estimate_time_offset(imu.t, imu.dtheta_b, imu.dv_b, gnss)
            if est is not None and not est.ambiguous and abs(est.lag_s) > HINT_TIME_OFFSET_S:
                how = "behind" if est.lag_s > 0 else "ahead of"
                hints.append(f"the turns put the GNSS {abs(est.lag_s):.2f} s {how} the IMU"
                             f"{time_offset_cause(est.lag_s)} (shift the IMU times by {est.lag_s:+.2f} s)")
            fit = gyro_course_slope(imu.t, imu.dtheta_b, imu.dv_b, gnss)
            if fit is not None and fit[0] < -0.5:
                hints.append(f"the GNSS track turns opposite to the gyros (slope {fit[0]:.2f}): a flipped longitude "
                             "(or latitude) sign, or inverted gyro axes?")
            off = initial_yaw_offset_deg(dataset)
            if off is not None and abs(off) > 30.0:
                hints.append(f"the initial yaw ({dataset.initial.yaw_deg:.1f} deg) is {off:+.0f} deg off the GNSS "
                             "course" + (" (180 deg: heading reversed?)" if abs(off) > 150.0 else ""))
    except Exception:  # noqa: BLE001 - a hint must never replace the message it belongs to
        hints = []
    return "; ".join(hints) if hints else "check units, lever arm and sigmas"


def initial_yaw_offset_deg(dataset, *, min_speed_mps: float = 1.0, window_s: float = 120.0) -> float | None:
    """The GNSS course minus the initial yaw carried forward by the gyros [deg].

    ``yaw(t) = yaw0 + g(t) - g(t0)`` with ``g`` the rotation about the vertical
    (:func:`check_gyro_against_gnss`), compared with the course at the fixes
    faster than ``min_speed_mps`` within ``window_s`` of the first of them; the
    circular mean of the differences.  About 0 for a vehicle whose heading is
    its course (no sideslip; a walker whose mounting is right); None without
    an initial yaw or 5 such fixes."""
    initial = getattr(dataset, "initial", None)
    yaw0 = getattr(initial, "yaw_deg", None)
    if yaw0 is None or not np.isfinite(yaw0):
        return None
    t, dtheta_b, dv_b, scan = _scanned(dataset.imu.t, dataset.imu.dtheta_b, dataset.imu.dv_b)
    if scan is None or t.size < 3 or len(dataset.gnss) < 5:
        return None
    gt, v, _ = _gnss_course(dataset.gnss)
    t0 = float(getattr(dataset, "t0", t[0]))
    with np.errstate(invalid="ignore"):
        fast = np.flatnonzero((np.hypot(v[:, 0], v[:, 1]) > min_speed_mps) & (gt >= t0) & (gt <= t[-1]))
    if fast.size < 5:
        return None
    fast = fast[gt[fast] <= gt[fast[0]] + window_s]
    if fast.size < 5:
        return None
    hg = _heading_grid(t, dtheta_b, scan)
    if hg is None:
        return None
    g = _heading_at(hg, np.concatenate([[max(t0, float(t[0]))], gt[fast]]))
    yaw = np.radians(yaw0) + g[1:] - g[0]
    d = np.arctan2(v[fast, 1], v[fast, 0]) - yaw
    ok = np.isfinite(d)
    if ok.sum() < 5:
        return None
    return float(np.degrees(np.arctan2(np.mean(np.sin(d[ok])), np.mean(np.cos(d[ok])))))


def _scanned(t, dtheta_b, dv_b):
    """(t, dtheta_b, dv_b) as float64 arrays and their one-pass scan
    (:func:`insnav._imu_scan.scan_imu`), None when a value is not finite or
    the shapes are not (N,), (N, 3), (N, 3)."""
    from .._imu_scan import scan_imu

    t = np.ascontiguousarray(t, float)
    dtheta_b, dv_b = np.ascontiguousarray(dtheta_b, float), np.ascontiguousarray(dv_b, float)
    n = t.shape[0] if t.ndim == 1 else -1
    if dtheta_b.shape != (n, 3) or dv_b.shape != (n, 3):
        return t, dtheta_b, dv_b, None
    scan = scan_imu(t, dtheta_b, dv_b)
    if scan["nonfinite_t"] >= 0 or scan["nonfinite_dtheta"] >= 0 or scan["nonfinite_dv"] >= 0:
        return t, dtheta_b, dv_b, None
    return t, dtheta_b, dv_b, scan


#: fixes a GNSS check takes at a time when the fixes are in time order (:func:`check_gnss`,
#: :func:`check_gnss_velocity`): its temporaries are a few arrays of this many rows, whatever the record's length
GNSS_CHECK_BLOCK = 1 << 12


def _in_time_order(t, block: int) -> bool:
    """Whether ``t`` never decreases (NaN: not in order), judged ``block`` values at a time (no whole-record
    temporary).  Then a stable sort by time is the identity and the checks take the fixes as stored."""
    n = len(t)
    for a in range(0, n - 1, block):
        seg = t[a:min(n, a + block + 1)]
        if not bool(np.all(seg[1:] >= seg[:-1])):
            return False
    return True


def _time_order_spans(t, block: int):
    """Index arrays that take the records in time order (stable), one at a time: ``block`` consecutive
    pairs when ``t`` is already in order (neighbouring spans share a record, so every consecutive pair is
    in one span), else the whole record sorted (a copy)."""
    n = len(t)
    if not _in_time_order(t, block):
        yield np.argsort(t, kind="stable")
        return
    for a in range(0, n - 1, block):
        yield np.arange(a, min(n, a + block + 1))


def check_gnss(gnss, *, initial=None, source: str = "gnss", max_speed_mps: float = 600.0,
               min_jump_m: float = 10_000.0, max_start_distance_m: float = 20_000.0,
               block: int | None = None) -> None:
    """Ranges, the distance from the initial position, jumps and sigmas of loose fixes.

    ``gnss`` is a :class:`insnav.data.dataset.GnssFixes`; ``initial`` an optional
    object with ``lat_deg``/``lon_deg`` (the stated initial state).  The fixes are
    taken ``block`` (default :data:`GNSS_CHECK_BLOCK`) at a time: the verdicts and
    messages are those of the whole record (the first bad fix in file order, the
    counts over all fixes); fixes not in time order are sorted whole (a copy).
    """
    m = len(gnss)
    if m == 0:
        return
    block = GNSS_CHECK_BLOCK if block is None else max(1, int(block))
    lat, lon = column(gnss.lat_deg), column(gnss.lon_deg)  # a column read on demand: a block at a time

    def where(i):
        o = getattr(gnss, "origin", None)
        try:
            return f"{o.where(int(i))}" if o is not None else f"{source}: record {int(i)}"
        except Exception:  # noqa: BLE001 - a message helper must never fail
            return f"{source}: record {int(i)}"

    sig = column(gnss.sigma_pos_n)
    nonpos0 = huge0 = None  # the first fix with a sigma <= 0 / over MAX_GNSS_SIGMA_M, and their counts
    n_nonpos = n_huge = 0
    for a in range(0, m, block):  # a range error anywhere comes first: the sigmas' verdicts wait for the end
        b = min(m, a + block)
        la, lo, sg = lat[a:b], lon[a:b], sig[a:b]
        bad = np.flatnonzero(~((np.abs(la) <= 90.0) & (lo >= -180.0) & (lo <= 360.0)))
        if bad.size:
            i = a + int(bad[0])
            raise DataCheckError(f"{where(i)}: lat_deg/lon_deg = {float(lat[i])!r}, {float(lon[i])!r} out of range")
        nonpos = np.flatnonzero(~np.all(sg > 0, axis=1))
        if nonpos.size and nonpos0 is None:
            nonpos0 = a + int(nonpos[0])
        n_nonpos += nonpos.size
        huge = np.flatnonzero(~np.all(sg <= MAX_GNSS_SIGMA_M, axis=1))
        if huge.size and huge0 is None:
            huge0 = a + int(huge[0])
        n_huge += huge.size
    if n_nonpos:
        raise DataCheckError(f"{where(nonpos0)}: sigma_{{n,e,d}}_m = {sig[nonpos0].tolist()} must be > 0 "
                             f"({n_nonpos} of {m} fixes; a zero sigma would make the filter ignore the IMU)")
    if n_huge:
        raise DataCheckError(f"{where(huge0)}: sigma_{{n,e,d}}_m = {sig[huge0].tolist()}: over "
                             f"{MAX_GNSS_SIGMA_M:g} m ({n_huge} of {m} fixes; no information, and the filter's "
                             "covariance would overflow)")
    if initial is not None:
        d = _distance_m(initial.lat_deg, initial.lon_deg, lat[0], lon[0])
        if d > max_start_distance_m:
            hint = ""
            if _distance_m(initial.lat_deg, initial.lon_deg, np.degrees(lat[0]), np.degrees(lon[0])) < max_start_distance_m:
                hint = " (lat/lon look like radians)"
            elif _distance_m(initial.lat_deg, initial.lon_deg, lat[0], -lon[0]) < max_start_distance_m:
                hint = " (the longitude sign looks flipped: west is negative)"
            elif _distance_m(initial.lat_deg, initial.lon_deg, -lat[0], lon[0]) < max_start_distance_m:
                hint = " (the latitude sign looks flipped: south is negative)"
            raise DataCheckError(f"{where(0)}: the first fix ({lat[0]:.6f}, {lon[0]:.6f}) is {d / 1000:.1f} km from "
                                 f"the initial position ({initial.lat_deg:.6f}, {initial.lon_deg:.6f}){hint}")
    if m > 1:
        # in time-of-validity order (delayed records are stored in arrival order): fixes already in order are
        # taken a block of consecutive pairs at a time (the stable sort is the identity), others sorted whole
        tv = np.asarray(gnss.t_valid, float)
        for idx in _time_order_spans(tv, block):
            t, la, lo = tv[idx], lat[idx], lon[idx]
            dt = np.diff(t)
            dist = _distance_m(la[:-1], lo[:-1], la[1:], lo[1:])
            with np.errstate(divide="ignore", invalid="ignore"):
                speed = np.where(dt > 0, dist / dt, 0.0)  # fixes of the same instant: not a motion
            # unit and sign mistakes move fixes by hundreds of km; a single bad fix of
            # metres to kilometres is the innovation gate's business
            jump = np.nonzero((speed > max_speed_mps) & (dist > min_jump_m))[0]
            if jump.size:
                j = jump[0]
                i = int(idx[j + 1])
                raise DataCheckError(f"{where(i)}: a jump of {dist[j] / 1000:.3f} km in {dt[j]:.3g} s from the "
                                     f"previous fix ({speed[j]:.4g} m/s > {max_speed_mps} m/s): a sign flip, "
                                     f"mixed units or a bad fix")


#: the longest IMU -> antenna lever arm accepted [m] (a large ship or aircraft stays below it; a lever
#: arm typed in millimetres or centimetres does not)
MAX_LEVER_ARM_M = 100.0


def lever_arm_problem(lever_arm_b) -> str | None:
    """Why an IMU -> antenna lever arm [m] cannot be right (not 3 finite values, or
    longer than :data:`MAX_LEVER_ARM_M`, with the unit it looks like), or None."""
    try:
        la = np.asarray(lever_arm_b, dtype=float)
    except (TypeError, ValueError):
        return "expected 3 numbers [m]"
    if la.shape != (3,) or not np.all(np.isfinite(la)):
        return "expected 3 finite numbers [m]"
    n = float(np.linalg.norm(la))
    if n <= MAX_LEVER_ARM_M:
        return None
    units = [u for u, f in (("millimetres", 1000.0), ("centimetres", 100.0)) if n / f <= 20.0]
    unit = f" (it looks like {' or '.join(units)}: the lever arm is in metres)" if units else ""
    return f"{n:.4g} m long, implausible for an IMU -> antenna lever arm (> {MAX_LEVER_ARM_M:g} m){unit}"


def check_latlon_radians(lat, lon, *, source: str = "gnss", column: str = "lat/lon") -> None:
    """Latitudes and longitudes given as degrees that all lie within
    +-pi/2, +-pi: radians (in degrees every fix would be within 180 km of
    (0, 0), in the Gulf of Guinea).  A loader calls this only when the user
    did not state the angle unit."""
    lat, lon = np.asarray(lat, float), np.asarray(lon, float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    if ok.sum() == 0:
        return
    if np.all(np.abs(lat[ok]) <= np.pi / 2) and np.all(np.abs(lon[ok]) <= np.pi):
        raise DataCheckError(f"{source}: {column}: every fix lies within +-{np.pi / 2:.4f}, +-{np.pi:.4f} (first "
                             f"{lat[ok][0]:.6f}, {lon[ok][0]:.6f}): these look like radians, not degrees "
                             f"(in degrees: off (0, 0) in the Gulf of Guinea); state the unit: [gnss] angle_unit = "
                             f'"rad" (or "deg" if the data really are there)')


def check_gnss_velocity(gnss, *, source: str = "gnss", min_speed_mps: float = 1.0, max_dt_s: float = 2.0,
                        min_pairs: int = 10, block: int | None = None) -> tuple[float, float] | None:
    """Position differences against the reported velocity of consecutive fixes.

    The north and east slopes of ``d(position)/dt`` regressed on the mean
    reported velocity are 1 for consistent data; -1 in one axis is a flipped
    latitude / longitude sign (the velocity columns are right, the positions
    mirrored), 1/57.3 in both is radians read as degrees.  Returns the slopes
    ``(north, east)`` (NaN for an axis with too little motion), or None when
    fewer than ``min_pairs`` pairs of fixes move faster than ``min_speed_mps``
    with reported velocities.

    Fixes in time order are taken ``block`` pairs at a time (default
    :data:`GNSS_CHECK_BLOCK`; records not in time order are sorted whole, a
    copy), the regression's sums accumulated over the blocks: the slopes
    agree with one pass over the whole record to rounding, whatever the block.
    """
    m = len(gnss)
    if m < min_pairs + 1:
        return None
    block = GNSS_CHECK_BLOCK if block is None else max(1, int(block))
    tv = np.asarray(gnss.t_valid, float)
    n_ok = 0
    rr = np.zeros(2)  # sum of vr^2 per axis (north, east) [m^2/s^2]
    pr = np.zeros(2)  # sum of vp vr per axis
    for idx in _time_order_spans(tv, block):
        t = tv[idx]
        lat = np.radians(column(gnss.lat_deg)[idx])
        lon = np.radians(column(gnss.lon_deg)[idx])
        h = column(gnss.h_m)[idx]
        v = column(gnss.v_n)[idx]
        dt = np.diff(t)
        vm = 0.5 * (v[1:] + v[:-1])
        R = 6_371_000.0 + np.nan_to_num(h[:-1])
        with np.errstate(invalid="ignore", divide="ignore"):
            vp_n = np.diff(lat) * R / dt
            vp_e = np.diff(lon) * R * np.cos(lat[:-1]) / dt
        ok = ((dt > 0) & (dt <= max_dt_s) & np.all(np.isfinite(vm[:, :2]), axis=1) & np.isfinite(vp_n)
              & np.isfinite(vp_e) & (np.hypot(vm[:, 0], vm[:, 1]) > min_speed_mps))
        n_ok += int(ok.sum())
        for k, (vp, vr) in enumerate(((vp_n[ok], vm[ok, 0]), (vp_e[ok], vm[ok, 1]))):
            rr[k] += float(np.dot(vr, vr))
            pr[k] += float(np.dot(vp, vr))
    if n_ok < min_pairs:
        return None
    # too little motion along an axis (rms of the reported velocity below min_speed_mps): NaN
    slopes = [np.nan if np.sqrt(rr[k] / n_ok) < min_speed_mps else float(pr[k] / rr[k]) for k in range(2)]
    sn, se = slopes
    where = f"{source}: lat/lon against the velocity columns over {n_ok} pairs of fixes"
    deg = np.degrees(1.0)
    if all(np.isfinite(x) and 0.5 < x * deg < 2.0 for x in slopes):
        raise DataCheckError(f"{where}: the positions move {1 / np.nanmean(slopes):.1f}x slower than the velocities "
                             f"say: the lat/lon look like radians read as degrees ([gnss] angle_unit = \"rad\")")
    flipped = [name for name, x in (("latitude", sn), ("longitude", se)) if np.isfinite(x) and x < -0.5]
    if flipped:
        raise DataCheckError(f"{where}: the {' and '.join(flipped)} moves opposite to the velocity (slopes north "
                             f"{sn:.2f}, east {se:.2f}): the {' and '.join(flipped)} sign looks flipped "
                             f"(south and west are negative)")
    return sn, se


def check_time_overlap(imu_t, gnss_t, *, imu_source: str = "imu", gnss_source: str = "gnss") -> None:
    """The GNSS times fall inside the IMU's span (same time base)."""
    imu_t = np.asarray(imu_t, float)
    gnss_t = np.asarray(gnss_t, float)
    if imu_t.size == 0 or gnss_t.size == 0:
        return
    inside = (gnss_t >= imu_t[0]) & (gnss_t <= imu_t[-1])
    if not inside.any():
        off = gnss_t[0] - imu_t[0]
        hint = ""
        for name, sec in (("a GPS week", 604800.0), ("a day", 86400.0)):
            k = round(off / sec)
            if k != 0 and abs(off - k * sec) < 3600.0:
                hint = f" (they differ by about {abs(k)} x {name}: seconds of week vs of day?)"
                break
        raise DataCheckError(f"{gnss_source}: no fix inside the IMU time span: GNSS {gnss_t[0]:.3f}..{gnss_t[-1]:.3f} s, "
                             f"{imu_source} {imu_t[0]:.3f}..{imu_t[-1]:.3f} s: different time bases?{hint}")


def _distance_m(lat1, lon1, lat2, lon2):
    """Great-circle distance on the mean Earth radius [m] (degrees in)."""
    p1, p2 = np.radians(lat1), np.radians(lat2)
    dl = np.radians(np.asarray(lon2, float) - np.asarray(lon1, float))
    a = np.sin((p2 - p1) / 2) ** 2 + np.cos(p1) * np.cos(p2) * np.sin(dl / 2) ** 2
    return 2 * 6_371_000.0 * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0)))


def check_dataset(dataset, *, max_time_offset_s: float = MAX_TIME_OFFSET_S) -> None:
    """Every check above on a dataset (loose fixes, IMU, time bases, gyro vs
    course, the IMU/GNSS time offset), naming the files the data came from
    where the readers recorded them.  A tight dataset's ``gnss`` are its
    single-point fixes (:func:`insnav.io.rinex_dataset.load_rinex`) or the
    simulator's fixes, so both couplings get the same checks."""
    imu, gnss = dataset.imu, dataset.gnss
    imu_src = _source(imu, "imu")
    problem = lever_arm_problem(getattr(dataset, "lever_arm_b", np.zeros(3)))
    if problem:
        raise DataCheckError(f"{getattr(dataset, 'name', None) or 'dataset'}: lever_arm_b = "
                             f"{np.asarray(dataset.lever_arm_b).tolist()}: {problem}")
    check_imu(imu.t, imu.dtheta_b, imu.dv_b, source=imu_src)
    if len(gnss):
        gnss_src = _source(gnss, "gnss")
        check_time_overlap(imu.t, gnss.t_valid, imu_source=imu_src, gnss_source=gnss_src)
        check_gnss(gnss, initial=getattr(dataset, "initial", None), source=gnss_src)
        check_gnss_velocity(gnss, source=gnss_src)  # flipped lat/lon signs, radians read as degrees
        # the time offset first: a shifted time base also spoils the gyro-against-course slope
        check_time_offset(imu.t, imu.dtheta_b, imu.dv_b, gnss, max_offset_s=max_time_offset_s, source=imu_src,
                          gnss_source=gnss_src, fix=_time_offset_key(dataset))
        check_gyro_against_gnss(imu.t, imu.dtheta_b, imu.dv_b, gnss, source=imu_src)


def _time_offset_key(dataset) -> str | None:
    """The loader's key that shifts the IMU times, for a message."""
    if getattr(dataset, "options", None) is not None and hasattr(dataset.options, "imu_time_offset_s"):
        return "[rinex] imu_time_offset_s"
    if "tables" in (getattr(dataset, "info", None) or {}):
        return "[imu] time_offset_s"
    return None


def _source(part, default: str) -> str:
    o = getattr(part, "origin", None)
    return str(getattr(o, "source", None) or default)
