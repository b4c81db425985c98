// insnav/meas/tdcp.hpp -- time-differenced carrier phase (TDCP) of one
// receiver, without a base: the change of the carrier phase of a satellite
// between two consecutive epochs as a measurement of the antenna's position
// change, processed with stochastic cloning of the previous epoch's error
// state (Roumeliotis & Burdick 2002, "Stochastic cloning: a generalized
// framework for processing relative state measurements", ICRA, sec. III).
//
// Model (docs/algorithms.md, "TDCP/INS"; phase in metres, Phi = lambda phi):
//   Phi_j = |r_sat_e,j - r_ant_e,j| + b_j - c dt_sv,j + lambda N - I_j + T_j + eps_j
// at epochs j = k-1, k of one unbroken phase arc, so the time difference
//   dPhi = Phi_k - Phi_{k-1}
//        = |r_sat,k - r_ant,k| - |r_sat,k-1 - r_ant,k-1| + (b_k - b_{k-1}) - (c dt_sv,k - c dt_sv,k-1)
// has no ambiguity.  Satellite motion: each epoch uses that epoch's own
// satellite position (transmission time, rotated into the ECEF frame of that
// epoch's reception: the Sagnac correction, as for the pseudorange,
// pseudorange.hpp) and its own satellite clock.  The change of the modelled
// atmosphere over one epoch interval (< 1 mm at 4 Hz) is left in the clock
// column's difference (the code delays enter with the opposite sign of the
// phase advance: the error is 2 dI, sub-millimetre).  The receiver clock
// change b_k - b_{k-1} is carried by the filter's clock states (bias, drift)
// rather than removed by a between-satellite difference: the filter's clock
// model then weighs it, and with n satellites the n rows give the position
// change and the clock change (the same information as n - 1 between-
// satellite differences when the clock model is loose).  The inter-system
// biases cancel in the time difference.
//
// Linearisation (error = computed - true, layout.hpp; antenna r_ant = r + C_nb l_b):
//   d dPhi = H_k dx_k + H_{k-1} dx_{k-1}
//   H_k     = [-u_k^T at position, -u_k^T [(C_nb,k l_b) x] at attitude, +1 at the clock bias]
//   H_{k-1} = [+u_{k-1}^T at position, +u_{k-1}^T [(C_nb,k-1 l_b) x] at attitude, -1 at the clock bias]
// with u_j the unit line of sight (antenna -> satellite) in the NED frame of
// epoch j (each epoch's position error is in its own NED frame).
//
// Self-calibration columns (layout.hpp; the conventions of pseudorange.hpp).
// A TDCP row is the difference of two epochs' ranges, so each of its
// self-calibration columns is the difference of the two epochs' columns of
// the range.  Lever arm, dl_b = l_b^ - l_b:
//   H_k += -u_k^T C_nb,k,   H_{k-1} += +u_{k-1}^T C_nb,k-1
// Time offset, dt_d = t_d^ - t_d (the true antenna of epoch j is the INS at
// t_j - shift_j + dt_d, d r_ant = -v_ant dt_d; pseudorange.hpp):
//   H_k += +u_k^T v_ant,k,  H_{k-1} += -u_{k-1}^T v_ant,k-1
// i.e. minus the change of the receiver's range rate over the epoch interval
// (the receiver's range acceleration times the interval): on a walk, whose
// steps change the velocity by ~0.5 m/s within 0.25 s, a 50 ms offset makes
// ~2.5 cm of TDCP residual.  The clone carries its own dt_d (a random walk of
// the current one).  An antenna evaluated shift_j [s] after the epoch's
// applied time (the engines: the INS state's time less record_time) is moved
// back along v_ant (first order, as pseudorange.hpp's shifted prediction).
//
// Stochastic cloning: after the update of epoch k-1 and its feedback the
// whole error state is cloned, x_c = x_{k-1} (mean 0, covariance P_{k-1}).
// The clone does not move, so over the filter cycle to epoch k its cross-
// covariance with the propagated state is cov(x_k, x_c) = Phi P_{k-1} (Phi:
// the cycle's transition).  The update of x_k alone (the clone is dropped
// after it) with the augmented H = [H_k, H_{k-1}]:
//   A = P_k H_k^T + Phi P_{k-1} H_{k-1}^T                 (cov(x_k, z))
//   B = (Phi P_{k-1})^T H_k^T + P_{k-1} H_{k-1}^T          (cov(x_c, z))
//   S = H_k A + H_{k-1} B + R,  K = A S^-1
//   x_k += K (y - H_k x_k),  P_k -= K A^T
// which is the clone-augmented Kalman update (Roumeliotis & Burdick 2002,
// sec. III) marginalised to x_k.  R_ii = sigma_k^2 + sigma_{k-1}^2 (the
// zero-difference phase sigmas of the two epochs); the correlation of
// consecutive TDCP rows through their common epoch (-1/2) is not modelled.
//
// Fixed-size storage (kMaxMeasRows rows), no heap allocation.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Cholesky>

