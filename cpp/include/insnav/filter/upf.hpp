// insnav/filter/upf.hpp -- the improved unscented particle filter of seed 004
// (Shao et al. 2013): a UKF per particle builds the importance density, with
// residual-constrained adaptive fading (fading.hpp); and the fading UKF alone.
//
// UKF step (per particle, and FadingUkf), seed 004 steps (2)-(5), eqs. (7)-(17):
//   sigma points  chi = [x, x +- cols(chol((n + lambda) P))]             (eqs. (7)-(8))
//   time update   every point through the exact nonlinear error model by RK4
//                 (error_model_nonlinear.hpp; multi-interval steps, see
//                 particle_filter.hpp), x^- = sum Wm chi, P^- = sum Wc (chi - x^-)(.)^T,
//                 process noise accumulated as Q_c = Phi Q_c Phi^T + Q_d  (eqs. (9)-(10))
//   fading        gamma = residual - h(x^-), eta = fading_factors(...)  (fading.hpp, eqs. (1)-(6));
//                 Pbar = Lambda^1/2 P^- Lambda^1/2 + Q_c, and the propagated points'
//                 deviations are scaled by Lambda^1/2 so they carry Pbar      (eq. (3))
//   measurement   the augmented-UT update of ukf.hpp (seed 000 eqs. (14)-(21)):
//                 points + (chi_0 +- cols(sqrt((n + lambda) Q_c))), z_i = h(X_i)
//                 (h = meas.predicted_residual, nonlinear pseudorange / rate),
//                 P_zz, P_xz, K = P_xz P_zz^-1 (llt().solve()),
//                 x^ = x^- + K (residual - z^), P^ = Pbar - K P_zz K^T     (eqs. (11)-(17))
// With the fading off this is exactly Ukf<L> (cpp/tests/test_upf.cpp checks it).
//
// UPF (seed 004 steps (1)-(7); van der Merwe, Doucet, de Freitas, Wan 2000),
// in its regularised Gaussian-mixture form:
//   particles i = 1..N each carry a Gaussian (x_i, P_i) and a log-weight;
//   1. each particle's UKF step above gives its posterior N(x^_i, P^_i) and
//      its predictive density of the measurement N(z; z^_i, P_zz,i);
//   2. weight (seed 004 eq. (18) in its marginal, Rao-Blackwellised form):
//      w_i *= N(residual; z^_i, P_zz,i), the particle's predictive likelihood.
//      It does not depend on a draw, so it carries no sampling noise, and it is
//      what the exact weight p(z | x) p(x | prior) / q(x | z) averages to over
//      the proposal when h is linear;
//   3. no draw: each particle keeps its UKF posterior (x^_i, P^_i), so the
//      particles form a Gaussian mixture (a Gaussian-sum filter of UKFs,
//      Alspach & Sorenson 1972, with particle-filter weights and resampling).
//      The earlier form drew x_i from N(x^_i, P^_i) and kept P_i = P^_i:
//      every particle then carried twice the spread its UKF believed, yaw and
//      the gyro biases random-walked with the sampling noise, and 100 such
//      particles lost to one UKF by 8-16x in position.  A jitter that keeps
//      the moments instead (x_i += h chol(P^) xi, P_i = (1 - h^2) P^, Liu & West
//      2001) fails differently: the states without process noise (the
//      random-constant gyro biases) lose a factor (1 - h^2) of variance every
//      epoch and the filter becomes overconfident (measured: h^2 = 0.1, 700 m);
//   4. normalise (eq. (19)); N_eff = 1 / sum w^2 (eq. (20));
//   5. if N_eff < threshold * N: systematic resampling (eqs. (21)-(22)); the
//      copies of one parent are separated by a draw from that parent's own
//      posterior scaled by h (x_j += h chol(P_j) xi, h^2 = kernel_h2; P_j kept):
//      regularisation shaped by the posterior (Musso, Oudjane, Le Gland 2001)
//      and only where resampling has removed diversity;
//   6. estimate (eq. (23)): x^ = sum w_i x_i; P^ = sum w_i (P_i + (x_i - x^)(x_i - x^)^T).
//   With N = 1, or kernel_h2 = 0 (every particle the same Gaussian), the UPF is
//   the UKF exactly (cpp/tests/test_upf.cpp); with N > 1 it is a weighted bank
//   of UKFs, so on a near-Gaussian problem it cannot do worse than one UKF by
//   more than the Monte Carlo spread of the kernel.
//   Initial particles: x_i = h chol(P0) xi, P_i = (1 - h^2) P0; or, for a
//   non-Gaussian start (init_yaw_halfwidth > 0: heading unknown within
//   +-halfwidth), yaw errors stratified uniformly over the interval with a yaw
//   sigma of one stratum -- the multi-modal prior a single Gaussian cannot hold.
//   No measurement in a cycle (GPS outage): every particle keeps its UKF
//   prediction (x_i = x^-_i, P_i = Pbar_i), weights unchanged, no jitter.
// Closed loop: the engine feeds x^ back and calls reset_state(), which shifts
// every particle by the fed-back part of x^ (x_i -= x^; Layout20's gyro Markov
// block is not fed back, layout20.hpp).
//
// Cost per particle and epoch: one Cholesky for the sigma points, 2n+1 RK4
// steps of the nonlinear model per rk4_step, 4n+1 + 2 evaluations of h, two
// more Choleskys (sampling, predictive density).  Fixed-size per particle; the
// vectors of particles and the per-thread workspaces are allocated once at
// construction.
#pragma once

