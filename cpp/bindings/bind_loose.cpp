// Loosely coupled run: the whole IMU loop in C++ with the GIL released.
#include <pybind11/stl.h>

#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/engine/loose_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"

namespace insnav::py_bind {

namespace {

Vec3 vec3_or_scalar(const py::dict& d, const char* key, const Vec3& dflt) {
  if (!d.contains(key)) return dflt;
  DArray a = py::cast<DArray>(d[key]);
  if (a.size() == 1) return Vec3::Constant(a.data()[0]);
  if (a.size() != 3) throw py::value_error(std::string("imu model/config key '") + key + "': expected 1 or 3 values");
  return Vec3(a.data()[0], a.data()[1], a.data()[2]);
}

double number(const py::dict& d, const char* key, double dflt) {
  return d.contains(key) ? py::cast<double>(d[key]) : dflt;
}

}  // namespace

ImuErrorModel imu_model_from_dict(const py::dict& d) {
  static const char* known[] = {"gyro_arw", "acc_vrw", "gyro_bias_sigma", "acc_bias_sigma", "gyro_bias_tau",
                                "acc_bias_tau", "gyro_bias_rw", "acc_bias_rw", "gyro_scale_sigma",
                                "acc_scale_sigma", "gyro_scale_tau", "acc_scale_tau", "clock_bias_psd",
                                "clock_drift_psd"};
  for (auto item : d) {
    const std::string k = py::cast<std::string>(item.first);
    bool ok = false;
    for (const char* kk : known) ok = ok || (k == kk);
    if (!ok) throw py::value_error("unknown IMU model key '" + k + "'");
  }
  ImuErrorModel m;
  m.gyro_arw = vec3_or_scalar(d, "gyro_arw", m.gyro_arw);
  m.acc_vrw = vec3_or_scalar(d, "acc_vrw", m.acc_vrw);
  m.gyro_bias_sigma = vec3_or_scalar(d, "gyro_bias_sigma", m.gyro_bias_sigma);
  m.acc_bias_sigma = vec3_or_scalar(d, "acc_bias_sigma", m.acc_bias_sigma);
  m.gyro_bias_tau = vec3_or_scalar(d, "gyro_bias_tau", m.gyro_bias_tau);
  m.acc_bias_tau = vec3_or_scalar(d, "acc_bias_tau", m.acc_bias_tau);
  m.gyro_bias_rw = vec3_or_scalar(d, "gyro_bias_rw", m.gyro_bias_rw);
  m.acc_bias_rw = vec3_or_scalar(d, "acc_bias_rw", m.acc_bias_rw);
  m.gyro_scale_sigma = vec3_or_scalar(d, "gyro_scale_sigma", m.gyro_scale_sigma);
  m.acc_scale_sigma = vec3_or_scalar(d, "acc_scale_sigma", m.acc_scale_sigma);
  m.gyro_scale_tau = vec3_or_scalar(d, "gyro_scale_tau", m.gyro_scale_tau);
  m.acc_scale_tau = vec3_or_scalar(d, "acc_scale_tau", m.acc_scale_tau);
  m.clock_bias_psd = number(d, "clock_bias_psd", m.clock_bias_psd);
  m.clock_drift_psd = number(d, "clock_drift_psd", m.clock_drift_psd);
  return m;
}

namespace {

LooseConfig loose_config_from_dict(const py::dict& d) {
  LooseConfig c;
  c.lever_arm_b = vec3_or_scalar(d, "lever_arm_b", c.lever_arm_b);
  c.propagation_interval = number(d, "propagation_interval", c.propagation_interval);
  c.cycle_period = number(d, "cycle_period", c.cycle_period);
  c.gate_chi2 = number(d, "gate_chi2", c.gate_chi2);
  c.use_position = d.contains("use_position") ? py::cast<bool>(d["use_position"]) : true;
  c.use_velocity = d.contains("use_velocity") ? py::cast<bool>(d["use_velocity"]) : true;
  c.output_decimation = static_cast<int>(number(d, "output_decimation", 1));
  if (!(c.propagation_interval > 0.0)) throw py::value_error("propagation_interval must be > 0");
  if (!(c.cycle_period > 0.0)) throw py::value_error("cycle_period must be > 0");
  if (c.output_decimation < 1) throw py::value_error("output_decimation must be >= 1");
  static const char* known[] = {"lever_arm_b", "propagation_interval", "cycle_period", "gate_chi2", "use_position",
                                "use_velocity", "output_decimation", "ut_alpha", "ut_beta", "ut_kappa"};
  for (auto item : d) {
    const std::string k = py::cast<std::string>(item.first);
    bool ok = false;
    for (const char* kk : known) ok = ok || (k == kk);
    if (!ok) throw py::value_error("unknown engine config key '" + k + "'");
  }
  return c;
}

template <class Filter>
py::dict run_impl(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, const DArray& gnss,
                  const DArray& init, const DArray& P0, const DArray& corr0, const ImuErrorModel& model,
                  const LooseConfig& cfg, const UtParams& ut) {
  using L = typename Filter::Layout;
  constexpr int ns = L::kSize;
  const py::ssize_t n = t.size();
  require_shape(t, n, -1, "t");
  require_shape(dtheta_b, n, 3, "dtheta_b");
  require_shape(dv_b, n, 3, "dv_b");
  const py::ssize_t m = gnss.ndim() == 2 ? gnss.shape(0) : 0;
  if (m > 0) require_shape(gnss, m, 13, "gnss");
  if (init.size() != 10) throw py::value_error("init: expected 10 values (t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw)");
  require_shape(P0, ns, ns, "P0");
  if (corr0.size() != 12) throw py::value_error("imu_correction: expected 12 values");

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

  // GNSS rows: t, lat, lon, h, vN, vE, vD, sN, sE, sD, svN, svE, svD (NaN velocity: position only)
  std::vector<GnssFix> fixes(static_cast<size_t>(m));
  const double* pg = gnss.data();
  for (py::ssize_t i = 0; i < m; ++i) {
    const double* r = pg + 13 * i;
    GnssFix& f = fixes[i];
    f.t = r[0];
    f.lat = r[1];
    f.lon = r[2];
    f.h = r[3];
    f.v_n = Vec3(r[4], r[5], r[6]);
    f.sigma_pos_n = Vec3(r[7], r[8], r[9]);
    f.sigma_vel_n = Vec3(r[10], r[11], r[12]);
    f.has_pos = std::isfinite(r[1]) && std::isfinite(r[2]) && std::isfinite(r[3]);
    f.has_vel = f.v_n.allFinite() && f.sigma_vel_n.allFinite();
  }

  const py::ssize_t n_out = (n + cfg.output_decimation - 1) / cfg.output_decimation + 1;
  DArray o_t({n_out}), o_llh({n_out, py::ssize_t(3)}), o_v({n_out, py::ssize_t(3)}),
      o_rpy({n_out, py::ssize_t(3)}), o_sig({n_out, py::ssize_t(ns)}), o_err({n_out, py::ssize_t(12)});
  DArray o_innov({m, py::ssize_t(6)}), o_nis({m});
  py::array_t<std::int8_t> o_status({m});
  LooseOutputs out;
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
    auto engine = std::make_unique<LooseEngine<Filter>>(model, cfg, ut);  // one allocation per run, not per sample
    engine->run(nav, P, corr, n, t.data(), dtheta_b.data(), dv_b.data(), m, fixes.data(), out);
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
  return res;
}

}  // namespace

void bind_loose(py::module_& m) {
  m.def(
      "run_loose",
      [](const std::string& filter, int layout, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& gnss, const DArray& init, const DArray& P0, const DArray& corr0, const py::dict& model,
         const py::dict& config) {
        const ImuErrorModel mdl = imu_model_from_dict(model);
        const LooseConfig cfg = loose_config_from_dict(config);
        UtParams ut;
        ut.alpha = number(config, "ut_alpha", ut.alpha);
        ut.beta = number(config, "ut_beta", ut.beta);
        ut.kappa = number(config, "ut_kappa", ut.kappa);
#define INSNAV_DISPATCH(NAME, FILTER, LAYOUT, N)                                                   \
  if (filter == NAME && layout == N)                                                             \
    return run_impl<FILTER<LAYOUT>>(t, dtheta_b, dv_b, gnss, init, P0, corr0, mdl, cfg, ut);
        INSNAV_DISPATCH("ekf", Ekf, Layout15, 15)
        INSNAV_DISPATCH("ekf", Ekf, Layout21, 21)
        INSNAV_DISPATCH("rbukf", RbUkf, Layout15, 15)
        INSNAV_DISPATCH("rbukf", RbUkf, Layout21, 21)
        INSNAV_DISPATCH("ukf", Ukf, Layout15, 15)
        INSNAV_DISPATCH("ukf", Ukf, Layout21, 21)
#undef INSNAV_DISPATCH
        throw py::value_error("unsupported filter/layout combination: " + filter + "/" + std::to_string(layout));
      },
      py::arg("filter"), py::arg("layout"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("gnss"),
      py::arg("init"), py::arg("P0"), py::arg("imu_correction"), py::arg("imu_model"), py::arg("config"),
      "Closed-loop loosely coupled run (SI units; see python/insnav/engine.py).");
}

}  // namespace insnav::py_bind
