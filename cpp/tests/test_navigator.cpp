// The push API (engine/navigator.hpp) against the batch engine
// (loose_engine.hpp): the same drive pushed sample by sample, with GNSS fixes
// and vehicle-constraint events pushed on time or late (held IMU samples),
// gives the batch rows bit for bit; late records beyond the hold are refused,
// never applied at a wrong time; no heap allocation after construction.
#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

#include "insnav/engine/navigator.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

struct Drive {
  std::vector<double> t, dth, dv;
  std::vector<GnssFix> fixes;
  std::vector<ConstraintEvent> events;
  NavState s0;
};

/// 60 s at 100 Hz of gentle S-curves; GNSS at 1 Hz between IMU epochs (the
/// increment is split), perturbed fixes; NHC + odometer at 10 Hz.
Drive make_drive() {
  Drive d;
  const double imu_dt = 0.01;
  const int n = 6000;
  d.s0.lat = 0.5;
  d.s0.lon = 0.2;
  d.s0.h = 50.0;
  d.s0.v_n = Vec3(10.0, 0.0, 0.0);
  Strapdown truth(d.s0);
  d.t.resize(n);
  d.dth.resize(3 * n);
  d.dv.resize(3 * n);
  for (int k = 0; k < n; ++k) {
    d.t[k] = imu_dt * (k + 1);
    const double turn = 0.05 * std::sin(0.1 * d.t[k]);
    ImuIncrement imu;
    imu.t = d.t[k];
    imu.dt = imu_dt;
    imu.dtheta_b = Vec3(1e-5, -2e-5, turn * imu_dt);
    imu.dv_b = Vec3(0.2 * std::cos(0.1 * d.t[k]), 10.0 * turn, -wgs84::gravity(d.s0.lat, d.s0.h)) * imu_dt;
    for (int j = 0; j < 3; ++j) d.dth[3 * k + j] = imu.dtheta_b[j], d.dv[3 * k + j] = imu.dv_b[j];
    truth.update(imu);
    const double tk = d.t[k];
    if (k % 100 == 49) {  // a fix valid 5 ms after this sample: inside the next increment
      const NavState& s = truth.state();
      GnssFix f;
      f.t = tk + 0.005;
      f.lat = s.lat + 1e-7 * std::sin(3.0 * k);
      f.lon = s.lon - 1e-7 * std::cos(5.0 * k);
      f.h = s.h + 0.5 * std::sin(7.0 * k);
      f.v_n = s.v_n + Vec3(0.05, -0.03, 0.02) * std::sin(11.0 * k);
      f.sigma_pos_n = Vec3(0.5, 0.5, 1.0);
      f.sigma_vel_n = Vec3::Constant(0.1);
      f.has_vel = (k / 100) % 3 != 0;  // some fixes position only
      d.fixes.push_back(f);
    }
    if (k % 10 == 9) d.events.push_back(ConstraintEvent{tk, static_cast<std::uint8_t>(kNhc | kOdometer),
                                                        truth.state().v_n.norm()});
  }
  // two records at the same time as a sample (a fix and an event at a tie: fix first)
  d.events.push_back(ConstraintEvent{d.fixes[10].t, kNhc, 0.0});
  std::sort(d.events.begin(), d.events.end(), [](const auto& a, const auto& b) { return a.t < b.t; });
  d.s0.q_nb = quat_from_euler(Vec3(0.01, -0.02, 0.05));  // a wrong initial attitude: the filter works
  d.s0.v_n += Vec3(0.3, -0.2, 0.1);
  return d;
}

