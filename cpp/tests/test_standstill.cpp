// Standstill detector (ins/standstill.hpp, SHOE statistic of Skog et al.
// 2010, eq. (10)): at rest with white noise the statistic has the chi-square
// mean 6 - 2/W and every window is declared stationary; a vehicle turning at
// 3 deg/s, accelerating at 2 m/s^2, or driving with 0.3 m/s^2 RMS road
// vibration (same sensor noise) is never stationary; the detection is
// independent of the IMU's tilt; no heap.  (A small *constant* acceleration
// is indistinguishable from a tilt for any IMU-only detector: |f| changes by
// only a^2 / 2g, 5 mm/s^2 at 0.3 m/s^2.)
#include <cstdio>
#include <random>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/core.hpp"
#include "insnav/ins/standstill.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

struct Rates {
  double stationary_share = 0.0, mean_T = 0.0;
};

/// n samples of a tilted IMU with specific force f_extra (body) and rate w (body) on top of gravity.
Rates run(StandstillDetector<>& d, const Vec3& rpy, const Vec3& f_extra, const Vec3& w, int n, unsigned seed,
         double vibration_mps2 = 0.0) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> nd;
  const StandstillConfig& c = d.config();
  const Mat3 C_bn = dcm_from_euler(rpy).transpose();
  const Vec3 f_rest = C_bn * Vec3(0.0, 0.0, -c.gravity_mps2);  // FRD: specific force points up
  d.reset();
  int full = 0, still = 0;
  double sum_T = 0.0;
  for (int k = 0; k < n; ++k) {
    const double vib = vibration_mps2 * std::sqrt(2.0) * std::sin(2 * M_PI * 12.0 * k / 200.0);  // 12 Hz at 200 Hz
    const Vec3 f = f_rest + f_extra + Vec3(0.0, 0.3 * vib, vib) + c.sigma_f_mps2 * Vec3(nd(rng), nd(rng), nd(rng));
    const Vec3 om = w + c.sigma_w_radps * Vec3(nd(rng), nd(rng), nd(rng));
    const double T = d.add(f, om);
    if (T == std::numeric_limits<double>::infinity()) continue;
    ++full;
    sum_T += T;
    still += d.stationary();
  }
  return {double(still) / full, sum_T / full};
}

}  // namespace

int main() {
  StandstillConfig cfg;
  cfg.window = 40;
  static StandstillDetector<> d(cfg);
  Eigen::internal::set_is_malloc_allowed(false);
  const Rates rest = run(d, Vec3(0.0, 0.0, 0.0), Vec3::Zero(), Vec3::Zero(), 4000, 1);
  const Rates tilted = run(d, Vec3(0.3, -0.2, 1.0), Vec3::Zero(), Vec3::Zero(), 4000, 2);
  const Rates turning = run(d, Vec3(0.0, 0.0, 0.0), Vec3::Zero(), Vec3(0.0, 0.0, 3.0 * M_PI / 180), 4000, 3);
  const Rates accel = run(d, Vec3(0.0, 0.0, 0.0), Vec3(2.0, 0.0, 0.0), Vec3::Zero(), 4000, 4);
  const Rates road = run(d, Vec3(0.0, 0.0, 0.0), Vec3::Zero(), Vec3::Zero(), 4000, 5, 0.3);
  Eigen::internal::set_is_malloc_allowed(true);
  std::printf("rest: T mean %.3f (chi-square mean %.3f), stationary %.4f\n", rest.mean_T, 6.0 - 2.0 / cfg.window,
              rest.stationary_share);
  std::printf("tilted: T mean %.3f, stationary %.4f\n", tilted.mean_T, tilted.stationary_share);
  std::printf("turning 3 deg/s: T mean %.1f, stationary %.4f\n", turning.mean_T, turning.stationary_share);
  std::printf("accelerating 2 m/s^2: T mean %.1f, stationary %.4f\n", accel.mean_T, accel.stationary_share);
  std::printf("road vibration 0.3 m/s^2 RMS: T mean %.1f, stationary %.4f\n", road.mean_T, road.stationary_share);
  // 4000 samples: ~100 independent windows, sd of the mean T ~0.055 (the test's cost under
  // ASan at -O0 is linear in the samples); a wrong scaling would be off by whole units
  EXPECT_LT(std::abs(rest.mean_T - (6.0 - 2.0 / cfg.window)), 0.15);
  EXPECT_LT(std::abs(tilted.mean_T - (6.0 - 2.0 / cfg.window)), 0.15);
  EXPECT_TRUE(rest.stationary_share == 1.0 && tilted.stationary_share == 1.0);
  EXPECT_TRUE(turning.stationary_share == 0.0 && accel.stationary_share == 0.0 && road.stationary_share == 0.0);
  EXPECT_TRUE(g_eigen_asserts == 0);
  TEST_MAIN_END();
}
