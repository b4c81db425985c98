"""Named IMU grades: typical error figures for when the user has no data
sheet (Groves 2013, Table 4.1 and sec. 4.4.5; Titterton & Weston 2004,
Table 4.1; representative data sheets); ``docs/formats.md`` lists them.
"""
from __future__ import annotations

from ..errors import close_matches

from ..units import DEG_PER_H, DEG_PER_SQRT_H, MG

__all__ = ["IMU_GRADES", "imu_grade", "imu_model_for_grade"]

#: Named IMU grades, SI: gyro bias sigma [rad/s], ARW [rad/sqrt(s)], accel
#: bias sigma [m/s^2], VRW [(m/s)/sqrt(s)], bias correlation time [s],
#: scale-factor sigma [-].
IMU_GRADES: dict[str, dict[str, float]] = {
    # ring-laser / navigation FOG: 0.01 deg/h, 0.002 deg/sqrt(h), 25 ug, 0.002 m/s/sqrt(h)
    "navigation": dict(gyro_bias_sigma=0.01 * DEG_PER_H, gyro_arw=0.002 * DEG_PER_SQRT_H,
                       accel_bias_sigma=0.025 * MG, accel_vrw=0.002 / 60.0, bias_tau_s=3600.0,
                       gyro_scale_sigma=5e-6, accel_scale_sigma=20e-6),
    # tactical FOG / high-end MEMS: 1 deg/h, 0.1 deg/sqrt(h), 1 mg, 0.05 m/s/sqrt(h)
    "tactical": dict(gyro_bias_sigma=1.0 * DEG_PER_H, gyro_arw=0.1 * DEG_PER_SQRT_H,
                     accel_bias_sigma=1.0 * MG, accel_vrw=0.05 / 60.0, bias_tau_s=1800.0,
                     gyro_scale_sigma=300e-6, accel_scale_sigma=300e-6),
    # industrial MEMS: 10 deg/h, 0.3 deg/sqrt(h), 3 mg, 0.1 m/s/sqrt(h)
    "industrial": dict(gyro_bias_sigma=10.0 * DEG_PER_H, gyro_arw=0.3 * DEG_PER_SQRT_H,
                       accel_bias_sigma=3.0 * MG, accel_vrw=0.1 / 60.0, bias_tau_s=600.0,
                       gyro_scale_sigma=1000e-6, accel_scale_sigma=1000e-6),
    # consumer MEMS (phones, hobby boards): 500 deg/h, 1 deg/sqrt(h), 30 mg, 0.5 m/s/sqrt(h)
    "consumer": dict(gyro_bias_sigma=500.0 * DEG_PER_H, gyro_arw=1.0 * DEG_PER_SQRT_H,
                     accel_bias_sigma=30.0 * MG, accel_vrw=0.5 / 60.0, bias_tau_s=300.0,
                     gyro_scale_sigma=10000e-6, accel_scale_sigma=10000e-6),
}


def imu_grade(name: str) -> dict[str, float]:
    """The error figures of a named grade (a copy); a clear error for an unknown name."""
    try:
        return dict(IMU_GRADES[name])
    except KeyError:
        close = close_matches(str(name), IMU_GRADES)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"imu_grade {name!r} unknown{hint}; known: {', '.join(IMU_GRADES)}") from None


def imu_model_for_grade(name: str) -> dict:
    """A dataset ``imu_model`` dict (keys of :func:`insnav.sim.imu.imu_model_dict`,
    SI) for a named grade: first-order Gauss-Markov biases with the grade's
    sigma and correlation time, white noise, scale-factor sigmas."""
    g = imu_grade(name)
    three = lambda v: [float(v)] * 3  # noqa: E731
    m = {"imu_grade": name}
    for p, q in (("gyro", "gyro"), ("accel", "accel")):
        m[f"{p}_gm_sigma"] = three(g[f"{q}_bias_sigma"])
        m[f"{p}_gm_tau"] = three(g["bias_tau_s"])
        m[f"{p}_bias_total_sigma"] = three(g[f"{q}_bias_sigma"])
        m[f"{p}_scale_sigma"] = three(g[f"{q}_scale_sigma"])
    m["gyro_arw"] = three(g["gyro_arw"])
    m["accel_vrw"] = three(g["accel_vrw"])
    return m
