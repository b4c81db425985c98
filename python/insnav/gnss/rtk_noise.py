"""Phase and code noise of an RTK run estimated from its fixed epochs (least-squares variance
component estimation).

The RTK engine weights the double differences with the configured zero-difference phase sigma
``sqrt(a^2 + b^2 / sin^2 el)`` (``sigma_phase_a_m``, ``sigma_phase_b_m``) and the code with
``code_phase_ratio`` times it.  A receiver (or a hardware simulator) quieter or noisier than that
gets a filter that weighs the phase wrongly against the code and, in RTK/INS, against the INS
prediction.  This module estimates two variance factors from the data:

    Q_y = k_phi Q_phi + k_P Q_P

with ``Q_phi`` and ``Q_P`` the configured covariances of the phase and code double differences of one
fixed epoch (``insnav.gnss.rtk.RtkSolution.fixed_rows``: the phase rows with the integer ambiguities
of the fix removed, the code rows; ``FixedDdRow`` in ``cpp/include/insnav/gnss/rtk.hpp``), the
functional model ``y = A dr + e`` (A: the 3 baseline columns) per epoch and the epochs independent.
Least-squares variance component estimation (P. J. G. Teunissen, A. R. Amiri-Simkooei,
"Least-squares variance component estimation", J. Geodesy 82 (2008) 65-82, sec. 3 with the weight
matrix W = Q_y^{-1}, the minimum-variance choice for normally distributed data) solves

    N k = l,   N_kl = 1/2 sum_epochs tr(Q_k R Q_l R),   l_k = 1/2 sum_epochs y^T R Q_k R y,
    R = W P_A^perp = W - W A (A^T W A)^{-1} A^T W,

iterated with Q_y at the estimate until it no longer changes; the covariance of k is N^{-1}.  With
one component it is the a-posteriori variance factor of unit weight the engine already uses for
its success-rate test (``RtkEngine::update_noise_factor``).  The redundancy number of row i is
r_i = (Q_v Q_y^{-1})_ii = (P_A^perp)_ii; summed over the phase rows and over the code rows it gives
the degrees of freedom each component is estimated with (Helmert's form k_c = v_c^T W_c v_c / r_c
holds at convergence for block-diagonal components).

The estimate is k_phi (a, b) and k_P code: ``sigma_phase_a_m = sqrt(k_phi) a``, ``sigma_phase_b_m =
sqrt(k_phi) b`` (the configured elevation shape is kept: a and b are not separated) and
``code_phase_ratio = ratio sqrt(k_P / k_phi)``.  Guard rails: the phase sigma is never below
:data:`NOISE_FLOOR_M` (0.1 mm), the code sigma never below :data:`CODE_FLOOR_M` (1 cm), and at least
:data:`MIN_NOISE_EPOCHS` fixed epochs are needed.
What it cannot see: errors correlated over the epochs (multipath) enter a single-epoch residual only
as far as they differ between satellites and are not absorbed by the position; a wrong fix inflates
``k_phi``.
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np

from ._rtk_keys import RTK_DEFAULTS

__all__ = ["NoiseEstimate", "NoiseEstimateError", "estimate_noise", "vce_epoch_matrices", "NOISE_FLOOR_M",
           "MIN_NOISE_EPOCHS", "CODE_FLOOR_M", "noise_options"]

#: Floor of the estimated zero-difference phase sigma max(a, b) [m].  0.1 mm is 1/2000 of the GPS L1
#: cycle, below the thermal noise of any carrier loop at realistic C/N0 (about 0.2-1 mm at 45 dB-Hz,
#: Springer Handbook of GNSS ch. 14) and below the unmodelled millimetre-level effects of the double
#: differences (antenna phase-centre variation, residual troposphere of the height difference): a
#: smaller sigma would let the filters trust the phase beyond what the model describes.  A hardware
#: simulator without carrier noise estimates below it and is held at it.
NOISE_FLOOR_M = 1e-4
#: Floor of the estimated zero-difference code sigma max(a, b) x code_phase_ratio [m].  1 cm is below the
#: thermal noise of any code loop (decimetres for a 1 Hz C/A-code loop at 45 dB-Hz, a few centimetres
#: for the modernised signals' wide-band codes) and ten times the RINEX code resolution (1 mm); a
#: simulator without code noise (the Spirent drive: 0.2 mm) is held there.
CODE_FLOOR_M = 1e-2
#: Fewest fixed epochs (with at least 4 rows) the estimate is computed from.
MIN_NOISE_EPOCHS = 10


class NoiseEstimateError(ValueError):
    """Too few fixed epochs (or double differences) to estimate the noise."""


@dataclass
class NoiseEstimate:
    """Phase and code noise estimated from the fixed epochs of an RTK run.

    Attributes
    ----------
    sigma_phase_a_m, sigma_phase_b_m : float
        Estimated zero-difference phase sigma terms [m] (``RtkOptions`` names), floored.
    code_phase_ratio : float
        Estimated code sigma / phase sigma.
    sigma_phase_a_sd_m, sigma_phase_b_sd_m, code_phase_ratio_sd : float
        Their standard deviations (from N^{-1}, first order).
    factor : (2,) ndarray
        Variance factors (k_phi, k_P) of the configured phase and code covariances.
    factor_cov : (2, 2) ndarray
        Their covariance N^{-1}.
    redundancy_phase, redundancy_code : float
        Sums of the redundancy numbers of the phase and code rows (degrees of freedom).
    n_epochs, n_phase_rows, n_code_rows, iterations : int
    floored, code_floored : bool
        The phase sigma was raised to :data:`NOISE_FLOOR_M`; the code sigma to :data:`CODE_FLOOR_M`.
    sigma_phase_raw_m, sigma_code_raw_m : float
        The estimates before the floors: max(a, b) of the phase and of the code [m].
    configured : dict
        The configured ``sigma_phase_a_m``, ``sigma_phase_b_m``, ``code_phase_ratio``.
    """

    sigma_phase_a_m: float
    sigma_phase_b_m: float
    code_phase_ratio: float
    sigma_phase_a_sd_m: float
    sigma_phase_b_sd_m: float
    code_phase_ratio_sd: float
    factor: np.ndarray
    factor_cov: np.ndarray
    redundancy_phase: float
    redundancy_code: float
    n_epochs: int
    n_phase_rows: int
    n_code_rows: int
    iterations: int
    floored: bool
    configured: dict
    code_floored: bool = False
    sigma_phase_raw_m: float = float("nan")
    sigma_code_raw_m: float = float("nan")

    @property
    def sigma_code_a_m(self) -> float:
        """Estimated zero-difference code sigma term a [m] (ratio x phase a)."""
        return self.code_phase_ratio * self.sigma_phase_a_m

    def options(self, opt):
        """``opt`` (an :class:`~insnav.gnss.rtk.RtkOptions`) with the estimated sigmas and ratio."""
        return dataclasses.replace(opt, sigma_phase_a_m=float(self.sigma_phase_a_m),
                                   sigma_phase_b_m=float(self.sigma_phase_b_m),
                                   code_phase_ratio=float(self.code_phase_ratio), noise="configured").validate()

    def text(self) -> str:
        """One line: the estimate with its sigma."""
        floor = (f" (held at the floor {1e3 * NOISE_FLOOR_M:.1f} mm; estimated max(a, b) "
                 f"{1e3 * self.sigma_phase_raw_m:.4f} mm)") if self.floored else ""
        cfloor = (f" (code held at the floor {1e2 * CODE_FLOOR_M:.0f} cm; estimated {1e3 * self.sigma_code_raw_m:.2f} "
                  "mm)") if self.code_floored else ""
        return (f"phase a {1e3 * self.sigma_phase_a_m:.3f} +- {1e3 * self.sigma_phase_a_sd_m:.3f} mm, "
                f"b {1e3 * self.sigma_phase_b_m:.3f} +- {1e3 * self.sigma_phase_b_sd_m:.3f} mm{floor}, code ratio "
                f"{self.code_phase_ratio:.0f} +- {self.code_phase_ratio_sd:.0f}{cfloor} ({self.n_epochs} fixed "
                f"epochs, redundancy {self.redundancy_phase:.0f} phase / {self.redundancy_code:.0f} code)")


def _epoch_blocks(rows: dict, sel: np.ndarray):
    """Design matrix A (m, 3), y (m,), configured Q_phi and Q_P (m, m) of the rows ``sel`` of one epoch."""
    code = np.asarray(rows["code"])[sel].astype(bool)
    group = np.asarray(rows["group"])[sel]
    own = np.asarray(rows["var_own"], float)[sel]
    ref = np.asarray(rows["var_ref"], float)[sel]
    # rows of one kind and group share the reference satellite: Cov = var_ref off the diagonal
    same = (group[:, None] == group[None, :]) & (code[:, None] == code[None, :])
    Q = np.where(same, ref[:, None], 0.0) + np.diag(own)
    Qphi = np.where(~code[:, None] & ~code[None, :], Q, 0.0)
    QP = np.where(code[:, None] & code[None, :], Q, 0.0)
    return np.asarray(rows["h"], float)[sel], np.asarray(rows["y"], float)[sel], Qphi, QP, code


def vce_epoch_matrices(A, y, Qs, k):
    """LS-VCE normal matrix, right-hand side and redundancy numbers of one epoch (or a stack).

    Parameters
    ----------
    A : (..., m, p) ndarray
        Design matrix.
    y : (..., m) ndarray
        Observations (observed minus computed) [m].
    Qs : sequence of (..., m, m) ndarrays
        Cofactor matrices Q_k of the components [m^2].
    k : (c,) array_like
        Variance factors at which Q_y = sum k_c Q_c (and W = Q_y^{-1}) is taken.

    Returns
    -------
    N : (..., c, c) ndarray
        1/2 tr(Q_k R Q_l R), R = W P_A^perp (Teunissen & Amiri-Simkooei 2008, sec. 3).
    l : (..., c) ndarray
        1/2 y^T R Q_k R y.
    r : (..., m) ndarray
        Redundancy numbers (P_A^perp)_ii = (Q_v Q_y^{-1})_ii.
    """
    Qy = sum(kc * Qc for kc, Qc in zip(k, Qs))
    W = np.linalg.inv(Qy)
    WA = W @ A
    NA = np.swapaxes(A, -1, -2) @ WA
    G = np.linalg.solve(NA, np.swapaxes(WA, -1, -2))  # (A^T W A)^{-1} A^T W
    R = W - WA @ G
    Pperp_diag = 1.0 - np.einsum("...ij,...ji->...i", A, G)
    Ry = np.einsum("...ij,...j->...i", R, y)
    RQ = [R @ Qc for Qc in Qs]
    c = len(Qs)
    N = np.empty(A.shape[:-2] + (c, c))
    l = np.empty(A.shape[:-2] + (c,))
    for a in range(c):
        l[..., a] = 0.5 * np.einsum("...i,...ij,...j->...", Ry, Qs[a], Ry)
        for b in range(a, c):
            N[..., a, b] = N[..., b, a] = 0.5 * np.einsum("...ij,...ji->...", RQ[a], RQ[b])
    return N, l, Pperp_diag


def _check_epochs(n_epochs: int, min_epochs: int):
    if n_epochs < min_epochs:
        raise NoiseEstimateError(f"rtk noise estimate: {n_epochs} fixed epochs with double differences, at least "
                                 f"{min_epochs} needed; the configured sigmas stay")


def _vce_factors_numpy(rows: dict, min_epochs: int, max_iter: int, tol: float):
    """The LS-VCE iteration with the per-epoch sums in numpy (:func:`vce_epoch_matrices`, stacked by
    epoch size): the reference of :func:`_vce_factors_core`.

    Returns
    -------
    k : (c,) ndarray
        Variance factors (k_phi[, k_P]); c = 1 without code rows.
    cov : (c, c) ndarray
        N^{-1} at k.
    red : (n,) ndarray
        Redundancy numbers of the rows at k (NaN in unusable epochs).
    n_epochs, n_phase, n_code, iterations : int
    """
    epoch = rows["epoch"]
    order = np.argsort(epoch, kind="stable")
    ep_sorted = epoch[order]
    starts = np.flatnonzero(np.r_[True, ep_sorted[1:] != ep_sorted[:-1]]) if ep_sorted.size else np.zeros(0, int)
    bounds = np.r_[starts, ep_sorted.size]
    # epochs bucketed by their row pattern size so that one stacked call serves a bucket
    buckets: dict = {}
    n_epochs = 0
    for s, e in zip(bounds[:-1], bounds[1:]):
        sel = order[s:e]
        A, y, Qphi, QP, code = _epoch_blocks(rows, sel)
        if sel.size < 4 or (~code).sum() < 1 or np.linalg.matrix_rank(A) < 3:
            continue
        n_epochs += 1
        buckets.setdefault(sel.size, []).append((sel, A, y, Qphi, QP, code))
    _check_epochs(n_epochs, min_epochs)
    stacks = [(np.stack([b[1] for b in v]), np.stack([b[2] for b in v]), np.stack([b[3] for b in v]),
               np.stack([b[4] for b in v]), v) for v in buckets.values()]
    n_code = sum(int(b[5].sum()) for v in buckets.values() for b in v)
    n_phase = sum(int((~b[5]).sum()) for v in buckets.values() for b in v)
    c = 2 if n_code > 0 else 1
    k = np.ones(c)
    for it in range(1, max_iter + 1):
        N = np.zeros((c, c))
        l = np.zeros(c)
        for A, y, Qphi, QP, _ in stacks:
            Nb, lb, _r = vce_epoch_matrices(A, y, [Qphi, QP][:c], k)
            N += Nb.sum(0)
            l += lb.sum(0)
        k_new = np.linalg.solve(N, l)
        k_new = np.maximum(k_new, 1e-12)  # a variance factor stays positive (sigma >= 1e-6 x configured)
        done = np.all(np.abs(k_new - k) <= tol * np.abs(k_new))
        k = k_new
        if done:
            break
    # precision and redundancy at the estimate
    N = np.zeros((c, c))
    red = np.full(epoch.size, np.nan)
    for A, y, Qphi, QP, v in stacks:
        Nb, _lb, rb = vce_epoch_matrices(A, y, [Qphi, QP][:c], k)
        N += Nb.sum(0)
        for j, b in enumerate(v):
            red[b[0]] = rb[j]
    return k, np.linalg.inv(N), red, n_epochs, n_phase, n_code, it


def _vce_factors_core(rows: dict, min_epochs: int, max_iter: int, tol: float):
    """The LS-VCE iteration with the per-epoch sums in C++ (``_core.rtk_vce_sums``,
    ``cpp/include/insnav/gnss/noise_vce.hpp``: the whitened 3 x 3 form of the same N and l); returns as
    :func:`_vce_factors_numpy`."""
    from .. import _core

    args = (np.ascontiguousarray(rows["epoch"], np.int64), np.ascontiguousarray(rows["code"], np.int32),
            np.ascontiguousarray(rows["group"], np.int32), np.ascontiguousarray(rows["y"], float),
            np.ascontiguousarray(np.reshape(rows["h"], (-1, 3)), float),
            np.ascontiguousarray(rows["var_own"], float), np.ascontiguousarray(rows["var_ref"], float))
    # the first iteration at k = 1 also counts the usable epochs and rows (an absent code block adds 0)
    s = _core.rtk_vce_sums(*args, np.ones(2))
    n_epochs, n_phase, n_code = int(s["n_epochs"]), int(s["n_phase_rows"]), int(s["n_code_rows"])
    _check_epochs(n_epochs, min_epochs)
    c = 2 if n_code > 0 else 1
    k = np.ones(c)
    for it in range(1, max_iter + 1):
        if it > 1:
            s = _core.rtk_vce_sums(*args, np.r_[k, np.ones(2 - c)])
        k_new = np.linalg.solve(s["N"][:c, :c], s["l"][:c])
        k_new = np.maximum(k_new, 1e-12)  # a variance factor stays positive (sigma >= 1e-6 x configured)
        done = np.all(np.abs(k_new - k) <= tol * np.abs(k_new))
        k = k_new
        if done:
            break
    # precision and redundancy at the estimate
    s = _core.rtk_vce_sums(*args, np.r_[k, np.ones(2 - c)], redundancy=True)
    return k, np.linalg.inv(s["N"][:c, :c]), s["redundancy"], n_epochs, n_phase, n_code, it


def estimate_noise(rows: dict, options=None, *, min_epochs: int = MIN_NOISE_EPOCHS, floor_m: float = NOISE_FLOOR_M,
                   code_floor_m: float = CODE_FLOOR_M, max_iter: int = 50, tol: float = 1e-12,
                   return_redundancy: bool = False, _accumulate: str = "core"):
    """Phase and code variance factors of the fixed epochs' double differences (LS-VCE).

    Parameters
    ----------
    rows : dict
        The fixed epochs' rows (``RtkSolution.fixed_rows``: ``epoch``, ``code``, ``group``, ``y`` [m],
        ``h`` (k, 3), ``var_own``, ``var_ref`` [m^2]).
    options : RtkOptions, optional
        The configuration the rows were recorded with (its sigmas are scaled); default: the ``[rtk]``
        defaults.  :func:`insnav.gnss.rtk.estimate_noise` also takes a ``[rtk]`` table (dict).
    min_epochs : int
        Fewest usable fixed epochs; fewer raise :class:`NoiseEstimateError`.
    floor_m : float
        Floor of the estimated phase sigma max(a, b) [m].
    code_floor_m : float
        Floor of the estimated code sigma max(a, b) x ratio [m].
    max_iter, tol : int, float
        Iterations of Q_y at the estimate and their relative tolerance on k.
    return_redundancy : bool
        Also return the redundancy number of every row (NaN for rows of unusable epochs).
    _accumulate : {"core", "numpy"}
        Where the per-epoch sums are computed: C++ (``_core.rtk_vce_sums``) or the numpy reference
        (:func:`vce_epoch_matrices`; private, for the tests).

    Returns
    -------
    NoiseEstimate (and the (k,) redundancy numbers)
    """
    # the three settings the rows were weighted with (no import of insnav.gnss.rtk, which imports this module)
    a0, b0, ratio0 = ((options.sigma_phase_a_m, options.sigma_phase_b_m, options.code_phase_ratio)
                      if options is not None else
                      tuple(RTK_DEFAULTS[k] for k in ("sigma_phase_a_m", "sigma_phase_b_m", "code_phase_ratio")))
    rows = {key: np.asarray(rows[key]) for key in ("epoch", "code", "group", "y", "h", "var_own", "var_ref")}
    factors = _vce_factors_numpy if _accumulate == "numpy" else _vce_factors_core
    k, cov, red, n_epochs, n_phase, n_code, it = factors(rows, min_epochs, max_iter, tol)
    c = k.size
    code_rows = np.asarray(rows["code"]).astype(bool)
    r_phase = float(np.nansum(np.where(code_rows, np.nan, red)))
    r_code = float(np.nansum(np.where(code_rows, red, np.nan)))
    m0 = max(a0, b0)
    s_phi = math.sqrt(k[0])
    sd_s = math.sqrt(max(cov[0, 0], 0.0)) / (2.0 * s_phi)  # d sqrt(k) = dk / (2 sqrt(k))
    raw_phase = m0 * s_phi
    floored = raw_phase < floor_m
    if floored:
        s_phi = floor_m / m0
    code_floored = False
    raw_code = float("nan")
    if c == 2:
        s_P = math.sqrt(k[1])
        raw_code = m0 * ratio0 * s_P
        code_floored = raw_code < code_floor_m
        if code_floored:
            s_P = code_floor_m / (m0 * ratio0)
        ratio = ratio0 * s_P / s_phi
        # ratio = ratio0 sqrt(k_P / k_phi): gradient (-ratio / (2 k_phi), ratio / (2 k_P)); a floored factor
        # is a constant
        g = np.array([0.0 if floored else -ratio / (2.0 * k[0]), 0.0 if code_floored else ratio / (2.0 * k[1])])
        ratio_sd = math.sqrt(max(float(g @ cov @ g), 0.0))
    else:
        ratio, ratio_sd = ratio0, float("nan")
    ratio_c = float(np.clip(ratio, 1.0, 1e4))  # the range RtkOptions accepts
    return_est = NoiseEstimate(
        sigma_phase_a_m=a0 * s_phi, sigma_phase_b_m=b0 * s_phi, code_phase_ratio=ratio_c,
        sigma_phase_a_sd_m=a0 * sd_s, sigma_phase_b_sd_m=b0 * sd_s, code_phase_ratio_sd=ratio_sd,
        factor=k if c == 2 else np.array([k[0], np.nan]), factor_cov=cov, redundancy_phase=r_phase,
        redundancy_code=r_code, n_epochs=n_epochs, n_phase_rows=n_phase, n_code_rows=n_code, iterations=it,
        floored=bool(floored), configured=dict(sigma_phase_a_m=a0, sigma_phase_b_m=b0, code_phase_ratio=ratio0),
        code_floored=bool(code_floored), sigma_phase_raw_m=raw_phase, sigma_code_raw_m=raw_code)
    return (return_est, red) if return_redundancy else return_est


def noise_options(opt, rows: dict):
    """The options a run with ``noise = "estimate"`` continues with: ``opt`` with the sigmas estimated from
    ``rows`` (a first GNSS-only pass), or, with too few fixed epochs, ``opt`` itself and a warning.

    Returns
    -------
    (RtkOptions, NoiseEstimate or None)
    """
    try:
        est = estimate_noise(rows, opt)
    except NoiseEstimateError as exc:
        warnings.warn(str(exc), RuntimeWarning, stacklevel=3)
        return dataclasses.replace(opt, noise="configured"), None
    return est.options(opt), est
