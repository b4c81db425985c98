"""RTK engines on the simulated carrier-phase presets: fix rate, wrong fixes, time to first fix, error by status.

Reproduce (from the repository root)::

    python3 bench/rtk_sim_rtklib.py --runs 20 --out docs/results/rtk_sim.md
    insnav simulate rtk-urban-car --seed 1 --out urban1      # one run's files: urban1/rover.obs, base.obs, nav.rnx
    rnx2rtkp -k rtk.conf -o urban1.pos urban1/rover.obs urban1/base.obs urban1/nav.rnx

For each preset with a ``[gnss_rtk]`` table (``rtk-open-sky-car``,
``rtk-urban-car``) and each seed ``1..N``, :func:`insnav.sim.simulate_rtk`
writes the rover and base RINEX 3 observation files and the navigation file
(:meth:`insnav.sim.gnss_rtk.RtkSimulation.write`); every engine of
:data:`ENGINES` processes the same three files in kinematic mode, L1 (E1)
only, with the preset's systems and a ratio-test threshold of 3, and its
per-epoch solution is compared with the simulated truth (the rover antenna
at each epoch's reception time; 3-D error).

Metrics, per engine and preset, pooled over the runs:

* fix rate: fixed epochs / rover epochs (an epoch without a solution counts as not fixed);
* wrong-fix rate: fixed epochs with a 3-D error above 5 cm / fixed epochs;
* fixed epochs more than 20 cm off (a fixed position that far off holds a wrong integer set; one
  between 5 and 20 cm may also be the right integers in a poor geometry);
* float consistency: rms(e / sigma) over the float epochs and the three axes of the engine's own
  ``.pos`` frame (its standard deviations sdn/sde/sdu or sdx/sdy/sdz; 1 for a consistent filter,
  larger for an overconfident one: its success rate and ratio test then trust a float solution
  that is not there);
* correct-fix rate: fixed epochs within 5 cm / rover epochs;
* time to first fix: from the first rover epoch to the first fixed one [s],
  median and maximum over the runs that fix (and how many never do);
* 3-D error by status (fixed / float / single): epochs, RMS, 95th percentile;
* a paired comparison of the engines' per-run fix rates (sign test, exact
  binomial p-value).

The engines: insnav's ``--filter rtk`` and RTKLIB's ``rnx2rtkp``, each with
continuous and instantaneous ambiguity resolution, each run as a process on
the same files (reading included).  Another engine is one function returning
an :class:`EngineSolution` and one line in :data:`ENGINES`.  Variants of insnav's
success-rate test: ``(SR configured only)`` without the route of the estimated
code variance factor (``min_success_rate_estimated = 0``, the default before it),
and ``(sigmas / 2)`` a receiver twice as noisy as configured (the configured
phase and code sigmas halved, the simulation unchanged), with the default test
and with the configured covariance's alone.
"""
from __future__ import annotations

import argparse
import math
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import git_commit  # noqa: E402
from _stamps import with_stamp  # noqa: E402

COMMAND = "python3 bench/rtk_sim_rtklib.py --runs 20 --out docs/results/rtk_sim.md"
PRESETS = ("rtk-open-sky-car", "rtk-urban-car")
#: a fixed epoch with a larger 3-D error is a wrong fix [m]
WRONG_FIX_M = 0.05
#: the issue's target on the simulated presets: wrong fixes / fixed epochs
TARGET_WRONG_RATE = 0.01
RATIO = 3.0
STATUS_NAMES = ("fixed", "float", "single")


@dataclass
class EngineSolution:
    """Per-epoch output of an RTK engine."""

    t_gps_s: np.ndarray  #: (n,) solution time [GPS s]
    r_e: np.ndarray  #: (n, 3) antenna ECEF [m]
    status: np.ndarray  #: (n,) "fixed" | "float" | "single" (anything else: no solution)
    cpu_s: float = float("nan")  #: CPU time of the engine's process [s]
    sd: np.ndarray | None = None  #: (n, 3) standard deviations of the .pos file's axes [m]
    C_sd_e: np.ndarray | None = None  #: (n, 3, 3) rotation ECEF -> the axes of sd (ENU or identity)


