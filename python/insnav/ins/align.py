"""Initial alignment: the initial state from the data, not typed by the user.

Static coarse alignment (Groves 2013, sec. 5.6.2; Titterton & Weston 2004,
sec. 10.2):

* **Levelling** from the mean specific force over a stationary interval.  At
  rest ``f_ib_b = C_bn [0, 0, -g]``, so (FRD body, NED)::

      pitch = atan2(f_x, sqrt(f_y^2 + f_z^2)),   roll = atan2(-f_y, -f_z)

  An accelerometer bias ``b_a`` tilts the solution by ``b_a / g`` [rad]; that
  is the levelling limit whatever the averaging time.
* **Gyrocompassing** from the mean angular rate over the same interval: at
  rest ``omega_ib_b = C_bn omega_ie_n`` with ``omega_ie_n = Omega [cos L, 0,
  -sin L]``.  With ``w = C_level omega_ib_b`` (levelled, yaw not applied),
  ``yaw = atan2(-w_y, w_x)``.  The limit is ``b_g,east / (Omega cos L)``
  [rad]: 0.04 deg for a navigation-grade gyro (0.01 deg/h) at 34 deg
  latitude, 4.6 deg for a tactical one (1 deg/h), useless below that.
* **Heading from GNSS velocity** when gyrocompassing cannot work: once the
  vehicle moves faster than ``min_speed_mps``, ``yaw = atan2(v_E, v_N)``
  (course over ground: assumes the IMU's x axis along the direction of
  travel, i.e. a car without sideslip or a walker's forward direction), with
  roll and pitch carried from the levelling through the gyro increments since.
  Sigma ``|sigma_v| / speed`` plus ``slip_sigma_deg`` for the sideslip.

Position and velocity come from the GNSS fix at the alignment time (antenna
position moved to the IMU with the lever arm).  Every result carries its own
1-sigma (the "alignment's own sigmas" that become the filter's initial P).

IMU grades: :mod:`insnav.data.imu_grades`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import earth
from ..data.imu_grades import IMU_GRADES, imu_grade, imu_model_for_grade  # noqa: F401  (part of this API)
from ..units import DEG


def level(f_ib_b: np.ndarray) -> tuple[float, float]:
    """Roll and pitch [rad] from a mean specific force at rest [m/s^2] (body FRD)."""
    f = np.asarray(f_ib_b, float)
    return float(np.arctan2(-f[1], -f[2])), float(np.arctan2(f[0], np.hypot(f[1], f[2])))


def _c_level(roll: float, pitch: float) -> np.ndarray:
    """C_nb with yaw = 0: Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    return np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])


def gyrocompass(omega_ib_b: np.ndarray, roll: float, pitch: float) -> float:
    """Yaw [rad] from a mean angular rate at rest [rad/s] and the levelled attitude."""
    w = _c_level(roll, pitch) @ np.asarray(omega_ib_b, float)
    return float(np.arctan2(-w[1], w[0]))


def gyrocompass_sigma(gyro_bias_sigma: float, gyro_arw: float, static_s: float, lat_rad: float) -> float:
    """1-sigma of the gyrocompass yaw [rad]: ``sqrt(b_g^2 + ARW^2 / T) / (Omega cos L)``."""
    rate_sigma = np.hypot(gyro_bias_sigma, gyro_arw / np.sqrt(max(static_s, 1e-9)))
    return float(rate_sigma / (earth.OMEGA_IE * max(np.cos(lat_rad), 1e-6)))


