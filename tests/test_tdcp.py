"""Time-differenced carrier phase in the tight EKF (cpp/include/insnav/meas/tdcp.hpp).

* The TDCP row with a lever arm against a numerical Jacobian of its own prediction
  (both epochs' error states, error = computed - true as fed back); the lever-arm and
  time-offset columns of the self-calibration layout against numerical derivatives, and
  the shifted prediction against the exact range change of a constant-velocity receiver.
* A stationary receiver whose body yaws (the antenna on a lever arm turns about the
  IMU), exact IMU increments and exact carrier phases of moving satellites: the
  INS-predicted phase change equals the measured one to 1e-6 m.
* An injected cycle slip of one cycle on one satellite is flagged by the INS-aided
  test (and an LLI flag by the indicator), the other rows are used.
* The option off: bit-identical to a run without phase; on with no phase rows: the
  same solution too (the change is additive).
"""
from __future__ import annotations

import numpy as np
import pytest

from insnav import _core, earth
from insnav.config import ImuNoise, RunConfig, Tdcp, ConfigError, config_from_dict

from imu_exact import euler_to_quat, quat_to_dcm, stationary_rotating

DEG = np.pi / 180.0
C = 299792458.0
LAMBDA_L1 = C / 1575.42e6


def _true_state(x, dx):
    """The navigation state (10 values) whose computed - true error is dx (17 states), as the feedback."""
    t, lat, lon, h = x[:4]
    a, e2 = 6378137.0, 6.69437999014e-3
    s2 = np.sin(lat) ** 2
    Rn = a / np.sqrt(1 - e2 * s2)
    Rm = a * (1 - e2) / (1 - e2 * s2) ** 1.5
    out = np.array(x, float)
    out[1] = lat - dx[0] / (Rm + h)
    out[2] = lon - dx[1] / ((Rn + h) * np.cos(lat))
    out[3] = h + dx[2]
    C_nb = np.asarray(_core.rotation.dcm_from_euler(np.asarray(x[7:10], float)))
    C_true = np.asarray(_core.rotation.dcm_from_euler(np.asarray(dx[6:9], float))) @ C_nb
    out[7:10] = np.asarray(_core.rotation.euler_from_dcm(C_true))
    return out


def test_tdcp_row_with_lever_arm_matches_numerical_jacobian():
    prev = np.array([0.0, 31.2 * DEG, 121.5 * DEG, 20.0, 1.0, 0.5, 0.0, 3 * DEG, -2 * DEG, 40 * DEG])
    cur = np.array([0.25, 31.2 * DEG + 2e-7, 121.5 * DEG + 1e-7, 20.1, 1.0, 0.5, 0.0, 4 * DEG, -1 * DEG, 55 * DEG])
    lever = np.array([0.4, -0.3, 0.6])
    r0 = earth.geodetic_to_ecef(prev[1], prev[2], prev[3])
    up = r0 / np.linalg.norm(r0)
    los = up + np.array([0.3, -0.5, 0.2])
    sat_p = np.r_[r0 + 2.2e7 * los / np.linalg.norm(los), 1234.5]
    sat_c = sat_p + np.r_[3000.0 * 0.25, -1500.0 * 0.25, 800.0 * 0.25, 0.07]
    b_p, b_c = 1000.0, 1000.3
    row = _core.tdcp_row(prev, cur, lever, sat_p, sat_c, b_p, b_c)
    pred0 = row["predicted"]
    # the prediction itself: ranges of the two antennas, clocks
    for key, x, b in (("H_cur", cur, b_c), ("H_prev", prev, b_p)):
        H = np.asarray(row[key])
        num = np.zeros(17)
        for j in list(range(3)) + list(range(6, 9)) + [15]:
            eps = 1e-2 if j < 3 or j == 15 else 1e-3  # central differences: ranges of 2e7 m in doubles
            val = []
            for sgn in (1.0, -1.0):
                dx = np.zeros(17)
                dx[j] = sgn * eps
                xt = _true_state(x, dx)
                bt = b - (sgn * eps if j == 15 else 0.0)
                args = ((prev, xt, lever, sat_p, sat_c, b_p, bt) if key == "H_cur"
                        else (xt, cur, lever, sat_p, sat_c, bt, b_c))
                val.append(pred0 - _core.tdcp_row(*args)["predicted"])
            num[j] = (val[0] - val[1]) / (2 * eps)
        assert np.abs(H[[3, 4, 5, 9, 10, 11, 12, 13, 14, 16]]).max() == 0.0
        np.testing.assert_allclose(H, num, atol=2e-5, rtol=1e-4)
        assert np.abs(H[6:9]).max() > 0.1  # the lever arm term is there (0.8 m arm)



