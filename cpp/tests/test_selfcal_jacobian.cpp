// The self-calibration states (layout.hpp): the H columns of the IMU-GNSS
// time offset and of the GNSS lever arm against numerical derivatives, for
// the loose position/velocity rows (meas/gnss_loose.hpp) and the pseudorange
// and pseudorange-rate rows (meas/pseudorange.hpp).
//
// Time offset: the derivative is taken of the physics, not of the model.  A
// car drives an analytic circle (speed 15 m/s, yaw rate 0.2 rad/s: 3 m/s^2 of
// centripetal acceleration); the GNSS record tagged t holds the true antenna
// at t - t_d.  With the INS exact at t and the estimate t_d^ = 0, the state
// is dt_d = 0 - t_d, so the column is -d residual / d t_d, taken by central
// differences of the residual the measurement class forms against the fix
// of the true trajectory at t -/+ h.
// Lever arm: the residual of the INS with l_b^ against the antenna of the
// true lever arm l_b^ - dl_b, differentiated in dl_b.
// Odometer lever arm (meas/vehicle.hpp): the NHC and odometer rows' columns
// against central differences of predicted_residual, the exact residual.
// Also: the shifted prediction (a record applied after its time) and
// predicted_residual of the new columns.
#include <cmath>
#include <cstdio>
#include <vector>

#include "insnav/earth/wgs84.hpp"
#include "insnav/meas/gnss_loose.hpp"
#include "insnav/meas/pseudorange.hpp"
#include "insnav/meas/vehicle.hpp"
#include "test_util.hpp"

using namespace insnav;

namespace {

constexpr double kLat0 = 0.52, kLon0 = 1.98, kH = 40.0;
constexpr double kSpeed = 15.0, kYawRate = 0.2, kRadius = kSpeed / kYawRate;

/// The true vehicle state on the circle at time t (NED offsets from the start
/// mapped to lat/lon by the radii at the start: what the measurement's own
/// small-difference form inverts).
struct Truth {
  NavState s;
  Vec3 omega_ib_b;  // body rate incl. the transport and Earth rates
  Vec3 a_n;         // d v_n / dt
};

Truth truth(double t) {
  const wgs84::Radii r = wgs84::radii(kLat0);
  const double yaw = kYawRate * t;
  const double pN = kRadius * std::sin(yaw), pE = kRadius * (1.0 - std::cos(yaw));
  Truth tr;
  tr.s.t = t;
  tr.s.lat = kLat0 + pN / (r.R_M + kH);
  tr.s.lon = kLon0 + pE / ((r.R_N + kH) * std::cos(kLat0));
  tr.s.h = kH;
  tr.s.v_n = Vec3(kSpeed * std::cos(yaw), kSpeed * std::sin(yaw), 0.0);
  tr.s.q_nb = quat_from_euler(Vec3(0.0, 0.0, yaw));
  tr.a_n = Vec3(-kSpeed * kYawRate * std::sin(yaw), kSpeed * kYawRate * std::cos(yaw), 0.0);
  const wgs84::Radii rr = wgs84::radii(tr.s.lat);
  const Vec3 w_in_n = wgs84::omega_ie_n(tr.s.lat) + wgs84::omega_en_n(tr.s.lat, tr.s.h, tr.s.v_n, rr);
  tr.omega_ib_b = Vec3(0.0, 0.0, kYawRate) + tr.s.q_nb.toRotationMatrix().transpose() * w_in_n;
  return tr;
}

Vec3 omega_in_n(const NavState& s) {
  const wgs84::Radii r = wgs84::radii(s.lat);
  return wgs84::omega_ie_n(s.lat) + wgs84::omega_en_n(s.lat, s.h, s.v_n, r);
}

/// The true antenna at time t as a loose fix (position and velocity of the lever arm l_b).
GnssFix antenna_fix(double t, const Vec3& l_b) {
  const Truth tr = truth(t);
  const NavState& s = tr.s;
  const Mat3 C_nb = s.q_nb.toRotationMatrix();
  const Vec3 l_n = C_nb * l_b;
  const wgs84::Radii r = wgs84::radii(s.lat);
  GnssFix f;
  f.t = t;
  f.lat = s.lat + l_n.x() / (r.R_M + s.h);
  f.lon = s.lon + l_n.y() / ((r.R_N + s.h) * std::cos(s.lat));
  f.h = s.h - l_n.z();
  f.v_n = s.v_n + C_nb * tr.omega_ib_b.cross(l_b) - omega_in_n(s).cross(l_n);
  return f;
}

/// ECEF antenna position and velocity of the truth at time t.
AntennaEcef antenna_at(double t, const Vec3& l_b) {
  const Truth tr = truth(t);
  return antenna_ecef(tr.s.lat, tr.s.lon, tr.s.h, tr.s.v_n, tr.s.q_nb.toRotationMatrix(), tr.omega_ib_b,
                      omega_in_n(tr.s), l_b);
}

/// Satellites at GPS range in several directions around r_e.
std::vector<SatObservation> satellites(const NavState& s, const Vec3& r_e) {
  std::vector<SatObservation> out;
  const Mat3 C_en = wgs84::C_en(s.lat, s.lon);
  for (int i = 0; i < 6; ++i) {
    const double az = 1.05 * i + 0.2, el = 0.3 + 0.2 * i;
    const Vec3 u_e = C_en * Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), -std::sin(el));
    SatObservation o;
    o.r_e = r_e + 2.2e7 * u_e;
    o.v_e = 3000.0 * u_e.cross(Vec3(0.3, -0.5, 0.8)).normalized();
    out.push_back(o);
  }
  return out;
}

