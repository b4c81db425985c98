// insnav/gnss/rtk.hpp -- carrier-phase relative positioning (RTK): double differences,
// a float EKF with single-differenced ambiguities, cycle-slip detection and integer
// ambiguity resolution (MLAMBDA, ratio test, partial AR, fix-and-hold).
//
// Frames and units: e = ECEF (WGS-84), SI throughout; carrier phase in cycles,
// pseudorange in metres, Doppler in Hz, ambiguities in cycles.
//
// Models (P. J. G. Teunissen, O. Montenbruck (eds.), Springer Handbook of GNSS,
// 2017, ch. 26 "Differential positioning" eqs. (26.9)-(26.17); T. Takasu,
// RTKLIB 2.4.2 manual, Appendix E.7 "Relative positioning"):
//
//   zero difference   phi_r^s lambda = rho_r^s - c dt^s + T_r^s + lambda N_r^s + c dt_r + e
//                     P_r^s          = rho_r^s - c dt^s + T_r^s               + c dt_r + e
//   range with Sagnac rho = |r^s - r_r| + omega_e (x^s y_r - y^s x_r) / c  (r^s at transmission,
//                     ECEF of that instant; RTKLIB manual eq. (E.3.8b))
//   single difference (rover r - base b) removes the satellite clock; the state holds
//                     single-differenced ambiguities N_rb^s [cycles] (one per satellite and
//                     frequency), so satellites rise, set and slip independently.
//   double difference (satellite s - reference satellite i of the same system and frequency)
//                     removes the receiver clocks:
//                     DD phi = DD rho + lambda_s N_rb^s - lambda_i N_rb^i   [m]
//                     (written per satellite wavelength, which also serves GLONASS FDMA).
//   covariance        Cov(DD) = D diag(sigma_sd^2) D^T: sigma_sd^2(s) = sigma^2(el_r) + sigma^2(el_b),
//                     sigma^2(el) = a^2 + b^2 / sin^2 el (the SPP elevation weighting), code
//                     sigma = code_phase_ratio x phase sigma; rows that share a reference are
//                     correlated by sigma_sd^2(i).
//   troposphere       Saastamoinen zenith delay of a standard atmosphere with a 1/sin(el) mapping at
//                     each receiver (cancels to the height difference on short baselines).
//   ionosphere        (iono_mode) kOff: none; kVariance: the residual ionosphere of a medium baseline
//                     enters as a variance (iono_sigma_per_10km_m x baseline / 10 km)^2 per double
//                     difference; kEstimate: one single-differenced slant ionosphere state per satellite,
//                     I_rb^s [m] = the rover-minus-base delay at the reference frequency f_0 = 1575.42 MHz,
//                     entering frequency k as -mu_k I (phase) and +mu_k I (code), mu_k = (f_0 / f_k)^2
//                     (Springer Handbook of GNSS eq. (26.9); RTKLIB manual eq. (E.7.20), option
//                     pos1-ionoopt=est-stec).  The ionosphere-weighted model (D. Odijk, "Fast precise GPS
//                     positioning in the presence of ionospheric delays", PhD thesis, TU Delft 2002,
//                     sec. 4.2; P. J. G. Teunissen, "The ionosphere-weighted GPS baseline precision in
//                     canonical form", J. Geodesy 72 (1998) 107-117): the pseudo-observation I = 0 with
//                     sigma_I(bl, el) = iono_sigma_per_10km_m x bl / 10 km x M(el), M the single-layer
//                     mapping 1 / sqrt(1 - (R cos el / (R + 350 km))^2), is the prior of a new state and
//                     the stationary variance of its first-order Gauss-Markov process,
//                         I_k = phi I_{k-1} + w,  phi = exp(-dt / iono_tau_s),  var w = sigma_I^2 (1 - phi^2)
//                     (PSD 2 sigma_I^2 / tau, growing with bl^2), so that single-frequency data stay
//                     solvable (the code-minus-phase divergence 2 mu I separates I from N over time).
//
// Ambiguity resolution: MLAMBDA (insnav/gnss/lambda.hpp; Chang, Yang and Zhou 2005) on the
// double-differenced ambiguities D x_N, Q_a = D P_NN D^T; ratio test s2/s1 >= threshold
// (Teunissen & Verhagen 2009, "The GNSS ambiguity ratio-test revisited"); on failure partial
// AR drops the largest-variance (or the lowest-elevation) ambiguity and retries down to
// min_fix_ambiguities; a set that passes is validated further (gnss/ambiguity_resolution.hpp:
// bootstrapped success rate in PartialAr; number fixed and confirmation over epochs in
// FixValidator); the fixed baseline is x_b = x_b - Q_ba Q_a^{-1} (a_hat - a_fix)
// (Teunissen 1995, eq. (6)).  Optional float-model terms for receivers noisier than configured:
// time-correlated code (code_corr_time_s), an adaptive code variance factor (code_scale_gain), the
// ambiguity random walk (amb_psd) and time-correlated phase errors (phase_corr_time_s with
// phase_error_ratio > 0: one first-order Gauss-Markov state b [m] per ambiguity slot, + (b^s - b^i) on
// a DD phase row, stationary variance phase_error_ratio^2 sigma_sd^2(s), started at 0 with it when its
// ambiguity is (re)initialised; state augmentation, A. Gelb (ed.), Applied Optimal Estimation, 1974,
// sec. 4.5; the RTK/INS engine's model, engine/rtk_ins_engine.hpp; ratio 0: the variance factor
// phase_var_factor instead).
//
// Cycle slips (per receiver, before differencing): loss-of-lock indicator; the geometry-free
// combination lambda_1 phi_1 - lambda_2 phi_2 jumping by more than gf_threshold_m between
// epochs; the Melbourne-Wuebbena wide-lane (Melbourne 1985, Wuebbena 1985) leaving its running
// mean by more than mw_threshold_cycles; and, on every frequency, the Doppler-predicted phase
// phi_k - phi_{k-1} + (D_k + D_{k-1}) dt / 2 (receiver clock removed as the median over
// satellites) beyond doppler_threshold_cycles when dt <= doppler_max_dt_s.
//
// No heap allocation per epoch: every matrix is bounded (kMaxStates, kMaxRows) and lives in the
// engine, which is allocated once (on the heap: its covariance exceeds Eigen's default 128 KiB
// limit of fixed-capacity objects, raised by the insnav_core CMake target or below).
#pragma once

#ifndef EIGEN_STACK_ALLOCATION_LIMIT
#define EIGEN_STACK_ALLOCATION_LIMIT 1048576
#endif
#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "insnav/earth/wgs84.hpp"
#include "insnav/gnss/ambiguity_resolution.hpp"
#include "insnav/gnss/broadcast_orbit.hpp"
#include "insnav/gnss/double_difference.hpp"
#include "insnav/gnss/lambda.hpp"

