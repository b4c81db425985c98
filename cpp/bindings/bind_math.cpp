// Bindings for rotations and the WGS-84 Earth model (mostly for tests and
// Python-side geometry; the hot loops never call back into Python).
#include "common.hpp"

#include <pybind11/eigen.h>

namespace insnav::py_bind {

void bind_math(py::module_& m) {
  auto e = m.def_submodule("earth", "WGS-84 Earth model (C++ core)");
  e.def("gravity", py::vectorize(&wgs84::gravity), py::arg("lat"), py::arg("h"),
        "Normal gravity [m/s^2] at latitude [rad] and height [m].");
  e.def("radius_meridian", py::vectorize([](double lat) { return wgs84::radii(lat).R_M; }));
  e.def("radius_prime_vertical", py::vectorize([](double lat) { return wgs84::radii(lat).R_N; }));
  e.def("geodetic_to_ecef", [](double lat, double lon, double h) { return wgs84::geodetic_to_ecef(lat, lon, h); });
  e.def("ecef_to_geodetic", [](const Vec3& r_e) { return wgs84::ecef_to_geodetic(r_e); });
  e.def("C_en", &wgs84::C_en);
  e.def("omega_ie_n", &wgs84::omega_ie_n);
  e.def("omega_en_n", [](double lat, double h, const Vec3& v_n) {
    return wgs84::omega_en_n(lat, h, v_n, wgs84::radii(lat));
  });

  auto r = m.def_submodule("rotation", "Rotations: DCM, quaternion (w, x, y, z), 3-2-1 Euler, rotation vector");
  r.def("dcm_from_euler", &dcm_from_euler, py::arg("rpy"));
  r.def("euler_from_dcm", &euler_from_dcm, py::arg("C_nb"));
  r.def("quat_from_euler", [](const Vec3& rpy) { return quat_from_euler(rpy).coeffs(); },
        "Returns (x, y, z, w) as Eigen stores it.");
  r.def("quat_from_rotvec", [](const Vec3& phi) {
    const Quat q = quat_from_rotvec(phi);
    return Eigen::Vector4d(q.w(), q.x(), q.y(), q.z());
  }, "Quaternion (w, x, y, z) of a rotation vector [rad].");
  r.def("rotvec_from_quat", [](const Eigen::Vector4d& wxyz) {
    return rotvec_from_quat(Quat(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).normalized());
  });
  r.def("dcm_from_rotvec", &dcm_from_rotvec);
}

}  // namespace insnav::py_bind
