// The tightly coupled run of bind_tight.cpp (Layout17) and
// bind_tight_multi.cpp (LayoutTightMulti, several constellations): one
// template, instantiated in two translation units so that they compile in
// parallel.
#pragma once

#include <array>
#include <memory>
#include <string>

#include "common.hpp"
#include "convert.hpp"
#include "insnav/engine/tight_engine.hpp"
#include "outputs.hpp"
#include "smoother_run.hpp"

namespace insnav::py_bind {

/// Everything run_tight hands a layout's run (converted once).
struct TightArgs {
  ImuArrays imu;
  TightInputs in;
  NavState nav;
  DArray P0;
  ImuCorrection corr;
  double clock_bias0 = 0.0, clock_drift0 = 0.0;
  IsbVec isb0 = IsbVec::Zero();
  ImuErrorModel model;
  TightConfig cfg;
  UtParams ut;
  bool smooth = false;  // config key 'smooth': RTS backward pass (EKF, RB-UKF, UKF; smoother_run.hpp)
  std::vector<PhaseObservation> phase;  // carrier phase per satellite row (TDCP; empty: none)
  double time_offset0_s = 0.0;  // config key 'time_offset0_s': initial t_d (time-offset layouts) [s]
  std::vector<std::uint8_t> epoch_still;  // the standstill detector's state per epoch (empty: none)
};

template <class Filter>
py::dict run_tight_impl(const TightArgs& a) {
  using L = typename Filter::Layout;
  if (a.cfg.tdcp.enabled && !TightEngine<Filter>::kCanTdcp)
    throw py::value_error("tdcp: time-differenced carrier phase runs with the tight ekf only");
  if (a.cfg.pr_gm.enabled()) {
    if (!TightEngine<Filter>::kCanGm)
      throw py::value_error("pr_gm_sigma_m: the Gauss-Markov pseudorange states run with the tight ekf only");
    if (a.cfg.tdcp.enabled) throw py::value_error("pr_gm_sigma_m: the Gauss-Markov pseudorange states do not run with tdcp");
    if (a.smooth) throw py::value_error("pr_gm_sigma_m: the Gauss-Markov pseudorange states do not run with smooth");
  }
  if (a.cfg.adaptive_q.window > 0 && !kScalableQ<Filter>)
    throw py::value_error("adaptive_q_window > 0: the EKF only (it scales the EKF's process noise)");
  const StateCov<L> P = state_cov_from<L>(a.P0);
  NavBuffers nav_buf(output_rows(a.imu.n, a.cfg.output_decimation), L::kSize, true, kHasIsb<L>, false,
                     kHasTimeOffset<L>, kHasLeverArm<L>);
  TightRecordBuffers rec_buf(a.in.E, a.in.M);
  TightOutputs out;
  nav_buf.attach(out);
  rec_buf.attach(out);
  const double span = a.imu.n ? a.imu.t[a.imu.n - 1] - a.nav.t : 0.0;
  SmootherRun<Filter> smoother(a.smooth, a.in.E, span, a.cfg.cycle_period);
  std::array<double, 2> q_scale{1.0, 1.0};
  {
    py::gil_scoped_release release;
    auto engine = std::make_unique<TightEngine<Filter>>(a.model, a.cfg, a.ut);  // one allocation per run
    engine->set_initial_isb(a.isb0);
    if (a.cfg.tdcp.enabled && !a.phase.empty()) engine->set_phase(a.phase.data());
    engine->set_initial_time_offset(a.time_offset0_s);
    if (!a.epoch_still.empty()) engine->set_standstill(a.epoch_still.data());
    smoother.attach(engine->core());
    engine->run(a.nav, P, a.corr, a.clock_bias0, a.clock_drift0, a.imu.n, a.imu.t, a.imu.dtheta_b, a.imu.dv_b, a.in.E,
                a.in.epochs.data(), a.in.sats.data(), out);
    smoother.finish(engine->core());
    q_scale = engine->process_noise_scale();
  }
  py::dict res;
  res["process_noise_scale"] = py::make_tuple(q_scale[0], q_scale[1]);
  nav_buf.put(res, out);
  rec_buf.put(res, out);
  smoother.put(res);
  return res;
}

/// LayoutTightMulti runs (bind_tight_multi.cpp).
py::dict run_tight_multi(const std::string& filter, const TightArgs& a);

/// The self-calibration layouts (LayoutTightTd, LayoutTightLever, LayoutTightTdLever; EKF):
/// bind_tight_selfcal.cpp.
py::dict run_tight_selfcal(const std::string& filter, const TightArgs& a, bool time_offset, bool lever_arm);

}  // namespace insnav::py_bind
