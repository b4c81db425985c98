"""The input checks of the block-by-block run (insnav.filters.stream) in
bounded memory: the IMU summed to 10 Hz that ``check_dataset`` sees is kept
at most ``CHECK_MAX_ROWS`` rows (summed further, to 5 Hz, 2.5 Hz, ..., when a
recording is longer), so the checks' state after N blocks is the size it is
after 2N; on the crafted mistakes of tests/test_checks.py and
tests/test_time_offset.py (wrong units, axes and signs, a time-base error,
an IMU/GNSS time offset) the halved record gives the 10 Hz record's verdict
and message (the same words; the numbers those of the coarser sums)."""
from __future__ import annotations

import dataclasses
import functools
import re

import numpy as np
import pytest

import insnav.filters.stream as stream
from insnav.data.checks import DataCheckError, check_dataset, heading_grid_step
from insnav.units import G0


def _feed(c, t, dth, dv, block: int, rng=None):
    i = 0
    while i < len(t):
        m = int(rng.integers(0, 2 * block)) if rng is not None else block
        if m:
            c.add(t[i:i + m], dth[i:i + m], dv[i:i + m])
        i += m
    return c


def test_below_its_limit_the_record_is_the_10_hz_sum_bit_for_bit():
    # a record of at most max_rows rows is the one summed without a limit, value for value (fed in the same
    # blocks: a window cut by a block boundary is summed in two parts)
    rng = np.random.default_rng(7)
    n, k = 20_011, 20
    t = np.arange(1, n + 1) * 0.005
    dth, dv = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    rows = 2 + (n - 2) // k  # the first sample alone, the windows, the incomplete last one
    a = _feed(stream._Coarse(k, max_rows=rows), t, dth, dv, 301, np.random.default_rng(1)).imu("imu")
    b = _feed(stream._Coarse(k, max_rows=10 ** 9), t, dth, dv, 301, np.random.default_rng(1)).imu("imu")
    assert len(a.t) == rows
    for x, y in ((a.t, b.t), (a.dtheta_b, b.dtheta_b), (a.dv_b, b.dv_b)):
        assert np.array_equal(x, y)


@pytest.mark.parametrize("max_rows", [8, 9, 64, 101])
def test_the_record_stays_bounded_and_is_the_sum_over_wider_windows(max_rows):
    # N blocks and 2N blocks: the same bytes, at most max_rows rows (+1 for the incomplete last window);
    # the halved record is the IMU summed over windows of k * merge samples (the first sample alone), as
    # an unbounded record with those windows sums it
    rng = np.random.default_rng(3)
    k, block = 20, 997
    sizes, records = [], []
    for blocks in (40, 80):
        n = blocks * block
        t = np.arange(1, n + 1) * 0.005
        dth, dv = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
        c = _feed(stream._Coarse(k, max_rows=max_rows), t, dth, dv, block, np.random.default_rng(blocks))
        assert c.n <= max_rows
        sizes.append(c.nbytes)
        got = c.imu("imu")
        assert len(got.t) <= max_rows + 1
        assert c.merge > 1 and c.merge & (c.merge - 1) == 0  # halved, a power of two
        ref = _feed(stream._Coarse(k * c.merge, max_rows=10 ** 9), t, dth, dv, block).imu("imu")
        assert np.array_equal(got.t, ref.t)  # each row: its window's last sample's time
        for x, y in ((got.dtheta_b, ref.dtheta_b), (got.dv_b, ref.dv_b)):
            assert np.allclose(x, y, rtol=0, atol=1e-11)
        assert np.allclose(got.dv_b.sum(axis=0), dv.sum(axis=0), rtol=0, atol=1e-9)  # nothing lost
        records.append(c.merge)
    assert sizes[0] == sizes[1] <= (max_rows + 2) * 7 * 8
    assert records[1] >= 2 * records[0] // 2  # twice the samples: the windows as wide or wider


@functools.lru_cache(maxsize=1)
def _car():
    """A car in a city with loose fixes (tests/test_time_offset.py's), ~0.5 s."""
    import insnav.sim as sim

    return sim.simulate("urban-multignss", seed=0)


