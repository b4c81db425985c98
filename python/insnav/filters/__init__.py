"""Running a filter: :func:`run` looks the filter up in the registry
(:mod:`insnav.registry`), checks and repairs the input once
(:mod:`~insnav.filters.sanitize`, :mod:`~insnav.filters.checks`) and calls the
runner of its family.  The runners are the only code that calls
``_core.run_*``:

=====================  ====================================  =========
module                 filters                               paper
=====================  ====================================  =========
:mod:`.loose`          ekf, rbukf, ukf (loose)               seed 000
:mod:`.tight`          ekf, rbukf, ukf (tight, 17 states)    seed 003
:mod:`.delay`          kf, rdkf, exact                       seed 001
:mod:`.particle`       fukf, upf, pf (tight, 20 states)      seed 004
:mod:`.spp`            spp (GNSS only, no IMU)               RTKLIB pntpos, RAIM FDE
:mod:`.rtk`            rtk (GNSS only, base + rover)         MLAMBDA (Chang et al. 2005)
=====================  ====================================  =========
"""
from __future__ import annotations

import dataclasses

from ..config import ConfigError, RunConfig, check_option_values
from ..registry import FILTERS, filter_spec
from .solution import GNSS_STATUS, RecordStatus, Solution

__all__ = ["run", "Solution", "RecordStatus", "GNSS_STATUS"]

_ADVERB = {"loose": "loosely", "tight": "tightly", "gnss": "GNSS-only (no IMU),",
           "rtk": "RTK/INS (carrier phase against a base),"}


def _as_config(config, filter: str | None = None, coupling: str | None = None) -> RunConfig:
    """A copy of ``config`` (a RunConfig, a dict of TOML keys, or a TOML file path) for a caller that runs
    no RTK (the navigators, the streamed run, the tuner): ``[rtk]`` / ``[rtk_engine]`` tables are refused
    with one line, as :func:`run` refuses them outside an RTK run."""
    cfg, extra = _config_and_tables(config, filter, coupling)
    for t in ("rtk", "rtk_engine"):
        if t in extra:
            raise ConfigError(f"{extra['source']}: [{t}] is read by RTK runs only (insnav.run with filter 'rtk' "
                              "or coupling 'rtk'): remove the table")
    return cfg


def _config_and_tables(config, filter: str | None = None, coupling: str | None = None) -> tuple[RunConfig, dict]:
    """A copy of ``config``: a RunConfig, a dict of TOML keys, or a TOML file path; a dict or file is
    checked against ``filter`` / ``coupling`` when given (they replace its own, as run() does).  With
    it, what a dict or file holds beyond the RunConfig: its ``[rtk]`` / ``[rtk_engine]`` tables
    (``"rtk"``, ``"rtk_engine"``), the ``[tdcp]`` settings given without ``enabled = true``
    (``"tdcp_settings"``) and the name of the source for the messages (``"source"``)."""
    if config is None:
        return RunConfig(), {}
    if isinstance(config, RunConfig):
        return dataclasses.replace(config), {}
    import os

    from ..config import config_from_dict, read_toml

    given = {k: v for k, v in (("filter", filter), ("coupling", coupling)) if v is not None}
    if isinstance(config, dict):
        d, source = dict(config), "config"
    else:
        d, source = read_toml(config), os.fspath(config)  # its one-line errors: unreadable, not TOML, not UTF-8
    d.update(given)
    extra = {t: d.pop(t) for t in ("rtk", "rtk_engine") if t in d}
    for t, v in extra.items():
        if not isinstance(v, dict):
            raise ConfigError(f"{source}: key '{t}': bad value {v!r}; allowed: an [{t}] table")
    tdcp = d.get("tdcp")
    if isinstance(tdcp, dict) and tdcp.get("enabled", False) is False:
        extra["tdcp_settings"] = [k for k in tdcp if k != "enabled"]
    return config_from_dict(d, source=source), dict(extra, source=source)


