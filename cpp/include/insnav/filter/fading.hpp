// insnav/filter/fading.hpp -- residual-constrained adaptive fading with
// multiple suboptimal fading factors (strong tracking; seed 004 eqs. (1)-(6),
// after Zhou Donghua, Xi Yugeng, Zhang Zhongjun, "A suboptimal multiple fading
// extended Kalman filter", Acta Automatica Sinica 17(6), 1991, seed 004 ref. [6]).
//
// Orthogonality principle (seed 004 eq. (1)): choose the predicted covariance
// so that the innovation sequence stays white,
//   E[gamma_{k+j} gamma_k^T] = 0,  j >= 1,
// which holds approximately (eq. (2)) when P_xz,k - K_k C_0,k = 0, i.e. when
// the innovation covariance the filter predicts equals the one it sees:
//   H Pbar H^T + R = C_0,k,   Pbar = Lambda P^- + Q   (eq. (3)),
// P^- the propagated spread without the process noise Q.  With
// Lambda = diag(eta_i), eta_i = alpha_i c_k, and traces on both sides:
//   c_k   = tr(N_k) / tr(diag(alpha) M_k)                             (eq. (5))
//   N_k   = C_0,k - beta R - H Q H^T,   M_k = P^- H^T H  (n x n; tr(diag(a) M) = sum a_i M_ii)
//   eta_i = max(1, alpha_i c_k)                                        (eq. (4))
//   C_0,k = (rho C_0,k-1 + gamma_k gamma_k^T) / (1 + rho),  0 < rho <= 1 (eq. (6))
// (equations (1)-(6) were lost in extraction; these are the standard forms of
// the seed's ref. [6] that the digest names).
//
// Choices made here (not in the paper):
//  * Whitening: all traces are taken after whitening the rows with R^{-1/2}
//    (gamma~ = L_R^-1 gamma, H~ = L_R^-1 H, R~ = I): a pseudorange row [m] and
//    a pseudorange-rate row [m/s] then count alike; without it the rate rows
//    (1e4 times smaller numbers) would never influence c_k.
//  * Only tr(C_0) enters c_k, and the trace of recursion (6) is the same
//    recursion on tr(C_0); it is carried per row, s_k = tr(C~_0,k) / m, so it
//    stays meaningful when satellites rise or set (the m x m recursion is not
//    defined when the rows change).  tr(N~) = m (s_k - beta) - tr(H~ Q H~^T).
//  * beta >= 1 is Zhou's softening factor (default 2): with beta = 1 the
//    factor is exactly 1 only on average and exceeds 1 on about half of the
//    epochs through the noise of a single-epoch C_0; beta > 1 keeps eta = 1 in
//    steady state and lets it rise on a real inconsistency.
//  * eta_max caps the factors (default 1e3): a single wild epoch cannot blow
//    the covariance up without bound.
//  * alpha_i = 0 is allowed and switches the fading of state i off (eta_i = 1;
//    Zhou's alpha_i >= 1 encode which states are expected to jump).  Fading a
//    weakly observable state (yaw, gyro biases) multiplies its variance on
//    every fading epoch while the measurements shrink it only slowly, so it
//    grows without bound: on seed004-uav alpha = 1 for all 20 states makes the
//    fading UKF diverge within 600 s; insnav.filters.particle fades only the
//    position, velocity and clock states (alpha = 1 there, 0 elsewhere).
//  * Lambda is applied symmetrically, Pbar = Lambda^1/2 P^- Lambda^1/2 + Q: the
//    diagonal gets eta_i as in Lambda P^-, and Pbar stays symmetric.
//  * H is the measurement's analytic Jacobian (meas.linear().H); the UKF
//    update itself stays nonlinear.
//  * Memory of recursion (6) (FadingMemoryForm).  kInnovation is eq. (6) as
//    written: it averages the raw innovation power.  After a GNSS outage the
//    first innovation is large and fully explained by the grown P (c_k ~ 0.06
//    on seed004-uav); the update then shrinks P, but C_0 still remembers that
//    epoch for a few more (rho = 0.95 weighs it 0.49 one epoch later), so
//    tr(N) / tr(M) jumps (c_k ~ 10 at the second epoch, whose own NIS is
//    normal) and the fading throws away the prior it just built: the
//    correction follows single-epoch noise (bench/seed004_tables.py: the
//    "fading memory" table and trace).  kNis averages the innovation power
//    *relative to the covariance predicted at its own epoch* (NIS per row,
//    s_k = gamma~^T S~^-1 gamma~ / m) and rescales it by the current epoch's
//    tr(S~)/m:  tr(C~_0) ~= s_k tr(S~_k).  Consistent innovations then give
//    c_k < 1 whatever P did in between, and innovations persistently larger
//    than predicted (the model missed a change) still raise c_k by their ratio.
// Everything fixed-size / bounded; nothing allocates.
#pragma once

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

#include "insnav/filter/types.hpp"

