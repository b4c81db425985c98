// insnav/filter/error_model_nonlinear.hpp -- the exact (large-error) INS error
// model of seed 000 eqs. (1)-(7): the state equation of the RB-UKF and UKF.
//
// Error convention (layout.hpp): delta = computed - true.  Every "true"
// quantity is formed exactly as computed minus error -- L = L~ - dL,
// h = h~ - dh, v = v~ - dv, f_b = f~_b - df_b, omega_ib_b = omega~_ib_b - dw_b,
// C_nb = C_{n n'} C~_{n' b} -- and the Earth terms (radii, gravity, Earth and
// transport rates) are evaluated at the true point; no small-angle or
// first-order approximation anywhere.  For small errors the model reduces to
// linear_F (error_model_linear.hpp).
//
// Attitude, seed 000 eqs. (1)-(3).  C_{n'n} = C_n^{n'} = dcm_from_euler(psi)^T
// (3-2-1 Euler platform error angles of n' relative to n).  Differentiating
// C_{n'n} = C~_{n'b} C_nb^T with the two mechanizations
//   C~' = C~ [omega~_ib x] - [omega~_in x] C~,  C' = C [omega_ib x] - [omega_in x] C
// gives C_{n'n}' = -[omega_nn'^{n'} x] C_{n'n} with
//   omega_nn'^{n'} = (I - C_{n'n}) omega~_in + C_{n'n} d omega_in - C~_{n'b} dw_b   (eq. (3))
//                  = omega~_in - C_{n'n} omega_in - C~_{n'b} dw_b,
// and the Euler-rate kinematics omega_nn'^{n'} = C_psi psi' (eq. (2)),
//   C_psi = [[1, 0, -sin psi_y], [0, cos psi_x, sin psi_x cos psi_y],
//            [0, -sin psi_x, cos psi_x cos psi_y]],
// solved in closed form (det C_psi = cos psi_y; singular only at psi_y = 90 deg).
//
// Velocity, seed 000 eq. (4) (lost in the extracted text; derived here and
// checked against two full mechanizations in cpp/tests/test_nonlinear_model.cpp).
// Subtracting v' = C_nb f_b - (2 omega_ie + omega_en) x v + g from
// v~' = C~ f~_b - (2 omega~_ie + omega~_en) x v~ + g~ with C_nb = C_{n n'} C~:
//   dv' = [I - C_{n n'}] C~ f~_b + C_{n n'} C~ df_b
//         - (2 omega~_ie + omega~_en) x dv - (2 d omega_ie + d omega_en) x (v~ - dv) + dg
// (C_{n n'} = (C_n^{n'})^T; the digest's form, Yan Gongmin 2009).
//
// Position, seed 000 eq. (5) (its R_N is our meridian radius R_M):
//   dL'      = v~_N / (R_M~ + h~) - (v~_N - dv_N) / (R_M + h)
//   dlambda' = v~_E / ((R_N~ + h~) cos L~) - (v~_E - dv_E) / ((R_N + h) cos L)
//   dh'      = -dv_D
// Our position error is in NED metres with the *computed* radii, as the engine's
// feedback uses them (layout.hpp, loose_engine.hpp):
//   dr = [dL (R_M~ + h~), dlambda (R_N~ + h~) cos L~, -dh]
// so dr' also carries the rate of the conversion factors along the computed
// trajectory (L~' = v~_N / (R_M~ + h~), h~' = -v~_D):
//   dr_N' = dL' (R_M~ + h~) + dL (dR_M/dL L~' - v~_D)
//   dr_E' = dlambda' (R_N~ + h~) cos L~
//           + dlambda [(dR_N/dL L~' - v~_D) cos L~ - (R_N~ + h~) sin L~ L~']
//   dr_D' = dv_D.
//
// IMU errors, seed 000 eqs. (6)-(7): first-order Gauss-Markov, b' = -b / tau
// (tau = inf: random constant / random walk, b' = 0); white noise is in Q.
// Scale factors (Layout21): the IMU is modelled as  meas = (1 + s) true + b
// (the engine's ImuCorrection inverts exactly this), so exactly
//   df_b = f~ - f = (b_a + s_a f~) / (1 + s_a),   dw_b = (b_g + s_g omega~) / (1 + s_g)
// (elementwise); to first order df = b_a + diag(f~) s_a, as in linear_F.
// Odometer scale factor (Layout16Odo): s_odo' = -s_odo / tau (tau = inf: 0); it
// enters only the odometer measurement (meas/vehicle.hpp), not the INS errors.
// Clock (Layout17): bias' = drift, drift' = 0 (integrated random walk); inter-system
// biases (LayoutTightMulti): isb' = 0 (random walk).
#pragma once

#include <cmath>

#include "insnav/filter/types.hpp"

