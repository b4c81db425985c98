"""Smaller input defects: the run summary's GNSS count, an implausible lever arm, the axes hint."""
from __future__ import annotations

import re

import numpy as np
import pytest

import insnav
from insnav.io import kfgins


@pytest.fixture(scope="module")
def sim():
    return insnav.simulate("seed000-sim", seed=1)


def _kfgins_set(ds, d, n_imu: int, n_gnss: int, starttime=None, antlever="[0.0, 0.0, 0.0]"):
    i = ds.initial
    imu = type(ds.imu)(ds.imu.t[:n_imu], ds.imu.dtheta_b[:n_imu], ds.imu.dv_b[:n_imu])
    kfgins.write_kfgins_imu(d / "imu.txt", imu)
    kfgins.write_kfgins_gnss(d / "gnss.txt", type(ds.gnss).from_array(ds.gnss.to_array()[:n_gnss]))
    (d / "kf-gins.yaml").write_text(
        f"imupath: imu.txt\ngnsspath: gnss.txt\noutputpath: out\nimudatalen: 7\nimudatarate: 200\n"
        f"starttime: {ds.t0 if starttime is None else starttime}\nendtime: -1\n"
        f"initpos: [{i.lat_deg}, {i.lon_deg}, {i.h_m}]\ninitvel: [{i.v_n[0]}, {i.v_n[1]}, {i.v_n[2]}]\n"
        f"initatt: [{i.roll_deg}, {i.pitch_deg}, {i.yaw_deg}]\n"
        "imunoise:\n  arw: [0.2, 0.2, 0.2]\n  vrw: [0.4, 0.4, 0.4]\n  corrtime: 1.0\n"
        f"antlever: {antlever}\n")
    return d / "kf-gins.yaml"


def test_summary_counts_gnss_records_outside_the_imu_span(sim, tmp_path, capsys):
    """20 s of IMU, 40 fixes: the 20 after the IMU ends are counted as records, outside the span."""
    from insnav.cli import main

    dt = float(np.median(np.diff(sim.imu.t)))
    n_imu = int(round(20.0 / dt))
    gt = sim.gnss.t_valid
    n_gnss = int(np.searchsorted(gt, sim.imu.t[n_imu - 1] + 20.0))
    inside = int(np.count_nonzero((gt[:n_gnss] > sim.t0) & (gt[:n_gnss] <= sim.imu.t[n_imu - 1])))
    y = _kfgins_set(sim, tmp_path, n_imu, n_gnss)
    rc = main(["run", "--format", "kfgins", "--config", str(y), "--out", str(tmp_path / "s.csv"), "-q"])
    out = capsys.readouterr().out
    assert rc == 0
    m = re.search(r"GNSS: (\d+) records \((\d+) outside the run's IMU time span, not used\), (\d+) updates used", out)
    assert m, out
    assert int(m.group(1)) == n_gnss and int(m.group(2)) == n_gnss - inside and int(m.group(3)) == inside


@pytest.mark.parametrize("where", ["kfgins", "config", "dataset"])
def test_lever_arm_in_millimetres_is_named(sim, tmp_path, where):
    """A lever arm typed in mm: a one-line error naming the key, not a FloatingPointError blaming the IMU."""
    import dataclasses

    from insnav.config import ConfigError
    from insnav.data.checks import DataCheckError
    from insnav.io.kfgins_dataset import load_kfgins

    if where == "kfgins":
        y = _kfgins_set(sim, tmp_path, 600, 3, antlever="[136, -301, -184]")
        with pytest.raises(ValueError, match=r"kf-gins.yaml: key 'antlever': .*378.1 m long.*millimetres"):
            load_kfgins(y)
    elif where == "config":
        with pytest.raises(ConfigError, match=r"'lever_arm_b'.*millimetres"):
            insnav.run(sim, lever_arm_b=[136.0, -301.0, -184.0])
    else:
        ds = dataclasses.replace(sim, lever_arm_b=np.array([13.6, -30.1, 118.4]))
        with pytest.raises(DataCheckError, match=r"lever_arm_b = .*centimetres"):
            insnav.run(ds)


@pytest.fixture(scope="module")
def car_csv(tmp_path_factory):
    from test_csv_dataset import _car, write_gnss

    car = _car(segments=7)  # the standstill, a straight, two turns
    d = tmp_path_factory.mktemp("car")
    return car, write_gnss(d / "gnss.csv", car), d


def test_rfu_read_as_flu_is_named_not_a_90_deg_heading(car_csv):
    """z-up data: the hint names FLU and RFU; RFU data mapped as FLU (x right taken as forward) would
    start 90 deg off from the GNSS course, so the loader refuses it, naming the axes."""
    from test_csv_dataset import config, write_imu

    from insnav.data.checks import DataCheckError

    car, gnss, d = car_csv
    rfu = write_imu(d / "rfu.csv", car, axes="RFU")
    with pytest.raises(DataCheckError, match=r'z up with x forward is FLU, with x right RFU|"FLU" if .*"RFU" if'):
        insnav.load_csv_dataset(rfu, gnss, config())  # read as FRD: the axes hint names both
    with pytest.raises(DataCheckError, match=r"along body -x, not \+y .*x axis points left|along body \+x, not \+y "
                                             r".*x axis points right") as err:
        insnav.load_csv_dataset(rfu, gnss, config(imu=dict(axes="FLU")))
    assert "[imu] axes" in str(err.value) and "\n" not in str(err.value)
    ds, cfg = insnav.load_csv_dataset(rfu, gnss, config(imu=dict(axes="RFU")))  # right: runs
    t_car = ds.t0 + ds.gps_time_offset_s - car.gps_time_offset_s
    yaw_err = (ds.initial.yaw_deg - np.interp(t_car, car.truth.t, car.truth.yaw_deg) + 180.0) % 360.0 - 180.0
    assert abs(yaw_err) < 5.0
