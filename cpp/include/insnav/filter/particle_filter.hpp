// insnav/filter/particle_filter.hpp -- particle-filter building blocks
// (deterministic random numbers, weight normalisation, effective sample size,
// systematic resampling, the multi-interval RK4 step) and the bootstrap
// particle filter that seed 004 (Shao et al. 2013) compares against.
//
// Bootstrap PF (Gordon, Salmond, Smith 1993; seed 004 ref. [2]):
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
//               sigma per sqrt(hour): resampling shrinks the spread of the states
//               without process noise (random-constant gyro biases) every epoch,
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
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "insnav/check.hpp"
#include "insnav/filter/error_model_linear.hpp"
#include "insnav/filter/error_model_nonlinear.hpp"
#include "insnav/filter/layout20.hpp"
#include "insnav/filter/sigma_points.hpp"
#include "insnav/filter/types.hpp"

#ifdef _OPENMP
#include <omp.h>
/// Loops over particles run in parallel when compiled with -fopenmp.
#define INSNAV_PARALLEL_FOR _Pragma("omp parallel for schedule(static)")
#else
#define INSNAV_PARALLEL_FOR
#endif

namespace insnav {

// --- deterministic random numbers --------------------------------------------

inline std::uint64_t splitmix64(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

/// xoshiro256** (Blackman & Vigna 2018) with Box-Muller normals.
class Rng {
 public:
  Rng() { seed(0, 0, 0, 0); }
  /// A stream for (seed, cycle, particle, purpose): independent, reproducible.
  void seed(std::uint64_t seed, std::uint64_t cycle, std::uint64_t particle, std::uint64_t purpose) {
    std::uint64_t h = seed;
    h ^= splitmix64(h) + cycle * 0xD1B54A32D192ED03ULL;
    h ^= splitmix64(h) + particle * 0xABC98388FB8FAC03ULL;
    h ^= splitmix64(h) + purpose * 0x8CB92BA72F3D8DD7ULL;
    for (auto& w : s_) w = splitmix64(h);
    have_spare_ = false;
  }
  std::uint64_t next() {
    const std::uint64_t r = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return r;
  }
  /// Uniform on [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double normal() {
    if (have_spare_) {
      have_spare_ = false;
      return spare_;
    }
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * M_PI * u2);
    have_spare_ = true;
    return r * std::cos(2.0 * M_PI * u2);
  }
  template <class V>
  void fill_normal(V& v) {
    for (int i = 0; i < v.size(); ++i) v[i] = normal();
  }

 private:
  static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::uint64_t s_[4];
  double spare_ = 0.0;
  bool have_spare_ = false;
};

/// Stream purposes (any distinct constants).
enum RngPurpose : std::uint64_t {
  kRngInit = 1, kRngProcess = 2, kRngProposal = 3, kRngResample = 4, kRngJitter = 5, kRngTemper = 6
};

// --- weights -------------------------------------------------------------------

/// Normalise log-weights into weights summing to 1 (log-sum-exp); returns
/// false (and sets uniform weights) if every log-weight is -inf or NaN.
inline bool normalize_log_weights(const double* logw, double* w, int n) {
  double mx = -std::numeric_limits<double>::infinity();
  for (int i = 0; i < n; ++i)
    if (std::isfinite(logw[i])) mx = std::max(mx, logw[i]);
  if (!std::isfinite(mx)) {
    for (int i = 0; i < n; ++i) w[i] = 1.0 / n;
    return false;
  }
  double s = 0.0;
  for (int i = 0; i < n; ++i) {
    w[i] = std::isfinite(logw[i]) ? std::exp(logw[i] - mx) : 0.0;
    s += w[i];
  }
  for (int i = 0; i < n; ++i) w[i] /= s;
  return true;
}

/// Effective sample size N_eff = 1 / sum w_i^2 of normalised weights.
inline double effective_sample_size(const double* w, int n) {
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += w[i] * w[i];
  return s > 0.0 ? 1.0 / s : 0.0;
}

/// Systematic resampling (Kitagawa 1996): one uniform u0 in [0, 1/N), index
/// of the points u0 + j/N in the cumulative weights.  O(N); idx has n entries.
inline void systematic_resample(const double* w, int n, double u0_unit, int* idx) {
  const double step = 1.0 / n;
  double u = u0_unit * step, c = w[0];
  int i = 0;
  for (int j = 0; j < n; ++j) {
    while (u > c && i < n - 1) c += w[++i];
    idx[j] = i;
    u += step;
  }
}

// --- multi-interval RK4 step ------------------------------------------------------

/// Collects engine intervals into one RK4 step of about `step` seconds (see the
/// header comment).  Holds copies of the INS points (bounded array, no heap).
template <class L>
class MacroStep {
 public:
  static constexpr int kMaxPoints = 256;
  using Cov = StateCov<L>;

  MacroStep(const ImuErrorModel& model, double step) : model_(model), step_(step) {}

  void reset() { n_ = 0; t_ = 0.0; }
  bool pending() const { return n_ > 0; }
  double step() const { return step_; }

  /// Add one interval; true when a step is ready (then call prepare()).
  bool add(const InsInterval& iv) {
    if (!(iv.dt > 0.0)) return false;
    if (n_ == 0) start_ = iv.start;
    pts_[n_] = iv.mid;
    tp_[n_++] = t_ + 0.5 * iv.dt;
    t_ += iv.dt;
    pts_[n_] = iv.end;
    tp_[n_++] = t_;
    return step_ <= 0.0 || t_ >= step_ - 1e-9 || n_ + 2 > kMaxPoints;
  }

