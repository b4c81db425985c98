// Single point positioning (insnav/gnss/spp_solver.hpp) on exact simulated
// epochs: noise-free pseudoranges and rates of four systems with inter-system
// biases give the position, clocks and velocity back to far below a millimetre;
// a 100 m pseudorange fault is excluded by RAIM (that row, and the epoch passes
// afterwards); the chi-square quantiles equal tabulated values; and the whole
// batch runs without heap allocation.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/core.hpp"
#include "insnav/gnss/spp_solver.hpp"
#include "test_util.hpp"

using namespace insnav;
using L = gnss::SppRowLayout;

int main() {
  // chi^2 quantiles (Abramowitz & Stegun Table 26.8: 10.828 for 1 dof, 29.588 for 10 dof at 0.999)
  EXPECT_LT(std::abs(gnss::chi2_quantile(0.999, 1) - 10.828), 1e-3);
  EXPECT_LT(std::abs(gnss::chi2_quantile(0.999, 10) - 29.588), 1e-3);

  const double lat = 52.51 * M_PI / 180.0, lon = 13.37 * M_PI / 180.0;
  const Vec3 r_rx = wgs84::geodetic_to_ecef(lat, lon, 60.0);
  const Vec3 v_rx(3.0, -4.0, 1.0);
  const double clock = 1234.5, drift = 0.7;
  const double isb[4] = {0.0, 30.0, -12.0, 55.0};
  const Mat3 C_en = wgs84::C_en(lat, lon);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uni(0.0, 1.0);

  const int n_epochs = 20, n_sats = 14, faulty_epoch = 7, faulty_row = 5;
  std::vector<std::int64_t> start(n_epochs + 1);
  std::vector<double> sats, spr, sprr;
  std::vector<std::int8_t> sys;
  for (int e = 0; e < n_epochs; ++e) {
    start[e] = static_cast<std::int64_t>(sys.size());
    for (int i = 0; i < n_sats; ++i) {
      const double az = 2 * M_PI * i / n_sats + 0.1 * e, el = 0.2 + 1.2 * uni(rng);
      const Vec3 u_e = C_en * Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), -std::sin(el));
      const double b = r_rx.dot(u_e), c = r_rx.squaredNorm() - 26560e3 * 26560e3;
      const double rho = -b + std::sqrt(b * b - c);
      const Vec3 r_s = r_rx + rho * u_e;
      const Vec3 v_s = 3874.0 * r_s.cross(Vec3(0.2, -0.3, 1.0)).normalized();
      const int s = i % 4;
      const double clk_s = 1e4 * (uni(rng) - 0.5), clkdot = 10.0 * (uni(rng) - 0.5);
      double pr = rho + clock + isb[s] - clk_s;
      if (e == faulty_epoch && i == faulty_row) pr += 100.0;
      const double prr = u_e.dot(v_s - v_rx) + drift - clkdot;
      const double row[L::kCols] = {pr, prr, r_s.x(), r_s.y(), r_s.z(), v_s.x(), v_s.y(), v_s.z(), clk_s, clkdot, 0, 0};
      sats.insert(sats.end(), row, row + L::kCols);
      spr.push_back(1.0 / std::sin(el));
      sprr.push_back(0.1 / std::sin(el));
      sys.push_back(static_cast<std::int8_t>(s));
    }
  }
  start[n_epochs] = static_cast<std::int64_t>(sys.size());
  const std::size_t M = sys.size();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> r(3 * n_epochs, nan), b(n_epochs, nan), v(3 * n_epochs, nan), d(n_epochs, nan),
      sp(3 * n_epochs, nan), sv(3 * n_epochs, nan), is(4 * n_epochs, nan), sis(4 * n_epochs, nan),
      cr(9 * n_epochs, nan), cv(9 * n_epochs, nan), sc(n_epochs, nan), sd(n_epochs, nan), g(n_epochs, nan),
      p(n_epochs, nan), h(n_epochs, nan), vd(n_epochs, nan), td(n_epochs, nan), c2(n_epochs, nan),
      thr(n_epochs, nan);
  std::vector<std::int64_t> ns(n_epochs), nu(n_epochs), nx(n_epochs), nr(n_epochs), nrx(n_epochs);
  std::vector<std::int8_t> st(n_epochs, 4), ref(n_epochs, -1);
  std::vector<std::uint8_t> rx(M, 0), rrx(M, 0);
  gnss::SppBatchOutput out{r.data(),  b.data(),  v.data(),  d.data(),  sp.data(), sv.data(), is.data(),
                           sis.data(), cr.data(), cv.data(), sc.data(), sd.data(), g.data(),  p.data(),
                           h.data(),  vd.data(), td.data(), c2.data(), thr.data(), ns.data(), nu.data(),
                           nx.data(), nr.data(), nrx.data(), st.data(), ref.data(), rx.data(), rrx.data()};
  gnss::SppBatchInput in;
  in.n_epochs = n_epochs;
  in.epoch_start = start.data();
  in.sats = sats.data();
  in.sigma_pr_m = spr.data();
  in.sigma_prr_mps = sprr.data();
  in.system = sys.data();
  in.r0_e = r_rx + Vec3(3000.0, -2000.0, 1500.0);
  gnss::SppOptions opt;

  Eigen::internal::set_is_malloc_allowed(false);
  const Status status = gnss::solve_spp_batch(in, opt, out);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(status == Status::kOk);
  EXPECT_TRUE(g_eigen_asserts == 0);

  for (int e = 0; e < n_epochs; ++e) {
    const Vec3 dr = Vec3(r[3 * e], r[3 * e + 1], r[3 * e + 2]) - r_rx;
    EXPECT_LT(dr.norm(), 1e-6);
    EXPECT_LT(std::abs(b[e] - clock), 1e-6);
    for (int s = 1; s < 4; ++s) EXPECT_LT(std::abs(is[4 * e + s] - isb[s]), 1e-6);
    const Vec3 dv = Vec3(v[3 * e], v[3 * e + 1], v[3 * e + 2]) - v_rx;
    EXPECT_LT(dv.norm(), 1e-7);
    EXPECT_LT(std::abs(d[e] - drift), 1e-7);
    EXPECT_TRUE(ref[e] == 0);
    EXPECT_TRUE(g[e] > p[e] && p[e] > h[e] && h[e] > 0.0);
    if (e == faulty_epoch) {
      EXPECT_TRUE(st[e] == static_cast<std::int8_t>(gnss::RaimStatus::kExcluded));
      EXPECT_TRUE(nx[e] == 1 && nu[e] == n_sats - 1);
      EXPECT_TRUE(rx[start[e] + faulty_row] == 1);
    } else {
      EXPECT_TRUE(st[e] == static_cast<std::int8_t>(gnss::RaimStatus::kPassed));
      EXPECT_TRUE(nx[e] == 0 && nu[e] == n_sats && nr[e] == n_sats);
      EXPECT_LT(c2[e], 1e-12);
    }
  }
  int n_excluded_rows = 0;
  for (std::size_t i = 0; i < M; ++i) n_excluded_rows += rx[i] + rrx[i];
  EXPECT_TRUE(n_excluded_rows == 1);

  // an epoch of more rows than the capacity is refused, nothing written
  std::vector<std::int64_t> big = {0, static_cast<std::int64_t>(gnss::kSppMaxRows + 1)};
  std::vector<double> big_sats(L::kCols * (gnss::kSppMaxRows + 1), 1.0), big_s(gnss::kSppMaxRows + 1, 1.0);
  std::vector<std::int8_t> big_sys(gnss::kSppMaxRows + 1, 0);
  gnss::SppBatchInput in2 = in;
  in2.n_epochs = 1;
  in2.epoch_start = big.data();
  in2.sats = big_sats.data();
  in2.sigma_pr_m = big_s.data();
  in2.sigma_prr_mps = big_s.data();
  in2.system = big_sys.data();
  EXPECT_TRUE(gnss::solve_spp_batch(in2, opt, out) == Status::kBadInput);
  TEST_MAIN_END();
}
