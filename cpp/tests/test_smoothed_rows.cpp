// The smoothed output rows (engine/smoothed_rows.hpp) and the navigation error
// correction they share with the engines' feedback (ins/nav_error.hpp):
//  * apply_nav_error against its definition (filter/layout.hpp): the corrected
//    state's position differs from the computed one by dr_n to first order
//    (checked against the exact geodetic -> ECEF -> NED difference), its DCM
//    is dcm_from_euler(psi) C_nb;
//  * a row between two epochs whose errors are equal is corrected exactly as
//    apply_nav_error corrects a NavState (the same formula, to rounding);
//  * linear interpolation in time, the d / d_end choice at an epoch, additive
//    columns subtracted, sigmas interpolated;
//  * the rows' Euler-angle sigmas from psi's covariance against a numerical Jacobian;
//  * rows in degrees and in radians give the same result; two threads give
//    the same bits as one; no Eigen heap allocation in the row loop.
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "eigen_malloc_check.hpp"  // first: before any Eigen header
#include <Eigen/Dense>

#include "insnav/engine/smoothed_rows.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

constexpr double kPi = 3.14159265358979323846;

/// NED difference [m] of position b relative to a (exact, through ECEF).
Vec3 ned_diff(double lat_a, double lon_a, double h_a, double lat_b, double lon_b, double h_b) {
  const Vec3 d = wgs84::geodetic_to_ecef(lat_b, lon_b, h_b) - wgs84::geodetic_to_ecef(lat_a, lon_a, h_a);
  return wgs84::C_en(lat_a, lon_a).transpose() * d;
}

double angle_diff(double a, double b) { return std::remainder(a - b, 2.0 * kPi); }

void test_apply_nav_error_matches_its_definition() {
  NavState s;
  s.lat = 0.6;
  s.lon = 2.0;
  s.h = 350.0;
  s.v_n = Vec3(10.0, -3.0, 0.5);
  s.q_nb = quat_from_euler(Vec3(0.1, -0.2, 2.5));
  const Vec3 dr(3.0, -4.0, 1.5), dv(0.2, -0.1, 0.05), psi(2e-3, -1e-3, 4e-3);
  NavState c = s;
  apply_nav_error(c, dr, dv, psi);
  // error = computed - true: the NED vector from the true (corrected) position to the computed one is dr
  // (down = -dh), to second order in |dr| / R (1e-13 m here)
  const Vec3 d = ned_diff(c.lat, c.lon, c.h, s.lat, s.lon, s.h);
  EXPECT_LT((d - dr).norm(), 1e-5);
  EXPECT_LT((c.v_n - (s.v_n - dv)).norm(), 1e-15);
  const Mat3 C_true = dcm_from_euler(psi) * s.q_nb.toRotationMatrix();
  EXPECT_LT((c.q_nb.toRotationMatrix() - C_true).norm(), 1e-14);
  EXPECT_LT(std::abs(c.q_nb.norm() - 1.0), 1e-15);
  // the series quaternion of small angles and the exact one agree to rounding; large angles are exact
  for (const Vec3& a : {Vec3(1e-3, -5e-3, 1.9e-2), Vec3(0.3, -0.2, 1.0)}) {
    const Quat qs = quat_from_small_euler(a), qe = quat_from_euler(a);
    EXPECT_LT((qs.coeffs() - qe.coeffs()).norm(), 1e-16);
  }
}

