"""The RTS smoother over tight RTK/INS and TDCP/INS (filter/rts_smoother.hpp, engine/rtk_ins_engine.hpp 4.,
ClosedLoop::condition_for_smoother / clone_update_for_smoother).

* RTK/INS (the Spirent drive with a synthesised IMU, one 30 s outage): the smoothed antenna at the
  fixed epochs agrees with the forward fixed antenna (RMS <= 5 mm, every epoch within 1.2 cm: the
  backward pass marginalises the correlated phase error states, which stay random once the integers
  are known; measured 3.7 mm RMS and 10.3 mm at most, 3.4 and 9.7 mm with white phase) and is at
  least as close to the truth; the fix status and ratio are the forward pass's; the smoothed error
  in the outage is a fraction of the forward one.
* The same with the RB-UKF (the unscented RTS smoother, Sarkka 2008 eqs. (13)-(15), the fixed solution
  carried into the next prediction by the cycle's statistically linearised transition): the fixed
  epochs keep the fixed solution and the fix status is the forward pass's; the UKF's smoothed solution
  is the RB-UKF's bit for bit (the DD rows are linear: the same forward filter); and the smoothed
  RB-UKF is the EKF smoother's to millimetres at the fixed epochs and centimetres in the outage.
* TDCP/INS (a stationary yawing receiver, exact IMU, 6 satellites at 4 Hz, pseudoranges 0.5 m and
  phases 3 mm noise): the smoothed position error is below half the forward one (RMS) and within
  0.2 m everywhere, and below the smoothed error of the same run without the TDCP rows.
"""
from __future__ import annotations

import numpy as np
import pytest

from insnav import earth
from insnav.config import RunConfig
from insnav.units import RAD2DEG

from test_rtk_ins import NAV, SP, _remove, _truth_e, drive, need  # noqa: F401 (the fixture)
from test_tdcp import H0, LAT, LON, _run, exact_case  # noqa: F401 (the fixture)

#: the RB-UKF smoother against the EKF smoother (test_unscented_rtk_ins_smoother_rbukf_equals_ukf_and_the_ekf_smoother),
#: as the forward float of the two is held to 2 mm (test_rtk_ins.py): the smoothed antenna at the epochs both
#: fix [m] (measured 0.025 mm RMS, 0.40 mm max); the smoothed IMU-centre rows in the 30 s outage [m] (measured
#: 0.2 mm, where the forward rows differ by 80 mm) and over the whole run [m] (measured 12.3 mm, in the second
#: after the outage, where the forward rows differ by 13.2 mm: the UT's running mean between two epochs)
TOL_FIX_M = 2e-3
TOL_OUTAGE_M = 1e-3
TOL_ROWS_M = 3e-2


@pytest.fixture(scope="module")
def rtk_data():
    """The Spirent drive's rover with one 30 s outage 100 s in, the base, and the outage start [s GPS]."""
    from insnav.gnss import rtk

    v = "iono-Klob_tropo-Saast"
    rover = rtk.read_phase_obs(need(SP / v / "Rover-dynamic_MO_Spirent.obs"), "GE")
    base = rtk.read_phase_obs(SP / v / "Base-static_MO_Spirent.obs", "GE")
    t_a = rover.epoch_t_gps_s[0] + 100.0
    rov2, _ = _remove(rover, t_a, t_a + 30.0)
    return rov2, base, t_a


def _rtk_run(drive, rtk_data, filt, smooth):  # noqa: F811
    """A run on rtk_data.  The unscented forward runs close their outage cycles as a smoothed run does
    (1.5 rover periods, insnav.filters.rtk_ins): the UT redraws its points at every cycle (seed 000
    eqs. (26)-(29)), so their forward pass is the smoothed run's only with the same cycles (the EKF's
    propagation does not depend on where cycles end)."""
    from insnav.filters.rtk_ins import run_rtk_ins

    rov2, base, _ = rtk_data
    engine = None
    if filt != "ekf" and not smooth:
        d = np.diff(rov2.epoch_t_gps_s)
        engine = dict(outage_cycle_s=1.5 * float(np.median(d[d > 0])))
    return run_rtk_ins(drive, RunConfig(filter=filt, smooth=smooth), rover=rov2, base=base, nav=NAV,
                       rtk_options=dict(systems="GE", frequencies=2), engine=engine)


@pytest.fixture(scope="module")
def rtk_runs(drive, rtk_data):  # noqa: F811
    runs = {sm: _rtk_run(drive, rtk_data, "ekf", sm) for sm in (False, True)}
    return runs, rtk_data[2]


@pytest.fixture(scope="module")
def unscented_rtk_runs(drive, rtk_data):  # noqa: F811
    """The RB-UKF forward and smoothed, the UKF smoothed (the same data as rtk_runs)."""
    return {k: _rtk_run(drive, rtk_data, *k) for k in (("rbukf", False), ("rbukf", True), ("ukf", True))}


