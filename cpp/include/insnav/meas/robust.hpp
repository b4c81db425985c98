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
#pragma once

#include <algorithm>
#include <cmath>

namespace insnav {

/// Robust tight update settings (run config [robust], insnav.config.Robust).
struct RobustConfig {
  bool screening = false;         // per-row screening + IGG-III in flagged epochs (off: plain update)
  double chi2_row = 10.83;        // 1-dof chi-square threshold on w_i^2 (1 - 1e-3 quantile, 3.29 sigma)
  double igg_k0 = 1.5;            // IGG-III: full weight up to |w| = k0
  double igg_k1 = 3.0;            // IGG-III: zero weight beyond |w| = k1
  bool clock_jump = true;         // absorb a common pseudorange offset into the clock
  double clock_jump_sigma = 10.0; // |median y| / median sqrt(S) above which the offset is a jump
  int clock_jump_min_rows = 3;    // pseudorange rows needed to call an offset common
};

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
