"""Paired comparison of two methods over the same Monte Carlo runs, and the
verdict word a results document prints for a paper's claim.

Each run gives one number per method (an RMSE, a maximum error, a
reconvergence time) on the *same* simulated data, so the runs are paired and
the test is on the per-run differences ``d_i = a_i - b_i``:

* the **sign test**: the number of runs where A is better, against
  Binomial(n, 1/2) (exact, two-sided; ties dropped);
* the **Wilcoxon signed-rank test**: exact permutation distribution of the
  signed-rank sum (midranks for tied ``|d_i|``, zeros dropped), two-sided;
* effect sizes: the median difference with its distribution-free confidence
  interval from the binomial order statistics, and the ratio of means ``B / A``
  with a percentile bootstrap interval (fixed seed: the document is
  reproducible).

Verdict (:func:`verdict`), at the stated threshold ``alpha`` (default 0.05) on
the Wilcoxon p-value: **reproduced** when significant in the claimed
direction, **opposite** when significant the other way, **not significant**
otherwise.  The direction is the test's own: the signed-rank sum of the runs
where A is better against that of the runs where B is (not the median
difference, which can be 0 or of the other sign when the test is
significant).  No dependency beyond numpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PairedResult", "paired", "sign_test_p", "wilcoxon_p", "verdict", "NOT_ATTEMPTED", "ALPHA"]

#: significance threshold of the verdicts (two-sided)
ALPHA = 0.05
#: the verdict of a claim the project cannot run (the document gives the reason in one sentence)
NOT_ATTEMPTED = "not attempted"


def sign_test_p(wins: int, losses: int) -> float:
    """Exact two-sided sign test: ``P(|W - n/2| >= |wins - n/2|)``, W ~ Binomial(n, 1/2), n = wins + losses."""
    n = wins + losses
    if n == 0:
        return 1.0
    k = min(wins, losses)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / (1 << n)  # integer division: no overflow for n >= 1024
    return float(min(1.0, 2.0 * tail))


def _midranks(x: np.ndarray) -> np.ndarray:
    order = np.argsort(x, kind="stable")
    r = np.empty(x.size)
    xs = x[order]
    i = 0
    while i < x.size:
        j = i
        while j + 1 < x.size and xs[j + 1] == xs[i]:
            j += 1
        r[order[i:j + 1]] = 0.5 * (i + j) + 1.0
        i = j + 1
    return r


def wilcoxon_p(d) -> float:
    """Exact two-sided Wilcoxon signed-rank p-value of the differences ``d``.

    Zeros are dropped; tied ``|d|`` get midranks, and the null distribution is
    the exact one of the signed midrank sum under random signs (a dynamic
    programme over the doubled, integer ranks), so ties are handled exactly.
    """
    d = np.asarray(d, float)
    d = d[d != 0]
    n = d.size
    if n == 0:
        return 1.0
    r2 = np.rint(2 * _midranks(np.abs(d))).astype(int)  # doubled midranks: integers
    total = int(r2.sum())
    dist = np.zeros(total + 1)
    dist[0] = 1.0
    for r in r2:  # probability of each positive-rank sum over the first ranks' random signs (r >= 2)
        shifted = dist[:-r].copy()  # halved at each rank: the counts 2**n would overflow for n >= 1024
        dist *= 0.5
        dist[r:] += 0.5 * shifted
    t_plus = int(r2[d > 0].sum())
    mean = total / 2.0
    dev = abs(t_plus - mean)
    s = np.arange(total + 1)
    return float(min(1.0, dist[np.abs(s - mean) >= dev - 1e-9].sum()))


def _signed_rank_direction(d) -> int:
    """Sign of the Wilcoxon statistic ``T+ - T-`` (midranks of ``|d|``, zeros dropped): +1, -1 or 0."""
    d = np.asarray(d, float)
    d = d[d != 0]
    if d.size == 0:
        return 0
    r = _midranks(np.abs(d))
    return int(np.sign(r[d > 0].sum() - r[d < 0].sum()))


def _median_ci(d: np.ndarray, level: float) -> tuple[float, float]:
    """Distribution-free CI of the median from the order statistics (sign-test inversion)."""
    n = d.size
    if n == 0:
        return (math.nan, math.nan)
    ds = np.sort(d)
    a = (1.0 - level) / 2.0
    cdf = 0.0
    k = 0
    for i in range(n + 1):  # largest k with P(B <= k - 1) <= a, B ~ Bin(n, 1/2)
        cdf_next = cdf + math.comb(n, i) / (1 << n)
        if cdf_next > a:
            k = i
            break
        cdf = cdf_next
    if k == 0:
        return (float(ds[0]), float(ds[-1]))  # too few runs for the level: the range
    return (float(ds[k - 1]), float(ds[n - k]))


@dataclass
class PairedResult:
    """A paired comparison "A better than B" over ``n`` runs.

    Attributes
    ----------
    n : int
        Runs (pairs).
    wins, losses, ties : int
        Runs where A is better / worse / equal (in the claimed sense).
    p_sign, p_wilcoxon : float
        Two-sided p-values.
    median_diff : float
        Median of ``a - b`` (units of the metric).
    median_diff_ci : (float, float)
        Its distribution-free confidence interval.
    ratio : float
        ``mean(b) / mean(a)`` (> 1: A better when lower is better).
    ratio_ci : (float, float)
        Percentile bootstrap interval of the ratio.
    level : float
        Confidence level of both intervals.
    lower_is_better : bool
    a_better_by_ranks : int
        +1 when the signed ranks favour A (the Wilcoxon statistic's side), -1
        when they favour B, 0 when balanced: the verdict's direction.
    dropped : int
        Pairs left out because a or b is NaN (a run without the metric, e.g.
        one that never reconverged): named in :meth:`evidence`.
    censored : int
        With ``nan_is_worst``: pairs where exactly one of a, b is NaN, counted
        as a loss of that side instead of left out: named in :meth:`evidence`.
    censored_ties : int
        With ``nan_is_worst``: pairs where both are NaN (ties).
    p_wilcoxon_bounds : tuple or None
        With ``nan_is_worst`` and ``censor_bound``: the Wilcoxon p with each
        censored value ranked at the top and with it set to its bound;
        ``p_wilcoxon`` is the larger.
    """

    n: int
    wins: int
    losses: int
    ties: int
    p_sign: float
    p_wilcoxon: float
    median_diff: float
    median_diff_ci: tuple
    ratio: float
    ratio_ci: tuple
    level: float
    lower_is_better: bool
    a_better_by_ranks: int = 0
    dropped: int = 0
    censored: int = 0
    censored_ties: int = 0
    p_wilcoxon_bounds: tuple | None = None

    def verdict(self, alpha: float = ALPHA) -> str:
        """reproduced / opposite / not significant (module docstring)."""
        return verdict(self, alpha)

    def evidence(self, unit: str = "", fmt: str = ".3g") -> str:
        """One line for a verdict table: wins, p-values, effect sizes with CIs."""
        lo, hi = self.median_diff_ci
        rlo, rhi = self.ratio_ci
        u = f" {unit}" if unit else ""
        return (f"A better in {self.wins}/{self.n} runs; sign test p = {self.p_sign:.2g}, Wilcoxon p = "
                f"{self.p_wilcoxon:.2g}; median A - B = {self.median_diff:{fmt}}{u} "
                f"({self.level:.0%} CI {lo:{fmt}} .. {hi:{fmt}}); mean B / mean A = {self.ratio:.3g} "
                f"(CI {rlo:.3g} .. {rhi:.3g})"
                + (f"; {self.dropped} run(s) without a value for A or B left out" if self.dropped else "")
                + (f"; {self.censored} run(s) where one of A, B never reached it counted as its loss"
                   + ("" if self.p_wilcoxon_bounds is None else
                      f" (Wilcoxon p {self.p_wilcoxon_bounds[0]:.2g} with it ranked at the top, "
                      f"{self.p_wilcoxon_bounds[1]:.2g} at its bound: the larger kept)")
                   + ", ratio of means over the runs with both" if self.censored else "")
                + (f"; {self.censored_ties} run(s) where neither reached it counted as ties"
                   if self.censored_ties else ""))


def paired(a, b, *, lower_is_better: bool = True, level: float = 0.95, n_boot: int = 2000,
           seed: int = 0, nan_is_worst: bool = False, censor_bound=None) -> PairedResult:
    """Compare method A with method B on paired per-run values.

    Parameters
    ----------
    a, b : array_like (n,)
        The metric of A and of B in the same runs (pairs with a NaN are left
        out and counted in ``dropped``: map a censored value, e.g. "never
        reconverged", to a number first if it should count).
    lower_is_better : bool
        The metric's sense (errors, times: True).
    level : float
        Confidence level of the intervals.
    n_boot : int
        Bootstrap resamples of the ratio of means.
    seed : int
        Bootstrap seed.
    nan_is_worst : bool
        Read NaN as a right-censored value worse than every observed one (a run
        that never reconverged inside a window shared by all runs, whose
        observed times all lie below the censoring point).  A pair with one NaN
        is a win for the other side; a pair of NaNs is a tie.  The size of such
        a difference is unknown: the Wilcoxon ranks take it as larger than
        every observed one (an assumption), and with ``censor_bound`` also as
        the smallest it can be (the censored value at its bound), the verdict
        then resting on the larger p and on both giving the same direction.
        The median difference and its interval take such a difference as
        infinite (undefined, NaN, when the two middle ones are -inf and +inf);
        the ratio of means is over the pairs without a NaN.
    censor_bound : float or array_like (n,), optional
        With ``nan_is_worst``: the least value a censored run can have (e.g. the
        window's end less the hold time), per run or for all.

    Returns
    -------
    PairedResult
    """
    a = np.asarray(a, float).ravel()
    b = np.asarray(b, float).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired: a and b differ in length ({a.size} vs {b.size})")
    ok = np.isfinite(a) & np.isfinite(b)
    if nan_is_worst:
        if np.isinf(a).any() or np.isinf(b).any():
            raise ValueError("paired: nan_is_worst reads NaN as censored; a or b holds an infinity")
        return _paired_censored(a, b, ok, lower_is_better, level, n_boot, seed, censor_bound)
    dropped = int(a.size - ok.sum())
    a, b = a[ok], b[ok]
    d = a - b
    better = d < 0 if lower_is_better else d > 0
    worse = d > 0 if lower_is_better else d < 0
    wins, losses = int(better.sum()), int(worse.sum())
    ratio, ratio_ci = _ratio_of_means(a, b, level, n_boot, seed)
    return PairedResult(n=int(a.size), wins=wins, losses=losses, ties=int(a.size - wins - losses),
                        p_sign=sign_test_p(wins, losses), p_wilcoxon=wilcoxon_p(d),
                        median_diff=float(np.median(d)) if d.size else math.nan,
                        median_diff_ci=_median_ci(d, level), ratio=ratio, ratio_ci=ratio_ci, level=level,
                        lower_is_better=lower_is_better,
                        a_better_by_ranks=_signed_rank_direction(-d if lower_is_better else d), dropped=dropped)


def _ratio_of_means(a, b, level, n_boot, seed):
    """mean(b) / mean(a) and its percentile bootstrap interval."""
    ratio = float(b.mean() / a.mean()) if a.size and a.mean() != 0 else math.nan
    if not a.size:
        return ratio, (math.nan, math.nan)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, a.size, size=(n_boot, a.size))
    with np.errstate(divide="ignore", invalid="ignore"):
        rb = b[idx].mean(axis=1) / a[idx].mean(axis=1)
    q = (1 - level) / 2
    return ratio, (float(np.nanquantile(rb, q)), float(np.nanquantile(rb, 1 - q)))


def _median(d: np.ndarray) -> float:
    """Median of d (may hold +-inf): NaN, without a warning, when the two middle values are -inf and +inf."""
    if not d.size:
        return math.nan
    ds = np.sort(d)
    n = ds.size
    if n % 2:
        return float(ds[n // 2])
    lo, hi = ds[n // 2 - 1], ds[n // 2]
    if np.isinf(lo) and np.isinf(hi) and lo != hi:
        return math.nan
    return float(lo) if lo == hi else float(0.5 * (lo + hi))


def _paired_censored(a, b, ok, lower_is_better, level, n_boot, seed, censor_bound=None) -> PairedResult:
    """:func:`paired` with NaN read as worse than every value (its ``nan_is_worst``)."""
    worst = math.inf if lower_is_better else -math.inf
    na, nb = np.isnan(a), np.isnan(b)
    a_c, b_c = np.where(na, worst, a), np.where(nb, worst, b)
    with np.errstate(invalid="ignore"):
        d = a_c - b_c
    d[na & nb] = 0.0  # both censored: a tie
    better = d < 0 if lower_is_better else d > 0
    worse = d > 0 if lower_is_better else d < 0
    wins, losses = int(better.sum()), int(worse.sum())
    fin = np.isfinite(d)
    top = (np.abs(d[fin]).max() if fin.any() else 0.0) + 1.0
    d_rank = np.where(fin, d, np.sign(d) * top)  # one side censored: tied above every observed |d|
    p_w = wilcoxon_p(d_rank)
    direction = _signed_rank_direction(-d_rank if lower_is_better else d_rank)
    bounds = None
    if censor_bound is not None and (na ^ nb).any():
        c = np.broadcast_to(np.asarray(censor_bound, float), a.shape)
        d_b = np.where(na, c, a) - np.where(nb, c, b)
        d_b[na & nb] = 0.0
        p_b = wilcoxon_p(d_b)
        bounds = (p_w, p_b)
        dir_b = _signed_rank_direction(-d_b if lower_is_better else d_b)
        p_w = max(p_w, p_b)
        direction = direction if direction == dir_b else 0
    ratio, ratio_ci = _ratio_of_means(a[ok], b[ok], level, n_boot, seed)
    return PairedResult(n=int(a.size), wins=wins, losses=losses, ties=int(a.size - wins - losses),
                        p_sign=sign_test_p(wins, losses), p_wilcoxon=p_w,
                        median_diff=_median(d), median_diff_ci=_median_ci(d, level), ratio=ratio,
                        ratio_ci=ratio_ci, level=level, lower_is_better=lower_is_better,
                        a_better_by_ranks=direction, censored=int((na ^ nb).sum()),
                        censored_ties=int((na & nb).sum()), p_wilcoxon_bounds=bounds)


def verdict(res: PairedResult, alpha: float = ALPHA) -> str:
    """The verdict word for the claim "A better than B" (module docstring)."""
    if not res.p_wilcoxon < alpha or res.a_better_by_ranks == 0:
        return "not significant"
    return "reproduced" if res.a_better_by_ranks > 0 else "opposite"
