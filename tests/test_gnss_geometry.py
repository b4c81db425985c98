"""Elevation/azimuth, DOP, best-GDOP selection, Klobuchar and Saastamoinen."""
import itertools

import numpy as np
import pytest

from insnav import earth
from insnav.gnss.corrections import klobuchar_delay, saastamoinen_delay
from insnav.gnss.ephemeris import C_LIGHT
from insnav.gnss.geometry import (
    _select_best_gdop_numpy, dop, dop_from_los_n, elevation_azimuth, elevation_mask, los_unit_n, select_best_gdop,
)


def _u_n(el, az):
    el, az = np.asarray(el, float), np.asarray(az, float)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], -1)


def test_elevation_azimuth_known():
    lat, lon, h = np.deg2rad(48.78), np.deg2rad(9.17), 320.0
    r = earth.geodetic_to_ecef(lat, lon, h)
    C = earth.C_en(lat, lon)
    want = np.deg2rad([[90.0, 0.0], [30.0, 45.0], [5.0, 270.0], [-10.0, 180.0]])
    sats = r + 2.0e7 * (C @ _u_n(want[:, 0], want[:, 1]).T).T
    el, az = elevation_azimuth(r, sats)
    np.testing.assert_allclose(el, want[:, 0], atol=1e-12)
    np.testing.assert_allclose(az[1:], want[1:, 1], atol=1e-12)  # azimuth undefined at zenith
    np.testing.assert_array_equal(elevation_mask(el, np.deg2rad(10)), [True, True, False, False])
    np.testing.assert_allclose(np.linalg.norm(los_unit_n(r, sats), axis=1), 1.0)


@pytest.mark.parametrize("el_ring_deg", [0.0, 30.0])
def test_dop_symmetric_geometry(el_ring_deg):
    """Zenith + 3 satellites at elevation t, azimuths 0/120/240 deg.

    With rows [-u_n, 1]: G^T G = diag(3c^2/2, 3c^2/2) (+) [[1+3s^2, 1+3s], [1+3s, 4]],
    c = cos t, s = sin t, so HDOP^2 = 4/(3c^2), VDOP^2 = 4/(3(1-s)^2),
    TDOP^2 = (1+3s^2)/(3(1-s)^2).  t = 0: HDOP = VDOP = 2/sqrt(3), TDOP = 1/sqrt(3), GDOP = sqrt(3).
    """
    t = np.deg2rad(el_ring_deg)
    u = _u_n([np.pi / 2, t, t, t], np.deg2rad([0, 0, 120, 240]))
    c, s = np.cos(t), np.sin(t)
    hd2, vd2, td2 = 4 / (3 * c * c), 4 / (3 * (1 - s) ** 2), (1 + 3 * s * s) / (3 * (1 - s) ** 2)
    d = dop_from_los_n(u)
    assert d.hdop == pytest.approx(np.sqrt(hd2), rel=1e-12)
    assert d.vdop == pytest.approx(np.sqrt(vd2), rel=1e-12)
    assert d.tdop == pytest.approx(np.sqrt(td2), rel=1e-12)
    assert d.pdop == pytest.approx(np.sqrt(hd2 + vd2), rel=1e-12)
    assert d.gdop == pytest.approx(np.sqrt(hd2 + vd2 + td2), rel=1e-12)
    if el_ring_deg == 0.0:
        assert d.gdop == pytest.approx(np.sqrt(3.0))
    # same through ECEF positions, and singular geometry -> inf
    lat, lon = 0.3, 1.2
    r = earth.geodetic_to_ecef(lat, lon, 0.0)
    sats = r + 2.2e7 * (earth.C_en(lat, lon) @ u.T).T
    assert dop(r, sats).gdop == pytest.approx(d.gdop, rel=1e-9)
    assert np.isinf(dop_from_los_n(_u_n([0.5] * 4, [0, 1, 2, 3])).gdop)  # all on one cone: singular


def _brute(u, n):
    best, arg = np.inf, None
    for c in itertools.combinations(range(len(u)), n):
        G = np.c_[-u[list(c)], np.ones(n)]
        try:
            g = np.sqrt(np.trace(np.linalg.inv(G.T @ G)))
        except np.linalg.LinAlgError:
            continue
        if g < best:
            best, arg = g, c
    return np.array(arg), best


