"""Unit and sanity checks (insnav.filters.checks): every wrong-unit case a user hits
gives a one-line DataCheckError naming the column and the likely cause; the
clean simulated data pass."""
import copy

import numpy as np
import pytest

import insnav
from insnav.filters.checks import DataCheckError, check_gnss, check_gyro_against_gnss, check_imu, check_time_overlap


@pytest.fixture(scope="module")
def ds():
    return insnav.simulate("seed000-car", seed=2)


def _gnss(ds, **changes):
    g = copy.copy(ds.gnss)
    for k, v in changes.items():
        setattr(g, k, v)
    return g


def test_clean_data_pass(ds):
    check_imu(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b)
    check_gnss(ds.gnss, initial=ds.initial)
    check_time_overlap(ds.imu.t, ds.gnss.t_valid)
    assert check_gyro_against_gnss(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b, ds.gnss) == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize("what, scale_th, scale_dv, t_scale, match", [
    ("dv in g", 1.0, 1 / 9.80665, 1.0, "look like g"),
    ("time in ms", 1.0, 1.0, 1000.0, "milliseconds"),
])
def test_imu_unit_mistakes(ds, what, scale_th, scale_dv, t_scale, match):
    t = ds.imu.t * t_scale
    with pytest.raises(DataCheckError, match=match) as e:
        check_imu(t, ds.imu.dtheta_b * scale_th, ds.imu.dv_b * scale_dv, source="imu.csv")
    msg = str(e.value)
    assert msg.startswith("imu.csv: ") and "\n" not in msg


def test_gyro_degrees_and_axes_against_the_gnss_course(ds):
    """A car's median rate is far too small to show degrees; its turns are not."""
    with pytest.raises(DataCheckError, match="look like degrees"):
        check_gyro_against_gnss(ds.imu.t, np.degrees(ds.imu.dtheta_b), ds.imu.dv_b, ds.gnss, source="imu.csv")
    flu = np.array([1.0, -1.0, -1.0])  # FRD -> FLU: y and z flipped
    with pytest.raises(DataCheckError, match="FLU/RFU axes are read as FRD"):
        check_imu(ds.imu.t, ds.imu.dtheta_b * flu, ds.imu.dv_b * flu)
    with pytest.raises(DataCheckError, match="gyro axes look inverted"):  # gyro axes only
        check_gyro_against_gnss(ds.imu.t, ds.imu.dtheta_b * flu, ds.imu.dv_b, ds.gnss)
    # the first 89 s: standstill, then straight at 12 m/s: no turn to compare
    k, j = np.searchsorted(ds.imu.t, 89.0), np.searchsorted(ds.gnss.t_valid, 89.0)
    straight = copy.copy(ds.gnss)
    for f in ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n"):
        setattr(straight, f, getattr(ds.gnss, f)[:j])
    assert check_gyro_against_gnss(ds.imu.t[:k], ds.imu.dtheta_b[:k], ds.imu.dv_b[:k], straight) is None


def test_dtheta_as_rate(ds):
    dt = np.median(np.diff(ds.imu.t))
    # rates (rad/s) written where increments belong look 200x too large; a car turning
    # at 10 deg/s median would then be 2000 deg/s: make the run turn enough to see it
    th = ds.imu.dtheta_b / dt * 50
    with pytest.raises(DataCheckError, match="dtheta"):
        check_imu(ds.imu.t, th, ds.imu.dv_b)


@pytest.mark.parametrize("what, change, match", [
    ("radians", lambda g: dict(lat_deg=np.radians(g.lat_deg), lon_deg=np.radians(g.lon_deg)), "radians"),
    ("west as east", lambda g: dict(lon_deg=-g.lon_deg), "longitude sign"),
    ("south as north", lambda g: dict(lat_deg=-g.lat_deg), "latitude sign"),
    ("out of range", lambda g: dict(lat_deg=np.where(np.arange(len(g)) == 5, 123.0, g.lat_deg)), "out of range"),
    ("zero sigma", lambda g: dict(sigma_pos_n=np.zeros_like(g.sigma_pos_n)), "must be > 0"),
])
def test_gnss_mistakes(ds, what, change, match):
    with pytest.raises(DataCheckError, match=match):
        check_gnss(_gnss(ds, **change(ds.gnss)), initial=ds.initial, source="gnss.csv")


def test_gnss_jump_names_the_record(ds):
    lon = ds.gnss.lon_deg.copy()
    lon[300:] = -lon[300:]  # sign flipped half-way through the file
    with pytest.raises(DataCheckError, match=r"record 300: a jump of \d+\.\d+ km"):
        check_gnss(_gnss(ds, lon_deg=lon), initial=ds.initial, source="gnss.csv")


@pytest.mark.parametrize("offset, hint", [(86400.0, "1 x a day"), (2 * 604800.0, "2 x a GPS week"),
                                         (1.7e9, "")])
def test_time_bases(ds, offset, hint):
    with pytest.raises(DataCheckError, match="different time bases") as e:
        check_time_overlap(ds.imu.t, ds.gnss.t_valid + offset, imu_source="imu.csv", gnss_source="gnss.csv")
    assert hint in str(e.value)
