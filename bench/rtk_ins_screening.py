"""Robust screening of the RTK/INS double differences on and off, on the inputs of docs/results/rtk_ins.md.

Writes docs/results/rtk_ins_screening.md (``--out``; without it, prints) with the fix rate, wrong-fix rate (fixed epochs more than 5 cm off)
and the 3-D error by status (epochs, RMS, 95th percentile) of the tight RTK/INS with
``[rtk_engine] robust_screening`` false and true (engine/rtk_ins_engine.hpp, 2a.), and how many single
differences the screening left out / down-weighted, on:

* the Spirent dynamic rover with its synthesised industrial IMU and the seven outages of
  ``bench/rtk_ins.py`` (GPS+Galileo, L1+L2 and L1 only, the same options);
* the simulator's ``rtk-urban-car`` preset with the slips of ``bench/rtk_ins.py`` (GPS L1, seeds 1..N),
  with a paired sign test of the per-run fix rates and wrong fixes;
* ``--faults``: faults injected into the Spirent rover (no outages, its tactical IMU of
  tests/test_rtk_ins.py, GPS+Galileo L1): 30 m on one GPS satellite's pseudorange (30-60 deg) or on the
  reference's (the highest) for 10 epochs, 0.3 cycles on the L1 phase of either from epoch 300 on, or
  at epoch 300 only; the largest 3-D error from epoch 298 to the end, float (AR off) and with AR, for
  the filter without any outlier test, with the per-row tests (the defaults) and with the screening
  alone.

Usage: ``python3 bench/rtk_ins_screening.py [--runs 20] [--skip-spirent] [--skip-urban] [--faults] [--out FILE]``.
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

    acc = {name: dict(n=0, fixed=0, wrong=0, err=[], q=[], scr=0, dw=0, per=[], per_wrong=[]) for name, _ in VARIANTS}
    for k in range(1, n_runs + 1):
        _, ds, _, files, opts = B.urban_inputs(k, work)
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


def faults():
    from insnav import earth
    from insnav.config import RunConfig
    from insnav.filters.rtk_ins import run_rtk_ins
    from insnav.gnss import rtk
    from insnav.sim.from_truth import simulate_from_truth

    e0 = 300
    v = B.SP / B.VARIANT
    nav = [B.SP / "RINEX_GN_Spirent.23N", B.SP / "RINEX_EN_Spirent.23L"]
    ds = simulate_from_truth(B.SP / "Rover-dynamic_motion_Spirent.csv", "tactical", imu_rate_hz=100.0, seed=1)
    rover = rtk.read_phase_obs(v / "Rover-dynamic_MO_Spirent.obs", "GE")
    base = rtk.read_phase_obs(v / "Base-static_MO_Spirent.obs", "GE")
    _, _, rb, _, roff, rrows, _, _ = rtk.prepare_rtk_rows(rover, base, nav, None, rtk.RtkOptions(systems="GE"))
    lat, lon, _ = earth.ecef_to_geodetic(rb)
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    R = rrows[roff[e0]:roff[e0 + 1]]
    los = R[:, 17:20] - rb
    el = np.degrees(np.arcsin(los @ up / np.linalg.norm(los, axis=1)))
    gps = np.flatnonzero(R[:, 1] == 0)
    ref = int(R[gps[np.argmax(el[gps])], 0])
    mid = int(R[np.flatnonzero((R[:, 1] == 0) & (el > 30) & (el < 60))[0], 0])
    r_t = B._truth(ds, rover.epoch_t_gps_s)

    def inject(prn, n, column, value):
        rows = np.flatnonzero((rover.system == "G") & (rover.prn == prn) & (rover.epoch >= e0) & (rover.epoch < e0 + n))
        a = getattr(rover, column).copy()
        a[rows, 0] += value
        return rtk.PhaseObs(**{**rover.__dict__, column: a})

    cases = (("clean", rover),
             (f"code +30 m, 10 epochs, G{mid:02d}", inject(mid, 10, "code_m", 30.0)),
             (f"code +30 m, 10 epochs, G{ref:02d} (reference)", inject(ref, 10, "code_m", 30.0)),
             (f"phase +0.3 cycle from epoch {e0} on, G{mid:02d}", inject(mid, 10 ** 6, "phase_cycles", 0.3)),
             (f"phase +0.3 cycle from epoch {e0} on, G{ref:02d} (reference)", inject(ref, 10 ** 6, "phase_cycles", 0.3)),
             (f"phase +0.3 cycle at epoch {e0} only, G{mid:02d}", inject(mid, 1, "phase_cycles", 0.3)))
    filters = (("no outlier test", dict(code_chi2_row=0.0), dict(outlier_sigma=0.0)),
               ("per-row tests (default)", {}, {}),
               ("screening alone", dict(code_chi2_row=0.0, robust_screening=True), dict(outlier_sigma=0.0)))
    print("\nFaults injected into the Spirent rover (tactical IMU, GPS+Galileo L1, no outages); largest 3-D error from "
          f"epoch {e0 - 2} on [cm], float (AR off) / with AR (fix rate, wrong fixes); SDs the screening left out\n")
    print("| fault | " + " | ".join(n for n, _, _ in filters) + " |\n|---|" + "---|" * len(filters))
    for cname, obs in cases:
        cells = []
        for _, eng, ro in filters:
            res = []
            for ar in ("off", "continuous"):
                sol = run_rtk_ins(ds, RunConfig(filter="ekf"), rover=obs, base=base, nav=nav, engine=eng,
                                  rtk_options=dict(systems="GE", frequencies=1, ar_mode=ar, **ro))
                err = np.linalg.norm(sol.rtk.r_e - r_t, axis=1)
                res.append((sol, err))
            (sf, ef), (sa, ea) = res
            fx = sa.rtk.status == 1
            cells.append(f"{100 * np.nanmax(ef[e0 - 2:]):.2f} / {100 * np.nanmax(ea[e0 - 2:]):.2f} "
                         f"({100 * fx.mean():.1f} %, {int(np.sum(fx & (ea > B.WRONG_FIX_M)))}); {int(sa.rtk.screened.sum())}")
        print(f"| {cname} | " + " | ".join(cells) + " |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--skip-spirent", action="store_true")
    ap.add_argument("--skip-urban", action="store_true")
    ap.add_argument("--faults", action="store_true", help="only the injected-fault table")
    ap.add_argument("--out", help="write the results document here (all sections, the faults included)")
    a = ap.parse_args(argv)
    if a.out:
        import contextlib
        import io

        from _common import git_commit
        from _stamps import with_stamp

        t0 = time.time()
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            _sections(a, faults_too=True)
        head = ["# Robust screening of the RTK/INS double differences: on against off", "",
                f"Generated by `bench/rtk_ins_screening.py` at commit `{git_commit()}`.  Reproduce: "
                f"`python3 bench/rtk_ins_screening.py --runs {a.runs} --out {a.out}` ({time.time() - t0:.0f} s).", "",
                "`[rtk_engine] robust_screening` (off by default): Teunissen's w-test on each satellite's single "
                "difference with the joint innovation covariance, identification and removal one at a time, "
                "IGG-III (or Huber) down-weighting of the rest in a flagged epoch (docs/algorithms.md section 22).  "
                "Columns: fix rate, wrong fixes (fixed epochs more than 5 cm off), the 3-D error by status "
                "(epochs: RMS / 95th percentile), single differences left out, down-weighted."]
        Path(a.out).write_text(with_stamp("\n".join(head) + "\n" + buf.getvalue(), a.out))
        print(buf.getvalue())
        return 0
    _sections(a, faults_too=a.faults)
    return 0


def _sections(a, faults_too: bool) -> None:
    if not (a.faults and not a.out):
        with tempfile.TemporaryDirectory() as td:
            work = Path(td)
            if not a.skip_spirent:
                for f in (2, 1):
                    spirent(work, f)
            if not a.skip_urban:
                urban(a.runs, work)
    if faults_too:
        faults()


if __name__ == "__main__":
    raise SystemExit(main())
