"""Why the tight EKF's adaptive process noise does not settle at the true Q: the prior
(P-) consistency of the tight EKF on the simulated tight mover, epoch by epoch.

The drive is the fixture of ``tests/test_adaptive_q_tight.py`` (``tight_mover``: a car,
225 s, Gauss-Markov IMU biases only, up to 8 GPS satellites, pseudorange 3 m, range rate
0.05 m/s, the filter's IMU noise the simulated one).  The run goes through the push API
(:class:`insnav.filters.navigator.TightNavigator`, the batch engine's code): the IMU up to
the sample at the epoch's time t_g, then the state and covariance there (the prior at t_g:
the last propagation interval ends at t_g), the epoch pushed at t_g + 1 ns (the navigator
refuses records at the last integrated time; 1 ns changes nothing measurable), one more
sample, and the state and covariance after the update.  Against the simulator's truth:

1. prior NEES per block, (x- - x_true)' P-^-1 (x- - x_true) with the full 3x3 (1x1) block of
   P-: velocity, attitude (psi from C_nb_est C_nb_true'), receiver clock drift; expected the
   block dimension;
2. the Doppler innovation split into its velocity part -u_n' dv, its clock-drift part dd, and
   the rest (the simulated noise if the filter's rate row is the simulator's model: std 0.05);
3. the adaptive process noise's per-update quantities (``filter/adaptive_noise.hpp``,
   AdaptiveProcessNoise): |dx_b|^2 against tr(P- - P+)_bb for velocity and attitude, windowed,
   at the true Q and at Q x 0.1 / x 10 (random walks scaled), and the share of the per-epoch
   velocity / attitude P growth that the scaled random walks make.

4. the adaptive process noise's own ratio (AdaptiveProcessNoise, the engine's numbers): a run cut
   after n applied epochs with the window n fills the window at its last epoch, so the reported
   factor is sum |dx_b|^2 / sum tr(P- - P+)_bb over those epochs with every record at factor 1 (the
   configured Q).  With the initial state exact and small initial sigmas (0.5 m, 0.01 m/s, 0.01 deg)
   the start-up corrections do not outweigh the rest.  Over simulation seeds, and at Q x 0.1 / x 10;
   beside it the adaptive factors of the whole drive (window 100, the test's setting).

Prints a text report; ``--scales`` chooses the Q factors of 1.-3., ``--seeds`` the simulation seeds
of 4.  About 10 s per run of 1.-3. and 3 s per seed of 4.

Reproduce (from the repository root)::

    python3 bench/tight_prior_consistency.py
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import insnav.sim as sim  # noqa: E402
from insnav import _core, earth  # noqa: E402
from insnav.config import ImuNoise, RunConfig  # noqa: E402
from insnav.filters.navigator import TightNavigator  # noqa: E402

from test_adaptive_q_tight import SMALL_P0, _scaled, ratio_at_configured_q, tight_mover  # noqa: E402

DEG = np.pi / 180.0
KV, KA, KD = slice(3, 6), slice(6, 9), 16  # Layout17: velocity, attitude, clock drift
#: the propagation interval of 1.-3. [s]: 0.1 s (the default) less 1 us, so that an interval ends at the
#: IMU sample at the epoch's time (the sample times carry rounding errors of 1e-14 s: with 0.1 s some
#: intervals end one sample later, and the covariance read at t_g would miss up to 0.11 s of growth)
PROPAGATION_S = 0.1 - 1e-6
#: epoch windows of the report (0-based indices of applied epochs)
WINDOWS = ((0, 10), (10, 100), (100, 232), (132, 232))


def dcm_nb(roll, pitch, yaw):
    """C_nb of 3-2-1 Euler angles [rad] (the core's conversion)."""
    return np.asarray(_core.rotation.dcm_from_euler(np.array([roll, pitch, yaw], float)))


def truth_at(ds, t):
    """Truth velocity (3,) [m/s] and C_nb at t (the truth is sampled at the IMU times)."""
    tr = ds.truth
    i = int(np.argmin(np.abs(tr.t - t)))
    if abs(tr.t[i] - t) > 1e-6:
        raise ValueError(f"no truth sample at t = {t}")
    return tr.v_n[i], dcm_nb(tr.roll_deg[i] * DEG, tr.pitch_deg[i] * DEG, tr.yaw_deg[i] * DEG)


def errors(ds, s):
    """Velocity error (3,) [m/s] and attitude error psi (3,) [rad] of a navigator state (computed - true)."""
    v_true, C_true = truth_at(ds, s["t"])
    C_est = dcm_nb(s["roll_deg"] * DEG, s["pitch_deg"] * DEG, s["yaw_deg"] * DEG)
    E = C_est @ C_true.T  # I + [psi x] for a small error
    psi = 0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
    return np.asarray(s["v_n_mps"]) - v_true, psi


def run(ds, noise, **kw):
    """Per applied epoch: prior/posterior errors and covariances, and the Doppler innovation parts."""
    cfg = RunConfig(filter="ekf", coupling="tight", imu=noise, propagation_interval_s=PROPAGATION_S)
    nav = TightNavigator.from_dataset(ds, cfg, **kw)
    inp = nav.inputs
    t, dth, dv = ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b
    g = ds.gnss_raw
    cur = 0
    rec = []
    for e, t_g in enumerate(inp.epoch_t):
        k = int(np.searchsorted(t, t_g - 1e-6))
        if k + 1 >= t.size:
            break
        nav.push_imu_array(t[cur:k + 1], dth[cur:k + 1], dv[cur:k + 1])
        P_prior, s_prior = nav.covariance(), nav.state()
        b, f = int(inp.epoch_start[e]), int(inp.epoch_start[e + 1])
        sats = np.array(inp.sats[b:f], float)
        if not kw.get("use_pseudorange", True):
            sats[:, 0] = np.nan
        if not kw.get("use_rate", True):
            sats[:, 1] = np.nan
        nav.push_pseudoranges(t_g + 1e-9, sats, prn=np.asarray(inp.prn[b:f], np.int64))
        nav.push_imu(t[k + 1], dth[k + 1], dv[k + 1])
        cur = k + 2
        if nav.last_epoch()["status"] != "applied":
            continue
        P_post, s_post = nav.covariance(), nav.state()
        ev0, ea0 = errors(ds, s_prior)
        ev1, ea1 = errors(ds, s_post)
        d_true = g.rx_clock_drift_mps[np.flatnonzero(np.isclose(g.t, t_g))[0]]
        ed = s_prior["clock_drift_mps"] - d_true
        # the rate rows' innovation (predicted - measured) split by the truth errors
        lat, lon = s_prior["lat_deg"] * DEG, s_prior["lon_deg"] * DEG
        r_rx = earth.geodetic_to_ecef(lat, lon, s_prior["h_m"])
        dr = sats[:, 2:5] - np.asarray(r_rx).reshape(1, 3)
        u_e = dr / np.linalg.norm(dr, axis=1)[:, None]
        u_n = earth.ecef_to_ned_vector(np.full(len(u_e), lat), np.full(len(u_e), lon), u_e)
        v_e = earth.ned_to_ecef_vector(lat, lon, np.asarray(s_prior["v_n_mps"]))
        pred = np.einsum("ij,ij->i", u_e, sats[:, 5:8] - v_e) + s_prior["clock_drift_mps"] - sats[:, 9]
        y = pred - sats[:, 1]
        rec.append(dict(t=t_g, Pm=P_prior, Pp=P_post, ev0=ev0, ea0=ea0, ev1=ev1, ea1=ea1, ed=ed,
                        dop=np.column_stack([y, -(u_n @ ev0), np.full(len(y), ed)])[np.isfinite(y)]))
    return rec


def engine_check(ds, noise, rec, kw, windows=(1, 10, 100)):
    """The ratio of 3. from the truth (the push API's P- and the corrections) against the engine's own
    AdaptiveProcessNoise over the first W epochs (the same run, cut after epoch W, window W)."""
    import insnav

    t_g = np.unique(ds.gnss_raw.t)
    for W in windows:
        n = int(np.searchsorted(ds.imu.t, t_g[W - 1] + 0.5))
        imu = dataclasses.replace(ds.imu, t=ds.imu.t[:n], dtheta_b=ds.imu.dtheta_b[:n], dv_b=ds.imu.dv_b[:n])
        cfg = RunConfig(filter="ekf", coupling="tight", imu=noise, propagation_interval_s=PROPAGATION_S,
                        adaptive_q_window=W, adaptive_q_min=1e-3, adaptive_q_max=1e3)
        f = insnav.run(dataclasses.replace(ds, imu=imu), config=cfg, **kw).summary["process_noise_scale"]
        r = rec[:W]
        mine = [sum(float(np.sum((x[e0] - x[e1]) ** 2)) for x in r) / sum(np.trace(x["Pm"][b, b] - x["Pp"][b, b]) for x in r)
                for e0, e1, b in (("ev0", "ev1", KV), ("ea0", "ea1", KA))]
        print(f"  first {W} epochs: |dx|^2/tr(P- - P+) from the truth velocity {mine[0]:.4f}, attitude {mine[1]:.4f}; "
              f"AdaptiveProcessNoise (engine) {f[0]:.4f}, {f[1]:.4f}")


def nees(err, P):
    return float(err @ np.linalg.solve(P, err))


def report(rec, label, noise):
    n = len(rec)
    print(f"\n== {label}: {n} applied epochs")
    for a, b in WINDOWS:
        r = rec[a:b]
        if not r:
            continue
        nv = np.mean([nees(x["ev0"], x["Pm"][KV, KV]) for x in r])
        na = np.mean([nees(x["ea0"], x["Pm"][KA, KA]) for x in r])
        nd = np.mean([x["ed"] ** 2 / x["Pm"][KD, KD] for x in r])
        dxv = sum(float(np.sum((x["ev0"] - x["ev1"]) ** 2)) for x in r)
        dxa = sum(float(np.sum((x["ea0"] - x["ea1"]) ** 2)) for x in r)
        kv = sum(np.trace(x["Pm"][KV, KV] - x["Pp"][KV, KV]) for x in r)
        ka = sum(np.trace(x["Pm"][KA, KA] - x["Pp"][KA, KA]) for x in r)
        print(f"  epochs [{a},{min(b, n)}): prior NEES velocity {nv:.2f} (3), attitude {na:.2f} (3), "
              f"clock drift {nd:.2f} (1); |dx|^2/tr(P- - P+): velocity {dxv / kv:.2f}, attitude {dxa / ka:.2f}")
    # the share of the random walks in the per-epoch growth of P (late epochs, steady state)
    late = rec[100:]
    if len(late) > 2:
        grow_v = np.mean([np.trace(late[i]["Pm"][KV, KV] - late[i - 1]["Pp"][KV, KV]) for i in range(1, len(late))])
        grow_a = np.mean([np.trace(late[i]["Pm"][KA, KA] - late[i - 1]["Pp"][KA, KA]) for i in range(1, len(late))])
        dt = np.median(np.diff([x["t"] for x in late]))
        q_v = float(np.sum(np.square(noise.acc_vrw))) * dt
        q_a = float(np.sum(np.square(noise.gyro_arw))) * dt
        print(f"  epochs 100+: tr P- growth per epoch velocity {grow_v:.3g} (m/s)^2, of which the velocity random "
              f"walk {q_v:.3g} ({100 * q_v / grow_v:.1f} %); attitude {grow_a:.3g} rad^2, of which the angle "
              f"random walk {q_a:.3g} ({100 * q_a / grow_a:.1f} %)")
    d = np.concatenate([x["dop"] for x in rec]) if rec else np.zeros((0, 3))
    if len(d):
        rest = d[:, 0] - d[:, 1] - d[:, 2]
        print(f"  Doppler innovation: std {d[:, 0].std():.4f} m/s = velocity part {d[:, 1].std():.4f}, clock-drift "
              f"part {d[:, 2].std():.4f} (correlation {np.corrcoef(d[:, 1], d[:, 2])[0, 1]:+.2f}), rest "
              f"{rest.std():.4f} (mean {rest.mean():+.4f}; the simulated noise: 0.05)")


def adaptive_factors(ds, noise, small_p0=False, **kw):
    """The adaptive factors at the end of the whole drive (window 100, bounds 0.01 and 100)."""
    import insnav

    base = SMALL_P0 if small_p0 else dict(filter="ekf", coupling="tight")
    cfg = RunConfig(**base, imu=noise, adaptive_q_window=100, adaptive_q_min=0.01, adaptive_q_max=100.0)
    return insnav.run(ds, config=cfg, **kw).summary["process_noise_scale"]


def seed_report(seeds):
    print("\n== 4. AdaptiveProcessNoise's ratio at the configured Q over the first 200 epochs (initial state exact, "
          "small initial sigmas), and the adaptive factors of the whole drive (window 100)")
    rows = []
    for seed in seeds:
        ds = sim.simulate(tight_mover(), seed=seed)
        noise = ImuNoise.from_dataset_model(ds.imu_model)
        r = ratio_at_configured_q(ds, noise)
        f = adaptive_factors(ds, noise)
        f0 = adaptive_factors(ds, noise, small_p0=True)
        rows.append(r + f + f0)
        print(f"  seed {seed}: ratio velocity {r[0]:.3f}, attitude {r[1]:.3f}; factors {f[0]:.2f}, {f[1]:.2f} "
              f"(small initial sigmas {f0[0]:.2f}, {f0[1]:.2f})", flush=True)
        if seed == 3:
            for s in (0.1, 10.0):
                rs = ratio_at_configured_q(ds, _scaled(noise, s))
                print(f"    Q x {s:g}: ratio velocity {rs[0]:.3f}, attitude {rs[1]:.3f}")
    a = np.array(rows)
    se = a[:, :2].std(0, ddof=1) / np.sqrt(len(a)) if len(a) > 1 else np.full(2, np.nan)
    print(f"  mean ratio velocity {a[:, 0].mean():.3f} +- {se[0]:.3f}, attitude {a[:, 1].mean():.3f} +- {se[1]:.3f}; "
          f"factors range velocity {a[:, 2].min():.2f} .. {a[:, 2].max():.2f}, attitude {a[:, 3].min():.2f} .. "
          f"{a[:, 3].max():.2f}, geometric mean {np.exp(np.log(a[:, 2]).mean()):.2f}, "
          f"{np.exp(np.log(a[:, 3]).mean()):.2f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scales", default="1,0.1,10", help="Q factors (random-walk variances) to run")
    ap.add_argument("--rows", default="both,rate,pseudorange", help="row kinds: both, rate, pseudorange")
    ap.add_argument("--seed", type=int, default=3, help="simulation seed of 1.-3.")
    ap.add_argument("--seeds", default="1,2,3,4,5,6,7,8", help="simulation seeds of 4. (empty: skip)")
    args = ap.parse_args(argv)
    if args.seeds:
        seed_report([int(x) for x in args.seeds.split(",")])
    ds = sim.simulate(tight_mover(), seed=args.seed)
    noise = ImuNoise.from_dataset_model(ds.imu_model)
    kinds = {"both": {}, "rate": dict(use_pseudorange=False), "pseudorange": dict(use_rate=False)}
    for s in (float(x) for x in args.scales.split(",") if x):
        for kind in args.rows.split(","):
            rec = run(ds, _scaled(noise, s), **kinds[kind])
            report(rec, f"Q x {s:g}, rows: {kind}", _scaled(noise, s))
            if s == 1.0:
                engine_check(ds, _scaled(noise, s), rec, kinds[kind])


if __name__ == "__main__":
    main()
