// insnav/engine/loose_engine.hpp -- closed-loop loosely coupled GNSS/INS run:
// mechanization at the IMU rate, the error-state filter at GNSS epochs, each
// fix applied at its own time of validity (timing and feedback:
// closed_loop.hpp).  The engine's own part is the fix: lever arm, position
// and/or velocity rows, gate, and the per-record outputs.
//
// Vehicle constraints (meas/vehicle.hpp) arrive as a second stream of timed
// events, merged with the fixes in time order (a fix first at a tie): each
// event is a non-holonomic constraint (lateral and vertical velocity of the
// rear-axle point zero), an odometer speed, or, while the vehicle stands
// still, a zero-velocity and zero-angular-rate update; the caller decides
// which (e.g. from a StandstillDetector over the IMU samples).  With a layout
// that estimates the odometer scale factor (Layout16Odo) the odometer row also
// carries that state, and the closed-loop core keeps its fed-back estimate.
//
// Adaptive measurement noise of the fixes (filter/adaptive_noise.hpp; EKF and
// RB-UKF, off by default): LooseConfig::adaptive_r.window > 0 scales each
// row's configured variance by the windowed innovation statistics of the past
// applied fixes, clamped to [min_fraction, 1] of it.
//
// Adaptive process noise (filter/adaptive_noise.hpp; EKF only, off by
// default): LooseConfig::adaptive_q.window > 0 scales the configured velocity
// and angle random walk variances by the windowed state corrections of the
// past applied fixes against their predicted covariance (Mohamed & Schwarz
// 1999, K C_v K^T against K S K^T), clamped to
// [adaptive_q.min_fraction, adaptive_q.max_factor].
//
// Standstill level of the process noise (EKF only, off by default):
// LooseConfig::standstill_q_scale = s != 1 multiplies the velocity and angle
// random walk PSDs (the Q of every propagation step, Ekf::
// set_process_noise_scale) by s while the standstill detector says the IMU
// stands still.  The caller marks the detector's state changes as constraint
// events (kStill: stationary from this event on, kMoving: moving from this
// event on; ins/standstill.hpp, the SHOE statistic of Skog et al. 2010, eq.
// (10)); the level holds until the next such event.  Why: a process noise
// tuned on a walker's gait and hand swing (or a car's driving) describes
// motion-induced IMU errors that are absent at rest, so over a standstill it
// makes P- grow faster than the INS actually drifts (an underconfident
// filter); ZUPT / ZARU constrain the velocity and the rate but not that
// growth.  With the adaptive process noise on as well, the two factors
// multiply.  s = 1 (the default) leaves every Q as before, bit for bit.
//
// No heap allocation inside run(); outputs go to caller-owned buffers.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "insnav/engine/closed_loop.hpp"
#include "insnav/filter/adaptive_noise.hpp"
#include "insnav/meas/gnss_loose.hpp"
#include "insnav/meas/vehicle.hpp"

