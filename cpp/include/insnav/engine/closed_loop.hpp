// insnav/engine/closed_loop.hpp -- the closed-loop core shared by every
// engine: strapdown mechanization at the IMU rate, the error-state filter's
// cycles and propagation intervals, feedback of the estimate into the INS, the
// IMU corrections and (layouts with clock states) the receiver clock, and the
// output rows.  An engine adds only its measurements (loose_engine.hpp,
// tight_engine.hpp, delay_engine.hpp).
//
// Timing (seed 000 sec. 3): a filter *cycle* spans one GNSS period.  Inside a
// cycle the error state is propagated over intervals of about
// `propagation_interval` seconds, each given to the filter with the INS
// solution at its start, middle and end.  A record valid at t_g inside an IMU
// interval (t_{k-1}, t_k] is applied exactly at t_g: the IMU increment is
// split in proportion (constant rate within the interval), the INS is advanced
// to t_g, the cycle is closed, the filter updates, the estimate is fed back,
// and the rest of the increment follows.  With no record for `cycle_period`
// (a GNSS outage) the cycle is closed without update and without feedback
// (seed 000 eqs. (26)-(29)).
//
// ClosedLoop is a copyable value (the exact time-tagged engine checkpoints it
// whole).  Two things are computed only when needed: the IMU rates (a few
// times per propagation interval, not per sample) and sqrt(diag P) / the IMU
// error estimates of the output rows (only after propagate, update or
// feedback changed them).
//
// The Filter type provides: initialize, begin_cycle, propagate, end_cycle,
// x, P, reset_state, cholesky_repairs (ekf.hpp, rbukf.hpp, ukf.hpp, upf.hpp,
// particle_filter.hpp, random_delay_kf.hpp).  No heap allocation.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <new>
#include <type_traits>
#include <utility>

#include "insnav/filter/nis_gate.hpp"
#include "insnav/filter/rts_smoother.hpp"
#include "insnav/filter/sigma_points.hpp"
#include "insnav/filter/types.hpp"
#include "insnav/ins/mechanization.hpp"
#include "insnav/ins/nav_error.hpp"

namespace insnav {

/// What became of one GNSS record (loose fix or tight epoch); the same codes
/// in Python (insnav.filters.solution.RecordStatus, GNSS_STATUS).
enum class RecordStatus : std::int8_t {
  kNotUsed = 0,              ///< nothing to use (masked out, or no satellite: prediction only)
  kApplied = 1,              ///< the update was applied and fed back
  kRejectedByGate = 2,       ///< NIS above the gate
  kNotPositiveDefinite = 3,  ///< innovation covariance not positive definite
  kOutsideImuSpan = 4,       ///< valid before the first or after the last IMU sample
  kTooOld = 5,               ///< exact delay engine: older than the history it keeps
  kQueueFull = 6,            ///< push API: every slot of the pending-record queue taken
};

inline RecordStatus status_of(const UpdateResult& r) {
  return r.applied ? RecordStatus::kApplied
                   : (r.rejected_by_gate ? RecordStatus::kRejectedByGate : RecordStatus::kNotPositiveDefinite);
}

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

/// Caller-owned per-sample output buffers and run counters (row-major, any
/// buffer may be null).  Engines extend it with their per-record outputs.
struct NavOutputs {
  double* t = nullptr;        // [s]
  double* llh = nullptr;      // (.,3) lat, lon [rad], h [m]
  double* v_n = nullptr;      // (.,3) [m/s]
  double* rpy = nullptr;      // (.,3) [rad]
  double* sigma = nullptr;    // (.,sigma_cols) sqrt(diag P) of the first sigma_cols states; columns kAtt..kAtt+2
                              // the 1-sigmas of the row's roll, pitch, yaw (euler_sigmas_from_psi), not of psi
  int sigma_cols = 0;         // <= 0 or >= n_state: all n_state
  double* imu_err = nullptr;  // (.,12) acc bias, gyro bias, acc scale, gyro scale (SI)
  double* clock = nullptr;    // (.,2) receiver clock bias [m], drift [m/s] (layouts with clock states)
  double* isb = nullptr;      // (.,3) inter-system biases of R, E, C [m] (layouts with ISB states)
  double* odo_scale = nullptr;  // (.,2) odometer scale factor s [-] and its 1-sigma (layouts with kOdoScale)
  double* time_offset = nullptr;  // (.,2) IMU-GNSS time offset t_d [s] and its 1-sigma (layouts with kTimeOffset)
  double* lever_arm = nullptr;    // (.,6) GNSS lever arm l_b [m] (FRD) and its 1-sigma (layouts with kLeverArm)
  double* odo_lever = nullptr;    // (.,6) odometer lever arm [m] (FRD) and its 1-sigma (layouts with kOdoLever)
  std::int64_t n_out = 0;     // rows written
  int updates = 0, rejected = 0, cholesky_repairs = 0;
  int gate_reopened = 0;       // records the gate rejected but applied, P scaled, after reopen_after rejections in a row
  int gate_outage_accepted = 0;  // records above the plain gate applied by its outage-aware test (nis_gate.hpp)

  // Interrupt and progress hook (may be null): called every `poll_every`
  // samples with the sample index and count; false stops the run with
  // `interrupted` set (the rows written so far stay valid).  The bindings use
  // it to check for Ctrl-C (taking the GIL only for that check).
  bool (*poll)(void* ctx, std::int64_t k, std::int64_t n) = nullptr;
  void* poll_ctx = nullptr;
  std::int64_t poll_every = 2048;
  bool interrupted = false;

