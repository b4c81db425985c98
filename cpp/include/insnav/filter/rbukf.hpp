// insnav/filter/rbukf.hpp -- Rao-Blackwellised UKF (seed 000): unscented time
// update through the nonlinear error model, linear Kalman measurement update.
//
// Cycle (seed 000 sec. 4; the engine calls, see engine/loose_engine.hpp):
//   begin_cycle()   sigma points 0, +-cols(chol((n + lambda) P)) around x
//                   (eq. (25) after feedback, x = 0; during an outage x is the
//                   non-zero multi-step prediction: the recursive UT of eqs. (26)-(29));
//   propagate(iv)   every sigma point advanced by RK4 through the nonlinear
//                   error model (error_model_nonlinear.hpp, eqs. (3)-(7)) with
//                   the INS at the start, middle and end of the interval (eq. (10));
//                   the process noise of the interval is accumulated as
//                   Q_c <- Phi Q_c Phi^T + Q_d(interval), Phi and Q_d from the
//                   linear model at the middle point (error_model_linear.hpp;
//                   the EKF's block form for Layout15/21);
//   end_cycle()     x = sum Wm chi, P = sum Wc (chi - x)(chi - x)^T + Q_c (eqs. (11)-(13));
//   update(meas)    eqs. (22)-(24): y = residual - h(x) (h = meas.predicted_residual,
//                   = H x for a linear measurement), S = H P H^T + R factorised
//                   with llt(), K = P H^T S^-1, x += K y, then the covariance:
//     UpdateForm::kDensePaper        P = (I - K H) P, eq. (24) literally, all n columns
//                                    (what seed 000 counts; symmetrised afterwards);
//     UpdateForm::kDenseJoseph       P = (I - K H) P (I - K H)^T + K R K^T, all n columns;
//     UpdateForm::kBlockSparseJoseph (default) the same Joseph form, but with H
//                                    non-zero only in its first c = meas.n_cols
//                                    columns: U = P_(:,c) H_c^T, S = H_c U_(c,:) + R,
//                                    and P = P - K U^T - U K^T + K S K^T, which is
//                                    the Joseph expression expanded (exact for any K);
//     UpdateForm::kBlockSparseFactored  S = L L^T, W = U L^-T, P = P - W W^T (lower
//                                    triangle, rank-r update), K y = W (L^-1 y): the
//                                    cheapest exact form, symmetric by construction.
// Covariance health (covariance.hpp): P is symmetrised after every step and
// repaired (eigenvalue clamp) whenever its Cholesky factor is needed and fails;
// repairs are counted.  Fixed-size Eigen everywhere, workspaces are members,
// no heap allocation (cpp/tests/test_rbukf.cpp checks with EIGEN_RUNTIME_NO_MALLOC).
#pragma once

#include <Eigen/Cholesky>

#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/error_model_nonlinear.hpp"
#include "insnav/filter/sigma_points.hpp"
#include "insnav/filter/types.hpp"

namespace insnav {

enum class UpdateForm { kDensePaper, kDenseJoseph, kBlockSparseJoseph, kBlockSparseFactored };

/// The unscented time update shared by RbUkf and Ukf (seed 000 eqs. (9)-(13), (25)-(29)).
template <class L>
class UnscentedPropagation {
 public:
  using Layout = L;
  static constexpr int kN = L::kSize;
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;
  using Points = SigmaPoints<kN>;

  explicit UnscentedPropagation(const ImuErrorModel& model, const UtParams& ut = {})
      : model_(model), w_(ut) {}

  void initialize(const Cov& P0) {
    x_.setZero();
    P_ = P0;
    symmetrize<kN>(P_);
    Q_cycle_.setZero();
    in_cycle_ = false;
    points_fresh_ = false;
  }

  /// Draw the sigma points around the current (x, P) (eq. (9) / (25)).
  void begin_cycle() {
    repairs_ += draw_sigma_points<kN>(x_, P_, w_, chi_, factor_, repair_opt_);
    if (track_cross_) {  // the drawn points' deviations, for the cycle's cross-covariance
      chi0_ = chi_;
      chi0_.colwise() -= x_;
    }
    Q_cycle_.setZero();
    in_cycle_ = true;
    points_fresh_ = false;
    n_intervals_ = 0;
  }

