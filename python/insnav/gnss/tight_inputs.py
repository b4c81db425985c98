"""The tight filters' GNSS input: every epoch's satellites in the flat layout
of ``_core.run_tight`` (pseudorange, rate, satellite position, velocity and
clock, sigmas), built from the simulator's raw observations or from RINEX
observation and navigation files (GPS LNAV broadcast ephemerides,
IS-GPS-200, transmit time and Sagnac as in :mod:`insnav.gnss.ephemeris`;
with ``systems="GREC"`` also GLONASS, Galileo and BeiDou through
:mod:`insnav.gnss.broadcast`; Klobuchar / Saastamoinen corrections), with an
elevation mask, a best-GDOP satellite selection and per-satellite sigmas.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import _core, earth

__all__ = ["TightInputs", "MAX_SATS", "pseudorange_sigma", "limit_sats", "tight_inputs_from_raw",
           "tight_inputs_from_rinex"]

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
    system : (M,) one-letter RINEX system code of each row (:data:`insnav.gnss.systems.SYSTEMS`);
        None on construction means GPS for every row
    phase : (M, 4) float or None
        Carrier phase of each row for the TDCP rows (:func:`insnav.gnss.tdcp.phase_rows`:
        phase [m], wavelength [m], sigma [m], LLI); None: no carrier phase
    """

    epoch_t: np.ndarray
    epoch_start: np.ndarray
    sats: np.ndarray
    prn: np.ndarray
    elevation_deg: np.ndarray
    info: dict = field(default_factory=dict)
    system: np.ndarray | None = None
    phase: np.ndarray | None = None

    def __post_init__(self):
        if self.system is None:
            self.system = np.full(len(self.prn), "G", dtype="<U1")
        else:
            self.system = np.asarray(self.system, dtype="<U1")
            if self.system.shape != np.shape(self.prn):
                raise ValueError(f"TightInputs: system has {self.system.size} rows, prn {np.size(self.prn)}")

    @property
    def row_epoch(self) -> np.ndarray:
        """(M,) epoch index of each row."""
        return np.repeat(np.arange(self.epoch_t.size), np.diff(self.epoch_start))

    def n_sats(self) -> np.ndarray:
        """(E,) satellites per epoch."""
        return np.diff(self.epoch_start)

    @classmethod
    def from_rows(cls, t_row, prn, sats, el_deg, info=None, system=None) -> "TightInputs":
        """Group rows by time (rows sorted by time on output); ``system`` None: GPS."""
        t_row = np.asarray(t_row, float)
        order = np.argsort(t_row, kind="stable")
        t_row = t_row[order]
        ep_t, start = np.unique(t_row, return_index=True)
        epoch_start = np.append(start, t_row.size).astype(np.int64)
        return cls(ep_t, epoch_start, np.ascontiguousarray(np.asarray(sats, float)[order]),
                   np.asarray(prn)[order], np.asarray(el_deg, float)[order], dict(info or {}),
                   None if system is None else np.asarray(system, dtype="<U1")[order])

    def select(self, keep) -> "TightInputs":
        """Keep the rows ``keep`` (bool (M,)); empty epochs stay (prediction only)."""
        keep = np.asarray(keep, bool)
        ep = self.row_epoch[keep]
        counts = np.bincount(ep, minlength=self.epoch_t.size)
        start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return TightInputs(self.epoch_t.copy(), start, np.ascontiguousarray(self.sats[keep]), self.prn[keep],
                           self.elevation_deg[keep], dict(self.info), self.system[keep],
                           None if self.phase is None else self.phase[keep].copy())


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


