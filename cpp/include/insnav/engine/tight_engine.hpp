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
// Several constellations: a layout with inter-system bias states
// (LayoutTightMulti) carries their estimates in the core like the clock and
// feeds them back; the measurement (pseudorange.hpp) is the same for any mix.
//
// Robust update (meas/robust.hpp, TightConfig::robust): before the update of
// an epoch, a common offset of all pseudorange innovations (a receiver clock
// jump) is moved into the clock estimate, then (screening on) rows whose
// predicted innovation fails the per-row chi-square test are rejected and,
// in such a flagged epoch, the rest are IGG-III (or Huber) down-weighted; a
// satellite whose rows keep failing slowly is caught by a CUSUM and excluded
// for a while; and when the epoch still fails the gate, the satellite with
// the largest w-test statistic is excluded and the epoch re-tested (FDE).
// After an outage (the gate's outage-aware test, nis_gate.hpp) every test
// uses alpha H P H' + R, so the first epochs after it are not screened out
// whole.
//
// TDCP (TightConfig::tdcp, meas/tdcp.hpp; off by default, and then nothing
// below changes): with a PhaseObservation per satellite row (set_phase), the
// time-differenced carrier phase of each satellite tracked at the previous
// epoch is applied first, by stochastic cloning of the previous epoch's error
// state (EKF only: the cycle transition Phi gives the clone's cross-
// covariance), after the clock-jump check and before the pseudorange / rate
// update (which then starts from the TDCP-corrected x); one feedback closes
// the epoch.  Screening: the loss-of-lock indicator, the INS-predicted phase
// change (single frequency: the residual less the epoch's common clock part,
// in cycles) and a per-row chi-square on the clone-augmented S_ii.  With the
// RTS smoother recording, the clone's side of the update (the previous
// epoch's corrected estimate, covariance and cross-covariance) goes into the
// smoother's record (ClosedLoop::clone_update_for_smoother, rts_smoother.hpp).
//
// Gauss-Markov pseudorange errors (TightConfig::pr_gm, meas/pseudorange_gm.hpp;
// off by default, and then nothing below changes; EKF only, batch run(), not
// with TDCP or the smoother): a per-satellite first-order Gauss-Markov state
// b_s [m] in a fixed-capacity block beside the core's states (the RTK/INS
// engine's ambiguity bookkeeping); its estimate is added to the INS-predicted
// pseudorange and the block is folded into the core's update exactly
// (PseudorangeGmBlock::fold / joint_posterior), so the gate, the robust step
// and the NIS see the joint innovation covariance.
//
// Adaptive process noise (TightConfig::adaptive_q, filter/adaptive_noise.hpp;
// EKF only, off by default, and then nothing below changes): the configured
// velocity and angle random walk variances scaled by the windowed state
// corrections of the past applied epochs against their predicted covariance
// (Mohamed & Schwarz 1999, K C_v K^T against K S K^T), the loose engine's
// AdaptiveProcessNoise.  An epoch's correction is the whole of it before the
// one feedback (TDCP rows and the pseudorange / rate update; with pr_gm the
// joint posterior), against tr(P- - P+) over the same span.
//
// Standstill level of the process noise (TightConfig::standstill_q_scale;
// EKF only, off by default): the loose engine's (engine/loose_engine.hpp),
// with the standstill detector's state given per epoch (set_standstill: one
// flag per epoch, from the detector at the epoch's time): the velocity and
// angle random walk PSDs times the factor from a stationary epoch to the
// next epoch.  Factor 1 or no flags: every Q as before, bit for bit.
//
// Input: E epochs (time, satellite range [begin, end) into one flat array of
// SatObservation), sorted by time.  No heap allocation inside run().
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "insnav/engine/closed_loop.hpp"
#include "insnav/filter/adaptive_noise.hpp"
#include "insnav/meas/pseudorange.hpp"
#include "insnav/meas/pseudorange_gm.hpp"
#include "insnav/meas/robust.hpp"
#include "insnav/meas/tdcp.hpp"

namespace insnav {

struct TightConfig {
  Vec3 lever_arm_b = Vec3::Zero();     // IMU centre -> GNSS antenna, FRD [m]
  double propagation_interval = 0.02;  // error-state propagation step [s]
  double cycle_period = 1.0;           // filter cycle without GNSS [s]
  GateConfig gate;                     // innovation gate of the whole epoch (nis_gate.hpp; on by default)
  bool use_pseudorange = true;
  bool use_rate = true;
  int output_decimation = 1;
  RobustConfig robust;                 // clock-jump check, screening and IGG-III (robust.hpp)
  TdcpConfig tdcp;                     // time-differenced carrier phase (tdcp.hpp; off by default, EKF only)
  PseudorangeGmConfig pr_gm;           // Gauss-Markov pseudorange errors (pseudorange_gm.hpp; off by default, EKF only)
  AdaptiveNoiseConfig adaptive_q{0, 0.05, 20.0};  // adaptive Q scale (velocity, attitude random walks; EKF; 0: off)
  double standstill_q_scale = 1.0;  // factor on the velocity and angle random walk PSDs after a stationary epoch
                                    // (set_standstill; EKF; 1: off)
};

/// What the robust step did to one satellite row kind (TightOutputs::sat_flag).
enum class SatFlag : std::int8_t {
  kAbsent = -1,       ///< no such observation (NaN) or switched off
  kUsed = 0,          ///< used with its own sigma
  kDownWeighted = 1,  ///< IGG-III: sigma inflated
  kRejected = 2,      ///< screened out
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
                                   // (after a detected clock jump was moved into the clock)
  std::int8_t* sat_flag = nullptr; // (.,2) SatFlag of the pseudorange and the rate
  // per epoch (E rows)
  double* nis = nullptr;
  double* log_det_s = nullptr;     // log det S of the epoch's update (NaN if none; insnav.calib.tune)
  std::int8_t* status = nullptr;   // RecordStatus
  std::int32_t* rows = nullptr;    // measurement rows used
  double* clock_jump = nullptr;    // receiver clock jump moved into the clock estimate [m] (0: none)
  // run counters of the robust step
  int rejected_sats = 0;           // satellite-epochs with a rejected row
  int downweighted_sats = 0;       // satellite-epochs down-weighted (and none of their rows rejected)
  int flagged_epochs = 0;          // epochs the screening flagged
  int clock_jumps = 0;             // clock jumps absorbed
  int fde_excluded = 0;            // satellite-epochs excluded by the whole-epoch FDE
  int cusum_alarms = 0;            // CUSUM alarms (a row kind of a satellite excluded for cusum_hold_s)
  int cusum_excluded = 0;          // satellite rows left out while a CUSUM exclusion held
  int variance_inflated[2] = {0, 0};  // epochs whose pseudorange / rate R the variance factor scaled (robust.hpp, 0.)
  // TDCP (TightConfig::tdcp): per satellite row (M) and per epoch (E), and run counters
  double* tdcp_residual = nullptr; // (M,) INS-predicted minus measured phase change [m], before the update
  std::int8_t* tdcp_flag = nullptr;  // (M,) TdcpFlag
  std::int32_t* tdcp_rows = nullptr; // (E,) TDCP rows used
  int tdcp_used = 0;               // rows used
  int tdcp_rejected = 0;           // rows rejected by the per-row chi-square
  int tdcp_slips_lli = 0;          // rows dropped for the loss-of-lock indicator
  int tdcp_slips_ins = 0;          // rows flagged by the INS-predicted phase-change test
  int tdcp_updates = 0;            // epochs with a TDCP update

