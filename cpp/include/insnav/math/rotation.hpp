// insnav/math/rotation.hpp -- quaternions, DCMs, 3-2-1 Euler angles and
// rotation vectors.
//
// Conventions (see docs/conventions.md):
//  * C_ab rotates a vector from frame b to frame a: v_a = C_ab * v_b.
//  * q_ab is the unit quaternion of C_ab, scalar first (Eigen's w, x, y, z).
//  * Euler angles are 3-2-1 (yaw psi about z, then pitch theta about the new y,
//    then roll phi about the new x):  C_nb = Rz(yaw) * Ry(pitch) * Rx(roll).
//  * A rotation vector phi_ab (axis * angle) gives C_ab = exp([phi x]).
// Small-angle series are used where the closed forms lose precision
// (Savage, "Strapdown Analytics", 2nd ed., sec. 3.2.2).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace insnav {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Quat = Eigen::Quaterniond;

/// Skew-symmetric (cross-product) matrix: skew(a) * b = a x b.
inline Mat3 skew(const Vec3& a) {
  Mat3 S;
  S << 0.0, -a.z(), a.y(),
       a.z(), 0.0, -a.x(),
       -a.y(), a.x(), 0.0;
  return S;
}

/// Quaternion of a rotation vector phi (rad): q = [cos(|phi|/2), sin(|phi|/2) phi/|phi|].
/// Uses the Taylor series of sin(x/2)/x below |phi| = 1e-4 rad.
inline Quat quat_from_rotvec(const Vec3& phi) {
  const double a2 = phi.squaredNorm();
  double w, s;  // s = sin(a/2)/a
  if (a2 < 1e-8) {
    w = 1.0 - a2 / 8.0 + a2 * a2 / 384.0;
    s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0;
  } else {
    const double a = std::sqrt(a2);
    w = std::cos(0.5 * a);
    s = std::sin(0.5 * a) / a;
  }
  return Quat(w, s * phi.x(), s * phi.y(), s * phi.z());
}

/// Rotation vector (rad) of a unit quaternion, angle in [0, pi].
inline Vec3 rotvec_from_quat(const Quat& q_in) {
  Quat q = q_in;
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();  // same rotation, angle <= pi
  const Vec3 v = q.vec();
  const double vn = v.norm();
  if (vn < 1e-6) {
    // angle / |v| = 2 atan2(|v|, w) / |v| = (2/w)(1 - |v|^2/(3 w^2) + ...)
    const double w = q.w();
    return v * (2.0 / w) * (1.0 - vn * vn / (3.0 * w * w));
  }
  return v * (2.0 * std::atan2(vn, q.w()) / vn);
}

/// sin and cos of an angle a [rad].  Below |a| = 2^-6 rad (0.9 deg: every
/// error angle of a converged filter) by the Taylor series to a^9 / a^10,
/// whose first omitted terms (a^11/11!, a^12/12!) are below 1e-25 relative:
/// the libm value to rounding, at a fraction of the call's cost (the unscented
/// time update evaluates the nonlinear error model 4 (2n + 1) times per interval).
inline void sincos_exact(double a, double& s, double& c) {
  if (std::abs(a) < 0.015625) {
    // Taylor coefficients as products (a division by a constant is not turned
    // into a multiplication without -ffast-math, and costs ~15 cycles)
    constexpr double s3 = -1.0 / 6.0, s5 = 1.0 / 120.0, s7 = -1.0 / 5040.0, s9 = 1.0 / 362880.0;
    constexpr double c2 = -0.5, c4 = 1.0 / 24.0, c6 = -1.0 / 720.0, c8 = 1.0 / 40320.0, c10 = -1.0 / 3628800.0;
    const double a2 = a * a;
    s = a + a * a2 * (s3 + a2 * (s5 + a2 * (s7 + a2 * s9)));
    c = 1.0 + a2 * (c2 + a2 * (c4 + a2 * (c6 + a2 * (c8 + a2 * c10))));
  } else {
    s = std::sin(a);
    c = std::cos(a);
  }
}

/// C_nb from 3-2-1 Euler angles (roll, pitch, yaw) [rad].
inline Mat3 dcm_from_euler(const Vec3& rpy) {
  double sr, cr, sp, cp, sy, cy;
  sincos_exact(rpy.x(), sr, cr);
  sincos_exact(rpy.y(), sp, cp);
  sincos_exact(rpy.z(), sy, cy);
  Mat3 C;
  C << cp * cy, -cr * sy + sr * sp * cy, sr * sy + cr * sp * cy,
       cp * sy, cr * cy + sr * sp * sy, -sr * cy + cr * sp * sy,
       -sp, sr * cp, cr * cp;
  return C;
}

/// 3-2-1 Euler angles (roll, pitch, yaw) [rad] of C_nb; yaw in (-pi, pi].
/// Pitch uses atan2 so it stays accurate near +-90 deg.  Yaw is taken from
/// roll-compensated elements that stay O(1) at any pitch
/// (cos(roll) C_11 - sin(roll) C_12 = cos(yaw), sin(roll) C_02 - cos(roll) C_01 = sin(yaw)),
/// so the DCM round trip is exact even where roll itself is ill-conditioned;
/// at gimbal lock (cos(pitch) < 1e-12) roll is set to 0 and yaw takes the rest.
inline Vec3 euler_from_dcm(const Mat3& C) {
  const double cp = std::hypot(C(2, 1), C(2, 2));
  const double pitch = std::atan2(-C(2, 0), cp);
  const bool locked = !(cp > 1e-12);
  const double roll = locked ? 0.0 : std::atan2(C(2, 1), C(2, 2));
  // sin/cos of roll straight from the DCM (no trig): C_21 = sr cp, C_22 = cr cp
  const double sr = locked ? 0.0 : C(2, 1) / cp, cr = locked ? 1.0 : C(2, 2) / cp;
  const double yaw = std::atan2(sr * C(0, 2) - cr * C(0, 1), cr * C(1, 1) - sr * C(1, 2));
  return Vec3(roll, pitch, yaw);
}

