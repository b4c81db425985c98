// Tightly coupled run (seed 003): the whole IMU loop in C++ with the GIL
// released; all epochs' satellite data handed over in one call as flat arrays
// (convert.hpp: tight_inputs_from).
#include <memory>
#include <string>

#include "common.hpp"
#include "convert.hpp"
#include "insnav/engine/tight_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "outputs.hpp"

namespace insnav::py_bind {

namespace {

template <class Filter>
py::dict run_tight_impl(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, const DArray& epoch_t,
                        const I64Array& epoch_start, const DArray& sats, const DArray& init, const DArray& P0,
                        const DArray& corr0, const DArray& clock0, const ImuErrorModel& model, const TightConfig& cfg,
                        const UtParams& ut) {
  using L = typename Filter::Layout;
  const ImuArrays imu = imu_arrays(t, dtheta_b, dv_b);
  const TightInputs in = tight_inputs_from(epoch_t, epoch_start, sats);
  const NavState nav = nav_state_from(init);
  const StateCov<L> P = state_cov_from<L>(P0);
  const ImuCorrection corr = imu_correction_from(corr0);
  const double clock_bias0 = clock0_bias(clock0), clock_drift0 = clock0.data()[1];

  NavBuffers nav_buf(output_rows(imu.n, cfg.output_decimation), L::kSize, true);
  TightRecordBuffers rec_buf(in.E, in.M);
  TightOutputs out;
  nav_buf.attach(out);
  rec_buf.attach(out);
  {
    py::gil_scoped_release release;
    auto engine = std::make_unique<TightEngine<Filter>>(model, cfg, ut);  // one allocation per run
    engine->run(nav, P, corr, clock_bias0, clock_drift0, imu.n, imu.t, imu.dtheta_b, imu.dv_b, in.E,
                in.epochs.data(), in.sats.data(), out);
  }
  py::dict res;
  nav_buf.put(res, out);
  rec_buf.put(res);
  return res;
}

}  // namespace

void bind_tight(py::module_& m) {
  m.def(
      "run_tight",
      [](const std::string& filter, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& epoch_t, const I64Array& epoch_start, const DArray& sats, const DArray& init, const DArray& P0,
         const DArray& corr0, const DArray& clock0, const py::dict& model, const py::dict& config) {
        const ImuErrorModel mdl = imu_model_from_dict(model);
        const TightConfig cfg = tight_config_from(config);
        const UtParams ut = ut_from(config);
        if (filter == "ekf")
          return run_tight_impl<Ekf<Layout17>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0,
                                               clock0, mdl, cfg, ut);
        if (filter == "rbukf")
          return run_tight_impl<RbUkf<Layout17>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0,
                                                 clock0, mdl, cfg, ut);
        if (filter == "ukf")
          return run_tight_impl<Ukf<Layout17>>(t, dtheta_b, dv_b, epoch_t, epoch_start, sats, init, P0, corr0,
                                               clock0, mdl, cfg, ut);
        throw py::value_error("unsupported tight filter: " + filter + " (ekf, rbukf, ukf)");
      },
      py::arg("filter"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("epoch_t"),
      py::arg("epoch_start"), py::arg("sats"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
      py::arg("clock0"), py::arg("imu_model"), py::arg("config"),
      "Closed-loop tightly coupled run, Layout17 (SI units; see python/insnav/filters/tight.py).");
}

}  // namespace insnav::py_bind
