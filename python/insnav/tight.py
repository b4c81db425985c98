"""Tightly coupled GNSS/INS (seed 003, Xu et al. 2012): 17-state
filters on pseudorange and pseudorange rate.

Python owns the geometry: satellite positions, velocities and clocks (from the
simulator's ``gnss_raw`` table or from GPS LNAV broadcast ephemerides,
IS-GPS-200, with transmit time and Sagnac as in
:mod:`insnav.gnss.ephemeris`), elevation mask, best-GDOP selection,
per-satellite sigmas and (real data) Klobuchar / Saastamoinen corrections are
computed for all epochs at once and handed to the C++ loop
(``cpp/include/insnav/engine/tight_engine.hpp``) in one call as flat arrays.

Public functions
----------------
:func:`run_tight`             the run (``insnav.run(ds, coupling="tight")`` calls it)
:func:`tight_inputs_from_raw` simulator ``GnssRaw`` -> :class:`TightInputs`
:func:`tight_inputs_from_rinex` RINEX obs + nav -> :class:`TightInputs`
:func:`pseudorange_sigma`     elevation / C/N0 sigma model
:func:`clock_model`           receiver clock noise (TCXO defaults, or the simulator's)

Receiver clock model (Layout17 states 15, 16: bias [m], drift [m/s]): the
bias is the integral of the drift plus white noise, the drift a random walk,
``b' = d + w_b``, ``d' = w_d`` with PSDs ``clock_bias_psd`` [m^2/s] and
``clock_drift_psd`` [m^2/s^3] (Brown & Hwang, *Introduction to Random
Signals and Applied Kalman Filtering*, 4th ed., sec. 9.3, eqs. (9.3.8)-(9.3.9):
S_b = c^2 h0 / 2, S_d = 2 pi^2 c^2 h_-2).  Defaults for a TCXO (their
Table 9.1: h0 = 2e-19, h_-2 = 2e-20, plus margin for flicker noise):
``clock_bias_psd = 0.1`` m^2/s, ``clock_drift_psd = 0.04`` m^2/s^3.
For simulator datasets the simulated clock's own random-walk densities are used.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from . import _core, earth
from ._validate import as_float_array, check_finite, check_increasing
from .config import DEG, ImuNoise, RunConfig
from .engine import RAD2DEG, Solution, _initial_state

__all__ = ["TightInputs", "TightSolution", "run_tight", "tight_inputs_from_raw", "tight_inputs_from_rinex",
           "pseudorange_sigma", "clock_model", "clock_psd_of_class", "TCXO_CLOCK_BIAS_PSD", "TCXO_CLOCK_DRIFT_PSD", "MAX_SATS"]

#: TCXO receiver clock noise (Brown & Hwang Table 9.1, see the module docstring)
TCXO_CLOCK_BIAS_PSD = 0.1     # m^2/s
TCXO_CLOCK_DRIFT_PSD = 0.04   # m^2/s^3
#: satellites per epoch the C++ measurement can hold (2 rows each, kMaxMeasRows = 32)
MAX_SATS = 16

_SAT_COLS = ("pseudorange_m", "pseudorange_rate_mps", "sat_x_m", "sat_y_m", "sat_z_m", "sat_vx_mps",
             "sat_vy_mps", "sat_vz_mps", "sat_clock_bias_m", "sat_clock_drift_mps", "sigma_pr_m", "sigma_prr_mps")


@dataclass
class TightInputs:
    """All epochs' satellite data in the flat layout of ``_core.run_tight``.

    Attributes
    ----------
    epoch_t : (E,) time of validity of each epoch (dataset time) [s]
    epoch_start : (E+1,) int64; epoch e owns rows ``epoch_start[e]:epoch_start[e+1]``
    sats : (M, 12) float, columns :data:`_SAT_COLS`: measured pseudorange [m] and rate
        [m/s] (NaN = not used), satellite ECEF position [m] / velocity [m/s] in the
        frame at reception, ``c dt_sv`` minus modelled atmosphere delays [m], its rate,
        1-sigma pseudorange [m] and rate [m/s]
    prn : (M,) int
    elevation_deg : (M,) seen from the (approximate) receiver
    """

    epoch_t: np.ndarray
    epoch_start: np.ndarray
    sats: np.ndarray
    prn: np.ndarray
    elevation_deg: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def row_epoch(self) -> np.ndarray:
        """(M,) epoch index of each row."""
        return np.repeat(np.arange(self.epoch_t.size), np.diff(self.epoch_start))

    def n_sats(self) -> np.ndarray:
        """(E,) satellites per epoch."""
        return np.diff(self.epoch_start)

    @classmethod
    def from_rows(cls, t_row, prn, sats, el_deg, info=None) -> "TightInputs":
        """Group rows by time (rows sorted by time on output)."""
        t_row = np.asarray(t_row, float)
        order = np.argsort(t_row, kind="stable")
        t_row = t_row[order]
        ep_t, start = np.unique(t_row, return_index=True)
        epoch_start = np.append(start, t_row.size).astype(np.int64)
        return cls(ep_t, epoch_start, np.ascontiguousarray(np.asarray(sats, float)[order]),
                   np.asarray(prn)[order], np.asarray(el_deg, float)[order], dict(info or {}))

    def select(self, keep) -> "TightInputs":
        """Keep the rows ``keep`` (bool (M,)); empty epochs stay (prediction only)."""
        keep = np.asarray(keep, bool)
        ep = self.row_epoch[keep]
        counts = np.bincount(ep, minlength=self.epoch_t.size)
        start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return TightInputs(self.epoch_t.copy(), start, np.ascontiguousarray(self.sats[keep]), self.prn[keep],
                           self.elevation_deg[keep], dict(self.info))


@dataclass
class TightSolution(Solution):
    """:class:`insnav.engine.Solution` plus the tight-coupling outputs.

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


