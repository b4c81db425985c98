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
// Input: E epochs (time, satellite range [begin, end) into one flat array of
// SatObservation), sorted by time.  No heap allocation inside run().
#pragma once

#include <cmath>
#include <cstdint>

#include "insnav/engine/closed_loop.hpp"
#include "insnav/meas/pseudorange.hpp"
#include "insnav/meas/robust.hpp"

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

  void mark(const TightEpoch& ep, std::int64_t g, RecordStatus st) {
    set_status(status, g, st);
    if (nis) nis[g] = NAN;
    if (rows) rows[g] = 0;
    if (clock_jump) clock_jump[g] = 0.0;
    if (sat_residual)
      for (std::int64_t j = ep.begin; j < ep.end; ++j) sat_residual[2 * j] = sat_residual[2 * j + 1] = NAN;
    if (sat_flag)
      for (std::int64_t j = ep.begin; j < ep.end; ++j)
        sat_flag[2 * j] = sat_flag[2 * j + 1] = static_cast<std::int8_t>(SatFlag::kAbsent);
  }
};

template <class Filter>
class TightEngine {
 public:
  using L = typename Filter::Layout;
  static_assert(kHasClock<L>, "TightEngine needs a layout with clock states");

  TightEngine(const ImuErrorModel& model, const TightConfig& cfg, const UtParams& ut = {})
      : core_(make_filter<Filter>(model, ut), cfg.propagation_interval), cfg_(cfg) {
    core_.gate = NisGate(cfg.gate);
  }

  Filter& filter() { return core_.filter; }
  ClosedLoop<Filter>& core() { return core_; }

  /// Initial inter-system bias estimates [m] of systems 1..3 (layouts with ISB states; default 0).
  void set_initial_isb(const IsbVec& isb0) { isb0_ = isb0; }

  /// n IMU samples; E epochs over M satellite rows.  clock0 = (bias [m], drift [m/s]).
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, double clock_bias0,
           double clock_drift0, std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
           std::int64_t n_epochs, const TightEpoch* epochs, const SatObservation* sats, TightOutputs& out) {
    start(initial, P0, corr0, clock_bias0, clock_drift0);
    sats_ = sats;
    std::int64_t g = 0;
    for (; g < n_epochs && !(epochs[g].t > initial.t); ++g) out.mark(epochs[g], g, RecordStatus::kOutsideImuSpan);
    core_.run_samples(initial.t, n, t, dtheta_b, dv_b, g, n_epochs, cfg_.cycle_period, cfg_.output_decimation, out,
                      [&](std::int64_t i) { return epochs[i].t; },
                      [&](std::int64_t i) { apply_epoch(epochs[i], i, out); });
    for (; g < n_epochs; ++g) out.mark(epochs[g], g, RecordStatus::kOutsideImuSpan);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
    out.gate_reopened = core_.gate.reopened();
    out.gate_outage_accepted = core_.gate.outage_accepted();
  }

  /// Reset to the initial state (the start of run(); the push API's constructor).
  void start(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, double clock_bias0,
             double clock_drift0) {
    core_.reset(initial, P0, corr0, clock_bias0, clock_drift0, isb0_);
    for (int i = 0; i < kSatKeys; ++i) {  // the per-satellite CUSUM of the robust step (robust.hpp, 4.)
      cusum_pos_[i] = cusum_neg_[i] = 0.0;
      excluded_until_[i] = -kInf;
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
    // copy the epoch's satellites, dropping the observation kinds switched off
    int ns = 0;
    for (std::int64_t j = ep.begin; j < ep.end && ns < kMaxMeasRows; ++j) {
      SatObservation s = sats_[j];
      if (!cfg_.use_pseudorange) s.pseudorange_m = NAN;
      if (!cfg_.use_rate) s.pseudorange_rate_mps = NAN;
      work_[ns] = s;
      src_[ns++] = j;
    }
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
      return;
    }
    const UpdateResult res = core_.update_gated(meas_);
    if (out.nis) out.nis[g] = res.nis;
    out.set_status(out.status, g, status_of(res));
    if (res.applied) {
      ++out.updates;
      core_.feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
  }

  void set_measurement(int ns) {
    meas_.set(core_.state(), core_.omega_ib_b(), cfg_.lever_arm_b, core_.clock_bias, core_.clock_drift, work_, ns,
              core_.isb.data());
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

  ClosedLoop<Filter> core_;
  TightConfig cfg_;
  TightMeasurement<L> meas_;
  SatObservation work_[kMaxMeasRows];
  std::int64_t src_[kMaxMeasRows] = {};
  IsbVec isb0_ = IsbVec::Zero();
  // robust step workspace (per row of the measurement / per satellite and kind)
  double y_[kMaxMeasRows] = {}, sqrt_S_[kMaxMeasRows] = {};
  Eigen::Matrix<double, 1, L::kSize> hP_;
  int row_sat_[kMaxMeasRows] = {}, row_kind_[kMaxMeasRows] = {};
  SatFlag flag_[2 * kMaxMeasRows] = {};
  bool cut_[2 * kMaxMeasRows] = {};  // rows left out by a CUSUM exclusion this epoch
  // CUSUM per (system, prn, row kind) (robust.hpp, 4.)
  static constexpr int kSatKeys = 4 * 64 * 2;
  double cusum_pos_[kSatKeys] = {}, cusum_neg_[kSatKeys] = {}, excluded_until_[kSatKeys] = {};
  const SatObservation* sats_ = nullptr;
};

}  // namespace insnav