  /// Call at the top of sample k of n: true when the run is to stop.
  bool stop_requested(std::int64_t k, std::int64_t n) {
    if (!poll || --poll_countdown_ > 0) return false;
    poll_countdown_ = poll_every;
    if (!poll(poll_ctx, k, n)) interrupted = true;
    return interrupted;
  }

  void set_status(std::int8_t* status, std::int64_t g, RecordStatus s) const {
    if (status) status[g] = static_cast<std::int8_t>(s);
  }

  std::int64_t poll_countdown_ = 1;  // samples to the next poll (the first sample polls at once)
};

/// One raw IMU sample k of the caller's arrays: the increment over (t_prev, t[k]].
inline ImuIncrement raw_imu_sample(std::int64_t k, double t_prev, const double* t, const double* dtheta_b,
                                   const double* dv_b) {
  ImuIncrement raw;
  raw.t = t[k];
  raw.dt = t[k] - t_prev;
  raw.dtheta_b = Vec3(dtheta_b[3 * k], dtheta_b[3 * k + 1], dtheta_b[3 * k + 2]);
  raw.dv_b = Vec3(dv_b[3 * k], dv_b[3 * k + 1], dv_b[3 * k + 2]);
  return raw;
}

template <class Filter>
Filter make_filter(const ImuErrorModel& model, const UtParams& ut) {
  if constexpr (std::is_constructible_v<Filter, const ImuErrorModel&, const UtParams&>)
    return Filter(model, ut);
  else
    return Filter(model);
}

/// Inter-system bias estimates of the non-GPS systems 1..kNumSystems-1 [m].
using IsbVec = Eigen::Matrix<double, kNumSystems - 1, 1>;

template <class Filter>
struct ClosedLoop {
  using L = typename Filter::Layout;

  Filter filter;
  Strapdown ins;
  ImuCorrection corr;
  NisGate gate;  // the GNSS records' innovation gate (the engine sets its config)
  double clock_bias = 0.0, clock_drift = 0.0;  // receiver clock estimate [m], [m/s] (kHasClock<L>)
  IsbVec isb = IsbVec::Zero();                  // inter-system bias estimates of systems 1..3 [m] (kHasIsb<L>)
  // Odometer scale factor s^ [-] (kHasOdoScale<L>): fed back like the IMU
  // biases, 1 + s^ <- (1 + s^)(1 + ds) (meas/vehicle.hpp); the engine applies
  // it to the odometer reading.  With a finite correlation time it decays as
  // the state model says (s' = -s / tau), exp(-dt / tau) per propagation interval.
  double odo_scale = 0.0;
  double odo_scale_tau = kInf;  // [s] (ImuErrorModel::odo_scale_tau)
  // Self-calibration estimates (layout.hpp), fed back like the clock: the
  // IMU-GNSS time offset t_d^ [s] (kHasTimeOffset<L>; the engines apply a
  // record tagged t_g at t_g - t_d^) and the GNSS lever arm l_b^ [m]
  // (kHasLeverArm<L>; used instead of the configured one).  reset() starts
  // them from time_offset0 / lever_arm_b0.
  double time_offset = 0.0, time_offset0 = 0.0;
  Vec3 lever_arm_b = Vec3::Zero(), lever_arm_b0 = Vec3::Zero();
  // the odometer / vehicle-constraint lever arm l_o^ [m] (kHasOdoLever<L>; the loose engine uses it
  // instead of VehicleConstraintConfig::lever_arm_b), from odo_lever_b0
  Vec3 odo_lever_b = Vec3::Zero(), odo_lever_b0 = Vec3::Zero();
  double propagation_interval = 0.02;          // [s]
  double cycle_start = 0.0, interval_t0 = 0.0;

  explicit ClosedLoop(const Filter& f, double propagation_interval_s = 0.02)
      : filter(f), propagation_interval(propagation_interval_s) {}

  /// Record one SmootherEpoch per filter epoch into buf[0..capacity) for the
  /// RTS backward pass (rts_smoother.hpp).  Needs a filter that keeps its
  /// cycle transition (Ekf::track_cycle_transition); call before reset().
  /// The storage may be uninitialized: each epoch is constructed in place
  /// when recorded, so capacity that is never used is never touched.
  void record_for_smoother(SmootherEpoch<L>* buf, std::int64_t capacity) {
    rec_ = buf;
    rec_cap_ = capacity;
    if constexpr (kCanRecordForSmoother) filter.track_cycle_transition(buf != nullptr);
  }
  std::int64_t recorded_epochs() const { return rec_n_; }
  bool recording() const { return rec_ != nullptr && !rec_overflow_; }

  /// An engine with its own joint update (rtk_ins_engine.hpp) fed the error
  /// estimate x back into the INS itself: the smoother's record of this epoch
  /// counts it (several feedbacks in one epoch add up, to first order).
  void smoother_feedback(const StateVec<L>& x) {
    if (!rec_pending_) return;
    SmootherEpoch<L>& e = rec_[rec_n_ - 1];
    e.x = e.fed_back ? StateVec<L>(e.x + x) : x;
    e.fed_back = true;
  }

  /// The smoother's filtered estimate of this epoch conditioned on more than
  /// the forward filter used (rts_smoother.hpp, c_k): the error of the
  /// post-feedback nominal is estimated as dx (not fed back) with covariance
  /// P - dP, e.g. the integer-fixed solution of an RTK/INS epoch (Teunissen
  /// 1995, eq. (6): dx = P_xa Q_a^-1 (a_hat - a_fix), dP = P_xa Q_a^-1 P_ax).
  /// The prediction to the next epoch is conditioned the same way there
  /// (xp += Phi dx, Pp -= Phi dP Phi', C from P - dP): by the EKF's cycle
  /// transition in close_cycle; the unscented filters have none, and their
  /// engine gives its statistically linearised one through
  /// condition_prediction_for_smoother.
  void condition_for_smoother(const StateVec<L>& dx, const StateCov<L>& dP) {
    if (!rec_pending_) return;
    cond_pred_pending_ = false;  // (condition_prediction_for_smoother comes first)
    cond_dx_ = dx;
    cond_dP_ = dP;
    cond_pending_ = true;
  }