def limit_sats(inp: TightInputs, max_sats: int) -> TightInputs:
    """Best-GDOP subset of ``max_sats`` per epoch where an epoch has more."""
    from .geometry import select_best_gdop

    counts = inp.n_sats()
    if max_sats <= 0 or counts.max(initial=0) <= max_sats:
        return inp
    if max_sats >= 4 and hasattr(_core, "best_gdop_keep") and counts.max() <= _core.GDOP_MAX_SATS:
        # every epoch in one compiled call (insnav/gnss/gdop_selection.hpp): the subsets of the loop below
        r_rx = inp.info.get("approx_r_e")
        d = inp.sats[:, 2:5] - np.asarray(r_rx if r_rx is not None else np.zeros(3), float)
        u = d / np.linalg.norm(d, axis=1)[:, None]
        return inp.select(_core.best_gdop_keep(u, np.asarray(inp.epoch_start, np.int64), int(max_sats), 5000))
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
    """Simulator raw observations (:class:`insnav.data.dataset.GnssRaw`) -> :class:`TightInputs`.

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
                                                                    approx_r_e=approx_r_e),
                                system=getattr(raw, "system", None))
    if elevation_mask_deg > 0:
        inp = inp.select(inp.elevation_deg >= elevation_mask_deg)
    return limit_sats(inp, max_sats)


def tight_inputs_from_rinex(obs, nav, t0_gps_s: float, approx_r_e, *, elevation_mask_deg: float = 10.0,
                            max_sats: int = MAX_SATS, iono: bool = True, tropo: bool = True,
                            sigma_pr_zenith_m: float = 3.0, sigma_prr_zenith_mps: float = 0.3,
                            use_cn0: bool = True, t_range=None, systems: str = "G", _prior=None,
                            _keep=None) -> TightInputs:
    """RINEX observations + broadcast navigation -> :class:`TightInputs`.

    Parameters
    ----------
    obs : insnav.gnss.ObsData
        Read with the systems wanted (``read_rinex_obs(path, systems="GREC")``).
    nav : insnav.gnss.NavData
        Read with the systems wanted (``read_rinex_nav(path, systems="GREC")``).
    systems : str
        Systems to use, letters of ``"GREC"``; default GPS only (results
        identical to the GPS-only code).  Each row's system is in
        ``TightInputs.system``.  Other systems: states from
        :func:`insnav.gnss.broadcast.transmit_states_multi` with each row's
        pseudorange code (group delay T_GD/BGD of that signal), Doppler ->
        rate with the signal's wavelength (GLONASS: the satellite's FDMA
        channel), Klobuchar scaled by ``(f_L1 / f)^2`` for the signal's
        frequency (Galileo's NeQuick is not implemented).
    t0_gps_s : float
        GPS time of dataset time 0 [s]; ``epoch_t = t_gps - t0_gps_s``.
    approx_r_e : (3,) approximate receiver ECEF position [m] (for light time,
        elevation and the atmosphere; a few hundred metres do not matter).
    iono, tropo : Klobuchar (``nav.ion_alpha/ion_beta``; RTKLIB's defaults without them,
        :func:`insnav.gnss.corrections.klobuchar_coefficients`) and Saastamoinen.
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

    The satellite states are evaluated once per row, at the time tags; the
    second clock iteration carries them (:func:`carry_transmit_states`).
    ``_keep`` (a dict) receives this call's states; given back as ``_prior`` to a
    call on the same files from another ``approx_r_e``, they are carried to it
    instead of evaluated again.
    """
    from .._median import group_median
    from .ephemeris import C_LIGHT, select_ephemeris, transmit_states
    from .corrections import klobuchar_coefficients, klobuchar_delay, saastamoinen_delay
    from .geometry import elevation_azimuth
    from .measurements import L1_WAVELENGTH
    from .rinex import _parse_systems

    systems = _parse_systems(systems)
    if systems != "G":
        return _tight_inputs_multi(obs, nav, t0_gps_s, approx_r_e, elevation_mask_deg=elevation_mask_deg,
                                   max_sats=max_sats, iono=iono, tropo=tropo, sigma_pr_zenith_m=sigma_pr_zenith_m,
                                   sigma_prr_zenith_mps=sigma_prr_zenith_mps, use_cn0=use_cn0, t_range=t_range,
                                   systems=systems, _prior=_prior, _keep=_keep)
    eph = nav.eph
    r0 = np.asarray(approx_r_e, float)
    t_tag = np.asarray(obs.t_gps_s, float)
    ok = np.isfinite(obs.C1)
    obs_sys = getattr(obs, "system", None)
    if obs_sys is not None:
        ok &= np.asarray(obs_sys) == "G"
    if t_range is not None:
        ok &= (t_tag - t0_gps_s >= t_range[0]) & (t_tag - t0_gps_s <= t_range[1])
    idx = select_ephemeris(eph, obs.prn, t_tag)
    ok &= idx >= 0
    rows = np.flatnonzero(ok)
    ep = obs.epoch[rows]
    n_ep = obs.epoch_t_gps_s.size
    clk = np.zeros(n_ep)
    lat, lon, h = earth.ecef_to_geodetic(r0)
    prior = _prior if _prior is not None and np.array_equal(_prior["rows"], rows) else None
    for it in range(2):
        t_rx = t_tag[rows] - clk[ep] / C_LIGHT
        evaluate = (lambda far: transmit_states(eph, idx[rows][far], t_rx[far], r0, tgd=True))  # noqa: E731
        if it == 0:
            ts = (transmit_states(eph, idx[rows], t_rx, r0, tgd=True) if prior is None
                  else _carried(prior["tag"], t_rx, r0, evaluate))
            ts_tag = ts
        else:  # the same satellites a receiver clock offset earlier: carried, not evaluated again
            ts = _carried(ts if prior is None else prior["final"], t_rx, r0, evaluate)
        raw = obs.C1[rows] - (ts.range_m - C_LIGHT * ts.clock_bias_s)
        med, present = group_median(raw, ep, n_ep)
        clk[present] = med[present]
    el, az = elevation_azimuth(r0, ts.r_e)
    iono_m = np.zeros(rows.size)
    tropo_m = np.zeros(rows.size)
    if iono:
        alpha, beta, _ = klobuchar_coefficients(nav)
        iono_m = klobuchar_delay(t_rx, np.full(rows.size, lat), np.full(rows.size, lon), el, az, alpha, beta)
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
    if _keep is not None:
        _keep.update(rows=rows, tag=ts_tag, final=ts)
    return limit_sats(inp, max_sats)




#: largest change of the transmit time [s] over which :func:`carry_transmit_states` carries a state
#: (callers evaluate the others again): at 0.01 s the neglected terms (the non-central part of the
#: acceleration, ~1e-4 m/s^2, and the jerk, ~1e-4 m/s^3) stay below 1e-8 m
CARRY_MAX_S = 0.01


def carry_transmit_states(r_e, v_e, clock_bias_s, clock_drift_s_s, t_tx_gps_s, tau_s, t_rx_gps_s, r_rx_e):
    """Satellite states at transmission carried to a new reception time and receiver position.

    The state of each row at its old transmit time ``t1`` (in the ECEF frame
    at transmission: the Sagnac rotation ``R3(OMEGA_E_DOT tau1)`` undone) is
    expanded to second order, ``r(t1 + d) = r + v d + a d^2 / 2``,
    ``v(t1 + d) = v + a d``, with ``a`` the central-force acceleration in the
    rotating ECEF frame (as the light-time iteration of
    ``insnav/gnss/broadcast_orbit.hpp`` does); the light time
    ``tau = |R3(OMEGA_E_DOT tau) r(t_rx - tau) - r_rx| / c`` is iterated on
    it (Misra & Enge 2011, sec. 5.1.2; the Sagnac rotation as in
    :func:`insnav.gnss.ephemeris.transmit_states`) and the clock carried as
    ``dt + dt' d``.  For the shifts of a receiver clock estimate and of a
    start position (|d| from nanoseconds to milliseconds) this equals an
    evaluation of the ephemeris at the new time to about 1e-7 m (the
    evaluation itself is reproducible to about 5e-8 m between times
    1e-7 s apart: its iterations stop at tolerances, and 2.6e7 m
    positions round at 4e-9 m).

    Parameters
    ----------
    r_e, v_e : (k, 3) state at transmission in the ECEF frame at reception [m], [m/s]
    clock_bias_s, clock_drift_s_s : (k,) satellite clock [s], [s/s]
    t_tx_gps_s, tau_s : (k,) transmit time and light time of that state [s]
    t_rx_gps_s : (k,) new reception time [s];  r_rx_e : (3,) or (k, 3) new receiver position [m]

    Returns
    -------
    (dict, far)
        ``r_e``, ``v_e``, ``clock_bias_s``, ``t_tx_gps_s``, ``tau_s``, ``range_m`` at the new
        reception time (the drift unchanged); ``far`` (k,) bool: the transmit time moved by more
        than :data:`CARRY_MAX_S` (or is not finite) -- evaluate those rows again.
    """
    from .ephemeris import C_LIGHT, GM_GPS, OMEGA_E_DOT

    t_rx = np.asarray(t_rx_gps_s, float)
    r_rx = np.broadcast_to(np.asarray(r_rx_e, float), (t_rx.size, 3))
    w = OMEGA_E_DOT
    c1, s1 = np.cos(w * tau_s), np.sin(w * tau_s)
    (xe, ye, ze), (vxe, vye, vze) = np.asarray(r_e, float).T, np.asarray(v_e, float).T
    x, y, z = c1 * xe - s1 * ye, s1 * xe + c1 * ye, ze  # the ECEF frame at transmission
    vx, vy, vz = c1 * vxe - s1 * vye, s1 * vxe + c1 * vye, vze
    k = -GM_GPS / (x * x + y * y + z * z) ** 1.5
    ax, ay, az = k * x + w * w * x + 2.0 * w * vy, k * y + w * w * y - 2.0 * w * vx, k * z
    xr, yr, zr = r_rx[:, 0], r_rx[:, 1], r_rx[:, 2]

    def at(tau):
        d = t_rx - tau - t_tx_gps_s
        hd = 0.5 * d * d
        return d, x + vx * d + ax * hd, y + vy * d + ay * hd, z + vz * d + az * hd

    def dist(c, s, px, py, pz):  # |R3(theta) p - r_rx|
        dx, dy, dz = c * px + s * py - xr, -s * px + c * py - yr, pz - zr
        return np.sqrt(dx * dx + dy * dy + dz * dz)

    tau = np.asarray(tau_s, float)
    for _ in range(10):
        _, px, py, pz = at(tau)
        tau_new = dist(np.cos(w * tau), np.sin(w * tau), px, py, pz) / C_LIGHT
        done = not np.any(np.abs(tau_new - tau) >= 1e-12)
        tau = tau_new
        if done:
            break
    d, px, py, pz = at(tau)
    c, s = np.cos(w * tau), np.sin(w * tau)
    qx, qy, qz = vx + ax * d, vy + ay * d, vz + az * d
    new = dict(r_e=np.column_stack([c * px + s * py, -s * px + c * py, pz]),
               v_e=np.column_stack([c * qx + s * qy, -s * qx + c * qy, qz]),
               clock_bias_s=clock_bias_s + clock_drift_s_s * d, t_tx_gps_s=t_rx - tau, tau_s=tau,
               range_m=dist(c, s, px, py, pz))
    return new, ~(np.abs(d) <= CARRY_MAX_S)


def _carried(ts, t_rx, r_rx_e, evaluate, valid=None):
    """``ts`` (a ``TransmitStates``/``MultiStates``) carried to the reception times ``t_rx`` by
    :func:`carry_transmit_states`; the rows it cannot carry are evaluated again by ``evaluate(rows)``."""
    new, far = carry_transmit_states(ts.r_e, ts.v_e, ts.clock_bias_s, ts.clock_drift_s_s, ts.t_tx_gps_s, ts.tau_s,
                                     t_rx, r_rx_e)
    out = ts._replace(**new)
    far = np.flatnonzero(far if valid is None else far & valid)
    if far.size:
        again = evaluate(far)
        for k in new:
            getattr(out, k)[far] = getattr(again, k)
    return out


def _tight_inputs_multi(obs, nav, t0_gps_s, approx_r_e, *, elevation_mask_deg, max_sats, iono, tropo,
                        sigma_pr_zenith_m, sigma_prr_zenith_mps, use_cn0, t_range, systems, _prior=None,
                        _keep=None) -> TightInputs:
    """Multi-system :func:`tight_inputs_from_rinex` (same steps, per-row system and signal)."""
    from .._median import group_median
    from .broadcast import select_multi, transmit_states_multi
    from .corrections import klobuchar_coefficients, klobuchar_delay, saastamoinen_delay
    from .ephemeris import C_LIGHT
    from .geometry import elevation_azimuth
    from .measurements import L1_WAVELENGTH

    r0 = np.asarray(approx_r_e, float)
    t_tag = np.asarray(obs.t_gps_s, float)
    sys_all = np.asarray(getattr(obs, "system", np.full(len(obs.prn), "G")), dtype="<U1")
    code_all = obs.pseudorange_code() if hasattr(obs, "pseudorange_code") else np.full(len(obs.prn), "C1C")
    ok = np.isfinite(obs.C1) & np.isin(sys_all, list(systems)) & (code_all != "")
    if t_range is not None:
        ok &= (t_tag - t0_gps_s >= t_range[0]) & (t_tag - t0_gps_s <= t_range[1])
    idx = np.full(len(obs.prn), -1, np.int64)
    idx[ok] = select_multi(nav, sys_all[ok], obs.prn[ok], t_tag[ok], code_all[ok])
    ok &= idx >= 0
    rows = np.flatnonzero(ok)
    ep = obs.epoch[rows]
    sys_r, prn_r, code_r = sys_all[rows], obs.prn[rows], code_all[rows]
    n_ep = obs.epoch_t_gps_s.size
    clk = np.zeros(n_ep)
    lat, lon, h = earth.ecef_to_geodetic(r0)
    prior = _prior if _prior is not None and np.array_equal(_prior["rows"], rows) else None
    for it in range(2):
        t_rx = t_tag[rows] - clk[ep] / C_LIGHT
        evaluate = (lambda far: transmit_states_multi(  # noqa: E731
            nav, t_rx[far], r0, system=sys_r[far], prn=prn_r[far], codes=code_r[far]))
        if it == 0:
            ts = (transmit_states_multi(nav, t_rx, r0, system=sys_r, prn=prn_r, codes=code_r) if prior is None
                  else _carried(prior["tag"], t_rx, r0, evaluate, valid=prior["tag"].valid))
            ts_tag = ts
        else:  # the same satellites a receiver clock offset earlier: carried, not evaluated again
            src = ts if prior is None else prior["final"]
            ts = _carried(src, t_rx, r0, evaluate, valid=src.valid)
        raw = obs.C1[rows] - (ts.range_m - C_LIGHT * ts.clock_bias_s)
        # receiver clock of the epoch (only sets the true reception time; inter-system
        # offsets of tens of ns do not matter for it)
        fin = np.isfinite(raw)
        med, present = group_median(raw[fin], ep[fin], n_ep)
        clk[ep] = 0.0
        clk[present] = med[present]
    good = ts.valid & np.isfinite(ts.range_m)
    el, az = elevation_azimuth(r0, np.where(good[:, None], ts.r_e, r0 + 1.0))
    iono_m = np.zeros(rows.size)
    tropo_m = np.zeros(rows.size)
    if iono:
        alpha, beta, _ = klobuchar_coefficients(nav)
        scale = (ts.wavelength_m / L1_WAVELENGTH) ** 2  # Klobuchar is the L1 delay; 1/f^2 to the signal
        iono_m = scale * klobuchar_delay(t_rx, np.full(rows.size, lat), np.full(rows.size, lon), el, az,
                                         alpha, beta)
    if tropo:
        tropo_m = saastamoinen_delay(np.full(rows.size, lat), np.full(rows.size, h), el)
    prr = -ts.wavelength_m * np.asarray(obs.D1, float)[rows]
    cn0 = np.asarray(obs.S1, float)[rows] if use_cn0 else None
    spr = pseudorange_sigma(el, sigma_pr_zenith_m, cn0)
    sprr = pseudorange_sigma(el, sigma_prr_zenith_mps, cn0)
    sats = np.column_stack([obs.C1[rows], prr, ts.r_e, ts.v_e, C_LIGHT * ts.clock_bias_s - iono_m - tropo_m,
                            C_LIGHT * ts.clock_drift_s_s, spr, sprr])
    t_ep = t_tag[rows] - clk[ep] / C_LIGHT - t0_gps_s
    inp = TightInputs.from_rows(t_ep, prn_r, sats, np.degrees(el),
                                info=dict(source=str(getattr(obs, "path", "rinex")), approx_r_e=r0,
                                          rx_clock_tag_m=clk, iono_m=iono_m, tropo_m=tropo_m, systems=systems),
                                system=sys_r)
    keep = (np.degrees(el) >= elevation_mask_deg) & good
    inp = inp.select(keep[np.argsort(t_ep, kind="stable")])
    if _keep is not None:
        _keep.update(rows=rows, tag=ts_tag, final=ts)
    return limit_sats(inp, max_sats)
