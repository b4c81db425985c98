// insnav/ins/nav_state.hpp -- navigation state and IMU sample types.
#pragma once

#include "insnav/math/rotation.hpp"

namespace insnav {

/// Navigation state of the IMU centre.  Position geodetic (WGS-84), velocity
/// relative to the Earth in NED, attitude q_nb (body FRD -> NED).
struct NavState {
  double t = 0.0;     // time of validity [s]
  double lat = 0.0;   // geodetic latitude [rad]
  double lon = 0.0;   // longitude [rad]
  double h = 0.0;     // height above the ellipsoid [m]
  Vec3 v_n = Vec3::Zero();       // [m/s] N, E, D
  Quat q_nb = Quat::Identity();  // body -> NED
};

/// One IMU sample: increments over (t - dt, t] in the body frame (FRD).
struct ImuIncrement {
  double t = 0.0;                     // end of the interval [s]
  double dt = 0.0;                    // interval length [s]
  Vec3 dtheta_b = Vec3::Zero();       // integral of omega_ib_b [rad]
  Vec3 dv_b = Vec3::Zero();           // integral of f_ib_b [m/s]
};

}  // namespace insnav