  void mark(const TightEpoch& ep, std::int64_t g, RecordStatus st) {
    set_status(status, g, st);
    if (nis) nis[g] = NAN;
    if (log_det_s) log_det_s[g] = NAN;
    if (rows) rows[g] = 0;
    if (clock_jump) clock_jump[g] = 0.0;
    if (sat_residual)
      for (std::int64_t j = ep.begin; j < ep.end; ++j) sat_residual[2 * j] = sat_residual[2 * j + 1] = NAN;
    if (sat_flag)
      for (std::int64_t j = ep.begin; j < ep.end; ++j)
        sat_flag[2 * j] = sat_flag[2 * j + 1] = static_cast<std::int8_t>(SatFlag::kAbsent);
    if (tdcp_rows) tdcp_rows[g] = 0;
    for (std::int64_t j = ep.begin; j < ep.end; ++j) {
      if (tdcp_residual) tdcp_residual[j] = NAN;
      if (tdcp_flag) tdcp_flag[j] = static_cast<std::int8_t>(TdcpFlag::kAbsent);
    }
  }
};

/// Filters whose x and P an update outside update() may write and whose
/// cycle transition is tracked (the EKF: the TDCP clone update, tdcp.hpp).
template <class F, class = void>
struct TdcpCapable : std::false_type {};
template <class F>
struct TdcpCapable<F, std::void_t<decltype(std::declval<F&>().x_mutable()), decltype(std::declval<F&>().P_mutable()),
                                  decltype(std::declval<const F&>().cycle_transition())>> : std::true_type {};

template <class Filter>
class TightEngine {
 public:
  using L = typename Filter::Layout;
  static_assert(kHasClock<L>, "TightEngine needs a layout with clock states");

  TightEngine(const ImuErrorModel& model, const TightConfig& cfg, const UtParams& ut = {})
      : core_(make_filter<Filter>(model, ut), cfg.propagation_interval), cfg_(cfg), adaptive_q_(cfg.adaptive_q) {
    core_.gate = NisGate(cfg.gate);
  }

  Filter& filter() { return core_.filter; }
  ClosedLoop<Filter>& core() { return core_; }

  /// The filters that take TDCP rows (an EKF: x and P writable, the cycle transition tracked).
  static constexpr bool kCanTdcp = TdcpCapable<Filter>::value;
  /// The filters that carry the Gauss-Markov pseudorange block (the cycle transition tracked: the EKF).
  static constexpr bool kCanGm = TdcpCapable<Filter>::value;
  bool gm_on() const { return kCanGm && cfg_.pr_gm.enabled(); }

  /// The current adaptive process-noise factors (velocity, attitude random walk variances; 1, 1 when off).
  const std::array<double, 2>& process_noise_scale() const { return adaptive_q_.scale(); }

  /// Carrier phase of the satellite rows (parallel to `sats` of run(); null: no TDCP rows).
  void set_phase(const PhaseObservation* phase) { phase_ = phase; }

  /// The standstill detector's state per epoch of run() (non-zero: stationary; null: none), for the
  /// standstill level of the process noise (TightConfig::standstill_q_scale).
  void set_standstill(const std::uint8_t* epoch_still) { epoch_still_ = epoch_still; }

  /// Initial inter-system bias estimates [m] of systems 1..3 (layouts with ISB states; default 0).
  void set_initial_isb(const IsbVec& isb0) { isb0_ = isb0; }

