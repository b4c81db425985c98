"""The course checks (the IMU/GNSS time offset, the gyro against the GNSS
course: insnav.data.checks) taken a block of fixes at a time: the same
figures as the whole-record arrays (tests/_course_reference.py, the code
before), whatever the block, and temporaries that do not grow with the
number of fixes."""
from __future__ import annotations

import dataclasses
import functools
import math
import tracemalloc

import numpy as np
import pytest

import insnav
import insnav.data.checks as checks
from insnav.data.dataset import GnssFixes
from insnav.data.checks import (DataCheckError, _stream_median, _Unwrap, check_gyro_against_gnss, check_time_offset,
                                estimate_time_offset, gyro_course_slope, heading_grid_step)

from _course_reference import estimate_time_offset as ref_offset
from _course_reference import gyro_course_slope as ref_slope

BLOCKS = (37, 256, None)


@functools.lru_cache(maxsize=1)
def _car():
    return insnav.simulate("urban-multignss", seed=0)


def _no_velocity(g):
    return dataclasses.replace(g, v_n=np.full_like(np.asarray(g.v_n, float), np.nan))


def _rtk(ds):
    """Positions only, exact (RTK-like: the truth at the fixes' times)."""
    g, tr = ds.gnss, ds.truth
    lat, lon = (np.interp(g.t_valid, tr.t, x) for x in (tr.lat_deg, tr.lon_deg))
    return dataclasses.replace(_no_velocity(g), lat_deg=lat, lon_deg=lon)


def _shifted(g, dt_s):
    return dataclasses.replace(g, t_valid=g.t_valid + dt_s, t_arrival=g.t_arrival + dt_s)


