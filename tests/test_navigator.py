"""The real-time push API (insnav.Navigator, engine/navigator.hpp): pushed in
time order, with fixes on time or late within the IMU hold, it reproduces the
batch run of insnav.run row for row; a fix beyond the hold is refused; bad
calls give one-line errors."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import insnav
from insnav import sim
from insnav.config import RunConfig
from insnav.filters.navigator import Navigator, TightNavigator


def _dataset(seed=2, duration_s=40.0, outages=((20.0, 26.0),)):
    """seed000-sim (MEMS IMU 200 Hz, GNSS 1 Hz) shortened, with an outage and a lever arm."""
    sc = copy.deepcopy(sim.simulate("seed000-sim", seed=0, with_truth=False).scenario)
    sc["motion"]["segments"] = [dict(duration_s=duration_s / 2), dict(duration_s=duration_s / 2, heading_change_deg=60.0)]
    sc["motion"]["oscillations"] = [dict(o, end_s=duration_s) for o in sc["motion"]["oscillations"]]
    sc["gnss"].update(lever_arm_b_m=[0.4, -0.2, -0.8], outages=[list(o) for o in outages])
    return insnav.simulate(sc, seed=seed)


def _drive(nav, ds, check, late_samples, push_upto):
    """Push the dataset's IMU samples; before sample k, `push_upto(tc)` pushes the records whose
    time is <= tc = t[k - late_samples] (a record `late_samples` samples after the sample covering
    it; tc = inf at the end).  The navigator's row after each checked sample and the last."""
    t = ds.imu.t
    rows = {}
    for k in range(len(t)):
        push_upto(t[max(0, k - late_samples)])
        nav.push_imu(t[k], ds.imu.dtheta_b[k], ds.imu.dv_b[k])
        done = nav.counters["samples"]
        if done and done - 1 in check and done - 1 not in rows:
            rows[done - 1] = nav.state()
    push_upto(np.inf)
    nav.flush()
    rows[len(t) - 1] = nav.state()
    return rows


def _worst_row_diff(rows, batch) -> float:
    """The largest difference of the pushed rows from the batch rows: position (m), velocity (m/s),
    attitude (deg) and position sigma (m); the rows' times must be the batch's."""
    worst = 0.0
    for k, r in rows.items():
        assert r["t"] == batch.t[k]
        worst = max(worst, abs(r["lat_deg"] - batch.lat_deg[k]) * 1.1e5, abs(r["lon_deg"] - batch.lon_deg[k]) * 1.1e5,
                    abs(r["h_m"] - batch.h_m[k]), np.max(np.abs(r["v_n_mps"] - batch.v_n[k])),
                    abs(r["roll_deg"] - batch.roll_deg[k]), abs(r["pitch_deg"] - batch.pitch_deg[k]),
                    abs(r["yaw_deg"] - batch.yaw_deg[k]), np.max(np.abs(r["sigma"][0:3] - batch.sigma_pos_n_m[k])))
    return worst


def _push_all(nav, ds, cfg_rows, late_samples=0):
    """Push the dataset's IMU samples and fixes in arrival order (a fix
    `late_samples` IMU samples after the sample covering it); the navigator's
    row after each integrated sample."""
    g = ds.gnss
    order = np.argsort(g.t_valid, kind="stable")
    gi = 0

    def push_fixes_upto(tc):
        nonlocal gi
        while gi < len(order) and g.t_valid[order[gi]] <= tc:
            j = order[gi]
            st = nav.push_gnss_fix(g.t_valid[j], g.lat_deg[j], g.lon_deg[j], g.h_m[j], g.sigma_pos_n[j],
                                   g.v_n[j], g.sigma_vel_n[j])
            assert st == "queued", (j, st)
            gi += 1

    return _drive(nav, ds, cfg_rows, late_samples, push_fixes_upto)


