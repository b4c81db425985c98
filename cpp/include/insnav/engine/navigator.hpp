// insnav/engine/navigator.hpp -- the real-time push API of the loosely
// coupled filters: one IMU sample, one GNSS fix or one vehicle-constraint
// event at a time (KF-GINS's addImuData / addGnssData, for a robot or an
// embedded receiver), instead of a whole batch.
//
// It is the batch engine (loose_engine.hpp) driven sample by sample: the same
// ClosedLoop::process_sample and the same LooseEngine::apply_fix /
// apply_constraint, so a run pushed in time order gives the batch run's rows
// bit for bit (tests/test_navigator.py, cpp/tests/test_navigator.cpp).
//
// Timing.  A record valid at t_g is applied exactly at t_g, inside the IMU
// increment that covers it (closed_loop.hpp), so it has to be pushed before
// that increment is integrated.  Real-time GNSS arrives after the IMU samples
// that cover its time of validity (the receiver's latency): with
// `NavigatorConfig::imu_hold` = k the navigator holds the newest k IMU samples
// back and integrates a sample only once k newer ones have arrived, so a record
// may arrive up to k samples late and still be applied at its own time (the
// state then lags the newest sample by k samples; flush() integrates the held
// samples).  A record older than the last integrated sample is refused
// (RecordStatus::kTooOld) and counted, never applied at a wrong time; one that
// finds the pending queue full is refused as kQueueFull.
//
// Three families: LooseNavigator (GNSS fixes, vehicle constraints),
// TightNavigator (pseudorange epochs) and DelayNavigator (seed 001's
// random-delay KF: the records that arrived by each receiver epoch).
//
// Memory: fixed capacities (kMaxHold held samples, kMaxPending records), no
// heap allocation after construction.  The object is large (the filter's
// fixed-size matrices): allocate it once, e.g. with std::make_unique.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "insnav/engine/delay_engine.hpp"
#include "insnav/engine/loose_engine.hpp"
#include "insnav/engine/tight_engine.hpp"

