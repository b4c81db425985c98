// insnav/engine/rtk_ins_engine.hpp -- tightly coupled RTK/INS: double-differenced carrier-phase
// and code rows (meas/dd_phase.hpp) in the closed-loop EKF, RB-UKF or UKF (Layout15; see "Filters"
// below) with single-differenced ambiguity states, INS-aided integer ambiguity resolution and
// INS-aided cycle-slip detection.
//
// State: the 15 INS error states of the closed-loop core (engine/closed_loop.hpp, filter/ekf.hpp:
// propagation, feedback, timing are the core's) and a fixed-capacity block of kMaxAmb
// single-differenced ambiguities N_rb^s_f [cycles] with an active mask (gnss/rtk.hpp's
// bookkeeping: a state is added when a satellite/frequency appears, re-initialised on a slip and
// removed after max_outage_epochs unobserved epochs).  With iono_mode kEstimate, a second
// fixed-capacity block of single-differenced (rover - base) slant ionosphere delays I_rb^s at
// gnss::kIonoRefFreqHz [m], one per satellite, the ionosphere-weighted model of gnss/rtk.hpp (Odijk
// 2002, sec. 4.2): a first-order Gauss-Markov process (iono_tau_s) whose stationary sigma is
// sigma_I(bl, el) = iono_sigma_per_10km_m x bl / 10 km x M(el); a DD row of frequency f carries
// mu^j I^j - mu^i I^i, mu = (f_0 / f)^2 of each satellite's frequency f, on code and its negative on
// phase.  Correlated phase errors (phase_corr_time_s > 0 and phase_error_ratio > 0, the defaults 30 s
// and 0.5): a third block, one first-order Gauss-Markov state b [m] per ambiguity slot (carrier
// multipath and what the atmosphere models leave; state augmentation, A. Gelb (ed.), Applied Optimal
// Estimation, 1974, sec. 4.5), + (b^j - b^i) on a DD phase row, stationary variance
// phase_error_ratio^2 times the white single difference's (the phase weighting of both receivers,
// gnss::phase_variance_zd; by default the correlated part has half the white part's sigma), started at
// 0 when its ambiguity is (re)initialised.  The three blocks are one "extra state" vector E (xe_,
// P_xE, P_EE; fixed capacity 3 x kMaxAmb, an active mask).  No receiver clock or inter-system bias
// states: double differences remove them.  The ambiguities are constants (plus amb_psd), so between
// two epochs their cross-covariance with the INS errors evolves by the INS transition alone,
// P_xN <- Phi_cycle P_xN (Phi_cycle: the EKF's product of the interval transitions), and the core
// propagates P_xx as in every other engine.  The Gauss-Markov states (ionosphere, correlated phase
// errors) decay by phi = exp(-dt / tau) between epochs: e <- phi e, P_xE <- Phi_cycle P_xE phi,
// P_EE <- phi P_EE phi + sigma^2 (1 - phi^2).
//
// Epoch (an RTK record applied at its time of validity):
//   1. slips: the receiver detectors of gnss/rtk.hpp (LLI, geometry-free, Melbourne-Wuebbena,
//      Doppler) and the INS-aided test, which works on one frequency: per satellite and frequency
//      d = [SD_now(r_ant prior) - SD_prev(r_ant posterior)] (observed minus computed single
//      differences, metres): the change of the receiver clock difference (common, removed as
//      the median over satellites) plus lambda x (slip) plus the error of the INS-predicted
//      position change; |d - median| > max(k sigma, min_cycles lambda) flags a slip of that
//      satellite only, and only its ambiguity is re-initialised (sigma^2 = 2 sigma_sd^2 +
//      u^T P_vv u dt^2, the INS's velocity uncertainty over the epoch interval).
//   2. DD code rows, robust screening (a row whose innovation exceeds sqrt(code_chi2_row) of
//      sqrt(H P H^T + R) is dropped, robust.hpp's per-row test), Kalman update of the joint state,
//      feedback; then DD phase rows at the new linearisation point (an innovation beyond
//      outlier_sigma re-initialises that ambiguity, as in rtk.hpp), update, feedback.
//  2a. robust screening (RtkInsConfig::robust, off by default), before the tests of 2. on each row
//      kind.  Double differences are correlated through the reference satellite, so the unit
//      tested is the single difference (SD) of one satellite on one frequency, not a DD row: the
//      w-test of the DIA procedure (P. J. G. Teunissen, "An integrity and quality control procedure
//      for use in multi sensor integration", ION GPS 1990, eq. (13); Teunissen, "Testing theory",
//      2000, sec. 4.4: w = d^T S^-1 y / sqrt(d^T S^-1 d)) with S = H P H^T + R the joint innovation
//      covariance of all rows of the kind (the INS-propagated state included) and d the rows' response
//      to a bias in that SD: -e_r for the non-reference satellite of row r, +1 on every row of its
//      group for a reference satellite, so a faulty reference is identified as itself rather than
//      as every row of its group.  w ~ N(0, 1) without a fault.  While the largest w^2 exceeds
//      chi2_row (robust.hpp's per-row quantile, 10.83), that SD is left out and the rows rebuilt and
//      tested again (at most fde_max_sats times per kind and epoch; a faulty reference is replaced
//      by the next highest satellite).  In such a flagged epoch the SDs left get the IGG-III
//      equivalent weight q(w) of robust.hpp (Yang, Song & Xu 2002, J. Geodesy 76:353-358, whose
//      bifactor weights for correlated observations scale a variance and keep the correlation
//      coefficients: here the SD variance is divided by q before the DD covariance is formed, so
//      the rows stay correlated through the reference as the model says), or Huber's; q = 0 leaves
//      it out.  A phase SD left out keeps its ambiguity's state (not fixed this epoch, so a one-epoch
//      phase outlier never reaches the float ambiguities); flagged phase_reset_epochs (2) epochs in a
//      row (a jump that stays, e.g. a fractional or undetected slip) its ambiguity is re-initialised
//      instead (0: never, left out while flagged).
//      An epoch with no w^2 beyond chi2_row is the plain one, bit for bit.
//   3. AR (gnss/ambiguity_resolution.hpp): MLAMBDA on the DD float ambiguities with the joint
//      covariance (so the INS-propagated position uncertainty conditions them: after a GNSS gap
//      the INS-predicted position constrains the search), ratio test, validation of the best
//      vector's squared norm against chi2(validation_prob, n), a bootstrapped success rate of at
//      least ar_min_success_rate (Teunissen 1998), partial AR; the fixed INS error is
//      dx_fix = P_xN D^T Q_a^{-1} (a_hat - a_fix) (Teunissen 1995, eq. (6)); fix-and-hold feeds the
//      fixed DD back as pseudo-measurements (sigma hold_sigma_cycles) into the joint filter.
//      Continuous AR leaves the filter float (RTKLIB's continuous mode): the antenna of the epoch is
//      the fixed one, and, without the smoother, the navigation rows until the next epoch are the INS
//      conditioned on the integers (dx_fix fed into a copy of the INS and its IMU corrections, with
//      sigmas sqrt(diag(P - P_xa Q_a^-1 P_ax))), mechanised beside the float INS with the same
//      increments (ClosedLoop::start_output_shadow).
//   4. RTS smoother (EKF, RB-UKF and UKF: "Filters" below; ClosedLoop::record_for_smoother;
//      filter/rts_smoother.hpp): the backward pass
//      runs over the 15 navigation error states with the ambiguities (and ionosphere states) marginalised (their block is
//      neither stored nor smoothed: an exact joint smoother would store (15 + kMaxAmb)^2 per epoch and
//      follow every ambiguity reset).  The engine's own feedbacks are recorded
//      (ClosedLoop::smoother_feedback).  Fixed epochs keep the fixed solution: with continuous AR the
//      smoother's filtered estimate at a fixed epoch is the navigation conditioned on the fixed
//      integers, dx_fix and P - P_xa Q_a^-1 P_ax (ClosedLoop::condition_for_smoother), and the step to
//      the next epoch is predicted from it (through outage cycles, which have no measurement, the
//      conditioned estimate is carried as its prediction).  The backward kernel is exact only when
//      the next epoch's estimate holds the same integers (one model, "the integers known"), so the
//      integers last fixed are held in the smoother's estimate of every epoch without a
//      continuous-AR fix of its own (float, code only, fix-and-hold) while their ambiguities are
//      the ones fixed and the float supports them (RtkInsEngine::hold_for_smoother); otherwise a
//      fixed epoch followed by a float one is smoothed towards the float solution.  The
//      backward pass thus smooths the navigation states conditioned on the fixed ambiguities at
//      fixed epochs (Rauch, Tung & Striebel 1965; Groves 2013, sec. 3.4.2), and a fixed epoch moves
//      only by what the neighbouring epochs add to its centimetre-level covariance.  Outage cycles
//      (RtkInsConfig::outage_cycle_s) give the smoother epochs inside GNSS gaps.
//
// Filters (the template parameter Filter, one of Ekf / RbUkf / Ukf of Layout15):
//   Ekf     the linear error model; P_xN <- Phi_cycle P_xN with the product of the intervals' Phi
//           (Ekf::cycle_transition).
//   RbUkf,  the unscented time update of seed 000 (filter/rbukf.hpp, UnscentedPropagation): the 2n+1
//   Ukf     sigma points of the navigation errors through the nonlinear Euler-angle error model
//           (seed 000 eqs. (1)-(7), (9)-(13)).  The ambiguities are constants, so only their
//           cross-covariance with the navigation errors needs a transition: the statistically
//           linearised transition of the cycle, Phi = C^T P_0^-1 with C = cov(error at the cycle
//           start, predicted error at its end) of the sigma points (Sarkka 2008, "Unscented
//           Rauch-Tung-Striebel smoother", IEEE TAC 53(3), eq. (13); the statistical linear
//           regression of the UT: Lefebvre, Bruyninckx & De Schutter 2002, IEEE TAC 47(8), eq. (7))
//           and P_0 the covariance the points were drawn from; exact (= the EKF's Phi_cycle) for
//           linear dynamics; Phi = I for a cycle without propagation.  The DD rows are linear in the
//           ambiguities and, at the centimetre-to-metre position uncertainty of an RTK epoch, in the
//           position (to rounding), so the joint Kalman update over [navigation; ambiguities] below is
//           the unscented update of a linear h (filter/ukf.hpp: Ukf = RbUkf = the Kalman update for a
//           linear h): RB-UKF and UKF RTK/INS are the same filter here.  The unscented predicted
//           mean x is not zero (the nonlinear model moves it, and it accumulates over the outage
//           cycles without feedback, seed 000 eqs. (26)-(29)): it is fed back into the INS before
//           the epoch's tests and rows (the closed loop of seed 000 eq. (25)), so the rows are
//           linearised at the predicted mean and the joint update starts from x = 0; the posterior
//           (x = 0, P) is where the next cycle draws its points.
//           The RTS smoother (4.) is the unscented RTS smoother (Sarkka 2008, eqs. (13)-(15)): the
//           core records the UT cross-covariance C of each cycle (ClosedLoop::close_cycle), the gain
//           is D = C Pp^-1 (filter/rts_smoother.hpp), and the conditioning on the fixed integers is
//           carried to the next epoch's prediction through the same statistically linearised Phi as
//           P_xN (ClosedLoop::condition_prediction_for_smoother: xp += Phi dx_fix,
//           Pp -= Phi dP Phi', C -= dP Phi'), where the EKF uses its Phi_cycle.  With Phi = the
//           EKF's (linear dynamics; Phi = I for a cycle without propagation) the smoother is the EKF's.
//
// No heap allocation per epoch: every matrix is bounded by kMaxAmb and lives in the engine
// (sizeof 2.4 MB for kMaxAmb = 64, measured: allocate the engine on the heap, as the bindings do).
#pragma once

