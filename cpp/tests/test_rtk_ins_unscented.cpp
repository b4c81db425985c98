// The unscented variants of the tight RTK/INS engine (engine/rtk_ins_engine.hpp, RtkInsEngine<kMaxAmb,
// RbUkf<Layout15>> and <..., Ukf<Layout15>>):
//  * reduction: with a navigation error covariance small enough that the nonlinear error model
//    (seed 000 eqs. (1)-(7)) is linear over the cycle, the statistically linearised transition of
//    a 1 s cycle, Phi = C^T P_0^-1 (Sarkka 2008 eq. (13)), equals the EKF's product of the
//    intervals' transitions (Ekf::cycle_transition) during a turn with acceleration, to the two
//    discretisations (3.2e-4 of a sigma, independent of the covariance's size); with a 20 deg
//    attitude uncertainty it does not (the nonlinearity is what the UT sees);
//  * a cycle without propagation has Phi = I exactly;
//  * a static receiver with an exact IMU and noise-free dual-frequency rows: the three filters fix at
//    the true position within 1 mm, RB-UKF and UKF give the same solution (the joint update is the
//    engine's linear one), and the whole run() after construction allocates nothing on the heap
//    (Eigen's malloc check on);
//  * the unscented RTS smoother's conditioning on a fixed epoch (ClosedLoop::condition_for_smoother,
//    condition_prediction_for_smoother with the engine's Phi): two epochs with no propagation between
//    them (Phi = I) record the EKF's moments, so the gain C Pp^-1 is I and the smoothed estimate of the
//    earlier epoch is exactly the later one's, as for the EKF (Sarkka 2008 eqs. (13)-(15); Rauch, Tung
//    & Striebel 1965).
#include <algorithm>
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/engine/rtk_ins_engine.hpp"
#include "insnav/filter/ukf.hpp"
#include "rtk_fixtures.hpp"
#include "test_util.hpp"

using namespace insnav;
using namespace insnav::gnss;

