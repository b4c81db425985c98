"""Scenario files: TOML parsing, validation and conversion to SI.

A scenario is a TOML document (see ``python/insnav/scenarios/*.toml`` for
complete, commented examples).  User units appear only in the key names
(``_deg``, ``_dph``, ``_mg``, ``_ppm`` ...) and are converted here, once, into
the SI dataclasses below; everything downstream works in SI.

Every error is a :class:`ScenarioError` whose message names the file, the
dotted key (``motion.segments[3].turn_rate_dps``), the offending value and
what was expected.

Layout (all tables optional unless marked)::

    name, description, seed, extends       # extends = "preset-name" or a path
    [time]    t0_s, gps_week, gps_tow_s
    [initial] lat_deg*, lon_deg*, h_m*, speed_mps, heading_deg, path_angle_deg,
              roll_deg, pitch_deg, yaw_deg
    [motion]  transition_s, coordinated_turns, g_ref_mps2, lateral_slip_mps,
              vertical_bounce_mps
    [[motion.segments]] duration_s*, label,
              accel_mps2 | target_speed_mps | speed_change_mps,
              turn_rate_dps | heading_change_deg,
              path_angle_rate_dps | target_path_angle_deg | path_angle_change_deg,
              roll_amp_deg, roll_period_s, pitch_amp_deg, pitch_period_s,
              yaw_amp_deg, yaw_period_s
    [[motion.oscillations]] axis*, amp_deg*, period_s*, start_s*, end_s*, phase_deg
    [imu]     rate_hz, quadrature_nodes, errors_rate_hz
    [imu.gyro] / [imu.accel]   error model, see _GYRO_KEYS / _ACCEL_KEYS
    [truth]   rate_hz
    [gnss]    enabled, rate_hz, lever_arm_b_m, sigma_h_m, sigma_v_m,
              sigma_vel_mps, outages, delay_p, delay_model, first_epoch_s
    [gnss_raw] enabled, rate_hz, constellation, elevation_mask_deg, max_sats,
              sigma_pr_m, sigma_prr_mps, clock_bias0_m, clock_drift0_mps,
              clock_bias_rw_m_per_sqrts, clock_drift_rw_mps_per_sqrts,
              clock ("tcxo" | "ocxo" | "rubidium": both densities, see sim/gnss_raw.py),
              systems (list of "G", "E", "C"; default ["G"])
    [gnss_raw.isb_m] E, C: true inter-system biases [m] (GPS the reference clock)
    [gnss_raw.urban_canyon] mask_across_deg*, mask_along_deg, street_azimuth_deg
              (absent: the street runs along the vehicle's heading; sim/gnss_raw.urban_canyon_mask)
    [[gnss_raw.windows]] start_s*, end_s*, n_sats*
    [gnss_rtk] rover and base carrier phase (insnav.sim.gnss_rtk; keys in _RTK_KEYS,
              docs/formats.md), [gnss_rtk.signals] G, E, [gnss_rtk.base] lat_deg/lon_deg/h_m
              or offset_ned_m, [gnss_rtk.urban_canyon] as [gnss_raw.urban_canyon]
"""
from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from ..units import DEG, DEG_PER_SQRT_H, G0, MG, PPM
from .._toml import dumps_toml  # noqa: F401  (part of this module's API)

# --- unit conversion constants (user units -> SI) -------------------------
HOUR = 3600.0  #: [s/h]
DPH = DEG / HOUR  #: deg/h -> rad/s
DPH_PER_SQRT_H = DPH / math.sqrt(HOUR)  #: deg/h/sqrt(h) -> rad/s/sqrt(s)
UG = 1e-6 * G0  #: ug -> m/s^2
UG_PER_SQRT_HZ = UG  #: ug/sqrt(Hz) -> (m/s^2)/sqrt(Hz) = (m/s)/sqrt(s)
MPS_PER_SQRT_H = 1.0 / math.sqrt(HOUR)  #: (m/s)/sqrt(h) -> (m/s)/sqrt(s)
MG_PER_SQRT_H = MG / math.sqrt(HOUR)  #: mg/sqrt(h) -> m/s^2/sqrt(s)
MRAD = 1e-3  #: mrad -> rad

PRESET_PACKAGE = "insnav.scenarios"


class ScenarioError(ValueError):
    """A scenario file is invalid; the message names the key and the reason."""


# --- SI dataclasses -------------------------------------------------------
@dataclass
class Segment:
    """One motion segment, rates in SI.

    ``accel`` [m/s^2], ``turn_rate`` [rad/s], ``path_angle_rate`` [rad/s] are
    the commanded (piecewise-constant) rates; the trajectory smooths the steps
    between segments (see :mod:`insnav.sim.trajectory`).
    """

    duration: float
    accel: float = 0.0
    turn_rate: float = 0.0
    path_angle_rate: float = 0.0
    label: str = ""


@dataclass
class Oscillation:
    """Sinusoidal attitude oscillation ``amp * E(t) * sin(2 pi (t - start)/period + phase)``.

    ``axis`` is ``'roll'``, ``'pitch'`` or ``'yaw'``; ``amp`` [rad], ``period``,
    ``start``, ``end`` [s], ``phase`` [rad].  ``E`` is a C2 envelope rising over
    the first and falling over the last transition time of ``[start, end]``.
    """

    axis: str
    amp: float
    period: float
    start: float
    end: float
    phase: float = 0.0


@dataclass
class SensorErrors:
    """Error model of one sensor triad (gyro or accelerometer), SI units.

    Bias-like quantities are in rad/s (gyro) or m/s^2 (accel); noise densities
    in rad/sqrt(s) (gyro ARW) or (m/s)/sqrt(s) (accel VRW); random-walk rates
    per sqrt(s); GM time constants in s; scale factors and misalignments
    dimensionless (rad for misalignment).  All arrays are per body axis (3,),
    misalignment is a (3, 3) matrix with zero diagonal.
    """

    bias: np.ndarray  #: deterministic constant bias
    bias_sigma: np.ndarray  #: sigma of the random constant (turn-on) bias
    gm_sigma: np.ndarray  #: steady-state sigma of the 1st-order Gauss-Markov bias
    gm_tau: np.ndarray  #: GM correlation time [s] (inf when unused)
    bias_rw: np.ndarray  #: bias random walk [unit/sqrt(s)]
    noise_density: np.ndarray  #: white noise density (ARW / VRW) [unit*sqrt(s)]
    scale: np.ndarray  #: deterministic scale-factor error [-]
    scale_sigma: np.ndarray  #: sigma of the random scale-factor error [-]
    misalignment: np.ndarray  #: deterministic misalignment (3, 3) [rad]
    misalignment_sigma: float  #: sigma of random off-diagonal misalignment [rad]