  /// Advance every sigma point over one interval by RK4 (eq. (10)) and
  /// accumulate the interval's process noise.
  void propagate(const InsInterval& iv) {
    if (!in_cycle_) begin_cycle();
    if (!(iv.dt > 0.0)) return;
    p0_.set(iv.start, model_);
    ph_.set(iv.mid, model_);
    p1_.set(iv.end, model_);
    for (int j = 0; j < 2 * kN + 1; ++j) {
      tmp_ = chi_.col(j);
      rk4_error_step<L>(tmp_, p0_, ph_, p1_, iv.dt);
      chi_.col(j) = tmp_;
    }
    // Q_c <- Phi Q_c Phi^T + Q_d: the EKF's covariance step (ekf.hpp), in block
    // form where the layout allows it (9 x n congruence instead of n^3 products)
    if constexpr (kDiagonalAuxDynamics<L>) {
      block_transition<L>(linear_F<L>(iv.mid, model_), iv.dt, phi_block_);
      block_propagate_covariance<L>(phi_block_, continuous_GQG<L>(iv.mid, model_), iv.dt, Q_cycle_);
    } else {
      phi_ = transition<L>(linear_F<L>(iv.mid, model_), iv.dt);
      qd_ = discrete_Q<L>(phi_, continuous_GQG<L>(iv.mid, model_), iv.dt);
      work_.noalias() = phi_ * Q_cycle_;
      Q_cycle_.noalias() = work_ * phi_.transpose();
      Q_cycle_ += qd_;
    }
    ut_mean<kN, 2 * kN + 1>(chi_, w_, x_);  // the running prediction (for mid-cycle output)
    ++n_intervals_;
  }

  /// Predicted mean and covariance, eqs. (11)-(13).
  void end_cycle() {
    if (!in_cycle_) return;
    in_cycle_ = false;
    if (n_intervals_ == 0) {  // nothing propagated: (x, P) unchanged
      if (track_cross_) C_cycle_ = P_;
      return;
    }
    sanitize_points();
    ut_mean<kN, 2 * kN + 1>(chi_, w_, x_);
    ut_covariance<kN, 2 * kN + 1>(chi_, x_, w_, dev_, P_);
    if (track_cross_) {  // Sarkka (2008) eq. (13): sum Wc (chi_k - x_k)(chi_k+1^- - x_k+1^-)^T
      C_cycle_.noalias() = w_.wi * chi0_.template rightCols<2 * kN>() * dev_.template rightCols<2 * kN>().transpose();
      C_cycle_.noalias() += w_.w0c * chi0_.col(0) * dev_.col(0).transpose();
    }
    P_ += Q_cycle_;
    symmetrize<kN>(P_);
    if (!P_.allFinite()) {
      repair_covariance<kN>(P_, repair_opt_);
      ++repairs_;
    }
    points_fresh_ = true;
  }

  const Vec& x() const { return x_; }
  const Cov& P() const { return P_; }
  Cov& P_mutable() { return P_; }

  /// Keep the UT cross-covariance of each cycle (the unscented RTS smoother's
  /// C_k+1, rts_smoother.hpp): the drawn points are kept at begin_cycle.
  void track_cycle_transition(bool on) { track_cross_ = on; }
  /// cov(error at the cycle start, predicted error at its end) of the last cycle.
  const Cov& cycle_cross_covariance() const { return C_cycle_; }
  /// Direct access to the mean (tests; an engine that feeds back partially).
  Vec& x_mutable() {
    points_fresh_ = false;
    return x_;
  }
  /// x = 0 after the engine fed x back into the INS (closed loop, eq. (25)).
  void reset_state() {
    x_.setZero();
    points_fresh_ = false;
  }
  /// P <- P + dP, dP positive semi-definite (the gate's lock-out recovery,
  /// ClosedLoop::observed_inflation); the next update draws its sigma points
  /// from the inflated P.
  void add_covariance(const Cov& dP) {
    P_ += dP;
    points_fresh_ = false;
  }
  int cholesky_repairs() const { return repairs_; }
  const UtWeights<kN>& weights() const { return w_; }
  /// Sigma points: drawn (after begin_cycle) or propagated (after end_cycle).
  const Points& sigma_points() const { return chi_; }
  /// Process noise accumulated over the last cycle.
  const Cov& cycle_Q() const { return Q_cycle_; }

