// insnav/filter/adaptive_noise.hpp -- innovation-based adaptive measurement
// noise of the loose GNSS rows (covariance matching; Mohamed & Schwarz 1999,
// "Adaptive Kalman filtering for INS/GPS", J. Geodesy 73:193-203: the
// innovation-based adaptive estimation of R, R^ = C_v - H P- H^T with C_v the
// innovation covariance over a window of the last N updates).
//
// Form used here, per row i of a fix (position N, E, D, velocity N, E, D; the
// diagonal of R only), over the last N applied updates j that had that row:
//
//   d_j   = y_j,i^2 - (H P-_j H^T)_ii     (each record's own H P- H^T)
//   lambda_i = sum_j d_j / sum_j R0_j,ii  (R0: the configured R of record j)
//   R_k,ii   = clamp(lambda_i, f, 1) R0_k,ii
//
// For a consistent filter E[y_j,i^2] = (H P-_j H^T)_ii + R_j,ii, so with a
// constant configured R the ratio times R0 is the paper's windowed estimate,
// except that each record's H P- H^T is subtracted instead of the current
// one's (unbiased when P- changes within the window, e.g. a walker stopping);
// the ratio to the configured R carries the estimate over to records whose
// data sigmas differ (receiver sigmas, motion-dependent sigmas).
//   * Only past records enter R_k (not y_k itself): R_k is then independent
//     of y_k, so the NIS and the innovation likelihood of record k keep their
//     chi-square / Gaussian meaning (the paper's window includes y_k).
//   * Lower clamp f R0 (f = min_fraction > 0): the windowed difference is
//     negative whenever H P- H^T overestimates the innovations (a small
//     window, or a process noise set too large); R never reaches zero.
//   * Upper clamp R0: a window of large innovations (a fault, a filter that
//     has not converged, a process noise set too small: all put the excess
//     into C_v) never inflates R beyond the configured value, so the adaptive
//     filter is never less confident in the fixes than the configured one
//     and the innovation gate keeps its meaning.  Measurement noise larger
//     than configured is then not followed: R stays R0 (documented limit).
//   * Until a row has N records, R = R0.
//   * Records the gate rejected do not enter the window.
//
//
// Why the innovation form and not the paper's residual form R = C_r + H P+ H^T
// (its eq. (28), which gnss/rtk.hpp uses for the code rows): the post-fit
// residuals and P+ both depend on the R being estimated (a fixed point that
// moves slowly when H P- H^T is comparable to R, the case of the loose walk),
// whereas y_j and P-_j depend only on the past; the residual form's advantage,
// an estimate that stays positive, is had here from the lower clamp.
//
// The same windowed ratio serves the adaptive process noise of the EKF
// (AdaptiveProcessNoise below; engine/loose_engine.hpp, LooseConfig::adaptive_q,
// and engine/tight_engine.hpp, TightConfig::adaptive_q): Mohamed & Schwarz 1999
// estimate Q from the state corrections dx = K y of the last N updates (their
// innovation-based adaptive Q, Q^ = K C_v K^T, C_v the windowed innovation
// covariance).  Used here as one scale per block of the configured Q
// (velocity random walk, angle random walk), matched against the correction
// covariance the filter predicts, K S K^T = P- - P+:
//
//   alpha_b = sum_j alpha_b,j |dx_j,b|^2 / sum_j tr(P-_j - P+_j)_bb,   clamp(alpha_b, q_min, q_max)
//
// (alpha_b,j the factor record j ran with).  A consistent filter has
// E[dx dx^T] = K S K^T whatever its transition, so the ratio is 1 there and
// the factor stays; corrections smaller than predicted (P- too large, e.g. a
// process noise tuned on walking while the walker stands) lower it.  The
// paper's direct form, Q^ = mean dx dx^T against Q dt, holds only for states
// that are a random walk observed directly; in the INS the velocity
// corrections also carry the attitude and bias growth (on a simulated
// tactical-grade mover it gave 20-100x the true velocity random walk).  The
// estimate feeds back through the gain, so both bounds are needed: q_min
// keeps the filter from collapsing when R alone exceeds the innovations.
//
// Fixed-size ring buffers (capacity kMaxAdaptiveWindow per row), no heap.
#pragma once