@dataclass
class Scenario:
    """A validated scenario in SI units.

    ``raw`` keeps the resolved TOML dictionary (after ``extends`` merging),
    which is what :meth:`insnav.data.dataset.Dataset.save` writes back as
    ``scenario.toml``.
    """

    name: str
    description: str
    seed: int
    t0: float
    gps_time_offset_s: float
    lat0: float
    lon0: float
    h0: float
    speed0: float
    heading0: float
    path_angle0: float
    roll_offset: float
    pitch_offset: float
    yaw_offset: float
    segments: list[Segment]
    oscillations: list[Oscillation]
    transition: float
    coordinated_turns: bool
    g_ref: float
    imu_rate: float
    quadrature_nodes: int
    errors_rate: float
    gyro: SensorErrors
    accel: SensorErrors
    truth_rate: float
    gnss: dict[str, Any]
    gnss_raw: dict[str, Any]
    #: RMS body-frame lateral / vertical velocity of a road vehicle [m/s]
    #: (wheel slip, suspension bounce; faded out at standstill)
    lateral_slip: float = 0.0
    vertical_bounce: float = 0.0
    #: odometer sensor (see insnav.sim.odometer), SI; None = no odometer
    odometer: dict[str, Any] | None = None
    #: carrier-phase rover/base simulation (see insnav.sim.gnss_rtk), SI; None = none
    gnss_rtk: dict[str, Any] | None = None
    raw: dict[str, Any] = field(repr=False, default_factory=dict)
    source: str = ""

    @property
    def duration(self) -> float:
        """Total duration of the motion [s]."""
        return float(sum(s.duration for s in self.segments))

    @property
    def t_end(self) -> float:
        """End time of the scenario [s]."""
        return self.t0 + self.duration


# --- helpers --------------------------------------------------------------
class _Ctx:
    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, reason: str) -> None:
        raise ScenarioError(f"scenario {self.source}: key '{key}': {reason}")