def test_best_gdop_equals_brute_force():
    rng = np.random.default_rng(7)
    for trial in range(30):
        k = rng.integers(5, 11)
        n = rng.integers(4, min(k, 7) + 1)
        u = _u_n(np.arcsin(rng.uniform(0.1, 1.0, k)), rng.uniform(0, 2 * np.pi, k))
        idx, g = select_best_gdop(u, n)
        bidx, bg = _brute(u, n)
        assert g == pytest.approx(bg, rel=1e-9)
        np.testing.assert_array_equal(idx, bidx)
        # greedy fallback: never better than the optimum, close to it
        gi, gg = select_best_gdop(u, n, max_combinations=0)
        assert len(gi) == n and len(set(gi)) == n
        assert bg - 1e-9 <= gg <= 1.5 * bg


@pytest.mark.parametrize("k, n, max_comb", [(8, 5, 5000), (12, 4, 5000), (20, 16, 5000), (22, 16, 5000),
                                            (30, 16, 5000), (10, 6, 0), (6, 4, 5000)])
def test_best_gdop_compiled_equals_numpy_reference(k, n, max_comb):
    """insnav/gnss/gdop_selection.hpp against the numpy reference: the same subset, the same GDOP to rounding,
    in the exhaustive search (chosen or left-out sums) and in the greedy elimination."""
    from insnav import _core

    rng = np.random.default_rng(11 + k + n)
    for _ in range(10):
        u = _u_n(np.arcsin(rng.uniform(0.05, 1.0, k)), rng.uniform(0, 2 * np.pi, k))
        idx_c, g_c = _core.select_best_gdop(u, n, max_comb)
        idx_p, g_p = _select_best_gdop_numpy(u, n, max_comb)
        np.testing.assert_array_equal(idx_c, idx_p)
        assert g_c == pytest.approx(g_p, rel=1e-12)
    # a degenerate subset (four on one cone) is never chosen; all singular: the reference's first subset
    u = _u_n([0.5] * 5 + [1.2], [0, 1, 2, 3, 4, 0.5])
    np.testing.assert_array_equal(_core.select_best_gdop(u, 5, 5000)[0], _select_best_gdop_numpy(u, 5)[0])
    cone = _u_n([0.5] * 6, [0, 1, 2, 3, 4, 5])
    for mc in (5000, 0):
        idx_c, g_c = _core.select_best_gdop(cone, 4, mc)
        idx_p, g_p = _select_best_gdop_numpy(cone, 4, mc)
        np.testing.assert_array_equal(idx_c, idx_p)
        assert np.isinf(g_c) and np.isinf(g_p)


def test_limit_sats_batch_equals_epoch_loop():
    """tight_inputs.limit_sats in one compiled call keeps the rows of the per-epoch numpy selection."""
    from insnav import _core
    from insnav.gnss import tight_inputs as ti

    rng = np.random.default_rng(3)
    r_rx = earth.geodetic_to_ecef(0.8, 0.2, 100.0)
    C = earth.C_en(0.8, 0.2)
    t, prn, sats, el = [], [], [], []
    for e in range(40):
        k = int(rng.integers(3, 24))
        el_e = np.arcsin(rng.uniform(0.1, 1.0, k))
        sats_e = r_rx + 2.2e7 * (C @ _u_n(el_e, rng.uniform(0, 2 * np.pi, k)).T).T
        row = np.zeros((k, 12))
        row[:, 2:5] = sats_e
        t += [float(e)] * k
        prn += list(range(1, k + 1))
        sats.append(row)
        el.append(np.degrees(el_e))
    inp = ti.TightInputs.from_rows(np.array(t), np.array(prn), np.vstack(sats), np.concatenate(el),
                                   info=dict(approx_r_e=r_rx))
    fast = ti.limit_sats(inp, 16)
    saved = ti._core
    ti._core = object()  # no compiled selection: the per-epoch loop through geometry.select_best_gdop
    import insnav.gnss.geometry as geo
    saved_geo, geo._core = geo._core, object()
    try:
        ref = ti.limit_sats(inp, 16)
    finally:
        ti._core, geo._core = saved, saved_geo
    assert fast.n_sats().max() == 16 and len(ref.prn) == len(fast.prn) < len(inp.prn)
    np.testing.assert_array_equal(fast.prn, ref.prn)
    np.testing.assert_array_equal(fast.sats, ref.sats)
    assert _core.GDOP_MAX_SATS >= 24


