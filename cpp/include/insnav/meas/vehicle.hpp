// insnav/meas/vehicle.hpp -- vehicle constraints as measurements:
// non-holonomic constraint (NHC), wheel odometer, zero-velocity (ZUPT) and
// zero-angular-rate (ZARU) updates.
//
// Frames: b the IMU body frame (FRD), v the vehicle frame (x forward along
// the rear axle's direction of travel, y right, z down), C_bv the mounting
// rotation (vehicle -> body; identity for an aligned IMU).  The constrained
// point is the centre of the rear axle, at lever_arm_b from the IMU (body
// axes): it does not slip sideways and does not leave the road, and the
// odometer measures its forward speed.
//
// Velocity of the constrained point, vehicle axes (Shin 2001, "Accuracy
// improvement of low cost INS/GPS for land applications", eq. (4.29); Groves
// 2013, eq. (16.22)):
//   v_v = C_vb (C_bn v_n + omega_nb_b x l_b),  omega_nb_b = omega_ib_b - C_bn omega_in_n
// NHC: v_v[1] = v_v[2] = 0.  Odometer: v_v[0] = speed.
// Linearisation (error = computed - true, C~_bn = C_bn (I + [psi x]),
// omega~_ib_b = omega_ib_b + dw_b, so d omega_nb_b = dw_b + C_bn [omega_in_n x] psi;
// the position error's effect on omega_in_n neglected, < 1e-9 m/s per metre):
//   d v_v = C_vb C_bn dv - C_vb (C_bn [v_n x] + [l_b x] C_bn [omega_in_n x]) psi - C_vb [l_b x] dw_b
// Second order: the exact residual of the velocity part is
//   d v_v = C~_vn dv - C~_vn [v~_n x] psi - C~_vn (psi x dv) + O(psi^2 v, psi^2 dv)
// (C~_vn the INS's nav -> vehicle rotation, v~_n its velocity), and the
// product of the attitude and the velocity error, row i (vehicle axis
// a_i = C~_nv e_i in n), is psi' [a_i x] dv.  An exact constraint is far more
// precise than this product on a long outage (psi 0.3 deg, along-track dv
// 4 m/s: 0.02 m/s against sigma_nhc 0.001 m/s): an EKF that drops it takes
// the along-track velocity error, which the INS's tilted lateral and vertical
// axes mix into their rows, for information and turns overconfident.
// add_second_order_noise(P) adds its covariance to R, the measurement side of
// the second-order filter (Gelb 1974, "Applied Optimal Estimation", sec. 6.1;
// Bar-Shalom, Li & Kirubarajan 2001, "Estimation with Applications to
// Tracking and Navigation", ch. 10, the second-order EKF): with
// r2_i = z' M_i z / 2, z = [dv; psi] ~ N(0, P_z), M_i = [0 B_i'; B_i 0],
// B_i = [a_i x],  Cov(r2_i, r2_j) = tr(M_i P_z M_j P_z) / 2.
// (Its mean tr(M_i P_z) / 2 is not added: it made no difference in the runs
// measured, and x is zero after each feedback.)  The product is not white: it
// moves with the attitude and along-track velocity errors, over seconds or
// more, and events 0.1 s apart see nearly the same value.  As for any
// time-correlated measurement error treated as white, its covariance is
// scaled by the number of events within its correlation time,
// max(1, second_order_corr_s / dt_event), dt_event the interval between the
// NHC events for the NHC rows and between the odometer events for the
// odometer row (the engine passes the factors; a cross term takes the
// geometric mean, which keeps R positive semi-definite), so that n events a
// correlation time apart do not average it down by n.  For the filters whose update
// is linear in H (EKF, RB-UKF); the UKF's sigma points see the product in
// predicted_residual.
// Odometer scale factor (layouts with kOdoScale, layout.hpp): the odometer
// reads z = (1 + s) v_fwd, v_fwd = v_v[0] of the true state.  The engine
// keeps the fed-back estimate s^ (engine/closed_loop.hpp) and the filter the
// remaining error ds of the corrected reading z / (1 + s^) = (1 + ds) v_fwd,
// i.e. 1 + s = (1 + s^)(1 + ds).  The odometer row is formed in reading units
// (its noise is sigma_odo_mps as it stands):
//   predicted reading  z^ = (1 + s^) v~_v[0]            (INS, ds = 0)
//   residual           r  = z^ - z
//   exact r(dx)           = (1 + s^) (v~_v[0] - (1 + ds) v_v[0](dx))
//   first order (ds v_v[0](dx) ~ ds v~_v[0], the product ds d v_v dropped):
//     r = (1 + s^) (d v_v[0] - v~_v[0] ds)
//   so H_row = (1 + s^) [d v_v[0] / d(dv, psi, dw_b)],  H(row, kOdoScale) = -(1 + s^) v~_v[0].
// Without the state (s^ = 0, no column) this is the plain odometer row.
// Lever arm of the constrained point as a state (layouts with kOdoLever,
// layout.hpp; dl_o = l_o^ - l_o, the engine passes l_o^ in the config):
//   d v_v = ... + C_vb [omega_nb_b x] dl_o
// (the odometer row times 1 + s^); observable only while the body turns
// (omega_nb_b != 0): the lateral row sees the forward component in yaw turns,
// the odometer row the lateral one; the vertical component needs roll/pitch
// rates (Groves 2013, eq. (16.22) differentiated in l; docs/algorithms.md section 21).
// The omega_ib_b in this column is a low-passed rate that holds no noise of the
// increment whose rate the residual takes (set_lever_arm_rate;
// ClosedLoop::omega_ib_b_lever): the one noisy rate in both the residual
// (omega x l_o^) and the column is an errors-in-variables bias of dl_o towards
// l_o^, i.e. of the estimate towards zero, as for the GNSS lever arm
// (meas/gnss_loose.hpp).
// ZUPT (standstill): v_n = 0:  d = dv.
// ZARU (standstill): omega_ib_b = C_bn omega_ie_n, residual
//   omega~_ib_b - C~_bn omega_ie_n,  d = dw_b - C_bn [psi x] omega_ie_n
//                                      = dw_b + C_bn [omega_ie_n x] psi.
// Each class gives the residual (INS-predicted minus measured), H and R in
// the LinearMeasurement form of the other measurements (gnss_loose.hpp), and
// predicted_residual(dx), the exact residual the INS would show if its true
// error were dx (for the unscented updates and the Jacobian tests).
#pragma once