def test_tdcp_row_selfcal_columns_match_numerical_jacobian():
    """LayoutTightTdLever (21 states): the lever-arm and time-offset columns of a TDCP row are the
    differences of the two epochs' range columns (meas/tdcp.hpp); the time-offset column of each epoch
    against the derivative of the prediction with respect to that epoch's shift (the true antenna is the
    INS at t - shift + dt_d), the lever-arm columns against a common lever-arm perturbation."""
    prev = np.array([0.0, 31.2 * DEG, 121.5 * DEG, 20.0, 1.2, -0.7, 0.1, 3 * DEG, -2 * DEG, 40 * DEG])
    cur = np.array([0.25, 31.2 * DEG + 2e-7, 121.5 * DEG + 1e-7, 20.1, 0.4, 0.9, -0.2, 4 * DEG, -1 * DEG, 55 * DEG])
    lever = np.array([0.4, -0.3, 0.6])
    w_p, w_c = np.array([0.2, -0.1, 0.5]), np.array([-0.3, 0.4, 0.1])  # [rad/s]
    r0 = earth.geodetic_to_ecef(prev[1], prev[2], prev[3])
    los = r0 / np.linalg.norm(r0) + np.array([0.3, -0.5, 0.2])
    sat_p = np.r_[r0 + 2.2e7 * los / np.linalg.norm(los), 1234.5]
    sat_c = sat_p + np.r_[3000.0 * 0.25, -1500.0 * 0.25, 800.0 * 0.25, 0.07]
    b_p, b_c = 1000.0, 1000.3

    def row(lev=lever, s_p=0.02, s_c=0.05, layout=21):
        return _core.tdcp_row(prev, cur, lev, sat_p, sat_c, b_p, b_c, omega_ib_b_prev=w_p, omega_ib_b_cur=w_c,
                              shift_prev_s=s_p, shift_cur_s=s_c, layout=layout)

    r21, r17 = row(), row(layout=17)
    H_c, H_p = np.asarray(r21["H_cur"]), np.asarray(r21["H_prev"])
    assert H_c.shape == (21,)
    assert r21["predicted"] == r17["predicted"]
    np.testing.assert_array_equal(H_c[:17], r17["H_cur"])  # the 17 navigation/clock columns unchanged
    np.testing.assert_array_equal(H_p[:17], r17["H_prev"])
    eps = 1e-3  # [s]: central differences of ranges of 2e7 m in doubles
    num_c = (row(s_c=0.05 + eps)["predicted"] - row(s_c=0.05 - eps)["predicted"]) / (2 * eps)
    num_p = (row(s_p=0.02 + eps)["predicted"] - row(s_p=0.02 - eps)["predicted"]) / (2 * eps)
    np.testing.assert_allclose([H_c[20], H_p[20]], [num_c, num_p], rtol=1e-4, atol=2e-5)
    assert abs(H_c[20]) > 0.1 and abs(H_p[20]) > 0.1  # the velocities make a column of order 1 m/s
    # the lever-arm columns (unshifted: the shift's own lever-arm term, shift x omega x dl, is second order
    # and left out as in pseudorange.hpp): the sum against a common perturbation dl_b = l_b^ - l_b ...
    r0 = row(s_p=0.0, s_c=0.0)
    H_c, H_p = np.asarray(r0["H_cur"]), np.asarray(r0["H_prev"])
    num_l = np.zeros(3)
    for j in range(3):
        dl = np.zeros(3)
        dl[j] = 1e-2
        num_l[j] = (row(lever + dl, 0.0, 0.0)["predicted"] - row(lever - dl, 0.0, 0.0)["predicted"]) / 2e-2
    np.testing.assert_allclose(H_c[17:20] + H_p[17:20], num_l, atol=2e-5, rtol=1e-4)
    assert np.abs(H_c[17:20] + H_p[17:20]).max() > 0.05  # the 15 deg turn between the epochs
    # ... and each epoch's column is its position column (-u^T, +u^T) rotated by that epoch's C_nb
    for H, x in ((H_c, cur), (H_p, prev)):
        C_nb = np.asarray(_core.rotation.dcm_from_euler(np.asarray(x[7:10], float)))
        np.testing.assert_allclose(H[17:20], H[0:3] @ C_nb, atol=1e-12)


