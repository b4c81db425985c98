"""Receiver-satellite geometry: line of sight, elevation/azimuth, DOP, best-GDOP subset.

Frames: ``e`` = ECEF, ``n`` = local North-East-Down at the receiver
(:func:`insnav.earth.C_en`).  Angles in rad.
"""
from __future__ import annotations

import functools
import itertools
import math
from typing import NamedTuple

import numpy as np

from .. import _core, earth

__all__ = ["los_unit_e", "elevation_azimuth", "elevation_mask", "los_unit_n",
           "Dop", "dop", "dop_from_los_n", "select_best_gdop"]


def los_unit_e(r_rx_e, r_sat_e):
    """Receiver-to-satellite unit vectors in ECEF, shape (k, 3), and ranges [m], shape (k,)."""
    d = np.asarray(r_sat_e, dtype=float) - np.asarray(r_rx_e, dtype=float)
    rng = np.linalg.norm(d, axis=-1)
    return d / rng[..., None], rng


def los_unit_n(r_rx_e, r_sat_e):
    """Receiver-to-satellite unit vectors in the receiver's NED frame, shape (k, 3)."""
    r_rx_e = np.asarray(r_rx_e, dtype=float)
    lat, lon, _ = earth.ecef_to_geodetic(r_rx_e)
    u_e, _ = los_unit_e(r_rx_e, r_sat_e)
    # u_n = C_en^T u_e (C_en broadcasts over a (k,3) receiver array too)
    return np.einsum("...ji,...j->...i", earth.C_en(lat, lon), u_e)


def elevation_azimuth(r_rx_e, r_sat_e):
    """Elevation and azimuth of satellites seen from a receiver.

    Parameters
    ----------
    r_rx_e : array_like, shape (3,) or (k, 3)
        Receiver ECEF position [m].
    r_sat_e : array_like, shape (k, 3)
        Satellite ECEF positions [m] (same frame epoch as the receiver, e.g.
        the output of :func:`insnav.gnss.ephemeris.transmit_states`).

    Returns
    -------
    el, az : ndarray, shape (k,)
        Elevation above the local ellipsoidal horizon [rad] in [-pi/2, pi/2];
        azimuth from north, clockwise (towards east) [rad] in [0, 2 pi).
    """
    u_n = los_unit_n(r_rx_e, r_sat_e)
    el = np.arcsin(np.clip(-u_n[..., 2], -1.0, 1.0))
    az = np.mod(np.arctan2(u_n[..., 1], u_n[..., 0]), 2.0 * np.pi)
    return el, az


def elevation_mask(el, mask_rad=np.deg2rad(10.0)):
    """Boolean mask of satellites at or above ``mask_rad`` [rad] (default 10 deg)."""
    return np.asarray(el) >= mask_rad


class Dop(NamedTuple):
    """Dilution of precision (dimensionless)."""

    gdop: float | np.ndarray
    pdop: float | np.ndarray
    hdop: float | np.ndarray
    vdop: float | np.ndarray
    tdop: float | np.ndarray


def dop_from_los_n(u_n, weights=None) -> Dop:
    """DOP from NED line-of-sight unit vectors.

    The geometry matrix has rows ``[-u_n, 1]`` (position in NED, receiver
    clock in metres); ``Q = (G^T W G)^-1``; GDOP = sqrt(trace Q), PDOP =
    sqrt(Q_NN + Q_EE + Q_DD), HDOP = sqrt(Q_NN + Q_EE), VDOP = sqrt(Q_DD),
    TDOP = sqrt(Q_tt) (Misra & Enge, *Global Positioning System*, 2nd ed.,
    sec. 6.1).

    Parameters
    ----------
    u_n : array_like, shape (..., k, 3)
        Batched sets of k >= 4 unit vectors.
    weights : array_like, shape (..., k), optional

    Returns
    -------
    Dop
        inf where the geometry is singular.
    """
    u_n = np.asarray(u_n, dtype=float)
    G = np.concatenate([-u_n, np.ones(u_n.shape[:-1] + (1,))], axis=-1)
    Gw = G if weights is None else G * np.asarray(weights, dtype=float)[..., None]
    return _dop_from_normal(np.swapaxes(Gw, -1, -2) @ G)


def _dop_from_normal(N) -> Dop:
    """DOP from (batched) 4 x 4 normal matrices N = G^T W G (:func:`dop_from_los_n`)."""
    # singular geometry: condition number >= 1e12.  ||N||_F ||N^-1||_F bounds
    # cond_2(N) within a factor 4 for 4 x 4 and costs one inverse, where
    # np.linalg.cond costs an SVD per matrix (10x the time: select_best_gdop
    # evaluates thousands of subsets per epoch)
    try:
        with np.errstate(all="ignore"):
            Q = np.linalg.inv(N)
            cond = np.sqrt(np.sum(N * N, axis=(-2, -1)) * np.sum(Q * Q, axis=(-2, -1)))
        cond_ok = np.isfinite(cond) & (cond < 1e12)
    except np.linalg.LinAlgError:  # an exactly singular matrix in the batch
        cond_ok = np.linalg.cond(N) < 1e12
    if not np.all(cond_ok):
        Q = np.linalg.inv(np.where(cond_ok[..., None, None], N, np.eye(4)))
    d = np.diagonal(Q, axis1=-2, axis2=-1)
    inf = np.where(cond_ok, 1.0, np.inf)
    gdop = np.sqrt(d.sum(-1)) * inf
    pdop = np.sqrt(d[..., :3].sum(-1)) * inf
    hdop = np.sqrt(d[..., :2].sum(-1)) * inf
    vdop = np.sqrt(d[..., 2]) * inf
    tdop = np.sqrt(d[..., 3]) * inf
    if gdop.ndim == 0:
        return Dop(float(gdop), float(pdop), float(hdop), float(vdop), float(tdop))
    return Dop(gdop, pdop, hdop, vdop, tdop)


