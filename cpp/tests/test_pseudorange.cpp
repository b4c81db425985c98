// Tight coupling (seed 003): pseudorange / pseudorange-rate H rows against
// numerical derivatives of the nonlinear predicted residual, residual = H dx
// for a known INS error, and TightEngine runs with 0..3 satellites, EKF /
// RB-UKF / UKF, without heap allocation inside the epoch loop.
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/core.hpp"
#include "insnav/engine/tight_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "insnav/meas/pseudorange.hpp"
#include "test_util.hpp"

using namespace insnav;
using L = Layout17;

// Satellites at GPS altitude in given (az, el) seen from r_rx_e, with ~3.9 km/s velocities.
static std::vector<SatObservation> make_sats(double lat, double lon, const Vec3& r_rx_e, int n, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<SatObservation> out;
  const Mat3 C_en = wgs84::C_en(lat, lon);
  for (int i = 0; i < n; ++i) {
    const double az = 2 * M_PI * i / n + 0.3, el = 0.25 + 1.1 * u(rng);
    const Vec3 u_n(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), -std::sin(el));
    const Vec3 u_e = C_en * u_n;
    // range so that |r_sat| ~ 26560 km
    const double b = r_rx_e.dot(u_e), c = r_rx_e.squaredNorm() - 26560e3 * 26560e3;
    const double rho = -b + std::sqrt(b * b - c);
    SatObservation s;
    s.r_e = r_rx_e + rho * u_e;
    Vec3 w = s.r_e.cross(Vec3(u(rng) - 0.5, u(rng) - 0.5, 1.0)).normalized();
    s.v_e = 3874.0 * w;
    s.clock_bias_m = 1e4 * (u(rng) - 0.5);
    s.clock_drift_mps = 0.1 * (u(rng) - 0.5);
    s.sigma_pr_m = 3.0;
    s.sigma_prr_mps = 0.1;
    out.push_back(s);
  }
  return out;
}

