// insnav/engine/tight_engine.hpp -- closed-loop tightly coupled GNSS/INS run
// (seed 003 tight: 17 states, pseudorange and pseudorange rate per satellite).
//
// Same structure and timing as LooseEngine (loose_engine.hpp): a filter cycle
// spans one GNSS period, the error state is propagated over intervals of
// about `propagation_interval`, a GNSS epoch valid at t_g inside an IMU
// interval is applied exactly at t_g by splitting the IMU increment, and the
// estimate is fed back into the INS, the IMU corrections and the receiver
// clock.  An epoch with no satellite closes the cycle and predicts only (no
// update).  The receiver clock estimate (bias b [m], drift d [m/s]) is carried
// here and propagated as b += d dt between epochs; the filter's clock states
// are its errors (computed - true), fed back like the others.
//
// Input: E epochs (time, satellite range [begin, end) into one flat array of
// SatObservation), sorted by time.  No heap allocation inside run().
//
// (A copy of LooseEngine's loop rather than a generalisation of it: the loop
// differs in the measurement, the clock feedback and the outputs, and
// loose_engine.hpp is being changed by other work; the shared pieces,
// ImuCorrection and the filter interface, are reused.)
#pragma once

#include <cmath>
#include <cstdint>
#include <type_traits>

#include "insnav/engine/loose_engine.hpp"
#include "insnav/meas/pseudorange.hpp"

namespace insnav {

struct TightConfig {
  Vec3 lever_arm_b = Vec3::Zero();     // IMU centre -> GNSS antenna, FRD [m]
  double propagation_interval = 0.02;  // error-state propagation step [s]
  double cycle_period = 1.0;           // filter cycle without GNSS [s]
  double gate_chi2 = 0.0;              // NIS gate on the whole epoch (<= 0: off)
  bool use_pseudorange = true;
  bool use_rate = true;
  int output_decimation = 1;
};

/// One GNSS epoch: time of validity and its satellites sats[begin, end).
struct TightEpoch {
  double t = 0.0;
  std::int64_t begin = 0, end = 0;
};

/// Caller-owned output buffers (row-major, any may be null).
struct TightOutputs {
  // per output sample
  double* t = nullptr;
  double* llh = nullptr;      // (.,3)
  double* v_n = nullptr;      // (.,3)
  double* rpy = nullptr;      // (.,3)
  double* sigma = nullptr;    // (.,17)
  double* imu_err = nullptr;  // (.,12)
  double* clock = nullptr;    // (.,2) receiver clock bias [m], drift [m/s] (corrected estimate)
  std::int64_t n_out = 0;
  // per satellite row (M rows)
  double* sat_residual = nullptr;  // (.,2) INS-predicted minus measured pseudorange [m], rate [m/s], before the update
  // per epoch (E rows)
  double* nis = nullptr;
  std::int8_t* status = nullptr;   // 0 no satellite used, 1 applied, 2 rejected by gate, 3 S not PD, 4 outside IMU span
  std::int32_t* rows = nullptr;    // measurement rows used
  int updates = 0, rejected = 0, cholesky_repairs = 0;
};

template <class Filter>
class TightEngine {
 public:
  using L = typename Filter::Layout;
  static_assert(kHasClock<L>, "TightEngine needs a layout with clock states");

  TightEngine(const ImuErrorModel& model, const TightConfig& cfg, const UtParams& ut = {})
      : filter_(make_filter(model, ut)), cfg_(cfg) {}

  Filter& filter() { return filter_; }

  static Filter make_filter(const ImuErrorModel& model, const UtParams& ut) {
    if constexpr (std::is_constructible_v<Filter, const ImuErrorModel&, const UtParams&>)
      return Filter(model, ut);
    else
      return Filter(model);
  }

