"""The ``spp`` filter: GNSS-only single point positioning as an insnav run.

:func:`run_spp` is the registry runner: ``insnav.run(inputs, "spp", "gnss",
spp_options=..., weighting=...)`` (``insnav run --filter spp --format rinex
--obs --nav`` calls it so), no IMU used.  ``inputs`` is either

* a :class:`SppDataset`: RINEX observation and navigation files (or read
  data) with the ``[rinex]`` reading options (atmosphere, elevation mask,
  zenith sigmas); the ``[gnss]`` table is the ``weighting`` option
  (:class:`insnav.gnss.weighting.Weighting`), the ``[spp]`` table the
  ``spp_options`` option (:class:`insnav.gnss.spp.SppOptions`); or
* any dataset with satellite rows: ``RinexDataset.tight_inputs``, or the
  simulator's raw observations (every satellite).

:func:`load_spp_run` reads the three tables of a run TOML into those
inputs; :func:`run_spp_rinex` is the older entry (deprecated, a thin wrapper).

The result is a :class:`~insnav.filters.solution.Solution` (assembled by
:func:`insnav.filters._assemble.gnss_solution`) with one row per
solved epoch: antenna position, NED velocity and their 1-sigma in the usual
columns, attitude and IMU errors NaN; ``gnss_t``/``nis``/``gnss_status`` per
epoch hold the RAIM test statistic (``v^T W v``) and whether a position came
out (:attr:`RecordStatus.APPLIED`).  The receiver clock, inter-system biases,
drift, DOPs and RAIM counts, which have no solution column, are in
``solution.spp`` (:class:`insnav.gnss.spp.SppSolution`) and, from the CLI, in
``<out>.spp.csv`` (:data:`SPP_COLUMNS`).
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import numpy as np

from .. import earth
from .._median import median
from ..config import ConfigError, read_toml
from ..gnss.spp import (SppOptions, SppSolution, _spp_inputs_from_rinex, read_nav_multi, read_obs_multi, solve_spp,
                        summary_counts)
from ..gnss.code_check import check_inputs_code_fit
from ..gnss.systems import SPP_SYSTEMS, SYSTEMS
from ..gnss.weighting import Weighting
from ._gnss_only_toml import check_gnss_only_toml_keys
from ._assemble import gnss_solution
from .solution import RecordStatus, Solution

__all__ = ["run_spp", "run_spp_rinex", "spp_solution", "SPP_COLUMNS", "write_spp_table", "SppDataset",
           "load_spp_run"]

#: columns of ``<out>.spp.csv``: per epoch (solved or not)
SPP_COLUMNS = ("t_s", "solved", "n_sats", "n_used", "n_excluded", "raim_status", "chi2", "chi2_threshold",
               "clock_bias_m", "sigma_clock_m", "clock_drift_mps", "sigma_drift_mps",
               *(f"isb_{s}_m" for s in SYSTEMS), *(f"sigma_isb_{s}_m" for s in SYSTEMS),
               "gdop", "pdop", "hdop", "vdop", "tdop", "n_rate_used", "n_rate_excluded", "ref_system")


def spp_solution(sp: SppSolution, filter_name: str = "spp") -> Solution:
    """The solved epochs of an :class:`SppSolution` as a :class:`Solution` (position of the antenna)."""
    ok = sp.solved
    n = int(ok.sum())
    st = np.where(ok, int(RecordStatus.APPLIED), int(RecordStatus.NOT_USED)).astype(np.int8)
    summary = dict(filter=filter_name, coupling="gnss", updates=n, rejected=0, gnss_records=len(sp),
                   cholesky_repairs=0, **summary_counts(sp))
    sol = gnss_solution(sp.t[ok].copy(), sp.r_e[ok], np.asarray(sp.v_n()[ok]), sp.sigma_pos_n_m[ok].copy(),
                        sp.sigma_vel_n_mps[ok].copy(), gnss_t=sp.t.copy(), nis=sp.chi2.copy(), gnss_status=st,
                        summary=summary)
    sol.spp = sp
    # the innovations file's rows: the degrees of freedom of each epoch's post-fit chi-square (its nis, the RAIM
    # statistic): pseudoranges used - 3 position - 1 clock - the inter-system biases estimated (sigma > 0)
    n_isb = np.sum(np.nan_to_num(np.asarray(sp.sigma_isb_m, float)) > 0, axis=1)
    sol.rows = np.maximum(np.asarray(sp.n_used, int) - 4 - n_isb, 0)
    return sol


@dataclass
class SppDataset:
    """The inputs of an SPP run over RINEX (``insnav.run(SppDataset(...), "spp")``; no IMU).

    Attributes
    ----------
    obs : path or insnav.gnss.ObsData
        Observations; a path is read with the ``weighting.systems``.
    nav : path, list of paths (merged) or insnav.gnss.NavData
    rinex : insnav.io.rinex_dataset.RinexOptions, optional
        The ``[rinex]`` reading options (elevation mask, atmosphere, zenith sigmas, C/N0); None: the defaults.
    approx_r_e : (3,) array, optional
        Starting position, ECEF [m]; default the header's, else a GPS bootstrap.
    """

    obs: object
    nav: object
    rinex: object = None
    approx_r_e: object = None
    gnss_only = True  # no IMU: insnav.run skips the IMU sanitizer and checks


def _as_options(value, cls, source: str):
    """``value`` as a ``cls`` (an instance, a dict of its TOML keys, or None: the defaults)."""
    return value if isinstance(value, cls) else cls.from_dict(value if value is not None else {}, source)


def run_spp(dataset, cfg, *, spp_options: SppOptions | dict | None = None, weighting: Weighting | dict | None = None):
    """Registry runner: single point positioning over the dataset's GNSS rows (the IMU is not used).

    A :class:`SppDataset` (RINEX files): the rows are computed from its
    observations and navigation data with its ``[rinex]`` options and
    ``weighting`` (default :class:`Weighting`'s), twice: the second pass takes
    light time, elevations and atmosphere from the median of the first pass's
    positions.  Time: GPS seconds of week of the first epoch's week;
    ``solution.spp`` the full :class:`SppSolution`; ``solution.rinex_options``,
    ``weighting``, ``spp_options`` the options used.

    Other datasets: rows from ``dataset.tight_inputs`` (RINEX datasets; sigmas as loaded, or
    reweighted with ``weighting`` when the dataset kept the C/N0 -- it does
    not, so only the elevation and system enter), else every satellite of
    ``dataset.gnss_raw`` (simulator) with its own sigmas.
    """
    from ..gnss.tight_inputs import tight_inputs_from_raw

    if isinstance(dataset, SppDataset):
        return _run_spp_rinex(dataset, _as_options(spp_options, SppOptions, "spp options"),
                              _as_options(weighting, Weighting, "gnss weighting"))
    opt = _as_options(spp_options, SppOptions, "spp options")
    if spp_options is None and getattr(dataset, "spp_options", None) is not None:
        opt = dataset.spp_options
    inp = getattr(dataset, "tight_inputs", None)
    if inp is None:
        if getattr(dataset, "gnss_raw", None) is None:
            raise ValueError("filter 'spp' needs raw GNSS observations (a RINEX dataset or a simulated gnss_raw)")
        inp = tight_inputs_from_raw(dataset.gnss_raw, max_sats=0)
    r0 = inp.info.get("approx_r_e")
    if r0 is None:
        ini = dataset.initial
        r0 = earth.geodetic_to_ecef(np.radians(ini.lat_deg), np.radians(ini.lon_deg), ini.h_m)
    spr = sprr = None
    if weighting is not None:
        w = weighting if isinstance(weighting, Weighting) else Weighting.from_dict(weighting, "gnss weighting")
        spr, sprr = w.sigmas(np.radians(inp.elevation_deg), None, inp.system)
    sp = solve_spp(inp, np.asarray(r0, float), options=opt, sigma_pr_m=spr, sigma_prr_mps=sprr)
    return spp_solution(sp)


def load_spp_config(config_path=None):
    """(RinexOptions, Weighting, SppOptions) from a run TOML (its other tables and keys are not used by spp).

    Raises ConfigError (one line, naming the file and key) for a bad or unknown key.
    """
    from ..io.rinex_dataset import RinexOptions

    d = {}
    source = "run configuration"
    if config_path is not None:
        source = os.fspath(config_path)
        d = read_toml(config_path)
        check_gnss_only_toml_keys(d, source, "spp", {key: {f.name for f in dataclasses.fields(cls)} for key, cls in
                                                     (("rinex", RinexOptions), ("gnss", Weighting), ("spp", SppOptions))})
    tables = {}
    for key in ("rinex", "gnss", "spp"):
        v = d.get(key, {})
        if not isinstance(v, dict):
            raise ConfigError(f"{source}: key '{key}': bad value {v!r}; allowed: a table")
        tables[key] = v
    ropt, wgt = RinexOptions.from_dict(tables["rinex"], source), Weighting.from_dict(tables["gnss"], source)
    if "systems" in tables["rinex"]:  # an INS run's [rinex] systems: the same satellites here
        if "systems" not in tables["gnss"]:
            wgt.systems = list(ropt.systems)
        elif ropt.systems != "G" and set(wgt.systems) - set(ropt.systems):  # "G": a resolved config's default
            raise ConfigError(f"{source}: [gnss] systems = {wgt.systems} and [rinex] systems = \"{ropt.systems}\" "
                              "differ: give one of them (spp reads the systems of [gnss] systems)")
    return ropt, wgt, SppOptions.from_dict(tables["spp"], source)


def load_spp_run(obs, nav, config_path=None, *, rinex: dict | None = None, gnss: dict | None = None,
                 spp: dict | None = None, approx_r_e=None):
    """The inputs of an SPP run from RINEX files and a run TOML.

    Parameters
    ----------
    obs, nav : see :class:`SppDataset`
    config_path : path, optional
        Run TOML (its ``[rinex]``, ``[gnss]``, ``[spp]`` tables; nothing else is used).
    rinex, gnss, spp : dict, optional
        Table entries overriding the file's.
    approx_r_e : (3,), optional
        Starting position [m].

    Returns
    -------
    (SppDataset, dict)
        The dataset and the family's options (``spp_options``, ``weighting``) for :func:`insnav.run`.
    """
    from ..io.rinex_dataset import RinexOptions

    ropt, wgt, sopt = load_spp_config(config_path)
    src = os.fspath(config_path) if config_path is not None else "spp options"
    if rinex:
        ropt = RinexOptions.from_dict({**_fields(ropt), **rinex}, src)
    if gnss:
        wgt = Weighting.from_dict({**_fields(wgt), **gnss}, src)
    if spp:
        sopt = SppOptions.from_dict({**_fields(sopt), **spp}, src)
    return SppDataset(obs, nav, ropt, approx_r_e), dict(spp_options=sopt, weighting=wgt)


def run_spp_rinex(obs, nav, config_path=None, *, rinex: dict | None = None, gnss: dict | None = None,
                  spp: dict | None = None, approx_r_e=None):
    """Single point positioning over RINEX files (parameters as :func:`load_spp_run`).

    .. deprecated::
        Use ``insnav.run(*load_spp_run(...))``-style:
        ``ds, opts = load_spp_run(obs, nav, config_path); insnav.run(ds, "spp", **opts)``;
        this wrapper does exactly that.

    Returns
    -------
    Solution
        Time: GPS seconds of week of the first epoch's week; ``solution.spp``
        the full :class:`SppSolution`, ``solution.summary`` the counts and options.
    """
    from . import run

    ds, opts = load_spp_run(obs, nav, config_path, rinex=rinex, gnss=gnss, spp=spp, approx_r_e=approx_r_e)
    return run(ds, "spp", "gnss", **opts)


def _run_spp_rinex(ds: SppDataset, sopt: SppOptions, wgt: Weighting) -> Solution:
    """:func:`run_spp` over a :class:`SppDataset`."""
    from ..gnss.gpstime import SECONDS_PER_WEEK
    from ..io.rinex_dataset import RinexOptions, _approx_position

    ropt = ds.rinex if ds.rinex is not None else RinexOptions()
    obs, nav, approx_r_e = ds.obs, ds.nav, ds.approx_r_e
    if not hasattr(obs, "C1"):
        obs = read_obs_multi(obs, wgt.systems)
    if not hasattr(nav, "eph"):
        nav = read_nav_multi(nav, wgt.systems)
    if obs.epoch_t_gps_s.size == 0:
        raise ValueError(f"{obs.path}: no observation epochs")
    t_week0 = SECONDS_PER_WEEK * int(obs.epoch_week[0])
    r0 = np.asarray(approx_r_e, float) if approx_r_e is not None else _approx_position(obs, nav, t_week0)
    kw = dict(weighting=wgt, elevation_mask_deg=ropt.elevation_mask_deg, iono=ropt.iono, tropo=ropt.tropo,
              sigma_pr_zenith_m=ropt.sigma_pr_zenith_m, sigma_prr_zenith_mps=ropt.sigma_prr_zenith_mps,
              use_cn0=ropt.use_cn0)
    inp, _, states = _spp_inputs_from_rinex(obs, nav, t_week0, r0, **kw)
    sp = solve_spp(inp, r0, options=sopt)
    good = sp.solved
    if good.any():  # light time, elevation and atmosphere again from the data's own position
        r0 = np.array([median(sp.r_e[good, k]) for k in range(3)])  # np.median(axis=0), without numpy.ma
        # (the first pass's satellite states carried to the new light times and clock estimates)
        inp, _, _ = _spp_inputs_from_rinex(obs, nav, t_week0, r0, prior=states, **kw)
        sp = solve_spp(inp, r0, options=sopt)
    check_inputs_code_fit(inp, r0, obs.path)
    sp.info.update(inputs=inp, t_week0_gps_s=float(t_week0), approx_r_e=r0.tolist())
    sol = spp_solution(sp)
    sol.summary.update(systems="".join(s for s in SPP_SYSTEMS if np.any(inp.system == s)), weighting=wgt.model)
    sol.rinex_options, sol.weighting, sol.spp_options = ropt, wgt, sopt
    return sol


def _fields(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


def write_spp_table(sp: SppSolution, path) -> "os.PathLike":
    """Write ``path`` (``<out>.spp.csv``): :data:`SPP_COLUMNS`, one line per epoch."""
    from .._atomic import atomic_write_text

    cols = [sp.t, sp.solved.astype(int), sp.n_sats, sp.n_used, sp.n_excluded, sp.raim_status, sp.chi2,
            sp.chi2_threshold, sp.clock_bias_m, sp.sigma_clock_m, sp.clock_drift_mps, sp.sigma_drift_mps,
            *sp.isb_m.T, *sp.sigma_isb_m.T, sp.gdop, sp.pdop, sp.hdop, sp.vdop, sp.tdop, sp.n_rate_used,
            sp.n_rate_excluded]
    k = sp.isb_m.shape[1]  # clock and ISBs to 0.1 mm / 1 um/s (%.6g rounded a 462559 m clock to the metre)
    fmt = (["%.6f"] + ["%d"] * 5 + ["%.6g"] * 2 + ["%.4f", "%.6g", "%.6f", "%.6g"] + ["%.4f"] * k
           + ["%.6g"] * (len(cols) - 14 - k) + ["%d", "%d"])
    text_cols = []
    for f, c in zip(fmt, cols):  # column by column: one isfinite per column, not per value
        c = np.asarray(c)
        fin = np.isfinite(c).tolist()
        text_cols.append([(f % v) if ok else "nan" for v, ok in zip(c.tolist(), fin)])
    text_cols.append([str(r) for r in sp.ref_system.tolist()])
    lines = [",".join(SPP_COLUMNS)] + [",".join(row) for row in zip(*text_cols)]
    return atomic_write_text(path, "\n".join(lines) + "\n")
