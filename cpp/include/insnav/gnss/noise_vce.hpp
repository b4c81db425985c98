// Least-squares variance component estimation (LS-VCE) of the phase and code noise of an RTK run:
// the per-epoch normal equations of the estimator, summed over the fixed epochs' double differences
// (FixedDdRow in insnav/gnss/rtk.hpp; the orchestration, iteration and floors are in
// insnav.gnss.rtk_noise).
//
// Model per epoch (P. J. G. Teunissen, A. R. Amiri-Simkooei, "Least-squares variance component
// estimation", J. Geodesy 82 (2008) 65-82, sec. 3, W = Q_y^{-1}):
//
//   y = A dr + e,  Q_y = k_phi Q_phi + k_P Q_P,
//   N_kl = 1/2 tr(Q_k R Q_l R),  l_k = 1/2 y^T R Q_k R y,  R = W - W A (A^T W A)^{-1} A^T W.
//
// The two components are the phase and the code block of Q_y, which share no row.  With the Cholesky
// factor of each block, L_c L_c^T = k_c Q_c, and the whitened design and observations
// A~_c = L_c^{-1} A_c, y~_c = L_c^{-1} y_c, S_c = A~_c^T A~_c, M = S_phi + S_P = A^T W A,
// x^ = M^{-1} (A~^T y~) and e~_c = y~_c - A~_c x^, the trace and quadratic forms reduce to 3 x 3 work:
//
//   L^{-1} Q_c L^{-T} = D_c / k_c  (D_c: the selector of block c),  P = I - A~ M^{-1} A~^T,
//   N_kl = 1/(2 k_k k_l) [ [k == l] (m_k - 2 tr(M^{-1} S_k)) + tr(M^{-1} S_l M^{-1} S_k) ],
//   l_k  = 1/(2 k_k) |e~_k|^2,
//
// and the redundancy number of row i of block c, (P_A^perp)_ii = 1 - a_i^T M^{-1} (W_c A_c)_i with
// W_c A_c = L_c^{-T} A~_c.  Cost per epoch: the two Cholesky factorisations (m_c^3 / 3) and
// triangular solves with 4 right-hand sides, instead of the m x m products of R Q_k.
//
// No heap allocation per epoch: the blocks are bounded by kMaxVceRows rows of one kind (the engine's
// kMaxRows) and live in VceAccumulator, which the caller allocates once.
#pragma once

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace insnav::gnss {

inline constexpr int kMaxVceRows = 120;  // double differences of one kind (phase or code) in one epoch
// (a 120 x 120 block, 115 kB, stays within Eigen's default 128 KiB limit of fixed-capacity objects)

/// The fixed epochs' rows as parallel arrays (row i: epoch[i], code[i], ..., h[3 i .. 3 i + 2]).
struct VceRows {
  std::int64_t n = 0;
  const std::int64_t* epoch = nullptr;  // epoch index of the row
  const int* code = nullptr;            // 1 code, 0 phase
  const int* group = nullptr;           // rows of one kind and group share the reference satellite
  const double* y = nullptr;            // observed minus computed [m]
  const double* h = nullptr;            // d(computed)/d(r_e), n x 3 row-major [-]
  const double* var_own = nullptr;      // configured single-difference variance of the satellite [m^2]
  const double* var_ref = nullptr;      // ... of the group's reference satellite [m^2]
};

enum class VceStatus { kOk, kTooManyRows, kNotPositiveDefinite };

/// The sums of the LS-VCE normal equations over the usable epochs.
struct VceSums {
  Eigen::Matrix2d N = Eigen::Matrix2d::Zero();  // 1/2 sum tr(Q_k R Q_l R) [1/ (factor^2)]
  Eigen::Vector2d l = Eigen::Vector2d::Zero();  // 1/2 sum y^T R Q_k R y
  int n_epochs = 0;      // usable epochs: >= 4 rows, >= 1 phase row, rank(A) = 3
  int n_phase_rows = 0;  // rows of the usable epochs
  int n_code_rows = 0;
  VceStatus status = VceStatus::kOk;
  std::int64_t bad_epoch = -1;  // the epoch of a failure
};

/// Workspace and per-epoch kernel of the LS-VCE sums (allocate once, on the heap: about 0.5 MB).
class VceAccumulator {
 public:
  /// Adds the epoch made of rows ``idx[0 .. m)`` to ``sums`` at the variance factors ``k`` (k_phi, k_P);
  /// with ``redundancy`` non-null also writes the redundancy number of each of those rows to
  /// redundancy[idx[j]].  An unusable epoch (fewer than 4 rows, no phase row, rank(A) < 3) adds nothing
  /// and returns false.
  bool add_epoch(const VceRows& rows, const std::int64_t* idx, int m, const Eigen::Vector2d& k, VceSums& sums,
                 double* redundancy = nullptr) {
    int mc[2] = {0, 0};
    for (int j = 0; j < m; ++j) {
      const int c = rows.code[idx[j]] ? 1 : 0;
      if (mc[c] >= kMaxVceRows) {
        sums.status = VceStatus::kTooManyRows;
        sums.bad_epoch = rows.epoch[idx[j]];
        return false;
      }
      blk_[c].idx[mc[c]++] = idx[j];
    }
    if (m < 4 || mc[0] < 1) return false;
    // rank(A) as numpy.linalg.matrix_rank: singular values above s_max * max(m, 3) * eps
    a_all_.resize(m, 3);
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < 3; ++i) a_all_(j, i) = rows.h[3 * idx[j] + i];
    qr_.compute(a_all_);  // the singular values of A are those of its 3 x 3 triangular factor
    const Eigen::Matrix3d R3 = qr_.matrixQR().topRows<3>().triangularView<Eigen::Upper>();
    const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(R3).singularValues();
    const double tol = sv.maxCoeff() * static_cast<double>(std::max(m, 3)) * std::numeric_limits<double>::epsilon();
    if (!(sv(2) > tol)) return false;
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    Eigen::Matrix3d S[2] = {Eigen::Matrix3d::Zero(), Eigen::Matrix3d::Zero()};
    for (int c = 0; c < 2; ++c) {
      Block& B = blk_[c];
      B.m = mc[c];
      if (B.m == 0) continue;
      B.Q.resize(B.m, B.m);
      B.A.resize(B.m, 3);
      B.y.resize(B.m);
      for (int i = 0; i < B.m; ++i) {
        const std::int64_t ri = B.idx[i];
        for (int j = 0; j <= i; ++j)  // lower triangle: [same group] var_ref + [i == j] var_own
          B.Q(i, j) = k(c) * ((rows.group[ri] == rows.group[B.idx[j]] ? rows.var_ref[ri] : 0.0) +
                              (i == j ? rows.var_own[ri] : 0.0));
        for (int j = 0; j < 3; ++j) B.A(i, j) = rows.h[3 * ri + j];
        B.y(i) = rows.y[ri];
      }
      B.llt.compute(B.Q);  // reads the lower triangle
      if (B.llt.info() != Eigen::Success) {
        sums.status = VceStatus::kNotPositiveDefinite;
        sums.bad_epoch = rows.epoch[idx[0]];
        return false;
      }
      B.At = B.A;
      B.llt.matrixL().solveInPlace(B.At);  // A~ = L^{-1} A
      B.yt = B.y;
      B.llt.matrixL().solveInPlace(B.yt);
      S[c].noalias() = B.At.transpose() * B.At;
      M += S[c];
      b.noalias() += B.At.transpose() * B.yt;
    }
    const Eigen::LLT<Eigen::Matrix3d> Ml(M);
    if (Ml.info() != Eigen::Success) {
      sums.status = VceStatus::kNotPositiveDefinite;
      sums.bad_epoch = rows.epoch[idx[0]];
      return false;
    }
    const Eigen::Vector3d x = Ml.solve(b);
    const Eigen::Matrix3d T[2] = {Ml.solve(S[0]), Ml.solve(S[1])};  // M^{-1} S_c
    for (int p = 0; p < 2; ++p) {
      for (int q = p; q < 2; ++q) {
        double t = (T[q] * T[p]).trace();
        if (p == q) t += blk_[p].m - 2.0 * T[p].trace();
        const double v = 0.5 * t / (k(p) * k(q));
        sums.N(p, q) += v;
        if (p != q) sums.N(q, p) += v;
      }
      Block& B = blk_[p];
      if (B.m == 0) continue;
      B.et.noalias() = B.yt - B.At * x;  // whitened residual of the block
      sums.l(p) += 0.5 * B.et.squaredNorm() / k(p);
      if (redundancy != nullptr) {
        B.G = B.At;
        B.llt.matrixU().solveInPlace(B.G);  // W_c A_c = L^{-T} A~
        for (int i = 0; i < B.m; ++i) {
          const Eigen::Vector3d g = Ml.solve(B.G.row(i).transpose());
          redundancy[B.idx[i]] = 1.0 - B.A.row(i).dot(g);
        }
      }
    }
    ++sums.n_epochs;
    sums.n_phase_rows += mc[0];
    sums.n_code_rows += mc[1];
    return true;
  }

  /// The sums over all epochs; ``order`` lists the row indices with the rows of one epoch contiguous
  /// (for example a stable sort by epoch).  Stops at the first failure (sums.status).
  VceSums accumulate(const VceRows& rows, const std::int64_t* order, const Eigen::Vector2d& k,
                     double* redundancy = nullptr) {
    VceSums sums;
    std::int64_t s = 0;
    while (s < rows.n) {
      std::int64_t e = s + 1;
      while (e < rows.n && rows.epoch[order[e]] == rows.epoch[order[s]]) ++e;
      const std::int64_t m = e - s;
      if (m > 2 * kMaxVceRows) {
        sums.status = VceStatus::kTooManyRows;
        sums.bad_epoch = rows.epoch[order[s]];
        return sums;
      }
      add_epoch(rows, order + s, static_cast<int>(m), k, sums, redundancy);
      if (sums.status != VceStatus::kOk) return sums;
      s = e;
    }
    return sums;
  }

 private:
  using BlockMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxVceRows, kMaxVceRows>;
  using BlockA = Eigen::Matrix<double, Eigen::Dynamic, 3, 0, kMaxVceRows, 3>;
  using BlockV = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxVceRows, 1>;
  using AllA = Eigen::Matrix<double, Eigen::Dynamic, 3, 0, 2 * kMaxVceRows, 3>;
  struct Block {
    int m = 0;
    std::int64_t idx[kMaxVceRows] = {};
    BlockMat Q;
    Eigen::LLT<BlockMat> llt{kMaxVceRows};
    BlockA A, At, G;
    BlockV y, yt, et;
  };
  Block blk_[2];
  AllA a_all_;
  Eigen::HouseholderQR<AllA> qr_{2 * kMaxVceRows, 3};
};

}  // namespace insnav::gnss
