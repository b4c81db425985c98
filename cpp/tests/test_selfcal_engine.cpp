// The self-calibration states in the closed loop (engine/loose_engine.hpp,
// engine/closed_loop.hpp): a noise-free turning, accelerating drive whose
// GNSS fixes are tagged 150 ms late (the fix tagged t holds the antenna at
// IMU time t - 0.15 s) and whose antenna sits 1.5 m from the IMU.  The EKF
// on Layout19TdLever, started from t_d^ = 0 and l_b^ = 0, must recover both;
// Layout16Td must leave the result of a zero offset as it is; and the loop
// must not allocate (Eigen's malloc check on from the first sample).
#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/engine/loose_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

struct Drive {
  std::vector<double> t, dtheta, dv;
  std::vector<GnssFix> fixes;
  NavState initial;
};

/// 120 s at 100 Hz: forward acceleration and a yaw rate that changes sign every 20 s, plus some roll
/// and pitch motion (attitude changes for the lever arm); fixes at 5 Hz, tagged t_d late, of the
/// antenna at l_b (position and velocity of the antenna of the true state, noise-free).
Drive make_drive(double t_d, const Vec3& l_b) {
  Drive d;
  NavState s;
  s.t = 0.0;
  s.lat = 0.6;
  s.lon = 1.9;
  s.h = 100.0;
  s.v_n = Vec3(10.0, 0.0, 0.0);
  s.q_nb = quat_from_euler(Vec3(0.0, 0.0, 0.0));
  d.initial = s;
  Strapdown ins(s);
  const double dt = 0.01;
  for (int k = 1; k <= 12000; ++k) {
    const double t = k * dt;
    const double yaw_rate = (static_cast<int>(t / 20.0) % 2 == 0 ? 0.15 : -0.15);
    const Vec3 w_nb_b(0.05 * std::sin(0.5 * t), 0.04 * std::cos(0.3 * t), yaw_rate);
    const NavState& n = ins.state();
    const wgs84::Radii r = wgs84::radii(n.lat);
    const Vec3 w_in_n = wgs84::omega_ie_n(n.lat) + wgs84::omega_en_n(n.lat, n.h, n.v_n, r);
    const Mat3 C_nb = n.q_nb.toRotationMatrix();
    const Vec3 w_ib_b = w_nb_b + C_nb.transpose() * w_in_n;
    // specific force: gravity compensated, a forward push of 0.5 sin(0.2 t) m/s^2 and the
    // centripetal force of the turn, so that the velocity stays along the body x axis roughly
    EarthTerms e;
    e.evaluate(n.lat, n.h, n.v_n);
    const Vec3 a_n = C_nb * Vec3(0.5 * std::sin(0.2 * t), yaw_rate * n.v_n.norm(), 0.0);
    const Vec3 f_n = a_n - Vec3(0.0, 0.0, e.g) + (2.0 * e.omega_ie_n + e.omega_en_n).cross(n.v_n);
    const Vec3 f_b = C_nb.transpose() * f_n;
    ImuIncrement imu;
    imu.t = t;
    imu.dt = dt;
    imu.dtheta_b = w_ib_b * dt;
    imu.dv_b = f_b * dt;
    ins.update(imu);
    d.t.push_back(t);
    for (int j = 0; j < 3; ++j) {
      d.dtheta.push_back(imu.dtheta_b[j]);
      d.dv.push_back(imu.dv_b[j]);
    }
    if (k % 20 == 0) {  // the antenna at IMU time t, tagged t + t_d
      const NavState& a = ins.state();
      const Mat3 C = a.q_nb.toRotationMatrix();
      const Vec3 l_n = C * l_b;
      const wgs84::Radii ra = wgs84::radii(a.lat);
      const Vec3 w_in = wgs84::omega_ie_n(a.lat) + wgs84::omega_en_n(a.lat, a.h, a.v_n, ra);
      GnssFix f;
      f.t = t + t_d;
      f.lat = a.lat + l_n.x() / (ra.R_M + a.h);
      f.lon = a.lon + l_n.y() / ((ra.R_N + a.h) * std::cos(a.lat));
      f.h = a.h - l_n.z();
      f.v_n = a.v_n + C * w_ib_b.cross(l_b) - w_in.cross(l_n);
      f.sigma_pos_n = Vec3::Constant(0.02);
      f.sigma_vel_n = Vec3::Constant(0.02);
      d.fixes.push_back(f);
    }
  }
  return d;
}