  /// n IMU samples; E epochs over M satellite rows.  clock0 = (bias [m], drift [m/s]).
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, double clock_bias0,
           double clock_drift0, std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
           std::int64_t n_epochs, const TightEpoch* epochs, const SatObservation* sats, TightOutputs& out) {
    start(initial, P0, corr0, clock_bias0, clock_drift0);
    sats_ = sats;
    std::int64_t g = 0;
    // an epoch applies at core_.record_time(t_g): t_g - t_d^ with the time-offset state, else t_g
    for (; g < n_epochs && !(core_.record_time(epochs[g].t) > initial.t); ++g)
      out.mark(epochs[g], g, RecordStatus::kOutsideImuSpan);
    if (gm_on()) {  // the core's loop, with the block's cross-covariance carried over outage cycles
      const auto next_t = [&]() { return g < n_epochs ? core_.record_time(epochs[g].t) : kInf; };
      const auto apply_next = [&]() {
        const std::int64_t i = g++;
        apply_epoch(epochs[i], i, out);
      };
      double t_prev = initial.t;
      int until_output = cfg_.output_decimation;
      for (std::int64_t k = 0; k < n; ++k) {
        if (out.stop_requested(k, n)) break;
        const ImuIncrement raw = raw_imu_sample(k, t_prev, t, dtheta_b, dv_b);
        core_.process_sample(raw, t_prev, kInf, next_t, apply_next);
        if (core_.outage_due(cfg_.cycle_period)) {
          core_.close_cycle();
          if constexpr (kCanGm) gm_.carry_cycle(core_.filter.cycle_transition());
          core_.start_cycle();
        }
        if (--until_output == 0 || k + 1 == n) {
          core_.write_output(out);
          until_output = cfg_.output_decimation;
        }
        t_prev = raw.t;
      }
    } else {
      core_.run_samples(initial.t, n, t, dtheta_b, dv_b, g, n_epochs, cfg_.cycle_period, cfg_.output_decimation, out,
                        [&](std::int64_t i) { return core_.record_time(epochs[i].t); },
                        [&](std::int64_t i) { apply_epoch(epochs[i], i, out); });
    }
    for (; g < n_epochs; ++g) out.mark(epochs[g], g, RecordStatus::kOutsideImuSpan);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
    out.gate_reopened = core_.gate.reopened();
    out.gate_outage_accepted = core_.gate.outage_accepted();
  }

  /// Reset to the initial state (the start of run(); the push API's constructor).
  /// Initial time offset t_d [s] (layouts with the state, layout.hpp); the
  /// lever arm starts from TightConfig::lever_arm_b.
  void set_initial_time_offset(double t_d0_s) { core_.time_offset0 = t_d0_s; }

  void start(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, double clock_bias0,
             double clock_drift0) {
    core_.lever_arm_b0 = cfg_.lever_arm_b;
    core_.reset(initial, P0, corr0, clock_bias0, clock_drift0, isb0_);
    adaptive_q_.start(core_.filter);
    still_ = false;
    apply_process_noise_scale();
    var_epochs_ = 0;  // the variance factor's window (robust.hpp, 0.)
    for (int i = 0; i < kSatKeys; ++i) {  // the per-satellite CUSUM of the robust step (robust.hpp, 4.)
      cusum_pos_[i] = cusum_neg_[i] = 0.0;
      excluded_until_[i] = -kInf;
    }
    if constexpr (kCanTdcp) {
      have_prev_ = false;
      epoch_count_ = 0;
      for (int i = 0; i < kTdcpKeys; ++i) prev_epoch_[i] = -1;
      if (cfg_.tdcp.enabled) core_.filter.track_cycle_transition(true);
    }
    if constexpr (kCanGm) {
      gm_.reset(cfg_.pr_gm);
      if (gm_on()) core_.filter.track_cycle_transition(true);
    }
  }

  /// The measurement step of epoch g over sats[ep.begin, ep.end), applied now
  /// (the INS is at its time of validity; the push API, navigator.hpp).
  void apply_epoch(const SatObservation* sats, const TightEpoch& ep, std::int64_t g, TightOutputs& out) {
    sats_ = sats;
    apply_epoch(ep, g, out);
  }

