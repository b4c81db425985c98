"""What a float ambiguity solution supports: bootstrapped success rates of partial-AR subsets, the
partially fixed position, and the float conditioned on extra position information.

The RTK engine hands partial AR n float double-differenced ambiguities ``a_hat`` [cycles] with
covariance ``Q_a`` in its priority order (partial AR drops from the end; ``solve_rtk(...,
record_float=True)`` records them, :func:`float_epochs` splits the record).  For a consistent float
covariance the bootstrapped success rate (P. J. G. Teunissen, "Success probability of integer GPS
ambiguity rounding and bootstrapping", J. Geodesy 72 (1998) 606-612, eq. (11)) of the decorrelated
problem (MLAMBDA's Z^T Q_a Z = L^T D L; X.-W. Chang, X. Yang, T. Zhou, J. Geodesy 79 (2005) 552-565)

    P_s = prod_i (2 Phi(1 / (2 sqrt(D_i))) - 1)

is a sharp lower bound of the integer least-squares success rate (Teunissen, J. Geodesy 73 (1999)
587-593): a fix is supportable when P_s of the set fixed reaches the wanted rate, whatever the ratio
test of the data says.  A subset of the first k candidates is fixed by the conditional mean
(Teunissen 1995, "The least-squares ambiguity decorrelation adjustment", J. Geodesy 70, eq. (6))

    b_fix = b_hat - Q_ba Q_a^{-1} (a_hat - a_fix),   Q_b|a = Q_bb - Q_ba Q_a^{-1} Q_ab,

which is cm-precise only when the ambiguities left out do not carry the position.

Extra position information (an oracle bound of an aided float): a measurement ``y = r + e`` of the
float position, ``e ~ N(0, R)`` independent of the float, updates the joint float (b, a) by the
Kalman update (:func:`condition_on_position`).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["bootstrap_success_rate", "bootstrap_estimate", "ordered_success_rate", "partial_success_rates",
           "best_partial_subset", "partial_fix", "condition_on_position", "float_epochs"]


def bootstrap_success_rate(Q_a, variance_factor: float = 1.0) -> float:
    """Bootstrapped success rate of the decorrelated problem of ``Q_a`` (n, n) [cycles^2]
    (Teunissen 1998, eq. (11); the engine's ``Lambda::bootstrap_success_rate``); 1 for n = 0."""
    from .. import _core

    Q = np.asarray(Q_a, float)
    if Q.size == 0:
        return 1.0
    return float(_core.lambda_success_rate(Q, variance_factor))


def bootstrap_estimate(z_hat, Q_z) -> np.ndarray:
    """Integer bootstrapping of ``z_hat`` (n,) or (m, n) (m float vectors) with covariance ``Q_z``
    (n, n), from the last component to the first (the order of MLAMBDA's L^T D L factor): round the
    last, then each earlier one at its conditional mean given the ones already fixed (Teunissen 1998,
    sec. 3), computed from ``Q_z`` by its own conditioning (numpy; independent of the engine's
    factorisation).  Returns the integers, shaped as ``z_hat``."""
    z_hat = np.asarray(z_hat, float)
    Z = np.atleast_2d(z_hat)
    Q = np.asarray(Q_z, float)
    n = Z.shape[1]
    z = np.zeros_like(Z)
    for i in range(n - 1, -1, -1):
        J = np.arange(i + 1, n)
        zc = Z[:, i].copy()
        if J.size:
            zc += (z[:, J] - Z[:, J]) @ np.linalg.solve(Q[np.ix_(J, J)], Q[J, i])
        z[:, i] = np.round(zc)
    return z.reshape(z_hat.shape)


def ordered_success_rate(Q_a) -> np.ndarray:
    """Bootstrapped success rates (k = 1..n) of the first k candidates of ``Q_a`` bootstrapped in the
    given order without decorrelation: prod_{i <= k} (2 Phi(1 / (2 sigma_{i|1..i-1})) - 1), the
    conditional sigmas from the Cholesky factor (Teunissen 1998, eq. (11)).  Each factor is <= 1 and
    does not depend on later candidates, so it cannot rise with k (the decorrelated rate of
    :func:`partial_success_rates` can: a further ambiguity may admit a better decorrelation)."""
    C = np.linalg.cholesky(np.asarray(Q_a, float))
    sig = np.diag(C)
    return np.cumprod([math.erf(1.0 / (2.0 * math.sqrt(2.0) * s)) for s in sig])


def partial_success_rates(Q_a) -> np.ndarray:
    """Bootstrapped success rates (k = 1..n) of the first k candidates of ``Q_a`` (n, n) in the given
    (partial-AR) order, each subset decorrelated on its own as partial AR solves it.  Not monotone in
    k in general: one more ambiguity can admit a better decorrelation of the others."""
    Q = np.asarray(Q_a, float)
    return np.array([bootstrap_success_rate(Q[:k, :k]) for k in range(1, Q.shape[0] + 1)])


def best_partial_subset(Q_a, min_success_rate: float, min_fix: int = 1) -> tuple[int, float]:
    """Largest k >= ``min_fix`` whose first k candidates of ``Q_a`` have a bootstrapped success rate of at
    least ``min_success_rate``, scanned from k = n down as the engine's partial AR drops the last
    candidate; (0, nan) when none.  Returns (k, its success rate)."""
    Q = np.asarray(Q_a, float)
    for k in range(Q.shape[0], max(int(min_fix), 1) - 1, -1):
        ps = bootstrap_success_rate(Q[:k, :k])
        if ps >= min_success_rate:
            return k, ps
    return 0, math.nan


def partial_fix(b_hat, Q_bb, a_hat, Q_a, Q_ab, a_fix):
    """Conditional mean of the float position ``b_hat`` (3,) [m] given the first k = len(a_fix)
    ambiguities fixed to ``a_fix`` (Teunissen 1995, eq. (6)): (b_fix (3,), Q_b|a (3, 3)).
    ``Q_ab`` (n, 3) [cycles m]."""
    k = len(a_fix)
    Qa = np.asarray(Q_a, float)[:k, :k]
    Qab = np.asarray(Q_ab, float)[:k]
    d = np.asarray(a_hat, float)[:k] - np.asarray(a_fix, float)
    b = np.asarray(b_hat, float) - Qab.T @ np.linalg.solve(Qa, d)
    P = np.asarray(Q_bb, float) - Qab.T @ np.linalg.solve(Qa, Qab)
    return b, 0.5 * (P + P.T)


def condition_on_position(b_hat, Q_bb, a_hat, Q_a, Q_ab, y, R):
    """The joint float (b, a) updated with a position measurement ``y = b + e`` (3,) [m],
    ``e ~ N(0, R)`` (R (3, 3) [m^2]) independent of the float (Kalman update, H = [I 0]):
    (b_hat, Q_bb, a_hat, Q_a, Q_ab) after it."""
    Q_bb = np.asarray(Q_bb, float)
    Q_ab = np.asarray(Q_ab, float)
    S = Q_bb + np.asarray(R, float)
    v = np.asarray(y, float) - np.asarray(b_hat, float)
    Kb = np.linalg.solve(S, Q_bb).T      # Q_bb S^-1
    Ka = np.linalg.solve(S, Q_ab.T).T    # Q_ab S^-1
    b = np.asarray(b_hat, float) + Kb @ v
    a = np.asarray(a_hat, float) + Ka @ v
    Pbb = Q_bb - Kb @ Q_bb
    Pa = np.asarray(Q_a, float) - Ka @ Q_ab.T
    Pab = Q_ab - Ka @ Q_bb
    return b, 0.5 * (Pbb + Pbb.T), a, 0.5 * (Pa + Pa.T), Pab


def float_epochs(float_ar: dict):
    """The record of ``solve_rtk(..., record_float=True)`` (``info["float_ar"]``) split per epoch:
    yields dicts with ``epoch``, ``a_hat`` (n,), ``Q_a`` (n, n), ``Q_ab`` (n, 3), ``Q_bb`` (3, 3),
    ``sat_j``, ``sat_i``, ``freq`` (n,)."""
    n = np.asarray(float_ar["n"], np.int64)
    off = np.concatenate([[0], np.cumsum(n)])
    qoff = np.concatenate([[0], np.cumsum(n * n)])
    for e in range(n.size):
        s = slice(off[e], off[e + 1])
        k = int(n[e])
        yield dict(epoch=int(float_ar["epoch"][e]), a_hat=float_ar["a_hat"][s],
                   Q_a=float_ar["Q_a"][qoff[e]:qoff[e + 1]].reshape(k, k), Q_ab=float_ar["Q_ab"][s],
                   Q_bb=float_ar["Q_bb"][e], sat_j=float_ar["sat_j"][s], sat_i=float_ar["sat_i"][s],
                   freq=float_ar["freq"][s])
