// insnav/filter/ekf.hpp -- closed-loop error-state EKF (the baseline of
// seed 000; the filter of seed 003's loose and tight coupling).
//
// Time update with the linear error model of error_model_linear.hpp evaluated
// at the middle of each propagation interval, Phi = I + F dt + (F dt)^2/2,
// trapezoidal Q; for the layouts with diagonal sensor-error dynamics
// (Layout15, Layout21) in block form: one 9 x n congruence instead of five
// n x n x n products (error_model_linear.hpp, kDiagonalAuxDynamics).
// Measurement update: Joseph form (kalman_update.hpp).
// Interface shared by all filters (see engine/loose_engine.hpp):
// initialize / begin_cycle / propagate / end_cycle / update / reset_state.
#pragma once

#include <cmath>

#include "insnav/filter/covariance.hpp"
#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/kalman_update.hpp"

namespace insnav {

template <class L>
class Ekf {
 public:
  using Layout = L;
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;
  /// The update is linear in the measurement's H (kJacobianUpdate, types.hpp).
  static constexpr bool kJacobianUpdate = true;

  explicit Ekf(const ImuErrorModel& model)
      : model_(model), acc_vrw0_(model.acc_vrw), gyro_arw0_(model.gyro_arw) {}

  /// Scale the configured velocity and angle random walk PSDs (variances) by
  /// s_vel and s_att from the next propagation on (the adaptive process noise,
  /// filter/adaptive_noise.hpp); 1, 1 is the configured model exactly.
  void set_process_noise_scale(double s_vel, double s_att) {
    model_.acc_vrw = acc_vrw0_ * std::sqrt(s_vel);
    model_.gyro_arw = gyro_arw0_ * std::sqrt(s_att);
  }
  /// The configured (unscaled) model.
  const Vec3& acc_vrw0() const { return acc_vrw0_; }
  const Vec3& gyro_arw0() const { return gyro_arw0_; }

  void initialize(const Cov& P0) {
    x_.setZero();
    P_ = 0.5 * (P0 + P0.transpose());
  }
  void begin_cycle() {
    if (track_) reset_cycle_transition();
  }
  void end_cycle() {}

  /// Keep the transition of the whole cycle (the product of the intervals'
  /// Phi) for the RTS smoother (rts_smoother.hpp: C = P_k Phi'); off by default.
  void track_cycle_transition(bool on) {
    track_ = on;
    reset_cycle_transition();
  }
  /// The cycle's transition (assembled from its block form on layouts with
  /// diagonal sensor-error dynamics: once per epoch, not per interval).
  const Cov& cycle_transition() const {
    if constexpr (kDiagonalAuxDynamics<L>) {
      Phi_cycle_.template topRows<kNav>() = T_cycle_;
      Phi_cycle_.template bottomRows<kAux>().setZero();
      Phi_cycle_.template bottomRightCorner<kAux, kAux>().diagonal() = d_cycle_;
    }
    return Phi_cycle_;
  }

  void propagate(const InsInterval& iv) {
    if constexpr (kDiagonalAuxDynamics<L>) {
      // block form (error_model_linear.hpp): one 9 x n congruence, no n^3 product
      F_ = linear_F<L>(iv.mid, model_);
      Qc_ = continuous_GQG<L>(iv.mid, model_);
      block_transition<L>(F_, iv.dt, phi_);
      block_propagate_covariance<L>(phi_, Qc_, iv.dt, P_);
      constexpr int N = NavAuxTransition<L>::kNav, K = NavAuxTransition<L>::kAux;
      const Eigen::Matrix<double, N, 1> x_nav = phi_.U.lazyProduct(x_);
      x_.template tail<K>().array() *= phi_.d.array();
      x_.template head<N>() = x_nav;
      if (track_) {
        // Phi_cycle <- [U_nn U_na; 0 diag(d)] Phi_cycle keeps the form [T; 0 diag(D)]
        // (a product of such matrices): T <- U_nn T + [0, U_na diag(D)], D <- d D,
        // 9 x 9 x n + 9 x K products instead of 9 x n x n (the zero block is not multiplied)
        T_work_.noalias() = phi_.U.template leftCols<N>() * T_cycle_;
        T_work_.template rightCols<K>().noalias() += phi_.U.template rightCols<K>() * d_cycle_.asDiagonal();
        T_cycle_ = T_work_;
        d_cycle_.array() *= phi_.d.array();
      }
    } else {
      const Cov F = linear_F<L>(iv.mid, model_);
      const Cov Phi = transition<L>(F, iv.dt);
      const Cov Qc = continuous_GQG<L>(iv.mid, model_);
      P_ = Phi * P_ * Phi.transpose() + discrete_Q<L>(Phi, Qc, iv.dt);
      P_ = 0.5 * (P_ + P_.transpose()).eval();
      x_ = Phi * x_;
      if (track_) Phi_cycle_ = (Phi * Phi_cycle_).eval();
    }
  }

  template <class Meas>
  UpdateResult update(const Meas& meas, double gate_chi2) {
    UpdateResult r = kalman_update<L>(x_, P_, meas.linear(), gate_chi2);
    repairs_ += r.cholesky_repairs;
    return r;
  }

  const Vec& x() const { return x_; }
  const Cov& P() const { return P_; }
  Cov& P_mutable() { return P_; }
  /// The error state for an update done outside update() (the TDCP clone update, meas/tdcp.hpp).
  Vec& x_mutable() { return x_; }
  void reset_state() { x_.setZero(); }
  /// P <- P + dP, dP positive semi-definite (the gate's lock-out recovery,
  /// ClosedLoop::observed_inflation).
  void add_covariance(const Cov& dP) { P_ += dP; }
  int cholesky_repairs() const { return repairs_; }

 private:
  ImuErrorModel model_;
  Vec3 acc_vrw0_, gyro_arw0_;  // the configured random walks (set_process_noise_scale)
  Vec x_ = Vec::Zero();
  Cov P_ = Cov::Identity();
  Cov F_ = Cov::Zero(), Qc_ = Cov::Zero();  // propagation workspace
  NavAuxTransition<L> phi_;
  static constexpr int kNav = NavAuxTransition<L>::kNav, kAux = NavAuxTransition<L>::kAux;
  void reset_cycle_transition() {
    Phi_cycle_.setIdentity();
    T_cycle_.setZero();
    T_cycle_.template leftCols<kNav>().setIdentity();
    d_cycle_.setOnes();
  }
  bool track_ = false;
  mutable Cov Phi_cycle_ = Cov::Identity();  // the whole product (assembled in cycle_transition on the block path)
  // block path: Phi_cycle = [T_cycle; 0 diag(d_cycle)] (nav rows, sensor-error diagonal)
  Eigen::Matrix<double, kNav, L::kSize> T_cycle_ = Eigen::Matrix<double, kNav, L::kSize>::Zero(), T_work_;
  Eigen::Matrix<double, kAux, 1> d_cycle_ = Eigen::Matrix<double, kAux, 1>::Ones();
  int repairs_ = 0;
};

}  // namespace insnav
