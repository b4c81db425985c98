"""IMU increments synthesised from a sampled truth trajectory file.

Hardware GNSS simulators (Spirent SimGEN, ...) record the vehicle motion they
simulated, typically at 10 Hz, but no IMU.  This module turns such a truth file
into a continuous trajectory with a documented interpolation and integrates
the exact IMU increments from it (plus the errors of a named IMU grade), so
that the IMU is consistent with the GNSS observations the simulator produced
for the same motion.

Interpolation (between two truth epochs ``t_k``, ``t_k+1 = t_k + h``):

* **Position**: a quintic Hermite polynomial in ECEF per interval matching the
  recorded position, velocity *and* acceleration at both ends (C2 across
  knots; the recorded positions are reproduced exactly).  Its derivatives give
  the velocity and the kinematic acceleration ``r_e''``.
* **Attitude**: a C2 cubic spline ("not-a-knot") through the recorded 3-2-1
  Euler angles (roll = bank, pitch = elevation, yaw = heading, roll and yaw
  unwrapped: a bank through +-pi is a turn, not a jump); the Euler rates are its
  derivative.

Sensor outputs (Groves 2013, eqs. (5.44) and (5.19); gravity = the normal
gravity of the mechanization, ``insnav.earth.gravity``):

    f_ib_b     = C_bn [C_ne (r_e'' + 2 omega_ie x v_e) - (0, 0, g(lat, h))]
    omega_ib_b = omega_nb_b(Euler, Euler rates) + C_bn (omega_ie_n + omega_en_n)

integrated over each IMU interval by Gauss-Legendre quadrature (3 nodes), as
:meth:`insnav.sim.trajectory.Trajectory.imu_increments` does for the analytic
scenarios; the IMU-grade errors are those of :mod:`insnav.sim.imu`.

Files read: the Spirent SimGEN motion file (``Time_ms,Pos_X,...``, header
line 1 ending with the GPS time of ``Time_ms = 0`` in seconds since
1980-01-06, as INSTINCT's test data carry it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import earth
from ..data.dataset import Dataset, GnssFixes, ImuData, ImuErrors, Truth
from ..units import wrap_deg
from .trajectory import _cross, euler_rate_to_omega_nb_b, rotate_n_to_b

__all__ = ["TruthFile", "TruthInterpolant", "read_spirent_motion", "sensor_errors_for_grade",
           "simulate_from_truth"]

_SPIRENT_COLS = ("Time_ms", "Pos_X", "Pos_Y", "Pos_Z", "Vel_X", "Vel_Y", "Vel_Z", "Acc_X", "Acc_Y", "Acc_Z")


class TruthFileError(ValueError):
    """A truth file that cannot be used (message names the file and line)."""


@dataclass
class TruthFile:
    """A sampled truth trajectory (SI): ``t_s`` (N,) [s], ``r_e``, ``v_e``, ``a_e`` (N, 3) ECEF
    [m, m/s, m/s^2], ``euler_rad`` (N, 3) roll, pitch, yaw [rad] (roll and yaw unwrapped), ``lever_arm_b``
    (3,) antenna relative to the motion point, body FRD [m]; ``gps_time_offset_s``: GPS time of
    ``t = 0`` [s since 1980-01-06] (NaN when the file does not say)."""

    path: str
    t_s: np.ndarray
    r_e: np.ndarray
    v_e: np.ndarray
    a_e: np.ndarray
    euler_rad: np.ndarray
    lever_arm_b: np.ndarray
    gps_time_offset_s: float


def read_spirent_motion(path) -> TruthFile:
    """Read a Spirent SimGEN motion file (``Time_ms,Pos_X,...,Heading,Elevation,Bank,...``).

    Raises
    ------
    TruthFileError
        Missing columns, non-numeric or non-finite values (in the columns read), times not strictly
        increasing (naming the line).
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="ascii", errors="replace").splitlines()
    except OSError as exc:
        raise TruthFileError(f"{path}: cannot read truth file ({exc.strerror})") from None
    hdr_i = next((i for i, ln in enumerate(lines[:10]) if ln.startswith("Time_ms")), None)
    if hdr_i is None:
        raise TruthFileError(f"{path}: not a Spirent motion file (no 'Time_ms,Pos_X,...' header line "
                             "in the first 10 lines)")
    names = [c.strip() for c in lines[hdr_i].split(",")]
    need = _SPIRENT_COLS + ("Heading", "Elevation", "Bank")
    missing = [c for c in need if c not in names]
    if missing:
        raise TruthFileError(f"{path}, line {hdr_i + 1}: missing column(s) {', '.join(missing)}")
    offset = math.nan
    if hdr_i > 0:
        try:
            offset = float(lines[0].split(",")[-1])
        except ValueError:
            offset = math.nan
    rows, line_no = [], []
    for j, ln in enumerate(lines[hdr_i + 1:], start=hdr_i + 2):
        if not ln.strip():
            continue
        line_no.append(j)
        try:
            rows.append([float(v) for v in ln.split(",")])
        except ValueError:
            raise TruthFileError(f"{path}, line {j}: non-numeric value") from None
        if len(rows[-1]) != len(names):
            raise TruthFileError(f"{path}, line {j}: {len(rows[-1])} values, header has {len(names)}")
    if len(rows) < 4:
        raise TruthFileError(f"{path}: fewer than 4 truth epochs")
    d = np.asarray(rows)
    used = [names.index(n) for n in need + ("Ant1_Pos_X", "Ant1_Pos_Y", "Ant1_Pos_Z") if n in names]
    bad = np.argwhere(~np.isfinite(d[:, used]))
    if bad.size:  # float() reads 'nan' and 'inf': a NaN would run through the synthesis into every IMU sample
        i, k = bad[0]
        raise TruthFileError(f"{path}, line {line_no[i]}: non-finite value {float(d[i, used[k]])!r} in column "
                             f"'{names[used[k]]}'")
    col = {n: d[:, names.index(n)] for n in names}
    t = col["Time_ms"] / 1e3
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise TruthFileError(f"{path}, line {line_no[bad[0] + 1]}: time not strictly increasing")
    xyz = lambda p: np.column_stack([col[p + "_X"], col[p + "_Y"], col[p + "_Z"]])  # noqa: E731
    euler = np.column_stack([np.unwrap(col["Bank"]), col["Elevation"], np.unwrap(col["Heading"])])
    r_e = xyz("Pos")
    _check_plausible(path, r_e, xyz("Vel"), xyz("Acc"), euler, t, line_no)
    lever = np.zeros(3)
    if "Ant1_Pos_X" in col:
        d_e = xyz("Ant1_Pos") - r_e
        lat, lon, _ = earth.ecef_to_geodetic(r_e[0])
        lever = rotate_n_to_b(euler[:1], (earth.C_en(lat, lon).T @ d_e[0])[None, :])[0]
    return TruthFile(str(path), t, r_e, xyz("Vel"), xyz("Acc"), euler, lever, offset)


