// insnav/meas/pseudorange_gm.hpp -- time-correlated pseudorange errors as
// first-order Gauss-Markov states of the tight EKF (engine/tight_engine.hpp,
// TightConfig::pr_gm; off by default).
//
// Model (Gelb 1974, "Applied Optimal Estimation", sec. 3.8 and Table 3.8-1:
// the first-order Markov process b' = -b / tau + w with stationary variance
// sigma^2, discretised exactly): per satellite s
//   b_s,k = a b_s,k-1 + w_k,   a = exp(-dt / tau),   Var w_k = sigma^2 (1 - a^2),
// the measured pseudorange is rho + c dt_r + b_s + v (v white, the row's own
// sigma), and a satellite's state starts at 0 with variance sigma^2 when it
// enters.  The filter's state is the error of the estimate, x_b = b^ - b
// (computed - true, as the clock states), so the INS-predicted pseudorange
// carries + b^ and the pseudorange row gets +1 in the b_s column; the Doppler
// rows have no b column.  Closed loop: b^ -= x_b after the update.
//
// Bookkeeping as the RTK/INS ambiguity block (engine/rtk_ins_engine.hpp): a
// fixed-capacity block of kMaxGm states beside the core's navigation states,
// with an active mask keyed by satellite (system * 64 + prn), the cross-
// covariance P_xb carried over a filter cycle by the EKF's cycle transition
// (P_xb <- Phi_cycle P_xb; the b states have no IMU-rate dynamics), and a
// state removed when its satellite has not been seen for max_gap_s (a
// re-acquisition after a longer gap starts a new state).
//
// The update goes through the core's own EKF update (gate, robust screening,
// FDE, NIS and log det S unchanged) by marginalising b exactly: with
// G = P_bx P_xx^-1 and e = b - G x (independent of x, covariance
// P_e = P_bb - G P_xb), a pseudorange row y = H_x x + D b + v reads
//   y = (H_x + D G) x + (D e + v),
// i.e. the core's update with H' = H_x + D G and R' = R + D P_e D^T, whose
// innovation covariance S = H' P_xx H'^T + R' is the joint one.  The b part
// of the joint posterior then follows from the same S (joint_posterior()):
// with U = P_xx H'^T and W = D P_e,
//   e+ = W^T S^-1 nu,  P_ee+ = P_e - W^T S^-1 W,  P_xe+ = -U S^-1 W,
//   b+ = G x+ + e+,    P_bx+ = G P_xx+ + P_ex+,  P_bb+ = G P_xx+ G^T + G P_xe+ + P_ex+ G^T + P_ee+,
// which is the joint Kalman update of [x; b] (a linear change of variables
// of it).  Fixed sizes; no heap.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Dense>

#include <cmath>

#include "insnav/filter/types.hpp"

namespace insnav {

/// Gauss-Markov pseudorange errors (TightConfig::pr_gm).  sigma_m = 0: off
/// (the engine is then the filter without the block, bit for bit).
struct PseudorangeGmConfig {
  double sigma_m = 0.0;     // stationary 1-sigma of b_s [m] (0: no block)
  double tau_s = 60.0;      // correlation time [s]
  double max_gap_s = 10.0;  // a state unobserved this long is removed [s]
  bool enabled() const { return sigma_m > 0.0; }
};

/// The block of kMaxGm per-satellite states and its covariance with the kN
/// navigation error states (engine/tight_engine.hpp).
template <int kN, int kMaxGm = 32>
class PseudorangeGmBlock {
 public:
  static constexpr int kKeys = 4 * 64;  // system (0..3) * 64 + prn
  using NMat = Eigen::Matrix<double, kN, kN>;
  using XbMat = Eigen::Matrix<double, kN, kMaxGm>;
  using BbMat = Eigen::Matrix<double, kMaxGm, kMaxGm>;
  using BVec = Eigen::Matrix<double, kMaxGm, 1>;
  using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  using Vm = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxMeasRows, 1>;
  using MxN = Eigen::Matrix<double, Eigen::Dynamic, kN, 0, kMaxMeasRows, kN>;
  using MxB = Eigen::Matrix<double, Eigen::Dynamic, kMaxGm, 0, kMaxMeasRows, kMaxGm>;

