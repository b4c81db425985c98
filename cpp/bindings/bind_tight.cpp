// Tightly coupled run (seed 003): the whole IMU loop in C++ with the GIL
// released; all epochs' satellite data handed over in one call as flat arrays
// (convert.hpp: tight_inputs_from).  layout 17: one receiver clock (GPS, or
// any data whose inter-system biases were removed); layout 20
// (LayoutTightMulti): + the inter-system biases of R, E, C (bind_tight_multi.cpp).
#include <string>

#include "insnav/filter/ekf.hpp"
#include "insnav/filter/rbukf.hpp"
#include "insnav/filter/ukf.hpp"
#include "tight_run.hpp"

namespace insnav::py_bind {

void bind_tight(py::module_& m) {
  m.def(
      "run_tight",
      [](const std::string& filter, const DArray& t, const DArray& dtheta_b, const DArray& dv_b,
         const DArray& epoch_t, const I64Array& epoch_start, const DArray& sats, const DArray& init, const DArray& P0,
         const DArray& corr0, const DArray& clock0, const py::dict& model, const py::dict& config, int layout,
         const py::object& system, const py::object& isb0, const py::object& prn, const py::object& phase,
         const py::object& epoch_still) {
        TightArgs a;
        a.model = imu_model_from_dict(model);
        a.cfg = tight_config_from(config);
        a.ut = ut_from(config);
        a.smooth = flag(config, "smooth", false);
        a.imu = imu_arrays(t, dtheta_b, dv_b);
        a.in = tight_inputs_from(epoch_t, epoch_start, sats, system, prn);
        a.phase = phase_rows_from(phase, a.in);
        if (a.cfg.tdcp.enabled && a.phase.empty())
          throw py::value_error("tdcp: the config asks for TDCP rows but no carrier phase was given (phase=None)");
        if (!epoch_still.is_none()) {  // the standstill level of Q (engine/tight_engine.hpp)
          const py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast> s(epoch_still);
          if (s.size() != epoch_t.size()) throw py::value_error("epoch_still: expected one flag per epoch");
          a.epoch_still.assign(s.data(), s.data() + s.size());
        }
        a.nav = nav_state_from(init);
        a.P0 = P0;
        a.corr = imu_correction_from(corr0);
        a.clock_bias0 = clock0_bias(clock0);
        a.clock_drift0 = clock0.data()[1];
        if (!isb0.is_none()) {
          const DArray b = py::cast<DArray>(isb0);
          if (b.size() != 3) throw py::value_error("isb0: expected 3 values (R, E, C) [m]");
          a.isb0 = IsbVec(b.data()[0], b.data()[1], b.data()[2]);
        }
        const SelfCal sc = selfcal_from(config);
        a.time_offset0_s = sc.time_offset0_s;
        if (sc.any()) {  // self-calibration layouts (layout.hpp): on the 17 states, EKF (bind_tight_selfcal.cpp)
          if (layout != 17)
            throw py::value_error("estimate_time_offset / estimate_lever_arm: layout " + std::to_string(layout) +
                                  " unsupported (the self-calibration states extend the 17-state layout: "
                                  "one constellation)");
          if (sc.odo_lever_arm) throw py::value_error("estimate_odo_lever_arm: loose coupling only");
          return run_tight_selfcal(filter, a, sc.time_offset, sc.lever_arm);
        }
        if (layout == 20) return run_tight_multi(filter, a);
        if (layout != 17) throw py::value_error("run_tight: layout must be 17 or 20 (with inter-system biases)");
        if (filter == "ekf") return run_tight_impl<Ekf<Layout17>>(a);
        if (filter == "rbukf") return run_tight_impl<RbUkf<Layout17>>(a);
        if (filter == "ukf") return run_tight_impl<Ukf<Layout17>>(a);
        throw py::value_error("unsupported tight filter: " + filter + " (ekf, rbukf, ukf)");
      },
      py::arg("filter"), py::arg("t"), py::arg("dtheta_b"), py::arg("dv_b"), py::arg("epoch_t"),
      py::arg("epoch_start"), py::arg("sats"), py::arg("init"), py::arg("P0"), py::arg("imu_correction"),
      py::arg("clock0"), py::arg("imu_model"), py::arg("config"), py::arg("layout") = 17,
      py::arg("system") = py::none(), py::arg("isb0") = py::none(), py::arg("prn") = py::none(),
      py::arg("phase") = py::none(), py::arg("epoch_still") = py::none(),
      "Closed-loop tightly coupled run, Layout17 or (layout=20) LayoutTightMulti with inter-system biases "
      "(SI units; see python/insnav/filters/tight.py).  phase: (M, 4) carrier phase [m], wavelength [m], "
      "zero-difference sigma [m], LLI per satellite row, for the TDCP rows (config key 'tdcp').  epoch_still: "
      "the standstill detector's state per epoch (non-zero: stationary), for config key 'standstill_q_scale'.");

  m.def(
      "tdcp_row",
      [](const DArray& prev, const DArray& cur, const DArray& lever_arm_b, const DArray& sat_prev, const DArray& sat_cur,
         double clock_bias_prev_m, double clock_bias_cur_m, const py::object& omega_ib_b_prev,
         const py::object& omega_ib_b_cur, double shift_prev_s, double shift_cur_s, int layout) {
        auto sat = [](const DArray& s, const char* name) {
          if (s.size() != 4) throw py::value_error(std::string(name) + ": expected 4 values (x, y, z [m], c dt_sv [m])");
          return TdcpSatEpoch{Vec3(s.data()[0], s.data()[1], s.data()[2]), s.data()[3]};
        };
        auto vec3 = [](const py::object& o, const char* name) {
          if (o.is_none()) return Vec3(Vec3::Zero());
          const DArray a = py::cast<DArray>(o);
          if (a.size() != 3) throw py::value_error(std::string(name) + ": expected 3 values [rad/s]");
          return Vec3(a.data()[0], a.data()[1], a.data()[2]);
        };
        if (lever_arm_b.size() != 3) throw py::value_error("lever_arm_b: expected 3 values [m]");
        const Vec3 l(lever_arm_b.data()[0], lever_arm_b.data()[1], lever_arm_b.data()[2]);
        const TdcpAntenna a_prev = tdcp_antenna(nav_state_from(prev), l, clock_bias_prev_m,
                                                vec3(omega_ib_b_prev, "omega_ib_b_prev"), shift_prev_s);
        const TdcpAntenna a_cur =
            tdcp_antenna(nav_state_from(cur), l, clock_bias_cur_m, vec3(omega_ib_b_cur, "omega_ib_b_cur"), shift_cur_s);
        auto rows = [&](auto tag) {
          using Lr = decltype(tag);
          const TdcpRow<Lr> r = tdcp_row<Lr>(a_prev, a_cur, sat(sat_prev, "sat_prev"), sat(sat_cur, "sat_cur"));
          py::dict d;
          d["predicted"] = r.predicted;
          DArray hc({py::ssize_t(Lr::kSize)}), hp({py::ssize_t(Lr::kSize)});
          for (int i = 0; i < Lr::kSize; ++i) {
            hc.mutable_data()[i] = r.H_cur[i];
            hp.mutable_data()[i] = r.H_prev[i];
          }
          d["H_cur"] = hc;
          d["H_prev"] = hp;
          return d;
        };
        if (layout == 17) return rows(Layout17{});
        if (layout == 21) return rows(LayoutTightTdLever{});
        throw py::value_error("tdcp_row: layout must be 17 or 21 (LayoutTightTdLever)");
      },
      py::arg("prev"), py::arg("cur"), py::arg("lever_arm_b"), py::arg("sat_prev"), py::arg("sat_cur"),
      py::arg("clock_bias_prev_m"), py::arg("clock_bias_cur_m"), py::arg("omega_ib_b_prev") = py::none(),
      py::arg("omega_ib_b_cur") = py::none(), py::arg("shift_prev_s") = 0.0, py::arg("shift_cur_s") = 0.0,
      py::arg("layout") = 17,
      "The TDCP row of meas/tdcp.hpp: INS-predicted phase change [m] between the navigation states "
      "prev and cur (10 values: t, lat, lon [rad], h [m], v_n [m/s], roll, pitch, yaw [rad]) and its "
      "Jacobians H_cur, H_prev with respect to the error states of the two epochs: (17,) for layout=17, (21,) "
      "for layout=21 (LayoutTightTdLever: + lever arm at 17-19, time offset at 20).  omega_ib_b_*: the "
      "corrected angular rate [rad/s] (the lever arm's velocity); shift_*_s: how far each state is past its "
      "epoch's applied time [s] (the antenna is moved back along its velocity).");

  m.def(
      "pseudorange_gm_fold_check",
      [](const DArray& Pxx, const DArray& Pxb, const DArray& Pbb, const DArray& Hx, const DArray& R, const DArray& y,
         const py::array_t<std::int32_t, py::array::c_style | py::array::forcecast>& row_slot) {
        using L = Layout17;
        constexpr int n = L::kSize;
        using Block = PseudorangeGmBlock<n>;
        const py::ssize_t m = y.size();
        const py::ssize_t nb = Pbb.ndim() == 2 ? Pbb.shape(0) : 0;
        require_shape(Pxx, n, n, "Pxx");
        require_shape(Pxb, n, nb, "Pxb");
        require_shape(Pbb, nb, nb, "Pbb");
        require_shape(Hx, m, n, "Hx");
        require_shape(R, m, m, "R");
        if (m > kMaxMeasRows || nb > 32 || row_slot.size() != m)
          throw py::value_error("pseudorange_gm_fold_check: at most 32 rows and 32 states, row_slot (m,)");
        Block blk;
        PseudorangeGmConfig c;
        c.sigma_m = 1.0;
        blk.reset(c);
        Eigen::Matrix<double, n, 32> xb = Eigen::Matrix<double, n, 32>::Zero();
        Eigen::Matrix<double, 32, 32> bb = Eigen::Matrix<double, 32, 32>::Zero();
        for (int k = 0; k < nb; ++k) {
          blk.observe(k, 0.0);  // satellites 0..nb-1 take slots 0..nb-1
          for (int i = 0; i < n; ++i) xb(i, k) = Pxb.data()[i * nb + k];
          for (int j = 0; j < nb; ++j) bb(k, j) = Pbb.data()[k * nb + j];
        }
        blk.set_covariance(xb, bb);
        StateCov<L> P;
        for (int i = 0; i < n; ++i)
          for (int j = 0; j < n; ++j) P(i, j) = Pxx.data()[i * n + j];
        LinearMeasurement<L> lin;
        lin.residual.resize(m);
        lin.H.setZero(m, n);
        lin.R.setZero(m, m);
        for (int r = 0; r < m; ++r) {
          lin.residual[r] = y.data()[r];
          for (int j = 0; j < n; ++j) lin.H(r, j) = Hx.data()[r * n + j];
          for (int j = 0; j < m; ++j) lin.R(r, j) = R.data()[r * m + j];
        }
        if (!blk.fold(P, lin.H, lin.R, row_slot.data(), static_cast<int>(m)))
          throw py::value_error("pseudorange_gm_fold_check: Pxx not positive definite");
        const StateCov<L> P_prior = P;
        StateVec<L> x = StateVec<L>::Zero();
        const UpdateResult res = kalman_update<L>(x, P, lin, 0.0);
        if (!res.applied || !blk.joint_posterior(P_prior, lin.H, lin.R, lin.residual, x, P))
          throw py::value_error("pseudorange_gm_fold_check: S not positive definite");
        py::dict d;
        d["nis"] = res.nis;
        DArray xo({py::ssize_t(n)}), xbo({nb}), Pxo({py::ssize_t(n), py::ssize_t(n)}), Pxbo({py::ssize_t(n), nb}),
            Pbbo({nb, nb});
        for (int i = 0; i < n; ++i) {
          xo.mutable_data()[i] = x[i];
          for (int j = 0; j < n; ++j) Pxo.mutable_data()[i * n + j] = P(i, j);
          for (int k = 0; k < nb; ++k) Pxbo.mutable_data()[i * nb + k] = blk.Pxb()(i, k);
        }
        for (int k = 0; k < nb; ++k) {
          xbo.mutable_data()[k] = -blk.estimate(k);  // b^ started at 0 and was fed back: b^ = -x_b+
          for (int j = 0; j < nb; ++j) Pbbo.mutable_data()[k * nb + j] = blk.Pbb()(k, j);
        }
        d["x"] = xo;
        d["xb"] = xbo;
        d["Pxx"] = Pxo;
        d["Pxb"] = Pxbo;
        d["Pbb"] = Pbbo;
        return d;
      },
      py::arg("Pxx"), py::arg("Pxb"), py::arg("Pbb"), py::arg("Hx"), py::arg("R"), py::arg("y"), py::arg("row_slot"),
      "Test hook of meas/pseudorange_gm.hpp (Layout17): the prior (Pxx, Pxb, Pbb) of the navigation errors and nb "
      "Gauss-Markov pseudorange states, m rows (Hx, R, residual y; row_slot[r] = the b state of a pseudorange row, "
      "-1 for a Doppler row) folded into the EKF update, then the block's joint posterior: nis, x (17,), "
      "xb (nb,), Pxx, Pxb, Pbb.");
}

}  // namespace insnav::py_bind
