// Tight RTK/INS (insnav/engine/rtk_ins_engine.hpp): the batch run with the GIL released (EKF, RB-UKF or
// UKF time update, one table below), one DD row and its Jacobian (meas/dd_phase.hpp), and the AR tests
// applied to a given integer vector.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>
#include <algorithm>
#include <type_traits>

#include "common.hpp"
#include "convert.hpp"
#include "insnav/engine/rtk_ins_engine.hpp"
#include "insnav/filter/ukf.hpp"
#include "outputs.hpp"
#include "smoother_run.hpp"

namespace insnav::py_bind {

gnss::RtkOptions rtk_options_from_dict(const py::dict& d);  // bind_rtk.cpp

namespace {

using IArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

RtkInsConfig rtk_ins_config_from(const py::dict& engine, const py::dict& rtk) {
  reject_unknown(engine, {"lever_arm_b", "propagation_interval", "output_decimation", "ins_slip_k_sigma",
                          "ins_slip_min_cycles", "ins_slip_max_dt_s", "code_chi2_row", "validation_prob",
                          "ar_min_success_rate", "outage_cycle_s", "smooth", "robust_screening",
                          "robust_chi2_row", "robust_igg_k0", "robust_igg_k1", "robust_huber", "robust_huber_k",
                          "robust_max_sats", "robust_phase_reset_epochs", INSNAV_UT_KEYS},
                 "rtk/ins engine config");
  RtkInsConfig c;
  c.rtk = rtk_options_from_dict(rtk);
  c.lever_arm_b = vec3_or_scalar(engine, "lever_arm_b", c.lever_arm_b);
  c.ut = ut_from(engine);
  c.propagation_interval = num(engine, "propagation_interval", c.propagation_interval);
  c.output_decimation = static_cast<int>(num(engine, "output_decimation", c.output_decimation));
  c.ins_slip_k_sigma = num(engine, "ins_slip_k_sigma", c.ins_slip_k_sigma);
  c.ins_slip_min_cycles = num(engine, "ins_slip_min_cycles", c.ins_slip_min_cycles);
  c.ins_slip_max_dt_s = num(engine, "ins_slip_max_dt_s", c.ins_slip_max_dt_s);
  c.code_chi2_row = num(engine, "code_chi2_row", c.code_chi2_row);
  c.validation_prob = num(engine, "validation_prob", c.validation_prob);
  c.ar_min_success_rate = num(engine, "ar_min_success_rate", c.ar_min_success_rate);
  c.outage_cycle_s = num(engine, "outage_cycle_s", c.outage_cycle_s);
  c.robust.screening = flag(engine, "robust_screening", c.robust.screening);
  c.robust.chi2_row = num(engine, "robust_chi2_row", c.robust.chi2_row);
  c.robust.igg_k0 = num(engine, "robust_igg_k0", c.robust.igg_k0);
  c.robust.igg_k1 = num(engine, "robust_igg_k1", c.robust.igg_k1);
  c.robust.huber = flag(engine, "robust_huber", c.robust.huber);
  c.robust.huber_k = num(engine, "robust_huber_k", c.robust.huber_k);
  c.robust.fde_max_sats = static_cast<int>(num(engine, "robust_max_sats", c.robust.fde_max_sats));
  if (!(c.robust.chi2_row > 0.0)) throw py::value_error("robust_chi2_row must be > 0");
  if (!(c.robust.igg_k0 > 0.0 && c.robust.igg_k1 > c.robust.igg_k0))
    throw py::value_error("robust_igg_k0 and robust_igg_k1 must satisfy 0 < k0 < k1");
  if (!(c.robust.huber_k > 0.0)) throw py::value_error("robust_huber_k must be > 0");
  c.phase_reset_epochs = static_cast<int>(num(engine, "robust_phase_reset_epochs", c.phase_reset_epochs));
  if (c.phase_reset_epochs < 0) throw py::value_error("robust_phase_reset_epochs must be >= 0");
  if (c.robust.fde_max_sats < 0) throw py::value_error("robust_max_sats must be >= 0");
  if (!(c.outage_cycle_s > 0.0)) throw py::value_error("outage_cycle_s must be > 0 (inf: one cycle per gap)");
  if (!(c.ar_min_success_rate >= 0.0 && c.ar_min_success_rate < 1.0))
    throw py::value_error("ar_min_success_rate must be in [0, 1)");
  if (!(c.propagation_interval > 0.0)) throw py::value_error("propagation_interval must be > 0");
  if (c.output_decimation < 1) throw py::value_error("output_decimation must be >= 1");
  if (!(c.ins_slip_k_sigma > 0.0) || !(c.ins_slip_min_cycles >= 0.0) || !(c.ins_slip_max_dt_s >= 0.0))
    throw py::value_error("ins_slip_k_sigma must be > 0, ins_slip_min_cycles and ins_slip_max_dt_s >= 0");
  if (!(c.code_chi2_row >= 0.0)) throw py::value_error("code_chi2_row must be >= 0");
  if (!(c.validation_prob >= 0.0 && c.validation_prob < 1.0)) throw py::value_error("validation_prob must be in [0, 1)");
  return c;
}

template <class Filter>
py::dict rtk_ins_run_with(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, const DArray& init, const DArray& P0,
                     const DArray& corr0, const py::dict& model, const py::dict& engine_cfg, const py::dict& rtk_opts,
                     const DArray& t_rec, const IArray& rover_off, const DArray& rover_rows, const IArray& base_off,
                     const DArray& base_rows, const IArray& base_index, const DArray& r_base_e,
                     std::int64_t probe_epoch) {
  const ImuArrays imu = imu_arrays(t, dtheta_b, dv_b);
  const NavState nav = nav_state_from(init);
  const StateCov<Layout15> P = state_cov_from<Layout15>(P0);
  const ImuCorrection corr = imu_correction_from(corr0);
  const ImuErrorModel mdl = imu_model_from_dict(model);
  const RtkInsConfig cfg = rtk_ins_config_from(engine_cfg, rtk_opts);
  const bool smooth = flag(engine_cfg, "smooth", false);  // the RTS backward pass (smoother_run.hpp)
  // EKF: the cycle transition; RB-UKF / UKF: the UT cross-covariance and the statistically linearised
  // transition (rtk_ins_engine.hpp, "Filters")
  static_assert(SmootherRun<Filter>::kSupported, "rtk_ins_run: a filter the RTS smoother runs with");
  using Engine = RtkInsEngine<64, Filter>;
  if (smooth && probe_epoch >= 0) throw py::value_error("rtk_ins_run: probe_epoch and smooth exclude each other");
  const Vec3 rb = vec3_from(r_base_e, "rtk_ins_run: r_base_e");
  const py::ssize_t E = t_rec.ndim() == 1 ? t_rec.shape(0) : -1;
  if (E < 0) throw py::value_error("rtk_ins_run: t_rec must be 1-D");
  for (const DArray* a : {&rover_rows, &base_rows})
    if (a->ndim() != 2 || a->shape(1) != gnss::RtkRow::kCols)
      throw py::value_error("rtk_ins_run: rows must have shape (m, " + std::to_string(gnss::RtkRow::kCols) + ")");
  if (rover_off.size() != E + 1 || base_index.size() != E) throw py::value_error("rtk_ins_run: offsets / base index sizes");
  const py::ssize_t nb = base_off.size() - 1, mr = rover_rows.shape(0), mb = base_rows.shape(0);
  const std::int64_t *ro = rover_off.data(), *bo = base_off.data(), *bi = base_index.data();
  for (py::ssize_t e = 0; e < nb; ++e)
    if (bo[e] < 0 || bo[e + 1] < bo[e] || bo[e + 1] > mb) throw py::value_error("rtk_ins_run: bad base offsets");
  // records: epochs with a base epoch (others get no solution: status 0)
  std::vector<RtkInsRecord> recs;
  std::vector<py::ssize_t> rec_of;
  std::int64_t last_b = -1;
  for (py::ssize_t e = 0; e < E; ++e) {
    if (ro[e] < 0 || ro[e + 1] < ro[e] || ro[e + 1] > mr) throw py::value_error("rtk_ins_run: bad rover offsets");
    if (bi[e] >= nb) throw py::value_error("rtk_ins_run: base index out of range");
    if (e > 0 && !(t_rec.data()[e] > t_rec.data()[e - 1])) throw py::value_error("rtk_ins_run: t_rec not increasing");
    if (bi[e] < 0) continue;
    RtkInsRecord r;
    r.t = t_rec.data()[e];
    r.begin = ro[e];
    r.end = ro[e + 1];
    r.base_begin = bo[bi[e]];
    r.base_end = bo[bi[e] + 1];
    r.base_new = bi[e] != last_b;
    last_b = bi[e];
    recs.push_back(r);
    rec_of.push_back(e);
  }
  const py::ssize_t R = static_cast<py::ssize_t>(recs.size());
  NavBuffers nav_buf(output_rows(imu.n, cfg.output_decimation), Layout15::kSize, false);
  py::array_t<std::int32_t> status(R), n_fix(R), n_dd(R), n_sat(R), code_rej(R), screened(R), downweighted(R),
      slips({R, static_cast<py::ssize_t>(kRtkInsSlipKinds)});
  DArray ratio(R), success_rate(R), r_e({R, py::ssize_t(3)}), r_float({R, py::ssize_t(3)}), P_r({R, py::ssize_t(9)});
  RtkInsOutputs out;
  nav_buf.attach(out);
  out.status = status.mutable_data();
  out.ratio = ratio.mutable_data();
  out.success_rate = success_rate.mutable_data();
  out.n_fix = n_fix.mutable_data();
  out.n_dd = n_dd.mutable_data();
  out.n_sat = n_sat.mutable_data();
  out.code_rejected = code_rej.mutable_data();
  out.screened = screened.mutable_data();
  out.downweighted = downweighted.mutable_data();
  out.r_e = r_e.mutable_data();
  out.r_float_e = r_float.mutable_data();
  out.P_r = P_r.mutable_data();
  out.slips = slips.mutable_data();
  DArray nav_ep({R, py::ssize_t(9)});
  std::fill(nav_ep.mutable_data(), nav_ep.mutable_data() + 9 * R, NAN);
  out.nav_epoch = nav_ep.mutable_data();
  const double span = imu.n ? imu.t[imu.n - 1] - nav.t : 0.0;
  SmootherRun<Filter> smoother(smooth, R, span, cfg.outage_cycle_s);
  py::array_t<std::uint8_t> row_slip(mr);
  std::fill(row_slip.mutable_data(), row_slip.mutable_data() + mr, 0);
  out.row_slip = row_slip.mutable_data();
  // probe: the AR of one record (tests): float DD ambiguities, covariance, fixed vector, keys
  std::int64_t probe = -1;
  for (py::ssize_t i = 0; i < R; ++i)
    if (rec_of[i] == probe_epoch) probe = i;
  gnss::AmbVec p_a;
  gnss::AmbMat p_Q;
  gnss::AmbVec p_fix;
  std::vector<int> p_sj(gnss::kMaxAmbiguities), p_si(gnss::kMaxAmbiguities), p_f(gnss::kMaxAmbiguities);
  int p_n = 0;
  {
    py::gil_scoped_release release;
    auto eng = std::make_unique<Engine>(mdl, cfg);  // one allocation per run
    if (probe < 0) {
      smoother.attach(eng->core());
      eng->run(nav, P, corr, imu.n, imu.t, imu.dtheta_b, imu.dv_b, R, recs.data(), rover_rows.data(), base_rows.data(),
               rb, out);
      smoother.finish(eng->core());
    } else {
      // run up to and including the probed record, then read its AR
      eng->run(nav, P, corr, imu.n, imu.t, imu.dtheta_b, imu.dv_b, probe + 1, recs.data(), rover_rows.data(),
               base_rows.data(), rb, out);
      (void)0;
    }
    if (probe >= 0) {
      p_n = eng->last_candidates(p_sj.data(), p_si.data(), p_f.data(), gnss::kMaxAmbiguities);
      p_a = eng->ar().a_hat();
      p_Q = eng->ar().Qa();
      p_fix = eng->ar().a_fix();
    }
  }
  py::dict res;
  nav_buf.put(res, out);
  smoother.put(res);
  // per rover epoch (E): records scattered back, epochs without a base: status 0
  py::array_t<std::int32_t> st_all(E), nfix_all(E), ndd_all(E), nsat_all(E), crej_all(E), scr_all(E), dw_all(E),
      sl_all({E, static_cast<py::ssize_t>(kRtkInsSlipKinds)});
  DArray ratio_all(E), ps_all(E), re_all({E, py::ssize_t(3)}), rf_all({E, py::ssize_t(3)}), pr_all({E, py::ssize_t(9)}),
      nav_all({E, py::ssize_t(9)});
  std::fill(nav_all.mutable_data(), nav_all.mutable_data() + 9 * E, NAN);
  for (py::ssize_t e = 0; e < E; ++e) {
    st_all.mutable_data()[e] = nfix_all.mutable_data()[e] = ndd_all.mutable_data()[e] = nsat_all.mutable_data()[e] =
        crej_all.mutable_data()[e] = scr_all.mutable_data()[e] = dw_all.mutable_data()[e] = 0;
    ratio_all.mutable_data()[e] = ps_all.mutable_data()[e] = 0.0;
    for (int k = 0; k < 3; ++k) re_all.mutable_data()[3 * e + k] = rf_all.mutable_data()[3 * e + k] = NAN;
    for (int k = 0; k < 9; ++k) pr_all.mutable_data()[9 * e + k] = NAN;
    for (int k = 0; k < kRtkInsSlipKinds; ++k) sl_all.mutable_data()[kRtkInsSlipKinds * e + k] = 0;
  }
  const py::ssize_t R_done = probe >= 0 ? probe + 1 : R;
  for (py::ssize_t i = 0; i < R_done; ++i) {
    const py::ssize_t e = rec_of[i];
    st_all.mutable_data()[e] = status.data()[i];
    nfix_all.mutable_data()[e] = n_fix.data()[i];
    ndd_all.mutable_data()[e] = n_dd.data()[i];
    nsat_all.mutable_data()[e] = n_sat.data()[i];
    crej_all.mutable_data()[e] = code_rej.data()[i];
    scr_all.mutable_data()[e] = screened.data()[i];
    dw_all.mutable_data()[e] = downweighted.data()[i];
    ratio_all.mutable_data()[e] = ratio.data()[i];
    ps_all.mutable_data()[e] = success_rate.data()[i];
    for (int k = 0; k < 3; ++k) {
      re_all.mutable_data()[3 * e + k] = r_e.data()[3 * i + k];
      rf_all.mutable_data()[3 * e + k] = r_float.data()[3 * i + k];
    }
    for (int k = 0; k < 9; ++k) {
      pr_all.mutable_data()[9 * e + k] = P_r.data()[9 * i + k];
      nav_all.mutable_data()[9 * e + k] = nav_ep.data()[9 * i + k];
    }
    for (int k = 0; k < kRtkInsSlipKinds; ++k)
      sl_all.mutable_data()[kRtkInsSlipKinds * e + k] = slips.data()[kRtkInsSlipKinds * i + k];
  }
  res["status_epoch"] = st_all;
  res["ratio"] = ratio_all;
  res["success_rate"] = ps_all;
  res["n_fix"] = nfix_all;
  res["n_dd"] = ndd_all;
  res["n_sat"] = nsat_all;
  res["code_rejected"] = crej_all;
  res["screened"] = scr_all;
  res["downweighted"] = dw_all;
  res["r_e"] = re_all;
  res["r_float_e"] = rf_all;
  res["P_r_ned"] = pr_all;
  res["slips"] = sl_all;
  res["row_slip"] = row_slip;
  res["nav_epoch"] = nav_all;  // (E, 9) the INS after each epoch: lat, lon [rad], h, v_n, roll, pitch, yaw [rad]
  {  // the run's work (RtkInsCounters): AR cost, ambiguity states added / re-initialised, skipped updates
    const RtkInsCounters& c = out.counters;
    py::dict cn;
    cn["ar_epochs"] = c.ar.resolves;
    cn["lambda_calls"] = c.ar.lambda_calls;
    cn["search_nodes"] = c.ar.search_nodes;
    cn["max_search_nodes"] = c.ar.max_search_nodes;
    cn["lambda_failures"] = c.ar.lambda_failures;
    cn["amb_added"] = c.amb_added;
    cn["amb_reset"] = c.amb_reset;
    cn["update_failures"] = c.update_failures;
    res["counters"] = cn;
  }
  if (probe >= 0) {
    py::dict pr;
    const py::ssize_t n = p_n;
    DArray a(n), fx(n), Q({n, n});
    py::array_t<int> sj(n), si(n), fq(n);
    for (py::ssize_t i = 0; i < n; ++i) {
      a.mutable_data()[i] = p_a(i);
      fx.mutable_data()[i] = p_fix(i);
      sj.mutable_data()[i] = p_sj[i];
      si.mutable_data()[i] = p_si[i];
      fq.mutable_data()[i] = p_f[i];
      for (py::ssize_t j = 0; j < n; ++j) Q.mutable_data()[i * n + j] = p_Q(i, j);
    }
    pr["a_hat"] = a;
    pr["Q_a"] = Q;
    pr["a_fix"] = fx;
    pr["sat_j"] = sj;
    pr["sat_i"] = si;
    pr["freq"] = fq;
    res["probe"] = pr;
  }
  return res;
}

using RtkInsRunFn = py::dict (*)(const DArray&, const DArray&, const DArray&, const DArray&, const DArray&,
                                  const DArray&, const py::dict&, const py::dict&, const py::dict&, const DArray&,
                                  const IArray&, const DArray&, const IArray&, const DArray&, const IArray&,
                                  const DArray&, std::int64_t);
struct RtkInsFilter {
  const char* name;
  RtkInsRunFn run;
};
/// The filters of the tight RTK/INS engine (engine/rtk_ins_engine.hpp, template parameter Filter).
const RtkInsFilter kRtkInsFilters[] = {
    {"ekf", &rtk_ins_run_with<Ekf<Layout15>>},
    {"rbukf", &rtk_ins_run_with<RbUkf<Layout15>>},
    {"ukf", &rtk_ins_run_with<Ukf<Layout15>>},
};

py::dict rtk_ins_run(const DArray& t, const DArray& dtheta_b, const DArray& dv_b, const DArray& init, const DArray& P0,
                     const DArray& corr0, const py::dict& model, const py::dict& engine_cfg, const py::dict& rtk_opts,
                     const DArray& t_rec, const IArray& rover_off, const DArray& rover_rows, const IArray& base_off,
                     const DArray& base_rows, const IArray& base_index, const DArray& r_base_e,
                     std::int64_t probe_epoch, const std::string& filter) {
  std::string known;
  for (const RtkInsFilter& f : kRtkInsFilters) {
    if (filter == f.name)
      return f.run(t, dtheta_b, dv_b, init, P0, corr0, model, engine_cfg, rtk_opts, t_rec, rover_off, rover_rows,
                   base_off, base_rows, base_index, r_base_e, probe_epoch);
    known += known.empty() ? f.name : std::string(", ") + f.name;
  }
  throw py::value_error("rtk_ins_run: filter '" + filter + "' unknown (" + known + ")");
}

py::tuple dd_phase_row(const DArray& init, const DArray& lever_arm_b, const DArray& r_base_e, const DArray& rover_s,
                       const DArray& rover_i, const DArray& base_s, const DArray& base_i, int freq, bool code,
                       bool tropo) {
  const NavState s = nav_state_from(init);
  for (const DArray* a : {&rover_s, &rover_i, &base_s, &base_i})
    if (a->size() != gnss::RtkRow::kCols) throw py::value_error("dd_phase_row: rows must have RTK_ROW_COLS values");
  if (freq < 0 || freq >= gnss::kMaxFreq) throw py::value_error("dd_phase_row: freq out of range");
  DArray H(15);
  const double y = dd_row_at(s, vec3_from(lever_arm_b, "lever_arm_b"), vec3_from(r_base_e, "r_base_e"), rover_s.data(),
                             rover_i.data(), base_s.data(), base_i.data(), freq, code, tropo, H.mutable_data());
  return py::make_tuple(y, H);
}

py::tuple ambiguity_accepts(const DArray& a_hat, const DArray& Q, const DArray& a_cand, double ratio_threshold,
                            double validation_prob) {
  const py::ssize_t n = a_hat.size();
  if (n < 1 || n > gnss::kMaxAmbiguities) throw py::value_error("ambiguity_accepts: bad size");
  require_shape(Q, n, n, "ambiguity_accepts: Q");
  if (a_cand.size() != n) throw py::value_error("ambiguity_accepts: a_cand size");
  gnss::ArSettings s;
  s.ratio_threshold = ratio_threshold;
  s.min_fix = static_cast<int>(n);
  s.max_drops = 0;
  s.validation_prob = 0.0;  // resolve() finds the best vector; accepts() applies the validation
  auto ar = std::make_unique<gnss::PartialAr>();
  const bool ok = ar->resolve(
      static_cast<int>(n), [&](int p) { return a_hat.data()[p]; }, [&](int p, int q) { return Q.data()[p * n + q]; },
      gnss::ArSettings{0.0, static_cast<int>(n), 0, 0.0});
  if (!ok) throw py::value_error("ambiguity_accepts: Q not positive definite");
  gnss::AmbVec c(n);
  for (py::ssize_t i = 0; i < n; ++i) c(i) = a_cand.data()[i];
  double s_c = NAN, r_c = 0.0;
  s.validation_prob = validation_prob;
  const bool acc = ar->accepts(c, s, s_c, r_c);
  return py::make_tuple(acc, s_c, r_c);
}

}  // namespace

void bind_rtk_ins(py::module_& m) {
  m.def("rtk_ins_run", &rtk_ins_run, py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("init"), py::arg("P0"),
        py::arg("imu_correction"), py::arg("imu_model"), py::arg("config"), py::arg("rtk_options"), py::arg("t_rec"),
        py::arg("rover_off"), py::arg("rover_rows"), py::arg("base_off"), py::arg("base_rows"),
        py::arg("base_index"), py::arg("r_base_e"), py::arg("probe_epoch") = -1, py::arg("filter") = "ekf",
        "Tight RTK/INS run (Layout15 + ambiguity block; filter ekf, rbukf or ukf) with the GIL released.");
  m.def("dd_phase_row", &dd_phase_row, py::arg("init"), py::arg("lever_arm_b"), py::arg("r_base_e"),
        py::arg("rover_s"), py::arg("rover_i"), py::arg("base_s"), py::arg("base_i"), py::arg("freq"),
        py::arg("code"), py::arg("tropo") = true,
        "One DD row computed - measured (no ambiguity) at an INS state and its Jacobian over the 15 error states.");
  m.def("ambiguity_accepts", &ambiguity_accepts, py::arg("a_hat"), py::arg("Q"), py::arg("a_cand"),
        py::arg("ratio_threshold"), py::arg("validation_prob"),
        "The AR tests (ratio, validation chi2) applied to a given integer vector: (accepted, s, ratio).");
  m.attr("RTK_INS_SLIP_KINDS") = kRtkInsSlipKinds;
}

}  // namespace insnav::py_bind