#ifndef EIGEN_STACK_ALLOCATION_LIMIT  // before the first Eigen include (gnss/rtk.hpp's fixed-capacity matrices)
#define EIGEN_STACK_ALLOCATION_LIMIT 1048576
#endif

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <type_traits>

#include "insnav/engine/closed_loop.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/layout.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/sigma_points.hpp"
#include "insnav/gnss/ambiguity_resolution.hpp"
#include "insnav/gnss/double_difference.hpp"
#include "insnav/gnss/rtk.hpp"
#include "insnav/meas/dd_phase.hpp"
#include "insnav/meas/robust.hpp"

namespace insnav {

struct RtkInsConfig {
  // weighting, masks, AR, receiver slip detectors (gnss/rtk.hpp), with the correlated phase errors
  // as states by default here (phase_corr_time_s 30 s, phase_error_ratio 0.5; file comment)
  gnss::RtkOptions rtk = default_rtk_options();
  static gnss::RtkOptions default_rtk_options() {
    gnss::RtkOptions o;
    o.phase_corr_time_s = 30.0;
    o.phase_error_ratio = 0.5;
    return o;
  }
  Vec3 lever_arm_b = Vec3::Zero();    // IMU centre -> GNSS antenna, FRD [m]
  double propagation_interval = 0.02; // error-state propagation step [s]
  int output_decimation = 1;
  double ins_slip_k_sigma = 5.0;      // INS-aided slip test threshold max(k sigma, min_cycles lambda)
  double ins_slip_min_cycles = 0.35;
  double ins_slip_max_dt_s = 2.0;     // the test needs the previous epoch of the satellite within this
  double code_chi2_row = 25.0;        // code row screening (0: off)
  double validation_prob = 0.999;     // AR: best vector's squared norm <= chi2 quantile (0: off)
  double ar_min_success_rate = 0.0;   // AR: bootstrapped success rate of the fixed subset (0: off)
  // A filter cycle without a rover epoch is closed after this long [s] (+inf: one cycle spans a
  // whole gap).  The RTS smoother needs epochs inside GNSS outages (the bindings set it when
  // smoothing); the EKF's propagation does not depend on where cycles end, so the forward
  // solution is the same up to rounding.
  double outage_cycle_s = kInf;
  // Robust screening of the DD rows per satellite (file comment, 2a.): robust.hpp's settings; read
  // are screening, chi2_row, igg_k0, igg_k1, huber, huber_k and fde_max_sats (identifications per
  // row kind and epoch).  Off by default (docs/algorithms.md, "Tight RTK/INS").
  RobustConfig robust = rtk_ins_robust_defaults();
  int phase_reset_epochs = 2;  // a phase SD flagged this many epochs in a row: its ambiguity re-initialised
  UtParams ut{};               // the unscented filters' UT scaling (filter/sigma_points.hpp; the EKF ignores it)

  static RobustConfig rtk_ins_robust_defaults() {
    RobustConfig r;
    r.screening = false;
    return r;
  }
};

/// Slip count index of the INS-aided test (after gnss::SlipKind's).
inline constexpr int kSlipIns = gnss::kNumSlipKinds;
inline constexpr int kRtkInsSlipKinds = gnss::kNumSlipKinds + 1;

/// One GNSS epoch of the RTK/INS solution.
struct RtkInsEpoch {
  gnss::RtkStatus status = gnss::RtkStatus::kNone;
  double ratio = 0.0;
  double success_rate = 0.0;  // bootstrapped success rate of the ambiguities fixed (of all, when float)
  int n_fix = 0, n_dd = 0, n_sat = 0, code_rejected = 0;
  int screened = 0;      // robust screening: single differences left out (code) or left out / reset (phase)
  int downweighted = 0;  // robust screening: single differences IGG-III (Huber) down-weighted
  Vec3 r_e = Vec3::Zero();        // antenna, fixed if fixed, else float [m]
  Vec3 r_float_e = Vec3::Zero();  // antenna, float [m]
  Mat3 P_r = Mat3::Zero();        // covariance of r_e, NED [m^2]
  std::array<int, kRtkInsSlipKinds> slips{};
};

/// Work counters of a run (RtkInsOutputs::counters): the cost of its AR and what re-initialised or
/// skipped filter states, for the summary (a regression shows as a count, not only as time).
struct RtkInsCounters {
  gnss::ArCounts ar;         // PartialAr: AR epochs, MLAMBDA solves (partial-AR subsets) and search nodes
  long amb_added = 0;        // ambiguity states added (a satellite/frequency appearing)
  long amb_reset = 0;        // re-initialised: a slip flag, a phase outlier (outlier_sigma), robust screening
  long update_failures = 0;  // joint Kalman updates skipped: H P H^T + R not positive definite (LLT)
};

/// Caller-owned per-epoch outputs (any may be null); rows for E epochs.
struct RtkInsOutputs : NavOutputs {
  std::int32_t* status = nullptr;
  double* ratio = nullptr;
  double* success_rate = nullptr;
  std::int32_t* n_fix = nullptr;
  std::int32_t* n_dd = nullptr;
  std::int32_t* n_sat = nullptr;
  std::int32_t* code_rejected = nullptr;
  std::int32_t* screened = nullptr;      // RtkInsEpoch::screened
  std::int32_t* downweighted = nullptr;  // RtkInsEpoch::downweighted
  double* r_e = nullptr;        // (E, 3)
  double* r_float_e = nullptr;  // (E, 3)
  double* P_r = nullptr;        // (E, 9) NED
  std::int32_t* slips = nullptr;  // (E, kRtkInsSlipKinds)
  // (E, 9) the INS after the epoch's updates and feedback (the nominal the RTS smoother corrects):
  // lat, lon [rad], h [m], v_n [m/s], roll, pitch, yaw [rad]
  double* nav_epoch = nullptr;
  // per rover row (M rows over all epochs): slip flags of the row, bits gnss::SlipKind and kSlipIns,
  // OR over the frequencies
  std::uint8_t* row_slip = nullptr;
  RtkInsCounters counters{};  // filled at the end of run()
};

/// One rover epoch: time of validity, rover rows [begin, end) and base rows [base_begin, base_end)
/// (RtkRow layout), base_new: a new base epoch (false when an older one is held).
struct RtkInsRecord {
  double t = 0.0;
  std::int64_t begin = 0, end = 0, base_begin = 0, base_end = 0;
  bool base_new = true;
};

template <int kMaxAmb = 64, class FilterT = Ekf<Layout15>>
class RtkInsEngine {
 public:
  using Filter = FilterT;
  using L = typename Filter::Layout;
  static_assert(std::is_same_v<L, Layout15>, "RtkInsEngine: the 15 navigation error states (Layout15)");
  /// The unscented time update (RbUkf, Ukf): the statistically linearised cycle transition.
  static constexpr bool kUnscented = std::is_base_of_v<UnscentedPropagation<L>, Filter>;
  using Mat15 = StateCov<L>;
  static constexpr int kN = L::kSize;
  static constexpr int kMaxIono = kMaxAmb;  // ionosphere states (one per satellite; iono_mode kEstimate)
  static constexpr int kIono0 = kMaxAmb;             // extra-state index of the first ionosphere slot
  static constexpr int kPhaseErr0 = kMaxAmb + kMaxIono;  // ... of the first correlated phase error (one per ambiguity)
  static constexpr int kMaxExtra = kPhaseErr0 + kMaxAmb;
  static constexpr int kMaxJ = kN + kMaxExtra;
  static constexpr int kMaxRowsE = kMaxAmb;  // DD rows of one kind
  using JVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxJ, 1>;
  using JMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxJ, kMaxJ>;
  using RVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxRowsE, 1>;
  using RMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxRowsE, kMaxRowsE>;
  using HMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxRowsE, kMaxJ>;
  using KMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxJ, kMaxRowsE>;

  RtkInsEngine(const ImuErrorModel& model, const RtkInsConfig& cfg)
      : core_(make_filter<Filter>(model, cfg.ut), cfg.propagation_interval), cfg_(cfg) {
    core_.gate = NisGate(GateConfig{});
    core_.filter.track_cycle_transition(true);
  }

  ClosedLoop<Filter>& core() { return core_; }
  const gnss::PartialAr& ar() const { return ar_; }
  const RtkInsConfig& config() const { return cfg_; }

  void start(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0) {
    core_.reset(initial, P0, corr0);
    cond_valid_ = false;
    core_.filter.track_cycle_transition(true);
    if constexpr (kUnscented) {
      P_start_ = core_.filter.P();
      p_start_t_ = core_.cycle_start;
    }
    xe_.setZero();
    Pxe_.setZero();
    Pee_.setZero();
    iono_of_.fill(-1);
    for (auto& a : iono_) a = gnss::IonoSlot{};
    amb_of_.fill(-1);
    for (auto& a : amb_) a = AmbSlot{};
    validator_.reset();
    rover_slip_.reset();
    base_slip_.reset();
    for (auto& p : prev_) p = PrevSd{};
    t_last_ = NAN;
    dt_epoch_ = 0.0;
    code_scale_ = 1.0;
    epoch_index_ = 0;
    amb_gen_.fill(0);
    counters_ = RtkInsCounters{};
    ar_.reset_counts();
    held_n_ = 0;
    last_phase_flag_.fill(-2);
    phase_flag_run_.fill(0);
  }

