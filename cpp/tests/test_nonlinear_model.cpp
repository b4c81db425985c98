// The nonlinear error model (seed 000 eqs. (1)-(7)) against the difference of
// two full strapdown mechanizations, and its linearisation against linear_F.
#include <cstdio>

#include "insnav/core.hpp"
#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/error_model_nonlinear.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

constexpr double kDeg = M_PI / 180.0;

/// Error state (computed - true) between two navigation states, in the
/// layout's conventions: NED metres with the computed radii, Euler platform
/// error angles psi with dcm_from_euler(psi) = C_{n n'} = C_nb C~_nb^T.
template <class L>
void nav_error(const NavState& comp, const NavState& truth, StateVec<L>& dx) {
  const wgs84::Radii r = wgs84::radii(comp.lat);
  dx[L::kPos] = (comp.lat - truth.lat) * (r.R_M + comp.h);
  dx[L::kPos + 1] = (comp.lon - truth.lon) * (r.R_N + comp.h) * std::cos(comp.lat);
  dx[L::kPos + 2] = -(comp.h - truth.h);
  dx.template segment<3>(L::kVel) = comp.v_n - truth.v_n;
  const Mat3 C_n_np = truth.q_nb.toRotationMatrix() * comp.q_nb.toRotationMatrix().transpose();
  dx.template segment<3>(L::kAtt) = euler_from_dcm(C_n_np);
}

/// Computed initial state from the truth and an error (dr, dv, psi).
NavState perturb(const NavState& truth, const Vec3& dr, const Vec3& dv, const Vec3& psi) {
  NavState c = truth;
  c.h = truth.h - dr.z();
  c.lat = truth.lat;
  for (int it = 0; it < 5; ++it) {  // dr_N = dL (R_M(L~) + h~)
    const wgs84::Radii r = wgs84::radii(c.lat);
    c.lat = truth.lat + dr.x() / (r.R_M + c.h);
  }
  const wgs84::Radii r = wgs84::radii(c.lat);
  c.lon = truth.lon + dr.y() / ((r.R_N + c.h) * std::cos(c.lat));
  c.v_n = truth.v_n + dv;
  // C~ = C_{n'n} C = dcm_from_euler(psi)^T C
  c.q_nb = (Quat(dcm_from_euler(psi).transpose()) * truth.q_nb).normalized();
  return c;
}

struct Scenario {
  double seconds = 10.0;
  double imu_dt = 0.01;
  int samples_per_step = 2;  // RK4 step = 2 IMU samples (start, mid, end)
  Vec3 omega_b{0.01, -0.005, 0.1};  // turning [rad/s]
  Vec3 f_b{1.0, 0.5, -9.81};        // accelerating [m/s^2]
  Vec3 dr0{30.0, -20.0, 10.0}, dv0{1.0, -0.7, 0.4}, psi0{2.0 * kDeg, -2.0 * kDeg, 10.0 * kDeg};
  Vec3 ba{0.05, -0.04, 0.03}, bg{2e-3, -1.5e-3, 1e-3};
  Vec3 sa{0.0, 0.0, 0.0}, sg{0.0, 0.0, 0.0};
};

struct Outcome {
  double att_nl = 0, vel_nl = 0, pos_nl = 0;  // max |nonlinear - mechanization difference|
  double att_lin = 0, vel_lin = 0, pos_lin = 0;
  double att_err = 0, vel_err = 0;  // max |error| itself (scale)
};

