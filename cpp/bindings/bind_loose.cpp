// Loosely coupled run: the whole IMU loop in C++ with the GIL released.
// This file parses the arguments and dispatches; the engines are instantiated
// in bind_loose_l15.cpp and bind_loose_l21.cpp (loose_run.hpp).
#include <pybind11/stl.h>

#include <string>

#include "loose_run.hpp"

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
                                "use_velocity", "output_decimation", "ut_alpha", "ut_beta", "ut_kappa",
                                "sigma_columns"};
  for (auto item : d) {
    const std::string k = py::cast<std::string>(item.first);
    bool ok = false;
    for (const char* kk : known) ok = ok || (k == kk);
    if (!ok) throw py::value_error("unknown engine config key '" + k + "'");
  }
  return c;
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
        const int sigma_columns = static_cast<int>(number(config, "sigma_columns", 0));
        const LooseRunArgs args{t, dtheta_b, dv_b, gnss, init, P0, corr0, mdl, cfg, ut, sigma_columns};
        if (layout == 15) return run_loose_l15(filter, args);
        if (layout == 21) return run_loose_l21(filter, args);
        unsupported_loose(filter, layout);
      },
      py::arg("filter"), py::arg("layout"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("gnss"),
      py::arg("init"), py::arg("P0"), py::arg("imu_correction"), py::arg("imu_model"), py::arg("config"),
      "Closed-loop loosely coupled run (SI units; see python/insnav/engine.py).");
}

}  // namespace insnav::py_bind
