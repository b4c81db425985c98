// RB-UKF and UKF (seed 000): UT exactness, time update vs the EKF for small
// errors, update forms vs the linear Kalman update, UKF vs RB-UKF for a linear
// h, outage recursion, Cholesky repair, and no heap allocation in the cycle.
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

// Count Eigen assertions (also in Release, where eigen_assert is normally off)
// so that EIGEN_RUNTIME_NO_MALLOC's check is live in every build type.
#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/core.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/kalman_update.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "insnav/meas/gnss_loose.hpp"
#include "fixtures.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

constexpr double kDeg = M_PI / 180.0;

/// A linear measurement: h(dx) = H dx.
template <class L>
struct LinMeas {
  LinearMeasurement<L> lin;
  const LinearMeasurement<L>& linear() const { return lin; }
  typename LinearMeasurement<L>::RowVec predicted_residual(const StateVec<L>& dx) const {
    typename LinearMeasurement<L>::RowVec z = lin.H * dx;
    return z;
  }
};

template <class L>
StateCov<L> typical_P0() {
  StateVec<L> s = StateVec<L>::Zero();
  s.template segment<3>(L::kPos) = Vec3(5.0, 5.0, 10.0);
  s.template segment<3>(L::kVel) = Vec3::Constant(0.2);
  s.template segment<3>(L::kAtt) = Vec3(1.0, 1.0, 3.0) * kDeg;
  s.template segment<3>(L::kAccBias) = Vec3::Constant(5e-2);
  s.template segment<3>(L::kGyroBias) = Vec3::Constant(20.0 * kDeg / 3600.0);
  if constexpr (kHasScale<L>) {
    s.template segment<3>(L::kAccScale) = Vec3::Constant(1e-3);
    s.template segment<3>(L::kGyroScale) = Vec3::Constant(1e-3);
  }
  if constexpr (kHasClock<L>) {
    s[L::kClockBias] = 10.0;
    s[L::kClockDrift] = 1.0;
  }
  return s.cwiseAbs2().asDiagonal();
}

template <class L>
StateCov<L> random_spd(std::mt19937& rng, double scale) {
  std::normal_distribution<double> nd;
  StateCov<L> A;
  for (int i = 0; i < L::kSize; ++i)
    for (int j = 0; j < L::kSize; ++j) A(i, j) = nd(rng);
  StateCov<L> P = scale * (A * A.transpose() / L::kSize + 0.1 * StateCov<L>::Identity());
  // give it navigation-like scales
  const StateCov<L> D = typical_P0<L>().diagonal().cwiseSqrt().asDiagonal();
  return D * P * D;
}


double rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).norm() / std::max(b.norm(), 1e-300); }

// --- 3. UT exactness --------------------------------------------------------
template <class L>
void test_ut_exactness() {
  constexpr int n = L::kSize;
  std::mt19937 rng(11);
  UtWeights<n> w{UtParams{}};
  double sm = w.w0m + 2 * n * w.wi, sc = w.w0c + 2 * n * w.wi;
  EXPECT_LT(std::abs(sm - 1.0), 1e-13);                                    // mean weights sum to 1
  EXPECT_LT(std::abs(sc - (2.0 - w.alpha * w.alpha + w.beta)), 1e-13);      // = 1 + (1 - a^2 + b)
  EXPECT_LT(std::abs(w.n_plus_lambda - 3.0), 1e-13);                       // kappa = 3 - n, alpha = 1
  for (double alpha : {1.0, 0.5, 1e-2}) {
    UtWeights<n> wa{UtParams{alpha, 2.0}};
    StateCov<L> P = random_spd<L>(rng, 1.0), Lf;
    StateVec<L> x = StateVec<L>::Random();
    SigmaPoints<n> chi, dev;
    draw_sigma_points<n>(x, P, wa, chi, Lf);
    // a linear map F: mean F x, covariance F P F^T exactly
    const StateCov<L> F = StateCov<L>::Identity() + 0.1 * StateCov<L>::Random();
    const SigmaPoints<n> y = F * chi;
    StateVec<L> mean;
    StateCov<L> Py;
    ut_mean<n, 2 * n + 1>(y, wa, mean);
    ut_covariance<n, 2 * n + 1>(y, mean, wa, dev, Py);
    EXPECT_LT(rel(mean, F * x), alpha < 0.1 ? 1e-7 : 1e-10);
    const StateCov<L> FPF = F * P * F.transpose();
    EXPECT_LT(rel(Py, FPF), alpha < 0.1 ? 1e-7 : 1e-12);  // small alpha: cancellation in huge W0
  }
  // after reset_state the cycle's points are centred at 0 (eq. (25))
  RbUkf<L> f(ImuErrorModel{});
  f.initialize(typical_P0<L>());
  f.begin_cycle();
  const auto& chi = f.sigma_points();
  EXPECT_TRUE(chi.col(0).isZero(0.0));
  EXPECT_LT((chi.rightCols(2 * n).rowwise().sum()).norm(), 1e-12);
  // the columns reproduce (n + lambda) P
  StateCov<L> S = StateCov<L>::Zero();
  for (int i = 1; i <= n; ++i) S += chi.col(i) * chi.col(i).transpose();
  EXPECT_LT(rel(S / f.weights().n_plus_lambda, typical_P0<L>()), 1e-12);
}