 private:
  void apply_epoch(const TightEpoch& ep, std::int64_t g, TightOutputs& out) {
    ep_t_ = ep.t;
    if (epoch_still_) {  // the level of Q from this epoch to the next (Q enters at the propagation only)
      still_ = epoch_still_[g] != 0;
      apply_process_noise_scale();
    }
    // copy the epoch's satellites, dropping the observation kinds switched off
    int ns = 0;
    for (std::int64_t j = ep.begin; j < ep.end && ns < kMaxMeasRows; ++j) {
      SatObservation s = sats_[j];
      if (!cfg_.use_pseudorange) s.pseudorange_m = NAN;
      if (!cfg_.use_rate) s.pseudorange_rate_mps = NAN;
      work_[ns] = s;
      src_[ns++] = j;
    }
    if constexpr (kCanGm)
      if (gm_on()) gm_begin_epoch(ns);
    const RobustConfig& rc = cfg_.robust;
    const double t_ep = core_.state().t;
    const bool outage = core_.gate.outage_aware(t_ep);
    const double alpha = outage ? core_.gate.config().mismatch : 1.0;
    for (int i = 0; i < ns; ++i) cut_[2 * i] = cut_[2 * i + 1] = false;
    if (rc.screening && rc.cusum_h > 0.0)  // rows a CUSUM alarm excluded (robust.hpp, 4.)
      for (int i = 0; i < ns; ++i)
        for (int kind = 0; kind < 2; ++kind) {
          double& z = kind == 0 ? work_[i].pseudorange_m : work_[i].pseudorange_rate_mps;
          if (std::isfinite(z) && excluded_until_[sat_key(work_[i], kind)] > t_ep) {
            z = NAN;
            cut_[2 * i + kind] = true;
            ++out.cusum_excluded;
          }
        }
    set_measurement(ns);
    double jump = 0.0;
    if (rc.clock_jump && meas_.linear().rows() > 0) {
      standardize(1.0);
      jump = common_pseudorange_offset();
      if (jump != 0.0) {
        core_.clock_bias -= jump;  // residual = predicted - measured: a jump J of the receiver shows as -J
        ++out.clock_jumps;
        set_measurement(ns);
      }
    }
    if (out.clock_jump) out.clock_jump[g] = -jump;
    if (rc.screening && rc.variance_window > 0 && !outage && meas_.linear().rows() > 0)
      apply_variance_factor(ns, out);  // robust.hpp, 0.: before the tests, which are in units of R
    adaptive_q_.before_update(core_.filter);  // P- of the epoch (before its TDCP rows, if any)
    if constexpr (kCanTdcp) tdcp_step(ep, g, out);
    const int m0 = meas_.linear().rows();
    for (int i = 0; i < ns; ++i)
      for (int kind = 0; kind < 2; ++kind) flag_[2 * i + kind] = cut_[2 * i + kind] ? SatFlag::kRejected : SatFlag::kAbsent;
    {
      int row = 0;
      for (int i = 0; i < ns && row < m0; ++i)
        for (int kind = 0; kind < 2 && row < m0; ++kind)
          if (std::isfinite(kind == 0 ? work_[i].pseudorange_m : work_[i].pseudorange_rate_mps)) {
            row_sat_[row] = i;
            row_kind_[row++] = kind;
            flag_[2 * i + kind] = SatFlag::kUsed;
          }
    }
    if (out.sat_residual) {
      for (std::int64_t j = ep.begin; j < ep.end; ++j) out.sat_residual[2 * j] = out.sat_residual[2 * j + 1] = NAN;
      for (int r = 0; r < m0; ++r) out.sat_residual[2 * src_[row_sat_[r]] + row_kind_[r]] = meas_.linear().residual[r];
    }
    if (rc.screening && m0 > 0) {
      screen_and_weight(ns, alpha, !outage, t_ep, out);
      if (rc.fde_max_sats > 0) exclude_faults(ns, alpha, out);
    }
    if (rc.screening)  // satellites with a rejected (screened, CUSUM-held or FDE-excluded) or down-weighted row
      for (int i = 0; i < ns; ++i) {
        const SatFlag a = flag_[2 * i], b = flag_[2 * i + 1];
        if (a == SatFlag::kRejected || b == SatFlag::kRejected) ++out.rejected_sats;
        else if (a == SatFlag::kDownWeighted || b == SatFlag::kDownWeighted) ++out.downweighted_sats;
      }
    if (out.sat_flag) {
      for (std::int64_t j = ep.begin; j < ep.end; ++j)
        out.sat_flag[2 * j] = out.sat_flag[2 * j + 1] = static_cast<std::int8_t>(SatFlag::kAbsent);
      for (int i = 0; i < ns; ++i)
        for (int kind = 0; kind < 2; ++kind) out.sat_flag[2 * src_[i] + kind] = static_cast<std::int8_t>(flag_[2 * i + kind]);
    }
    const int m = meas_.linear().rows();
    if (out.rows) out.rows[g] = m;
    if (m == 0) {  // no satellite (or every row screened out): prediction only
      const bool screened = m0 > 0;
      out.set_status(out.status, g, screened ? RecordStatus::kRejectedByGate : RecordStatus::kNotUsed);
      if (screened) ++out.rejected;
      if (out.nis) out.nis[g] = NAN;
      if (out.log_det_s) out.log_det_s[g] = NAN;
      if constexpr (kCanTdcp) tdcp_close(ep);
      return;
    }
    if constexpr (kCanGm)
      if (gm_on()) {
        gm_Pxx_prior_ = core_.filter.P();
        gm_reopened_ = core_.gate.reopened();
      }
    const UpdateResult res = core_.update_gated(meas_);
    if constexpr (kCanGm)
      if (gm_on() && res.applied) gm_end_update();
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
    if constexpr (kCanTdcp) tdcp_close(ep);
  }

  // ---------------------------------------------------------------- TDCP (meas/tdcp.hpp)
  static int tdcp_key(const SatObservation& s) { return (s.system & 3) * 64 + (s.prn & 63); }