def test_tdcp_row_shift_analytic_constant_velocity():
    """A receiver moving at a constant ECEF velocity; each INS state is taken shift_j after its epoch's
    time (the time-offset estimate moved it).  The shifted prediction equals the exact range and clock
    difference at the epochs' true positions (the first-order move is exact on a straight line; the
    range's curvature over the 0.5 m shift is 1e-8 m)."""
    lat0, lon0, h0 = 45.0 * DEG, 7.0 * DEG, 300.0
    r0 = earth.geodetic_to_ecef(lat0, lon0, h0)
    v_e = earth.ned_to_ecef_vector(lat0, lon0, np.array([8.0, -6.0, 0.5]))
    sats = [r0 + 2.2e7 * u / np.linalg.norm(u) for u in (r0 / np.linalg.norm(r0) + np.array([0.2, 0.1, -0.3]),
                                                          r0 / np.linalg.norm(r0) + np.array([-0.4, 0.3, 0.1]))]
    t_p, t_c, s_p, s_c = 0.0, 0.25, 0.03, -0.04

    def state(t):
        r = r0 + v_e * t
        lat, lon, h = earth.ecef_to_geodetic(r)
        return np.r_[t, lat, lon, h, earth.ecef_to_ned_vector(lat, lon, v_e), 0.0, 0.0, 0.0]

    for rs in sats:
        exact = np.linalg.norm(rs - (r0 + v_e * t_c)) - np.linalg.norm(rs - (r0 + v_e * t_p))
        out = _core.tdcp_row(state(t_p + s_p), state(t_c + s_c), np.zeros(3), np.r_[rs, 0.0], np.r_[rs, 0.0],
                             0.0, 0.0, shift_prev_s=s_p, shift_cur_s=s_c, layout=21)
        assert abs(out["predicted"] - exact) < 1e-6
        unshifted = _core.tdcp_row(state(t_p + s_p), state(t_c + s_c), np.zeros(3), np.r_[rs, 0.0],
                                   np.r_[rs, 0.0], 0.0, 0.0, layout=21)
        assert abs(unshifted["predicted"] - exact) > 1e-3  # the shift matters: u.v (s_c - s_p), mm to cm

# ------------------------------------------------------------------ engine cases
LAT, LON, H0 = 30.5 * DEG, 114.3 * DEG, 25.0
LEVER = np.array([0.5, 0.2, -0.3])
RATE = 100.0
T_END = 10.0
YAW_RATE = 0.3  # rad/s: the antenna turns about the IMU on the lever arm


def _yaw(tt):
    tt = np.asarray(tt, float)
    z = np.zeros_like(tt)
    return np.stack([np.cos(0.5 * YAW_RATE * tt), z, z, np.sin(0.5 * YAW_RATE * tt)], -1)


def _yaw_dot(tt):
    tt = np.asarray(tt, float)
    z = np.zeros_like(tt)
    return np.stack([-0.5 * YAW_RATE * np.sin(0.5 * YAW_RATE * tt), z, z, 0.5 * YAW_RATE * np.cos(0.5 * YAW_RATE * tt)],
                    -1)