def pseudorange_sigma(el_rad, sigma_zenith_m, cn0_dbhz=None, cn0_ref_dbhz=45.0, floor_el_deg=5.0):
    """Elevation (and C/N0) dependent 1-sigma.

    ``sigma = sigma_zenith / sin(el)`` (Groves 2013, eq. (9.168) form), and
    when C/N0 is given, times ``sqrt(10^((cn0_ref - cn0)/10))`` (tracking
    noise variance inversely proportional to C/N0, Groves eq. (9.165)); the
    C/N0 factor is not allowed below 1.
    """
    s = np.asarray(sigma_zenith_m, float) / np.sin(np.maximum(np.asarray(el_rad, float), np.deg2rad(floor_el_deg)))
    if cn0_dbhz is not None:
        cn0 = np.asarray(cn0_dbhz, float)
        f = np.sqrt(np.maximum(10.0 ** ((cn0_ref_dbhz - np.where(np.isfinite(cn0), cn0, cn0_ref_dbhz)) / 10.0), 1.0))
        s = s * f
    return s


def clock_model(dataset) -> tuple[float, float]:
    """(clock_bias_psd [m^2/s], clock_drift_psd [m^2/s^3]) for a dataset.

    A simulator dataset's ``gnss_raw`` random-walk densities (squared, with a
    small floor), else the TCXO defaults.
    """
    gr = (getattr(dataset, "scenario", None) or {}).get("gnss_raw") or {}
    if "clock_bias_rw_m_per_sqrts" in gr or "clock_drift_rw_mps_per_sqrts" in gr or "clock" in gr:
        from .sim.gnss_raw import CLOCK_CLASSES

        cb, cd = CLOCK_CLASSES.get(gr.get("clock", ""), (0.0, 0.0))
        qb = float(gr.get("clock_bias_rw_m_per_sqrts", cb)) ** 2
        qd = float(gr.get("clock_drift_rw_mps_per_sqrts", cd)) ** 2
        return max(qb, 1e-6), max(qd, 1e-12)
    return TCXO_CLOCK_BIAS_PSD, TCXO_CLOCK_DRIFT_PSD


def clock_psd_of_class(name: str) -> tuple[float, float]:
    """(clock_bias_psd [m^2/s], clock_drift_psd [m^2/s^3]) of a named clock class
    (``"tcxo"``, ``"ocxo"``, ``"rubidium"``; Brown & Hwang Table 9.1, see
    :mod:`insnav.sim.gnss_raw`)."""
    from .sim.gnss_raw import CLOCK_CLASSES

    if name not in CLOCK_CLASSES:
        raise ValueError(f"clock class {name!r} unknown; known: {', '.join(CLOCK_CLASSES)}")
    qb, qd = CLOCK_CLASSES[name]
    return qb * qb, qd * qd


