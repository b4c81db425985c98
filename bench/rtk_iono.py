"""RTK between-receiver ionosphere: ``[rtk] iono`` = off / variance / estimate, with RTKLIB's
``pos1-ionoopt`` = brdc / est-stec beside it, on a medium-baseline simulation and on the short real pairs.

Reproduce (from the repository root, ../shared/data beside the repo, Debian's ``rtklib``)::

    python3 bench/rtk_iono.py --seeds 5            # simulation and real pairs, a table on stdout
    python3 bench/rtk_iono.py --seeds 5 --no-real  # the simulation only

Simulation: the ``rtk-open-sky-car`` preset (600 s, GPS L1/L2 + Galileo E1/E5a, 1 Hz) with the base moved
to ``--base-km`` north-east/south-west offsets (``offset_ned_m = -d, -d, 0``; default 20 km: a baseline of
28-34 km) and ``iono_ppm`` (default 1: a quiet mid-latitude ionosphere), written as RINEX 3 and processed
by every engine from those files (kinematic, continuous AR, ratio 3, 10 deg).  Real pairs: the settings of
``bench/rtk_compare.py`` with ``iono`` switched.  A wrong fix is a fixed epoch more than 5 cm off the truth.
Nothing here writes a results document.
"""
from __future__ import annotations

import argparse
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

WRONG_FIX_M = 0.05
INSNAV_MODES = {"off": dict(iono="off"), "variance": dict(iono="variance", iono_sigma_per_10km_m=0.02),
                "estimate": dict(iono="estimate")}
RTKLIB_IONO = ("brdc", "est-stec")


def medium_scenario(base_km: float, iono_ppm: float, duration_s: float | None = None) -> dict:
    """The open-sky preset with the base ``base_km`` km south and west of the start."""
    from insnav.sim.scenario import resolve_raw

    raw, _ = resolve_raw("rtk-open-sky-car")
    raw["gnss_rtk"]["base"] = {"offset_ned_m": [-1e3 * base_km, -1e3 * base_km, 0.0]}
    raw["gnss_rtk"]["iono_ppm"] = float(iono_ppm)
    if duration_s is not None:
        raw["motion"]["segments"] = [{"duration_s": duration_s / 2, "target_speed_mps": 12.0},
                                     {"duration_s": duration_s / 2, "heading_change_deg": 90.0}]
        raw["initial"]["speed_mps"] = 5.0
    return raw


def score(t, r_e, q, t_truth, r_truth) -> dict:
    i = np.clip(np.searchsorted(t_truth, np.asarray(t) - 0.5e-3), 0, t_truth.size - 1)
    ok = np.abs(t_truth[i] - t) < 1e-3
    err = np.where(ok, np.linalg.norm(r_e - r_truth[i], axis=1), np.nan)
    fx = (q == 1) & ok
    e = err[fx]
    fl = (q == 2) & ok
    return dict(n=int(t_truth.size), fixed=int(fx.sum()), wrong=int(np.sum(e > WRONG_FIX_M)),
                sq=float(np.sum(e ** 2)), float_err=err[fl])


def insnav_solve(files, nf, extra, systems="GE", mask=10.0, record_iono=False):
    from insnav.gnss.rtk import RtkOptions, solve_rtk

    opt = RtkOptions.from_dict(dict(mode="kinematic", ar_mode="continuous", systems=systems, frequencies=nf,
                                    elevation_mask_deg=mask, ratio_threshold=3.0, **extra))
    return solve_rtk(str(files["rover"]), str(files["base"]), str(files["nav"]), options=opt, record_iono=record_iono)


def rtklib_solve(files, nf, ionoopt, workdir: Path, navsys=9, mask=10.0):
    from rtk_compare import read_pos

    conf = workdir / f"rtklib_{ionoopt}_{nf}.conf"
    conf.write_text("\n".join([
        "pos1-posmode=kinematic", f"pos1-frequency={'l1' if nf == 1 else 'l1+l2'}", "pos1-soltype=forward",
        f"pos1-elmask={mask:g}", f"pos1-ionoopt={ionoopt}", "pos1-tropopt=saas", f"pos1-navsys={navsys}",
        "pos2-armode=continuous", "pos2-arthres=3", "out-solformat=xyz", "ant2-postype=rinexhead"]) + "\n")
    pos = workdir / f"rtklib_{ionoopt}_{nf}.pos"
    subprocess.run(["rnx2rtkp", "-k", str(conf), "-o", str(pos), str(files["rover"]), str(files["base"]),
                    str(files["nav"])], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=600)
    return read_pos(pos)


def _add(acc, s):
    for k in ("n", "fixed", "wrong", "sq"):
        acc[k] = acc.get(k, 0) + s[k]
    acc.setdefault("runs", []).append(s)
    acc.setdefault("float_err", []).append(s["float_err"])


def _row(name, a) -> str:
    fr = a["fixed"] / max(a["n"], 1)
    rms = 100 * math.sqrt(a["sq"] / a["fixed"]) if a["fixed"] else float("nan")
    per = " ".join(f"{r['fixed']}/{r['wrong']}" for r in a["runs"])
    fe = np.concatenate(a["float_err"])
    fl = f"{100 * np.median(fe):.1f} cm" if fe.size else "-"
    return (f"| {name} | {100 * fr:.1f} % ({a['fixed']} / {a['n']}) | {100 * a['wrong'] / max(a['fixed'], 1):.2f} % "
            f"({a['wrong']}) | {rms:.2f} cm | {fl} | {per} |")


