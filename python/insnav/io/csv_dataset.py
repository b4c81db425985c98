"""A user's own IMU and GNSS files, loosely coupled (``insnav run --format csv``).

:func:`load_csv_dataset` reads an IMU CSV (:mod:`insnav.io.imu_csv`: columns,
units, axes, time base) and a GNSS file (:mod:`insnav.io.gnss_files`: a CSV,
an RTKLIB ``.pos`` or NMEA GGA + RMC + GST), checks the units before anything
else (:mod:`insnav.data.checks`), finds the initial state from the data
(:func:`insnav.ins.align.align`: levelling, gyrocompassing when the grade
allows it, otherwise the GNSS course once moving) and returns a
:class:`~insnav.data.dataset.Dataset` and a :class:`~insnav.config.RunConfig`
whose initial covariance is the alignment's own sigmas.

The run TOML (``docs/formats.md``) holds the usual run keys plus:

* ``[imu]``: the IMU file mapping (fields of
  :class:`~insnav.io.imu_csv.ImuCsvFormat`, and ``tag``: a str2str time tag),
  the noise model: ``grade`` (:data:`insnav.data.imu_grades.IMU_GRADES`)
  and/or the noise keys of the run configuration's ``[imu]`` table
  (``gyro_arw_deg_per_sqrt_h`` ...; they override the grade's).  No noise
  model at all is an error, never a silent default.
* ``[gnss]``: the GNSS file (fields of :class:`~insnav.io.gnss_files.GnssFileFormat`).
* ``[initial]`` (optional): ``t_s``, ``lat_deg``, ``lon_deg``, ``h_m``
  (IMU centre), ``v_n_mps``, ``roll_deg``, ``pitch_deg``, ``yaw_deg``: any
  key given wins over the alignment; all of them given: no alignment.
* ``[align]`` (optional): ``min_speed_mps``, ``max_heading_sigma_deg``,
  ``slip_sigma_deg``, ``max_gyrocompass_sigma_deg`` of :func:`~insnav.ins.align.align`.

Time axis: with GPS-time files the dataset time (and the solution's ``t_s``)
is GPS seconds of week of the first GNSS fix, ``gps_time_offset_s = 604800
week``, as for ``--format rinex`` and KF-GINS; with ``time = "relative"`` in
both tables it is the files' own clock.

Unknown keys are :class:`~insnav.config.ConfigError` lines naming the table,
the key and the closest known key.
"""
from __future__ import annotations

from ..errors import close_matches

import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import _USER_UNITS, ConfigError, ImuNoise, RunConfig, config_from_dict, read_toml
from ..data.checks import (MAX_TIME_OFFSET_S, check_gnss, check_gnss_velocity, check_gyro_against_gnss,
                           check_heading_axes, check_imu, check_latlon_radians, check_time_offset,
                           check_time_overlap)
from ..data.dataset import Dataset, GnssFixes, ImuData, RowOrigin
from ..data.imu_grades import IMU_GRADES, imu_model_for_grade
from ..data.nav import NavState
from ..gnss.gpstime import SECONDS_PER_WEEK
from ..ins.align import Alignment, align, level
from .gnss_files import GnssFileFormat, GnssRecords, read_gnss, velocity_lag_warning
from .imu_csv import ImuCsvFormat, ImuSamples, read_imu_csv

__all__ = ["CsvDataset", "load_csv_dataset", "load_csv_run", "IMU_KEYS", "GNSS_KEYS", "INITIAL_KEYS", "ALIGN_KEYS",
           "initial_state_line"]

IMU_FORMAT_KEYS = tuple(f.name for f in dataclasses.fields(ImuCsvFormat))
#: keys of the [imu] table: the file mapping, the str2str tag, the grade and the noise keys
IMU_KEYS = IMU_FORMAT_KEYS + ("tag", "grade") + tuple(_USER_UNITS)
#: keys of the [gnss] table
GNSS_KEYS = tuple(f.name for f in dataclasses.fields(GnssFileFormat))
INITIAL_KEYS = ("t_s", "lat_deg", "lon_deg", "h_m", "v_n_mps", "roll_deg", "pitch_deg", "yaw_deg")
ALIGN_KEYS = ("min_speed_mps", "max_heading_sigma_deg", "slip_sigma_deg", "max_gyrocompass_sigma_deg", "course_window_s")
_TABLES = ("imu", "gnss", "initial", "align")
#: the noise figures a run needs when no grade is given (ARW, VRW, both bias sigmas)
_REQUIRED_NOISE = (("gyro_arw_deg_per_sqrt_h",), ("acc_vrw_m_per_s_per_sqrt_h", "acc_vrw_ug_per_sqrt_hz"),
                   ("gyro_bias_sigma_deg_per_h",), ("acc_bias_sigma_mg",))


