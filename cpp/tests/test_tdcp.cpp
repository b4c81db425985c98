// TDCP stochastic-cloning update (meas/tdcp.hpp): the marginalised update of
// x_k equals the Kalman update of the explicit clone-augmented state
// [x_k; x_c] with covariance [[P, Phi P_prev], [(Phi P_prev)^T, P_prev]]
// (Roumeliotis & Burdick 2002, sec. III), and it runs without heap allocation.
#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include <Eigen/Cholesky>
#include <random>

#include "insnav/core.hpp"
#include "insnav/meas/tdcp.hpp"
#include "test_util.hpp"

using namespace insnav;
using L = Layout17;
constexpr int N = L::kSize;

int main() {
  std::mt19937 gen(7);
  std::normal_distribution<double> nd(0.0, 1.0);
  auto rnd_spd = [&](double scale) {
    StateCov<L> A;
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < N; ++j) A(i, j) = nd(gen);
    StateCov<L> P = scale * (A * A.transpose() / N + 0.1 * StateCov<L>::Identity());
    return P;
  };
  const StateCov<L> P_prev = rnd_spd(1.0);
  StateCov<L> Phi = StateCov<L>::Identity();
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) Phi(i, j) += 0.05 * nd(gen);
  const StateCov<L> Q = 0.01 * rnd_spd(1.0);
  StateCov<L> P = Phi * P_prev * Phi.transpose() + Q;
  const StateCov<L> Phi_P_prev = Phi * P_prev;

  // rows: random lines of sight, a lever arm
  TdcpUpdate<L> up;
  up.clear();
  const int m = 6;
  Eigen::Matrix<double, m, 2 * N> Ha = Eigen::Matrix<double, m, 2 * N>::Zero();
  Eigen::Matrix<double, m, 1> y, r;
  for (int i = 0; i < m; ++i) {
    TdcpRow<L> row;
    for (int j = 0; j < N; ++j) {
      row.H_cur[j] = (j < 9 || j == L::kClockBias) ? nd(gen) : 0.0;
      row.H_prev[j] = (j < 9 || j == L::kClockBias) ? nd(gen) : 0.0;
    }
    y[i] = 0.1 * nd(gen);
    r[i] = 1e-4 * (1.0 + i);
    up.add(row, y[i], r[i]);
    Ha.row(i).head<N>() = row.H_cur;
    Ha.row(i).tail<N>() = row.H_prev;
  }
  // explicit augmented update (x = 0, clone mean 0)
  Eigen::Matrix<double, 2 * N, 2 * N> Pa;
  Pa << P, Phi_P_prev, Phi_P_prev.transpose(), P_prev;
  const Eigen::Matrix<double, m, m> S = Ha * Pa * Ha.transpose() + Eigen::Matrix<double, m, 1>(r).asDiagonal().toDenseMatrix();
  const Eigen::Matrix<double, 2 * N, m> K = Pa * Ha.transpose() * S.inverse();
  const Eigen::Matrix<double, 2 * N, 1> xa = K * y;
  const Eigen::Matrix<double, 2 * N, 2 * N> Pa_post = Pa - K * S * K.transpose();

  StateVec<L> x = StateVec<L>::Zero();
  StateCov<L> Pk = P;
  Eigen::internal::set_is_malloc_allowed(false);
  const bool ok = up.covariance(Pk, Phi_P_prev, P_prev);
  double nis = 0.0;
  if (ok) nis = up.apply(x, Pk);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(ok);
  EXPECT_TRUE(g_eigen_asserts == 0);
  for (int i = 0; i < m; ++i) EXPECT_LT(std::abs(up.S(i) - S(i, i)), 1e-9 * S(i, i));
  EXPECT_LT((x - xa.head<N>()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((Pk - Pa_post.topLeftCorner<N, N>()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(std::abs(nis - y.dot(S.inverse() * y)), 1e-8 * nis);
  // select(): dropping rows 1 and 4 equals the update with the 4 others
  TdcpUpdate<L> up2;
  for (int i = 0; i < m; ++i) {
    TdcpRow<L> row;
    row.H_cur = Ha.row(i).head<N>();
    row.H_prev = Ha.row(i).tail<N>();
    up2.add(row, y[i], r[i]);
  }
  const bool keep[m] = {true, false, true, true, false, true};
  up2.select(keep);
  EXPECT_TRUE(up2.rows() == 4);
  EXPECT_LT(std::abs(up2.residual(2) - y[3]), 1e-15);
  TEST_MAIN_END()
}