#include <algorithm>
#include <cmath>

#include "insnav/earth/wgs84.hpp"
#include "insnav/filter/types.hpp"
#include "insnav/math/rotation.hpp"

namespace insnav {

/// Mounting and noise of the vehicle constraints (SI).
struct VehicleConstraintConfig {
  Mat3 C_bv = Mat3::Identity();     // vehicle -> body rotation (IMU mounting)
  Vec3 lever_arm_b = Vec3::Zero();  // IMU -> rear-axle centre, body axes [m]
  double sigma_nhc_mps = 0.1;       // lateral / vertical velocity noise [m/s]
  double sigma_odo_mps = 0.05;      // odometer speed noise [m/s]
  double sigma_zupt_mps = 0.01;     // zero-velocity noise [m/s]
  double sigma_zaru_radps = 1e-4;   // zero-angular-rate noise [rad/s]
  // correlation time of the attitude x velocity error product of the NHC /
  // odometer rows (add_second_order_noise) [s]; its covariance is scaled by
  // max(1, second_order_corr_s / event interval)
  double second_order_corr_s = 1.0;
};

namespace vehicle_detail {

/// Velocity of the constrained point in vehicle axes for a given attitude,
/// velocity and body rate (the nonlinear h of NHC and the odometer).
inline Vec3 point_velocity_v(const Mat3& C_nb, const Vec3& v_n, const Vec3& omega_ib_b, const Vec3& omega_in_n,
                             const VehicleConstraintConfig& cfg) {
  const Mat3 C_bn = C_nb.transpose();
  const Vec3 omega_nb_b = omega_ib_b - C_bn * omega_in_n;
  return cfg.C_bv.transpose() * (C_bn * v_n + omega_nb_b.cross(cfg.lever_arm_b));
}

}  // namespace vehicle_detail

/// NHC (rows: lateral, vertical) and/or odometer (row: forward speed) on the
/// velocity of the rear-axle point.
template <class L>
class VehicleVelocityMeasurement {
 public:
  using RowVec = typename LinearMeasurement<L>::RowVec;

