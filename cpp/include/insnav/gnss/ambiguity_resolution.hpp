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
//      ambiguities; a set that fails it may pass a second, stricter minimum on the success rate
//      of k Q_a, k a variance factor of the float estimated from the data by the caller;
//   4. the caller's check of the candidate (PartialAr::resolve's check callback), e.g. the rules
//      over epochs of FixValidator below: accept it, try a smaller subset, or stop (float epoch);
//   5. on failure, partial AR drops the last ambiguity of the order and retries, down to
//      min_fix ambiguities and at most max_drops times.
// The fixed baseline follows from the conditional mean (Teunissen 1995, eq. (6)):
//   x_b_fix = x_b - Q_ba Q_a^{-1} (a_hat - a_fix),  P_b_fix = P_b - Q_ba Q_a^{-1} Q_ab;
// solve() gives Q_a^{-1} v for the caller, which knows its own Q_ba.
//
// FixValidator: the rules of an accepted set over epochs (minimum number fixed, consistency with
// the last validated set, confirmation of small sets over consecutive epochs), for engines whose
// single-differenced ambiguities live in numbered slots.
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
  int min_fix = 3;            // partial AR tries subsets down to this count
  int max_drops = 12;         // at most this many partial-AR retries
  double validation_prob = 0.0;  // > 0: also require s_1 <= chi2_quantile(validation_prob, n)
  double min_success_rate = 0.0; // > 0: also require the bootstrapped success rate >= this
  // > 0: a set whose success rate fails min_success_rate also passes when the success rate of
  // k Q_a (k = success_variance_factor, e.g. an estimated variance factor of the float) is >= this;
  // and with k > 1 min_success_rate applies to k Q_a (the configured Q_a is then optimistic)
  double min_success_rate_scaled = 0.0;
  double success_variance_factor = 1.0;
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

/// What a caller's check makes of a candidate subset (PartialAr::resolve).
enum class ArVerdict : int { kAccept = 0, kReject = 1, kStop = 2 };

/// Work of PartialAr over its resolve() calls since reset_counts(): what an engine's summary reports
/// of the cost of its AR.
struct ArCounts {
  long resolves = 0;          // resolve() calls (epochs with AR)
  long lambda_calls = 0;      // MLAMBDA solves: the full set and each partial-AR subset tried
  long search_nodes = 0;      // MLAMBDA search nodes, summed over the solves (Lambda::nodes)
  long max_search_nodes = 0;  // the most of one solve
  long lambda_failures = 0;   // solves without a result (Q_a not positive definite, node budget)
};

/// Partial ambiguity resolution over candidates given in priority order.
class PartialAr {
 public:
  /// n candidates, priority order p = 0..n-1: float value a(p) and covariance q(p, q) (callables).
  /// Returns true when a subset of the first n_used() candidates passes; ratio() and
  /// success_rate() are the full set's (or the accepted subset's when one passes).
  template <class ValueFn, class CovFn>
  bool resolve(int n, ValueFn&& a, CovFn&& q, const ArSettings& s) {
    return resolve(n, a, q, s, [](int) { return ArVerdict::kAccept; });
  }

