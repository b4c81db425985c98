// Batch strapdown mechanization (the whole loop in C++ with the GIL released), the
// standstill statistic, and the wrapper of the smoothed output rows (engine/smoothed_rows.hpp).
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include <pybind11/stl.h>

#include "common.hpp"
#include "insnav/engine/smoothed_rows.hpp"
#include "insnav/ins/standstill.hpp"

namespace insnav::py_bind {

namespace {

/// `a`: a writeable float64 array of shape (n, cols) (cols < 0: (n,)), any
/// strides, written in place (no converted copy whose writes would be lost).
inline void require_inplace(const py::array& a, py::ssize_t n, py::ssize_t cols, const char* name) {
  if (!a.dtype().is(py::dtype::of<double>()) || !a.writeable())
    throw py::type_error(std::string(name) + ": expected a writeable float64 array");
  const bool ok = cols < 0 ? (a.ndim() == 1 && a.shape(0) == n) : (a.ndim() == 2 && a.shape(0) == n && a.shape(1) == cols);
  if (!ok) throw py::value_error(std::string(name) + ": expected " + std::to_string(n) + " rows" +
                                 (cols < 0 ? std::string() : " of " + std::to_string(cols)));
}

/// A float64 array's element strides (its byte strides are multiples of 8 for any view numpy makes of
/// float64 data; anything else is refused).
inline std::ptrdiff_t element_stride(const py::array& a, int axis) {
  const py::ssize_t b = a.strides(axis);
  if (b % static_cast<py::ssize_t>(sizeof(double)) != 0) throw py::value_error("rows: unaligned float64 strides");
  return static_cast<std::ptrdiff_t>(b / static_cast<py::ssize_t>(sizeof(double)));
}

inline StridedColumn column(py::array& a) {
  return StridedColumn{static_cast<double*>(a.mutable_data()), element_stride(a, 0)};
}

inline StridedMatrix matrix(py::array& a) {
  return StridedMatrix{static_cast<double*>(a.mutable_data()), element_stride(a, 0), element_stride(a, 1)};
}

/// Run the mechanization over n samples.  The loop also checks each sample
/// before using it (finite values, strictly increasing time) and stops at the
/// first bad one, returning its index as "bad_sample" (python/insnav/ins/mechanize.py
/// then raises the ValueError naming it), so the batch call pays no separate
/// validation pass.  Outputs are written once, in the user units of
/// insnav.Trajectory (degrees), into separate contiguous arrays.
py::dict mechanize(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, double t0,
                   const DArray& pos_llh, const DArray& v_n0, const DArray& rpy0,
                   bool coning, bool sculling) {
  constexpr double kRad2Deg = 180.0 / 3.14159265358979323846;
  const py::ssize_t n = t.size();
  require_shape(t, n, -1, "t");
  require_shape(dtheta_b, n, 3, "dtheta_b");
  require_shape(dv_b, n, 3, "dv_b");
  const Vec3 llh = vec3_from(pos_llh, "pos_llh");
  NavState nav;
  nav.t = t0;
  nav.lat = llh.x();
  nav.lon = llh.y();
  nav.h = llh.z();
  nav.v_n = vec3_from(v_n0, "v_n");
  nav.q_nb = quat_from_euler(vec3_from(rpy0, "rpy"));

  DArray o_lat({n}), o_lon({n}), o_h({n}), o_v({n, py::ssize_t(3)}), o_roll({n}), o_pitch({n}), o_yaw({n});
  const double* pt = t.data();
  const double* pth = dtheta_b.data();
  const double* pdv = dv_b.data();
  double* lat = o_lat.mutable_data();
  double* lon = o_lon.mutable_data();
  double* h = o_h.mutable_data();
  double* v = o_v.mutable_data();
  double* roll = o_roll.mutable_data();
  double* pitch = o_pitch.mutable_data();
  double* yaw = o_yaw.mutable_data();
  py::ssize_t bad = -1;
  {
    py::gil_scoped_release release;
    Strapdown ins(nav, MechanizationOptions{coning, sculling});
    double t_prev = t0;
    ImuIncrement imu;
    for (py::ssize_t i = 0; i < n; ++i) {
      imu.t = pt[i];
      imu.dt = pt[i] - t_prev;
      imu.dtheta_b = Vec3(pth[3 * i], pth[3 * i + 1], pth[3 * i + 2]);
      imu.dv_b = Vec3(pdv[3 * i], pdv[3 * i + 1], pdv[3 * i + 2]);
      // !(dt > 0) also catches a NaN time
      if (!(imu.dt > 0.0) || !std::isfinite(imu.t) || !imu.dtheta_b.allFinite() || !imu.dv_b.allFinite()) {
        bad = i;
        break;
      }
      t_prev = pt[i];
      ins.update(imu);
      const NavState& s = ins.state();
      lat[i] = s.lat * kRad2Deg;
      lon[i] = s.lon * kRad2Deg;
      h[i] = s.h;
      v[3 * i] = s.v_n.x();
      v[3 * i + 1] = s.v_n.y();
      v[3 * i + 2] = s.v_n.z();
      const Vec3 rpy = euler_from_quat(s.q_nb);
      roll[i] = rpy.x() * kRad2Deg;
      pitch[i] = rpy.y() * kRad2Deg;
      yaw[i] = rpy.z() * kRad2Deg;
    }
  }
  py::dict out;
  out["bad_sample"] = bad;
  out["lat_deg"] = o_lat;
  out["lon_deg"] = o_lon;
  out["h_m"] = o_h;
  out["v_n"] = o_v;
  out["roll_deg"] = o_roll;
  out["pitch_deg"] = o_pitch;
  out["yaw_deg"] = o_yaw;
  return out;
}

}  // namespace

void bind_ins(py::module_& m) {
  m.def("mechanize", &mechanize, py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("t0"),
        py::arg("pos_llh"), py::arg("v_n"), py::arg("rpy"), py::arg("coning") = true,
        py::arg("sculling") = true,
        "Strapdown mechanization over IMU increments (rad, m/s) from the state at t0 "
        "(lat/lon rad, h m, v_n m/s, roll/pitch/yaw rad). Returns lat_deg, lon_deg, h_m, v_n [m/s], "
        "roll_deg, pitch_deg, yaw_deg arrays and bad_sample (-1, or the first sample that is not finite "
        "or not after the previous time; the outputs are then incomplete).");
  m.def(
      "smooth_rows",
      [](const DArray& t, py::array lat_deg, py::array lon_deg, py::array h_m, py::array v_n, py::array roll_deg,
         py::array pitch_deg, py::array yaw_deg, const DArray& te, const DArray& s, const DArray& s_end,
         const DArray& sig_e, py::array sig_out, const std::optional<py::array>& extra) {
        const py::ssize_t n = t.size(), E = te.size();
        // columns: 9 navigation errors (position, velocity, attitude), then q additive ones (clock, ISBs)
        const py::ssize_t c = s.ndim() == 2 ? s.shape(1) : 0, q = c - 9;
        if (q < 0) throw py::value_error("smooth_rows: s needs at least 9 columns");
        require_shape(t, n, -1, "t");
        for (const py::array* a : {&lat_deg, &lon_deg, &h_m, &roll_deg, &pitch_deg, &yaw_deg})
          require_inplace(*a, n, -1, "rows");
        require_inplace(v_n, n, 3, "v_n");
        require_inplace(sig_out, n, c, "sigma_out");
        require_shape(te, E, -1, "te");
        for (const DArray* a : {&s, &s_end, &sig_e}) require_shape(*a, E, c, "epochs");
        if (q > 0 && !extra) throw py::value_error("smooth_rows: extra (n, " + std::to_string(q) + ") rows needed");
        py::array ex = q > 0 ? *extra : py::array_t<double>(std::vector<py::ssize_t>{0, 1});
        if (q > 0) require_inplace(ex, n, q, "extra");
        if (E < 2) throw py::value_error("smooth_rows: needs at least 2 epochs");
        SmoothedErrors e;
        e.n_epochs = E;
        e.cols = static_cast<int>(c);
        e.t = te.data();
        e.d = s.data();
        e.d_end = s_end.data();
        e.sigma = sig_e.data();
        // in place, any strides (e.g. the columns of the engine's (n, 3) llh array): no copies
        NavRowsRef r;
        r.n = n;
        r.t = t.data();
        r.lat = column(lat_deg);
        r.lon = column(lon_deg);
        r.h = column(h_m);
        r.roll = column(roll_deg);
        r.pitch = column(pitch_deg);
        r.yaw = column(yaw_deg);
        r.v_n = matrix(v_n);
        r.sigma = matrix(sig_out);
        r.extra = matrix(ex);
        r.to_rad = kDegToRad;
        r.from_rad = kRadToDeg;
        py::gil_scoped_release release;
        smooth_nav_rows(e, r, n < 20000 ? 1 : 2);  // engine/smoothed_rows.hpp
      },
      py::arg("t"), py::arg("lat_deg"), py::arg("lon_deg"), py::arg("h_m"), py::arg("v_n"), py::arg("roll_deg"),
      py::arg("pitch_deg"), py::arg("yaw_deg"), py::arg("te"), py::arg("s"), py::arg("s_end"), py::arg("sigma_e"),
      py::arg("sigma_out"), py::arg("extra") = py::none(),
      "Smoothed output rows in place (python/insnav/filters/smoothing.py; float64 rows, any strides): the error at each row time, "
      "interpolated between the epochs' smoothed errors s (after) and s_end (before feedback), corrects "
      "position [m], velocity [m/s] and attitude [rad] (s columns 0-8) as the engines' feedback does, and "
      "subtracts from `extra` (n, c - 9) the errors of s columns 9.. (receiver clock, inter-system biases); "
      "sigmas (c columns, in the units of sigma_e) interpolated into sigma_out (n, c; written in place, any strides).");
  m.def(
      "standstill_statistic",
      [](const DArray& t, const DArray& dtheta_b, const DArray& dv_b, double t0, int window, double sigma_f_mps2,
         double sigma_w_radps, double gravity_mps2) {
        const py::ssize_t n = t.size();
        require_shape(t, n, -1, "t");
        require_shape(dtheta_b, n, 3, "dtheta_b");
        require_shape(dv_b, n, 3, "dv_b");
        StandstillConfig cfg;
        cfg.window = window;
        cfg.sigma_f_mps2 = sigma_f_mps2;
        cfg.sigma_w_radps = sigma_w_radps;
        cfg.gravity_mps2 = gravity_mps2;
        if (!(window >= 2 && window <= 512)) throw py::value_error("standstill window must be 2..512 samples");
        if (!(sigma_f_mps2 > 0 && sigma_w_radps > 0)) throw py::value_error("standstill sigmas must be > 0");
        DArray out({n});
        {
          py::gil_scoped_release release;
          StandstillDetector<512> det(cfg);
          const double *pt = t.data(), *pa = dtheta_b.data(), *pv = dv_b.data();
          double* po = out.mutable_data();
          double prev = t0;
          for (py::ssize_t k = 0; k < n; ++k) {
            const double dt = pt[k] - prev;
            prev = pt[k];
            if (!(dt > 0)) {
              po[k] = std::numeric_limits<double>::infinity();
              det.reset();
              continue;
            }
            po[k] = det.add(Vec3(pv[3 * k], pv[3 * k + 1], pv[3 * k + 2]) / dt,
                            Vec3(pa[3 * k], pa[3 * k + 1], pa[3 * k + 2]) / dt);
          }
        }
        return out;
      },
      py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("t0"), py::arg("window"), py::arg("sigma_f_mps2"),
      py::arg("sigma_w_radps"), py::arg("gravity_mps2") = 9.80665,
      "The standstill test statistic T of every IMU sample over the last `window` samples "
      "(ins/standstill.hpp; +inf until the window is full); stationary where T < gamma.");
}

}  // namespace insnav::py_bind
