// insnav/filter/covariance.hpp -- covariance health: symmetrise, check,
// repair.  Fixed size, no heap, never NaN.
//
// Repair strategy (used when llt() fails, or when P holds a non-finite value):
//  1. non-finite entries: an off-diagonal NaN/inf becomes 0, a diagonal one
//     becomes the largest finite diagonal variance (1 if there is none) --
//     the state is then uncertain rather than poisoned;
//  2. symmetrise, P = (P + P^T) / 2;
//  3. eigen-decompose (SelfAdjointEigenSolver, fixed size) and clamp every
//     eigenvalue to  floor = max(abs_floor, rel_floor * max(lambda_max, 0)),
//     P = V diag(max(lambda, floor)) V^T  -- the nearest (Frobenius) symmetric
//     matrix with eigenvalues >= floor (Higham 1988, "Computing a nearest
//     symmetric positive semidefinite matrix");
//  4. symmetrise again and verify with llt(); if the reconstruction still fails
//     (extreme conditioning) add diagonal jitter growing x10 from the floor.
// Every call that changes P counts as one repair.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace insnav {

struct RepairOptions {
  double rel_floor = 1e-12;  // eigenvalue floor relative to the largest eigenvalue
  double abs_floor = 1e-18;  // absolute eigenvalue floor [state units^2]
};

template <int N>
using SquareMat = Eigen::Matrix<double, N, N>;

/// P = (P + P^T) / 2 in place (no temporary on the heap).
template <int N>
inline void symmetrize(SquareMat<N>& P) {
  for (int j = 0; j < N; ++j)
    for (int i = j + 1; i < N; ++i) {
      const double a = 0.5 * (P(i, j) + P(j, i));
      P(i, j) = a;
      P(j, i) = a;
    }
}

template <int N>
inline bool all_finite(const SquareMat<N>& P) {
  return P.allFinite();
}

/// Largest state dimension the repair handles (every layout fits: 15..21).
inline constexpr int kMaxRepairSize = 32;

namespace detail {

/// Bounded dynamic-size square matrix: no heap, and one instantiation of the
/// eigen-solver machinery for every layout (the repair is rare; compiling
/// SelfAdjointEigenSolver once per fixed size N cost seconds per layout per
/// translation unit).
using RepairMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxRepairSize, kMaxRepairSize>;

/// Steps 3-4 of the strategy on a symmetric, finite P (any size <= kMaxRepairSize).
inline void clamp_eigenvalues(RepairMat& P, const RepairOptions& opt) {
  const Eigen::Index n = P.rows();
  Eigen::SelfAdjointEigenSolver<RepairMat> es(P);
  Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxRepairSize, 1> lam = es.eigenvalues();
  const double lmax = std::max(lam.maxCoeff(), 0.0);
  const double floor = std::max(opt.abs_floor, opt.rel_floor * lmax);
  for (Eigen::Index i = 0; i < n; ++i) lam[i] = std::max(lam[i], floor);
  const RepairMat& V = es.eigenvectors();
  RepairMat VL = V * lam.asDiagonal();
  P.noalias() = VL * V.transpose();
  P = (0.5 * (P + P.transpose())).eval();
  double jitter = floor;
  for (int k = 0; k < 20; ++k) {
    Eigen::LLT<RepairMat> llt(P);
    if (llt.info() == Eigen::Success) break;
    P.diagonal().array() += jitter;
    jitter *= 10.0;
  }
}

}  // namespace detail

/// Make P symmetric positive definite (strategy in the header comment).
/// Returns true if P had to be changed beyond symmetrisation (one repair).
template <int N>
bool repair_covariance(SquareMat<N>& P, const RepairOptions& opt = {}) {
  static_assert(N <= kMaxRepairSize, "repair_covariance: raise kMaxRepairSize");
  bool changed = false;
  if (!P.allFinite()) {
    double dmax = 0.0;
    for (int i = 0; i < N; ++i)
      if (std::isfinite(P(i, i))) dmax = std::max(dmax, std::abs(P(i, i)));
    if (dmax == 0.0) dmax = 1.0;
    for (int j = 0; j < N; ++j)
      for (int i = 0; i < N; ++i)
        if (!std::isfinite(P(i, j))) P(i, j) = (i == j) ? dmax : 0.0;
    changed = true;
  }
  symmetrize<N>(P);
  if (!changed) {
    Eigen::LLT<SquareMat<N>> llt(P);
    if (llt.info() == Eigen::Success) return false;
  }
  detail::RepairMat A = P;
  detail::clamp_eigenvalues(A, opt);
  P = A;
  symmetrize<N>(P);
  return true;
}

/// Lower Cholesky factor of P, repairing P first if needed.  Returns the
/// number of repairs (0 or 1).
template <int N>
int cholesky_with_repair(SquareMat<N>& P, SquareMat<N>& L_out, const RepairOptions& opt = {}) {
  int repairs = 0;
  symmetrize<N>(P);
  Eigen::LLT<SquareMat<N>> llt;
  if (P.allFinite()) {
    llt.compute(P);
    if (llt.info() == Eigen::Success) {
      L_out = llt.matrixL();
      return 0;
    }
  }
  repair_covariance<N>(P, opt);
  repairs = 1;
  llt.compute(P);
  L_out = llt.matrixL();
  if (llt.info() != Eigen::Success || !L_out.allFinite()) {  // cannot happen after the jitter loop; be safe
    L_out = P.diagonal().cwiseMax(opt.abs_floor).cwiseSqrt().asDiagonal();
  }
  return repairs;
}

/// Lower square-root factor of a positive *semi*-definite A (A = S S^T) by a
/// column Cholesky that zeroes a column whose pivot d_j is <= tol * A(j, j)
/// (process-noise matrices are singular: states without driving noise; the
/// test is relative to each state's own variance because Q's diagonal spans
/// many decades, e.g. 1e-2 m^2 against 1e-14 (rad/s)^2).
/// n^3/6 multiplications like llt(); exact for PSD matrices whose null space is
/// spanned by coordinate axes, approximate (to the tolerance) otherwise.
template <int N>
void psd_cholesky_lower(const SquareMat<N>& A, SquareMat<N>& S, double tol = 1e-10) {
  S.setZero();
  for (int j = 0; j < N; ++j) {
    double d = A(j, j);
    for (int k = 0; k < j; ++k) d -= S(j, k) * S(j, k);
    if (!(d > tol * A(j, j)) || !(A(j, j) > 0.0)) continue;  // column stays zero
    const double sjj = std::sqrt(d);
    S(j, j) = sjj;
    for (int i = j + 1; i < N; ++i) {
      double a = A(i, j);
      for (int k = 0; k < j; ++k) a -= S(i, k) * S(j, k);
      S(i, j) = a / sjj;
    }
  }
}

}  // namespace insnav
