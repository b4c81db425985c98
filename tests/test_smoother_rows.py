"""The smoothed output rows (``_core.smooth_rows``, ``filters/smoothing.py``)
against the plain formula they implement, written out in numpy: the error
interpolated linearly between the epochs' smoothed errors, position and
velocity subtracted, ``C_nb <- dcm(psi) C_nb`` for the attitude with full
``atan2`` for the Euler angles, sigmas interpolated."""
from __future__ import annotations

import numpy as np
import pytest

import insnav
import insnav.filters.loose as loose_mod
from insnav import _core
from insnav.config import RunConfig
from insnav.earth import radii
from insnav.units import DEG, RAD2DEG


def _dcm(rpy):
    """C_nb (k, 3, 3) of roll, pitch, yaw [rad] (k, 3), ZYX."""
    r, p, y = rpy.T
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack([np.stack([cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy], -1),
                     np.stack([cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy], -1),
                     np.stack([-sp, sr * cp, cr * cp], -1)], -2)


def reference_rows(t, rows, te, s, s_end, sig_e):
    """The smoothed rows by the plain formula (numpy; every row before the last epoch).

    ``rows``: lat_deg, lon_deg, h_m, v_n (n, 3), roll_deg, pitch_deg, yaw_deg; ``s``, ``s_end``,
    ``sig_e`` (E, 9) per epoch: the correction after / just before the epoch's feedback and the
    sigmas.  Returns the corrected rows and the (n, 9) sigmas.
    """
    k = np.clip(np.searchsorted(te, t, side="left") - 1, 0, len(te) - 2)  # te[k] < t <= te[k + 1]
    t0, t1 = te[k], te[k + 1]
    w = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)[:, None]
    end = np.where((t > t1 - 1e-9)[:, None], s[k + 1], s_end[k + 1])
    x = (1.0 - w) * s[k] + w * end
    sig = (1.0 - w) * sig_e[k] + w * sig_e[k + 1]
    lat, lon, h, v, roll, pitch, yaw = (np.array(a, float) for a in rows)
    R_M, R_N = radii(lat * DEG)
    lat_new = (lat * DEG - x[:, 0] / (R_M + h)) / DEG
    lon_new = lon - x[:, 1] / ((R_N + h) * np.cos(lat * DEG)) / DEG
    C = _dcm(x[:, 6:9]) @ _dcm(np.column_stack([roll, pitch, yaw]) * DEG)
    rpy = np.column_stack([np.arctan2(C[:, 2, 1], C[:, 2, 2]),
                           np.arctan2(-C[:, 2, 0], np.hypot(C[:, 2, 1], C[:, 2, 2])),
                           np.arctan2(C[:, 1, 0], C[:, 0, 0])]) * RAD2DEG
    return [lat_new, lon_new, h + x[:, 2], v - x[:, 3:6], rpy[:, 0], rpy[:, 1], rpy[:, 2]], sig


def _close(new, ref, before, rel=1e-9):
    """|new - ref| within rel of the correction (ref - before), angles wrapped."""
    d = (np.asarray(new) - ref + 180.0) % 360.0 - 180.0
    c = (ref - np.asarray(before) + 180.0) % 360.0 - 180.0
    scale = np.max(np.abs(c))
    assert scale > 0
    assert np.max(np.abs(d)) <= rel * scale, (np.max(np.abs(d)), scale)


