// insnav/filter/types.hpp -- what the engine hands the filters: the INS
// solution at the points of a propagation interval, the IMU error model, and
// measurements.  Fixed-size; nothing here allocates.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <type_traits>

#include "insnav/ins/mechanization.hpp"
#include "insnav/filter/layout.hpp"

namespace insnav {

template <class L>
using StateVec = Eigen::Matrix<double, L::kSize, 1>;
template <class L>
using StateCov = Eigen::Matrix<double, L::kSize, L::kSize>;

/// The computed (INS) solution at one instant, with the Earth terms and the
/// measured (uncorrected for the current error estimate: the engine already
/// applied the fed-back IMU corrections) specific force and angular rate.
struct InsPoint {
  double lat = 0.0, h = 0.0;       // computed position [rad, m]
  Vec3 v_n = Vec3::Zero();         // computed velocity [m/s]
  Mat3 C_nb = Mat3::Identity();    // computed attitude C_{n'b}
  Vec3 f_ib_b = Vec3::Zero();      // specific force, corrected IMU output [m/s^2]
  Vec3 omega_ib_b = Vec3::Zero();  // angular rate, corrected IMU output [rad/s]
  EarthTerms earth{};              // at (lat, h, v_n)

  void set(double lat_, double h_, const Vec3& v, const Mat3& C, const Vec3& f_b, const Vec3& w_b) {
    lat = lat_;
    h = h_;
    v_n = v;
    C_nb = C;
    f_ib_b = f_b;
    omega_ib_b = w_b;
    earth.evaluate(lat, h, v_n);
  }
};

/// One propagation interval (t0, t1] of the error state with the INS solution
/// at its start, middle and end: the k-1, k-1/2, k points of seed 000's RK4.
struct InsInterval {
  double dt = 0.0;  // t1 - t0 [s]
  InsPoint start, mid, end;
};

/// IMU error model in SI (the same fields the simulator's imu_model uses).
///   gyro_arw  [rad/sqrt(s)], acc_vrw [(m/s)/sqrt(s)]  white noise
///   gyro_bias_sigma [rad/s], acc_bias_sigma [m/s^2]   steady-state sigma of the
///       first-order Gauss-Markov bias (tau = inf: random walk with
///       gyro/acc_bias_rw instead; tau = inf and rw = 0: random constant)
///   gyro_bias_tau, acc_bias_tau [s]
///   gyro_bias_rw, acc_bias_rw: an extra random-walk drive of the bias state
///   gyro_scale_sigma, acc_scale_sigma [-], *_scale_tau [s]  (Layout21 only)
///   odo_scale_sigma [-], odo_scale_tau [s]  (Layout16Odo only)
///   time_offset_psd [s^2/s], lever_arm_psd [m^2/s]  (self-calibration layouts only)
struct ImuErrorModel {
  Vec3 gyro_arw = Vec3::Constant(1e-4);
  Vec3 acc_vrw = Vec3::Constant(1e-3);
  Vec3 gyro_bias_sigma = Vec3::Constant(1e-5);
  Vec3 acc_bias_sigma = Vec3::Constant(1e-3);
  Vec3 gyro_bias_tau = Vec3::Constant(3600.0);
  Vec3 acc_bias_tau = Vec3::Constant(3600.0);
  Vec3 gyro_bias_rw = Vec3::Zero();  // bias random walk [rad/s/sqrt(s)], added to the Markov drive
  Vec3 acc_bias_rw = Vec3::Zero();   // [m/s^2/sqrt(s)]
  Vec3 gyro_scale_sigma = Vec3::Constant(1e-4);
  Vec3 acc_scale_sigma = Vec3::Constant(1e-4);
  Vec3 gyro_scale_tau = Vec3::Constant(3600.0 * 4);
  Vec3 acc_scale_tau = Vec3::Constant(3600.0 * 4);
  double clock_bias_psd = 0.1;    // receiver clock phase noise PSD [m^2/s]
  double clock_drift_psd = 0.04;  // receiver clock frequency noise PSD [m^2/s^3]
  // Inter-system bias random walk PSD [m^2/s] (layouts with ISB states):
  // 1e-4 m^2/s = 0.01 m/sqrt(s), 0.6 m in an hour -- hardware delays and the
  // GPS-Galileo/BeiDou time offsets drift by ns per day (Groves 2013, sec. 9.4.3)
  double isb_psd = 1e-4;
  // Odometer scale-factor error s_odo [-] (layouts with kOdoScale, layout.hpp):
  // first-order Gauss-Markov with steady-state sigma odo_scale_sigma [-] and
  // correlation time odo_scale_tau [s]; tau = inf: a random constant (no
  // driving noise; its sigma then enters only through P0).
  double odo_scale_sigma = 0.01;
  double odo_scale_tau = std::numeric_limits<double>::infinity();
  // Self-calibration states (layout.hpp): random-walk PSD of the IMU-GNSS
  // time offset [s^2/s] and of each lever-arm component [m^2/s]; 0: random
  // constants (their sigma then enters only through P0).
  double time_offset_psd = 0.0;
  double lever_arm_psd = 0.0;
};

/// Maximum rows of one measurement update (tight coupling: 2 per satellite).
inline constexpr int kMaxMeasRows = 32;

/// A linearised measurement: innovation y = z_measured - h(x_pred) is formed by
/// the filter from `residual` = (INS-predicted - measured) as y = residual - H x,
/// so residual = H dx + noise with dx = computed - true.
/// Rows are dynamic but bounded (no heap).
template <class L>
struct LinearMeasurement {
  using RowVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxMeasRows, 1>;
  using HMat = Eigen::Matrix<double, Eigen::Dynamic, L::kSize, Eigen::RowMajor, kMaxMeasRows, L::kSize>;
  using RMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  RowVec residual;  // INS-predicted minus measured
  HMat H;           // d residual / d dx
  RMat R;           // measurement noise covariance
  /// Columns [0, n_cols) hold all non-zeros of H (block-sparse updates use it).
  int n_cols = L::kSize;
  int rows() const { return static_cast<int>(residual.size()); }
};

/// Outcome of one update.
struct UpdateResult {
  bool applied = false;
  bool rejected_by_gate = false;
  double nis = 0.0;             // y' S^-1 y
  double log_det_s = NAN;       // log det S (NaN: no S): the innovation log-likelihood's other term (Mehra 1970)
  int rows = 0;
  int cholesky_repairs = 0;     // covariance repairs during this update
};

inline constexpr double kInf = std::numeric_limits<double>::infinity();

/// True for a filter whose measurement update is linear in the measurement's
/// Jacobian H (Ekf, RbUkf: they declare kJacobianUpdate = true), false for the
/// filters that evaluate predicted_residual at sigma points or particles.
/// A measurement may then add the covariance of the terms H leaves out
/// (meas/vehicle.hpp, add_second_order_noise).
template <class F, class = void>
struct JacobianUpdate : std::false_type {};
template <class F>
struct JacobianUpdate<F, std::void_t<decltype(F::kJacobianUpdate)>> : std::bool_constant<F::kJacobianUpdate> {};
template <class F>
inline constexpr bool kJacobianUpdate = JacobianUpdate<F>::value;

}  // namespace insnav
