"""TDCP/INS on real data (rtklibexplorer walk_0827): time-differenced carrier phase
in the tight EKF, rover only (no base), against the code + Doppler tight EKF, with
GNSS outages inserted.

Both filters read the same files as ``insnav run --format rinex --config
tests/data/walk_0827.toml --coupling tight --filter ekf`` (``--tdcp`` for TDCP/INS:
pseudorange + Doppler + TDCP rows).  The RTK ``.pos`` is the reference only.
Complete GNSS outages (every satellite row of the epochs in the window removed,
the same windows for both methods) of 10, 30 and 60 s are inserted one per run,
at several start times; inside each the maximum horizontal drift is measured:
``max |e(t) - e(t_start)|`` with ``e`` the horizontal antenna error against the
reference and ``t_start`` the last reference epoch before the outage (so the
reference's constant offset from every single-point solution (the RTK base)
and the filter's own offset at the start cancel).  The runs are paired (same
window), the statistics are those of ``insnav.analysis.paired``.  TDCP/INS is
also run with the RTS smoother (``smooth = true``) on the complete-outage windows:
its max drift against the forward TDCP/INS's, paired the same way.

Reproduce (from the repository root, with ../shared/data beside the repo)::

    python3 bench/tdcp_walk.py --out docs/results/tdcp_walk.md
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import insnav  # noqa: E402
from _common import git_commit  # noqa: E402
from _stamps import with_stamp  # noqa: E402
from insnav import _core, earth  # noqa: E402
from insnav.analysis.paired import paired  # noqa: E402
from insnav.config import ImuNoise  # noqa: E402
from insnav.io.gnss_files import read_rtklib_pos  # noqa: E402
from insnav.io.rinex_dataset import load_rinex_run  # noqa: E402

COMMAND = "python3 bench/tdcp_walk.py --out docs/results/tdcp_walk.md"
CONFIG = ROOT / "tests" / "data" / "walk_0827.toml"
DEG = np.pi / 180.0
#: outage lengths [s] and the start times of their windows [s after the run start]
WINDOWS = {10.0: (10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0),
           30.0: (10.0, 25.0, 40.0, 55.0, 70.0),
           60.0: (10.0, 25.0, 40.0)}
TARGET = 0.5  # TDCP/INS drift <= TARGET x the code + Doppler filter's
G0 = 9.80665  # [m/s^2], for the drift of a gyro-bias error (g b t^3 / 6)
SIGMA_WIDE = 0.03  # [m]: a TDCP phase sigma 3x the default, for the consistency row of the diagnosis
END_STILL_S = 30.0  # the walker stands still again in the log's last seconds: its standstill is searched here [s]


def run_with_inputs(ds, config, inputs):
    """``insnav.run(ds, config=config)`` with ``ds.tight_inputs`` replaced by ``inputs`` for the call."""
    inp0 = ds.tight_inputs
    ds.tight_inputs = inputs
    try:
        return insnav.run(ds, config=config)
    finally:
        ds.tight_inputs = inp0


def with_outage(inputs, t_lo, t_hi):
    """The inputs with every row of the epochs t_lo < t <= t_hi removed (empty epochs: prediction only)."""
    if t_hi <= t_lo:
        return inputs
    ep = inputs.row_epoch
    t = inputs.epoch_t[ep]
    return inputs.select(~((t > t_lo) & (t <= t_hi)))


def without_code(inputs, t_lo, t_hi):
    """The inputs with the pseudoranges of the epochs t_lo < t <= t_hi removed (Doppler and phase kept)."""
    t = inputs.epoch_t[inputs.row_epoch]
    sats = inputs.sats.copy()
    sats[(t > t_lo) & (t <= t_hi), 0] = np.nan
    return dataclasses.replace(inputs, sats=sats)


def horizontal_error(sol, ds, ref_t, ref_r_e):
    """(t, e (n, 2)) horizontal antenna error N, E against the reference at its epochs inside the run [m]."""
    m = (ref_t >= sol.t[0]) & (ref_t <= sol.t[-1])
    t = ref_t[m]
    lat = np.interp(t, sol.t, sol.lat_deg) * DEG
    lon = np.interp(t, sol.t, sol.lon_deg) * DEG
    h = np.interp(t, sol.t, sol.h_m)
    yaw = np.interp(t, sol.t, np.unwrap(sol.yaw_deg * DEG))
    rpy = np.column_stack([np.interp(t, sol.t, sol.roll_deg) * DEG, np.interp(t, sol.t, sol.pitch_deg) * DEG, yaw])
    lever_n = np.array([np.asarray(_core.rotation.dcm_from_euler(a)) @ ds.lever_arm_b for a in rpy])
    r = earth.geodetic_to_ecef(lat, lon, h) + earth.ned_to_ecef_vector(lat, lon, lever_n)
    lat0, lon0, _ = earth.ecef_to_geodetic(ref_r_e[m][0])
    e = earth.ecef_to_ned_vector(lat0, lon0, r - ref_r_e[m])
    return t, e[:, :2]


def sigma_h_end(sol, t_hi):
    """Horizontal 1-sigma of the filter's position at the last output at or before t_hi [m]: what the filter
    predicts for the drift of a complete outage ending there (the error at its start is far smaller)."""
    k = max(int(np.searchsorted(sol.t, t_hi, side="right")) - 1, 0)
    return float(np.hypot(*sol.sigma_pos_n_m[k, :2]))


def drift_in(t, e, t_lo, t_hi):
    """Max horizontal |e(t) - e(t_start)| over the reference epochs t_lo < t <= t_hi [m]."""
    i0 = int(np.searchsorted(t, t_lo, side="right")) - 1
    w = (t > t_lo) & (t <= t_hi)
    if i0 < 0 or not w.any():
        return np.nan
    return float(np.max(np.hypot(*(e[w] - e[i0]).T)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path,
                    default=Path(os.environ.get("INSNAV_SHARED_DATA", ROOT.parent / "shared" / "data")))
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    wall0 = time.perf_counter()
    d = a.data / "rtklibexplorer_walk_0827"
    if not d.is_dir():
        print(f"{d} not found", file=sys.stderr)
        return 1
    obs, nav = d / "rinex_derived/gnss_1730.obs", d / "rinex_derived/gnss_1730.nav"
    ds, cfg = load_rinex_run(obs, nav, d / "raw/imu_1730.csv", CONFIG)
    ref = read_rtklib_pos(d / "raw/gnss_1730_sf.pos")
    ref_t = ref.t_gps_s - ds.gps_time_offset_s
    inp0 = ds.tight_inputs
    cfg_code = dataclasses.replace(cfg, coupling="tight", filter="ekf")
    cfg_tdcp = dataclasses.replace(cfg_code, tdcp=dataclasses.replace(cfg.tdcp, enabled=True))
    t_run0, t_run1 = float(ds.t0), float(ds.imu.t[-1])

    def run(c, inputs):
        return run_with_inputs(ds, c, inputs)

    # ---------------------------------------------------------------- no outage
    full = {}
    for name, c in (("code", cfg_code), ("tdcp", cfg_tdcp)):
        s = run(c, inp0)
        t, e = horizontal_error(s, ds, ref_t, ref.r_e)
        full[name] = (s, t, e)
    s_t = full["tdcp"][0]
    summ = s_t.summary
    res_used = s_t.tdcp_residual_m[s_t.tdcp_flag == 0]
    ac1 = residual_lag1(s_t, inp0)
    n_phase = int(np.isfinite(inp0.phase[:, 0]).sum())

    # ---------------------------------------------------------------- outages
    cfg_tdcp_s = dataclasses.replace(cfg_tdcp, smooth=True)
    smooth_rows_ = []

    def campaign(make_inputs, smooth=False):
        rows, verdicts, per = [], [], {}
        for dur, starts in WINDOWS.items():
            dc, dt_, ds_ = [], [], []
            sg = {"code": [], "tdcp": [], "bg_code": [], "bg_tdcp": []}
            for st in starts:
                lo = t_run0 + st
                hi = lo + dur
                if hi > t_run1:
                    continue
                inp = make_inputs(inp0, lo, hi)
                out = {}
                for name, c in (("code", cfg_code), ("tdcp", cfg_tdcp)):
                    s = run(c, inp)
                    t, e = horizontal_error(s, ds, ref_t, ref.r_e)
                    out[name] = drift_in(t, e, lo, hi)
                    sg[name].append(sigma_h_end(s, hi))
                    k0 = max(int(np.searchsorted(s.t, lo, side="right")) - 1, 0)
                    sg["bg_" + name].append(s.gyro_bias_rps[k0, :2])
                if smooth:  # TDCP/INS with the RTS smoother (filter/rts_smoother.hpp, clone-augmented kernel)
                    t, e = horizontal_error(run(cfg_tdcp_s, inp), ds, ref_t, ref.r_e)
                    ds_.append(drift_in(t, e, lo, hi))
                dc.append(out["code"])
                dt_.append(out["tdcp"])
                rows.append(f"| {dur:.0f} | {st:.0f}-{st + dur:.0f} | {out['code']:.2f} | {out['tdcp']:.2f} | "
                            f"{out['tdcp'] / out['code']:.2f} |")
            dc, dt_ = np.array(dc), np.array(dt_)
            if smooth:
                ds_ = np.array(ds_)
                prs = paired(ds_, dt_)
                smooth_rows_.append(f"| {dur:.0f} s | {dt_.size} | {dt_.mean():.2f} | {ds_.mean():.2f} | "
                                    f"{ds_.mean() / dt_.mean():.2f} | {np.max(dt_):.2f} | {np.max(ds_):.2f} | "
                                    f"{prs.wins}/{prs.n} | {prs.p_wilcoxon:.2g} | {prs.verdict()} |")
            pr = paired(dt_, dc)
            ratio = float(dt_.mean() / dc.mean())
            met = ratio <= TARGET
            per[dur] = (dc, dt_, pr, ratio, met, {k: np.array(v) for k, v in sg.items()})
            verdicts.append(f"| {dur:.0f} s | {dc.size} | {dc.mean():.2f} | {dt_.mean():.2f} | {ratio:.2f} | "
                            f"{'met' if met else 'not met'} | {pr.wins}/{pr.n} | {pr.p_wilcoxon:.2g} | "
                            f"{pr.verdict()} |")
        return rows, verdicts, per

    rows, verdicts, per = campaign(with_outage, smooth=True)
    rows_b, verdicts_b, per_b = campaign(without_code)
    cons_rows = []
    for dur, (dc, dt_, pr, ratio, met, sg) in per.items():
        z_c, z_t = dc / sg["code"], dt_ / sg["tdcp"]
        dbg = np.linalg.norm(sg["bg_tdcp"] - sg["bg_code"], axis=1)  # |difference of the level gyro-bias estimates|
        cons_rows.append(f"| {dur:.0f} s | {dc.mean():.2f} | {sg['code'].mean():.2f} | {z_c.mean():.2f} | "
                         f"{dt_.mean():.2f} | {sg['tdcp'].mean():.2f} | {z_t.mean():.2f} | "
                         f"{np.degrees(dbg.mean()):.3f} | {G0 * dbg.mean() * dur ** 3 / 6:.1f} |")

    # ---------------------------------------------------------------- sensitivity (the 10 s complete outages)
    import tomllib

    from insnav.io.rinex_dataset import load_rinex

    rin = tomllib.loads(CONFIG.read_text())["rinex"]
    sens = []
    for off in (-0.05, 0.0, 0.05):
        ds_o, cfg_o = load_rinex(obs, nav, d / "raw/imu_1730.csv", dict(rin, imu_time_offset_s=off))
        inp_o = ds_o.tight_inputs
        for sig in (0.003, 0.01, 0.03):
            c_code = dataclasses.replace(cfg_o, coupling="tight", filter="ekf")
            c_tdcp = dataclasses.replace(c_code, tdcp=dataclasses.replace(cfg_o.tdcp, enabled=True, sigma_phase_m=sig))
            dr = {"code": [], "tdcp": []}
            for st in WINDOWS[10.0]:
                lo = float(ds_o.t0) + st
                ds_o.tight_inputs = with_outage(inp_o, lo, lo + 10.0)
                for name, c in (("code", c_code), ("tdcp", c_tdcp)):
                    s = insnav.run(ds_o, config=c)
                    t, e = horizontal_error(s, ds_o, ref.t_gps_s - ds_o.gps_time_offset_s, ref.r_e)
                    dr[name].append(drift_in(t, e, lo, lo + 10.0))
            ds_o.tight_inputs = inp_o
            s_full = insnav.run(ds_o, config=c_tdcp)
            r = s_full.tdcp_residual_m[s_full.tdcp_flag == 0]
            sens.append(f"| {off:+.2f} | {sig} | {np.sqrt(np.mean(r ** 2)) * 100:.1f} | {np.mean(dr['code']):.2f} | "
                        f"{np.mean(dr['tdcp']):.2f} | {np.mean(dr['tdcp']) / np.mean(dr['code']):.2f} |")

    # ---------------------------------------------------------------- diagnosis: the hypotheses, measured
    from insnav.config import TimeOffset

    ds_g, cfg_g = load_rinex(obs, nav, d / "raw/imu_1730.csv", dict(rin, init_gyro_bias="static"))
    td_on = TimeOffset(estimate_offset=True)
    diag = []  # (label, {dur: (code, tdcp, ratio, z_code, z_tdcp)}, {name: no-outage track RMS})
    offsets = {}
    for label, dsv, c0 in (("time offset as a state (`[time] estimate_offset = true`)", ds,
                            dataclasses.replace(cfg_code, time=td_on)),
                           ("gyro bias from the standstill (`[rinex] init_gyro_bias = \"static\"`)", ds_g,
                            dataclasses.replace(cfg_g, coupling="tight", filter="ekf")),
                           ("both", ds_g, dataclasses.replace(cfg_g, coupling="tight", filter="ekf", time=td_on)),
                           (f"gyro bias from the standstill, TDCP sigma_phase_m = {SIGMA_WIDE}", ds_g,
                            dataclasses.replace(cfg_g, coupling="tight", filter="ekf"))):
        sig = SIGMA_WIDE if "sigma_phase_m" in label else c0.tdcp.sigma_phase_m
        c_t = dataclasses.replace(c0, tdcp=dataclasses.replace(c0.tdcp, enabled=True, sigma_phase_m=sig))
        ratios_v, full_v = outage_ratios(dsv, ref.t_gps_s - dsv.gps_time_offset_s, ref.r_e, c0, c_t)
        diag.append((label, ratios_v, full_v))
        if c0.time.estimate_offset and label not in offsets:
            for name, c in (("code", c0), ("tdcp", c_t)):
                so = insnav.run(dsv, config=c)
                offsets[name] = (float(so.time_offset_s[-1]), float(so.sigma_time_offset_s[-1]))
    base_ratios = {dur: (v[0].mean(), v[1].mean(), v[3], float(np.mean(v[0] / v[5]["code"])),
                         float(np.mean(v[1] / v[5]["tdcp"]))) for dur, v in per.items()}
    diag.insert(0, ("as above (the walk TOML)", base_ratios, None))
    diag_rows = []
    for label, rv, fv in diag:
        cells = " | ".join(f"{rv[dur][0]:.2f} / {rv[dur][1]:.2f} = **{rv[dur][2]:.2f}** ({rv[dur][3]:.2f}, {rv[dur][4]:.2f})"
                           for dur in WINDOWS)
        fcell = "(the table above)" if fv is None else f"{fv['code']:.3f} / {fv['tdcp']:.3f}"
        diag_rows.append(f"| {label} | {cells} | {fcell} |")
    best = {dur: min(diag, key=lambda v: v[1][dur][2]) for dur in WINDOWS}
    best_line = "; ".join(f"{dur:.0f} s: {best[dur][1][dur][2]:.2f} ({best[dur][0].split(' (')[0]})" for dur in WINDOWS)
    any_met = any(v[1][dur][2] <= TARGET for v in diag for dur in WINDOWS)
    all_met_v = [v[0] for v in diag if all(v[1][dur][2] <= TARGET for dur in WINDOWS)]
    res_rows, res_med_cm = residuals_by_elevation(s_t, inp0, cfg_tdcp.tdcp.sigma_phase_m)
    sols_g = {"code + Doppler, zero start": full["code"][0], "TDCP/INS, zero start": full["tdcp"][0],
              "code + Doppler, static start": insnav.run(ds_g, config=dataclasses.replace(cfg_g, coupling="tight",
                                                                                         filter="ekf")),
              "TDCP/INS, static start": insnav.run(ds_g, config=dataclasses.replace(
                  cfg_g, coupling="tight", filter="ekf", tdcp=dataclasses.replace(cfg_g.tdcp, enabled=True)))}
    gb0, gs0, gb1, gs1, log_s, gerr = gyro_bias_standstills(ds, sols_g)
    noise0 = ImuNoise.from_dataset_model(ds.imu_model)
    q_model = 2.0 * np.asarray(noise0.gyro_bias_sigma) ** 2 / np.asarray(noise0.gyro_bias_tau)  # [rad^2/s^3]
    q_data = (gb1 - gb0) ** 2 / log_s  # one random-walk draw over the log [rad^2/s^3]
    gb_rows = [f"| {name} | " + " | ".join(f"{np.degrees(x):.3f}" for x in e) + " |" for name, e in gerr.items()]

    # ---------------------------------------------------------------- overall error (no outage)
    def overall(name):
        s, t, e = full[name]
        hz = np.hypot(*e.T)
        c = e - e.mean(axis=0)
        return (float(np.sqrt(np.mean(hz ** 2))), float(hz.max()), float(np.sqrt(np.mean(np.sum(c ** 2, axis=1)))),
                *e.mean(axis=0))

    def velocity_rms(name):
        s, _, _ = full[name]
        m = (ref_t >= s.t[0]) & (ref_t <= s.t[-1])
        t = ref_t[m]
        lat0, lon0, _ = earth.ecef_to_geodetic(ref.r_e[m][0])
        v_ref = earth.ecef_to_ned_vector(lat0, lon0, ref.v_e[m])
        v = np.column_stack([np.interp(t, s.t, s.v_n[:, i]) for i in range(2)])
        return float(np.sqrt(np.mean(np.sum((v - v_ref[:, :2]) ** 2, axis=1))))

    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        sim_rows, sim_verdicts, sim_ratios, sim_desc = simulated_car(tmp)
    ov = {k: overall(k) for k in full}
    vr = {k: velocity_rms(k) for k in full}
    # paired over the reference epochs: |e - mean e| of each
    ec = {k: np.hypot(*(full[k][2] - full[k][2].mean(axis=0)).T) for k in full}
    pr_all = paired(ec["tdcp"], ec["code"])
    wall = time.perf_counter() - wall0
    all_met = all(v[4] for v in per.values())

    md = f"""# TDCP/INS on the walk: time-differenced carrier phase without a base

