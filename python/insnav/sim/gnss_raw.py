"""Raw GNSS output for tight coupling: pseudoranges and pseudorange rates
of GPS and (``systems``) the nominal Galileo and BeiDou MEO constellations.

Model (documented here because the tight filter inverts exactly this)::

    tau   = |R_z(w tau) r_sat(t - tau) - r_rx(t)| / c          (light time, iterated)
    r_sat = R_z(w tau) r_sat_e(t - tau),  v_sat = R_z(w tau) v_sat_e(t - tau)
    rho   = |r_sat - r_rx(t)| + b_rx(t) - c dt_sv(t - tau) + e_rho
    rhod  = u . (v_sat - v_rx(t)) + d_rx(t) - c ddt_sv(t - tau) + e_rhod
    u     = (r_sat - r_rx) / |r_sat - r_rx|

with ``w`` the IS-GPS-200 Earth rate (Sagnac rotation into the ECEF frame at
reception), ``r_rx``/``v_rx`` the true antenna ECEF position/velocity at the
true reception time ``t`` (the record's ``t``), ``c dt_sv`` the broadcast
clock polynomial with the relativistic term (no T_GD), ``e_rho ~ N(0,
sigma_pr^2)``, ``e_rhod ~ N(0, sigma_prr^2)``.  No ionosphere or troposphere.
Satellite states come from :class:`insnav.gnss.constellation.Constellation`
(nominal 32-satellite set re-referenced to the scenario's start, or a RINEX
navigation file) and :func:`insnav.gnss.ephemeris.transmit_states`.

Several systems (``systems = ["G", "E", "C"]``): Galileo and BeiDou satellites
from the nominal Walker constellations of :mod:`insnav.gnss.walker`; the
pseudorange of a satellite of system s adds its inter-system bias ``isb_s``
[m] (``[gnss_raw.isb_m]``, GPS 0: the receiver clock is GPS time), the rate
does not.  Urban canyon (``[gnss_raw.urban_canyon]``): the elevation mask
becomes azimuth dependent, :func:`urban_canyon_mask` about the street axis
(the vehicle's heading unless a fixed ``street_azimuth_deg`` is given).

Receiver clock: bias ``b`` [m] and drift ``d`` [m/s] as a two-state random
walk, ``b' = d + w_b``, ``d' = w_d`` with white-noise densities
``clock_bias_rw`` [m/sqrt(s)] and ``clock_drift_rw`` [(m/s)/sqrt(s)],
discretised exactly (Brown & Hwang, *Introduction to Random Signals and
Applied Kalman Filtering*, 4th ed., section 9.3), starting from
``(clock_bias0_m, clock_drift0_mps)`` at ``t0``.

Satellite selection per epoch: elevation at or above the mask; then, if
``max_sats`` > 0, the best-GDOP subset of that size
(:func:`insnav.gnss.geometry.select_best_gdop`).  Inside a
``[[gnss_raw.windows]]`` window (epochs strictly inside ``(start, end)``, as for
GNSS outages) satellites *fail* (seed 003): at the window's first epoch the
``n_sats`` highest of the satellites in use at the epoch before are kept
(a subset of them, never a new satellite), and the same satellites are kept
through the window while they stay above the mask; one that sets is replaced
by the highest remaining satellite of the pre-window set, then by any visible
one.  A window asking for at least as many satellites as are in use keeps the
usual selection.  An epoch with fewer visible satellites than asked keeps all
it has.

Receiver clock classes (``clock = "tcxo" | "ocxo" | "rubidium"``) set the two
densities from the Allan-variance coefficients of Brown & Hwang (2012),
*Introduction to Random Signals and Applied Kalman Filtering*, 4th ed.,
Table 9.1 (``h0``, ``h_-2``): ``clock_bias_rw = c sqrt(h0 / 2)``,
``clock_drift_rw = c sqrt(2 pi^2 h_-2)`` (white frequency and random-walk
frequency noise; the flicker term ``h_-1`` is left out of the two-state
model).  See :data:`CLOCK_CLASSES`.
"""
from __future__ import annotations

import numpy as np

from .. import earth
from ..data.dataset import GnssRaw
from .gnss_loose import antenna_state, gnss_epochs
from .trajectory import Trajectory

from ..gnss.clock import C_LIGHT_MPS, CLOCK_ALLAN, CLOCK_CLASSES  # noqa: F401  (re-used names)


