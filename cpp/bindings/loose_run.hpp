// The loosely coupled run behind _core.run_loose, shared by bind_loose*.cpp.
// The engines are instantiated in one translation unit per layout
// (bind_loose_l15.cpp, bind_loose_l21.cpp: ekf, rbukf and ukf each), so that a
// parallel build compiles them side by side; bind_loose.cpp parses the
// arguments and dispatches.  (Per layout rather than per filter: RB-UKF and UKF
// share UnscentedPropagation<L>, and all three share the layout's error models
// and measurement, which a per-filter split would compile three times.)
#pragma once

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/engine/loose_engine.hpp"

namespace insnav::py_bind {

/// The arguments of _core.run_loose, the dicts already parsed.
struct LooseRunArgs {
  const DArray& t;
  const DArray& dtheta_b;
  const DArray& dv_b;
  const DArray& gnss;
  const DArray& init;
  const DArray& P0;
  const DArray& corr0;
  ImuErrorModel model;
  LooseConfig cfg;
  UtParams ut;
  int sigma_columns = 0;  // config key 'sigma_columns': sigmas of the first k states only (<= 0: all)
};

/// filter 'ekf', 'rbukf' or 'ukf' on one layout (any other filter: ValueError).
py::dict run_loose_l15(const std::string& filter, const LooseRunArgs& a);  // bind_loose_l15.cpp
py::dict run_loose_l21(const std::string& filter, const LooseRunArgs& a);  // bind_loose_l21.cpp

[[noreturn]] inline void unsupported_loose(const std::string& filter, int layout) {
  throw py::value_error("unsupported filter/layout combination: " + filter + "/" + std::to_string(layout));
}

/// Validate, run the engine with the GIL released, return the output dict.
template <class Filter>
py::dict run_loose_impl(const LooseRunArgs& a) {
  using L = typename Filter::Layout;
  constexpr int ns = L::kSize;
  const LooseConfig& cfg = a.cfg;
  const py::ssize_t n = a.t.size();
  require_shape(a.t, n, -1, "t");
  require_shape(a.dtheta_b, n, 3, "dtheta_b");
  require_shape(a.dv_b, n, 3, "dv_b");
  const py::ssize_t m = a.gnss.ndim() == 2 ? a.gnss.shape(0) : 0;
  if (m > 0) require_shape(a.gnss, m, 13, "gnss");
  if (a.init.size() != 10)
    throw py::value_error("init: expected 10 values (t0, lat, lon, h, vN, vE, vD, roll, pitch, yaw)");
  require_shape(a.P0, ns, ns, "P0");
  if (a.corr0.size() != 12) throw py::value_error("imu_correction: expected 12 values");

  const double* pi = a.init.data();
  NavState nav;
  nav.t = pi[0];
  nav.lat = pi[1];
  nav.lon = pi[2];
  nav.h = pi[3];
  nav.v_n = Vec3(pi[4], pi[5], pi[6]);
  nav.q_nb = quat_from_euler(Vec3(pi[7], pi[8], pi[9]));
  StateCov<L> P = Eigen::Map<const Eigen::Matrix<double, ns, ns, Eigen::RowMajor>>(a.P0.data());
  ImuCorrection corr;
  const double* pc = a.corr0.data();
  corr.acc_bias = Vec3(pc[0], pc[1], pc[2]);
  corr.gyro_bias = Vec3(pc[3], pc[4], pc[5]);
  corr.acc_scale = Vec3(pc[6], pc[7], pc[8]);
  corr.gyro_scale = Vec3(pc[9], pc[10], pc[11]);

  // GNSS rows: t, lat, lon, h, vN, vE, vD, sN, sE, sD, svN, svE, svD (NaN velocity: position only)
  std::vector<GnssFix> fixes(static_cast<size_t>(m));
  const double* pg = a.gnss.data();
  for (py::ssize_t i = 0; i < m; ++i) {
    const double* r = pg + 13 * i;
    GnssFix& f = fixes[i];
    f.t = r[0];
    f.lat = r[1];
    f.lon = r[2];
    f.h = r[3];
    f.v_n = Vec3(r[4], r[5], r[6]);
    f.sigma_pos_n = Vec3(r[7], r[8], r[9]);
    f.sigma_vel_n = Vec3(r[10], r[11], r[12]);
    f.has_pos = std::isfinite(r[1]) && std::isfinite(r[2]) && std::isfinite(r[3]);
    f.has_vel = f.v_n.allFinite() && f.sigma_vel_n.allFinite();
  }

  const py::ssize_t n_out = (n + cfg.output_decimation - 1) / cfg.output_decimation + 1;
  const int n_sig = (a.sigma_columns > 0 && a.sigma_columns < ns) ? a.sigma_columns : ns;
  DArray o_t({n_out}), o_llh({n_out, py::ssize_t(3)}), o_v({n_out, py::ssize_t(3)}),
      o_rpy({n_out, py::ssize_t(3)}), o_sig({n_out, py::ssize_t(n_sig)}), o_err({n_out, py::ssize_t(12)});
  DArray o_innov({m, py::ssize_t(6)}), o_nis({m});
  py::array_t<std::int8_t> o_status({m});
  LooseOutputs out;
  out.t = o_t.mutable_data();
  out.llh = o_llh.mutable_data();
  out.v_n = o_v.mutable_data();
  out.rpy = o_rpy.mutable_data();
  out.sigma = o_sig.mutable_data();
  out.sigma_cols = n_sig;
  out.imu_err = o_err.mutable_data();
  out.innovation = m ? o_innov.mutable_data() : nullptr;
  out.nis = m ? o_nis.mutable_data() : nullptr;
  out.status = m ? o_status.mutable_data() : nullptr;
  {
    py::gil_scoped_release release;
    auto engine = std::make_unique<LooseEngine<Filter>>(a.model, cfg, a.ut);  // one allocation per run, not per sample
    engine->run(nav, P, corr, n, a.t.data(), a.dtheta_b.data(), a.dv_b.data(), m, fixes.data(), out);
  }
  const py::ssize_t k = out.n_out;
  py::dict res;
  res["t"] = o_t[py::slice(0, k, 1)];
  res["llh"] = o_llh[py::slice(0, k, 1)];
  res["v_n"] = o_v[py::slice(0, k, 1)];
  res["rpy"] = o_rpy[py::slice(0, k, 1)];
  res["sigma"] = o_sig[py::slice(0, k, 1)];
  res["imu_err"] = o_err[py::slice(0, k, 1)];
  res["innovation"] = o_innov;
  res["nis"] = o_nis;
  res["status"] = o_status;
  res["updates"] = out.updates;
  res["rejected"] = out.rejected;
  res["cholesky_repairs"] = out.cholesky_repairs;
  return res;
}

}  // namespace insnav::py_bind
