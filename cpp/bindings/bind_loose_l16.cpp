// run_loose for Layout16Odo (Layout15 + the odometer scale factor; ekf, rbukf,
// ukf): one translation unit per layout (loose_run.hpp), so that the parallel
// build compiles the layouts side by side.
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "loose_run.hpp"

namespace insnav::py_bind {

py::dict run_loose_l16(const std::string& filter, const LooseRunArgs& a) {
  if (filter == "ekf") return run_loose_impl<Ekf<Layout16Odo>>(a);
  if (filter == "rbukf") return run_loose_impl<RbUkf<Layout16Odo>>(a);
  if (filter == "ukf") return run_loose_impl<Ukf<Layout16Odo>>(a);
  unsupported_loose(filter, 16);
}

}  // namespace insnav::py_bind
