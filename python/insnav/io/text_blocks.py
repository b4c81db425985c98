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

__all__ = ["GNSS_BLOCK_LINES", "LINE_BYTES_GUESS", "FileColumn", "count_lines", "open_text", "read_gnss_text_blocks",
           "text_blocks"]

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


class _GnssTextIndex:
    """Where each block of lines of a plain KF-GINS GNSS file lies (the first
    pass of :func:`read_gnss_text_blocks` with ``on_demand=True``): its byte
    offset and length, first file line, first row and row count, and the
    file's size and ``st_mtime_ns`` before that pass.  :meth:`rows` reads a
    span of rows back with plain reads (the very bytes and parser of the first
    pass, so the values are equal bit for bit), the last :attr:`CACHED` blocks
    parsed kept; a file whose size or modification time changed since the first pass
    is a one-line error naming it (the fixes read back would not be the fixes
    checked)."""

    #: parsed blocks kept: a span of the course checks (COURSE_CHECK_BLOCK rows, about 3 blocks) read column
    #: after column parses each block once (2 kept: 873 parses instead of 588 for a run of 288,000 fixes)
    CACHED = 4

    def __init__(self, path: Path, ncols: int, stat: tuple[int, int], offset, nbytes, line, row0, rows):
        self.path, self.ncols, self.stat = path, int(ncols), stat
        self.offset, self.nbytes, self.line = offset, nbytes, line
        self.row0, self.rows_of = row0, rows
        self.cache: dict[int, np.ndarray] = {}
        self.reads = 0  # blocks parsed again (a test's count)

    def held_bytes(self) -> int:
        """Bytes this index holds: its per-block arrays and the parsed blocks kept."""
        return (sum(a.nbytes for a in (self.offset, self.nbytes, self.line, self.row0, self.rows_of))
                + sum(a.nbytes for a in self.cache.values()))

    def _block(self, k: int) -> np.ndarray:
        a = self.cache.get(k)
        if a is not None:
            return a
        st = os.stat(self.path)
        if (st.st_size, st.st_mtime_ns) != self.stat:
            what = (f"size {self.stat[0]} -> {st.st_size} bytes" if st.st_size != self.stat[0] else "modified")
            raise ValueError(f"{self.path}: the GNSS file changed since it was first read ({what}); its fixes are "
                             "read again a block at a time during the run: run again once it is complete")
        with open(self.path, "rb", buffering=0) as f:
            f.seek(int(self.offset[k]))
            data = f.read(int(self.nbytes[k]))
        a, _ = parse_numeric(data, self.ncols, str(self.path), first_line=int(self.line[k]), comma=False)
        if a.shape[0] != int(self.rows_of[k]):  # pragma: no cover - the size and time said it is the same file
            raise ValueError(f"{self.path}:{int(self.line[k])}: the GNSS file changed since it was first read")
        self.reads += 1
        if len(self.cache) >= self.CACHED:
            self.cache.pop(next(iter(self.cache)))
        self.cache[k] = a
        return a

    def rows(self, lo: int, hi: int, cols: slice) -> np.ndarray:
        """Rows ``lo .. hi - 1`` (of the file's fixes), text columns ``cols`` (a new array)."""
        width = len(range(*cols.indices(self.ncols)))
        out = np.empty((max(0, hi - lo), width))
        if hi <= lo:
            return out
        k = int(np.searchsorted(self.row0, lo, side="right")) - 1
        r = lo
        while r < hi:
            a = self._block(k)
            b0 = int(self.row0[k])
            e = min(hi, b0 + a.shape[0])
            out[r - lo:e - lo] = a[r - b0:e - b0, cols]
            r, k = e, k + 1
        return out