template <class Filter>
double run_compare(const Drive& d, int hold, int late_samples, bool constraints) {
  using L = typename Filter::Layout;
  NavigatorConfig cfg;
  cfg.loose.propagation_interval = 0.05;
  cfg.loose.lever_arm_b = Vec3(0.5, -0.2, -1.0);
  cfg.imu_hold = hold;
  StateVec<L> sd = StateVec<L>::Constant(1e-3);
  sd.template head<9>() << 2, 2, 3, 0.5, 0.5, 0.5, 0.02, 0.02, 0.1;
  const StateCov<L> P0 = sd.cwiseAbs2().asDiagonal();
  const int n = static_cast<int>(d.t.size());
  const int k_ev = constraints ? static_cast<int>(d.events.size()) : 0;

  // batch
  std::vector<double> bt(n), bllh(3 * n), bv(3 * n), brpy(3 * n), bsig(L::kSize * n);
  LooseOutputs out;
  out.t = bt.data();
  out.llh = bllh.data();
  out.v_n = bv.data();
  out.rpy = brpy.data();
  out.sigma = bsig.data();
  auto batch = std::make_unique<LooseEngine<Filter>>(cfg.imu_model, cfg.loose, cfg.ut);
  batch->run(d.s0, P0, ImuCorrection{}, n, d.t.data(), d.dth.data(), d.dv.data(),
             static_cast<std::int64_t>(d.fixes.size()), d.fixes.data(), k_ev, d.events.data(), out);

  // push: a record is pushed `late_samples` samples after the sample that covers it
  auto nav = std::make_unique<LooseNavigator<Filter>>(cfg, d.s0, P0);
  size_t g = 0, c = 0;
  double max_diff = 0.0;
  int rows = 0;
  const long before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  auto compare_row = [&](int k) {
    const auto r = nav->solution();
    double dmax = std::abs(r.t - bt[k]);
    for (int j = 0; j < 3; ++j) {
      dmax = std::max(dmax, std::abs(r.llh[j] - bllh[3 * k + j]) * (j < 2 ? 6.4e6 : 1.0));
      dmax = std::max(dmax, std::abs(r.v_n[j] - bv[3 * k + j]));
      dmax = std::max(dmax, std::abs(r.rpy[j] - brpy[3 * k + j]));
    }
    for (int j = 0; j < L::kSize; ++j) dmax = std::max(dmax, std::abs(r.sigma[j] - bsig[L::kSize * k + j]));
    max_diff = std::max(max_diff, dmax);
    ++rows;
  };
  for (int k = 0; k < n; ++k) {
    const double t_cover = d.t[std::max(0, k - late_samples)];  // records covered up to here are "arrived"
    while (g < d.fixes.size() && d.fixes[g].t <= (late_samples ? t_cover : d.t[k])) nav->push_gnss_fix(d.fixes[g++]);
    while (constraints && c < d.events.size() && d.events[c].t <= (late_samples ? t_cover : d.t[k]))
      nav->push_constraint(d.events[c++]);
    nav->push_imu(d.t[k], Vec3(d.dth[3 * k], d.dth[3 * k + 1], d.dth[3 * k + 2]),
                  Vec3(d.dv[3 * k], d.dv[3 * k + 1], d.dv[3 * k + 2]));
    const std::int64_t done = nav->samples();  // rows integrated so far: compare the newest
    if (done > 0 && done == k + 1 - hold) compare_row(static_cast<int>(done - 1));
  }
  while (g < d.fixes.size()) nav->push_gnss_fix(d.fixes[g++]);
  while (constraints && c < d.events.size()) nav->push_constraint(d.events[c++]);
  nav->flush();
  compare_row(n - 1);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);  // no heap allocation while pushing
  EXPECT_TRUE(nav->updates() == out.updates);
  EXPECT_TRUE(nav->refused_records() == 0);
  EXPECT_TRUE(rows >= n - hold);
  if (constraints) EXPECT_TRUE(nav->constraint_updates() == out.constraint_updates && out.constraint_updates > 0);
  return max_diff;
}

