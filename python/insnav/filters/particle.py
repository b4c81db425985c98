"""Seed 004 (Shao et al. 2013): the improved unscented particle filter with
residual-constrained adaptive fading, and its UKF and bootstrap-PF baselines,
tightly coupled on pseudorange / pseudorange rate, 20 states.

The C++ side is ``cpp/include/insnav/filter/{layout20,fading,upf,particle_filter}.hpp``
on the tight engine and pseudorange measurement of seed 003's tight coupling
(``engine/tight_engine.hpp``, ``meas/pseudorange.hpp``); the satellite
selection and all GNSS inputs come from :mod:`insnav.filters.tight`.

Filters (``filter=``)
---------------------
``"upf"``   improved UPF: a UKF per particle builds the proposal, with adaptive fading
            (``fading=False`` gives the plain UPF)

``"pf"``    particle filter: by default marginalised (attitude and gyro biases sampled,
            position/velocity/clock/accelerometer bias in one shared Kalman covariance);
            ``marginalize=False`` gives the bootstrap PF (systematic resampling + regularisation)

``"fukf"``  fading UKF; ``fading=False`` is the plain UKF baseline of seed 004

State layout (Layout20, NED, error = computed - true; the paper is ENU):
position error N/E/D [m], velocity error [m/s], attitude error [rad],
accelerometer first-order Markov [m/s^2], gyro random constant [rad/s], gyro
first-order Markov [rad/s], receiver clock bias [m] and drift [m/s].

Closed loop: the weighted-mean estimate is fed back into the INS after every
update and every particle is shifted by it (``x_i -= x_hat``); the gyro Markov
block is not fed back (it stays in the filter, see ``layout20.hpp``).

Use ``insnav.run(ds, filter="upf", coupling="tight", particles=100)`` or
:func:`run_tight_particle` directly.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .. import _core
from ..config import ImuNoise, RunConfig
from ..gnss.clock import clock_psd_option
from ..gnss.tight_inputs import MAX_SATS, TightInputs
from ..registry import FILTERS, PARTICLE_OPTIONS
from ..units import DEG, DEG_PER_H
from ._setup import (TIGHT_ELEVATION_MASK_DEG, engine_config, imu_arrays, init_vector, initial_clock,
                     initial_imu_correction, initial_state, raise_if_nonfinite, tight_inputs_for)
from ._assemble import nav_solution
from .tight import TightSolution, scaled_sigmas

__all__ = ["DEFAULT_ALPHA", "PARTICLE_FILTERS", "PARTICLE_OPTIONS", "ParticleSolution", "run_tight_particle", "layout20_model"]

#: filter names handled here (``insnav.run(..., coupling="tight")`` routes them)
PARTICLE_FILTERS = tuple(n for n, s in FILTERS.items() if s.runners.get("tight", "").endswith(":run_tight_particle"))

#: keyword options of :func:`run_tight_particle` that ``insnav.run`` passes through


#: default a priori fading ratios: 1 for position, velocity, clock; 0 (not faded) elsewhere
DEFAULT_ALPHA = np.r_[np.ones(6), np.zeros(12), np.ones(2)]


@dataclass
class ParticleSolution(TightSolution):
    """:class:`insnav.filters.tight.TightSolution` plus per-epoch filter diagnostics.

    ``ess`` (E,) effective sample size after the update (before resampling;
    1 for the UKF; NaN where no update was applied), ``fading_c`` (E,) the
    (weighted mean) c_k of the fading factors (0 = no fading needed / off),
    ``eta_max`` (E,) the (weighted mean) largest fading factor, ``resampled``
    (E,) bool.  ``run_seconds``: wall time of the C++ loop.
    """

    ess: np.ndarray = None
    fading_c: np.ndarray = None
    eta_max: np.ndarray = None
    resampled: np.ndarray = None
    run_seconds: float = float("nan")


def layout20_model(noise: ImuNoise, gyro_markov_sigma_dph: float = 1.0, gyro_markov_tau_s: float = 3600.0,
                   acc_markov_tau_s: float = 3600.0) -> tuple[dict, np.ndarray]:
    """C++ model dict and the 20-state sensor sigmas (acc Markov, gyro constant, gyro Markov).

    The gyro bias of ``noise`` (its total sigma) becomes the random constant
    (no driving noise; P0 only); the gyro Markov block gets
    ``gyro_markov_sigma_dph`` and ``gyro_markov_tau_s``; the accelerometer bias
    is first-order Markov with the sigma of ``noise`` and ``acc_markov_tau_s``.
    """
    model = noise.as_core_dict()
    gyro_const = np.asarray(noise.gyro_bias_sigma, float)
    gm = np.full(3, gyro_markov_sigma_dph * DEG_PER_H)
    model["gyro_bias_sigma"] = gm
    model["gyro_bias_tau"] = np.full(3, float(gyro_markov_tau_s))
    model["acc_bias_tau"] = np.full(3, float(acc_markov_tau_s))
    sig = np.concatenate([np.asarray(noise.acc_bias_sigma, float), gyro_const, gm])
    return model, sig


def run_tight_particle(dataset, cfg: RunConfig | None = None, *, filter: str | None = None, particles: int = 100,
                       seed: int = 1, fading: bool | None = None, rho: float = 0.95, beta: float = 2.0,
                       eta_max: float = 1e3, alpha=None, fading_memory: str = "innovation",
                       resample_threshold: float = 0.5,
                       roughening: float | None = None, rk4_step_s: float = 1.0, kernel_h2: float = 0.1,
                       init_yaw_uniform_deg: float = 0.0, temper_stages: int = 8, divergence_chi2: float = 25.0,
                       noise_floor: float | None = None, reseed: bool = True, marginalize: bool = True,
                       gyro_markov_sigma_dph: float = 1.0, gyro_markov_tau_s: float = 3600.0,
                       acc_markov_tau_s: float = 3600.0, inputs: TightInputs | None = None,
                       elevation_mask_deg: float = TIGHT_ELEVATION_MASK_DEG, max_sats: int = MAX_SATS, clock_psd=None,
                       init_sigma_clock=(30.0, 1.0), clock0=None) -> ParticleSolution:
    """Closed-loop tightly coupled run with a seed 004 filter (Layout20).

    Parameters
    ----------
    dataset : insnav.Dataset with ``gnss_raw`` (or ``inputs``)
    cfg : RunConfig
        initial sigmas / perturbation (``init_seed``), IMU noise, gate,
        propagation step, output decimation, UT parameters; ``filter`` if the
        ``filter`` argument is not given.
    filter : {'upf', 'pf', 'fukf'}
    particles : int
        N (UPF, PF; ignored by the UKF).
    seed : int
        Seed of the filter's random streams (sampling, resampling, noise):
        the result is identical for the same seed.
    fading : bool
        Adaptive fading (default: on for 'upf' and 'fukf'; the PF has none).
    rho, beta, eta_max, alpha : fading forgetting factor (0 < rho <= 1), softening
        factor (>= 1), cap of the factors, a priori ratios alpha_i (1 or 20 values >= 0;
        0 = that state is not faded).  Default :data:`DEFAULT_ALPHA`: fade position,
        velocity and clock only (fading the weakly observable yaw and gyro states
        makes their variance grow without bound; see ``fading.hpp``).
    fading_memory : {'innovation', 'nis'}
        What the forgetting recursion of C_0 (seed 004 eq. (6)) averages: the raw
        innovation power, as the paper writes it, or the innovation power relative
        to the covariance predicted at its own epoch (NIS per row), rescaled by the
        current epoch's: the second does not fade on the epochs right after an
        outage whose large innovations the filter had predicted (``fading.hpp``).
    resample_threshold : resample when N_eff < threshold * N.
    roughening : regularisation bandwidth after resampling, kernel shaped by the unweighted
        cloud covariance (default 0.2 for the PF, 0 for the UPF).
    kernel_h2 : UPF: Liu-West kernel shrinkage h^2 in [0, 1): each particle is jittered by
        h^2 of its UKF posterior covariance and keeps (1 - h^2) of it (0: a bank of UKFs).
    init_yaw_uniform_deg : UPF: > 0 starts the particles' yaw errors stratified uniformly over
        +-this [deg] (a non-Gaussian prior: heading unknown), instead of Gaussian draws.
    temper_stages : PF: at most this many progressive-correction stages per update (1: none).
    noise_floor : PF: every state random-walks by this x its initial sigma per sqrt(hour), which
        keeps the bootstrap cloud from collapsing in the states without process noise (default 3 for
        ``marginalize=False``, 0 for the marginalised PF, whose floor only degrades its yaw).
    divergence_chi2 : PF: an epoch where no particle explains the measurement within this
        chi-square per row is counted in ``summary["divergences"]`` and warned about.
    reseed : PF: sensor resetting at such an epoch (default on; ``particle_filter.hpp``): the
        position, velocity and clock of every particle are drawn again from the measurement
        given the particle's other states (needs >= 8 rows: 4 satellites with pseudorange and
        rate), counted in ``summary["reseeds"]``.  False: the plain bootstrap PF.
    marginalize : PF: the marginalised (Rao-Blackwellised) particle filter, insnav's default
        (Schön, Gustafsson, Nordlund 2005; ``particle_filter.hpp``): position, velocity, clock
        and accelerometer bias are a linear substate with one Kalman covariance shared by all
        particles, and only attitude and gyro biases are sampled.  False: the bootstrap PF
        (with ``reseed``: the sensor-resetting variant; without: the plain bootstrap PF).
    rk4_step_s : multi-interval RK4 step of the error state [s] (0: every engine interval).
    gyro_markov_sigma_dph, gyro_markov_tau_s, acc_markov_tau_s : the Markov blocks (:func:`layout20_model`).
    inputs, elevation_mask_deg, max_sats, clock_psd, init_sigma_clock, clock0 : as :func:`insnav.filters.tight.run_tight`.

    Returns
    -------
    ParticleSolution
    """
    cfg = dataclasses.replace(cfg or RunConfig(), coupling="tight")
    filt = filter or cfg.filter
    if filt not in PARTICLE_FILTERS:
        raise ValueError(f"filter {filt!r}: expected one of {', '.join(PARTICLE_FILTERS)}")
    cfg.filter = filt
    cfg.validate()
    if fading is None:
        fading = filt in ("upf", "fukf")
    if alpha is None:
        alpha = DEFAULT_ALPHA
    if roughening is None:
        roughening = 0.2 if filt == "pf" else 0.0
    if noise_floor is None:
        noise_floor = 0.0 if marginalize else 3.0
    t, dth, dv = imu_arrays(dataset)
    inputs = scaled_sigmas(tight_inputs_for(dataset, inputs, elevation_mask_deg=elevation_mask_deg,
                                            max_sats=max_sats), cfg)
    if np.any(np.asarray(inputs.system) != "G"):
        others = sorted(set(np.asarray(inputs.system).tolist()) - {"G"})
        raise ValueError(f"{filt}: the seed 004 particle filters are GPS-only (Layout20 has no inter-system bias "
                         f"states); the inputs have {', '.join(others)} rows -- select the GPS rows "
                         "(inputs.select(inputs.system == 'G')) or use filter ekf/rbukf/ukf")

    rng = np.random.default_rng(cfg.init_seed)
    init, sig0 = initial_state(dataset, cfg, rng)
    noise = cfg.imu or ImuNoise.from_dataset_model(dataset.imu_model)
    model, sig_sensor = layout20_model(noise, gyro_markov_sigma_dph, gyro_markov_tau_s, acc_markov_tau_s)
    qb, qd = clock_psd_option(clock_psd, dataset)
    model["clock_bias_psd"] = float(qb)
    model["clock_drift_psd"] = float(qd)
    # the run config's initial bias sigmas where given (as the tight EKF): the accelerometer's Markov
    # block and the gyro's random constant
    if cfg.init_sigma_acc_bias_mps2 is not None:
        sig_sensor[0:3] = cfg.init_sigma_acc_bias_mps2
    if cfg.init_sigma_gyro_bias_radps is not None:
        sig_sensor[3:6] = cfg.init_sigma_gyro_bias_radps
    p0 = np.concatenate([sig0, sig_sensor, np.asarray(init_sigma_clock, float)])
    P0 = np.diag(p0 ** 2)
    if clock0 is None:
        clock0 = initial_clock(inputs, dataset, cfg, init)
    ep_t = np.asarray(inputs.epoch_t, float)
    init_vec = init_vector(dataset, init)
    core_cfg = engine_config(dataset, cfg, ep_t, 20, **cfg.robust.as_core_dict(dataset))
    pcfg = dict(particles=int(particles), seed=int(seed), fading=bool(fading), rho=float(rho), beta=float(beta),
                eta_max=float(eta_max), alpha=np.atleast_1d(np.asarray(alpha, float)),
                fading_memory=str(fading_memory),
                resample_threshold=float(resample_threshold), roughening=float(roughening),
                rk4_step=float(rk4_step_s), kernel_h2=float(kernel_h2),
                init_yaw_halfwidth=float(init_yaw_uniform_deg) * DEG, temper_stages=int(temper_stages),
                divergence_chi2=float(divergence_chi2), noise_floor=float(noise_floor), reseed=bool(reseed),
                marginalize=bool(marginalize))
    out = _core.run_tight_particle(filt, t, dth, dv, ep_t, inputs.epoch_start.astype(np.int64),
                                   np.ascontiguousarray(inputs.sats, float).reshape(-1, 12), init_vec, P0,
                                   initial_imu_correction(cfg), np.asarray(clock0, float), model, core_cfg, pcfg)
    sig = out["sigma"]
    # per-update traces -> per-epoch arrays (entries belong to the applied epochs in order)
    applied = np.flatnonzero(out["status"] == 1)
    E = ep_t.size

    def per_epoch(a, fill=np.nan, dtype=float):
        r = np.full(E, fill, dtype=dtype)
        k = min(len(a), len(applied))
        r[applied[:k]] = np.asarray(a)[:k]
        return r

    sol, _ = nav_solution(
        out, ParticleSolution, gnss_t=ep_t, innovation=out["sat_residual"], nis=out["nis"], gnss_status=out["status"],
        summary=dict(filter=filt, coupling="tight", layout=20, particles=int(particles) if filt != "fukf" else 1,
                     fading=bool(fading), seed=int(seed), updates=int(out["updates"]),
                     rejected=int(out["rejected"]), gate_reopened=int(out["gate_reopened"]), gate_outage_accepted=int(out["gate_outage_accepted"]), cholesky_repairs=int(out["cholesky_repairs"]),
                     resamples=int(out["resamples"]), divergences=int(out["divergences"]),
                     reseeds=int(out["reseeds"]), marginalize=bool(marginalize) if filt == "pf" else False,
                     gnss_records=int(E), sat_rows=int(len(inputs.prn)),
                     clock0=tuple(clock0), clock_psd=(float(qb), float(qd)), run_seconds=float(out["run_seconds"])),
        clock_bias_m=out["clock"][:, 0], clock_drift_mps=out["clock"][:, 1], sigma_clock=sig[:, 18:20],
        rows=out["rows"], inputs=inputs,
        ess=per_epoch(out["trace_ess"]), fading_c=per_epoch(out["trace_fading_c"]),
        eta_max=per_epoch(out["trace_eta_max"]), resampled=per_epoch(out["trace_resampled"], 0, bool),
        run_seconds=float(out["run_seconds"]))
    if out["divergences"]:
        import warnings

        reset = (f"; the cloud was reset from the measurement at {out['reseeds']} of them" if out["reseeds"]
                 else "")
        warnings.warn(f"tight {filt}: at {out['divergences']} of {int(out['updates'])} updates no particle explained "
                      f"the measurements within chi2 {divergence_chi2:g} per row: the particle cloud lost the "
                      f"solution there{reset} (more particles, or the UPF)", RuntimeWarning, stacklevel=2)
    raise_if_nonfinite(sol, f"tight {filt}")
    return sol
