// insnav/gnss/ambiguity_resolution.hpp -- integer ambiguity resolution of double-differenced
// ambiguities: MLAMBDA, the ratio test, partial AR and the validation of a candidate, shared by
// the GNSS-only RTK engine (gnss/rtk.hpp) and the tight RTK/INS engine (engine/rtk_ins_engine.hpp).
//
// Given n double-differenced float ambiguities a_hat = D x_N [cycles] with covariance
// Q_a = D P_NN D^T, ordered by priority (highest elevation first, or smallest variance first):
//   1. MLAMBDA (lambda.hpp; Chang, Yang & Zhou 2005) returns the best and second-best integer
//      vectors a_1, a_2 with s_k = (a_hat - a_k)^T Q_a^{-1} (a_hat - a_k), s_1 <= s_2;
//   2. ratio test s_2 / s_1 >= threshold (Teunissen & Verhagen 2009);
//   3. optional validation of a_1 against the float solution: s_1 <= chi2_{1-alpha}(n) (a fixed
//      vector the float ambiguities and their covariance cannot explain is rejected: an
//      INS-predicted position that constrains the float ambiguities makes this test sharp), and
//      a minimum bootstrapped success rate of the subset (Teunissen 1998): the float precision
//      must make a correct fix likely, which the ratio test alone does not ensure with few
//      ambiguities;
//   4. on failure, partial AR drops the last ambiguity of the order and retries, down to
//      min_fix ambiguities and at most max_drops times.
// The fixed baseline follows from the conditional mean (Teunissen 1995, eq. (6)):
//   x_b_fix = x_b - Q_ba Q_a^{-1} (a_hat - a_fix),  P_b_fix = P_b - Q_ba Q_a^{-1} Q_ab;
// solve() gives Q_a^{-1} v for the caller, which knows its own Q_ba.
//
// Bounded sizes (kMaxAmbiguities), no heap allocation.
#pragma once

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>

#include "insnav/filter/nis_gate.hpp"
#include "insnav/gnss/lambda.hpp"

namespace insnav::gnss {

struct ArSettings {
  double ratio_threshold = 3.0;
  int min_fix = 3;            // partial AR stops above this count
  int max_drops = 12;         // at most this many partial-AR retries
  double validation_prob = 0.0;  // > 0: also require s_1 <= chi2_quantile(validation_prob, n)
  double min_success_rate = 0.0; // > 0: also require the bootstrapped success rate >= this
};

/// Bootstrapped success rate of integer ambiguity resolution (Teunissen 1998, "Success probability
/// of integer GPS ambiguity rounding and bootstrapping", J. Geodesy 72):
/// P_s = prod_i (2 Phi(1 / (2 sigma_i|I)) - 1) = prod_i erf(1 / (2 sqrt(2 D_i))), D_i the conditional
/// variances of the decorrelated ambiguities (Z^T Q Z = L^T diag(D) L).
inline double bootstrap_success_rate(const AmbVec& D) {
  double p = 1.0;
  for (int i = 0; i < D.size(); ++i) p *= std::erf(1.0 / (2.0 * std::sqrt(2.0 * std::max(D(i), 1e-300))));
  return p;
}

/// Partial ambiguity resolution over candidates given in priority order.
class PartialAr {
 public:
  /// n candidates, priority order p = 0..n-1: float value a(p) and covariance q(p, q) (callables).
  /// Returns true when a subset of the first n_used() candidates passes; ratio() is the full set's
  /// ratio (or the accepted subset's when one passes).
  template <class ValueFn, class CovFn>
  bool resolve(int n, ValueFn&& a, CovFn&& q, const ArSettings& s) {
    n = std::min(n, kMaxAmbiguities);
    n_used_ = 0;
    ratio_ = 0.0;
    s1_ = 0.0;
    int drops = 0;
    for (int nuse = n; nuse >= std::max(s.min_fix, 1); --nuse) {
      if (drops++ > s.max_drops) break;
      a_hat_.resize(nuse);
      Qa_.resize(nuse, nuse);
      for (int p = 0; p < nuse; ++p) {
        a_hat_(p) = a(p);
        for (int r = 0; r <= p; ++r) Qa_(p, r) = Qa_(r, p) = q(p, r);
      }
      double sq[2];
      if (lambda_.solve(a_hat_, Qa_, a_fix_, sq) != LambdaStatus::kOk) continue;
      const double ratio = sq[0] > 0.0 ? std::min(sq[1] / sq[0], 999.9) : 999.9;
      if (nuse == n) ratio_ = ratio;
      if (ratio < s.ratio_threshold) continue;
      if (s.validation_prob > 0.0 && sq[0] > ::insnav::chi2_quantile(s.validation_prob, nuse)) continue;
      if (s.min_success_rate > 0.0) {
        if (!lambda_.decorrelate(Qa_, Zw_, Lw_, Dw_)) continue;
        success_ = bootstrap_success_rate(Dw_);
        if (success_ < s.min_success_rate) continue;
      }
      llt_.compute(Qa_);
      if (llt_.info() != Eigen::Success) continue;
      ratio_ = ratio;
      s1_ = sq[0];
      n_used_ = nuse;
      da_ = a_hat_ - a_fix_.col(0);
      return true;
    }
    return false;
  }

  /// The tests of resolve() applied to another integer vector a_cand (n_used() values) in place
  /// of LAMBDA's best, at the last accepted float solution: its squared norm
  /// s_c = (a_hat - a_cand)^T Q_a^{-1} (a_hat - a_cand) (s_out) against the validation quantile,
  /// and the ratio test with a_cand as the fix (s_2 / s_1 when it is the best, else s_1 / s_c < 1:
  /// a better integer vector exists).  The engines' tests reject a wrong integer set by these.
  bool accepts(const AmbVec& a_cand, const ArSettings& s, double& s_out, double& ratio_out) const {
    s_out = NAN;
    ratio_out = 0.0;
    if (n_used_ == 0 || a_cand.size() != n_used_) return false;
    const AmbVec d = a_hat_ - a_cand;
    s_out = d.dot(llt_.solve(d));
    const bool best = (a_cand - a_fix_.col(0)).cwiseAbs().maxCoeff() < 0.5;
    ratio_out = best ? ratio_ : s1_ / std::max(s_out, 1e-300);
    if (s.validation_prob > 0.0 && s_out > ::insnav::chi2_quantile(s.validation_prob, n_used_)) return false;
    return ratio_out >= s.ratio_threshold;
  }

  int n_used() const { return n_used_; }
  double ratio() const { return ratio_; }
  double s1() const { return s1_; }
  const AmbVec& a_hat() const { return a_hat_; }
  auto a_fix() const { return a_fix_.col(0); }
  /// a_hat - a_fix of the accepted subset.
  const AmbVec& residual() const { return da_; }
  const AmbMat& Qa() const { return Qa_; }
  /// Q_a^{-1} M in place (M: n_used() rows).
  template <class M>
  void solve_in_place(M& m) const {
    llt_.solveInPlace(m);
  }

 private:
  Lambda lambda_;
  AmbVec a_hat_, da_;
  AmbMat Qa_;
  AmbCand a_fix_;
  AmbMat Zw_, Lw_;
  AmbVec Dw_;
  double success_ = 1.0;
  Eigen::LLT<AmbMat> llt_{kMaxAmbiguities};
  int n_used_ = 0;
  double ratio_ = 0.0, s1_ = 0.0;
};

}  // namespace insnav::gnss