def _check_keys(ctx: _Ctx, table: dict, prefix: str, allowed: set[str]) -> None:
    for k in table:
        if k not in allowed:
            ctx.fail(_join(prefix, k), "unknown key; allowed keys here are: "
                     + ", ".join(sorted(allowed)))


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _num(ctx, table, prefix, key, default=None, *, required=False, lo=None, hi=None,
         lo_open=False, integer=False):
    name = _join(prefix, key)
    if key not in table:
        if required:
            ctx.fail(name, "missing (required)")
        return default
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        ctx.fail(name, f"expected a number, got {v!r}")
    if integer and (not float(v).is_integer()):
        ctx.fail(name, f"expected an integer, got {v!r}")
    if integer and isinstance(v, int):  # exact: a seed above 2**53 is not rounded through a float
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            ctx.fail(name, f"value {v!r} out of range: must be >= {lo}" + (f" and <= {hi}" if hi is not None else ""))
        return v
    v = float(v)
    if not math.isfinite(v):
        ctx.fail(name, f"expected a finite number, got {v!r}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        ctx.fail(name, f"value {v!r} out of range: must be {'>' if lo_open else '>='} {lo}")
    if hi is not None and v > hi:
        ctx.fail(name, f"value {v!r} out of range: must be <= {hi}")
    return int(v) if integer else v


def _vec3(ctx, table, prefix, key, default=0.0, *, lo=None):
    """A per-axis quantity: a scalar (all axes) or a list of 3 numbers."""
    name = _join(prefix, key)
    if key not in table:
        return np.full(3, float(default))
    v = table[key]
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        arr = np.full(3, float(v))
    elif isinstance(v, list) and len(v) == 3 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        arr = np.array(v, dtype=float)
    else:
        ctx.fail(name, f"expected a number or a list of 3 numbers (x, y, z body axes), got {v!r}")
    if not np.all(np.isfinite(arr)):
        ctx.fail(name, f"values must be finite, got {v!r}")
    if lo is not None and np.any(arr < lo):
        ctx.fail(name, f"values {v!r} out of range: must be >= {lo}")
    return arr


def _bool(ctx, table, prefix, key, default):
    if key not in table:
        return default
    v = table[key]
    if not isinstance(v, bool):
        ctx.fail(_join(prefix, key), f"expected true or false, got {v!r}")
    return v


def _str(ctx, table, prefix, key, default):
    if key not in table:
        return default
    v = table[key]
    if not isinstance(v, str):
        ctx.fail(_join(prefix, key), f"expected a string, got {v!r}")
    return v


def _table(ctx, table, prefix, key):
    v = table.get(key, {})
    if not isinstance(v, dict):
        ctx.fail(_join(prefix, key), f"expected a table, got {v!r}")
    return v


def _exclusive(ctx, table, prefix, keys):
    present = [k for k in keys if k in table]
    if len(present) > 1:
        ctx.fail(_join(prefix, present[1]),
                 f"conflicts with '{_join(prefix, present[0])}': give only one of "
                 + ", ".join(keys))
    return present[0] if present else None


# --- IMU error tables -----------------------------------------------------
#: gyro keys -> (SI field, conversion factor).  White noise may be given as a
#: density (arw_deg_per_sqrth) or as the 1-sigma rate noise per sample at the
#: IMU rate (white_dph, the way the seed papers state it).
_GYRO_KEYS = {
    "bias_dph": ("bias", DPH),
    "bias_sigma_dph": ("bias_sigma", DPH),
    "gm_sigma_dph": ("gm_sigma", DPH),
    "gm_tau_s": ("gm_tau", 1.0),
    "rw_dph_per_sqrth": ("bias_rw", DPH_PER_SQRT_H),
    "arw_deg_per_sqrth": ("noise_density", DEG_PER_SQRT_H),
    "white_dph": ("white", DPH),
    "scale_ppm": ("scale", PPM),
    "scale_sigma_ppm": ("scale_sigma", PPM),
    "misalignment_mrad": ("misalignment", MRAD),
    "misalignment_sigma_mrad": ("misalignment_sigma", MRAD),
}
_ACCEL_KEYS = {
    "bias_mg": ("bias", MG),
    "bias_sigma_mg": ("bias_sigma", MG),
    "gm_sigma_mg": ("gm_sigma", MG),
    "gm_tau_s": ("gm_tau", 1.0),
    "rw_mg_per_sqrth": ("bias_rw", MG_PER_SQRT_H),
    "vrw_ug_per_sqrthz": ("noise_density", UG_PER_SQRT_HZ),
    "vrw_mps_per_sqrth": ("noise_density", MPS_PER_SQRT_H),
    "white_mg": ("white", MG),
    "scale_ppm": ("scale", PPM),
    "scale_sigma_ppm": ("scale_sigma", PPM),
    "misalignment_mrad": ("misalignment", MRAD),
    "misalignment_sigma_mrad": ("misalignment_sigma", MRAD),
}


def _sensor(ctx, table, prefix, keys, imu_rate) -> SensorErrors:
    _check_keys(ctx, table, prefix, set(keys))
    out: dict[str, Any] = {}
    for key, (fld, k) in keys.items():
        if key not in table:
            continue
        if fld == "misalignment":
            v = table[key]
            if not (isinstance(v, list) and len(v) == 6 and all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
                ctx.fail(_join(prefix, key), "expected 6 numbers [xy, xz, yx, yz, zx, zy] "
                         f"(off-diagonal elements of the misalignment matrix), got {v!r}")
            M = np.zeros((3, 3))
            M[0, 1], M[0, 2], M[1, 0], M[1, 2], M[2, 0], M[2, 1] = (float(x) * k for x in v)
            out[fld] = M
        elif fld == "misalignment_sigma":
            out[fld] = _num(ctx, table, prefix, key, lo=0.0) * k
        elif fld == "gm_tau":
            out[fld] = _vec3(ctx, table, prefix, key, lo=0.0) * k
            if np.any(out[fld] <= 0):
                ctx.fail(_join(prefix, key), "correlation time must be > 0 s")
        else:
            lo = None if fld in ("bias", "scale") else 0.0
            out[fld] = _vec3(ctx, table, prefix, key, lo=lo) * k
    if "noise_density" in out and "white" in out:
        ctx.fail(_join(prefix, [k for k, f in keys.items() if f[0] == "white"][0]),
                 "give the white noise either as a density or as a per-sample sigma, not both")
    dens = [k for k, f in keys.items() if f[0] == "noise_density" and k in table]
    if len(dens) > 1:
        ctx.fail(_join(prefix, dens[1]), f"conflicts with '{_join(prefix, dens[0])}'")
    if "white" in out:  # per-sample rate sigma at the IMU rate -> density
        out["noise_density"] = out.pop("white") / math.sqrt(imu_rate)
    if "gm_sigma" in out and "gm_tau" not in out and np.any(out["gm_sigma"] > 0):
        ctx.fail(_join(prefix, "gm_tau_s"), "missing: required when gm_sigma_* is given")
    z = np.zeros(3)
    return SensorErrors(
        bias=out.get("bias", z.copy()), bias_sigma=out.get("bias_sigma", z.copy()),
        gm_sigma=out.get("gm_sigma", z.copy()), gm_tau=out.get("gm_tau", np.full(3, np.inf)),
        bias_rw=out.get("bias_rw", z.copy()), noise_density=out.get("noise_density", z.copy()),
        scale=out.get("scale", z.copy()), scale_sigma=out.get("scale_sigma", z.copy()),
        misalignment=out.get("misalignment", np.zeros((3, 3))),
        misalignment_sigma=float(out.get("misalignment_sigma", 0.0)))


# --- loading ----------------------------------------------------------------
def list_presets() -> list[str]:
    """Names of the preset scenarios shipped in ``insnav/scenarios``."""
    root = resources.files(PRESET_PACKAGE)
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def preset_path(name: str):
    """Traversable of a preset file; :class:`ScenarioError` lists the known ones."""
    root = resources.files(PRESET_PACKAGE)
    p = root / f"{name}.toml"
    if not p.is_file():
        raise ScenarioError(f"unknown preset {name!r}; known presets: "
                            + ", ".join(list_presets()))
    return p


def _deep_merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _read_toml(text: str, source: str) -> dict:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"scenario {source}: not valid TOML: {exc}") from None


def resolve_raw(scenario, _depth: int = 0) -> tuple[dict, str]:
    """Load a scenario source into a resolved dictionary.

    Parameters
    ----------
    scenario : str, Path or dict
        A preset name (see :func:`list_presets`), a path to a TOML file, or an
        already parsed dictionary.

    Returns
    -------
    raw : dict
        The dictionary with ``extends`` resolved (deep merge, child wins).
    source : str
        A description of where it came from, for error messages.
    """
    base_dir = None
    if isinstance(scenario, dict):
        raw, source = copy.deepcopy(scenario), "<dict>"
    else:
        s = str(scenario)
        p = Path(s)
        if p.is_file():
            try:
                text = p.read_text(encoding="utf-8")
            except UnicodeDecodeError as exc:
                raise ScenarioError(f"scenario file '{p}': not UTF-8 text (byte {exc.start})") from None
            raw, source = _read_toml(text, f"'{p}'"), f"'{p}'"
            base_dir = p.parent
            _own_paths_absolute(raw, base_dir)
        elif s.endswith(".toml") or (p.exists() and s not in list_presets()):  # a folder named like a preset
            raise ScenarioError(f"scenario file {s!r} {'is a directory' if p.is_dir() else 'does not exist'}")
        else:
            pp = preset_path(s)
            raw, source = _read_toml(pp.read_text(encoding="utf-8"), f"preset '{s}'"), f"preset '{s}'"
    if "extends" in raw:
        if _depth > 8:
            raise ScenarioError(f"scenario {source}: key 'extends': nesting too deep")
        parent = raw.pop("extends")
        if not isinstance(parent, str):
            raise ScenarioError(f"scenario {source}: key 'extends': expected a preset name or path")
        if base_dir is not None and parent.endswith(".toml") and not Path(parent).is_absolute():
            parent = str(base_dir / parent)
        try:
            base, _ = resolve_raw(parent, _depth + 1)
        except ScenarioError as exc:
            raise ScenarioError(f"scenario {source}: key 'extends': {exc}") from None
        base.pop("name", None)
        base.pop("description", None)
        raw = _deep_merge(base, raw)
    if base_dir is not None:
        raw.setdefault("_base_dir", str(base_dir))
    return raw, source


def _own_paths_absolute(raw: dict, base_dir: Path) -> None:
    """The file's own relative paths (``[gnss_raw] constellation``, a RINEX navigation
    file) made absolute against its folder before an ``extends`` merge: a child's path
    is the child's, a parent's the parent's, and the dataset's scenario.toml repeats."""
    gr = raw.get("gnss_raw")
    cons = gr.get("constellation") if isinstance(gr, dict) else None
    if isinstance(cons, str) and cons != "nominal" and not Path(cons).is_absolute():
        gr["constellation"] = str((base_dir / cons).resolve())


def load_scenario(scenario, *, seed: int | None = None) -> Scenario:
    """Parse and validate a scenario into SI units.

    Parameters
    ----------
    scenario : str, Path, dict or Scenario
        Preset name, TOML path, parsed dictionary, or an existing
        :class:`Scenario` (returned unchanged apart from ``seed``).
    seed : int, optional
        Overrides the scenario's ``seed`` key.

    Raises
    ------
    ScenarioError
        Naming the key, the value and the reason.
    """
    if isinstance(scenario, Scenario):
        sc = dataclasses.replace(scenario)
        if seed is not None:
            sc.seed = int(seed)
            sc.raw = dict(sc.raw, seed=int(seed))
        return sc
    raw, source = resolve_raw(scenario)
    base_dir = raw.pop("_base_dir", None)
    if seed is not None:
        raw["seed"] = int(seed)
    sc = _parse(raw, _Ctx(source), base_dir)
    sc.source = source
    return sc


_TOP = {"name", "description", "seed", "time", "initial", "motion", "imu", "truth",
        "gnss", "gnss_raw", "gnss_rtk", "odometer", "run"}
#: keys of a preset's [run] table: run-configuration defaults of the data it
#: simulates (Dataset.scenario["run"]), e.g. gate_prob = 0 for the seed-paper
#: presets, whose filters have no innovation gate, and robust_screening = false
#: for their tight filters (no per-satellite screening, FDE or CUSUM)
RUN_DEFAULT_KEYS = {"gate_prob", "robust_screening"}


def _parse(raw: dict, ctx: _Ctx, base_dir) -> Scenario:
    _check_keys(ctx, raw, "", _TOP)
    rn = _table(ctx, raw, "", "run")
    _check_keys(ctx, rn, "run", RUN_DEFAULT_KEYS)
    gate_prob = _num(ctx, rn, "run", "gate_prob", 0.0, lo=0.0, hi=0.999999999)
    screening = _bool(ctx, rn, "run", "robust_screening", True)
    del gate_prob, screening  # read by insnav.run from Dataset.scenario["run"]; checked here
    name = _str(ctx, raw, "", "name", "unnamed")
    description = _str(ctx, raw, "", "description", "")
    seed = _num(ctx, raw, "", "seed", 0, integer=True, lo=0)

    tm = _table(ctx, raw, "", "time")
    _check_keys(ctx, tm, "time", {"t0_s", "gps_week", "gps_tow_s"})
    t0 = _num(ctx, tm, "time", "t0_s", 0.0)
    week = _num(ctx, tm, "time", "gps_week", 2155, integer=True, lo=0)
    tow = _num(ctx, tm, "time", "gps_tow_s", 345600.0, lo=0.0, hi=604800.0)
    gps_offset = week * 604800.0 + tow - t0

    ini = _table(ctx, raw, "", "initial")
    _check_keys(ctx, ini, "initial", {"lat_deg", "lon_deg", "h_m", "speed_mps", "heading_deg",
                                      "path_angle_deg", "roll_deg", "pitch_deg", "yaw_deg"})
    lat0 = _num(ctx, ini, "initial", "lat_deg", required=True, lo=-89.0, hi=89.0) * DEG
    lon0 = _num(ctx, ini, "initial", "lon_deg", required=True, lo=-180.0, hi=360.0) * DEG
    h0 = _num(ctx, ini, "initial", "h_m", required=True, lo=-1000.0, hi=1e5)
    speed0 = _num(ctx, ini, "initial", "speed_mps", 0.0, lo=0.0)
    heading0 = _num(ctx, ini, "initial", "heading_deg", 0.0) * DEG
    gamma0 = _num(ctx, ini, "initial", "path_angle_deg", 0.0, lo=-80.0, hi=80.0) * DEG
    roll0 = _num(ctx, ini, "initial", "roll_deg", 0.0, lo=-90.0, hi=90.0) * DEG
    pitch0 = _num(ctx, ini, "initial", "pitch_deg", gamma0 / DEG, lo=-85.0, hi=85.0) * DEG
    yaw0 = _num(ctx, ini, "initial", "yaw_deg", heading0 / DEG) * DEG

    mo = _table(ctx, raw, "", "motion")
    _check_keys(ctx, mo, "motion", {"transition_s", "coordinated_turns", "g_ref_mps2",
                                    "segments", "oscillations", "lateral_slip_mps",
                                    "vertical_bounce_mps"})
    lateral_slip = _num(ctx, mo, "motion", "lateral_slip_mps", 0.0, lo=0.0, hi=5.0)
    vertical_bounce = _num(ctx, mo, "motion", "vertical_bounce_mps", 0.0, lo=0.0, hi=5.0)
    transition = _num(ctx, mo, "motion", "transition_s", 1.0, lo=0.0, lo_open=True)
    coordinated = _bool(ctx, mo, "motion", "coordinated_turns", False)
    g_ref = _num(ctx, mo, "motion", "g_ref_mps2", G0, lo=0.0, lo_open=True)
    segs_raw = mo.get("segments")
    if not isinstance(segs_raw, list) or not segs_raw or not all(isinstance(s, dict) for s in segs_raw):
        ctx.fail("motion.segments", "missing or empty: give at least one [[motion.segments]] table")
    seg_keys = {"duration_s", "label", "accel_mps2", "target_speed_mps", "speed_change_mps",
                "turn_rate_dps", "heading_change_deg", "path_angle_rate_dps",
                "target_path_angle_deg", "path_angle_change_deg"}
    osc_keys_seg = {f"{a}_{q}" for a in ("roll", "pitch", "yaw") for q in ("amp_deg", "period_s")}
    segments: list[Segment] = []
    oscillations: list[Oscillation] = []
    n = len(segs_raw)
    t = t0
    speed, gamma = speed0, gamma0
    for i, sr in enumerate(segs_raw):
        p = f"motion.segments[{i}]"
        _check_keys(ctx, sr, p, seg_keys | osc_keys_seg)
        d = _num(ctx, sr, p, "duration_s", required=True, lo=0.0, lo_open=True)
        if d < transition * (2.0 if i in (0, n - 1) else 1.0) - 1e-12:
            ctx.fail(_join(p, "duration_s"), f"value {d!r} too short: segments must last at least "
                     f"motion.transition_s = {transition} s (twice that for the first and last)")
        # effective duration over which a commanded change is reached (the
        # one-sided ramps at the start and the end lose half a transition each)
        d_eff = d - transition / 2 * ((i == 0) + (i == n - 1))
        if d_eff <= 0:
            ctx.fail(_join(p, "duration_s"), f"value {d!r} shorter than the transitions")
        k = _exclusive(ctx, sr, p, ["accel_mps2", "target_speed_mps", "speed_change_mps"])
        if k == "accel_mps2":
            acc = _num(ctx, sr, p, k)
        elif k == "target_speed_mps":
            acc = (_num(ctx, sr, p, k, lo=0.0) - speed) / d_eff
        elif k == "speed_change_mps":
            acc = _num(ctx, sr, p, k) / d_eff
        else:
            acc = 0.0
        speed_end = speed + acc * d_eff
        if speed_end < -1e-9:
            ctx.fail(_join(p, k or "accel_mps2"), f"speed would become negative ({speed_end:.3f} m/s) "
                     "by the end of this segment")
        k = _exclusive(ctx, sr, p, ["turn_rate_dps", "heading_change_deg"])
        if k == "turn_rate_dps":
            turn = _num(ctx, sr, p, k) * DEG
        elif k == "heading_change_deg":
            turn = _num(ctx, sr, p, k) * DEG / d_eff
        else:
            turn = 0.0
        k = _exclusive(ctx, sr, p, ["path_angle_rate_dps", "target_path_angle_deg",
                                    "path_angle_change_deg"])
        if k == "path_angle_rate_dps":
            q = _num(ctx, sr, p, k) * DEG
        elif k == "target_path_angle_deg":
            q = (_num(ctx, sr, p, k, lo=-80.0, hi=80.0) * DEG - gamma) / d_eff
        elif k == "path_angle_change_deg":
            q = _num(ctx, sr, p, k) * DEG / d_eff
        else:
            q = 0.0
        gamma_end = gamma + q * d_eff
        if abs(gamma_end) > 80 * DEG:
            ctx.fail(_join(p, k or "path_angle_rate_dps"),
                     f"flight-path angle would reach {gamma_end / DEG:.1f} deg (limit 80)")
        label = _str(ctx, sr, p, "label", "")
        segments.append(Segment(d, acc, turn, q, label))
        for ax in ("roll", "pitch", "yaw"):
            a_key, p_key = f"{ax}_amp_deg", f"{ax}_period_s"
            if (a_key in sr) != (p_key in sr):
                ctx.fail(_join(p, p_key if a_key in sr else a_key),
                         f"missing: '{a_key}' and '{p_key}' go together")
            if a_key in sr:
                amp = _num(ctx, sr, p, a_key, lo=0.0, hi=60.0) * DEG
                per = _num(ctx, sr, p, p_key, lo=0.0, lo_open=True)
                if d < 2 * transition:
                    ctx.fail(_join(p, "duration_s"), "a segment with an oscillation must last at "
                             "least 2 * motion.transition_s")
                oscillations.append(Oscillation(ax, amp, per, t, t + d, 0.0))
        t += d
        speed, gamma = speed_end, gamma_end
    t_end = t
    for i, orw in enumerate(mo.get("oscillations", []) or []):
        p = f"motion.oscillations[{i}]"
        if not isinstance(orw, dict):
            ctx.fail(p, "expected a table")
        _check_keys(ctx, orw, p, {"axis", "amp_deg", "period_s", "start_s", "end_s", "phase_deg"})
        ax = _str(ctx, orw, p, "axis", None)
        if ax not in ("roll", "pitch", "yaw"):
            ctx.fail(_join(p, "axis"), f"value {ax!r} not allowed: use 'roll', 'pitch' or 'yaw'")
        amp = _num(ctx, orw, p, "amp_deg", required=True, lo=0.0, hi=60.0) * DEG
        per = _num(ctx, orw, p, "period_s", required=True, lo=0.0, lo_open=True)
        st = _num(ctx, orw, p, "start_s", required=True)
        en = _num(ctx, orw, p, "end_s", required=True)
        if en - st < 2 * transition:
            ctx.fail(_join(p, "end_s"), f"window [{st}, {en}] shorter than 2 * motion.transition_s")
        if st < t0 or en > t_end + 1e-9:
            ctx.fail(_join(p, "start_s"), f"window [{st}, {en}] outside the scenario [{t0}, {t_end}]")
        ph = _num(ctx, orw, p, "phase_deg", 0.0) * DEG
        oscillations.append(Oscillation(ax, amp, per, st, en, ph))

    imu = _table(ctx, raw, "", "imu")
    _check_keys(ctx, imu, "imu", {"rate_hz", "quadrature_nodes", "errors_rate_hz", "gyro", "accel"})
    imu_rate = _num(ctx, imu, "imu", "rate_hz", 100.0, lo=1.0, hi=10000.0)
    nodes = _num(ctx, imu, "imu", "quadrature_nodes", 3, integer=True, lo=1, hi=8)
    errors_rate = _num(ctx, imu, "imu", "errors_rate_hz", min(10.0, imu_rate), lo=0.0, lo_open=True, hi=imu_rate)
    if "errors_rate_hz" in imu and abs(imu_rate / errors_rate - round(imu_rate / errors_rate)) > 1e-9 * imu_rate:
        ctx.fail("imu.errors_rate_hz", f"{errors_rate:g} does not divide the IMU rate {imu_rate:g} Hz (imu_errors.csv "
                                       "holds every n-th IMU sample's errors)")
    gyro = _sensor(ctx, _table(ctx, imu, "imu", "gyro"), "imu.gyro", _GYRO_KEYS, imu_rate)
    accel = _sensor(ctx, _table(ctx, imu, "imu", "accel"), "imu.accel", _ACCEL_KEYS, imu_rate)

    tr = _table(ctx, raw, "", "truth")
    _check_keys(ctx, tr, "truth", {"rate_hz"})
    truth_rate = _num(ctx, tr, "truth", "rate_hz", imu_rate, lo=0.0, lo_open=True)

    gn = _table(ctx, raw, "", "gnss")
    _check_keys(ctx, gn, "gnss", {"enabled", "rate_hz", "lever_arm_b_m", "sigma_h_m", "sigma_v_m",
                                  "sigma_vel_mps", "outages", "delay_p", "delay_model", "first_epoch_s"})
    gnss = {
        "enabled": _bool(ctx, gn, "gnss", "enabled", True),
        "rate": _num(ctx, gn, "gnss", "rate_hz", 1.0, lo=0.0, lo_open=True, hi=imu_rate),
        "lever_arm_b": _vec3(ctx, gn, "gnss", "lever_arm_b_m", 0.0),
        "sigma_h": _num(ctx, gn, "gnss", "sigma_h_m", 1.0, lo=0.0),
        "sigma_v": _num(ctx, gn, "gnss", "sigma_v_m", 2.0, lo=0.0),
        "sigma_vel": _num(ctx, gn, "gnss", "sigma_vel_mps", 0.1, lo=0.0),
        "outages": _windows(ctx, gn, "gnss", "outages"),
    }
    gnss["first_epoch"] = _num(ctx, gn, "gnss", "first_epoch_s", t0 + 1.0 / gnss["rate"])
    dp = gn.get("delay_p", [1.0])
    if (not isinstance(dp, list) or not dp or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and x >= 0 for x in dp)):
        ctx.fail("gnss.delay_p", f"expected a list of probabilities [p0, p1, ...], got {dp!r}")
    if abs(sum(dp) - 1.0) > 1e-9:
        ctx.fail("gnss.delay_p", f"probabilities {dp!r} must sum to 1 (sum is {sum(dp)!r})")
    gnss["delay_p"] = np.array(dp, dtype=float)
    gnss["delay_model"] = _str(ctx, gn, "gnss", "delay_model", "independent")
    if gnss["delay_model"] not in ("independent", "one_per_epoch"):
        ctx.fail("gnss.delay_model", f"expected \"one_per_epoch\" (seed 001: one measurement received per "
                 f"epoch) or \"independent\" (each fix delayed on its own), got {gnss['delay_model']!r}")

    gr = _table(ctx, raw, "", "gnss_raw")
    _check_keys(ctx, gr, "gnss_raw", {"enabled", "rate_hz", "constellation", "elevation_mask_deg",
                                      "max_sats", "sigma_pr_m", "sigma_prr_mps", "clock_bias0_m",
                                      "clock_drift0_mps", "clock_bias_rw_m_per_sqrts",
                                      "clock_drift_rw_mps_per_sqrts", "clock", "windows", "systems", "isb_m",
                                      "urban_canyon"})
    cons = _str(ctx, gr, "gnss_raw", "constellation", "nominal")
    if cons != "nominal" and base_dir is not None and not Path(cons).is_absolute():
        cons = str(Path(base_dir) / cons)
    gnss_raw = {
        "enabled": _bool(ctx, gr, "gnss_raw", "enabled", False),
        "rate": _num(ctx, gr, "gnss_raw", "rate_hz", 1.0, lo=0.0, lo_open=True, hi=imu_rate),
        "constellation": cons,
        "elevation_mask": _num(ctx, gr, "gnss_raw", "elevation_mask_deg", 10.0, lo=-5.0, hi=89.0) * DEG,
        "max_sats": _num(ctx, gr, "gnss_raw", "max_sats", 0, integer=True, lo=0),
        "sigma_pr": _num(ctx, gr, "gnss_raw", "sigma_pr_m", 3.0, lo=0.0),
        "sigma_prr": _num(ctx, gr, "gnss_raw", "sigma_prr_mps", 0.05, lo=0.0),
        "clock_bias0": _num(ctx, gr, "gnss_raw", "clock_bias0_m", 0.0),
        "clock_drift0": _num(ctx, gr, "gnss_raw", "clock_drift0_mps", 0.0),
        "clock_bias_rw": _num(ctx, gr, "gnss_raw", "clock_bias_rw_m_per_sqrts", 0.0, lo=0.0),
        "clock_drift_rw": _num(ctx, gr, "gnss_raw", "clock_drift_rw_mps_per_sqrts", 0.0, lo=0.0),
        "windows": [],
    }
    systems = gr.get("systems", ["G"])
    if (not isinstance(systems, list) or not systems or any(x not in ("G", "E", "C") for x in systems)
            or len(set(systems)) != len(systems)):
        ctx.fail("gnss_raw.systems", f'expected a list of distinct "G", "E", "C" (GPS, Galileo, BeiDou MEO), '
                 f"got {systems!r}")
    gnss_raw["systems"] = tuple(systems)
    isb_t = _table(ctx, gr, "gnss_raw", "isb_m")
    _check_keys(ctx, isb_t, "gnss_raw.isb_m", {"E", "C"})
    gnss_raw["isb"] = {k: _num(ctx, isb_t, "gnss_raw.isb_m", k, 0.0) for k in isb_t}
    if "urban_canyon" in gr:
        uc = _table(ctx, gr, "gnss_raw", "urban_canyon")
        _check_keys(ctx, uc, "gnss_raw.urban_canyon", {"mask_across_deg", "mask_along_deg", "street_azimuth_deg"})
        st_az = _num(ctx, uc, "gnss_raw.urban_canyon", "street_azimuth_deg", None, lo=-360.0, hi=360.0)
        gnss_raw["urban_canyon"] = dict(
            mask_across=_num(ctx, uc, "gnss_raw.urban_canyon", "mask_across_deg", required=True, lo=0.0, hi=89.0)
            * DEG,
            mask_along=_num(ctx, uc, "gnss_raw.urban_canyon", "mask_along_deg", 0.0, lo=-5.0, hi=89.0) * DEG,
            street_azimuth=None if st_az is None else st_az * DEG)
    clock = _str(ctx, gr, "gnss_raw", "clock", "")
    if clock:
        from ..gnss.clock import CLOCK_CLASSES

        if clock not in CLOCK_CLASSES:
            ctx.fail("gnss_raw.clock", f"unknown clock class {clock!r}; known: {', '.join(CLOCK_CLASSES)} "
                     "(or give clock_bias_rw_m_per_sqrts / clock_drift_rw_mps_per_sqrts)")
        qb, qd = CLOCK_CLASSES[clock]
        if "clock_bias_rw_m_per_sqrts" not in gr:
            gnss_raw["clock_bias_rw"] = qb
        if "clock_drift_rw_mps_per_sqrts" not in gr:
            gnss_raw["clock_drift_rw"] = qd
    if gnss_raw["max_sats"] and gnss_raw["max_sats"] < 4:
        ctx.fail("gnss_raw.max_sats", f"value {gnss_raw['max_sats']} must be 0 (all) or >= 4; "
                 "use [[gnss_raw.windows]] to force fewer satellites")
    for i, w in enumerate(gr.get("windows", []) or []):
        p = f"gnss_raw.windows[{i}]"
        if not isinstance(w, dict):
            ctx.fail(p, "expected a table with start_s, end_s, n_sats")
        _check_keys(ctx, w, p, {"start_s", "end_s", "n_sats"})
        st = _num(ctx, w, p, "start_s", required=True)
        en = _num(ctx, w, p, "end_s", required=True)
        if en <= st:
            ctx.fail(_join(p, "end_s"), f"value {en!r} must be > start_s = {st!r}")
        gnss_raw["windows"].append((st, en, _num(ctx, w, p, "n_sats", required=True, integer=True,
                                                lo=0, hi=32)))
    return Scenario(
        name=name, description=description, seed=seed, t0=t0, gps_time_offset_s=gps_offset,
        lat0=lat0, lon0=lon0, h0=h0, speed0=speed0, heading0=heading0, path_angle0=gamma0,
        roll_offset=roll0, pitch_offset=pitch0 - gamma0, yaw_offset=yaw0 - heading0,
        segments=segments, oscillations=oscillations, transition=transition,
        coordinated_turns=coordinated, g_ref=g_ref, imu_rate=imu_rate, quadrature_nodes=nodes,
        errors_rate=errors_rate, gyro=gyro, accel=accel, truth_rate=truth_rate, gnss=gnss,
        gnss_raw=gnss_raw, lateral_slip=lateral_slip, vertical_bounce=vertical_bounce,
        odometer=_odometer(ctx, raw, imu_rate), gnss_rtk=_gnss_rtk(ctx, raw, imu_rate), raw=raw)


