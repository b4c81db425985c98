// insnav/ins/imu_scan.hpp -- the per-sample input checks of an IMU increment
// stream in one pass: non-finite values, time order, repeated times, the
// plausibility limits of the angular rate and the specific force, gaps, and
// the sum of the velocity increments (the mean specific-force direction).
// The pass only reports the first offending sample of each kind; the caller
// (python/insnav/filters/sanitize.py, insnav/_validate.py,
// insnav/data/checks.py) turns it into its message naming the sample and file
// line.  Plain C++17, no Python, no allocation per sample.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace insnav::ins {

/// Limits of the rate and gap tests.  Sample k covers (t[k-1], t[k]]; the
/// first one (t0, t[0]] when t[0] > t0, else the nominal interval dt0.
struct ImuScanLimits {
  double t0_s = std::numeric_limits<double>::quiet_NaN();  ///< start of the first interval [s]; NaN: none
  double max_rate_rps = std::numeric_limits<double>::infinity();    ///< |dtheta| / dt limit [rad/s]
  double max_accel_mps2 = std::numeric_limits<double>::infinity();  ///< |dv| / dt limit [m/s^2]
  double gap_factor = std::numeric_limits<double>::infinity();      ///< gap: dt > gap_factor * dt0
};

/// What the pass found (-1: nothing of that kind).
struct ImuScan {
  std::int64_t first_nonfinite_t = -1;       ///< first sample with a non-finite time
  std::int64_t first_nonfinite_dtheta = -1;  ///< ... dtheta_b component
  std::int64_t first_nonfinite_dv = -1;      ///< ... dv_b component
  std::int64_t first_decrease = -1;          ///< first k with t[k] < t[k-1]
  std::int64_t first_not_increasing = -1;    ///< first k with !(t[k] > t[k-1]) (repeats and NaN too)
  std::int64_t repeats = 0;                  ///< intervals with t[k] == t[k-1]
  double dt0_s = 0.0;  ///< nominal interval [s]: median interval (as sanitize computes it); 0 if none
  std::int64_t first_rate = -1;   ///< first sample over max_rate_rps (only when dt0_s > 0)
  std::int64_t first_accel = -1;  ///< first sample over max_accel_mps2 (only when dt0_s > 0)
  std::int64_t gaps = 0;          ///< samples k >= 1 with t[k] - t[k-1] > gap_factor * dt0 (when dt0_s > 0)
  double max_gap_s = 0.0;         ///< longest of those intervals [s]
  double dv_sum[3] = {0.0, 0.0, 0.0};  ///< sum of dv_b over the samples [m/s]
};

/// The nominal interval of the stream [s]: the median of every step-th
/// interval, step = max(1, (n - 1) / 200000) (the median of numpy: the mean
/// of the two middle values for an even count); when that is not a positive
/// number, t[0] - t0 if t[0] > t0, else 0.  ``scratch`` is reused.
inline double nominal_interval(const double* t, std::int64_t n, double t0_s, std::vector<double>& scratch) {
  double dt0 = std::numeric_limits<double>::quiet_NaN();
  const std::int64_t nd = n > 1 ? n - 1 : 0;
  if (nd > 0) {
    const std::int64_t step = std::max<std::int64_t>(1, nd / 200000);
    scratch.clear();
    bool nan = false;
    for (std::int64_t k = 0; k < nd; k += step) {
      const double d = t[k + 1] - t[k];
      nan = nan || std::isnan(d);
      scratch.push_back(d);
    }
    if (!nan) {
      const std::size_t m = scratch.size();
      const auto mid = scratch.begin() + static_cast<std::ptrdiff_t>(m / 2);
      std::nth_element(scratch.begin(), mid, scratch.end());
      dt0 = *mid;
      if (m % 2 == 0) dt0 = (*std::max_element(scratch.begin(), mid) + dt0) / 2.0;
    }
  }
  if (!(std::isfinite(dt0) && dt0 > 0.0)) {
    dt0 = (n > 0 && std::isfinite(t0_s) && t[0] > t0_s) ? t[0] - t0_s : 0.0;
  }
  return dt0;
}

