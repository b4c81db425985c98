"""Carrier-phase simulation for RTK: a moving rover and a static base, written as RINEX 3.

The rover antenna follows the scenario's analytic trajectory (the same
:class:`~insnav.sim.trajectory.Trajectory` that drives the IMU, the loose
fixes and ``gnss_raw``), the base antenna is fixed.  Satellites are the
broadcast ephemerides of the navigation file written beside the
observations (:func:`rtk_navdata`: the nominal GPS set and the Walker
Galileo set of the ``gnss_raw`` simulation, made RINEX-exact by
:func:`insnav.gnss.rinex_write.rinex_representable`), so every RINEX reader
computes the satellite orbits and clocks the simulation used.

Observation model (receiver ``r`` = rover or base, satellite ``s``, signal
``k`` of frequency ``f_k``, wavelength ``lambda_k = c / f_k``; Teunissen &
Montenbruck (eds.), *Springer Handbook of GNSS*, 2017, eqs. (19.1)-(19.2))::

    t_tag  = epoch time tag (receiver clock), every 1 / rate_hz
    t      = t_tag - b_r(t_tag) / c                 true reception time
    rho    = |R_z(w tau) r_sat(t - tau) - r_r(t)|   light time and Sagnac (insnav.gnss.ephemeris)
    P_k    = rho + b_r - c dt_s + q_k I + T + m_P + e_P
    L_k    = (rho + b_r - c dt_s - q_k I + T + m_L + e_L) / lambda_k + N_k       [cycles]
    D_k    = -(u . (v_sat - v_r) + d_r - c ddt_s + dT/dt - q_k dI/dt) / lambda_k + e_D    [Hz]
    q_k    = (f_1 / f_k)^2,  f_1 = 1575.42 MHz

* ``b_r``, ``d_r``: receiver clock bias [m] and drift [m/s], the two-state
  random walk of :func:`insnav.sim.gnss_raw.simulate_clock`, one per receiver.
  Time tags are whole epochs of the receiver clock, so the two receivers
  sample at true times that differ by ``(b_rover - b_base) / c``.
* ``I`` [m, on L1]: the Klobuchar delay (the broadcast coefficients of the
  navigation file) along the base's line of sight to the satellite, the same
  for both receivers (the model's own horizontal and elevation gradients,
  several ppm at low latitudes, would otherwise add a between-receiver
  ionosphere nobody configured), plus at the rover a residual
  ``iono_ppm 1e-6 d M_I(el) x_I`` with ``d`` the rover-base distance,
  ``M_I`` the single-layer mapping function (350 km shell) and ``x_I`` a
  unit first-order Gauss-Markov process per satellite (``iono_tau_s``): the
  between-receiver ionosphere grows with the baseline (1-2 ppm is a quiet
  mid-latitude ionosphere; Misra & Enge 2011, sec. 5.4).
* ``T`` [m]: Saastamoinen with the standard atmosphere at each receiver
  (:func:`insnav.gnss.corrections.saastamoinen_delay`), plus at the rover
  ``tropo_ppm 1e-6 d / sin(el) x_T``, ``x_T`` a unit Gauss-Markov process per
  satellite (``tropo_tau_s``).
* ``m_P``, ``m_L``: code and phase multipath, unit first-order Gauss-Markov
  processes per receiver, satellite and signal with correlation time
  ``multipath_tau_s``, scaled by ``sigma w(el)``; the base's by ``base_multipath_scale``.
* ``dT/dt``, ``dI/dt``: central differences over the epoch grid (the
  Doppler follows the phase rate; multipath rates are left out of it).
* ``e_P``, ``e_L``, ``e_D``: white noise ``sigma w(el)``,
  ``w(el) = sqrt((1 + 1 / sin^2 el) / 2)`` (1 at the zenith, 4.1 at 10 deg;
  the ``a + b / sin el`` form of RTKLIB's weighting with ``a = b``).
* ``N_k``: an integer ambiguity per receiver, satellite, signal and arc.  An
  arc starts when the satellite rises above the receiver's mask (a
  re-acquisition after a gap gets a new ambiguity and the loss-of-lock bit
  ``LLI & 1``).  Inside an arc each signal slips with probability
  ``1 - exp(-slip_rate_per_h dt / 3600)`` per epoch by a non-zero integer
  uniform in ``[-slip_max_cycles, slip_max_cycles]``; a slip sets the LLI bit
  with probability ``slip_lli_prob`` (1: every slip flagged, as a receiver
  does when its tracking loop loses lock; less: slips only a detector can find).

Visibility: rover above ``elevation_mask_deg`` and, in an urban canyon, above
:func:`insnav.sim.gnss_raw.urban_canyon_mask` about the street axis (the
car's heading unless ``street_azimuth_deg``); base above
``base_elevation_mask_deg``.

The between-receiver single difference removes ``c dt_s`` (up to its drift
over ``|tau_rover - tau_base|`` < 0.1 ms, below 1e-9 m), the double
difference also ``b_r``; what remains of ``lambda_k L_k`` is the DD of ``rho``
plus ``lambda_k N_DD`` plus the DD of ``-q_k I + T + m_L + e_L``, which the
truth tables of :class:`RtkReceiverObs` hold term by term.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import earth
from ..gnss.ephemeris import C_LIGHT

__all__ = ["RtkReceiverObs", "RtkSimulation", "rtk_navdata", "simulate_rtk_obs", "SIGNALS", "signal_frequency_hz",
           "elevation_weight", "rtk_noise_options"]

from .scenario import RTK_SIGNALS as SIGNALS  # RINEX 3 signals the simulator can write, per system
F_L1_HZ = 1575.42e6
#: ionospheric single-layer height [m] of the mapping function M_I
IONO_SHELL_M = 350e3


def signal_frequency_hz(system: str, code: str) -> float:
    """Carrier frequency [Hz] of a RINEX signal ``code`` (``'1C'``, ``'C1C'``...) of ``system``."""
    from ..gnss.galbds import FREQ_HZ

    band = code[1] if len(code) == 3 else code[0]
    return FREQ_HZ[(system, band)]


def elevation_weight(el):
    """``w(el) = sqrt((1 + 1/sin^2 el) / 2)``: noise and multipath scale [-] (1 at the zenith)."""
    s = np.maximum(np.sin(el), 0.05)
    return np.sqrt(0.5 * (1.0 + 1.0 / s ** 2))


def rtk_noise_options(cfg: dict) -> dict:
    """``[rtk]`` noise options that describe the simulated receivers (for RTK and RTK/INS runs on them).

    The simulator's code and phase errors of each receiver, satellite and signal are white noise
    ``sigma w(el)`` plus a unit first-order Gauss-Markov multipath ``sigma_mp w(el) x`` of correlation
    time ``tau`` (the base's multipath scaled by ``s``), ``w(el)^2 = (1 + 1/sin^2 el) / 2``
    (:func:`elevation_weight`).  The engines' zero-difference phase variance is
    ``a^2 + b^2 / sin^2 el`` (``sigma_phase_a_m``, ``sigma_phase_b_m``), so

    * ``a = b = sigma_L / sqrt(2)`` reproduces the white phase noise exactly;
    * code: ``code_phase_ratio = sqrt(sigma_P^2 + sigma_mp,P^2) / sigma_L`` (noise and multipath),
      correlation time ``code_correlation_time_s = tau`` (the white part counted as correlated
      too: a conservative bound);
    * phase multipath: not white noise on the phase rows but a slow walk of each single-differenced
      ambiguity state, with the process noise of a first-order Gauss-Markov process of variance
      ``(1 + s^2) sigma_mp,L^2`` (zenith) and correlation time ``tau``, ``q = 2 (1 + s^2) sigma_mp,L^2
      / (tau lambda_1^2)`` [cycles^2/s] (``amb_psd_cycles2ps``; A. Gelb (ed.), *Applied Optimal
      Estimation*, 1974, sec. 4.3, the PSD ``2 sigma^2 / tau`` of a first-order Gauss-Markov process).

    Parameters
    ----------
    cfg : dict
        A scenario's ``gnss_rtk`` block in SI units (:attr:`insnav.sim.scenario.Scenario.gnss_rtk`:
        ``sigma_code``, ``multipath_code``, ``sigma_phase``, ``multipath_phase`` [m],
        ``multipath_tau`` [s], ``base_multipath_scale`` [-]).

    Returns
    -------
    dict
        ``sigma_phase_a_m``, ``sigma_phase_b_m`` [m], ``code_phase_ratio`` [-],
        ``code_correlation_time_s`` [s] (0 without code multipath), ``amb_psd_cycles2ps`` [cycles^2/s]
        (an :class:`insnav.gnss.rtk.RtkOptions` dictionary).
    """
    sig_l = float(cfg["sigma_phase"])
    if not sig_l > 0.0:
        raise ValueError("rtk_noise_options: gnss_rtk sigma_phase_m must be > 0")
    lam1 = C_LIGHT / F_L1_HZ
    tau = float(cfg["multipath_tau"])
    mp_l = float(cfg["multipath_phase"])
    q = 2.0 * (1.0 + cfg["base_multipath_scale"] ** 2) * mp_l ** 2 / (tau * lam1 ** 2) if tau > 0.0 else 0.0
    return dict(sigma_phase_a_m=sig_l / math.sqrt(2.0), sigma_phase_b_m=sig_l / math.sqrt(2.0),
                code_phase_ratio=math.hypot(cfg["sigma_code"], cfg["multipath_code"]) / sig_l,
                code_correlation_time_s=tau if cfg["multipath_code"] > 0.0 else 0.0,
                amb_psd_cycles2ps=max(q, 1e-8))


def iono_mapping(el):
    """Single-layer ionospheric mapping function ``1 / sqrt(1 - (R cos el / (R + H))^2)``, H = 350 km."""
    re = 6371e3
    x = re * np.cos(el) / (re + IONO_SHELL_M)
    return 1.0 / np.sqrt(1.0 - x ** 2)


@dataclass
class RtkReceiverObs:
    """Simulated observations of one receiver, one row per (epoch, satellite) in view.

    Signals: column ``k`` of the ``(m, K)`` arrays is signal ``signals[system][k]``
    of the row's system (NaN beyond a system's list).  Everything in SI.
    """

    name: str  #: "rover" or "base"
    t_tag_gps_s: np.ndarray  #: (n,) epoch time tags [GPS s]
    t_rx_gps_s: np.ndarray  #: (n,) true reception times [GPS s]
    r_e: np.ndarray  #: (n, 3) antenna ECEF at the true reception time [m]
    v_e: np.ndarray  #: (n, 3) antenna ECEF velocity [m/s]
    clock_bias_m: np.ndarray  #: (n,) receiver clock bias b [m]
    clock_drift_mps: np.ndarray  #: (n,) receiver clock drift d [m/s]
    epoch: np.ndarray  #: (m,) row -> epoch index
    system: np.ndarray  #: (m,) one-letter system
    prn: np.ndarray  #: (m,) int
    code_m: np.ndarray  #: (m, K) pseudorange [m]
    phase_cyc: np.ndarray  #: (m, K) carrier phase [cycles]
    doppler_hz: np.ndarray  #: (m, K) Doppler [Hz]
    cn0_dbhz: np.ndarray  #: (m, K) C/N0 [dB-Hz]
    lli: np.ndarray  #: (m, K) loss-of-lock indicator (bit 0)
    wavelength_m: np.ndarray  #: (m, K) [m]
    # truth, term by term
    range_m: np.ndarray  #: (m,) geometric range rho [m]
    sat_clock_m: np.ndarray  #: (m,) c dt_s [m]
    el: np.ndarray  #: (m,) elevation [rad]
    az: np.ndarray  #: (m,) azimuth [rad]
    iono_l1_m: np.ndarray  #: (m,) I on L1 [m] (Klobuchar + residual)
    tropo_m: np.ndarray  #: (m,) T [m]
    mp_code_m: np.ndarray  #: (m, K) code multipath [m]
    mp_phase_m: np.ndarray  #: (m, K) phase multipath [m]
    noise_code_m: np.ndarray  #: (m, K) white code noise [m]
    noise_phase_m: np.ndarray  #: (m, K) white phase noise [m]
    ambiguity_cyc: np.ndarray  #: (m, K) integer ambiguity N [cycles]
    slip: np.ndarray  #: (m, K) bool, a cycle slip happened at this row
    iono_freq_factor: np.ndarray  #: (m, K) q_k = (f_1 / f_k)^2

    def __len__(self) -> int:
        return int(self.prn.size)

    @property
    def sat_id(self) -> np.ndarray:
        from ..gnss.systems import sat_id

        return sat_id(self.system, self.prn)


@dataclass
class RtkSimulation:
    """Rover and base observations, the navigation data behind them and the signals simulated."""

    rover: RtkReceiverObs
    base: RtkReceiverObs
    nav: object  #: insnav.gnss.rinex.NavData (in memory; what nav.rnx holds)
    signals: dict  #: system -> tuple of signal codes ('1C', '2W', ...)
    base_r_e: np.ndarray  #: (3,) base antenna ECEF [m]
    rate_hz: float
    config: dict = field(repr=False, default_factory=dict)

    FILES = ("rover.obs", "base.obs", "nav.rnx", "rtk_truth.csv")

    def obs_types(self) -> dict:
        """System -> RINEX observation codes in file order (C, L, D, S per signal)."""
        return {s: [f"{t}{c}" for c in sig for t in "CLDS"] for s, sig in self.signals.items()}

    def write(self, directory, *, overwrite_ok: bool = True) -> dict:
        """Write ``rover.obs``, ``base.obs``, ``nav.rnx`` (RINEX 3.04) and ``rtk_truth.csv`` into ``directory``.

        ``rtk_truth.csv``: per rover epoch the time tag and the true rover
        antenna ECEF position at the reception time (``t_gps_s, x_e_m,
        y_e_m, z_e_m, lat_deg, lon_deg, h_m, n_sats_rover, n_sats_common``).

        Parameters
        ----------
        directory : path
            Made (with its parents) when missing.
        overwrite_ok : bool
            False: refuse (FileExistsError naming it) when one of the four files exists; nothing is
            written then.

        Returns
        -------
        dict
            File kind -> Path.
        """
        from pathlib import Path

        from ..gnss.glonass import gps_utc_leap_seconds
        from ..gnss.rinex_write import write_rinex_nav, write_rinex_obs

        d = Path(directory)
        if d.exists() and not d.is_dir():
            raise NotADirectoryError(f"{d}: not a directory (simulate_rtk writes four files into a directory)")
        if not overwrite_ok:
            for name in ("rover.obs", "base.obs", "nav.rnx", "rtk_truth.csv"):
                if (d / name).exists():
                    raise FileExistsError(f"{d / name}: exists (overwrite_ok=False)")
        d.mkdir(parents=True, exist_ok=True)
        out = {}
        types = self.obs_types()
        for rx, name in ((self.rover, "rover"), (self.base, "base")):
            values, lli = {}, {}
            for s in types:
                rows = rx.system == s
                ks = len(self.signals[s])
                v = np.full((int(rows.sum()), 4 * ks), np.nan)
                li = np.zeros(v.shape, int)
                v[:, 0::4] = rx.code_m[rows, :ks]
                v[:, 1::4] = rx.phase_cyc[rows, :ks]
                v[:, 2::4] = rx.doppler_hz[rows, :ks]
                v[:, 3::4] = rx.cn0_dbhz[rows, :ks]
                li[:, 1::4] = rx.lli[rows, :ks]
                values[s], lli[s] = v, li
            approx = self.base_r_e if name == "base" else rx.r_e[0]
            out[name] = write_rinex_obs(d / f"{name}.obs", t_gps_s=rx.t_tag_gps_s, epoch=rx.epoch, sat_id=rx.sat_id,
                                        obs_types=types, values=values, lli=lli, marker_name=name.upper(),
                                        approx_r_e=approx, interval_s=1.0 / self.rate_hz,
                                        comment=f"insnav simulation: {name} (truth in rtk_truth.csv)")
        nav = self.nav
        t_first = float(np.concatenate([self.rover.t_tag_gps_s, self.base.t_tag_gps_s, [np.nan]])[0])
        out["nav"] = write_rinex_nav(d / "nav.rnx", nav.eph if len(nav.eph) else None,
                                     nav.eph_e if len(nav.eph_e) else None, ion_alpha=nav.ion_alpha,
                                     ion_beta=nav.ion_beta, leap_seconds=int(gps_utc_leap_seconds(t_first)),
                                     comment="insnav simulation: nominal constellations")
        out["truth"] = self.write_truth(d / "rtk_truth.csv")
        return out

    def common_counts(self):
        """(n_rover_sats, n_common_sats) per rover epoch."""
        r, b = self.rover, self.base
        n_r = np.bincount(r.epoch, minlength=r.t_tag_gps_s.size)
        key_r = r.epoch * 100000 + np.array([ord(s) for s in r.system]) * 100 + r.prn
        key_b = b.epoch * 100000 + np.array([ord(s) for s in b.system]) * 100 + b.prn
        common = np.isin(key_r, key_b)
        n_c = np.bincount(r.epoch[common], minlength=r.t_tag_gps_s.size)
        return n_r, n_c

    def write_truth(self, path):
        from ..data.dataset import write_csv

        r = self.rover
        lat, lon, h = earth.ecef_to_geodetic(r.r_e)
        n_r, n_c = self.common_counts()
        cols = ("t_gps_s", "x_e_m", "y_e_m", "z_e_m", "lat_deg", "lon_deg", "h_m", "n_sats_rover", "n_sats_common")
        arr = np.column_stack([r.t_tag_gps_s, r.r_e, np.degrees(lat), np.degrees(lon), h, n_r, n_c])
        write_csv(path, cols, arr, "%.17g")
        return path


# --------------------------------------------------------------------------- navigation data
#: spacing of the navigation records of one satellite [s] (every record is valid +-2 h)
NAV_RECORD_SPACING_S = 7200.0


def rtk_navdata(t0_gps_s: float, systems=("G",), duration_s: float = 0.0):
    """In-memory broadcast navigation data of the simulated constellations, exactly as ``nav.rnx`` holds it.

    GPS: :meth:`insnav.gnss.constellation.Constellation.nominal` re-referenced
    to ``t0_gps_s`` with ``T_GD = 0`` (the simulation has no satellite group
    delay); Galileo: the Walker set of :func:`insnav.gnss.walker.walker_constellation`,
    re-expressed for the Galileo constants (:func:`insnav.gnss.rinex_write.elements_for_system`),
    data source 513 (I/NAV E1-B, clock E1/E5b), BGDs 0.  One record per
    satellite every :data:`NAV_RECORD_SPACING_S` from ``t0_gps_s`` to
    ``t0_gps_s + duration_s`` (:func:`insnav.gnss.rinex_write.rereference`:
    one continuous orbit, so any scenario length stays inside the 4 h fit
    interval of some record), each passed through
    :func:`insnav.gnss.rinex_write.rinex_representable`.  The satellite
    positions equal those of the ``gnss_raw`` simulation's constellations to
    the 12-digit rounding (< 1 mm).
    """
    from ..gnss.constellation import Constellation
    from ..gnss.ephemeris import GM_GPS, OMEGA_E_DOT, Ephemerides
    from ..gnss.galbds import GM_GAL, OMEGA_E_GAL, KeplerEphemerides
    from ..gnss.rinex import NavData
    from ..gnss.rinex_write import elements_for_system, rereference, rinex_representable

    bad = [s for s in systems if s not in SIGNALS]
    if bad:
        raise ValueError(f"carrier-phase simulation: system(s) {', '.join(bad)} not supported "
                         f"(supported: {', '.join(SIGNALS)})")
    n_rec = int(np.floor(max(duration_s, 0.0) / NAV_RECORD_SPACING_S)) + 1
    nominal = Constellation.nominal(t0_gps_s=t0_gps_s)

    def records(cols, omega_e, gm):
        parts = []
        for k in range(n_rec):
            c = rereference(cols, cols["toe"] + k * NAV_RECORD_SPACING_S, None, omega_e, gm) if k else cols
            c = rinex_representable(c, omega_e, gm)
            c["iode"] = np.mod(np.asarray(c["iode"], float) + k, 256.0)
            parts.append(c)
        return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}

    eph_g = None
    if "G" in systems:
        cols = nominal.eph.to_columns()
        cols["tgd"] = np.zeros_like(cols["tgd"])
        cols["fit_s"] = np.full(cols["prn"].shape, 4 * 3600.0)
        cols = records(cols, OMEGA_E_DOT, GM_GPS)
        cols["iodc"] = cols["iode"].copy()
        eph_g = Ephemerides.from_columns(cols)
    eph_e = None
    if "E" in systems:
        from ..gnss.walker import walker_elements

        cols = walker_elements("E", nominal.eph.to_columns(), float(t0_gps_s))
        cols = elements_for_system(cols, GM_GAL, OMEGA_E_GAL)
        n = cols["prn"].size
        cols.update(tgd=np.zeros(n), tgd2=np.zeros(n), data_source=np.full(n, 513.0), iodc=np.zeros(n),
                    iode=np.arange(n, dtype=float) % 128, fit_s=np.full(n, 4 * 3600.0))
        eph_e = KeplerEphemerides.from_columns(records(cols, OMEGA_E_GAL, GM_GAL))
    if eph_g is None:
        eph_g = Ephemerides.from_columns({k: np.zeros(0) for k in nominal.eph.to_columns()})
    return NavData("<simulated>", 3.04, eph_g, nominal.ion_alpha, nominal.ion_beta, 0, None, eph_e, None, 18.0)


# --------------------------------------------------------------------------- processes
def gauss_markov(n_epochs: int, shape, dt: float, tau: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance stationary first-order Gauss-Markov processes, (n_epochs, *shape).

    ``x_k = a x_{k-1} + sqrt(1 - a^2) w_k``, ``a = exp(-dt / tau)`` (exact
    discretisation; Brown & Hwang 2012, sec. 2.9); ``x_0 ~ N(0, 1)``;
    ``tau = 0`` gives white noise.
    """
    w = rng.standard_normal((n_epochs,) + tuple(shape))
    if tau <= 0:
        return w
    a = np.exp(-dt / tau)
    b = np.sqrt(1.0 - a * a)
    x = np.empty_like(w)
    x[0] = w[0]
    for k in range(1, n_epochs):
        x[k] = a * x[k - 1] + b * w[k]
    return x


