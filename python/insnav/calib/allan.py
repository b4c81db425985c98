"""Allan-variance identification of IMU noise (IEEE Std 952-1997, Annex C).

Overlapping Allan deviation per axis (computed in C++, ``calib/allan.hpp``),
a weighted least-squares fit of the five IEEE 952 noise terms, confidence
intervals from the equivalent degrees of freedom, and the filter's ``[imu]``
noise keys derived from the fit.

Model (IEEE Std 952-1997, Annex C, eqs. (C.8)-(C.16), Table C.1; El-Sheimy,
Hou & Niu 2008, "Analysis and modeling of inertial sensors using Allan
variance", IEEE Trans. Instrum. Meas. 57(1), eqs. (11)-(18)): the Allan
variance of a rate is the sum of

=====  =========================  =================================  =======  ======================
term   noise                      sigma^2(tau)                       slope    SI unit (gyro / accel)
=====  =========================  =================================  =======  ======================
Q      quantisation (angle /      3 Q^2 / tau^2                      -1       rad / (m/s)
       velocity white noise)
N      angle / velocity random    N^2 / tau                          -1/2     rad/sqrt(s) / (m/s)/sqrt(s)
       walk (rate white noise)
B      bias instability (flicker  (2 ln 2 / pi) B^2 (= (0.664 B)^2)  0        rad/s / m/s^2
       rate noise)
K      rate random walk           K^2 tau / 3                        +1/2     rad/s/sqrt(s) / m/s^2/sqrt(s)
R      rate ramp (drift)          R^2 tau^2 / 2                      +1       rad/s^2 / m/s^3
=====  =========================  =================================  =======  ======================

(slopes of the Allan *deviation* on log-log axes).  The fit is the standard
least-squares fit of sigma^2(tau) = sum_k C_k tau^k, k = -2..2 (IEEE Std 952
Annex C, sec. C.2; El-Sheimy et al. 2008, eq. (19)), weighted by the inverse
variance of each Allan-variance estimate, 2 sigma^4 / edf (chi-square with
``edf`` equivalent degrees of freedom, NIST SP 1065 sec. 5.2.3 and Table 5),
the weights computed from the fitted curve and iterated (iteratively
reweighted; weights from the noisy estimates themselves would bias the fit
low), every C_k >= 0 (the best of the 31 subsets of terms).  Not the tangent
method: the tangents read each term at one tau and are biased where two terms
overlap, which the sum fits.

Confidence intervals: each fitted C_k is taken as a chi-square variable
with nu equivalent degrees of freedom and the interval of the coefficient is
sqrt(nu C_k / chi2_{1-a/2,nu}) .. sqrt(nu C_k / chi2_{a/2,nu}).  nu is the
smaller of the least-squares value (Satterthwaite, nu = 2 C_k^2 / var(C_k))
and the value of the single averaging time that tells most about the term,
max_i edf_i s_i^2 (s_i the term's share of the fitted variance at tau_i; the
edf from the number of clusters, NIST SP 1065 Table 5): the least-squares
variance treats the overlapping, strongly correlated estimates at
neighbouring tau as independent and its 95 % intervals held the rate random
walk of 20 simulated logs 12 times, the single-tau value 19 times
(docs/results/allan.md counts the coverage over all terms and grades).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ..units import DEG, DEG_PER_H, DEG_PER_SQRT_H, HOUR, MG, MPS_PER_SQRT_H

__all__ = ["AllanCurve", "AllanFit", "TERMS", "allan_deviation", "fit_allan", "edf_oadev", "chi2_ppf",
           "simulate_ieee952", "gauss_markov_from_fit", "imu_noise_toml", "check_static", "check_sampling",
           "STATIC_THRESHOLD_MPS2", "GM_PEAK"]

#: the IEEE 952 terms: name -> (power of tau in sigma^2, factor c with sigma^2 = c coef^2 tau^power)
TERMS: dict[str, tuple[int, float]] = {
    "Q": (-2, 3.0),
    "N": (-1, 1.0),
    "B": (0, 2.0 * math.log(2.0) / math.pi),
    "K": (1, 1.0 / 3.0),
    "R": (2, 0.5),
}
#: Allan-deviation slope of each term on log-log axes (IEEE Std 952, Table C.1)
SLOPES = {"Q": -1.0, "N": -0.5, "B": 0.0, "K": 0.5, "R": 1.0}
#: noise-type exponent alpha of the rate PSD f^alpha that each term is (for the edf, NIST SP 1065 Table 5)
_ALPHA = {"Q": 2, "N": 0, "B": -1, "K": -2, "R": -2}


# --------------------------------------------------------------------------- the curve

@dataclass
class AllanCurve:
    """Overlapping Allan deviation of several axes.

    Attributes
    ----------
    tau_s : (n_tau,) averaging time [s]
    adev : (n_tau, n_axes) Allan deviation, in the rate unit of the input
    m : (n_tau,) cluster sizes (tau = m tau0)
    terms : (n_tau,) number of second differences summed (n + 1 - 2m)
    tau0_s : sample interval [s]
    n : samples per axis
    axes : names of the axes
    """

    tau_s: np.ndarray
    adev: np.ndarray
    m: np.ndarray
    terms: np.ndarray
    tau0_s: float
    n: int
    axes: tuple = ()

    @property
    def clusters(self) -> np.ndarray:
        """(n_tau,) number of independent (non-overlapping) clusters, floor(n / m)."""
        return self.n // self.m

    def edf(self, alpha: int = 0) -> np.ndarray:
        """(n_tau,) equivalent degrees of freedom for the noise type ``alpha``."""
        return edf_oadev(self.n + 1, self.m, alpha)


def allan_deviation(rates, tau0_s: float, *, per_octave: int = 1, max_m: int | None = None, axes=(),
                    threads: int = 0) -> AllanCurve:
    """Overlapping Allan deviation of rate series sampled every ``tau0_s``.

    Parameters
    ----------
    rates : array (n,) or (n, k), or a sequence of them (same n)
        Rate samples (angular rate [rad/s], specific force [m/s^2], any unit):
        increments divided by ``tau0_s``.  Not copied (any strides).
    tau0_s : float
        Sample interval [s].
    per_octave : int
        Cluster sizes per octave: 1 gives m = 1, 2, 4, ...; 4 or 8 a denser curve.
    max_m : int, optional
        Largest cluster size (default n / 2).
    axes : sequence of str
        Names of the columns (for tables and plots).
    threads : int
        Threads for the axes (<= 0: all cores).

    Returns
    -------
    AllanCurve
        The same numbers as ``allantools.oadev(y, rate=1/tau0_s,
        data_type="freq", taus=m * tau0_s)`` (Riley, NIST SP 1065, eq. (11)).
    """
    from .. import _core

    seq = [rates] if isinstance(rates, np.ndarray) else list(rates)
    seq = [np.asarray(a, dtype=float) for a in seq]
    n = int(seq[0].shape[0])
    if not (tau0_s > 0 and math.isfinite(tau0_s)):
        raise ValueError(f"tau0_s must be a positive number of seconds, got {tau0_s!r}")
    if n < 4:
        raise ValueError(f"an Allan deviation needs at least 4 samples, got {n}")
    m = _core.allan_cluster_sizes(n, per_octave, -1 if max_m is None else int(max_m))
    avar, terms, bad, bad_axis = _core.overlapping_avar(seq, m, threads)
    if bad >= 0:
        raise ValueError(f"non-finite rate sample at row {bad} (axes from {bad_axis})")
    return AllanCurve(m * tau0_s, np.sqrt(avar), m, terms, float(tau0_s), n, tuple(axes))


# --------------------------------------------------------------------------- statistics

def edf_oadev(N, m, alpha: int) -> np.ndarray:
    """Equivalent degrees of freedom of the overlapping Allan variance.

    Simple approximations of NIST SP 1065 (Riley 2008), Table 5 (Howe, Allan
    & Barnes 1981), for ``N`` phase points (n + 1 rate samples) and cluster
    size ``m``; ``alpha`` the exponent of the rate PSD f^alpha (2: white
    phase = quantisation, 0: white rate = ARW/VRW, -1: flicker rate = bias
    instability, -2: random-walk rate).  At least 1.
    """
    N = float(N)
    m = np.asarray(m, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        if alpha == 2:
            e = (N + 1) * (N - 2 * m) / (2 * (N - m))
        elif alpha == 1:
            e = np.exp(np.sqrt(np.log((N - 1) / (2 * m)) * np.log((2 * m + 1) * (N - 1) / 4)))
        elif alpha == 0:
            e = (3 * (N - 1) / (2 * m) - 2 * (N - 2) / N) * 4 * m ** 2 / (4 * m ** 2 + 5)
        elif alpha == -1:
            e = np.where(m == 1, 2 * (N - 2) / (2.3 * N - 4.9), 5 * N ** 2 / (4 * m * (N + 3 * m)))
        elif alpha == -2:
            e = (N - 2) / m * ((N - 1) ** 2 - 3 * m * (N - 1) + 4 * m ** 2) / (N - 3) ** 2
        else:
            raise ValueError(f"alpha must be one of 2, 1, 0, -1, -2, got {alpha!r}")
    return np.maximum(np.nan_to_num(e, nan=1.0), 1.0)


def _gammainc_lower(a: float, x: float) -> float:
    """Regularised lower incomplete gamma P(a, x) (series / Lentz continued
    fraction; Press et al., Numerical Recipes, 3rd ed., sec. 6.2)."""
    if x <= 0.0:
        return 0.0
    lg = math.lgamma(a)
    if x < a + 1.0:
        term = total = 1.0 / a
        ap = a
        for _ in range(10000):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * 1e-15:
                break
        return total * math.exp(-x + a * math.log(x) - lg)
    tiny = 1e-300
    b = x + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 10000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-15:
            break
    return 1.0 - math.exp(-x + a * math.log(x) - lg) * h


def chi2_ppf(p: float, nu: float) -> float:
    """Quantile of the chi-square distribution with ``nu`` (> 0, real) degrees
    of freedom: P(chi2_nu <= x) = p (bisection on the incomplete gamma
    function, started from the Wilson-Hilferty approximation)."""
    if not (0.0 < p < 1.0) or not nu > 0:
        raise ValueError(f"chi2_ppf: need 0 < p < 1 and nu > 0, got p={p!r}, nu={nu!r}")
    if nu > 1e7:  # normal limit
        z = math.sqrt(2.0) * _erfinv(2.0 * p - 1.0)
        return nu + z * math.sqrt(2.0 * nu)
    z = math.sqrt(2.0) * _erfinv(2.0 * p - 1.0)
    guess = max(nu * (1.0 - 2.0 / (9.0 * nu) + z * math.sqrt(2.0 / (9.0 * nu))) ** 3, 1e-300)
    lo, hi = guess, guess
    while _gammainc_lower(nu / 2.0, lo / 2.0) > p and lo > 1e-300:
        lo *= 0.5
    while _gammainc_lower(nu / 2.0, hi / 2.0) < p:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _gammainc_lower(nu / 2.0, mid / 2.0) < p:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-13 * hi:
            break
    return 0.5 * (lo + hi)


def _erfinv(y: float) -> float:
    """Inverse error function (Giles 2012 single-precision start, two Newton steps)."""
    w = -math.log((1.0 - y) * (1.0 + y))
    if w < 5.0:
        w -= 2.5
        p = 2.81022636e-08
        for c in (3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087, -0.00125372503,
                  -0.00417768164, 0.246640727, 1.50140941):
            p = c + p * w
    else:
        w = math.sqrt(w) - 3.0
        p = -0.000200214257
        for c in (0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773, -0.0076224613,
                  0.00943887047, 1.00167406, 2.83297682):
            p = c + p * w
    x = p * y
    for _ in range(2):
        x -= (math.erf(x) - y) / (2.0 / math.sqrt(math.pi) * math.exp(-x * x))
    return x


# --------------------------------------------------------------------------- the fit

@dataclass
class AllanFit:
    """IEEE 952 terms of one axis, SI (see the module table).

    Attributes
    ----------
    coef : dict name -> value [SI] (0: not resolved by the data, see ``upper``)
    ci : dict name -> (low, high) confidence interval [SI] (NaN when not resolved)
    nu : dict name -> equivalent degrees of freedom of the term
    tau_s, avar_fit : the tau used and the fitted Allan variance there
    tau_min_s : tau of the smallest fitted Allan deviation (the bias-instability point)
    confidence : level of ``ci``
    """

    coef: dict
    ci: dict
    nu: dict
    tau_s: np.ndarray
    avar_fit: np.ndarray
    tau_min_s: float
    confidence: float = 0.95
    axis: str = ""
    #: name -> one-sided upper bound [SI] of a term removed as not resolved
    upper: dict = field(default_factory=dict)
    #: the fitted Allan deviation has its minimum inside the log's averaging times (not at the
    #: longest one: there the curve still falls, and tau_min is the log's length, not the data's)
    tau_min_inside: bool = True

    def adev_model(self, tau_s) -> np.ndarray:
        """The fitted Allan deviation at ``tau_s`` [rate unit]."""
        tau = np.asarray(tau_s, dtype=float)
        return np.sqrt(sum(c * self.coef[k] ** 2 * tau ** p for k, (p, c) in TERMS.items()))


def _nnls_subsets(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """min |A x - b| with x >= 0 for a few columns: the best unconstrained
    least-squares solution among the column subsets that is non-negative."""
    k = A.shape[1]
    best, best_r = np.zeros(k), float(b @ b)
    for r in range(1, k + 1):
        for cols in itertools.combinations(range(k), r):
            sub = A[:, cols]
            x, *_ = np.linalg.lstsq(sub, b, rcond=None)
            if np.all(x >= 0):
                res = b - sub @ x
                rr = float(res @ res)
                if rr < best_r * (1 - 1e-12):
                    best_r = rr
                    best = np.zeros(k)
                    best[list(cols)] = x
    return best


def _wls(tau, avar, m, n: int, names: list, iterations: int):
    """Iteratively reweighted non-negative least squares of sigma^2(tau) =
    sum C_k tau^p_k over the terms ``names``: (C, covariance of C (NaN rows
    for C_k = 0), fitted variance)."""
    A = np.column_stack([tau ** TERMS[k][0] for k in names])
    model = avar.copy()
    edf = edf_oadev(n + 1, m, 0)
    C = np.zeros(len(names))
    for _ in range(iterations):
        sd = model * np.sqrt(2.0 / edf)  # sd of each Allan-variance estimate
        Aw, bw = A / sd[:, None], avar / sd
        scale = np.linalg.norm(Aw, axis=0)
        scale[scale == 0] = 1.0
        C_new = _nnls_subsets(Aw / scale, bw) / scale
        model = np.maximum(A @ C_new, 1e-6 * avar)
        # edf of the noise type that dominates the fitted curve at each tau
        dom = np.argmax(A * C_new, axis=1)
        edf = np.array([float(edf_oadev(n + 1, mi, _ALPHA[names[d]])) for mi, d in zip(m, dom)])
        done = np.allclose(C_new, C, rtol=1e-10, atol=0)
        C = C_new
        if done:
            break
    sd = model * np.sqrt(2.0 / edf)
    cov = np.full((len(names), len(names)), np.nan)
    active = [i for i in range(len(names)) if C[i] > 0]
    if active:
        Aw = A[:, active] / sd[:, None]
        scale = np.linalg.norm(Aw, axis=0)
        try:
            cov_a = np.linalg.inv((Aw / scale).T @ (Aw / scale)) / np.outer(scale, scale)
            cov[np.ix_(active, active)] = cov_a
        except np.linalg.LinAlgError:
            pass
    # equivalent dof of each coefficient read at its single most informative tau: nu = max_i edf_i s_i^2, s_i
    # the term's share of the fitted variance there (var(C) / C^2 = 2 / (edf_i s_i^2) from that tau alone)
    share = (A * C) / np.maximum(A @ C, 1e-300)[:, None]
    nu_single = np.max(edf[:, None] * share ** 2, axis=0)
    return C, cov, A @ C, nu_single


def fit_allan(curve: AllanCurve, axis: int = 0, *, terms=tuple(TERMS), confidence: float = 0.95,
              iterations: int = 8) -> AllanFit:
    """Fit the IEEE 952 terms to one axis of an Allan curve.

    Weighted least squares on the Allan *variance*, sigma^2(tau) =
    sum_k C_k tau^k (IEEE Std 952-1997 Annex C; El-Sheimy et al. 2008,
    eq. (19)), C_k >= 0, weights edf / (2 model^2) iterated from the fitted
    curve, the edf of each tau for the noise type that dominates the fitted
    curve there (NIST SP 1065, Table 5).  A term the data do not resolve
    (C_k below twice its standard deviation) is removed, the least
    significant first, and the rest refitted; its coefficient is then 0 and
    ``upper`` holds its one-sided bound sqrt((C_k + 2 sd_k) / c).  See the
    module docstring for the confidence intervals.

    Parameters
    ----------
    curve : AllanCurve
    axis : int
        Column of ``curve.adev``.
    terms : sequence of str
        The terms to fit (default all five: Q, N, B, K, R).
    confidence : float
        Level of the intervals.

    Returns
    -------
    AllanFit
    """
    unknown = set(terms) - set(TERMS)
    if unknown:
        raise ValueError(f"unknown Allan term(s) {sorted(unknown)}; known: {', '.join(TERMS)}")
    names = [t for t in TERMS if t in terms]
    avar = curve.adev[:, axis] ** 2
    ok = np.isfinite(avar) & (avar > 0)
    tau, avar, m = curve.tau_s[ok], avar[ok], curve.m[ok]
    if tau.size < 2:
        raise ValueError("Allan fit: fewer than 2 usable averaging times")
    upper = {}
    while True:
        C, cov, fitted, nu_single = _wls(tau, avar, m, curve.n, names, iterations)
        sd = np.sqrt(np.abs(np.diag(cov)))
        # significance C / sd: 0 for a term the non-negative fit set to zero
        z = np.where(C > 0, C / np.where(np.isfinite(sd) & (sd > 0), sd, np.inf), 0.0)
        z = np.where((C > 0) & ~(np.isfinite(sd) & (sd > 0)), np.inf, z)
        weak = [i for i in range(len(names)) if z[i] < 2.0]
        if not weak or len(names) == 1:
            break
        i = min(weak, key=lambda j: z[j])
        k = names[i]
        bound = C[i] + 2.0 * sd[i] if np.isfinite(sd[i]) else math.nan
        upper[k] = math.sqrt(bound / TERMS[k][1]) if bound > 0 else math.nan
        names.pop(i)
    coef, ci, nu = {}, {}, {}
    lo_p, hi_p = (1 - confidence) / 2, 1 - (1 - confidence) / 2
    for k in TERMS:
        coef[k], ci[k], nu[k] = 0.0, (math.nan, math.nan), math.nan
        if k not in names:
            continue
        j = names.index(k)
        c_fac = TERMS[k][1]
        coef[k] = math.sqrt(C[j] / c_fac) if C[j] > 0 else 0.0
        var = cov[j, j]
        if C[j] > 0 and np.isfinite(var) and var > 0:
            # the least-squares dof counts the correlated neighbouring taus as independent (coverage
            # 60 % for 95 % intervals in tests); the single most informative tau does not (95 %)
            v = min(2.0 * C[j] ** 2 / var, max(nu_single[j], 1e-3), 1e12)
            nu[k] = v
            ci[k] = (math.sqrt(v * C[j] / chi2_ppf(hi_p, v) / c_fac), math.sqrt(v * C[j] / chi2_ppf(lo_p, v) / c_fac))
    fit = AllanFit(coef, ci, nu, tau, fitted, math.nan, confidence,
                   curve.axes[axis] if axis < len(curve.axes) else str(axis), upper)
    fine = np.geomspace(curve.tau_s[0], curve.tau_s[-1], 400)
    i_min = int(np.argmin(fit.adev_model(fine)))
    fit.tau_min_s = float(fine[i_min])
    fit.tau_min_inside = 0 < i_min < fine.size - 1
    return fit


# --------------------------------------------------------------------------- Gauss-Markov model for the filter

def _gm_avar_shape(x):
    """sigma^2(tau) / (2 sigma_GM^2) of a first-order Gauss-Markov rate of
    steady-state sigma_GM and correlation time T, x = tau / T (IEEE Std 952,
    eq. (C.21) with q_c^2 = 2 sigma_GM^2 / T)."""
    x = np.asarray(x, dtype=float)
    return (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x)) / x


def _gm_peak():
    x = np.geomspace(0.3, 10.0, 20001)
    f = _gm_avar_shape(x)
    i = int(np.argmax(f))
    return float(x[i]), float(np.sqrt(2.0 * f[i]))


#: (tau / T at the peak, peak Allan deviation / sigma_GM) of a first-order Gauss-Markov process: (1.89, 0.618)
GM_PEAK = _gm_peak()


def gauss_markov_from_fit(fit: AllanFit) -> tuple[float, float]:
    """First-order Gauss-Markov (sigma_GM [SI rate], T [s]) standing for the
    bias instability in the filter: the process whose Allan-deviation peak
    (0.618 sigma_GM at tau = 1.89 T) equals the flicker floor 0.664 B at the
    bias-instability point tau_min of the fit.  (0, inf) when B is not resolved, or when the
    fitted curve has no minimum inside the log (still falling at the longest averaging time:
    tau_min, and so T, would be set by the log's length, not by the data).
    """
    B = fit.coef["B"]
    if not B > 0 or not fit.tau_min_inside:
        return 0.0, math.inf
    x_peak, peak = GM_PEAK
    return math.sqrt(TERMS["B"][1]) * B / peak, fit.tau_min_s / x_peak


# --------------------------------------------------------------------------- config snippet

def imu_noise_toml(gyro: list[AllanFit], accel: list[AllanFit], source: str = "") -> str:
    """The ``[imu]`` noise table of an insnav run configuration from the fits
    of the three gyro and three accelerometer axes (docs/algorithms.md, "From
    the Allan terms to the filter's process noise").

    ARW/VRW -> ``gyro_arw_deg_per_sqrt_h``/``acc_vrw_m_per_s_per_sqrt_h``;
    bias instability -> a first-order Gauss-Markov bias
    (``*_bias_sigma_*``, ``*_bias_tau_s``, :func:`gauss_markov_from_fit`);
    rate random walk -> ``gyro_bias_rw_deg_per_h_per_sqrt_h`` /
    ``acc_bias_rw_mg_per_sqrt_h``.  Quantisation and rate ramp have no filter
    state; they appear as comments.  Per-axis values are written as lists.
    """
    from .._toml import toml_value

    def fmt(vals):
        vals = [float(f"{v:.4g}") for v in vals]
        return toml_value(vals)

    lines = [f"# IMU noise identified by insnav allan{' from ' + source if source else ''}",
             "# (IEEE Std 952 Allan-variance fit; x, y, z axes).  The turn-on bias (run to run) is not visible",
             "# in one static log: *_bias_sigma_* is the in-run Gauss-Markov sigma and is also the filter's",
             "# initial bias sigma unless init_sigma_*_bias_* is given (give it from the data sheet).",
             "[imu]"]
    gm_g = [gauss_markov_from_fit(f) for f in gyro]
    gm_a = [gauss_markov_from_fit(f) for f in accel]
    for name, fits, key, unit in (("gyro", gyro, "gyro_arw_deg_per_sqrt_h", DEG_PER_SQRT_H),
                                  ("accel", accel, "acc_vrw_m_per_s_per_sqrt_h", MPS_PER_SQRT_H)):
        # an unresolved white noise (the fit put the short-tau noise in quantisation, or the log is a few
        # samples long) is not written as 0, which would give the filter no white process noise on that
        # axis: its upper bound is, else the Allan deviation of the shortest tau times sqrt(tau) (all of
        # the noise there taken as white, also an upper bound)
        vals, bounded = [], []
        for f in fits:
            v = f.coef["N"]
            if not v > 0:
                v = f.upper.get("N", math.nan)
                if not (math.isfinite(v) and v > 0):
                    v = float(np.sqrt(f.avar_fit[0] * f.tau_s[0]))
                bounded.append(f.axis)
            vals.append(v)
        lines.append(f"{key} = {fmt([v / unit for v in vals])}")
        if bounded:
            lines.append(f"# {name} {', '.join(bounded)}: white noise not resolved by the fit: its upper bound written")
    for name, gm, key_s, unit, key_t in (("gyro", gm_g, "gyro_bias_sigma_deg_per_h", DEG_PER_H, "gyro_bias_tau_s"),
                                         ("accel", gm_a, "acc_bias_sigma_mg", MG, "acc_bias_tau_s")):
        if all(s > 0 for s, _ in gm):
            lines.append(f"{key_s} = {fmt([s / unit for s, _ in gm])}")
            lines.append(f"{key_t} = {fmt([t for _, t in gm])}")
        else:
            lines.append(f"# {name}: bias instability not resolved on every axis (log too short: no Allan-deviation "
                         f"minimum inside it, or masked by the random walks): {key_s} / {key_t} left to the "
                         "defaults (--format csv has none: give them from the data sheet)")
    lines.append(f"gyro_bias_rw_deg_per_h_per_sqrt_h = {fmt([f.coef['K'] / (DEG_PER_H / 60.0) for f in gyro])}")
    lines.append(f"acc_bias_rw_mg_per_sqrt_h = {fmt([f.coef['K'] / (MG / 60.0) for f in accel])}")
    q_g = [f.coef["Q"] for f in gyro]
    q_a = [f.coef["Q"] for f in accel]
    r_g = [f.coef["R"] for f in gyro]
    r_a = [f.coef["R"] for f in accel]
    lines.append(f"# not filter states: quantisation gyro {fmt([q / DEG * 3600 for q in q_g])} arcsec, "
                 f"accel {fmt(q_a)} m/s; rate ramp gyro {fmt([r / DEG_PER_H * HOUR for r in r_g])} deg/h/h, "
                 f"accel {fmt([r / MG * HOUR for r in r_a])} mg/h")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- input checks

#: rms of successive 1 s specific-force means (per axis, / sqrt 2) above which a log is not static [m/s^2]:
#: 0.05 m/s^2 = 5 mg, six times the white-noise level of a consumer MEMS (0.5 m/s/sqrt(h) -> 0.008 m/s^2 in 1 s)
STATIC_THRESHOLD_MPS2 = 0.05


def check_static(f_ib_b: np.ndarray, tau0_s: float, threshold_mps2: float = STATIC_THRESHOLD_MPS2) -> dict:
    """Is the IMU at rest?  The specific force averaged over 1 s windows, the
    rms of the differences of successive windows / sqrt(2) per axis (white
    sensor noise averages down to VRW / sqrt(1 s), slow thermal drift cancels;
    motion, vibration and tilting do not).

    Returns
    -------
    dict
        ``stat_mps2`` (largest axis), ``axis``, ``static`` (stat below the
        threshold), ``worst_t_s`` (start of the window with the largest jump,
        from the first sample), ``threshold_mps2``.
    """
    w = max(1, int(round(1.0 / tau0_s)))
    f = np.asarray(f_ib_b, dtype=float)
    nw = f.shape[0] // w
    if nw < 3:
        return dict(stat_mps2=0.0, axis=0, static=True, worst_t_s=0.0, threshold_mps2=threshold_mps2)
    means = f[: nw * w].reshape(nw, w, -1).mean(axis=1)
    d = np.diff(means, axis=0) / math.sqrt(2.0)
    rms = np.sqrt(np.mean(d * d, axis=0))
    ax = int(np.argmax(rms))
    worst = int(np.argmax(np.max(np.abs(d), axis=1)))
    return dict(stat_mps2=float(rms[ax]), axis=ax, static=bool(rms[ax] <= threshold_mps2),
                worst_t_s=float(worst * w * tau0_s), threshold_mps2=threshold_mps2)


def check_sampling(t_s: np.ndarray, gap_factor: float = 1.5, jitter_max: float = 0.01) -> dict:
    """Uniform sampling?  ``gaps``: indices i with t[i+1] - t[i] > gap_factor
    x the median interval (or <= 0: repeated/decreasing times); ``jitter``:
    the rms relative deviation of the other intervals from the median.

    Returns a dict with ``tau0_s`` (median interval), ``gaps`` (indices),
    ``jitter`` and ``uniform`` (no gap and jitter <= jitter_max)."""
    t = np.asarray(t_s, dtype=float)
    dt = np.diff(t)
    tau0 = float(np.median(dt)) if dt.size else math.nan
    bad = np.flatnonzero((dt > gap_factor * tau0) | (dt <= 0.5 * tau0))
    good = np.ones(dt.size, bool)
    good[bad] = False
    jitter = float(np.sqrt(np.mean((dt[good] / tau0 - 1.0) ** 2))) if good.any() else 0.0
    return dict(tau0_s=tau0, gaps=bad, jitter=jitter, uniform=bool(bad.size == 0 and jitter <= jitter_max))


# --------------------------------------------------------------------------- a documented synthetic generator

def simulate_ieee952(n: int, tau0_s: float, *, Q: float = 0.0, N: float = 0.0, B: float = 0.0, K: float = 0.0,
                     R: float = 0.0, axes: int = 1, rng=None) -> np.ndarray:
    """Rate samples whose Allan variance is the IEEE 952 sum of the five terms
    (IEEE Std 952-1997, Annex C; SI units as in the module table).

    * Q: white angle (phase) noise of sigma Q, y_k += (e_k - e_{k-1}) / tau0 --
      sigma^2 = 3 Q^2 / tau^2 exactly;
    * N: white rate noise of variance N^2 / tau0 -- N^2 / tau exactly;
    * B: flicker rate noise by spectral synthesis (one-sided PSD B^2 / (pi f)
      = the two-sided B^2 / (2 pi f) of IEEE 952 eq. (C.12), Gaussian Fourier
      coefficients, inverse FFT of twice the length, first half kept) --
      (2 ln 2 / pi) B^2 for tau well above tau0 (19 % more at tau = tau0,
      where the sampled spectrum ends at Nyquist);
    * K: random-walk rate, increments of variance K^2 tau0 -- K^2 tau / 3 (+ K^2 tau0 / (6 m));
    * R: rate ramp R t -- R^2 tau^2 / 2 exactly.

    Returns (n, axes) rates.
    """
    rng = np.random.default_rng(rng)
    y = np.zeros((n, axes))
    if N > 0:
        y += (N / math.sqrt(tau0_s)) * rng.standard_normal((n, axes))
    if Q > 0:
        e = Q * rng.standard_normal((n + 1, axes))
        y += np.diff(e, axis=0) / tau0_s
    if B > 0:
        nf = 2 * n
        f = np.arange(1, nf // 2 + 1) / (nf * tau0_s)
        amp = np.sqrt(nf * (B * B / (math.pi * f)) / (2.0 * tau0_s))
        for a in range(axes):
            X = np.zeros(nf // 2 + 1, dtype=complex)
            X[1:] = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / math.sqrt(2.0)
            X[-1] = X[-1].real * math.sqrt(2.0)
            y[:, a] += np.fft.irfft(X, nf)[:n]
    if K > 0:
        y += np.cumsum(K * math.sqrt(tau0_s) * rng.standard_normal((n, axes)), axis=0)
    if R > 0:
        y += (R * tau0_s) * np.arange(n)[:, None]
    return y
