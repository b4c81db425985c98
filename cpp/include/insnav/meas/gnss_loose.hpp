// insnav/meas/gnss_loose.hpp -- loosely coupled GNSS position/velocity
// measurement with the antenna lever arm (seed 000 eq. (8), extended).
//
// residual = INS-predicted antenna quantity - GNSS, position in NED metres:
//   r_ant = r_imu + C_nb l_b,  v_ant = v_n + C_nb (omega_ib_b x l_b) - omega_in_n x (C_nb l_b)
// Linearisation (error = computed - true, C~_nb = (I - [psi x]) C_nb):
//   d r_ant = dr + [(C_nb l_b) x] psi
//   d v_ant = dv + [(C_nb (omega x l)) x] psi - [omega_in x][(C_nb l) x] psi - C_nb [l x] dw_b
// Groves (2013) eqs. (14.113)-(14.118); KF-GINS uses the same position form.
//
// Self-calibration states (layout.hpp).  Lever arm, dl_b = l_b^ - l_b: the
// same residual differentiated with respect to l_b,
//   d r_ant = ... + C_nb dl_b
//   d v_ant = ... + (C_nb [omega_ib_b x] - [omega_in_n x] C_nb) dl_b
// where the rate in this column is a low-passed one that holds no noise of
// the increment whose rate the residual takes (set_lever_arm_rate;
// ClosedLoop::omega_ib_b_lever: the one rate in both is an errors-in-variables
// bias of dl_b towards l_b^, i.e. of the estimate towards zero).
// Time offset, dt_d = t_d^ - t_d: the fix tagged t_g holds the antenna at IMU
// time t_g - t_d; the engine applies it at t_a = t_g - t_d^ + shift (shift =
// 0 unless the INS had already passed that time) and the prediction is taken
// back by `shift` to first order, r_ant - v_ant shift, v_ant - a_n shift.  The
// true antenna is then at t_a - shift + dt_d, so to first order
//   residual = ... - v_ant dt_d            (position rows)
//   residual = ... - a_n dt_d              (velocity rows)
// with a_n = C_nb f_ib_b + g_n - (2 omega_ie_n + omega_en_n) x v_n the INS
// acceleration (the lever arm's own acceleration, omega-dot x l and
// omega x (omega x l), left out: < 0.05 m/s^2 for l = 1.5 m at 0.2 rad/s).
// (The time-synchronisation error as an integration-filter state: Groves
// 2013, ch. 14; lever-arm observability: Hong et al. 2005, docs/algorithms.md
// section 21.)
#pragma once

#include "insnav/earth/wgs84.hpp"
#include "insnav/filter/types.hpp"

namespace insnav {

/// One GNSS position/velocity fix.  has_vel = false (or NaN velocity) for
/// position-only receivers.
struct GnssFix {
  double t = 0.0;                          // time of validity [s]
  double lat = 0.0, lon = 0.0, h = 0.0;    // antenna position [rad, rad, m]
  Vec3 v_n = Vec3::Zero();                 // antenna velocity [m/s]
  Vec3 sigma_pos_n = Vec3::Constant(1.0);  // 1-sigma N, E, D [m]
  Vec3 sigma_vel_n = Vec3::Constant(0.1);  // [m/s]
  bool has_pos = true;   // the engines take a non-finite position (or sigma) as absent (masked_fix)
  bool has_vel = true;   // and a non-finite velocity (or sigma) as absent
};

template <class L>
class LooseMeasurement {
 public:
  using RowVec = typename LinearMeasurement<L>::RowVec;

  /// Build residual, H and R from the INS state at the fix time.
  /// omega_ib_b: corrected angular rate [rad/s]; lever_arm_b: IMU -> antenna [m].
  void set(const NavState& ins, const Vec3& omega_ib_b, const Vec3& lever_arm_b, const GnssFix& fix) {
    set(ins, omega_ib_b, lever_arm_b, fix, Vec3::Zero(), 0.0);
  }