def _ambiguities(vis: np.ndarray, p_slip: float, slip_max: int, lli_prob: float, n0_max: int,
                 rng: np.random.Generator):
    """Ambiguity, slip and LLI grids (n_epochs, n_sats, K) from the visibility grid (n_epochs, n_sats).

    New arc (visible after not visible): a fresh ambiguity uniform in
    ``[-n0_max, n0_max]``; LLI set when the satellite had been seen before.
    Inside an arc: slips with probability ``p_slip`` per epoch and signal.
    """
    ne, ns, kk = vis.shape
    prev = np.zeros_like(vis)
    prev[1:] = vis[:-1]
    start = vis & ~prev
    seen_before = np.cumsum(vis, axis=0) - vis > 0
    reacq = start & seen_before
    n0 = rng.integers(-n0_max, n0_max + 1, size=vis.shape)
    slip = vis & ~start & (rng.random(vis.shape) < p_slip)
    mag = rng.integers(1, slip_max + 1, size=vis.shape) * np.where(rng.random(vis.shape) < 0.5, -1, 1)
    flagged = slip & (rng.random(vis.shape) < lli_prob)
    # N = value at the arc start plus the slips since; built as a cumulative sum of increments
    inc = np.where(slip, mag, 0).astype(np.int64)
    amb = np.zeros(vis.shape, np.int64)
    running = np.zeros((ns, kk), np.int64)
    for k in range(ne):
        running = np.where(start[k], n0[k], running + inc[k])
        amb[k] = running
    lli = (flagged | reacq).astype(np.int64)
    return amb, slip, lli