def _limit_sats(inp: TightInputs, max_sats: int) -> TightInputs:
    """Best-GDOP subset of ``max_sats`` per epoch where an epoch has more."""
    from .gnss.geometry import select_best_gdop

    counts = inp.n_sats()
    if max_sats <= 0 or counts.max(initial=0) <= max_sats:
        return inp
    keep = np.ones(len(inp.prn), bool)
    for e in np.flatnonzero(counts > max_sats):
        a, b = inp.epoch_start[e], inp.epoch_start[e + 1]
        # LOS from the Earth's centre direction is not needed: GDOP is rotation invariant,
        # use the ECEF LOS from the mean of the rows' approximate receiver (info)
        r_rx = inp.info.get("approx_r_e")
        r_rx = np.asarray(r_rx if r_rx is not None else np.zeros(3), float)
        d = inp.sats[a:b, 2:5] - r_rx
        u = d / np.linalg.norm(d, axis=1)[:, None]
        if max_sats >= 4:
            sel, _ = select_best_gdop(u, max_sats)
        else:
            sel = np.argsort(-inp.elevation_deg[a:b], kind="stable")[:max_sats]
        k = np.zeros(b - a, bool)
        k[sel] = True
        keep[a:b] = k
    return inp.select(keep)


def tight_inputs_from_raw(raw, *, elevation_mask_deg: float = 0.0, max_sats: int = MAX_SATS,
                          sigma_pr_m=None, sigma_prr_mps=None, elevation_weighting: bool = False,
                          approx_r_e=None) -> TightInputs:
    """Simulator raw observations (:class:`insnav.dataset.GnssRaw`) -> :class:`TightInputs`.

    Sigmas default to the dataset's own (the simulated noise); with
    ``elevation_weighting`` they are scaled by ``1/sin(el)``.  The true
    receiver clock columns are never read.
    """
    el = np.asarray(raw.elevation_deg, float)
    spr = np.asarray(raw.sigma_pr_m if sigma_pr_m is None else np.broadcast_to(sigma_pr_m, el.shape), float)
    sprr = np.asarray(raw.sigma_prr_mps if sigma_prr_mps is None else np.broadcast_to(sigma_prr_mps, el.shape), float)
    if elevation_weighting:
        spr = pseudorange_sigma(np.deg2rad(el), spr)
        sprr = pseudorange_sigma(np.deg2rad(el), sprr)
    sats = np.column_stack([raw.pseudorange_m, raw.pseudorange_rate_mps, raw.sat_r_e, raw.sat_v_e,
                            raw.sat_clock_bias_m, raw.sat_clock_drift_mps, spr, sprr])
    inp = TightInputs.from_rows(raw.t, raw.prn, sats, el, info=dict(source="simulator gnss_raw",
                                                                    approx_r_e=approx_r_e))
    if elevation_mask_deg > 0:
        inp = inp.select(inp.elevation_deg >= elevation_mask_deg)
    return _limit_sats(inp, max_sats)


