// Delayed GNSS (seed 001): random-delay KF reduces to the EKF for p = [1];
// the stack shift; the time-tagged engine equals LooseEngine with zero delay
// and, with delays, ends in the state LooseEngine reaches with all records on
// time; records older than the history are refused and counted; no heap
// allocation inside run(); the push API of the random-delay KF
// (navigator.hpp DelayNavigator) gives the batch rows bit for bit.
#include <cstdio>
#include <memory>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/core.hpp"
#include "insnav/engine/delay_engine.hpp"
#include "insnav/engine/loose_engine.hpp"
#include "insnav/engine/navigator.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/random_delay_kf.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

constexpr double kLat = 0.53, kLon = 2.0, kH = 20.0;

/// A level vehicle heading north at constant speed v on a slowly turning
/// path is too much for a unit test; a stationary one with biased sensors and
/// GNSS fixes at the truth plus deterministic "noise" is enough to exercise
/// every path (equality tests do not need realism).
struct Data {
  std::vector<double> t, dth, dv;
  std::vector<GnssFix> fixes;
  std::vector<double> t_arr, epochs;
  NavState init;
};

Data make_data(double T, const std::vector<int>& delays) {
  Data d;
  const double dt = 0.01;
  const int n = static_cast<int>(T / dt + 0.5);
  const Vec3 w_b = wgs84::omega_ie_n(kLat) + Vec3(2e-5, -1e-5, 3e-5);  // level, north: b = n
  const Vec3 f_b = Vec3(0.0, 0.0, -wgs84::gravity(kLat, kH)) + Vec3(3e-3, -2e-3, 1e-3);
  for (int k = 1; k <= n; ++k) {
    d.t.push_back(k * dt);
    for (int j = 0; j < 3; ++j) {
      d.dth.push_back(w_b[j] * dt);
      d.dv.push_back(f_b[j] * dt);
    }
  }
  d.init.t = 0.0;
  d.init.lat = kLat;
  d.init.lon = kLon;
  d.init.h = kH;
  const wgs84::Radii r = wgs84::radii(kLat);
  int e = 0;
  for (double tg = 0.1; tg < T + 1e-9; tg += 0.1, ++e) {  // the last epoch ends the data
    GnssFix f;
    f.t = std::round(tg * 10.0) / 10.0;
    const double nN = 0.05 * std::sin(1.7 * e), nE = 0.05 * std::cos(2.3 * e);
    f.lat = kLat + (0.3 + nN) / (r.R_M + kH);
    f.lon = kLon + (-0.2 + nE) / ((r.R_N + kH) * std::cos(kLat));
    f.h = kH + 0.02 * std::sin(0.7 * e);
    f.v_n = Vec3(0.01 * std::sin(e), 0.01 * std::cos(e), 0.0);
    f.sigma_pos_n = Vec3(0.05, 0.05, 0.1);
    f.sigma_vel_n = Vec3::Constant(0.01);
    d.fixes.push_back(f);
    d.epochs.push_back(f.t);
  }
  // arrival = valid + delay epochs; sort by arrival (stable)
  std::vector<int> idx(d.fixes.size());
  std::vector<double> arr(d.fixes.size());
  for (size_t i = 0; i < d.fixes.size(); ++i) {
    idx[i] = static_cast<int>(i);
    arr[i] = std::round((d.fixes[i].t + 0.1 * delays[i % delays.size()]) * 10.0) / 10.0;
  }
  std::stable_sort(idx.begin(), idx.end(), [&](int a, int b) { return arr[a] < arr[b]; });
  std::vector<GnssFix> sorted;
  for (int i : idx) {
    sorted.push_back(d.fixes[i]);
    d.t_arr.push_back(arr[i]);
  }
  d.fixes = sorted;
  return d;
}

StateCov<Layout15> P0() {
  StateVec<Layout15> s;
  s << 2, 2, 3, 0.1, 0.1, 0.1, 0.01, 0.01, 0.02, 3e-3, 3e-3, 3e-3, 5e-5, 5e-5, 5e-5;
  return s.cwiseAbs2().asDiagonal();
}

struct Out {
  std::vector<double> t, llh, v;
  std::vector<std::int8_t> status;
  DelayOutputs o;
  Out(std::int64_t n, std::int64_t m) : t(n + 1), llh(3 * (n + 1)), v(3 * (n + 1)), status(m, -1) {
    o.t = t.data();
    o.llh = llh.data();
    o.v_n = v.data();
    o.status = status.data();
  }
};