 protected:
  /// A sigma point that left the domain of the model (non-finite, e.g. pitch
  /// error at 90 deg) is replaced by the centre point; counted as a repair.
  void sanitize_points() {
    bool bad = false;
    for (int j = 0; j < 2 * kN + 1; ++j)
      if (!chi_.col(j).allFinite()) {
        bad = true;
        if (j > 0 && chi_.col(0).allFinite()) chi_.col(j) = chi_.col(0);
        else chi_.col(j).setZero();
      }
    if (bad) ++repairs_;
  }

  ImuErrorModel model_;
  UtWeights<kN> w_;
  RepairOptions repair_opt_{};
  Vec x_ = Vec::Zero();
  Cov P_ = Cov::Identity();
  Cov Q_cycle_ = Cov::Zero();
  Points chi_ = Points::Zero();
  Points chi0_ = Points::Zero();  // deviations of the drawn points (smoother only)
  Cov C_cycle_ = Cov::Zero();
  bool track_cross_ = false;
  Points dev_ = Points::Zero();
  Cov factor_ = Cov::Zero();
  Cov phi_ = Cov::Identity(), qd_ = Cov::Zero(), work_ = Cov::Zero();
  NavAuxTransition<L> phi_block_;  // Phi in block form (kDiagonalAuxDynamics layouts)
  Vec tmp_ = Vec::Zero();
  NonlinearErrorPoint p0_, ph_, p1_;
  int repairs_ = 0;
  int n_intervals_ = 0;
  bool in_cycle_ = false;
  bool points_fresh_ = false;  // chi_ are the propagated points of (x_, P_) (UKF update)
};

/// Measurement-side workspace types.
template <class L>
struct MeasTypes {
  static constexpr int kN = L::kSize;
  using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  using Gain = Eigen::Matrix<double, kN, Eigen::Dynamic, 0, kN, kMaxMeasRows>;
  using RowVec = typename LinearMeasurement<L>::RowVec;
};

template <class L>
class RbUkf : public UnscentedPropagation<L> {
  using Base = UnscentedPropagation<L>;
  using T = MeasTypes<L>;

 public:
  using typename Base::Cov;
  using typename Base::Vec;
  using Layout = L;
  static constexpr int kN = L::kSize;
  /// The update is linear in the measurement's H (kJacobianUpdate, types.hpp).
  static constexpr bool kJacobianUpdate = true;

  explicit RbUkf(const ImuErrorModel& model, const UtParams& ut = {}) : Base(model, ut) {}

  /// Covariance form of the update (default kBlockSparseJoseph; the block-sparse
  /// forms fall back to dense columns automatically when n_cols = n).
  void set_update_form(UpdateForm f) { form_ = f; }
  UpdateForm update_form() const { return form_; }

  /// Linear Kalman update, seed 000 eqs. (22)-(24).  gate_chi2 <= 0: no gating.
  /// The two shapes of seed 000's experiments (6 rows, position + velocity; H
  /// non-zero in its first 6 columns, or in all n with a lever arm) run with
  /// compile-time sizes; any other shape with bounded dynamic sizes (same
  /// results).  Each fixed shape is a full instantiation of the update and
  /// costs compile time in every translation unit, so only these two are kept
  /// (the update runs once per GNSS epoch; the time update dominates a run).
  /// Define INSNAV_NO_FIXED_UPDATE_KERNELS to build only the bounded dynamic
  /// path (used by the sanitizer test build).
  template <class Meas>
  UpdateResult update(const Meas& meas, double gate_chi2) {
    const LinearMeasurement<L>& lin = meas.linear();
    UpdateResult res;
    const int r = lin.rows();
    res.rows = r;
    if (r == 0) return res;
    y_ = lin.residual - meas.predicted_residual(this->x_);  // = residual - H x for linear h
#ifndef INSNAV_NO_FIXED_UPDATE_KERNELS
    const bool dense = form_ == UpdateForm::kDensePaper || form_ == UpdateForm::kDenseJoseph;
    const int c = dense ? kN : lin.n_cols;
    if (r == 6 && c == 6) return update_impl<6, 6>(lin, gate_chi2, res);
    if (r == 6 && c == kN) return update_impl<6, kN>(lin, gate_chi2, res);
#endif
    return update_impl<Eigen::Dynamic, Eigen::Dynamic>(lin, gate_chi2, res);
  }

