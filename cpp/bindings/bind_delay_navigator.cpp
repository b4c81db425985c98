// _core.DelayNavigator: seed 001's random-delay KF as a real-time push API
// (engine/navigator.hpp DelayNavigator) for Python (insnav.DelayNavigator,
// python/insnav/filters/navigator.py).  The family-independent part is
// push_binding.hpp; this adds the receiver epochs with the records that
// arrived by them.
#include <algorithm>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "push_binding.hpp"

namespace insnav::py_bind {

void bind_delay_navigator(py::module_& m);
void delay_configs_from_dict(const py::dict& d, LooseConfig& c, DelayConfig& dc);  // bind_delay.cpp
std::vector<double> delay_p_from(const DArray& delay_p);                            // bind_delay.cpp

namespace {

/// The delay family's calls: one receiver epoch with its arrived records.
struct DelayNavigatorBase : PushNavigator {
  virtual RecordStatus push_epoch(double t, const GnssFix* records, int n) = 0;
  virtual int max_records_per_epoch() const = 0;
  virtual py::dict last_record() = 0;
};

template <int S>
struct DelayNavigatorImpl final : PushImpl<DelayNavigator<Layout15, S>, DelayNavigatorBase> {
  using PushImpl<DelayNavigator<Layout15, S>, DelayNavigatorBase>::PushImpl;

  RecordStatus push_epoch(double t, const GnssFix* records, int n) override {
    return this->nav.push_epoch(t, records, n);
  }
  int max_records_per_epoch() const override { return DelayNavigator<Layout15, S>::kMaxRecordsPerEpoch; }
  py::dict solution() override { return row_dict(this->nav.solution()); }
  py::dict counters() override {
    py::dict d = this->base_counters();
    d["dropped_records"] = this->nav.dropped_records();
    return d;
  }
  py::dict last_record() override { return record_dict(this->nav.last_record()); }
};

/// The maximum delay S = len(p) - 1 (at least 1): the batch binder's instantiations (bind_delay.cpp).
std::unique_ptr<DelayNavigatorBase> make_delay_navigator(int layout, const DelayNavigatorConfig& cfg,
                                                         const NavState& s0, const DArray& P0,
                                                         const ImuCorrection& c0) {
  if (layout != 15) throw py::value_error("DelayNavigator: rdkf runs the 15-state layout only");
  const StateCov<Layout15> P = state_cov_from<Layout15>(P0);
  switch (std::max(1, cfg.n_delay_p - 1)) {
    case 1: return std::make_unique<DelayNavigatorImpl<1>>(cfg, s0, P, c0);
    case 2: return std::make_unique<DelayNavigatorImpl<2>>(cfg, s0, P, c0);
    case 3: return std::make_unique<DelayNavigatorImpl<3>>(cfg, s0, P, c0);
    case 4: return std::make_unique<DelayNavigatorImpl<4>>(cfg, s0, P, c0);
    default:
      throw py::value_error("DelayNavigator: maximum delay s = " + std::to_string(cfg.n_delay_p - 1) +
                            " epochs is not instantiated (1..4)");
  }
}

}  // namespace

void bind_delay_navigator(py::module_& m) {
  py::class_<DelayNavigatorBase> c(
      m, "DelayNavigator", "Real-time random-delay KF navigator (engine/navigator.hpp); use insnav.DelayNavigator.");
  c.def(py::init([](int layout, const DArray& init, const DArray& P0, const DArray& corr0, const py::dict& model,
                    const py::dict& config, const DArray& delay_p, int imu_hold) {
          DelayNavigatorConfig cfg;
          cfg.imu_model = imu_model_from_dict(model);
          delay_configs_from_dict(config, cfg.loose, cfg.delay);
          cfg.imu_hold = imu_hold_from(imu_hold);
          const std::vector<double> p = delay_p_from(delay_p);
          if (p.size() > cfg.delay_p.size()) throw py::value_error("delay_p: at most 5 probabilities (s <= 4)");
          for (size_t i = 0; i < p.size(); ++i) cfg.delay_p[i] = p[i];
          cfg.n_delay_p = static_cast<int>(p.size());
          return make_delay_navigator(layout, cfg, nav_state_from(init), P0, imu_correction_from(corr0));
        }),
        py::arg("layout"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"), py::arg("imu_model"),
        py::arg("config"), py::arg("delay_p"), py::arg("imu_hold") = 0);
  def_push_api(c);
  c.def("push_epoch",
        [](DelayNavigatorBase& n, double t, const DArray& rows) {
          // rows: (k, 14) as the batch run_delay's: t_valid, t_arrival, then the loose fix row
          const py::ssize_t k = rows.ndim() == 2 ? rows.shape(0) : 0;
          if (k > 0) require_shape(rows, k, 14, "records");
          if (k > n.max_records_per_epoch())
            throw py::value_error("push_epoch: " + std::to_string(k) + " records at one epoch, at most " +
                                  std::to_string(n.max_records_per_epoch()));
          std::array<GnssFix, 16> fixes;
          for (py::ssize_t i = 0; i < k; ++i) {  // checked by push_epoch (a finite velocity needs its sigmas)
            fixes[i] = gnss_fix_from(rows.data()[14 * i], rows.data() + 14 * i + 2);
            fixes[i].has_vel = fixes[i].v_n.allFinite();
          }
          return static_cast<int>(n.push_epoch(t, fixes.data(), static_cast<int>(k)));
        },
        py::arg("t"), py::arg("records"))
      .def("last_record", &DelayNavigatorBase::last_record);
}

}  // namespace insnav::py_bind
