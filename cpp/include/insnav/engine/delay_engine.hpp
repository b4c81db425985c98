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
// Both reuse LooseConfig, ImuCorrection, LooseMeasurement and the timing rules
// of loose_engine.hpp (cycles, propagation intervals, outage cycles, feedback);
// DelayCore below repeats LooseEngine's private mechanics (kept identical so
// that with zero delay both engines reproduce LooseEngine).
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

/// LooseOutputs plus the delay counters.  Status codes per record:
/// 0 not used, 1 applied, 2 rejected by gate, 3 S not PD, 4 outside IMU span,
/// 5 refused: older than the history (exact engine).
struct DelayOutputs : LooseOutputs {
  int refused_too_old = 0;             // exact engine
  int replays = 0;                     // exact engine: restores from a checkpoint
  std::int64_t replayed_samples = 0;   // exact engine: IMU samples integrated again
  int filter_updates = 0;              // all filter updates incl. repeated ones in replays
};

/// The mechanics of LooseEngine (same order of operations), as a copyable
/// value so that the exact engine can checkpoint it whole.
template <class Filter>
struct DelayCore {
  using L = typename Filter::Layout;

  Filter filter;
  Strapdown ins;
  ImuCorrection corr;
  InsInterval iv;
  Vec3 omega_ib_b = Vec3::Zero(), f_ib_b = Vec3::Zero();
  double cycle_start = 0.0, interval_t0 = 0.0;
  bool have_mid = false;

  explicit DelayCore(const Filter& f) : filter(f) {}

  void reset(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0) {
    ins.reset(initial);
    corr = corr0;
    filter.initialize(P0);
    cycle_start = initial.t;
    start_cycle();
  }

  /// Integrate the fraction (a0, a1] of one raw IMU increment (LooseEngine::step).
  void step(const ImuIncrement& raw, double a0, double a1, double propagation_interval) {
    ImuIncrement imu;
    const double f = a1 - a0;
    imu.dt = raw.dt * f;
    imu.t = raw.t - raw.dt * (1.0 - a1);
    imu.dtheta_b = raw.dtheta_b * f;
    imu.dv_b = raw.dv_b * f;
    corr.apply(imu);
    ins.update(imu);
    omega_ib_b = imu.dtheta_b / imu.dt;
    f_ib_b = imu.dv_b / imu.dt;
    const double elapsed = ins.state().t - interval_t0;
    if (!have_mid && elapsed >= 0.5 * propagation_interval) {
      set_point(iv.mid);
      have_mid = true;
    }
    if (elapsed >= propagation_interval - 1e-12) flush_interval();
  }

  void set_point(InsPoint& p) {
    const NavState& s = ins.state();
    p.set(s.lat, s.h, s.v_n, s.q_nb.toRotationMatrix(), f_ib_b, omega_ib_b);
  }

  void flush_interval() {
    const NavState& s = ins.state();
    iv.dt = s.t - interval_t0;
    if (iv.dt <= 0.0) return;
    set_point(iv.end);
    if (!have_mid) {
      iv.mid = iv.end;
      iv.mid.lat = 0.5 * (iv.start.lat + iv.end.lat);
      iv.mid.h = 0.5 * (iv.start.h + iv.end.h);
      iv.mid.v_n = 0.5 * (iv.start.v_n + iv.end.v_n);
      iv.mid.earth.evaluate(iv.mid.lat, iv.mid.h, iv.mid.v_n);
    }
    filter.propagate(iv);
    iv.start = iv.end;
    interval_t0 = s.t;
    have_mid = false;
  }

  void start_cycle() {
    cycle_start = ins.state().t;
    interval_t0 = cycle_start;
    set_point(iv.start);
    have_mid = false;
    filter.begin_cycle();
  }

  void close_cycle() {
    flush_interval();
    filter.end_cycle();
  }