Generated by `bench/tdcp_walk.py` at commit `{git_commit()}`.  Reproduce: `{COMMAND}`
({wall:.0f} s on the shared 2-core machine).

Data: `../shared/data/rtklibexplorer_walk_0827` (u-blox RINEX 3.04, GPS L1 C/A code, carrier
phase and Doppler; the raw consumer IMU log with its str2str tag; {t_run1 - t_run0:.0f} s of run
after the course-over-ground start; see [tight_realdata.md](tight_realdata.md)).  The RTK `.pos`
is the reference only.  GPS satellites with ephemeris per epoch: {int(inp0.n_sats().min())}-{int(inp0.n_sats().max())}.

Both filters: `insnav run --format rinex --config tests/data/walk_0827.toml --coupling tight --filter
ekf` (the code + Doppler tight EKF), and the same with `--tdcp` (TDCP/INS: + one
time-differenced carrier-phase row per satellite tracked at two consecutive epochs, stochastic
cloning of the previous epoch's error state; `[tdcp]` defaults: zero-difference phase sigma
{cfg_tdcp.tdcp.sigma_phase_m} m / sin(el), slip test {cfg_tdcp.tdcp.slip_threshold_cycles} cycle,
chi-square {cfg_tdcp.tdcp.chi2_row}; docs/algorithms.md section 19).

