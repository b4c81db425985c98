// insnav/earth/wgs84.hpp -- WGS-84 ellipsoid, normal gravity, Earth and
// transport rates in NED, geodetic <-> ECEF.
//
// Frames: e = ECEF, n = North-East-Down.  SI: lat/lon in rad, h in m above
// the ellipsoid.  Reference: NIMA TR8350.2 (WGS-84); Groves (2013) ch. 2.
// python/insnav/earth.py is the vectorised twin; tests check they agree.
#pragma once

#include <cmath>

#include "insnav/math/rotation.hpp"

namespace insnav::wgs84 {

inline constexpr double kA = 6378137.0;                 // semi-major axis [m]
inline constexpr double kF = 1.0 / 298.257223563;       // flattening
inline constexpr double kB = kA * (1.0 - kF);           // semi-minor axis [m]
inline constexpr double kE2 = kF * (2.0 - kF);          // first eccentricity^2
inline constexpr double kOmegaIe = 7.292115e-5;         // Earth rate [rad/s]
inline constexpr double kGM = 3.986004418e14;           // [m^3/s^2]
inline constexpr double kGammaE = 9.7803253359;         // normal gravity, equator [m/s^2]
inline constexpr double kGammaP = 9.8321849378;         // normal gravity, pole [m/s^2]
inline constexpr double kSomiglianaK = 0.00193185265241;
inline constexpr double kM = kOmegaIe * kOmegaIe * kA * kA * kB / kGM;

/// Meridian radius R_M and prime-vertical radius R_N [m] at latitude lat.
struct Radii {
  double R_M;
  double R_N;
};

/// radii(lat) from sin(lat) (a caller that has the sine at hand).
inline Radii radii_from_sin(double sin_lat) {
  const double w = 1.0 - kE2 * sin_lat * sin_lat;
  const double R_N = kA / std::sqrt(w);
  return {R_N * (1.0 - kE2) / w, R_N};
}

inline Radii radii(double lat) { return radii_from_sin(std::sin(lat)); }

/// Normal gravity [m/s^2]: Somigliana's closed form on the ellipsoid with the
/// second-order free-air height correction (TR8350.2 eq. 4-1 and 4-3).
inline double gravity(double lat, double h) {
  const double s2 = std::sin(lat) * std::sin(lat);
  const double g0 = kGammaE * (1.0 + kSomiglianaK * s2) / std::sqrt(1.0 - kE2 * s2);
  return g0 * (1.0 - 2.0 / kA * (1.0 + kF + kM - 2.0 * kF * s2) * h + 3.0 * h * h / (kA * kA));
}

/// Earth rotation rate expressed in NED [rad/s].
inline Vec3 omega_ie_n(double lat) {
  return Vec3(kOmegaIe * std::cos(lat), 0.0, -kOmegaIe * std::sin(lat));
}

/// Transport rate omega_en_n [rad/s] for NED velocity v_n.
inline Vec3 omega_en_n(double lat, double h, const Vec3& v_n, const Radii& r) {
  return Vec3(v_n.y() / (r.R_N + h), -v_n.x() / (r.R_M + h), -v_n.y() * std::tan(lat) / (r.R_N + h));
}

/// DCM from NED to ECEF: r_e = C_en * r_n.
inline Mat3 C_en(double lat, double lon) {
  const double sl = std::sin(lat), cl = std::cos(lat);
  const double so = std::sin(lon), co = std::cos(lon);
  Mat3 C;
  C << -sl * co, -so, -cl * co,
       -sl * so, co, -cl * so,
       cl, 0.0, -sl;
  return C;
}

inline Vec3 geodetic_to_ecef(double lat, double lon, double h) {
  const double R_N = radii(lat).R_N;
  const double cl = std::cos(lat);
  return Vec3((R_N + h) * cl * std::cos(lon), (R_N + h) * cl * std::sin(lon),
              (R_N * (1.0 - kE2) + h) * std::sin(lat));
}

/// ECEF [m] -> (lat, lon, h).  Fixed-point iteration on latitude, with the
/// height computed as p cos(lat) + z sin(lat) - a^2/N, well conditioned at the
/// poles; < 1e-9 m for -1e4 m < h < 1e7 m.  The iteration stops when latitude
/// changes by less than lat_tol_rad, after 8 steps at the most; lat_tol_rad = 0
/// always takes the 8 steps, the operations of earth.py ecef_to_geodetic (whose
/// last bit differs from the early stop for about 1 point in 2000).
inline Vec3 ecef_to_geodetic(const Vec3& r_e, double lat_tol_rad = 1e-15) {
  const double p = std::hypot(r_e.x(), r_e.y());
  const double z = r_e.z();
  const double lon = std::atan2(r_e.y(), r_e.x());
  double lat = std::atan2(z, p * (1.0 - kE2));
  double h = 0.0;
  for (int i = 0; i < 8; ++i) {
    const double s = std::sin(lat), c = std::cos(lat);
    const double N = kA / std::sqrt(1.0 - kE2 * s * s);
    h = p * c + z * s - kA * kA / N;
    const double lat_new = std::atan2(z, p * (1.0 - kE2 * N / (N + h)));
    if (std::abs(lat_new - lat) < lat_tol_rad) { lat = lat_new; break; }
    lat = lat_new;
  }
  const double s = std::sin(lat), c = std::cos(lat);
  const double N = kA / std::sqrt(1.0 - kE2 * s * s);
  h = p * c + z * s - kA * kA / N;
  return Vec3(lat, lon, h);
}

}  // namespace insnav::wgs84
