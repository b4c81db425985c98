"""A user's own IMU and GNSS files, loosely coupled (``insnav.load_csv_dataset``,
``insnav run --format csv``): the same simulated drive written in other units
and axes gives the same solution; each wrong unit is a one-line error naming
the problem; RTKLIB .pos and NMEA round trips; the alignment through the
pipeline on a consumer-IMU car; the rtklibexplorer walk (real data) against
its RTK solution.
"""
from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest

import insnav
from insnav.cli import main
from insnav.config import ConfigError
from insnav.data.checks import DataCheckError
from insnav.io.gnss_files import (GnssFileError, GnssFileFormat, nmea_checksum, read_gnss, read_nmea, read_pos,
                                  write_nmea, write_pos)
from insnav.io.imu_csv import _split_time, axes_matrix, gps_minus_utc_s
from insnav.sim.scenario import resolve_raw
from insnav.units import DEG, G0, RAD2DEG

WALK = "rtklibexplorer_walk_0827"


def _car(seed=1, segments=5):
    """car-mems cut to its first segments (20 s standstill, accelerate, 60 s straight,
    a 90 deg turn), with a consumer-grade IMU (500 deg/h, 30 mg turn-on biases)."""
    raw, _ = resolve_raw("car-mems")
    raw["motion"]["segments"] = raw["motion"]["segments"][:segments]
    raw["imu"]["gyro"] = {"bias_sigma_dph": 500.0, "arw_deg_per_sqrth": 1.0}
    raw["imu"]["accel"] = {"bias_sigma_mg": 30.0, "vrw_mps_per_sqrth": 0.5}
    raw.pop("odometer", None)
    return insnav.simulate(raw, seed=seed)


@pytest.fixture(scope="module")
def car():
    return _car()


def _time_text(ds, t):
    """GPS seconds of week as exact decimal text (ns)."""
    sow0 = ds.gps_time_offset_s % 604800.0
    return [f"{sow0 + x:.9f}" for x in t]


def write_imu(path, ds, *, axes="FRD", gyro="rad", acc="mps2", samples="increments", header=True):
    """The dataset's IMU in the given axes and units; ``samples`` increments or
    mean_rates (then a leading row at t0 so that the same increments come back)."""
    A = axes_matrix(axes)  # x_FRD = A x_sensor
    dth = ds.imu.dtheta_b @ A  # sensor = A^T frd, row-wise
    dv = ds.imu.dv_b @ A
    kg = RAD2DEG if gyro == "deg" else 1.0
    ka = 1.0 / G0 if acc == "g" else 1.0
    tt = _time_text(ds, ds.imu.t)
    if samples in ("mean_rates", "rates"):
        tt = _time_text(ds, [ds.t0]) + tt
        _, t = _split_time(tt, 1)
        dt = np.diff(t)[:, None]
        if samples == "mean_rates":
            dth, dv = np.vstack([dth[:1], dth / dt]), np.vstack([dv[:1], dv / dt])
        else:  # instantaneous rates whose trapezoid gives the increments: w_k = 2 inc_k / dt_k - w_(k-1)
            w, f = np.empty((len(tt), 3)), np.empty((len(tt), 3))
            w[0], f[0] = dth[0] / dt[0], dv[0] / dt[0]
            for k in range(1, len(tt)):
                w[k] = 2.0 * dth[k - 1] / dt[k - 1] - w[k - 1]
                f[k] = 2.0 * dv[k - 1] / dt[k - 1] - f[k - 1]
            dth, dv = w, f
    lines = ["time,gx,gy,gz,ax,ay,az"] if header else []
    g, a = (dth * kg).tolist(), (dv * ka).tolist()
    lines += [f"{tt[k]},{g[k][0]!r},{g[k][1]!r},{g[k][2]!r},{a[k][0]!r},{a[k][1]!r},{a[k][2]!r}" for k in range(len(tt))]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_gnss(path, ds, *, angle="deg", height="ellipsoidal", undulation=0.0, flip_lon=False):
    g = ds.gnss
    lat, lon = g.lat_deg.copy(), g.lon_deg.copy() * (-1 if flip_lon else 1)
    if angle == "rad":
        lat, lon = lat * DEG, lon * DEG
    h = g.h_m - (undulation if height == "msl" else 0.0)
    tt = _time_text(ds, g.t_valid)
    cols = np.column_stack([lat, lon, h, g.v_n[:, 0], g.v_n[:, 1], -g.v_n[:, 2], g.sigma_pos_n, g.sigma_vel_n])
    rows = ["t,lat,lon,h,vn,ve,vu,sn,se,sd,svn,sve,svd"]
    rows += [tt[k] + "," + ",".join(repr(x) for x in r) for k, r in enumerate(cols.tolist())]
    path.write_text("\n".join(rows) + "\n")
    return path


