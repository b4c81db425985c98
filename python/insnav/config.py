"""Run configuration: filter, initial state and its sigmas, IMU noise model,
GNSS settings, lever arm, gating, output rate.

User units at the edge (deg, deg/h, deg/sqrt(h), mg, ug/sqrt(Hz), m, m/s),
SI inside.  :func:`load_config` reads a TOML file; unknown keys and bad values
raise :class:`ConfigError` naming the key, the value and what is allowed.
"""
from __future__ import annotations

from .errors import close_matches

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from .registry import FILTERS
from .units import DEG, DEG_PER_H, DEG_PER_SQRT_H, G0, MG, MPS_PER_SQRT_H, UG_PER_SQRT_HZ


COUPLINGS = ("loose", "tight", "gnss", "rtk")
#: every ``layout`` value (the registry's facts say which a filter and coupling run on)
LAYOUTS = (15, 17, 20, 21)


#: probability of the innovation gate when neither the run nor the dataset's
#: preset sets ``gate_prob`` (chi-square 0.9999 quantile of the record's rows)
GATE_PROB_DEFAULT = 0.9999


class ConfigError(ValueError):
    """A bad configuration key or value; the message names both."""


class TomlTable:
    """Base of the option dataclasses read from one TOML table named ``TABLE``
    (e.g. ``[gnss]``, ``[spp]``): ``from_dict`` rejects an unknown key with a
    did-you-mean, then the subclass's ``validate(source)`` checks the values."""

    TABLE = ""

    @classmethod
    def from_dict(cls, d: dict | None, source: str = "run configuration"):
        """From the TOML table ``d``; a one-line ConfigError names a bad or unknown key."""
        d = dict(d or {})
        names = [f.name for f in dataclasses.fields(cls)]
        for k in d:
            if k not in names:
                close = close_matches(k, names)
                hint = f" (did you mean '{cls.TABLE}.{close[0]}'?)" if close else ""
                raise ConfigError(f"{source}: unknown key '{cls.TABLE}.{k}'{hint}; known keys: {', '.join(names)}")
        return cls(**d).validate(source)


