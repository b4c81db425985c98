// Tightly coupled runs with the seed 004 filters on Layout20: the
// improved UPF, the bootstrap PF and the (fading) UKF, on the tight engine and
// pseudorange measurement of seed 003 (engine/tight_engine.hpp,
// meas/pseudorange.hpp).  The input format is that of _core.run_tight
// (bind_tight.cpp, whose parsing is repeated here because it is file-local
// there); the whole loop runs in C++ with the GIL released.
#include <chrono>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "common.hpp"
#include "insnav/engine/tight_engine.hpp"
#include "insnav/filter/layout20.hpp"
#include "insnav/filter/particle_filter.hpp"
#include "insnav/filter/upf.hpp"

namespace insnav::py_bind {

namespace {

using L20 = Layout20;

double num(const py::dict& d, const char* key, double dflt) {
  return d.contains(key) ? py::cast<double>(d[key]) : dflt;
}

void reject_unknown(const py::dict& d, const std::vector<std::string>& known, const char* what) {
  for (auto item : d) {
    const std::string k = py::cast<std::string>(item.first);
    bool ok = false;
    for (const auto& kk : known) ok = ok || (k == kk);
    if (!ok) throw py::value_error(std::string("unknown ") + what + " key '" + k + "'");
  }
}

TightConfig tight_config(const py::dict& d) {
  reject_unknown(d,
                 {"lever_arm_b", "propagation_interval", "cycle_period", "gate_chi2", "use_pseudorange", "use_rate",
                  "output_decimation", "ut_alpha", "ut_beta", "ut_kappa"},
                 "tight engine config");
  TightConfig c;
  if (d.contains("lever_arm_b")) c.lever_arm_b = vec3_from(py::cast<DArray>(d["lever_arm_b"]), "lever_arm_b");
  c.propagation_interval = num(d, "propagation_interval", c.propagation_interval);
  c.cycle_period = num(d, "cycle_period", c.cycle_period);
  c.gate_chi2 = num(d, "gate_chi2", c.gate_chi2);
  c.use_pseudorange = d.contains("use_pseudorange") ? py::cast<bool>(d["use_pseudorange"]) : true;
  c.use_rate = d.contains("use_rate") ? py::cast<bool>(d["use_rate"]) : true;
  c.output_decimation = static_cast<int>(num(d, "output_decimation", 1));
  if (!(c.propagation_interval > 0.0)) throw py::value_error("propagation_interval must be > 0");
  if (!(c.cycle_period > 0.0)) throw py::value_error("cycle_period must be > 0");
  if (c.output_decimation < 1) throw py::value_error("output_decimation must be >= 1");
  return c;
}

struct ParticleSetup {
  ParticleParams pp;
  FadingParams<L20::kSize> fp;
  UpfOptions opt;
};

ParticleSetup particle_setup(const py::dict& d) {
  reject_unknown(d,
                 {"particles", "seed", "resample_threshold", "roughening", "rk4_step", "fading", "rho", "beta",
                  "eta_max", "alpha", "fading_memory", "sample", "kernel_h2", "init_yaw_halfwidth", "temper_stages",
                  "divergence_chi2", "noise_floor"},
                 "particle config");
  ParticleSetup s;
  s.pp.particles = static_cast<int>(num(d, "particles", s.pp.particles));
  s.pp.seed = d.contains("seed") ? py::cast<std::uint64_t>(d["seed"]) : s.pp.seed;
  s.pp.resample_threshold = num(d, "resample_threshold", s.pp.resample_threshold);
  s.pp.roughening = num(d, "roughening", s.pp.roughening);
  s.pp.rk4_step = num(d, "rk4_step", s.pp.rk4_step);
  s.fp.enabled = d.contains("fading") ? py::cast<bool>(d["fading"]) : s.fp.enabled;
  s.fp.rho = num(d, "rho", s.fp.rho);
  s.fp.beta = num(d, "beta", s.fp.beta);
  s.fp.eta_max = num(d, "eta_max", s.fp.eta_max);
  if (d.contains("fading_memory")) {
    const auto form = py::cast<std::string>(d["fading_memory"]);
    if (form == "innovation") s.fp.memory = FadingMemoryForm::kInnovation;
    else if (form == "nis") s.fp.memory = FadingMemoryForm::kNis;
    else throw py::value_error("fading_memory: expected 'innovation' (seed 004 eq. (6)) or 'nis', got '" + form + "'");
  }
  if (d.contains("alpha")) {
    DArray a = py::cast<DArray>(d["alpha"]);
    if (a.size() == 1) s.fp.alpha.setConstant(a.data()[0]);
    else if (a.size() == L20::kSize)
      for (int i = 0; i < L20::kSize; ++i) s.fp.alpha[i] = a.data()[i];
    else throw py::value_error("alpha: expected 1 or 20 values");
  }
  s.opt.sample = d.contains("sample") ? py::cast<bool>(d["sample"]) : true;
  s.opt.kernel_h2 = num(d, "kernel_h2", s.opt.kernel_h2);
  s.opt.init_yaw_halfwidth = num(d, "init_yaw_halfwidth", s.opt.init_yaw_halfwidth);
  s.pp.temper_stages = static_cast<int>(num(d, "temper_stages", s.pp.temper_stages));
  s.pp.divergence_chi2 = num(d, "divergence_chi2", s.pp.divergence_chi2);
  s.pp.noise_floor = num(d, "noise_floor", s.pp.noise_floor);
  if (!(s.pp.noise_floor >= 0.0)) throw py::value_error("noise_floor must be >= 0");
  if (!(s.opt.kernel_h2 >= 0.0 && s.opt.kernel_h2 < 1.0)) throw py::value_error("kernel_h2 must be in [0, 1)");
  if (!(s.opt.init_yaw_halfwidth >= 0.0 && s.opt.init_yaw_halfwidth <= M_PI))
    throw py::value_error("init_yaw_halfwidth must be in [0, pi] rad");
  if (s.pp.temper_stages < 1 || s.pp.temper_stages > 64) throw py::value_error("temper_stages must be in [1, 64]");
  if (!(s.pp.divergence_chi2 > 0.0)) throw py::value_error("divergence_chi2 must be > 0");
  if (s.pp.particles < 1 || s.pp.particles > s.pp.max_particles)
    throw py::value_error("particles must be in [1, " + std::to_string(s.pp.max_particles) + "]");
  if (!(s.pp.resample_threshold >= 0.0 && s.pp.resample_threshold <= 1.0))
    throw py::value_error("resample_threshold must be in [0, 1]");
  if (!(s.pp.roughening >= 0.0)) throw py::value_error("roughening must be >= 0");
  if (!(s.pp.rk4_step >= 0.0)) throw py::value_error("rk4_step must be >= 0");
  if (!(s.fp.rho > 0.0 && s.fp.rho <= 1.0)) throw py::value_error("rho must be in (0, 1]");
  if (!(s.fp.beta >= 1.0)) throw py::value_error("beta must be >= 1");
  if (!(s.fp.eta_max >= 1.0)) throw py::value_error("eta_max must be >= 1");
  if (!(s.fp.alpha.minCoeff() >= 0.0)) throw py::value_error("alpha values must be >= 0 (0: no fading of that state)");
  return s;
}

template <class Filter>
void configure(Filter& f, const ImuErrorModel& model, const UtParams& ut, const ParticleSetup& s);

template <>
void configure(Upf<L20>& f, const ImuErrorModel& model, const UtParams& ut, const ParticleSetup& s) {
  f = Upf<L20>(model, ut, s.pp, s.fp, s.opt);
}
template <>
void configure(ParticleFilter<L20>& f, const ImuErrorModel& model, const UtParams&, const ParticleSetup& s) {
  f = ParticleFilter<L20>(model, s.pp);
}
template <>
void configure(FadingUkf<L20>& f, const ImuErrorModel& model, const UtParams& ut, const ParticleSetup& s) {
  f = FadingUkf<L20>(model, ut, s.fp, s.pp.rk4_step);
}

template <class Filter>
py::dict run_impl(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, const DArray& epoch_t,
                  const py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>& epoch_start,
                  const DArray& sats, const DArray& init, const DArray& P0, const DArray& corr0, const DArray& clock0,
                  const ImuErrorModel& model, const TightConfig& cfg, const UtParams& ut, const ParticleSetup& ps) {
  constexpr int ns = L20::kSize;
  const py::ssize_t n = t.size();
  require_shape(t, n, -1, "t");
  require_shape(dtheta_b, n, 3, "dtheta_b");
  require_shape(dv_b, n, 3, "dv_b");
  const py::ssize_t E = epoch_t.size();
  require_shape(epoch_t, E, -1, "epoch_t");
  if (epoch_start.ndim() != 1 || epoch_start.shape(0) != E + 1)
    throw py::value_error("epoch_start: expected shape (" + std::to_string(E + 1) + ",)");
  const py::ssize_t M = sats.ndim() == 2 ? sats.shape(0) : 0;
  if (M > 0) require_shape(sats, M, 12, "sats");
  if (init.size() != 10) throw py::value_error("init: expected 10 values (t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw)");
  require_shape(P0, ns, ns, "P0");
  if (corr0.size() != 12) throw py::value_error("imu_correction: expected 12 values");
  if (clock0.size() != 2) throw py::value_error("clock0: expected 2 values (bias m, drift m/s)");

  const std::int64_t* es = epoch_start.data();
  std::vector<TightEpoch> epochs(static_cast<size_t>(E));
  for (py::ssize_t i = 0; i < E; ++i) {
    if (es[i] < 0 || es[i + 1] < es[i] || es[i + 1] > M)
      throw py::value_error("epoch_start: bad range at epoch " + std::to_string(i));
    epochs[i].t = epoch_t.data()[i];
    epochs[i].begin = es[i];
    epochs[i].end = es[i + 1];
    if (i > 0 && !(epochs[i].t > epochs[i - 1].t))
      throw py::value_error("epoch_t: not strictly increasing at epoch " + std::to_string(i));
  }
  std::vector<SatObservation> obs(static_cast<size_t>(M));
  const double* psat = M ? sats.data() : nullptr;
  for (py::ssize_t i = 0; i < M; ++i) {
    const double* r = psat + 12 * i;
    SatObservation& o = obs[i];
    o.pseudorange_m = r[0];
    o.pseudorange_rate_mps = r[1];
    o.r_e = Vec3(r[2], r[3], r[4]);
    o.v_e = Vec3(r[5], r[6], r[7]);
    o.clock_bias_m = r[8];
    o.clock_drift_mps = r[9];
    o.sigma_pr_m = r[10];
    o.sigma_prr_mps = r[11];
    const bool any = std::isfinite(o.pseudorange_m) || std::isfinite(o.pseudorange_rate_mps);
    if (any && !(o.r_e.allFinite() && o.v_e.allFinite() && std::isfinite(o.clock_bias_m) &&
                 std::isfinite(o.clock_drift_mps)))
      throw py::value_error("sats: non-finite satellite state at row " + std::to_string(i));
    if (std::isfinite(o.pseudorange_m) && !(o.sigma_pr_m > 0.0))
      throw py::value_error("sats: sigma_pr must be > 0 at row " + std::to_string(i));
    if (std::isfinite(o.pseudorange_rate_mps) && !(o.sigma_prr_mps > 0.0))
      throw py::value_error("sats: sigma_prr must be > 0 at row " + std::to_string(i));
  }
  const double* pi = init.data();
  NavState nav;
  nav.t = pi[0];
  nav.lat = pi[1];
  nav.lon = pi[2];
  nav.h = pi[3];
  nav.v_n = Vec3(pi[4], pi[5], pi[6]);
  nav.q_nb = quat_from_euler(Vec3(pi[7], pi[8], pi[9]));
  StateCov<L20> P = Eigen::Map<const Eigen::Matrix<double, ns, ns, Eigen::RowMajor>>(P0.data());
  ImuCorrection corr;
  const double* pc = corr0.data();
  corr.acc_bias = Vec3(pc[0], pc[1], pc[2]);
  corr.gyro_bias = Vec3(pc[3], pc[4], pc[5]);
  corr.acc_scale = Vec3(pc[6], pc[7], pc[8]);
  corr.gyro_scale = Vec3(pc[9], pc[10], pc[11]);

  const py::ssize_t n_out = (n + cfg.output_decimation - 1) / cfg.output_decimation + 1;
  const py::ssize_t three = 3;
  DArray o_t({n_out}), o_llh({n_out, three}), o_v({n_out, three}), o_rpy({n_out, three}),
      o_sig({n_out, py::ssize_t(ns)}), o_err({n_out, py::ssize_t(12)}), o_clk({n_out, py::ssize_t(2)});
  DArray o_res({M, py::ssize_t(2)}), o_nis({E});
  DArray o_ess({E}), o_c({E}), o_eta({E});
  py::array_t<std::int8_t> o_status({E}), o_rs({E});
  py::array_t<std::int32_t> o_rows({E});
  TightOutputs out;
  out.t = o_t.mutable_data();
  out.llh = o_llh.mutable_data();
  out.v_n = o_v.mutable_data();
  out.rpy = o_rpy.mutable_data();
  out.sigma = o_sig.mutable_data();
  out.imu_err = o_err.mutable_data();
  out.clock = o_clk.mutable_data();
  out.sat_residual = M ? o_res.mutable_data() : nullptr;
  out.nis = E ? o_nis.mutable_data() : nullptr;
  out.status = E ? o_status.mutable_data() : nullptr;
  out.rows = E ? o_rows.mutable_data() : nullptr;
  ParticleTrace trace;
  trace.ess = E ? o_ess.mutable_data() : nullptr;
  trace.fading_c = E ? o_c.mutable_data() : nullptr;
  trace.eta_max = E ? o_eta.mutable_data() : nullptr;
  trace.resampled = E ? o_rs.mutable_data() : nullptr;
  trace.capacity = E;
  double seconds = 0.0;
  int resamples = 0, divergences = 0;
  {
    py::gil_scoped_release release;
    auto engine = std::make_unique<TightEngine<Filter>>(model, cfg, ut);  // one allocation per run
    configure(engine->filter(), model, ut, ps);
    engine->filter().set_trace(&trace);
    const auto t0 = std::chrono::steady_clock::now();
    engine->run(nav, P, corr, clock0.data()[0], clock0.data()[1], n, t.data(), dtheta_b.data(), dv_b.data(), E,
                epochs.data(), obs.data(), out);
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if constexpr (!std::is_same_v<Filter, FadingUkf<L20>>) resamples = engine->filter().resample_count();
    if constexpr (std::is_same_v<Filter, ParticleFilter<L20>>) divergences = engine->filter().divergences();
  }
  const py::ssize_t k = out.n_out;
  const py::ssize_t nt = trace.n;
  py::dict res;
  res["t"] = o_t[py::slice(0, k, 1)];
  res["llh"] = o_llh[py::slice(0, k, 1)];
  res["v_n"] = o_v[py::slice(0, k, 1)];
  res["rpy"] = o_rpy[py::slice(0, k, 1)];
  res["sigma"] = o_sig[py::slice(0, k, 1)];
  res["imu_err"] = o_err[py::slice(0, k, 1)];
  res["clock"] = o_clk[py::slice(0, k, 1)];
  res["sat_residual"] = o_res;
  res["nis"] = o_nis;
  res["status"] = o_status;
  res["rows"] = o_rows;
  res["updates"] = out.updates;
  res["rejected"] = out.rejected;
  res["cholesky_repairs"] = out.cholesky_repairs;
  res["trace_ess"] = o_ess[py::slice(0, nt, 1)];
  res["trace_fading_c"] = o_c[py::slice(0, nt, 1)];
  res["trace_eta_max"] = o_eta[py::slice(0, nt, 1)];
  res["trace_resampled"] = o_rs[py::slice(0, nt, 1)];
  res["resamples"] = resamples;
  res["divergences"] = divergences;
  res["run_seconds"] = seconds;
  return res;
}

}  // namespace

void bind_particle(py::module_& m) {
  m.def(
      "run_tight_particle",
      [](const std::string& filter, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& epoch_t, const py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>& epoch_start,
         const DArray& sats, const DArray& init, const DArray& P0, const DArray& corr0, const DArray& clock0,
         const py::dict& model, const py::dict& config, const py::dict& particle) {
        const ImuErrorModel mdl = imu_model_from_dict(model);
        const TightConfig cfg = tight_config(config);
        const ParticleSetup ps = particle_setup(particle);
        UtParams ut;
        ut.alpha = num(config, "ut_alpha", ut.alpha);
        ut.beta = num(config, "ut_beta", ut.beta);
        ut.kappa = num(config, "ut_kappa", ut.kappa);
        if (filter == "upf")
          return run_impl<Upf<L20>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0, clock0, mdl, cfg,
                                    ut, ps);
        if (filter == "pf")
          return run_impl<ParticleFilter<L20>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0,
                                               clock0, mdl, cfg, ut, ps);
        if (filter == "fukf")
          return run_impl<FadingUkf<L20>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0, clock0,
                                          mdl, cfg, ut, ps);
        throw py::value_error("unsupported particle filter: " + filter + " (upf, pf, fukf)");
      },
      py::arg("filter"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("epoch_t"),
      py::arg("epoch_start"), py::arg("sats"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
      py::arg("clock0"), py::arg("imu_model"), py::arg("config"), py::arg("particle"),
      "Closed-loop tightly coupled run with the seed 004 filters, Layout20 (see python/insnav/particle.py).");
}

}  // namespace insnav::py_bind