## TDCP rows over the whole run (no outage)

* Satellite rows with carrier phase: {n_phase} of {len(inp0.prn)}.
* TDCP rows used: {summ['tdcp_used']} in {summ['tdcp_updates']} epochs; rejected by the per-row
  chi-square: {summ['tdcp_rejected']}; slips: {summ['tdcp_slips_lli']} by the loss-of-lock indicator
  (or a half-cycle flag change), {summ['tdcp_slips_ins']} by the INS-predicted phase-change test.
* Residuals of the rows used (INS-predicted minus measured phase change, before the update):
  RMS {np.sqrt(np.mean(res_used ** 2)) * 100:.1f} cm, 95th percentile {np.quantile(np.abs(res_used), 0.95) * 100:.1f} cm,
  max {np.abs(res_used).max() * 100:.1f} cm.

## Overall horizontal error against the RTK `.pos` (no outage)

Antenna (IMU centre + lever arm), at the {full['code'][1].size} reference epochs inside the run.
The reference sits {np.hypot(ov['code'][3], ov['code'][4]):.1f} m (code + Doppler filter's mean offset) from the
pseudorange solutions (the RTK base; tight_realdata.md), so the absolute error is that offset; the error around its mean is the shape of the track.

| filter | horizontal RMS [m] | max [m] | mean offset N, E [m] | RMS around the mean offset [m] | horizontal velocity RMS [m/s] |
|---|---|---|---|---|---|
| code + Doppler tight EKF | {ov['code'][0]:.2f} | {ov['code'][1]:.2f} | {ov['code'][3]:+.2f}, {ov['code'][4]:+.2f} | {ov['code'][2]:.3f} | {vr['code']:.3f} |
| TDCP/INS (code + Doppler + TDCP) | {ov['tdcp'][0]:.2f} | {ov['tdcp'][1]:.2f} | {ov['tdcp'][3]:+.2f}, {ov['tdcp'][4]:+.2f} | {ov['tdcp'][2]:.3f} | {vr['tdcp']:.3f} |

Paired over the reference epochs (error around each filter's mean offset): TDCP/INS smaller at
{pr_all.wins} of {pr_all.n} epochs, Wilcoxon p = {pr_all.p_wilcoxon:.2g} ({pr_all.verdict()}; epochs are
serially correlated, so this p-value is optimistic).

## Drift inside GNSS outages

Every satellite row of the epochs inside the window is removed (complete outage: no code, no
Doppler, no phase; TDCP restarts after it, as a receiver that lost the signals would).  Max
horizontal drift = max over the reference epochs inside the window of |e(t) - e(t_start)|.
Window start in seconds after the run start (t0 = {t_run0:.2f} s of GPS week).

| outage [s] | window [s] | code + Doppler max drift [m] | TDCP/INS max drift [m] | TDCP / code |
|---|---|---|---|---|
{chr(10).join(rows)}

Target: mean TDCP/INS drift at most {TARGET}x the code + Doppler filter's (ratio of the means over the
windows).  Paired test "TDCP/INS drifts less" (Wilcoxon signed-rank, two-sided, alpha 0.05):

| outage | windows | code + Doppler mean max drift [m] | TDCP/INS mean [m] | ratio | target <= {TARGET} | TDCP smaller | Wilcoxon p | verdict |
|---|---|---|---|---|---|---|---|---|
{chr(10).join(verdicts)}

TDCP/INS forward against RTS-smoothed (`smooth = true`: the backward pass with the TDCP rows'
clone-augmented kernel, `cpp/include/insnav/filter/rts_smoother.hpp`) on the same complete-outage
windows; paired test "smoothed drifts less" (Wilcoxon signed-rank, two-sided, alpha 0.05):

| outage | windows | TDCP/INS forward mean max drift [m] | smoothed mean [m] | ratio | forward max [m] | smoothed max [m] | smoothed smaller | Wilcoxon p | verdict |
|---|---|---|---|---|---|---|---|---|---|
{chr(10).join(smooth_rows_)}

Target met in every outage length: **{'yes' if all_met else 'no'}**.

Is the missing gain a fault of the TDCP rows?  The same 10 s complete outages with the IMU time
shifted against GNSS (`imu_time_offset_s`: the tag-derived time is right to about 0.1 s,
tight_realdata.md) and with other phase sigmas (mean max drift over the {len(WINDOWS[10.0])} windows):

| IMU time offset [s] | sigma_phase_m [m] | TDCP residual RMS [cm] | code + Doppler [m] | TDCP/INS [m] | TDCP / code |
|---|---|---|---|---|---|
{chr(10).join(sens)}

### Diagnosis: the hypotheses, measured

Complete outages as above (every window), each filter pair re-run with one change.  Cells: code + Doppler
mean max drift / TDCP/INS mean max drift [m] = **ratio** (mean drift / end sigma of code + Doppler,
TDCP/INS); last column: the no-outage track error around the mean offset, code + Doppler / TDCP/INS [m].

| set-up (both filters) | 10 s | 30 s | 60 s | no-outage RMS around the mean [m] |
|---|---|---|---|---|
{chr(10).join(diag_rows)}

Lowest ratio per outage length: {best_line}.  A set-up meeting the {TARGET}x target in every
length: {', '.join(all_met_v) if all_met_v else 'none'}{'' if any_met else f' (no cell at or below {TARGET})'}.

* Timing: with the time-offset state (its TDCP column: the difference of the two epochs' range-rate columns,
  `meas/tdcp.hpp`) the estimates at the end of the run are t_d = {offsets['code'][0] * 1e3:+.1f} +- {offsets['code'][1] * 1e3:.1f} ms
  (code + Doppler) and {offsets['tdcp'][0] * 1e3:+.1f} +- {offsets['tdcp'][1] * 1e3:.1f} ms (TDCP/INS).
* The TDCP rows' noise: residuals of the used rows per elevation [cm], before the update; most of the raw
  RMS is common to the epoch's satellites (RMS of the epoch medians {res_med_cm:.2f} cm: the receiver clock
  change, which the clock states take), and the rest is below the rows' own sigma, so a sigma from the
  residuals would be smaller, not larger:

| elevation [deg] | rows | RMS | RMS less the epoch median | row sigma sqrt(2) sigma_phase / sin(el) |
|---|---|---|---|---|
{chr(10).join(res_rows)}

* Process noise against the data: the walker stands still before the start and again at the end of the
  log; the gyro bias there (the standstill detector's samples, body x, y, z) is
  {', '.join(f'{np.degrees(x):+.3f}' for x in gb0)} deg/s (1-sigma {', '.join(f'{np.degrees(x):.3f}' for x in gs0)})
  and {', '.join(f'{np.degrees(x):+.3f}' for x in gb1)} deg/s ({', '.join(f'{np.degrees(x):.3f}' for x in gs1)}) {log_s:.0f} s later:
  one random-walk draw of PSD {', '.join(f'{x:.1e}' for x in q_data)} rad^2/s^3 against the model's
  2 sigma^2 / tau = {q_model[0]:.1e} (consumer model, Gauss-Markov {np.degrees(noise0.gyro_bias_sigma[0]):.2f} deg/s,
  {noise0.gyro_bias_tau[0]:.0f} s): the model's bias PSD is not too small.  The filters start from a zero
  bias (a sigma of {np.degrees(noise0.gyro_bias_sigma[0]):.1f} deg/s) whereas the bias is 0.1-0.2 deg/s; RMS per axis of
  each filter's gyro-bias estimate against the straight line between the two standstills [deg/s]:

| run | x | y | z |
|---|---|---|---|
{chr(10).join(gb_rows)}

{diagnosis_reading(diag, gerr)}

### What each filter expected: consistency of the outage drift

Each filter's own prediction of the drift is the horizontal 1-sigma of its position at the end of the
outage (`sigma_pos_n_m`; the error at the start is far smaller); a filter that knows the states that make
the free-inertial drift (attitude, velocity, IMU biases) as well as it claims has max drift / sigma of
about 1.  Last two columns: the mean difference between the two filters' level gyro-bias estimates
(body x, y) at the outage start, and the drift such a difference alone makes by the end of the outage
through the tilt it builds up, g |db| t^3 / 6.

| outage | code + Doppler mean max drift [m] | its mean sigma at the end [m] | mean drift / sigma | TDCP/INS mean max drift [m] | its mean sigma at the end [m] | mean drift / sigma | mean gyro-bias difference [deg/s] | g db t^3 / 6 [m] |
|---|---|---|---|---|---|---|---|---|
{chr(10).join(cons_rows)}

## Drift without absolute position: pseudorange outages (Doppler and phase kept)

Not the target above, an added view of what TDCP is for: the same windows with only the
pseudoranges removed, so neither filter has an absolute position inside them; the code + Doppler
filter dead-reckons on Doppler + IMU, TDCP/INS on Doppler + TDCP + IMU.

| outage [s] | window [s] | Doppler-only max drift [m] | Doppler + TDCP max drift [m] | TDCP / Doppler-only |
|---|---|---|---|---|
{chr(10).join(rows_b)}

| outage | windows | Doppler-only mean max drift [m] | Doppler + TDCP mean [m] | ratio | <= {TARGET} | TDCP smaller | Wilcoxon p | verdict |
|---|---|---|---|---|---|---|---|---|
{chr(10).join(verdicts_b)}

## The same complete outages on a simulated car (truth known)

The expectation behind the target, checked where the truth is exact: preset `{SIM_PRESET}`
(`insnav simulate`: a car, 600 s, MEMS IMU at 100 Hz, GPS L1 C/A code, Doppler and carrier phase of
its `rover.obs` at 1 Hz, read back through the same RINEX path and `phase_rows`), the code + Doppler
tight EKF against TDCP/INS with the same `[tdcp]` defaults; drift of the IMU centre against the
simulator's truth.  {sim_desc}.

| outage [s] | window [s of the run] | code + Doppler max drift [m] | TDCP/INS max drift [m] | TDCP / code |
|---|---|---|---|---|
{chr(10).join(sim_rows)}

| outage | windows | code + Doppler mean max drift [m] | TDCP/INS mean [m] | ratio | target <= {TARGET} | TDCP smaller | Wilcoxon p | verdict |
|---|---|---|---|---|---|---|---|---|
{chr(10).join(sim_verdicts)}

{discussion(per, per_b, ov, vr, ac1)}
* On the simulated car the complete-outage drift ratios are {', '.join(f'{r:.2f}' for r in sim_ratios.values())}
  (10, 30, 60 s): with a vehicle IMU whose errors the filter's model describes, the better velocity and
  IMU-error estimates TDCP gives do show in an outage; on the handheld walk they do not.
"""
    print(md)
    if a.out:
        a.out.write_text(with_stamp(md, a.out))
    return 0


def outage_ratios(ds, ref_t, ref_r_e, c_code, c_tdcp):
    """Complete-outage drift of the two filters over WINDOWS for one set-up: {duration: (code mean max drift,
    TDCP mean, ratio, code mean drift / sigma, TDCP mean drift / sigma)} [m], and the no-outage track error
    around the mean offset of each [m] (the diagnosis rows)."""
    inp0 = ds.tight_inputs
    t0, t1 = float(ds.t0), float(ds.imu.t[-1])

    def run(c, inputs):
        return run_with_inputs(ds, c, inputs)

    full = {}
    for name, c in (("code", c_code), ("tdcp", c_tdcp)):
        _, e = horizontal_error(run(c, inp0), ds, ref_t, ref_r_e)
        full[name] = float(np.sqrt(np.mean(np.sum((e - e.mean(axis=0)) ** 2, axis=1))))
    out = {}
    for dur, starts in WINDOWS.items():
        d = {"code": [], "tdcp": []}
        z = {"code": [], "tdcp": []}
        for st in starts:
            lo, hi = t0 + st, t0 + st + dur
            if hi > t1:
                continue
            inp = with_outage(inp0, lo, hi)
            for name, c in (("code", c_code), ("tdcp", c_tdcp)):
                s = run(c, inp)
                t, e = horizontal_error(s, ds, ref_t, ref_r_e)
                d[name].append(drift_in(t, e, lo, hi))
                z[name].append(d[name][-1] / sigma_h_end(s, hi))
        mc, mt = float(np.mean(d["code"])), float(np.mean(d["tdcp"]))
        out[dur] = (mc, mt, mt / mc, float(np.mean(z["code"])), float(np.mean(z["tdcp"])))
    return out, full


def diagnosis_reading(diag, gerr) -> str:
    """Computed statements on the diagnosis rows (no figure the script did not compute)."""
    e = {k: np.degrees(np.hypot(v[0], v[1])) for k, v in gerr.items()}  # level axes, RMS magnitude [deg/s]
    wide = diag[-1]
    st = next(v for v in diag if v[0].startswith("gyro bias from the standstill (`"))
    durs = list(WINDOWS)
    return "\n".join([
        f"* The level gyro-bias error (x, y) of TDCP/INS is {e['TDCP/INS, zero start']:.3f} deg/s against "
        f"{e['code + Doppler, zero start']:.3f} for code + Doppler from a zero start, and "
        f"{e['TDCP/INS, static start']:.3f} against {e['code + Doppler, static start']:.3f} from the standstill "
        "bias: the TDCP rows do not make the bias that sets the complete-outage drift better known, they move it "
        "away from the standstills' line (errors the 15-state model has no states for, scale factor and "
        "misalignment under the walker's turns, go into the bias states) while shrinking its covariance.",
        "* A wider TDCP sigma makes TDCP/INS consistent (mean drift / sigma "
        + ", ".join(f"{wide[1][d][4]:.2f}" for d in durs) + " against "
        + ", ".join(f"{st[1][d][4]:.2f}" for d in durs) + " with the default) but moves it towards the code + "
        "Doppler filter (ratios " + ", ".join(f"{wide[1][d][2]:.2f}" for d in durs) + ") and costs the no-outage "
        f"track error ({wide[2]['tdcp']:.3f} m against {st[2]['tdcp']:.3f} m).",
    ])


def residuals_by_elevation(sol, inputs, sigma_phase_m):
    """Rows of the TDCP residuals (used rows) per elevation bin: count, RMS, RMS less the epoch's median (the
    receiver clock change, which the clock states absorb), the rows' own sigma (sqrt(2) sigma_phase / sin(el)),
    all [cm]; and the RMS of the epochs' medians [cm]."""
    r, f, ep = sol.tdcp_residual_m, sol.tdcp_flag, inputs.row_epoch
    el = np.asarray(inputs.elevation_deg, float)
    used = f == 0
    less = np.full(r.shape, np.nan)
    med = []
    for k in np.unique(ep[used]):
        m = (ep == k) & used
        if m.sum() >= 3:
            med.append(np.median(r[m]))
            less[m] = r[m] - med[-1]
    sig = np.sqrt(2.0) * sigma_phase_m / np.sin(np.radians(np.maximum(el, 5.0)))
    rows = []
    for lo, hi in ((10, 30), (30, 45), (45, 60), (60, 90)):
        m = used & (el >= lo) & (el < hi)
        if m.sum() < 10:
            continue
        rows.append(f"| {lo}-{hi} | {int(m.sum())} | {np.sqrt(np.mean(r[m] ** 2)) * 100:.2f} | "
                    f"{np.sqrt(np.nanmean(less[m] ** 2)) * 100:.2f} | {np.sqrt(np.mean(sig[m] ** 2)) * 100:.2f} |")
    return rows, float(np.sqrt(np.mean(np.square(med))) * 100)


