// insnav/engine/delay_engine.hpp -- closed-loop loose GNSS/INS with late
// (delayed) GNSS records.
//
// Records carry a time of validity t_valid and an arrival time t_arrival >=
// t_valid (seed 001: a whole number of GNSS epochs later).  Two engines:
//
//  * RandomDelayEngine<L, S>: seed 001's random-delay KF (random_delay_kf.hpp).
//    It does not know t_valid: at each GNSS epoch of the receiver schedule it
//    stores the INS solution, and a record arriving at an epoch is compared with
//    the stored solutions of the last S + 1 epochs, weighted by the delay
//    probabilities.
//
//  * TimeTaggedEngine<Filter, kRing>: exact processing when t_valid is known.
//    The engine state (INS, IMU corrections, filter x/P, propagation interval
//    bookkeeping) is checkpointed at IMU sample starts every
//    `checkpoint_interval` seconds in a fixed ring of kRing entries.  A record
//    arriving late restores the newest checkpoint older than its t_valid and
//    re-runs the IMU samples from the caller's arrays (indices only, no copies)
//    applying every record received so far at its own t_valid (exact time
//    alignment by splitting the IMU increment, as in LooseEngine), until the
//    present.  The result is exactly what LooseEngine would have computed had
//    all those records been on time; the output written at each IMU sample is
//    the real-time solution (past outputs are not rewritten).
//    Bounded: history = min(max_history_s, (kRing - 1) checkpoint_interval);
//    an older record is refused (status 5) and counted (refused_too_old).
//    Cost: one replay per arrival instant that brings a late record, at most
//    history / imu_dt samples each; memory kRing * sizeof(engine state)
//    (~3 kB for the 15-state EKF), allocated once with the engine.
//    Why re-processing rather than a delayed-state (Larsen) update: it is exact
//    for the nonlinear closed loop (feedback and re-linearisation at the right
//    times), works for any Filter, and its cost is bounded by the history.
//
// Both run on the closed-loop core of every engine (closed_loop.hpp: cycles,
// propagation intervals, outage cycles, feedback, outputs) and reuse
// LooseConfig and LooseMeasurement, so that with zero delay both reproduce
// LooseEngine.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <optional>

#include "insnav/check.hpp"
#include "insnav/engine/loose_engine.hpp"
#include "insnav/filter/random_delay_kf.hpp"

namespace insnav {

struct DelayConfig {
  double max_history_s = 1.0;        // exact engine: refuse records older than this [s]
  double checkpoint_interval = 0.1;  // exact engine: checkpoint spacing [s] (>= one IMU sample)
  double time_tolerance = 1e-6;      // arrival at an epoch / same instant [s]
};

/// LooseOutputs plus the delay counters.  Status per record: RecordStatus
/// (kTooOld: refused by the exact engine, older than its history).
struct DelayOutputs : LooseOutputs {
  int refused_too_old = 0;             // exact engine
  int replays = 0;                     // exact engine: restores from a checkpoint
  std::int64_t replayed_samples = 0;   // exact engine: IMU samples integrated again
  int filter_updates = 0;              // all filter updates incl. repeated ones in replays
};

// ---------------------------------------------------------------------------
/// seed 001's random-delay KF in the closed-loop engine.
template <class L, int S>
class RandomDelayEngine {
 public:
  using Filter = RandomDelayKf<L, S>;

  RandomDelayEngine(const ImuErrorModel& model, const LooseConfig& cfg, const DelayConfig& dcfg,
                    const double* delay_p, int n_p)
      : core_(make(model, delay_p, n_p), cfg.propagation_interval), cfg_(cfg), dcfg_(dcfg) {
    core_.gate = NisGate(cfg.gate);
  }

  const Filter& filter() const { return core_.filter; }
  ClosedLoop<Filter>& core() { return core_; }
  const LooseConfig& config() const { return cfg_; }
  const DelayConfig& delay_config() const { return dcfg_; }