void test_push_equals_batch() {
  const Drive d = make_drive();
  // on time, no hold
  EXPECT_TRUE(run_compare<Ekf<Layout15>>(d, 0, 0, false) == 0.0);
  EXPECT_TRUE(run_compare<Ekf<Layout15>>(d, 0, 0, true) == 0.0);
  // records arriving 20 samples (0.2 s) late, 25 samples held back
  EXPECT_TRUE(run_compare<Ekf<Layout15>>(d, 25, 20, true) == 0.0);
  EXPECT_TRUE(run_compare<Ekf<Layout21>>(d, 25, 20, false) == 0.0);
  EXPECT_TRUE(run_compare<RbUkf<Layout15>>(d, 25, 20, false) == 0.0);
}

/// The batch engine takes a non-finite velocity or position as absent (masked_fix), as the
/// bindings do: a NaN velocity with has_vel left true runs as has_vel = false, bit for bit.
void test_batch_nan_velocity_is_no_velocity() {
  using L = Layout15;
  const Drive d = make_drive();
  Drive d_nan = d, d_off = d;
  for (size_t i = 0; i < d.fixes.size(); i += 3) {
    d_nan.fixes[i].v_n = Vec3(NAN, 0.0, 0.0);
    d_nan.fixes[i].has_vel = true;
    d_off.fixes[i].has_vel = false;
  }
  for (size_t i = 1; i < d.fixes.size(); i += 7) {
    d_nan.fixes[i].h = NAN;
    d_off.fixes[i].has_pos = false;
  }
  NavigatorConfig cfg;
  StateVec<L> sd = StateVec<L>::Constant(1e-3);
  sd.template head<9>() << 2, 2, 3, 0.5, 0.5, 0.5, 0.02, 0.02, 0.1;
  const StateCov<L> P0 = sd.cwiseAbs2().asDiagonal();
  const int n = static_cast<int>(d.t.size());
  auto run = [&](const Drive& dr, std::vector<double>& llh, std::vector<double>& sig) {
    std::vector<double> t(n);
    llh.assign(3 * n, 0.0);
    sig.assign(L::kSize * n, 0.0);
    LooseOutputs out;
    out.t = t.data();
    out.llh = llh.data();
    out.sigma = sig.data();
    auto e = std::make_unique<LooseEngine<Ekf<L>>>(cfg.imu_model, cfg.loose, cfg.ut);
    e->run(dr.s0, P0, ImuCorrection{}, n, dr.t.data(), dr.dth.data(), dr.dv.data(),
           static_cast<std::int64_t>(dr.fixes.size()), dr.fixes.data(), 0, nullptr, out);
    return out.updates;
  };
  std::vector<double> a_llh, a_sig, b_llh, b_sig;
  const int ua = run(d_nan, a_llh, a_sig), ub = run(d_off, b_llh, b_sig);
  EXPECT_TRUE(ua == ub && ua > 0);
  bool finite = true, same = a_llh == b_llh && a_sig == b_sig;
  for (double x : a_llh) finite = finite && std::isfinite(x);
  EXPECT_TRUE(finite);
  EXPECT_TRUE(same);
}

void test_late_record_refused() {
  const Drive d = make_drive();
  NavigatorConfig cfg;
  cfg.imu_hold = 2;
  const StateCov<Layout15> P0 = StateCov<Layout15>::Identity();
  auto nav = std::make_unique<LooseNavigator<Ekf<Layout15>>>(cfg, d.s0, P0);
  for (int k = 0; k < 100; ++k)
    nav->push_imu(d.t[k], Vec3(d.dth[3 * k], d.dth[3 * k + 1], d.dth[3 * k + 2]),
                  Vec3(d.dv[3 * k], d.dv[3 * k + 1], d.dv[3 * k + 2]));
  EXPECT_TRUE(nav->held_samples() == 2);
  EXPECT_TRUE(nav->t_integrated() == d.t[97]);
  GnssFix f = d.fixes[0];  // valid at 0.505 s: integrated long ago
  EXPECT_TRUE(nav->push_gnss_fix(f) == RecordStatus::kTooOld);
  f.t = d.t[98];  // inside a held sample: still on time
  EXPECT_TRUE(nav->push_gnss_fix(f) == RecordStatus::kNotUsed);
  f.t = d.s0.t;  // the initial time itself
  EXPECT_TRUE(nav->push_gnss_fix(f) == RecordStatus::kOutsideImuSpan);
  EXPECT_TRUE(nav->refused_records() == 2);
  EXPECT_TRUE(!nav->push_imu(d.t[99], Vec3::Zero(), Vec3::Zero()));  // time not increasing
  nav->flush();
  EXPECT_TRUE(nav->held_samples() == 0 && nav->pending_records() == 0);
}


