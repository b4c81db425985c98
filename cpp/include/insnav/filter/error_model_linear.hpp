// insnav/filter/error_model_linear.hpp -- the linear (small-angle) INS error
// model used by the EKF: continuous F, discrete transition and process noise.
//
// Psi-angle (phi-angle) error model in NED with the position error in NED
// metres, error = computed - true (see layout.hpp):
//   dr'   = -[omega_en x] dr + (terms of dr through the radii) + dv
//   dv'   = [f_n x] psi + C_nb df_b - (2 omega_ie + omega_en) x dv
//           + (velocity/position coupling through the Coriolis, transport and
//              gravity terms, incl. + 2 g / R dr_D)
//   psi'  = -[omega_in x] psi + d omega_in(dr, dv) - C_nb dw_b
//   b'    = -b / tau + w                           (first-order Gauss-Markov)
// E.-H. Shin, "Estimation techniques for low-cost inertial navigation",
// UCGE 20219, 2005, eqs. (2.55)-(2.68); Groves (2013) sec. 14.2.4.
// seed 003 prints the same model (its eq. for dV and phi) in a local-level
// geodetic form.
#pragma once

#include <cmath>

#include "insnav/filter/types.hpp"

namespace insnav {

/// Continuous-time system matrix F at one INS point.
template <class L>
StateCov<L> linear_F(const InsPoint& ins, const ImuErrorModel& m) {
  StateCov<L> F = StateCov<L>::Zero();
  const double lat = ins.lat, h = ins.h;
  const Vec3& v = ins.v_n;
  const double RMh = ins.earth.radii.R_M + h, RNh = ins.earth.radii.R_N + h;
  const double sL = ins.earth.sin_lat, cL = ins.earth.cos_lat, tL = sL / cL;
  const double W = wgs84::kOmegaIe, g = ins.earth.g;
  const Vec3 f_n = ins.C_nb * ins.f_ib_b;
  const Vec3 omega_in_n = ins.earth.omega_ie_n + ins.earth.omega_en_n;
  constexpr int P = L::kPos, V = L::kVel, A = L::kAtt, BA = L::kAccBias, BG = L::kGyroBias;
  (void)lat;

  Mat3 T = Mat3::Zero();
  // position rows
  T(0, 0) = -v.z() / RMh;
  T(0, 2) = v.x() / RMh;
  T(1, 0) = v.y() * tL / RNh;
  T(1, 1) = -(v.z() + v.x() * tL) / RNh;
  T(1, 2) = v.y() / RNh;
  F.template block<3, 3>(P, P) = T;
  F.template block<3, 3>(P, V) = Mat3::Identity();

  // velocity rows
  T.setZero();
  T(0, 0) = -2.0 * v.y() * W * cL / RMh - v.y() * v.y() / (RMh * RNh * cL * cL);
  T(0, 2) = v.x() * v.z() / (RMh * RMh) - v.y() * v.y() * tL / (RNh * RNh);
  T(1, 0) = 2.0 * W * (v.x() * cL - v.z() * sL) / RMh + v.x() * v.y() / (RMh * RNh * cL * cL);
  T(1, 2) = (v.y() * v.z() + v.x() * v.y() * tL) / (RNh * RNh);
  T(2, 0) = 2.0 * W * v.y() * sL / RMh;
  T(2, 2) = -v.y() * v.y() / (RNh * RNh) - v.x() * v.x() / (RMh * RMh) +
            2.0 * g / (std::sqrt(ins.earth.radii.R_M * ins.earth.radii.R_N) + h);
  F.template block<3, 3>(V, P) = T;
  T.setZero();
  T(0, 0) = v.z() / RMh;
  T(0, 1) = -2.0 * (W * sL + v.y() * tL / RNh);
  T(0, 2) = v.x() / RMh;
  T(1, 0) = 2.0 * W * sL + v.y() * tL / RNh;
  T(1, 1) = (v.z() + v.x() * tL) / RNh;
  T(1, 2) = 2.0 * W * cL + v.y() / RNh;
  T(2, 0) = -2.0 * v.x() / RMh;
  T(2, 1) = -2.0 * (W * cL + v.y() / RNh);
  F.template block<3, 3>(V, V) = T;
  F.template block<3, 3>(V, A) = skew(f_n);
  F.template block<3, 3>(V, BA) = ins.C_nb;

  // attitude rows
  T.setZero();
  T(0, 0) = -W * sL / RMh;
  T(0, 2) = v.y() / (RNh * RNh);
  T(1, 2) = -v.x() / (RMh * RMh);
  T(2, 0) = -W * cL / RMh - v.y() / (RMh * RNh * cL * cL);
  T(2, 2) = -v.y() * tL / (RNh * RNh);
  F.template block<3, 3>(A, P) = T;
  T.setZero();
  T(0, 1) = 1.0 / RNh;
  T(1, 0) = -1.0 / RMh;
  T(2, 1) = -tL / RNh;
  F.template block<3, 3>(A, V) = T;
  F.template block<3, 3>(A, A) = -skew(omega_in_n);
  F.template block<3, 3>(A, BG) = -ins.C_nb;

  // sensor error states: first-order Gauss-Markov (tau = inf: random constant/walk)
  for (int i = 0; i < 3; ++i) {
    F(BA + i, BA + i) = std::isfinite(m.acc_bias_tau[i]) ? -1.0 / m.acc_bias_tau[i] : 0.0;
    F(BG + i, BG + i) = std::isfinite(m.gyro_bias_tau[i]) ? -1.0 / m.gyro_bias_tau[i] : 0.0;
  }
  if constexpr (kHasScale<L>) {
    constexpr int SA = L::kAccScale, SG = L::kGyroScale;
    F.template block<3, 3>(V, SA) = ins.C_nb * ins.f_ib_b.asDiagonal();
    F.template block<3, 3>(A, SG) = -ins.C_nb * ins.omega_ib_b.asDiagonal();
    for (int i = 0; i < 3; ++i) {
      F(SA + i, SA + i) = std::isfinite(m.acc_scale_tau[i]) ? -1.0 / m.acc_scale_tau[i] : 0.0;
      F(SG + i, SG + i) = std::isfinite(m.gyro_scale_tau[i]) ? -1.0 / m.gyro_scale_tau[i] : 0.0;
    }
  }
  if constexpr (kHasClock<L>) {
    F(L::kClockBias, L::kClockDrift) = 1.0;  // bias' = drift
  }
  return F;
}

/// Driving-noise PSD of a first-order Gauss-Markov state with steady-state
/// sigma s and correlation time tau (2 s^2 / tau), plus a random-walk PSD.
inline double markov_psd(double sigma, double tau, double rw) {
  return (std::isfinite(tau) && tau > 0.0 ? 2.0 * sigma * sigma / tau : 0.0) + rw * rw;
}

/// Continuous process-noise covariance G q G^T (already in state axes).
template <class L>
StateCov<L> continuous_GQG(const InsPoint& ins, const ImuErrorModel& m) {
  StateCov<L> Qc = StateCov<L>::Zero();
  const Mat3& C = ins.C_nb;
  Qc.template block<3, 3>(L::kVel, L::kVel) = C * m.acc_vrw.cwiseAbs2().asDiagonal() * C.transpose();
  Qc.template block<3, 3>(L::kAtt, L::kAtt) = C * m.gyro_arw.cwiseAbs2().asDiagonal() * C.transpose();
  for (int i = 0; i < 3; ++i) {
    Qc(L::kAccBias + i, L::kAccBias + i) = markov_psd(m.acc_bias_sigma[i], m.acc_bias_tau[i], m.acc_bias_rw[i]);
    Qc(L::kGyroBias + i, L::kGyroBias + i) = markov_psd(m.gyro_bias_sigma[i], m.gyro_bias_tau[i], m.gyro_bias_rw[i]);
  }
  if constexpr (kHasScale<L>) {
    for (int i = 0; i < 3; ++i) {
      Qc(L::kAccScale + i, L::kAccScale + i) = markov_psd(m.acc_scale_sigma[i], m.acc_scale_tau[i], 0.0);
      Qc(L::kGyroScale + i, L::kGyroScale + i) = markov_psd(m.gyro_scale_sigma[i], m.gyro_scale_tau[i], 0.0);
    }
  }
  if constexpr (kHasClock<L>) {
    Qc(L::kClockBias, L::kClockBias) = m.clock_bias_psd;
    Qc(L::kClockDrift, L::kClockDrift) = m.clock_drift_psd;
  }
  return Qc;
}

/// Second-order transition matrix Phi = I + F dt + (F dt)^2 / 2.
template <class L>
StateCov<L> transition(const StateCov<L>& F, double dt) {
  const StateCov<L> Fdt = F * dt;
  return StateCov<L>::Identity() + Fdt + 0.5 * Fdt * Fdt;
}

/// Discrete process noise by the trapezoidal rule,
/// Q_d = (Phi Qc Phi^T + Qc) dt / 2  (Shin 2005, eq. (2.72)).
template <class L>
StateCov<L> discrete_Q(const StateCov<L>& Phi, const StateCov<L>& Qc, double dt) {
  return 0.5 * dt * (Phi * Qc * Phi.transpose() + Qc);
}

/// Convenience: discrete Q at one INS point over dt.
template <class L>
StateCov<L> discrete_Q(const InsPoint& ins, const ImuErrorModel& m, double dt) {
  return discrete_Q<L>(transition<L>(linear_F<L>(ins, m), dt), continuous_GQG<L>(ins, m), dt);
}

}  // namespace insnav