@pytest.fixture(scope="module")
def exact_case():
    """Exact IMU of a stationary yawing body, 6 moving satellites, exact phases at 4 Hz."""
    rpy0 = np.array([2.0, -1.5, 30.0]) * DEG
    q0 = euler_to_quat(rpy0)
    t, dth, dv, q_true = stationary_rotating(LAT, H0, q0, _yaw, _yaw_dot, T_END, RATE)
    r_imu = earth.geodetic_to_ecef(LAT, LON, H0)
    C_en = earth.C_en(LAT, LON)
    ep_t = np.arange(0.25, T_END - 0.01, 0.25)
    k = np.rint(ep_t * RATE).astype(int) - 1  # the IMU sample at each epoch
    C_nb = quat_to_dcm(q_true[k])
    r_ant = r_imu + (C_en @ (C_nb @ LEVER)[..., None])[..., 0]
    rng = np.random.default_rng(3)
    n_sat = 6
    az = np.radians([10, 80, 150, 200, 260, 320])
    el = np.radians([70, 35, 50, 25, 60, 40])
    los_n = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], -1)
    r_s0 = r_imu + 2.2e7 * (C_en @ los_n.T).T
    v_s = rng.normal(0.0, 2000.0, (n_sat, 3))
    clk0, clk1 = rng.normal(0, 1e4, n_sat), rng.normal(0, 0.3, n_sat)
    b0, d0 = 250.0, 0.8  # receiver clock [m], [m/s]
    n_amb = rng.integers(-10 ** 6, 10 ** 6, n_sat)
    sats, phase, prn = [], [], []
    for e, te in enumerate(ep_t):
        for s in range(n_sat):
            rs = r_s0[s] + v_s[s] * te
            clk = clk0[s] + clk1[s] * te
            rho = np.linalg.norm(rs - r_ant[e])
            sats.append([np.nan, np.nan, *rs, *v_s[s], clk, clk1[s], 1.0, 1.0])
            phase.append([rho + b0 + d0 * te - clk + n_amb[s] * LAMBDA_L1, LAMBDA_L1, 0.003, 0.0])
            prn.append(s + 1)
    sats, phase, prn = np.array(sats), np.array(phase), np.array(prn, np.int64)
    start = np.arange(ep_t.size + 1, dtype=np.int64) * n_sat
    init = np.array([0.0, LAT, LON, H0, 0, 0, 0, *rpy0])
    model = {k: v for k, v in ImuNoise().as_core_dict().items()}
    model["clock_bias_psd"], model["clock_drift_psd"] = 0.1, 0.01
    P0 = np.diag(np.r_[[1.0] * 3, [0.1] * 3, [0.01] * 3, [1e-3] * 3, [1e-5] * 3, 10.0, 1.0] ** 2)
    return dict(t=t, dth=dth, dv=dv, ep_t=ep_t, start=start, sats=sats, phase=phase, prn=prn, init=init,
                model=model, P0=P0, clock0=np.array([b0, d0]), n_sat=n_sat, r_ant=r_ant)


def _run(c, phase=None, **cfg):
    config = dict(lever_arm_b=LEVER, propagation_interval=0.05, cycle_period=0.25, gate_prob=0.0, **cfg)
    return _core.run_tight("ekf", c["t"], c["dth"], c["dv"], c["ep_t"], c["start"], c["sats"], c["init"], c["P0"],
                           np.zeros(12), c["clock0"], c["model"], config, prn=c["prn"], phase=phase)


def test_exact_static_case_predicted_equals_measured(exact_case):
    c = exact_case
    out = _run(c, c["phase"], tdcp=True)
    flag = out["tdcp_flag"].reshape(-1, c["n_sat"])
    res = out["tdcp_residual"].reshape(-1, c["n_sat"])
    assert np.all(flag[0] == -1)  # the first epoch has no previous one
    assert np.all(flag[1:] == 0)  # every later row used
    assert out["tdcp_used"] == (c["ep_t"].size - 1) * c["n_sat"]
    assert np.abs(res[1:]).max() < 1e-6
    # the solution stays on the truth (no update moved it)
    llh = out["llh"][-1]
    r = earth.geodetic_to_ecef(*llh)
    assert np.linalg.norm(r - earth.geodetic_to_ecef(LAT, LON, H0)) < 1e-5


