// Covariance health (covariance.hpp): symmetrise, repair indefinite and
// non-finite matrices, semi-definite square root.
#include <random>

#include "insnav/filter/covariance.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {
constexpr int N = 15;
using M = SquareMat<N>;

bool is_pd(const M& P) {
  Eigen::LLT<M> llt(P);
  return llt.info() == Eigen::Success;
}

M random_spd(std::mt19937& rng) {
  std::normal_distribution<double> nd;
  M A;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) A(i, j) = nd(rng);
  return A * A.transpose() + 0.1 * M::Identity();
}
}  // namespace

int main() {
  std::mt19937 rng(3);
  // a healthy P is left alone (symmetrised only)
  M P = random_spd(rng);
  M P0 = P;
  EXPECT_TRUE(!repair_covariance<N>(P));
  EXPECT_LT((P - P0).norm(), 1e-12 * P0.norm());

  // indefinite: one negative eigenvalue of -5 -> clamped to the floor, the rest kept
  Eigen::SelfAdjointEigenSolver<M> es(random_spd(rng));
  Eigen::Matrix<double, N, 1> lam = es.eigenvalues();
  lam[0] = -5.0;
  M Pi = es.eigenvectors() * lam.asDiagonal() * es.eigenvectors().transpose();
  Pi(2, 7) += 1e-9;  // and slightly asymmetric
  EXPECT_TRUE(!is_pd(Pi));
  EXPECT_TRUE(repair_covariance<N>(Pi));
  EXPECT_TRUE(is_pd(Pi));
  EXPECT_TRUE(Pi.isApprox(Pi.transpose(), 0.0));
  Eigen::SelfAdjointEigenSolver<M> es2(Pi);
  EXPECT_LT(0.0, es2.eigenvalues()[0]);
  EXPECT_LT(es2.eigenvalues()[0], 1e-10 * es2.eigenvalues()[N - 1]);
  EXPECT_LT((es2.eigenvalues().tail<N - 1>() - lam.tail<N - 1>()).norm(), 1e-10 * lam.norm());  // the rest kept

  // non-finite entries: repaired, finite, PD
  M Pn = random_spd(rng);
  Pn(1, 4) = NAN;
  Pn(4, 1) = NAN;
  Pn(6, 6) = INFINITY;
  Pn(9, 3) = -INFINITY;
  EXPECT_TRUE(repair_covariance<N>(Pn));
  EXPECT_TRUE(Pn.allFinite());
  EXPECT_TRUE(is_pd(Pn));
  M Pall = M::Constant(NAN);
  EXPECT_TRUE(repair_covariance<N>(Pall));
  EXPECT_TRUE(Pall.allFinite() && is_pd(Pall));

  // cholesky_with_repair counts one repair and returns a factor of the repaired P
  M Pz = M::Zero(), Lf;
  EXPECT_TRUE(cholesky_with_repair<N>(Pz, Lf) == 1);
  EXPECT_TRUE(Lf.allFinite());
  EXPECT_LT((Lf * Lf.transpose() - Pz).norm(), 1e-12);
  M Pg = random_spd(rng);
  EXPECT_TRUE(cholesky_with_repair<N>(Pg, Lf) == 0);
  EXPECT_LT((Lf * Lf.transpose() - Pg).norm(), 1e-12 * Pg.norm());

  // semi-definite square root: zero rows/columns and decades of scale
  M Q = M::Zero();
  Eigen::Matrix<double, N, 1> d;
  for (int i = 0; i < N; ++i) d[i] = (i % 4 == 3) ? 0.0 : std::pow(10.0, -i);
  M B = random_spd(rng);
  Q = d.asDiagonal() * B * d.asDiagonal();
  M S;
  psd_cholesky_lower<N>(Q, S);
  EXPECT_TRUE(S.allFinite());
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      const double scale = std::sqrt(std::abs(Q(i, i) * Q(j, j))) + 1e-300;
      EXPECT_LT(std::abs((S * S.transpose())(i, j) - Q(i, j)) / scale, 1e-10);
    }
  TEST_MAIN_END()
}
