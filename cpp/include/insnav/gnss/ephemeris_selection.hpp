// insnav/gnss/ephemeris_selection.hpp -- the broadcast record to use for each
// (satellite, time): among the usable records of that satellite whose
// reference time is within the record's window of t, the nearest; ties go to
// the record that appears last.
//
// The C++ twin of the per-satellite loops of python/insnav/gnss/ephemeris.py
// (select_ephemeris: GPS / Galileo / BeiDou toe and the fit interval,
// IS-GPS-200 20.3.4.4) and glonass.py (select_glonass: t_b and the age limit),
// which stay the reference (tests/test_gnss_ephemeris.py compares the two).
// The caller gives each record's window (0.5 fit + 1e-6 s, or the age limit)
// computed as the reference computes it, so that the comparisons are the same.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "insnav/check.hpp"

namespace insnav::gnss {

/// idx[i] = the record for row i (satellite row_prn[i] at row_t[i]), or -1.
///
/// Records r with rec_ok[r] != 0 and |row_t - rec_t[r]| <= rec_window[r] are candidates; the nearest
/// wins, the last of equals.  Status::kBadInput when the satellite numbers span more than 100000.
inline Status select_nearest_record(const std::int64_t* rec_prn, const std::uint8_t* rec_ok, const double* rec_t,
                                    const double* rec_window, std::int64_t n_rec, const std::int64_t* row_prn,
                                    const double* row_t, std::int64_t n_rows, std::int64_t* idx) {
  for (std::int64_t i = 0; i < n_rows; ++i) idx[i] = -1;
  if (n_rec == 0 || n_rows == 0) return Status::kOk;
  std::int64_t lo = rec_prn[0], hi = rec_prn[0];
  for (std::int64_t r = 0; r < n_rec; ++r) {
    lo = std::min(lo, rec_prn[r]);
    hi = std::max(hi, rec_prn[r]);
  }
  if (hi - lo > 100000) return Status::kBadInput;
  // the usable records of each satellite number, in file order (one grouping per call)
  const std::size_t span = static_cast<std::size_t>(hi - lo + 1);
  std::vector<std::int64_t> start(span + 1, 0), order;
  for (std::int64_t r = 0; r < n_rec; ++r)
    if (rec_ok[r]) ++start[static_cast<std::size_t>(rec_prn[r] - lo) + 1];
  for (std::size_t p = 0; p < span; ++p) start[p + 1] += start[p];
  order.resize(static_cast<std::size_t>(start[span]));
  {
    std::vector<std::int64_t> fill(start.begin(), start.end() - 1);
    for (std::int64_t r = 0; r < n_rec; ++r)
      if (rec_ok[r]) order[static_cast<std::size_t>(fill[static_cast<std::size_t>(rec_prn[r] - lo)]++)] = r;
  }
  for (std::int64_t i = 0; i < n_rows; ++i) {
    const std::int64_t p = row_prn[i];
    if (p < lo || p > hi) continue;
    const std::size_t b = static_cast<std::size_t>(p - lo);
    double best = INFINITY;
    std::int64_t arg = -1;
    for (std::int64_t q = start[b]; q < start[b + 1]; ++q) {
      const std::int64_t r = order[static_cast<std::size_t>(q)];
      const double dt = std::abs(row_t[i] - rec_t[r]);
      if (!(dt <= rec_window[r]) || !std::isfinite(dt)) continue;  // cost +inf in the reference
      if (dt <= best) {                      // ties: the last record
        best = dt;
        arg = r;
      }
    }
    idx[i] = arg;
  }
  return Status::kOk;
}

}  // namespace insnav::gnss