  /// The unscented filters (RB-UKF, UKF): the prediction of the epoch just
  /// recorded (close_cycle) from the previous epoch's conditioned estimate
  /// (condition_for_smoother), through the cycle's statistically linearised
  /// transition Phi = C^T P_0^-1 (Sarkka 2008, "Unscented Rauch-Tung-Striebel
  /// smoother", IEEE TAC 53(3), eq. (13); the engine computes it, e.g.
  /// RtkInsEngine::cycle_phi): xp += Phi dx, Pp -= Phi dP Phi', and the UT
  /// cross-covariance C = P_0 Phi' of the points drawn from P_0 becomes that of
  /// the conditioned estimate, (P_0 - dP) Phi' = C - dP Phi' -- the EKF's
  /// conditioning (close_cycle) with the statistical linearisation in place of
  /// its Jacobian product, so the smoother gain C Pp^-1 is the EKF's when Phi
  /// is.  Call once after close_cycle and before the next condition_for_smoother
  /// (which replaces dx, dP); a no-op when the previous epoch was not
  /// conditioned or the filter has its own transition.
  void condition_prediction_for_smoother(const StateCov<L>& Phi) {
    if (!cond_pred_pending_ || !rec_pending_) return;
    cond_pred_pending_ = false;
    SmootherEpoch<L>& e = rec_[rec_n_ - 1];
    e.x_pred.noalias() += Phi * cond_dx_;
    StateCov<L> dP_PhiT;  // fixed size, on the stack
    dP_PhiT.noalias() = cond_dP_ * Phi.transpose();
    e.P_pred.noalias() -= Phi * dP_PhiT;
    e.C -= dP_PhiT;
  }

  /// A relative measurement of this epoch and the previous one applied to the
  /// filter by stochastic cloning (meas/tdcp.hpp): the smoother's moments of the
  /// step from the previous epoch become the clone-augmented posterior ones
  /// (rts_smoother.hpp): the previous epoch's estimate += dx_prev, its
  /// covariance -= dP_prev, the cross-covariance -= dC (= B S^-1 A'), and the
  /// prediction to this epoch the filter's updated x and P.  Call right after
  /// the update; the previous epoch must be the last one recorded before this one.
  void clone_update_for_smoother(const StateVec<L>& dx_prev, const StateCov<L>& dP_prev, const StateCov<L>& dC) {
    if (!rec_pending_ || rec_n_ < 2) return;
    SmootherEpoch<L>& prev = rec_[rec_n_ - 2];
    SmootherEpoch<L>& e = rec_[rec_n_ - 1];
    prev.x_cond += dx_prev;
    prev.P -= dP_prev;
    e.C -= dC;
    e.x_pred = filter.x();
    e.P_pred = filter.P();
  }
  bool recording_overflowed() const { return rec_overflow_; }

  void reset(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, double clock_bias0 = 0.0,
             double clock_drift0 = 0.0, const IsbVec& isb0 = IsbVec::Zero()) {
    rec_n_ = 0;
    rec_overflow_ = false;
    rec_pending_ = false;
    cond_pending_ = cond_next_ = cond_pred_pending_ = false;
    if (rec_) {  // epoch 0: the initial state, nothing fed back
      if (rec_cap_ < 1) {
        rec_overflow_ = true;
      } else {
        SmootherEpoch<L>& e = *new (&rec_[rec_n_++]) SmootherEpoch<L>;  // constructed in place (see record_for_smoother)
        e.t = initial.t;
        e.P = P0;
        P_post_ = P0;
      }
    }
    ins.reset(initial);
    corr = corr0;
    clock_bias = clock_bias0;
    clock_drift = clock_drift0;
    isb = isb0;
    odo_scale = 0.0;
    time_offset = time_offset0;
    lever_arm_b = lever_arm_b0;
    odo_lever_b = odo_lever_b0;
    filter.initialize(P0);
    rates_stale_ = false;
    omega_ib_b_.setZero();
    f_ib_b_.setZero();
    omega_lp_b_.setZero();
    omega_lever_b_.setZero();
    have_lp_ = false;
    out_cache_dirty_ = true;
    start_cycle();
  }

  const NavState& state() const { return ins.state(); }

  /// Corrected angular rate and specific force of the last integrated increment.
  const Vec3& omega_ib_b() {
    rates();
    return omega_ib_b_;
  }
  const Vec3& f_ib_b() {
    rates();
    return f_ib_b_;
  }

  /// Time constant [s] of the low-passed angular rate of the lever-arm
  /// states' H columns (omega_ib_b_lever).
  static constexpr double kLeverRateTau = 0.1;

