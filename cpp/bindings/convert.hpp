// Python -> core conversions shared by every binder: config dicts (unknown
// keys are errors), the IMU arrays, the initial state, P0, the IMU
// correction, loose GNSS fixes and tight epochs.  A binder is then its
// filter's own config and nothing else.
#pragma once

#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/engine/loose_engine.hpp"
#include "insnav/engine/tight_engine.hpp"

namespace insnav::py_bind {

inline double num(const py::dict& d, const char* key, double dflt) {
  return d.contains(key) ? py::cast<double>(d[key]) : dflt;
}

inline bool flag(const py::dict& d, const char* key, bool dflt) {
  return d.contains(key) ? py::cast<bool>(d[key]) : dflt;
}

/// 1 value (broadcast) or 3.
inline Vec3 vec3_or_scalar(const py::dict& d, const char* key, const Vec3& dflt) {
  if (!d.contains(key)) return dflt;
  DArray a = py::cast<DArray>(d[key]);
  if (a.size() == 1) return Vec3::Constant(a.data()[0]);
  if (a.size() != 3) throw py::value_error(std::string("key '") + key + "': expected 1 or 3 values");
  return Vec3(a.data()[0], a.data()[1], a.data()[2]);
}

/// Any key of d not in `known` (or in `known2`) is a ValueError naming it and `what`.
inline void reject_unknown(const py::dict& d, std::initializer_list<const char*> known, const char* what,
                           std::initializer_list<const char*> known2 = {}) {
  for (auto item : d) {
    const std::string k = py::cast<std::string>(item.first);
    bool ok = false;
    for (const char* kk : known) ok = ok || (k == kk);
    for (const char* kk : known2) ok = ok || (k == kk);
    if (!ok) throw py::value_error(std::string("unknown ") + what + " key '" + k + "'");
  }
}

/// The engine timing keys every config shares.
inline void timing_from(const py::dict& d, double& propagation_interval, double& cycle_period, GateConfig& gate,
                        int& output_decimation) {
  propagation_interval = num(d, "propagation_interval", propagation_interval);
  cycle_period = num(d, "cycle_period", cycle_period);
  gate.chi2 = num(d, "gate_chi2", gate.chi2);
  gate.prob = num(d, "gate_prob", gate.prob);
  gate.reopen_after = static_cast<int>(num(d, "gate_reopen_after", gate.reopen_after));
  gate.mismatch = num(d, "gate_mismatch", gate.mismatch);
  gate.outage_s = num(d, "gate_outage_s", gate.outage_s);
  if (!(gate.chi2 >= 0.0) || !(gate.prob >= 0.0 && gate.prob < 1.0) || gate.reopen_after < 0)
    throw py::value_error("gate: need gate_chi2 >= 0, 0 <= gate_prob < 1, gate_reopen_after >= 0");
  if (!(gate.mismatch >= 0.0) || !(gate.outage_s >= 0.0))
    throw py::value_error("gate: need gate_mismatch >= 0 and gate_outage_s >= 0");
  output_decimation = static_cast<int>(num(d, "output_decimation", output_decimation));
  if (!(propagation_interval > 0.0)) throw py::value_error("propagation_interval must be > 0");
  if (!(cycle_period > 0.0)) throw py::value_error("cycle_period must be > 0");
  if (output_decimation < 1) throw py::value_error("output_decimation must be >= 1");
}

inline UtParams ut_from(const py::dict& d) {
  UtParams ut;
  ut.alpha = num(d, "ut_alpha", ut.alpha);
  ut.beta = num(d, "ut_beta", ut.beta);
  ut.kappa = num(d, "ut_kappa", ut.kappa);
  return ut;
}

#define INSNAV_TIMING_KEYS "lever_arm_b", "propagation_interval", "cycle_period", "gate_chi2", "gate_prob", "gate_reopen_after", "gate_mismatch", "gate_outage_s", "output_decimation"
#define INSNAV_UT_KEYS "ut_alpha", "ut_beta", "ut_kappa"

/// LooseConfig from a dict; `extra` keys are allowed (and read by the caller).
/// Engine-config keys of the self-calibration states (layout.hpp): the
/// IMU-GNSS time offset and the GNSS lever arm as filter states, and the
/// initial time-offset estimate [s].
#define INSNAV_SELFCAL_KEYS "estimate_time_offset", "estimate_lever_arm", "estimate_odo_lever_arm", "time_offset0_s"

/// Which self-calibration states a run asks for.
struct SelfCal {
  bool time_offset = false, lever_arm = false, odo_lever_arm = false;
  double time_offset0_s = 0.0;
  bool any() const { return time_offset || lever_arm || odo_lever_arm; }
};

inline SelfCal selfcal_from(const py::dict& d) {
  SelfCal s;
  s.time_offset = flag(d, "estimate_time_offset", false);
  s.lever_arm = flag(d, "estimate_lever_arm", false);
  s.odo_lever_arm = flag(d, "estimate_odo_lever_arm", false);
  s.time_offset0_s = num(d, "time_offset0_s", 0.0);
  if (!std::isfinite(s.time_offset0_s)) throw py::value_error("time_offset0_s must be finite");
  return s;
}

inline LooseConfig loose_config_from(const py::dict& d, const char* what, std::initializer_list<const char*> extra) {
  reject_unknown(d, {INSNAV_TIMING_KEYS, "use_position", "use_velocity"}, what, extra);
  LooseConfig c;
  c.lever_arm_b = vec3_or_scalar(d, "lever_arm_b", c.lever_arm_b);
  timing_from(d, c.propagation_interval, c.cycle_period, c.gate, c.output_decimation);
  c.use_position = flag(d, "use_position", true);
  c.use_velocity = flag(d, "use_velocity", true);
  return c;
}

/// The adaptive process-noise keys adaptive_q_window, adaptive_q_min, adaptive_q_max
/// (filter/adaptive_noise.hpp; loose and tight runs), validated; q holds the defaults.
inline AdaptiveNoiseConfig adaptive_q_from(const py::dict& d, AdaptiveNoiseConfig q) {
  const double wq = num(d, "adaptive_q_window", 0.0);
  if (!(wq >= 0.0 && wq <= kMaxAdaptiveWindow && wq == std::floor(wq)))
    throw py::value_error("adaptive_q_window must be an integer in 0.." + std::to_string(kMaxAdaptiveWindow));
  q.window = static_cast<int>(wq);
  q.min_fraction = num(d, "adaptive_q_min", q.min_fraction);
  q.max_factor = num(d, "adaptive_q_max", q.max_factor);
  if (!(q.min_fraction > 0.0 && q.min_fraction <= 1.0 && q.max_factor >= 1.0 && std::isfinite(q.max_factor)))
    throw py::value_error("adaptive_q_min must be in (0, 1] and adaptive_q_max finite and >= 1");
  return q;
}

inline TightConfig tight_config_from(const py::dict& d) {
  reject_unknown(d, {INSNAV_TIMING_KEYS, "use_pseudorange", "use_rate", INSNAV_UT_KEYS, "smooth"}, "tight engine config",
                 {"robust_screening", "robust_chi2_row", "robust_igg_k0", "robust_igg_k1", "robust_clock_jump",
                  "robust_clock_jump_sigma", "robust_clock_jump_min_rows", "robust_huber", "robust_huber_k",
                  "robust_fde_max_sats", "robust_fde_min_rows", "robust_cusum_k", "robust_cusum_h",
                   "robust_cusum_hold_s", "robust_cusum_min_pseudoranges", "robust_variance_window",
                   "robust_variance_min_rows", "tdcp", "tdcp_slip_threshold_cycles",
                   "tdcp_chi2_row", "pr_gm_sigma_m", "pr_gm_tau_s", "pr_gm_max_gap_s", "adaptive_q_window",
                   "adaptive_q_min", "adaptive_q_max", "standstill_q_scale", INSNAV_SELFCAL_KEYS});
  TightConfig c;
  c.lever_arm_b = vec3_or_scalar(d, "lever_arm_b", c.lever_arm_b);
  timing_from(d, c.propagation_interval, c.cycle_period, c.gate, c.output_decimation);
  c.use_pseudorange = flag(d, "use_pseudorange", true);
  c.use_rate = flag(d, "use_rate", true);
  RobustConfig& r = c.robust;
  r.screening = flag(d, "robust_screening", r.screening);
  r.chi2_row = num(d, "robust_chi2_row", r.chi2_row);
  r.igg_k0 = num(d, "robust_igg_k0", r.igg_k0);
  r.igg_k1 = num(d, "robust_igg_k1", r.igg_k1);
  r.clock_jump = flag(d, "robust_clock_jump", r.clock_jump);
  r.clock_jump_sigma = num(d, "robust_clock_jump_sigma", r.clock_jump_sigma);
  r.clock_jump_min_rows = static_cast<int>(num(d, "robust_clock_jump_min_rows", r.clock_jump_min_rows));
  if (!(r.chi2_row > 0.0)) throw py::value_error("robust_chi2_row must be > 0");
  if (!(r.igg_k0 > 0.0 && r.igg_k1 > r.igg_k0)) throw py::value_error("robust IGG-III: need 0 < k0 < k1");
  if (!(r.clock_jump_sigma > 0.0)) throw py::value_error("robust_clock_jump_sigma must be > 0");
  if (r.clock_jump_min_rows < 1) throw py::value_error("robust_clock_jump_min_rows must be >= 1");
  r.huber = flag(d, "robust_huber", r.huber);
  r.huber_k = num(d, "robust_huber_k", r.huber_k);
  r.fde_max_sats = static_cast<int>(num(d, "robust_fde_max_sats", r.fde_max_sats));
  r.fde_min_rows = static_cast<int>(num(d, "robust_fde_min_rows", r.fde_min_rows));
  r.cusum_k = num(d, "robust_cusum_k", r.cusum_k);
  r.cusum_h = num(d, "robust_cusum_h", r.cusum_h);
  r.cusum_hold_s = num(d, "robust_cusum_hold_s", r.cusum_hold_s);
  r.cusum_min_pseudoranges = static_cast<int>(num(d, "robust_cusum_min_pseudoranges", r.cusum_min_pseudoranges));
  if (r.cusum_min_pseudoranges < 0) throw py::value_error("robust_cusum_min_pseudoranges must be >= 0");
  r.variance_window = static_cast<int>(num(d, "robust_variance_window", r.variance_window));
  r.variance_min_rows = static_cast<int>(num(d, "robust_variance_min_rows", r.variance_min_rows));
  if (r.variance_window < 0 || r.variance_window > kMaxVarianceWindow || r.variance_min_rows < 1)
    throw py::value_error("robust_variance_window must be in 0 .. " + std::to_string(kMaxVarianceWindow) +
                          " and robust_variance_min_rows >= 1");
  if (!(r.huber_k > 0.0)) throw py::value_error("robust_huber_k must be > 0");
  if (r.fde_max_sats < 0 || r.fde_min_rows < 0) throw py::value_error("robust_fde_max_sats, robust_fde_min_rows must be >= 0");
  if (!(r.cusum_k >= 0.0) || !(r.cusum_h >= 0.0) || !(r.cusum_hold_s >= 0.0))
    throw py::value_error("robust_cusum_k, robust_cusum_h, robust_cusum_hold_s must be >= 0");
  TdcpConfig& td = c.tdcp;  // time-differenced carrier phase (meas/tdcp.hpp)
  td.enabled = flag(d, "tdcp", td.enabled);
  td.slip_threshold_cycles = num(d, "tdcp_slip_threshold_cycles", td.slip_threshold_cycles);
  td.chi2_row = num(d, "tdcp_chi2_row", td.chi2_row);
  if (!(td.slip_threshold_cycles > 0.0) || !(td.chi2_row > 0.0))
    throw py::value_error("tdcp_slip_threshold_cycles and tdcp_chi2_row must be > 0");
  PseudorangeGmConfig& gm = c.pr_gm;  // Gauss-Markov pseudorange errors (meas/pseudorange_gm.hpp)
  gm.sigma_m = num(d, "pr_gm_sigma_m", gm.sigma_m);
  gm.tau_s = num(d, "pr_gm_tau_s", gm.tau_s);
  gm.max_gap_s = num(d, "pr_gm_max_gap_s", gm.max_gap_s);
  if (!(gm.sigma_m >= 0.0) || !std::isfinite(gm.sigma_m)) throw py::value_error("pr_gm_sigma_m must be >= 0 and finite");
  if (!(gm.tau_s > 0.0) || !(gm.max_gap_s > 0.0)) throw py::value_error("pr_gm_tau_s and pr_gm_max_gap_s must be > 0");
  c.adaptive_q = adaptive_q_from(d, c.adaptive_q);  // adaptive process noise (filter/adaptive_noise.hpp)
  c.standstill_q_scale = num(d, "standstill_q_scale", c.standstill_q_scale);  // engine/tight_engine.hpp
  if (!(c.standstill_q_scale > 0.0 && std::isfinite(c.standstill_q_scale)))
    throw py::value_error("standstill_q_scale must be finite and > 0 (1: off)");
  return c;
}


/// The IMU arrays t (n,), dtheta_b (n,3), dv_b (n,3), shapes checked.
struct ImuArrays {
  py::ssize_t n = 0;
  const double *t = nullptr, *dtheta_b = nullptr, *dv_b = nullptr;
};

inline ImuArrays imu_arrays(const DArray& t, const DArray& dtheta_b, const DArray& dv_b) {
  const py::ssize_t n = t.size();
  require_shape(t, n, -1, "t");
  require_shape(dtheta_b, n, 3, "dtheta_b");
  require_shape(dv_b, n, 3, "dv_b");
  return {n, t.data(), dtheta_b.data(), dv_b.data()};
}

/// init = (t0, lat, lon [rad], h [m], vN, vE, vD [m/s], roll, pitch, yaw [rad]).
inline NavState nav_state_from(const DArray& init) {
  if (init.size() != 10)
    throw py::value_error("init: expected 10 values (t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw)");
  const double* pi = init.data();
  NavState nav;
  nav.t = pi[0];
  nav.lat = pi[1];
  nav.lon = pi[2];
  nav.h = pi[3];
  nav.v_n = Vec3(pi[4], pi[5], pi[6]);
  nav.q_nb = quat_from_euler(Vec3(pi[7], pi[8], pi[9]));
  return nav;
}

/// imu_correction = (acc bias, gyro bias, acc scale, gyro scale), 12 values SI.
inline ImuCorrection imu_correction_from(const DArray& corr0) {
  if (corr0.size() != 12) throw py::value_error("imu_correction: expected 12 values");
  const double* pc = corr0.data();
  ImuCorrection corr;
  corr.acc_bias = Vec3(pc[0], pc[1], pc[2]);
  corr.gyro_bias = Vec3(pc[3], pc[4], pc[5]);
  corr.acc_scale = Vec3(pc[6], pc[7], pc[8]);
  corr.gyro_scale = Vec3(pc[9], pc[10], pc[11]);
  return corr;
}

template <class L>
StateCov<L> state_cov_from(const DArray& P0) {
  constexpr int ns = L::kSize;
  require_shape(P0, ns, ns, "P0");
  return Eigen::Map<const Eigen::Matrix<double, ns, ns, Eigen::RowMajor>>(P0.data());
}

/// A loose fix from its row: t, lat, lon [rad], h, vN, vE, vD, sN, sE, sD, svN, svE, svD
/// (NaN position or velocity: that part absent).
inline GnssFix gnss_fix_from(double t_valid, const double* r) {
  GnssFix f;
  f.t = t_valid;
  f.lat = r[0];
  f.lon = r[1];
  f.h = r[2];
  f.v_n = Vec3(r[3], r[4], r[5]);
  f.sigma_pos_n = Vec3(r[6], r[7], r[8]);
  f.sigma_vel_n = Vec3(r[9], r[10], r[11]);
  f.has_pos = std::isfinite(r[0]) && std::isfinite(r[1]) && std::isfinite(r[2]);
  f.has_vel = f.v_n.allFinite() && f.sigma_vel_n.allFinite();
  return f;
}

/// Tight epochs and their satellites, validated: epoch_t (E,), epoch_start
/// (E+1,) into sats (M, 12) = pr, prr, x, y, z, vx, vy, vz, clock_bias_m,
/// clock_drift_mps, sigma_pr, sigma_prr.
struct TightInputs {
  std::vector<TightEpoch> epochs;
  std::vector<SatObservation> sats;
  py::ssize_t E = 0, M = 0;
};

using I64Array = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

/// One satellite row of `sats` (12 values, the order above), its system index
/// (insnav.gnss.systems: 0 G, 1 R, 2 E, 3 C) and PRN, validated (`row` for the messages).
inline SatObservation sat_observation_from(const double* r, std::int64_t system, std::int64_t prn, py::ssize_t row) {
  SatObservation o;
  o.pseudorange_m = r[0];
  o.pseudorange_rate_mps = r[1];
  o.r_e = Vec3(r[2], r[3], r[4]);
  o.v_e = Vec3(r[5], r[6], r[7]);
  o.clock_bias_m = r[8];
  o.clock_drift_mps = r[9];
  o.sigma_pr_m = r[10];
  o.sigma_prr_mps = r[11];
  if (system < 0 || system >= kNumSystems)
    throw py::value_error("system: index " + std::to_string(system) + " at row " + std::to_string(row) +
                          " (expected 0 G, 1 R, 2 E, 3 C)");
  o.system = static_cast<int>(system);
  o.prn = static_cast<int>(std::max<std::int64_t>(0, prn));
  const bool any = std::isfinite(o.pseudorange_m) || std::isfinite(o.pseudorange_rate_mps);
  if (any && !(o.r_e.allFinite() && o.v_e.allFinite() && std::isfinite(o.clock_bias_m) &&
               std::isfinite(o.clock_drift_mps)))
    throw py::value_error("sats: non-finite satellite state at row " + std::to_string(row));
  if (std::isfinite(o.pseudorange_m) && !(o.sigma_pr_m > 0.0 && std::isfinite(o.sigma_pr_m)))
    throw py::value_error("sats: sigma_pr must be finite and > 0 at row " + std::to_string(row));
  if (std::isfinite(o.pseudorange_rate_mps) && !(o.sigma_prr_mps > 0.0 && std::isfinite(o.sigma_prr_mps)))
    throw py::value_error("sats: sigma_prr must be finite and > 0 at row " + std::to_string(row));
  return o;
}

/// system: None (every row GPS) or (M,) int, each in [0, kNumSystems) (insnav.gnss.systems index).
inline TightInputs tight_inputs_from(const DArray& epoch_t, const I64Array& epoch_start, const DArray& sats,
                                     const py::object& system = py::none(), const py::object& prn = py::none()) {
  TightInputs in;
  in.E = epoch_t.size();
  require_shape(epoch_t, in.E, -1, "epoch_t");
  if (epoch_start.ndim() != 1 || epoch_start.shape(0) != in.E + 1)
    throw py::value_error("epoch_start: expected shape (" + std::to_string(in.E + 1) + ",)");
  in.M = sats.ndim() == 2 ? sats.shape(0) : 0;
  if (in.M > 0) require_shape(sats, in.M, 12, "sats");
  const std::int64_t* es = epoch_start.data();
  in.epochs.resize(static_cast<size_t>(in.E));
  for (py::ssize_t i = 0; i < in.E; ++i) {
    if (es[i] < 0 || es[i + 1] < es[i] || es[i + 1] > in.M)
      throw py::value_error("epoch_start: bad range at epoch " + std::to_string(i));
    in.epochs[i].t = epoch_t.data()[i];
    in.epochs[i].begin = es[i];
    in.epochs[i].end = es[i + 1];
    if (i > 0 && !(in.epochs[i].t > in.epochs[i - 1].t))
      throw py::value_error("epoch_t: not strictly increasing at epoch " + std::to_string(i));
  }
  in.sats.resize(static_cast<size_t>(in.M));
  const double* ps = in.M ? sats.data() : nullptr;
  I64Array sys;
  if (!system.is_none()) {
    sys = py::cast<I64Array>(system);
    if (sys.ndim() != 1 || sys.shape(0) != in.M)
      throw py::value_error("system: expected shape (" + std::to_string(in.M) + ",)");
  }
  I64Array prns;
  if (!prn.is_none()) {
    prns = py::cast<I64Array>(prn);
    if (prns.ndim() != 1 || prns.shape(0) != in.M)
      throw py::value_error("prn: expected shape (" + std::to_string(in.M) + ",)");
  }
  for (py::ssize_t i = 0; i < in.M; ++i)
    in.sats[i] = sat_observation_from(ps + 12 * i, sys.size() ? sys.data()[i] : 0, prns.size() ? prns.data()[i] : 0, i);
  return in;
}

/// The carrier phase of the tight rows: None, or (M, 4) phase [m], wavelength [m],
/// zero-difference sigma [m], LLI (meas/tdcp.hpp, PhaseObservation).
inline std::vector<PhaseObservation> phase_rows_from(const py::object& phase, const TightInputs& in) {
  std::vector<PhaseObservation> out;
  if (phase.is_none()) return out;
  const DArray a = py::cast<DArray>(phase);
  if (a.ndim() != 2 || a.shape(0) != in.M || a.shape(1) != 4)
    throw py::value_error("phase: expected shape (" + std::to_string(in.M) +
                          ", 4) (phase [m], wavelength [m], sigma [m], LLI)");
  out.resize(static_cast<size_t>(in.M));
  for (py::ssize_t i = 0; i < in.M; ++i) {
    const double* r = a.data() + 4 * i;
    PhaseObservation& p = out[static_cast<size_t>(i)];
    p.phase_m = r[0];
    p.wavelength_m = r[1];
    p.sigma_m = r[2];
    p.lli = std::isfinite(r[3]) ? static_cast<int>(r[3]) : 0;
    if (!std::isfinite(p.phase_m)) continue;
    const SatObservation& o = in.sats[static_cast<size_t>(i)];
    if (!(p.wavelength_m > 0.0) || !(p.sigma_m > 0.0))
      throw py::value_error("phase: wavelength and sigma must be > 0 at row " + std::to_string(i));
    if (!(o.r_e.allFinite() && std::isfinite(o.clock_bias_m)))
      throw py::value_error("phase: non-finite satellite state at row " + std::to_string(i));
    if (o.prn <= 0) throw py::value_error("phase: row " + std::to_string(i) + " needs its satellite number (prn)");
  }
  return out;
}

inline double clock0_bias(const DArray& clock0) {
  if (clock0.size() != 2) throw py::value_error("clock0: expected 2 values (bias m, drift m/s)");
  return clock0.data()[0];
}

}  // namespace insnav::py_bind
