// insnav/engine/loose_engine.hpp -- closed-loop loosely coupled GNSS/INS run:
// mechanization at the IMU rate, the error-state filter at GNSS epochs.
//
// Timing (seed 000 sec. 3): a filter *cycle* spans one GNSS period.  Inside a
// cycle the error state is propagated over intervals of about
// `propagation_interval` seconds, each given to the filter with the INS
// solution at its start, middle and end.  A GNSS fix valid at t_g inside an
// IMU interval (t_{k-1}, t_k] is applied exactly at t_g: the IMU increment is
// split in proportion (constant rate within the interval), the INS is advanced
// to t_g, the cycle is closed, the filter updates, the estimate is fed back
// into the INS and the IMU corrections, and the rest of the increment follows.
// With no fix for longer than `cycle_period` (a GNSS outage) the cycle is
// closed without update and without feedback (seed 000 eqs. (26)-(29)).
//
// The Filter type provides: initialize, begin_cycle, propagate, end_cycle,
// update<Meas>, x, P, reset_state, cholesky_repairs (ekf.hpp, rbukf.hpp, ukf.hpp).
// No heap allocation inside run(); outputs go to caller-owned buffers.
#pragma once

#include <cmath>
#include <cstdint>
#include <type_traits>

#include "insnav/filter/sigma_points.hpp"
#include "insnav/filter/types.hpp"
#include "insnav/meas/gnss_loose.hpp"

namespace insnav {

struct LooseConfig {
  Vec3 lever_arm_b = Vec3::Zero();   // IMU centre -> GNSS antenna, FRD [m]
  double propagation_interval = 0.02;  // error-state propagation step [s]
  double cycle_period = 1.0;         // filter cycle without GNSS (outage) [s]
  double gate_chi2 = 0.0;            // NIS gate (<= 0: off)
  bool use_position = true;
  bool use_velocity = true;
  int output_decimation = 1;         // write every k-th IMU sample
};

/// Accumulated IMU error estimates fed back into the IMU data.
struct ImuCorrection {
  Vec3 acc_bias = Vec3::Zero();    // [m/s^2]
  Vec3 gyro_bias = Vec3::Zero();   // [rad/s]
  Vec3 acc_scale = Vec3::Zero();   // [-]
  Vec3 gyro_scale = Vec3::Zero();  // [-]

  void apply(ImuIncrement& imu) const {
    imu.dtheta_b = ((imu.dtheta_b - gyro_bias * imu.dt).array() / (1.0 + gyro_scale.array())).matrix();
    imu.dv_b = ((imu.dv_b - acc_bias * imu.dt).array() / (1.0 + acc_scale.array())).matrix();
  }
};

/// Caller-owned output buffers (row-major, any may be null).
struct LooseOutputs {
  // per output sample (n_out rows)
  double* t = nullptr;        // [s]
  double* llh = nullptr;      // (.,3) lat, lon [rad], h [m]
  double* v_n = nullptr;      // (.,3) [m/s]
  double* rpy = nullptr;      // (.,3) [rad]
  double* sigma = nullptr;    // (.,sigma_cols) sqrt(diag P) of the first sigma_cols states
  int sigma_cols = 0;         // <= 0 or >= n_state: all n_state
  double* imu_err = nullptr;  // (.,12) acc bias, gyro bias, acc scale, gyro scale (SI)
  std::int64_t n_out = 0;     // rows written
  // per GNSS record (n_gnss rows)
  double* innovation = nullptr;  // (.,6) INS - GNSS residual before the update (NaN if absent)
  double* nis = nullptr;         // (.)
  std::int8_t* status = nullptr; // 0 not used, 1 applied, 2 rejected by gate, 3 S not PD, 4 outside IMU span
  // run summary
  int updates = 0, rejected = 0, cholesky_repairs = 0;
};

template <class Filter>
class LooseEngine {
 public:
  using L = typename Filter::Layout;