  /// The angular rate [rad/s] of the lever-arm states' velocity columns
  /// (meas/gnss_loose.hpp, meas/pseudorange.hpp; the odometer / vehicle-constraint
  /// lever arm's columns, meas/vehicle.hpp, alike): the corrected rate low-passed
  /// over kLeverRateTau (first order, alpha = dt / tau per increment) up to the
  /// raw increment BEFORE the one being integrated.  The residual must take
  /// the rate of the last increment (the antenna velocity C_nb (omega x l) at
  /// that instant), and that rate carries the gyro's white noise n (ARW /
  /// sqrt(dt): 8e-4 rad/s for 0.2 deg/sqrt(h) at 200 Hz), so the residual
  /// holds C_nb (n x l_b^).  The same n in H makes an errors-in-variables
  /// regression (Fuller 1987, ch. 1): where the true rate is small (roll and
  /// pitch rates on a level road) the noise alone fits dl_b = l_b^, i.e. it
  /// pulls the estimate towards zero, and its fake information makes the
  /// sigma too small (the vertical lever arm of a simulated car came out 0.6-1.1
  /// m off with a sigma of 0.23 m; docs/algorithms.md section 21).  This rate
  /// holds no noise of the current increment (no correlation with the
  /// residual) and the older noise falls to ARW^2 / (2 tau) in variance; its
  /// lag, omega-dot tau, multiplies only the state error dl_b.
  /// Layouts with the GNSS or odometer lever-arm states (zero otherwise).
  const Vec3& omega_ib_b_lever() const { return omega_lever_b_; }

  /// The INS acceleration over the Earth in n [m/s^2] at the current state:
  /// a_n = C_nb f_ib_b + g_n - (2 omega_ie_n + omega_en_n) x v_n (the
  /// velocity equation of the mechanization; the time-offset columns,
  /// meas/gnss_loose.hpp, meas/pseudorange.hpp).
  Vec3 acceleration_n() {
    rates();
    const NavState& s = ins.state();
    EarthTerms e;
    e.evaluate(s.lat, s.h, s.v_n);
    return s.q_nb.toRotationMatrix() * f_ib_b_ + Vec3(0.0, 0.0, e.g) -
           (2.0 * e.omega_ie_n + e.omega_en_n).cross(s.v_n);
  }

  /// The time at which a record tagged t_g (GNSS time) is applied: t_g - t_d^
  /// with the time-offset state, else t_g.
  double record_time(double t_g) const {
    if constexpr (kHasTimeOffset<L>) return t_g - time_offset;
    else return t_g;
  }

  /// Integrate the fraction (a0, a1] of one raw IMU increment.
  void step(const ImuIncrement& raw, double a0, double a1) {
    ImuIncrement imu;
    const double f = a1 - a0;
    imu.dt = raw.dt * f;
    imu.t = raw.t - raw.dt * (1.0 - a1);
    imu.dtheta_b = raw.dtheta_b * f;
    imu.dv_b = raw.dv_b * f;
    if (shadow_on_) {  // the output shadow: the same increment, its own corrections
      ImuIncrement si = imu;
      shadow_corr_.apply(si);
      shadow_ins_.update(si);
    }
    corr.apply(imu);
    if constexpr (kHasLeverArm<L> || kHasOdoLever<L>) lever_rate_step(imu, a0 == 0.0);
    ins.update(imu);
    if constexpr (kHasClock<L>) clock_bias += clock_drift * imu.dt;
    last_imu_ = imu;
    rates_stale_ = true;
    const NavState& s = ins.state();
    const double elapsed = s.t - interval_t0;
    if (!have_mid_ && elapsed >= 0.5 * propagation_interval) {
      set_point(iv_.mid);
      have_mid_ = true;
    }
    if (elapsed >= propagation_interval - 1e-12) flush_interval();
  }

  void start_cycle() {
    cond_pred_pending_ = false;  // the closed cycle's prediction is conditioned by now, or never
    if (rec_pending_) {  // close the epoch: its posterior (x was saved by feedback() if fed back)
      SmootherEpoch<L>& e = rec_[rec_n_ - 1];
      if (!e.fed_back) e.x = filter.x();
      e.P = filter.P();
      if (cond_pending_) {  // condition_for_smoother
        e.x_cond = cond_dx_;
        e.P -= cond_dP_;
        cond_pending_ = false;
        cond_next_ = true;
      }
      P_post_ = e.P;
      rec_pending_ = false;
    }
    cycle_start = ins.state().t;
    interval_t0 = cycle_start;
    set_point(iv_.start);
    have_mid_ = false;
    filter.begin_cycle();
  }

  void close_cycle() {
    flush_interval();
    filter.end_cycle();
    out_cache_dirty_ = true;
    if constexpr (kCanRecordForSmoother) {
      if (rec_ && !rec_overflow_) {  // the prediction to this epoch
        if (rec_n_ >= rec_cap_) {
          rec_overflow_ = true;
          return;
        }
        SmootherEpoch<L>& e = *new (&rec_[rec_n_++]) SmootherEpoch<L>;
        e.t = ins.state().t;
        e.x_pred = filter.x();
        e.x_rows = e.x_pred;  // what the rows carry; x_pred may be conditioned below
        e.P_pred = filter.P();
        if constexpr (kTracksCross)  // the unscented filters' UT cross-covariance
          e.C = filter.cycle_cross_covariance();
        else  // EKF: P_k Phi'
          e.C.noalias() = P_post_ * filter.cycle_transition().transpose();
        if constexpr (kTracksTransition) {
          if (cond_next_) {  // the prediction from the conditioned estimate (condition_for_smoother)
            const StateCov<L>& Phi = filter.cycle_transition();
            e.x_pred.noalias() += Phi * cond_dx_;
            StateCov<L> dP_PhiT;  // fixed size, on the stack
            dP_PhiT.noalias() = cond_dP_ * Phi.transpose();
            e.P_pred.noalias() -= Phi * dP_PhiT;
          }
        }
        // the unscented filters: conditioned by the engine's transition (condition_prediction_for_smoother)
        cond_pred_pending_ = kTracksCross && !kTracksTransition && cond_next_;
        cond_next_ = false;
        e.fed_back = false;
        rec_pending_ = true;
      }
    }
  }