namespace insnav::gnss {

// kCLight: broadcast_orbit.hpp
inline constexpr double kOmegaE = kOmegaEDotGps;  // IS-GPS Earth rate [rad/s] (Sagnac term)

inline constexpr int kMaxAmbStates = 120; // tracked single-differenced ambiguities
inline constexpr int kMaxIonoStates = 64;  // tracked single-differenced ionosphere states (iono_mode kEstimate)
inline constexpr int kMaxStates = 6 + 2 * kMaxAmbStates + kMaxIonoStates;
static_assert(EIGEN_STACK_ALLOCATION_LIMIT == 0 || EIGEN_STACK_ALLOCATION_LIMIT >= kMaxStates * kMaxStates * 8,
              "insnav/gnss/rtk.hpp: define EIGEN_STACK_ALLOCATION_LIMIT >= 1048576 before including Eigen "
              "(the insnav_core CMake target does)");
inline constexpr double kIonoRefFreqHz = 1575.42e6;  // f_0 of the ionosphere states (GPS L1)
inline constexpr double kIonoShellHeightM = 350e3;   // single-layer height of the mapping function
inline constexpr int kMaxRows = kMaxAmbStates;  // DD rows of one kind (phase and code are updated in turn)

/// State layout: position, velocity (kinematic), single-differenced ambiguities [cycles],
/// single-differenced slant ionosphere delays at kIonoRefFreqHz [m] (iono_mode kEstimate), then one
/// correlated phase error [m] per ambiguity slot (phase_error_states()).
struct RtkLayout {
  static constexpr int kPos = 0;
  static constexpr int kVel = 3;
  static constexpr int kAmb = 6;
  static constexpr int kIono = kAmb + kMaxAmbStates;
  static constexpr int kPhaseErr = kIono + kMaxIonoStates;
};

enum class RtkMode : int { kStatic = 0, kKinematic = 1 };
/// Between-receiver ionosphere: none, a variance per double difference, or estimated states.
enum class IonoMode : int { kOff = 0, kVariance = 1, kEstimate = 2 };
enum class ArMode : int { kOff = 0, kContinuous = 1, kInstantaneous = 2, kFixAndHold = 3 };
/// Solution status, RTKLIB's Q values: 1 fixed, 2 float, 4 DGPS (code only); 0 none.
enum class RtkStatus : int { kNone = 0, kFixed = 1, kFloat = 2, kDgps = 4 };
/// Slip detectors (bits of the per-epoch counts).
enum SlipKind : int { kSlipLli = 0, kSlipGf = 1, kSlipMw = 2, kSlipDoppler = 3, kSlipGap = 4, kSlipOutlier = 5,
                      kNumSlipKinds = 6 };

struct RtkOptions {
  RtkMode mode = RtkMode::kKinematic;
  ArMode ar_mode = ArMode::kContinuous;
  int n_freq = 2;
  double elevation_mask_rad = 15.0 * M_PI / 180.0;
  double ar_elevation_mask_rad = 0.0;
  double ratio_threshold = 3.0;
  int min_fix_ambiguities = 5;     // fewest ambiguities fixed (partial AR stops there; FixValidator rule 1)
  int max_partial_drops = 4;         // partial AR: at most this many ambiguities dropped (docs/algorithms.md)
  bool partial_by_variance = true;   // partial AR drops the largest-variance ambiguity first (else the lowest)
  int min_lock_epochs = 0;         // epochs an ambiguity is tracked before it is fixed
  bool glonass_ar = false;
  double sigma_phase_a_m = 0.003;  // sigma(el) = sqrt(a^2 + b^2 / sin^2 el), zero difference
  double sigma_phase_b_m = 0.003;
  double code_phase_ratio = 100.0;
  double code_corr_time_s = 0.0;   // correlation time of the code errors (multipath) [s]; 0: white
  // Time-correlated phase errors (carrier multipath, the residual atmosphere a model leaves): their
  // correlation time [s] (0: white phase) and the sigma of a first-order Gauss-Markov error per
  // ambiguity relative to the white phase sigma of the weighting (phase_error_states()); ratio 0 with a
  // correlation time: a tracked ambiguity's phase variance x (1 + rho) / (1 - rho) instead
  double phase_corr_time_s = 0.0;
  double phase_error_ratio = 0.0;
  double code_scale_gain = 0.0;    // adaptive code variance factor: gain of its update per epoch (0: off)
  double glonass_factor = 1.5;
  IonoMode iono_mode = IonoMode::kVariance;
  double iono_sigma_per_10km_m = 0.0;  // kVariance: DD sigma; kEstimate: zenith SD prior sigma (per 10 km) [m]
  double iono_tau_s = 1800.0;          // kEstimate: correlation time of the Gauss-Markov states [s]
  bool tropo_model = true;
  double accel_psd_h = 9.0;        // white acceleration [m^2/s^3], horizontal
  double accel_psd_v = 1.0;        // vertical
  double static_pos_psd = 0.0;     // random walk of a static position [m^2/s]
  double pos_init_sigma_m = 30.0;
  double vel_init_sigma_mps = 10.0;
  double amb_init_sigma_cycles = 30.0;
  double amb_psd = 1e-8;           // [cycles^2/s]
  double gf_threshold_m = 0.05;
  double mw_threshold_cycles = 2.0;
  double doppler_threshold_cycles = 1.0;  // <= 0: off
  double doppler_max_dt_s = 1.5;
  double max_gap_s = 120.0;        // a satellite unseen longer: its phase is treated as slipped
  int max_outage_epochs = 5;       // an ambiguity unobserved this many epochs is removed
  double outlier_sigma = 5.0;      // phase innovation beyond this many sigmas: ambiguity reset (0 off)
  double hold_sigma_cycles = 0.0316;
  // fix validation beyond the ratio test (ambiguity_resolution.hpp: PartialAr, FixValidator)
  double min_success_rate = 0.95;  // bootstrapped success rate of the subset fixed (0: off)
  // ... or at least this success rate of k Q_a, k the code variance factor estimated from the data
  // (RtkEngine::update_noise_factor; 0: off)
  double min_success_rate_estimated = 0.98;
  double noise_window_s = 300.0;     // forgetting time of that estimate [s]
  double noise_confidence = 0.5;     // the factor used is its upper bound at this confidence (0.5: median)
  int confirm_epochs = 5;          // a new set of few ambiguities is reported after this many repeats
  int confirm_max_ambiguities = 6; // ... "few": at most this many (more: reported at once)
  double max_age_s = 30.0;         // (applied by the caller that matches the base epochs)
};

/// One double-differenced row of a fixed epoch, recorded for the variance component estimation
/// (RtkEngine::set_record_fixed_rows; insnav.gnss.rtk.estimate_noise): the phase rows with their
/// integer ambiguities removed and the code rows, both at the float position after the epoch's update.
/// The row's configured covariance is Cov(y_a, y_b) = [a == b] var_own + [same group] var_ref (the
/// white single-difference variances of the satellite and of the group's reference satellite,
/// sigma_phase_a_m / sigma_phase_b_m and, for code, x code_phase_ratio^2; without the ionosphere
/// variance of iono_mode kVariance).
struct FixedDdRow {
  int code = 0;        // 1 code, 0 phase
  int group = 0;       // system * kMaxFreq + frequency slot (rows of one group share the reference)
  double y = 0.0;      // observed minus computed [m] (phase: integer ambiguities removed)
  double h[3] = {0.0, 0.0, 0.0};  // d(computed)/d(r_e) [-]
  double var_own = 0.0;  // configured single-difference variance of the satellite [m^2]
  double var_ref = 0.0;  // ... of the reference satellite [m^2]
};

/// One epoch of the solution.
struct RtkEpoch {
  RtkStatus status = RtkStatus::kNone;
  double ratio = 0.0;
  double success_rate = 0.0;  // bootstrapped success rate of the ambiguities fixed (of all, when float)
  double success_variance_factor = 1.0;  // k: the code variance factor estimated (update_noise_factor)
  double success_rate_estimated = 0.0;   // the success rate of k Q_a (0 when min_success_rate_estimated is 0)
  int n_fix = 0;       // ambiguities fixed (double differences)
  int n_dd = 0;        // double-differenced phase rows used
  int n_sat = 0;       // common satellites above the mask
  Vec3 r_e = Vec3::Zero();       // fixed if fixed, else float [m]
  Vec3 v_e = Vec3::Zero();        // [m/s]; NaN in kinematic mode where nothing estimates it yet (the
                                  // first epoch after an initialisation, every epoch of instantaneous AR)
  Vec3 r_float_e = Vec3::Zero();
  Mat3 P_r = Mat3::Zero();        // covariance of r_e [m^2]
  std::array<int, kNumSlipKinds> slips{};
};

namespace detail {

/// erfc^-1(y), 0 < y < 2 (bisection on std::erfc to 1e-12; used once per engine).
inline double erfc_inv(double y) {
  double lo = -10.0, hi = 10.0;  // erfc decreasing
  for (int i = 0; i < 100 && hi - lo > 1e-12; ++i) {
    const double mid = 0.5 * (lo + hi);
    (std::erfc(mid) > y ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

inline double tropo_saastamoinen_m(double lat, double h, double el) {
  // Saastamoinen (1972) zenith delay of a standard atmosphere (RTKLIB manual eq. (E.5.4)),
  // humidity 0.7, mapped by 1/cos(z).
  if (el <= 0.0 || h < -100.0 || h > 1e4) return 0.0;
  const double hgt = h < 0.0 ? 0.0 : h;
  const double pres = 1013.25 * std::pow(1.0 - 2.2557e-5 * hgt, 5.2568);
  const double temp = 15.0 - 6.5e-3 * hgt + 273.16;
  const double e = 6.108 * 0.7 * std::exp((17.15 * temp - 4684.0) / (temp - 38.45));
  const double z = M_PI / 2.0 - el;
  const double trph = 0.0022768 * pres / (1.0 - 0.00266 * std::cos(2.0 * lat) - 0.00028 * hgt / 1e3) / std::cos(z);
  const double trpw = 0.002277 * (1255.0 / temp + 0.05) * e / std::cos(z);
  return trph + trpw;
}

}  // namespace detail

/// Geometry of a receiver at r_e to the satellite of an RtkRow: range with the Sagnac term
/// (RTKLIB manual eq. (E.3.8b)) [m] and the unit vector receiver -> satellite (e_unit, ECEF).
inline double sat_range(const double* row, const Vec3& r_e, Vec3& e_unit) {
  const Vec3 rs(row[RtkRow::kSatPos], row[RtkRow::kSatPos + 1], row[RtkRow::kSatPos + 2]);
  const Vec3 d = rs - r_e;
  const double g = d.norm();
  e_unit = d / g;
  return g + kOmegaE * (rs.x() * r_e.y() - rs.y() * r_e.x()) / kCLight;
}

/// Zero-difference phase variance sigma^2(el) = F^2 (a^2 + b^2 / sin^2 el) [m^2] (F: GLONASS factor).
inline double phase_variance_zd(double el, int sys, const RtkOptions& o) {
  const double s = std::max(std::sin(el), 0.05);
  const double f = sys == kGlonass ? o.glonass_factor : 1.0;
  return f * f * (o.sigma_phase_a_m * o.sigma_phase_a_m + o.sigma_phase_b_m * o.sigma_phase_b_m / (s * s));
}

/// Are the correlated phase errors carried as states (one first-order Gauss-Markov error per
/// ambiguity, A. Gelb (ed.), Applied Optimal Estimation, 1974, sec. 4.5: state augmentation)?
inline bool phase_error_states(const RtkOptions& o) { return o.phase_error_ratio > 0.0 && o.phase_corr_time_s > 0.0; }

/// The correlated phase errors as a variance factor instead (phase_error_ratio = 0 with a correlation
/// time): a tracked ambiguity's (lock > 0) phase row enters with its white variance x (1 + rho) /
/// (1 - rho), rho = exp(-dt / tau), the generalised least-squares information of an AR(1) error per
/// further sample (Gelb 1974, sec. 3.8; as the code's code_corr_time_s).  1 otherwise.
inline double phase_var_factor(const RtkOptions& o, double dt, int lock) {
  if (!(o.phase_corr_time_s > 0.0) || !(dt > 0.0) || phase_error_states(o) || lock == 0) return 1.0;
  const double rho = std::exp(-dt / o.phase_corr_time_s);
  return (1.0 + rho) / std::max(1.0 - rho, 1e-6);
}

/// Single-layer ionospheric mapping function M(el) = 1 / sqrt(1 - (R cos el / (R + H))^2), H = 350 km.
inline double iono_mapping(double el) {
  const double x = wgs84::kA * std::cos(el) / (wgs84::kA + kIonoShellHeightM);
  return 1.0 / std::sqrt(1.0 - x * x);
}

/// Ionospheric factor mu = (f_0 / f)^2 = (lambda / lambda_0)^2 of a wavelength lambda [m] (1 if unknown).
inline double iono_factor(double lambda_m) {
  const double l0 = kCLight / kIonoRefFreqHz;
  return lambda_m > 0.0 ? (lambda_m / l0) * (lambda_m / l0) : 1.0;
}

/// The ionosphere-weighted prior of a single-differenced slant ionosphere state (iono_mode kEstimate):
/// sigma_I^2(bl, el) = (iono_sigma_per_10km_m bl / 10 km M(el))^2 [m^2], bl the baseline [m], el the
/// rover elevation [rad]; the stationary variance of its Gauss-Markov process.
inline double iono_prior_var(const RtkOptions& o, double bl, double el) {
  const double s = o.iono_sigma_per_10km_m * bl / 1e4 * iono_mapping(el);
  return s * s;
}

/// A tracked single-differenced ionosphere state (iono_mode kEstimate), one per satellite; the slot
/// table of RtkEngine and RtkInsEngine.
struct IonoSlot {
  int sat = -1;      // satellite key (system * 64 + prn), -1: free
  int outage = 0;    // epochs unseen
  bool used = false; // seen this epoch
  double el = 0.0;   // rover elevation of the last epoch [rad]
};

/// Per-receiver cycle-slip detector (LLI, geometry-free, Melbourne-Wuebbena, Doppler).
class SlipDetector {
 public:
  void reset() {
    for (auto& s : sat_) s = SatTrack{};
  }

  /// Flags of one receiver epoch: flags[i * kMaxFreq + f] = bitmask of SlipKind for row i.
  /// Rows: RtkRow layout, n rows.  Counts are added per detected (row, frequency).
  void detect(double t, const double* rows, int n, int n_freq, const RtkOptions& o, std::uint8_t* flags,
              std::array<int, kNumSlipKinds>& counts) {
    // Doppler test: the receiver clock drift is common to all satellites: remove its median.
    int nd = 0;
    for (int i = 0; i < n; ++i) {
      const double* r = rows + i * RtkRow::kCols;
      const SatTrack& s = sat_[key(r)];
      for (int f = 0; f < n_freq; ++f) {
        dop_res_[i * kMaxFreq + f] = std::numeric_limits<double>::quiet_NaN();
        const double L = r[RtkRow::kFreq0 + RtkRow::kPerFreq * f + 1];
        const double D = r[RtkRow::kFreq0 + RtkRow::kPerFreq * f + 2];
        const double dt = t - s.t[f];
        if (o.doppler_threshold_cycles > 0.0 && std::isfinite(L) && std::isfinite(D) && std::isfinite(s.L[f]) &&
            std::isfinite(s.D[f]) && dt > 0.0 && dt <= o.doppler_max_dt_s) {
          const double d = (L - s.L[f]) + 0.5 * (D + s.D[f]) * dt;
          dop_res_[i * kMaxFreq + f] = d;
          if (nd < static_cast<int>(med_.size())) med_[nd++] = d;
        }
      }
    }
    double med = 0.0;
    if (nd > 0) {
      std::nth_element(med_.begin(), med_.begin() + nd / 2, med_.begin() + nd);
      med = med_[nd / 2];
    }
    for (int i = 0; i < n; ++i) {
      const double* r = rows + i * RtkRow::kCols;
      SatTrack& s = sat_[key(r)];
      std::uint8_t any = 0;
      for (int f = 0; f < n_freq; ++f) {
        std::uint8_t fl = 0;
        const double* fr = r + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        const double L = fr[1];
        if (!std::isfinite(L)) {
          flags[i * kMaxFreq + f] = 0;
          continue;
        }
        const int lli = std::isfinite(fr[3]) ? static_cast<int>(fr[3]) : 0;
        if (lli & 1) fl |= 1u << kSlipLli;
        if (std::isfinite(s.t[f]) && t - s.t[f] > o.max_gap_s) fl |= 1u << kSlipGap;
        const double d = dop_res_[i * kMaxFreq + f];
        if (std::isfinite(d) && nd >= 2 && std::abs(d - med) > o.doppler_threshold_cycles) fl |= 1u << kSlipDoppler;
        flags[i * kMaxFreq + f] = fl;
        any |= fl;
      }
      // geometry-free and Melbourne-Wuebbena on the first two frequencies
      if (n_freq >= 2) {
        const double* f0 = r + RtkRow::kFreq0;
        const double* f1 = r + RtkRow::kFreq0 + RtkRow::kPerFreq;
        const double L0 = f0[1], L1 = f1[1], lam0 = f0[4], lam1 = f1[4];
        if (std::isfinite(L0) && std::isfinite(L1) && lam0 > 0.0 && lam1 > 0.0 && lam0 != lam1) {
          const double gf = lam0 * L0 - lam1 * L1;
          std::uint8_t fl = 0;
          if (std::isfinite(s.gf) && t - s.gf_t <= o.max_gap_s && std::abs(gf - s.gf) > o.gf_threshold_m)
            fl |= 1u << kSlipGf;
          s.gf = gf;
          s.gf_t = t;
          const double P0 = f0[0], P1 = f1[0];
          if (std::isfinite(P0) && std::isfinite(P1)) {
            const double fr0 = kCLight / lam0, fr1 = kCLight / lam1;
            const double lam_wl = kCLight / (fr0 - fr1);
            const double mw = (L0 - L1) - (fr0 * P0 + fr1 * P1) / (fr0 + fr1) / lam_wl;
            const bool restart = (any != 0) || (fl != 0) || !(t - s.mw_t <= o.max_gap_s);
            if (!restart && s.mw_n >= 2) {
              const double sd = std::sqrt(s.mw_m2 / (s.mw_n - 1));
              if (std::abs(mw - s.mw_mean) > std::max(o.mw_threshold_cycles, 5.0 * sd)) fl |= 1u << kSlipMw;
            }
            if (restart || fl) {
              s.mw_n = 0;
              s.mw_mean = s.mw_m2 = 0.0;
            }
            ++s.mw_n;  // Welford running mean and variance
            const double dm = mw - s.mw_mean;
            s.mw_mean += dm / s.mw_n;
            s.mw_m2 += dm * (mw - s.mw_mean);
            s.mw_t = t;
          }
          if (fl)
            for (int f = 0; f < 2; ++f) flags[i * kMaxFreq + f] |= fl;
        }
      }
      for (int f = 0; f < n_freq; ++f) {
        const std::uint8_t fl = flags[i * kMaxFreq + f];
        for (int k = 0; k < kNumSlipKinds; ++k)
          if (fl & (1u << k)) ++counts[k];
        const double* fr = r + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        if (std::isfinite(fr[1])) {
          s.t[f] = t;
          s.L[f] = fr[1];
          s.D[f] = fr[2];
        }
      }
    }
  }

 private:
  struct SatTrack {
    double t[kMaxFreq] = {NAN, NAN, NAN};
    double L[kMaxFreq] = {NAN, NAN, NAN};
    double D[kMaxFreq] = {NAN, NAN, NAN};
    double gf = NAN, gf_t = NAN;
    double mw_mean = 0.0, mw_m2 = 0.0, mw_t = NAN;
    int mw_n = 0;
  };
  static int key(const double* r) { return sat_key(r); }
  std::array<SatTrack, kMaxSatKeys> sat_{};
  std::array<double, kMaxSatKeys * kMaxFreq> dop_res_{};
  std::array<double, kMaxSatKeys * kMaxFreq> med_{};
};

/// The RTK engine: feed it epochs in time order (process), read RtkEpoch back.
class RtkEngine {
 public:
  using StateVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxStates, 1>;
  using StateMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxStates, kMaxStates>;
  using RowVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxRows, 1>;
  using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxRows, kMaxRows>;
  using HMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxRows, kMaxStates>;
  using KMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxStates, kMaxRows>;

  explicit RtkEngine(const RtkOptions& o) : opt_(o) {
    // standard normal quantile of 1 - noise_confidence: Phi^-1(p) = -sqrt(2) erfc^-1(2 p)
    noise_z_ = -std::sqrt(2.0) * detail::erfc_inv(2.0 * (1.0 - std::clamp(opt_.noise_confidence, 0.5, 0.999999)));
    reset();
  }

  void reset() {
    x_.setZero(kMaxStates);
    P_.setZero(kMaxStates, kMaxStates);
    p_dim_ = RtkLayout::kAmb;
    amb_of_.fill(-1);
    for (auto& a : amb_) a = AmbSlot{};
    iono_of_.fill(-1);
    for (auto& a : iono_) a = IonoSlot{};
    validator_.reset();
    initialized_ = false;
    t_prev_ = NAN;
    code_scale_ = 1.0;
    noise_q_ = noise_dof_ = 0.0;
    noise_t_ = NAN;
    sr_factor_ = 1.0;
    rover_slip_.reset();
    base_slip_.reset();
  }

  const RtkOptions& options() const { return opt_; }

  /// Record, at every fixed epoch, its double-differenced rows (FixedDdRow) for the variance
  /// component estimation of the phase and code noise (off by default: two more row builds per
  /// fixed epoch).  Read them after process() with fixed_rows() / fixed_row(i).
  void set_record_fixed_rows(bool on) { record_fixed_ = on; }
  /// Record, at every epoch with AR, the float ambiguity problem that resolve() hands to partial AR
  /// (off by default): the n candidate double differences in the engine's priority order (partial AR
  /// drops from the end), their float values a_hat [cycles], covariance Q_a [cycles^2], the
  /// cross-covariance Q_ba of the float position with them [m cycles], the float position's
  /// covariance Q_bb [m^2], and the satellite keys (sat_key) of each double difference's satellite j
  /// and reference i and its frequency slot.  For studies of what the float supports (success rates of
  /// subsets, conditioning on extra information); read after process() with float_problem().
  void set_record_float(bool on) { record_float_ = on; }
  struct FloatProblem {
    int n = 0;  // candidates (0: no AR this epoch)
    AmbVec a_hat;
    AmbMat Qa;
    Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxAmbiguities> Qba;
    Mat3 Qbb = Mat3::Zero();
    std::array<int, kMaxAmbiguities> sat_j{}, sat_i{}, freq{};
  };
  const FloatProblem& float_problem() const { return float_; }
  /// Rows recorded at the last processed epoch (0 unless it was fixed and recording is on).
  int fixed_rows() const { return n_fixed_rows_; }
  const FixedDdRow& fixed_row(int i) const { return fixed_rows_[i]; }

  /// The linearised double-difference rows of the last processed epoch at the current state (tests
  /// and diagnostics; the epoch's observation arrays must still be alive): code = 1 code rows, 0 phase
  /// rows; y[r] the innovation (observed minus computed) [m], H_full[r * kMaxStates + j] its
  /// derivative with respect to state j (d(computed)/dx_j; states in RtkLayout).  Returns the rows.
  int linearised_rows(int code, double* y, double* H_full, int max_rows) {
    const int nf = std::clamp(opt_.n_freq, 1, kMaxFreq);
    const int m = std::min(build_rows(nf, code), max_rows);
    for (int r = 0; r < m; ++r) {
      y[r] = y_(r);
      std::fill(H_full + r * kMaxStates, H_full + (r + 1) * kMaxStates, 0.0);
      for (int k = 0; k < nz_[r]; ++k) H_full[r * kMaxStates + act_[hc_[r][k]]] += hv_[r][k];
    }
    return m;
  }

  /// State element i (RtkLayout), writable (tests: numerical Jacobians).
  double& state(int i) { return x_(i); }

  /// State slot of the ionosphere of satellite key sat (RtkLayout::kIono + slot), or -1.
  int iono_index(int sat) const {
    return (sat >= 0 && sat < kMaxSatKeys && iono_of_[sat] >= 0) ? RtkLayout::kIono + iono_of_[sat] : -1;
  }

  /// The double-differenced ionosphere of satellite key sat against the reference of its system (the
  /// highest satellite with an ionosphere state in use): I^sat - I^ref and its sigma [m] at
  /// kIonoRefFreqHz.  Only double differences are observable: the common part of a system's
  /// single differences is the prior's.  False for the reference itself and without a state.
  bool iono_dd_estimate(int sat, double& value_m, double& sigma_m) const {
    if (sat < 0 || sat >= kMaxSatKeys || iono_of_[sat] < 0) return false;
    const int sys = sat / kMaxPrn;
    int ref = -1;
    for (int k = 0; k < kMaxIonoStates; ++k)
      if (iono_[k].sat >= 0 && iono_[k].used && iono_[k].sat / kMaxPrn == sys && (ref < 0 || iono_[k].el > iono_[ref].el))
        ref = k;
    const int k = iono_of_[sat];
    if (ref < 0 || ref == k || !iono_[k].used) return false;
    const int s = RtkLayout::kIono + k, r = RtkLayout::kIono + ref;
    value_m = x_(s) - x_(r);
    sigma_m = std::sqrt(std::max(P_(s, s) + P_(r, r) - 2.0 * P_(s, r), 0.0));
    return true;
  }

  /// The single-differenced (rover - base) slant ionosphere of satellite key sat (system * 64 + prn)
  /// at kIonoRefFreqHz: value and sigma [m].  False when no state is tracked (iono_mode != kEstimate).
  bool iono_estimate(int sat, double& value_m, double& sigma_m) const {
    if (sat < 0 || sat >= kMaxSatKeys || iono_of_[sat] < 0) return false;
    const int s = RtkLayout::kIono + iono_of_[sat];
    value_m = x_(s);
    sigma_m = std::sqrt(std::max(P_(s, s), 0.0));
    return true;
  }

  /// Double differences "observed minus computed" at a given rover position, without the
  /// ambiguity term (for tests against analytic values): per row the rover row index of the
  /// satellite, of its reference, the frequency slot, whether it is code, and the value [m].
  /// Returns the number of rows written (at most max_rows).  Resets the engine.
  int double_differences(const double* rover, int n_r, const double* base, int n_b, const Vec3& r_rover_e,
                         const Vec3& r_base_e, int* sat_row, int* ref_row, int* freq, int* is_code, double* value,
                         int max_rows) {
    reset();
    const int nf = std::clamp(opt_.n_freq, 1, kMaxFreq);
    std::array<int, kNumSlipKinds> slips{};
    rover_slip_.detect(0.0, rover, n_r, nf, opt_, flags_r_.data(), slips);
    std::fill(flags_b_.begin(), flags_b_.end(), 0);
    n_common_ = match_common_satellites(rover, n_r, base, n_b, base_of_, common_r_.data(), common_b_.data());
    rover_ = rover;
    base_ = base;
    r_base_ = r_base_e;
    const Vec3 llh_b = wgs84::ecef_to_geodetic(r_base_e);
    lat_b_ = llh_b(0);
    h_b_ = llh_b(2);
    x_.segment<3>(RtkLayout::kPos) = r_rover_e;
    update_geometry();
    RtkEpoch dummy;
    manage_ambiguities(nf, dummy);
    int w = 0;
    for (int code = 0; code < 2; ++code) {
      const int m = build_rows(nf, code);
      for (int i = 0; i < m && w < max_rows; ++i, ++w) {
        const int c = row_c_[i], r = row_ref_[i], f = row_f_[i];
        sat_row[w] = common_r_[c];
        ref_row[w] = common_r_[r];
        freq[w] = f;
        is_code[w] = code;
        value[w] = code ? sd_code_[c * kMaxFreq + f] - sd_code_[r * kMaxFreq + f]
                        : sd_phase_[c * kMaxFreq + f] - sd_phase_[r * kMaxFreq + f];
      }
    }
    return w;
  }

  /// Process one rover epoch at GPS time t [s] against a base epoch.
  /// rover/base: n_r / n_b rows of RtkRow::kCols; base_new: the base rows are a new base epoch
  /// (false when the caller holds an older one); r_base_e: base antenna position [m].
  RtkEpoch process(double t, const double* rover, int n_r, const double* base, int n_b, bool base_new,
                   const Vec3& r_base_e) {
    RtkEpoch out;
    n_fixed_rows_ = 0;
    float_.n = 0;
    const int nf = std::clamp(opt_.n_freq, 1, kMaxFreq);
    n_r = std::min(n_r, kMaxSatKeys);
    n_b = std::min(n_b, kMaxSatKeys);
    rover_slip_.detect(t, rover, n_r, nf, opt_, flags_r_.data(), out.slips);
    if (base_new) base_slip_.detect(t, base, n_b, nf, opt_, flags_b_.data(), out.slips);
    else std::fill(flags_b_.begin(), flags_b_.end(), 0);
    // common satellites (gnss/double_difference.hpp)
    n_common_ = match_common_satellites(rover, n_r, base, n_b, base_of_, common_r_.data(), common_b_.data());
    rover_ = rover;
    base_ = base;
    r_base_ = r_base_e;
    const Vec3 llh_b = wgs84::ecef_to_geodetic(r_base_e);
    lat_b_ = llh_b(0);
    h_b_ = llh_b(2);

    const bool inst = opt_.ar_mode == ArMode::kInstantaneous;
    const bool kin = opt_.mode == RtkMode::kKinematic;
    // (re)initialise the position from the code double differences
    if (!initialized_ || inst) {
      Vec3 r0 = initialized_ ? Vec3(x_.segment<3>(RtkLayout::kPos)) : r_base_e;
      Mat3 Pr;
      if (!dgps(r0, nf, Pr)) {
        out.n_sat = n_common_;
        return out;  // no solution this epoch
      }
      x_.setZero(kMaxStates);
      zero_covariance();
      amb_of_.fill(-1);
      for (auto& a : amb_) a = AmbSlot{};
      iono_of_.fill(-1);
      for (auto& a : iono_) a = IonoSlot{};
      validator_.reset();
      x_.segment<3>(RtkLayout::kPos) = r0;
      P_.block<3, 3>(RtkLayout::kPos, RtkLayout::kPos) = Mat3::Identity() * opt_.pos_init_sigma_m * opt_.pos_init_sigma_m;
      if (kin)
        P_.block<3, 3>(RtkLayout::kVel, RtkLayout::kVel) =
            Mat3::Identity() * opt_.vel_init_sigma_mps * opt_.vel_init_sigma_mps;
      initialized_ = true;
      t_prev_ = t;
    }
    // time update
    const double dt = std::isfinite(t_prev_) ? t - t_prev_ : 0.0;
    dt_epoch_ = dt;
    if (dt > 0.0) predict(dt, kin);
    t_prev_ = t;
    // elevations at the current rover estimate and the ambiguity bookkeeping
    update_geometry();
    manage_ambiguities(nf, out);
    out.n_sat = n_used_sats_;
    if (opt_.ar_mode != ArMode::kOff && opt_.min_success_rate_estimated > 0.0) update_noise_factor(t, nf);
    // float update: code rows, then phase rows (uncorrelated, so two updates in turn are exact up
    // to the relinearisation); phase rows are rebuilt after outlier resets, at most twice
    const int n_code = build_rows(nf, 1);
    if (n_code > 0) kalman_update(n_code, false, out);
    int n_rows = 0;
    for (int pass = 0; pass < 3; ++pass) {
      n_rows = build_rows(nf, 0);
      if (n_rows == 0) break;
      if (!kalman_update(n_rows, pass < 2, out)) continue;  // an outlier reset: rebuild
      break;
    }
    out.n_dd = n_phase_rows_;
    if (n_rows == 0 || n_phase_rows_ == 0) {
      Mat3 Pr;
      Vec3 r0 = x_.segment<3>(RtkLayout::kPos);
      if (dgps(r0, nf, Pr)) {
        out.status = RtkStatus::kDgps;
        out.r_e = r0;
        out.r_float_e = r0;
        out.P_r = Pr;
      }
      return out;
    }
    update_code_scale(nf);
    for (int k = 0; k < kMaxAmbStates; ++k)
      if (amb_[k].used) ++amb_[k].lock;
    out.r_float_e = x_.segment<3>(RtkLayout::kPos);
    out.r_e = out.r_float_e;
    out.v_e = !kin ? Vec3::Zero() : dt > 0.0 ? Vec3(x_.segment<3>(RtkLayout::kVel)) : Vec3::Constant(NAN);
    out.P_r = P_.block<3, 3>(RtkLayout::kPos, RtkLayout::kPos);
    out.status = RtkStatus::kFloat;
    if (opt_.ar_mode != ArMode::kOff) {
      validator_.begin_epoch();
      resolve(out, kin);
      validator_.end_epoch();
    }
    return out;
  }

 private:
  struct AmbSlot {
    int sat = -1, freq = -1;
    int lock = 0, outage = 0;
    bool used = false;      // a phase row this epoch
    bool half = false;      // half-cycle ambiguity flagged
    double el = 0.0;
    double phase_error_var = 0.0;  // stationary variance of its correlated phase error [m^2]
  };
  static int key(const double* r) { return sat_key(r); }
  static int sys_of(const double* r) { return static_cast<int>(r[RtkRow::kSys]); }

  // Geometry of a receiver at r to the satellite of row: range with Sagnac term, unit vector, elevation.
  static double range(const double* row, const Vec3& r, Vec3& e_unit) { return sat_range(row, r, e_unit); }

  double var_zd(double el, int sys) const { return phase_variance_zd(el, sys, opt_); }

  void update_geometry() {
    const Vec3 rr = x_.segment<3>(RtkLayout::kPos);
    const Vec3 llh = wgs84::ecef_to_geodetic(rr);
    lat_r_ = llh(0);
    h_r_ = llh(2);
    const Mat3 C = wgs84::C_en(llh(0), llh(1));
    const Mat3 Cb = wgs84::C_en(lat_b_, wgs84::ecef_to_geodetic(r_base_)(1));
    n_used_sats_ = 0;
    for (int c = 0; c < n_common_; ++c) {
      Vec3 e;
      range(rover_ + common_r_[c] * RtkRow::kCols, rr, e);
      const Vec3 e_n = C.transpose() * e;
      el_r_[c] = std::asin(std::clamp(-e_n(2), -1.0, 1.0));
      range(base_ + common_b_[c] * RtkRow::kCols, r_base_, e);
      const Vec3 eb_n = Cb.transpose() * e;
      el_b_[c] = std::asin(std::clamp(-eb_n(2), -1.0, 1.0));
      use_[c] = el_r_[c] >= opt_.elevation_mask_rad && el_b_[c] >= 0.0;
      if (use_[c]) ++n_used_sats_;
    }
  }

  void predict(double dt, bool kin) {
    if (kin) {
      // x_pos += v dt; white acceleration in ENU (q_h, q_h, q_v)
      x_.segment<3>(RtkLayout::kPos) += x_.segment<3>(RtkLayout::kVel) * dt;
      const int n = p_dim_;  // P_ is zero beyond its first p_dim_ rows and columns
      // P <- F P F^T with F = [I I dt; 0 I] on the first six states
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < 3; ++i) P_(i, j) += dt * P_(3 + i, j);
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < 3; ++j) P_(i, j) += dt * P_(i, 3 + j);
      const Vec3 llh = wgs84::ecef_to_geodetic(Vec3(x_.segment<3>(RtkLayout::kPos)));
      const Mat3 C = wgs84::C_en(llh(0), llh(1));
      const Mat3 Qn = Vec3(opt_.accel_psd_h, opt_.accel_psd_h, opt_.accel_psd_v).asDiagonal();
      const Mat3 Qe = C * Qn * C.transpose();
      P_.block<3, 3>(0, 0) += Qe * (dt * dt * dt / 3.0);
      P_.block<3, 3>(0, 3) += Qe * (dt * dt / 2.0);
      P_.block<3, 3>(3, 0) += Qe * (dt * dt / 2.0);
      P_.block<3, 3>(3, 3) += Qe * dt;
    } else if (opt_.static_pos_psd > 0.0) {
      P_.block<3, 3>(0, 0) += Mat3::Identity() * opt_.static_pos_psd * dt;
    }
    for (int k = 0; k < kMaxAmbStates; ++k)
      if (amb_[k].sat >= 0) P_(RtkLayout::kAmb + k, RtkLayout::kAmb + k) += opt_.amb_psd * dt;
    // ionosphere and correlated phase errors, first-order Gauss-Markov: x <- phi x,
    // P <- Phi P Phi^T + sigma^2 (1 - phi^2) on the diagonal (sigma: the state's stationary sigma)
    const auto gm = [&](int s, double phi, double var) {
      x_(s) *= phi;
      P_.row(s) *= phi;
      P_.col(s) *= phi;
      P_(s, s) += var * (1.0 - phi * phi);
    };
    if (opt_.iono_mode == IonoMode::kEstimate) {
      const double phi = opt_.iono_tau_s > 0.0 ? std::exp(-dt / opt_.iono_tau_s) : 0.0;
      const double bl = (Vec3(x_.segment<3>(RtkLayout::kPos)) - r_base_).norm();
      for (int k = 0; k < kMaxIonoStates; ++k)
        if (iono_[k].sat >= 0) gm(RtkLayout::kIono + k, phi, iono_prior_var(opt_, bl, iono_[k].el));
    }
    if (phase_error_states(opt_)) {
      const double phi = std::exp(-dt / opt_.phase_corr_time_s);
      for (int k = 0; k < kMaxAmbStates; ++k)
        if (amb_[k].sat >= 0) gm(RtkLayout::kPhaseErr + k, phi, amb_[k].phase_error_var);
    }
  }

  // Stationary variance of the single-differenced correlated phase error of common satellite c [m^2]:
  // phase_error_ratio^2 times the white single difference's (the phase weighting of both receivers at
  // their elevations).
  double phase_error_var(int c) const {
    const int sys = sys_of(rover_ + common_r_[c] * RtkRow::kCols);
    return opt_.phase_error_ratio * opt_.phase_error_ratio * (var_zd(el_r_[c], sys) + var_zd(el_b_[c], sys));
  }

  // Ionosphere states of the satellites in use: a new satellite starts at I = 0 with the prior
  // sigma_I^2 (the ionosphere-weighted pseudo-observation); one unseen for max_outage_epochs is removed.
  void manage_iono() {
    for (auto& a : iono_) a.used = false;
    if (opt_.iono_mode != IonoMode::kEstimate) return;
    const double bl = (Vec3(x_.segment<3>(RtkLayout::kPos)) - r_base_).norm();
    for (int c = 0; c < n_common_; ++c) {
      if (!use_[c]) continue;
      const int sat = key(rover_ + common_r_[c] * RtkRow::kCols);
      int k = iono_of_[sat];
      if (k < 0) {
        for (int q = 0; q < kMaxIonoStates; ++q)
          if (iono_[q].sat < 0) { k = q; break; }
        if (k < 0) continue;  // table full: no ionosphere state (rows of this satellite carry none)
        const int s = RtkLayout::kIono + k;
        iono_[k].sat = sat;
        iono_of_[sat] = k;
        p_dim_ = std::max(p_dim_, s + 1);
        clear_state(s);
        P_(s, s) = iono_prior_var(opt_, bl, el_r_[c]);
      }
      iono_[k].used = true;
      iono_[k].outage = 0;
      iono_[k].el = el_r_[c];
    }
    for (int k = 0; k < kMaxIonoStates; ++k) {
      if (iono_[k].sat < 0 || iono_[k].used || ++iono_[k].outage <= opt_.max_outage_epochs) continue;
      iono_of_[iono_[k].sat] = -1;
      iono_[k] = IonoSlot{};
      clear_state(RtkLayout::kIono + k);
    }
  }

  // Active states of the compact update: position, velocity (kinematic), tracked ambiguities,
  // ionosphere states and correlated phase errors; col_of_ / iono_col_ / perr_col_ map a slot to its
  // column (-1: inactive).
  void build_active(bool kin) {
    na_ = 0;
    for (int i = 0; i < (kin ? 6 : 3); ++i) act_[na_++] = i;
    std::fill(col_of_.begin(), col_of_.end(), -1);
    std::fill(iono_col_.begin(), iono_col_.end(), -1);
    for (int k = 0; k < kMaxAmbStates; ++k)
      if (amb_[k].sat >= 0) {
        col_of_[k] = na_;
        act_[na_++] = RtkLayout::kAmb + k;
      }
    for (int k = 0; k < kMaxIonoStates; ++k)
      if (iono_[k].sat >= 0) {
        iono_col_[k] = na_;
        act_[na_++] = RtkLayout::kIono + k;
      }
    std::fill(perr_col_.begin(), perr_col_.end(), -1);
    if (phase_error_states(opt_))
      for (int k = 0; k < kMaxAmbStates; ++k)
        if (amb_[k].sat >= 0) {
          perr_col_[k] = na_;
          act_[na_++] = RtkLayout::kPhaseErr + k;
        }
  }

  // Zero state s and its covariance row and column.
  void clear_state(int s) {
    x_(s) = 0.0;
    P_.row(s).setZero();
    P_.col(s).setZero();
  }

  void remove_amb(int k) {
    const int s = RtkLayout::kAmb + k;
    if (amb_[k].sat >= 0) amb_of_[amb_[k].sat * kMaxFreq + amb_[k].freq] = -1;
    amb_[k] = AmbSlot{};
    validator_.invalidate(k);
    clear_state(s);
    clear_state(RtkLayout::kPhaseErr + k);
  }

  // Initialise (or re-initialise) the ambiguity of common satellite c, frequency f from SD(phase - code).
  void init_amb(int k, int c, int f) {
    const int s = RtkLayout::kAmb + k;
    const double* fr = rover_ + common_r_[c] * RtkRow::kCols + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
    const double* fb = base_ + common_b_[c] * RtkRow::kCols + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
    const double lam = fr[4];
    double n0 = fr[1] - fb[1];
    if (std::isfinite(fr[0]) && std::isfinite(fb[0])) n0 -= (fr[0] - fb[0]) / lam;
    else {  // no code: from the geometry of the current estimate, plus the single-differenced receiver
            // clock that the code-initialised ambiguities carry (else a satellite without code, once
            // the reference, puts that clock, up to 300 km, into every double difference)
      const Vec3 rr = x_.segment<3>(RtkLayout::kPos);
      Vec3 e;
      const auto sd_range = [&](int k) {
        return range(rover_ + common_r_[k] * RtkRow::kCols, rr, e) - range(base_ + common_b_[k] * RtkRow::kCols, r_base_, e);
      };
      const int sys = sys_of(rover_ + common_r_[c] * RtkRow::kCols);
      int n = 0;
      for (int k = 0; k < n_common_; ++k) {
        const double* gr = rover_ + common_r_[k] * RtkRow::kCols;
        const double* gb = base_ + common_b_[k] * RtkRow::kCols;
        if (k == c || sys_of(gr) != sys) continue;
        const double Pr = gr[RtkRow::kFreq0 + RtkRow::kPerFreq * f], Pb = gb[RtkRow::kFreq0 + RtkRow::kPerFreq * f];
        if (std::isfinite(Pr) && std::isfinite(Pb)) clock_buf_[n++] = (Pr - Pb) - sd_range(k);
      }
      const double clk = median_in_place(clock_buf_.data(), n);
      n0 -= (sd_range(c) + (std::isfinite(clk) ? clk : 0.0)) / lam;
    }
    clear_state(s);
    x_(s) = n0;
    p_dim_ = std::max(p_dim_, s + 1);
    P_(s, s) = opt_.amb_init_sigma_cycles * opt_.amb_init_sigma_cycles;
    // its correlated phase error starts at 0 with the stationary variance
    const int e = RtkLayout::kPhaseErr + k;
    clear_state(e);
    amb_[k].phase_error_var = phase_error_states(opt_) ? phase_error_var(c) : 0.0;
    if (phase_error_states(opt_)) {
      p_dim_ = std::max(p_dim_, e + 1);
      P_(e, e) = amb_[k].phase_error_var;
    }
    amb_[k].lock = 0;
    amb_[k].outage = 0;
    validator_.invalidate(k);
  }

  void manage_ambiguities(int nf, RtkEpoch& out) {
    for (int k = 0; k < kMaxAmbStates; ++k) amb_[k].used = false;
    for (int c = 0; c < n_common_; ++c) {
      if (!use_[c]) continue;
      const double* r = rover_ + common_r_[c] * RtkRow::kCols;
      const double* b = base_ + common_b_[c] * RtkRow::kCols;
      const int sat = key(r);
      for (int f = 0; f < nf; ++f) {
        const double* fr = r + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        const double* fb = b + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        if (!std::isfinite(fr[1]) || !std::isfinite(fb[1]) || !(fr[4] > 0.0)) continue;
        const bool slip = flags_r_[common_r_[c] * kMaxFreq + f] != 0 || flags_b_[common_b_[c] * kMaxFreq + f] != 0;
        int k = amb_of_[sat * kMaxFreq + f];
        if (k < 0) {
          for (int q = 0; q < kMaxAmbStates; ++q)
            if (amb_[q].sat < 0) { k = q; break; }
          if (k < 0) continue;  // table full: the satellite is not used on this frequency
          amb_[k].sat = sat;
          amb_[k].freq = f;
          amb_of_[sat * kMaxFreq + f] = k;
          init_amb(k, c, f);
        } else if (slip) {
          init_amb(k, c, f);
        }
        const int lli_r = std::isfinite(fr[3]) ? static_cast<int>(fr[3]) : 0;
        const int lli_b = std::isfinite(fb[3]) ? static_cast<int>(fb[3]) : 0;
        amb_[k].half = ((lli_r | lli_b) & 2) != 0;
        amb_[k].used = true;
        amb_[k].outage = 0;
        amb_[k].el = el_r_[c];
        if (phase_error_states(opt_)) amb_[k].phase_error_var = phase_error_var(c);
        amb_row_[c * kMaxFreq + f] = k;
      }
    }
    for (int k = 0; k < kMaxAmbStates; ++k)
      if (amb_[k].sat >= 0 && !amb_[k].used && ++amb_[k].outage > opt_.max_outage_epochs) remove_amb(k);
    manage_iono();
    (void)out;
  }

  // Build the double-difference rows at the current state (y, H over the compact state, R).
  int build_rows(int nf, int code) {
    // active states: position, velocity (kinematic), tracked ambiguities and ionosphere states
    build_active(opt_.mode == RtkMode::kKinematic && opt_.ar_mode != ArMode::kInstantaneous);
    const Vec3 rr = x_.segment<3>(RtkLayout::kPos);
    const double bl = (rr - r_base_).norm();
    const double var_bl =
        opt_.iono_mode == IonoMode::kVariance ? std::pow(opt_.iono_sigma_per_10km_m * bl / 1e4, 2) : 0.0;
    const bool est_iono = opt_.iono_mode == IonoMode::kEstimate;
    // zero-difference residuals
    for (int c = 0; c < n_common_; ++c) {
      if (!use_[c]) continue;
      const double* r = rover_ + common_r_[c] * RtkRow::kCols;
      const double* b = base_ + common_b_[c] * RtkRow::kCols;
      Vec3 eb;
      const double rho_r = range(r, rr, e_[c]);
      const double rho_b = range(b, r_base_, eb);
      double tr = 0.0, tb = 0.0;
      if (opt_.tropo_model) {
        tr = detail::tropo_saastamoinen_m(lat_r_, h_r_, el_r_[c]);
        tb = detail::tropo_saastamoinen_m(lat_b_, h_b_, el_b_[c]);
      }
      const double mr = rho_r - r[RtkRow::kSatClock] + tr;
      const double mb = rho_b - b[RtkRow::kSatClock] + tb;
      for (int f = 0; f < nf; ++f) {
        const double* fr = r + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        const double* fb = b + RtkRow::kFreq0 + RtkRow::kPerFreq * f;
        sd_phase_[c * kMaxFreq + f] = (fr[4] > 0.0 && std::isfinite(fr[1]) && std::isfinite(fb[1]))
                                          ? (fr[4] * fr[1] - mr) - (fb[4] * fb[1] - mb)
                                          : NAN;
        sd_code_[c * kMaxFreq + f] =
            (std::isfinite(fr[0]) && std::isfinite(fb[0])) ? (fr[0] - mr) - (fb[0] - mb) : NAN;
      }
      var_sd_[c] = var_zd(el_r_[c], sys_of(r)) + var_zd(el_b_[c], sys_of(r));
    }
    int m = 0;
    n_phase_rows_ = 0;
    R_.resize(kMaxRows, kMaxRows);  // each row m zeroes its own entries left of m below (no full memset)
    y_.setZero(kMaxRows);
    {
      for (int sys = 0; sys < kNumSystems; ++sys) {
        for (int f = 0; f < nf; ++f) {
          // reference: highest rover elevation with a valid observation (and ambiguity for phase)
          const int ref = highest_elevation_reference(
              n_common_,
              [&](int c) { return use_[c] && sys_of(rover_ + common_r_[c] * RtkRow::kCols) == sys && valid(c, f, code); },
              [&](int c) { return el_r_[c]; });
          if (ref < 0) continue;
          const int m0 = m;
          const double var_ref =
              var_sd_[ref] * (code ? opt_.code_phase_ratio * opt_.code_phase_ratio * code_var_factor(ref, f)
                                   : phase_factor(ref, f));
          for (int c = 0; c < n_common_; ++c) {
            if (c == ref || !use_[c] || sys_of(rover_ + common_r_[c] * RtkRow::kCols) != sys) continue;
            if (!valid(c, f, code) || m >= kMaxRows) continue;
            const Vec3 dH = -(e_[c] - e_[ref]);
            nz_[m] = 0;
            for (int i = 0; i < 3; ++i) set_h(m, i, dH(i));
            if (!code) {
              const int kj = amb_row_[c * kMaxFreq + f], ki = amb_row_[ref * kMaxFreq + f];
              const double lj = lam(common_r_[c], f), li = lam(common_r_[ref], f);
              y_(m) = (sd_phase_[c * kMaxFreq + f] - sd_phase_[ref * kMaxFreq + f]) -
                      (lj * x_(RtkLayout::kAmb + kj) - li * x_(RtkLayout::kAmb + ki));
              set_h(m, col_of_[kj], lj);
              set_h(m, col_of_[ki], -li);
              if (perr_col_[kj] >= 0 && perr_col_[ki] >= 0) {  // correlated phase errors: + (b_j - b_i)
                y_(m) -= x_(RtkLayout::kPhaseErr + kj) - x_(RtkLayout::kPhaseErr + ki);
                set_h(m, perr_col_[kj], 1.0);
                set_h(m, perr_col_[ki], -1.0);
              }
              row_amb_[m] = kj;
              ++n_phase_rows_;
            } else {
              y_(m) = sd_code_[c * kMaxFreq + f] - sd_code_[ref * kMaxFreq + f];
              row_amb_[m] = -1;
            }
            if (est_iono) {
              // DD ionosphere: -/+ (mu_j I_j - mu_i I_i) on phase / code (mu = (f_0 / f)^2)
              const double sgn = code ? 1.0 : -1.0;
              const int sj = iono_of_[key(rover_ + common_r_[c] * RtkRow::kCols)];
              const int si = iono_of_[key(rover_ + common_r_[ref] * RtkRow::kCols)];
              if (sj >= 0) {
                const double mu = sgn * iono_factor(lam(common_r_[c], f));
                y_(m) -= mu * x_(RtkLayout::kIono + sj);
                set_h(m, iono_col_[sj], mu);
              }
              if (si >= 0) {
                const double mu = sgn * iono_factor(lam(common_r_[ref], f));
                y_(m) += mu * x_(RtkLayout::kIono + si);
                set_h(m, iono_col_[si], -mu);
              }
            }
            row_code_[m] = code;
            row_c_[m] = c;
            row_ref_[m] = ref;
            row_f_[m] = f;
            const double var_j =
                var_sd_[c] * (code ? opt_.code_phase_ratio * opt_.code_phase_ratio * code_var_factor(c, f)
                                   : phase_factor(c, f));
            R_.row(m).head(m0).setZero();  // rows of another system or frequency: uncorrelated
            R_.col(m).head(m0).setZero();
            R_(m, m) = var_j + var_bl;
            for (int q = m0; q < m; ++q) R_(m, q) = R_(q, m) = var_ref + var_bl;
            R_(m, m) += var_ref + var_bl;
            ++m;
          }
        }
      }
    }
    return m;
  }

  // Time-correlated code errors.  A first-order Gauss-Markov error of variance sigma^2 and correlation
  // rho = exp(-dt / tau) between epochs: the generalised least-squares information of N such samples on
  // a constant is [2 + (N - 2)(1 - rho)] / ((1 + rho) sigma^2) (inverse of the AR(1) covariance,
  // A. Gelb (ed.), Applied Optimal Estimation, 1974, sec. 3.8), i.e. 1 / sigma^2 for the first sample
  // and (1 - rho) / (1 + rho) / sigma^2 for each further one.  The filter treats code as white, so the
  // code of a satellite whose ambiguity was already tracked (lock > 0) enters with its variance scaled
  // by (1 + rho) / (1 - rho): the float ambiguities (and the success rate and ratio test built on their
  // covariance) then accumulate what correlated multipath really gives, not sqrt(N) of it.  The first
  // epoch of an ambiguity (and every epoch of instantaneous AR) keeps the white variance.
  //
  // The factor also holds code_scale_, the adaptive variance factor of the code (update_code_scale).
  double code_var_factor(int c, int f) const {
    if (white_code_) return 1.0;
    if (!(opt_.code_corr_time_s > 0.0) || !(dt_epoch_ > 0.0)) return code_scale_;
    const int k = amb_of_[key(rover_ + common_r_[c] * RtkRow::kCols) * kMaxFreq + f];
    if (k < 0 || amb_[k].lock == 0) return code_scale_;
    const double rho = std::exp(-dt_epoch_ / opt_.code_corr_time_s);
    return code_scale_ * (1.0 + rho) / std::max(1.0 - rho, 1e-6);
  }

  // The phase variance factor of common satellite c, frequency f (phase_var_factor; 1 where the
  // correlated phase errors are states or white, or with white_code_ set for the recorded rows).
  double phase_factor(int c, int f) const {
    if (white_code_) return 1.0;
    const int k = amb_of_[key(rover_ + common_r_[c] * RtkRow::kCols) * kMaxFreq + f];
    return phase_var_factor(opt_, dt_epoch_, k < 0 ? 0 : amb_[k].lock);
  }

  // Adaptive variance factor of the code rows from their post-fit residuals (residual-based adaptive
  // estimation, A. H. Mohamed, K. P. Schwarz, "Adaptive Kalman filtering for INS/GPS", J. Geodesy 73
  // (1999) 193-203, eq. (28) in its scalar form).  After the phase update the position is known far
  // better than the code, so the code double differences rebuilt at the updated state, y_i, have
  // E[y_i^2] ~ k R_i with R_i the configured (white, single-epoch) variance of the row: the factor k
  // moves towards what the epoch's mean of nu_i = y_i^2 / (k R_i) says, log k <- log k + g log(mean nu)
  // (each nu_i capped at 25: one outlier moves it little), kept in [1, 100].  A receiver noisier than
  // configured gets a larger code variance (so the float ambiguities, the success rate and the ratio
  // test are not over-confident); never a smaller one.
  void update_code_scale(int nf) {
    if (!(opt_.code_scale_gain > 0.0)) return;
    const int m = build_rows(nf, 1);
    if (m <= 0) return;
    const double r2 = opt_.code_phase_ratio * opt_.code_phase_ratio;
    double sum = 0.0;
    for (int i = 0; i < m; ++i) {
      const double var = code_scale_ * r2 * (var_sd_[row_c_[i]] + var_sd_[row_ref_[i]]);
      sum += std::min(y_(i) * y_(i) / var, 25.0);
    }
    const double mean = sum / m;
    if (!(mean > 0.0) || !std::isfinite(mean)) return;
    code_scale_ = std::clamp(code_scale_ * std::pow(mean, opt_.code_scale_gain), 1.0, 100.0);
  }

  // Variance factor k of the code double differences, estimated from the data, for the success rate
  // of integer bootstrapping (Teunissen 1998) computed from k Q_a instead of the configured Q_a.
  // The configured noise (RTKLIB's default: phase 3 mm, code 100 x) is a prior: a receiver quieter
  // than it gets a pessimistic success rate (measured on a Septentrio pair, GPS L1, one epoch: 0.40
  // with the configured covariance, above 0.99 with the one of its real scatter), a noisier one an
  // optimistic rate.  Single-epoch float ambiguities are determined by the code, so the factor is
  // the code's.  Least-squares variance component estimation with one component (P. J. G.
  // Teunissen, A. R. Amiri-Simkooei, "Least-squares variance component estimation", J. Geodesy 82
  // (2008) 65-82; with one component it is the a-posteriori variance factor of unit weight): the epoch's DD code rows y = H dr + e with the configured white
  // covariance R (m rows, 3 position unknowns) give the weighted sum of squared residuals
  //   q = y^T R^-1 y - b^T N^-1 b,  N = H^T R^-1 H,  b = H^T R^-1 y,  E[q] = k (m - 3).
  // Over epochs with forgetting w = exp(-dt / noise_window_s): Q <- w Q + q, F <- w F + (m - 3), and
  // the factor used is the upper confidence bound k = Q / chi2_{1-c}(F) (c = noise_confidence;
  // the quantile by Wilson and Hilferty 1931), so few data give a factor above the point estimate
  // Q / F (c = 0.5, the default: the median, about Q / (F - 2/3)); k is kept in [0.01, 100].  A set
  // passes the success-rate test with P_s(Q_a) >= min_success_rate (the configured covariance) or
  // P_s(k Q_a) >= min_success_rate_estimated (0.98, stricter: on the open-sky preset, single epoch,
  // 0.95 and 0.97 let wrong sets through, docs/algorithms.md).  Its two-component extension over the
  // fixed epochs (phase and code factors, iterated; record_fixed_rows() and insnav.gnss.rtk_noise) gives
  // the sigmas of [rtk] noise = "estimate".
  void update_noise_factor(double t, int nf) {
    white_code_ = true;
    const int m = build_rows(nf, 1);
    white_code_ = false;
    const double w = std::isfinite(noise_t_) && t > noise_t_ ? std::exp(-(t - noise_t_) / opt_.noise_window_s) : 1.0;
    noise_t_ = t;
    noise_q_ *= w;
    noise_dof_ *= w;
    if (m >= 4) {
      Eigen::Matrix<double, Eigen::Dynamic, 3, 0, kMaxRows, 3> H(m, 3), WH(m, 3);
      for (int r = 0; r < m; ++r) {
        H.row(r).setZero();
        for (int k = 0; k < nz_[r]; ++k)
          if (hc_[r][k] < 3) H(r, hc_[r][k]) += hv_[r][k];
      }
      llt_.compute(R_.topLeftCorner(m, m));
      if (llt_.info() == Eigen::Success) {
        RowVec wy = llt_.solve(y_.head(m));
        WH = llt_.solve(H);
        const Mat3 N = H.transpose() * WH;
        const Vec3 b = WH.transpose() * y_.head(m);
        Eigen::LDLT<Mat3> ldlt(N);
        const double q = y_.head(m).dot(wy) - b.dot(ldlt.solve(b));
        if (ldlt.info() == Eigen::Success && std::isfinite(q) && q >= 0.0) {
          noise_q_ += q;
          noise_dof_ += m - 3;
        }
      }
    }
    sr_factor_ = 1.0;
    if (noise_dof_ >= 1.0) {
      const double f = noise_dof_, g = 2.0 / (9.0 * f);
      const double c = 1.0 - g + noise_z_ * std::sqrt(g);  // chi2_{1-c}(F) = F c^3 (Wilson-Hilferty)
      const double lo = f * std::max(c, 1e-3) * std::max(c, 1e-3) * std::max(c, 1e-3);
      sr_factor_ = std::clamp(noise_q_ / lo, 0.01, 100.0);
    }
  }

  double lam(int rover_row, int f) const {
    return rover_[rover_row * RtkRow::kCols + RtkRow::kFreq0 + RtkRow::kPerFreq * f + 4];
  }

  bool valid(int c, int f, int code) const {
    if (code) return std::isfinite(sd_code_[c * kMaxFreq + f]);
    return std::isfinite(sd_phase_[c * kMaxFreq + f]) && amb_of_[key(rover_ + common_r_[c] * RtkRow::kCols) * kMaxFreq + f] >= 0;
  }

  // Kalman update over the compact state.  Returns false after resetting outlier ambiguities.
  bool kalman_update(int m, bool allow_reset, RtkEpoch& out) {
    Pa_.resize(na_, na_);
    xa_.resize(na_);
    for (int i = 0; i < na_; ++i) {
      xa_(i) = x_(act_[i]);
      for (int j = 0; j < na_; ++j) Pa_(i, j) = P_(act_[i], act_[j]);
    }
    // H is sparse (3 position columns and two ambiguities per row): P H^T and H P H^T by its
    // non-zeros, O(n m) and O(m^2) instead of O(n^2 m) and O(n m^2)
    PHt_.setZero(na_, m);
    for (int r = 0; r < m; ++r)
      for (int k = 0; k < nz_[r]; ++k) PHt_.col(r) += Pa_.col(hc_[r][k]) * hv_[r][k];
    S_ = R_.topLeftCorner(m, m);
    for (int a = 0; a < m; ++a)
      for (int k = 0; k < nz_[a]; ++k) S_.row(a) += hv_[a][k] * PHt_.row(hc_[a][k]);
    if (opt_.outlier_sigma > 0.0 && allow_reset) {
      bool reset_any = false;
      for (int i = 0; i < m; ++i) {
        if (row_code_[i]) continue;
        const double lim = opt_.outlier_sigma * std::sqrt(S_(i, i));
        if (std::abs(y_(i)) > lim && amb_[row_amb_[i]].lock > 0) {
          // re-initialise the ambiguity (an undetected slip or a multipath outlier)
          const int k = row_amb_[i];
          for (int c = 0; c < n_common_; ++c)
            if (key(rover_ + common_r_[c] * RtkRow::kCols) == amb_[k].sat) { init_amb(k, c, amb_[k].freq); break; }
          ++out.slips[kSlipOutlier];
          reset_any = true;
        }
      }
      if (reset_any) return false;
    }
    llt_.compute(S_);
    if (llt_.info() != Eigen::Success) return true;
    KT_ = PHt_.transpose();  // K^T = S^{-1} (P H^T)^T
    llt_.solveInPlace(KT_);
    K_ = KT_.transpose();
    xa_.noalias() += K_ * y_.head(m);
    Pa_.noalias() -= K_ * PHt_.transpose();  // P - K H P
    Pn_ = 0.5 * (Pa_ + Pa_.transpose());
    Pa_ = Pn_;
    for (int i = 0; i < na_; ++i) {
      x_(act_[i]) = xa_(i);
      for (int j = 0; j < na_; ++j) P_(act_[i], act_[j]) = Pa_(i, j);
    }
    return true;
  }

  // Code-only double-difference least squares (the DGPS solution; initialisation).
  bool dgps(Vec3& r, int nf, Mat3& P_r) {
    (void)nf;
    for (int it = 0; it < 10; ++it) {
      Mat3 N = Mat3::Zero();
      Vec3 b = Vec3::Zero();
      int nrows = 0;
      for (int sys = 0; sys < kNumSystems; ++sys) {
        int ref = -1;
        double best = -2.0;
        for (int c = 0; c < n_common_; ++c) {
          const double* rw = rover_ + common_r_[c] * RtkRow::kCols;
          const double* bw = base_ + common_b_[c] * RtkRow::kCols;
          if (sys_of(rw) != sys || !std::isfinite(rw[RtkRow::kFreq0]) || !std::isfinite(bw[RtkRow::kFreq0])) continue;
          Vec3 e;
          range(rw, r, e);
          const double up = e.dot(r.normalized());  // sin of the geocentric elevation
          if (up < std::sin(opt_.elevation_mask_rad)) continue;
          if (up > best) { best = up; ref = c; }
        }
        if (ref < 0) continue;
        Vec3 ei, eb;
        const double* ri = rover_ + common_r_[ref] * RtkRow::kCols;
        const double* bi = base_ + common_b_[ref] * RtkRow::kCols;
        const double sdi = (ri[RtkRow::kFreq0] - range(ri, r, ei)) - (bi[RtkRow::kFreq0] - range(bi, r_base_, eb));
        for (int c = 0; c < n_common_; ++c) {
          if (c == ref) continue;
          const double* rw = rover_ + common_r_[c] * RtkRow::kCols;
          const double* bw = base_ + common_b_[c] * RtkRow::kCols;
          if (sys_of(rw) != sys || !std::isfinite(rw[RtkRow::kFreq0]) || !std::isfinite(bw[RtkRow::kFreq0])) continue;
          Vec3 e;
          const double rho = range(rw, r, e);
          const double up = e.dot(r.normalized());
          if (up < std::sin(opt_.elevation_mask_rad)) continue;
          const double sd = (rw[RtkRow::kFreq0] - rho) - (bw[RtkRow::kFreq0] - range(bw, r_base_, eb));
          const Vec3 h = -(e - ei);
          const double w = up * up;  // ~ 1 / sigma^2 with sigma ~ 1 / sin(el)
          N += w * h * h.transpose();
          b += w * h * (sd - sdi);
          ++nrows;
        }
      }
      if (nrows < 3) return false;
      Eigen::LDLT<Mat3> ldlt(N);
      if (ldlt.info() != Eigen::Success) return false;
      const Vec3 dx = ldlt.solve(b);
      if (!dx.allFinite()) return false;
      r += dx;
      if (dx.norm() < 1e-4) {
        P_r = N.inverse() * std::pow(opt_.sigma_phase_a_m * opt_.code_phase_ratio, 2) * 4.0;
        return true;
      }
    }
    P_r = Mat3::Identity() * opt_.pos_init_sigma_m * opt_.pos_init_sigma_m;
    return true;
  }

  // Integer ambiguity resolution with partial AR; fills out (fixed position, ratio, counts).
  void resolve(RtkEpoch& out, bool kin) {
    // candidate double differences: per system and frequency, reference = highest elevation
    int n = 0;
    for (int sys = 0; sys < kNumSystems; ++sys) {
      if (sys == kGlonass && !opt_.glonass_ar) continue;
      for (int f = 0; f < kMaxFreq; ++f) {
        const int ref = highest_elevation_reference(
            kMaxAmbStates, [&](int k) { return eligible(amb_[k], sys, f); }, [&](int k) { return amb_[k].el; });
        if (ref < 0) continue;
        for (int k = 0; k < kMaxAmbStates; ++k) {
          if (k == ref || !eligible(amb_[k], sys, f) || n >= kMaxAmbiguities) continue;
          dd_j_[n] = k;
          dd_i_[n] = ref;
          dd_el_[n] = amb_[k].el;
          {
            const int sj = RtkLayout::kAmb + k, si = RtkLayout::kAmb + ref;
            dd_var_[n] = P_(sj, sj) - 2.0 * P_(sj, si) + P_(si, si);
          }
          ++n;
        }
      }
    }
    // order by elevation, highest first (or by variance, smallest first): partial AR drops from the end
    for (int i = 0; i < n; ++i) order_[i] = i;
    if (opt_.partial_by_variance)
      std::sort(order_.begin(), order_.begin() + n, [&](int a, int b) { return dd_var_[a] < dd_var_[b]; });
    else
      std::sort(order_.begin(), order_.begin() + n, [&](int a, int b) { return dd_el_[a] > dd_el_[b]; });
    if (record_float_) record_float(n);
    const bool kv = kin;
    ArSettings st;
    st.ratio_threshold = opt_.ratio_threshold;
    // subsets below min_fix_ambiguities only pass as every candidate of the epoch (FixValidator rule 1)
    st.min_fix = std::max(std::min(opt_.min_fix_ambiguities, n), 1);
    st.max_drops = opt_.max_partial_drops;
    st.min_success_rate = opt_.min_success_rate;
    st.min_success_rate_scaled = opt_.min_success_rate_estimated;
    st.success_variance_factor = opt_.min_success_rate_estimated > 0.0 ? sr_factor_ : 1.0;
    out.success_variance_factor = st.success_variance_factor;
    const FixRules rules{opt_.min_fix_ambiguities, opt_.confirm_epochs, opt_.confirm_max_ambiguities};
    const auto slot_j = [&](int p) { return dd_j_[order_[p]]; };
    const auto slot_i = [&](int p) { return dd_i_[order_[p]]; };
    const bool ok = ar_.resolve(
        n,
        [&](int p) {
          return x_(RtkLayout::kAmb + dd_j_[order_[p]]) - x_(RtkLayout::kAmb + dd_i_[order_[p]]);
        },
        [&](int p, int q) {
          const int sj = RtkLayout::kAmb + dd_j_[order_[p]], si = RtkLayout::kAmb + dd_i_[order_[p]];
          const int tj = RtkLayout::kAmb + dd_j_[order_[q]], ti = RtkLayout::kAmb + dd_i_[order_[q]];
          return P_(sj, tj) - P_(sj, ti) - P_(si, tj) + P_(si, ti);
        },
        st, [&](int n_fix) { return validator_(n_fix, n, slot_j, slot_i, ar_.a_fix(), rules); });
    out.ratio = ar_.ratio();
    out.success_rate = ar_.success_rate();
    out.success_rate_estimated = opt_.min_success_rate_estimated > 0.0 ? ar_.success_rate_scaled() : 0.0;
    if (!ok) return;  // no set passed, or a new small set waits for its repeats (FixValidator rule 2)
    const int nuse = ar_.n_used();
    // fixed solution: x_b - Q_ba Q_a^{-1} (a_hat - a_fix)
    Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, kMaxAmbiguities> Qba(6, nuse);
    for (int p = 0; p < nuse; ++p) {
      const int sj = RtkLayout::kAmb + dd_j_[order_[p]], si = RtkLayout::kAmb + dd_i_[order_[p]];
      for (int i = 0; i < 6; ++i) Qba(i, p) = P_(i, sj) - P_(i, si);
    }
    da_ = ar_.residual();
    ar_.solve_in_place(da_);
    const Eigen::Matrix<double, 6, 1> xb = x_.head<6>() - Qba * da_;
    AmbMat QabT(Qba.transpose());
    ar_.solve_in_place(QabT);
    const Eigen::Matrix<double, 6, 6> Pb = P_.topLeftCorner<6, 6>() - Qba * QabT;
    out.status = RtkStatus::kFixed;
    out.n_fix = nuse;
    out.r_e = xb.head<3>();
    if (kv && dt_epoch_ > 0.0) out.v_e = xb.tail<3>();  // else as the float (NaN: no epoch has observed it)
    out.P_r = Pb.topLeftCorner<3, 3>();
    if (record_fixed_) record_fixed_rows(nuse);
    if (opt_.ar_mode == ArMode::kFixAndHold) hold(nuse);
  }

  // The float AR problem of resolve()'s n ordered candidates (set_record_float).
  void record_float(int n) {
    float_.n = n;
    float_.a_hat.resize(n);
    float_.Qa.resize(n, n);
    float_.Qba.resize(3, n);
    float_.Qbb = P_.block<3, 3>(RtkLayout::kPos, RtkLayout::kPos);
    for (int p = 0; p < n; ++p) {
      const int sj = RtkLayout::kAmb + dd_j_[order_[p]], si = RtkLayout::kAmb + dd_i_[order_[p]];
      float_.a_hat(p) = x_(sj) - x_(si);
      for (int q = 0; q < n; ++q) {
        const int tj = RtkLayout::kAmb + dd_j_[order_[q]], ti = RtkLayout::kAmb + dd_i_[order_[q]];
        float_.Qa(p, q) = P_(sj, tj) - P_(sj, ti) - P_(si, tj) + P_(si, ti);
      }
      for (int i = 0; i < 3; ++i) float_.Qba(i, p) = P_(RtkLayout::kPos + i, sj) - P_(RtkLayout::kPos + i, si);
      float_.sat_j[p] = amb_[dd_j_[order_[p]]].sat;
      float_.sat_i[p] = amb_[dd_i_[order_[p]]].sat;
      float_.freq[p] = amb_[dd_j_[order_[p]]].freq;
    }
  }

  // The fixed epoch's double differences for the variance component estimation (FixedDdRow).  The
  // fixed set gives N_j - N_i for the ambiguity slots j fixed against the reference slot i of their
  // system and frequency (resolve()); a phase row of build_rows() (satellite c against its reference
  // r, both fixed) then has the integer DD ambiguity (N_c - N_i) - (N_r - N_i), which replaces the
  // float one.  Rows with an unfixed ambiguity or two wavelengths (GLONASS FDMA) are left out; the
  // code rows are taken with their white configured variance (no correlation or adaptive factor).
  void record_fixed_rows(int nuse) {
    fix_val_.fill(NAN);
    for (int p = 0; p < nuse; ++p) {
      fix_val_[dd_i_[order_[p]]] = 0.0;
      fix_val_[dd_j_[order_[p]]] = ar_.a_fix()(p);
    }
    const int nf = std::clamp(opt_.n_freq, 1, kMaxFreq);
    const double code_var = opt_.code_phase_ratio * opt_.code_phase_ratio;
    n_fixed_rows_ = 0;
    for (int code = 0; code < 2; ++code) {
      white_code_ = true;
      const int m = build_rows(nf, code);
      white_code_ = false;
      for (int r = 0; r < m && n_fixed_rows_ < 2 * kMaxRows; ++r) {
        const int c = row_c_[r], ref = row_ref_[r], f = row_f_[r];
        double y = y_(r);
        if (!code) {
          const int kj = row_amb_[r], ki = amb_row_[ref * kMaxFreq + f];
          const double lj = lam(common_r_[c], f), li = lam(common_r_[ref], f);
          if (!std::isfinite(fix_val_[kj]) || !std::isfinite(fix_val_[ki]) || lj != li) continue;
          y += lj * ((x_(RtkLayout::kAmb + kj) - x_(RtkLayout::kAmb + ki)) - (fix_val_[kj] - fix_val_[ki]));
        }
        FixedDdRow& o = fixed_rows_[n_fixed_rows_++];
        o.code = code;
        o.group = sys_of(rover_ + common_r_[c] * RtkRow::kCols) * kMaxFreq + f;
        o.y = y;
        o.h[0] = o.h[1] = o.h[2] = 0.0;
        for (int k = 0; k < nz_[r]; ++k)
          if (hc_[r][k] < 3) o.h[hc_[r][k]] += hv_[r][k];
        o.var_own = var_sd_[c] * (code ? code_var : 1.0);
        o.var_ref = var_sd_[ref] * (code ? code_var : 1.0);
      }
    }
  }

  bool eligible(const AmbSlot& a, int sys, int f) const {
    return a.sat >= 0 && a.used && !a.half && a.freq == f && a.sat / kMaxPrn == sys && a.lock >= opt_.min_lock_epochs &&
           a.el >= opt_.ar_elevation_mask_rad;
  }

  // Fix-and-hold: the fixed double differences as tight pseudo-measurements of the float filter.
  void hold(int nuse) {
    build_active(opt_.mode == RtkMode::kKinematic);
    const int m = std::min(nuse, kMaxRows);
    R_.resize(kMaxRows, kMaxRows);
    R_.topLeftCorner(m, m).setZero();
    for (int p = 0; p < m; ++p) {
      const int kj = dd_j_[order_[p]], ki = dd_i_[order_[p]];
      nz_[p] = 0;
      set_h(p, col_of_[kj], 1.0);
      set_h(p, col_of_[ki], -1.0);
      y_(p) = ar_.a_fix()(p) - (x_(RtkLayout::kAmb + kj) - x_(RtkLayout::kAmb + ki));
      R_(p, p) = opt_.hold_sigma_cycles * opt_.hold_sigma_cycles;
      row_code_[p] = 1;  // no outlier test on these
    }
    RtkEpoch dummy;
    kalman_update(m, false, dummy);
  }

  RtkOptions opt_;
  StateVec x_;
  StateMat P_;
  // P_ (always kMaxStates x kMaxStates) is zero outside its top-left p_dim_ x p_dim_ corner: p_dim_ is
  // one past the highest state slot given a variance since the last zeroing (init_amb, manage_iono)
  int p_dim_ = kMaxStates;

  // Zero P_ where it can be non-zero: instantaneous AR re-initialises every epoch, and the full
  // 190 x 190 matrix (282 KiB) would be written for the few slots in use.
  void zero_covariance() {
    P_.topLeftCorner(p_dim_, p_dim_).setZero();
    p_dim_ = RtkLayout::kAmb;
  }
  std::array<int, kMaxSatKeys * kMaxFreq> amb_of_{};
  std::array<AmbSlot, kMaxAmbStates> amb_{};
  std::array<int, kMaxSatKeys> iono_of_{};           // satellite key -> ionosphere slot (-1: none)
  std::array<IonoSlot, kMaxIonoStates> iono_{};
  bool initialized_ = false;
  double t_prev_ = NAN;
  SlipDetector rover_slip_, base_slip_;
  std::array<std::uint8_t, kMaxSatKeys * kMaxFreq> flags_r_{}, flags_b_{};
  std::array<int, kMaxSatKeys> base_of_{}, common_r_{}, common_b_{};
  std::array<double, kMaxSatKeys> clock_buf_{};  // init_amb's single-differenced code residuals
  std::array<double, kMaxSatKeys> el_r_{}, el_b_{}, var_sd_{};
  std::array<bool, kMaxSatKeys> use_{};
  std::array<Vec3, kMaxSatKeys> e_{};
  std::array<int, kMaxSatKeys * kMaxFreq> amb_row_{};
  std::array<double, kMaxSatKeys * kMaxFreq> sd_phase_{}, sd_code_{};
  int n_common_ = 0, n_used_sats_ = 0, n_phase_rows_ = 0;
  double dt_epoch_ = 0.0;  // time since the previous epoch [s] (0 on the first)
  double code_scale_ = 1.0;  // adaptive variance factor of the code rows (update_code_scale)
  // code variance factor for the success rate (update_noise_factor): sums, time, factor, quantile
  double noise_q_ = 0.0, noise_dof_ = 0.0, noise_t_ = NAN, sr_factor_ = 1.0;
  double noise_z_ = 0.0;  // Phi^-1(1 - noise_confidence), set by the constructor
  bool white_code_ = false;  // code_var_factor() returns 1 (the configured white code)
  bool record_fixed_ = false;  // record_fixed_rows() at every fixed epoch
  bool record_float_ = false;  // record_float() at every epoch with AR
  FloatProblem float_;
  int n_fixed_rows_ = 0;
  std::array<FixedDdRow, 2 * kMaxRows> fixed_rows_{};
  std::array<double, kMaxAmbStates> fix_val_{};  // fixed DD ambiguity of a slot against its reference [cycles]
  FixValidator<kMaxAmbStates> validator_;  // fix validation over epochs (ambiguity_resolution.hpp)

  const double* rover_ = nullptr;
  const double* base_ = nullptr;
  Vec3 r_base_ = Vec3::Zero();
  double lat_b_ = 0.0, h_b_ = 0.0, lat_r_ = 0.0, h_r_ = 0.0;
  // update workspace (compact state)
  int na_ = 0;
  std::array<int, kMaxStates> act_{};
  std::array<int, kMaxAmbStates> col_of_{};
  std::array<int, kMaxIonoStates> iono_col_{};
  std::array<int, kMaxAmbStates> perr_col_{};
  std::array<int, kMaxRows> row_amb_{}, row_code_{}, row_c_{}, row_ref_{}, row_f_{}, nz_{};
  // non-zero columns of each row of H (3 position, 2 ambiguities, 2 ionosphere states, 2 phase errors)
  // and their values
  std::array<std::array<int, 9>, kMaxRows> hc_{};
  std::array<std::array<double, 9>, kMaxRows> hv_{};
  void set_h(int r, int col, double v) {
    for (int k = 0; k < nz_[r]; ++k)
      if (hc_[r][k] == col) { hv_[r][k] += v; return; }
    hc_[r][nz_[r]] = col;
    hv_[r][nz_[r]] = v;
    ++nz_[r];
  }

  RowMat R_, S_;
  RowVec y_;
  StateMat Pa_, Pn_;
  StateVec xa_;
  KMat PHt_, K_;
  HMat KT_;
  Eigen::LLT<RowMat> llt_{kMaxRows};
  // AR workspace (gnss/ambiguity_resolution.hpp)
  PartialAr ar_;
  std::array<int, kMaxAmbiguities> dd_j_{}, dd_i_{}, order_{};
  std::array<double, kMaxAmbiguities> dd_el_{}, dd_var_{};
  AmbVec da_;
};

}  // namespace insnav::gnss