namespace insnav {

/// The plain configuration of a Navigator (SI units, as the batch engines).
struct NavigatorConfig {
  ImuErrorModel imu_model;  // continuous-time IMU noise and error model (filter/types.hpp)
  LooseConfig loose;        // lever arm, propagation interval, outage cycle, gate, constraint noise
  UtParams ut;              // unscented transform of the RB-UKF / UKF (ignored by the EKF)
  int imu_hold = 0;         // IMU samples held back for late records [samples], 0 .. kMaxHold
};

/// One output row of the navigator: the INS corrected by the filter's x.
template <class L>
struct NavigatorRow {
  double t = 0.0;                               // [s]
  Vec3 llh = Vec3::Zero();                      // lat, lon [rad], h [m]
  Vec3 v_n = Vec3::Zero();                      // [m/s]
  Vec3 rpy = Vec3::Zero();                      // roll, pitch, yaw [rad]
  StateVec<L> sigma = StateVec<L>::Zero();      // sqrt(diag P), layout order; kAtt..kAtt+2 the 1-sigmas
                                                // of roll, pitch, yaw (ins/nav_error.hpp euler_sigmas_from_psi)
  Eigen::Matrix<double, 12, 1> imu_err;         // acc bias, gyro bias, acc scale, gyro scale (SI)
  Eigen::Matrix<double, 2, 1> odo_scale;        // odometer scale factor and its sigma (Layout16Odo)
  Eigen::Matrix<double, 2, 1> clock = Eigen::Matrix<double, 2, 1>::Constant(NAN);  // receiver clock bias [m], drift [m/s] (tight)
  IsbVec isb = IsbVec::Constant(NAN);           // inter-system biases of R, E, C [m] (LayoutTightMulti)
};

/// The output row of a closed loop (the batch engines' write_output, one row).
template <class L, class Core>
NavigatorRow<L> navigator_row(Core& core) {
  NavOutputs o;
  double t = 0, llh[3], v[3], rpy[3], sig[L::kSize], err[12], odo[2] = {0.0, 0.0}, clk[2] = {NAN, NAN},
         isb[3] = {NAN, NAN, NAN};
  o.t = &t;
  o.clock = clk;
  o.isb = isb;
  o.llh = llh;
  o.v_n = v;
  o.rpy = rpy;
  o.sigma = sig;
  o.imu_err = err;
  o.odo_scale = odo;
  core.write_output(o);
  NavigatorRow<L> r;
  r.t = t;
  r.llh = Vec3(llh[0], llh[1], llh[2]);
  r.v_n = Vec3(v[0], v[1], v[2]);
  r.rpy = Vec3(rpy[0], rpy[1], rpy[2]);
  for (int j = 0; j < L::kSize; ++j) r.sigma[j] = sig[j];
  for (int j = 0; j < 12; ++j) r.imu_err[j] = err[j];
  r.odo_scale << odo[0], odo[1];
  r.clock << clk[0], clk[1];
  r.isb = IsbVec(isb[0], isb[1], isb[2]);
  return r;
}

/// What became of the last GNSS fix applied (or refused).
struct NavigatorRecord {
  RecordStatus status = RecordStatus::kNotUsed;
  double nis = NAN;
  std::array<double, 6> innovation{};  // INS - GNSS before the update: N, E, D [m], vN, vE, vD [m/s] (NaN: absent)
};

/// Why a fix pushed by a caller cannot be used (nullptr: it can).  A position needs finite lat, lon,
/// h and position 1-sigmas finite and > 0; a velocity (has_vel and a finite v_n: a NaN velocity means
/// none, GnssFix in meas/gnss_loose.hpp) needs velocity 1-sigmas finite and > 0.  A NaN or an
/// infinite sigma would put NaN into the state for good; a zero one, an infinite weight.
inline const char* push_fix_problem(const GnssFix& f) {
  const auto bad_sigma = [](const Vec3& s) { return !(s.allFinite() && (s.array() > 0.0).all()); };
  if (f.has_pos && !(std::isfinite(f.lat) && std::isfinite(f.lon) && std::isfinite(f.h)))
    return "the position must be finite";
  if (f.has_pos && bad_sigma(f.sigma_pos_n)) return "the position 1-sigma must be finite and > 0";
  if (f.has_vel && f.v_n.allFinite() && bad_sigma(f.sigma_vel_n))
    return "the velocity 1-sigma must be finite and > 0 where the velocity is given";
  return nullptr;
}

/// A pushed fix as the engines take it: a NaN velocity is no velocity (has_vel false).
inline GnssFix normalized_push_fix(GnssFix f) {
  if (f.has_vel && !f.v_n.allFinite()) f.has_vel = false;
  return f;
}

/// normalized_push_fix(f), or std::invalid_argument naming `what` (and the record `index` when >= 0)
/// for a fix push_fix_problem() refuses.
inline GnssFix checked_push_fix(const GnssFix& fix, const char* what, int index = -1) {
  const GnssFix f = normalized_push_fix(fix);
  if (const char* why = push_fix_problem(f))  // the message only on the error path: no allocation otherwise
    throw std::invalid_argument(std::string(what) + (index >= 0 ? ": record " + std::to_string(index) : "") + ": " +
                                why);
  return f;
}

/// Why a satellite row pushed by a caller cannot be used (nullptr: it can): the system must be
/// one of kNumSystems; a row with a pseudorange or rate needs a finite satellite state (position,
/// velocity, clock bias and drift); the 1-sigma of a pseudorange or rate that is given must be
/// finite and > 0 (an infinite one put NaN into the state through the gain).
inline const char* push_sat_problem(const SatObservation& o) {
  if (o.system < 0 || o.system >= kNumSystems) return "system must be 0 G, 1 R, 2 E or 3 C";
  const bool any = std::isfinite(o.pseudorange_m) || std::isfinite(o.pseudorange_rate_mps);
  if (any && !(o.r_e.allFinite() && o.v_e.allFinite() && std::isfinite(o.clock_bias_m) &&
               std::isfinite(o.clock_drift_mps)))
    return "non-finite satellite state (r_e, v_e, clock bias or drift)";
  if (std::isfinite(o.pseudorange_m) && !(std::isfinite(o.sigma_pr_m) && o.sigma_pr_m > 0.0))
    return "sigma_pr must be finite and > 0";
  if (std::isfinite(o.pseudorange_rate_mps) && !(std::isfinite(o.sigma_prr_mps) && o.sigma_prr_mps > 0.0))
    return "sigma_prr must be finite and > 0";
  return nullptr;
}

/// Largest IMU step and increments push_imu takes (beyond any real sample: a corrupted one would
/// overflow the mechanization and put NaN into the state for good): a year, 1e3 rad, 1e6 m/s.
inline constexpr double kMaxPushDt = 3.2e7, kMaxPushDtheta = 1.0e3, kMaxPushDv = 1.0e6;

/// The part every navigator shares: the IMU hold ring, the queue of pending
/// records sorted by time of validity, and the per-sample step through
/// ClosedLoop::process_sample.  Derived (CRTP) provides `core()` (its
/// ClosedLoop), `apply(const Record&)` (the engine's measurement step) and
/// `Record::t`; `Record::order` breaks ties (lower first, then push order).
/// A Derived whose engine steps a sample its own way (the random-delay engine)
/// also provides `step_sample(raw, t_prev, next_t, apply_next)`.
template <class Derived, class Record, int kMaxHold, int kMaxPending>
class PushLoop {
 public:
  static_assert(kMaxHold >= 1 && kMaxPending >= 1, "capacities must be positive");

