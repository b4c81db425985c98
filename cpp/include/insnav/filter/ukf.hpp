// insnav/filter/ukf.hpp -- the standard (augmented) UKF of seed 000: the
// baseline whose measurement-update cost the RB-UKF cuts.
//
// Time update: identical to the RB-UKF (UnscentedPropagation, rbukf.hpp).
// Measurement update, seed 000 eqs. (14)-(21):
//   (14) augment the 2n+1 propagated points xi with xi_0 +- cols(sqrt((n + lambda) Q))
//        (4n+1 points; Q = the process noise of the cycle; sqrt = Cholesky for a
//        semi-definite matrix, psd_cholesky_lower);
//   (15) z_i = h(chi_i) = meas.predicted_residual(chi_i);
//   (16) z^ = sum Wm_i z_i;
//   (17) P_xz = sum Wc_i (chi_i - x^)(z_i - z^)^T;
//   (18) P_zz = sum Wc_i (z_i - z^)(z_i - z^)^T + R;
//   (19) K = P_xz P_zz^-1 (llt().solve(), never an inverse);
//   (20) x = x^ + K (residual - z^);
//   (21) P = P - K P_zz K^T.
// Weights of the augmented set: Wi = 1 / (2 (n + lambda)) for the 4n outer
// points as in the time update, W0m = 1 - 2n / (n + lambda) = (lambda - n)/(n + lambda),
// W0c = W0m + 1 - alpha^2 + beta.  With these the augmented set has exactly the
// mean x^ and the covariance P^- = sum_time-update + Q of the prediction (the
// Q points, centred on xi_0, put back the 2n Wi (xi_0 - x^)(xi_0 - x^)^T the
// smaller centre weight removes), so for a linear h the update equals the
// Kalman update to rounding (cpp/tests/test_rbukf.cpp: Ukf = RbUkf).  The paper's eqs. (14)-(21)
// leave these weights implicit.
// When the propagated points are not those of the current (x, P) (a second
// update in the same epoch, or no propagation since initialize), they are
// redrawn from (x, P) and the Q columns are zero.
#pragma once

#include "insnav/filter/augmented_ut.hpp"
#include "insnav/filter/rbukf.hpp"

namespace insnav {

template <class L>
class Ukf : public UnscentedPropagation<L> {
  using Base = UnscentedPropagation<L>;
  using T = MeasTypes<L>;

 public:
  using typename Base::Cov;
  using typename Base::Vec;
  using Layout = L;
  static constexpr int kN = L::kSize;
  static constexpr int kAug = 4 * kN + 1;
  using AugPoints = Eigen::Matrix<double, kN, kAug>;

  explicit Ukf(const ImuErrorModel& model, const UtParams& ut = {}) : Base(model, ut) {}

  /// Augmented-UT measurement update, eqs. (14)-(21) (augmented_ut.hpp).
  /// gate_chi2 <= 0: no gating.  6 rows (position + velocity) run with
  /// compile-time sizes (as RbUkf::update does).
  template <class Meas>
  UpdateResult update(const Meas& meas, double gate_chi2) {
    UpdateResult res;
    const int r = meas.linear().rows();
    res.rows = r;
    if (r == 0) return res;
#ifndef INSNAV_NO_FIXED_UPDATE_KERNELS
    if (r == 6) return update_impl(meas, gate_chi2, res, ws6_);
#endif
    return update_impl(meas, gate_chi2, res, ws_);
  }

 private:
  template <class Meas, int R>
  UpdateResult update_impl(const Meas& meas, double gate_chi2, UpdateResult& res, AugmentedUtWorkspace<L, R>& ws) {
    Vec& x = this->x_;
    Cov& P = this->P_;
    const UtWeights<kN>& w = this->w_;
    // (14) augmented points
    if (this->points_fresh_) {
      Qs_ = this->Q_cycle_ * w.n_plus_lambda;
      psd_cholesky_lower<kN>(Qs_, sqrtQ_);
    } else {
      res.cholesky_repairs += draw_sigma_points<kN>(x, P, w, this->chi_, this->factor_, this->repair_opt_);
      this->repairs_ += res.cholesky_repairs;
      sqrtQ_.setZero();
    }
    X_.template leftCols<2 * kN + 1>() = this->chi_;
    for (int i = 0; i < kN; ++i) {
      X_.col(2 * kN + 1 + i) = X_.col(0) + sqrtQ_.col(i);
      X_.col(3 * kN + 1 + i) = X_.col(0) - sqrtQ_.col(i);
    }
    this->points_fresh_ = false;
    // (15)-(21); deviations from x (x^ = x: the augmented mean, see the header comment)
    switch (augmented_ut_update<L, R>(X_, meas, w, x, P, gate_chi2, ws, res.nis)) {
      case AugmentedUtStatus::kNotPositiveDefinite:
        res.cholesky_repairs += 1;
        this->repairs_ += 1;
        return res;
      case AugmentedUtStatus::kRejectedByGate:
        res.rejected_by_gate = true;
        return res;
      case AugmentedUtStatus::kApplied:
        break;
    }
    if (!P.allFinite() || !x.allFinite()) {
      if (!x.allFinite()) x.setZero();
      repair_covariance<kN>(P, this->repair_opt_);
      res.cholesky_repairs += 1;
      this->repairs_ += 1;
    }
    res.applied = true;
    return res;
  }

  Cov Qs_ = Cov::Zero(), sqrtQ_ = Cov::Zero();
  AugPoints X_ = AugPoints::Zero();
  AugmentedUtWorkspace<L, 6> ws6_;
  AugmentedUtWorkspace<L> ws_;
};

}  // namespace insnav
