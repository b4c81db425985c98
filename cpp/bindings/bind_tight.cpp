// Tightly coupled run (seed 003): the whole IMU loop in C++ with the GIL
// released; all epochs' satellite data handed over in one call as flat arrays
// (convert.hpp: tight_inputs_from).  layout 17: one receiver clock (GPS, or
// any data whose inter-system biases were removed); layout 20
// (LayoutTightMulti): + the inter-system biases of R, E, C (bind_tight_multi.cpp).
#include <string>

#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "tight_run.hpp"

namespace insnav::py_bind {

void bind_tight(py::module_& m) {
  m.def(
      "run_tight",
      [](const std::string& filter, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& epoch_t, const I64Array& epoch_start, const DArray& sats, const DArray& init, const DArray& P0,
         const DArray& corr0, const DArray& clock0, const py::dict& model, const py::dict& config, int layout,
         const py::object& system, const py::object& isb0, const py::object& prn) {
        TightArgs a;
        a.model = imu_model_from_dict(model);
        a.cfg = tight_config_from(config);
        a.ut = ut_from(config);
        a.smooth = flag(config, "smooth", false);
        a.imu = imu_arrays(t, dtheta_b, dv_b);
        a.in = tight_inputs_from(epoch_t, epoch_start, sats, system, prn);
        a.nav = nav_state_from(init);
        a.P0 = P0;
        a.corr = imu_correction_from(corr0);
        a.clock_bias0 = clock0_bias(clock0);
        a.clock_drift0 = clock0.data()[1];
        if (!isb0.is_none()) {
          const DArray b = py::cast<DArray>(isb0);
          if (b.size() != 3) throw py::value_error("isb0: expected 3 values (R, E, C) [m]");
          a.isb0 = IsbVec(b.data()[0], b.data()[1], b.data()[2]);
        }
        const SelfCal sc = selfcal_from(config);
        a.time_offset0_s = sc.time_offset0_s;
        if (sc.any()) {  // self-calibration layouts (layout.hpp): on the 17 states, EKF (bind_tight_selfcal.cpp)
          if (layout != 17)
            throw py::value_error("estimate_time_offset / estimate_lever_arm: layout " + std::to_string(layout) +
                                  " unsupported (the self-calibration states extend the 17-state layout: "
                                  "one constellation)");
          if (sc.odo_lever_arm) throw py::value_error("estimate_odo_lever_arm: loose coupling only");
          return run_tight_selfcal(filter, a, sc.time_offset, sc.lever_arm);
        }
        if (layout == 20) return run_tight_multi(filter, a);
        if (layout != 17) throw py::value_error("run_tight: layout must be 17 or 20 (with inter-system biases)");
        if (filter == "ekf") return run_tight_impl<Ekf<Layout17>>(a);
        if (filter == "rbukf") return run_tight_impl<RbUkf<Layout17>>(a);
        if (filter == "ukf") return run_tight_impl<Ukf<Layout17>>(a);
        throw py::value_error("unsupported tight filter: " + filter + " (ekf, rbukf, ukf)");
      },
      py::arg("filter"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("epoch_t"),
      py::arg("epoch_start"), py::arg("sats"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
      py::arg("clock0"), py::arg("imu_model"), py::arg("config"), py::arg("layout") = 17,
      py::arg("system") = py::none(), py::arg("isb0") = py::none(), py::arg("prn") = py::none(),
      "Closed-loop tightly coupled run, Layout17 or (layout=20) LayoutTightMulti with inter-system biases "
      "(SI units; see python/insnav/filters/tight.py).");
}

}  // namespace insnav::py_bind