  /// No record for a cycle period (an outage): true when the cycle is to be
  /// closed without an update.
  bool outage_due(double cycle_period) const { return ins.state().t - cycle_start >= cycle_period - 1e-9; }

  /// The filter's measurement update (the output cache follows).
  template <class Meas>
  UpdateResult update(const Meas& meas, double gate_chi2) {
    out_cache_dirty_ = true;
    return filter.update(meas, gate_chi2);
  }

  /// The measurement update of a GNSS record through the record stream's
  /// innovation gate (nis_gate.hpp: the chi-square quantile of its row count).
  template <class Meas>
  UpdateResult update_gated(const Meas& meas) {
    const int m = static_cast<int>(meas.linear().rows());
    const double t = ins.state().t;
    double threshold = gate.nominal_threshold(m);
    bool bridged = false;
    if constexpr (kCanInflate) {
      // outage-aware test (nis_gate.hpp): passed -> the plain update, ungated
      if (threshold > 0.0 && gate.outage_aware(t) &&
          mismatch_nis(meas.linear(), gate.config().mismatch) <= threshold) {
        bridged = true;
        threshold = 0.0;
      }
    }
    UpdateResult r = update(meas, threshold);
    if (bridged && r.applied && !(r.nis > gate.nominal_threshold(m))) bridged = false;  // passed the plain test too
    bool forced = false;
    if (r.rejected_by_gate && gate.reopening()) {
      // lock-out recovery (nis_gate.hpp): the covariance under which this
      // innovation is ordinary, inflated where the record observes it, then
      // the update without the gate
      if constexpr (kCanInflate) {
        const double lambda = r.nis / m;
        StateCov<L> dP;  // fixed size, on the stack
        if (lambda > 1.0 && std::isfinite(lambda) && observed_inflation(meas.linear(), lambda, dP)) {
          filter.add_covariance(dP);
          if (rec_pending_) rec_[rec_n_ - 1].P_pred += dP;  // the smoother sees it as process noise
        }
      }
      r = update(meas, 0.0);
      forced = r.applied;
    }
    gate.record(r, forced, t, bridged);
    return r;
  }

  /// The lock-out recovery's covariance increment (nis_gate.hpp):
  /// dP = (lambda - 1) P H' (H P H')^-1 H P, the covariance inflated by lambda
  /// in the directions the record observes only (H (P + dP) H' = lambda H P H'),
  /// so that its innovation is ordinary, while what the record does not see
  /// (attitude, biases, as far as they are uncorrelated with it) keeps its
  /// covariance: scaling the whole P by lambda made a run of records noisier
  /// than their sigma (a multipath burst) inflate the attitude again at every
  /// reopening until the linearisation failed.  H P H' is singular when the
  /// rows outnumber the states they observe (a tight epoch of 5 or more
  /// pseudoranges: position, clock and the lever arm's attitude terms span at
  /// most 4 + ISB directions), so the inverse is taken of
  /// H P H' + delta I, delta = 1e-10 max diag(H P H'): the rows of H P have no
  /// component in its null space, so this is the pseudo-inverse to 1e-10.
  /// False (dP untouched) when that fails (a non-finite P).  No heap.
  bool observed_inflation(const LinearMeasurement<L>& lin, double lambda, StateCov<L>& dP) {
    using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
    using HP = Eigen::Matrix<double, Eigen::Dynamic, L::kSize, Eigen::RowMajor, kMaxMeasRows, L::kSize>;
    const int m = lin.rows();
    if (m == 0) return false;
    HP hp(m, L::kSize);
    hp.noalias() = lin.H * filter.P();
    Dyn A(m, m);
    A.noalias() = hp * lin.H.transpose();
    const double delta = 1e-10 * A.diagonal().maxCoeff();
    if (!(delta > 0.0) || !std::isfinite(delta)) return false;
    A.diagonal().array() += delta;
    Eigen::LLT<Dyn> llt(A);
    if (llt.info() != Eigen::Success) return false;
    llt.matrixL().solveInPlace(hp);  // L^-1 H P: dP = (lambda - 1) (L^-1 H P)' (L^-1 H P)
    dP.noalias() = (lambda - 1.0) * (hp.transpose() * hp);
    dP = (0.5 * (dP + dP.transpose())).eval();
    return dP.allFinite();
  }

  /// The NIS of `lin` under S_a = alpha H P H' + R (the outage-aware test of
  /// nis_gate.hpp); +inf when S_a is not positive definite.  No heap.
  double mismatch_nis(const LinearMeasurement<L>& lin, double alpha) {
    using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
    using Vm = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxMeasRows, 1>;
    using HP = Eigen::Matrix<double, Eigen::Dynamic, L::kSize, Eigen::RowMajor, kMaxMeasRows, L::kSize>;
    const int m = lin.rows();
    if (m == 0) return 0.0;
    const Vm y = lin.residual - lin.H * filter.x();
    HP hp(m, L::kSize);
    hp.noalias() = lin.H * filter.P();
    Dyn S(m, m);
    S.noalias() = alpha * (hp * lin.H.transpose());
    S += lin.R;
    Eigen::LLT<Dyn> llt(S);
    if (llt.info() != Eigen::Success) return kInf;
    const double nis = y.dot(llt.solve(y));
    return std::isfinite(nis) ? nis : kInf;
  }

  /// Call after changing the filter directly (e.g. a delayed update).
  void touch() { out_cache_dirty_ = true; }

