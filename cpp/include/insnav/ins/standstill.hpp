// insnav/ins/standstill.hpp -- standstill (zero-velocity) detection from the
// IMU alone, for ZUPT / ZARU updates (meas/vehicle.hpp).
//
// Test statistic: the SHOE detector (stance hypothesis optimal estimation,
// the GLRT for "the IMU is stationary" with unknown attitude), Skog,
// Handel, Nilsson, Rantakokko (2010), "Zero-velocity detection -- an
// algorithm evaluation", IEEE TBME 57(11), eq. (10):
//   T = 1/W sum_{k in window} ( |f_k - g f_mean/|f_mean||^2 / sigma_f^2
//                              + |omega_k|^2 / sigma_w^2 )
// over the last W samples (f specific force [m/s^2], omega angular rate
// [rad/s], both per sample: increment / dt), sigma_f and sigma_w the
// per-sample noise standard deviations of the accelerometer and gyro at the
// IMU rate (plus the vibration the vehicle has at standstill, e.g. the
// engine idling).  Stationary when T < gamma.  At standstill with white
// noise W T ~ chi^2(6 W - 2), so T has mean ~6 and standard deviation
// ~sqrt(12 / W) (0.55 for W = 40); the default gamma = 18 (3x the mean)
// accepts essentially every stationary window of white noise and leaves
// margin for unmodelled vibration.  A turning or accelerating vehicle
// exceeds it by orders of magnitude.  A vehicle at exactly constant velocity
// on a straight, smooth road is indistinguishable from one at rest for any
// IMU-only detector: road vibration is what separates them, so the false
// alarm rate must be measured on realistic moving data (and an odometer, when
// present, vetoes the detection).  The Earth rate (7.3e-5 rad/s) is far below
// any IMU's per-sample noise and is not removed.
// Fixed window (kMaxWindow samples, a ring of sums), no heap.
#pragma once

#include <array>
#include <cmath>
#include <limits>

#include "insnav/check.hpp"
#include "insnav/ins/nav_state.hpp"

namespace insnav {

struct StandstillConfig {
  int window = 40;               // W samples (0.2 s at 200 Hz)
  double sigma_f_mps2 = 0.02;    // per-sample accelerometer noise + idle vibration [m/s^2]
  double sigma_w_radps = 2e-3;   // per-sample gyro noise + idle vibration [rad/s]
  double gamma = 18.0;           // threshold on T (mean ~6 at standstill)
  double gravity_mps2 = 9.80665; // |g| at the site [m/s^2]
};

template <int kMaxWindow = 512>
class StandstillDetector {
 public:
  explicit StandstillDetector(const StandstillConfig& cfg = {}) : cfg_(cfg) {
    INSNAV_CHECK(cfg_.window >= 2 && cfg_.window <= kMaxWindow, "standstill window must be in 2..kMaxWindow");
    INSNAV_CHECK(cfg_.sigma_f_mps2 > 0 && cfg_.sigma_w_radps > 0, "standstill sigmas must be > 0");
    INSNAV_CHECK(cfg_.gamma > 0, "standstill threshold gamma must be > 0");
  }

  void reset() { n_ = head_ = 0; }

  /// Add one IMU sample (specific force and angular rate, body axes, per
  /// sample) and return the statistic T of the last W samples (+inf until the
  /// window is full).
  double add(const Vec3& f_ib_b, const Vec3& omega_ib_b) {
    f_[head_] = f_ib_b;
    w_[head_] = omega_ib_b;
    head_ = (head_ + 1) % cfg_.window;
    if (n_ < cfg_.window) ++n_;
    if (n_ < cfg_.window) return last_ = std::numeric_limits<double>::infinity();
    // two passes over W <= kMaxWindow samples: the mean direction, then the sum
    Vec3 f_mean = Vec3::Zero();
    for (int i = 0; i < cfg_.window; ++i) f_mean += f_[i];
    f_mean /= cfg_.window;
    const double fn = f_mean.norm();
    const Vec3 g_dir = fn > 0 ? Vec3(f_mean / fn) : Vec3(0.0, 0.0, -1.0);
    double sa = 0.0, sw = 0.0;
    for (int i = 0; i < cfg_.window; ++i) {
      sa += (f_[i] - cfg_.gravity_mps2 * g_dir).squaredNorm();
      sw += w_[i].squaredNorm();
    }
    return last_ = (sa / (cfg_.sigma_f_mps2 * cfg_.sigma_f_mps2) + sw / (cfg_.sigma_w_radps * cfg_.sigma_w_radps)) /
                   cfg_.window;
  }

  double statistic() const { return last_; }
  bool stationary() const { return last_ < cfg_.gamma; }
  const StandstillConfig& config() const { return cfg_; }

 private:
  StandstillConfig cfg_;
  std::array<Vec3, kMaxWindow> f_{}, w_{};
  int n_ = 0, head_ = 0;
  double last_ = std::numeric_limits<double>::infinity();
};

}  // namespace insnav