double max_pos_diff_m(const Out& a, const Out& b) {
  double d = 0.0;
  const double R = 6.4e6;
  for (std::int64_t i = 0; i < a.o.n_out; ++i) {
    d = std::max(d, std::abs(a.llh[3 * i] - b.llh[3 * i]) * R);
    d = std::max(d, std::abs(a.llh[3 * i + 1] - b.llh[3 * i + 1]) * R);
    d = std::max(d, std::abs(a.llh[3 * i + 2] - b.llh[3 * i + 2]));
  }
  return d;
}

void run_loose(const Data& d, bool by_arrival, Out& out) {
  auto eng = std::make_unique<LooseEngine<Ekf<Layout15>>>(ImuErrorModel{}, LooseConfig{});
  std::vector<GnssFix> f = d.fixes;
  if (by_arrival)
    for (size_t i = 0; i < f.size(); ++i) f[i].t = d.t_arr[i];
  else
    std::stable_sort(f.begin(), f.end(), [](const GnssFix& a, const GnssFix& b) { return a.t < b.t; });
  eng->run(d.init, P0(), ImuCorrection{}, static_cast<std::int64_t>(d.t.size()), d.t.data(), d.dth.data(),
           d.dv.data(), static_cast<std::int64_t>(f.size()), f.data(), out.o);
}

/// The loose engine (by time of validity) into `ref` and the random-delay engine with p = [1] into `rd`.
template <int S>
std::unique_ptr<RandomDelayEngine<Layout15, S>> run_p1_and_loose(const Data& d, Out& ref, Out& rd) {
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  run_loose(d, false, ref);
  const double p[1] = {1.0};
  auto eng = std::make_unique<RandomDelayEngine<Layout15, S>>(ImuErrorModel{}, LooseConfig{}, DelayConfig{}, p, 1);
  eng->run(d.init, P0(), ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(), m, d.fixes.data(),
           d.t_arr.data(), static_cast<std::int64_t>(d.epochs.size()), d.epochs.data(), rd.o);
  return eng;
}

// --- 1. p = [1]: the random-delay KF is the ordinary KF ----------------------
template <int S>
void test_rdkf_reduces_to_kf() {
  const Data d = make_data(20.0, {0});
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  Out ref(n, m), rd(n, m);
  auto eng = run_p1_and_loose<S>(d, ref, rd);
  EXPECT_TRUE(rd.o.n_out == ref.o.n_out);
  EXPECT_TRUE(rd.o.updates == ref.o.updates && rd.o.updates == m);
  const double diff = max_pos_diff_m(rd, ref);
  std::printf("S=%d: p=[1] RDKF vs EKF max position difference %.3g m\n", S, diff);
  EXPECT_LT(diff, 1e-9);
  // the stack is a valid (PSD) covariance at an epoch (the data end at one)
  if constexpr (S > 0) {
    const auto& Pb = eng->filter().P_stacked();
    EXPECT_LT((Pb - Pb.transpose()).cwiseAbs().maxCoeff(), 1e-12);
    const Eigen::MatrixXd Pd = Pb;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Pd);
    std::printf("  min eigenvalue %.3g max %.3g\n", es.eigenvalues().minCoeff(), es.eigenvalues().maxCoeff());
    EXPECT_LT(-1e-9 * es.eigenvalues().maxCoeff(), es.eigenvalues().minCoeff());
  }
}

// --- 1b. p = [1] through the gate's lock-out recovery and its outage-aware test ----
/// A lasting 3 m position step after 8 s (the gate locks out and reopens with the covariance
/// scaled, ClosedLoop::update_gated) and a 3 s gap (the outage-aware test): the RDKF with
/// p = [1] takes the loose engine's steps, row for row.
template <int S>
void test_rdkf_gate_reopen_reduces_to_kf(double gap_end, double step_m, bool want_bridge) {
  Data d = make_data(20.0, {0});
  const wgs84::Radii r = wgs84::radii(kLat);
  std::vector<GnssFix> kept;
  std::vector<double> arr;
  for (size_t i = 0; i < d.fixes.size(); ++i) {
    GnssFix f = d.fixes[i];
    if (f.t > 4.0 && f.t < gap_end) continue;  // the gap
    if (f.t > gap_end - 1e-9) f.lat += step_m / (r.R_M + kH);  // the step, from the first fix after the gap
    kept.push_back(f);
    arr.push_back(d.t_arr[i]);
  }
  d.fixes = kept;
  d.t_arr = arr;
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  Out ref(n, m), rd(n, m);
  auto eng = run_p1_and_loose<S>(d, ref, rd);
  std::printf("S=%d gate: EKF updates %d reopened %d outage-accepted %d; RDKF %d / %d / %d\n", S, ref.o.updates,
              ref.o.gate_reopened, ref.o.gate_outage_accepted, rd.o.updates, rd.o.gate_reopened,
              rd.o.gate_outage_accepted);
  EXPECT_TRUE(want_bridge ? ref.o.gate_outage_accepted >= 1 : ref.o.gate_reopened >= 1);  // the case is exercised
  EXPECT_TRUE(rd.o.updates == ref.o.updates && rd.o.gate_reopened == ref.o.gate_reopened);
  EXPECT_TRUE(rd.o.gate_outage_accepted == ref.o.gate_outage_accepted);
  const double diff = max_pos_diff_m(rd, ref);
  std::printf("  max position difference %.3g m\n", diff);
  EXPECT_LT(diff, 1e-6);  // rounding of the two update forms, carried by the covariance scaling (metres without it)
}

