// _core.LooseStream: the loosely coupled run fed one block of IMU samples at a
// time (engine/loose_stream.hpp), for `insnav run` in bounded memory
// (python/insnav/filters/stream.py).  Two row buffers of one block each are
// allocated once, at construction (capacity: the largest block), and used in
// turn: each run_block fills the next one with the GIL released and returns
// the row count; the arrays of rows() are views of the buffer just filled,
// valid until the next-but-one call (a writer thread may format block i
// while block i + 1 is filtered, without a copy).  The GNSS fixes are pushed
// as the run goes (push_gnss) and the per-fix records of the fixes consumed
// taken after each block (take_records): the stream holds a window of the
// fixes not yet consumed and their record rows, which grows only with the
// fixes of one block (max_window, for the tests), never with the run.
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "insnav/engine/loose_stream.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "loose_run.hpp"

namespace insnav::py_bind {

namespace {

/// The filter/layout-independent interface.
struct StreamBase {
  virtual ~StreamBase() = default;
  virtual void run_block(std::int64_t n, const double* t, const double* dth, const double* dv, NavOutputs& rows) = 0;
  virtual bool finish(NavOutputs& rows) = 0;
  virtual std::int64_t samples() const = 0;
  virtual double t_last() const = 0;
  virtual std::int64_t consumed() const = 0;
  virtual void set_fixes(std::int64_t base, std::int64_t m, const GnssFix* fixes) = 0;
};

template <class Filter>
struct StreamImpl final : StreamBase {
  LooseStream<Filter> s;
  template <class... A>
  explicit StreamImpl(A&&... a) : s(std::forward<A>(a)...) {}
  void run_block(std::int64_t n, const double* t, const double* dth, const double* dv, NavOutputs& rows) override {
    s.run_block(n, t, dth, dv, rows);
  }
  bool finish(NavOutputs& rows) override { return s.finish(rows); }
  std::int64_t samples() const override { return s.samples(); }
  double t_last() const override { return s.t_last(); }
  std::int64_t consumed() const override { return s.consumed(); }
  void set_fixes(std::int64_t base, std::int64_t m, const GnssFix* fixes) override { s.set_fixes(base, m, fixes); }
};

/// The stream object Python holds: the engine, the window of fixes (those
/// not yet consumed: fixes[i] is the run's fix base + i), their per-fix
/// output rows and the row buffers of one block.
struct PyLooseStream {
  std::vector<GnssFix> fixes;
  std::int64_t base = 0;        // the run's index of fixes[0]
  std::int64_t max_window = 0;  // the most fixes the window held (bounded by the fixes of a block)
  LooseRecordBuffers rec;       // rows 0 .. capacity - 1: the records of fixes[0 ..]
  py::ssize_t rec_capacity;
  LooseOutputs rec_out;
  NavBuffers rows[2];  // used in turn
  int cur = 1;         // the buffer of the last call
  NavOutputs rows_out;
  py::ssize_t capacity;
  std::unique_ptr<StreamBase> impl;
  bool finished = false;

  PyLooseStream(py::ssize_t m, py::ssize_t cap, int sigma_cols)
      : fixes(m), max_window(m), rec(m), rec_capacity(m),
        rows{NavBuffers(cap + 1, sigma_cols, false), NavBuffers(cap + 1, sigma_cols, false)}, capacity(cap) {}

  /// Fixes (n, 13) appended to the window (the record rows grown when they are too few: the rows
  /// already written kept).
  void push(const DArray& gnss) {
    const py::ssize_t n = gnss.ndim() == 2 ? gnss.shape(0) : 0;
    if (n > 0) require_shape(gnss, n, 13, "gnss");
    const std::size_t m0 = fixes.size();
    fixes.resize(m0 + static_cast<std::size_t>(n));
    for (py::ssize_t i = 0; i < n; ++i) fixes[m0 + i] = gnss_fix_from(gnss.data()[13 * i], gnss.data() + 13 * i + 1);
    const auto m = static_cast<py::ssize_t>(fixes.size());
    max_window = std::max<std::int64_t>(max_window, m);
    if (m > rec_capacity) {
      const py::ssize_t cap = std::max(m, 2 * rec_capacity);
      LooseRecordBuffers grown(cap);
      const py::ssize_t k = impl ? static_cast<py::ssize_t>(impl->consumed() - base) : 0;  // rows written
      std::copy_n(rec.innovation.data(), 6 * k, grown.innovation.mutable_data());
      std::copy_n(rec.nis.data(), k, grown.nis.mutable_data());
      std::copy_n(rec.log_det_s.data(), k, grown.log_det_s.mutable_data());
      std::copy_n(rec.meas_sigma.data(), 6 * k, grown.meas_sigma.mutable_data());
      std::copy_n(rec.status.data(), k, grown.status.mutable_data());
      rec = std::move(grown);
      rec_capacity = cap;
      rec.attach(rec_out, cap);
    }
    if (impl) impl->set_fixes(base, m, fixes.data());
  }