  /// The same for the self-calibration layouts: a_n the INS acceleration
  /// [m/s^2] (time-offset column of the velocity rows) and shift_s [s] how
  /// far past the fix's (shifted) time of validity the INS is (header comment).
  void set(const NavState& ins, const Vec3& omega_ib_b, const Vec3& lever_arm_b, const GnssFix& fix,
           const Vec3& a_n, double shift_s) {
    const int rows = (fix.has_pos ? 3 : 0) + (fix.has_vel ? 3 : 0);
    lin_.residual.resize(rows);
    lin_.H.setZero(rows, L::kSize);
    lin_.R.setZero(rows, rows);
    has_pos_ = fix.has_pos;
    has_vel_ = fix.has_vel;
    C_nb_ = ins.q_nb.toRotationMatrix();
    l_b_ = lever_arm_b;
    omega_ib_b_ = omega_ib_b;
    if (!lever_rate_set_) omega_lever_b_ = omega_ib_b;
    lever_rate_set_ = false;
    const wgs84::Radii r = wgs84::radii(ins.lat);
    const double RMh = r.R_M + ins.h, RNh = r.R_N + ins.h;
    const Vec3 l_n = C_nb_ * l_b_;
    const bool lever = l_b_.squaredNorm() > 0.0;
    int row = 0;
    if (fix.has_pos) {
      // antenna minus GNSS, NED metres (small-difference form is exact to < 1 um for < 1 km)
      lin_.residual.template segment<3>(row) =
          Vec3((ins.lat - fix.lat) * RMh, (ins.lon - fix.lon) * RNh * std::cos(ins.lat), -(ins.h - fix.h)) + l_n;
      lin_.H.template block<3, 3>(row, L::kPos) = Mat3::Identity();
      if (lever) lin_.H.template block<3, 3>(row, L::kAtt) = skew(l_n);
      lin_.R.template block<3, 3>(row, row) = fix.sigma_pos_n.cwiseAbs2().asDiagonal();
      if constexpr (kHasLeverArm<L> || kHasTimeOffset<L>) {
        const Vec3 omega_in_n = wgs84::omega_ie_n(ins.lat) + wgs84::omega_en_n(ins.lat, ins.h, ins.v_n, r);
        const Vec3 v_ant_n = ins.v_n + C_nb_ * omega_ib_b_.cross(l_b_) - omega_in_n.cross(l_n);
        omega_in_n_ = omega_in_n;
        if constexpr (kHasLeverArm<L>) lin_.H.template block<3, 3>(row, kLever) = C_nb_;
        if constexpr (kHasTimeOffset<L>) {
          lin_.H.template block<3, 1>(row, kTd) = -v_ant_n;
          if (shift_s != 0.0) lin_.residual.template segment<3>(row) -= v_ant_n * shift_s;
        }
      }
      row += 3;
    }
    if (fix.has_vel) {
      const Vec3 omega_in_n = wgs84::omega_ie_n(ins.lat) + wgs84::omega_en_n(ins.lat, ins.h, ins.v_n, r);
      const Vec3 wxl_n = C_nb_ * omega_ib_b_.cross(l_b_);
      lin_.residual.template segment<3>(row) = ins.v_n + wxl_n - omega_in_n.cross(l_n) - fix.v_n;
      lin_.H.template block<3, 3>(row, L::kVel) = Mat3::Identity();
      if (lever) {
        lin_.H.template block<3, 3>(row, L::kAtt) = skew(wxl_n) - skew(omega_in_n) * skew(l_n);
        lin_.H.template block<3, 3>(row, L::kGyroBias) = -C_nb_ * skew(l_b_);
      }
      if constexpr (kHasLeverArm<L>) {  // the rate of set_lever_arm_rate
        lin_.H.template block<3, 3>(row, kLever) = C_nb_ * skew(omega_lever_b_) - skew(omega_in_n) * C_nb_;
        omega_in_n_ = omega_in_n;
      }
      if constexpr (kHasTimeOffset<L>) {
        lin_.H.template block<3, 1>(row, kTd) = -a_n;
        if (shift_s != 0.0) lin_.residual.template segment<3>(row) -= a_n * shift_s;
      }
      lin_.R.template block<3, 3>(row, row) = fix.sigma_vel_n.cwiseAbs2().asDiagonal();
    }
    // block sparsity: pos/vel only -> 6 columns; lever arm adds psi (and dw_b for velocity)
    lin_.n_cols = !lever ? 6 : (fix.has_vel ? L::kGyroBias + 3 : L::kAtt + 3);
    if constexpr (kHasLeverArm<L> || kHasTimeOffset<L>) lin_.n_cols = L::kSize;  // the extra states come last
    (void)a_n;
    (void)shift_s;
  }