  /// n IMU samples; E records over the rover rows and base rows (RtkRow layout).
  void run(const NavState& initial, const StateCov<L>& P0, const ImuCorrection& corr0, std::int64_t n,
           const double* t, const double* dtheta_b, const double* dv_b, std::int64_t n_epochs,
           const RtkInsRecord* recs, const double* rover_rows, const double* base_rows, const Vec3& r_base_e,
           RtkInsOutputs& out) {
    start(initial, P0, corr0);
    std::int64_t g = 0;
    for (; g < n_epochs && !(recs[g].t > initial.t); ++g) mark(g, out);
    // the core's IMU loop (ClosedLoop::run_events) with outage cycles that also carry the
    // ambiguities' cross-covariance P_xN over the cycle (ambiguities constant: P_xN <- Phi P_xN)
    const double period = cfg_.outage_cycle_s > 0.0 ? cfg_.outage_cycle_s : kInf;
    const auto next_t = [&]() { return g < n_epochs ? recs[g].t : kInf; };
    const auto apply_next = [&]() {
                        const std::int64_t i = g++;
                        const RtkInsRecord& r = recs[i];
                        const RtkInsEpoch e = apply_epoch(
                            rover_rows + r.begin * gnss::RtkRow::kCols, static_cast<int>(r.end - r.begin),
                            base_rows + r.base_begin * gnss::RtkRow::kCols,
                            static_cast<int>(r.base_end - r.base_begin), r.base_new, r_base_e);
                        write_epoch(i, e, out);
                        if (out.row_slip) {
                          const int nr = static_cast<int>(std::min<std::int64_t>(r.end - r.begin, gnss::kMaxSatKeys));
                          for (int j = 0; j < nr; ++j) {
                            std::uint8_t fl = 0;
                            for (int f = 0; f < std::clamp(cfg_.rtk.n_freq, 1, gnss::kMaxFreq); ++f) fl |= flags_r_[j * gnss::kMaxFreq + f];
                            out.row_slip[r.begin + j] = fl;
                          }
                        }
                        if (out.nav_epoch) {
                          const NavState& s = core_.state();
                          const Vec3 rpy = euler_from_quat(s.q_nb);
                          double* q = out.nav_epoch + 9 * i;
                          q[0] = s.lat;
                          q[1] = s.lon;
                          q[2] = s.h;
                          for (int j = 0; j < 3; ++j) {
                            q[3 + j] = s.v_n[j];
                            q[6 + j] = rpy[j];
                          }
                        }
                      };
    double t_prev = initial.t;
    int until_output = cfg_.output_decimation;
    for (std::int64_t k = 0; k < n; ++k) {
      if (out.stop_requested(k, n)) break;
      const ImuIncrement raw = raw_imu_sample(k, t_prev, t, dtheta_b, dv_b);
      core_.process_sample(raw, t_prev, kInf, next_t, apply_next);
      if constexpr (kUnscented) {
        if (core_.cycle_start != p_start_t_) {  // a cycle began in this sample: the P its points came from
          P_start_ = core_.filter.P();
          p_start_t_ = core_.cycle_start;
        }
      }
      if (core_.outage_due(period)) {  // an outage cycle (no record for `period`)
        core_.close_cycle();
        const auto& Phi = cycle_phi();
        if constexpr (kUnscented) core_.condition_prediction_for_smoother(Phi);  // before the next conditioning
        Pxe_ = Phi * Pxe_;
        if (cond_valid_) {  // no measurement: the smoother's estimate stays the fixed one, predicted
          cond_dx_ = Phi * cond_dx_;
          dP_fix_.noalias() = cond_dP_ * Phi.transpose();
          cond_dP_.noalias() = Phi * dP_fix_;
          core_.condition_for_smoother(cond_dx_, cond_dP_);
        }
        core_.start_cycle();
        if constexpr (kUnscented) {  // the points of the next cycle were drawn from it
          P_start_ = core_.filter.P();
          p_start_t_ = core_.cycle_start;
        }
      }
      if (--until_output == 0 || k + 1 == n) {
        core_.write_output(out);
        until_output = cfg_.output_decimation;
      }
      t_prev = raw.t;
    }
    for (; g < n_epochs; ++g) mark(g, out);
    out.cholesky_repairs = core_.filter.cholesky_repairs();
    out.counters = counters_;
    out.counters.ar = ar_.counts();
  }

  /// The measurement step of one rover epoch at the INS's current time.
  RtkInsEpoch apply_epoch(const double* rover, int n_r, const double* base, int n_b, bool base_new,
                          const Vec3& r_base_e) {
    using gnss::RtkRow;
    RtkInsEpoch out;
    const gnss::RtkOptions& o = cfg_.rtk;
    const int nf = std::clamp(o.n_freq, 1, gnss::kMaxFreq);
    const double t = core_.state().t;
    cond_valid_ = false;
    core_.end_output_shadow();  // the previous epoch's fix is carried no further (resolve() may start one)
    const Mat15& Phi = cycle_phi();  // before the prior mean's feedback below (which moves nothing of the cycle)
    // the smoother's prediction from the previous epoch's fixed solution (4.), before resolve() conditions this one
    if constexpr (kUnscented) core_.condition_prediction_for_smoother(Phi);
    if constexpr (kUnscented) {
      // the unscented prior mean (not zero: nonlinear model, outage cycles) into the INS, so the
      // slip test, the rows and the joint update start from the predicted mean with x = 0
      const StateVec<L> x = core_.filter.x();
      if (!x.isZero(0.0)) {
        feedback_ins(x);
        core_.filter.reset_state();
      }
    }
    n_r = std::min(n_r, gnss::kMaxSatKeys);
    n_b = std::min(n_b, gnss::kMaxSatKeys);
    std::array<int, gnss::kNumSlipKinds> sl{};
    rover_slip_.detect(t, rover, n_r, nf, o, flags_r_.data(), sl);
    if (base_new) base_slip_.detect(t, base, n_b, nf, o, flags_b_.data(), sl);
    else std::fill(flags_b_.begin(), flags_b_.end(), 0);
    for (int k = 0; k < gnss::kNumSlipKinds; ++k) out.slips[k] = sl[k];
    // ambiguity covariance to this epoch: P_xN <- Phi P_xN, P_NN += q dt
    const double dt = std::isfinite(t_last_) ? t - t_last_ : 0.0;
    dt_epoch_ = dt;
    Pxe_ = Phi * Pxe_;
    predict_extra(dt);
    t_last_ = t;
    // common satellites (gnss/double_difference.hpp, shared with gnss/rtk.hpp)
    n_common_ = gnss::match_common_satellites(rover, n_r, base, n_b, base_of_, common_r_.data(), common_b_.data());
    rover_ = rover;
    base_ = base;
    r_base_ = r_base_e;
    const Vec3 llh_b = wgs84::ecef_to_geodetic(r_base_e);
    lat_b_ = llh_b(0);
    h_b_ = llh_b(2);
    C_en_b_ = wgs84::C_en(llh_b(0), llh_b(1));
    // geometry and single differences at the INS-predicted antenna
    single_differences(nf);
    out.n_sat = n_used_sats_;
    ins_slip_test(nf, dt, out);
    manage_ambiguities(nf);
    manage_iono();
    // code rows, screened
    std::fill(code_out_.begin(), code_out_.end(), false);
    std::fill(phase_out_.begin(), phase_out_.end(), false);
    std::fill(var_factor_code_.begin(), var_factor_code_.end(), 1.0);
    std::fill(var_factor_phase_.begin(), var_factor_phase_.end(), 1.0);
    ++epoch_index_;
    int m = build_rows(nf, true);
    if (m > 0 && cfg_.robust.screening) m = screen_rows(nf, true, m, out);
    if (m > 0 && cfg_.code_chi2_row > 0.0) {
      gather();
      fill_H(m);
      bool any = false;
      for (int r = 0; r < m; ++r) {
        const double S = (H_.row(r) * Pj_ * H_.row(r).transpose()).value() + R_(r, r);
        if (y_(r) * y_(r) > cfg_.code_chi2_row * S) {
          code_out_[row_c_[r] * gnss::kMaxFreq + row_f_[r]] = true;
          any = true;
          ++out.code_rejected;
        }
      }
      if (any) m = build_rows(nf, true);
    }
    if (m > 0) {
      gather();
      fill_H(m);
      kalman_update(m);
      scatter_and_feedback();
      single_differences(nf);
    }
    // phase rows; an outlier re-initialises its ambiguity (at most two rebuilds)
    int mp = 0;
    for (int pass = 0; pass < 3; ++pass) {
      mp = build_rows(nf, false);
      if (mp == 0) break;
      if (pass == 0 && cfg_.robust.screening) {
        mp = screen_rows(nf, false, mp, out);
        if (mp == 0) break;
      }
      gather();
      fill_H(mp);
      if (pass < 2 && o.outlier_sigma > 0.0) {
        bool reset_any = false;
        for (int r = 0; r < mp; ++r) {
          const double S = (H_.row(r) * Pj_ * H_.row(r).transpose()).value() + R_(r, r);
          const int k = row_amb_[r];
          if (std::abs(y_(r)) > o.outlier_sigma * std::sqrt(S) && amb_[k].lock > 0) {
            init_amb(k, row_c_[r], amb_[k].freq);
            ++counters_.amb_reset;
            ++out.slips[gnss::kSlipOutlier];
            reset_any = true;
          }
        }
        if (reset_any) continue;
      }
      kalman_update(mp);
      scatter_and_feedback();
      break;
    }
    out.n_dd = mp;
    if (mp > 0) {  // adaptive code variance from the code residuals at the updated state (gnss/rtk.hpp)
      single_differences(nf);
      update_code_scale(nf);
    }
    RtkAntenna ant;
    ant.set(core_.state(), cfg_.lever_arm_b);
    out.r_float_e = ant.r_e;
    out.r_e = ant.r_e;
    out.P_r = core_.filter.P().template block<3, 3>(L::kPos, L::kPos);
    out.status = mp > 0 ? gnss::RtkStatus::kFloat : (m > 0 ? gnss::RtkStatus::kDgps : gnss::RtkStatus::kNone);
    if (mp > 0) {
      for (int k = 0; k < kMaxAmb; ++k)
        if (amb_[k].used) ++amb_[k].lock;
      if (o.ar_mode != gnss::ArMode::kOff) {
        validator_.begin_epoch();
        resolve(out);
        validator_.end_epoch();
      }
    }
    // the smoother's estimate of an epoch without its own continuous-AR fix (float, code only, or
    // fix-and-hold): conditioned on the integers last fixed while their ambiguities persist (4.)
    if (!cond_valid_) hold_for_smoother();
    // single differences at the final antenna position: the reference of the next INS-aided slip test
    single_differences(nf);
    store_prev(nf, t);
    // the next cycle draws its sigma points from this posterior (ClosedLoop::start_cycle)
    if constexpr (kUnscented) P_start_ = core_.filter.P();
    return out;
  }

  /// The ambiguity candidates of the last AR (satellite keys and frequency of each DD, in the
  /// order of ar().a_hat()): sat_j, sat_i (system * 64 + prn), freq.
  int last_candidates(int* sat_j, int* sat_i, int* freq, int max_n) const {
    const int n = std::min(ar_.n_used(), max_n);
    for (int p = 0; p < n; ++p) {
      sat_j[p] = amb_[dd_j_[order_[p]]].sat;
      sat_i[p] = amb_[dd_i_[order_[p]]].sat;
      freq[p] = amb_[dd_j_[order_[p]]].freq;
    }
    return n;
  }