def static_interval(t: np.ndarray, dtheta_b: np.ndarray, dv_b: np.ndarray, *, window_s: float = 0.5,
                    sigma_f_mps2: float = 0.05, sigma_w_radps: float = 5e-3, gamma: float = 18.0,
                    max_f_change_mps2: float = 0.03, t_moving: float = np.inf) -> tuple[int, int]:
    """The stationary stretch at the start: sample indices ``[0, k)``.

    Consecutive windows of ``window_s`` are stationary while (a) the SHOE
    statistic (Skog et al. 2010, eq. (10); the C++ detector
    ``ins/standstill.hpp`` is the same test)
    ``T = mean(|f - g f_mean/|f_mean||^2 / sigma_f^2 + |omega|^2 / sigma_w^2)``
    stays below ``gamma``, and (b) the window's mean specific force stays
    within ``max_f_change_mps2`` of the first window's: a smooth straight-line
    acceleration looks like a tilt to (a) alone, never like the *same* tilt.
    ``t_moving`` (e.g. the first GNSS fix faster than its noise) ends the
    interval too.  Returns ``(0, k)``, ``k = 0`` if the data start moving.
    """
    return 0, _static_interval(t, dtheta_b, dv_b, window_s=window_s, sigma_f_mps2=sigma_f_mps2,
                               sigma_w_radps=sigma_w_radps, gamma=gamma, max_f_change_mps2=max_f_change_mps2,
                               t_moving=t_moving)[0]


def _static_interval(t, dtheta_b, dv_b, *, window_s: float = 0.5, sigma_f_mps2: float = 0.05,
                     sigma_w_radps: float = 5e-3, gamma: float = 18.0, max_f_change_mps2: float = 0.03,
                     t_moving: float = np.inf) -> tuple[int, int]:
    """:func:`static_interval`'s ``k`` and how many leading samples it read (``len(t)``: it ran out)."""
    dt = np.diff(np.concatenate([[t[0] - (t[1] - t[0])], t]))
    f = dv_b / dt[:, None]
    w = dtheta_b / dt[:, None]
    n = max(2, int(round(window_s / np.median(dt))))
    if len(t) < n:
        return 0, len(t)
    f_ref = f[:n].mean(axis=0)
    g = np.linalg.norm(f_ref)
    k = 0
    while k + n <= len(t) and t[k + n - 1] < t_moving:
        fw, ww = f[k:k + n], w[k:k + n]
        fm = fw.mean(axis=0)
        dirn = fm / max(np.linalg.norm(fm), 1e-12)
        T = np.mean(np.sum((fw - g * dirn) ** 2, axis=1) / sigma_f_mps2 ** 2 + np.sum(ww ** 2, axis=1) / sigma_w_radps ** 2)
        if not (T < gamma and np.linalg.norm(fm - f_ref) < max_f_change_mps2):
            break
        k += n
    # the last stationary window may already hold the onset of motion: drop it
    return max(0, k - n), min(k + n, len(t))


@dataclass
class Alignment:
    """An initial state with its 1-sigma (SI inside, degrees in the names).

    Attributes
    ----------
    t_s : float
        Time of the aligned state [s] (the end of an IMU sample).
    index : int
        Index of that IMU sample (the filter starts after it).
    lat_deg, lon_deg, h_m : float
        IMU position.
    v_n_mps : ndarray (3,)
    roll_deg, pitch_deg, yaw_deg : float
    sigma_pos_n_m, sigma_vel_n_mps, sigma_att_deg : ndarray (3,)
        The alignment's own 1-sigma (the filter's initial P).
    heading_source : str
        ``"gyrocompass"`` or ``"gnss_velocity"``.
    static_s : float
        Length of the stationary interval used for levelling [s].
    samples_used : int
        How many leading IMU samples the alignment read: any longer record
        with the same first samples and the same median interval aligns the
        same (``len(t)``: it may have needed more; the block-by-block run,
        :mod:`insnav.filters.stream`, aligns on the record's first blocks).
    """

    t_s: float
    index: int
    lat_deg: float
    lon_deg: float
    h_m: float
    v_n_mps: np.ndarray
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    sigma_pos_n_m: np.ndarray
    sigma_vel_n_mps: np.ndarray
    sigma_att_deg: np.ndarray
    heading_source: str
    static_s: float
    notes: list[str] = field(default_factory=list)
    samples_used: int = 0


