"""The one-pass IMU input checks (``_core.scan_imu``, ``insnav/_imu_scan.py``)
against the array logic they replace, and the messages built from them."""
from __future__ import annotations

import numpy as np
import pytest

from insnav import _core
from insnav._imu_scan import scan_imu, scan_memo
from insnav.data.dataset import ImuData, RowOrigin
from insnav.filters.sanitize import DEFAULTS, sanitize_imu

RATE, ACCEL, GAP = DEFAULTS["max_rate_rps"], DEFAULTS["max_accel_mps2"], DEFAULTS["gap_factor"]


def _stream(n=2000, dt=0.005, seed=3):
    """A level IMU at rest turning slowly: t [s], dtheta_b [rad], dv_b [m/s]."""
    rng = np.random.default_rng(seed)
    t = 100.0 + dt * np.arange(1, n + 1)
    dth = rng.normal(0.0, 1e-4, (n, 3)) + [0.0, 0.0, 0.1 * dt]
    dv = rng.normal(0.0, 1e-3, (n, 3)) + [0.0, 0.0, -9.8 * dt]
    return t, dth, dv


def _reference(t, dth, dv, t0=None):
    """The checks as sanitize_imu made them with whole-array numpy operations
    before the compiled pass (first index of each kind, -1 for none)."""
    first = lambda mask: int(np.argmax(mask)) if mask.any() else -1  # noqa: E731
    n = len(t)
    ref = {"nonfinite_t": first(~np.isfinite(t)),
           "nonfinite_dtheta": first(~np.isfinite(dth).all(axis=1)),
           "nonfinite_dv": first(~np.isfinite(dv).all(axis=1))}
    d = np.diff(t)
    ref["decrease"] = first(d < 0) + 1 if (d < 0).any() else -1
    ref["not_increasing"] = first(~(d > 0)) + 1 if (~(d > 0)).any() else -1
    ref["repeats"] = int((d == 0).sum())
    dt0 = float(np.median(d[:: max(1, len(d) // 200_000)])) if len(d) else np.nan
    if not np.isfinite(dt0) or dt0 <= 0:
        dt0 = float(t[0] - t0) if t0 is not None and t[0] > t0 else 0.0
    ref["dt0"] = dt0
    ref["rate"] = ref["accel"] = -1
    ref["gaps"], ref["max_gap_s"] = 0, 0.0
    if dt0 > 0:
        dts = np.empty(n)
        dts[1:] = d
        dts[0] = (t[0] - t0) if (t0 is not None and t[0] > t0) else dt0
        ref["rate"] = first(np.einsum("ij,ij->i", dth, dth) > np.square(RATE * dts))
        ref["accel"] = first(np.einsum("ij,ij->i", dv, dv) > np.square(ACCEL * dts))
        gaps = np.flatnonzero(dts[1:] > GAP * dt0) + 1
        ref["gaps"] = int(gaps.size)
        ref["max_gap_s"] = float(dts[gaps].max()) if gaps.size else 0.0
    return ref


def _scan(t, dth, dv, t0=None):
    return _core.scan_imu(t, dth, dv, np.nan if t0 is None else t0, RATE, ACCEL, GAP)


def _same(t, dth, dv, t0=None):
    got, ref = _scan(t, dth, dv, t0), _reference(t, dth, dv, t0)
    for key, want in ref.items():
        assert got[key] == want, (key, got[key], want)
    np.testing.assert_allclose(got["dv_sum"], dv.sum(axis=0), rtol=1e-12)
    return got


def test_clean_stream_flags_nothing():
    t, dth, dv = _stream()
    s = _same(t, dth, dv, t0=100.0)
    assert s["dt0"] == pytest.approx(0.005)
    assert (s["nonfinite_t"], s["decrease"], s["rate"], s["accel"], s["gaps"]) == (-1, -1, -1, -1, 0)


@pytest.mark.parametrize("k", [0, 1, 777, 1999])
@pytest.mark.parametrize("what", ["t", "dtheta", "dv"])
def test_nonfinite_flagged_at_the_same_sample(k, what):
    t, dth, dv = _stream()
    arr = {"t": t, "dtheta": dth, "dv": dv}[what]
    if what == "t":
        arr[k] = np.nan
    else:
        arr[k, 1] = np.inf
    s = _same(t, dth, dv)
    assert s["nonfinite_" + what] == k
    # a second, later fault does not move the first one
    if what != "t":
        arr[min(k + 5, 1999), 2] = np.nan
        assert _scan(t, dth, dv)["nonfinite_" + what] == k


@pytest.mark.parametrize("k", [1, 500, 1999])
def test_decreasing_and_repeated_times(k):
    t, dth, dv = _stream()
    t2 = t.copy()
    t2[k] = t2[k - 1] - 0.001  # decreases at k
    s = _same(t2, dth, dv)
    assert s["decrease"] == k and s["not_increasing"] == k
    t3 = t.copy()
    t3[k] = t3[k - 1]  # repeated at k
    s = _same(t3, dth, dv)
    assert (s["decrease"], s["not_increasing"], s["repeats"]) == (-1, k, 1)


def test_gap_and_rate_limits():
    t, dth, dv = _stream()
    t[700:] += 0.05  # a 55 ms interval at sample 700
    dth[1200] = [0.0, 0.0, 40.0 * 0.005]  # 40 rad/s over 5 ms
    dv[1500] = [0.0, 0.0, 1200.0 * 0.005]  # 1200 m/s^2
    s = _same(t, dth, dv)
    assert (s["gaps"], s["rate"], s["accel"]) == (1, 1200, 1500)
    assert s["max_gap_s"] == pytest.approx(0.055)
    # the first sample is judged over (t0, t[0]] when t0 is given: 40 rad/s over 5 ms, under the limit over 1 s
    dth[0] = [0.2, 0.0, 0.0]
    assert _same(t, dth, dv, t0=t[0] - 0.005)["rate"] == 0
    assert _same(t, dth, dv, t0=t[0] - 1.0)["rate"] == 1200


@pytest.mark.parametrize("n", [2, 3, 4, 1001, 400_002, 600_001])
def test_nominal_interval_is_numpys_median(n):
    """Odd and even counts of intervals, and the strided subsample above 200k."""
    rng = np.random.default_rng(n)
    t = np.cumsum(rng.uniform(0.004, 0.006, n))
    s = _scan(t, np.zeros((n, 3)), np.zeros((n, 3)))
    assert s["dt0"] == _reference(t, np.zeros((n, 3)), np.zeros((n, 3)))["dt0"]


def test_sanitize_messages_name_the_sample_and_line():
    t, dth, dv = _stream()
    origin = RowOrigin("imu.txt", 1, None)
    dth[321, 0] = np.nan
    with pytest.raises(ValueError, match=r"imu\.txt:322 \(sample 321\): non-finite dtheta_b"):
        sanitize_imu(ImuData(t, dth, dv, origin=origin))
    dth[321, 0] = 0.0
    t2 = t.copy()
    t2[900] = t2[898]
    with pytest.raises(ValueError, match=r"imu\.txt:901 \(sample 900\): time .* decreases \(previous sample "
                                         r"imu\.txt:900 \(sample 899\)"):
        sanitize_imu(ImuData(t2, dth, dv, origin=origin))
    dv[1500] = [0.0, 0.0, 1200.0 * 0.005]
    with pytest.raises(ValueError, match=r"imu: sample 1500: specific force \|dv\|/dt = 1200 m/s\^2 exceeds"):
        sanitize_imu(ImuData(t, dth, dv))
    dv[1500] = [0.0, 0.0, -9.8 * 0.005]
    t3 = t.copy()
    t3[1000:] += 1.0
    with pytest.raises(ValueError, match=r"imu: sample 1000: IMU gap of 1\.005 s after t="):
        sanitize_imu(ImuData(t3, dth, dv))


def test_duplicates_dropped_then_rates_over_the_remaining_intervals():
    """A repeated identical record: dropped, and the rate test does not see a zero interval."""
    t, dth, dv = _stream()
    t = np.insert(t, 50, t[49])
    dth, dv = np.insert(dth, 50, dth[49], axis=0), np.insert(dv, 50, dv[49], axis=0)
    out, rep = sanitize_imu(ImuData(t, dth, dv))
    assert rep["imu_duplicates_dropped"] == 1 and len(out.t) == 2000


def test_run_checks_name_the_sample():
    """imu_arrays (sanitize off): the finite and increasing checks' messages, from the scan."""
    import insnav

    ds = insnav.simulate("seed000-sim", seed=1)
    imu = ds.imu
    t, dth, dv = imu.t.copy(), imu.dtheta_b.copy(), imu.dv_b.copy()
    dv[4321, 2] = np.nan
    import dataclasses

    bad = dataclasses.replace(ds, imu=ImuData(t, dth, dv))
    with pytest.raises(ValueError, match=r"imu\.dv_b: non-finite value at sample 4321"):
        insnav.run(bad, sanitize=False, checks=False)
    dv[4321, 2] = imu.dv_b[4321, 2]
    t[2345] = t[2344]
    bad = dataclasses.replace(ds, imu=ImuData(t, dth, dv))
    with pytest.raises(ValueError, match=r"imu\.t: time not strictly increasing at sample 2345"):
        insnav.run(bad, sanitize=False, checks=False)


def test_rotation_about_at_is_interp_of_the_cumulative_sum():
    t, dth, dv = _stream()
    axis = np.array([0.1, -0.2, 0.97])
    axis /= np.linalg.norm(axis)
    tt = np.concatenate([[t[0] - (t[1] - t[0])], t])
    cum = np.concatenate([[0.0], np.cumsum(dth @ axis)])
    rng = np.random.default_rng(5)
    q = np.concatenate([rng.uniform(t[0] - 0.01, t[-1] + 0.01, 300), t[[0, 10, -1]], tt[:1], [t[0] - 1.0]])
    rng.shuffle(q)
    got = _core.rotation_about_at(t, dth, axis, q)
    want = np.interp(q, tt, cum, left=np.nan, right=np.nan)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    assert np.isnan(want).sum() >= 2
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_scan_memo_reads_each_stream_once():
    t, dth, dv = _stream()
    assert scan_imu(t, dth, dv) is not scan_imu(t, dth, dv)
    with scan_memo():
        a = scan_imu(t, dth, dv, t0=100.0, max_rate_rps=RATE, max_accel_mps2=ACCEL, gap_factor=GAP)
        assert scan_imu(t, dth, dv) is a  # the limit-free entries of the same arrays
        assert scan_imu(t, dth, dv, t0=99.0, max_rate_rps=RATE, max_accel_mps2=ACCEL, gap_factor=GAP) is not a
        t2 = t.copy()
        t2[5] = np.nan
        assert scan_imu(t2, dth, dv)["nonfinite_t"] == 5  # other memory, another scan
    assert scan_imu(t, dth, dv) is not a


@pytest.mark.parametrize("n", [1, 2, 3, 10, 11, 50_001])
def test_median_is_numpys_without_numpy_ma(n):
    from insnav._median import median

    rng = np.random.default_rng(n)
    x = rng.normal(size=n)
    assert median(x) == float(np.median(x))
    x[n // 3] = np.nan
    assert np.isnan(median(x)) and np.isnan(median([]))
    import subprocess
    import sys

    if n == 1:  # the run path's medians leave numpy.ma unimported
        code = "import sys, numpy as np; from insnav._median import median; median(np.arange(5.)); " \
               "print('numpy.ma' in sys.modules)"
        assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip() == "False"


def test_nav_rows_to_degrees_is_the_numpy_conversion_bit_for_bit():
    from insnav.units import RAD2DEG

    rng = np.random.default_rng(7)
    n = 1001
    llh, rpy, sig, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.random((n, 15)), rng.normal(size=(n, 3))
    want_llh, want_rpy, want_sig = llh.copy(), rpy * RAD2DEG, sig.copy()
    want_llh[:, :2] *= RAD2DEG
    want_sig[:, 6:9] *= RAD2DEG
    assert _core.nav_rows_to_degrees(llh, rpy, sig, 6, v) == (-1, False)
    for got, want in ((llh, want_llh), (rpy, want_rpy), (sig, want_sig)):
        np.testing.assert_array_equal(got, want)
    # the first row raise_if_nonfinite names: non-finite latitude, or no finite velocity component
    v[300, 1] = np.nan  # one component: not that row, but still non-finite
    assert _core.nav_rows_to_degrees(llh, rpy, sig, 6, v) == (-1, True)
    v[500] = np.nan
    llh[700, 0] = np.inf
    assert _core.nav_rows_to_degrees(llh, rpy, sig, 6, v) == (500, True)
    with pytest.raises(ValueError, match="writeable"):
        _core.nav_rows_to_degrees(llh[:10], rpy, sig, 6, v)


def test_a_diverging_run_names_its_row():
    """raise_if_nonfinite's message after the compiled conversion pass."""
    import dataclasses

    import insnav

    ds = insnav.simulate("seed000-sim", seed=1)
    imu = ds.imu
    dv = imu.dv_b.copy()
    dv[6000:, 2] *= 1e12  # absurd forces after 30 s: the run leaves the finite numbers
    bad = dataclasses.replace(ds, imu=ImuData(imu.t, imu.dtheta_b, dv))
    with pytest.raises(FloatingPointError, match=r"ekf: the solution became non-finite at t=\d+\.\d{3} s \(row \d+\)"):
        insnav.run(bad, sanitize=False, checks=False)
