// Batch strapdown mechanization: the whole loop in C++ with the GIL released.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <thread>
#include <vector>

#include <pybind11/stl.h>

#include "common.hpp"
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

/// sin and cos of one angle in one call where the C library has sincos (glibc).
inline void sin_cos(double a, double& s, double& c) {
#if defined(__GLIBC__)
  ::sincos(a, &s, &c);
#else
  s = std::sin(a);
  c = std::cos(a);
#endif
}

/// quat_from_euler for the attitude corrections of smooth_rows: half angles
/// below 1e-2 rad by their Taylor series (remainder below 1e-19), else exact.
inline Quat small_quat_from_euler(double roll, double pitch, double yaw) {
  const double hr = 0.5 * roll, hp = 0.5 * pitch, hy = 0.5 * yaw;
  if (!(std::max({std::abs(hr), std::abs(hp), std::abs(hy)}) < 1e-2)) return quat_from_euler(Vec3(roll, pitch, yaw));
  // reciprocal constants: multiplications, not divisions, in the row loop (the same to rounding)
  const auto sin_s = [](double h) {
    const double h2 = h * h;
    return h * (1.0 - h2 * (1.0 / 6.0) * (1.0 - h2 * (1.0 / 20.0) * (1.0 - h2 * (1.0 / 42.0))));
  };
  const auto cos_s = [](double h) {
    const double h2 = h * h;
    return 1.0 - h2 * 0.5 * (1.0 - h2 * (1.0 / 12.0) * (1.0 - h2 * (1.0 / 30.0) * (1.0 - h2 * (1.0 / 56.0))));
  };
  const double sr = sin_s(hr), cr = cos_s(hr), sp = sin_s(hp), cp = cos_s(hp), sy = sin_s(hy), cy = cos_s(hy);
  return Quat(cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
              cr * cp * sy - sr * sp * cy);
}

/// atan(x) for |x| <= 0.02 by its series to x^11 (remainder below x^13 / 13 < 1e-23).
inline double small_atan(double x) {
  const double x2 = x * x;
  return x * (1.0 - x2 * (1.0 / 3.0 - x2 * (1.0 / 5.0 - x2 * (1.0 / 7.0 - x2 * (1.0 / 9.0 - x2 * (1.0 / 11.0))))));
}