def test_saastamoinen_zenith_and_mapping():
    z0 = saastamoinen_delay(np.deg2rad(45.0), 0.0, np.pi / 2)
    assert 2.2 < z0 < 2.5  # 2.30 m hydrostatic + 0.12 m wet
    assert z0 == pytest.approx(2.42, abs=0.02)
    dry = saastamoinen_delay(np.deg2rad(45.0), 0.0, np.pi / 2, humidity=0.0)
    assert dry == pytest.approx(0.002277 * 1013.25, rel=1e-6)  # D = 1 at 45 deg, h = 0
    assert saastamoinen_delay(0.8, 2000.0, np.pi / 2) < 0.82 * z0  # ~ 20 % less air at 2 km
    el = np.deg2rad([90, 30, 10])
    d = saastamoinen_delay(0.8, 300.0, el)
    assert d[1] / d[0] == pytest.approx(2.0, rel=0.01) and 5.3 < d[2] / d[0] < 5.8
    assert np.isnan(saastamoinen_delay(0.8, 0.0, -0.1))


def test_klobuchar_reference_and_range():
    """Hand-computed reference (IS-GPS-200 Figure 20-4), at the equator, lon 0, zenith.

    E = 0.5 sc, psi = 0.0137/0.61 - 0.022 = 4.59e-4 sc, phi_i = 4.59e-4, lambda_i = 0,
    local time t = 50400 s (14:00, the peak), alpha = [1e-8, 0, 0, 0] -> AMP = 1e-8 s,
    beta = [1e5, 0, 0, 0] -> PER = 1e5 s, x = 0, F = 1 + 16 (0.03)^3 = 1.000432,
    T = F (5e-9 + 1e-8) = 1.500648e-8 s -> 4.49883 m.
    At t = 50400 + 43200: x = 2 pi 0.432 = 2.71 > 1.57 -> night: F 5e-9 s -> 1.49961 m.
    """
    a, b = [1e-8, 0, 0, 0], [1e5, 0, 0, 0]
    d = klobuchar_delay(np.array([50400.0, 93600.0]), 0.0, 0.0, np.pi / 2, 0.0, a, b)
    assert d[0] == pytest.approx(1.000432 * 15e-9 * C_LIGHT, rel=1e-9)
    assert d[0] == pytest.approx(4.49883, abs=1e-5)
    assert d[1] == pytest.approx(1.000432 * 5e-9 * C_LIGHT, rel=1e-9)
    # physical range with a real broadcast set (brdc1180.21n), random geometry and time
    alpha = [0.9313e-08, 0.1490e-07, -0.5960e-07, -0.1192e-06]
    beta = [0.8806e05, 0.4915e05, -0.1311e06, -0.3277e06]
    rng = np.random.default_rng(3)
    n = 5000
    lat = np.arcsin(rng.uniform(-1, 1, n))
    lon = rng.uniform(-np.pi, np.pi, n)
    el = rng.uniform(np.deg2rad(5), np.pi / 2, n)
    az = rng.uniform(0, 2 * np.pi, n)
    t = rng.uniform(0, 604800.0, n)
    d = klobuchar_delay(t, lat, lon, el, az, alpha, beta)
    night_min = 5e-9 * C_LIGHT  # 1.499 m vertical floor, F >= 1
    assert np.all(d >= night_min * 0.9999) and np.all(d < 3.08 * (5e-9 + 2e-7) * C_LIGHT)
    assert 1.5 < np.median(d) < 30.0
    # at night (local 02:00, |x| > 1.57) the delay is F * 5 ns: the ratio is the obliquity factor
    lo = klobuchar_delay(7200.0, 0.8, 0.0, np.deg2rad(5), 0.0, alpha, beta)
    hi = klobuchar_delay(7200.0, 0.8, 0.0, np.pi / 2, 0.0, alpha, beta)
    assert lo / hi == pytest.approx((1 + 16 * (0.53 - 5 / 180) ** 3) / (1 + 16 * 0.03**3), rel=1e-12)


