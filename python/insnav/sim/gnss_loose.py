"""Loosely coupled GNSS output: antenna position and velocity fixes.

Antenna (lever arm ``l_b`` from the IMU centre, body FRD):

    r_ant_e = r_e + C_en C_nb l_b                              (exact, via ECEF)
    v_ant_n = v_n + C_nb (omega_eb_b x l_b),  omega_eb_b = omega_nb_b + C_bn omega_en_n

(Groves 2013, eqs. (14.121)-(14.122); ``v_ant_n`` is resolved in the NED
frame of the IMU position.)  White noise ``N(0, sigma_h^2)`` north and east,
``N(0, sigma_v^2)`` down, ``N(0, sigma_vel^2)`` per velocity axis is added in
metres and converted to latitude/longitude with the radii of curvature.

Epochs at ``first_epoch_s + k / rate_hz`` up to the end of the scenario;
epochs strictly inside an outage window ``(start, end)`` are removed.
Delays (seed 001 eq. (4)), in whole GNSS epochs, ``delay_model``:

* ``"one_per_epoch"`` (the paper's model): at every epoch ``k`` the filter
  receives exactly one measurement, ``y_k = z_{k - tau_k}`` with
  ``P(tau_k = i) = delay_p[i]`` drawn independently per epoch.  A fix may
  therefore arrive twice (same noise realisation) or never.  At the start only
  delays reaching back to the first epoch are possible (``delay_p`` is
  renormalised over them); nothing is received at an epoch inside an outage
  or when the chosen fix fell in one.  Records are in ``t_arrival`` order
  (one per arrival epoch).
* ``"independent"``: each fix is delayed by its own draw ``i`` and arrives at
  ``t_valid + i / rate_hz``; several fixes can arrive in the same epoch
  (21-26 % of the epochs of the seed001 presets) and some epochs receive
  none.  Records are in ``t_valid`` order.
"""
from __future__ import annotations

import numpy as np

from .. import earth
from ..data.dataset import GnssFixes
from .trajectory import Trajectory, rotate_b_to_n, rotate_n_to_b


def antenna_state(traj: Trajectory, t, lever_arm_b):
    """True antenna position and velocity.

    Returns
    -------
    lat, lon, h : ndarray
        Antenna geodetic position [rad, rad, m].
    v_ant_n : ndarray (N, 3)
        Antenna velocity relative to the Earth, NED [m/s].
    r_ant_e, v_ant_e : ndarray (N, 3)
        The same in ECEF [m], [m/s].
    """
    st = traj.state(t)
    l_b = np.broadcast_to(np.asarray(lever_arm_b, float), st["v_n"].shape)
    r_e = earth.geodetic_to_ecef(st["lat"], st["lon"], st["h"])
    l_n = rotate_b_to_n(st["euler"], l_b)
    r_ant_e = r_e + earth.ned_to_ecef_vector(st["lat"], st["lon"], l_n)
    w_en_b = rotate_n_to_b(st["euler"], earth.omega_en_n(st["lat"], st["h"], st["v_n"]))
    omega_eb_b = st["omega_nb_b"] + w_en_b
    v_ant_n = st["v_n"] + rotate_b_to_n(st["euler"], np.cross(omega_eb_b, l_b))
    lat, lon, h = earth.ecef_to_geodetic(r_ant_e)
    v_ant_e = earth.ned_to_ecef_vector(st["lat"], st["lon"], v_ant_n)
    return lat, lon, h, v_ant_n, r_ant_e, v_ant_e


def gnss_epochs(t0, t_end, first, rate):
    """Epoch times ``first + k / rate`` in ``[t0, t_end]`` (rounded to 1 ns)."""
    k0 = int(np.ceil((t0 - first) * rate - 1e-9)) if first < t0 else 0
    k1 = int(np.floor((t_end - first) * rate + 1e-9))
    k = np.arange(max(k0, 0), k1 + 1)
    return np.round(first + k / rate, 9)


