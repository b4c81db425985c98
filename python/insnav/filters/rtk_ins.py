"""Tightly coupled RTK/INS (``--filter ekf|rbukf|ukf --coupling rtk --base BASE``).

The closed-loop EKF, RB-UKF or UKF (15 INS error states) with double-differenced carrier-phase and
code rows of a rover against a base, single-differenced ambiguity states in a fixed-capacity block,
INS-aided ambiguity resolution (MLAMBDA, ratio and validation tests, partial AR,
fix-and-hold) and INS-aided cycle-slip detection.  The engine is C++
(``cpp/include/insnav/engine/rtk_ins_engine.hpp``, ``insnav._core.rtk_ins_run``, GIL released);
the equations are in docs/algorithms.md, "Tight RTK/INS".

``cfg.filter``: ``"ekf"`` propagates the navigation errors with the linear error model; ``"rbukf"``
and ``"ukf"`` with the unscented time update through the nonlinear Euler-angle error model (seed 000),
the ambiguities' cross-covariance by the statistically linearised transition of each cycle
(Sarkka 2008, eq. (13)).  The DD rows are linear in the ambiguities and, at RTK position
uncertainty, in the position, so both use the same joint Kalman update and give the same solution
(the UKF's augmented update reduces to it for a linear measurement).

Inputs: an IMU dataset (:class:`insnav.Dataset`: IMU increments, initial state, lever arm, IMU
model; its time ``t`` relates to GPS time by ``t_gps = t + gps_time_offset_s``), rover and base
observations (RINEX paths or :class:`insnav.gnss.rtk.PhaseObs`) and navigation file(s).

The result is a :class:`~insnav.filters.solution.Solution` (one row per IMU sample: the
IMU-centre navigation) with ``gnss_t``/``gnss_status`` (per rover epoch: applied or not),
``fix_status`` (per rover epoch: RTKLIB's Q, 1 fixed, 2 float, 4 code only, 0 none), ``ratio``,
``solution.rtk`` (:class:`RtkInsSolution`: antenna positions
fixed or float per epoch, ratio, fixed ambiguities, slip detections including the INS-aided
test) and ``summary`` counts (fix rate, slips; ``summary["counters"]``: the run's work, the AR epochs,
MLAMBDA solves including the partial-AR subsets, their search nodes (sum and largest), failed solves,
ambiguity states added and re-initialised, joint updates skipped for a covariance that is not
positive definite).

``cfg.smooth`` (every filter here): the RTS smoother (:mod:`insnav.filters.smoothing`) over the 15
navigation error states, the ambiguities marginalised; at a fixed epoch the smoother starts from the
navigation conditioned on the fixed integers (the fixed solution and its covariance), so the fixed
epochs keep the fixed solution (Rauch, Tung & Striebel 1965; Groves 2013, sec. 3.4.2;
``cpp/include/insnav/engine/rtk_ins_engine.hpp``, 4.).  With ``"rbukf"`` / ``"ukf"`` it is the
unscented RTS smoother (Sarkka 2008, "Unscented Rauch-Tung-Striebel smoother", IEEE TAC 53(3),
eqs. (13)-(15)): the gain from the UT cross-covariance of each cycle, and the fixed solution carried
into the next prediction by the cycle's statistically linearised transition (the one that carries
the ambiguities' cross-covariance); the two give the same smoothed solution, as they give the same
forward one.  Not with ``probe_epoch``.  The rows are smoothed; ``fix_status``,
``ratio`` and ``solution.rtk`` stay the forward pass's (what was fixed), and
``solution.rtk.r_smoothed_e`` is the smoothed antenna per rover epoch.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .. import _core, earth
from ..config import ConfigError, RunConfig, ImuNoise
from ..gnss.rtk import RtkOptions, RtkSolution, estimate_noise_prepass, prepare_rtk_rows
from ._setup import imu_arrays, init_vector, initial_state, lever_arm, raise_if_nonfinite
from ._assemble import nav_solution
from ..units import RAD2DEG
from .solution import Solution

__all__ = ["RtkInsDataset", "RtkInsSolution", "RTK_INS_DEFAULTS", "check_engine", "deprecated_conflict", "run_rtk_ins",
           "rtk_ins_options"]

#: [rtk] defaults of the RTK/INS filter that differ from the GNSS-only engine's.  AR continuous, as the
#: GNSS-only engine (fix-and-hold holds a wrong fix in the joint filter, which on the urban simulator
#: preset costs more than it gains).  The GNSS-only engine's fix validation applies (at least 5
#: ambiguities, partial AR by float variance, confirmation of small sets over 5 epochs) with a lower
#: floor on the bootstrapped success rate, 0.4 instead of 0.95: after a 30 s outage the INS-constrained
#: L1-only float of the Spirent drive has a success rate of 0.77-0.85 at the first epoch and fixes the
#: true integers (0.95 delays that fix to the second epoch, docs/results/rtk_ins.md), while the wrong
#: fixes on the simulator presets have 0.07-0.29 (open sky, GPS L1: 49 of 1037 fixes wrong, up to
#: 0.8 m; urban, GPS L1: 7 of 159; measured with the floor at 0) and the floor removes every one of
#: them (docs/algorithms.md section 22).  Code errors time-correlated over 10 s
#: (``code_correlation_time_s``: multipath of a moving antenna; the first epoch of an ambiguity keeps the
#: white variance): the INS holds the position between epochs, so a white-code model averages correlated
#: multipath as if it were white noise and its float ambiguities are over-confident (on the urban
#: simulator preset the float position's NEES was 10-40x its dimension and most fixes wrong; with the
#: correlated model the wrong fixes fall, docs/results/rtk_ins.md).  The between-receiver ionosphere as
#: states (``iono = "estimate"``, the GNSS-only engine's ionosphere-weighted Gauss-Markov model), with
#: correlated phase error states (``phase_correlation_time_s = 30``, ``phase_error_ratio = 0.5``: one
#: Gauss-Markov error per ambiguity, half the white phase sigma; the GNSS-only engine has them off): on the open-sky
#: simulator preset (2.5-8 km baseline, 1 ppm ionosphere, 3 mm phase multipath over 30 s) the float with
#: neither was over-confident and 10 of 599 epochs fixed; with both all are fixed, and the Spirent drive
#: (under 2 km, no multipath) keeps its fixes and accuracy (docs/algorithms.md section 22).
RTK_INS_DEFAULTS: dict = dict(min_success_rate=0.4, code_correlation_time_s=10.0, iono="estimate",
                              phase_correlation_time_s=30.0, phase_error_ratio=0.5)
#: keys that were engine ([rtk_engine]) keys and are now [rtk] keys (the phase noise model, shared
#: with the GNSS-only engine): still read there, with a deprecation note
MOVED_TO_RTK = ("phase_correlation_time_s", "phase_error_ratio")
#: engine ([rtk_engine]) defaults applied under the caller's (empty: the C++ RtkInsConfig defaults)
ENGINE_DEFAULTS: dict = {}
#: [rtk_engine] keys (``RtkInsConfig``, ``cpp/bindings/bind_rtk_ins.cpp``) that take a number; the
#: range checks are the engine's.  ``outage_cycle_s``: the outage cycle of the unscented time update
#: (default: one cycle per gap; a smoothed run closes them after 1.5 rover periods).
ENGINE_NUMBERS = ("ins_slip_k_sigma", "ins_slip_min_cycles", "ins_slip_max_dt_s", "code_chi2_row",
                  "validation_prob", "ar_min_success_rate", "outage_cycle_s", "robust_chi2_row", "robust_igg_k0",
                  "robust_igg_k1", "robust_huber_k", "robust_max_sats", "robust_phase_reset_epochs")
#: the integer [rtk_engine] keys (``int`` in ``RtkInsConfig``): (lowest, highest)
ENGINE_INTS = {"robust_max_sats": (0, 100), "robust_phase_reset_epochs": (0, 1_000_000)}
#: the engine's ranges of the real [rtk_engine] keys (bind_rtk_ins.cpp checks them, naming no table):
#: (lowest, highest, lowest included, highest included)
ENGINE_RANGES = {"ins_slip_k_sigma": (0.0, math.inf, False, True), "ins_slip_min_cycles": (0.0, math.inf, True, True),
                 "ins_slip_max_dt_s": (0.0, math.inf, True, True), "code_chi2_row": (0.0, math.inf, True, True),
                 "validation_prob": (0.0, 1.0, True, False), "ar_min_success_rate": (0.0, 1.0, True, False),
                 "outage_cycle_s": (0.0, math.inf, False, True), "robust_chi2_row": (0.0, math.inf, False, True),
                 "robust_igg_k0": (0.0, math.inf, False, False), "robust_igg_k1": (0.0, math.inf, False, False),
                 "robust_huber_k": (0.0, math.inf, False, False)}
#: the engine's IGG-III defaults (RobustConfig), for the check 0 < k0 < k1 when one of them is given
ENGINE_IGG_DEFAULTS = {"robust_igg_k0": 1.5, "robust_igg_k1": 3.0}
#: ambiguity states of the RTK/INS engine (``RtkInsEngine<64, ...>`` in cpp/bindings/bind_rtk_ins.cpp)
MAX_AMBIGUITIES = 64
#: [rtk_engine] keys that take true or false
ENGINE_FLAGS = ("robust_screening", "robust_huber")
#: engine keys the run sets from its own keys (RunConfig): refused in the engine table, naming the run key
ENGINE_RUN_KEYS = {"lever_arm_b": "lever_arm_b", "propagation_interval": "propagation_interval_s",
                   "output_decimation": "output_decimation", "smooth": "smooth", "ut_alpha": "ut_alpha",
                   "ut_beta": "ut_beta", "ut_kappa": "ut_kappa"}


def check_engine(engine, source: str | None = None) -> dict:
    """The ``[rtk_engine]`` table (``engine=`` of :func:`run_rtk_ins`) checked: a table of the keys
    :data:`ENGINE_NUMBERS` (numbers), :data:`ENGINE_FLAGS` (booleans) and the deprecated
    :data:`MOVED_TO_RTK`.  A key the run sets (:data:`ENGINE_RUN_KEYS`), an unknown key or a value
    of the wrong type is a one-line ConfigError (a ValueError) naming ``source`` (the TOML file) and the key."""
    from ..config import _suggest

    where = lambda k: f"{source + ': ' if source else ''}key 'rtk_engine.{k}'"  # noqa: E731
    if engine is None:
        return {}
    if not isinstance(engine, dict):
        raise ConfigError(f"{source}: key 'rtk_engine': bad value {engine!r}; allowed: an [rtk_engine] table"
                         if source else f"engine: expected a dict of engine keys, got {type(engine).__name__}")
    known = ENGINE_NUMBERS + ENGINE_FLAGS + MOVED_TO_RTK
    for k, v in engine.items():
        if k in ENGINE_RUN_KEYS:
            raise ConfigError(f"{where(k)}: the run sets it; write the run key '{ENGINE_RUN_KEYS[k]}' instead")
        if k not in known:
            raise ConfigError(f"{where(k)}: unknown{_suggest(k, known)}")
        if k in ENGINE_FLAGS:
            if not isinstance(v, (bool, np.bool_)):
                raise ConfigError(f"{where(k)}: bad value {v!r}; allowed: true or false")
        elif k in ENGINE_INTS:
            lo, hi = ENGINE_INTS[k]
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise ConfigError(f"{where(k)}: bad value {v!r}; allowed: an integer in [{lo}, {hi}]")
        elif isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or np.isnan(v):
            raise ConfigError(f"{where(k)}: bad value {v!r}; allowed: a number")
        elif k in ENGINE_RANGES:
            lo, hi, lo_in, hi_in = ENGINE_RANGES[k]
            if not ((lo <= v if lo_in else lo < v) and (v <= hi if hi_in else v < hi)):
                allowed = (f"a number {'>=' if lo_in else '>'} {lo:g}" if hi == math.inf else
                           f"a number in {'[' if lo_in else '('}{lo:g}, {hi:g}{']' if hi_in else ')'}")
                raise ConfigError(f"{where(k)}: bad value {v!r}; allowed: {allowed}")
        elif k in MOVED_TO_RTK:  # the [rtk] key's range, named in the table it was given in
            from ..gnss._rtk_keys import rtk_value_error

            msg = rtk_value_error({**RtkOptions().__dict__, k: v}, source or "engine", "rtk_engine")
            if msg is not None:
                raise ConfigError(msg if source else msg.removeprefix("engine: "))
    k0, k1 = (engine.get(k, d) for k, d in ENGINE_IGG_DEFAULTS.items())
    if not k0 < k1:
        raise ConfigError(f"{where('robust_igg_k0')}: bad value {k0!r} with robust_igg_k1 = {k1!r}; allowed: "
                          "0 < robust_igg_k0 < robust_igg_k1")
    return dict(engine)


def deprecated_conflict(key: str, source: str | None = None) -> str:
    """The one-line message for a :data:`MOVED_TO_RTK` key given in both ``[rtk]`` and ``[rtk_engine]``."""
    return (f"{source + ': ' if source else ''}keys 'rtk.{key}' and 'rtk_engine.{key}' both given; keep "
            f"'rtk.{key}' (the [rtk_engine] key is deprecated)")


@dataclass
class RtkInsDataset:
    """An IMU dataset plus rover, base and navigation files for ``coupling = "rtk"``."""

    imu_dataset: object
    rover: object
    base: object
    nav: object
    base_position_e_m: object = None
    #: where ``base_position_e_m`` came from, for the messages (``--base-pos``, the TOML's key)
    base_position_source: str | None = None

    def __getattr__(self, name):  # the IMU side (imu, initial, t0, lever_arm_b, imu_model, ...)
        if name in ("imu_dataset", "rover", "base", "nav", "base_position_e_m", "base_position_source"):
            raise AttributeError(name)
        return getattr(self.imu_dataset, name)


@dataclass
class RtkInsSolution(RtkSolution):
    """Per rover epoch, as :class:`insnav.gnss.rtk.RtkSolution` (``r_e`` the antenna, fixed where
    fixed), plus ``slips[:, 6]`` the INS-aided detections and ``code_rejected`` (DD code rows
    screened out), ``screened`` and ``downweighted`` (the robust screening's single differences left
    out or, for phase, re-initialised, and down-weighted per epoch; ``[rtk_engine] robust_screening``);
    with the smoother, ``r_smoothed_e`` (E, 3) the smoothed antenna [m] (NaN where
    the epoch has no solution)."""

    code_rejected: np.ndarray | None = None
    screened: np.ndarray | None = None
    downweighted: np.ndarray | None = None
    r_smoothed_e: np.ndarray | None = None

    SLIP_KINDS = RtkSolution.SLIP_KINDS + ("ins",)


def rtk_ins_options(options=None, source: str = "rtk options") -> RtkOptions:
    """:class:`RtkOptions` of an RTK/INS run: :data:`RTK_INS_DEFAULTS` under the given ones (a bad
    key's one-line ConfigError names ``source``); ``min_fix_ambiguities`` at most the engine's
    :data:`MAX_AMBIGUITIES`."""
    if options is not None and not isinstance(options, (dict, RtkOptions)):
        raise ConfigError(f"{source}: bad value {options!r}; allowed: a table of [rtk] keys")
    opt = options if isinstance(options, RtkOptions) else \
        RtkOptions.from_dict({**RTK_INS_DEFAULTS, **(options or {})}, source)
    if opt.min_fix_ambiguities > MAX_AMBIGUITIES:  # the GNSS-only engine's 120 passed RtkOptions' check
        raise ConfigError(f"{source}: key 'rtk.min_fix_ambiguities': bad value {opt.min_fix_ambiguities!r}; "
                          f"allowed: an integer in [1, {MAX_AMBIGUITIES}] with RTK/INS (the ambiguity states "
                          "its engine holds)")
    return opt


def run_rtk_ins(dataset, cfg: RunConfig | None = None, *, rover=None, base=None, nav=None, base_pos=None,
                rtk_options=None, engine: dict | None = None, probe_epoch: int = -1) -> Solution:
    """Tight RTK/INS over an IMU dataset and rover/base observations.

    Parameters
    ----------
    dataset : insnav.Dataset or RtkInsDataset
        IMU side (and, for :class:`RtkInsDataset`, the GNSS files).
    cfg : RunConfig
        Initial sigmas and perturbation, IMU noise, propagation step, output decimation, lever arm.
    rover, base : path or PhaseObs
        Rover and base observations (default: the dataset's).
    nav : path, list of paths or NavData
    base_pos : (3,) ECEF [m], optional
        Base antenna reference point; default the base header's.
    rtk_options : RtkOptions or dict
        ``[rtk]`` options (weighting, masks, AR, slip detectors); :data:`RTK_INS_DEFAULTS` apply,
        among them ``phase_correlation_time_s`` (30 s; 0: white phase) and ``phase_error_ratio`` (0.5):
        the time-correlated phase errors as one first-order Gauss-Markov state per ambiguity, its sigma
        that multiple of the white phase sigma (0: a tracked ambiguity's phase variance
        x (1 + rho) / (1 - rho), rho = exp(-dt / tau), instead; docs/algorithms.md, "Tight RTK/INS").
    engine : dict, optional
        Engine keys: ``ins_slip_k_sigma`` (5), ``ins_slip_min_cycles`` (0.35), ``ins_slip_max_dt_s``
        (2 s), ``code_chi2_row`` (25; 0 off), ``validation_prob`` (0.999; 0 off), the robust
        screening of the single differences (Teunissen's w-test per satellite and frequency, IGG-III
        down-weighting; docs/algorithms.md, "Tight RTK/INS"): ``robust_screening`` (False),
        ``robust_chi2_row`` (10.83), ``robust_igg_k0`` (1.5), ``robust_igg_k1`` (3.0),
        ``robust_huber`` (False), ``robust_huber_k`` (1.5), ``robust_max_sats`` (2),
        ``robust_phase_reset_epochs`` (2), ``ar_min_success_rate`` (0), ``outage_cycle_s`` (the unscented
        time update's outage cycle [s]; default one per gap, 1.5 rover periods in a smoothed run).  The
        run's own keys (lever arm, propagation interval, output decimation, smoother, UT scaling) come
        from ``cfg``; :func:`check_engine` refuses them here.
    probe_epoch : int
        Tests: stop the records after this rover epoch and return its AR in ``solution.probe``.

    Returns
    -------
    Solution
    """
    cfg = dataclasses.replace(cfg or RunConfig(), coupling="rtk")
    cfg.validate()  # the filters of coupling 'rtk' and their facts: insnav.registry
    imu_ds = getattr(dataset, "imu_dataset", dataset)
    rover = rover if rover is not None else getattr(dataset, "rover", None)
    base = base if base is not None else getattr(dataset, "base", None)
    nav = nav if nav is not None else getattr(dataset, "nav", None)
    base_source = None
    if base_pos is None:
        base_pos = getattr(dataset, "base_position_e_m", None)
        base_source = getattr(dataset, "base_position_source", None)
    for k, v in (("rover", rover), ("base", base), ("nav", nav)):
        if v is None:
            raise ValueError(f"coupling 'rtk' needs rover, base and nav observations; missing {k!r} "
                             "(insnav run --coupling rtk --obs ROVER --base BASE --nav NAV)")
    engine = check_engine(engine)
    moved = {k: engine.pop(k) for k in MOVED_TO_RTK if k in engine}
    both = [k for k in moved if isinstance(rtk_options, RtkOptions) or k in (rtk_options or {})]
    if both:  # the deprecated place silently won before
        raise ConfigError(deprecated_conflict(both[0]))
    if moved:
        import warnings

        warnings.warn(f"key '[rtk_engine] {next(iter(moved))}' is deprecated; write it in [rtk] "
                      "(the phase noise model, shared with the GNSS-only engine)", FutureWarning, stacklevel=2)
        rtk_options = dataclasses.replace(rtk_options, **moved).validate() if isinstance(rtk_options, RtkOptions) \
            else {**(rtk_options or {}), **moved}
    opt = rtk_ins_options(rtk_options)
    rover, base, r_base_e, bidx, roff, rrows, boff, brows = prepare_rtk_rows(rover, base, nav, base_pos, opt,
                                                                             base_source=base_source)
    noise_est = None
    if opt.noise == "estimate":
        # the GNSS-only pre-pass (with the GNSS-only engine's success-rate test, so that the epochs the
        # noise is estimated from are validated fixes) estimates the sigmas this run then uses
        pre = dataclasses.replace(opt, min_success_rate=RtkOptions.min_success_rate)
        opt, noise_est = estimate_noise_prepass(rover.epoch_t_gps_s, roff, rrows, boff, brows, bidx, r_base_e, opt,
                                                validation=pre)
    t, dth, dv = imu_arrays(imu_ds)
    off = float(imu_ds.gps_time_offset_s)
    t_rec = rover.epoch_t_gps_s - off
    rng = np.random.default_rng(cfg.init_seed)
    init, sig0 = initial_state(imu_ds, cfg, rng)
    noise = cfg.imu or ImuNoise.from_dataset_model(imu_ds.imu_model)
    p0 = np.zeros(15)
    p0[:9] = sig0
    p0[9:12] = noise.acc_bias_sigma
    p0[12:15] = noise.gyro_bias_sigma
    eng = dict(lever_arm_b=lever_arm(imu_ds, cfg), propagation_interval=cfg.propagation_interval_s,
               output_decimation=int(cfg.output_decimation))
    if cfg.filter != "ekf":  # the unscented time update's UT scaling (seed 000 defaults: kappa = 3 - n)
        eng.update(ut_alpha=cfg.ut_alpha, ut_beta=cfg.ut_beta,
                   ut_kappa=(3.0 - 15) if cfg.ut_kappa is None else cfg.ut_kappa)
    eng.update(ENGINE_DEFAULTS)
    if cfg.smooth:  # the smoother's epochs inside outages: a cycle closed after 1.5 rover periods
        d = np.diff(t_rec)
        period = cfg.cycle_period_s or (float(np.median(d[d > 0])) if np.any(d > 0) else 1.0)
        eng.update(smooth=True, outage_cycle_s=1.5 * period)
    eng.update(engine)
    out = _core.rtk_ins_run(t, dth, dv, init_vector(imu_ds, init), np.diag(p0 ** 2), np.zeros(12),
                            noise.as_core_dict(), eng, opt.core_dict(), t_rec, roff, rrows, boff, brows, bidx,
                            r_base_e, int(probe_epoch), cfg.filter)
    age = np.where(bidx >= 0, rover.epoch_t_gps_s - base.epoch_t_gps_s[np.maximum(bidx, 0)], np.nan)
    status = np.asarray(out["status_epoch"])
    P_ned = np.asarray(out["P_r_ned"]).reshape(-1, 3, 3)
    lat_b, lon_b, _ = earth.ecef_to_geodetic(r_base_e)
    C_en = np.asarray(earth.C_en(lat_b, lon_b))  # NED -> ECEF at the base (short baselines)
    P_e = np.einsum("ij,njk,lk->nil", C_en, P_ned, C_en)
    rs = RtkInsSolution(t_gps_s=rover.epoch_t_gps_s.copy(), status=status, ratio=np.asarray(out["ratio"]),
                        success_rate=np.asarray(out["success_rate"]), n_fix=np.asarray(out["n_fix"]),
                        n_dd=np.asarray(out["n_dd"]), n_sat=np.asarray(out["n_sat"]),
                        r_e=np.asarray(out["r_e"]), v_e=np.full((status.size, 3), np.nan),
                        r_float_e=np.asarray(out["r_float_e"]), P_r=P_e, slips=np.asarray(out["slips"]),
                        base_age_s=age, r_base_e=r_base_e, code_rejected=np.asarray(out["code_rejected"]),
                        screened=np.asarray(out["screened"]), downweighted=np.asarray(out["downweighted"]),
                        info=dict(rover=rover.path, base=base.path, options=opt, engine=eng,
                                  noise_estimate=noise_est))
    counts = rs.counts()
    summary = dict(filter=cfg.filter, coupling="rtk", layout=15, updates=int((status > 0).sum()), rejected=0,
                   gnss_records=int(status.size), cholesky_repairs=int(out["cholesky_repairs"]), **counts,
                   counters={k: int(v) for k, v in out["counters"].items()})
    # <out>.innovations.csv: no NIS (the DD rows' test is the AR ratio, in <out>.rtk.csv), the DD rows per epoch
    sol, _ = nav_solution(out, gnss_t=t_rec, innovation=np.full((status.size, 6), np.nan), nis=np.full(status.size, np.nan),
                          gnss_status=np.where(status > 0, 1, 0).astype(np.int8), summary=summary)
    sol.rows = rs.n_dd.astype(int)
    sol.rtk = rs
    sol.rtk_options = opt
    sol.fix_status = status.copy()
    sol.ratio = rs.ratio.copy()
    sol.n_fix = rs.n_fix.copy()
    sol.rtk_row_slip = np.asarray(out["row_slip"])  # per rover row: slip bits (SLIP_KINDS order)
    if "probe" in out:
        sol.probe = {k: np.asarray(v) for k, v in out["probe"].items()}
    if cfg.smooth:  # RTS backward pass: the rows, and the antenna per rover epoch
        from .smoothing import smoothed_rows

        smoothed_rows(sol, out, cfg.filter)
        rs.r_smoothed_e = _smoothed_antenna(out, t_rec, status, eng["lever_arm_b"])
    raise_if_nonfinite(sol, cfg.filter)
    return sol


def _smoothed_antenna(out: dict, t_rec, status, lever_arm_b) -> np.ndarray:
    """The smoothed antenna per rover epoch (E, 3) ECEF [m]: the INS after each epoch
    (``nav_epoch``) corrected as the rows are (:func:`insnav.filters.smoothing.smoothed_rows`), plus
    the lever arm ``C_en C_nb l_b``; NaN where the epoch has no solution."""
    nav = np.asarray(out["nav_epoch"], float)
    te = np.asarray(out["smooth_t"], float)
    r = np.full((len(t_rec), 3), np.nan)
    if te.size < 2:
        return r
    k = np.flatnonzero((status > 0) & np.all(np.isfinite(nav), axis=1) & (t_rec <= te[-1] + 1e-9))
    if k.size == 0:
        return r
    lat, lon = nav[k, 0] * RAD2DEG, nav[k, 1] * RAD2DEG
    h, v = nav[k, 2].copy(), np.ascontiguousarray(nav[k, 3:6])
    roll, pitch, yaw = (np.ascontiguousarray(nav[k, 6 + j] * RAD2DEG) for j in range(3))
    cols = list(range(9))
    d = np.ascontiguousarray(np.asarray(out["smooth_d"], float)[:, cols])
    d_end = np.ascontiguousarray(np.asarray(out["smooth_d_end"], float)[:, cols])
    sig = np.ascontiguousarray(np.asarray(out["smooth_sigma"], float)[:, cols])
    sg = np.empty((k.size, 9))
    _core.smooth_rows(np.ascontiguousarray(t_rec[k], float), lat, lon, h, v, roll, pitch, yaw, te, d, d_end, sig, sg,
                      None)
    # l_n = C_nb l_b (3-2-1 Euler angles), then r = r_imu + C_en l_n
    ph, th, ps = np.radians(roll), np.radians(pitch), np.radians(yaw)
    sr, cr, sp, cp, sy, cy = np.sin(ph), np.cos(ph), np.sin(th), np.cos(th), np.sin(ps), np.cos(ps)
    lx, ly, lz = (float(c) for c in np.broadcast_to(np.asarray(lever_arm_b, float), (3,)))
    y1, z1 = cr * ly - sr * lz, sr * ly + cr * lz
    x2, z2 = cp * lx + sp * z1, -sp * lx + cp * z1
    l_n = np.stack([cy * x2 - sy * y1, sy * x2 + cy * y1, z2], axis=-1)
    lat_r, lon_r = np.radians(lat), np.radians(lon)
    r[k] = earth.geodetic_to_ecef(lat_r, lon_r, h) + np.einsum("nij,nj->ni", earth.C_en(lat_r, lon_r), l_n)
    return r