@dataclass
class CsvDataset(Dataset):
    """A :class:`~insnav.data.dataset.Dataset` from a user's IMU and GNSS files.

    The attributes below are in addition to those of the Dataset.

    Attributes
    ----------
    alignment : insnav.ins.align.Alignment or None
        The alignment that gave the initial state (None: all of it given).
    info : dict
        Files, formats, counts, the time base and ``initial_state`` (a line for the run summary).
    """

    alignment: Alignment | None = None
    info: dict = field(default_factory=dict)


def _unknown(source: str, table: str, key: str, known) -> ConfigError:
    close = close_matches(key, list(known))
    name = f"{table}.{key}" if table else key
    hint = f" (did you mean '{table + '.' if table else ''}{close[0]}'?)" if close else ""
    return ConfigError(f"{source}: unknown key '{name}'{hint}; known keys: {', '.join(sorted(known))}")


def _table(d: dict, name: str, known, source: str) -> dict:
    t = d.get(name, {})
    if not isinstance(t, dict):
        raise ConfigError(f"{source}: key '{name}': bad value {t!r}; allowed: a table")
    for k in t:
        if k not in known:
            raise _unknown(source, name, k, known)
    return dict(t)


def _noise_model(imu_d: dict, source: str) -> tuple[ImuNoise, dict]:
    """The filter's IMU noise model from ``grade`` and/or explicit keys (never silently zero)."""
    grade = imu_d.get("grade")
    explicit = {k: v for k, v in imu_d.items() if k in _USER_UNITS}
    if grade is None and not explicit:
        raise ConfigError(f"{source}: no IMU noise model: set [imu] grade = {' | '.join(IMU_GRADES)} or the noise "
                          f"keys ({', '.join(k[0] for k in _REQUIRED_NOISE)}); a filter with zero IMU noise would "
                          "trust the IMU blindly")
    model = {}
    if grade is not None and not isinstance(grade, str):
        raise ConfigError(f"{source}: key 'imu.grade': bad value {grade!r}; allowed: {' | '.join(IMU_GRADES)}")
    if grade is not None:
        try:
            model = imu_model_for_grade(grade)
        except ValueError as exc:
            raise ConfigError(f"{source}: key 'imu.grade': {exc}") from None
        noise = ImuNoise.from_dataset_model(model, default_tau_s=IMU_GRADES[grade]["bias_tau_s"])
    else:
        missing = [alts[0] for alts in _REQUIRED_NOISE if not any(a in explicit for a in alts)]
        if missing:
            raise ConfigError(f"{source}: [imu] without grade needs {', '.join('imu.' + m for m in missing)} "
                              "(or a grade whose figures the keys then override)")
        noise = ImuNoise()
    for k, v in explicit.items():
        fld, factor = _USER_UNITS[k]
        try:
            arr = np.broadcast_to(np.asarray(v, dtype=float), (3,)) * factor
        except (TypeError, ValueError):
            arr = np.full(3, np.nan)
        if isinstance(v, bool) or not (np.all(arr >= 0) and np.all(np.isfinite(arr))):
            raise ConfigError(f"{source}: key 'imu.{k}': bad value {v!r}; allowed: values >= 0")
        setattr(noise, fld, arr.tolist())
    return noise, model


def _labels(fmt: ImuCsvFormat, path: str) -> tuple[str, str]:
    """How the messages name the accelerometer and gyro columns of the user's file."""
    def names(roles):
        if isinstance(fmt.columns, dict):
            return ",".join(fmt.columns[r] for r in roles)
        cols = list(fmt.columns)
        return ",".join(f"{r} (field {cols.index(r) + 1})" for r in roles)
    return (f"columns {names(('ax', 'ay', 'az'))} [acc_unit {fmt.acc_unit}, samples {fmt.samples}]",
            f"columns {names(('gx', 'gy', 'gz'))} [gyro_unit {fmt.gyro_unit}, samples {fmt.samples}]")


