"""The filter registry: every filter name insnav knows, what it couples,
and per coupling its facts (:class:`CouplingFacts`: the state layouts it runs
on, whether the RTS smoother runs after it, the vehicle constraints it takes,
whether it reads the UT parameters, the GNSS systems it uses), its options
and the function that runs it.  ``insnav.run``, the configuration check, the
engine configuration, the CLI help and ``insnav compare`` all read this one
table, so they cannot disagree; ``tests/test_registry_facts.py`` checks it
against the runners.

Every family is run as ``FilterSpec.run(coupling, dataset, cfg, options)``:
``options`` is the family's options dataclass (:meth:`FilterSpec.options_class`),
derived from the runner function's keyword parameters, so the registry's
option list, the dataclass and the runner cannot drift apart.

The runners are named as ``"module:function"`` strings and imported only
when a run starts (this module sits below the run layer and imports nothing
of it).
"""
from __future__ import annotations

import dataclasses
import functools
import inspect
from dataclasses import dataclass, field

from .errors import close_matches

__all__ = ["FilterSpec", "CouplingFacts", "FILTERS", "filter_spec", "filter_names", "options_class"]


@dataclass(frozen=True)
class CouplingFacts:
    """What one filter does with one coupling (:meth:`FilterSpec.facts`).

    Attributes
    ----------
    layouts : tuple of int
        The error-state sizes it runs on (15, 21 loose; 17, 20 tight; 20 the
        seed 004 filters; () GNSS only).
    smoothable : bool
        The RTS smoother runs after it (``smooth = true``).
    constraints : tuple of str
        The vehicle constraints it applies (``[constraints] use``).
    ut_params : bool
        It reads the unscented-transform parameters ``ut_alpha``, ``ut_beta``, ``ut_kappa``.
    systems : tuple of str
        The GNSS systems it uses (``"G"`` GPS, ``"R"``, ``"E"``, ``"C"``).
    selfcal : bool
        It can estimate the time offset and the lever arm as states.
    options : tuple of str
        Its keyword options beyond the RunConfig fields (:meth:`FilterSpec.options_for`).
    runner : str
        ``"module:function"`` of the runner.
    """

    layouts: tuple
    smoothable: bool
    constraints: tuple
    ut_params: bool
    systems: tuple
    selfcal: bool
    options: tuple
    runner: str


