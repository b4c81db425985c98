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
