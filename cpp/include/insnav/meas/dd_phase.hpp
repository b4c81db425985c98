// insnav/meas/dd_phase.hpp -- double-differenced carrier-phase and code rows predicted from an
// INS state with the lever arm (tight RTK/INS, engine/rtk_ins_engine.hpp).
//
// Rover antenna (the INS is at the IMU centre, l_b = IMU centre -> antenna, FRD):
//   r_ant_e = r_e(lat, lon, h) + C_en C_nb l_b
// Single difference rover r - base b of satellite s on frequency f (gnss/rtk.hpp, Springer
// Handbook of GNSS 2017, eqs. (26.9)-(26.17)); m = rho (Sagnac) - c dt^s + T (Saastamoinen):
//   SD_s = (lambda phi_r^s - m_r^s) - (lambda phi_b^s - m_b^s)           [m]  (observed - computed)
// Double difference against the reference satellite i (same system and frequency), with the
// single-differenced ambiguity states N (cycles):
//   DD residual  y = computed - measured = -(SD_s - SD_i) + lambda_s N_s - lambda_i N_i
// The error state is computed - true (layout.hpp: position in NED metres, attitude psi), and
// d rho / d r_ant_e = -u^T (u the unit vector receiver -> satellite, ECEF), so (as for the
// pseudorange, meas/pseudorange.hpp, Groves 2013 eqs. (14.127)-(14.129)):
//   d r_ant_n = dr_n + [(C_nb l_b) x] psi
//   H_pos = -(u_s - u_i)^T C_en,   H_att = H_pos [(C_nb l_b) x],   H_N_s = +lambda_s, H_N_i = -lambda_i.
// A code row is the same without the ambiguity terms.
#pragma once

#ifndef EIGEN_STACK_ALLOCATION_LIMIT  // before the first Eigen include (gnss/rtk.hpp's fixed-capacity matrices)
#define EIGEN_STACK_ALLOCATION_LIMIT 1048576
#endif

#include <cmath>

#include "insnav/earth/wgs84.hpp"
#include "insnav/gnss/rtk.hpp"
#include "insnav/ins/nav_state.hpp"
#include "insnav/math/rotation.hpp"

namespace insnav {

/// The rover antenna of an INS state: ECEF position, C_en and the lever arm in NED.
struct RtkAntenna {
  Vec3 r_e = Vec3::Zero();
  Mat3 C_en = Mat3::Identity();
  Vec3 l_n = Vec3::Zero();

  void set(const NavState& s, const Vec3& lever_arm_b) {
    C_en = wgs84::C_en(s.lat, s.lon);
    l_n = s.q_nb.toRotationMatrix() * lever_arm_b;
    r_e = wgs84::geodetic_to_ecef(s.lat, s.lon, s.h) + C_en * l_n;
  }

  /// Row of H over (position NED [m], attitude psi [rad]) for a DD of unit vectors u_s - u_i
  /// (ECEF): h_pos = -(u_s - u_i)^T C_en, h_att = h_pos [l_n x].
  void dd_jacobian(const Vec3& du_e, double* h_pos3, double* h_att3) const {
    const Eigen::RowVector3d hp = -(du_e.transpose() * C_en);
    const Eigen::RowVector3d ha = hp * skew(l_n);
    for (int k = 0; k < 3; ++k) {
      h_pos3[k] = hp(k);
      h_att3[k] = ha(k);
    }
  }
};

/// Computed zero-difference terms m = rho + Sagnac - c dt^s + T of one receiver and satellite row,
/// with the unit vector receiver -> satellite.
inline double rtk_computed_zd(const double* row, const Vec3& r_e, double lat, double h, double el, bool tropo,
                              Vec3& u_e) {
  const double rho = gnss::sat_range(row, r_e, u_e);
  const double T = tropo ? gnss::detail::tropo_saastamoinen_m(lat, h, el) : 0.0;
  return rho - row[gnss::RtkRow::kSatClock] + T;
}

/// One DD phase (or code) row "computed - measured" at an INS state, without the ambiguity term,
/// and its Jacobian over the 15 INS error states (Layout15 order: position, velocity, attitude,
/// ...; only position and attitude are non-zero).  rover_s / rover_i / base_s / base_i: RtkRow rows
/// of the satellite and its reference; f: frequency slot; code: a code row.  The elevations for
/// the troposphere are those of each receiver.  Returns NaN when an observation is missing.
inline double dd_row_at(const NavState& s, const Vec3& lever_arm_b, const Vec3& r_base_e, const double* rover_s,
                        const double* rover_i, const double* base_s, const double* base_i, int f, bool code,
                        bool tropo, double* H15) {
  using gnss::RtkRow;
  RtkAntenna a;
  a.set(s, lever_arm_b);
  const Vec3 llh_r = wgs84::ecef_to_geodetic(a.r_e);
  const Vec3 llh_b = wgs84::ecef_to_geodetic(r_base_e);
  auto elev = [](const Vec3& llh, const Vec3& u_e) {
    const Vec3 u_n = wgs84::C_en(llh(0), llh(1)).transpose() * u_e;
    return std::asin(std::clamp(-u_n(2), -1.0, 1.0));
  };
  auto sd = [&](const double* r, const double* b, Vec3& u_r) {
    Vec3 ub;
    gnss::sat_range(r, a.r_e, u_r);
    gnss::sat_range(b, r_base_e, ub);
    const double mr = rtk_computed_zd(r, a.r_e, llh_r(0), llh_r(2), elev(llh_r, u_r), tropo, u_r);
    const double mb = rtk_computed_zd(b, r_base_e, llh_b(0), llh_b(2), elev(llh_b, ub), tropo, ub);
    const int k = RtkRow::kFreq0 + RtkRow::kPerFreq * f;
    if (code) return (r[k] - mr) - (b[k] - mb);
    return (r[k + 4] * r[k + 1] - mr) - (b[k + 4] * b[k + 1] - mb);
  };
  Vec3 us, ui;
  const double y = -(sd(rover_s, base_s, us) - sd(rover_i, base_i, ui));
  if (H15) {
    for (int k = 0; k < 15; ++k) H15[k] = 0.0;
    a.dd_jacobian(us - ui, H15 + 0, H15 + 6);
  }
  return y;
}

}  // namespace insnav