  /// The records of the fixes consumed since the last call (copies, in time order) and `first`, the
  /// run's index of the first of them; the window then starts at the first fix not consumed.
  py::dict take() {
    const auto k = static_cast<py::ssize_t>(impl->consumed() - base);
    DArray innovation({k, py::ssize_t(6)}), nis({k}), log_det_s({k}), meas_sigma({k, py::ssize_t(6)});
    py::array_t<std::int8_t> status({k});
    std::copy_n(rec.innovation.data(), 6 * k, innovation.mutable_data());
    std::copy_n(rec.nis.data(), k, nis.mutable_data());
    std::copy_n(rec.log_det_s.data(), k, log_det_s.mutable_data());
    std::copy_n(rec.meas_sigma.data(), 6 * k, meas_sigma.mutable_data());
    std::copy_n(rec.status.data(), k, status.mutable_data());
    py::dict d;
    d["first"] = base;
    d["innovation"] = innovation;
    d["nis"] = nis;
    d["log_det_s"] = log_det_s;
    d["meas_sigma"] = meas_sigma;
    d["status"] = status;
    // the rows of the fixes left move to the front (none is written yet: a fix's record is written when
    // it is consumed); the rows reused start as fresh ones (log_det_s and meas_sigma NaN)
    std::fill_n(rec.log_det_s.mutable_data(), rec_capacity, NAN);
    std::fill_n(rec.meas_sigma.mutable_data(), 6 * rec_capacity, NAN);
    fixes.erase(fixes.begin(), fixes.begin() + k);
    base += k;
    impl->set_fixes(base, static_cast<std::int64_t>(fixes.size()), fixes.data());
    return d;
  }