def test_kernel_matches_the_plain_formula():
    """Random rows and corrections (attitude corrections up to ~0.05 rad: both the
    small-difference series and the full atan2 fallback), every pose."""
    rng = np.random.default_rng(7)
    n, E = 20_000, 101
    t = np.sort(rng.uniform(0.0, 100.0, n))
    te = np.linspace(0.0, 100.0, E)
    s, s_end = rng.normal(scale=2.0, size=(E, 9)), rng.normal(scale=2.0, size=(E, 9))
    for a in (s, s_end):
        a[:, 6:9] = rng.normal(scale=5e-3, size=(E, 3)) * np.where(rng.uniform(size=(E, 1)) < 0.2, 6.0, 1.0)
    sig = np.abs(rng.normal(size=(E, 9)))
    before = [rng.uniform(-60, 60, n), rng.uniform(-180, 180, n), rng.uniform(-100, 3000, n),
              rng.normal(scale=20.0, size=(n, 3)), rng.uniform(-180, 180, n), rng.uniform(-85, 85, n),
              rng.uniform(-180, 180, n)]
    rows = [a.copy() for a in before]
    sig_out = np.full((n, 9), np.nan)
    _core.smooth_rows(t, *rows, te, s, s_end, sig, sig_out)
    ref, ref_sig = reference_rows(t, before, te, s, s_end, sig)
    for new, r, b in zip(rows, ref, before):
        _close(new, r, b)
    np.testing.assert_allclose(sig_out, ref_sig, rtol=1e-12)


def test_sigma_written_in_place_with_strides():
    """sigma_out may be a column view of a wider array (the loose engine's sigmas): only its columns change."""
    rng = np.random.default_rng(1)
    n, E = 500, 11
    t = np.linspace(0.0, 10.0, n)
    te = np.linspace(0.0, 10.0, E)
    s, s_end, sig = (rng.normal(scale=1e-3, size=(E, 9)) for _ in range(3))
    rows = [np.full(n, 30.0), np.full(n, 114.0), np.full(n, 20.0), np.zeros((n, 3)), np.zeros(n), np.zeros(n),
            np.zeros(n)]
    wide = np.full((n, 12), -1.0)
    _core.smooth_rows(t, *rows, te, s, s_end, np.abs(sig), wide[:, :9])
    contiguous = np.empty((n, 9))
    _core.smooth_rows(t, *[a.copy() for a in rows], te, s, s_end, np.abs(sig), contiguous)
    assert np.array_equal(wide[:, :9], contiguous)
    assert np.all(wide[:, 9:] == -1.0)
    with pytest.raises(TypeError):
        _core.smooth_rows(t, *rows, te, s, s_end, np.abs(sig), wide[:, :9].astype(np.float32))


def test_smoothed_run_matches_the_plain_formula(monkeypatch):
    """A short smoothed loose EKF run: its rows and sigmas are the forward run's corrected by
    the plain formula from the engine's smoother epochs (to 1e-9 of the correction)."""
    ds = insnav.simulate("car-mems-outage30", seed=2)
    ds = ds.slice(0.0, 620.0) if hasattr(ds, "slice") else ds
    kept = {}
    run_loose = loose_mod._core.run_loose

    class Core:
        def __getattr__(self, name):
            if name != "run_loose":
                return getattr(_core, name)

            def run(*a, **k):
                out = run_loose(*a, **k)
                kept.update({key: np.array(v, copy=True) for key, v in out.items() if key.startswith("smooth_")})
                return out
            return run

    monkeypatch.setattr(loose_mod, "_core", Core())
    fwd = insnav.run(ds, config=RunConfig(filter="ekf", init_seed=2))
    sm = insnav.run(ds, config=RunConfig(filter="ekf", init_seed=2, smooth=True))
    te = kept["smooth_t"]
    n_in = int(np.searchsorted(fwd.t, te[-1] + 1e-9, side="right"))
    names = ("lat_deg", "lon_deg", "h_m", "v_n", "roll_deg", "pitch_deg", "yaw_deg")
    before = [np.asarray(getattr(fwd, k))[:n_in] for k in names]
    sig_e = kept["smooth_sigma"][:, :9].copy()
    # the attitude sigmas: of roll, pitch, yaw, Ps's psi block mapped at each epoch's (forward) attitude
    from insnav.filters.smoothing import euler_sigmas_from_psi

    t_f = np.asarray(fwd.t)
    yaw = np.unwrap(np.asarray(fwd.yaw_deg, float), period=360.0)
    sig_e[:, 6:9] = euler_sigmas_from_psi(kept["smooth_P_att"], np.interp(te, t_f, fwd.pitch_deg) * DEG,
                                          np.interp(te, t_f, yaw) * DEG)
    assert np.max(np.abs(sig_e[:, 6:8] / kept["smooth_sigma"][:, 6:8] - 1.0)) > 0.05  # the mapping matters here
    ref, ref_sig = reference_rows(np.asarray(fwd.t)[:n_in], before, te, kept["smooth_d"][:, :9],
                                  kept["smooth_d_end"][:, :9], sig_e)
    for k, r, b in zip(names, ref, before):
        _close(np.asarray(getattr(sm, k))[:n_in], r, b)
        assert np.array_equal(np.asarray(getattr(sm, k))[n_in:], np.asarray(getattr(fwd, k))[n_in:])
    sig = np.column_stack([sm.sigma_pos_n_m, sm.sigma_vel_n_mps, np.asarray(sm.sigma_att_deg) * DEG])
    np.testing.assert_allclose(sig[:n_in], ref_sig, rtol=1e-12)
    fsig = np.column_stack([fwd.sigma_pos_n_m, fwd.sigma_vel_n_mps, fwd.sigma_att_deg])
    assert np.array_equal(np.column_stack([sm.sigma_pos_n_m, sm.sigma_vel_n_mps, sm.sigma_att_deg])[n_in:],
                          fsig[n_in:])


