// Delayed GNSS runs (seed 001): random-delay KF and exact time-tagged
// re-processing; the whole IMU loop in C++ with the GIL released.
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/engine/delay_engine.hpp"
#include "insnav/filter/ekf.hpp"

namespace insnav::py_bind {

namespace {

double num(const py::dict& d, const char* key, double dflt) {
  return d.contains(key) ? py::cast<double>(d[key]) : dflt;
}

void delay_configs_from_dict(const py::dict& d, LooseConfig& c, DelayConfig& dc) {
  static const char* known[] = {"lever_arm_b", "propagation_interval", "cycle_period", "gate_chi2",
                                "use_position", "use_velocity", "output_decimation", "max_history_s",
                                "checkpoint_interval", "time_tolerance"};
  for (auto item : d) {
    const std::string k = py::cast<std::string>(item.first);
    if (std::none_of(std::begin(known), std::end(known), [&](const char* kk) { return k == kk; }))
      throw py::value_error("unknown delay engine config key '" + k + "'");
  }
  if (d.contains("lever_arm_b")) c.lever_arm_b = vec3_from(py::cast<DArray>(d["lever_arm_b"]), "lever_arm_b");
  c.propagation_interval = num(d, "propagation_interval", c.propagation_interval);
  c.cycle_period = num(d, "cycle_period", c.cycle_period);
  c.gate_chi2 = num(d, "gate_chi2", c.gate_chi2);
  c.use_position = d.contains("use_position") ? py::cast<bool>(d["use_position"]) : true;
  c.use_velocity = d.contains("use_velocity") ? py::cast<bool>(d["use_velocity"]) : true;
  c.output_decimation = static_cast<int>(num(d, "output_decimation", 1));
  dc.max_history_s = num(d, "max_history_s", dc.max_history_s);
  dc.checkpoint_interval = num(d, "checkpoint_interval", dc.checkpoint_interval);
  dc.time_tolerance = num(d, "time_tolerance", dc.time_tolerance);
  if (!(c.propagation_interval > 0.0)) throw py::value_error("propagation_interval must be > 0");
  if (!(c.cycle_period > 0.0)) throw py::value_error("cycle_period must be > 0");
  if (c.output_decimation < 1) throw py::value_error("output_decimation must be >= 1");
  if (!(dc.max_history_s >= 0.0)) throw py::value_error("max_history_s must be >= 0");
  if (!(dc.checkpoint_interval > 0.0)) throw py::value_error("checkpoint_interval must be > 0");
}

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
  in.n = t.size();
  require_shape(t, in.n, -1, "t");
  require_shape(dtheta_b, in.n, 3, "dtheta_b");
  require_shape(dv_b, in.n, 3, "dv_b");
  in.m = gnss.ndim() == 2 ? gnss.shape(0) : 0;
  if (in.m > 0) require_shape(gnss, in.m, 14, "gnss");
  if (init.size() != 10) throw py::value_error("init: expected 10 values (t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw)");
  if (corr0.size() != 12) throw py::value_error("imu_correction: expected 12 values");
  const double* pi = init.data();
  in.nav.t = pi[0];
  in.nav.lat = pi[1];
  in.nav.lon = pi[2];
  in.nav.h = pi[3];
  in.nav.v_n = Vec3(pi[4], pi[5], pi[6]);
  in.nav.q_nb = quat_from_euler(Vec3(pi[7], pi[8], pi[9]));
  const double* pc = corr0.data();
  in.corr.acc_bias = Vec3(pc[0], pc[1], pc[2]);
  in.corr.gyro_bias = Vec3(pc[3], pc[4], pc[5]);
  in.corr.acc_scale = Vec3(pc[6], pc[7], pc[8]);
  in.corr.gyro_scale = Vec3(pc[9], pc[10], pc[11]);
  // rows: t_valid, t_arrival, lat, lon, h, vN, vE, vD, sN, sE, sD, svN, svE, svD; sorted by t_arrival
  in.fixes.resize(static_cast<size_t>(in.m));
  in.t_arrival.resize(static_cast<size_t>(in.m));
  const double* pg = gnss.data();
  for (py::ssize_t i = 0; i < in.m; ++i) {
    const double* r = pg + 14 * i;
    GnssFix& f = in.fixes[i];
    f.t = r[0];
    in.t_arrival[i] = r[1];
    if (!(r[1] >= r[0])) throw py::value_error("gnss row " + std::to_string(i) + ": t_arrival < t_valid");
    if (i > 0 && r[1] < pg[14 * (i - 1) + 1])
      throw py::value_error("gnss row " + std::to_string(i) + ": records must be sorted by t_arrival");
    f.lat = r[2];
    f.lon = r[3];
    f.h = r[4];
    f.v_n = Vec3(r[5], r[6], r[7]);
    f.sigma_pos_n = Vec3(r[8], r[9], r[10]);
    f.sigma_vel_n = Vec3(r[11], r[12], r[13]);
    f.has_pos = std::isfinite(r[2]) && std::isfinite(r[3]) && std::isfinite(r[4]);
    f.has_vel = f.v_n.allFinite() && f.sigma_vel_n.allFinite();
  }
  return in;
}

/// Output arrays + a runner callback (the engine-specific part).
template <int NS, class RunFn>
py::dict run_with_outputs(const Inputs& in, const LooseConfig& cfg, RunFn&& fn) {
  const py::ssize_t n = in.n, m = in.m;
  const py::ssize_t n_out = (n + cfg.output_decimation - 1) / cfg.output_decimation + 1;
  DArray o_t({n_out}), o_llh({n_out, py::ssize_t(3)}), o_v({n_out, py::ssize_t(3)}), o_rpy({n_out, py::ssize_t(3)}),
      o_sig({n_out, py::ssize_t(NS)}), o_err({n_out, py::ssize_t(12)});
  DArray o_innov({m, py::ssize_t(6)}), o_nis({m});
  py::array_t<std::int8_t> o_status({m});
  DelayOutputs out;
  out.t = o_t.mutable_data();
  out.llh = o_llh.mutable_data();
  out.v_n = o_v.mutable_data();
  out.rpy = o_rpy.mutable_data();
  out.sigma = o_sig.mutable_data();
  out.imu_err = o_err.mutable_data();
  out.innovation = m ? o_innov.mutable_data() : nullptr;
  out.nis = m ? o_nis.mutable_data() : nullptr;
  out.status = m ? o_status.mutable_data() : nullptr;
  {
    py::gil_scoped_release release;
    fn(out);
  }
  const py::ssize_t k = out.n_out;
  py::dict res;
  res["t"] = o_t[py::slice(0, k, 1)];
  res["llh"] = o_llh[py::slice(0, k, 1)];
  res["v_n"] = o_v[py::slice(0, k, 1)];
  res["rpy"] = o_rpy[py::slice(0, k, 1)];
  res["sigma"] = o_sig[py::slice(0, k, 1)];
  res["imu_err"] = o_err[py::slice(0, k, 1)];
  res["innovation"] = o_innov;
  res["nis"] = o_nis;
  res["status"] = o_status;
  res["updates"] = out.updates;
  res["rejected"] = out.rejected;
  res["cholesky_repairs"] = out.cholesky_repairs;
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
  constexpr int ns = L::kSize;
  require_shape(P0, ns, ns, "P0");
  const StateCov<L> P = Eigen::Map<const Eigen::Matrix<double, ns, ns, Eigen::RowMajor>>(P0.data());
  return run_with_outputs<ns>(in, cfg, [&](DelayOutputs& out) {
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
          require_shape(P0, 15, 15, "P0");
          const StateCov<Layout15> P = Eigen::Map<const Eigen::Matrix<double, 15, 15, Eigen::RowMajor>>(P0.data());
          std::vector<double> p(delay_p.data(), delay_p.data() + delay_p.size());
          double sum = 0.0;
          for (double v : p) {
            if (!(v >= 0.0 && v <= 1.0)) throw py::value_error("delay_p: probabilities must be in [0, 1]");
            sum += v;
          }
          if (p.empty() || std::abs(sum - 1.0) > 1e-9)
            throw py::value_error("delay_p: expected probabilities p_0..p_s summing to 1");
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
      "Closed-loop loose run with delayed GNSS records (SI; see python/insnav/delay.py).");
}

}  // namespace insnav::py_bind
