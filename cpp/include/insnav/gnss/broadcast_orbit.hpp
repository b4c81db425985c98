// insnav/gnss/broadcast_orbit.hpp -- satellite states from broadcast ephemerides
// at signal transmission, in the ECEF frame at reception: GPS / Galileo / BeiDou
// Kepler elements (BeiDou GEO included) and GLONASS state vectors, with the
// light-time iteration and the Sagnac rotation.
//
// The C++ twin of python/insnav/gnss/ephemeris.py (sat_position_velocity,
// sat_clock, transmit_states), galbds.py (bds_geo_position_velocity) and
// glonass.py (glonass_integrate, glonass_clock); the numpy functions there are
// the reference (tests/test_gnss_ephemeris.py compares the two).  References:
//   * IS-GPS-200 N, 20.3.3.4.3, Table 20-IV (orbit) and 20.3.3.3.3.1 (clock and
//     the relativistic term F e sqrt(A) sin E); Galileo OS SIS ICD 2.1, 5.1.1;
//   * BDS-SIS-ICD-B1I 3.0, 5.2.4.12, Table 5-11 (GEO: R_Z(Omega_e t_k) R_X(-5 deg));
//   * GLONASS ICD Ed. 5.1, A.3.1.2 (equations of motion, RK4 from t_b).
// Light time: tau from 0.075 s, t_tx = t_rx - tau, the state rotated by
// R3(OMEGA_E_DOT tau) into the frame at reception, tau = |r - r_rx| / c, until
// tau changes by less than tol_s; the state during the iteration from a
// second-order Taylor expansion about t_rx - 0.075 s (light_time_row), then one
// exact step (the orbit at t_rx - tau, tau from its range) and the returned
// state evaluated exactly at t_tx, so that range = c tau as in the numpy
// reference, which evaluates the orbit at every iteration (3 evaluations per
// row instead of 4-5; the two agree to 1e-12 s in tau, 1e-8 m in position).
// Clock without group delay (the caller subtracts the signal's T_GD / BGD).
//
// Frames: e = ECEF (WGS-84 / PZ-90 taken equal).  SI throughout.  Element
// tables are row-major (records x columns) with the column offsets below; rows
// reference them by index.  Nothing is allocated.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace insnav::gnss {

/// Earth rotation rate of the Sagnac rotation, IS-GPS-200 Table 20-IV [rad/s].
inline constexpr double kOmegaEDotGps = 7.2921151467e-5;
/// Speed of light, IS-GPS-200 20.3.4.3 [m/s].
inline constexpr double kCLight = 299792458.0;
/// GPS value of the Earth's gravitational constant, IS-GPS-200 Table 20-IV [m^3/s^2] (ephemeris.py GM_GPS).
inline constexpr double kGmGps = 3.986005e14;
/// Relativistic clock constant F = -2 sqrt(GM) / c^2, IS-GPS-200 20.3.3.3.3.1 [s/sqrt(m)] (ephemeris.py F_REL).
inline constexpr double kFRelGps = -4.442807633e-10;

/// Columns of a Kepler element table (GPS LNAV, Galileo, BeiDou D1/D2).
struct KeplerCols {
  static constexpr int kSqrtA = 0, kToe = 1, kDeltaN = 2, kM0 = 3, kE = 4, kOmega = 5, kCus = 6, kCuc = 7,
                       kCrs = 8, kCrc = 9, kCis = 10, kCic = 11, kI0 = 12, kIdot = 13, kOmega0 = 14,
                       kOmegaDot = 15, kToeSow = 16, kToc = 17, kAf0 = 18, kAf1 = 19, kAf2 = 20, kGeo = 21;
  static constexpr int kCols = 22;  // kGeo: 1 for a BeiDou GEO record, else 0
};

/// Constants of a Kepler system (the orbit's GM and Earth rate, the clock's relativistic F).
struct KeplerConstants {
  double gm;        // [m^3/s^2]
  double omega_e;   // [rad/s]
  double f_rel;     // -2 sqrt(GM) / c^2 [s/sqrt(m)]
  double omega_geo; // BeiDou GEO rotation rate (OMEGA_E_BDS) [rad/s]
};