  /// The TDCP update of this epoch against the previous one (stochastic cloning, tdcp.hpp).
  void tdcp_step(const TightEpoch& ep, std::int64_t g, TightOutputs& out) {
    if (out.tdcp_rows) out.tdcp_rows[g] = 0;
    for (std::int64_t j = ep.begin; j < ep.end; ++j) {
      if (out.tdcp_residual) out.tdcp_residual[j] = NAN;
      if (out.tdcp_flag) out.tdcp_flag[j] = static_cast<std::int8_t>(TdcpFlag::kAbsent);
    }
    if (!cfg_.tdcp.enabled || !phase_) return;
    // chained: the filter cycle began at the previous epoch (no outage cycle closed between)
    if (!have_prev_ || core_.cycle_start != t_prev_) return;
    // the INS is max(0, state time - applied time) past the epoch, as for the code rows (set_measurement)
    const TdcpAntenna cur = tdcp_antenna_now(std::max(0.0, core_.state().t - core_.record_time(ep_t_)));
    tdcp_.clear();
    int n = 0;
    for (std::int64_t j = ep.begin; j < ep.end && !tdcp_.full(); ++j) {
      const SatObservation& s = sats_[j];
      const PhaseObservation& p = phase_[j];
      if (s.prn <= 0 || !std::isfinite(p.phase_m) || !(p.wavelength_m > 0.0)) continue;
      const int key = tdcp_key(s);
      if (prev_epoch_[key] != epoch_count_ - 1) continue;  // not tracked at the previous epoch
      if (p.lli & 1) {
        ++out.tdcp_slips_lli;
        if (out.tdcp_flag) out.tdcp_flag[j] = static_cast<std::int8_t>(TdcpFlag::kSlipLli);
        continue;
      }
      const TdcpRow<L> row = tdcp_row<L>(ant_prev_, cur, TdcpSatEpoch{prev_r_e_[key], prev_clock_[key]},
                                         TdcpSatEpoch{s.r_e, s.clock_bias_m});
      const double y = row.predicted - (p.phase_m - prev_phase_[key]);
      if (out.tdcp_residual) out.tdcp_residual[j] = y;
      tdcp_.add(row, y, p.sigma_m * p.sigma_m + prev_sigma_[key] * prev_sigma_[key]);
      tdcp_src_[n] = j;
      tdcp_lambda_[n++] = p.wavelength_m;
    }
    if (n == 0) return;
    // INS-predicted phase change test (single frequency): residual less the common (clock) part
    bool keep[kMaxMeasRows] = {};
    double common = 0.0;
    if (n >= 3) {
      double tmp[kMaxMeasRows];
      for (int i = 0; i < n; ++i) tmp[i] = tdcp_.residual(i);
      common = median_inplace(tmp, n);
    }
    for (int i = 0; i < n; ++i) {
      keep[i] = std::fabs(tdcp_.residual(i) - common) <= cfg_.tdcp.slip_threshold_cycles * tdcp_lambda_[i];
      if (!keep[i]) {
        ++out.tdcp_slips_ins;
        if (out.tdcp_flag) out.tdcp_flag[tdcp_src_[i]] = static_cast<std::int8_t>(TdcpFlag::kSlipIns);
      }
    }
    compact(keep, n);
    if (n == 0) return;
    // per-row chi-square on the clone-augmented S_ii
    Phi_P_prev_.noalias() = core_.filter.cycle_transition() * P_prev_;
    if (!tdcp_.covariance(core_.filter.P(), Phi_P_prev_, P_prev_)) return;
    bool any_rejected = false;
    for (int i = 0; i < n; ++i) {
      const double w2 = tdcp_.residual(i) * tdcp_.residual(i) / tdcp_.S(i);  // x = 0 here (fed back)
      keep[i] = w2 <= cfg_.tdcp.chi2_row;
      if (!keep[i]) {
        any_rejected = true;
        ++out.tdcp_rejected;
        if (out.tdcp_flag) out.tdcp_flag[tdcp_src_[i]] = static_cast<std::int8_t>(TdcpFlag::kRejected);
      }
    }
    if (any_rejected) {
      compact(keep, n);
      if (n == 0 || !tdcp_.covariance(core_.filter.P(), Phi_P_prev_, P_prev_)) return;
    }
    const bool smoothing = core_.recording();
    if (smoothing) tdcp_.clone_terms(core_.filter.x(), clone_dx_, clone_dP_, clone_dC_);
    tdcp_.apply(core_.filter.x_mutable(), core_.filter.P_mutable());
    if (smoothing) core_.clone_update_for_smoother(clone_dx_, clone_dP_, clone_dC_);  // the RTS smoother's moments
    core_.touch();
    for (int i = 0; i < n; ++i)
      if (out.tdcp_flag) out.tdcp_flag[tdcp_src_[i]] = static_cast<std::int8_t>(TdcpFlag::kUsed);
    out.tdcp_used += n;
    ++out.tdcp_updates;
    if (out.tdcp_rows) out.tdcp_rows[g] = n;
  }

  /// The antenna of the current INS state for a TDCP row (tdcp.hpp): the lever-arm estimate with the
  /// lever-arm states, and shift_s [s] past the epoch's applied time with the time-offset state.
  TdcpAntenna tdcp_antenna_now(double shift_s) {
    const Vec3& l_b = kHasLeverArm<L> ? core_.lever_arm_b : cfg_.lever_arm_b;
    return tdcp_antenna(core_.state(), l_b, core_.clock_bias, core_.omega_ib_b(),
                        kHasTimeOffset<L> ? shift_s : 0.0);
  }

  /// Keep the TDCP rows with keep[i] (and their source indices / wavelengths).
  void compact(const bool* keep, int& n) {
    tdcp_.select(keep);
    int k = 0;
    for (int i = 0; i < n; ++i)
      if (keep[i]) {
        tdcp_src_[k] = tdcp_src_[i];
        tdcp_lambda_[k++] = tdcp_lambda_[i];
      }
    n = k;
  }

  /// End of an epoch: feed back what is left in x (the TDCP correction when the
  /// code update was not applied), then clone: the fed-back state, P and this
  /// epoch's phases become the previous epoch of the next TDCP update.
  void tdcp_close(const TightEpoch& ep) {
    if (!cfg_.tdcp.enabled || !phase_) return;
    if (!core_.filter.x().isZero(0.0)) core_.feedback();
    P_prev_ = core_.filter.P();
    // after the feedback the time-offset estimate may have moved the epoch's applied time: the signed shift
    ant_prev_ = tdcp_antenna_now(core_.state().t - core_.record_time(ep.t));
    t_prev_ = core_.state().t;
    have_prev_ = true;
    for (std::int64_t j = ep.begin; j < ep.end; ++j) {
      const SatObservation& s = sats_[j];
      const PhaseObservation& p = phase_[j];
      if (s.prn <= 0 || !std::isfinite(p.phase_m) || !(p.wavelength_m > 0.0)) continue;
      const int key = tdcp_key(s);
      prev_epoch_[key] = epoch_count_;
      prev_phase_[key] = p.phase_m;
      prev_sigma_[key] = p.sigma_m;
      prev_r_e_[key] = s.r_e;
      prev_clock_[key] = s.clock_bias_m;
    }
    ++epoch_count_;
  }

  // ---------------------------------------------------------------- Gauss-Markov pseudorange errors
  /// The block to this epoch (carried over the cycle just closed, propagated,
  /// expired, new satellites added) and its estimates b^ applied to the
  /// pseudoranges (predicted - measured gains + b^: measured - b^).
  void gm_begin_epoch(int ns) {
    const double t_ep = core_.state().t;
    gm_.carry_cycle(core_.filter.cycle_transition());
    gm_.propagate_to(t_ep);
    gm_.expire(t_ep);
    for (int i = 0; i < ns; ++i) {
      gm_slot_[i] = -1;
      SatObservation& s = work_[i];
      if (s.prn <= 0 || !std::isfinite(s.pseudorange_m)) continue;
      gm_slot_[i] = gm_.observe(decltype(gm_)::key(s.system, s.prn), t_ep);
      if (gm_slot_[i] >= 0) s.pseudorange_m -= gm_.estimate(gm_slot_[i]);
    }
    gm_ns_ = ns;
  }

