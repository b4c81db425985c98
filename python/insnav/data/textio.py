"""Numeric text tables through the compiled reader and writer
(``cpp/include/insnav/io/text_table.hpp``): the solution CSV and KF-GINS
layouts are written, and the KF-GINS and insnav CSV files read, in C++ with
the GIL released."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["write_text_columns", "threads"]


def threads() -> int:
    """Threads for formatting and parsing: at most two (the machine's cores)."""
    return max(1, min(2, os.cpu_count() or 1))


def write_text_columns(path, header: str, cols, decimals, **fmt) -> Path:
    """Write ``cols`` (name, array, unit factor) as a text table, atomically.

    Parameters
    ----------
    path : str or Path
    header : str
        Written first, as is (with its newline; may be empty).
    cols : list of (str, ndarray (N,), float)
        The values written are ``factor * array`` (any stride, no copy).
    decimals : list of int
        Per column: >= 0 fixed decimals (trailing zeros dropped unless
        ``trim_zeros=False``), < 0 the shortest round-trip text.
    **fmt
        ``sep`` (one character), ``width`` (left-justified field width),
        ``trim_zeros``, ``trailing_sep`` of ``_core.write_table``.
    """
    from .. import _core
    from .._atomic import atomic_write_with

    arrays = [np.asarray(x, float) for _, x, _ in cols]
    return atomic_write_with(Path(path), lambda tmp: _core.write_table(
        str(tmp), header, arrays, [float(f) for _, _, f in cols], list(decimals), threads=threads(), **fmt))
