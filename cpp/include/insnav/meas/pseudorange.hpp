// insnav/meas/pseudorange.hpp -- tightly coupled GNSS measurement: pseudorange
// and pseudorange rate of every satellite of one epoch (seed 003, Xu et al. 2012,
// sec. "tight coupling": z = INS-predicted minus measured, one row pair per
// satellite, linearised with the line-of-sight unit vectors).
//
// Model (the one insnav.sim.gnss_raw simulates and insnav.gnss.ephemeris
// documents; satellite states are already light-time and Sagnac corrected into
// the ECEF frame at reception by Python):
//   rho  = |r_sat_e - r_ant_e| + b - c dt_sv
//   rhod = u_e . (v_sat_e - v_ant_e) + d - c ddt_sv,   u_e = (r_sat_e - r_ant_e) / |.|
//   r_ant_e = r_e(lat, lon, h) + C_en C_nb l_b
//   v_ant_e = C_en (v_n + C_nb (omega_ib_b x l_b) - omega_in_n x (C_nb l_b))
// with b [m], d [m/s] the receiver clock bias and drift states.  Several
// constellations (LayoutTightMulti, layout.hpp): b is the GPS-time clock and a
// satellite of system s != GPS adds its inter-system bias isb_s to rho (not to
// rhod), so its pseudorange row has +1 in the ISB column of s; GPS-only data
// leave the ISB columns zero (one code path for any mix).  A layout without
// ISB states treats every system's pseudorange with the common clock b (the
// caller has removed the ISB or uses GPS only).
//
// Linearisation (error = computed - true, layout.hpp; Groves 2013 eqs.
// (14.127)-(14.129), mapped to our NED-metre position error):
//   d rho  = -u_n^T d r_ant_n + db,         d r_ant_n = dr + [(C_nb l_b) x] psi
//   d rhod = -u_n^T d v_ant_n - g_n^T d r_ant_n - u_n^T dC_en(dr) v_ant_n + dd
//   g_n = C_ne (I - u u^T) (v_sat - v_ant) / rho          (change of the LOS)
//   d v_ant_n = dv + [(C_nb (w x l)) x] psi - [w_in x][(C_nb l) x] psi - C_nb [l x] dw_b
// and the frame-rotation term dC_en(dr) v (rotation of the NED axes with the
// position error), both of order 1e-4 (m/s)/m.
//
// Self-calibration states (layout.hpp; the same conventions as
// gnss_loose.hpp).  Lever arm, dl_b = l_b^ - l_b:
//   d rho  = ... - u_n^T C_nb dl_b
//   d rhod = ... - u_n^T (C_nb [omega_ib_b x] - [omega_in_n x] C_nb) dl_b - g_n^T C_nb dl_b
// Time offset, dt_d = t_d^ - t_d (the satellite states stay at the epoch's
// GNSS time; only the INS is offset): the true antenna is at the INS time
// t_a - shift + dt_d, d r_ant = -v_ant dt_d, d v_ant = -a_n dt_d, so
//   d rho  = ... + u_n^T v_ant_n dt_d                       (minus the receiver's range rate)
//   d rhod = ... + (u_n^T a_n + g_n^T v_ant_n) dt_d         (minus its range acceleration)
// the second derivative of the range with respect to the receiver's motion
// (the lever arm's own acceleration left out, as in gnss_loose.hpp).  A
// prediction taken at shift > 0 after its time is moved back by shift with
// the same terms.
//
// Rows: one per finite observation (NaN pseudorange or rate drops that row),
// at most kMaxMeasRows (16 satellites with both); fixed storage, no heap.
#pragma once

#include <cmath>

#include "insnav/earth/wgs84.hpp"
#include "insnav/filter/types.hpp"

