// Vehicle constraints (meas/vehicle.hpp): every analytic Jacobian H against a
// central-difference derivative of the exact residual predicted_residual(dx)
// (NHC, odometer, ZUPT, ZARU; a mounting rotation and a lever arm), the
// residual sign (computed minus measured), and what each constraint sees:
// a sideways velocity error shows in the NHC rows, an attitude error of a
// moving vehicle too, a stationary vehicle's velocity in ZUPT.
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include "insnav/core.hpp"
#include "insnav/filter/layout.hpp"
#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/error_model_nonlinear.hpp"
#include "insnav/meas/vehicle.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

template <class M, class L = Layout21>
double jacobian_error(const M& meas) {
  const auto& lin = meas.linear();
  double worst = 0.0;
  for (int j = 0; j < L::kSize; ++j) {
    const double h = (j >= L::kAtt && j < L::kAtt + 3) ? 1e-6
                     : (j >= L::kGyroBias && j < L::kGyroBias + 3) ? 1e-7
                     : j == OdoScaleState<L>::offset ? 1e-6
                                                     : 1e-4;
    StateVec<L> dx = StateVec<L>::Zero();
    dx[j] = h;
    const auto rp = meas.predicted_residual(dx);
    dx[j] = -h;
    const auto rm = meas.predicted_residual(dx);
    for (int i = 0; i < lin.rows(); ++i) {
      const double num = (rp[i] - rm[i]) / (2 * h);
      const double scale = std::max(1.0, std::abs(lin.H(i, j)));
      worst = std::max(worst, std::abs(num - lin.H(i, j)) / scale);
    }
  }
  return worst;
}

NavState moving_state() {
  NavState s;
  s.lat = 30.5 * M_PI / 180;
  s.lon = 114.4 * M_PI / 180;
  s.h = 20.0;
  s.q_nb = quat_from_euler(Vec3(0.03, -0.02, 0.8));
  s.v_n = s.q_nb.toRotationMatrix() * Vec3(15.0, 0.0, 0.0) + Vec3(0.0, 0.0, 0.0);
  return s;
}

void test_jacobians() {
  VehicleConstraintConfig cfg;
  cfg.C_bv = dcm_from_euler(Vec3(0.01, 0.02, -0.03));
  cfg.lever_arm_b = Vec3(-1.2, 0.3, 0.8);
  const NavState s = moving_state();
  const Vec3 w(0.01, -0.02, 0.15);
  VehicleVelocityMeasurement<Layout21> v;
  v.set(s, w, cfg, true, 14.8);
  EXPECT_TRUE(v.linear().rows() == 3);
  const double ev = jacobian_error(v);
  std::printf("NHC + odometer: max relative |H - numerical| %.2e\n", ev);
  EXPECT_LT(ev, 1e-5);
  v.set(s, w, cfg, true, std::numeric_limits<double>::quiet_NaN());
  EXPECT_TRUE(v.linear().rows() == 2);
  EXPECT_LT(jacobian_error(v), 1e-6);

  NavState still = s;
  still.v_n = Vec3(0.002, -0.001, 0.0005);
  StandstillMeasurement<Layout21> z;
  z.set(still, Vec3(1e-5, 2e-5, -3e-5), cfg, true, true);
  EXPECT_TRUE(z.linear().rows() == 6);
  const double ez = jacobian_error(z);
  std::printf("ZUPT + ZARU: max relative |H - numerical| %.2e\n", ez);
  EXPECT_LT(ez, 1e-6);
}