  /// One IMU increment over (t_prev, t]: dtheta_b [rad], dv_b [m/s] (FRD).
  /// Returns false (nothing done) when t does not increase or is not finite, or an
  /// increment is not finite (a NaN would stay in the state for good), or the step or an
  /// increment is beyond any real sample (kMaxPushDt, kMaxPushDtheta, kMaxPushDv: it would
  /// overflow the mechanization).
  bool push_imu(double t, const Vec3& dtheta_b, const Vec3& dv_b) {
    if (!std::isfinite(t) || !(t > t_pushed_) || !dtheta_b.allFinite() || !dv_b.allFinite()) return false;
    if (!(t - t_pushed_ <= kMaxPushDt) || !(dtheta_b.cwiseAbs().maxCoeff() <= kMaxPushDtheta) ||
        !(dv_b.cwiseAbs().maxCoeff() <= kMaxPushDv))
      return false;
    if (hold_n_ == kMaxHold) integrate_oldest();  // the ring is full (hold = kMaxHold): make room first
    ImuIncrement& raw = ring_[(hold_head_ + hold_n_) % kMaxHold];
    raw.t = t;
    raw.dt = t - t_pushed_;
    raw.dtheta_b = dtheta_b;
    raw.dv_b = dv_b;
    ++hold_n_;
    t_pushed_ = t;
    while (hold_n_ > hold_) integrate_oldest();
    return true;
  }

  /// Integrate every held sample (the end of a run, or no more late records expected).
  void flush() {
    while (hold_n_ > 0) integrate_oldest();
  }

  double t_integrated() const { return t_done_; }  // last integrated sample [s]
  int held_samples() const { return hold_n_; }
  int pending_records() const { return pend_n_; }
  std::int64_t samples() const { return samples_; }
  int refused_records() const { return refused_; }  // too old, outside the span, or the queue full

 protected:
  void start(double t0, int hold, double cycle_period) {
    if (hold < 0 || hold > kMaxHold) throw std::invalid_argument("imu_hold must be in 0 .. kMaxHold");
    hold_ = hold;
    cycle_period_ = cycle_period;
    t_pushed_ = t_done_ = t0_ = t0;
  }

  /// Why a record valid at t cannot be queued for its time (kNotUsed: it can): at or
  /// before the initial time, or not finite (kOutsideImuSpan); not after the last
  /// integrated sample (kTooOld).
  RecordStatus timing_of(double t) const {
    if (!std::isfinite(t) || !(t > t0_)) return RecordStatus::kOutsideImuSpan;
    if (!(t > t_done_)) return RecordStatus::kTooOld;
    return RecordStatus::kNotUsed;
  }

  /// A record with no room in the queue: refused for its time if that refuses it, else kQueueFull.
  RecordStatus refuse_full(double t) {
    const RecordStatus why = timing_of(t);
    return refuse(why == RecordStatus::kNotUsed ? RecordStatus::kQueueFull : why);
  }

  /// Queue a record (sorted by t, then by order, then in push order).
  RecordStatus enqueue(const Record& r) {
    if (const RecordStatus why = timing_of(r.t); why != RecordStatus::kNotUsed) return refuse(why);
    if (pend_n_ == kMaxPending) return refuse(RecordStatus::kQueueFull);
    int i = pend_n_;
    while (i > 0 && (pend_[i - 1].t > r.t || (pend_[i - 1].t == r.t && pend_[i - 1].order > r.order))) {
      pend_[i] = pend_[i - 1];
      --i;
    }
    pend_[i] = r;
    ++pend_n_;
    return RecordStatus::kNotUsed;
  }

