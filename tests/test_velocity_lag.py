"""[gnss] velocity_lag_s: a velocity column that lags its own positions, re-timed on reading
(insnav.io.gnss_files.shift_velocity) and measured from the positions (estimate_velocity_lag)."""
import numpy as np
import pytest

from insnav import earth
from insnav.config import ConfigError
from insnav.io.gnss_files import (GnssFileFormat, estimate_velocity_lag, read_gnss, shift_velocity,
                                  velocity_lag_warning, write_pos)

LAT0, LON0, H0 = np.radians(40.0), np.radians(-105.0), 1600.0
T0 = 1_400_000_000.0  # GPS seconds
DT = 0.25             # 4 Hz, like the walk's RTK .pos
R_CIRCLE, V0, A_MOD, W_MOD = 20.0, 1.4, 0.5, 2 * np.pi / 8.0  # walk on a circle, speed 1.4 +- 0.5 m/s


def walk(t):
    """A walk on a circle (north = R cos th, east = R sin th) with a varying speed: the positions and the
    true NED velocity at times t [s] from the start."""
    th = (V0 * t - A_MOD / W_MOD * (np.cos(W_MOD * t) - 1.0)) / R_CIRCLE
    speed = V0 + A_MOD * np.sin(W_MOD * t)
    north, east = R_CIRCLE * np.cos(th), R_CIRCLE * np.sin(th)
    v = np.column_stack([-speed * np.sin(th), speed * np.cos(th), np.zeros_like(t)])
    R_M, R_N = earth.radii(LAT0)
    lat = np.degrees(LAT0 + north / (R_M + H0))
    lon = np.degrees(LON0 + east / ((R_N + H0) * np.cos(LAT0)))
    return lat, lon, np.full_like(t, H0), v


def lagged_pos(tmp_path, lag_s, n=800):
    """A .pos whose velocity column tagged t holds the velocity at t - lag_s."""
    t = np.arange(n) * DT
    lat, lon, h, _ = walk(t)
    _, _, _, v_late = walk(t - lag_s)
    p = write_pos(tmp_path / "lag.pos", T0 + t, lat, lon, h, np.full((n, 3), 0.01), v_late, np.full((n, 3), 0.05))
    return p, t


def test_lag_measured_and_removed(tmp_path):
    lag = 0.15
    p, t = lagged_pos(tmp_path, lag)
    _, _, _, v_true = walk(t)
    as_tagged = read_gnss(p, GnssFileFormat(format="pos"))
    est = estimate_velocity_lag(as_tagged.t_s, as_tagged.lat_deg, as_tagged.lon_deg, as_tagged.h_m, as_tagged.v_n)
    assert est["lag_s"] == pytest.approx(lag, abs=0.003)
    assert est["rms_as_tagged_mps"] > 10 * est["rms_at_lag_mps"]
    assert as_tagged.info["velocity_lag_check"]["lag_s"] == pytest.approx(lag, abs=0.003)
    msg = velocity_lag_warning(as_tagged)
    assert msg is not None and "lags its own positions by 150 ms" in msg and "velocity_lag_s = 0.15" in msg

    fixed = read_gnss(p, GnssFileFormat(format="pos", velocity_lag_s=lag))
    ok = np.all(np.isfinite(fixed.v_n), axis=1)
    # the last records cannot be interpolated (t + lag after the last record): velocity dropped, position kept
    assert np.count_nonzero(~ok) == int(np.ceil(lag / DT)) and not ok[-1] and ok[:-1].all()
    assert len(fixed) == len(t) and np.all(np.isfinite(fixed.lat_deg))
    err = np.abs(fixed.v_n[ok] - v_true[ok]).max()
    err_tagged = np.abs(as_tagged.v_n - v_true).max()
    # linear interpolation between 4 Hz records: dt^2 |v''| / 8 = 2.5 mm/s at most here (+ 5-decimal rounding)
    assert err < 3e-3 and err_tagged > 20 * err
    assert np.all(fixed.sigma_vel_n[ok] == 0.05) and np.all(np.isnan(fixed.sigma_vel_n[~ok]))
    assert abs(fixed.info["velocity_lag_check"]["lag_s"]) < 0.003
    assert velocity_lag_warning(fixed) is None


def test_decimate_after_retiming(tmp_path):
    """The column is re-timed on every record, then decimated: the kept fixes' velocities are those of
    the full-rate re-timing."""
    p, t = lagged_pos(tmp_path, 0.1)
    full = read_gnss(p, GnssFileFormat(format="pos", velocity_lag_s=0.1))
    dec = read_gnss(p, GnssFileFormat(format="pos", velocity_lag_s=0.1, decimate=4))
    np.testing.assert_array_equal(dec.v_n, full.v_n[::4])
    np.testing.assert_array_equal(dec.t_s, full.t_s[::4])


def test_shift_round_trip_and_gaps():
    t = np.concatenate([np.arange(0.0, 10.0, 0.5), np.arange(20.0, 30.0, 0.5)])  # a 10.5 s gap
    v = np.column_stack([2.0 * t - 3.0, -0.5 * t, np.ones_like(t)])  # linear: interpolation is exact
    s = np.full_like(v, 0.1)
    s[5] = 0.3
    v1, s1 = shift_velocity(t, v, s, 0.2)
    np.testing.assert_allclose(v1[:, 0][np.isfinite(v1[:, 0])], (2.0 * (t + 0.2) - 3.0)[np.isfinite(v1[:, 0])],
                               atol=1e-12)
    # no interpolation across the gap nor past the end; the larger sigma of the bracketing pair
    assert np.isnan(v1[19]).all() and np.isnan(v1[-1]).all() and np.isfinite(v1[:19]).all()
    assert s1[4, 0] == 0.3 and s1[5, 0] == 0.3 and s1[6, 0] == 0.1
    v2, _ = shift_velocity(t, v1, s1, -0.2)  # back again: the original where both steps interpolated
    m = np.all(np.isfinite(v2), axis=1)
    assert m.sum() == len(t) - 4
    np.testing.assert_allclose(v2[m], v[m], atol=1e-12)
    # a lag that is a whole number of records moves the column by records
    v3, _ = shift_velocity(t, v, s, 1.0)
    np.testing.assert_array_equal(v3[:18], v[2:20])


@pytest.mark.parametrize("bad", ["0.13", float("nan"), 2.5, -10.0, True])
def test_bad_lag_is_named(bad):
    with pytest.raises(ConfigError, match=r"gnss\.velocity_lag_s: bad value .*within \+-2"):
        GnssFileFormat(velocity_lag_s=bad).validate()