  /// n IMU samples; m records sorted by t_arrival (fixes[g].t = t_valid is NOT
  /// used: the filter does not know it); n_ep GNSS epochs (the receiver's
  /// output schedule, sorted): the stack shifts at each of them.
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, std::int64_t n,
           const double* t, const double* dtheta_b, const double* dv_b, std::int64_t m, const GnssFix* fixes,
           const double* t_arrival, std::int64_t n_ep, const double* epochs, DelayOutputs& out) {
    const double tol = dcfg_.time_tolerance;
    start(initial, P0, corr0);
    std::int64_t g = 0, ep = 0;
    while (g < m && !(t_arrival[g] > initial.t + tol)) out.mark(g++, RecordStatus::kOutsideImuSpan);
    while (ep < n_ep && !(epochs[ep] > initial.t + tol)) ++ep;
    double t_prev = initial.t;
    for (std::int64_t k = 0; k < n; ++k) {
      if (out.stop_requested(k, n)) break;
      const ImuIncrement raw = raw_imu_sample(k, t_prev, t, dtheta_b, dv_b);
      process_sample(
          raw, t_prev, [&]() { return ep < n_ep ? epochs[ep] : kInf; },
          [&](double te) {
            for (; g < m && t_arrival[g] <= te + tol; ++g) receive(fixes[g], g, out);
            ++ep;
          });
      if ((k + 1) % cfg_.output_decimation == 0 || k + 1 == n) core_.write_output(out);
      t_prev = raw.t;
    }
    for (; g < m; ++g) out.mark(g, RecordStatus::kOutsideImuSpan);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
    out.gate_reopened = core_.gate.reopened();
    out.gate_outage_accepted = core_.gate.outage_accepted();
  }

  /// The initial state; no epoch stored yet.
  void start(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0) {
    core_.reset(initial, P0, corr0);
    for (auto& r : refs_) r.valid = false;
  }

  /// One raw IMU increment over (t_prev, raw.t].  At each receiver epoch te it
  /// covers (`next_epoch()` <= raw.t + tolerance) the increment is integrated up
  /// to te, the cycle closed and the INS solution stored as block 0 of the
  /// stack; `on_epoch(te)` then hands the records that arrived by te to
  /// receive() and moves next_epoch() on; the stack shifts (seed 001 eq. (6))
  /// and a new cycle starts.  The rest of the increment is integrated and an
  /// outage cycle (no shift) closed when due.  The batch run above and the push
  /// API (engine/navigator.hpp DelayNavigator) both call it, so their results
  /// are identical.
  template <class NextEpoch, class OnEpoch>
  void process_sample(const ImuIncrement& raw, double t_prev, NextEpoch&& next_epoch, OnEpoch&& on_epoch) {
    const double tol = dcfg_.time_tolerance;
    double done = 0.0;
    for (double te = next_epoch(); te <= raw.t + tol; te = next_epoch()) {
      const double a = std::min(1.0, (te - t_prev) / raw.dt);
      if (a > done) {
        core_.step(raw, done, a);
        done = a;
      }
      core_.close_cycle();
      refs_[0] = Ref{core_.ins.state(), core_.omega_ib_b(), true};
      on_epoch(te);
      core_.filter.shift();
      core_.touch();
      for (int i = S; i > 0; --i) refs_[i] = refs_[i - 1];
      core_.start_cycle();
    }
    if (done < 1.0) core_.step(raw, done, 1.0);
    if (core_.ins.state().t - core_.cycle_start >= cfg_.cycle_period - 1e-9) {  // outage: no shift
      core_.close_cycle();
      core_.start_cycle();
    }
  }

  /// A record received at the current epoch (call only inside process_sample's
  /// on_epoch): the delay hypotheses against the stored epochs, the update and
  /// the feedback; its status, NIS and innovation go to row g of `out`.
  /// Returns true when it was applied.
  bool receive(const GnssFix& fix, std::int64_t g, DelayOutputs& out) {
    // After a fed-back correction block 0 of the stack is zero and refers to
    // the corrected INS: the next record of the same epoch must be differenced
    // against that, not against the INS stored before the correction (which
    // would apply the correction twice).
    const bool applied = apply(fix, g, out);
    if (applied) refs_[0].nav = core_.ins.state();
    return applied;
  }

 private:
  struct Ref {
    NavState nav;
    Vec3 omega_ib_b = Vec3::Zero();
    bool valid = false;
  };

  static Filter make(const ImuErrorModel& model, const double* p, int n_p) {
    Filter f(model);
    f.set_delay_probabilities(p, n_p);
    return f;
  }

