// Carrier-phase RTK: the fast RINEX 3 observation reader, MLAMBDA and the RTK engine batch
// loop (insnav/gnss/rtk.hpp) with the GIL released.
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <map>
#include <string>
#include <vector>

#include "common.hpp"
#include "insnav/gnss/lambda.hpp"
#include "insnav/gnss/noise_vce.hpp"
#include "insnav/gnss/rtk.hpp"
#include "insnav/gnss/rtk_rinex.hpp"
#include "insnav/io/rinex3_obs.hpp"

namespace insnav::py_bind {

namespace {

using gnss::RtkOptions;
using IArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

template <class T>
py::array_t<T> to_array(const std::vector<T>& v) {
  py::array_t<T> a(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(T));
  return a;
}

py::dict read_obs(const std::string& path, const std::map<std::string, std::vector<std::vector<std::string>>>& prefs) {
  std::map<char, std::vector<std::vector<std::string>>> p;
  for (const auto& [k, v] : prefs)
    if (!k.empty()) p[k[0]] = v;
  io::RinexObsTable t;
  {
    py::gil_scoped_release release;
    t = io::read_rinex3_obs(path, p);
  }
  py::dict d;
  d["version"] = t.version;
  d["approx_r_e"] = t.has_approx ? py::object(py::make_tuple(t.approx_r_e[0], t.approx_r_e[1], t.approx_r_e[2]))
                                 : py::object(py::none());
  d["antenna_hen_m"] = py::make_tuple(t.antenna_hen_m[0], t.antenna_hen_m[1], t.antenna_hen_m[2]);
  d["marker_name"] = t.marker_name;
  d["glonass_channels"] = t.glonass_channels;
  std::map<std::string, std::vector<std::string>> chosen;
  for (const auto& [s, a] : t.chosen) chosen[std::string(1, s)] = std::vector<std::string>(a.begin(), a.end());
  d["chosen"] = chosen;
  d["epoch_t_gps_s"] = to_array(t.epoch_t_gps_s);
  d["epoch_flag"] = to_array(t.epoch_flag);
  d["n_repeated_epochs"] = t.n_repeated_epochs;
  d["first_repeated_line"] = t.first_repeated_line;
  d["row_epoch"] = to_array(t.row_epoch);
  d["row_sys"] = to_array(t.row_sys);
  d["row_prn"] = to_array(t.row_prn);
  const py::ssize_t n = static_cast<py::ssize_t>(t.row_epoch.size());
  py::array_t<double> obs({n, static_cast<py::ssize_t>(io::kObsSlots * io::kObsPerSlot)});
  if (n) std::memcpy(obs.mutable_data(), t.obs.data(), t.obs.size() * sizeof(double));
  d["obs"] = obs;
  return d;
}

// The records of a RINEX 3 observation file whose header the caller parsed: ``types`` every
// system's header types (3-character codes), ``select`` system -> the codes read in the order
// C, L, D, S ("" where not read) of slot 0, optionally followed by those of slots 1 and 2 (4, 8
// or 12 codes).  Returns the columns of read_obs (and the epochs' receiver clock offsets).
py::dict read_obs_body(const py::bytes& text, const std::string& path, std::size_t offset, long lineno,
                       const std::map<std::string, std::vector<std::string>>& types,
                       const std::map<std::string, std::vector<std::string>>& select, bool zero_is_missing,
                       bool rinex2) {
  io::ObsColumns c;
  c.zero_is_missing = zero_is_missing;
  for (const auto& [k, ty] : types)
    if (k.size() == 1 && static_cast<unsigned char>(k[0]) < 128) c.set_types(static_cast<unsigned char>(k[0]), ty);
  for (const auto& [k, codes] : select) {
    if (k.size() != 1 || static_cast<unsigned char>(k[0]) >= 128) throw py::value_error("read_rinex3_obs_body: bad system key '" + k + "'");
    const unsigned char s = static_cast<unsigned char>(k[0]);
    if (codes.size() != 4 && codes.size() != 8 && codes.size() != 12)
      throw py::value_error("read_rinex3_obs_body: select needs 4, 8 or 12 codes (C, L, D, S per slot) per system");
    const auto it = types.find(rinex2 ? std::string("G") : k);  // RINEX 2: one list of types for all systems
    c.want[s] = it != types.end();
    if (!c.want[s]) continue;
    for (std::size_t j = 0; j < codes.size(); ++j) {
      const std::size_t slot = j / 4, q = j % 4;
      if (codes[j].empty()) continue;
      const auto& ty = it->second;
      for (std::size_t i = 0; i < ty.size(); ++i)
        if (ty[i] == codes[j]) { c.col[s][slot][q] = static_cast<int>(i); break; }
      if (c.col[s][slot][q] < 0) throw py::value_error("read_rinex3_obs_body: code " + codes[j] + " not in the header types of " + k);
      c.names[s][slot][q] = codes[j];
    }
  }
  const auto g = types.find("G");
  const int n_types_v2 = g == types.end() ? 0 : static_cast<int>(g->second.size());
  char* data = nullptr;
  Py_ssize_t size = 0;
  if (PyBytes_AsStringAndSize(text.ptr(), &data, &size) != 0) throw py::error_already_set();
  if (offset > static_cast<std::size_t>(size)) throw py::value_error("read_rinex3_obs_body: offset beyond the text");
  io::RinexObsTable t;
  {
    py::gil_scoped_release release;  // `text` stays referenced by the caller
    if (rinex2)
      io::read_rinex2_obs_body(data, static_cast<std::size_t>(size), path, offset, lineno, n_types_v2, c, t);
    else
      io::read_rinex3_obs_body(data, static_cast<std::size_t>(size), path, offset, lineno, c, t);
  }
  py::dict d;
  d["epoch_t_gps_s"] = to_array(t.epoch_t_gps_s);
  d["epoch_flag"] = to_array(t.epoch_flag);
  d["epoch_clock_s"] = to_array(t.epoch_clock_s);
  d["n_repeated_epochs"] = t.n_repeated_epochs;
  d["first_repeated_line"] = t.first_repeated_line;
  d["row_epoch"] = to_array(t.row_epoch);
  d["row_sys"] = to_array(t.row_sys);
  d["row_prn"] = to_array(t.row_prn);
  const py::ssize_t n = static_cast<py::ssize_t>(t.row_epoch.size());
  py::array_t<double> obs({n, static_cast<py::ssize_t>(io::kObsSlots * io::kObsPerSlot)});
  if (n) std::memcpy(obs.mutable_data(), t.obs.data(), t.obs.size() * sizeof(double));
  d["obs"] = obs;
  return d;
}

// One MLAMBDA solve of the float ambiguities a_hat (n) with covariance Q (n x n, row-major) in lam:
// the shape checks and the copy into the fixed-capacity types shared by the two bindings below.
gnss::LambdaStatus solve_lambda(const DArray& a_hat, const DArray& Q, const char* name, gnss::Lambda& lam,
                                gnss::AmbCand& fix, double s[2]) {
  const py::ssize_t n = a_hat.ndim() == 1 ? a_hat.shape(0) : -1;
  if (n < 0) throw py::value_error(std::string(name) + ": a_hat must be 1-D");
  if (n > gnss::kMaxAmbiguities)
    throw py::value_error(std::string(name) + ": at most " + std::to_string(gnss::kMaxAmbiguities) +
                          " ambiguities");
  require_shape(Q, n, n, (std::string(name) + ": Q").c_str());
  gnss::AmbVec a(n);
  gnss::AmbMat q(n, n);
  for (py::ssize_t i = 0; i < n; ++i) {
    a(i) = a_hat.data()[i];
    for (py::ssize_t j = 0; j < n; ++j) q(i, j) = Q.data()[i * n + j];
  }
  const auto st = lam.solve(a, q, fix, s);
  if (st == gnss::LambdaStatus::kNotPositiveDefinite)
    throw py::value_error(std::string(name) + ": Q is not positive definite");
  return st;
}

py::tuple lambda_search(const DArray& a_hat, const DArray& Q) {
  gnss::AmbCand fix;
  double s[2];
  gnss::Lambda lam;
  if (solve_lambda(a_hat, Q, "lambda_search", lam, fix, s) != gnss::LambdaStatus::kOk)
    throw py::value_error("lambda_search: search failed");
  const py::ssize_t n = fix.rows();
  py::array_t<double> out({n, static_cast<py::ssize_t>(2)});
  for (py::ssize_t i = 0; i < n; ++i)
    for (int c = 0; c < 2; ++c) out.mutable_data()[i * 2 + c] = fix(i, c);
  return py::make_tuple(out, py::make_tuple(s[0], s[1]));
}

// The work of one MLAMBDA solve: search nodes and reduction permutations (Lambda::nodes, permutations).
py::dict lambda_search_stats(const DArray& a_hat, const DArray& Q) {
  gnss::AmbCand fix;
  double s[2];
  gnss::Lambda lam;
  const auto st = solve_lambda(a_hat, Q, "lambda_search_stats", lam, fix, s);
  py::dict d;
  d["nodes"] = lam.nodes();
  d["permutations"] = lam.permutations();
  d["ok"] = st == gnss::LambdaStatus::kOk;
  return d;
}

double lambda_success_rate(const DArray& Q, double variance_factor) {
  if (!(variance_factor > 0.0) || !std::isfinite(variance_factor))
    throw py::value_error("lambda_success_rate: variance_factor must be > 0");
  const py::ssize_t n = Q.ndim() == 2 ? Q.shape(0) : -1;
  if (n < 1 || n > gnss::kMaxAmbiguities) throw py::value_error("lambda_success_rate: bad Q");
  require_shape(Q, n, n, "lambda_success_rate: Q");
  gnss::AmbMat q(n, n), Z, L;
  gnss::AmbVec D;
  for (py::ssize_t i = 0; i < n; ++i)
    for (py::ssize_t j = 0; j < n; ++j) q(i, j) = Q.data()[i * n + j];
  gnss::Lambda lam;
  if (!lam.decorrelate(q, Z, L, D)) throw py::value_error("lambda_success_rate: Q is not positive definite");
  return lam.bootstrap_success_rate(variance_factor);
}

py::tuple lambda_decorrelate(const DArray& Q) {
  const py::ssize_t n = Q.ndim() == 2 ? Q.shape(0) : -1;
  if (n < 0 || n > gnss::kMaxAmbiguities) throw py::value_error("lambda_decorrelate: bad Q");
  require_shape(Q, n, n, "lambda_decorrelate: Q");
  gnss::AmbMat q(n, n), Z, L;
  gnss::AmbVec D;
  for (py::ssize_t i = 0; i < n; ++i)
    for (py::ssize_t j = 0; j < n; ++j) q(i, j) = Q.data()[i * n + j];
  gnss::Lambda lam;
  if (!lam.decorrelate(q, Z, L, D)) throw py::value_error("lambda_decorrelate: Q is not positive definite");
  py::array_t<double> z({n, n}), l({n, n}), d(n);
  for (py::ssize_t i = 0; i < n; ++i) {
    d.mutable_data()[i] = D(i);
    for (py::ssize_t j = 0; j < n; ++j) {
      z.mutable_data()[i * n + j] = Z(i, j);
      l.mutable_data()[i * n + j] = L(i, j);
    }
  }
  return py::make_tuple(z, l, d);
}

}  // namespace

RtkOptions rtk_options_from_dict(const py::dict& d) {
  RtkOptions o;
  for (auto item : d) {
    const std::string k = py::str(item.first);
    const py::handle v = item.second;
    if (k == "mode") o.mode = static_cast<gnss::RtkMode>(v.cast<int>());
    else if (k == "ar_mode") o.ar_mode = static_cast<gnss::ArMode>(v.cast<int>());
    else if (k == "n_freq") o.n_freq = v.cast<int>();
    else if (k == "elevation_mask_rad") o.elevation_mask_rad = v.cast<double>();
    else if (k == "ar_elevation_mask_rad") o.ar_elevation_mask_rad = v.cast<double>();
    else if (k == "ratio_threshold") o.ratio_threshold = v.cast<double>();
    else if (k == "min_fix_ambiguities") o.min_fix_ambiguities = v.cast<int>();
    else if (k == "max_partial_drops") o.max_partial_drops = v.cast<int>();
    else if (k == "partial_by_variance") o.partial_by_variance = v.cast<bool>();
    else if (k == "min_lock_epochs") o.min_lock_epochs = v.cast<int>();
    else if (k == "glonass_ar") o.glonass_ar = v.cast<bool>();
    else if (k == "sigma_phase_a_m") o.sigma_phase_a_m = v.cast<double>();
    else if (k == "sigma_phase_b_m") o.sigma_phase_b_m = v.cast<double>();
    else if (k == "code_phase_ratio") o.code_phase_ratio = v.cast<double>();
    else if (k == "code_corr_time_s") o.code_corr_time_s = v.cast<double>();
    else if (k == "code_scale_gain") o.code_scale_gain = v.cast<double>();
    else if (k == "phase_corr_time_s") o.phase_corr_time_s = v.cast<double>();
    else if (k == "phase_error_ratio") o.phase_error_ratio = v.cast<double>();
    else if (k == "confirm_epochs") o.confirm_epochs = v.cast<int>();
    else if (k == "confirm_max_ambiguities") o.confirm_max_ambiguities = v.cast<int>();
    else if (k == "min_success_rate") o.min_success_rate = v.cast<double>();
    else if (k == "min_success_rate_estimated") o.min_success_rate_estimated = v.cast<double>();
    else if (k == "noise_window_s") o.noise_window_s = v.cast<double>();
    else if (k == "noise_confidence") o.noise_confidence = v.cast<double>();
    else if (k == "glonass_factor") o.glonass_factor = v.cast<double>();
    else if (k == "iono_sigma_per_10km_m") o.iono_sigma_per_10km_m = v.cast<double>();
    else if (k == "iono_mode") {
      const int im = v.cast<int>();
      if (im < 0 || im > 2) throw py::value_error("rtk options: iono_mode must be 0 (off), 1 (variance) or 2 (estimate)");
      o.iono_mode = static_cast<gnss::IonoMode>(im);
    } else if (k == "iono_tau_s") o.iono_tau_s = v.cast<double>();
    else if (k == "tropo_model") o.tropo_model = v.cast<bool>();
    else if (k == "accel_psd_h") o.accel_psd_h = v.cast<double>();
    else if (k == "accel_psd_v") o.accel_psd_v = v.cast<double>();
    else if (k == "static_pos_psd") o.static_pos_psd = v.cast<double>();
    else if (k == "pos_init_sigma_m") o.pos_init_sigma_m = v.cast<double>();
    else if (k == "vel_init_sigma_mps") o.vel_init_sigma_mps = v.cast<double>();
    else if (k == "amb_init_sigma_cycles") o.amb_init_sigma_cycles = v.cast<double>();
    else if (k == "amb_psd") o.amb_psd = v.cast<double>();
    else if (k == "gf_threshold_m") o.gf_threshold_m = v.cast<double>();
    else if (k == "mw_threshold_cycles") o.mw_threshold_cycles = v.cast<double>();
    else if (k == "doppler_threshold_cycles") o.doppler_threshold_cycles = v.cast<double>();
    else if (k == "doppler_max_dt_s") o.doppler_max_dt_s = v.cast<double>();
    else if (k == "max_gap_s") o.max_gap_s = v.cast<double>();
    else if (k == "max_outage_epochs") o.max_outage_epochs = v.cast<int>();
    else if (k == "outlier_sigma") o.outlier_sigma = v.cast<double>();
    else if (k == "hold_sigma_cycles") o.hold_sigma_cycles = v.cast<double>();
    else if (k == "max_age_s") o.max_age_s = v.cast<double>();
    else throw py::value_error("rtk options: unknown key '" + k + "'");
  }
  return o;
}

namespace {

RtkOptions options_from_dict(const py::dict& d) { return rtk_options_from_dict(d); }

void check_rows(const DArray& rows, const char* name) {
  if (rows.ndim() != 2 || rows.shape(1) != gnss::RtkRow::kCols)
    throw py::value_error(std::string(name) + ": expected shape (m, " + std::to_string(gnss::RtkRow::kCols) + ")");
}

static_assert(gnss::kMaxVceRows >= gnss::kMaxRows, "the VCE blocks hold an engine epoch's rows of one kind");

// The LS-VCE sums of the fixed epochs' rows (insnav/gnss/noise_vce.hpp) at the variance factors k.
py::dict rtk_vce_sums(const IArray& epoch, const py::array_t<int, py::array::c_style | py::array::forcecast>& code,
                      const py::array_t<int, py::array::c_style | py::array::forcecast>& group, const DArray& y,
                      const DArray& h, const DArray& var_own, const DArray& var_ref, const DArray& k,
                      bool redundancy) {
  const py::ssize_t n = y.ndim() == 1 ? y.shape(0) : -1;
  if (n < 0) throw py::value_error("rtk_vce_sums: y must be 1-D");
  if (epoch.size() != n || code.size() != n || group.size() != n || var_own.size() != n || var_ref.size() != n)
    throw py::value_error("rtk_vce_sums: epoch, code, group, y, var_own, var_ref must have one entry per row");
  if (h.ndim() != 2 || h.shape(0) != n || h.shape(1) != 3) throw py::value_error("rtk_vce_sums: h must be (n, 3)");
  if (k.size() != 2) throw py::value_error("rtk_vce_sums: k must hold 2 variance factors");
  gnss::VceRows rows;
  rows.n = n;
  rows.epoch = epoch.data();
  rows.code = code.data();
  rows.group = group.data();
  rows.y = y.data();
  rows.h = h.data();
  rows.var_own = var_own.data();
  rows.var_ref = var_ref.data();
  const Eigen::Vector2d kv(k.data()[0], k.data()[1]);
  py::array_t<double> red(redundancy ? n : 0);
  double* rp = redundancy ? red.mutable_data() : nullptr;
  for (py::ssize_t i = 0; redundancy && i < n; ++i) rp[i] = NAN;
  gnss::VceSums s;
  {
    py::gil_scoped_release release;
    std::vector<std::int64_t> order(static_cast<std::size_t>(n));
    for (py::ssize_t i = 0; i < n; ++i) order[static_cast<std::size_t>(i)] = i;
    const std::int64_t* ep = rows.epoch;
    std::stable_sort(order.begin(), order.end(), [ep](std::int64_t a, std::int64_t b) { return ep[a] < ep[b]; });
    auto acc = std::make_unique<gnss::VceAccumulator>();
    s = acc->accumulate(rows, order.data(), kv, rp);
  }
  if (s.status == gnss::VceStatus::kTooManyRows)
    throw py::value_error("rtk_vce_sums: epoch " + std::to_string(s.bad_epoch) + " has more than " +
                          std::to_string(gnss::kMaxVceRows) + " rows of one kind");
  if (s.status == gnss::VceStatus::kNotPositiveDefinite)
    throw py::value_error("rtk_vce_sums: epoch " + std::to_string(s.bad_epoch) +
                          ": covariance of the double differences (or A^T W A) not positive definite");
  py::array_t<double> N({static_cast<py::ssize_t>(2), static_cast<py::ssize_t>(2)}), l(2);
  for (int i = 0; i < 2; ++i) {
    l.mutable_data()[i] = s.l(i);
    for (int j = 0; j < 2; ++j) N.mutable_data()[2 * i + j] = s.N(i, j);
  }
  py::dict d;
  d["N"] = N;
  d["l"] = l;
  d["n_epochs"] = s.n_epochs;
  d["n_phase_rows"] = s.n_phase_rows;
  d["n_code_rows"] = s.n_code_rows;
  if (redundancy) d["redundancy"] = red;
  return d;
}

py::dict rtk_run(const DArray& t_rover, const IArray& rover_off, const DArray& rover_rows, const IArray& base_off,
                 const DArray& base_rows, const IArray& base_index, const DArray& r_base_e, const py::dict& opts,
                 bool record_iono, bool record_fixed_rows, bool record_float) {
  const py::ssize_t n = t_rover.ndim() == 1 ? t_rover.shape(0) : -1;
  if (n < 0) throw py::value_error("rtk_run: t_rover must be 1-D");
  check_rows(rover_rows, "rtk_run: rover_rows");
  check_rows(base_rows, "rtk_run: base_rows");
  if (rover_off.size() != n + 1 || base_index.size() != n) throw py::value_error("rtk_run: offsets / base index sizes");
  const py::ssize_t nb = base_off.size() - 1;
  const Vec3 rb = vec3_from(r_base_e, "rtk_run: r_base_e");
  const RtkOptions o = options_from_dict(opts);
  py::array_t<int> status(n), n_fix(n), n_dd(n), n_sat(n);
  py::array_t<double> ratio(n), success_rate(n), sr_factor(n), sr_est(n), r_e({n, static_cast<py::ssize_t>(3)}), v_e({n, static_cast<py::ssize_t>(3)}),
      r_float({n, static_cast<py::ssize_t>(3)}), P_r({n, static_cast<py::ssize_t>(9)});
  py::array_t<int> slips({n, static_cast<py::ssize_t>(gnss::kNumSlipKinds)});
  // per epoch and satellite key: the single-differenced ionosphere estimate and sigma [m] (NaN: no state)
  const py::ssize_t ni = record_iono ? n : 0;
  const py::ssize_t nk = gnss::kMaxSatKeys;
  py::array_t<double> iono_m({ni, nk}), iono_sigma_m({ni, nk}), iono_dd_m({ni, nk}), iono_dd_sigma_m({ni, nk});
  const std::int64_t* ro = rover_off.data();
  const std::int64_t* bo = base_off.data();
  const std::int64_t* bi = base_index.data();
  const py::ssize_t mr = rover_rows.shape(0), mb = base_rows.shape(0);
  for (py::ssize_t e = 0; e < n; ++e) {
    if (ro[e] < 0 || ro[e + 1] < ro[e] || ro[e + 1] > mr) throw py::value_error("rtk_run: bad rover offsets");
    if (bi[e] >= nb) throw py::value_error("rtk_run: base index out of range");
  }
  for (py::ssize_t e = 0; e < nb; ++e)
    if (bo[e] < 0 || bo[e + 1] < bo[e] || bo[e + 1] > mb) throw py::value_error("rtk_run: bad base offsets");
  // the fixed epochs' double differences (RtkEngine::set_record_fixed_rows), one entry per row
  std::vector<std::int64_t> fr_epoch;
  std::vector<int> fr_code, fr_group;
  std::vector<double> fr_y, fr_h, fr_var_own, fr_var_ref;
  // the float AR problem of every epoch with AR (RtkEngine::set_record_float), concatenated
  std::vector<std::int64_t> fp_epoch, fp_n;
  std::vector<int> fp_sat_j, fp_sat_i, fp_freq;
  std::vector<double> fp_a, fp_Q, fp_Qba, fp_Qbb;
  {
    py::gil_scoped_release release;
    auto eng = std::make_unique<gnss::RtkEngine>(o);
    eng->set_record_fixed_rows(record_fixed_rows);
    eng->set_record_float(record_float);
    std::int64_t last_b = -1;
    for (py::ssize_t e = 0; e < n; ++e) {
      gnss::RtkEpoch out;
      const std::int64_t b = bi[e];
      if (b >= 0) {
        out = eng->process(t_rover.data()[e], rover_rows.data() + ro[e] * gnss::RtkRow::kCols,
                           static_cast<int>(ro[e + 1] - ro[e]), base_rows.data() + bo[b] * gnss::RtkRow::kCols,
                           static_cast<int>(bo[b + 1] - bo[b]), b != last_b, rb);
        last_b = b;
      }
      status.mutable_data()[e] = static_cast<int>(out.status);
      n_fix.mutable_data()[e] = out.n_fix;
      n_dd.mutable_data()[e] = out.n_dd;
      n_sat.mutable_data()[e] = out.n_sat;
      ratio.mutable_data()[e] = out.ratio;
      success_rate.mutable_data()[e] = out.success_rate;
      sr_factor.mutable_data()[e] = out.success_variance_factor;
      sr_est.mutable_data()[e] = out.success_rate_estimated;
      for (int i = 0; i < 3; ++i) {
        r_e.mutable_data()[e * 3 + i] = out.r_e(i);
        v_e.mutable_data()[e * 3 + i] = out.v_e(i);
        r_float.mutable_data()[e * 3 + i] = out.r_float_e(i);
        for (int j = 0; j < 3; ++j) P_r.mutable_data()[e * 9 + i * 3 + j] = out.P_r(i, j);
      }
      for (int k = 0; k < gnss::kNumSlipKinds; ++k) slips.mutable_data()[e * gnss::kNumSlipKinds + k] = out.slips[k];
      for (int i = 0; i < eng->fixed_rows(); ++i) {
        const gnss::FixedDdRow& fr = eng->fixed_row(i);
        fr_epoch.push_back(e);
        fr_code.push_back(fr.code);
        fr_group.push_back(fr.group);
        fr_y.push_back(fr.y);
        fr_h.insert(fr_h.end(), fr.h, fr.h + 3);
        fr_var_own.push_back(fr.var_own);
        fr_var_ref.push_back(fr.var_ref);
      }
      if (record_float && b >= 0 && eng->float_problem().n > 0) {
        const auto& fp = eng->float_problem();
        fp_epoch.push_back(e);
        fp_n.push_back(fp.n);
        for (int p = 0; p < fp.n; ++p) {
          fp_a.push_back(fp.a_hat(p));
          fp_sat_j.push_back(fp.sat_j[p]);
          fp_sat_i.push_back(fp.sat_i[p]);
          fp_freq.push_back(fp.freq[p]);
          for (int q = 0; q < fp.n; ++q) fp_Q.push_back(fp.Qa(p, q));
          for (int i = 0; i < 3; ++i) fp_Qba.push_back(fp.Qba(i, p));  // (n, 3) per epoch: Q_ab
        }
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) fp_Qbb.push_back(fp.Qbb(i, j));
      }
      if (record_iono)
        for (int s = 0; s < gnss::kMaxSatKeys; ++s) {
          double v = NAN, sg = NAN;
          if (!eng->iono_estimate(s, v, sg)) v = sg = NAN;
          iono_m.mutable_data()[e * gnss::kMaxSatKeys + s] = v;
          iono_sigma_m.mutable_data()[e * gnss::kMaxSatKeys + s] = sg;
          if (!eng->iono_dd_estimate(s, v, sg)) v = sg = NAN;
          iono_dd_m.mutable_data()[e * gnss::kMaxSatKeys + s] = v;
          iono_dd_sigma_m.mutable_data()[e * gnss::kMaxSatKeys + s] = sg;
        }
    }
  }
  py::dict d;
  d["status"] = status;
  d["n_fix"] = n_fix;
  d["n_dd"] = n_dd;
  d["n_sat"] = n_sat;
  d["ratio"] = ratio;
  d["success_rate"] = success_rate;
  d["success_variance_factor"] = sr_factor;
  d["success_rate_estimated"] = sr_est;
  d["r_e"] = r_e;
  d["v_e"] = v_e;
  d["r_float_e"] = r_float;
  d["P_r"] = P_r;
  d["slips"] = slips;
  if (record_fixed_rows) {
    const auto nr = static_cast<py::ssize_t>(fr_y.size());
    py::dict f;
    f["epoch"] = py::array_t<std::int64_t>(nr, fr_epoch.data());
    f["code"] = py::array_t<int>(nr, fr_code.data());
    f["group"] = py::array_t<int>(nr, fr_group.data());
    f["y"] = py::array_t<double>(nr, fr_y.data());
    f["h"] = py::array_t<double>({nr, static_cast<py::ssize_t>(3)}, fr_h.data());
    f["var_own"] = py::array_t<double>(nr, fr_var_own.data());
    f["var_ref"] = py::array_t<double>(nr, fr_var_ref.data());
    d["fixed_rows"] = f;
  }
  if (record_float) {
    const auto ne = static_cast<py::ssize_t>(fp_n.size()), na = static_cast<py::ssize_t>(fp_a.size());
    py::dict f;
    f["epoch"] = py::array_t<std::int64_t>(ne, fp_epoch.data());
    f["n"] = py::array_t<std::int64_t>(ne, fp_n.data());
    f["a_hat"] = py::array_t<double>(na, fp_a.data());
    f["Q_a"] = py::array_t<double>(static_cast<py::ssize_t>(fp_Q.size()), fp_Q.data());
    f["Q_ab"] = py::array_t<double>({na, static_cast<py::ssize_t>(3)}, fp_Qba.data());
    f["Q_bb"] = py::array_t<double>({ne, static_cast<py::ssize_t>(3), static_cast<py::ssize_t>(3)}, fp_Qbb.data());
    f["sat_j"] = py::array_t<int>(na, fp_sat_j.data());
    f["sat_i"] = py::array_t<int>(na, fp_sat_i.data());
    f["freq"] = py::array_t<int>(na, fp_freq.data());
    d["float_ar"] = f;
  }
  if (record_iono) {
    d["iono_m"] = iono_m;
    d["iono_sigma_m"] = iono_sigma_m;
    d["iono_dd_m"] = iono_dd_m;
    d["iono_dd_sigma_m"] = iono_dd_sigma_m;
  }
  return d;
}

py::array_t<std::uint8_t> slip_detect(const DArray& t, const IArray& off, const DArray& rows, const py::dict& opts) {
  const py::ssize_t n = t.ndim() == 1 ? t.shape(0) : -1;
  check_rows(rows, "slip_detect: rows");
  if (n < 0 || off.size() != n + 1) throw py::value_error("slip_detect: offsets");
  const RtkOptions o = options_from_dict(opts);
  const py::ssize_t m = rows.shape(0);
  py::array_t<std::uint8_t> flags({m, static_cast<py::ssize_t>(gnss::kMaxFreq)});
  std::fill(flags.mutable_data(), flags.mutable_data() + m * gnss::kMaxFreq, 0);
  {
    py::gil_scoped_release release;
    auto det = std::make_unique<gnss::SlipDetector>();
    std::array<int, gnss::kNumSlipKinds> counts{};
    std::vector<std::uint8_t> buf(gnss::kMaxSatKeys * gnss::kMaxFreq);
    for (py::ssize_t e = 0; e < n; ++e) {
      const auto a = off.data()[e], b = off.data()[e + 1];
      const int k = static_cast<int>(std::min<std::int64_t>(b - a, gnss::kMaxSatKeys));
      det->detect(t.data()[e], rows.data() + a * gnss::RtkRow::kCols, k, o.n_freq, o, buf.data(), counts);
      std::memcpy(flags.mutable_data() + a * gnss::kMaxFreq, buf.data(), static_cast<size_t>(k) * gnss::kMaxFreq);
    }
  }
  return flags;
}

py::dict rtk_double_differences(const DArray& rover_rows, const DArray& base_rows, const DArray& r_rover_e,
                                const DArray& r_base_e, const py::dict& opts) {
  check_rows(rover_rows, "rtk_double_differences: rover_rows");
  check_rows(base_rows, "rtk_double_differences: base_rows");
  const RtkOptions o = options_from_dict(opts);
  const int nr = static_cast<int>(std::min<py::ssize_t>(rover_rows.shape(0), gnss::kMaxSatKeys));
  const int nb = static_cast<int>(std::min<py::ssize_t>(base_rows.shape(0), gnss::kMaxSatKeys));
  constexpr int kMax = 2 * gnss::kMaxRows;
  std::vector<int> sat(kMax), ref(kMax), freq(kMax), code(kMax);
  std::vector<double> val(kMax);
  auto eng = std::make_unique<gnss::RtkEngine>(o);
  const int n = eng->double_differences(rover_rows.data(), nr, base_rows.data(), nb, vec3_from(r_rover_e, "r_rover_e"),
                                        vec3_from(r_base_e, "r_base_e"), sat.data(), ref.data(), freq.data(),
                                        code.data(), val.data(), kMax);
  sat.resize(n); ref.resize(n); freq.resize(n); code.resize(n); val.resize(n);
  py::dict d;
  d["sat_row"] = to_array(sat);
  d["ref_row"] = to_array(ref);
  d["freq"] = to_array(freq);
  d["is_code"] = to_array(code);
  d["value_m"] = to_array(val);
  return d;
}

// RTK from RINEX files in one call (insnav/gnss/rtk_rinex.hpp), for `insnav run --filter rtk` without
// numpy: no array crosses the boundary.  Returns a dict (the .pos and .rtk.csv texts, the counts of
// the summary line) or a str: why the files are left to the Python path.
py::object rtk_rinex_files(const std::string& rover, const std::string& base, const std::vector<std::string>& nav,
                           const std::string& systems, const py::dict& opts, const py::object& base_position_e_m,
                           const std::map<std::string, std::vector<std::vector<std::string>>>& prefs) {
  gnss::RtkRinexInputs in;
  in.rover_path = rover;
  in.base_path = base;
  in.nav_paths = nav;
  in.systems = systems;
  for (const auto& [k, v] : prefs)
    if (!k.empty()) in.signal_prefs[k[0]] = v;
  const RtkOptions o = options_from_dict(opts);
  in.n_freq = o.n_freq;
  in.max_age_s = o.max_age_s;
  if (!base_position_e_m.is_none()) {
    const auto v = base_position_e_m.cast<std::vector<double>>();
    if (v.size() != 3) throw py::value_error("rtk_rinex_files: base_position_e_m needs 3 values");
    in.has_base_position = true;
    for (int i = 0; i < 3; ++i) in.base_position_e_m[i] = v[static_cast<std::size_t>(i)];
  }
  gnss::RtkRinexResult r;
  {
    py::gil_scoped_release release;
    r = gnss::rtk_rinex_run(in, o);
  }
  if (!r.ok) return py::str(r.why);
  py::dict d;
  d["pos_text"] = py::str(r.pos_text);
  d["table_text"] = py::str(r.table_text);
  d["epochs"] = r.epochs;
  d["n_fixed"] = r.n_fixed;
  d["n_float"] = r.n_float;
  d["n_dgps"] = r.n_dgps;
  d["n_none"] = r.n_none;
  d["slips"] = r.slips_total;
  return d;
}

}  // namespace

