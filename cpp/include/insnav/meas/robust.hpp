// insnav/meas/robust.hpp -- robust estimation in the tight update: per-row
// innovation screening, IGG-III down-weighting and the receiver clock-jump
// check (used by engine/tight_engine.hpp; any filter with x() and P()).
//
// Every test is on the *predicted* innovation of one row i (pseudorange or
// pseudorange rate of one satellite), before any update of the epoch:
//   y_i = residual_i - H_i x,   S_ii = H_i P H_i^T + R_ii,   w_i = y_i / sqrt(S_ii)
// (residual = INS-predicted minus measured, pseudorange.hpp), so one faulty
// satellite does not spread into the others' test values as it would in
// least-squares residuals.
//
// 1. Clock jump (a receiver that resets its clock by a millisecond, c 1e-3 s =
//    299792.458 m, shifts every pseudorange at once; Doppler is unchanged):
//    when at least `clock_jump_min_rows` pseudorange rows have a median
//    innovation beyond `clock_jump_sigma` times their median sqrt(S_ii) and at
//    least half of them agree with that median to within sqrt(chi2_row)
//    sqrt(S_ii), the median is a common offset: it is moved into the
//    receiver clock estimate (b -= median y) instead of rejecting every
//    satellite, and the epoch is processed with the corrected clock.
// 2. Detection, identification, adaptation (Teunissen 1990, "An integrity
//    and quality control procedure for use in multi sensor integration", the
//    DIA scheme): an epoch is *flagged* when any row has w_i^2 > chi2_row (the
//    1-dof chi-square quantile; default 10.83, false alarm 1e-3 per row).  In
//    a flagged epoch rows with w_i^2 > chi2_row are rejected and the others
//    are weighted with the IGG-III equivalent weight (Yang, Song & Xu 2002,
//    "Robust estimator for correlated observations based on bifactor
//    equivalent weights", J. Geodesy 76:353-358; Yang, He & Xu 2001,
//    "Adaptively robust filtering for kinematic geodetic positioning",
//    J. Geodesy 75:109-116):
//        q(w) = 1                                   |w| <= k0
//             = k0/|w| ((k1 - |w|)/(k1 - k0))^2      k0 < |w| <= k1
//             = 0                                   |w| > k1
//    applied as R_ii / q (q = 0: rejected), k0 = 1.5, k1 = 3.0 by default.
//    An epoch that is not flagged is the plain update, so on clean data the
//    robust filter equals the plain one except at the rare false alarms.
//    `huber = true` replaces IGG-III by the Huber weight (Huber 1964; the
//    M-estimator form of Yang et al. 2002): q(w) = 1 for |w| <= k, k/|w|
//    beyond (k = huber_k, default 1.5), never zero below the chi2_row test.
// 3. Fault detection and exclusion over the whole epoch (RAIM in the
//    innovation domain, the DIA scheme's identification step): when the
//    epoch's NIS over the rows left after 2. fails the gate (nis_gate.hpp),
//    the satellite of the row with the largest w-test statistic
//        w_i = (S^-1 y)_i / sqrt((S^-1)_ii)            (Teunissen 1990, eq. 13)
//    is excluded (both its rows) and the epoch re-tested, up to
//    `fde_max_sats` satellites and while more than `fde_min_rows` rows remain
//    (below that the epoch has no redundancy to identify a fault and goes to
//    the gate whole).  One faulty satellite of many no longer costs the
//    epoch, and the gate's reopening never applies a row the screening or the
//    exclusion removed (it sees only the rows left).
// 4. Slow faults (a ramp of a few m/s on one pseudorange grows under the
//    per-row threshold while the filter absorbs part of it): a two-sided
//    CUSUM (Page 1954; Basseville & Nikiforov 1993, sec. 2.2) per satellite
//    and row kind on the standardized innovation, clipped to
//    +-sqrt(chi2_row) so one outlier cannot trigger it alone:
//        g+ = max(0, g+ + w - k),   g- = max(0, g- - w - k),   alarm: g > h
//    (k = cusum_k = 0.5 detects a mean shift of about 1 sigma, h = cusum_h).
//    An alarm excludes that row of that satellite for `cusum_hold_s` and
//    resets its sums; a fault still there afterwards fails the per-row test
//    at once.  Not updated while the gate's outage-aware test is active
//    (after an outage the innovations of every satellite are large together)
//    nor in an epoch with fewer than `cusum_min_pseudoranges` (4)
//    pseudoranges: with fewer than position + clock the epoch cannot pin the
//    filter, whose coasting drift then shows on every satellite alike (on the
//    rtklibexplorer walk with 2-3 GPS satellites left it excluded a good
//    satellite's Doppler); with 4 the prediction from the INS is the
//    redundancy (a 1 m/s ramp on that walk's four GPS satellites is caught
//    only by the CUSUM: docs/results/gate_outages.md).
// 0. Variance factor, before every test above (Koch 1999, "Parameter
//    estimation and hypothesis testing in linear models", sec. 3.4: the
//    variance factor of the observations; here robustly, by the median):
//    every threshold above is in units of the configured sigma, so data
//    noisier than their sigma (multipath, a receiver that reports optimistic
//    sigmas) fail the tests on good satellites, the CUSUM excludes them and
//    the filter coasts: with true pseudorange noise 3 times the configured,
//    hundreds of metres where the plain update stays at tens.  Per row kind
//    (pseudorange, rate), over the rows of the last `variance_window` epochs
//    (y_i, a_i = H_i P H_i^T, r_i = R_ii of their own epoch), the smallest
//    f >= 1 with
//        median_i  y_i^2 / (a_i + f r_i)  <=  0.4549  (the median of chi2_1)
//    scales the epoch's R of that kind by f before the tests.  Measured
//    against a dead zone of 3 standard deviations of the sample median
//    (f = 1 unless the median at f = 1 exceeds 0.4549 + 3.18 / sqrt(n)): no
//    gain on clean simulated data, whose rate rows are themselves noisier
//    than R + H P H^T, and twice the error with 3x noise (urban-multignss).
//    The estimate is biased upward: on consistent data the sample median
//    exceeds 0.4549 in half the windows (f a little above 1), and a faulty
//    share eps of the rows moves the median to the 0.5 / (1 - eps) quantile
//    of the clean ones (one satellite of four: f about 2).  The median's
//    breakdown point of 50 % bounds that: the faulty rows' standardized
//    innovations stay large and beyond the tests.  Not in the gate's outage-aware
//    epochs (after an outage the INS drift, not R, makes the innovations
//    large) nor with fewer than `variance_min_rows` rows in the window.
#pragma once