#include "insnav/earth/wgs84.hpp"
#include "insnav/filter/types.hpp"
#include "insnav/math/rotation.hpp"

namespace insnav {

/// Carrier phase of one satellite row (parallel to the epoch's SatObservation rows).
struct PhaseObservation {
  double phase_m = NAN;       ///< lambda times the carrier phase [m]; NaN: no phase
  double wavelength_m = NAN;  ///< carrier wavelength [m]
  double sigma_m = 0.01;      ///< zero-difference 1-sigma of phase_m [m]
  int lli = 0;                ///< RINEX loss-of-lock indicator (bit 0: lost lock / possible slip)
};

/// TDCP options of the tight engine (TightConfig::tdcp).
struct TdcpConfig {
  bool enabled = false;
  /// INS-aided slip test: a row whose residual, less the epoch's common part
  /// (median over >= 3 rows: the receiver clock), exceeds this many cycles is a slip.
  double slip_threshold_cycles = 0.5;
  /// Per-row chi-square: rejected when y_i^2 > chi2_row S_ii (1 dof; 10.83 = 1 - 1e-3).
  double chi2_row = 10.83;
};

/// What became of one satellite's TDCP row (TightOutputs::tdcp_flag).
enum class TdcpFlag : std::int8_t {
  kAbsent = -1,   ///< no phase at this or the previous epoch (or the previous epoch not chained)
  kUsed = 0,      ///< in the update
  kSlipLli = 1,   ///< loss-of-lock indicator set: arc restarted
  kSlipIns = 2,   ///< INS-predicted phase change test: slip
  kRejected = 3,  ///< per-row chi-square
};

/// The antenna of one epoch as the TDCP row needs it.
struct TdcpAntenna {
  Vec3 r_e = Vec3::Zero();      ///< antenna ECEF position at the epoch's applied time [m]
  Mat3 C_en = Mat3::Identity(); ///< NED -> ECEF at the INS position
  Mat3 C_nb = Mat3::Identity(); ///< body -> NED (the lever-arm columns)
  Vec3 l_n = Vec3::Zero();      ///< lever arm C_nb l_b in NED [m]
  Vec3 v_ant_n = Vec3::Zero();  ///< antenna velocity in NED [m/s] (the time-offset column)
  double clock_bias_m = 0.0;    ///< receiver clock bias estimate [m]
};

/// The antenna of the INS state s with lever arm l_b [m], clock bias [m],
/// corrected angular rate omega_ib_b [rad/s] (the lever arm's velocity), and
/// shift_s [s]: how far the state's time is past the epoch's applied time
/// (the antenna is moved back by v_ant shift_s; header).
inline TdcpAntenna tdcp_antenna(const NavState& s, const Vec3& lever_arm_b, double clock_bias_m,
                                const Vec3& omega_ib_b = Vec3::Zero(), double shift_s = 0.0) {
  TdcpAntenna a;
  a.C_en = wgs84::C_en(s.lat, s.lon);
  a.C_nb = s.q_nb.toRotationMatrix();
  a.l_n = a.C_nb * lever_arm_b;
  const wgs84::Radii r = wgs84::radii(s.lat);
  const Vec3 omega_in_n = wgs84::omega_ie_n(s.lat) + wgs84::omega_en_n(s.lat, s.h, s.v_n, r);
  a.v_ant_n = s.v_n + a.C_nb * omega_ib_b.cross(lever_arm_b) - omega_in_n.cross(a.l_n);
  a.r_e = wgs84::geodetic_to_ecef(s.lat, s.lon, s.h) + a.C_en * (a.l_n - a.v_ant_n * shift_s);
  a.clock_bias_m = clock_bias_m;
  return a;
}

/// One satellite at one epoch: position at transmission in the ECEF frame at
/// reception [m] and c dt_sv (less modelled delays) [m] (SatObservation's r_e, clock_bias_m).
struct TdcpSatEpoch {
  Vec3 r_e = Vec3::Zero();
  double clock_bias_m = 0.0;
};

/// The row of one satellite: INS-predicted phase change [m] and its Jacobians.
template <class L>
struct TdcpRow {
  using RowVec = Eigen::Matrix<double, 1, L::kSize>;
  double predicted = 0.0;
  RowVec H_cur = RowVec::Zero(), H_prev = RowVec::Zero();
  double sin_el = 1.0;  ///< sine of the elevation at the current epoch
};

/// predicted dPhi and H_k, H_{k-1} of one satellite (header equations).
template <class L>
TdcpRow<L> tdcp_row(const TdcpAntenna& prev, const TdcpAntenna& cur, const TdcpSatEpoch& sat_prev,
                    const TdcpSatEpoch& sat_cur) {
  static_assert(kHasClock<L>, "TDCP rows need a layout with clock states");
  TdcpRow<L> r;
  const Vec3 d_cur = sat_cur.r_e - cur.r_e, d_prev = sat_prev.r_e - prev.r_e;
  const double rho_cur = d_cur.norm(), rho_prev = d_prev.norm();
  const Vec3 u_cur = cur.C_en.transpose() * (d_cur / rho_cur);
  const Vec3 u_prev = prev.C_en.transpose() * (d_prev / rho_prev);
  r.predicted = (rho_cur - rho_prev) + (cur.clock_bias_m - prev.clock_bias_m) -
                (sat_cur.clock_bias_m - sat_prev.clock_bias_m);
  r.H_cur.template segment<3>(L::kPos) = -u_cur.transpose();
  r.H_prev.template segment<3>(L::kPos) = u_prev.transpose();
  r.H_cur.template segment<3>(L::kAtt) = -u_cur.transpose() * skew(cur.l_n);
  r.H_prev.template segment<3>(L::kAtt) = u_prev.transpose() * skew(prev.l_n);
  r.H_cur[L::kClockBias] = 1.0;
  r.H_prev[L::kClockBias] = -1.0;
  if constexpr (kHasLeverArm<L>) {
    constexpr int kLever = LeverArmState<L>::offset;
    r.H_cur.template segment<3>(kLever) = -u_cur.transpose() * cur.C_nb;
    r.H_prev.template segment<3>(kLever) = u_prev.transpose() * prev.C_nb;
  }
  if constexpr (kHasTimeOffset<L>) {
    constexpr int kTd = TimeOffsetState<L>::offset;
    r.H_cur[kTd] = u_cur.dot(cur.v_ant_n);
    r.H_prev[kTd] = -u_prev.dot(prev.v_ant_n);
  }
  r.sin_el = -u_cur.z();
  return r;
}

/// Rows of one epoch and the stochastic-cloning update (header).  Fixed
/// storage for kMaxMeasRows rows.
template <class L>
class TdcpUpdate {
 public:
  static constexpr int N = L::kSize;
  using HMat = Eigen::Matrix<double, Eigen::Dynamic, N, Eigen::RowMajor, kMaxMeasRows, N>;
  using Vm = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxMeasRows, 1>;
  using Sm = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  using NM = Eigen::Matrix<double, N, Eigen::Dynamic, 0, N, kMaxMeasRows>;