  double t0() const { return t0_; }  // the initial time [s]

  RecordStatus refuse(RecordStatus why) {
    ++refused_;
    return why;
  }

  /// The closed loop's sample step (ClosedLoop::process_sample); a Derived may hide it.
  template <class NextT, class ApplyNext>
  void step_sample(const ImuIncrement& raw, double t_prev, NextT&& next_t, ApplyNext&& apply_next) {
    static_cast<Derived&>(*this).core().process_sample(raw, t_prev, cycle_period_, next_t, apply_next);
  }

  /// True when a pending record would still be applied (its slot of a pool is in use).
  template <class Pred>
  bool any_pending(Pred&& pred) const {
    for (int i = 0; i < pend_n_; ++i)
      if (pred(pend_[i])) return true;
    return false;
  }

 private:
  void integrate_oldest() {
    Derived& self = static_cast<Derived&>(*this);
    const ImuIncrement raw = ring_[hold_head_];
    hold_head_ = (hold_head_ + 1) % kMaxHold;
    --hold_n_;
    int done = 0;  // records applied in this sample (the queue front)
    self.step_sample(
        raw, t_done_, [&]() { return pend_n_ > done ? pend_[done].t : kInf; },
        [&]() { self.apply(pend_[done++]); });
    if (done > 0) {
      for (int j = done; j < pend_n_; ++j) pend_[j - done] = pend_[j];
      pend_n_ -= done;
    }
    t_done_ = raw.t;
    ++samples_;
  }

  std::array<ImuIncrement, kMaxHold> ring_;
  int hold_head_ = 0, hold_n_ = 0, hold_ = 0;  // ring_ start, samples in it, samples to hold
  std::array<Record, kMaxPending> pend_;
  int pend_n_ = 0;
  double t_pushed_ = 0.0, t_done_ = 0.0, t0_ = 0.0, cycle_period_ = 1.0;
  std::int64_t samples_ = 0;
  int refused_ = 0;
};

/// A queued loose record: a GNSS fix (order 0: first at a tie, as the batch
/// engine merges its two sorted streams) or a vehicle-constraint event (order 1).
struct LoosePending {
  double t = 0.0;
  int order = 0;
  GnssFix fix;
  ConstraintEvent event;
};

template <class Filter, int kMaxHold = 256, int kMaxPending = 64>
class LooseNavigator : public PushLoop<LooseNavigator<Filter, kMaxHold, kMaxPending>, LoosePending, kMaxHold, kMaxPending> {
  using Base = PushLoop<LooseNavigator, LoosePending, kMaxHold, kMaxPending>;
  friend Base;

 public:
  using L = typename Filter::Layout;

  /// initial: the state at initial.t (the first IMU sample's interval starts there).
  LooseNavigator(const NavigatorConfig& cfg, const NavState& initial, const StateCov<L>& P0,
                 const ImuCorrection& corr0 = ImuCorrection())
      : engine_(cfg.imu_model, cfg.loose, cfg.ut) {
    Base::start(initial.t, cfg.imu_hold, cfg.loose.cycle_period);
    engine_.start(initial, P0, corr0);
    fix_out_.innovation = last_fix_.innovation.data();
    fix_out_.nis = &last_fix_.nis;
    fix_out_.status = &fix_status_;
    fix_out_.constraint_nis = &constraint_nis_;
    fix_out_.constraint_status = &constraint_status_;
  }

  /// A GNSS position (and/or velocity) fix valid at fix.t, queued until the
  /// IMU sample that covers it is integrated.  kNotUsed: queued;
  /// kOutsideImuSpan: at or before the initial time; kTooOld: older than the
  /// last integrated sample; kQueueFull: no room in the pending queue.  A fix
  /// push_fix_problem() refuses throws std::invalid_argument (nothing queued).
  RecordStatus push_gnss_fix(const GnssFix& fix) {
    LoosePending p;
    p.t = fix.t;
    p.order = 0;
    p.fix = checked_push_fix(fix, "push_gnss_fix");
    return Base::enqueue(p);
  }