#include <Eigen/Cholesky>
#include <cmath>
#include <limits>
#include <vector>

#include "insnav/filter/augmented_ut.hpp"
#include "insnav/filter/fading.hpp"
#include "insnav/filter/particle_filter.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/sigma_points.hpp"

namespace insnav {

/// One UKF's state: mean, covariance, its sigma points and fading memory.
template <class L>
struct UkfState {
  static constexpr int kN = L::kSize;
  StateVec<L> x = StateVec<L>::Zero();
  StateCov<L> P = StateCov<L>::Identity();
  StateCov<L> P_minus = StateCov<L>::Zero();  // propagated spread without Q (fading)
  SigmaPoints<kN> chi = SigmaPoints<kN>::Zero();
  FadingMemory fade;
  int steps = 0;
  bool in_cycle = false;
  bool fresh = false;  // chi are the propagated points of (x, P)
};

/// The UKF operations on a UkfState, with their workspace (one per thread).
template <class L>
class UkfKernel {
 public:
  static constexpr int kN = L::kSize;
  static constexpr int kAug = 4 * kN + 1;
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;
  using T = MeasTypes<L>;
  using AugPoints = Eigen::Matrix<double, kN, kAug>;

  explicit UkfKernel(const UtParams& ut = {}) : w_(ut) {}

  const UtWeights<kN>& weights() const { return w_; }

  /// Draw the sigma points of (x, P) (eq. (7)).  Returns repairs (0/1).
  int begin(UkfState<L>& s) {
    const int r = draw_sigma_points<kN>(s.x, s.P, w_, s.chi, factor_, repair_opt_);
    s.steps = 0;
    s.in_cycle = true;
    s.fresh = false;
    return r;
  }

  /// Advance every sigma point by one multi-interval RK4 step (eq. (9)).
  void step(UkfState<L>& s, const MacroStep<L>& ms) {
    for (int j = 0; j < 2 * kN + 1; ++j) {
      tmp_ = s.chi.col(j);
      rk4_error_step<L>(tmp_, ms.p0, ms.ph, ms.p1, ms.dt);
      s.chi.col(j) = tmp_;
    }
    ut_mean<kN, 2 * kN + 1>(s.chi, w_, s.x);  // running prediction (mid-cycle output)
    ++s.steps;
  }

  /// Predicted mean and covariance (eqs. (9)-(10)); Q = process noise of the cycle.
  int end(UkfState<L>& s, const Cov& Q) {
    if (!s.in_cycle) return 0;
    s.in_cycle = false;
    if (s.steps == 0) return 0;
    int repairs = 0;
    bool bad = false;
    for (int j = 0; j < 2 * kN + 1; ++j)
      if (!s.chi.col(j).allFinite()) {
        bad = true;
        if (j > 0 && s.chi.col(0).allFinite()) s.chi.col(j) = s.chi.col(0);
        else s.chi.col(j).setZero();
      }
    repairs += bad ? 1 : 0;
    ut_mean<kN, 2 * kN + 1>(s.chi, w_, s.x);
    ut_covariance<kN, 2 * kN + 1>(s.chi, s.x, w_, dev_, s.P_minus);
    s.P = s.P_minus + Q;
    symmetrize<kN>(s.P);
    if (!s.P.allFinite()) {
      repair_covariance<kN>(s.P, repair_opt_);
      s.P_minus = s.P;
      ++repairs;
    }
    s.fresh = true;
    return repairs;
  }