#: radius of a truth position [m]: below the deepest ocean floor to beyond geostationary orbit
_RADIUS_M = (6.3e6, 1e8)
#: the position step of an interval must match the recorded velocity and acceleration
#: (the quintic Hermite's own relation, below) within this, plus 1 % of the step [m]
_STEP_TOL_M = 1.0
#: ... and the velocity step the recorded acceleration (trapezoid) within this plus 1 % [m/s]
_VEL_TOL_MPS = 1.0
#: largest attitude rate between two epochs [rad/s] (1146 deg/s: above any vehicle's)
_MAX_EULER_RATE = 20.0


def _check_plausible(path, r_e, v_e, a_e, euler, t, line_no) -> None:
    """Refuse a truth file the synthesis would turn into absurd IMU increments, naming the line.

    A corrupted row is finite yet impossible: a position off the Earth, a position or velocity
    step the recorded velocity and acceleration cannot produce, a pitch (Elevation) beyond
    +-90 deg, an attitude that jumps.  Over an interval h the quintic Hermite through
    (r, v, a) at both ends satisfies r1 - r0 = h (v0 + v1) / 2 + h^2 (a0 - a1) / 12 exactly when
    the motion's jerk is constant; a real file matches to a fraction of a millimetre (0.27 mm on
    the Spirent dynamic rover).
    """
    def fail(i, what):
        raise TruthFileError(f"{path}, line {line_no[i]}: {what}: a corrupted row?")

    radius = np.linalg.norm(r_e, axis=1)
    bad = np.flatnonzero((radius < _RADIUS_M[0]) | (radius > _RADIUS_M[1]))
    if bad.size:
        fail(bad[0], f"position {radius[bad[0]]:.6g} m from the Earth's centre (Pos_X, Pos_Y, Pos_Z)")
    h = np.diff(t)[:, None]
    dr = np.diff(r_e, axis=0)
    res = np.linalg.norm(dr - h * (v_e[:-1] + v_e[1:]) / 2 - h ** 2 * (a_e[:-1] - a_e[1:]) / 12, axis=1)
    bad = np.flatnonzero(res > _STEP_TOL_M + 0.01 * np.linalg.norm(dr, axis=1))
    if bad.size:
        fail(bad[0] + 1, f"the position step from the line before differs by {res[bad[0]]:.4g} m from the one "
                         "its velocity and acceleration give")
    dv = np.diff(v_e, axis=0)
    res = np.linalg.norm(dv - h * (a_e[:-1] + a_e[1:]) / 2, axis=1)
    bad = np.flatnonzero(res > _VEL_TOL_MPS + 0.01 * np.linalg.norm(dv, axis=1))
    if bad.size:
        fail(bad[0] + 1, f"the velocity step from the line before differs by {res[bad[0]]:.4g} m/s from the "
                         "one its acceleration gives")
    bad = np.flatnonzero(np.abs(euler[:, 1]) > np.pi / 2 + 1e-9)
    if bad.size:
        fail(bad[0], f"Elevation {euler[bad[0], 1]:.6g} rad beyond +-pi/2")
    rate = np.abs((np.diff(euler, axis=0) + np.pi) % (2 * np.pi) - np.pi) / h  # a bank through +-pi is no jump
    bad = np.flatnonzero(rate.max(axis=1) > _MAX_EULER_RATE)
    if bad.size:
        k = int(np.argmax(rate[bad[0]]))
        fail(bad[0] + 1, f"{('Bank', 'Elevation', 'Heading')[k]} changes at {rate[bad[0], k]:.4g} rad/s from the "
                         f"line before (more than {_MAX_EULER_RATE:g})")