def gyro_bias_standstills(ds_static, sols):
    """The gyro bias where the walker stands still, before the start and after the end of the run (the raw
    log's samples the standstill detector marks stationary; insnav.io.rinex_dataset.static_gyro_bias), body
    axes [rad/s]: (b_start, sigma_start, b_end, sigma_end, log length [s]), and for each named solution the
    RMS per axis of its gyro-bias estimate against the straight line between the two [rad/s]."""
    from insnav.data.dataset import ImuData
    from insnav.io.imu_csv import read_imu_csv
    from insnav.io.rinex_dataset import static_gyro_bias

    opt = ds_static.options
    samples = read_imu_csv(ds_static.info["imu"], opt.imu_format(), tag=opt.imu_tag, week=ds_static.info["week"])
    imu = samples.to_increments(ds_static.gps_time_offset_s)
    b0, s0, _ = static_gyro_bias(imu, float(ds_static.t0))
    # the end: the stationary samples of the log's last END_STILL_S (the reversed log's first)
    dt = np.diff(imu.t, prepend=imu.t[0] - imu.dt)
    rev = ImuData(imu.t[0] + np.cumsum(dt[::-1]), imu.dtheta_b[::-1].copy(), imu.dv_b[::-1].copy())  # each its dt
    b1, s1, _ = static_gyro_bias(rev, float(imu.t[0] + END_STILL_S))
    b0, b1 = np.asarray(b0), np.asarray(b1)
    t_a, t_b = float(imu.t[0]), float(imu.t[-1])
    errs = {}
    for name, sol in sols.items():
        f = np.clip((sol.t - t_a) / (t_b - t_a), 0.0, 1.0)[:, None]
        errs[name] = np.sqrt(np.mean((sol.gyro_bias_rps - ((1 - f) * b0 + f * b1)) ** 2, axis=0))
    return b0, np.asarray(s0), b1, np.asarray(s1), t_b - t_a, errs