GNSS_COLS = ["t", "lat", "lon", "h", "vn", "ve", "vu", "sigma_n", "sigma_e", "sigma_d", "sigma_vn", "sigma_ve",
             "sigma_vd"]


def config(imu=None, gnss=None, **top):
    d = dict(top)
    d["imu"] = dict(dict(columns=["t", "gx", "gy", "gz", "ax", "ay", "az"], time="gps_sow", samples="increments",
                         grade="consumer"), **(imu or {}))
    d["gnss"] = dict(dict(columns=GNSS_COLS, time="gps_sow", angle_unit="deg"), **(gnss or {}))
    week = 2155
    d["imu"].setdefault("gps_week", week)
    d["gnss"].setdefault("gps_week", week)
    return d


@pytest.fixture(scope="module")
def frd_files(car, tmp_path_factory):
    d = tmp_path_factory.mktemp("frd")
    return write_imu(d / "imu.csv", car), write_gnss(d / "gnss.csv", car)


# --------------------------------------------------------------------------- same data, other units


def _sol_diff(a, b):
    """Largest difference of two solutions: position [m], velocity [m/s], attitude [deg]."""
    assert len(a.t) == len(b.t) and np.array_equal(a.t, b.t)
    dn = np.abs(a.lat_deg - b.lat_deg) * DEG * 6.4e6
    de = np.abs(a.lon_deg - b.lon_deg) * DEG * 6.4e6
    return max(dn.max(), de.max(), np.abs(a.h_m - b.h_m).max(), np.abs(a.v_n - b.v_n).max(),
               np.abs(a.roll_deg - b.roll_deg).max(), np.abs(a.pitch_deg - b.pitch_deg).max(),
               np.abs(a.yaw_deg - b.yaw_deg).max())


@pytest.mark.parametrize("axes,gyro,acc", [("FLU", "deg", "g"), ("RFU", "deg", "mps2"), ("FRD", "rad", "g"),
                                           ("LBU", "deg", "g")])
def test_other_axes_units_and_rates_give_the_same_solution(car, frd_files, tmp_path, axes, gyro, acc):
    """Property: the drive written in another axis order, in deg/g and as mean
    rates, with the mapping saying so, gives the FRD/rad/m/s^2/increments
    solution to 1e-9 (m, m/s, deg)."""
    imu_frd, gnss = frd_files
    ds0, cfg0 = insnav.load_csv_dataset(imu_frd, gnss, config())
    sol0 = insnav.run(ds0, config=cfg0)
    imu_b = write_imu(tmp_path / "imu_b.csv", car, axes=axes, gyro=gyro, acc=acc, samples="mean_rates")
    ds1, cfg1 = insnav.load_csv_dataset(imu_b, gnss, config(imu=dict(axes=axes, gyro_unit=gyro, acc_unit=acc,
                                                                      samples="mean_rates")))
    assert ds1.t0 == ds0.t0 and ds1.alignment.index == ds0.alignment.index
    sol1 = insnav.run(ds1, config=cfg1)
    assert _sol_diff(sol0, sol1) < 1e-9
    assert sol0.summary["updates"] > 0.9 * len(ds0.gnss)


def test_instantaneous_rates_give_the_same_solution(tmp_path):
    """Rates at the sample times (trapezoid to increments) written so that the
    trapezoid returns the simulator's increments (an error-free IMU keeps them
    smooth): FLU, deg/s, g, the same solution as the increments to 1e-9."""
    raw, _ = resolve_raw("car-mems")
    raw["motion"]["segments"] = raw["motion"]["segments"][:5]
    raw["imu"]["gyro"], raw["imu"]["accel"] = {}, {}
    raw.pop("odometer", None)
    ds = insnav.simulate(raw, seed=4)
    g = write_gnss(tmp_path / "g.csv", ds)
    ds0, cfg0 = insnav.load_csv_dataset(write_imu(tmp_path / "i0.csv", ds), g, config())
    i1 = write_imu(tmp_path / "i1.csv", ds, axes="FLU", gyro="deg", acc="g", samples="rates")
    ds1, cfg1 = insnav.load_csv_dataset(i1, g, config(imu=dict(axes="FLU", gyro_unit="deg", acc_unit="g",
                                                                samples="rates")))
    assert np.abs(ds1.imu.dv_b - ds0.imu.dv_b).max() < 1e-12
    assert _sol_diff(insnav.run(ds0, config=cfg0), insnav.run(ds1, config=cfg1)) < 1e-9