namespace insnav {

/// The parts of the error-state derivative that depend only on the computed
/// INS point (and the model), precomputed once and shared by all sigma points.
struct NonlinearErrorPoint {
  const InsPoint* ins = nullptr;
  Vec3 f_n_computed = Vec3::Zero();  // C~_{n'b} f~_b
  Vec3 omega_in_computed = Vec3::Zero();
  Vec3 coriolis_computed = Vec3::Zero();  // (2 omega~_ie + omega~_en) x v~
  double RMh = 0.0, RNh = 0.0;            // R_M~ + h~, R_N~ + h~
  double inv_RMh = 0.0, inv_RNh_cos = 0.0; // 1 / (R_M~ + h~), 1 / ((R_N~ + h~) cos L~)
  double lat_rate = 0.0;                  // L~' [rad/s]
  double dRM_dlat = 0.0, dRN_dlat = 0.0;  // [m/rad] at L~
  double lon_rate = 0.0;                  // lambda~' [rad/s]
  Vec3 decay_acc_bias = Vec3::Zero(), decay_gyro_bias = Vec3::Zero();  // 1/tau or 0
  Vec3 decay_acc_scale = Vec3::Zero(), decay_gyro_scale = Vec3::Zero();
  double decay_odo_scale = 0.0;  // 1 / odo_scale_tau or 0 (layouts with kOdoScale)

  static double decay(double tau) { return (std::isfinite(tau) && tau > 0.0) ? 1.0 / tau : 0.0; }