def test_injected_cycle_slip_is_flagged(exact_case):
    c = exact_case
    ph = c["phase"].copy()
    n = c["n_sat"]
    slip_epoch, slip_sat = 12, 3
    ph[slip_epoch * n + slip_sat:, 0] += np.where(np.arange(len(ph) - slip_epoch * n - slip_sat) % n == 0,
                                                  LAMBDA_L1, 0.0)  # +1 cycle from this epoch on
    lli_epoch, lli_sat = 20, 1
    ph[lli_epoch * n + lli_sat, 3] = 1.0
    out = _run(c, ph, tdcp=True)
    flag = out["tdcp_flag"].reshape(-1, n)
    res = out["tdcp_residual"].reshape(-1, n)
    assert flag[slip_epoch, slip_sat] == 2  # INS-predicted phase-change test
    assert abs(res[slip_epoch, slip_sat] + LAMBDA_L1) < 1e-6  # predicted - measured = -1 cycle
    assert flag[lli_epoch, lli_sat] == 1
    assert out["tdcp_slips_ins"] == 1 and out["tdcp_slips_lli"] == 1
    others = np.ones_like(flag, bool)
    others[0] = False
    others[slip_epoch, slip_sat] = others[lli_epoch, lli_sat] = False
    assert np.all(flag[others] == 0)  # the arc goes on after the slip (a TDCP needs no ambiguity)
    llh = out["llh"][-1]
    assert np.linalg.norm(earth.geodetic_to_ecef(*llh) - earth.geodetic_to_ecef(LAT, LON, H0)) < 1e-5


def test_option_off_is_bit_identical(exact_case):
    c = exact_case
    sats = c["sats"].copy()
    rng = np.random.default_rng(1)
    # pseudoranges and rates with noise, so the code update moves the solution
    r_ant = np.repeat(c["r_ant"], c["n_sat"], axis=0)
    rho = np.linalg.norm(sats[:, 2:5] - r_ant, axis=1)
    te = np.repeat(c["ep_t"], c["n_sat"])
    sats[:, 0] = rho + 250.0 + 0.8 * te - sats[:, 8] + rng.normal(0, 3.0, rho.size)
    u = (sats[:, 2:5] - r_ant) / rho[:, None]
    sats[:, 1] = np.einsum("ij,ij->i", u, sats[:, 5:8]) + 0.8 - sats[:, 9] + rng.normal(0, 0.1, rho.size)
    sats[:, 10], sats[:, 11] = 3.0, 0.1
    cc = dict(c, sats=sats)
    base = _run(cc)
    off = _run(cc, c["phase"], tdcp=False)
    nan_phase = c["phase"].copy()
    nan_phase[:, 0] = np.nan
    on_empty = _run(cc, nan_phase, tdcp=True)
    for k in ("llh", "v_n", "rpy", "sigma", "clock", "nis", "sat_residual"):
        np.testing.assert_array_equal(off[k], base[k])
        np.testing.assert_array_equal(on_empty[k], base[k])
    on = _run(cc, c["phase"], tdcp=True)
    assert on["tdcp_used"] > 0
    assert not np.array_equal(on["llh"], base["llh"])


