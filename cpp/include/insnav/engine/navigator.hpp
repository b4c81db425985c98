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
// (RecordStatus::kTooOld) and counted, never applied at a wrong time.
//
// Memory: fixed capacities (kMaxHold held samples, kMaxPending records), no
// heap allocation after construction.  The object is large (the filter's
// fixed-size matrices): allocate it once, e.g. with std::make_unique.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>

#include "insnav/engine/loose_engine.hpp"

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
  StateVec<L> sigma = StateVec<L>::Zero();      // sqrt(diag P), layout order
  Eigen::Matrix<double, 12, 1> imu_err;         // acc bias, gyro bias, acc scale, gyro scale (SI)
  Eigen::Matrix<double, 2, 1> odo_scale;        // odometer scale factor and its sigma (Layout16Odo)
};

/// What became of the last GNSS fix applied (or refused).
struct NavigatorRecord {
  RecordStatus status = RecordStatus::kNotUsed;
  double nis = NAN;
  std::array<double, 6> innovation{};  // INS - GNSS before the update: N, E, D [m], vN, vE, vD [m/s] (NaN: absent)
};

template <class Filter, int kMaxHold = 256, int kMaxPending = 64>
class LooseNavigator {
 public:
  using L = typename Filter::Layout;
  static_assert(kMaxHold >= 1 && kMaxPending >= 1, "capacities must be positive");

  /// initial: the state at initial.t (the first IMU sample's interval starts there).
  LooseNavigator(const NavigatorConfig& cfg, const NavState& initial, const StateCov<L>& P0,
                 const ImuCorrection& corr0 = ImuCorrection())
      : engine_(cfg.imu_model, cfg.loose, cfg.ut), cfg_(cfg) {
    if (cfg.imu_hold < 0 || cfg.imu_hold > kMaxHold) throw std::invalid_argument("imu_hold must be in 0 .. kMaxHold");
    engine_.start(initial, P0, corr0);
    t_pushed_ = t_done_ = initial_t_ = initial.t;
    fix_out_.innovation = last_fix_.innovation.data();
    fix_out_.nis = &last_fix_.nis;
    fix_out_.status = &fix_status_;
    fix_out_.constraint_nis = &constraint_nis_;
    fix_out_.constraint_status = &constraint_status_;
  }

  /// One IMU increment over (t_prev, t]: dtheta_b [rad], dv_b [m/s] (FRD).
  /// Returns false (nothing done) when t does not increase.
  bool push_imu(double t, const Vec3& dtheta_b, const Vec3& dv_b) {
    if (!(t > t_pushed_)) return false;
    ImuIncrement& raw = hold_[(hold_head_ + hold_n_) % kMaxHold];
    raw.t = t;
    raw.dt = t - t_pushed_;
    raw.dtheta_b = dtheta_b;
    raw.dv_b = dv_b;
    ++hold_n_;
    t_pushed_ = t;
    while (hold_n_ > cfg_.imu_hold) integrate_oldest();
    return true;
  }

  /// A GNSS position (and/or velocity) fix valid at fix.t, queued until the
  /// IMU sample that covers it is integrated.  kNotUsed: queued;
  /// kOutsideImuSpan: at or before the initial time; kTooOld: older than the
  /// last integrated sample (or the queue is full).
  RecordStatus push_gnss_fix(const GnssFix& fix) {
    Pending p;
    p.t = fix.t;
    p.is_fix = true;
    p.fix = fix;
    return enqueue(p);
  }

  /// A vehicle-constraint event (NHC, odometer speed, ZUPT, ZARU), queued as a fix.
  RecordStatus push_constraint(const ConstraintEvent& e) {
    Pending p;
    p.t = e.t;
    p.is_fix = false;
    p.event = e;
    return enqueue(p);
  }

  /// Integrate every held sample (the end of a run, or no more late records expected).
  void flush() {
    while (hold_n_ > 0) integrate_oldest();
  }

