// insnav/filter/resampling.hpp -- particle weights and resampling: log-weight
// normalisation, effective sample size, systematic resampling, the cloud and
// weighted covariances, and roughening (shared by ParticleFilter and Upf).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "insnav/filter/covariance.hpp"
#include "insnav/filter/random.hpp"
#include "insnav/filter/types.hpp"

#ifdef _OPENMP
#include <omp.h>
/// Loops over particles run in parallel when compiled with -fopenmp.
#define INSNAV_PARALLEL_FOR _Pragma("omp parallel for schedule(static)")
#else
#define INSNAV_PARALLEL_FOR
#endif

namespace insnav {

// --- weights -------------------------------------------------------------------

/// Normalise log-weights into weights summing to 1 (log-sum-exp); returns
/// false (and sets uniform weights) if every log-weight is -inf or NaN.
inline bool normalize_log_weights(const double* logw, double* w, int n) {
  double mx = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < n; ++i)
    if (std::isfinite(logw[i])) mx = std::max(mx, logw[i]);
  if (!std::isfinite(mx)) {
    for (int i = 0; i < n; ++i) w[i] = 1.0 / n;
    return false;
  }
  double s = 0.0;
  for (int i = 0; i < n; ++i) {
    w[i] = std::isfinite(logw[i]) ? std::exp(logw[i] - mx) : 0.0;
    s += w[i];
  }
  for (int i = 0; i < n; ++i) w[i] /= s;
  return true;
}

/// Effective sample size N_eff = 1 / sum w_i^2 of normalised weights.
inline double effective_sample_size(const double* w, int n) {
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += w[i] * w[i];
  return s > 0.0 ? 1.0 / s : 0.0;
}

/// Systematic resampling (Kitagawa 1996): one uniform u0 in [0, 1/N), index
/// of the points u0 + j/N in the cumulative weights.  O(N); idx has n entries.
inline void systematic_resample(const double* w, int n, double u0_unit, int* idx) {
  const double step = 1.0 / n;
  double u = u0_unit * step, c = w[0];
  int i = 0;
  for (int j = 0; j < n; ++j) {
    while (u > c && i < n - 1) c += w[++i];
    idx[j] = i;
    u += step;
  }
}

/// Unweighted mean and covariance of a particle cloud (the shape of the
/// roughening kernel: unlike the weighted covariance it does not collapse
/// when one particle takes all the weight).
template <class L>
void cloud_covariance(const std::vector<StateVec<L>>& xs, int n, StateCov<L>& P) {
  StateVec<L> m = StateVec<L>::Zero();
  for (int i = 0; i < n; ++i) m += xs[i];
  m /= n;
  P.setZero();
  for (int i = 0; i < n; ++i) {
    const StateVec<L> d = xs[i] - m;
    P.noalias() += d * d.transpose();
  }
  P /= std::max(n - 1, 1);
}

// --- weighted estimate ----------------------------------------------------------

template <class L>
void weighted_mean_cov(const std::vector<StateVec<L>>& xs, const double* w, int n, StateVec<L>& x,
                       StateCov<L>& P) {
  x.setZero();
  for (int i = 0; i < n; ++i) x.noalias() += w[i] * xs[i];
  P.setZero();
  for (int i = 0; i < n; ++i) {
    const StateVec<L> d = xs[i] - x;
    P.noalias() += w[i] * d * d.transpose();
  }
}


/// Regularisation ("roughening", Musso, Oudjane, Le Gland 2001): every
/// particle x_i(s) += k chol(P_cloud) xi, xi ~ N(0, I) from its own stream
/// (seed, stream, i, kRngJitter); parallel, with results independent of the
/// thread count.  `state(i)` returns a reference to particle i's state.
/// Returns the Cholesky repairs of P_cloud.
template <class L, class StateOf>
int roughen(int n, StateCov<L> P_cloud, double k, std::uint64_t seed, std::uint64_t stream, StateOf&& state) {
  StateCov<L> sqrtP;
  const int repairs = cholesky_with_repair<L::kSize>(P_cloud, sqrtP);
  sqrtP *= k;
  INSNAV_PARALLEL_FOR
  for (int i = 0; i < n; ++i) {
    Rng r;
    r.seed(seed, stream, i, kRngJitter);
    StateVec<L> xi;
    r.fill_normal(xi);
    state(i).noalias() += sqrtP * xi;
  }
  return repairs;
}

}  // namespace insnav