class TruthInterpolant:
    """Continuous trajectory through a :class:`TruthFile` (module docstring: quintic Hermite
    position, cubic-spline attitude)."""

    def __init__(self, truth: TruthFile):
        from scipy.interpolate import CubicSpline

        self.truth = truth
        self._att = CubicSpline(truth.t_s, truth.euler_rad, axis=0, bc_type="not-a-knot")
        self._datt = self._att.derivative()

    def _interval(self, t):
        tk = self.truth.t_s
        k = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, tk.size - 2)
        h = tk[k + 1] - tk[k]
        return k, h, ((t - tk[k]) / h)[:, None], h[:, None]

    def position(self, t):
        """ECEF position, velocity and acceleration (N, 3) each at times t [s] (quintic Hermite)."""
        t = np.atleast_1d(np.asarray(t, float))
        k, _, s, h = self._interval(t)
        T = self.truth
        p0, p1, v0, v1, a0, a1 = T.r_e[k], T.r_e[k + 1], T.v_e[k] * h, T.v_e[k + 1] * h, \
            T.a_e[k] * h * h, T.a_e[k + 1] * h * h
        s2, s3, s4, s5 = s * s, s ** 3, s ** 4, s ** 5
        # quintic Hermite basis (value, first and second derivative at both ends)
        H0 = 1 - 10 * s3 + 15 * s4 - 6 * s5
        H1 = s - 6 * s3 + 8 * s4 - 3 * s5
        H2 = 0.5 * s2 - 1.5 * s3 + 1.5 * s4 - 0.5 * s5
        H3 = 0.5 * s3 - s4 + 0.5 * s5
        H4 = -4 * s3 + 7 * s4 - 3 * s5
        H5 = 10 * s3 - 15 * s4 + 6 * s5
        dH0 = -30 * s2 + 60 * s3 - 30 * s4
        dH1 = 1 - 18 * s2 + 32 * s3 - 15 * s4
        dH2 = s - 4.5 * s2 + 6 * s3 - 2.5 * s4
        dH3 = 1.5 * s2 - 4 * s3 + 2.5 * s4
        dH4 = -12 * s2 + 28 * s3 - 15 * s4
        dH5 = -dH0
        ddH0 = -60 * s + 180 * s2 - 120 * s3
        ddH1 = -36 * s + 96 * s2 - 60 * s3
        ddH2 = 1 - 9 * s + 18 * s2 - 10 * s3
        ddH3 = 3 * s - 12 * s2 + 10 * s3
        ddH4 = -24 * s + 84 * s2 - 60 * s3
        ddH5 = -ddH0
        r = H0 * p0 + H1 * v0 + H2 * a0 + H3 * a1 + H4 * v1 + H5 * p1
        v = (dH0 * p0 + dH1 * v0 + dH2 * a0 + dH3 * a1 + dH4 * v1 + dH5 * p1) / h
        a = (ddH0 * p0 + ddH1 * v0 + ddH2 * a0 + ddH3 * a1 + ddH4 * v1 + ddH5 * p1) / (h * h)
        return r, v, a

    def attitude(self, t):
        """3-2-1 Euler angles and their rates (N, 3) [rad, rad/s] at t [s]."""
        t = np.atleast_1d(np.asarray(t, float))
        return self._att(t), self._datt(t)

    def state(self, t):
        """lat, lon [rad], h [m], v_n, euler (yaw unwrapped), f_ib_b, omega_ib_b at t (SI)."""
        t = np.atleast_1d(np.asarray(t, float))
        r, v_e, a_e = self.position(t)
        lat, lon, h = earth.ecef_to_geodetic(r)
        eul, deul = self.attitude(t)
        sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)

        def e2n(x):  # C_ne x for each row
            n = -sl * co * x[:, 0] - sl * so * x[:, 1] + cl * x[:, 2]
            e = -so * x[:, 0] + co * x[:, 1]
            d = -cl * co * x[:, 0] - cl * so * x[:, 1] - sl * x[:, 2]
            return np.column_stack([n, e, d])

        w_ie_e = np.zeros_like(v_e)
        w_ie_e[:, 2] = earth.OMEGA_IE
        v_n = e2n(v_e)
        f_n = e2n(a_e + 2.0 * _cross(w_ie_e, v_e))
        f_n[:, 2] -= earth.gravity(lat, h)
        R_M, R_N = earth.radii(lat)
        w_in = np.column_stack([earth.OMEGA_IE * cl + v_n[:, 1] / (R_N + h), -v_n[:, 0] / (R_M + h),
                                -earth.OMEGA_IE * sl - v_n[:, 1] * sl / cl / (R_N + h)])
        omega_nb_b = euler_rate_to_omega_nb_b(eul, deul)
        return dict(t=t, lat=lat, lon=lon, h=h, v_n=v_n, euler=eul, f_ib_b=rotate_n_to_b(eul, f_n),
                    omega_ib_b=omega_nb_b + rotate_n_to_b(eul, w_in))

    def imu_increments(self, t_imu, nodes: int = 3):
        """Ideal increments over ``(t_imu[k-1], t_imu[k]]`` (Gauss-Legendre, ``nodes`` per interval):
        ``dtheta_b``, ``dv_b`` (N, 3) [rad, m/s]."""
        t_imu = np.asarray(t_imu, float)
        xg, wg = np.polynomial.legendre.leggauss(nodes)
        a, b = t_imu[:-1], t_imu[1:]
        half = 0.5 * (b - a)
        tn = (0.5 * (a + b))[:, None] + half[:, None] * xg[None, :]
        st = self.state(tn.ravel())
        wn = (half[:, None] * wg[None, :])[..., None]
        dth = (st["omega_ib_b"].reshape(tn.shape + (3,)) * wn).sum(axis=1)
        dv = (st["f_ib_b"].reshape(tn.shape + (3,)) * wn).sum(axis=1)
        return dth, dv