@dataclass(frozen=True)
class FilterSpec:
    """One filter of the registry.

    Attributes
    ----------
    name : str
        The ``filter=`` / ``--filter`` value.
    couplings : tuple of str
        ``"loose"`` and/or ``"tight"``; ``"gnss"``: GNSS only, no IMU (``spp``).
    layouts : dict
        coupling -> error-state size(s) it runs on (15, 21: loose; 17, 20: tight).
    runners : dict
        coupling -> ``"module:function"`` of the run function.
    options : tuple of str
        Keyword options of ``insnav.run`` beyond :class:`~insnav.config.RunConfig` fields,
        for every coupling.
    selfcal : tuple of str
        The couplings on which the filter can estimate the IMU-GNSS time
        offset and the GNSS lever arm as states (``[time] estimate_offset``,
        ``[lever_arm] estimate``; ``cpp/include/insnav/filter/layout.hpp``).
    coupling_options : dict
        coupling -> further keyword options of that coupling's runner only
        (:meth:`options_for`; ``tests/test_architecture.py`` checks them against
        the runners' signatures).
    outage_cycle_factor : float
        The filter cycle without GNSS (an outage) closes after this many GNSS
        periods.  1 for the sigma-point filters: seed 000's UT prediction runs
        once per GNSS period through an outage.  1.5 for the Kalman filters
        whose linear propagation does not depend on where a cycle ends: a fix
        that arrives a little late (receiver jitter) then still falls in its
        own cycle instead of after an empty one.
    paper : str
        The seed paper it comes from.
    summary : str
        One line for the CLI help.
    smoothable : tuple of str
        The couplings after which the RTS smoother runs (``smooth = true``).
    constraints : dict
        coupling -> the vehicle constraints it applies (``[constraints] use``).
    ut_params : bool
        A sigma-point filter: it reads ``ut_alpha``, ``ut_beta``, ``ut_kappa``.
    systems : dict
        coupling -> the GNSS systems it uses (every system where absent).
    data_options : tuple of str
        The options that carry data (input rows, observation files read
        elsewhere), not settings: given to :func:`insnav.run` only, never in a
        TOML ``[options]`` table or on the command line.
    """

    name: str
    couplings: tuple
    layouts: dict
    runners: dict
    options: tuple = ()
    outage_cycle_factor: float = 1.0
    paper: str = ""
    summary: str = ""
    coupling_options: dict = field(default_factory=dict)
    selfcal: tuple = ()
    smoothable: tuple = ()
    constraints: dict = field(default_factory=dict)
    ut_params: bool = False
    systems: dict = field(default_factory=dict)
    data_options: tuple = ()

    def options_for(self, coupling: str) -> tuple:
        """The ``insnav.run`` keyword options of this filter run with ``coupling``."""
        return self.options + tuple(self.coupling_options.get(coupling, ()))

    @property
    def all_options(self) -> tuple:
        """Every keyword option of this filter, over its couplings."""
        return tuple(dict.fromkeys(self.options + tuple(o for c in self.couplings
                                                        for o in self.coupling_options.get(c, ()))))

    def facts(self, coupling: str) -> CouplingFacts:
        """Everything the registry knows of this filter run with ``coupling``."""
        return CouplingFacts(layouts=tuple(self.layouts.get(coupling, ())),
                             smoothable=coupling in self.smoothable,
                             constraints=tuple(self.constraints.get(coupling, ())), ut_params=self.ut_params,
                             systems=tuple(self.systems.get(coupling, ALL_SYSTEMS)),
                             selfcal=coupling in self.selfcal, options=self.options_for(coupling),
                             runner=self.runners[coupling])

    def setting_options(self, coupling: str) -> tuple:
        """The options of ``coupling`` a TOML ``[options]`` table and ``--option`` may set."""
        return tuple(o for o in self.options_for(coupling) if o not in self.data_options)

    def runner(self, coupling: str):
        """The family's run function for a coupling (imported now), with its keyword options."""
        import importlib

        mod, fn = self.runners[coupling].split(":")
        return getattr(importlib.import_module(mod), fn)

    def options_class(self, coupling: str) -> type:
        """The options dataclass of this filter's family on ``coupling``: one field per
        keyword option, with the runner's default (:func:`options_class`)."""
        return options_class(self.runners[coupling], self.options_for(coupling))

    def run(self, coupling: str, dataset, cfg, options=None):
        """The one runner signature of every family: ``(dataset, cfg, options)``, with
        ``options`` an instance of :meth:`options_class` (None: the defaults)."""
        cls = self.options_class(coupling)
        if options is None:
            options = cls()
        elif not isinstance(options, cls):
            raise TypeError(f"filter {self.name!r} {coupling}: options must be a {cls.__name__}, "
                            f"got {type(options).__name__}")
        return self.runner(coupling)(dataset, cfg, **{f.name: getattr(options, f.name)
                                                     for f in dataclasses.fields(options)})


#: every GNSS system insnav reads (gnss/systems.py SYSTEMS; repeated here, below that layer)
ALL_SYSTEMS = ("G", "R", "E", "C")


@functools.lru_cache(maxsize=None)
def options_class(runner: str, names: tuple) -> type:
    """The options dataclass of the runner ``"module:function"``: a frozen dataclass
    with the keyword parameters ``names`` of the function's signature, their
    annotations and defaults (a parameter without a default defaults to None).
    Derived from the signature, so the two cannot disagree."""
    import importlib

    mod, fn = runner.split(":")
    func = getattr(importlib.import_module(mod), fn)
    params = inspect.signature(func).parameters
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):
        raise TypeError(f"{runner}: a runner takes its options by name, not **kwargs")
    missing = [n for n in names if n not in params]
    if missing:
        raise TypeError(f"{runner}: the registry lists options {missing} that the runner does not take")
    fields = []
    for n in names:
        p = params[n]
        default = None if p.default is p.empty else p.default
        f = field(default_factory=lambda d=default: type(d)(d)) if isinstance(default, (list, dict, set)) \
            else field(default=default)
        fields.append((n, object if p.annotation is p.empty else p.annotation, f))
    family = fn.removeprefix("run_").title().replace("_", "")
    return dataclasses.make_dataclass(f"{family}RunOptions", fields, frozen=True)