def _odometer(ctx, raw, imu_rate):
    """``[odometer]``: wheel odometer of the rear-axle centre (insnav.sim.odometer)."""
    od = _table(ctx, raw, "", "odometer")
    _check_keys(ctx, od, "odometer", {"enabled", "rate_hz", "lever_arm_b_m", "ticks_per_m",
                                      "scale_error_ppm", "scale_error_sigma_ppm", "sigma_mps"})
    if not _bool(ctx, od, "odometer", "enabled", bool(od)):
        return None
    return {
        "rate": _num(ctx, od, "odometer", "rate_hz", 10.0, lo=0.0, lo_open=True, hi=imu_rate),
        "lever_arm_b": _vec3(ctx, od, "odometer", "lever_arm_b_m", 0.0),
        "ticks_per_m": _num(ctx, od, "odometer", "ticks_per_m", 50.0, lo=0.0),
        "scale_error": _num(ctx, od, "odometer", "scale_error_ppm", 0.0, lo=-1e5, hi=1e5) * 1e-6,
        "scale_error_sigma": _num(ctx, od, "odometer", "scale_error_sigma_ppm", 0.0, lo=0.0, hi=1e5) * 1e-6,
        "sigma": _num(ctx, od, "odometer", "sigma_mps", 0.0, lo=0.0),
    }


