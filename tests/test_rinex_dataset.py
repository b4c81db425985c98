"""Real RINEX + IMU data for the tight filter: ``insnav.io.rinex_dataset``
on the rtklibexplorer walk_0827 log (raw u-blox GPS L1 + consumer IMU at ~152 Hz,
time-tagged by str2str, RTK reference), ``insnav run --format rinex`` and
``insnav evaluate SOL REF.pos``, malformed IMU CSV / tag files, and synthetic
round trips of the generic IMU CSV and of the tick -> GPS time map.
"""
from __future__ import annotations

import contextlib
import io
import json
import math
import struct

import numpy as np
import pytest

from insnav.analysis import errors
from insnav.cli import main
from insnav.config import ConfigError
from insnav.gnss.gpstime import SECONDS_PER_WEEK
from insnav.io.rinex_dataset import (GPST_UNIX_OFFSET_S, ImuCsvFormat, ImuFileError, RinexOptions, load_rinex,
                                     read_imu_csv, read_str2str_tag, rtklib_truth, tick_time_map)
from insnav.filters.tight import run_tight
from insnav.gnss.weighting import Weighting

G0 = 9.80665
WALK = "rtklibexplorer_walk_0827"
# the raw log: ax,ay,az [g], gx,gy,gz [deg/s], tick [ms]; mounting and lever arm of the author's walk_config.py
WALK_OPTIONS = dict(imu_columns=["ax", "ay", "az", "gx", "gy", "gz", "tick_ms"], imu_acc_unit="g",
                    imu_gyro_unit="dps", imu_mount_rpy_deg=[180.0, 0.0, -90.0], lever_arm_b=[0.0, -0.05, 0.0])
RAW_FMT = ImuCsvFormat(("ax", "ay", "az", "gx", "gy", "gz", "tick_ms"), acc_unit="g", gyro_unit="dps",
                       mount_rpy_deg=(180.0, 0.0, -90.0))


def _walk(shared_data, *parts):
    p = shared_data.joinpath(WALK, *parts)
    if not p.exists():
        pytest.skip(f"{p} not found")
    return p


@pytest.fixture(scope="module")
def walk_files(shared_data):
    return dict(obs=_walk(shared_data, "rinex_derived", "gnss_1730.obs"),
                nav=_walk(shared_data, "rinex_derived", "gnss_1730.nav"),
                imu=_walk(shared_data, "raw", "imu_1730.csv"),
                pos=_walk(shared_data, "raw", "gnss_1730_sf.pos"))


@pytest.fixture(scope="module")
def walk60(walk_files):
    """The walk up to 60 s after the first epoch (the run starts when walking, ~16 s)."""
    return load_rinex(walk_files["obs"], walk_files["nav"], walk_files["imu"], dict(WALK_OPTIONS, end_s=60.0),
                      reference=walk_files["pos"])


# --------------------------------------------------------------------------- the walk


def test_walk_imu_log_time_rate_and_units(walk_files):
    s = read_imu_csv(walk_files["imu"], RAW_FMT)
    # 20 457 lines, the first and the (unterminated) last are partial and dropped
    assert len(s) == 20455 and s.info["lines_dropped"] == [1, 20457]
    assert s.lines[0] == 2 and s.lines[-1] == 20456
    assert np.all(np.diff(s.t_gps_s) > 0)
    assert 151.0 < s.rate_hz < 154.0
    dt = np.diff(s.t_gps_s)
    assert 0.005 < dt.min() and dt.max() < 0.011  # 6-9 ms IMU counter steps
    tag = read_str2str_tag(str(walk_files["imu"]) + ".tag")
    # the tag file starts 2025-08-28 17:30:40.961 GPST, 1.2 s after the first GNSS epoch
    assert tag.t_start_gps_s == pytest.approx(1440437440.961, abs=1e-6)
    assert 0.0 < s.t_gps_s[0] - tag.t_start_gps_s < 0.05
    assert s.t_gps_s[-1] - s.t_gps_s[0] == pytest.approx(134.25, abs=0.05)
    # the log had \r\n line ends (tag bytes = file bytes + lines); clocks agree to ~10 ppm
    assert s.info["crlf_converted"] and abs(s.info["drift_ppm"]) < 100.0
    assert 0.0 <= s.info["latency_median_ms"] < 30.0
    # units and mounting: standing still for the first 8 s, f_b = C_bn (0, 0, -g)
    rest = s.t_gps_s < s.t_gps_s[0] + 8.0
    f_rest = s.acc_b[rest].mean(axis=0)
    assert f_rest[2] < -9.6 and np.all(np.abs(f_rest[:2]) < 0.5)
    assert np.linalg.norm(f_rest) == pytest.approx(9.80, abs=0.3)  # local g 9.797, consumer bias ~15 mg
    assert np.linalg.norm(s.acc_b, axis=1).mean() == pytest.approx(9.80, abs=0.3)
    w_rest = np.degrees(np.linalg.norm(s.gyro_b[rest].mean(axis=0)))
    assert w_rest < 0.5  # deg/s: only the gyro bias
    yaw_rate = np.degrees(s.gyro_b[:, 2])
    assert 30.0 < np.abs(yaw_rate).max() < 300.0  # tight turns while walking, not rad read as deg


