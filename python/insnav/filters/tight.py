"""Tightly coupled GNSS/INS (seed 003, Xu et al. 2012): 17-state
filters on pseudorange and pseudorange rate.

Python owns the geometry (:mod:`insnav.gnss.tight_inputs`: satellite
positions, velocities and clocks, elevation mask, best-GDOP selection,
per-satellite sigmas, corrections), computed for all epochs at once and
handed to the C++ loop (``cpp/include/insnav/engine/tight_engine.hpp``) in
one call as flat arrays.  The receiver clock model (Layout17 states 15, 16:
bias [m], drift [m/s]) is :mod:`insnav.gnss.clock`'s: TCXO defaults, or a
simulator dataset's own clock densities.

:func:`run_tight` is what ``insnav.run(ds, coupling="tight")`` calls.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .. import _core, earth
from ..config import ImuNoise, RunConfig
from ..gnss.clock import clock_model
from ..gnss.tight_inputs import MAX_SATS, TightInputs, limit_sats, tight_inputs_from_raw
from ..units import DEG, RAD2DEG
from ._setup import imu_arrays, initial_state, outage_cycle_period
from .solution import Solution

__all__ = ["TightSolution", "run_tight"]


@dataclass
class TightSolution(Solution):
    """:class:`insnav.filters.Solution` plus the tight-coupling outputs.

    Per epoch: ``gnss_t``, ``nis``, ``gnss_status`` (as the loose solution),
    ``rows`` (measurement rows used).  Per satellite row (``inputs`` order):
    ``innovation`` (M, 2) INS-predicted minus measured pseudorange [m] and
    rate [m/s] before the update.  Per output sample: ``clock_bias_m``,
    ``clock_drift_mps`` (estimated receiver clock), ``sigma_clock`` (N, 2).
    """

    clock_bias_m: np.ndarray = None
    clock_drift_mps: np.ndarray = None
    sigma_clock: np.ndarray = None
    rows: np.ndarray = None
    inputs: TightInputs | None = None


def _initial_clock(inp: TightInputs, r_ant_e, v_ant_e) -> tuple[float, float]:
    """Receiver clock bias/drift from the first epoch with data, at the initial antenna state."""
    for e in range(inp.epoch_t.size):
        a, b = inp.epoch_start[e], inp.epoch_start[e + 1]
        if b <= a:
            continue
        s = inp.sats[a:b]
        d = s[:, 2:5] - r_ant_e
        rng = np.linalg.norm(d, axis=1)
        u = d / rng[:, None]
        bias = np.nanmedian(s[:, 0] - (rng - s[:, 8]))
        rate = s[:, 1] - (np.einsum("ij,ij->i", u, s[:, 5:8] - v_ant_e) - s[:, 9])
        drift = np.nanmedian(rate) if np.any(np.isfinite(rate)) else 0.0
        return float(bias), float(drift)
    return 0.0, 0.0


def run_tight(dataset, cfg: RunConfig | None = None, *, inputs: TightInputs | None = None,
              elevation_mask_deg: float = 10.0, max_sats: int = MAX_SATS, clock_psd=None,
              init_sigma_clock=(30.0, 1.0), clock0=None, use_pseudorange: bool = True,
              use_rate: bool = True) -> TightSolution:
    """Closed-loop tightly coupled run over a dataset (EKF, RB-UKF or UKF, Layout17).

    Parameters
    ----------
    dataset : insnav.Dataset or :class:`insnav.io.rinex_dataset.RinexDataset`
        IMU increments, initial state, lever arm, IMU model; the GNSS data come
        from ``inputs`` if given, else from ``dataset.tight_inputs`` (a real-data
        loader sets it) or ``dataset.gnss_raw`` (simulator).
    cfg : RunConfig
        ``filter``, initial sigmas/perturbation, IMU noise, gate, propagation
        step, output decimation, UT parameters.  ``layout`` is ignored (17).
    elevation_mask_deg, max_sats : satellite selection for ``gnss_raw`` input.
    clock_psd : (bias [m^2/s], drift [m^2/s^3]), optional; default :func:`clock_model`.
    init_sigma_clock : 1-sigma of the initial clock bias [m] and drift [m/s].
    clock0 : (bias, drift), optional; default from the first epoch at the initial state.

    Returns
    -------
    TightSolution
    """
    cfg = dataclasses.replace(cfg or RunConfig(), coupling="tight")
    cfg.validate()
    t, dth, dv = imu_arrays(dataset)

    if inputs is None:
        inputs = getattr(dataset, "tight_inputs", None)
    if inputs is None:
        if getattr(dataset, "gnss_raw", None) is None:
            raise ValueError(f"dataset {getattr(dataset, 'name', '')!r} has no raw GNSS data (gnss_raw); "
                             "tight coupling needs pseudoranges (simulate a preset with [gnss_raw], or load "
                             "RINEX + IMU files with insnav.io.rinex_dataset.load_rinex / "
                             "`insnav run --format rinex`)")
        s0 = dataset.initial
        r0 = earth.geodetic_to_ecef(s0.lat_deg * DEG, s0.lon_deg * DEG, s0.h_m)
        inputs = tight_inputs_from_raw(dataset.gnss_raw, elevation_mask_deg=elevation_mask_deg,
                                       max_sats=max_sats, approx_r_e=r0)
    if inputs.n_sats().max(initial=0) > MAX_SATS:
        inputs = limit_sats(inputs, MAX_SATS)

    rng = np.random.default_rng(cfg.init_seed)
    init, sig0 = initial_state(dataset, cfg, rng)
    noise = cfg.imu or ImuNoise.from_dataset_model(dataset.imu_model)
    model = noise.as_core_dict()
    qb, qd = clock_psd if clock_psd is not None else clock_model(dataset)
    model["clock_bias_psd"] = float(qb)
    model["clock_drift_psd"] = float(qd)
    p0 = np.zeros(17)
    p0[:9] = sig0
    p0[9:12] = noise.acc_bias_sigma
    p0[12:15] = noise.gyro_bias_sigma
    p0[15:17] = init_sigma_clock
    P0 = np.diag(p0 ** 2)
    lever = np.asarray(dataset.lever_arm_b if cfg.lever_arm_b is None else cfg.lever_arm_b, float)
    lat0, lon0 = init.lat_deg * DEG, init.lon_deg * DEG
    rpy0 = np.array([init.roll_deg, init.pitch_deg, init.yaw_deg]) * DEG
    if clock0 is None:
        C_en = earth.C_en(lat0, lon0)
        C_nb = np.asarray(_core.rotation.dcm_from_euler(rpy0))
        r_ant = earth.geodetic_to_ecef(lat0, lon0, init.h_m) + C_en @ (C_nb @ lever)
        clock0 = _initial_clock(inputs, r_ant, C_en @ init.v_n)
    ep_t = np.asarray(inputs.epoch_t, float)
    if ep_t.size > 1 and not np.all(np.diff(ep_t) > 0):
        bad = int(np.argmax(~(np.diff(ep_t) > 0))) + 1
        raise ValueError(f"GNSS epoch_t not strictly increasing at epoch {bad} (t = {ep_t[bad]:.3f} s)")
    cycle = cfg.cycle_period_s
    if cycle is None:
        cycle = float(np.median(np.diff(ep_t))) if ep_t.size > 1 else 1.0
    init_vec = np.array([dataset.t0, lat0, lon0, init.h_m, *init.v_n, *rpy0])
    core_cfg = dict(lever_arm_b=lever, propagation_interval=cfg.propagation_interval_s,
                    cycle_period=outage_cycle_period(cfg.filter, cycle), gate_chi2=cfg.gate_chi2,
                    use_pseudorange=bool(use_pseudorange), use_rate=bool(use_rate),
                    output_decimation=int(cfg.output_decimation))
    if cfg.filter != "ekf":
        core_cfg.update(ut_alpha=cfg.ut_alpha, ut_beta=cfg.ut_beta,
                        ut_kappa=(3.0 - 17) if cfg.ut_kappa is None else cfg.ut_kappa)
    out = _core.run_tight(cfg.filter, t, dth, dv, ep_t, inputs.epoch_start.astype(np.int64),
                          np.ascontiguousarray(inputs.sats, float).reshape(-1, 12), init_vec, P0, np.zeros(12),
                          np.asarray(clock0, float), model, core_cfg)
    sig, err, llh, rpy = out["sigma"], out["imu_err"], out["llh"], out["rpy"] * RAD2DEG
    sol = TightSolution(
        t=out["t"], lat_deg=llh[:, 0] * RAD2DEG, lon_deg=llh[:, 1] * RAD2DEG, h_m=llh[:, 2], v_n=out["v_n"],
        roll_deg=rpy[:, 0], pitch_deg=rpy[:, 1], yaw_deg=rpy[:, 2], sigma_pos_n_m=sig[:, 0:3],
        sigma_vel_n_mps=sig[:, 3:6], sigma_att_deg=sig[:, 6:9] * RAD2DEG, acc_bias_mps2=err[:, 0:3],
        gyro_bias_rps=err[:, 3:6], acc_scale=err[:, 6:9], gyro_scale=err[:, 9:12], gnss_t=ep_t,
        innovation=out["sat_residual"], nis=out["nis"], gnss_status=out["status"],
        summary=dict(filter=cfg.filter, coupling="tight", layout=17, updates=int(out["updates"]),
                     rejected=int(out["rejected"]), cholesky_repairs=int(out["cholesky_repairs"]),
                     gnss_records=int(ep_t.size), sat_rows=int(len(inputs.prn)), clock0=tuple(clock0),
                     clock_psd=(float(qb), float(qd))),
        clock_bias_m=out["clock"][:, 0], clock_drift_mps=out["clock"][:, 1], sigma_clock=sig[:, 15:17],
        rows=out["rows"], inputs=inputs)
    if not (np.all(np.isfinite(sol.lat_deg)) and np.all(np.isfinite(sol.v_n))):
        bad = int(np.argmax(~np.isfinite(sol.lat_deg) | ~np.isfinite(sol.v_n).any(axis=1)))
        raise FloatingPointError(f"tight {cfg.filter}: the solution became non-finite at t={sol.t[bad]:.3f} s "
                                 f"(row {bad})")
    return sol