def tight_inputs_from_rinex(obs, nav, t0_gps_s: float, approx_r_e, *, elevation_mask_deg: float = 10.0,
                            max_sats: int = MAX_SATS, iono: bool = True, tropo: bool = True,
                            sigma_pr_zenith_m: float = 3.0, sigma_prr_zenith_mps: float = 0.3,
                            use_cn0: bool = True, t_range=None) -> TightInputs:
    """RINEX observations + broadcast navigation -> :class:`TightInputs`.

    Parameters
    ----------
    obs : insnav.gnss.ObsData
    nav : insnav.gnss.NavData
    t0_gps_s : float
        GPS time of dataset time 0 [s]; ``epoch_t = t_gps - t0_gps_s``.
    approx_r_e : (3,) approximate receiver ECEF position [m] (for light time,
        elevation and the atmosphere; a few hundred metres do not matter).
    iono, tropo : Klobuchar (needs ``nav.ion_alpha/ion_beta``) and Saastamoinen.
    sigma_pr_zenith_m, sigma_prr_zenith_mps, use_cn0 : see :func:`pseudorange_sigma`.
    t_range : (t_min, t_max) in dataset time, optional.

    Notes
    -----
    Time tags are receiver time.  The receiver clock offset of each epoch is
    first estimated (median of pseudorange minus predicted range at
    ``approx_r_e``); satellites are then evaluated at the true reception time
    ``t_tag - dt_rx`` (a 1 ms receiver clock error otherwise moves a
    satellite by ~4 m along the line of sight), and the epoch is placed at its
    true time on the dataset time axis.  Doppler -> rate: ``-lambda_L1 D1``.
    T_GD is applied (L1 C/A user).
    """
    from .gnss.ephemeris import C_LIGHT, select_ephemeris, transmit_states
    from .gnss.corrections import klobuchar_delay, saastamoinen_delay
    from .gnss.geometry import elevation_azimuth
    from .gnss.measurements import L1_WAVELENGTH

    eph = nav.eph
    r0 = np.asarray(approx_r_e, float)
    t_tag = np.asarray(obs.t_gps_s, float)
    ok = np.isfinite(obs.C1)
    if t_range is not None:
        ok &= (t_tag - t0_gps_s >= t_range[0]) & (t_tag - t0_gps_s <= t_range[1])
    idx = select_ephemeris(eph, obs.prn, t_tag)
    ok &= idx >= 0
    rows = np.flatnonzero(ok)
    ep = obs.epoch[rows]
    n_ep = obs.epoch_t_gps_s.size
    clk = np.zeros(n_ep)
    lat, lon, h = earth.ecef_to_geodetic(r0)
    for _ in range(2):
        t_rx = t_tag[rows] - clk[ep] / C_LIGHT
        ts = transmit_states(eph, idx[rows], t_rx, r0, tgd=True)
        raw = obs.C1[rows] - (ts.range_m - C_LIGHT * ts.clock_bias_s)
        for e in np.unique(ep):
            clk[e] = np.median(raw[ep == e])
    el, az = elevation_azimuth(r0, ts.r_e)
    iono_m = np.zeros(rows.size)
    tropo_m = np.zeros(rows.size)
    if iono and nav.ion_alpha is not None and nav.ion_beta is not None:
        iono_m = klobuchar_delay(t_rx, np.full(rows.size, lat), np.full(rows.size, lon), el, az,
                                 nav.ion_alpha, nav.ion_beta)
    if tropo:
        tropo_m = saastamoinen_delay(np.full(rows.size, lat), np.full(rows.size, h), el)
    prr = -L1_WAVELENGTH * np.asarray(obs.D1, float)[rows]
    cn0 = np.asarray(obs.S1, float)[rows] if use_cn0 else None
    spr = pseudorange_sigma(el, sigma_pr_zenith_m, cn0)
    sprr = pseudorange_sigma(el, sigma_prr_zenith_mps, cn0)
    # modelled delays go into the satellite "clock" column: predicted = range + b - (c dt_sv - I - T)
    sats = np.column_stack([obs.C1[rows], prr, ts.r_e, ts.v_e, C_LIGHT * ts.clock_bias_s - iono_m - tropo_m,
                            C_LIGHT * ts.clock_drift_s_s, spr, sprr])
    # epoch time: true reception time (receiver tag minus the estimated clock offset)
    t_ep = t_tag[rows] - clk[ep] / C_LIGHT - t0_gps_s
    inp = TightInputs.from_rows(t_ep, obs.prn[rows], sats, np.degrees(el),
                                info=dict(source=str(getattr(obs, "path", "rinex")), approx_r_e=r0,
                                          rx_clock_tag_m=clk, iono_m=iono_m, tropo_m=tropo_m))
    # epochs of one tag share one true time only if the clock estimate is per epoch (it is)
    inp = inp.select(np.degrees(el)[np.argsort(t_ep, kind="stable")] >= elevation_mask_deg)
    return _limit_sats(inp, max_sats)


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
    imu = dataset.imu
    t = as_float_array(imu.t, "imu.t")
    dth = as_float_array(imu.dtheta_b, "imu.dtheta_b", (3,))
    dv = as_float_array(imu.dv_b, "imu.dv_b", (3,))
    for a, name in ((t, "imu.t"), (dth, "imu.dtheta_b"), (dv, "imu.dv_b")):
        check_finite(a, name)
    check_increasing(t, "imu.t", t0=float(dataset.t0))

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
        inputs = _limit_sats(inputs, MAX_SATS)

    rng = np.random.default_rng(cfg.init_seed)
    init, sig0 = _initial_state(dataset, cfg, rng)
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
                    cycle_period=cycle * 1.5 if cfg.filter == "ekf" else cycle, gate_chi2=cfg.gate_chi2,
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