def test_walk_loader_dataset(walk60, walk_files):
    ds, cfg = walk60
    info = ds.info
    assert ds.gps_time_offset_s == 2381 * SECONDS_PER_WEEK  # dataset time = GPS seconds of week
    assert info["gps_prns_with_ephemeris"] == [10, 23, 27, 32] and info["prns_used"] == [10, 23, 27, 32]
    assert len(info["gps_prns_observed"]) == 9
    assert info["sats_per_epoch"] == (4, 4, 4)  # G23 drops out only at 95-97 s
    # start rule "course": walking from ~12 s, 1 s above 0.8 m/s
    t_first = ds.spp.t[0]
    assert 13.0 < ds.t0 - t_first < 20.0
    inp = ds.tight_inputs
    assert np.all(inp.epoch_t > ds.t0) and np.all(np.diff(inp.epoch_t) == pytest.approx(0.25, abs=1e-3))
    assert inp.epoch_t.size == pytest.approx((60.0 - (ds.t0 - t_first)) * 4, abs=2)
    assert np.all(ds.imu.t > ds.t0) and ds.imu.t[-1] <= t_first + 60.0
    assert ds.imu.dtheta_b.shape == ds.imu.dv_b.shape == (len(ds.imu.t), 3)
    assert ds.imu.origin.where(0).startswith(str(walk_files["imu"]) + ":")
    assert len(ds.gnss) == inp.epoch_t.size  # single-point fixes, all epochs have 4 satellites
    # initial heading = course over ground within 30 deg of the RTK course (handheld, tight turns)
    tr = ds.truth
    i = int(np.searchsorted(tr.t, ds.t0))
    course = math.degrees(math.atan2(tr.v_n[i, 1], tr.v_n[i, 0]))
    assert abs((ds.initial.yaw_deg - course + 180.0) % 360.0 - 180.0) < 30.0
    assert abs(ds.initial.roll_deg) < 10.0 and abs(ds.initial.pitch_deg) < 10.0
    assert tr.quality.min() == 1 and set(np.unique(tr.quality)) <= {1, 2}
    assert not cfg.init_error and cfg.coupling == "tight"


def _horizontal(sol, truth):
    e = errors(sol, truth)
    p, v = e["pos_n_m"][:, :2], e["vel_n_mps"][:, :2]
    shape = p - p.mean(axis=0)
    return (np.hypot(p[:, 0], p[:, 1]), np.sqrt(np.mean(np.sum(shape ** 2, axis=1))),
            np.sqrt(np.mean(np.sum(v ** 2, axis=1))))


@pytest.mark.parametrize("filt", ["ekf", "rbukf"])
def test_walk_tight_first_60s_against_rtk(walk60, filt):
    ds, cfg = walk60
    cfg.filter = filt
    sol = run_tight(ds, cfg)
    hz, shape_rms, vel_rms = _horizontal(sol, ds.truth)
    # measured (EKF and RB-UKF alike): max 8.97 m, RMS 8.37 m, almost all of it a constant offset
    # (pseudorange biases of 4 satellites: G23 -7.8 m); around that offset 0.43 m RMS; velocity 0.23 m/s RMS
    assert hz.max() < 10.5
    assert shape_rms < 0.7
    assert vel_rms < 0.30
    assert sol.summary["updates"] >= ds.tight_inputs.epoch_t.size - 2 and sol.summary["rejected"] == 0
    # the gyro bias seen standing still (body x about +0.16 deg/s) is found
    assert np.degrees(sol.gyro_bias_rps[-1, 0]) == pytest.approx(0.15, abs=0.08)
    # the same consumer IMU alone: hundreds of metres within 40 s
    free = run_tight(ds, cfg, use_pseudorange=False, use_rate=False)
    hz_free, _, _ = _horizontal(free, ds.truth)
    assert hz_free.max() > 100.0


