"""The GNSS sanitizer a block of fixes at a time (``sanitize_gnss_blocks``, the block-by-block run's)
against the whole-record one (``sanitize_gnss``): the same fixes, file lines and report for every block
size, tiny ones and bad records on the block boundaries included."""
from __future__ import annotations

import numpy as np
import pytest

from insnav.data.dataset import GnssFixes, RowOrigin
from insnav.filters import sanitize
from insnav.filters.sanitize import sanitize_gnss, sanitize_gnss_blocks

FIELDS = ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n")
BLOCKS = (1, 2, 3, 7, 64, 4096)


def _fixes(n=200, seed=0, velocity=True, origin="lines"):
    """``n`` fixes at 1 Hz in time order, velocity columns or the compact reader's broadcast NaN rows."""
    rng = np.random.default_rng(seed)
    t = 1000.0 + np.arange(n, dtype=float)
    lat = 30.0 + 1e-5 * rng.standard_normal(n)
    lon = 114.0 + 1e-5 * rng.standard_normal(n)
    h = 20.0 + rng.standard_normal(n)
    sp = np.tile([0.01, 0.01, 0.02], (n, 1))
    if velocity:
        v = rng.standard_normal((n, 3))
        sv = np.tile([0.05, 0.05, 0.1], (n, 1))
    else:
        v = sv = np.broadcast_to(np.full(3, np.nan), (n, 3))
    o = {"lines": RowOrigin("g.txt", 1, 3 + 2 * np.arange(n, dtype=np.int64)),
         "first": RowOrigin("g.txt", 5), "none": None}[origin]
    return GnssFixes(t, t, lat, lon, h, v, sp, sv, origin=o)


def _spoil(g, edits):
    """A copy of ``g`` with ``edits`` (field, row, value) applied."""
    cols = {f: np.array(getattr(g, f), float) for f in FIELDS}
    for f, i, val in edits:
        cols[f][i] = val
    return GnssFixes(**cols, origin=g.origin)


def _same(got, ref):
    (ga, ra), (gb, rb) = got, ref
    assert ra == rb
    assert len(ga) == len(gb)
    for f in FIELDS:
        x, y = np.asarray(getattr(ga, f)), np.asarray(getattr(gb, f))
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert np.array_equal(x, y, equal_nan=True), f
    if gb.origin is None:
        assert ga.origin is None
    else:
        n = len(gb)
        assert ga.origin.source == gb.origin.source
        assert [ga.origin.line(i) for i in range(n)] == [gb.origin.line(i) for i in range(n)]


# every kind of record the sanitizer drops or repairs, on block boundaries of 2, 3, 7 and 64 (rows 63/64,
# 127/128), a run of bad rows across a boundary, duplicates across a boundary and a triple tie
BAD = [("lat_deg", 0, np.nan), ("h_m", 6, 1e6), ("sigma_pos_n", 7, 0.0), ("lon_deg", 63, 400.0),
       ("sigma_pos_n", 64, 2e5), ("t_valid", 20, np.nan), ("v_n", 11, np.nan), ("sigma_vel_n", 13, -1.0),
       ("v_n", 127, 2e4), ("t_valid", 128, 1127.0), ("t_valid", 129, 1127.0), ("t_valid", 150, 1149.0),
       ("h_m", 160, np.inf), ("h_m", 161, np.inf), ("h_m", 162, np.inf), ("lat_deg", 199, -91.0)]


@pytest.mark.parametrize("origin", ["lines", "first", "none"])
@pytest.mark.parametrize("block", BLOCKS)
def test_blockwise_sanitizer_gives_the_whole_records_fixes_and_report(block, origin):
    g = _spoil(_fixes(origin=origin), BAD)
    ref = sanitize_gnss(g)
    got = sanitize_gnss_blocks(g, block=block)
    _same(got, ref)
    rep = ref[1]
    # the counts this record must give (the whole sanitizer is the reference; these pin the case)
    assert rep["gnss_invalid_dropped"] == 10 and rep["gnss_duplicates_dropped"] == 3
    assert rep["gnss_velocity_removed"] == 3 and rep["gnss_records_out"] == 187
    assert len(rep["gnss_dropped_lines"]) == 13