  /// Closed loop (LooseEngine::feedback): correct the INS and the IMU
  /// corrections with the (newest) error estimate, then zero it.
  void feedback() {
    const StateVec<L> x = filter.x();
    NavState s = ins.state();
    const wgs84::Radii r = wgs84::radii(s.lat);
    s.lat -= x[L::kPos] / (r.R_M + s.h);
    s.lon -= x[L::kPos + 1] / ((r.R_N + s.h) * std::cos(s.lat));
    s.h += x[L::kPos + 2];
    s.v_n -= x.template segment<3>(L::kVel);
    s.q_nb = (quat_from_euler(x.template segment<3>(L::kAtt)) * s.q_nb).normalized();
    corr.acc_bias += x.template segment<3>(L::kAccBias);
    corr.gyro_bias += x.template segment<3>(L::kGyroBias);
    if constexpr (kHasScale<L>) {
      corr.acc_scale += x.template segment<3>(L::kAccScale);
      corr.gyro_scale += x.template segment<3>(L::kGyroScale);
    }
    ins.set_state(s);
    filter.reset_state();
  }

  void write_output(LooseOutputs& out) const {
    const std::int64_t i = out.n_out++;
    const NavState& s = ins.state();
    if (out.t) out.t[i] = s.t;
    const StateVec<L> x = filter.x();
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
      const StateCov<L> P = filter.P();
      for (int j = 0; j < L::kSize; ++j) out.sigma[L::kSize * i + j] = std::sqrt(std::max(P(j, j), 0.0));
    }
    if (out.imu_err) {
      double* e = out.imu_err + 12 * i;
      for (int j = 0; j < 3; ++j) {
        e[j] = corr.acc_bias[j] + x[L::kAccBias + j];
        e[3 + j] = corr.gyro_bias[j] + x[L::kGyroBias + j];
        e[6 + j] = corr.acc_scale[j] + (kHasScale<L> ? x[L::kAccScale >= 0 ? L::kAccScale + j : 0] : 0.0);
        e[9 + j] = corr.gyro_scale[j] + (kHasScale<L> ? x[L::kGyroScale >= 0 ? L::kGyroScale + j : 0] : 0.0);
      }
    }
  }
};

namespace delay_detail {

inline ImuIncrement raw_sample(std::int64_t k, double t_prev, const double* t, const double* dtheta_b,
                               const double* dv_b) {
  ImuIncrement raw;
  raw.t = t[k];
  raw.dt = t[k] - t_prev;
  raw.dtheta_b = Vec3(dtheta_b[3 * k], dtheta_b[3 * k + 1], dtheta_b[3 * k + 2]);
  raw.dv_b = Vec3(dv_b[3 * k], dv_b[3 * k + 1], dv_b[3 * k + 2]);
  return raw;
}

inline void mark(LooseOutputs& out, std::int64_t g, int st) {
  if (out.status) out.status[g] = static_cast<std::int8_t>(st);
  if (out.nis) out.nis[g] = NAN;
  if (out.innovation)
    for (int i = 0; i < 6; ++i) out.innovation[6 * g + i] = NAN;
}

template <class RowVec>
void write_innovation(LooseOutputs& out, std::int64_t g, const GnssFix& fix, const RowVec& r) {
  if (!out.innovation) return;
  for (int i = 0; i < 6; ++i) out.innovation[6 * g + i] = NAN;
  const int off = fix.has_pos ? 0 : 3;
  for (int i = 0; i < r.size(); ++i) out.innovation[6 * g + off + i] = r[i];
}

inline GnssFix masked(const GnssFix& in, const LooseConfig& cfg) {
  GnssFix f = in;
  f.has_pos = f.has_pos && cfg.use_position;
  f.has_vel = f.has_vel && cfg.use_velocity;
  return f;
}

}  // namespace delay_detail

// ---------------------------------------------------------------------------
/// seed 001's random-delay KF in the closed-loop engine.
template <class L, int S>
class RandomDelayEngine {
 public:
  using Filter = RandomDelayKf<L, S>;