_LOOSE = "insnav.filters.loose:run_loose"
_TIGHT = "insnav.filters.tight:run_tight"
#: options of the tightly coupled EKF / RB-UKF / UKF (``insnav.filters.tight.run_tight``)
TIGHT_OPTIONS = ("inputs", "elevation_mask_deg", "max_sats", "clock_psd", "init_sigma_clock", "clock0",
                 "use_pseudorange", "use_rate", "isb_psd", "init_sigma_isb", "isb0")
_DELAY = "insnav.filters.delay:run_delay"
_PARTICLE = "insnav.filters.particle:run_tight_particle"
#: options of the seed 004 filters (``insnav.filters.particle.run_tight_particle``)
PARTICLE_OPTIONS = ("particles", "seed", "fading", "rho", "beta", "eta_max", "alpha", "fading_memory",
                    "resample_threshold", "roughening", "rk4_step_s", "kernel_h2", "init_yaw_uniform_deg",
                    "temper_stages", "divergence_chi2", "noise_floor", "reseed", "marginalize", "gyro_markov_sigma_dph",
                    "gyro_markov_tau_s", "acc_markov_tau_s", "inputs", "elevation_mask_deg", "max_sats",
                    "clock_psd", "init_sigma_clock", "clock0")
_SPP = "insnav.filters.spp:run_spp"
#: options of the single point solution (``insnav.filters.spp.run_spp``)
SPP_OPTIONS = ("spp_options", "weighting")
_RTK = "insnav.filters.rtk:run_rtk"
#: options of the carrier-phase RTK (``insnav.filters.rtk.run_rtk``)
RTK_OPTIONS = ("rtk_options",)
_RTK_INS = "insnav.filters.rtk_ins:run_rtk_ins"
#: options of the tight RTK/INS EKF / RB-UKF / UKF (``insnav.filters.rtk_ins.run_rtk_ins``)
RTK_INS_OPTIONS = ("rover", "base", "nav", "base_pos", "rtk_options", "engine", "probe_epoch")
#: options of the delay filters (``insnav.filters.delay.run_delayed``)
DELAY_OPTIONS = ("delay_p", "max_history_s", "checkpoint_interval_s")

#: the facts every closed-loop EKF / RB-UKF / UKF shares: the RTS smoother after loose, tight and
#: RTK/INS runs (the RB-UKF / UKF: the unscented RTS smoother, Sarkka 2008), the vehicle constraints in
#: loose runs
_KALMAN = dict(smoothable=("loose", "tight", "rtk"), constraints={"loose": ("nhc", "odo", "zupt")})
#: options that carry data, not settings (given to insnav.run only; the CLI reads them from files)
_DATA = ("inputs", "rover", "base", "nav", "base_pos", "engine", "probe_epoch")