  /// The current output row (the batch engine's row after the last integrated sample).
  NavigatorRow<L> solution() {
    NavOutputs o;
    double t = 0, llh[3], v[3], rpy[3], sig[L::kSize], err[12], odo[2] = {0.0, 0.0};
    o.t = &t;
    o.llh = llh;
    o.v_n = v;
    o.rpy = rpy;
    o.sigma = sig;
    o.imu_err = err;
    o.odo_scale = odo;
    engine_.core().write_output(o);
    NavigatorRow<L> r;
    r.t = t;
    r.llh = Vec3(llh[0], llh[1], llh[2]);
    r.v_n = Vec3(v[0], v[1], v[2]);
    r.rpy = Vec3(rpy[0], rpy[1], rpy[2]);
    for (int j = 0; j < L::kSize; ++j) r.sigma[j] = sig[j];
    for (int j = 0; j < 12; ++j) r.imu_err[j] = err[j];
    r.odo_scale << odo[0], odo[1];
    return r;
  }

  /// The INS state after the last feedback (not corrected by a pending x).
  const NavState& ins_state() { return engine_.core().state(); }
  /// The filter's error-state covariance.
  const StateCov<L>& covariance() { return engine_.filter().P(); }
  /// The last fix applied or refused by the gate (its innovation, NIS and status).
  const NavigatorRecord& last_fix() const { return last_fix_; }

  double t_integrated() const { return t_done_; }  // last integrated sample [s]
  int held_samples() const { return hold_n_; }
  int pending_records() const { return pend_n_; }
  std::int64_t samples() const { return samples_; }
  int updates() const { return fix_out_.updates; }
  int rejected() const { return fix_out_.rejected; }
  int constraint_updates() const { return fix_out_.constraint_updates; }
  int gate_reopened() { return engine_.core().gate.reopened(); }
  int refused_records() const { return refused_; }  // too old, outside the span, or the queue full

 private:
  struct Pending {
    double t = 0.0;
    bool is_fix = true;
    GnssFix fix;
    ConstraintEvent event;
  };

  RecordStatus enqueue(const Pending& p) {
    if (!(p.t > initial_t_)) {
      ++refused_;
      return RecordStatus::kOutsideImuSpan;
    }
    if (!(p.t > t_done_) || pend_n_ == kMaxPending) {
      ++refused_;
      return RecordStatus::kTooOld;
    }
    // sorted by time, a fix before a constraint event at the same time, else in push order
    // (the batch engine's merge of its two sorted streams)
    int i = pend_n_;
    while (i > 0 && (pend_[i - 1].t > p.t || (pend_[i - 1].t == p.t && p.is_fix && !pend_[i - 1].is_fix))) {
      pend_[i] = pend_[i - 1];
      --i;
    }
    pend_[i] = p;
    ++pend_n_;
    return RecordStatus::kNotUsed;
  }

  void integrate_oldest() {
    const ImuIncrement raw = hold_[hold_head_];
    hold_head_ = (hold_head_ + 1) % kMaxHold;
    --hold_n_;
    engine_.core().process_sample(
        raw, t_done_, cfg_.loose.cycle_period, [&]() { return pend_n_ > pend_head_ ? pend_[pend_head_].t : kInf; },
        [&]() {
          const Pending& p = pend_[pend_head_++];
          if (p.is_fix) {
            engine_.apply_fix(p.fix, 0, fix_out_);
            last_fix_.status = static_cast<RecordStatus>(fix_status_);
          } else {
            engine_.apply_constraint(p.event, 0, fix_out_);
          }
        });
    // drop the applied records from the queue front
    if (pend_head_ > 0) {
      for (int j = pend_head_; j < pend_n_; ++j) pend_[j - pend_head_] = pend_[j];
      pend_n_ -= pend_head_;
      pend_head_ = 0;
    }
    t_done_ = raw.t;
    ++samples_;
  }

  LooseEngine<Filter> engine_;
  NavigatorConfig cfg_;
  std::array<ImuIncrement, kMaxHold> hold_;
  int hold_head_ = 0, hold_n_ = 0;
  std::array<Pending, kMaxPending> pend_;
  int pend_head_ = 0, pend_n_ = 0;
  double t_pushed_ = 0.0, t_done_ = 0.0;
  double initial_t_ = 0.0;
  std::int64_t samples_ = 0;
  int refused_ = 0;
  LooseOutputs fix_out_;
  NavigatorRecord last_fix_;
  std::int8_t fix_status_ = 0;
  double constraint_nis_ = NAN;
  std::int8_t constraint_status_ = 0;
};

}  // namespace insnav
