"""``np.median`` and ``np.unique`` of a 1-D array without importing :mod:`numpy.ma`.

``np.median`` checks its result for NaN through ``np.ma.isMaskedArray``, and
``np.unique`` (without ``return_index``/``return_inverse``) asks
``np.ma.is_masked``: either imports ``numpy.ma`` (~30 ms of CPU with the
signatures it parses) the first time; the command line's run path needs a
handful of medians and unique values and nothing else from it."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["median", "percentile", "group_median", "unique", "stream_median", "spacing_median", "diff_median"]


def median(x) -> float:
    """The median of the values of ``x`` as ``np.median`` computes it (the
    mean of the two middle values for an even count; NaN when a value is NaN
    or there is none)."""
    a = np.asarray(x, dtype=float).reshape(-1)
    n = a.size
    if n == 0:
        return float("nan")
    k = n // 2
    p = np.partition(a, k if n % 2 else (k - 1, k))
    if np.isnan(p[-1]):  # NaNs sort last
        return float("nan")
    return float(p[k]) if n % 2 else float((p[k - 1] + p[k]) / 2.0)


def percentile(x, q: float) -> float:
    """The ``q``-th percentile of the values of ``x`` as ``np.percentile(x, q)`` computes it
    (method "linear": the virtual index ``(n - 1) q / 100`` between its two neighbours, numpy's
    interpolation arithmetic; NaN when a value is NaN or there is none)."""
    a = np.asarray(x, dtype=float).reshape(-1)
    n = a.size
    if n == 0:
        return float("nan")
    vi = (n - 1) * (q / 100.0)
    if vi >= n - 1:
        lo = hi = n - 1
    else:
        lo = max(int(math.floor(vi)), 0)
        hi = lo + 1
    p = np.partition(a, sorted({lo, hi, n - 1}))
    if np.isnan(p[-1]):  # NaNs sort last
        return float("nan")
    gamma = vi - math.floor(vi) if vi < n - 1 else 0.0
    lo_v, hi_v = float(p[lo]), float(p[hi])
    diff = hi_v - lo_v
    return hi_v - diff * (1.0 - gamma) if gamma >= 0.5 else lo_v + diff * gamma


def group_median(x, group, n_groups: int):
    """Per-group medians of ``x`` (1-D), as ``np.median(x[group == g])`` for each group ``g``.

    Parameters
    ----------
    x : (k,) values
    group : (k,) int group of each value, 0 <= group < n_groups
    n_groups : int

    Returns
    -------
    med : (n_groups,) the median of each group (the mean of the two middle
        values for an even count; NaN for a group holding a NaN or no value)
    present : (n_groups,) bool, the groups with at least one value
    """
    a = np.asarray(x, dtype=float).reshape(-1)
    g = np.asarray(group, dtype=np.int64).reshape(-1)
    out = np.full(n_groups, np.nan)
    counts = np.bincount(g, minlength=n_groups) if g.size else np.zeros(n_groups, np.int64)
    present = counts > 0
    if not g.size:
        return out, present
    xs = a[np.lexsort((a, g))]  # by group, then value (NaN last in its group)
    start = np.cumsum(counts) - counts
    c, s0 = counts[present], start[present]
    lo, hi = s0 + (c - 1) // 2, s0 + c // 2
    med = np.where(c % 2 == 1, xs[lo], (xs[lo] + xs[hi]) / 2.0)
    med[np.isnan(xs[s0 + c - 1])] = np.nan
    out[present] = med
    return out, present


def unique(x) -> np.ndarray:
    """The sorted distinct values of ``x`` (flattened), as ``np.unique(x)`` returns them (no NaN handling:
    for integer and string arrays)."""
    a = np.asarray(x).reshape(-1)
    n_chars = a.dtype.itemsize // 4 if a.dtype.str.startswith("<U") else 0
    if 1 <= n_chars <= 3 and a.size > 64:
        # short strings (system letters, observation codes): sorted as integers, the code points packed
        # 21 bits each (Unicode < 2^21; a shorter string's NUL padding sorts first, as numpy sorts strings)
        codes = np.ascontiguousarray(a).view(np.uint32).reshape(-1, n_chars).astype(np.int64)
        key = codes[:, 0]
        for j in range(1, n_chars):
            key = (key << 21) | codes[:, j]
        key = _sorted_distinct(key)
        out = np.empty((key.size, n_chars), np.uint32)
        for j in range(n_chars - 1, -1, -1):
            out[:, j] = key & 0x1FFFFF
            key = key >> 21
        return out.reshape(-1).view(a.dtype)
    return _sorted_distinct(a)


def _sorted_distinct(a: np.ndarray) -> np.ndarray:
    a = np.sort(a)
    if a.size < 2:
        return a
    keep = np.empty(a.size, bool)
    keep[0] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    return a[keep]


#: distinct values :func:`stream_median` counts before it bisects instead
_MEDIAN_DISTINCT_MAX = 1 << 12


def _diffs(chunks):
    """``np.diff`` of the concatenation of ``chunks`` (1-D arrays), a chunk at a time."""
    prev = None
    for x in chunks:
        if not x.size:
            continue
        yield np.diff(x) if prev is None else np.diff(np.concatenate([prev, x]))
        prev = x[-1:]


def _sorted_counts(x):
    """The distinct values of a sorted array and how often each occurs."""
    if not x.size:
        return x, np.zeros(0, np.int64)
    first = np.flatnonzero(np.concatenate([[True], x[1:] != x[:-1]]))
    return x[first], np.diff(np.append(first, x.size))


def stream_median(chunks) -> float:
    """``median(np.concatenate(list(chunks())))`` (:func:`insnav._median.median`: the mean of the two middle
    values for an even count; NaN for a NaN or no value) exactly, with temporaries of one chunk.

    ``chunks()`` returns a fresh iterator of 1-D float arrays.  The counts of the distinct values while
    there are at most :data:`_MEDIAN_DISTINCT_MAX` (a receiver's intervals take a handful), else a
    bisection on the values' order-preserving 64-bit keys (at most 64 counting passes)."""
    n = 0
    vals, cnt = np.zeros(0), np.zeros(0, np.int64)
    few = True
    for x in chunks():
        if not x.size:
            continue
        if np.isnan(x).any():
            return float("nan")
        n += x.size
        if few:
            v2, c2 = _sorted_counts(np.sort(x))
            allv = np.concatenate([vals, v2])
            o = np.argsort(allv, kind="stable")
            allv, allc = allv[o], np.concatenate([cnt, c2])[o]
            first = np.flatnonzero(np.concatenate([[True], allv[1:] != allv[:-1]]))
            vals, cnt = allv[first], np.add.reduceat(allc, first) if allc.size else allc
            few = vals.size <= _MEDIAN_DISTINCT_MAX
    if n == 0:
        return float("nan")
    if few:
        cum = np.cumsum(cnt)

        def kth(i):
            return vals[int(np.searchsorted(cum, i, side="right"))]
    else:
        mask = np.int64(0x7FFFFFFFFFFFFFFF)

        def keys(x):
            b = np.ascontiguousarray(x, float).view(np.int64)
            return b ^ ((b >> 63) & mask)

        def kth(i):  # the smallest key with more than i keys at or below it
            lo, hi = -(1 << 63), (1 << 63) - 1
            while lo < hi:
                mid = (lo + hi) // 2
                if sum(int(np.count_nonzero(keys(x) <= mid)) for x in chunks()) > i:
                    hi = mid
                else:
                    lo = mid + 1
            k = np.array([lo], np.int64)
            return (k ^ ((k >> 63) & mask)).view(float)[0]
    k = n // 2
    return float(kth(k)) if n % 2 else float((kth(k - 1) + kth(k)) / 2.0)

#: values per block of :func:`spacing_median`
SPACING_BLOCK = 1 << 14


def spacing_median(t, block: int = SPACING_BLOCK) -> float | None:
    """The median spacing of the distinct values of ``t``: ``median(d[d != 0])`` with ``d =
    np.diff(np.sort(t))`` (None: no spacing), the same value, with temporaries of ``block`` values when
    ``t`` is in order (the sort then the identity; else ``t`` sorted whole)."""
    t = np.asarray(t, dtype=float).reshape(-1)
    n = t.size
    ordered = True
    for a in range(0, n - 1, block):  # NaN: not in order
        seg = t[a:a + block + 1]
        if not bool(np.all(seg[1:] >= seg[:-1])):
            ordered = False
            break
    if not ordered:
        t = np.sort(t)

    def chunks():
        for d in _diffs(t[a:a + block] for a in range(0, n, block)):
            yield d[d != 0]

    if not any(d.size for d in chunks()):
        return None
    return stream_median(chunks)


def diff_median(x, block: int = SPACING_BLOCK) -> float:
    """``median(np.diff(x))`` (NaN: fewer than two values), the same value, with temporaries of ``block``
    values (the fixes' interval of a long record: no whole-record copies)."""
    x = np.asarray(x, dtype=float).reshape(-1)
    return stream_median(lambda: _diffs(x[a:a + block] for a in range(0, x.size, block)))