  /// Closed loop: correct the INS, the IMU corrections, the receiver clock and
  /// the odometer scale factor with x, then x = 0.
  void feedback() {
    const StateVec<L> x = filter.x();
    if (rec_pending_) {
      rec_[rec_n_ - 1].x = x;
      rec_[rec_n_ - 1].fed_back = true;
    }
    NavState s = ins.state();
    apply_nav_error(s, x.template segment<3>(L::kPos), x.template segment<3>(L::kVel),
                    x.template segment<3>(L::kAtt));  // ins/nav_error.hpp
    corr.acc_bias += x.template segment<3>(L::kAccBias);
    corr.gyro_bias += x.template segment<3>(L::kGyroBias);
    if constexpr (kHasScale<L>) {
      corr.acc_scale += x.template segment<3>(L::kAccScale);
      corr.gyro_scale += x.template segment<3>(L::kGyroScale);
    }
    if constexpr (kHasClock<L>) {
      clock_bias -= x[L::kClockBias];
      clock_drift -= x[L::kClockDrift];
    }
    if constexpr (kHasIsb<L>) {
      for (int i = 0; i < IsbStates<L>::count; ++i) isb[i] -= x[IsbStates<L>::offset + i];
    }
    if constexpr (kHasOdoScale<L>) odo_scale += (1.0 + odo_scale) * x[OdoScaleState<L>::offset];
    if constexpr (kHasTimeOffset<L>) time_offset -= x[TimeOffsetState<L>::offset];
    if constexpr (kHasLeverArm<L>) lever_arm_b -= x.template segment<3>(LeverArmState<L>::offset);
    if constexpr (kHasOdoLever<L>) odo_lever_b -= x.template segment<3>(OdoLeverState<L>::offset);
    ins.set_state(s);
    filter.reset_state();
    out_cache_dirty_ = true;
  }

  /// Output shadow (continuous ambiguity resolution, engine/rtk_ins_engine.hpp): from now on the
  /// rows are written from `s`, the INS conditioned on a fix that the filter does not take,
  /// mechanised with the same IMU increments and its own IMU corrections `c`, with the sigmas
  /// sqrt(diag(P) - dvar) (dvar: the variance the fix removed; dP_att: the whole attitude block it
  /// removed, for the rows' Euler-angle sigmas), until end_output_shadow().  The
  /// filter, its INS and its feedback are not changed: the rows RTKLIB's continuous mode would
  /// output (the fixed solution), carried between epochs by the INS.
  void start_output_shadow(const NavState& s, const ImuCorrection& c, const StateVec<L>& dvar,
                           const Mat3& dP_att) {
    shadow_ins_ = ins;  // the mechanization's own history (previous increment, Earth terms)
    shadow_ins_.set_state(s);
    shadow_corr_ = c;
    shadow_dvar_ = dvar;
    shadow_dP_att_ = dP_att;
    shadow_on_ = true;
    out_cache_dirty_ = true;
  }
  void end_output_shadow() {
    if (!shadow_on_) return;
    shadow_on_ = false;
    out_cache_dirty_ = true;
  }
  bool output_shadow() const { return shadow_on_; }