  /// A vehicle-constraint event (NHC, odometer speed, ZUPT, ZARU), queued as a fix.
  RecordStatus push_constraint(const ConstraintEvent& e) {
    LoosePending p;
    p.t = e.t;
    p.order = 1;
    p.event = e;
    return Base::enqueue(p);
  }

  /// The current output row (the batch engine's row after the last integrated sample).
  NavigatorRow<L> solution() { return navigator_row<L>(engine_.core()); }

  /// The INS state after the last feedback (not corrected by a pending x).
  const NavState& ins_state() { return engine_.core().state(); }
  /// The filter's error-state covariance.
  const StateCov<L>& covariance() { return engine_.filter().P(); }
  /// The last fix applied or refused by the gate (its innovation, NIS and status).
  const NavigatorRecord& last_fix() const { return last_fix_; }

  int updates() const { return fix_out_.updates; }
  int rejected() const { return fix_out_.rejected; }
  int constraint_updates() const { return fix_out_.constraint_updates; }
  int gate_reopened() { return engine_.core().gate.reopened(); }

 private:
  ClosedLoop<Filter>& core() { return engine_.core(); }
  void apply(const LoosePending& p) {
    if (p.order == 0) {
      engine_.apply_fix(p.fix, 0, fix_out_);
      last_fix_.status = static_cast<RecordStatus>(fix_status_);
    } else {
      engine_.apply_constraint(p.event, 0, fix_out_);
    }
  }

