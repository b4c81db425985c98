// _core.solve_spp_batch: single point positioning with RAIM FDE over all epochs
// (insnav/gnss/spp_solver.hpp) with the GIL released; python/insnav/gnss/spp.py
// allocates the output arrays (NaN / 0 / no-solution) and wraps them.
// _core.select_best_gdop / best_gdop_keep: the best-GDOP satellite subset of one
// epoch / of every epoch (insnav/gnss/gdop_selection.hpp).
// _core.select_nearest_record: the broadcast record of each (satellite, time)
// (insnav/gnss/ephemeris_selection.hpp).
// _core.scan_rinex_nav_body: the fields of a navigation file's records
// (insnav/io/rinex_nav.hpp; python/insnav/gnss/rinex.py builds the tables).
#include <algorithm>
#include <cstdint>
#include <string>

#include "common.hpp"
#include "insnav/gnss/broadcast_orbit.hpp"
#include "insnav/gnss/ephemeris_selection.hpp"
#include "insnav/gnss/gdop_selection.hpp"
#include "insnav/gnss/spp_solver.hpp"
#include "insnav/io/rinex_nav.hpp"

namespace insnav::py_bind {

namespace {

template <class T>
T* mutable_data(py::array& a, py::ssize_t size, const char* name) {
  if (!a.dtype().is(py::dtype::of<T>()) || !(a.flags() & py::array::c_style) || a.size() != size ||
      !a.writeable())
    throw py::value_error(std::string("solve_spp_batch: output '") + name + "' has the wrong dtype, layout or size");
  return static_cast<T*>(a.mutable_data());
}

void solve_spp_batch(const py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>& epoch_start,
                     const DArray& sats, const DArray& sigma_pr_m, const DArray& sigma_prr_mps,
                     const py::array_t<std::int8_t, py::array::c_style | py::array::forcecast>& system,
                     const DArray& r0_e, const py::dict& options, py::dict out) {
  if (epoch_start.ndim() != 1 || epoch_start.shape(0) < 1)
    throw py::value_error("solve_spp_batch: epoch_start must be 1-D with E+1 entries");
  const py::ssize_t E = epoch_start.shape(0) - 1;
  const py::ssize_t M = sats.ndim() == 2 ? sats.shape(0) : -1;
  require_shape(sats, M, gnss::SppRowLayout::kCols, "solve_spp_batch: sats");
  require_shape(sigma_pr_m, M, -1, "solve_spp_batch: sigma_pr_m");
  require_shape(sigma_prr_mps, M, -1, "solve_spp_batch: sigma_prr_mps");
  if (system.ndim() != 1 || system.shape(0) != M) throw py::value_error("solve_spp_batch: system must be (M,)");
  const std::int64_t* es = epoch_start.data();
  if (es[0] != 0 || es[E] != M) throw py::value_error("solve_spp_batch: epoch_start must run from 0 to M");
  for (py::ssize_t e = 0; e < E; ++e)
    if (es[e + 1] < es[e]) throw py::value_error("solve_spp_batch: epoch_start must not decrease");

  gnss::SppOptions opt;
  opt.raim = options["raim"].cast<bool>();
  opt.raim_alpha = options["raim_alpha"].cast<double>();
  opt.max_exclusions = options["max_exclusions"].cast<int>();
  opt.min_sats = options["min_sats"].cast<int>();
  opt.iterations = options["iterations"].cast<int>();
  opt.velocity = options["velocity"].cast<bool>();
  opt.warm_start = options["warm_start"].cast<bool>();

  gnss::SppBatchInput in;
  in.n_epochs = E;
  in.epoch_start = es;
  in.sats = sats.data();
  in.sigma_pr_m = sigma_pr_m.data();
  in.sigma_prr_mps = sigma_prr_mps.data();
  in.system = system.data();
  in.r0_e = vec3_from(r0_e, "solve_spp_batch: r0_e");

  auto arr = [&](const char* key) { return out[key].cast<py::array>(); };
  py::array a_r = arr("r_e"), a_b = arr("clock_bias_m"), a_v = arr("v_e"), a_d = arr("clock_drift_mps"),
            a_sp = arr("sigma_pos_n_m"), a_sv = arr("sigma_vel_n_mps"), a_isb = arr("isb_m"),
            a_sisb = arr("sigma_isb_m"), a_cr = arr("cov_r_e"), a_cv = arr("cov_v_e"), a_sc = arr("sigma_clock_m"),
            a_sd = arr("sigma_drift_mps"), a_g = arr("gdop"), a_p = arr("pdop"), a_h = arr("hdop"),
            a_vd = arr("vdop"), a_t = arr("tdop"), a_c2 = arr("chi2"), a_thr = arr("chi2_threshold"),
            a_ns = arr("n_sats"), a_nu = arr("n_used"), a_nx = arr("n_excluded"), a_nr = arr("n_rate_used"),
            a_nrx = arr("n_rate_excluded"), a_st = arr("raim_status"), a_ref = arr("ref_system"),
            a_rx = arr("row_excluded"), a_rrx = arr("rate_row_excluded");
  const py::ssize_t S = gnss::kSppNumSystems;
  gnss::SppBatchOutput o{};
  o.r_e = mutable_data<double>(a_r, 3 * E, "r_e");
  o.clock_bias_m = mutable_data<double>(a_b, E, "clock_bias_m");
  o.v_e = mutable_data<double>(a_v, 3 * E, "v_e");
  o.clock_drift_mps = mutable_data<double>(a_d, E, "clock_drift_mps");
  o.sigma_pos_n_m = mutable_data<double>(a_sp, 3 * E, "sigma_pos_n_m");
  o.sigma_vel_n_mps = mutable_data<double>(a_sv, 3 * E, "sigma_vel_n_mps");
  o.isb_m = mutable_data<double>(a_isb, S * E, "isb_m");
  o.sigma_isb_m = mutable_data<double>(a_sisb, S * E, "sigma_isb_m");
  o.cov_r_e = mutable_data<double>(a_cr, 9 * E, "cov_r_e");
  o.cov_v_e = mutable_data<double>(a_cv, 9 * E, "cov_v_e");
  o.sigma_clock_m = mutable_data<double>(a_sc, E, "sigma_clock_m");
  o.sigma_drift_mps = mutable_data<double>(a_sd, E, "sigma_drift_mps");
  o.gdop = mutable_data<double>(a_g, E, "gdop");
  o.pdop = mutable_data<double>(a_p, E, "pdop");
  o.hdop = mutable_data<double>(a_h, E, "hdop");
  o.vdop = mutable_data<double>(a_vd, E, "vdop");
  o.tdop = mutable_data<double>(a_t, E, "tdop");
  o.chi2 = mutable_data<double>(a_c2, E, "chi2");
  o.chi2_threshold = mutable_data<double>(a_thr, E, "chi2_threshold");
  o.n_sats = mutable_data<std::int64_t>(a_ns, E, "n_sats");
  o.n_used = mutable_data<std::int64_t>(a_nu, E, "n_used");
  o.n_excluded = mutable_data<std::int64_t>(a_nx, E, "n_excluded");
  o.n_rate_used = mutable_data<std::int64_t>(a_nr, E, "n_rate_used");
  o.n_rate_excluded = mutable_data<std::int64_t>(a_nrx, E, "n_rate_excluded");
  o.raim_status = mutable_data<std::int8_t>(a_st, E, "raim_status");
  o.ref_system = mutable_data<std::int8_t>(a_ref, E, "ref_system");
  o.row_excluded = mutable_data<std::uint8_t>(a_rx, M, "row_excluded");
  o.rate_row_excluded = mutable_data<std::uint8_t>(a_rrx, M, "rate_row_excluded");

  Status s;
  {
    py::gil_scoped_release release;
    s = gnss::solve_spp_batch(in, opt, o);
  }
  if (s != Status::kOk)
    throw py::value_error("solve_spp_batch: an epoch has more than " + std::to_string(gnss::kSppMaxRows) +
                          " rows or a system index outside 0.." + std::to_string(gnss::kSppNumSystems - 1));
}

using IArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

/// (k,) and (k, 3) output arrays of the transmit-state functions.
struct TransmitArrays {
  py::array_t<double> r, v, bias, drift, t_tx, tau, rng;
  explicit TransmitArrays(py::ssize_t k)
      : r({k, py::ssize_t(3)}), v({k, py::ssize_t(3)}), bias(k), drift(k), t_tx(k), tau(k), rng(k) {}
  gnss::TransmitOutput view() {
    return gnss::TransmitOutput{r.mutable_data(), v.mutable_data(), bias.mutable_data(), drift.mutable_data(),
                                t_tx.mutable_data(), tau.mutable_data(), rng.mutable_data()};
  }
  py::tuple result() { return py::make_tuple(r, v, bias, drift, t_tx, tau, rng); }
};

py::ssize_t check_rows(const DArray& table, int cols, const IArray& idx, const DArray& t_rx, const DArray& r_rx,
                       const char* name) {
  if (table.ndim() != 2 || table.shape(1) != cols)
    throw py::value_error(std::string(name) + ": element table must be (records, " + std::to_string(cols) + ")");
  if (idx.ndim() != 1) throw py::value_error(std::string(name) + ": idx must be 1-D");
  const py::ssize_t k = idx.shape(0);
  require_shape(t_rx, k, -1, (std::string(name) + ": t_rx").c_str());
  require_shape(r_rx, k, 3, (std::string(name) + ": r_rx").c_str());
  const std::int64_t* p = idx.data();
  for (py::ssize_t i = 0; i < k; ++i)
    if (p[i] < 0 || p[i] >= table.shape(0)) throw py::value_error(std::string(name) + ": idx out of range");
  return k;
}

py::tuple transmit_states_kepler(const DArray& elem, const IArray& idx, const DArray& t_rx, const DArray& r_rx,
                                 double gm, double omega_e, double f_rel, double omega_geo, double tol_s,
                                 int max_iter) {
  const py::ssize_t k = check_rows(elem, gnss::KeplerCols::kCols, idx, t_rx, r_rx, "transmit_states_kepler");
  TransmitArrays out(k);
  gnss::TransmitOutput o = out.view();
  const gnss::KeplerConstants c{gm, omega_e, f_rel, omega_geo};
  {
    py::gil_scoped_release release;
    gnss::transmit_states_kepler(elem.data(), idx.data(), k, t_rx.data(), r_rx.data(), 3, c, tol_s, max_iter, o);
  }
  return out.result();
}

py::tuple transmit_states_glonass(const DArray& glo, const IArray& idx, const DArray& t_rx, const DArray& r_rx,
                                  double gm, double j2_term, double omega_e, double step_s, double tol_s,
                                  int max_iter) {
  const py::ssize_t k = check_rows(glo, gnss::GlonassCols::kCols, idx, t_rx, r_rx, "transmit_states_glonass");
  if (!(step_s > 0.0)) throw py::value_error("transmit_states_glonass: step_s must be > 0");
  TransmitArrays out(k);
  gnss::TransmitOutput o = out.view();
  py::array_t<double> scratch(k);
  double* dt = scratch.mutable_data();
  const gnss::GlonassConstants c{gm, j2_term, omega_e};
  {
    py::gil_scoped_release release;
    gnss::transmit_states_glonass(glo.data(), idx.data(), k, t_rx.data(), r_rx.data(), 3, c, step_s, tol_s,
                                  max_iter, dt, o);
  }
  return out.result();
}

py::tuple select_best_gdop(const DArray& u, int n_select, std::int64_t max_combinations) {
  if (u.ndim() != 2 || u.shape(1) != 3) throw py::value_error("select_best_gdop: u must be (k, 3)");
  const py::ssize_t k = u.shape(0);
  if (n_select < 4) throw py::value_error("select_best_gdop: n_select must be >= 4 (3 position + clock)");
  if (k > gnss::kGdopMaxSats)
    throw py::value_error("select_best_gdop: more than " + std::to_string(gnss::kGdopMaxSats) + " satellites");
  int sel[gnss::kGdopMaxSats];
  double g = 0.0;
  int m = 0;
  {
    py::gil_scoped_release release;
    m = gnss::select_best_gdop(u.data(), static_cast<int>(k), n_select, max_combinations, sel, &g);
  }
  py::array_t<std::int64_t> idx(m);
  std::int64_t* p = idx.mutable_data();
  for (int j = 0; j < m; ++j) p[j] = sel[j];
  return py::make_tuple(idx, g);
}

py::array_t<bool> best_gdop_keep(const DArray& u, const IArray& epoch_start, int n_select,
                                 std::int64_t max_combinations) {
  if (u.ndim() != 2 || u.shape(1) != 3) throw py::value_error("best_gdop_keep: u must be (M, 3)");
  if (epoch_start.ndim() != 1 || epoch_start.shape(0) < 1)
    throw py::value_error("best_gdop_keep: epoch_start must be 1-D with E+1 entries");
  if (n_select < 4) throw py::value_error("best_gdop_keep: n_select must be >= 4 (3 position + clock)");
  const py::ssize_t M = u.shape(0), E = epoch_start.shape(0) - 1;
  const std::int64_t* es = epoch_start.data();
  if (es[0] != 0 || es[E] != M) throw py::value_error("best_gdop_keep: epoch_start must run from 0 to M");
  for (py::ssize_t e = 0; e < E; ++e)
    if (es[e + 1] < es[e]) throw py::value_error("best_gdop_keep: epoch_start must not decrease");
  py::array_t<bool> keep(M);
  bool* kp = keep.mutable_data();
  std::fill(kp, kp + M, true);
  Status s;
  {
    py::gil_scoped_release release;
    static_assert(sizeof(bool) == sizeof(std::uint8_t), "bool is one byte");
    s = gnss::select_best_gdop_batch(u.data(), es, E, n_select, max_combinations,
                                     reinterpret_cast<std::uint8_t*>(kp));
  }
  if (s != Status::kOk)
    throw py::value_error("best_gdop_keep: an epoch has more than " + std::to_string(gnss::kGdopMaxSats) +
                          " satellites");
  return keep;
}

using U8Array = py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>;

py::array_t<std::int64_t> select_nearest_record(const IArray& rec_prn, const U8Array& rec_ok, const DArray& rec_t,
                                                const DArray& rec_window, const IArray& row_prn, const DArray& row_t) {
  const py::ssize_t nr = rec_prn.ndim() == 1 ? rec_prn.shape(0) : -1;
  if (nr < 0 || rec_ok.ndim() != 1 || rec_ok.shape(0) != nr || rec_t.ndim() != 1 || rec_t.shape(0) != nr ||
      rec_window.ndim() != 1 || rec_window.shape(0) != nr)
    throw py::value_error("select_nearest_record: rec_prn, rec_ok, rec_t, rec_window must be (n_rec,)");
  const py::ssize_t k = row_prn.ndim() == 1 ? row_prn.shape(0) : -1;
  if (k < 0 || row_t.ndim() != 1 || row_t.shape(0) != k)
    throw py::value_error("select_nearest_record: row_prn, row_t must be (k,)");
  py::array_t<std::int64_t> idx(k);
  Status s;
  {
    py::gil_scoped_release release;
    s = gnss::select_nearest_record(rec_prn.data(), rec_ok.data(), rec_t.data(), rec_window.data(), nr,
                                    row_prn.data(), row_t.data(), k, idx.mutable_data());
  }
  if (s != Status::kOk) throw py::value_error("select_nearest_record: satellite numbers span more than 100000");
  return idx;
}

py::object scan_rinex_nav_body(const std::string& body, bool rinex3, bool glonass2, const std::string& want) {
  io::NavScan scan;
  {
    py::gil_scoped_release release;
    io::scan_rinex_nav_body(body, rinex3, glonass2, want, scan);
  }
  if (scan.irregular) return py::none();
  const py::ssize_t n = static_cast<py::ssize_t>(scan.prn.size());
  py::array_t<std::uint8_t> sys(n);
  py::array_t<std::int64_t> prn(n), ymdhm({n, py::ssize_t(5)});
  py::array_t<double> sec(n), clk({n, py::ssize_t(3)}), orbit({n, py::ssize_t(io::kNavOrbitValues)});
  std::copy(scan.sys.begin(), scan.sys.end(), sys.mutable_data());
  std::copy(scan.prn.begin(), scan.prn.end(), prn.mutable_data());
  std::copy(scan.ymdhm.begin(), scan.ymdhm.end(), ymdhm.mutable_data());
  std::copy(scan.sec.begin(), scan.sec.end(), sec.mutable_data());
  std::copy(scan.clk.begin(), scan.clk.end(), clk.mutable_data());
  std::copy(scan.orbit.begin(), scan.orbit.end(), orbit.mutable_data());
  py::dict d;
  d["sys"] = sys;
  d["prn"] = prn;
  d["ymdhm"] = ymdhm;
  d["sec"] = sec;
  d["clk"] = clk;
  d["orbit"] = orbit;
  py::list counts;
  for (std::int64_t c : scan.skipped_count) counts.append(c);
  d["skipped_sys"] = py::str(scan.skipped_sys);
  d["skipped_count"] = counts;
  return d;
}

}  // namespace

void bind_spp(py::module_& m) {
  m.def("transmit_states_kepler", &transmit_states_kepler, py::arg("elem"), py::arg("idx"), py::arg("t_rx"),
        py::arg("r_rx"), py::arg("gm"), py::arg("omega_e"), py::arg("f_rel"), py::arg("omega_geo"),
        py::arg("tol_s"), py::arg("max_iter"),
        "Kepler-element satellites at transmission in the ECEF frame at reception (insnav/gnss/broadcast_orbit.hpp): "
        "(r_e, v_e, clock_bias_s without group delay, clock_drift_s_s, t_tx_gps_s, tau_s, range_m).");
  m.def("transmit_states_glonass", &transmit_states_glonass, py::arg("glo"), py::arg("idx"), py::arg("t_rx"),
        py::arg("r_rx"), py::arg("gm"), py::arg("j2_term"), py::arg("omega_e"), py::arg("step_s"), py::arg("tol_s"),
        py::arg("max_iter"), "GLONASS satellites at transmission (insnav/gnss/broadcast_orbit.hpp), as "
        "transmit_states_kepler.");
  m.attr("SPP_MAX_ROWS") = gnss::kSppMaxRows;
  m.attr("GDOP_MAX_SATS") = gnss::kGdopMaxSats;
  m.def("select_nearest_record", &select_nearest_record, py::arg("rec_prn"), py::arg("rec_ok"), py::arg("rec_t"),
        py::arg("rec_window"), py::arg("row_prn"), py::arg("row_t"),
        "(k,) int64: for each row the usable record (rec_ok) of its satellite whose time is nearest to the row's "
        "within the record's window, the last of equals; -1 if none (insnav/gnss/ephemeris_selection.hpp).");
  m.def("scan_rinex_nav_body", &scan_rinex_nav_body, py::arg("body"), py::arg("rinex3"), py::arg("glonass2"),
        py::arg("want"),
        "Fields of the records of a RINEX navigation body (lines joined with newlines; insnav/io/rinex_nav.hpp): "
        "dict of sys, prn, ymdhm, sec, clk, orbit, skipped_sys, skipped_count; None where the Python reader "
        "must read the file (an error to report, or a form it handles itself).");
  m.def("select_best_gdop", &select_best_gdop, py::arg("u"), py::arg("n_select"), py::arg("max_combinations"),
        "Best-GDOP subset of n_select of the (k, 3) line-of-sight unit vectors u (insnav/gnss/gdop_selection.hpp): "
        "(sorted indices, GDOP).");
  m.def("best_gdop_keep", &best_gdop_keep, py::arg("u"), py::arg("epoch_start"), py::arg("n_select"),
        py::arg("max_combinations"),
        "(M,) bool: the rows of the best-GDOP subset of n_select satellites of every epoch with more "
        "(insnav/gnss/gdop_selection.hpp); GIL released.");
  m.def("solve_spp_batch", &solve_spp_batch, py::arg("epoch_start"), py::arg("sats"), py::arg("sigma_pr_m"),
        py::arg("sigma_prr_mps"), py::arg("system"), py::arg("r0_e"), py::arg("options"), py::arg("out"),
        "Single point positioning with RAIM FDE over every epoch (insnav/gnss/spp_solver.hpp), filling the "
        "preset arrays of ``out`` (keys of insnav.gnss.spp.SppSolution); GIL released.");
}

}  // namespace insnav::py_bind