/// q_nb of 3-2-1 Euler angles from the sines and cosines of the half angles
/// (roll/2, pitch/2, yaw/2): q = q_z(yaw) q_y(pitch) q_x(roll).
inline Quat quat_from_half_sincos(double sr, double cr, double sp, double cp, double sy, double cy) {
  return Quat(cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
              cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy);
}

/// q_nb of 3-2-1 Euler angles (roll, pitch, yaw) [rad].
inline Quat quat_from_euler(const Vec3& rpy) {
  const double hr = 0.5 * rpy.x(), hp = 0.5 * rpy.y(), hy = 0.5 * rpy.z();
  return quat_from_half_sincos(std::sin(hr), std::cos(hr), std::sin(hp), std::cos(hp), std::sin(hy), std::cos(hy));
}

/// quat_from_euler for error angles (an attitude correction psi [rad]): half
/// angles below 1e-2 rad by their Taylor series (remainder below 1e-19), else
/// exact; the same quaternion to rounding, without six libm calls.
inline Quat quat_from_small_euler(const Vec3& rpy) {
  const double hr = 0.5 * rpy.x(), hp = 0.5 * rpy.y(), hy = 0.5 * rpy.z();
  if (!(std::max({std::abs(hr), std::abs(hp), std::abs(hy)}) < 1e-2)) return quat_from_euler(rpy);
  // reciprocal constants: multiplications, not divisions (the same to rounding)
  const auto sin_s = [](double h) {
    const double h2 = h * h;
    return h * (1.0 - h2 * (1.0 / 6.0) * (1.0 - h2 * (1.0 / 20.0) * (1.0 - h2 * (1.0 / 42.0))));
  };
  const auto cos_s = [](double h) {
    const double h2 = h * h;
    return 1.0 - h2 * 0.5 * (1.0 - h2 * (1.0 / 12.0) * (1.0 - h2 * (1.0 / 30.0) * (1.0 - h2 * (1.0 / 56.0))));
  };
  return quat_from_half_sincos(sin_s(hr), cos_s(hr), sin_s(hp), cos_s(hp), sin_s(hy), cos_s(hy));
}

/// q / |q| with one division (the correction of a unit quaternion by a unit quaternion).
inline Quat unit_quat(const Quat& q) {
  Quat u = q;
  u.coeffs() *= 1.0 / u.coeffs().norm();
  return u;
}

/// atan2(a, b) near a known angle `ref` [rad] (sin_ref, cos_ref at hand): ref
/// plus the small difference atan2(a cos_ref - b sin_ref, b cos_ref + a sin_ref)
/// by its series to x^11 (remainder below 1e-23), wrapped to (-pi, pi]; the
/// same angle without a full atan2 when the result is within 0.02 rad of ref,
/// else atan2(a, b).
inline double atan2_near(double a, double b, double ref, double sin_ref, double cos_ref) {
  constexpr double kPi = 3.14159265358979323846;
  const double num = a * cos_ref - b * sin_ref, den = b * cos_ref + a * sin_ref;
  if (!(den > 0.0) || !(std::abs(num) <= 0.02 * den)) return std::atan2(a, b);
  const double x = num / den, x2 = x * x;
  double r = ref + x * (1.0 - x2 * (1.0 / 3.0 - x2 * (1.0 / 5.0 - x2 * (1.0 / 7.0 - x2 * (1.0 / 9.0 - x2 * (1.0 / 11.0))))));
  if (r > kPi) r -= 2.0 * kPi;
  if (r <= -kPi) r += 2.0 * kPi;
  return r;
}

/// euler_from_dcm of a C_nb known to be close to the attitude `rpy_ref` [rad]
/// (sines and cosines of its angles at hand: s_ref, c_ref): the same angles to
/// rounding, each by atan2_near (an attitude corrected by a small psi).
inline Vec3 euler_from_dcm_near(const Mat3& C, const Vec3& rpy_ref, const Vec3& s_ref, const Vec3& c_ref) {
  const double cp = std::sqrt(C(2, 1) * C(2, 1) + C(2, 2) * C(2, 2));
  const bool locked = !(cp > 1e-12);
  const double inv_cp = locked ? 0.0 : 1.0 / cp;
  const double sr = locked ? 0.0 : C(2, 1) * inv_cp, cr = locked ? 1.0 : C(2, 2) * inv_cp;
  const double pitch = atan2_near(-C(2, 0), cp, rpy_ref.y(), s_ref.y(), c_ref.y());
  const double roll = locked ? 0.0 : atan2_near(C(2, 1), C(2, 2), rpy_ref.x(), s_ref.x(), c_ref.x());
  const double yaw = atan2_near(sr * C(0, 2) - cr * C(0, 1), cr * C(1, 1) - sr * C(1, 2), rpy_ref.z(), s_ref.z(),
                                c_ref.z());
  return Vec3(roll, pitch, yaw);
}

inline Vec3 euler_from_quat(const Quat& q) { return euler_from_dcm(q.toRotationMatrix()); }

/// Rotation matrix of a rotation vector (Rodrigues, with series for small angles).
inline Mat3 dcm_from_rotvec(const Vec3& phi) { return quat_from_rotvec(phi).toRotationMatrix(); }

/// Elementary rotation about z by angle a: the frame rotation used for Earth rotation.
inline Mat3 rot_z(double a) {
  const double s = std::sin(a), c = std::cos(a);
  Mat3 R;
  R << c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0;
  return R;
}

}  // namespace insnav
