"""The GNSS end checks (insnav.data.checks.check_gnss, check_gnss_velocity) taken a
block of fixes at a time give the whole record's verdicts and one-line messages
(the first bad fix in file order, counts over every fix, a bad fix on a block
boundary, a jump straddling two blocks), and their temporaries do not grow with
the number of fixes."""
import tracemalloc
from types import SimpleNamespace

import numpy as np
import pytest

from insnav.data.checks import DataCheckError, check_gnss, check_gnss_velocity
from insnav.data.dataset import GnssFixes, RowOrigin

BLOCKS = (1, 2, 7, 64, 1000)  # 1: every pair of fixes straddles two blocks
WHOLE = 1 << 40  # one block: the whole-record path
R_M = 6_371_000.0  # the checks' mean Earth radius [m]


def _track(n: int, v_n=(12.0, -9.0, 0.0), dt_s: float = 1.0, lat0_deg: float = 30.5, lon0_deg: float = 114.3):
    """``n`` fixes of a constant-velocity drive on the checks' sphere (positions and velocities consistent:
    the velocity check's slopes are 1 up to the secant over one interval), on file lines 1..n."""
    t = 1000.0 + dt_s * np.arange(n)
    lat = lat0_deg + np.degrees(v_n[0] * (t - t[0]) / R_M)
    lon = lon0_deg + np.degrees(v_n[1] * (t - t[0]) / (R_M * np.cos(np.radians(lat))))
    v = np.tile(np.asarray(v_n, float), (n, 1))
    sig = np.tile([0.02, 0.02, 0.05], (n, 1))
    return GnssFixes(t, t.copy(), lat, lon, np.full(n, 20.0), v, sig, np.full((n, 3), 0.1),
                     origin=RowOrigin("gnss.txt", 1))


def _with(g, **cols):
    f = {k: np.array(getattr(g, k), copy=True) for k in ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m",
                                                         "v_n", "sigma_pos_n", "sigma_vel_n")}
    f.update(cols)
    return GnssFixes(**f, origin=g.origin)


def _outcome(fn, g, **kw):
    try:
        return "ok", fn(g, **kw)
    except DataCheckError as e:
        return "error", str(e)


def _same(fn, g, **kw):
    """fn's outcome on every block size equals the whole record's; returns it."""
    ref = _outcome(fn, g, block=WHOLE, **kw)
    for b in BLOCKS:
        got = _outcome(fn, g, block=b, **kw)
        assert got[0] == ref[0], (b, got, ref)
        if ref[0] == "error" or ref[1] is None:
            assert got[1] == ref[1], b
        else:
            np.testing.assert_allclose(got[1], ref[1], rtol=1e-12, err_msg=str(b))
    return ref


def test_clean_track_slopes_one():
    g = _track(3000)
    assert _same(check_gnss, g, initial=SimpleNamespace(lat_deg=30.5, lon_deg=114.3)) == ("ok", None)
    kind, slopes = _same(check_gnss_velocity, g)
    assert kind == "ok"
    # north: (R + h) / R = 1 + 3e-6; east: the track keeps cos(latitude) of each fix, 0.2 % off over 36 km
    np.testing.assert_allclose(slopes, [1.0, 1.0], atol=5e-3)


@pytest.mark.parametrize("at", [0, 6, 7, 63, 64, 999, 1000, 2999])
def test_out_of_range_on_a_block_boundary_beats_an_earlier_zero_sigma(at):
    g = _track(3000)
    lat, sig = g.lat_deg.copy(), g.sigma_pos_n.copy()
    lat[at] = 123.0
    sig[[0, 1500]] = 0.0  # earlier sigma errors: the range error is reported (the whole record's order)
    kind, msg = _same(check_gnss, _with(g, lat_deg=lat, sigma_pos_n=sig))
    assert kind == "error" and msg.startswith(f"gnss.txt:{at + 1}: lat_deg/lon_deg = 123.0")


