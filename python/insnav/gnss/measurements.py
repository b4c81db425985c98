"""Predicted GPS L1 observables (pseudorange, pseudorange rate) for given receiver states.

Glue between the ephemeris, geometry and correction modules; used by the
residual checks (tests, ``bench/gnss_residuals.py``) and usable by filters
for per-epoch prediction arrays.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import earth
from .corrections import klobuchar_delay, saastamoinen_delay
from .ephemeris import C_LIGHT, Ephemerides, select_ephemeris, transmit_states
from .geometry import elevation_azimuth

__all__ = ["L1_WAVELENGTH", "Predicted", "predict_observables", "common_clock_residuals",
           "Residuals", "observation_residuals"]

#: GPS L1 carrier frequency [Hz] and wavelength [m] (IS-GPS-200 3.3.1.1).
L1_FREQ_HZ = 1575.42e6
L1_WAVELENGTH = C_LIGHT / L1_FREQ_HZ


class Predicted(NamedTuple):
    """Predicted observables, one per input row (NaN where no ephemeris)."""

    range_m: np.ndarray  #: geometric range incl. Sagnac [m]
    pseudorange_m: np.ndarray  #: range - c dt_sv + iono + tropo (no receiver clock) [m]
    range_rate_mps: np.ndarray  #: u.(v_sat - v_rx) - c d(dt_sv)/dt (no receiver drift) [m/s]
    iono_m: np.ndarray  #: Klobuchar delay used (0 if off) [m]
    tropo_m: np.ndarray  #: Saastamoinen delay used (0 if off) [m]
    el: np.ndarray  #: elevation [rad]
    az: np.ndarray  #: azimuth [rad]
    eph_idx: np.ndarray  #: ephemeris row used (-1 = none)


def predict_observables(eph: Ephemerides, t_rx_gps_s, prn, r_rx_e, v_rx_e=None, *,
                        ion_alpha=None, ion_beta=None, iono=False, tropo=False, tgd=True) -> Predicted:
    """Predict L1 C/A pseudorange and pseudorange rate, vectorised over rows.

    Parameters
    ----------
    eph : Ephemerides
    t_rx_gps_s : (m,) receive times, true GPS time [s]
    prn : (m,) int
    r_rx_e : (m, 3) or (3,) receiver ECEF position [m]
    v_rx_e : (m, 3) or (3,), optional receiver ECEF velocity [m/s] (default 0)
    ion_alpha, ion_beta : (4,) Klobuchar coefficients (needed if ``iono``)
    iono, tropo : bool
        Add the Klobuchar / Saastamoinen delays.
    tgd : bool
        Apply T_GD to the satellite clock (L1 C/A user, IS-GPS-200 20.3.3.3.3.2).

    Returns
    -------
    Predicted
        ``pseudorange_m = rho - c dt_sv + I + T``; the measurement equals it
        plus ``c dt_rx`` and noise.  Transmit time and Sagnac as in
        :func:`insnav.gnss.ephemeris.transmit_states`.
    """
    prn = np.atleast_1d(np.asarray(prn, dtype=np.int64))
    m = prn.size
    t = np.broadcast_to(np.asarray(t_rx_gps_s, dtype=float), (m,))
    r_rx = np.broadcast_to(np.asarray(r_rx_e, dtype=float), (m, 3))
    v_rx = np.zeros((m, 3)) if v_rx_e is None else np.broadcast_to(np.asarray(v_rx_e, dtype=float), (m, 3))
    idx = select_ephemeris(eph, prn, t)
    ok = idx >= 0
    nan = np.full(m, np.nan)
    rng, pr, rr, io, tr, el, az = (nan.copy() for _ in range(7))
    if np.any(ok):
        ts = transmit_states(eph, idx[ok], t[ok], r_rx[ok], tgd=tgd)
        d = ts.r_e - r_rx[ok]
        u = d / ts.range_m[:, None]
        el_k, az_k = elevation_azimuth(r_rx[ok], ts.r_e)
        i_k = np.zeros(ok.sum())
        t_k = np.zeros(ok.sum())
        if iono or tropo:
            lat, lon, h = earth.ecef_to_geodetic(r_rx[ok])
            if iono:
                if ion_alpha is None or ion_beta is None:
                    raise ValueError("iono=True needs ion_alpha and ion_beta")
                i_k = klobuchar_delay(t[ok], lat, lon, el_k, az_k, ion_alpha, ion_beta)
            if tropo:
                t_k = saastamoinen_delay(lat, h, el_k)
        rng[ok] = ts.range_m
        pr[ok] = ts.range_m - C_LIGHT * ts.clock_bias_s + i_k + t_k
        rr[ok] = np.einsum("ij,ij->i", u, ts.v_e - v_rx[ok]) - C_LIGHT * ts.clock_drift_s_s
        io[ok], tr[ok], el[ok], az[ok] = i_k, t_k, el_k, az_k
    return Predicted(rng, pr, rr, io, tr, el, az, idx)


def common_clock_residuals(resid, epoch):
    """Remove the per-epoch median (common receiver clock) from residuals.

    Parameters
    ----------
    resid : (m,) residuals (NaN allowed)
    epoch : (m,) int epoch index of each row

    Returns
    -------
    (m,) residuals minus the median of their epoch (NaN rows stay NaN);
    rows of epochs with fewer than 2 finite values are set to NaN.
    """
    resid = np.asarray(resid, dtype=float)
    epoch = np.asarray(epoch)
    out = np.full_like(resid, np.nan)
    ok = np.isfinite(resid)
    e = epoch[ok]
    r = resid[ok]
    order = np.argsort(e, kind="stable")
    e_s, r_s = e[order], r[order]
    starts = np.flatnonzero(np.r_[True, e_s[1:] != e_s[:-1]])
    counts = np.diff(np.r_[starts, e_s.size])
    med = np.array([np.median(r_s[s:s + c]) for s, c in zip(starts, counts)])
    med_row = np.repeat(med, counts)
    cnt_row = np.repeat(counts, counts)
    res_s = np.where(cnt_row >= 2, r_s - med_row, np.nan)
    tmp = np.empty_like(r)
    tmp[order] = res_s
    out[ok] = tmp
    return out


class Residuals(NamedTuple):
    """Observation-minus-prediction residuals, one per observation row."""

    pseudorange_m: np.ndarray  #: C1 residual after removing the per-epoch median [m]
    range_rate_mps: np.ndarray  #: -lambda*D1 residual after removing the per-epoch median [m/s]
    rx_clock_m: np.ndarray  #: (n_epochs,) per-epoch median of the raw C1 residual (c dt_rx) [m]
    predicted: Predicted


def observation_residuals(obs, eph: Ephemerides, r_rx_e, v_rx_e=None, **kwargs) -> Residuals:
    """Residuals of an :class:`~insnav.gnss.rinex.ObsData` against known receiver states.

    Two passes: the first, with the receiver time tags, estimates the
    per-epoch receiver clock ``c dt_rx`` (median raw residual); the second
    evaluates the model at the true reception time ``t_tag - dt_rx`` (a
    1 ms receiver clock error otherwise moves satellites by ~4 m).  The
    per-epoch median is then removed from the pseudorange and the
    pseudorange-rate residuals (receiver clock and clock drift).

    Parameters
    ----------
    obs : ObsData
    eph : Ephemerides
    r_rx_e : (n_epochs, 3) receiver ECEF positions at the observation epochs [m]
    v_rx_e : (n_epochs, 3), optional receiver ECEF velocities [m/s]
    **kwargs
        Passed to :func:`predict_observables` (``iono``, ``tropo``,
        ``ion_alpha``, ``ion_beta``, ``tgd``).
    """
    n_ep = obs.epoch_t_gps_s.size
    r = np.asarray(r_rx_e, dtype=float)[obs.epoch]
    v = None if v_rx_e is None else np.asarray(v_rx_e, dtype=float)[obs.epoch]
    clk = np.zeros(n_ep)
    for _ in range(2):
        pred = predict_observables(eph, obs.t_gps_s - clk[obs.epoch] / C_LIGHT, obs.prn, r, v, **kwargs)
        raw = obs.C1 - pred.pseudorange_m
        ok = np.isfinite(raw)
        sums = np.bincount(obs.epoch[ok], minlength=n_ep)
        med = np.zeros(n_ep)
        for e in np.flatnonzero(sums):
            med[e] = np.median(raw[ok & (obs.epoch == e)])
        clk = med
    pr_res = common_clock_residuals(raw, obs.epoch)
    rr_res = common_clock_residuals(-L1_WAVELENGTH * obs.D1 - pred.range_rate_mps, obs.epoch)
    return Residuals(pr_res, rr_res, clk, pred)


class RtklibPos(NamedTuple):
    """An RTKLIB ``.pos`` solution as a reference (GPST time, ECEF), as
    :func:`insnav.io.gnss_files.read_rtklib_pos` reads it."""

    t_gps_s: np.ndarray  #: (n,) [s]
    r_e: np.ndarray  #: (n, 3) ECEF [m]
    v_e: np.ndarray  #: (n, 3) ECEF [m/s] (NaN if the file has no velocity columns)
    q: np.ndarray  #: (n,) quality flag (1 fix, 2 float, 5 single)
    lines: np.ndarray | None = None  #: (n,) 1-based file line of each record (None: not read from a file)