def test_relative_time_bases(car, tmp_path):
    """Both files on the user's own clock: the dataset keeps it; one relative and
    one GPS-time file is a one-line error."""
    sow0 = car.gps_time_offset_s % 604800.0
    imu = write_imu(tmp_path / "i.csv", car)
    g = write_gnss(tmp_path / "g.csv", car)
    rel = dict(time="relative", time_offset_s=-sow0 + 1000.0)
    ds, _ = insnav.load_csv_dataset(imu, g, config(imu=rel, gnss=rel))
    assert ds.gps_time_offset_s == 0.0 and abs(ds.imu.t[-1] - (car.imu.t[-1] + 1000.0)) < 1e-6
    with pytest.raises(ConfigError, match=r"\[imu\] time = 'relative'.*GPS time: both need the same clock"):
        insnav.load_csv_dataset(imu, g, config(imu=rel))


def test_nmea_without_gst_needs_sigmas(car, frd_files, tmp_path):
    imu, _ = frd_files
    g = car.gnss
    nm = write_nmea(tmp_path / "f.nmea", g.t_valid + car.gps_time_offset_s, g.lat_deg, g.lon_deg, g.h_m, None, g.v_n)
    c = config()
    c["gnss"] = {}
    with pytest.raises(GnssFileError, match=r"f\.nmea, line 1: no position sigma.*GST.*sigma_pos_m"):
        insnav.load_csv_dataset(imu, nm, c)
    c["gnss"] = dict(sigma_pos_m=[5.0, 5.0, 10.0])
    ds, _ = insnav.load_csv_dataset(imu, nm, c)
    assert np.all(ds.gnss.sigma_pos_n == [5.0, 5.0, 10.0])


def test_gnss_in_radians_msl_and_header_names_same_solution(car, frd_files, tmp_path):
    """lat/lon in radians, MSL height with the geoid undulation, columns mapped by
    header name: the same solution (to the radian->degree round-off: 1e-6 m)."""
    imu_frd, gnss = frd_files
    ds0, cfg0 = insnav.load_csv_dataset(imu_frd, gnss, config())
    g2 = write_gnss(tmp_path / "g2.csv", car, angle="rad", height="msl", undulation=-27.5)
    names = dict(zip(["t", "lat", "lon", "h", "vn", "ve", "vu", "sigma_n", "sigma_e", "sigma_d", "sigma_vn",
                      "sigma_ve", "sigma_vd"], "t,lat,lon,h,vn,ve,vu,sn,se,sd,svn,sve,svd".split(",")))
    ds1, cfg1 = insnav.load_csv_dataset(imu_frd, g2, config(gnss=dict(columns=names, angle_unit="rad", height="msl",
                                                                       geoid_undulation_m=-27.5)))
    np.testing.assert_allclose(ds1.gnss.lat_deg, ds0.gnss.lat_deg, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ds1.gnss.h_m, ds0.gnss.h_m, rtol=0, atol=1e-9)
    assert _sol_diff(insnav.run(ds0, config=cfg0), insnav.run(ds1, config=cfg1)) < 1e-6


# --------------------------------------------------------------------------- wrong units: one-line errors


WRONG = [
    # (what the file has, what the mapping says, expected message)
    ("acc in g", dict(acc="g"), {}, r"median \|f\| = 1\.0\d+ m/s\^2.*look like g.*acc_unit = \"g\""),
    ("gyro in deg", dict(gyro="deg"), {}, r"gyros turn 5\d\.\dx the GNSS course.*degrees.*gyro_unit = \"deg\""),
    ("FLU axes", dict(axes="FLU"), {}, r"points along \+z.*FLU/RFU axes are read as FRD.*\[imu\] axes"),
    ("rates as increments", dict(samples="mean_rates"), dict(samples="increments"),
     r"looks like a specific force in m/s\^2, not an increment.*samples = \"rates\""),
    ("increments as rates", {}, dict(samples="mean_rates"), r"look like increments over the sample interval, not "
                                                             r"rates.*samples = \"increments\""),
]