namespace insnav {

struct LooseConfig {
  Vec3 lever_arm_b = Vec3::Zero();   // IMU centre -> GNSS antenna, FRD [m]
  double propagation_interval = 0.02;  // error-state propagation step [s]
  double cycle_period = 1.0;         // filter cycle without GNSS (outage) [s]
  GateConfig gate;                   // innovation gate of the fixes (nis_gate.hpp; on by default)
  bool use_position = true;
  bool use_velocity = true;
  int output_decimation = 1;         // write every k-th IMU sample
  VehicleConstraintConfig vehicle;   // mounting, rear-axle lever arm and noise of the constraint events
  double constraint_gate_chi2 = 0.0; // NIS gate of the constraint events (<= 0: off)
  AdaptiveNoiseConfig adaptive_r;    // adaptive R of the fixes (filter/adaptive_noise.hpp; window 0: off)
  AdaptiveNoiseConfig adaptive_q{0, 0.05, 20.0};  // adaptive Q scale (velocity, attitude random walks; EKF; 0: off)
  double standstill_q_scale = 1.0;  // factor on the velocity and angle random walk PSDs while stationary (kStill
                                    // events; EKF; 1: off)
};

/// What a vehicle-constraint event asks for (bit flags).  kStill / kMoving
/// carry the standstill detector's state from this event on (the standstill
/// level of the process noise, LooseConfig::standstill_q_scale); an event
/// with only those bits updates nothing (status kNotUsed).
enum ConstraintKind : std::uint8_t { kNhc = 1, kOdometer = 2, kZupt = 4, kZaru = 8, kStill = 16, kMoving = 32 };

/// One vehicle-constraint event at time t: kinds (ConstraintKind flags) and,
/// with kOdometer, the measured forward speed of the rear-axle point [m/s].
struct ConstraintEvent {
  double t = 0.0;
  std::uint8_t kinds = 0;
  double speed_mps = 0.0;
};

/// Caller-owned output buffers (row-major, any may be null): the per-sample
/// rows of NavOutputs plus, per GNSS record (n_gnss rows):
struct LooseOutputs : NavOutputs {
  double* innovation = nullptr;  // (.,6) INS - GNSS residual before the update (NaN if absent)
  double* nis = nullptr;         // (.)
  double* log_det_s = nullptr;   // (.) log det S of the update (NaN if none; insnav.calib.tune's likelihood)
  double* meas_sigma = nullptr;  // (.,6) sqrt of R's diagonal as the update used it (after the adaptive
                                 // scaling; NaN where the fix has no such row or is not used)
  std::int8_t* status = nullptr; // RecordStatus
  // per constraint event (k rows)
  double* constraint_nis = nullptr;
  double* constraint_log_det_s = nullptr;
  std::int8_t* constraint_status = nullptr;  // RecordStatus
  int constraint_updates = 0, constraint_rejected = 0;

  /// A record that is not used for an update: status, NaN innovation and NIS.
  void mark(std::int64_t g, RecordStatus st) {
    set_status(status, g, st);
    if (nis) nis[g] = NAN;
    if (log_det_s) log_det_s[g] = NAN;
    if (innovation)
      for (int i = 0; i < 6; ++i) innovation[6 * g + i] = NAN;
    if (meas_sigma)
      for (int i = 0; i < 6; ++i) meas_sigma[6 * g + i] = NAN;
  }

  /// The residual rows of a fix (position and/or velocity) into its innovation row.
  template <class RowVec>
  void write_innovation(std::int64_t g, const GnssFix& fix, const RowVec& r) {
    if (!innovation) return;
    for (int i = 0; i < 6; ++i) innovation[6 * g + i] = NAN;
    const int off = fix.has_pos ? 0 : 3;
    for (int i = 0; i < r.size(); ++i) innovation[6 * g + off + i] = r[i];
  }

  /// The sigmas of the rows of a fix (sqrt of R's diagonal) into its meas_sigma row.
  template <class RMat>
  void write_meas_sigma(std::int64_t g, const GnssFix& fix, const RMat& R) {
    if (!meas_sigma) return;
    for (int i = 0; i < 6; ++i) meas_sigma[6 * g + i] = NAN;
    const int off = fix.has_pos ? 0 : 3;
    for (int i = 0; i < R.rows(); ++i) meas_sigma[6 * g + off + i] = std::sqrt(R(i, i));
  }
};

/// The fix with the observation kinds switched off by the config removed, and a position or a
/// velocity that is not finite (with its sigmas) taken as absent, as the bindings read a NaN column:
/// a C++ caller's NaN velocity with has_vel left true would otherwise put NaN into the state.
inline GnssFix masked_fix(const GnssFix& in, const LooseConfig& cfg) {
  GnssFix f = in;
  f.has_pos = f.has_pos && cfg.use_position && std::isfinite(f.lat) && std::isfinite(f.lon) && std::isfinite(f.h) &&
              f.sigma_pos_n.allFinite();
  f.has_vel = f.has_vel && cfg.use_velocity && f.v_n.allFinite() && f.sigma_vel_n.allFinite();
  return f;
}

template <class Filter>
class LooseEngine {
 public:
  using L = typename Filter::Layout;