void test_residuals() {
  VehicleConstraintConfig cfg;  // aligned IMU at the rear axle
  NavState s = moving_state();
  const Mat3 C_nb = s.q_nb.toRotationMatrix();
  // a 0.5 m/s sideways velocity error of the INS shows as +0.5 in the lateral row
  s.v_n += C_nb * Vec3(0.0, 0.5, 0.0);
  VehicleVelocityMeasurement<Layout15> v;
  v.set(s, Vec3::Zero(), cfg, true, 15.0);
  EXPECT_LT(std::abs(v.linear().residual[0] - 0.0), 1e-9);  // forward speed matches the odometer
  EXPECT_LT(std::abs(v.linear().residual[1] - 0.5), 1e-9);
  EXPECT_LT(std::abs(v.linear().residual[2]), 1e-9);
  // a heading error psi_z of a vehicle moving at 15 m/s: lateral residual ~ -15 psi_z
  // (H_att row: -C_vn [v_n x])
  const double h_yaw = v.linear().H(1, Layout15::kAtt + 2);
  std::printf("NHC lateral d/dpsi_z at 15 m/s: %.3f\n", h_yaw);
  EXPECT_LT(std::abs(std::abs(h_yaw) - 15.0), 0.5);
  // ZUPT residual is the INS velocity
  NavState still = s;
  still.v_n = Vec3(0.1, -0.2, 0.05);
  StandstillMeasurement<Layout15> z;
  z.set(still, Vec3::Zero(), cfg, true, false);
  EXPECT_LT((z.linear().residual.head<3>() - still.v_n).norm(), 1e-12);
}

/// The odometer row with the scale-factor state (Layout16Odo): H against the
/// numerical derivative of the exact residual (the scale column included), the
/// column's value -(1 + s^) v_fwd, the residual in reading units, and the
/// scale-free layouts' rows unchanged.
void test_odo_scale_row() {
  using L = Layout16Odo;
  VehicleConstraintConfig cfg;
  cfg.C_bv = dcm_from_euler(Vec3(0.01, 0.02, -0.03));
  cfg.lever_arm_b = Vec3(-1.2, 0.3, 0.8);
  const NavState s = moving_state();
  const Vec3 w(0.01, -0.02, 0.15);
  const double s_hat = 2.5e-3;  // fed-back estimate
  VehicleVelocityMeasurement<L> v;
  v.set(s, w, cfg, true, 14.8, s_hat);
  EXPECT_TRUE(v.linear().rows() == 3);
  EXPECT_TRUE(v.linear().n_cols == L::kOdoScale + 1);
  const double e = jacobian_error<VehicleVelocityMeasurement<L>, L>(v);
  std::printf("NHC + odometer with the scale state: max relative |H - numerical| %.2e\n", e);
  EXPECT_LT(e, 1e-5);
  // the scale column alone, odometer only, larger s^
  v.set(s, w, cfg, false, 15.2, -0.02);
  EXPECT_TRUE(v.linear().rows() == 1);
  EXPECT_LT((jacobian_error<VehicleVelocityMeasurement<L>, L>(v)), 1e-6);
  StateVec<L> dx = StateVec<L>::Zero();
  const double h = 1e-6;
  dx[L::kOdoScale] = h;
  const double num = (v.predicted_residual(dx)[0] - v.predicted_residual(-dx)[0]) / (2 * h);
  std::printf("d r / d s_odo: analytic %.9f numerical %.9f\n", v.linear().H(0, L::kOdoScale), num);
  EXPECT_LT(std::abs(num - v.linear().H(0, L::kOdoScale)), 1e-7);
  // value: -(1 + s^) times the INS forward speed of the constrained point
  const Vec3 v_v = vehicle_detail::point_velocity_v(s.q_nb.toRotationMatrix(), s.v_n, w,
                                                    wgs84::omega_ie_n(s.lat) +
                                                        wgs84::omega_en_n(s.lat, s.h, s.v_n, wgs84::radii(s.lat)),
                                                    cfg);
  EXPECT_LT(std::abs(v.linear().H(0, L::kOdoScale) + (1.0 - 0.02) * v_v[0]), 1e-12);
  // a reading (1 + s^) v_fwd of an error-free INS gives a zero residual
  v.set(s, w, cfg, false, (1.0 - 0.02) * v_v[0], -0.02);
  EXPECT_LT(std::abs(v.linear().residual[0]), 1e-12);
  // a layout without the state: the same NHC / odometer rows as before (s^ = 0, no column)
  VehicleVelocityMeasurement<Layout15> v15;
  v15.set(s, w, cfg, true, 14.8);
  v.set(s, w, cfg, true, 14.8, 0.0);
  EXPECT_TRUE(v15.linear().n_cols == Layout15::kGyroBias + 3);
  EXPECT_LT((v15.linear().residual - v.linear().residual).norm(), 1e-15);
  EXPECT_LT((v15.linear().H - v.linear().H.leftCols<15>()).norm(), 1e-15);
}

