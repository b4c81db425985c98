// insnav/filter/particle_filter.hpp -- insnav's particle filter (by default
// marginalised), the bootstrap particle filter that seed 004 (Shao et al.
// 2013) compares against, and the settings and diagnostics every particle
// filter shares (random.hpp: random numbers; resampling.hpp: weights,
// resampling, roughening; macro_step.hpp: the multi-interval RK4 step).
//
// Marginalised PF (`marginalize`, the default; Rao-Blackwellised PF: Schön,
// Gustafsson, Nordlund 2005, "Marginalized particle filters for mixed
// linear/nonlinear state-space models", IEEE Trans. Signal Processing
// 53(7):2279-2289, sec. III-IV and Algorithm 1; Doucet, Godsill, Andrieu 2000,
// Statistics and Computing 10:197-208, sec. IV):
//   split       x = (r, s): the particles sample only r -- attitude, gyro
//               random constant and gyro Markov (9 states), the states through
//               which the error model is nonlinear (large attitude errors) and
//               which the GNSS rows see only through the dynamics -- while s --
//               position, velocity, clock bias and drift, accelerometer bias
//               (11 states), whose dynamics given r are linear and which the
//               pseudoranges and rates observe -- is carried by a Kalman mean
//               s_i per particle and ONE covariance P_s shared by all particles.
//               The covariance is shared because its Riccati recursion uses
//               Phi_ss and H_s of the linear model at the INS (linearised at the
//               estimate, not at each particle): exact when they do not depend
//               on r (Schön et al. 2005, sec. IV-B), an EKF-type approximation
//               here.  One gain and one factorisation per epoch, no
//               per-particle covariance: that is what separates this filter
//               from the UPF (upf.hpp), whose particles each carry a UKF;
//   propagate   every particle (r_i, s_i) through the exact nonlinear model
//               (RK4; for s_i this is the conditional mean, the dynamics being
//               affine in s given r), P_s = Phi_ss P_s Phi_ss^T; the cycle's
//               process noise w ~ N(0, Q) is split in (r, s) order with one
//               lower Cholesky factor [L_rr 0; L_sr L_ss]: w_r = L_rr xi is
//               drawn per particle (the bootstrap proposal for r), s_i moves by
//               E[w_s | w_r] = L_sr xi, and P_s += L_ss L_ss^T (Schön et al.
//               2005, sec. III, correlated process noise);
//   update      S = H_s P_s H_s^T + R, K = P_s H_s^T S^-1 (LLT solves; one of
//               each per epoch), for every particle the innovation
//               g_i = residual - h(r_i, s_i) (nonlinear h), the weight
//               log w_i += -1/2 |L_S^-1 g_i|^2 (the predictive likelihood
//               p(z | r_i, past z): Schön et al. 2005 eq. (25a)), the mean
//               s_i += K g_i; P_s by the Joseph form.  No progressive correction
//               (the predictive likelihood is as wide as P_s: N_eff stays high).
//               What is left out: the information the sampled r transition
//               carries about s (Schön et al. 2005 eq. (24), the "second
//               measurement update"), since s enters the attitude dynamics only
//               through the transport rate (v / R, ~1e-7 rad/s per m/s);
//   resampling  systematic when N_eff < threshold * N, roughening of r only
//               (the spread of s is in P_s), no noise floor by default: the
//               kernel alone keeps the gyro random constants from collapsing,
//               and a floor only adds yaw random walk (seed004-uav: whole-run
//               yaw RMS 6-16 arcmin without it, 25-30 with a floor of 1,
//               80-400 with 3);
//   divergence  counted as below with S in place of R; with `reseed` the
//               linear means of position, velocity and clock are set to the
//               measurement's solution given r_i (no draw) and P_s's block to
//               its covariance A^-1 (below).
// Why (seed004-uav, N = 1000; docs/results/seed004.md): the bootstrap PF's
// position and clock are near-static states for which resampling is a random
// walk (genetic drift) that the 15-m pseudoranges cannot undo -- after the
// outage its vertical stayed tens of metres off for 100 s and more -- and with
// the 0.1-m/s rates the weights select velocity, not attitude: its yaw error
// grew to 1-50 deg.  The marginalised PF averages the pseudoranges in P_s and
// its weights, no longer dominated by the rates, select the attitude.
//
// Bootstrap PF (`marginalize = false`; Gordon, Salmond, Smith 1993; seed 004 ref. [2]):
//   propagate   every particle through the exact nonlinear error model
//               (error_model_nonlinear.hpp, RK4) and add process noise drawn
//               from the accumulated Q of the cycle (Q_c = Phi Q_c Phi^T + Q_d);
//   update      log w_i += log p(z | x_i) = -1/2 |L_R^-1 (residual - h(x_i))|^2
//               (h = meas.predicted_residual, nonlinear); normalise;
//               N_eff = 1 / sum w_i^2; if N_eff < threshold * N: systematic
//               resampling, then regularisation ("roughening"): every particle,
//               in every state, is moved by k * chol(P_cloud) xi, xi ~ N(0, I),
//               with P_cloud the *unweighted* covariance of the cloud before
//               resampling (Musso, Oudjane, Le Gland 2001, with a bandwidth k
//               below their h_opt, which over-disperses: for N = 100 and n = 20
//               h_opt = 0.77).  The weighted covariance would collapse with the
//               weights: when one particle takes all the weight (N_eff ~ 1, the
//               rule with 0.1 m/s pseudorange rates) the kernel vanished and the
//               cloud degenerated to one point, the cause of the earlier km-level
//               divergence.  Without roughening the random-constant gyro states
//               (no process noise) collapse onto a few values.
//   progressive correction (Oudjane, Musso 2000): when the full likelihood
//               would leave N_eff below threshold * N, it is applied in stages
//               p(z | x)^beta_s, sum beta_s = 1, each beta chosen by bisection so
//               that the stage keeps N_eff >= threshold * N, with resampling and
//               roughening between stages (at most temper_stages; the last takes
//               what is left).  The particles move towards the likelihood's peak
//               instead of all weight landing on the one nearest it;
//   noise floor every state also random-walks by noise_floor x its initial
//               sigma per sqrt(hour) (3 for this variant; the Python default):
//               resampling shrinks the spread of the states without process
//               noise (random-constant gyro biases) every epoch,
//               and a roughening kernel shaped by the cloud shrinks with it; the
//               floor keeps the cloud wide enough to follow the truth (seed004-uav,
//               N = 1000: without it the cloud collapsed to one point within
//               600 s and lost the solution; floors of 1 and 2 sigma per sqrt(h)
//               still lost it in some runs, 3 in none of the runs tried;
//               docs/results/seed004.md has the success rate over 20 runs).
//   divergence  when the particle that explains z best is still more than
//               divergence_chi2 per measurement row away (no particle within
//               ~5 sigma), the epoch is counted in divergences() and reported by
//               the bindings: the estimate there is not to be trusted.
//   sensor resetting (Lenser & Veloso 2000, "Sensor resetting localization
//               for poorly modelled mobile robots", ICRA; `reseed`, on by
//               default): at a divergent epoch the states the GNSS rows observe
//               directly -- position, velocity, clock bias and drift, s -- of
//               every particle are drawn again from the measurement, given the
//               particle's other states r:  s_i ~ N(A^-1 H_s' R^-1 (z - H_r r_i),
//               A^-1),  A = H_s' R^-1 H_s  (needs as many rows as s has states
//               and a full-rank A; 4 satellites with pseudorange and rate: 8 = 8);
//               the weights become uniform and the measurement is not applied
//               again as a likelihood.  A bootstrap PF in 20 states loses the
//               truth whenever no particle lies within the pseudorange rates'
//               0.1 m/s (seed004-uav: 511 such epochs per run, 505 m median
//               error after the outage without it); the reset puts the cloud
//               back on the measurement, the attitude and bias states keep
//               their particle values.  reseeds() counts the epochs.
//   estimate    x^ = sum w_i x_i and P^ = sum w_i (x_i - x^)(x_i - x^)^T, formed
//               before resampling (less Monte Carlo noise).
// Closed loop (engines): after an applied update the engine feeds x^ back into
// the INS and calls reset_state(), which shifts every particle by the fed-back
// part of x^ (x_i -= x^), so the cloud keeps its shape around the corrected INS.
//
// Determinism: every random number comes from a counter-based stream
// (xoshiro256** seeded by splitmix64 of (seed, cycle, particle, purpose)); the
// result does not depend on the order particles are processed in, so the loops
// over particles can run in parallel (OpenMP when compiled with -fopenmp) with
// results identical to the serial run.  Normals by Box-Muller (portable; the
// std:: distributions differ between standard libraries).
//
// Storage: the particle count is a run-time value; all per-particle storage is
// std::vector allocated once at construction (never per epoch).
//
// Multi-interval RK4 step (MacroStep): the engines hand the filter propagation
// intervals of ~20 ms; the particle filters integrate the error state over
// `rk4_step` seconds (default 1 s, the filter period) with one RK4 step using
// the INS at the start, the middle (the stored interval point nearest to it)
// and the end; the process noise uses Phi and Q_d of the linear model at the
// middle.  rk4_step = 0 integrates every engine interval (as Ukf/RbUkf do).
// The error dynamics are slow (Schuler period 84 min) and RK4 is 4th order,
// so 1-s steps change the propagated error by far less than the noise.
#pragma once

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "insnav/check.hpp"
#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/error_model_nonlinear.hpp"
#include "insnav/filter/layout20.hpp"
#include "insnav/filter/macro_step.hpp"
#include "insnav/filter/random.hpp"
#include "insnav/filter/resampling.hpp"
#include "insnav/filter/sigma_points.hpp"
#include "insnav/filter/types.hpp"