@dataclass
class ImuNoise:
    """IMU error model given to the filter, SI.  See ``ImuErrorModel`` in
    ``cpp/include/insnav/filter/types.hpp`` for the meaning of each field."""

    gyro_arw: list = field(default_factory=lambda: [1e-4] * 3)        # rad/sqrt(s)
    acc_vrw: list = field(default_factory=lambda: [1e-3] * 3)         # (m/s)/sqrt(s)
    gyro_bias_sigma: list = field(default_factory=lambda: [1e-5] * 3)  # rad/s
    acc_bias_sigma: list = field(default_factory=lambda: [1e-3] * 3)   # m/s^2
    gyro_bias_tau: list = field(default_factory=lambda: [3600.0] * 3)  # s
    acc_bias_tau: list = field(default_factory=lambda: [3600.0] * 3)   # s
    gyro_bias_rw: list = field(default_factory=lambda: [0.0] * 3)
    acc_bias_rw: list = field(default_factory=lambda: [0.0] * 3)
    gyro_scale_sigma: list = field(default_factory=lambda: [1e-4] * 3)
    acc_scale_sigma: list = field(default_factory=lambda: [1e-4] * 3)
    gyro_scale_tau: list = field(default_factory=lambda: [14400.0] * 3)
    acc_scale_tau: list = field(default_factory=lambda: [14400.0] * 3)

    def as_core_dict(self) -> dict:
        return {k: np.asarray(v, dtype=float) for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dataset_model(cls, m: dict, default_tau_s: float = 3600.0) -> "ImuNoise":
        """The filter model matching a simulator ``imu_model`` dict (SI).

        Bias states are first-order Gauss-Markov: the simulated Gauss-Markov
        part when there is one, otherwise a slowly varying constant with the
        total bias sigma and ``default_tau_s``.
        """
        if not m or not any(k in m for k in ("gyro_arw", "accel_vrw", "gyro_bias_total_sigma",
                                               "accel_bias_total_sigma")):
            raise ValueError("no IMU noise model: the dataset has neither 'imu_model' nor 'imu_grade' "
                             "(dataset.json; imu_grade = consumer | industrial | tactical | navigation, "
                             "docs/formats.md), and the run config gives no [imu] noise; a filter with zero "
                             "IMU noise would trust the IMU blindly")
        unknown = set(m) - _IMU_MODEL_KEYS
        if unknown:
            k = sorted(unknown)[0]
            close = close_matches(k, _IMU_MODEL_KEYS)
            raise ValueError(f"imu_model: unknown key {k!r}" + (f" (did you mean {close[0]!r}?)" if close else "")
                             + f"; known: {', '.join(sorted(_IMU_MODEL_KEYS))}")

        def vec(key, default=0.0):
            return np.broadcast_to(np.asarray(m.get(key, default), dtype=float), (3,)).copy()

        out = cls()
        out.gyro_arw = vec("gyro_arw").tolist()
        out.acc_vrw = vec("accel_vrw").tolist()
        for p, q in (("gyro", "gyro"), ("accel", "acc")):
            gm_s, gm_tau = vec(f"{p}_gm_sigma"), vec(f"{p}_gm_tau", np.inf)
            total = vec(f"{p}_bias_total_sigma")
            use_gm = (gm_s > 0) & np.isfinite(gm_tau)
            sigma = np.where(use_gm, np.maximum(gm_s, total), total)
            tau = np.where(use_gm, gm_tau, default_tau_s)
            setattr(out, f"{q}_bias_sigma", np.maximum(sigma, 1e-12).tolist())
            setattr(out, f"{q}_bias_tau", tau.tolist())
            setattr(out, f"{q}_bias_rw", vec(f"{p}_bias_rw").tolist())
            sc = vec(f"{p}_scale_sigma")
            setattr(out, f"{q}_scale_sigma", np.maximum(sc, 1e-7).tolist())
        return out


#: keys of a dataset's imu_model (insnav.sim.imu.imu_model_dict, insnav.data.imu_grades.imu_model_for_grade)
_IMU_MODEL_KEYS = {"rate_hz", "imu_grade", "gyro_arw", "accel_vrw"} | {
    f"{p}_{k}" for p in ("gyro", "accel")
    for k in ("bias", "bias_sigma", "gm_sigma", "gm_tau", "bias_rw", "scale", "scale_sigma",
              "misalignment_sigma", "bias_total_sigma")}


@dataclass
class TimeOffset(TomlTable):
    """The IMU-GNSS time offset as a filter state (``[time]`` in the run TOML;
    ``cpp/include/insnav/filter/layout.hpp``, docs/algorithms.md
    "Self-calibration states").

    A GNSS record tagged ``t`` holds the antenna at IMU time ``t - t_d``
    (``t_d > 0``: the GNSS data are tagged late against the IMU clock).  With
    ``estimate_offset`` the EKF carries ``t_d`` as a state (loose: 16 states,
    19 with the lever arm; tight: 18 / 21), applies every record at
    ``t - t_d^`` and reports ``Solution.time_offset_s`` and its 1-sigma.

    With ``estimate_offset = "auto"`` (post-processing, :func:`insnav.run`) the
    run is made with the state, and the estimate is tested against ``t_d = 0``
    (Wald test, ``z = t_d^ / sigma`` at the end of the run against the
    two-sided normal quantile of ``auto_false_alarm``): a significant estimate
    keeps that run, else the run without the state is returned, bit for bit
    (docs/algorithms.md section 21).  ``Solution.summary["time_offset_test"]``
    holds the estimate, its sigma, ``z``, the threshold and the decision.

    Attributes
    ----------
    estimate_offset : bool or "auto"
        Estimate ``t_d`` (default false: the layouts and results without it);
        ``"auto"``: estimate it and keep the state only if the estimate is
        significant.
    auto_false_alarm : float
        ``"auto"`` only: the probability of keeping the state when the true
        offset is zero (default 0.01: ``|z| > 2.576``), in (0, 0.5].
    offset_sigma_ms : float
        Initial 1-sigma of ``t_d`` [ms] (default 100).
    initial_offset_ms : float
        Initial estimate of ``t_d`` [ms] (default 0).
    offset_psd_ms2_per_s : float
        Random-walk PSD of ``t_d`` [ms^2/s] (default 0: a random constant;
        e.g. 0.01 lets it wander 6 ms in an hour).
    """

    TABLE = "time"
    estimate_offset: bool | str = False
    auto_false_alarm: float = 0.01
    offset_sigma_ms: float = 100.0
    initial_offset_ms: float = 0.0
    offset_psd_ms2_per_s: float = 0.0

    def validate(self, source: str | None = None) -> "TimeOffset":
        """Check the values; a one-line ConfigError naming ``time.<key>`` (prefixed by ``source`` if given)."""
        with _prefixed(source):
            if self.estimate_offset != "auto":
                v = self.estimate_offset
                if not isinstance(v, (bool, np.bool_)):
                    raise ConfigError(f"config key 'time.estimate_offset': bad value {v!r}; allowed: true, false "
                                      "or \"auto\"")
            _check_number(self, "auto_false_alarm", "time", lo=0.0, strict=True)
            if self.auto_false_alarm > 0.5:
                raise ConfigError(f"config key 'time.auto_false_alarm': bad value {self.auto_false_alarm!r}; "
                                  "allowed: a probability in (0, 0.5]")
            _check_number(self, "offset_sigma_ms", "time", lo=0.0, strict=True)
            _check_number(self, "initial_offset_ms", "time")
            _check_number(self, "offset_psd_ms2_per_s", "time", lo=0.0)
        return self


@dataclass
class LeverArmEstimation(TomlTable):
    """The GNSS antenna lever arm as filter states (``[lever_arm]`` in the run
    TOML; docs/algorithms.md "Self-calibration states").

    The states start from the run's lever arm (``lever_arm_b``, else the
    dataset's) and are observable only with attitude changes (turns); the
    estimate and its 1-sigma are ``Solution.lever_arm_b_m`` /
    ``sigma_lever_arm_b_m``.

    Attributes
    ----------
    estimate : bool
        Estimate the lever arm (default false).
    sigma_m : float
        Initial 1-sigma of each component [m] (default 0.5).
    psd_m2_per_s : float
        Random-walk PSD of each component [m^2/s] (default 0: random
        constants); also that of the odometer lever arm.
    estimate_odometer : bool
        Estimate the lever arm of the vehicle constraints' point (IMU -> the
        rear-axle centre, ``[constraints] lever_arm_b_m``) instead (loose EKF
        with ``[constraints] use`` nhc and/or odo; 18 states; not together
        with ``estimate`` or ``[time] estimate_offset``).  Observable in turns.
        ``Solution.odo_lever_arm_b_m`` / ``sigma_odo_lever_arm_b_m``.
    odometer_sigma_m : float
        Initial 1-sigma of each component of the odometer lever arm [m] (default 0.5).
    """

    TABLE = "lever_arm"
    estimate: bool = False
    sigma_m: float = 0.5
    psd_m2_per_s: float = 0.0
    estimate_odometer: bool = False
    odometer_sigma_m: float = 0.5

    def validate(self, source: str | None = None) -> "LeverArmEstimation":
        """Check the values; a one-line ConfigError naming ``lever_arm.<key>`` (prefixed by ``source`` if given)."""
        with _prefixed(source):
            _check_flag(self, "estimate", "lever_arm")
            _check_number(self, "sigma_m", "lever_arm", lo=0.0, strict=True)
            _check_number(self, "psd_m2_per_s", "lever_arm", lo=0.0)
            _check_flag(self, "estimate_odometer", "lever_arm")
            _check_number(self, "odometer_sigma_m", "lever_arm", lo=0.0, strict=True)
        return self


#: the self-calibration tables of a run (RunConfig fields, TOML tables of the same names)
_SELFCAL_TABLES = (("time", TimeOffset), ("lever_arm", LeverArmEstimation))


class _prefixed:
    """Prefix a ConfigError raised inside the block with ``source: `` (no-op for None)."""

    def __init__(self, source: str | None):
        self.source = source

    def __enter__(self):
        return self

    def __exit__(self, typ, exc, tb):
        if exc is not None and isinstance(exc, ConfigError) and self.source:
            raise ConfigError(f"{self.source}: {exc}") from None
        return False


def _check_flag(obj, key: str, table: str) -> None:
    v = getattr(obj, key)
    if not isinstance(v, (bool, np.bool_)):
        raise ConfigError(f"config key '{table}.{key}': bad value {v!r}; allowed: true or false")


def _check_number(obj, key: str, table: str, lo: float | None = None, strict: bool = False) -> None:
    v = getattr(obj, key)
    ok = not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(v)
    if ok and lo is not None:
        ok = v > lo if strict else v >= lo
    if not ok:
        bound = "" if lo is None else f" {'>' if strict else '>='} {lo:g}"
        raise ConfigError(f"config key '{table}.{key}': bad value {v!r}; allowed: a finite number{bound}")


#: limits of the input repairs (insnav.filters.sanitize; [sanitize] in the TOML overrides them):
#: beyond the full scale of automotive, aerial and tactical IMUs; max_gap_s is the longest IMU gap bridged
SANITIZE_DEFAULTS = dict(max_gap_s=0.1, gap_factor=1.5, max_rate_rps=2000.0 * DEG, max_accel_mps2=100.0 * G0,
                         min_h_m=-2000.0, max_h_m=100_000.0)

#: vehicle constraints a run can use ([constraints] use = [...]); "zupt" brings ZARU with it
CONSTRAINT_NAMES = ("nhc", "odo", "zupt")


@dataclass
class Constraints:
    """Vehicle constraints as measurement updates (``[constraints]`` in the
    TOML; ``cpp/include/insnav/meas/vehicle.hpp``).  Loose coupling with the
    EKF, RB-UKF or UKF.

    Attributes
    ----------
    use : list of {'nhc', 'odo', 'zupt'}
        ``nhc``: the lateral and vertical velocity of the rear-axle point are
        zero; ``odo``: its forward speed is the odometer's (the dataset's
        ``odometer.csv``); ``zupt``: while the IMU stands still (test
        statistic of ``ins/standstill.hpp`` below ``zupt_threshold``) zero
        velocity and zero angular rate instead.
    rate_hz : float
        Update rate of ZUPT and of the odometer (its own samples decimated to
        this rate when ``odo``).
    nhc_rate_hz : float or None
        Update rate of NHC, at most ``rate_hz`` (NHC on every k-th event of
        the ``rate_hz`` grid or of the odometer updates).  None (default):
        1 Hz on its own, every odometer update with ``odo``.  Slip and bounce
        are correlated over seconds, so NHC updates closer than that are not
        independent: treated as white noise at 10 Hz on their own they make
        the outage drift larger, the more so the smaller ``sigma_nhc_mps``;
        with the odometer pinning the forward speed, 10 Hz and 1 Hz are within
        a few percent of each other (docs/results/vehicle_constraints.md,
        "NHC rate and noise").
    sigma_nhc_mps, sigma_odo_mps, sigma_zupt_mps : float
        Measurement noise [m/s] of one update: lateral slip and vertical
        bounce; odometer speed; standstill.  Slip and the odometer's
        scale-factor error (when no state estimates it) are correlated over
        seconds, so at 10 updates per second each update counts for less
        than its own noise.  ``sigma_odo_mps`` None (default): 0.5 m/s
        without the scale-factor state (``odo_scale``), 0.16 m/s over one
        second, what a 2000 ppm scale error at 20 m/s and 0.05 m/s of
        quantisation noise call for; 0.1 m/s with the state, which takes the
        scale error out of the readings and leaves quantisation, the
        odometer's lever-arm motion and slip
        (docs/results/vehicle_constraints.md).
    sigma_zaru_dph : float
        Zero-angular-rate noise [deg/h].
    lever_arm_b_m : 3 floats or None
        IMU -> the point that does not slip (the rear-axle centre of a real
        car; also where the odometer speed holds), body axes FRD [m]; None:
        zero (the IMU itself: where the simulator's car presets hold it).
    mounting_rpy_deg : 3 floats
        Rotation vehicle -> IMU body (3-2-1 Euler angles) [deg]; zero for an aligned IMU.
    zupt_window_s, zupt_threshold, zupt_sigma_f_mps2, zupt_sigma_w_dps : float
        The standstill detector: window [s], threshold on the statistic (its
        mean is about 6 at standstill), per-sample specific-force [m/s^2] and
        rate [deg/s] noise including idle vibration.
    gate_chi2 : float
        NIS gate of the constraint updates (0 = off).
    second_order_corr_s : float
        Correlation time [s] of the attitude x velocity error product that
        the NHC and odometer rows of the EKF and RB-UKF leave out of H (its
        covariance is added to R, scaled by ``max(1, second_order_corr_s /
        event interval)``; ``meas/vehicle.hpp``, docs/algorithms.md); 0: as
        white noise.  Default 1 s.
    odo_scale : bool or "auto"
        Estimate the odometer's scale-factor error ``s`` (reading = (1 + s)
        true forward speed) as a filter state: the 16-state layout (the 15
        states + ``s``, ``cpp/include/insnav/filter/layout.hpp``
        ``Layout16Odo``), fed back into the odometer readings like the IMU
        biases into the IMU data.  ``"auto"`` (default): on whenever ``odo``
        is used on the 15-state layout; ``true`` needs ``odo`` and
        ``layout = 15``; ``false``: the raw readings, the scale error left to
        ``sigma_odo_mps``.
    odo_scale_sigma : float
        Initial 1-sigma of ``s`` [-] (0.01 = 10000 ppm), also the steady-state
        sigma of its Gauss-Markov model when ``odo_scale_tau_s`` is set.
    odo_scale_tau_s : float or None
        Correlation time of ``s`` [s] (first-order Gauss-Markov,
        ``s' = -s / tau + w``, e.g. for tyre wear and temperature); None
        (default): a random constant.
    standstill_q_scale : float
        Standstill level of the process noise: while the standstill detector
        (the ``zupt_*`` settings above) says the IMU stands still, the
        velocity and angle random walk PSDs are multiplied by this factor
        (``cpp/include/insnav/engine/loose_engine.hpp``): a noise tuned on
        motion (a walker's gait and hand swing) describes errors that are
        absent at rest.  1 (default): off.  Loose and tight EKF (tight: the
        detector's state at each epoch holds to the next,
        ``engine/tight_engine.hpp``); needs no ``use`` entry (the detector
        runs for it alone); insnav.calib.tune's factor ``standstill_q``.
    """

    use: list = field(default_factory=list)
    rate_hz: float = 10.0
    nhc_rate_hz: float | None = None
    sigma_nhc_mps: float = 0.1
    sigma_odo_mps: float | None = None
    sigma_zupt_mps: float = 0.01
    sigma_zaru_dph: float = 20.0
    lever_arm_b_m: list | None = None
    mounting_rpy_deg: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    zupt_window_s: float = 0.2
    zupt_threshold: float = 18.0
    zupt_sigma_f_mps2: float = 0.02
    zupt_sigma_w_dps: float = 0.115
    gate_chi2: float = 0.0
    second_order_corr_s: float = 1.0
    odo_scale: bool | str = "auto"
    odo_scale_sigma: float = 0.01
    odo_scale_tau_s: float | None = None
    standstill_q_scale: float = 1.0

    #: default NHC rate without the odometer [Hz]
    NHC_RATE_HZ_DEFAULT = 1.0
    #: default odometer sigma per update [m/s]: without / with the scale-factor state
    SIGMA_ODO_MPS_DEFAULT = (0.5, 0.1)

    def nhc_rate(self, grid_hz: float) -> float:
        """NHC's update rate [Hz] on an event grid of ``grid_hz``: ``nhc_rate_hz``, or its default (see above)."""
        if self.nhc_rate_hz is not None:
            return float(self.nhc_rate_hz)
        return grid_hz if "odo" in self.use else min(grid_hz, self.NHC_RATE_HZ_DEFAULT)

    def odo_sigma_mps(self, layout: int = 15) -> float:
        """The odometer's per-update sigma [m/s]: ``sigma_odo_mps``, or its default (see above)."""
        if self.sigma_odo_mps is not None:
            return float(self.sigma_odo_mps)
        return self.SIGMA_ODO_MPS_DEFAULT[int(self.odo_scale_state(layout))]

    def odo_scale_state(self, layout: int = 15) -> bool:
        """True when the run estimates the odometer scale factor (``odo_scale``, see above)."""
        if self.odo_scale == "auto":
            return "odo" in self.use and layout == 15
        return bool(self.odo_scale)

    def validate(self, prefix: str = "constraints") -> "Constraints":
        def bad(key, value, allowed):
            raise ConfigError(f"config key '{prefix}.{key}': bad value {value!r}; allowed: {allowed}")

        use = self.use
        if isinstance(use, str):
            use = [u.strip() for u in use.split(",") if u.strip()]
        if not isinstance(use, (list, tuple)) or any(u not in CONSTRAINT_NAMES for u in use):
            bad("use", self.use, f"a list of {', '.join(CONSTRAINT_NAMES)}")
        self.use = list(dict.fromkeys(use))
        for key in ("rate_hz", "nhc_rate_hz", "sigma_nhc_mps", "sigma_odo_mps", "sigma_zupt_mps", "sigma_zaru_dph", "zupt_window_s",
                    "zupt_threshold", "zupt_sigma_f_mps2", "zupt_sigma_w_dps"):
            v = getattr(self, key)
            if v is None and key in ("sigma_odo_mps", "nhc_rate_hz"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                bad(key, v, "a number > 0")
        if self.nhc_rate_hz is not None and self.nhc_rate_hz > self.rate_hz:
            bad("nhc_rate_hz", self.nhc_rate_hz, f"a number > 0 and at most rate_hz ({self.rate_hz:g})")
        v = self.gate_chi2
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            bad("gate_chi2", v, "a number >= 0 (0 = off)")
        v = self.second_order_corr_s
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            bad("second_order_corr_s", v, "a number >= 0 [s] (0 = white)")
        v = self.standstill_q_scale
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
            bad("standstill_q_scale", v, "a number > 0 (1 = off)")
        for key in ("lever_arm_b_m", "mounting_rpy_deg"):
            if key == "lever_arm_b_m" and self.lever_arm_b_m is None:
                continue
            try:
                a = np.asarray(getattr(self, key), dtype=float)
            except (TypeError, ValueError):
                a = np.full(1, np.nan)
            if a.shape != (3,) or not np.all(np.isfinite(a)):
                bad(key, getattr(self, key), "3 finite numbers")
        if not (isinstance(self.odo_scale, (bool, np.bool_)) or self.odo_scale == "auto"):
            bad("odo_scale", self.odo_scale, 'true, false or "auto"')
        if self.odo_scale is True and "odo" not in self.use:
            bad("odo_scale", self.odo_scale, "true only with 'odo' in constraints.use")
        v = self.odo_scale_sigma
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v < 1):
            bad("odo_scale_sigma", v, "a number in (0, 1) (1-sigma of the scale factor, 0.01 = 10000 ppm)")
        v = self.odo_scale_tau_s
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0)):
            bad("odo_scale_tau_s", v, "a number > 0 [s] (inf or absent: random constant)")
        return self


