// The per-sample input checks of an IMU stream in one pass
// (insnav/ins/imu_scan.hpp) with the GIL released: _core.scan_imu for
// sanitize_imu, the run's finite/increasing checks and check_imu, and
// _core.rotation_about_at for the gyro-against-GNSS-course check.  Python
// builds the messages (which sample, which file line) from the indices.
#include <cmath>
#include <limits>
#include <vector>

#include "common.hpp"
#include "insnav/ins/imu_scan.hpp"

namespace insnav::py_bind {

namespace {

py::dict scan_imu(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, double t0, double max_rate_rps,
                  double max_accel_mps2, double gap_factor) {
  const py::ssize_t n = t.ndim() == 1 ? t.shape(0) : -1;
  if (n < 0) throw py::value_error("scan_imu: t must be 1-D");
  require_shape(dtheta_b, n, 3, "scan_imu: dtheta_b");
  require_shape(dv_b, n, 3, "scan_imu: dv_b");
  ins::ImuScanLimits lim;
  lim.t0_s = t0;
  lim.max_rate_rps = max_rate_rps;
  lim.max_accel_mps2 = max_accel_mps2;
  lim.gap_factor = gap_factor;
  ins::ImuScan s;
  {
    py::gil_scoped_release release;
    std::vector<double> scratch;
    s = ins::scan_imu(t.data(), dtheta_b.data(), dv_b.data(), n, lim, scratch);
  }
  py::dict d;
  d["nonfinite_t"] = s.first_nonfinite_t;
  d["nonfinite_dtheta"] = s.first_nonfinite_dtheta;
  d["nonfinite_dv"] = s.first_nonfinite_dv;
  d["decrease"] = s.first_decrease;
  d["not_increasing"] = s.first_not_increasing;
  d["repeats"] = s.repeats;
  d["dt0"] = s.dt0_s;
  d["rate"] = s.first_rate;
  d["accel"] = s.first_accel;
  d["gaps"] = s.gaps;
  d["max_gap_s"] = s.max_gap_s;
  d["dv_sum"] = py::make_tuple(s.dv_sum[0], s.dv_sum[1], s.dv_sum[2]);
  return d;
}

DArray rotation_about_at(const DArray& t, const DArray& dtheta_b, const DArray& axis_b, const DArray& query) {
  const py::ssize_t n = t.ndim() == 1 ? t.shape(0) : -1;
  if (n < 0) throw py::value_error("rotation_about_at: t must be 1-D");
  require_shape(dtheta_b, n, 3, "rotation_about_at: dtheta_b");
  const Vec3 axis = vec3_from(axis_b, "rotation_about_at: axis_b");
  if (query.ndim() != 1) throw py::value_error("rotation_about_at: query must be 1-D");
  const py::ssize_t m = query.shape(0);
  DArray out(m);
  double* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    const double a[3] = {axis(0), axis(1), axis(2)};
    std::vector<std::int64_t> order;
    ins::rotation_about_at(t.data(), dtheta_b.data(), n, a, query.data(), m, o, order);
  }
  return out;
}

}  // namespace

void bind_checks(py::module_& m) {
  const double inf = std::numeric_limits<double>::infinity();
  m.def("scan_imu", &scan_imu, py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"),
        py::arg("t0") = std::numeric_limits<double>::quiet_NaN(), py::arg("max_rate_rps") = inf,
        py::arg("max_accel_mps2") = inf, py::arg("gap_factor") = inf,
        "One pass over an IMU stream (t [s], dtheta_b [rad], dv_b [m/s]): the first non-finite sample of each "
        "array, the first decreasing / not increasing time, the count of repeated times, the nominal interval "
        "dt0 [s] (median), the first sample over max_rate_rps [rad/s] / max_accel_mps2 [m/s^2], the gaps "
        "(interval > gap_factor * dt0) and the longest, and the sum of dv_b [m/s].  Indices are -1 when none.");
  m.def("rotation_about_at", &rotation_about_at, py::arg("t"), py::arg("dtheta_b"), py::arg("axis_b"),
        py::arg("query"),
        "The rotation about the body axis axis_b [rad] integrated from the start of the first sample to each "
        "query time [s], linear between samples; NaN outside [t[0] - (t[1] - t[0]), t[-1]].");
}

}  // namespace insnav::py_bind
