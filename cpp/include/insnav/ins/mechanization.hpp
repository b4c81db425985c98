// insnav/ins/mechanization.hpp -- strapdown INS mechanization in NED.
//
// Input: IMU increments dtheta_b, dv_b over (t_{k-1}, t_k] (any, variable dt).
// Update order per step (Savage, "Strapdown Analytics" 2nd ed., ch. 7;
// Shin, "Estimation techniques for low-cost inertial navigation", 2005,
// sec. 2.2; the same scheme as KF-GINS):
//   1. velocity: the body-frame increment gets the rotation correction
//      1/2 dtheta x dv and the two-sample sculling correction
//      1/12 (dtheta_{k-1} x dv_k + dv_{k-1} x dtheta_k); it is rotated to n
//      with C_nb(k-1) and the half-step rotation of the n frame
//      (I - 1/2 [zeta x]), zeta = omega_in_n dt; gravity and Coriolis are
//      evaluated at the mid-interval position and velocity, which are
//      extrapolated with a first velocity estimate;
//   2. position: trapezoidal (mid-interval velocity, radii at mid-interval);
//   3. attitude: q_nb(k) = q_n(k)n(k-1) * q_nb(k-1) * q_b(k-1)b(k), the body
//      rotation vector with the two-sample coning correction
//      1/12 dtheta_{k-1} x dtheta_k, the n-frame rotation -omega_in_n dt at
//      mid-interval.
// Earth terms are evaluated once per step at the extrapolated mid-interval
// point (one sin/cos/sqrt/tan set per sample): the first velocity estimate
// uses the previous step's mid-interval terms, whose error is O(dt) on an
// O(dt) correction and is removed by the second pass.
// The NED mechanization is singular at the poles (longitude rate).
#pragma once

#include <cmath>

#include "insnav/earth/wgs84.hpp"
#include "insnav/ins/nav_state.hpp"

namespace insnav {

struct MechanizationOptions {
  bool coning_correction = true;   // two-sample coning in the attitude update
  bool sculling_correction = true; // two-sample sculling + rotation correction in the velocity update
};

/// Earth quantities at one point, computed together to share the trig.
struct EarthTerms {
  double sin_lat = 0.0, cos_lat = 1.0;
  wgs84::Radii radii{wgs84::kA, wgs84::kA};
  double g = wgs84::kGammaE;
  Vec3 omega_ie_n = Vec3::Zero();
  Vec3 omega_en_n = Vec3::Zero();

  void evaluate(double lat, double h, const Vec3& v_n) { evaluate(std::sin(lat), std::cos(lat), h, v_n); }
  /// The same from sin and cos of the latitude.
  void evaluate(double sin_latitude, double cos_latitude, double h, const Vec3& v_n) {
    sin_lat = sin_latitude;
    cos_lat = cos_latitude;
    const double s2 = sin_lat * sin_lat;
    const double w = 1.0 - wgs84::kE2 * s2;
    const double sw = std::sqrt(w);
    radii.R_N = wgs84::kA / sw;
    radii.R_M = radii.R_N * (1.0 - wgs84::kE2) / w;
    const double g0 = wgs84::kGammaE * (1.0 + wgs84::kSomiglianaK * s2) / sw;
    g = g0 * (1.0 - 2.0 / wgs84::kA * (1.0 + wgs84::kF + wgs84::kM - 2.0 * wgs84::kF * s2) * h +
              3.0 * h * h / (wgs84::kA * wgs84::kA));
    omega_ie_n = Vec3(wgs84::kOmegaIe * cos_lat, 0.0, -wgs84::kOmegaIe * sin_lat);
    set_velocity(h, v_n);
  }
  /// Recompute the transport rate for a new velocity at the same point.
  void set_velocity(double h, const Vec3& v_n) {
    const double tan_lat = sin_lat / cos_lat;
    omega_en_n = Vec3(v_n.y() / (radii.R_N + h), -v_n.x() / (radii.R_M + h),
                      -v_n.y() * tan_lat / (radii.R_N + h));
  }
};

/// Quaternion of a rotation vector with a 6th-order series up to |phi| = 0.01
/// rad (every IMU attitude increment at >= 50 Hz), saving the trig calls.
inline Quat quat_from_small_rotvec(const Vec3& phi) {
  const double a2 = phi.squaredNorm();
  if (a2 >= 1e-4) return quat_from_rotvec(phi);
  const double w = 1.0 - a2 / 8.0 + a2 * a2 / 384.0 - a2 * a2 * a2 / 46080.0;
  const double s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0 - a2 * a2 * a2 / 645120.0;
  return Quat(w, s * phi.x(), s * phi.y(), s * phi.z());
}

/// Stateful strapdown integrator: holds the previous IMU sample (for the
/// two-sample corrections) and the Earth terms of the previous step.
/// No heap allocation; cheap to copy.
class Strapdown {
 public:
  Strapdown() = default;
  explicit Strapdown(const NavState& initial, MechanizationOptions opt = {}) { reset(initial, opt); }