namespace insnav {

/// One satellite at one epoch.  r_e/v_e in the ECEF frame at reception.
struct SatObservation {
  Vec3 r_e = Vec3::Zero();        // satellite position at transmission [m]
  Vec3 v_e = Vec3::Zero();        // satellite velocity [m/s]
  double clock_bias_m = 0.0;      // c dt_sv (+ modelled iono/tropo delays subtracted by the caller) [m]
  double clock_drift_mps = 0.0;   // c d(dt_sv)/dt [m/s]
  double pseudorange_m = NAN;     // measured; NaN: no pseudorange row
  double pseudorange_rate_mps = NAN;  // measured; NaN: no rate row
  double sigma_pr_m = 10.0;       // 1-sigma [m]
  double sigma_prr_mps = 0.1;     // 1-sigma [m/s]
  int system = 0;                 // 0 GPS (reference clock), 1 GLONASS, 2 Galileo, 3 BeiDou (insnav.gnss.systems)
  int prn = 0;                    // satellite number within its system (0: unknown; the robust CUSUM keys on it)
};

/// Antenna position/velocity in ECEF of a navigation state.
struct AntennaEcef {
  Vec3 r_e, v_e;
};

/// r_ant_e and v_ant_e of the state (lat, lon, h, v_n, C_nb) with lever arm l_b.
inline AntennaEcef antenna_ecef(double lat, double lon, double h, const Vec3& v_n, const Mat3& C_nb,
                                const Vec3& omega_ib_b, const Vec3& omega_in_n, const Vec3& l_b) {
  const Mat3 C_en = wgs84::C_en(lat, lon);
  const Vec3 l_n = C_nb * l_b;
  AntennaEcef a;
  a.r_e = wgs84::geodetic_to_ecef(lat, lon, h) + C_en * l_n;
  a.v_e = C_en * (v_n + C_nb * omega_ib_b.cross(l_b) - omega_in_n.cross(l_n));
  return a;
}

template <class L>
class TightMeasurement {
  static_assert(kHasClock<L>, "tight coupling needs a layout with clock states (Layout17)");
  static constexpr int kIsb = IsbStates<L>::offset, kNumIsb = IsbStates<L>::count;

 public:
  using RowVec = typename LinearMeasurement<L>::RowVec;