def solution_from_rtklib_pos(path) -> EngineSolution:
    """An RTKLIB ``.pos`` file (lat/lon/height or ECEF x/y/z layout) -> :class:`EngineSolution`."""
    from insnav.gnss.gpstime import gps_seconds_from_calendar

    from insnav import earth

    t, xyz, q, sd = [], [], [], []
    is_llh = None
    for line in Path(path).read_text(encoding="ascii", errors="replace").splitlines():
        if line.startswith("%"):
            if "x-ecef" in line:
                is_llh = False
            elif "latitude" in line:
                is_llh = True
            continue
        p = line.split()
        if len(p) < 6:
            continue
        y, mo, d = (int(x) for x in p[0].split("/"))
        hh, mi, ss = p[1].split(":")
        t.append(gps_seconds_from_calendar(y, mo, d, int(hh), int(mi), float(ss)))
        xyz.append([float(x) for x in p[2:5]])
        q.append(int(p[5]))
        sd.append([float(x) for x in p[7:10]] if len(p) >= 10 else [math.nan] * 3)
    a = np.asarray(xyz, float).reshape(-1, 3)
    sd = np.asarray(sd, float).reshape(-1, 3)
    C = np.broadcast_to(np.eye(3), (a.shape[0], 3, 3)).copy()
    if is_llh:
        lat, lon = np.radians(a[:, 0]), np.radians(a[:, 1])
        a = earth.geodetic_to_ecef(lat, lon, a[:, 2])
        sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
        z = np.zeros_like(sl)
        # rows: north, east, up (the order of sdn, sde, sdu)
        C = np.stack([np.stack([-sl * co, -sl * so, cl], -1), np.stack([-so, co, z], -1),
                      np.stack([cl * co, cl * so, sl], -1)], 1)
    names = {1: "fixed", 2: "float", 5: "single", 4: "dgps"}
    return EngineSolution(np.asarray(t), a, np.array([names.get(x, "other") for x in q]), sd=sd, C_sd_e=C)


def rtklib_options(setting, armode) -> list:
    """``rnx2rtkp -k`` options: kinematic, L1, the preset's systems, ratio 3, base position from its header."""
    navsys = sum({"G": 1, "R": 4, "E": 8, "C": 32}[s] for s in setting["systems"])
    return ["pos1-posmode=kinematic", "pos1-frequency=l1", "pos1-soltype=forward",
            f"pos1-elmask={setting['elevation_mask_deg']:g}", "pos1-ionoopt=brdc", "pos1-tropopt=saas",
            f"pos1-navsys={navsys}", f"pos2-armode={armode}", f"pos2-arthres={RATIO:g}",
            "out-solformat=xyz", "ant2-postype=rinexhead"]


def _rtklib(files, setting, workdir, armode):
    """RTKLIB ``rnx2rtkp`` (Debian rtklib 2.4.3) with :func:`rtklib_options`."""
    conf = workdir / f"rtklib_{armode}.conf"
    conf.write_text("\n".join(rtklib_options(setting, armode)) + "\n")
    pos = workdir / f"rtklib_{armode}.pos"
    t0 = os.times()
    subprocess.run(["rnx2rtkp", "-k", str(conf), "-o", str(pos), str(files["rover"]), str(files["base"]),
                    str(files["nav"])], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=600)
    t1 = os.times()
    sol = solution_from_rtklib_pos(pos)
    sol.cpu_s = (t1.children_user - t0.children_user) + (t1.children_system - t0.children_system)
    return sol


def rtklib_continuous(files, setting, workdir):
    """RTKLIB, continuous ambiguity resolution (ambiguities kept as float states across epochs)."""
    return _rtklib(files, setting, workdir, "continuous")


def rtklib_instantaneous(files, setting, workdir):
    """RTKLIB, instantaneous (single-epoch) ambiguity resolution."""
    return _rtklib(files, setting, workdir, "instantaneous")


def _insnav(files, setting, workdir, ar_mode, extra=(), tag=""):
    """insnav ``--filter rtk`` as a process (reading included) with the options RTKLIB gets:
    kinematic, L1 (E1), the preset's systems and mask, ratio 3, base position from its header
    (``extra``: further ``[rtk]`` lines)."""
    toml = workdir / f"insnav_{ar_mode}{tag}.toml"
    toml.write_text("\n".join([
        'filter = "rtk"', "", "[rtk]", 'mode = "kinematic"', f'ar_mode = "{ar_mode}"',
        f'systems = "{"".join(setting["systems"])}"', "frequencies = 1",
        f"elevation_mask_deg = {setting['elevation_mask_deg']:g}", f"ratio_threshold = {RATIO:g}", *extra]) + "\n")
    pos = workdir / f"insnav_{ar_mode}{tag}.pos"
    t0 = os.times()
    subprocess.run([sys.executable, "-m", "insnav", "run", "--filter", "rtk", "--format", "rinex",
                    "--obs", str(files["rover"]), "--base", str(files["base"]), "--nav", str(files["nav"]),
                    "--config", str(toml), "--out", str(pos)],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=600)
    t1 = os.times()
    sol = solution_from_rtklib_pos(pos)
    sol.cpu_s = (t1.children_user - t0.children_user) + (t1.children_system - t0.children_system)
    return sol