  /// As above, with check(n_fix) called for a subset of the first n_fix candidates that passed
  /// the ratio, chi2 and success-rate tests (a_fix() is its integer vector during the call):
  /// kAccept fixes it, kReject tries the next smaller subset, kStop ends the search (no fix).
  template <class ValueFn, class CovFn, class CheckFn>
  bool resolve(int n, ValueFn&& a, CovFn&& q, const ArSettings& s, CheckFn&& check) {
    n = std::min(n, kMaxAmbiguities);
    ++counts_.resolves;
    n_used_ = 0;
    ratio_ = 0.0;
    success_ = success_scaled_ = 0.0;
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
      const LambdaStatus st = lambda_.solve(a_hat_, Qa_, a_fix_, sq);
      ++counts_.lambda_calls;
      counts_.search_nodes += lambda_.nodes();
      counts_.max_search_nodes = std::max(counts_.max_search_nodes, lambda_.nodes());
      if (st != LambdaStatus::kOk) {
        ++counts_.lambda_failures;
        continue;
      }
      const double ratio = sq[0] > 0.0 ? std::min(sq[1] / sq[0], 999.9) : 999.9;
      const double ps = lambda_.bootstrap_success_rate();  // of this subset's decorrelated Q_a
      const double ps_k = s.min_success_rate_scaled > 0.0 ? lambda_.bootstrap_success_rate(s.success_variance_factor) : ps;
      if (nuse == n) {
        ratio_ = ratio;
        success_ = ps;
        success_scaled_ = ps_k;
      }
      if (ratio < s.ratio_threshold) continue;
      if (s.validation_prob > 0.0 && sq[0] > ::insnav::chi2_quantile(s.validation_prob, nuse)) continue;
      // the configured covariance's route, with Q_a scaled up where the data say the float is noisier
      // than configured (k > 1): its success rate is then that of k Q_a
      const double ps_cfg = s.min_success_rate_scaled > 0.0 && s.success_variance_factor > 1.0 ? ps_k : ps;
      if (s.min_success_rate > 0.0 && ps_cfg < s.min_success_rate &&
          !(s.min_success_rate_scaled > 0.0 && ps_k >= s.min_success_rate_scaled))
        continue;
      llt_.compute(Qa_);
      if (llt_.info() != Eigen::Success) continue;
      const ArVerdict v = check(nuse);
      if (v == ArVerdict::kReject) continue;
      if (v == ArVerdict::kStop) return false;
      ratio_ = ratio;
      success_ = ps;
      success_scaled_ = ps_k;
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
  /// Work since the last reset_counts() (ArCounts).
  const ArCounts& counts() const { return counts_; }
  void reset_counts() { counts_ = ArCounts{}; }
  double ratio() const { return ratio_; }
  /// Bootstrapped success rate of the full set (or of the accepted subset when one passes).
  double success_rate() const { return success_; }
  /// The same of k Q_a (ArSettings::success_variance_factor; = success_rate() unless
  /// min_success_rate_scaled > 0).
  double success_rate_scaled() const { return success_scaled_; }
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
  double success_ = 0.0, success_scaled_ = 0.0;
  Eigen::LLT<AmbMat> llt_{kMaxAmbiguities};
  int n_used_ = 0;
  double ratio_ = 0.0, s1_ = 0.0;
  ArCounts counts_{};
};

/// Rules of FixValidator (the [rtk] keys min_fix_ambiguities, confirm_epochs, confirm_max_ambiguities).
struct FixRules {
  int min_fix = 5;       // fewest ambiguities of a new set
  int confirm_epochs = 5;  // a new set of few ambiguities is reported after this many repeats (1: at once)
  int confirm_max = 6;   // ... "few": at most this many (more: reported at once)
};

/// Validation of an accepted integer set beyond the tests of one epoch, for an engine whose
/// single-differenced ambiguities live in kSlots numbered slots and whose double differences are
/// a_p = N_j(p) - N_i(p) (slots j(p), i(p)).  The engine calls invalidate(k) whenever slot k is
/// (re-)initialised (new satellite, slip, outlier, removal), reset() when all are, and
/// begin_epoch() / end_epoch() around each epoch's AR.
///  1. Number fixed (check): n_fix >= min_fix.  With the three position coordinates free, a
///     subset of n ambiguities leaves n - 3 checks on the integers: a wrong set that only moves the
///     position fits as well as the right one when n - 3 < 2 (measured on the urban preset, GPS L1,
///     5-6 satellites, ratio 3: 3 fixed 100 % wrong, 4 fixed 57 %, 5 fixed 6 %).  A smaller set is
///     accepted (kConsistent) when it is every fixable ambiguity of the epoch (at least 3, so the
///     position is pinned) and repeats a validated fix: each of its double differences was fixed to
///     the same integer by an earlier accepted set and its ambiguities have been tracked without a
///     slip since (consistency over consecutive epochs: a satellite setting does not undo what the
///     larger set established).
///  2. Confirmation over consecutive epochs (confirm): a new set of at most confirm_max ambiguities
///     (redundancy n - 3 <= 3) is reported fixed once the same integers have passed the checks in
///     confirm_epochs consecutive epochs; until then the epoch stays float.  A float filter biased by
///     an undetected slip or by correlated multipath yields a wrong set that passes the ratio test
///     for a few epochs and then changes; the right set repeats.  Larger sets are reported at once.
/// (The success rate, Teunissen 1998, is ArSettings::min_success_rate, tested by PartialAr first.)
template <int kSlots>
class FixValidator {
 public:
  enum class Check : int { kAccepted = 0, kTooFew = 1, kConsistent = 3 };