def _fixes(fmt: ImuCsvFormat) -> dict:
    """The setting that fixes each cause a check can name."""
    out = {"axes": '[imu] axes = "FLU" if the IMU\'s x axis points forward, "RFU" if it points right (the axes '
                   'the IMU has: three of F/B, R/L, D/U; a wrong x turns every heading by 90 deg)',
           "inverted": "check [imu] axes / mount_rpy_deg",
           "t_ms": '[imu] time_unit = "ms"?'}
    if fmt.acc_unit != "g":
        out["acc_g"] = '[imu] acc_unit = "g"'
    if fmt.gyro_unit != "dps":
        out["gyro_deg"] = '[imu] gyro_unit = "deg"'
    if fmt.samples == "increment":
        out["dv_rate"] = out["dtheta_rate"] = '[imu] samples = "rates"'
    else:
        out["dv_increment"] = '[imu] samples = "increments"'
    return out


def _with_velocity(g: GnssFixes) -> GnssFixes:
    """The fixes with a horizontal velocity from central position differences
    where the file gave none (for the alignment's course only), sigma
    ``sqrt(2) sigma_pos / (t[k+1] - t[k-1])``."""
    v = np.array(g.v_n, float)
    sv = np.array(g.sigma_vel_n, float)
    miss = ~np.all(np.isfinite(v[:, :2]), axis=1)
    if not miss.any() or len(g) < 3:
        return g
    lat = np.radians(g.lat_deg)
    from ..earth import radii

    R_M, R_N = radii(lat)
    n = (lat - lat[0]) * (R_M + g.h_m)
    e = np.radians(g.lon_deg - g.lon_deg[0]) * (R_N + g.h_m) * np.cos(lat)
    t = np.asarray(g.t_valid, float)
    vn, ve = np.gradient(n, t), np.gradient(e, t)
    span = np.gradient(t) * 2.0
    s = np.sqrt(2.0) * np.maximum(g.sigma_pos_n[:, 0], g.sigma_pos_n[:, 1]) / span
    v[miss, 0], v[miss, 1] = vn[miss], ve[miss]
    sv[miss, 0] = sv[miss, 1] = s[miss]
    sv[miss, 2] = np.nan
    return dataclasses.replace(g, v_n=v, sigma_vel_n=sv)


def initial_state_line(ds) -> str:
    """One line for the run summary: where the initial state came from, and its 1-sigma."""
    s, a = ds.initial, getattr(ds, "alignment", None)
    given = ds.info.get("initial_given", [])
    how = "given in [initial]" if a is None else (
        f"alignment: heading from {a.heading_source.replace('_', ' ')}, {a.static_s:.1f} s static"
        + (f"; [initial] {', '.join(given)}" if given else ""))
    sig = ds.info.get("initial_sigma", {})
    txt = (f"initial state at t = {ds.t0:.3f} s ({how}): {s.lat_deg:.8f} {s.lon_deg:.8f} {s.h_m:.3f} m, "
           f"v_n {np.round(s.v_n, 3).tolist()} m/s, roll/pitch/yaw {s.roll_deg:.2f} {s.pitch_deg:.2f} "
           f"{s.yaw_deg:.2f} deg")
    if sig:
        txt += (f"; 1-sigma pos {np.round(sig['pos_m'], 2).tolist()} m, vel {np.round(sig['vel_mps'], 3).tolist()} "
                f"m/s, att {np.round(sig['att_deg'], 2).tolist()} deg")
    return txt


