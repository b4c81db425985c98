// insnav/filter/layout.hpp -- error-state layouts as types with named offsets.
//
// Error convention everywhere: delta = computed (INS) - true.
//   dr   position error in NED [m]: [dL (R_M + h), dlambda (R_N + h) cos L, dh_down]
//        (down = -dh so that the block is a NED vector)
//   dv   velocity error in NED [m/s]
//   psi  attitude error [rad]: 3-2-1 Euler platform error angles of the computed
//        frame n' relative to the true n, C_n^{n'} = dcm_from_euler(psi)^T
//        (seed 000 eq. (1)); for small angles C_n^{n'} = I - [psi x]
//   df_b accelerometer error (measured - true) in body axes [m/s^2]
//   dw_b gyro error (measured - true) in body axes [rad/s]
// A new layout (clock states, scale factors, 20-state seed 004) is a new type
// here; the filters are templates on the layout.
#pragma once

#include <type_traits>

namespace insnav {

/// seed 000 / 001 / 003 loose: [dr dv psi df_b dw_b]
struct Layout15 {
  static constexpr int kSize = 15;
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAtt = 6;
  static constexpr int kAccBias = 9;
  static constexpr int kGyroBias = 12;
  static constexpr int kAccScale = -1;    // not in this layout
  static constexpr int kGyroScale = -1;
  static constexpr int kClockBias = -1;
  static constexpr int kClockDrift = -1;
};

/// seed 003 tight: Layout15 + receiver clock bias [m] and drift [m/s]
struct Layout17 {
  static constexpr int kSize = 17;
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAtt = 6;
  static constexpr int kAccBias = 9;
  static constexpr int kGyroBias = 12;
  static constexpr int kAccScale = -1;
  static constexpr int kGyroScale = -1;
  static constexpr int kClockBias = 15;
  static constexpr int kClockDrift = 16;
};

/// KF-GINS-like: Layout15 + accelerometer and gyro scale-factor errors [-]
struct Layout21 {
  static constexpr int kSize = 21;
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAtt = 6;
  static constexpr int kAccBias = 9;
  static constexpr int kGyroBias = 12;
  static constexpr int kAccScale = 15;
  static constexpr int kGyroScale = 18;
  static constexpr int kClockBias = -1;
  static constexpr int kClockDrift = -1;
};

/// Loose coupling with a wheel odometer: Layout15 + the odometer's
/// scale-factor error s_odo [-] (meas/vehicle.hpp).  Error convention of a
/// sensor error (measured - true, as df_b, dw_b): the odometer reads
///   v_odo = (1 + s_odo) v_fwd,
/// v_fwd the true forward speed of the constrained point.  State equation:
/// first-order Gauss-Markov s' = -s / tau + w (tau = inf: random constant,
/// no driving noise), ImuErrorModel::odo_scale_sigma / odo_scale_tau
/// (Groves 2013, sec. 16.2.1 and 16.3.3: an odometer scale-factor state in
/// the integration filter; Shin 2001, sec. 4.4).  Fed back like the IMU
/// biases (engine/closed_loop.hpp).
struct Layout16Odo {
  static constexpr int kSize = 16;
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAtt = 6;
  static constexpr int kAccBias = 9;
  static constexpr int kGyroBias = 12;
  static constexpr int kAccScale = -1;
  static constexpr int kGyroScale = -1;
  static constexpr int kClockBias = -1;
  static constexpr int kClockDrift = -1;
  static constexpr int kOdoScale = 15;
};

/// Tight coupling with several constellations: Layout17 + one inter-system
/// bias (ISB) [m] per non-GPS system.  The receiver clock (kClockBias,
/// kClockDrift) is the GPS-time clock; the pseudorange of a satellite of
/// system s (insnav.gnss.systems: G = 0 reference, R = 1, E = 2, C = 3) is
///   rho = |r_sat - r_ant| + b + isb_s - c dt_sv,   isb_G = 0,
/// its rate shares the drift d (an ISB is a hardware/time-scale offset that
/// changes too slowly to show in a Doppler).  Each ISB is a random walk
/// (ImuErrorModel::isb_psd).  Groves 2013, sec. 9.4.3 ("inter-constellation
/// timing biases"); Cai & Gao 2013 (GPS/GLONASS PPP with an ISB state).
struct LayoutTightMulti {
  static constexpr int kSize = 20;
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAtt = 6;
  static constexpr int kAccBias = 9;
  static constexpr int kGyroBias = 12;
  static constexpr int kAccScale = -1;
  static constexpr int kGyroScale = -1;
  static constexpr int kClockBias = 15;
  static constexpr int kClockDrift = 16;
  static constexpr int kIsb = 17;      // ISB of system 1 (R), 2 (E), 3 (C) at kIsb + s - 1
  static constexpr int kNumIsb = 3;
};

/// Number of satellite systems a tight measurement tells apart (G, R, E, C).
inline constexpr int kNumSystems = 4;

// --- self-calibration states: IMU-GNSS time offset and GNSS antenna lever arm ---
//
// Time offset t_d [s]: a GNSS record time-tagged t_g (GNSS time) holds the
// antenna at IMU time t_g - t_d (t_d > 0: the IMU clock runs behind, or the
// GNSS data are tagged late).  The engines keep the estimate t_d^ and apply
// the record when the INS reaches t_g - t_d^ ("shifting the time tag"); the
// filter state is its error dt_d = t_d^ - t_d (computed - true, like every
// state here), fed back as t_d^ <- t_d^ - dt_d.  Model: random walk of PSD
// ImuErrorModel::time_offset_psd [s^2/s] (0: a random constant).
// Lever arm l_b [m] (IMU centre -> GNSS antenna, body FRD): the estimate l_b^
// replaces the configured lever arm in the GNSS measurements; the state is
// dl_b = l_b^ - l_b, fed back as l_b^ <- l_b^ - dl_b; random walk of PSD
// ImuErrorModel::lever_arm_psd [m^2/s] (0: a random constant).
// Measurement columns: meas/gnss_loose.hpp, meas/pseudorange.hpp; equations
// and observability: docs/algorithms.md ("Self-calibration states").
// The extra states follow the layout they extend, so its offsets (and every
// result with the options off) are unchanged.

/// Layout15 + time offset.
struct Layout16Td : Layout15 {
  static constexpr int kSize = 16;
  static constexpr int kTimeOffset = 15;
};

/// Layout15 + GNSS antenna lever arm.
struct Layout18Lever : Layout15 {
  static constexpr int kSize = 18;
  static constexpr int kLeverArm = 15;
};

/// Layout15 + lever arm + time offset.
struct Layout19TdLever : Layout15 {
  static constexpr int kSize = 19;
  static constexpr int kLeverArm = 15;
  static constexpr int kTimeOffset = 18;
};

/// Layout17 (tight) + time offset.
struct LayoutTightTd : Layout17 {
  static constexpr int kSize = 18;
  static constexpr int kTimeOffset = 17;
};

/// Layout17 (tight) + GNSS antenna lever arm.
struct LayoutTightLever : Layout17 {
  static constexpr int kSize = 20;
  static constexpr int kLeverArm = 17;
};

/// Layout17 (tight) + lever arm + time offset.
struct LayoutTightTdLever : Layout17 {
  static constexpr int kSize = 21;
  static constexpr int kLeverArm = 17;
  static constexpr int kTimeOffset = 20;
};

/// Layout15 + the odometer lever arm (IMU -> the constrained rear-axle point,
/// body axes [m]; meas/vehicle.hpp): the state is dl_o = l_o^ - l_o, fed
/// back l_o^ <- l_o^ - dl_o, random walk of ImuErrorModel::lever_arm_psd.
struct Layout18OdoLever : Layout15 {
  static constexpr int kSize = 18;
  static constexpr int kOdoLever = 15;
};

template <class L, class = void>
struct OdoLeverState {
  static constexpr int offset = -1;
};
template <class L>
struct OdoLeverState<L, std::void_t<decltype(L::kOdoLever)>> {
  static constexpr int offset = L::kOdoLever;
};
/// True for a layout with the odometer / vehicle-constraint lever-arm states (L::kOdoLever, 3 states).
template <class L>
inline constexpr bool kHasOdoLever = OdoLeverState<L>::offset >= 0;

template <class L, class = void>
struct TimeOffsetState {
  static constexpr int offset = -1;
};
template <class L>
struct TimeOffsetState<L, std::void_t<decltype(L::kTimeOffset)>> {
  static constexpr int offset = L::kTimeOffset;
};
/// True for a layout with the IMU-GNSS time-offset state (L::kTimeOffset).
template <class L>
inline constexpr bool kHasTimeOffset = TimeOffsetState<L>::offset >= 0;

template <class L, class = void>
struct LeverArmState {
  static constexpr int offset = -1;
};
template <class L>
struct LeverArmState<L, std::void_t<decltype(L::kLeverArm)>> {
  static constexpr int offset = L::kLeverArm;
};
/// True for a layout with the GNSS antenna lever-arm states (L::kLeverArm, 3 states).
template <class L>
inline constexpr bool kHasLeverArm = LeverArmState<L>::offset >= 0;

template <class L, class = void>
struct IsbStates {
  static constexpr int offset = -1, count = 0;
};
template <class L>
struct IsbStates<L, std::void_t<decltype(L::kIsb)>> {
  static constexpr int offset = L::kIsb, count = L::kNumIsb;
};
/// True for a layout with inter-system bias states (L::kIsb, L::kNumIsb).
template <class L>
inline constexpr bool kHasIsb = IsbStates<L>::count > 0;

template <class L, class = void>
struct OdoScaleState {
  static constexpr int offset = -1;
};
template <class L>
struct OdoScaleState<L, std::void_t<decltype(L::kOdoScale)>> {
  static constexpr int offset = L::kOdoScale;
};
/// True for a layout with the odometer scale-factor state (L::kOdoScale).
template <class L>
inline constexpr bool kHasOdoScale = OdoScaleState<L>::offset >= 0;

template <class L>
inline constexpr bool kHasScale = (L::kAccScale >= 0);
template <class L>
inline constexpr bool kHasClock = (L::kClockBias >= 0);

}  // namespace insnav
