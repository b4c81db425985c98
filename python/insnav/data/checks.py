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

import numpy as np

from .._median import median
from ..units import DEG, G0


class DataCheckError(ValueError):
    """Input that cannot be right (units, signs, time bases)."""


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
                             f"are read as FRD ({fixes.get('axes', 'map the axes in the input settings')})")
    if wm > 1.0:
        hint = ""
        if wm * DEG < 1.0:
            hint = " (the increments look like degrees, not radians" + fix("gyro_deg") + ")"
        elif wm * dtm < 1.0:
            hint = " (dtheta looks like an angular rate in rad/s, not an increment in rad" + fix("dtheta_rate") + ")"
        raise DataCheckError(f"{source}: {gyro_label}: median |omega| = {wm:.4g} rad/s ({np.degrees(wm):.4g} deg/s) "
                             f"over {n} samples, implausible for a vehicle{hint}")


def check_gyro_against_gnss(t, dtheta_b, dv_b, gnss, *, source: str = "imu", min_speed_mps: float = 3.0,
                            min_turn_deg: float = 45.0, gyro_label: str = "dtheta_*",
                            fixes: dict | None = None) -> float | None:
    """Slope of the gyro heading change on the GNSS course change (1 when right).

    Returns the slope, or None when the run turns less than ``min_turn_deg``
    at speed (nothing to compare).  Raises :class:`DataCheckError` when the
    slope says degrees (> 10) or an inverted vertical axis (< -0.5), or is
    otherwise far from 1 (outside 0.5..2).
    """
    t, dtheta_b, dv_b, scan = _scanned(t, dtheta_b, dv_b)
    gt = np.asarray(gnss.t_valid, float)
    if t.size < 3 or gt.size < 3 or scan is None or not np.isfinite(gt).all():
        return None
    v = np.asarray(gnss.v_n, float)
    speed = np.hypot(v[:, 0], v[:, 1])
    course = np.arctan2(v[:, 1], v[:, 0])
    f = np.array(scan["dv_sum"])  # sum of dv_b over the samples
    down_b = -f / max(np.linalg.norm(f), 1e-12)  # the mean specific force points up
    # ~1 s intervals (the course of a 10 Hz receiver is noisy fix to fix)
    step = max(1, int(round(1.0 / max(median(np.diff(gt)), 1e-3))))
    sel = np.arange(0, gt.size, step)
    gt, v, speed, course = gt[sel], v[sel], speed[sel], course[sel]
    # the heading the gyros integrate about the vertical, at the fixes: np.interp(gt, [t[0] - (t[1] - t[0]), t],
    # [0, cumsum(dtheta_b @ down_b)], left=nan, right=nan) in one compiled pass, no (N,) temporaries
    from .. import _core

    g_at = _core.rotation_about_at(t, dtheta_b, down_b, gt)
    fast = (speed[:-1] > min_speed_mps) & (speed[1:] > min_speed_mps) & np.all(np.isfinite(v[:, :2]), axis=1)[1:] \
        & np.isfinite(g_at[:-1]) & np.isfinite(g_at[1:]) & (np.diff(gt) < 5.0 * step * 0.1 + 2.0)
    dc = (np.diff(course) + np.pi) % (2 * np.pi) - np.pi
    dg = np.diff(g_at)
    dc, dg = dc[fast], dg[fast]
    # evidence: the turning the gyros saw (low noise; the course of a noisy or slow
    # receiver adds up to many degrees even on a straight line)
    if np.sum(np.abs(dg)) < np.radians(min_turn_deg) or dg.size < 5:
        return None
    # the course is the noisy one: regress it on the gyro, slope = 1 / (d course / d gyro)
    inv = float(np.dot(dg, dc) / np.dot(dg, dg))
    res = dc - inv * dg
    se = float(np.sqrt(np.dot(res, res) / max(dg.size - 1, 1) / np.dot(dg, dg)))
    if abs(inv - 1.0) < 5.0 * se:  # consistent with 1 (or too noisy to say otherwise)
        return 1.0 / inv if inv != 0 else np.inf
    slope = 1.0 / inv if inv != 0 else np.inf
    fixes = fixes or {}
    if slope > 10.0 and 0.5 < slope / np.degrees(1.0) < 2.0:
        raise DataCheckError(f"{source}: {gyro_label}: the gyros turn {slope:.1f}x the GNSS course over "
                             f"{np.degrees(np.sum(np.abs(dc))):.0f} deg of turns: the increments look like degrees, "
                             f"not radians" + (f"; {fixes['gyro_deg']}" if "gyro_deg" in fixes else ""))
    if slope < -0.5:
        raise DataCheckError(f"{source}: {gyro_label}: the gyros turn opposite to the GNSS course (slope "
                             f"{slope:.2f}): the gyro axes look inverted relative to the accelerometers'"
                             + (f", {fixes['inverted']}" if "inverted" in fixes else ""))
    if not 0.5 < slope < 2.0:
        raise DataCheckError(f"{source}: {gyro_label}: the gyro heading change is {slope:.2f}x the GNSS course change "
                             f"over {np.degrees(np.sum(np.abs(dc))):.0f} deg of turns (expected 1): wrong units, "
                             f"scale or axes")
    return slope


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


