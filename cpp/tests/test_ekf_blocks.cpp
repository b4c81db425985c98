// The EKF's block-structured hot path against the dense formulas it replaces:
// the layout contract of kDiagonalAuxDynamics (F and Qc block structure),
// block_transition / block_propagate_covariance vs I + F dt + (F dt)^2/2 and
// Phi P Phi^T + Q_d, the structured Joseph update vs the dense one, no heap in
// propagate/update, the loose engine's output options (sigma_cols,
// output_decimation) and its adaptive measurement noise.

// Count Eigen assertions (also in Release) so that EIGEN_RUNTIME_NO_MALLOC is live.
#include "eigen_malloc_check.hpp"  // first: before any Eigen header

#include <memory>
#include <random>
#include <vector>

#include "insnav/engine/loose_engine.hpp"
#include "insnav/filter/ekf.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

double rel(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).norm() / b.norm(); }

/// A linear measurement h(dx) = H dx (the Meas interface of Ekf::update).
template <class L>
struct LinMeas {
  LinearMeasurement<L> lin;
  const LinearMeasurement<L>& linear() const { return lin; }
};

/// A varied INS point: latitude, height, velocity, attitude, f and omega drawn at random.
InsPoint random_point(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  InsPoint p;
  const Vec3 rpy(0.3 * u(rng), 0.3 * u(rng), 3.0 * u(rng));
  p.set(1.2 * u(rng), 500.0 * (1.0 + u(rng)), Vec3(30.0 * u(rng), 30.0 * u(rng), 2.0 * u(rng)),
        quat_from_euler(rpy).toRotationMatrix(), Vec3(2.0 * u(rng), 2.0 * u(rng), -9.8 + u(rng)),
        Vec3(0.1 * u(rng), 0.1 * u(rng), 0.3 * u(rng)));
  return p;
}

ImuErrorModel random_model(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.5, 2.0);
  ImuErrorModel m;
  m.acc_vrw = Vec3(1e-3 * u(rng), 2e-3 * u(rng), 1e-3 * u(rng));  // anisotropic: Q_nn is not diagonal
  m.gyro_arw = Vec3(1e-4 * u(rng), 1e-4 * u(rng), 3e-4 * u(rng));
  m.acc_bias_tau = Vec3(3600.0 * u(rng), kInf, 1800.0);
  m.gyro_bias_rw = Vec3::Constant(1e-7);
  m.odo_scale_tau = 900.0 * u(rng);  // Layout16Odo: a decaying odometer scale factor (q = 2 sigma^2 / tau)
  return m;
}

template <class L>
StateCov<L> random_spd(std::mt19937& rng) {
  std::normal_distribution<double> nd;
  StateCov<L> A;
  for (int i = 0; i < L::kSize; ++i)
    for (int j = 0; j < L::kSize; ++j) A(i, j) = nd(rng);
  StateVec<L> s = StateVec<L>::Constant(1e-3);
  s.template head<9>() << 2.0, 2.0, 4.0, 0.1, 0.1, 0.2, 1e-2, 1e-2, 3e-2;
  const StateCov<L> D = s.asDiagonal();
  return D * (A * A.transpose() / L::kSize + 0.1 * StateCov<L>::Identity()) * D;
}

// --- the layout contract behind the block path ------------------------------
template <class L>
void test_structure() {
  static_assert(kDiagonalAuxDynamics<L>);
  constexpr int N = 9, K = L::kSize - 9;
  std::mt19937 rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const InsPoint p = random_point(rng);
    const ImuErrorModel m = random_model(rng);
    const StateCov<L> F = linear_F<L>(p, m), Qc = continuous_GQG<L>(p, m);
    EXPECT_TRUE((F.template bottomLeftCorner<K, N>().array() == 0.0).all());
    const Eigen::Matrix<double, K, K> Faa = F.template bottomRightCorner<K, K>();
    EXPECT_TRUE(Faa.isDiagonal(0.0));
    EXPECT_TRUE((Qc.template bottomLeftCorner<K, N>().array() == 0.0).all());
    EXPECT_TRUE((Qc.template topRightCorner<N, K>().array() == 0.0).all());
    const Eigen::Matrix<double, K, K> Qaa = Qc.template bottomRightCorner<K, K>();
    EXPECT_TRUE(Qaa.isDiagonal(0.0));

    // block_transition == transition
    for (double dt : {0.005, 0.1, 1.0}) {
      NavAuxTransition<L> phi;
      block_transition<L>(F, dt, phi);
      const StateCov<L> Phi = transition<L>(F, dt);
      EXPECT_LT(rel(phi.U, Phi.template topRows<N>()), 1e-15);
      EXPECT_LT(rel(phi.d, Phi.template bottomRightCorner<K, K>().diagonal()), 1e-15);
      EXPECT_TRUE((Phi.template bottomLeftCorner<K, N>().array() == 0.0).all());
    }
  }
}