/// The nonlinear error model's rate of the scale state against linear_F
/// (s' = -s / tau), and no coupling into the navigation errors.
void test_odo_scale_model() {
  using L = Layout16Odo;
  ImuErrorModel m;
  m.odo_scale_tau = 600.0;
  InsPoint p;
  p.set(0.5, 100.0, Vec3(10.0, 2.0, 0.1), dcm_from_euler(Vec3(0.02, 0.01, 0.3)), Vec3(0.3, 0.1, -9.8),
        Vec3(0.001, 0.002, 0.05));
  const StateCov<L> F = linear_F<L>(p, m);
  EXPECT_LT(std::abs(F(L::kOdoScale, L::kOdoScale) + 1.0 / 600.0), 1e-15);
  EXPECT_TRUE(F.col(L::kOdoScale).head<15>().isZero(0.0) && F.row(L::kOdoScale).head<15>().isZero(0.0));
  const StateCov<L> Qc = continuous_GQG<L>(p, m);
  EXPECT_LT(std::abs(Qc(L::kOdoScale, L::kOdoScale) - 2.0 * 0.01 * 0.01 / 600.0), 1e-18);
  StateVec<L> dx = StateVec<L>::Zero();
  dx[L::kOdoScale] = 4e-3;
  const StateVec<L> r = nonlinear_error_rate<L>(dx, p, m);
  EXPECT_LT(std::abs(r[L::kOdoScale] + 4e-3 / 600.0), 1e-18);
  const StateVec<L> r0 = nonlinear_error_rate<L>(StateVec<L>::Zero(), p, m);
  EXPECT_LT((r - r0).head<15>().norm(), 1e-15);
  m.odo_scale_tau = kInf;  // random constant
  EXPECT_TRUE(linear_F<L>(p, m)(L::kOdoScale, L::kOdoScale) == 0.0);
  EXPECT_TRUE(continuous_GQG<L>(p, m)(L::kOdoScale, L::kOdoScale) == 0.0);
  EXPECT_TRUE(nonlinear_error_rate<L>(dx, p, m)[L::kOdoScale] == 0.0);
}

}  // namespace

