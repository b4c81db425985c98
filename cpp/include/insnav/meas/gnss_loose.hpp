// insnav/meas/gnss_loose.hpp -- loosely coupled GNSS position/velocity
// measurement with the antenna lever arm (seed 000 eq. (8), extended).
//
// residual = INS-predicted antenna quantity - GNSS, position in NED metres:
//   r_ant = r_imu + C_nb l_b,  v_ant = v_n + C_nb (omega_ib_b x l_b) - omega_in_n x (C_nb l_b)
// Linearisation (error = computed - true, C~_nb = (I - [psi x]) C_nb):
//   d r_ant = dr + [(C_nb l_b) x] psi
//   d v_ant = dv + [(C_nb (omega x l)) x] psi - [omega_in x][(C_nb l) x] psi - C_nb [l x] dw_b
// Groves (2013) eqs. (14.113)-(14.118); KF-GINS uses the same position form.
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
  bool has_pos = true;
  bool has_vel = true;
};

template <class L>
class LooseMeasurement {
 public:
  using RowVec = typename LinearMeasurement<L>::RowVec;

  /// Build residual, H and R from the INS state at the fix time.
  /// omega_ib_b: corrected angular rate [rad/s]; lever_arm_b: IMU -> antenna [m].
  void set(const NavState& ins, const Vec3& omega_ib_b, const Vec3& lever_arm_b, const GnssFix& fix) {
    const int rows = (fix.has_pos ? 3 : 0) + (fix.has_vel ? 3 : 0);
    lin_.residual.resize(rows);
    lin_.H.setZero(rows, L::kSize);
    lin_.R.setZero(rows, rows);
    has_pos_ = fix.has_pos;
    has_vel_ = fix.has_vel;
    C_nb_ = ins.q_nb.toRotationMatrix();
    l_b_ = lever_arm_b;
    omega_ib_b_ = omega_ib_b;
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
      lin_.R.template block<3, 3>(row, row) = fix.sigma_vel_n.cwiseAbs2().asDiagonal();
    }
    // block sparsity: pos/vel only -> 6 columns; lever arm adds psi (and dw_b for velocity)
    lin_.n_cols = !lever ? 6 : (fix.has_vel ? L::kGyroBias + 3 : L::kAtt + 3);
  }

  const LinearMeasurement<L>& linear() const { return lin_; }

  /// Nonlinear h(dx): the residual the INS would show if its true error were dx
  /// (exact attitude dependence of the lever-arm terms; seed 000 UKF eqs. (14)-(21)).
  RowVec predicted_residual(const StateVec<L>& dx) const {
    RowVec out(lin_.rows());
    const Mat3 C_true = dcm_from_euler(dx.template segment<3>(L::kAtt)) * C_nb_;
    int row = 0;
    if (has_pos_) {
      out.template segment<3>(row) = dx.template segment<3>(L::kPos) + (C_nb_ - C_true) * l_b_;
      row += 3;
    }
    if (has_vel_) {
      const Vec3 dw = dx.template segment<3>(L::kGyroBias);
      out.template segment<3>(row) = dx.template segment<3>(L::kVel) + C_nb_ * omega_ib_b_.cross(l_b_) -
                                     C_true * (omega_ib_b_ - dw).cross(l_b_);
    }
    return out;
  }

 private:
  LinearMeasurement<L> lin_;
  Mat3 C_nb_ = Mat3::Identity();
  Vec3 l_b_ = Vec3::Zero();
  Vec3 omega_ib_b_ = Vec3::Zero();
  bool has_pos_ = true, has_vel_ = true;
};

}  // namespace insnav