// --- Ekf::propagate (block path) vs the dense formula ------------------------
template <class L>
void test_propagate_vs_dense() {
  std::mt19937 rng(3);
  std::normal_distribution<double> nd;
  const ImuErrorModel m = random_model(rng);
  const StateCov<L> P0 = random_spd<L>(rng);
  Ekf<L> ekf(m);
  ekf.initialize(P0);
  StateCov<L> P = ekf.P();
  StateVec<L> x = StateVec<L>::Zero();
  double worst_P = 0.0, worst_x = 0.0;
  for (int k = 0; k < 200; ++k) {
    InsInterval iv;
    iv.dt = (k % 7 == 3) ? 0.013 : 0.1;  // short split intervals as at GNSS epochs
    iv.mid = random_point(rng);
    if (k == 50) {  // an update without feedback: x != 0 from here on
      LinMeas<L> meas;
      meas.lin.residual.resize(6);
      meas.lin.H.setZero(6, L::kSize);
      meas.lin.R.setZero(6, 6);
      for (int i = 0; i < 6; ++i) {
        meas.lin.residual[i] = nd(rng);
        meas.lin.H(i, i) = 1.0;
        meas.lin.R(i, i) = 0.1;
      }
      meas.lin.n_cols = 6;
      EXPECT_TRUE(ekf.update(meas, 0.0).applied);
      EXPECT_TRUE(kalman_update<L>(x, P, meas.lin, 0.0).applied);
    }
    ekf.propagate(iv);
    // dense reference, exactly the pre-block formula
    const StateCov<L> F = linear_F<L>(iv.mid, m);
    const StateCov<L> Phi = transition<L>(F, iv.dt);
    const StateCov<L> Qc = continuous_GQG<L>(iv.mid, m);
    P = Phi * P * Phi.transpose() + discrete_Q<L>(Phi, Qc, iv.dt);
    P = 0.5 * (P + P.transpose()).eval();
    x = Phi * x;
    worst_P = std::max(worst_P, rel(ekf.P(), P));
    if (x.norm() > 0) worst_x = std::max(worst_x, rel(ekf.x(), x));
    EXPECT_TRUE(ekf.P() == ekf.P().transpose());  // exactly symmetric
  }
  std::printf("L%d: 200 propagations, block vs dense: |dP|/|P| <= %.3g, |dx|/|x| <= %.3g\n", L::kSize, worst_P,
              worst_x);
  EXPECT_LT(worst_P, 1e-12);
  EXPECT_LT(worst_x, 1e-12);
}

// --- kalman_update (structured Joseph) vs the dense Joseph form ------------------
template <class L>
void test_update_vs_dense() {
  constexpr int n = L::kSize;
  std::mt19937 rng(7);
  std::normal_distribution<double> nd;
  struct Shape {
    int rows, cols;
  };
  for (const Shape sh : {Shape{6, 6}, Shape{3, 6}, Shape{3, 9}, Shape{6, 15}, Shape{6, n}, Shape{12, n}}) {
    LinearMeasurement<L> lin;
    lin.residual.resize(sh.rows);
    lin.H.setZero(sh.rows, n);
    lin.R.setZero(sh.rows, sh.rows);
    for (int i = 0; i < sh.rows; ++i) {
      lin.residual[i] = nd(rng);
      for (int j = 0; j < sh.cols; ++j) lin.H(i, j) = (i == j) + 0.1 * nd(rng);
      lin.R(i, i) = 0.01 + 0.1 * std::abs(nd(rng));
    }
    lin.n_cols = sh.cols;
    const StateCov<L> P0 = random_spd<L>(rng);
    StateVec<L> x0;
    for (int i = 0; i < n; ++i) x0[i] = 1e-3 * nd(rng);
    StateVec<L> x = x0;
    StateCov<L> P = P0;
    const UpdateResult r = kalman_update<L>(x, P, lin, 0.0);
    EXPECT_TRUE(r.applied);
    EXPECT_TRUE(P == P.transpose());
    // dense reference
    const Eigen::MatrixXd H = lin.H, R = lin.R;
    const Eigen::MatrixXd S = H * P0 * H.transpose() + R;
    const Eigen::MatrixXd K = P0 * H.transpose() * S.llt().solve(Eigen::MatrixXd::Identity(sh.rows, sh.rows));
    const Eigen::VectorXd xr = x0 + K * (Eigen::VectorXd(lin.residual) - H * x0);
    const Eigen::MatrixXd A = Eigen::MatrixXd::Identity(n, n) - K * H;
    const Eigen::MatrixXd Pr = A * P0 * A.transpose() + K * R * K.transpose();
    EXPECT_LT(rel(x, xr), 1e-12);
    EXPECT_LT(rel(P, Pr), 1e-12);
  }
}