 /// The transition of the last closed cycle, for the ambiguities' cross-covariance P_xN <- Phi P_xN:
  /// the EKF's product of the intervals' Phi, or for the unscented filters the statistically
  /// linearised Phi = C^T P_0^-1 (file comment; Sarkka 2008 eq. (13)), solved with a pivoting LDL^T
  /// of the Jacobi-scaled P_0 (D^-1 P_0 D^-1, D = sqrt(diag P_0): the navigation errors' variances
  /// span many decades), never an explicit inverse; a zero pivot (a state with no variance, whose
  /// P_xN row is zero too) contributes nothing.  Call once per closed cycle.
  const Mat15& cycle_phi() {
    if constexpr (!kUnscented) {
      return core_.filter.cycle_transition();
    } else {
      if (!(core_.state().t > core_.cycle_start)) {  // nothing propagated in the cycle
        Phi_ut_.setIdentity();
        return Phi_ut_;
      }
      const Mat15& C = core_.filter.cycle_cross_covariance();
      Eigen::Matrix<double, kN, 1> d = P_start_.diagonal();
      for (int i = 0; i < kN; ++i) d[i] = d[i] > 0.0 ? 1.0 / std::sqrt(d[i]) : 1.0;
      Ps_ = d.asDiagonal() * P_start_ * d.asDiagonal();
      ldlt_.compute(Ps_);
      W_ = d.asDiagonal() * C;            // D^-1 C
      PhiT_ = ldlt_.solve(W_);            // (D^-1 P_0 D^-1)^-1 D^-1 C
      PhiT_ = d.asDiagonal() * PhiT_;     // P_0^-1 C = Phi^T
      Phi_ut_ = PhiT_.transpose();
      if (!Phi_ut_.allFinite()) Phi_ut_.setIdentity();
      return Phi_ut_;
    }
  }

 private:
  struct AmbSlot {
    int sat = -1, freq = -1;
    int lock = 0, outage = 0;
    bool used = false, half = false;
    double el = 0.0;
    double phase_error_var = 0.0;  // stationary variance of its correlated phase error at el [m^2] (phase_error_var)
  };
  struct PrevSd {
    double t = NAN;
    double sd = NAN;  // observed minus computed single difference at the posterior antenna [m]
  };

  static int key(const double* r) { return gnss::sat_key(r); }
  static int sys_of(const double* r) { return static_cast<int>(r[gnss::RtkRow::kSys]); }
  double lam(int c, int f) const {
    return rover_[common_r_[c] * gnss::RtkRow::kCols + gnss::RtkRow::kFreq0 + gnss::RtkRow::kPerFreq * f + 4];
  }

  void mark(std::int64_t g, RtkInsOutputs& out) {
    RtkInsEpoch e;
    write_epoch(g, e, out);
  }

  void write_epoch(std::int64_t g, const RtkInsEpoch& e, RtkInsOutputs& out) const {
    if (out.status) out.status[g] = static_cast<std::int32_t>(e.status);
    if (out.ratio) out.ratio[g] = e.ratio;
    if (out.success_rate) out.success_rate[g] = e.success_rate;
    if (out.n_fix) out.n_fix[g] = e.n_fix;
    if (out.n_dd) out.n_dd[g] = e.n_dd;
    if (out.n_sat) out.n_sat[g] = e.n_sat;
    if (out.code_rejected) out.code_rejected[g] = e.code_rejected;
    if (out.screened) out.screened[g] = e.screened;
    if (out.downweighted) out.downweighted[g] = e.downweighted;
    const bool none = e.status == gnss::RtkStatus::kNone;
    for (int i = 0; i < 3; ++i) {
      if (out.r_e) out.r_e[3 * g + i] = none ? NAN : e.r_e(i);
      if (out.r_float_e) out.r_float_e[3 * g + i] = none ? NAN : e.r_float_e(i);
      for (int j = 0; j < 3; ++j)
        if (out.P_r) out.P_r[9 * g + 3 * i + j] = none ? NAN : e.P_r(i, j);
    }
    if (out.slips)
      for (int k = 0; k < kRtkInsSlipKinds; ++k) out.slips[kRtkInsSlipKinds * g + k] = e.slips[k];
  }

  // Elevations, unit vectors and observed-minus-computed single differences of the common
  // satellites at the current INS antenna.
  void single_differences(int nf) {
    using gnss::RtkRow;
    const gnss::RtkOptions& o = cfg_.rtk;
    ant_.set(core_.state(), cfg_.lever_arm_b);
    const Vec3 llh = wgs84::ecef_to_geodetic(ant_.r_e);
    const Mat3 C = wgs84::C_en(llh(0), llh(1));
    n_used_sats_ = 0;
    for (int c = 0; c < n_common_; ++c) {
      const double* r = rover_ + common_r_[c] * RtkRow::kCols;
      const double* b = base_ + common_b_[c] * RtkRow::kCols;
      Vec3 ur, ub;
      gnss::sat_range(r, ant_.r_e, ur);
      gnss::sat_range(b, r_base_, ub);
      el_r_[c] = std::asin(std::clamp(-(C.transpose() * ur)(2), -1.0, 1.0));
      el_b_[c] = std::asin(std::clamp(-(C_en_b_.transpose() * ub)(2), -1.0, 1.0));
      use_[c] = el_r_[c] >= o.elevation_mask_rad && el_b_[c] >= 0.0;
      if (use_[c]) ++n_used_sats_;
      const double mr = rtk_computed_zd(r, ant_.r_e, llh(0), llh(2), el_r_[c], o.tropo_model, ur);
      const double mb = rtk_computed_zd(b, r_base_, lat_b_, h_b_, el_b_[c], o.tropo_model, ub);
      u_[c] = ur;
      for (int f = 0; f < nf; ++f) {
        const double* fr = r + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        const double* fb = b + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        sd_phase_[c * gnss::kMaxFreq + f] = (fr[4] > 0.0 && std::isfinite(fr[1]) && std::isfinite(fb[1]))
                                                ? (fr[4] * fr[1] - mr) - (fb[4] * fb[1] - mb)
                                                : NAN;
        sd_code_[c * gnss::kMaxFreq + f] =
            (std::isfinite(fr[0]) && std::isfinite(fb[0])) ? (fr[0] - mr) - (fb[0] - mb) : NAN;
      }
      var_sd_[c] = gnss::phase_variance_zd(el_r_[c], sys_of(r), o) + gnss::phase_variance_zd(el_b_[c], sys_of(r), o);
    }
  }

  void store_prev(int nf, double t) {
    for (int c = 0; c < n_common_; ++c) {
      const int sat = key(rover_ + common_r_[c] * gnss::RtkRow::kCols);
      for (int f = 0; f < nf; ++f) {
        PrevSd& p = prev_[sat * gnss::kMaxFreq + f];
        p.sd = sd_phase_[c * gnss::kMaxFreq + f];
        p.t = std::isfinite(p.sd) ? t : NAN;
      }
    }
  }

  // INS-aided slip test (see the file comment, 1.)
  void ins_slip_test(int nf, double dt, RtkInsEpoch& out) {
    int nd = 0;
    const Mat3 Pvv = core_.filter.P().template block<3, 3>(L::kVel, L::kVel);
    const double t = core_.state().t;
    for (int c = 0; c < n_common_; ++c) {
      const int sat = key(rover_ + common_r_[c] * gnss::RtkRow::kCols);
      for (int f = 0; f < nf; ++f) {
        const int i = c * gnss::kMaxFreq + f;
        d_[i] = NAN;
        const PrevSd& p = prev_[sat * gnss::kMaxFreq + f];
        if (!use_[c] || !std::isfinite(sd_phase_[i]) || !std::isfinite(p.sd) || !(t - p.t <= cfg_.ins_slip_max_dt_s))
          continue;
        d_[i] = sd_phase_[i] - p.sd;
        med_[nd++] = d_[i];
      }
    }
    if (nd < 3) return;
    std::nth_element(med_.begin(), med_.begin() + nd / 2, med_.begin() + nd);
    const double med = med_[nd / 2];
    for (int c = 0; c < n_common_; ++c) {
      const int r = common_r_[c], b = common_b_[c];
      const Vec3 u_n = ant_.C_en.transpose() * u_[c];
      const double var_ins = u_n.dot(Pvv * u_n) * dt * dt;
      for (int f = 0; f < nf; ++f) {
        const double d = d_[c * gnss::kMaxFreq + f];
        if (!std::isfinite(d)) continue;
        const double thr =
            std::max(cfg_.ins_slip_k_sigma * std::sqrt(2.0 * var_sd_[c] + var_ins), cfg_.ins_slip_min_cycles * lam(c, f));
        if (std::abs(d - med) > thr) {
          flags_r_[r * gnss::kMaxFreq + f] |= 1u << kSlipIns;
          (void)b;
          ++out.slips[kSlipIns];
        }
      }
    }
  }

  void remove_amb(int k) {
    if (amb_[k].sat >= 0) amb_of_[amb_[k].sat * gnss::kMaxFreq + amb_[k].freq] = -1;
    amb_[k] = AmbSlot{};
    ++amb_gen_[k];  // a held integer of this slot no longer applies (hold_for_smoother)
    validator_.invalidate(k);
    xe_(k) = 0.0;
    Pxe_.col(k).setZero();
    Pee_.row(k).setZero();
    Pee_.col(k).setZero();
    clear_extra(kPhaseErr0 + k);
  }

  // (Re-)initialise ambiguity k of common satellite c, frequency f from SD(phase - code / lambda)
  // (as gnss/rtk.hpp), uncorrelated, sigma amb_init_sigma_cycles.
  void init_amb(int k, int c, int f) {
    const double* fr = rover_ + common_r_[c] * gnss::RtkRow::kCols + gnss::RtkRow::kFreq0 + gnss::RtkRow::kPerFreq * f;
    const double* fb = base_ + common_b_[c] * gnss::RtkRow::kCols + gnss::RtkRow::kFreq0 + gnss::RtkRow::kPerFreq * f;
    const double lam = fr[4];
    double n0 = fr[1] - fb[1];
    if (std::isfinite(fr[0]) && std::isfinite(fb[0])) n0 -= (fr[0] - fb[0]) / lam;
    else {  // no code: from the INS-predicted geometry, less the single-differenced receiver clock that
            // the code-initialised ambiguities carry (the median SD code residual of the system's
            // satellites; as gnss/rtk.hpp)
      const int sys = sys_of(rover_ + common_r_[c] * gnss::RtkRow::kCols);
      int n = 0;
      for (int k = 0; k < n_common_; ++k) {
        const double v = sd_code_[k * gnss::kMaxFreq + f];
        if (k != c && std::isfinite(v) && sys_of(rover_ + common_r_[k] * gnss::RtkRow::kCols) == sys) clock_buf_[n++] = v;
      }
      const double clk = gnss::median_in_place(clock_buf_.data(), n);
      n0 = (sd_phase_[c * gnss::kMaxFreq + f] - (std::isfinite(clk) ? clk : 0.0)) / lam;
    }
    xe_(k) = n0;
    Pxe_.col(k).setZero();
    Pee_.row(k).setZero();
    Pee_.col(k).setZero();
    Pee_(k, k) = cfg_.rtk.amb_init_sigma_cycles * cfg_.rtk.amb_init_sigma_cycles;
    // its correlated phase error (phase_error_ratio): 0 with the stationary variance
    clear_extra(kPhaseErr0 + k);
    amb_[k].phase_error_var = phase_errors_active() ? phase_error_var(c) : 0.0;
    Pee_(kPhaseErr0 + k, kPhaseErr0 + k) = amb_[k].phase_error_var;
    amb_[k].lock = 0;
    amb_[k].outage = 0;
    validator_.invalidate(k);
    ++amb_gen_[k];  // a new ambiguity: a held integer of this slot no longer applies (hold_for_smoother)
  }