namespace insnav {

/// Per-epoch diagnostics a particle filter can write (caller-owned, optional).
struct ParticleTrace {
  double* ess = nullptr;       // effective sample size after the update, before resampling
  double* fading_c = nullptr;  // weighted mean c_k of the fading factors (0: off)
  double* eta_max = nullptr;   // weighted mean of max_i eta_i (1: no fading)
  std::int8_t* resampled = nullptr;
  std::int64_t capacity = 0, n = 0;
  void record(double e, double c, double eta, bool rs) {
    if (n >= capacity) return;
    if (ess) ess[n] = e;
    if (fading_c) fading_c[n] = c;
    if (eta_max) eta_max[n] = eta;
    if (resampled) resampled[n] = rs ? 1 : 0;
    ++n;
  }
};

/// Settings shared by the particle filters.
struct ParticleParams {
  int particles = 100;
  std::uint64_t seed = 1;
  double resample_threshold = 0.5;  // resample when N_eff < threshold * N
  double roughening = 0.2;          // regularisation bandwidth k (0: off)
  double rk4_step = 1.0;            // [s] multi-interval RK4 step; 0: every engine interval
  int max_particles = 4096;         // upper bound checked at construction
  int temper_stages = 8;            // PF: progressive-correction stages at most (1: plain bootstrap update)
  double noise_floor = 0.0;         // PF: every state random-walks by this x its initial sigma per sqrt(h)
                                    //     (the bootstrap variants need ~3, the marginalised PF none: header)
  double divergence_chi2 = 25.0;    // PF: divergence when no particle explains z within this chi^2 per row
  bool reseed = true;               // PF: sensor resetting at a divergent epoch (header)
  bool marginalize = true;          // PF: Rao-Blackwellised linear substate (header); false: bootstrap
};

/// Innovation gate / NIS of the estimate: gamma = residual - h(x),
/// S = H P H^T + R.  Returns NaN when S is not positive definite.
template <class L, class Meas>
double estimate_nis(const Meas& meas, const StateVec<L>& x, const StateCov<L>& P) {
  using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  using Gain = Eigen::Matrix<double, L::kSize, Eigen::Dynamic, 0, L::kSize, kMaxMeasRows>;
  const LinearMeasurement<L>& lin = meas.linear();
  typename LinearMeasurement<L>::RowVec g = lin.residual - meas.predicted_residual(x);
  Gain PHt;
  PHt.noalias() = P * lin.H.transpose();
  Dyn S;
  S.noalias() = lin.H * PHt;
  S += lin.R;
  Eigen::LLT<Dyn> llt(S);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::quiet_NaN();
  llt.matrixL().solveInPlace(g);
  return g.squaredNorm();
}

/// The start of every particle filter's update: the rows, the NIS of the
/// estimate against the gate (gate_chi2 <= 0: no gate), and R positive
/// definite (factorised into lltR).  False when the update stops here; `res`
/// says why (no rows, rejected by the gate, or a Cholesky repair count of 1).
template <class L, class Meas, class Llt>
bool update_admitted(const Meas& meas, const StateVec<L>& x, const StateCov<L>& P, double gate_chi2, Llt& lltR,
                     UpdateResult& res) {
  const LinearMeasurement<L>& lin = meas.linear();
  res.rows = lin.rows();
  if (res.rows == 0) return false;
  res.nis = estimate_nis<L>(meas, x, P);
  if (gate_chi2 > 0.0 && !(res.nis <= gate_chi2)) {
    res.rejected_by_gate = true;
    return false;
  }
  lltR.compute(lin.R);
  if (lltR.info() != Eigen::Success) {
    res.cholesky_repairs = 1;
    return false;
  }
  return true;
}

// --- bootstrap particle filter -------------------------------------------------------

template <class L>
class ParticleFilter {
 public:
  using Layout = L;
  static constexpr int kN = L::kSize;
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;

