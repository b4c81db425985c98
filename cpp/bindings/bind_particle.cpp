// Tightly coupled runs with the seed 004 filters on Layout20: the
// improved UPF, the bootstrap PF and the (fading) UKF, on the tight engine and
// pseudorange measurement of seed 003 (engine/tight_engine.hpp,
// meas/pseudorange.hpp).  The input format is that of _core.run_tight
// (convert.hpp); the whole loop runs in C++ with the GIL released.
#include <chrono>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "common.hpp"
#include "convert.hpp"
#include "outputs.hpp"
#include "insnav/engine/tight_engine.hpp"
#include "insnav/filter/layout20.hpp"
#include "insnav/filter/particle_filter.hpp"
#include "insnav/filter/upf.hpp"

namespace insnav::py_bind {

namespace {

using L20 = Layout20;

struct ParticleSetup {
  ParticleParams pp;
  FadingParams<L20::kSize> fp;
  UpfOptions opt;
};

ParticleSetup particle_setup(const py::dict& d) {
  reject_unknown(d, {"particles", "seed", "resample_threshold", "roughening", "rk4_step", "fading", "rho", "beta",
                  "eta_max", "alpha", "fading_memory", "sample", "kernel_h2", "init_yaw_halfwidth", "temper_stages",
                  "divergence_chi2", "noise_floor", "reseed", "marginalize"},
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
  s.pp.reseed = d.contains("reseed") ? py::cast<bool>(d["reseed"]) : s.pp.reseed;
  s.pp.marginalize = d.contains("marginalize") ? py::cast<bool>(d["marginalize"]) : s.pp.marginalize;
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
                  const I64Array& epoch_start, const DArray& sats, const DArray& init, const DArray& P0,
                  const DArray& corr0, const DArray& clock0, const ImuErrorModel& model, const TightConfig& cfg,
                  const UtParams& ut, const ParticleSetup& ps) {
  const ImuArrays imu = imu_arrays(t, dtheta_b, dv_b);
  const TightInputs in = tight_inputs_from(epoch_t, epoch_start, sats);
  const NavState nav = nav_state_from(init);
  const StateCov<L20> P = state_cov_from<L20>(P0);
  const ImuCorrection corr = imu_correction_from(corr0);
  const double clock_bias0 = clock0_bias(clock0), clock_drift0 = clock0.data()[1];
  const py::ssize_t E = in.E;

  NavBuffers nav_buf(output_rows(imu.n, cfg.output_decimation), L20::kSize, true);
  TightRecordBuffers rec_buf(in.E, in.M);
  TightOutputs out;
  nav_buf.attach(out);
  rec_buf.attach(out);
  DArray o_ess({E}), o_c({E}), o_eta({E});
  py::array_t<std::int8_t> o_rs({E});
  ParticleTrace trace;
  trace.ess = E ? o_ess.mutable_data() : nullptr;
  trace.fading_c = E ? o_c.mutable_data() : nullptr;
  trace.eta_max = E ? o_eta.mutable_data() : nullptr;
  trace.resampled = E ? o_rs.mutable_data() : nullptr;
  trace.capacity = E;
  double seconds = 0.0;
  int resamples = 0, divergences = 0, reseeds = 0;
  {
    py::gil_scoped_release release;
    auto engine = std::make_unique<TightEngine<Filter>>(model, cfg, ut);  // one allocation per run
    configure(engine->filter(), model, ut, ps);
    engine->filter().set_trace(&trace);
    const auto t0 = std::chrono::steady_clock::now();
    engine->run(nav, P, corr, clock_bias0, clock_drift0, imu.n, imu.t, imu.dtheta_b, imu.dv_b, E, in.epochs.data(),
                in.sats.data(), out);
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if constexpr (!std::is_same_v<Filter, FadingUkf<L20>>) resamples = engine->filter().resample_count();
    if constexpr (std::is_same_v<Filter, ParticleFilter<L20>>) {
      divergences = engine->filter().divergences();
      reseeds = engine->filter().reseeds();
    }
  }
  const py::slice traced(0, trace.n, 1);
  py::dict res;
  nav_buf.put(res, out);
  rec_buf.put(res, out);
  res["trace_ess"] = o_ess[traced];
  res["trace_fading_c"] = o_c[traced];
  res["trace_eta_max"] = o_eta[traced];
  res["trace_resampled"] = o_rs[traced];
  res["resamples"] = resamples;
  res["divergences"] = divergences;
  res["reseeds"] = reseeds;
  res["run_seconds"] = seconds;
  return res;
}

}  // namespace

void bind_particle(py::module_& m) {
  m.def(
      "run_tight_particle",
      [](const std::string& filter, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& epoch_t, const I64Array& epoch_start, const DArray& sats, const DArray& init, const DArray& P0,
         const DArray& corr0, const DArray& clock0, const py::dict& model, const py::dict& config,
         const py::dict& particle) {
        const ImuErrorModel mdl = imu_model_from_dict(model);
        const TightConfig cfg = tight_config_from(config);
        if (cfg.pr_gm.enabled())
          throw py::value_error("pr_gm_sigma_m: the Gauss-Markov pseudorange states run with the tight ekf only");
        if (cfg.adaptive_q.window > 0)
          throw py::value_error("adaptive_q_window > 0: the EKF only (it scales the EKF's process noise), not " + filter);
        if (flag(config, "smooth", false))
          throw py::value_error("smooth: the RTS smoother runs with the EKF, RB-UKF and UKF (not " + filter + ")");
        const ParticleSetup ps = particle_setup(particle);
        const UtParams ut = ut_from(config);
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
      "Closed-loop tightly coupled run with the seed 004 filters, Layout20 (see python/insnav/filters/particle.py).");
}

}  // namespace insnav::py_bind