def _cases():
    """(name, t, dtheta_b, dv_b, gnss): velocity and positions-only courses, shifted time bases, gyros in
    degrees and inverted (the verdicts each check gives)."""
    ds = _car()
    imu, g = ds.imu, ds.gnss
    yield "car", imu.t, imu.dtheta_b, imu.dv_b, g
    yield "car, positions only", imu.t, imu.dtheta_b, imu.dv_b, _no_velocity(g)
    yield "car, exact positions only, GNSS 18 s late", imu.t, imu.dtheta_b, imu.dv_b, _shifted(_rtk(ds), 18.0)
    yield "car, GNSS 18 s late, positions only", imu.t, imu.dtheta_b, imu.dv_b, _shifted(_no_velocity(g), 18.0)
    yield "car, GNSS 1 s early", imu.t, imu.dtheta_b, imu.dv_b, _shifted(g, -1.0)
    yield "car, gyro in degrees", imu.t, np.degrees(imu.dtheta_b), imu.dv_b, g
    yield "car, gyro inverted", imu.t, -imu.dtheta_b, imu.dv_b, _rtk(ds)
    rev = np.arange(len(g))[::-1]  # out of time order: sorted first
    yield "car, fixes reversed", imu.t, imu.dtheta_b, imu.dv_b, dataclasses.replace(
        g, **{f: np.asarray(getattr(g, f))[rev] for f in ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m",
                                                          "v_n", "sigma_pos_n", "sigma_vel_n")}, origin=None)
    lon = np.asarray(g.lon_deg, float)  # across the antimeridian: the longitude unwrapped block to block
    yield "car, across 180 deg E", imu.t, imu.dtheta_b, imu.dv_b, dataclasses.replace(
        _rtk(ds), lon_deg=(np.asarray(_rtk(ds).lon_deg) - lon[len(lon) // 2] + 180.0 + 180.0) % 360.0 - 180.0)


def _same_offset(a, b):
    if a is None or b is None:
        return a is b
    return all((x == y) or (math.isnan(x) and math.isnan(y)) for x, y in
               zip(dataclasses.astuple(a), dataclasses.astuple(b)))


@pytest.mark.parametrize("block", BLOCKS)
def test_time_offset_equals_the_whole_record_estimate(block):
    """estimate_time_offset: every figure bit for bit (its pairs and samples are the whole record's)."""
    seen = 0
    for name, t, dth, dv, g in _cases():
        want = ref_offset(t, dth, dv, g)
        got = estimate_time_offset(t, dth, dv, g, block=block)
        assert _same_offset(got, want), (name, got, want)
        seen += want is not None
    assert seen >= 5


@pytest.mark.parametrize("block", BLOCKS)
def test_gyro_slope_equals_the_whole_record_regression(block):
    """gyro_course_slope: the verdict and the course flag exactly; the slope and the turning to 1e-12
    (the block sums added in another order), bit for bit in one block."""
    seen = 0
    for name, t, dth, dv, g in _cases():
        want = ref_slope(t, dth, dv, g)
        got = gyro_course_slope(t, dth, dv, g, block=block)
        assert (got is None) == (want is None), name
        if want is None:
            continue
        seen += 1
        if block is None:
            assert got == want, name
        assert got[1:4:2] == want[1:4:2], name
        assert got[0] == pytest.approx(want[0], rel=1e-12) and got[2] == pytest.approx(want[2], rel=1e-12), name
    assert seen >= 5


def test_messages_equal_in_small_blocks(monkeypatch):
    """The one-line refusals are the same with blocks of 37 fixes as in one block."""
    ds = _car()
    imu, g = ds.imu, ds.gnss
    calls = [lambda: check_time_offset(imu.t, imu.dtheta_b, imu.dv_b, _shifted(_rtk(ds), 18.0)),
             lambda: check_time_offset(imu.t, imu.dtheta_b, imu.dv_b, _shifted(g, -1.0)),
             lambda: check_gyro_against_gnss(imu.t, np.degrees(imu.dtheta_b), imu.dv_b, g),
             lambda: check_gyro_against_gnss(imu.t, -imu.dtheta_b, imu.dv_b, _rtk(ds))]
    whole = []
    for c in calls:
        with pytest.raises(DataCheckError) as e:
            c()
        whole.append(str(e.value))
    monkeypatch.setattr(checks, "COURSE_CHECK_BLOCK", 37)
    for c, msg in zip(calls, whole):
        with pytest.raises(DataCheckError) as e:
            c()
        assert str(e.value) == msg
    assert "GNSS is 18" in whole[0] and "GNSS is 1.0 s ahead" in whole[1]
    assert "degrees" in whole[2] and "opposite" in whole[3]


@pytest.mark.slow
def test_kfgins_sim_record_same_figures(shared_data):
    """The KF-GINS simulated track (positions only, 1 Hz): the same figures in blocks of 256 fixes."""
    from insnav.io.kfgins_dataset import load_kfgins

    ds, _ = load_kfgins(shared_data / "kfgins" / "sim" / "kf-gins-sim.yaml")
    imu, g = ds.imu, ds.gnss
    assert _same_offset(estimate_time_offset(imu.t, imu.dtheta_b, imu.dv_b, g, block=256),
                        ref_offset(imu.t, imu.dtheta_b, imu.dv_b, g))
    got, want = gyro_course_slope(imu.t, imu.dtheta_b, imu.dv_b, g, block=256), ref_slope(imu.t, imu.dtheta_b,
                                                                                          imu.dv_b, g)
    assert (got is None) == (want is None)
    if want is not None:
        assert got[1:4:2] == want[1:4:2] and got[0] == pytest.approx(want[0], rel=1e-12)


def test_stream_median_is_the_median():
    """_stream_median: np.median of the concatenation, by counts and (many distinct values) by bisection."""
    rng = np.random.default_rng(3)
    for x in (np.round(rng.normal(1.0, 0.01, 1001), 3), rng.normal(0.0, 1.0, 10_000), rng.normal(0.0, 1.0, 9_999),
              np.array([-0.0, 0.0, 5.0, -3.0])):
        parts = np.array_split(x, 7)
        assert _stream_median(lambda: iter(parts)) == np.median(x)
    assert math.isnan(_stream_median(lambda: iter([np.array([1.0, np.nan])])))
    assert math.isnan(_stream_median(lambda: iter([])))


def test_unwrap_in_chunks_is_np_unwrap():
    rng = np.random.default_rng(4)
    p = np.cumsum(rng.normal(0.0, 1.5, 500))
    p = (p + np.pi) % (2 * np.pi) - np.pi
    for cuts in ([1, 2, 100, 101], [250], list(range(1, 500, 17))):
        u = _Unwrap()
        got = np.concatenate([u(c) for c in np.split(p, cuts)])
        assert np.array_equal(got, np.unwrap(p))


def _turning(n_fix: int, span_s: float):
    """A vehicle at 10 m/s turning back and forth (IMU at 10 Hz over ``span_s``) with ``n_fix`` GNSS
    fixes over the same span, positions only (the KF-GINS file's case)."""
    t = np.arange(1, int(span_s * 10) + 1) * 0.1
    w = 0.2 * np.sin(2 * np.pi * t / 60.0)
    dth = np.zeros((t.size, 3))
    dth[:, 2] = w * 0.1
    dv = np.zeros((t.size, 3))
    dv[:, 2] = -9.8 * 0.1
    gt = np.linspace(t[0], t[-1], n_fix)
    head = np.interp(gt, t, np.cumsum(dth[:, 2]))
    # positions from the course: the integral of the velocity (trapezoid)
    vn, ve = 10 * np.cos(head), 10 * np.sin(head)
    dt = np.diff(gt, prepend=gt[0])
    n_m = np.cumsum(vn * dt)
    e_m = np.cumsum(ve * dt)
    lat = 0.5 + n_m / 6_371_000.0
    lon = 0.2 + e_m / (6_371_000.0 * np.cos(0.5))
    z = np.zeros(n_fix)
    g = GnssFixes(t_valid=gt, t_arrival=gt, lat_deg=np.degrees(lat), lon_deg=np.degrees(lon), h_m=z,
                         v_n=np.full((n_fix, 3), np.nan), sigma_pos_n=np.ones((n_fix, 3)),
                         sigma_vel_n=np.full((n_fix, 3), np.nan))
    return t, dth, dv, g


def _peak_bytes(f, *args, **kw) -> int:
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        f(*args, **kw)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_temporaries_do_not_grow_with_the_fixes():
    """10x the fixes over the same IMU span: the bounded checks' peak of traced allocations grows by less
    than 512 KiB (what differs is bounded: a few blocks of 1024 fixes, the median's counts of at most 4096
    distinct intervals, the samples of the at most 4000 pairs, ~4 MB with the correlation's lags; the
    heading grid, the IMU's, is the same); the whole-record reference's grows by megabytes."""
    t, dth, dv, g1 = _turning(20_000, 2000.0)
    _, _, _, g10 = _turning(200_000, 2000.0)
    with heading_grid_step(0.5):
        for f, kw in ((estimate_time_offset, dict(block=1024)), (gyro_course_slope, dict(block=1024))):
            p1, p10 = (_peak_bytes(f, t, dth, dv, g, **kw) for g in (g1, g10))
            assert p10 - p1 < 512 * 1024, (f.__name__, p1, p10)
            assert p10 < 6_000_000, (f.__name__, p10)
        for f in (ref_offset, ref_slope):  # the measure sees the whole-record temporaries
            r1, r10 = (_peak_bytes(f, t, dth, dv, g) for g in (g1, g10))
            assert r10 - r1 > 10_000_000, (f.__name__, r1, r10)


def test_spacing_median_is_the_sorted_distinct_spacing():
    """spacing_median: median(d[d != 0]) of d = diff(sort(t)), in order or not, blocks of 16; None without."""
    from insnav._median import spacing_median

    rng = np.random.default_rng(5)
    t = np.round(np.cumsum(rng.choice([0.0, 0.1, 0.1, 0.2, 0.1000001], 1000)), 7)
    for x in (t, t[::-1], rng.permutation(t), np.append(t, np.nan)):
        d = np.diff(np.sort(x))
        want = np.median(d[d != 0])
        got = spacing_median(x, block=16)
        assert got == want or (math.isnan(got) and math.isnan(want))
    assert spacing_median(np.ones(5)) is None and spacing_median(np.zeros(0)) is None


def test_diff_median_is_the_median_of_the_intervals():
    from insnav._median import diff_median

    rng = np.random.default_rng(6)
    for x in (np.round(np.cumsum(rng.choice([0.1, 0.1, 0.2], 999)), 3), rng.normal(0.0, 1.0, 1000),
              np.array([0.0, np.nan, 1.0])):
        want, got = np.median(np.diff(x)), diff_median(x, block=16)
        assert got == want or (math.isnan(got) and math.isnan(want))
    assert math.isnan(diff_median(np.ones(1)))
