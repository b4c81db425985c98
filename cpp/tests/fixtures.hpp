// Test fixtures shared by the C++ tests: an IMU-rate INS run of a turning,
// accelerating vehicle cut into the propagation intervals the filters take.
#pragma once

#include <vector>

#include "insnav/filter/layout20.hpp"
#include "insnav/filter/types.hpp"
#include "insnav/ins/mechanization.hpp"
#include "insnav/math/rotation.hpp"

namespace insnav {

/// IMU-rate INS of a turning, accelerating vehicle, cut into propagation
/// intervals of `per` samples (start, middle, end); the final INS state into
/// *end_state when given.
inline std::vector<InsInterval> make_intervals(int n_intervals, int per = 2, double imu_dt = 0.01,
                                               NavState* end_state = nullptr) {
  NavState s;
  s.lat = 0.6;
  s.lon = 1.9;
  s.h = 200.0;
  s.v_n = Vec3(15.0, -3.0, 0.0);
  s.q_nb = quat_from_euler(Vec3(0.05, -0.03, 1.0));
  Strapdown ins(s);
  const Vec3 w_b(0.02, -0.01, 0.1), f_b(1.0, 0.5, -9.79);
  std::vector<InsInterval> out(n_intervals);
  auto point = [&](InsPoint& p) {
    const NavState& n = ins.state();
    p.set(n.lat, n.h, n.v_n, n.q_nb.toRotationMatrix(), f_b, w_b);
  };
  InsPoint start;
  point(start);
  double t = 0.0;
  for (int k = 0; k < n_intervals; ++k) {
    InsInterval& iv = out[k];
    iv.start = start;
    for (int j = 1; j <= per; ++j) {
      ImuIncrement imu;
      t += imu_dt;
      imu.t = t;
      imu.dt = imu_dt;
      imu.dtheta_b = w_b * imu_dt;
      imu.dv_b = f_b * imu_dt;
      ins.update(imu);
      if (j == per / 2) point(iv.mid);
    }
    point(iv.end);
    iv.dt = per * imu_dt;
    start = iv.end;
  }
  if (end_state) *end_state = ins.state();
  return out;
}

/// Initial covariance of the seed 004 20-state filters (Layout20): position 5/5/8 m,
/// velocity 0.2 m/s, attitude 0.5/0.5/1 deg, accelerometer 10 mg, gyro constant
/// 10 deg/h and Markov 1 deg/h, clock 30 m and 1 m/s (1 sigma).
inline StateCov<Layout20> seed004_typical_P0() {
  constexpr double deg = M_PI / 180.0;
  StateVec<Layout20> s;
  s << 5, 5, 8, 0.2, 0.2, 0.2, 0.5 * deg, 0.5 * deg, 1.0 * deg, 1e-2, 1e-2, 1e-2, 10 * deg / 3600,
      10 * deg / 3600, 10 * deg / 3600, 1 * deg / 3600, 1 * deg / 3600, 1 * deg / 3600, 30.0, 1.0;
  return s.cwiseAbs2().asDiagonal();
}

}  // namespace insnav
