"""The run set-up every filter family shares: the initial state (optionally
perturbed, Monte Carlo style), the IMU arrays, and the outage cycle."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._imu_scan import scan_imu
from .._median import median, spacing_median
from .._validate import as_float_array, check_finite, check_increasing
from ..config import GATE_PROB_DEFAULT, ConfigError, RunConfig
from ..data.nav import NavState
from ..earth import radii
from ..registry import FILTERS, filter_spec
from ..units import DEG

__all__ = ["initial_state", "imu_arrays", "outage_cycle_period", "loose_initial_sigmas", "initial_imu_correction",
           "init_vector", "lever_arm", "engine_config", "tight_inputs_for", "initial_clock", "antenna_at_init",
           "raise_if_nonfinite", "EngineArgs"]


@dataclass
class EngineArgs:
    """What every closed-loop engine is built from (``_core.run_*`` and the push API's
    navigators take the same): the core error-state layout, the initial state vector
    (:func:`init_vector`), its covariance P0 (layout order, SI), the initial IMU
    correction (:func:`initial_imu_correction`), and the IMU-model and engine-config
    dicts.  Each family's set-up extends it with its own inputs."""

    layout: int
    init: np.ndarray
    P0: np.ndarray
    imu_correction: np.ndarray
    imu_model: dict
    config: dict


def initial_state(dataset, cfg: RunConfig, rng: np.random.Generator | None = None) -> tuple[NavState, np.ndarray]:
    """Initial state (optionally perturbed, Monte Carlo style) and its 15/21 sigmas;
    the draw uses ``rng``, or ``np.random.default_rng(cfg.init_seed)`` when None
    (made only when there is a draw: numpy.random is not imported otherwise)."""
    s0: NavState = dataset.initial
    sp = np.asarray(cfg.init_sigma_pos_m, float)
    sv = np.asarray(cfg.init_sigma_vel_mps, float)
    sa = np.asarray(cfg.init_sigma_att_deg, float)
    lat, lon, h = s0.lat_deg * DEG, s0.lon_deg * DEG, s0.h_m
    v = s0.v_n.copy()
    rpy = np.array([s0.roll_deg, s0.pitch_deg, s0.yaw_deg])
    draw = cfg.init_error if cfg.init_error != "auto" else bool(getattr(dataset, "initial_is_truth", False))
    if draw:
        if rng is None:
            rng = np.random.default_rng(cfg.init_seed)
        dp, dv, da = rng.standard_normal(3) * sp, rng.standard_normal(3) * sv, rng.standard_normal(3) * sa
        R_M, R_N = radii(lat)
        lat, lon, h = lat + dp[0] / (R_M + h), lon + dp[1] / ((R_N + h) * np.cos(lat)), h - dp[2]
        v = v + dv
        rpy = rpy + da
    state = NavState(lat / DEG, lon / DEG, h, v, *rpy)
    return state, np.concatenate([sp, sv, sa * DEG])


def imu_arrays(dataset, *, check_nonfinite: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], dtheta_b (N,3) [rad], dv_b (N,3) [m/s]) as float arrays, times increasing after t0."""
    imu = dataset.imu
    t = as_float_array(imu.t, "imu.t")
    dth = as_float_array(imu.dtheta_b, "imu.dtheta_b", (3,))
    dv = as_float_array(imu.dv_b, "imu.dv_b", (3,))
    if len(t) != len(dth) or len(t) != len(dv):  # the messages of the checks one array at a time
        if check_nonfinite:
            for a, name in ((t, "imu.t"), (dth, "imu.dtheta_b"), (dv, "imu.dv_b")):
                check_finite(a, name)
        check_increasing(t, "imu.t", t0=float(dataset.t0))
        return t, dth, dv
    # one compiled pass (memoised within insnav.run, where the sanitizer made it already)
    scan = scan_imu(t, dth, dv)
    if check_nonfinite:
        for a, name, key in ((t, "imu.t", "nonfinite_t"), (dth, "imu.dtheta_b", "nonfinite_dtheta"),
                             (dv, "imu.dv_b", "nonfinite_dv")):
            if scan[key] >= 0:
                check_finite(a, name)  # its message, at the sample the scan found
    t0 = float(dataset.t0)
    if len(t) and not t[0] > t0 or scan["not_increasing"] >= 0:
        check_increasing(t, "imu.t", t0=t0)
    return t, dth, dv


def outage_cycle_period(filter_name: str, cycle_s: float) -> float:
    """The engine's ``cycle_period``: ``cycle_s`` (one GNSS period) times the
    filter's ``outage_cycle_factor`` (:mod:`insnav.registry`)."""
    return float(cycle_s) * filter_spec(filter_name).outage_cycle_factor


