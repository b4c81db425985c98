"""Real-time loosely coupled navigation, one sample at a time.

:class:`Navigator` is the push API for a ROS-style node or any program that
receives IMU samples and GNSS fixes as they happen, instead of whole files:
``push_imu``, ``push_gnss_fix``, ``push_constraint``, then ``state()`` /
``covariance()`` whenever an estimate is wanted.  :class:`TightNavigator`
takes epochs of pseudoranges instead of fixes, :class:`DelayNavigator` (seed
001's random-delay KF) the receiver epochs with the fixes that arrived late by
them.  It drives the same compiled
engine as :func:`insnav.run` (``cpp/include/insnav/engine/navigator.hpp``):
pushed in time order, its rows equal the batch run's bit for bit.

Timing: a GNSS fix is applied exactly at its time of validity, inside the IMU
increment that covers it, so it must be pushed before that increment is
integrated.  Receivers deliver fixes late; ``imu_hold`` IMU samples are held
back so that a fix up to ``imu_hold`` samples late is still applied at its own
time (the state then lags the newest sample by that many samples).  A fix
older than the last integrated sample is refused (``"too_old"``) and counted,
never applied at a wrong time.

Frames and units are the library's: NED navigation frame, FRD body frame,
IMU increments over ``(t_prev, t]`` (``dtheta_b`` [rad], ``dv_b`` [m/s]),
latitude/longitude in degrees at the API, SI elsewhere.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from .. import _core
from ..config import RunConfig
from ..data.nav import NavState
from ..units import DEG
from ._setup import lever_arm
from .loose import apply_sigma_factors, has_speed_terms, loose_engine_args

__all__ = ["Navigator", "TightNavigator", "DelayNavigator"]

_RAD2DEG = 180.0 / np.pi  # the batch run's conversion (_core.nav_rows_to_degrees), to the bit

#: what a push call returns (closed_loop.hpp RecordStatus): queued, or why the record was refused
PUSH_STATUS = {0: "queued", 4: "outside_imu_span", 5: "too_old", 6: "queue_full"}
#: what became of the last record processed (``last_fix()``, ``last_epoch()``, ``last_record()``):
#: ``not_used`` when it had nothing to use (every satellite masked out), or none was processed yet
RECORD_STATUS = {0: "not_used", 1: "applied", 2: "rejected_by_gate", 3: "not_positive_definite",
                 4: "outside_imu_span", 5: "too_old", 6: "queue_full"}


def _time(t, call: str) -> float:
    """``t`` as a float [s]; a TypeError naming the call for anything that is not a real number."""
    if isinstance(t, (bool, np.bool_)) or not isinstance(t, (int, float, np.integer, np.floating)):
        raise TypeError(f"{call}: t must be a time in seconds (a real number), got {type(t).__name__} {t!r}")
    return float(t)


def _refuse_batch_only(cfg: RunConfig, who: str) -> None:
    """A ValueError for the settings only the batch run derives (from the whole IMU record or the
    carrier phase of every epoch), which a push engine would otherwise run without."""
    if cfg.constraints.standstill_q_scale != 1.0:
        raise ValueError(f"{who}: [constraints] standstill_q_scale = {cfg.constraints.standstill_q_scale:g} "
                         "unsupported (the standstill detector runs over the whole IMU record in insnav.run); "
                         "leave it at 1")
    if cfg.tdcp.enabled:
        raise ValueError(f"{who}: [tdcp] unsupported (the time-differenced carrier phase rows are built by "
                         "insnav.run from the whole RINEX record)")


#: constraint kinds (loose_engine.hpp ConstraintKind)
CONSTRAINT_KINDS = {"nhc": 1, "odo": 2, "zupt": 4, "zaru": 8}


def _imu_model(imu_model) -> dict:
    """A dataset ``imu_model`` dict from a dict or an IMU grade name."""
    if isinstance(imu_model, str):
        from ..data.imu_grades import imu_model_for_grade

        return imu_model_for_grade(imu_model)
    if not isinstance(imu_model, dict):
        raise TypeError(f"Navigator: imu_model must be a dict (SI keys) or a grade name, got {type(imu_model).__name__}")
    return dict(imu_model)


def _state_dict(s: dict) -> dict:
    """The engine's row (radians, SI) as the API's dict (degrees at the API, as the batch Solution)."""
    rpy = s["rpy"] * _RAD2DEG
    err = s["imu_err"]
    return dict(t=s["t"], lat_deg=s["lat"] * _RAD2DEG, lon_deg=s["lon"] * _RAD2DEG, h_m=s["h"], v_n_mps=s["v_n"],
                roll_deg=rpy[0], pitch_deg=rpy[1], yaw_deg=rpy[2], sigma=s["sigma"],
                acc_bias_mps2=err[0:3], gyro_bias_rps=err[3:6], acc_scale=err[6:9], gyro_scale=err[9:12])


class _PushApi:
    """The calls every push navigator shares (``self._nav`` is its ``_core`` object)."""

    _nav = None

    def push_imu(self, t: float, dtheta_b, dv_b) -> bool:
        """One IMU increment over (t_prev, t]: ``dtheta_b`` [rad], ``dv_b`` [m/s], FRD.
        False (ignored) when ``t`` does not increase, or ``t`` or an increment is not finite."""
        t = t if isinstance(t, float) else _time(t, "push_imu")  # float and numpy.float64 at once: the per-sample path
        return bool(self._nav.push_imu(t, np.asarray(dtheta_b, float), np.asarray(dv_b, float)))

    def push_imu_array(self, t, dtheta_b, dv_b) -> int:
        """Many IMU increments at once (N,), (N,3), (N,3); returns how many were taken."""
        return int(self._nav.push_imu_array(np.asarray(t, float), np.asarray(dtheta_b, float),
                                            np.asarray(dv_b, float)))

    def flush(self) -> None:
        """Integrate the held IMU samples (at the end of a run)."""
        self._nav.flush()

    def covariance(self) -> np.ndarray:
        """The error-state covariance (layout order, SI: m, m/s, rad, m/s^2, rad/s; clock states
        in m and m/s; for the random-delay KF the newest block of its stack)."""
        return self._nav.covariance()

    @property
    def counters(self) -> dict:
        """samples integrated, held samples, pending records (epochs), updates, rejected,
        refused records, and the family's own counts."""
        return self._nav.counters()