namespace {

using Cov15 = StateCov<Layout15>;
using test_rtk::rows_for;

NavState start_state(double lat, double lon, double h, double t) {
  NavState s;
  s.t = t;
  s.lat = lat;
  s.lon = lon;
  s.h = h;
  return s;
}

// The transition of one 1 s cycle of a turning, accelerating IMU (100 Hz) from P0.
template <class F>
Cov15 cycle_phi(const Cov15& P0) {
  RtkInsConfig rc;
  auto eng = std::make_unique<RtkInsEngine<64, F>>(ImuErrorModel{}, rc);
  NavState s0 = start_state(0.6, 0.3, 100.0, 0.0);
  s0.v_n = Vec3(15.0, 5.0, 0.0);
  eng->start(s0, P0, ImuCorrection{});
  auto& core = eng->core();
  const double dt = 0.01, g = wgs84::gravity(s0.lat, s0.h);
  double t_prev = 0.0;
  for (int k = 1; k <= 100; ++k) {
    ImuIncrement raw;
    raw.t = k * dt;
    raw.dt = dt;
    raw.dtheta_b = Vec3(0.02, -0.01, 0.15) * dt;  // yaw rate 0.15 rad/s, some roll and pitch rate
    raw.dv_b = Vec3(1.5, 0.8, -g) * dt;           // forward and lateral acceleration
    core.process_sample(raw, t_prev, kInf, []() { return kInf; }, []() {});
    t_prev = raw.t;
  }
  core.close_cycle();
  return eng->cycle_phi();
}

// max over entries of |Phi_a - Phi_b| scaled to sigmas: the contribution of each initial state's
// 1-sigma to each final state's 1-sigma (of the EKF's Phi P0 Phi^T)
double scaled_difference(const Cov15& Pa, const Cov15& Pb, const Cov15& P0) {
  const Cov15 P1 = Pb * P0 * Pb.transpose();
  double worst = 0.0;
  for (int i = 0; i < 15; ++i)
    for (int j = 0; j < 15; ++j)
      worst = std::max(worst, std::abs(Pa(i, j) - Pb(i, j)) * std::sqrt(P0(j, j) / P1(i, i)));
  return worst;
}

struct StaticRun {
  std::vector<std::int32_t> status;
  std::vector<double> r_e, r_float_e;
  int asserts = 0;
};

template <class F>
StaticRun run_static(const Vec3& r_r, const Vec3& r_b, const std::vector<Vec3>& sats, const std::vector<double>& N1r,
                     const std::vector<double>& N2r, const std::vector<double>& N1b, const std::vector<double>& N2b) {
  constexpr int E = 10;
  RtkInsConfig rc;
  rc.rtk.tropo_model = false;
  rc.rtk.min_success_rate = 0.0;
  auto eng = std::make_unique<RtkInsEngine<64, F>>(ImuErrorModel{}, rc);
  const Vec3 llh = wgs84::ecef_to_geodetic(r_r);
  const NavState s0 = start_state(llh(0), llh(1), llh(2), 1000.0);
  Cov15 P0 = Cov15::Zero();
  P0.diagonal() << 1.0, 1.0, 1.0, 1e-2, 1e-2, 1e-2, 1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6, 1e-10, 1e-10, 1e-10;
  // exact increments of a level, north-facing IMU at rest: omega_ie_n and the gravity reaction
  const int n = 1020;
  const double dt = 0.01, g = wgs84::gravity(llh(0), llh(2));
  std::vector<double> t(n), dth(3 * n), dv(3 * n);
  const Vec3 w = wgs84::omega_ie_n(llh(0));
  for (int k = 0; k < n; ++k) {
    t[k] = 1000.0 + (k + 1) * dt;
    for (int i = 0; i < 3; ++i) {
      dth[3 * k + i] = w(i) * dt;
      dv[3 * k + i] = i == 2 ? -g * dt : 0.0;
    }
  }
  std::vector<double> rover, base;
  std::vector<RtkInsRecord> recs(E);
  for (int e = 0; e < E; ++e) {
    const auto rr = rows_for(r_r, sats, N1r, N2r, 1234.0 + e);
    const auto rb = rows_for(r_b, sats, N1b, N2b, -567.0 + 2 * e);
    recs[e].t = 1000.505 + e;
    recs[e].begin = 8 * e;
    recs[e].end = 8 * (e + 1);
    recs[e].base_begin = 8 * e;
    recs[e].base_end = 8 * (e + 1);
    rover.insert(rover.end(), rr.begin(), rr.end());
    base.insert(base.end(), rb.begin(), rb.end());
  }
  StaticRun res;
  res.status.assign(E, -1);
  res.r_e.assign(3 * E, NAN);
  res.r_float_e.assign(3 * E, NAN);
  RtkInsOutputs out;
  out.status = res.status.data();
  out.r_e = res.r_e.data();
  out.r_float_e = res.r_float_e.data();
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  eng->run(s0, P0, ImuCorrection{}, n, t.data(), dth.data(), dv.data(), E, recs.data(), rover.data(), base.data(),
           r_b, out);
  Eigen::internal::set_is_malloc_allowed(true);
  res.asserts = g_eigen_asserts - before;
  return res;
}

// Epoch 0 the start (P0); epoch 1 closed without propagation and conditioned (dx1, dP1: a fixed
// solution); epoch 2 closed without propagation, its prediction from the conditioned epoch 1, and
// conditioned itself (dx2, dP2); then the backward pass.
template <class F>
void conditioned_without_propagation(const Cov15& P0, const StateVec<Layout15>& dx1, const Cov15& dP1,
                                     const StateVec<Layout15>& dx2, const Cov15& dP2,
                                     SmootherEpoch<Layout15>* rec, SmoothedEpoch<Layout15>* out, std::int64_t& n,
                                     int& asserts) {
  RtkInsConfig rc;
  auto eng = std::make_unique<RtkInsEngine<64, F>>(ImuErrorModel{}, rc);
  auto& core = eng->core();
  core.record_for_smoother(rec, 4);
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);  // the recording, the conditioning and the backward pass
  eng->start(start_state(0.6, 0.3, 100.0, 0.0), P0, ImuCorrection{});
  core.close_cycle();
  core.condition_prediction_for_smoother(eng->cycle_phi());  // nothing conditioned before: no-op
  core.condition_for_smoother(dx1, dP1);
  core.start_cycle();
  core.close_cycle();
  core.condition_prediction_for_smoother(eng->cycle_phi());  // the unscented filters' (the EKF's in close_cycle)
  core.condition_for_smoother(dx2, dP2);
  core.start_cycle();
  n = core.recorded_epochs();
  rts_backward<Layout15>(rec, n, out);
  Eigen::internal::set_is_malloc_allowed(true);
  asserts = g_eigen_asserts - before;
}

}  // namespace