def loose_initial_sigmas(sig0: np.ndarray, noise, layout: int, cfg=None) -> np.ndarray:
    """1-sigma of the loose layouts' states: position, velocity, attitude
    (``sig0``), accelerometer and gyro biases, and (21 states) scale factors:
    the run config's ``init_sigma_*`` IMU-error keys where given, else the
    IMU noise model's sigmas."""
    def pick(key, default):
        v = getattr(cfg, key, None) if cfg is not None else None
        return default if v is None else v

    p0 = np.zeros(layout)
    p0[:9] = sig0
    p0[9:12] = pick("init_sigma_acc_bias_mps2", noise.acc_bias_sigma)
    p0[12:15] = pick("init_sigma_gyro_bias_radps", noise.gyro_bias_sigma)
    if layout == 21:
        p0[15:18] = pick("init_sigma_acc_scale", noise.acc_scale_sigma)
        p0[18:21] = pick("init_sigma_gyro_scale", noise.gyro_scale_sigma)
    return p0


def initial_imu_correction(cfg) -> np.ndarray:
    """The engines' ``imu_correction``: the run config's initial IMU-error
    estimate (accelerometer bias [m/s^2], gyro bias [rad/s], accelerometer and
    gyro scale factor [-]; zero where not given)."""
    out = np.zeros(12)
    for j, key in enumerate(("init_acc_bias_mps2", "init_gyro_bias_radps", "init_acc_scale", "init_gyro_scale")):
        v = getattr(cfg, key, None)
        if v is not None:
            out[3 * j:3 * j + 3] = v
    return out


def init_vector(dataset, init: NavState) -> np.ndarray:
    """The engines' ``init``: t0 [s], lat, lon [rad], h [m], v_n [m/s], roll, pitch, yaw [rad]."""
    return np.array([dataset.t0, init.lat_deg * DEG, init.lon_deg * DEG, init.h_m, *init.v_n,
                     init.roll_deg * DEG, init.pitch_deg * DEG, init.yaw_deg * DEG])


def lever_arm(dataset, cfg: RunConfig) -> np.ndarray:
    """IMU centre -> antenna, body FRD [m]: the config's if set, else the dataset's."""
    return np.asarray(dataset.lever_arm_b if cfg.lever_arm_b is None else cfg.lever_arm_b, float)


def gate_config(cfg: RunConfig, dataset=None) -> dict:
    """The engines' gate keys (nis_gate.hpp): ``gate_chi2`` None -> the
    ``gate_prob`` quantile of each record's row count, 0 -> no gate, > 0 -> that
    fixed threshold.  ``gate_prob`` None: the dataset's preset default
    (``[run] gate_prob`` of a simulator preset, e.g. 0 for the seed papers),
    else :data:`insnav.config.GATE_PROB_DEFAULT`."""
    if cfg.gate_chi2 is None:
        prob = cfg.gate_prob
        if prob is None:
            prob = (getattr(dataset, "scenario", None) or {}).get("run", {}).get("gate_prob", GATE_PROB_DEFAULT)
        chi2, prob = 0.0, float(prob)
    else:
        chi2, prob = float(cfg.gate_chi2), 0.0
    return dict(gate_chi2=chi2, gate_prob=prob, gate_reopen_after=int(cfg.gate_reopen_after),
                gate_mismatch=float(cfg.gate_mismatch), gate_outage_s=float(cfg.gate_outage_s))


def engine_config(dataset, cfg: RunConfig, record_t: np.ndarray, layout: int, **extra) -> dict:
    """The engine config every binder reads: lever arm, propagation interval,
    outage cycle (the GNSS period, the median spacing of ``record_t``, unless
    ``cfg.cycle_period_s``, times the filter's factor), gate, output
    decimation, and the UT parameters of the sigma-point filters."""
    cycle = cfg.cycle_period_s
    if cycle is None:
        # the spacing of the distinct times, a block of them at a time when in time order (a day of 10 Hz
        # fixes: no whole-record copies)
        cycle = spacing_median(record_t)
        cycle = 1.0 if cycle is None else cycle
    out = dict(lever_arm_b=lever_arm(dataset, cfg), propagation_interval=cfg.propagation_interval_s,
               cycle_period=outage_cycle_period(cfg.filter, cycle), **gate_config(cfg, dataset),
               output_decimation=int(cfg.output_decimation))
    if cfg.filter not in FILTERS or FILTERS[cfg.filter].ut_params:  # the sigma-point filters' UT
        out.update(ut_alpha=cfg.ut_alpha, ut_beta=cfg.ut_beta,
                   ut_kappa=(3.0 - layout) if cfg.ut_kappa is None else cfg.ut_kappa)
    out.update(extra)
    return out


#: the tight filters' default elevation mask [deg] of rows built from a simulated dataset's raw observations
TIGHT_ELEVATION_MASK_DEG = 10.0