#include <algorithm>
#include <cmath>

namespace insnav {

/// Robust tight update settings (run config [robust], insnav.config.Robust).
struct RobustConfig {
  bool screening = true;          // per-row screening + IGG-III, FDE and CUSUM (off: plain update)
  double chi2_row = 10.83;        // 1-dof chi-square threshold on w_i^2 (1 - 1e-3 quantile, 3.29 sigma)
  double igg_k0 = 1.5;            // IGG-III: full weight up to |w| = k0
  double igg_k1 = 3.0;            // IGG-III: zero weight beyond |w| = k1
  bool clock_jump = true;         // absorb a common pseudorange offset into the clock
  double clock_jump_sigma = 10.0; // |median y| / median sqrt(S) above which the offset is a jump
  int clock_jump_min_rows = 3;    // pseudorange rows needed to call an offset common
  bool huber = false;             // Huber instead of IGG-III weights
  double huber_k = 1.5;           // Huber: full weight up to |w| = k
  int fde_max_sats = 2;           // whole-epoch FDE: satellites excluded per epoch at most (0: off)
  int fde_min_rows = 8;           // ... while more rows than this remain
  double cusum_k = 0.5;           // CUSUM drift (in sigma of w)
  double cusum_h = 8.0;           // CUSUM alarm threshold (0: off)
  double cusum_hold_s = 60.0;     // an alarm excludes the row this long [s]
  int cusum_min_pseudoranges = 4; // the CUSUM acts only in epochs with at least this many pseudoranges
  int variance_window = 10;       // variance factor (header comment, 0.): epochs pooled (0: off), <= kMaxVarianceWindow
  int variance_min_rows = 4;      // ... rows of a kind the window needs
};

/// Longest variance-factor window [epochs] (RobustConfig::variance_window).
inline constexpr int kMaxVarianceWindow = 30;
/// Median of the chi-square distribution with one degree of freedom.
inline constexpr double kChi2OneMedian = 0.45493642311957184;

/// The variance factor of header comment 0.: the smallest f >= 1 with
/// median_i y2_i / (a_i + f r_i) <= kChi2OneMedian over n > 0 rows (bisection on
/// ln f, to 1e-6 relative; at most 1e8); `scratch` holds n doubles.
inline double variance_factor(const double* y2, const double* a, const double* r, int n, double* scratch) {
  const auto g = [&](double f) {
    for (int i = 0; i < n; ++i) scratch[i] = y2[i] / std::max(a[i] + f * r[i], 1e-300);
    const int h = n / 2;
    std::nth_element(scratch, scratch + h, scratch + n);
    return n % 2 ? scratch[h] : 0.5 * (scratch[h] + *std::max_element(scratch, scratch + h));
  };
  if (!(g(1.0) > kChi2OneMedian)) return 1.0;
  double lo = 0.0, hi = std::log(1e8);
  if (g(1e8) > kChi2OneMedian) return 1e8;
  while (hi - lo > 1e-6) {
    const double mid = 0.5 * (lo + hi);
    (g(std::exp(mid)) > kChi2OneMedian ? lo : hi) = mid;
  }
  return std::exp(hi);
}

/// Huber weight factor q(w) = min(1, k/|w|) (header comment, 2.).
inline double huber_weight(double w, double k) {
  const double a = std::fabs(w);
  return a <= k ? 1.0 : k / a;
}

/// IGG-III equivalent weight factor q(w) of a standardized residual w (header comment).
inline double igg3_weight(double w, double k0, double k1) {
  const double a = std::fabs(w);
  if (a <= k0) return 1.0;
  if (a > k1) return 0.0;
  const double r = (k1 - a) / (k1 - k0);
  return k0 / a * r * r;
}

/// Median of v[0..n) (reorders v); n > 0.
inline double median_inplace(double* v, int n) {
  const int h = n / 2;
  std::nth_element(v, v + h, v + n);
  const double hi = v[h];
  if (n % 2) return hi;
  return 0.5 * (hi + *std::max_element(v, v + h));
}

}  // namespace insnav
