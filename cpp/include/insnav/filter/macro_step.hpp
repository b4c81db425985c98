// insnav/filter/macro_step.hpp -- the multi-interval RK4 step of the particle
// filters: the engine's propagation intervals are collected into one RK4 step
// of about `rk4_step` seconds (particle_filter.hpp explains why 1-s steps are
// enough).
#pragma once

#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/error_model_nonlinear.hpp"
#include "insnav/filter/types.hpp"

namespace insnav {

// --- multi-interval RK4 step ------------------------------------------------------

/// Collects engine intervals into one RK4 step of about `step` seconds (see the
/// header comment).  Holds copies of the INS points (bounded array, no heap).
template <class L>
class MacroStep {
 public:
  static constexpr int kMaxPoints = 256;
  using Cov = StateCov<L>;

  MacroStep(const ImuErrorModel& model, double step) : model_(model), step_(step) {}

  void reset() { n_ = 0; t_ = 0.0; }
  bool pending() const { return n_ > 0; }
  double step() const { return step_; }

  /// Add one interval; true when a step is ready (then call prepare()).
  bool add(const InsInterval& iv) {
    if (!(iv.dt > 0.0)) return false;
    if (n_ == 0) start_ = iv.start;
    pts_[n_] = iv.mid;
    tp_[n_++] = t_ + 0.5 * iv.dt;
    t_ += iv.dt;
    pts_[n_] = iv.end;
    tp_[n_++] = t_;
    return step_ <= 0.0 || t_ >= step_ - 1e-9 || n_ + 2 > kMaxPoints;
  }

  /// Make the pending step ready: p0, ph, p1, dt, Phi, Q_d.  Clears the buffer.
  void prepare() {
    int mid = 0;
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < n_ - 1; ++i) {
      const double d = std::abs(tp_[i] - 0.5 * t_);
      if (d < best) {
        best = d;
        mid = i;
      }
    }
    a_ = start_;
    m_ = pts_[mid];
    b_ = pts_[n_ - 1];
    dt = t_;
    p0.set(a_, model_);
    ph.set(m_, model_);
    p1.set(b_, model_);
    phi = transition<L>(linear_F<L>(m_, model_), dt);
    qd = discrete_Q<L>(phi, continuous_GQG<L>(m_, model_), dt);
    reset();
  }

  NonlinearErrorPoint p0, ph, p1;
  double dt = 0.0;
  Cov phi = Cov::Identity(), qd = Cov::Zero();

 private:
  ImuErrorModel model_;
  double step_;
  InsPoint start_, a_, m_, b_;
  InsPoint pts_[kMaxPoints];
  double tp_[kMaxPoints] = {};
  int n_ = 0;
  double t_ = 0.0;
};

}  // namespace insnav
