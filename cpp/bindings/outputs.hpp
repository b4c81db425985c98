// Core -> Python: the numpy arrays behind NavOutputs (the per-sample rows
// every engine writes) and their result-dict entries, shared by every binder.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "common.hpp"
#include "insnav/engine/closed_loop.hpp"
#include "insnav/engine/tight_engine.hpp"

namespace insnav::py_bind {

/// Rows an engine writes at most: every decimation-th of n samples, the last, and slack of one.
inline py::ssize_t output_rows(py::ssize_t n, int decimation) { return (n + decimation - 1) / decimation + 1; }

/// The progress callable of the runs (None: none), set by _core.set_progress.
inline PyObject*& progress_hook() {
  static PyObject* hook = nullptr;  // a strong reference, never released at exit
  return hook;
}

/// The NavOutputs poll of a run from Python: called every kPollSamples
/// samples, it takes the GIL at most every kPollPeriod (a clock read
/// otherwise) for PyErr_CheckSignals (Ctrl-C) and the progress callable (k, n).
struct PyPoll {
  static constexpr std::int64_t kPollSamples = 256;
  static constexpr std::chrono::milliseconds kPollPeriod{20};
  py::object progress;
  bool failed = false;
  std::chrono::steady_clock::time_point last{};

  static bool call(void* ctx, std::int64_t k, std::int64_t n) {
    auto* self = static_cast<PyPoll*>(ctx);
    const auto now = std::chrono::steady_clock::now();
    if (now - self->last < kPollPeriod) return true;
    self->last = now;
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) {
      self->failed = true;
      return false;
    }
    if (self->progress) {
      PyObject* r = PyObject_CallFunction(self->progress.ptr(), "LL", static_cast<long long>(k),
                                          static_cast<long long>(n));
      if (!r) {
        self->failed = true;
        return false;
      }
      Py_DECREF(r);
    }
    return true;
  }
};

/// Arrays for n_out per-sample rows: t, llh, v_n, rpy, sigma (sigma_cols), imu_err, and clock, ISBs and the
/// odometer scale factor (estimate, sigma) if asked.
struct NavBuffers {
  DArray t, llh, v_n, rpy, sigma, imu_err, clock, isb, odo_scale, time_offset, lever_arm, odo_lever;
  bool with_clock, with_isb, with_odo_scale, with_time_offset, with_lever_arm, with_odo_lever;
  PyPoll poll;

  NavBuffers(py::ssize_t n_out, int sigma_cols, bool with_clock_, bool with_isb_ = false, bool with_odo_scale_ = false,
             bool with_time_offset_ = false, bool with_lever_arm_ = false, bool with_odo_lever_ = false)
      : t({n_out}), llh({n_out, py::ssize_t(3)}), v_n({n_out, py::ssize_t(3)}), rpy({n_out, py::ssize_t(3)}),
        sigma({n_out, py::ssize_t(sigma_cols)}), imu_err({n_out, py::ssize_t(12)}),
        clock({with_clock_ ? n_out : py::ssize_t(0), py::ssize_t(2)}),
        isb({with_isb_ ? n_out : py::ssize_t(0), py::ssize_t(3)}),
        odo_scale({with_odo_scale_ ? n_out : py::ssize_t(0), py::ssize_t(2)}),
        time_offset({with_time_offset_ ? n_out : py::ssize_t(0), py::ssize_t(2)}),
        lever_arm({with_lever_arm_ ? n_out : py::ssize_t(0), py::ssize_t(6)}),
        odo_lever({with_odo_lever_ ? n_out : py::ssize_t(0), py::ssize_t(6)}), with_clock(with_clock_),
        with_isb(with_isb_), with_odo_scale(with_odo_scale_), with_time_offset(with_time_offset_),
        with_lever_arm(with_lever_arm_), with_odo_lever(with_odo_lever_) {}

  void attach(NavOutputs& out) {
    if (progress_hook()) poll.progress = py::reinterpret_borrow<py::object>(progress_hook());
    out.poll = &PyPoll::call;
    out.poll_ctx = &poll;
    out.poll_every = PyPoll::kPollSamples;
    out.t = t.mutable_data();
    out.llh = llh.mutable_data();
    out.v_n = v_n.mutable_data();
    out.rpy = rpy.mutable_data();
    out.sigma = sigma.mutable_data();
    out.sigma_cols = static_cast<int>(sigma.shape(1));
    out.imu_err = imu_err.mutable_data();
    out.clock = with_clock ? clock.mutable_data() : nullptr;
    out.isb = with_isb ? isb.mutable_data() : nullptr;
    out.odo_scale = with_odo_scale ? odo_scale.mutable_data() : nullptr;
    out.time_offset = with_time_offset ? time_offset.mutable_data() : nullptr;
    out.lever_arm = with_lever_arm ? lever_arm.mutable_data() : nullptr;
    out.odo_lever = with_odo_lever ? odo_lever.mutable_data() : nullptr;
  }