  void clear() { m_ = 0; }
  int rows() const { return m_; }
  bool full() const { return m_ >= kMaxMeasRows; }

  /// Add a row: residual y = predicted - measured [m], variance r [m^2].
  void add(const TdcpRow<L>& row, double residual_m, double variance_m2) {
    H_cur_.row(m_) = row.H_cur;  // storage is kMaxMeasRows rows; rows() counts the used ones
    H_prev_.row(m_) = row.H_prev;
    y_[m_] = residual_m;
    r_[m_] = variance_m2;
    ++m_;
  }

  /// Keep only the rows with keep[i] (in order).
  void select(const bool* keep) {
    int k = 0;
    for (int i = 0; i < m_; ++i) {
      if (!keep[i]) continue;
      if (k != i) {
        H_cur_.row(k) = H_cur_.row(i);
        H_prev_.row(k) = H_prev_.row(i);
        y_[k] = y_[i];
        r_[k] = r_[i];
      }
      ++k;
    }
    m_ = k;
  }

  /// Innovation covariance of the rows under the clone-augmented covariance
  /// [[P, Phi P_prev], [(Phi P_prev)^T, P_prev]]; fills A, B, S.  False when S
  /// is not positive definite.
  bool covariance(const StateCov<L>& P, const StateCov<L>& Phi_P_prev, const StateCov<L>& P_prev) {
    const int m = m_;
    if (m == 0) return false;
    const auto Hc = H_cur_.topRows(m);
    const auto Hp = H_prev_.topRows(m);
    A_.resize(N, m);
    B_.resize(N, m);
    A_.noalias() = P * Hc.transpose();
    A_.noalias() += Phi_P_prev * Hp.transpose();
    B_.noalias() = Phi_P_prev.transpose() * Hc.transpose();
    B_.noalias() += P_prev * Hp.transpose();
    S_.resize(m, m);
    S_.noalias() = Hc * A_;
    S_.noalias() += Hp * B_;
    S_ = (0.5 * (S_ + S_.transpose())).eval();
    for (int i = 0; i < m; ++i) S_(i, i) += r_[i];
    llt_.compute(S_);
    return llt_.info() == Eigen::Success;
  }

