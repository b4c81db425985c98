"""The C allocator's setting for long block-by-block runs (glibc only).

glibc's ``malloc`` serves a request of at least ``M_MMAP_THRESHOLD`` bytes
(128 KiB by default) with its own ``mmap``, returned to the system by
``free``.  Its *dynamic* threshold (glibc >= 2.18, ``malloc/malloc.c``:
``mp_.no_dyn_threshold``) raises the threshold to the size of any such chunk
that is freed, up to 32 MiB on 64-bit Linux.  A block-by-block run frees
buffers of a few MB at every block (numpy arrays and text of the IMU block
and of its rows), so after the first block every later one comes from the
heap instead, where blocks of slightly different sizes, interleaved with small
long-lived objects, leave holes that the next block does not fit: the heap
grows with free space in it.  Measured on a standing-vehicle KF-GINS
recording (``insnav run --format kfgins``, 1 Hz GNSS, ``mallinfo2`` at block
ends): over an 8 h run at ``--output-rate 10`` the heap (``arena``) grew
24.3 -> 31.0 MB while its used bytes stayed at 18.8 -> 19.1 MB (the free
bytes in it 5.5 -> 11.9 MB); with the threshold fixed at 128 KiB it stayed
at 7.8 MB, 2.3 MB of it free, the blocks being mapped and unmapped.  The
peak RSS, medians of 3 runs at 1 h and 24 h: 65.4 -> 78.4 MB
(+0.57 MB per hour of recording) without the setting, 62.5 -> 67.3 MB
(+0.21 MB/h) with it; 200 Hz with the navigation columns +0.38 -> +0.23 MB/h.
The price: each block's pages are faulted in afresh: a 24 h run at 10 Hz,
3 runs alternated, took 16.75 s of CPU instead of 15.80 s (medians; system
time 0.75 -> 1.81 s, wall 10.2 -> 10.8 s); a 1 h run's CPU is unchanged
(1.05 s / 1.04 s).  Reusing the block buffers would remove both the holes
and this cost.
"""
from __future__ import annotations

import ctypes
import os

#: ``M_MMAP_THRESHOLD`` of glibc's ``malloc.h``
M_MMAP_THRESHOLD = -3
#: the threshold fixed for a block-by-block run [bytes]: glibc's default (``DEFAULT_MMAP_THRESHOLD_MIN``)
STREAM_MMAP_THRESHOLD = 128 * 1024


def _glibc():
    """The C library when it is glibc (``os.confstr('CS_GNU_LIBC_VERSION')`` names it), else None."""
    try:
        if not (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc"):
            return None
        return ctypes.CDLL(None)
    except (ValueError, OSError, AttributeError):  # pragma: no cover - no confstr name, no C library
        return None


def fix_mmap_threshold(nbytes: int = STREAM_MMAP_THRESHOLD) -> bool:
    """Fix glibc's mmap threshold at ``nbytes`` for the rest of the process.

    Every allocation of at least ``nbytes`` is then mapped and unmapped on
    its own, never carved from the heap, and glibc's dynamic raising of the
    threshold (to the size of each large chunk freed) is switched off for
    good (``mallopt(M_MMAP_THRESHOLD, ...)`` sets ``no_dyn_threshold``; glibc
    has no call that switches it back on).  This keeps the heap of a long
    block-by-block run from growing with holes left by blocks of a few MB
    (the module's docstring gives the measured figures).  A no-op off glibc
    (musl, macOS, Windows).

    Parameters
    ----------
    nbytes : int
        The threshold [bytes]; glibc accepts at most 32 MiB on 64-bit.

    Returns
    -------
    bool
        True when glibc accepted the setting (``mallopt`` returned 1),
        False off glibc or when it refused the value.
    """
    libc = _glibc()
    if libc is None:
        return False
    mallopt = libc.mallopt
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return mallopt(M_MMAP_THRESHOLD, int(nbytes)) == 1
