// The per-sample input checks of an IMU stream in one pass
// (insnav/ins/imu_scan.hpp) with the GIL released: _core.scan_imu for
// sanitize_imu, the run's finite/increasing checks and check_imu, and
// _core.rotation_about_at for the gyro-against-GNSS-course check.  Python
// builds the messages (which sample, which file line) from the indices.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/engine/solution_scan.hpp"
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

/// A C-contiguous float64 array changed in place (no converting copy).
using InPlace = py::array_t<double, py::array::c_style>;

InPlace require_in_place(const py::object& o, py::ssize_t n, py::ssize_t cols, const char* name) {
  if (!py::isinstance<InPlace>(o)) throw py::value_error(std::string(name) + ": expected a C-contiguous float64 array");
  auto a = py::reinterpret_borrow<InPlace>(o);
  if (a.ndim() != 2 || a.shape(0) != n || a.shape(1) < cols || !a.writeable())
    throw py::value_error(std::string(name) + ": expected a writeable (" + std::to_string(n) + ", >= " +
                          std::to_string(cols) + ") array");
  return a;
}

// The engines' rows in the Solution's units, in place and in one pass: latitude,
// longitude, roll, pitch, yaw and the attitude sigmas (columns att_col..att_col+2 of
// sigma) from rad to deg.  Returns (first row whose latitude, or every velocity
// component, is not finite; whether any latitude or velocity value is not finite),
// -1 for no such row.
py::tuple nav_rows_to_degrees(const py::object& llh_o, const py::object& rpy_o, const py::object& sigma_o,
                              int att_col, const py::object& v_n_o) {
  const py::ssize_t n = py::isinstance<py::array>(llh_o) ? py::reinterpret_borrow<py::array>(llh_o).shape(0) : -1;
  InPlace llh = require_in_place(llh_o, n, 3, "nav_rows_to_degrees: llh");
  InPlace rpy = require_in_place(rpy_o, n, 3, "nav_rows_to_degrees: rpy");
  InPlace sigma = require_in_place(sigma_o, n, att_col + 3, "nav_rows_to_degrees: sigma");
  const DArray v_n = py::cast<DArray>(v_n_o);
  require_shape(v_n, n, 3, "nav_rows_to_degrees: v_n");
  if (att_col < 0) throw py::value_error("nav_rows_to_degrees: att_col < 0");
  constexpr double kRad2Deg = 180.0 / 3.14159265358979323846;
  std::int64_t first_bad = -1;
  bool any_bad = false;
  {
    py::gil_scoped_release release;
    double* pl = llh.mutable_data();
    double* pr = rpy.mutable_data();
    double* ps = sigma.mutable_data() + att_col;
    const py::ssize_t sc = sigma.shape(1);
    const double* pv = v_n.data();
    for (py::ssize_t i = 0; i < n; ++i) {
      double* l = pl + 3 * i;
      double* r = pr + 3 * i;
      double* s = ps + sc * i;
      const double* v = pv + 3 * i;
      const bool lat_ok = std::isfinite(l[0]);
      const int v_ok = int(std::isfinite(v[0])) + int(std::isfinite(v[1])) + int(std::isfinite(v[2]));
      if (!lat_ok || v_ok < 3) {
        any_bad = true;
        if (first_bad < 0 && (!lat_ok || v_ok == 0)) first_bad = i;
      }
      l[0] *= kRad2Deg;
      l[1] *= kRad2Deg;
      r[0] *= kRad2Deg;
      r[1] *= kRad2Deg;
      r[2] *= kRad2Deg;
      s[0] *= kRad2Deg;
      s[1] *= kRad2Deg;
      s[2] *= kRad2Deg;
    }
  }
  return py::make_tuple(first_bad, any_bad);
}

/// Any float64 array (strides kept: the Solution's columns are views of the engine's row blocks).
using Strided = py::array_t<double, 0>;

Strided require_float64(const py::object& o, py::ssize_t n, int ndim, const char* name) {
  if (!py::isinstance<py::array>(o) || py::reinterpret_borrow<py::array>(o).dtype().kind() != 'f' ||
      py::reinterpret_borrow<py::array>(o).itemsize() != 8)
    throw py::value_error(std::string(name) + ": expected a float64 array");
  auto a = py::reinterpret_borrow<Strided>(o);
  if (a.ndim() != ndim || a.shape(0) != n || (ndim == 2 && a.shape(1) != 3))
    throw py::value_error(std::string(name) + ": expected shape (" + std::to_string(n) + (ndim == 2 ? ", 3)" : ",)"));
  return a;
}

