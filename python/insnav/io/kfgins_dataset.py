"""Run insnav on KF-GINS data: a KF-GINS YAML configuration plus its IMU and
GNSS files become an insnav :class:`~insnav.data.dataset.Dataset` and a
:class:`~insnav.config.RunConfig` with the same initial state, initial
sigmas, IMU noise model (Gauss-Markov biases and scale factors with KF-GINS's
correlation time) and antenna lever arm.

Frames and units are the same as KF-GINS (NED, FRD, ZYX Euler, increments
over the preceding interval); times stay GPS seconds of week.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config import ImuNoise, RunConfig
from ..data.dataset import Dataset, GnssFixes, ImuData
from ..data.nav import NavState
from .kfgins import read_kfgins_config, read_kfgins_gnss, read_kfgins_imu
from ..units import RAD2DEG



def _or(v, default):
    return default if v is None else np.asarray(v, float)


def load_kfgins(config_path, imu_path=None, gnss_path=None, *, layout: int = 21):
    """Build a dataset and run configuration from a KF-GINS YAML file.

    Parameters
    ----------
    config_path : path
        KF-GINS YAML (``imupath``, ``gnsspath``, ``starttime``, ``initpos`` ...).
    imu_path, gnss_path : path, optional
        Override the files named in the YAML (``.xz`` is read transparently).
    layout : {15, 21}
        21 estimates scale factors as KF-GINS does.

    Returns
    -------
    dataset : Dataset
    config : RunConfig
        ``init_error=False``: the run starts from the YAML's initial state.
    """
    c, imu_path, gnss_path = _kfgins_files(config_path, imu_path, gnss_path)
    imu = read_kfgins_imu(imu_path, c["imudatalen"])
    gnss = read_kfgins_gnss(gnss_path)
    start = c["starttime_s"]
    end = c["endtime_s"]
    # the initial state is valid at the first IMU epoch at or after starttime
    i0 = int(np.searchsorted(imu.t, start))
    if i0 >= len(imu.t) - 1:
        raise ValueError(f"{config_path}: key 'starttime': {start} is after the IMU data "
                         f"({imu_path}: {len(imu.t)} records, the last at {imu.t[-1] if len(imu.t) else 'none'})")
    t0 = float(imu.t[i0])
    # t never decreases (read_kfgins_imu), so t0 < t <= end is one run of rows: views, no copy
    lo = int(np.searchsorted(imu.t, t0, side="right"))
    hi = len(imu.t) if end is None else int(np.searchsorted(imu.t, end, side="right"))
    if hi - lo < 2:
        raise ValueError(f"{config_path}: keys 'starttime' {start:.10g} and 'endtime' "
                         f"{-1 if end is None else end:.10g} leave {max(hi - lo, 0)} IMU records of {imu_path}")
    # the rows keep their file lines (messages name "file:line")
    imu_origin = None if imu.origin is None else imu.origin.take(np.arange(lo, hi), len(imu.t))
    imu = ImuData(imu.t[lo:hi], imu.dtheta_b[lo:hi], imu.dv_b[lo:hi], origin=imu_origin)
    g = (gnss.t_valid > t0) & (gnss.t_valid <= imu.t[-1])
    gnss = GnssFixes(*(np.asarray(getattr(gnss, f))[g] for f in
                       ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n")),
                     origin=None if gnss.origin is None else gnss.origin.take(g, len(g)))
    initial, cfg = _kfgins_run_config(c, config_path, layout)
    # the records outside the run's IMU span are not carried; the run summary counts them
    scenario = {"kfgins_config": str(config_path), "gnss_outside_imu_span": int(g.size - np.count_nonzero(g))}
    ds = Dataset(imu=imu, gnss=gnss, truth=None, gnss_raw=None, imu_errors=None, scenario=scenario,
                 lever_arm_b=np.asarray(cfg.lever_arm_b), initial=initial, t0=t0, gps_time_offset_s=0.0,
                 imu_model={}, name=Path(config_path).stem)
    return ds, cfg


def _kfgins_files(config_path, imu_path=None, gnss_path=None):
    """The YAML read, and the IMU and GNSS file paths (given, else the YAML's; ``.xz`` beside them)."""
    c = read_kfgins_config(config_path)
    imu_path = imu_path or c["imupath"]
    gnss_path = gnss_path or c["gnsspath"]
    for p, key in ((imu_path, "imupath"), (gnss_path, "gnsspath")):
        if p is None or not Path(p).exists():
            alt = Path(str(p) + ".xz") if p else None
            if alt is not None and alt.exists():
                if key == "imupath":
                    imu_path = alt
                else:
                    gnss_path = alt
                continue
            raise FileNotFoundError(f"{config_path}: key '{key}': file not found: {p}")
    return c, imu_path, gnss_path


def _kfgins_run_config(c, config_path, layout: int):
    """The initial state and the run configuration of a read KF-GINS YAML ``c``."""
    if c["initpos"] is None or c["initatt_rad"] is None:
        raise ValueError(f"{config_path}: keys 'initpos' and 'initatt' are required")
    pos, att = c["initpos"], c["initatt_rad"]
    initial = NavState(pos[0] * RAD2DEG, pos[1] * RAD2DEG, pos[2], _or(c["initvel_n_mps"], np.zeros(3)),
                       *(att * RAD2DEG))
    n = c["imunoise"]
    tau = n["corrtime_s"] if np.isfinite(n["corrtime_s"]) else 3600.0
    noise = ImuNoise(
        gyro_arw=_or(n["arw_rad_per_sqrts"], np.full(3, 1e-4)).tolist(),
        acc_vrw=_or(n["vrw_mps_per_sqrts"], np.full(3, 1e-3)).tolist(),
        gyro_bias_sigma=_or(n["gbstd_radps"], np.full(3, 1e-5)).tolist(),
        acc_bias_sigma=_or(n["abstd_mps2"], np.full(3, 1e-3)).tolist(),
        gyro_bias_tau=[tau] * 3, acc_bias_tau=[tau] * 3,
        gyro_scale_sigma=_or(n["gsstd"], np.full(3, 1e-4)).tolist(),
        acc_scale_sigma=_or(n["asstd"], np.full(3, 1e-4)).tolist(),
        gyro_scale_tau=[tau] * 3, acc_scale_tau=[tau] * 3)
    def given(key, scale=True):  # a 3-vector of the YAML, or None
        v = c[key]
        if v is None or (not scale and layout != 21):
            return None
        return np.asarray(v, float).tolist()

    if layout != 21:  # a non-zero initial scale factor cannot be carried by 15 states
        for key in ("initgyrscale", "initaccscale"):
            if c[key] is not None and np.any(np.asarray(c[key]) != 0):
                raise ValueError(f"{config_path}: key '{key}': scale factors need the 21-state layout "
                                 f"(layout={layout} has none)")
    # the initial IMU-error estimate and its sigmas (KF-GINS: initial state and P0 of the
    # bias and scale-factor states; the sigmas default to the imunoise values, as in KF-GINS)
    cfg = RunConfig(filter="ekf", coupling="loose", layout=layout,
                    init_sigma_pos_m=_or(c["initposstd_m"], np.full(3, 1.0)).tolist(),
                    init_sigma_vel_mps=_or(c["initvelstd_mps"], np.full(3, 0.1)).tolist(),
                    init_sigma_att_deg=(_or(c["initattstd_rad"], np.full(3, 0.01)) * RAD2DEG).tolist(),
                    init_error=False, imu=noise,
                    lever_arm_b=_or(c["antlever_b_m"], np.zeros(3)).tolist(),
                    init_acc_bias_mps2=given("initaccbias_mps2"), init_gyro_bias_radps=given("initgyrbias_radps"),
                    init_acc_scale=given("initaccscale", scale=False),
                    init_gyro_scale=given("initgyrscale", scale=False),
                    init_sigma_acc_bias_mps2=given("initbastd_mps2"),
                    init_sigma_gyro_bias_radps=given("initbgstd_radps"),
                    init_sigma_acc_scale=given("initsastd", scale=False),
                    init_sigma_gyro_scale=given("initsgstd", scale=False))
    return initial, cfg


def kfgins_stream_inputs(config_path, imu_path=None, gnss_path=None, *, layout: int = 21):
    """What a block-by-block run of KF-GINS files needs before its IMU file is
    read (:mod:`insnav.filters.stream`): the YAML (``read_kfgins_config``), the
    IMU file's path, every GNSS record, a dataset without IMU (initial state,
    lever arm, scenario; ``t0`` set by the stream) and the run configuration,
    exactly as :func:`load_kfgins` makes them."""
    c, imu_path, gnss_path = _kfgins_files(config_path, imu_path, gnss_path)
    from .text_blocks import read_gnss_text_blocks

    # in blocks; a plain file's fixes read back on demand (the times held, 8 bytes per fix), a compressed one's held
    gnss = read_gnss_text_blocks(gnss_path, on_demand=True)
    initial, cfg = _kfgins_run_config(c, config_path, layout)
    scenario = {"kfgins_config": str(config_path), "gnss_outside_imu_span": 0}
    ds = Dataset(imu=None, gnss=gnss, truth=None, gnss_raw=None, imu_errors=None, scenario=scenario,
                 lever_arm_b=np.asarray(cfg.lever_arm_b), initial=initial, t0=float("nan"), gps_time_offset_s=0.0,
                 imu_model={}, name=Path(config_path).stem)
    return dict(yaml=c, imu_path=imu_path, gnss=gnss, dataset=ds, config=cfg)