  /// ins: INS state at the update time; omega_ib_b: corrected body rate [rad/s];
  /// use_nhc: the two zero rows; odo_speed_mps: the odometer's reading (forward
  /// speed) [m/s], or NaN for none; odo_scale: the fed-back scale-factor
  /// estimate s^ [-] of the reading (layouts with kOdoScale; see the header comment).
  void set(const NavState& ins, const Vec3& omega_ib_b, const VehicleConstraintConfig& cfg, bool use_nhc,
           double odo_speed_mps, double odo_scale = 0.0) {
    cfg_ = cfg;
    odo_gain_ = 1.0 + odo_scale;
    C_nb_ = ins.q_nb.toRotationMatrix();
    v_n_ = ins.v_n;
    omega_ib_b_ = omega_ib_b;
    const wgs84::Radii r = wgs84::radii(ins.lat);
    omega_in_n_ = wgs84::omega_ie_n(ins.lat) + wgs84::omega_en_n(ins.lat, ins.h, ins.v_n, r);
    if (!lever_rate_set_) omega_lever_b_ = omega_ib_b;
    lever_rate_set_ = false;
    use_odo_ = odo_speed_mps == odo_speed_mps;  // not NaN
    use_nhc_ = use_nhc;
    odo_ = use_odo_ ? odo_speed_mps : 0.0;
    const int rows = (use_odo_ ? 1 : 0) + (use_nhc_ ? 2 : 0);
    lin_.residual.resize(rows);
    lin_.H.setZero(rows, L::kSize);
    lin_.R.setZero(rows, rows);
    const Vec3 v_v = vehicle_detail::point_velocity_v(C_nb_, v_n_, omega_ib_b_, omega_in_n_, cfg_);
    v_fwd_computed_ = v_v[0];
    const Mat3 C_vn = cfg_.C_bv.transpose() * C_nb_.transpose();
    Eigen::Matrix<double, 3, 9> J;  // d v_v / d [dv psi dw_b]
    J.leftCols<3>() = C_vn;
    J.middleCols<3>(3) = -C_vn * skew(v_n_) - cfg_.C_bv.transpose() * skew(cfg_.lever_arm_b) *
                                                  C_nb_.transpose() * skew(omega_in_n_);
    J.rightCols<3>() = -cfg_.C_bv.transpose() * skew(cfg_.lever_arm_b);
    int row = 0;
    for (int axis = 0; axis < 3; ++axis) {
      const bool on = axis == 0 ? use_odo_ : use_nhc_;
      if (!on) continue;
      const double k = axis == 0 ? odo_gain_ : 1.0;  // the odometer row in reading units
      lin_.residual[row] = axis == 0 ? k * v_v[0] - odo_ : v_v[axis];
      lin_.H.template block<1, 3>(row, L::kVel) = k * J.template block<1, 3>(axis, 0);
      lin_.H.template block<1, 3>(row, L::kAtt) = k * J.template block<1, 3>(axis, 3);
      lin_.H.template block<1, 3>(row, L::kGyroBias) = k * J.template block<1, 3>(axis, 6);
      if constexpr (kHasOdoScale<L>) {
        if (axis == 0) lin_.H(row, OdoScaleState<L>::offset) = -k * v_v[0];
      }
      if constexpr (kHasOdoLever<L>) {  // the rate of set_lever_arm_rate
        const Vec3 omega_nb_b = omega_lever_b_ - C_nb_.transpose() * omega_in_n_;
        const Mat3 J_l = cfg_.C_bv.transpose() * skew(omega_nb_b);
        lin_.H.template block<1, 3>(row, OdoLeverState<L>::offset) = k * J_l.row(axis);
      }
      const double s = axis == 0 ? cfg_.sigma_odo_mps : cfg_.sigma_nhc_mps;
      lin_.R(row, row) = s * s;
      rows_axis_[row] = axis;
      ++row;
    }
    lin_.n_cols = L::kGyroBias + 3;
    if constexpr (kHasOdoScale<L>) {
      if (use_odo_) lin_.n_cols = std::max(lin_.n_cols, OdoScaleState<L>::offset + 1);
    }
    if constexpr (kHasOdoLever<L>) lin_.n_cols = OdoLeverState<L>::offset + 3;
  }