/// One pass over t (n,), dtheta_b (n, 3) and dv_b (n, 3), row-major.  The
/// limits are tested as |x|^2 > (lim dt)^2 (no root or division per sample),
/// dt being the sample's own interval.
inline ImuScan scan_imu(const double* t, const double* dtheta_b, const double* dv_b, std::int64_t n,
                        const ImuScanLimits& lim, std::vector<double>& scratch) {
  ImuScan s;
  s.dt0_s = nominal_interval(t, n, lim.t0_s, scratch);
  const double dt0 = s.dt0_s;
  const bool rates = dt0 > 0.0;
  const double gap_dt = lim.gap_factor * dt0;
  const double first_dt = (n > 0 && std::isfinite(lim.t0_s) && t[0] > lim.t0_s) ? t[0] - lim.t0_s : dt0;
  double sx = 0.0, sy = 0.0, sz = 0.0;
  for (std::int64_t k = 0; k < n; ++k) {
    const double* w = dtheta_b + 3 * k;
    const double* v = dv_b + 3 * k;
    const double tk = t[k];
    if (s.first_nonfinite_t < 0 && !std::isfinite(tk)) s.first_nonfinite_t = k;
    if (s.first_nonfinite_dtheta < 0 && !(std::isfinite(w[0]) && std::isfinite(w[1]) && std::isfinite(w[2])))
      s.first_nonfinite_dtheta = k;
    if (s.first_nonfinite_dv < 0 && !(std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2])))
      s.first_nonfinite_dv = k;
    double dt = first_dt;
    if (k > 0) {
      dt = tk - t[k - 1];
      if (!(dt > 0.0)) {
        if (s.first_not_increasing < 0) s.first_not_increasing = k;
        if (dt < 0.0 && s.first_decrease < 0) s.first_decrease = k;
        if (dt == 0.0) ++s.repeats;
      }
      if (rates && dt > gap_dt) {
        ++s.gaps;
        s.max_gap_s = std::max(s.max_gap_s, dt);
      }
    }
    if (rates) {
      const double ww = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
      const double vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
      const double lw = lim.max_rate_rps * dt, lv = lim.max_accel_mps2 * dt;
      if (s.first_rate < 0 && ww > lw * lw) s.first_rate = k;
      if (s.first_accel < 0 && vv > lv * lv) s.first_accel = k;
    }
    sx += v[0];
    sy += v[1];
    sz += v[2];
  }
  s.dv_sum[0] = sx;
  s.dv_sum[1] = sy;
  s.dv_sum[2] = sz;
  return s;
}

/// The integral of dtheta_b . axis_b (the rotation about a fixed body axis
/// [rad]) from before the first sample up to each of the query times, linear
/// between the samples: np.interp(query, [t[0] - (t[1] - t[0]), t...],
/// [0, cumsum(dtheta_b @ axis_b)...], left=NaN, right=NaN).  t increasing,
/// n >= 2; the queries in any order.  ``order`` is reused.
inline void rotation_about_at(const double* t, const double* dtheta_b, std::int64_t n, const double axis_b[3],
                              const double* query, std::int64_t m, double* out, std::vector<std::int64_t>& order) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  order.resize(static_cast<std::size_t>(m));
  for (std::int64_t j = 0; j < m; ++j) order[static_cast<std::size_t>(j)] = j;
  std::sort(order.begin(), order.end(), [&](std::int64_t a, std::int64_t b) {
    return query[a] < query[b] || (!std::isnan(query[a]) && std::isnan(query[b]));
  });
  // knots: x_0 = t[0] - (t[1] - t[0]) with value 0, x_{k+1} = t[k] with cum[k]
  const double x0 = n >= 2 ? t[0] - (t[1] - t[0]) : nan;
  std::int64_t knot = 0;  // current knot index i: x_i <= q
  double x_lo = x0, c_lo = 0.0;
  for (std::int64_t j = 0; j < m; ++j) {
    const std::int64_t qi = order[static_cast<std::size_t>(j)];
    const double q = query[qi];
    if (!(q >= x0) || n < 2 || !(q <= t[n - 1])) {  // outside (or NaN): NaN as np.interp's left/right
      out[qi] = nan;
      continue;
    }
    // advance while the next knot is <= q
    while (knot < n && t[knot] <= q) {
      const double* w = dtheta_b + 3 * knot;
      c_lo += w[0] * axis_b[0] + w[1] * axis_b[1] + w[2] * axis_b[2];
      x_lo = t[knot];
      ++knot;
    }
    if (knot == n || x_lo == q) {  // at a knot (the last one included)
      out[qi] = c_lo;
      continue;
    }
    const double* w = dtheta_b + 3 * knot;
    const double c_hi = c_lo + (w[0] * axis_b[0] + w[1] * axis_b[1] + w[2] * axis_b[2]);
    const double slope = (c_hi - c_lo) / (t[knot] - x_lo);
    out[qi] = slope * (q - x_lo) + c_lo;
  }
}

}  // namespace insnav::ins