/// What the push calls refuse: a fix with a non-finite position or a sigma that is not finite and
/// > 0 throws std::invalid_argument (before, it was queued: with the gate off the first one made the
/// state NaN for good, with the gate on the sixth, let in by the gate's reopening); a NaN velocity is
/// no velocity (the GnssFix comment), the state stays finite; an IMU step or increment beyond any
/// real sample (1e300) is refused (false) instead of overflowing the mechanization.
void test_hostile_push_inputs() {
  const Drive d = make_drive();
  NavigatorConfig cfg;
  cfg.loose.gate.prob = 0.0;  // no gate: a bad fix would be applied at once
  const StateCov<Layout15> P0 = StateCov<Layout15>::Identity();
  auto nav = std::make_unique<LooseNavigator<Ekf<Layout15>>>(cfg, d.s0, P0);
  for (int k = 0; k < 100; ++k)
    nav->push_imu(d.t[k], Vec3(d.dth[3 * k], d.dth[3 * k + 1], d.dth[3 * k + 2]),
                  Vec3(d.dv[3 * k], d.dv[3 * k + 1], d.dv[3 * k + 2]));
  const auto refused = [&](GnssFix f) {
    f.t = d.t[100] - 0.001;
    try {
      nav->push_gnss_fix(f);
    } catch (const std::invalid_argument&) {
      return true;
    }
    return false;
  };
  GnssFix f = d.fixes[0];
  f.has_vel = false;
  GnssFix g = f;
  g.lat = NAN;
  EXPECT_TRUE(refused(g));
  g = f;
  g.sigma_pos_n[1] = NAN;
  EXPECT_TRUE(refused(g));
  g.sigma_pos_n[1] = INFINITY;
  EXPECT_TRUE(refused(g));
  g.sigma_pos_n[1] = 0.0;
  EXPECT_TRUE(refused(g));
  g.sigma_pos_n[1] = -1.0;
  EXPECT_TRUE(refused(g));
  g = f;
  g.has_vel = true;
  g.v_n = Vec3(1.0, 0.0, 0.0);
  g.sigma_vel_n = Vec3(NAN, 0.1, 0.1);
  EXPECT_TRUE(refused(g));
  EXPECT_TRUE(nav->pending_records() == 0);
  // a position-only receiver's fix with a NaN velocity (has_vel left true): the velocity is absent
  g = f;
  g.t = d.fixes[1].t;
  g.has_vel = true;
  g.v_n = Vec3(NAN, NAN, NAN);
  g.sigma_vel_n = Vec3(NAN, NAN, NAN);
  g.lat = d.fixes[1].lat;
  g.lon = d.fixes[1].lon;
  g.h = d.fixes[1].h;
  EXPECT_TRUE(nav->push_gnss_fix(g) == RecordStatus::kNotUsed);
  // absurd samples: refused, nothing integrated
  const std::int64_t n0 = nav->samples();
  EXPECT_TRUE(!nav->push_imu(d.t[100] + 1e300, Vec3::Zero(), Vec3::Zero()));
  EXPECT_TRUE(!nav->push_imu(d.t[100], Vec3::Constant(1e300), Vec3::Zero()));
  EXPECT_TRUE(!nav->push_imu(d.t[100], Vec3::Zero(), Vec3::Constant(1e300)));
  for (int k = 100; k < 300; ++k)
    EXPECT_TRUE(nav->push_imu(d.t[k], Vec3(d.dth[3 * k], d.dth[3 * k + 1], d.dth[3 * k + 2]),
                              Vec3(d.dv[3 * k], d.dv[3 * k + 1], d.dv[3 * k + 2])));
  nav->flush();
  EXPECT_TRUE(nav->samples() == n0 + 200 && nav->updates() >= 1);
  const NavigatorRow<Layout15> r = nav->solution();
  EXPECT_TRUE(r.llh.allFinite() && r.v_n.allFinite() && nav->covariance().allFinite());
}