// --- 2. shift: new(i, j) = old(max(i-1,0), max(j-1,0)) -----------------------
void test_shift() {
  RandomDelayKf<Layout15, 2> f(ImuErrorModel{});
  StateCov<Layout15> A = P0();
  f.initialize(A);
  f.shift();
  const auto& P = f.P_stacked();
  auto off = [&](int i, int j, const StateCov<Layout15>& ref) {
    return (P.block(15 * i, 15 * j, 15, 15) - ref).cwiseAbs().maxCoeff();
  };
  const StateCov<Layout15> Z = StateCov<Layout15>::Zero();
  EXPECT_LT(off(1, 1, A), 1e-15);
  EXPECT_LT(off(0, 1, A), 1e-15);
  EXPECT_LT(off(2, 2, Z), 1e-15);  // still empty
  f.shift();
  EXPECT_LT(off(2, 0, A), 1e-15);
  EXPECT_LT(off(2, 1, A), 1e-15);
}

// --- 3. time-tagged engine -------------------------------------------------
void test_exact_zero_delay_equals_loose() {
  const Data d = make_data(20.0, {0});
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  Out ref(n, m), ex(n, m);
  run_loose(d, false, ref);
  auto eng = std::make_unique<TimeTaggedEngine<Ekf<Layout15>>>(ImuErrorModel{}, LooseConfig{}, DelayConfig{});
  eng->run(d.init, P0(), ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(), m, d.fixes.data(),
           d.t_arr.data(), ex.o);
  EXPECT_TRUE(ex.o.replays == 0);
  EXPECT_TRUE(ex.o.updates == m);
  EXPECT_LT(max_pos_diff_m(ex, ref), 1e-12);
}

void test_exact_with_delays_ends_like_offline() {
  const std::vector<int> delays = {0, 2, 1, 3, 1, 0, 2, 1};
  const Data d = make_data(20.0, delays);
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  // offline reference: only the records that arrive within the IMU span
  Data on_time = d;
  on_time.fixes.clear();
  on_time.t_arr.clear();
  for (std::int64_t g = 0; g < m; ++g)
    if (d.t_arr[g] <= d.t.back() + 1e-9) {
      on_time.fixes.push_back(d.fixes[g]);
      on_time.t_arr.push_back(d.fixes[g].t);
    }
  Out ref(n, m), ex(n, m), naive(n, m);
  run_loose(on_time, false, ref);
  run_loose(d, true, naive);
  auto eng = std::make_unique<TimeTaggedEngine<Ekf<Layout15>>>(ImuErrorModel{}, LooseConfig{}, DelayConfig{});
  eng->run(d.init, P0(), ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(), m, d.fixes.data(),
           d.t_arr.data(), ex.o);
  std::printf("replays %d, replayed samples %lld\n", ex.o.replays, (long long)ex.o.replayed_samples);
  EXPECT_TRUE(ex.o.replays > 50);
  EXPECT_TRUE(ex.o.refused_too_old == 0);
  const std::int64_t last = ex.o.n_out - 1;
  double diff = 0.0;
  for (int j = 0; j < 3; ++j) diff = std::max(diff, std::abs(ex.llh[3 * last + j] - ref.llh[3 * last + j]) * 6.4e6);
  std::printf("time-tagged vs offline LooseEngine, final position difference %.3g m\n", diff);
  EXPECT_LT(diff, 1e-9);
  // and the real-time output differs from the offline one while records are late
  EXPECT_LT(1e-6, max_pos_diff_m(ex, ref));
}

