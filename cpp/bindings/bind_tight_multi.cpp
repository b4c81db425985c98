// Tightly coupled run with inter-system bias states (LayoutTightMulti): the
// EKF, RB-UKF and UKF of bind_tight.cpp on 20 states (tight_run.hpp).
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "tight_run.hpp"

namespace insnav::py_bind {

py::dict run_tight_multi(const std::string& filter, const TightArgs& a) {
  if (filter == "ekf") return run_tight_impl<Ekf<LayoutTightMulti>>(a);
  if (filter == "rbukf") return run_tight_impl<RbUkf<LayoutTightMulti>>(a);
  if (filter == "ukf") return run_tight_impl<Ukf<LayoutTightMulti>>(a);
  throw py::value_error("unsupported tight filter: " + filter + " (ekf, rbukf, ukf)");
}

}  // namespace insnav::py_bind