  /// Fading + augmented-UT measurement update (header comment).  After the
  /// call prior_x() / prior_P() hold x^- and Pbar (faded) of this update;
  /// c() and eta() the fading result.  gate_chi2 <= 0: no gating.
  template <class Meas>
  UpdateResult update(UkfState<L>& s, const Meas& meas, const Cov& Q_cycle, const FadingParams<kN>& fp,
                      double gate_chi2) {
    const LinearMeasurement<L>& lin = meas.linear();
    UpdateResult res;
    const int r = lin.rows();
    res.rows = r;
    c_ = 0.0;
    eta_.setOnes();
    if (r == 0) return res;

    // augmented points (ukf.hpp eq. (14))
    const bool fresh = s.fresh;
    if (fresh) {
      Qs_ = Q_cycle * w_.n_plus_lambda;
      psd_cholesky_lower<kN>(Qs_, sqrtQ_);
    } else {
      res.cholesky_repairs += draw_sigma_points<kN>(s.x, s.P, w_, s.chi, factor_, repair_opt_);
      sqrtQ_.setZero();
    }
    X_.template leftCols<2 * kN + 1>() = s.chi;
    xbar_ = s.x;
    Pbar_ = s.P;

    // adaptive fading (fading.hpp), applied to the propagated spread
    if (fp.enabled) {
      gamma_ = lin.residual - meas.predicted_residual(s.x);
      c_ = fading_factors<L>(gamma_, lin, fresh ? s.P_minus : s.P, fresh ? Q_cycle : zeroQ_, fp, s.fade, fws_,
                             eta_);
      if (eta_.maxCoeff() > 1.0) {
        const Vec d = eta_.cwiseSqrt();
        for (int j = 0; j < 2 * kN + 1; ++j) X_.col(j) = s.x + d.cwiseProduct(X_.col(j) - s.x);
        Pbar_ = d.asDiagonal() * (fresh ? s.P_minus : s.P) * d.asDiagonal();
        if (fresh) Pbar_ += Q_cycle;
        symmetrize<kN>(Pbar_);
      }
    }
    for (int i = 0; i < kN; ++i) {
      X_.col(2 * kN + 1 + i) = X_.col(0) + sqrtQ_.col(i);
      X_.col(3 * kN + 1 + i) = X_.col(0) - sqrtQ_.col(i);
    }
    s.fresh = false;
    // (ukf.hpp eqs. (15)-(21), augmented_ut.hpp) from the faded prior Pbar; s.P
    // changes only when the update is applied
    Ppost_ = Pbar_;
    const AugmentedUtStatus st = augmented_ut_update<L, Eigen::Dynamic>(X_, meas, w_, s.x, Ppost_, gate_chi2, ws_,
                                                                         res.nis);
    log_pred_ = ws_.log_predictive;
    if (st == AugmentedUtStatus::kNotPositiveDefinite) {
      res.cholesky_repairs += 1;
      return res;
    }
    if (st == AugmentedUtStatus::kRejectedByGate) {
      res.rejected_by_gate = true;
      return res;
    }
    s.P = Ppost_;
    if (!s.P.allFinite() || !s.x.allFinite()) {
      if (!s.x.allFinite()) s.x = xbar_;
      repair_covariance<kN>(s.P, repair_opt_);
      res.cholesky_repairs += 1;
    }
    res.applied = true;
    return res;
  }

  const Vec& prior_x() const { return xbar_; }
  const Cov& prior_P() const { return Pbar_; }
  /// log N(residual; z^, P_zz) of the last update, without the 2 pi constant.
  double log_predictive() const { return log_pred_; }
  double c() const { return c_; }
  const Vec& eta() const { return eta_; }

  // scratch used by the UPF per particle (thread-local through the kernel)
  Cov scratch_L = Cov::Zero(), scratch_P = Cov::Zero();
  Vec scratch_v = Vec::Zero();

 private:
  UtWeights<kN> w_;
  RepairOptions repair_opt_{};
  Cov factor_ = Cov::Zero(), Qs_ = Cov::Zero(), sqrtQ_ = Cov::Zero(), Pbar_ = Cov::Zero(), Ppost_ = Cov::Zero();
  Cov zeroQ_ = Cov::Zero();
  SigmaPoints<kN> dev_ = SigmaPoints<kN>::Zero();
  typename AugmentedUtWorkspace<L>::Points X_ = AugPoints::Zero();
  AugmentedUtWorkspace<L> ws_;  // its LLT is initialised: kernels are copied
  Vec tmp_ = Vec::Zero(), xbar_ = Vec::Zero(), eta_ = Vec::Ones();
  typename T::RowVec gamma_;
  FadingWorkspace<L> fws_;
  double c_ = 0.0, log_pred_ = 0.0;
};

/// The UKF with residual-constrained adaptive fading (seed 004 without the
/// particles).  FadingParams::enabled = false gives the plain UKF (= Ukf<L>
/// for rk4_step = 0) -- the seed 004 "UKF" baseline.
template <class L>
class FadingUkf {
 public:
  using Layout = L;
  static constexpr int kN = L::kSize;
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;