/// Tight: a stationary receiver, 6 satellites, epochs 5 ms after an IMU
/// sample, a clock bias and drift; the batch TightEngine against the pushed
/// TightNavigator (epochs 20 samples late, 25 held back).
template <class Filter>
void test_tight_push_equals_batch() {
  using L = typename Filter::Layout;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> nd(0.0, 1.0);
  const double lat = 0.8, lon = 0.2, h = 300.0, dt = 0.01;
  const int n = 6000;
  const Vec3 w_ie_n = wgs84::omega_ie_n(lat), f_n(0.0, 0.0, -wgs84::gravity(lat, h));
  std::vector<double> t(n), dth(3 * n), dv(3 * n);
  for (int k = 0; k < n; ++k) {
    t[k] = (k + 1) * dt;
    for (int j = 0; j < 3; ++j) dth[3 * k + j] = w_ie_n[j] * dt, dv[3 * k + j] = f_n[j] * dt;
  }
  const Vec3 r_e = wgs84::geodetic_to_ecef(lat, lon, h);
  const Mat3 C_en = wgs84::C_en(lat, lon);
  std::vector<SatObservation> geom;
  for (int i = 0; i < 6; ++i) {
    const double az = 2 * M_PI * i / 6 + 0.3, el = 0.25 + 1.1 * u(rng);
    const Vec3 u_e = C_en * Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), -std::sin(el));
    const double b = r_e.dot(u_e), c = r_e.squaredNorm() - 26560e3 * 26560e3;
    SatObservation s;
    s.r_e = r_e + (-b + std::sqrt(b * b - c)) * u_e;
    s.v_e = 3874.0 * s.r_e.cross(Vec3(u(rng) - 0.5, u(rng) - 0.5, 1.0)).normalized();
    s.sigma_pr_m = 3.0;
    s.sigma_prr_mps = 0.1;
    geom.push_back(s);
  }
  std::vector<TightEpoch> ep;
  std::vector<SatObservation> obs;
  for (int e = 1; e < 60; ++e) {
    TightEpoch x;
    x.t = e + 0.005;
    x.begin = static_cast<std::int64_t>(obs.size());
    for (int i = 0; i < (e % 7 == 0 ? 3 : 6); ++i) {
      SatObservation s = geom[i];
      const Vec3 d = s.r_e - r_e;
      s.pseudorange_m = d.norm() + 50.0 + 0.3 * x.t + 3.0 * nd(rng);
      s.pseudorange_rate_mps = d.normalized().dot(s.v_e) + 0.3 + 0.1 * nd(rng);
      obs.push_back(s);
    }
    x.end = static_cast<std::int64_t>(obs.size());
    ep.push_back(x);
  }
  NavState init;
  init.lat = lat + 3.0 / 6.4e6;
  init.lon = lon;
  init.h = h - 2.0;
  init.q_nb = quat_from_euler(Vec3(1e-3, -1e-3, 5e-3));
  StateVec<L> p0 = StateVec<L>::Constant(1e-3);
  p0.template head<9>() << 5, 5, 5, 0.1, 0.1, 0.1, 2e-3, 2e-3, 1e-2;
  p0[L::kClockBias] = 20.0;
  p0[L::kClockDrift] = 1.0;
  const StateCov<L> P0 = p0.cwiseAbs2().asDiagonal();
  TightNavigatorConfig cfg;
  cfg.tight.propagation_interval = 0.1;
  cfg.imu_hold = 25;
  cfg.clock_bias0_m = 40.0;
  std::vector<double> bt(n), bllh(3 * n), bclk(2 * n);
  TightOutputs out;
  out.t = bt.data();
  out.llh = bllh.data();
  out.clock = bclk.data();
  auto batch = std::make_unique<TightEngine<Filter>>(cfg.imu_model, cfg.tight, cfg.ut);
  batch->run(init, P0, ImuCorrection{}, cfg.clock_bias0_m, 0.0, n, t.data(), dth.data(), dv.data(),
             static_cast<std::int64_t>(ep.size()), ep.data(), obs.data(), out);
  // the batch-only settings are refused by the push engine, not run differently
  for (int which = 0; which < 2; ++which) {
    TightNavigatorConfig bad = cfg;
    if (which == 0) bad.tight.pr_gm.sigma_m = 2.0;
    else bad.tight.tdcp.enabled = true;
    bool threw = false;
    try {
      TightNavigator<Filter> refused(bad, init, P0);
    } catch (const std::invalid_argument&) {
      threw = true;
    }
    EXPECT_TRUE(threw);
  }
  auto nav = std::make_unique<TightNavigator<Filter>>(cfg, init, P0);
  // a non-finite satellite state or an unknown system throws before anything is queued
  // (it would put NaN into the state through the row, or index past the ISB block)
  for (int which = 0; which < 3; ++which) {
    SatObservation bad = obs[0];
    if (which == 0) bad.r_e[1] = NAN;
    else if (which == 1) bad.clock_drift_mps = INFINITY;
    else bad.system = kNumSystems;
    bool threw = false;
    try {
      nav->push_pseudoranges(ep[0].t, &bad, 1);
    } catch (const std::invalid_argument&) {
      threw = true;
    }
    EXPECT_TRUE(threw);
  }
  EXPECT_TRUE(nav->pending_records() == 0);
  const long before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  size_t g = 0;
  double worst = 0.0;
  for (int k = 0; k < n; ++k) {
    const double t_arrived = t[std::max(0, k - 20)];
    while (g < ep.size() && ep[g].t <= t_arrived) {
      nav->push_pseudoranges(ep[g].t, obs.data() + ep[g].begin, static_cast<int>(ep[g].end - ep[g].begin));
      ++g;
    }
    nav->push_imu(t[k], Vec3(dth[3 * k], dth[3 * k + 1], dth[3 * k + 2]), Vec3(dv[3 * k], dv[3 * k + 1], dv[3 * k + 2]));
    const std::int64_t i = nav->samples() - 1;
    if (i >= 0 && k >= cfg.imu_hold) {
      const auto r = nav->solution();
      worst = std::max({worst, std::abs(r.llh[0] - bllh[3 * i]) * 6.4e6, std::abs(r.llh[2] - bllh[3 * i + 2]),
                        std::abs(nav->clock_bias_m() - bclk[2 * i]), std::abs(r.t - bt[i])});
    }
  }
  nav->flush();
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);
  std::printf("tight push vs batch (%s): max difference %.3g, updates %d / %d\n", L::kSize == 17 ? "17" : "20", worst,
              nav->updates(), out.updates);
  EXPECT_TRUE(worst == 0.0);
  EXPECT_TRUE(nav->updates() == out.updates && out.updates > 50);
  EXPECT_TRUE(nav->refused_records() == 0);
}
}  // namespace

int main() {
  test_batch_nan_velocity_is_no_velocity();
  test_push_equals_batch();
  test_late_record_refused();
  test_hostile_push_inputs();
  test_tight_push_equals_batch<Ekf<Layout17>>();
  TEST_MAIN_END();
}