def dop(r_rx_e, r_sat_e, weights=None) -> Dop:
    """DOP of satellites ``r_sat_e`` (k, 3) seen from ``r_rx_e`` (3,), positions in ECEF [m]."""
    return dop_from_los_n(los_unit_n(r_rx_e, r_sat_e), weights)


@functools.lru_cache(maxsize=64)
def _combinations(k: int, m: int) -> np.ndarray:
    """All m-subsets of range(k) in lexicographic order, (C(k, m), m), read-only."""
    c = np.array(list(itertools.combinations(range(k), m)), dtype=np.int64).reshape(-1, m)
    c.setflags(write=False)
    return c


def select_best_gdop(u_n, n_select: int, max_combinations: int = 5000):
    """Choose ``n_select`` satellites minimising GDOP.

    Parameters
    ----------
    u_n : array_like, shape (k, 3)
        Line-of-sight unit vectors of the visible satellites (NED or ECEF:
        GDOP is invariant under a rotation of the frame).
    n_select : int
        Number wanted, 4 <= n_select.  If ``n_select >= k`` all are returned.
    max_combinations : int
        Exhaustive search over all ``C(k, n_select)`` subsets (evaluated in
        vectorised batches) when that number is at most ``max_combinations``
        (e.g. C(12, 4) = 495, C(14, 6) = 3003); otherwise a greedy backward
        elimination: start from all k and repeatedly drop the satellite whose
        removal gives the smallest GDOP.  The greedy result is not guaranteed
        optimal but is usually within a few per cent of it and costs
        O(k^2) DOP evaluations.

    Returns
    -------
    idx : ndarray of int, shape (n_select,)
        Sorted indices into ``u_n``.
    gdop : float
        GDOP of the chosen subset.

    Notes
    -----
    Computed by the compiled code (``insnav/gnss/gdop_selection.hpp``) for up
    to ``_core.GDOP_MAX_SATS`` satellites; :func:`_select_best_gdop_numpy` is
    its reference (the same subsets; GDOP to rounding).
    """
    u = np.ascontiguousarray(u_n, dtype=float)
    if n_select < 4:
        raise ValueError("n_select must be >= 4 (3 position + clock)")
    if hasattr(_core, "select_best_gdop") and u.ndim == 2 and u.shape[0] <= _core.GDOP_MAX_SATS:
        idx, g = _core.select_best_gdop(u, int(n_select), int(max_combinations))
        return idx, float(g)
    return _select_best_gdop_numpy(u, n_select, max_combinations)


def _select_best_gdop_numpy(u_n, n_select: int, max_combinations: int = 5000):
    """:func:`select_best_gdop` in numpy (the reference of the compiled code)."""
    u = np.asarray(u_n, dtype=float)
    k = u.shape[0]
    if n_select < 4:
        raise ValueError("n_select must be >= 4 (3 position + clock)")
    if n_select >= k:
        idx = np.arange(k)
        return idx, float(dop_from_los_n(u).gdop)
    if math.comb(k, n_select) <= max_combinations:
        # normal matrices of all subsets from the satellites' outer products
        # g g^T: a sum over the chosen or, when fewer, the full sum minus the
        # left-out ones (C(20, 16) = 4845 subsets: 4 terms each, not 16)
        G = np.concatenate([-u, np.ones((k, 1))], axis=1)
        outer = G[:, :, None] * G[:, None, :]
        if n_select <= k - n_select:
            combos = _combinations(k, n_select)
            N = outer[combos].sum(axis=1)
        else:
            left_out = _combinations(k, k - n_select)[::-1]  # the order of the chosen subsets' combinations
            N = outer.sum(axis=0) - outer[left_out].sum(axis=1)
            combos = None
        g = _dop_from_normal(N).gdop
        j = int(np.argmin(g))
        if combos is None:
            return np.setdiff1d(np.arange(k), left_out[j]), float(g[j])
        return combos[j], float(g[j])
    keep = np.arange(k, dtype=np.int64)
    while keep.size > n_select:
        m = keep.size  # row j of cand: keep without its j-th entry, in order
        cand = np.broadcast_to(keep, (m, m))[~np.eye(m, dtype=bool)].reshape(m, m - 1)
        g = dop_from_los_n(u[cand]).gdop
        j = int(np.argmin(g))
        keep = cand[j]
    idx = np.sort(keep)
    return idx, float(dop_from_los_n(u[idx]).gdop)