  /// Build residual, H and R for the satellites sats[0..n_sats) at the INS state.
  /// clock_bias_m / clock_drift_mps: the current receiver clock estimate.
  /// Satellites beyond kMaxMeasRows rows are ignored (the caller selects).
  /// isb_m: the current inter-system bias estimates [m] of systems 1..kNumIsb
  /// (layouts with ISB states; null: zero).
  void set(const NavState& ins, const Vec3& omega_ib_b, const Vec3& lever_arm_b, double clock_bias_m,
           double clock_drift_mps, const SatObservation* sats, int n_sats, const double* isb_m = nullptr,
           const Vec3& a_n = Vec3::Zero(), double shift_s = 0.0) {
    (void)isb_m;  // layouts without ISB states
    (void)a_n;    // layouts without the time offset
    (void)shift_s;
    ins_ = ins;
    C_nb_ = ins.q_nb.toRotationMatrix();
    l_b_ = lever_arm_b;
    omega_ib_b_ = omega_ib_b;
    if (!lever_rate_set_) omega_lever_b_ = omega_ib_b;
    lever_rate_set_ = false;
    b_ = clock_bias_m;
    d_ = clock_drift_mps;
    shift_ = shift_s;
    const wgs84::Radii r = wgs84::radii(ins.lat);
    RMh_ = r.R_M + ins.h;
    RNh_ = r.R_N + ins.h;
    omega_in_n_ = wgs84::omega_ie_n(ins.lat) + wgs84::omega_en_n(ins.lat, ins.h, ins.v_n, r);
    const Mat3 C_en = wgs84::C_en(ins.lat, ins.lon);
    const Vec3 l_n = C_nb_ * l_b_;
    const Vec3 wxl_n = C_nb_ * omega_ib_b_.cross(l_b_);
    const Vec3 v_ant_n = ins.v_n + wxl_n - omega_in_n_.cross(l_n);
    const AntennaEcef ant = antenna_ecef(ins.lat, ins.lon, ins.h, ins.v_n, C_nb_, omega_ib_b_, omega_in_n_, l_b_);
    const bool lever = l_b_.squaredNorm() > 0.0;
    const Mat3 dr_ant_dpsi = skew(l_n);
    const Mat3 dv_ant_dpsi = skew(wxl_n) - skew(omega_in_n_) * skew(l_n);
    const Mat3 dv_ant_ddw = -C_nb_ * skew(l_b_);
    // d(C_en v)/d(dN, dE) expressed in NED (frame rotation with the position error)
    const double sl = std::sin(ins.lat), cl = std::cos(ins.lat);
    const Vec3 dv_dN = Vec3(-v_ant_n.z(), 0.0, v_ant_n.x()) / RMh_;
    const Vec3 dv_dE = Vec3(sl * v_ant_n.y(), -sl * v_ant_n.x() - cl * v_ant_n.z(), cl * v_ant_n.y()) / (RNh_ * cl);

    int rows = 0;
    for (int i = 0; i < n_sats; ++i) {
      rows += std::isfinite(sats[i].pseudorange_m) ? 1 : 0;
      rows += std::isfinite(sats[i].pseudorange_rate_mps) ? 1 : 0;
    }
    if (rows > kMaxMeasRows) rows = kMaxMeasRows;
    lin_.residual.resize(rows);
    lin_.H.setZero(rows, L::kSize);
    lin_.R.setZero(rows, rows);
    int row = 0;
    for (int i = 0; i < n_sats && row < rows; ++i) {
      const SatObservation& s = sats[i];
      const Vec3 dr_e = s.r_e - ant.r_e;
      const double rho = dr_e.norm();
      const Vec3 u_e = dr_e / rho;
      const Vec3 u_n = C_en.transpose() * u_e;
      const Vec3 vrel_e = s.v_e - ant.v_e;
      for (int kind = 0; kind < 2 && row < rows; ++kind) {
        const double z = kind == 0 ? s.pseudorange_m : s.pseudorange_rate_mps;
        if (!std::isfinite(z)) continue;
        Row& rw = rows_[row];
        rw.sat_r_e = s.r_e;
        rw.sat_v_e = s.v_e;
        rw.sat_clock = kind == 0 ? s.clock_bias_m : s.clock_drift_mps;
        rw.is_rate = kind == 1;
        rw.isb_col = -1;
        rw.isb = 0.0;
        auto H = lin_.H.row(row);
        if (kind == 0) {
          double isb = 0.0;
          if constexpr (kHasIsb<L>) {
            if (s.system >= 1 && s.system <= kNumIsb) {
              rw.isb_col = kIsb + s.system - 1;
              isb = isb_m ? isb_m[s.system - 1] : 0.0;
              H[rw.isb_col] = 1.0;
            }
          }
          rw.isb = isb;
          rw.predicted = rho + b_ + isb - s.clock_bias_m;
          H.template segment<3>(L::kPos) = -u_n.transpose();
          if (lever) H.template segment<3>(L::kAtt) = -u_n.transpose() * dr_ant_dpsi;
          H[L::kClockBias] = 1.0;
          if constexpr (kHasLeverArm<L>) H.template segment<3>(kLever) = -u_n.transpose() * C_nb_;
          if constexpr (kHasTimeOffset<L>) {
            H[kTd] = u_n.dot(v_ant_n);
            rw.predicted += H[kTd] * shift_s;
          }
          lin_.R(row, row) = s.sigma_pr_m * s.sigma_pr_m;
        } else {
          rw.predicted = u_e.dot(vrel_e) + d_ - s.clock_drift_mps;
          const Vec3 g_n = C_en.transpose() * ((vrel_e - u_e * u_e.dot(vrel_e)) / rho);
          Vec3 h_pos = -g_n;
          h_pos.x() -= u_n.dot(dv_dN);
          h_pos.y() -= u_n.dot(dv_dE);
          H.template segment<3>(L::kPos) = h_pos.transpose();
          H.template segment<3>(L::kVel) = -u_n.transpose();
          if (lever) {
            H.template segment<3>(L::kAtt) = -u_n.transpose() * dv_ant_dpsi - g_n.transpose() * dr_ant_dpsi;
            H.template segment<3>(L::kGyroBias) = -u_n.transpose() * dv_ant_ddw;
          }
          H[L::kClockDrift] = 1.0;
          if constexpr (kHasLeverArm<L>)
            H.template segment<3>(kLever) =
                -u_n.transpose() * (C_nb_ * skew(omega_lever_b_) - skew(omega_in_n_) * C_nb_) - g_n.transpose() * C_nb_;
          if constexpr (kHasTimeOffset<L>) {
            H[kTd] = u_n.dot(a_n) + g_n.dot(v_ant_n);
            rw.predicted += H[kTd] * shift_s;
          }
          lin_.R(row, row) = s.sigma_prr_mps * s.sigma_prr_mps;
        }
        lin_.residual[row] = rw.predicted - z;
        ++row;
      }
    }
    lin_.n_cols = L::kSize;  // clock columns are last
  }

