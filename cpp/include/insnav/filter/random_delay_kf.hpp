// insnav/filter/random_delay_kf.hpp -- the random-delay Kalman filter of
// seed 001 (Pan, Zhao, Li 2022) on the closed-loop error state.
//
// Delay model (seed 001 eqs. (4)-(6)): the measurement received at GNSS epoch
// k is y_k = z_{k - tau_k}, tau_k in {0..S} with known P(tau_k = i) = p_i.
// Stacked state (eq. (6)): xbar_k = [x_k; x_{k-1}; ...; x_{k-S}], 15 (S + 1)
// states, fixed size (S is a template parameter).  Here x_j is the error of
// the *stored* INS solution at epoch j (error = computed - true, layout.hpp).
//
// Time update (eqs. (9), (13)): only the newest block moves.  Between two
// epochs it is propagated exactly like the EKF (ekf.hpp: Phi per propagation
// interval, trapezoidal Q), the cross-covariances with the older blocks get
// the accumulated cycle transition Phi_cycle; at an epoch the blocks shift by
// one (the newest is cloned).  The paper writes Phibar = blockdiag(Phi_k ..
// Phi_{k-S}), Qbar = blockdiag(Q .. Q); for a stack of the *same* trajectory at
// successive epochs that is the shift below, and the shifted copies carry no
// new noise, so Qbar = blockdiag(Q, 0, .., 0).
//
// Measurement update (eqs. (10), (17), (20), (21)) with Abar = sum_i p_i E_i Hbar:
//   nu_i  = r_i - H_i x_{k-i}   innovation if the delay were i, r_i = h(ins_{k-i}) - y
//   nubar = sum_i p_i nu_i       (= y - Abar xbar in the paper's sign)
//   S     = Abar Pbar Abar' + R + sum_j p_j (nu_j - nubar)(nu_j - nubar)'
//   M     = Pbar Abar' S^-1                                        (eq. (17))
//   xbar += M nubar                                                (eq. (20))
//   Pbar  = Pbar - M Abar Pbar - (M Abar Pbar)' + M S M'           (eq. (15) at
//           the gain (17); equal to (21) (I - M Abar) Pbar, symmetric by construction)
// The spread term of eq. (17), sum_j p_j H (x_j - sum_i p_i x_i)(..)' H', is
// the spread of the *full-state* predicted measurements over the delay
// hypotheses; with the error state it is the spread of the nu_i (the
// measured value cancels).  For a moving vehicle it is large (metres at
// 20 m/s and 0.1 s epochs): the filter de-weights position accordingly.
//
// With p = [1, 0, ..] Abar = [H 0 ..], the spread is zero and the update is
// the ordinary (Joseph-form) Kalman update of kalman_update.hpp.
// Only the first S + 1 - (unfilled slots) hypotheses exist at start-up: the
// probabilities are renormalised over the filled slots.
#pragma once

#include <Eigen/Cholesky>
#include <array>
#include <limits>

#include "insnav/check.hpp"
#include "insnav/filter/error_model_linear.hpp"

namespace insnav {

template <class L, int S>
class RandomDelayKf {
  static_assert(S >= 0 && S <= 8, "maximum delay S must be in 0..8 epochs");

 public:
  using Layout = L;
  static constexpr int kMaxDelay = S;
  static constexpr int kBlocks = S + 1;
  static constexpr int kN = L::kSize;
  static constexpr int kStacked = kN * kBlocks;
  static constexpr int kMaxRows = 6;  // loose position + velocity
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;
  using StackedVec = Eigen::Matrix<double, kStacked, 1>;
  using StackedCov = Eigen::Matrix<double, kStacked, kStacked>;
  using MVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxRows, 1>;
  using MMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxRows, kMaxRows>;
  using AP = Eigen::Matrix<double, Eigen::Dynamic, kStacked, Eigen::RowMajor, kMaxRows, kStacked>;
  using Gain = Eigen::Matrix<double, kStacked, Eigen::Dynamic, 0, kStacked, kMaxRows>;
  /// One hypothesis per block; nullptr where the slot holds no epoch yet.
  using Hypotheses = std::array<const LinearMeasurement<L>*, kBlocks>;

  explicit RandomDelayKf(const ImuErrorModel& model) : model_(model) { p_.setZero(); p_[0] = 1.0; }

  /// Delay probabilities p_0..p_{count-1} (seed 001 eq. (4)); count <= S + 1,
  /// missing entries are 0.  They must be >= 0 and sum to 1.
  void set_delay_probabilities(const double* p, int count) {
    INSNAV_CHECK(count >= 1 && count <= kBlocks, "delay_p: need 1..S+1 probabilities");
    p_.setZero();
    double sum = 0.0;
    for (int i = 0; i < count; ++i) {
      INSNAV_CHECK(p[i] >= 0.0 && p[i] <= 1.0, "delay_p: probabilities must be in [0, 1]");
      p_[i] = p[i];
      sum += p[i];
    }
    INSNAV_CHECK(std::abs(sum - 1.0) < 1e-9, "delay_p: probabilities must sum to 1");
  }
  const Eigen::Matrix<double, kBlocks, 1>& delay_probabilities() const { return p_; }