def _apply_rtk_tables(dataset, cfg: RunConfig, extra: dict, spec, options: dict):
    """The ``[rtk]`` / ``[rtk_engine]`` tables of a config dict or file applied as the command line
    applies them (:func:`insnav.cli.run._rtk_ins_inputs`): ``[rtk]`` under the ``rtk_options`` given
    (``run(rtk_options=...)``, else ``[options] rtk_options``), ``[rtk_engine]`` under ``engine``, its
    base position key as the dataset's base position when the dataset has none (an explicit one wins,
    as ``--base-pos`` over the TOML's).  Refused, with one line naming the table and the source, in a run
    that is not RTK (the filter ``rtk``, or the coupling ``rtk``).  Returns the dataset."""
    from ..gnss.rtk import RtkOptions
    from ._base_position import pop_base_position

    source = extra.get("source", "config")
    tables = [t for t in ("rtk", "rtk_engine") if t in extra]
    if not tables:
        return dataset
    rtk_ins = cfg.coupling == "rtk"
    for t in tables:
        if not rtk_ins and not (t == "rtk" and cfg.filter == "rtk"):
            reads = "RTK runs only (filter 'rtk', or coupling 'rtk')" if t == "rtk" else "RTK/INS only (coupling 'rtk')"
            raise ConfigError(f"{source}: [{t}] is read by {reads}; this run is filter '{cfg.filter}', coupling "
                              f"'{cfg.coupling}': remove the table")
    table = dict(extra.get("rtk", {}))
    base_e, where = pop_base_position(table, source)
    eng = extra.get("rtk_engine")
    if rtk_ins:
        from .rtk_ins import MOVED_TO_RTK, check_engine, deprecated_conflict, rtk_ins_options

        eng = check_engine(eng, source)
        for k in MOVED_TO_RTK:
            if k in table and k in eng:
                raise ConfigError(deprecated_conflict(k, source))
        rtk_ins_options(table, source)  # a bad key named with its file
    else:
        RtkOptions.from_dict(table, source)
    given = options["rtk_options"] if "rtk_options" in options else cfg.options.get("rtk_options")
    if isinstance(given, RtkOptions) and table:
        raise ConfigError(f"{source}: an [rtk] table and rtk_options=RtkOptions(...) both given: pass rtk_options as "
                          "a dict of keys (written over the table's), or leave one out")
    if not isinstance(given, RtkOptions):
        if given is not None and not isinstance(given, dict):
            raise ConfigError(f"rtk_options: bad value {given!r}; allowed: a table of [rtk] keys")
        options["rtk_options"] = {**table, **(given or {})}
    if eng:
        given = options["engine"] if "engine" in options else cfg.options.get("engine")
        if given is not None and not isinstance(given, dict):
            raise ConfigError(f"engine: bad value {given!r}; allowed: a dict of [rtk_engine] keys")
        options["engine"] = {**eng, **(given or {})}
    if base_e is not None:
        if dataclasses.is_dataclass(dataset) and any(f.name == "base_position_e_m" for f in dataclasses.fields(dataset)):
            if getattr(dataset, "base_position_e_m", None) is None:
                dataset = dataclasses.replace(dataset, base_position_e_m=base_e, base_position_source=where)
        elif rtk_ins and options.get("base_pos", cfg.options.get("base_pos")) is None:
            options["base_pos"] = base_e
    return dataset