def test_klobuchar_defaults_stand_in_for_missing_coefficients():
    """A navigation file without Klobuchar coefficients (or with all eight zero) gets RTKLIB's ion_default
    (the GPS broadcast of 2004-01-01, rtkcmn.c) and one InsnavWarning naming the file; broadcast ones are
    kept as they are, without a warning."""
    import types
    import warnings

    from insnav.errors import InsnavWarning
    from insnav.gnss.corrections import KLOBUCHAR_DEFAULT_ALPHA, KLOBUCHAR_DEFAULT_BETA, klobuchar_coefficients

    np.testing.assert_array_equal(KLOBUCHAR_DEFAULT_ALPHA, [0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06])
    np.testing.assert_array_equal(KLOBUCHAR_DEFAULT_BETA, [0.1167e+06, -0.2294e+06, -0.1311e+06, 0.1049e+07])
    for alpha, beta in ((None, None), (np.zeros(4), np.zeros(4)), (np.ones(4), None)):
        nav = types.SimpleNamespace(path="x.nav", ion_alpha=alpha, ion_beta=beta)
        with pytest.warns(InsnavWarning, match=r"^x\.nav: no Klobuchar coefficients"):
            a, b, default = klobuchar_coefficients(nav)
        assert default and np.array_equal(a, KLOBUCHAR_DEFAULT_ALPHA) and np.array_equal(b, KLOBUCHAR_DEFAULT_BETA)
    nav = types.SimpleNamespace(path="y.nav", ion_alpha=[1e-8, 0, 0, 0], ion_beta=[1e5, 0, 0, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a, b, default = klobuchar_coefficients(nav)
    assert not default and a.tolist() == [1e-8, 0, 0, 0] and b.tolist() == [1e5, 0, 0, 0]


def test_klobuchar_defaults_on_real_static_data(shared_data):
    """The static Septentrio rover (known position; Japan, 17:20 local time): a navigation file stripped
    of its coefficients is positioned with the defaults, nearer the broadcast model's solution than with
    no ionosphere at all (measured 3D rms: 9.3 m without, 4.5 m default, 4.3 m broadcast)."""
    import dataclasses
    import warnings

    from insnav.gnss.spp import read_nav_multi, read_obs_multi, solve_spp, spp_inputs_from_rinex
    from insnav.io.rinex_dataset import _approx_position

    d = shared_data / "matrtklib_static_septentrio"
    if not (d / "rover.obs").is_file():
        pytest.skip(f"{d} not found (the static Septentrio pair)")
    lat, lon, h = (float(v) for v in (d / "rover_position.txt").read_text().split()[:3])
    ref = earth.geodetic_to_ecef(np.radians(lat), np.radians(lon), h)
    obs, nav = read_obs_multi(d / "rover.obs", "G"), read_nav_multi([d / "base.nav"], "G")
    t0 = 604800 * int(obs.epoch_week[0])
    r0 = _approx_position(obs, nav, t0)
    bare = dataclasses.replace(nav, ion_alpha=None, ion_beta=None)

    def rms3d(n, **kw):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            inp, _ = spp_inputs_from_rinex(obs, n, t0, r0, **kw)
        sp = solve_spp(inp, r0)
        assert sp.solved.sum() == 301
        return float(np.sqrt(np.mean(np.sum((sp.r_e[sp.solved] - ref) ** 2, axis=1))))

    off, default, broadcast = rms3d(nav, iono=False), rms3d(bare), rms3d(nav)
    assert default < 0.6 * off and broadcast < 0.6 * off
    assert abs(default - broadcast) < 0.15 * broadcast


def test_unique_without_numpy_ma_equals_np_unique():
    """insnav._median.unique (no numpy.ma import; short strings sorted as packed code points) returns what
    np.unique returns: system letters, observation codes with blanks and shorter codes, integers."""
    from insnav._median import unique

    rng = np.random.default_rng(2)
    cases = [("<U1", list("GRECJ")), ("<U3", ["C1C", "C2I", "C1X", "C5Q", "", "C1", "C7I", "Z", "\u00e9a"]),
             ("<U2", ["G1", "", "R", "E5"])]
    for dt, alphabet in cases:
        for n in (0, 1, 5, 65, 5000):
            a = np.array(rng.choice(alphabet, n), dtype=dt)
            u, r = unique(a), np.unique(a)
            assert u.dtype == r.dtype
            np.testing.assert_array_equal(u, r)
    a = rng.integers(-5, 40, 1000)
    np.testing.assert_array_equal(unique(a), np.unique(a))