class FileColumn:
    """A column of fixes read back from their plain text file on demand
    (:class:`_GnssTextIndex`): rows ``start .. stop - 1`` of the file's
    fixes, one text column (``lat_deg``, ``lon_deg``, ``h_m``: shape (N,)) or
    three (``sigma_pos_n``, ``v_n``, ``sigma_vel_n``: (N, 3)).  Indexing with
    an integer, a slice, an index array or a boolean mask (optionally with a
    column key: ``col[idx, :2]``) reads the rows it needs and returns a
    float64 array; :meth:`view` cuts it without reading; ``np.asarray`` reads
    it whole (a consumer that needs it whole still gets it)."""

    dtype = np.dtype(float)
    #: read by the rows a consumer indexes (:func:`insnav.data.dataset.column` leaves it as it is)
    on_demand = True

    def __init__(self, index: _GnssTextIndex, cols: slice, start: int, stop: int):
        self.index, self.cols, self.start, self.stop = index, cols, int(start), int(stop)
        self.width = len(range(*cols.indices(index.ncols)))

    def __len__(self) -> int:
        return self.stop - self.start

    @property
    def shape(self) -> tuple:
        return (len(self),) if self.width == 1 else (len(self), self.width)

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        return len(self) * self.width

    def view(self, a: int, b: int) -> "FileColumn":
        """Rows ``a .. b - 1`` of this column, nothing read."""
        n = len(self)
        a, b = max(0, min(n, int(a))), max(0, min(n, int(b)))
        return FileColumn(self.index, self.cols, self.start + a, self.start + max(a, b))

    def reshape(self, *shape):
        shape = tuple(shape[0]) if len(shape) == 1 and isinstance(shape[0], tuple) else shape
        if shape == self.shape:
            return self
        return np.asarray(self).reshape(*shape)

    def _read(self, lo: int, hi: int) -> np.ndarray:
        a = self.index.rows(self.start + lo, self.start + hi, self.cols)
        return a[:, 0] if self.width == 1 else a

    def __array__(self, dtype=None, copy=None):
        a = self._read(0, len(self))
        return a if dtype is None else a.astype(dtype, copy=False)

    def __getitem__(self, key):
        rest = ()
        if isinstance(key, tuple):
            key, rest = key[0], key[1:]
        n = len(self)
        if isinstance(key, (int, np.integer)):
            i = int(key) + (n if key < 0 else 0)
            if not 0 <= i < n:
                raise IndexError(f"index {int(key)} is out of bounds for a column of {n} fixes")
            out = self._read(i, i + 1)[0]
        elif isinstance(key, slice):
            a, b, step = key.indices(n)
            if step == 1:
                out = self._read(a, max(a, b))
            else:
                idx = np.arange(a, b, step)
                out = self._read(int(idx.min()), int(idx.max()) + 1)[idx - idx.min()] if idx.size else \
                    self._read(0, 0)
        else:
            idx = np.asarray(key)
            if idx.dtype == bool:
                idx = np.flatnonzero(idx)
            idx = idx.astype(np.int64, copy=False)
            idx = np.where(idx < 0, idx + n, idx)
            if idx.size == 0:
                out = self._read(0, 0)
            else:
                lo, hi = int(idx.min()), int(idx.max()) + 1
                out = self._read(lo, hi)[idx - lo]
        return out[(Ellipsis, *rest)] if rest else out