  RandomDelayEngine(const ImuErrorModel& model, const LooseConfig& cfg, const DelayConfig& dcfg,
                    const double* delay_p, int n_p)
      : core_(make(model, delay_p, n_p)), cfg_(cfg), dcfg_(dcfg) {}

  const Filter& filter() const { return core_.filter; }

  /// n IMU samples; m records sorted by t_arrival (fixes[g].t = t_valid is NOT
  /// used: the filter does not know it); n_ep GNSS epochs (the receiver's
  /// output schedule, sorted): the stack shifts at each of them.
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, std::int64_t n,
           const double* t, const double* dtheta_b, const double* dv_b, std::int64_t m, const GnssFix* fixes,
           const double* t_arrival, std::int64_t n_ep, const double* epochs, DelayOutputs& out) {
    using namespace delay_detail;
    const double tol = dcfg_.time_tolerance;
    core_.reset(initial, P0, corr0);
    for (auto& r : refs_) r.valid = false;
    std::int64_t g = 0, ep = 0;
    while (g < m && !(t_arrival[g] > initial.t + tol)) mark(out, g++, 4);
    while (ep < n_ep && !(epochs[ep] > initial.t + tol)) ++ep;
    double t_prev = initial.t;
    for (std::int64_t k = 0; k < n; ++k) {
      const ImuIncrement raw = raw_sample(k, t_prev, t, dtheta_b, dv_b);
      double done = 0.0;
      while (ep < n_ep && epochs[ep] <= raw.t + tol) {
        const double a = std::min(1.0, (epochs[ep] - t_prev) / raw.dt);
        if (a > done) {
          core_.step(raw, done, a, cfg_.propagation_interval);
          done = a;
        }
        core_.close_cycle();
        refs_[0] = Ref{core_.ins.state(), core_.omega_ib_b, true};
        for (; g < m && t_arrival[g] <= epochs[ep] + tol; ++g) {
          // After a fed-back correction block 0 of the stack is zero and refers
          // to the corrected INS: the next record of the same epoch must be
          // differenced against that, not against the INS stored before the
          // correction (which would apply the correction twice).
          if (apply(fixes[g], g, out)) refs_[0].nav = core_.ins.state();
        }
        core_.filter.shift();
        for (int i = S; i > 0; --i) refs_[i] = refs_[i - 1];
        core_.start_cycle();
        ++ep;
      }
      if (done < 1.0) core_.step(raw, done, 1.0, cfg_.propagation_interval);
      if (core_.ins.state().t - core_.cycle_start >= cfg_.cycle_period - 1e-9) {  // outage: no shift
        core_.close_cycle();
        core_.start_cycle();
      }
      if ((k + 1) % cfg_.output_decimation == 0 || k + 1 == n) core_.write_output(out);
      t_prev = raw.t;
    }
    for (; g < m; ++g) mark(out, g, 4);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
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
    using namespace delay_detail;
    const GnssFix fix = masked(fix_in, cfg_);
    if (!fix.has_pos && !fix.has_vel) {
      mark(out, g, 0);
      return false;
    }
    typename Filter::Hypotheses hyp{};
    for (int i = 0; i <= S; ++i) {
      hyp[i] = nullptr;
      if (!refs_[i].valid) continue;
      meas_[i].set(refs_[i].nav, refs_[i].omega_ib_b, cfg_.lever_arm_b, fix);
      hyp[i] = &meas_[i].linear();
    }
    const UpdateResult res = core_.filter.update_delayed(hyp, cfg_.gate_chi2);
    if (res.rows > 0) write_innovation(out, g, fix, core_.filter.last_mean_residual());
    if (out.nis) out.nis[g] = res.rows > 0 ? res.nis : NAN;
    const int st = res.applied ? 1 : (res.rejected_by_gate ? 2 : (res.cholesky_repairs ? 3 : 0));
    if (out.status) out.status[g] = static_cast<std::int8_t>(st);
    if (res.applied) {
      ++out.updates;
      ++out.filter_updates;
      core_.feedback();
    } else if (res.rejected_by_gate) {
      ++out.rejected;
    }
    return res.applied;
  }

  DelayCore<Filter> core_;
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
      : core_(Filter(model)), cfg_(cfg), dcfg_(dcfg) {
    INSNAV_CHECK(dcfg_.checkpoint_interval > 0.0, "checkpoint_interval must be > 0");
    INSNAV_CHECK(dcfg_.max_history_s >= 0.0, "max_history_s must be >= 0");
  }

  /// Effective history [s]: min(max_history_s, (kRing - 1) checkpoint_interval).
  double history_s() const { return std::min(dcfg_.max_history_s, (kRing - 1) * dcfg_.checkpoint_interval); }

  /// n IMU samples; m records sorted by t_arrival, fixes[g].t = t_valid <= t_arrival[g].
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, std::int64_t n,
           const double* t, const double* dtheta_b, const double* dv_b, std::int64_t m, const GnssFix* fixes,
           const double* t_arrival, DelayOutputs& out) {
    using namespace delay_detail;
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
    while (ga < m && !(fixes[ga].t > initial.t)) mark(out, ga++, 4);
    for (std::int64_t k = 0; k < n; ++k) {
      begin_sample(k);
      while (ga < m && t_arrival[ga] <= raw_.t + tol) {
        const double now = t_arrival[ga];
        const double a = std::max(done_, std::min(1.0, (now - t_prev_) / raw_.dt));
        advance(a, out);  // up to the arrival instant with what was known before it
        double oldest = kInf;
        while (ga < m && t_arrival[ga] <= now + tol) {
          const GnssFix& f = fixes[ga];
          if (!(f.t > t0_)) {
            mark(out, ga, 4);
          } else if (now - f.t > history_s() + tol || !has_checkpoint_before(f.t) ||
                     known_count_ == kMaxKnown) {
            mark(out, ga, 5);
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
    for (; ga < m; ++ga) mark(out, ga, 4);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
    out.updates = 0;
    if (out.status)
      for (std::int64_t g = 0; g < m; ++g) out.updates += out.status[g] == 1;
  }

 private:
  struct Checkpoint {
    std::optional<DelayCore<Filter>> core;  // engaged once the slot is first written
    std::int64_t k;     // the sample about to be integrated
    double t;           // time of the state = t[k-1] (or t0)
  };

  void begin_sample(std::int64_t k) {
    t_prev_ = k > 0 ? t_[k - 1] : t0_;
    raw_ = delay_detail::raw_sample(k, t_prev_, t_, dth_, dv_);
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
        core_.step(raw_, done_, af, cfg_.propagation_interval);
        done_ = af;
      }
      core_.close_cycle();
      apply_fix(g, out);
      core_.start_cycle();
      ++next_;
    }
    if (a > done_) {
      core_.step(raw_, done_, a, cfg_.propagation_interval);
      done_ = a;
    }
  }

  void apply_fix(std::int64_t g, DelayOutputs& out) {
    using namespace delay_detail;
    const GnssFix fix = masked(fixes_[g], cfg_);
    if (!fix.has_pos && !fix.has_vel) {
      mark(out, g, 0);
      return;
    }
    meas_.set(core_.ins.state(), core_.omega_ib_b, cfg_.lever_arm_b, fix);
    write_innovation(out, g, fix, meas_.linear().residual);
    const UpdateResult res = core_.filter.update(meas_, cfg_.gate_chi2);
    if (out.nis) out.nis[g] = res.nis;
    if (out.status) out.status[g] = static_cast<std::int8_t>(res.applied ? 1 : (res.rejected_by_gate ? 2 : 3));
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
    raw_ = delay_detail::raw_sample(k0, t_prev_, t_, dth_, dv_);
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

  DelayCore<Filter> core_;
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