/// euler_sigmas_from_psi against the numerical Jacobian of the Euler angles of the computed frame:
/// the true frame is dcm_from_euler(psi) C (apply_nav_error), so the computed one at error psi is
/// dcm_from_euler(psi)^T C_true; at several headings and pitches.
void test_euler_sigmas_are_the_mapped_psi_covariance() {
  Mat3 L;
  L << 2e-3, 0.0, 0.0, 5e-4, 1e-3, 0.0, -7e-4, 3e-4, 4e-3;
  const Mat3 P = L * L.transpose();
  for (const Vec3& e : {Vec3(0.1, -0.2, 2.5), Vec3(-0.3, 0.7, -1.2), Vec3(0.0, 0.0, 1.5707963), Vec3(0.2, 1.3, 0.4)}) {
    const Mat3 C_true = dcm_from_euler(e);
    Mat3 J;
    const double h = 1e-6;
    for (int i = 0; i < 3; ++i) {
      Vec3 d = Vec3::Zero();
      d[i] = h;
      const Vec3 ep = euler_from_dcm(dcm_from_euler(d).transpose() * C_true);
      const Vec3 em = euler_from_dcm(dcm_from_euler(-d).transpose() * C_true);
      for (int j = 0; j < 3; ++j) J(j, i) = angle_diff(ep[j], em[j]) / (2.0 * h);
    }
    const Vec3 want = (J * P * J.transpose()).diagonal().cwiseSqrt();
    const Vec3 got = euler_sigmas_from_psi(P, e[1], e[2]);
    EXPECT_LT(((got - want).array() / want.array()).abs().maxCoeff(), 1e-6);
    // the output rows' trig-free form at the same attitude's DCM
    const Vec3 got_dcm = euler_sigmas_from_psi_dcm(P, C_true);
    EXPECT_LT(((got_dcm - want).array() / want.array()).abs().maxCoeff(), 1e-6);
    EXPECT_LT(((got_dcm - got).array() / got.array()).abs().maxCoeff(), 1e-12);
  }
  // the trig-free form equals the trig form at random attitudes (pitch up to 89 deg, every quadrant
  // of yaw) and random covariances, and falls back to it at gimbal lock
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    const Vec3 e(3.1 * u(rng), 1.553 * u(rng), 3.14 * u(rng));
    Mat3 Lr;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) Lr(i, j) = j <= i ? 1e-3 * u(rng) : 0.0;
    const Mat3 Pr = Lr * Lr.transpose() + 1e-10 * Mat3::Identity();
    const Vec3 a = euler_sigmas_from_psi(Pr, e[1], e[2]), b = euler_sigmas_from_psi_dcm(Pr, dcm_from_euler(e));
    EXPECT_LT(((a - b).array() / a.array()).abs().maxCoeff(), 1e-9);
  }
  const Mat3 C_lock = dcm_from_euler(Vec3(0.0, 1.5707963267948966, 0.3));
  const Vec3 e_lock = euler_from_dcm(C_lock);
  EXPECT_LT((euler_sigmas_from_psi_dcm(P, C_lock) - euler_sigmas_from_psi(P, e_lock[1], e_lock[2])).norm(), 1e-300);
}

struct Rows {
  std::vector<double> t, lat, lon, h, v, roll, pitch, yaw, sigma, extra;
  int cols = 0;
  NavRowsRef ref(double to_rad, double from_rad) {
    NavRowsRef r;
    r.n = static_cast<std::int64_t>(t.size());
    r.t = t.data();
    r.lat = StridedColumn{lat.data(), 1};
    r.lon = StridedColumn{lon.data(), 1};
    r.h = StridedColumn{h.data(), 1};
    r.v_n = StridedMatrix{v.data(), 3, 1};
    r.roll = StridedColumn{roll.data(), 1};
    r.pitch = StridedColumn{pitch.data(), 1};
    r.yaw = StridedColumn{yaw.data(), 1};
    r.sigma = StridedMatrix{sigma.data(), cols, 1};
    r.extra = StridedMatrix{extra.data(), cols - 9, 1};
    r.to_rad = to_rad;
    r.from_rad = from_rad;
    return r;
  }
};

Rows random_rows(int n, int cols, double t_end, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Rows r;
  r.cols = cols;
  for (int i = 0; i < n; ++i) {
    r.t.push_back(t_end * (i + 0.5) / n);
    r.lat.push_back(1.2 * u(rng));
    r.lon.push_back(3.0 * u(rng));
    r.h.push_back(500.0 + 400.0 * u(rng));
    for (int j = 0; j < 3; ++j) r.v.push_back(20.0 * u(rng));
    r.roll.push_back(3.0 * u(rng));
    r.pitch.push_back(1.4 * u(rng));
    r.yaw.push_back(3.1 * u(rng));
    for (int j = 0; j < cols - 9; ++j) r.extra.push_back(100.0 * u(rng));
  }
  r.sigma.assign(static_cast<std::size_t>(n) * cols, -1.0);
  return r;
}