  /// ut is used by the sigma-point filters (RB-UKF, UKF) and ignored by the EKF.
  LooseEngine(const ImuErrorModel& model, const LooseConfig& cfg, const UtParams& ut = {})
      : core_(make_filter<Filter>(model, ut), cfg.propagation_interval),
        cfg_(cfg),
        adaptive_(cfg.adaptive_r),
        adaptive_q_(cfg.adaptive_q) {
    core_.gate = NisGate(cfg.gate);
    core_.odo_scale_tau = model.odo_scale_tau;
  }

  Filter& filter() { return core_.filter; }
  /// Record the forward pass for the RTS smoother (closed_loop.hpp); EKF, RB-UKF, UKF.
  ClosedLoop<Filter>& core() { return core_; }

  /// Run over n IMU samples (t, dtheta_b (n,3), dv_b (n,3)) and m GNSS fixes
  /// sorted by time.  initial is valid at initial.t (<= t[0]).
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0,
           std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
           std::int64_t m, const GnssFix* fixes, LooseOutputs& out) {
    run(initial, P0, corr0, n, t, dtheta_b, dv_b, m, fixes, 0, nullptr, out);
  }

  /// The same with k vehicle-constraint events sorted by time.
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0,
           std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
           std::int64_t m, const GnssFix* fixes, std::int64_t k, const ConstraintEvent* events, LooseOutputs& out) {
    start(initial, P0, corr0);
    std::int64_t g = 0, c = 0;
    // a fix applies at core_.record_time(t_g): t_g - t_d^ with the time-offset state, else t_g
    while (g < m && !(core_.record_time(fixes[g].t) > initial.t)) out.mark(g++, RecordStatus::kOutsideImuSpan);
    while (c < k && !(events[c].t > initial.t)) mark_constraint(out, c++, RecordStatus::kOutsideImuSpan);
    core_.run_events(
        initial.t, n, t, dtheta_b, dv_b, cfg_.cycle_period, cfg_.output_decimation, out,
        [&]() { return std::min(g < m ? core_.record_time(fixes[g].t) : kInf, c < k ? events[c].t : kInf); },
        [&]() {
          if (g < m && (c >= k || core_.record_time(fixes[g].t) <= events[c].t)) {
            apply_fix(fixes[g], g, out);
            ++g;
          } else {
            apply_constraint(events[c], c, out);
            ++c;
          }
        });
    for (; g < m; ++g) out.mark(g, RecordStatus::kOutsideImuSpan);
    for (; c < k; ++c) mark_constraint(out, c, RecordStatus::kOutsideImuSpan);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
    out.gate_reopened = core_.gate.reopened();
    out.gate_outage_accepted = core_.gate.outage_accepted();
  }

  /// Initial self-calibration estimates (layouts with the states, layout.hpp):
  /// time offset t_d [s]; the lever arms start from LooseConfig::lever_arm_b
  /// and VehicleConstraintConfig::lever_arm_b.
  void set_initial_time_offset(double t_d0_s) { core_.time_offset0 = t_d0_s; }

  /// Reset to the initial state (the start of run(); the push API's constructor).
  void start(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0) {
    core_.lever_arm_b0 = cfg_.lever_arm_b;
    core_.odo_lever_b0 = cfg_.vehicle.lever_arm_b;
    core_.reset(initial, P0, corr0);
    adaptive_.reset();
    adaptive_q_.start(core_.filter);
    still_ = false;
    apply_process_noise_scale();
    last_nhc_t_ = last_odo_t_ = -kInf;
  }

  /// The measurement step of fix g, applied now (the INS is at its time of
  /// validity): lever arm, gate, update, feedback; record g's outputs in out.
  void apply_fix(const GnssFix& fix_in, std::int64_t g, LooseOutputs& out) {
    const GnssFix fix = masked_fix(fix_in, cfg_);
    if (!fix.has_pos && !fix.has_vel) {
      out.mark(g, RecordStatus::kNotUsed);
      return;
    }
    if constexpr (kHasTimeOffset<L> || kHasLeverArm<L>) {
      // self-calibration (layout.hpp): the lever-arm estimate, and how far the INS is past the fix's
      // shifted time (0 unless the estimate moved it into the past; meas/gnss_loose.hpp)
      const Vec3& l_b = kHasLeverArm<L> ? core_.lever_arm_b : cfg_.lever_arm_b;
      const double shift = std::max(0.0, core_.state().t - core_.record_time(fix.t));
      if constexpr (kHasLeverArm<L>) meas_.set_lever_arm_rate(core_.omega_ib_b_lever());
      meas_.set(core_.state(), core_.omega_ib_b(), l_b, fix, core_.acceleration_n(), shift);
    } else {
      meas_.set(core_.state(), core_.omega_ib_b(), cfg_.lever_arm_b, fix);
    }
    out.write_innovation(g, fix, meas_.linear().residual);
    const int ch0 = fix.has_pos ? 0 : 3;  // adaptive-noise channel of the first row
    if constexpr (kJacobianUpdate<Filter>) {
      if (adaptive_.enabled()) adapt_noise(ch0);
    }
    out.write_meas_sigma(g, fix, meas_.linear().R);
    adaptive_q_.before_update(core_.filter);
    const UpdateResult res = core_.update_gated(meas_);
    if constexpr (kJacobianUpdate<Filter>) {
      if (adaptive_.enabled() && res.applied)
        for (int i = 0; i < meas_.linear().rows(); ++i) adaptive_.push(ch0 + i, ad_y_[i], ad_hph_[i], ad_r0_[i]);
    }
    if (res.applied) {
      adaptive_q_.after_update(core_.filter);
      apply_process_noise_scale();  // the standstill level on top of the adaptive factors
    }
    if (out.nis) out.nis[g] = res.nis;
    if (out.log_det_s) out.log_det_s[g] = res.log_det_s;
    out.set_status(out.status, g, status_of(res));
    if (res.applied) {
      ++out.updates;
      core_.feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
  }

  /// The current adaptive process-noise factors (velocity, attitude random walk variances; 1, 1 when off).
  const std::array<double, 2>& process_noise_scale() const { return adaptive_q_.scale(); }

  /// True while the last kStill / kMoving event said stationary (the standstill level of Q).
  bool stationary() const { return still_; }

  static void mark_constraint(LooseOutputs& out, std::int64_t c, RecordStatus st) {
    out.set_status(out.constraint_status, c, st);
    if (out.constraint_nis) out.constraint_nis[c] = NAN;
    if (out.constraint_log_det_s) out.constraint_log_det_s[c] = NAN;
  }

  /// The measurement step of constraint event c, applied now (as apply_fix).
  void apply_constraint(const ConstraintEvent& e, std::int64_t c, LooseOutputs& out) {
    const bool zupt = e.kinds & kZupt, zaru = e.kinds & kZaru;
    const bool nhc = e.kinds & kNhc, odo = e.kinds & kOdometer;
    if (e.kinds & (kStill | kMoving)) {  // the detector's state from here on: the process noise's level
      still_ = (e.kinds & kStill) != 0;
      apply_process_noise_scale();
    }
    UpdateResult res;
    if (zupt || zaru) {
      standstill_.set(core_.state(), core_.omega_ib_b(), cfg_.vehicle, zupt, zaru);
      res = core_.update(standstill_, cfg_.constraint_gate_chi2);
    } else if (nhc || odo) {
      // the odometer reading against (1 + s^) times the INS forward speed (meas/vehicle.hpp; s^ = 0
      // for a layout without the scale-factor state)
      if constexpr (kHasOdoLever<L>) {  // the lever-arm estimate of the constrained point (layout.hpp)
        VehicleConstraintConfig v = cfg_.vehicle;
        v.lever_arm_b = core_.odo_lever_b;
        vehicle_.set_lever_arm_rate(core_.omega_ib_b_lever());  // errors-in-variables (meas/vehicle.hpp)
        vehicle_.set(core_.state(), core_.omega_ib_b(), v, nhc, odo ? e.speed_mps : NAN, core_.odo_scale);
      } else {
        vehicle_.set(core_.state(), core_.omega_ib_b(), cfg_.vehicle, nhc, odo ? e.speed_mps : NAN, core_.odo_scale);
      }
      // an update linear in H: R + the covariance of the attitude x velocity error product it leaves out
      // (second-order filter, meas/vehicle.hpp), scaled by the events within its correlation time
      // (NHC rows: the interval between NHC events; odometer row: between odometer events)
      if constexpr (kJacobianUpdate<Filter>) {
        const double tau = cfg_.vehicle.second_order_corr_s;
        auto scale = [&](double t_prev) { return e.t > t_prev ? std::max(1.0, tau / (e.t - t_prev)) : 1.0; };
        vehicle_.add_second_order_noise(core_.filter.P(), scale(last_nhc_t_), scale(last_odo_t_));
      }
      if (nhc) last_nhc_t_ = e.t;
      if (odo) last_odo_t_ = e.t;
      res = core_.update(vehicle_, cfg_.constraint_gate_chi2);
    } else {
      mark_constraint(out, c, RecordStatus::kNotUsed);
      return;
    }
    if (out.constraint_nis) out.constraint_nis[c] = res.nis;
    if (out.constraint_log_det_s) out.constraint_log_det_s[c] = res.log_det_s;
    out.set_status(out.constraint_status, c, status_of(res));
    if (res.applied) {
      ++out.constraint_updates;
      core_.feedback();
    } else if (res.rejected_by_gate) {
      ++out.constraint_rejected;
    }
  }

 private:
  void apply_process_noise_scale() { adaptive_q_.apply_standstill(core_.filter, cfg_.standstill_q_scale, still_); }

  /// The innovation, (H P- H^T)_ii and configured variance of each row of the
  /// fix in meas_ (kept for the window after the update), and R's diagonal
  /// scaled by the window of the past fixes (filter/adaptive_noise.hpp).
  void adapt_noise(int ch0) {
    const auto& lin = meas_.linear();
    const auto hph = hph_diagonal(lin, core_.filter.P());
    const auto& x = core_.filter.x();  // zero after the feedback of the last update (closed loop)
    for (int i = 0; i < lin.rows(); ++i) {
      double hx = 0.0;
      for (int a = 0; a < lin.n_cols; ++a) hx += lin.H(i, a) * x[a];
      ad_y_[i] = lin.residual[i] - hx;
      ad_hph_[i] = hph[i];
      ad_r0_[i] = lin.R(i, i);
      meas_.scale_noise_row(i, adaptive_.factor(ch0 + i));
    }
  }

  ClosedLoop<Filter> core_;
  LooseConfig cfg_;
  AdaptiveMeasurementNoise<6> adaptive_;
  AdaptiveProcessNoise adaptive_q_;  // adaptive Q factors (velocity, attitude random walk)
  std::array<double, 6> ad_y_{}, ad_hph_{}, ad_r0_{};  // the current fix's rows (adapt_noise)
  LooseMeasurement<L> meas_;
  VehicleVelocityMeasurement<L> vehicle_;
  StandstillMeasurement<L> standstill_;
  double last_nhc_t_ = -kInf, last_odo_t_ = -kInf;  // the previous NHC / odometer event [s]
  bool still_ = false;  // the standstill detector's state from the last kStill / kMoving event
};

}  // namespace insnav
