"""The ``rtk`` filter: carrier-phase relative positioning of a rover against a base (no IMU).

* :func:`run_rtk`, the registry runner: ``insnav.run(RtkDataset(rover, base, nav), "rtk",
  rtk_options=...)``; ``insnav run --filter rtk --format rinex --obs ROVER --base BASE --nav NAV``
  calls it so, with the inputs of :func:`load_rtk_run`: a run TOML's ``[rtk]`` table
  (:class:`insnav.gnss.rtk.RtkOptions`, plus ``base_position_ecef_m`` / ``base_position_llh``
  for the base antenna reference point).
* :func:`run_rtk_rinex`: the older entry (deprecated; a thin wrapper of the above).

The result is a :class:`~insnav.filters.solution.Solution` (assembled by
:func:`insnav.filters._assemble.gnss_solution`) with one row per
rover epoch that has a solution (antenna position, ECEF velocity rotated to
NED, 1-sigma from the fixed or float covariance); ``gnss_status`` holds the
fix status per epoch (RTKLIB's Q: 1 fixed, 2 float, 4 DGPS, 0 none) and
``solution.rtk`` the full :class:`insnav.gnss.rtk.RtkSolution` (ratio,
number of fixed ambiguities, slips per epoch).
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import numpy as np

from .. import earth
from ..config import ConfigError, read_toml
from ..gnss.rtk import RtkOptions, RtkSolution, solve_rtk
from ._base_position import _BASE_KEYS, parse_base_position, pop_base_position
from ._gnss_only_toml import check_gnss_only_toml_keys
from ._assemble import gnss_solution
from .solution import Solution

__all__ = ["RtkDataset", "run_rtk", "run_rtk_rinex", "rtk_solution", "load_rtk_config", "load_rtk_run",
           "parse_base_position", "pop_base_position"]

@dataclass
class RtkDataset:
    """Inputs of an RTK run: rover and base observation files (or PhaseObs), navigation file(s),
    and optionally the base antenna reference point, ECEF [m]."""

    rover: object
    base: object
    nav: object
    base_position_e_m: object = None
    #: where ``base_position_e_m`` came from, for the messages (``--base-pos``, the TOML's key)
    base_position_source: str | None = None
    gnss_only = True  # no IMU: insnav.run skips the IMU sanitizer and checks


def load_rtk_config(config_path=None, overrides: dict | None = None):
    """(RtkOptions, base position ECEF or None) from a run TOML's ``[rtk]`` table."""
    d = {}
    source = "rtk options"
    if config_path is not None:
        source = os.fspath(config_path)
        d = read_toml(config_path)
        check_gnss_only_toml_keys(d, source, "rtk", {"rtk": {f.name for f in dataclasses.fields(RtkOptions)}
                                                         | set(_BASE_KEYS)})
    t = d.get("rtk", {})
    if not isinstance(t, dict):
        raise ConfigError(f"{source}: key 'rtk': bad value {t!r}; allowed: a table")
    t = {**t, **(overrides or {})}
    base, _ = pop_base_position(t, source)
    return RtkOptions.from_dict(t, source), base