  const LinearMeasurement<L>& linear() const { return lin_; }

  /// The angular rate omega_ib_b [rad/s] of the lever-arm state's columns
  /// (layouts with kOdoLever) for the next set(): a rate whose noise is
  /// independent of the one given to set() (ClosedLoop::omega_ib_b_lever;
  /// header comment).  Without this call: the rate given to set().
  void set_lever_arm_rate(const Vec3& omega_b) {
    omega_lever_b_ = omega_b;
    lever_rate_set_ = true;
  }

  /// R += the covariance of the rows' attitude x velocity error product under
  /// the prior covariance P (second-order filter), scaled by scale_nhc >= 1 in
  /// the NHC rows and scale_odo >= 1 in the odometer row for its time
  /// correlation (header comment).  Call after set(), for a filter whose
  /// update is linear in H.
  void add_second_order_noise(const StateCov<L>& P, double scale_nhc = 1.0, double scale_odo = 1.0) {
    using Mat6 = Eigen::Matrix<double, 6, 6>;
    Mat6 Pz;  // covariance of z = [dv; psi]
    Pz.template topLeftCorner<3, 3>() = P.template block<3, 3>(L::kVel, L::kVel);
    Pz.template topRightCorner<3, 3>() = P.template block<3, 3>(L::kVel, L::kAtt);
    Pz.template bottomLeftCorner<3, 3>() = P.template block<3, 3>(L::kAtt, L::kVel);
    Pz.template bottomRightCorner<3, 3>() = P.template block<3, 3>(L::kAtt, L::kAtt);
    const Mat3 C_nv = C_nb_ * cfg_.C_bv;
    Mat6 MP[3];     // M_i P_z per row
    double sq[3];   // sqrt of the row's scale
    const int rows = lin_.rows();
    for (int i = 0; i < rows; ++i) {
      const int axis = rows_axis_[i];
      sq[i] = std::sqrt(axis == 0 ? scale_odo : scale_nhc);
      const double k = axis == 0 ? odo_gain_ : 1.0;  // the odometer row in reading units
      const Mat3 B = k * skew(Vec3(C_nv.col(axis)));
      Mat6 M = Mat6::Zero();
      M.template topRightCorner<3, 3>() = B.transpose();
      M.template bottomLeftCorner<3, 3>() = B;
      MP[i].noalias() = M * Pz;
    }
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j <= i; ++j) {
        const double c = 0.5 * sq[i] * sq[j] * (MP[i] * MP[j]).trace();
        lin_.R(i, j) += c;
        if (j != i) lin_.R(j, i) += c;
      }
  }

  RowVec predicted_residual(const StateVec<L>& dx) const {
    const Mat3 C_true = dcm_from_euler(dx.template segment<3>(L::kAtt)) * C_nb_;
    const Vec3 v_true = v_n_ - dx.template segment<3>(L::kVel);
    const Vec3 w_true = omega_ib_b_ - dx.template segment<3>(L::kGyroBias);
    // the true lever arm l_o^ - dl_o (layouts with kOdoLever): the l_o^ part with the rate of set(),
    // the dl_o part with the rate of set_lever_arm_rate (as in H)
    Vec3 d = vehicle_detail::point_velocity_v(C_nb_, v_n_, omega_ib_b_, omega_in_n_, cfg_) -
             vehicle_detail::point_velocity_v(C_true, v_true, w_true, omega_in_n_, cfg_);
    if constexpr (kHasOdoLever<L>) {
      const Vec3 dl = dx.template segment<3>(OdoLeverState<L>::offset);
      const Vec3 omega_nb_lever_b = omega_lever_b_ - dx.template segment<3>(L::kGyroBias) - C_true.transpose() * omega_in_n_;
      d += cfg_.C_bv.transpose() * omega_nb_lever_b.cross(dl);
    }
    RowVec out(lin_.rows());
    for (int i = 0; i < lin_.rows(); ++i) out[i] = d[rows_axis_[i]];
    if (use_odo_) {  // row 0: (1 + s^) (v~_fwd - (1 + ds) v_fwd(dx)), header comment
      const double v_fwd_true = v_fwd_computed_ - d[0];
      double ds = 0.0;
      if constexpr (kHasOdoScale<L>) ds = dx[OdoScaleState<L>::offset];
      out[0] = odo_gain_ * (v_fwd_computed_ - (1.0 + ds) * v_fwd_true);
    }
    return out;
  }

