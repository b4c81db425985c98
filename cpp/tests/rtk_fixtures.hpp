// Test fixtures shared by the RTK and RTK/INS C++ tests: a static base and rover
// 47 m apart under 8 GPS satellites, and their noise-free dual-frequency rows.
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include "insnav/earth/wgs84.hpp"
#include "insnav/gnss/rtk.hpp"

namespace insnav::test_rtk {

inline constexpr double kL1 = gnss::kCLight / 1575.42e6, kL2 = gnss::kCLight / 1227.60e6;

/// Geometric range with the Sagnac term (ECEF, metres).
inline double range_sagnac(const Vec3& rs, const Vec3& r) {
  return (rs - r).norm() + gnss::kOmegaE * (rs.x() * r.y() - rs.y() * r.x()) / gnss::kCLight;
}

/// Noise-free L1/L2 GPS rows (gnss::RtkRow layout) of a receiver at r_e with clock offset clk_m [m];
/// iono_l1_m: a slant ionospheric delay on L1 per satellite [m] (code delayed, phase advanced).
inline std::vector<double> rows_for(const Vec3& r_e, const std::vector<Vec3>& sats, const std::vector<double>& N1,
                                    const std::vector<double>& N2, double clk_m,
                                    const std::vector<double>* iono_l1_m = nullptr) {
  using gnss::RtkRow;
  std::vector<double> rows(sats.size() * RtkRow::kCols, NAN);
  for (size_t k = 0; k < sats.size(); ++k) {
    double* w = rows.data() + k * RtkRow::kCols;
    const double rho = range_sagnac(sats[k], r_e) + clk_m;
    w[RtkRow::kSat] = static_cast<double>(k + 1);
    w[RtkRow::kSys] = gnss::kGps;
    const double lam[2] = {kL1, kL2};
    const double N[2] = {N1[k], N2[k]};
    for (int f = 0; f < 2; ++f) {
      double* q = w + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
      const double I = iono_l1_m ? (*iono_l1_m)[k] * (lam[f] / kL1) * (lam[f] / kL1) : 0.0;  // (f_1 / f)^2 I
      q[0] = rho + I;
      q[1] = (rho - I) / lam[f] + N[f];
      q[2] = 0.0;
      q[3] = 0.0;
      q[4] = lam[f];
    }
    for (int i = 0; i < 3; ++i) w[RtkRow::kSatPos + i] = sats[k](i);
    w[RtkRow::kSatClock] = 0.0;
  }
  return rows;
}

/// A static base r_b and rover r_r (40 m north, 25 m west, 3 m up) at lat 0.84, lon 0.20 rad,
/// 8 GPS satellites at 20200 km altitude (elevations 28-80 deg), and random integer
/// ambiguities per receiver and frequency (seeded: every test sees the same scene).
struct StaticScene {
  Mat3 C_en;  // the base's local-level frame (wgs84::C_en)
  Vec3 r_b, r_r;
  std::vector<Vec3> sats;
  std::vector<double> N1r, N2r, N1b, N2b;
};

inline StaticScene static_scene() {
  StaticScene s;
  const double lat = 0.84, lon = 0.20;
  s.r_b = wgs84::geodetic_to_ecef(lat, lon, 300.0);
  s.C_en = wgs84::C_en(lat, lon);
  const Mat3& C = s.C_en;
  s.r_r = s.r_b + C * Vec3(40.0, -25.0, 3.0);
  const double els[8] = {80, 60, 45, 35, 28, 50, 40, 65}, azs[8] = {0, 50, 100, 150, 200, 250, 300, 330};
  for (int k = 0; k < 8; ++k) {
    const double el = els[k] * M_PI / 180.0, az = azs[k] * M_PI / 180.0;
    const Vec3 u = C * Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), -std::sin(el));
    const double b = 2.0 * s.r_b.dot(u), c = s.r_b.squaredNorm() - 26560e3 * 26560e3;
    s.sats.push_back(s.r_b + u * ((-b + std::sqrt(b * b - 4.0 * c)) / 2.0));
  }
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> ui(-100000, 100000);
  s.N1r.resize(8), s.N2r.resize(8), s.N1b.resize(8), s.N2b.resize(8);
  for (int k = 0; k < 8; ++k) {
    s.N1r[k] = ui(rng);
    s.N2r[k] = ui(rng);
    s.N1b[k] = ui(rng);
    s.N2b[k] = ui(rng);
  }
  return s;
}

}  // namespace insnav::test_rtk
