"""Delayed GNSS (seed 001): delay statistics, reduction of the
random-delay KF and of the exact engine to the ordinary KF, the three filters
on a high-delay scenario, and the history bound of the exact engine."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import insnav
from insnav.filters.delay import run_delayed, scenario_delay_p

R_EARTH = 6.378e6
#: seed001-low with each fix delayed on its own: with the delays removed, one
#: record per epoch (the paper's one-per-epoch model repeats some fixes)
INDEPENDENT_LOW = {"extends": "seed001-low", "gnss": {"delay_model": "independent"}}


@pytest.fixture(scope="module")
def high():
    return insnav.simulate("seed001-high", seed=11)


def _no_delay(ds):
    d = copy.copy(ds)
    d.gnss = copy.copy(ds.gnss)
    d.gnss.t_arrival = ds.gnss.t_valid.copy()
    return d


def _max_pos_diff_m(a, b):
    return max(np.max(np.abs(a.lat_deg - b.lat_deg)), np.max(np.abs(a.lon_deg - b.lon_deg))) * np.pi / 180 * R_EARTH


def test_delay_statistics(high):
    """Delays are whole epochs distributed as the scenario's p (seed 001 eq. (4))."""
    p = scenario_delay_p(high)
    np.testing.assert_allclose(p, [0.2, 0.4, 0.2, 0.2])
    d = high.gnss.delay_epochs * 10.0  # seconds -> 10 Hz epochs
    k = np.round(d).astype(int)
    np.testing.assert_allclose(d, k, atol=1e-6)
    counts = np.bincount(k, minlength=p.size)
    assert counts.size == p.size
    n = k.size
    sd = np.sqrt(n * p * (1 - p))
    assert np.all(np.abs(counts - n * p) < 4 * sd), (counts, n * p)


def test_rdkf_without_a_scenario_p_takes_the_records_own_delays(high):
    """No delay_p given and none in the scenario: the random-delay KF's p is the
    distribution of the records' delays in receiver epochs (not [1], which would model
    every late record as on time), and the run equals the one given that p."""
    d = copy.copy(high)
    d.scenario = copy.deepcopy(high.scenario)
    del d.scenario["gnss"]["delay_p"]
    k = np.round(high.gnss.delay_epochs * 10.0).astype(int)  # 10 Hz epochs, whole by construction
    want = np.bincount(k) / k.size
    rd = insnav.run(d, "rdkf")
    assert rd.summary["delay_p_source"] == "arrival times"
    np.testing.assert_allclose(rd.summary["delay_p"], want, rtol=0, atol=1e-15)
    assert np.all(np.abs(want - [0.2, 0.4, 0.2, 0.2]) < 0.05)  # the scenario's, to sampling error
    given = insnav.run(d, "rdkf", delay_p=want)
    assert given.summary["delay_p_source"] == "option"
    np.testing.assert_array_equal(rd.lat_deg, given.lat_deg)
    assert insnav.run(high, "rdkf").summary["delay_p_source"] == "scenario"
    on_time = insnav.run(_no_delay(d), "rdkf")
    assert on_time.summary["delay_p"] == [1.0] and on_time.summary["delay_p_source"] == "arrival times"


def test_rdkf_with_p1_is_the_kf():
    """p = [1]: the random-delay KF, the exact engine and the arrival-order KF
    are the ordinary EKF (no delays in the data)."""
    ds = _no_delay(insnav.simulate(INDEPENDENT_LOW, seed=5))
    ref = insnav.run(ds, "ekf")
    rd = insnav.run(ds, "rdkf", delay_p=[1.0])
    rd2 = insnav.run(ds, "rdkf", delay_p=[1.0, 0.0, 0.0, 0.0, 0.0])
    ex = insnav.run(ds, "exact")
    kf = insnav.run(ds, "kf")
    assert rd.summary["updates"] == ref.summary["updates"] == len(ds.gnss)
    for s in (rd, rd2, ex, kf):
        assert _max_pos_diff_m(s, ref) < 1e-8
        np.testing.assert_allclose(s.v_n, ref.v_n, atol=1e-10)
    assert ex.summary["replays"] == 0