/// Pseudorange and rate of the satellites as seen from antenna `a` (clock 0).
std::vector<SatObservation> observe(std::vector<SatObservation> sats, const AntennaEcef& a) {
  for (SatObservation& o : sats) {
    const Vec3 d = o.r_e - a.r_e;
    o.pseudorange_m = d.norm();
    o.pseudorange_rate_mps = d.normalized().dot(o.v_e - a.v_e);
  }
  return sats;
}

double rel_err(double a, double b) { return std::abs(a - b) / std::max(1.0, std::abs(b)); }

}  // namespace

int main() {
  const double t = 3.0, h = 1e-3;  // t_d steps of 1 ms (the residual's t_d^3 term: ~1e-8 of the column)
  const Truth ins = truth(t);      // the INS is exact at t
  const Vec3 l_b(1.1, -0.4, -0.9);

  // --- loose, time offset: position rows with the lever arm, velocity rows without it ---
  {
    using L = Layout19TdLever;
    constexpr int TD = L::kTimeOffset;
    for (const bool with_lever : {true, false}) {
      const Vec3 l = with_lever ? l_b : Vec3::Zero();
      auto residual = [&](double t_d) {  // fix tagged t holds the antenna at t - t_d
        GnssFix f = antenna_fix(t - t_d, l);
        f.t = t;
        LooseMeasurement<L> m;
        m.set(ins.s, ins.omega_ib_b, l, f, ins.a_n, 0.0);
        return Eigen::Matrix<double, 6, 1>(m.linear().residual);
      };
      LooseMeasurement<L> m;
      m.set(ins.s, ins.omega_ib_b, l, antenna_fix(t, l), ins.a_n, 0.0);
      const Eigen::Matrix<double, 6, 1> num = -(residual(h) - residual(-h)) / (2 * h);  // d / d(dt_d)
      double worst_pos = 0.0, worst_vel = 0.0;
      for (int i = 0; i < 3; ++i) {
        worst_pos = std::max(worst_pos, rel_err(m.linear().H(i, TD), num[i]));
        worst_vel = std::max(worst_vel, rel_err(m.linear().H(3 + i, TD), num[3 + i]));
      }
      std::printf("loose t_d column (lever %s): position rows %.2e, velocity rows %.2e (|H pos| %.2f m/s, "
                  "|H vel| %.2f m/s^2)\n",
                  with_lever ? "1.5 m" : "0", worst_pos, worst_vel, m.linear().H.block<3, 1>(0, TD).norm(),
                  m.linear().H.block<3, 1>(3, TD).norm());
      EXPECT_LT(worst_pos, 1e-5);
      EXPECT_LT(1.0, (m.linear().H.template block<3, 1>(0, TD).norm()));  // not a zero column passing trivially
      if (!with_lever) {
        EXPECT_LT(worst_vel, 1e-4);  // exact without the lever arm's own acceleration
        EXPECT_LT(1.0, (m.linear().H.template block<3, 1>(3, TD).norm()));
      } else {
        // with the lever arm, the velocity column leaves out omega x (omega x l): 0.2^2 * 1.2 m = 0.05 m/s^2
        EXPECT_LT((m.linear().H.block<3, 1>(3, TD) - num.tail<3>()).norm(), 0.06);
      }
      // predicted_residual carries the column linearly
      StateVec<L> dx = StateVec<L>::Zero();
      dx[TD] = 0.01;
      EXPECT_LT((m.predicted_residual(dx) - m.linear().H.col(TD) * 0.01).norm(), 1e-12);
    }
    // shifted prediction: the INS 40 ms past the fix's time; the shifted residual is second order
    const double shift = 0.04;
    const Truth late = truth(t + shift);
    LooseMeasurement<L> m0, m1;
    m0.set(late.s, late.omega_ib_b, Vec3::Zero(), antenna_fix(t, Vec3::Zero()), late.a_n, 0.0);
    m1.set(late.s, late.omega_ib_b, Vec3::Zero(), antenna_fix(t, Vec3::Zero()), late.a_n, shift);
    const double r0 = m0.linear().residual.norm(), r1 = m1.linear().residual.norm();
    std::printf("loose, applied 40 ms late: |residual| %.3f unshifted, %.4f shifted\n", r0, r1);
    EXPECT_LT(0.5, r0);
    EXPECT_LT(r1, 0.01);
  }

  // --- loose, lever arm columns ---
  {
    using L = Layout19TdLever;
    constexpr int LA = L::kLeverArm;
    auto residual = [&](const Vec3& dl) {
      LooseMeasurement<L> m;
      m.set(ins.s, ins.omega_ib_b, l_b, antenna_fix(t, l_b - dl), ins.a_n, 0.0);
      return Eigen::Matrix<double, 6, 1>(m.linear().residual);
    };
    LooseMeasurement<L> m;
    m.set(ins.s, ins.omega_ib_b, l_b, antenna_fix(t, l_b), ins.a_n, 0.0);
    double worst = 0.0;
    for (int j = 0; j < 3; ++j) {
      Vec3 e = Vec3::Zero();
      e[j] = 1e-3;
      const Eigen::Matrix<double, 6, 1> col = (residual(e) - residual(-e)) / 2e-3;
      for (int i = 0; i < 6; ++i) worst = std::max(worst, rel_err(m.linear().H(i, LA + j), col[i]));
    }
    std::printf("loose lever-arm columns: max relative |H - numerical| %.2e\n", worst);
    EXPECT_LT(worst, 1e-6);
    EXPECT_LT(0.9, (m.linear().H.template block<3, 3>(0, LA).norm()));
    // predicted_residual in the lever arm is exact (residual of the true lever arm l^ - dl)
    StateVec<L> dx = StateVec<L>::Zero();
    dx.segment<3>(LA) = Vec3(0.3, -0.2, 0.1);
    EXPECT_LT((m.predicted_residual(dx) - residual(dx.segment<3>(LA))).norm(), 1e-6);

    // set_lever_arm_rate: the residual keeps the rate given to set() (bit for bit), the lever-arm
    // columns take the other rate (a low-passed rate: ClosedLoop::omega_ib_b_lever), i.e. they equal
    // the columns of a measurement built with that rate; predicted_residual's derivative in dl agrees.
    const Vec3 w_lever = ins.omega_ib_b + Vec3(0.02, -0.03, 0.01);
    LooseMeasurement<L> ml, mw;
    ml.set_lever_arm_rate(w_lever);
    ml.set(ins.s, ins.omega_ib_b, l_b, antenna_fix(t, l_b - Vec3(0.1, 0.2, -0.3)), ins.a_n, 0.0);
    mw.set(ins.s, w_lever, l_b, antenna_fix(t, l_b - Vec3(0.1, 0.2, -0.3)), ins.a_n, 0.0);
    LooseMeasurement<L> m0;
    m0.set(ins.s, ins.omega_ib_b, l_b, antenna_fix(t, l_b - Vec3(0.1, 0.2, -0.3)), ins.a_n, 0.0);
    EXPECT_LT((ml.linear().residual - m0.linear().residual).norm(), 1e-15);
    EXPECT_LT((ml.linear().H.block<6, 3>(0, LA) - mw.linear().H.block<6, 3>(0, LA)).norm(), 1e-12);
    EXPECT_LT(1e-3, (ml.linear().H.block<3, 3>(3, LA) - m0.linear().H.block<3, 3>(3, LA)).norm());
    double worst_pr = 0.0;
    for (int j = 0; j < 3; ++j) {
      StateVec<L> e = StateVec<L>::Zero();
      e[LA + j] = 1e-4;
      const Eigen::Matrix<double, 6, 1> col = (ml.predicted_residual(e) - ml.predicted_residual(-e)) / 2e-4;
      for (int i = 0; i < 6; ++i) worst_pr = std::max(worst_pr, std::abs(ml.linear().H(i, LA + j) - col[i]));
    }
    std::printf("loose lever-arm columns with a separate rate: |H - d predicted_residual / d dl| %.2e\n", worst_pr);
    EXPECT_LT(worst_pr, 1e-8);
    // the next set() without the call takes the rate of set() again
    ml.set(ins.s, ins.omega_ib_b, l_b, antenna_fix(t, l_b), ins.a_n, 0.0);
    EXPECT_LT((ml.linear().H - m.linear().H).norm(), 1e-15);
  }

  // --- tight, time offset: pseudorange and rate rows ---
  {
    using L = LayoutTightTdLever;
    constexpr int TD = L::kTimeOffset;
    for (const bool with_lever : {true, false}) {
      const Vec3 l = with_lever ? l_b : Vec3::Zero();
      const std::vector<SatObservation> sats = satellites(ins.s, antenna_at(t, l).r_e);
      auto residual = [&](double t_d) {
        const std::vector<SatObservation> obs = observe(sats, antenna_at(t - t_d, l));
        TightMeasurement<L> m;
        m.set(ins.s, ins.omega_ib_b, l, 0.0, 0.0, obs.data(), static_cast<int>(obs.size()), nullptr, ins.a_n, 0.0);
        return typename LinearMeasurement<L>::RowVec(m.linear().residual);
      };
      const std::vector<SatObservation> obs = observe(sats, antenna_at(t, l));
      TightMeasurement<L> m;
      m.set(ins.s, ins.omega_ib_b, l, 0.0, 0.0, obs.data(), static_cast<int>(obs.size()), nullptr, ins.a_n, 0.0);
      const auto num = ((residual(h) - residual(-h)) / (-2 * h)).eval();
      double worst_pr = 0.0, worst_rate = 0.0, h_pr = 0.0, h_rate = 0.0;
      for (int i = 0; i < m.linear().rows(); ++i) {
        const double e = std::abs(m.linear().H(i, TD) - num[i]);
        if (i % 2 == 0) {
          worst_pr = std::max(worst_pr, e / std::max(1.0, std::abs(num[i])));
          h_pr = std::max(h_pr, std::abs(num[i]));
        } else {
          worst_rate = std::max(worst_rate, e);
          h_rate = std::max(h_rate, std::abs(num[i]));
        }
      }
      std::printf("tight t_d column (lever %s): pseudorange rows rel %.2e (max |col| %.1f m/s), rate rows abs %.2e "
                  "m/s^2 (max |col| %.2f m/s^2)\n",
                  with_lever ? "1.5 m" : "0", worst_pr, h_pr, worst_rate, h_rate);
      // (the truth maps its NED offsets to lat/lon with cos(lat0): its ECEF velocity differs from v_n by
      // tan(lat) dlat ~ 1e-5 relative, which the numerical column sees)
      EXPECT_LT(worst_pr, 5e-5);
      EXPECT_LT(1.0, h_pr);
      EXPECT_LT(0.5, h_rate);
      // rate rows: the lever arm's own acceleration (0.05 m/s^2) is left out; exact without the lever arm
      // up to the transport rate's rotation of the NED axes (v^2 / R ~ 4e-5 m/s^2)
      EXPECT_LT(worst_rate, with_lever ? 0.06 : 1e-3);
    }
  }

  // --- tight, lever arm columns ---
  {
    using L = LayoutTightTdLever;
    constexpr int LA = L::kLeverArm;
    const std::vector<SatObservation> sats = satellites(ins.s, antenna_at(t, l_b).r_e);
    auto residual = [&](const Vec3& dl) {
      const std::vector<SatObservation> obs = observe(sats, antenna_at(t, l_b - dl));
      TightMeasurement<L> m;
      m.set(ins.s, ins.omega_ib_b, l_b, 0.0, 0.0, obs.data(), static_cast<int>(obs.size()), nullptr, ins.a_n, 0.0);
      return typename LinearMeasurement<L>::RowVec(m.linear().residual);
    };
    const std::vector<SatObservation> obs = observe(sats, antenna_at(t, l_b));
    TightMeasurement<L> m;
    m.set(ins.s, ins.omega_ib_b, l_b, 0.0, 0.0, obs.data(), static_cast<int>(obs.size()), nullptr, ins.a_n, 0.0);
    double worst = 0.0;
    for (int j = 0; j < 3; ++j) {
      Vec3 e = Vec3::Zero();
      e[j] = 1e-3;
      const auto col = ((residual(e) - residual(-e)) / 2e-3).eval();
      for (int i = 0; i < m.linear().rows(); ++i) worst = std::max(worst, rel_err(m.linear().H(i, LA + j), col[i]));
    }
    std::printf("tight lever-arm columns: max relative |H - numerical| %.2e\n", worst);
    EXPECT_LT(worst, 1e-5);  // central differences of 2.2e7 m ranges over 1 mm steps: ~1e-6 of round-off
    EXPECT_LT(0.5, m.linear().H.block(0, LA, m.linear().rows(), 3).norm());
    // set_lever_arm_rate: the residual keeps the rate of set(), the lever-arm columns take the other
    // rate (the columns of a measurement built with it, up to its g_n term, which sees the antenna
    // velocity of the other rate: 5e-9)
    const Vec3 w_lever = ins.omega_ib_b + Vec3(0.02, -0.03, 0.01);
    TightMeasurement<L> ml, mw;
    ml.set_lever_arm_rate(w_lever);
    ml.set(ins.s, ins.omega_ib_b, l_b, 0.0, 0.0, obs.data(), static_cast<int>(obs.size()), nullptr, ins.a_n, 0.0);
    mw.set(ins.s, w_lever, l_b, 0.0, 0.0, obs.data(), static_cast<int>(obs.size()), nullptr, ins.a_n, 0.0);
    const int rows = m.linear().rows();
    EXPECT_LT((ml.linear().residual - m.linear().residual).norm(), 1e-12);
    EXPECT_LT((ml.linear().H.block(0, LA, rows, 3) - mw.linear().H.block(0, LA, rows, 3)).norm(), 1e-7);
    EXPECT_LT(1e-3, (ml.linear().H.block(0, LA, rows, 3) - m.linear().H.block(0, LA, rows, 3)).norm());
  }
  // --- vehicle constraints, odometer lever-arm columns (NHC + odometer rows, turning) ---
  {
    using L = Layout18OdoLever;
    constexpr int LO = L::kOdoLever;
    VehicleConstraintConfig vc;
    vc.lever_arm_b = Vec3(-1.3, 0.2, 0.4);
    vc.C_bv = dcm_from_euler(Vec3(0.01, -0.02, 0.03)).transpose();
    VehicleVelocityMeasurement<L> m;
    const Vec3 w = ins.omega_ib_b + Vec3(0.03, -0.05, 0.0);  // some roll and pitch rate besides the yaw rate
    m.set(ins.s, w, vc, true, 14.0, 0.002);
    double worst = 0.0;
    for (int j = 0; j < 3; ++j) {
      StateVec<L> dp = StateVec<L>::Zero(), dm = StateVec<L>::Zero();
      dp[LO + j] = 1e-3;
      dm[LO + j] = -1e-3;
      const auto col = ((m.predicted_residual(dp) - m.predicted_residual(dm)) / 2e-3).eval();
      for (int i = 0; i < m.linear().rows(); ++i) worst = std::max(worst, rel_err(m.linear().H(i, LO + j), col[i]));
    }
    std::printf("vehicle odometer lever-arm columns: max relative |H - numerical| %.2e (|H| %.3f)\n", worst,
                m.linear().H.block(0, LO, m.linear().rows(), 3).norm());
    EXPECT_LT(worst, 1e-9);  // linear in l: central differences are exact up to round-off
    EXPECT_LT(0.1, (m.linear().H.block(0, LO, m.linear().rows(), 3).norm()));
    // set_lever_arm_rate: the residual keeps the rate given to set() (bit for bit), the lever-arm
    // columns take the other rate (ClosedLoop::omega_ib_b_lever), i.e. they equal the columns of a
    // measurement built with that rate, and they are the derivative of predicted_residual at it; the
    // other columns (dv, psi, dw_b, ds) stay the derivatives of predicted_residual
    const Vec3 w_lever = w + Vec3(0.02, -0.03, 0.01);
    VehicleVelocityMeasurement<L> ml, mw;
    ml.set_lever_arm_rate(w_lever);
    ml.set(ins.s, w, vc, true, 14.0, 0.002);
    mw.set(ins.s, w_lever, vc, true, 14.0, 0.002);
    const int rows = m.linear().rows();
    EXPECT_LT((ml.linear().residual - m.linear().residual).norm(), 1e-15);
    EXPECT_LT((ml.linear().H.block(0, LO, rows, 3) - mw.linear().H.block(0, LO, rows, 3)).norm(), 1e-12);
    EXPECT_LT(1e-2, (ml.linear().H.block(0, LO, rows, 3) - m.linear().H.block(0, LO, rows, 3)).norm());
    double worst_l = 0.0, worst_all = 0.0;
    for (int j = 0; j < L::kSize; ++j) {
      StateVec<L> dp = StateVec<L>::Zero(), dm = StateVec<L>::Zero();
      const double h = j >= LO ? 1e-3 : 1e-6;
      dp[j] = h;
      dm[j] = -h;
      const auto col = ((ml.predicted_residual(dp) - ml.predicted_residual(dm)) / (2.0 * h)).eval();
      for (int i = 0; i < rows; ++i) {
        const double e = std::abs(ml.linear().H(i, j) - col[i]);
        worst_all = std::max(worst_all, e);
        if (j >= LO) worst_l = std::max(worst_l, e);
      }
    }
    std::printf("vehicle lever-arm columns with a separate rate: |H - d predicted_residual / d dl| %.2e, "
                "all columns %.2e\n", worst_l, worst_all);
    EXPECT_LT(worst_l, 1e-10);
    EXPECT_LT(worst_all, 1e-6);
    // the next set() without the call takes the rate of set() again
    ml.set(ins.s, w, vc, true, 14.0, 0.002);
    EXPECT_LT((ml.linear().H - m.linear().H).norm(), 1e-15);
  }
  TEST_MAIN_END();
}