@pytest.mark.parametrize("what,written,mapping,match", WRONG, ids=[w[0] for w in WRONG])
def test_wrong_imu_units_are_one_line_errors(car, frd_files, tmp_path, what, written, mapping, match):
    _, gnss = frd_files
    imu = write_imu(tmp_path / "imu.csv", car, **written)
    with pytest.raises(DataCheckError, match=match) as ei:
        insnav.load_csv_dataset(imu, gnss, config(imu=mapping))
    msg = str(ei.value)
    assert "\n" not in msg and str(imu) in msg


@pytest.mark.parametrize("what,gnss_kw,mapping,match", [
    ("lat/lon in radians read as degrees", dict(angle="rad"), dict(angle_unit=None),
     r"lat/lon: every fix lies within.*look like radians.*angle_unit = \"rad\""),
    ("longitude sign flipped", dict(flip_lon=True), {},
     r"the longitude moves opposite to the velocity.*longitude sign looks flipped"),
    ("GNSS time base a week off", {}, dict(gps_week=2156),
     r"no fix inside the IMU time span.*1 x a GPS week"),
])
def test_wrong_gnss_units_are_one_line_errors(car, frd_files, tmp_path, what, gnss_kw, mapping, match):
    imu, _ = frd_files
    g = write_gnss(tmp_path / "g.csv", car, **gnss_kw)
    with pytest.raises(DataCheckError, match=match) as ei:
        insnav.load_csv_dataset(imu, g, config(gnss=mapping))
    assert "\n" not in str(ei.value) and str(g) in str(ei.value)


def test_config_mistakes_are_one_line_errors(frd_files):
    imu, gnss = frd_files
    with pytest.raises(ConfigError, match=r"unknown key 'imu.gyro_units' \(did you mean 'imu.gyro_unit'\?\)"):
        insnav.load_csv_dataset(imu, gnss, config(imu=dict(gyro_units="deg")))
    with pytest.raises(ConfigError, match=r"unknown key 'gnss.angle_units' \(did you mean 'gnss.angle_unit'\?\)"):
        insnav.load_csv_dataset(imu, gnss, config(gnss=dict(angle_units="deg")))
    with pytest.raises(ConfigError, match=r"unknown key 'filtre' \(did you mean 'filter'\?\)"):
        insnav.load_csv_dataset(imu, gnss, config(filtre="ekf"))
    with pytest.raises(ConfigError, match=r"no IMU noise model"):
        c = config()
        del c["imu"]["grade"]
        insnav.load_csv_dataset(imu, gnss, c)
    with pytest.raises(ConfigError, match=r"imu.grade.*'consumr' unknown \(did you mean 'consumer'\?\)"):
        insnav.load_csv_dataset(imu, gnss, config(imu=dict(grade="consumr")))
    with pytest.raises(ConfigError, match=r"imu.axes: bad axes 'FLD'.*left-handed"):
        insnav.load_csv_dataset(imu, gnss, config(imu=dict(axes="FLD")))
    with pytest.raises(ConfigError, match=r"height = 'msl' needs gnss.geoid_undulation_m"):
        insnav.load_csv_dataset(imu, gnss, config(gnss=dict(height="msl")))


def test_explicit_noise_keys_override_the_grade(frd_files):
    imu, gnss = frd_files
    _, cfg = insnav.load_csv_dataset(imu, gnss, config(imu=dict(gyro_arw_deg_per_sqrt_h=0.5)))
    assert cfg.imu.gyro_arw == pytest.approx([0.5 * DEG / 60.0] * 3)
    assert cfg.imu.acc_bias_sigma == pytest.approx([30e-3 * G0] * 3)  # the consumer grade's