template <class L>
Outcome run(const Scenario& sc) {
  NavState truth;
  truth.lat = 0.6;
  truth.lon = 1.9;
  truth.h = 200.0;
  truth.v_n = Vec3(15.0, -3.0, 0.2);
  truth.q_nb = quat_from_euler(Vec3(0.05, -0.03, 1.0));
  const NavState comp0 = perturb(truth, sc.dr0, sc.dv0, sc.psi0);
  Strapdown ins_true(truth), ins_comp(comp0);

  ImuErrorModel model;
  model.acc_bias_tau = Vec3::Constant(kInf);  // the biases of this run are constant
  model.gyro_bias_tau = Vec3::Constant(kInf);
  model.acc_scale_tau = Vec3::Constant(kInf);
  model.gyro_scale_tau = Vec3::Constant(kInf);

  StateVec<L> dx_nl = StateVec<L>::Zero();
  nav_error<L>(comp0, truth, dx_nl);
  dx_nl.template segment<3>(L::kAccBias) = sc.ba;
  dx_nl.template segment<3>(L::kGyroBias) = sc.bg;
  if constexpr (kHasScale<L>) {
    dx_nl.template segment<3>(L::kAccScale) = sc.sa;
    dx_nl.template segment<3>(L::kGyroScale) = sc.sg;
  }
  if constexpr (kHasClock<L>) {
    dx_nl[L::kClockBias] = 3.0;
    dx_nl[L::kClockDrift] = 0.5;
  }
  StateVec<L> dx_lin = dx_nl;
  const double clock0 = kHasClock<L> ? 3.0 : 0.0;

  // measured increments of the computed INS: meas = (1 + s) true + b
  const Vec3 f_meas = (Vec3::Ones() + sc.sa).cwiseProduct(sc.f_b) + sc.ba;
  const Vec3 w_meas = (Vec3::Ones() + sc.sg).cwiseProduct(sc.omega_b) + sc.bg;
  auto point = [&](const Strapdown& s, InsPoint& p) {
    const NavState& n = s.state();
    p.set(n.lat, n.h, n.v_n, n.q_nb.toRotationMatrix(), f_meas, w_meas);
  };
  InsPoint pts[3];
  point(ins_comp, pts[0]);
  NonlinearErrorPoint np[3];
  const int n_steps = static_cast<int>(std::lround(sc.seconds / (sc.imu_dt * sc.samples_per_step)));
  Outcome o;
  double t = 0.0;
  for (int k = 0; k < n_steps; ++k) {
    for (int j = 1; j <= sc.samples_per_step; ++j) {
      ImuIncrement tr, cm;
      t += sc.imu_dt;
      tr.t = cm.t = t;
      tr.dt = cm.dt = sc.imu_dt;
      tr.dtheta_b = sc.omega_b * sc.imu_dt;
      tr.dv_b = sc.f_b * sc.imu_dt;
      cm.dtheta_b = w_meas * sc.imu_dt;
      cm.dv_b = f_meas * sc.imu_dt;
      ins_true.update(tr);
      ins_comp.update(cm);
      if (j == sc.samples_per_step / 2) point(ins_comp, pts[1]);
    }
    point(ins_comp, pts[2]);
    const double dt = sc.imu_dt * sc.samples_per_step;
    for (int i = 0; i < 3; ++i) np[i].set(pts[i], model);
    rk4_error_step<L>(dx_nl, np[0], np[1], np[2], dt);
    const StateCov<L> Phi = transition<L>(linear_F<L>(pts[1], model), dt);
    dx_lin = Phi * dx_lin;
    pts[0] = pts[2];

    StateVec<L> ref = StateVec<L>::Zero();
    nav_error<L>(ins_comp.state(), ins_true.state(), ref);
    const auto seg = [](const StateVec<L>& a, const StateVec<L>& b, int off) {
      return (a.template segment<3>(off) - b.template segment<3>(off)).norm();
    };
    o.att_nl = std::max(o.att_nl, seg(dx_nl, ref, L::kAtt));
    o.vel_nl = std::max(o.vel_nl, seg(dx_nl, ref, L::kVel));
    o.pos_nl = std::max(o.pos_nl, seg(dx_nl, ref, L::kPos));
    o.att_lin = std::max(o.att_lin, seg(dx_lin, ref, L::kAtt));
    o.vel_lin = std::max(o.vel_lin, seg(dx_lin, ref, L::kVel));
    o.pos_lin = std::max(o.pos_lin, seg(dx_lin, ref, L::kPos));
    o.att_err = std::max(o.att_err, ref.template segment<3>(L::kAtt).norm());
    o.vel_err = std::max(o.vel_err, ref.template segment<3>(L::kVel).norm());
    // sensor states stay constant (tau = inf); the clock integrates its drift
    EXPECT_LT((dx_nl.template segment<3>(L::kGyroBias) - sc.bg).norm(), 1e-15);
    if constexpr (kHasClock<L>) EXPECT_LT(std::abs(dx_nl[L::kClockBias] - (clock0 + 0.5 * t)), 1e-9);
  }
  return o;
}

template <class L>
void check_mechanization_difference(const char* name, const Scenario& sc) {
  const Outcome o = run<L>(sc);
  std::printf("%s: |nonlinear - mech diff| att %.3g rad, vel %.3g m/s, pos %.3g m; "
              "linear att %.3g, vel %.3g, pos %.3g (max |psi| %.3g, |dv| %.3g)\n",
              name, o.att_nl, o.vel_nl, o.pos_nl, o.att_lin, o.vel_lin, o.pos_lin, o.att_err, o.vel_err);
  // second-order agreement over 10 s (measured: ~1e-12 rad, ~1e-6 m/s, ~1e-5 m)
  EXPECT_LT(o.att_nl, 1e-9);
  EXPECT_LT(o.vel_nl, 1e-5);
  EXPECT_LT(o.pos_nl, 1e-4);
  EXPECT_LT(10.0 * o.att_nl, o.att_lin);  // the linear model is >= 10x worse
  EXPECT_LT(10.0 * o.vel_nl, o.vel_lin);
}

