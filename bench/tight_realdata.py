"""Tight-coupling measurement model on real data (rtklibexplorer walk_0827).

Builds the tight filter's per-epoch satellite inputs exactly as
``insnav.tight.tight_inputs_from_rinex`` hands them to the C++ loop (GPS LNAV
broadcast orbits/clocks, transmit time + Sagnac, T_GD, receiver-clock-corrected
reception time, Klobuchar + Saastamoinen, 10 deg mask) and evaluates the
pseudorange and Doppler (pseudorange-rate) residuals against the RTK
reference trajectory (per-epoch median removed = receiver clock / drift).

Reproduce (from the repository root, with ../shared/data beside the repo)::

    PYTHONPATH=python python bench/tight_realdata.py --out docs/results/tight_realdata.md
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "python"))

from insnav.gnss import read_rinex_nav, read_rinex_obs  # noqa: E402
from insnav.gnss.measurements import read_rtklib_pos  # noqa: E402
from insnav.tight import tight_inputs_from_rinex  # noqa: E402

COMMAND = "PYTHONPATH=python python bench/tight_realdata.py --out docs/results/tight_realdata.md"


def residuals(inp, t0, ref):
    ep = inp.row_epoch
    t = inp.epoch_t[ep] + t0
    r = np.column_stack([np.interp(t, ref.t_gps_s, ref.r_e[:, i]) for i in range(3)])
    v = np.column_stack([np.interp(t, ref.t_gps_s, ref.v_e[:, i]) for i in range(3)])
    s = inp.sats
    d = s[:, 2:5] - r
    rng = np.linalg.norm(d, axis=1)
    u = d / rng[:, None]
    pr = s[:, 0] - (rng - s[:, 8])
    rr = s[:, 1] - (np.einsum("ij,ij->i", u, s[:, 5:8] - v) - s[:, 9])
    out = []
    for x in (pr, rr):
        y = x.copy()
        for e in np.unique(ep):
            m = ep == e
            y[m] = np.where(m.sum() >= 2, x[m] - np.nanmedian(x[m]), np.nan)
        out.append(y)
    return out


def stats(x):
    x = x[np.isfinite(x)]
    return f"{x.size} | {np.std(x):.2f} | {np.sqrt(np.mean(x ** 2)):.2f} | {np.max(np.abs(x)):.2f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared/data")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    d = a.data / "rtklibexplorer_walk_0827"
    obs = read_rinex_obs(d / "rinex_derived/gnss_1730.obs")
    nav = read_rinex_nav(d / "rinex_derived/gnss_1730.nav")
    ref = read_rtklib_pos(d / "raw/gnss_1730_sf.pos")
    t0 = float(obs.epoch_t_gps_s[0])
    r0 = ref.r_e[0]
    lines = []
    gps_prns = np.unique(obs.prn)
    eph_prns = np.unique(nav.eph.prn)
    for iono_tropo in (True, False):
        inp = tight_inputs_from_rinex(obs, nav, t0, r0, iono=iono_tropo, tropo=iono_tropo, elevation_mask_deg=10.0)
        pr, rr = residuals(inp, t0, ref)
        n = inp.n_sats()
        lines.append(f"| {'Klobuchar + Saastamoinen' if iono_tropo else 'no atmosphere model'} | "
                     f"{n.min()}-{n.max()} (median {int(np.median(n))}) | {stats(pr)} | {stats(rr)} |")
        if iono_tropo:
            per_prn = [f"| G{p:02d} | {np.mean(inp.elevation_deg[inp.prn == p]):.1f} | "
                       f"{np.nanmean(pr[inp.prn == p]):+.2f} | {np.nanstd(pr[inp.prn == p]):.2f} | "
                       f"{np.nanstd(rr[inp.prn == p]):.3f} |" for p in np.unique(inp.prn)]
    md = f"""# Tight coupling on real data: rtklibexplorer walk_0827

Reproduce: `{COMMAND}`

Data: `../shared/data/rtklibexplorer_walk_0827` (u-blox RINEX 3.04 obs/nav made with
convbin, RTK reference `gnss_1730_sf.pos`, 536 epochs at 4 Hz, about 134 s).

## What the GPS data allow

* GPS satellites observed: {len(gps_prns)} ({', '.join(f'G{p:02d}' for p in gps_prns)}).
* GPS LNAV ephemerides in the nav file: {len(eph_prns)} ({', '.join(f'G{p:02d}' for p in eph_prns)}),
  as the GNSS engineer noted; the rest of the nav file is Galileo and BeiDou, which the
  insnav readers skip (GPS LNAV only).
* So a GPS-only tight filter sees at most those satellites: that is enough for the
  tight filter (it works from 1 satellite up, see `docs/results/seed003.md`), but a
  4-satellite geometry over a 2-minute walk gives a weak absolute position.

## Residuals of the tight measurement model against the RTK reference

Per-satellite residual = measured - predicted at the RTK antenna position/velocity,
with exactly the satellite inputs the tight filter receives; the per-epoch median is
removed (receiver clock bias / drift).  Sigmas: std, RMS, max over all rows.

| model | satellites per epoch | PR rows | PR std [m] | PR RMS [m] | PR max [m] | rate rows | rate std [m/s] | rate RMS [m/s] | rate max [m/s] |
|---|---|---|---|---|---|---|---|---|---|
{chr(10).join(lines)}

Per satellite (with the atmosphere models):

| PRN | mean elevation [deg] | PR mean [m] | PR std [m] | rate std [m/s] |
|---|---|---|---|---|
{chr(10).join(per_prn)}

The expected figures for a plain model are about 4 m (pseudorange) and 0.5 m/s
(Doppler) (data README).  With 4 satellites the per-epoch median absorbs part of the
error, so these stds are slightly optimistic.  Spirent pseudorange residuals against
exact truth with and without the atmosphere corrections: `docs/results/gnss_geometry.md`
(bench/gnss_residuals.py, done by the GNSS engineer).

## Not done

* The tight-coupled IMU solution on this walk against the RTK reference (horizontal
  RMS and max) is **not produced**: the IMU CSV + RINEX loader
  (`python/insnav/io/rinex_dataset.py`) was not written in the time box.  What it needs:
  IMU time from the tick column (`t_gps = tag start + (tick - tick_first)/1000`, first and
  last CSV lines are partial), g and deg/s to SI increments, the mounting
  rpy = [180, 0, -90] deg and lever arm from the author's walk_config.py, an initial
  heading (a consumer gyro cannot gyrocompass; use the Doppler velocity course once
  walking), then `run_tight(ds, cfg, inputs=tight_inputs_from_rinex(...))`.
* Galileo (7 ephemerides in the nav file) would give a usable geometry; it needs a
  Galileo nav/obs reader (same Keplerian algorithm, GST, BGD) that insnav does not have.
"""
    print(md)
    if a.out:
        a.out.write_text(md)


if __name__ == "__main__":
    main()
