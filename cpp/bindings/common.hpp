// Shared helpers for the pybind11 bindings (not part of the core).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>

#include "insnav/core.hpp"
#include "insnav/filter/types.hpp"

namespace insnav::py_bind {

namespace py = pybind11;

/// C-contiguous float64 array; forcecast converts other dtypes once.
using DArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

/// Require `a` to have shape (n, cols) (cols < 0: 1-D of length n).
inline void require_shape(const DArray& a, py::ssize_t n, py::ssize_t cols, const char* name) {
  if (cols < 0) {
    if (a.ndim() != 1 || a.shape(0) != n)
      throw py::value_error(std::string(name) + ": expected shape (" + std::to_string(n) + ",)");
  } else if (a.ndim() != 2 || a.shape(0) != n || a.shape(1) != cols) {
    throw py::value_error(std::string(name) + ": expected shape (" + std::to_string(n) + ", " +
                          std::to_string(cols) + ")");
  }
}

inline Vec3 vec3_from(const DArray& a, const char* name) {
  if (a.size() != 3) throw py::value_error(std::string(name) + ": expected 3 values");
  const double* p = a.data();
  return Vec3(p[0], p[1], p[2]);
}

void bind_math(py::module_& m);
void bind_ins(py::module_& m);
void bind_loose(py::module_& m);
void bind_tight(py::module_& m);
void bind_delay(py::module_& m);
void bind_particle(py::module_& m);
void bind_textio(py::module_& m);
void bind_checks(py::module_& m);
void bind_navigator(py::module_& m);
void bind_rtk(py::module_& m);
void bind_spp(py::module_& m);
ImuErrorModel imu_model_from_dict(const py::dict& d);

}  // namespace insnav::py_bind