# --------------------------------------------------------------------------- alignment through the pipeline


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_consumer_car_alignment_heading_within_2_deg_after_10_s_of_motion(tmp_path, seed):
    """No initial state typed: levelling on the 20 s standstill, heading from
    the GNSS course once moving (a 500 deg/h gyro cannot gyrocompass)."""
    ds = _car(seed)
    imu, gnss = write_imu(tmp_path / "i.csv", ds), write_gnss(tmp_path / "g.csv", ds)
    d, cfg = insnav.load_csv_dataset(imu, gnss, config())
    a = d.alignment
    assert a.heading_source == "gnss_velocity"
    sow0 = ds.gps_time_offset_s % 604800.0  # the loader's time: GPS seconds of week
    t_move = sow0 + ds.t0 + 20.0
    assert t_move < d.t0 <= t_move + 10.0
    k = int(np.argmin(np.abs(ds.truth.t + sow0 - d.t0)))
    err = (d.initial.yaw_deg - ds.truth.yaw_deg[k] + 180.0) % 360.0 - 180.0
    sig = cfg.init_sigma_att_deg
    assert abs(err) < 2.0 and abs(err) < 3 * sig[2], (err, sig)
    assert 15.0 < a.static_s <= 20.0  # levelled on the standstill (the detector scaled to the IMU's noise)
    # roll/pitch: the levelling limit of a 30 mg accelerometer bias (1.7 deg) + the gyro drift carried since
    assert abs(d.initial.roll_deg - ds.truth.roll_deg[k]) < 3 * sig[0]
    assert abs(d.initial.pitch_deg - ds.truth.pitch_deg[k]) < 3 * sig[1]
    sol = insnav.run(d, config=cfg)
    # the filter's heading error stays inside its own 3.5 sigma (it drifts on straights: 500 deg/h gyro)
    yaw_true = np.interp(sol.t, ds.truth.t + sow0, np.unwrap(np.radians(ds.truth.yaw_deg)))
    e_yaw = (sol.yaw_deg - np.degrees(yaw_true) + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(e_yaw) / sol.sigma_att_deg[:, 2]) < 3.5


def test_no_motion_needs_the_yaw(tmp_path):
    """A consumer IMU that never moves cannot find north: a one-line error, unless
    [initial] gives the yaw (then levelling over the first second)."""
    ds = _car(segments=1)  # 20 s standstill only
    imu, g = write_imu(tmp_path / "i.csv", ds), write_gnss(tmp_path / "g.csv", ds)
    with pytest.raises(ValueError, match=r"i\.csv: cannot align the heading.*no GNSS fix reaches 3.0 m/s"):
        insnav.load_csv_dataset(imu, g, config())
    d, cfg = insnav.load_csv_dataset(imu, g, config(initial=dict(yaw_deg=90.0)))
    assert d.initial.yaw_deg == 90.0 and d.alignment.heading_source == "given"
    sig = cfg.init_sigma_att_deg  # the levelling limit of a 30 mg bias: 1.8 deg
    assert 1.7 < sig[0] < 1.9
    assert abs(d.initial.roll_deg - ds.truth.roll_deg[0]) < 3 * sig[0]
    assert abs(d.initial.pitch_deg - ds.truth.pitch_deg[0]) < 3 * sig[1]
    sol = insnav.run(d, config=cfg)
    assert np.hypot(*(sol.v_n[-1, :2])) < 0.5


def test_initial_table_wins(frd_files, car):
    imu, gnss = frd_files
    ds, cfg = insnav.load_csv_dataset(imu, gnss, config(initial=dict(yaw_deg=33.0), init_sigma_att_deg=[1, 1, 7]))
    assert ds.initial.yaw_deg == 33.0 and cfg.init_sigma_att_deg == [1, 1, 7]
    assert "[initial] yaw_deg" in ds.info["initial_state"]
    ini = dict(t_s=ds.t0, lat_deg=34.25, lon_deg=108.95, h_m=400.0, v_n_mps=[0, 0, 0], roll_deg=0.0,
               pitch_deg=0.0, yaw_deg=90.0)
    ds2, _ = insnav.load_csv_dataset(imu, gnss, config(initial=ini))
    assert ds2.alignment is None and ds2.t0 == ds.t0 and ds2.initial.yaw_deg == 90.0


# --------------------------------------------------------------------------- RTKLIB .pos and NMEA


