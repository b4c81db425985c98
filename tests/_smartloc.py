"""GNSS-only single point positioning on smartLoc "Berlin Potsdamer Platz"
(deep urban car drive) against its ground truth: the evaluation that
tests/test_spp.py asserts bounds on and bench/spp_smartloc.py tabulates into
docs/results/spp_smartloc.md.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from insnav import earth

#: test bounds (tests/test_spp.py): about 1.5x the values measured at the commit of the results document
BOUNDS = {"G": dict(p50_m=25.0, p95_m=75.0), "GR": dict(p50_m=22.0, p95_m=65.0)}
MODELS = ("legacy", "rtklib", "cn0")


def ground_truth(d: Path):
    """(t [s after the first RINEX epoch], (K, 3) ECEF [m])."""
    a = np.loadtxt(d / "Berlin_Potsdamer_Platz_GT.txt", usecols=(1, 2, 3, 4))
    return a[:, 0], a[:, 1:4]


NAV_FILES = {"G": ("brdc1580.16n",), "GR": ("brdc1580.16n", "brdc1580.16g")}


def nav_for(d: Path, systems: str):
    """Navigation data of the systems (GPS: brdc1580.16n; GPS+GLONASS: with brdc1580.16g), or None when
    the reader of this commit does not read GLONASS."""
    from insnav.gnss.spp import read_nav_multi

    from insnav.gnss import RinexError

    try:
        nav = read_nav_multi([d / f for f in NAV_FILES[systems]], systems)
    except RinexError:
        if systems == "G":
            raise
        return None  # a GPS-only reader refuses the GLONASS file
    if "R" in systems and not len(getattr(nav, "eph_r", ())):
        return None
    return nav


def read_obs(d: Path, systems: str):
    from insnav.gnss.spp import read_obs_multi

    return read_obs_multi(d / "Berlin_Potsdamer_Platz.obs", systems)


def evaluate(d: Path, systems: str = "G", model: str = "legacy", raim: bool = True, obs=None, nav=None) -> dict:
    """Horizontal error percentiles of one SPP run (and its counts)."""
    from insnav.filters.spp import run_spp_rinex
    from insnav.gnss.ephemeris import C_LIGHT

    d = Path(d)
    obs = obs if obs is not None else read_obs(d, systems)
    nav = nav if nav is not None else nav_for(d, systems)
    if nav is None:
        raise RuntimeError(f"no navigation data for systems {systems!r}")
    sol = run_spp_rinex(obs, nav, gnss=dict(model=model, systems=list(systems)), spp=dict(raim=raim))
    sp = sol.spp
    inp = sp.info["inputs"]
    # receiver time tag of each epoch (dataset time is the tag minus the receiver clock estimate)
    t0 = float(obs.epoch_t_gps_s[0]) - sp.info["t_week0_gps_s"]
    clk = np.asarray(inp.info["rx_clock_tag_m"])
    tags = obs.epoch_t_gps_s - sp.info["t_week0_gps_s"]
    k = np.clip(np.searchsorted(tags - clk / C_LIGHT, sp.t - 1e-4), 0, tags.size - 1)
    t_tag = tags[k] - t0
    t_gt, r_gt = ground_truth(d)
    j = np.clip(np.searchsorted(t_gt, t_tag - 0.01), 0, t_gt.size - 1)
    m = sp.solved & (np.abs(t_gt[j] - t_tag) < 0.02)
    dr = sp.r_e[m] - r_gt[j[m]]
    lat, lon, _ = earth.ecef_to_geodetic(r_gt[j[m]])
    d_n = np.einsum("kji,kj->ki", earth.C_en(lat, lon), dr)
    hor = np.hypot(d_n[:, 0], d_n[:, 1])
    s = sol.summary
    return dict(systems=systems, model=model, raim=raim, epochs=int(obs.epoch_t_gps_s.size),
                epochs_solved=int(s["solved"]), epochs_compared=int(m.sum()),
                p50_m=float(np.percentile(hor, 50)), p95_m=float(np.percentile(hor, 95)),
                rms_m=float(np.sqrt(np.mean(hor ** 2))), up_p50_m=float(np.percentile(np.abs(d_n[:, 2]), 50)),
                sats_used_mean=float(np.mean(sp.n_used[sp.solved])), rows_excluded=int(s["rows_excluded"]),
                raim_excluded_epochs=int(s["raim_excluded_epochs"]), raim_failed=int(s["raim_failed"]),
                raim_untested=int(s["raim_untested"]),
                h_err_over_sigma_rms=float(np.sqrt(np.mean((d_n[:, :2] / sp.sigma_pos_n_m[m, :2]) ** 2))))