  void reset() {
    for (auto& v : slot_) v = Slot{};
    count_ = 0;
    seen_ = false;
  }
  void invalidate(int k) { slot_[k].valid = false; }
  void begin_epoch() { seen_ = false; }
  void end_epoch() {
    if (!seen_) count_ = 0;  // the repeats must be consecutive epochs
  }

  /// Verdict on the candidate of PartialAr::resolve's check (n_fix of n_candidates fixable; slot_j,
  /// slot_i: slots of double difference p; a_fix: its integers): rule 1, then rule 2.
  template <class SlotJ, class SlotI, class AFix>
  ArVerdict operator()(int n_fix, int n_candidates, SlotJ&& slot_j, SlotI&& slot_i, const AFix& a_fix,
                       const FixRules& r) {
    const Check c = check(n_fix, n_candidates, slot_j, slot_i, a_fix, r);
    if (c == Check::kTooFew) return ArVerdict::kReject;
    return confirm(n_fix, c, slot_j, slot_i, a_fix, r) ? ArVerdict::kAccept : ArVerdict::kStop;
  }

  template <class SlotJ, class SlotI, class AFix>
  Check check(int n_fix, int n_candidates, SlotJ&& slot_j, SlotI&& slot_i, const AFix& a_fix,
              const FixRules& r) const {
    if (n_fix >= r.min_fix) return Check::kAccepted;
    if (n_fix == n_candidates && n_fix >= 3 && repeats(n_fix, slot_j, slot_i, a_fix)) return Check::kConsistent;
    return Check::kTooFew;
  }

  /// Rule 2; returns whether the set is reported fixed this epoch.
  template <class SlotJ, class SlotI, class AFix>
  bool confirm(int n_fix, Check c, SlotJ&& slot_j, SlotI&& slot_i, const AFix& a_fix, const FixRules& r) {
    seen_ = true;
    if (c == Check::kConsistent) return ++count_ >= r.confirm_epochs;
    if (repeats(n_fix, slot_j, slot_i, a_fix)) {
      ++count_;
    } else {
      remember(n_fix, slot_j, slot_i, a_fix);
      count_ = 1;
    }
    return n_fix > r.confirm_max || count_ >= r.confirm_epochs;
  }

  /// The candidate's n_fix double differences equal the last validated fix: both single-differenced
  /// ambiguities carry a validated integer against the same reference and their difference is the
  /// candidate's.
  template <class SlotJ, class SlotI, class AFix>
  bool repeats(int n_fix, SlotJ&& slot_j, SlotI&& slot_i, const AFix& a_fix) const {
    for (int p = 0; p < n_fix; ++p) {
      const Slot& j = slot_[slot_j(p)];
      const Slot& i = slot_[slot_i(p)];
      if (!j.valid || !i.valid || j.ref != i.ref) return false;
      if (j.integer - i.integer != a_fix(p)) return false;
    }
    return n_fix > 0;
  }

  int confirm_count() const { return count_; }

 private:
  // N^k - N^ref = integer [cycles] of the last validated set
  struct Slot {
    bool valid = false;
    int ref = -1;
    double integer = 0.0;
  };

  // Store a set's integers as the validated ones (replacing the old set).
  template <class SlotJ, class SlotI, class AFix>
  void remember(int n_fix, SlotJ&& slot_j, SlotI&& slot_i, const AFix& a_fix) {
    for (auto& v : slot_) v.valid = false;
    for (int p = 0; p < n_fix; ++p) {
      Slot& j = slot_[slot_j(p)];
      Slot& i = slot_[slot_i(p)];
      const int ref = slot_i(p);
      i.valid = true;
      i.ref = ref;
      i.integer = 0.0;
      j.valid = true;
      j.ref = ref;
      j.integer = a_fix(p);
    }
  }

  std::array<Slot, kSlots> slot_{};
  int count_ = 0;   // consecutive epochs the validated set was found
  bool seen_ = false;
};

}  // namespace insnav::gnss
