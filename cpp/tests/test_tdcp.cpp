// TDCP stochastic-cloning update (meas/tdcp.hpp): the marginalised update of
// x_k equals the Kalman update of the explicit clone-augmented state
// [x_k; x_c] with covariance [[P, Phi P_prev], [(Phi P_prev)^T, P_prev]]
// (Roumeliotis & Burdick 2002, sec. III), and it runs without heap allocation.
#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include <Eigen/Cholesky>
#include <memory>
#include <random>
#include <vector>

#include "insnav/core.hpp"
#include "insnav/engine/tight_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "insnav/meas/tdcp.hpp"
#include "test_util.hpp"

using namespace insnav;
using L = Layout17;
constexpr int N = L::kSize;

// TightEngine<Ekf<Lx>> with TDCP rows: a stationary receiver (exact IMU increments),
// 6 moving satellites, noisy code and rate, carrier phase with 3 mm noise: the engine runs
// without heap allocation, uses the TDCP rows and ends near the truth.  Lx = Layout17, and
// LayoutTightTdLever (the rows' time-offset and lever-arm columns, meas/tdcp.hpp).
template <class Lx>
static void engine_no_heap() {
  std::mt19937 rng(11);
  std::normal_distribution<double> nd(0.0, 1.0);
  const double lat = 0.7, lon = 0.3, h = 100.0, dt = 0.01, T = 30.0;
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
  const Mat3 C_en = wgs84::C_en(lat, lon);
  const int ns = 6;
  std::vector<TightEpoch> ep;
  std::vector<SatObservation> obs;
  std::vector<PhaseObservation> ph;
  const double b0 = 20.0, d0 = 0.2, lambda = 0.19029367;
  for (int e = 1; e <= static_cast<int>(T * 4) - 1; ++e) {
    const double te = 0.25 * e;
    TightEpoch x;
    x.t = te;
    x.begin = static_cast<std::int64_t>(obs.size());
    for (int i = 0; i < ns; ++i) {
      const double az = 2 * M_PI * i / ns, el = 0.4 + 0.15 * i;
      const Vec3 u_e = C_en * Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), -std::sin(el));
      SatObservation s;
      s.v_e = 3000.0 * u_e.cross(Vec3(0.0, 0.0, 1.0)).normalized();
      s.r_e = r_e + 2.2e7 * u_e + s.v_e * te;
      s.clock_bias_m = 100.0 * i + 0.01 * te;
      s.clock_drift_mps = 0.01;
      s.prn = i + 1;
      const Vec3 d = s.r_e - r_e;
      s.pseudorange_m = d.norm() + b0 + d0 * te - s.clock_bias_m + 3.0 * nd(rng);
      s.pseudorange_rate_mps = d.normalized().dot(s.v_e) + d0 - s.clock_drift_mps + 0.1 * nd(rng);
      PhaseObservation p;
      p.phase_m = d.norm() + b0 + d0 * te - s.clock_bias_m + 1000 * lambda + 0.003 * nd(rng);
      p.wavelength_m = lambda;
      p.sigma_m = 0.005;
      obs.push_back(s);
      ph.push_back(p);
    }
    x.end = static_cast<std::int64_t>(obs.size());
    ep.push_back(x);
  }
  NavState init;
  init.lat = lat + 2.0 / 6.4e6;
  init.lon = lon;
  init.h = h - 1.0;
  ImuErrorModel model;
  model.clock_bias_psd = 0.1;
  model.clock_drift_psd = 0.01;
  StateVec<Lx> p0 = StateVec<Lx>::Constant(0.01);  // the self-calibration states: 1 cm, 10 ms
  p0.template head<17>() << 5, 5, 5, 0.1, 0.1, 0.1, 2e-3, 2e-3, 1e-2, 1e-3, 1e-3, 1e-3, 1e-6, 1e-6, 1e-6, 20.0, 1.0;
  const StateCov<Lx> P0 = p0.cwiseAbs2().asDiagonal();
  TightConfig cfg;
  cfg.propagation_interval = 0.05;
  // 1.5 GNSS periods, as the EKF runs (insnav.registry outage_cycle_factor): with the time-offset state
  // an epoch applies at t - t_d^, and a t_d^ that moves later would otherwise close an empty cycle
  // first and break the TDCP chain (2 of 119 epochs here at exactly one period)
  cfg.cycle_period = 0.375;
  cfg.tdcp.enabled = true;
  auto engine = std::make_unique<TightEngine<Ekf<Lx>>>(model, cfg);
  static_assert(TightEngine<Ekf<Lx>>::kCanTdcp, "the EKF takes TDCP rows");
  engine->set_phase(ph.data());
  std::vector<double> o_llh(3 * (n + 1)), o_res(obs.size());
  std::vector<std::int8_t> o_flag(obs.size());
  std::vector<std::int32_t> o_rows(ep.size());
  TightOutputs out;
  out.llh = o_llh.data();
  out.tdcp_residual = o_res.data();
  out.tdcp_flag = o_flag.data();
  out.tdcp_rows = o_rows.data();
  Eigen::internal::set_is_malloc_allowed(false);
  engine->run(init, P0, ImuCorrection{}, b0, d0, n, t.data(), dth.data(), dv.data(),
              static_cast<std::int64_t>(ep.size()), ep.data(), obs.data(), out);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == 0);
  EXPECT_TRUE(out.tdcp_used > static_cast<int>(ep.size() - 2) * ns - 3);
  EXPECT_TRUE(out.tdcp_slips_ins == 0);
  const std::int64_t last = out.n_out - 1;
  const double dN = (o_llh[3 * last] - lat) * 6.37e6, dE = (o_llh[3 * last + 1] - lon) * 6.37e6 * std::cos(lat);
  std::printf("engine with TDCP (%d states): %d rows used (%d rejected, %d INS slips, %d updates of %d epochs), "
              "final horizontal error %.3f m\n", Lx::kSize, out.tdcp_used, out.tdcp_rejected, out.tdcp_slips_ins,
              out.tdcp_updates, static_cast<int>(ep.size()), std::hypot(dN, dE));
  EXPECT_LT(std::hypot(dN, dE), 2.0);
}