  /// Make the pending step ready: p0, ph, p1, dt, Phi, Q_d.  Clears the buffer.
  void prepare() {
    int mid = 0;
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < n_ - 1; ++i) {
      const double d = std::abs(tp_[i] - 0.5 * t_);
      if (d < best) {
        best = d;
        mid = i;
      }
    }
    a_ = start_;
    m_ = pts_[mid];
    b_ = pts_[n_ - 1];
    dt = t_;
    p0.set(a_, model_);
    ph.set(m_, model_);
    p1.set(b_, model_);
    phi = transition<L>(linear_F<L>(m_, model_), dt);
    qd = discrete_Q<L>(phi, continuous_GQG<L>(m_, model_), dt);
    reset();
  }

  NonlinearErrorPoint p0, ph, p1;
  double dt = 0.0;
  Cov phi = Cov::Identity(), qd = Cov::Zero();

 private:
  ImuErrorModel model_;
  double step_;
  InsPoint start_, a_, m_, b_;
  InsPoint pts_[kMaxPoints];
  double tp_[kMaxPoints] = {};
  int n_ = 0;
  double t_ = 0.0;
};

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
  double noise_floor = 3.0;         // PF: every state random-walks by this x its initial sigma per sqrt(h)
  double divergence_chi2 = 25.0;    // PF: divergence when no particle explains z within this chi^2 per row
};

/// Unweighted mean and covariance of a particle cloud (the shape of the
/// roughening kernel: unlike the weighted covariance it does not collapse
/// when one particle takes all the weight).
template <class L>
void cloud_covariance(const std::vector<StateVec<L>>& xs, int n, StateCov<L>& P) {
  StateVec<L> m = StateVec<L>::Zero();
  for (int i = 0; i < n; ++i) m += xs[i];
  m /= n;
  P.setZero();
  for (int i = 0; i < n; ++i) {
    const StateVec<L> d = xs[i] - m;
    P.noalias() += d * d.transpose();
  }
  P /= std::max(n - 1, 1);
}

// --- weighted estimate ----------------------------------------------------------

template <class L>
void weighted_mean_cov(const std::vector<StateVec<L>>& xs, const double* w, int n, StateVec<L>& x,
                       StateCov<L>& P) {
  x.setZero();
  for (int i = 0; i < n; ++i) x.noalias() += w[i] * xs[i];
  P.setZero();
  for (int i = 0; i < n; ++i) {
    const StateVec<L> d = xs[i] - x;
    P.noalias() += w[i] * d * d.transpose();
  }
}

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
    psd_cholesky_lower<kN>(Q_cycle_, sqrtQ_);
    const Vec floor = (prm_.noise_floor * std::sqrt(cycle_dt_ / 3600.0)) * sigma0_;
    cycle_dt_ = 0.0;
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
    const int m = lin.rows();
    res.rows = m;
    if (m == 0) return res;
    res.nis = estimate_nis<L>(meas, x_, P_);
    if (gate_chi2 > 0.0 && !(res.nis <= gate_chi2)) {
      res.rejected_by_gate = true;
      return res;
    }
    Dyn R = lin.R;
    Eigen::LLT<Dyn> lltR(R);
    if (lltR.info() != Eigen::Success) {
      res.cholesky_repairs = 1;
      ++repairs_;
      return res;
    }
    const int n = prm_.particles;
    double left = 1.0;
    for (int stage = 0; stage < std::max(prm_.temper_stages, 1) && left > 0.0; ++stage) {
      INSNAV_PARALLEL_FOR
      for (int i = 0; i < n; ++i) {
        RowVec e = lin.residual - meas.predicted_residual(xs_[i]);
        lltR.matrixL().solveInPlace(e);
        const double ll = -0.5 * e.squaredNorm();
        ll_[i] = std::isfinite(ll) ? ll : -std::numeric_limits<double>::infinity();
      }
      if (stage == 0) {
        double best = -std::numeric_limits<double>::infinity();
        for (int i = 0; i < n; ++i) best = std::max(best, ll_[i]);
        if (!(-2.0 * best <= prm_.divergence_chi2 * m)) ++divergences_;
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

  void run_step() {
    macro_.prepare();
    cycle_dt_ += macro_.dt;
    const int n = prm_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) rk4_error_step<L>(xs_[i], macro_.p0, macro_.ph, macro_.p1, macro_.dt);
    work_.noalias() = macro_.phi * Q_cycle_;
    Q_cycle_.noalias() = work_ * macro_.phi.transpose();
    Q_cycle_ += macro_.qd;
    ++steps_;
  }

  void estimate() { weighted_mean_cov<L>(xs_, w_.data(), prm_.particles, x_, P_); }

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
      if (prm_.roughening > 0.0) {
        repairs_ += cholesky_with_repair<kN>(Pcloud_, sqrtP_);
        sqrtP_ *= prm_.roughening;
        const std::uint64_t stream = cycle_ * 16 + stage_rng_;
    INSNAV_PARALLEL_FOR
        for (int i = 0; i < n; ++i) {
          Rng r;
          r.seed(prm_.seed, stream, i, kRngJitter);
          Vec xi;
          r.fill_normal(xi);
          xs_[i].noalias() += sqrtP_ * xi;
        }
      }
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
  int divergences_ = 0;
  std::uint64_t stage_rng_ = 0;
  std::vector<int> idx_;
  Vec x_ = Vec::Zero();
  Cov P_ = Cov::Identity();
  Cov Q_cycle_ = Cov::Zero(), sqrtQ_ = Cov::Zero(), sqrtP_ = Cov::Zero(), work_ = Cov::Zero();
  ParticleTrace* trace_ = nullptr;
  std::uint64_t cycle_ = 0;
  int steps_ = 0;
  int repairs_ = 0;
  int resamples_ = 0;
  double ess_ = 0.0;
};

}  // namespace insnav