  /// One output row: the INS corrected by the filter's current x (zero after
  /// every feedback; non-zero during an outage for a sigma-point filter), or
  /// the output shadow while one is on.
  void write_output(NavOutputs& out) {
    const std::int64_t i = out.n_out++;
    const NavState& s = shadow_on_ ? shadow_ins_.state() : ins.state();
    if (out.t) out.t[i] = s.t;
    const StateVec<L>& x = filter.x();
    const bool corrected = !shadow_on_ && !x.template head<9>().isZero(0.0);
    NavState c = s;  // the INS corrected by the estimate not yet fed back (feedback's formula)
    if (corrected)
      apply_nav_error(c, x.template segment<3>(L::kPos), x.template segment<3>(L::kVel),
                      x.template segment<3>(L::kAtt));
    const double lat = c.lat, lon = c.lon, h = c.h;
    const Vec3& v = c.v_n;
    const Quat& q = c.q_nb;
    if (out.llh) {
      out.llh[3 * i] = lat;
      out.llh[3 * i + 1] = lon;
      out.llh[3 * i + 2] = h;
    }
    if (out.v_n)
      for (int j = 0; j < 3; ++j) out.v_n[3 * i + j] = v[j];
    const bool need_C = out.rpy || out.sigma;
    const Mat3 C_nb = need_C ? Mat3(q.toRotationMatrix()) : Mat3::Identity();
    const Vec3 e = out.rpy ? euler_from_dcm(C_nb) : Vec3::Zero();
    if (out.rpy)
      for (int j = 0; j < 3; ++j) out.rpy[3 * i + j] = e[j];
    if (out_cache_dirty_) {  // P, x and the corrections change only at propagate/update/feedback
      if (shadow_on_) {
        sigma_ = (filter.P().diagonal() - shadow_dvar_).cwiseMax(0.0).cwiseSqrt();
        P_psi_ = filter.P().template block<3, 3>(L::kAtt, L::kAtt) - shadow_dP_att_;
        for (int j = 0; j < 3; ++j) {
          imu_err_[j] = shadow_corr_.acc_bias[j];
          imu_err_[3 + j] = shadow_corr_.gyro_bias[j];
          imu_err_[6 + j] = shadow_corr_.acc_scale[j];
          imu_err_[9 + j] = shadow_corr_.gyro_scale[j];
        }
      } else {
        sigma_ = filter.P().diagonal().cwiseMax(0.0).cwiseSqrt();
        P_psi_ = filter.P().template block<3, 3>(L::kAtt, L::kAtt);
        for (int j = 0; j < 3; ++j) {
          imu_err_[j] = corr.acc_bias[j] + x[L::kAccBias + j];
          imu_err_[3 + j] = corr.gyro_bias[j] + x[L::kGyroBias + j];
          imu_err_[6 + j] = corr.acc_scale[j] + (kHasScale<L> ? x[L::kAccScale >= 0 ? L::kAccScale + j : 0] : 0.0);
          imu_err_[9 + j] = corr.gyro_scale[j] + (kHasScale<L> ? x[L::kGyroScale >= 0 ? L::kGyroScale + j : 0] : 0.0);
        }
      }
      out_cache_dirty_ = false;
    }
    if (out.sigma) {  // sqrt(diag P), the attitude's as sigmas of the row's Euler angles (not of psi)
      const int nc = (out.sigma_cols > 0 && out.sigma_cols < L::kSize) ? out.sigma_cols : L::kSize;
      for (int j = 0; j < nc; ++j) out.sigma[nc * i + j] = sigma_[j];
      if (nc >= L::kAtt + 3) {
        const Vec3 sig_e = euler_sigmas_from_psi_dcm(P_psi_, C_nb);
        for (int j = 0; j < 3; ++j) out.sigma[nc * i + L::kAtt + j] = sig_e[j];
      }
    }
    if (out.imu_err)
      for (int j = 0; j < 12; ++j) out.imu_err[12 * i + j] = imu_err_[j];
    if constexpr (kHasClock<L>) {
      if (out.clock) {
        out.clock[2 * i] = clock_bias - x[L::kClockBias];
        out.clock[2 * i + 1] = clock_drift - x[L::kClockDrift];
      }
    }
    if constexpr (kHasOdoScale<L>) {
      if (out.odo_scale) {  // 1 + s = (1 + s^)(1 + ds)
        const double g = 1.0 + odo_scale;
        out.odo_scale[2 * i] = odo_scale + g * x[OdoScaleState<L>::offset];
        out.odo_scale[2 * i + 1] = g * sigma_[OdoScaleState<L>::offset];
      }
    }
    if constexpr (kHasTimeOffset<L>) {
      if (out.time_offset) {
        out.time_offset[2 * i] = time_offset - x[TimeOffsetState<L>::offset];
        out.time_offset[2 * i + 1] = sigma_[TimeOffsetState<L>::offset];
      }
    }
    if constexpr (kHasLeverArm<L>) {
      if (out.lever_arm)
        for (int j = 0; j < 3; ++j) {
          out.lever_arm[6 * i + j] = lever_arm_b[j] - x[LeverArmState<L>::offset + j];
          out.lever_arm[6 * i + 3 + j] = sigma_[LeverArmState<L>::offset + j];
        }
    }
    if constexpr (kHasOdoLever<L>) {
      if (out.odo_lever)
        for (int j = 0; j < 3; ++j) {
          out.odo_lever[6 * i + j] = odo_lever_b[j] - x[OdoLeverState<L>::offset + j];
          out.odo_lever[6 * i + 3 + j] = sigma_[OdoLeverState<L>::offset + j];
        }
    }
    if constexpr (kHasIsb<L>) {
      if (out.isb)
        for (int j = 0; j < IsbStates<L>::count; ++j) out.isb[3 * i + j] = isb[j] - x[IsbStates<L>::offset + j];
    }
  }

  /// The IMU loop of the engines that apply each record at its own time of
  /// validity (loose, tight): for every sample, the records valid in it are
  /// applied at their times (`record_t(g)`, sorted, `apply(g)` between a
  /// closed and a new cycle), an outage cycle is closed when due, and every
  /// `decimation`-th row (and the last) is written.  `g` is the first record
  /// not yet applied (updated).
  template <class RecordTime, class Apply>
  void run_samples(double t0, std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
                   std::int64_t& g, std::int64_t m, double cycle_period, int decimation, NavOutputs& out,
                   RecordTime&& record_t, Apply&& apply) {
    run_events(t0, n, t, dtheta_b, dv_b, cycle_period, decimation, out,
               [&]() { return g < m ? record_t(g) : kInf; }, [&]() { apply(g++); });
  }

  /// The same loop over any stream of timed events: `next_t()` is the time of
  /// the next pending event (+inf: none), `apply_next()` applies it and moves on.
  template <class NextTime, class ApplyNext>
  void run_events(double t0, std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b,
                  double cycle_period, int decimation, NavOutputs& out, NextTime&& next_t, ApplyNext&& apply_next) {
    double t_prev = t0;
    int until_output = decimation;  // countdown: no division per sample
    for (std::int64_t k = 0; k < n; ++k) {
      if (out.stop_requested(k, n)) return;
      const ImuIncrement raw = raw_imu_sample(k, t_prev, t, dtheta_b, dv_b);
      process_sample(raw, t_prev, cycle_period, next_t, apply_next);
      if (--until_output == 0 || k + 1 == n) {
        write_output(out);
        until_output = decimation;
      }
      t_prev = raw.t;
    }
  }

  /// One raw IMU increment over (t_prev, raw.t]: the events valid in it are
  /// applied at their own times (the increment split in proportion, the cycle
  /// closed, `apply_next()`, a new cycle), then the rest is integrated and an
  /// outage cycle closed when due.  The batch loop above and the push API
  /// (engine/navigator.hpp) both call it, so their results are identical.
  template <class NextTime, class ApplyNext>
  void process_sample(const ImuIncrement& raw, double t_prev, double cycle_period, NextTime&& next_t,
                      ApplyNext&& apply_next) {
    double done = 0.0;  // fraction of this increment already integrated
    for (double te = next_t(); te <= raw.t; te = next_t()) {
      const double a = (te - t_prev) / raw.dt;  // in (0, 1]
      if (a > done) {
        step(raw, done, a);
        done = a;
      }
      close_cycle();
      apply_next();
      start_cycle();
    }
    if (done < 1.0) step(raw, done, 1.0);
    if (outage_due(cycle_period)) {
      close_cycle();
      start_cycle();
    }
  }

