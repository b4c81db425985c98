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


def simulate_gnss_fixes(traj: Trajectory, cfg: dict, rng_noise: np.random.Generator,
                        rng_delay: np.random.Generator) -> GnssFixes:
    """Simulate loosely coupled fixes for the ``[gnss]`` configuration ``cfg`` (SI dict)."""
    sc = traj.sc
    t_all = gnss_epochs(sc.t0, sc.t_end, cfg["first_epoch"], cfg["rate"])
    received = ~in_windows(t_all, cfg["outages"])
    t = t_all[received]
    n = t.size
    if n == 0 or not cfg["enabled"]:
        z = np.empty((0,))
        return GnssFixes(z, z, z, z, z, np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))
    lat, lon, h, v_n, _, _ = antenna_state(traj, t, cfg["lever_arm_b"])
    sig_pos = np.array([cfg["sigma_h"], cfg["sigma_h"], cfg["sigma_v"]])
    sig_vel = np.full(3, cfg["sigma_vel"])
    e_pos = sig_pos * rng_noise.standard_normal((n, 3))
    e_vel = sig_vel * rng_noise.standard_normal((n, 3))
    R_M, R_N = earth.radii(lat)
    lat_m = lat + e_pos[:, 0] / (R_M + h)
    lon_m = lon + e_pos[:, 1] / ((R_N + h) * np.cos(lat))
    h_m = h - e_pos[:, 2]
    p = cfg["delay_p"]
    lat_d, lon_d, v_m = np.degrees(lat_m), np.degrees(lon_m), v_n + e_vel
    if p.size > 1 and cfg.get("delay_model", "independent") == "one_per_epoch":
        # fix j (index into the received epochs) of every epoch k of t_all
        j_of_epoch = np.cumsum(received) - 1
        pick = _one_per_epoch_delays(t_all.size, p, rng_delay)
        k = np.arange(t_all.size)
        src = k - pick
        ok = received & received[src]  # nothing at an outage epoch, nor a fix that was never made
        j = j_of_epoch[src[ok]]
        t_arr = t_all[ok]
        return GnssFixes(t[j], t_arr, lat_d[j], lon_d[j], h_m[j], v_m[j],
                         np.tile(sig_pos, (j.size, 1)), np.tile(sig_vel, (j.size, 1)))
    delay = rng_delay.choice(p.size, size=n, p=p) if p.size > 1 else np.zeros(n, int)
    t_arr = np.round(t + delay / cfg["rate"], 9)
    return GnssFixes(t, t_arr, lat_d, lon_d, h_m, v_m,
                     np.tile(sig_pos, (n, 1)), np.tile(sig_vel, (n, 1)))


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