  void initialize(const Cov& P0) {
    xbar_.setZero();
    Pbar_.setZero();
    Pbar_.template topLeftCorner<kN, kN>() = 0.5 * (P0 + P0.transpose());
    Phi_cycle_.setIdentity();
  }
  void begin_cycle() { Phi_cycle_.setIdentity(); }

  /// Newest block: identical to Ekf::propagate; the cross-covariances follow
  /// at end_cycle() with the accumulated Phi_cycle.
  void propagate(const InsInterval& iv) {
    const Cov F = linear_F<L>(iv.mid, model_);
    const Cov Phi = transition<L>(F, iv.dt);
    const Cov Qc = continuous_GQG<L>(iv.mid, model_);
    Cov P = Pbar_.template topLeftCorner<kN, kN>();
    P = Phi * P * Phi.transpose() + discrete_Q<L>(Phi, Qc, iv.dt);
    Pbar_.template topLeftCorner<kN, kN>() = 0.5 * (P + P.transpose());
    xbar_.template head<kN>() = (Phi * xbar_.template head<kN>()).eval();
    Phi_cycle_ = (Phi * Phi_cycle_).eval();
  }

  void end_cycle() {
    if constexpr (S > 0) {
      for (int j = 1; j < kBlocks; ++j) {
        const Cov Pj = Phi_cycle_ * Pbar_.template block<kN, kN>(0, j * kN);
        Pbar_.template block<kN, kN>(0, j * kN) = Pj;
        Pbar_.template block<kN, kN>(j * kN, 0) = Pj.transpose();
      }
    }
    Phi_cycle_.setIdentity();
  }

  /// At a GNSS epoch, after the update and the feedback: [x_k; x_k; .. x_{k-S+1}].
  void shift() {
    if constexpr (S > 0) {
      // new(i, j) = old(max(i-1, 0), max(j-1, 0)); descending order reads before it writes
      for (int i = S; i >= 0; --i) {
        for (int j = S; j >= 0; --j) {
          if (i == 0 && j == 0) continue;
          const int si = i > 0 ? i - 1 : 0, sj = j > 0 ? j - 1 : 0;
          Pbar_.template block<kN, kN>(i * kN, j * kN) = Pbar_.template block<kN, kN>(si * kN, sj * kN);
        }
        if (i > 0) xbar_.template segment<kN>(i * kN) = xbar_.template segment<kN>((i - 1) * kN);
      }
    }
  }

  /// Random-delay update (seed 001 eqs. (17), (20), (21)) for one received
  /// record: hyp[i] is the linearised measurement if the record were valid at
  /// the epoch of block i (residual = INS at that epoch - record).
  UpdateResult update_delayed(const Hypotheses& hyp, double gate_chi2) {
    UpdateResult res;
    const int m = innovation(hyp, 1.0);
    if (m == 0) return res;  // no filled slot has a non-zero probability
    res.rows = m;
    Eigen::LLT<MMat> llt(Smat_);
    if (llt.info() != Eigen::Success) {
      res.cholesky_repairs = 1;
      ++repairs_;
      return res;
    }
    res.nis = nubar_.dot(llt.solve(nubar_));
    if (gate_chi2 > 0.0 && !(res.nis <= gate_chi2)) {
      res.rejected_by_gate = true;
      return res;
    }
    M_ = llt.solve(ap_).transpose();  // Pbar Abar' S^-1 (eq. (17))
    xbar_.noalias() += M_ * nubar_;
    MAP_.noalias() = M_ * ap_;
    Pbar_ -= MAP_;
    Pbar_ -= MAP_.transpose();
    Pbar_.noalias() += M_ * Smat_ * M_.transpose();
    Pbar_ = 0.5 * (Pbar_ + Pbar_.transpose()).eval();
    res.applied = true;
    return res;
  }

  /// The record's NIS under S_a = alpha Abar Pbar Abar' + R + spread: the outage-aware test of the
  /// record stream's gate (nis_gate.hpp; ClosedLoop::mismatch_nis for one hypothesis, which it equals
  /// with delay_p = [1]); +inf when S_a is not positive definite, 0 without a usable hypothesis.
  double mismatch_nis(const Hypotheses& hyp, double alpha) {
    if (innovation(hyp, alpha) == 0) return 0.0;
    Eigen::LLT<MMat> llt(Smat_);
    if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
    return nubar_.dot(llt.solve(nubar_));
  }