def _duplicate_every_second(ds):
    """Every second fix twice: two records with the same time of validity and
    the same arrival time (a receiver repeating a fix, or two fixes of one
    epoch)."""
    d = _no_delay(ds)
    g = copy.copy(d.gnss)
    idx = np.sort(np.concatenate([np.arange(len(g)), np.arange(1, len(g), 2)]))
    for f in ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n"):
        setattr(g, f, getattr(d.gnss, f)[idx])
    g.origin = None
    d.gnss = g
    return d


@pytest.mark.parametrize("flt, opts", [("rdkf", {"delay_p": [1.0]}),
                                       ("rdkf", {"delay_p": [1.0, 0.0, 0.0, 0.0]}),
                                       ("exact", {})])
def test_same_epoch_records_equal_the_kf(flt, opts):
    """Several records in one epoch, no delay: the random-delay KF with
    p = [1] (seed 001 eq. (17) reduces to the Kalman gain) and the exact engine
    are the sequential EKF, which applies the two records one after the other
    with a feedback in between.  Each record after the first must be
    differenced against the INS *after* the previous correction was fed back;
    differencing it against the INS stored before (the bug this pins) applied
    the first correction twice: ~2 m off with a 0.035 m sigma."""
    ds = _duplicate_every_second(insnav.simulate(INDEPENDENT_LOW, seed=5))
    assert len(ds.gnss) > 2000
    # the repeats are the point here: sanitize (on by default for every filter) would drop them
    ref = insnav.run(ds, "kf", sanitize=False)
    s = insnav.run(ds, flt, sanitize=False, **opts)
    assert ref.summary["updates"] == s.summary["updates"] == len(ds.gnss)
    assert _max_pos_diff_m(s, ref) < 1e-9
    np.testing.assert_allclose(s.v_n, ref.v_n, atol=1e-9)
    np.testing.assert_allclose(s.sigma_pos_n_m, ref.sigma_pos_n_m, rtol=1e-9, atol=1e-12)


def test_exact_matches_offline_at_the_end(high):
    """With every record known the exact engine ends where the on-time EKF
    (records at t_valid) ends, although it learnt them late."""
    ex = insnav.run(high, "exact", sanitize=False)
    late = high.gnss.t_arrival > high.imu.t[-1] + 1e-9
    ds = copy.copy(high)
    g = copy.copy(high.gnss)
    for f in ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n"):
        setattr(g, f, getattr(high.gnss, f)[~late])
    ds.gnss = g
    # the paper's arrival model repeats some fixes; the exact engine applies
    # every record, so the reference must not drop the repeats (sanitize would)
    ref = insnav.run(ds, "ekf", sanitize=False)
    assert ex.summary["replays"] > 500
    d_end = max(abs(ex.lat_deg[-1] - ref.lat_deg[-1]), abs(ex.lon_deg[-1] - ref.lon_deg[-1])) * np.pi / 180 * R_EARTH
    assert d_end < 1e-6
    assert _max_pos_diff_m(ex, ref) > 1e-4  # but the real-time output differs on the way
    np.testing.assert_array_equal(ex.gnss_status[late], 4)
    assert np.all(ex.gnss_status[~late] == 1)


def test_exact_refuses_records_older_than_the_history(high):
    with pytest.warns(RuntimeWarning, match="history"):
        ex = run_delayed(high, "exact", max_history_s=0.15)
    delay = high.gnss.t_arrival - high.gnss.t_valid
    inside = high.gnss.t_arrival <= high.imu.t[-1] + 1e-9
    expected = int(np.sum((delay > 0.15 + 1e-6) & inside))
    assert expected > 200
    assert ex.summary["refused_too_old"] == expected
    assert int(np.sum(ex.gnss_status == 5)) == expected
    assert ex.summary["history_s"] == pytest.approx(0.15)


def test_bad_inputs(high):
    with pytest.raises(ValueError, match="delay_p"):
        insnav.run(high, "rdkf", delay_p=[0.5, 0.2])
    with pytest.raises(ValueError, match="delay_p"):
        insnav.run(high, "rdkf", delay_p=[0.2] * 5 + [0.0])
    with pytest.raises(ValueError, match="filter"):
        run_delayed(high, "nope")


