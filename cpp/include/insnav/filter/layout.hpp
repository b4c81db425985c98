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

template <class L>
inline constexpr bool kHasScale = (L::kAccScale >= 0);
template <class L>
inline constexpr bool kHasClock = (L::kClockBias >= 0);

}  // namespace insnav
