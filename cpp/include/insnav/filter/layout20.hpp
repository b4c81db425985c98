// insnav/filter/layout20.hpp -- the 20-state layout of seed 004 (Shao et al.
// 2013, eq. (25)) and its error model, built on the generic models of
// error_model_linear.hpp / error_model_nonlinear.hpp without changing them.
//
// seed 004 eq. (25) orders the states (ENU)
//   [phi_E phi_N phi_U  dv_E dv_N dv_U  dL dlambda dh  eps_b(3)  eps_r(3)  nabla(3)  dt_u  dt_ru]
// insnav works in NED with error = computed - true (layout.hpp), so the same
// 20 quantities are kept here as
//   [dr_NED(3)  dv_NED(3)  psi(3)  acc Markov(3)  gyro random constant(3)
//    gyro first-order Markov(3)  clock bias b [m]  clock drift d [m/s]]
// (the paper's East/North/Up attitude, velocity and position errors are our
// N/E/-D components; its "equivalent range/velocity errors of the clock" are
// the clock states of Layout17).
//
// Sensor error model (seed 004: gyro = random constant + first-order Markov,
// accelerometer = first-order Markov; white noise in Q):
//   dw_b = eps_b + eps_r,   eps_b' = 0,   eps_r' = -eps_r / tau_g + w_g
//   df_b = nabla,           nabla' = -nabla / tau_a + w_a
// The Markov blocks take sigma, tau and the extra random walk from
// ImuErrorModel's gyro_bias_* / acc_bias_* fields (so no new fields in
// types.hpp); the random-constant block has no driving noise and its initial
// sigma comes only from P0.
//
// Closed loop: the engines feed back L::kAccBias, L::kGyroBias (here the
// random constant) and the clock into the INS; the gyro Markov block is NOT
// fed back -- it stays in the filter as an estimated, decaying error of the
// corrected IMU (a Markov error fed into a constant IMU correction would stop
// decaying).  kFedBack<Layout20>(i) says which states reset_state() zeroes.
//
// How the generic models are reused: `Layout20Core` is the same 20-vector with
// kGyroBias pointing at the Markov block, so linear_F / continuous_GQG /
// nonlinear_error_rate<Layout20Core> produce everything except the coupling of
// the random-constant block; the explicit specialisations below for Layout20
// add it (F(att, eps_b) = -C_nb; the total dw_b = eps_b + eps_r in the exact
// model).  StateVec<Layout20> and StateVec<Layout20Core> are the same type.
#pragma once

#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/error_model_nonlinear.hpp"
#include "insnav/filter/layout.hpp"

namespace insnav {

/// seed 004 tight: 20 states (see the header comment for the ENU -> NED mapping).
struct Layout20 {
  static constexpr int kSize = 20;
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAtt = 6;
  static constexpr int kAccBias = 9;      // accelerometer first-order Markov (nabla)
  static constexpr int kGyroBias = 12;    // gyro random constant (eps_b)
  static constexpr int kGyroMarkov = 15;  // gyro first-order Markov (eps_r)
  static constexpr int kAccScale = -1;
  static constexpr int kGyroScale = -1;
  static constexpr int kClockBias = 18;
  static constexpr int kClockDrift = 19;
};

/// Internal: Layout20 with kGyroBias on the Markov block (see the header comment).
struct Layout20Core {
  static constexpr int kSize = 20;
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAtt = 6;
  static constexpr int kAccBias = 9;
  static constexpr int kGyroBias = 15;  // the Markov block
  static constexpr int kGyroConst = 12;
  static constexpr int kAccScale = -1;
  static constexpr int kGyroScale = -1;
  static constexpr int kClockBias = 18;
  static constexpr int kClockDrift = 19;
};

template <class L>
inline constexpr bool kHasGyroMarkov = false;
template <>
inline constexpr bool kHasGyroMarkov<Layout20> = true;

/// True for the states an engine's feedback zeroes (closed loop); false for a
/// state the filter keeps across reset_state() (Layout20's gyro Markov block).
template <class L>
constexpr bool kFedBack(int i) {
  if constexpr (kHasGyroMarkov<L>) return !(i >= L::kGyroMarkov && i < L::kGyroMarkov + 3);
  else return (void)i, true;
}

/// Zero the fed-back states of dx (what reset_state() does after feedback).
template <class L>
inline void zero_fed_back(StateVec<L>& dx) {
  for (int i = 0; i < L::kSize; ++i)
    if (kFedBack<L>(i)) dx[i] = 0.0;
}

/// Subtract the fed-back part of `shift` from dx (a particle after feedback of
/// the weighted mean, upf.hpp / particle_filter.hpp).
template <class L>
inline void subtract_fed_back(StateVec<L>& dx, const StateVec<L>& shift) {
  for (int i = 0; i < L::kSize; ++i)
    if (kFedBack<L>(i)) dx[i] -= shift[i];
}

// --- the error model of Layout20 (explicit specialisations) --------------------

/// Exact IMU errors: dw_b = eps_b + eps_r, df_b = nabla.
template <>
inline void imu_errors_from_state<Layout20Core>(const StateVec<Layout20Core>& dx, const Vec3& /*f_b*/,
                                                const Vec3& /*omega_b*/, Vec3& df_b, Vec3& dw_b) {
  df_b = dx.segment<3>(Layout20Core::kAccBias);
  dw_b = dx.segment<3>(Layout20Core::kGyroBias) + dx.segment<3>(Layout20Core::kGyroConst);
}

template <>
inline void imu_errors_from_state<Layout20>(const StateVec<Layout20>& dx, const Vec3& f_b, const Vec3& omega_b,
                                            Vec3& df_b, Vec3& dw_b) {
  imu_errors_from_state<Layout20Core>(dx, f_b, omega_b, df_b, dw_b);
}

/// F of seed 004 eq. (24) in our frame: the generic F with the Markov gyro
/// block, plus psi' = ... - C_nb eps_b (eps_b' = 0).
template <>
inline StateCov<Layout20> linear_F<Layout20>(const InsPoint& ins, const ImuErrorModel& m) {
  StateCov<Layout20> F = linear_F<Layout20Core>(ins, m);
  F.block<3, 3>(Layout20::kAtt, Layout20::kGyroBias) = -ins.C_nb;
  return F;
}

/// G q G^T: the random-constant block has no driving noise.
template <>
inline StateCov<Layout20> continuous_GQG<Layout20>(const InsPoint& ins, const ImuErrorModel& m) {
  return continuous_GQG<Layout20Core>(ins, m);
}

/// Exact error-state derivative (seed 000 eqs. (3)-(7) with dw_b = eps_b + eps_r).
template <>
inline StateVec<Layout20> nonlinear_error_rate<Layout20>(const StateVec<Layout20>& dx,
                                                         const NonlinearErrorPoint& pt) {
  StateVec<Layout20> rate = nonlinear_error_rate<Layout20Core>(dx, pt);
  rate.segment<3>(Layout20::kGyroBias).setZero();  // random constant
  return rate;
}

}  // namespace insnav