  const LinearMeasurement<L>& linear() const { return lin_; }
  /// For an engine that folds extra states into the rows (meas/pseudorange_gm.hpp; the EKF's update).
  LinearMeasurement<L>& linear_mutable() { return lin_; }

  /// The angular rate [rad/s] of the lever-arm states' Doppler columns for the
  /// next set() (layouts with them; meas/gnss_loose.hpp, set_lever_arm_rate):
  /// a rate whose noise is independent of the one given to set()
  /// (ClosedLoop::omega_ib_b_lever).  Without this call: the rate given to set().
  void set_lever_arm_rate(const Vec3& omega_b) {
    omega_lever_b_ = omega_b;
    lever_rate_set_ = true;
  }

  /// Nonlinear h(dx): the residual the INS would show if its true error were dx
  /// (noise-free), i.e. h(INS) - h(INS (-) dx) with the true state recovered
  /// as in the engine's feedback.  Used by the UKF measurement update.
  RowVec predicted_residual(const StateVec<L>& dx) const {
    const int m = lin_.rows();
    RowVec out(m);
    if (m == 0) return out;
    const double lat = ins_.lat - dx[L::kPos] / RMh_;
    const double lon = ins_.lon - dx[L::kPos + 1] / (RNh_ * std::cos(ins_.lat));
    const double h = ins_.h + dx[L::kPos + 2];
    const Vec3 v_n = ins_.v_n - dx.template segment<3>(L::kVel);
    const Mat3 C_true = dcm_from_euler(dx.template segment<3>(L::kAtt)) * C_nb_;
    const Vec3 w_true = omega_ib_b_ - dx.template segment<3>(L::kGyroBias);
    Vec3 l_true = l_b_;
    if constexpr (kHasLeverArm<L>) l_true -= dx.template segment<3>(kLever);
    const AntennaEcef ant = antenna_ecef(lat, lon, h, v_n, C_true, w_true, omega_in_n_, l_true);
    const double b = b_ - dx[L::kClockBias], d = d_ - dx[L::kClockDrift];
    for (int i = 0; i < m; ++i) {
      const Row& rw = rows_[i];
      const Vec3 dr_e = rw.sat_r_e - ant.r_e;
      const double rho = dr_e.norm();
      // the ISB estimate is in `predicted`; its error dx[isb_col] enters as the clock's
      const double h_true = rw.is_rate ? dr_e.dot(rw.sat_v_e - ant.v_e) / rho + d - rw.sat_clock
                                       : rho + b - rw.sat_clock + (rw.isb_col >= 0 ? rw.isb - dx[rw.isb_col] : 0.0);
      out[i] = rw.predicted - h_true;
      if constexpr (kHasTimeOffset<L>) out[i] += lin_.H(i, kTd) * (dx[kTd] - shift_);
    }
    return out;
  }

  /// INS-predicted value of row i (pseudorange [m] or rate [m/s]).
  double predicted(int i) const { return rows_[i].predicted; }

 private:
  struct Row {
    Vec3 sat_r_e = Vec3::Zero(), sat_v_e = Vec3::Zero();
    double sat_clock = 0.0, predicted = 0.0;
    double isb = 0.0;  // ISB estimate in `predicted` [m]
    int isb_col = -1;  // its state column (pseudorange of a non-GPS satellite), else -1
    bool is_rate = false;
  };
  static constexpr int kLever = LeverArmState<L>::offset, kTd = TimeOffsetState<L>::offset;
  double shift_ = 0.0;  // shift_s of set() (time-offset layouts)
  LinearMeasurement<L> lin_;
  Row rows_[kMaxMeasRows];
  NavState ins_{};
  Mat3 C_nb_ = Mat3::Identity();
  Vec3 l_b_ = Vec3::Zero(), omega_ib_b_ = Vec3::Zero(), omega_in_n_ = Vec3::Zero();
  Vec3 omega_lever_b_ = Vec3::Zero();  // rate of the lever-arm Doppler columns (set_lever_arm_rate)
  bool lever_rate_set_ = false;
  double b_ = 0.0, d_ = 0.0, RMh_ = 1.0, RNh_ = 1.0;
};

}  // namespace insnav