def insnav_continuous(files, setting, workdir):
    """insnav ``--filter rtk``, continuous ambiguity resolution (its default)."""
    return _insnav(files, setting, workdir, "continuous")


def insnav_instantaneous(files, setting, workdir):
    """insnav ``--filter rtk``, instantaneous (single-epoch) ambiguity resolution."""
    return _insnav(files, setting, workdir, "instantaneous")


#: the float-model terms of the consistent-float engine: the simulator's multipath correlation time
#: (multipath_tau_s of both presets), the adaptive code variance factor and an ambiguity random
#: walk that bounds what correlated phase multipath lets the filter learn (RtkOptions)
CONSISTENT_FLOAT = ("code_correlation_time_s = 20.0", "adaptive_code_gain = 0.1", "amb_psd_cycles2ps = 1e-4")


def insnav_consistent_float(files, setting, workdir):
    """insnav ``--filter rtk``, continuous, with the float-model terms of :data:`CONSISTENT_FLOAT`:
    a float filter whose covariance matches its errors (float rms(e / sigma) near 1), so the success
    rate and the ratio test judge the information the observations really hold."""
    return _insnav(files, setting, workdir, "continuous", CONSISTENT_FLOAT, "_consistent")


#: success-rate test variant (RtkOptions): the configured covariance's alone (the default before the
#: route of the estimated code variance factor, min_success_rate_estimated, was added)
SR_CONFIGURED = ("min_success_rate_estimated = 0.0",)
#: a receiver twice as noisy as configured: the configured sigmas halved (the simulation unchanged)
HALF_SIGMAS = ("sigma_phase_a_m = 0.0015", "sigma_phase_b_m = 0.0015")
#: the time-correlated phase errors as states (one Gauss-Markov error per ambiguity over 30 s, half the
#: white phase sigma: the RTK/INS defaults; off by default in GNSS-only RTK)
PHASE_STATES = ("phase_correlation_time_s = 30.0", "phase_error_ratio = 0.5")


def _variant(ar_mode, extra, tag, doc):
    def fn(files, setting, workdir):
        return _insnav(files, setting, workdir, ar_mode, extra, tag)

    fn.__doc__ = doc
    return fn


#: engine name -> function(files {"rover", "base", "nav"}, setting, workdir) -> EngineSolution
ENGINES = {"insnav continuous": insnav_continuous, "insnav instantaneous": insnav_instantaneous,
           "insnav continuous (consistent float)": insnav_consistent_float,
           "RTKLIB continuous": rtklib_continuous, "RTKLIB instantaneous": rtklib_instantaneous}
for _mode, _label, _extra, _tag in (
        ("continuous", "SR configured only", SR_CONFIGURED, "_srcfg"),
        ("continuous", "correlated phase error states", PHASE_STATES, "_phase"),
        ("instantaneous", "SR configured only", SR_CONFIGURED, "_srcfg"),
        ("instantaneous", "sigmas / 2", HALF_SIGMAS, "_half"),
        ("instantaneous", "sigmas / 2; SR configured only", HALF_SIGMAS + SR_CONFIGURED, "_half_srcfg")):
    ENGINES[f"insnav {_mode} ({_label})"] = _variant(_mode, _extra, _tag, f"insnav {_mode}, {_label}: {_extra}")
#: a fixed epoch this far off holds a wrong integer set [m]
WRONG_SET_M = 0.20