def simulate_clock(t, t0, b0, d0, q_b, q_d, rng: np.random.Generator):
    """Receiver clock bias [m] and drift [m/s] at times ``t`` (increasing, > t0)."""
    t = np.asarray(t, float)
    dt = np.diff(np.concatenate([[t0], t]))
    z = rng.standard_normal((t.size, 2))
    # exact discrete process noise of [b, d] over dt
    q11 = q_b ** 2 * dt + q_d ** 2 * dt ** 3 / 3.0
    q12 = q_d ** 2 * dt ** 2 / 2.0
    q22 = q_d ** 2 * dt
    l11 = np.sqrt(q11)
    l21 = np.where(l11 > 0, q12 / np.where(l11 > 0, l11, 1.0), 0.0)
    l22 = np.sqrt(np.maximum(q22 - l21 ** 2, 0.0))
    w_b = l11 * z[:, 0]
    w_d = l21 * z[:, 0] + l22 * z[:, 1]
    d = d0 + np.cumsum(w_d)
    d_prev = np.concatenate([[d0], d[:-1]])
    b = b0 + np.cumsum(d_prev * dt + w_b)
    return b, d


def make_constellation(spec: str, t_start_gps: float):
    """``'nominal'`` or a RINEX navigation file path -> :class:`Constellation`."""
    from ..gnss.constellation import Constellation

    if spec == "nominal":
        return Constellation.nominal(t0_gps_s=t_start_gps)
    cons = Constellation.from_rinex_nav(spec)
    toe = np.asarray(cons.eph.toe, float)  # GPS seconds since 1980-01-06
    if toe.size and not np.any(np.abs(toe - t_start_gps) <= 4 * 3600.0):  # a broadcast fit interval (4 h)
        week = int(t_start_gps // 604800.0)
        raise ValueError(f"{spec}: no GPS ephemeris within 4 h of the scenario's start (GPS week {week}, "
                         f"{t_start_gps - week * 604800.0:.0f} s of week; the file's reference times span week "
                         f"{int(toe.min() // 604800)} {toe.min() % 604800:.0f} s to {toe.max() % 604800:.0f} s): set "
                         "[time] gps_week / gps_tow_s inside it")
    return cons


def simulate_gnss_raw(traj: Trajectory, cfg: dict, lever_arm_b, gps_time_offset_s: float,
                      rng_noise: np.random.Generator, rng_clock: np.random.Generator,
                      constellation=None) -> GnssRaw:
    """Simulate raw observations for the ``[gnss_raw]`` configuration ``cfg`` (SI dict)."""
    from ..gnss.ephemeris import C_LIGHT, select_ephemeris, transmit_states
    from ..gnss.geometry import select_best_gdop

    from ..gnss.systems import SYSTEMS

    sc = traj.sc
    t = gnss_epochs(sc.t0, sc.t_end, sc.t0 + 1.0 / cfg["rate"], cfg["rate"])
    if constellation is None:
        constellation = make_constellation(cfg["constellation"], sc.t0 + gps_time_offset_s)
    ne = t.size
    lat, lon, _, _, r_rx_e, v_rx_e = antenna_state(traj, t, lever_arm_b)
    t_gps = t + gps_time_offset_s
    parts = []
    for system in cfg.get("systems", ("G",)):
        if system == "G":
            cons = constellation
        else:
            from ..gnss.walker import walker_constellation

            cons = walker_constellation(system, sc.t0 + gps_time_offset_s)
        eph = cons.eph
        prns = np.asarray(cons.prns, dtype=np.int64)
        ns = prns.size
        ep_s = np.repeat(np.arange(ne), ns)
        prn_s = np.tile(prns, ne)
        if cons.is_nominal:
            lut = {int(p): i for i, p in enumerate(eph.prn)}
            idx = np.tile(np.array([lut[int(p)] for p in prns], np.int64), ne)
        else:
            idx = select_ephemeris(eph, prn_s, t_gps[ep_s])
        ok = idx >= 0
        ep_s, prn_s, idx = ep_s[ok], prn_s[ok], idx[ok]
        ts_s = transmit_states(eph, idx, t_gps[ep_s], r_rx_e[ep_s])
        parts.append((ep_s, prn_s, np.full(ep_s.size, SYSTEMS.index(system), np.int64), ts_s.r_e, ts_s.v_e,
                      ts_s.clock_bias_s, ts_s.clock_drift_s_s, ts_s.tau_s))
    order = np.argsort(np.concatenate([p[0] for p in parts]), kind="stable")  # by epoch, then system, PRN
    ep, prn_rows, sys_rows, sat_r, sat_v, clk_s, clkd_s, tau_s = (np.concatenate([p[k] for p in parts])[order]
                                                                  for k in range(8))
    sid = sys_rows * 1000 + prn_rows  # one identifier per satellite across systems
    d = sat_r - r_rx_e[ep]
    rng = np.linalg.norm(d, axis=1)
    u_e = d / rng[:, None]
    u_n = earth.ecef_to_ned_vector(lat[ep], lon[ep], u_e)
    el = np.arcsin(np.clip(-u_n[:, 2], -1.0, 1.0))
    az = np.mod(np.arctan2(u_n[:, 1], u_n[:, 0]), 2 * np.pi)
    mask = np.full(el.shape, cfg["elevation_mask"])
    canyon = cfg.get("urban_canyon")
    if canyon:
        if canyon["street_azimuth"] is None:  # the street runs along the vehicle's heading
            street = traj.state(t)["euler"][:, 2][ep]
        else:
            street = np.full(el.shape, canyon["street_azimuth"])
        mask = np.maximum(mask, urban_canyon_mask(az - street, canyon["mask_across"], canyon["mask_along"]))
    keep = el >= mask

    windows = cfg["windows"]
    max_sats = cfg["max_sats"]
    if max_sats or windows:
        starts = np.searchsorted(ep, np.arange(ne))
        ends = np.searchsorted(ep, np.arange(ne), side="right")
        in_use: list[int] = []       # PRNs kept at the previous epoch
        before: list[int] = []       # PRNs in use just before the current window
        failing: list[int] = []      # PRNs kept inside the current window
        current_window = None
        for k in range(ne):
            wins = [(a, b, n_w) for (a, b, n_w) in windows if a < t[k] < b]
            rows = np.arange(starts[k], ends[k])
            rows = rows[keep[rows]]
            if wins and wins[0][2] < max(len(in_use) if current_window is None else len(before), 1):
                # satellites fail: a subset of those in use before the window
                if wins[0] != current_window:
                    current_window, before, failing = wins[0], list(in_use), []
                want = wins[0][2]
                prn_here = {int(sid[r]): r for r in rows}
                chosen = [p for p in failing if p in prn_here]
                for pool in (before, [int(sid[r]) for r in rows]):
                    for p in sorted((q for q in pool if q in prn_here and q not in chosen),
                                    key=lambda q: -el[prn_here[q]]):
                        if len(chosen) >= want:
                            break
                        chosen.append(p)
                failing = chosen
                keep[starts[k]:ends[k]] = False
                keep[[prn_here[p] for p in chosen]] = True
                in_use = chosen
                continue
            current_window = None
            want = wins[0][2] if wins else max_sats
            if want and want < rows.size:
                keep[starts[k]:ends[k]] = False
                if want >= 4:
                    sel, _ = select_best_gdop(u_n[rows], want)
                    keep[rows[sel]] = True
                else:
                    keep[rows[np.argsort(-el[rows], kind="stable")[:want]]] = True
            in_use = [int(p) for p in sid[starts[k]:ends[k]][keep[starts[k]:ends[k]]]]

    ep, prn_rows, sys_rows = ep[keep], prn_rows[keep], sys_rows[keep]
    r_sat, v_sat = sat_r[keep], sat_v[keep]
    clk_b = C_LIGHT * clk_s[keep]
    clk_d = C_LIGHT * clkd_s[keep]
    rng, u_e = rng[keep], u_e[keep]
    m = ep.size
    b_rx, d_rx = simulate_clock(t, sc.t0, cfg["clock_bias0"], cfg["clock_drift0"],
                                cfg["clock_bias_rw"], cfg["clock_drift_rw"], rng_clock)
    e = rng_noise.standard_normal((m, 2))
    isb = np.array([cfg.get("isb", {}).get(sy, 0.0) for sy in SYSTEMS])  # true inter-system biases [m]
    pr = rng + b_rx[ep] + isb[sys_rows] - clk_b + cfg["sigma_pr"] * e[:, 0]
    prr = (np.einsum("ij,ij->i", u_e, v_sat - v_rx_e[ep]) + d_rx[ep] - clk_d
           + cfg["sigma_prr"] * e[:, 1])
    return GnssRaw(t=t[ep], prn=prn_rows, pseudorange_m=pr, pseudorange_rate_mps=prr,
                   sat_r_e=r_sat, sat_v_e=v_sat, sat_clock_bias_m=clk_b, sat_clock_drift_mps=clk_d,
                   elevation_deg=np.degrees(el[keep]), azimuth_deg=np.degrees(az[keep]),
                   travel_time_s=tau_s[keep], sigma_pr_m=np.full(m, cfg["sigma_pr"]),
                   sigma_prr_mps=np.full(m, cfg["sigma_prr"]), rx_clock_bias_m=b_rx[ep],
                   rx_clock_drift_mps=d_rx[ep], system=np.asarray(SYSTEMS)[sys_rows])


def urban_canyon_mask(d_az, mask_across, mask_along):
    """Elevation mask [rad] of a straight street canyon at azimuth ``d_az`` [rad]
    from the street axis: buildings of height H at distance W/2 on both sides
    hide a satellite below ``atan(tan(mask_across) |sin d_az|)`` (the building
    edge seen along the line of sight is ``W / (2 |sin d_az|)`` away), so
    ``mask_across`` [rad] is the mask across the street (``atan(2 H / W)``),
    and along it the mask falls to ``mask_along`` [rad] (the far end of the
    street, other obstructions)."""
    geo = np.arctan(np.tan(mask_across) * np.abs(np.sin(d_az)))
    return np.maximum(geo, mask_along)
