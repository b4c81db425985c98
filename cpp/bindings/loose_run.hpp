// The loosely coupled run behind _core.run_loose, shared by bind_loose*.cpp.
// The engines are instantiated in one translation unit per layout
// (bind_loose_l15.cpp, bind_loose_l16.cpp, bind_loose_l21.cpp: ekf, rbukf and
// ukf each), so that a
// parallel build compiles them side by side; bind_loose.cpp parses the
// arguments and dispatches.  (Per layout rather than per filter: RB-UKF and UKF
// share UnscentedPropagation<L>, and all three share the layout's error models
// and measurement, which a per-filter split would compile three times.)
#pragma once

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <type_traits>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common.hpp"
#include "convert.hpp"
#include "insnav/engine/loose_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "outputs.hpp"
#include "smoother_run.hpp"

namespace insnav::py_bind {

/// The arguments of _core.run_loose, the dicts already parsed.
struct LooseRunArgs {
  const DArray& t;
  const DArray& dtheta_b;
  const DArray& dv_b;
  const DArray& gnss;
  const DArray& init;
  const DArray& P0;
  const DArray& corr0;
  ImuErrorModel model;
  LooseConfig cfg;
  UtParams ut;
  int sigma_columns = 0;  // config key 'sigma_columns': sigmas of the first k states only (<= 0: all)
  const DArray* constraints = nullptr;  // (k, 3): t [s], kinds (ConstraintKind flags), speed [m/s]; sorted by t
  bool smooth = false;                   // config key 'smooth': RTS backward pass (EKF, RB-UKF, UKF)
  double time_offset0_s = 0.0;           // config key 'time_offset0_s': initial t_d (time-offset layouts) [s]
};

LooseConfig loose_run_config_from(const py::dict& config);  // bind_loose.cpp

/// filter 'ekf', 'rbukf' or 'ukf' on one layout (any other filter: ValueError).
py::dict run_loose_l15(const std::string& filter, const LooseRunArgs& a);  // bind_loose_l15.cpp
py::dict run_loose_l21(const std::string& filter, const LooseRunArgs& a);  // bind_loose_l21.cpp
py::dict run_loose_l16(const std::string& filter, const LooseRunArgs& a);  // bind_loose_l16.cpp (Layout16Odo)
/// The self-calibration layouts (Layout16Td, Layout18Lever, Layout19TdLever, Layout18OdoLever; EKF):
/// bind_loose_selfcal.cpp.
py::dict run_loose_selfcal(const std::string& filter, const LooseRunArgs& a, const SelfCal& sc);

[[noreturn]] inline void unsupported_loose(const std::string& filter, int layout) {
  throw py::value_error("unsupported filter/layout combination: " + filter + "/" + std::to_string(layout));
}

/// Validate, run the engine with the GIL released, return the output dict.
template <class Filter>
py::dict run_loose_impl(const LooseRunArgs& a) {
  using L = typename Filter::Layout;
  constexpr int ns = L::kSize;
  const LooseConfig& cfg = a.cfg;
  if (cfg.adaptive_r.window > 0 && !kJacobianUpdate<Filter>)
    throw py::value_error("adaptive_r_window > 0: the EKF and the RB-UKF only (it needs the update's H P H^T)");
  if (cfg.adaptive_q.window > 0 && !kScalableQ<Filter>)
    throw py::value_error("adaptive_q_window > 0: the EKF only (it scales the EKF's process noise)");
  const ImuArrays imu = imu_arrays(a.t, a.dtheta_b, a.dv_b);
  const py::ssize_t m = a.gnss.ndim() == 2 ? a.gnss.shape(0) : 0;
  if (m > 0) require_shape(a.gnss, m, 13, "gnss");
  const NavState nav = nav_state_from(a.init);
  const StateCov<L> P = state_cov_from<L>(a.P0);
  const ImuCorrection corr = imu_correction_from(a.corr0);
  // GNSS rows: t, lat, lon, h, vN, vE, vD, sN, sE, sD, svN, svE, svD (NaN velocity: position only)
  std::vector<GnssFix> fixes(static_cast<size_t>(m));
  for (py::ssize_t i = 0; i < m; ++i) fixes[i] = gnss_fix_from(a.gnss.data()[13 * i], a.gnss.data() + 13 * i + 1);

  // vehicle-constraint events: t, kinds, odometer speed (NaN: none)
  const py::ssize_t k = (a.constraints && a.constraints->ndim() == 2) ? a.constraints->shape(0) : 0;
  std::vector<ConstraintEvent> events(static_cast<size_t>(k));
  if (k > 0) {
    require_shape(*a.constraints, k, 3, "constraints");
    const double* pe = a.constraints->data();
    for (py::ssize_t i = 0; i < k; ++i) {
      const double* r = pe + 3 * i;
      const double kinds = r[1];
      if (!(kinds >= 0 && kinds <= 63 && kinds == std::floor(kinds)))  // ConstraintKind, loose_engine.hpp
        throw py::value_error("constraints row " + std::to_string(i) + ": kinds must be flags 0..63");
      if (i > 0 && !(r[0] >= pe[3 * (i - 1)]))
        throw py::value_error("constraints row " + std::to_string(i) + ": times must be non-decreasing");
      events[i] = ConstraintEvent{r[0], static_cast<std::uint8_t>(kinds), r[2]};
      if ((events[i].kinds & kOdometer) && !std::isfinite(r[2]))
        throw py::value_error("constraints row " + std::to_string(i) + ": odometer event without a finite speed");
    }
  }
  const int n_sig = (a.sigma_columns > 0 && a.sigma_columns < ns) ? a.sigma_columns : ns;
  NavBuffers nav_buf(output_rows(imu.n, cfg.output_decimation), n_sig, false, false, kHasOdoScale<L>,
                     kHasTimeOffset<L>, kHasLeverArm<L>, kHasOdoLever<L>);
  LooseRecordBuffers rec_buf(m);
  DArray o_cnis({k}), o_cldet({k});
  py::array_t<std::int8_t> o_cst({k});
  LooseOutputs out;
  nav_buf.attach(out);
  rec_buf.attach(out, m);
  out.constraint_nis = k ? o_cnis.mutable_data() : nullptr;
  out.constraint_log_det_s = k ? o_cldet.mutable_data() : nullptr;
  out.constraint_status = k ? o_cst.mutable_data() : nullptr;
  const double span = imu.n ? imu.t[imu.n - 1] - nav.t : 0.0;
  SmootherRun<Filter> smoother(a.smooth, m + k, span, cfg.cycle_period);
  std::array<double, 2> q_scale{1.0, 1.0};
  {
    py::gil_scoped_release release;
    auto engine = std::make_unique<LooseEngine<Filter>>(a.model, cfg, a.ut);  // one allocation per run, not per sample
    engine->set_initial_time_offset(a.time_offset0_s);
    smoother.attach(engine->core());
    engine->run(nav, P, corr, imu.n, imu.t, imu.dtheta_b, imu.dv_b, m, fixes.data(), k, events.data(), out);
    smoother.finish(engine->core());
    q_scale = engine->process_noise_scale();
  }
  py::dict res;
  res["process_noise_scale"] = py::make_tuple(q_scale[0], q_scale[1]);
  nav_buf.put(res, out);
  rec_buf.put(res);
  res["constraint_nis"] = o_cnis;
  res["constraint_log_det_s"] = o_cldet;
  res["constraint_status"] = o_cst;
  res["constraint_updates"] = out.constraint_updates;
  res["constraint_rejected"] = out.constraint_rejected;
  smoother.put(res);
  return res;
}

}  // namespace insnav::py_bind
