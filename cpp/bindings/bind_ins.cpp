// Batch strapdown mechanization: the whole loop in C++ with the GIL released.
#include "common.hpp"

namespace insnav::py_bind {

namespace {

/// Run the mechanization over n samples; inputs validated by the caller
/// (python/insnav/ins.py) and re-checked here for shapes.
py::dict mechanize(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, double t0,
                   const DArray& pos_llh, const DArray& v_n0, const DArray& rpy0,
                   bool coning, bool sculling) {
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

  DArray out_llh({n, py::ssize_t(3)}), out_v({n, py::ssize_t(3)}), out_rpy({n, py::ssize_t(3)});
  const double* pt = t.data();
  const double* pth = dtheta_b.data();
  const double* pdv = dv_b.data();
  double* o_llh = out_llh.mutable_data();
  double* o_v = out_v.mutable_data();
  double* o_rpy = out_rpy.mutable_data();
  {
    py::gil_scoped_release release;
    Strapdown ins(nav, MechanizationOptions{coning, sculling});
    double t_prev = t0;
    ImuIncrement imu;
    for (py::ssize_t i = 0; i < n; ++i) {
      imu.t = pt[i];
      imu.dt = pt[i] - t_prev;
      t_prev = pt[i];
      imu.dtheta_b = Vec3(pth[3 * i], pth[3 * i + 1], pth[3 * i + 2]);
      imu.dv_b = Vec3(pdv[3 * i], pdv[3 * i + 1], pdv[3 * i + 2]);
      ins.update(imu);
      const NavState& s = ins.state();
      o_llh[3 * i] = s.lat;
      o_llh[3 * i + 1] = s.lon;
      o_llh[3 * i + 2] = s.h;
      o_v[3 * i] = s.v_n.x();
      o_v[3 * i + 1] = s.v_n.y();
      o_v[3 * i + 2] = s.v_n.z();
      const Vec3 rpy = euler_from_quat(s.q_nb);
      o_rpy[3 * i] = rpy.x();
      o_rpy[3 * i + 1] = rpy.y();
      o_rpy[3 * i + 2] = rpy.z();
    }
  }
  py::dict out;
  out["llh"] = out_llh;
  out["v_n"] = out_v;
  out["rpy"] = out_rpy;
  return out;
}

}  // namespace

void bind_ins(py::module_& m) {
  m.def("mechanize", &mechanize, py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("t0"),
        py::arg("pos_llh"), py::arg("v_n"), py::arg("rpy"), py::arg("coning") = true,
        py::arg("sculling") = true,
        "Strapdown mechanization over IMU increments (rad, m/s) from the state at t0 "
        "(lat/lon rad, h m, v_n m/s, roll/pitch/yaw rad). Returns llh, v_n, rpy arrays (SI).");
}

}  // namespace insnav::py_bind