def test_high_delay_ordering():
    """seed001-high, 8 Monte Carlo runs on the paper's arrival stream: (b)
    random-delay KF and (c) exact beat (a) the naive KF on north position
    RMSE by a wide margin; (c) with the time tags is at least as good as (b)."""
    res = insnav.montecarlo("seed001-high", ("kf", "rdkf", "exact"), runs=8, seed=7, workers=2)
    kf = res.values("kf", "pos_n_rmse_m")
    rd = res.values("rdkf", "pos_n_rmse_m")
    ex = res.values("exact", "pos_n_rmse_m")
    assert kf.mean() > 30 * rd.mean()      # measured 86x (paper: 9.8x)
    assert kf.mean() > 100 * ex.mean()     # measured 270x
    assert np.all(rd < kf) and np.all(ex < kf)
    assert ex.mean() <= rd.mean()
    assert np.mean(ex <= rd) >= 0.8
    # velocity too (measured 32x)
    assert res.values("kf", "vel_n_rmse_mps").mean() > 10 * res.values("rdkf", "vel_n_rmse_mps").mean()


def test_delay_filters_drop_only_true_duplicates():
    """insnav.run applies the same input repairs to every filter family: a
    record that repeats both the time of validity and the arrival time is a
    duplicate and is dropped (and counted) before the delay filters too,
    unless sanitize=False."""
    ds = _duplicate_every_second(insnav.simulate(INDEPENDENT_LOW, seed=5))
    for flt in ("kf", "rdkf", "exact"):
        on = insnav.run(ds, flt)
        off = insnav.run(ds, flt, sanitize=False)
        assert on.summary["sanitize"]["gnss_duplicates_dropped"] == len(ds.gnss) // 3, on.summary["sanitize"]
        assert on.summary["sanitize"]["gnss_repeat_arrivals_kept"] == 0
        assert "sanitize" not in off.summary
        assert on.summary["updates"] < off.summary["updates"] == len(ds.gnss)


def _poisson_binomial(p):
    """Distribution of the number of arrivals of one fix under seed 001 eq. (4):
    fix k arrives at epoch k + i when tau_(k+i) = i, independently for each i,
    so its count is a sum of independent Bernoulli(p_i)."""
    dist = np.array([1.0])
    for pi in p:
        dist = np.convolve(dist, [1.0 - pi, pi])
    return dist


@pytest.mark.parametrize("scen", ["seed001-low", "seed001-high"])
def test_filter_receives_the_paper_arrival_stream(scen):
    """What the delay filters receive after insnav.run's input repairs is the
    paper's stream (seed 001 eq. (4), y_k = z_(k - tau_k)): exactly one record
    at every receiver epoch, and each epoch's fix arrives 0, 1, 2, ... times
    with the shares that p implies (low delay p = [0.7, 0.3]: 0.21 / 0.58 /
    0.21).  A fix that arrives twice is two records with one time of validity
    and two arrival times: both reach the filter."""
    ds = insnav.simulate(scen, seed=3)
    p = scenario_delay_p(ds)
    expected = _poisson_binomial(p)
    for flt in ("kf", "rdkf"):
        s = insnav.run(ds, flt)
        san = s.summary["sanitize"]
        assert san["gnss_duplicates_dropped"] == 0
        assert san["gnss_repeat_arrivals_kept"] > 0.15 * len(ds.gnss)
        assert s.summary["updates"] == len(ds.gnss)
        n_ep = s.summary["receiver_epochs"]
        assert n_ep == pytest.approx(175 * 10, abs=2)
        assert s.summary["epoch_arrivals"] == [0, n_ep]
        fix = np.asarray(s.summary["fix_arrivals"], float)
        n = fix.sum()
        assert n == pytest.approx(n_ep, abs=len(p))
        share = np.zeros(expected.size)
        share[:fix.size] = fix / n
        sd = np.sqrt(expected * (1 - expected) / n)
        assert np.all(np.abs(share - expected) < 4 * sd + 1e-12), (share, expected)


