// RTS smoother backward pass (filter/rts_smoother.hpp) on a linear-Gaussian
// system against the batch least-squares solution of the same problem
// (the smoother's defining property: the fixed-interval MAP estimate and its
// marginal covariances), for the open-loop, the closed-loop and a mixed
// feedback schedule, with epochs that have no measurement (an outage); the
// last smoothed epoch equals the filtered one; no heap allocation in the pass.
#include <cstdio>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header
#include <Eigen/Dense>

#include "insnav/filter/rts_smoother.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

/// 1-D position, velocity and an accelerometer-bias-like random walk.
struct ToyLayout {
  static constexpr int kSize = 3;
};
using Vec = StateVec<ToyLayout>;
using Cov = StateCov<ToyLayout>;
constexpr int kN = 3;
using Meas = Eigen::Matrix<double, 1, kN>;

struct Problem {
  Cov F, Q, P0;
  Vec mu0;
  Meas H;
  double R = 0.0;
  std::vector<double> z;     // measurement per epoch
  std::vector<bool> has_z;   // false in the outage
};

Problem make_problem(int n_epochs, unsigned seed) {
  Problem p;
  const double dt = 1.0;
  p.F << 1, dt, -0.5 * dt * dt, 0, 1, -dt, 0, 0, 1;
  p.Q = Vec(0.01, 0.04, 1e-4).asDiagonal();
  p.Q(0, 1) = p.Q(1, 0) = 0.005;
  p.P0 = Vec(25.0, 1.0, 0.01).asDiagonal();
  p.mu0 = Vec(3.0, -1.0, 0.05);
  p.H << 1, 0, 0;
  p.R = 4.0;
  std::mt19937 rng(seed);
  std::normal_distribution<double> nd;
  Eigen::LLT<Cov> lq(p.Q), lp(p.P0);
  Vec x = p.mu0 + lp.matrixL() * Vec(nd(rng), nd(rng), nd(rng));
  for (int k = 0; k < n_epochs; ++k) {
    if (k > 0) x = p.F * x + lq.matrixL() * Vec(nd(rng), nd(rng), nd(rng));
    p.z.push_back((p.H * x)(0) + 2.0 * nd(rng));
    p.has_z.push_back(!(k >= 12 && k < 20) && k != 0);  // outage 12..19, none at 0
  }
  return p;
}

/// Batch MAP: minimise the prior, process and measurement quadratic forms over
/// all states at once; returns the stacked mean and the full covariance.
void batch(const Problem& p, Eigen::VectorXd& mean, Eigen::MatrixXd& cov) {
  const int n = static_cast<int>(p.z.size()), m = n * kN;
  Eigen::MatrixXd I = Eigen::MatrixXd::Zero(m, m);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(m);
  const Cov P0i = p.P0.inverse(), Qi = p.Q.inverse();
  I.topLeftCorner(kN, kN) += P0i;
  b.head(kN) += P0i * p.mu0;
  for (int k = 0; k + 1 < n; ++k) {
    // r = x_{k+1} - F x_k: J = [-F, I]
    Eigen::Matrix<double, kN, 2 * kN> J;
    J << -p.F, Cov::Identity();
    I.block(k * kN, k * kN, 2 * kN, 2 * kN) += J.transpose() * Qi * J;
  }
  for (int k = 0; k < n; ++k) {
    if (!p.has_z[k]) continue;
    I.block(k * kN, k * kN, kN, kN) += p.H.transpose() * p.H / p.R;
    b.segment(k * kN, kN) += p.H.transpose() * p.z[k] / p.R;
  }
  Eigen::LDLT<Eigen::MatrixXd> ldlt(I);
  mean = ldlt.solve(b);
  cov = ldlt.solve(Eigen::MatrixXd::Identity(m, m));
}