  static int key(int system, int prn) { return (system & 3) * 64 + (prn & 63); }

  void reset(const PseudorangeGmConfig& cfg) {
    cfg_ = cfg;
    b_.setZero();
    Pxb_.setZero();
    Pbb_.setZero();
    for (int k = 0; k < kMaxGm; ++k) slot_key_[k] = -1;
    for (int i = 0; i < kKeys; ++i) slot_of_[i] = -1;
    t_ = NAN;
  }

  /// The navigation errors' transition over a closed filter cycle: P_xb <- Phi P_xb.
  void carry_cycle(const NMat& Phi) { Pxb_ = (Phi * Pxb_).eval(); }

  /// Gauss-Markov propagation of every active state to time t [s] (Gelb 1974, Table 3.8-1).
  void propagate_to(double t) {
    if (std::isfinite(t_) && t > t_) {
      const double a = std::exp(-(t - t_) / cfg_.tau_s);
      b_ *= a;
      Pxb_ *= a;
      Pbb_ *= a * a;
      const double q = cfg_.sigma_m * cfg_.sigma_m * (1.0 - a * a);
      for (int k = 0; k < kMaxGm; ++k)
        if (slot_key_[k] >= 0) Pbb_(k, k) += q;
    }
    t_ = t;
  }

  /// Remove the states whose satellite was last seen more than max_gap_s before t.
  void expire(double t) {
    for (int k = 0; k < kMaxGm; ++k)
      if (slot_key_[k] >= 0 && t - t_seen_[k] > cfg_.max_gap_s) remove(k);
  }

  /// The slot of satellite `key` seen at t (a new state, variance sigma^2, when
  /// it has none); -1 when the block is full.
  int observe(int k_sat, double t) {
    int k = slot_of_[k_sat];
    if (k < 0) {
      for (int q = 0; q < kMaxGm; ++q)
        if (slot_key_[q] < 0) {
          k = q;
          break;
        }
      if (k < 0) return -1;
      slot_key_[k] = k_sat;
      slot_of_[k_sat] = k;
      b_[k] = 0.0;
      Pxb_.col(k).setZero();
      Pbb_.row(k).setZero();
      Pbb_.col(k).setZero();
      Pbb_(k, k) = cfg_.sigma_m * cfg_.sigma_m;
    }
    t_seen_[k] = t;
    return k;
  }

  /// Start every state again (b^ = 0, uncorrelated, sigma^2): after a
  /// lock-out recovery of the gate, whose covariance inflation the block did not follow.
  void reinitialise() {
    b_.setZero();
    Pxb_.setZero();
    Pbb_.setZero();
    for (int k = 0; k < kMaxGm; ++k)
      if (slot_key_[k] >= 0) Pbb_(k, k) = cfg_.sigma_m * cfg_.sigma_m;
  }

  /// b^ of slot k [m] (added to the INS-predicted pseudorange).
  double estimate(int k) const { return b_[k]; }

  /// Fold the block into the core's measurement (file comment): rows r with
  /// row_slot[r] >= 0 are pseudorange rows of that slot.  H (m x kN), R (m x m)
  /// are edited in place; G and P_e are kept for joint_posterior().
  template <class HType, class RType>
  bool fold(const NMat& Pxx, HType& H, RType& R, const int* row_slot, int m) {
    llt_.compute(Pxx);
    if (llt_.info() != Eigen::Success) return false;
    Gt_ = llt_.solve(Pxb_);  // G^T = P_xx^-1 P_xb (kN x kMaxGm)
    Pe_ = Pbb_;
    Pe_.noalias() -= Pxb_.transpose() * Gt_;
    Pe_ = (0.5 * (Pe_ + Pe_.transpose())).eval();
    for (int r = 0; r < m; ++r) {
      row_slot_[r] = row_slot[r];
      if (row_slot[r] < 0) continue;
      H.row(r) += Gt_.col(row_slot[r]).transpose();
      for (int c = 0; c < m; ++c)
        if (row_slot[c] >= 0) R(r, c) += Pe_(row_slot[r], row_slot[c]);
    }
    m_ = m;
    return true;
  }

