// Loosely coupled run: the whole IMU loop in C++ with the GIL released.
// This file parses the arguments and dispatches; the engines are instantiated
// in bind_loose_l15.cpp, bind_loose_l16.cpp and bind_loose_l21.cpp (loose_run.hpp).
#include <pybind11/stl.h>

#include <cmath>
#include <optional>
#include <string>

#include "loose_run.hpp"

namespace insnav::py_bind {

ImuErrorModel imu_model_from_dict(const py::dict& d) {
  reject_unknown(d,
                 {"gyro_arw", "acc_vrw", "gyro_bias_sigma", "acc_bias_sigma", "gyro_bias_tau", "acc_bias_tau",
                  "gyro_bias_rw", "acc_bias_rw", "gyro_scale_sigma", "acc_scale_sigma", "gyro_scale_tau",
                  "acc_scale_tau", "clock_bias_psd", "clock_drift_psd", "isb_psd", "odo_scale_sigma", "odo_scale_tau",
                  "time_offset_psd", "lever_arm_psd"},
                 "IMU model");
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
  m.clock_bias_psd = num(d, "clock_bias_psd", m.clock_bias_psd);
  m.clock_drift_psd = num(d, "clock_drift_psd", m.clock_drift_psd);
  m.isb_psd = num(d, "isb_psd", m.isb_psd);
  m.odo_scale_sigma = num(d, "odo_scale_sigma", m.odo_scale_sigma);
  m.odo_scale_tau = num(d, "odo_scale_tau", m.odo_scale_tau);
  m.time_offset_psd = num(d, "time_offset_psd", m.time_offset_psd);
  m.lever_arm_psd = num(d, "lever_arm_psd", m.lever_arm_psd);
  if (!(m.time_offset_psd >= 0.0 && std::isfinite(m.time_offset_psd)))
    throw py::value_error("IMU model: time_offset_psd must be finite and >= 0 [s^2/s]");
  if (!(m.lever_arm_psd >= 0.0 && std::isfinite(m.lever_arm_psd)))
    throw py::value_error("IMU model: lever_arm_psd must be finite and >= 0 [m^2/s]");
  if (!(m.odo_scale_sigma >= 0.0)) throw py::value_error("IMU model: odo_scale_sigma must be >= 0");
  if (!(m.odo_scale_tau > 0.0)) throw py::value_error("IMU model: odo_scale_tau must be > 0 (inf: random constant)");
  return m;
}

/// The loose engine config of _core.run_loose / _core.LooseNavigator, with the
/// vehicle-constraint keys (unknown keys are errors).
LooseConfig loose_run_config_from(const py::dict& config) {
  LooseConfig cfg = loose_config_from(config, "engine config",
                                      {INSNAV_UT_KEYS, "sigma_columns", "vehicle_lever_arm_b", "vehicle_C_bv",
                                       "sigma_nhc_mps", "sigma_odo_mps", "sigma_zupt_mps", "sigma_zaru_radps",
                                       "constraint_gate_chi2", "second_order_corr_s", "smooth", "adaptive_r_window",
                                       "adaptive_r_min_fraction", "adaptive_q_window", "adaptive_q_min", "adaptive_q_max",
                                       "standstill_q_scale", INSNAV_SELFCAL_KEYS});
  VehicleConstraintConfig& v = cfg.vehicle;
  v.lever_arm_b = vec3_or_scalar(config, "vehicle_lever_arm_b", v.lever_arm_b);
  if (config.contains("vehicle_C_bv")) {
    DArray c = py::cast<DArray>(config["vehicle_C_bv"]);
    if (c.size() != 9) throw py::value_error("vehicle_C_bv: expected 9 values (row-major 3x3)");
    v.C_bv = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(c.data());
  }
  v.sigma_nhc_mps = num(config, "sigma_nhc_mps", v.sigma_nhc_mps);
  v.sigma_odo_mps = num(config, "sigma_odo_mps", v.sigma_odo_mps);
  v.sigma_zupt_mps = num(config, "sigma_zupt_mps", v.sigma_zupt_mps);
  v.sigma_zaru_radps = num(config, "sigma_zaru_radps", v.sigma_zaru_radps);
  v.second_order_corr_s = num(config, "second_order_corr_s", v.second_order_corr_s);
  if (!(v.second_order_corr_s >= 0.0)) throw py::value_error("second_order_corr_s must be >= 0");
  cfg.constraint_gate_chi2 = num(config, "constraint_gate_chi2", 0.0);
  for (double sgm : {v.sigma_nhc_mps, v.sigma_odo_mps, v.sigma_zupt_mps, v.sigma_zaru_radps})
    if (!(sgm > 0.0)) throw py::value_error("vehicle constraint sigmas must be > 0");
  // adaptive measurement noise of the fixes (filter/adaptive_noise.hpp)
  const double w = num(config, "adaptive_r_window", 0.0);
  if (!(w >= 0.0 && w <= kMaxAdaptiveWindow && w == std::floor(w)))
    throw py::value_error("adaptive_r_window must be an integer in 0.." + std::to_string(kMaxAdaptiveWindow));
  cfg.adaptive_r.window = static_cast<int>(w);
  cfg.adaptive_r.min_fraction = num(config, "adaptive_r_min_fraction", cfg.adaptive_r.min_fraction);
  if (!(cfg.adaptive_r.min_fraction > 0.0 && cfg.adaptive_r.min_fraction <= 1.0))
    throw py::value_error("adaptive_r_min_fraction must be in (0, 1]");
  // adaptive process noise (filter/adaptive_noise.hpp, engine/loose_engine.hpp)
  cfg.adaptive_q = adaptive_q_from(config, cfg.adaptive_q);
  // standstill level of the process noise (engine/loose_engine.hpp; kStill / kMoving events)
  cfg.standstill_q_scale = num(config, "standstill_q_scale", cfg.standstill_q_scale);
  if (!(cfg.standstill_q_scale > 0.0 && std::isfinite(cfg.standstill_q_scale)))
    throw py::value_error("standstill_q_scale must be finite and > 0 (1: off)");
  return cfg;
}

void bind_loose(py::module_& m) {
  m.def(
      "run_loose",
      [](const std::string& filter, int layout, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& gnss, const DArray& init, const DArray& P0, const DArray& corr0, const py::dict& model,
         const py::dict& config, const std::optional<DArray>& constraints) {
        const ImuErrorModel mdl = imu_model_from_dict(model);
        const LooseConfig cfg = loose_run_config_from(config);
        const UtParams ut = ut_from(config);
        const int sigma_columns = static_cast<int>(num(config, "sigma_columns", 0));
        LooseRunArgs args{t, dtheta_b, dv_b, gnss, init, P0, corr0, mdl, cfg, ut, sigma_columns,
                          constraints ? &*constraints : nullptr, flag(config, "smooth", false)};
        const SelfCal sc = selfcal_from(config);
        args.time_offset0_s = sc.time_offset0_s;
        if (sc.any()) {  // self-calibration layouts (layout.hpp): on the 15 states, EKF (bind_loose_selfcal.cpp)
          if (layout != 15)
            throw py::value_error("estimate_time_offset / estimate_lever_arm: layout " + std::to_string(layout) +
                                  " unsupported (the self-calibration states extend the 15-state layout)");
          return run_loose_selfcal(filter, args, sc);
        }
        if (layout == 15) return run_loose_l15(filter, args);
        if (layout == 21) return run_loose_l21(filter, args);
        if (layout == 16) return run_loose_l16(filter, args);  // Layout15 + odometer scale factor
        unsupported_loose(filter, layout);
      },
      py::arg("filter"), py::arg("layout"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("gnss"),
      py::arg("init"), py::arg("P0"), py::arg("imu_correction"), py::arg("imu_model"), py::arg("config"),
      py::arg("constraints") = py::none(),
      "Closed-loop loosely coupled run (SI units; see python/insnav/filters/loose.py).");
}

}  // namespace insnav::py_bind