class Navigator(_PushApi):
    """Loosely coupled EKF / RB-UKF / UKF fed one sample at a time.

    Parameters
    ----------
    initial : NavState
        Initial position, velocity and attitude (degrees, m, m/s), valid at ``t0``.
    t0 : float
        Time of the initial state [s]; the first IMU increment starts there.
    imu_model : dict or str
        The IMU noise model: a dataset ``imu_model`` dict (SI keys,
        docs/formats.md) or a grade name (``"consumer"``, ``"industrial"``,
        ``"tactical"``, ``"navigation"``).
    config : RunConfig, dict or path, optional
        Run configuration (filter, layout, initial sigmas, gate, lever arm, ...);
        ``filter`` must be ``ekf`` (layouts 15/16/21), ``rbukf`` or ``ukf`` (15).
    lever_arm_b : array_like of 3, optional
        IMU centre to GNSS antenna, body FRD [m] (the config's ``lever_arm_b`` wins).
    gnss_period_s : float
        Nominal GNSS period [s]: the filter cycle during an outage (the batch
        run takes the median fix spacing).
    imu_hold : int
        IMU samples held back for late fixes (0 .. 256).
    """

    def __init__(self, initial: NavState, t0: float, imu_model, config=None, *, lever_arm_b=(0.0, 0.0, 0.0),
                 gnss_period_s: float = 1.0, imu_hold: int = 0):
        from . import _as_config

        cfg = _as_config(config)
        cfg.validate()
        if not (np.isfinite(gnss_period_s) and gnss_period_s > 0):
            raise ValueError(f"Navigator: gnss_period_s must be > 0 s, got {gnss_period_s!r}")
        t0 = _time(t0, "Navigator")
        if not np.isfinite(t0):
            raise ValueError(f"Navigator: t0 must be a finite time [s], got {t0}")
        ds = SimpleNamespace(initial=initial, t0=t0, lever_arm_b=np.asarray(lever_arm_b, float),
                             imu_model=_imu_model(imu_model), scenario=None, initial_is_truth=False)
        self._setup(ds, cfg, np.array([0.0, float(gnss_period_s)]), imu_hold)

    @classmethod
    def from_dataset(cls, dataset, config=None, *, imu_hold: int = 0, **overrides) -> "Navigator":
        """A navigator set up exactly as :func:`insnav.run` sets up its loose
        run of ``dataset`` (initial state and its sigmas, IMU model, lever arm,
        gate, outage cycle from the fix spacing); push the data yourself."""
        from . import _as_config

        cfg = _as_config(config)
        for k, v in overrides.items():
            if not hasattr(cfg, k):
                raise TypeError(f"Navigator.from_dataset() got an unknown option {k!r}")
            setattr(cfg, k, v)
        cfg.validate()
        self = cls.__new__(cls)
        self._setup(dataset, cfg, np.asarray(dataset.gnss.t_valid, float), imu_hold)
        return self

    def _setup(self, dataset, cfg: RunConfig, record_t: np.ndarray, imu_hold: int) -> None:
        if cfg.coupling != "loose" or cfg.filter not in ("ekf", "rbukf", "ukf"):
            raise ValueError(f"Navigator: filter {cfg.filter!r} / coupling {cfg.coupling!r}: the push API runs "
                             "the loose ekf, rbukf and ukf (tight: TightNavigator; RTK/INS has no push API: "
                             "insnav.run)")
        if cfg.smooth:
            raise ValueError("Navigator: the RTS smoother needs the whole run (insnav.run(..., smooth=True))")
        _refuse_batch_only(cfg, "Navigator")
        lever = lever_arm(dataset, cfg)  # the config's wins (validated with it)
        if lever.shape != (3,) or not np.all(np.isfinite(lever)):
            raise ValueError(f"Navigator: lever_arm_b must be 3 finite numbers [m], got {lever.tolist()}")
        a = loose_engine_args(dataset, cfg, record_t)
        self.config = cfg
        self._speed_terms = has_speed_terms(cfg)
        self._factors = self._speed_terms or any(
            x != 1.0 for x in (cfg.gnss_pos_sigma_scale, cfg.gnss_vel_sigma_scale, cfg.gnss_pos_v_sigma_scale))
        self.layout = a.layout
        self._nav = _core.LooseNavigator(cfg.filter, a.layout, a.init, a.P0, a.imu_correction, a.imu_model,
                                         a.config, int(imu_hold))
        self._row = np.empty(13)

    # --- input -----------------------------------------------------------------------------
    def push_gnss_fix(self, t: float, lat_deg: float, lon_deg: float, h_m: float, sigma_pos_n_m,
                      v_n_mps=None, sigma_vel_n_mps=None) -> str:
        """A GNSS antenna fix valid at ``t`` [s]: position (deg, deg, ellipsoidal m)
        with N/E/D 1-sigma [m], optionally NED velocity [m/s] with its 1-sigma.  The
        config's GNSS sigma factors apply as in the batch run (``gnss_pos_sigma_scale``,
        ``gnss_vel_sigma_scale``, ``gnss_pos_v_sigma_scale``; the per-speed terms with the
        fix's own velocity, which they then need).
        Returns ``"queued"``, or why it was refused (``"too_old"``, ``"outside_imu_span"``,
        ``"queue_full"``)."""
        r = self._row
        r[0], r[1], r[2], r[3] = _time(t, "push_gnss_fix"), lat_deg * DEG, lon_deg * DEG, h_m
        r[4:7] = np.nan if v_n_mps is None else np.asarray(v_n_mps, float)
        r[7:10] = sigma_pos_n_m
        r[10:13] = np.nan if sigma_vel_n_mps is None else np.asarray(sigma_vel_n_mps, float)
        if self._factors:  # the config's GNSS sigma factors, as the batch run weights its fixes
            speed = None
            if self._speed_terms:
                speed = np.hypot(r[4], r[5])
                if not np.isfinite(speed):
                    raise ValueError(f"push_gnss_fix at t={r[0]}: gnss_pos_sigma_per_speed_s / "
                                     "gnss_vel_sigma_per_speed need the fix's velocity (the batch run takes "
                                     "the neighbouring fixes' positions, which a push does not have)")
                speed = np.array([speed])
            apply_sigma_factors(r.reshape(1, 13), self.config, speed)
        # a non-finite position or a sigma not finite and > 0: ValueError from the engine's check
        # (engine/navigator.hpp push_fix_problem), nothing queued
        return PUSH_STATUS[self._nav.push_gnss_fix(r)]

    def push_constraint(self, t: float, kinds, speed_mps: float = float("nan")) -> str:
        """A vehicle-constraint event at ``t`` [s]: ``kinds`` a name or names of
        ``nhc``, ``odo`` (with ``speed_mps``, the rear-axle forward speed), ``zupt``, ``zaru``."""
        names = [kinds] if isinstance(kinds, str) else list(kinds)
        bad = [k for k in names if k not in CONSTRAINT_KINDS]
        if bad:
            raise ValueError(f"push_constraint: unknown kind {bad[0]!r} (one of {', '.join(CONSTRAINT_KINDS)})")
        flags = sum(CONSTRAINT_KINDS[k] for k in set(names))
        return PUSH_STATUS[self._nav.push_constraint(_time(t, "push_constraint"), flags, float(speed_mps))]

    # --- output ----------------------------------------------------------------------------
    def state(self) -> dict:
        """The current solution after the last integrated sample: ``t`` [s],
        ``lat_deg``, ``lon_deg``, ``h_m``, ``v_n_mps`` (3), ``roll_deg``,
        ``pitch_deg``, ``yaw_deg``, ``sigma`` (sqrt(diag P), layout order, SI; entries 6-8 the 1-sigmas
        of roll, pitch, yaw [rad], psi's covariance mapped to the Euler angles: ins/nav_error.hpp),
        ``acc_bias_mps2``, ``gyro_bias_rps`` (and scale factors)."""
        s = self._nav.solution()
        out = _state_dict(s)
        if "odo_scale" in s:
            out["odo_scale"], out["sigma_odo_scale"] = s["odo_scale"]
        return out

    def last_fix(self) -> dict:
        """The last fix applied or refused by the gate: ``status``, ``nis``,
        ``innovation`` (INS - GNSS: N, E, D [m], vN, vE, vD [m/s])."""
        d = self._nav.last_fix()
        d["status"] = RECORD_STATUS[d["status"]]
        return d