  /// After the core applied the update of the folded measurement (residual nu,
  /// H', R') from the prior P_xx to the posterior x+ (not yet fed back) and
  /// P_xx+: the joint posterior of the block, then its closed-loop feedback
  /// b^ -= x_b+ (file comment).
  template <class HType, class RType, class VType>
  bool joint_posterior(const NMat& Pxx_prior, const HType& H, const RType& R, const VType& nu,
                       const Eigen::Matrix<double, kN, 1>& x_post, const NMat& Pxx_post) {
    const int m = m_;
    MxN HP(m, kN);
    HP.noalias() = H * Pxx_prior;  // U^T
    Dyn S(m, m);
    S.noalias() = HP * H.transpose();
    S += R;
    S = (0.5 * (S + S.transpose())).eval();
    Eigen::LLT<Dyn> llt(S);
    if (llt.info() != Eigen::Success) return false;
    MxB W = MxB::Zero(m, kMaxGm);  // D P_e
    for (int r = 0; r < m; ++r)
      if (row_slot_[r] >= 0) W.row(r) = Pe_.row(row_slot_[r]);
    const MxB Z = llt.solve(W);  // S^-1 W
    const BVec e_post = Z.transpose() * nu;
    BbMat Pee = Pe_;
    Pee.noalias() -= W.transpose() * Z;
    XbMat Pxe;
    Pxe.noalias() = -HP.transpose() * Z;
    const BVec xb = Gt_.transpose() * x_post + e_post;
    XbMat Pxb;  // P_xb+ = P_xx+ G^T + P_xe+
    Pxb.noalias() = Pxx_post * Gt_;
    Pxb += Pxe;
    BbMat GPxe;
    GPxe.noalias() = Gt_.transpose() * Pxe;
    Pbb_.noalias() = Gt_.transpose() * Pxx_post * Gt_;
    Pbb_ += GPxe + GPxe.transpose() + Pee;
    Pbb_ = (0.5 * (Pbb_ + Pbb_.transpose())).eval();
    Pxb_ = Pxb;
    b_ -= xb;  // closed loop: b^ -= (b^ - b)^
    return true;
  }

  int active() const {
    int n = 0;
    for (int k = 0; k < kMaxGm; ++k) n += slot_key_[k] >= 0 ? 1 : 0;
    return n;
  }
  /// Set the block's covariance (its inactive slots must be zero; tests).
  void set_covariance(const XbMat& Pxb, const BbMat& Pbb) {
    Pxb_ = Pxb;
    Pbb_ = Pbb;
  }
  const XbMat& Pxb() const { return Pxb_; }
  const BbMat& Pbb() const { return Pbb_; }
  int slot_of(int k_sat) const { return slot_of_[k_sat]; }

 private:
  void remove(int k) {
    slot_of_[slot_key_[k]] = -1;
    slot_key_[k] = -1;
    b_[k] = 0.0;
    Pxb_.col(k).setZero();
    Pbb_.row(k).setZero();
    Pbb_.col(k).setZero();
  }

  PseudorangeGmConfig cfg_;
  BVec b_ = BVec::Zero();
  XbMat Pxb_ = XbMat::Zero();
  BbMat Pbb_ = BbMat::Zero();
  int slot_key_[kMaxGm] = {};
  double t_seen_[kMaxGm] = {};
  int slot_of_[kKeys] = {};
  double t_ = NAN;
  // fold -> joint_posterior
  Eigen::LLT<NMat> llt_;
  XbMat Gt_ = XbMat::Zero();
  BbMat Pe_ = BbMat::Zero();
  int row_slot_[kMaxMeasRows] = {};
  int m_ = 0;
};

}  // namespace insnav