// The per-row part of the health verdict in one pass (insnav/engine/solution_scan.hpp).
py::dict scan_solution(const py::object& lat_deg_o, const py::object& lon_deg_o, const py::object& h_m_o,
                       const py::object& v_n_o, const py::list& sigmas, double h_lo_m, double h_hi_m, double r_m) {
  const py::ssize_t n = py::isinstance<py::array>(lat_deg_o) ? py::reinterpret_borrow<py::array>(lat_deg_o).shape(0) : -1;
  if (n < 0) throw py::value_error("scan_solution: lat_deg must be an array");
  Strided lat = require_float64(lat_deg_o, n, 1, "scan_solution: lat_deg");
  Strided lon = require_float64(lon_deg_o, n, 1, "scan_solution: lon_deg");
  Strided h = require_float64(h_m_o, n, 1, "scan_solution: h_m");
  Strided v = require_float64(v_n_o, n, 2, "scan_solution: v_n");
  if (sigmas.size() > 3) throw py::value_error("scan_solution: at most 3 sigma blocks");
  std::vector<Strided> sig;
  RowBlock3 blocks[3];
  for (std::size_t b = 0; b < sigmas.size(); ++b) {
    sig.push_back(require_float64(sigmas[b], n, 2, "scan_solution: sigma"));
    blocks[b] = RowBlock3{sig.back().data(), sig.back().strides(0) / 8, sig.back().strides(1) / 8};
  }
  const auto col = [](const Strided& a) { return Column{a.data(), a.strides(0) / 8}; };
  SolutionScan s;
  {
    py::gil_scoped_release release;
    s = insnav::scan_solution(n, col(lat), col(lon), col(h), RowBlock3{v.data(), v.strides(0) / 8, v.strides(1) / 8},
                              blocks, static_cast<int>(sig.size()), h_lo_m, h_hi_m, r_m);
  }
  py::dict d;
  py::list first, first_col, rows;
  for (std::size_t b = 0; b < sig.size(); ++b) {
    first.append(s.first_bad_sigma[b]);
    first_col.append(s.first_bad_sigma_col[b]);
    rows.append(s.bad_sigma_rows[b]);
  }
  d["first_bad_sigma"] = first;
  d["first_bad_sigma_col"] = first_col;
  d["bad_sigma_rows"] = rows;
  d["first_nonfinite_pos"] = s.first_nonfinite_pos;
  d["max_step_m"] = s.max_step_m;
  d["max_step_row"] = s.max_step_row;
  d["any_finite_step"] = s.any_finite_step;
  d["max_speed_mps"] = s.max_speed_mps;
  d["max_speed_row"] = s.max_speed_row;
  d["any_finite_speed"] = s.any_finite_speed;
  d["first_height_out"] = s.first_height_out;
  return d;
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
  m.def("scan_solution", &scan_solution, py::arg("lat_deg"), py::arg("lon_deg"), py::arg("h_m"), py::arg("v_n"),
        py::arg("sigmas"), py::arg("h_lo_m"), py::arg("h_hi_m"), py::arg("r_m"),
        "One pass over a solution's rows for its health verdict (float64 arrays, any strides): per sigma "
        "block (n, 3) the first row with a value not finite or <= 0, its column and the count of such rows; "
        "the first non-finite position; the longest step between rows [m] on a sphere of radius r_m and the "
        "highest speed [m/s] (NaN skipped, first index of the maximum); the first finite row with a height "
        "outside [h_lo_m, h_hi_m].  Indices are -1 when none.");
  m.def("rotation_about_at", &rotation_about_at, py::arg("t"), py::arg("dtheta_b"), py::arg("axis_b"),
        py::arg("query"),
        "The rotation about the body axis axis_b [rad] integrated from the start of the first sample to each "
        "query time [s], linear between samples; NaN outside [t[0] - (t[1] - t[0]), t[-1]].");
  m.def("nav_rows_to_degrees", &nav_rows_to_degrees, py::arg("llh"), py::arg("rpy"), py::arg("sigma"),
        py::arg("att_col"), py::arg("v_n"),
        "In place, one pass: llh[:, :2], rpy and sigma[:, att_col:att_col + 3] from rad to deg.  Returns "
        "(first row whose latitude or whole velocity is not finite, or -1; any latitude or velocity value not "
        "finite).");
}

}  // namespace insnav::py_bind
