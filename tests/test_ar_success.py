"""Success rates of partial ambiguity resolution (insnav.gnss.ar_success): the bootstrapped success rate
(Teunissen 1998, eq. (11)) against a Monte Carlo of integer bootstrapping on the same float covariance,
the monotonicity of the ordered bootstrap over nested subsets, the conditional-mean partial fix
(Teunissen 1995, eq. (6)) and the position conditioning against a joint Gaussian."""
from __future__ import annotations

import math

import numpy as np
import pytest

from insnav import _core
from insnav.gnss import ar_success as ars


def _small_q():
    # three double differences sharing a reference (covariance 1 + I pattern) plus a geometry term:
    # strongly correlated, as a float DD covariance is
    G = np.array([[1.0, 0.2, -0.5], [0.4, 1.0, 0.3], [-0.2, 0.6, 1.0]])
    return 0.012 * (np.ones((3, 3)) + np.eye(3)) + 0.05 * G @ G.T


def test_bootstrap_success_rate_diagonal_is_the_product_of_erfs():
    s = np.array([0.1, 0.2, 0.3])
    want = np.prod([math.erf(1.0 / (2.0 * math.sqrt(2.0) * x)) for x in s])
    assert ars.bootstrap_success_rate(np.diag(s ** 2)) == pytest.approx(want, rel=1e-12)
    assert ars.ordered_success_rate(np.diag(s ** 2))[-1] == pytest.approx(want, rel=1e-12)


def test_bootstrap_success_rate_matches_monte_carlo_of_bootstrapping():
    Q = _small_q()
    ps = ars.bootstrap_success_rate(Q)
    assert 0.3 < ps < 0.95  # a case where the rate is neither 0 nor 1
    Z, _, _ = _core.lambda_decorrelate(Q)
    Qz = Z.T @ Q @ Z
    rng = np.random.default_rng(7)
    m = 40000
    a_true = rng.integers(-20, 21, size=3).astype(float)
    a_hat = a_true + rng.standard_normal((m, 3)) @ np.linalg.cholesky(Q).T
    z = ars.bootstrap_estimate(a_hat @ Z, Qz)   # z = Z^T a per row
    ok = np.all(z == Z.T @ a_true, axis=1)
    sd = math.sqrt(ps * (1.0 - ps) / m)
    assert abs(ok.mean() - ps) < 4.0 * sd


def test_bootstrap_is_a_lower_bound_of_integer_least_squares():
    # Teunissen (1999): P(ILS correct) >= P(bootstrapping correct); ILS by MLAMBDA on the same samples
    Q = _small_q()
    ps = ars.bootstrap_success_rate(Q)
    rng = np.random.default_rng(11)
    m = 3000
    C = np.linalg.cholesky(Q)
    hits = 0
    for _ in range(m):
        a_hat = C @ rng.standard_normal(3)
        cand, _ = _core.lambda_search(a_hat, Q)
        hits += bool(np.all(np.asarray(cand)[:, 0] == 0.0))
    assert hits / m >= ps - 4.0 * math.sqrt(ps * (1.0 - ps) / m)


def test_ordered_success_rate_is_monotone_over_nested_subsets():
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(2, 8))
        A = rng.normal(size=(n, n + 2)) * 0.3
        G = rng.normal(size=(n, 3))
        Q = A @ A.T / (n + 2) + 0.02 * G @ G.T
        p = ars.ordered_success_rate(Q)
        assert np.all(np.diff(p) <= 1e-15)  # dropping the last candidate never lowers it
        # and each subset's value is the full computation on that subset
        k = int(rng.integers(1, n + 1))
        assert ars.ordered_success_rate(Q[:k, :k])[-1] == pytest.approx(p[k - 1], rel=1e-12)


def test_best_partial_subset_is_the_largest_passing_prefix():
    s = np.array([0.05, 0.08, 0.1, 0.4, 0.5])  # the last two drag the rate down
    Q = np.diag(s ** 2)
    rates = ars.partial_success_rates(Q)
    k, ps = ars.best_partial_subset(Q, 0.99, min_fix=1)
    assert k == 3 and ps == pytest.approx(rates[2])
    assert rates[2] >= 0.99 > rates[3]
    assert ars.best_partial_subset(Q, 0.99, min_fix=4) == (0, pytest.approx(math.nan, nan_ok=True))