  /// ut is used by the sigma-point filters (RB-UKF, UKF) and ignored by the EKF.
  LooseEngine(const ImuErrorModel& model, const LooseConfig& cfg, const UtParams& ut = {})
      : filter_(make_filter(model, ut)), cfg_(cfg) {}

  Filter& filter() { return filter_; }

  static Filter make_filter(const ImuErrorModel& model, const UtParams& ut) {
    if constexpr (std::is_constructible_v<Filter, const ImuErrorModel&, const UtParams&>)
      return Filter(model, ut);
    else
      return Filter(model);
  }

  /// Run over n IMU samples (t, dtheta_b (n,3), dv_b (n,3)) and m GNSS fixes
  /// sorted by time.  initial is valid at initial.t (<= t[0]).
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0,
           std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
           std::int64_t m, const GnssFix* fixes, LooseOutputs& out) {
    ins_.reset(initial);
    corr_ = corr0;
    filter_.initialize(P0);
    out_cache_dirty_ = true;
    std::int64_t g = 0;
    while (g < m && !(fixes[g].t > initial.t)) mark(out, g++, 4);
    last_t_ = initial.t;
    cycle_start_ = initial.t;
    start_cycle();
    ImuIncrement raw;
    double t_prev = initial.t;
    int until_output = cfg_.output_decimation;  // countdown: no division per sample
    for (std::int64_t k = 0; k < n; ++k) {
      raw.t = t[k];
      raw.dt = t[k] - t_prev;
      raw.dtheta_b = Vec3(dtheta_b[3 * k], dtheta_b[3 * k + 1], dtheta_b[3 * k + 2]);
      raw.dv_b = Vec3(dv_b[3 * k], dv_b[3 * k + 1], dv_b[3 * k + 2]);
      double done = 0.0;  // fraction of this increment already integrated
      while (g < m && fixes[g].t <= raw.t) {
        const double a = (fixes[g].t - t_prev) / raw.dt;  // in (0, 1]
        if (a > done) {
          step(raw, done, a);
          done = a;
        }
        close_cycle();
        apply_fix(fixes[g], g, out);
        ++g;
        start_cycle();
      }
      if (done < 1.0) step(raw, done, 1.0);
      if (ins_.state().t - cycle_start_ >= cfg_.cycle_period - 1e-9) {  // outage: cycle without update
        close_cycle();
        start_cycle();
      }
      if (--until_output == 0 || k + 1 == n) {
        write_output(out);
        until_output = cfg_.output_decimation;
      }
      t_prev = raw.t;
    }
    for (; g < m; ++g) mark(out, g, 4);
    out.cholesky_repairs = filter_.cholesky_repairs();
  }

 private:
  void mark(LooseOutputs& out, std::int64_t g, int st) {
    if (out.status) out.status[g] = static_cast<std::int8_t>(st);
    if (out.nis) out.nis[g] = NAN;
    if (out.innovation)
      for (int i = 0; i < 6; ++i) out.innovation[6 * g + i] = NAN;
  }

  /// Integrate the fraction (a0, a1] of one raw IMU increment.
  void step(const ImuIncrement& raw, double a0, double a1) {
    ImuIncrement imu;
    const double f = a1 - a0;
    imu.dt = raw.dt * f;
    imu.t = raw.t - raw.dt * (1.0 - a1);
    imu.dtheta_b = raw.dtheta_b * f;
    imu.dv_b = raw.dv_b * f;
    corr_.apply(imu);
    ins_.update(imu);
    last_imu_ = imu;  // the rates omega_ib_b_, f_ib_b_ follow when needed (rates())
    rates_stale_ = true;
    const NavState& s = ins_.state();
    const double elapsed = s.t - interval_t0_;
    if (!have_mid_ && elapsed >= 0.5 * cfg_.propagation_interval) {
      set_point(iv_.mid);
      have_mid_ = true;
      t_mid_ = s.t;
    }
    if (elapsed >= cfg_.propagation_interval - 1e-12) flush_interval();
  }