def _check_fixed_epochs_keep_the_fixed_solution(drive, f, s):  # noqa: F811
    """The smoothed run s against its forward run f; returns the smoothed minus forward fixed antenna
    RMS and max [m]."""
    np.testing.assert_array_equal(s.fix_status, f.fix_status)  # the status column is the forward pass's
    # the ratio to rounding: the smoothed run closes outage cycles, so the ionosphere states' cross-
    # covariance, which outlives a 30 s outage (the ambiguities restart after it), is carried by another
    # product of the same transitions (measured: 2e-8 relative at ratios near 500)
    np.testing.assert_allclose(s.ratio, f.ratio, rtol=1e-6)
    fx = f.rtk.status == 1
    assert fx.mean() > 0.95
    np.testing.assert_allclose(s.rtk.r_e[fx], f.rtk.r_e[fx], atol=1e-6)  # the forward fixed solution itself
    d = np.linalg.norm(s.rtk.r_smoothed_e[fx] - f.rtk.r_e[fx], axis=1)
    assert np.sqrt(np.mean(d ** 2)) < 0.005 and d.max() < 0.012, (np.sqrt(np.mean(d ** 2)), d.max())
    tru = _truth_e(drive, f.rtk.t_gps_s)[fx]
    e_f = np.linalg.norm(f.rtk.r_e[fx] - tru, axis=1)
    e_s = np.linalg.norm(s.rtk.r_smoothed_e[fx] - tru, axis=1)
    ok = np.isfinite(e_f) & np.isfinite(e_s)
    assert np.sqrt(np.mean(e_s[ok] ** 2)) <= np.sqrt(np.mean(e_f[ok] ** 2))
    assert s.summary["smoother"]["gain_failures"] == 0
    return float(np.sqrt(np.mean(d ** 2))), float(d.max())


def test_rtk_ins_smoothed_fixed_epochs_keep_the_fixed_solution(drive, rtk_runs):  # noqa: F811
    (runs, _) = rtk_runs
    _check_fixed_epochs_keep_the_fixed_solution(drive, runs[False], runs[True])


def _outage_error(drive, sol, t_a):  # noqa: F811
    """Maximum 3-D error of the IMU-centre rows in the outage [t_a, t_a + 30 s) [m]."""
    tt = sol.t + drive.gps_time_offset_s
    m = (tt >= t_a) & (tt < t_a + 30.0)
    r = np.asarray(earth.geodetic_to_ecef(np.radians(sol.lat_deg[m]), np.radians(sol.lon_deg[m]), sol.h_m[m]),
                   float).reshape(-1, 3)
    return float(np.nanmax(np.linalg.norm(r - _truth_e(drive, tt[m]), axis=1)))


def test_unscented_rtk_ins_smoothed_fixed_epochs_keep_the_fixed_solution(drive, rtk_data,  # noqa: F811
                                                                          unscented_rtk_runs):
    """The unscented RTS smoother over the RB-UKF RTK/INS: the fixed epochs keep the forward fixed solution
    (RMS <= 5 mm, every epoch within 1.2 cm, at least as close to the truth), the fix status and ratio are
    the forward pass's, and the outage error falls below a quarter of the forward one, as for the EKF."""
    r = unscented_rtk_runs
    _check_fixed_epochs_keep_the_fixed_solution(drive, r["rbukf", False], r["rbukf", True])
    e_f, e_s = (_outage_error(drive, r["rbukf", sm], rtk_data[2]) for sm in (False, True))
    assert e_f > 0.3 and e_s < 0.25 * e_f, (e_f, e_s)