@pytest.mark.parametrize("at", [[5, 64, 2000], [1000, 1001], [2999]])
def test_zero_and_huge_sigmas_counted_over_every_block(at):
    g = _track(3000)
    sig = g.sigma_pos_n.copy()
    sig[at, 1] = 0.0
    kind, msg = _same(check_gnss, _with(g, sigma_pos_n=sig))
    assert kind == "error" and f"gnss.txt:{at[0] + 1}:" in msg and f"({len(at)} of 3000 fixes" in msg
    sig = g.sigma_pos_n.copy()
    sig[at, 2] = 1e6
    kind, msg = _same(check_gnss, _with(g, sigma_pos_n=sig))
    assert kind == "error" and f"gnss.txt:{at[0] + 1}:" in msg and "over 100000 m" in msg


@pytest.mark.parametrize("at", [1, 7, 8, 64, 65, 1000, 2999])
def test_jump_straddling_two_blocks_names_its_line(at):
    g = _track(3000)
    lon = g.lon_deg.copy()
    lon[at:] = -lon[at:]  # the longitude sign flipped from fix ``at`` on
    kind, msg = _same(check_gnss, _with(g, lon_deg=lon))
    assert kind == "error" and msg.startswith(f"gnss.txt:{at + 1}: a jump of ")


def test_fixes_out_of_time_order_are_sorted():
    g = _track(3000)
    t = g.t_valid.copy()
    t[[100, 101]] = t[[101, 100]]  # a delayed record stored in arrival order
    assert _same(check_gnss, _with(g, t_valid=t)) == ("ok", None)
    lon = g.lon_deg.copy()
    lon[2000:] = -lon[2000:]
    kind, msg = _same(check_gnss, _with(g, t_valid=t, lon_deg=lon))
    assert msg.startswith("gnss.txt:2001: a jump of ")
    assert _same(check_gnss_velocity, _with(g, t_valid=t))[0] == "ok"


@pytest.mark.parametrize("change, words", [
    (lambda g: dict(lon_deg=2 * g.lon_deg[0] - g.lon_deg), "the longitude moves opposite"),
    (lambda g: dict(lat_deg=2 * g.lat_deg[0] - g.lat_deg), "the latitude moves opposite"),
    (lambda g: dict(lat_deg=g.lat_deg[0] + np.radians(g.lat_deg - g.lat_deg[0]),
                    lon_deg=g.lon_deg[0] + np.radians(g.lon_deg - g.lon_deg[0])), "radians read as degrees"),
])
def test_velocity_verdicts_and_messages(change, words):
    g = _track(3000)
    kind, msg = _same(check_gnss_velocity, _with(g, **change(g)))
    assert kind == "error" and words in msg and "over 2999 pairs of fixes" in msg


@pytest.mark.slow  # block sizes 1 and 2 of 3000 fixes: about 2.5 s
def test_velocity_too_little_motion_and_gaps():
    g = _track(3000, v_n=(0.2, 0.1, 0.0))  # standing: no pair moves faster than 1 m/s
    assert _same(check_gnss_velocity, g) == ("ok", None)
    g = _track(3000, v_n=(15.0, 0.0, 0.0))  # east: too little motion, a NaN slope
    kind, (sn, se) = _same(check_gnss_velocity, g)
    assert sn == pytest.approx(1.0, abs=1e-5) and np.isnan(se)
    t = g.t_valid.copy()
    t[1500:] += 10.0  # a 11 s gap: that pair is left out
    v = g.v_n.copy()
    v[[7, 64, 65]] = np.nan  # no velocity: the 5 pairs beside them are left out
    kind, msg = _same(check_gnss_velocity, _with(g, t_valid=t, v_n=v, lat_deg=2 * g.lat_deg[0] - g.lat_deg))
    assert "over 2993 pairs of fixes" in msg


def _peak_bytes(n: int, block: int) -> int:
    g = _track(n)
    tracemalloc.start()
    try:
        check_gnss(g, block=block)
        check_gnss_velocity(g, block=block)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow  # tracemalloc on 10^4 and 10^5 fixes: about 3 s
def test_temporaries_do_not_grow_with_the_fixes():
    block = 2048
    small, large = _peak_bytes(10_000, block), _peak_bytes(100_000, block)
    # a few arrays of one block (8 bytes per value, 3 columns at most): far below one column of the record
    assert large < 32 * block * 8 < 100_000 * 8
    assert large <= small + 8 * 1024
    # the whole-record path (one block) holds sorted copies of every column
    assert _peak_bytes(100_000, 1 << 40) > 10 * large
