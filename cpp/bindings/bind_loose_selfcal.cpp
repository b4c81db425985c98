// run_loose for the self-calibration layouts (layout.hpp: Layout16Td = the 15
// states + the IMU-GNSS time offset, Layout18Lever = + the GNSS lever arm,
// Layout19TdLever = both, Layout18OdoLever = + the odometer lever arm), EKF
// only: one translation unit (loose_run.hpp).
#include "insnav/filter/ekf.hpp"
#include "loose_run.hpp"

namespace insnav::py_bind {

py::dict run_loose_selfcal(const std::string& filter, const LooseRunArgs& a, const SelfCal& sc) {
  if (filter != "ekf")
    throw py::value_error("estimate_time_offset / estimate_lever_arm / estimate_odo_lever_arm: filter '" + filter +
                          "' unsupported (the self-calibration states run with the ekf)");
  if (sc.odo_lever_arm) {
    if (sc.time_offset || sc.lever_arm)
      throw py::value_error("estimate_odo_lever_arm: not together with estimate_time_offset / estimate_lever_arm "
                            "(no such layout)");
    return run_loose_impl<Ekf<Layout18OdoLever>>(a);
  }
  if (sc.time_offset && sc.lever_arm) return run_loose_impl<Ekf<Layout19TdLever>>(a);
  if (sc.time_offset) return run_loose_impl<Ekf<Layout16Td>>(a);
  return run_loose_impl<Ekf<Layout18Lever>>(a);
}

}  // namespace insnav::py_bind