def test_pos_round_trip(car, tmp_path):
    g = car.gnss
    t_gps = g.t_valid + car.gps_time_offset_s
    q = np.where(np.arange(len(g)) % 7 == 0, 2, 1)
    p = write_pos(tmp_path / "f.pos", t_gps, g.lat_deg, g.lon_deg, g.h_m, g.sigma_pos_n, g.v_n, g.sigma_vel_n, q=q)
    r = read_pos(p)
    assert r.format == "pos" and len(r) == len(g)
    np.testing.assert_allclose(r.t_ref_s + r.t_s, t_gps, rtol=0, atol=5e-4)  # 1 ms
    np.testing.assert_allclose(r.lat_deg, g.lat_deg, rtol=0, atol=0.51e-9)
    np.testing.assert_allclose(r.lon_deg, g.lon_deg, rtol=0, atol=0.51e-9)
    np.testing.assert_allclose(r.h_m, g.h_m, rtol=0, atol=0.51e-4)
    np.testing.assert_allclose(r.sigma_pos_n, g.sigma_pos_n, rtol=0, atol=0.51e-4)
    np.testing.assert_allclose(r.v_n, g.v_n, rtol=0, atol=0.51e-5)
    np.testing.assert_allclose(r.sigma_vel_n, g.sigma_vel_n, rtol=0, atol=0.51e-5)
    assert r.info["time_system"] == "GPST"
    fixed = read_gnss(p, GnssFileFormat(quality_max=1))
    assert len(fixed) == int((q == 1).sum())
    lines = p.read_text().splitlines()
    lines[5] = lines[5][:40] + "x" + lines[5][41:]
    (tmp_path / "bad.pos").write_text("\n".join(lines) + "\n")
    with pytest.raises(GnssFileError, match=r"bad\.pos, line 6: bad RTKLIB solution line"):
        read_gnss(tmp_path / "bad.pos")


def test_nmea_round_trip(car, tmp_path):
    g = car.gnss
    t_gps = g.t_valid + car.gps_time_offset_s
    p = write_nmea(tmp_path / "f.nmea", t_gps, g.lat_deg, g.lon_deg, g.h_m, g.sigma_pos_n, g.v_n, undulation_m=-31.2)
    r = read_nmea(p)
    assert len(r) == len(g) and r.info["sentences"]["GGA"] == len(g) and r.info["leap_seconds"] == 18.0
    np.testing.assert_allclose(r.t_ref_s + r.t_s, t_gps, rtol=0, atol=5e-3)  # 0.01 s
    np.testing.assert_allclose(r.lat_deg, g.lat_deg, rtol=0, atol=0.51e-7 / 60)  # 1e-7 minute
    np.testing.assert_allclose(r.lon_deg, g.lon_deg, rtol=0, atol=0.51e-7 / 60)
    np.testing.assert_allclose(r.h_m, g.h_m, rtol=0, atol=1.01e-3)  # MSL + N, each to 1 mm
    np.testing.assert_allclose(r.sigma_pos_n, g.sigma_pos_n, rtol=0, atol=0.51e-3)
    speed = np.hypot(g.v_n[:, 0], g.v_n[:, 1])
    np.testing.assert_allclose(np.hypot(r.v_n[:, 0], r.v_n[:, 1]), speed, rtol=0, atol=0.51e-3 * 0.5145)
    moving = speed > 1.0
    crs = np.degrees(np.arctan2(r.v_n[moving, 1], r.v_n[moving, 0]) - np.arctan2(g.v_n[moving, 1], g.v_n[moving, 0]))
    assert np.abs((crs + 180) % 360 - 180).max() < 0.0051
    assert np.all(np.isnan(r.v_n[:, 2]))  # RMC has no vertical velocity: position updates only


def _resign(line: str) -> str:
    """An NMEA line with its checksum recomputed (to plant a bad field, not a bad checksum)."""
    body = line[1:line.rindex("*")]
    return f"${body}*{nmea_checksum(body)}"


def _edit_line(text: str, k: int, fn) -> str:
    lines = text.split("\r\n")
    lines[k] = fn(lines[k])
    return "\r\n".join(lines)


@pytest.mark.parametrize("edit,match", [
    (lambda s: _edit_line(s, 0, lambda x: x[:x.rindex("*")]), r"line 1: NMEA sentence without a checksum"),
    (lambda s: _edit_line(s, 4, lambda x: x.replace(",A,", ",V,", 1)), r"line 5: bad NMEA checksum \*[0-9A-F]{2} "
                                                                       r"\(computed \*[0-9A-F]{2}\)"),
    (lambda s: _edit_line(s, 3, lambda x: _resign(x.replace(",N,", ",Q,", 1))),
     r"line 4: bad GNGGA sentence: bad latitude hemisphere 'Q'"),
    (lambda s: _edit_line(s, 4, lambda x: _resign(",".join(f if i != 9 else "321" for i, f in enumerate(x.split(","))))),
     r"line 5: bad GNRMC sentence: bad date '321'"),
    (lambda s: "garbage\r\n" + s, r"line 1: not an NMEA sentence"),
])
def test_bad_nmea_sentence_names_file_and_line(car, tmp_path, edit, match):
    g = car.gnss
    p = write_nmea(tmp_path / "f.nmea", g.t_valid[:20] + car.gps_time_offset_s, g.lat_deg[:20], g.lon_deg[:20],
                   g.h_m[:20], g.sigma_pos_n[:20], g.v_n[:20])
    p.write_bytes(edit(p.read_bytes().decode()).encode())
    with pytest.raises(GnssFileError, match=match) as ei:
        read_gnss(p)
    assert str(p) in str(ei.value) and "\n" not in str(ei.value)