def read_gnss_text_blocks(path, *, block_lines: int | None = None, on_demand: bool = False) -> GnssFixes:
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

    With ``on_demand`` (the block-by-block run) a plain file's fixes are not
    held: the pass records where each block of lines lies
    (:class:`_GnssTextIndex`: byte offset and length, first line, first row
    and row count, about 40 bytes per :data:`GNSS_BLOCK_LINES` lines) and the
    file's size and ``st_mtime_ns`` before it, and keeps the times only
    (``t_valid``, also ``t_arrival``: 8 bytes per fix); the other columns are
    :class:`FileColumn` objects that read the rows a consumer indexes back
    from the file (a file changed since: a one-line error naming it).  A
    compressed file (``.xz``, ``.gz``, ``.bz2``: no byte offsets to seek to)
    is held whole, as without ``on_demand``.

    Returns
    -------
    GnssFixes
        Equal to ``read_kfgins_gnss(path, compact=True)`` (column by column
        when read on demand).
    """
    from .kfgins import read_kfgins_gnss

    p = Path(path)
    on_demand = bool(on_demand) and p.suffix.lower() not in (".xz", ".lzma", ".gz", ".bz2")
    st0 = os.stat(p) if on_demand else None  # before the passes: a change after it fails every read back
    cap = count_lines(p) + 1
    cols: dict = {}
    n = None
    rows = 0
    pos = 0  # the byte offset of the next block
    blocks: list[tuple[int, int, int, int, int]] = []  # (offset, bytes, first line, first row, rows)
    # the file lines of the rows: (first row, first line, rows) per run of consecutive lines, an array per block
    # of other lines (blank lines inside it): no array of a line per row unless some line is not a row
    spans: list = []

    def parse(data, line, eof):
        nonlocal n, rows, pos
        off = pos
        pos += len(data)
        if n is None and bytes(data).strip():
            n = count_columns(bytes(data), p)
            if n not in (7, 13):
                raise ValueError(f"{p}:1: expected 7 or 13 columns (sow lat lon h std_N std_E std_D"
                                 f" [vN vE vD std_vN std_vE std_vD]), found {n}")
            cols.update(t=np.empty(cap))
            if not on_demand:
                cols.update(lat=np.empty(cap), lon=np.empty(cap), h=np.empty(cap), sp=np.empty((cap, 3)))
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
        cols["t"][r] = a[:, 0]
        if on_demand:
            if k:
                blocks.append((off, len(data), line, rows, k))
        else:
            cols["lat"][r], cols["lon"][r], cols["h"][r] = a[:, 1], a[:, 2], a[:, 3]
            cols["sp"][r] = a[:, 4:7]
            if n == 13:
                cols["v"][r], cols["sv"][r] = a[:, 7:10], a[:, 10:13]
        if lines is not None:
            spans.append((rows, np.asarray(lines, np.int64).copy(), k))
        elif spans and not isinstance(spans[-1][1], np.ndarray) and spans[-1][1] + spans[-1][2] == line:
            spans[-1] = (spans[-1][0], spans[-1][1], spans[-1][2] + k)
        elif k:
            spans.append((rows, line, k))
        rows += k
        return None, (k if lines is None and not eof else None)

    for _ in text_blocks(p, GNSS_BLOCK_LINES if block_lines is None else block_lines, parse):
        pass  # parse keeps no block
    if n is None:
        return read_kfgins_gnss(p, compact=True)
    k = rows
    if not spans or (len(spans) == 1 and not isinstance(spans[0][1], np.ndarray) and spans[0][1] == 1):
        origin = RowOrigin(str(p), 1, None)
    else:
        lines = np.empty(k, np.int64)
        for r0, ln, m in spans:
            lines[r0:r0 + m] = ln if isinstance(ln, np.ndarray) else ln + np.arange(m)
        origin = RowOrigin(str(p), 1, None if np.array_equal(lines, np.arange(1, k + 1)) else lines)
    t = cols["t"][:k]
    check_finite_rows(t[:, None], origin, ("sow",))
    nan3 = np.broadcast_to(np.full(3, np.nan), (k, 3))
    if on_demand:
        b = np.array(blocks, np.int64).reshape(-1, 5).T
        idx = _GnssTextIndex(p, n, (st0.st_size, st0.st_mtime_ns), *(np.ascontiguousarray(x) for x in b))

        def col(c):
            return FileColumn(idx, c, 0, k)

        v, sv = (col(slice(7, 10)), col(slice(10, 13))) if n == 13 else (nan3, nan3)
        return GnssFixes(t, t, col(slice(1, 2)), col(slice(2, 3)), col(slice(3, 4)), v, col(slice(4, 7)), sv,
                         origin=origin)
    v, sv = (cols["v"][:k], cols["sv"][:k]) if n == 13 else (nan3, nan3)
    return GnssFixes(t, t, cols["lat"][:k], cols["lon"][:k], cols["h"][:k], v, cols["sp"][:k], sv, origin=origin)
