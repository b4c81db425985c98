// _core.TightNavigator: the tightly coupled real-time push API
// (engine/navigator.hpp TightNavigator) for Python (insnav.TightNavigator,
// python/insnav/filters/navigator.py).  As bind_navigator.cpp: one object per
// filter/layout behind a small virtual interface, one C++ call per push.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "convert.hpp"
#include "insnav/engine/navigator.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"

namespace insnav::py_bind {

void bind_tight_navigator(py::module_& m);

namespace {

struct TightNavigatorBase {
  virtual ~TightNavigatorBase() = default;
  virtual bool push_imu(double t, const Vec3& dth, const Vec3& dv) = 0;
  virtual std::int64_t push_imu_array(const double* t, const double* dth, const double* dv, std::int64_t n) = 0;
  virtual RecordStatus push_pseudoranges(double t, const SatObservation* sats, int n) = 0;
  virtual void flush() = 0;
  virtual py::dict solution() = 0;
  virtual DArray covariance() = 0;
  virtual py::dict counters() = 0;
  virtual py::dict last_epoch() = 0;
};

template <class V>
DArray to_array(const V& v) {
  DArray a({static_cast<py::ssize_t>(v.size())});
  for (py::ssize_t j = 0; j < a.size(); ++j) a.mutable_data()[j] = v[j];
  return a;
}

template <class Filter>
struct TightNavigatorImpl final : TightNavigatorBase {
  using L = typename Filter::Layout;
  TightNavigator<Filter> nav;

  TightNavigatorImpl(const TightNavigatorConfig& cfg, const NavState& s0, const StateCov<L>& P0,
                     const ImuCorrection& c0)
      : nav(cfg, s0, P0, c0) {}

  bool push_imu(double t, const Vec3& dth, const Vec3& dv) override { return nav.push_imu(t, dth, dv); }
  std::int64_t push_imu_array(const double* t, const double* dth, const double* dv, std::int64_t n) override {
    std::int64_t taken = 0;
    for (std::int64_t k = 0; k < n; ++k)
      taken += nav.push_imu(t[k], Vec3(dth[3 * k], dth[3 * k + 1], dth[3 * k + 2]),
                            Vec3(dv[3 * k], dv[3 * k + 1], dv[3 * k + 2]));
    return taken;
  }
  RecordStatus push_pseudoranges(double t, const SatObservation* sats, int n) override {
    return nav.push_pseudoranges(t, sats, n);
  }
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
    d["clock"] = to_array(r.clock);
    if constexpr (kHasIsb<L>) d["isb"] = to_array(r.isb);
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
    d["rejected_sats"] = nav.rejected_sats();
    d["gate_reopened"] = nav.gate_reopened();
    d["refused_records"] = nav.refused_records();
    return d;
  }
  py::dict last_epoch() override {
    py::dict d;
    d["status"] = static_cast<int>(nav.last_status());
    d["nis"] = nav.last_nis();
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
  py::class_<TightNavigatorBase>(m, "TightNavigator",
                                 "Real-time tightly coupled navigator (engine/navigator.hpp); use insnav.TightNavigator.")
      .def(py::init([](const std::string& filter, int layout, const DArray& init, const DArray& P0,
                       const DArray& corr0, const DArray& clock0, const py::object& isb0, const py::dict& model,
                       const py::dict& config, int imu_hold) {
             TightNavigatorConfig cfg;
             cfg.imu_model = imu_model_from_dict(model);
             cfg.tight = tight_config_from(config);
             cfg.ut = ut_from(config);
             if (imu_hold < 0 || imu_hold > 256) throw py::value_error("imu_hold must be in 0 .. 256 samples");
             cfg.imu_hold = imu_hold;
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
           py::arg("clock0"), py::arg("isb0"), py::arg("imu_model"), py::arg("config"), py::arg("imu_hold") = 0)
      .def("push_imu",
           [](TightNavigatorBase& n, double t, const DArray& dth, const DArray& dv) {
             return n.push_imu(t, vec3_from(dth, "dtheta_b"), vec3_from(dv, "dv_b"));
           },
           py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"))
      .def("push_imu_array",
           [](TightNavigatorBase& n, const DArray& t, const DArray& dth, const DArray& dv) {
             const ImuArrays a = imu_arrays(t, dth, dv);
             py::gil_scoped_release release;
             return n.push_imu_array(a.t, a.dtheta_b, a.dv_b, a.n);
           },
           py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"))
      .def("push_pseudoranges",
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
      .def("flush", [](TightNavigatorBase& n) {
        py::gil_scoped_release release;
        n.flush();
      })
      .def("solution", &TightNavigatorBase::solution)
      .def("covariance", &TightNavigatorBase::covariance)
      .def("counters", &TightNavigatorBase::counters)
      .def("last_epoch", &TightNavigatorBase::last_epoch);
}

}  // namespace insnav::py_bind
