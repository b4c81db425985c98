// insnav/filter/nis_gate.hpp -- the innovation gate of the GNSS updates.
//
// A record whose normalized innovation squared  nis = y' S^-1 y  exceeds the
// chi-square quantile of its row count m at probability `prob` is rejected
// (the validation gate: Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4.2; for a
// consistent filter nis ~ chi2(m)).  One probability therefore serves a
// position-only fix (3 rows), a position + velocity fix (6) and a tight epoch
// of any satellite count.  A fixed threshold for every row count (`chi2`)
// overrides the quantile.
//
// A filter whose covariance has become too small rejects every record after
// it and never recovers (lock-out).  After `reopen_after` rejected records in
// a row the gate reopens: the closed-loop core (closed_loop.hpp) tries the
// next record at the gate as usual and, if it is rejected again, scales the
// covariance by lambda = NIS / m (P <- lambda P, the fading-memory form of
// seed 004 eq. (1): the covariance under which this innovation is ordinary)
// and applies it without the gate.  Merely applying it ungated is not enough:
// with the small P the gain stays small and the next records are rejected
// again (a 100 m step: 30 % of it followed after 10 ungated updates).
// `reopened()` counts the records applied that way.  It is on by default
// (after 5): on real data whose noise model is optimistic the gate otherwise
// locks the filter out for good (the handheld walk of docs/results/walk_loose.md
// with every 4 Hz fix: 89 m RMS and 179 of 536 fixes rejected without
// reopening, 0.10 m with it; 0.07 m ungated).  The price is a fault that lasts
// (a pseudorange ramp on one satellite of a tight epoch) is taken in whole
// after 5 rejections (a 240 m ramp: 73 m horizontal error against 8 m without
// reopening and 17 m with no gate); the per-satellite robust screening of a
// tight run (meas/robust.hpp) is the remedy for that.
//
// Outage-aware test.  After a GNSS outage the predicted covariance of a
// filter whose IMU noise model is optimistic (a consumer IMU's real drift is
// several times what its configured noise predicts) is too small, and the
// first fixes after the outage fail the gate although they are right: the
// gate then discards exactly the fixes that end the drift, and the reopening
// below applies one of them with a scaled covariance, which the RTS smoother
// reads as a burst of process noise at that epoch and so cannot carry the
// post-outage fixes back into the outage (measured on a car simulation whose
// IMU noise is 5x the configured one: smoothed 30 s outage maximum 17.9 m
// with the plain gate, 1.0 m ungated; docs/results/gate_outages.md).  So when
// the last applied record is older than `outage_s` (an outage, or a run of
// rejections), the record is tested against
//     S_a = alpha H P H' + R,   nis_a = y' S_a^-1 y  <=  threshold,
// the innovation covariance of a filter whose predicted error covariance is
// `alpha` (= `mismatch`, default 25: IMU noise up to 5x the configured) times
// its own -- a mismatch of the process noise only, the part that grows with
// the time since the last update (Bar-Shalom, Li & Kirubarajan 2001, sec.
// 5.4.2 with the process-noise mismatch of sec. 11.6.4 taken as a bound).
// A record that passes is applied as the plain update (no covariance
// scaling, so the smoother sees an ordinary update); in steady state
// (updates every record) the plain test stays as sharp as before, and a
// fault that is large against sqrt(alpha) times the predicted spread is
// still rejected after an outage.
//
// The quantiles are tabulated once at construction; threshold() allocates
// nothing.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

#include "insnav/filter/types.hpp"

namespace insnav {

/// Regularized lower incomplete gamma function P(a, x), a > 0, x >= 0: the
/// series for x < a + 1, otherwise the Lentz continued fraction of Q = 1 - P
/// (Press et al., Numerical Recipes, 3rd ed., sec. 6.2).
inline double gamma_p(double a, double x) {
  if (!(x > 0.0)) return 0.0;
  const double log_prefix = a * std::log(x) - x - std::lgamma(a);
  if (x < a + 1.0) {
    double term = 1.0 / a, sum = term;
    for (int n = 1; n < 1000 && std::fabs(term) > std::fabs(sum) * 1e-16; ++n) {
      term *= x / (a + n);
      sum += term;
    }
    return std::min(1.0, sum * std::exp(log_prefix));
  }
  constexpr double kTiny = 1e-300;
  double b = x + 1.0 - a, c = 1.0 / kTiny, d = 1.0 / b, h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::fabs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::fabs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::fabs(delta - 1.0) < 1e-16) break;
  }
  return std::max(0.0, 1.0 - std::exp(log_prefix) * h);
}