def _rot(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    a = float(np.linalg.norm(phi))
    K = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    if a < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(a) / a * K + (1 - np.cos(a)) / a ** 2 * K @ K


def _euler(C: np.ndarray) -> tuple[float, float, float]:
    return (float(np.arctan2(C[2, 1], C[2, 2])), float(-np.arcsin(np.clip(C[2, 0], -1, 1))),
            float(np.arctan2(C[1, 0], C[0, 0])))


def align(t, dtheta_b, dv_b, gnss, *, gyro_bias_sigma: float, gyro_arw: float, accel_bias_sigma: float,
          lever_arm_b=(0.0, 0.0, 0.0), min_speed_mps: float = 3.0, max_gyrocompass_sigma_deg: float = 5.0,
          slip_sigma_deg: float = 0.5, max_heading_sigma_deg: float = 1.5, source: str = "imu",
          accel_vrw: float | None = None, course_window_s: float = 1.0) -> Alignment:
    """Align from the data: level on the static start, gyrocompass if the gyro
    grade allows it, otherwise take the heading from GNSS velocity once moving.

    Parameters
    ----------
    t, dtheta_b, dv_b : ndarray
        IMU sample times [s] and increments over ``(t[k-1], t[k]]`` [rad], [m/s].
    gnss : insnav.data.dataset.GnssFixes
        Fixes (``t_valid``, antenna position, velocity and sigmas).
    gyro_bias_sigma, gyro_arw, accel_bias_sigma : float
        The IMU's error figures (SI; e.g. from :data:`IMU_GRADES`).
    lever_arm_b : array_like
        IMU -> antenna, body FRD [m].
    min_speed_mps : float
        Lowest speed at which the GNSS course may become the heading.
    max_heading_sigma_deg : float
        The first fix whose course sigma ``hypot(sigma_v / speed, slip)`` is
        below this gives the heading (faster fixes give better courses).
    max_gyrocompass_sigma_deg : float
        Gyrocompass only when its 1-sigma is below this.
    slip_sigma_deg : float
        Sideslip allowance added to the GNSS-course heading sigma.
    source : str
        Name used in error messages (the IMU file).
    course_window_s : float
        The heading is the weighted circular mean of the GNSS courses of the
        fixes over this window [s] (ending at the first good fix), each
        carried to that fix by the gyro heading change since: the course
        noise averages down as 1/sqrt(n) (sideslip does not).
    accel_vrw : float, optional
        Accelerometer white noise [(m/s)/sqrt(s)]: the standstill detector's
        per-sample specific-force noise becomes ``max(0.05, 1.5 VRW sqrt(rate))``
        [m/s^2] and its rate noise ``max(5e-3, 1.5 hypot(ARW sqrt(rate), b_g))``
        [rad/s] (a consumer IMU at 200 Hz is noisier than the defaults).

    Returns
    -------
    Alignment

    Raises
    ------
    ValueError
        No stationary start and no GNSS fix faster than ``min_speed_mps``; no
        GNSS fix at all.
    """
    t = np.asarray(t, float)
    dtheta_b = np.asarray(dtheta_b, float)
    dv_b = np.asarray(dv_b, float)
    if len(gnss) == 0:
        raise ValueError(f"{source}: alignment needs GNSS fixes for the initial position (none given)")
    ant_speed = np.linalg.norm(gnss.v_n[:, :2], axis=1)
    sv = np.where(np.isfinite(gnss.sigma_vel_n[:, 0]), gnss.sigma_vel_n[:, 0], 0.1)
    fast = np.nonzero(np.isfinite(ant_speed) & (ant_speed > 5 * sv + 0.1))[0]  # 5 sigma: no false start in hours of fixes
    t_moving = float(gnss.t_valid[fast[0]]) if fast.size else np.inf
    kw = {}
    if accel_vrw is not None and len(t) > 1:
        rate = 1.0 / float(np.median(np.diff(t)))
        kw = dict(sigma_f_mps2=max(0.05, 1.5 * accel_vrw * np.sqrt(rate)),
                  sigma_w_radps=max(5e-3, 1.5 * float(np.hypot(gyro_arw * np.sqrt(rate), gyro_bias_sigma))),
                  # the mean of a 0.5 s window wanders by ~VRW sqrt(2 / 0.5 s) per axis
                  max_f_change_mps2=max(0.03, 5.0 * accel_vrw * np.sqrt(2.0 / 0.5)))
    k_static, used = _static_interval(t, dtheta_b, dv_b, t_moving=t_moving, **kw)
    dt = np.diff(np.concatenate([[2 * t[0] - t[1]], t]))
    notes: list[str] = []
    static_s = float(t[k_static - 1] - t[0] + dt[0]) if k_static > 0 else 0.0
    lat0 = np.radians(np.nanmedian(gnss.lat_deg[: min(len(gnss), 10)]))
    if k_static > 0:
        T = dt[:k_static].sum()
        f_mean = dv_b[:k_static].sum(axis=0) / T
        w_mean = dtheta_b[:k_static].sum(axis=0) / T
        roll, pitch = level(f_mean)
        sig_level = accel_bias_sigma / earth.gravity(lat0, 0.0)
        yaw_sig = gyrocompass_sigma(gyro_bias_sigma, gyro_arw, static_s, lat0)
    else:
        roll = pitch = 0.0
        sig_level = np.inf
        yaw_sig = np.inf
        notes.append("no stationary start: levelling from the mean specific force of the first second")
        n1 = max(2, int(round(1.0 / np.median(dt))))
        roll, pitch = level(dv_b[:n1].sum(axis=0) / dt[:n1].sum())
        sig_level = 2 * DEG
        used = max(used, min(n1, len(t)))
    if k_static > 0 and yaw_sig < max_gyrocompass_sigma_deg * DEG:
        yaw = gyrocompass(w_mean, roll, pitch)
        idx = k_static - 1
        C_nb = _euler_to_dcm(roll, pitch, yaw)
        att_sig = np.array([sig_level, sig_level, yaw_sig])
        heading_source = "gyrocompass"
    else:
        t_start = t[k_static - 1] if k_static > 0 else t[0]
        sv_all = np.nanmax(np.where(np.isfinite(gnss.sigma_vel_n[:, :2]), gnss.sigma_vel_n[:, :2], 0.1), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            course_sig = np.hypot(sv_all / ant_speed, slip_sigma_deg * DEG)
        ok = (gnss.t_valid >= t_start) & (ant_speed >= min_speed_mps) & np.isfinite(ant_speed)
        moving = np.nonzero(ok & (course_sig <= max_heading_sigma_deg * DEG))[0]
        if moving.size == 0:
            moving = np.nonzero(ok)[0][np.argsort(course_sig[ok], kind="stable")][:1]
            if moving.size:
                notes.append(f"no GNSS course better than {max_heading_sigma_deg} deg: used the best one")
        if moving.size == 0:
            raise ValueError(f"{source}: cannot align the heading: gyrocompassing 1-sigma "
                             f"{np.degrees(yaw_sig):.1f} deg > {max_gyrocompass_sigma_deg} deg for this gyro, "
                             f"and no GNSS fix reaches {min_speed_mps} m/s")
        g = int(moving[0])
        idx = int(np.clip(np.searchsorted(t, gnss.t_valid[g]), 0, len(t) - 1))
        used = len(t) if t[-1] < gnss.t_valid[g] else max(used, idx + 1)
        # carry the levelled attitude through the gyro increments to t[idx], keeping its yaw
        C = _c_level(roll, pitch)
        k_from = max(k_static, 0)
        i_win = int(np.searchsorted(t, gnss.t_valid[g] - course_window_s))
        yaw_rel = {}
        for k in range(k_from, idx + 1):
            C = C @ _rot(dtheta_b[k])
            if k >= i_win:
                yaw_rel[k] = _euler(C)[2]
        r, p, y_rel = _euler(C)
        # the courses of the fixes over the last course_window_s, each carried to t[idx] by
        # the gyro's heading change since, weighted by 1/sigma^2 (a circular mean)
        sv_g = np.where(np.all(np.isfinite(gnss.sigma_vel_n[:, :2]), axis=1),
                        np.nanmax(np.nan_to_num(gnss.sigma_vel_n[:, :2], nan=0.1), axis=1), 0.1)
        win = np.flatnonzero((gnss.t_valid > gnss.t_valid[g] - course_window_s) & (gnss.t_valid <= gnss.t_valid[g])
                             & ok)
        sw = cw = wsum = 0.0
        for j in win:
            kj = int(np.clip(np.searchsorted(t, gnss.t_valid[j]), k_from, idx))
            dpsi = y_rel - yaw_rel.get(kj, y_rel)
            est = float(np.arctan2(gnss.v_n[j, 1], gnss.v_n[j, 0])) + dpsi
            w = (ant_speed[j] / sv_g[j]) ** 2
            sw, cw, wsum = sw + w * np.sin(est), cw + w * np.cos(est), wsum + w
        course = float(np.arctan2(sw, cw))
        roll, pitch, yaw = r, p, course
        C_nb = _euler_to_dcm(roll, pitch, yaw)
        carried = gyro_bias_sigma * float(t[idx] - (t[k_static - 1] if k_static > 0 else t[0]))
        yaw_sig = float(np.hypot(1.0 / np.sqrt(wsum), slip_sigma_deg * DEG))
        att_sig = np.array([np.hypot(sig_level, carried), np.hypot(sig_level, carried), yaw_sig])
        notes.append(f"heading: course of {win.size} fixes over {course_window_s:g} s")
        heading_source = "gnss_velocity"
    # position / velocity from the GNSS fix nearest the alignment time, antenna -> IMU
    t_a = float(t[idx])
    g = int(np.argmin(np.abs(gnss.t_valid - t_a)))
    if abs(gnss.t_valid[g] - t_a) > 1.5:
        notes.append(f"nearest GNSS fix is {gnss.t_valid[g] - t_a:+.2f} s from the alignment time")
    lat, lon, h = np.radians(gnss.lat_deg[g]), np.radians(gnss.lon_deg[g]), float(gnss.h_m[g])
    l_n = C_nb @ np.asarray(lever_arm_b, float)
    R_M, R_N = earth.radii(lat)
    lat_i = lat - l_n[0] / (R_M + h)
    lon_i = lon - l_n[1] / ((R_N + h) * np.cos(lat))
    h_i = h + l_n[2]
    v = np.array(gnss.v_n[g], float)
    v_sig = np.array(gnss.sigma_vel_n[g], float)
    if not np.all(np.isfinite(v)):
        v = np.zeros(3) if heading_source == "gyrocompass" else np.nan_to_num(v)
        v_sig = np.full(3, 0.1 if heading_source == "gyrocompass" else 1.0)
        notes.append("the GNSS fix has no velocity: " + ("zero velocity at rest" if heading_source == "gyrocompass"
                                                         else "velocity taken as 0 +- 1 m/s"))
    elif heading_source == "gyrocompass":
        v = np.zeros(3)  # at rest by detection
        v_sig = np.full(3, 0.01)
    return Alignment(t_s=t_a, index=idx, lat_deg=float(np.degrees(lat_i)), lon_deg=float(np.degrees(lon_i)),
                     h_m=float(h_i), v_n_mps=v, roll_deg=float(np.degrees(roll)), pitch_deg=float(np.degrees(pitch)),
                     yaw_deg=float(np.degrees(yaw)), sigma_pos_n_m=np.array(gnss.sigma_pos_n[g], float),
                     sigma_vel_n_mps=v_sig, sigma_att_deg=np.degrees(att_sig), heading_source=heading_source,
                     static_s=static_s, notes=notes, samples_used=int(used))


def _euler_to_dcm(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ _c_level(roll, pitch)