// The second-order term of the NHC / odometer rows (add_second_order_noise):
// the covariance of z' M_i z / 2 it adds to R, with M_i from the mixed second
// difference d^2 r_i / (d psi d dv) of the exact residual predicted_residual,
// under a correlated covariance of [dv; psi] (so the signs of the cross-row
// and dv-psi terms matter).  Catches a wrong axis, sign or odometer gain.
void test_second_order_noise() {
  using L = Layout21;
  VehicleConstraintConfig cfg;
  cfg.C_bv = dcm_from_euler(Vec3(0.01, 0.02, -0.03));
  const NavState s = moving_state();
  const Vec3 w(0.01, -0.02, 0.15);
  StateCov<L> P = StateCov<L>::Zero();
  Eigen::Matrix<double, 6, 6> A;  // a fixed, well-conditioned correlated covariance of [dv; psi]
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) A(i, j) = std::sin(1.0 + 3.0 * i + 7.0 * j);
  Eigen::Matrix<double, 6, 6> Pz = A * A.transpose() + 6.0 * Eigen::Matrix<double, 6, 6>::Identity();
  Pz.topRows<3>() *= 0.5;  // dv [m/s]
  Pz.leftCols<3>() *= 0.5;
  Pz.bottomRows<3>() *= 0.01;  // psi [rad]
  Pz.rightCols<3>() *= 0.01;
  P.block<3, 3>(L::kVel, L::kVel) = Pz.topLeftCorner<3, 3>();
  P.block<3, 3>(L::kVel, L::kAtt) = Pz.topRightCorner<3, 3>();
  P.block<3, 3>(L::kAtt, L::kVel) = Pz.bottomLeftCorner<3, 3>();
  P.block<3, 3>(L::kAtt, L::kAtt) = Pz.bottomRightCorner<3, 3>();
  P.diagonal().tail<L::kSize - 9>().setConstant(1e-6);  // the other states do not enter
  for (const bool odo : {false, true}) {
    VehicleVelocityMeasurement<L> v;
    v.set(s, w, cfg, true, odo ? 14.8 : std::numeric_limits<double>::quiet_NaN(), odo ? 0.02 : 0.0);
    const auto R0 = v.linear().R;
    const int m = v.linear().rows();
    // numerical M_i (6 x 6 over [dv; psi]) from the mixed differences of the exact residual
    std::vector<Eigen::Matrix<double, 6, 6>> M(m, Eigen::Matrix<double, 6, 6>::Zero());
    const double hv = 1e-3, ha = 1e-5;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        auto r = [&](double sa, double sb) {
          StateVec<L> dx = StateVec<L>::Zero();
          dx[L::kAtt + a] = sa * ha;
          dx[L::kVel + b] = sb * hv;
          return v.predicted_residual(dx);
        };
        const typename LinearMeasurement<L>::RowVec d = (r(1, 1) - r(1, -1) - r(-1, 1) + r(-1, -1)) / (4.0 * ha * hv);
        for (int i = 0; i < m; ++i) {
          M[i](3 + a, b) = d[i];
          M[i](b, 3 + a) = d[i];
        }
      }
    v.add_second_order_noise(P);
    const typename LinearMeasurement<L>::RMat dR = v.linear().R - R0;
    double worst = 0.0, scale = 0.0;
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < m; ++j) {
        const double want = 0.5 * (M[i] * Pz * M[j] * Pz).trace();
        worst = std::max(worst, std::abs(dR(i, j) - want));
        scale = std::max(scale, std::abs(want));
      }
    std::printf("second-order noise (%s): max |dR - tr(M_i P M_j P)/2| %.2e of %.2e\n",
                odo ? "NHC + odometer" : "NHC", worst, scale);
    EXPECT_TRUE(scale > 1e-6);
    EXPECT_LT(worst, 1e-4 * scale);
    EXPECT_LT((dR - dR.transpose()).cwiseAbs().maxCoeff(), 1e-15);
    // time-correlation scales: NHC rows 4, odometer row 9, cross terms sqrt(4 * 9)
    VehicleVelocityMeasurement<L> vs;
    vs.set(s, w, cfg, true, odo ? 14.8 : std::numeric_limits<double>::quiet_NaN(), odo ? 0.02 : 0.0);
    vs.add_second_order_noise(P, 4.0, 9.0);
    const typename LinearMeasurement<L>::RMat dRs = vs.linear().R - R0;
    for (int i = 0; i < m; ++i)
      for (int j = 0; j < m; ++j) {
        const double si = (odo && i == 0) ? 3.0 : 2.0, sj = (odo && j == 0) ? 3.0 : 2.0;
        EXPECT_LT(std::abs(dRs(i, j) - si * sj * dR(i, j)), 1e-12 * scale);
      }
  }
}

int main() {
  test_jacobians();
  test_second_order_noise();
  test_odo_scale_row();
  test_odo_scale_model();
  test_residuals();
  TEST_MAIN_END();
}