// LL = LayoutTightMulti: the satellites cycle through G, R, E, C and each
// non-GPS pseudorange row has +1 in its system's ISB column (checked
// numerically with the rest of H).
template <class LL>
static void test_h_numerical() {
  using L = LL;
  std::mt19937 rng(11);
  NavState ins;
  ins.lat = 0.7;
  ins.lon = 2.0;
  ins.h = 1200.0;
  ins.v_n = Vec3(120.0, -60.0, 4.0);
  ins.q_nb = quat_from_euler(Vec3(0.2, -0.1, 2.5));
  const Vec3 w_b(0.03, -0.02, 0.1), l_b(0.8, -0.3, -1.2);
  const Vec3 r_e = wgs84::geodetic_to_ecef(ins.lat, ins.lon, ins.h);
  auto sats = make_sats(ins.lat, ins.lon, r_e, 8, rng);
  for (auto& s : sats) {
    s.pseudorange_m = 2.2e7;  // any value: H does not depend on it
    s.pseudorange_rate_mps = 100.0;
  }
  sats[2].pseudorange_rate_mps = NAN;  // a missing Doppler drops one row
  const double isb[3] = {-20.0, 35.0, 11.0};
  if constexpr (kHasIsb<L>)
    for (size_t i = 0; i < sats.size(); ++i) sats[i].system = static_cast<int>(i % 4);
  TightMeasurement<L> meas;
  meas.set(ins, w_b, l_b, 123.0, 0.4, sats.data(), static_cast<int>(sats.size()), isb);
  if constexpr (kHasIsb<L>) {  // H: +1 in the ISB column of its system, pseudorange rows only
    int row = 0;
    for (size_t i = 0; i < sats.size(); ++i)
      for (int kind = 0; kind < 2; ++kind) {
        if (!std::isfinite(kind == 0 ? sats[i].pseudorange_m : sats[i].pseudorange_rate_mps)) continue;
        for (int k = 0; k < 3; ++k)
          EXPECT_TRUE(meas.linear().H(row, L::kIsb + k) == ((kind == 0 && sats[i].system == k + 1) ? 1.0 : 0.0));
        ++row;
      }
  }
  const auto& lin = meas.linear();
  EXPECT_TRUE(lin.rows() == 15);
  const StateVec<L> zero = StateVec<L>::Zero();
  EXPECT_LT(meas.predicted_residual(zero).cwiseAbs().maxCoeff(), 1e-12);
  double worst = 0.0;
  for (int j = 0; j < L::kSize; ++j) {
    double eps = 1e-2;  // pos [m], vel [m/s], clock
    // (ranges are ~2e7 m: a too small step drowns in rounding, 4e-9 m / 2 eps)
    if (j >= L::kAtt && j < L::kAtt + 3) eps = 1e-3;
    if (j >= L::kAccBias && j < L::kGyroBias + 3) eps = 1e-4;
    StateVec<L> dp = zero, dm = zero;
    dp[j] = eps;
    dm[j] = -eps;
    const auto num = ((meas.predicted_residual(dp) - meas.predicted_residual(dm)) / (2 * eps)).eval();
    for (int i = 0; i < lin.rows(); ++i) {
      const double e = std::abs(num[i] - lin.H(i, j));
      const double tol = 1e-5 + 1e-5 * std::abs(lin.H(i, j));
      if (e > tol) std::printf("H(%d,%d) = %.9g, numerical %.9g\n", i, j, lin.H(i, j), num[i]);
      EXPECT_LT(e, tol);
      worst = std::max(worst, e);
    }
  }
  std::printf("H vs numerical derivative: worst abs difference %.3g\n", worst);
  // residual from exact measurements of a true state = predicted_residual(dx) ~ H dx
  StateVec<L> dx = zero;
  dx.template segment<3>(L::kPos) = Vec3(5.0, -3.0, 8.0);
  dx.template segment<3>(L::kVel) = Vec3(0.2, 0.1, -0.3);
  dx.template segment<3>(L::kAtt) = Vec3(1e-3, -2e-3, 5e-3);
  dx.template segment<3>(L::kGyroBias) = Vec3(1e-4, 2e-4, -1e-4);
  dx[L::kClockBias] = 7.0;
  dx[L::kClockDrift] = -0.05;
  if constexpr (kHasIsb<L>) dx.template segment<3>(L::kIsb) = Vec3(2.0, -6.0, 1.5);
  const auto z_sim = meas.predicted_residual(dx);  // INS-predicted - true-state prediction
  const auto lin_pred = (lin.H * dx).eval();
  EXPECT_LT((z_sim - lin_pred).cwiseAbs().maxCoeff(), 1e-3);
  // the pseudorange row of an exact measurement of the true state
  NavState tru = ins;
  const wgs84::Radii rr = wgs84::radii(ins.lat);
  tru.lat -= dx[0] / (rr.R_M + ins.h);
  tru.lon -= dx[1] / ((rr.R_N + ins.h) * std::cos(ins.lat));
  tru.h += dx[2];
  const Mat3 C_true = dcm_from_euler(dx.template segment<3>(L::kAtt)) * ins.q_nb.toRotationMatrix();
  const Vec3 r_ant = wgs84::geodetic_to_ecef(tru.lat, tru.lon, tru.h) + wgs84::C_en(tru.lat, tru.lon) * C_true * l_b;
  auto s1 = sats;
  for (auto& s : s1) {
    double isb_true = 0.0;
    if constexpr (kHasIsb<L>)
      if (s.system > 0) isb_true = isb[s.system - 1] - dx[L::kIsb + s.system - 1];
    s.pseudorange_m = (s.r_e - r_ant).norm() + (123.0 - 7.0) + isb_true - s.clock_bias_m;
    s.pseudorange_rate_mps = NAN;
  }
  TightMeasurement<L> m2;
  m2.set(ins, w_b, l_b, 123.0, 0.4, s1.data(), static_cast<int>(s1.size()), isb);
  for (int i = 0; i < m2.linear().rows(); ++i)
    EXPECT_LT(std::abs(m2.linear().residual[i] - (m2.linear().H.row(i) * dx)(0)), 1e-4);
}