SIM_PRESET = "rtk-open-sky-car"
#: simulated car: outage lengths [s] and window starts [s of dataset time]
SIM_WINDOWS = {10.0: tuple(range(60, 550, 60)), 30.0: tuple(range(60, 530, 60)), 60.0: tuple(range(60, 500, 90))}


def simulated_car(tmp_dir):
    """The same complete-outage experiment on the simulated car of ``SIM_PRESET`` (MEMS IMU, GPS L1
    code / Doppler / phase of its rover.obs at 1 Hz), against its truth (IMU centre).  Returns the
    table rows, the verdict rows, {duration: ratio} and a description line."""
    from insnav.config import RunConfig, Tdcp
    from insnav.filters.tight import run_tight
    from insnav.gnss import read_rinex_nav, read_rinex_obs
    from insnav.gnss.tdcp import phase_rows
    from insnav.gnss.tight_inputs import tight_inputs_from_rinex

    ds = insnav.simulate(SIM_PRESET)
    folder = Path(tmp_dir) / SIM_PRESET
    ds.save(folder)
    obs = read_rinex_obs(folder / "rover.obs", systems="G")
    nav = read_rinex_nav(folder / "nav.rnx", systems="G")
    s0 = ds.initial
    r0 = earth.geodetic_to_ecef(s0.lat_deg * DEG, s0.lon_deg * DEG, s0.h_m)
    inp = tight_inputs_from_rinex(obs, nav, ds.gps_time_offset_s, r0, systems="G")
    inp.phase = phase_rows(inp, obs, nav, ds.gps_time_offset_s)
    c_code = RunConfig(filter="ekf", coupling="tight")
    c_tdcp = dataclasses.replace(c_code, tdcp=Tdcp(enabled=True))
    tr = ds.truth
    r_true = earth.geodetic_to_ecef(tr.lat_deg * DEG, tr.lon_deg * DEG, tr.h_m)

    def err(sol):
        """(t, (n, 2)) horizontal error N, E of the IMU centre against the truth [m]."""
        r = earth.geodetic_to_ecef(np.interp(tr.t, sol.t, sol.lat_deg) * DEG, np.interp(tr.t, sol.t, sol.lon_deg) * DEG,
                                   np.interp(tr.t, sol.t, sol.h_m))
        e = earth.ecef_to_ned_vector(tr.lat_deg[0] * DEG, tr.lon_deg[0] * DEG, r - r_true)
        return tr.t, e[:, :2]

    rows, verdicts, ratios = [], [], {}
    for dur, starts in SIM_WINDOWS.items():
        dc, dt_ = [], []
        for st in starts:
            i2 = with_outage(inp, float(st), float(st) + dur)
            out = {}
            for name, c in (("code", c_code), ("tdcp", c_tdcp)):
                t, e = err(run_tight(ds, c, inputs=i2))
                out[name] = drift_in(t, e, float(st), float(st) + dur)
            dc.append(out["code"])
            dt_.append(out["tdcp"])
            rows.append(f"| {dur:.0f} | {st}-{st + dur:.0f} | {out['code']:.2f} | {out['tdcp']:.2f} | "
                        f"{out['tdcp'] / out['code']:.2f} |")
        dc, dt_ = np.array(dc), np.array(dt_)
        pr = paired(dt_, dc)
        ratio = float(dt_.mean() / dc.mean())
        ratios[dur] = ratio
        verdicts.append(f"| {dur:.0f} s | {dc.size} | {dc.mean():.2f} | {dt_.mean():.2f} | {ratio:.2f} | "
                        f"{'met' if ratio <= TARGET else 'not met'} | {pr.wins}/{pr.n} | {pr.p_wilcoxon:.2g} | "
                        f"{pr.verdict()} |")
    s_full = run_tight(ds, c_tdcp, inputs=inp)
    sm = s_full.summary
    desc = (f"{len(inp.prn)} satellite rows ({int(inp.n_sats().min())}-{int(inp.n_sats().max())} GPS satellites per "
            f"epoch, {inp.epoch_t.size} epochs); TDCP rows used {sm['tdcp_used']}, slips {sm['tdcp_slips_lli']} by "
            f"LLI and {sm['tdcp_slips_ins']} by the INS test, {sm['tdcp_rejected']} rejected")
    return rows, verdicts, ratios, desc


