// insnav/ins/nav_error.hpp -- correcting a navigation solution by the
// navigation error states of the closed-loop filters.
//
// The error is computed minus true (filter/layout.hpp): dr_n [m] the N, E, D
// position error [dL (R_M + h), dlambda (R_N + h) cos L, -dh], dv_n [m/s] the
// velocity error, psi [rad] the attitude error with C_nb(true) =
// dcm_from_euler(psi) C_nb (seed 000 eq. (1)).  The latitude / longitude
// corrections divide by the radii and cos(lat) of the computed latitude, as
// KF-GINS's feedback does (the error's first-order definition above).
//
// One place for the formula: ClosedLoop::feedback (the INS reset), its
// output rows (ClosedLoop::write_output, the INS corrected by a filter estimate
// not yet fed back) and the RTS smoother's rows (engine/smoothed_rows.hpp); and
// for the output's Euler-angle sigmas from psi's covariance (euler_sigmas_from_psi).
#pragma once

#include <algorithm>
#include <cmath>

#include "insnav/earth/wgs84.hpp"
#include "insnav/ins/nav_state.hpp"
#include "insnav/math/rotation.hpp"

namespace insnav {

/// sin and cos of one angle [rad] in one call where the C library has sincos
/// (glibc: the same values as std::sin and std::cos).
inline void sin_cos(double a, double& s, double& c) {
#if defined(__GLIBC__)
  ::sincos(a, &s, &c);
#else
  s = std::sin(a);
  c = std::cos(a);
#endif
}

/// Latitude and longitude corrections [rad] of the horizontal position error
/// (dr_north, dr_east) [m] at height h [m], sin and cos of the computed
/// latitude at hand: lat(true) = lat - dlat, lon(true) = lon - dlon.
struct LatLonCorrection {
  double dlat = 0.0;
  double dlon = 0.0;
};

inline LatLonCorrection latlon_correction(double sin_lat, double cos_lat, double h, double dr_north, double dr_east) {
  const wgs84::Radii r = wgs84::radii_from_sin(sin_lat);
  return {dr_north / (r.R_M + h), dr_east / ((r.R_N + h) * cos_lat)};
}

/// q_nb corrected by the attitude error psi [rad]: dcm(psi) C_nb as quaternions, renormalised.
inline Quat corrected_attitude(const Vec3& psi, const Quat& q_nb) {
  return unit_quat(quat_from_small_euler(psi) * q_nb);
}

/// Correct a navigation state by its error (dr_n [m], dv_n [m/s], psi [rad];
/// the file comment): position, velocity and attitude of the true state.
inline void apply_nav_error(NavState& s, const Vec3& dr_n, const Vec3& dv_n, const Vec3& psi) {
  double sin_lat, cos_lat;
  sin_cos(s.lat, sin_lat, cos_lat);
  const LatLonCorrection c = latlon_correction(sin_lat, cos_lat, s.h, dr_n.x(), dr_n.y());
  s.lat -= c.dlat;
  s.lon -= c.dlon;
  s.h += dr_n.z();
  s.v_n -= dv_n;
  s.q_nb = corrected_attitude(psi, s.q_nb);
}

/// 1-sigmas [rad] of the 3-2-1 Euler angles (roll, pitch, yaw) at `pitch`, `yaw` [rad] whose
/// attitude error angles psi (the file comment; about N, E, D) have the covariance P_psi [rad^2].
/// A change d = d(roll, pitch, yaw) turns the frame by omega_n = A d about the NED axes,
///     A = [[cy cp, -sy, 0], [sy cp, cy, 0], [-sp, 0, 1]]
/// (roll about the body x axis Rz(yaw) Ry(pitch) e1, pitch about Rz(yaw) e2, yaw about e3), and
/// the computed frame differs from the true one by omega_n = -psi, so the Euler-angle error is
/// -A^-1 psi with
///     A^-1 = [[cy/cp, sy/cp, 0], [-sy, cy, 0], [cy tp, sy tp, 1]],
/// and its covariance A^-1 P_psi A^-T.  psi's own sigmas equal these only at yaw 0 (level or not:
/// heading east, psi_N is the pitch error).  cos(pitch) is held at >= 1e-9 at +-90 deg, where roll
/// and yaw are not separable.
inline Vec3 euler_sigmas_from_psi(const Mat3& P_psi, double pitch, double yaw) {
  double sp, cp, sy, cy;
  sin_cos(pitch, sp, cp);
  sin_cos(yaw, sy, cy);
  if (std::abs(cp) < 1e-9) cp = cp < 0.0 ? -1e-9 : 1e-9;
  Mat3 A_inv;
  A_inv << cy / cp, sy / cp, 0.0,
           -sy, cy, 0.0,
           cy * sp / cp, sy * sp / cp, 1.0;
  const Mat3 P_e = A_inv * P_psi * A_inv.transpose();
  return P_e.diagonal().cwiseMax(0.0).cwiseSqrt();
}

/// euler_sigmas_from_psi at the attitude C_nb, without trigonometry (the output rows' hot path).
/// C_nb's first column is (a, b, c) = (cy cp, sy cp, -sp), so with cp^2 = a^2 + b^2 and
/// H = a^2 P00 + 2 a b P01 + b^2 P11 the diagonal of A^-1 P_psi A^-T is
///     var_roll  = H / cp^4,
///     var_pitch = (b^2 P00 - 2 a b P01 + a^2 P11) / cp^2,
///     var_yaw   = c^2 H / cp^4 - 2 c (a P02 + b P12) / cp^2 + P22
/// (one division, no square root but the three sigmas').  At gimbal lock (cp < 1e-9) it falls
/// back to euler_sigmas_from_psi at C_nb's Euler angles.
inline Vec3 euler_sigmas_from_psi_dcm(const Mat3& P_psi, const Mat3& C_nb) {
  const double a = C_nb(0, 0), b = C_nb(1, 0), c = C_nb(2, 0);
  const double cp2 = a * a + b * b;
  if (!(cp2 >= 1e-18)) {
    const Vec3 e = euler_from_dcm(C_nb);
    return euler_sigmas_from_psi(P_psi, e[1], e[2]);
  }
  const double inv_cp2 = 1.0 / cp2;
  const double ab2P01 = a * b * (P_psi(0, 1) + P_psi(1, 0));
  const double H = a * a * P_psi(0, 0) + ab2P01 + b * b * P_psi(1, 1);
  const double cross = a * (P_psi(0, 2) + P_psi(2, 0)) + b * (P_psi(1, 2) + P_psi(2, 1));
  const double roll_var = H * inv_cp2 * inv_cp2;
  const Eigen::Array3d var(roll_var, (b * b * P_psi(0, 0) - ab2P01 + a * a * P_psi(1, 1)) * inv_cp2,
                           c * c * roll_var - c * cross * inv_cp2 + P_psi(2, 2));
  return var.max(0.0).sqrt().matrix();
}

}  // namespace insnav
