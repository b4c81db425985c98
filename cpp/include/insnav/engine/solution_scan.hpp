// insnav/engine/solution_scan.hpp -- the per-row part of a run's health
// verdict (python/insnav/filters/health.py) in one pass over the solution:
// broken 1-sigma columns, non-finite positions, the longest step between two
// rows, the highest speed and heights outside a plausible range.  The pass
// only reports indices and extremes; health.py builds the one-line reasons.
// Plain C++17, no Python, no allocation.
//
// Step between rows k and k+1 (the small-step flat-Earth distance on a
// sphere of radius R = 6371 km, exactly as health.py defines it):
//   dn = (lat[k+1] - lat[k]) R,  de = (lon[k+1] - lon[k]) R cos(lat[k]),
//   step = sqrt(dn^2 + de^2 + (h[k+1] - h[k])^2)
// (lat, lon in rad: the solution's degrees times pi/180, as numpy.radians).
// Extremes skip NaN as numpy's nanmax / nanargmax do (first index of the
// maximum).
#pragma once

#include <cmath>
#include <cstdint>

namespace insnav {

/// A (n, 3) column block of doubles with a row stride (in elements).
struct RowBlock3 {
  const double* data = nullptr;
  std::int64_t row_stride = 3;
  std::int64_t col_stride = 1;
  double at(std::int64_t i, int c) const { return data[i * row_stride + c * col_stride]; }
};

/// A strided column of doubles.
struct Column {
  const double* data = nullptr;
  std::int64_t stride = 1;
  double at(std::int64_t i) const { return data[i * stride]; }
};

/// What one pass over the rows found (-1: none).
struct SolutionScan {
  std::int64_t first_bad_sigma[3] = {-1, -1, -1};  ///< per sigma block: first row with a value not finite or <= 0
  int first_bad_sigma_col[3] = {-1, -1, -1};       ///< ... its first such column
  std::int64_t bad_sigma_rows[3] = {0, 0, 0};      ///< ... rows with such a value
  std::int64_t first_nonfinite_pos = -1;           ///< first row whose lat, lon or h is not finite
  double max_step_m = std::nan("");                ///< longest finite step [m] (NaN: none)
  std::int64_t max_step_row = -1;                  ///< its first row k (step k -> k + 1)
  double max_speed_mps = std::nan("");             ///< highest finite |v_n| [m/s] (NaN: none)
  std::int64_t max_speed_row = -1;
  std::int64_t first_height_out = -1;              ///< first row with finite position and h outside [lo, hi]
  bool any_finite_step = false;                    ///< some step is finite
  bool any_finite_speed = false;                   ///< some speed is finite
};

/// One pass over n rows: lat_deg, lon_deg, h_m (columns), v_n (n, 3) [m/s]
/// and up to three (n, 3) sigma blocks (null: absent); heights outside
/// [h_lo_m, h_hi_m] are reported.  r_m: the sphere radius of the step [m].
inline SolutionScan scan_solution(std::int64_t n, Column lat_deg, Column lon_deg, Column h_m, RowBlock3 v_n,
                                  const RowBlock3* sigma, int n_sigma, double h_lo_m, double h_hi_m, double r_m) {
  constexpr double kDeg2Rad = 3.14159265358979323846 / 180.0;
  SolutionScan s;
  double best_step = -1.0, best_speed = -1.0;
  for (std::int64_t i = 0; i < n; ++i) {
    for (int b = 0; b < n_sigma && b < 3; ++b) {
      int bad_col = -1;
      for (int c = 0; c < 3 && bad_col < 0; ++c) {
        const double x = sigma[b].at(i, c);
        if (!(std::isfinite(x) && x > 0.0)) bad_col = c;
      }
      if (bad_col >= 0) {
        ++s.bad_sigma_rows[b];
        if (s.first_bad_sigma[b] < 0) {
          s.first_bad_sigma[b] = i;
          s.first_bad_sigma_col[b] = bad_col;
        }
      }
    }
    const double la = lat_deg.at(i) * kDeg2Rad, lo = lon_deg.at(i) * kDeg2Rad, h = h_m.at(i);
    const bool finite = std::isfinite(la) && std::isfinite(lo) && std::isfinite(h);
    if (!finite && s.first_nonfinite_pos < 0) s.first_nonfinite_pos = i;
    if (finite && s.first_height_out < 0 && (h < h_lo_m || h > h_hi_m)) s.first_height_out = i;
    if (i + 1 < n) {
      const double dn = (lat_deg.at(i + 1) * kDeg2Rad - la) * r_m;
      const double de = (lon_deg.at(i + 1) * kDeg2Rad - lo) * r_m * std::cos(la);
      const double dh = h_m.at(i + 1) - h;
      const double step = std::sqrt(dn * dn + de * de + dh * dh);
      s.any_finite_step = s.any_finite_step || std::isfinite(step);
      if (step > best_step) {  // false for NaN
        best_step = step;
        s.max_step_row = i;
      }
    }
    const double v0 = v_n.at(i, 0), v1 = v_n.at(i, 1), v2 = v_n.at(i, 2);
    const double speed = std::sqrt(v0 * v0 + v1 * v1 + v2 * v2);
    s.any_finite_speed = s.any_finite_speed || std::isfinite(speed);
    if (speed > best_speed) {
      best_speed = speed;
      s.max_speed_row = i;
    }
  }
  if (s.max_step_row >= 0) s.max_step_m = best_step;
  if (s.max_speed_row >= 0) s.max_speed_mps = best_speed;
  return s;
}

}  // namespace insnav