namespace insnav {

/// What recursion (6) averages (see the file comment).
enum class FadingMemoryForm : int {
  kInnovation = 0,  ///< raw innovation power, eq. (6) as written
  kNis = 1,         ///< innovation power relative to its own epoch's S (regime-robust)
};

/// Tuning of the adaptive fading (seed 004 eqs. (4)-(6)).
template <int N>
struct FadingParams {
  bool enabled = false;
  FadingMemoryForm memory = FadingMemoryForm::kInnovation;
  double rho = 0.95;   // forgetting factor, 0 < rho <= 1 (eq. (6))
  double beta = 2.0;   // softening factor >= 1 (Zhou 1991)
  double eta_max = 1e3;
  Eigen::Matrix<double, N, 1> alpha = Eigen::Matrix<double, N, 1>::Ones();  // a priori ratios (0: no fading)
};

/// Per-filter (per-particle) memory of the fading recursion: s = tr(C~_0) / m.
struct FadingMemory {
  double s = 0.0;
  int epochs = 0;  // epochs seen (0: the next gamma initialises C_0)
  double c_last = 0.0;
  void reset() { s = 0.0; epochs = 0; c_last = 0.0; }
};

/// Workspace of the fading-factor computation (bounded; no heap).
template <class L>
struct FadingWorkspace {
  static constexpr int kN = L::kSize;
  using RowVec = typename LinearMeasurement<L>::RowVec;
  using HMat = Eigen::Matrix<double, Eigen::Dynamic, kN, 0, kMaxMeasRows, kN>;
  using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  HMat Ht, HtQ;
  RowVec g;
  Dyn R;
  // factorised once (0 x 0) so a copied workspace never reads Eigen's uninitialised info()
  Eigen::LLT<Dyn> llt{Dyn(0, 0)};
  Eigen::LLT<Dyn> llt_S{Dyn(0, 0)};
  Dyn S;
  RowVec u;
  StateCov<L> G, PQ;
};

/// The fading factors eta (eq. (4)) of one epoch from the innovation gamma =
/// residual - h(x_pred), the Jacobian H and noise R of the measurement, the
/// propagated spread P^- (without Q) and the process noise Q of the cycle.
/// Updates `mem` (eq. (6)).  Returns c_k (eq. (5)); eta = 1 when disabled.
template <class L>
double fading_factors(const typename LinearMeasurement<L>::RowVec& gamma, const LinearMeasurement<L>& lin,
                      const StateCov<L>& P_minus, const StateCov<L>& Q, const FadingParams<L::kSize>& prm,
                      FadingMemory& mem, FadingWorkspace<L>& ws, StateVec<L>& eta) {
  eta.setOnes();
  const int m = lin.rows();
  if (!prm.enabled || m == 0) return 0.0;
  // whitening: R = L_R L_R^T
  ws.R = lin.R;
  ws.llt.compute(ws.R);
  if (ws.llt.info() != Eigen::Success) return 0.0;
  ws.g = gamma;
  ws.llt.matrixL().solveInPlace(ws.g);
  ws.Ht = lin.H;
  ws.llt.matrixL().solveInPlace(ws.Ht);
  ws.HtQ.noalias() = ws.Ht * Q;
  const double trHQH = (ws.HtQ.cwiseProduct(ws.Ht)).sum();
  // eq. (6) on the trace, per row
  double s_now = ws.g.squaredNorm() / m;
  double scale = 1.0;  // tr(C~_0) / m = mem.s * scale
  if (prm.memory == FadingMemoryForm::kNis) {
    // S~ = H~ (P^- + Q) H~^T + I; s_now = NIS per row; scale = tr(S~) / m
    ws.PQ = P_minus + Q;
    ws.S.noalias() = ws.Ht * ws.PQ * ws.Ht.transpose();
    ws.S.diagonal().array() += 1.0;
    ws.llt_S.compute(ws.S);
    if (ws.llt_S.info() != Eigen::Success) return 0.0;
    ws.u = ws.g;
    ws.llt_S.matrixL().solveInPlace(ws.u);
    s_now = ws.u.squaredNorm() / m;
    scale = ws.S.trace() / m;
  }
  mem.s = mem.epochs == 0 ? s_now : (prm.rho * mem.s + s_now) / (1.0 + prm.rho);
  ++mem.epochs;
  // tr(N~) = m (s - beta) - tr(H~ Q H~^T)
  const double trN = m * (mem.s * scale - prm.beta) - trHQH;
  // M = P^- H~^T H~ ; tr(diag(alpha) M) = sum_i alpha_i sum_j P^-_ij G_ji
  ws.G.noalias() = ws.Ht.transpose() * ws.Ht;
  double trM = 0.0;
  for (int i = 0; i < L::kSize; ++i) trM += prm.alpha[i] * P_minus.row(i).dot(ws.G.col(i));
  double c = 0.0;
  if (trM > 0.0 && trN > 0.0) c = trN / trM;
  mem.c_last = c;
  for (int i = 0; i < L::kSize; ++i) eta[i] = std::min(prm.eta_max, std::max(1.0, prm.alpha[i] * c));
  return c;
}

}  // namespace insnav