template <class L>
StateCov<L> initial_P(double sigma_td, double sigma_lever) {
  StateVec<L> s = StateVec<L>::Zero();
  s.template head<15>() << 0.05, 0.05, 0.05, 0.02, 0.02, 0.02, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-5, 1e-5, 1e-5;
  if constexpr (kHasTimeOffset<L>) s[L::kTimeOffset] = sigma_td;
  if constexpr (kHasLeverArm<L>) s.template segment<3>(L::kLeverArm).setConstant(sigma_lever);
  return s.cwiseAbs2().asDiagonal();
}

template <class L>
struct Result {
  double td = 0, sigma_td = 0;
  Vec3 lever = Vec3::Zero(), sigma_lever = Vec3::Zero();
  std::vector<double> llh;
  int updates = 0;
  int heap = 0;  // Eigen allocations inside run()
};

template <class L>
Result<L> run(const Drive& d, bool malloc_check) {
  ImuErrorModel model;
  model.gyro_arw.setConstant(1e-5);
  model.acc_vrw.setConstant(1e-4);
  LooseConfig cfg;  // lever arm 0: the estimate starts there
  cfg.propagation_interval = 0.1;
  cfg.cycle_period = 0.3;
  auto engine = std::make_unique<LooseEngine<Ekf<L>>>(model, cfg);
  const std::int64_t n = static_cast<std::int64_t>(d.t.size()), m = static_cast<std::int64_t>(d.fixes.size());
  Result<L> r;
  r.llh.resize(3 * (n + 1));
  std::vector<double> td(2 * (n + 1)), lever(6 * (n + 1));
  LooseOutputs out;
  out.llh = r.llh.data();
  out.time_offset = td.data();
  out.lever_arm = lever.data();
  const StateCov<L> P0 = initial_P<L>(0.25, 1.0);
  const int asserts0 = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(!malloc_check);
  engine->run(d.initial, P0, ImuCorrection{}, n, d.t.data(), d.dtheta.data(), d.dv.data(), m, d.fixes.data(), out);
  Eigen::internal::set_is_malloc_allowed(true);
  r.heap = g_eigen_asserts - asserts0;
  const std::int64_t last = out.n_out - 1;
  r.td = td[2 * last];
  r.sigma_td = td[2 * last + 1];
  for (int j = 0; j < 3; ++j) {
    r.lever[j] = lever[6 * last + j];
    r.sigma_lever[j] = lever[6 * last + 3 + j];
  }
  r.updates = out.updates;
  return r;
}

}  // namespace

int main() {
  const Vec3 l_b(1.0, 0.5, -1.0);
  {
    const Drive d = make_drive(0.15, l_b);
    const Result<Layout19TdLever> r = run<Layout19TdLever>(d, true);
    std::printf("Layout19TdLever, t_d 150 ms, lever [1 0.5 -1] m: t_d^ %.3f ms (sigma %.3f ms), lever "
                "[%.4f %.4f %.4f] m (sigma [%.4f %.4f %.4f]), %d updates\n",
                1e3 * r.td, 1e3 * r.sigma_td, r.lever[0], r.lever[1], r.lever[2], r.sigma_lever[0], r.sigma_lever[1],
                r.sigma_lever[2], r.updates);
    EXPECT_LT(std::abs(r.td - 0.15), 1e-3);
    EXPECT_LT((r.lever - l_b).cwiseAbs().maxCoeff(), 0.02);
    EXPECT_LT(500, r.updates);
    EXPECT_TRUE(r.heap == 0);
  }
  {
    const Drive d = make_drive(-0.2, Vec3::Zero());
    const Result<Layout16Td> r = run<Layout16Td>(d, true);
    std::printf("Layout16Td, t_d -200 ms: t_d^ %.3f ms (sigma %.3f ms)\n", 1e3 * r.td, 1e3 * r.sigma_td);
    EXPECT_LT(std::abs(r.td + 0.2), 1e-3);
  }
  TEST_MAIN_END();
}
