// The part of the push-API binders (bind_navigator.cpp, bind_tight_navigator.cpp,
// bind_delay_navigator.cpp) that does not depend on the family: the IMU pushes,
// flush, the output row as a dict, the covariance and the common counters.
// Each family derives its virtual interface from PushNavigator, its
// implementation from PushImpl, and adds its own record pushes.
#pragma once

#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "convert.hpp"
#include "insnav/engine/navigator.hpp"

namespace insnav::py_bind {

/// The calls every push navigator has, independent of the filter and layout.
struct PushNavigator {
  virtual ~PushNavigator() = default;
  virtual bool push_imu(double t, const Vec3& dth, const Vec3& dv) = 0;
  virtual std::int64_t push_imu_array(const double* t, const double* dth, const double* dv, std::int64_t n) = 0;
  virtual void flush() = 0;
  virtual py::dict solution() = 0;
  virtual DArray covariance() = 0;
  virtual py::dict counters() = 0;
};

template <class V>
DArray to_array(const V& v) {
  DArray a({static_cast<py::ssize_t>(v.size())});
  for (py::ssize_t j = 0; j < a.size(); ++j) a.mutable_data()[j] = v[j];
  return a;
}

/// A navigator row as the dict insnav.filters.navigator reads (radians, SI).
template <class L>
py::dict row_dict(const NavigatorRow<L>& r) {
  py::dict d;
  d["t"] = r.t;
  d["lat"] = r.llh[0];
  d["lon"] = r.llh[1];
  d["h"] = r.llh[2];
  d["v_n"] = to_array(r.v_n);
  d["rpy"] = to_array(r.rpy);
  d["sigma"] = to_array(r.sigma);
  d["imu_err"] = to_array(r.imu_err);
  return d;
}

/// A record's fate (NavigatorRecord): status, NIS and the INS - GNSS innovation (6, NaN: absent).
inline py::dict record_dict(const NavigatorRecord& r) {
  py::dict d;
  d["status"] = static_cast<int>(r.status);
  d["nis"] = r.nis;
  d["innovation"] = to_array(r.innovation);
  return d;
}

/// The family-independent implementation over a navigator `Nav` (LooseNavigator,
/// TightNavigator, DelayNavigator) of the interface `Iface` (derived from PushNavigator).
template <class Nav, class Iface>
struct PushImpl : Iface {
  using Cov = std::decay_t<decltype(std::declval<Nav&>().covariance())>;
  static constexpr int kN = Cov::RowsAtCompileTime;
  Nav nav;

  template <class Config>
  PushImpl(const Config& cfg, const NavState& s0, const Cov& P0, const ImuCorrection& c0)
      : nav(cfg, s0, P0, c0) {}

  bool push_imu(double t, const Vec3& dth, const Vec3& dv) override { return nav.push_imu(t, dth, dv); }
  std::int64_t push_imu_array(const double* t, const double* dth, const double* dv, std::int64_t n) override {
    std::int64_t taken = 0;
    for (std::int64_t k = 0; k < n; ++k)
      taken += nav.push_imu(t[k], Vec3(dth[3 * k], dth[3 * k + 1], dth[3 * k + 2]),
                            Vec3(dv[3 * k], dv[3 * k + 1], dv[3 * k + 2]));
    return taken;
  }
  void flush() override { nav.flush(); }
  DArray covariance() override {
    const Cov P = nav.covariance();
    DArray out(std::vector<py::ssize_t>{kN, kN});
    Eigen::Map<Eigen::Matrix<double, kN, kN, Eigen::RowMajor>>(out.mutable_data()) = P;
    return out;
  }
  /// The counters every family has (a family's counters() adds its own).
  py::dict base_counters() {
    py::dict d;
    d["samples"] = nav.samples();
    d["held_samples"] = nav.held_samples();
    d["pending_records"] = nav.pending_records();
    d["t_integrated"] = nav.t_integrated();
    d["updates"] = nav.updates();
    d["rejected"] = nav.rejected();
    d["gate_reopened"] = nav.gate_reopened();
    d["refused_records"] = nav.refused_records();
    return d;
  }
};

/// The family-independent methods of a binder's class (the GIL released around flush
/// and the array push, the calls that can take long).
template <class Iface>
void def_push_api(py::class_<Iface>& c) {
  c.def("push_imu",
        [](Iface& n, double t, const DArray& dth, const DArray& dv) {
          return n.push_imu(t, vec3_from(dth, "dtheta_b"), vec3_from(dv, "dv_b"));
        },
        py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"))
      .def("push_imu_array",
           [](Iface& n, const DArray& t, const DArray& dth, const DArray& dv) {
             const ImuArrays a = imu_arrays(t, dth, dv);
             py::gil_scoped_release release;
             return n.push_imu_array(a.t, a.dtheta_b, a.dv_b, a.n);
           },
           py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"))
      .def("flush",
           [](Iface& n) {
             py::gil_scoped_release release;
             n.flush();
           })
      .def("solution", &Iface::solution)
      .def("covariance", &Iface::covariance)
      .def("counters", &Iface::counters);
}

/// The IMU hold of a navigator's constructor (PushLoop's kMaxHold = 256 of the binders).
inline int imu_hold_from(int imu_hold) {
  if (imu_hold < 0 || imu_hold > 256) throw py::value_error("imu_hold must be in 0 .. 256 samples");
  return imu_hold;
}

}  // namespace insnav::py_bind
