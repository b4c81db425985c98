"""Carrier-phase RTK: insnav against RTKLIB's ``rnx2rtkp`` on the same files, one results document per dataset.

Reproduce (from the repository root, with ../shared/data beside the repo and Debian's ``rtklib``)::

    python3 bench/rtk_compare.py            # writes docs/results/rtk_<dataset>.md for the three pairs

For each setting (the issue's table: instantaneous AR on the real pairs, continuous on the Spirent
drive; plus continuous AR, insnav's default, on the real pairs) the script

* writes the RTKLIB configuration ``bench/rtk/<setting>.conf`` and the insnav run TOML
  ``bench/rtk/<setting>.toml`` (the same options: kinematic, forward, broadcast ephemerides,
  Saastamoinen troposphere, ratio 3, GLONASS not fixed, the same base position);
* runs ``rnx2rtkp -k <conf>`` and ``insnav run --filter rtk ... --out X.pos`` as processes
  (reading included), alternately, ``--repeat`` times, and keeps each one's best wall time;
* scores both ``.pos`` files against the truth: fix rate, 3-D RMS of the fixed epochs, wrong
  fixes (a fixed epoch more than 5 cm from the truth), and the verdicts of the targets (fix rate
  at least RTKLIB's, RMS at most 1.2x RTKLIB's, no wrong fix; time at most 0.5x on MatRTKLIB).

Truth: WTZR/WTZZ the marker coordinates of the oracle file plus the antenna heights (antenna
reference points); MatRTKLIB ``base_position.txt`` / ``rover_position.txt``; Spirent the base's
header position and the 10 Hz ``Rover-dynamic_PVA_Spirent.csv`` at the rover epochs.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import compile_package, git_commit  # noqa: E402
from _stamps import with_stamp  # noqa: E402
from insnav import earth  # noqa: E402

DATA = Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data"))
CONF_DIR = ROOT / "bench" / "rtk"
COMMAND = "python3 bench/rtk_compare.py"
NAVSYS = {"G": 1, "R": 4, "E": 8, "C": 32, "J": 16}
FREQ = {1: "l1", 2: "l1+l2", 3: "l1+l2+l5"}
WRONG_FIX_M = 0.05


def _arp(marker, h):
    r = np.array([marker["x"], marker["y"], marker["z"]], float)
    lat, lon, _ = earth.ecef_to_geodetic(r)
    return r + h * np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])


def _llh_file(p):
    lat, lon, h = np.loadtxt(p)
    return np.asarray(earth.geodetic_to_ecef(np.radians(lat), np.radians(lon), h), float).ravel()


#: the correlated phase error states of RTK/INS's defaults, an option of GNSS-only RTK (off by default)
PHASE_STATES = dict(phase_correlation_time_s=30.0, phase_error_ratio=0.5)


def datasets():
    """name -> dict(rover, base, nav list, base_e, truth(t_gps_s) -> (n, 3), title, settings)."""
    out = {}
    w = DATA / "euref_wettzell_wtzr_wtzz"
    if w.is_dir():
        tr = json.loads((w / "wtzr_wtzz_rtklib_oracle.json").read_text())["truth"]
        rb = _arp(tr["base_marker_ecef_m"], tr["base_antenna_height_m"])
        rt = _arp(tr["rover_marker_ecef_m"], tr["rover_antenna_height_m"])
        out["euref_wettzell_wtzr_wtzz"] = dict(
            title="WTZR/WTZZ (real geodetic receivers, 3.3 m, 30 s, 1 h)", rover=w / "WTZZ00DEU_R_20201770000_01D_30S_MO_120epoch.rnx",
            base=w / "WTZR00DEU_R_20201770000_01D_30S_MO_120epoch.rnx",
            nav=[w / "ESBC00DNK_R_20201770000_01D_MN.rnx", w / "ESBC00DNK_R_20201770000_01D_RN.rnx"],
            base_e=rb, truth=lambda t, rt=rt: np.broadcast_to(rt, (len(t), 3)),
            settings=[dict(name="wtzr_wtzz_l1_gec_inst", systems="GEC", freq=1, armode="instantaneous", mask=15.0),
                      dict(name="wtzr_wtzz_l1l2_gec_inst", systems="GEC", freq=2, armode="instantaneous", mask=15.0),
                      dict(name="wtzr_wtzz_l1l2_gec_cont", systems="GEC", freq=2, armode="continuous", mask=15.0),
                      dict(name="wtzr_wtzz_l1l2_gec_cont_phase", systems="GEC", freq=2, armode="continuous", mask=15.0,
                           insnav=PHASE_STATES)])
    m = DATA / "matrtklib_static_septentrio"
    if m.is_dir():
        rb, rt = _llh_file(m / "base_position.txt"), _llh_file(m / "rover_position.txt")
        out["matrtklib_static_septentrio"] = dict(
            title="MatRTKLIB static (real Septentrio pair, 1 m, 1 Hz, 5 min)", rover=m / "rover.obs", base=m / "base.obs",
            nav=[m / "base.nav"], base_e=rb, truth=lambda t, rt=rt: np.broadcast_to(rt, (len(t), 3)),
            settings=[dict(name="matrtklib_l1_grec_inst", systems="GREC", freq=1, armode="instantaneous", mask=15.0),
                      dict(name="matrtklib_l1l2_grec_inst", systems="GREC", freq=2, armode="instantaneous", mask=15.0),
                      dict(name="matrtklib_l1l2_grec_cont", systems="GREC", freq=2, armode="continuous", mask=15.0),
                      # QZSS: the five systems of the data, and GPS alone against GPS + QZSS (weak geometry); on
                      # L1 alone also with the ratio test only (insnav's success-rate test off), as RTKLIB validates,
                      # and with the success rate of the configured covariance only (the estimated code variance
                      # factor's route off: the default before it)
                      dict(name="matrtklib_l1_grecj_inst", systems="GRECJ", freq=1, armode="instantaneous", mask=15.0),
                      dict(name="matrtklib_l1l2_g_inst", systems="G", freq=2, armode="instantaneous", mask=15.0),
                      dict(name="matrtklib_l1l2_gj_inst", systems="GJ", freq=2, armode="instantaneous", mask=15.0),
                      dict(name="matrtklib_l1_g_inst", systems="G", freq=1, armode="instantaneous", mask=15.0),
                      dict(name="matrtklib_l1_gj_inst", systems="GJ", freq=1, armode="instantaneous", mask=15.0),
                      dict(name="matrtklib_l1_g_inst_ratio", systems="G", freq=1, armode="instantaneous", mask=15.0,
                           insnav=dict(min_success_rate=0.0)),
                      dict(name="matrtklib_l1_gj_inst_ratio", systems="GJ", freq=1, armode="instantaneous", mask=15.0,
                           insnav=dict(min_success_rate=0.0)),
                      dict(name="matrtklib_l1_g_inst_srcfg", systems="G", freq=1, armode="instantaneous", mask=15.0,
                           insnav=dict(min_success_rate_estimated=0.0)),
                      dict(name="matrtklib_l1_gj_inst_srcfg", systems="GJ", freq=1, armode="instantaneous", mask=15.0,
                           insnav=dict(min_success_rate_estimated=0.0)),
                      # the correlated phase error states (off by default in GNSS-only RTK) on real data
                      dict(name="matrtklib_l1l2_grec_cont_phase", systems="GREC", freq=2, armode="continuous",
                           mask=15.0, insnav=PHASE_STATES),
                      dict(name="matrtklib_l1_g_inst_phase", systems="G", freq=1, armode="instantaneous", mask=15.0,
                           insnav=PHASE_STATES)])
    s = DATA / "instinct_spirent_rtk_dynamic_SIMULATED"
    if s.is_dir():
        v = s / "iono-Klob_tropo-Saast"
        pva = np.loadtxt(s / "Rover-dynamic_PVA_Spirent.csv", delimiter=",", skiprows=1)
        week = int(pva[0, 2] + 1024 * pva[0, 1])
        t_truth = week * 604800.0 + pva[:, 3]

        def truth(t, t_truth=t_truth, pva=pva):
            i = np.clip(np.searchsorted(t_truth, np.asarray(t) - 1e-4), 0, len(t_truth) - 1)
            r = pva[i, 4:7].copy()
            r[np.abs(t_truth[i] - t) > 1e-3] = np.nan
            return r

        with open(v / "Base-static_MO_Spirent.obs") as f:
            hdr = next(ln for ln in f if "APPROX POSITION XYZ" in ln)
        rb = np.array([float(hdr[14 * k:14 * k + 14]) for k in range(3)])
        out["instinct_spirent_rtk_dynamic_SIMULATED"] = dict(
            title="Spirent dynamic rover (hardware-simulated, Klobuchar + Saastamoinen, 1 Hz, 10 min)",
            rover=v / "Rover-dynamic_MO_Spirent.obs", base=v / "Base-static_MO_Spirent.obs",
            nav=[s / "RINEX_GN_Spirent.23N", s / "RINEX_EN_Spirent.23L"], base_e=rb, truth=truth,
            settings=[dict(name="spirent_dynamic_l1l2_ge_cont", systems="GE", freq=2, armode="continuous", mask=15.0),
                      dict(name="spirent_dynamic_l1l2_ge_cont_phase", systems="GE", freq=2, armode="continuous",
                           mask=15.0, insnav=PHASE_STATES)])
    return out


def rtklib_conf(st, base_e) -> str:
    navsys = sum(NAVSYS[s] for s in st["systems"])
    return "\n".join([
        "# RTKLIB 2.4.3 rnx2rtkp configuration written by bench/rtk_compare.py (the insnav TOML beside it "
        "holds the same options)",
        "pos1-posmode       =kinematic", f"pos1-frequency     ={FREQ[st['freq']]}", "pos1-soltype       =forward",
        f"pos1-elmask        ={st['mask']:g}", "pos1-snrmask_r     =off", "pos1-snrmask_b     =off",
        "pos1-dynamics      =off", "pos1-tidecorr      =off", "pos1-ionoopt       =brdc", "pos1-tropopt       =saas",
        "pos1-sateph        =brdc", f"pos1-navsys        ={navsys}", "pos1-exclsats      =",
        f"pos2-armode        ={st['armode']}", "pos2-gloarmode     =off", "pos2-bdsarmode     =on",
        "pos2-arthres       =3", "pos2-arlockcnt     =0", "pos2-arelmask      =0", "pos2-arminfix      =10",
        "pos2-elmaskhold    =0", "pos2-aroutcnt      =5", "pos2-maxage        =30", "pos2-slipthres     =0.05",
        "pos2-rejionno      =30", "pos2-niter         =1", "pos2-baselen       =0", "pos2-basesig       =0",
        "out-solformat      =xyz", "out-outhead        =on", "out-outopt         =off", "out-timesys        =gpst",
        "out-timeform       =tow", "out-timendec      =3", "out-outstat       =off",
        "stats-eratio1      =100", "stats-eratio2      =100", "stats-errphase     =0.003",
        "stats-errphaseel   =0.003", "stats-errphasebl   =0", "stats-errdoppler   =10",
        "stats-stdbias      =30", "stats-prnbias      =0.0001", "stats-prnaccelh    =3", "stats-prnaccelv    =1",
        "ant1-postype       =llh", "ant2-postype       =xyz",
        f"ant2-pos1          ={base_e[0]:.4f}", f"ant2-pos2          ={base_e[1]:.4f}",
        f"ant2-pos3          ={base_e[2]:.4f}", "ant2-antdelu       =0", "ant2-antdele       =0",
        "ant2-antdeln       =0", "misc-timeinterp    =off", ""])


def insnav_toml(st, base_e) -> str:
    return "\n".join([
        "# insnav run configuration written by bench/rtk_compare.py (the same options as the .conf beside it)",
        'filter = "rtk"', "", "[rtk]", 'mode = "kinematic"', f'ar_mode = "{st["armode"]}"',
        f'systems = "{st["systems"]}"', f"frequencies = {st['freq']}", f"elevation_mask_deg = {st['mask']:g}",
        "ratio_threshold = 3.0", "glonass_ar = false",
        *(f"{k} = {v!r}" for k, v in st.get("insnav", {}).items()),
        f"base_position_ecef_m = [{base_e[0]:.4f}, {base_e[1]:.4f}, {base_e[2]:.4f}]", ""])


def read_pos(path):
    """(t_gps_s, (n, 3) ECEF, Q) from an RTKLIB .pos file (xyz or llh layout, GPST week + seconds)."""
    t, r, q = [], [], []
    llh = False
    with open(path) as fh:
        lines = fh.readlines()
    for ln in lines:
        if ln.startswith("%"):
            if "latitude" in ln:
                llh = True
            continue
        f = ln.split()
        if len(f) < 6:
            continue
        if "/" in f[0]:
            from insnav.gnss.gpstime import gps_seconds_from_calendar

            y, mo, d = (int(x) for x in f[0].split("/"))
            hh, mi, ss = f[1].split(":")
            t.append(gps_seconds_from_calendar(y, mo, d, int(hh), int(mi), float(ss)))
        else:
            t.append(float(f[0]) * 604800.0 + float(f[1]))
        a, b, c = float(f[2]), float(f[3]), float(f[4])
        if llh:
            r.append(np.asarray(earth.geodetic_to_ecef(np.radians(a), np.radians(b), c), float).ravel())
        else:
            r.append((a, b, c))
        q.append(int(f[5]))
    return np.asarray(t), np.asarray(r, float).reshape(-1, 3), np.asarray(q, int)


def score(pos, truth, n_epochs):
    t, r, q = pos
    err = np.linalg.norm(r - truth(t), axis=1)
    fx = q == 1
    e = err[fx]
    e = e[np.isfinite(e)]
    return dict(epochs=n_epochs, fixed=int(fx.sum()), fix_rate=float(fx.sum()) / max(n_epochs, 1),
                rms_fixed_mm=float(1e3 * np.sqrt(np.mean(e ** 2))) if e.size else float("nan"),
                max_fixed_mm=float(1e3 * e.max()) if e.size else float("nan"),
                wrong=int(np.sum(e > WRONG_FIX_M)),
                float_median_mm=float(1e3 * np.nanmedian(err[q == 2])) if np.any(q == 2) else float("nan"))


def run_timed(cmd, env=None):
    """(wall time, CPU time user + sys) of the process [s]."""
    import resource

    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed ({p.returncode}): {p.stderr.strip()[-800:]}")
    return dt, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def n_rover_epochs(path):
    n = 0
    with open(path) as f:
        for ln in f:
            if ln.startswith(">"):
                n += 1
    return n


def run_setting(ds, st, repeat, work: Path):
    CONF_DIR.mkdir(parents=True, exist_ok=True)
    conf = CONF_DIR / f"{st['name']}.conf"
    toml = CONF_DIR / f"{st['name']}.toml"
    conf.write_text(rtklib_conf(st, ds["base_e"]))
    toml.write_text(insnav_toml(st, ds["base_e"]))
    out_r = work / f"{st['name']}_rtklib.pos"
    out_i = work / f"{st['name']}_insnav.pos"
    rnx = shutil.which("rnx2rtkp")
    cmd_r = [rnx, "-k", str(conf), "-o", str(out_r), str(ds["rover"]), str(ds["base"]), *map(str, ds["nav"])]
    env = dict(os.environ)  # the insnav this interpreter imports (an install of this tree)
    cmd_i = [sys.executable, "-m", "insnav", "run", "--filter", "rtk", "--format", "rinex", "--obs", str(ds["rover"]),
             "--base", str(ds["base"]), "--nav", ",".join(map(str, ds["nav"])), "--config", str(toml), "--out",
             str(out_i), "--quiet"]
    tr, ti = [], []
    for _ in range(repeat):
        tr.append(run_timed(cmd_r))
        ti.append(run_timed(cmd_i, env))
    n = n_rover_epochs(ds["rover"])
    res_r = score(read_pos(out_r), ds["truth"], n)
    res_i = score(read_pos(out_i), ds["truth"], n)
    res_r["time_s"], res_i["time_s"] = min(x[0] for x in tr), min(x[0] for x in ti)
    res_r["cpu_s"], res_i["cpu_s"] = min(x[1] for x in tr), min(x[1] for x in ti)
    return dict(setting=st, rtklib=res_r, insnav=res_i,
                cmd_insnav=_shown(["insnav"] + cmd_i[3:], work), cmd_rtklib=_shown(["rnx2rtkp"] + cmd_r[1:], work))


def _shown(cmd, work: Path) -> str:
    """A command as the reader types it: data under $DATA, outputs in the current folder."""
    return (" ".join(map(str, cmd)).replace(str(work) + "/", "").replace(str(ROOT) + "/", "")
            .replace(str(DATA), "$DATA"))


def verdicts(r, speed_target: bool):
    a, b = r["insnav"], r["rtklib"]
    v = dict(fix_rate="met" if a["fix_rate"] >= b["fix_rate"] else "NOT met",
             rms="met" if (np.isfinite(a["rms_fixed_mm"]) and (not np.isfinite(b["rms_fixed_mm"])
                                                               or a["rms_fixed_mm"] <= 1.2 * b["rms_fixed_mm"]))
             else "NOT met",
             wrong="met" if a["wrong"] == 0 else "NOT met")
    if speed_target:
        v["time"] = "met" if a["cpu_s"] <= 0.5 * b["cpu_s"] else "NOT met"
    return v


def _qzss_section(results) -> list:
    """Each setting with QZSS (J) beside the same setting without it: what the QZSS satellites change."""
    by = {(r["setting"]["systems"], r["setting"]["freq"], r["setting"]["armode"],
           tuple(sorted(r["setting"].get("insnav", {}).items()))): r for r in results}
    L = []
    for (systems, freq, armode, extra), r in by.items():
        if "J" not in systems or (systems.replace("J", ""), freq, armode, extra) not in by:
            continue
        r0 = by[(systems.replace("J", ""), freq, armode, extra)]
        if not L:
            L = ["", "## QZSS", "",
                 "Each setting with QZSS beside the same setting without it (QZSS double differences against a "
                 "QZSS reference satellite of their own).", "",
                 "| with QZSS | without | program | fixed (without -> with) | 3-D RMS fixed [mm] (without -> with) "
                 "| wrong fixes (without -> with) |", "|---|---|---|---|---|---|"]
        for prog in ("insnav", "rtklib"):
            a, b = r0[prog], r[prog]
            L.append(f"| {r['setting']['name']} | {r0['setting']['name']} | {prog} | {a['fixed']} -> {b['fixed']} | "
                     f"{a['rms_fixed_mm']:.2f} -> {b['rms_fixed_mm']:.2f} | {a['wrong']} -> {b['wrong']} |")
    return L


def truth_code_variance_factor(ds, systems: str, freq: int, mask_deg: float) -> tuple:
    """Mean of z^2 over the double-differenced code rows at the true rover position, z = residual /
    its configured sigma (the insnav defaults: phase 3 mm, code 100 x, elevation weighting), and the
    same of the phase rows (the fractional part of the DD phase in cycles, in metres): what the
    receiver pair's noise is against the configured one (1: as configured).  Returns (k_code,
    k_phase, rows)."""
    from insnav import _core
    from insnav.gnss.rtk import RtkOptions, prepare_rtk_rows

    opt = RtkOptions.from_dict(dict(ar_mode="instantaneous", systems=systems, frequencies=freq,
                                    elevation_mask_deg=mask_deg), "truth_code_variance_factor")
    rover, _base, rb, bidx, roff, rrows, boff, brows = prepare_rtk_rows(ds["rover"], ds["base"], ds["nav"],
                                                                         ds["base_e"], opt)
    rt = ds["truth"](rover.epoch_t_gps_s)
    cd = opt.core_dict()

    def el(rows, r):
        lat, lon, _h = earth.ecef_to_geodetic(r)
        up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]).ravel()
        d = rows[:, 17:20] - r
        return np.arcsin((d @ up) / np.linalg.norm(d, axis=1))

    def var_zd(e):
        return opt.sigma_phase_a_m ** 2 + opt.sigma_phase_b_m ** 2 / np.maximum(np.sin(e), 0.05) ** 2

    zc, zp = [], []
    for k in range(rover.epoch_t_gps_s.size):
        j = bidx[k]
        if j < 0 or not np.all(np.isfinite(rt[k])):
            continue
        R, B = rrows[roff[k]:roff[k + 1]], brows[boff[j]:boff[j + 1]]
        d = _core.rtk_double_differences(R, B, np.ascontiguousarray(rt[k]), rb, cd)
        el_r, el_b = el(R, rt[k]), el(B, rb)
        row_b = {int(b[0]): i for i, b in enumerate(B)}
        v = {}
        for s, r, f, c, val in zip(d["sat_row"], d["ref_row"], d["freq"], d["is_code"], d["value_m"]):
            for q in (s, r):
                v.setdefault(q, var_zd(el_r[q]) + var_zd(el_b[row_b[int(R[q, 0])]]))
            sig = np.sqrt(v[s] + v[r])
            if c:
                zc.append(val / (opt.code_phase_ratio * sig))
            else:
                lam = R[s, 6 + 5 * f]
                zp.append((val / lam - np.round(val / lam)) * lam / sig)
    return float(np.mean(np.square(zc))), float(np.mean(np.square(zp))), len(zc)


def _noise_section(ds, results) -> list:
    """Why the success-rate test of the configured covariance keeps the L1 single-system settings
    float: the receivers' real scatter against the configured one, and the engine's estimate."""
    from insnav.gnss.rtk import RtkOptions, solve_rtk

    d = RtkOptions()
    L = ["", "## Success-rate test and the receivers' noise", "",
         "Each single-system L1 setting: the mean squared double-differenced code (and phase) residual at the "
         "true position over its configured variance (k from the truth, 1 when the receivers are as noisy as "
         "configured), the engine's code variance factor k estimated from its least-squares code residuals "
         "(last epoch; `success_variance_factor`), and the median over the epochs of the bootstrapped success "
         "rate of the float covariance as configured and scaled by k (`success_rate`, `success_rate_estimated`); "
         f"then the fixed epochs of the default (a set passes with P_s(Q) >= min_success_rate = {d.min_success_rate:g} "
         f"or P_s(k Q) >= min_success_rate_estimated = {d.min_success_rate_estimated:g}), of the configured "
         "covariance's test alone "
         "(min_success_rate_estimated = 0) and of the ratio test alone (min_success_rate = 0), all run above.", "",
         "| setting | code k from the truth | phase k from the truth | code k estimated | median P_s(Q) | "
         "median P_s(k Q) | fixed: default | SR configured only | ratio only | RTKLIB |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    by = {r["setting"]["name"]: r for r in results}
    for st in ds["settings"]:
        if st["freq"] != 1 or st.get("insnav") or len(st["systems"].replace("J", "")) != 1:
            continue
        kc, kp, _n = truth_code_variance_factor(ds, st["systems"], st["freq"], st["mask"])
        rs = solve_rtk(ds["rover"], ds["base"], ds["nav"], ds["base_e"],
                       RtkOptions.from_dict(dict(mode="kinematic", ar_mode=st["armode"], systems=st["systems"],
                                                 frequencies=st["freq"], elevation_mask_deg=st["mask"]), "noise"))
        fx = {k: by[n]["insnav"]["fixed"] if n in by else "-" for k, n in
              (("default", st["name"]), ("cfg", st["name"] + "_srcfg"), ("ratio", st["name"] + "_ratio"))}
        L.append(f"| {st['name']} | {kc:.3f} | {kp:.3f} | {rs.success_variance_factor[-1]:.3f} | "
                 f"{np.median(rs.success_rate):.3f} | {np.median(rs.success_rate_estimated):.4f} | {fx['default']} | "
                 f"{fx['cfg']} | {fx['ratio']} | {by[st['name']]['rtklib']['fixed']} |")
    return L


def _path_text(results) -> str:
    """Which settings insnav's numpy-free path covers (insnav.cli.rtk_fast: RINEX 3, GPS and QZSS;
    tests/test_rtk_fast.py checks that it runs on exactly these and writes the Python path's files)."""
    fast = [r["setting"]["name"] for r in results if set(r["setting"]["systems"]) <= set("GJ")]
    if not fast:
        return "insnav runs its Python path (numpy) on every setting here."
    return (f"insnav runs without numpy (one call into its compiled core, `insnav.cli.rtk_fast`; the same files as "
            f"its Python path) on {', '.join(fast)}; on the others its Python path (numpy).")