  FadingUkf(const ImuErrorModel& model, const UtParams& ut = {}, const FadingParams<kN>& fp = {},
            double rk4_step = 0.0)
      : kernel_(ut), fp_(fp), macro_(model, rk4_step) {}

  void set_trace(ParticleTrace* t) { trace_ = t; }
  FadingParams<kN>& fading() { return fp_; }

  void initialize(const Cov& P0) {
    s_ = UkfState<L>{};
    s_.P = P0;
    symmetrize<kN>(s_.P);
    Q_.setZero();
    macro_.reset();
  }
  void begin_cycle() {
    repairs_ += kernel_.begin(s_);
    Q_.setZero();
    macro_.reset();
  }
  void propagate(const InsInterval& iv) {
    if (!s_.in_cycle) begin_cycle();
    if (macro_.add(iv)) run_step();
  }
  void end_cycle() {
    if (macro_.pending()) run_step();
    repairs_ += kernel_.end(s_, Q_);
  }
  template <class Meas>
  UpdateResult update(const Meas& meas, double gate_chi2) {
    UpdateResult r = kernel_.update(s_, meas, Q_, fp_, gate_chi2);
    repairs_ += r.cholesky_repairs;
    if (trace_ && r.applied) trace_->record(1.0, kernel_.c(), kernel_.eta().maxCoeff(), false);
    return r;
  }

  const Vec& x() const { return s_.x; }
  const Cov& P() const { return s_.P; }
  Cov& P_mutable() { return s_.P; }
  Vec& x_mutable() {
    s_.fresh = false;
    return s_.x;
  }
  void reset_state() {
    zero_fed_back<L>(s_.x);
    s_.fresh = false;
  }
  int cholesky_repairs() const { return repairs_; }
  const UkfState<L>& state() const { return s_; }
  const UkfKernel<L>& kernel() const { return kernel_; }
  const Cov& cycle_Q() const { return Q_; }

 private:
  void run_step() {
    macro_.prepare();
    kernel_.step(s_, macro_);
    work_.noalias() = macro_.phi * Q_;
    Q_.noalias() = work_ * macro_.phi.transpose();
    Q_ += macro_.qd;
  }

  UkfKernel<L> kernel_;
  FadingParams<kN> fp_;
  MacroStep<L> macro_;
  UkfState<L> s_;
  Cov Q_ = Cov::Zero(), work_ = Cov::Zero();
  ParticleTrace* trace_ = nullptr;
  int repairs_ = 0;
};

/// Settings of the UPF beyond ParticleParams.
struct UpfOptions {
  bool sample = true;             // false: no kernel jitter (x_i = UKF posterior mean; tests)
  double kernel_h2 = 0.1;         // h^2: copies after resampling jitter by h chol(P) and at the start (see header)
  double init_yaw_halfwidth = 0;  // [rad] > 0: yaw errors stratified uniformly over +-halfwidth
};

/// The improved unscented particle filter of seed 004 (header comment).
template <class L>
class Upf {
 public:
  using Layout = L;
  static constexpr int kN = L::kSize;
  using Vec = StateVec<L>;
  using Cov = StateCov<L>;

  /// The engines construct filters from (model, ut); a run then assigns a
  /// fully configured Upf (engine.filter() = Upf(model, ut, pp, fp)).
  explicit Upf(const ImuErrorModel& model, const UtParams& ut = {})
      : Upf(model, ut, ParticleParams{}, FadingParams<kN>{}) {}

  Upf(const ImuErrorModel& model, const UtParams& ut, const ParticleParams& pp, const FadingParams<kN>& fp,
      const UpfOptions& opt = {})
      : pp_(pp), fp_(fp), opt_(opt), macro_(model, pp.rk4_step) {
    INSNAV_CHECK(pp.particles >= 1 && pp.particles <= pp.max_particles, "particle count out of range");
    const int n = pp.particles;
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    kernels_.assign(threads, UkfKernel<L>(ut));
    ps_.assign(n, UkfState<L>{});
    ps_tmp_.assign(n, UkfState<L>{});
    means_.assign(n, Vec::Zero());
    logw_.assign(n, 0.0);
    w_.assign(n, 1.0 / n);
    idx_.assign(n, 0);
    c_.assign(n, 0.0);
    etamax_.assign(n, 1.0);
    rep_.assign(n, 0);
  }

