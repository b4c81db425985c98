// _core.LooseNavigator: the real-time push API (engine/navigator.hpp) for
// Python (insnav.Navigator, python/insnav/filters/navigator.py).  One object
// per filter/layout behind a small virtual interface (push_binding.hpp: the
// part every family shares); each push is one C++ call.
#include <memory>
#include <string>

#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "loose_run.hpp"
#include "push_binding.hpp"

namespace insnav::py_bind {

void bind_tight_navigator(py::module_& m);  // bind_tight_navigator.cpp (registered with this one)
void bind_delay_navigator(py::module_& m);  // bind_delay_navigator.cpp (registered with this one)

namespace {

/// The loose family's calls: GNSS fixes and vehicle-constraint events.
struct NavigatorBase : PushNavigator {
  virtual RecordStatus push_fix(const GnssFix& f) = 0;
  virtual RecordStatus push_constraint(const ConstraintEvent& e) = 0;
  virtual py::dict last_fix() = 0;
};

template <class Filter>
struct NavigatorImpl final : PushImpl<LooseNavigator<Filter>, NavigatorBase> {
  using PushImpl<LooseNavigator<Filter>, NavigatorBase>::PushImpl;
  using L = typename Filter::Layout;

  RecordStatus push_fix(const GnssFix& f) override { return this->nav.push_gnss_fix(f); }
  RecordStatus push_constraint(const ConstraintEvent& e) override { return this->nav.push_constraint(e); }

  py::dict solution() override {
    const NavigatorRow<L> r = this->nav.solution();
    py::dict d = row_dict(r);
    if constexpr (kHasOdoScale<L>) d["odo_scale"] = to_array(r.odo_scale);
    return d;
  }
  py::dict counters() override {
    py::dict d = this->base_counters();
    d["constraint_updates"] = this->nav.constraint_updates();
    return d;
  }
  py::dict last_fix() override { return record_dict(this->nav.last_fix()); }
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
  py::class_<NavigatorBase> c(m, "LooseNavigator",
                              "Real-time loosely coupled navigator (engine/navigator.hpp); use insnav.Navigator.");
  c.def(py::init([](const std::string& filter, int layout, const DArray& init, const DArray& P0, const DArray& corr0,
                    const py::dict& model, const py::dict& config, int imu_hold) {
          NavigatorConfig cfg;
          cfg.imu_model = imu_model_from_dict(model);
          cfg.loose = loose_run_config_from(config);
          if (selfcal_from(config).any())
            throw py::value_error("LooseNavigator: estimate_time_offset / estimate_lever_arm unsupported "
                                  "(the self-calibration states run in the batch engines, insnav.run)");
          cfg.ut = ut_from(config);
          cfg.imu_hold = imu_hold_from(imu_hold);
          return make_navigator(filter, layout, cfg, nav_state_from(init), P0, imu_correction_from(corr0));
        }),
        py::arg("filter"), py::arg("layout"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
        py::arg("imu_model"), py::arg("config"), py::arg("imu_hold") = 0);
  def_push_api(c);
  c.def("push_gnss_fix",
        [](NavigatorBase& n, const DArray& row) {
          if (row.size() != 13) throw py::value_error("gnss fix: expected 13 values (t, lat, lon, h, v_n, sigmas)");
          GnssFix f = gnss_fix_from(row.data()[0], row.data() + 1);
          f.has_vel = f.v_n.allFinite();  // checked by push_gnss_fix: a finite velocity needs its sigmas
          return static_cast<int>(n.push_fix(f));
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
      .def("last_fix", &NavigatorBase::last_fix);
  bind_tight_navigator(m);
  bind_delay_navigator(m);
}

}  // namespace insnav::py_bind