@pytest.mark.parametrize("block", BLOCKS)
def test_blockwise_sanitizer_lists_the_first_20_dropped_lines(block):
    # 40 bad records: the report lists the 20 smallest lines, as the whole sanitizer does
    g = _spoil(_fixes(n=120), [("h_m", i, np.nan) for i in range(1, 120, 3)])
    ref = sanitize_gnss(g)
    _same(sanitize_gnss_blocks(g, block=block), ref)
    assert ref[1]["gnss_dropped_lines"] == [3 + 2 * i for i in range(1, 60, 3)]


@pytest.mark.parametrize("block", BLOCKS)
def test_clean_fixes_come_back_as_the_same_object(block):
    for g in (_fixes(), _fixes(velocity=False)):
        got, rep = sanitize_gnss_blocks(g, block=block)
        assert got is g and rep == sanitize_gnss(g)[1]
        assert rep["gnss_records_out"] == len(g) and rep["gnss_dropped_lines"] == []


@pytest.mark.parametrize("block", BLOCKS)
def test_compact_fixes_without_velocity(block):
    # the compact reader's broadcast (read-only) NaN velocity columns: never written, dropped rows copied out
    g = _fixes(velocity=False)
    g = GnssFixes(g.t_valid, g.t_valid, np.array(g.lat_deg), g.lon_deg, g.h_m, g.v_n, g.sigma_pos_n,
                  g.sigma_vel_n, origin=g.origin)
    g.lat_deg[[5, 6, 64]] = np.nan
    _same(sanitize_gnss_blocks(g, block=block), sanitize_gnss(g))


@pytest.mark.parametrize("block", BLOCKS)
def test_fixes_out_of_time_order_get_the_whole_sanitizers_sort(block):
    # a swap across a block boundary and one inside a block; an invalid fix out of order does not count
    g = _spoil(_fixes(), [("t_valid", 63, 1064.5), ("t_valid", 64, 1063.5), ("t_valid", 100, 1095.0),
                          ("h_m", 30, np.nan)])
    ref = sanitize_gnss(g)
    assert ref[1]["gnss_reordered"] > 0
    _same(sanitize_gnss_blocks(g, block=block), ref)
    g2 = _spoil(_fixes(), [("t_valid", 10, 900.0), ("lat_deg", 10, np.nan)])  # invalid: left out of the order
    ref2 = sanitize_gnss(g2)
    assert ref2[1]["gnss_reordered"] == 0
    _same(sanitize_gnss_blocks(g2, block=block), ref2)


def test_empty_record_and_default_block(monkeypatch):
    g = _fixes(n=0)
    assert sanitize_gnss_blocks(g) == (g, sanitize_gnss(g)[1])
    monkeypatch.setattr(sanitize, "GNSS_SANITIZE_BLOCK", 5)  # the default block read at call time
    g = _spoil(_fixes(), BAD)
    _same(sanitize_gnss_blocks(g), sanitize_gnss(g))


@pytest.mark.parametrize("seed", range(6))
def test_random_records(seed):
    # random bad rows and ties in time order, random block sizes
    rng = np.random.default_rng(100 + seed)
    n = 300
    g = _fixes(n=n, seed=seed, velocity=bool(seed % 2))
    t = np.array(g.t_valid)
    t[rng.choice(np.arange(1, n), 30, replace=False)] -= 1.0  # ties with the fix before (times stay ordered)
    t = np.maximum.accumulate(t)
    edits = [("t_valid", i, t[i]) for i in range(n)]
    for i in rng.choice(n, 25, replace=False):
        f = rng.choice(["lat_deg", "h_m", "sigma_pos_n", "v_n", "sigma_vel_n"])
        edits.append((str(f), int(i), float(rng.choice([np.nan, np.inf, -1.0, 1e9]))))
    g = _spoil(g, edits)
    for block in (1, int(rng.integers(2, 9)), int(rng.integers(9, 200)), n):
        _same(sanitize_gnss_blocks(g, block=block), sanitize_gnss(g))


def test_fixes_given_as_lists():
    # columns as Python lists (a user's GnssFixes): converted once, the same result as the whole sanitizer
    g = _spoil(_fixes(n=40, origin="none"), [("h_m", 3, np.nan), ("t_valid", 9, 1008.0)])
    lists = GnssFixes(*(np.asarray(getattr(g, f)).tolist() for f in FIELDS))
    _same(sanitize_gnss_blocks(lists, block=3), sanitize_gnss(lists))
    assert sanitize_gnss(lists)[1]["gnss_records_out"] == 38