def run(dataset, filter: str | None = None, coupling: str | None = None, config=None,
        *, sanitize: bool | dict = True, checks: bool = True, **overrides) -> Solution:
    """Run a closed-loop GNSS/INS filter over a dataset.

    Parameters
    ----------
    dataset : insnav.Dataset
        IMU increments, GNSS fixes (``t_valid``; the delay filters also use
        ``t_arrival``) or raw observations (tight), initial state, lever arm and
        IMU model.
    filter : str, optional
        A registered filter (:data:`insnav.registry.FILTERS`: ekf, rbukf, ukf,
        kf, rdkf, exact, fukf, upf, pf); overrides ``config.filter``.
    coupling : {'loose', 'tight', 'rtk', 'gnss'}, optional
        Overrides ``config.coupling``; a filter that cannot run that way is an error.
        Not given with a ``filter`` that has one coupling (fukf, upf, pf: tight; spp,
        rtk: gnss), that one.
    config : RunConfig, dict or path, optional
        A :class:`~insnav.config.RunConfig`, a dict of its TOML keys, or a TOML file.  A dict's or
        file's ``[rtk]`` / ``[rtk_engine]`` tables apply to an RTK run as on the command line (under
        ``rtk_options=`` / ``engine=``, whose keys win; the ``[rtk]`` base position when the dataset has
        none) and are refused in any other run; ``[tdcp]`` settings without ``enabled = true`` are refused.
    sanitize : bool or dict
        Check and repair the input first (:mod:`insnav.filters.sanitize`:
        duplicates dropped, short IMU gaps bridged, bad GNSS fixes dropped; a
        dict overrides ``DEFAULTS``); the counts go to ``summary["sanitize"]``.
        Clean data are not changed.
    checks : bool
        Unit and sanity checks before the filter (:mod:`insnav.filters.checks`);
        a :class:`~insnav.filters.checks.DataCheckError` names the file, column and cause.
    **overrides
        Any :class:`RunConfig` field (``init_seed=3``), or an option of the
        filter's family (``delay_p=`` for the delay filters, ``particles=`` for
        the seed 004 filters; :meth:`FilterSpec.options_for`), over the
        config's ``[options]``.  The family's runner receives them as one
        options dataclass (:meth:`FilterSpec.options_class`, derived from the
        runner's signature): every runner is called as ``(dataset, cfg, options)``.

    Returns
    -------
    Solution
        (its subclasses ``TightSolution`` / ``ParticleSolution`` for the tight families)
    """
    if filter is not None and coupling is None and filter in FILTERS and len(FILTERS[filter].couplings) == 1:
        coupling = FILTERS[filter].couplings[0]  # a filter with one coupling (spp, rtk, fukf, upf, pf) runs it
    cfg, extra = _config_and_tables(config, filter, coupling)
    if filter is not None:
        cfg.filter = filter
    if coupling is not None:
        cfg.coupling = coupling
    if cfg.filter not in FILTERS or cfg.coupling not in _ADVERB:
        cfg.validate()  # a ConfigError naming the key and the allowed values
    spec = filter_spec(cfg.filter)
    if cfg.coupling not in spec.couplings:
        how = " or ".join(_ADVERB[c] for c in spec.couplings)
        raise ValueError(f"filter {spec.name!r} runs {how} coupled only (coupling={spec.couplings[0]!r})")
    mine = spec.options_for(cfg.coupling)
    options = {k: overrides.pop(k) for k in list(overrides) if k in mine}  # over the config's [options]
    for k, v in overrides.items():
        if not hasattr(cfg, k):
            owners = [f"{s.name!r} {c}" for s in FILTERS.values() for c in s.couplings if k in s.options_for(c)]
            if owners:
                raise TypeError(f"run() option {k!r} needs filter {' or '.join(owners)} coupling, "
                                f"not {spec.name!r} {cfg.coupling}")
            raise TypeError(f"run() got an unknown option {k!r}")
        setattr(cfg, k, v)
    cfg.validate()
    if extra.get("tdcp_settings") and not cfg.tdcp.enabled:  # dropped from the run before
        raise ConfigError(f"{extra['source']}: key 'tdcp.{extra['tdcp_settings'][0]}': TDCP is off ([tdcp] enabled "
                          "is not true), so the setting would be ignored: enable TDCP or remove it")
    dataset = _apply_rtk_tables(dataset, cfg, extra, spec, options)
    run_options = spec.options_class(cfg.coupling)(**{**cfg.options, **options})
    check_option_values(run_options)  # before the input checks: a bad option fails at once
    report = None
    if getattr(dataset, "gnss_only", False):  # GNSS-only inputs (rtk): no IMU to sanitize, check or scan
        import contextlib

        sanitize = checks = False
        memo = contextlib.nullcontext()
    else:
        from .._imu_scan import scan_memo

        memo = scan_memo()
    with memo:  # the sanitizer, the checks and the runner share one pass over the IMU arrays
        inner = getattr(dataset, "imu_dataset", None)  # RTK/INS: the IMU side of an RtkInsDataset
        if sanitize:
            from .sanitize import sanitize_dataset

            opts = {**cfg.sanitize, **(sanitize if isinstance(sanitize, dict) else {})}
            # the delay filters receive the arrival stream: a fix that arrives
            # twice (seed 001 eq. (4)) is two records, not a duplicate
            arrivals = spec.runners.get(cfg.coupling) == "insnav.filters.delay:run_delay"
            if inner is not None:
                inner, report = sanitize_dataset(inner, opts or True, arrivals=arrivals)
                dataset = dataclasses.replace(dataset, imu_dataset=inner)
            else:
                dataset, report = sanitize_dataset(dataset, opts or True, arrivals=arrivals)
        if not getattr(dataset, "gnss_only", False):  # checks or not: no empty solution reported as healthy
            _check_imu_count(inner if inner is not None else dataset)
        if checks:
            from .checks import check_dataset

            check_dataset(inner if inner is not None else dataset, max_time_offset_s=cfg.max_time_offset_s)
        if cfg.time.estimate_offset == "auto":
            sol = _run_offset_auto(spec, dataset, cfg, run_options)
        else:
            sol = spec.run(cfg.coupling, dataset, cfg, run_options)
    if report is not None:
        sol.summary["sanitize"] = report
    if cfg.coupling != "gnss":
        from .health import assess

        imu_t = getattr(getattr(dataset, "imu", None), "t", None)
        sol.summary["health"] = assess(sol, imu_t_end=float(imu_t[-1]) if imu_t is not None and len(imu_t) else None)
    return sol