def _fallback_attitude(imu: ImuData, gnss: GnssFixes, ini: dict, exc: Exception, accel_bias_sigma: float):
    """Levelling over the first second when the alignment finds no heading but
    [initial] gives the yaw; roll/pitch 1-sigma the levelling limit b_a / g
    (and 0.5 deg for motion in that second), yaw 5 deg."""
    if "yaw_deg" not in ini:
        raise exc
    dt = np.diff(np.concatenate([[2 * imu.t[0] - imu.t[1]], imu.t]))
    n1 = max(2, int(round(1.0 / np.median(dt))))
    roll, pitch = level(imu.dv_b[:n1].sum(axis=0) / dt[:n1].sum())
    idx = n1 - 1
    sig_level = float(np.hypot(np.degrees(accel_bias_sigma / 9.80665), 0.5))
    g = int(np.argmin(np.abs(gnss.t_valid - imu.t[idx])))
    v = np.nan_to_num(np.asarray(gnss.v_n[g], float))
    return Alignment(t_s=float(imu.t[idx]), index=idx, lat_deg=float(gnss.lat_deg[g]), lon_deg=float(gnss.lon_deg[g]),
                     h_m=float(gnss.h_m[g]), v_n_mps=v, roll_deg=float(np.degrees(roll)),
                     pitch_deg=float(np.degrees(pitch)), yaw_deg=float(ini["yaw_deg"]),
                     sigma_pos_n_m=np.asarray(gnss.sigma_pos_n[g], float), sigma_vel_n_mps=np.full(3, 0.5),
                     sigma_att_deg=np.array([sig_level, sig_level, 5.0]), heading_source="given", static_s=0.0,
                     notes=[f"alignment failed ({exc}); levelled over the first second, yaw from [initial]"],
                     samples_used=n1)


def load_csv_dataset(imu, gnss, config=None, *, imu_tag=None) -> tuple[CsvDataset, RunConfig]:
    """Build a dataset and a run configuration from a user's IMU and GNSS files.

    Parameters
    ----------
    imu : path
        IMU CSV (mapping: the ``[imu]`` table).
    gnss : path
        GNSS fixes: CSV, RTKLIB ``.pos`` or NMEA (``[gnss]`` table; by suffix).
    config : path, dict or None
        The run TOML (or its dict): run keys plus ``[imu]``, ``[gnss]``,
        ``[initial]``, ``[align]`` (module docstring).  ``[imu]`` must give a
        noise model (``grade`` or the noise keys).
    imu_tag : path, optional
        str2str time tag (``tick_ms`` column); overrides ``[imu] tag``.

    Returns
    -------
    dataset : CsvDataset
        Initial state from the alignment (or ``[initial]``), ``t0`` its time;
        IMU samples and fixes after ``t0``.
    config : RunConfig
        Loose EKF, ``init_error = false``, initial sigmas from the alignment
        (run keys of the TOML override them), ``imu`` the noise model.

    Raises
    ------
    insnav.config.ConfigError
        Unknown keys (with the closest known one), bad values, no noise model.
    insnav.io.imu_csv.ImuFileError, insnav.io.gnss_files.GnssFileError
        Malformed files (file and line).
    insnav.data.checks.DataCheckError
        Units, axes, signs or time bases that cannot be right (file, column, evidence).
    ValueError
        No alignment possible (no static start and no motion, no fixes).
    """
    inp = csv_inputs(imu, gnss, config, imu_tag=imu_tag)
    samples: ImuSamples = read_imu_csv(imu, inp.fmt, tag=inp.tag, week=inp.week)
    check_time_base(inp, samples.info.get("time_base", "gps"))
    imu_all = samples.to_increments(inp.offset)
    # -- checks before the alignment (wrong units make a wrong initial state, not a clear error)
    input_checks(inp, imu_all, samples.path)
    t0, initial, sig, a = initial_state(inp, imu_all, samples.path)
    sel = imu_all.t > t0
    if sel.sum() < 2:
        raise ValueError(f"{samples.path}: no IMU data after the initial time {t0:.3f} s")
    imu_run = ImuData(imu_all.t[sel], imu_all.dtheta_b[sel], imu_all.dv_b[sel],
                      origin=imu_all.origin.take(sel, len(imu_all.t)))
    gnss_all = inp.gnss_all
    gsel = (gnss_all.t_valid > t0) & (gnss_all.t_valid <= imu_run.t[-1])
    gnss_run = GnssFixes(*(np.asarray(getattr(gnss_all, f.name))[gsel] for f in dataclasses.fields(GnssFixes)
                           if f.name != "origin"), origin=gnss_all.origin.take(gsel, len(gnss_all)))
    ds, cfg = csv_run_dataset(inp, samples.path, t0, initial, sig, a, imu=imu_run, gnss=gnss_run)
    ds.info.update(imu_samples=len(samples), imu_rate_hz=samples.rate_hz, imu_time=samples.info)
    return ds, cfg