def sensor_errors_for_grade(name: str, rate_hz: float):
    """(gyro, accel) :class:`insnav.sim.scenario.SensorErrors` of a named grade
    (:mod:`insnav.data.imu_grades`): first-order Gauss-Markov bias (the grade's sigma and
    correlation time), white noise, random scale factors; ``"exact"``: no error at all."""
    from ..data.imu_grades import imu_grade
    from .scenario import SensorErrors

    z = np.zeros(3)
    if name == "exact":
        g = dict(gyro_bias_sigma=0.0, gyro_arw=0.0, accel_bias_sigma=0.0, accel_vrw=0.0, bias_tau_s=math.inf,
                 gyro_scale_sigma=0.0, accel_scale_sigma=0.0)
    else:
        g = imu_grade(name)

    def se(p, noise):
        return SensorErrors(bias=z.copy(), bias_sigma=z.copy(), gm_sigma=np.full(3, g[f"{p}_bias_sigma"]),
                            gm_tau=np.full(3, g["bias_tau_s"]), bias_rw=z.copy(), noise_density=np.full(3, noise),
                            scale=z.copy(), scale_sigma=np.full(3, g[f"{p}_scale_sigma"]),
                            misalignment=np.zeros((3, 3)), misalignment_sigma=0.0)
    return se("gyro", g["gyro_arw"]), se("accel", g["accel_vrw"])