// --- no heap in the EKF's propagate and update ---------------------------------
template <class L>
void test_no_malloc() {
  std::mt19937 rng(5);
  const ImuErrorModel m = random_model(rng);
  Ekf<L> ekf(m);
  ekf.initialize(random_spd<L>(rng));
  InsInterval iv;
  iv.dt = 0.1;
  iv.mid = random_point(rng);
  LooseMeasurement<L> lm;
  NavState s;
  s.lat = 0.6;
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  for (int k = 0; k < 3; ++k) {
    ekf.propagate(iv);
    lm.set(s, Vec3(0, 0, 0.2), Vec3(1.0, 0.3, -0.5), GnssFix{});
    ekf.update(lm, 0.0);
    ekf.reset_state();
  }
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);
}

// --- engine output options ------------------------------------------------------
void test_engine_outputs() {
  using L = Layout21;
  const int n = 1000;  // 10 s at 100 Hz, GNSS at 1 Hz
  std::vector<double> t(n), dth(3 * n), dv(3 * n);
  for (int k = 0; k < n; ++k) {
    t[k] = 0.01 * (k + 1);
    dth[3 * k] = 1e-5, dth[3 * k + 1] = -2e-5, dth[3 * k + 2] = 1e-3;
    dv[3 * k] = 0.01, dv[3 * k + 1] = 0.0, dv[3 * k + 2] = -0.0980665;
  }
  NavState s0;
  s0.lat = 0.5;
  s0.v_n = Vec3(1.0, 0.0, 0.0);
  std::vector<GnssFix> fixes;
  for (int g = 1; g <= 9; ++g) {
    GnssFix f;
    f.t = g + 0.005;  // between IMU epochs: the increment is split
    f.lat = 0.5 + 1e-8 * g;
    f.lon = 1e-8 * g;
    f.v_n = Vec3(1.0 + 0.01 * g, 0.0, 0.0);
    fixes.push_back(f);
  }
  StateVec<L> sd = StateVec<L>::Constant(1e-3);
  sd.head<9>().setConstant(0.1);
  const StateCov<L> P0 = sd.cwiseAbs2().asDiagonal();
  auto run = [&](int sigma_cols, int decimation, std::vector<double>& sig, std::vector<double>& rpy) {
    LooseConfig cfg;
    cfg.propagation_interval = 0.1;
    cfg.output_decimation = decimation;
    cfg.lever_arm_b = Vec3(0.1, 0.2, -0.3);
    cfg.gate.prob = 0.0;  // synthetic fixes: this test is about the outputs, not the innovation gate
    auto eng = std::make_unique<LooseEngine<Ekf<L>>>(ImuErrorModel{}, cfg);
    const int n_out = n / decimation + 1;
    const int cols = sigma_cols > 0 ? sigma_cols : L::kSize;
    sig.assign(static_cast<size_t>(n_out) * cols, -1.0);
    rpy.assign(3 * n_out, -1.0);
    std::vector<double> err(12 * n_out);
    LooseOutputs out;
    out.sigma = sig.data();
    out.sigma_cols = sigma_cols;
    out.rpy = rpy.data();
    out.imu_err = err.data();
    eng->run(s0, P0, ImuCorrection{}, n, t.data(), dth.data(), dv.data(), static_cast<int>(fixes.size()),
             fixes.data(), out);
    EXPECT_TRUE(out.updates == 9);
    return out.n_out;
  };
  std::vector<double> sig_all, rpy_all, sig9, rpy9, sig_d, rpy_d;
  EXPECT_TRUE(run(0, 1, sig_all, rpy_all) == n);
  EXPECT_TRUE(run(9, 1, sig9, rpy9) == n);
  EXPECT_TRUE(rpy9 == rpy_all);
  bool same = true;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < 9; ++j) same = same && sig9[9 * k + j] == sig_all[L::kSize * k + j];
  EXPECT_TRUE(same);
  // every 3rd sample and the last one: rows 3, 6, ..., 999, 1000
  EXPECT_TRUE(run(0, 3, sig_d, rpy_d) == n / 3 + 1);
  bool dec = true;
  for (int r = 0; r < n / 3; ++r)
    for (int j = 0; j < 3; ++j) dec = dec && rpy_d[3 * r + j] == rpy_all[3 * (3 * r + 2) + j];
  for (int j = 0; j < 3; ++j) dec = dec && rpy_d[3 * (n / 3) + j] == rpy_all[3 * (n - 1) + j];
  EXPECT_TRUE(dec);
}

