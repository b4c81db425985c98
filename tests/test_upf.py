"""Seed 004 filters (issue 7): routing through insnav.run, determinism for a
seed, and short closed-loop runs of the UKF / fading UKF / UPF / PF on the
seed004-uav preset (truncated to keep the test fast)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import insnav
from insnav.analysis import errors, rms
from insnav.config import ConfigError, RunConfig
from insnav.dataset import ImuData
from insnav.particle import DEFAULT_ALPHA, PARTICLE_FILTERS, run_tight_particle


@pytest.fixture(scope="module")
def ds_full():
    return insnav.simulate("seed004-uav", seed=3)


def _truncate(ds, t_end):
    """The dataset up to t_end (IMU and raw GNSS)."""
    k = np.searchsorted(ds.imu.t, t_end, side="right")
    imu = ImuData(t=ds.imu.t[:k], dtheta_b=ds.imu.dtheta_b[:k], dv_b=ds.imu.dv_b[:k])
    raw = ds.gnss_raw
    keep = raw.t <= t_end
    fields = {f.name: (getattr(raw, f.name)[keep] if isinstance(getattr(raw, f.name), np.ndarray)
                       and np.shape(getattr(raw, f.name))[:1] == keep.shape else getattr(raw, f.name))
              for f in dataclasses.fields(raw)}
    return dataclasses.replace(ds, imu=imu, gnss_raw=type(raw)(**fields))


@pytest.fixture(scope="module")
def ds(ds_full):
    return _truncate(ds_full, 240.0)


def _err(sol, ds):
    e = errors(sol, ds.truth)
    late = e["t"] > 120.0
    return rms(e["pos_n_m"][late]), rms(e["vel_n_mps"][late])


def test_filters_registered():
    from insnav.config import FILTERS

    assert set(PARTICLE_FILTERS) <= set(FILTERS)
    assert DEFAULT_ALPHA.shape == (20,)


def test_run_routes_and_validates(ds):
    sol = insnav.run(ds, filter="upf", coupling="tight", particles=8, seed=5, init_seed=1, output_decimation=10)
    assert sol.summary["filter"] == "upf" and sol.summary["layout"] == 20 and sol.summary["particles"] == 8
    assert sol.summary["updates"] > 200
    assert sol.sigma_clock.shape[1] == 2
    with pytest.raises(ValueError, match="tight"):
        insnav.run(ds, filter="upf", coupling="loose")
    with pytest.raises(TypeError):
        insnav.run(ds, filter="ekf", coupling="tight", particles=10)
    with pytest.raises(ValueError, match="particles"):
        run_tight_particle(ds, RunConfig(filter="upf"), particles=0)
    with pytest.raises(ValueError, match="rho"):
        run_tight_particle(ds, RunConfig(filter="upf"), particles=4, rho=1.5)
    with pytest.raises(ConfigError):
        run_tight_particle(ds, RunConfig(filter="upf", init_sigma_pos_m=[0, 1, 1]), particles=4)


def test_deterministic_for_a_seed(ds):
    cfg = RunConfig(filter="upf", init_seed=2, output_decimation=20)
    a = run_tight_particle(ds, cfg, particles=6, seed=11)
    b = run_tight_particle(ds, cfg, particles=6, seed=11)
    c = run_tight_particle(ds, cfg, particles=6, seed=12)
    np.testing.assert_array_equal(a.lat_deg, b.lat_deg)
    np.testing.assert_array_equal(a.v_n, b.v_n)
    np.testing.assert_array_equal(a.ess, b.ess)
    assert not np.array_equal(a.lat_deg, c.lat_deg)
    p = run_tight_particle(ds, RunConfig(filter="pf", init_seed=2, output_decimation=20), particles=20, seed=4)
    q = run_tight_particle(ds, RunConfig(filter="pf", init_seed=2, output_decimation=20), particles=20, seed=4)
    np.testing.assert_array_equal(p.lat_deg, q.lat_deg)


def test_short_runs_accuracy(ds):
    cfg = RunConfig(init_seed=1, output_decimation=10)
    ukf = run_tight_particle(ds, dataclasses.replace(cfg, filter="fukf"), fading=False)
    fukf = run_tight_particle(ds, dataclasses.replace(cfg, filter="fukf"))
    upf = run_tight_particle(ds, dataclasses.replace(cfg, filter="upf"), particles=20, seed=1)
    pf = run_tight_particle(ds, dataclasses.replace(cfg, filter="pf"), particles=100, seed=1)
    for name, sol, pos_tol, vel_tol in (("ukf", ukf, 6.0, 0.1), ("fukf", fukf, 6.0, 0.1), ("upf", upf, 15.0, 0.3),
                                        ("pf", pf, 1e4, 50.0)):
        p, v = _err(sol, ds)
        print(name, "pos rms 120-240 s", p.round(2), "vel rms", v.round(3))
        # regression bounds at the levels measured (seed004.md): the UKF is the most accurate
        # filter here; the bootstrap PF with 100 particles in 20 dimensions degenerates
        assert np.all(p < pos_tol), (name, p)
        assert np.all(v < vel_tol), (name, v)
    # the UKF never fades; N_eff within (0, N]; traces only where updates applied
    assert np.all(ukf.eta_max[np.isfinite(ukf.eta_max)] == 1.0)
    ok = np.isfinite(upf.ess)
    assert ok.sum() == upf.summary["updates"]
    assert np.all((upf.ess[ok] > 0) & (upf.ess[ok] <= 20 + 1e-9))
    assert np.all(np.isnan(upf.ess[upf.gnss_status != 1]))
    assert pf.summary["resamples"] > 0


def test_fading_reacts_to_outage(ds_full):
    """GPS off 600-800 s: the fading UKF's factors rise right after 800 s."""
    d = _truncate(ds_full, 860.0)
    sol = run_tight_particle(d, RunConfig(filter="fukf", init_seed=1, output_decimation=50))
    t = sol.gnss_t
    after = (t >= 800) & (t < 806)
    steady = (t > 300) & (t < 600)
    assert np.nanmax(sol.eta_max[after]) > 1.0
    assert np.nanmean(sol.eta_max[steady] > 1.0) < 0.2
    e = errors(sol, d.truth)
    late = e["t"] > 840
    assert np.all(np.abs(e["pos_n_m"][late]) < 15.0)