  /// Restart from a state; the next sample gets no two-sample correction.
  void reset(const NavState& initial, MechanizationOptions opt = {}) {
    nav_ = initial;
    opt_ = opt;
    has_prev_ = false;
    earth_.evaluate(nav_.lat, nav_.h, nav_.v_n);
  }

  /// Replace the navigation state (closed-loop feedback) keeping the IMU history.
  void set_state(const NavState& nav) { nav_ = nav; }

  const NavState& state() const { return nav_; }
  /// Earth terms at the mid-point of the last step (used by error models).
  const EarthTerms& earth() const { return earth_; }
  /// Specific force in n at the mid-point of the last step [m/s^2] (dv_f_n / dt).
  const Vec3& f_ib_n() const { return f_ib_n_; }

  /// Advance by one IMU sample.  imu.dt must be > 0.
  void update(const ImuIncrement& imu) {
    const double dt = imu.dt;
    const ImuIncrement& pre = has_prev_ ? prev_ : imu;  // no correction on the first sample
    const bool use_prev = has_prev_;

    // --- 1. velocity --------------------------------------------------------
    Vec3 dv_f_b = imu.dv_b;
    if (opt_.sculling_correction) {
      dv_f_b += 0.5 * imu.dtheta_b.cross(imu.dv_b);
      if (use_prev)
        dv_f_b += (pre.dtheta_b.cross(imu.dv_b) + pre.dv_b.cross(imu.dtheta_b)) / 12.0;
    }
    const Mat3 C_nb = nav_.q_nb.toRotationMatrix();
    const Vec3 dv_b_n = C_nb * dv_f_b;

    // first pass with the previous mid-interval Earth terms
    Vec3 zeta = (earth_.omega_ie_n + earth_.omega_en_n) * dt;
    Vec3 dv_f_n = dv_b_n - 0.5 * zeta.cross(dv_b_n);
    Vec3 dv_g_n = (Vec3(0.0, 0.0, earth_.g) -
                   (2.0 * earth_.omega_ie_n + earth_.omega_en_n).cross(nav_.v_n)) * dt;
    const Vec3 v_mid_est = nav_.v_n + 0.5 * (dv_f_n + dv_g_n);
    const double h_mid = nav_.h - 0.5 * v_mid_est.z() * dt;
    const double lat_mid = nav_.lat + 0.5 * v_mid_est.x() / (earth_.radii.R_M + nav_.h) * dt;

    // second pass at the extrapolated mid-interval point
    earth_.evaluate(lat_mid, h_mid, v_mid_est);
    zeta = (earth_.omega_ie_n + earth_.omega_en_n) * dt;
    dv_f_n = dv_b_n - 0.5 * zeta.cross(dv_b_n);
    dv_g_n = (Vec3(0.0, 0.0, earth_.g) -
              (2.0 * earth_.omega_ie_n + earth_.omega_en_n).cross(v_mid_est)) * dt;
    const Vec3 v_pre = nav_.v_n;
    nav_.v_n = v_pre + dv_f_n + dv_g_n;
    f_ib_n_ = dv_f_n / dt;

    // --- 2. position (trapezoidal) -------------------------------------------
    const Vec3 v_mid = 0.5 * (v_pre + nav_.v_n);
    const double h_pre = nav_.h;
    nav_.h = h_pre - v_mid.z() * dt;
    const double h_mid2 = 0.5 * (h_pre + nav_.h);
    nav_.lat += v_mid.x() / (earth_.radii.R_M + h_mid2) * dt;
    nav_.lon += v_mid.y() / ((earth_.radii.R_N + h_mid2) * earth_.cos_lat) * dt;

    // --- 3. attitude -----------------------------------------------------------
    earth_.set_velocity(h_mid2, v_mid);
    Vec3 phi_b = imu.dtheta_b;
    if (opt_.coning_correction && use_prev) phi_b += pre.dtheta_b.cross(imu.dtheta_b) / 12.0;
    const Quat q_bb = quat_from_small_rotvec(phi_b);
    const Quat q_nn = quat_from_small_rotvec(-(earth_.omega_ie_n + earth_.omega_en_n) * dt);
    nav_.q_nb = q_nn * nav_.q_nb * q_bb;
    nav_.q_nb.normalize();
    nav_.t = imu.t;

    prev_ = imu;
    has_prev_ = true;
  }

 private:
  NavState nav_{};
  MechanizationOptions opt_{};
  EarthTerms earth_{};
  ImuIncrement prev_{};
  Vec3 f_ib_n_ = Vec3::Zero();
  bool has_prev_ = false;
};

}  // namespace insnav
