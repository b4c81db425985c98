"""Text files read a block of lines at a time, without the whole text in memory.

:func:`text_blocks` cuts a plain or compressed (``.xz``, ``.gz``, ``.bz2``)
file into blocks at line ends and hands each to a parser;
:func:`read_gnss_text_blocks` reads a KF-GINS GNSS file with it in two passes.
The block-by-block run (:mod:`insnav.filters.stream`) uses both.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..data.dataset import GnssFixes, RowOrigin, check_finite_rows
from ..data.textio import count_columns, parse_numeric

__all__ = ["GNSS_BLOCK_LINES", "LINE_BYTES_GUESS", "count_lines", "open_text", "read_gnss_text_blocks", "text_blocks"]

#: bytes per text line assumed when sizing a block's read (the block is cut at a line end)
LINE_BYTES_GUESS = 112


def open_text(path: Path):
    """(the text stream, the file on disk: its position is the progress; compressed or not)."""
    raw = open(path, "rb", buffering=0)
    kind = {".xz": "lzma", ".lzma": "lzma", ".gz": "gzip", ".bz2": "bz2"}.get(path.suffix.lower())
    if kind is None:
        return raw, raw, False
    import bz2
    import gzip
    import lzma

    try:
        return {"lzma": lzma.open, "gzip": gzip.open, "bz2": bz2.open}[kind](raw, "rb"), raw, True
    except BaseException:
        raw.close()
        raise


def text_blocks(path, block_lines: int, parse):
    """The blocks of a text file: about ``block_lines`` lines each, cut at a
    line end (the file read with plain reads into one buffer, decompressed as
    it is read), each handed to ``parse(data, first_line, eof) -> (block or
    None, lines or None)`` (``data`` a memoryview valid during the call, its
    first line ``first_line``; ``lines``: how many lines it held, None: counted
    here); the blocks parse returns are yielded with their progress set.

    Raises
    ------
    ValueError
        A truncated compressed stream, or a file that changed while it was
        read (:class:`insnav.data.textio.FileChangedError`); parse's own errors.
    """
    p = Path(path)
    if not p.is_file():
        exc = FileNotFoundError(f"{p} does not exist")
        exc.strerror, exc.filename = "No such file or directory", str(p)
        raise exc
    f, raw, compressed = open_text(p)
    chunk = max(1, int(block_lines)) * LINE_BYTES_GUESS
    line = 1  # file line of the next block's first line
    with raw, f:
        st0 = os.stat(p)
        buf = bytearray(chunk)  # one buffer for every block: the unfinished line moved to its start
        have = 0  # bytes of the unfinished line at buf's start
        pos = 0  # bytes read from the file
        eof = False
        while not eof:
            if have == len(buf):  # one line longer than the buffer: grow it
                buf.extend(bytes(len(buf)))
            total = have
            try:
                with memoryview(buf) as mv:
                    while total < len(buf):  # fill the buffer (a decompressor returns a little at a time)
                        k = f.readinto(mv[total:])
                        if not k:
                            eof = True
                            break
                        total += k
            except (EOFError, OSError, ValueError) as exc:  # lzma / gzip / bz2: a truncated or corrupt stream
                why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise ValueError(f"{p}: truncated or corrupt {p.suffix.lstrip('.')} file ({why}); "
                                 "decompress it again or fetch a complete copy") from None
            pos += total - have
            cut = total if eof else buf.rfind(b"\n", 0, total) + 1
            if cut == 0:  # no line end yet: read on
                have = total
                continue
            with memoryview(buf) as mv:
                data = mv[:cut]
                blk, lines = parse(data, line, eof)
                del data
            line += lines if lines is not None else buf.count(b"\n", 0, cut)
            if blk is not None:
                blk.file_bytes_done, blk.file_bytes = raw.tell(), st0.st_size
                yield blk
            buf[:total - cut] = buf[cut:total]
            have = total - cut
        if not compressed:
            st1 = os.stat(p)
            if (st1.st_size, st1.st_mtime_ns) != (st0.st_size, st0.st_mtime_ns) or pos != st0.st_size:
                from ..data.textio import _changed

                raise _changed(p, (st0.st_size, st0.st_mtime_ns), (st1.st_size, st1.st_mtime_ns), pos)


#: GNSS text lines parsed at a time by :func:`read_gnss_text_blocks`
GNSS_BLOCK_LINES = 1 << 12


def count_lines(path: Path) -> int:
    """Line ends in the file (plain or compressed), read 1 MiB at a time: an upper bound of its rows - 1."""
    f, raw, _ = open_text(path)
    n = 0
    with raw, f:
        while True:
            b = f.read(1 << 20)
            if not b:
                return n
            n += b.count(b"\n")


def read_gnss_text_blocks(path, *, block_lines: int | None = None) -> GnssFixes:
    """A KF-GINS GNSS file (7 columns, or 13 with velocity) read in two passes
    without the whole text or a whole parsed table in memory: the first pass
    counts the lines (an upper bound of the rows), the second parses
    ``block_lines`` lines at a time straight into the fixes' arrays (the
    layout of :func:`insnav.io.kfgins.read_kfgins_gnss` with ``compact=True``:
    7 float64 per fix; ``t_arrival`` is ``t_valid``).  The checks are the
    whole-file reader's, with its one-line messages naming the file and line:
    the column count of the first line, every line's parse (a block's first
    line numbered in the file), then the times' finiteness over all rows (the
    whole-file order of the messages: a malformed line before a non-finite
    time anywhere).  An empty file is left to the whole-file reader (its own
    message).

    Returns
    -------
    GnssFixes
        Equal to ``read_kfgins_gnss(path, compact=True)``.
    """
    from .kfgins import read_kfgins_gnss

    p = Path(path)
    cap = count_lines(p) + 1
    cols: dict = {}
    n = None
    rows = 0
    file_lines = np.empty(cap, np.int64)

    def parse(data, line, eof):
        nonlocal n, rows
        if n is None and bytes(data).strip():
            n = count_columns(bytes(data), p)
            if n not in (7, 13):
                raise ValueError(f"{p}:1: expected 7 or 13 columns (sow lat lon h std_N std_E std_D"
                                 f" [vN vE vD std_vN std_vE std_vD]), found {n}")
            cols.update(t=np.empty(cap), lat=np.empty(cap), lon=np.empty(cap), h=np.empty(cap),
                        sp=np.empty((cap, 3)))
            if n == 13:
                cols.update(v=np.empty((cap, 3)), sv=np.empty((cap, 3)))
        if n is None:
            return None, None
        a, lines = parse_numeric(data, n, str(p), first_line=line, comma=False)
        k = a.shape[0]
        if rows + k > cap:  # more rows than the first pass counted lines: the file grew in between
            raise ValueError(f"{p}:{line}: the file changed while it was read (more lines than its first pass "
                             f"counted, {cap - 1}); read it again once it is complete")
        r = slice(rows, rows + k)
        cols["t"][r], cols["lat"][r], cols["lon"][r], cols["h"][r] = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
        cols["sp"][r] = a[:, 4:7]
        if n == 13:
            cols["v"][r], cols["sv"][r] = a[:, 7:10], a[:, 10:13]
        file_lines[r] = line + np.arange(k) if lines is None else lines
        rows += k
        return None, (k if lines is None and not eof else None)

    for _ in text_blocks(p, GNSS_BLOCK_LINES if block_lines is None else block_lines, parse):
        pass  # parse keeps no block
    if n is None:
        return read_kfgins_gnss(p, compact=True)
    k = rows
    lines = file_lines[:k]
    origin = RowOrigin(str(p), 1, None if np.array_equal(lines, np.arange(1, k + 1)) else lines.copy())
    del file_lines, lines
    t = cols["t"][:k]
    check_finite_rows(t[:, None], origin, ("sow",))
    nan3 = np.broadcast_to(np.full(3, np.nan), (k, 3))
    v, sv = (cols["v"][:k], cols["sv"][:k]) if n == 13 else (nan3, nan3)
    return GnssFixes(t, t, cols["lat"][:k], cols["lon"][:k], cols["h"][:k], v, cols["sp"][:k], sv, origin=origin)
