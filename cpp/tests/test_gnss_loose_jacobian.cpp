// The loose GNSS measurement (meas/gnss_loose.hpp) with a lever arm: H against
// the numerical derivative of the exact residual.  The exact residual of an
// error dx (computed minus true, the feedback convention of closed_loop.hpp)
// is the INS antenna minus the antenna of the true state: position through
// ECEF (independent of the model's small-difference form), velocity
// v_n + C_nb (w_ib_b x l_b) - w_in_n x (C_nb l_b) of the true state with the
// true rate w_ib_b - dw.  Also: predicted_residual(dx), the nonlinear form the
// UKF uses, equals the exact residual to second order.
#include <cmath>
#include <cstdio>

#include "insnav/earth/wgs84.hpp"
#include "insnav/meas/gnss_loose.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

using L = Layout21;

NavState ins_state() {
  NavState s;
  s.lat = 0.61;
  s.lon = 1.93;
  s.h = 310.0;
  s.v_n = Vec3(14.0, -6.0, 0.4);
  s.q_nb = quat_from_euler(Vec3(0.08, -0.05, 2.2));
  return s;
}

/// The true state for an error dx (INS minus true): the feedback of closed_loop.hpp.
NavState true_state(const NavState& ins, const StateVec<L>& dx) {
  NavState s = ins;
  const wgs84::Radii r = wgs84::radii(ins.lat);
  s.lat -= dx[L::kPos] / (r.R_M + ins.h);
  s.lon -= dx[L::kPos + 1] / ((r.R_N + ins.h) * std::cos(s.lat));
  s.h += dx[L::kPos + 2];
  s.v_n -= dx.segment<3>(L::kVel);
  s.q_nb = (quat_from_euler(dx.segment<3>(L::kAtt)) * ins.q_nb).normalized();
  return s;
}

/// A fix at the antenna of `s` (position via ECEF; velocity of the lever arm with rate w).
GnssFix antenna_fix(const NavState& s, const Vec3& w_ib_b, const Vec3& l_b) {
  const Mat3 C_nb = s.q_nb.toRotationMatrix();
  const Vec3 r_e = wgs84::geodetic_to_ecef(s.lat, s.lon, s.h) + wgs84::C_en(s.lat, s.lon) * (C_nb * l_b);
  const Vec3 llh = wgs84::ecef_to_geodetic(r_e);
  const wgs84::Radii r = wgs84::radii(s.lat);
  const Vec3 w_in_n = wgs84::omega_ie_n(s.lat) + wgs84::omega_en_n(s.lat, s.h, s.v_n, r);
  GnssFix f;
  f.lat = llh[0];
  f.lon = llh[1];
  f.h = llh[2];
  f.v_n = s.v_n + C_nb * w_ib_b.cross(l_b) - w_in_n.cross(C_nb * l_b);
  return f;
}

}  // namespace

int main() {
  const NavState ins = ins_state();
  const Vec3 w(0.02, -0.03, 0.25), l_b(1.2, -0.4, -1.6);
  // the residual the measurement forms for the INS against the true state's antenna
  auto residual = [&](const StateVec<L>& dx) {
    const NavState tru = true_state(ins, dx);
    const Vec3 w_true = w - dx.segment<3>(L::kGyroBias);
    LooseMeasurement<L> m;
    m.set(ins, w, l_b, antenna_fix(tru, w_true, l_b));
    return Eigen::Matrix<double, 6, 1>(m.linear().residual);
  };
  LooseMeasurement<L> m;
  m.set(ins, w, l_b, antenna_fix(ins, w, l_b));
  const auto& H = m.linear().H;
  EXPECT_LT(residual(StateVec<L>::Zero()).head<3>().norm(), 1e-6);  // no error: the fix is the antenna
  double worst = 0.0;
  for (int j = 0; j < L::kSize; ++j) {
    const double step = (j >= L::kAtt && j < L::kAtt + 3) ? 1e-4 : (j >= L::kGyroBias && j < L::kGyroBias + 3) ? 1e-6 : 1e-3;
    StateVec<L> dp = StateVec<L>::Zero(), dm = StateVec<L>::Zero();
    dp[j] = step;
    dm[j] = -step;
    const Eigen::Matrix<double, 6, 1> col = (residual(dp) - residual(dm)) / (2 * step);
    for (int i = 0; i < 6; ++i) {
      const double scale = std::max(1.0, std::abs(H(i, j)));
      worst = std::max(worst, std::abs(H(i, j) - col[i]) / scale);
    }
  }
  std::printf("loose GNSS rows with lever arm: max relative |H - numerical| %.2e\n", worst);
  EXPECT_LT(worst, 2e-5);
  // the lever-arm columns are there (not a zero H passing trivially)
  const double h_att = H.block<3, 3>(0, L::kAtt).norm(), h_bg = H.block<3, 3>(3, L::kGyroBias).norm();
  EXPECT_LT(1.0, h_att);
  EXPECT_LT(0.1, h_bg);
  // predicted_residual (nonlinear) against the exact residual for a finite error
  StateVec<L> dx = StateVec<L>::Zero();
  dx.segment<3>(L::kPos) = Vec3(0.4, -0.3, 0.2);
  dx.segment<3>(L::kVel) = Vec3(0.05, 0.02, -0.03);
  dx.segment<3>(L::kAtt) = Vec3(0.01, -0.02, 0.05);
  dx.segment<3>(L::kGyroBias) = Vec3(1e-3, -2e-3, 5e-4);
  const Eigen::Matrix<double, 6, 1> exact = residual(dx);
  const Eigen::Matrix<double, 6, 1> pred = m.predicted_residual(dx);
  const double e_nl = (exact - pred).norm(), e_lin = (exact - H * dx).norm();
  std::printf("finite error: |exact - predicted_residual| %.2e, |exact - H dx| %.2e\n", e_nl, e_lin);
  EXPECT_LT(e_nl, 0.2 * e_lin);  // the nonlinear form captures the lever-arm rotation the linear one misses
  EXPECT_LT(e_nl, 2e-3);
  TEST_MAIN_END();
}