  /// The rows written and the run counters into res.
  void put(py::dict& res, const NavOutputs& out) const {
    if (poll.failed) throw py::error_already_set();  // KeyboardInterrupt, or the progress callable's error
    const py::slice rows(0, out.n_out, 1);
    res["t"] = t[rows];
    res["llh"] = llh[rows];
    res["v_n"] = v_n[rows];
    res["rpy"] = rpy[rows];
    res["sigma"] = sigma[rows];
    res["imu_err"] = imu_err[rows];
    if (with_clock) res["clock"] = clock[rows];
    if (with_isb) res["isb"] = isb[rows];
    if (with_odo_scale) res["odo_scale"] = odo_scale[rows];  // (., 2): s [-], its 1-sigma [-]
    if (with_time_offset) res["time_offset"] = time_offset[rows];  // (., 2): t_d [s], its 1-sigma [s]
    if (with_lever_arm) res["lever_arm"] = lever_arm[rows];        // (., 6): l_b [m], its 1-sigma [m]
    if (with_odo_lever) res["odo_lever"] = odo_lever[rows];        // (., 6): odometer lever arm [m], 1-sigma [m]
    res["updates"] = out.updates;
    res["rejected"] = out.rejected;
    res["gate_reopened"] = out.gate_reopened;
    res["gate_outage_accepted"] = out.gate_outage_accepted;
    res["cholesky_repairs"] = out.cholesky_repairs;
  }
};

/// Per loose record (m rows): innovation (m, 6), nis, status.
/// Outputs with a meas_sigma buffer (LooseOutputs; the delay engines' have none).
template <class Out, class = void>
struct HasMeasSigma : std::false_type {};
template <class Out>
struct HasMeasSigma<Out, std::void_t<decltype(std::declval<Out&>().meas_sigma)>> : std::true_type {};

struct LooseRecordBuffers {
  DArray innovation, nis, log_det_s, meas_sigma;
  py::array_t<std::int8_t> status;

  explicit LooseRecordBuffers(py::ssize_t m)
      : innovation({m, py::ssize_t(6)}), nis({m}), log_det_s({m}), meas_sigma({m, py::ssize_t(6)}), status({m}) {
    std::fill_n(log_det_s.mutable_data(), m, NAN);  // engines that do not write it (delay filters)
    std::fill_n(meas_sigma.mutable_data(), 6 * m, NAN);
  }

  template <class Out>
  void attach(Out& out, py::ssize_t m) {
    out.innovation = m ? innovation.mutable_data() : nullptr;
    out.nis = m ? nis.mutable_data() : nullptr;
    out.log_det_s = m ? log_det_s.mutable_data() : nullptr;
    if constexpr (HasMeasSigma<Out>::value) out.meas_sigma = m ? meas_sigma.mutable_data() : nullptr;
    out.status = m ? status.mutable_data() : nullptr;
  }

  void put(py::dict& res) const {
    res["innovation"] = innovation;
    res["nis"] = nis;
    res["log_det_s"] = log_det_s;
    res["meas_sigma"] = meas_sigma;
    res["status"] = status;
  }
};

/// Per tight epoch (E) and satellite row (M): sat_residual (M, 2), sat_flag (M, 2), nis, status, rows,
/// clock_jump; and the robust step's counters.
struct TightRecordBuffers {
  DArray sat_residual, nis, clock_jump, tdcp_residual, log_det_s;
  py::array_t<std::int8_t> status, sat_flag, tdcp_flag;
  py::array_t<std::int32_t> rows, tdcp_rows;
  py::ssize_t E, M;

  TightRecordBuffers(py::ssize_t E_, py::ssize_t M_)
      : sat_residual({M_, py::ssize_t(2)}), nis({E_}), clock_jump({E_}), tdcp_residual({M_}), log_det_s({E_}),
        status({E_}), sat_flag({M_, py::ssize_t(2)}), tdcp_flag({M_}), rows({E_}), tdcp_rows({E_}), E(E_), M(M_) {
    std::fill_n(log_det_s.mutable_data(), E_, NAN);  // engines that do not write it (particle filters)
  }

  template <class Out>
  void attach(Out& out) {
    out.sat_residual = M ? sat_residual.mutable_data() : nullptr;
    out.sat_flag = M ? sat_flag.mutable_data() : nullptr;
    out.nis = E ? nis.mutable_data() : nullptr;
    out.log_det_s = E ? log_det_s.mutable_data() : nullptr;
    out.status = E ? status.mutable_data() : nullptr;
    out.rows = E ? rows.mutable_data() : nullptr;
    out.clock_jump = E ? clock_jump.mutable_data() : nullptr;
    out.tdcp_residual = M ? tdcp_residual.mutable_data() : nullptr;  // TDCP rows (meas/tdcp.hpp)
    out.tdcp_flag = M ? tdcp_flag.mutable_data() : nullptr;
    out.tdcp_rows = E ? tdcp_rows.mutable_data() : nullptr;
  }

  template <class Out>
  void put(py::dict& res, const Out& out) const {
    res["sat_residual"] = sat_residual;
    res["sat_flag"] = sat_flag;
    res["nis"] = nis;
    res["log_det_s"] = log_det_s;
    res["status"] = status;
    res["rows"] = rows;
    res["clock_jump"] = clock_jump;
    res["rejected_sats"] = out.rejected_sats;
    res["fde_excluded"] = out.fde_excluded;
    res["cusum_alarms"] = out.cusum_alarms;
    res["cusum_excluded"] = out.cusum_excluded;
    res["variance_inflated"] = py::make_tuple(out.variance_inflated[0], out.variance_inflated[1]);
    res["downweighted_sats"] = out.downweighted_sats;
    res["flagged_epochs"] = out.flagged_epochs;
    res["clock_jumps"] = out.clock_jumps;
    res["tdcp_residual"] = tdcp_residual;
    res["tdcp_flag"] = tdcp_flag;
    res["tdcp_rows"] = tdcp_rows;
    res["tdcp_used"] = out.tdcp_used;
    res["tdcp_rejected"] = out.tdcp_rejected;
    res["tdcp_slips_lli"] = out.tdcp_slips_lli;
    res["tdcp_slips_ins"] = out.tdcp_slips_ins;
    res["tdcp_updates"] = out.tdcp_updates;
  }
};

}  // namespace insnav::py_bind