@pytest.mark.parametrize("filt,late,hold", [("ekf", 0, 0), ("ekf", 30, 40), ("rbukf", 30, 40)])
def test_push_equals_batch(filt, late, hold):
    ds = _dataset()
    cfg = RunConfig(filter=filt)
    batch = insnav.run(ds, config=cfg, sanitize=False, checks=False)
    nav = Navigator.from_dataset(ds, RunConfig(filter=filt), imu_hold=hold)
    check = set(range(0, len(ds.imu.t), 97)) | {len(ds.imu.t) - 1}
    rows = _push_all(nav, ds, check, late_samples=late)
    assert len(rows) >= len(check) - 1
    worst = dict(pos=0.0, vel=0.0, att=0.0, sig=0.0)
    for k, r in rows.items():
        assert r["t"] == batch.t[k]
        worst["pos"] = max(worst["pos"], abs(r["lat_deg"] - batch.lat_deg[k]) * 1.1e5,
                           abs(r["lon_deg"] - batch.lon_deg[k]) * 1.1e5, abs(r["h_m"] - batch.h_m[k]))
        worst["vel"] = max(worst["vel"], np.max(np.abs(r["v_n_mps"] - batch.v_n[k])))
        worst["att"] = max(worst["att"], abs(r["roll_deg"] - batch.roll_deg[k]), abs(r["pitch_deg"] - batch.pitch_deg[k]),
                           abs(r["yaw_deg"] - batch.yaw_deg[k]))
        worst["sig"] = max(worst["sig"], np.max(np.abs(r["sigma"][0:3] - batch.sigma_pos_n_m[k])))
    assert max(worst.values()) < 1e-9, worst
    c = nav.counters
    assert c["updates"] == batch.summary["updates"] and c["updates"] > 20
    assert c["refused_records"] == 0 and c["pending_records"] == 0 and c["held_samples"] == 0


def test_push_matches_truth_and_sigma():
    """A navigator built by hand (no dataset) from the truth's initial state
    tracks the truth within its own 4 sigma after 40 s."""
    ds = _dataset(seed=5)
    s0 = ds.initial
    nav = Navigator(s0, ds.t0, ds.imu_model, RunConfig(filter="ekf"), lever_arm_b=ds.lever_arm_b,
                    gnss_period_s=1.0, imu_hold=50)
    rows = _push_all(nav, ds, set(), late_samples=20)
    last = rows[len(ds.imu.t) - 1]
    tr = ds.truth
    k = int(np.argmin(np.abs(tr.t - last["t"])))
    from insnav.earth import radii

    R_M, R_N = radii(np.radians(tr.lat_deg[k]))
    dn = np.radians(last["lat_deg"] - tr.lat_deg[k]) * (R_M + tr.h_m[k])
    de = np.radians(last["lon_deg"] - tr.lon_deg[k]) * (R_N + tr.h_m[k]) * np.cos(np.radians(tr.lat_deg[k]))
    assert abs(dn) < 4 * last["sigma"][0] and abs(de) < 4 * last["sigma"][1], (dn, de, last["sigma"][:2])
    assert np.all(np.abs(last["v_n_mps"] - tr.v_n[k]) < 4 * last["sigma"][3:6] + 1e-3)
    P = nav.covariance()
    assert P.shape == (15, 15) and np.allclose(P, P.T) and np.all(np.linalg.eigvalsh(P) > 0)
    att = slice(6, 9)
    keep = np.r_[0:6, 9:15]
    assert np.allclose(np.sqrt(np.diag(P))[keep], last["sigma"][keep])
    # the attitude entries: the 1-sigmas of roll, pitch, yaw, psi's covariance carried through the
    # numerical Jacobian of the Euler angles of C~ = (I - [psi x]) C (layout.hpp), not psi's own
    e = np.radians([last["roll_deg"], last["pitch_deg"], last["yaw_deg"]])
    assert abs(np.sin(e[2])) > 0.3  # a heading where the two differ
    J = euler_jacobian_of_psi(e)
    sig_e = np.sqrt(np.diag(J @ P[att, att] @ J.T))
    np.testing.assert_allclose(last["sigma"][att], sig_e, rtol=1e-6)
    assert np.max(np.abs(last["sigma"][att] / np.sqrt(np.diag(P[att, att])) - 1)) > 0.05


