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

from .. import _core
from ..config import ImuNoise, RunConfig
from ..gnss.clock import clock_model
from ..gnss.tight_inputs import MAX_SATS, TightInputs
from ..units import RAD2DEG
from ._setup import (engine_config, imu_arrays, init_vector, initial_clock, initial_state, raise_if_nonfinite,
                     tight_inputs_for)
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

    inputs = tight_inputs_for(dataset, inputs, elevation_mask_deg=elevation_mask_deg, max_sats=max_sats)

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
    if clock0 is None:
        clock0 = initial_clock(inputs, dataset, cfg, init)
    ep_t = np.asarray(inputs.epoch_t, float)
    init_vec = init_vector(dataset, init)
    core_cfg = engine_config(dataset, cfg, ep_t, 17, use_pseudorange=bool(use_pseudorange), use_rate=bool(use_rate))
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
    raise_if_nonfinite(sol, cfg.filter)
    return sol
