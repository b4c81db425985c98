"""Paired statistics of the results verdicts (insnav.analysis.paired) against
values computed by hand."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from insnav.analysis.paired import paired, sign_test_p, verdict, wilcoxon_p


def test_sign_test_exact_values():
    assert sign_test_p(10, 0) == pytest.approx(2 / 2 ** 10)
    assert sign_test_p(13, 7) == pytest.approx(2 * sum(math.comb(20, i) for i in range(8)) / 2 ** 20)
    assert sign_test_p(13, 7) == pytest.approx(0.2632, abs=1e-4)  # the "13 of 20" of an earlier verdict
    assert sign_test_p(5, 5) == 1.0 and sign_test_p(0, 0) == 1.0


def _wilcoxon_brute(d):
    d = np.asarray([x for x in d if x != 0], float)
    a = np.abs(d)
    ranks = np.array([np.sum(a < x) + (np.sum(a == x) + 1) / 2 for x in a])
    t = ranks[d > 0].sum()
    mean = ranks.sum() / 2
    sums = [sum(r for r, s in zip(ranks, signs) if s) for signs in itertools.product((0, 1), repeat=d.size)]
    return np.mean([abs(s - mean) >= abs(t - mean) - 1e-9 for s in sums])


@pytest.mark.parametrize("d", [[1, 2, 3, 4, 5], [-1, 2, 3, -4, 5, 6, 7, 0.5],
                               [1, 1, 2, -2, 3, 3, 3, -0.5, 4, 0.0]])  # ties and a zero
def test_wilcoxon_equals_brute_force_enumeration(d):
    assert wilcoxon_p(d) == pytest.approx(_wilcoxon_brute(d), rel=1e-12)


def test_wilcoxon_all_positive_five():
    assert wilcoxon_p([0.1, 0.2, 0.3, 0.4, 0.5]) == pytest.approx(2 / 32)


def test_paired_effects_and_verdicts():
    rng = np.random.default_rng(1)
    b = 1.0 + 0.1 * rng.standard_normal(30)
    a = 0.5 * b + 0.01 * rng.standard_normal(30)  # A halves the error
    r = paired(a, b)
    assert r.wins == 30 and r.p_sign == pytest.approx(2 / 2 ** 30)
    assert r.ratio == pytest.approx(b.mean() / a.mean())
    assert r.ratio_ci[0] < r.ratio < r.ratio_ci[1] and 1.8 < r.ratio_ci[0]
    lo, hi = r.median_diff_ci
    assert lo <= r.median_diff <= hi < 0
    assert verdict(r) == "reproduced"
    assert paired(b, a).verdict() == "opposite"
    assert paired(a, b, lower_is_better=False).verdict() == "opposite"
    assert paired(b[:4] * 0.5, b[:4]).verdict() == "not significant"  # 4 runs cannot reach p < 0.05


def test_verdict_direction_is_the_signed_rank_side_not_the_median():
    # A better in 10 runs, never worse, tied in 11: significant, median difference exactly 0
    a = np.r_[np.full(10, 1.0), np.full(11, 2.0)]
    b = np.r_[np.full(10, 2.0), np.full(11, 2.0)]
    r = paired(a, b)
    assert r.median_diff == 0.0 and r.p_wilcoxon == pytest.approx(2 / 2 ** 10)
    assert r.a_better_by_ranks == 1 and r.verdict() == "reproduced"
    # A slightly lower in 16 runs, much higher in 14: the ranks favour B, the median A
    a = np.r_[np.full(16, 10.0), np.full(14, 15.0)]
    b = np.r_[np.full(16, 10.01), np.full(14, 10.0)]
    r = paired(a, b)
    assert r.median_diff < 0 and r.p_wilcoxon < 0.05
    assert r.a_better_by_ranks == -1 and r.verdict() == "opposite"


def test_large_n_does_not_overflow():
    # n = 1100: 2**n overflows a float; the sign test is exact in integers, the Wilcoxon DP is normalised
    assert sign_test_p(600, 500) == pytest.approx(
        2 * sum(math.comb(1100, i) for i in range(501)) / (1 << 1100), rel=1e-12)
    assert 0.002 < sign_test_p(600, 500) < 0.004  # normal approximation: z = 2.98, p = 0.0029
    rng = np.random.default_rng(3)
    d = rng.standard_normal(1100) + 0.07
    p = wilcoxon_p(d)
    # normal approximation of the signed-rank sum (no ties): z = (T+ - m) / s
    n = d.size
    r = np.argsort(np.argsort(np.abs(d))) + 1.0
    z = (r[d > 0].sum() - n * (n + 1) / 4) / math.sqrt(n * (n + 1) * (2 * n + 1) / 24)
    p_normal = math.erfc(abs(z) / math.sqrt(2))
    assert p < 0.05 and p == pytest.approx(p_normal, rel=0.05)
    r = paired(d + 1.0, np.ones(1100), lower_is_better=False)
    assert r.verdict() == "reproduced"


def test_nan_pairs_are_counted_and_named():
    a = np.r_[np.arange(12.0), np.nan]
    b = np.r_[np.arange(12.0) + 1, 3.0]
    r = paired(a, b)
    assert r.n == 12 and r.dropped == 1
    assert "1 run(s) without a value for A or B left out" in r.evidence()
    assert "left out" not in paired(a[:12], b[:12]).evidence()


def test_nan_is_worst_reduces_to_the_plain_test_without_nan():
    rng = np.random.default_rng(5)
    a, b = rng.gamma(2.0, size=30), rng.gamma(2.2, size=30)
    plain, cens = paired(a, b), paired(a, b, nan_is_worst=True)
    for k in ("n", "wins", "losses", "p_sign", "p_wilcoxon", "median_diff", "median_diff_ci", "ratio", "ratio_ci"):
        assert getattr(cens, k) == getattr(plain, k), k
    assert cens.censored == 0 and "never reached" not in cens.evidence()


def test_nan_is_worst_by_hand_and_as_a_large_substitute():
    # A never reached it in run 3: B wins that run with the top rank; ranks 1, 2 for A, 3 for B
    r = paired([1.0, 2.0, np.nan], [2.0, 4.0, 3.0], nan_is_worst=True)
    assert (r.n, r.wins, r.losses, r.ties, r.censored) == (3, 2, 1, 0, 1)
    assert r.a_better_by_ranks == 0 and r.p_wilcoxon == 1.0
    assert r.median_diff == -1.0 and r.ratio == pytest.approx(3.0 / 1.5)
    # both censored: a tie; and with one censored pair the test equals substituting a value above all
    r2 = paired([1.0, np.nan, 5.0, np.nan], [3.0, np.nan, 2.0, 1.0], nan_is_worst=True)
    assert (r2.wins, r2.losses, r2.ties, r2.censored, r2.censored_ties) == (1, 2, 1, 1, 1)
    assert "1 run(s) where neither reached it counted as ties" in r2.evidence()
    rng = np.random.default_rng(9)
    a, b = rng.normal(5, 1, 25), rng.normal(5.8, 1, 25)
    a[7] = np.nan
    sub = a.copy()
    sub[7] = 1e9
    r, s = paired(a, b, nan_is_worst=True), paired(sub, b)
    assert (r.wins, r.losses, r.p_sign) == (s.wins, s.losses, s.p_sign)
    assert r.p_wilcoxon == pytest.approx(s.p_wilcoxon, rel=1e-12)
    assert "1 run(s) where one of A, B never reached it counted as its loss" in r.evidence()


def test_nan_is_worst_changes_the_verdict_where_dropping_hid_the_losses():
    # B never reconverges in 8 runs; in the 6 others A is slightly worse: dropping the NaNs reads
    # "B better" (opposite), counting them as censored reads A better (reproduced)
    a = np.r_[np.full(8, 10.0), 5.1, 5.2, 5.3, 5.4, 5.5, 5.6]
    b = np.r_[np.full(8, np.nan), 5.0, 5.0, 5.0, 5.0, 5.0, 5.0]
    assert paired(a, b).verdict() == "opposite"
    r = paired(a, b, nan_is_worst=True)
    assert r.verdict() == "reproduced" and r.wins == 8 and r.median_diff == -math.inf
    with pytest.raises(ValueError, match="infinity"):
        paired([np.inf, 1.0], [1.0, 2.0], nan_is_worst=True)


def test_censored_ranks_at_the_top_and_at_the_bound_keep_the_larger_p():
    """The size of a censored difference is unknown: with censor_bound the test is also made with each
    censored value at its bound (the smallest it can be), and the verdict keeps the larger p."""
    # B (the EKF, say) never reached it in 12 runs, just past the observed values (bound 10); A is
    # slightly worse in 8 observed runs: ranked at the top the censored runs make it "reproduced"
    # (p 0.005), at the bound they are small differences and A's losses dominate
    a = np.r_[np.full(12, 9.5), np.linspace(5.0, 9.0, 8)]
    b = np.r_[np.full(12, np.nan), np.linspace(5.0, 9.0, 8) - 0.6]
    top = paired(a, b, nan_is_worst=True)
    both = paired(a, b, nan_is_worst=True, censor_bound=10.0)
    sub = np.where(np.isnan(b), 10.0, b)
    assert both.p_wilcoxon_bounds == (top.p_wilcoxon, wilcoxon_p(a - sub))
    assert both.p_wilcoxon == max(top.p_wilcoxon, wilcoxon_p(a - sub))
    assert top.verdict() == "reproduced" and top.p_wilcoxon < 0.01
    assert both.a_better_by_ranks == 0 and both.verdict() == "not significant"  # the two readings disagree
    assert "ranked at the top" in both.evidence()
    # censored both ways: the median of -inf and +inf is undefined, without a warning
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = paired([np.nan, 1.0], [1.0, np.nan], nan_is_worst=True)
    assert math.isnan(r.median_diff)