  /// Fold the block into the measurement just built (PseudorangeGmBlock::fold).
  void gm_fold() {
    auto& lin = meas_.linear_mutable();
    const int m = lin.rows();
    int row = 0;
    for (int i = 0; i < gm_ns_ && row < m; ++i)
      for (int kind = 0; kind < 2 && row < m; ++kind)
        if (std::isfinite(kind == 0 ? work_[i].pseudorange_m : work_[i].pseudorange_rate_mps))
          gm_row_slot_[row++] = kind == 0 ? gm_slot_[i] : -1;
    gm_folded_ = gm_.fold(core_.filter.P(), lin.H, lin.R, gm_row_slot_, m);
  }

  /// The block's joint posterior after an applied update (before the core's feedback).
  void gm_end_update() {
    const auto& lin = meas_.linear();
    if (!gm_folded_ || core_.gate.reopened() != gm_reopened_ ||
        !gm_.joint_posterior(gm_Pxx_prior_, lin.H, lin.R, lin.residual, core_.filter.x(), core_.filter.P()))
      gm_.reinitialise();  // the core's covariance was inflated (lock-out recovery) or not factorable
  }

  void set_measurement(int ns) {
    if constexpr (kHasTimeOffset<L> || kHasLeverArm<L>) {
      // self-calibration (layout.hpp; meas/pseudorange.hpp): the lever-arm estimate, and how far the
      // INS is past the epoch's shifted time (0 unless the estimate moved it into the past)
      const Vec3& l_b = kHasLeverArm<L> ? core_.lever_arm_b : cfg_.lever_arm_b;
      const double shift = std::max(0.0, core_.state().t - core_.record_time(ep_t_));
      if constexpr (kHasLeverArm<L>) meas_.set_lever_arm_rate(core_.omega_ib_b_lever());
      meas_.set(core_.state(), core_.omega_ib_b(), l_b, core_.clock_bias, core_.clock_drift, work_, ns,
                core_.isb.data(), core_.acceleration_n(), shift);
    } else {
      meas_.set(core_.state(), core_.omega_ib_b(), cfg_.lever_arm_b, core_.clock_bias, core_.clock_drift, work_, ns,
                core_.isb.data());
    }
    if constexpr (kCanGm)
      if (gm_on()) gm_fold();
  }

  /// The variance factor of robust.hpp 0.: this epoch's rows into the window, then per row kind
  /// the factor over the window; R of that kind scaled by it for this epoch (the satellites' sigmas
  /// times sqrt(f), the rows formed again).  No heap.
  void apply_variance_factor(int ns, TightOutputs& out) {
    const RobustConfig& rc = cfg_.robust;
    standardize(1.0);
    const auto& lin = meas_.linear();
    const int window = std::min(rc.variance_window, kMaxVarianceWindow);
    const int slot = var_epochs_ % window;
    VarianceRows& e = var_rows_[slot];
    e.n[0] = e.n[1] = 0;
    int row = 0;
    for (int i = 0; i < ns && row < lin.rows(); ++i)
      for (int kind = 0; kind < 2 && row < lin.rows(); ++kind) {
        if (!std::isfinite(kind == 0 ? work_[i].pseudorange_m : work_[i].pseudorange_rate_mps)) continue;
        // r: the satellite's own variance, the part f scales; the rest of S (H P H^T, and the
        // Gauss-Markov states' conditional variance that gm_fold adds to R) stays in a
        const double sigma = kind == 0 ? work_[i].sigma_pr_m : work_[i].sigma_prr_mps;
        const double r = sigma * sigma;
        const int k = e.n[kind]++;
        e.y2[kind][k] = y_[row] * y_[row];
        e.a[kind][k] = std::max(sqrt_S_[row] * sqrt_S_[row] - r, 0.0);
        e.r[kind][k] = r;
        ++row;
      }
    ++var_epochs_;
    const int epochs = std::min(var_epochs_, window);
    double f[2] = {1.0, 1.0};
    for (int kind = 0; kind < 2; ++kind) {
      int n = 0;
      for (int s = 0; s < epochs; ++s) {
        const VarianceRows& v = var_rows_[s];
        std::copy(v.y2[kind], v.y2[kind] + v.n[kind], var_y2_ + n);
        std::copy(v.a[kind], v.a[kind] + v.n[kind], var_a_ + n);
        std::copy(v.r[kind], v.r[kind] + v.n[kind], var_r_ + n);
        n += v.n[kind];
      }
      if (n >= std::max(rc.variance_min_rows, 1)) f[kind] = variance_factor(var_y2_, var_a_, var_r_, n, var_scratch_);
    }
    if (f[0] > 1.0) ++out.variance_inflated[0];
    if (f[1] > 1.0) ++out.variance_inflated[1];
    if (!(f[0] > 1.0 || f[1] > 1.0)) return;
    const double s_pr = std::sqrt(f[0]), s_prr = std::sqrt(f[1]);
    for (int i = 0; i < ns; ++i) {
      work_[i].sigma_pr_m *= s_pr;
      work_[i].sigma_prr_mps *= s_prr;
    }
    set_measurement(ns);
  }

  /// y_i = residual_i - H_i x and sqrt(S_ii) = sqrt(alpha H_i P H_i^T + R_ii) of every row (robust.hpp;
  /// alpha > 1: the gate's outage-aware test, nis_gate.hpp).
  void standardize(double alpha) {
    const auto& lin = meas_.linear();
    const auto& x = core_.filter.x();
    const auto& P = core_.filter.P();
    for (int i = 0; i < lin.rows(); ++i) {
      const auto h = lin.H.row(i);
      hP_.noalias() = h * P;
      y_[i] = lin.residual[i] - (h * x).value();
      sqrt_S_[i] = std::sqrt(std::max(alpha * hP_.dot(h) + lin.R(i, i), 0.0));
    }
  }