@dataclass
class CsvInputs:
    """What ``--format csv`` knows before its IMU file is read (:func:`csv_inputs`): the
    TOML's tables, the noise model, the IMU mapping and every GNSS fix."""

    source: str
    d: dict
    imu_d: dict
    gnss_d: dict
    ini: dict
    align_d: dict
    noise: ImuNoise
    model: dict
    fmt: ImuCsvFormat
    gfmt: GnssFileFormat
    tag: object
    rec: GnssRecords
    week: int | None
    offset: float
    gnss_all: GnssFixes
    gnss_al: GnssFixes


def csv_inputs(imu, gnss, config=None, *, imu_tag=None) -> CsvInputs:
    """The run TOML parsed and checked, and the GNSS file read (:func:`load_csv_dataset`'s first step)."""
    source = "run configuration"
    base_dir = None
    if config is None:
        d = {}
    elif isinstance(config, dict):
        d = dict(config)
    else:
        source = os.fspath(config)
        base_dir = os.path.dirname(os.path.abspath(source))
        d = read_toml(config)  # one line naming the file: unreadable, not TOML, not UTF-8
    run_keys = {f.name for f in dataclasses.fields(RunConfig)}
    for k in d:
        if k not in run_keys and k not in _TABLES:
            raise _unknown(source, "", k, run_keys | set(_TABLES))
    imu_d = _table(d, "imu", IMU_KEYS, source)
    gnss_d = _table(d, "gnss", GNSS_KEYS, source)
    ini = _table(d, "initial", INITIAL_KEYS, source)
    align_d = _table(d, "align", ALIGN_KEYS, source)
    for k, v in list(ini.items()) + list(align_d.items()):
        try:
            vals = np.atleast_1d(np.asarray(v, dtype=float)) if not isinstance(v, (str, bool)) else np.array([np.nan])
        except (TypeError, ValueError):  # a table or a nested list where numbers belong
            vals = np.array([np.nan])
        if not np.all(np.isfinite(vals)) or (k == "v_n_mps" and vals.shape != (3,)) or \
                (k != "v_n_mps" and vals.shape != (1,)):
            raise ConfigError(f"{source}: key '{'initial' if k in INITIAL_KEYS else 'align'}.{k}': bad value {v!r}; "
                              f"allowed: {'3 numbers' if k == 'v_n_mps' else 'a finite number'}")
    noise, model = _noise_model(imu_d, source)
    fmt = ImuCsvFormat(**{k: v for k, v in imu_d.items() if k in IMU_FORMAT_KEYS})
    fmt.validate(source, prefix="imu.")
    gfmt = GnssFileFormat(**gnss_d).validate(source)
    tag = imu_tag if imu_tag is not None else imu_d.get("tag")
    if isinstance(tag, str) and base_dir is not None and not os.path.isabs(tag):
        tag = os.path.join(base_dir, tag)

    rec: GnssRecords = read_gnss(gnss, gfmt)
    week = None
    if rec.time_base == "gps":
        week = int(math.floor((rec.t_ref_s + rec.t_s[0]) / SECONDS_PER_WEEK))
    offset = SECONDS_PER_WEEK * week if week is not None else 0.0
    t_g = (rec.t_ref_s - offset) + rec.t_s
    gnss_all = GnssFixes(t_g, t_g.copy(), rec.lat_deg, rec.lon_deg, rec.h_m, rec.v_n, rec.sigma_pos_n,
                         rec.sigma_vel_n, origin=RowOrigin(rec.path, lines=rec.lines))
    return CsvInputs(source, d, imu_d, gnss_d, ini, align_d, noise, model, fmt, gfmt, tag, rec, week, float(offset),
                     gnss_all, _with_velocity(gnss_all))


def check_time_base(inp: CsvInputs, imu_time_base: str) -> None:
    """Both files on the same clock (GPS time or the same relative clock)."""
    if imu_time_base != inp.rec.time_base:
        raise ConfigError(f"{inp.source}: [imu] time = {inp.fmt.time!r} ({imu_time_base}) but the GNSS "
                          f"file {inp.rec.path} is in {'GPS time' if inp.rec.time_base == 'gps' else 'relative time'}: "
                          "both need the same clock")