def check_gnss(gnss, *, initial=None, source: str = "gnss", max_speed_mps: float = 600.0,
               min_jump_m: float = 10_000.0, max_start_distance_m: float = 20_000.0) -> None:
    """Ranges, the distance from the initial position, jumps and sigmas of loose fixes.

    ``gnss`` is a :class:`insnav.data.dataset.GnssFixes`; ``initial`` an optional
    object with ``lat_deg``/``lon_deg`` (the stated initial state).
    """
    m = len(gnss)
    if m == 0:
        return
    lat, lon = np.asarray(gnss.lat_deg, float), np.asarray(gnss.lon_deg, float)

    def where(i):
        o = getattr(gnss, "origin", None)
        try:
            return f"{o.where(int(i))}" if o is not None else f"{source}: record {int(i)}"
        except Exception:  # noqa: BLE001 - a message helper must never fail
            return f"{source}: record {int(i)}"

    bad = np.nonzero(~((np.abs(lat) <= 90.0) & (lon >= -180.0) & (lon <= 360.0)))[0]
    if bad.size:
        raise DataCheckError(f"{where(bad[0])}: lat_deg/lon_deg = {lat[bad[0]]!r}, {lon[bad[0]]!r} out of range")
    sig = np.asarray(gnss.sigma_pos_n, float)
    nonpos = np.nonzero(~np.all(sig > 0, axis=1))[0]
    if nonpos.size:
        raise DataCheckError(f"{where(nonpos[0])}: sigma_{{n,e,d}}_m = {sig[nonpos[0]].tolist()} must be > 0 "
                             f"({nonpos.size} of {m} fixes; a zero sigma would make the filter ignore the IMU)")
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
        # in time-of-validity order (delayed records are stored in arrival order)
        order = np.argsort(np.asarray(gnss.t_valid, float), kind="stable")
        t = np.asarray(gnss.t_valid, float)[order]
        la, lo = lat[order], lon[order]
        dt = np.diff(t)
        dist = _distance_m(la[:-1], lo[:-1], la[1:], lo[1:])
        with np.errstate(divide="ignore", invalid="ignore"):
            speed = np.where(dt > 0, dist / dt, 0.0)  # fixes of the same instant: not a motion
        # unit and sign mistakes move fixes by hundreds of km; a single bad fix of
        # metres to kilometres is the innovation gate's business
        jump = np.nonzero((speed > max_speed_mps) & (dist > min_jump_m))[0]
        if jump.size:
            j = jump[0]
            i = int(order[j + 1])
            raise DataCheckError(f"{where(i)}: a jump of {dist[j] / 1000:.3f} km in {dt[j]:.3g} s from the "
                                 f"previous fix ({speed[j]:.4g} m/s > {max_speed_mps} m/s): a sign flip, "
                                 f"mixed units or a bad fix")


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
                        min_pairs: int = 10) -> tuple[float, float] | None:
    """Position differences against the reported velocity of consecutive fixes.

    The north and east slopes of ``d(position)/dt`` regressed on the mean
    reported velocity are 1 for consistent data; -1 in one axis is a flipped
    latitude / longitude sign (the velocity columns are right, the positions
    mirrored), 1/57.3 in both is radians read as degrees.  Returns the slopes
    ``(north, east)`` (NaN for an axis with too little motion), or None when
    fewer than ``min_pairs`` pairs of fixes move faster than ``min_speed_mps``
    with reported velocities.
    """
    m = len(gnss)
    if m < min_pairs + 1:
        return None
    order = np.argsort(np.asarray(gnss.t_valid, float), kind="stable")
    t = np.asarray(gnss.t_valid, float)[order]
    lat = np.radians(np.asarray(gnss.lat_deg, float)[order])
    lon = np.radians(np.asarray(gnss.lon_deg, float)[order])
    h = np.asarray(gnss.h_m, float)[order]
    v = np.asarray(gnss.v_n, float)[order]
    dt = np.diff(t)
    vm = 0.5 * (v[1:] + v[:-1])
    R = 6_371_000.0 + np.nan_to_num(h[:-1])
    with np.errstate(invalid="ignore", divide="ignore"):
        vp_n = np.diff(lat) * R / dt
        vp_e = np.diff(lon) * R * np.cos(lat[:-1]) / dt
    ok = ((dt > 0) & (dt <= max_dt_s) & np.all(np.isfinite(vm[:, :2]), axis=1) & np.isfinite(vp_n)
          & np.isfinite(vp_e) & (np.hypot(vm[:, 0], vm[:, 1]) > min_speed_mps))
    if ok.sum() < min_pairs:
        return None
    slopes = []
    for vp, vr in ((vp_n[ok], vm[ok, 0]), (vp_e[ok], vm[ok, 1])):
        if np.sqrt(np.mean(vr ** 2)) < min_speed_mps:  # too little motion along this axis
            slopes.append(np.nan)
        else:
            slopes.append(float(np.dot(vp, vr) / np.dot(vr, vr)))
    sn, se = slopes
    where = f"{source}: lat/lon against the velocity columns over {int(ok.sum())} pairs of fixes"
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


def check_dataset(dataset) -> None:
    """Every check above on a dataset (loose fixes, IMU, time bases, gyro vs
    course), naming the files the data came from where the readers recorded them."""
    imu, gnss = dataset.imu, dataset.gnss
    imu_src = _source(imu, "imu")
    check_imu(imu.t, imu.dtheta_b, imu.dv_b, source=imu_src)
    if len(gnss):
        gnss_src = _source(gnss, "gnss")
        check_time_overlap(imu.t, gnss.t_valid, imu_source=imu_src, gnss_source=gnss_src)
        check_gnss(gnss, initial=getattr(dataset, "initial", None), source=gnss_src)
        check_gnss_velocity(gnss, source=gnss_src)  # flipped lat/lon signs, radians read as degrees
        check_gyro_against_gnss(imu.t, imu.dtheta_b, imu.dv_b, gnss, source=imu_src)


def _source(part, default: str) -> str:
    o = getattr(part, "origin", None)
    return str(getattr(o, "source", None) or default)