  /// The common offset of the pseudorange innovations when it is a clock jump, else 0 (robust.hpp, 1.).
  double common_pseudorange_offset() {
    const RobustConfig& rc = cfg_.robust;
    const auto& lin = meas_.linear();
    double yv[kMaxMeasRows], sv[kMaxMeasRows];
    int n = 0;
    int row = 0;
    for (int i = 0; row < lin.rows(); ++i)
      for (int kind = 0; kind < 2 && row < lin.rows(); ++kind) {
        if (!std::isfinite(kind == 0 ? work_[i].pseudorange_m : work_[i].pseudorange_rate_mps)) continue;
        if (kind == 0) {
          yv[n] = y_[row];
          sv[n++] = sqrt_S_[row];
        }
        ++row;
      }
    if (n < rc.clock_jump_min_rows || n < 1) return 0.0;
    double tmp[kMaxMeasRows];
    std::copy(yv, yv + n, tmp);
    const double med = median_inplace(tmp, n);
    std::copy(sv, sv + n, tmp);
    const double med_s = median_inplace(tmp, n);
    if (!(std::fabs(med) > rc.clock_jump_sigma * med_s)) return 0.0;
    const double k = std::sqrt(rc.chi2_row);
    int agree = 0;
    for (int i = 0; i < n; ++i) agree += std::fabs(yv[i] - med) <= k * sv[i] ? 1 : 0;
    return 2 * agree >= n ? med : 0.0;
  }

  /// The CUSUM slot of a satellite's row kind (robust.hpp, 4.).
  static int sat_key(const SatObservation& s, int kind) {
    return ((s.system & 3) * 64 + (s.prn & 63)) * 2 + kind;
  }

  /// Screening and IGG-III / Huber (robust.hpp, 2.) and the CUSUM (4.; when
  /// `cusum`): edits work_ and rebuilds the measurement.
  void screen_and_weight(int ns, double alpha, bool cusum, double t_ep, TightOutputs& out) {
    const RobustConfig& rc = cfg_.robust;
    standardize(alpha);
    const int m0 = meas_.linear().rows();
    bool alarm = false;
    int n_pr = 0;  // with too few pseudoranges to pin position and clock, the filter's own coasting drift
    for (int r = 0; r < m0; ++r) n_pr += row_kind_[r] == 0 ? 1 : 0;  // shows on every satellite (robust.hpp, 4.)
    if (cusum && rc.cusum_h > 0.0 && n_pr >= rc.cusum_min_pseudoranges) {
      const double clip = std::sqrt(rc.chi2_row);
      for (int r = 0; r < m0; ++r) {
        SatObservation& s = work_[row_sat_[r]];
        if (s.prn <= 0) continue;  // no satellite identity: no CUSUM
        const int key = sat_key(s, row_kind_[r]);
        const double w = std::clamp(y_[r] / sqrt_S_[r], -clip, clip);
        cusum_pos_[key] = std::max(0.0, cusum_pos_[key] + w - rc.cusum_k);
        cusum_neg_[key] = std::max(0.0, cusum_neg_[key] - w - rc.cusum_k);
        if (cusum_pos_[key] > rc.cusum_h || cusum_neg_[key] > rc.cusum_h) {
          cusum_pos_[key] = cusum_neg_[key] = 0.0;
          excluded_until_[key] = t_ep + rc.cusum_hold_s;
          ++out.cusum_alarms;
          (row_kind_[r] == 0 ? s.pseudorange_m : s.pseudorange_rate_mps) = NAN;
          flag_[2 * row_sat_[r] + row_kind_[r]] = SatFlag::kRejected;
          alarm = true;
        }
      }
    }
    bool flagged = alarm;
    for (int r = 0; r < m0; ++r) flagged = flagged || !(y_[r] * y_[r] <= rc.chi2_row * sqrt_S_[r] * sqrt_S_[r]);
    if (!flagged) return;
    ++out.flagged_epochs;
    for (int r = 0; r < m0; ++r) {
      const double w = y_[r] / sqrt_S_[r];
      SatObservation& s = work_[row_sat_[r]];
      const int kind = row_kind_[r];
      if (flag_[2 * row_sat_[r] + kind] == SatFlag::kRejected) continue;  // the CUSUM's
      const double q = !(w * w <= rc.chi2_row) ? 0.0
                       : rc.huber             ? huber_weight(w, rc.huber_k)
                                              : igg3_weight(w, rc.igg_k0, rc.igg_k1);
      if (q <= 0.0) {
        (kind == 0 ? s.pseudorange_m : s.pseudorange_rate_mps) = NAN;
        flag_[2 * row_sat_[r] + kind] = SatFlag::kRejected;
      } else if (q < 1.0) {
        (kind == 0 ? s.sigma_pr_m : s.sigma_prr_mps) /= std::sqrt(q);
        flag_[2 * row_sat_[r] + kind] = SatFlag::kDownWeighted;
      }
    }
    set_measurement(ns);
  }

