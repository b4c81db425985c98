"""The RTS smoother over tight RTK/INS and TDCP/INS (filter/rts_smoother.hpp, engine/rtk_ins_engine.hpp 4.,
ClosedLoop::condition_for_smoother / clone_update_for_smoother).

* RTK/INS (the Spirent drive with a synthesised IMU, one 30 s outage): the smoothed antenna at the
  fixed epochs agrees with the forward fixed antenna (RMS <= 5 mm, every epoch within 1 cm) and is at
  least as close to the truth; the fix status and ratio are the forward pass's; the smoothed error
  in the outage is a fraction of the forward one.
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


@pytest.fixture(scope="module")
def rtk_runs(drive):  # noqa: F811
    from insnav.filters.rtk_ins import run_rtk_ins
    from insnav.gnss import rtk

    v = "iono-Klob_tropo-Saast"
    rover = rtk.read_phase_obs(need(SP / v / "Rover-dynamic_MO_Spirent.obs"), "GE")
    base = rtk.read_phase_obs(SP / v / "Base-static_MO_Spirent.obs", "GE")
    t_a = rover.epoch_t_gps_s[0] + 100.0
    rov2, _ = _remove(rover, t_a, t_a + 30.0)
    runs = {sm: run_rtk_ins(drive, RunConfig(filter="ekf", smooth=sm), rover=rov2, base=base, nav=NAV,
                            rtk_options=dict(systems="GE", frequencies=2)) for sm in (False, True)}
    return runs, t_a


def test_rtk_ins_smoothed_fixed_epochs_keep_the_fixed_solution(drive, rtk_runs):  # noqa: F811
    (runs, _) = rtk_runs
    f, s = runs[False], runs[True]
    np.testing.assert_array_equal(s.fix_status, f.fix_status)  # the status column is the forward pass's
    np.testing.assert_array_equal(s.ratio, f.ratio)
    fx = f.rtk.status == 1
    assert fx.mean() > 0.95
    np.testing.assert_allclose(s.rtk.r_e[fx], f.rtk.r_e[fx], atol=1e-6)  # the forward fixed solution itself
    d = np.linalg.norm(s.rtk.r_smoothed_e[fx] - f.rtk.r_e[fx], axis=1)
    assert np.sqrt(np.mean(d ** 2)) < 0.005 and d.max() < 0.01, (np.sqrt(np.mean(d ** 2)), d.max())
    tru = _truth_e(drive, f.rtk.t_gps_s)[fx]
    e_f = np.linalg.norm(f.rtk.r_e[fx] - tru, axis=1)
    e_s = np.linalg.norm(s.rtk.r_smoothed_e[fx] - tru, axis=1)
    ok = np.isfinite(e_f) & np.isfinite(e_s)
    assert np.sqrt(np.mean(e_s[ok] ** 2)) <= np.sqrt(np.mean(e_f[ok] ** 2))
    assert s.summary["smoother"]["gain_failures"] == 0


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