def simulate_from_truth(path, imu_grade: str = "industrial", *, imu_rate_hz: float = 100.0, seed: int = 0,
                        gps_time_offset_s: float | None = None) -> Dataset:
    """A dataset (IMU, truth, no GNSS fixes) synthesised from a truth trajectory file.

    Parameters
    ----------
    path : path
        Spirent SimGEN motion file (:func:`read_spirent_motion`).
    imu_grade : str
        A grade of :data:`insnav.data.imu_grades.IMU_GRADES`, or ``"exact"`` (no error).
    imu_rate_hz : float
        IMU sample rate [Hz] (the truth file's own rate is typically 10 Hz).
    seed : int
        Random seed of the IMU errors.
    gps_time_offset_s : float, optional
        GPS time of ``t = 0`` [s since 1980-01-06]; default the file's.

    Returns
    -------
    Dataset
        ``imu`` over the truth file's span, ``truth`` at the file's epochs, ``initial`` the true
        state at the first epoch, ``lever_arm_b`` the file's antenna offset.
    """
    from .imu import apply_errors, imu_model_dict, simulate_sensor_errors
    from . import sample_times

    if not 1.0 <= imu_rate_hz <= 10000.0:  # the scenarios' [imu] rate_hz range
        raise ValueError(f"imu_rate_hz (--imu-rate-hz): {imu_rate_hz!r}; allowed: 1 to 10000 [Hz]")
    tf = read_spirent_motion(path)
    off = tf.gps_time_offset_s if gps_time_offset_s is None else float(gps_time_offset_s)
    if not math.isfinite(off):
        raise TruthFileError(f"{tf.path}: the file gives no GPS time of t = 0 (its first line's last field); "
                             "insnav.sim.from_truth.simulate_from_truth(..., gps_time_offset_s=...) takes it")
    interp = TruthInterpolant(tf)
    t0, t_end = float(tf.t_s[0]), float(tf.t_s[-1])
    t_imu = sample_times(t0, t_end, imu_rate_hz)
    if t_imu.size < 3:  # two increments: the fewest a navigation run takes
        raise TruthFileError(f"{tf.path}: the truth spans {t_end - t0:g} s, too short for 2 IMU samples at "
                             f"{imu_rate_hz:g} Hz (it needs {2.0 / imu_rate_hz:g} s or more)")
    dth, dv = interp.imu_increments(t_imu)
    gyro, accel = sensor_errors_for_grade(imu_grade, imu_rate_hz)
    rng_g, rng_a = (np.random.default_rng(c) for c in np.random.SeedSequence(seed).spawn(2))
    n = dth.shape[0]
    dt = 1.0 / imu_rate_hz
    g_real, g_noise = simulate_sensor_errors(gyro, n + 1, dt, rng_g)
    a_real, a_noise = simulate_sensor_errors(accel, n + 1, dt, rng_a)
    g_s = type(g_real)(g_real.bias[1:], g_real.scale, g_real.misalignment, g_real.turn_on_bias)
    a_s = type(a_real)(a_real.bias[1:], a_real.scale, a_real.misalignment, a_real.turn_on_bias)
    imu = ImuData(t_imu[1:].copy(), apply_errors(dth, g_s, g_noise[1:], dt), apply_errors(dv, a_s, a_noise[1:], dt))
    st = interp.state(tf.t_s)
    eul = np.degrees(st["euler"])
    eul[:, 0] = np.where(np.abs(eul[:, 0]) > 180.0, wrap_deg(eul[:, 0]), eul[:, 0])  # the unwrapped roll
    truth = Truth(t=st["t"], lat_deg=np.degrees(st["lat"]), lon_deg=np.degrees(st["lon"]), h_m=st["h"],
                  v_n=st["v_n"], roll_deg=eul[:, 0], pitch_deg=eul[:, 1], yaw_deg=wrap_deg(eul[:, 2]),
                  f_ib_b=st["f_ib_b"], omega_ib_b=st["omega_ib_b"])
    sel = np.arange(0, n + 1, max(1, int(round(imu_rate_hz))))
    imu_errors = ImuErrors(t_imu[sel], g_real.bias[sel], a_real.bias[sel], g_real.scale, a_real.scale,
                           g_real.misalignment, a_real.misalignment)
    z = np.empty(0)
    gnss = GnssFixes(z, z, z, z, z, np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))
    model = imu_model_dict(gyro, accel, imu_rate_hz)
    model["imu_grade"] = imu_grade
    scenario = {"name": f"from-truth:{Path(tf.path).name}", "truth_file": tf.path, "imu_grade": imu_grade,
                "imu_rate_hz": float(imu_rate_hz), "interpolation": "quintic Hermite position (p, v, a), "
                "cubic spline 3-2-1 Euler angles", "seed": int(seed)}
    return Dataset(imu=imu, gnss=gnss, truth=truth, gnss_raw=None, imu_errors=imu_errors, scenario=scenario,
                   lever_arm_b=tf.lever_arm_b.copy(), initial=truth.state_at(0), t0=t0, gps_time_offset_s=off,
                   imu_model=model, name=scenario["name"], seed=int(seed), initial_is_truth=True)