def test_partial_fix_and_position_conditioning_match_the_joint_gaussian():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(7, 7))
    P = A @ A.T + 7 * np.eye(7)  # joint covariance of (b (3), a (4))
    x = rng.normal(size=7)
    Qbb, Qab, Qa = P[:3, :3], P[3:, :3], P[3:, 3:]
    # fixing the first two ambiguities: the Gaussian conditional of b on a_1, a_2
    a_fix = np.array([1.0, -2.0])
    b, Pb = ars.partial_fix(x[:3], Qbb, x[3:], Qa, Qab, a_fix)
    idx = [3, 4]
    K = P[np.ix_(range(3), idx)] @ np.linalg.inv(P[np.ix_(idx, idx)])
    assert np.allclose(b, x[:3] + K @ (a_fix - x[idx]))
    assert np.allclose(Pb, Qbb - K @ P[np.ix_(idx, range(3))])
    # a position measurement y = b + e: the Kalman update of the joint (b, a)
    R = np.diag([0.1, 0.2, 0.3])
    y = rng.normal(size=3)
    b2, Pbb2, a2, Qa2, Qab2 = ars.condition_on_position(x[:3], Qbb, x[3:], Qa, Qab, y, R)
    H = np.hstack([np.eye(3), np.zeros((3, 4))])
    Kf = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    xf = x + Kf @ (y - x[:3])
    Pf = P - Kf @ H @ P
    assert np.allclose(b2, xf[:3]) and np.allclose(a2, xf[3:])
    assert np.allclose(Pbb2, Pf[:3, :3]) and np.allclose(Qa2, Pf[3:, 3:]) and np.allclose(Qab2, Pf[3:, :3])
    # extra information never lowers the success rate
    assert ars.bootstrap_success_rate(Qa2 * 1e-2) >= ars.bootstrap_success_rate(Qa * 1e-2) - 1e-12


def test_recorded_float_problem_is_the_engines(tmp_path):
    """solve_rtk(record_float=True): the full set's success rate of each recorded float problem is the one
    the engine reports for the epoch, the order is partial AR's (smallest variance first), and the float
    ambiguities scatter about the simulator's true double-differenced integers as Q_a says."""
    import math as _m

    from insnav.gnss._rtk_keys import SYSTEM_INDEX
    from insnav.gnss.rtk import solve_rtk
    from insnav.sim import load_scenario, simulate_rtk
    from insnav.sim.gnss_rtk import rtk_noise_options
    from insnav.sim.scenario import resolve_raw

    raw, _ = resolve_raw("rtk-open-sky-car")
    raw["motion"]["segments"] = [{"duration_s": 40.0, "target_speed_mps": 12.0}]
    raw["gnss_rtk"].update(slip_rate_per_h=0.0, iono_ppm=0.0, tropo_ppm=0.0)
    sc = load_scenario(raw, seed=3)
    sim = simulate_rtk(sc, seed=3)
    files = sim.write(tmp_path)
    cfg = sc.gnss_rtk
    opts = dict(systems="".join(sim.signals), frequencies=1, ratio_threshold=3.0,
                elevation_mask_deg=_m.degrees(cfg["base_elevation_mask"]), **rtk_noise_options(cfg))
    rs = solve_rtk(files["rover"], files["base"], files["nav"], options=opts, record_float=True)
    epochs = list(ars.float_epochs(rs.info["float_ar"]))
    assert len(epochs) > 20

    def table(rx):
        key = [SYSTEM_INDEX[s] * 64 + int(p) for s, p in zip(rx.system, rx.prn)]
        return {(int(e), k): n for e, k, n in zip(rx.epoch, key, rx.ambiguity_cyc[:, 0])}

    rov, bas = table(sim.rover), table(sim.base)
    r_true = sim.rover.r_e
    worst = 0.0
    for fe in epochs:
        e = fe["epoch"]
        assert np.all(np.diff(np.diag(fe["Q_a"])) >= -1e-12)
        if rs.status[e] == 2:
            assert ars.bootstrap_success_rate(fe["Q_a"]) == pytest.approx(rs.success_rate[e], rel=1e-9, abs=1e-12)
        sd = {k: rov[(e, k)] - bas[(e, k)] for k in set(fe["sat_j"]) | set(fe["sat_i"])}
        a_true = np.array([sd[j] - sd[i] for j, i in zip(fe["sat_j"], fe["sat_i"])])
        # the float ambiguities' error is what the float position's error explains through Q_ab Q_bb^-1
        # (the phases pin the rest to millimetres): the residual is a small fraction of a cycle, so the
        # state's convention (phase = range / lambda + N) and the recorded order are the simulator's
        d = fe["a_hat"] - a_true
        res = d - fe["Q_ab"] @ np.linalg.solve(fe["Q_bb"], rs.r_float_e[e] - r_true[e])
        assert np.abs(d).max() > 0.3  # the float itself is metres off: the test is not trivial
        worst = max(worst, float(np.abs(res).max()))
    assert worst < 0.25  # an integer offset or a sign error would leave >= 1 cycle