  /// Engines construct filters from the model alone; a run then assigns a
  /// configured filter (engine.filter() = ParticleFilter(model, prm)).
  explicit ParticleFilter(const ImuErrorModel& model) : ParticleFilter(model, ParticleParams{}) {}

  ParticleFilter(const ImuErrorModel& model, const ParticleParams& prm)
      : model_(model), prm_(prm), macro_(model, prm.rk4_step) {
    INSNAV_CHECK(prm.particles >= 1 && prm.particles <= prm.max_particles, "particle count out of range");
    const int n = prm.particles;
    xs_.assign(n, Vec::Zero());
    xs_tmp_.assign(n, Vec::Zero());
    logw_.assign(n, 0.0);
    w_.assign(n, 1.0 / n);
    ll_.assign(n, 0.0);
    tw_.assign(n, 0.0);
    idx_.assign(n, 0);
    innov_.assign(n, RowVec::Zero(kMaxMeasRows));
  }

  void set_trace(ParticleTrace* t) { trace_ = t; }

  void initialize(const Cov& P0) {
    const int n = prm_.particles;
    divergences_ = 0;
    Cov S;
    Cov P = P0;
    cholesky_with_repair<kN>(P, S);
    sigma0_ = P0.diagonal().cwiseMax(0.0).cwiseSqrt();
    cycle_ = 0;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      Rng rng;
      rng.seed(prm_.seed, 0, i, kRngInit);
      Vec xi;
      rng.fill_normal(xi);
      xs_[i] = n == 1 ? Vec::Zero() : Vec(S * xi);
    }
    if (prm_.marginalize) condition_initial(P0);
    for (int i = 0; i < n; ++i) {
      logw_[i] = 0.0;
      w_[i] = 1.0 / n;
    }
    estimate();
    Q_cycle_.setZero();
    macro_.reset();
  }