/// atan2(a, b) as the angle `ref` (sin_ref, cos_ref at hand) plus the small
/// difference atan2(a cos_ref - b sin_ref, b cos_ref + a sin_ref) by its
/// series, wrapped to (-pi, pi]: the same angle without a full atan2 when the
/// corrected angle is within 0.02 rad of the row's own; else atan2(a, b).
inline double atan2_near(double a, double b, double ref, double sin_ref, double cos_ref) {
  constexpr double kPi = 3.14159265358979323846;
  const double num = a * cos_ref - b * sin_ref, den = b * cos_ref + a * sin_ref;
  if (!(den > 0.0) || !(std::abs(num) <= 0.02 * den)) return std::atan2(a, b);
  double r = ref + small_atan(num / den);
  if (r > kPi) r -= 2.0 * kPi;
  if (r <= -kPi) r += 2.0 * kPi;
  return r;
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
        // in place, any strides (e.g. the columns of the engine's (n, 3) llh array): no copies
        auto la = lat_deg.mutable_unchecked<double, 1>(), lo = lon_deg.mutable_unchecked<double, 1>(),
             h = h_m.mutable_unchecked<double, 1>(), r = roll_deg.mutable_unchecked<double, 1>(),
             p = pitch_deg.mutable_unchecked<double, 1>(), y = yaw_deg.mutable_unchecked<double, 1>();
        auto v = v_n.mutable_unchecked<double, 2>();
        auto px = ex.mutable_unchecked<double, 2>();
        auto so = sig_out.mutable_unchecked<double, 2>();
        const double *pt = t.data(), *pe = te.data(), *ps = s.data(), *pse = s_end.data(), *pg = sig_e.data();
        constexpr double kDeg = 3.14159265358979323846 / 180.0, kRad2Deg = 180.0 / 3.14159265358979323846;
        // rows are independent: blocks on up to 2 threads (the rows' own
        // trigonometry dominates: ~0.25 us a row), each finding its first epoch
        // interval by bisection (rows are sorted in time)
        auto rows = [&](py::ssize_t i_begin, py::ssize_t i_end) {
          py::ssize_t k = 0;  // epoch interval [te[k], te[k+1]) holding the row
          if (i_begin < i_end) {
            const py::ssize_t idx = std::lower_bound(pe, pe + E, pt[i_begin]) - pe;  // pe[idx] >= t
            k = std::min<py::ssize_t>(std::max<py::ssize_t>(idx - 1, 0), E - 2);
          }
          // blocks of kBlock rows in three passes (interpolation; position and velocity; attitude):
          // the short passes let the rows' sqrt / division chains overlap (the same arithmetic per row)
          constexpr py::ssize_t kBlock = 32;
          double X[kBlock][9];
          for (py::ssize_t i0 = i_begin; i0 < i_end; i0 += kBlock) {
            const py::ssize_t m = std::min(kBlock, i_end - i0);
            for (py::ssize_t b = 0; b < m; ++b) {
              const py::ssize_t i = i0 + b;
              double* x = X[b];
              const double ti = pt[i];
              while (k + 2 < E && pe[k + 1] < ti) ++k;  // ti in (te[k], te[k+1]]
              const double t0 = pe[k], t1 = pe[k + 1];
              const double w = t1 > t0 ? std::min(1.0, std::max(0.0, (ti - t0) / (t1 - t0))) : 1.0;
              // a row at t_{k+1} (or after the last epoch) is written after that epoch's feedback:
              // s_{k+1}; before it, s_{k+1} + x_fed
              const double* end = ti > t1 - 1e-9 ? ps + c * (k + 1) : pse + c * (k + 1);
              const double* beg = ps + c * k;
              for (py::ssize_t j = 0; j < c; ++j) so(i, j) = (1.0 - w) * pg[c * k + j] + w * pg[c * (k + 1) + j];
              for (int j = 0; j < 9; ++j) x[j] = (1.0 - w) * beg[j] + w * end[j];
              for (py::ssize_t j = 0; j < q; ++j) px(i, j) -= (1.0 - w) * beg[9 + j] + w * end[9 + j];
            }
            for (py::ssize_t b = 0; b < m; ++b) {
              const py::ssize_t i = i0 + b;
              const double* x = X[b];
              const double lat = la(i) * kDeg;
              double s_lat, c_lat;
              sin_cos(lat, s_lat, c_lat);
              const double w_lat = 1.0 - wgs84::kE2 * s_lat * s_lat;  // wgs84::radii with the sine at hand
              const double R_N = wgs84::kA / std::sqrt(w_lat), R_M = R_N * (1.0 - wgs84::kE2) / w_lat;
              la(i) = (lat - x[0] / (R_M + h(i))) * kRad2Deg;
              lo(i) -= x[1] / ((R_N + h(i)) * c_lat) * kRad2Deg;
              h(i) += x[2];
              for (int j = 0; j < 3; ++j) v(i, j) -= x[3 + j];
            }
            for (py::ssize_t b = 0; b < m; ++b) {
              const py::ssize_t i = i0 + b;
              const double* x = X[b];
              // C_nb <- dcm(psi) C_nb through quaternions (quat_from_euler, euler_from_dcm of
              // math/rotation.hpp); the new angles as the row's plus a small difference
              // (atan2_near: no full atan2 when the correction is below 0.02 rad)
              const double roll = r(i) * kDeg, pitch = p(i) * kDeg, yaw = y(i) * kDeg;
              double shr, chr, shp, chp, shy, chy;  // half angles
              sin_cos(0.5 * roll, shr, chr);
              sin_cos(0.5 * pitch, shp, chp);
              sin_cos(0.5 * yaw, shy, chy);
              const Quat q_row(chr * chp * chy + shr * shp * shy, shr * chp * chy - chr * shp * shy,
                               chr * shp * chy + shr * chp * shy, chr * chp * shy - shr * shp * chy);
              Quat qc = small_quat_from_euler(x[6], x[7], x[8]) * q_row;
              qc.coeffs() *= 1.0 / qc.coeffs().norm();  // normalized with one division
              const Mat3 C = qc.toRotationMatrix();
              const double cp = std::sqrt(C(2, 1) * C(2, 1) + C(2, 2) * C(2, 2));
              const bool locked = !(cp > 1e-12);
              const double inv_cp = locked ? 0.0 : 1.0 / cp;
              const double sr = locked ? 0.0 : C(2, 1) * inv_cp, cr = locked ? 1.0 : C(2, 2) * inv_cp;
              // sin and cos of the row's angles from the half angles' (double-angle formulas)
              const auto full = [](double sh, double ch, double& sf, double& cf) {
                sf = 2.0 * sh * ch;
                cf = (ch - sh) * (ch + sh);
              };
              double sin_r, cos_r, sin_p, cos_p, sin_y, cos_y;
              full(shr, chr, sin_r, cos_r);
              full(shp, chp, sin_p, cos_p);
              full(shy, chy, sin_y, cos_y);
              p(i) = atan2_near(-C(2, 0), cp, pitch, sin_p, cos_p) * kRad2Deg;
              r(i) = locked ? 0.0 : atan2_near(C(2, 1), C(2, 2), roll, sin_r, cos_r) * kRad2Deg;
              y(i) = atan2_near(sr * C(0, 2) - cr * C(0, 1), cr * C(1, 1) - sr * C(1, 2), yaw, sin_y, cos_y) * kRad2Deg;
            }
          }
        };
        {
          py::gil_scoped_release release;
          const int threads = n < 20000 ? 1 : 2;
          std::vector<std::thread> pool;
          const py::ssize_t block = (n + threads - 1) / threads;
          for (int th = 1; th < threads; ++th)
            pool.emplace_back(rows, std::min<py::ssize_t>(n, th * block), std::min<py::ssize_t>(n, (th + 1) * block));
          rows(0, std::min<py::ssize_t>(n, block));
          for (auto& th : pool) th.join();
        }
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