 private:
  /// R rows, C leading columns of H (Eigen::Dynamic: runtime sizes <= bounds).
  template <int R, int C>
  UpdateResult update_impl(const LinearMeasurement<L>& lin, double gate_chi2, UpdateResult& res) {
    constexpr int RM = (R == Eigen::Dynamic) ? kMaxMeasRows : R;
    constexpr int CM = (C == Eigen::Dynamic) ? kN : C;
    using MatRR = Eigen::Matrix<double, R, R, 0, RM, RM>;
    using MatNR = Eigen::Matrix<double, kN, R, 0, kN, RM>;
    using MatRN = Eigen::Matrix<double, R, kN, 0, RM, kN>;
    using MatRC = Eigen::Matrix<double, R, C, 0, RM, CM>;
    using VecR = Eigen::Matrix<double, R, 1, 0, RM, 1>;
    Vec& x = this->x_;
    Cov& P = this->P_;
    const int r = lin.rows();
    const int c = (form_ == UpdateForm::kDensePaper || form_ == UpdateForm::kDenseJoseph) ? kN : lin.n_cols;
    const MatRC Hc = lin.H.template block<R, C>(0, 0, r, c);
    const VecR y = y_;
    MatNR U;
    U.noalias() = P.template block<kN, C>(0, 0, kN, c) * Hc.transpose();  // P H^T (n x r)
    MatRR S;
    S.noalias() = Hc * U.template block<C, R>(0, 0, c, r);
    S += lin.R;
    Eigen::LLT<MatRR> llt(S);  // reads the lower triangle
    if (llt.info() != Eigen::Success) {
      res.cholesky_repairs = 1;  // S not PD (bad R): refuse rather than corrupt P
      this->repairs_ += 1;
      return res;
    }
    // v = L^-1 y, NIS = |v|^2
    VecR v = y;
    llt.matrixL().solveInPlace(v);
    res.nis = v.squaredNorm();
    res.log_det_s = 2.0 * llt.matrixLLT().diagonal().array().log().sum();
    if (gate_chi2 > 0.0 && !(res.nis <= gate_chi2)) {
      res.rejected_by_gate = true;
      return res;
    }
    if (form_ == UpdateForm::kBlockSparseFactored) {
      // W^T = L^-1 U^T (r x n);  K y = W v;  P -= W W^T (lower triangle, mirrored)
      MatRN Wt = U.transpose();
      llt.matrixL().solveInPlace(Wt);
      x.noalias() += Wt.transpose() * v;
      P.template triangularView<Eigen::Lower>() -= Wt.transpose() * Wt;
      P.template triangularView<Eigen::StrictlyUpper>() = P.transpose();
    } else {
      // K = U S^-1 (llt solve, never an inverse)
      MatRN Kt = U.transpose();
      llt.solveInPlace(Kt);
      const MatNR K = Kt.transpose();
      x.noalias() += K * y;
      if (form_ == UpdateForm::kDensePaper) {
        // P = (I - K H) P, eq. (24)
        A_.setIdentity();
        A_.noalias() -= K * lin.H.template block<R, kN>(0, 0, r, kN);
        AP_.noalias() = A_ * P;
        P = AP_;
        symmetrize<kN>(P);
      } else if (form_ == UpdateForm::kDenseJoseph) {
        // P = (I - K H) P (I - K H)^T + K R K^T
        A_.setIdentity();
        A_.noalias() -= K * lin.H.template block<R, kN>(0, 0, r, kN);
        AP_.noalias() = A_ * P;
        P.noalias() = AP_ * A_.transpose();
        const MatNR KR = K * MatRR(lin.R);
        P.noalias() += KR * K.transpose();
        symmetrize<kN>(P);
      } else {
        // Joseph expanded: P - K U^T - U K^T + K S K^T  (S = H P H^T + R)
        const MatNR KS = K * S;
        AP_.noalias() = K * U.transpose();
        P -= AP_;
        P -= AP_.transpose();
        P.template triangularView<Eigen::Lower>() += KS * K.transpose();
        P.template triangularView<Eigen::StrictlyUpper>() = P.transpose();
      }
    }
    if (!P.allFinite() || !x.allFinite()) {  // never let a NaN through
      if (!x.allFinite()) x.setZero();
      repair_covariance<kN>(P, this->repair_opt_);
      res.cholesky_repairs += 1;
      this->repairs_ += 1;
    }
    this->points_fresh_ = false;
    res.applied = true;
    return res;
  }

  UpdateForm form_ = UpdateForm::kBlockSparseJoseph;
  typename T::RowVec y_;
  Cov A_ = Cov::Identity(), AP_ = Cov::Zero();
};

}  // namespace insnav
