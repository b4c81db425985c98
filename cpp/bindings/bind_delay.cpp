// Delayed GNSS runs (seed 001): random-delay KF and exact time-tagged
// re-processing; the whole IMU loop in C++ with the GIL released.
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "common.hpp"
#include "convert.hpp"
#include "outputs.hpp"
#include "insnav/engine/delay_engine.hpp"
#include "insnav/filter/ekf.hpp"

namespace insnav::py_bind {

/// The loose and delay parts of a delay run's config dict (also bind_delay_navigator.cpp).
void delay_configs_from_dict(const py::dict& d, LooseConfig& c, DelayConfig& dc) {
  c = loose_config_from(d, "delay engine config", {"max_history_s", "checkpoint_interval", "time_tolerance"});
  dc.max_history_s = num(d, "max_history_s", dc.max_history_s);
  dc.checkpoint_interval = num(d, "checkpoint_interval", dc.checkpoint_interval);
  dc.time_tolerance = num(d, "time_tolerance", dc.time_tolerance);
  if (!(dc.max_history_s >= 0.0)) throw py::value_error("max_history_s must be >= 0");
  if (!(dc.checkpoint_interval > 0.0)) throw py::value_error("checkpoint_interval must be > 0");
}

/// The delay probabilities p_0..p_s: in [0, 1], summing to 1 (seed 001 eq. (4)).
std::vector<double> delay_p_from(const DArray& delay_p) {
  std::vector<double> p(delay_p.data(), delay_p.data() + delay_p.size());
  double sum = 0.0;
  for (double v : p) {
    if (!(v >= 0.0 && v <= 1.0)) throw py::value_error("delay_p: probabilities must be in [0, 1]");
    sum += v;
  }
  if (p.empty() || std::abs(sum - 1.0) > 1e-9) throw py::value_error("delay_p: expected probabilities p_0..p_s summing to 1");
  return p;
}

namespace {

struct Inputs {
  NavState nav;
  ImuCorrection corr;
  std::vector<GnssFix> fixes;
  std::vector<double> t_arrival;
  py::ssize_t n = 0, m = 0;
};

Inputs parse_inputs(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, const DArray& gnss,
                    const DArray& init, const DArray& corr0) {
  Inputs in;
  in.n = imu_arrays(t, dtheta_b, dv_b).n;
  in.m = gnss.ndim() == 2 ? gnss.shape(0) : 0;
  if (in.m > 0) require_shape(gnss, in.m, 14, "gnss");
  in.nav = nav_state_from(init);
  in.corr = imu_correction_from(corr0);
  // rows: t_valid, t_arrival, then the loose fix row (lat .. svD); sorted by t_arrival
  in.fixes.resize(static_cast<size_t>(in.m));
  in.t_arrival.resize(static_cast<size_t>(in.m));
  const double* pg = gnss.data();
  for (py::ssize_t i = 0; i < in.m; ++i) {
    const double* r = pg + 14 * i;
    in.t_arrival[i] = r[1];
    if (!(r[1] >= r[0])) throw py::value_error("gnss row " + std::to_string(i) + ": t_arrival < t_valid");
    if (i > 0 && r[1] < pg[14 * (i - 1) + 1])
      throw py::value_error("gnss row " + std::to_string(i) + ": records must be sorted by t_arrival");
    in.fixes[i] = gnss_fix_from(r[0], r + 2);
  }
  return in;
}

/// Output arrays + a runner callback (the engine-specific part).
template <int NS, class RunFn>
py::dict run_with_outputs(const Inputs& in, const LooseConfig& cfg, RunFn&& fn) {
  NavBuffers nav_buf(output_rows(in.n, cfg.output_decimation), NS, false);
  LooseRecordBuffers rec_buf(in.m);
  DelayOutputs out;
  nav_buf.attach(out);
  rec_buf.attach(out, in.m);
  {
    py::gil_scoped_release release;
    fn(out);
  }
  py::dict res;
  nav_buf.put(res, out);
  rec_buf.put(res);
  res["refused_too_old"] = out.refused_too_old;
  res["replays"] = out.replays;
  res["replayed_samples"] = out.replayed_samples;
  res["filter_updates"] = out.filter_updates;
  return res;
}

struct Imu {
  const double *t, *dtheta_b, *dv_b;
};

template <int S>
py::dict run_rdkf(const Inputs& in, const Imu& imu, const StateCov<Layout15>& P, const ImuErrorModel& model,
                  const LooseConfig& cfg, const DelayConfig& dc, const std::vector<double>& p, const DArray& epochs) {
  const double* ep = epochs.data();
  const py::ssize_t n_ep = epochs.size();
  return run_with_outputs<15>(in, cfg, [&](DelayOutputs& out) {
    auto eng = std::make_unique<RandomDelayEngine<Layout15, S>>(model, cfg, dc, p.data(), static_cast<int>(p.size()));
    eng->run(in.nav, P, in.corr, in.n, imu.t, imu.dtheta_b, imu.dv_b, in.m, in.fixes.data(), in.t_arrival.data(),
             n_ep, ep, out);
  });
}

template <class L>
py::dict run_exact(const Inputs& in, const Imu& imu, const DArray& P0, const ImuErrorModel& model,
                   const LooseConfig& cfg, const DelayConfig& dc, double* history_s) {
  const StateCov<L> P = state_cov_from<L>(P0);
  return run_with_outputs<L::kSize>(in, cfg, [&](DelayOutputs& out) {
    auto eng = std::make_unique<TimeTaggedEngine<Ekf<L>>>(model, cfg, dc);
    *history_s = eng->history_s();
    eng->run(in.nav, P, in.corr, in.n, imu.t, imu.dtheta_b, imu.dv_b, in.m, in.fixes.data(), in.t_arrival.data(), out);
  });
}

}  // namespace

void bind_delay(py::module_& m) {
  m.def(
      "run_delay",
      [](const std::string& method, int layout, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& gnss, const DArray& epochs, const DArray& init, const DArray& P0, const DArray& corr0,
         const py::dict& model, const py::dict& config, const DArray& delay_p) {
        const ImuErrorModel mdl = imu_model_from_dict(model);
        LooseConfig cfg;
        DelayConfig dc;
        delay_configs_from_dict(config, cfg, dc);
        const Inputs in = parse_inputs(t, dtheta_b, dv_b, gnss, init, corr0);
        const Imu imu{t.data(), dtheta_b.data(), dv_b.data()};
        if (method == "rdkf") {
          if (layout != 15) throw py::value_error("rdkf: only the 15-state layout is instantiated");
          const StateCov<Layout15> P = state_cov_from<Layout15>(P0);
          const std::vector<double> p = delay_p_from(delay_p);
          if (epochs.ndim() != 1) throw py::value_error("epochs: expected a 1-D array");
          const double* e = epochs.data();
          for (py::ssize_t i = 1; i < epochs.size(); ++i)
            if (!(e[i] > e[i - 1])) throw py::value_error("epochs: must be strictly increasing");
          const int s = std::max<int>(1, static_cast<int>(p.size()) - 1);
          py::dict res;
          switch (s) {
            case 1: res = run_rdkf<1>(in, imu, P, mdl, cfg, dc, p, epochs); break;
            case 2: res = run_rdkf<2>(in, imu, P, mdl, cfg, dc, p, epochs); break;
            case 3: res = run_rdkf<3>(in, imu, P, mdl, cfg, dc, p, epochs); break;
            case 4: res = run_rdkf<4>(in, imu, P, mdl, cfg, dc, p, epochs); break;
            default:
              throw py::value_error("rdkf: maximum delay s = " + std::to_string(s) +
                                    " epochs is not instantiated (1..4; see RandomDelayKf<L, S>)");
          }
          res["max_delay_epochs"] = s;
          return res;
        }
        if (method == "exact") {
          double hist = 0.0;
          py::dict res;
          if (layout == 15)
            res = run_exact<Layout15>(in, imu, P0, mdl, cfg, dc, &hist);
          else if (layout == 21)
            res = run_exact<Layout21>(in, imu, P0, mdl, cfg, dc, &hist);
          else
            throw py::value_error("exact: unsupported layout " + std::to_string(layout));
          res["history_s"] = hist;
          return res;
        }
        throw py::value_error("unknown delay method '" + method + "' (rdkf, exact)");
      },
      py::arg("method"), py::arg("layout"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("gnss"),
      py::arg("epochs"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"), py::arg("imu_model"),
      py::arg("config"), py::arg("delay_p"),
      "Closed-loop loose run with delayed GNSS records (SI; see python/insnav/filters/delay.py).");
}

}  // namespace insnav::py_bind