def _check_imu_count(dataset) -> None:
    """A navigation run needs two IMU samples (one interval); fewer gave a 0- or 1-row solution with
    "health: ok".  A DataCheckError naming the IMU file."""
    from ..data.checks import DataCheckError, _source

    imu = getattr(dataset, "imu", None)
    if imu is None:
        return
    n = len(imu.t)
    if n < 2:
        raise DataCheckError(f"{_source(imu, 'imu')}: {n} IMU sample{'' if n == 1 else 's'}: a navigation run "
                             "needs 2 or more (one sample interval)")


def _run_offset_auto(spec, dataset, cfg, opts):
    """``[time] estimate_offset = "auto"`` (docs/algorithms.md section 21): the run with the
    time-offset state; its last estimate t_d^ and 1-sigma give the Wald statistic z = t_d^ / sigma,
    N(0, 1) under t_d = 0 for a consistent filter (a random-constant state: the last estimate uses
    every record).  |z| above the two-sided normal quantile of ``cfg.time.auto_false_alarm`` keeps
    that run; otherwise the run without the state (t_d = 0) is made and returned unchanged.  The
    test and the decision go to ``summary["time_offset_test"]``."""
    from statistics import NormalDist

    with_cfg = dataclasses.replace(cfg, time=dataclasses.replace(cfg.time, estimate_offset=True))
    sol = spec.run(cfg.coupling, dataset, with_cfg, opts)
    alpha = float(cfg.time.auto_false_alarm)
    threshold = -NormalDist().inv_cdf(0.5 * alpha)  # the upper alpha/2 quantile, exact for tiny alpha
    est = float(sol.time_offset_s[-1]) if sol.time_offset_s is not None and len(sol.t) else float("nan")
    sig = float(sol.sigma_time_offset_s[-1]) if sol.time_offset_s is not None and len(sol.t) else float("nan")
    z = est / sig if sig > 0.0 else float("nan")
    keep = bool(abs(z) > threshold)  # nan (no rows): the run without the state
    test = dict(estimate_ms=est * 1e3, sigma_ms=sig * 1e3, z=z, threshold_z=threshold, false_alarm=alpha,
                state_kept=keep)
    if not keep:
        sol = spec.run(cfg.coupling, dataset, dataclasses.replace(
            cfg, time=dataclasses.replace(cfg.time, estimate_offset=False)), opts)
    sol.summary["time_offset_test"] = test
    return sol

