// run_loose for Layout15 (ekf, rbukf, ukf): one translation unit per layout
// (loose_run.hpp), so that the parallel build compiles the layouts side by side.
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "loose_run.hpp"

namespace insnav::py_bind {

py::dict run_loose_l15(const std::string& filter, const LooseRunArgs& a) {
  if (filter == "ekf") return run_loose_impl<Ekf<Layout15>>(a);
  if (filter == "rbukf") return run_loose_impl<RbUkf<Layout15>>(a);
  if (filter == "ukf") return run_loose_impl<Ukf<Layout15>>(a);
  unsupported_loose(filter, 15);
}

}  // namespace insnav::py_bind