def test_unscented_rtk_ins_smoother_rbukf_equals_ukf_and_the_ekf_smoother(drive, rtk_data, rtk_runs,  # noqa: F811
                                                                            unscented_rtk_runs):
    """RB-UKF and UKF RTK/INS are the same forward filter (linear DD rows, the engine's joint update), so
    their smoothed solutions are the same bit for bit.  Against the EKF's smoother (same fixed integers,
    a different time update): at the epochs both fix the smoothed antennas agree to TOL_FIX_M, the
    smoothed IMU-centre rows in the 30 s outage to TOL_OUTAGE_M (the forward rows differ by 100 times
    more there: the smoother takes out the difference of the time updates) and over the run to TOL_ROWS_M."""
    r = unscented_rtk_runs
    rb, uk, ek = r["rbukf", True], r["ukf", True], rtk_runs[0][True]
    for k in ("lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "pitch_deg", "yaw_deg", "sigma_pos_n_m"):
        np.testing.assert_array_equal(getattr(rb, k), getattr(uk, k), err_msg=k)
    np.testing.assert_array_equal(rb.rtk.r_smoothed_e, uk.rtk.r_smoothed_e)
    np.testing.assert_array_equal(rb.fix_status, uk.fix_status)
    both = (rb.fix_status == 1) & (ek.fix_status == 1)
    assert both.mean() > 0.9
    d = np.linalg.norm(rb.rtk.r_smoothed_e[both] - ek.rtk.r_smoothed_e[both], axis=1)
    assert np.nanmax(d) < TOL_FIX_M, (np.sqrt(np.nanmean(d ** 2)), np.nanmax(d))
    r_rb, r_ek = (np.asarray(earth.geodetic_to_ecef(np.radians(s.lat_deg), np.radians(s.lon_deg), s.h_m),
                             float).reshape(-1, 3) for s in (rb, ek))
    dr = np.linalg.norm(r_rb - r_ek, axis=1)
    assert dr.max() < TOL_ROWS_M, dr.max()
    assert dr.max() > 0.0  # a different time update, not the EKF under another name
    tt = rb.t + drive.gps_time_offset_s
    m = (tt >= rtk_data[2]) & (tt < rtk_data[2] + 30.0)
    f_rb, f_ek = (r["rbukf", False], rtk_runs[0][False])
    df = np.linalg.norm(np.asarray(earth.geodetic_to_ecef(np.radians(f_rb.lat_deg[m]), np.radians(f_rb.lon_deg[m]),
                                                          f_rb.h_m[m]), float).reshape(-1, 3)
                        - np.asarray(earth.geodetic_to_ecef(np.radians(f_ek.lat_deg[m]), np.radians(f_ek.lon_deg[m]),
                                                            f_ek.h_m[m]), float).reshape(-1, 3), axis=1)
    assert dr[m].max() < TOL_OUTAGE_M < 0.1 * df.max(), (dr[m].max(), df.max())
    assert rb.summary["smoother"]["gain_failures"] == 0


def test_rtk_ins_smoothed_error_in_an_outage_below_the_forward(drive, rtk_runs):  # noqa: F811
    runs, t_a = rtk_runs
    err = {}
    for sm, sol in runs.items():
        tt = sol.t + drive.gps_time_offset_s
        m = (tt >= t_a) & (tt < t_a + 30.0)
        r = np.asarray(earth.geodetic_to_ecef(np.radians(sol.lat_deg[m]), np.radians(sol.lon_deg[m]), sol.h_m[m]),
                       float).reshape(-1, 3)
        e = np.linalg.norm(r - _truth_e(drive, tt[m]), axis=1)
        err[sm] = np.nanmax(e)
    assert err[False] > 0.3  # the outage matters
    assert err[True] < 0.25 * err[False], err


def _smoothed_position_error(out, smooth):
    from types import SimpleNamespace

    from insnav.filters.smoothing import smoothed_rows

    llh = out["llh"]
    if smooth:
        rpy, sg = out["rpy"] * RAD2DEG, out["sigma"]
        s = SimpleNamespace(t=out["t"], lat_deg=llh[:, 0] * RAD2DEG, lon_deg=llh[:, 1] * RAD2DEG, h_m=llh[:, 2].copy(),
                            v_n=out["v_n"].copy(), roll_deg=rpy[:, 0].copy(), pitch_deg=rpy[:, 1].copy(),
                            yaw_deg=rpy[:, 2].copy(), sigma_pos_n_m=sg[:, 0:3], sigma_vel_n_mps=sg[:, 3:6],
                            sigma_att_deg=sg[:, 6:9], summary={})
        smoothed_rows(s, out)
        assert s.summary["smoother"]["gain_failures"] == 0
        llh = np.c_[np.radians(s.lat_deg), np.radians(s.lon_deg), s.h_m]
    r = earth.geodetic_to_ecef(llh[:, 0], llh[:, 1], llh[:, 2])
    return np.linalg.norm(r - earth.geodetic_to_ecef(LAT, LON, H0), axis=1)


def test_tdcp_ins_smoother_error_bound(exact_case):  # noqa: F811
    c = dict(exact_case)
    rng = np.random.default_rng(5)
    phase = c["phase"].copy()
    phase[:, 0] += rng.normal(0.0, 0.003, len(phase))
    sats = c["sats"].copy()
    ep = np.repeat(np.arange(c["ep_t"].size), c["n_sat"])
    rho = np.linalg.norm(sats[:, 2:5] - c["r_ant"][ep], axis=1)
    sats[:, 0] = rho + 250.0 + 0.8 * c["ep_t"][ep] - sats[:, 8] + rng.normal(0.0, 0.5, len(sats))  # clock b0, d0
    c["sats"] = sats
    e = {(sm, td): _smoothed_position_error(_run(c, phase, tdcp=td, smooth=sm), sm)
         for sm in (False, True) for td in (False, True)}
    rms = {k: float(np.sqrt(np.mean(v ** 2))) for k, v in e.items()}
    assert rms[(True, True)] < 0.5 * rms[(False, True)], rms
    assert e[(True, True)].max() < 0.2, e[(True, True)].max()
    assert rms[(True, True)] < rms[(True, False)], rms
