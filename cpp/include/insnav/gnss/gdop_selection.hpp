// insnav/gnss/gdop_selection.hpp -- the best-GDOP subset of n satellites of an
// epoch, and of every epoch of a batch.
//
// The C++ twin of python/insnav/gnss/geometry.py (select_best_gdop, the
// reference of tests/test_gnss_geometry.py, which compares the two).  With the
// geometry matrix rows g_i = (-u_i, 1) of the line-of-sight unit vectors u_i
// (any frame: GDOP is invariant under a rotation), the normal matrix of a
// subset S is N_S = sum_{i in S} g_i g_i^T and GDOP = sqrt(trace(N_S^-1))
// (Misra & Enge, *Global Positioning System*, 2nd ed., sec. 6.1.2, eq. (6.14)).
//
//   * Exhaustive search when C(k, n) <= max_combinations: every subset in
//     lexicographic order, N_S summed over the chosen satellites or, when
//     fewer, the sum over all minus the left-out ones (as the reference does).
//   * Otherwise greedy backward elimination: from all k, repeatedly drop the
//     satellite whose removal gives the smallest GDOP.
//
// A subset whose N_S has a condition estimate ||N||_F ||N^-1||_F >= 1e12 (or
// no inverse) has GDOP = +inf.  Ties go to the first subset in the order of
// the reference.  Nothing is allocated: an epoch holds at most
// kGdopMaxSats satellites (select_best_gdop_batch returns Status::kBadInput
// otherwise).
#pragma once

#include <Eigen/Dense>
#include <cmath>
#include <cstdint>
#include <limits>

#include "insnav/check.hpp"