def test_an_epoch_without_arrival_still_shifts_the_stack():
    """Every fix two epochs late (p = [0, 0, 1]) and only every fourth fix
    sent: three of four receiver epochs receive nothing.  The stack must still
    shift at them (seed 001 eqs. (5)-(7)), so that block 2 is the epoch two
    periods ago, where the fix was valid; the random-delay KF then tracks the
    exact engine (measured 0.0158 m north RMSE for both).  Had the schedule
    been only the record times, block 2 would be the epoch of the fix before
    (0.4 s earlier): ~3 m."""
    ds = insnav.simulate(INDEPENDENT_LOW, seed=5)
    g = copy.copy(ds.gnss)
    keep = np.round(g.t_valid * 10).astype(int) % 4 == 2
    for f in ("t_valid", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n"):
        setattr(g, f, getattr(ds.gnss, f)[keep])
    g.t_arrival = np.round(g.t_valid + 0.2, 9)
    g.origin = None
    d = copy.copy(ds)
    d.gnss = g
    from insnav.analysis import errors
    from insnav.filters.delay import receiver_epochs

    ep = receiver_epochs(g.t_valid, g.t_arrival, 0.1)
    np.testing.assert_allclose(np.diff(ep), 0.1, atol=1e-9)

    def north_rmse(sol):
        e = errors(sol, ds.truth)
        m = e["t"] > 5
        return float(np.sqrt(np.mean(e["pos_n_m"][m, 0] ** 2)))

    rd = insnav.run(d, "rdkf", delay_p=[0.0, 0.0, 1.0])
    ex = insnav.run(d, "exact")
    assert rd.summary["epoch_arrivals"][1] == int(keep.sum()) - 1  # the last arrives after the IMU span
    assert rd.summary["epoch_arrivals"][0] > 2.5 * rd.summary["epoch_arrivals"][1]
    assert north_rmse(rd) < 0.03
    assert north_rmse(rd) == pytest.approx(north_rmse(ex), rel=0.05)


@pytest.mark.parametrize("flt", ["kf", "rdkf", "exact"])
def test_delay_filters_weight_the_fixes_with_the_tuned_sigma_factors(high, flt):
    """``gnss_pos_sigma_scale`` / ``gnss_vel_sigma_scale`` / ``gnss_pos_v_sigma_scale`` weight the
    fixes of the delay filters as the loose EKF's: the run equals the default run on fixes whose
    sigmas were multiplied by the factors (exact reduction), and differs from the unscaled run."""
    d = copy.copy(high)
    d.gnss = copy.copy(high.gnss)
    d.gnss.sigma_pos_n = np.asarray(high.gnss.sigma_pos_n, float) * [4.0, 4.0, 4.0 * 3.0]
    d.gnss.sigma_vel_n = np.asarray(high.gnss.sigma_vel_n, float) * 2.0
    kw = dict(output_decimation=50)
    scaled = insnav.run(high, flt, gnss_pos_sigma_scale=4.0, gnss_vel_sigma_scale=2.0, gnss_pos_v_sigma_scale=3.0,
                        **kw)
    ref = insnav.run(d, flt, **kw)
    plain = insnav.run(high, flt, **kw)
    assert _max_pos_diff_m(scaled, ref) < 1e-9
    np.testing.assert_allclose(scaled.sigma_pos_n_m, ref.sigma_pos_n_m, rtol=1e-12, atol=0)
    assert np.max(np.abs(scaled.sigma_pos_n_m[-1] - plain.sigma_pos_n_m[-1])) > 1e-3  # the factors act


@pytest.mark.parametrize("flt, opt, match", [
    ("rdkf", {"delay_p": "x"}, r"option 'delay_p' = 'x': allowed: 1..5 probabilities"),
    ("rdkf", {"delay_p": [0.5, 0.9]}, r"option 'delay_p' = \[0.5, 0.9\]: allowed: .* summing to 1"),
    ("rdkf", {"delay_p": [1.2, -0.2]}, r"each in \[0, 1\]"),
    ("exact", {"checkpoint_interval_s": 0}, r"option 'checkpoint_interval_s' = 0: allowed: a number > 0"),
])
def test_bad_delay_options_are_one_line_naming_the_option(high, flt, opt, match):
    from insnav.config import ConfigError

    with pytest.raises(ConfigError, match=match):
        insnav.run(high, flt, **opt)
