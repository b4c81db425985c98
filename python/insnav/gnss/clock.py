"""Receiver clock noise models.

Two-state clock (bias b [m], drift d [m/s]): ``b' = d + w_b``, ``d' = w_d``
with PSDs ``clock_bias_psd`` [m^2/s] and ``clock_drift_psd`` [m^2/s^3]
(Brown & Hwang, *Introduction to Random Signals and Applied Kalman
Filtering*, 4th ed., sec. 9.3, eqs. (9.3.8)-(9.3.9): ``S_b = c^2 h0 / 2``,
``S_d = 2 pi^2 c^2 h_-2``).  Clock classes from their Table 9.1 Allan-variance
coefficients (``h0``, ``h_-2``); the flicker term ``h_-1`` is left out of the two-state
model.  TCXO defaults with margin for flicker noise:
``clock_bias_psd = 0.1`` m^2/s, ``clock_drift_psd = 0.04`` m^2/s^3.

Real receivers often drift faster than that table (a TCXO warming up after
power-on changes its frequency steadily; the rtklibexplorer walk's u-blox
drift runs from -64 to -81 m/s in two minutes).  A filter whose drift model is
too tight cannot follow the change; with few satellites the common part of
the Doppler residuals that the clock should take then goes into the velocity
(on that walk, with two of its four GPS satellites lost for 30 s, the
tight solution moves several times further with the table's PSD than with
the data's own: docs/results/gate_outages.md).  So for
real data :func:`clock_model` takes the larger of the table's drift PSD and
the one the data show (:func:`clock_drift_psd_from_drift`, from the
single-point drift of every epoch).
"""
from __future__ import annotations

import numpy as np

from .._median import median  # np.median without numpy.ma

__all__ = ["C_LIGHT_MPS", "CLOCK_ALLAN", "CLOCK_CLASSES", "TCXO_CLOCK_BIAS_PSD", "TCXO_CLOCK_DRIFT_PSD",
           "DRIFT_PSD_TAU_S", "clock_drift_psd_from_drift", "clock_model", "clock_psd_of_class"]

C_LIGHT_MPS = 299_792_458.0
#: Brown & Hwang (2012) Table 9.1: ``(h0, h_-2)`` of the fractional frequency PSD
CLOCK_ALLAN = {"tcxo": (2e-19, 2e-20), "ocxo": (8e-20, 4e-23), "rubidium": (2e-20, 4e-29)}
#: clock class -> (clock_bias_rw [m/sqrt(s)], clock_drift_rw [(m/s)/sqrt(s)])
CLOCK_CLASSES = {k: (C_LIGHT_MPS * np.sqrt(h0 / 2.0), C_LIGHT_MPS * np.sqrt(2.0 * np.pi ** 2 * hm2))
                 for k, (h0, hm2) in CLOCK_ALLAN.items()}

#: TCXO receiver clock noise (Brown & Hwang Table 9.1, see the module docstring)
TCXO_CLOCK_BIAS_PSD = 0.1     # m^2/s
TCXO_CLOCK_DRIFT_PSD = 0.04   # m^2/s^3
#: lag over which the data's drift PSD is measured [s] (the time the filter may have to predict the
#: clock with too few satellites to separate it from the velocity)
DRIFT_PSD_TAU_S = 10.0
#: differences further than this many robust standard deviations from their median are outliers
_OUTLIER_SIGMAS = 5.0


def _robust_mean_square(t: np.ndarray, d: np.ndarray, lag_s: float, tol_s: float) -> tuple[float, int]:
    """The mean of (d(t + lag) - d(t))^2 over the pairs whose time difference is lag +- tol, leaving out
    differences more than 5 robust standard deviations (1.4826 MAD) from their median, and the count of
    pairs.  A random walk's and a steady ramp's differences are all kept (a ramp's are all equal), a
    faulty satellite's epochs (under half of the pairs) are not."""
    j = np.searchsorted(t, t + lag_s - tol_s)
    ok = j < len(t)
    i, j = np.flatnonzero(ok), j[ok]
    ok = np.abs(t[j] - t[i] - lag_s) <= tol_s
    diff = d[j[ok]] - d[i[ok]]
    if diff.size == 0:
        return np.nan, 0
    med = median(diff)
    mad = median(np.abs(diff - med))
    keep = np.abs(diff - med) <= _OUTLIER_SIGMAS * 1.4826 * mad
    return float(np.mean(diff[keep] ** 2)), int(diff.size)