  void manage_ambiguities(int nf) {
    using gnss::RtkRow;
    for (int k = 0; k < kMaxAmb; ++k) amb_[k].used = false;
    for (int c = 0; c < n_common_; ++c) {
      if (!use_[c]) continue;
      const double* r = rover_ + common_r_[c] * RtkRow::kCols;
      const double* b = base_ + common_b_[c] * RtkRow::kCols;
      const int sat = key(r);
      for (int f = 0; f < nf; ++f) {
        const double* fr = r + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        const double* fb = b + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        if (!std::isfinite(fr[1]) || !std::isfinite(fb[1]) || !(fr[4] > 0.0)) continue;
        const bool slip = flags_r_[common_r_[c] * gnss::kMaxFreq + f] != 0 || flags_b_[common_b_[c] * gnss::kMaxFreq + f] != 0;
        int k = amb_of_[sat * gnss::kMaxFreq + f];
        if (k < 0) {
          for (int q = 0; q < kMaxAmb; ++q)
            if (amb_[q].sat < 0) { k = q; break; }
          if (k < 0) continue;  // table full
          amb_[k].sat = sat;
          amb_[k].freq = f;
          amb_of_[sat * gnss::kMaxFreq + f] = k;
          init_amb(k, c, f);
          ++counters_.amb_added;
        } else if (slip) {
          init_amb(k, c, f);
          ++counters_.amb_reset;
        }
        const int lli_r = std::isfinite(fr[3]) ? static_cast<int>(fr[3]) : 0;
        const int lli_b = std::isfinite(fb[3]) ? static_cast<int>(fb[3]) : 0;
        amb_[k].half = ((lli_r | lli_b) & 2) != 0;
        amb_[k].used = true;
        amb_[k].outage = 0;
        amb_[k].el = el_r_[c];
        if (phase_errors_active()) amb_[k].phase_error_var = phase_error_var(c);
        amb_row_[c * gnss::kMaxFreq + f] = k;
      }
    }
    for (int k = 0; k < kMaxAmb; ++k)
      if (amb_[k].sat >= 0 && !amb_[k].used && ++amb_[k].outage > cfg_.rtk.max_outage_epochs) remove_amb(k);
  }

  bool valid(int c, int f, bool code) const {
    if (code) return std::isfinite(sd_code_[c * gnss::kMaxFreq + f]) && !code_out_[c * gnss::kMaxFreq + f];
    return std::isfinite(sd_phase_[c * gnss::kMaxFreq + f]) && !phase_out_[c * gnss::kMaxFreq + f] &&
           amb_of_[key(rover_ + common_r_[c] * gnss::RtkRow::kCols) * gnss::kMaxFreq + f] >= 0;
  }

  // DD rows (y = computed - measured, R) per system and frequency against the highest satellite,
  // the ordering and covariance of gnss/rtk.hpp.  H is filled by fill_H after gather().
  int build_rows(int nf, bool code) {
    const gnss::RtkOptions& o = cfg_.rtk;
    const double bl = (ant_.r_e - r_base_).norm();
    // the DD ionosphere as a variance (iono_mode kVariance); kEstimate: the states' mu^j I^j - mu^i I^i
    // enters the computed value (iono_dd) and H (fill_H)
    const double var_bl =
        o.iono_mode == gnss::IonoMode::kVariance ? std::pow(o.iono_sigma_per_10km_m * bl / 1e4, 2) : 0.0;
    const double cf = code ? o.code_phase_ratio * o.code_phase_ratio : 1.0;  // x code_var_factor per satellite
    int m = 0;
    R_.setZero(kMaxRowsE, kMaxRowsE);
    y_.setZero(kMaxRowsE);
    for (int sys = 0; sys < gnss::kNumSystems; ++sys) {
      for (int f = 0; f < nf; ++f) {
        const int ref = gnss::highest_elevation_reference(
            n_common_,
            [&](int c) { return use_[c] && sys_of(rover_ + common_r_[c] * gnss::RtkRow::kCols) == sys && valid(c, f, code); },
            [&](int c) { return el_r_[c]; });
        if (ref < 0) continue;
        const int m0 = m;
        const double var_ref = var_sd_[ref] * cf * (code ? code_var_factor(ref, f) : phase_var_factor(ref, f)) *
                           var_factor(ref, f, code);
        for (int c = 0; c < n_common_; ++c) {
          if (c == ref || !use_[c] || sys_of(rover_ + common_r_[c] * gnss::RtkRow::kCols) != sys) continue;
          if (!valid(c, f, code) || m >= kMaxRowsE) continue;
          const int i = c * gnss::kMaxFreq + f, ir = ref * gnss::kMaxFreq + f;
          if (code) {
            y_(m) = -(sd_code_[i] - sd_code_[ir]) + iono_dd(c, ref, f);
            row_amb_[m] = row_amb_ref_[m] = -1;
          } else {
            const int kj = amb_row_[i], ki = amb_row_[ir];
            y_(m) = -(sd_phase_[i] - sd_phase_[ir]) + lam(c, f) * xe_(kj) - lam(ref, f) * xe_(ki) - iono_dd(c, ref, f) +
                    (phase_errors_active() ? xe_(kPhaseErr0 + kj) - xe_(kPhaseErr0 + ki) : 0.0);
            row_amb_[m] = kj;
            row_amb_ref_[m] = ki;
          }
          row_c_[m] = c;
          row_ref_[m] = ref;
          row_f_[m] = f;
          R_(m, m) = var_sd_[c] * cf * (code ? code_var_factor(c, f) : phase_var_factor(c, f)) * var_factor(c, f, code) +
                     var_bl + var_ref + var_bl;
          for (int q = m0; q < m; ++q) R_(m, q) = R_(q, m) = var_ref + var_bl;
          ++m;
        }
      }
    }
    return m;
  }

  // The robust variance factor 1/q of a single difference (screen_rows; 1 unless down-weighted).
  double var_factor(int c, int f, bool code) const {
    return (code ? var_factor_code_ : var_factor_phase_)[c * gnss::kMaxFreq + f];
  }

  // Teunissen's w-test of every single difference in the m DD rows built (file comment, 2a.), after
  // gather() and fill_H(m): S = H P H^T + R, and for a bias in the SD of satellite c on frequency f
  // the DD rows move by the column d (d = -e_r for the non-reference satellite of row r, d = +1 on
  // every row of the group for its reference), w = d^T S^-1 y / sqrt(d^T S^-1 d).  Fills unit_*;
  // false when S is not positive definite.
  bool w_tests(int m) {
    PHt_.noalias() = Pj_ * H_.transpose();
    S_ = R_.topLeftCorner(m, m);
    S_.noalias() += H_ * PHt_;
    llt_.compute(S_);
    if (llt_.info() != Eigen::Success) return false;
    Sy_ = llt_.solve(y_.head(m));
    Sinv_.setIdentity(m, m);
    llt_.solveInPlace(Sinv_);
    n_units_ = 0;
    for (int r = 0; r < m; ++r) {
      unit_c_[n_units_] = row_c_[r];
      unit_f_[n_units_] = row_f_[r];
      unit_w_[n_units_++] = -Sy_(r) / std::sqrt(std::max(Sinv_(r, r), 1e-300));
    }
    // the rows of one reference (one system and frequency) are consecutive (build_rows)
    for (int r0 = 0; r0 < m;) {
      int r1 = r0 + 1;
      while (r1 < m && row_ref_[r1] == row_ref_[r0] && row_f_[r1] == row_f_[r0]) ++r1;
      double num = 0.0, den = 0.0;
      for (int q = r0; q < r1; ++q) {
        num += Sy_(q);
        for (int p = r0; p < r1; ++p) den += Sinv_(q, p);
      }
      unit_c_[n_units_] = row_ref_[r0];
      unit_f_[n_units_] = row_f_[r0];
      unit_w_[n_units_++] = num / std::sqrt(std::max(den, 1e-300));
      r0 = r1;
    }
    return true;
  }

  // Leave the single difference of common satellite c, frequency f out of this epoch's rows of one
  // kind.  Phase: the satellite's ambiguity keeps its state (not fixed this epoch, its lock not
  // counted); flagged phase_reset_epochs epochs in a row (a jump that stays: a fractional or
  // undetected slip), the ambiguity is re-initialised instead and its row kept (0: never).
  void leave_out(int c, int f, bool code, RtkInsEpoch& out) {
    const int i = c * gnss::kMaxFreq + f;
    ++out.screened;
    if (code) {
      code_out_[i] = true;
      return;
    }
    const int sf = key(rover_ + common_r_[c] * gnss::RtkRow::kCols) * gnss::kMaxFreq + f;
    const int k = amb_of_[sf];
    if (last_phase_flag_[sf] == epoch_index_) {  // flagged again in this epoch (after a reset): out
      phase_out_[i] = true;
      if (k >= 0) amb_[k].used = false;
      return;
    }
    phase_flag_run_[sf] = last_phase_flag_[sf] == epoch_index_ - 1 ? phase_flag_run_[sf] + 1 : 1;
    last_phase_flag_[sf] = epoch_index_;
    if (k >= 0 && amb_[k].lock > 0 && cfg_.phase_reset_epochs > 0 && phase_flag_run_[sf] >= cfg_.phase_reset_epochs) {
      init_amb(k, c, f);
      ++counters_.amb_reset;
      ++out.slips[gnss::kSlipOutlier];
    } else {
      phase_out_[i] = true;
      if (k >= 0) amb_[k].used = false;
    }
  }

  // Robust screening of the m DD rows of one kind (file comment, 2a.): while the largest |w| of the
  // single differences exceeds sqrt(chi2_row), leave that one out (identification and adaptation
  // of the DIA procedure, at most fde_max_sats per kind and epoch) and test again; in a flagged
  // epoch the remaining single differences get the IGG-III (or Huber) factor q(w) of robust.hpp on
  // their variance (q = 0: left out).  An epoch with no |w| beyond the threshold is untouched.
  // Returns the rows left (rebuilt).
  int screen_rows(int nf, bool code, int m, RtkInsEpoch& out) {
    const RobustConfig& rc = cfg_.robust;
    bool flagged = false, current = false;  // current: unit_w_ belongs to the rows as they are
    for (int it = 0; m > 0; ++it) {
      gather();
      fill_H(m);
      current = w_tests(m);
      if (!current) break;
      int worst = -1;
      double w2_max = rc.chi2_row;
      for (int u = 0; u < n_units_; ++u)
        if (unit_w_[u] * unit_w_[u] > w2_max) {
          w2_max = unit_w_[u] * unit_w_[u];
          worst = u;
        }
      if (worst < 0) break;
      flagged = true;
      if (it >= rc.fde_max_sats) break;  // the rest: q(w) below
      leave_out(unit_c_[worst], unit_f_[worst], code, out);
      m = build_rows(nf, code);
      current = false;
    }
    if (!flagged || !current || m == 0) return m;
    bool changed = false;
    for (int u = 0; u < n_units_; ++u) {
      const double w = unit_w_[u];
      const double q = !(w * w <= rc.chi2_row) ? 0.0
                       : rc.huber             ? huber_weight(w, rc.huber_k)
                                              : igg3_weight(w, rc.igg_k0, rc.igg_k1);
      const int c = unit_c_[u], f = unit_f_[u];
      if (q <= 0.0) {
        if (!(code ? code_out_ : phase_out_)[c * gnss::kMaxFreq + f]) leave_out(c, f, code, out);
        changed = true;
      } else if (q < 1.0) {
        (code ? var_factor_code_ : var_factor_phase_)[c * gnss::kMaxFreq + f] /= q;
        ++out.downweighted;
        changed = true;
      }
    }
    return changed ? build_rows(nf, code) : m;
  }