# --------------------------------------------------------------------------- simulation
def _receiver(name, t_tag, clock, pos_fn, nav, systems, signals, cfg, rng, *, mask_fn, iono_origin_e,
              rover_extra=None):
    """Observations of one receiver (see the module docstring)."""
    from ..gnss.corrections import klobuchar_delay, saastamoinen_delay
    from ..gnss.geometry import elevation_azimuth

    b, d = clock
    t_rx = t_tag - b / C_LIGHT
    r_e, v_e = pos_fn(t_rx)
    ne = t_tag.size
    sats = [(s, int(p)) for s in systems for p in np.unique((nav.eph if s == "G" else nav.eph_e).prn)]
    ns = len(sats)
    kk = max(len(signals[s]) for s in systems)
    sys_s = np.array([s for s, _ in sats], dtype="<U1")
    prn_s = np.array([p for _, p in sats], np.int64)
    ep = np.repeat(np.arange(ne), ns)
    sy = np.tile(sys_s, ne)
    pr = np.tile(prn_s, ne)
    ts = nav.transmit_states(t_rx[ep], r_e[ep], system=sy, prn=pr, codes={"G": "C1C", "E": "C1C"})
    if not np.all(ts.valid):
        raise ValueError(f"carrier-phase simulation ({name}): no broadcast ephemeris for some satellites")
    el, az = elevation_azimuth(r_e[ep], ts.r_e)
    vis_flat = el >= mask_fn(el, az, ep)
    vis = vis_flat.reshape(ne, ns)
    dt = float(np.median(np.diff(t_tag))) if ne > 1 else 1.0

    # signal table per satellite column
    lam = np.full((ns, kk), np.nan)
    q = np.full((ns, kk), np.nan)
    have = np.zeros((ns, kk), bool)
    for j, s in enumerate(sys_s):
        for k, c in enumerate(signals[s]):
            f = signal_frequency_hz(s, c)
            lam[j, k] = C_LIGHT / f
            q[j, k] = (F_L1_HZ / f) ** 2
            have[j, k] = True
    vis3 = vis[:, :, None] & have[None, :, :]

    p_slip = 1.0 - np.exp(-cfg["slip_rate_per_h"] * dt / 3600.0) if rover_extra is not None or cfg["base_slips"] \
        else 0.0
    amb, slip, lli = _ambiguities(vis3, p_slip, cfg["slip_max_cycles"], cfg["slip_lli_prob"], cfg["ambiguity_max"],
                                  rng)
    mp_scale = 1.0 if rover_extra is not None else cfg["base_multipath_scale"]
    x_mp_c = gauss_markov(ne, (ns, kk), dt, cfg["multipath_tau"], rng)
    x_mp_l = gauss_markov(ne, (ns, kk), dt, cfg["multipath_tau"], rng)
    e_c = rng.standard_normal((ne, ns, kk))
    e_l = rng.standard_normal((ne, ns, kk))
    e_d = rng.standard_normal((ne, ns, kk))
    x_i = gauss_markov(ne, (ns,), dt, cfg["iono_tau"], rng)
    x_t = gauss_markov(ne, (ns,), dt, cfg["tropo_tau"], rng)

    rows = np.flatnonzero(vis_flat)
    e_row = ep[rows]
    j_row = rows % ns
    el_r, az_r = el[rows], az[rows]
    # atmosphere on the whole (epoch, satellite) grid, so that its rate enters the Doppler
    lat, lon, h = earth.ecef_to_geodetic(r_e)
    iono_g = np.zeros(ep.size)
    if cfg["klobuchar"]:
        # the ionosphere over the area: Klobuchar along the base's line of sight for both receivers, so
        # the between-receiver ionosphere is the residual term alone (Klobuchar's own horizontal and
        # elevation gradients reach several ppm at low latitudes and would not be the configured ones)
        origin = np.asarray(iono_origin_e, float)
        lat_i, lon_i, _ = earth.ecef_to_geodetic(origin[None, :])
        el_i, az_i = elevation_azimuth(origin, ts.r_e)
        iono_g = klobuchar_delay(t_rx[ep], lat_i[0], lon_i[0], np.maximum(el_i, 0.0), az_i, nav.ion_alpha,
                                 nav.ion_beta)
    el_c = np.maximum(el, np.radians(1.0))  # below the horizon: any finite value (never observed)
    tropo_g = saastamoinen_delay(lat[ep], h[ep], el_c) if cfg["saastamoinen"] else np.zeros(ep.size)
    if rover_extra is not None:
        dist = np.linalg.norm(r_e - rover_extra["base_r_e"], axis=1)[ep]
        iono_g = iono_g + cfg["iono_ppm"] * 1e-6 * dist * iono_mapping(el_c) * x_i.ravel()
        tropo_g = tropo_g + cfg["tropo_ppm"] * 1e-6 * dist / np.maximum(np.sin(el_c), 0.05) * x_t.ravel()
    iono, tropo = iono_g[rows], tropo_g[rows]
    # d/dt of tropo and iono (central differences on the epoch grid) for the Doppler
    dt_grid = np.gradient(t_rx) if ne > 1 else np.ones(1)
    tropo_rate = (np.gradient(tropo_g.reshape(ne, ns), axis=0) / dt_grid[:, None]).ravel()[rows] if ne > 1 \
        else np.zeros(rows.size)
    iono_rate = (np.gradient(iono_g.reshape(ne, ns), axis=0) / dt_grid[:, None]).ravel()[rows] if ne > 1 \
        else np.zeros(rows.size)
    w = elevation_weight(el_r)[:, None]
    mp_c = mp_scale * cfg["multipath_code"] * w * x_mp_c[e_row, j_row]
    mp_l = mp_scale * cfg["multipath_phase"] * w * x_mp_l[e_row, j_row]
    n_c = cfg["sigma_code"] * w * e_c[e_row, j_row]
    n_l = cfg["sigma_phase"] * w * e_l[e_row, j_row]
    lam_r, q_r, have_r = lam[j_row], q[j_row], have[j_row]
    rho = ts.range_m[rows]
    clk_s = C_LIGHT * ts.clock_bias_s[rows]
    common = (rho + b[e_row] - clk_s + tropo)[:, None]
    code = common + q_r * iono[:, None] + mp_c + n_c
    amb_r = amb[e_row, j_row]
    phase = (common - q_r * iono[:, None] + mp_l + n_l) / lam_r + amb_r
    u = (ts.r_e[rows] - r_e[e_row]) / rho[:, None]
    rr = np.einsum("ij,ij->i", u, ts.v_e[rows] - v_e[e_row]) + d[e_row] - C_LIGHT * ts.clock_drift_s_s[rows]
    # the carrier's rate: geometry, clocks and the atmosphere (dispersive part with the phase's sign)
    dop = -(rr[:, None] + tropo_rate[:, None] - q_r * iono_rate[:, None]) / lam_r \
        + cfg["sigma_doppler"] * e_d[e_row, j_row]
    cn0 = (cfg["cn0_zenith"] - cfg["cn0_span"] * (1.0 - np.sin(el_r)))[:, None] + np.zeros((1, kk))
    nan = ~have_r
    for a in (code, phase, dop, cn0, mp_c, mp_l, n_c, n_l):
        a[nan] = np.nan
    amb_r = np.where(have_r, amb_r, 0)
    return RtkReceiverObs(
        name=name, t_tag_gps_s=t_tag, t_rx_gps_s=t_rx, r_e=r_e, v_e=v_e, clock_bias_m=b, clock_drift_mps=d,
        epoch=e_row, system=sys_s[j_row], prn=prn_s[j_row], code_m=code, phase_cyc=phase, doppler_hz=dop,
        cn0_dbhz=cn0, lli=np.where(have_r, lli[e_row, j_row], 0), wavelength_m=lam_r, range_m=rho, sat_clock_m=clk_s,
        el=el_r, az=az_r, iono_l1_m=iono, tropo_m=tropo, mp_code_m=mp_c, mp_phase_m=mp_l, noise_code_m=n_c,
        noise_phase_m=n_l, ambiguity_cyc=amb_r, slip=np.where(have_r, slip[e_row, j_row], False), iono_freq_factor=q_r)