def write_doc(name, ds, results, path: Path):
    speed = name == "matrtklib_static_septentrio"
    L = [f"# RTK on {ds['title']}: insnav vs RTKLIB", "",
         f"Written by `{COMMAND}` at commit {git_commit()}; do not edit by hand.  Data: `../shared/data/{name}/` "
         "(its README).  RTKLIB: Debian's `rnx2rtkp` (2.4.3 b34) with the configuration files under `bench/rtk/`; "
         "insnav: `insnav run --filter rtk` with the TOML beside each, the same options and base position.  Both "
         "kinematic (a position every epoch, no dynamics model in RTKLIB), forward, broadcast ephemerides.", "",
         f"Truth: {'the marker coordinates of the oracle file plus the antenna heights (ARP)' if 'wtz' in name else ('the known antenna positions' if speed else 'the 10 Hz Spirent truth at each rover epoch')}.  "
         f"A wrong fix is a fixed epoch more than {100 * WRONG_FIX_M:.0f} cm from the truth.  Time: the whole process "
         "(Python start, reading, satellite orbits, filter, writing), best of the repeats, both programs run "
         "alternately on the same machine; CPU is user + system time of the process, the comparable figure on a "
         "shared machine (wall time is also given; it grows with the machine's load).  "
         + _path_text(results), "",
         "| setting | program | epochs | fixed | fix rate | 3-D RMS fixed [mm] | max fixed [mm] | wrong fixes | "
         "float median [mm] | CPU [s] | wall [s] |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        st = r["setting"]
        lab = f"{st['name']} ({FREQ[st['freq']].upper()}, {st['systems']}, {st['armode']}, mask {st['mask']:g} deg" + \
            "".join(f"; insnav {k} = {v!r}" for k, v in st.get("insnav", {}).items()) + ")"
        for prog in ("insnav", "rtklib"):
            x = r[prog]
            L.append(f"| {lab} | {prog} | {x['epochs']} | {x['fixed']} | {100 * x['fix_rate']:.1f} % | "
                     f"{x['rms_fixed_mm']:.2f} | {x['max_fixed_mm']:.2f} | {x['wrong']} | {x['float_median_mm']:.0f} | "
                     f"{x['cpu_s']:.2f} | {x['time_s']:.2f} |")
    L += ["", "## Targets", "", "| setting | fix rate >= RTKLIB | RMS <= 1.2x RTKLIB | no wrong fix |"
          + (" CPU time <= 0.5x RTKLIB |" if speed else ""), "|---|---|---|---|" + ("---|" if speed else "")]
    ablations = [r for r in results if r["setting"].get("insnav")]
    for r in results:
        if r in ablations:
            continue
        v = verdicts(r, speed)
        ratio = r["insnav"]["cpu_s"] / r["rtklib"]["cpu_s"]
        L.append(f"| {r['setting']['name']} | {v['fix_rate']} | {v['rms']} | {v['wrong']} |"
                 + (f" {v['time']} ({ratio:.2f}x) |" if speed else ""))
    if ablations:
        # insnav with one of its options changed from the default: what the option does, not a setting
        # the targets judge (RTKLIB runs the same configuration in both rows of a pair)
        L += ["", "Ablations (insnav with the option named in the setting changed from its default; the same "
              "comparisons, not judged as targets):", "",
              "| setting | insnav option | fix rate >= RTKLIB | RMS <= 1.2x RTKLIB | no wrong fix |"
              + (" CPU time <= 0.5x RTKLIB |" if speed else ""), "|---|---|---|---|---|" + ("---|" if speed else "")]
        for r in ablations:
            v = verdicts(r, speed)
            ratio = r["insnav"]["cpu_s"] / r["rtklib"]["cpu_s"]
            opt = ", ".join(f"{k} = {x!r}" for k, x in r["setting"]["insnav"].items())
            L.append(f"| {r['setting']['name']} | {opt} | {v['fix_rate']} | {v['rms']} | {v['wrong']} |"
                     + (f" {v['time']} ({ratio:.2f}x) |" if speed else ""))
    L += _qzss_section(results)
    if speed:
        L += _noise_section(ds, results)
    L += ["", "## Commands", ""]
    for r in results:
        L += [f"- `{r['cmd_insnav']}`", f"- `{r['cmd_rtklib']}`"]
    L.append("")
    path.write_text(with_stamp("\n".join(L), path))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=None, help="comma-separated dataset names")
    ap.add_argument("--repeat", type=int, default=3, help="timing repeats (best kept)")
    ap.add_argument("--out-dir", default=str(ROOT / "docs" / "results"))
    a = ap.parse_args(argv)
    if shutil.which("rnx2rtkp") is None:
        sys.exit("rnx2rtkp not found: apt-get install rtklib")
    dss = datasets()
    if not dss:
        sys.exit(f"no data under {DATA}")
    only = None if a.only is None else set(a.only.split(","))
    compile_package()
    with tempfile.TemporaryDirectory() as tmp:
        for name, ds in dss.items():
            if only and name not in only:
                continue
            res = [run_setting(ds, st, a.repeat, Path(tmp)) for st in ds["settings"]]
            out = Path(a.out_dir) / f"rtk_{name}.md"
            write_doc(name, ds, res, out)
            for r in res:
                print(r["setting"]["name"], "insnav", r["insnav"], "rtklib", r["rtklib"], flush=True)
            print("wrote", out, flush=True)


if __name__ == "__main__":
    main()