// --- time update vs the EKF for small errors ---------------------------------
template <class L>
void test_time_update_vs_ekf() {
  const auto ivs = make_intervals(50);  // one 1-s cycle of 20 ms intervals
  ImuErrorModel m;
  const StateCov<L> P0 = typical_P0<L>() * 1e-4;  // small errors: the linear model is accurate
  RbUkf<L> rb(m);
  Ekf<L> ekf(m);
  rb.initialize(P0);
  ekf.initialize(P0);
  rb.begin_cycle();
  ekf.begin_cycle();
  for (const auto& iv : ivs) {
    rb.propagate(iv);
    ekf.propagate(iv);
  }
  rb.end_cycle();
  ekf.end_cycle();
  const double r = rel(rb.P(), ekf.P());
  std::printf("L%d: one cycle, small errors: |P_rbukf - P_ekf| / |P_ekf| = %.3g, |x| = %.3g\n", L::kSize, r,
              rb.x().norm());
  EXPECT_LT(r, 1e-6);  // measured ~2e-8: the nonlinearity is second order in the spread
  // per-state sigmas agree to 1e-6
  const StateVec<L> ratio = rb.P().diagonal().cwiseSqrt().cwiseQuotient(ekf.P().diagonal().cwiseSqrt());
  EXPECT_LT((ratio - StateVec<L>::Ones()).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT(rb.x().template segment<3>(L::kAtt).norm(), 1e-6);  // mean stays ~0 (second order)
}

// --- 2. update forms vs the linear Kalman update ------------------------------
template <class L>
void test_update_forms() {
  constexpr int n = L::kSize;
  std::mt19937 rng(5);
  std::normal_distribution<double> nd;
  for (int trial = 0; trial < 6; ++trial) {
    const int rows = (trial % 3 == 0) ? 6 : ((trial % 3 == 1) ? 3 : 6);
    const int cols = (trial % 3 == 0) ? 6 : ((trial % 3 == 1) ? 9 : n);
    LinMeas<L> meas;
    meas.lin.residual.resize(rows);
    meas.lin.H.setZero(rows, n);
    meas.lin.R.setZero(rows, rows);
    for (int i = 0; i < rows; ++i) {
      meas.lin.residual[i] = 3.0 * nd(rng);
      if (trial % 3 == 0) meas.lin.H(i, i) = 1.0;
      else
        for (int j = 0; j < cols; ++j) meas.lin.H(i, j) = nd(rng);
      meas.lin.R(i, i) = 0.5 + std::abs(nd(rng));
    }
    meas.lin.n_cols = cols;
    const StateCov<L> P0 = random_spd<L>(rng, 1.0);
    StateVec<L> x0 = StateVec<L>::Zero();
    if (trial >= 3) x0 = 0.01 * StateVec<L>::Random();  // multi-step prediction (outage): x != 0

    // reference: the lead's Joseph update (EKF)
    StateVec<L> xr = x0;
    StateCov<L> Pr = P0;
    const UpdateResult rr = kalman_update<L>(xr, Pr, meas.lin, 0.0);
    EXPECT_TRUE(rr.applied);
    for (UpdateForm form : {UpdateForm::kDensePaper, UpdateForm::kDenseJoseph, UpdateForm::kBlockSparseJoseph,
                            UpdateForm::kBlockSparseFactored}) {
      RbUkf<L> f(ImuErrorModel{});
      f.initialize(P0);
      f.set_update_form(form);
      f.x_mutable() = x0;
      const UpdateResult res = f.update(meas, 0.0);
      EXPECT_TRUE(res.applied);
      EXPECT_LT(std::abs(res.nis - rr.nis), 1e-9 * (1.0 + rr.nis));
      EXPECT_LT(rel(f.x(), xr), 1e-9);
      EXPECT_LT(rel(f.P(), Pr), 1e-9);
      EXPECT_TRUE(f.P().isApprox(f.P().transpose(), 0.0));  // exactly symmetric
    }
    // gating: a 1e-3 gate rejects, nothing changes
    RbUkf<L> g(ImuErrorModel{});
    g.initialize(P0);
    const StateCov<L> Pg = g.P();
    const UpdateResult rg = g.update(meas, 1e-3);
    EXPECT_TRUE(rg.rejected_by_gate && !rg.applied);
    EXPECT_TRUE(g.P() == Pg);
  }
}

// --- UKF vs RB-UKF ---------------------------------------------------------
template <class L>
void test_ukf_vs_rbukf() {
  const auto ivs = make_intervals(50);
  ImuErrorModel m;
  RbUkf<L> rb(m);
  Ukf<L> uk(m);
  rb.initialize(typical_P0<L>());
  uk.initialize(typical_P0<L>());
  for (auto* f : {static_cast<UnscentedPropagation<L>*>(&rb), static_cast<UnscentedPropagation<L>*>(&uk)}) {
    f->begin_cycle();
    for (const auto& iv : ivs) f->propagate(iv);
    f->end_cycle();
  }
  EXPECT_TRUE(rb.P() == uk.P());  // the shared time update
  LinMeas<L> meas;
  meas.lin.residual.resize(6);
  meas.lin.residual << 4.0, -3.0, 6.0, 0.3, -0.2, 0.1;
  meas.lin.H.setZero(6, L::kSize);
  meas.lin.H.template leftCols<6>().setIdentity();
  meas.lin.R = (Eigen::Matrix<double, 6, 1>() << 25, 25, 100, 0.04, 0.04, 0.04).finished().asDiagonal();
  meas.lin.n_cols = 6;
  const UpdateResult a = rb.update(meas, 0.0), b = uk.update(meas, 0.0);
  EXPECT_TRUE(a.applied && b.applied);
  std::printf("L%d: UKF vs RB-UKF, linear h: |dx| rel %.3g, |dP| rel %.3g, NIS %.6g vs %.6g\n", L::kSize,
              rel(uk.x(), rb.x()), rel(uk.P(), rb.P()), b.nis, a.nis);
  EXPECT_LT(rel(uk.x(), rb.x()), 1e-9);
  EXPECT_LT(rel(uk.P(), rb.P()), 1e-9);
  EXPECT_LT(std::abs(a.nis - b.nis), 1e-9 * a.nis);

  // nonlinear h (lever arm, 10 deg yaw error in the state): the UKF differs
  // from the linear update, but stays close for a 1 m lever arm
  Ukf<L> uk2(m);
  RbUkf<L> rb2(m);
  StateCov<L> P = typical_P0<L>();
  uk2.initialize(P);
  rb2.initialize(P);
  LooseMeasurement<L> lm;
  NavState s;
  s.lat = 0.6;
  s.h = 100.0;
  s.v_n = Vec3(10, 0, 0);
  s.q_nb = quat_from_euler(Vec3(0.0, 0.0, 0.3));
  GnssFix fix;
  fix.lat = s.lat + 2.0 / 6.4e6;
  fix.h = s.h - 1.0;
  fix.v_n = Vec3(10.1, 0.05, 0.0);
  lm.set(s, Vec3(0, 0, 0.2), Vec3(1.0, 0.3, -0.5), fix);
  const UpdateResult c = uk2.update(lm, 0.0), d = rb2.update(lm, 0.0);
  EXPECT_TRUE(c.applied && d.applied);
  std::printf("L%d: UKF vs RB-UKF, lever-arm h: |dx| rel %.3g, |dP| rel %.3g\n", L::kSize, rel(uk2.x(), rb2.x()),
              rel(uk2.P(), rb2.P()));
  EXPECT_LT(rel(uk2.x(), rb2.x()), 0.05);
  EXPECT_LT(rel(uk2.P(), rb2.P()), 0.05);
}

// --- outage: recursive UT around a non-zero mean (eqs. (26)-(29)) -------------
template <class L>
void test_outage_recursion() {
  const auto ivs = make_intervals(100);
  ImuErrorModel m;
  RbUkf<L> f(m);
  StateCov<L> P0 = typical_P0<L>();
  f.initialize(P0);
  for (int cyc = 0; cyc < 2; ++cyc) {
    f.begin_cycle();
    if (cyc == 1) EXPECT_TRUE((f.sigma_points().col(0) - f.x()).norm() == 0.0);  // drawn around x
    for (int k = 0; k < 50; ++k) f.propagate(ivs[50 * cyc + k]);
    f.end_cycle();
  }
  // large attitude uncertainty: the second-order mean is non-zero and P grows
  EXPECT_LT(1e-6, f.x().norm());
  EXPECT_LT(P0(L::kPos, L::kPos), f.P()(L::kPos, L::kPos));
  EXPECT_TRUE(f.P().allFinite() && f.x().allFinite());
  Eigen::LLT<StateCov<L>> llt(f.P());
  EXPECT_TRUE(llt.info() == Eigen::Success);
}

// --- 4. Cholesky repair in the cycle ------------------------------------------
template <class L>
void test_repair_in_cycle() {
  StateCov<L> P = typical_P0<L>();
  P(L::kAtt + 2, L::kAtt + 2) = -1e-4;  // indefinite
  P(0, 1) = P(1, 0) = 40.0;             // |corr| > 1
  RbUkf<L> f(ImuErrorModel{});
  f.initialize(P);
  f.begin_cycle();
  EXPECT_TRUE(f.cholesky_repairs() == 1);
  EXPECT_TRUE(f.P().allFinite() && f.sigma_points().allFinite());
  Eigen::LLT<StateCov<L>> llt(f.P());
  EXPECT_TRUE(llt.info() == Eigen::Success);
  EXPECT_TRUE(f.P().isApprox(f.P().transpose(), 0.0));
  f.end_cycle();
  f.begin_cycle();
  EXPECT_TRUE(f.cholesky_repairs() == 1);  // repaired once, then healthy
  // NaN in P: repaired, never propagated
  StateCov<L> Pn = typical_P0<L>();
  Pn(3, 4) = NAN;
  Pn(5, 5) = INFINITY;
  f.initialize(Pn);
  f.begin_cycle();
  EXPECT_TRUE(f.cholesky_repairs() == 2);
  EXPECT_TRUE(f.P().allFinite() && f.sigma_points().allFinite());
}

// --- 5. no heap allocation --------------------------------------------------
template <class L>
void test_no_malloc() {
  const auto ivs = make_intervals(50);
  ImuErrorModel m;
  RbUkf<L> rb(m);
  Ukf<L> uk(m);
  LinMeas<L> meas;
  meas.lin.residual.resize(6);
  meas.lin.residual << 4.0, -3.0, 6.0, 0.3, -0.2, 0.1;
  meas.lin.H.setZero(6, L::kSize);
  meas.lin.H.template leftCols<6>().setIdentity();
  meas.lin.R = Eigen::Matrix<double, 6, 6>::Identity();
  meas.lin.n_cols = 6;
  LooseMeasurement<L> lm;
  NavState s;
  s.lat = 0.6;
  lm.set(s, Vec3(0, 0, 0.2), Vec3(1.0, 0.3, -0.5), GnssFix{});
  rb.initialize(typical_P0<L>());
  uk.initialize(typical_P0<L>());
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  for (UpdateForm form : {UpdateForm::kDensePaper, UpdateForm::kDenseJoseph, UpdateForm::kBlockSparseJoseph,
                          UpdateForm::kBlockSparseFactored}) {
    rb.set_update_form(form);
    rb.begin_cycle();
    for (const auto& iv : ivs) rb.propagate(iv);
    rb.end_cycle();
    rb.update(meas, 0.0);
    rb.update(lm, 100.0);
    rb.reset_state();
  }
  for (int k = 0; k < 2; ++k) {
    uk.begin_cycle();
    for (const auto& iv : ivs) uk.propagate(iv);
    uk.end_cycle();
    uk.update(meas, 0.0);
    uk.update(lm, 0.0);  // a second update in the same epoch redraws the points
    uk.reset_state();
  }
  StateCov<L> bad = typical_P0<L>();
  bad(0, 0) = -1.0;
  repair_covariance<L::kSize>(bad);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);
}

void test_malloc_check_is_live() {
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  Eigen::MatrixXd M(40, 40);  // must trip the check
  Eigen::internal::set_is_malloc_allowed(true);
  M.setZero();
  EXPECT_TRUE(g_eigen_asserts == before + 1);
  g_eigen_asserts = before;
}

}  // namespace

int main() {
  test_malloc_check_is_live();
  test_ut_exactness<Layout15>();
  test_ut_exactness<Layout21>();
  test_time_update_vs_ekf<Layout15>();
  test_time_update_vs_ekf<Layout17>();
  test_time_update_vs_ekf<Layout21>();
  test_update_forms<Layout15>();
  test_update_forms<Layout17>();
  test_update_forms<Layout21>();
  test_ukf_vs_rbukf<Layout15>();
  test_ukf_vs_rbukf<Layout21>();
  test_outage_recursion<Layout15>();
  test_repair_in_cycle<Layout15>();
  test_repair_in_cycle<Layout21>();
  test_no_malloc<Layout15>();
  test_no_malloc<Layout17>();
  test_no_malloc<Layout21>();
  TEST_MAIN_END()
}