  /// One received record: hypotheses against the stored epochs, update, feedback.
  bool apply(const GnssFix& fix_in, std::int64_t g, DelayOutputs& out) {
    const GnssFix fix = masked_fix(fix_in, cfg_);
    if (!fix.has_pos && !fix.has_vel) {
      out.mark(g, RecordStatus::kNotUsed);
      return false;
    }
    typename Filter::Hypotheses hyp{};
    for (int i = 0; i <= S; ++i) {
      hyp[i] = nullptr;
      if (!refs_[i].valid) continue;
      meas_[i].set(refs_[i].nav, refs_[i].omega_ib_b, cfg_.lever_arm_b, fix);
      hyp[i] = &meas_[i].linear();
    }
    // the gate of the record stream, as ClosedLoop::update_gated applies it (nis_gate.hpp): the
    // outage-aware test, then on a lock-out the stacked covariance inflated by lambda = NIS / m where
    // the record observes it and the record applied ungated; with delay_p = [1] the loose engine's steps exactly
    int rows = 0;  // every hypothesis has the fix's rows
    for (const auto* h : hyp)
      if (h && rows == 0) rows = h->rows();
    const double t = core_.ins.state().t;
    double threshold = core_.gate.nominal_threshold(rows);
    bool bridged = false;
    if (threshold > 0.0 && core_.gate.outage_aware(t) &&
        core_.filter.mismatch_nis(hyp, core_.gate.config().mismatch) <= threshold) {
      bridged = true;
      threshold = 0.0;
    }
    UpdateResult res = core_.filter.update_delayed(hyp, threshold);
    if (bridged && res.applied && !(res.nis > core_.gate.nominal_threshold(rows))) bridged = false;
    bool forced = false;
    if (res.rejected_by_gate && core_.gate.reopening()) {
      const double lambda = res.nis / rows;
      if (lambda > 1.0 && std::isfinite(lambda)) core_.filter.inflate_observed(hyp, lambda);
      res = core_.filter.update_delayed(hyp, 0.0);
      forced = res.applied;
    }
    core_.gate.record(res, forced, t, bridged);
    core_.touch();
    if (res.rows > 0) out.write_innovation(g, fix, core_.filter.last_mean_residual());
    if (out.nis) out.nis[g] = res.rows > 0 ? res.nis : NAN;
    out.set_status(out.status, g,
                   res.applied || res.rejected_by_gate || res.cholesky_repairs ? status_of(res) : RecordStatus::kNotUsed);
    if (res.applied) {
      ++out.updates;
      ++out.filter_updates;
      core_.feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
    return res.applied;
  }

  ClosedLoop<Filter> core_;
  LooseConfig cfg_;
  DelayConfig dcfg_;
  std::array<Ref, S + 1> refs_{};
  std::array<LooseMeasurement<L>, S + 1> meas_;
};

// ---------------------------------------------------------------------------
/// Exact processing of time-tagged late records by checkpoint + re-processing.
template <class Filter, int kRing = 64>
class TimeTaggedEngine {
 public:
  using L = typename Filter::Layout;
  static constexpr int kRingSize = kRing;
  static constexpr int kMaxKnown = 4 * kRing + 16;  // received records kept for replays

  TimeTaggedEngine(const ImuErrorModel& model, const LooseConfig& cfg, const DelayConfig& dcfg)
      : core_(Filter(model), cfg.propagation_interval), cfg_(cfg), dcfg_(dcfg) {
    core_.gate = NisGate(cfg.gate);
    INSNAV_CHECK(dcfg_.checkpoint_interval > 0.0, "checkpoint_interval must be > 0");
    INSNAV_CHECK(dcfg_.max_history_s >= 0.0, "max_history_s must be >= 0");
  }

  /// Effective history [s]: min(max_history_s, (kRing - 1) checkpoint_interval).
  double history_s() const { return std::min(dcfg_.max_history_s, (kRing - 1) * dcfg_.checkpoint_interval); }