/// Forward error-state Kalman filter about a nominal (error = nominal - true),
/// feeding the estimate back when feedback(k) is true; records the epochs.
template <class FeedbackRule>
void forward(const Problem& p, FeedbackRule feedback, std::vector<SmootherEpoch<ToyLayout>>& rec,
             std::vector<Vec>& post_fb_nominal, std::vector<Vec>& filtered) {
  const int n = static_cast<int>(p.z.size());
  rec.assign(n, SmootherEpoch<ToyLayout>{});
  post_fb_nominal.assign(n, Vec::Zero());
  filtered.assign(n, Vec::Zero());
  Vec nominal = p.mu0 + Vec(1.0, 0.5, -0.02);  // a wrong nominal: the filter carries the difference
  Vec x = nominal - p.mu0;                      // prior error estimate of the nominal
  Cov P = p.P0;
  Vec r = x;                                    // what remains after the previous feedback
  Cov P_prev = P;
  for (int k = 0; k < n; ++k) {
    SmootherEpoch<ToyLayout>& e = rec[k];
    e.t = k;
    if (k > 0) {
      nominal = p.F * nominal;  // propagate the (post-feedback) nominal, no noise
      e.x_pred = p.F * r;
      e.P_pred = p.F * P_prev * p.F.transpose() + p.Q;
      e.C = P_prev * p.F.transpose();
      x = e.x_pred;
      P = e.P_pred;
    }
    if (p.has_z[k]) {
      const double y = (p.H * nominal)(0) - p.z[k];  // computed - measured = H e - v
      const double S = (p.H * P * p.H.transpose())(0) + p.R;
      const Vec K = P * p.H.transpose() / S;
      x += K * (y - (p.H * x)(0));
      P = (Cov::Identity() - K * p.H) * P * (Cov::Identity() - K * p.H).transpose() + K * p.R * K.transpose();
    }
    e.x = x;
    e.P = P;
    e.fed_back = feedback(k);
    filtered[k] = nominal - x;
    if (e.fed_back) {
      nominal -= x;
      r.setZero();
    } else {
      r = x;
    }
    post_fb_nominal[k] = nominal;
    P_prev = P;
  }
}

template <class FeedbackRule>
void check_against_batch(const char* name, FeedbackRule feedback) {
  const Problem p = make_problem(40, 7);
  Eigen::VectorXd bm;
  Eigen::MatrixXd bc;
  batch(p, bm, bc);
  std::vector<SmootherEpoch<ToyLayout>> rec;
  std::vector<Vec> m, filt;
  forward(p, feedback, rec, m, filt);
  std::vector<SmoothedEpoch<ToyLayout>> sm(rec.size());
  Eigen::internal::set_is_malloc_allowed(false);
  const SmootherStatus st = rts_backward(rec.data(), static_cast<std::int64_t>(rec.size()), sm.data());
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(st.gain_failures == 0);
  double worst_mean = 0.0, worst_cov = 0.0, gain = 0.0;
  const int n = static_cast<int>(rec.size());
  for (int k = 0; k < n; ++k) {
    const Vec smoothed = m[k] - sm[k].s;
    worst_mean = std::max(worst_mean, (smoothed - bm.segment<kN>(k * kN)).cwiseAbs().maxCoeff());
    worst_cov = std::max(worst_cov, (sm[k].P - bc.block<kN, kN>(k * kN, k * kN)).cwiseAbs().maxCoeff());
    gain = std::max(gain, rec[k].P(0, 0) / sm[k].P(0, 0));
  }
  std::printf("%s: max |smoothed - batch| mean %.3g, cov %.3g; max filtered/smoothed var %.2f\n", name,
              worst_mean, worst_cov, gain);
  EXPECT_LT(worst_mean, 1e-9);
  EXPECT_LT(worst_cov, 1e-9);
  EXPECT_LT(2.0, gain);  // the outage is where smoothing pays: > 2x smaller variance
  // no measurement after the last epoch: smoothed = filtered
  EXPECT_LT((m[n - 1] - sm[n - 1].s - filt[n - 1]).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((sm[n - 1].P - rec[n - 1].P).cwiseAbs().maxCoeff(), 1e-15);
}

}  // namespace

int main() {
  check_against_batch("open loop", [](int) { return false; });
  check_against_batch("closed loop", [](int) { return true; });
  check_against_batch("mixed feedback", [](int k) { return k % 3 == 1; });
  EXPECT_TRUE(g_eigen_asserts == 0);
  TEST_MAIN_END();
}