def score(sol: EngineSolution, t_truth, r_truth) -> dict:
    """Per-run metrics of one engine's solution against the truth epochs."""
    i = np.searchsorted(t_truth, sol.t_gps_s - 0.5e-3)
    ok = (i < t_truth.size) & (np.abs(t_truth[np.minimum(i, t_truth.size - 1)] - sol.t_gps_s) < 1e-3)
    status = np.full(t_truth.size, "none", dtype="<U8")
    err = np.full(t_truth.size, np.nan)
    status[i[ok]] = sol.status[ok]
    err[i[ok]] = np.linalg.norm(sol.r_e[ok] - r_truth[i[ok]], axis=1)
    # float epochs: e / sigma on the axes of the engine's .pos file
    z2 = np.zeros(0)
    if sol.sd is not None:
        fl = ok & (sol.status == "float")
        e_ax = np.einsum("nij,nj->ni", sol.C_sd_e[fl], sol.r_e[fl] - r_truth[i[fl]])
        z = e_ax / sol.sd[fl]
        z2 = (z[np.isfinite(z)]) ** 2
    fixed = status == "fixed"
    first = np.flatnonzero(fixed)
    return dict(n=t_truth.size, status=status, err=err, n_fixed=int(fixed.sum()), z2_float=z2,
                n_wrong=int((fixed & (err > WRONG_FIX_M)).sum()), n_wrong_set=int((fixed & (err > WRONG_SET_M)).sum()),
                ttff_s=float(t_truth[first[0]] - t_truth[0]) if first.size else math.nan, cpu_s=sol.cpu_s)


def sign_test_p(wins: int, losses: int) -> float:
    """Two-sided exact sign test p-value (ties dropped)."""
    n = wins + losses
    if n == 0:
        return 1.0
    k = min(wins, losses)
    p = sum(math.comb(n, j) for j in range(k + 1)) / 2.0 ** n
    return min(1.0, 2.0 * p)


def run(presets, n_runs, workroot: Path, engines=None, progress=print, keep=False):
    """Simulate and process every run; returns {preset: {engine: [per-run score]}} and the preset settings."""
    from insnav.sim import load_scenario, simulate_rtk

    engines = ENGINES if engines is None else engines
    results, settings = {}, {}
    for preset in presets:
        sc = load_scenario(preset)
        cfg = sc.gnss_rtk
        setting = dict(systems=cfg["systems"], elevation_mask_deg=math.degrees(cfg["base_elevation_mask"]))
        settings[preset] = dict(setting, description=sc.description)
        results[preset] = {e: [] for e in engines}
        stats = dict(n_common=[], baseline_m=[], slips=0, slips_flagged=0, epochs=0)
        for k in range(1, n_runs + 1):
            sim = simulate_rtk(preset, seed=k)
            _n_r, n_c = sim.common_counts()
            stats["n_common"].append(n_c)
            stats["baseline_m"].append(np.linalg.norm(sim.rover.r_e - sim.base_r_e, axis=1))
            stats["slips"] += int(sim.rover.slip.sum() + sim.base.slip.sum())
            stats["slips_flagged"] += int((sim.rover.slip & (sim.rover.lli & 1 > 0)).sum()
                                          + (sim.base.slip & (sim.base.lli & 1 > 0)).sum())
            stats["epochs"] += int(n_c.size)
            wd = workroot / f"{preset}-{k}"
            wd.mkdir(parents=True, exist_ok=True)
            files = sim.write(wd)
            for name, fn in engines.items():
                sol = fn(files, setting, wd)
                results[preset][name].append(score(sol, sim.rover.t_tag_gps_s, sim.rover.r_e))
            if not keep:
                shutil.rmtree(wd, ignore_errors=True)
            settings[preset]["stats"] = stats
            if progress:
                progress(f"{preset} run {k}/{n_runs}: " + ", ".join(
                    f"{e} {r[-1]['n_fixed']}/{r[-1]['n']} fixed, {r[-1]['n_wrong']} wrong"
                    for e, r in results[preset].items()))
    return results, settings


def summarise(runs: list) -> dict:
    """Pool the per-run scores of one engine on one preset."""
    n = sum(r["n"] for r in runs)
    n_fixed = sum(r["n_fixed"] for r in runs)
    n_wrong = sum(r["n_wrong"] for r in runs)
    ttff = np.array([r["ttff_s"] for r in runs])
    st = np.concatenate([r["status"] for r in runs])
    err = np.concatenate([r["err"] for r in runs])
    by = {}
    for s in STATUS_NAMES:
        e = err[(st == s) & np.isfinite(err)]
        by[s] = (e.size, float(np.sqrt(np.mean(e ** 2))) if e.size else math.nan,
                 float(np.percentile(e, 95)) if e.size else math.nan)
    z2 = np.concatenate([r["z2_float"] for r in runs])
    return dict(n=n, fix_rate=n_fixed / n if n else math.nan, n_fixed=n_fixed, n_wrong=n_wrong,
                n_wrong_set=sum(r["n_wrong_set"] for r in runs),
                float_z_rms=float(np.sqrt(np.mean(z2))) if z2.size else math.nan,
                wrong_rate=n_wrong / n_fixed if n_fixed else math.nan,
                runs_wrong=sum(r["n_wrong"] > 0 for r in runs),
                ttff_median=float(np.nanmedian(ttff)) if np.isfinite(ttff).any() else math.nan,
                ttff_max=float(np.nanmax(ttff)) if np.isfinite(ttff).any() else math.nan,
                never=int(np.isnan(ttff).sum()), by=by, per_run_fix=[r["n_fixed"] / r["n"] for r in runs],
                cpu_s=float(np.nanmean([r["cpu_s"] for r in runs])))