void test_exact_refuses_old_records() {
  const Data d = make_data(10.0, {0, 0, 0, 12});  // every 4th record 1.2 s late
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  Out ex(n, m);
  DelayConfig dc;
  dc.max_history_s = 1.0;
  auto eng = std::make_unique<TimeTaggedEngine<Ekf<Layout15>>>(ImuErrorModel{}, LooseConfig{}, dc);
  eng->run(d.init, P0(), ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(), m, d.fixes.data(),
           d.t_arr.data(), ex.o);
  int refused = 0, late_arrivals = 0;
  for (std::int64_t g = 0; g < m; ++g) {
    refused += ex.status[g] == 5;
    late_arrivals += (d.t_arr[g] - d.fixes[g].t > 1.1) && d.t_arr[g] <= d.t.back() + 1e-9;
  }
  std::printf("refused %d of %d late records\n", refused, late_arrivals);
  EXPECT_TRUE(refused == ex.o.refused_too_old);
  EXPECT_TRUE(refused == late_arrivals && refused > 10);
  // a small ring bounds the history below max_history_s
  TimeTaggedEngine<Ekf<Layout15>, 4> small(ImuErrorModel{}, LooseConfig{}, dc);
  EXPECT_LT(std::abs(small.history_s() - 0.3), 1e-12);
}

// --- 4. no heap allocation inside run() --------------------------------------
void test_no_malloc() {
  const Data d = make_data(5.0, {0, 1, 3, 2});
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  Out a(n, m), b(n, m);
  const double p[4] = {0.2, 0.4, 0.2, 0.2};
  auto rd = std::make_unique<RandomDelayEngine<Layout15, 3>>(ImuErrorModel{}, LooseConfig{}, DelayConfig{}, p, 4);
  auto ex = std::make_unique<TimeTaggedEngine<Ekf<Layout15>>>(ImuErrorModel{}, LooseConfig{}, DelayConfig{});
  const StateCov<Layout15> P = P0();
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  rd->run(d.init, P, ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(), m, d.fixes.data(), d.t_arr.data(),
          static_cast<std::int64_t>(d.epochs.size()), d.epochs.data(), a.o);
  ex->run(d.init, P, ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(), m, d.fixes.data(), d.t_arr.data(),
          b.o);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);
  EXPECT_TRUE(a.o.updates > 0 && b.o.updates > 0);
  bool finite = true;
  for (std::int64_t i = 0; i < 3 * a.o.n_out; ++i) finite = finite && std::isfinite(a.llh[i]) && std::isfinite(b.llh[i]);
  EXPECT_TRUE(finite);
}