def tight_inputs_for(dataset, inputs=None, *, elevation_mask_deg: float, max_sats: int):
    """The tight filters' GNSS input: ``inputs``, or the dataset's, or built
    from its raw observations; at most MAX_SATS per epoch (best GDOP)."""
    from ..earth import geodetic_to_ecef
    from ..gnss.tight_inputs import MAX_SATS, limit_sats, tight_inputs_from_raw

    built = inputs is not None or getattr(dataset, "tight_inputs", None) is not None
    if built and (elevation_mask_deg != TIGHT_ELEVATION_MASK_DEG or max_sats != MAX_SATS):
        # the rows exist already (RINEX: built by the loader with [rinex] / [gnss]): the options would be ignored
        key, value = (("elevation_mask_deg", elevation_mask_deg) if elevation_mask_deg != TIGHT_ELEVATION_MASK_DEG
                      else ("max_sats", max_sats))
        raise ConfigError(f"option '{key}' = {value!r} builds the rows of a simulated dataset's raw observations; "
                          f"these rows are built already (RINEX: set [rinex] elevation_mask_deg or the [gnss] "
                          f"table's masks instead)")
    if inputs is None:
        inputs = getattr(dataset, "tight_inputs", None)
    if inputs is None:
        if getattr(dataset, "gnss_raw", None) is None:
            raise ValueError(f"dataset {getattr(dataset, 'name', '')!r} has no raw GNSS data (gnss_raw); "
                             "tight coupling needs pseudoranges (simulate a preset with [gnss_raw], or load "
                             "RINEX + IMU files with insnav.io.rinex_dataset.load_rinex / "
                             "`insnav run --format rinex`)")
        s0 = dataset.initial
        r0 = geodetic_to_ecef(s0.lat_deg * DEG, s0.lon_deg * DEG, s0.h_m)
        inputs = tight_inputs_from_raw(dataset.gnss_raw, elevation_mask_deg=elevation_mask_deg,
                                       max_sats=max_sats, approx_r_e=r0)
    if inputs.n_sats().max(initial=0) > MAX_SATS:
        inputs = limit_sats(inputs, MAX_SATS)
    ep_t = np.asarray(inputs.epoch_t, float)
    if ep_t.size > 1 and not np.all(np.diff(ep_t) > 0):
        bad = int(np.argmax(~(np.diff(ep_t) > 0))) + 1
        raise ValueError(f"GNSS epoch_t not strictly increasing at epoch {bad} (t = {ep_t[bad]:.3f} s)")
    return inputs


def antenna_at_init(dataset, cfg: RunConfig, init: NavState) -> tuple[np.ndarray, np.ndarray]:
    """ECEF antenna position [m] and velocity [m/s] (no lever-arm rate term) of the initial state."""
    from .. import _core, earth

    lat0, lon0 = init.lat_deg * DEG, init.lon_deg * DEG
    rpy0 = np.array([init.roll_deg, init.pitch_deg, init.yaw_deg]) * DEG
    C_en = earth.C_en(lat0, lon0)
    C_nb = np.asarray(_core.rotation.dcm_from_euler(rpy0))
    r_ant = earth.geodetic_to_ecef(lat0, lon0, init.h_m) + C_en @ (C_nb @ lever_arm(dataset, cfg))
    return r_ant, C_en @ init.v_n


def initial_clock(inputs, dataset, cfg: RunConfig, init: NavState) -> tuple[float, float]:
    """Receiver clock bias [m] and drift [m/s] from the first epoch with data,
    at the initial antenna position and velocity (GPS rows when the epoch has
    any: the clock is GPS time and the other systems' offsets are their ISBs)."""
    from ..gnss.systems import system_index

    r_ant, v_ant = antenna_at_init(dataset, cfg, init)
    sys_idx = system_index(inputs.system) if getattr(inputs, "system", None) is not None and len(inputs.prn) \
        else np.zeros(len(inputs.prn), np.int64)
    for e in range(inputs.epoch_t.size):
        a, b = inputs.epoch_start[e], inputs.epoch_start[e + 1]
        if b <= a:
            continue
        s = inputs.sats[a:b]
        gps = sys_idx[a:b] == 0
        if gps.any():
            s = s[gps]
        d = s[:, 2:5] - r_ant
        rng = np.linalg.norm(d, axis=1)
        u = d / rng[:, None]
        raw = s[:, 0] - (rng - s[:, 8])
        bias = median(raw[~np.isnan(raw)])  # np.nanmedian without numpy.ma
        rate = s[:, 1] - (np.einsum("ij,ij->i", u, s[:, 5:8] - v_ant) - s[:, 9])
        drift = median(rate[~np.isnan(rate)]) if np.any(np.isfinite(rate)) else 0.0
        return float(bias), float(drift)
    return 0.0, 0.0


def raise_if_nonfinite(sol, name: str) -> None:
    """A FloatingPointError naming the first output row where the solution left the finite numbers."""
    if not (np.all(np.isfinite(sol.lat_deg)) and np.all(np.isfinite(sol.v_n))):
        bad = int(np.argmax(~np.isfinite(sol.lat_deg) | ~np.isfinite(sol.v_n).any(axis=1)))
        raise FloatingPointError(f"{name}: the solution became non-finite at t={sol.t[bad]:.3f} s "
                                 f"(row {bad}); check the IMU data and the noise model")