def test_nmea_and_pos_through_the_pipeline(car, frd_files, tmp_path):
    """The same fixes as .pos and as NMEA (no GNSS velocity measurement there):
    both runs stay within a few sigma of the truth."""
    imu, _ = frd_files
    g = car.gnss
    t_gps = g.t_valid + car.gps_time_offset_s
    pos = write_pos(tmp_path / "f.pos", t_gps, g.lat_deg, g.lon_deg, g.h_m, g.sigma_pos_n, g.v_n, g.sigma_vel_n)
    nm = write_nmea(tmp_path / "f.nmea", t_gps, g.lat_deg, g.lon_deg, g.h_m, g.sigma_pos_n, g.v_n)
    import dataclasses

    from insnav.analysis import errors

    truth = dataclasses.replace(car.truth, t=car.truth.t + car.gps_time_offset_s % 604800.0)
    for f in (pos, nm):
        c = config()
        c["gnss"] = {}
        ds, cfg = insnav.load_csv_dataset(imu, f, c)
        sol = insnav.run(ds, config=cfg)
        e = errors(sol, truth)
        hor = np.hypot(e["pos_n_m"][:, 0], e["pos_n_m"][:, 1])
        assert np.sqrt(np.mean(hor[len(hor) // 2:] ** 2)) < 3.0, f  # GNSS sigma 5 m horizontal


def test_leap_seconds():
    from insnav.gnss.gpstime import gps_seconds_from_calendar as cal

    assert gps_minus_utc_s(cal(1980, 1, 6)) == 0
    assert gps_minus_utc_s(cal(2016, 12, 31, 23, 59, 59)) == 17
    assert gps_minus_utc_s(cal(2017, 1, 1)) == 18
    assert gps_minus_utc_s(cal(2025, 8, 28)) == 18


# --------------------------------------------------------------------------- CLI


def test_cli_format_csv_prints_the_initial_state_and_repeats(frd_files, tmp_path):
    imu, gnss = frd_files
    import tomllib

    from insnav._toml import dumps_toml

    cfgp = tmp_path / "run.toml"
    cfgp.write_text(dumps_toml(config()))
    out = tmp_path / "sol.csv"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["run", "--format", "csv", "--imu", str(imu), "--gnss", str(gnss), "--config", str(cfgp),
                     "--out", str(out), "--quiet"]) == 0
    text = buf.getvalue()
    assert "initial state at t = " in text and "heading from gnss velocity" in text and "1-sigma" in text
    sol = insnav.load_solution(out)
    resolved = out.with_suffix(".csv.config.toml")
    d = tomllib.loads(resolved.read_text())
    assert d["imu"]["samples"] == "increments" and d["gnss"]["angle_unit"] == "deg" and "gyro_arw_deg_per_sqrt_h" in d["imu"]
    out2 = tmp_path / "sol2.csv"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["run", "--format", "csv", "--imu", str(imu), "--gnss", str(gnss), "--config", str(resolved),
                     "--out", str(out2), "--quiet"]) == 0
    sol2 = insnav.load_solution(out2)
    np.testing.assert_array_equal(sol.lat_deg, sol2.lat_deg)


def test_cli_format_csv_bad_unit_is_one_line(car, frd_files, tmp_path, capsys):
    _, gnss = frd_files
    imu = write_imu(tmp_path / "imu.csv", car, acc="g")
    from insnav._toml import dumps_toml

    cfgp = tmp_path / "run.toml"
    cfgp.write_text(dumps_toml(config()))
    rc = main(["run", "--format", "csv", "--imu", str(imu), "--gnss", str(gnss), "--config", str(cfgp),
               "--out", str(tmp_path / "s.csv"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "acc_unit = \"g\"" in err
    assert not (tmp_path / "s.csv").exists()


# --------------------------------------------------------------------------- real data: rtklibexplorer walk


def _walk(shared_data, *parts):
    p = shared_data.joinpath(WALK, *parts)
    if not p.exists():
        pytest.skip(f"{p} not found")
    return p


#: horizontal error against the RTK solution at the epochs the filter did not see [m]: rms and max
#: (measured 0.083 and 0.28 m at tests/data/walk_0827_loose.toml's settings; linear interpolation of the
#: same 1 Hz fixes gives 0.110 and 0.75 m)
WALK_HOLDOUT_RMS_M, WALK_HOLDOUT_MAX_M = 0.15, 0.5


def test_walk_loose_from_pos_no_typed_initial_state(shared_data):
    """The real walk: raw consumer IMU log (str2str-tagged) + the RTK .pos, 1 of
    every 4 fixes given to the filter (1 Hz), no initial state typed.  The RTK
    solution is the only reference, so the error is measured at the 3 of 4
    epochs the filter did not use (the INS bridging 1 s gaps of a walk in tight turns)."""
    import tomllib
    from pathlib import Path

    from insnav.io.rinex_dataset import rtklib_truth

    imu = _walk(shared_data, "raw", "imu_1730.csv")
    pos = _walk(shared_data, "raw", "gnss_1730_sf.pos")
    d = tomllib.loads((Path(__file__).resolve().parent / "data" / "walk_0827_loose.toml").read_text())
    ds, cfg = insnav.load_csv_dataset(imu, pos, d)
    a = ds.alignment
    assert a is not None and a.heading_source == "gnss_velocity" and a.static_s > 1.0
    sol = insnav.run(ds, config=cfg)
    # the default innovation gate rejects none (with the file's 5 cm/s velocity sigmas it rejected
    # 10 of 118: the reason for [gnss] sigma_vel_mps = 0.1 in the config)
    assert sol.summary["rejected"] == 0 and sol.summary["updates"] == len(ds.gnss) > 100
    ref = rtklib_truth(str(pos), ds.gps_time_offset_s)
    m = (ref.t > sol.t[0]) & (ref.t <= sol.t[-1])
    lat = np.interp(ref.t[m], sol.t, sol.lat_deg)
    lon = np.interp(ref.t[m], sol.t, sol.lon_deg)
    dn = (lat - ref.lat_deg[m]) * DEG * 6.37e6
    de = (lon - ref.lon_deg[m]) * DEG * 6.37e6 * math.cos(math.radians(ref.lat_deg[0]))
    hor = np.hypot(dn, de)
    held = ~np.isin(np.round(ref.t[m], 3), np.round(ds.gnss.t_valid, 3))
    assert held.sum() > 300
    rms = float(np.sqrt(np.mean(hor[held] ** 2)))
    assert rms < WALK_HOLDOUT_RMS_M and hor[held].max() < WALK_HOLDOUT_MAX_M, (rms, hor[held].max())


def test_a_relative_tag_in_the_toml_is_saved_resolved_and_the_saved_config_reruns(shared_data, tmp_path):
    """``[imu] tag`` relative to the TOML's folder: the resolved config written beside ``--out`` (another
    folder) names the file absolutely, so re-running it reads the same tag and gives the same rows."""
    import shutil
    import tomllib
    from pathlib import Path

    (tmp_path / "cfg").mkdir()
    (tmp_path / "results").mkdir()
    shutil.copy(_walk(shared_data, "raw", "imu_1730.csv.tag"), tmp_path / "cfg" / "walk_imu.tag")
    imu = tmp_path / "imu.csv"  # no imu.csv.tag beside it: the TOML's tag is the one read
    shutil.copy(_walk(shared_data, "raw", "imu_1730.csv"), imu)
    pos = _walk(shared_data, "raw", "gnss_1730_sf.pos")
    text = (Path(__file__).resolve().parent / "data" / "walk_0827_loose.toml").read_text()
    (tmp_path / "cfg" / "walk.toml").write_text(text.replace('grade = "consumer"',
                                                             'grade = "consumer"\ntag = "walk_imu.tag"', 1))
    a, b = tmp_path / "results" / "a.csv", tmp_path / "results" / "b.csv"
    run = ["run", "--format", "csv", "--imu", str(imu), "--gnss", str(pos), "--quiet"]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(run + ["--config", str(tmp_path / "cfg" / "walk.toml"), "--out", str(a)]) == 0
        saved = tomllib.loads((tmp_path / "results" / "a.csv.config.toml").read_text())
        assert saved["imu"]["tag"] == str((tmp_path / "cfg" / "walk_imu.tag").resolve())
        assert main(run + ["--config", str(tmp_path / "results" / "a.csv.config.toml"), "--out", str(b)]) == 0
    assert a.read_bytes() == b.read_bytes()