// --- the odometer scale-factor state in the closed loop ----------------------------
// A drive whose truth is the mechanization of the IMU data itself (so the INS
// has no error of its own), GNSS position and velocity at 1 Hz, and an
// odometer at 10 Hz that reads (1 + 3000 ppm) times the true forward speed:
// the fed-back estimate converges to the truth within its 3 sigma, the odometer
// rows then agree with the INS, and the whole run (constraint updates
// included) does not touch the heap.
void test_odo_scale_engine() {
  using L = Layout16Odo;
  constexpr double kScale = 3e-3, imu_dt = 0.01;
  const int n = 12000;  // 120 s at 100 Hz
  std::vector<double> t(n), dth(3 * n), dv(3 * n);
  NavState s0;
  s0.lat = 0.5;
  s0.h = 50.0;
  s0.v_n = Vec3(10.0, 0.0, 0.0);
  Strapdown truth(s0);
  std::vector<GnssFix> fixes;
  std::vector<ConstraintEvent> events;
  for (int k = 0; k < n; ++k) {
    t[k] = imu_dt * (k + 1);
    const double turn = 0.05 * std::sin(0.05 * t[k]);  // gentle S-curves [rad/s]
    ImuIncrement imu;
    imu.t = t[k];
    imu.dt = imu_dt;
    imu.dtheta_b = Vec3(0.0, 0.0, turn) * imu_dt;
    imu.dv_b = Vec3(0.2 * std::cos(0.1 * t[k]), 10.0 * turn, -wgs84::gravity(s0.lat, s0.h)) * imu_dt;
    for (int j = 0; j < 3; ++j) dth[3 * k + j] = imu.dtheta_b[j], dv[3 * k + j] = imu.dv_b[j];
    truth.update(imu);
    const NavState& s = truth.state();
    if ((k + 1) % 10 == 0) {  // odometer: forward speed of the IMU (the constrained point), scaled
      const double v_fwd = (s.q_nb.toRotationMatrix().transpose() * s.v_n)[0];
      events.push_back(ConstraintEvent{t[k], std::uint8_t(kOdometer), (1.0 + kScale) * v_fwd});
    }
    if ((k + 1) % 100 == 0) {
      GnssFix f;
      f.t = t[k];
      f.lat = s.lat, f.lon = s.lon, f.h = s.h;
      f.v_n = s.v_n;
      f.sigma_pos_n = Vec3::Constant(0.5);
      f.sigma_vel_n = Vec3::Constant(0.05);
      fixes.push_back(f);
    }
  }
  StateVec<L> sd = StateVec<L>::Constant(1e-4);
  sd.head<9>() << 0.5, 0.5, 0.5, 0.05, 0.05, 0.05, 1e-3, 1e-3, 3e-3;
  sd[L::kOdoScale] = 0.01;
  const StateCov<L> P0 = sd.cwiseAbs2().asDiagonal();
  LooseConfig cfg;
  cfg.gate.prob = 0.0;
  cfg.vehicle.sigma_odo_mps = 0.05;
  ImuErrorModel model;
  model.odo_scale_sigma = 0.01;  // random constant (tau = inf)
  auto eng = std::make_unique<LooseEngine<Ekf<L>>>(model, cfg);
  std::vector<double> odo(2 * (n + 1)), cnis(events.size());
  LooseOutputs out;
  out.odo_scale = odo.data();
  out.constraint_nis = cnis.data();
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  eng->run(s0, P0, ImuCorrection{}, n, t.data(), dth.data(), dv.data(), static_cast<std::int64_t>(fixes.size()),
           fixes.data(), static_cast<std::int64_t>(events.size()), events.data(), out);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);
  const std::int64_t last = out.n_out - 1;
  const double est = odo[2 * last], sig = odo[2 * last + 1];
  std::printf("odometer scale: estimate %.1f ppm, sigma %.1f ppm (truth %.0f ppm); %d constraint updates\n",
              est * 1e6, sig * 1e6, kScale * 1e6, out.constraint_updates);
  EXPECT_TRUE(out.constraint_updates == static_cast<int>(events.size()));
  EXPECT_LT(std::abs(est - kScale), 3.0 * sig);
  EXPECT_LT(std::abs(est - kScale), 1e-4);
  EXPECT_LT(sig, 1e-3);
  EXPECT_LT(std::abs(eng->core().odo_scale - est), 1e-9);  // fed back: the filter's remainder is zero
}