FILTERS: dict[str, FilterSpec] = {s.name: s for s in (
    FilterSpec("ekf", ("loose", "tight", "rtk"), {"loose": (15, 21), "tight": (17, 20), "rtk": (15,)},
               {"loose": _LOOSE, "tight": _TIGHT, "rtk": _RTK_INS}, outage_cycle_factor=1.5,
               paper="seed 000 baseline, seed 003; rtk: Teunissen 1995, Chang, Yang & Zhou 2005 (MLAMBDA)",
               summary="closed-loop error-state EKF, Joseph update; rtk: double-differenced carrier phase and code "
                       "against a base, ambiguity states, INS-aided AR and slip detection",
               coupling_options={"tight": TIGHT_OPTIONS, "rtk": RTK_INS_OPTIONS},
               selfcal=("loose", "tight"), data_options=_DATA, **_KALMAN),
    FilterSpec("rbukf", ("loose", "tight", "rtk"), {"loose": (15, 21), "tight": (17, 20), "rtk": (15,)},
               {"loose": _LOOSE, "tight": _TIGHT, "rtk": _RTK_INS}, paper="seed 000; rtk: + Sarkka 2008 eq. (13)",
               summary="UT time update through the nonlinear error model, linear KF update; rtk: the EKF's DD rows "
                       "and AR, ambiguity cross-covariance by the UT's statistically linearised cycle transition",
               coupling_options={"tight": TIGHT_OPTIONS, "rtk": RTK_INS_OPTIONS}, ut_params=True,
               data_options=_DATA, **_KALMAN),
    FilterSpec("ukf", ("loose", "tight", "rtk"), {"loose": (15, 21), "tight": (17, 20), "rtk": (15,)},
               {"loose": _LOOSE, "tight": _TIGHT, "rtk": _RTK_INS}, paper="seed 000 baseline; rtk: + Sarkka 2008",
               summary="UT time update + augmented unscented measurement update; rtk: the DD rows are linear, so "
                       "the update is the RB-UKF's (the same solution)",
               coupling_options={"tight": TIGHT_OPTIONS, "rtk": RTK_INS_OPTIONS}, ut_params=True,
               data_options=_DATA, **_KALMAN),
    FilterSpec("kf", ("loose",), {"loose": (15,)}, {"loose": _DELAY}, DELAY_OPTIONS, 1.5, "seed 001",
               summary="late GNSS used as if current"),
    FilterSpec("rdkf", ("loose",), {"loose": (15,)}, {"loose": _DELAY}, DELAY_OPTIONS, 1.5, "seed 001",
               summary="random-delay Kalman filter"),
    FilterSpec("exact", ("loose",), {"loose": (15, 21)}, {"loose": _DELAY}, DELAY_OPTIONS, 1.5, "seed 001",
               summary="exact time-tagged re-processing from checkpoints"),
    FilterSpec("fukf", ("tight",), {"tight": (20,)}, {"tight": _PARTICLE}, PARTICLE_OPTIONS, paper="seed 004",
               summary="UKF with residual-constrained adaptive fading", ut_params=True,
               systems={"tight": ("G",)}, data_options=_DATA),
    FilterSpec("upf", ("tight",), {"tight": (20,)}, {"tight": _PARTICLE}, PARTICLE_OPTIONS, paper="seed 004",
               summary="unscented particle filter (a weighted bank of UKFs)", ut_params=True,
               systems={"tight": ("G",)}, data_options=_DATA),
    FilterSpec("pf", ("tight",), {"tight": (20,)}, {"tight": _PARTICLE}, PARTICLE_OPTIONS, paper="seed 004",
               summary="marginalised particle filter (marginalize=False: bootstrap PF)",
               systems={"tight": ("G",)}, data_options=_DATA),
    FilterSpec("spp", ("gnss",), {"gnss": ()}, {"gnss": _SPP}, SPP_OPTIONS,
               paper="RTKLIB pntpos; Kuusniemi 2005 RAIM",
               summary="GNSS-only weighted least-squares single point positioning, every system, RAIM FDE; "
                       "no IMU (--format rinex --obs --nav)"),
    FilterSpec("rtk", ("gnss",), {"gnss": ()}, {"gnss": _RTK}, RTK_OPTIONS,
               paper="Chang, Yang & Zhou 2005 (MLAMBDA); RTKLIB relpos",
               summary="GNSS-only carrier-phase RTK against a base: double differences, float EKF, MLAMBDA "
                       "integer fix, cycle slips; no IMU (--format rinex --obs --base --nav)"),
)}


def filter_names(coupling: str | None = None) -> tuple:
    """The registered names (for one coupling, or all)."""
    return tuple(n for n, s in FILTERS.items() if coupling is None or coupling in s.couplings)


def filter_spec(name: str) -> FilterSpec:
    """The spec of a filter; a ValueError naming the known ones for an unknown name."""
    try:
        return FILTERS[name]
    except KeyError:
        close = close_matches(str(name), FILTERS)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"filter {name!r} unknown{hint}; known: {', '.join(FILTERS)}") from None
