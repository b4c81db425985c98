// insnav/engine/loose_stream.hpp -- the loosely coupled batch run driven one
// block of IMU samples at a time, for a caller that reads the IMU file in
// blocks and writes the output rows as they come (`insnav run` in bounded
// memory: python/insnav/filters/stream.py).
//
// It is LooseEngine::run (loose_engine.hpp) cut into pieces: the same
// ClosedLoop::process_sample per sample, the same LooseEngine::apply_fix per
// fix, the same output countdown (every `output_decimation`-th sample, and the
// last one: finish()), so the rows and the per-fix outputs equal the batch
// run's bit for bit whatever the block boundaries are.
//
// The GNSS fixes are pushed as the run goes too (push API): the caller hands
// over a window of fixes (set_fixes: the fixes base .. base + m - 1 of the
// run, in time order) that holds at least every fix up to the last sample of
// the next block; fix g's per-fix outputs go to row g - base of the caller's
// record arrays.  After a block the caller takes the records of the fixes
// consumed (base .. consumed() - 1) and hands over the next window starting
// at consumed(), so neither the fixes nor their records grow with the run.
// Given all fixes at once (base 0) it is the batch run's whole table.
//
// Memory: nothing is allocated here; the rows of a block go to caller-owned
// buffers (NavOutputs, n_out reset by the caller per block), the per-fix
// outputs to caller-owned arrays of the window's size.  The object is large
// (the filter's fixed-size matrices): allocate it once.
#pragma once

#include <cstdint>

#include "insnav/engine/loose_engine.hpp"

namespace insnav {

template <class Filter>
class LooseStream {
 public:
  using L = typename Filter::Layout;

  /// initial is valid at initial.t (< the first sample's time); `fixes` (m,
  /// sorted by time, caller-owned, alive until the next set_fixes) and
  /// `records` (its per-fix arrays of m rows and counters) as
  /// LooseEngine::run's: the whole table, or the first window (base 0).
  LooseStream(const ImuErrorModel& model, const LooseConfig& cfg, const UtParams& ut, const NavState& initial,
              const StateCov<L>& P0, const ImuCorrection& corr0, std::int64_t m, const GnssFix* fixes,
              LooseOutputs& records)
      : engine_(model, cfg, ut), cfg_(cfg), rec_(records) {
    engine_.start(initial, P0, corr0);
    t_prev_ = initial.t;
    until_output_ = decimation();
    set_fixes(0, m, fixes);
  }

  /// The window of fixes base .. base + m - 1 (sorted by time, caller-owned,
  /// alive until the next call; base <= consumed() <= base + m), their
  /// records at rows 0 .. m - 1 of the record arrays from now on.  Before the
  /// first sample, the fixes at or before the initial time are marked
  /// outside the IMU span (as LooseEngine::run marks them).
  void set_fixes(std::int64_t base, std::int64_t m, const GnssFix* fixes) {
    base_ = base;
    end_ = base + m;
    fixes_ = fixes;
    if (samples_ > 0) return;
    ClosedLoop<Filter>& core = engine_.core();
    while (g_ < end_ && !(core.record_time(fix(g_).t) > t_prev_))
      rec_.mark(g_++ - base_, RecordStatus::kOutsideImuSpan);
  }

  /// The next n samples (t (n,), dtheta_b (n,3), dv_b (n,3), row-major): their
  /// rows appended to `rows` (at most n / output_decimation + 1 of them).
  void run_block(std::int64_t n, const double* t, const double* dtheta_b, const double* dv_b, NavOutputs& rows) {
    ClosedLoop<Filter>& core = engine_.core();
    const int dec = decimation();
    for (std::int64_t k = 0; k < n; ++k) {
      const ImuIncrement raw = raw_imu_sample(k, t_prev_, t, dtheta_b, dv_b);
      core.process_sample(
          raw, t_prev_, cfg_.cycle_period, [&]() { return g_ < end_ ? core.record_time(fix(g_).t) : kInf; },
          [&]() {
            engine_.apply_fix(fix(g_), g_ - base_, rec_);
            ++g_;
          });
      if (--until_output_ == 0) {
        core.write_output(rows);
        until_output_ = dec;
      }
      t_prev_ = raw.t;
      ++samples_;
    }
  }

  /// The end of the IMU stream: the last sample's row (when the countdown
  /// did not write it; returns whether a row was written), the fixes left in
  /// the window (the caller's last window holds every fix after the last
  /// sample) marked outside the IMU span, the counters.
  bool finish(NavOutputs& rows) {
    bool wrote = false;
    if (samples_ > 0 && until_output_ != decimation()) {
      engine_.core().write_output(rows);
      wrote = true;
    }
    for (; g_ < end_; ++g_) rec_.mark(g_ - base_, RecordStatus::kOutsideImuSpan);
    rec_.cholesky_repairs = engine_.core().filter.cholesky_repairs();
    rec_.gate_reopened = engine_.core().gate.reopened();
    rec_.gate_outage_accepted = engine_.core().gate.outage_accepted();
    return wrote;
  }

  std::int64_t samples() const { return samples_; }
  double t_last() const { return t_prev_; }  // the last sample's time (the initial time before any) [s]
  std::int64_t consumed() const { return g_; }  // the fixes applied or marked so far (their records are final)

 private:
  int decimation() const { return cfg_.output_decimation > 0 ? cfg_.output_decimation : 1; }
  const GnssFix& fix(std::int64_t g) const { return fixes_[g - base_]; }

  LooseEngine<Filter> engine_;
  LooseConfig cfg_;
  const GnssFix* fixes_ = nullptr;
  std::int64_t base_ = 0, end_ = 0, g_ = 0, samples_ = 0;  // the window [base_, end_), the next fix g_
  LooseOutputs& rec_;
  double t_prev_ = 0.0;
  int until_output_ = 1;
};

}  // namespace insnav