  /// Predicted innovation variance S_ii of row i (after covariance()).
  double S(int i) const { return S_(i, i); }
  double residual(int i) const { return y_[i]; }

  /// The clone's side of the update (the RTS smoother, ClosedLoop::clone_update_for_smoother):
  /// the correction of the previous epoch's error B S^-1 v (v = y - H_k x), the reduction of
  /// its covariance B S^-1 B^T and of cov(x_c, x_k), B S^-1 A^T.  After covariance(), before
  /// apply() (x: the state apply() will update).  No heap allocation.
  void clone_terms(const StateVec<L>& x, StateVec<L>& dx_c, StateCov<L>& dP_c, StateCov<L>& dC) {
    const int m = m_;
    Vm v = y_.head(m);
    v.noalias() -= H_cur_.topRows(m) * x;
    const Vm Sv = llt_.solve(v);
    dx_c.noalias() = B_ * Sv;
    K_T_ = llt_.solve(B_.transpose());  // S^-1 B^T (m x N); apply() refills it
    dP_c.noalias() = B_ * K_T_;
    dP_c = (0.5 * (dP_c + dP_c.transpose())).eval();
    dC.noalias() = K_T_.transpose() * A_.transpose();
  }

  /// x += K (y - H_k x), P -= K A^T, with the S of the last covariance()
  /// (the clone's mean is zero: fed back).  Returns the NIS.
  double apply(StateVec<L>& x, StateCov<L>& P) {
    const int m = m_;
    Vm v = y_.head(m);
    v.noalias() -= H_cur_.topRows(m) * x;
    const Vm Sv = llt_.solve(v);
    K_T_ = llt_.solve(A_.transpose());  // K^T = S^-1 A^T (m x N)
    x.noalias() += A_ * Sv;
    P.noalias() -= K_T_.transpose() * A_.transpose();
    P = (0.5 * (P + P.transpose())).eval();
    return v.dot(Sv);
  }

 private:
  int m_ = 0;
  HMat H_cur_ = HMat::Zero(kMaxMeasRows, N), H_prev_ = HMat::Zero(kMaxMeasRows, N);
  Vm y_ = Vm::Zero(kMaxMeasRows), r_ = Vm::Zero(kMaxMeasRows);
  NM A_, B_;
  Sm S_;
  Eigen::Matrix<double, Eigen::Dynamic, N, Eigen::RowMajor, kMaxMeasRows, N> K_T_;
  Eigen::LLT<Sm> llt_{kMaxMeasRows};
};

}  // namespace insnav