 private:
  void rates() {
    if (!rates_stale_) return;
    omega_ib_b_ = last_imu_.dtheta_b / last_imu_.dt;
    f_ib_b_ = last_imu_.dv_b / last_imu_.dt;
    rates_stale_ = false;
  }

  /// omega_ib_b_lever(): freeze the low-passed rate at the start of a raw
  /// increment, then fold the increment (or the fraction of one) into it.
  void lever_rate_step(const ImuIncrement& imu, bool new_increment) {
    if (!(imu.dt > 0.0)) return;
    const Vec3 w = imu.dtheta_b / imu.dt;
    if (!have_lp_) {  // the first increment: nothing older to take
      omega_lp_b_ = w;
      omega_lever_b_ = w;
      have_lp_ = true;
      return;
    }
    if (new_increment) omega_lever_b_ = omega_lp_b_;
    omega_lp_b_ += std::min(1.0, imu.dt / kLeverRateTau) * (w - omega_lp_b_);
  }

  void set_point(InsPoint& p) {
    rates();
    const NavState& s = ins.state();
    p.set(s.lat, s.h, s.v_n, s.q_nb.toRotationMatrix(), f_ib_b_, omega_ib_b_);
  }

  /// Hand the filter the interval (interval_t0, now].
  void flush_interval() {
    const NavState& s = ins.state();
    iv_.dt = s.t - interval_t0;
    if (iv_.dt <= 0.0) return;
    set_point(iv_.end);
    if (!have_mid_) {  // a single short step: the middle is the mean of the ends
      iv_.mid = iv_.end;
      iv_.mid.lat = 0.5 * (iv_.start.lat + iv_.end.lat);
      iv_.mid.h = 0.5 * (iv_.start.h + iv_.end.h);
      iv_.mid.v_n = 0.5 * (iv_.start.v_n + iv_.end.v_n);
      iv_.mid.earth.evaluate(iv_.mid.lat, iv_.mid.h, iv_.mid.v_n);
    }
    filter.propagate(iv_);
    if constexpr (kHasOdoScale<L>) {
      if (std::isfinite(odo_scale_tau) && odo_scale_tau > 0.0) odo_scale *= std::exp(-iv_.dt / odo_scale_tau);
    }
    out_cache_dirty_ = true;
    iv_.start = iv_.end;
    interval_t0 = s.t;
    have_mid_ = false;
  }

  template <class F, class = void>
  struct TracksTransition : std::false_type {};
  template <class F>
  struct TracksTransition<F, std::void_t<decltype(std::declval<F&>().cycle_transition())>> : std::true_type {};
  static constexpr bool kTracksTransition = TracksTransition<Filter>::value;
  template <class F, class = void>
  struct TracksCross : std::false_type {};
  template <class F>
  struct TracksCross<F, std::void_t<decltype(std::declval<F&>().cycle_cross_covariance())>> : std::true_type {};
  static constexpr bool kTracksCross = TracksCross<Filter>::value;
  template <class F, class = void>
  struct CanInflate : std::false_type {};
  template <class F>
  struct CanInflate<F, std::void_t<decltype(std::declval<F&>().add_covariance(std::declval<const StateCov<L>&>()))>>
      : std::true_type {};
  static constexpr bool kCanInflate = CanInflate<Filter>::value;  // EKF, RB-UKF, UKF (not the particle filters)

 public:
  /// The filter gives what the RTS smoother needs (EKF transition or UT cross-covariance).
  static constexpr bool kCanRecordForSmoother = kTracksTransition || kTracksCross;

 private:

  SmootherEpoch<L>* rec_ = nullptr;
  std::int64_t rec_cap_ = 0, rec_n_ = 0;
  bool rec_pending_ = false, rec_overflow_ = false;
  StateCov<L> P_post_ = StateCov<L>::Zero();
  // condition_for_smoother: pending for the open epoch, then for the next prediction
  bool cond_pending_ = false, cond_next_ = false;
  bool cond_pred_pending_ = false;  // the unscented filters' prediction to condition (condition_prediction_for_smoother)
  StateVec<L> cond_dx_ = StateVec<L>::Zero();
  StateCov<L> cond_dP_ = StateCov<L>::Zero();
  InsInterval iv_;
  bool have_mid_ = false;
  ImuIncrement last_imu_;     // last corrected increment integrated
  bool rates_stale_ = false;  // omega_ib_b_, f_ib_b_ not yet taken from last_imu_
  Vec3 omega_ib_b_ = Vec3::Zero(), f_ib_b_ = Vec3::Zero();
  Vec3 omega_lp_b_ = Vec3::Zero();     // low-passed rate up to the last increment (lever-arm layouts)
  Vec3 omega_lever_b_ = Vec3::Zero();  // omega_ib_b_lever(): omega_lp_b_ before the current raw increment
  bool have_lp_ = false;
  StateVec<L> sigma_ = StateVec<L>::Zero();  // output cache: sqrt(diag P)
  Mat3 P_psi_ = Mat3::Zero();                // and P's attitude block (the rows' Euler-angle sigmas)
  Eigen::Matrix<double, 12, 1> imu_err_ = Eigen::Matrix<double, 12, 1>::Zero();  // and the IMU errors
  bool out_cache_dirty_ = true;  // P, x or the corrections changed since the cache was filled
  // start_output_shadow(): the rows' own INS while a fix the filter does not take is held
  Strapdown shadow_ins_;
  ImuCorrection shadow_corr_;
  StateVec<L> shadow_dvar_ = StateVec<L>::Zero();
  Mat3 shadow_dP_att_ = Mat3::Zero();
  bool shadow_on_ = false;
};

}  // namespace insnav