def test_true_position_change_makes_a_moving_rover_static(tmp_path):
    """bench/rtk_urban_feasibility.static_rows (the perfect-INS oracle): the moving rover's observations moved
    to its first position by the true ranges; the static engine then fixes at that position, and the
    Doppler moved with the phase raises no slip."""
    import importlib.util
    import math as _m
    from pathlib import Path

    from insnav.gnss.rtk import RtkOptions, prepare_rtk_rows
    from insnav.sim import load_scenario, simulate_rtk
    from insnav.sim.gnss_rtk import rtk_noise_options
    from insnav.sim.scenario import resolve_raw

    path = Path(__file__).resolve().parents[1] / "bench" / "rtk_urban_feasibility.py"
    spec = importlib.util.spec_from_file_location("rtk_urban_feasibility", path)
    feas = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(feas)
    raw, _ = resolve_raw("rtk-open-sky-car")
    raw["motion"]["segments"] = [{"duration_s": 20.0, "target_speed_mps": 12.0},
                                 {"duration_s": 20.0, "heading_change_deg": 90.0}]
    raw["gnss_rtk"].update(slip_rate_per_h=0.0)
    sc = load_scenario(raw, seed=4)
    sim = simulate_rtk(sc, seed=4)
    files = sim.write(tmp_path)
    cfg = sc.gnss_rtk
    opt = RtkOptions.from_dict(dict(systems="".join(sim.signals), frequencies=2, ratio_threshold=3.0, mode="static",
                                    elevation_mask_deg=_m.degrees(cfg["base_elevation_mask"]),
                                    **rtk_noise_options(cfg)), "test")
    rover, base, r_base_e, bidx, roff, rrows, boff, brows = prepare_rtk_rows(files["rover"], files["base"],
                                                                             files["nav"], None, opt)
    t = rover.epoch_t_gps_s
    r_true, ok = feas._truth_pos(sim, t)
    assert ok.all() and np.linalg.norm(r_true[-1] - r_true[0]) > 200.0  # the car really moves
    r0 = r_true[0]
    out = _core.rtk_run(t, roff, feas.static_rows(t, roff, rrows, r_true, r0), boff, brows, bidx, r_base_e,
                        opt.core_dict())
    st = np.asarray(out["status"])
    assert (st == 1).mean() > 0.8
    assert np.linalg.norm(np.asarray(out["r_e"])[st == 1] - r0, axis=1).max() < 0.05
    assert np.asarray(out["slips"])[:, 3].sum() == 0  # Doppler test
    # without the move the static engine cannot fix the moving rover
    moving = _core.rtk_run(t, roff, rrows, boff, brows, bidx, r_base_e, opt.core_dict())
    assert (np.asarray(moving["status"]) == 1).mean() < 0.5