def _satellite_ids(values, k: int, name: str, t: float) -> np.ndarray:
    """``system`` / ``prn`` of :meth:`TightNavigator.push_pseudoranges` as (k,)
    int64: zeros when None; a float that is not a whole number (2.7 would
    truncate to another system) or a wrong length is refused, naming it."""
    if values is None:
        return np.zeros(k, np.int64)
    a = np.asarray(values)
    if a.shape != (k,):
        raise ValueError(f"push_pseudoranges at t={t}: {name} must have one entry per row of sats ({k}), "
                         f"got shape {a.shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a) & (a == np.round(a))):
        raise ValueError(f"push_pseudoranges at t={t}: {name} must be whole numbers, got {a.tolist()}")
    if a.dtype.kind not in "iuf":
        raise ValueError(f"push_pseudoranges at t={t}: {name} must be integers, got {a.dtype}")
    return a.astype(np.int64)


class TightNavigator(_PushApi):
    """Tightly coupled EKF / RB-UKF / UKF (17 states, or 20 with the
    inter-system biases of several constellations) fed one IMU sample and one
    GNSS epoch of pseudoranges / pseudorange rates at a time.

    The same compiled engine as ``insnav.run(..., coupling="tight")``
    (``engine/navigator.hpp`` ``TightNavigator``): pushed in time order, its rows
    equal the batch run's.  Timing as :class:`Navigator` (``imu_hold`` IMU
    samples held back for late epochs; an epoch older than the last integrated
    sample is refused).  Build it with :meth:`from_dataset`, which sets it up
    exactly as the batch run (initial state and sigmas, receiver clock, ISBs,
    gate, robust screening); :attr:`inputs` then holds the satellite rows the
    batch run would use (``insnav.gnss.tight_inputs.TightInputs``).
    """

    @classmethod
    def from_dataset(cls, dataset, config=None, *, imu_hold: int = 0, **options) -> "TightNavigator":
        """A navigator set up as :func:`insnav.filters.tight.run_tight` sets up its run of
        ``dataset``; ``options`` are run_tight's keywords (``elevation_mask_deg``,
        ``layout``, ``clock0``, ...), ``config`` a RunConfig, dict or path."""
        import dataclasses

        from . import _as_config
        from .tight import tight_engine_args

        cfg = _as_config(config)
        if cfg.coupling == "rtk":
            raise ValueError("TightNavigator: coupling 'rtk': RTK/INS (carrier phase, a base station) has no push "
                             "API; run it with insnav.run")
        cfg = dataclasses.replace(cfg, coupling="tight")
        cfg.validate()
        if cfg.filter not in ("ekf", "rbukf", "ukf"):
            raise ValueError(f"TightNavigator: filter {cfg.filter!r}: the push API runs the tight ekf, rbukf and ukf")
        if cfg.smooth:
            raise ValueError("TightNavigator: the RTS smoother needs the whole run (insnav.run(..., smooth=True))")
        if cfg.time.estimate_offset or cfg.lever_arm.estimate:
            raise ValueError("TightNavigator: [time] estimate_offset / [lever_arm] estimate unsupported (the "
                             "self-calibration states run in the batch engines, insnav.run)")
        _refuse_batch_only(cfg, "TightNavigator")
        if not (0 <= int(imu_hold) <= 256):
            raise ValueError(f"TightNavigator: imu_hold must be in 0 .. 256 samples, got {imu_hold!r}")
        a = tight_engine_args(dataset, cfg, **options)
        self = cls.__new__(cls)
        self.config = cfg
        self.layout = a.layout
        self.inputs = a.inputs
        self._nav = _core.TightNavigator(cfg.filter, a.layout, a.init, a.P0, a.imu_correction,
                                         np.asarray(a.clock0, float), a.isb0 if a.layout == 20 else None,
                                         a.imu_model, a.config, int(imu_hold))
        return self

    def push_pseudoranges(self, t: float, sats, system=None, prn=None) -> str:
        """One GNSS epoch valid at ``t`` [s]: ``sats`` (k, 12) rows of pseudorange [m],
        pseudorange rate [m/s] (NaN: absent), satellite ECEF position [m] and velocity
        [m/s], satellite clock bias [m] and drift [m/s], and the 1-sigma of the
        pseudorange [m] and rate [m/s] (``TightInputs.sats``'s columns);
        ``system`` (k,) indices 0 G, 1 R, 2 E, 3 C (default GPS), ``prn`` (k,).
        Returns ``"queued"``, or why the epoch was refused."""
        t = _time(t, "push_pseudoranges")
        rows = np.ascontiguousarray(np.asarray(sats, float))
        if rows.size == 0:
            rows = np.zeros((0, 12))
        if rows.ndim != 2 or rows.shape[1] != 12:
            raise ValueError(f"push_pseudoranges at t={t}: sats must be (k, 12) rows, got shape {rows.shape}")
        k = rows.shape[0]
        sys_ = _satellite_ids(system, k, "system", t)
        prn_ = _satellite_ids(prn, k, "prn", t)
        return PUSH_STATUS[self._nav.push_pseudoranges(t, rows, sys_, prn_)]

    def push_epoch(self, e: int) -> str:
        """Push epoch ``e`` of :attr:`inputs` (the batch run's satellite rows)."""
        inp = self.inputs
        b, f = int(inp.epoch_start[e]), int(inp.epoch_start[e + 1])
        from ..gnss.systems import system_index

        sys_ = system_index(inp.system[b:f]) if f > b else np.zeros(0, np.int64)
        return self.push_pseudoranges(inp.epoch_t[e], inp.sats[b:f], sys_, np.asarray(inp.prn[b:f], np.int64))

    def state(self) -> dict:
        """The current solution after the last integrated sample: as
        :meth:`Navigator.state`, plus ``clock_bias_m``, ``clock_drift_mps`` and,
        with 20 states, ``isb_m`` (R, E, C) [m]."""
        s = self._nav.solution()
        out = _state_dict(s)
        out["clock_bias_m"], out["clock_drift_mps"] = s["clock"]
        if "isb" in s:
            out["isb_m"] = s["isb"]
        return out

    def last_epoch(self) -> dict:
        """The last epoch applied: ``status`` and ``nis``."""
        d = self._nav.last_epoch()
        d["status"] = RECORD_STATUS[d["status"]]
        return d



class DelayNavigator(_PushApi):
    """Seed 001's random-delay Kalman filter (loose, 15 states) fed one IMU
    sample and one receiver epoch at a time.

    At every epoch of the receiver's schedule push the GNSS records that
    arrived since the previous epoch (:meth:`push_epoch`), also when none
    arrived: the filter does not know a record's time of validity, it weights
    the ``s + 1`` possible delays with the probabilities ``delay_p`` and shifts
    its stacked state at each epoch (Pan, Zhao, Li 2022, eqs. (4)-(21)).  The
    same compiled engine as ``insnav.run(ds, "rdkf")``
    (``engine/navigator.hpp`` ``DelayNavigator``): pushed in time order, its
    rows equal the batch run's.  Timing as :class:`Navigator` (``imu_hold``
    IMU samples held back for late epochs).  Build it with
    :meth:`from_dataset`; :attr:`epochs` and :attr:`records` then hold the
    batch run's receiver epochs and arrival-ordered records, and
    :meth:`push_receiver_epoch` pushes one of them.  The naive use of late
    fixes (``"kf"``) is :class:`Navigator` fed the arrival times; exact
    time-tagged re-processing (``"exact"``) needs the IMU history and runs in
    :func:`insnav.run` only.
    """

    @classmethod
    def from_dataset(cls, dataset, config=None, *, delay_p=None, imu_hold: int = 0,
                     **overrides) -> "DelayNavigator":
        """A navigator set up as ``insnav.run(dataset, "rdkf", delay_p=...)`` sets up its
        run (initial state and sigmas, IMU model, lever arm, gate, outage cycle);
        ``delay_p`` defaults as the batch run's (the scenario's ``gnss.delay_p``, else
        the records' own delays); ``overrides`` are :class:`RunConfig` fields."""
        import dataclasses

        from . import _as_config
        from .delay import check_rdkf, delay_engine_args

        cfg = dataclasses.replace(_as_config(config), filter="rdkf", coupling="loose")
        for k, v in overrides.items():
            if not hasattr(cfg, k):
                raise TypeError(f"DelayNavigator.from_dataset() got an unknown option {k!r}")
            setattr(cfg, k, v)
        cfg.validate()
        if cfg.smooth:
            raise ValueError("DelayNavigator: the RTS smoother needs the whole run")
        if not (0 <= int(imu_hold) <= 256):
            raise ValueError(f"DelayNavigator: imu_hold must be in 0 .. 256 samples, got {imu_hold!r}")
        a = delay_engine_args(dataset, cfg, delay_p)
        check_rdkf(a.p, a.layout)
        self = cls.__new__(cls)
        self.config = cfg
        self.layout = a.layout
        self.delay_p = a.p
        self.epochs = a.epochs
        self.records = a.rec
        # the records that arrived by each epoch (the batch engine's rule: t_arrival <= epoch + 1e-6 s)
        tol = 1e-6
        t0 = float(dataset.t0)
        first = int(np.searchsorted(a.rec[:, 1], t0 + tol, side="right"))
        self._bounds = np.maximum(np.searchsorted(a.rec[:, 1], a.epochs + tol, side="right"), first)
        self._first = first
        self._nav = _core.DelayNavigator(a.layout, a.init, a.P0, a.imu_correction, a.imu_model, a.config,
                                         np.asarray(a.p, float), int(imu_hold))
        return self

    def push_epoch(self, t: float, records=None) -> str:
        """One receiver epoch at ``t`` [s] with the records that arrived since the previous
        epoch: ``records`` (k, 14) rows of t_valid, t_arrival [s], lat, lon [rad], h [m],
        v_n [m/s] (NaN: none), position and velocity 1-sigma N, E, D [m, m/s] (the rows of
        :attr:`records`; at most 8 per epoch).  The sigmas are used as given: the rows of
        :attr:`records` already carry the config's GNSS sigma factors (``gnss_pos_sigma_scale``, ...).
        Returns ``"queued"``, or why it was refused."""
        t = _time(t, "push_epoch")
        rows = np.zeros((0, 14)) if records is None else np.ascontiguousarray(np.asarray(records, float))
        if rows.size == 0:
            rows = np.zeros((0, 14))
        if rows.ndim != 2 or rows.shape[1] != 14:
            raise ValueError(f"push_epoch at t={t}: records must be (k, 14) rows, got shape {rows.shape}")
        # a record with a sigma not finite and > 0: ValueError naming it from the engine's check
        # (engine/navigator.hpp push_fix_problem), nothing queued
        return PUSH_STATUS[self._nav.push_epoch(t, rows)]

    def push_receiver_epoch(self, e: int) -> str:
        """Push epoch ``e`` of :attr:`epochs` with the records of :attr:`records` that arrived by it."""
        b = self._first if e == 0 else int(self._bounds[e - 1])
        return self.push_epoch(self.epochs[e], self.records[b:int(self._bounds[e])])

    def state(self) -> dict:
        """The current solution after the last integrated sample, as :meth:`Navigator.state`."""
        return _state_dict(self._nav.solution())

    def last_record(self) -> dict:
        """The last record applied or refused by the gate: ``status``, ``nis``, ``innovation``
        (the probability-weighted INS - GNSS residual: N, E, D [m], vN, vE, vD [m/s])."""
        d = self._nav.last_record()
        d["status"] = RECORD_STATUS[d["status"]]
        return d

