// Batch strapdown mechanization: the whole loop in C++ with the GIL released.
#include <cmath>
#include <limits>

#include "common.hpp"
#include "insnav/ins/standstill.hpp"

namespace insnav::py_bind {

namespace {

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