  void set_trace(ParticleTrace* t) { trace_ = t; }

  /// Every particle starts at x = 0 with P0 (the mixture of N identical
  /// Gaussians is the prior exactly); the first draw creates the diversity.
  void initialize(const Cov& P0) {
    const int n = pp_.particles;
    const double h2 = (n > 1 && opt_.sample) ? opt_.kernel_h2 : 0.0;
    Cov S = P0, L0;
    symmetrize<kN>(S);
    repairs_ += cholesky_with_repair<kN>(S, L0);
    const double hw = opt_.init_yaw_halfwidth;
    for (int i = 0; i < n; ++i) {
      ps_[i] = UkfState<L>{};
      ps_[i].P = P0;
      symmetrize<kN>(ps_[i].P);
      if (n > 1 && hw > 0.0) {
        // stratified uniform yaw over [-hw, hw], one stratum wide each
        const int a = L::kAtt + 2;
        const double width = 2.0 * hw / n;
        ps_[i].x[a] = -hw + width * (i + 0.5);
        ps_[i].P.row(a).setZero();
        ps_[i].P.col(a).setZero();
        ps_[i].P(a, a) = width * width / 3.0;
      } else if (h2 > 0.0) {
        Rng rng;
        rng.seed(pp_.seed, 0, i, kRngInit);
        Vec xi;
        rng.fill_normal(xi);
        ps_[i].x.noalias() = std::sqrt(h2) * (L0 * xi);
        ps_[i].P *= 1.0 - h2;
      }
      logw_[i] = 0.0;
      w_[i] = 1.0 / n;
    }
    cycle_ = 0;
    Q_.setZero();
    macro_.reset();
    estimate();
  }

  void begin_cycle() {
    ++cycle_;
    Q_.setZero();
    macro_.reset();
    in_cycle_ = true;
    const int n = pp_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) rep_[i] += kernel().begin(ps_[i]);
  }

  void propagate(const InsInterval& iv) {
    if (!in_cycle_) begin_cycle();
    if (macro_.add(iv)) run_step();
  }

