// _core.LooseNavigator: the real-time push API (engine/navigator.hpp) for
// Python (insnav.Navigator, python/insnav/filters/navigator.py).  One object
// per filter/layout behind a small virtual interface; each push is one C++
// call (the GIL released only around work that can take long: flush and the
// array pushes).
#include <memory>
#include <string>
#include <vector>

#include "convert.hpp"
#include "insnav/engine/navigator.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "loose_run.hpp"

namespace insnav::py_bind {

void bind_tight_navigator(py::module_& m);  // bind_tight_navigator.cpp (registered with this one)

namespace {

/// The calls the binding needs, independent of the filter and layout.
struct NavigatorBase {
  virtual ~NavigatorBase() = default;
  virtual bool push_imu(double t, const Vec3& dth, const Vec3& dv) = 0;
  virtual std::int64_t push_imu_array(const double* t, const double* dth, const double* dv, std::int64_t n) = 0;
  virtual RecordStatus push_fix(const GnssFix& f) = 0;
  virtual RecordStatus push_constraint(const ConstraintEvent& e) = 0;
  virtual void flush() = 0;
  virtual py::dict solution() = 0;
  virtual DArray covariance() = 0;
  virtual py::dict counters() = 0;
  virtual py::dict last_fix() = 0;
};

template <class Filter>
struct NavigatorImpl final : NavigatorBase {
  using L = typename Filter::Layout;
  LooseNavigator<Filter> nav;

  NavigatorImpl(const NavigatorConfig& cfg, const NavState& s0, const StateCov<L>& P0, const ImuCorrection& c0)
      : nav(cfg, s0, P0, c0) {}

  bool push_imu(double t, const Vec3& dth, const Vec3& dv) override { return nav.push_imu(t, dth, dv); }
  std::int64_t push_imu_array(const double* t, const double* dth, const double* dv, std::int64_t n) override {
    std::int64_t taken = 0;
    for (std::int64_t k = 0; k < n; ++k)
      taken += nav.push_imu(t[k], Vec3(dth[3 * k], dth[3 * k + 1], dth[3 * k + 2]),
                            Vec3(dv[3 * k], dv[3 * k + 1], dv[3 * k + 2]));
    return taken;
  }
  RecordStatus push_fix(const GnssFix& f) override { return nav.push_gnss_fix(f); }
  RecordStatus push_constraint(const ConstraintEvent& e) override { return nav.push_constraint(e); }
  void flush() override { nav.flush(); }

  py::dict solution() override {
    const NavigatorRow<L> r = nav.solution();
    py::dict d;
    d["t"] = r.t;
    d["lat"] = r.llh[0];
    d["lon"] = r.llh[1];
    d["h"] = r.llh[2];
    d["v_n"] = to_array(r.v_n);
    d["rpy"] = to_array(r.rpy);
    d["sigma"] = to_array(r.sigma);
    d["imu_err"] = to_array(r.imu_err);
    if constexpr (kHasOdoScale<L>) d["odo_scale"] = to_array(r.odo_scale);
    return d;
  }
  DArray covariance() override {
    const StateCov<L>& P = nav.covariance();
    DArray out(std::vector<py::ssize_t>{L::kSize, L::kSize});
    Eigen::Map<Eigen::Matrix<double, L::kSize, L::kSize, Eigen::RowMajor>>(out.mutable_data()) = P;
    return out;
  }
  py::dict counters() override {
    py::dict d;
    d["samples"] = nav.samples();
    d["held_samples"] = nav.held_samples();
    d["pending_records"] = nav.pending_records();
    d["t_integrated"] = nav.t_integrated();
    d["updates"] = nav.updates();
    d["rejected"] = nav.rejected();
    d["gate_reopened"] = nav.gate_reopened();
    d["constraint_updates"] = nav.constraint_updates();
    d["refused_records"] = nav.refused_records();
    return d;
  }
  py::dict last_fix() override {
    const NavigatorRecord& r = nav.last_fix();
    py::dict d;
    d["status"] = static_cast<int>(r.status);
    d["nis"] = r.nis;
    DArray inn({6});
    for (int j = 0; j < 6; ++j) inn.mutable_data()[j] = r.innovation[j];
    d["innovation"] = inn;
    return d;
  }

