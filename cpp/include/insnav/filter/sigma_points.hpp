// insnav/filter/sigma_points.hpp -- scaled unscented transform: parameters,
// weights, symmetric sigma points, weighted mean and covariance.
//
// seed 000 eqs. (9), (11)-(13), (25):
//   lambda = alpha^2 (n + kappa) - n,  1e-4 <= alpha <= 1,  kappa = 3 - n,  beta = 2
//   chi_0 = x,  chi_i = x + (sqrt((n + lambda) P))_i,  chi_{n+i} = x - (sqrt((n + lambda) P))_i
//   W0m = lambda / (n + lambda),  W0c = W0m + 1 - alpha^2 + beta,  Wi = 1 / (2 (n + lambda))
// (the paper prints lambda / (2 (n + lambda)) for Wi, a typo: the weights must sum to 1).
// The square root is the lower Cholesky factor.  With the seed defaults
// (alpha = 1, kappa = 3 - n) n + lambda = 3 and the centre weights are negative
// (W0m = 1 - n/3); the transform is still exact for linear maps, and a
// covariance that loses definiteness through a strongly nonlinear step is
// repaired by covariance.hpp.
#pragma once

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "insnav/filter/covariance.hpp"

namespace insnav {

/// UT scaling parameters.  kappa = NaN means the seed 000 default 3 - n.
struct UtParams {
  double alpha = 1.0;
  double beta = 2.0;
  double kappa = std::numeric_limits<double>::quiet_NaN();
};

/// Weights of the 2n+1 symmetric sigma points of an n-dimensional state.
template <int N>
struct UtWeights {
  double lambda = 0.0;
  double n_plus_lambda = 0.0;
  double w0m = 0.0, w0c = 0.0, wi = 0.0;
  double alpha = 1.0, beta = 2.0;

  UtWeights() = default;
  explicit UtWeights(const UtParams& p) { set(p); }

  void set(const UtParams& p) {
    alpha = p.alpha;
    beta = p.beta;
    const double kappa = std::isnan(p.kappa) ? 3.0 - N : p.kappa;
    lambda = alpha * alpha * (N + kappa) - N;
    n_plus_lambda = N + lambda;
    if (!(n_plus_lambda > 0.0))  // sqrt((n + lambda) P) and the weights 1 / (2 (n + lambda)) need it
      throw std::invalid_argument("ut_kappa = " + std::to_string(kappa) + ", ut_alpha = " + std::to_string(alpha) +
                                  ": the unscented transform needs alpha^2 (n + kappa) > 0 (n = " +
                                  std::to_string(N) + " sigma-point dimensions)");
    w0m = lambda / n_plus_lambda;
    w0c = w0m + 1.0 - alpha * alpha + beta;
    wi = 1.0 / (2.0 * n_plus_lambda);
  }
  double mean_weight(int i) const { return i == 0 ? w0m : wi; }
  double cov_weight(int i) const { return i == 0 ? w0c : wi; }
};

template <int N>
using SigmaPoints = Eigen::Matrix<double, N, 2 * N + 1>;

/// chi = [x, x + S_i, x - S_i] with S the given square-root factor already
/// scaled by sqrt(n + lambda) (eq. (9); eq. (25) when x = 0).
template <int N>
inline void sigma_points_from_factor(const Eigen::Matrix<double, N, 1>& x, const SquareMat<N>& S_scaled,
                                     SigmaPoints<N>& chi) {
  chi.col(0) = x;
  for (int i = 0; i < N; ++i) {
    chi.col(1 + i) = x + S_scaled.col(i);
    chi.col(1 + N + i) = x - S_scaled.col(i);
  }
}

/// Draw the sigma points of (x, P) with the Cholesky factor of (n + lambda) P;
/// P is repaired in place if it is not positive definite.  Returns the number
/// of repairs (0 or 1).
template <int N>
int draw_sigma_points(const Eigen::Matrix<double, N, 1>& x, SquareMat<N>& P, const UtWeights<N>& w,
                      SigmaPoints<N>& chi, SquareMat<N>& work_factor, const RepairOptions& opt = {}) {
  const int repairs = cholesky_with_repair<N>(P, work_factor, opt);
  work_factor *= std::sqrt(w.n_plus_lambda);
  sigma_points_from_factor<N>(x, work_factor, chi);
  return repairs;
}

/// Weighted mean, eq. (11).
template <int N, int M>
inline void ut_mean(const Eigen::Matrix<double, N, M>& pts, const UtWeights<(M - 1) / 2>& w,
                    Eigen::Matrix<double, N, 1>& mean) {
  mean = w.w0m * pts.col(0);
  Eigen::Matrix<double, N, 1> s = pts.col(1);
  for (int i = 2; i < M; ++i) s += pts.col(i);
  mean += w.wi * s;
}

/// Weighted covariance about `mean`, eq. (12) without Q:
/// sum_i Wc_i (pts_i - mean)(pts_i - mean)^T.  `dev` is a workspace.
template <int N, int M>
inline void ut_covariance(const Eigen::Matrix<double, N, M>& pts, const Eigen::Matrix<double, N, 1>& mean,
                          const UtWeights<(M - 1) / 2>& w, Eigen::Matrix<double, N, M>& dev, SquareMat<N>& P) {
  dev = pts.colwise() - mean;
  const Eigen::Matrix<double, N, 1> d0 = dev.col(0);
  // Wi * D_{1..} D_{1..}^T + W0c d0 d0^T
  P.noalias() = w.wi * dev.template rightCols<M - 1>() * dev.template rightCols<M - 1>().transpose();
  P.noalias() += w.w0c * d0 * d0.transpose();
}

}  // namespace insnav