int main() {
  engine_no_heap<Layout17>();
  engine_no_heap<LayoutTightTdLever>();
  std::mt19937 gen(7);
  std::normal_distribution<double> nd(0.0, 1.0);
  auto rnd_spd = [&](double scale) {
    StateCov<L> A;
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < N; ++j) A(i, j) = nd(gen);
    StateCov<L> P = scale * (A * A.transpose() / N + 0.1 * StateCov<L>::Identity());
    return P;
  };
  const StateCov<L> P_prev = rnd_spd(1.0);
  StateCov<L> Phi = StateCov<L>::Identity();
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) Phi(i, j) += 0.05 * nd(gen);
  const StateCov<L> Q = 0.01 * rnd_spd(1.0);
  StateCov<L> P = Phi * P_prev * Phi.transpose() + Q;
  const StateCov<L> Phi_P_prev = Phi * P_prev;

  // rows: random lines of sight, a lever arm
  TdcpUpdate<L> up;
  up.clear();
  const int m = 6;
  Eigen::Matrix<double, m, 2 * N> Ha = Eigen::Matrix<double, m, 2 * N>::Zero();
  Eigen::Matrix<double, m, 1> y, r;
  for (int i = 0; i < m; ++i) {
    TdcpRow<L> row;
    for (int j = 0; j < N; ++j) {
      row.H_cur[j] = (j < 9 || j == L::kClockBias) ? nd(gen) : 0.0;
      row.H_prev[j] = (j < 9 || j == L::kClockBias) ? nd(gen) : 0.0;
    }
    y[i] = 0.1 * nd(gen);
    r[i] = 1e-4 * (1.0 + i);
    up.add(row, y[i], r[i]);
    Ha.row(i).head<N>() = row.H_cur;
    Ha.row(i).tail<N>() = row.H_prev;
  }
  // explicit augmented update (x = 0, clone mean 0)
  Eigen::Matrix<double, 2 * N, 2 * N> Pa;
  Pa << P, Phi_P_prev, Phi_P_prev.transpose(), P_prev;
  const Eigen::Matrix<double, m, m> S = Ha * Pa * Ha.transpose() + Eigen::Matrix<double, m, 1>(r).asDiagonal().toDenseMatrix();
  const Eigen::Matrix<double, 2 * N, m> K = Pa * Ha.transpose() * S.inverse();
  const Eigen::Matrix<double, 2 * N, 1> xa = K * y;
  const Eigen::Matrix<double, 2 * N, 2 * N> Pa_post = Pa - K * S * K.transpose();

  StateVec<L> x = StateVec<L>::Zero();
  StateCov<L> Pk = P;
  Eigen::internal::set_is_malloc_allowed(false);
  const bool ok = up.covariance(Pk, Phi_P_prev, P_prev);
  double nis = 0.0;
  if (ok) nis = up.apply(x, Pk);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(ok);
  EXPECT_TRUE(g_eigen_asserts == 0);
  for (int i = 0; i < m; ++i) EXPECT_LT(std::abs(up.S(i) - S(i, i)), 1e-9 * S(i, i));
  EXPECT_LT((x - xa.head<N>()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((Pk - Pa_post.topLeftCorner<N, N>()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(std::abs(nis - y.dot(S.inverse() * y)), 1e-8 * nis);
  // select(): dropping rows 1 and 4 equals the update with the 4 others
  TdcpUpdate<L> up2;
  for (int i = 0; i < m; ++i) {
    TdcpRow<L> row;
    row.H_cur = Ha.row(i).head<N>();
    row.H_prev = Ha.row(i).tail<N>();
    up2.add(row, y[i], r[i]);
  }
  const bool keep[m] = {true, false, true, true, false, true};
  up2.select(keep);
  EXPECT_TRUE(up2.rows() == 4);
  EXPECT_LT(std::abs(up2.residual(2) - y[3]), 1e-15);
  TEST_MAIN_END()
}