/// Chi-square quantile: the x with P(x; dof) = p, 0 < p < 1, dof >= 1
/// (bisection on the CDF gamma_p(dof/2, x/2); to ~1e-12 relative).
inline double chi2_quantile(double p, int dof) {
  if (!(p > 0.0) || dof < 1) return 0.0;
  if (!(p < 1.0)) return kInf;
  const double a = 0.5 * dof;
  double lo = 0.0, hi = std::max(1.0, 2.0 * dof);
  while (gamma_p(a, 0.5 * hi) < p) hi *= 2.0;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (gamma_p(a, 0.5 * mid) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// The gate's settings.  Defaults: the 0.9999 quantile of the record's row
/// count (6 rows: 27.86, 3 rows: 21.11), reopened after 5 rejections in a row.
struct GateConfig {
  double prob = 0.9999;   ///< probability that a consistent record passes (<= 0: no quantile gate)
  double chi2 = 0.0;      ///< > 0: this fixed threshold for every row count instead of the quantile
  int reopen_after = 5;   ///< reopen after this many rejections in a row (0: never)
  double mismatch = 25.0; ///< outage-aware test: alpha of S_a = alpha H P H' + R (<= 1: off)
  double outage_s = 2.0;  ///< ... when the last applied record is older than this [s]
  bool enabled() const { return chi2 > 0.0 || prob > 0.0; }
};

/// The gate of one record stream (a copyable value: the exact delay engine
/// checkpoints it with the rest of the closed loop).
class NisGate {
 public:
  static constexpr int kTabulatedRows = 64;

  NisGate() : NisGate(GateConfig{}) {}
  explicit NisGate(const GateConfig& cfg) : cfg_(cfg) {
    for (int m = 1; m <= kTabulatedRows; ++m) quantile_[m] = chi2_quantile(cfg_.prob, m);
  }

  const GateConfig& config() const { return cfg_; }

  /// True after `reopen_after` rejections in a row: the next record is to be
  /// applied even if the gate rejects it.
  bool reopening() const { return cfg_.reopen_after > 0 && in_a_row_ >= cfg_.reopen_after; }

  /// The NIS threshold for a record of `rows` rows; 0 = no gate for this
  /// record (gate off, or reopening).
  double threshold(int rows) const { return reopening() ? 0.0 : nominal_threshold(rows); }

  /// The threshold for `rows` rows whether or not the gate is reopening (0: off).
  double nominal_threshold(int rows) const {
    if (!cfg_.enabled()) return 0.0;
    if (cfg_.chi2 > 0.0) return cfg_.chi2;
    if (rows < 1) return 0.0;
    return rows <= kTabulatedRows ? quantile_[rows] : chi2_quantile(cfg_.prob, rows);
  }

  /// True when a record valid at `t` [s] is to be tested outage-aware
  /// (header comment): gate on, mismatch > 1 and no record applied within `outage_s`.
  bool outage_aware(double t) const {
    return cfg_.enabled() && cfg_.mismatch > 1.0 && !(t - t_applied_ <= cfg_.outage_s);
  }

  /// Account for the result of a record's update at time `t` [s]; `forced`:
  /// it was applied without the gate because the gate was reopening (counted
  /// in reopened()); `bridged`: it passed the outage-aware test only (counted
  /// in outage_accepted()).  A record that passes the gate on its own while
  /// reopening is not counted.
  void record(const UpdateResult& r, bool forced = false, double t = NAN, bool bridged = false) {
    if (r.rejected_by_gate) {
      ++in_a_row_;
    } else if (r.applied) {
      if (forced) ++reopened_;
      if (bridged) ++outage_accepted_;
      in_a_row_ = 0;
      if (std::isfinite(t)) t_applied_ = t;
    }
  }

  int rejected_in_a_row() const { return in_a_row_; }
  int reopened() const { return reopened_; }
  int outage_accepted() const { return outage_accepted_; }

 private:
  GateConfig cfg_;
  std::array<double, kTabulatedRows + 1> quantile_{};
  int in_a_row_ = 0, reopened_ = 0, outage_accepted_ = 0;
  double t_applied_ = -kInf;  // time of the last applied record [s]
};

}  // namespace insnav