  const LinearMeasurement<L>& linear() const { return lin_; }

  /// Multiply the variance of row i of R by factor (the adaptive measurement
  /// noise, filter/adaptive_noise.hpp; R is diagonal).
  void scale_noise_row(int i, double factor) { lin_.R(i, i) *= factor; }

  /// The angular rate [rad/s] of the lever-arm states' velocity columns for
  /// the next set() (layouts with them): a rate whose noise is independent of
  /// the one given to set() (ClosedLoop::omega_ib_b_lever).  Without this
  /// call: the rate given to set().
  void set_lever_arm_rate(const Vec3& omega_b) {
    omega_lever_b_ = omega_b;
    lever_rate_set_ = true;
  }

  /// Nonlinear h(dx): the residual the INS would show if its true error were dx
  /// (exact attitude dependence of the lever-arm terms; seed 000 UKF eqs. (14)-(21)).
  /// Lever-arm states: the true lever arm l_b^ - dl_b (exact), the velocity
  /// rows' dl_b term with the rate of set_lever_arm_rate (as in H); time
  /// offset: its linear column (header comment).
  RowVec predicted_residual(const StateVec<L>& dx) const {
    RowVec out(lin_.rows());
    const Mat3 C_true = dcm_from_euler(dx.template segment<3>(L::kAtt)) * C_nb_;
    Vec3 l_true = l_b_;
    if constexpr (kHasLeverArm<L>) l_true -= dx.template segment<3>(kLever);
    int row = 0;
    if (has_pos_) {
      if constexpr (kHasLeverArm<L>)
        out.template segment<3>(row) = dx.template segment<3>(L::kPos) + C_nb_ * l_b_ - C_true * l_true;
      else
        out.template segment<3>(row) = dx.template segment<3>(L::kPos) + (C_nb_ - C_true) * l_b_;
      row += 3;
    }
    if (has_vel_) {
      const Vec3 dw = dx.template segment<3>(L::kGyroBias);
      if constexpr (kHasLeverArm<L>) {  // l_true = l_b^ - dl_b, the dl_b part with the lever-arm rate
        const Vec3 dl = dx.template segment<3>(kLever);
        out.template segment<3>(row) = dx.template segment<3>(L::kVel) + C_nb_ * omega_ib_b_.cross(l_b_) -
                                       C_true * ((omega_ib_b_ - dw).cross(l_b_) - (omega_lever_b_ - dw).cross(dl));
      } else {
        out.template segment<3>(row) = dx.template segment<3>(L::kVel) + C_nb_ * omega_ib_b_.cross(l_b_) -
                                       C_true * (omega_ib_b_ - dw).cross(l_true);
      }
      if constexpr (kHasLeverArm<L>) {  // the transport term of the lever arm, exact in l
        const Vec3 d_l = C_nb_ * l_b_ - C_true * l_true;
        out.template segment<3>(row) -= omega_in_n_.cross(d_l);
      }
    }
    if constexpr (kHasTimeOffset<L>) out += lin_.H.col(kTd) * dx[kTd];
    return out;
  }

 private:
  static constexpr int kLever = LeverArmState<L>::offset, kTd = TimeOffsetState<L>::offset;
  LinearMeasurement<L> lin_;
  Mat3 C_nb_ = Mat3::Identity();
  Vec3 l_b_ = Vec3::Zero();
  Vec3 omega_ib_b_ = Vec3::Zero();
  Vec3 omega_in_n_ = Vec3::Zero();  // lever-arm layouts only (predicted_residual)
  Vec3 omega_lever_b_ = Vec3::Zero();  // rate of the lever-arm velocity columns (set_lever_arm_rate)
  bool lever_rate_set_ = false;
  bool has_pos_ = true, has_vel_ = true;
};

}  // namespace insnav