/// Columns of a GLONASS record table.
struct GlonassCols {
  static constexpr int kX = 0, kVx = 3, kAx = 6, kTb = 9, kClockBias = 10, kGammaN = 11;
  static constexpr int kCols = 12;
};

/// PZ-90 constants of the GLONASS equations of motion (ICD Ed. 5.1, A.3.1.2).
struct GlonassConstants {
  double gm;                // [m^3/s^2]
  double j2_term;           // 1.5 J2 GM a_e^2 [m^5/s^2]
  double omega_e;           // [rad/s]
};

/// State of one satellite at one time: ECEF position [m], velocity [m/s], eccentric anomaly and its rate.
struct OrbitState {
  double r[3];
  double v[3];
  double E = 0.0;
  double E_dot = 0.0;
};

namespace detail {

/// Mean anomaly M = M_0 + (sqrt(GM / A^3) + Delta n) t_k [rad] of Kepler elements k at GPS time t [s]
/// (IS-GPS-200 Table 20-IV).
inline double kepler_mean_anomaly(const double* k, double t, double gm) {
  using C = KeplerCols;
  const double A = k[C::kSqrtA] * k[C::kSqrtA];
  const double n0 = std::sqrt(gm / std::pow(A, 3.0));
  const double tk = t - k[C::kToe];
  const double n = n0 + k[C::kDeltaN];
  return k[C::kM0] + n * tk;
}

/// One Newton step on Kepler's equation E - e sin E = M (IS-GPS-200 Table 20-IV): the correction dE [rad],
/// to be subtracted from E.
inline double kepler_newton_step(double E, double e, double M) {
  return (E - e * std::sin(E) - M) / (1.0 - e * std::cos(E));
}

/// Eccentric anomaly E [rad] of mean anomaly M [rad] and eccentricity e: Newton's method from E = M, at
/// most 10 steps, until the step is below 1e-14 rad.
inline double kepler_eccentric_anomaly(double M, double e) {
  double E = M;
  for (int i = 0; i < 10; ++i) {
    const double dE = kepler_newton_step(E, e, M);
    E = E - dE;
    if (std::abs(dE) < 1e-14) break;
  }
  return E;
}

/// Position / velocity from Kepler elements k at GPS time t [s] with the eccentric anomaly E [rad] already
/// solved (IS-GPS-200 Table 20-IV and its analytic time derivative; the operations of
/// ephemeris.sat_position_velocity after its Kepler loop).  For callers that solve Kepler's equation for a
/// whole batch at once (rtk_rinex.hpp); kepler_state solves it row by row.
inline void kepler_state_at_E(const double* k, double t, double gm, double omega_e, double E, OrbitState& out) {
  using C = KeplerCols;
  const double A = k[C::kSqrtA] * k[C::kSqrtA];
  const double n0 = std::sqrt(gm / std::pow(A, 3.0));
  const double tk = t - k[C::kToe];
  const double n = n0 + k[C::kDeltaN];
  const double e = k[C::kE];
  const double sE = std::sin(E), cE = std::cos(E);
  const double one_m_ecE = 1.0 - e * cE;
  const double sq = std::sqrt(1.0 - e * e);
  const double nu = std::atan2(sq * sE, cE - e);
  const double phi = nu + k[C::kOmega];
  const double s2 = std::sin(2.0 * phi), c2 = std::cos(2.0 * phi);
  const double du = k[C::kCus] * s2 + k[C::kCuc] * c2;
  const double dr = k[C::kCrs] * s2 + k[C::kCrc] * c2;
  const double di = k[C::kCis] * s2 + k[C::kCic] * c2;
  const double u = phi + du;
  const double r = A * one_m_ecE + dr;
  const double i = k[C::kI0] + di + k[C::kIdot] * tk;
  const double cu = std::cos(u), su = std::sin(u);
  const double xp = r * cu, yp = r * su;
  const double Om = k[C::kOmega0] + (k[C::kOmegaDot] - omega_e) * tk - omega_e * k[C::kToeSow];
  const double cO = std::cos(Om), sO = std::sin(Om), ci = std::cos(i), si = std::sin(i);
  const double x = xp * cO - yp * ci * sO;
  const double y = xp * sO + yp * ci * cO;
  const double z = yp * si;
  const double E_dot = n / one_m_ecE;
  const double nu_dot = E_dot * sq / one_m_ecE;
  const double phi_dot = nu_dot;
  const double u_dot = phi_dot * (1.0 + 2.0 * (k[C::kCus] * c2 - k[C::kCuc] * s2));
  const double r_dot = A * e * sE * E_dot + 2.0 * phi_dot * (k[C::kCrs] * c2 - k[C::kCrc] * s2);
  const double i_dot = k[C::kIdot] + 2.0 * phi_dot * (k[C::kCis] * c2 - k[C::kCic] * s2);
  const double Om_dot = k[C::kOmegaDot] - omega_e;
  const double xp_dot = r_dot * cu - yp * u_dot;
  const double yp_dot = r_dot * su + xp * u_dot;
  out.r[0] = x;
  out.r[1] = y;
  out.r[2] = z;
  out.v[0] = xp_dot * cO - yp_dot * ci * sO + yp * si * i_dot * sO - y * Om_dot;
  out.v[1] = xp_dot * sO + yp_dot * ci * cO - yp * si * i_dot * cO + x * Om_dot;
  out.v[2] = yp_dot * si + yp * ci * i_dot;
  out.E = E;
  out.E_dot = E_dot;
}

/// Position / velocity from Kepler elements k at GPS time t [s] (IS-GPS-200 Table 20-IV; the operations of
/// ephemeris.sat_position_velocity, Kepler's equation solved for this row alone).
inline void kepler_state(const double* k, double t, double gm, double omega_e, OrbitState& out) {
  const double E = kepler_eccentric_anomaly(kepler_mean_anomaly(k, t, gm), k[KeplerCols::kE]);
  kepler_state_at_E(k, t, gm, omega_e, E, out);
}

/// Clock of Kepler elements el at GPS time t [s] from the state st of that time: the polynomial plus the
/// relativistic term F e sqrt(A) sin E (IS-GPS-200 20.3.3.3.3.1), no group delay: bias [s], drift [s/s].
inline void kepler_clock(const double* el, double t, const OrbitState& st, double f_rel, double& bias,
                         double& drift) {
  using C = KeplerCols;
  const double dt = t - el[C::kToc];
  bias = el[C::kAf0] + el[C::kAf1] * dt + el[C::kAf2] * dt * dt;
  drift = el[C::kAf1] + 2.0 * el[C::kAf2] * dt;
  const double kr = f_rel * el[C::kE] * el[C::kSqrtA];
  bias = bias + kr * std::sin(st.E);
  drift = drift + kr * std::cos(st.E) * st.E_dot;
}

/// BeiDou GEO (BDS-SIS-ICD-B1I 3.0 Table 5-11): the orbit in the GK frame (node without
/// - Omega_e t_k), then X_K = R_Z(Omega_e t_k) R_X(-5 deg) X_GK, V_K = R_Z R_X V_GK + Omega_e [Y_K, -X_K, 0].
inline void bds_geo_state(const double* k, double t, double gm, double omega_bds, OrbitState& out) {
  using C = KeplerCols;
  double kk[C::kCols];
  for (int j = 0; j < C::kCols; ++j) kk[j] = k[j];
  kk[C::kOmega0] = k[C::kOmega0] - omega_bds * k[C::kToeSow];
  OrbitState g;
  kepler_state(kk, t, gm, 0.0, g);
  const double tilt = -5.0 * (3.14159265358979323846 / 180.0);  // np.deg2rad(-5)
  const double cx = std::cos(tilt), sx = std::sin(tilt);
  const double th = omega_bds * (t - k[C::kToe]);
  const double cz = std::cos(th), sz = std::sin(th);
  auto rot = [&](const double* v, double* o) {
    const double w0 = v[0], w1 = cx * v[1] + sx * v[2], w2 = -sx * v[1] + cx * v[2];
    o[0] = cz * w0 + sz * w1;
    o[1] = -sz * w0 + cz * w1;
    o[2] = w2;
  };
  rot(g.r, out.r);
  rot(g.v, out.v);
  out.v[0] += omega_bds * out.r[1];
  out.v[1] -= omega_bds * out.r[0];
  out.E = g.E;
  out.E_dot = g.E_dot;
}

inline void kepler_any(const double* k, double t, const KeplerConstants& c, OrbitState& out) {
  if (k[KeplerCols::kGeo] != 0.0)
    bds_geo_state(k, t, c.gm, c.omega_geo, out);
  else
    kepler_state(k, t, c.gm, c.omega_e, out);
}

/// Right-hand side of the GLONASS equations of motion (glonass.glonass_derivatives).
inline void glonass_rhs(const double* s, const double* a_ls, const GlonassConstants& c, double* out) {
  const double x = s[0], y = s[1], z = s[2], vx = s[3], vy = s[4];
  const double r2 = x * x + y * y + z * z;
  const double r = std::sqrt(r2);
  const double mu_r3 = c.gm / (r2 * r);
  const double j = c.j2_term / (r2 * r2 * r);
  const double q = 5.0 * z * z / r2;
  const double w2 = c.omega_e * c.omega_e;
  out[0] = s[3];
  out[1] = s[4];
  out[2] = s[5];
  out[3] = -mu_r3 * x - j * x * (1.0 - q) + w2 * x + 2.0 * c.omega_e * vy + a_ls[0];
  out[4] = -mu_r3 * y - j * y * (1.0 - q) + w2 * y - 2.0 * c.omega_e * vx + a_ls[1];
  out[5] = -mu_r3 * z - j * z * (3.0 - q) + a_ls[2];
}

/// Classical RK4 from t_b over dt in n equal steps (glonass.glonass_integrate with its common n).
inline void glonass_integrate(const double* g, double dt, int n, const GlonassConstants& c, OrbitState& out) {
  using C = GlonassCols;
  double s[6];
  for (int j = 0; j < 6; ++j) s[j] = g[C::kX + j];
  const double* a = g + C::kAx;
  if (n > 0) {
    const double h = dt / n;
    double k1[6], k2[6], k3[6], k4[6], tmp[6];
    for (int step = 0; step < n; ++step) {
      glonass_rhs(s, a, c, k1);
      for (int j = 0; j < 6; ++j) tmp[j] = s[j] + 0.5 * h * k1[j];
      glonass_rhs(tmp, a, c, k2);
      for (int j = 0; j < 6; ++j) tmp[j] = s[j] + 0.5 * h * k2[j];
      glonass_rhs(tmp, a, c, k3);
      for (int j = 0; j < 6; ++j) tmp[j] = s[j] + h * k3[j];
      glonass_rhs(tmp, a, c, k4);
      for (int j = 0; j < 6; ++j) s[j] = s[j] + (h / 6.0) * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
    }
  }
  for (int j = 0; j < 3; ++j) {
    out.r[j] = s[j];
    out.v[j] = s[3 + j];
  }
}

/// R3(theta) applied to a vector (ephemeris.rotate_earth).
inline void rotate_z(const double* v, double theta, double* o) {
  const double c = std::cos(theta), s = std::sin(theta);
  const double x = v[0], y = v[1];
  o[0] = c * x + s * y;
  o[1] = -s * x + c * y;
  o[2] = v[2];
}

inline double range_to(const double* r, const double* r_rx) {
  const double dx = r[0] - r_rx[0], dy = r[1] - r_rx[1], dz = r[2] - r_rx[2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

}  // namespace detail

/// Output rows of transmit_states_* (all (k,) or (k, 3) row-major arrays).
struct TransmitOutput {
  double* r_e;              // (k, 3) at transmission, ECEF frame at reception [m]
  double* v_e;              // (k, 3) [m/s]
  double* clock_bias_s;     // (k,) dt_sv at t_tx, relativistic term included, no group delay [s]
  double* clock_drift_s_s;  // (k,)
  double* t_tx_gps_s;       // (k,)
  double* tau_s;            // (k,)
  double* range_m;          // (k,) |r_e - r_rx|
};

/// Light time of one row from its state (r0, v0, a0) at t_rx - 0.075 s: tau = |R3(OMEGA_E_DOT tau) r(t_rx -
/// tau) - r_rx| / c with r(t0 + d) = r0 + v0 d + a0 d^2 / 2 (|d| < 0.06 s: the third-order term is below 1e-9 m
/// for any GNSS orbit), iterated from 0.075 s until tau changes by less than tol_s.  The satellite is then
/// refined by one exact step and evaluated at t_tx by the callers.
inline double light_time_row(const OrbitState& s0, const double* a0, const double* r_rx, double tol_s, int max_iter) {
  double tau = 0.075, r[3], rt[3];
  for (int it = 0; it < max_iter; ++it) {
    const double d = 0.075 - tau;
    for (int j = 0; j < 3; ++j) r[j] = s0.r[j] + s0.v[j] * d + 0.5 * a0[j] * d * d;
    detail::rotate_z(r, kOmegaEDotGps * tau, rt);
    const double tau_new = detail::range_to(rt, r_rx) / kCLight;
    const bool done = std::abs(tau_new - tau) < tol_s;
    tau = tau_new;
    if (done) break;
  }
  return tau;
}

/// ECEF acceleration of a two-body orbit in a frame rotating at omega_e about z (for light_time_row).
inline void two_body_accel_e(const OrbitState& s, double gm, double omega_e, double* a) {
  const double r2 = s.r[0] * s.r[0] + s.r[1] * s.r[1] + s.r[2] * s.r[2];
  const double k = -gm / (r2 * std::sqrt(r2));
  const double w2 = omega_e * omega_e;
  a[0] = k * s.r[0] + w2 * s.r[0] + 2.0 * omega_e * s.v[1];
  a[1] = k * s.r[1] + w2 * s.r[1] - 2.0 * omega_e * s.v[0];
  a[2] = k * s.r[2];
}

/// Kepler systems: states at transmission for rows ``idx`` of the element table ``elem``.
inline void transmit_states_kepler(const double* elem, const std::int64_t* idx, std::int64_t k, const double* t_rx,
                                   const double* r_rx, int r_rx_stride, const KeplerConstants& c, double tol_s,
                                   int max_iter, TransmitOutput& out) {
  using C = KeplerCols;
  auto state = [&](std::int64_t i, double t, OrbitState& st) {
    detail::kepler_any(elem + C::kCols * idx[i], t, c, st);
  };
  OrbitState st;
  double a0[3];
  for (std::int64_t i = 0; i < k; ++i) {
    const double* el = elem + C::kCols * idx[i];
    state(i, t_rx[i] - 0.075, st);
    two_body_accel_e(st, c.gm, el[C::kGeo] != 0.0 ? c.omega_geo : c.omega_e, a0);
    double tau = light_time_row(st, a0, r_rx + r_rx_stride * i, tol_s, max_iter);
    {  // one exact step of the iteration: tau consistent with the range of the state returned
      double rt[3];
      state(i, t_rx[i] - tau, st);
      detail::rotate_z(st.r, kOmegaEDotGps * tau, rt);
      tau = detail::range_to(rt, r_rx + r_rx_stride * i) / kCLight;
    }
    out.tau_s[i] = tau;
    const double t_tx = t_rx[i] - tau;
    state(i, t_tx, st);
    const double theta = kOmegaEDotGps * tau;
    detail::rotate_z(st.r, theta, out.r_e + 3 * i);
    detail::rotate_z(st.v, theta, out.v_e + 3 * i);
    detail::kepler_clock(el, t_tx, st, c.f_rel, out.clock_bias_s[i], out.clock_drift_s_s[i]);
    out.t_tx_gps_s[i] = t_tx;
    out.range_m[i] = detail::range_to(out.r_e + 3 * i, r_rx + r_rx_stride * i);
  }
}

/// GLONASS: states at transmission for rows ``idx`` of the record table ``glo``; RK4 with one step count
/// n = ceil(max |t - t_b| / step_s) for the whole batch at each evaluation (as glonass.glonass_integrate).
inline void transmit_states_glonass(const double* glo, const std::int64_t* idx, std::int64_t k, const double* t_rx,
                                    const double* r_rx, int r_rx_stride, const GlonassConstants& c, double step_s,
                                    double tol_s, int max_iter, double* dt_scratch, TransmitOutput& out) {
  using C = GlonassCols;
  // every evaluation of the batch shares one step count: the times of one pass are known before it
  int n_steps = 0;
  auto steps_for = [&](const double* t_of_row) {
    double m = 0.0;
    for (std::int64_t i = 0; i < k; ++i) m = std::max(m, std::abs(t_of_row[i] - glo[C::kCols * idx[i] + C::kTb]));
    return m > 0.0 ? static_cast<int>(std::ceil(m / step_s)) : 0;
  };
  // light time from the state at t_rx - 0.075 s (one RK4 pass for the batch), then the exact state at t_tx
  for (std::int64_t i = 0; i < k; ++i) dt_scratch[i] = t_rx[i] - 0.075;
  n_steps = steps_for(dt_scratch);
  OrbitState st;
  double deriv[6];
  for (std::int64_t i = 0; i < k; ++i) {
    const double* g = glo + C::kCols * idx[i];
    detail::glonass_integrate(g, dt_scratch[i] - g[C::kTb], n_steps, c, st);
    const double s6[6] = {st.r[0], st.r[1], st.r[2], st.v[0], st.v[1], st.v[2]};
    detail::glonass_rhs(s6, g + C::kAx, c, deriv);
    out.tau_s[i] = light_time_row(st, deriv + 3, r_rx + r_rx_stride * i, tol_s, max_iter);
  }
  // one exact step of the iteration: tau consistent with the range of the state returned
  for (std::int64_t i = 0; i < k; ++i) dt_scratch[i] = t_rx[i] - out.tau_s[i];
  n_steps = steps_for(dt_scratch);
  for (std::int64_t i = 0; i < k; ++i) {
    const double* g = glo + C::kCols * idx[i];
    double rt[3];
    detail::glonass_integrate(g, dt_scratch[i] - g[C::kTb], n_steps, c, st);
    detail::rotate_z(st.r, kOmegaEDotGps * out.tau_s[i], rt);
    out.tau_s[i] = detail::range_to(rt, r_rx + r_rx_stride * i) / kCLight;
  }
  for (std::int64_t i = 0; i < k; ++i) dt_scratch[i] = t_rx[i] - out.tau_s[i];
  n_steps = steps_for(dt_scratch);
  for (std::int64_t i = 0; i < k; ++i) {
    const double* g = glo + C::kCols * idx[i];
    const double tau = out.tau_s[i];
    const double t_tx = dt_scratch[i];
    detail::glonass_integrate(g, t_tx - g[C::kTb], n_steps, c, st);
    const double theta = kOmegaEDotGps * tau;
    detail::rotate_z(st.r, theta, out.r_e + 3 * i);
    detail::rotate_z(st.v, theta, out.v_e + 3 * i);
    // ICD A.3.1.2: dt_sv = -tau_n + gamma_n (t - t_b) (clock_bias holds -tau_n)
    out.clock_bias_s[i] = g[C::kClockBias] + g[C::kGammaN] * (t_tx - g[C::kTb]);
    out.clock_drift_s_s[i] = g[C::kGammaN];
    out.t_tx_gps_s[i] = t_tx;
    out.range_m[i] = detail::range_to(out.r_e + 3 * i, r_rx + r_rx_stride * i);
  }
}

}  // namespace insnav::gnss
