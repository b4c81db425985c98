// insnav/gnss/double_difference.hpp -- the observation row layout of the carrier-phase engines and
// the two steps of forming double differences that the GNSS-only RTK engine (gnss/rtk.hpp) and the
// tight RTK/INS engine (engine/rtk_ins_engine.hpp) share:
//
//   1. common satellites: the rover rows whose satellite the base epoch also holds, both with a
//      satellite position (an orbit): match_common_satellites();
//   2. the reference satellite of each system and frequency: the candidate of highest elevation
//      (the first of equal ones), so that the double differences s - i, s != i, have the smallest
//      reference noise (Teunissen & Montenbruck (eds.), Springer Handbook of GNSS, 2017, sec. 26.2;
//      RTKLIB 2.4.2 manual, Appendix E.7): highest_elevation_reference().  The same rule picks the
//      reference ambiguity of the AR candidates (the single-differenced ambiguity slots eligible for
//      fixing).
//
// No heap allocation: the caller owns the fixed-size index arrays.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

namespace insnav::gnss {

/// Systems of the RTK engines (index order of the per-row ``system`` column).
enum RtkSystem : int { kGps = 0, kGlonass = 1, kGalileo = 2, kBeidou = 3, kQzss = 4, kNumSystems = 5 };

inline constexpr int kMaxFreq = 3;        // frequency slots per system
inline constexpr int kMaxPrn = 64;        // satellite numbers per system
inline constexpr int kMaxSatKeys = kNumSystems * kMaxPrn;

/// Column layout of one observation row (one satellite of one receiver epoch).
struct RtkRow {
  static constexpr int kSat = 0;     // key = system * 64 + prn
  static constexpr int kSys = 1;     // RtkSystem
  static constexpr int kFreq0 = 2;   // per frequency slot f: kFreq0 + 5 f + {0 P [m], 1 L [cyc], 2 D [Hz], 3 LLI, 4 lambda [m]}
  static constexpr int kPerFreq = 5;
  static constexpr int kSatPos = kFreq0 + kPerFreq * kMaxFreq;  // r^s at transmission, ECEF of that instant [m]
  static constexpr int kSatClock = kSatPos + 3;                 // c dt^s [m]
  static constexpr int kCols = kSatClock + 1;
};

/// The median of buf[0..n) (reordered in place; NaN for n = 0).  Used for the single-differenced
/// receiver clock (rover - base) [m] of an ambiguity initialised without code (gnss/rtk.hpp and
/// engine/rtk_ins_engine.hpp init_amb): the median over the system's satellites of
/// SD(code) - SD(geometry).
inline double median_in_place(double* buf, int n) {
  if (n <= 0) return NAN;
  std::nth_element(buf, buf + n / 2, buf + n);
  const double hi = buf[n / 2];
  return n % 2 ? hi : 0.5 * (hi + *std::max_element(buf, buf + n / 2));
}

/// The satellite key (system * 64 + prn) of an RtkRow, clamped into [0, kMaxSatKeys).
inline int sat_key(const double* row) {
  const int k = static_cast<int>(row[RtkRow::kSat]);
  return (k >= 0 && k < kMaxSatKeys) ? k : 0;
}

/// Common satellites of a rover epoch (n_r rows) and a base epoch (n_b rows), RtkRow layout: for
/// each rover row i, in rover order, whose satellite key the base also has and whose satellite
/// position is finite in both, common_r[c] = i and common_b[c] = the base row.  base_of is the
/// caller's workspace (base row per key, -1 where absent; filled here).  Returns the count c.
inline int match_common_satellites(const double* rover, int n_r, const double* base, int n_b,
                                   std::array<int, kMaxSatKeys>& base_of, int* common_r, int* common_b) {
  base_of.fill(-1);
  for (int j = 0; j < n_b; ++j) base_of[sat_key(base + j * RtkRow::kCols)] = j;
  int n = 0;
  for (int i = 0; i < n_r; ++i) {
    const double* rr = rover + i * RtkRow::kCols;
    const int j = base_of[sat_key(rr)];
    if (j < 0) continue;
    if (!std::isfinite(rr[RtkRow::kSatPos]) || !std::isfinite(base[j * RtkRow::kCols + RtkRow::kSatPos])) continue;
    common_r[n] = i;
    common_b[n] = j;
    ++n;
  }
  return n;
}

/// The reference of one system and frequency: of the candidates k in [0, n) with ok(k), the one of
/// highest elevation el(k) [rad] (the first of equal ones); -1 when there is none.
template <class Ok, class El>
int highest_elevation_reference(int n, Ok&& ok, El&& el) {
  int ref = -1;
  double el_ref = 0.0;
  for (int k = 0; k < n; ++k) {
    if (!ok(k)) continue;
    const double e = el(k);
    if (ref < 0 || e > el_ref) {
      ref = k;
      el_ref = e;
    }
  }
  return ref;
}

}  // namespace insnav::gnss