  void set(const InsPoint& p, const ImuErrorModel& m) {
    ins = &p;
    const EarthTerms& e = p.earth;
    f_n_computed = p.C_nb * p.f_ib_b;
    omega_in_computed = e.omega_ie_n + e.omega_en_n;
    coriolis_computed = (2.0 * e.omega_ie_n + e.omega_en_n).cross(p.v_n);
    RMh = e.radii.R_M + p.h;
    RNh = e.radii.R_N + p.h;
    inv_RMh = 1.0 / RMh;
    inv_RNh_cos = 1.0 / (RNh * e.cos_lat);
    lat_rate = p.v_n.x() * inv_RMh;
    lon_rate = p.v_n.y() * inv_RNh_cos;
    const double w = 1.0 - wgs84::kE2 * e.sin_lat * e.sin_lat;
    const double k = wgs84::kE2 * e.sin_lat * e.cos_lat / w;  // d ln(R_N)/dL = k, d ln(R_M)/dL = 3k
    dRN_dlat = e.radii.R_N * k;
    dRM_dlat = 3.0 * e.radii.R_M * k;
    for (int i = 0; i < 3; ++i) {
      decay_acc_bias[i] = decay(m.acc_bias_tau[i]);
      decay_gyro_bias[i] = decay(m.gyro_bias_tau[i]);
      decay_acc_scale[i] = decay(m.acc_scale_tau[i]);
      decay_gyro_scale[i] = decay(m.gyro_scale_tau[i]);
    }
    decay_odo_scale = decay(m.odo_scale_tau);
  }
};

/// Exact specific-force and angular-rate errors (measured - true) in body axes
/// from the sensor states of dx (see the header comment for the scale model).
template <class L>
inline void imu_errors_from_state(const StateVec<L>& dx, const Vec3& f_b, const Vec3& omega_b, Vec3& df_b,
                                  Vec3& dw_b) {
  df_b = dx.template segment<3>(L::kAccBias);
  dw_b = dx.template segment<3>(L::kGyroBias);
  if constexpr (kHasScale<L>) {
    const Vec3 s_a = dx.template segment<3>(L::kAccScale), s_g = dx.template segment<3>(L::kGyroScale);
    df_b = ((df_b + s_a.cwiseProduct(f_b)).array() / (1.0 + s_a.array())).matrix();
    dw_b = ((dw_b + s_g.cwiseProduct(omega_b)).array() / (1.0 + s_g.array())).matrix();
  }
}

/// Deterministic part of the nonlinear error-state derivative d(dx)/dt at one
/// INS point, precomputed (seed 000 eqs. (3)-(7), header comment).
template <class L>
StateVec<L> nonlinear_error_rate(const StateVec<L>& dx, const NonlinearErrorPoint& pt) {
  const InsPoint& ins = *pt.ins;
  const EarthTerms& ec = ins.earth;
  StateVec<L> rate;

  const Vec3 dr = dx.template segment<3>(L::kPos);
  const Vec3 dv = dx.template segment<3>(L::kVel);
  const Vec3 psi = dx.template segment<3>(L::kAtt);
  Vec3 df_b, dw_b;
  imu_errors_from_state<L>(dx, ins.f_ib_b, ins.omega_ib_b, df_b, dw_b);

  // --- true point: L = L~ - dL, h = h~ - dh, v = v~ - dv ----------------------
  const double dL = dr.x() * pt.inv_RMh;
  const double dlon = dr.y() * pt.inv_RNh_cos;
  const double dh = -dr.z();
  const double h = ins.h - dh;
  const Vec3 v_n = ins.v_n - dv;
  // sin, cos of L = L~ - dL from L~'s and the small dL's (rotation.hpp: sincos_exact)
  double s_dL, c_dL;
  sincos_exact(dL, s_dL, c_dL);
  EarthTerms et;
  et.evaluate(ec.sin_lat * c_dL - ec.cos_lat * s_dL, ec.cos_lat * c_dL + ec.sin_lat * s_dL, h, v_n);

  // --- attitude, eqs. (1)-(3) -------------------------------------------------
  const Mat3 C_n_np = dcm_from_euler(psi);  // C_{n n'} = (C_n^{n'})^T
  const Vec3 omega_in_true = et.omega_ie_n + et.omega_en_n;
  // (I - C_{n'n}) omega~_in + C_{n'n} (omega~_in - omega_in) = omega~_in - C_{n'n} omega_in
  const Vec3 w = pt.omega_in_computed - C_n_np.transpose() * omega_in_true - ins.C_nb * dw_b;
  // psi' = C_psi^{-1} w, eq. (2) solved in closed form
  double sx, cx, sy, cy;
  sincos_exact(psi.x(), sx, cx);
  sincos_exact(psi.y(), sy, cy);
  const double psi_z_rate = (sx * w.y() + cx * w.z()) / cy;
  rate.template segment<3>(L::kAtt) =
      Vec3(w.x() + sy * psi_z_rate, cx * w.y() - sx * w.z(), psi_z_rate);

  // --- velocity, eq. (4) --------------------------------------------------------
  // [I - C_{nn'}] C~ f~ + C_{nn'} C~ df = C~ f~ - C_{nn'} C~ (f~ - df)
  const Vec3 f_n_true = C_n_np * (ins.C_nb * (ins.f_ib_b - df_b));
  const Vec3 coriolis_true = (2.0 * et.omega_ie_n + et.omega_en_n).cross(v_n);
  rate.template segment<3>(L::kVel) = pt.f_n_computed - f_n_true - pt.coriolis_computed + coriolis_true +
                                      Vec3(0.0, 0.0, ec.g - et.g);

  // --- position, eq. (5), in NED metres with the computed radii -------------------
  const double RMh_true = et.radii.R_M + h, RNh_true = et.radii.R_N + h;
  const double dlat_rate = pt.lat_rate - v_n.x() / RMh_true;
  const double dlon_rate = pt.lon_rate - v_n.y() / (RNh_true * et.cos_lat);
  const double h_rate = -ins.v_n.z();
  rate[L::kPos] = dlat_rate * pt.RMh + dL * (pt.dRM_dlat * pt.lat_rate + h_rate);
  rate[L::kPos + 1] = dlon_rate * pt.RNh * ec.cos_lat +
                      dlon * ((pt.dRN_dlat * pt.lat_rate + h_rate) * ec.cos_lat - pt.RNh * ec.sin_lat * pt.lat_rate);
  rate[L::kPos + 2] = dv.z();

  // --- sensor errors, eqs. (6)-(7), and the receiver clock ------------------------
  rate.template segment<3>(L::kAccBias) = -pt.decay_acc_bias.cwiseProduct(dx.template segment<3>(L::kAccBias));
  rate.template segment<3>(L::kGyroBias) = -pt.decay_gyro_bias.cwiseProduct(dx.template segment<3>(L::kGyroBias));
  if constexpr (kHasScale<L>) {
    rate.template segment<3>(L::kAccScale) = -pt.decay_acc_scale.cwiseProduct(dx.template segment<3>(L::kAccScale));
    rate.template segment<3>(L::kGyroScale) =
        -pt.decay_gyro_scale.cwiseProduct(dx.template segment<3>(L::kGyroScale));
  }
  if constexpr (kHasClock<L>) {
    rate[L::kClockBias] = dx[L::kClockDrift];
    rate[L::kClockDrift] = 0.0;
  }
  if constexpr (kHasOdoScale<L>) {  // odometer scale factor: s' = -s / tau (no effect on the INS errors)
    constexpr int O = OdoScaleState<L>::offset;
    rate[O] = -pt.decay_odo_scale * dx[O];
  }
  if constexpr (kHasIsb<L>) rate.template segment<IsbStates<L>::count>(IsbStates<L>::offset).setZero();  // random walk
  return rate;
}

/// Convenience form: the same at one INS point (precomputes per call).
template <class L>
StateVec<L> nonlinear_error_rate(const StateVec<L>& dx, const InsPoint& ins, const ImuErrorModel& m) {
  NonlinearErrorPoint pt;
  pt.set(ins, m);
  return nonlinear_error_rate<L>(dx, pt);
}

/// One RK4 step of the nonlinear error model over an interval with the INS at
/// its start, middle and end (seed 000 sec. 4: the k-1, k-1/2, k points).
template <class L>
void rk4_error_step(StateVec<L>& dx, const NonlinearErrorPoint& p0, const NonlinearErrorPoint& p_half,
                    const NonlinearErrorPoint& p1, double dt) {
  const StateVec<L> k1 = nonlinear_error_rate<L>(dx, p0);
  const StateVec<L> k2 = nonlinear_error_rate<L>(dx + (0.5 * dt) * k1, p_half);
  const StateVec<L> k3 = nonlinear_error_rate<L>(dx + (0.5 * dt) * k2, p_half);
  const StateVec<L> k4 = nonlinear_error_rate<L>(dx + dt * k3, p1);
  dx += (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
}

}  // namespace insnav
