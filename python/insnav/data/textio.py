"""Numeric text tables through the compiled reader and writer
(``cpp/include/insnav/io/text_table.hpp``): the solution CSV and KF-GINS
layouts are written, and the KF-GINS and insnav CSV files read, in C++ with
the GIL released."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

__all__ = ["write_text_columns", "threads", "read_bytes", "read_text", "file_bytes", "mapped_bytes", "count_columns",
           "parse_numeric", "FileChangedError"]


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


# --------------------------------------------------------------------------- reading

_OPENERS = {".xz": "lzma", ".lzma": "lzma", ".gz": "gzip", ".bz2": "bz2"}


class FileChangedError(ValueError):
    """An input file changed (size or modification time) while it was read."""


def _stamp(st) -> tuple[int, int]:
    return st.st_size, st.st_mtime_ns


def _changed(p: Path, before, after, got: int | None = None) -> FileChangedError:
    what = f"size {before[0]} -> {after[0]} bytes" if before[0] != after[0] else (
        f"{got} of {before[0]} bytes read" if got is not None and got != before[0] else "modified")
    return FileChangedError(f"{p}: the file changed while it was read ({what}); read it again once it is "
                            "complete (is another program still writing it?)")


def _read_whole(p: Path):
    """The bytes of the plain file ``p`` (a bytes-like object), refused when
    its size or modification time changes during the read.

    The file is read, never memory-mapped: a map of a file that another
    program truncates meanwhile faults (SIGBUS) on the first page past the new
    end.  Large files are read into an anonymous map whose pages are made at
    once (``MAP_POPULATE``: one call instead of a page fault per 4 KiB; 76 MB
    in 50 ms of CPU in a fresh process here, 58 ms into a ``bytes``, 57-108 ms
    with huge pages, whose compaction stalls on a busy machine)."""
    import mmap

    with open(p, "rb", buffering=0) as f:
        st0 = _stamp(os.fstat(f.fileno()))
        size = st0[0]
        if size < MAP_MIN_BYTES or not hasattr(mmap, "MAP_ANONYMOUS"):
            parts, got = [], 0
            while got <= size:  # one byte more than the size: a file that grew meanwhile shows it
                b = f.read(size + 1 - got)
                if not b:
                    break
                parts.append(b)
                got += len(b)
            buf = parts[0] if len(parts) == 1 else b"".join(parts)
        else:
            buf = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | getattr(mmap, "MAP_POPULATE", 0))
            view, got = memoryview(buf), 0
            while got < size:
                k = f.readinto(view[got:])
                if not k:
                    break
                got += k
            view.release()
            got += len(f.read(1))  # a file that grew meanwhile
        st1 = _stamp(os.fstat(f.fileno()))
    if st1 != st0 or got != size:
        raise _changed(p, st0, st1, got)
    return buf


def read_text(path, encoding: str = "utf-8", errors: str = "replace") -> str:
    """:func:`read_bytes` decoded (a small input such as a configuration file)."""
    return bytes(read_bytes(path)).decode(encoding, errors)


def read_bytes(path) -> bytes:
    """The whole file, decompressed when it ends in ``.xz``/``.lzma``/``.gz``/``.bz2``.

    The file is read once (never memory-mapped) and refused when its size or
    modification time changes during the read.

    Raises
    ------
    FileNotFoundError
        Naming the file.
    FileChangedError
        (a ValueError) One line naming the file when it changed while it was read.
    ValueError
        One line naming the file when the compressed stream is truncated or corrupt.
    """
    p = Path(path)
    if not p.is_file():
        if p.is_dir():  # said as such: "No such file" misleads when the path is a folder
            exc = IsADirectoryError(f"{p} is a folder, not a file")
            exc.strerror = "Is a directory"
        elif p.exists():  # a FIFO or a device: never read (a FIFO would wait for a writer)
            exc = OSError(f"{p} is not a regular file")
            exc.strerror = "not a regular file"
        else:
            exc = FileNotFoundError(f"{p} does not exist")
            exc.strerror = "No such file or directory"
        exc.filename = str(p)
        raise exc
    kind = _OPENERS.get(p.suffix.lower())
    raw = _read_whole(p)
    if kind is None:
        return bytes(raw) if not isinstance(raw, bytes) else raw
    import bz2
    import gzip
    import lzma
    import zlib

    try:
        if kind == "lzma":
            d = lzma.LZMADecompressor()
            out = d.decompress(raw)
            if not d.eof:
                raise EOFError("the stream ends before its end marker")
            return out
        if kind == "gzip":
            return gzip.decompress(raw)
        d = bz2.BZ2Decompressor()
        out = d.decompress(raw)
        if not d.eof:
            raise EOFError("the stream ends before its end marker")
        return out
    except (EOFError, lzma.LZMAError, OSError, zlib.error, ValueError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"{p}: truncated or corrupt {p.suffix.lstrip('.')} file ({why}); "
                         "decompress it again or fetch a complete copy") from None


#: plain files from this size on are read by :func:`file_bytes` into an anonymous populated map [bytes]
MAP_MIN_BYTES = 1 << 20


@contextlib.contextmanager
def file_bytes(path):
    """The whole file as a read-only bytes-like object, for the length of the
    ``with`` block, without the copy into a ``bytes`` that :func:`read_bytes`
    makes of a large file (the parser reads the buffer in place).  Same errors
    as :func:`read_bytes`; the file is read, not mapped, so a file truncated
    meanwhile is an error, never a SIGBUS."""
    p = Path(path)
    if p.suffix.lower() not in _OPENERS and p.is_file():
        yield _read_whole(p)
    else:
        yield read_bytes(p)


#: the former name of :func:`file_bytes` (the file used to be memory-mapped)
mapped_bytes = file_bytes


def count_columns(data: bytes, source, comma: bool = False) -> int:
    """Values on the first non-blank line."""
    start = 0
    while start < len(data):
        end = data.find(b"\n", start)
        end = len(data) if end < 0 else end
        line = data[start:end]
        if comma:
            line = line.replace(b",", b" ")
        n = len(line.split())
        if n:
            return n
        start = end + 1
    raise ValueError(f"{source}:1: file is empty")


def parse_numeric(data, ncols: int, source, *, first_line: int = 1, comma: bool = True, keep: int | None = None,
                  allow_extra: bool = False, names=None, groups=None):
    """Parse numeric text (C++ ``std::from_chars`` on two threads, the GIL released; the
    lines are counted on the same threads).

    Parameters
    ----------
    data : bytes or str
        One record per line; values separated by whitespace (and with
        ``comma`` by commas); blank lines are skipped.
    ncols : int
        Values a row must have (``allow_extra``: at least).
    source : str
        File name for the messages.
    first_line : int
        File line of ``data``'s first line (2 after a header).
    keep : int, optional
        Only the first ``keep`` values of each row are returned (default ``ncols``).
    names : sequence of str, optional
        Column names for the messages.
    groups : sequence of int, optional
        Widths adding up to ``keep``: the kept values go to one array per
        group, parsed in place (``(N,)`` for a width of 1, else ``(N, width)``).

    Returns
    -------
    (ndarray (N, keep) or tuple of ndarray, ndarray (N,) of int or None)
        The rows (or the tuple of groups) and, when a blank line was skipped,
        the file line of each.

    Raises
    ------
    ValueError
        ``"<source>:<line>: expected <n> columns, found <k>"`` (with a
        truncation hint for an incomplete last line) or ``"<source>:<line>:
        not a number: '<text>' in column <j>"``, for the first bad row.
    """
    from .. import _core

    if isinstance(data, str):
        data = data.encode("utf-8", "replace")
    keep = ncols if keep is None else keep
    a, lines, err = _core.parse_text(data, ncols, keep, allow_extra, comma, first_line, threads(),
                                     None if groups is None else list(groups))
    if err is not None:
        data = bytes(data)
        kind, line, found, col, tb, te, line_end = err
        if kind == 1:
            hint = ""
            if found < ncols and not data.rstrip(b" \t").endswith(b"\n") and not data[line_end:].strip():
                hint = " (incomplete last line: file truncated?)"
            raise ValueError(f"{source}:{line}: expected {ncols} columns, found {found}{hint}")
        tok = data[tb:te].decode("utf-8", "replace")
        where = f"{names[col]!r}" if names is not None and col < len(names) else f"{col + 1}"
        raise ValueError(f"{source}:{line}: not a number: {tok!r} in column {where}")
    return a, lines