def _f(x, fmt):
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def _paired(a: str, b: str) -> bool:
    """Pairs of the sign tests: the first five engines among themselves, each variant with its default."""
    base = list(ENGINES)[:5]
    return (a in base and b in base) or b.startswith(a + " (") or a.startswith(b + " (")


def report(results, settings, n_runs, wall_s, command=COMMAND) -> str:
    lines = ["# RTK on the simulated carrier-phase presets (RTKLIB side by side)", "",
             f"Generated by `{command}` at commit {git_commit()} in {wall_s:.0f} s.", "",
             f"Each preset is simulated {n_runs} times (seeds 1-{n_runs}: new noise, multipath, ionosphere, "
             "slips and ambiguities over the same drive and sky) by `insnav.sim.simulate_rtk`, written as RINEX 3 "
             "(`rover.obs`, `base.obs`, `nav.rnx`) and processed by every engine from those files: kinematic, "
             f"L1/E1 only, the preset's systems, ratio threshold {RATIO:g}, elevation mask of the base "
             "(the rover's files hold only what its mask and canyon let through). Errors are 3-D against the "
             f"simulated rover antenna. A wrong fix is a fixed epoch more than {WRONG_FIX_M * 100:.0f} cm off.", ""]
    for preset, by_engine in results.items():
        s = settings[preset]
        st = s["stats"]
        nc = np.concatenate(st["n_common"])
        bl = np.concatenate(st["baseline_m"])
        lines += [f"## {preset}", "", f"{s['description']}; systems {'+'.join(s['systems'])}, "
                  f"mask {s['elevation_mask_deg']:g} deg.", "",
                  "RTKLIB (`rnx2rtkp -k`): `" + " ".join(rtklib_options(s, "continuous|instantaneous")) + "`.", "",
                  f"Simulated: {st['epochs']} rover epochs; satellites in both files {int(nc.min())}-{int(nc.max())} "
                  f"(median {np.median(nc):g}); baseline {bl.min() / 1e3:.1f}-{bl.max() / 1e3:.1f} km; "
                  f"{st['slips']} cycle slips on all signals, {st['slips_flagged']} of them flagged by LLI "
                  "(plus a new ambiguity at every re-acquisition, flagged).", "",
                  "| engine | fix rate | wrong fixes / fixed | correct fixes / epochs | runs with a wrong fix "
                  f"| fixed > {WRONG_SET_M * 100:.0f} cm | float rms(e / sigma) "
                  "| TTFF median [s] | TTFF max [s] | runs never fixed | CPU per run [s] |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        sums = {e: summarise(r) for e, r in by_engine.items()}
        for e, m in sums.items():
            lines.append(f"| {e} | {m['fix_rate'] * 100:.1f} % ({m['n_fixed']} / {m['n']}) | "
                         f"{_f(m['wrong_rate'] * 100 if m['n_fixed'] else math.nan, '.2f')} % ({m['n_wrong']}) | "
                         f"{(m['n_fixed'] - m['n_wrong']) / m['n'] * 100:.1f} % | {m['runs_wrong']} / {n_runs} | "
                         f"{m['n_wrong_set']} | {_f(m['float_z_rms'], '.1f')} | "
                         f"{_f(m['ttff_median'], '.0f')} | {_f(m['ttff_max'], '.0f')} | "
                         f"{m['never']} | {_f(m['cpu_s'], '.2f')} |")
        a, b = sums.get("insnav continuous"), sums.get("RTKLIB continuous")
        if a and b:
            ok_w = a["n_fixed"] == 0 or a["wrong_rate"] <= TARGET_WRONG_RATE
            ok_f = a["fix_rate"] >= b["fix_rate"]
            lines += ["", f"Target (insnav continuous): wrong fixes at most {TARGET_WRONG_RATE * 100:g} % of the fixed "
                      f"epochs: {_f(a['wrong_rate'] * 100 if a['n_fixed'] else 0.0, '.2f')} %, "
                      f"{'met' if ok_w else 'not met'}; fix rate at least RTKLIB continuous's "
                      f"({b['fix_rate'] * 100:.1f} %): {a['fix_rate'] * 100:.1f} %, {'met' if ok_f else 'not met'}; "
                      f"correct fixes {(a['n_fixed'] - a['n_wrong']) / a['n'] * 100:.1f} % of the epochs against "
                      f"RTKLIB's {(b['n_fixed'] - b['n_wrong']) / b['n'] * 100:.1f} %."]
            c = sums.get("insnav continuous (consistent float)")
            if c:
                lines += ["", f"Float consistency: insnav continuous's float rms(e / sigma) is {_f(a['float_z_rms'], '.1f')}, "
                          f"RTKLIB continuous's {_f(b['float_z_rms'], '.1f')}; with the float-model terms "
                          f"`{'`, `'.join(CONSISTENT_FLOAT)}` it is {_f(c['float_z_rms'], '.1f')}, and that engine "
                          f"fixes {c['fix_rate'] * 100:.1f} % of the epochs "
                          f"({_f(c['wrong_rate'] * 100 if c['n_fixed'] else math.nan, '.2f')} % of them wrong)."]
        lines += ["", "3-D error by status (epochs, RMS, 95th percentile):", "",
                  "| engine | " + " | ".join(STATUS_NAMES) + " |", "|---|" + "---|" * len(STATUS_NAMES)]
        for e, m in sums.items():
            cells = []
            for st in STATUS_NAMES:
                n, rms, p95 = m["by"][st]
                cells.append(f"{n}: {_f(rms * 100 if n else math.nan, '.1f')} cm / {_f(p95 * 100 if n else math.nan, '.1f')} cm"
                             if n else "0")
            lines.append(f"| {e} | " + " | ".join(cells) + " |")
        names = list(sums)
        if len(names) >= 2:
            lines += ["", "Paired per-run fix rates (sign test over the runs, ties dropped):", ""]
            for a_i in range(len(names)):
                for b_i in range(a_i + 1, len(names)):
                    a, b = names[a_i], names[b_i]
                    if not _paired(a, b):
                        continue
                    fa, fb = np.array(sums[a]["per_run_fix"]), np.array(sums[b]["per_run_fix"])
                    wins, losses = int((fa > fb).sum()), int((fa < fb).sum())
                    p = sign_test_p(wins, losses)
                    verdict = (f"{a} fixes more" if wins > losses else f"{b} fixes more") if p < 0.05 \
                        else "no significant difference"
                    lines.append(f"- {a} vs {b}: higher in {wins} runs, lower in {losses}, p = {p:.2g}: {verdict} "
                                 f"(median per-run fix rate {np.median(fa) * 100:.1f} % vs {np.median(fb) * 100:.1f} %).")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=20, help="runs per preset (seeds 1..N)")
    ap.add_argument("--presets", default=",".join(PRESETS), help="comma-separated presets with [gnss_rtk]")
    ap.add_argument("--out", default=None, help="results document to write (default: print)")
    ap.add_argument("--keep", default=None, help="keep the RINEX files and solutions in this folder")
    ap.add_argument("--engines", default=",".join(ENGINES), help="comma-separated engines of ENGINES")
    args = ap.parse_args(argv)
    if shutil.which("rnx2rtkp") is None:
        print("rnx2rtkp not found: apt-get install rtklib", file=sys.stderr)
        return 2
    t = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rtk_sim_") as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        names = args.engines.split(",")
        unknown = [n for n in names if n not in ENGINES]
        if unknown:
            print(f"unknown engine(s) {', '.join(unknown)}; known: {', '.join(ENGINES)}", file=sys.stderr)
            return 2
        results, settings = run(args.presets.split(","), args.runs, root, engines={n: ENGINES[n] for n in names},
                                progress=lambda s: print(s, file=sys.stderr), keep=bool(args.keep))
    argv = sys.argv[1:] if argv is None else list(argv)
    text = report(results, settings, args.runs, time.perf_counter() - t,
                  command=shlex.join(["python3", "bench/rtk_sim_rtklib.py"] + argv))
    if args.out:
        Path(args.out).write_text(with_stamp(text, args.out), encoding="utf-8")
        print(f"wrote {args.out}")
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