  /// The next row buffer, empty.
  NavOutputs& next_rows() {
    cur ^= 1;
    NavBuffers& b = rows[cur];
    rows_out = NavOutputs();
    rows_out.t = b.t.mutable_data();
    rows_out.llh = b.llh.mutable_data();
    rows_out.v_n = b.v_n.mutable_data();
    rows_out.rpy = b.rpy.mutable_data();
    rows_out.sigma = b.sigma.mutable_data();
    rows_out.sigma_cols = static_cast<int>(b.sigma.shape(1));
    rows_out.imu_err = b.imu_err.mutable_data();
    return rows_out;
  }
};

template <class Filter>
std::unique_ptr<StreamBase> make(const ImuErrorModel& model, const LooseConfig& cfg, const UtParams& ut,
                                 const NavState& s0, const DArray& P0, const ImuCorrection& c0, PyLooseStream& ps) {
  if (cfg.adaptive_r.window > 0 && !kJacobianUpdate<Filter>)
    throw py::value_error("adaptive_r_window > 0: the EKF and the RB-UKF only (it needs the update's H P H^T)");
  if (cfg.adaptive_q.window > 0 && !kScalableQ<Filter>)
    throw py::value_error("adaptive_q_window > 0: the EKF only (it scales the EKF's process noise)");
  return std::make_unique<StreamImpl<Filter>>(model, cfg, ut, s0, state_cov_from<typename Filter::Layout>(P0), c0,
                                              static_cast<std::int64_t>(ps.fixes.size()), ps.fixes.data(),
                                              ps.rec_out);
}

std::unique_ptr<StreamBase> make_stream(const std::string& filter, int layout, const ImuErrorModel& model,
                                        const LooseConfig& cfg, const UtParams& ut, const NavState& s0,
                                        const DArray& P0, const ImuCorrection& c0, PyLooseStream& ps) {
  if (filter == "ekf") {
    if (layout == 15) return make<Ekf<Layout15>>(model, cfg, ut, s0, P0, c0, ps);
    if (layout == 21) return make<Ekf<Layout21>>(model, cfg, ut, s0, P0, c0, ps);
  } else if (filter == "rbukf") {
    if (layout == 15) return make<RbUkf<Layout15>>(model, cfg, ut, s0, P0, c0, ps);
    if (layout == 21) return make<RbUkf<Layout21>>(model, cfg, ut, s0, P0, c0, ps);
  } else if (filter == "ukf") {
    if (layout == 15) return make<Ukf<Layout15>>(model, cfg, ut, s0, P0, c0, ps);
    if (layout == 21) return make<Ukf<Layout21>>(model, cfg, ut, s0, P0, c0, ps);
  }
  throw py::value_error("LooseStream: unsupported filter/layout combination " + filter + "/" +
                        std::to_string(layout) + " (ekf, rbukf, ukf on 15 or 21 states)");
}

}  // namespace

void bind_loose_stream(py::module_& m) {
  py::class_<PyLooseStream> c(m, "LooseStream",
                              "The loose run fed block by block (engine/loose_stream.hpp); "
                              "used by insnav.filters.stream.");
  c.def(py::init([](const std::string& filter, int layout, const DArray& gnss, const DArray& init, const DArray& P0,
                    const DArray& corr0, const py::dict& model, const py::dict& config, py::ssize_t block_samples) {
          const ImuErrorModel mdl = imu_model_from_dict(model);
          const LooseConfig cfg = loose_run_config_from(config);
          if (selfcal_from(config).any() || flag(config, "smooth", false))
            throw py::value_error("LooseStream: the self-calibration states and the smoother run in the batch "
                                  "engine (insnav.run)");
          const UtParams ut = ut_from(config);
          if (block_samples < 1) throw py::value_error("LooseStream: block_samples must be >= 1");
          const py::ssize_t m = gnss.ndim() == 2 ? gnss.shape(0) : 0;
          if (m > 0) require_shape(gnss, m, 13, "gnss");
          const int ns = layout;
          const int sc = static_cast<int>(num(config, "sigma_columns", 0));
          const int n_sig = (sc > 0 && sc < ns) ? sc : ns;
          auto ps = std::make_unique<PyLooseStream>(m, block_samples, n_sig);
          for (py::ssize_t i = 0; i < m; ++i)
            ps->fixes[i] = gnss_fix_from(gnss.data()[13 * i], gnss.data() + 13 * i + 1);
          ps->rec.attach(ps->rec_out, m);
          ps->impl = make_stream(filter, layout, mdl, cfg, ut, nav_state_from(init), P0, imu_correction_from(corr0),
                                 *ps);
          return ps;
        }),
        py::arg("filter"), py::arg("layout"), py::arg("gnss"), py::arg("init"), py::arg("P0"),
        py::arg("imu_correction"), py::arg("imu_model"), py::arg("config"), py::arg("block_samples"));
  c.def(
      "run_block",
      [](PyLooseStream& ps, const DArray& t, const DArray& dtheta_b, const DArray& dv_b) {
        if (ps.finished) throw py::value_error("LooseStream.run_block after finish()");
        const ImuArrays imu = imu_arrays(t, dtheta_b, dv_b);
        if (imu.n > ps.capacity)
          throw py::value_error("LooseStream.run_block: " + std::to_string(imu.n) + " samples exceed block_samples " +
                                std::to_string(ps.capacity));
        NavOutputs& rows = ps.next_rows();
        {
          py::gil_scoped_release release;
          ps.impl->run_block(imu.n, imu.t, imu.dtheta_b, imu.dv_b, rows);
        }
        return rows.n_out;
      },
      py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"),
      "Run the next samples; returns the rows written (rows() until the next call).");
  c.def("finish",
        [](PyLooseStream& ps) {
          NavOutputs& rows = ps.next_rows();
          ps.impl->finish(rows);
          ps.finished = true;
          return rows.n_out;
        },
        "End of the IMU stream: the last sample's row when not yet written (0 or 1 rows).");
  c.def(
      "rows",
      [](PyLooseStream& ps) {
        py::dict d;
        const py::slice r(0, ps.rows_out.n_out, 1);
        NavBuffers& b = ps.rows[ps.cur];
        d["t"] = b.t[r];
        d["llh"] = b.llh[r];
        d["v_n"] = b.v_n[r];
        d["rpy"] = b.rpy[r];
        d["sigma"] = b.sigma[r];
        d["imu_err"] = b.imu_err[r];
        return d;
      },
      "The rows of the last run_block / finish (radians, SI): views of its row buffer, valid until the "
      "next-but-one call.");
  c.def(
      "push_gnss", [](PyLooseStream& ps, const DArray& gnss) { ps.push(gnss); }, py::arg("gnss"),
      "Append fixes (n, 13; the same rows as the constructor's gnss, in time order, after those given) "
      "to the window: it must hold every fix up to the last sample of the next run_block.");
  c.def("take_records", [](PyLooseStream& ps) { return ps.take(); },
        "The per-fix records (innovation (k,6), nis, log_det_s, meas_sigma (k,6), status) of the fixes "
        "consumed since the last call, and 'first': the run's index of the first of them.");
  c.def_property_readonly("max_window", [](const PyLooseStream& ps) { return ps.max_window; },
                          "The most fixes the window held (its record rows: at least as many).");
  c.def("records",
        [](PyLooseStream& ps) {
          py::dict d = ps.take();
          d["updates"] = ps.rec_out.updates;
          d["rejected"] = ps.rec_out.rejected;
          d["gate_reopened"] = ps.rec_out.gate_reopened;
          d["gate_outage_accepted"] = ps.rec_out.gate_outage_accepted;
          d["cholesky_repairs"] = ps.rec_out.cholesky_repairs;
          return d;
        },
        "The records of the fixes not yet taken (take_records) and the counters (after finish()): the whole "
        "table when none was taken.");
  c.def_property_readonly("samples", [](const PyLooseStream& ps) { return ps.impl->samples(); });
  c.def_property_readonly("t_last", [](const PyLooseStream& ps) { return ps.impl->t_last(); });
}

}  // namespace insnav::py_bind