def simulation(seeds, base_km, iono_ppm, nfs=(2, 1), rtklib=True):
    from insnav.sim import simulate_rtk

    lines = []
    for nf in nfs:
        acc = {}
        bls = []
        for seed in seeds:
            sim = simulate_rtk(medium_scenario(base_km, iono_ppm), seed=seed)
            bls.append(np.linalg.norm(sim.rover.r_e - sim.base_r_e, axis=1))
            wd = Path(tempfile.mkdtemp(prefix="rtkiono-"))
            try:
                files = sim.write(wd)
                tt, rt = sim.rover.t_tag_gps_s, sim.rover.r_e
                for name, extra in INSNAV_MODES.items():
                    sol = insnav_solve(files, nf, extra)
                    _add(acc.setdefault(f"insnav {name}", {}), score(sol.t_gps_s, sol.r_e, sol.status, tt, rt))
                if rtklib and shutil.which("rnx2rtkp"):
                    for io in RTKLIB_IONO:
                        t, r, q = rtklib_solve(files, nf, io, wd)
                        _add(acc.setdefault(f"RTKLIB {io}", {}), score(t, r, q, tt, rt))
            finally:
                shutil.rmtree(wd, ignore_errors=True)
            print(f"  L{'1' if nf == 1 else '1+L2'} seed {seed} done", file=sys.stderr)
        bl = np.concatenate(bls)
        lines += [f"\nSimulation: base {base_km:g} km S and W of the start (baseline {bl.min() / 1e3:.1f}-"
                  f"{bl.max() / 1e3:.1f} km), iono_ppm {iono_ppm:g}, seeds {list(seeds)}, "
                  f"frequencies {nf}, GPS+Galileo, continuous AR", "",
                  "| engine | fix rate | wrong / fixed | fixed 3-D RMS | float median 3-D error | per seed fixed/wrong |",
                  "|---|---|---|---|---|---|"]
        lines += [_row(k, a) for k, a in acc.items()]
    return lines


def real_pairs():
    import rtk_compare as rc

    lines = ["\nReal and hardware-simulated short baselines (bench/rtk_compare.py settings)", "",
             "| setting | engine | fix rate | wrong | fixed 3-D RMS [mm] |", "|---|---|---|---|---|"]
    work = Path(tempfile.mkdtemp(prefix="rtkiono-real-"))
    try:
        for name, ds in rc.datasets().items():
            for st in ds["settings"]:
                if st["name"].endswith(("_ratio", "_srcfg")) or "_g_" in st["name"] or "_gj_" in st["name"]:
                    continue
                n = rc.n_rover_epochs(ds["rover"])
                for mode in INSNAV_MODES:
                    s2 = dict(st, insnav=dict(st.get("insnav", {}), **INSNAV_MODES[mode]))
                    toml = work / f"{st['name']}_{mode}.toml"
                    toml.write_text(rc.insnav_toml(s2, ds["base_e"]))
                    out = work / f"{st['name']}_{mode}.pos"
                    subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "rtk", "--format", "rinex",
                                    "--obs", str(ds["rover"]), "--base", str(ds["base"]), "--nav",
                                    ",".join(map(str, ds["nav"])), "--config", str(toml), "--out", str(out), "--quiet"],
                                   check=True, capture_output=True)
                    r = rc.score(rc.read_pos(out), ds["truth"], n)
                    lines.append(f"| {st['name']} | insnav {mode} | {100 * r['fix_rate']:.1f} % | {r['wrong']} | "
                                 f"{r['rms_fixed_mm']:.1f} |")
                for io in RTKLIB_IONO:
                    conf = work / f"{st['name']}_{io}.conf"
                    conf.write_text(rc.rtklib_conf(st, ds["base_e"]).replace("pos1-ionoopt       =brdc",
                                                                            f"pos1-ionoopt       ={io}"))
                    out = work / f"{st['name']}_{io}.pos"
                    subprocess.run(["rnx2rtkp", "-k", str(conf), "-o", str(out), str(ds["rover"]), str(ds["base"]),
                                    *map(str, ds["nav"])], check=True, capture_output=True)
                    r = rc.score(rc.read_pos(out), ds["truth"], n)
                    lines.append(f"| {st['name']} | RTKLIB {io} | {100 * r['fix_rate']:.1f} % | {r['wrong']} | "
                                 f"{r['rms_fixed_mm']:.1f} |")
                print(f"  {st['name']} done", file=sys.stderr)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--base-km", type=float, default=20.0)
    ap.add_argument("--iono-ppm", type=float, default=1.0)
    ap.add_argument("--freq", default="2,1", help="frequency counts of the simulation runs")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--no-sim", action="store_true")
    ap.add_argument("--no-rtklib", action="store_true")
    a = ap.parse_args(argv)
    lines = []
    if not a.no_sim:
        lines += simulation(range(1, a.seeds + 1), a.base_km, a.iono_ppm,
                            tuple(int(x) for x in a.freq.split(",")), not a.no_rtklib)
    if not a.no_real:
        lines += real_pairs()
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