  // Time-correlated code errors and the adaptive code variance factor, as gnss/rtk.hpp's
  // code_var_factor / update_code_scale (the [rtk] keys code_correlation_time_s, adaptive_code_gain):
  // a first-order Gauss-Markov code error of correlation rho = exp(-dt / tau) between epochs gives
  // the information (1 - rho) / (1 + rho) / sigma^2 per further epoch on a constant (A. Gelb (ed.),
  // Applied Optimal Estimation, 1974, sec. 3.8), so the code of a satellite whose ambiguity is
  // already tracked (lock > 0) enters with its variance x (1 + rho) / (1 - rho); the first epoch of
  // an ambiguity keeps the white variance (an INS-aided re-fix after an outage is not slowed).
  // With an INS holding the position between epochs the white-code float solution would average
  // correlated multipath as if it were white, and its ambiguities, success rate and ratio test
  // would be over-confident.
  double code_var_factor(int c, int f) const {
    const gnss::RtkOptions& o = cfg_.rtk;
    if (!(o.code_corr_time_s > 0.0) || !(dt_epoch_ > 0.0)) return code_scale_;
    const int k = amb_of_[key(rover_ + common_r_[c] * gnss::RtkRow::kCols) * gnss::kMaxFreq + f];
    if (k < 0 || amb_[k].lock == 0) return code_scale_;
    const double rho = std::exp(-dt_epoch_ / o.code_corr_time_s);
    return code_scale_ * (1.0 + rho) / std::max(1.0 - rho, 1e-6);
  }

  // Time-correlated phase errors as a variance factor (RtkOptions::phase_corr_time_s with
  // phase_error_ratio = 0; the default carries them as states, phase_errors_active), the same first-order
  // Gauss-Markov model as code_var_factor: carrier multipath of a few mm correlated over tens of seconds is, with
  // the INS holding the position between epochs, averaged into the float position and ambiguities as
  // if it were white, so their covariance is over-confident and the fix validation (the best
  // vector's squared norm against a chi2 quantile) rejects the correct integers.  The phase of a
  // tracked ambiguity (lock > 0) enters with its variance x (1 + rho) / (1 - rho), rho =
  // exp(-dt / tau); the first epoch of an ambiguity keeps the white variance.
  double phase_var_factor(int c, int f) const {
    const int k = amb_of_[key(rover_ + common_r_[c] * gnss::RtkRow::kCols) * gnss::kMaxFreq + f];
    return gnss::phase_var_factor(cfg_.rtk, dt_epoch_, k < 0 ? 0 : amb_[k].lock);
  }

  // Adaptive variance factor of the code rows (Mohamed & Schwarz 1999, J. Geodesy 73, eq. (28),
  // scalar form; gnss/rtk.hpp's update_code_scale): the code DD residuals at the state after the
  // phase update, nu_i = y_i^2 / (k R_i) (capped at 25), move log k by gain x log(mean nu), k in
  // [1, 100]: never smaller than configured.
  void update_code_scale(int nf) {
    const gnss::RtkOptions& o = cfg_.rtk;
    if (!(o.code_scale_gain > 0.0)) return;
    const int m = build_rows(nf, true);
    if (m <= 0) return;
    const double r2 = o.code_phase_ratio * o.code_phase_ratio;
    double sum = 0.0;
    for (int i = 0; i < m; ++i) {
      const double var = code_scale_ * r2 * (var_sd_[row_c_[i]] + var_sd_[row_ref_[i]]);
      sum += std::min(y_(i) * y_(i) / var, 25.0);
    }
    const double mean = sum / m;
    if (!(mean > 0.0) || !std::isfinite(mean)) return;
    code_scale_ = std::clamp(code_scale_ * std::pow(mean, o.code_scale_gain), 1.0, 100.0);
  }

  // Compact joint state: the 15 INS errors and the active extra states (ambiguities, ionosphere,
  // correlated phase errors).
  void gather() {
    ne_ = 0;
    std::fill(ecol_.begin(), ecol_.end(), -1);
    for (int e = 0; e < kMaxExtra; ++e)
      if (extra_in_use(e)) {
        ecol_[e] = kN + ne_;
        act_e_[ne_++] = e;
      }
    const int n = kN + ne_;
    Pj_.resize(n, n);
    Pj_.template topLeftCorner<kN, kN>() = core_.filter.P();
    for (int a = 0; a < ne_; ++a) {
      Pj_.col(kN + a).template head<kN>() = Pxe_.col(act_e_[a]);
      Pj_.row(kN + a).template head<kN>() = Pxe_.col(act_e_[a]).transpose();
      for (int b = 0; b < ne_; ++b) Pj_(kN + a, kN + b) = Pee_(act_e_[a], act_e_[b]);
    }
  }

  void fill_H(int m) {
    const int n = kN + ne_;
    H_.setZero(m, n);
    for (int r = 0; r < m; ++r) {
      double hp[3], ha[3];
      ant_.dd_jacobian(u_[row_c_[r]] - u_[row_ref_[r]], hp, ha);
      for (int k = 0; k < 3; ++k) {
        H_(r, L::kPos + k) = hp[k];
        H_(r, L::kAtt + k) = ha[k];
      }
      if (row_amb_[r] >= 0) {
        H_(r, ecol_[row_amb_[r]]) += lam(row_c_[r], row_f_[r]);
        H_(r, ecol_[row_amb_ref_[r]]) -= lam(row_ref_[r], row_f_[r]);
        if (phase_errors_active()) {  // correlated phase errors: + (b_j - b_i)
          H_(r, ecol_[kPhaseErr0 + row_amb_[r]]) += 1.0;
          H_(r, ecol_[kPhaseErr0 + row_amb_ref_[r]]) -= 1.0;
        }
      }
      // ionosphere: +(mu^j I^j - mu^i I^i) on code, -(mu^j I^j - mu^i I^i) on phase (iono_dd)
      const int kj = iono_slot(row_c_[r]), ki = iono_slot(row_ref_[r]);
      if (kj >= 0 && ki >= 0) {
        const double sgn = row_amb_[r] >= 0 ? -1.0 : 1.0;
        H_(r, ecol_[kIono0 + kj]) += sgn * gnss::iono_factor(lam(row_c_[r], row_f_[r]));
        H_(r, ecol_[kIono0 + ki]) -= sgn * gnss::iono_factor(lam(row_ref_[r], row_f_[r]));
      }
    }
  }

  // x = K y, P = P - K H P over the compact joint state (y = computed - measured = H dx + v).
  void kalman_update(int m) {
    const int n = kN + ne_;
    PHt_.noalias() = Pj_ * H_.transpose();
    S_ = R_.topLeftCorner(m, m);
    S_.noalias() += H_ * PHt_;
    llt_.compute(S_);
    dx_.setZero(n);
    if (llt_.info() != Eigen::Success) {
      ++counters_.update_failures;
      return;
    }
    KT_ = PHt_.transpose();
    llt_.solveInPlace(KT_);
    dx_.noalias() = KT_.transpose() * y_.head(m);
    Pj_.noalias() -= KT_.transpose() * PHt_.transpose();
    Pn_ = 0.5 * (Pj_ + Pj_.transpose());
    Pj_ = Pn_;
  }

  // Write the compact joint state back, feed the INS errors back and correct the extra states.
  void scatter_and_feedback() {
    core_.filter.P_mutable() = Pj_.template topLeftCorner<kN, kN>();
    for (int a = 0; a < ne_; ++a) {
      const int e = act_e_[a];
      Pxe_.col(e) = Pj_.col(kN + a).template head<kN>();
      for (int b = 0; b < ne_; ++b) Pee_(e, act_e_[b]) = Pj_(kN + a, kN + b);
      xe_(e) -= dx_(kN + a);
    }
    feedback_ins(dx_.template head<kN>());
  }

  // Closed-loop feedback of a Layout15 error estimate (computed - true) into the core's INS and IMU
  // corrections, as ClosedLoop::feedback does with the filter's x (which stays zero here: the joint
  // update is this engine's own).
  void feedback_ins(const Eigen::Matrix<double, kN, 1>& x) {
    NavState s = core_.ins.state();
    const wgs84::Radii r = wgs84::radii(s.lat);
    s.lat -= x[L::kPos] / (r.R_M + s.h);
    s.lon -= x[L::kPos + 1] / ((r.R_N + s.h) * std::cos(s.lat));
    s.h += x[L::kPos + 2];
    s.v_n -= x.template segment<3>(L::kVel);
    s.q_nb = (quat_from_euler(x.template segment<3>(L::kAtt)) * s.q_nb).normalized();
    core_.corr.acc_bias += x.template segment<3>(L::kAccBias);
    core_.corr.gyro_bias += x.template segment<3>(L::kGyroBias);
    core_.ins.set_state(s);
    core_.touch();
    core_.smoother_feedback(x);  // the RTS smoother's record of the epoch (closed_loop.hpp)
  }

  // ---- ionosphere states (iono_mode kEstimate; gnss/rtk.hpp's model) ----
  bool iono_active() const { return cfg_.rtk.iono_mode == gnss::IonoMode::kEstimate; }

  // The ionosphere slot of common satellite c, or -1.
  int iono_slot(int c) const {
    if (!iono_active()) return -1;
    return iono_of_[key(rover_ + common_r_[c] * gnss::RtkRow::kCols)];
  }

  // The estimated DD ionosphere of a row on frequency f: mu^c I^c - mu^ref I^ref [m] (0 without states;
  // mu of each satellite's own wavelength: the GLONASS FDMA channels differ).
  double iono_dd(int c, int ref, int f) const {
    const int kj = iono_slot(c), ki = iono_slot(ref);
    if (kj < 0 || ki < 0) return 0.0;
    return gnss::iono_factor(lam(c, f)) * xe_(kIono0 + kj) - gnss::iono_factor(lam(ref, f)) * xe_(kIono0 + ki);
  }

  // The correlated phase errors (phase_error_ratio > 0 with phase_corr_time_s > 0: states instead of
  // phase_var_factor's inflation).
  bool phase_errors_active() const { return gnss::phase_error_states(cfg_.rtk); }