def base_position(traj, cfg, lever_arm_b):
    """Base antenna ECEF [m]: ``[gnss_rtk.base]`` geodetic position, or the NED offset from the rover's
    antenna at the scenario start."""
    from .gnss_loose import antenna_state

    base = cfg["base"]
    if base.get("lat") is not None:
        return earth.geodetic_to_ecef(np.array([base["lat"]]), np.array([base["lon"]]), np.array([base["h"]]))[0]
    lat, lon, _h, _v, r_ant_e, _ve = antenna_state(traj, np.array([traj.sc.t0]), lever_arm_b)
    return r_ant_e[0] + earth.ned_to_ecef_vector(lat, lon, np.asarray(base["offset_ned"], float)[None, :])[0]


def simulate_rtk_obs(traj, cfg: dict, lever_arm_b, gps_time_offset_s: float, rng: np.random.Generator,
                     street_heading=None) -> RtkSimulation:
    """Simulate rover and base carrier-phase observations for the ``[gnss_rtk]`` configuration ``cfg`` (SI).

    Parameters
    ----------
    traj : Trajectory
        The scenario's analytic truth (rover antenna = IMU centre + lever arm).
    cfg : dict
        Parsed ``[gnss_rtk]`` table (:mod:`insnav.sim.scenario`).
    lever_arm_b : (3,) antenna lever arm, body FRD [m].
    gps_time_offset_s : float
        GPS time of scenario time 0 [s]; ``t0 + offset`` must be a whole second
        (RINEX navigation epochs are).
    rng : numpy.random.Generator
        The simulation's ``rtk`` stream.

    Returns
    -------
    RtkSimulation
    """
    from .gnss_loose import antenna_state, gnss_epochs
    from .gnss_raw import simulate_clock, urban_canyon_mask

    sc = traj.sc
    systems = tuple(cfg["systems"])
    signals = {s: tuple(cfg["signals"].get(s, ("1C",))) for s in systems}
    t0_gps = sc.t0 + gps_time_offset_s
    nav = rtk_navdata(t0_gps, systems, sc.duration)
    rate = cfg["rate"]
    t_sim = gnss_epochs(sc.t0, sc.t_end, sc.t0 + 1.0 / rate, rate)
    # the true reception time t_tag - b / c must stay inside the trajectory
    # independent child streams: the rover's numbers do not depend on the base's settings
    rng_clock_r, rng_clock_b, rng_rover, rng_base = rng.spawn(4)
    b_r, d_r = simulate_clock(t_sim, sc.t0, cfg["rover_clock_bias0"], cfg["rover_clock_drift0"], cfg["clock_bias_rw"],
                              cfg["clock_drift_rw"], rng_clock_r)
    b_b, d_b = simulate_clock(t_sim, sc.t0, cfg["base_clock_bias0"], cfg["base_clock_drift0"], cfg["clock_bias_rw"],
                              cfg["clock_drift_rw"], rng_clock_b)
    ok = (t_sim - b_r / C_LIGHT <= sc.t_end) & (t_sim - b_r / C_LIGHT >= sc.t0)
    t_sim, b_r, d_r, b_b, d_b = t_sim[ok], b_r[ok], d_r[ok], b_b[ok], d_b[ok]
    t_tag = t_sim + gps_time_offset_s
    base_r_e = base_position(traj, cfg, lever_arm_b)

    def rover_pos(t_rx_gps):
        _la, _lo, _h, _vn, r, v = antenna_state(traj, t_rx_gps - gps_time_offset_s, lever_arm_b)
        return r, v

    def base_pos(t_rx_gps):
        n = t_rx_gps.size
        return np.tile(base_r_e, (n, 1)), np.zeros((n, 3))

    canyon = cfg.get("urban_canyon")
    heading = None
    if canyon and canyon["street_azimuth"] is None:
        heading = traj.state(t_sim)["euler"][:, 2]

    def rover_mask(el, az, ep):
        m = np.full(el.shape, cfg["elevation_mask"])
        if canyon:
            street = heading[ep] if heading is not None else np.full(el.shape, canyon["street_azimuth"])
            m = np.maximum(m, urban_canyon_mask(az - street, canyon["mask_across"], canyon["mask_along"]))
        return m

    def base_mask(el, az, ep):
        return np.full(el.shape, cfg["base_elevation_mask"])

    rover = _receiver("rover", t_tag, (b_r, d_r), rover_pos, nav, systems, signals, cfg, rng_rover,
                      mask_fn=rover_mask, iono_origin_e=base_r_e, rover_extra={"base_r_e": base_r_e})
    base = _receiver("base", t_tag, (b_b, d_b), base_pos, nav, systems, signals, cfg, rng_base, mask_fn=base_mask,
                     iono_origin_e=base_r_e)
    return RtkSimulation(rover, base, nav, signals, base_r_e, rate, dict(cfg))