// --- adaptive measurement noise (filter/adaptive_noise.hpp) ------------------------
// The window arithmetic: lambda = sum(y^2 - hph) / sum(r0) over the last N
// records, clamped to [f, 1]; 1 until the window is full.
void test_adaptive_noise_window() {
  AdaptiveMeasurementNoise<2> a(AdaptiveNoiseConfig{3, 0.1});
  EXPECT_TRUE(a.factor(0) == 1.0);
  a.push(0, 1.0, 0.5, 2.0);  // d = 0.5
  a.push(0, 2.0, 1.0, 2.0);  // d = 3
  EXPECT_TRUE(a.factor(0) == 1.0);  // not full
  a.push(0, 1.0, 0.0, 2.0);  // d = 1: (0.5 + 3 + 1) / 6 = 0.75
  EXPECT_LT(std::abs(a.factor(0) - 0.75), 1e-15);
  a.push(0, 0.0, 1.0, 2.0);  // the first leaves: (3 + 1 - 1) / 6 = 0.5
  EXPECT_LT(std::abs(a.factor(0) - 0.5), 1e-15);
  a.push(0, 0.0, 2.0, 2.0);
  a.push(0, 0.0, 2.0, 2.0);  // (-1 - 2 - 2) / 6 < 0: the lower clamp
  EXPECT_TRUE(a.factor(0) == 0.1);
  for (int k = 0; k < 3; ++k) a.push(0, 10.0, 0.0, 2.0);  // large innovations: the upper clamp
  EXPECT_TRUE(a.factor(0) == 1.0);
  EXPECT_TRUE(a.factor(1) == 1.0);  // the other channel has no records
  a.reset();
  EXPECT_TRUE(a.factor(0) == 1.0);
}