  void end_cycle() {
    if (!in_cycle_) return;
    in_cycle_ = false;
    if (macro_.pending()) run_step();
    const int n = pp_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) rep_[i] += kernel().end(ps_[i], Q_);
    estimate();
  }

  template <class Meas>
  UpdateResult update(const Meas& meas, double gate_chi2) {
    UpdateResult res;
    if (!update_admitted<L>(meas, x_, P_, gate_chi2, lltR_, res)) {
      repairs_ += res.cholesky_repairs;
      return res;
    }
    const int n = pp_.particles;
    const double ninf = -std::numeric_limits<double>::infinity();
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) {
      UkfKernel<L>& k = kernel();
      UkfState<L>& s = ps_[i];
      const UpdateResult ri = k.update(s, meas, Q_, fp_, 0.0);
      rep_[i] += ri.cholesky_repairs;
      c_[i] = k.c();
      etamax_[i] = k.eta().maxCoeff();
      if (!ri.applied) {  // P_zz not positive definite for this particle
        logw_[i] = ninf;
        continue;
      }
      // marginal weight: the particle's predictive likelihood (header, step 2)
      const double inc = k.log_predictive();
      logw_[i] += std::isfinite(inc) ? inc : ninf;
    }
    finish_update();
    res.applied = true;
    return res;
  }

  const Vec& x() const { return x_; }
  const Cov& P() const { return P_; }
  void reset_state() {
    const int n = pp_.particles;
    for (int i = 0; i < n; ++i) {
      subtract_fed_back<L>(ps_[i].x, x_);
      ps_[i].fresh = false;
    }
    zero_fed_back<L>(x_);
  }
  int cholesky_repairs() const {
    int r = repairs_;
    for (int v : rep_) r += v;
    return r;
  }
  int particles() const { return pp_.particles; }
  const std::vector<UkfState<L>>& particle_states() const { return ps_; }
  const std::vector<double>& weights() const { return w_; }
  double last_ess() const { return ess_; }
  int resample_count() const { return resamples_; }

 private:
  using Dyn = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasRows, kMaxMeasRows>;
  using RowVec = typename LinearMeasurement<L>::RowVec;

  UkfKernel<L>& kernel() {
#ifdef _OPENMP
    return kernels_[omp_get_thread_num()];
#else
    return kernels_[0];
#endif
  }

  void run_step() {
    macro_.prepare();
    const int n = pp_.particles;
    INSNAV_PARALLEL_FOR
    for (int i = 0; i < n; ++i) kernel().step(ps_[i], macro_);
    work_.noalias() = macro_.phi * Q_;
    Q_.noalias() = work_ * macro_.phi.transpose();
    Q_ += macro_.qd;
  }

  /// x^ = sum w x_i, P^ = sum w (P_i + (x_i - x^)(x_i - x^)^T)  (eq. (23)).
  void estimate() {
    const int n = pp_.particles;
    x_.setZero();
    for (int i = 0; i < n; ++i) x_.noalias() += w_[i] * ps_[i].x;
    P_.setZero();
    for (int i = 0; i < n; ++i) {
      d_ = ps_[i].x - x_;
      P_.noalias() += w_[i] * (ps_[i].P + d_ * d_.transpose());
    }
  }

  void finish_update() {
    const int n = pp_.particles;
    normalize_log_weights(logw_.data(), w_.data(), n);
    ess_ = effective_sample_size(w_.data(), n);
    estimate();
    double cm = 0.0, em = 0.0;
    for (int i = 0; i < n; ++i) {
      cm += w_[i] * c_[i];
      em += w_[i] * etamax_[i];
    }
    const bool rs = n > 1 && ess_ < pp_.resample_threshold * n;
    if (rs) {
      Rng rng;
      rng.seed(pp_.seed, cycle_, 0, kRngResample);
      systematic_resample(w_.data(), n, rng.uniform(), idx_.data());
      for (int j = 0; j < n; ++j) ps_tmp_[j] = ps_[idx_[j]];
      ps_.swap(ps_tmp_);
      // copies of one parent separate by a draw from their own posterior,
      // scaled by h (header, step 5); the first copy stays where it was
      const double h2 = opt_.sample ? opt_.kernel_h2 : 0.0;
      if (h2 > 0.0) {
        INSNAV_PARALLEL_FOR
        for (int j = 1; j < n; ++j) {
          if (idx_[j] != idx_[j - 1]) continue;
          UkfKernel<L>& k = kernel();
          k.scratch_P = ps_[j].P;
          rep_[j] += cholesky_with_repair<kN>(k.scratch_P, k.scratch_L);
          Rng rng;
          rng.seed(pp_.seed, cycle_, j, kRngProposal);
          rng.fill_normal(k.scratch_v);
          ps_[j].x.noalias() += std::sqrt(h2) * (k.scratch_L * k.scratch_v);
          ps_[j].fresh = false;
        }
      }
      if (pp_.roughening > 0.0) {
        for (int i = 0; i < n; ++i) means_[i] = ps_[i].x;
        cloud_covariance<L>(means_, n, Pcloud_);
        repairs_ += roughen<L>(n, Pcloud_, pp_.roughening, pp_.seed, cycle_, [&](int i) -> Vec& { return ps_[i].x; });
      }
      for (int i = 0; i < n; ++i) {
        logw_[i] = 0.0;
        w_[i] = 1.0 / n;
      }
      ++resamples_;
    } else {
      for (int i = 0; i < n; ++i) logw_[i] = std::log(std::max(w_[i], 1e-300));
    }
    if (trace_) trace_->record(ess_, cm, em, rs);
  }

  ParticleParams pp_;
  FadingParams<kN> fp_;
  UpfOptions opt_;
  MacroStep<L> macro_;
  std::vector<UkfKernel<L>> kernels_;
  std::vector<UkfState<L>> ps_, ps_tmp_;
  std::vector<Vec> means_;
  Cov Pcloud_ = Cov::Zero();
  std::vector<double> logw_, w_, c_, etamax_;
  std::vector<int> idx_, rep_;
  Vec x_ = Vec::Zero(), d_ = Vec::Zero();
  Cov P_ = Cov::Identity(), Q_ = Cov::Zero(), work_ = Cov::Zero();
  Eigen::LLT<Dyn> lltR_{Dyn(0, 0)};
  ParticleTrace* trace_ = nullptr;
  std::uint64_t cycle_ = 0;
  int repairs_ = 0, resamples_ = 0;
  double ess_ = 0.0;
  bool in_cycle_ = false;
};

}  // namespace insnav
