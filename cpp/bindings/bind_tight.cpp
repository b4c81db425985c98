// Tightly coupled run (seed 003): the whole IMU loop in C++ with the GIL
// released; all epochs' satellite data handed over in one call as flat arrays.
#include <memory>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/engine/tight_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"

namespace insnav::py_bind {

namespace {

double num(const py::dict& d, const char* key, double dflt) {
  return d.contains(key) ? py::cast<double>(d[key]) : dflt;
}

TightConfig tight_config_from_dict(const py::dict& d) {
  static const char* known[] = {"lever_arm_b", "propagation_interval", "cycle_period", "gate_chi2",
                                "use_pseudorange", "use_rate", "output_decimation", "ut_alpha", "ut_beta",
                                "ut_kappa"};
  for (auto item : d) {
    const std::string k = py::cast<std::string>(item.first);
    bool ok = false;
    for (const char* kk : known) ok = ok || (k == kk);
    if (!ok) throw py::value_error("unknown tight engine config key '" + k + "'");
  }
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

template <class Filter>
py::dict run_tight_impl(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, const DArray& epoch_t,
                        const py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>& epoch_start,
                        const DArray& sats, const DArray& init, const DArray& P0, const DArray& corr0,
                        const DArray& clock0, const ImuErrorModel& model, const TightConfig& cfg,
                        const UtParams& ut) {
  using L = typename Filter::Layout;
  constexpr int ns = L::kSize;
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
  // sats rows: pr, prr, x, y, z, vx, vy, vz, clock_bias_m, clock_drift_mps, sigma_pr, sigma_prr
  std::vector<SatObservation> obs(static_cast<size_t>(M));
  const double* ps = M ? sats.data() : nullptr;
  for (py::ssize_t i = 0; i < M; ++i) {
    const double* r = ps + 12 * i;
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
  StateCov<L> P = Eigen::Map<const Eigen::Matrix<double, ns, ns, Eigen::RowMajor>>(P0.data());
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
  py::array_t<std::int8_t> o_status({E});
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
  {
    py::gil_scoped_release release;
    auto engine = std::make_unique<TightEngine<Filter>>(model, cfg, ut);  // one allocation per run
    engine->run(nav, P, corr, clock0.data()[0], clock0.data()[1], n, t.data(), dtheta_b.data(), dv_b.data(), E,
                epochs.data(), obs.data(), out);
  }
  const py::ssize_t k = out.n_out;
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
  return res;
}

}  // namespace

void bind_tight(py::module_& m) {
  m.def(
      "run_tight",
      [](const std::string& filter, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& epoch_t, const py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>& epoch_start,
         const DArray& sats, const DArray& init, const DArray& P0, const DArray& corr0, const DArray& clock0,
         const py::dict& model, const py::dict& config) {
        const ImuErrorModel mdl = imu_model_from_dict(model);
        const TightConfig cfg = tight_config_from_dict(config);
        UtParams ut;
        ut.alpha = num(config, "ut_alpha", ut.alpha);
        ut.beta = num(config, "ut_beta", ut.beta);
        ut.kappa = num(config, "ut_kappa", ut.kappa);
        if (filter == "ekf")
          return run_tight_impl<Ekf<Layout17>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0,
                                               clock0, mdl, cfg, ut);
        if (filter == "rbukf")
          return run_tight_impl<RbUkf<Layout17>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0,
                                                 clock0, mdl, cfg, ut);
        if (filter == "ukf")
          return run_tight_impl<Ukf<Layout17>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0,
                                               clock0, mdl, cfg, ut);
        throw py::value_error("unsupported tight filter: " + filter + " (ekf, rbukf, ukf)");
      },
      py::arg("filter"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("epoch_t"),
      py::arg("epoch_start"), py::arg("sats"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
      py::arg("clock0"), py::arg("imu_model"), py::arg("config"),
      "Closed-loop tightly coupled run, Layout17 (SI units; see python/insnav/tight.py).");
}

}  // namespace insnav::py_bind