@dataclass
class Robust:
    """Robust tight update (``[robust]`` in the TOML;
    ``cpp/include/insnav/meas/robust.hpp``).  Every test is on the predicted
    innovation ``y_i`` of one satellite's pseudorange or rate row against its
    predicted variance ``S_ii = H_i P H_i' + R_ii`` (``w_i = y_i / sqrt(S_ii)``).

    Attributes
    ----------
    screening : bool or None
        Per-row chi-square screening with IGG-III (or Huber) down-weighting
        (Yang, Song & Xu 2002, J. Geodesy 76) in the epochs it flags, the
        whole-epoch fault exclusion and the CUSUM below (an unflagged epoch
        is always the plain update).  None (default): on, unless the
        dataset's simulator preset says ``[run] robust_screening = false``
        (the seed-paper presets, whose filters are the plain ones).
    chi2_row : float
        Threshold on ``w_i^2`` (1-dof chi-square; 10.83 = the 1 - 1e-3
        quantile): a row above it flags the epoch and is rejected.
    igg_k0, igg_k1 : float
        IGG-III limits on ``|w_i|`` in a flagged epoch: full weight up to
        ``k0`` (1.5), ``R_ii`` inflated between, rejected beyond ``k1`` (3.0).
    clock_jump : bool
        Move a common offset of all pseudorange innovations (a receiver clock
        reset, e.g. 1 ms = 299792.458 m) into the clock estimate instead of
        rejecting every satellite (on by default).
    clock_jump_sigma : float
        The offset is a jump when its median exceeds this many median
        ``sqrt(S_ii)`` (10) and at least half of the rows agree with it.
    clock_jump_min_rows : int
        Pseudorange rows an epoch needs for the check (3).
    huber : bool
        Huber weights ``q = min(1, huber_k / |w|)`` instead of IGG-III (off).
    huber_k : float
        Huber: full weight up to ``|w| = huber_k`` (1.5).
    fde_max_sats : int
        Whole-epoch fault detection and exclusion (meas/robust.hpp, 3.): when
        the epoch still fails the gate, the satellite with the largest w-test
        statistic (Teunissen 1990) is excluded and the epoch re-tested, up to
        this many satellites per epoch (2; 0 = off).
    fde_min_rows : int
        ... while more than this many rows remain (8).
    cusum_k, cusum_h : float
        Two-sided CUSUM per satellite and row kind on the standardized
        innovation (Page 1954), for slow faults such as a pseudorange ramp:
        drift ``k`` (0.5) and alarm threshold ``h`` (8; 0 = off).
    cusum_hold_s : float
        An alarm excludes that satellite's row this long [s] (60).
    cusum_min_pseudoranges : int
        The CUSUM acts only in epochs with at least this many pseudoranges
        (4: with fewer, position and clock are not pinned by the epoch and
        the filter's coasting drift shows on every satellite alike).
    variance_window : int
        Variance factor before the tests (meas/robust.hpp, 0.): per row kind
        the smallest ``f >= 1`` with ``median(y^2 / (H P H^T + f R)) <= 0.4549``
        (the median of chi-square with 1 dof) over the rows of this many
        epochs scales ``R`` of the epoch, so that data noisier than their
        sigma are weighted as such instead of failing the tests on good
        satellites (10; 0 = off; at most 30).
    variance_min_rows : int
        ... rows of a kind the window needs (4).
    """

    screening: bool | None = None
    chi2_row: float = 10.83
    igg_k0: float = 1.5
    igg_k1: float = 3.0
    clock_jump: bool = True
    clock_jump_sigma: float = 10.0
    clock_jump_min_rows: int = 3
    huber: bool = False
    huber_k: float = 1.5
    fde_max_sats: int = 2
    fde_min_rows: int = 8
    cusum_k: float = 0.5
    cusum_h: float = 8.0
    cusum_hold_s: float = 60.0
    cusum_min_pseudoranges: int = 4
    variance_window: int = 10
    variance_min_rows: int = 4

    def validate(self, prefix: str = "robust") -> "Robust":
        def bad(key, value, allowed):
            raise ConfigError(f"config key '{prefix}.{key}': bad value {value!r}; allowed: {allowed}")

        for key in ("screening", "clock_jump", "huber"):
            if key == "screening" and self.screening is None:
                continue
            if not isinstance(getattr(self, key), (bool, np.bool_)):
                bad(key, getattr(self, key), "true or false")
        for key in ("chi2_row", "igg_k0", "igg_k1", "clock_jump_sigma"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                bad(key, v, "a number > 0")
        if not self.igg_k1 > self.igg_k0:
            bad("igg_k1", self.igg_k1, f"a number > igg_k0 = {self.igg_k0}")
        v = self.clock_jump_min_rows
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            bad("clock_jump_min_rows", v, "an integer >= 1")
        for key in ("fde_max_sats", "fde_min_rows", "cusum_min_pseudoranges"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                bad(key, v, "an integer >= 0")
        v = self.variance_window
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= 30:
            bad("variance_window", v, "an integer in 0 .. 30 (epochs; 0: off)")
        v = self.variance_min_rows
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            bad("variance_min_rows", v, "an integer >= 1")
        for key in ("cusum_k", "cusum_h", "cusum_hold_s"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                bad(key, v, "a number >= 0")
        return self

    def as_core_dict(self, dataset=None) -> dict:
        """The ``robust_*`` keys of the tight engine config (``screening``
        None: on unless ``dataset``'s simulator preset sets ``[run]
        robust_screening = false``)."""
        d = {f"robust_{f.name}": getattr(self, f.name) for f in dataclasses.fields(self)}
        if self.screening is None:
            run = (getattr(dataset, "scenario", None) or {}).get("run", {})
            d["robust_screening"] = bool(run.get("robust_screening", True))
        return d


@dataclass
class Tdcp:
    """Time-differenced carrier phase in the tight EKF (``[tdcp]`` in the TOML,
    ``--tdcp``; ``cpp/include/insnav/meas/tdcp.hpp``, docs/algorithms.md
    "TDCP/INS").  Off by default.

    Attributes
    ----------
    enabled : bool
        Add a TDCP row per satellite tracked at two consecutive epochs
        (stochastic cloning of the previous epoch's error state, Roumeliotis
        & Burdick 2002); needs carrier phase in the tight inputs (RINEX data:
        ``insnav run --format rinex``) and the tight ``ekf``; with ``smooth``
        the RTS smoother runs over the cloned epochs.
        With ``[time] estimate_offset`` or ``[lever_arm] estimate`` the rows
        carry the time-offset and lever-arm columns (each the difference of
        the two epochs' range columns, meas/tdcp.hpp).
    sigma_phase_m : float
        Zero-difference carrier-phase 1-sigma at zenith [m], divided by
        sin(elevation) (floor 5 deg); a TDCP row's variance is the sum of its
        two epochs' (0.01 m: consumer receiver and antenna, multipath and the
        unmodelled correlation of consecutive rows included).
    slip_threshold_cycles : float
        INS-aided slip test: a row whose INS-predicted minus measured phase
        change, less the epoch's common (receiver clock) part, exceeds this
        many cycles is a slip (0.5).
    chi2_row : float
        Per-row chi-square on ``w^2 = y^2 / S_ii`` under the clone-augmented
        covariance (10.83: 1 - 1e-3, 1 dof).
    """

    enabled: bool = False
    sigma_phase_m: float = 0.01
    slip_threshold_cycles: float = 0.5
    chi2_row: float = 10.83

    def validate(self, prefix: str = "tdcp") -> "Tdcp":
        if not isinstance(self.enabled, (bool, np.bool_)):
            raise ConfigError(f"config key '{prefix}.enabled': bad value {self.enabled!r}; allowed: true or false")
        for key in ("sigma_phase_m", "slip_threshold_cycles", "chi2_row"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ConfigError(f"config key '{prefix}.{key}': bad value {v!r}; allowed: a number > 0")
        return self

    def as_core_dict(self) -> dict:
        """The ``tdcp*`` keys of the tight engine config."""
        return dict(tdcp=bool(self.enabled), tdcp_slip_threshold_cycles=float(self.slip_threshold_cycles),
                    tdcp_chi2_row=float(self.chi2_row))


@dataclass
class RunConfig:
    """Everything a run needs besides the data (SI unless the name says otherwise).

    Attributes
    ----------
    filter : {'ekf', 'rbukf', 'ukf'}
    coupling : {'loose', 'tight', 'rtk'}
        (``rtk``: tight RTK/INS, ``insnav.filters.rtk_ins``; ``gnss``: the GNSS-only filters)
    layout : {15, 21, 17, 20}
        The error-state layout (:attr:`insnav.registry.CouplingFacts.layouts`).
        Loose: 15 states (seed 000) or 21 with scale factors (KF-GINS-like).
        Tight: 17 (one receiver clock, seed 003) or 20 (+ the inter-system
        biases of GLONASS, Galileo, BeiDou); the default 15 lets the data
        choose: 17 when every satellite row is GPS, else 20, and the resolved
        configuration a run writes names the one it ran (the seed 004 filters
        run on their own 20 states).  GNSS-only filters: the default (no INS).
    init_sigma_pos_m, init_sigma_vel_mps, init_sigma_att_deg : 3 floats
        Initial 1-sigma of position (N, E, D), velocity, roll/pitch/yaw.
    init_error : bool or "auto"
        Draw the initial state error from those sigmas (``init_seed``), as in
        a Monte Carlo run; otherwise start from the given initial state.
        ``"auto"`` (default): draw only when the dataset's initial state is the
        simulator's truth (``Dataset.initial_is_truth``); a state the user gives
        (dataset.json, KF-GINS, RINEX, CSV) is taken as given.
    imu : ImuNoise or None
        None: derived from the dataset's IMU model.
    lever_arm_b : 3 floats or None
        IMU -> antenna in FRD [m]; None: the dataset's.
    gate_prob : float or None
        Innovation gate of the GNSS records, on by default: a record (loose
        fix or tight epoch) whose NIS exceeds the chi-square quantile of its
        row count at this probability is rejected (0.9999: 27.86 for a
        position + velocity fix, 21.11 for position only; 0 = off).  None
        (default): the dataset's preset default (``[run] gate_prob`` of a
        simulator preset: 0 for the seed-paper presets, whose filters have no
        gate), else ``GATE_PROB_DEFAULT`` = 0.9999.
    gate_chi2 : float or None
        A fixed NIS threshold for every row count instead of the quantile
        (0 = no gate at all; None, the default: ``gate_prob``).
    gate_reopen_after : int
        Lock-out recovery (default 5; 0 = never): after this many rejected
        records in a row the next one, if the gate rejects it too, is applied
        with the covariance scaled by NIS / rows (nis_gate.hpp), so a filter
        whose covariance became too small follows the GNSS again instead of
        diverging.  A lasting fault is then taken in whole too (tight runs:
        the ``[robust]`` per-satellite screening removes it first); the run
        summary counts these records as ``gate_reopened``.
    gate_mismatch : float
        Outage-aware test (nis_gate.hpp; default 25, <= 1 = off): when no
        record was applied for ``gate_outage_s``, a record is tested against
        ``S = gate_mismatch * H P H' + R`` (an IMU whose real noise is up to
        5x the configured one) and, if it passes, applied as the plain
        update.  The first fixes after an outage then end the drift instead
        of being rejected, and the smoother carries them into the outage
        (docs/results/gate_outages.md); in steady state the gate is unchanged.
    gate_outage_s : float
        Time without an applied record after which the outage-aware test is
        used [s] (default 2).
    use_position, use_velocity : bool
    gnss_pos_sigma_scale, gnss_vel_sigma_scale : float
        Factors on the GNSS measurement sigmas the data give (default 1):
        loose runs, the position and the velocity sigmas of each fix; tight
        runs, the pseudorange and the pseudorange-rate sigmas of each
        satellite row.  ``insnav tune`` estimates them
        (:mod:`insnav.calib.tune`).
    gnss_pos_v_sigma_scale : float
        Loose runs: a further factor on the down (vertical) position sigma of
        each fix, on top of ``gnss_pos_sigma_scale`` (default 1: the data's
        ratio of vertical to horizontal sigma).  A receiver's or a sigma
        floor's vertical-to-horizontal ratio is often not the error's (the
        vertical error is larger: no satellite below the horizon, VDOP >
        HDOP; Misra & Enge 2006, *Global Positioning System*, on DOP);
        ``insnav tune`` estimates it (``gnss_pos_v``).  Tight runs: must be 1.
    gnss_pos_sigma_per_speed_s, gnss_vel_sigma_per_speed : float
        Loose runs: a motion-dependent term of the GNSS sigmas, added in
        quadrature to the data's (scaled) sigma of every axis of each fix,
        ``sigma^2 = (scale sigma_data)^2 + (k |v_h|)^2`` with ``|v_h|`` the
        fix's own horizontal speed [m/s] (``k`` in s for the position rows,
        dimensionless for the velocity rows; default 0: none).  A hand-held or
        body-worn receiver's fixes are as good as its own sigmas say while it
        stands, and worse while it moves (gait and hand motion the receiver's
        solution smooths and the INS-to-fix time alignment turns into errors
        proportional to the motion; Groves 2013, *Principles of GNSS, Inertial,
        and Multisensor Integrated Navigation Systems*, 2nd ed., sec. 14.3.2
        on measurement-noise models that depend on the host's dynamics): a
        constant floor describes one of the two.  ``insnav tune`` estimates
        the factors ``gnss_pos_speed`` and ``gnss_vel_speed`` on them when
        they are > 0.  Tight runs: must be 0.
    adaptive_r_window : int
        Loose EKF and RB-UKF: innovation-based adaptive measurement noise of
        the GNSS rows (``cpp/include/insnav/filter/adaptive_noise.hpp``;
        Mohamed & Schwarz 1999, *Adaptive Kalman filtering for INS/GPS*, J.
        Geodesy 73: R = C_v - H P- H', C_v the innovation covariance over a
        window).  Each row's configured variance (the data's sigma with the
        factors and terms above) is multiplied by
        ``clamp(sum(nu^2 - H P- H') / sum(R), adaptive_r_min_fraction, 1)``
        over the last ``adaptive_r_window`` applied fixes with that row (not
        the current one); the configured R until the window is full.  R never
        exceeds the configured value: measurement noise larger than
        configured is not followed.  0 (default): off, the configured R.
        At most 256.
    adaptive_r_min_fraction : float
        Lower clamp of that factor (variance; default 0.01: sigma 0.1x the
        configured), in (0, 1].
    adaptive_q_window : int
        Loose and tight EKF (batch runs): adaptive process noise
        (``cpp/include/insnav/filter/adaptive_noise.hpp``; Mohamed & Schwarz
        1999, Q^ = K C_v K' over a window of updates).  The configured
        velocity and angle random walk variances (``acc_vrw``, ``gyro_arw``)
        are each multiplied by ``clamp(sum a_j |dx_b|^2 / sum tr(P- - P+)_bb,
        adaptive_q_min, adaptive_q_max)`` over the last ``adaptive_q_window``
        applied fixes (tight: epochs; dx the update's state correction, a_j
        the factor it ran with); the configured Q until the window is full.
        0 (default): off.  At most 256.
    adaptive_q_min, adaptive_q_max : float
        Bounds of those factors (variance; defaults 0.05 and 20): the
        estimate feeds back through the gain, the lower bound keeps the
        filter from collapsing.  0 < min <= 1 <= max.
    pr_gm_sigma_m, pr_gm_tau_s, pr_gm_max_gap_s : float
        Tight EKF: time-correlated pseudorange errors (multipath, ionosphere
        and troposphere residuals) as one first-order Gauss-Markov state per
        satellite (``cpp/include/insnav/meas/pseudorange_gm.hpp``, Gelb 1974;
        docs/algorithms.md "Gauss-Markov pseudorange errors"): stationary
        1-sigma [m] (default 0: no such states, the filter as without them),
        correlation time [s] (60) and the time after which the state of a
        satellite no longer seen is dropped [s] (10; a later re-acquisition
        starts a new state).  The row's own sigma stays its white part.
        Not with ``smooth`` or ``[tdcp]``.
    propagation_interval_s : float
        Error-state propagation step inside a filter cycle (default 0.1 s:
        on the KF-GINS track 0.02 s to 0.5 s give the same accuracy to 0.1 mm).
    cycle_period_s : float or None
        Filter cycle without GNSS (outage); None: the median GNSS interval.
    output_decimation : int
        Keep every k-th IMU-rate output row.
    ut_alpha, ut_beta, ut_kappa : float
        Unscented-transform parameters (kappa None: 3 - n, seed 000).
    constraints : Constraints
        Vehicle constraints (NHC, odometer, ZUPT/ZARU; none by default).
    robust : Robust
        Tight coupling: clock-jump check, per-satellite screening with IGG-III
        or Huber down-weighting, whole-epoch fault exclusion and the CUSUM of
        slow faults (``[robust]``; on by default except for the seed-paper
        presets).
    smooth : bool
        Post-process with the RTS smoother (EKF; RB-UKF and UKF: the unscented
        RTS smoother, Sarkka 2008; loose, tight with or without TDCP, and
        RTK/INS, whose fixed epochs keep the fixed solution): every output
        row and sigma, and a tight run's receiver clock and inter-system biases,
        from all the data, before and after it.
    init_acc_bias_mps2, init_gyro_bias_radps, init_acc_scale, init_gyro_scale : 3 floats or None
        Initial estimate of the IMU errors (measured minus true; scale factors
        [-]); None: zero.  KF-GINS's ``initaccbias``/``initgyrbias``/
        ``initaccscale``/``initgyrscale``.  Loose runs; the bias keys also
        tight runs.
    init_sigma_acc_bias_mps2, init_sigma_gyro_bias_radps, init_sigma_acc_scale, init_sigma_gyro_scale : 3 floats or None
        Initial 1-sigma of those states; None: the IMU noise model's bias and
        scale-factor sigmas.  KF-GINS's ``initbastd``/``initbgstd``/
        ``initsastd``/``initsgstd``.  Loose runs; the bias keys also tight
        runs.
    imu_error_sigmas : bool
        Also keep the 1-sigma of the IMU-error states (biases, scale factors)
        for every output row (``Solution.sigma_imu_err``; loose runs).
        ``insnav run --out-format kfgins`` turns it on for ``KF_GINS_STD.txt``.
    max_time_offset_s : float
        Largest IMU/GNSS time offset accepted before the run [s] (default
        0.8; ``inf``: no check): the lag between the gyro heading and the
        GNSS course in the turns (:func:`insnav.data.checks.check_time_offset`).
    time : TimeOffset
        ``[time]``: the IMU-GNSS time offset as an EKF state
        (``estimate_offset``, ``offset_sigma_ms``, ...; :class:`TimeOffset`).
        A dict of its keys is accepted.
    lever_arm : LeverArmEstimation
        ``[lever_arm]``: the GNSS antenna (or the vehicle constraints') lever
        arm as EKF states (:class:`LeverArmEstimation`).  A dict is accepted.
    sanitize : dict
        Overrides of the input repairs' limits (``[sanitize]`` in the TOML;
        ``insnav.filters.sanitize.DEFAULTS``: ``max_gap_s``, ``gap_factor``,
        ``max_rate_rps``, ``max_accel_mps2``, ``min_h_m``, ``max_h_m``).
    options : dict
        ``[options]``: the filter family's own options (``--option KEY=VALUE``;
        :meth:`insnav.registry.FilterSpec.setting_options`, e.g.
        ``elevation_mask_deg`` for the tight filters, ``particles`` for the
        seed 004 filters, ``delay_p`` for the delay filters); the keyword
        options of :func:`insnav.run` override them.
    """

    filter: str = "ekf"
    coupling: str = "loose"
    layout: int = 15
    init_sigma_pos_m: list = field(default_factory=lambda: [2.0, 2.0, 3.0])
    init_sigma_vel_mps: list = field(default_factory=lambda: [0.1, 0.1, 0.1])
    init_sigma_att_deg: list = field(default_factory=lambda: [0.5, 0.5, 1.0])
    init_error: bool | str = "auto"
    init_seed: int = 0
    imu: ImuNoise | None = None
    lever_arm_b: list | None = None
    gate_prob: float | None = None
    gate_chi2: float | None = None
    gate_reopen_after: int = 5
    gate_mismatch: float = 25.0
    gate_outage_s: float = 2.0
    use_position: bool = True
    use_velocity: bool = True
    gnss_pos_sigma_scale: float = 1.0
    gnss_vel_sigma_scale: float = 1.0
    gnss_pos_v_sigma_scale: float = 1.0
    gnss_pos_sigma_per_speed_s: float = 0.0
    gnss_vel_sigma_per_speed: float = 0.0
    adaptive_r_window: int = 0
    adaptive_r_min_fraction: float = 0.01
    adaptive_q_window: int = 0
    adaptive_q_min: float = 0.05
    adaptive_q_max: float = 20.0
    pr_gm_sigma_m: float = 0.0
    pr_gm_tau_s: float = 60.0
    pr_gm_max_gap_s: float = 10.0
    propagation_interval_s: float = 0.1
    cycle_period_s: float | None = None
    output_decimation: int = 1
    ut_alpha: float = 1.0
    ut_beta: float = 2.0
    ut_kappa: float | None = None
    constraints: Constraints = field(default_factory=Constraints)
    robust: Robust = field(default_factory=Robust)
    tdcp: Tdcp = field(default_factory=Tdcp)
    smooth: bool = False
    max_time_offset_s: float = 0.8
    sanitize: dict = field(default_factory=dict)
    imu_error_sigmas: bool = False
    init_acc_bias_mps2: list | None = None
    init_gyro_bias_radps: list | None = None
    init_acc_scale: list | None = None
    init_gyro_scale: list | None = None
    init_sigma_acc_bias_mps2: list | None = None
    init_sigma_gyro_bias_radps: list | None = None
    init_sigma_acc_scale: list | None = None
    init_sigma_gyro_scale: list | None = None
    time: TimeOffset = field(default_factory=TimeOffset)
    lever_arm: LeverArmEstimation = field(default_factory=LeverArmEstimation)
    options: dict = field(default_factory=dict)

    @property
    def selfcal(self) -> bool:
        """True when the run estimates the time offset and/or the lever arm."""
        return bool(self.time.estimate_offset or self.lever_arm.estimate or self.lever_arm.estimate_odometer)

    def validate(self) -> "RunConfig":
        def bad(key, value, allowed):
            raise ConfigError(f"config key '{key}': bad value {value!r}; allowed: {allowed}")

        # types first (TOML gives any type): names str, numbers finite and not bool, flags bool;
        # an option table given as a dict (insnav.run(..., constraints={...})) is read as the TOML's
        for key, cls in _OPTION_TABLES:
            v = getattr(self, key)
            if isinstance(v, dict):
                setattr(self, key, _table_from_dict(key, v, cls, "run configuration"))
            elif not isinstance(v, cls):
                bad(key, v, f"a [{key}] table")
        for key, allowed in (("filter", FILTERS), ("coupling", COUPLINGS)):
            if not isinstance(getattr(self, key), str):
                bad(key, getattr(self, key), ", ".join(allowed))
        for key in ("init_seed", "gate_prob", "gate_chi2", "gate_reopen_after", "gate_mismatch", "gate_outage_s",
                    "propagation_interval_s",
                    "output_decimation", "ut_alpha", "ut_beta", "ut_kappa", "cycle_period_s"):
            v = getattr(self, key)
            if v is None and key in ("ut_kappa", "cycle_period_s", "gate_chi2", "gate_prob"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v):
                bad(key, v, "a finite number")
        for key in ("gnss_pos_sigma_scale", "gnss_vel_sigma_scale", "gnss_pos_v_sigma_scale"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not (math.isfinite(v) and v > 0):
                bad(key, v, "a finite number > 0 (factor on the data's GNSS sigmas)")
        for key in ("gnss_pos_sigma_per_speed_s", "gnss_vel_sigma_per_speed"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not (math.isfinite(v) and v >= 0):
                bad(key, v, "a finite number >= 0 (the GNSS sigma's term per unit of the fix's horizontal speed; "
                    "0: none)")
            if v != 0.0 and self.coupling != "loose":
                bad(key, v, f"0 with {self.coupling} coupling (it adds to the sigmas of loose fixes)")
        v = self.adaptive_r_window
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= 256:
            bad("adaptive_r_window", v, "an integer in 0..256 (GNSS records in the window; 0: off)")
        self.adaptive_r_window = int(v)
        v = self.adaptive_r_min_fraction
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(v) and 0 < v <= 1):
            bad("adaptive_r_min_fraction", v, "a number in (0, 1] (lower clamp of the adaptive R, fraction of "
                "the configured variance)")
        if self.adaptive_r_window and (self.coupling != "loose" or self.filter not in ("ekf", "rbukf")):
            bad("adaptive_r_window", self.adaptive_r_window, f"0 with {self.coupling} {self.filter!r} (the adaptive "
                "measurement noise is the loose EKF's and RB-UKF's)")
        v = self.adaptive_q_window
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= 256:
            bad("adaptive_q_window", v, "an integer in 0..256 (GNSS updates in the window; 0: off)")
        self.adaptive_q_window = int(v)
        for key, ok, what in (("adaptive_q_min", lambda x: 0 < x <= 1, "a number in (0, 1]"),
                              ("adaptive_q_max", lambda x: x >= 1, "a finite number >= 1")):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not (math.isfinite(v) and ok(v)):
                bad(key, v, what + " (bound of the adaptive process-noise factor, variance)")
        if self.adaptive_q_window and (self.coupling not in ("loose", "tight") or self.filter != "ekf"):
            bad("adaptive_q_window", self.adaptive_q_window, f"0 with {self.coupling} {self.filter!r} (the adaptive "
                "process noise is the loose and tight EKF's: it scales the EKF's process noise)")
        if self.constraints.standstill_q_scale != 1.0 and (self.coupling not in ("loose", "tight")
                                                           or self.filter != "ekf"):
            bad("constraints.standstill_q_scale", self.constraints.standstill_q_scale, f"1 with {self.coupling} "
                f"{self.filter!r} (the standstill level scales the loose and tight EKF's process noise)")
        for key, low in (("pr_gm_sigma_m", 0.0), ("pr_gm_tau_s", None), ("pr_gm_max_gap_s", None)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v) or not (v >= 0.0 if low is not None else v > 0.0):
                bad(key, v, "a finite number >= 0 [m] (0: no Gauss-Markov pseudorange states)" if low is not None
                    else "a finite number > 0 [s]")
        if self.pr_gm_sigma_m > 0.0:
            if self.coupling != "tight" or self.filter != "ekf":
                bad("pr_gm_sigma_m", self.pr_gm_sigma_m, "0 unless coupling = \"tight\" and filter = \"ekf\" "
                    "(the Gauss-Markov pseudorange states are tight EKF states)")
            if self.smooth or getattr(self.tdcp, "enabled", False):
                bad("pr_gm_sigma_m", self.pr_gm_sigma_m, "0 with smooth or [tdcp] enabled")
        v = self.max_time_offset_s
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not v > 0:
            bad("max_time_offset_s", v, "a number > 0 [s] (inf: no check)")
        if int(self.init_seed) != self.init_seed or self.init_seed < 0:
            bad("init_seed", self.init_seed, "an integer >= 0")
        self.init_seed = int(self.init_seed)
        if not (isinstance(self.init_error, (bool, np.bool_)) or self.init_error == "auto"):
            bad("init_error", self.init_error, 'true, false or "auto"')
        for key in ("use_position", "use_velocity", "imu_error_sigmas"):
            if not isinstance(getattr(self, key), (bool, np.bool_)):
                bad(key, getattr(self, key), "true or false")
        if self.lever_arm_b is not None:
            try:
                la = np.asarray(self.lever_arm_b, dtype=float)
            except (TypeError, ValueError):
                la = np.full(1, np.nan)
            if la.shape != (3,) or not np.all(np.isfinite(la)):
                bad("lever_arm_b", self.lever_arm_b, "3 finite values [m]")
            from .data.checks import lever_arm_problem

            problem = lever_arm_problem(la)
            if problem:
                raise ConfigError(f"config key 'lever_arm_b': {self.lever_arm_b!r}: {problem}")
        if self.imu is not None and not isinstance(self.imu, ImuNoise):
            bad("imu", self.imu, "a table of IMU noise keys")
        if not isinstance(self.constraints, Constraints):
            bad("constraints", self.constraints, "a [constraints] table")
        self.constraints.validate()
        if not isinstance(self.robust, Robust):
            bad("robust", self.robust, "a [robust] table")
        self.robust.validate()
        if not isinstance(self.tdcp, Tdcp):
            bad("tdcp", self.tdcp, "a [tdcp] table")
        self.tdcp.validate()
        if self.tdcp.enabled and (self.coupling != "tight" or self.filter != "ekf"):
            bad("tdcp.enabled", True, f"true only with coupling = \"tight\" and filter = \"ekf\" "
                f"(not {self.coupling} {self.filter!r})")
        if not isinstance(self.sanitize, dict):
            bad("sanitize", self.sanitize, "a [sanitize] table")
        _SAN = SANITIZE_DEFAULTS
        for k, v in self.sanitize.items():
            if k not in _SAN:
                raise ConfigError(f"unknown key 'sanitize.{k}'{_suggest(k, _SAN)}")
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            if not ok or (k not in ("min_h_m", "max_h_m") and v <= 0) or (k == "gap_factor" and v <= 1):
                bad(f"sanitize.{k}", v, "a finite number" + ("" if k in ("min_h_m", "max_h_m") else
                                                               " > 1" if k == "gap_factor" else " > 0"))
        if not isinstance(self.smooth, (bool, np.bool_)):
            bad("smooth", self.smooth, "true or false")
        if self.constraints.odo_scale is True and self.layout != 15:
            bad("constraints.odo_scale", True, "true only with layout = 15 (the 16-state odometer layout "
                "is the 15 states + the scale factor)")
        for key, cls in _SELFCAL_TABLES:
            v = getattr(self, key)
            if isinstance(v, dict):
                v = cls.from_dict(v)
                setattr(self, key, v)
            if not isinstance(v, cls):
                bad(key, v, f"a [{key}] table")
            v.validate()
        if self.filter not in FILTERS:
            bad("filter", self.filter, ", ".join(FILTERS))
        if self.coupling not in COUPLINGS:
            bad("coupling", self.coupling, ", ".join(COUPLINGS))
        spec = FILTERS[self.filter]
        if self.coupling not in spec.couplings:
            bad("coupling", self.coupling, f"{' or '.join(spec.couplings)} (filter {self.filter!r})")
        if self.coupling == "rtk":  # RTK/INS reads carrier phase and code, no fixes, and screens them itself
            for key, default, label, why in (
                    ("gate_chi2", None, "absent", "the DD code rows are screened by [rtk_engine] code_chi2_row"),
                    ("gate_prob", None, "absent", "the DD code rows are screened by [rtk_engine] code_chi2_row"),
                    ("use_position", True, "true", "it reads no position fixes"),
                    ("use_velocity", True, "true", "it reads no velocity fixes"),
                    ("gnss_pos_sigma_scale", 1.0, "1", "it reads no position fixes: the [rtk] sigmas weight its rows"),
                    ("gnss_vel_sigma_scale", 1.0, "1", "it reads no velocity fixes")):
                v = getattr(self, key)
                if v is not default and v != default:
                    bad(key, v, f"{label} with rtk coupling ({why})")
            changed = next((f.name for f in dataclasses.fields(Robust) if getattr(self.robust, f.name) != f.default),
                           None)
            if changed is not None:
                bad(f"robust.{changed}", getattr(self.robust, changed), "absent with rtk coupling ([robust] is the "
                    "tight filter's; RTK/INS screens with [rtk_engine] robust_screening, robust_chi2_row, ...)")
        if self.coupling == "tight":  # pseudoranges and their rates, no fixes
            for key, option in (("use_position", "use_pseudorange"), ("use_velocity", "use_rate")):
                if getattr(self, key) is not True:
                    instead = (f"; the option is options.{option}"
                               if option in spec.setting_options(self.coupling) else "")
                    bad(key, getattr(self, key), f"true with tight coupling (it reads no fixes{instead})")
        if self.coupling != "loose" and self.gnss_pos_v_sigma_scale != 1.0:
            bad("gnss_pos_v_sigma_scale", self.gnss_pos_v_sigma_scale, f"1 with {self.coupling} coupling (it scales "
                "the vertical sigma of loose position fixes)")
        facts = spec.facts(self.coupling)
        if isinstance(self.layout, bool) or self.layout not in LAYOUTS or not (
                self.layout in facts.layouts or (self.layout == 15 and self.coupling != "loose")):
            allowed = ", ".join(map(str, facts.layouts)) or "absent (GNSS only: no INS states)"
            if self.coupling == "tight":
                allowed += " or absent (17 GPS-only, 20 with several systems: chosen from the data)"
            bad("layout", self.layout, f"{allowed} (filter {self.filter!r} {self.coupling})")
        if self.smooth and not facts.smoothable:
            where = ", ".join(f"{n} {c}" for n, s_ in FILTERS.items() for c in s_.smoothable)
            bad("smooth", self.smooth, f"false with filter {self.filter!r} {self.coupling} (the RTS smoother runs "
                                       f"with: {where})")
        if set(self.constraints.use) - set(facts.constraints):
            where = ", ".join(f"{n} {c}" for n, s_ in FILTERS.items() for c in s_.constraints)
            bad("constraints.use", self.constraints.use,
                f"vehicle constraints with {where} only (not {self.coupling} {self.filter!r})")
        if not isinstance(self.options, dict):
            bad("options", self.options, "an [options] table of the filter family's options")
        settable = spec.setting_options(self.coupling)
        for k in self.options:
            if k not in settable:
                raise ConfigError(f"unknown key 'options.{k}' for filter {self.filter!r} {self.coupling}"
                                  + (_suggest(k, settable) if settable else "; it takes no options"))
        if self.lever_arm.estimate_odometer:
            if not (set(self.constraints.use) & {"nhc", "odo"}):
                bad("lever_arm.estimate_odometer", True, "false without nhc or odo in constraints.use "
                    "(the odometer lever arm is seen through the vehicle constraints)")
            if self.time.estimate_offset or self.lever_arm.estimate:
                bad("lever_arm.estimate_odometer", True, "false together with time.estimate_offset or "
                    "lever_arm.estimate (no such layout)")
        for key, on in (("time.estimate_offset", self.time.estimate_offset),
                        ("lever_arm.estimate", self.lever_arm.estimate),
                        ("lever_arm.estimate_odometer", self.lever_arm.estimate_odometer)):
            if not on:
                continue
            if self.coupling not in spec.selfcal:
                where = ", ".join(f"{n} {c}" for n, s_ in FILTERS.items() for c in s_.selfcal)
                bad(key, on, f"false with filter {self.filter!r} {self.coupling} (the self-calibration states "
                             f"run with: {where})")
            if self.coupling == "loose" and self.layout != 15:
                bad(key, on, f"false with layout = {self.layout} (the self-calibration states extend the 15-state "
                             "layout: set layout = 15)")
            if self.constraints.use and self.constraints.odo_scale_state(self.layout):
                bad(key, on, "false with the odometer scale-factor state (set constraints.odo_scale = false)")
            if self.smooth:
                bad(key, on, "false with smooth = true (the RTS smoother does not run on these states)")
        for key in ("init_sigma_pos_m", "init_sigma_vel_mps", "init_sigma_att_deg"):
            try:
                v = np.asarray(getattr(self, key), dtype=float)
            except (TypeError, ValueError):
                bad(key, getattr(self, key), "3 finite values > 0")
            if v.shape != (3,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                bad(key, getattr(self, key), "3 finite values > 0")
        if not (self.propagation_interval_s > 0):
            bad("propagation_interval_s", self.propagation_interval_s, "> 0")
        if self.gate_chi2 is not None and self.gate_chi2 < 0:
            bad("gate_chi2", self.gate_chi2, ">= 0 (0 = off) or absent (the gate_prob quantile)")
        if self.gate_prob is not None and not 0 <= self.gate_prob < 1:
            bad("gate_prob", self.gate_prob, "0 <= p < 1 (0 = off)")
        if (int(self.gate_reopen_after) != self.gate_reopen_after or not 0 <= self.gate_reopen_after < 2 ** 31):
            bad("gate_reopen_after", self.gate_reopen_after, "an integer 0 .. 2147483647 (0 = never)")
        self.gate_reopen_after = int(self.gate_reopen_after)
        for key in ("gate_mismatch", "gate_outage_s"):
            if getattr(self, key) < 0:
                bad(key, getattr(self, key), "a number >= 0" + (" (<= 1: off)" if key == "gate_mismatch" else " [s]"))
        if self.cycle_period_s is not None and not self.cycle_period_s > 0:
            bad("cycle_period_s", self.cycle_period_s, "> 0 or absent")
        if int(self.output_decimation) != self.output_decimation or int(self.output_decimation) < 1:
            bad("output_decimation", self.output_decimation, "integer >= 1")
        if not (0 < self.ut_alpha <= 1):
            bad("ut_alpha", self.ut_alpha, "0 < alpha <= 1")
        for key in INIT_IMU_KEYS:
            v = getattr(self, key)
            if v is None:
                continue
            try:
                a = np.asarray(v, dtype=float)
            except (TypeError, ValueError):
                a = np.full(1, np.nan)
            sigma = key.startswith("init_sigma")
            if a.shape != (3,) or not np.all(np.isfinite(a)) or (sigma and np.any(a < 0)):
                bad(key, v, "3 finite values" + (" >= 0" if sigma else ""))
            if self.coupling != "loose" and not (self.coupling == "tight" and "bias" in key):
                bad(key, v, "absent: the initial IMU-error estimate and sigmas apply to loose runs (the bias "
                    "keys also to tight runs)")
            if "scale" in key and self.layout != 21:
                bad(key, v, "absent: scale factors are states of layout = 21 only")
        return self


def check_option_values(options) -> None:
    """A one-line ConfigError for an option value of another kind than the runner's
    default: a whole number (>= 0 unless the default is negative) where the default is an
    int (``particles = 2.7`` would be truncated), a finite number where it is a float,
    true/false where it is a bool, as many finite numbers where it is a tuple; and >= 0
    for a ``*sigma*`` option (a negative sigma would be squared into a positive one).
    Options whose default is None are the runner's to check."""
    import numbers

    def bad(name, value, allowed):
        raise ConfigError(f"option '{name}' = {value!r}: allowed: {allowed}")

    for f in dataclasses.fields(options):
        value, default = getattr(options, f.name), f.default
        if default is dataclasses.MISSING or default is None or value is default:
            continue
        positive = "sigma" in f.name
        if isinstance(default, bool):
            if not isinstance(value, (bool, np.bool_)):
                bad(f.name, value, "true or false")
        elif isinstance(default, numbers.Integral):  # negative only where the default is (-1: off)
            low = min(0, default)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real) \
                    or not math.isfinite(value) or value != int(value) or value < low:
                bad(f.name, value, f"a whole number >= {low} (default {default})")
        elif isinstance(default, numbers.Real):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real) \
                    or not math.isfinite(value) or (positive and value < 0):
                bad(f.name, value, f"a finite number{' >= 0' if positive else ''} (default {default})")
        elif isinstance(default, tuple) and all(isinstance(x, numbers.Real) for x in default):
            try:
                v = np.asarray(value, float)
            except (TypeError, ValueError):
                v = np.full(0, np.nan)
            if isinstance(value, (str, bool)) or v.shape != (len(default),) or not np.all(np.isfinite(v)) \
                    or (positive and np.any(v < 0)):
                bad(f.name, value, f"{len(default)} finite numbers{' >= 0' if positive else ''} "
                                   f"(default {list(default)})")


#: RunConfig keys of the initial IMU-error estimate and its sigmas, in the imu_correction order
INIT_IMU_KEYS = ("init_acc_bias_mps2", "init_gyro_bias_radps", "init_acc_scale", "init_gyro_scale",
                 "init_sigma_acc_bias_mps2", "init_sigma_gyro_bias_radps", "init_sigma_acc_scale",
                 "init_sigma_gyro_scale")

_USER_UNITS = {
    # TOML key in [imu] -> (field, factor to SI)
    "gyro_arw_deg_per_sqrt_h": ("gyro_arw", DEG_PER_SQRT_H),
    "acc_vrw_m_per_s_per_sqrt_h": ("acc_vrw", MPS_PER_SQRT_H),
    "acc_vrw_ug_per_sqrt_hz": ("acc_vrw", UG_PER_SQRT_HZ),
    "gyro_bias_sigma_deg_per_h": ("gyro_bias_sigma", DEG_PER_H),
    "acc_bias_sigma_mg": ("acc_bias_sigma", MG),
    "gyro_bias_tau_s": ("gyro_bias_tau", 1.0),
    "acc_bias_tau_s": ("acc_bias_tau", 1.0),
    # rate random walk of the bias (IEEE Std 952 K; insnav allan): deg/h/sqrt(h) -> rad/s/sqrt(s), mg/sqrt(h)
    "gyro_bias_rw_deg_per_h_per_sqrt_h": ("gyro_bias_rw", DEG_PER_H / 60.0),
    "acc_bias_rw_mg_per_sqrt_h": ("acc_bias_rw", MG / 60.0),
    "gyro_scale_sigma_ppm": ("gyro_scale_sigma", 1e-6),
    "acc_scale_sigma_ppm": ("acc_scale_sigma", 1e-6),
    "gyro_scale_tau_s": ("gyro_scale_tau", 1.0),
    "acc_scale_tau_s": ("acc_scale_tau", 1.0),
}


def _suggest(key: str, known) -> str:
    """'; did you mean 'x'?' for the closest known key, else the list of known keys."""
    known = sorted(known)
    close = close_matches(key, known)
    return f"; did you mean '{close[0]}'?" if close else f"; known keys: {', '.join(known)}"


#: the option tables of a run TOML that are RunConfig fields of their own dataclass
#: ([imu] is read apart: user units)
_OPTION_TABLES = _SELFCAL_TABLES + (("tdcp", Tdcp), ("robust", Robust), ("constraints", Constraints))


def _table_from_dict(key: str, value, cls, source: str):
    """The dataclass ``cls`` from the TOML table ``[key]``: a one-line ConfigError for a
    value that is not a table or an unknown key (with a did-you-mean)."""
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: key '{key}': bad value {value!r}; allowed: a [{key}] table")
    if issubclass(cls, TomlTable):
        return cls.from_dict(value, source)
    known = {f.name for f in dataclasses.fields(cls)}
    for k in value:
        if k not in known:
            raise ConfigError(f"{source}: unknown key '{key}.{k}'{_suggest(k, known)}")
    return cls(**value)


def config_from_dict(d: dict, source: str = "config") -> RunConfig:
    """Build a :class:`RunConfig` from a (TOML) dict, rejecting unknown keys."""
    d = dict(d)
    imu_d = d.pop("imu", None)
    for table in ("rtk", "rtk_engine"):  # coupling = "rtk": read by insnav.filters.rtk_ins (the CLI passes them)
        value = d.pop(table, {})
        if not isinstance(value, dict):
            raise ConfigError(f"{source}: key '{table}': bad value {value!r}; allowed: an [{table}] table")
    raw_tables = {key: d.pop(key) for key, _ in _OPTION_TABLES if key in d}
    if "options" in d and not isinstance(d["options"], dict):
        raise ConfigError(f"{source}: key 'options': bad value {d['options']!r}; allowed: an [options] table")
    tabled = {"imu"} | {key for key, _ in _OPTION_TABLES}
    names = {f.name for f in dataclasses.fields(RunConfig)} - tabled
    for k in d:
        if k not in names:
            raise ConfigError(f"{source}: unknown key '{k}'{_suggest(k, names | tabled)}")
    opts = d.get("options")
    if isinstance(opts, dict) and "layout" in opts and "layout" not in d:  # the key's place before the run layer
        import warnings

        warnings.warn(f"{source}: key 'options.layout' is deprecated; write 'layout' (17 or 20) at the top level",
                      FutureWarning, stacklevel=2)
        d["options"] = {k: v for k, v in opts.items() if k != "layout"}
        d["layout"] = opts["layout"] if opts["layout"] != "auto" else 15
    tables = {key: _table_from_dict(key, raw_tables[key], cls, source)
              for key, cls in _OPTION_TABLES if key in raw_tables}
    cfg = RunConfig(**d, **tables)
    if imu_d is not None:
        if not isinstance(imu_d, dict):
            raise ConfigError(f"{source}: key 'imu': bad value {imu_d!r}; allowed: a table of IMU noise keys")
        noise = ImuNoise()
        for k, v in imu_d.items():
            if k not in _USER_UNITS:
                raise ConfigError(f"{source}: unknown key 'imu.{k}'{_suggest(k, _USER_UNITS)}")
            fld, factor = _USER_UNITS[k]
            try:  # numbers only: float() would read a quoted "0.2" and a true
                if not all(isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))
                           for x in np.ravel(np.asarray(v, dtype=object))):
                    raise TypeError
                arr = np.broadcast_to(np.asarray(v, dtype=float), (3,)) * factor
            except (TypeError, ValueError):
                arr = np.full(3, np.nan)
            if k.endswith("_tau_s"):  # a Gauss-Markov correlation time: exp(-dt/tau) needs tau > 0
                if not (np.all(arr > 0) and np.all(np.isfinite(arr))):
                    raise ConfigError(f"{source}: key 'imu.{k}': bad value {v!r}; allowed: finite values > 0 [s]")
            elif not (np.all(arr >= 0) and np.all(np.isfinite(arr))):
                raise ConfigError(f"{source}: key 'imu.{k}': bad value {v!r}; allowed: values >= 0")
            setattr(noise, fld, arr.tolist())
        cfg.imu = noise
    return _validated(cfg, source)


def read_toml(path) -> dict:
    """A TOML file as a dict; a one-line :class:`ConfigError` naming the file when it
    cannot be read or is not valid TOML."""
    import tomllib  # here: insnav run --format kfgins never reads TOML (~2 ms of import)

    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:  # a binary file: tomllib decodes the bytes before it parses
        raise ConfigError(f"{path}: not valid TOML: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at "
                          f"offset {exc.start})") from None


def load_config(path, overrides: dict | None = None) -> RunConfig:
    """Read an insnav TOML run configuration; ``overrides`` (e.g. the command line's ``filter`` and
    ``coupling``) replace the file's keys before it is checked, so its other keys are checked
    against the filter that will run."""
    path = Path(path)
    d = read_toml(path)  # its one-line errors: unreadable, not TOML, not UTF-8
    d.update({k: v for k, v in (overrides or {}).items() if v is not None})
    return config_from_dict(d, source=str(path))


def _validated(cfg: RunConfig, source: str) -> RunConfig:
    try:
        return cfg.validate()
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