// --- 5. push API: the random-delay KF pushed epoch by epoch == the batch run ----
template <int S>
void test_rdkf_push_equals_batch(int hold, int late_samples) {
  const Data d = make_data(12.0, {0, 1, 2, 1, 0, 3, 1});
  const auto n = static_cast<std::int64_t>(d.t.size());
  const auto m = static_cast<std::int64_t>(d.fixes.size());
  const double p[4] = {0.3, 0.4, 0.2, 0.1};
  DelayNavigatorConfig cfg;
  cfg.imu_hold = hold;
  cfg.loose.propagation_interval = 0.05;
  cfg.loose.lever_arm_b = Vec3(0.3, -0.1, -0.5);
  for (int i = 0; i <= S; ++i) cfg.delay_p[i] = p[i];
  cfg.n_delay_p = S + 1;
  double sum = 0.0;
  for (int i = 0; i <= S; ++i) sum += p[i];
  for (int i = 0; i <= S; ++i) cfg.delay_p[i] /= sum;
  Out batch(n, m);
  std::vector<double> bsig(15 * (n + 1));
  batch.o.sigma = bsig.data();
  auto eng = std::make_unique<RandomDelayEngine<Layout15, S>>(cfg.imu_model, cfg.loose, cfg.delay, cfg.delay_p.data(),
                                                             cfg.n_delay_p);
  eng->run(d.init, P0(), ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(), m, d.fixes.data(), d.t_arr.data(),
           static_cast<std::int64_t>(d.epochs.size()), d.epochs.data(), batch.o);

  auto nav = std::make_unique<DelayNavigator<Layout15, S>>(cfg, d.init, P0());
  const double tol = cfg.delay.time_tolerance;
  std::int64_t g = 0;
  size_t e = 0;
  double worst = 0.0;
  int compared = 0;
  auto compare = [&](std::int64_t i) {
    const auto r = nav->solution();
    double w = std::abs(r.t - batch.t[i]);
    for (int j = 0; j < 3; ++j) {
      w = std::max(w, std::abs(r.llh[j] - batch.llh[3 * i + j]) * (j < 2 ? 6.4e6 : 1.0));
      w = std::max(w, std::abs(r.v_n[j] - batch.v[3 * i + j]));
    }
    for (int j = 0; j < 15; ++j) w = std::max(w, std::abs(r.sigma[j] - bsig[15 * i + j]));
    worst = std::max(worst, w);
    ++compared;
  };
  const long before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  auto push_epochs_upto = [&](double tc) {
    for (; e < d.epochs.size() && d.epochs[e] <= tc; ++e) {
      const std::int64_t g0 = g;
      while (g < m && d.t_arr[g] <= d.epochs[e] + tol) ++g;
      nav->push_epoch(d.epochs[e], d.fixes.data() + g0, static_cast<int>(g - g0));
    }
  };
  for (std::int64_t k = 0; k < n; ++k) {
    push_epochs_upto(d.t[std::max<std::int64_t>(0, k - late_samples)] + tol);
    nav->push_imu(d.t[k], Vec3(d.dth[3 * k], d.dth[3 * k + 1], d.dth[3 * k + 2]),
                  Vec3(d.dv[3 * k], d.dv[3 * k + 1], d.dv[3 * k + 2]));
    const std::int64_t done = nav->samples();
    if (done > 0 && done == k + 1 - hold) compare(done - 1);
  }
  push_epochs_upto(kInf);
  nav->flush();
  compare(n - 1);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);  // no heap allocation while pushing
  std::printf("rdkf S=%d push vs batch (hold %d, %d samples late): max difference %.3g over %d rows, updates %d / %d\n",
              S, hold, late_samples, worst, compared, nav->updates(), batch.o.updates);
  EXPECT_TRUE(worst == 0.0);
  EXPECT_TRUE(compared >= n - hold);
  EXPECT_TRUE(nav->updates() == batch.o.updates && batch.o.updates > 50);
  EXPECT_TRUE(nav->refused_records() == 0 && nav->dropped_records() == 0);
}

void test_rdkf_push_refuses() {
  const Data d = make_data(2.0, {0, 1});
  DelayNavigatorConfig cfg;
  cfg.imu_hold = 2;
  cfg.delay_p[0] = 0.5;
  cfg.delay_p[1] = 0.5;
  cfg.n_delay_p = 2;
  auto nav = std::make_unique<DelayNavigator<Layout15, 1>>(cfg, d.init, P0());
  for (int k = 0; k < 50; ++k)
    nav->push_imu(d.t[k], Vec3(d.dth[3 * k], d.dth[3 * k + 1], d.dth[3 * k + 2]),
                  Vec3(d.dv[3 * k], d.dv[3 * k + 1], d.dv[3 * k + 2]));
  EXPECT_TRUE(nav->push_epoch(d.init.t, d.fixes.data(), 1) == RecordStatus::kOutsideImuSpan);
  EXPECT_TRUE(nav->push_epoch(0.2, d.fixes.data(), 1) == RecordStatus::kTooOld);  // integrated long ago
  EXPECT_TRUE(nav->push_epoch(d.t[48], d.fixes.data(), 1) == RecordStatus::kNotUsed);  // a held sample
  EXPECT_TRUE(nav->refused_records() == 2);
  nav->flush();
  EXPECT_TRUE(nav->pending_records() == 0 && nav->updates() == 1);
}

}  // namespace

int main() {
  test_rdkf_gate_reopen_reduces_to_kf<0>(7.0, 3.0, false);
  test_rdkf_gate_reopen_reduces_to_kf<3>(7.0, 3.0, false);
  test_rdkf_gate_reopen_reduces_to_kf<3>(12.0, 0.5, true);  // the outage-aware test passes it
  test_rdkf_gate_reopen_reduces_to_kf<3>(16.0, 1.0, true);  // and with a reopening after it
  test_rdkf_reduces_to_kf<1>();
  test_rdkf_reduces_to_kf<4>();
  test_shift();
  test_exact_zero_delay_equals_loose();
  test_exact_with_delays_ends_like_offline();
  test_exact_refuses_old_records();
  test_no_malloc();
  test_rdkf_push_equals_batch<1>(0, 0);
  test_rdkf_push_equals_batch<3>(0, 0);
  test_rdkf_push_equals_batch<3>(12, 8);
  test_rdkf_push_refuses();
  TEST_MAIN_END();
}
