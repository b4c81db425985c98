// insnav._core: the private compiled module under the pure-Python API.
#include <stdexcept>
#include <string>

#include "common.hpp"

namespace py = pybind11;

namespace insnav::py_bind {
void bind_rtk_ins(py::module_& m);  // bind_rtk_ins.cpp (declared here: common.hpp is in every binder's TU)
void bind_calib(py::module_& m);
void bind_loose_stream(py::module_& m);  // bind_loose_stream.cpp  // bind_calib.cpp (declared here: common.hpp unchanged keeps the other units' builds cached)
}  // namespace insnav::py_bind

namespace {
// Core precondition failures become Python exceptions instead of abort().
void throwing_check_handler(const char* expr, const char* msg, const char* file, int line) {
  throw std::invalid_argument(std::string("insnav: ") + msg + " [" + expr + " at " + file + ":" +
                              std::to_string(line) + "]");
}
}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "insnav compiled core (private; use the insnav package API)";
  m.attr("__version__") = INSNAV_VERSION;
  insnav::set_check_handler(&throwing_check_handler);
  insnav::py_bind::bind_math(m);
  insnav::py_bind::bind_ins(m);
  insnav::py_bind::bind_loose(m);
  insnav::py_bind::bind_tight(m);
  insnav::py_bind::bind_delay(m);
  insnav::py_bind::bind_particle(m);
  insnav::py_bind::bind_textio(m);
  insnav::py_bind::bind_checks(m);
  insnav::py_bind::bind_navigator(m);
  insnav::py_bind::bind_rtk(m);
  insnav::py_bind::bind_spp(m);
  insnav::py_bind::bind_rtk_ins(m);
  insnav::py_bind::bind_calib(m);
  insnav::py_bind::bind_loose_stream(m);
  // one call per cpp/bindings/bind_*.cpp (declared in common.hpp)
}