int main() {
  // (1) reduction of the statistically linearised cycle transition to the EKF's
  Cov15 P0 = Cov15::Zero();
  P0.diagonal() << 1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6, 1e-10, 1e-10, 1e-10, 1e-8, 1e-8, 1e-8, 1e-12, 1e-12, 1e-12;
  const Cov15 phi_ekf = cycle_phi<Ekf<Layout15>>(P0);
  const Cov15 phi_rb = cycle_phi<RbUkf<Layout15>>(P0);
  const Cov15 phi_ukf = cycle_phi<Ukf<Layout15>>(P0);
  const double d_lin = scaled_difference(phi_rb, phi_ekf, P0);
  // what is left is the two discretisations (the EKF's Phi = I + F dt + (F dt)^2 / 2 at the middle of each
  // 20 ms interval, the UT's RK4 of the nonlinear model with the INS at the start, middle and end):
  // 3.2e-4 sigma, the same for a covariance 1e4 times smaller (no nonlinearity left in it)
  EXPECT_LT(d_lin, 1e-3);
  const Cov15 P_small = P0 * 1e-4;
  const double d_small = scaled_difference(cycle_phi<RbUkf<Layout15>>(P_small), cycle_phi<Ekf<Layout15>>(P_small), P_small);
  EXPECT_LT(std::abs(d_small - d_lin), 0.01 * d_lin);
  EXPECT_TRUE((phi_rb - phi_ukf).cwiseAbs().maxCoeff() == 0.0);  // the same time update
  EXPECT_LT(0.5, (phi_ekf - Cov15::Identity()).cwiseAbs().maxCoeff());  // a non-trivial transition
  // the same with a 20 deg attitude uncertainty: the error model is no longer linear over the cycle
  Cov15 P_big = P0;
  P_big.diagonal().segment<3>(6).setConstant(std::pow(20.0 * M_PI / 180.0, 2));
  const double d_big = scaled_difference(cycle_phi<RbUkf<Layout15>>(P_big), cycle_phi<Ekf<Layout15>>(P_big), P_big);
  EXPECT_LT(100.0 * d_lin, d_big);
  std::printf("cycle Phi, UT vs EKF (sigma-scaled): %.2e linear regime (%.2e with P / 1e4), %.2e at 20 deg attitude "
              "sigma\n", d_lin, d_small, d_big);

  // (2) a cycle without propagation: Phi = I exactly
  {
    RtkInsConfig rc;
    auto eng = std::make_unique<RtkInsEngine<64, RbUkf<Layout15>>>(ImuErrorModel{}, rc);
    eng->start(start_state(0.6, 0.3, 100.0, 0.0), P0, ImuCorrection{});
    eng->core().close_cycle();
    EXPECT_TRUE(eng->cycle_phi() == Cov15::Identity());
  }

  // (2a) the smoother over fixed epochs without propagation between them: the EKF's records, gain I
  {
    std::mt19937 rng(7);
    std::normal_distribution<double> nd;
    Cov15 B1, B2;
    StateVec<Layout15> dx1, dx2;
    for (int i = 0; i < 15; ++i) {
      dx1[i] = 0.01 * nd(rng) * std::sqrt(P0(i, i));
      dx2[i] = 0.01 * nd(rng) * std::sqrt(P0(i, i));
      for (int j = 0; j < 15; ++j) {
        B1(i, j) = 0.05 * nd(rng);
        B2(i, j) = 0.05 * nd(rng);
      }
    }
    // dP = S B B' S (S = sqrt(diag P0)): positive semi-definite, well below P0 (P0 - dP stays positive definite)
    const Cov15 S = P0.diagonal().cwiseSqrt().asDiagonal();
    const Cov15 dP1 = S * B1 * B1.transpose() * S;
    const Cov15 dP2 = dP1 + S * B2 * B2.transpose() * S;
    SmootherEpoch<Layout15> rec[3][4];
    SmoothedEpoch<Layout15> out[3][4];
    std::int64_t n[3] = {0, 0, 0};
    int asserts[3] = {0, 0, 0};
    conditioned_without_propagation<Ekf<Layout15>>(P0, dx1, dP1, dx2, dP2, rec[0], out[0], n[0], asserts[0]);
    conditioned_without_propagation<RbUkf<Layout15>>(P0, dx1, dP1, dx2, dP2, rec[1], out[1], n[1], asserts[1]);
    conditioned_without_propagation<Ukf<Layout15>>(P0, dx1, dP1, dx2, dP2, rec[2], out[2], n[2], asserts[2]);
    double d_rec = 0.0, d_s = 0.0, d_P = 0.0;
    for (int f = 0; f < 3; ++f) {
      EXPECT_TRUE(n[f] == 3);
      EXPECT_TRUE(asserts[f] == 0);  // no heap allocation (and no other Eigen assertion)
      const SmootherEpoch<Layout15>& e2 = rec[f][2];
      const SmootherEpoch<Layout15>& k2 = rec[0][2];
      // the prediction from the conditioned epoch 1 (xp = dx1, Pp = P0 - dP1, C = P0 - dP1): the EKF's
      d_rec = std::max({d_rec, (e2.x_pred - k2.x_pred).cwiseAbs().maxCoeff(), (e2.P_pred - k2.P_pred).cwiseAbs().maxCoeff(),
                        (e2.C - k2.C).cwiseAbs().maxCoeff(), (e2.x_pred - dx1).cwiseAbs().maxCoeff(),
                        (e2.C - (P0 - dP1)).cwiseAbs().maxCoeff(), (e2.P_pred - (P0 - dP1)).cwiseAbs().maxCoeff()});
      // gain I: epoch 1 smoothed = epoch 2's estimate (dx2, P0 - dP2); relative to P0's scale
      for (int i = 0; i < 15; ++i) {
        d_s = std::max(d_s, std::abs(out[f][1].s[i] - dx2[i]) / std::sqrt(P0(i, i)));
        for (int j = 0; j < 15; ++j)
          d_P = std::max(d_P, std::abs(out[f][1].P(i, j) - (P0 - dP2)(i, j)) / std::sqrt(P0(i, i) * P0(j, j)));
      }
    }
    EXPECT_TRUE(d_rec == 0.0);  // the same arithmetic: P0 - dP1 (Phi = I exactly)
    EXPECT_LT(d_s, 1e-12);
    EXPECT_LT(d_P, 1e-12);
    // not trivially met: without the conditioned prediction s_1 would be dx1 + dx2, dx1 / sigma ~ 0.01
    EXPECT_LT(1e-3, (dx1.array() / P0.diagonal().array().sqrt()).abs().maxCoeff());
    std::printf("smoother over fixed epochs without propagation: records vs EKF %.1e, s_1 - s_2 %.1e sigma, "
                "Ps_1 - Ps_2 %.1e\n", d_rec, d_s, d_P);
  }

  // (3) static receiver, exact IMU, noise-free rows: fixed at the truth, RB-UKF = UKF, no heap per epoch
  const test_rtk::StaticScene sc = test_rtk::static_scene();
  const Vec3& r_b = sc.r_b;
  const Vec3& r_r = sc.r_r;
  const std::vector<Vec3>& sats = sc.sats;
  const std::vector<double>&N1r = sc.N1r, &N2r = sc.N2r, &N1b = sc.N1b, &N2b = sc.N2b;
  const StaticRun ekf = run_static<Ekf<Layout15>>(r_r, r_b, sats, N1r, N2r, N1b, N2b);
  const StaticRun rb = run_static<RbUkf<Layout15>>(r_r, r_b, sats, N1r, N2r, N1b, N2b);
  const StaticRun ukf = run_static<Ukf<Layout15>>(r_r, r_b, sats, N1r, N2r, N1b, N2b);
  double worst[3] = {0.0, 0.0, 0.0}, rb_ukf = 0.0, rb_ekf = 0.0;
  int fixed[3] = {0, 0, 0};
  const StaticRun* runs[3] = {&ekf, &rb, &ukf};
  for (int e = 0; e < 10; ++e) {
    for (int f = 0; f < 3; ++f) {
      const StaticRun& r = *runs[f];
      if (r.status[e] == static_cast<int>(RtkStatus::kFixed)) {
        ++fixed[f];
        worst[f] = std::max(worst[f], (Vec3(r.r_e[3 * e], r.r_e[3 * e + 1], r.r_e[3 * e + 2]) - r_r).norm());
      }
    }
    for (int i = 0; i < 3; ++i) {
      rb_ukf = std::max(rb_ukf, std::abs(rb.r_float_e[3 * e + i] - ukf.r_float_e[3 * e + i]));
      rb_ekf = std::max(rb_ekf, std::abs(rb.r_float_e[3 * e + i] - ekf.r_float_e[3 * e + i]));
    }
  }
  for (int f = 0; f < 3; ++f) {
    EXPECT_TRUE(fixed[f] >= 9);
    EXPECT_LT(worst[f], 1e-3);
    EXPECT_TRUE(runs[f]->asserts == 0);  // no heap allocation in run() (and no other Eigen assertion)
  }
  EXPECT_TRUE(rb_ukf == 0.0);  // the same filter: unscented time update, the engine's linear joint update
  EXPECT_LT(rb_ekf, 1e-3);
  std::printf("static exact IMU: fixed %d/%d/%d of 10 (EKF/RB-UKF/UKF), worst %.1e/%.1e/%.1e m; float RB-UKF - EKF "
              "%.1e m\n",
              fixed[0], fixed[1], fixed[2], worst[0], worst[1], worst[2], rb_ekf);
  TEST_MAIN_END()
}
