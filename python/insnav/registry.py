"""The filter registry: every filter name insnav knows, what it couples,
which state layouts it runs on, which extra options it takes and which
function runs it.  ``insnav.run``, the configuration check, the CLI help and
``insnav compare`` all read this one table, so they cannot disagree.

The runners are named as ``"module:function"`` strings and imported only
when a run starts (this module sits below the run layer and imports nothing
of it).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .errors import close_matches

__all__ = ["FilterSpec", "FILTERS", "filter_spec", "filter_names"]


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

    def options_for(self, coupling: str) -> tuple:
        """The ``insnav.run`` keyword options of this filter run with ``coupling``."""
        return self.options + tuple(self.coupling_options.get(coupling, ()))

    @property
    def all_options(self) -> tuple:
        """Every keyword option of this filter, over its couplings."""
        return tuple(dict.fromkeys(self.options + tuple(o for c in self.couplings
                                                        for o in self.coupling_options.get(c, ()))))

    def runner(self, coupling: str):
        """The run function for a coupling (imported now)."""
        import importlib

        mod, fn = self.runners[coupling].split(":")
        return getattr(importlib.import_module(mod), fn)


_LOOSE = "insnav.filters.loose:run_loose"
_TIGHT = "insnav.filters.tight:run_tight"
#: options of the tightly coupled EKF / RB-UKF / UKF (``insnav.filters.tight.run_tight``)
TIGHT_OPTIONS = ("inputs", "elevation_mask_deg", "max_sats", "clock_psd", "init_sigma_clock", "clock0",
                 "use_pseudorange", "use_rate", "layout", "isb_psd", "init_sigma_isb", "isb0")
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
#: options of the tight RTK/INS EKF (``insnav.filters.rtk_ins.run_rtk_ins``)
RTK_INS_OPTIONS = ("rover", "base", "nav", "base_pos", "rtk_options", "engine", "probe_epoch")
#: options of the delay filters (``insnav.filters.delay.run_delayed``)
DELAY_OPTIONS = ("delay_p", "max_history_s", "checkpoint_interval_s")

FILTERS: dict[str, FilterSpec] = {s.name: s for s in (
    FilterSpec("ekf", ("loose", "tight", "rtk"), {"loose": (15, 21), "tight": (17,), "rtk": (15,)},
               {"loose": _LOOSE, "tight": _TIGHT, "rtk": _RTK_INS}, outage_cycle_factor=1.5,
               paper="seed 000 baseline, seed 003; rtk: Teunissen 1995, Chang, Yang & Zhou 2005 (MLAMBDA)",
               summary="closed-loop error-state EKF, Joseph update; rtk: double-differenced carrier phase and code "
                       "against a base, ambiguity states, INS-aided AR and slip detection",
               coupling_options={"tight": TIGHT_OPTIONS, "rtk": RTK_INS_OPTIONS}),
    FilterSpec("rbukf", ("loose", "tight"), {"loose": (15, 21), "tight": (17,)},
               {"loose": _LOOSE, "tight": _TIGHT}, paper="seed 000",
               summary="UT time update through the nonlinear error model, linear KF update",
               coupling_options={"tight": TIGHT_OPTIONS}),
    FilterSpec("ukf", ("loose", "tight"), {"loose": (15, 21), "tight": (17,)},
               {"loose": _LOOSE, "tight": _TIGHT}, paper="seed 000 baseline",
               summary="UT time update + augmented unscented measurement update",
               coupling_options={"tight": TIGHT_OPTIONS}),
    FilterSpec("kf", ("loose",), {"loose": (15,)}, {"loose": _DELAY}, DELAY_OPTIONS, 1.5, "seed 001",
               summary="late GNSS used as if current"),
    FilterSpec("rdkf", ("loose",), {"loose": (15,)}, {"loose": _DELAY}, DELAY_OPTIONS, 1.5, "seed 001",
               summary="random-delay Kalman filter"),
    FilterSpec("exact", ("loose",), {"loose": (15, 21)}, {"loose": _DELAY}, DELAY_OPTIONS, 1.5, "seed 001",
               summary="exact time-tagged re-processing from checkpoints"),
    FilterSpec("fukf", ("tight",), {"tight": (20,)}, {"tight": _PARTICLE}, PARTICLE_OPTIONS, paper="seed 004",
               summary="UKF with residual-constrained adaptive fading"),
    FilterSpec("upf", ("tight",), {"tight": (20,)}, {"tight": _PARTICLE}, PARTICLE_OPTIONS, paper="seed 004",
               summary="unscented particle filter (a weighted bank of UKFs)"),
    FilterSpec("pf", ("tight",), {"tight": (20,)}, {"tight": _PARTICLE}, PARTICLE_OPTIONS, paper="seed 004",
               summary="marginalised particle filter (marginalize=False: bootstrap PF)"),
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