def _mistakes():
    """(name, dataset): the clean car and the mistakes users make."""
    ds = _car()
    imu, g = ds.imu, ds.gnss
    flu = np.array([1.0, -1.0, -1.0])

    def imu_with(**kw):
        return dataclasses.replace(ds, imu=dataclasses.replace(imu, **kw))

    def imu_shifted(dt_s):
        return dataclasses.replace(ds, imu=dataclasses.replace(imu, t=imu.t + dt_s), t0=ds.t0 + dt_s)

    return [
        ("clean", ds),
        ("dv in g", imu_with(dv_b=imu.dv_b / G0)),
        ("dv in cm/s", imu_with(dv_b=imu.dv_b * 100.0)),
        ("dtheta in degrees", imu_with(dtheta_b=np.degrees(imu.dtheta_b))),
        ("FLU read as FRD", imu_with(dtheta_b=imu.dtheta_b * flu, dv_b=imu.dv_b * flu)),
        ("gyro axes inverted", imu_with(dtheta_b=imu.dtheta_b * flu)),
        ("IMU 1 s early", imu_shifted(-1.0)),
        ("IMU 18 s early (leap seconds)", imu_shifted(-18.0)),
        ("IMU 0.3 s late (accepted)", imu_shifted(0.3)),
        ("GNSS a day late", dataclasses.replace(ds, gnss=dataclasses.replace(g, t_valid=g.t_valid + 86400.0,
                                                                            t_arrival=g.t_arrival + 86400.0))),
    ]


def _verdict(ds, imu, grid_s: float = 0.1):
    try:
        with heading_grid_step(grid_s):  # as the stream checks its record (one heading grid point per row)
            check_dataset(dataclasses.replace(ds, imu=imu))
    except DataCheckError as exc:
        return str(exc)
    return None


def _words(msg):
    """The message without its numbers (the halved record's medians, counts and lags differ in the digits)."""
    return None if msg is None else re.sub(r"[-+]?\d+(\.\d+)?(e[-+]?\d+)?", "#", msg)


@pytest.mark.parametrize("divisor, merge", [(3, 4), (12, 16)])
def test_the_halved_record_gives_the_10_hz_records_verdicts(divisor, merge):
    # the crafted mistakes on the car: check_dataset on the IMU summed to 10 Hz (the stream's checks so far)
    # and on the record halved twice (2.5 Hz, as a 7 h recording's at the default limit of 2^16 rows) and
    # four times (0.625 Hz, rows of 1.6 s: a 24 h recording's): the same verdict, the same words
    ds = _car()
    dt = float(np.median(np.diff(ds.imu.t)))
    k = max(1, int(round(1.0 / (stream.CHECK_RATE_HZ * dt))))
    rows10 = 2 + (len(ds.imu.t) - 2) // k
    raised = []
    for name, d in _mistakes():
        imu = d.imu
        full = _feed(stream._Coarse(k, max_rows=10 ** 9), imu.t, imu.dtheta_b, imu.dv_b, 4093)
        halved = _feed(stream._Coarse(k, max_rows=rows10 // divisor), imu.t, imu.dtheta_b, imu.dv_b, 4093)
        v10, vh = _verdict(d, full.imu("imu")), _verdict(d, halved.imu("imu"), halved.grid_step())
        assert halved.merge == merge and full.merge == 1, name
        assert _words(vh) == _words(v10), (name, v10, vh)
        if name == "clean":  # the heading grid: one point per row of the record, not per 0.1 s of the span
            from insnav.data.checks import _heading_grid, _scanned

            r = halved.imu("imu")
            t, dtheta_b, _, scan = _scanned(r.t, r.dtheta_b, r.dv_b)
            with heading_grid_step(halved.grid_step()):
                _, h, g = _heading_grid(t, dtheta_b, scan)
            assert h == pytest.approx(0.1 * merge) and g.size <= len(r.t) + 1 <= rows10 // divisor + 1
        raised.append((name, v10 is not None))
    assert [n for n, r in raised if not r] == ["clean", "IMU 0.3 s late (accepted)"]


def test_the_whole_file_checks_give_the_same_verdicts():
    # the IMU read whole (200 Hz): the mistakes refused and the clean data passed as on the summed records
    for name, d in _mistakes():
        k = max(1, int(round(1.0 / (stream.CHECK_RATE_HZ * float(np.median(np.diff(d.imu.t)))))))
        rec = _feed(stream._Coarse(k, max_rows=10 ** 9), d.imu.t, d.imu.dtheta_b, d.imu.dv_b, 4093)
        assert (_verdict(d, d.imu) is None) == (_verdict(d, rec.imu("imu")) is None), name