#: sha256 of the rows, sigmas and extra columns of the case below as the row correction computed them before it
#: moved from the binder (cpp/bindings/bind_ins.cpp) into engine/smoothed_rows.hpp (x86-64, this compiler family)
_GOLDEN_SHA256 = "0adda025b5bfcb1265d6ae7cab3f995badb60f626827daa90a0879de1b37008d"
#: rows 0, 17, 39 of lat_deg, lon_deg, h_m, roll_deg, pitch_deg, yaw_deg then
_GOLDEN_ROWS = [[51.49491247516262, -15.20650023588993, 2.259013784788604],
                [144.00997876989766, -121.37228032731778, -65.79471059801757],
                [1102.8146265372175, 514.9139916162742, 559.1715088024745],
                [81.30422742115512, -60.48892611793492, 76.43665636612465],
                [18.84600813016549, -25.528172216552793, 0.032254982614302624],
                [-166.81878447847086, -177.39032462589617, -48.76137045461069]]


def test_rows_identical_to_the_binder_implementation_they_replace():
    """The smoothed rows (clock columns too) equal those of the row correction before it moved into the C++
    core: bit for bit on x86-64 (the same arithmetic in the same order), to 1e-13 elsewhere."""
    import hashlib
    import platform

    rng = np.random.default_rng(11)
    n, E = 40, 5
    t = np.sort(rng.uniform(0.0, 4.0, n))
    te = np.linspace(0.0, 4.0, E)
    s, s_end = rng.normal(scale=2.0, size=(E, 11)), rng.normal(scale=2.0, size=(E, 11))
    for a in (s, s_end):
        a[:, 6:9] = rng.normal(scale=5e-3, size=(E, 3)) * np.where(rng.uniform(size=(E, 1)) < 0.3, 6.0, 1.0)
    sig = np.abs(rng.normal(size=(E, 11)))
    rows = [rng.uniform(-60, 60, n), rng.uniform(-180, 180, n), rng.uniform(-100, 3000, n),
            rng.normal(scale=20.0, size=(n, 3)), rng.uniform(-180, 180, n), rng.uniform(-85, 85, n),
            rng.uniform(-180, 180, n)]
    extra = rng.normal(scale=50.0, size=(n, 2))
    so = np.empty((n, 11))
    _core.smooth_rows(t, *rows, te, s, s_end, sig, so, extra)
    got = [a[[0, 17, 39]] for a in rows[:3] + rows[4:]]
    np.testing.assert_allclose(got, _GOLDEN_ROWS, rtol=1e-13)
    if platform.machine() in ("x86_64", "AMD64"):
        h = hashlib.sha256()
        for a in rows + [so, extra]:
            h.update(np.ascontiguousarray(a).tobytes())
        assert h.hexdigest() == _GOLDEN_SHA256