// A drive whose truth is the mechanization of the IMU data (no INS error of its
// own), fixes at 1 Hz with white noise 4x smaller (sigma) than configured: with
// a window of 30 the variances the updates use come to the simulated ones
// (mean over the last 120 fixes within 0.7-1.4 of it per block of rows: some 4
// independent windows x 3 rows, each with a standard deviation of about
// sqrt(2/30) (1 + H P- H'/R) R = 0.3 R here), never above the configured, and
// the run does not touch the heap.
void test_adaptive_noise_engine() {
  using L = Layout15;
  constexpr double imu_dt = 0.01, kSigP = 0.05, kSigV = 0.02;
  const int n = 20000;  // 200 s at 100 Hz
  std::vector<double> t(n), dth(3 * n), dv(3 * n);
  NavState s0;
  s0.lat = 0.5;
  s0.h = 50.0;
  s0.v_n = Vec3(5.0, 0.0, 0.0);
  Strapdown truth(s0);
  std::vector<GnssFix> fixes;
  std::mt19937 rng(11);
  std::normal_distribution<double> gauss;
  for (int k = 0; k < n; ++k) {
    t[k] = imu_dt * (k + 1);
    ImuIncrement imu;
    imu.t = t[k];
    imu.dt = imu_dt;
    imu.dtheta_b = Vec3(0.0, 0.0, 0.05 * std::sin(0.05 * t[k])) * imu_dt;
    imu.dv_b = Vec3(0.02 * std::cos(0.1 * t[k]), 0.0, -9.80665) * imu_dt;
    for (int j = 0; j < 3; ++j) dth[3 * k + j] = imu.dtheta_b[j], dv[3 * k + j] = imu.dv_b[j];
    truth.update(imu);
    const NavState& s = truth.state();
    if ((k + 1) % 100 == 0) {
      const wgs84::Radii r = wgs84::radii(s.lat);
      GnssFix f;
      f.t = t[k];
      f.lat = s.lat + kSigP * gauss(rng) / (r.R_M + s.h);
      f.lon = s.lon + kSigP * gauss(rng) / ((r.R_N + s.h) * std::cos(s.lat));
      f.h = s.h + kSigP * gauss(rng);
      for (int j = 0; j < 3; ++j) f.v_n[j] = s.v_n[j] + kSigV * gauss(rng);
      f.sigma_pos_n = Vec3::Constant(4.0 * kSigP);
      f.sigma_vel_n = Vec3::Constant(4.0 * kSigV);
      fixes.push_back(f);
    }
  }
  StateVec<L> sd = StateVec<L>::Constant(1e-4);
  sd.head<9>() << 0.2, 0.2, 0.2, 0.05, 0.05, 0.05, 1e-3, 1e-3, 3e-3;
  const StateCov<L> P0 = sd.cwiseAbs2().asDiagonal();
  LooseConfig cfg;
  cfg.adaptive_r.window = 30;
  cfg.gate.prob = 0.0;  // every fix in the window (the gate's own tests: test_nis_gate.cpp)
  ImuErrorModel model;  // defaults: a small process noise
  auto eng = std::make_unique<LooseEngine<Ekf<L>>>(model, cfg);
  const int m = static_cast<int>(fixes.size());
  std::vector<double> ms(6 * m), nis(m);
  LooseOutputs out;
  out.meas_sigma = ms.data();
  out.nis = nis.data();
  const int before = g_eigen_asserts;
  Eigen::internal::set_is_malloc_allowed(false);
  eng->run(s0, P0, ImuCorrection{}, n, t.data(), dth.data(), dv.data(), m, fixes.data(), out);
  Eigen::internal::set_is_malloc_allowed(true);
  EXPECT_TRUE(g_eigen_asserts == before);
  EXPECT_TRUE(out.updates == m);
  double vp = 0.0, vv = 0.0, nis_mean = 0.0;
  bool below = true;
  for (int g = m - 120; g < m; ++g) {
    for (int j = 0; j < 3; ++j) {
      vp += ms[6 * g + j] * ms[6 * g + j] / 360.0;
      vv += ms[6 * g + 3 + j] * ms[6 * g + 3 + j] / 360.0;
      below = below && ms[6 * g + j] <= 4.0 * kSigP && ms[6 * g + 3 + j] <= 4.0 * kSigV;
    }
    nis_mean += nis[g] / 120.0 / 6.0;
  }
  std::printf("adaptive R: variance / simulated, position %.3f, velocity %.3f; NIS per row %.3f\n",
              vp / (kSigP * kSigP), vv / (kSigV * kSigV), nis_mean);
  EXPECT_TRUE(below);
  EXPECT_LT(std::abs(std::log(vp / (kSigP * kSigP))), std::log(1.4));
  EXPECT_LT(std::abs(std::log(vv / (kSigV * kSigV))), std::log(1.4));
  EXPECT_LT(std::abs(nis_mean - 1.0), 0.25);
}

}  // namespace

int main() {
  test_structure<Layout15>();
  test_structure<Layout21>();
  test_structure<Layout16Odo>();
  test_propagate_vs_dense<Layout15>();
  test_propagate_vs_dense<Layout21>();
  test_propagate_vs_dense<Layout16Odo>();
  test_update_vs_dense<Layout15>();
  test_update_vs_dense<Layout21>();
  test_update_vs_dense<Layout16Odo>();
  test_no_malloc<Layout15>();
  test_no_malloc<Layout21>();
  test_no_malloc<Layout16Odo>();
  test_engine_outputs();
  test_odo_scale_engine();
  test_adaptive_noise_window();
  test_adaptive_noise_engine();
  TEST_MAIN_END()
}