  template <class V>
  static DArray to_array(const V& v) {
    DArray a({static_cast<py::ssize_t>(v.size())});
    for (py::ssize_t j = 0; j < a.size(); ++j) a.mutable_data()[j] = v[j];
    return a;
  }
};

template <class Filter>
std::unique_ptr<NavigatorBase> make(const NavigatorConfig& cfg, const NavState& s0, const DArray& P0,
                                    const ImuCorrection& c0) {
  return std::make_unique<NavigatorImpl<Filter>>(cfg, s0, state_cov_from<typename Filter::Layout>(P0), c0);
}

/// The filter/layout dispatch (the batch binder's combinations).
std::unique_ptr<NavigatorBase> make_navigator(const std::string& filter, int layout, const NavigatorConfig& cfg,
                                              const NavState& s0, const DArray& P0, const ImuCorrection& c0) {
  if (filter == "ekf") {
    if (layout == 15) return make<Ekf<Layout15>>(cfg, s0, P0, c0);
    if (layout == 16) return make<Ekf<Layout16Odo>>(cfg, s0, P0, c0);
    if (layout == 21) return make<Ekf<Layout21>>(cfg, s0, P0, c0);
  } else if (filter == "rbukf") {
    if (layout == 15) return make<RbUkf<Layout15>>(cfg, s0, P0, c0);
  } else if (filter == "ukf") {
    if (layout == 15) return make<Ukf<Layout15>>(cfg, s0, P0, c0);
  }
  throw py::value_error("LooseNavigator: unsupported filter/layout combination " + filter + "/" +
                        std::to_string(layout) + " (ekf 15/16/21, rbukf 15, ukf 15)");
}

}  // namespace

void bind_navigator(py::module_& m) {
  py::class_<NavigatorBase>(m, "LooseNavigator",
                            "Real-time loosely coupled navigator (engine/navigator.hpp); use insnav.Navigator.")
      .def(py::init([](const std::string& filter, int layout, const DArray& init, const DArray& P0,
                       const DArray& corr0, const py::dict& model, const py::dict& config, int imu_hold) {
             NavigatorConfig cfg;
             cfg.imu_model = imu_model_from_dict(model);
             cfg.loose = loose_run_config_from(config);
             if (selfcal_from(config).any())
               throw py::value_error("LooseNavigator: estimate_time_offset / estimate_lever_arm unsupported "
                                     "(the self-calibration states run in the batch engines, insnav.run)");
             cfg.ut = ut_from(config);
             if (imu_hold < 0 || imu_hold > 256) throw py::value_error("imu_hold must be in 0 .. 256 samples");
             cfg.imu_hold = imu_hold;
             return make_navigator(filter, layout, cfg, nav_state_from(init), P0, imu_correction_from(corr0));
           }),
           py::arg("filter"), py::arg("layout"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
           py::arg("imu_model"), py::arg("config"), py::arg("imu_hold") = 0)
      .def("push_imu",
           [](NavigatorBase& n, double t, const DArray& dth, const DArray& dv) {
             return n.push_imu(t, vec3_from(dth, "dtheta_b"), vec3_from(dv, "dv_b"));
           },
           py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"))
      .def("push_imu_array",
           [](NavigatorBase& n, const DArray& t, const DArray& dth, const DArray& dv) {
             const ImuArrays a = imu_arrays(t, dth, dv);
             py::gil_scoped_release release;
             return n.push_imu_array(a.t, a.dtheta_b, a.dv_b, a.n);
           },
           py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"))
      .def("push_gnss_fix",
           [](NavigatorBase& n, const DArray& row) {
             if (row.size() != 13) throw py::value_error("gnss fix: expected 13 values (t, lat, lon, h, v_n, sigmas)");
             return static_cast<int>(n.push_fix(gnss_fix_from(row.data()[0], row.data() + 1)));
           },
           py::arg("row"))
      .def("push_constraint",
           [](NavigatorBase& n, double t, int kinds, double speed_mps) {
             if (kinds < 0 || kinds > 15) throw py::value_error("constraint kinds must be flags 0..15");
             if ((kinds & kOdometer) && !std::isfinite(speed_mps))
               throw py::value_error("odometer event without a finite speed");
             return static_cast<int>(n.push_constraint(ConstraintEvent{t, static_cast<std::uint8_t>(kinds), speed_mps}));
           },
           py::arg("t"), py::arg("kinds"), py::arg("speed_mps") = NAN)
      .def("flush", [](NavigatorBase& n) {
        py::gil_scoped_release release;
        n.flush();
      })
      .def("solution", &NavigatorBase::solution)
      .def("covariance", &NavigatorBase::covariance)
      .def("counters", &NavigatorBase::counters)
      .def("last_fix", &NavigatorBase::last_fix);
  bind_tight_navigator(m);
}

}  // namespace insnav::py_bind