  /// n IMU samples; m records sorted by t_arrival, fixes[g].t = t_valid <= t_arrival[g].
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, std::int64_t n,
           const double* t, const double* dtheta_b, const double* dv_b, std::int64_t m, const GnssFix* fixes,
           const double* t_arrival, DelayOutputs& out) {
        const double tol = dcfg_.time_tolerance;
    t_ = t;
    dth_ = dtheta_b;
    dv_ = dv_b;
    fixes_ = fixes;
    t0_ = initial.t;
    core_.reset(initial, P0, corr0);
    ring_count_ = 0;
    ring_head_ = 0;
    known_count_ = 0;
    next_ = 0;
    last_ckpt_t_ = -kInf;
    std::int64_t ga = 0;
    while (ga < m && !(fixes[ga].t > initial.t)) out.mark(ga++, RecordStatus::kOutsideImuSpan);
    for (std::int64_t k = 0; k < n; ++k) {
      if (out.stop_requested(k, n)) break;
      begin_sample(k);
      while (ga < m && t_arrival[ga] <= raw_.t + tol) {
        const double now = t_arrival[ga];
        const double a = std::max(done_, std::min(1.0, (now - t_prev_) / raw_.dt));
        advance(a, out);  // up to the arrival instant with what was known before it
        double oldest = kInf;
        while (ga < m && t_arrival[ga] <= now + tol) {
          const GnssFix& f = fixes[ga];
          if (!(f.t > t0_)) {
            out.mark(ga, RecordStatus::kOutsideImuSpan);
          } else if (now - f.t > history_s() + tol || !has_checkpoint_before(f.t) ||
                     known_count_ == kMaxKnown) {
            out.mark(ga, RecordStatus::kTooOld);
            ++out.refused_too_old;
          } else {
            insert_known(ga);
            if (f.t < core_.ins.state().t - tol) oldest = std::min(oldest, f.t);
          }
          ++ga;
        }
        if (oldest < kInf) replay_from(oldest, k, a, out);
        advance(a, out);  // records valid at this very instant
      }
      advance(1.0, out);
      end_sample(k, n, out, true);
    }
    for (; ga < m; ++ga) out.mark(ga, RecordStatus::kOutsideImuSpan);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
    out.gate_reopened = core_.gate.reopened();
    out.gate_outage_accepted = core_.gate.outage_accepted();
    out.updates = 0;
    if (out.status)
      for (std::int64_t g = 0; g < m; ++g) out.updates += out.status[g] == static_cast<std::int8_t>(RecordStatus::kApplied);
  }

 private:
  struct Checkpoint {
    std::optional<ClosedLoop<Filter>> core;  // engaged once the slot is first written
    std::int64_t k;     // the sample about to be integrated
    double t;           // time of the state = t[k-1] (or t0)
  };

  void begin_sample(std::int64_t k) {
    t_prev_ = k > 0 ? t_[k - 1] : t0_;
    raw_ = raw_imu_sample(k, t_prev_, t_, dth_, dv_);
    k_ = k;
    done_ = 0.0;
    if (t_prev_ - last_ckpt_t_ >= dcfg_.checkpoint_interval - 1e-9) push_checkpoint();
  }

  void end_sample(std::int64_t k, std::int64_t n, DelayOutputs& out, bool write) {
    if (core_.ins.state().t - core_.cycle_start >= cfg_.cycle_period - 1e-9) {  // outage cycle
      core_.close_cycle();
      core_.start_cycle();
    }
    if (write && ((k + 1) % cfg_.output_decimation == 0 || k + 1 == n)) core_.write_output(out);
  }

  /// Integrate the current sample up to fraction a, applying the known records
  /// valid in (now, t_prev + a dt] at their own times (LooseEngine's rule).
  void advance(double a, DelayOutputs& out) {
    while (next_ < known_count_) {
      const std::int64_t g = known_[next_];
      const double af = (fixes_[g].t - t_prev_) / raw_.dt;
      if (!(fixes_[g].t <= raw_.t) || af > a + 1e-12) break;
      if (af > done_) {
        core_.step(raw_, done_, af);
        done_ = af;
      }
      core_.close_cycle();
      apply_fix(g, out);
      core_.start_cycle();
      ++next_;
    }
    if (a > done_) {
      core_.step(raw_, done_, a);
      done_ = a;
    }
  }

