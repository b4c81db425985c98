// A plain C++ program using the insnav core with no Python: a stationary IMU
// at 45 deg latitude with exact Earth-rate and gravity increments, navigated
// for 10 minutes at 200 Hz.  Prints the position drift; exits non-zero if it
// exceeds 1 mm (the core is then broken).
//
// Build: cmake -S . -B build/cpp -DINSNAV_BUILD_EXAMPLES=ON && cmake --build build/cpp
// or, in your own project:  find_package(insnav) ... target_link_libraries(app insnav::core)
#include <cstdio>

#include "insnav/core.hpp"

int main() {
  using namespace insnav;
  const double kDeg = M_PI / 180.0;
  NavState nav;
  nav.lat = 45.0 * kDeg;
  nav.lon = 7.0 * kDeg;
  nav.h = 250.0;
  nav.q_nb = quat_from_euler(Vec3(1.0 * kDeg, -2.0 * kDeg, 30.0 * kDeg));

  // Exact increments of a stationary IMU: omega_ib_b = C_bn omega_ie_n,
  // f_ib_b = -C_bn g_n (normal gravity already contains the centrifugal term).
  const Mat3 C_bn = nav.q_nb.toRotationMatrix().transpose();
  const double rate_hz = 200.0, dt = 1.0 / rate_hz;
  ImuIncrement imu;
  imu.dt = dt;
  imu.dtheta_b = C_bn * wgs84::omega_ie_n(nav.lat) * dt;
  imu.dv_b = -C_bn * Vec3(0.0, 0.0, wgs84::gravity(nav.lat, nav.h)) * dt;

  Strapdown ins(nav);
  const int n = static_cast<int>(600 * rate_hz);
  for (int i = 1; i <= n; ++i) {
    imu.t = i * dt;
    ins.update(imu);
  }
  const NavState& s = ins.state();
  const Vec3 dr_e = wgs84::geodetic_to_ecef(s.lat, s.lon, s.h) - wgs84::geodetic_to_ecef(nav.lat, nav.lon, nav.h);
  const Vec3 datt = rotvec_from_quat(s.q_nb * nav.q_nb.conjugate());
  std::printf("free-inertial, stationary, 600 s at 200 Hz: position drift %.3e m, attitude drift %.3e rad\n",
              dr_e.norm(), datt.norm());
  return (dr_e.norm() < 1e-3 && datt.norm() < 1e-6) ? 0 : 1;
}