/// Small errors: the nonlinear model's Jacobian at dx = 0 (central
/// differences) equals linear_F, and the rate at 0 is 0.
template <class L>
void check_jacobian(const char* name) {
  InsPoint p;
  p.set(0.7, 350.0, Vec3(20.0, -8.0, 0.5), dcm_from_euler(Vec3(0.1, -0.2, 2.0)), Vec3(0.6, -0.4, -9.7),
        Vec3(0.02, -0.03, 0.15));
  ImuErrorModel m;
  const StateVec<L> zero = StateVec<L>::Zero();
  const StateVec<L> f0 = nonlinear_error_rate<L>(zero, p, m);
  EXPECT_LT(f0.norm(), 1e-15);
  const StateCov<L> F = linear_F<L>(p, m);
  StateCov<L> J;
  for (int j = 0; j < L::kSize; ++j) {
    double h = 1e-6;
    if (j >= L::kPos && j < L::kPos + 3) h = 1e-2;
    if (j >= L::kVel && j < L::kVel + 3) h = 1e-4;
    StateVec<L> e = zero;
    e[j] = h;
    J.col(j) = (nonlinear_error_rate<L>(e, p, m) - nonlinear_error_rate<L>(-e, p, m)) / (2.0 * h);
  }
  // block-wise relative agreement
  const int blocks[] = {L::kPos, L::kVel, L::kAtt, L::kAccBias, L::kGyroBias};
  double worst = 0.0;
  for (int bi : blocks)
    for (int bj : blocks) {
      const double scale = std::max(F.template block<3, 3>(bi, bj).norm(), 1e-12);
      const double d = (J.template block<3, 3>(bi, bj) - F.template block<3, 3>(bi, bj)).norm();
      const double rel = d / scale;
      if (rel > 1e-3 && d > 1e-9) std::printf("  %s: d(rate_%d)/d(x_%d) differs: |J - F| = %.3g, |F| = %.3g\n",
                                              name, bi, bj, d, scale);
      worst = std::max(worst, std::min(rel, d / 1e-9));
    }
  std::printf("%s: worst block mismatch of the numerical Jacobian vs linear_F: %.3g\n", name, worst);
  // the attitude/velocity blocks that drive the filter must agree tightly
  EXPECT_LT((J.template block<3, 3>(L::kAtt, L::kAtt) - F.template block<3, 3>(L::kAtt, L::kAtt)).norm(), 1e-10);
  EXPECT_LT((J.template block<3, 3>(L::kVel, L::kAtt) - F.template block<3, 3>(L::kVel, L::kAtt)).norm(), 1e-6);
  EXPECT_LT((J.template block<3, 3>(L::kVel, L::kAccBias) - F.template block<3, 3>(L::kVel, L::kAccBias)).norm(), 1e-9);
  EXPECT_LT((J.template block<3, 3>(L::kAtt, L::kGyroBias) - F.template block<3, 3>(L::kAtt, L::kGyroBias)).norm(), 1e-9);
  EXPECT_LT((J.template block<3, 3>(L::kPos, L::kVel) - F.template block<3, 3>(L::kPos, L::kVel)).norm(), 1e-9);
  if constexpr (kHasScale<L>) {
    EXPECT_LT((J.template block<3, 3>(L::kVel, L::kAccScale) - F.template block<3, 3>(L::kVel, L::kAccScale)).norm(), 1e-8);
    EXPECT_LT((J.template block<3, 3>(L::kAtt, L::kGyroScale) - F.template block<3, 3>(L::kAtt, L::kGyroScale)).norm(), 1e-9);
  }
}

}  // namespace

int main() {
  Scenario sc;
  check_mechanization_difference<Layout15>("Layout15 (10 deg yaw, 2 deg tilt, 30 m, 1 m/s)", sc);
  check_mechanization_difference<Layout17>("Layout17", sc);
  Scenario s21 = sc;
  s21.sa = Vec3(2e-3, -3e-3, 1e-3);
  s21.sg = Vec3(-4e-3, 2e-3, 5e-3);
  check_mechanization_difference<Layout21>("Layout21 (+ scale factors)", s21);
  check_jacobian<Layout15>("Layout15");
  check_jacobian<Layout21>("Layout21");
  TEST_MAIN_END()
}