  void begin_cycle() {
    Q_cycle_.setZero();
    macro_.reset();
    steps_ = 0;
    ++cycle_;
    stage_rng_ = 0;
  }

  void propagate(const InsInterval& iv) {
    if (macro_.add(iv)) run_step();
  }

  void end_cycle() {
    if (macro_.pending()) run_step();
    if (steps_ == 0) return;
    steps_ = 0;
    // process noise of the cycle, plus the floor on every state (header)
    const Vec floor = (prm_.noise_floor * std::sqrt(cycle_dt_ / 3600.0)) * sigma0_;
    cycle_dt_ = 0.0;
    if (prm_.marginalize) {
      sample_process_noise_marginalised(floor);
      estimate();
      return;
    }
    psd_cholesky_lower<kN>(Q_cycle_, sqrtQ_);
    const int n = prm_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      Rng rng;
      rng.seed(prm_.seed, cycle_, i, kRngProcess);
      Vec xi, eta;
      rng.fill_normal(xi);
      rng.fill_normal(eta);
      xs_[i].noalias() += sqrtQ_ * xi;
      xs_[i] += floor.cwiseProduct(eta);
      if (!xs_[i].allFinite()) xs_[i] = x_;  // left the model's domain: back to the estimate
    }
    estimate();
  }

  template <class Meas>
  UpdateResult update(const Meas& meas, double gate_chi2) {
    const LinearMeasurement<L>& lin = meas.linear();
    UpdateResult res;
    if (!update_admitted<L>(meas, x_, P_, gate_chi2, lltR_, res)) {
      repairs_ += res.cholesky_repairs;
      return res;
    }
    if (prm_.marginalize) return update_marginalised(meas, res);
    const int m = res.rows;
    const int n = prm_.particles;
    double left = 1.0;
    for (int stage = 0; stage < std::max(prm_.temper_stages, 1) && left > 0.0; ++stage) {
      INSNAV_PARALLEL_FOR
      for (int i = 0; i < n; ++i) {
        RowVec e = lin.residual - meas.predicted_residual(xs_[i]);
        lltR_.matrixL().solveInPlace(e);
        const double ll = -0.5 * e.squaredNorm();
        ll_[i] = std::isfinite(ll) ? ll : -std::numeric_limits<double>::infinity();
      }
      if (stage == 0) {
        double best = -std::numeric_limits<double>::infinity();
        for (int i = 0; i < n; ++i) best = std::max(best, ll_[i]);
        if (!(-2.0 * best <= prm_.divergence_chi2 * m)) {
          ++divergences_;
          if (prm_.reseed && n > 1 && reseed_from(lin)) {
            res.applied = true;
            return res;
          }
        }
      }
      const bool last = stage + 1 >= std::max(prm_.temper_stages, 1);
      const double beta = (n == 1 || last) ? left : temper_exponent(left);
      for (int i = 0; i < n; ++i) logw_[i] += beta * ll_[i];
      left -= beta;
      if (left <= 1e-12) left = 0.0;
      finish_update(left > 0.0);
    }
    res.applied = true;
    return res;
  }
  int divergences() const { return divergences_; }
  int reseeds() const { return reseeds_; }
  /// Marginalised PF: the covariance shared by every particle's linear
  /// substate (order: linear_index()); zero for the bootstrap PF.
  const Eigen::Matrix<double, 11, 11>& linear_covariance() const { return Ps_; }
  static constexpr std::array<int, 11> linear_index() { return kLin; }

  const Vec& x() const { return x_; }
  const Cov& P() const { return P_; }
  void reset_state() {
    const int n = prm_.particles;
    for (int i = 0; i < n; ++i) subtract_fed_back<L>(xs_[i], x_);
    zero_fed_back<L>(x_);
  }
  int cholesky_repairs() const { return repairs_; }
  int particles() const { return prm_.particles; }
  const std::vector<Vec>& particle_states() const { return xs_; }
  const std::vector<double>& weights() const { return w_; }
  double last_ess() const { return ess_; }
  int resample_count() const { return resamples_; }

 private:
  using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  using RowVec = typename LinearMeasurement<L>::RowVec;
  using Self = ParticleFilter;

  // Marginalised PF: the linear substate s (position, velocity, clock bias and
  // drift -- the states the GNSS rows observe, in the order of reseed_from --
  // then the accelerometer bias) and the nonlinear substate r (attitude, gyro
  // biases): every other state.  kPerm = (r, s).
  static constexpr int kS = 11;
  static constexpr int kR = kN - kS;
  using SVec = Eigen::Matrix<double, kS, 1>;
  using SMat = Eigen::Matrix<double, kS, kS>;
  using RMat = Eigen::Matrix<double, kR, kR>;
  using HsMat = Eigen::Matrix<double, Eigen::Dynamic, kS, 0, kMaxMeasRows, kS>;
  using KMat = Eigen::Matrix<double, kS, Eigen::Dynamic, 0, kS, kMaxMeasRows>;
  static constexpr std::array<int, kS> kLin = {L::kPos,         L::kPos + 1,      L::kPos + 2,     L::kVel,
                                               L::kVel + 1,     L::kVel + 2,      L::kClockBias,   L::kClockDrift,
                                               L::kAccBias,     L::kAccBias + 1,  L::kAccBias + 2};
  static constexpr bool is_linear(int k) {
    for (int a = 0; a < kS; ++a)
      if (kLin[a] == k) return true;
    return false;
  }
  static constexpr std::array<int, kR> nonlinear_index() {
    std::array<int, kR> r{};
    int j = 0;
    for (int k = 0; k < kN; ++k)
      if (!is_linear(k)) r[j++] = k;
    return r;
  }
  static constexpr std::array<int, kR> kNonlin = nonlinear_index();
  static constexpr std::array<int, kN> permutation() {
    std::array<int, kN> p{};
    for (int b = 0; b < kR; ++b) p[b] = kNonlin[b];
    for (int a = 0; a < kS; ++a) p[kR + a] = kLin[a];
    return p;
  }
  static constexpr std::array<int, kN> kPerm = permutation();

  void run_step() {
    macro_.prepare();
    cycle_dt_ += macro_.dt;
    const int n = prm_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) rk4_error_step<L>(xs_[i], macro_.p0, macro_.ph, macro_.p1, macro_.dt);
    work_.noalias() = macro_.phi * Q_cycle_;
    Q_cycle_.noalias() = work_ * macro_.phi.transpose();
    Q_cycle_ += macro_.qd;
    if (prm_.marginalize) {  // P_s = Phi_ss P_s Phi_ss^T (the particle carries r exactly)
      SMat phi_ss;
      for (int a = 0; a < kS; ++a)
        for (int b = 0; b < kS; ++b) phi_ss(a, b) = macro_.phi(kLin[a], kLin[b]);
      Ps_work_.noalias() = phi_ss * Ps_;
      Ps_.noalias() = Ps_work_ * phi_ss.transpose();
    }
    ++steps_;
  }

  /// x^ and P^ of the cloud; the marginalised PF adds the shared covariance
  /// of the linear substate (law of total covariance).
  void estimate() {
    weighted_mean_cov<L>(xs_, w_.data(), prm_.particles, x_, P_);
    if (prm_.marginalize)
      for (int a = 0; a < kS; ++a)
        for (int b = 0; b < kS; ++b) P_(kLin[a], kLin[b]) += Ps_(a, b);
  }

  // --- marginalised (Rao-Blackwellised) PF: header ---------------------------------

  /// Initial linear substate given each particle's nonlinear draw:
  /// s_i = P_sr P_rr^-1 r_i, P_s = P_ss - P_sr P_rr^-1 P_rs (a Gaussian P0
  /// conditioned on r; P_rr singular: s_i = 0, P_s = P_ss).
  void condition_initial(const Cov& P0) {
    RMat Prr;
    Eigen::Matrix<double, kS, kR> Psr;
    for (int a = 0; a < kR; ++a)
      for (int b = 0; b < kR; ++b) Prr(a, b) = P0(kNonlin[a], kNonlin[b]);
    for (int a = 0; a < kS; ++a) {
      for (int b = 0; b < kR; ++b) Psr(a, b) = P0(kLin[a], kNonlin[b]);
      for (int b = 0; b < kS; ++b) Ps_(a, b) = P0(kLin[a], kLin[b]);
    }
    Eigen::Matrix<double, kS, kR> G = Eigen::Matrix<double, kS, kR>::Zero();
    const Eigen::LLT<RMat> llt(Prr);
    if (llt.info() == Eigen::Success && Psr.cwiseAbs().maxCoeff() > 0.0) {
      G = llt.solve(Psr.transpose()).transpose();
      Ps_ -= G * Psr.transpose();
    }
    symmetrize<kS>(Ps_);
    const int n = prm_.particles;
    for (int i = 0; i < n; ++i) {
      Eigen::Matrix<double, kR, 1> r;
      for (int b = 0; b < kR; ++b) r[b] = xs_[i][kNonlin[b]];
      const SVec s = G * r;
      for (int a = 0; a < kS; ++a) xs_[i][kLin[a]] = s[a];
    }
  }

  /// The cycle's process noise w ~ N(0, Q) split into the nonlinear part w_r,
  /// drawn per particle, and the linear part: its conditional mean
  /// E[w_s | w_r] = Q_sr Q_rr^-1 w_r moves the particle's linear mean, its
  /// conditional covariance Q_ss - Q_sr Q_rr^-1 Q_rs (and the noise floor of
  /// the linear states) goes into the shared P_s.  With the lower Cholesky
  /// factor of Q in (r, s) order, [L_rr 0; L_sr L_ss], both come from one
  /// factorisation: w_r = L_rr xi, E[w_s | w_r] = L_sr xi, cov = L_ss L_ss^T
  /// (Schön, Gustafsson, Nordlund 2005, sec. III, correlated noise).
  void sample_process_noise_marginalised(const Vec& floor) {
    for (int a = 0; a < kN; ++a)
      for (int b = 0; b < kN; ++b) work_(a, b) = Q_cycle_(kPerm[a], kPerm[b]);
    psd_cholesky_lower<kN>(work_, sqrtQ_);
    const SMat Lss = sqrtQ_.template bottomRightCorner<kS, kS>();
    Ps_.noalias() += Lss * Lss.transpose();
    for (int a = 0; a < kS; ++a) Ps_(a, a) += floor[kLin[a]] * floor[kLin[a]];
    const int n = prm_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      Rng rng;
      rng.seed(prm_.seed, cycle_, i, kRngProcess);
      Eigen::Matrix<double, kR, 1> xi, eta;
      rng.fill_normal(xi);
      rng.fill_normal(eta);
      const Vec w = sqrtQ_.template leftCols<kR>() * xi;  // (r, s) order
      Vec& x = xs_[i];
      for (int a = 0; a < kN; ++a) x[kPerm[a]] += w[a];
      for (int b = 0; b < kR; ++b) x[kNonlin[b]] += floor[kNonlin[b]] * eta[b];
      if (!x.allFinite()) x = x_;
    }
  }

  /// Measurement update of the marginalised PF (header): one Kalman gain for
  /// every particle's linear mean, weights by the predictive likelihood
  /// N(z; h(x_i), H_s P_s H_s^T + R).
  template <class Meas>
  UpdateResult update_marginalised(const Meas& meas, UpdateResult res) {
    const LinearMeasurement<L>& lin = meas.linear();
    const int m = res.rows;
    const int n = prm_.particles;
    HsMat Hs(m, kS);
    for (int a = 0; a < kS; ++a) Hs.col(a) = lin.H.col(kLin[a]);
    const KMat PHt = Ps_ * Hs.transpose();
    Dyn S = Hs * PHt;
    S += lin.R;
    lltS_.compute(S);
    if (lltS_.info() != Eigen::Success) {
      ++repairs_;
      res.cholesky_repairs = 1;
      return res;
    }
    const KMat K = lltS_.solve(PHt.transpose()).transpose();  // P_s H_s^T S^-1
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      innov_[i] = lin.residual - meas.predicted_residual(xs_[i]);
      RowVec e = innov_[i];
      lltS_.matrixL().solveInPlace(e);
      const double ll = -0.5 * e.squaredNorm();
      ll_[i] = std::isfinite(ll) ? ll : -std::numeric_limits<double>::infinity();
    }
    double best = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) best = std::max(best, ll_[i]);
    if (!(-2.0 * best <= prm_.divergence_chi2 * m)) {
      ++divergences_;
      if (prm_.reseed && reseed_from(lin)) {
        res.applied = true;
        return res;
      }
    }
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      const SVec ds = K * innov_[i];
      for (int a = 0; a < kS; ++a) xs_[i][kLin[a]] += ds[a];
      logw_[i] += ll_[i];
    }
    // Joseph form: P_s = (I - K H_s) P_s (I - K H_s)^T + K R K^T
    const SMat IKH = SMat::Identity() - K * Hs;
    Ps_work_.noalias() = IKH * Ps_;
    Ps_.noalias() = Ps_work_ * IKH.transpose();
    Ps_.noalias() += K * lin.R * K.transpose();
    symmetrize<kS>(Ps_);
    finish_update(false);
    res.applied = true;
    return res;
  }

  /// Roughening of the marginalised PF: only the nonlinear substate (the
  /// spread of the linear one is in P_s); the kernel is k chol of the
  /// unweighted cloud covariance of r (as roughen() does for the whole state).
  void roughen_nonlinear(const Cov& P_cloud, std::uint64_t stream) {
    RMat Prr, Lrr;
    for (int a = 0; a < kR; ++a)
      for (int b = 0; b < kR; ++b) Prr(a, b) = P_cloud(kNonlin[a], kNonlin[b]);
    psd_cholesky_lower<kR>(Prr, Lrr);
    Lrr *= prm_.roughening;
    const int n = prm_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      Rng r;
      r.seed(prm_.seed, stream, i, kRngJitter);
      Eigen::Matrix<double, kR, 1> xi;
      r.fill_normal(xi);
      const Eigen::Matrix<double, kR, 1> d = Lrr * xi;
      for (int b = 0; b < kR; ++b) xs_[i][kNonlin[b]] += d[b];
    }
  }

  /// Sensor resetting (header): position, velocity and clock of every
  /// particle drawn from the linearised measurement given its other states.
  /// False (nothing changed) with too few rows or a rank-deficient geometry.
  bool reseed_from(const LinearMeasurement<L>& lin) {
    constexpr int kS = 8;
    static constexpr int kIdx[kS] = {L::kPos,     L::kPos + 1,   L::kPos + 2,     L::kVel,
                                     L::kVel + 1, L::kVel + 2,   L::kClockBias,   L::kClockDrift};
    const int m = lin.rows();
    if (m < kS) return false;
    using HsMat = Eigen::Matrix<double, Eigen::Dynamic, kS, 0, kMaxMeasRows, kS>;
    HsMat Ws(m, kS);  // L_R^-1 H_s (whitened)
    for (int j = 0; j < kS; ++j) Ws.col(j) = lin.H.col(kIdx[j]);
    lltR_.matrixL().solveInPlace(Ws);
    const Eigen::Matrix<double, kS, kS> A = Ws.transpose() * Ws;
    const Eigen::LLT<Eigen::Matrix<double, kS, kS>> lltA(A);
    if (lltA.info() != Eigen::Success || !(lltA.matrixL().toDenseMatrix().diagonal().minCoeff() > 1e-9)) return false;
    const int n = prm_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      Vec& x = xs_[i];
      RowVec r = lin.residual - lin.H * x;  // z - H_r r_i - H_s s_i ...
      for (int j = 0; j < kS; ++j) r += lin.H.col(kIdx[j]) * x[kIdx[j]];  // ... + H_s s_i
      lltR_.matrixL().solveInPlace(r);
      Eigen::Matrix<double, kS, 1> s = lltA.solve(Ws.transpose() * r), xi;
      Rng rng;
      rng.seed(prm_.seed, cycle_, i, kRngReseed);
      rng.fill_normal(xi);
      if (!prm_.marginalize) s += lltA.matrixU().solve(xi);  // cov (L L')^-1 = A^-1
      for (int j = 0; j < kS; ++j) x[kIdx[j]] = s[j];
      if (!x.allFinite()) x = x_;
    }
    if (prm_.marginalize) {  // the linear means keep the solution, P_s its covariance A^-1
      const Eigen::Matrix<double, kS, kS> Ainv = lltA.solve(Eigen::Matrix<double, kS, kS>::Identity());
      Ps_.template topLeftCorner<kS, kS>() = Ainv;
      Ps_.template topRightCorner<kS, Self::kS - kS>().setZero();
      Ps_.template bottomLeftCorner<Self::kS - kS, kS>().setZero();
    }
    for (int i = 0; i < n; ++i) {
      logw_[i] = 0.0;
      w_[i] = 1.0 / n;
    }
    ess_ = n;
    estimate();
    ++reseeds_;
    if (trace_) trace_->record(ess_, 0.0, 1.0, false);
    return true;
  }

  /// Largest beta in (0, left] whose tempered weights keep N_eff >= threshold N
  /// (bisection on the exponent of the likelihood; seed of no randomness).
  double temper_exponent(double left) {
    const int n = prm_.particles;
    const double target = std::max(prm_.resample_threshold, 0.1) * n;
    auto ess_at = [&](double b) {
      for (int i = 0; i < n; ++i) tw_[i] = logw_[i] + b * ll_[i];
      normalize_log_weights(tw_.data(), w_.data(), n);
      return effective_sample_size(w_.data(), n);
    };
    if (ess_at(left) >= target) return left;
    double lo = 0.0, hi = left;
    for (int it = 0; it < 30; ++it) {
      const double mid = 0.5 * (lo + hi);
      (ess_at(mid) >= target ? lo : hi) = mid;
    }
    return std::max(lo, 1e-6 * left);
  }

  /// Normalise, estimate, and resample + roughen when N_eff is low (always
  /// between progressive-correction stages: force).
  void finish_update(bool force = false) {
    const int n = prm_.particles;
    normalize_log_weights(logw_.data(), w_.data(), n);
    ess_ = effective_sample_size(w_.data(), n);
    estimate();
    const bool rs = n > 1 && (force || ess_ < prm_.resample_threshold * n);
    if (rs) {
      if (prm_.roughening > 0.0) cloud_covariance<L>(xs_, n, Pcloud_);
      Rng rng;
      rng.seed(prm_.seed, cycle_ * 16 + stage_rng_++, 0, kRngResample);
      systematic_resample(w_.data(), n, rng.uniform(), idx_.data());
      for (int j = 0; j < n; ++j) xs_tmp_[j] = xs_[idx_[j]];
      xs_.swap(xs_tmp_);
      if (prm_.roughening > 0.0 && prm_.marginalize)
        roughen_nonlinear(Pcloud_, cycle_ * 16 + stage_rng_);
      else if (prm_.roughening > 0.0)
        repairs_ += roughen<L>(n, Pcloud_, prm_.roughening, prm_.seed, cycle_ * 16 + stage_rng_,
                               [&](int i) -> Vec& { return xs_[i]; });
      for (int i = 0; i < n; ++i) {
        logw_[i] = 0.0;
        w_[i] = 1.0 / n;
      }
      ++resamples_;
    } else {
      for (int i = 0; i < n; ++i) logw_[i] = std::log(std::max(w_[i], 1e-300));
    }
    if (trace_ && !force) trace_->record(ess_, 0.0, 1.0, rs);  // one record per epoch (the last stage)
  }

  ImuErrorModel model_;
  ParticleParams prm_;
  MacroStep<L> macro_;
  std::vector<Vec> xs_, xs_tmp_;
  std::vector<double> logw_, w_, ll_, tw_;
  Cov Pcloud_ = Cov::Zero();
  Vec sigma0_ = Vec::Zero();
  double cycle_dt_ = 0.0;
  int divergences_ = 0, reseeds_ = 0;
  std::uint64_t stage_rng_ = 0;
  std::vector<int> idx_;
  Vec x_ = Vec::Zero();
  Cov P_ = Cov::Identity();
  Cov Q_cycle_ = Cov::Zero(), sqrtQ_ = Cov::Zero(), work_ = Cov::Zero();
  Eigen::LLT<Dyn> lltR_{Dyn(0, 0)};
  Eigen::LLT<Dyn> lltS_{Dyn(0, 0)};
  SMat Ps_ = SMat::Zero(), Ps_work_ = SMat::Zero();
  std::vector<RowVec> innov_;
  ParticleTrace* trace_ = nullptr;
  std::uint64_t cycle_ = 0;
  int steps_ = 0;
  int repairs_ = 0;
  int resamples_ = 0;
  double ess_ = 0.0;
};

}  // namespace insnav