def rtk_solution(rs: RtkSolution, filter_name: str = "rtk") -> Solution:
    """The epochs of an :class:`RtkSolution` that have a position, as a :class:`Solution`."""
    from ..gnss.gpstime import SECONDS_PER_WEEK

    ok = rs.status > 0
    n = int(ok.sum())
    t0 = SECONDS_PER_WEEK * np.floor(rs.t_gps_s[0] / SECONDS_PER_WEEK) if len(rs) else 0.0
    lat, lon, _ = earth.ecef_to_geodetic(rs.r_e[ok]) if n else (np.zeros(0),) * 3
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    C_ne = np.stack([np.stack([-sl * co, -sl * so, cl], -1), np.stack([-so, co, np.zeros_like(sl)], -1),
                     np.stack([-cl * co, -cl * so, -sl], -1)], 1)  # (n, 3, 3): NED <- ECEF
    v_n = np.einsum("nij,nj->ni", C_ne, rs.v_e[ok])
    P_n = np.einsum("nij,njk,nlk->nil", C_ne, rs.P_r[ok], C_ne)
    sig = np.sqrt(np.maximum(np.diagonal(P_n, axis1=1, axis2=2), 0.0))
    summary = dict(filter=filter_name, coupling="gnss", updates=n, rejected=0, gnss_records=len(rs),
                   cholesky_repairs=0, **rs.counts())
    sol = gnss_solution(rs.t_gps_s[ok] - t0, rs.r_e[ok], v_n, sig, np.full((n, 3), np.nan), gnss_t=rs.t_gps_s - t0,
                        nis=rs.ratio.copy(), gnss_status=rs.status.astype(np.int8), summary=summary)
    sol.rtk = rs
    sol.fix_status = rs.status[ok].copy()
    sol.ratio = rs.ratio[ok].copy()
    sol.n_fix = rs.n_fix[ok].copy()
    return sol


def load_rtk_run(obs, base, nav, config_path=None, *, base_pos=None, rtk: dict | None = None):
    """The inputs of an RTK run from RINEX files and a run TOML.

    Parameters
    ----------
    obs, base : path
        Rover and base RINEX observation files.
    nav : path or list of paths
    config_path : path, optional
        Run TOML with an ``[rtk]`` table (nothing else is used).
    base_pos : str or (3,), optional
        Base antenna reference point (ECEF [m] or lat_deg, lon_deg, h_m); overrides the TOML's
        and the header's.
    rtk : dict, optional
        ``[rtk]`` entries overriding the file's.

    Returns
    -------
    (RtkDataset, dict)
        The dataset and the family's options (``rtk_options``) for :func:`insnav.run`.
    """
    opt, base_e = load_rtk_config(config_path, rtk)
    source = None
    if base_pos is not None:
        base_e = base_pos if isinstance(base_pos, np.ndarray) else parse_base_position(base_pos)
        source = "--base-pos"
    elif base_e is not None:
        table = {**(read_toml(config_path).get("rtk", {}) if config_path is not None else {}), **(rtk or {})}
        key = next((k for k in reversed(_BASE_KEYS) if k in table), _BASE_KEYS[0])  # the one load_rtk_config kept
        source = f"{config_path}: key 'rtk.{key}'" if config_path is not None else f"key 'rtk.{key}'"
    return RtkDataset(obs, base, nav, base_e, source), dict(rtk_options=opt)


def run_rtk_rinex(obs, base, nav, config_path=None, *, base_pos=None, rtk: dict | None = None) -> Solution:
    """RTK over RINEX files (parameters as :func:`load_rtk_run`).

    .. deprecated::
        Use ``ds, opts = load_rtk_run(...); insnav.run(ds, "rtk", **opts)``; this wrapper does exactly that.
    """
    from . import run

    ds, opts = load_rtk_run(obs, base, nav, config_path, base_pos=base_pos, rtk=rtk)
    return run(ds, "rtk", "gnss", **opts)


def run_rtk(dataset, cfg, *, rtk_options: RtkOptions | dict | None = None):
    """Registry runner: ``insnav.run(RtkDataset(rover, base, nav), filter="rtk")`` (no IMU)."""
    for k in ("rover", "base", "nav"):
        if getattr(dataset, k, None) is None:
            raise ValueError(f"filter 'rtk' needs a dataset with rover, base and nav (insnav.filters.rtk.RtkDataset); "
                             f"missing {k!r}")
    opt = rtk_options if isinstance(rtk_options, RtkOptions) else RtkOptions.from_dict(rtk_options or {}, "rtk options")
    rs = solve_rtk(dataset.rover, dataset.base, dataset.nav, r_base_e=getattr(dataset, "base_position_e_m", None),
                   options=opt, base_source=getattr(dataset, "base_position_source", None))
    sol = rtk_solution(rs)
    sol.rtk_options = opt
    return sol
