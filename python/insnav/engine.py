"""Closed-loop GNSS/INS runs: :func:`run` and the :class:`Solution` it returns.

The whole IMU loop runs in C++ with the GIL released
(``cpp/include/insnav/engine/loose_engine.hpp``); this module converts units,
builds the initial state and covariance, and validates inputs once.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _core
from ._validate import as_float_array, check_finite, check_increasing
from .config import DEG, ImuNoise, RunConfig
from .earth import radii
from .types import NavState

RAD2DEG = 180.0 / np.pi

#: GNSS record status codes of :attr:`Solution.gnss_status`
GNSS_STATUS = {0: "not used", 1: "applied", 2: "rejected by gate", 3: "S not positive definite",
               4: "outside the IMU time span"}


@dataclass
class Solution:
    """A navigation solution with its uncertainty and filter diagnostics.

    Attributes
    ----------
    t : (N,) s
    lat_deg, lon_deg, h_m : (N,) position of the IMU centre
    v_n : (N, 3) m/s NED velocity
    roll_deg, pitch_deg, yaw_deg : (N,)
    sigma_pos_n_m : (N, 3) 1-sigma N, E, D position [m]
    sigma_vel_n_mps : (N, 3)
    sigma_att_deg : (N, 3) 1-sigma of the attitude error angles [deg]
    acc_bias_mps2, gyro_bias_rps : (N, 3) estimated IMU biases (SI)
    acc_scale, gyro_scale : (N, 3) estimated scale-factor errors [-]
    gnss_t : (M,) s, time of validity of each GNSS record
    innovation : (M, 6) INS minus GNSS (N, E, D position [m], velocity [m/s]) before the update
    nis : (M,) normalised innovation squared
    gnss_status : (M,) int8, see :data:`GNSS_STATUS`
    summary : dict
        filter, coupling, counts of updates / rejections / covariance repairs.
    """

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    v_n: np.ndarray
    roll_deg: np.ndarray
    pitch_deg: np.ndarray
    yaw_deg: np.ndarray
    sigma_pos_n_m: np.ndarray
    sigma_vel_n_mps: np.ndarray
    sigma_att_deg: np.ndarray
    acc_bias_mps2: np.ndarray
    gyro_bias_rps: np.ndarray
    acc_scale: np.ndarray
    gyro_scale: np.ndarray
    gnss_t: np.ndarray
    innovation: np.ndarray
    nis: np.ndarray
    gnss_status: np.ndarray
    summary: dict = field(default_factory=dict)

    COLUMNS = ("t", "lat_deg", "lon_deg", "h_m", "vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg",
               "sigma_n_m", "sigma_e_m", "sigma_d_m", "sigma_vn_mps", "sigma_ve_mps", "sigma_vd_mps",
               "sigma_roll_deg", "sigma_pitch_deg", "sigma_yaw_deg",
               "acc_bias_x_mps2", "acc_bias_y_mps2", "acc_bias_z_mps2",
               "gyro_bias_x_dph", "gyro_bias_y_dph", "gyro_bias_z_dph",
               "acc_scale_x_ppm", "acc_scale_y_ppm", "acc_scale_z_ppm",
               "gyro_scale_x_ppm", "gyro_scale_y_ppm", "gyro_scale_z_ppm")

    def __len__(self) -> int:
        return len(self.t)

    def to_array(self) -> np.ndarray:
        """(N, 31) array in :attr:`COLUMNS` order (user units as named)."""
        return np.column_stack([self.t, self.lat_deg, self.lon_deg, self.h_m, self.v_n,
                                self.roll_deg, self.pitch_deg, self.yaw_deg,
                                self.sigma_pos_n_m, self.sigma_vel_n_mps, self.sigma_att_deg,
                                self.acc_bias_mps2, self.gyro_bias_rps * RAD2DEG * 3600.0,
                                self.acc_scale * 1e6, self.gyro_scale * 1e6])

    def to_dataframe(self):
        """A pandas DataFrame with the fixed :attr:`COLUMNS` (pandas is optional)."""
        import pandas as pd

        return pd.DataFrame(self.to_array(), columns=list(self.COLUMNS))

    def save_csv(self, path) -> None:
        """Write the solution CSV atomically (a temp file renamed into place)."""
        from ._atomic import atomic_write_text

        header = ",".join(self.COLUMNS)
        import io

        buf = io.StringIO()
        np.savetxt(buf, self.to_array(), delimiter=",", header=header, comments="",
                   fmt=["%.6f"] + ["%.10f"] * 2 + ["%.5f"] * 28)
        atomic_write_text(path, buf.getvalue())


def _initial_state(dataset, cfg: RunConfig, rng: np.random.Generator) -> tuple[NavState, np.ndarray]:
    """Initial state (optionally perturbed, Monte Carlo style) and its 15/21 sigmas."""
    s0: NavState = dataset.initial
    sp = np.asarray(cfg.init_sigma_pos_m, float)
    sv = np.asarray(cfg.init_sigma_vel_mps, float)
    sa = np.asarray(cfg.init_sigma_att_deg, float)
    lat, lon, h = s0.lat_deg * DEG, s0.lon_deg * DEG, s0.h_m
    v = s0.v_n.copy()
    rpy = np.array([s0.roll_deg, s0.pitch_deg, s0.yaw_deg])
    if cfg.init_error:
        dp, dv, da = rng.standard_normal(3) * sp, rng.standard_normal(3) * sv, rng.standard_normal(3) * sa
        R_M, R_N = radii(lat)
        lat, lon, h = lat + dp[0] / (R_M + h), lon + dp[1] / ((R_N + h) * np.cos(lat)), h - dp[2]
        v = v + dv
        rpy = rpy + da
    state = NavState(lat / DEG, lon / DEG, h, v, *rpy)
    return state, np.concatenate([sp, sv, sa * DEG])


def run(dataset, filter: str | None = None, coupling: str | None = None, config: RunConfig | None = None,
        *, sanitize: bool | dict = True, checks: bool = True, **overrides) -> Solution:
    """Run a closed-loop GNSS/INS filter over a dataset.

    Parameters
    ----------
    dataset : insnav.Dataset
        IMU increments, GNSS fixes (``t_valid`` is used; see the delay filters
        for ``t_arrival``), initial state, lever arm and IMU model.
    filter : {'ekf', 'rbukf', 'ukf', 'upf', 'pf', 'fukf'}, optional
        Overrides ``config.filter``.  'upf', 'pf', 'fukf' (seed 004, 20 states)
        are tight only and take the options of
        :func:`insnav.particle.run_tight_particle` (``particles=``, ``seed=``, ...).
    coupling : {'loose', 'tight'}, optional
    config : RunConfig, optional
    sanitize : bool or dict
        Check and repair the input first (:mod:`insnav.sanitize`: duplicates
        dropped, short IMU gaps bridged, bad GNSS fixes dropped; a dict
        overrides ``insnav.sanitize.DEFAULTS``); the counts go to
        ``summary["sanitize"]``.  Clean data are not changed.
    checks : bool
        Unit and sanity checks before the filter (:mod:`insnav.checks`:
        specific force ~ g, axes, gyro units against the GNSS course, GNSS
        ranges / jumps / sigmas, overlapping time bases); a
        :class:`insnav.checks.DataCheckError` names the file, column and cause.
    **overrides
        Any :class:`RunConfig` field, e.g. ``init_seed=3``.

    Returns
    -------
    Solution
    """
    import dataclasses

    if filter in ("kf", "rdkf", "exact"):  # delayed GNSS (seed 001), see insnav.delay
        from .delay import run_delayed

        if checks:
            from .checks import check_dataset

            check_dataset(dataset)
        return run_delayed(dataset, filter, config=config, **overrides)
    cfg = dataclasses.replace(config or RunConfig())
    if filter is not None:
        cfg.filter = filter
    if coupling is not None:
        cfg.coupling = coupling
    from .particle import PARTICLE_FILTERS, PARTICLE_OPTIONS  # seed 004 filters

    particle_opts = {k: overrides.pop(k) for k in list(overrides) if k in PARTICLE_OPTIONS}
    if cfg.filter in PARTICLE_FILTERS and cfg.coupling != "tight":
        raise ValueError(f"filter {cfg.filter!r} runs tightly coupled only (coupling='tight')")
    if particle_opts and cfg.filter not in PARTICLE_FILTERS:
        raise TypeError(f"run() options {sorted(particle_opts)} need filter 'upf', 'pf' or 'fukf'")
    for k, v in overrides.items():
        if not hasattr(cfg, k):
            raise TypeError(f"run() got an unknown option {k!r}")
        setattr(cfg, k, v)
    cfg.validate()
    input_report = None
    if sanitize:
        from .sanitize import sanitize_dataset  # input checks and repairs

        dataset, input_report = sanitize_dataset(dataset, sanitize)
    if checks:
        from .checks import check_dataset

        check_dataset(dataset)
    if cfg.coupling == "tight":
        from .tight import run_tight  # seed 003 tight coupling

        if cfg.filter in PARTICLE_FILTERS:
            from .particle import run_tight_particle  # seed 004 filters

            sol = run_tight_particle(dataset, cfg, **particle_opts)
        else:
            sol = run_tight(dataset, cfg)
        if input_report is not None:
            sol.summary["sanitize"] = input_report
        return sol

    imu = dataset.imu
    t = as_float_array(imu.t, "imu.t")
    dth = as_float_array(imu.dtheta_b, "imu.dtheta_b", (3,))
    dv = as_float_array(imu.dv_b, "imu.dv_b", (3,))
    if not sanitize:  # sanitize_imu has already refused non-finite samples
        for a, name in ((t, "imu.t"), (dth, "imu.dtheta_b"), (dv, "imu.dv_b")):
            check_finite(a, name)
    check_increasing(t, "imu.t", t0=float(dataset.t0))

    g = dataset.gnss
    gnss = np.column_stack([g.t_valid, g.lat_deg * DEG, g.lon_deg * DEG, g.h_m, g.v_n,
                            g.sigma_pos_n, g.sigma_vel_n]).astype(float) if len(g) else np.zeros((0, 13))
    if len(gnss):
        order = np.argsort(gnss[:, 0], kind="stable")
        gnss = np.ascontiguousarray(gnss[order])
        check_finite(gnss[:, [0, 7, 8, 9]], "gnss (time/position sigma)")
    gnss_t = gnss[:, 0].copy()

    rng = np.random.default_rng(cfg.init_seed)
    init, sig0 = _initial_state(dataset, cfg, rng)
    noise = cfg.imu or ImuNoise.from_dataset_model(dataset.imu_model)
    n = cfg.layout
    p0 = np.zeros(n)
    p0[:9] = sig0
    p0[9:12] = noise.acc_bias_sigma
    p0[12:15] = noise.gyro_bias_sigma
    if n == 21:
        p0[15:18] = noise.acc_scale_sigma
        p0[18:21] = noise.gyro_scale_sigma
    P0 = np.diag(p0 ** 2)
    lever = np.asarray(dataset.lever_arm_b if cfg.lever_arm_b is None else cfg.lever_arm_b, float)
    cycle = cfg.cycle_period_s
    if cycle is None:
        cycle = float(np.median(np.diff(gnss_t))) if len(gnss_t) > 1 else 1.0
    init_vec = np.array([dataset.t0, init.lat_deg * DEG, init.lon_deg * DEG, init.h_m, *init.v_n,
                         init.roll_deg * DEG, init.pitch_deg * DEG, init.yaw_deg * DEG])
    core_cfg = dict(lever_arm_b=lever, propagation_interval=cfg.propagation_interval_s,
                    cycle_period=cycle * 1.5 if cfg.filter == "ekf" else cycle, gate_chi2=cfg.gate_chi2,
                    use_position=cfg.use_position, use_velocity=cfg.use_velocity,
                    output_decimation=int(cfg.output_decimation),
                    sigma_columns=9)  # Solution keeps the position, velocity and attitude sigmas only
    if cfg.filter != "ekf":
        core_cfg.update(ut_alpha=cfg.ut_alpha, ut_beta=cfg.ut_beta,
                        ut_kappa=(3.0 - n) if cfg.ut_kappa is None else cfg.ut_kappa)
    out = _core.run_loose(cfg.filter, n, t, dth, dv, gnss, init_vec, P0, np.zeros(12), noise.as_core_dict(),
                          core_cfg)
    # unit conversions in place (the arrays are ours), one column at a time:
    # numpy's strided 2-D loops over 2-3 columns are ~10x slower than 1-D ones
    sig = out["sigma"]
    err = out["imu_err"]
    llh, rpy = out["llh"], out["rpy"]
    rpy *= RAD2DEG
    for j in (0, 1):
        llh[:, j] *= RAD2DEG
    for j in (6, 7, 8):
        sig[:, j] *= RAD2DEG
    sol = Solution(t=out["t"], lat_deg=llh[:, 0], lon_deg=llh[:, 1], h_m=llh[:, 2],
                   v_n=out["v_n"], roll_deg=rpy[:, 0], pitch_deg=rpy[:, 1], yaw_deg=rpy[:, 2],
                   sigma_pos_n_m=sig[:, 0:3], sigma_vel_n_mps=sig[:, 3:6], sigma_att_deg=sig[:, 6:9],
                   acc_bias_mps2=err[:, 0:3], gyro_bias_rps=err[:, 3:6], acc_scale=err[:, 6:9],
                   gyro_scale=err[:, 9:12], gnss_t=gnss_t, innovation=out["innovation"], nis=out["nis"],
                   gnss_status=out["status"],
                   summary=dict(filter=cfg.filter, coupling=cfg.coupling, layout=n, updates=int(out["updates"]),
                                rejected=int(out["rejected"]), cholesky_repairs=int(out["cholesky_repairs"]),
                                gnss_records=len(gnss_t)))
    if input_report is not None:
        sol.summary["sanitize"] = input_report
    if not (np.all(np.isfinite(sol.lat_deg)) and np.all(np.isfinite(sol.v_n))):
        bad = int(np.argmax(~np.isfinite(sol.lat_deg) | ~np.isfinite(sol.v_n).any(axis=1)))
        raise FloatingPointError(f"{cfg.filter}: the solution became non-finite at t={sol.t[bad]:.3f} s "
                                 f"(row {bad}); check the IMU data and the noise model")
    return sol
