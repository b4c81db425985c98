// insnav/engine/tight_engine.hpp -- closed-loop tightly coupled GNSS/INS run
// (seed 003 tight: 17 states, pseudorange and pseudorange rate per satellite;
// seed 004's 20-state particle filters).
//
// Timing, feedback (INS, IMU corrections and the receiver clock) and outputs
// are the closed-loop core's (closed_loop.hpp); an epoch valid at t_g is
// applied exactly at t_g.  The receiver clock estimate (bias b [m], drift d
// [m/s]) is carried by the core and propagated as b += d dt; the filter's
// clock states are its errors (computed - true), fed back like the others.
// An epoch with no satellite closes the cycle and predicts only (no update).
//
// Input: E epochs (time, satellite range [begin, end) into one flat array of
// SatObservation), sorted by time.  No heap allocation inside run().
#pragma once

#include <cmath>
#include <cstdint>

#include "insnav/engine/closed_loop.hpp"
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

/// Caller-owned output buffers (row-major, any may be null): the per-sample
/// rows of NavOutputs (with `clock`), plus
struct TightOutputs : NavOutputs {
  // per satellite row (M rows)
  double* sat_residual = nullptr;  // (.,2) INS-predicted minus measured pseudorange [m], rate [m/s], before the update
  // per epoch (E rows)
  double* nis = nullptr;
  std::int8_t* status = nullptr;   // RecordStatus
  std::int32_t* rows = nullptr;    // measurement rows used

  void mark(const TightEpoch& ep, std::int64_t g, RecordStatus st) {
    set_status(status, g, st);
    if (nis) nis[g] = NAN;
    if (rows) rows[g] = 0;
    if (sat_residual)
      for (std::int64_t j = ep.begin; j < ep.end; ++j) sat_residual[2 * j] = sat_residual[2 * j + 1] = NAN;
  }
};

template <class Filter>
class TightEngine {
 public:
  using L = typename Filter::Layout;
  static_assert(kHasClock<L>, "TightEngine needs a layout with clock states");

  TightEngine(const ImuErrorModel& model, const TightConfig& cfg, const UtParams& ut = {})
      : core_(make_filter<Filter>(model, ut), cfg.propagation_interval), cfg_(cfg) {}

  Filter& filter() { return core_.filter; }

  /// n IMU samples; E epochs over M satellite rows.  clock0 = (bias [m], drift [m/s]).
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, double clock_bias0,
           double clock_drift0, std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
           std::int64_t n_epochs, const TightEpoch* epochs, const SatObservation* sats, TightOutputs& out) {
    core_.reset(initial, P0, corr0, clock_bias0, clock_drift0);
    sats_ = sats;
    std::int64_t g = 0;
    for (; g < n_epochs && !(epochs[g].t > initial.t); ++g) out.mark(epochs[g], g, RecordStatus::kOutsideImuSpan);
    core_.run_samples(initial.t, n, t, dtheta_b, dv_b, g, n_epochs, cfg_.cycle_period, cfg_.output_decimation, out,
                      [&](std::int64_t i) { return epochs[i].t; },
                      [&](std::int64_t i) { apply_epoch(epochs[i], i, out); });
    for (; g < n_epochs; ++g) out.mark(epochs[g], g, RecordStatus::kOutsideImuSpan);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
  }

 private:
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
    meas_.set(core_.state(), core_.omega_ib_b(), cfg_.lever_arm_b, core_.clock_bias, core_.clock_drift, work_, ns);
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
      out.set_status(out.status, g, RecordStatus::kNotUsed);
      if (out.nis) out.nis[g] = NAN;
      return;
    }
    const UpdateResult res = core_.update(meas_, cfg_.gate_chi2);
    if (out.nis) out.nis[g] = res.nis;
    out.set_status(out.status, g, status_of(res));
    if (res.applied) {
      ++out.updates;
      core_.feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
  }

  ClosedLoop<Filter> core_;
  TightConfig cfg_;
  TightMeasurement<L> meas_;
  SatObservation work_[kMaxMeasRows];
  std::int64_t src_[kMaxMeasRows] = {};
  const SatObservation* sats_ = nullptr;
};

}  // namespace insnav
