// run_tight for the self-calibration layouts (layout.hpp: LayoutTightTd = the
// 17 states + the IMU-GNSS time offset, LayoutTightLever = + the GNSS lever
// arm, LayoutTightTdLever = both), EKF only (tight_run.hpp).
#include "insnav/filter/ekf.hpp"
#include "tight_run.hpp"

namespace insnav::py_bind {

py::dict run_tight_selfcal(const std::string& filter, const TightArgs& a, bool time_offset, bool lever_arm) {
  if (filter != "ekf")
    throw py::value_error("estimate_time_offset / estimate_lever_arm: filter '" + filter +
                          "' unsupported (the self-calibration states run with the ekf)");
  if (time_offset && lever_arm) return run_tight_impl<Ekf<LayoutTightTdLever>>(a);
  if (time_offset) return run_tight_impl<Ekf<LayoutTightTd>>(a);
  return run_tight_impl<Ekf<LayoutTightLever>>(a);
}

}  // namespace insnav::py_bind
