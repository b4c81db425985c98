// The RTS smoother around one engine run (config key 'smooth'), shared by the
// loose (loose_run.hpp) and tight (tight_run.hpp) runs: the epoch buffers
// sized once per run, the forward record attached to the engine's closed-loop
// core, the backward pass (filter/rts_smoother.hpp) and its result arrays.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "common.hpp"
#include "insnav/engine/closed_loop.hpp"
#include "insnav/engine/smoothed_rows.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/rts_smoother.hpp"

namespace insnav::py_bind {

/// Storage for n objects of T, not initialized (aligned for T; T trivially destructible).
template <class T>
class RawBuffer {
 public:
  void allocate(std::int64_t n) {
    const std::size_t a = alignof(T) < alignof(std::max_align_t) ? alignof(std::max_align_t) : alignof(T);
    const std::size_t bytes = ((static_cast<std::size_t>(std::max<std::int64_t>(n, 1)) * sizeof(T) + a - 1) / a) * a;
    p_.reset(static_cast<T*>(std::aligned_alloc(a, bytes)));
    if (!p_) throw std::bad_alloc();
    n_ = n;
  }
  T* data() const { return p_.get(); }
  std::int64_t size() const { return n_; }
  const T& operator[](std::int64_t i) const { return p_.get()[i]; }

 private:
  struct Free {
    void operator()(T* p) const { std::free(p); }
  };
  std::unique_ptr<T, Free> p_;
  std::int64_t n_ = 0;
};

template <class Filter>
class SmootherRun {
 public:
  using L = typename Filter::Layout;
  static constexpr int kN = L::kSize;
  /// The EKF (cycle transition) and the RB-UKF / UKF (UT cross-covariance, the unscented RTS smoother).
  static constexpr bool kSupported =
      std::is_same_v<Filter, Ekf<L>> || std::is_base_of_v<UnscentedPropagation<L>, Filter>;

  /// With the GIL held.  `records`: measurement records and events that close
  /// a cycle; `span_s` / `cycle_period_s`: the outage cycles at most.
  SmootherRun(bool on, std::int64_t records, double span_s, double cycle_period_s) : on_(on) {
    if (!on_) return;
    if (!kSupported) throw py::value_error("smooth: the RTS smoother runs with the EKF, RB-UKF and UKF");
    const std::int64_t cap =
        records + static_cast<std::int64_t>(std::ceil(std::max(span_s, 0.0) / cycle_period_s)) + 16;
    // once per run, not initialized: the core constructs each epoch it records, and the pages of
    // the capacity never used (the bound counts every outage cycle) are never touched
    fwd_.allocate(cap);
  }

  bool on() const { return on_; }

  /// Before the engine's run (GIL released or not).
  void attach(ClosedLoop<Filter>& core) {
    if (on_) core.record_for_smoother(fwd_.data(), static_cast<std::int64_t>(fwd_.size()));
  }

  /// After the run: the backward pass (no GIL needed).
  void finish(const ClosedLoop<Filter>& core) {
    if (!on_) return;
    if (core.recording_overflowed()) throw std::runtime_error("smoother: epoch buffer overflow");
    n_ = core.recorded_epochs();
    bwd_.resize(static_cast<std::size_t>(n_));
    status_ = rts_backward<L>(fwd_.data(), n_, bwd_.data());
  }

  /// The result arrays (GIL held), per epoch k (E rows; n columns: the layout's states):
  ///   smooth_t (E,), smooth_fed (E,) x_k fed back, smooth_s (E, n) s_k, smooth_sigma (E, n) sqrt(diag Ps_k),
  ///   smooth_P_att (E, 3, 3) Ps_k's attitude (psi) block, for the rows' Euler-angle sigmas;
  ///   the corrections of the output rows (engine/smoothed_rows.hpp smoothed_row_errors): smooth_d (E, n)
  ///   for the rows from epoch k on, smooth_d_end (E, n) for the rows just before it; smooth_gain_failures.
  void put(py::dict& res) const {
    if (!on_) return;
    const py::ssize_t E = n_, n = kN;
    DArray o_et({E}), o_s({E, n}), o_d({E, n}), o_de({E, n}), o_ss({E, n}), o_pa({E, py::ssize_t(3), py::ssize_t(3)});
    py::array_t<std::int8_t> o_fed({E});
    double *et = o_et.mutable_data(), *s = o_s.mutable_data(), *d = o_d.mutable_data(), *de = o_de.mutable_data(),
           *ss = o_ss.mutable_data(), *pa = o_pa.mutable_data();
    std::int8_t* fed = o_fed.mutable_data();
    for (std::int64_t i = 0; i < n_; ++i) {
      const SmootherEpoch<L>& f = fwd_[i];
      const SmoothedEpoch<L>& b = bwd_[i];
      et[i] = f.t;
      fed[i] = f.fed_back ? 1 : 0;
      smoothed_row_errors<L>(f, b, i > 0, d + i * kN, de + i * kN);
      for (int j = 0; j < kN; ++j) {
        const std::int64_t ij = i * kN + j;
        s[ij] = b.s[j];
        ss[ij] = std::sqrt(std::max(b.P(j, j), 0.0));
      }
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) pa[9 * i + 3 * r + c] = b.P(L::kAtt + r, L::kAtt + c);
    }
    res["smooth_t"] = o_et;
    res["smooth_fed"] = o_fed;
    res["smooth_s"] = o_s;
    res["smooth_d"] = o_d;
    res["smooth_d_end"] = o_de;
    res["smooth_sigma"] = o_ss;
    res["smooth_P_att"] = o_pa;
    res["smooth_gain_failures"] = status_.gain_failures;
  }

 private:
  bool on_ = false;
  static_assert(std::is_trivially_destructible_v<SmootherEpoch<L>>);
  RawBuffer<SmootherEpoch<L>> fwd_;
  std::vector<SmoothedEpoch<L>> bwd_;
  std::int64_t n_ = 0;
  SmootherStatus status_;
};

}  // namespace insnav::py_bind