  /// Whole-epoch FDE (robust.hpp, 3.): while the epoch's NIS under
  /// alpha H P H' + R fails the gate, exclude the satellite of the largest
  /// w-test statistic.  Edits work_ and rebuilds the measurement.
  void exclude_faults(int ns, double alpha, TightOutputs& out) {
    using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
    using Vm = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxMeasRows, 1>;
    using HP = Eigen::Matrix<double, Eigen::Dynamic, L::kSize, Eigen::RowMajor, kMaxMeasRows, L::kSize>;
    const RobustConfig& rc = cfg_.robust;
    for (int k = 0; k < rc.fde_max_sats; ++k) {
      const auto& lin = meas_.linear();
      const int m = lin.rows();
      const double threshold = core_.gate.nominal_threshold(m);
      if (threshold <= 0.0 || m <= rc.fde_min_rows) return;
      const Vm y = lin.residual - lin.H * core_.filter.x();
      HP hp(m, L::kSize);
      hp.noalias() = lin.H * core_.filter.P();
      Dyn S(m, m);
      S.noalias() = alpha * (hp * lin.H.transpose());
      S += lin.R;
      Eigen::LLT<Dyn> llt(S);
      if (llt.info() != Eigen::Success) return;
      const Vm Sy = llt.solve(y);
      if (!(y.dot(Sy) > threshold)) return;
      Dyn Sinv = Dyn::Identity(m, m);
      llt.solveInPlace(Sinv);
      // rows of meas_ -> satellites (the finite observations, in order)
      int worst = -1, row = 0;
      double w_max = 0.0;
      for (int i = 0; i < ns && row < m; ++i)
        for (int kind = 0; kind < 2 && row < m; ++kind) {
          if (!std::isfinite(kind == 0 ? work_[i].pseudorange_m : work_[i].pseudorange_rate_mps)) continue;
          const double w = std::fabs(Sy[row]) / std::sqrt(std::max(Sinv(row, row), 1e-300));
          if (w > w_max) {
            w_max = w;
            worst = i;
          }
          ++row;
        }
      if (worst < 0) return;
      work_[worst].pseudorange_m = work_[worst].pseudorange_rate_mps = NAN;
      flag_[2 * worst] = flag_[2 * worst + 1] = SatFlag::kRejected;
      ++out.fde_excluded;
      set_measurement(ns);
    }
  }

  void apply_process_noise_scale() { adaptive_q_.apply_standstill(core_.filter, cfg_.standstill_q_scale, still_); }

  ClosedLoop<Filter> core_;
  TightConfig cfg_;
  AdaptiveProcessNoise adaptive_q_;  // adaptive Q factors (velocity, attitude random walk)
  const std::uint8_t* epoch_still_ = nullptr;  // the standstill detector's state per epoch (set_standstill)
  bool still_ = false;                         // the last epoch's (the level of Q until the next)
  TightMeasurement<L> meas_;
  SatObservation work_[kMaxMeasRows];
  std::int64_t src_[kMaxMeasRows] = {};
  IsbVec isb0_ = IsbVec::Zero();
  // robust step workspace (per row of the measurement / per satellite and kind)
  double y_[kMaxMeasRows] = {}, sqrt_S_[kMaxMeasRows] = {};
  /// The variance factor's window (robust.hpp, 0.): per epoch and row kind y^2, H P H^T and R.
  struct VarianceRows {
    int n[2] = {0, 0};
    double y2[2][kMaxMeasRows], a[2][kMaxMeasRows], r[2][kMaxMeasRows];
  };
  std::array<VarianceRows, kMaxVarianceWindow> var_rows_;
  int var_epochs_ = 0;
  double var_y2_[kMaxVarianceWindow * kMaxMeasRows], var_a_[kMaxVarianceWindow * kMaxMeasRows],
      var_r_[kMaxVarianceWindow * kMaxMeasRows], var_scratch_[kMaxVarianceWindow * kMaxMeasRows];
  Eigen::Matrix<double, 1, L::kSize> hP_;
  int row_sat_[kMaxMeasRows] = {}, row_kind_[kMaxMeasRows] = {};
  SatFlag flag_[2 * kMaxMeasRows] = {};
  bool cut_[2 * kMaxMeasRows] = {};  // rows left out by a CUSUM exclusion this epoch
  // CUSUM per (system, prn, row kind) (robust.hpp, 4.)
  static constexpr int kSatKeys = 4 * 64 * 2;
  double cusum_pos_[kSatKeys] = {}, cusum_neg_[kSatKeys] = {}, excluded_until_[kSatKeys] = {};
  const SatObservation* sats_ = nullptr;
  // TDCP: the clone of the previous epoch and its satellites' phases per (system, prn)
  static constexpr int kTdcpKeys = 4 * 64;
  const PhaseObservation* phase_ = nullptr;
  TdcpUpdate<L> tdcp_;
  StateCov<L> P_prev_ = StateCov<L>::Zero(), Phi_P_prev_ = StateCov<L>::Zero();
  // the clone's side of a TDCP update for the RTS smoother (TdcpUpdate::clone_terms)
  StateVec<L> clone_dx_ = StateVec<L>::Zero();
  StateCov<L> clone_dP_ = StateCov<L>::Zero(), clone_dC_ = StateCov<L>::Zero();
  TdcpAntenna ant_prev_;
  double t_prev_ = 0.0;
  bool have_prev_ = false;
  std::int64_t epoch_count_ = 0;
  std::int64_t prev_epoch_[kTdcpKeys] = {};
  double prev_phase_[kTdcpKeys] = {}, prev_sigma_[kTdcpKeys] = {}, prev_clock_[kTdcpKeys] = {};
  Vec3 prev_r_e_[kTdcpKeys];
  std::int64_t tdcp_src_[kMaxMeasRows] = {};
  double tdcp_lambda_[kMaxMeasRows] = {};
  double ep_t_ = 0.0;  // the time tag of the epoch being applied [s]
  // Gauss-Markov pseudorange errors (pseudorange_gm.hpp): the block, the slot of each satellite row
  // of the epoch, of each measurement row, and the prior P_xx of the update
  PseudorangeGmBlock<L::kSize> gm_;
  int gm_slot_[kMaxMeasRows] = {}, gm_row_slot_[kMaxMeasRows] = {};
  int gm_ns_ = 0;
  bool gm_folded_ = false;
  int gm_reopened_ = 0;
  StateCov<L> gm_Pxx_prior_ = StateCov<L>::Zero();
};

}  // namespace insnav