  void apply_fix(std::int64_t g, DelayOutputs& out) {
        const GnssFix fix = masked_fix(fixes_[g], cfg_);
    if (!fix.has_pos && !fix.has_vel) {
      out.mark(g, RecordStatus::kNotUsed);
      return;
    }
    meas_.set(core_.ins.state(), core_.omega_ib_b(), cfg_.lever_arm_b, fix);
    out.write_innovation(g, fix, meas_.linear().residual);
    const UpdateResult res = core_.update_gated(meas_);
    if (out.nis) out.nis[g] = res.nis;
    out.set_status(out.status, g, status_of(res));
    if (res.applied) {
      ++out.filter_updates;
      core_.feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
  }

  // --- checkpoints: ring of kRing, newest at ring_head_ - 1 -------------------
  int ring_index(int age) const { return ((ring_head_ - 1 - age) % kRing + kRing) % kRing; }  // age 0 = newest

  void push_checkpoint() {
    Checkpoint& c = ring_[ring_head_];
    c.core = core_;
    c.k = k_;
    c.t = t_prev_;
    ring_head_ = (ring_head_ + 1) % kRing;
    ring_count_ = std::min(ring_count_ + 1, kRing);
    last_ckpt_t_ = t_prev_;
    prune_known();
  }

  bool has_checkpoint_before(double tv) const {
    return ring_count_ > 0 && ring_[ring_index(ring_count_ - 1)].t < tv;
  }

  /// Restore the newest checkpoint older than tv and re-run up to (k, a).
  void replay_from(double tv, std::int64_t k, double a, DelayOutputs& out) {
    int age = 0;
    while (age < ring_count_ && !(ring_[ring_index(age)].t < tv)) ++age;
    INSNAV_CHECK(age < ring_count_, "time-tagged engine: no checkpoint before the record (checked on receipt)");
    const Checkpoint& c = ring_[ring_index(age)];
    core_ = *c.core;
    const std::int64_t k0 = c.k;
    last_ckpt_t_ = c.t;
    // drop the newer checkpoints (they are re-taken on the way)
    ring_head_ = (ring_index(age) + 1) % kRing;
    ring_count_ -= age;
    next_ = 0;
    while (next_ < known_count_ && fixes_[known_[next_]].t <= c.t) ++next_;
    ++out.replays;
    t_prev_ = c.t;
    raw_ = raw_imu_sample(k0, t_prev_, t_, dth_, dv_);
    k_ = k0;
    done_ = 0.0;  // the checkpoint itself is kept: no new push for sample k0
    for (std::int64_t kk = k0; kk < k; ++kk) {
      if (kk > k0) begin_sample(kk);
      advance(1.0, out);
      end_sample(kk, 0, out, false);
      ++out.replayed_samples;
    }
    if (k > k0) begin_sample(k);
    advance(a, out);
  }

  // --- received records, sorted by t_valid (stable in arrival order) ---------
  void insert_known(std::int64_t g) {
    int pos = known_count_;
    while (pos > 0 && fixes_[known_[pos - 1]].t > fixes_[g].t) {
      known_[pos] = known_[pos - 1];
      --pos;
    }
    known_[pos] = g;
    ++known_count_;
    if (pos < next_) ++next_;  // inserted among the applied ones: a replay follows
  }

  /// Forget records no checkpoint can precede any more.
  void prune_known() {
    if (ring_count_ == 0) return;
    const double t_old = ring_[ring_index(ring_count_ - 1)].t;
    int drop = 0;
    while (drop < next_ && drop < known_count_ && fixes_[known_[drop]].t <= t_old) ++drop;
    if (drop == 0) return;
    for (int i = drop; i < known_count_; ++i) known_[i - drop] = known_[i];
    known_count_ -= drop;
    next_ -= drop;
  }

  ClosedLoop<Filter> core_;
  LooseConfig cfg_;
  DelayConfig dcfg_;
  LooseMeasurement<L> meas_;
  std::array<Checkpoint, kRing> ring_{};
  int ring_head_ = 0, ring_count_ = 0;
  std::array<std::int64_t, kMaxKnown> known_{};
  int known_count_ = 0, next_ = 0;
  // current IMU sample
  const double *t_ = nullptr, *dth_ = nullptr, *dv_ = nullptr;
  const GnssFix* fixes_ = nullptr;
  ImuIncrement raw_;
  std::int64_t k_ = 0;
  double t_prev_ = 0.0, done_ = 0.0, t0_ = 0.0, last_ckpt_t_ = -kInf;
};

}  // namespace insnav
