// Plain C++ tests of the core (run by ctest, also under ASan/UBSan).
#include <random>

#include "insnav/core.hpp"
#include "test_util.hpp"

using namespace insnav;

static void test_rotations() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  for (int i = 0; i < 2000; ++i) {
    // include pitch within 1e-7 rad of +-90 deg (gimbal lock)
    double pitch = u(rng) / 2.0;
    if (i % 4 == 0) pitch = (i % 8 == 0 ? 1 : -1) * (M_PI / 2 - std::pow(10.0, -(i % 9)));
    const Vec3 rpy(u(rng), pitch, u(rng));
    const Mat3 C = dcm_from_euler(rpy);
    EXPECT_LT((C * C.transpose() - Mat3::Identity()).norm(), 1e-14);
    EXPECT_LT((dcm_from_euler(euler_from_dcm(C)) - C).norm(), 1e-9);
    EXPECT_LT((quat_from_euler(rpy).toRotationMatrix() - C).norm(), 1e-14);
    const Vec3 phi = rotvec_from_quat(quat_from_euler(rpy));
    EXPECT_LT((dcm_from_rotvec(phi) - C).norm(), 1e-13);
  }
  // small-angle series: continuity across the switch and against the closed form
  for (double a : {1e-12, 1e-6, 9.9e-5, 1.01e-4, 9e-3, 1.1e-2}) {
    const Vec3 phi = Vec3(0.3, -0.5, 0.81).normalized() * a;
    const Quat q = quat_from_rotvec(phi);
    const Quat qs = quat_from_small_rotvec(phi);
    EXPECT_LT(std::abs(q.w() - std::cos(a / 2)), 1e-16);
    EXPECT_LT((q.vec() - phi.normalized() * std::sin(a / 2)).norm(), 1e-17 + 1e-15 * a);
    EXPECT_LT((qs.coeffs() - q.coeffs()).norm(), 1e-16);
    EXPECT_LT((rotvec_from_quat(q) - phi).norm(), 1e-15 * (1 + a));
  }
}

/// sincos_exact (rotation.hpp): the series branch equals libm to rounding
/// (within 2 ulp of sin and cos) on both sides of its 2^-6 switch.
static void test_sincos_exact() {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.02, 0.02);
  double worst_ulp = 0.0;
  for (int i = 0; i < 200000; ++i) {
    double a = u(rng);
    if (i % 1000 == 0) a = std::ldexp(1.0, -6) * (i % 2000 == 0 ? 1 : -1) * (1.0 - 1e-16);  // just below the switch
    if (i % 1000 == 1) a = std::ldexp(1.0, -60);                                           // tiny
    double s, c;
    sincos_exact(a, s, c);
    const double s_ref = std::sin(a), c_ref = std::cos(a);
    worst_ulp = std::max(worst_ulp, std::abs(s - s_ref) / (std::nextafter(std::abs(s_ref), 1.0) - std::abs(s_ref)));
    worst_ulp = std::max(worst_ulp, std::abs(c - c_ref) / (std::nextafter(c_ref, 2.0) - c_ref));
  }
  EXPECT_LT(worst_ulp, 2.01);
  double s0, c0;
  sincos_exact(0.0, s0, c0);
  EXPECT_TRUE(s0 == 0.0 && c0 == 1.0);
}

static void test_earth() {
  EXPECT_LT(std::abs(wgs84::gravity(0.0, 0.0) - 9.7803253359), 1e-10);
  EXPECT_LT(std::abs(wgs84::gravity(M_PI / 2, 0.0) - 9.8321849378), 1e-9);
  // free-air gradient ~ -3.086e-6 s^-2
  EXPECT_LT(std::abs((wgs84::gravity(0.7, 1000.0) - wgs84::gravity(0.7, 0.0)) / 1000.0 + 3.086e-6), 1e-8);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ulat(-M_PI / 2, M_PI / 2), ulon(-M_PI, M_PI), uh(-1000.0, 1e6);
  double worst = 0.0;
  for (int i = 0; i < 20000; ++i) {
    double lat = ulat(rng);
    if (i % 10 == 0) lat = (i % 20 == 0 ? 1 : -1) * M_PI / 2;       // poles
    if (i % 10 == 1) lat = (i % 20 == 1 ? 1 : -1) * (M_PI / 2 - 1e-9);
    const double lon = ulon(rng), h = (i % 7 == 0) ? -1000.0 : ((i % 7 == 1) ? 1e6 : uh(rng));
    const Vec3 r = wgs84::geodetic_to_ecef(lat, lon, h);
    const Vec3 llh = wgs84::ecef_to_geodetic(r);
    const Vec3 r2 = wgs84::geodetic_to_ecef(llh.x(), llh.y(), llh.z());
    worst = std::max(worst, (r2 - r).norm());
    worst = std::max(worst, std::abs(llh.z() - h));
  }
  EXPECT_LT(worst, 1e-6);
  // C_en is orthonormal and maps NED down to minus the geodetic normal
  const Mat3 C = wgs84::C_en(0.6, -1.2);
  EXPECT_LT((C.transpose() * C - Mat3::Identity()).norm(), 1e-15);
}

int main() {
  test_rotations();
  test_sincos_exact();
  test_earth();
  TEST_MAIN_END();
}
