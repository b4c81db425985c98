"""Real GNSS + IMU data for the tightly coupled filter.

A RINEX observation + navigation file pair, an IMU file (a generic CSV, or a
raw log time-tagged by RTKLIB ``str2str``) and, optionally, an RTKLIB ``.pos``
reference become a :class:`RinexDataset` that :func:`insnav.filters.tight.run_tight`
and ``insnav.run(ds, config=cfg)`` accept, plus a :class:`~insnav.config.RunConfig`
suited to it (:func:`load_rinex`).  ``insnav run --format rinex`` calls
:func:`load_rinex_run`.

Time axis
---------
Dataset time is **GPS seconds of week** of the week of the first observation
epoch (as for the KF-GINS loader): ``t_gps = t + gps_time_offset_s`` with
``gps_time_offset_s = 604800 * week``.  The solution CSV therefore has GPS
seconds of week in its ``t`` column and ``insnav evaluate SOL REF.pos`` can
compare it with an RTKLIB reference directly.

IMU file
--------
Read by :func:`insnav.io.imu_csv.read_imu_csv` (columns, units, axes, time
base, str2str-tagged raw logs; see that module).  The ``imu_*`` keys of
:class:`RinexOptions` are the fields of :class:`~insnav.io.imu_csv.ImuCsvFormat`
with an ``imu_`` prefix.

Initial state
-------------
Position and velocity from a single-point fix (:func:`single_point_solution`:
least squares over the pseudoranges and Dopplers of one epoch, needs 4
satellites) at the start epoch, or given.  Roll and pitch from the mean
specific force over ``level_window_s`` before the start (accelerometer
levelling).  Heading: a consumer gyro cannot gyrocompass (Earth rate,
4e-3 deg/s, is far below its bias), so ``init_yaw_deg`` is either given or
``"course"``: the run then starts at the first epoch at which the single-point
horizontal speed has stayed above ``course_min_speed_mps`` for
``course_window_s``, and the yaw is the course over ground of the mean
Doppler velocity of that window.  This assumes the body x axis points along
the direction of travel (true for a car, roughly true for a handheld unit
carried in front of the walker), and it drops the data before the start.

Errors
------
Every problem with an input file raises :class:`ImuFileError` (or the
:class:`insnav.gnss.RinexError` of the RINEX/``.pos`` readers), a
``ValueError`` whose message names the file, the 1-based line (the byte
offset for the binary tag file) and what was wrong.
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import _core, earth
from .._median import median, unique
from ..config import ConfigError, RunConfig, config_from_dict
from ..data.dataset import Dataset, GnssFixes, ImuData, Truth
from ..gnss.gpstime import SECONDS_PER_WEEK
from ..gnss.spp import SppOptions, SppSolution, solve_spp, spp_inputs_from_rinex
from ..gnss.systems import SYSTEMS
from ..gnss.weighting import Weighting
from ..data.nav import NavState
from ..units import DEG, G0, RAD2DEG
# the IMU CSV / str2str readers live in insnav.io.imu_csv (shared with --format csv); re-exported here
from .imu_csv import (GPST_UNIX_OFFSET_S, ImuCsvFormat, ImuFileError, ImuSamples, Str2strTag,  # noqa: F401
                      read_imu_csv, read_str2str_tag, tick_time_map)

__all__ = ["ImuFileError", "ImuCsvFormat", "Str2strTag", "read_str2str_tag", "read_imu_csv", "ImuSamples",
           "tick_time_map", "SinglePoint", "single_point_solution", "rtklib_truth", "RinexOptions",
           "RinexDataset", "load_rinex", "load_rinex_run", "CONSUMER_MEMS_MODEL", "GPST_UNIX_OFFSET_S"]

#: Default filter IMU model for a consumer MEMS IMU (SI, keys of
#: :func:`insnav.sim.imu.imu_model_dict` read by ``ImuNoise.from_dataset_model``):
#: white noise 4x a good consumer part's datasheet (0.0038 deg/s/sqrt(Hz),
#: 70 ug/sqrt(Hz), e.g. TDK ICM-42688; the factor covers handling vibration),
#: turn-on biases 0.3 deg/s and 30 mg (uncalibrated, 1-sigma, nearly constant
#: over a run: Gauss-Markov with 3600 s).
CONSUMER_MEMS_MODEL = dict(gyro_arw=4 * 0.0038 * DEG, accel_vrw=4 * 70e-6 * G0,
                           gyro_bias_total_sigma=0.3 * DEG, accel_bias_total_sigma=30e-3 * G0,
                           gyro_scale_sigma=1e-3, accel_scale_sigma=1e-3)


# --------------------------------------------------------------------------- single-point solution


#: the single-point solution type (:class:`insnav.gnss.spp.SppSolution`; the name kept for the loader's users)
SinglePoint = SppSolution


def single_point_solution(inputs, r0_e, *, min_sats: int = 4, iterations: int = 10, raim: bool = False,
                          options: SppOptions | None = None) -> SppSolution:
    """Weighted least-squares position/clock and velocity/drift per epoch (:func:`insnav.gnss.spp.solve_spp`).

    Uses exactly the rows the tight filter receives (same satellites,
    corrections and sigmas).  Model (``TightInputs.sats`` columns)::

        rho  = |r_s - r| + b (+ ISB) - clk_s         (Gauss-Newton from r0_e, then from the previous epoch)
        rhod = u . (v_s - v) + d - clkdot_s          (linear once r is known)

    Parameters
    ----------
    inputs : insnav.gnss.tight_inputs.TightInputs
    r0_e : (3,) starting ECEF position [m]
    min_sats : int
        Epochs with fewer usable rows give NaN (4 unknowns each, one more per further system).
    raim : bool
        RAIM fault detection and exclusion (off for the start-up fix, as before).
    options : SppOptions, optional
        Overrides ``min_sats`` and ``iterations``.

    Returns
    -------
    SppSolution (alias :data:`SinglePoint`)
    """
    opt = options or SppOptions(min_sats=min_sats, iterations=iterations)
    return solve_spp(inputs, r0_e, options=opt, raim=raim)


# --------------------------------------------------------------------------- reference


def rtklib_truth(ref, t_offset_gps_s: float, quality_max: int | None = None) -> Truth:
    """An RTKLIB ``.pos`` solution as a :class:`~insnav.data.dataset.Truth` (no attitude).

    Parameters
    ----------
    ref : path or insnav.gnss.measurements.RtklibPos
    t_offset_gps_s : float
        GPS time of dataset time 0 [s since 1980-01-06] (``604800 * week``
        for GPS seconds of week).
    quality_max : int, optional
        Keep records with ``Q <= quality_max`` (1: fix only, 2: fix and float).

    Returns
    -------
    Truth
        Antenna position and velocity (NaN velocity when the file has none),
        attitude NaN; ``truth.quality`` holds Q.
    """
    from .gnss_files import read_rtklib_pos

    if not hasattr(ref, "r_e"):
        ref = read_rtklib_pos(ref)
    keep = np.ones(len(ref.t_gps_s), bool) if quality_max is None else ref.q <= quality_max
    lat, lon, h = earth.ecef_to_geodetic(ref.r_e[keep])
    v_n = earth.ecef_to_ned_vector(lat, lon, ref.v_e[keep])
    nan = np.full(int(keep.sum()), np.nan)
    tr = Truth(ref.t_gps_s[keep] - t_offset_gps_s, lat * RAD2DEG, lon * RAD2DEG, h, v_n, nan, nan.copy(), nan.copy())
    tr.quality = np.asarray(ref.q)[keep]
    return tr


# --------------------------------------------------------------------------- options and loader


@dataclass
class RinexOptions:
    """Options of :func:`load_rinex` (the ``[rinex]`` table of a run TOML).
    Units are in the attribute names.

    Attributes
    ----------
    imu_columns, imu_time, imu_acc_unit, imu_gyro_unit, imu_samples,
    imu_mount_rpy_deg, imu_time_offset_s, imu_delimiter, imu_axes, imu_time_unit,
    imu_rate_hz, imu_gps_week :
        The IMU CSV format (:class:`ImuCsvFormat` without the ``imu_`` prefix).
    imu_tag : str or None
        str2str tag file (``tick_ms`` column); None: ``IMU + ".tag"``.
    lever_arm_b : 3 floats
        IMU -> antenna, body FRD [m].
    elevation_mask_deg, iono, tropo, sigma_pr_zenith_m, sigma_prr_zenith_mps, use_cn0 :
        GNSS inputs (:func:`insnav.gnss.tight_inputs.tight_inputs_from_rinex`).
    systems : str
        Systems of the tight inputs, letters of "GREC" with G (default "G"):
        the start (single-point fix, course) uses GPS; with more systems the
        tight filter gets every system's rows and runs with inter-system bias
        states (``LayoutTightMulti``).  Files given as paths are read with
        these systems; already read ObsData/NavData are used as they are.
        With a ``[gnss]`` weighting table its rows (and systems) are used instead.
    start_s, end_s : float
        Span to use, seconds after the first observation epoch (end None: all).
    init_position : "spp" or [lat_deg, lon_deg, h_m] (antenna)
    init_velocity : "doppler", "zero" or [vn, ve, vd] [m/s]
    init_yaw_deg : "course" or a number [deg]
    init_yaw_sigma_deg : float or None (None: 20 with "course", 10 given)
    course_min_speed_mps, course_window_s : the "course" start rule
    level_window_s : accelerometer levelling window before the start [s]
    init_gyro_bias : "zero" or "static"
        "static": the initial gyro-bias estimate of the run config
        (``init_gyro_bias_radps``) is the mean angular rate of the IMU samples
        before the start that the standstill detector marks stationary
        (``ins/standstill.hpp``, the SHOE statistic of Skog et al. 2010 with
        the ``[constraints]`` zupt defaults and gravity as the accelerometer
        measures it, the median ``|f|``; at least 1 s of them), its
        1-sigma (``init_sigma_gyro_bias_radps``) the standard error of that
        mean and the Earth rate (left in: the heading is not known there) in
        quadrature.  "zero" (default): zero, with the noise model's sigma.
    reference : str or None
        RTKLIB ``.pos`` reference (becomes ``dataset.truth``).
    """

    imu_columns: tuple = ("t", "ax", "ay", "az", "gx", "gy", "gz")
    imu_time: str = "gps_s"
    imu_acc_unit: str = "mps2"
    imu_gyro_unit: str = "rps"
    imu_samples: str = "rate"
    imu_mount_rpy_deg: tuple = (0.0, 0.0, 0.0)
    imu_time_offset_s: float = 0.0
    imu_delimiter: str = ","
    imu_axes: str = "FRD"
    imu_time_unit: str = "s"
    imu_rate_hz: float | None = None
    imu_gps_week: int | None = None
    imu_tag: str | None = None
    lever_arm_b: tuple = (0.0, 0.0, 0.0)
    elevation_mask_deg: float = 10.0
    iono: bool = True
    tropo: bool = True
    sigma_pr_zenith_m: float = 3.0
    sigma_prr_zenith_mps: float = 0.3
    use_cn0: bool = True
    systems: str = "G"
    start_s: float = 0.0
    end_s: float | None = None
    init_position: object = "spp"
    init_velocity: object = "doppler"
    init_yaw_deg: object = "course"
    init_yaw_sigma_deg: float | None = None
    course_min_speed_mps: float = 0.8
    course_window_s: float = 1.0
    level_window_s: float = 1.0
    init_gyro_bias: str = "zero"
    reference: str | None = None

    def imu_format(self) -> ImuCsvFormat:
        cols = self.imu_columns
        if isinstance(cols, (list, tuple)):
            cols = tuple(cols)
        mount = self.imu_mount_rpy_deg
        if isinstance(mount, (list, tuple)):
            mount = tuple(mount)
        # anything else (a number where a list belongs) is named by ImuCsvFormat.validate
        return ImuCsvFormat(cols, self.imu_time, self.imu_acc_unit, self.imu_gyro_unit,
                            self.imu_samples, mount, self.imu_time_offset_s,
                            self.imu_delimiter, self.imu_axes, self.imu_time_unit, self.imu_gps_week, self.imu_rate_hz)

    @classmethod
    def from_dict(cls, d: dict, source: str = "[rinex]") -> "RinexOptions":
        """Options from a TOML table; unknown keys and bad values raise ConfigError naming them."""
        names = {f.name for f in dataclasses.fields(cls)}
        for k in d:
            if k not in names:
                raise ConfigError(f"{source}: unknown key 'rinex.{k}'; known keys: {', '.join(sorted(names))}")
        opt = cls(**d)
        return opt.validate(source)

    def validate(self, source: str = "rinex options") -> "RinexOptions":
        def bad(key, allowed):
            raise ConfigError(f"{source}: key 'rinex.{key}': bad value {getattr(self, key)!r}; allowed: {allowed}")

        self.imu_format().validate(source)
        if not (isinstance(self.systems, str) and "G" in self.systems and set(self.systems) <= set("GREC")
                and len(set(self.systems)) == len(self.systems)):
            bad("systems", 'letters of "GREC" including G (GPS is the clock reference), e.g. "GEC"')
        for key in ("iono", "tropo", "use_cn0"):
            if not isinstance(getattr(self, key), bool):
                bad(key, "true or false")
        for key in ("elevation_mask_deg", "sigma_pr_zenith_m", "sigma_prr_zenith_mps", "start_s",
                    "course_min_speed_mps", "course_window_s", "level_window_s", "end_s", "init_yaw_sigma_deg"):
            v = getattr(self, key)
            if v is None and key in ("end_s", "init_yaw_sigma_deg"):
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                bad(key, "a finite number")
        for key in ("sigma_pr_zenith_m", "sigma_prr_zenith_mps", "course_window_s", "level_window_s"):
            if not getattr(self, key) > 0:
                bad(key, "> 0")
        if self.end_s is not None and not self.end_s > self.start_s:
            bad("end_s", f"> start_s ({self.start_s})")
        try:
            la = np.asarray(self.lever_arm_b, dtype=float) if not isinstance(self.lever_arm_b, str) else np.zeros(0)
        except (TypeError, ValueError):  # a table or a nested list where 3 numbers belong
            la = np.zeros(0)
        if la.shape != (3,) or not np.all(np.isfinite(la)):
            bad("lever_arm_b", "3 finite values [m]")
        from ..data.checks import lever_arm_problem

        problem = lever_arm_problem(la)
        if problem:
            raise ConfigError(f"{source}: key 'rinex.lever_arm_b': {self.lever_arm_b!r}: {problem}")
        for key, word, n in (("init_position", "spp", 3), ("init_velocity", ("doppler", "zero"), 3)):
            v = getattr(self, key)
            words = (word,) if isinstance(word, str) else word
            if isinstance(v, str):
                if v not in words:
                    bad(key, " or ".join(f'"{w}"' for w in words) + f" or {n} numbers")
            else:
                try:
                    a = np.asarray(v, dtype=float)
                except (TypeError, ValueError):
                    a = np.zeros(0)
                if a.shape != (n,) or not np.all(np.isfinite(a)):
                    bad(key, " or ".join(f'"{w}"' for w in words) + f" or {n} numbers")
        if self.init_gyro_bias not in ("zero", "static"):
            bad("init_gyro_bias", '"zero" or "static"')
        v = self.init_yaw_deg
        if isinstance(v, str) and v != "course" or (not isinstance(v, str) and (
                isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v))):
            bad("init_yaw_deg", '"course" or a number [deg]')
        return self


@dataclass
class RinexDataset(Dataset):
    """A :class:`~insnav.data.dataset.Dataset` built from real files (tight coupling).

    The attributes below are in addition to those of the Dataset.

    Attributes
    ----------
    tight_inputs : insnav.gnss.tight_inputs.TightInputs
        Per-epoch satellite rows (read by :func:`insnav.filters.tight.run_tight`).
    spp : SinglePoint
        GNSS-only single-point solution of the same rows (all epochs).
    info : dict
        Counts and choices (satellites, IMU rate, time-tag fit, start rule).
    options : RinexOptions
        The loader options used.

    ``gnss`` holds the single-point fixes after ``t0`` (so loose coupling runs
    too); ``truth`` the RTKLIB reference (antenna, no attitude) when given.
    """

    tight_inputs: object = None
    spp: SinglePoint | None = None
    info: dict = field(default_factory=dict)
    options: RinexOptions | None = None
    weighting: Weighting | None = None
    spp_options: SppOptions | None = None


def _level(f_b_mean) -> tuple[float, float]:
    """(roll, pitch) [rad] from a mean specific force in FRD (at rest f_b = C_bn (0, 0, -g))."""
    fx, fy, fz = f_b_mean
    return math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))


def _epochs_in(inp, t_lo, t_hi):
    """Sub-:class:`TightInputs` with the epochs ``t_lo < t <= t_hi``."""
    from ..gnss.tight_inputs import TightInputs

    m = (inp.epoch_t > t_lo) & (inp.epoch_t <= t_hi)
    e = np.flatnonzero(m)
    if e.size == 0:
        return TightInputs(np.zeros(0), np.zeros(1, np.int64), np.zeros((0, 12)), np.zeros(0, np.int64),
                           np.zeros(0), dict(inp.info))
    a, b = inp.epoch_start[e[0]], inp.epoch_start[e[-1] + 1]
    return TightInputs(inp.epoch_t[e].copy(), (inp.epoch_start[e[0]:e[-1] + 2] - a).astype(np.int64),
                       inp.sats[a:b].copy(), inp.prn[a:b].copy(), inp.elevation_deg[a:b].copy(), dict(inp.info),
                       inp.system[a:b].copy())


def _approx_position(obs, nav, t_week0):
    """Approximate receiver position: the header's, else a bootstrap from the centroid of the satellites."""
    from ..gnss.tight_inputs import tight_inputs_from_rinex

    r = getattr(obs, "approx_r_e", None)
    if r is not None and np.all(np.isfinite(r)) and np.linalg.norm(r) > 6.0e6:
        return np.asarray(r, float)
    from ..gnss.ephemeris import sat_position_velocity, select_ephemeris

    system = np.asarray(getattr(obs, "system", np.full(np.shape(obs.prn), "G")))  # multi-system obs
    gps = system == "G"
    idx = select_ephemeris(nav.eph, obs.prn[gps], obs.t_gps_s[gps])
    ok = idx >= 0
    systems = "G"
    if ok.any():
        rs = sat_position_velocity(nav.eph, idx[ok], obs.t_gps_s[gps][ok]).r_e
    else:  # no GPS: the other systems' satellites (states of tight_inputs_from_rinex, from any start)
        systems = "".join(s for s in "REC" if np.any(system == s))
        rows = tight_inputs_from_rinex(obs, nav, t_week0, np.array([earth.A, 0.0, 0.0]), elevation_mask_deg=-90.0,
                                       iono=False, tropo=False, systems=systems).sats if systems else np.zeros((0, 12))
        rs = rows[np.isfinite(rows[:, 2]), 2:5]
        if rs.size == 0:
            raise ValueError(f"{obs.path}: no observation has an ephemeris in {getattr(nav, 'path', 'the nav file')}"
                             " (and the header has no APPROX POSITION XYZ)")
    c = rs.mean(axis=0)
    r_start = c / np.linalg.norm(c) * earth.A
    # Every caller solves again from this position and then from the median of that solution, and a
    # start position off by d moves those final fixes by about 1e-10 d (light time, elevation and
    # atmosphere at the start position; tests/test_spp.py): about 100 epochs spread over the file
    # give the median to metres at a fraction of the cost of all of them.
    n_ep = obs.epoch_t_gps_s.size
    for sub in ((_every_kth_epoch(obs, max(1, n_ep // _BOOTSTRAP_EPOCHS)), obs) if n_ep > 2 * _BOOTSTRAP_EPOCHS
                else (obs,)):
        r0 = r_start
        for _ in range(2):  # rough inputs -> single point -> again
            inp = tight_inputs_from_rinex(sub, nav, t_week0, r0, elevation_mask_deg=-90.0, iono=False, tropo=False,
                                          systems=systems)
            spp = single_point_solution(inp, r0)
            good = np.isfinite(spp.r_e[:, 0])
            if not good.any():
                break
            r0 = np.array([median(spp.r_e[good, k]) for k in range(3)])  # np.median(axis=0), without numpy.ma
        if good.any():
            return r0
    raise ValueError(f"{obs.path}: no epoch with 4 {'GPS ' if systems == 'G' else ''}satellites for a first "
                     "position fix")


#: epochs (about) of the start-position bootstrap of :func:`_approx_position`
_BOOTSTRAP_EPOCHS = 100
#: per-epoch fields of an ObsData (the other arrays of one row per observation are subset by row)
_OBS_EPOCH_FIELDS = ("epoch_t_gps_s", "epoch_week", "epoch_tow", "epoch_flag", "clock_offset_s")


def _every_kth_epoch(obs, k: int):
    """``obs`` with the observations of every ``k``-th epoch only (the epoch arrays and indices unchanged)."""
    if k <= 1:
        return obs
    keep = obs.epoch % k == 0
    m = keep.size
    sub = {}
    for f in dataclasses.fields(obs):
        v = getattr(obs, f.name)
        if f.name not in _OBS_EPOCH_FIELDS and isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == m:
            sub[f.name] = v[keep]
    return dataclasses.replace(obs, **sub)


#: Doppler velocity vs the slope of the single-point positions: window [s] and largest difference [m/s]
DOPPLER_CHECK_WINDOW_S = 10.0
DOPPLER_CHECK_MAX_MPS = 3.0


def doppler_consistent(t, r_e, v_e, *, window_s: float = DOPPLER_CHECK_WINDOW_S,
                       max_diff_mps: float = DOPPLER_CHECK_MAX_MPS) -> np.ndarray:
    """True where the Doppler velocity of a single-point fix agrees with the change of the fixes' positions.

    The velocity from the pseudorange rates and the least-squares slope of the positions over
    ``window_s`` centred on the epoch are independent; with 4 or 5 satellites snapshot RAIM cannot
    find a biased Doppler on one of them (no redundancy), but the two velocities then differ by
    metres per second (a 5 m/s bias on one of 5 satellites: about 5-10 m/s).  Over 10 s of 1 Hz
    fixes with 5 m position noise the slope is good to about 0.5 m/s, so ``max_diff_mps`` = 3 m/s
    is about 6 sigma.  Epochs without a position or velocity, or with fewer than 4 positions in the
    window, are kept (True) when their velocity is finite.

    Parameters
    ----------
    t : (E,) s;  r_e : (E, 3) ECEF position [m];  v_e : (E, 3) ECEF velocity [m/s]

    Returns
    -------
    (E,) bool
    """
    t = np.asarray(t, float)
    r_e, v_e = np.asarray(r_e, float), np.asarray(v_e, float)
    ok = np.isfinite(r_e[:, 0])
    keep = np.isfinite(v_e[:, 0])
    tt, rr = t[ok], r_e[ok]
    lo = np.searchsorted(tt, t - window_s / 2.0)
    hi = np.searchsorted(tt, t + window_s / 2.0, side="right")
    ks = np.flatnonzero(keep)
    n = hi[ks] - lo[ks]
    ks, n = ks[n >= 4], n[n >= 4]
    if ks.size == 0:
        return keep
    # every window at once: rows a..b-1 of each, padded with zero rows (which change neither the singular
    # values nor the least-squares solution), solved as np.linalg.lstsq(A, r, rcond=None) does: through the
    # SVD, singular values below eps max(rows, 3) s_max dropped, rank < 3 left untested
    j = np.arange(int(n.max()))
    valid = j < n[:, None]
    rows = np.where(valid, lo[ks][:, None] + j, 0)
    dt = np.where(valid, tt[rows] - t[ks][:, None], 0.0)
    A = np.stack([valid.astype(float), dt, dt * dt], axis=-1)  # constant acceleration: turns, speed changes
    B = np.where(valid[..., None], rr[rows], 0.0)
    U, sv, Vt = np.linalg.svd(A, full_matrices=False)
    big = sv > np.finfo(float).eps * np.maximum(n, 3)[:, None] * sv[:, :1]
    inv_s = np.where(big, 1.0 / np.where(big, sv, 1.0), 0.0)
    coef = np.swapaxes(Vt, 1, 2) @ (inv_s[..., None] * (np.swapaxes(U, 1, 2) @ B))  # (K, 3 coefficients, 3 axes)
    full = big.sum(axis=1) == 3
    keep[ks[full]] = np.linalg.norm(coef[full, 1] - v_e[ks[full]], axis=1) <= max_diff_mps
    return keep


def _warn_systems_without_ephemerides(nav, systems: str) -> None:
    """A RuntimeWarning for each system of ``systems`` (``[rinex] systems``) that
    ``nav`` holds no ephemeris of: its satellites would be left out without a word
    (RINEX 2 keeps GLONASS in a ``.g`` file of its own)."""
    import warnings

    from ..errors import InsnavWarning

    names = {"R": ("eph_r", "GLONASS"), "E": ("eph_e", "Galileo"), "C": ("eph_c", "BeiDou")}
    for letter in systems:
        if letter not in names:
            continue
        eph = getattr(nav, names[letter][0], None)
        if eph is None or len(eph.prn) == 0:
            warnings.warn(f"{getattr(nav, 'path', 'the navigation data')}: no {names[letter][1]} ephemeris, so "
                          f"[rinex] systems = \"{systems}\" uses no {names[letter][1]} satellite (give a navigation "
                          f"file with them: a mixed RINEX 3 file)", InsnavWarning, stacklevel=3)


def load_rinex(obs, nav, imu, options: RinexOptions | dict | None = None, *, imu_tag=None,
               reference=None, weighting=None) -> tuple[RinexDataset, RunConfig]:
    """Build a dataset and a run configuration from RINEX + IMU (+ reference) files.

    Parameters
    ----------
    obs, nav : path or insnav.gnss.ObsData / NavData
        RINEX 2/3 observation and navigation files (GPS L1 C/A, LNAV).
    imu : path
        IMU CSV (format: ``options``).
    options : RinexOptions or dict (the ``[rinex]`` TOML table)
    imu_tag : path, optional
        Overrides ``options.imu_tag``.
    reference : path, optional
        RTKLIB ``.pos``; overrides ``options.reference``.
    weighting : insnav.gnss.weighting.Weighting or dict (the ``[gnss]`` TOML table), optional
        Pseudorange variance model, masks and systems of the rows; None (or
        the defaults): the rows of :func:`~insnav.gnss.tight_inputs.tight_inputs_from_rinex`
        unchanged.  Otherwise the rows of :func:`insnav.gnss.spp.spp_inputs_from_rinex`
        (then the best-GDOP limit of :data:`~insnav.gnss.tight_inputs.MAX_SATS`).

    Returns
    -------
    dataset : RinexDataset
        Dataset time = GPS seconds of week (see the module docstring).
    config : RunConfig
        ``coupling="tight"``, ``filter="ekf"``, ``init_error=False`` and initial
        sigmas from the single-point covariance and the start rule.

    Raises
    ------
    ImuFileError, insnav.gnss.RinexError
        Malformed files (file and line).
    ValueError
        No usable start epoch, no IMU data over the GNSS span.
    """
    from ..gnss import read_rinex_obs
    from ..gnss.rinex import read_nav_multi
    from ..gnss.tight_inputs import tight_inputs_from_rinex

    if options is None:
        opt = RinexOptions().validate()
    elif isinstance(options, dict):
        opt = RinexOptions.from_dict(options)
    else:
        opt = options.validate()
    if imu_tag is not None:
        opt.imu_tag = os.path.abspath(imu_tag)
    if reference is not None:
        opt.reference = os.path.abspath(reference)
    wgt = None if weighting is None else (Weighting.from_dict(weighting, "[gnss]") if isinstance(weighting, dict)
                                          else weighting.validate())
    if wgt is not None and wgt.is_default:
        wgt = None
    if wgt is not None and wgt.systems != list(SYSTEMS):  # [gnss] systems selects among the systems read
        unread = [s for s in wgt.systems if s not in opt.systems]
        if unread:
            raise ConfigError(f"[gnss] systems = {wgt.systems} asks for {', '.join(unread)}, which [rinex] systems = "
                              f"\"{opt.systems}\" does not read: add {''.join(unread)} to [rinex] systems (the "
                              f"systems read from the files; [gnss] systems selects among them)")

    if not hasattr(obs, "C1"):
        obs = read_rinex_obs(obs, systems=opt.systems)
    if not hasattr(nav, "eph"):  # one path, or several merged (a RINEX 2 .n and .g pair)
        nav = read_nav_multi(nav, opt.systems)
    if obs.epoch_t_gps_s.size == 0:
        raise ValueError(f"{obs.path}: no observation epochs")
    _warn_systems_without_ephemerides(nav, opt.systems)
    week = int(obs.epoch_week[0])
    t_week0 = SECONDS_PER_WEEK * week
    fmt = opt.imu_format().validate()
    samples = read_imu_csv(imu, fmt, tag=opt.imu_tag, week=week)

    r0 = _approx_position(obs, nav, t_week0)
    kw = dict(elevation_mask_deg=opt.elevation_mask_deg, iono=opt.iono, tropo=opt.tropo,
              sigma_pr_zenith_m=opt.sigma_pr_zenith_m, sigma_prr_zenith_mps=opt.sigma_prr_zenith_mps,
              use_cn0=opt.use_cn0)
    states: dict = {}  # the first call's satellite states, carried to the second call's position

    def inputs_at(r):
        if wgt is None:  # today's rows, unchanged
            keep: dict = {}
            inp = tight_inputs_from_rinex(obs, nav, t_week0, r, _prior=states.get("tight"), _keep=keep, **kw)
            states["tight"] = keep
            return inp
        from ..gnss.spp import _spp_inputs_from_rinex
        from ..gnss.tight_inputs import MAX_SATS, limit_sats

        inp_all, _, states["spp"] = _spp_inputs_from_rinex(obs, nav, t_week0, r, weighting=wgt,
                                                           prior=states.get("spp"), **kw)
        return limit_sats(inp_all, MAX_SATS)

    # the fixes of the start (course, initial position) and of the input checks: with RAIM FDE on
    # positions and Doppler velocities, so one faulty satellite (a Doppler bias, a wrong PRN) neither
    # moves the start nor fails the gyro-vs-course check (insnav.gnss.spp.solve_spp)
    inp = inputs_at(r0)
    spp = single_point_solution(inp, r0, raim=True)
    good = np.isfinite(spp.r_e[:, 0])
    if good.any():  # recompute light time / elevation / atmosphere at the data's own position
        r0 = np.array([median(spp.r_e[good, k]) for k in range(3)])  # np.median(axis=0), without numpy.ma
        inp = inputs_at(r0)
        spp = single_point_solution(inp, r0, raim=True)
        good = np.isfinite(spp.r_e[:, 0])

    t_first = float(obs.epoch_t_gps_s[0] - t_week0)
    imu_t = (samples.t_ref_gps_s - t_week0) + samples.t_s
    t_lo = max(t_first + opt.start_s, float(imu_t[1]) + opt.level_window_s
               if opt.init_yaw_deg == "course" else float(imu_t[1]))
    t_hi = float(imu_t[-1]) if opt.end_s is None else min(float(imu_t[-1]), t_first + opt.end_s)
    t_last = float(obs.epoch_t_gps_s[-1] - t_week0)
    if imu_t[-1] <= t_first or imu_t[0] >= t_last:
        raise ValueError(f"{samples.path}: the IMU data (GPS seconds of week {week}: {imu_t[0]:.3f} to "
                         f"{imu_t[-1]:.3f}) do not overlap the observations in {obs.path} ({t_first:.3f} to "
                         f"{t_last:.3f}); check the IMU time column and imu_time")
    v_n_spp = spp.v_n()
    v_n_spp[~doppler_consistent(spp.t, spp.r_e, spp.v_e)] = np.nan  # not used for the start or the checks
    speed = np.hypot(v_n_spp[:, 0], v_n_spp[:, 1])
    cand = np.flatnonzero(good & (spp.t >= t_lo) & (spp.t < t_hi))
    if cand.size == 0:
        raise ValueError(f"{obs.path}: no epoch with a single-point fix (4 GPS satellites with ephemeris) "
                         f"between {t_lo - t_first:.1f} s and {t_hi - t_first:.1f} s after the first epoch "
                         f"and inside the IMU data ({samples.path})")
    start_rule = "first fix"
    yaw_sigma = 10.0 if opt.init_yaw_sigma_deg is None else float(opt.init_yaw_sigma_deg)
    if opt.init_yaw_deg == "course":
        k0 = None
        for k in cand:
            w = (spp.t > spp.t[k] - opt.course_window_s - 1e-6) & (spp.t <= spp.t[k])
            if spp.t[k] - opt.course_window_s < t_lo - 1e-6:
                continue
            ok_w = good[w] & np.isfinite(speed[w])
            if ok_w.all() and np.all(speed[w] >= opt.course_min_speed_mps):
                k0 = int(k)
                break
        if k0 is None:
            raise ValueError(f"{obs.path}: init_yaw_deg = \"course\": the single-point speed never stays above "
                             f"{opt.course_min_speed_mps} m/s for {opt.course_window_s} s; give init_yaw_deg")
        w = (spp.t > spp.t[k0] - opt.course_window_s - 1e-6) & (spp.t <= spp.t[k0])
        vm = v_n_spp[w].mean(axis=0)
        yaw0 = math.degrees(math.atan2(vm[1], vm[0]))
        start_rule = (f"course: first {opt.course_window_s:g} s with single-point speed >= "
                      f"{opt.course_min_speed_mps:g} m/s")
        yaw_sigma = 20.0 if opt.init_yaw_sigma_deg is None else float(opt.init_yaw_sigma_deg)
    else:
        k0 = int(cand[0])
        yaw0 = float(opt.init_yaw_deg)
    t_ep = float(spp.t[k0])
    i0 = int(np.searchsorted(imu_t, t_ep, side="right")) - 1  # last IMU sample at or before the epoch
    if i0 < 1:
        raise ValueError(f"{samples.path}: the IMU data start after the start epoch ({t_ep:.3f} s of week)")
    t0 = float(imu_t[i0])

    # levelling: mean specific force over level_window_s before t0 (after it if the data start later)
    imu = samples.to_increments(t_week0)
    lw = (imu.t > t0 - opt.level_window_s) & (imu.t <= t0)
    if lw.sum() < 3:
        lw = (imu.t > t0) & (imu.t <= t0 + opt.level_window_s)
    dt_imu = np.diff(imu.t, prepend=imu.t[0] - imu.dt)
    f_mean = imu.dv_b[lw].sum(axis=0) / dt_imu[lw].sum()
    roll0, pitch0 = _level(f_mean)
    gyro_bias = static_gyro_bias(imu, t0, samples.path) if opt.init_gyro_bias == "static" else None

    lever = np.asarray(opt.lever_arm_b, float)
    if isinstance(opt.init_position, str):
        lat_a, lon_a, h_a = earth.ecef_to_geodetic(spp.r_e[k0])
        sig_pos = np.maximum(spp.sigma_pos_n_m[k0], 1.0)
    else:
        lat_a, lon_a, h_a = opt.init_position[0] * DEG, opt.init_position[1] * DEG, float(opt.init_position[2])
        sig_pos = np.array([1.0, 1.0, 1.0])
    if isinstance(opt.init_velocity, str):
        v0 = v_n_spp[k0].copy() if opt.init_velocity == "doppler" else np.zeros(3)
        sig_vel = (np.maximum(spp.sigma_vel_n_mps[k0], 0.1) if opt.init_velocity == "doppler"
                   else np.full(3, 0.1))
        if opt.init_velocity == "doppler" and not np.all(np.isfinite(v0)):
            v0, sig_vel = np.zeros(3), np.full(3, 1.0)
    else:
        v0, sig_vel = np.asarray(opt.init_velocity, float), np.full(3, 0.1)
    # antenna -> IMU centre
    C_nb = np.asarray(_core.rotation.dcm_from_euler(np.array([roll0, pitch0, yaw0 * DEG])))
    r_imu = earth.geodetic_to_ecef(lat_a, lon_a, h_a) - earth.C_en(lat_a, lon_a) @ (C_nb @ lever)
    lat0, lon0, h0 = earth.ecef_to_geodetic(r_imu)
    initial = NavState(lat0 * RAD2DEG, lon0 * RAD2DEG, h0, v0, roll0 * RAD2DEG, pitch0 * RAD2DEG, yaw0)

    sel = (imu.t > t0) & (imu.t <= t_hi)
    origin = imu.origin.take(sel, len(imu.t))
    imu = ImuData(imu.t[sel], imu.dtheta_b[sel], imu.dv_b[sel], origin=origin)
    if opt.systems != "G" and wgt is None:  # every system's rows for the filter (ISB states); start: GPS
        inp = tight_inputs_from_rinex(obs, nav, t_week0, r0, systems=opt.systems, **kw)
    inp_run = _epochs_in(inp, t0, float(imu.t[-1]))
    from ..gnss.tdcp import phase_rows  # carrier phase of the rows, for the TDCP rows ([tdcp], --tdcp)

    inp_run.phase = phase_rows(inp_run, obs, nav, t_week0)
    g = np.flatnonzero(good & (spp.t > t0) & (spp.t <= float(imu.t[-1])))
    lat_g, lon_g, h_g = earth.ecef_to_geodetic(spp.r_e[g])
    gnss = GnssFixes(spp.t[g], spp.t[g], lat_g * RAD2DEG, lon_g * RAD2DEG, h_g, v_n_spp[g],
                     spp.sigma_pos_n_m[g], spp.sigma_vel_n_mps[g])
    truth = None
    if opt.reference:
        truth = rtklib_truth(opt.reference, t_week0)
    n = inp_run.n_sats()
    info = dict(obs=str(obs.path), nav=str(getattr(nav, "path", "")), imu=samples.path, week=week,
                imu_samples=len(samples), imu_rate_hz=samples.rate_hz, imu_time=samples.info,
                gps_prns_observed=sorted(int(p) for p in unique(np.asarray(obs.prn)[
                    np.asarray(getattr(obs, "system", np.full(len(obs.prn), "G"))) == "G"])),
                gps_prns_with_ephemeris=sorted(int(p) for p in unique(nav.eph.prn)),
                prns_used=sorted(int(p) for p in unique(inp_run.prn[inp_run.system == "G"])),
                sats_used=_sat_names(inp_run.system, inp_run.prn),
                sats_per_epoch=(int(n.min()), int(median(n)), int(n.max())) if n.size else (0, 0, 0),
                start_rule=start_rule, start_s_after_first_epoch=t0 - t_first, approx_r_e=r0.tolist(),
                fix_systems="G" if wgt is None else "".join(x for x in wgt.systems if x in opt.systems),
                f_level_mps2=f_mean.tolist())
    ds = RinexDataset(imu=imu, gnss=gnss, truth=truth, gnss_raw=None, imu_errors=None,
                      scenario={"rinex": dict(obs=str(obs.path), imu=samples.path)}, lever_arm_b=lever,
                      initial=initial, t0=t0, gps_time_offset_s=float(t_week0), imu_model=dict(CONSUMER_MEMS_MODEL),
                      name=Path(str(obs.path)).stem, tight_inputs=inp_run, spp=spp, info=info, options=opt)
    moving = opt.init_yaw_deg == "course" or np.linalg.norm(v0) > 0.3
    cfg = RunConfig(filter="ekf", coupling="tight", init_error=False,
                    init_sigma_pos_m=np.asarray(sig_pos, float).tolist(),
                    init_sigma_vel_mps=np.asarray(sig_vel, float).tolist(),
                    init_sigma_att_deg=[3.0 if moving else 1.0, 3.0 if moving else 1.0, yaw_sigma])
    if gyro_bias is not None:
        cfg.init_gyro_bias_radps, cfg.init_sigma_gyro_bias_radps, n_still = gyro_bias
        info["gyro_bias_static"] = dict(bias_radps=cfg.init_gyro_bias_radps,
                                        sigma_radps=cfg.init_sigma_gyro_bias_radps, samples=n_still)
    return ds, cfg


#: [constraints] zupt defaults of the standstill detector (insnav.config.Constraints)
_STILL_WINDOW_S, _STILL_THRESHOLD, _STILL_SIGMA_F_MPS2, _STILL_SIGMA_W_DPS = 0.2, 18.0, 0.02, 0.115
#: least standstill before the start for init_gyro_bias = "static" [s]
STATIC_GYRO_BIAS_MIN_S = 1.0


def static_gyro_bias(imu: ImuData, t0: float, where: str = "IMU log") -> tuple[list, list, int]:
    """The gyro bias from the standstill before the start (``init_gyro_bias = "static"``).

    Parameters
    ----------
    imu : ImuData
        The increments, body axes, including the samples before ``t0``.
    t0 : float
        Start of the run [s]; only samples at or before it are used.
    where : str
        The file named in the error.

    Returns
    -------
    bias_radps, sigma_radps : list of 3 floats
        Mean angular rate of the samples the standstill detector (SHOE, Skog
        et al. 2010, eq. (10)) marks stationary [rad/s], and its 1-sigma: the
        standard error of the mean and the Earth rate (7.3e-5 rad/s, not
        removed: no heading before the start) in quadrature [rad/s].
    n : int
        Number of stationary samples.
    """
    before = imu.t <= t0
    t, dth, dv = imu.t[before], imu.dtheta_b[before], imu.dv_b[before]
    dt = np.diff(t, prepend=t[0] - imu.dt) if t.size else t
    rate = 1.0 / float(np.median(dt)) if t.size > 1 else 100.0
    window = int(np.clip(round(_STILL_WINDOW_S * rate), 2, 512))
    still = np.zeros(t.size, bool)
    if t.size > window:
        # gravity as this accelerometer measures it (median |f|: a consumer part's scale error of 1 % alone
        # would put 0.1 m/s^2 = 5 sigma_f into every sample of the statistic)
        g_meas = float(np.median(np.linalg.norm(dv, axis=1) / dt))
        T = np.asarray(_core.standstill_statistic(np.ascontiguousarray(t), np.ascontiguousarray(dth),
                                                  np.ascontiguousarray(dv), float(t[0]), window, _STILL_SIGMA_F_MPS2,
                                                  _STILL_SIGMA_W_DPS * DEG, g_meas))
        still = T < _STILL_THRESHOLD
    if dt[still].sum() < STATIC_GYRO_BIAS_MIN_S:
        raise ValueError(f"{where}: init_gyro_bias = \"static\": {dt[still].sum():.2f} s of standstill before the "
                         f"start (at least {STATIC_GYRO_BIAS_MIN_S:g} s needed); set init_gyro_bias = \"zero\"")
    w = dth[still] / dt[still, None]
    n = int(still.sum())
    sem = w.std(axis=0, ddof=1) / math.sqrt(n)
    sigma = np.hypot(sem, earth.OMEGA_IE)
    return w.mean(axis=0).tolist(), sigma.tolist(), n


def _sat_names(system, prn) -> list[str]:
    """Sorted distinct RINEX satellite names ``'E11'``, ``'G05'``... of (system, prn) rows."""
    from .._median import unique

    if len(prn) == 0:
        return []
    sys_code = np.asarray(system, dtype="<U1").view(np.int32).astype(np.int64)  # the letter's code point
    key = unique(sys_code * 1_000_000 + np.asarray(prn, dtype=np.int64))  # one row per satellite
    return sorted(set(f"{chr(int(k // 1_000_000))}{int(k % 1_000_000):02d}" for k in key.tolist()))


def _bad_table(source, key, value):
    raise ConfigError(f"{source}: key '{key}': bad value {value!r}; allowed: a table")


def load_rinex_run(obs, nav, imu, config_path=None, *, imu_tag=None, reference=None):
    """:func:`load_rinex` with a run TOML (``insnav run --format rinex``).

    The TOML holds the usual run keys (``docs/formats.md``) plus a ``[rinex]``
    table (:class:`RinexOptions`), a ``[gnss]`` table (pseudorange weighting,
    masks, systems: :class:`insnav.gnss.weighting.Weighting`) and an ``[spp]``
    table (:class:`insnav.gnss.spp.SppOptions`, for ``--filter spp``).  Run keys it sets override the loader's
    suggestions (initial sigmas, ``init_error = false``); a top-level
    ``lever_arm_b`` is also used as the dataset's lever arm.  Relative paths in
    the table (``imu_tag``, ``reference``) are relative to the TOML file.

    Returns
    -------
    (RinexDataset, RunConfig)
    """
    d = {}
    source = "run configuration"
    if config_path is not None:
        from ..config import read_toml

        source = os.fspath(config_path)
        d = read_toml(config_path)  # one line naming the file: unreadable, not TOML, not UTF-8
    rin = d.pop("rinex", {})
    if not isinstance(rin, dict):
        raise ConfigError(f"{source}: key 'rinex': bad value {rin!r}; allowed: a table")
    gnss = d.pop("gnss", {})
    if not isinstance(gnss, dict):
        raise ConfigError(f"{source}: key 'gnss': bad value {gnss!r}; allowed: a table")
    wgt = Weighting.from_dict(gnss, source)
    spp_opt = SppOptions.from_dict(d.pop("spp", {}) if isinstance(d.get("spp", {}), dict) else
                                   _bad_table(source, "spp", d["spp"]), source)
    if "lever_arm_b" in d and "lever_arm_b" not in rin:
        rin = dict(rin, lever_arm_b=d["lever_arm_b"])
    for key in ("imu_tag", "reference"):
        if isinstance(rin.get(key), str) and config_path is not None and not os.path.isabs(rin[key]):
            rin = dict(rin, **{key: os.path.join(os.path.dirname(os.path.abspath(config_path)), rin[key])})
    opt = RinexOptions.from_dict(rin, source)
    ds, cfg = load_rinex(obs, nav, imu, opt, imu_tag=imu_tag, reference=reference, weighting=wgt)
    ds.weighting, ds.spp_options = wgt, spp_opt
    base = {k: v for k, v in dataclasses.asdict(cfg).items() if v is not None and k != "imu"}
    base.update(d)
    return ds, config_from_dict(base, source=source)