  /// Corrected IMU rates of the last integrated increment (computed on demand:
  /// the filter needs them a few times per propagation interval, not per sample).
  void rates() {
    if (!rates_stale_) return;
    omega_ib_b_ = last_imu_.dtheta_b / last_imu_.dt;
    f_ib_b_ = last_imu_.dv_b / last_imu_.dt;
    rates_stale_ = false;
  }

  void set_point(InsPoint& p) {
    rates();
    const NavState& s = ins_.state();
    p.set(s.lat, s.h, s.v_n, s.q_nb.toRotationMatrix(), f_ib_b_, omega_ib_b_);
  }

  /// Hand the filter the interval (interval_t0_, now].
  void flush_interval() {
    const NavState& s = ins_.state();
    iv_.dt = s.t - interval_t0_;
    if (iv_.dt <= 0.0) return;
    set_point(iv_.end);
    if (!have_mid_) {  // a single short step: the middle is the mean of the ends
      iv_.mid = iv_.end;
      iv_.mid.lat = 0.5 * (iv_.start.lat + iv_.end.lat);
      iv_.mid.h = 0.5 * (iv_.start.h + iv_.end.h);
      iv_.mid.v_n = 0.5 * (iv_.start.v_n + iv_.end.v_n);
      iv_.mid.earth.evaluate(iv_.mid.lat, iv_.mid.h, iv_.mid.v_n);
    }
    filter_.propagate(iv_);
    out_cache_dirty_ = true;
    iv_.start = iv_.end;
    interval_t0_ = s.t;
    have_mid_ = false;
  }

  void start_cycle() {
    cycle_start_ = ins_.state().t;
    interval_t0_ = cycle_start_;
    set_point(iv_.start);
    have_mid_ = false;
    filter_.begin_cycle();
  }

  void close_cycle() {
    flush_interval();
    filter_.end_cycle();
    out_cache_dirty_ = true;
  }