// Stationary IMU at lat, level, facing north: exact increments at rate 100 Hz.
template <class Filter>
// gm_sigma_m > 0: with the Gauss-Markov pseudorange states (meas/pseudorange_gm.hpp) on, under the
// same malloc check (fixed-capacity block, no heap per epoch)
static void run_stationary(int n_sats, const char* name, double gm_sigma_m = 0.0) {
  std::mt19937 rng(5);
  const double lat = 0.8, lon = 0.2, h = 300.0, dt = 0.01, T = 120.0;
  const int n = static_cast<int>(T / dt);
  const Vec3 w_ie_n = wgs84::omega_ie_n(lat);
  const Vec3 f_n(0.0, 0.0, -wgs84::gravity(lat, h));
  std::vector<double> t(n), dth(3 * n), dv(3 * n);
  for (int k = 0; k < n; ++k) {
    t[k] = (k + 1) * dt;
    for (int j = 0; j < 3; ++j) {
      dth[3 * k + j] = w_ie_n[j] * dt;
      dv[3 * k + j] = f_n[j] * dt;
    }
  }
  const Vec3 r_e = wgs84::geodetic_to_ecef(lat, lon, h);
  const auto geom = make_sats(lat, lon, r_e, 4, rng);
  std::normal_distribution<double> nd(0.0, 1.0);
  std::vector<TightEpoch> ep;
  std::vector<SatObservation> obs;
  const double b0 = 50.0, d0 = 0.3;
  for (int e = 1; e <= static_cast<int>(T); ++e) {
    TightEpoch x;
    x.t = e;
    x.begin = static_cast<std::int64_t>(obs.size());
    const int use = (e > 20) ? n_sats : 4;  // 4 satellites for 20 s, then n_sats
    for (int i = 0; i < use; ++i) {
      SatObservation s = geom[i];
      if (gm_sigma_m > 0.0) s.prn = i + 1;  // the Gauss-Markov states key on the satellite
      const Vec3 d = s.r_e - r_e;
      s.pseudorange_m = d.norm() + b0 + d0 * e - s.clock_bias_m + 3.0 * nd(rng);
      s.pseudorange_rate_mps = d.normalized().dot(s.v_e) + d0 - s.clock_drift_mps + 0.1 * nd(rng);
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
  ImuErrorModel model;
  model.gyro_arw = Vec3::Constant(1e-5);
  model.acc_vrw = Vec3::Constant(1e-3);
  model.gyro_bias_sigma = Vec3::Constant(1e-6);
  model.acc_bias_sigma = Vec3::Constant(1e-3);
  model.clock_bias_psd = 0.1;
  model.clock_drift_psd = 0.01;
  StateVec<L> p0;
  p0 << 5, 5, 5, 0.1, 0.1, 0.1, 2e-3, 2e-3, 1e-2, 1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6, 20.0, 1.0;
  const StateCov<L> P0 = p0.cwiseAbs2().asDiagonal();
  TightConfig cfg;
  cfg.propagation_interval = 0.1;  // insnav.run's default (the C++ default 0.02 s: 5x the UT propagations)
  cfg.pr_gm.sigma_m = gm_sigma_m;
  auto engine = std::make_unique<TightEngine<Filter>>(model, cfg);
  std::vector<double> o_t(n + 1), o_llh(3 * (n + 1)), o_clk(2 * (n + 1)), o_sig(17 * (n + 1)), o_res(2 * obs.size()),
      o_nis(ep.size());
  std::vector<std::int8_t> o_st(ep.size());
  TightOutputs out;
  out.t = o_t.data();
  out.llh = o_llh.data();
  out.clock = o_clk.data();
  out.sigma = o_sig.data();
  out.sat_residual = o_res.empty() ? nullptr : o_res.data();
  out.nis = o_nis.data();
  out.status = o_st.data();
  Eigen::internal::set_is_malloc_allowed(false);
  engine->run(init, P0, ImuCorrection{}, 40.0, 0.0, n, t.data(), dth.data(), dv.data(),
              static_cast<std::int64_t>(ep.size()), ep.data(), obs.data(), out);
  Eigen::internal::set_is_malloc_allowed(true);
  const std::int64_t last = out.n_out - 1;
  const double dN = (o_llh[3 * last] - lat) * 6.37e6, dE = (o_llh[3 * last + 1] - lon) * 6.37e6 * std::cos(lat);
  const double dU = o_llh[3 * last + 2] - h;
  const double clk_err = o_clk[2 * last] - (b0 + d0 * T), drift_err = o_clk[2 * last + 1] - d0;
  std::printf("%s, %d sats after 20 s: final pos err N %.2f E %.2f U %.2f m, clock err %.2f m (sigma %.2f), "
              "drift err %.3f m/s, updates %d\n",
              name, n_sats, dN, dE, dU, clk_err, o_sig[17 * last + 15], drift_err, out.updates);
  bool finite = true;
  for (std::int64_t i = 0; i <= last; ++i) finite = finite && std::isfinite(o_llh[3 * i]) && std::isfinite(o_clk[2 * i]);
  EXPECT_TRUE(finite);
  EXPECT_TRUE(out.updates == (n_sats > 0 ? 120 : 20));
  // clock stays bounded: within 5 sigma and within 100 m of truth
  EXPECT_LT(std::abs(clk_err), std::max(5.0 * o_sig[17 * last + 15], 1.0));
  EXPECT_LT(std::abs(clk_err), 100.0);
  EXPECT_LT(std::abs(drift_err), 1.0);
  if (n_sats >= 1) EXPECT_LT(std::hypot(dN, dE), 30.0);
}

// LayoutTightMulti, stationary, 9 satellites of G, E, C, R with true ISBs;
// a 50 m pseudorange step on one Galileo satellite over epochs 40-79 and a
// 1 ms receiver clock reset (all pseudoranges + 299792.458 m) from epoch 100:
// with the robust step the fault is rejected, the jump absorbed into the
// clock, the ISBs estimated, the position stays; no heap allocation.
template <class Filter>
static void run_multi_robust(const char* name) {
  using LM = LayoutTightMulti;
  std::mt19937 rng(7);
  const double lat = 0.8, lon = 0.2, h = 300.0, dt = 0.01, T = 150.0;
  const int n = static_cast<int>(T / dt);
  const Vec3 w_ie_n = wgs84::omega_ie_n(lat);
  const Vec3 f_n(0.0, 0.0, -wgs84::gravity(lat, h));
  std::vector<double> t(n), dth(3 * n), dv(3 * n);
  for (int k = 0; k < n; ++k) {
    t[k] = (k + 1) * dt;
    for (int j = 0; j < 3; ++j) {
      dth[3 * k + j] = w_ie_n[j] * dt;
      dv[3 * k + j] = f_n[j] * dt;
    }
  }
  const Vec3 r_e = wgs84::geodetic_to_ecef(lat, lon, h);
  auto geom = make_sats(lat, lon, r_e, 9, rng);
  const int sys[9] = {0, 2, 3, 0, 2, 3, 0, 1, 2};
  const double isb_true[3] = {-15.0, 42.0, -27.0};  // R, E, C [m]
  for (int i = 0; i < 9; ++i) geom[i].system = sys[i];
  std::normal_distribution<double> nd(0.0, 1.0);
  std::vector<TightEpoch> ep;
  std::vector<SatObservation> obs;
  const double b0 = 50.0, d0 = 0.3, jump = 299792.458;
  for (int e = 1; e <= static_cast<int>(T); ++e) {
    TightEpoch x;
    x.t = e;
    x.begin = static_cast<std::int64_t>(obs.size());
    for (int i = 0; i < 9; ++i) {
      SatObservation s = geom[i];
      const Vec3 d = s.r_e - r_e;
      s.pseudorange_m = d.norm() + b0 + d0 * e + (s.system ? isb_true[s.system - 1] : 0.0) - s.clock_bias_m +
                        1.0 * nd(rng) + ((i == 1 && e >= 40 && e < 80) ? 50.0 : 0.0) + (e >= 100 ? jump : 0.0);
      s.sigma_pr_m = 1.0;
      s.pseudorange_rate_mps = d.normalized().dot(s.v_e) + d0 - s.clock_drift_mps + 0.1 * nd(rng);
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
  ImuErrorModel model;
  model.gyro_arw = Vec3::Constant(1e-5);
  model.acc_vrw = Vec3::Constant(1e-3);
  model.gyro_bias_sigma = Vec3::Constant(1e-6);
  model.acc_bias_sigma = Vec3::Constant(1e-3);
  model.clock_bias_psd = 0.1;
  model.clock_drift_psd = 0.01;
  StateVec<LM> p0;
  p0 << 5, 5, 5, 0.1, 0.1, 0.1, 2e-3, 2e-3, 1e-2, 1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6, 20.0, 1.0, 100, 100, 100;
  const StateCov<LM> P0 = p0.cwiseAbs2().asDiagonal();
  TightConfig cfg;
  cfg.propagation_interval = 0.1;  // insnav.run's default
  cfg.robust.screening = true;
  auto engine = std::make_unique<TightEngine<Filter>>(model, cfg);
  std::vector<double> o_t(n + 1), o_llh(3 * (n + 1)), o_clk(2 * (n + 1)), o_isb(3 * (n + 1)), o_sig(20 * (n + 1)),
      o_jump(ep.size());
  std::vector<std::int8_t> o_flag(2 * obs.size());
  TightOutputs out;
  out.t = o_t.data();
  out.llh = o_llh.data();
  out.clock = o_clk.data();
  out.isb = o_isb.data();
  out.sigma = o_sig.data();
  out.sat_flag = o_flag.data();
  out.clock_jump = o_jump.data();
  Eigen::internal::set_is_malloc_allowed(false);
  engine->run(init, P0, ImuCorrection{}, 40.0, 0.0, n, t.data(), dth.data(), dv.data(),
              static_cast<std::int64_t>(ep.size()), ep.data(), obs.data(), out);
  Eigen::internal::set_is_malloc_allowed(true);
  const std::int64_t last = out.n_out - 1;
  const double dN = (o_llh[3 * last] - lat) * 6.37e6, dE = (o_llh[3 * last + 1] - lon) * 6.37e6 * std::cos(lat);
  const double clk_err = o_clk[2 * last] - (b0 + d0 * T + jump);
  int rejected_fault = 0;
  for (int e = 40; e < 80; ++e) rejected_fault += o_flag[2 * (9 * (e - 1) + 1)] == 2 ? 1 : 0;
  std::printf("%s multi-GNSS robust: pos err N %.2f E %.2f m, clock err %.2f m, ISB err %.2f %.2f %.2f m, "
              "fault rejected %d/40 epochs, clock jumps %d (%.3f m at epoch 100), rejected sats %d, flagged %d\n",
              name, dN, dE, clk_err, o_isb[3 * last] - isb_true[0], o_isb[3 * last + 1] - isb_true[1],
              o_isb[3 * last + 2] - isb_true[2], rejected_fault, out.clock_jumps, o_jump[99], out.rejected_sats,
              out.flagged_epochs);
  EXPECT_TRUE(rejected_fault == 40);
  EXPECT_TRUE(out.clock_jumps == 1);
  EXPECT_LT(std::abs(o_jump[99] - jump), 5.0);
  EXPECT_LT(std::abs(clk_err), 5.0);
  for (int k = 0; k < 3; ++k) EXPECT_LT(std::abs(o_isb[3 * last + k] - isb_true[k]), 5.0);
  EXPECT_LT(std::hypot(dN, dE), 5.0);
  EXPECT_TRUE(out.updates == 150);
}

/// The robust variance factor (meas/robust.hpp, 0.): analytic cases, the breakdown point, and a
/// large sample of noise 3 times its sigma.
void test_variance_factor() {
  std::vector<double> y2(20001), a(20001, 0.0), r(20001, 1.0), scratch(20001);
  const double c = 2.0;
  std::fill(y2.begin(), y2.begin() + 7, c);  // y^2 / (a + f r) = c / f: f = c / median(chi2_1)
  double f = variance_factor(y2.data(), a.data(), r.data(), 7, scratch.data());
  EXPECT_LT(std::abs(f - c / kChi2OneMedian), 1e-5 * f);
  std::fill(a.begin(), a.begin() + 7, 1.0);  // c / (1 + f)
  f = variance_factor(y2.data(), a.data(), r.data(), 7, scratch.data());
  EXPECT_LT(std::abs(f - (c / kChi2OneMedian - 1.0)), 1e-5 * f);
  std::fill(a.begin(), a.end(), 0.0);
  std::fill(y2.begin(), y2.begin() + 10, 0.3);  // rows below the median: no factor
  EXPECT_TRUE(variance_factor(y2.data(), a.data(), r.data(), 10, scratch.data()) == 1.0);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> nd;
  {  // a faulty quarter of consistent rows: the median moves to the clean rows' 2/3 quantile
    const int n_clean = 15000, n_bad = 5000;
    for (int i = 0; i < n_clean; ++i) y2[i] = std::pow(nd(rng), 2);
    for (int i = n_clean; i < n_clean + n_bad; ++i) y2[i] = 1e6;
    f = variance_factor(y2.data(), a.data(), r.data(), n_clean + n_bad, scratch.data());
    const double q23 = 0.93590449;  // chi2_1 quantile at 2/3
    std::printf("variance factor, a quarter of the rows faulty: %.4f (%.4f)\n", f, q23 / kChi2OneMedian);
    EXPECT_LT(std::abs(f - q23 / kChi2OneMedian), 0.05 * f);
  }
  for (double& v : y2) v = std::pow(nd(rng), 2);  // consistent noise: 1 to the sample median's spread
  f = variance_factor(y2.data(), a.data(), r.data(), 20001, scratch.data());
  EXPECT_LT(f, 1.0 + 4.0 * 1.0616 / std::sqrt(20001.0) / kChi2OneMedian);
  for (double& v : y2) v *= 9.0;  // noise 3 times its sigma
  f = variance_factor(y2.data(), a.data(), r.data(), 20001, scratch.data());
  std::printf("variance factor of noise 3 sigma (20001 rows): %.4f (9)\n", f);
  EXPECT_LT(std::abs(f - 9.0), 0.05 * 9.0);
}

int main() {
  test_variance_factor();
  run_multi_robust<Ekf<LayoutTightMulti>>("EKF");
  run_multi_robust<RbUkf<LayoutTightMulti>>("RB-UKF");
  run_multi_robust<Ukf<LayoutTightMulti>>("UKF");
  test_h_numerical<Layout17>();
  test_h_numerical<LayoutTightMulti>();
  for (int ns : {0, 1, 2, 3, 4}) {
    run_stationary<Ekf<L>>(ns, "EKF");
    run_stationary<RbUkf<L>>(ns, "RB-UKF");
    run_stationary<Ukf<L>>(ns, "UKF");
  }
  run_stationary<Ekf<L>>(4, "EKF + Gauss-Markov pseudorange states", 2.0);
  EXPECT_TRUE(g_eigen_asserts == 0);
  TEST_MAIN_END()
}