  // Stationary variance of the single-differenced correlated phase error of common satellite c [m^2]:
  // phase_error_ratio^2 times the white single difference's (var_sd_: the phase weighting of both
  // receivers at their elevations).
  double phase_error_var(int c) const { return cfg_.rtk.phase_error_ratio * cfg_.rtk.phase_error_ratio * var_sd_[c]; }

  // Is extra state e (ambiguity, ionosphere or correlated phase error slot) in the filter?
  bool extra_in_use(int e) const {
    if (e < kIono0) return amb_[e].sat >= 0;
    if (e < kPhaseErr0) return iono_[e - kIono0].sat >= 0;
    return phase_errors_active() && amb_[e - kPhaseErr0].sat >= 0;
  }

  void clear_extra(int e) {
    xe_(e) = 0.0;
    Pxe_.col(e).setZero();
    Pee_.row(e).setZero();
    Pee_.col(e).setZero();
  }

  // The step of the extra states over dt (file comment): ambiguities + amb_psd dt; ionosphere and
  // correlated phase errors first-order Gauss-Markov, x <- phi x, P_xE, P_EE scaled by phi,
  // + sigma^2 (1 - phi^2) on the diagonal (sigma at the last epoch's elevation).
  void predict_extra(double dt) {
    if (!(dt > 0.0)) return;
    for (int k = 0; k < kMaxAmb; ++k)
      if (amb_[k].sat >= 0) Pee_(k, k) += cfg_.rtk.amb_psd * dt;
    const auto gm = [&](int e, double phi, double var) {
      xe_(e) *= phi;
      Pxe_.col(e) *= phi;
      Pee_.row(e) *= phi;
      Pee_.col(e) *= phi;
      Pee_(e, e) += var * (1.0 - phi * phi);
    };
    if (iono_active()) {
      const double phi = cfg_.rtk.iono_tau_s > 0.0 ? std::exp(-dt / cfg_.rtk.iono_tau_s) : 0.0;
      const double bl = (ant_.r_e - r_base_).norm();
      for (int k = 0; k < kMaxIono; ++k)
        if (iono_[k].sat >= 0) gm(kIono0 + k, phi, gnss::iono_prior_var(cfg_.rtk, bl, iono_[k].el));
    }
    if (phase_errors_active()) {
      const double phi = std::exp(-dt / cfg_.rtk.phase_corr_time_s);
      for (int k = 0; k < kMaxAmb; ++k)
        if (amb_[k].sat >= 0) gm(kPhaseErr0 + k, phi, amb_[k].phase_error_var);
    }
  }

  // Ionosphere states of the satellites in use: a new one starts at I = 0 with the stationary
  // sigma_I^2 (the ionosphere-weighted pseudo-observation), one unseen for max_outage_epochs is removed.
  void manage_iono() {
    if (!iono_active()) return;
    for (auto& a : iono_) a.used = false;
    const double bl = (ant_.r_e - r_base_).norm();
    for (int c = 0; c < n_common_; ++c) {
      if (!use_[c]) continue;
      const int sat = key(rover_ + common_r_[c] * gnss::RtkRow::kCols);
      int k = iono_of_[sat];
      if (k < 0) {
        for (int q = 0; q < kMaxIono; ++q)
          if (iono_[q].sat < 0) { k = q; break; }
        if (k < 0) continue;  // table full: the satellite's rows carry no ionosphere
        iono_[k].sat = sat;
        iono_of_[sat] = k;
        clear_extra(kIono0 + k);
        Pee_(kIono0 + k, kIono0 + k) = gnss::iono_prior_var(cfg_.rtk, bl, el_r_[c]);
      }
      iono_[k].used = true;
      iono_[k].outage = 0;
      iono_[k].el = el_r_[c];
    }
    for (int k = 0; k < kMaxIono; ++k) {
      if (iono_[k].sat < 0 || iono_[k].used || ++iono_[k].outage <= cfg_.rtk.max_outage_epochs) continue;
      iono_of_[iono_[k].sat] = -1;
      iono_[k] = gnss::IonoSlot{};
      clear_extra(kIono0 + k);
    }
  }

  bool eligible(const AmbSlot& a, int sys, int f) const {
    const gnss::RtkOptions& o = cfg_.rtk;
    return a.sat >= 0 && a.used && !a.half && a.freq == f && a.sat / gnss::kMaxPrn == sys &&
           a.lock >= o.min_lock_epochs && a.el >= o.ar_elevation_mask_rad;
  }

  void resolve(RtkInsEpoch& out) {
    const gnss::RtkOptions& o = cfg_.rtk;
    int n = 0;
    for (int sys = 0; sys < gnss::kNumSystems; ++sys) {
      if (sys == gnss::kGlonass && !o.glonass_ar) continue;
      for (int f = 0; f < gnss::kMaxFreq; ++f) {
        const int ref = gnss::highest_elevation_reference(
            kMaxAmb, [&](int k) { return eligible(amb_[k], sys, f); }, [&](int k) { return amb_[k].el; });
        if (ref < 0) continue;
        for (int k = 0; k < kMaxAmb; ++k) {
          if (k == ref || !eligible(amb_[k], sys, f) || n >= gnss::kMaxAmbiguities) continue;
          dd_j_[n] = k;
          dd_i_[n] = ref;
          dd_el_[n] = amb_[k].el;
          dd_var_[n] = Pee_(k, k) - 2.0 * Pee_(k, ref) + Pee_(ref, ref);
          ++n;
        }
      }
    }
    for (int i = 0; i < n; ++i) order_[i] = i;
    if (o.partial_by_variance)
      std::sort(order_.begin(), order_.begin() + n, [&](int a, int b) { return dd_var_[a] < dd_var_[b]; });
    else
      std::sort(order_.begin(), order_.begin() + n, [&](int a, int b) { return dd_el_[a] > dd_el_[b]; });
    gnss::ArSettings s;
    s.ratio_threshold = o.ratio_threshold;
    // subsets below min_fix_ambiguities only pass as every candidate of the epoch (FixValidator rule 1)
    s.min_fix = std::max(std::min(o.min_fix_ambiguities, n), 1);
    s.max_drops = o.max_partial_drops;
    s.validation_prob = cfg_.validation_prob;
    s.min_success_rate = std::max(cfg_.ar_min_success_rate, o.min_success_rate);
    const gnss::FixRules rules{o.min_fix_ambiguities, o.confirm_epochs, o.confirm_max_ambiguities};
    const auto slot_j = [&](int p) { return dd_j_[order_[p]]; };
    const auto slot_i = [&](int p) { return dd_i_[order_[p]]; };
    const bool ok = ar_.resolve(
        n, [&](int p) { return xe_(dd_j_[order_[p]]) - xe_(dd_i_[order_[p]]); },
        [&](int p, int q) {
          const int sj = dd_j_[order_[p]], si = dd_i_[order_[p]], tj = dd_j_[order_[q]], ti = dd_i_[order_[q]];
          return Pee_(sj, tj) - Pee_(sj, ti) - Pee_(si, tj) + Pee_(si, ti);
        },
        s, [&](int n_fix) { return validator_(n_fix, n, slot_j, slot_i, ar_.a_fix(), rules); });
    out.ratio = ar_.ratio();
    out.success_rate = ar_.success_rate();
    if (!ok) return;
    const int nu = ar_.n_used();
    // dx_fix = P_xN D^T Q_a^{-1} (a_hat - a_fix); the antenna follows the INS error
    Qxa_.resize(kN, nu);
    for (int p = 0; p < nu; ++p) Qxa_.col(p) = Pxe_.col(dd_j_[order_[p]]) - Pxe_.col(dd_i_[order_[p]]);
    w_ = ar_.residual();
    ar_.solve_in_place(w_);
    const Eigen::Matrix<double, kN, 1> dx_fix = Qxa_ * w_;
    NavState s_fix = core_.state();
    const wgs84::Radii rr = wgs84::radii(s_fix.lat);
    s_fix.lat -= dx_fix[L::kPos] / (rr.R_M + s_fix.h);
    s_fix.lon -= dx_fix[L::kPos + 1] / ((rr.R_N + s_fix.h) * std::cos(s_fix.lat));
    s_fix.h += dx_fix[L::kPos + 2];
    s_fix.q_nb = (quat_from_euler(dx_fix.template segment<3>(L::kAtt)) * s_fix.q_nb).normalized();
    RtkAntenna a;
    a.set(s_fix, cfg_.lever_arm_b);
    out.status = gnss::RtkStatus::kFixed;
    out.n_fix = nu;
    out.r_e = a.r_e;
    QxaT_ = Qxa_.transpose();
    ar_.solve_in_place(QxaT_);
    dP_fix_.noalias() = Qxa_ * QxaT_;  // P_xa Q_a^-1 P_ax: the covariance the fix removes
    out.P_r = (core_.filter.P() - dP_fix_).template block<3, 3>(L::kPos, L::kPos);
    // the integers the smoother holds from now on (hold_for_smoother): this fix's DDs as slot pairs
    held_n_ = nu;
    for (int p = 0; p < nu; ++p) {
      held_j_[p] = dd_j_[order_[p]];
      held_i_[p] = dd_i_[order_[p]];
      held_gen_j_[p] = amb_gen_[held_j_[p]];
      held_gen_i_[p] = amb_gen_[held_i_[p]];
      held_z_[p] = ar_.a_fix()(p);
    }
    if (o.ar_mode == gnss::ArMode::kFixAndHold) hold(nu);
    else {  // the smoother starts from the fixed solution (carried through outage cycles)
      core_.condition_for_smoother(dx_fix, dP_fix_);
      cond_dx_ = dx_fix;
      cond_dP_ = dP_fix_;
      cond_valid_ = true;
      if (!core_.recording()) {
        // no smoother: the rows hold the fixed solution (the INS conditioned on the integers, with the
        // feedback's formula) until the next epoch, mechanised beside the float filter, which does not
        // take the fix (ClosedLoop::start_output_shadow); the smoother's rows are conditioned above
        NavState s_out = core_.state();
        apply_nav_error(s_out, dx_fix.template segment<3>(L::kPos), dx_fix.template segment<3>(L::kVel),
                        dx_fix.template segment<3>(L::kAtt));
        ImuCorrection c = core_.corr;
        c.acc_bias += dx_fix.template segment<3>(L::kAccBias);
        c.gyro_bias += dx_fix.template segment<3>(L::kGyroBias);
        core_.start_output_shadow(s_out, c, dP_fix_.diagonal(),
                                  dP_fix_.template block<3, 3>(L::kAtt, L::kAtt));
      }
    }
  }