void bind_rtk(py::module_& m) {
  m.def("read_rinex3_obs", &read_obs, py::arg("path"), py::arg("prefs"),
        "Fast RINEX 3 observation reader: up to 3 frequency slots per system (C, L, D, S, LLI).");
  m.def("read_rinex3_obs_body", &read_obs_body, py::arg("text"), py::arg("path"), py::arg("offset"), py::arg("lineno"),
        py::arg("types"), py::arg("select"), py::arg("zero_is_missing"), py::arg("rinex2") = false,
        "Records of a RINEX 3 (or, rinex2=True, 2.1x) observation file after a header parsed by the caller (per slot: C, L, D, S, LLI).");
  m.def("lambda_search", &lambda_search, py::arg("a_hat"), py::arg("Q"),
        "MLAMBDA (Chang, Yang, Zhou 2005): best and second-best integer vectors (n, 2) and squared norms.");
  m.def("lambda_search_stats", &lambda_search_stats, py::arg("a_hat"), py::arg("Q"),
        "The work of one MLAMBDA solve: dict(nodes (search), permutations (reduction), ok).");
  m.def("lambda_decorrelate", &lambda_decorrelate, py::arg("Q"),
        "MLAMBDA reduction: (Z, L, D) with Z^T Q Z = L^T diag(D) L.");
  m.def("lambda_success_rate", &lambda_success_rate, py::arg("Q"), py::arg("variance_factor") = 1.0,
        "Bootstrapped success rate of the decorrelated ambiguities of variance_factor * Q (Teunissen 1998), "
        "a lower bound of ILS's.");
  m.def("rtk_vce_sums", &rtk_vce_sums, py::arg("epoch"), py::arg("code"), py::arg("group"), py::arg("y"), py::arg("h"),
        py::arg("var_own"), py::arg("var_ref"), py::arg("k"), py::arg("redundancy") = false,
        "LS-VCE sums of the RTK fixed epochs' double differences at the variance factors k = (k_phi, k_P) "
        "(Teunissen & Amiri-Simkooei 2008, sec. 3; insnav/gnss/noise_vce.hpp): dict with N (2, 2), l (2,), "
        "n_epochs, n_phase_rows, n_code_rows of the usable epochs and, with redundancy=True, the redundancy number "
        "of every row (NaN in unusable epochs).");
  m.def("rtk_run", &rtk_run, py::arg("t_rover"), py::arg("rover_off"), py::arg("rover_rows"), py::arg("base_off"),
        py::arg("base_rows"), py::arg("base_index"), py::arg("r_base_e"), py::arg("options"),
        py::arg("record_iono") = false, py::arg("record_fixed_rows") = false, py::arg("record_float") = false,
        "RTK engine over every rover epoch (GIL released); record_iono: also the (n, 320) single-differenced "
        "ionosphere estimates iono_m and iono_sigma_m [m] per satellite key (NaN: no state), and iono_dd_m, "
        "iono_dd_sigma_m: the double differences against the reference of each system (NaN for it); "
        "record_fixed_rows: also fixed_rows, the double-differenced rows of every fixed epoch (epoch, code, "
        "group, y [m], h (k, 3), var_own, var_ref [m^2]) for the variance component estimation; "
        "record_float: also float_ar, the float ambiguity problem of every epoch with AR in the engine's partial-AR "
        "order (epoch, n per epoch; concatenated a_hat [cycles], Q_a (n x n row-major per epoch) [cycles^2], Q_ab "
        "(n, 3) [cycles m], sat_j, sat_i (satellite keys), freq; Q_bb (k, 3, 3) [m^2]).");
  m.def("slip_detect", &slip_detect, py::arg("t"), py::arg("off"), py::arg("rows"), py::arg("options"),
        "Cycle-slip flags (m, 3) of one receiver's rows (bits: LLI, GF, MW, Doppler, gap).");
  m.def("rtk_double_differences", &rtk_double_differences, py::arg("rover_rows"), py::arg("base_rows"),
        py::arg("r_rover_e"), py::arg("r_base_e"), py::arg("options"),
        "Double differences observed minus computed (no ambiguity term) at a given rover position.");
  m.def("rtk_rinex_files", &rtk_rinex_files, py::arg("rover"), py::arg("base"), py::arg("nav"), py::arg("systems"),
        py::arg("options"), py::arg("base_position_e_m"), py::arg("signal_prefs"),
        "RTK from RINEX 3 files (systems G and J) in one call, no arrays: {pos_text, table_text, epochs, n_fixed, "
        "n_float, n_dgps, n_none, slips}, or a str saying why the files are left to the Python path.");
  m.attr("RTK_ROW_COLS") = gnss::RtkRow::kCols;
  m.attr("RTK_MAX_AMBIGUITIES") = gnss::kMaxAmbiguities;
}

}  // namespace insnav::py_bind