  /// The gate's lock-out recovery (nis_gate.hpp; ClosedLoop::observed_inflation for one
  /// hypothesis, which it equals): the stacked covariance inflated by lambda in the directions the
  /// record's probability-weighted measurement Abar observes,
  /// Pbar += (lambda - 1) Pbar Abar' (Abar Pbar Abar')^-1 Abar Pbar, so that its innovation is
  /// ordinary while the rest keeps its covariance.  Formed from Abar Pbar as the update forms it (the
  /// same blocks, the cross ones included).  False (nothing changed) when Abar Pbar Abar' is not
  /// positive definite.  No heap.
  bool inflate_observed(const Hypotheses& hyp, double lambda) {
    if (innovation(hyp, 0.0) == 0) return false;
    const MMat S0 = Smat_;  // R + spread
    innovation(hyp, 1.0);
    const MMat A = Smat_ - S0;  // Abar Pbar Abar'
    Eigen::LLT<MMat> llt(A);
    if (llt.info() != Eigen::Success) return false;
    AP w = ap_;
    llt.matrixL().solveInPlace(w);  // L^-1 Abar Pbar
    MAP_.noalias() = (lambda - 1.0) * (w.transpose() * w);
    if (!MAP_.allFinite()) return false;
    Pbar_ += MAP_;
    return true;
  }

 private:
  /// The probability-weighted innovation of a record (seed 001 eq. (17)) into nubar_, rbar_, ap_ and
  /// Smat_ = alpha Abar Pbar Abar' + R + spread; its rows (0: no hypothesis with p > 0).
  int innovation(const Hypotheses& hyp, double alpha) {
    double wsum = 0.0;
    int first = -1;
    for (int i = 0; i < kBlocks; ++i)
      if (hyp[i] && p_[i] > 0.0) {
        wsum += p_[i];
        if (first < 0) first = i;
      }
    if (first < 0) return 0;
    const int m = hyp[first]->rows();
    INSNAV_CHECK(m >= 1 && m <= kMaxRows, "random-delay update: 1..6 measurement rows");
    Eigen::Matrix<double, kBlocks, 1> w = Eigen::Matrix<double, kBlocks, 1>::Zero();
    std::array<MVec, kBlocks> nu;
    nubar_.setZero(m);
    rbar_.setZero(m);
    for (int i = 0; i < kBlocks; ++i) {
      if (!hyp[i] || !(p_[i] > 0.0)) continue;
      const LinearMeasurement<L>& h = *hyp[i];
      INSNAV_CHECK(h.rows() == m, "random-delay update: hypotheses differ in rows");
      w[i] = p_[i] / wsum;
      const int c = h.n_cols;
      nu[i] = h.residual - h.H.leftCols(c) * xbar_.template segment<kN>(i * kN).head(c);
      nubar_ += w[i] * nu[i];
      rbar_ += w[i] * h.residual;
    }
    // Abar Pbar and S = Abar Pbar Abar' + R + spread
    ap_.setZero(m, kStacked);
    for (int i = 0; i < kBlocks; ++i) {
      if (w[i] == 0.0) continue;
      const LinearMeasurement<L>& h = *hyp[i];
      const int c = h.n_cols;
      ap_.noalias() += w[i] * h.H.leftCols(c) * Pbar_.middleRows(i * kN, c);
    }
    Smat_ = hyp[first]->R;
    for (int i = 0; i < kBlocks; ++i) {
      if (w[i] == 0.0) continue;
      const LinearMeasurement<L>& h = *hyp[i];
      const int c = h.n_cols;
      Smat_.noalias() += (alpha * w[i]) * ap_.middleCols(i * kN, c) * h.H.leftCols(c).transpose();
      const MVec d = nu[i] - nubar_;
      Smat_.noalias() += w[i] * d * d.transpose();  // spread term of eq. (17)
    }
    Smat_ = 0.5 * (Smat_ + Smat_.transpose()).eval();
    return m;
  }

 public:

  /// Newest block (eq. (11)): what the engine feeds back and outputs.
  Vec x() const { return xbar_.template head<kN>(); }
  Cov P() const { return Pbar_.template topLeftCorner<kN, kN>(); }
  const StackedVec& x_stacked() const { return xbar_; }
  /// The stacked covariance; consistent after end_cycle() (inside a cycle the
  /// cross blocks wait for the accumulated Phi_cycle).
  const StackedCov& P_stacked() const { return Pbar_; }
  /// sum_i w_i r_i of the last update: the expected INS-minus-GNSS residual.
  const MVec& last_mean_residual() const { return rbar_; }
  void reset_state() { xbar_.template head<kN>().setZero(); }
  int cholesky_repairs() const { return repairs_; }

 private:
  ImuErrorModel model_;
  Eigen::Matrix<double, kBlocks, 1> p_;
  StackedVec xbar_ = StackedVec::Zero();
  StackedCov Pbar_ = StackedCov::Identity();
  Cov Phi_cycle_ = Cov::Identity();
  // workspaces (members: no large temporaries per update)
  AP ap_;
  Gain M_;
  StackedCov MAP_;
  MVec nubar_, rbar_;
  MMat Smat_;
  int repairs_ = 0;
};

}  // namespace insnav