 private:
  LinearMeasurement<L> lin_;
  VehicleConstraintConfig cfg_;
  Mat3 C_nb_ = Mat3::Identity();
  Vec3 v_n_ = Vec3::Zero(), omega_ib_b_ = Vec3::Zero(), omega_in_n_ = Vec3::Zero();
  Vec3 omega_lever_b_ = Vec3::Zero();  // rate of the lever-arm columns (set_lever_arm_rate)
  bool lever_rate_set_ = false;
  bool use_odo_ = false, use_nhc_ = false;
  double odo_ = 0.0;
  double odo_gain_ = 1.0;        // 1 + s^ (fed-back odometer scale factor)
  double v_fwd_computed_ = 0.0;  // v~_v[0]: forward speed of the constrained point from the INS [m/s]
  int rows_axis_[3] = {0, 1, 2};
};

/// ZUPT (3 rows, v_n = 0) and/or ZARU (3 rows, omega_eb = 0) while stationary.
template <class L>
class StandstillMeasurement {
 public:
  using RowVec = typename LinearMeasurement<L>::RowVec;

  void set(const NavState& ins, const Vec3& omega_ib_b, const VehicleConstraintConfig& cfg, bool zupt, bool zaru) {
    C_nb_ = ins.q_nb.toRotationMatrix();
    v_n_ = ins.v_n;
    omega_ib_b_ = omega_ib_b;
    omega_ie_n_ = wgs84::omega_ie_n(ins.lat);
    zupt_ = zupt;
    zaru_ = zaru;
    const int rows = (zupt ? 3 : 0) + (zaru ? 3 : 0);
    lin_.residual.resize(rows);
    lin_.H.setZero(rows, L::kSize);
    lin_.R.setZero(rows, rows);
    int row = 0;
    if (zupt) {
      lin_.residual.template segment<3>(row) = v_n_;
      lin_.H.template block<3, 3>(row, L::kVel) = Mat3::Identity();
      lin_.R.template block<3, 3>(row, row) = Mat3::Identity() * (cfg.sigma_zupt_mps * cfg.sigma_zupt_mps);
      row += 3;
    }
    if (zaru) {
      lin_.residual.template segment<3>(row) = omega_ib_b_ - C_nb_.transpose() * omega_ie_n_;
      lin_.H.template block<3, 3>(row, L::kAtt) = C_nb_.transpose() * skew(omega_ie_n_);
      lin_.H.template block<3, 3>(row, L::kGyroBias) = Mat3::Identity();
      lin_.R.template block<3, 3>(row, row) = Mat3::Identity() * (cfg.sigma_zaru_radps * cfg.sigma_zaru_radps);
    }
    lin_.n_cols = zaru ? L::kGyroBias + 3 : L::kVel + 3;
  }

  const LinearMeasurement<L>& linear() const { return lin_; }

  RowVec predicted_residual(const StateVec<L>& dx) const {
    RowVec out(lin_.rows());
    int row = 0;
    if (zupt_) {
      out.template segment<3>(row) = dx.template segment<3>(L::kVel);
      row += 3;
    }
    if (zaru_) {
      const Mat3 C_true = dcm_from_euler(dx.template segment<3>(L::kAtt)) * C_nb_;
      // computed residual minus the residual of the true state (which is zero at standstill)
      out.template segment<3>(row) = (omega_ib_b_ - C_nb_.transpose() * omega_ie_n_) -
                                     ((omega_ib_b_ - dx.template segment<3>(L::kGyroBias)) -
                                      C_true.transpose() * omega_ie_n_);
    }
    return out;
  }

 private:
  LinearMeasurement<L> lin_;
  Mat3 C_nb_ = Mat3::Identity();
  Vec3 v_n_ = Vec3::Zero(), omega_ib_b_ = Vec3::Zero(), omega_ie_n_ = Vec3::Zero();
  bool zupt_ = false, zaru_ = false;
};

}  // namespace insnav
