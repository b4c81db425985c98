// _core.TightNavigator: the tightly coupled real-time push API
// (engine/navigator.hpp TightNavigator) for Python (insnav.TightNavigator,
// python/insnav/filters/navigator.py).  The family-independent part is
// push_binding.hpp; this adds the pseudorange epochs and the receiver clock.
#include <algorithm>
#include <array>
#include <memory>
#include <string>

#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "push_binding.hpp"

namespace insnav::py_bind {

void bind_tight_navigator(py::module_& m);

namespace {

/// The tight family's calls: one epoch of pseudoranges / pseudorange rates.
struct TightNavigatorBase : PushNavigator {
  virtual RecordStatus push_pseudoranges(double t, const SatObservation* sats, int n) = 0;
  virtual py::dict last_epoch() = 0;
};

template <class Filter>
struct TightNavigatorImpl final : PushImpl<TightNavigator<Filter>, TightNavigatorBase> {
  using PushImpl<TightNavigator<Filter>, TightNavigatorBase>::PushImpl;
  using L = typename Filter::Layout;

  RecordStatus push_pseudoranges(double t, const SatObservation* sats, int n) override {
    return this->nav.push_pseudoranges(t, sats, n);
  }
  py::dict solution() override {
    const NavigatorRow<L> r = this->nav.solution();
    py::dict d = row_dict(r);
    d["clock"] = to_array(r.clock);
    if constexpr (kHasIsb<L>) d["isb"] = to_array(r.isb);
    return d;
  }
  py::dict counters() override {
    py::dict d = this->base_counters();
    d["rejected_sats"] = this->nav.rejected_sats();
    return d;
  }
  py::dict last_epoch() override {
    py::dict d;
    d["status"] = static_cast<int>(this->nav.last_status());
    d["nis"] = this->nav.last_nis();
    return d;
  }
};

template <class Filter>
std::unique_ptr<TightNavigatorBase> make(const TightNavigatorConfig& cfg, const NavState& s0, const DArray& P0,
                                         const ImuCorrection& c0) {
  return std::make_unique<TightNavigatorImpl<Filter>>(cfg, s0, state_cov_from<typename Filter::Layout>(P0), c0);
}

/// The filter/layout dispatch (the batch binder's combinations: bind_tight.cpp, bind_tight_multi.cpp).
std::unique_ptr<TightNavigatorBase> make_tight_navigator(const std::string& filter, int layout,
                                                         const TightNavigatorConfig& cfg, const NavState& s0,
                                                         const DArray& P0, const ImuCorrection& c0) {
  if (layout == 17) {
    if (filter == "ekf") return make<Ekf<Layout17>>(cfg, s0, P0, c0);
    if (filter == "rbukf") return make<RbUkf<Layout17>>(cfg, s0, P0, c0);
    if (filter == "ukf") return make<Ukf<Layout17>>(cfg, s0, P0, c0);
  } else if (layout == 20) {
    if (filter == "ekf") return make<Ekf<LayoutTightMulti>>(cfg, s0, P0, c0);
    if (filter == "rbukf") return make<RbUkf<LayoutTightMulti>>(cfg, s0, P0, c0);
    if (filter == "ukf") return make<Ukf<LayoutTightMulti>>(cfg, s0, P0, c0);
  }
  throw py::value_error("TightNavigator: unsupported filter/layout combination " + filter + "/" +
                        std::to_string(layout) + " (ekf, rbukf, ukf with 17 or 20)");
}

}  // namespace

void bind_tight_navigator(py::module_& m) {
  py::class_<TightNavigatorBase> c(m, "TightNavigator",
                                   "Real-time tightly coupled navigator (engine/navigator.hpp); use insnav.TightNavigator.");
  c.def(py::init([](const std::string& filter, int layout, const DArray& init, const DArray& P0, const DArray& corr0,
                    const DArray& clock0, const py::object& isb0, const py::dict& model, const py::dict& config,
                    int imu_hold) {
          TightNavigatorConfig cfg;
          cfg.imu_model = imu_model_from_dict(model);
          cfg.tight = tight_config_from(config);
          if (cfg.tight.pr_gm.enabled())
            throw py::value_error("pr_gm_sigma_m: the Gauss-Markov pseudorange states run in the batch tight run only");
          cfg.ut = ut_from(config);
          cfg.imu_hold = imu_hold_from(imu_hold);
          cfg.clock_bias0_m = clock0_bias(clock0);
          cfg.clock_drift0_mps = clock0.data()[1];
          if (!isb0.is_none()) {
            const DArray b = py::cast<DArray>(isb0);
            if (b.size() != 3) throw py::value_error("isb0: expected 3 values (R, E, C) [m]");
            cfg.isb0 = IsbVec(b.data()[0], b.data()[1], b.data()[2]);
          }
          return make_tight_navigator(filter, layout, cfg, nav_state_from(init), P0, imu_correction_from(corr0));
        }),
        py::arg("filter"), py::arg("layout"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
        py::arg("clock0"), py::arg("isb0"), py::arg("imu_model"), py::arg("config"), py::arg("imu_hold") = 0);
  def_push_api(c);
  c.def("push_pseudoranges",
        [](TightNavigatorBase& n, double t, const DArray& sats, const I64Array& system, const I64Array& prn) {
          const py::ssize_t k = sats.ndim() == 2 ? sats.shape(0) : 0;
          if (k > 0) require_shape(sats, k, 12, "sats");
          if (system.ndim() != 1 || system.shape(0) != k || prn.ndim() != 1 || prn.shape(0) != k)
            throw py::value_error("push_pseudoranges: system and prn need one value per satellite row");
          std::array<SatObservation, kMaxMeasRows> obs;
          const int used = static_cast<int>(std::min<py::ssize_t>(k, kMaxMeasRows));
          for (int i = 0; i < used; ++i)
            obs[i] = sat_observation_from(sats.data() + 12 * i, system.data()[i], prn.data()[i], i);
          return static_cast<int>(n.push_pseudoranges(t, obs.data(), used));
        },
        py::arg("t"), py::arg("sats"), py::arg("system"), py::arg("prn"))
      .def("last_epoch", &TightNavigatorBase::last_epoch);
}

}  // namespace insnav::py_bind