def clock_drift_psd_from_drift(t_s, drift_mps, tau_s: float = DRIFT_PSD_TAU_S, min_pairs: int = 20) -> float:
    """The random-walk PSD [m^2/s^3] of a receiver clock drift series that reproduces its change over
    ``tau_s``.

    For ``d' = w_d`` with PSD ``q`` observed with white noise of variance ``s^2`` per epoch, the
    lag-``tau`` difference has ``V(tau) = q tau + 2 s^2`` (Brown & Hwang, sec. 9.3; the structure
    function of a random walk), so ``q = (V(tau) - V(tau0)) / (tau - tau0)`` with ``tau0`` the epoch
    interval removes the noise.  ``V`` is the mean square of the differences without the outliers
    (further than 5 x 1.4826 MAD from their median), so a faulty satellite's epochs (under half of
    the pairs) do not raise it.
    A steady frequency change ``r`` [m/s^2] (warm-up) adds ``r^2 tau^2`` to ``V(tau)`` (so
    ``r^2 (tau + tau0)`` to ``q``): the returned PSD then covers that change over ``tau``, which is
    what the filter has to follow.

    Parameters
    ----------
    t_s : (E,) epoch times [s], increasing
    drift_mps : (E,) receiver clock drift of each epoch [m/s] (NaN: none)
    tau_s : float
        Lag [s] (default :data:`DRIFT_PSD_TAU_S`).
    min_pairs : int
        Fewer pairs at either lag give NaN.

    Returns
    -------
    float
        ``q`` [m^2/s^3] (>= 0), NaN when the series is too short.
    """
    t = np.asarray(t_s, float)
    d = np.asarray(drift_mps, float)
    ok = np.isfinite(t) & np.isfinite(d)
    t, d = t[ok], d[ok]
    if t.size < 3:
        return np.nan
    dt = np.diff(t)
    dt = dt[dt > 0]
    if dt.size == 0:
        return np.nan
    tau0 = median(dt)
    if not tau_s > 2.0 * tau0:
        return np.nan
    tol = 0.25 * tau0
    v0, n0 = _robust_mean_square(t, d, tau0, tol)
    v, n = _robust_mean_square(t, d, tau_s, tol)
    if min(n0, n) < min_pairs:
        return np.nan
    return max(0.0, (v - v0) / (tau_s - tau0))


def clock_psd_option(clock_psd, dataset) -> tuple[float, float]:
    """The tight filters' option ``clock_psd``: (bias [m^2/s], drift [m^2/s^3]) spectral
    densities, two finite numbers >= 0; None: :func:`clock_model` of the dataset."""
    if clock_psd is None:
        return clock_model(dataset)
    try:
        v = np.asarray(clock_psd, float)
    except (TypeError, ValueError):
        v = np.full(0, np.nan)
    if isinstance(clock_psd, (str, bytes)) or v.shape != (2,) or not np.all(np.isfinite(v) & (v >= 0.0)):
        from ..config import ConfigError

        raise ConfigError(f"option 'clock_psd' = {clock_psd!r}: allowed: 2 numbers >= 0, the clock bias and drift "
                          "spectral densities [m^2/s, m^2/s^3] (absent: the dataset's clock model)")
    return float(v[0]), float(v[1])


def clock_model(dataset) -> tuple[float, float]:
    """(clock_bias_psd [m^2/s], clock_drift_psd [m^2/s^3]) for a dataset.

    A simulator dataset's ``gnss_raw`` random-walk densities (squared, with a
    small floor); else the TCXO defaults, with the drift PSD raised to the one
    the data show when the dataset has a single-point solution of every epoch
    (``dataset.spp.clock_drift_mps``, real RINEX data;
    :func:`clock_drift_psd_from_drift`, module docstring).
    """
    gr = (getattr(dataset, "scenario", None) or {}).get("gnss_raw") or {}
    if "clock_bias_rw_m_per_sqrts" in gr or "clock_drift_rw_mps_per_sqrts" in gr or "clock" in gr:
        cb, cd = CLOCK_CLASSES.get(gr.get("clock", ""), (0.0, 0.0))
        qb = float(gr.get("clock_bias_rw_m_per_sqrts", cb)) ** 2
        qd = float(gr.get("clock_drift_rw_mps_per_sqrts", cd)) ** 2
        return max(qb, 1e-6), max(qd, 1e-12)
    spp = getattr(dataset, "spp", None)
    if spp is not None and getattr(spp, "clock_drift_mps", None) is not None:
        q = clock_drift_psd_from_drift(spp.t, spp.clock_drift_mps)
        if np.isfinite(q) and q > TCXO_CLOCK_DRIFT_PSD:
            return TCXO_CLOCK_BIAS_PSD, q
    return TCXO_CLOCK_BIAS_PSD, TCXO_CLOCK_DRIFT_PSD


def clock_psd_of_class(name: str) -> tuple[float, float]:
    """(clock_bias_psd [m^2/s], clock_drift_psd [m^2/s^3]) of a named clock class
    (``"tcxo"``, ``"ocxo"``, ``"rubidium"``; Brown & Hwang Table 9.1, see
    :data:`CLOCK_CLASSES`)."""
    if name not in CLOCK_CLASSES:
        raise ValueError(f"clock class {name!r} unknown; known: {', '.join(CLOCK_CLASSES)}")
    qb, qd = CLOCK_CLASSES[name]
    return qb * qb, qd * qd