#include <algorithm>
#include <array>
#include <type_traits>
#include <utility>

#include "insnav/filter/types.hpp"

namespace insnav {

/// Largest window of the adaptive measurement noise [records].
inline constexpr int kMaxAdaptiveWindow = 256;

struct AdaptiveNoiseConfig {
  int window = 0;              // N: records per row in the window (0: off, the configured R)
  double min_fraction = 0.01;  // f: lower clamp of R as a fraction of the configured R (variance)
  double max_factor = 1.0;     // upper clamp of the factor (R: 1, the configured R; Q: q_max)
};

/// The windowed innovation statistics of `kRows` measurement channels (loose
/// GNSS: 6, position N, E, D and velocity N, E, D) and the R they give.
template <int kRows = 6>
class AdaptiveMeasurementNoise {
 public:
  AdaptiveMeasurementNoise() = default;
  explicit AdaptiveMeasurementNoise(const AdaptiveNoiseConfig& cfg) : cfg_(cfg) {
    cfg_.window = std::clamp(cfg_.window, 0, kMaxAdaptiveWindow);
  }

  bool enabled() const { return cfg_.window > 0; }
  const AdaptiveNoiseConfig& config() const { return cfg_; }

  /// Forget every record (the start of a run).
  void reset() {
    for (Channel& c : ch_) c.count = c.head = 0;
  }

  /// The factor on the configured variance of channel ch: clamp(lambda, f,
  /// max_factor) once the window is full, else 1.
  double factor(int ch) const {
    const Channel& c = ch_[ch];
    if (!enabled() || c.count < cfg_.window) return 1.0;
    double sd = 0.0, sr = 0.0;
    for (int j = 0; j < c.count; ++j) {
      sd += c.d[j];
      sr += c.r0[j];
    }
    if (!(sr > 0.0)) return 1.0;
    return std::clamp(sd / sr, cfg_.min_fraction, cfg_.max_factor);
  }

  /// Add a record of channel ch: innovation y, (H P- H^T)_ii = hph, configured variance r0.
  void push(int ch, double y, double hph, double r0) { push_ratio(ch, y * y - hph, r0); }

  /// Add a record of channel ch to the windowed ratio sum(num) / sum(den).
  void push_ratio(int ch, double num, double den) {
    Channel& c = ch_[ch];
    c.d[c.head] = num;
    c.r0[c.head] = den;
    c.head = (c.head + 1) % cfg_.window;
    if (c.count < cfg_.window) ++c.count;
  }

 private:
  struct Channel {
    std::array<double, kMaxAdaptiveWindow> d{}, r0{};
    int count = 0, head = 0;
  };
  AdaptiveNoiseConfig cfg_;
  std::array<Channel, kRows> ch_{};
};

/// The filter takes a process-noise scale (Ekf::set_process_noise_scale).
template <class F, class = void>
inline constexpr bool kScalableQ = false;
template <class F>
inline constexpr bool kScalableQ<F, std::void_t<decltype(std::declval<F&>().set_process_noise_scale(1.0, 1.0))>> =
    true;

/// The adaptive process noise of an EKF (Mohamed & Schwarz 1999, K C_v K^T
/// against K S K^T; the form in the header comment): one factor on the
/// configured velocity random walk and one on the angle random walk, each the
/// windowed ratio of the squared state corrections of the past applied
/// updates to the traces of P- - P+ of the velocity / attitude blocks.  The
/// engines (loose and tight) call, per update:
///   before_update(f)            P- traces (after any R adaptation or screening)
///   after_update(f)             if the update was applied, before the feedback
/// and start(f) at the start of a run.  Fixed size, no heap.
class AdaptiveProcessNoise {
 public:
  AdaptiveProcessNoise() = default;
  explicit AdaptiveProcessNoise(const AdaptiveNoiseConfig& cfg) : window_(cfg) {}