def test_config_and_errors(exact_case):
    cfg = config_from_dict({"coupling": "tight", "tdcp": {"enabled": True, "sigma_phase_m": 0.02}})
    assert cfg.validate().tdcp == Tdcp(enabled=True, sigma_phase_m=0.02)
    with pytest.raises(ConfigError, match="tdcp.sigma_phase_m"):
        config_from_dict({"coupling": "tight", "tdcp": {"enabled": True, "sigma_phase_m": -1}}).validate()
    with pytest.raises(ConfigError, match="unknown key 'tdcp.sigma'"):
        config_from_dict({"tdcp": {"sigma": 1}})
    with pytest.raises(ConfigError, match="tdcp.enabled"):
        RunConfig(coupling="tight", filter="rbukf", tdcp=Tdcp(enabled=True)).validate()
    with pytest.raises(ConfigError, match="tdcp.enabled"):
        RunConfig(coupling="loose", tdcp=Tdcp(enabled=True)).validate()
    c = exact_case
    with pytest.raises(ValueError, match="no carrier phase"):
        _run(c, None, tdcp=True)
    with pytest.raises(ValueError, match="phase: expected shape"):
        _run(c, c["phase"][:5], tdcp=True)
    with pytest.raises(ValueError, match="ekf only"):
        _core.run_tight("rbukf", c["t"], c["dth"], c["dv"], c["ep_t"], c["start"], c["sats"], c["init"], c["P0"],
                        np.zeros(12), c["clock0"], c["model"], dict(lever_arm_b=LEVER, tdcp=True), prn=c["prn"],
                        phase=c["phase"])


def test_walk_tdcp_from_the_command_line(tmp_path, shared_data):
    """Real data (rtklibexplorer walk, u-blox L1 phase): `insnav run --format rinex ... --tdcp` uses the
    TDCP rows of nearly every epoch and tightens the track against the RTK reference (error around each
    solution's mean offset, which is the RTK base's: docs/results/tdcp_walk.md)."""
    import subprocess
    import sys

    from insnav.io.gnss_files import read_rtklib_pos
    from insnav.filters.solution import load_solution

    d = shared_data / "rtklibexplorer_walk_0827"
    repo = __import__("pathlib").Path(__file__).resolve().parents[1]
    args = [sys.executable, "-m", "insnav", "run", "--format", "rinex", "--obs", str(d / "rinex_derived/gnss_1730.obs"),
            "--nav", str(d / "rinex_derived/gnss_1730.nav"), "--imu", str(d / "raw/imu_1730.csv"), "--config",
            str(repo / "tests/data/walk_0827.toml"), "--coupling", "tight", "--filter", "ekf"]
    ref = read_rtklib_pos(d / "raw/gnss_1730_sf.pos")
    spread = {}
    for name, extra in (("code", []), ("tdcp", ["--tdcp"])):
        out = tmp_path / f"{name}.csv"
        p = subprocess.run(args + extra + ["--out", str(out)], capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        assert ("TDCP:" in p.stdout) == (name == "tdcp")
        sol = load_solution(out)
        t_ref = ref.t_gps_s - np.floor(ref.t_gps_s[0] / 604800.0) * 604800.0
        m = (t_ref > sol.t[0]) & (t_ref < sol.t[-1])
        lat = np.interp(t_ref[m], sol.t, sol.lat_deg) * DEG
        lon = np.interp(t_ref[m], sol.t, sol.lon_deg) * DEG
        h = np.interp(t_ref[m], sol.t, sol.h_m)
        lat0, lon0, _ = earth.ecef_to_geodetic(ref.r_e[m][0])
        dn, de, _ = earth.ecef_to_ned_vector(lat0, lon0, earth.geodetic_to_ecef(lat, lon, h) - ref.r_e[m]).T
        spread[name] = float(np.sqrt(np.mean((dn - dn.mean()) ** 2 + (de - de.mean()) ** 2)))
        if name == "tdcp":
            used = int(p.stdout.split("TDCP: ")[1].split(" rows")[0])
            assert used > 1500  # of 1835 rows with phase
            assert "[tdcp]" in (tmp_path / "tdcp.csv.config.toml").read_text()
    assert spread["tdcp"] < 0.7 * spread["code"]


def test_tdcp_accepts_self_calibration_states():
    """TDCP rows carry the time-offset and lever-arm columns (meas/tdcp.hpp): the combination validates."""
    from insnav.config import RunConfig, Tdcp

    for extra in (dict(time={"estimate_offset": True}), dict(lever_arm={"estimate": True})):
        cfg = config_from_dict(dict(filter="ekf", coupling="tight", tdcp={"enabled": True}, **extra)).validate()
        assert cfg.tdcp.enabled and cfg.selfcal
    assert RunConfig(filter="ekf", coupling="tight", tdcp=Tdcp(enabled=True)).validate().selfcal is False