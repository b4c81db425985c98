"""Error figures at the edges of their definitions (insnav.analysis.metrics and
evaluate): longitude across +-180 deg and written 0-360, the end of the data in a
reconvergence hold, fix status between solution epochs, and a NaN row."""
from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from insnav.analysis.evaluate import _solution_at, evaluate, static_truth
from insnav.analysis.metrics import errors, reconvergence_time
from insnav.earth import radii


def _track(t, lat, lon, yaw=None):
    n = t.size
    return NS(t=t, lat_deg=np.full(n, lat) if np.ndim(lat) == 0 else lat, lon_deg=lon, h_m=np.full(n, 100.0),
              v_n=np.zeros((n, 3)), roll_deg=np.zeros(n), pitch_deg=np.zeros(n),
              yaw_deg=np.zeros(n) if yaw is None else yaw)


def test_longitude_across_the_antimeridian_is_interpolated_and_differenced_wrapped():
    tt = np.arange(11.0)
    lon_t = (179.9995 + 1e-4 * tt + 180.0) % 360.0 - 180.0  # crosses +180 -> -180 between t = 5 and 6
    sol_t = tt[:-1] + 0.5
    lon_s = (179.9995 + 1e-4 * sol_t + 180.0) % 360.0 - 180.0  # exactly on the truth's line
    e = errors(_track(sol_t, 45.0, lon_s), _track(tt, 45.0, lon_t))
    assert np.abs(e["pos_n_m"]).max() < 1e-6  # was 14,000 km at the crossing


def test_a_static_truth_written_0_to_360_deg_is_the_same_place():
    t = np.arange(10.0)
    R_M, _ = radii(np.radians(35.0))
    sol = _track(t, 35.0 + np.degrees(0.5 / (R_M + 100.0)), np.full(10, -117.5))  # 0.5 m north of the truth
    for text in ("35,242.5,100", "35,-117.5,100"):
        r = evaluate(sol, static_truth(text, t))
        assert r["horizontal_rms_m"] == pytest.approx(0.5, abs=1e-6)


def test_reconvergence_needs_the_hold_inside_the_data():
    t = np.arange(20.0)
    err = np.full(20, 10.0)
    err[-1] = 0.0  # within the band at the last sample only: not shown to hold 5 s
    assert np.isnan(reconvergence_time(t, err, 0.0, 1.0, hold_s=5.0))
    err[-6:] = 0.0  # t = 14..19: 5 s inside the data
    assert reconvergence_time(t, err, 0.0, 1.0, hold_s=5.0) == 14.0
    err = np.full(20, 10.0)
    err[5:10] = 0.0  # t = 5..9, out again at 10: held [5, 10)
    assert reconvergence_time(t, err, 0.0, 1.0, hold_s=5.0) == 5.0


def test_an_interpolated_time_between_a_float_and_a_fixed_epoch_is_float():
    st = np.arange(4.0)
    sol = _track(st, 45.0, np.full(4, 7.0))
    for k in ("sigma_pos_n_m", "sigma_vel_n_mps", "sigma_att_deg"):
        setattr(sol, k, np.ones((4, 3)))
    sol.fix_status = np.array([1, 2, 1, 1])
    out = _solution_at(sol, np.arange(0.0, 3.01, 0.25))
    #            t: 0  .25 .5 .75 1  1.25 ... 2  2.25 ... 3
    assert out.fix_status.tolist() == [1, 2, 2, 2, 2, 2, 2, 2, 1, 1, 1, 1, 1]


def test_a_nan_row_is_left_out_of_every_position_figure():
    t = np.arange(10.0)
    R_M, _ = radii(np.radians(45.0))
    lat = np.full(10, 45.0 + np.degrees(0.3 / (R_M + 100.0)))
    lat[4] = np.nan
    r = evaluate(_track(t, lat, np.full(10, 7.0)), _track(t, 45.0, np.full(10, 7.0)), outages=[(2.0, 3.0)])
    assert r["horizontal_rms_m"] == pytest.approx(0.3, abs=1e-6)
    assert r["horizontal_max_m"] == pytest.approx(0.3, abs=1e-6)
    assert r["rms_3d_m"] == pytest.approx(0.3, abs=1e-6)
    assert r["outages"][0]["max_horizontal_inside_m"] == pytest.approx(0.3, abs=1e-6)


def test_a_nan_row_does_not_take_the_later_longitudes_with_it():
    st = np.arange(11.0)
    lon = 10.0 + 1e-4 * st
    lat = np.full(11, 45.0)
    lat[3] = lon[3] = np.nan
    sol = _track(st, lat, lon)
    for k in ("sigma_pos_n_m", "sigma_vel_n_mps", "sigma_att_deg"):
        setattr(sol, k, np.ones((11, 3)))
    out = _solution_at(sol, st)
    fin = np.isfinite(out.lon_deg)
    assert fin.sum() == 10 and not fin[3]  # np.unwrap alone carried the NaN to every later row
    np.testing.assert_allclose(out.lon_deg[fin], lon[np.isfinite(lon)], rtol=0, atol=1e-12)


def test_report_fmt_takes_numpy_non_finite_values():
    from insnav.analysis.report import _fmt

    assert _fmt(np.float32("nan")) == _fmt(np.float32(np.inf)) == _fmt(None) == "n/a"
    assert _fmt(np.float32(0.25)) == "0.250"