#: RINEX 3 signals (band + attribute) the carrier-phase simulation writes, per system (insnav.sim.gnss_rtk)
RTK_SIGNALS = {"G": ("1C", "1W", "2W", "2L", "5Q"), "E": ("1C", "5Q", "7Q")}

_RTK_KEYS = {"enabled", "rate_hz", "systems", "signals", "elevation_mask_deg", "base_elevation_mask_deg",
             "sigma_code_m", "sigma_phase_m", "sigma_doppler_hz", "multipath_code_m", "multipath_phase_m",
             "multipath_tau_s", "base_multipath_scale", "iono_ppm", "iono_tau_s", "tropo_ppm", "tropo_tau_s",
             "klobuchar", "saastamoinen", "slip_rate_per_h", "slip_max_cycles", "slip_lli_prob", "base_slips",
             "ambiguity_max_cycles", "clock", "clock_bias_rw_m_per_sqrts", "clock_drift_rw_mps_per_sqrts",
             "rover_clock_bias0_m", "rover_clock_drift0_mps", "base_clock_bias0_m", "base_clock_drift0_mps",
             "cn0_zenith_dbhz", "cn0_span_dbhz", "base", "urban_canyon"}


def _gnss_rtk(ctx, raw, imu_rate):
    """``[gnss_rtk]``: rover and base carrier phase and code (insnav.sim.gnss_rtk), SI; None when absent."""
    p = "gnss_rtk"
    gr = _table(ctx, raw, "", p)
    _check_keys(ctx, gr, p, _RTK_KEYS)
    if not _bool(ctx, gr, p, "enabled", bool(gr)):
        return None
    systems = gr.get("systems", ["G"])
    if (not isinstance(systems, list) or not systems or any(x not in RTK_SIGNALS for x in systems)
            or len(set(systems)) != len(systems)):
        ctx.fail(f"{p}.systems", f'expected a list of distinct {", ".join(repr(s) for s in RTK_SIGNALS)} '
                 f"(GPS, Galileo), got {systems!r}")
    sig_t = _table(ctx, gr, p, "signals")
    _check_keys(ctx, sig_t, f"{p}.signals", set(RTK_SIGNALS))
    signals = {}
    for s in systems:
        v = sig_t.get(s, ["1C"])
        if (not isinstance(v, list) or not v or any(x not in RTK_SIGNALS[s] for x in v) or len(set(v)) != len(v)
                or len({x[0] for x in v}) != len(v)):
            ctx.fail(f"{p}.signals.{s}", f"expected a list of signals on distinct bands out of "
                     f"{', '.join(RTK_SIGNALS[s])}, got {v!r}")
        signals[s] = tuple(v)
    mask = _num(ctx, gr, p, "elevation_mask_deg", 10.0, lo=-5.0, hi=89.0) * DEG
    cfg = {
        "rate": _num(ctx, gr, p, "rate_hz", 1.0, lo=0.0, lo_open=True, hi=min(imu_rate, 100.0)),
        "systems": tuple(systems), "signals": signals, "elevation_mask": mask,
        "base_elevation_mask": _num(ctx, gr, p, "base_elevation_mask_deg", mask / DEG, lo=-5.0, hi=89.0) * DEG,
        "sigma_code": _num(ctx, gr, p, "sigma_code_m", 0.3, lo=0.0),
        "sigma_phase": _num(ctx, gr, p, "sigma_phase_m", 0.002, lo=0.0),
        "sigma_doppler": _num(ctx, gr, p, "sigma_doppler_hz", 0.05, lo=0.0),
        "multipath_code": _num(ctx, gr, p, "multipath_code_m", 0.3, lo=0.0),
        "multipath_phase": _num(ctx, gr, p, "multipath_phase_m", 0.003, lo=0.0, hi=0.05),
        "multipath_tau": _num(ctx, gr, p, "multipath_tau_s", 30.0, lo=0.0),
        "base_multipath_scale": _num(ctx, gr, p, "base_multipath_scale", 0.3, lo=0.0),
        "iono_ppm": _num(ctx, gr, p, "iono_ppm", 1.0, lo=0.0),
        "iono_tau": _num(ctx, gr, p, "iono_tau_s", 600.0, lo=0.0),
        "tropo_ppm": _num(ctx, gr, p, "tropo_ppm", 0.3, lo=0.0),
        "tropo_tau": _num(ctx, gr, p, "tropo_tau_s", 1800.0, lo=0.0),
        "klobuchar": _bool(ctx, gr, p, "klobuchar", True),
        "saastamoinen": _bool(ctx, gr, p, "saastamoinen", True),
        "slip_rate_per_h": _num(ctx, gr, p, "slip_rate_per_h", 0.0, lo=0.0),
        "slip_max_cycles": _num(ctx, gr, p, "slip_max_cycles", 10, integer=True, lo=1, hi=1000000),
        "slip_lli_prob": _num(ctx, gr, p, "slip_lli_prob", 1.0, lo=0.0, hi=1.0),
        "base_slips": _bool(ctx, gr, p, "base_slips", False),
        "ambiguity_max": _num(ctx, gr, p, "ambiguity_max_cycles", 1000000, integer=True, lo=0, hi=100000000),
        "clock_bias_rw": _num(ctx, gr, p, "clock_bias_rw_m_per_sqrts", 0.0, lo=0.0),
        "clock_drift_rw": _num(ctx, gr, p, "clock_drift_rw_mps_per_sqrts", 0.0, lo=0.0),
        "rover_clock_bias0": _num(ctx, gr, p, "rover_clock_bias0_m", 300.0, lo=-3e5, hi=3e5),
        "rover_clock_drift0": _num(ctx, gr, p, "rover_clock_drift0_mps", 0.3, lo=-300.0, hi=300.0),
        "base_clock_bias0": _num(ctx, gr, p, "base_clock_bias0_m", -150.0, lo=-3e5, hi=3e5),
        "base_clock_drift0": _num(ctx, gr, p, "base_clock_drift0_mps", 0.1, lo=-300.0, hi=300.0),
        "cn0_zenith": _num(ctx, gr, p, "cn0_zenith_dbhz", 48.0, lo=0.0, hi=99.0),
        "cn0_span": _num(ctx, gr, p, "cn0_span_dbhz", 15.0, lo=0.0, hi=99.0),
    }
    clock = _str(ctx, gr, p, "clock", "")
    if clock:
        from ..gnss.clock import CLOCK_CLASSES

        if clock not in CLOCK_CLASSES:
            ctx.fail(f"{p}.clock", f"unknown clock class {clock!r}; known: {', '.join(CLOCK_CLASSES)}")
        qb, qd = CLOCK_CLASSES[clock]
        if "clock_bias_rw_m_per_sqrts" not in gr:
            cfg["clock_bias_rw"] = qb
        if "clock_drift_rw_mps_per_sqrts" not in gr:
            cfg["clock_drift_rw"] = qd
    bt = _table(ctx, gr, p, "base")
    pb = f"{p}.base"
    _check_keys(ctx, bt, pb, {"lat_deg", "lon_deg", "h_m", "offset_ned_m"})
    geo = [k for k in ("lat_deg", "lon_deg", "h_m") if k in bt]
    if geo and "offset_ned_m" in bt:
        ctx.fail(f"{pb}.offset_ned_m", f"conflicts with '{pb}.{geo[0]}': give the base as lat_deg/lon_deg/h_m "
                 "or as offset_ned_m from the rover's start, not both")
    if geo:
        cfg["base"] = {"lat": _num(ctx, bt, pb, "lat_deg", required=True, lo=-89.0, hi=89.0) * DEG,
                       "lon": _num(ctx, bt, pb, "lon_deg", required=True, lo=-360.0, hi=360.0) * DEG,
                       "h": _num(ctx, bt, pb, "h_m", required=True, lo=-500.0, hi=9000.0)}
    else:
        off = _vec3(ctx, bt, pb, "offset_ned_m", 0.0)
        if np.linalg.norm(off) > 100e3:
            ctx.fail(f"{pb}.offset_ned_m", f"baseline {np.linalg.norm(off) / 1e3:.1f} km: at most 100 km")
        cfg["base"] = {"offset_ned": off}
    if "urban_canyon" in gr:
        uc = _table(ctx, gr, p, "urban_canyon")
        pu = f"{p}.urban_canyon"
        _check_keys(ctx, uc, pu, {"mask_across_deg", "mask_along_deg", "street_azimuth_deg"})
        st_az = _num(ctx, uc, pu, "street_azimuth_deg", None, lo=-360.0, hi=360.0)
        cfg["urban_canyon"] = dict(
            mask_across=_num(ctx, uc, pu, "mask_across_deg", required=True, lo=0.0, hi=89.0) * DEG,
            mask_along=_num(ctx, uc, pu, "mask_along_deg", 0.0, lo=-5.0, hi=89.0) * DEG,
            street_azimuth=None if st_az is None else st_az * DEG)
    return cfg


def _windows(ctx, table, prefix, key):
    v = table.get(key, [])
    name = _join(prefix, key)
    if not isinstance(v, list):
        ctx.fail(name, f"expected a list of [start_s, end_s] pairs, got {v!r}")
    out = []
    for i, w in enumerate(v):
        if not (isinstance(w, list) and len(w) == 2 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in w)):
            ctx.fail(f"{name}[{i}]", f"expected [start_s, end_s], got {w!r}")
        if w[1] <= w[0]:
            ctx.fail(f"{name}[{i}]", f"end {w[1]!r} must be after start {w[0]!r}")
        out.append((float(w[0]), float(w[1])))
    return out