  void apply_fix(const GnssFix& fix_in, std::int64_t g, LooseOutputs& out) {
    GnssFix fix = fix_in;
    fix.has_pos = fix.has_pos && cfg_.use_position;
    fix.has_vel = fix.has_vel && cfg_.use_velocity;
    if (!fix.has_pos && !fix.has_vel) {
      mark(out, g, 0);
      return;
    }
    rates();
    meas_.set(ins_.state(), omega_ib_b_, cfg_.lever_arm_b, fix);
    if (out.innovation) {
      const auto& r = meas_.linear().residual;
      for (int i = 0; i < 6; ++i) out.innovation[6 * g + i] = NAN;
      const int off = fix.has_pos ? 0 : 3;
      for (int i = 0; i < r.size(); ++i) out.innovation[6 * g + off + i] = r[i];
    }
    const UpdateResult res = filter_.update(meas_, cfg_.gate_chi2);
    out_cache_dirty_ = true;
    if (out.nis) out.nis[g] = res.nis;
    int st = res.applied ? 1 : (res.rejected_by_gate ? 2 : 3);
    if (out.status) out.status[g] = static_cast<std::int8_t>(st);
    if (res.applied) {
      ++out.updates;
      feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
  }

  /// Closed loop: correct the INS and the IMU corrections with x, then x = 0.
  void feedback() {
    const StateVec<L>& x = filter_.x();
    NavState s = ins_.state();
    const wgs84::Radii r = wgs84::radii(s.lat);
    s.lat -= x[L::kPos] / (r.R_M + s.h);
    s.lon -= x[L::kPos + 1] / ((r.R_N + s.h) * std::cos(s.lat));
    s.h += x[L::kPos + 2];
    s.v_n -= x.template segment<3>(L::kVel);
    // C_nb(true) = C_{n n'} C_{n' b}, C_{n n'} = dcm_from_euler(psi) (layout.hpp)
    s.q_nb = (quat_from_euler(x.template segment<3>(L::kAtt)) * s.q_nb).normalized();
    corr_.acc_bias += x.template segment<3>(L::kAccBias);
    corr_.gyro_bias += x.template segment<3>(L::kGyroBias);
    if constexpr (kHasScale<L>) {
      corr_.acc_scale += x.template segment<3>(L::kAccScale);
      corr_.gyro_scale += x.template segment<3>(L::kGyroScale);
    }
    ins_.set_state(s);
    filter_.reset_state();
  }

  void write_output(LooseOutputs& out) {
    const std::int64_t i = out.n_out++;
    const NavState& s = ins_.state();
    if (out.t) out.t[i] = s.t;
    // x is zero after every feedback; between feedbacks (GNSS outage with a
    // sigma-point filter's non-zero predicted mean) report the corrected state.
    const StateVec<L>& x = filter_.x();
    const bool corrected = !x.template head<9>().isZero(0.0);
    double lat = s.lat, lon = s.lon, h = s.h;
    Vec3 v = s.v_n;
    Quat q = s.q_nb;
    if (corrected) {
      const wgs84::Radii r = wgs84::radii(s.lat);
      lat = s.lat - x[L::kPos] / (r.R_M + s.h);
      lon = s.lon - x[L::kPos + 1] / ((r.R_N + s.h) * std::cos(s.lat));
      h = s.h + x[L::kPos + 2];
      v = s.v_n - x.template segment<3>(L::kVel);
      q = quat_from_euler(x.template segment<3>(L::kAtt)) * s.q_nb;
    }
    if (out.llh) {
      out.llh[3 * i] = lat;
      out.llh[3 * i + 1] = lon;
      out.llh[3 * i + 2] = h;
    }
    if (out.v_n)
      for (int j = 0; j < 3; ++j) out.v_n[3 * i + j] = v[j];
    if (out.rpy) {
      const Vec3 e = euler_from_quat(q);
      for (int j = 0; j < 3; ++j) out.rpy[3 * i + j] = e[j];
    }
    if (out_cache_dirty_) {  // P, x and the corrections change only at propagate/update/feedback
      sigma_ = filter_.P().diagonal().cwiseMax(0.0).cwiseSqrt();
      for (int j = 0; j < 3; ++j) {
        imu_err_[j] = corr_.acc_bias[j] + x[L::kAccBias + j];
        imu_err_[3 + j] = corr_.gyro_bias[j] + x[L::kGyroBias + j];
        imu_err_[6 + j] = corr_.acc_scale[j] + (kHasScale<L> ? x[L::kAccScale >= 0 ? L::kAccScale + j : 0] : 0.0);
        imu_err_[9 + j] = corr_.gyro_scale[j] + (kHasScale<L> ? x[L::kGyroScale >= 0 ? L::kGyroScale + j : 0] : 0.0);
      }
      out_cache_dirty_ = false;
    }
    if (out.sigma) {
      const int nc = (out.sigma_cols > 0 && out.sigma_cols < L::kSize) ? out.sigma_cols : L::kSize;
      for (int j = 0; j < nc; ++j) out.sigma[nc * i + j] = sigma_[j];
    }
    if (out.imu_err)
      for (int j = 0; j < 12; ++j) out.imu_err[12 * i + j] = imu_err_[j];
  }

  Filter filter_;
  LooseConfig cfg_;
  Strapdown ins_;
  ImuCorrection corr_;
  LooseMeasurement<L> meas_;
  InsInterval iv_;
  Vec3 omega_ib_b_ = Vec3::Zero(), f_ib_b_ = Vec3::Zero();
  ImuIncrement last_imu_;     // last corrected increment integrated
  bool rates_stale_ = false;  // omega_ib_b_, f_ib_b_ not yet taken from last_imu_
  double last_t_ = 0.0, cycle_start_ = 0.0, interval_t0_ = 0.0, t_mid_ = 0.0;
  bool have_mid_ = false;
  StateVec<L> sigma_ = StateVec<L>::Zero();    // output cache: sqrt(diag P)
  Eigen::Matrix<double, 12, 1> imu_err_ = Eigen::Matrix<double, 12, 1>::Zero();  // and the IMU errors
  bool out_cache_dirty_ = true;   // P, x or the corrections changed since the cache was filled
};

}  // namespace insnav