def gnss_checks(inp: CsvInputs) -> None:
    """The checks of the GNSS fixes alone (units, signs, velocities)."""
    rec = inp.rec
    if rec.format == "csv" and inp.gfmt.angle_unit is None:
        check_latlon_radians(rec.lat_deg, rec.lon_deg, source=rec.path)
    check_gnss(inp.gnss_all, source=rec.path)
    check_gnss_velocity(inp.gnss_all, source=rec.path)


def imu_unit_checks(inp: CsvInputs, imu: ImuData, imu_path: str) -> None:
    """The IMU's own unit and rate checks (:func:`insnav.data.checks.check_imu`), naming the mapped columns."""
    acc_label, gyro_label = _labels(inp.fmt, imu_path)
    check_imu(imu.t, imu.dtheta_b, imu.dv_b, source=imu_path, acc_label=acc_label, gyro_label=gyro_label,
              fixes=_fixes(inp.fmt))


def input_checks(inp: CsvInputs, imu_all: ImuData, imu_path: str) -> None:
    """The unit, axis, sign and time-base checks of the IMU against the GNSS (before the alignment)."""
    fmt, rec, gnss_al = inp.fmt, inp.rec, inp.gnss_al
    acc_label, gyro_label = _labels(fmt, imu_path)
    fixes = _fixes(fmt)
    imu_unit_checks(inp, imu_all, imu_path)
    check_time_overlap(imu_all.t, inp.gnss_all.t_valid, imu_source=f"{imu_path} [imu] time = {fmt.time!r}",
                       gnss_source=f"{rec.path} ({rec.format})")
    gnss_checks(inp)
    mto = inp.d.get("max_time_offset_s", MAX_TIME_OFFSET_S)  # a bad value: the run configuration's error below
    if isinstance(mto, (int, float)) and not isinstance(mto, bool) and mto > 0:
        check_time_offset(imu_all.t, imu_all.dtheta_b, imu_all.dv_b, gnss_al, max_offset_s=float(mto),
                          source=imu_path, gnss_source=rec.path, fix="[imu] time_offset_s")
    check_gyro_against_gnss(imu_all.t, imu_all.dtheta_b, imu_all.dv_b, gnss_al, source=imu_path,
                            gyro_label=gyro_label, fixes=dict(fixes, inverted="or the lat/lon signs are flipped; "
                                                              "check [imu] axes and the GNSS signs"))
    if "yaw_deg" not in inp.ini:  # the heading will come from the GNSS course: body x must be forward
        check_heading_axes(imu_all.t, imu_all.dtheta_b, imu_all.dv_b, gnss_al, source=imu_path,
                           fix="map the axes so that x is forward: [imu] axes (e.g. \"RFU\") or mount_rpy_deg")


def initial_state(inp: CsvInputs, imu_all: ImuData, imu_path: str):
    """(t0 [s], the initial NavState, its 1-sigma dict, the Alignment or None): ``[initial]``
    when it gives the whole state, else :func:`insnav.ins.align.align` (``[initial]`` keys win)."""
    ini, noise, d = inp.ini, inp.noise, inp.d
    lever = np.asarray(d.get("lever_arm_b", (0.0, 0.0, 0.0)), float)
    full = all(k in ini for k in INITIAL_KEYS[1:])
    a = None
    if full:
        t0 = float(ini.get("t_s", imu_all.t[0]))
        initial = NavState(float(ini["lat_deg"]), float(ini["lon_deg"]), float(ini["h_m"]),
                           np.asarray(ini["v_n_mps"], float), float(ini["roll_deg"]), float(ini["pitch_deg"]),
                           float(ini["yaw_deg"]))
        sig = dict(pos_m=[2.0, 2.0, 3.0], vel_mps=[0.1, 0.1, 0.1], att_deg=[1.0, 1.0, 5.0])
    else:
        if "t_s" in ini:
            raise ConfigError(f"{inp.source}: key 'initial.t_s' needs the whole initial state "
                              f"({', '.join(INITIAL_KEYS[1:])}); without it the alignment chooses the time")
        gyro_bias = float(np.max(noise.gyro_bias_sigma))
        try:
            a = align(imu_all.t, imu_all.dtheta_b, imu_all.dv_b, inp.gnss_al, gyro_bias_sigma=gyro_bias,
                      gyro_arw=float(np.max(noise.gyro_arw)), accel_bias_sigma=float(np.max(noise.acc_bias_sigma)),
                      lever_arm_b=lever, source=imu_path, accel_vrw=float(np.max(noise.acc_vrw)), **inp.align_d)
        except ValueError as exc:
            a = _fallback_attitude(imu_all, inp.gnss_al, ini, exc, float(np.max(noise.acc_bias_sigma)))
        t0 = a.t_s
        vals = dict(lat_deg=a.lat_deg, lon_deg=a.lon_deg, h_m=a.h_m, v_n_mps=np.asarray(a.v_n_mps, float),
                    roll_deg=a.roll_deg, pitch_deg=a.pitch_deg, yaw_deg=a.yaw_deg)
        vals.update({k: (np.asarray(v, float) if k == "v_n_mps" else float(v)) for k, v in ini.items()})
        initial = NavState(vals["lat_deg"], vals["lon_deg"], vals["h_m"], np.nan_to_num(vals["v_n_mps"]),
                           vals["roll_deg"], vals["pitch_deg"], vals["yaw_deg"])
        sig = dict(pos_m=np.maximum(a.sigma_pos_n_m, 0.01).tolist(),
                   vel_mps=np.maximum(np.nan_to_num(a.sigma_vel_n_mps, nan=1.0), 0.01).tolist(),
                   att_deg=np.maximum(a.sigma_att_deg, 0.05).tolist())
    return t0, initial, sig, a


