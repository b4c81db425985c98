"""Robust screening of the RTK/INS double differences on and off, on the inputs of docs/results/rtk_ins.md.

Prints (writes no results document) the fix rate, wrong-fix rate (fixed epochs more than 5 cm off)
and the 3-D error by status (epochs, RMS, 95th percentile) of the tight RTK/INS with
``[rtk_engine] robust_screening`` false and true (engine/rtk_ins_engine.hpp, 2a.), and how many single
differences the screening left out / down-weighted, on:

* the Spirent dynamic rover with its synthesised industrial IMU and the seven outages of
  ``bench/rtk_ins.py`` (GPS+Galileo, L1+L2 and L1 only, the same options);
* the simulator's ``rtk-urban-car`` preset with the slips of ``bench/rtk_ins.py`` (GPS L1, seeds 1..N),
  with a paired sign test of the per-run fix rates and wrong fixes.

Usage: ``python3 bench/rtk_ins_screening.py [--runs 20] [--skip-spirent] [--skip-urban]``.
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import rtk_ins as B  # noqa: E402  (bench/rtk_ins.py: inputs, outages, metrics)

VARIANTS = (("screening off (default)", {}), ("screening on", {"robust_screening": True}),
            ("screening on, phase reset after 3 flagged epochs", {"robust_screening": True,
                                                                  "robust_phase_reset_epochs": 3}),
            ("screening on, phase never reset", {"robust_screening": True, "robust_phase_reset_epochs": 0}),
            ("screening on, Huber", {"robust_screening": True, "robust_huber": True}))


def _by_status(err, q):
    out = {}
    for name, code in (("fixed", 1), ("float", 2)):
        e = err[(q == code) & np.isfinite(err)]
        out[name] = (e.size, float(np.sqrt(np.mean(e ** 2))) if e.size else math.nan,
                     float(np.percentile(e, 95)) if e.size else math.nan)
    return out


def _line(name, n, err, q, screened, dw):
    fixed = q == 1
    wrong = int(np.sum(fixed & (err > B.WRONG_FIX_M)))
    bs = _by_status(err, q)
    st = "; ".join(f"{k} {v[0]}: {100 * v[1]:.2f} / {100 * v[2]:.2f} cm" for k, v in bs.items())
    return (f"| {name} | {100 * fixed.sum() / n:.1f} % ({int(fixed.sum())}/{n}) | "
            f"{100 * wrong / max(int(fixed.sum()), 1):.2f} % ({wrong}) | {st} | {screened} | {dw} |")


HEAD = ("| variant | fix rate | wrong / fixed | 3-D error by status (epochs: RMS / p95) | SDs left out | "
        "SDs down-weighted |\n|---|---|---|---|---|---|")


def spirent(work: Path, freq: int):
    from insnav.config import RunConfig
    from insnav.filters.rtk_ins import run_rtk_ins
    from insnav.gnss.rtk import base_position_from_header, read_phase_obs
    from insnav.sim.from_truth import simulate_from_truth

    v = B.SP / B.VARIANT
    nav = [B.SP / "RINEX_GN_Spirent.23N", B.SP / "RINEX_EN_Spirent.23L"]
    ds = simulate_from_truth(B.SP / "Rover-dynamic_motion_Spirent.csv", B.IMU_GRADE, imu_rate_hz=100.0, seed=1)
    rover0 = read_phase_obs(v / "Rover-dynamic_MO_Spirent.obs", "GE")
    rov = work / f"rover_outages_f{freq}.obs"
    B.write_with_outages(v / "Rover-dynamic_MO_Spirent.obs", rov, float(rover0.epoch_t_gps_s[0]), B.OUTAGES)
    base = v / "Base-static_MO_Spirent.obs"
    base_e = base_position_from_header(read_phase_obs(base, "GE"))
    opts = dict(systems="GE", frequencies=freq, elevation_mask_deg=15.0, ratio_threshold=3.0, ar_mode="continuous")
    print(f"\nSpirent dynamic rover + industrial IMU, outages {B.OUTAGES}, GPS+Galileo L1{'+L2' if freq == 2 else ''}\n")
    print(HEAD)
    sols = {}
    for name, eng in VARIANTS:
        t0 = time.process_time()
        sol = run_rtk_ins(ds, RunConfig(filter="ekf", init_error=False), rover=rov, base=base, nav=nav,
                          base_pos=base_e, rtk_options=opts, engine=eng)
        cpu = time.process_time() - t0
        rs = sol.rtk
        err = np.linalg.norm(rs.r_e - B._truth(ds, rs.t_gps_s), axis=1)
        print(_line(f"{name} (CPU {cpu:.2f} s)", rs.status.size, err, rs.status, int(rs.screened.sum()),
                    int(rs.downweighted.sum())))
        sols[name] = sol
    a = sols[VARIANTS[0][0]].rtk
    for n, _ in VARIANTS[1:]:
        b = sols[n].rtk
        same = all(np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True) for k in ("r_e", "status", "ratio"))
        print(f"\n{n}: solution identical bit for bit to the unscreened one: {'yes' if same else 'no'}")


def urban(n_runs: int, work: Path):
    from insnav.config import RunConfig
    from insnav.filters.rtk_ins import run_rtk_ins
    from insnav.sim import simulate

    acc = {name: dict(n=0, fixed=0, wrong=0, err=[], q=[], scr=0, dw=0, per=[], per_wrong=[]) for name, _ in VARIANTS}
    for k in range(1, n_runs + 1):
        sc = B._urban_scenario(k)
        ds = simulate(sc, seed=k)
        wd = work / f"urban{k}"
        wd.mkdir(parents=True, exist_ok=True)
        files = ds.rtk.write(wd)
        mask = math.degrees(sc.gnss_rtk["base_elevation_mask"])
        opts = dict(systems="G", frequencies=1, elevation_mask_deg=mask, ratio_threshold=3.0)
        truth_t, truth_r = ds.rtk.rover.t_tag_gps_s, ds.rtk.rover.r_e
        for name, eng in VARIANTS:
            sol = run_rtk_ins(ds, RunConfig(filter="ekf"), rover=files["rover"], base=files["base"], nav=files["nav"],
                              rtk_options=opts, engine=eng)
            rs = sol.rtk
            i = np.searchsorted(truth_t, rs.t_gps_s - 0.5e-3)
            ok = (i < truth_t.size) & (np.abs(truth_t[np.minimum(i, truth_t.size - 1)] - rs.t_gps_s) < 1e-3)
            err = np.full(truth_t.size, np.nan)
            q = np.zeros(truth_t.size, int)
            err[i[ok]] = np.linalg.norm(rs.r_e[ok] - truth_r[i[ok]], axis=1)
            q[i[ok]] = rs.status[ok]
            a = acc[name]
            fixed = q == 1
            a["n"] += truth_t.size
            a["fixed"] += int(fixed.sum())
            a["wrong"] += int(np.sum(fixed & (err > B.WRONG_FIX_M)))
            a["err"].append(err)
            a["q"].append(q)
            a["scr"] += int(rs.screened.sum())
            a["dw"] += int(rs.downweighted.sum())
            a["per"].append(fixed.mean())
            a["per_wrong"].append(int(np.sum(fixed & (err > B.WRONG_FIX_M))))
        print(f"urban run {k}: " + ", ".join(f"{n}: {acc[n]['fixed']} fixed ({acc[n]['wrong']} wrong)"
                                             for n, _ in VARIANTS), file=sys.stderr)
    print(f"\nSimulator rtk-urban-car (slips as bench/rtk_ins.py), GPS L1, {n_runs} runs\n")
    print(HEAD)
    for name, _ in VARIANTS:
        a = acc[name]
        print(_line(name, a["n"], np.concatenate(a["err"]), np.concatenate(a["q"]), a["scr"], a["dw"]))
    off = acc[VARIANTS[0][0]]
    for n, _ in VARIANTS[1:]:
        on = acc[n]
        d = np.array(on["per"]) - np.array(off["per"])
        dw_ = np.array(on["per_wrong"]) - np.array(off["per_wrong"])
        up, down = int((d > 0).sum()), int((d < 0).sum())
        more, fewer = int((dw_ > 0).sum()), int((dw_ < 0).sum())
        print(f"\n{n}: paired per-run fix rate against off: higher in {up}, lower in {down} runs "
              f"(sign test p = {B.sign_test_p(up, down):.3g}); wrong fixes per run: more in {more}, fewer in "
              f"{fewer} runs (p = {B.sign_test_p(more, fewer):.3g})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--skip-spirent", action="store_true")
    ap.add_argument("--skip-urban", action="store_true")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as td:
        work = Path(td)
        if not a.skip_spirent:
            for f in (2, 1):
                spirent(work, f)
        if not a.skip_urban:
            urban(a.runs, work)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