def residual_lag1(sol, inputs):
    """Lag-1 autocorrelation of each satellite's TDCP residuals (used rows, less the epoch's median: the clock),
    for satellites with more than 30 consecutive pairs.  White zero-difference phase noise gives -0.5 (consecutive
    differences share an epoch); a positive value says the residuals are mostly something slower (the INS
    prediction between epochs), which the filter's white R does not describe."""
    r, f, ep, prn = sol.tdcp_residual_m, sol.tdcp_flag, inputs.row_epoch, inputs.prn
    res = np.full(r.shape, np.nan)
    for e in np.unique(ep):
        m = (ep == e) & (f == 0)
        if m.sum() >= 3:
            res[m] = r[m] - np.median(r[m])
    out = []
    for p in np.unique(prn):
        x = res[prn == p]
        ok = np.isfinite(x[1:]) & np.isfinite(x[:-1])
        if ok.sum() > 30:
            out.append(float(np.corrcoef(x[1:][ok], x[:-1][ok])[0, 1]))
    return np.array(out)


def discussion(per, per_b, ov, vr, ac1) -> str:
    """Computed statements about the outcome (no figure here that the script did not compute)."""
    lines = ["## Reading the numbers", ""]
    for dur, (dc, dt_, pr, ratio, met, _) in per.items():
        lines.append(f"* {dur:.0f} s complete outages: TDCP/INS drifts {ratio:.2f}x the code + Doppler filter "
                     f"({'within' if met else 'above'} the {TARGET}x target); TDCP/INS smaller in {pr.wins} of "
                     f"{pr.n} windows.")
    for dur, (dc, dt_, pr, ratio, met, _) in per_b.items():
        lines.append(f"* {dur:.0f} s pseudorange outages: Doppler + TDCP drifts {ratio:.2f}x Doppler only "
                     f"(smaller in {pr.wins} of {pr.n} windows).")
    lines += [
        f"* Without outages the horizontal velocity error against the RTK velocity is {vr['tdcp']:.3f} m/s with "
        f"TDCP against {vr['code']:.3f} m/s without, and the track error around the mean offset "
        f"{ov['tdcp'][2]:.3f} m against {ov['code'][2]:.3f} m.",
        "* In a complete outage neither filter has any GNSS row: both coast on the consumer IMU from the state",
        "  and the IMU-error estimates they had at the outage start.  TDCP can only act through those (a better",
        "  velocity, attitude and bias estimate at the start); the drift of the free consumer IMU grows with the",
        "  outage length and dominates both (the window-to-window spread above is larger than the difference",
        "  between the filters).  The TDCP rows themselves are sound by the other measures here: their residuals,",
        "  the pseudorange-outage drift and the track error; and by `tests/test_tdcp.py` (exact data to 1e-6 m,",
        "  the numerical Jacobian, the injected slip).  The issue's target assumes that TDCP's better calibration",
        "  shows in a complete outage; with this handheld consumer IMU it does not.",
    ]
    zc = {d: float(np.mean(v[0] / v[5]["code"])) for d, v in per.items()}
    zt = {d: float(np.mean(v[1] / v[5]["tdcp"])) for d, v in per.items()}
    dbg = {d: float(np.mean(np.linalg.norm(v[5]["bg_tdcp"] - v[5]["bg_code"], axis=1))) for d, v in per.items()}
    over = [d for d in per if zt[d] > 1.2 * zc[d] and zt[d] > 1.0]
    lines += [
        "* Why TDCP/INS drifts more in some complete outages: it is over-confident there.  "
        "Its max drift is " + ", ".join(f"{zt[d]:.2f}" for d in per) + " times the 1-sigma it predicts at the end of "
        "the 10, 30, 60 s outages, against " + ", ".join(f"{zc[d]:.2f}" for d in per) + " for the code + Doppler filter"
        + (f" (TDCP/INS over-confident in the {', '.join(f'{d:.0f} s' for d in over)} outages)." if over else "."),
        "  TDCP's velocity-grade rows shrink its covariance of the tilt and of the gyro biases (its sigma at the "
        "outage end is " + ", ".join(f"{per[d][5]['tdcp'].mean() / per[d][5]['code'].mean():.2f}" for d in per)
        + "x the code + Doppler filter's), but the drift does not shrink with it.  The drift is set by the gyro-bias",
        "  estimate at the outage start: the two filters' level gyro-bias estimates there differ by "
        + ", ".join(f"{np.degrees(dbg[d]):.3f}" for d in per) + " deg/s on average, and a difference that size "
        "alone makes up to " + ", ".join(f"{G0 * dbg[d] * d ** 3 / 6:.1f}" for d in per) + " m by the end of the "
        "outage (g b t^3 / 6: an upper bound, the walker's turns average part of it), against a mean difference "
        "|TDCP - code| of the max drifts of " + ", ".join(f"{np.mean(np.abs(per[d][1] - per[d][0])):.1f}" for d in per)
        + " m per window.",
        "  Neither filter knows this handheld consumer IMU's gyro biases after a 2-minute walk well enough for a "
        "30 s outage, and TDCP tightens the covariance of that estimate beyond what the data support (likely through "
        "IMU errors the 15-state model has no states for: scale factor and misalignment under the walking motion, "
        "time tagging).",
        f"  The TDCP residuals point the same way: their lag-1 autocorrelation per satellite (less the epoch median) is "
        + ", ".join(f"{x:+.2f}" for x in ac1) + " where white phase noise, which the rows' R assumes, gives -0.50: "
        "what the residuals hold is mostly an error slower than the phase noise (likely the INS prediction over the "
        "epoch), which the filter takes as independent information every epoch.",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