def euler_jacobian_of_psi(e, eps=1e-6):
    """d(roll, pitch, yaw) / d psi by central differences: the computed frame
    ``expm(-[psi x]) C_nb(e)`` (psi about N, E, D), its 3-2-1 Euler angles by their definition."""
    def dcm(r, p, y):
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
        Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        return Rz @ Ry @ Rx

    def euler(C):
        return np.array([np.arctan2(C[2, 1], C[2, 2]), -np.arcsin(C[2, 0]), np.arctan2(C[1, 0], C[0, 0])])

    def rot(v):  # Rodrigues: expm([v x])
        a = np.linalg.norm(v)
        K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / a
        return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K

    C = dcm(*e)
    J = np.empty((3, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        J[:, i] = (euler(rot(-d) @ C) - euler(rot(d) @ C)) / (2 * eps)
    return J


def test_late_fix_refused_and_bad_calls():
    ds = _dataset(duration_s=10.0, outages=())
    nav = Navigator(ds.initial, ds.t0, "consumer", imu_hold=5)
    for k in range(400):
        nav.push_imu(ds.imu.t[k], ds.imu.dtheta_b[k], ds.imu.dv_b[k])
    c = nav.counters
    assert c["held_samples"] == 5 and c["samples"] == 395
    g = ds.gnss
    # valid long before the last integrated sample: refused, never applied at a wrong time
    assert nav.push_gnss_fix(g.t_valid[0], g.lat_deg[0], g.lon_deg[0], g.h_m[0], g.sigma_pos_n[0]) == "too_old"
    assert nav.push_gnss_fix(ds.imu.t[398], g.lat_deg[1], g.lon_deg[1], g.h_m[1], g.sigma_pos_n[1]) == "queued"
    assert nav.counters["refused_records"] == 1
    assert nav.push_imu(ds.imu.t[399], ds.imu.dtheta_b[0], ds.imu.dv_b[0]) is False  # time not increasing
    with pytest.raises(ValueError, match="push_gnss_fix: the position 1-sigma must be finite and > 0"):
        nav.push_gnss_fix(ds.imu.t[399], 0.0, 0.0, 0.0, [0.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="unknown kind 'nhcc'"):
        nav.push_constraint(ds.imu.t[399], "nhcc")
    with pytest.raises(ValueError, match="push API runs the loose"):
        Navigator(ds.initial, ds.t0, "consumer", RunConfig(filter="upf", coupling="tight"))
    with pytest.raises(ValueError, match="imu_hold"):
        Navigator(ds.initial, ds.t0, "consumer", imu_hold=1000)


# --- tightly coupled push API (insnav.TightNavigator) --------------------------------------------

def test_non_finite_inputs_and_the_largest_hold():
    """A time of +inf was taken as a sample and then read past the queue's end (a segfault); a NaN
    increment stayed in the state for good; a non-finite sigma was "applied" and left P non-finite; and
    at imu_hold = 256, the largest allowed, the newest sample overwrote the oldest before it was
    integrated (velocity 13.9 m/s against 6.9).  Now: refused (False), one-line errors naming the
    argument, and the flushed state of hold 256 equals hold 0 bit for bit."""
    ds = _dataset(duration_s=10.0, outages=())
    states = {}
    for hold in (0, 255, 256):
        nav = Navigator(ds.initial, ds.t0, "consumer", imu_hold=hold)
        for k in range(600):
            assert nav.push_imu(ds.imu.t[k], ds.imu.dtheta_b[k], ds.imu.dv_b[k])
        nav.flush()
        states[hold] = nav.state()
    for hold in (255, 256):
        for key in ("lat_deg", "lon_deg", "h_m", "v_n_mps", "yaw_deg"):
            np.testing.assert_array_equal(states[hold][key], states[0][key])
    nav = Navigator(ds.initial, ds.t0, "consumer", imu_hold=3)
    for k in range(100):
        nav.push_imu(ds.imu.t[k], ds.imu.dtheta_b[k], ds.imu.dv_b[k])
    bad = ds.imu.dtheta_b[100].copy()
    bad[0] = np.nan
    assert nav.push_imu(np.inf, ds.imu.dtheta_b[100], ds.imu.dv_b[100]) is False
    assert nav.push_imu(ds.imu.t[100], bad, ds.imu.dv_b[100]) is False
    assert nav.push_imu(ds.imu.t[100], ds.imu.dtheta_b[100], np.full(3, np.inf)) is False
    assert nav.counters["samples"] + nav.counters["held_samples"] == 100
    g = ds.gnss
    assert nav.push_gnss_fix(np.inf, g.lat_deg[0], g.lon_deg[0], g.h_m[0], g.sigma_pos_n[0]) == "outside_imu_span"
    with pytest.raises(ValueError, match="push_gnss_fix: the position 1-sigma must be finite and > 0"):
        nav.push_gnss_fix(ds.imu.t[101], g.lat_deg[0], g.lon_deg[0], g.h_m[0], [np.inf, 1.0, 1.0])
    with pytest.raises(ValueError, match="push_gnss_fix: the velocity 1-sigma must be finite and > 0 where the "
                                         "velocity is given"):
        nav.push_gnss_fix(ds.imu.t[101], g.lat_deg[0], g.lon_deg[0], g.h_m[0], g.sigma_pos_n[0], [1.0, 0.0, 0.0],
                          [np.nan, 0.1, 0.1])
    for k in range(100, 200):
        assert nav.push_imu(ds.imu.t[k], ds.imu.dtheta_b[k], ds.imu.dv_b[k])
    nav.flush()
    s = nav.state()
    assert np.isfinite(s["lat_deg"]) and np.all(np.isfinite(s["v_n_mps"])) and np.all(np.isfinite(s["sigma"]))


def test_delay_push_refuses_bad_sigmas_and_shapes():
    """DelayNavigator.push_epoch took sigmas of 0, negative, inf and NaN (the state went NaN) and reshaped a
    (14, 2) array into scrambled records.  Now one line naming the record and the sigma, or the shape."""
    ds = _delay_dataset(duration_s=10.0)
    nav = insnav.DelayNavigator.from_dataset(ds, RunConfig(filter="exact"))
    rec = nav.records[:1].copy()
    for bad in (0.0, -1.0, np.inf, np.nan):
        r = rec.copy()
        r[0, 9] = bad
        with pytest.raises(ValueError, match=r"push_epoch: record 0: the position 1-sigma must be finite and > 0"):
            nav.push_epoch(nav.epochs[0], r)
    with pytest.raises(ValueError, match=r"records must be \(k, 14\) rows, got shape \(14, 1\)"):
        nav.push_epoch(nav.epochs[0], rec.T)


def _cut_scenario(name, duration_s):
    """The preset `name` cut to its first motion segments (>= duration_s)."""
    sc = copy.deepcopy(sim.load_scenario(name).raw)
    segs, tot = [], 0.0
    for s in sc["motion"]["segments"]:
        if tot >= duration_s:
            break
        segs.append(s)
        tot += float(s["duration_s"])
    sc["motion"]["segments"] = segs
    return sc


def _multi_dataset(duration_s=60.0, seed=4):
    """urban-multignss (GPS + Galileo + BeiDou) cut to its first motion segments, open sky."""
    sc = _cut_scenario("urban-multignss", duration_s)
    sc["gnss_raw"].pop("urban_canyon", None)
    return sim.simulate(sc, seed=seed)


def _push_tight(nav, ds, check, late_samples):
    """IMU samples and the navigator's own epochs (TightNavigator.inputs) in arrival order, an
    epoch `late_samples` IMU samples after the sample covering it; rows after the checked samples."""
    ep_t = nav.inputs.epoch_t
    e = 0

    def push_epochs_upto(tc):
        nonlocal e
        while e < len(ep_t) and ep_t[e] <= tc:
            st = nav.push_epoch(e)
            assert st == "queued" or tc == np.inf, (e, st)
            e += 1

    return _drive(nav, ds, check, late_samples, push_epochs_upto)


@pytest.mark.parametrize("filt,multi,extra", [("ekf", False, {}), ("rbukf", False, {}), ("ekf", True, {}),
                                              ("ekf", False, {"adaptive_q_window": 10})])
def test_tight_push_equals_batch(filt, multi, extra):
    """The tight push API from the same inputs (epochs 30 IMU samples late, 40 held) gives the batch
    run's rows to 1e-12 (m, m/s, deg), its receiver clock and (20 states) ISBs, and its counts; the
    adaptive process noise (the engine's per-epoch step, filter/adaptive_noise.hpp) too."""
    from conftest import short_tight_dataset

    from insnav.filters.navigator import TightNavigator

    ds = _multi_dataset() if multi else short_tight_dataset(60.0)
    batch = insnav.run(ds, filt, "tight", sanitize=False, checks=False, **extra)
    nav = TightNavigator.from_dataset(ds, RunConfig(filter=filt, **extra), imu_hold=40)
    assert nav.layout == (20 if multi else 17) == batch.summary["layout"]
    check = set(range(0, len(ds.imu.t), 89)) | {len(ds.imu.t) - 1}
    rows = _push_tight(nav, ds, check, late_samples=30)
    assert len(rows) >= len(check) - 1
    worst = _worst_row_diff(rows, batch)
    for k, r in rows.items():
        worst = max(worst, abs(r["clock_bias_m"] - batch.clock_bias_m[k]),
                    abs(r["clock_drift_mps"] - batch.clock_drift_mps[k]))
        if multi:
            worst = max(worst, np.max(np.abs(r["isb_m"] - batch.isb_m[k])))
    assert worst <= 1e-12, worst
    c = nav.counters
    assert c["updates"] == batch.summary["updates"] and c["updates"] > 40
    assert c["rejected_sats"] == batch.summary["rejected_sats"]
    assert c["refused_records"] == 0 and c["pending_records"] == 0 and c["held_samples"] == 0


def test_tight_push_refuses_a_late_epoch_and_bad_rows():
    from conftest import short_tight_dataset

    from insnav.filters.navigator import TightNavigator

    ds = short_tight_dataset(20.0)
    nav = TightNavigator.from_dataset(ds, RunConfig(filter="ekf"))
    nav.push_imu_array(ds.imu.t[:1000], ds.imu.dtheta_b[:1000], ds.imu.dv_b[:1000])
    assert nav.push_epoch(0) == "too_old" and nav.counters["refused_records"] == 1
    bad = np.array(nav.inputs.sats[:4], float)
    bad[0, 10] = 0.0  # sigma_pr
    with pytest.raises(ValueError, match="sigma_pr must be finite and > 0 at row 0"):
        nav.push_pseudoranges(ds.imu.t[1000] + 0.1, bad)
    with pytest.raises(ValueError, match="smoother"):
        TightNavigator.from_dataset(ds, RunConfig(filter="ekf", smooth=True))


# --- random-delay KF push API (insnav.DelayNavigator, seed 001) ----------------------------------

def _delay_dataset(duration_s=30.0, seed=3):
    """seed001-high (INS 100 Hz, GNSS 10 Hz, delays of 0..3 epochs with p = [0.2, 0.4, 0.2, 0.2])
    cut to its first motion segments."""
    return sim.simulate(_cut_scenario("seed001-high", duration_s), seed=seed)


@pytest.mark.parametrize("late,hold", [(0, 0), (8, 12)])
def test_delay_push_equals_batch(late, hold):
    """Seed 001's random-delay KF pushed one receiver epoch at a time (with the records that
    arrived by it; epochs `late` IMU samples late, `hold` held) gives the batch run's rows
    (insnav.run(ds, "rdkf")) to 1e-9 (m, m/s, deg) and its update count."""
    from insnav.filters.navigator import DelayNavigator

    ds = _delay_dataset()
    batch = insnav.run(ds, "rdkf", sanitize=False, checks=False)
    nav = DelayNavigator.from_dataset(ds, imu_hold=hold)
    np.testing.assert_array_equal(nav.delay_p, [0.2, 0.4, 0.2, 0.2])
    ep = nav.epochs
    check = set(range(0, len(ds.imu.t), 53)) | {len(ds.imu.t) - 1}
    e = 0

    def push_epochs_upto(tc):
        nonlocal e
        while e < len(ep) and ep[e] <= tc + 1e-6:  # an epoch at an IMU sample time belongs to that sample
            st = nav.push_receiver_epoch(e)
            assert st == ("outside_imu_span" if ep[e] <= ds.t0 + 1e-6 else "queued") or tc == np.inf, (e, st)
            e += 1

    rows = _drive(nav, ds, check, late, push_epochs_upto)
    assert len(rows) >= len(check) - 1
    worst = _worst_row_diff(rows, batch)
    assert worst <= 1e-9, worst
    c = nav.counters
    assert c["updates"] == batch.summary["updates"] and c["updates"] > 200
    assert c["held_samples"] == 0 and c["dropped_records"] == 0
    P = nav.covariance()
    last = rows[len(ds.imu.t) - 1]
    keep = np.r_[0:6, 9:15]  # the attitude entries are the Euler angles' (test_push_matches_truth_and_sigma)
    assert P.shape == (15, 15) and np.allclose(np.sqrt(np.diag(P))[keep], last["sigma"][keep])
    J = euler_jacobian_of_psi(np.radians([last["roll_deg"], last["pitch_deg"], last["yaw_deg"]]))
    np.testing.assert_allclose(last["sigma"][6:9], np.sqrt(np.diag(J @ P[6:9, 6:9] @ J.T)), rtol=1e-6)


def test_delay_push_refuses_and_bad_calls():
    from insnav.filters.navigator import DelayNavigator

    ds = _delay_dataset(duration_s=10.0)
    nav = DelayNavigator.from_dataset(ds, delay_p=[0.5, 0.5], imu_hold=3)
    nav.push_imu_array(ds.imu.t[:200], ds.imu.dtheta_b[:200], ds.imu.dv_b[:200])
    assert nav.counters["samples"] == 197
    assert nav.push_epoch(ds.imu.t[100]) == "too_old" and nav.counters["refused_records"] == 1
    assert nav.push_epoch(ds.imu.t[198], nav.records[:2]) == "queued"
    with pytest.raises(ValueError, match="at most 8"):
        nav.push_epoch(ds.imu.t[199], nav.records[:9])
    with pytest.raises(ValueError, match="delay_p"):
        DelayNavigator.from_dataset(ds, delay_p=[0.5, 0.6])
    with pytest.raises(ValueError, match="config key 'layout': bad value 21; allowed: 15"):
        DelayNavigator.from_dataset(ds, layout=21)


def test_push_calls_name_wrong_arguments_and_statuses_say_what_happened():
    """Before: ``t=None`` was queued as a NaN time and refused as "outside_imu_span", ``t0=nan``
    built a navigator that refused every sample, a (12, k) satellite array was reshaped into
    scrambled rows, the self-calibration options of TightNavigator stopped on "P0: expected shape",
    a full queue said "too_old" and ``last_*()`` said "queued" for a record processed and not used.
    Now: TypeError / ValueError naming the call and argument, "queue_full", "not_used"."""
    from conftest import short_tight_dataset

    from insnav.filters.navigator import TightNavigator

    ds = _dataset(duration_s=10.0, outages=())
    g = ds.gnss
    with pytest.raises(ValueError, match=r"Navigator: t0 must be a finite time \[s\], got nan"):
        Navigator(ds.initial, float("nan"), "consumer")
    with pytest.raises(TypeError, match="Navigator: t must be a time in seconds"):
        Navigator(ds.initial, None, "consumer")
    nav = Navigator(ds.initial, ds.t0, "consumer", imu_hold=256)
    assert nav.last_fix()["status"] == "not_used"  # nothing processed yet
    for k in range(300):
        assert nav.push_imu(ds.imu.t[k], ds.imu.dtheta_b[k], ds.imu.dv_b[k])
    with pytest.raises(TypeError, match="push_gnss_fix: t must be a time in seconds .*NoneType None"):
        nav.push_gnss_fix(None, g.lat_deg[0], g.lon_deg[0], g.h_m[0], g.sigma_pos_n[0])
    with pytest.raises(TypeError, match="push_imu: t must be a time in seconds .*str '1.0'"):
        nav.push_imu("1.0", ds.imu.dtheta_b[0], ds.imu.dv_b[0])
    # 64 pending fixes fill the queue (engine/navigator.hpp): the 65th is refused as queue_full, an old
    # one still as too_old
    t_ok = ds.imu.t[250:299]
    states = [nav.push_gnss_fix(t, g.lat_deg[1], g.lon_deg[1], g.h_m[1], g.sigma_pos_n[1])
              for t in np.linspace(t_ok[0], t_ok[-1], 65)]
    assert states[:64] == ["queued"] * 64 and states[64] == "queue_full", states[60:]
    c = nav.counters
    assert c["pending_records"] == 64 and c["refused_records"] == 1
    nav.flush()
    assert nav.counters["pending_records"] == 0 and nav.last_fix()["status"] in ("applied", "rejected_by_gate")
    assert nav.push_gnss_fix(ds.imu.t[10], g.lat_deg[1], g.lon_deg[1], g.h_m[1], g.sigma_pos_n[1]) == "too_old"

    tds = short_tight_dataset(20.0)
    tnav = TightNavigator.from_dataset(tds, RunConfig(filter="ekf"))
    inp = tnav.inputs
    b, f = int(inp.epoch_start[1]), int(inp.epoch_start[2])
    assert f - b != 12
    with pytest.raises(ValueError, match=rf"sats must be \(k, 12\) rows, got shape \(12, {f - b}\)"):
        tnav.push_pseudoranges(inp.epoch_t[1], inp.sats[b:f].T)
    with pytest.raises(ValueError, match=r"sats must be \(k, 12\) rows, got shape \(\d+,\)"):
        tnav.push_pseudoranges(inp.epoch_t[1], inp.sats[b:f].ravel())
    # a system index 1.6 would truncate to GLONASS: refused, as is a length other than the rows'
    with pytest.raises(ValueError, match=r"system must be whole numbers, got \[1.6"):
        tnav.push_pseudoranges(inp.epoch_t[1], inp.sats[b:f], np.full(f - b, 1.6))
    with pytest.raises(ValueError, match=rf"prn must have one entry per row of sats \({f - b}\), got shape \(1,\)"):
        tnav.push_pseudoranges(inp.epoch_t[1], inp.sats[b:f], None, [3])
    # an epoch with every pseudorange absent is processed and not used: "not_used", not "queued"
    k1 = int(np.searchsorted(tds.imu.t, inp.epoch_t[1]))
    tnav.push_imu_array(tds.imu.t[:k1 - 2], tds.imu.dtheta_b[:k1 - 2], tds.imu.dv_b[:k1 - 2])
    empty = np.array(inp.sats[b:f], float)
    empty[:, 0] = empty[:, 1] = np.nan
    assert tnav.push_pseudoranges(inp.epoch_t[1], empty) == "queued"
    tnav.push_imu_array(tds.imu.t[k1 - 2:k1 + 5], tds.imu.dtheta_b[k1 - 2:k1 + 5], tds.imu.dv_b[k1 - 2:k1 + 5])
    assert tnav.counters["pending_records"] == 0 and tnav.last_epoch()["status"] == "not_used"
    for opt in ({"time": {"estimate_offset": True}}, {"lever_arm": {"estimate": True}}):
        with pytest.raises(ValueError, match=r"TightNavigator: \[time\] estimate_offset / \[lever_arm\] estimate "
                                             "unsupported"):
            TightNavigator.from_dataset(tds, dict(filter="ekf", **opt))


def test_the_compiled_push_calls_check_the_sigmas_themselves():
    """The Python wrappers check a fix's sigmas; the compiled objects (``insnav._core``, what a C++-minded
    caller or a subclass reaches) trusted them: a zero position sigma in a delay record was applied and
    the state went NaN.  Now the binding refuses it too, naming the record."""
    from insnav.filters.navigator import DelayNavigator

    dds = _delay_dataset(duration_s=10.0)
    dnav = DelayNavigator.from_dataset(dds, delay_p=[0.5, 0.5])
    rec = np.array(dnav.records[:1], float)
    rec[0, 8] = 0.0
    with pytest.raises(ValueError, match="push_epoch: record 0: the position 1-sigma must be finite and > 0"):
        dnav._nav.push_epoch(float(dnav.epochs[3]), np.ascontiguousarray(rec))
    rec = np.array(dnav.records[:1], float)
    rec[0, 5:8] = 1.0  # a velocity given with a NaN sigma
    rec[0, 11:14] = np.nan
    with pytest.raises(ValueError, match="push_epoch: record 0: the velocity 1-sigma must be finite and > 0"):
        dnav._nav.push_epoch(float(dnav.epochs[3]), np.ascontiguousarray(rec))
    ds = _dataset(duration_s=10.0, outages=())
    nav = Navigator(ds.initial, ds.t0, "consumer")
    row = np.array([ds.imu.t[5], 0.7, 0.2, 100.0, np.nan, np.nan, np.nan, 1.0, -1.0, 1.0, np.nan, np.nan, np.nan])
    with pytest.raises(ValueError, match="push_gnss_fix: the position 1-sigma must be finite and > 0"):
        nav._nav.push_gnss_fix(row)


def test_the_smoothers_euler_sigmas_are_the_numerical_jacobians():
    """``filters.smoothing.euler_sigmas_from_psi`` (the smoothed rows' attitude sigmas, the numpy form
    of ins/nav_error.hpp's) against the numerical Jacobian, at headings all round and pitch to 80 deg."""
    from insnav.filters.smoothing import euler_sigmas_from_psi

    rng = np.random.default_rng(4)
    e = np.column_stack([rng.uniform(-np.pi, np.pi, 40), rng.uniform(-1.4, 1.4, 40), rng.uniform(-np.pi, np.pi, 40)])
    L = rng.standard_normal((40, 3, 3)) * 0.01
    P = L @ np.swapaxes(L, 1, 2) + 1e-6 * np.eye(3)
    got = euler_sigmas_from_psi(P, e[:, 1], e[:, 2])
    for k in range(40):
        J = euler_jacobian_of_psi(e[k])
        np.testing.assert_allclose(got[k], np.sqrt(np.diag(J @ P[k] @ J.T)), rtol=1e-6)


@pytest.mark.parametrize("factors", [dict(gnss_pos_sigma_scale=2.0, gnss_vel_sigma_scale=3.0),
                                     dict(gnss_pos_v_sigma_scale=2.0),
                                     dict(gnss_pos_sigma_per_speed_s=0.5, gnss_vel_sigma_per_speed=0.05)])
def test_push_applies_the_gnss_sigma_factors_as_the_batch(factors):
    """The config's GNSS sigma factors (insnav tune's) weight the pushed fixes as the batch run
    weights its own (loose_gnss_rows): push equals batch, and differs from the run without them."""
    ds = _dataset(duration_s=30.0)
    check = set(range(0, len(ds.imu.t), 211)) | {len(ds.imu.t) - 1}
    batch = insnav.run(ds, config=RunConfig(**factors), sanitize=False, checks=False)
    rows = _push_all(Navigator.from_dataset(ds, RunConfig(**factors)), ds, check)
    assert _worst_row_diff(rows, batch) < 1e-9
    plain = insnav.run(ds, sanitize=False, checks=False)
    assert _worst_row_diff(rows, plain) > 1e-3


def test_push_refuses_what_it_cannot_run_as_the_batch():
    ds = _dataset(duration_s=10.0)
    # RTK/INS and tight configs: not the loose push engine, and TightNavigator says RTK/INS has no push API
    with pytest.raises(ValueError, match="coupling 'rtk'"):
        Navigator.from_dataset(ds, RunConfig(coupling="rtk"))
    with pytest.raises(ValueError, match="coupling 'tight'"):
        Navigator.from_dataset(ds, RunConfig(coupling="tight"))
    with pytest.raises(ValueError, match="RTK/INS .*has no push API"):
        TightNavigator.from_dataset(ds, RunConfig(coupling="rtk"))
    # a non-finite lever arm keyword: refused at construction, not a NaN state later
    with pytest.raises(ValueError, match=r"lever_arm_b must be 3 finite numbers"):
        Navigator(ds.initial, ds.t0, ds.imu_model, lever_arm_b=[np.nan, 0.0, 0.0])
    # the per-speed sigma terms need the pushed fix's own velocity
    nav = Navigator.from_dataset(ds, RunConfig(gnss_pos_sigma_per_speed_s=0.5))
    g = ds.gnss
    with pytest.raises(ValueError, match="need the fix's velocity"):
        nav.push_gnss_fix(g.t_valid[0], g.lat_deg[0], g.lon_deg[0], g.h_m[0], g.sigma_pos_n[0])
    assert nav.counters["pending_records"] == 0