def in_windows(t, windows):
    """Mask of ``t`` strictly inside any ``(start, end)`` window."""
    m = np.zeros(np.shape(t), bool)
    for a, b in windows:
        m |= (t > a) & (t < b)
    return m


def _no_fixes() -> GnssFixes:
    z = np.empty((0,))
    return GnssFixes(z, z, z, z, z, np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))


def simulate_gnss_fixes(traj: Trajectory, cfg: dict, rng_noise: np.random.Generator,
                        rng_delay: np.random.Generator) -> GnssFixes:
    """Simulate loosely coupled fixes for the ``[gnss]`` configuration ``cfg`` (SI dict)."""
    fixes = GnssFixStream(traj, cfg, rng_noise, rng_delay)
    return fixes.block(fixes.k_lo, fixes.k_hi)


class GnssFixStream:
    """The fixes of :func:`simulate_gnss_fixes`, epoch block by epoch block, with the same numbers.

    The whole-array draw takes the position noise of every received epoch
    (``standard_normal((n, 3))``) and then the velocity noise
    (``standard_normal((n, 3))``) from one generator: here the velocity noise
    comes from a copy of the generator advanced past the ``3 n`` position
    draws (made once, in blocks), so each block takes its rows of both in
    turn.  Delays (``"independent"``) are one uniform draw per fix in order,
    so drawn per block too.  The ``"one_per_epoch"`` model looks back up to
    ``len(delay_p) - 1`` epochs and is computed whole at the first block.

    Parameters
    ----------
    traj, cfg, rng_noise, rng_delay
        As :func:`simulate_gnss_fixes`; blocks must be asked for in order.
    """

    def __init__(self, traj: Trajectory, cfg: dict, rng_noise: np.random.Generator,
                 rng_delay: np.random.Generator, count_block: int = 100_000):
        import copy

        sc = traj.sc
        self.traj, self.cfg, self.rng_delay = traj, cfg, rng_delay
        first, rate = cfg["first_epoch"], cfg["rate"]
        # epoch k at first + k / rate, k in [k_lo, k_hi) (gnss_epochs without the array)
        k0 = int(np.ceil((sc.t0 - first) * rate - 1e-9)) if first < sc.t0 else 0
        self.k_lo = max(k0, 0)
        self.k_hi = max(self.k_lo, int(np.floor((sc.t_end - first) * rate + 1e-9)) + 1)
        self.enabled = bool(cfg["enabled"])
        self.one_per_epoch = cfg["delay_p"].size > 1 and cfg.get("delay_model", "independent") == "one_per_epoch"
        self._whole = None
        self._next = self.k_lo
        self.rng_pos = rng_noise
        self.rng_vel = copy.deepcopy(rng_noise)
        n = 0
        for a in range(self.k_lo, self.k_hi, count_block):
            m = int(np.count_nonzero(self._received(self._epochs(a, min(self.k_hi, a + count_block)))))
            self.rng_vel.standard_normal((m, 3))  # past the position noise of these epochs
            n += m
        self.n_received = n

    def _epochs(self, a: int, b: int) -> np.ndarray:
        return np.round(self.cfg["first_epoch"] + np.arange(a, b) / self.cfg["rate"], 9)

    def _received(self, t: np.ndarray) -> np.ndarray:
        return ~in_windows(t, self.cfg["outages"])

    def epoch_index(self, t: float) -> int:
        """The first epoch index at or after time ``t`` [s], within ``[k_lo, k_hi]``."""
        k = int(np.ceil((t - self.cfg["first_epoch"]) * self.cfg["rate"] - 1e-9))
        return min(self.k_hi, max(self.k_lo, k))

    def block(self, a: int, b: int) -> GnssFixes:
        """The records of the epochs ``a .. b - 1`` (``a`` where the previous block ended): by valid
        time (``"independent"``), by arrival epoch (``"one_per_epoch"``)."""
        if a != self._next:
            raise ValueError(f"GnssFixStream: expected epochs from {self._next}, got {a}")
        self._next = b
        if self.n_received == 0 or not self.enabled or b <= a:
            return _no_fixes()
        if self.one_per_epoch:
            if self._whole is None:
                self._whole = self._one_per_epoch()
            sel = (self._whole.t_arrival >= self._epochs(a, a + 1)[0]) & (self._whole.t_arrival < (
                self._epochs(b, b + 1)[0] if b < self.k_hi else np.inf))
            return GnssFixes(*(getattr(self._whole, f)[sel] for f in _FIELDS))
        cfg = self.cfg
        t_all = self._epochs(a, b)
        t = t_all[self._received(t_all)]
        lat_d, lon_d, h_m, v_m, sig_pos, sig_vel = self._fixes(t)
        p = cfg["delay_p"]
        n = t.size
        delay = self.rng_delay.choice(p.size, size=n, p=p) if p.size > 1 else np.zeros(n, int)
        t_arr = np.round(t + delay / cfg["rate"], 9)
        return GnssFixes(t, t_arr, lat_d, lon_d, h_m, v_m, np.tile(sig_pos, (n, 1)), np.tile(sig_vel, (n, 1)))

    def _fixes(self, t):
        """Noisy antenna fixes at the received epochs ``t``: degrees, metres, m/s, and the sigmas."""
        cfg, n = self.cfg, t.size
        lat, lon, h, v_n, _, _ = antenna_state(self.traj, t, cfg["lever_arm_b"])
        sig_pos = np.array([cfg["sigma_h"], cfg["sigma_h"], cfg["sigma_v"]])
        sig_vel = np.full(3, cfg["sigma_vel"])
        e_pos = sig_pos * self.rng_pos.standard_normal((n, 3))
        e_vel = sig_vel * self.rng_vel.standard_normal((n, 3))
        R_M, R_N = earth.radii(lat)
        lat_m = lat + e_pos[:, 0] / (R_M + h)
        lon_m = lon + e_pos[:, 1] / ((R_N + h) * np.cos(lat))
        h_m = h - e_pos[:, 2]
        return np.degrees(lat_m), np.degrees(lon_m), h_m, v_n + e_vel, sig_pos, sig_vel

    def _one_per_epoch(self) -> GnssFixes:
        """All the records of the ``"one_per_epoch"`` model (seed 001 eq. (4)), whole."""
        cfg = self.cfg
        t_all = self._epochs(self.k_lo, self.k_hi)
        received = self._received(t_all)
        t = t_all[received]
        lat_d, lon_d, h_m, v_m, sig_pos, sig_vel = self._fixes(t)
        # fix j (index into the received epochs) of every epoch k of t_all
        j_of_epoch = np.cumsum(received) - 1
        pick = _one_per_epoch_delays(t_all.size, cfg["delay_p"], self.rng_delay)
        k = np.arange(t_all.size)
        src = k - pick
        ok = received & received[src]  # nothing at an outage epoch, nor a fix that was never made
        j = j_of_epoch[src[ok]]
        t_arr = t_all[ok]
        return GnssFixes(t[j], t_arr, lat_d[j], lon_d[j], h_m[j], v_m[j],
                         np.tile(sig_pos, (j.size, 1)), np.tile(sig_vel, (j.size, 1)))


_FIELDS = ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n")


def _one_per_epoch_delays(n_epochs: int, p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Delay ``tau_k`` [epochs] of the one measurement received at each of
    ``n_epochs`` epochs, ``P(tau_k = i) = p[i]`` (seed 001 eq. (4)); at epoch
    ``k < len(p) - 1`` only ``tau <= k`` exist and ``p`` is renormalised over them."""
    u = rng.random(n_epochs)
    tau = np.searchsorted(np.cumsum(p), u * p.sum(), side="right")
    tau = np.minimum(tau, p.size - 1)
    for k in range(min(n_epochs, p.size - 1)):  # the first epochs: renormalise over tau <= k
        q = p[:k + 1] / p[:k + 1].sum()
        tau[k] = min(int(np.searchsorted(np.cumsum(q), u[k], side="right")), k)
    return tau