  /// n IMU samples; E epochs over M satellite rows.  clock0 = (bias [m], drift [m/s]).
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, double clock_bias0,
           double clock_drift0, std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
           std::int64_t n_epochs, const TightEpoch* epochs, const SatObservation* sats, TightOutputs& out) {
    ins_.reset(initial);
    corr_ = corr0;
    clock_bias_ = clock_bias0;
    clock_drift_ = clock_drift0;
    filter_.initialize(P0);
    sats_ = sats;
    std::int64_t g = 0;
    for (; g < n_epochs && !(epochs[g].t > initial.t); ++g) mark(out, epochs[g], g, 4);
    start_cycle();
    ImuIncrement raw;
    double t_prev = initial.t;
    for (std::int64_t k = 0; k < n; ++k) {
      raw.t = t[k];
      raw.dt = t[k] - t_prev;
      raw.dtheta_b = Vec3(dtheta_b[3 * k], dtheta_b[3 * k + 1], dtheta_b[3 * k + 2]);
      raw.dv_b = Vec3(dv_b[3 * k], dv_b[3 * k + 1], dv_b[3 * k + 2]);
      double done = 0.0;
      while (g < n_epochs && epochs[g].t <= raw.t) {
        const double a = (epochs[g].t - t_prev) / raw.dt;
        if (a > done) {
          step(raw, done, a);
          done = a;
        }
        close_cycle();
        apply_epoch(epochs[g], g, out);
        ++g;
        start_cycle();
      }
      if (done < 1.0) step(raw, done, 1.0);
      if (ins_.state().t - cycle_start_ >= cfg_.cycle_period - 1e-9) {
        close_cycle();
        start_cycle();
      }
      if ((k + 1) % cfg_.output_decimation == 0 || k + 1 == n) write_output(out);
      t_prev = raw.t;
    }
    for (; g < n_epochs; ++g) mark(out, epochs[g], g, 4);
    out.cholesky_repairs = filter_.cholesky_repairs();
  }

 private:
  void mark(TightOutputs& out, const TightEpoch& ep, std::int64_t g, int st) {
    if (out.status) out.status[g] = static_cast<std::int8_t>(st);
    if (out.nis) out.nis[g] = NAN;
    if (out.rows) out.rows[g] = 0;
    if (out.sat_residual)
      for (std::int64_t j = ep.begin; j < ep.end; ++j) out.sat_residual[2 * j] = out.sat_residual[2 * j + 1] = NAN;
  }

  void step(const ImuIncrement& raw, double a0, double a1) {
    ImuIncrement imu;
    const double f = a1 - a0;
    imu.dt = raw.dt * f;
    imu.t = raw.t - raw.dt * (1.0 - a1);
    imu.dtheta_b = raw.dtheta_b * f;
    imu.dv_b = raw.dv_b * f;
    corr_.apply(imu);
    ins_.update(imu);
    clock_bias_ += clock_drift_ * imu.dt;
    omega_ib_b_ = imu.dtheta_b / imu.dt;
    f_ib_b_ = imu.dv_b / imu.dt;
    const NavState& s = ins_.state();
    const double elapsed = s.t - interval_t0_;
    if (!have_mid_ && elapsed >= 0.5 * cfg_.propagation_interval) {
      set_point(iv_.mid);
      have_mid_ = true;
    }
    if (elapsed >= cfg_.propagation_interval - 1e-12) flush_interval();
  }

  void set_point(InsPoint& p) {
    const NavState& s = ins_.state();
    p.set(s.lat, s.h, s.v_n, s.q_nb.toRotationMatrix(), f_ib_b_, omega_ib_b_);
  }

  void flush_interval() {
    const NavState& s = ins_.state();
    iv_.dt = s.t - interval_t0_;
    if (iv_.dt <= 0.0) return;
    set_point(iv_.end);
    if (!have_mid_) {
      iv_.mid = iv_.end;
      iv_.mid.lat = 0.5 * (iv_.start.lat + iv_.end.lat);
      iv_.mid.h = 0.5 * (iv_.start.h + iv_.end.h);
      iv_.mid.v_n = 0.5 * (iv_.start.v_n + iv_.end.v_n);
      iv_.mid.earth.evaluate(iv_.mid.lat, iv_.mid.h, iv_.mid.v_n);
    }
    filter_.propagate(iv_);
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
  }

