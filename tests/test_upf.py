"""Seed 004 filters: routing through insnav.run, determinism for a seed, and
short closed-loop runs of the UKF / fading UKF / UPF / PF on the seed004-uav
preset (truncated to keep the test fast): the UPF (a weighted bank of UKFs)
equals the UKF when its particles cannot differ and is not worse than it when
they do; the bootstrap PF with more particles beats fewer, and its divergence is
reported; the marginalised PF (the default) stays within metres after the
outage where the bootstrap PF does not; a non-Gaussian (uniform heading)
start is where the UPF wins."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import insnav
from insnav.analysis import errors, rms
from insnav.config import ConfigError, RunConfig
from insnav.data.dataset import ImuData
from insnav.filters.particle import DEFAULT_ALPHA, run_tight_particle


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


def test_upf_without_diversity_is_the_ukf(ds):
    """kernel_h2 = 0: every particle is the same Gaussian, so the mixture is
    the UKF exactly, whatever N (seed 004 reduced to the UKF; the 1-particle
    reduction is in cpp/tests/test_upf.cpp)."""
    cfg = RunConfig(filter="fukf", init_seed=1, output_decimation=20)
    ukf = run_tight_particle(ds, cfg, fading=False)
    upf = run_tight_particle(ds, dataclasses.replace(cfg, filter="upf"), particles=5, kernel_h2=0.0, fading=False)
    np.testing.assert_allclose(upf.lat_deg, ukf.lat_deg, rtol=0, atol=1e-12)
    np.testing.assert_allclose(upf.v_n, ukf.v_n, rtol=0, atol=1e-9)
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
    with pytest.warns(RuntimeWarning, match="no particle"):  # 20 particles in 20 dimensions lose the cloud
        p = run_tight_particle(ds, RunConfig(filter="pf", init_seed=2, output_decimation=20), particles=20, seed=4,
                               marginalize=False)
        q = run_tight_particle(ds, RunConfig(filter="pf", init_seed=2, output_decimation=20), particles=20, seed=4,
                               marginalize=False)
    np.testing.assert_array_equal(p.lat_deg, q.lat_deg)
    m = [run_tight_particle(ds, RunConfig(filter="pf", init_seed=2, output_decimation=20), particles=20, seed=s)
         for s in (4, 4, 5)]
    np.testing.assert_array_equal(m[0].lat_deg, m[1].lat_deg)
    assert not np.array_equal(m[0].lat_deg, m[2].lat_deg)


def test_short_runs_accuracy(ds):
    """120-240 s position/velocity RMS per axis (measured, 4 satellites:
    UKF 1.2/1.5/2.5 m, UPF(20) 1.3/1.6/2.5 m, fading UKF 3.7/3.8/8.7 m, PF(20)
    46/32/32 m with 27 divergent epochs, PF(1000) 2.4/1.8/4.4 m).  The UPF may
    not lose to its own UKF by more than 20 %; the bootstrap PF with 1000
    particles must beat 20 particles by 5x and stay within 3x the UKF.  (The
    marginalised PF, insnav's default: test_marginalised_pf_after_outage.)"""
    cfg = RunConfig(init_seed=1, output_decimation=10)
    ukf = run_tight_particle(ds, dataclasses.replace(cfg, filter="fukf"), fading=False)
    fukf = run_tight_particle(ds, dataclasses.replace(cfg, filter="fukf"))
    upf = run_tight_particle(ds, dataclasses.replace(cfg, filter="upf"), particles=20, seed=1, fading=False)
    res = {}
    for name, sol, pos_tol, vel_tol in (("ukf", ukf, 4.0, 0.06), ("fukf", fukf, 12.0, 0.1), ("upf", upf, 4.0, 0.06)):
        p, v = _err(sol, ds)
        res[name] = np.linalg.norm(p)
        assert np.all(p < pos_tol), (name, p)
        assert np.all(v < vel_tol), (name, v)
    assert res["upf"] <= 1.2 * res["ukf"], res
    pf_err = {}
    for n in (20, 1000):
        with pytest.warns(RuntimeWarning) if n == 20 else _no_warning():
            pf = run_tight_particle(ds, dataclasses.replace(cfg, filter="pf"), particles=n, seed=1, reseed=False,
                                    marginalize=False)
        pf_err[n] = np.linalg.norm(_err(pf, ds)[0])
        assert pf.summary["resamples"] > 0
    assert pf_err[1000] < 0.2 * pf_err[20], pf_err
    assert pf_err[1000] < 3 * res["ukf"], pf_err
    # the UKF never fades; N_eff within (0, N]; traces only where updates applied
    assert np.all(ukf.eta_max[np.isfinite(ukf.eta_max)] == 1.0)
    ok = np.isfinite(upf.ess)
    assert ok.sum() == upf.summary["updates"]
    assert np.all((upf.ess[ok] > 0) & (upf.ess[ok] <= 20 + 1e-9))
    assert np.all(np.isnan(upf.ess[upf.gnss_status != 1]))


class _no_warning:
    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("error", RuntimeWarning)

    def __exit__(self, *a):
        return self._w.__exit__(*a)


def test_pf_divergence_is_reported_and_reset(ds):
    """A bootstrap PF whose cloud cannot hold the solution (no noise floor, no
    progressive correction, 10 particles) is reported, not silent: without
    sensor resetting 228 divergent epochs and 1047/1186 m N/E RMS (120-240 s);
    with it (the default, particle_filter.hpp) every divergent epoch resets the
    cloud from the measurement: 29 divergent epochs, 16/16 m N/E RMS."""
    cfg = RunConfig(filter="pf", init_seed=1, output_decimation=20)
    with pytest.warns(RuntimeWarning, match="no particle explained"):
        plain = run_tight_particle(ds, cfg, particles=10, seed=1, noise_floor=0.0, temper_stages=1, reseed=False,
                                   marginalize=False)
    assert plain.summary["divergences"] > 100 and plain.summary["reseeds"] == 0
    with pytest.warns(RuntimeWarning, match="reset from the measurement"):
        reset = run_tight_particle(ds, cfg, particles=10, seed=1, noise_floor=0.0, temper_stages=1,
                                   marginalize=False)
    s = reset.summary
    assert 0 < s["reseeds"] == s["divergences"] < plain.summary["divergences"] / 4
    p_plain, p_reset = _err(plain, ds)[0], _err(reset, ds)[0]
    assert np.all(p_reset[:2] < p_plain[:2] / 20) and np.all(p_reset < 60.0), (p_plain, p_reset)


def test_marginalised_pf_after_outage(ds_full):
    """GPS off 600-800 s, run to 880 s, 300 particles, the error after 805 s
    (measured: 3-D position max 12.8 m, velocity 0.085 m/s, whole-run yaw RMS
    10 arcmin, no divergent epoch).  The marginalised PF (the default,
    particle_filter.hpp) stays within the bounds the bootstrap PF (557 m,
    2.75 m/s, 179 arcmin, 81 divergent epochs) and its sensor-resetting
    variant (19 m, 0.19 m/s, 179 arcmin) miss; its output sigma includes the
    shared Kalman covariance of the linear substate."""
    d = _truncate(ds_full, 880.0)
    cfg = RunConfig(filter="pf", init_seed=1, output_decimation=20)

    def after(sol):
        e = errors(sol, d.truth)
        a = e["t"] >= 805.0
        return (np.linalg.norm(e["pos_n_m"][a], axis=1).max(), np.linalg.norm(e["vel_n_mps"][a], axis=1).max(),
                np.sqrt(np.mean(e["att_deg"][:, 2] ** 2)) * 60.0)

    mpf = run_tight_particle(d, cfg, particles=300, seed=1)
    assert mpf.summary["marginalize"] and mpf.summary["divergences"] == 0
    with pytest.warns(RuntimeWarning, match="no particle"):
        boot = run_tight_particle(d, cfg, particles=300, seed=1, marginalize=False, reseed=False)
    pos, vel, yaw = after(mpf)
    b_pos, b_vel, b_yaw = after(boot)
    assert pos < 25.0 and vel < 0.15 and yaw < 30.0, (pos, vel, yaw)
    assert b_pos > 4 * 25.0 and b_vel > 0.15 and b_yaw > 30.0, (b_pos, b_vel, b_yaw)
    # the reported sigma covers the error (the bootstrap cloud's alone would not hold P_s)
    e = errors(mpf, d.truth)
    late = (e["t"] > 820.0)
    sig = np.array([np.interp(e["t"][late], mpf.t, mpf.sigma_pos_n_m[:, i]) for i in range(3)]).T
    assert np.sqrt(np.mean((e["pos_n_m"][late] / sig) ** 2)) < 2.0


def test_upf_wins_from_an_unknown_heading(ds):
    """A non-Gaussian start: the heading is unknown (the filter starts 120 deg
    off).  The UKF's Gaussian yaw prior (sigma 104 deg, the same variance as a
    uniform +-180 deg) linearises badly; the UPF's particles, stratified over
    +-180 deg, keep the mixture and weigh the right heading up.  Measured yaw
    error 100-240 s: UPF(36) < 2 deg, UKF tens of degrees."""
    from insnav.data.nav import NavState

    s0 = ds.initial
    d = dataclasses.replace(ds, initial=NavState(s0.lat_deg, s0.lon_deg, s0.h_m, s0.v_n, s0.roll_deg,
                                                 s0.pitch_deg, (s0.yaw_deg + 120.0 + 180.0) % 360.0 - 180.0))
    cfg = RunConfig(filter="fukf", init_error=False, init_sigma_att_deg=[0.5, 0.5, 104.0], output_decimation=20)
    ukf = run_tight_particle(d, cfg, fading=False)
    upf = run_tight_particle(d, dataclasses.replace(cfg, filter="upf"), particles=36, fading=False,
                             init_yaw_uniform_deg=180.0)
    yaw = {}
    for name, sol in (("ukf", ukf), ("upf", upf)):
        e = errors(sol, ds.truth)
        late = e["t"] > 100.0
        yaw[name] = float(np.sqrt(np.mean(e["att_deg"][late, 2] ** 2)))
    assert yaw["upf"] < 2.0 and yaw["upf"] < 0.2 * yaw["ukf"], yaw


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


def test_fading_memory_after_outage(ds_full):
    """The first epoch after the outage (800 s) has a large innovation that the
    grown covariance predicts: neither memory fades there (c_k < 1).  Seed 004
    eq. (6) keeps that innovation in C_0, so the next epoch, whose P the first
    update shrank, fades although its NIS is normal; the NIS memory
    (``fading_memory="nis"``, fading.hpp) does not fade those epochs."""
    d = _truncate(ds_full, 820.0)
    cfg = RunConfig(filter="fukf", init_seed=1, output_decimation=50)
    eq6 = run_tight_particle(d, cfg)
    nis = run_tight_particle(d, cfg, fading_memory="nis")
    t = eq6.gnss_t
    first = np.flatnonzero(t >= 800.0)[0]
    assert eq6.fading_c[first] < 1.0 and nis.fading_c[first] < 1.0
    nxt = slice(first + 1, first + 4)
    assert np.all(eq6.nis[nxt] < 16.0)  # normal innovations (8 rows, chi-square 99 %: 20)
    assert eq6.fading_c[first + 1] > 3.0, eq6.fading_c[nxt]
    assert np.all(nis.fading_c[nxt] < 1.0), nis.fading_c[nxt]
    with pytest.raises(ValueError, match="fading_memory"):
        run_tight_particle(d, cfg, fading_memory="window")


def test_particle_filters_read_the_initial_bias_keys_and_sigma_factors(ds):
    """The seed 004 filters take the run config's initial IMU biases (the first row, before any
    update, holds them exactly) and insnav tune's pseudorange / rate sigma factors (the run equals
    the default run on rows whose sigma columns were multiplied by them: exact reduction)."""
    short = _truncate(ds, 60.0)
    kw = dict(filter="fukf", coupling="tight", init_seed=1, output_decimation=20)
    plain = insnav.run(short, **kw)
    biased = insnav.run(short, **kw, init_acc_bias_mps2=[0.05, -0.05, 0.05],
                        init_gyro_bias_radps=[1e-3, 1e-3, -1e-3], init_sigma_acc_bias_mps2=[0.2] * 3)
    np.testing.assert_allclose(plain.acc_bias_mps2[0], 0.0, atol=0)
    np.testing.assert_allclose(biased.acc_bias_mps2[0], [0.05, -0.05, 0.05], rtol=1e-12)
    np.testing.assert_allclose(biased.gyro_bias_rps[0], [1e-3, 1e-3, -1e-3], rtol=1e-12)
    assert np.max(np.abs(biased.lat_deg - plain.lat_deg)) > 1e-7
    from insnav.filters._setup import tight_inputs_for

    inp = tight_inputs_for(short, elevation_mask_deg=10.0, max_sats=12)
    sats = np.array(inp.sats)
    sats[:, 10] *= 3.0
    sats[:, 11] *= 2.0
    scaled = insnav.run(short, **kw, gnss_pos_sigma_scale=3.0, gnss_vel_sigma_scale=2.0)
    ref = insnav.run(short, **kw, inputs=dataclasses.replace(inp, sats=sats))
    np.testing.assert_allclose(scaled.lat_deg, ref.lat_deg, rtol=0, atol=1e-13)
    assert np.max(np.abs(scaled.lat_deg - plain.lat_deg)) > 1e-6
    # the rows exist already: an elevation mask or satellite limit of their own would be ignored, refused
    with pytest.raises(ConfigError, match="option 'elevation_mask_deg' = 15.0 builds the rows of a simulated"):
        insnav.run(short, **kw, inputs=inp, elevation_mask_deg=15.0)


@pytest.mark.parametrize("opt, match", [
    ({"particles": 2.7}, r"option 'particles' = 2.7: allowed: a whole number >= 0 \(default 100\)"),
    ({"seed": -1}, r"option 'seed' = -1: allowed: a whole number >= 0"),
    ({"init_sigma_clock": [-30.0, 1.0]}, r"option 'init_sigma_clock' = \[-30.0, 1.0\]: allowed: 2 finite numbers >= 0"),
    ({"init_sigma_clock": [30.0]}, r"option 'init_sigma_clock' = \[30.0\]: allowed: 2 finite numbers"),
    ({"reseed": 1}, r"option 'reseed' = 1: allowed: true or false"),
    ({"rho": float("nan")}, r"option 'rho' = nan: allowed: a finite number"),
    ({"clock_psd": [1.0]}, r"option 'clock_psd' = \[1.0\]: allowed: 2 numbers >= 0, the clock bias and drift"),
])
def test_options_of_another_kind_than_the_default_are_refused(ds, opt, match):
    """particles = 2.7 would run 2 particles and write 2.7 into the resolved config: refused, as is a
    negative sigma (squared into a positive one) or a tuple of the wrong length."""
    with pytest.raises(ConfigError, match=match):
        insnav.run(ds, filter="upf", coupling="tight", **opt)


@pytest.mark.parametrize("filt, coupling, n", [("ukf", "loose", 15), ("fukf", "tight", 20)])
def test_a_ut_without_positive_spread_is_refused(ds, filt, coupling, n):
    """alpha^2 (n + kappa) <= 0 has no square root of (n + lambda) P: the run failed at its first
    step as a non-finite solution; the UT's weights refuse it, naming the parameters and n."""
    data = ds if coupling == "tight" else insnav.simulate("seed000-sim", seed=1)
    with pytest.raises(ValueError, match=rf"ut_kappa = -{n + 5}\.0+, ut_alpha = 1\.0+: the unscented transform "
                                         rf"needs alpha\^2 \(n \+ kappa\) > 0 \(n = {n} sigma-point"):
        insnav.run(data, filt, coupling, ut_kappa=-(n + 5.0))
    assert insnav.run(_truncate(ds, 20.0), "fukf", "tight", ut_kappa=1.0 - 20.0).summary["updates"] > 0
