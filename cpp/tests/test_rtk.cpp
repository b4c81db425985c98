// The RTK engine (insnav/gnss/rtk.hpp) on a synthetic short baseline: noise-free dual-frequency
// code and phase with integer ambiguities; the engine fixes from the first epoch to the true
// position within 1 mm, and after construction it allocates nothing on the heap per epoch
// (Eigen's malloc check on).  MLAMBDA: the fixed vector of a well-conditioned problem is the
// rounded one.  PartialAr (gnss/ambiguity_resolution.hpp): the per-subset check callback (reject ->
// a smaller subset, stop -> no fix) and the bootstrapped success rate of a diagonal Q_a, the
// product formula (Teunissen 1998); FixValidator's rules over epochs; the common-satellite matching
// and reference choice shared by both carrier-phase engines (gnss/double_difference.hpp); the RTK/INS
// engine's robust screening of the single differences (engine/rtk_ins_engine.hpp, 2a.): outliers
// identified per satellite, no heap allocation in a flagged epoch.  Estimated ionosphere
// (iono_mode kEstimate) on a 20 km baseline with a known single-differenced ionosphere: the
// ionosphere and position columns of H against numerical derivatives of the innovations, the
// analytic factors -/+ (f_1 / f_k)^2 on phase / code, and the estimates converging to the truth.
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include "insnav/gnss/ambiguity_resolution.hpp"
#include "insnav/gnss/double_difference.hpp"
#include "insnav/gnss/lambda.hpp"
#include "insnav/gnss/rtk.hpp"
#include "insnav/engine/rtk_ins_engine.hpp"
#include "rtk_fixtures.hpp"
#include "test_util.hpp"

using namespace insnav;
using namespace insnav::gnss;

namespace {

using test_rtk::kL1;
using test_rtk::kL2;
using test_rtk::rows_for;

// An INS at rest at r_e (level, north-facing) started in an RTK/INS engine: position sigma 10 cm, the
// rest nearly known.
template <class Engine>
void start_static_ins(Engine& ins, const Vec3& r_e) {
  const Vec3 llh = wgs84::ecef_to_geodetic(r_e);
  NavState s0;
  s0.t = 1000.0;
  s0.lat = llh(0);
  s0.lon = llh(1);
  s0.h = llh(2);
  StateCov<Layout15> P0 = StateCov<Layout15>::Zero();
  P0.diagonal() << 0.01, 0.01, 0.01, 1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-10, 1e-10, 1e-10;
  ins.start(s0, P0, ImuCorrection{});
}

}  // namespace

