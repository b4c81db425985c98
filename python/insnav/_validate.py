"""Input validation at the Python/C++ boundary (done once, vectorised)."""
from __future__ import annotations

import numpy as np


def as_float_array(a, name: str, shape_tail: tuple = ()) -> np.ndarray:
    """Convert to a C-contiguous float64 array and check the trailing shape.

    Raises
    ------
    ValueError
        Naming the argument, the expected and the actual shape.
    """
    try:
        arr = np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot convert to a float array ({exc})") from None
    expected_ndim = 1 + len(shape_tail)
    if arr.ndim != expected_ndim or tuple(arr.shape[1:]) != tuple(shape_tail):
        want = "(N" + "".join(f", {d}" for d in shape_tail) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    return arr


def check_finite(arr: np.ndarray, name: str) -> None:
    """Raise ``ValueError`` naming the first sample index holding a NaN/inf."""
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = int(np.argmax(bad.reshape(len(arr), -1).any(axis=1)))
        raise ValueError(f"{name}: non-finite value at sample {idx}: {arr[idx]!r}")


def check_increasing(t: np.ndarray, name: str = "t", t0: float | None = None) -> None:
    """Raise ``ValueError`` naming the first sample whose time does not increase."""
    if t0 is not None and len(t) and not t[0] > t0:
        raise ValueError(f"{name}: sample 0 at t={t[0]!r} is not after the initial time t0={t0!r}")
    d = np.diff(t)
    bad = ~(d > 0)
    if bad.any():
        i = int(np.argmax(bad)) + 1
        raise ValueError(
            f"{name}: time not strictly increasing at sample {i} (t[{i - 1}]={t[i - 1]!r}, t[{i}]={t[i]!r})"
        )