  LooseEngine<Filter> engine_;
  LooseOutputs fix_out_;
  NavigatorRecord last_fix_;
  std::int8_t fix_status_ = 0;
  double constraint_nis_ = NAN;
  std::int8_t constraint_status_ = 0;
};

/// The plain configuration of a TightNavigator (SI units, as the batch engine).
struct TightNavigatorConfig {
  ImuErrorModel imu_model;
  TightConfig tight;   // lever arm, propagation interval, outage cycle, gate, robust screening
  UtParams ut;
  int imu_hold = 0;    // IMU samples held back for late epochs [samples], 0 .. kMaxHold
  double clock_bias0_m = 0.0, clock_drift0_mps = 0.0;  // initial receiver clock estimate
  IsbVec isb0 = IsbVec::Zero();                         // initial inter-system biases of R, E, C [m]
};

/// A queued tight epoch: its satellites sit in the navigator's pool at slot * kMaxMeasRows.
struct TightPending {
  double t = 0.0;
  int order = 0;
  int slot = 0, n_sats = 0;
};

/// The tightly coupled engine (tight_engine.hpp) pushed one GNSS epoch of
/// pseudoranges / pseudorange rates at a time; as LooseNavigator otherwise.
template <class Filter, int kMaxHold = 256, int kMaxPendingEpochs = 8>
class TightNavigator
    : public PushLoop<TightNavigator<Filter, kMaxHold, kMaxPendingEpochs>, TightPending, kMaxHold, kMaxPendingEpochs> {
  using Base = PushLoop<TightNavigator, TightPending, kMaxHold, kMaxPendingEpochs>;
  friend Base;

 public:
  using L = typename Filter::Layout;

  /// Throws std::invalid_argument for the settings only the batch run (TightEngine::run) has: the
  /// Gauss-Markov pseudorange states (carried over each outage cycle there) and TDCP (no phase is pushed).
  TightNavigator(const TightNavigatorConfig& cfg, const NavState& initial, const StateCov<L>& P0,
                 const ImuCorrection& corr0 = ImuCorrection())
      : engine_(checked(cfg).imu_model, cfg.tight, cfg.ut) {
    Base::start(initial.t, cfg.imu_hold, cfg.tight.cycle_period);
    engine_.set_initial_isb(cfg.isb0);
    engine_.start(initial, P0, corr0, cfg.clock_bias0_m, cfg.clock_drift0_mps);
    out_.nis = &last_nis_;
    out_.status = &last_status_;
    out_.rows = &last_rows_;
    out_.clock_jump = &last_clock_jump_;
  }

  /// One GNSS epoch valid at t: n satellites (at most kMaxMeasRows; the rest
  /// are dropped as the batch engine drops them).  kNotUsed: queued; else why refused.
  /// A satellite push_sat_problem() refuses throws std::invalid_argument (nothing queued).
  RecordStatus push_pseudoranges(double t, const SatObservation* sats, int n) {
    for (int i = 0; i < std::min(std::max(n, 0), kMaxMeasRows); ++i)
      if (const char* why = push_sat_problem(sats[i]))
        throw std::invalid_argument("push_pseudoranges: satellite row " + std::to_string(i) + ": " + why);
    int slot = 0;
    while (slot < kMaxPendingEpochs && Base::any_pending([&](const TightPending& p) { return p.slot == slot; })) ++slot;
    if (slot == kMaxPendingEpochs) return Base::refuse_full(t);  // every slot pending
    TightPending p;
    p.t = t;
    p.slot = slot;
    p.n_sats = std::min(std::max(n, 0), kMaxMeasRows);
    const RecordStatus st = Base::enqueue(p);
    if (st == RecordStatus::kNotUsed)
      for (int i = 0; i < p.n_sats; ++i) pool_[slot * kMaxMeasRows + i] = sats[i];
    return st;
  }

  NavigatorRow<L> solution() { return navigator_row<L>(engine_.core()); }
  const NavState& ins_state() { return engine_.core().state(); }
  const StateCov<L>& covariance() { return engine_.filter().P(); }
  double clock_bias_m() { return engine_.core().clock_bias - engine_.filter().x()[L::kClockBias]; }
  double clock_drift_mps() { return engine_.core().clock_drift - engine_.filter().x()[L::kClockDrift]; }
  RecordStatus last_status() const { return static_cast<RecordStatus>(last_status_); }
  double last_nis() const { return last_nis_; }

  int updates() const { return out_.updates; }
  int rejected() const { return out_.rejected; }
  int rejected_sats() const { return out_.rejected_sats; }
  int gate_reopened() { return engine_.core().gate.reopened(); }

 private:
  static const TightNavigatorConfig& checked(const TightNavigatorConfig& cfg) {
    if (cfg.tight.pr_gm.enabled())
      throw std::invalid_argument("TightNavigator: pr_gm (Gauss-Markov pseudorange states) runs in the batch "
                                  "tight run only (TightEngine::run)");
    if (cfg.tight.tdcp.enabled)
      throw std::invalid_argument("TightNavigator: tdcp needs carrier phase, which the push API does not take");
    return cfg;
  }

  ClosedLoop<Filter>& core() { return engine_.core(); }
  void apply(const TightPending& p) {
    engine_.apply_epoch(pool_.data() + p.slot * kMaxMeasRows, TightEpoch{p.t, 0, p.n_sats}, 0, out_);
  }

  TightEngine<Filter> engine_;
  std::array<SatObservation, kMaxPendingEpochs * kMaxMeasRows> pool_;
  TightOutputs out_;
  double last_nis_ = NAN, last_clock_jump_ = 0.0;
  std::int8_t last_status_ = 0;
  std::int32_t last_rows_ = 0;
};

/// The plain configuration of a DelayNavigator (SI units, as the batch engine).
struct DelayNavigatorConfig {
  ImuErrorModel imu_model;
  LooseConfig loose;   // lever arm, propagation interval, outage cycle, gate
  DelayConfig delay;   // time_tolerance: an epoch at the IMU sample time (the others are the exact engine's)
  int imu_hold = 0;    // IMU samples held back for late epochs [samples], 0 .. kMaxHold
  std::array<double, 9> delay_p{{1.0}};  // P(delay = i epochs), i = 0 .. n_delay_p - 1 (seed 001 eq. (4))
  int n_delay_p = 1;
};

/// A queued receiver epoch: the records that arrived by it sit in the pool at slot * kMaxRecords.
struct DelayPending {
  double t = 0.0;
  int order = 0;
  int slot = 0, n_records = 0;
};

/// Seed 001's random-delay KF (RandomDelayEngine, delay_engine.hpp) pushed one
/// receiver epoch at a time.  At each epoch of the receiver's schedule the
/// caller pushes the GNSS records that arrived since the previous epoch (their
/// time of validity is not used: the filter does not know it; it weights the
/// S + 1 delay hypotheses with the probabilities p), also when none arrived,
/// so that block i of the stack always means "i epochs ago".  Timing and the
/// IMU hold as LooseNavigator: an epoch is pushed before the IMU sample that
/// covers it is integrated (or within imu_hold samples of it).
template <class L, int S, int kMaxHold = 256, int kMaxPendingEpochs = 8, int kMaxRecords = 8>
class DelayNavigator : public PushLoop<DelayNavigator<L, S, kMaxHold, kMaxPendingEpochs, kMaxRecords>, DelayPending,
                                       kMaxHold, kMaxPendingEpochs> {
  using Base = PushLoop<DelayNavigator, DelayPending, kMaxHold, kMaxPendingEpochs>;
  friend Base;

 public:
  using Engine = RandomDelayEngine<L, S>;
  using Filter = typename Engine::Filter;
  static constexpr int kMaxRecordsPerEpoch = kMaxRecords;

  DelayNavigator(const DelayNavigatorConfig& cfg, const NavState& initial, const StateCov<L>& P0,
                 const ImuCorrection& corr0 = ImuCorrection())
      : engine_(cfg.imu_model, cfg.loose, cfg.delay, cfg.delay_p.data(), cfg.n_delay_p),
        tol_(cfg.delay.time_tolerance) {
    Base::start(initial.t, cfg.imu_hold, cfg.loose.cycle_period);
    engine_.start(initial, P0, corr0);
    out_.innovation = last_.innovation.data();
    out_.nis = &last_.nis;
    out_.status = &status_;
  }

  /// One receiver epoch at t [s] with the n records that arrived since the
  /// previous epoch (at most kMaxRecords; the rest are refused and counted).
  /// kNotUsed: queued; kOutsideImuSpan: at or before the initial time (+ the
  /// time tolerance); kTooOld: older than the last integrated sample;
  /// kQueueFull: every pending slot taken.  A record push_fix_problem() refuses throws
  /// std::invalid_argument naming it (nothing queued).
  RecordStatus push_epoch(double t, const GnssFix* records, int n) {
    for (int i = 0; i < std::min(std::max(n, 0), kMaxRecords); ++i) checked_push_fix(records[i], "push_epoch", i);
    if (!(t > Base::t0() + tol_)) return Base::refuse(RecordStatus::kOutsideImuSpan);
    int slot = 0;
    while (slot < kMaxPendingEpochs && Base::any_pending([&](const DelayPending& p) { return p.slot == slot; })) ++slot;
    if (slot == kMaxPendingEpochs) return Base::refuse_full(t);  // every slot pending
    DelayPending p;
    p.t = t;
    p.slot = slot;
    p.n_records = std::min(std::max(n, 0), kMaxRecords);
    const RecordStatus st = Base::enqueue(p);
    if (st == RecordStatus::kNotUsed) {
      for (int i = 0; i < p.n_records; ++i) pool_[slot * kMaxRecords + i] = normalized_push_fix(records[i]);  // checked above
      dropped_ += std::max(n, 0) - p.n_records;
    }
    return st;
  }

  NavigatorRow<L> solution() { return navigator_row<L>(engine_.core()); }
  const NavState& ins_state() { return engine_.core().state(); }
  /// The newest block of the stacked covariance (the current error state's).
  StateCov<L> covariance() const { return engine_.filter().P(); }
  /// The last record applied or refused by the gate (its innovation, NIS and status).
  const NavigatorRecord& last_record() const { return last_; }

  int updates() const { return out_.updates; }
  int rejected() const { return out_.rejected; }
  int dropped_records() const { return dropped_; }  // beyond kMaxRecords in one epoch
  int gate_reopened() { return engine_.core().gate.reopened(); }

 private:
  ClosedLoop<Filter>& core() { return engine_.core(); }

  template <class NextT, class ApplyNext>
  void step_sample(const ImuIncrement& raw, double t_prev, NextT&& next_t, ApplyNext&& apply_next) {
    engine_.process_sample(raw, t_prev, next_t, [&](double) { apply_next(); });
  }

  void apply(const DelayPending& p) {
    for (int i = 0; i < p.n_records; ++i) {
      engine_.receive(pool_[p.slot * kMaxRecords + i], 0, out_);
      last_.status = static_cast<RecordStatus>(status_);
    }
  }

  Engine engine_;
  double tol_;
  std::array<GnssFix, kMaxPendingEpochs * kMaxRecords> pool_;
  DelayOutputs out_;
  NavigatorRecord last_;
  std::int8_t status_ = 0;
  int dropped_ = 0;
};

}  // namespace insnav
