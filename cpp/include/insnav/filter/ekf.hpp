// insnav/filter/ekf.hpp -- closed-loop error-state EKF (the baseline of
// seed 000; the filter of seed 003's loose and tight coupling).
//
// Time update with the linear error model of error_model_linear.hpp evaluated
// at the middle of each propagation interval, Phi = I + F dt + (F dt)^2/2,
// trapezoidal Q.  Measurement update: Joseph form (kalman_update.hpp).
// Interface shared by all filters (see engine/loose_engine.hpp):
// initialize / begin_cycle / propagate / end_cycle / update / reset_state.
#pragma once

#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/kalman_update.hpp"

namespace insnav {

template <class L>
class Ekf {
 public:
  using Layout = L;
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;

  explicit Ekf(const ImuErrorModel& model) : model_(model) {}

  void initialize(const Cov& P0) {
    x_.setZero();
    P_ = 0.5 * (P0 + P0.transpose());
  }
  void begin_cycle() {}
  void end_cycle() {}

  void propagate(const InsInterval& iv) {
    const Cov F = linear_F<L>(iv.mid, model_);
    const Cov Phi = transition<L>(F, iv.dt);
    const Cov Qc = continuous_GQG<L>(iv.mid, model_);
    P_ = Phi * P_ * Phi.transpose() + discrete_Q<L>(Phi, Qc, iv.dt);
    P_ = 0.5 * (P_ + P_.transpose()).eval();
    x_ = Phi * x_;
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
  void reset_state() { x_.setZero(); }
  int cholesky_repairs() const { return repairs_; }

 private:
  ImuErrorModel model_;
  Vec x_ = Vec::Zero();
  Cov P_ = Cov::Identity();
  int repairs_ = 0;
};

}  // namespace insnav
