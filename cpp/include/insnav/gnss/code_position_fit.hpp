// insnav/gnss/code_position_fit.hpp -- one epoch's code-only position fit (Gauss-Newton weighted
// least squares for position, a reference receiver clock and inter-system biases), shared by the SPP
// batch solver (spp_solver.hpp) and the RTK path's code-fit check of its input files (rtk_rinex.hpp).
//
// Model (Misra & Enge, *Global Positioning System*, 2nd ed., sec. 6.1; Groves 2013, eq. (9.141)):
//   rho_k = |r_s,k - r| + b + [col_k > 0] ISB_col_k - c dt_sv,k + e_k,   weights w_k = 1 / sigma_k.
// Frames: ECEF, the satellite at reception with the Earth's rotation applied by the caller.  SI.
// Fixed capacity: at most kSppMaxRows rows and kSppMaxParams unknowns, nothing allocated.
#pragma once

#include <Eigen/Dense>

#include "insnav/math/rotation.hpp"

namespace insnav::gnss {

/// Systems with a clock column in a position fit (GPS, GLONASS, Galileo, BeiDou).
inline constexpr int kSppNumSystems = 4;
/// Most rows (satellites) of one epoch.
inline constexpr int kSppMaxRows = 64;
/// Most position-fix unknowns: 3 position, the reference clock, 3 inter-system biases.
inline constexpr int kSppMaxParams = 3 + kSppNumSystems;

using SppRowsMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kSppMaxRows, kSppMaxParams>;
using SppRowsVec = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kSppMaxRows, 1>;
using SppParVec = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kSppMaxParams, 1>;
using SppRowsBy3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::ColMajor, kSppMaxRows, 3>;

/// One row of a code-only position fit: the satellite at reception in ECEF (Earth rotation applied)
/// [m], the pseudorange [m] and the satellite clock term it is corrected by (c dt_sv minus modelled
/// delays) [m].
struct CodeFitRow {
  Vec3 r_s;
  double pr_m;
  double sat_clock_m;
};

/// One epoch's code-only position fit by Gauss-Newton, weighted least squares solved by a complete
/// orthogonal decomposition of the whitened design.  Unknowns x = (r_e [m], the reference clock [m],
/// then one inter-system bias [m] per further clock column); row k (row(k) -> CodeFitRow, clock column
/// col[k], 0 the reference) observes pr_k = |r_s,k - r_e| - c dt_sv,k + x_3 + [col_k > 0] x_{3 + col_k}.
/// Starts from x as given (np unknowns) and stops when the position step is below 0.1 mm, after at most
/// `iterations` steps.  Returns true with H (the design), u (unit vectors receiver -> satellite), rng
/// (ranges) and y (residuals) at the solution; false when it diverges or does not converge.
template <class Row>
inline bool code_position_fit(int n, int np, const Row& row, const int* col, const SppRowsVec& w, int iterations,
                              SppParVec& x, SppRowsMat& H, SppRowsBy3& u, SppRowsVec& rng, SppRowsVec& y) {
  H.resize(n, np);
  u.resize(n, 3);
  rng.resize(n);
  y.resize(n);
  auto design = [&]() {
    H.setZero();
    for (int k = 0; k < n; ++k) {
      const CodeFitRow s = row(k);
      const Vec3 d = s.r_s - x.head<3>();
      rng[k] = d.norm();
      u.row(k) = (d / rng[k]).transpose();
      H.block<1, 3>(k, 0) = -u.row(k);
      H(k, 3) = 1.0;
      if (col[k] > 0) H(k, 3 + col[k]) = 1.0;
      const double clk = x[3] + (col[k] > 0 ? x[3 + col[k]] : 0.0);
      y[k] = s.pr_m - (rng[k] - s.sat_clock_m + clk);
    }
  };
  for (int it = 0; it < iterations; ++it) {
    design();
    const SppRowsMat Hw = w.asDiagonal() * H;
    const SppRowsVec yw = y.cwiseProduct(w);
    const SppParVec dx = Eigen::CompleteOrthogonalDecomposition<SppRowsMat>(Hw).solve(yw);
    x += dx;
    if (!x.allFinite()) return false;
    if (dx.head<3>().norm() < 1e-4) {
      design();
      return true;
    }
  }
  return false;
}

}  // namespace insnav::gnss
