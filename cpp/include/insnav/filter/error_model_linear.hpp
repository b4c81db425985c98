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
//   s_odo' = -s_odo / tau_odo + w                  (Layout16Odo: odometer scale factor,
//                                                   no coupling into dr, dv, psi)
//   dt_d' = w, dl_b' = w                           (time offset, lever arm: random walks,
//                                                   no coupling; layout.hpp)
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
  if constexpr (kHasOdoScale<L>) {  // s_odo' = -s_odo / tau (no coupling into the navigation errors)
    constexpr int O = OdoScaleState<L>::offset;
    F(O, O) = std::isfinite(m.odo_scale_tau) ? -1.0 / m.odo_scale_tau : 0.0;
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
  if constexpr (kHasOdoScale<L>) {
    constexpr int O = OdoScaleState<L>::offset;
    Qc(O, O) = markov_psd(m.odo_scale_sigma, m.odo_scale_tau, 0.0);
  }
  if constexpr (kHasClock<L>) {
    Qc(L::kClockBias, L::kClockBias) = m.clock_bias_psd;
    Qc(L::kClockDrift, L::kClockDrift) = m.clock_drift_psd;
  }
  if constexpr (kHasTimeOffset<L>) {  // time offset: random walk (F row zero; layout.hpp)
    Qc(TimeOffsetState<L>::offset, TimeOffsetState<L>::offset) = m.time_offset_psd;
  }
  if constexpr (kHasLeverArm<L>) {  // lever arm: random walk (F rows zero)
    for (int i = 0; i < 3; ++i) Qc(LeverArmState<L>::offset + i, LeverArmState<L>::offset + i) = m.lever_arm_psd;
  }
  if constexpr (kHasOdoLever<L>) {  // odometer lever arm: random walk (F rows zero)
    for (int i = 0; i < 3; ++i) Qc(OdoLeverState<L>::offset + i, OdoLeverState<L>::offset + i) = m.lever_arm_psd;
  }
  if constexpr (kHasIsb<L>) {  // inter-system biases: random walk (F rows zero)
    for (int i = 0; i < IsbStates<L>::count; ++i) Qc(IsbStates<L>::offset + i, IsbStates<L>::offset + i) = m.isb_psd;
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

// --- block-structured time update (the EKF's hot path) ----------------------
//
// In the layouts whose sensor-error states have their own diagonal dynamics
// (first-order Gauss-Markov biases and scale factors, no clock: Layout15,
// Layout21, Layout16Odo) F and Qc have the block form, nav = the first 9 states (dr, dv,
// psi), aux = the sensor-error states:
//   F  = [F_nn  F_na     ]      Qc = [Q_nn  0        ]
//        [0     diag(f_a)],          [0     diag(q_a)]
// and Phi = I + F dt + (F dt)^2 / 2 = [U; 0 diag(d)] keeps it, with U the 9
// nav rows of Phi (9 x n).  Phi M Phi^T then needs 9 n (n + 9) + O(n^2)
// multiplications instead of 2 n^3 (n = 21: 5.7k instead of 18.5k), and the
// trapezoidal Q_d (Shin 2005, eq. (2.72)) folds into the same congruence:
//   Phi P Phi^T + (Phi Qc Phi^T + Qc) dt/2 = Phi (P + Qc dt/2) Phi^T + Qc dt/2.
// A layout opts in through kDiagonalAuxDynamics; any other layout (clock
// states, Layout20's specialisations) keeps the dense products.
template <class L>
inline constexpr bool kDiagonalAuxDynamics = false;
template <>
inline constexpr bool kDiagonalAuxDynamics<Layout15> = true;
template <>
inline constexpr bool kDiagonalAuxDynamics<Layout21> = true;
template <>
inline constexpr bool kDiagonalAuxDynamics<Layout16Odo> = true;
template <>
inline constexpr bool kDiagonalAuxDynamics<Layout16Td> = true;
template <>
inline constexpr bool kDiagonalAuxDynamics<Layout18Lever> = true;
template <>
inline constexpr bool kDiagonalAuxDynamics<Layout19TdLever> = true;
template <>
inline constexpr bool kDiagonalAuxDynamics<Layout18OdoLever> = true;

/// Phi = [U; 0 diag(d)] of a layout with kDiagonalAuxDynamics.
template <class L>
struct NavAuxTransition {
  static constexpr int kNav = 9;                 // dr, dv, psi
  static constexpr int kAux = L::kSize - kNav;   // sensor errors
  static_assert(L::kPos == 0 && L::kVel == 3 && L::kAtt == 6, "nav states first");
  Eigen::Matrix<double, kNav, L::kSize> U = Eigen::Matrix<double, kNav, L::kSize>::Zero();  // nav rows of Phi
  Eigen::Matrix<double, kAux, 1> d = Eigen::Matrix<double, kAux, 1>::Ones();                // aux diagonal of Phi
};

/// Second-order Phi = I + F dt + (F dt)^2 / 2 in block form (F as linear_F
/// builds it; its aux rows must be diagonal, see kDiagonalAuxDynamics):
///   U = [I 0] + G + G_nn G / 2 + [0, G_na diag(a) / 2],  d = 1 + a + a^2 / 2,
/// with G = F_nav,: dt and a = diag(F_aa) dt.
template <class L>
void block_transition(const StateCov<L>& F, double dt, NavAuxTransition<L>& phi) {
  constexpr int N = NavAuxTransition<L>::kNav, K = NavAuxTransition<L>::kAux, n = L::kSize;
  using VecN = Eigen::Matrix<double, N, 1>;
  const Eigen::Matrix<double, N, n> G = F.template topRows<N>() * dt;
  const Eigen::Matrix<double, K, 1> a = F.template bottomRightCorner<K, K>().diagonal() * dt;
  const Eigen::Matrix<double, N, N> G_nn_half = 0.5 * G.template leftCols<N>();
  // column by column (axpys over the 9 nav rows; Eigen's product kernels are
  // slower at these sizes)
  for (int k = 0; k < n; ++k) {
    VecN u = G.col(k);
    for (int j = 0; j < N; ++j) u += G_nn_half.col(j) * G(j, k);
    if (k >= N) u += (0.5 * a[k - N]) * G.col(k);
    phi.U.col(k) = u;
  }
  phi.U.template leftCols<N>().diagonal().array() += 1.0;
  phi.d = (1.0 + a.array() + 0.5 * a.array().square()).matrix();
}

/// M = Phi M Phi^T in place for a symmetric M, Phi = [U; 0 diag(d)]:
///   W^T = M U^T (n x 9),  M_nn = U W^T,  M_an = diag(d) W^T_a,  M_aa,ij = d_i d_j M_aa,ij.
/// The aux rows and columns come out exactly symmetric, M_nn up to round-off.
template <class L>
void block_congruence(const NavAuxTransition<L>& phi, StateCov<L>& M) {
  constexpr int N = NavAuxTransition<L>::kNav, K = NavAuxTransition<L>::kAux, n = L::kSize;
  // column by column: axpys over the n rows of M vectorise; Eigen's product
  // kernels are slower at these sizes (packing, odd row counts)
  Eigen::Matrix<double, n, N> Wt;
  for (int i = 0; i < N; ++i) {
    StateVec<L> w = M.col(0) * phi.U(i, 0);
    for (int k = 1; k < n; ++k) w += M.col(k) * phi.U(i, k);
    Wt.col(i) = w;
  }
  for (int j = 0; j < K; ++j)
    for (int i = j; i < K; ++i) {
      const double v = (phi.d[i] * phi.d[j]) * M(N + i, N + j);
      M(N + i, N + j) = v;
      M(N + j, N + i) = v;
    }
  M.template bottomLeftCorner<K, N>() = phi.d.asDiagonal() * Wt.template bottomRows<K>();
  M.template topRightCorner<N, K>() = M.template bottomLeftCorner<K, N>().transpose();
  for (int j = 0; j < N; ++j) {
    Eigen::Matrix<double, N, 1> c = phi.U.col(0) * Wt(0, j);
    for (int k = 1; k < n; ++k) c += phi.U.col(k) * Wt(k, j);
    M.col(j).template head<N>() = c;
  }
}

/// The EKF time update P = Phi P Phi^T + (Phi Qc Phi^T + Qc) dt/2 as one
/// congruence, P = Phi (P + Qc dt/2) Phi^T + Qc dt/2, for a layout with
/// kDiagonalAuxDynamics (Qc = [Q_nn 0; 0 diag(q_a)]).  P stays exactly symmetric.
template <class L>
void block_propagate_covariance(const NavAuxTransition<L>& phi, const StateCov<L>& Qc, double dt,
                                StateCov<L>& P) {
  constexpr int N = NavAuxTransition<L>::kNav, K = NavAuxTransition<L>::kAux;
  const double half_dt = 0.5 * dt;
  const Eigen::Matrix<double, N, N> hQ_nn = half_dt * Qc.template topLeftCorner<N, N>();
  const Eigen::Matrix<double, K, 1> hq_a = half_dt * Qc.template bottomRightCorner<K, K>().diagonal();
  P.template topLeftCorner<N, N>() += hQ_nn;
  P.template bottomRightCorner<K, K>().diagonal() += hq_a;
  block_congruence<L>(phi, P);
  P.template topLeftCorner<N, N>() += hQ_nn;
  P.template bottomRightCorner<K, K>().diagonal() += hq_a;
  for (int j = 0; j < N; ++j)  // symmetrise the nav block (the rest is symmetric by construction)
    for (int i = j + 1; i < N; ++i) {
      const double v = 0.5 * (P(i, j) + P(j, i));
      P(i, j) = v;
      P(j, i) = v;
    }
}

/// Convenience: discrete Q at one INS point over dt.
template <class L>
StateCov<L> discrete_Q(const InsPoint& ins, const ImuErrorModel& m, double dt) {
  return discrete_Q<L>(transition<L>(linear_F<L>(ins, m), dt), continuous_GQG<L>(ins, m), dt);
}

}  // namespace insnav