# --------------------------------------------------------------------------- CLI


def _call(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 1
    return rc, out.getvalue(), err.getvalue()


def _toml_list(v):
    return "[" + ", ".join(f'"{x}"' if isinstance(x, str) else repr(float(x)) for x in v) + "]"


def test_cli_run_format_rinex_and_evaluate_against_pos(walk_files, walk60, tmp_path):
    cfg_file = tmp_path / "walk.toml"
    cfg_file.write_text("[rinex]\n" + "".join(f"{k} = {_toml_list(v) if isinstance(v, list) else repr(v)}\n"
                                              for k, v in dict(WALK_OPTIONS, end_s=60.0).items()))
    out = tmp_path / "sol.csv"
    rc, so, se = _call(["run", "--format", "rinex", "--obs", walk_files["obs"], "--nav", walk_files["nav"],
                        "--imu", walk_files["imu"], "--config", cfg_file, "--coupling", "tight", "--filter",
                        "ekf", "--out", out])
    assert rc == 0, se
    assert "tight coupling" in so
    a = np.loadtxt(out, delimiter=",", skiprows=1)
    ds, _ = walk60
    assert a[0, 0] > ds.t0 and a[-1, 0] <= ds.spp.t[0] + 60.0  # GPS seconds of week
    rc, so, se = _call(["evaluate", out, walk_files["pos"], "--json"])
    assert rc == 0, se
    res = json.loads(so)
    assert "att_deg" not in res["rms"]  # an RTK reference has no attitude
    assert res["samples"] == pytest.approx((60.0 - (ds.t0 - ds.spp.t[0])) * 4, abs=2)  # at the 4 Hz epochs
    assert 7.0 < res["horizontal_rms_m"] < 10.0 and res["horizontal_max_m"] < 10.5
    rc, so, se = _call(["evaluate", out, walk_files["pos"], "--json", "--quality", "1"])
    assert rc == 0, se
    assert json.loads(so)["samples"] == res["samples"]  # RTK float only before 16 s and after 85 s
    assert len(rtklib_truth(walk_files["pos"], 0.0).t) == 536  # README: 349 fix + 187 float
    assert len(rtklib_truth(walk_files["pos"], 0.0, quality_max=1).t) == 349
    # the resolved configuration (with its [rinex] table) repeats the run
    out2 = tmp_path / "sol2.csv"
    rc, _, se = _call(["run", "--format", "rinex", "--obs", walk_files["obs"], "--nav", walk_files["nav"],
                       "--imu", walk_files["imu"], "--config", str(out) + ".config.toml", "--out", out2])
    assert rc == 0, se
    assert out2.read_text() == out.read_text()


def test_cli_rinex_bad_imu_line_is_one_line_error_and_no_output(walk_files, tmp_path):
    bad = tmp_path / "imu.csv"
    bad.write_text("t,ax,ay,az,gx,gy,gz\n1440437440.0,0,0,-9.8,0,0,0\n1440437440.01,0,0,-9.8,0,zero,0\n")
    out = tmp_path / "sol.csv"
    rc, so, se = _call(["run", "--format", "rinex", "--obs", walk_files["obs"], "--nav", walk_files["nav"],
                        "--imu", bad, "--out", out])
    assert rc == 2 and len(se.strip().splitlines()) == 1
    assert f"{bad}, line 3: bad number 'zero' in field 6 (gy)" in se
    assert not out.exists()
    rc, _, se = _call(["run", "--format", "rinex", "--obs", walk_files["obs"], "--imu", bad, "--out", out])
    assert rc == 2 and "--format rinex needs --nav" in se
    # well-formed, but a day before the observations (e.g. UTC or seconds of week taken for GPS seconds)
    far = _csv(tmp_path, "1440350000.0,0,0,-9.8,0,0,0\n1440350000.01,0,0,-9.8,0,0,0\n", "far.csv")
    rc, _, se = _call(["run", "--format", "rinex", "--obs", walk_files["obs"], "--nav", walk_files["nav"],
                       "--imu", far, "--out", out])
    assert rc == 2 and f"{far}: the IMU data" in se and "do not overlap the observations" in se
    assert not out.exists()


# --------------------------------------------------------------------------- malformed files


def _csv(tmp_path, text, name="imu.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text, line, what", [
    ("1,0,0,-9.8,0,0,0\n2,0,0,-9.8,0,0\n", 2, "expected 7 ',"),
    ("# comment\nt,ax,ay,az,gx,gy,gz\n1,0,0,-9.8,0,0,0\n2,0,0,-9.8,0,0,0x\n", 4, "bad number '0x' in field 7 (gz)"),
    ("1,0,0,-9.8,0,0,0\n2,0,nan,-9.8,0,0,0\n", 2, "non-finite value 'nan' in field 3 (ay)"),
    ("1,0,0,-9.8,0,0,0\n2,0,0,-9.8,0,0,0\n\n2,0,0,-9.8,0,0,0\n", 4, "time 2.0 does not increase (line 2"),
    ("1,0,0,-9.8,0,0,0\nt,ax,ay,az,gx,gy,gz\n", 2, "bad number 't' in field 1 (t)"),
])
def test_malformed_imu_csv_names_file_and_line(tmp_path, text, line, what):
    p = _csv(tmp_path, text)
    with pytest.raises(ImuFileError) as ei:
        read_imu_csv(p)
    assert f"{p}, line {line}: " in str(ei.value) and what in str(ei.value)
    assert ei.value.line == line


def _tag_bytes(t_start_unix_s, records):
    head = b"TIMETAG RTKLIB EX".ljust(60, b"\0") + struct.pack("<I", 12345)
    t_int = int(math.floor(t_start_unix_s))
    return head + struct.pack("<Id", t_int, t_start_unix_s - t_int) + b"".join(
        struct.pack("<II", *r) for r in records)


def test_malformed_tag_file_names_the_byte(tmp_path):
    p = tmp_path / "x.tag"
    p.write_bytes(b"NOT A TAG" + b"\0" * 80)
    with pytest.raises(ImuFileError, match=r"x\.tag, byte 0: not an RTKLIB str2str time-tag file"):
        read_str2str_tag(p)
    good = _tag_bytes(1756402240.5, [(10, 100), (20, 200)])
    p.write_bytes(good + b"\1\2\3")
    with pytest.raises(ImuFileError, match=r"byte 92: truncated record \(3 of 8 bytes\)"):
        read_str2str_tag(p)
    p.write_bytes(_tag_bytes(1756402240.5, [(10, 100), (20, 200), (15, 300)]))
    with pytest.raises(ImuFileError, match=r"byte 92: tick 15 goes backwards \(previous record: 20\)"):
        read_str2str_tag(p)
    p.write_bytes(_tag_bytes(1756402240.5, [(10, 100), (20, 90)]))
    with pytest.raises(ImuFileError, match=r"byte 88: file position 90 goes backwards"):
        read_str2str_tag(p)
    # a tag that does not describe the CSV beside it
    csv = _csv(tmp_path, "partial\n0,0,1,0,0,0,1000\n0,0,1,0,0,0,1006\n0,0,1,0,0,0,1012\n", "log.csv")
    p.write_bytes(_tag_bytes(1756402240.5, [(10, 500)]))
    with pytest.raises(ImuFileError, match=r"x\.tag: the tag covers 500 bytes but .*log\.csv has 59 bytes \(4 lines\)"):
        read_imu_csv(csv, RAW_FMT, tag=p)


def test_rinex_options_are_checked():
    with pytest.raises(ConfigError, match=r"unknown key 'rinex.imu_unit'"):
        RinexOptions.from_dict({"imu_unit": "g"})
    with pytest.raises(ConfigError, match=r"imu_acc_unit: bad value 'G'; allowed: mps2, g"):
        RinexOptions.from_dict({"imu_acc_unit": "G"})
    with pytest.raises(ConfigError, match=r"'rinex.init_yaw_deg': bad value 'north'"):
        RinexOptions.from_dict({"init_yaw_deg": "north"})
    with pytest.raises(ConfigError, match=r"must name 'gz' exactly once"):
        RinexOptions.from_dict({"imu_columns": ["t", "ax", "ay", "az", "gx", "gy"]})


# --------------------------------------------------------------------------- synthetic round trips


def test_generic_csv_units_mounting_and_integration(tmp_path):
    """Rates in g and deg/s, mounted upside down and turned: exact body increments."""
    week = 2381
    sow = 408000.0 + np.arange(201) * 0.01
    rpy = (180.0, 0.0, -90.0)  # x_b = -y_imu, y_b = -x_imu, z_b = -z_imu
    f_b = np.array([0.3, -0.2, -9.81])  # m/s^2
    w_b = np.radians([1.0, -2.0, 30.0])  # rad/s
    f_imu = np.array([-f_b[1], -f_b[0], -f_b[2]])
    w_imu = np.array([-w_b[1], -w_b[0], -w_b[2]])
    ramp = np.linspace(0.0, 1.0, sow.size)[:, None]  # a rate varying linearly: trapezoid is exact
    rows = np.column_stack([sow, f_imu / G0 * (1 + ramp), np.degrees(w_imu) * (1 + ramp)])
    p = tmp_path / "imu.csv"
    np.savetxt(p, rows, delimiter=",", fmt="%.12f", header="sow,ax,ay,az,gx,gy,gz", comments="")
    fmt = ImuCsvFormat(time="gps_sow", acc_unit="g", gyro_unit="dps", mount_rpy_deg=rpy)
    s = read_imu_csv(p, fmt, week=week)
    assert s.t_gps_s[0] == week * SECONDS_PER_WEEK + 408000.0
    np.testing.assert_allclose(s.acc_b[0], f_b, atol=1e-9)
    np.testing.assert_allclose(s.gyro_b[-1], 2 * w_b, atol=1e-9)
    imu = s.to_increments(week * SECONDS_PER_WEEK)
    assert len(imu.t) == 200 and imu.t[0] == pytest.approx(408000.01)
    k = (1 + 0.5 * (ramp[1:] + ramp[:-1]))  # mean of the rate over each interval
    np.testing.assert_allclose(imu.dv_b, f_b * k * 0.01, atol=1e-9)
    np.testing.assert_allclose(imu.dtheta_b, w_b * k * 0.01, atol=1e-11)
    assert imu.origin.where(0) == f"{p}:3"  # header is line 1, first increment ends at line 3
    # increments in m/s and rad, time as RTKLIB gtime_t (GPST since 1970)
    rows2 = np.column_stack([sow + week * SECONDS_PER_WEEK + GPST_UNIX_OFFSET_S, np.tile(f_imu * 0.01, (201, 1)),
                             np.tile(w_imu * 0.01, (201, 1)), np.zeros(201)])
    p2 = tmp_path / "inc.csv"
    np.savetxt(p2, rows2, delimiter=",", fmt="%.9f")
    fmt2 = ImuCsvFormat(columns=("t", "ax", "ay", "az", "gx", "gy", "gz", "_"), time="gpst_unix_s",
                        samples="increment", mount_rpy_deg=rpy)
    imu2 = read_imu_csv(p2, fmt2).to_increments(week * SECONDS_PER_WEEK)
    assert len(imu2.t) == 201 and imu2.t[0] == pytest.approx(408000.0, abs=1e-6)
    np.testing.assert_allclose(imu2.dv_b, np.tile(f_b * 0.01, (201, 1)), atol=1e-9)


def test_tick_time_map_recovers_a_known_clock(tmp_path):
    """A tagged log with a known IMU clock offset and drift, latencies 2-40 ms: the lower envelope finds it."""
    rng = np.random.default_rng(5)
    n = 3000
    tick_ms = 500000 + np.cumsum(rng.integers(6, 8, n))  # IMU counter [ms]
    t_start = 1756402240.25  # GPST since 1970 at tag tick 0
    drift = 40e-6
    t_true = 0.3 + (tick_ms - tick_ms[0]) / 1000.0 * (1 + drift)  # sample time after opening [s]
    lines = [f"{0.01:.3f},{0.0:.3f},{-1.0:.3f},{0.1:.3f},{0.0:.3f},{0.0:.3f},{k}\n" for k in tick_ms]
    text = "0,-1.000,0.1,0.0,0.0,999\n" + "".join(lines)  # a partial first line, as str2str logs start
    csv = tmp_path / "imu.csv"
    csv.write_bytes(text.encode())
    ends = np.cumsum([len(x) for x in text.splitlines(keepends=True)])
    # writes every ~15.6 ms (a Windows PC timer): each carries the lines that arrived since the last one
    latency = 0.002 + rng.uniform(0.0, 0.038, n)
    arrival = t_true + latency
    write_t = np.arange(0.3, arrival.max() + 0.05, 0.0156)
    recs = []
    for tw in write_t:
        done = np.flatnonzero(arrival <= tw)
        fpos = int(ends[done[-1] + 1]) if done.size else int(ends[0])
        recs.append((int(round(tw * 1000)), fpos))
    recs[-1] = (recs[-1][0], len(text))
    tag = tmp_path / "imu.csv.tag"
    tag.write_bytes(_tag_bytes(t_start, recs))
    s = read_imu_csv(csv, RAW_FMT)
    assert len(s) == n
    t_expect = t_start - GPST_UNIX_OFFSET_S + t_true
    err_ms = (s.t_gps_s - t_expect) * 1e3
    # the map is the true time plus the smallest latency seen (>= 2 ms) plus PC tick rounding
    assert np.all(err_ms > 0.0) and np.all(err_ms < 4.5)
    assert s.info["drift_ppm"] == pytest.approx(40.0, abs=15.0)
    assert np.allclose(s.acc_b[0], [0.0, -0.01 * G0, G0], atol=1e-9)
    with pytest.raises(ValueError, match="drift apart by"):
        tick_time_map(np.arange(1000) * 0.01, np.arange(1000) * 0.012)  # 20 % apart over 10 s


# --------------------------------------------------------------------------- gyro bias from the standstill


def _static_then_moving(bias_rps, sigma_w=2e-3, rate=150.0, t_still=4.0, t_move=3.0, seed=5):
    """IMU increments (body FRD): t_still s standing level with a constant gyro bias and white noise,
    then t_move s rotating at 1 rad/s with 2 m/s^2 of horizontal acceleration."""
    from insnav.data.dataset import ImuData

    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    n_s, n_m = int(t_still * rate), int(t_move * rate)
    t = 100.0 + dt * np.arange(1, n_s + n_m + 1)
    w = np.asarray(bias_rps) + sigma_w * rng.standard_normal((t.size, 3))
    f = np.tile([0.0, 0.0, -9.81], (t.size, 1)) + 1e-3 * rng.standard_normal((t.size, 3))
    w[n_s:, 2] += 1.0
    f[n_s:, 0] += 2.0
    return ImuData(t, w * dt, f * dt), t[n_s - 1], t[-1], sigma_w, n_s


def test_static_gyro_bias_is_the_mean_rate_of_the_standstill():
    """init_gyro_bias = "static": the mean rate of the stationary samples before the start, within its
    own sigma of the true bias (the moving samples after the standstill and after the start left out),
    the sigma the standard error and the Earth rate in quadrature."""
    from insnav.earth import OMEGA_IE
    from insnav.io.rinex_dataset import static_gyro_bias

    b = np.radians([0.15, -0.09, -0.19])
    imu, t_still_end, t_end, sigma_w, n_s = _static_then_moving(b)
    bias, sigma, n = static_gyro_bias(imu, t_end)  # the start after the motion: motion samples excluded
    assert 0.8 * n_s <= n <= n_s  # the detector's window fills first; no moving sample
    sem = sigma_w / math.sqrt(n)
    assert np.all(np.abs(np.asarray(bias) - b) < 4 * sem)
    np.testing.assert_allclose(sigma, np.hypot(sem, OMEGA_IE), rtol=0.1)
    # a start before any standstill: a one-line error naming the key
    with pytest.raises(ValueError, match='init_gyro_bias = "static": 0.00 s of standstill'):
        static_gyro_bias(imu, imu.t[20])
    assert RinexOptions.from_dict({"init_gyro_bias": "static"}).init_gyro_bias == "static"
    with pytest.raises(ConfigError, match=r"'rinex.init_gyro_bias': bad value 'mean'"):
        RinexOptions.from_dict({"init_gyro_bias": "mean"})


def test_walk_static_gyro_bias_reaches_the_tight_filter(walk_files):
    """The walk stands still for ~3 s before it starts: the static gyro bias (0.15-0.19 deg/s per axis,
    far above the consumer gyro's 0.005 deg/s sigma of that mean) is the tight filter's first estimate."""
    ds, cfg = load_rinex(walk_files["obs"], walk_files["nav"], walk_files["imu"],
                         dict(WALK_OPTIONS, end_s=30.0, init_gyro_bias="static"))
    b = np.asarray(cfg.init_gyro_bias_radps)
    s = np.asarray(cfg.init_sigma_gyro_bias_radps)
    assert ds.info["gyro_bias_static"]["samples"] > 150  # > 1 s at ~167 Hz
    assert np.all(np.abs(np.degrees(b)) > 0.05) and np.all(np.degrees(s) < 0.01)
    sol = run_tight(ds, cfg)
    np.testing.assert_allclose(sol.gyro_bias_rps[0], b, atol=float(3 * s.max()))
    zero = run_tight(ds, load_rinex(walk_files["obs"], walk_files["nav"], walk_files["imu"],
                                    dict(WALK_OPTIONS, end_s=30.0))[1])
    assert np.abs(zero.gyro_bias_rps[0]).max() < np.radians(0.05)


def test_systems_of_the_gnss_and_rinex_tables(tmp_path, shared_data):
    """[gnss] systems selects among the systems [rinex] systems reads: one asking for a system that
    is not read is refused (it would be left out without a word); a [gnss] table that restates the
    documented defaults is the default weighting; spp reads an INS run's [rinex] systems."""
    from insnav.filters.spp import load_spp_config

    with pytest.raises(ConfigError, match=r"\[gnss\] systems = \['G', 'E'\] asks for E, which \[rinex\] systems = "
                                          r"\"G\" does not read: add E to \[rinex\] systems"):
        load_rinex("no.obs", "no.nav", "no.csv", dict(WALK_OPTIONS), weighting={"systems": ["G", "E"]})
    assert Weighting.from_dict({"system_factors": {"R": 1.5}}, "t").is_default
    assert not Weighting.from_dict({"system_factors": {"R": 2.0}}, "t").is_default
    toml = tmp_path / "run.toml"
    toml.write_text('[rinex]\nsystems = "GE"\n', encoding="utf-8")
    assert load_spp_config(toml)[1].systems == ["G", "E"]
    toml.write_text('[rinex]\nsystems = "GE"\n[gnss]\nsystems = ["G", "C"]\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"run.toml: \[gnss\] systems = \['G', 'C'\] and \[rinex\] systems = \"GE\" "
                                          r"differ"):
        load_spp_config(toml)


def test_a_system_without_ephemerides_is_named(shared_data):
    """RINEX 2 keeps GLONASS in a .g file of its own: [rinex] systems = "GR" with the .n file alone
    warns that no GLONASS satellite is used; with both files merged (--nav a.n,a.g) it does not."""
    import warnings

    from insnav.errors import InsnavWarning
    from insnav.gnss.rinex import read_nav_multi
    from insnav.io.rinex_dataset import _warn_systems_without_ephemerides

    folder = shared_data / "smartloc_berlin_potsdamer_platz"
    if not folder.is_dir():
        pytest.skip(f"smartLoc data not found at {folder}")
    n, g = folder / "brdc1580.16n", folder / "brdc1580.16g"
    with pytest.warns(InsnavWarning, match=r"brdc1580.16n: no GLONASS ephemeris, so \[rinex\] systems = \"GR\" uses "
                                           "no GLONASS satellite"):
        _warn_systems_without_ephemerides(read_nav_multi([n], "GR"), "GR")
    both = read_nav_multi([n, g], "GR")
    assert len(both.eph_r.prn) > 20
    with warnings.catch_warnings():
        warnings.simplefilter("error", InsnavWarning)
        _warn_systems_without_ephemerides(both, "GR")
