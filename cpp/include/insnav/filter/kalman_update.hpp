// insnav/filter/kalman_update.hpp -- the linear Kalman measurement update in
// Joseph form, shared by the EKF and the RB-UKF (seed 000 eqs. (22)-(24)).
//
// Exploits block sparsity: only the first meas.n_cols columns of H are
// non-zero (6 for H = [I6 0], 9 with a lever arm), so S = H_c P_cc H_c^T + R
// and P H^T = P_(:,c) H_c^T touch only those columns of P.  Fixed maximum
// sizes, no heap; S is factorised once with llt() (never inverted); the
// covariance update costs 2 n m c + n m^2 + 2 n^2 m multiplications instead
// of 2 n^3 + n c m + n m^2 + n^2 m.
#pragma once

#include <Eigen/Cholesky>

#include "insnav/filter/covariance.hpp"
#include "insnav/filter/types.hpp"

namespace insnav {

/// In-place update of (x, P) with the linear measurement `lin`.
/// The innovation is y = residual - H x; gating by NIS = y' S^-1 y when
/// gate_chi2 > 0 (the update is then skipped, result.rejected_by_gate).
template <class L>
UpdateResult kalman_update(StateVec<L>& x, StateCov<L>& P, const LinearMeasurement<L>& lin,
                           double gate_chi2) {
  constexpr int n = L::kSize;
  using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  using Gain = Eigen::Matrix<double, n, Eigen::Dynamic, 0, n, kMaxMeasRows>;
  using Vm = typename LinearMeasurement<L>::RowVec;
  UpdateResult res;
  const int m = lin.rows();
  res.rows = m;
  if (m == 0) return res;
  const int c = lin.n_cols;
  const auto Hc = lin.H.leftCols(c);
  const Vm y = lin.residual - Hc * x.head(c);
  const Gain PHt = P.leftCols(c) * Hc.transpose();           // n x m
  Dyn S = Hc * PHt.topRows(c) + lin.R;                         // m x m
  S = 0.5 * (S + S.transpose()).eval();
  Eigen::LLT<Dyn> llt(S);
  if (llt.info() != Eigen::Success) {
    res.cholesky_repairs = 1;
    return res;  // S not PD: refuse the update rather than corrupt P
  }
  res.nis = y.dot(llt.solve(y));
  res.log_det_s = 2.0 * llt.matrixLLT().diagonal().array().log().sum();
  if (gate_chi2 > 0.0 && !(res.nis <= gate_chi2)) {
    res.rejected_by_gate = true;
    return res;
  }
  const Gain K = llt.solve(PHt.transpose()).transpose();       // n x m
  x.noalias() += K * y;
  // Joseph form P = (I - K H) P (I - K H)^T + K R K^T with the identity and
  // the zero columns of H taken out (no n x n x n product):
  //   X = (I - K H) P = P - K (H_c P_c,:),   P = X - (X_:,c H_c^T - K R) K^T.
  // (The bracket vanishes for the optimal gain; computed, it is the round-off
  // correction that makes the Joseph form robust.)
  using Wide = Eigen::Matrix<double, Eigen::Dynamic, n, 0, kMaxMeasRows, n>;
  Wide HP;
  HP.noalias() = Hc * P.topRows(c);                           // m x n
  P.noalias() -= K * HP;                                      // X
  Gain T = -K * lin.R;                                        // n x m
  T.noalias() += P.leftCols(c) * Hc.transpose();
  P.noalias() -= T * K.transpose();
  symmetrize<n>(P);
  res.applied = true;
  return res;
}

}  // namespace insnav
