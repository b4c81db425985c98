// insnav/filter/kalman_update.hpp -- the linear Kalman measurement update in
// Joseph form, shared by the EKF and the RB-UKF (seed 000 eqs. (22)-(24)).
//
// Exploits block sparsity: only the first meas.n_cols columns of H are
// non-zero (6 for H = [I6 0], 9 with a lever arm), so S = H_c P_cc H_c^T + R
// and P H^T = P_(:,c) H_c^T touch only those columns of P.  Fixed maximum
// sizes, no heap; S is factorised once with llt() (never inverted).
#pragma once

#include <Eigen/Cholesky>

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
  if (gate_chi2 > 0.0 && !(res.nis <= gate_chi2)) {
    res.rejected_by_gate = true;
    return res;
  }
  const Gain K = llt.solve(PHt.transpose()).transpose();       // n x m
  x += K * y;
  // Joseph form: P = (I - K H) P (I - K H)^T + K R K^T, with H non-zero in c columns
  StateCov<L> IKH = StateCov<L>::Identity();
  IKH.leftCols(c) -= K * Hc;
  P = IKH * P * IKH.transpose() + K * lin.R * K.transpose();
  P = 0.5 * (P + P.transpose()).eval();
  res.applied = true;
  return res;
}

}  // namespace insnav