  // The smoother's filtered estimate of an epoch that has no continuous-AR fix of its own, conditioned
  // on the integers last fixed (held_*) whose two single-differenced ambiguities are still the ones
  // fixed (not re-initialised or removed since): dx = P_xa Q_a^-1 (a_hat - a_fix), dP = P_xa Q_a^-1 P_ax
  // from this epoch's joint float state (Teunissen 1995, eq. (6)), given to the smoother as a fixed
  // epoch's (ClosedLoop::condition_for_smoother) and carried through outage cycles.  The RTS backward
  // kernel p(x_k | x_k+1, data to k) at a fixed epoch k is only exact when the filtered estimate at
  // k + 1 holds the same integers (Rauch, Tung & Striebel 1965: the estimates must be those of one
  // model, here "the integers known"): without this, a fixed epoch followed by a float or code-only one
  // is smoothed towards the float solution, which has forgotten the integers.  With fix-and-hold the
  // fixed epoch itself is conditioned here (on the post-hold state: conditioning on a after the hold's
  // noisy pseudo-measurement of a is the conditioning of the pre-hold state, the forward fixed
  // solution).  The forward solution and its status are not changed.  The held integers are dropped
  // when their float no longer supports them: (a_hat - a_fix)' Q_a^-1 (a_hat - a_fix) beyond the
  // chi2 quantile of the fix validation (validation_prob, else 0.999), or Q_a not positive definite.
  void hold_for_smoother() {
    if (!core_.recording()) return;  // no smoother: nothing to condition (the forward pass is not changed)
    int n = 0;
    for (int p = 0; p < held_n_; ++p) {
      const int j = held_j_[p], i = held_i_[p];
      if (amb_[j].sat < 0 || amb_[i].sat < 0 || amb_gen_[j] != held_gen_j_[p] || amb_gen_[i] != held_gen_i_[p]) continue;
      held_j_[n] = j;
      held_i_[n] = i;
      held_gen_j_[n] = held_gen_j_[p];
      held_gen_i_[n] = held_gen_i_[p];
      held_z_[n] = held_z_[p];
      ++n;
    }
    held_n_ = n;
    if (n == 0) return;
    Qh_.resize(n, n);
    rh_.resize(n);
    Qxa_.resize(kN, n);
    for (int p = 0; p < n; ++p) {
      const int sj = held_j_[p], si = held_i_[p];
      rh_(p) = (xe_(sj) - xe_(si)) - held_z_[p];
      Qxa_.col(p) = Pxe_.col(sj) - Pxe_.col(si);
      for (int q = 0; q < n; ++q) {
        const int tj = held_j_[q], ti = held_i_[q];
        Qh_(p, q) = Pee_(sj, tj) - Pee_(sj, ti) - Pee_(si, tj) + Pee_(si, ti);
      }
    }
    llt_h_.compute(Qh_);
    if (llt_h_.info() != Eigen::Success) {
      held_n_ = 0;
      return;
    }
    w_ = llt_h_.solve(rh_);
    const double prob = cfg_.validation_prob > 0.0 ? cfg_.validation_prob : 0.999;
    if (!(rh_.dot(w_) <= chi2_quantile(prob, n))) {
      held_n_ = 0;
      return;
    }
    cond_dx_ = Qxa_ * w_;
    QxaT_ = llt_h_.solve(Qxa_.transpose());
    cond_dP_.noalias() = Qxa_ * QxaT_;
    core_.condition_for_smoother(cond_dx_, cond_dP_);
    cond_valid_ = true;
  }

  // Fix-and-hold: the fixed DD as pseudo-measurements N_j - N_i = a_fix (sigma hold_sigma_cycles).
  void hold(int nu) {
    gather();
    const int n = kN + ne_;
    const int m = std::min(nu, kMaxRowsE);
    H_.setZero(m, n);
    R_.setZero(kMaxRowsE, kMaxRowsE);
    for (int p = 0; p < m; ++p) {
      const int kj = dd_j_[order_[p]], ki = dd_i_[order_[p]];
      H_(p, ecol_[kj]) = 1.0;
      H_(p, ecol_[ki]) = -1.0;
      y_(p) = (xe_(kj) - xe_(ki)) - ar_.a_fix()(p);  // computed - "measured"
      R_(p, p) = cfg_.rtk.hold_sigma_cycles * cfg_.rtk.hold_sigma_cycles;
    }
    kalman_update(m);
    scatter_and_feedback();
  }

  ClosedLoop<Filter> core_;
  RtkInsConfig cfg_;
  // ambiguity block (fixed capacity, active mask = amb_[k].sat >= 0)
  // extra states E (ambiguities [cycles] at [0, kIono0), ionosphere [m] at [kIono0, kPhaseErr0), correlated
  // phase errors [m] at [kPhaseErr0, kMaxExtra)): mean, cross-covariance with the INS errors, covariance
  Eigen::Matrix<double, kMaxExtra, 1> xe_ = Eigen::Matrix<double, kMaxExtra, 1>::Zero();
  Eigen::Matrix<double, kN, kMaxExtra> Pxe_ = Eigen::Matrix<double, kN, kMaxExtra>::Zero();
  Eigen::Matrix<double, kMaxExtra, kMaxExtra> Pee_ = Eigen::Matrix<double, kMaxExtra, kMaxExtra>::Zero();
  std::array<AmbSlot, kMaxAmb> amb_{};
  std::array<int, gnss::kMaxSatKeys * gnss::kMaxFreq> amb_of_{};
  // ionosphere slots (iono_mode kEstimate; active mask = iono_[k].sat >= 0)
  std::array<gnss::IonoSlot, kMaxIono> iono_{};
  std::array<int, gnss::kMaxSatKeys> iono_of_{};
  double t_last_ = NAN;
  double dt_epoch_ = 0.0;    // time since the previous rover epoch [s] (0 on the first)
  double code_scale_ = 1.0;  // adaptive variance factor of the code rows (update_code_scale)
  RtkInsCounters counters_{};  // this run's work (RtkInsOutputs::counters; ar is ar_.counts())
  gnss::SlipDetector rover_slip_, base_slip_;
  std::array<std::uint8_t, gnss::kMaxSatKeys * gnss::kMaxFreq> flags_r_{}, flags_b_{};
  std::array<PrevSd, gnss::kMaxSatKeys * gnss::kMaxFreq> prev_{};
  // epoch geometry
  const double* rover_ = nullptr;
  const double* base_ = nullptr;
  Vec3 r_base_ = Vec3::Zero();
  Mat3 C_en_b_ = Mat3::Identity();
  double lat_b_ = 0.0, h_b_ = 0.0;
  RtkAntenna ant_;
  int n_common_ = 0, n_used_sats_ = 0;
  std::array<int, gnss::kMaxSatKeys> base_of_{}, common_r_{}, common_b_{};
  std::array<double, gnss::kMaxSatKeys> clock_buf_{};  // init_amb's single-differenced code residuals
  std::array<double, gnss::kMaxSatKeys> el_r_{}, el_b_{}, var_sd_{};
  std::array<bool, gnss::kMaxSatKeys> use_{};
  std::array<Vec3, gnss::kMaxSatKeys> u_{};
  std::array<int, gnss::kMaxSatKeys * gnss::kMaxFreq> amb_row_{};
  std::array<bool, gnss::kMaxSatKeys * gnss::kMaxFreq> code_out_{};
  // robust screening (screen_rows): per common satellite and frequency, phase left out this epoch
  // and the variance factors 1/q; per satellite key and frequency, the epoch of the last phase flag
  std::array<bool, gnss::kMaxSatKeys * gnss::kMaxFreq> phase_out_{};
  std::array<double, gnss::kMaxSatKeys * gnss::kMaxFreq> var_factor_code_{}, var_factor_phase_{};
  std::array<std::int64_t, gnss::kMaxSatKeys * gnss::kMaxFreq> last_phase_flag_{};
  std::array<int, gnss::kMaxSatKeys * gnss::kMaxFreq> phase_flag_run_{};  // epochs flagged in a row
  std::int64_t epoch_index_ = 0;
  int n_units_ = 0;
  std::array<int, 2 * kMaxRowsE> unit_c_{}, unit_f_{};
  std::array<double, 2 * kMaxRowsE> unit_w_{};
  RMat Sinv_;
  RVec Sy_;
  std::array<double, gnss::kMaxSatKeys * gnss::kMaxFreq> sd_phase_{}, sd_code_{}, d_{}, med_{};
  // rows and the compact update
  std::array<int, kMaxRowsE> row_c_{}, row_ref_{}, row_f_{}, row_amb_{}, row_amb_ref_{};
  int ne_ = 0;                                  // active extra states (gather)
  std::array<int, kMaxExtra> act_e_{}, ecol_{};  // their slots; a slot's column in the compact state or -1
  JMat Pj_, Pn_;
  JVec dx_;
  HMat H_, KT_;
  KMat PHt_;
  RMat R_, S_;
  RVec y_;
  Eigen::LLT<RMat> llt_{kMaxRowsE};
  // AR
  gnss::PartialAr ar_;
  gnss::FixValidator<kMaxAmb> validator_;  // fix validation over epochs (gnss/ambiguity_resolution.hpp)
  std::array<int, gnss::kMaxAmbiguities> dd_j_{}, dd_i_{}, order_{};
  std::array<double, gnss::kMaxAmbiguities> dd_el_{}, dd_var_{};
  Eigen::Matrix<double, kN, Eigen::Dynamic, 0, kN, gnss::kMaxAmbiguities> Qxa_;
  Eigen::Matrix<double, Eigen::Dynamic, kN, 0, gnss::kMaxAmbiguities, kN> QxaT_;
  Eigen::Matrix<double, kN, kN> dP_fix_ = Eigen::Matrix<double, kN, kN>::Zero();
  // the last epoch's fixed conditioning of the smoother (continuous AR), predicted over outage cycles
  bool cond_valid_ = false;
  Eigen::Matrix<double, kN, 1> cond_dx_ = Eigen::Matrix<double, kN, 1>::Zero();
  Eigen::Matrix<double, kN, kN> cond_dP_ = Eigen::Matrix<double, kN, kN>::Zero();
  // the integers the smoother holds (hold_for_smoother): the last fix's DDs N_j - N_i = z as slot
  // pairs, with the slots' generations at the fix (amb_gen_: bumped when a slot is re-initialised or freed)
  std::array<std::uint32_t, kMaxAmb> amb_gen_{};
  int held_n_ = 0;
  std::array<int, gnss::kMaxAmbiguities> held_j_{}, held_i_{};
  std::array<std::uint32_t, gnss::kMaxAmbiguities> held_gen_j_{}, held_gen_i_{};
  std::array<double, gnss::kMaxAmbiguities> held_z_{};
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, gnss::kMaxAmbiguities, gnss::kMaxAmbiguities> Qh_;
  gnss::AmbVec rh_;
  Eigen::LLT<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, gnss::kMaxAmbiguities, gnss::kMaxAmbiguities>>
      llt_h_{gnss::kMaxAmbiguities};
  gnss::AmbVec w_;
  // the unscented filters' cycle transition (cycle_phi): the covariance the cycle's points were drawn from
  // (ClosedLoop::start_cycle -> begin_cycle draws them from P, repairing P in place if it is not
  // positive definite; P then stays unchanged until end_cycle, so it is read once a cycle has begun)
  Mat15 P_start_ = Mat15::Zero(), Ps_ = Mat15::Zero(), W_ = Mat15::Zero(), PhiT_ = Mat15::Zero(),
        Phi_ut_ = Mat15::Identity();
  double p_start_t_ = NAN;  // cycle_start of the cycle P_start_ belongs to
  Eigen::LDLT<Mat15> ldlt_{};
};

}  // namespace insnav
