// insnav/filter/flops.hpp -- analytic floating-point operation counts of the
// measurement updates (one flop = one add or one multiply; a Cholesky of a
// k x k matrix counts k^3 / 3).
//
// m = number of states, n = number of measurement rows, c = non-zero columns
// of H (block sparsity, LinearMeasurement::n_cols).  The first two functions
// are seed 000's counts (sec. 3, after eq. (25)), quoted from its ref. [15];
// for m = 15, n = 6 they give 29 295 and 17 091 flops (41.7 % less).  The
// others count the operations of this library's implementations line by line
// (rbukf.hpp, ukf.hpp), with h applied as a dense H_c x_c product.
// bench/update_cost.sh measures the same updates in instructions.
#pragma once

namespace insnav::flops {

/// seed 000: standard UKF sigma-point augmentation + measurement update, eqs. (14)-(21).
constexpr double ukf_update_paper(double m, double n) {
  return m * m * m / 3.0 + 3.0 * m * m * m + 10.0 * m * m * n + 6.0 * m * n * n + 4.0 * m * m + 3.0 * n * n +
         3.0 * m * n + 2.0 * n + m;
}

/// seed 000: RB-UKF (linear Kalman) measurement update, eqs. (22)-(24).
constexpr double rbukf_update_paper(double m, double n) {
  return 2.0 * m * m * m + 6.0 * m * m * n + 4.0 * m * n * n + n * n * n - m * m + m * n;
}

/// Relative saving of b over a: 1 - b / a.
constexpr double saving(double a, double b) { return 1.0 - b / a; }

namespace detail {
/// Common head of the linear updates with c columns of H in use:
/// y = residual - H_c x_c, U = P_(:,c) H_c^T, S = H_c U_(c,:) + R,
/// chol(S), v = L^-1 y, NIS = v'v.
constexpr double linear_head(double m, double n, double c) {
  return n * (2.0 * c - 1.0) + n        // y
         + m * n * (2.0 * c - 1.0)      // U
         + n * n * (2.0 * c - 1.0) + n * n  // S
         + n * n * n / 3.0              // chol
         + n * n + 2.0 * n;             // v, NIS
}
}  // namespace detail

/// This library, RbUkf with UpdateForm::kDensePaper: eq. (24) literally,
/// P = (I - K H) P over all m columns (what seed 000 counts).
constexpr double rbukf_dense_paper(double m, double n) {
  return detail::linear_head(m, n, m) + 2.0 * m * n * n  // K^T = S^-1 U^T (two triangular solves)
         + 2.0 * m * n                                    // x += K y
         + m * m * (2.0 * n - 1.0) + m                    // A = I - K H
         + m * m * (2.0 * m - 1.0);                       // A P
}

/// UpdateForm::kDenseJoseph: P = (I - K H) P (I - K H)^T + K R K^T, all m columns.
constexpr double rbukf_dense_joseph(double m, double n) {
  return detail::linear_head(m, n, m) + 2.0 * m * n * n + 2.0 * m * n + m * m * (2.0 * n - 1.0) + m  // A
         + 2.0 * m * m * (2.0 * m - 1.0)                                  // A P A^T
         + m * n * (2.0 * n - 1.0) + m * m * (2.0 * n - 1.0) + m * m;     // + K R K^T
}

/// UpdateForm::kBlockSparseJoseph: the Joseph form expanded,
/// P - K U^T - U K^T + K S K^T, with U and S from c columns
/// (K S K^T on the lower triangle only).
constexpr double rbukf_block_sparse_joseph(double m, double n, double c) {
  return detail::linear_head(m, n, c) + 2.0 * m * n * n + 2.0 * m * n  // K, x
         + m * n * (2.0 * n - 1.0)                                     // K S
         + m * m * (2.0 * n - 1.0)                                     // K U^T
         + m * (m + 1.0) / 2.0 * 2.0 * n                               // lower (K S) K^T, added
         + 2.0 * m * m;                                                // - K U^T - U K^T
}

/// UpdateForm::kBlockSparseFactored: W^T = L^-1 U^T, x += W v,
/// P -= W W^T (lower triangle only, mirrored).
constexpr double rbukf_block_sparse_factored(double m, double n, double c) {
  return detail::linear_head(m, n, c) + m * n * n  // one triangular solve, m right-hand sides
         + 2.0 * m * n                             // x += W v
         + m * (m + 1.0) * n;                      // lower triangle of W W^T, subtracted
}

/// This library's Ukf::update (augmented UT, eqs. (14)-(21)), h = H_c x_c.
constexpr double ukf_update(double m, double n, double c) {
  const double p = 4.0 * m + 1.0;                   // augmented points
  return m * m + m * m * m / 3.0                    // (n + lambda) Q, its Cholesky
         + 2.0 * m * m                              // xi_0 +- columns
         + p * n * (2.0 * c - 1.0)                  // h at every point
         + p * n                                    // z mean
         + p * (m + n)                              // deviations
         + m * n * 2.0 * p + n * n * 2.0 * p + n * n  // P_xz, P_zz (+ R)
         + n * n * n / 3.0 + n * n + 2.0 * n        // chol(P_zz), v, NIS
         + 2.0 * m * n * n + 2.0 * m * n            // K, x
         + m * n * (2.0 * n - 1.0)                  // K P_zz
         + m * (m + 1.0) * n;                       // lower (K P_zz) K^T, subtracted
}

}  // namespace insnav::flops