int main() {
  const test_rtk::StaticScene sc = test_rtk::static_scene();
  const Mat3& C = sc.C_en;
  const Vec3& r_b = sc.r_b;
  const Vec3& r_r = sc.r_r;
  const std::vector<Vec3>& sats = sc.sats;
  const std::vector<double>&N1r = sc.N1r, &N2r = sc.N2r, &N1b = sc.N1b, &N2b = sc.N2b;
  RtkOptions o;
  o.tropo_model = false;
  o.mode = RtkMode::kKinematic;
  // 10 epochs of the exact static scene: every one fixed within 1 mm, no allocation from the third on
  const auto static_scene_fixes = [&](const RtkOptions& opt) {
    auto eng = std::make_unique<RtkEngine>(opt);
    double worst = 0.0;
    int fixed = 0;
    for (int e = 0; e < 10; ++e) {
      const auto rr = rows_for(r_r, sats, N1r, N2r, 1234.0 + e);
      const auto rb = rows_for(r_b, sats, N1b, N2b, -567.0 + 2 * e);
      if (e == 2) Eigen::internal::set_is_malloc_allowed(false);
      const RtkEpoch out = eng->process(1000.0 + e, rr.data(), 8, rb.data(), 8, true, r_b);
      if (out.status == RtkStatus::kFixed) {
        ++fixed;
        worst = std::max(worst, (out.r_e - r_r).norm());
      }
    }
    Eigen::internal::set_is_malloc_allowed(true);
    EXPECT_TRUE(fixed == 10);
    EXPECT_LT(worst, 1e-3);
    EXPECT_TRUE(g_eigen_asserts == 0);
    std::printf("rtk (phase error states %s): %d fixed epochs, worst %.2e m\n",
                gnss::phase_error_states(opt) ? "on" : "off", fixed, worst);
  };
  static_scene_fixes(o);
  // with the correlated phase error states (one Gauss-Markov state per ambiguity, the state block
  // beyond the ionosphere's)
  RtkOptions op = o;
  op.phase_corr_time_s = 30.0;
  op.phase_error_ratio = 0.5;
  static_scene_fixes(op);

  // MLAMBDA on a well-conditioned problem: the rounded vector, no allocation
  Lambda lam;
  AmbVec a(4);
  a << 1.1, -2.05, 3.02, 0.97;
  AmbMat Q = AmbMat::Identity(4, 4) * 0.01;
  Q(0, 1) = Q(1, 0) = 0.004;
  AmbCand fix;
  double s[2];
  Eigen::internal::set_is_malloc_allowed(false);
  const LambdaStatus st = lam.solve(a, Q, fix, s);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(st == LambdaStatus::kOk);
  EXPECT_TRUE(fix(0, 0) == 1 && fix(1, 0) == -2 && fix(2, 0) == 3 && fix(3, 0) == 1);
  EXPECT_TRUE(s[1] > s[0]);
  EXPECT_TRUE(g_eigen_asserts == 0);
  // PartialAr: 6 candidates, Q_a = 0.04 I (D = diag(Q_a) after the reduction)
  {
    auto ar = std::make_unique<PartialAr>();
    ArSettings st;
    st.min_fix = 2;
    const double av[6] = {3.02, -1.03, 7.0, 0.96, -4.01, 2.05};
    auto value = [&](int p) { return av[p]; };
    auto cov = [&](int p, int q) { return p == q ? 0.04 : 0.0; };
    int calls = 0, first = 0;
    Eigen::internal::set_is_malloc_allowed(false);
    const bool ok = ar->resolve(6, value, cov, st, [&](int n_fix) {
      if (calls++ == 0) first = n_fix;
      return n_fix > 4 ? ArVerdict::kReject : ArVerdict::kAccept;
    });
    Eigen::internal::set_is_malloc_allowed(true);
    EXPECT_TRUE(ok && first == 6 && calls == 3 && ar->n_used() == 4);
    const double p1 = std::erf(1.0 / (2.0 * std::sqrt(2.0 * 0.04)));
    EXPECT_LT(std::abs(ar->success_rate() - std::pow(p1, 4)), 1e-14);
    EXPECT_TRUE(ar->a_fix()(0) == 3 && ar->a_fix()(3) == 1);
    const bool stop = ar->resolve(6, value, cov, st, [](int) { return ArVerdict::kStop; });
    EXPECT_TRUE(!stop && ar->n_used() == 0 && ar->ratio() > 3.0);
    EXPECT_LT(std::abs(ar->success_rate() - std::pow(p1, 6)), 1e-14);  // the full set's when none is fixed
    st.min_success_rate = 0.5 * (std::pow(p1, 5) + std::pow(p1, 4));  // 6 and 5 fail the success rate, 4 passes
    calls = 0;
    EXPECT_TRUE(ar->resolve(6, value, cov, st, [&](int n_fix) { first = n_fix; ++calls; return ArVerdict::kAccept; }));
    EXPECT_TRUE(calls == 1 && first == 4 && ar->n_used() == 4);
  }
  // FixValidator: DD p = slot p+1 - slot 0, integers a(p) = 10 + p
  {
    auto v = std::make_unique<FixValidator<16>>();
    const FixRules r{5, 3, 6};
    auto sj = [](int p) { return p + 1; };
    auto si = [](int) { return 0; };
    auto a = [](int p) { return 10.0 + p; };
    auto epoch = [&](int n_fix, int n_cand) {
      v->begin_epoch();
      const ArVerdict x = (*v)(n_fix, n_cand, sj, si, a, r);
      v->end_epoch();
      return x;
    };
    EXPECT_TRUE(epoch(4, 8) == ArVerdict::kReject);  // fewer than min_fix, not every candidate
    EXPECT_TRUE(epoch(5, 8) == ArVerdict::kStop);    // a new small set: 1st of 3 repeats
    EXPECT_TRUE(epoch(5, 8) == ArVerdict::kStop);
    EXPECT_TRUE(epoch(5, 8) == ArVerdict::kAccept);  // 3rd consecutive epoch
    EXPECT_TRUE(epoch(3, 3) == ArVerdict::kAccept);  // every candidate, repeats the validated integers
    v->begin_epoch();
    v->end_epoch();  // an epoch without the set: the repeats start again
    EXPECT_TRUE(epoch(3, 3) == ArVerdict::kStop && v->confirm_count() == 1);
    v->invalidate(2);  // slot 2 re-initialised (slip): DD 1 no longer repeats
    EXPECT_TRUE(epoch(3, 3) == ArVerdict::kReject);
    EXPECT_TRUE(epoch(7, 8) == ArVerdict::kAccept);  // more than confirm_max: at once
  }
  // Common satellites and references (gnss/double_difference.hpp, shared by gnss/rtk.hpp and
  // engine/rtk_ins_engine.hpp): rover order kept; a satellite the base lacks, or without an orbit
  // on either side, is not common; the reference is the first of the highest elevation.
  {
    constexpr int C = RtkRow::kCols;
    std::vector<double> rov(5 * C, 0.0), bas(4 * C, 0.0);
    const int rk[5] = {3, 7, 64 + 2, 9, 11}, bk[4] = {11, 7, 3, 64 + 2};  // key 9: rover only
    for (int i = 0; i < 5; ++i) rov[i * C + RtkRow::kSat] = rk[i];
    for (int j = 0; j < 4; ++j) bas[j * C + RtkRow::kSat] = bk[j];
    rov[4 * C + RtkRow::kSatPos] = NAN;  // key 11: no rover orbit
    std::array<int, kMaxSatKeys> base_of{};
    int cr[5] = {-1, -1, -1, -1, -1}, cb[5] = {-1, -1, -1, -1, -1};
    const int n = match_common_satellites(rov.data(), 5, bas.data(), 4, base_of, cr, cb);
    EXPECT_TRUE(n == 3);
    EXPECT_TRUE(cr[0] == 0 && cb[0] == 2 && cr[1] == 1 && cb[1] == 1 && cr[2] == 2 && cb[2] == 3);
    EXPECT_TRUE(base_of[11] == 0 && base_of[9] == -1);
    bas[1 * C + RtkRow::kSatPos] = NAN;  // key 7: no base orbit
    EXPECT_TRUE(match_common_satellites(rov.data(), 5, bas.data(), 4, base_of, cr, cb) == 2 && cr[1] == 2);
    const double el[6] = {0.3, 0.9, 0.9, 0.2, 1.2, 0.5};
    const auto all = [](int) { return true; };
    const auto elev = [&](int k) { return el[k]; };
    EXPECT_TRUE(highest_elevation_reference(6, all, elev) == 4);
    EXPECT_TRUE(highest_elevation_reference(6, [](int k) { return k != 4; }, elev) == 1);  // first of equal
    EXPECT_TRUE(highest_elevation_reference(6, [](int) { return false; }, elev) == -1);
  }
  // RTK/INS robust screening of the single differences (engine/rtk_ins_engine.hpp, 2a.) on the same
  // static noise-free pair, the INS at the true rover position: a 30 m code outlier on one satellite
  // (epochs 4-5) and a 0.3-cycle phase outlier on another (epoch 7) are each identified as that
  // satellite alone, the solution stays fixed within 1 mm, and the flagged epochs (w-tests, rebuilds,
  // IGG-III) allocate nothing on the heap; a clean epoch flags nothing.
  {
    RtkInsConfig rc;
    rc.rtk.tropo_model = false;
    rc.rtk.n_freq = 1;  // one frequency: the geometry-free slip test would catch the phase outlier
    rc.rtk.min_success_rate = 0.0;
    rc.robust.screening = true;
    rc.code_chi2_row = 0.0;  // the screening alone
    rc.rtk.outlier_sigma = 0.0;
    auto ins = std::make_unique<RtkInsEngine<64>>(ImuErrorModel{}, rc);
    start_static_ins(*ins, r_r);
    int fixed_ins = 0, screened[10] = {};
    double worst_ins = 0.0;
    for (int e = 0; e < 10; ++e) {
      auto rr = rows_for(r_r, sats, N1r, N2r, 1234.0 + e);
      const auto rb = rows_for(r_b, sats, N1b, N2b, -567.0 + 2 * e);
      if (e == 4 || e == 5) rr[3 * RtkRow::kCols + RtkRow::kFreq0] += 30.0;      // satellite 4, L1 code
      if (e == 7) rr[5 * RtkRow::kCols + RtkRow::kFreq0 + 1] += 0.3;            // satellite 6, L1 phase
      if (e == 2) Eigen::internal::set_is_malloc_allowed(false);
      const RtkInsEpoch out = ins->apply_epoch(rr.data(), 8, rb.data(), 8, true, r_b);
      screened[e] = out.screened;
      if (out.status == RtkStatus::kFixed) {
        ++fixed_ins;
        worst_ins = std::max(worst_ins, (out.r_e - r_r).norm());
      }
    }
    Eigen::internal::set_is_malloc_allowed(true);
    EXPECT_TRUE(screened[4] == 1 && screened[5] == 1 && screened[7] == 1);
    EXPECT_TRUE(screened[0] + screened[1] + screened[2] + screened[3] + screened[6] + screened[8] + screened[9] == 0);
    EXPECT_TRUE(fixed_ins >= 8);
    EXPECT_LT(worst_ins, 1e-3);
    EXPECT_TRUE(g_eigen_asserts == 0);
    std::printf("rtk/ins screening: %d fixed epochs, worst %.2e m\n", fixed_ins, worst_ins);
  }
  // Estimated ionosphere, 20 km baseline: rover rows carry the single-differenced ionosphere I_k
  {
    const Vec3 r_r2 = r_b + C * Vec3(14000.0, -14000.0, 20.0);
    std::vector<double> iono(8);
    for (int k = 0; k < 8; ++k) iono[k] = 0.04 * (k - 3.5) / 3.5;  // -4 .. +4 cm on L1
    RtkOptions oi = o;
    oi.iono_mode = IonoMode::kEstimate;
    oi.iono_sigma_per_10km_m = 0.03;
    oi.ar_mode = ArMode::kFixAndHold;  // the held integers make the float double-differenced ionosphere exact
    auto ei = std::make_unique<RtkEngine>(oi);
    const auto rr = rows_for(r_r2, sats, N1r, N2r, 1234.0, &iono);
    const auto rb = rows_for(r_b, sats, N1b, N2b, -567.0);
    ei->process(2000.0, rr.data(), 8, rb.data(), 8, true, r_b);
    constexpr int kM = 16;
    std::vector<double> y0(kM), y1(kM), H(kM * kMaxStates), H1(kM * kMaxStates);
    const double mu2 = (kL2 / kL1) * (kL2 / kL1);
    double worst_h = 0.0, worst_mu = 0.0, worst_pos = 0.0;
    int n_iono_cols = 0;
    for (int code = 0; code < 2; ++code) {
      const int m = ei->linearised_rows(code, y0.data(), H.data(), kM);
      EXPECT_TRUE(m == 14);  // 7 double differences on each of two frequencies
      for (int k = 0; k < 8; ++k) {
        const int j = ei->iono_index(k + 1);
        EXPECT_TRUE(j >= RtkLayout::kIono);
        if (j < 0) continue;
        ++n_iono_cols;
        const double eps = 1e-3, x0 = ei->state(j);
        ei->state(j) = x0 + eps;
        ei->linearised_rows(code, y1.data(), H1.data(), kM);
        ei->state(j) = x0;
        for (int r = 0; r < m; ++r) {
          // y = z - h(x): dh/dx_j = -(y(x + eps) - y(x)) / eps, exact (h is linear in I)
          worst_h = std::max(worst_h, std::abs(-(y1[r] - y0[r]) / eps - H[r * kMaxStates + j]));
          const double h = H[r * kMaxStates + j];
          if (h != 0.0) worst_mu = std::max(worst_mu, std::abs(std::abs(h) - (r < 7 ? 1.0 : mu2)));  // slot 0 rows first
        }
      }
      // position columns: a 1 mm step; H omits the derivative of the Sagnac term, omega_e |r^s| / c ~ 6e-6
      // per satellite (RTKLIB's H omits it too), and the nonlinearity is ~ 1 mm / 20000 km
      for (int i = 0; i < 3; ++i) {
        const double eps = 1e-3, x0 = ei->state(RtkLayout::kPos + i);
        ei->state(RtkLayout::kPos + i) = x0 + eps;
        ei->linearised_rows(code, y1.data(), H1.data(), kM);
        ei->state(RtkLayout::kPos + i) = x0;
        for (int r = 0; r < m; ++r)
          worst_pos = std::max(worst_pos, std::abs(-(y1[r] - y0[r]) / eps - H[r * kMaxStates + RtkLayout::kPos + i]));
      }
    }
    EXPECT_TRUE(n_iono_cols == 16);
    EXPECT_LT(worst_h, 1e-9);
    EXPECT_LT(worst_mu, 1e-12);
    EXPECT_LT(worst_pos, 3e-5);
    // signs: satellite 1 (80 deg) is the reference of every row: its column +mu on phase, -mu on code;
    // every other satellite's column -mu on phase, +mu on code
    {
      int sign_ok = 0, rows = 0;
      for (int code = 0; code < 2; ++code) {
        const int m = ei->linearised_rows(code, y0.data(), H.data(), kM);
        const double sgn = code ? 1.0 : -1.0;
        for (int r = 0; r < m; ++r, ++rows) {
          int pos = 0, neg = 0;
          for (int k = 0; k < 8; ++k) {
            const double h = sgn * H[r * kMaxStates + ei->iono_index(k + 1)];
            if (h > 0.0) ++pos;
            if (h < 0.0) ++neg;
            if (k == 0 && h < 0.0) ++sign_ok;
          }
          EXPECT_TRUE(pos == 1 && neg == 1);
        }
      }
      EXPECT_TRUE(rows == 28 && sign_ok == 28);
    }
    // noise-free epochs: fixed at the true position (to the few mm of the compromise between the
    // phase sigma and the prior's pull towards I = 0), the double-differenced ionosphere (the
    // observable part: against satellite 1, the reference) to 1 mm once the integers are held
    int fixed_i = 0;
    double worst_r = 0.0, worst_i = 0.0;
    for (int e = 1; e < 30; ++e) {
      const auto r2 = rows_for(r_r2, sats, N1r, N2r, 1234.0 + e, &iono);
      const auto b2 = rows_for(r_b, sats, N1b, N2b, -567.0 + 2 * e);
      if (e == 3) Eigen::internal::set_is_malloc_allowed(false);
      const RtkEpoch out = ei->process(2000.0 + e, r2.data(), 8, b2.data(), 8, true, r_b);
      if (e >= 20 && out.status == RtkStatus::kFixed) {
        ++fixed_i;
        worst_r = std::max(worst_r, (out.r_e - r_r2).norm());
      }
    }
    Eigen::internal::set_is_malloc_allowed(true);
    for (int k = 1; k < 8; ++k) {
      double v = 0.0, sg = 0.0, v0 = 0.0, sg0 = 0.0;
      EXPECT_TRUE(ei->iono_estimate(k + 1, v, sg) && ei->iono_estimate(1, v0, sg0));
      EXPECT_TRUE(ei->iono_dd_estimate(k + 1, v, sg));
      worst_i = std::max(worst_i, std::abs(v - (iono[k] - iono[0])));
      EXPECT_LT(sg, 0.01);
    }
    {
      double v = 0.0, sg = 0.0;
      EXPECT_TRUE(!ei->iono_dd_estimate(1, v, sg));  // the reference
    }
    EXPECT_TRUE(fixed_i == 10);
    EXPECT_LT(worst_r, 2e-3);
    EXPECT_LT(worst_i, 1e-3);
    EXPECT_TRUE(g_eigen_asserts == 0);
    std::printf("rtk iono: dH %.1e, dmu %.1e, dpos %.1e; fixed %d, worst %.2e m, iono worst %.2e m\n", worst_h,
                worst_mu, worst_pos, fixed_i, worst_r, worst_i);
  }
  // RTK/INS on the same 20 km scene with the between-receiver ionosphere on the rover rows (-4 .. +4 cm
  // on L1), the INS static at the true rover (engine/rtk_ins_engine.hpp: the ionosphere states of
  // iono_mode kEstimate and the default correlated phase error states, one extra-state block): the
  // ionosphere states fix at the true position to a few mm, and the epochs allocate nothing on the
  // heap; without an ionosphere term the same epochs fix with the ionosphere in the position or not at all.
  {
    const Vec3 r_r2 = r_b + C * Vec3(14000.0, -14000.0, 20.0);
    std::vector<double> iono(8);
    for (int k = 0; k < 8; ++k) iono[k] = 0.04 * (k - 3.5) / 3.5;
    double worst_est = 0.0, worst_off = 0.0;
    int fixed_est = 0, fixed_off = 0;
    for (const IonoMode mode : {IonoMode::kEstimate, IonoMode::kOff}) {
      RtkInsConfig rc;
      rc.rtk.tropo_model = false;
      rc.rtk.min_success_rate = 0.0;
      rc.rtk.iono_mode = mode;
      rc.rtk.iono_sigma_per_10km_m = 0.03;
      EXPECT_TRUE(rc.rtk.phase_corr_time_s > 0.0 && rc.rtk.phase_error_ratio > 0.0);  // the defaults: phase error states
      auto ins = std::make_unique<RtkInsEngine<64>>(ImuErrorModel{}, rc);
      start_static_ins(*ins, r_r2);
      for (int e = 0; e < 20; ++e) {
        const auto rr = rows_for(r_r2, sats, N1r, N2r, 1234.0 + e, &iono);
        const auto rb = rows_for(r_b, sats, N1b, N2b, -567.0 + 2 * e);
        if (e == 2) Eigen::internal::set_is_malloc_allowed(false);
        const RtkInsEpoch out = ins->apply_epoch(rr.data(), 8, rb.data(), 8, true, r_b);
        if (e >= 10 && out.status == RtkStatus::kFixed) {
          (mode == IonoMode::kEstimate ? fixed_est : fixed_off) += 1;
          double& w = mode == IonoMode::kEstimate ? worst_est : worst_off;
          w = std::max(w, (out.r_e - r_r2).norm());
        }
      }
      Eigen::internal::set_is_malloc_allowed(true);
    }
    EXPECT_TRUE(fixed_est == 10);
    EXPECT_LT(worst_est, 5e-3);
    EXPECT_TRUE(fixed_off < 10 || worst_off > 1e-2);
    EXPECT_TRUE(g_eigen_asserts == 0);
    std::printf("rtk/ins iono: states fixed %d, worst %.2e m; none fixed %d, worst %.2e m\n", fixed_est, worst_est,
                fixed_off, worst_off);
  }
  TEST_MAIN_END()
}