void test_rows_equal_the_feedback_formula_and_interpolate() {
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0.0, 1.0);
  const int E = 6, cols = 11, n = 500;
  std::vector<double> te(E), d(E * cols), d_end(E * cols), sig(E * cols);
  for (int k = 0; k < E; ++k) {
    te[k] = 2.0 * k;
    for (int j = 0; j < cols; ++j) {
      const double scale = j >= 6 && j < 9 ? 3e-3 : 2.0;
      d[k * cols + j] = scale * g(rng);
      d_end[k * cols + j] = scale * g(rng);
      sig[k * cols + j] = std::abs(g(rng));
    }
  }
  // epochs 2 and 3: the rows between them see one constant error (d_2 = d_end_3)
  for (int j = 0; j < cols; ++j) d_end[3 * cols + j] = d[2 * cols + j];
  SmoothedErrors e;
  e.n_epochs = E;
  e.cols = cols;
  e.t = te.data();
  e.d = d.data();
  e.d_end = d_end.data();
  e.sigma = sig.data();
  Rows before = random_rows(n, cols, te[E - 1], rng);
  Rows rows = before;
  Eigen::internal::set_is_malloc_allowed(false);  // the row loop allocates nothing (Eigen)
  smooth_nav_rows(e, rows.ref(1.0, 1.0), 0, n);
  Eigen::internal::set_is_malloc_allowed(true);
  double worst_pos = 0, worst_att = 0, worst_lin = 0;
  for (int i = 0; i < n; ++i) {
    const double t = rows.t[i];
    const int k = std::min(static_cast<int>(t / 2.0), E - 2);
    const double w = (t - te[k]) / (te[k + 1] - te[k]);
    for (int j = 0; j < cols; ++j) {  // sigmas and the additive columns: linear in time
      const double s_lin = (1 - w) * sig[k * cols + j] + w * sig[(k + 1) * cols + j];
      worst_lin = std::max(worst_lin, std::abs(rows.sigma[i * cols + j] - s_lin));
      if (j >= 9) {
        const double x = (1 - w) * d[k * cols + j] + w * d_end[(k + 1) * cols + j];
        worst_lin = std::max(worst_lin, std::abs(rows.extra[i * (cols - 9) + j - 9] - (before.extra[i * (cols - 9) + j - 9] - x)));
      }
    }
    if (k != 2) continue;
    NavState s;
    s.lat = before.lat[i];
    s.lon = before.lon[i];
    s.h = before.h[i];
    s.v_n = Vec3(before.v[3 * i], before.v[3 * i + 1], before.v[3 * i + 2]);
    s.q_nb = quat_from_euler(Vec3(before.roll[i], before.pitch[i], before.yaw[i]));
    const double* x = &d[2 * cols];
    apply_nav_error(s, Vec3(x[0], x[1], x[2]), Vec3(x[3], x[4], x[5]), Vec3(x[6], x[7], x[8]));
    worst_pos = std::max({worst_pos, std::abs(rows.lat[i] - s.lat), std::abs(rows.lon[i] - s.lon),
                          std::abs(rows.h[i] - s.h) / 1e7, (Vec3(rows.v[3 * i], rows.v[3 * i + 1], rows.v[3 * i + 2]) - s.v_n).norm() / 1e7});
    const Mat3 C_row = dcm_from_euler(Vec3(rows.roll[i], rows.pitch[i], rows.yaw[i]));
    worst_att = std::max(worst_att, (C_row - s.q_nb.toRotationMatrix()).norm());
  }
  std::printf("rows = feedback formula: |d lat, lon| %.2e rad, |d C_nb| %.2e; interpolation %.2e\n", worst_pos,
              worst_att, worst_lin);
  EXPECT_LT(worst_pos, 1e-15);  // position and velocity: the same arithmetic
  EXPECT_LT(worst_att, 1e-14);  // attitude: the row's Euler angles round trip
  EXPECT_LT(worst_lin, 1e-13);
  // a row exactly at an epoch takes that epoch's d (after its feedback)
  Rows at = random_rows(1, cols, 1.0, rng);
  at.t[0] = te[4];
  Rows at0 = at;
  smooth_nav_rows(e, at.ref(1.0, 1.0), 0, 1);
  EXPECT_LT(std::abs(at.h[0] - (at0.h[0] + d[4 * cols + 2])), 1e-12);

  // degrees give the radians' result; two threads the same bits as one
  Rows deg = before;
  for (auto* col : {&deg.lat, &deg.lon, &deg.roll, &deg.pitch, &deg.yaw})
    for (double& a : *col) a *= kRadToDeg;
  smooth_nav_rows(e, deg.ref(kDegToRad, kRadToDeg), 2);
  double worst_deg = 0;
  for (int i = 0; i < n; ++i)
    worst_deg = std::max({worst_deg, std::abs(deg.lat[i] * kDegToRad - rows.lat[i]),
                          std::abs(angle_diff(deg.lon[i] * kDegToRad, rows.lon[i])),
                          std::abs(angle_diff(deg.yaw[i] * kDegToRad, rows.yaw[i])),
                          std::abs(angle_diff(deg.roll[i] * kDegToRad, rows.roll[i]))});
  EXPECT_LT(worst_deg, 1e-13);
  Rows one = before, two = before;
  smooth_nav_rows(e, one.ref(1.0, 1.0), 1);
  smooth_nav_rows(e, two.ref(1.0, 1.0), 2);
  EXPECT_TRUE(one.lat == two.lat && one.yaw == two.yaw && one.sigma == two.sigma && one.extra == two.extra);
  EXPECT_TRUE(one.lat == rows.lat && one.pitch == rows.pitch);
}

}  // namespace

int main() {
  test_apply_nav_error_matches_its_definition();
  test_euler_sigmas_are_the_mapped_psi_covariance();
  test_rows_equal_the_feedback_formula_and_interpolate();
  EXPECT_TRUE(g_eigen_asserts == 0);
  TEST_MAIN_END();
}