namespace insnav::gnss {

/// Most satellites of one epoch for the selection.
inline constexpr int kGdopMaxSats = 64;

namespace detail {

/// Number of n-subsets of k, saturated at cap + 1 (no overflow for any k <= kGdopMaxSats).
inline std::int64_t combinations_capped(int k, int n, std::int64_t cap) {
  if (n < 0 || n > k) return 0;
  if (n > k - n) n = k - n;
  // C(k, j) = C(k, j - 1) (k - j + 1) / j is exact at each step; stop once it exceeds the cap
  double c = 1.0;
  for (int j = 1; j <= n; ++j) {
    c = c * static_cast<double>(k - n + j) / static_cast<double>(j);
    if (c > static_cast<double>(cap)) return cap + 1;
  }
  return static_cast<std::int64_t>(std::llround(c));
}

/// GDOP of a 4 x 4 normal matrix (row-major); +inf for a singular or ill-conditioned one.
inline double gdop_of_normal(const double* N) {
  const Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> Nm(N);
  Eigen::Matrix4d Q;
  bool invertible = false;
  double det = 0.0;
  Nm.computeInverseAndDetWithCheck(Q, det, invertible, 0.0);
  if (!invertible) return std::numeric_limits<double>::infinity();
  const double cond = std::sqrt(Nm.squaredNorm() * Q.squaredNorm());
  if (!(std::isfinite(cond) && cond < 1e12)) return std::numeric_limits<double>::infinity();
  return std::sqrt(Q(0, 0) + Q(1, 1) + Q(2, 2) + Q(3, 3));
}

/// The next n-subset of {0..k-1} in lexicographic order; false after the last.
inline bool next_combination(int* c, int n, int k) {
  int i = n - 1;
  while (i >= 0 && c[i] == k - n + i) --i;
  if (i < 0) return false;
  ++c[i];
  for (int j = i + 1; j < n; ++j) c[j] = c[j - 1] + 1;
  return true;
}

}  // namespace detail

/// Best-GDOP subset of n_select of the k line-of-sight unit vectors u (k x 3, row-major).
///
/// Writes the chosen indices, ascending, to sel[0..m) and returns m = min(n_select, k); *gdop gets the
/// subset's GDOP.  Returns -1 (nothing written) for k > kGdopMaxSats or n_select < 4.
inline int select_best_gdop(const double* u, int k, int n_select, std::int64_t max_combinations, int* sel,
                            double* gdop) {
  if (k > kGdopMaxSats || n_select < 4 || k < 0) return -1;
  double outer[kGdopMaxSats][16];
  for (int i = 0; i < k; ++i) {
    const double g[4] = {-u[3 * i], -u[3 * i + 1], -u[3 * i + 2], 1.0};
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) outer[i][4 * r + c] = g[r] * g[c];
  }
  auto sum_rows = [&](const int* idx, int m, double* N) {
    for (int q = 0; q < 16; ++q) N[q] = outer[idx[0]][q];
    for (int j = 1; j < m; ++j)
      for (int q = 0; q < 16; ++q) N[q] += outer[idx[j]][q];
  };
  double N[16];
  if (n_select >= k) {
    for (int i = 0; i < k; ++i) sel[i] = i;
    if (k == 0) {
      *gdop = std::numeric_limits<double>::infinity();
      return 0;
    }
    sum_rows(sel, k, N);
    *gdop = detail::gdop_of_normal(N);
    return k;
  }
  if (detail::combinations_capped(k, n_select, max_combinations) <= max_combinations) {
    const bool direct = n_select <= k - n_select;
    const int r = direct ? n_select : k - n_select;
    double total[16];
    if (!direct) {
      int all[kGdopMaxSats];
      for (int i = 0; i < k; ++i) all[i] = i;
      sum_rows(all, k, total);
    }
    int c[kGdopMaxSats], best[kGdopMaxSats];
    for (int j = 0; j < r; ++j) c[j] = j;
    double g_best = std::numeric_limits<double>::infinity();
    bool have = false;
    do {
      sum_rows(c, r, N);
      if (!direct)
        for (int q = 0; q < 16; ++q) N[q] = total[q] - N[q];
      const double g = detail::gdop_of_normal(N);
      // the reference visits the left-out subsets in reverse lexicographic order and keeps the first
      // minimum: in lexicographic order that is the last one
      const bool better = !have || (direct ? g < g_best : g <= g_best);
      if (better) {
        g_best = g;
        have = true;
        for (int j = 0; j < r; ++j) best[j] = c[j];
      }
    } while (detail::next_combination(c, r, k));
    if (direct) {
      for (int j = 0; j < r; ++j) sel[j] = best[j];
    } else {
      int m = 0, j = 0;
      for (int i = 0; i < k; ++i) {
        if (j < r && best[j] == i) {
          ++j;
          continue;
        }
        sel[m++] = i;
      }
    }
    *gdop = g_best;
    return n_select;
  }
  // greedy backward elimination
  int keep[kGdopMaxSats], cand[kGdopMaxSats];
  int m = k;
  for (int i = 0; i < k; ++i) keep[i] = i;
  while (m > n_select) {
    int j_best = 0;
    double g_best = std::numeric_limits<double>::infinity();
    for (int j = 0; j < m; ++j) {
      int t = 0;
      for (int i = 0; i < m; ++i)
        if (i != j) cand[t++] = keep[i];
      sum_rows(cand, m - 1, N);
      const double g = detail::gdop_of_normal(N);
      if (g < g_best) {  // first minimum (all +inf: the first)
        g_best = g;
        j_best = j;
      }
    }
    for (int i = j_best; i < m - 1; ++i) keep[i] = keep[i + 1];
    --m;
  }
  for (int i = 0; i < m; ++i) sel[i] = keep[i];
  sum_rows(sel, m, N);
  *gdop = detail::gdop_of_normal(N);
  return m;
}

/// Best-GDOP subsets of every epoch with more than n_select rows.
///
/// u: (M x 3) line-of-sight unit vectors, row-major; epoch_start: (n_epochs + 1) row offsets.  keep[i]
/// is set to 1 for the chosen rows and 0 for the others of those epochs; rows of the other epochs are
/// left as they are.  Status::kBadInput for an epoch with more than kGdopMaxSats rows (to be
/// selected) or n_select < 4.
inline Status select_best_gdop_batch(const double* u, const std::int64_t* epoch_start, std::int64_t n_epochs,
                                     int n_select, std::int64_t max_combinations, std::uint8_t* keep) {
  if (n_select < 4) return Status::kBadInput;
  int sel[kGdopMaxSats];
  for (std::int64_t e = 0; e < n_epochs; ++e) {
    const std::int64_t a = epoch_start[e], b = epoch_start[e + 1];
    const std::int64_t k = b - a;
    if (k <= n_select) continue;
    if (k > kGdopMaxSats) return Status::kBadInput;
    double g = 0.0;
    const int m = select_best_gdop(u + 3 * a, static_cast<int>(k), n_select, max_combinations, sel, &g);
    if (m < 0) return Status::kBadInput;
    for (std::int64_t i = a; i < b; ++i) keep[i] = 0;
    for (int j = 0; j < m; ++j) keep[a + sel[j]] = 1;
  }
  return Status::kOk;
}

}  // namespace insnav::gnss
