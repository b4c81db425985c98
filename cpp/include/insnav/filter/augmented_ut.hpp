// insnav/filter/augmented_ut.hpp -- the augmented-UT measurement update of
// seed 000 eqs. (15)-(21) on an assembled set of 4n+1 sigma points: the one
// implementation behind the UKF (ukf.hpp) and the per-particle UKF of the
// UPF (upf.hpp, UkfKernel).  The callers assemble the points (eq. (14): the
// 2n+1 propagated points, faded by seed 004's factors in the UPF, then
// xi_0 +- cols(sqrt((n + lambda) Q))) and keep their own policies for a
// failed update (counters, which state a non-finite result falls back to).
//
//   (15) z_i = h(X_i) = meas.predicted_residual(X_i)
//   (16) z^ = W0m z_0 + Wi sum_{i>0} z_i
//   (17) P_xz = sum Wc_i (X_i - x)(z_i - z^)^T      (x: the mean of the points)
//   (18) P_zz = sum Wc_i (z_i - z^)(z_i - z^)^T + R
//   (19) K = P_xz P_zz^-1                            (llt().solve(), never an inverse)
//   (20) x += K (residual - z^)
//   (21) P -= K P_zz K^T                             (lower triangle, then mirrored)
// Weights: ukf.hpp's header comment (W0m = 1 - 4n Wi makes the 4n+1 weights sum to 1).
// No heap: every matrix has fixed maximum sizes (R rows, at most kMaxMeasRows).
#pragma once

#include <Eigen/Cholesky>
#include <cmath>

#include "insnav/filter/sigma_points.hpp"
#include "insnav/filter/types.hpp"

namespace insnav {

/// Workspace of the update for R measurement rows (Eigen::Dynamic: up to kMaxMeasRows).
template <class L, int R = Eigen::Dynamic>
struct AugmentedUtWorkspace {
  static constexpr int kN = L::kSize;
  static constexpr int kAug = 4 * kN + 1;
  static constexpr int RM = (R == Eigen::Dynamic) ? kMaxMeasRows : R;
  using Points = Eigen::Matrix<double, kN, kAug>;
  using MatRR = Eigen::Matrix<double, R, R, 0, RM, RM>;
  using MatNR = Eigen::Matrix<double, kN, R, 0, kN, RM>;
  using MatRN = Eigen::Matrix<double, R, kN, 0, RM, kN>;
  using VecR = Eigen::Matrix<double, R, 1, 0, RM, 1>;
  using MatRA = Eigen::Matrix<double, R, kAug, 0, RM, kAug>;

  MatRA Z;
  VecR zmean, y, v;
  MatNR Pxz, K, KP;
  MatRN Kt;
  MatRR Pzz;
  Eigen::LLT<MatRR> llt{MatRR(R == Eigen::Dynamic ? 0 : RM, R == Eigen::Dynamic ? 0 : RM)};
  /// log N(residual; z^, P_zz) of the last update without the 2 pi constant
  /// (the UPF's particle weight); -inf when P_zz was not positive definite.
  double log_predictive = 0.0;
};

enum class AugmentedUtStatus { kApplied, kNotPositiveDefinite, kRejectedByGate };

/// Eqs. (15)-(21) on the points X (kN x (4n+1), centred on their mean x; they
/// hold the deviations X_i - x on return).  P: the prior covariance of the
/// points in, the posterior out (only when applied).  nis: the normalised
/// innovation squared (also when rejected by the gate; gate_chi2 <= 0: no gate).
template <class L, int R, class Meas>
AugmentedUtStatus augmented_ut_update(typename AugmentedUtWorkspace<L, R>::Points& X, const Meas& meas,
                                      const UtWeights<L::kSize>& w, StateVec<L>& x, StateCov<L>& P,
                                      double gate_chi2, AugmentedUtWorkspace<L, R>& ws, double& nis) {
  constexpr int kN = L::kSize;
  constexpr int kAug = 4 * kN + 1;
  const LinearMeasurement<L>& lin = meas.linear();
  const int r = lin.rows();
  const double wi = w.wi;
  const double w0m = 1.0 - 4.0 * kN * wi;  // weights of the 4n+1 points sum to 1
  const double w0c = w0m + 1.0 - w.alpha * w.alpha + w.beta;
  // (15)-(16)
  ws.Z.resize(r, kAug);
  for (int i = 0; i < kAug; ++i) ws.Z.col(i) = meas.predicted_residual(X.col(i));
  ws.zmean = w0m * ws.Z.col(0);
  ws.zmean += wi * ws.Z.template rightCols<kAug - 1>().rowwise().sum();
  X.colwise() -= x;
  ws.Z.colwise() -= ws.zmean;
  // (17)-(18)
  ws.Pxz.noalias() = wi * X.template rightCols<kAug - 1>() * ws.Z.template rightCols<kAug - 1>().transpose();
  ws.Pxz.noalias() += w0c * X.col(0) * ws.Z.col(0).transpose();
  ws.Pzz.noalias() = wi * ws.Z.template rightCols<kAug - 1>() * ws.Z.template rightCols<kAug - 1>().transpose();
  ws.Pzz.noalias() += w0c * ws.Z.col(0) * ws.Z.col(0).transpose();
  ws.Pzz += lin.R;
  ws.llt.compute(ws.Pzz);
  if (ws.llt.info() != Eigen::Success) {
    ws.log_predictive = -kInf;
    return AugmentedUtStatus::kNotPositiveDefinite;
  }
  ws.y = lin.residual - ws.zmean;
  ws.v = ws.y;
  ws.llt.matrixL().solveInPlace(ws.v);
  nis = ws.v.squaredNorm();
  ws.log_predictive = -0.5 * nis - ws.llt.matrixLLT().diagonal().array().log().sum();
  if (gate_chi2 > 0.0 && !(nis <= gate_chi2)) return AugmentedUtStatus::kRejectedByGate;
  // (19) K = P_xz P_zz^-1
  ws.Kt = ws.Pxz.transpose();
  ws.llt.solveInPlace(ws.Kt);
  ws.K = ws.Kt.transpose();
  // (20)-(21), the lower triangle then mirrored
  x.noalias() += ws.K * ws.y;
  ws.KP.noalias() = ws.K * ws.Pzz;
  P.template triangularView<Eigen::Lower>() -= ws.KP * ws.K.transpose();
  P.template triangularView<Eigen::StrictlyUpper>() = P.transpose();
  return AugmentedUtStatus::kApplied;
}

}  // namespace insnav
