"""Self-calibration states: the IMU-GNSS time offset and the GNSS lever arm
estimated by the EKF (``[time] estimate_offset``, ``[lever_arm] estimate``;
docs/algorithms.md section 21), on simulation and on the real walk.

    python3 bench/selfcal_states.py [--runs 20] [--out docs/results/selfcal_states.md]

1. Time offset, loose EKF, simulated car (``car-mems`` drive cut to its first 450 s,
   RTK-grade fixes at 5 Hz): a time offset t_d is injected by re-tagging every
   fix (a fix tagged t holds the antenna at t - t_d); ``--runs`` runs with
   t_d evenly spaced over [-200, +200] ms, one simulator seed each.
   Target: |error| <= 2 ms in every run, rms(error / sigma) in 0.7-1.3.
   1b. The same on the whole 900 s drive.  1c. What sets sigma_td: drive
   length, fix rate, either kind of row switched off, against the bound of
   the velocity rows alone.
2. The state must not hurt at t_d = 0: the same seeds with and without the
   state, rms horizontal position error, paired; target within 2 %; with the
   RTK-grade fixes and with car-mems' own single-frequency fixes; the extra
   error decomposed into v_n t_d^ and the rest, the ratio the state's sigma
   predicts, (RTK-grade) the cost against the prior sigma of t_d, and
   ``estimate_offset = "auto"`` (the state kept only when its estimate is
   significant) against the same target.
3. Lever arm, loose EKF, the whole car-mems drive with the antenna 1.5 m from
   the IMU (turns, stops): the filter starts from a zero lever arm (sigma 1 m);
   target: every component within 3 cm (the horizontal ones on a road drive,
   where the vertical one is weakly observable), rms(error / sigma) per
   component; a truth-independence check of the vertical estimate.
   3a. The same on the drive with roll and pitch excitation (ROCKING): all
   three components within 3 cm.  3b. The vehicle constraints' lever arm.
   3c. A calibration drive (bench/tune_check.py's town drive: a 90 deg turn
   every 16 s), level and with body roll in the turns: the horizontal and the
   all-three 3 cm verdicts.  3d. What sets section 3's horizontal sigma: the
   information turn by turn against the velocity rows' bound, and one thing
   changed at a time (fixes, rows, IMU errors, bias model, prior, yaw rate).
4. Tight EKF (simulated pseudorange and Doppler, the same car): the time
   offset at -100 / +100 ms (reported, no target in the task).
5. Real walk (rtklibexplorer walk_0827): loose on the ``.pos``
   (``tests/data/walk_0827_loose.toml``, 1 fix in 4 to the filter, the rest
   held out) and tight on the RINEX (against the shifted NAV-PVT track): the
   t_d estimate, its sigma and the error without the state, with it and with
   ``"auto"``.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import insnav  # noqa: E402
import insnav.sim as sim  # noqa: E402
from _common import git_commit  # noqa: E402
from _stamps import with_stamp  # noqa: E402

COMMAND = "python3 bench/selfcal_states.py --out docs/results/selfcal_states.md"
DEG = np.pi / 180.0
DURATION_S = 420.0  # [s]: the drive is cut after the segment that reaches it (450 s)

#: the simulated car: car-mems' drive and MEMS IMU, RTK-grade loose fixes at 5 Hz
CAR = {"extends": "car-mems", "name": "selfcal-car",
       "gnss": {"rate_hz": 5.0, "sigma_h_m": 0.02, "sigma_v_m": 0.04, "sigma_vel_mps": 0.02}}


_SEGMENTS = None


#: roll and pitch excitation of the "rocking" drive (section 3a): amplitude [deg], period [s]
ROCKING = {"roll": (5.0, 6.0), "pitch": (5.0, 8.0)}


def car(seed: int, lever_arm_b=(0.0, 0.0, 0.0), raw: bool = False, full: bool = False, gnss=None,
        rocking: bool = False, motion=None, imu=None):
    """The simulated car: car-mems' drive cut after the first segment ending at or after DURATION_S
    (``full``: the whole 900 s drive); ``gnss``: the [gnss] table (default: RTK-grade, CAR);
    ``rocking``: the cut drive with the roll and pitch oscillations ROCKING from 20 s to its end;
    ``motion``: a [motion] table replacing the drive (merged over car-mems' slip and bounce), e.g.
    town_motion(); ``imu``: an [imu] table merged over car-mems' IMU."""
    global _SEGMENTS
    if _SEGMENTS is None:
        segs, tot = [], 0.0
        for seg in sim.load_scenario("car-mems").raw["motion"]["segments"]:
            if tot >= DURATION_S:
                break
            segs.append(seg)
            tot += float(seg["duration_s"])
        _SEGMENTS = segs
    sc = {**CAR, "gnss": {**(CAR["gnss"] if gnss is None else gnss), "lever_arm_b_m": list(lever_arm_b)}}
    if motion is not None:
        sc["motion"] = motion
    elif not full:
        sc["motion"] = {"segments": _SEGMENTS}
    if imu is not None:
        sc["imu"] = imu
    if rocking:
        t_end = sum(float(seg["duration_s"]) for seg in _SEGMENTS)
        sc["motion"]["oscillations"] = [{"axis": ax, "amp_deg": a, "period_s": T, "start_s": 20.0, "end_s": t_end}
                                        for ax, (a, T) in ROCKING.items()]
    if raw:  # simulated pseudorange (3 m) and Doppler (0.05 m/s) at 1 Hz, up to 8 satellites
        sc["gnss_raw"] = {"enabled": True, "max_sats": 8}
    return sim.simulate(sc, seed=seed)


def offset(ds, t_d):
    """The dataset with its GNSS fixes tagged t_d late (fix tagged t = antenna at t - t_d)."""
    g = ds.gnss
    return dataclasses.replace(ds, gnss=dataclasses.replace(g, t_valid=g.t_valid + t_d, t_arrival=g.t_arrival + t_d))


def horizontal_rms(ds, sol):
    tr = ds.truth
    lat = np.interp(tr.t, sol.t, sol.lat_deg)
    lon = np.interp(tr.t, sol.t, sol.lon_deg)
    m = (tr.t >= sol.t[0]) & (tr.t <= sol.t[-1])
    dn = (lat - tr.lat_deg)[m] * DEG * 6.371e6
    de = (lon - tr.lon_deg)[m] * DEG * 6.371e6 * np.cos(tr.lat_deg[0] * DEG)
    return float(np.sqrt(np.mean(dn ** 2 + de ** 2)))


def time_offset_runs(runs: int, full: bool = False):
    """``runs`` offsets evenly over [-200, +200] ms, one seed each; with the state, without it, and
    ``estimate_offset = "auto"`` (whether it kept the state, ``kept``)."""
    rows = []
    for i, t_d in enumerate(np.linspace(-0.2, 0.2, runs)):
        ds = offset(car(100 + i, full=full), t_d)
        sol = insnav.run(ds, time={"estimate_offset": True, "offset_sigma_ms": 250.0}, max_time_offset_s=np.inf)
        est, sig = sol.time_offset_s[-1], sol.sigma_time_offset_s[-1]
        base = insnav.run(ds, max_time_offset_s=np.inf)
        auto = insnav.run(ds, time={"estimate_offset": "auto", "offset_sigma_ms": 250.0}, max_time_offset_s=np.inf)
        rows.append(dict(t_d=t_d, est=est, sigma=sig, err=est - t_d, rms_with=horizontal_rms(ds, sol),
                         rms_without=horizontal_rms(ds, base), kept=auto.summary["time_offset_test"]["state_kept"]))
    return rows


def velocity_row_bound(ds) -> float:
    """The 1-sigma [s] of t_d from the velocity rows alone with a perfectly known INS velocity: the
    rows' t_d column is -a_n (docs/algorithms.md section 21), so the information is
    sum_k sum_axis a_n,axis(t_k)^2 / sigma_v,axis^2 over the fixes k (truth acceleration)."""
    tr, g = ds.truth, ds.gnss
    a = np.gradient(tr.v_n, tr.t, axis=0)
    a_k = np.column_stack([np.interp(g.t_valid, tr.t, a[:, j]) for j in range(3)])
    return float(1.0 / np.sqrt(np.sum(a_k ** 2 / np.asarray(g.sigma_vel_n) ** 2)))


def scale_check(n: int = 6, t_d: float = 0.2):
    """Is the estimate proportional to the truth?  The same seeds (700...) at +t_d and -t_d: the noise
    is the same, so err(+) - err(-) = -2 k t_d measures a scale error k of the estimate (an
    errors-in-variables attenuation by the IMU noise in the -a_n column would show as k > 0)."""
    d = []
    for i in range(n):
        ds = car(700 + i)
        e = []
        for s_ in (1.0, -1.0):
            sol = insnav.run(offset(ds, s_ * t_d), time={"estimate_offset": True, "offset_sigma_ms": 250.0},
                             max_time_offset_s=np.inf)
            e.append(float(sol.time_offset_s[-1] - s_ * t_d))
        d.append(e[0] - e[1])
    d = np.asarray(d)
    k = -d / (2.0 * t_d)
    return dict(n=n, t_d=t_d, k=float(np.mean(k)), k_se=float(np.std(k, ddof=1) / np.sqrt(n)))


def sigma_drivers(seed: int = 100, t_d: float = 0.1):
    """What sets sigma_td: one seed, +100 ms, the filter's sigma at the end with the drive length,
    the fix rate and either kind of row switched off (its sigma x 1e4), next to velocity_row_bound."""
    rate = CAR["gnss"]["rate_hz"]
    variants = [("450 s, 5 Hz (section 1)", dict(), None), ("900 s, 5 Hz (section 1b)", dict(full=True), None),
                ("450 s, 10 Hz", dict(rate=10.0), None), ("450 s, 20 Hz", dict(rate=20.0), None),
                ("450 s, 5 Hz, 1.5 m lever arm (given)", dict(lever_arm_b=(1.0, 0.5, -1.0)), None),
                ("450 s, 5 Hz, velocity rows off", dict(), "sigma_vel_n"),
                ("450 s, 5 Hz, position rows off", dict(), "sigma_pos_n")]
    rows = []
    for label, kw, off in variants:
        kw = dict(kw)
        r = kw.pop("rate", rate)
        CAR["gnss"]["rate_hz"] = r
        try:
            ds = car(seed, **kw)
        finally:
            CAR["gnss"]["rate_hz"] = rate
        bound = velocity_row_bound(ds)
        if off is not None:
            ds = dataclasses.replace(ds, gnss=dataclasses.replace(ds.gnss, **{off: getattr(ds.gnss, off) * 1e4}))
            bound = float("nan") if off == "sigma_vel_n" else bound
        sol = insnav.run(offset(ds, t_d), time={"estimate_offset": True, "offset_sigma_ms": 250.0},
                         max_time_offset_s=np.inf)
        rows.append(dict(label=label, n=len(ds.gnss.t_valid), sigma=float(sol.sigma_time_offset_s[-1]),
                         err=float(sol.time_offset_s[-1] - t_d), bound=bound))
    return rows


#: car-mems' own GNSS: single-frequency fixes, 5 m horizontal, 10 m vertical, 0.15 m/s, 10 Hz
STANDARD_GNSS = {"rate_hz": 10.0, "sigma_h_m": 5.0, "sigma_v_m": 10.0, "sigma_vel_mps": 0.15}


def horizontal_en(ds, sol):
    """(mask of the truth epochs inside the solution, north/east error [m] at them)."""
    tr = ds.truth
    lat = np.interp(tr.t, sol.t, sol.lat_deg)
    lon = np.interp(tr.t, sol.t, sol.lon_deg)
    m = (tr.t >= sol.t[0]) & (tr.t <= sol.t[-1])
    return m, np.column_stack([(lat - tr.lat_deg)[m] * DEG * 6.371e6,
                               (lon - tr.lon_deg)[m] * DEG * 6.371e6 * np.cos(tr.lat_deg[0] * DEG)])


def _rms2(x):
    return float(np.sqrt(np.mean(np.sum(x ** 2, axis=1))))


#: prior sigmas [ms] of the zero-offset sweep (the default, 100 ms, first)
PRIOR_SIGMAS_MS = (100.0, 10.0, 1.0)


def zero_offset_runs(n: int, gnss=None, sigmas_ms=(100.0,)):
    """Paired runs at t_d = 0 without and with the state, for each prior sigma.  Besides the rms,
    the decomposition of the extra error: a fix tagged t is applied at t - t_d^, so the INS is
    pulled v_n t_d^ along the track; ``residual`` is the rms of (error with - error without -
    v_n t_d^), ``shift`` the rms of v_n t_d^, ``predicted`` the rms the state's own sigma implies,
    sqrt(without^2 + mean(|v|^2 sigma_td^2)), ``z`` rms(t_d^ / sigma) along the run (after the first 20 s)."""
    rows = []
    for i in range(n):
        ds = car(200 + i, gnss=gnss)
        tr = ds.truth
        a = insnav.run(ds)
        m, ea = horizontal_en(ds, a)
        auto = insnav.run(ds, time={"estimate_offset": "auto"})
        row = dict(without=_rms2(ea), by_sigma={}, auto=_rms2(horizontal_en(ds, auto)[1]),
                   auto_test=auto.summary["time_offset_test"])
        for s_ms in sigmas_ms:
            b = insnav.run(ds, time={"estimate_offset": True, "offset_sigma_ms": s_ms})
            mb, eb = horizontal_en(ds, b)
            td = np.interp(tr.t[m], b.t, b.time_offset_s)
            sg = np.interp(tr.t[m], b.t, b.sigma_time_offset_s)
            v = tr.v_n[m, :2]
            shift = v * td[:, None]
            late = b.t > b.t[0] + 20.0
            row["by_sigma"][s_ms] = dict(
                with_=_rms2(eb), est=b.time_offset_s[-1], sigma=b.sigma_time_offset_s[-1],
                shift=_rms2(shift), residual=_rms2(eb - ea - shift),
                predicted=float(np.sqrt(row["without"] ** 2 + np.mean(np.sum(v ** 2, axis=1) * sg ** 2))),
                z=float(np.sqrt(np.mean((b.time_offset_s[late] / b.sigma_time_offset_s[late]) ** 2))))
        rows.append(row)
    return rows


def constant_plus_walk(m: dict):
    """The filter's IMU model with each bias a random constant (P0 the total sigma, tau 1e9 s) plus a
    random walk of the simulated Gauss-Markov part's short-term drift, gm_sigma sqrt(2 / gm_tau); the
    default (ImuNoise.from_dataset_model) is one Gauss-Markov state with the total sigma and gm_tau."""
    from insnav.config import ImuNoise

    out = ImuNoise.from_dataset_model(m)
    for p, q in (("gyro", "gyro"), ("accel", "acc")):
        setattr(out, f"{q}_bias_sigma", list(m[f"{p}_bias_total_sigma"]))
        setattr(out, f"{q}_bias_tau", [1e9] * 3)
        setattr(out, f"{q}_bias_rw", (np.asarray(m[f"{p}_gm_sigma"]) * np.sqrt(2.0 / np.asarray(m[f"{p}_gm_tau"]))).tolist())
    return out


def lever_runs(n: int, l_true=(1.0, 0.5, -1.0), rocking: bool = False, seed0: int = 300, motion=None):
    """``rocking``: the 450 s drive with roll and pitch excitation (ROCKING); ``motion``: that [motion]
    table (town_motion: the calibration drive); else the whole 900 s drive.  Also the error / sigma with
    the IMU biases modelled by ``constant_plus_walk`` (``z_cw``)."""
    l_true = np.asarray(l_true, float)
    rows = []
    for i in range(n):
        ds = car(seed0 + i, lever_arm_b=l_true, full=not rocking, rocking=rocking, motion=motion)
        sol = insnav.run(ds, lever_arm_b=[0.0, 0.0, 0.0], lever_arm={"estimate": True, "sigma_m": 1.0})
        fixed_wrong = insnav.run(ds, lever_arm_b=[0.0, 0.0, 0.0])
        fixed_right = insnav.run(ds)
        cw = insnav.run(ds, lever_arm_b=[0.0, 0.0, 0.0], lever_arm={"estimate": True, "sigma_m": 1.0},
                        imu=constant_plus_walk(ds.imu_model))
        m = ds.imu_model
        rows.append(dict(drift_ratio=float(np.max((np.asarray(m["gyro_bias_total_sigma"]) / np.asarray(m["gyro_gm_sigma"])) ** 2)),
                         z_cw=(cw.lever_arm_b_m[-1] - l_true) / cw.sigma_lever_arm_b_m[-1],
                         err_cw=cw.lever_arm_b_m[-1] - l_true,
                         est=sol.lever_arm_b_m[-1], sigma=sol.sigma_lever_arm_b_m[-1],
                         err=sol.lever_arm_b_m[-1] - l_true, rms=horizontal_rms(ds, sol),
                         rms_zero=horizontal_rms(ds, fixed_wrong), rms_true=horizontal_rms(ds, fixed_right),
                         exc=drive_excitation(ds)))
    return l_true, rows


def lever_shrink_check(seed: int = 301, lz=(0.0, -3.0)):
    """The whole drive and one noise realisation with vertical lever arms ``lz``, each run started at its
    truth: a filter whose error does not depend on the truth ends with estimates as far apart as the
    truths (kept share 1); an errors-in-variables bias pulls them towards zero (docs/algorithms.md
    section 21)."""
    est = []
    for z in lz:
        ds = car(seed, lever_arm_b=(0.0, 0.0, z), full=True)
        sol = insnav.run(ds, lever_arm={"estimate": True, "sigma_m": 1.0})
        est.append((float(sol.lever_arm_b_m[-1, 2]), float(sol.sigma_lever_arm_b_m[-1, 2])))
    return lz, est, (est[1][0] - est[0][0]) / (lz[1] - lz[0])


#: roll gradients [deg/g] of the calibration drive with turn roll (section 3c)
ROLL_GRADIENTS_DEG_PER_G = (5.0, 10.0)


def town_motion(roll_gradient_deg_per_g: float = 0.0, n_turns: int | None = None) -> dict:
    """The calibration drive's [motion] table: bench/tune_check.py's town drive (its SIM scenario: from a
    stop to 12 m/s, then 56 x (8 s straight, a 90 deg turn in 8 s, alternately left and right)),
    cut after ``n_turns`` turns if given.  ``roll_gradient_deg_per_g`` > 0: body roll in the turns
    through the simulator's coordinated-turn bank atan(V r / g_ref) (sim/trajectory.py) with
    g_ref = g / k, i.e. k [rad] of roll per g of lateral acceleration for small angles.  That option
    banks the body into the turn (an aircraft's); a car rolls out of it by about the same gradient:
    the lever arm's information is quadratic in the roll angle (C_nb l) and rate (w x l), so to first
    order the sign does not matter.  The simulator has no pitch under braking (its pitch is the
    track's path angle plus oscillations), and the drive holds its speed in the turns."""
    import copy

    import tune_check

    mo = copy.deepcopy(tune_check.SIM["motion"])
    if n_turns is not None:
        mo["segments"] = mo["segments"][:2 + 2 * n_turns]
    if roll_gradient_deg_per_g > 0.0:
        from insnav.units import G0

        mo["coordinated_turns"] = True
        mo["g_ref_mps2"] = G0 / (roll_gradient_deg_per_g * DEG)
    return mo


def drive_excitation(ds, skip_end_s: float = 20.0) -> dict:
    """Peak |roll| [deg], |roll rate| [deg/s], |yaw rate| [deg/s] and horizontal acceleration [g] of a
    simulated drive (truth), its last ``skip_end_s`` left out (the scenario's last segment ends without
    a smoothing transition: a turn ending the drive turns faster); ``t``: the drive's length [s]."""
    tr = ds.truth
    a = np.gradient(tr.v_n, tr.t, axis=0)
    m = tr.t <= tr.t[-1] - skip_end_s
    return dict(roll=float(np.max(np.abs(tr.roll_deg[m]))),
                roll_rate=float(np.max(np.abs(tr.omega_ib_b[m, 0]))) / DEG,
                yaw_rate=float(np.max(np.abs(tr.omega_ib_b[m, 2]))) / DEG,
                a_h=float(np.max(np.hypot(a[m, 0], a[m, 1]))) / 9.80665, t=float(tr.t[-1] - tr.t[0]))


def lever_sigma_drivers(seed: int = 300, l_true=(1.0, 0.5, -1.0)):
    """What sets the horizontal sigma of section 3: the whole car-mems drive, one seed, the filter's
    final sigma (and error) with one thing changed at a time: the fix rate and noise, either row kind
    switched off (its sigma x 1e4), the simulated IMU's errors / 10, the filter's bias model, the
    initial sigma, the turns' yaw rate (turn segments shorter or longer), and the calibration drive."""
    l_true = np.asarray(l_true, float)
    segs = sim.load_scenario("car-mems").raw["motion"]["segments"]

    def turns_x(f):
        return {"segments": [{**sg, "duration_s": sg["duration_s"] * f}
                             if abs(float(sg.get("heading_change_deg", 0.0))) >= 90.0 else sg for sg in segs]}

    g = CAR["gnss"]
    gyro10 = {"gyro": {"arw_deg_per_sqrth": 0.02, "bias_sigma_dph": 3.0, "gm_sigma_dph": 0.05}}
    acc10 = {"accel": {"vrw_mps_per_sqrth": 0.01, "bias_sigma_mg": 0.5, "gm_sigma_mg": 0.2}}
    accb10 = {"accel": {"bias_sigma_mg": 0.5, "gm_sigma_mg": 0.2}}
    variants = [  # label, car() keywords, GNSS sigma scale, run keywords
        ("section 3 (5 Hz fixes, 2 cm / 2 cm/s, lever arm sigma 1 m)", {}, None, {}),
        ("fixes at 1 Hz", dict(gnss={**g, "rate_hz": 1.0}), None, {}),
        ("fixes at 20 Hz", dict(gnss={**g, "rate_hz": 20.0}), None, {}),
        ("position sigma / 2 (1 cm)", dict(gnss={**g, "sigma_h_m": 0.01, "sigma_v_m": 0.02}), None, {}),
        ("velocity sigma / 2 (1 cm/s)", dict(gnss={**g, "sigma_vel_mps": 0.01}), None, {}),
        ("velocity rows off", {}, "sigma_vel_n", {}),
        ("position rows off", {}, "sigma_pos_n", {}),
        ("gyro errors / 10 (ARW, turn-on and Gauss-Markov bias)", dict(imu=gyro10), None, {}),
        ("accelerometer biases / 10 (turn-on and Gauss-Markov)", dict(imu=accb10), None, {}),
        ("accelerometer errors / 10 (biases and VRW)", dict(imu=acc10), None, {}),
        ("gyro and accelerometer errors / 10", dict(imu={**gyro10, **acc10}), None, {}),
        ("filter bias model: constant + random walk", {}, None, dict(cw=True)),
        ("initial sigma 0.1 m", {}, None, dict(sigma_m=0.1)),
        ("initial sigma 10 m", {}, None, dict(sigma_m=10.0)),
        ("turns twice as fast (turn segments x 0.5)", dict(motion=turns_x(0.5)), None, {}),
        ("turns twice as slow (turn segments x 2)", dict(motion=turns_x(2.0)), None, {}),
        ("calibration drive (section 3c, level body)", dict(motion=town_motion()), None, {}),
    ]
    rows = []
    for label, kw, off, rk in variants:
        ds = car(seed, lever_arm_b=l_true, full=True, **kw)
        if off is not None:
            ds = dataclasses.replace(ds, gnss=dataclasses.replace(ds.gnss, **{off: getattr(ds.gnss, off) * 1e4}))
        extra = {"imu": constant_plus_walk(ds.imu_model)} if rk.get("cw") else {}
        sol = insnav.run(ds, lever_arm_b=[0.0, 0.0, 0.0],
                         lever_arm={"estimate": True, "sigma_m": rk.get("sigma_m", 1.0)}, **extra)
        rows.append(dict(label=label, n=len(ds.gnss.t_valid), sigma=sol.sigma_lever_arm_b_m[-1],
                         err=sol.lever_arm_b_m[-1] - l_true, exc=drive_excitation(ds)))
    return rows


def turn_information(seed: int = 300, l_true=(1.0, 0.5, -1.0)):
    """Section 3's run turn by turn: the horizontal sigma (mean of x and y) before each heading change of
    the car-mems drive and after it (20 s on, or 2 s before the next one), the information gained
    1/sigma_after^2 - 1/sigma_before^2 [m^-2], and the velocity rows' bound for it with a perfectly known
    INS: their l_x, l_y columns are C_nb [w x] (docs/algorithms.md section 21), so each fix gives
    (w_z^2 + w_y^2) / sigma_v^2 (truth rates, the fixes within the turn segment and 1 s either side)."""
    l_true = np.asarray(l_true, float)
    ds = car(seed, lever_arm_b=l_true, full=True)
    sol = insnav.run(ds, lever_arm_b=[0.0, 0.0, 0.0], lever_arm={"estimate": True, "sigma_m": 1.0})
    tr, g = ds.truth, ds.gnss
    t0 = float(tr.t[0])
    w_k = np.column_stack([np.interp(g.t_valid, tr.t, tr.omega_ib_b[:, j]) for j in range(3)])
    sv = np.asarray(g.sigma_vel_n)[:, 0]
    sh = np.mean(sol.sigma_lever_arm_b_m[:, :2], axis=1)
    turns, tot = [], 0.0
    for seg in sim.load_scenario("car-mems").raw["motion"]["segments"]:
        d = float(seg["duration_s"])
        if "heading_change_deg" in seg:
            turns.append((seg.get("label", ""), float(seg["heading_change_deg"]), t0 + tot, t0 + tot + d))
        tot += d
    rows = []
    for i, (lab, dpsi, ta, tb) in enumerate(turns):
        t_next = turns[i + 1][2] if i + 1 < len(turns) else sol.t[-1] + 2.0
        s_b = float(np.interp(ta - 1.0, sol.t, sh))
        s_a = float(np.interp(min(tb + 20.0, t_next - 2.0), sol.t, sh))
        m = (g.t_valid >= ta - 1.0) & (g.t_valid <= tb + 1.0)
        bound = float(np.sum((w_k[m, 2] ** 2 + w_k[m, 1] ** 2) / sv[m] ** 2))
        rows.append(dict(label=lab, dpsi=dpsi, dur=tb - ta, r=float(np.max(np.abs(w_k[m, 2]))), before=s_b,
                         after=s_a, gain=1.0 / s_a ** 2 - 1.0 / s_b ** 2, bound=bound))
    m = ds.imu_model
    return rows, float(np.linalg.norm(l_true[:2])), float(np.max(m["accel_bias_total_sigma"]))


def odo_lever_runs(n: int, l0=(-1.3, 0.0, 0.4)):
    """NHC only; the simulator's non-slipping point is the IMU itself (l = 0); the filter starts from
    the rear-axle guess l0 (sigma 1 m)."""
    from insnav.config import Constraints

    rows = []
    for i in range(n):
        ds = car(500 + i)
        con = Constraints(use=["nhc"], lever_arm_b_m=list(l0))
        sol = insnav.run(ds, constraints=con, lever_arm={"estimate_odometer": True, "odometer_sigma_m": 1.0})
        wrong = insnav.run(ds, constraints=con)
        right = insnav.run(ds, constraints=Constraints(use=["nhc"]))
        rows.append(dict(est=sol.odo_lever_arm_b_m[-1], sigma=sol.sigma_odo_lever_arm_b_m[-1],
                         rms=horizontal_rms(ds, sol), rms_wrong=horizontal_rms(ds, wrong),
                         rms_right=horizontal_rms(ds, right)))
    return np.asarray(l0, float), rows


def tight_runs(offsets=(-0.1, 0.1)):
    rows = []
    for j, t_d in enumerate(offsets):
        ds = car(400 + j, raw=True)
        raw = ds.gnss_raw
        ds = dataclasses.replace(ds, gnss_raw=dataclasses.replace(raw, t=np.asarray(raw.t) + t_d))
        sol = insnav.run(ds, coupling="tight", time={"estimate_offset": True, "offset_sigma_ms": 250.0},
                         max_time_offset_s=np.inf)
        base = insnav.run(ds, coupling="tight", max_time_offset_s=np.inf)
        rows.append(dict(t_d=t_d, est=sol.time_offset_s[-1], sigma=sol.sigma_time_offset_s[-1],
                         rms_with=horizontal_rms(ds, sol), rms_without=horizontal_rms(ds, base)))
    return rows


WALK_RUNS = (("without the state", False), ("with the state", True), ("auto", "auto"))


def _walk_row(sol, ref, held=None):
    """Horizontal rms [m] of ``sol`` against ``ref`` (at the ``held`` reference epochs): in the IMU time
    frame (the solution at the reference's tag t) and in the GNSS one (at t - t_d^, where the antenna
    was when a record tagged t was made; the reference is a GNSS record too)."""
    from walk_loose import horizontal

    m = (ref.t > sol.t[0]) & (ref.t <= sol.t[-1])
    h = np.ones(int(m.sum()), bool) if held is None else held(ref.t[m])
    td = 0.0 if sol.time_offset_s is None else float(sol.time_offset_s[-1])
    out = {}
    for key, shift in (("rms", 0.0), ("rms_gnss", td)):
        dn, de = horizontal(ref.t[m] - shift, ref.lat_deg[m], ref.lon_deg[m], sol.t, sol.lat_deg, sol.lon_deg)
        hor = np.hypot(dn, de)[h]
        out[key] = float(np.sqrt(np.mean(hor ** 2)))
    test = sol.summary.get("time_offset_test")
    out.update(n=int(h.sum()), est=None if sol.time_offset_s is None else td,
               sigma=None if sol.time_offset_s is None else float(sol.sigma_time_offset_s[-1]),
               kept=None if test is None else test["state_kept"], z=None if test is None else test["z"])
    return out


def velocity_lag(data: Path):
    """The lag [s] of the walk ``.pos``'s velocity columns behind its own positions: the horizontal
    velocity from central differences of the positions (two fix intervals, centred: no lag of its own)
    against the velocity column read at t + tau, tau over +-300 ms in 5 ms steps; -> (tau minimising
    the rms difference, that rms [m/s], the rms at tau = 0, the full-rate fixes (t, v_n))."""
    d = tomllib.loads((ROOT / "tests" / "data" / "walk_0827_loose.toml").read_text())
    d["gnss"]["decimate"] = 1
    d["gnss"]["velocity_lag_s"] = 0.0  # the column as the file tags it
    ds, _ = insnav.load_csv_dataset(data / "raw" / "imu_1730.csv", data / "raw" / "gnss_1730_sf.pos", d)
    g = ds.gnss
    t, v = np.asarray(g.t_valid, float), np.asarray(g.v_n, float)
    n = (g.lat_deg - g.lat_deg[0]) * DEG * 6.371e6
    e = (g.lon_deg - g.lon_deg[0]) * DEG * 6.371e6 * np.cos(g.lat_deg[0] * DEG)
    dt2 = t[2:] - t[:-2]
    ok = np.abs(dt2 - 2.0 * np.median(np.diff(t))) < 1e-3
    v_d = np.column_stack([(n[2:] - n[:-2]) / dt2, (e[2:] - e[:-2]) / dt2])[ok]
    tc = t[1:-1][ok]
    taus = np.round(np.arange(-0.3, 0.3001, 0.005), 3)
    rms = [float(np.sqrt(np.mean(np.sum((np.column_stack([np.interp(tc + tau, t, v[:, j]) for j in range(2)])
                                          - v_d) ** 2, axis=1)))) for tau in taus]
    k = int(np.argmin(rms))
    return float(taus[k]), rms[k], rms[int(np.argmin(np.abs(taus)))], (t, v)


def walk(data: Path, decimate: int = 4):
    """Loose EKF on the walk, 1 fix in `decimate` to the filter; held-out horizontal rms [m] (WALK_RUNS);
    the run with the state and the .pos velocities unused; and the runs with the velocities re-timed by
    their measured lag (velocity_lag: the velocity of fix t taken from the column at t + lag, the
    reader's ``[gnss] velocity_lag_s``; the other runs read the column as tagged, velocity_lag_s = 0)."""
    from insnav.io.rinex_dataset import rtklib_truth

    out = {}
    pos = data / "raw" / "gnss_1730_sf.pos"
    lag, _, _, _ = velocity_lag(data)
    runs = [(lab, on, True, False) for lab, on in WALK_RUNS] + [
        ("with the state, .pos velocities unused", True, False, False),
        ("velocities re-timed, without the state", False, True, True),
        ("velocities re-timed, with the state", True, True, True),
        ("velocities re-timed, auto", "auto", True, True)]
    for label, on, vel, retime in runs:
        d = tomllib.loads((ROOT / "tests" / "data" / "walk_0827_loose.toml").read_text())
        d["gnss"]["decimate"] = decimate
        d["gnss"]["velocity"] = vel
        d["time"] = {"estimate_offset": on}
        d["gnss"]["velocity_lag_s"] = lag if retime else 0.0
        ds, cfg = insnav.load_csv_dataset(data / "raw" / "imu_1730.csv", pos, d)
        sol = insnav.run(ds, config=cfg)
        ref = rtklib_truth(str(pos), ds.gps_time_offset_s)
        seen = np.round(ds.gnss.t_valid, 3)
        out[label] = _walk_row(sol, ref, held=lambda t: ~np.isin(np.round(t, 3), seen))
        out[label]["track"] = sol if label == "with the state" else None
    return out


def walk_tight(data_root: Path):
    """Tight EKF on the walk's RINEX (GPS L1 pseudorange and Doppler, tests/data/walk_0827.toml), WALK_RUNS;
    reference: the receiver's NAV-PVT track moved by the mean single-point offset of the RTK .pos's base
    (bench/walk_reference_check.py, as in docs/results/tune.md)."""
    from insnav.io.rinex_dataset import load_rinex_run, rtklib_truth
    from walk_reference_check import reference_experiment

    w = data_root / "rtklibexplorer_walk_0827"
    ds, cfg = load_rinex_run(w / "rinex_derived" / "gnss_1730.obs", w / "rinex_derived" / "gnss_1730.nav",
                             w / "raw" / "imu_1730.csv", ROOT / "tests" / "data" / "walk_0827.toml")
    cfg = dataclasses.replace(cfg, coupling="tight", filter="ekf")
    x = reference_experiment(data_root)
    ref = rtklib_truth(x["pvt_shifted"], ds.gps_time_offset_s)
    out = {}
    for label, on in WALK_RUNS:
        sol = insnav.run(ds, config=dataclasses.replace(cfg, time=dataclasses.replace(cfg.time, estimate_offset=on)))
        out[label] = _walk_row(sol, ref)
    return out, x["shift_neu"]


def seeds_txt(seed0: int, n: int) -> str:
    return f"{seed0}" if n == 1 else f"{seed0}-{seed0 + n - 1}"


def n_turns_txt(n: int) -> str:
    return f"{n} turn" + ("" if n == 1 else "s")


def verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=20, help="time-offset runs (offsets evenly over +-200 ms)")
    ap.add_argument("--zero-runs", type=int, default=10)
    ap.add_argument("--lever-runs", type=int, default=5)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    lines = ["# Self-calibration states: IMU-GNSS time offset and GNSS lever arm", "",
             f"Commit `{git_commit()}`; command `{COMMAND}`" + (f" (`--runs {args.runs}`)" if args.runs != 20 else "")
             + ".", "",
             "The EKF estimates the IMU-GNSS time offset t_d (a GNSS record tagged t holds the antenna at",
             "IMU time t - t_d; `[time] estimate_offset`) and the GNSS lever arm (`[lever_arm] estimate`)",
             "as extra states (docs/algorithms.md section 21).  Simulation: the `car-mems` drive (MEMS IMU",
             "200 Hz, a stop, two 90 deg turns, a gentle curve) cut to its first 450 s, with RTK-grade loose fixes (5 Hz,",
             "2 cm horizontal, 4 cm vertical, 2 cm/s), one simulator seed per run; the offset is injected by",
             "re-tagging the fixes.  Errors are of the last estimate, horizontal position errors rms over",
             "the run against the simulator's truth.", ""]

    # 1. time offset
    print("time offset runs ...", file=sys.stderr, flush=True)

    def offset_table(rows):
        err = np.array([r["err"] for r in rows])
        z = err / np.array([r["sigma"] for r in rows])
        worst = float(np.max(np.abs(err)))
        cons = float(np.sqrt(np.mean(z ** 2)))
        out = ["| injected t_d [ms] | estimate [ms] | error [ms] | sigma [ms] | error / sigma | "
               "horizontal rms with the state [m] | without [m] | auto keeps the state |",
               "|---|---|---|---|---|---|---|---|"]
        for r in rows:
            out.append(f"| {1e3 * r['t_d']:+.1f} | {1e3 * r['est']:+.3f} | {1e3 * r['err']:+.3f} | "
                       f"{1e3 * r['sigma']:.3f} | {r['err'] / r['sigma']:+.2f} | {r['rms_with']:.3f} | "
                       f"{r['rms_without']:.3f} | {'yes' if r['kept'] else 'no'} |")
        kept = sum(r["kept"] for r in rows)
        out += ["", f"Largest |error| {1e3 * worst:.3f} ms (target 2 ms: {verdict(worst <= 2e-3)}); "
                    f"rms(error / sigma) over the {len(rows)} runs {cons:.2f} (target 0.7-1.3: "
                    f"{verdict(0.7 <= cons <= 1.3)}).  `estimate_offset = \"auto\"` (section 2) kept the state in "
                    f"{kept} of {len(rows)} runs.", ""]
        return out, worst, cons

    rows = time_offset_runs(args.runs)
    tab, worst_cut, cons_cut = offset_table(rows)
    lines += ["## 1. Time offset, loose EKF, simulated car", "",
              "Initial t_d^ = 0 with sigma 250 ms, random constant.", ""] + tab

    rows_full = time_offset_runs(args.runs, full=True)
    tab, worst_full, cons_full = offset_table(rows_full)
    lines += ["### 1b. The whole car-mems drive", "",
              "The same runs (seeds, offsets, fixes) on the whole 900 s drive (four 90 deg turns, a U-turn, grades "
              "of +-2 deg) instead of its first 450 s.", ""] + tab

    print("sigma drivers ...", file=sys.stderr, flush=True)
    drv = sigma_drivers()
    lines += ["### 1c. What sets sigma_td", "",
              "One seed (100), t_d = +100 ms; the filter's sigma at the end of the run, and the bound the velocity "
              "rows alone would give with a perfectly known INS velocity: their t_d column is -a_n, so "
              "sigma >= 1 / sqrt(sum over fixes and axes of a_n^2 / sigma_v^2) (truth acceleration at the fixes; "
              "`bench/selfcal_states.py` velocity_row_bound).  A row kind is switched off by multiplying its "
              "sigma by 1e4.", "",
              "| drive, fix rate, rows | fixes | sigma [ms] | error [ms] | velocity-row bound [ms] | sigma / bound |",
              "|---|---|---|---|---|---|"]
    for r in drv:
        lines.append(f"| {r['label']} | {r['n']} | {1e3 * r['sigma']:.3f} | {1e3 * r['err']:+.3f} | "
                     + ("- | - |" if not np.isfinite(r["bound"]) else
                        f"{1e3 * r['bound']:.3f} | {r['sigma'] / r['bound']:.2f} |"))
    base, lever, vel_off, pos_off = drv[0], drv[4], drv[5], drv[6]
    lines += ["", f"The velocity rows carry the information: without them sigma is {1e3 * vel_off['sigma']:.2f} ms, "
                  f"without the position rows {1e3 * pos_off['sigma']:.2f} ms (both: {1e3 * base['sigma']:.2f} ms).  "
                  "On a straight line at constant speed a time offset is an along-track position offset the position "
                  "rows cannot tell from an INS position error; what separates them is the acceleration, here "
                  "mostly the car's small random lateral slip and vertical bounce and the speed changes, through "
                  "the -a_n column of the velocity rows.  sigma_td therefore falls as 1 / sqrt(number of fixes) "
                  f"(x {drv[2]['sigma'] / base['sigma']:.2f} at twice the fix rate, x "
                  f"{drv[3]['sigma'] / base['sigma']:.2f} at four times, x {drv[1]['sigma'] / base['sigma']:.2f} "
                  "on the twice longer drive) and as sigma_v / rms(a); the filter stays "
                  f"{base['sigma'] / base['bound']:.1f} times above the bound because it must also estimate the "
                  "INS velocity error from the same rows.  The bound is set by the data (the fixes' velocity "
                  "noise, their rate, the motion), not by the model.  2 ms in every one of 20 runs needs a sigma "
                  "near 0.7 ms (2 ms / 2.8, about the largest |z| of 20 normal draws); the whole drive gives "
                  f"{1e3 * np.mean([r['sigma'] for r in rows_full]):.2f} ms (largest |error| "
                  f"{1e3 * worst_full:.3f} ms: {verdict(worst_full <= 2e-3)}), the 450 s cut "
                  f"{1e3 * np.mean([r['sigma'] for r in rows]):.2f} ms.  A 1.5 m lever arm (known to the "
                  f"filter; its own acceleration is left out of a_n, docs/algorithms.md section 21) gives sigma "
                  f"{1e3 * lever['sigma']:.2f} ms and an error of {1e3 * lever['err']:+.2f} ms.", ""]
    sc = scale_check()
    lines += [f"Scale of the estimate: the same {sc['n']} seeds and noise at +{1e3 * sc['t_d']:.0f} and "
              f"-{1e3 * sc['t_d']:.0f} ms give estimate = (1 - k) t_d with k = {100 * sc['k']:+.3f} % +- "
              f"{100 * sc['k_se']:.3f} % (a bias of {1e3 * sc['k'] * sc['t_d']:+.2f} ms at {1e3 * sc['t_d']:.0f} ms): "
              "the -a_n column takes the acceleration of the current IMU increment, whose noise (the MEMS "
              "accelerometer's white noise at 200 Hz) could attenuate the estimate as an error in the "
              "regressor; the H columns themselves match numerical derivatives (loose position and velocity "
              "rows, tight pseudorange and Doppler rows: cpp/tests/test_selfcal_jacobian.cpp).", ""]

    # 2. zero offset
    print("zero offset runs ...", file=sys.stderr, flush=True)
    lines += ["## 2. Zero offset: the state must not hurt", "",
              "The same fixes (t_d = 0), paired by seed; default time-offset settings (sigma 100 ms), with the",
              "RTK-grade fixes above and with car-mems' own single-frequency fixes (5 m, 0.15 m/s, 10 Hz).",
              "Where the extra error comes from: a fix tagged t is applied at t - t_d^, so an estimate t_d^ != 0",
              "pulls the INS v_n t_d^ along the track.  'v t_d^' is the rms of that shift along the run,",
              "'unexplained' the rms of (error with - error without - v_n t_d^); 'predicted' the rms the state's",
              "own sigma implies, sqrt(rms_without^2 + mean(|v|^2 sigma_td^2)); 'z' rms(t_d^ / sigma) along the",
              "run after the first 20 s (the truth is 0).", ""]
    auto_tests = []
    for label, gnss in (("RTK-grade fixes", None), ("single-frequency fixes", STANDARD_GNSS)):
        sig = PRIOR_SIGMAS_MS if gnss is None else PRIOR_SIGMAS_MS[:1]
        zr = zero_offset_runs(args.zero_runs, gnss, sig)
        s0 = sig[0]
        b = [r["by_sigma"][s0] for r in zr]
        w = np.array([x["with_"] for x in b])
        wo = np.array([r["without"] for r in zr])
        ratio = w / wo
        lines += [f"{label}:", "",
                  "| seed | rms without the state [m] | with [m] | ratio | t_d estimate [ms] | sigma [ms] | "
                  "v t_d^ [m] | unexplained [m] | predicted ratio | z |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for i, (r, x) in enumerate(zip(zr, b)):
            lines.append(f"| {200 + i} | {r['without']:.4f} | {x['with_']:.4f} | {ratio[i]:.4f} | "
                         f"{1e3 * x['est']:+.3f} | {1e3 * x['sigma']:.3f} | {x['shift']:.4f} | "
                         f"{x['residual']:.4f} | {x['predicted'] / r['without']:.3f} | {x['z']:.2f} |")
        worst_ratio = float(np.max(ratio))
        shift = float(np.sqrt(np.mean([x["shift"] ** 2 for x in b])))
        rest = float(np.sqrt(np.mean([x["residual"] ** 2 for x in b])))
        pred = np.mean([x["predicted"] / r["without"] for r, x in zip(zr, b)])
        zz = float(np.sqrt(np.mean([x["z"] ** 2 for x in b])))
        lines += ["", f"{label}: mean ratio {np.mean(ratio):.4f}, largest {worst_ratio:.4f} (target: within 2 %, "
                      f"i.e. <= 1.02: {verdict(worst_ratio <= 1.02)}).  Difference of the two runs' errors: "
                      f"v_n t_d^ {shift:.4f} m rms over the seeds, the rest {rest:.4f} m "
                      f"({100 * rest / np.sqrt(np.mean(wo ** 2)):.1f} % of the error without the state).  The "
                      f"estimate is {'consistent' if 0.5 <= zz <= 1.3 else 'NOT consistent'} with its sigma (z "
                      f"{zz:.2f} over the seeds, 0.5-1.3); the ratio its sigma predicts is {pred:.3f} (measured "
                      f"{np.mean(ratio):.3f}).  A filter that must learn t_d pays v sigma_td along the track "
                      f"({1e3 * np.mean([x['sigma'] for x in b]):.2f} ms at the end: "
                      f"{15 * np.mean([x['sigma'] for x in b]) * 100:.1f} cm at 15 m/s); the run without the state "
                      "is given t_d = 0 exactly.", ""]
        # estimate_offset = "auto": the Wald test on the run with the state (docs/algorithms.md section 21)
        ra = np.array([r["auto"] for r in zr]) / wo
        kept = [r["auto_test"]["state_kept"] for r in zr]
        auto_tests.append((label, ra, kept, zr[0]["auto_test"]["threshold_z"]
                           * float(np.mean([r["auto_test"]["sigma_ms"] for r in zr]))))
        lines += [f"{label}, `[time] estimate_offset = \"auto\"` (false-alarm rate "
                  f"{zr[0]['auto_test']['false_alarm']:g}: the state is kept when |t_d^ / sigma| > "
                  f"{zr[0]['auto_test']['threshold_z']:.3f}):", "",
                  "| seed | t_d^ / sigma | state kept | rms auto [m] | ratio auto / without |", "|---|---|---|---|---|"]
        for i, r in enumerate(zr):
            lines.append(f"| {200 + i} | {r['auto_test']['z']:+.2f} | {'yes' if r['auto_test']['state_kept'] else 'no'} "
                         f"| {r['auto']:.4f} | {ra[i]:.4f} |")
        lines += ["", f"{label}, auto: kept the state in {sum(kept)} of {len(kept)} runs; mean ratio "
                      f"{np.mean(ra):.4f}, largest {np.max(ra):.4f} (target: within 2 %: "
                      f"{verdict(float(np.max(ra)) <= 1.02)}).", ""]
        if len(sig) > 1:
            lines += [f"{label}, the cost against the prior sigma of t_d (`[time] offset_sigma_ms`; the same seeds):", "",
                      "| prior sigma [ms] | mean ratio | largest ratio | sigma at the end [ms] | predicted ratio |",
                      "|---|---|---|---|---|"]
            for s_ms in sig:
                bb = [r["by_sigma"][s_ms] for r in zr]
                rr = np.array([x["with_"] for x in bb]) / wo
                lines.append(f"| {s_ms:g} | {np.mean(rr):.4f} | {np.max(rr):.4f} | "
                             f"{1e3 * np.mean([x['sigma'] for x in bb]):.3f} | "
                             f"{np.mean([x['predicted'] / r['without'] for r, x in zip(zr, bb)]):.3f} |")
            worst = {s_ms: float(np.max([r["by_sigma"][s_ms]["with_"] / r["without"] for r in zr])) for s_ms in sig}
            ok = [s_ms for s_ms in sig if worst[s_ms] <= 1.02]
            lines += ["", (f"Every seed within 2 % at a prior sigma of {max(ok):g} ms." if ok else
                           f"No prior sigma of the sweep keeps every seed within 2 %: at {min(sig):g} ms the largest "
                           f"ratio is {worst[min(sig)]:.4f}, the mean "
                           f"{np.mean([r['by_sigma'][min(sig)]['with_'] / r['without'] for r in zr]):.4f}.")
                      + "  Estimate the offset where it is actually unknown (docs/algorithms.md section 21).", ""]

    n_all = sum(len(k) for _, _, k, _ in auto_tests)
    fa = sum(sum(k) for _, _, k, _ in auto_tests)
    worst_auto = max(float(np.max(ra)) for _, ra, _, _ in auto_tests)
    lines += [f"Zero offset, auto, both fix grades: the state kept in {fa} of {n_all} runs (false alarms; "
              f"{zr[0]['auto_test']['false_alarm'] * n_all:.2f} expected), largest ratio {worst_auto:.4f} "
              f"(within 2 %: {verdict(worst_auto <= 1.02)}); with an offset (sections 1, 1b) auto kept the state in "
              f"{sum(r['kept'] for r in rows + rows_full)} of {len(rows) + len(rows_full)} runs.  A run the test "
              "sends back to t_d = 0 is the run without the state bit for bit (tests/test_selfcal.py); the price "
              "is the offsets below the detection threshold, which auto leaves uncorrected: the threshold times "
              "sigma_td, " + ", ".join(f"{thr:.1f} ms with the {lab}" for lab, _, _, thr in auto_tests)
              + " (an offset at the threshold is kept half of the time).", ""]

    # 3. lever arm
    print("lever arm runs ...", file=sys.stderr, flush=True)

    def lever_table(lr, seed0):
        out = ["| seed | estimate [m] | error [cm] | sigma [cm] | horizontal rms: estimated [m] | "
               "zero lever arm, not estimated [m] | true lever arm given [m] |",
               "|---|---|---|---|---|---|---|"]
        for i, r in enumerate(lr):
            out.append(f"| {seed0 + i} | {np.round(r['est'], 4).tolist()} | {np.round(100 * r['err'], 2).tolist()} | "
                       f"{np.round(100 * r['sigma'], 2).tolist()} | {r['rms']:.3f} | {r['rms_zero']:.3f} | "
                       f"{r['rms_true']:.3f} |")
        errs = np.array([r["err"] for r in lr])
        z = errs / np.array([r["sigma"] for r in lr])
        return out, errs, np.sqrt(np.mean(z ** 2, axis=0))

    def cw_line(lr):
        rz = np.sqrt(np.mean(np.array([r["z_cw"] for r in lr]) ** 2, axis=0))
        w = np.max(np.abs([r["err_cw"] for r in lr]), axis=0)
        return ("With the IMU biases modelled as a random constant plus a random walk of the simulated "
                "Gauss-Markov drift (`bench/selfcal_states.py` constant_plus_walk; the default model, "
                "`ImuNoise.from_dataset_model`, makes each bias one Gauss-Markov state with the total sigma and "
                f"the simulated correlation time, {lr[0]['drift_ratio']:.0f} times the gyro's simulated drift rate): "
                "largest error per "
                f"component {', '.join(f'{100 * v:.2f}' for v in w)} cm, rms(error / sigma) "
                + ", ".join(f"{c} {v:.2f} ({consistent(v)})" for c, v in zip("xyz", rz)) + ".")

    def consistent(rz):
        return "consistent" if 0.5 <= rz <= 1.5 else "NOT consistent"

    l_true, lr = lever_runs(args.lever_runs)
    tab, errs, rz = lever_table(lr, 300)
    worst_c = np.max(np.abs(errs), axis=0)
    worst_h = float(np.max(worst_c[:2]))
    lines += ["## 3. Lever arm, loose EKF, simulated car", "",
              f"True lever arm {np.round(l_true, 3).tolist()} m (|l| = {np.linalg.norm(l_true):.2f} m); the whole "
              "900 s drive (four 90 deg turns, a U-turn, grades of +-2 deg, no banking); the filter starts from zero "
              "with sigma 1 m per axis, random constant.", ""] + tab
    lines += ["", f"Largest error per component (x, y, z): {', '.join(f'{100 * v:.2f}' for v in worst_c)} cm.  "
                  f"Horizontal (x, y) components: {100 * worst_h:.2f} cm (target 3 cm: {verdict(worst_h <= 0.03)}); "
                  f"all three: {100 * float(np.max(worst_c)):.2f} cm ({verdict(float(np.max(worst_c)) <= 0.03)}).  "
                  "rms(error / sigma) over the seeds per component: "
                  + ", ".join(f"{c} {v:.2f} ({consistent(v)}, 0.5-1.5)" for c, v in zip("xyz", rz)) + ".  "
                  f"On a road drive the vertical component is weakly observable (sigma "
                  f"{100 * np.mean([r['sigma'][2] for r in lr]):.0f} cm at the end): it moves the antenna's "
                  "height exactly as the INS height does, and is told apart only through the small pitch changes "
                  "of the grades (C_nb l in the position rows) and the roll and pitch rates (omega x l in the "
                  "velocity rows), which a car hardly has (docs/algorithms.md section 21, observability).  "
                  "This drive has few turns: what sets its horizontal sigma is in section 3d, a calibration drive "
                  "with many turns in 3c.", "",
              cw_line(lr), ""]

    lz, est, kept = lever_shrink_check()
    lines += ["Truth-independence check (seed 301, the whole drive, antenna straight above the IMU): vertical lever "
              "arms of " + " and ".join(f"{z:g} m" for z in lz) + ", each run started at its truth, end at "
              + " and ".join(f"{e:+.3f} +- {s_:.3f} m" for e, s_ in est)
              + f": {kept:.3f} of the difference kept (1 for a filter whose error does not depend on the truth; "
              f"{verdict(abs(kept - 1) <= 0.1)} within 10 %).  The velocity rows' lever-arm columns take a "
              "low-passed angular rate without the current IMU increment (engine/closed_loop.hpp, "
              "omega_ib_b_lever): the increment's own rate, whose gyro white noise the residual also holds, "
              "is an errors-in-variables bias towards zero.", ""]

    # 3a. rocking drive: all three components observable
    l_true, rr = lever_runs(args.lever_runs, rocking=True, seed0=600)
    tab, errs, rz = lever_table(rr, 600)
    worst_c = np.max(np.abs(errs), axis=0)
    worst = float(np.max(worst_c))
    lines += ["### 3a. Lever arm with roll and pitch excitation", "",
              "The first 450 s of the drive with roll and pitch oscillations from 20 s on ("
              + ", ".join(f"{ax} {a:g} deg at a {T:g} s period" for ax, (a, T) in ROCKING.items())
              + "; a vessel in swell, an aircraft, or a calibration drive over a rough track): the roll and pitch "
              "rates make omega x l see every component in the velocity rows.  Same IMU, fixes and filter "
              "settings as above.", ""] + tab
    lines += ["", f"Largest error per component (x, y, z): {', '.join(f'{100 * v:.2f}' for v in worst_c)} cm; "
                  f"all three components within 3 cm: {verdict(worst <= 0.03)}.  rms(error / sigma) over the seeds "
                  "per component: " + ", ".join(f"{c} {v:.2f} ({consistent(v)})" for c, v in zip("xyz", rz)) + ".",
              "", cw_line(rr), ""]

    # 3b. odometer (vehicle-constraint) lever arm
    l0, orows = odo_lever_runs(max(1, args.lever_runs // 2))
    lines += ["### 3b. Lever arm of the vehicle constraints' point (NHC), loose EKF", "",
              "The simulator's car does not slip sideways at the IMU itself (true lever arm 0); NHC at 1 Hz",
              f"(`[constraints] use = [\"nhc\"]`), the filter starting from the rear-axle guess {l0.tolist()} m with",
              "sigma 1 m (`[lever_arm] estimate_odometer`).", "",
              "| seed | estimate [m] | sigma [m] | horizontal rms: estimated [m] | guess kept [m] | true (0) given [m] |",
              "|---|---|---|---|---|---|"]
    for i, r in enumerate(orows):
        lines.append(f"| {500 + i} | {np.round(r['est'], 3).tolist()} | {np.round(r['sigma'], 3).tolist()} | "
                     f"{r['rms']:.3f} | {r['rms_wrong']:.3f} | {r['rms_right']:.3f} |")
    lines.append("")

    # 3c. the calibration drive: many turns, with and without body roll
    print("calibration drive runs ...", file=sys.stderr, flush=True)
    drives = [("level body", 0.0)] + [(f"turn roll {k:g} deg/g", k) for k in ROLL_GRADIENTS_DEG_PER_G]
    town = {lab: lever_runs(args.lever_runs, seed0=800, motion=town_motion(k))[1] for lab, k in drives}
    exc = {lab: town[lab][0]["exc"] for lab, _ in drives}
    lines += ["### 3c. A calibration drive: a town drive with a 90 deg turn every 16 s", "",
              "What a user would drive to calibrate the lever arm: `bench/tune_check.py`'s town drive (its `SIM` "
              "scenario's motion, `town_motion` here: from a stop to 12 m/s, then 56 times an 8 s straight and a "
              f"90 deg turn in 8 s, alternately left and right; {exc['level body']['t']:.0f} s, yaw rate "
              f"{exc['level body']['yaw_rate']:.1f} deg/s, peak horizontal acceleration "
              f"{exc['level body']['a_h']:.2f} g), with section 3's IMU (car-mems), fixes (5 Hz, 2 cm / 2 cm/s) "
              f"and filter settings (from zero, sigma 1 m), seeds {seeds_txt(800, args.lever_runs)}, the same true "
              "lever arm.  Three bodies: level (the simulator's car keeps its body on the track's attitude: no "
              "roll in turns), and a body that rolls in the turns by a roll gradient of "
              + " and ".join(f"{k:g} deg/g (peak roll {exc[lab]['roll']:.2f} deg, roll rate "
                             f"{exc[lab]['roll_rate']:.2f} deg/s)" for lab, k in drives[1:])
              + ": passenger cars roll a few degrees per g of lateral acceleration.  The roll comes from the "
              "simulator's coordinated-turn bank atan(V r / g_ref) with g_ref = g / gradient; that bank leans "
              "into the turn, a car's body out of it, and the lever arm's information is quadratic in the roll "
              "angle (C_nb l) and rate (w x l), so to first order the sign does not matter.  The simulator has "
              "no pitch under braking or acceleration (its pitch is the track's path angle plus explicit "
              "oscillations), and this drive keeps its speed through the turns: no pitch excitation here.", "",
              "| body | seeds | largest error x, y, z [cm] | mean sigma x, y, z [cm] | rms(error / sigma) x, y, z | "
              "horizontal within 3 cm | all three within 3 cm |", "|---|---|---|---|---|---|---|"]
    town_tabs, town_ok = [], {}
    for lab, k in drives:
        tr_ = town[lab]
        tab, errs, rz = lever_table(tr_, 800)
        worst_c = np.max(np.abs(errs), axis=0)
        sig_c = np.mean([r["sigma"] for r in tr_], axis=0)
        ok_h, ok_all = bool(np.max(worst_c[:2]) <= 0.03), bool(np.max(worst_c) <= 0.03)
        town_ok[lab] = (ok_h, ok_all, sig_c)
        lines.append(f"| {lab} | {len(tr_)} | {', '.join(f'{100 * v:.2f}' for v in worst_c)} | "
                     f"{', '.join(f'{100 * v:.2f}' for v in sig_c)} | {', '.join(f'{v:.2f}' for v in rz)} | "
                     f"{verdict(ok_h)} | {verdict(ok_all)} |")
        town_tabs += [f"Per seed, {lab}:", ""] + tab + ["", cw_line(tr_), ""]
    lev = town_ok["level body"]
    lines += ["", f"On the level body the horizontal components are within 3 cm: {verdict(lev[0])} (sigma "
                  f"{100 * lev[2][0]:.2f} cm, against {100 * np.mean([r['sigma'][0] for r in lr]):.2f} cm on "
                  f"section 3's drive); the vertical one stays weakly observable (sigma {100 * lev[2][2]:.0f} cm) "
                  "as on any level drive.  With turn roll: "
                  + "; ".join(f"{lab}, vertical sigma {100 * town_ok[lab][2][2]:.2f} cm, all three within 3 cm: "
                              f"{verdict(town_ok[lab][1])}" for lab, _ in drives[1:])
                  + ".  Section 3's drive (car-mems: four 90 deg turns and a U-turn in 900 s) is kept as the weakly "
                  "excited case.", ""] + town_tabs

    # 3d. what sets the horizontal sigma of section 3
    print("lever-arm sigma drivers ...", file=sys.stderr, flush=True)
    ti, l_h, acc_b = turn_information()
    lines += ["### 3d. What sets the horizontal sigma of section 3", "",
              "Section 3's run (seed 300) turn by turn: the horizontal sigma (mean of x and y) before each heading "
              "change and after it (20 s on, or 2 s before the next one), the information gained "
              "1/sigma_after^2 - 1/sigma_before^2, and the velocity rows' bound for it with a perfectly known INS "
              "(their l_x, l_y columns are C_nb [w x]: each fix gives (w_z^2 + w_y^2) / sigma_v^2; "
              "`bench/selfcal_states.py` turn_information).", "",
              "| turn | heading change [deg] | duration [s] | peak yaw rate r [deg/s] | sigma before -> after [cm] | "
              "information gained [m^-2] | gained / r^2 [s^2 m^-2] | velocity-row bound [m^-2] | bound / gained |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in ti:
        lines.append(f"| {r['label']} | {r['dpsi']:+.0f} | {r['dur']:.0f} | {r['r'] / DEG:.2f} | "
                     f"{100 * r['before']:.2f} -> {100 * r['after']:.2f} | {r['gain']:.0f} | "
                     f"{r['gain'] / r['r'] ** 2:.0f} | {r['bound']:.0f} | {r['bound'] / r['gain']:.1f} |")
    big = [r for r in ti if abs(r["dpsi"]) >= 90.0]
    c = float(np.median([r["gain"] / r["r"] ** 2 for r in big]))
    r_i = np.array([abs(float(sg["heading_change_deg"])) / float(sg["duration_s"]) * DEG
                    for sg in town_motion()["segments"] if "heading_change_deg" in sg])
    n_town, r_town = len(r_i), float(np.median(r_i))
    pred = 1.0 / np.sqrt(c * np.sum(r_i ** 2))
    r1 = big[0]["r"]
    lines += ["", "Every turn of 90 deg or more gains about the same information per squared yaw rate (gained / r^2 "
                  f"from {min(r['gain'] / r['r'] ** 2 for r in big):.0f} to "
                  f"{max(r['gain'] / r['r'] ** 2 for r in big):.0f}), whatever its angle and length (the U-turn: "
                  "twice the angle, the same ratio), and "
                  f"{min(r['bound'] / r['gain'] for r in big):.0f}-{max(r['bound'] / r['gain'] for r in big):.0f} "
                  "times less than the velocity rows would give with a known INS.  The reason is kinematic: the "
                  "antenna's acceleration relative to the IMU is d^2(C_nb l)/dt^2 = C_nb (w x (w x l) + w' x l); in "
                  "a steady turn (w = r z, w' = 0) that is C_nb (-r^2 l_h), a body-fixed acceleration, exactly what "
                  "a horizontal accelerometer bias b = -r^2 l_h produces.  Through the whole steady part of a turn "
                  "the lever arm and an accelerometer bias give the same antenna velocity and position (up to the "
                  "constants the INS velocity and position errors absorb); only the turn's entry and exit (w' != 0) "
                  "and the bias's own observability on the straights (against the tilt, which does not rotate with "
                  "the body) tell them apart.  So each turn adds information proportional to r^2, not to its "
                  f"duration or number of fixes: in section 3's first turn r^2 |l_h| = "
                  f"{r1 ** 2 * l_h / 9.80665e-3:.2f} mg, against the simulated accelerometer's total bias sigma "
                  f"{acc_b / 9.80665e-3:.1f} mg.  The calibration drive's {n_turns_txt(n_town)} at "
                  f"{r_town / DEG:.2f} deg/s (heading change / duration) predict, at the median ratio {c:.0f}, "
                  "a horizontal sigma of "
                  f"{100 * pred:.2f} cm; the filter gives {100 * float(np.mean(lev[2][:2])):.2f} cm (3c).", "",
              "One thing changed at a time on section 3's drive (seed 300; the drive's own sigma in the first row; "
              "`bench/selfcal_states.py` lever_sigma_drivers):", "",
              "| change | fixes | sigma x, y, z [cm] | horizontal sigma / section 3's | error x, y [cm] |",
              "|---|---|---|---|---|"]
    drv_l = lever_sigma_drivers()
    s0 = float(np.mean(drv_l[0]["sigma"][:2]))
    for r in drv_l:
        lines.append(f"| {r['label']} | {r['n']} | {', '.join(f'{100 * v:.2f}' for v in r['sigma'])} | "
                     f"{float(np.mean(r['sigma'][:2])) / s0:.2f} | "
                     f"{', '.join(f'{100 * v:+.2f}' for v in r['err'][:2])} |")
    q = {r["label"].split(" (")[0]: float(np.mean(r["sigma"][:2])) / s0 for r in drv_l}
    both = q["gyro and accelerometer errors / 10"]
    lines += ["", "Read with the kinematics above: the turns' yaw rate sets the horizontal sigma (x "
                  f"{q['turns twice as fast']:.2f} with the turns twice as fast, x {q['turns twice as slow']:.2f} "
                  "twice as slow: sigma ~ 1 / r), then the accelerometer's biases, which the steady turn "
                  f"confuses with the lever arm (x {q['accelerometer biases / 10']:.2f} with them / 10, x "
                  f"{q['filter bias model: constant + random walk']:.2f} with the filter's bias model closer to "
                  "the simulated one); the gyro's errors alone do "
                  + ("nothing" if q["gyro errors / 10"] > 0.95 else "little")
                  + f" (x {q['gyro errors / 10']:.2f}), with the accelerometer's / 10 too they count (x {both:.2f} "
                  f"against x {q['accelerometer errors / 10']:.2f}).  The fixes matter less than 1 / sqrt(number): x "
                  f"{q['fixes at 20 Hz']:.2f} at four times the rate, x {q['position sigma / 2']:.2f} and x "
                  f"{q['velocity sigma / 2']:.2f} with the position or velocity sigma halved; either row kind "
                  f"alone still gives x {q['velocity rows off']:.2f} (position rows) and x "
                  f"{q['position rows off']:.2f} (velocity rows).  The initial sigma does not matter (x "
                  f"{q['initial sigma 10 m']:.2f} from 10 m; a 0.1 m prior is itself information, x "
                  f"{q['initial sigma 0.1 m']:.2f}).  More turns and faster ones are the lever: x "
                  f"{q['calibration drive']:.2f} on the calibration drive (3c).", ""]

    # 4. tight
    print("tight runs ...", file=sys.stderr, flush=True)
    tr = tight_runs()
    lines += ["## 4. Time offset, tight EKF (simulated pseudorange and Doppler)", "",
              "The same car with the simulator's raw GNSS (`[gnss_raw] enabled`, up to 8 satellites, 3 m",
              "pseudorange, 0.05 m/s Doppler, 1 Hz); the epochs re-tagged by t_d.", "",
              "| injected t_d [ms] | estimate [ms] | error [ms] | sigma [ms] | horizontal rms with [m] | "
              "without [m] |", "|---|---|---|---|---|---|"]
    for r in tr:
        lines.append(f"| {1e3 * r['t_d']:+.1f} | {1e3 * r['est']:+.3f} | {1e3 * (r['est'] - r['t_d']):+.3f} | "
                     f"{1e3 * r['sigma']:.3f} | {r['rms_with']:.3f} | {r['rms_without']:.3f} |")
    lines.append("")

    # 5. real walk
    data_root = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data"))
    data = data_root / "rtklibexplorer_walk_0827"

    def walk_table(wk):
        out = ["| run | epochs | rms, IMU time frame [m] | rms, GNSS time frame [m] | t_d estimate [ms] | sigma [ms] "
               "| t_d^ / sigma | auto keeps the state |", "|---|---|---|---|---|---|---|---|"]
        for lab, r in wk.items():
            est = "-" if r["est"] is None else f"{1e3 * r['est']:+.2f}"
            sg = "-" if r["sigma"] is None else f"{1e3 * r['sigma']:.2f}"
            z = "-" if r["est"] is None else f"{r['est'] / r['sigma']:+.2f}"
            kept = "-" if r["kept"] is None else ("yes" if r["kept"] else "no")
            out.append(f"| {lab} | {r['n']} | {r['rms']:.4f} | {r['rms_gnss']:.4f} | {est} | {sg} | {z} | {kept} |")
        return out

    lines += ["## 5. Real walk (rtklibexplorer walk_0827)", ""]
    if data.is_dir():
        wk = walk(data)
        a, b, au = wk["without the state"], wk["with the state"], wk["auto"]
        nv = wk["with the state, .pos velocities unused"]
        s = b["track"]
        k = np.searchsorted(s.t, s.t[0] + np.array([60.0, 120.0, 180.0]))
        k = k[k < len(s.t)]
        lines += ["### 5a. Loose EKF on the RTK `.pos`", "",
                  "`tests/data/walk_0827_loose.toml` (consumer IMU, RTK `.pos`), 1 fix in 4 to the filter, the horizontal",
                  "error at the other RTK epochs (held out), as in docs/results/walk_loose.md; the first four runs read",
                  "the `.pos` velocity column as tagged (`[gnss] velocity_lag_s = 0`; the toml re-times it).  Default time-offset",
                  "settings (sigma 100 ms, random constant).  The reference is a GNSS record: tagged t, it holds the",
                  "antenna at IMU time t - t_d, so a run that estimates t_d is compared in both time frames (the",
                  "solution at t, and at t - t_d^).", ""] + walk_table(wk) + [
                  "", "The estimate along the run: " + ", ".join(
                      f"{s.t[j] - s.t[0]:.0f} s: {1e3 * s.time_offset_s[j]:+.1f} +- {1e3 * s.sigma_time_offset_s[j]:.1f} ms"
                      for j in k) + ".",
                  f"Held-out rms with / without the state: {b['rms'] / a['rms']:.3f} (IMU time frame), "
                  f"{b['rms_gnss'] / a['rms']:.3f} (GNSS time frame); auto / without: {au['rms'] / a['rms']:.3f}.  "
                  f"The velocity rows (the `.pos` velocities, {1e3 * b['est']:+.1f} +- {1e3 * b['sigma']:.1f} ms with "
                  f"them) and the position rows alone ({1e3 * nv['est']:+.1f} +- {1e3 * nv['sigma']:.1f} ms) "
                  + ("disagree" if abs(b["est"] - nv["est"]) > 3 * np.hypot(b["sigma"], nv["sigma"]) else "agree")
                  + f" (difference {abs(b['est'] - nv['est']) / np.hypot(b['sigma'], nv['sigma']):.1f} combined "
                  + (f"sigma; the run without the velocities is poor in itself, held-out rms {nv['rms']:.4f} m, its "
                     "heading weakly held)." if nv["rms"] > 2.0 * a["rms"] else
                     f"sigma; the run without the velocities: held-out rms {nv['rms']:.4f} m).")
                  + "  The `.pos` "
                  "columns are the receiver's NAV-PVT solution (bench/walk_reference_check.py); a lag of its "
                  "velocity behind the antenna's (a receiver's navigation filter smooths it) reads as a time "
                  "offset in the -a_n column, and the loose run cannot tell the two apart.  The tight run on the "
                  "raw Doppler (5b) checks the clocks without that velocity.", ""]
        lag, lag_rms, rms0, _ = velocity_lag(data)
        rt, rw, ra = (wk["velocities re-timed, without the state"], wk["velocities re-timed, with the state"],
                      wk["velocities re-timed, auto"])
        lines += [f"The `.pos` velocity against its own positions (central differences over two fix intervals): "
                  f"the rms horizontal difference is {rms0:.3f} m/s as tagged and smallest, {lag_rms:.3f} m/s, with "
                  f"the velocity column read {1e3 * lag:+.0f} ms later, i.e. the velocity lags the positions by "
                  f"{1e3 * lag:.0f} ms.  The same runs with each fix's velocity taken from the column at "
                  f"t {1e3 * lag:+.0f} ms (`[gnss] velocity_lag_s`; the table's last three rows): held-out rms without the state "
                  f"{rt['rms']:.4f} m ({rt['rms'] / a['rms']:.3f} of the run as tagged), t_d^ "
                  f"{1e3 * rw['est']:+.1f} +- {1e3 * rw['sigma']:.1f} ms with it (|z| {abs(rw['est'] / rw['sigma']):.2f}), "
                  f"auto {'keeps' if ra['kept'] else 'drops'} the state (held-out rms {ra['rms']:.4f} m).", ""]
        print("walk tight ...", file=sys.stderr, flush=True)
        wt, sh = walk_tight(data_root)
        lines += ["### 5b. Tight EKF on the RINEX", "",
                  "`tests/data/walk_0827.toml` (GPS L1 pseudorange and Doppler), every epoch to the filter; the "
                  "reference (no epoch held out: it is an independent solution) is the receiver's NAV-PVT track "
                  "moved by the mean single-point offset of the RTK `.pos`'s base (N, E, U "
                  f"{sh[0]:+.2f}, {sh[1]:+.2f}, {sh[2]:+.2f} m; bench/walk_reference_check.py, as in "
                  "docs/results/tune.md).", ""] + walk_table(wt)
        ta, tb, tu = wt["without the state"], wt["with the state"], wt["auto"]
        dz = abs(b["est"] - tb["est"]) / np.hypot(b["sigma"], tb["sigma"])
        lines += ["", f"rms with / without the state: {tb['rms'] / ta['rms']:.3f}; auto / without: "
                      f"{tu['rms'] / ta['rms']:.3f}.  The tight estimate is {abs(tb['est'] / tb['sigma']):.1f} sigma "
                      f"from zero and {dz:.1f} combined sigma from the loose one (5a).", ""]
    else:
        lines += [f"{data} not found: not run.", ""]
    lines += [f"Wall time {time.perf_counter() - t_start:.0f} s."]
    text = "\n".join(lines) + "\n"
    if args.out:
        Path(args.out).write_text(with_stamp(text, args.out))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
