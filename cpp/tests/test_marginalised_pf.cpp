// The marginalised (Rao-Blackwellised) particle filter of particle_filter.hpp
// (Schön, Gustafsson, Nordlund 2005) on a linear measurement, where its update
// has a closed form: every particle's linear substate s (position, velocity,
// clock, accelerometer bias) takes the Kalman update with the one shared
// covariance, K = P_s H_s^T (H_s P_s H_s^T + R)^-1, its nonlinear substate r
// (attitude, gyro biases) is left alone, and its weight is the predictive
// likelihood N(z; h(r_i, s_i), H_s P_s H_s^T + R).  Awkward cases: a single
// particle, a single satellite (2 rows: no sensor resetting possible), a huge
// measurement noise (the update reduces to the prior), a measurement no
// particle explains (with 4 satellites: sensor resetting of the Kalman means);
// no heap allocation in the update.
#include <cstdio>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/filter/layout20.hpp"
#include "insnav/filter/particle_filter.hpp"
#include "fixtures.hpp"
#include "test_util.hpp"

using namespace insnav;
using L = Layout20;
constexpr int kN = L::kSize;
using Vec = StateVec<L>;
using Cov = StateCov<L>;

namespace {

constexpr double kDeg = M_PI / 180.0;

/// A linear stand-in for meas/pseudorange.hpp: predicted_residual(x) = H x.
struct LinearMeas {
  LinearMeasurement<L> lin;
  const LinearMeasurement<L>& linear() const { return lin; }
  LinearMeasurement<L>::RowVec predicted_residual(const Vec& x) const { return lin.H * x; }
};

/// One satellite: a pseudorange row (position, clock bias, and -- as with a
/// lever arm -- attitude) and a rate row (velocity, clock drift, attitude).
LinearMeas one_satellite(double sigma_pr_m, double sigma_prr_mps, double pr_res_m, double prr_res_mps) {
  LinearMeas m;
  m.lin.residual.resize(2);
  m.lin.residual << pr_res_m, prr_res_mps;
  m.lin.H.setZero(2, kN);
  const Vec3 u_n = Vec3(0.3, -0.5, -0.8).normalized();
  m.lin.H.block<1, 3>(0, L::kPos) = -u_n.transpose();
  m.lin.H(0, L::kClockBias) = 1.0;
  m.lin.H.block<1, 3>(0, L::kAtt) = Vec3(200.0, -100.0, 300.0).transpose();  // large: the weights must differ
  m.lin.H.block<1, 3>(1, L::kVel) = -u_n.transpose();
  m.lin.H(1, L::kClockDrift) = 1.0;
  m.lin.H.block<1, 3>(1, L::kAtt) = Vec3(-5.0, 2.0, 8.0).transpose();
  m.lin.R.setZero(2, 2);
  m.lin.R(0, 0) = sigma_pr_m * sigma_pr_m;
  m.lin.R(1, 1) = sigma_prr_mps * sigma_prr_mps;
  return m;
}

ImuErrorModel model() {
  ImuErrorModel m;
  m.gyro_arw = Vec3::Constant(4.85e-6);
  m.acc_vrw = Vec3::Constant(2e-4);
  return m;
}

/// The reference: the Kalman update of the linear substate given r, with the
/// prior covariance of s (P0 is diagonal, so P_s = P0_ss).
struct Reference {
  Eigen::Matrix<double, 11, Eigen::Dynamic> K;
  Eigen::Matrix<double, 11, 11> P_post;
  Eigen::MatrixXd S;
};

Reference kalman_reference(const LinearMeas& m, const Cov& P0) {
  constexpr auto idx = ParticleFilter<L>::linear_index();
  const int rows = m.lin.rows();
  Eigen::MatrixXd Hs(rows, 11);
  Eigen::Matrix<double, 11, 11> Ps;
  for (int a = 0; a < 11; ++a) {
    Hs.col(a) = m.lin.H.col(idx[a]);
    for (int b = 0; b < 11; ++b) Ps(a, b) = P0(idx[a], idx[b]);
  }
  Reference ref;
  ref.S = Hs * Ps * Hs.transpose() + Eigen::MatrixXd(m.lin.R);
  ref.K = Ps * Hs.transpose() * ref.S.inverse();  // reference only: inverse() is fine here
  ref.P_post = (Eigen::Matrix<double, 11, 11>::Identity() - ref.K * Hs) * Ps;
  return ref;
}

void test_single_particle_is_kalman() {
  constexpr auto idx = ParticleFilter<L>::linear_index();
  ParticleParams pp;
  pp.particles = 1;
  const Cov P0 = seed004_typical_P0();
  const LinearMeas m = one_satellite(15.0, 0.1, 12.0, 0.3);
  ParticleFilter<L> pf(model(), pp);
  pf.initialize(P0);
  Eigen::internal::set_is_malloc_allowed(false);
  const UpdateResult r = pf.update(m, 0.0);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(r.applied);
  const Reference ref = kalman_reference(m, P0);
  const Eigen::Matrix<double, 11, 1> s_ref = ref.K * m.lin.residual;  // x^- = 0
  double es = 0.0, eP = 0.0, er = 0.0;
  for (int a = 0; a < 11; ++a) {
    es = std::max(es, std::abs(pf.x()[idx[a]] - s_ref[a]) / (std::abs(s_ref[a]) + 1e-12));
    for (int b = 0; b < 11; ++b)
      eP = std::max(eP, std::abs(pf.P()(idx[a], idx[b]) - ref.P_post(a, b)) / std::sqrt(P0(idx[a], idx[a]) * P0(idx[b], idx[b])));
  }
  for (int k = L::kAtt; k < L::kClockBias; ++k)
    if (k < L::kAccBias || k >= L::kAccBias + 3) er = std::max(er, std::abs(pf.x()[k]));
  std::printf("N = 1, one satellite: |s - s_Kalman| rel %.2e, |P_s - P_Kalman| rel %.2e, |r| %.2e\n", es, eP, er);
  EXPECT_LT(es, 1e-9);
  EXPECT_LT(eP, 1e-9);
  EXPECT_TRUE(er == 0.0);  // r is sampled, never updated by the Kalman step
  EXPECT_TRUE(pf.divergences() == 0 && pf.reseeds() == 0);
}

void test_huge_noise_is_the_prior() {
  ParticleParams pp;
  pp.particles = 50;
  pp.resample_threshold = 0.0;
  const Cov P0 = seed004_typical_P0();
  ParticleFilter<L> pf(model(), pp);
  pf.initialize(P0);
  const std::vector<Vec> before = pf.particle_states();
  const Cov P_before = pf.P();
  const LinearMeas m = one_satellite(1e9, 1e9, 12.0, 0.3);
  pf.update(m, 0.0);
  double dx = 0.0, dw = 0.0;
  for (int i = 0; i < 50; ++i) {
    dx = std::max(dx, (pf.particle_states()[i] - before[i]).cwiseAbs().maxCoeff());
    dw = std::max(dw, std::abs(pf.weights()[i] - 1.0 / 50));
  }
  const double dP = (pf.P() - P_before).cwiseAbs().maxCoeff() / P_before.cwiseAbs().maxCoeff();
  std::printf("R -> inf: particles moved %.2e, weights off uniform %.2e, P changed %.2e (rel)\n", dx, dw, dP);
  EXPECT_LT(dx, 1e-12);
  EXPECT_LT(dw, 1e-12);
  EXPECT_LT(dP, 1e-12);
}

void test_weights_are_predictive_likelihoods() {
  constexpr auto idx = ParticleFilter<L>::linear_index();
  const int n = 40;
  ParticleParams pp;
  pp.particles = n;
  pp.seed = 3;
  pp.resample_threshold = 0.0;  // no resampling: the weights stay visible
  Cov P0 = seed004_typical_P0();
  P0.block<3, 3>(L::kAtt, L::kAtt) *= 400.0;  // 10-20 deg of attitude: the particles' h(x_i) differ by metres
  const LinearMeas m = one_satellite(15.0, 0.1, 12.0, 0.3);
  ParticleFilter<L> pf(model(), pp);
  pf.initialize(P0);
  const std::vector<Vec> before = pf.particle_states();
  Eigen::internal::set_is_malloc_allowed(false);
  pf.update(m, 0.0);
  Eigen::internal::set_is_malloc_allowed(true);
  const Reference ref = kalman_reference(m, P0);
  const Eigen::LLT<Eigen::MatrixXd> llt(ref.S);
  std::vector<double> lw(n), w(n);
  double es = 0.0;
  for (int i = 0; i < n; ++i) {
    const Eigen::VectorXd g = m.lin.residual - m.lin.H * before[i];
    lw[i] = -0.5 * g.dot(llt.solve(g));
    const Eigen::Matrix<double, 11, 1> ds = ref.K * g;
    for (int a = 0; a < 11; ++a)
      es = std::max(es, std::abs(pf.particle_states()[i][idx[a]] - before[i][idx[a]] - ds[a]) / (std::abs(ds[a]) + 1e-9));
  }
  normalize_log_weights(lw.data(), w.data(), n);
  double ew = 0.0, wmax = 0.0;
  for (int i = 0; i < n; ++i) {
    ew = std::max(ew, std::abs(pf.weights()[i] - w[i]));
    wmax = std::max(wmax, w[i]);
  }
  std::printf("N = %d: weights vs N(z; h(x_i), H_s P_s H_s' + R) %.2e (largest weight %.3f), means %.2e\n", n, ew,
              wmax, es);
  EXPECT_LT(ew, 1e-12);
  EXPECT_LT(es, 1e-8);
  EXPECT_TRUE(wmax > 1.5 / n);  // the test means something: the weights are not uniform
}

void test_unexplained_measurement_one_satellite() {
  // no particle within chi2 25 per row; 2 rows cannot reset the cloud (8 needed): counted, and the
  // Kalman update is applied all the same
  ParticleParams pp;
  pp.particles = 5;
  const Cov P0 = seed004_typical_P0();
  const LinearMeas m = one_satellite(15.0, 0.1, 5000.0, 30.0);
  ParticleFilter<L> pf(model(), pp);
  pf.initialize(P0);
  const UpdateResult r = pf.update(m, 0.0);
  EXPECT_TRUE(r.applied);
  EXPECT_TRUE(pf.divergences() == 1 && pf.reseeds() == 0);
  EXPECT_TRUE(pf.x().allFinite() && pf.P().allFinite());
  EXPECT_TRUE(std::abs(pf.x()[L::kClockDrift]) > 1.0);  // the rate pulled the drift towards the measurement
}

void test_reset_four_satellites() {
  // 4 satellites (8 rows) and a measurement no particle explains: sensor resetting puts the linear means of
  // position, velocity and clock on the measurement's solution given r (no draw) and P_s's block on its
  // covariance A^-1, A = H_s' R^-1 H_s; the weights become uniform
  constexpr auto idx = ParticleFilter<L>::linear_index();
  LinearMeas m;
  m.lin.residual.resize(8);
  m.lin.H.setZero(8, kN);
  m.lin.R.setZero(8, 8);
  const Vec3 u[4] = {Vec3(0.3, -0.5, -0.8).normalized(), Vec3(-0.6, 0.2, -0.7).normalized(),
                     Vec3(0.1, 0.9, -0.4).normalized(), Vec3(-0.2, -0.3, -0.95).normalized()};
  for (int k = 0; k < 4; ++k) {
    m.lin.H.block<1, 3>(k, L::kPos) = -u[k].transpose();
    m.lin.H(k, L::kClockBias) = 1.0;
    m.lin.H(k, L::kAtt + 2) = 3.0;
    m.lin.H.block<1, 3>(4 + k, L::kVel) = -u[k].transpose();
    m.lin.H(4 + k, L::kClockDrift) = 1.0;
    m.lin.R(k, k) = 15.0 * 15.0;
    m.lin.R(4 + k, 4 + k) = 0.1 * 0.1;
    m.lin.residual[k] = 3000.0 + 100.0 * k;
    m.lin.residual[4 + k] = 20.0 - 3.0 * k;
  }
  ParticleParams pp;
  pp.particles = 8;
  ParticleFilter<L> pf(model(), pp);
  pf.initialize(seed004_typical_P0());
  const std::vector<Vec> before = pf.particle_states();
  Eigen::internal::set_is_malloc_allowed(false);
  const UpdateResult r = pf.update(m, 0.0);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(r.applied && pf.divergences() == 1 && pf.reseeds() == 1);
  Eigen::MatrixXd Hs(8, 8), Wi = Eigen::MatrixXd(m.lin.R).inverse();
  for (int a = 0; a < 8; ++a) Hs.col(a) = m.lin.H.col(idx[a]);
  const Eigen::MatrixXd Ainv = (Hs.transpose() * Wi * Hs).inverse();
  double es = 0.0, eP = 0.0, ew = 0.0;
  for (int i = 0; i < 8; ++i) {
    Vec x_r = before[i];
    for (int a = 0; a < 8; ++a) x_r[idx[a]] = 0.0;
    const Eigen::VectorXd s_ls = Ainv * Hs.transpose() * Wi * (Eigen::VectorXd(m.lin.residual) - m.lin.H * x_r);
    for (int a = 0; a < 8; ++a)
      es = std::max(es, std::abs(pf.particle_states()[i][idx[a]] - s_ls[a]) / (std::abs(s_ls[a]) + 1e-9));
    ew = std::max(ew, std::abs(pf.weights()[i] - 1.0 / 8));
  }
  const auto& Ps = pf.linear_covariance();
  for (int a = 0; a < 8; ++a)
    for (int b = 0; b < 11; ++b)
      eP = std::max(eP, std::abs(Ps(a, b) - (b < 8 ? Ainv(a, b) : 0.0)) / std::sqrt(Ainv(a, a) * Ps(b, b)));
  std::printf("reset, 4 satellites: means vs least squares %.2e, P_s vs A^-1 %.2e, weights %.2e\n", es, eP, ew);
  EXPECT_LT(es, 1e-8);
  EXPECT_LT(eP, 1e-9);
  EXPECT_LT(ew, 1e-15);
}

}  // namespace

int main() {
  test_single_particle_is_kalman();
  test_huge_noise_is_the_prior();
  test_weights_are_predictive_likelihoods();
  test_unexplained_measurement_one_satellite();
  test_reset_four_satellites();
  EXPECT_TRUE(g_eigen_asserts == 0);
  TEST_MAIN_END()
}
