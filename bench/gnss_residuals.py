"""GNSS geometry figures: broadcast vs precise products, pseudorange/Doppler residuals.

Reproduce (from the repository root, with ../shared/data beside the repo)::

    python3 bench/gnss_residuals.py [--data ../shared/data] [--out docs/results/gnss_geometry.md]

Prints a Markdown report and, with ``--out``, writes it to that file.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from insnav.gnss import read_rinex_nav, read_rinex_obs, sat_clock, sat_position_velocity, select_ephemeris  # noqa: E402
from insnav.gnss.ephemeris import C_LIGHT  # noqa: E402
from insnav.gnss.gpstime import gps_seconds_from_week_tow  # noqa: E402
from insnav.gnss.measurements import observation_residuals, read_rtklib_pos  # noqa: E402
from insnav.gnss.sp3 import read_rinex_clk, read_sp3  # noqa: E402

COMMAND = "python3 bench/gnss_residuals.py --out docs/results/gnss_geometry.md"


def sp3_figures(d: Path):
    nav = read_rinex_nav(d / "brdc1180.21n")
    out = []
    for name in ("COD0MGXFIN_20211180000_01D_05M_ORB.SP3", "grg21553.sp3"):
        s = read_sp3(d / name)
        gps = [k for k, n in enumerate(s.sats) if n.startswith("G")]
        prn = np.array([int(s.sats[k][1:]) for k in gps])
        T = np.repeat(s.t_gps_s, prn.size)
        P = np.tile(prn, s.t_gps_s.size)
        ref = s.r_e[:, gps].reshape(-1, 3)
        clk = s.clock_s[:, gps].reshape(-1)
        idx = select_ephemeris(nav.eph, P, T)
        ok = (idx >= 0) & np.isfinite(ref[:, 0])
        err = np.linalg.norm(sat_position_velocity(nav.eph, idx[ok], T[ok]).r_e - ref[ok], axis=1)
        dc = C_LIGHT * (sat_clock(nav.eph, idx[ok], T[ok], relativistic=False).bias_s - clk[ok])
        dc = dc[np.isfinite(dc)]
        out.append((name, err.size, np.median(err), np.percentile(err, 95), err.max(), np.mean(dc), np.std(dc)))
    c = read_rinex_clk(d / "COD0MGXFIN_20211180000_01D_30S_CLK.CLK")
    prns = np.array([p for p in range(1, 33) if f"G{p:02d}" in c.sats])
    T = np.repeat(c.t_gps_s, prns.size)
    P = np.tile(prns, c.t_gps_s.size)
    ref = c.clock_s[:, [c.sats.index(f"G{p:02d}") for p in prns]].reshape(-1)
    idx = select_ephemeris(nav.eph, P, T)
    ok = (idx >= 0) & np.isfinite(ref)
    dc = C_LIGHT * (sat_clock(nav.eph, idx[ok], T[ok], relativistic=False).bias_s - ref[ok])
    return out, (dc.size, np.mean(dc), np.std(dc))


def walk_figures(d: Path):
    obs = read_rinex_obs(d / "rinex_derived" / "gnss_1730.obs")
    nav = read_rinex_nav(d / "rinex_derived" / "gnss_1730.nav")
    pos = read_rtklib_pos(d / "raw" / "gnss_1730_sf.pos")
    j = np.clip(np.searchsorted(pos.t_gps_s, obs.epoch_t_gps_s - 0.01), 0, pos.t_gps_s.size - 1)
    res = observation_residuals(obs, nav.eph, pos.r_e[j], pos.v_e[j])
    pr, rr = res.pseudorange_m, res.range_rate_mps
    return np.isfinite(pr).sum(), np.nanstd(pr), np.nanstd(rr), np.nanmedian(res.rx_clock_m) / C_LIGHT


def spirent_figures(d: Path):
    nav = read_rinex_nav(d / "RINEX_GN_Spirent.23N")
    tr = np.genfromtxt(d / "Rover-dynamic_PVA_Spirent.csv", delimiter=",", skip_header=1)
    t = gps_seconds_from_week_tow(tr[:, 1] * 1024 + tr[:, 2], tr[:, 3])
    rows = []
    for sub in ("iono-none_tropo-none", "iono-Klob_tropo-Saast"):
        obs = read_rinex_obs(d / sub / "Rover-dynamic_MO_Spirent.obs")
        j = np.searchsorted(t, obs.epoch_t_gps_s - 1e-3)
        r, v = tr[j, 4:7], tr[j, 7:10]
        for corr in (False, True):
            res = observation_residuals(obs, nav.eph, r, v, iono=corr, tropo=corr,
                                        ion_alpha=nav.ion_alpha, ion_beta=nav.ion_beta)
            hi = res.predicted.el > np.deg2rad(10)
            rows.append((sub, corr, np.isfinite(res.pseudorange_m).sum(), np.nanstd(res.pseudorange_m),
                         np.nanstd(res.pseudorange_m[hi]), np.nanstd(res.range_rate_mps)))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    L = ["# GNSS geometry: measured figures", "",
         f"Reproduce: `{COMMAND}` (needs `../shared/data`; about 2 s).", ""]
    orb, clk = sp3_figures(a.data / "ephemeris_sp3_2021-118")
    L += ["## Broadcast (brdc1180.21n, IS-GPS-200 LNAV) vs precise products, 2021-04-28 18:00-24:00", "",
          "| reference | N | 3-D orbit median [m] | p95 [m] | max [m] | clock mean [m] | clock std [m] |",
          "|---|---|---|---|---|---|---|"]
    for name, n, med, p95, mx, cm, cs in orb:
        L.append(f"| {name} | {n} | {med:.2f} | {p95:.2f} | {mx:.2f} | {cm:+.2f} | {cs:.2f} |")
    L += ["", f"Clock polynomial af0+af1 dt+af2 dt^2 (no relativistic term) minus CODE 30-s CLK: "
          f"N = {clk[0]}, mean {clk[1]:+.2f} m, std {clk[2]:.2f} m.", ""]
    n, s_pr, s_rr, clk_s = walk_figures(a.data / "rtklibexplorer_walk_0827")
    L += ["## rtklibexplorer walk_0827 (real, u-blox, GPS L1 C/A, 4 GPS satellites with ephemeris)", "",
          "Against the RTK reference position/velocity, per-epoch median (receiver clock / drift) removed, "
          "no iono/tropo model:", "",
          f"* pseudorange residual std: {s_pr:.2f} m (N = {n})",
          f"* Doppler (-lambda D1) vs RTK-velocity range rate, std: {s_rr:.3f} m/s",
          f"* receiver clock offset estimated: {clk_s * 1e3:.3f} ms", ""]
    L += ["## Spirent SimGEN (hardware simulator, exact truth), GPS L1 C/A", "",
          "| scenario | Klobuchar+Saastamoinen | N | PR std [m] | PR std el>10 deg [m] | range-rate std [m/s] |",
          "|---|---|---|---|---|---|"]
    for sub, corr, nn, s, shi, srr in spirent_figures(a.data / "instinct_spirent_rtk_dynamic_SIMULATED"):
        L.append(f"| {sub} | {'on' if corr else 'off'} | {nn} | {s:.4f} | {shi:.4f} | {srr:.4f} |")
    L += ["", "Residuals below 10 deg elevation dominate the corrected case: the simulator's tropospheric "
          "mapping differs from ours there (see `saastamoinen_delay`).", "",
          f"Run time: {time.perf_counter() - t0:.1f} s.", ""]
    text = "\n".join(L)
    print(text)
    if a.out:
        a.out.write_text(text)


if __name__ == "__main__":
    main()