  bool enabled() const { return window_.enabled(); }

  /// Forget every record; the filter back on the configured Q (factors 1, 1).
  template <class Filter>
  void start(Filter& f) {
    window_.reset();
    if constexpr (kScalableQ<Filter>) {
      if (enabled()) f.set_process_noise_scale(1.0, 1.0);
    }
    scale_ = {1.0, 1.0};
  }

  /// Keep tr P- of the velocity and attitude blocks (call just before the update).
  template <class Filter>
  void before_update(const Filter& f) {
    using L = typename Filter::Layout;
    if constexpr (kScalableQ<Filter>) {
      if (enabled())
        tr_prior_ = {f.P().template block<3, 3>(L::kVel, L::kVel).trace(),
                     f.P().template block<3, 3>(L::kAtt, L::kAtt).trace()};
    }
  }

  /// The state correction of the update just applied (x before the feedback)
  /// into the window against the correction covariance the update predicted,
  /// K S K^T = P- - P+; the filter's Q scaled by the windowed ratio.
  template <class Filter>
  void after_update(Filter& f) {
    using L = typename Filter::Layout;
    if constexpr (kScalableQ<Filter>) {
      if (!enabled()) return;
      const auto& x = f.x();
      const auto& P = f.P();
      const double ksk_v = tr_prior_[0] - P.template block<3, 3>(L::kVel, L::kVel).trace();
      const double ksk_a = tr_prior_[1] - P.template block<3, 3>(L::kAtt, L::kAtt).trace();
      if (ksk_v > 0.0) window_.push_ratio(0, scale_[0] * x.template segment<3>(L::kVel).squaredNorm(), ksk_v);
      if (ksk_a > 0.0) window_.push_ratio(1, scale_[1] * x.template segment<3>(L::kAtt).squaredNorm(), ksk_a);
      scale_ = {window_.factor(0), window_.factor(1)};
      f.set_process_noise_scale(scale_[0], scale_[1]);
    }
  }

  /// The current factors (velocity, attitude random walk variances; 1, 1 when off).
  const std::array<double, 2>& scale() const { return scale_; }

  /// The filter's Q scale: these factors times `standstill_scale` while `still` (the walker's or
  /// vehicle's standstill level of the process noise).  Nothing is touched when `standstill_scale`
  /// is 1 (after_update, if on, has set the factors), so a run without the level is unchanged bit
  /// for bit.
  template <class Filter>
  void apply_standstill(Filter& f, double standstill_scale, bool still) const {
    if constexpr (kScalableQ<Filter>) {
      if (standstill_scale == 1.0) return;
      const double k = still ? standstill_scale : 1.0;
      f.set_process_noise_scale(scale_[0] * k, scale_[1] * k);
    }
  }

 private:
  AdaptiveMeasurementNoise<2> window_;  // channels: velocity, attitude random walk
  std::array<double, 2> scale_{1.0, 1.0};
  std::array<double, 2> tr_prior_{};  // tr P- of the velocity and attitude blocks before the update
};

/// The diagonal of H P H^T of a linear measurement (its first n_cols columns).
template <class L>
typename LinearMeasurement<L>::RowVec hph_diagonal(const LinearMeasurement<L>& lin, const StateCov<L>& P) {
  typename LinearMeasurement<L>::RowVec out(lin.rows());
  const int c = lin.n_cols;
  for (int i = 0; i < lin.rows(); ++i) {  // plain loops: no temporaries of dynamic size
    double s = 0.0;
    for (int a = 0; a < c; ++a) {
      const double ha = lin.H(i, a);
      if (ha == 0.0) continue;
      double row = 0.0;
      for (int b = 0; b < c; ++b) row += P(a, b) * lin.H(i, b);
      s += ha * row;
    }
    out[i] = s;
  }
  return out;
}

}  // namespace insnav