def csv_run_dataset(inp: CsvInputs, imu_path: str, t0: float, initial, sig: dict, a, *, imu, gnss):
    """The CsvDataset (``imu`` / ``gnss`` the run's; None for a block-by-block run) and the run configuration."""
    d, ini = inp.d, inp.ini
    rec = inp.rec
    lever = np.asarray(d.get("lever_arm_b", (0.0, 0.0, 0.0)), float)
    info = dict(imu=imu_path, gnss=rec.path, gnss_format=rec.format, gnss_fixes=len(rec), time_base=rec.time_base,
                week=inp.week, gnss_info=rec.info, initial_given=sorted(ini), initial_sigma=sig,
                noise_grade=inp.imu_d.get("grade"),
                tables=dict(imu={k: v for k, v in inp.imu_d.items() if k in IMU_FORMAT_KEYS}
                            | ({"tag": os.path.abspath(inp.tag)} if isinstance(inp.tag, str) and "tag" in inp.imu_d
                               else {}),  # resolved against the TOML's folder: the saved config re-runs anywhere
                            gnss=inp.gnss_d, initial=ini, align=inp.align_d))
    ds = CsvDataset(imu=imu, gnss=gnss, truth=None, gnss_raw=None, imu_errors=None,
                    scenario={"csv": dict(imu=imu_path, gnss=rec.path)}, lever_arm_b=lever, initial=initial,
                    t0=float(t0), gps_time_offset_s=float(inp.offset), imu_model=inp.model, name=Path(imu_path).stem,
                    alignment=a, info=info)
    ds.info["initial_state"] = initial_state_line(ds)
    lag_warning = velocity_lag_warning(rec)  # velocities that visibly lag their own positions
    ds.info["warnings"] = [lag_warning] if lag_warning else []
    return ds, csv_run_config(inp, sig)


def csv_run_config(inp: CsvInputs, sig: dict | None = None) -> RunConfig:
    """The run configuration: loose EKF, no initial error, the initial sigmas ``sig`` (the
    alignment's; None: the defaults), the TOML's run keys over them, the noise model."""
    base = dict(filter="ekf", coupling="loose", init_error=False)
    if sig is not None:
        base.update(init_sigma_pos_m=list(map(float, sig["pos_m"])),
                    init_sigma_vel_mps=list(map(float, sig["vel_mps"])),
                    init_sigma_att_deg=list(map(float, sig["att_deg"])))
    base.update({k: v for k, v in inp.d.items() if k not in _TABLES})
    cfg = config_from_dict(base, source=inp.source)
    cfg.imu = inp.noise
    return cfg


def load_csv_run(imu, gnss, config_path=None, *, imu_tag=None):
    """:func:`load_csv_dataset` for ``insnav run --format csv`` (the same arguments)."""
    return load_csv_dataset(imu, gnss, config_path, imu_tag=imu_tag)