  void apply_epoch(const TightEpoch& ep, std::int64_t g, TightOutputs& out) {
    // copy the epoch's satellites, dropping the observation kinds switched off
    int ns = 0;
    for (std::int64_t j = ep.begin; j < ep.end && ns < kMaxMeasRows; ++j) {
      SatObservation s = sats_[j];
      if (!cfg_.use_pseudorange) s.pseudorange_m = NAN;
      if (!cfg_.use_rate) s.pseudorange_rate_mps = NAN;
      work_[ns] = s;
      src_[ns++] = j;
    }
    meas_.set(ins_.state(), omega_ib_b_, cfg_.lever_arm_b, clock_bias_, clock_drift_, work_, ns);
    const int m = meas_.linear().rows();
    if (out.sat_residual) {
      for (std::int64_t j = ep.begin; j < ep.end; ++j) out.sat_residual[2 * j] = out.sat_residual[2 * j + 1] = NAN;
      int row = 0;
      for (int i = 0; i < ns && row < m; ++i) {
        for (int kind = 0; kind < 2 && row < m; ++kind) {
          const double z = kind == 0 ? work_[i].pseudorange_m : work_[i].pseudorange_rate_mps;
          if (!std::isfinite(z)) continue;
          out.sat_residual[2 * src_[i] + kind] = meas_.linear().residual[row++];
        }
      }
    }
    if (out.rows) out.rows[g] = m;
    if (m == 0) {  // no satellite: prediction only
      if (out.status) out.status[g] = 0;
      if (out.nis) out.nis[g] = NAN;
      return;
    }
    const UpdateResult res = filter_.update(meas_, cfg_.gate_chi2);
    if (out.nis) out.nis[g] = res.nis;
    const int st = res.applied ? 1 : (res.rejected_by_gate ? 2 : 3);
    if (out.status) out.status[g] = static_cast<std::int8_t>(st);
    if (res.applied) {
      ++out.updates;
      feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
  }

  void feedback() {
    const StateVec<L>& x = filter_.x();
    NavState s = ins_.state();
    const wgs84::Radii r = wgs84::radii(s.lat);
    s.lat -= x[L::kPos] / (r.R_M + s.h);
    s.lon -= x[L::kPos + 1] / ((r.R_N + s.h) * std::cos(s.lat));
    s.h += x[L::kPos + 2];
    s.v_n -= x.template segment<3>(L::kVel);
    s.q_nb = (quat_from_euler(x.template segment<3>(L::kAtt)) * s.q_nb).normalized();
    corr_.acc_bias += x.template segment<3>(L::kAccBias);
    corr_.gyro_bias += x.template segment<3>(L::kGyroBias);
    if constexpr (kHasScale<L>) {
      corr_.acc_scale += x.template segment<3>(L::kAccScale);
      corr_.gyro_scale += x.template segment<3>(L::kGyroScale);
    }
    clock_bias_ -= x[L::kClockBias];
    clock_drift_ -= x[L::kClockDrift];
    ins_.set_state(s);
    filter_.reset_state();
  }

  void write_output(TightOutputs& out) {
    const std::int64_t i = out.n_out++;
    const NavState& s = ins_.state();
    if (out.t) out.t[i] = s.t;
    const StateVec<L>& x = filter_.x();
    const wgs84::Radii r = wgs84::radii(s.lat);
    if (out.llh) {
      out.llh[3 * i] = s.lat - x[L::kPos] / (r.R_M + s.h);
      out.llh[3 * i + 1] = s.lon - x[L::kPos + 1] / ((r.R_N + s.h) * std::cos(s.lat));
      out.llh[3 * i + 2] = s.h + x[L::kPos + 2];
    }
    if (out.v_n) {
      const Vec3 v = s.v_n - x.template segment<3>(L::kVel);
      for (int j = 0; j < 3; ++j) out.v_n[3 * i + j] = v[j];
    }
    if (out.rpy) {
      const Vec3 e = euler_from_quat(quat_from_euler(x.template segment<3>(L::kAtt)) * s.q_nb);
      for (int j = 0; j < 3; ++j) out.rpy[3 * i + j] = e[j];
    }
    if (out.sigma) {
      const auto& P = filter_.P();
      for (int j = 0; j < L::kSize; ++j) out.sigma[L::kSize * i + j] = std::sqrt(std::max(P(j, j), 0.0));
    }
    if (out.imu_err) {
      double* e = out.imu_err + 12 * i;
      for (int j = 0; j < 3; ++j) {
        e[j] = corr_.acc_bias[j] + x[L::kAccBias + j];
        e[3 + j] = corr_.gyro_bias[j] + x[L::kGyroBias + j];
        e[6 + j] = corr_.acc_scale[j];
        e[9 + j] = corr_.gyro_scale[j];
      }
    }
    if (out.clock) {
      out.clock[2 * i] = clock_bias_ - x[L::kClockBias];
      out.clock[2 * i + 1] = clock_drift_ - x[L::kClockDrift];
    }
  }

  Filter filter_;
  TightConfig cfg_;
  Strapdown ins_;
  ImuCorrection corr_;
  TightMeasurement<L> meas_;
  SatObservation work_[kMaxMeasRows];
  std::int64_t src_[kMaxMeasRows] = {};
  const SatObservation* sats_ = nullptr;
  InsInterval iv_;
  Vec3 omega_ib_b_ = Vec3::Zero(), f_ib_b_ = Vec3::Zero();
  double clock_bias_ = 0.0, clock_drift_ = 0.0;
  double cycle_start_ = 0.0, interval_t0_ = 0.0;
  bool have_mid_ = false;
};

}  // namespace insnav
