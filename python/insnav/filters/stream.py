"""The loosely coupled forward run without the recording in memory: the IMU file
read, filtered and written block by block (``insnav run`` on long recordings).

The batch path (:func:`insnav.run`) holds the whole IMU text, its arrays and
the whole solution in memory, so its memory grows with the recording.  Here
the IMU text is read in blocks of :data:`BLOCK_LINES` lines (plain reads, never a
memory map: a file truncated while it is read is an error naming it, never a
SIGBUS), each block is parsed by the compiled reader
(``cpp/include/insnav/io/text_table.hpp``), pushed through the compiled loose
engine (``cpp/include/insnav/engine/loose_stream.hpp``: the batch engine's
very loop, cut into blocks, the GIL released, no allocation per sample), and
its output rows (at the ``--output-rate`` decimation) are converted and
appended to a temporary CSV file beside the destination, renamed into place
only when the whole run succeeded.  An ``.npz`` destination gets each column
appended to its own scratch file (:class:`insnav._npz.NpzColumns`, in a
folder beside it), the members assembled into the temporary file at the end
and the scratch files removed, whatever happened.  A ``.parquet`` destination
gets one row group per :data:`~insnav.filters.solution.PARQUET_ROW_GROUP_ROWS`
rows (a buffer of one row group, allocated once), ``--out-format kfgins`` the
rows appended to the temporary KF-GINS files in the folder.  The next block is read and parsed on a
reader thread while this one is filtered, and the rows are formatted on a
writer thread while the next block is filtered (the engine's two row buffers
are used in turn).  The GNSS fixes are given to the engine a block at a
time (``_core.LooseStream.push_gnss``: those up to the block's last sample)
and their per-record outputs taken after each block, appended to the
temporary innovations sidecar and reduced to the running statistics the
summary and the health verdict need (:class:`_Innovations`), so the engine
holds the fixes of about one block.  Memory is a few blocks of IMU samples,
rows and records, the IMU summed to 10 Hz for the input checks, at most
:data:`CHECK_MAX_ROWS` rows (about 1.8 h, 3.7 MB; a longer recording's is summed
further, to 5 Hz, 2.5 Hz, ...: :class:`_Coarse`), and the GNSS fixes' times.
A plain KF-GINS GNSS file is read in two passes, a block of lines at a time
(:func:`read_gnss_text_blocks` with ``on_demand``): the passes keep the
times (8 bytes per fix, the one part that still grows with the recording)
and where each block of lines lies (its byte offset, first line and rows,
and the file's size and modification time); the other columns are
:class:`insnav.io.text_blocks.FileColumn` objects whose rows are read back
from the file, at most four parsed blocks kept, as their consumers index
them: the loader's cut (views, nothing read), the sanitizer
(:func:`insnav.filters.sanitize.sanitize_gnss_blocks`, a block at a time;
when it drops a fix, the kept fixes are copied and held), the engine's
rows (:data:`GNSS_PUSH_MAX` fixes at a time as the IMU blocks advance), and
at the end the input checks (:func:`insnav.data.checks.check_dataset`: the
range, sigma, jump and velocity checks a block of fixes at a time, the
course checks a block of :data:`insnav.data.checks.COURSE_CHECK_BLOCK`
fixes), the engine's outage cycle taking the median spacing a block at a
time (:func:`insnav._median.spacing_median`).  A GNSS file whose size or
modification time changed since its first pass stops the run with a
one-line error naming it (the temporary output removed, an earlier output
left as it was).  A compressed GNSS file (``.xz``, ``.gz``, ``.bz2``: no
offsets to seek to) is held whole, 7 float64 per fix, and so are the
fixes of a ``--format csv`` run (its GNSS reader's table)
(``bench/cli_end_to_end.py`` and ``bench/stream_rss_stages.py`` measure a
synthesised day).

The rows, the per-record outputs (innovations sidecar), the summary and the
health verdict equal the batch run's, and the CSV, Parquet and KF-GINS files
are byte for byte the batch run's; an ``.npz`` holds the batch run's members,
dtypes and values bit for bit (``tests/test_stream.py``,
``tests/test_stream_npz.py``, ``tests/test_stream_outputs.py``,
``tests/test_stream_gnss_push.py``); the health verdict's mean NIS ratio
sums the NIS exactly (:func:`_fsum_add`) where the batch run sums them
pairwise (numpy): the two agree to about 1e-15 relative, and the report
prints 3 digits.  The input checks differ in two
documented ways: the IMU sanitizer's block scan takes the nominal interval
from the first block (a later block whose median interval differs, an IMU gap,
a repeated time or an implausible rate hands the run to the batch path, whose
sanitizer repairs or names it), and the unit and time-base checks
(:func:`insnav.data.checks.check_dataset`) see the IMU increments summed to
10 Hz (beyond :data:`CHECK_MAX_ROWS` rows to 5 Hz, 2.5 Hz, ...).  Whatever
the stream cannot reproduce exactly (a sanitizer repair, a non-finite row,
an unhealthy run, a failed check, a GNSS record whose cut changes the
set-up) makes :func:`stream_loose_csv` raise :class:`Fallback`
with the reason, and ``insnav run`` then runs the batch path, whose result and messages are the
reference.  The RTS smoother needs the whole run and always takes the batch
path.

``insnav run --format csv`` streams the same way (:func:`stream_csv_loose`):
the generic IMU CSV is read in the same blocks, each mapped by the ``[imu]``
table (columns or header names, units, axes and mounting, time base; the very
parser and conversion of :func:`insnav.io.imu_csv.read_imu_csv`) and
integrated to increments (:func:`imu_csv_blocks`: the trapezoid's interval
over a block boundary from the block before), so the samples equal the
whole-file reader's bit for bit.  Two more documented differences: the
alignment (:func:`insnav.ins.align.align`) runs on the record's first blocks,
as many as it reads, with their median interval, and the loader's unit,
axis, sign and time-base checks see the whole record summed to 10 Hz (as
:func:`stream_loose_csv`'s, further beyond :data:`CHECK_MAX_ROWS` rows; the
unit checks also see the first blocks at full rate).  A ``tick_ms`` log with
its str2str tag (the tick map is fitted over the whole record) and an
alignment that needs more than :data:`ALIGN_MAX_SAMPLES` samples take the
batch path.
"""
from __future__ import annotations

import dataclasses
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import _core
from .._atomic import interrupts_deferred
from .._imu_scan import scan_imu
from .._median import median
from .._threads import Job
from ..data.dataset import Dataset, GnssFixes, ImuData, RowOrigin, check_finite_rows, column
from ..data.textio import count_columns, parse_numeric, threads
from ..io.text_blocks import GNSS_BLOCK_LINES, LINE_BYTES_GUESS, read_gnss_text_blocks, text_blocks  # noqa: F401 (re-exported)
from .solution import Solution

__all__ = ["BLOCK_LINES", "STREAM_SUFFIXES", "imu_text_blocks", "imu_csv_blocks", "stream_loose_csv", "stream_csv_loose", "StreamResult",
           "Fallback", "stream_unsupported", "csv_stream_unsupported",
           "StreamedSolution"]

#: IMU lines per block (2^16: about 7 MB of KF-GINS text)
BLOCK_LINES = 1 << 16
#: the rate of the summed IMU the input checks see [Hz]
CHECK_RATE_HZ = 10.0
#: the most rows of the summed IMU the input checks keep (about 1.8 h at 10 Hz, 3.7 MB): a longer
#: recording's record is halved to 5 Hz, then 2.5 Hz, ... (:class:`_Coarse`; a day: rows of 1.6 s, the
#: course checks' heading grid as wide).  2^18 rows (15 MB, full after 7.3 h) made the peak RSS of a 24 h
#: run 13 MB above a 1 h run's; each row's rotation is exact at its time (the sums of its samples), and
#: the time-offset and gyro-against-course checks interpolate the heading linearly between rows
#: (:func:`insnav.data.checks.heading_grid_step`)
CHECK_MAX_ROWS = 1 << 16
#: the most GNSS fixes converted to the engine's rows at a time (a block's fixes are given to the engine
#: before it runs, its records taken after it: the engine holds the fixes of about one block)
GNSS_PUSH_MAX = 1 << 12


class Fallback(Exception):
    """The stream cannot reproduce the batch run exactly here: the reason (one line).

    ``batch_names_it``: the batch path will most likely stop with its own
    one-line error (a failed input check, a malformed set-up), so ``insnav run
    --stream auto`` adds no note to it."""

    def __init__(self, why: str, *, batch_names_it: bool = False):
        super().__init__(why)
        self.batch_names_it = batch_names_it


@dataclass
class ImuBlock:
    """One block of IMU samples, the file line of its first row, and how far
    into the file (its bytes on disk, compressed or not) the block ends."""

    t: np.ndarray
    dtheta_b: np.ndarray
    dv_b: np.ndarray
    origin: RowOrigin
    file_bytes_done: int = 0
    file_bytes: int = 0


def _text_blocks(path, block_lines, parse):
    """:func:`insnav.io.text_blocks.text_blocks` with the stream's IMU block (``BLOCK_LINES``) by default."""
    return text_blocks(path, BLOCK_LINES if block_lines is None else block_lines, parse)


def imu_text_blocks(path, ncols: int | None = None, *, block_lines: int | None = None, names=None):
    """The rows of a whitespace-separated IMU text file (``t dtheta_xyz dv_xyz``,
    KF-GINS's layout; extra columns ignored), block by block.

    Parameters
    ----------
    path : str or Path
        Plain, ``.xz``, ``.gz`` or ``.bz2`` (decompressed as it is read).
    ncols : int, optional
        Columns per line (default: those of the first line, at least 7).
    block_lines : int
        Lines per block (about).
    names : sequence of str, optional
        Column names for the messages.

    Yields
    ------
    ImuBlock
        ``t`` (n,) [s], ``dtheta_b`` (n, 3) [rad], ``dv_b`` (n, 3) [m/s] and the
        rows' file lines (``origin``), right across blocks.

    Raises
    ------
    ValueError
        ``"<file>:<line>: ..."`` for a malformed line (a truncated last line
        says so), a truncated compressed stream, or a file that changed while
        it was read (:class:`insnav.data.textio.FileChangedError`).
    """
    p = Path(path)
    n = ncols

    def parse(data, line, eof):
        nonlocal n
        if n is None and bytes(data).strip():
            n = count_columns(bytes(data), p)
            if n < 7:
                raise ValueError(f"{p}:1: expected at least 7 columns (sow, dtheta xyz, dvel xyz), found {n}")
        if n is None:
            return None, None
        parts, lines = parse_numeric(data, n, str(p), first_line=line, comma=False, keep=7, names=names,
                                     groups=(1, 3, 3))
        rows = len(parts[0])
        # the lines of this block: its rows when none was blank (the parser counted them), else counted
        blk = ImuBlock(parts[0], parts[1], parts[2], RowOrigin(str(p), line, lines)) if rows else None
        return blk, (rows if lines is None and not eof else None)

    return _text_blocks(path, block_lines, parse)


def imu_csv_blocks(path, fmt, *, week: int | None = None, t_offset_s: float = 0.0, block_lines: int | None = None):
    """The samples of a generic IMU CSV (:mod:`insnav.io.imu_csv`: the
    ``[imu]`` table's columns, units, axes and time base) as increments, block
    by block: the very parser, time base and integration of
    :func:`insnav.io.imu_csv.read_imu_csv` and ``ImuSamples.to_increments``
    (the time reference from the first time field, the trapezoid over a block
    boundary from the last sample of the block before), so the values equal
    the whole-file reader's bit for bit.

    Parameters
    ----------
    path : str or Path
        Plain, ``.xz``, ``.gz`` or ``.bz2``.
    fmt : insnav.io.imu_csv.ImuCsvFormat
        The mapping (validated); not a ``tick_ms`` log (its time map needs the whole record).
    week : int, optional
        GPS week for ``time = "gps_sow"`` when ``fmt.gps_week`` is None.
    t_offset_s : float
        Subtracted from the GPS times (``604800 week``: seconds of week) [s].
    block_lines : int
        Lines per block (about).

    Yields
    ------
    ImuBlock
        Times [s], ``dtheta_b`` [rad], ``dv_b`` [m/s] in the body frame and the rows' file lines.

    Raises
    ------
    insnav.io.imu_csv.ImuFileError
        A malformed line or a time that does not increase (file and line).
    Fallback
        The first block's median interval contradicts ``rate_hz`` (the whole-file reader decides).
    """
    from ..io.imu_csv import CsvLineParser, ImuFileError, SampleConverter

    path = os.fspath(path)
    if fmt.uses_tick:
        raise ValueError("imu_csv_blocks: a tick_ms log needs the whole record (read_imu_csv)")
    week = fmt.gps_week if fmt.gps_week is not None else week
    parser = CsvLineParser(path, fmt)
    conv = SampleConverter(path, fmt, week)
    st = dict(k=0, raw=None, line=0, prev=None)  # samples so far; the last raw time, its line; the last sample

    def parse(data, line, eof):
        text = bytes(data)
        nlines = text.count(b"\n")
        a, lines, t_tok, _ = parser.feed(text, line)  # the block's lines as one text
        m = len(a)
        if not m:
            return None, nlines
        if t_tok is None:  # no time column: the sample counter
            a = np.column_stack([np.arange(st["k"], st["k"] + m, dtype=float), a])
        t_raw = a[:, 0]
        bad = np.flatnonzero(np.diff(t_raw) <= 0)
        if st["raw"] is not None and not t_raw[0] > st["raw"]:
            raise ImuFileError(path, int(lines[0]), parser.not_increasing(t_raw[0], st["line"], st["raw"]))
        if bad.size:
            k = int(bad[0]) + 1
            raise ImuFileError(path, int(lines[k]), parser.not_increasing(t_raw[k], lines[k - 1], t_raw[k - 1]))
        first = st["k"] == 0
        t_s = conv.times(t_tok, t_raw)
        if first:
            wrong = conv.rate_mismatch(t_s)
            if wrong:
                raise Fallback(f"the first block's interval contradicts rate_hz ({wrong[:60]}...)", batch_names_it=True)
        st["k"] += m
        st["raw"], st["line"] = float(t_raw[-1]), int(lines[-1])
        t_s = t_s + float(fmt.time_offset_s)
        acc_b, gyro_b = conv.body(a)
        t = (conv.t_ref - t_offset_s) + t_s  # as ImuSamples.to_increments
        if fmt.samples == "increment":
            blk = ImuBlock(t, gyro_b, acc_b, RowOrigin(path, lines=lines))
        else:  # the interval (t_prev, t] of each sample, the last of the block before included
            prev, st["prev"] = st["prev"], (t_s[-1:], acc_b[-1:], gyro_b[-1:])
            if prev is not None:
                t_s, acc_b, gyro_b = (np.concatenate([p, x]) for p, x in zip(prev, (t_s, acc_b, gyro_b)))
            else:
                t, lines = t[1:], lines[1:]
            dt = np.diff(t_s)[:, None]
            if fmt.samples == "mean_rate":
                dth, dv = gyro_b[1:] * dt, acc_b[1:] * dt
            else:
                dth = 0.5 * (gyro_b[1:] + gyro_b[:-1]) * dt
                dv = 0.5 * (acc_b[1:] + acc_b[:-1]) * dt
            if not len(t):
                return None, nlines
            blk = ImuBlock(np.ascontiguousarray(t), dth, dv, RowOrigin(path, lines=lines))
        return blk, nlines

    return _text_blocks(path, block_lines, parse)


class _Prefetch:
    """The blocks of a generator read one ahead on a background thread, so
    that reading and parsing the next block (the GIL released in the file
    read and the parser) overlap the filtering of this one (the GIL released
    in the engine) on a second core.  An exception of the reader is raised
    where its block would have been; :meth:`close` stops the thread."""

    _END = object()

    def __init__(self, gen, depth: int = 1):
        import queue
        import threading

        self._gen = gen
        self._done = False
        self._q = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, name="insnav-imu-reader", daemon=True)
        self._t.start()

    def _put(self, item) -> bool:
        import queue

        while not self._stop.is_set():
            try:
                self._q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _run(self) -> None:
        try:
            for item in self._gen:
                if not self._put(item):
                    return
            self._put(self._END)
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer
            self._put(exc)
        finally:
            self._gen.close()

    def __iter__(self):
        return self

    def __next__(self):
        if self._done:  # the end was taken already: a later call must not wait on the empty queue
            raise StopIteration
        item = self._q.get()
        if item is self._END:
            self._done = True
            raise StopIteration
        if isinstance(item, BaseException):
            raise item
        return item

    def close(self) -> None:
        self._stop.set()
        self._t.join()


#: the solution formats written block by block (and ``--out-format kfgins``: the KF-GINS layout)
STREAM_SUFFIXES = (".csv", ".npz", ".parquet")
#: the output layouts: insnav's solution file (by its suffix) or KF-GINS's folder of text files
OUT_FORMATS = ("insnav", "kfgins")


def stream_unsupported(cfg, *, out_suffix: str, out_format: str = "insnav") -> str | None:
    """Why a run cannot take the streaming path (None: it can): the loose
    ekf, rbukf or ukf forward run (15 or 21 states) written as CSV, npz,
    Parquet or the KF-GINS layout, without the smoother, vehicle constraints,
    self-calibration states, filter options or TDCP."""
    if out_format not in OUT_FORMATS:
        return f"the block-by-block writer writes {' and '.join(OUT_FORMATS)} output, not {out_format!r}"
    if out_format == "insnav" and out_suffix.lower() not in STREAM_SUFFIXES:
        return f"the block-by-block writer writes {', '.join(STREAM_SUFFIXES)} files and the KF-GINS layout"
    if cfg.smooth:
        return "the RTS smoother needs the whole run"
    if cfg.coupling != "loose" or cfg.filter not in ("ekf", "rbukf", "ukf") or cfg.layout not in (15, 21):
        return f"filter {cfg.filter} {cfg.coupling} with {cfg.layout} states runs whole (the stream: loose ekf, " \
               "rbukf, ukf on 15 or 21 states)"
    if cfg.constraints.use or cfg.constraints.standstill_q_scale != 1.0:
        return "the vehicle constraints and the standstill level are derived from the whole IMU record"
    if cfg.lever_arm.estimate or cfg.lever_arm.estimate_odometer or cfg.time.estimate_offset:
        return "the self-calibration states run in the batch engine"
    if cfg.options or cfg.tdcp.enabled:
        return "the filter options and TDCP run in the batch engine"
    return None


class _Coarse:
    """The IMU summed over windows for the input checks, in memory bounded by
    ``max_rows`` whatever the recording's length: the first sample alone,
    then windows of ``k`` samples (``k * merge`` once the record was
    halved), each row the time of its window's last sample and its summed
    increments.

    Up to ``max_rows`` rows it is the IMU summed to :data:`CHECK_RATE_HZ`
    exactly (the sums of each window's samples in their order).  A record
    that would hold more is halved in place: the rows after the first one
    are summed in pairs (an odd last row waits for its partner), and from
    then on every row sums twice as many samples (5 Hz, then 2.5 Hz, ...), so
    the checks see at most ``max_rows`` rows (about 3.7 MB at the default
    :data:`CHECK_MAX_ROWS`).  The arrays are sized once from the expected
    sample count (grown by half when that was too small), never beyond
    ``max_rows`` + 2 rows."""

    def __init__(self, k: int, expected_samples: int = 0, max_rows: int | None = None):
        self.k = max(1, int(k))
        self.max_rows = max(8, int(CHECK_MAX_ROWS if max_rows is None else max_rows))
        cap = min(max(64, int(1.02 * expected_samples / self.k) + 64), self.max_rows + 2)
        self.t, self.dth, self.dv = np.empty(cap), np.empty((cap, 3)), np.empty((cap, 3))
        self.n = 0
        self.merge = 1  # windows of k samples per row (after the first): doubled at each halving
        self.started = False
        self.pend_n = 0  # samples in the window of k not yet complete, their time and sums
        self.pend_t = 0.0
        self.pend_dth, self.pend_dv = np.zeros(3), np.zeros(3)
        self.rows_n = 0  # windows of k in the row not yet complete (merge > 1), their time and sums
        self.rows_t = 0.0
        self.rows_dth, self.rows_dv = np.zeros(3), np.zeros(3)

    @property
    def nbytes(self) -> int:
        """The bytes of the record's arrays (what grows with the length, up to ``max_rows``)."""
        return self.t.nbytes + self.dth.nbytes + self.dv.nbytes

    def _grow(self, cap: int) -> None:
        for name in ("t", "dth", "dv"):
            old = getattr(self, name)
            new = np.empty((cap,) + old.shape[1:])
            new[:self.n] = old[:self.n]
            setattr(self, name, new)

    def _store(self, t, dth, dv) -> None:
        """Rows appended as they are (the arrays grown by half, at most to ``max_rows`` + 2 rows)."""
        m = len(t)
        if self.n + m > len(self.t):
            self._grow(min(max(self.n + m, int(1.5 * len(self.t))), self.max_rows + 2))
        self.t[self.n:self.n + m] = t
        self.dth[self.n:self.n + m] = dth
        self.dv[self.n:self.n + m] = dv
        self.n += m

    def _halve(self) -> None:
        """Rows 1, 2, ... summed in pairs in place (an odd last one: the row begun), the windows doubled."""
        if len(self.t) < self.max_rows + 2:  # from now on the arrays are full size: their final size
            self._grow(self.max_rows + 2)
        m = (self.n - 1) // 2
        if (self.n - 1) % 2:  # the odd last row waits for its partner
            r = self.n - 1
            self.rows_n, self.rows_t = self.merge, float(self.t[r])
            self.rows_dth, self.rows_dv = self.dth[r].copy(), self.dv[r].copy()
        for x in (self.dth, self.dv):
            x[1:1 + m] = x[1:1 + 2 * m:2] + x[2:2 + 2 * m:2]
        self.t[1:1 + m] = self.t[2:2 + 2 * m:2]
        self.n = 1 + m
        self.merge *= 2

    def _stored(self, t, dth, dv) -> None:
        """Complete rows appended; a record then over ``max_rows`` rows halved."""
        self._store(t, dth, dv)
        if self.n > self.max_rows:
            self._halve()

    def _push(self, t, dth, dv) -> None:
        """Complete windows of k samples: stored as they are, or (after a halving) summed ``merge`` at a time."""
        t, dth, dv = np.asarray(t, float), np.asarray(dth, float), np.asarray(dv, float)
        while len(t):
            f = self.merge
            if self.rows_n:  # the row begun earlier (merge > 1)
                take = min(f - self.rows_n, len(t))
                self.rows_n += take
                self.rows_t = float(t[take - 1])
                self.rows_dth = self.rows_dth + dth[:take].sum(axis=0)
                self.rows_dv = self.rows_dv + dv[:take].sum(axis=0)
                t, dth, dv = t[take:], dth[take:], dv[take:]
                if self.rows_n < f:
                    return
                self.rows_n = 0
                self._stored([self.rows_t], self.rows_dth[None, :], self.rows_dv[None, :])
                continue
            m = min(len(t) // f, self.max_rows + 1 - self.n)  # rows (n <= max_rows here: room for one)
            if m == 0:  # fewer than f windows: a row begun
                self.rows_n, self.rows_t = len(t), float(t[-1])
                self.rows_dth, self.rows_dv = dth.sum(axis=0), dv.sum(axis=0)
                return
            if f == 1:
                self._stored(t[:m], dth[:m], dv[:m])
            else:
                self._stored(t[f - 1:m * f:f], dth[:m * f].reshape(-1, f, 3).sum(axis=1),
                             dv[:m * f].reshape(-1, f, 3).sum(axis=1))
            t, dth, dv = t[m * f:], dth[m * f:], dv[m * f:]

    def add(self, t, dth, dv) -> None:
        if not self.started:  # the first sample alone: the checks see the IMU span's start
            self.started = True
            self._store(t[:1], dth[:1], dv[:1])
            t, dth, dv = t[1:], dth[1:], dv[1:]
        k = self.k
        if self.pend_n:  # the window begun in an earlier block
            take = min(k - self.pend_n, len(t))
            if take:
                self.pend_n += take
                self.pend_t = float(t[take - 1])
                self.pend_dth += dth[:take].sum(axis=0)
                self.pend_dv += dv[:take].sum(axis=0)
                t, dth, dv = t[take:], dth[take:], dv[take:]
            if self.pend_n < k:
                return
            self.pend_n = 0
            self._push([self.pend_t], self.pend_dth[None, :], self.pend_dv[None, :])
        m = (len(t) // k) * k
        if m:
            self._push(t[k - 1:m:k], dth[:m].reshape(-1, k, 3).sum(axis=1), dv[:m].reshape(-1, k, 3).sum(axis=1))
        if m < len(t):
            self.pend_n = len(t) - m
            self.pend_t = float(t[-1])
            self.pend_dth = dth[m:].sum(axis=0)
            self.pend_dv = dv[m:].sum(axis=0)

    def grid_step(self) -> float:
        """The course checks' heading grid step for this record [s]: one point per row
        (:func:`insnav.data.checks.heading_grid_step`; 0.1 s, the whole-file checks', until halved)."""
        from ..data.checks import _HEADING_GRID_S

        return _HEADING_GRID_S * self.merge

    def imu(self, source: str) -> ImuData:
        """The summed IMU (the last, incomplete window too): views of the arrays."""
        if self.pend_n:
            self.pend_n = 0
            self._push([self.pend_t], self.pend_dth[None, :], self.pend_dv[None, :])
        if self.rows_n:  # the last, incomplete row (the arrays keep 2 spare rows)
            self.rows_n = 0
            self._store([self.rows_t], self.rows_dth[None, :], self.rows_dv[None, :])
        n = self.n
        return ImuData(self.t[:n], self.dth[:n], self.dv[:n], origin=RowOrigin(source, 0))


class _Health:
    """The health scan (``_core.scan_solution``) merged over blocks: the
    largest step (a block's first row against the previous block's last) and
    speed, and whether any row is bad (then the batch path names it)."""

    def __init__(self):
        self.bad = False
        self.max_step_m = float("nan")
        self.max_speed_mps = float("nan")
        self.any_finite_step = self.any_finite_speed = False
        self.last = None  # (lat, lon, h, v_n, sigmas) of the previous block's last row

    def _merge(self, sc, rows: bool) -> None:
        from .health import MAX_SPEED_MPS, MAX_STEP_M

        if rows and (max(sc["first_bad_sigma"]) >= 0 or sc["first_nonfinite_pos"] >= 0
                     or sc["first_height_out"] >= 0):
            self.bad = True
        if sc["max_step_row"] >= 0 and not (sc["max_step_m"] <= self.max_step_m):
            self.max_step_m = float(sc["max_step_m"])
        self.any_finite_step |= bool(sc["any_finite_step"])
        if rows:
            if sc["max_speed_row"] >= 0 and not (sc["max_speed_mps"] <= self.max_speed_mps):
                self.max_speed_mps = float(sc["max_speed_mps"])
            self.any_finite_speed |= bool(sc["any_finite_speed"])
        if self.max_step_m > MAX_STEP_M or self.max_speed_mps > MAX_SPEED_MPS:
            self.bad = True

    def add(self, lat, lon, h, v_n, sigmas) -> None:
        from .health import HEIGHT_RANGE_M, _R_EARTH_M

        lo, hi = float(HEIGHT_RANGE_M[0]), float(HEIGHT_RANGE_M[1])
        n = len(lat)
        if not n:
            return
        if self.last is not None:  # the step across the block boundary
            pl = self.last
            two = [np.concatenate([a, b]) for a, b in zip(pl[:4], (lat[:1], lon[:1], h[:1], v_n[:1]))]
            sig2 = [np.concatenate([a, b[:1]]) for a, b in zip(pl[4], sigmas)]
            self._merge(_core.scan_solution(*two, sig2, lo, hi, _R_EARTH_M), rows=False)
        self._merge(_core.scan_solution(lat, lon, h, v_n, sigmas, lo, hi, _R_EARTH_M), rows=True)
        self.last = (lat[-1:].copy(), lon[-1:].copy(), h[-1:].copy(), v_n[-1:].copy(), [s[-1:].copy() for s in sigmas])

    def scan(self) -> dict:
        """A ``_core.scan_solution`` result for :func:`insnav.filters.health.assess` (no bad row)."""
        return dict(first_bad_sigma=[-1, -1, -1], first_bad_sigma_col=[-1, -1, -1], bad_sigma_rows=[0, 0, 0],
                    first_nonfinite_pos=-1, max_step_m=self.max_step_m, max_step_row=-1,
                    any_finite_step=self.any_finite_step, max_speed_mps=self.max_speed_mps, max_speed_row=-1,
                    any_finite_speed=self.any_finite_speed, first_height_out=-1)


@dataclass
class StreamResult:
    """What :func:`stream_loose_csv` leaves: the solution without its rows
    (``gnss_t``, innovations, NIS, status, summary; ``len()`` the row count),
    the dataset the checks saw (IMU summed to 10 Hz), the run config and the
    finished temporary solution files (``files``: (temporary file,
    destination) pairs; one file, or the KF-GINS layout's two or three),
    renamed into place by the caller (:meth:`discard`: removed)."""

    solution: object
    dataset: Dataset
    config: object
    rows: int
    samples: int
    blocks: int = 0
    timings: dict = field(default_factory=dict)
    files: list = field(default_factory=list)

    def discard(self) -> None:
        """Remove the temporary files (the run is not kept; the destinations are not touched)."""
        for tmp, _ in self.files:
            Path(tmp).unlink(missing_ok=True)


def stream_loose_csv(ds0: Dataset, imu_path, cfg, out: Path, *, imu_ncols: int | None, start_s: float,
                     end_s: float | None, gnss_raw: GnssFixes, columns=None, precision: str = "resolution",
                     output_rate_hz: float | None = None, block_lines: int | None = None,
                     set_decimation=None, progress=None, out_format: str = "insnav") -> StreamResult:
    """Run the loose forward filter over the IMU file ``imu_path`` block by
    block, writing the solution (CSV, npz or Parquet, by the suffix of
    ``out``; or the KF-GINS layout into the folder ``out``) to temporary
    files beside the destinations.

    Parameters
    ----------
    ds0 : Dataset
        The dataset without its IMU (initial state, lever arm, IMU model; its
        ``gnss`` are ignored: ``gnss_raw`` is cut to the IMU span here).
    imu_path : path
        The IMU text file (KF-GINS layout).
    cfg : RunConfig
        The run configuration (:func:`stream_unsupported` is None for it).
    out : Path
        The solution file the temporary file is for (same folder); with
        ``out_format`` kfgins the folder (it must exist) of the KF-GINS files.
    imu_ncols : int, optional
        Columns per IMU line (KF-GINS ``imudatalen``).
    start_s, end_s : float
        KF-GINS ``starttime`` / ``endtime`` [s] (None: to the end of the file).
    gnss_raw : GnssFixes
        Every GNSS record of the file.
    columns, precision
        As :meth:`Solution.save`.
    output_rate_hz : float, optional
        ``--output-rate`` [Hz]: the decimation from the first block's median interval.
    block_lines : int, optional
        IMU lines per block (default :data:`BLOCK_LINES`).
    set_decimation : callable, optional
        ``(t_first_block, rate_hz) -> k`` (``insnav run``'s rule and message).
    progress : callable, optional
        ``(bytes_done, bytes_total)`` of the IMU file after each block
        (:class:`insnav._progress.Progress`).
    out_format : {'insnav', 'kfgins'}
        ``insnav run --out-format``: kfgins writes ``KF_GINS_Navresult.nav``,
        ``KF_GINS_IMU_ERR.txt`` and, with ``cfg.imu_error_sigmas``,
        ``KF_GINS_STD.txt`` (:func:`insnav.io.kfgins.write_kfgins_solution`'s files).

    Returns
    -------
    StreamResult
        Its ``files`` are complete; the caller renames them into place.

    Raises
    ------
    Fallback
        The reason the batch path must run instead (nothing is left behind).
    ValueError
        A malformed IMU line, a decreasing time, non-finite values (naming file and line).
    """
    from . import _as_config
    from ..io.kfgins import IMU_COLUMNS

    block_lines = int(BLOCK_LINES if block_lines is None else block_lines)

    def prepare(blocks):
        run = _BlockRun(ds0, _as_config(cfg), start_s=start_s, end_s=end_s, gnss_raw=gnss_raw,
                        output_rate_hz=output_rate_hz, set_decimation=set_decimation, block_lines=block_lines,
                        progress=progress)
        return run, blocks

    return _stream_to_file(out, lambda: imu_text_blocks(imu_path, imu_ncols, block_lines=block_lines,
                                                        names=IMU_COLUMNS), prepare, columns, precision, str(imu_path),
                           out_format)


def _stream_to_file(out, make_blocks, prepare, columns, precision, imu_source: str,
                    out_format: str = "insnav") -> StreamResult:
    """The IMU blocks read ahead on the reader thread (``make_blocks()``), ``prepare(blocks) ->
    (_BlockRun, the blocks it runs)``, the writer thread writing the temporary solution file(s) beside
    ``out`` (CSV, npz or Parquet by its suffix; ``out_format`` kfgins: the KF-GINS files in the folder
    ``out``); on any error (Ctrl-C included) the writer thread is joined and nothing is left behind.
    On glibc the allocator's mmap threshold is fixed first, for the rest of the process
    (:func:`insnav._malloc.fix_mmap_threshold`: blocks of a few MB allocated and freed at every block
    otherwise come from the heap and leave it growing with holes, about 0.5 MB per hour of recording)."""
    from .._malloc import fix_mmap_threshold
    from .solution import PRECISIONS

    if precision not in PRECISIONS:
        raise ValueError(f"precision {precision!r}: use one of {', '.join(PRECISIONS)}")
    if out_format not in OUT_FORMATS:
        raise ValueError(f"out_format {out_format!r}: use one of {', '.join(OUT_FORMATS)}")
    out = Path(out)
    fix_mmap_threshold()
    blocks = _Prefetch(make_blocks())
    writer = None
    try:
        try:
            run, todo = prepare(blocks)
            writer = _writer_class(out, out_format)(out, columns, precision, run.health, run.cfg)
            res = run.run(todo, writer, imu_source)
            res.files = list(writer.files)
            return res
        finally:
            with interrupts_deferred():  # a second Ctrl-C waits for the clean-up (it aborted in the reader)
                blocks.close()
                if writer is not None:
                    writer.shutdown()  # no write may outlive the run (the files are removed below on an error)
    except BaseException:
        if writer is not None:
            with interrupts_deferred():
                writer.discard()
        raise


class StreamedSolution(Solution):
    """A :class:`Solution` whose rows went to the file (``n_rows`` of them, its
    ``len()``) and whose per-record outputs went to the innovations sidecar as
    the run went: the records' times (``gnss_t``), their running statistics
    (``records``: :meth:`_Innovations.stats`) and the summary; no row or
    per-record arrays."""

    n_rows = 0
    records: dict | None = None

    def __len__(self):
        return int(self.n_rows)


def _median_spacing(cfg, record_t) -> float:
    """The outage cycle's GNSS period as :func:`insnav.filters._setup.engine_config` takes it [s]."""
    from .._median import spacing_median

    if cfg.cycle_period_s is not None:
        return cfg.cycle_period_s
    d = spacing_median(record_t)
    return 1.0 if d is None else d


_GNSS_FIELDS = ("t_valid", "t_arrival", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n")


def _gnss_take(g: GnssFixes, keep) -> GnssFixes:
    """The fixes where ``keep`` (a boolean mask) is true.  When they are one run of consecutive rows (a file
    in time order cut to (t0, endtime]): views of ``g``'s arrays, so a day of fixes is held once, not once
    per cut; else copies."""
    idx = np.flatnonzero(keep)
    if len(idx) and idx[-1] - idx[0] + 1 == len(idx):
        return _gnss_slice(g, int(idx[0]), int(idx[-1]) + 1)
    return GnssFixes(*(column(getattr(g, f))[keep] for f in _GNSS_FIELDS),
                     origin=None if g.origin is None else g.origin.take(keep, len(keep)))


#: times compared at a time by :func:`_window` (no whole-record temporary)
_ORDER_BLOCK = 1 << 16


def _window(t: np.ndarray, lo: float, hi: float) -> tuple[int, int] | None:
    """The rows ``a .. b - 1`` of ``t`` in (``lo``, ``hi``] when ``t`` never decreases (judged
    :data:`_ORDER_BLOCK` values at a time; NaN: not in order), else None (a mask's business)."""
    from ..data.checks import _in_time_order

    t = np.asarray(t, float)
    if not _in_time_order(t, _ORDER_BLOCK):
        return None
    return int(np.searchsorted(t, lo, side="right")), int(np.searchsorted(t, hi, side="right"))


def _gnss_window(g: GnssFixes, lo: float, hi: float) -> GnssFixes:
    """The fixes in (``lo``, ``hi``] [s]: views of ``g``'s columns when they are in time order (found by
    bisection, no mask of the whole record), else :func:`_gnss_take` of the mask."""
    w = _window(g.t_valid, lo, hi)
    if w is None:
        tv = np.asarray(g.t_valid)
        return _gnss_take(g, (tv > lo) & (tv <= hi))
    return _gnss_slice(g, *w)


def _gnss_slice(g: GnssFixes, a: int, b: int) -> GnssFixes:
    """Rows ``a .. b - 1`` of the fixes: views of ``g``'s columns (nothing read or copied) and their origin."""
    if g.origin is None:
        origin = None
    elif g.origin.lines is None:
        origin = RowOrigin(g.origin.source, g.origin.first_line + a)
    else:
        origin = RowOrigin(g.origin.source, g.origin.first_line, np.asarray(g.origin.lines)[a:b])
    return GnssFixes(*(_rows_view(getattr(g, f), a, b) for f in _GNSS_FIELDS), origin=origin)


def _count_window(t, lo: float, hi: float) -> int:
    """How many of the times ``t`` lie in (``lo``, ``hi``]."""
    w = _window(t, lo, hi)
    if w is not None:
        return w[1] - w[0]
    t = np.asarray(t, float)
    return int(np.count_nonzero((t > lo) & (t <= hi)))


def _rows_view(x, a: int, b: int):
    """Rows ``a .. b - 1`` of a column: a view (of an array, or of a column read on demand, nothing read)."""
    return x.view(a, b) if getattr(x, "on_demand", False) else np.asarray(x)[a:b]


def _fixes_equal(a: GnssFixes, b: GnssFixes, keep, block: int = GNSS_PUSH_MAX) -> bool:
    """Whether ``a`` holds the fixes of ``b`` where ``keep`` (NaN equal to NaN; every field but
    ``t_arrival``), compared :data:`GNSS_PUSH_MAX` fixes at a time (no whole-record copy of ``b``'s
    columns: the fixes in time order cut at the last IMU sample keep a leading run of them)."""
    n = len(b)
    idx = range(n)[keep] if isinstance(keep, slice) else np.flatnonzero(keep)  # a slice: no index array
    if len(a) != len(idx):
        return False
    for k in range(0, len(idx), block):
        rows = idx[k:k + block]
        rows = slice(rows.start, rows.stop) if isinstance(rows, range) else rows
        for f in _GNSS_FIELDS:
            if f == "t_arrival":
                continue
            x, y = column(getattr(a, f)), column(getattr(b, f))
            if x.ndim == 2 or y.ndim == 2:
                x, y = x.reshape(len(a), 3), y.reshape(n, 3)
            if not np.array_equal(x[k:k + block], y[rows], equal_nan=True):
                return False
    return True


class _FixSlice:
    """Fixes ``idx`` (a slice or indices) of ``g``: the fields :func:`insnav.filters.loose.loose_gnss_rows` reads."""

    def __init__(self, g: GnssFixes, idx):
        for f in ("t_valid", "lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n", "sigma_vel_n"):
            setattr(self, f, column(getattr(g, f))[idx])

    def __len__(self):
        return len(self.t_valid)


class _BlockRun:
    """One block-by-block run: the reader's and the sanitizer's checks per
    block, the span (t0, endtime], the engine, the output rows, and at the end
    the per-record outputs, the input checks and the summary of the batch run."""

    def __init__(self, ds0, cfg, *, start_s, end_s, gnss_raw, output_rate_hz, set_decimation,
                 block_lines: int, progress=None, t0_exact: bool = False, count_cut_gnss: bool = True,
                 extra_checks=None):
        from .sanitize import DEFAULTS, _imu_report

        self.ds0, self.cfg = ds0, cfg
        self.start_s, self.end_s, self.gnss_raw = start_s, end_s, gnss_raw
        # t0_exact: the initial state is at start_s itself (the CSV loader's), not at the first sample at or
        # after it (KF-GINS starttime); count_cut_gnss: the records outside (t0, last sample] are reported
        # (KF-GINS's loader counts them, the CSV loader's do not); extra_checks(): the loader's own checks
        self.t0_exact, self.count_cut_gnss, self.extra_checks = t0_exact, count_cut_gnss, extra_checks
        self.output_rate_hz, self.set_decimation = output_rate_hz, set_decimation
        self.block_lines = block_lines
        self.progress = progress
        self.opts = {**DEFAULTS, **(cfg.sanitize or {})}
        self.imu_report = _imu_report()
        self.health = _Health()
        self.timings = dict(read=0.0, filter=0.0, write=0.0)
        import time

        self.clock = time.perf_counter
        self.t0 = None  # the initial state's time: the first sample at or after starttime [s]
        self.t_prev = None  # the last sample read, and its line (the reader's checks across blocks)
        self.line_prev = 0
        self.n_kept = 0  # samples in the run's span so far
        self.last_kept = None  # the last of them [s]
        self.dt0 = None  # the nominal interval (the first block's median) [s]
        self.stream = self.gnss = self.gnss_rep = self.coarse = None
        self.rows = 0

    # --- per block ---------------------------------------------------------------------------
    def _scan(self, t, dth, dv, t0):
        o = self.opts
        return scan_imu(t, dth, dv, t0=t0, max_rate_rps=o["max_rate_rps"], max_accel_mps2=o["max_accel_mps2"],
                        gap_factor=o["gap_factor"])

    def _reader_checks(self, blk: ImuBlock, sc: dict) -> None:
        """read_kfgins_imu's checks on every line: non-finite values, decreasing time (across blocks too)."""
        from ..io.kfgins import IMU_COLUMNS

        t, origin = blk.t, blk.origin
        if sc["nonfinite_t"] >= 0 or sc["nonfinite_dtheta"] >= 0 or sc["nonfinite_dv"] >= 0:
            check_finite_rows((t, blk.dtheta_b, blk.dv_b), origin, IMU_COLUMNS)
        i = sc["decrease"]
        if i >= 0:
            raise ValueError(f"{origin.where(i)}: time {float(t[i])!r} does not increase "
                             f"(previous record at {float(t[i - 1])!r}, line {origin.line(i - 1)})")
        if self.t_prev is not None and t[0] < self.t_prev:
            raise ValueError(f"{origin.where(0)}: time {float(t[0])!r} does not increase "
                             f"(previous record at {self.t_prev!r}, line {self.line_prev})")
        self.t_prev, self.line_prev = float(t[-1]), origin.line(len(t) - 1)

    def _sanitizer_checks(self, t, sc: dict) -> None:
        """What the sanitizer (filters/sanitize.py) would repair or refuse: a Fallback."""
        first = self.n_kept == 0
        if sc["repeats"] or (not first and not t[0] > self.last_kept):
            raise Fallback("repeated IMU times (the sanitizer drops duplicates)")
        if self.dt0 is None:
            self.dt0 = sc["dt0"]
        elif len(t) > 16 and abs(sc["dt0"] - self.dt0) > 1e-6 * self.dt0:
            raise Fallback(f"the IMU interval changes ({self.dt0:.6g} s -> {sc['dt0']:.6g} s)")
        if sc["rate"] >= 0 or sc["accel"] >= 0:
            raise Fallback("an implausible IMU rate (the sanitizer names it)")
        if sc["gaps"] or (not first and t[0] - self.last_kept > self.opts["gap_factor"] * self.dt0):
            raise Fallback("an IMU gap (the sanitizer bridges it)")

    def run(self, blocks, writer, imu_source: str) -> StreamResult:
        clock, tm = self.clock, self.timings
        t_mark = clock()
        n_blocks = 0
        for blk in blocks:
            n_blocks += 1
            t, dth, dv = blk.t, blk.dtheta_b, blk.dv_b
            # inside the run's span one scan with the sanitizer's limits gives the reader's checks too
            inside = self.n_kept > 0 and (self.end_s is None or t[-1] <= self.end_s)
            sc = self._scan(t, dth, dv, self.last_kept) if inside else scan_imu(t, dth, dv)
            self._reader_checks(blk, sc)
            lo = 0
            if self.t0 is None:  # the initial state: the first sample at or after starttime
                i0 = int(np.searchsorted(t, self.start_s, side="right" if self.t0_exact else "left"))
                if i0 == len(t):
                    continue
                self.t0 = float(self.start_s if self.t0_exact else t[i0])
                lo = int(np.searchsorted(t, self.t0, side="right"))
                # the samples to expect: the file's size over the bytes per line so far
                lines = blk.origin.line(len(t) - 1)
                expected = int(blk.file_bytes * lines / blk.file_bytes_done) if blk.file_bytes_done else 0
                # the IMU interval (output decimation, the checks' window) from at least two intervals:
                # t0 may be the block's last sample or last but one (the stream runs on a constant interval)
                self._start(t[min(lo, max(0, len(t) - 3)):], expected)
            hi = len(t) if self.end_s is None else int(np.searchsorted(t, self.end_s, side="right"))
            last = hi < len(t)  # endtime reached: the rest of the file is not read
            if hi > lo:
                if not (inside and lo == 0 and hi == len(t)):
                    t, dth, dv = t[lo:hi], dth[lo:hi], dv[lo:hi]
                    sc = self._scan(t, dth, dv, self.t0 if self.n_kept == 0 else self.last_kept)
                self._sanitizer_checks(t, sc)
                self.coarse.add(t, dth, dv)
                self.n_kept += len(t)
                self.last_kept = float(t[-1])
                tm["read"] += clock() - t_mark
                for a in range(0, len(t), self.block_lines):  # the engine's buffers hold block_lines rows
                    t_mark = clock()
                    tb = t[a:a + self.block_lines]
                    self._push_gnss(float(tb[-1]))
                    n = self.stream.run_block(tb, dth[a:a + self.block_lines], dv[a:a + self.block_lines])
                    tm["filter"] += clock() - t_mark
                    t_mark = clock()
                    writer.records(self.stream.take_records(), self.gnss_t)
                    writer.add(self.stream, n)
                    self.rows += n
                    tm["write"] += clock() - t_mark
                t_mark = clock()
            if self.progress is not None:
                self.progress(blk.file_bytes_done, blk.file_bytes)
            if last:
                break
        tm["read"] += clock() - t_mark
        if self.t0 is None or self.n_kept < 2:
            raise Fallback("too few IMU records in the run's span (the batch path names the key)", batch_names_it=True)
        t_mark = clock()
        n = self.stream.finish()
        writer.records(self.stream.take_records(), self.gnss_t)  # none: every fix given was consumed
        writer.add(self.stream, n)
        self.rows += n
        writer.close()
        tm["write"] += clock() - t_mark
        t_mark = clock()
        if self.health.bad:
            raise Fallback("the health check found a bad row (the batch path names it)", batch_names_it=True)
        res = self._result(imu_source, n_blocks, writer.innovations)
        tm["filter"] += clock() - t_mark
        return res

    # --- start and end -----------------------------------------------------------------------
    def _start(self, t_first, expected_samples: int = 0) -> None:
        """The engine at t0: the GNSS records in (t0, endtime] sanitized (the batch loader's cut and
        sanitize_gnss), the output decimation from the first block, the batch loose runner's set-up."""
        from .loose import loose_engine_args
        from .sanitize import sanitize_gnss_blocks

        cfg, o = self.cfg, self.opts
        cut = _gnss_window(self.gnss_raw, self.t0, np.inf if self.end_s is None else self.end_s)
        self.gnss, self.gnss_rep = sanitize_gnss_blocks(cut, min_h_m=o["min_h_m"], max_h_m=o["max_h_m"],
                                                        source="gnss")
        del cut
        if self.output_rate_hz is not None:
            cfg.output_decimation = self.set_decimation(t_first, self.output_rate_hz)
        gn = self.gnss
        t_all = np.asarray(gn.t_valid, float)
        # the loose table's order (loose_gnss_rows: by time, stable), its rows made a block's fixes at a time
        self.order = None if _window(t_all, -np.inf, np.inf) is not None else np.argsort(t_all, kind="stable")
        self.gnss_t = t_all if self.order is None else t_all[self.order]
        for a in range(0, len(t_all), GNSS_PUSH_MAX):  # the table's checks on every fix before the run
            self._gnss_rows(a, min(a + GNSS_PUSH_MAX, len(t_all)))
        a = loose_engine_args(dataclasses.replace(self.ds0, t0=self.t0, gnss=gn), cfg, self.gnss_t)
        self.stream = _core.LooseStream(cfg.filter, a.layout, np.zeros((0, 13)), a.init, a.P0, a.imu_correction,
                                        a.imu_model, a.config, self.block_lines)
        self.pushed = 0  # the fixes given to the engine so far (the first of self.gnss_t's order)
        dt = median(np.diff(t_first)) if len(t_first) > 1 else 0.0
        self.coarse = _Coarse(max(1, int(round(1.0 / (CHECK_RATE_HZ * dt)))) if dt > 0 else 1, expected_samples)

    def _gnss_rows(self, a: int, b: int) -> np.ndarray:
        """The loose engine's GNSS rows of the fixes a .. b - 1 in time order (:func:`loose_gnss_rows` of
        those fixes: its rows of the whole table; a table that fails its checks: the whole table's error)."""
        from .loose import has_speed_terms, loose_gnss_rows

        # the per-speed sigma terms take a fix without velocity's speed from its neighbours (fix_speed_mps):
        # one fix of overlap on each side gives each fix of the slice the whole table's neighbours
        pad = has_speed_terms(self.cfg)
        a0, b0 = (max(a - 1, 0), min(b + 1, len(self.gnss_t))) if pad else (a, b)
        idx = slice(a0, b0) if self.order is None else self.order[a0:b0]
        try:
            rows = loose_gnss_rows(_FixSlice(self.gnss, idx), self.cfg)
            return rows[a - a0:len(rows) - (b0 - b)] if pad else rows
        except ValueError:
            loose_gnss_rows(self.gnss, self.cfg)  # the whole table's message (which fix)
            raise

    def _push_gnss(self, t_end: float) -> None:
        """The fixes up to ``t_end`` (the next block's last sample) given to the engine, at most
        :data:`GNSS_PUSH_MAX` at a time (each block's records are taken after it runs)."""
        j = int(np.searchsorted(self.gnss_t, t_end, side="right"))
        while self.pushed < j:
            b = min(j, self.pushed + GNSS_PUSH_MAX)
            self.stream.push_gnss(self._gnss_rows(self.pushed, b))
            self.pushed = b

    def _exact_gnss_cut(self, records: int) -> None:
        """The GNSS records after the last IMU sample: the batch loader cuts them before the run.  They
        changed nothing when the sanitizer treats the rest alike and the GNSS period is the same; they were
        never given to the engine (:meth:`_push_gnss`), so no output of theirs was written; else the batch
        path runs.  ``records``: the per-fix records written."""
        from .loose import has_speed_terms, loose_gnss_rows
        from .sanitize import sanitize_gnss_blocks

        n_keep = _count_window(self.gnss.t_valid, -np.inf, self.last_kept)
        if n_keep == len(self.gnss):
            if records != n_keep:  # pragma: no cover - every fix up to the last sample is consumed
                raise RuntimeError(f"{records} GNSS records written for {n_keep} fixes")
            return
        # the kept fixes: the first n_keep when in time order (the engine's order), else a mask
        keep = slice(0, n_keep) if self.order is None else np.asarray(self.gnss.t_valid) <= self.last_kept
        g2, rep2 = sanitize_gnss_blocks(_gnss_window(self.gnss_raw, self.t0, self.last_kept),
                                        min_h_m=self.opts["min_h_m"], max_h_m=self.opts["max_h_m"], source="gnss")
        counts = ("gnss_records_in", "gnss_records_out")
        same = ({k: v for k, v in rep2.items() if k not in counts}
                == {k: v for k, v in self.gnss_rep.items() if k not in counts}
                and len(g2) == n_keep
                and _fixes_equal(g2, self.gnss, keep)
                and _median_spacing(self.cfg, g2.t_valid) == _median_spacing(self.cfg, self.gnss.t_valid))
        if same and n_keep >= 1 and has_speed_terms(self.cfg):  # the last kept fix's speed: the batch table ends with it
            o2 = np.argsort(np.asarray(g2.t_valid, float), kind="stable")
            batch_last = loose_gnss_rows(_FixSlice(g2, o2[-2:]), self.cfg)[-1]
            same = np.array_equal(batch_last, self._gnss_rows(n_keep - 1, n_keep)[-1], equal_nan=True)
        if not same:
            raise Fallback("a GNSS record after the last IMU sample changes the set-up")
        if records != len(g2):  # pragma: no cover - the cut fixes are the last in time order, never consumed
            raise RuntimeError(f"{records} GNSS records written for {len(g2)} fixes")
        self.gnss, self.gnss_rep = g2, rep2
        self.gnss_t = self.gnss_t[:records]

    def _result(self, imu_source: str, n_blocks: int, innovations: "_Innovations") -> StreamResult:
        from ..data.checks import check_dataset, heading_grid_step
        from .health import assess

        cfg = self.cfg
        rec = self.stream.records()  # the counters (every record was taken block by block)
        self._exact_gnss_cut(innovations.n)
        gnss_t = self.gnss_t  # the fixes' times in the records' order (sorted, stable)
        n_all = len(self.gnss_raw)
        scenario = dict(self.ds0.scenario or {})
        if self.count_cut_gnss:
            scenario["gnss_outside_imu_span"] = int(n_all - _count_window(self.gnss_raw.t_valid, self.t0,
                                                                          self.last_kept))
        ds = dataclasses.replace(self.ds0, t0=self.t0, imu=self.coarse.imu(imu_source), gnss=self.gnss,
                                 scenario=scenario)
        try:  # the unit and time-base checks on the IMU summed to 10 Hz (a failure: the batch path's message)
            if self.extra_checks is not None:
                self.extra_checks()
            with heading_grid_step(self.coarse.grid_step()):
                check_dataset(ds, max_time_offset_s=cfg.max_time_offset_s)
        except ValueError as exc:
            raise Fallback(f"an input check failed on the summed IMU ({str(exc).splitlines()[0][:80]})", batch_names_it=True) from None
        z, e = np.zeros((0, 3)), np.zeros(0)
        sol = StreamedSolution(
            t=e, lat_deg=e, lon_deg=e, h_m=e, v_n=z, roll_deg=e, pitch_deg=e, yaw_deg=e, sigma_pos_n_m=z,
            sigma_vel_n_mps=z, sigma_att_deg=z, acc_bias_mps2=z, gyro_bias_rps=z, acc_scale=z, gyro_scale=z,
            gnss_t=gnss_t, innovation=z, nis=e, gnss_status=np.zeros(0, np.int8), log_det_s=e, gnss_sigma=z,
            summary=dict(filter=cfg.filter, coupling=cfg.coupling, layout=int(cfg.layout),
                         updates=int(rec["updates"]), rejected=int(rec["rejected"]),
                         gate_reopened=int(rec["gate_reopened"]), gate_outage_accepted=int(rec["gate_outage_accepted"]),
                         cholesky_repairs=int(rec["cholesky_repairs"]), gnss_records=len(gnss_t)))
        sol.n_rows = self.rows
        sol.records = innovations.stats()
        rep = dict(self.imu_report, imu_samples_in=self.n_kept, imu_samples_out=self.n_kept)
        sol.summary["sanitize"] = {**rep, **self.gnss_rep}
        sol.summary["health"] = assess(sol, imu_t_end=self.last_kept, scan=self.health.scan(), n_rows=self.rows,
                                       records=sol.records)
        return StreamResult(solution=sol, dataset=ds, config=cfg, rows=self.rows,
                            samples=self.n_kept, blocks=n_blocks, timings=self.timings)


class _Innovations:
    """The per-record outputs of a run written as it goes: each block's records
    (``_core.LooseStream.take_records``) appended to the temporary
    ``<solution>.innovations.csv`` in the text of
    :func:`insnav.filters.solution.write_innovations` (the same lines: the
    file is the whole-run writer's byte for byte), and reduced to what the
    summary and the health verdict need (:meth:`stats`): the count of records
    outside the IMU span, the applied records' NIS sum (exactly rounded,
    :func:`math.fsum`'s partials) and measurement rows, and the last applied
    record's time.  Memory: one block's records."""

    def __init__(self, tmp: Path):
        self.tmp = tmp
        self.f = open(tmp, "w")
        self.n = 0
        self.outside = 0
        self.nis_partials: list[float] = []
        self.rows_sum = 0
        self.applied = 0
        self.rejected = 0  # by the innovation gate
        self.applied_t_max = float("-inf")
        self.header = True

    def add(self, rec: dict, gnss_t: np.ndarray) -> None:
        from .solution import INNOVATION_COLUMNS, RecordStatus, _csv_text, _status_names

        st = np.asarray(rec["status"], int)
        k = len(st)
        if not k and not self.header:
            return
        first = int(rec["first"])
        if first != self.n:  # pragma: no cover - the engine hands over every record once, in order
            raise RuntimeError(f"GNSS record {first} taken after {self.n}")
        t = gnss_t[first:first + k]
        inn, nis = rec["innovation"], rec["nis"]
        rows = np.isfinite(inn).sum(axis=1)
        applied = st == RecordStatus.APPLIED
        body = np.column_stack([t, st, applied, nis, rows, inn])
        text = _csv_text(body, INNOVATION_COLUMNS, ["%.6f", "%d", "%d", "%.6g", "%d"] + ["%.6g"] * 6,
                         _status_names(st))
        if not self.header:
            text = text[text.index("\n") + 1:]
        self.f.write(text)
        self.header = False
        self.n += k
        self.outside += int(np.count_nonzero(st == RecordStatus.OUTSIDE_IMU_SPAN))
        self.rejected += int(np.count_nonzero(st == RecordStatus.REJECTED_BY_GATE))
        ok = applied & np.isfinite(nis) & (rows > 0)
        _fsum_add(self.nis_partials, nis[ok])
        self.rows_sum += int(rows[ok].sum())
        if applied.any():
            self.applied += int(applied.sum())
            self.applied_t_max = max(self.applied_t_max, float(t[applied].max()))

    def stats(self) -> dict:
        """What :func:`insnav.filters.health.assess` (``records=``) and the report line need."""
        import math

        return dict(n=self.n, outside=self.outside, nis_sum=math.fsum(self.nis_partials), rows_sum=self.rows_sum,
                    applied=self.applied, rejected=self.rejected, applied_t_max=self.applied_t_max)

    def close(self) -> None:
        if self.header:  # no record: the header alone
            self.add(dict(first=0, status=np.zeros(0, int), innovation=np.zeros((0, 6)), nis=np.zeros(0)),
                     np.zeros(0))
        self.f.close()

    def shutdown(self) -> None:
        if not self.f.closed:
            self.f.close()


def _fsum_add(partials: list, values) -> None:
    """``values`` added to the exact sum held in ``partials`` (non-overlapping float64 terms, largest
    first): ``math.fsum(partials)`` is the sum of every value added, exactly rounded, whatever the blocks
    were.  The new terms are the exactly rounded sum (:func:`math.fsum`: Shewchuk, "Adaptive precision
    floating-point arithmetic", Discrete Comput. Geom. 18, 1997) and the exactly rounded residuals
    after it, until a residual is zero (two or three terms in practice)."""
    import math

    terms = list(partials) + np.asarray(values, float).tolist()
    partials.clear()
    while True:
        r = math.fsum(terms + [-x for x in partials])
        if r == 0.0 or not math.isfinite(r):
            if not math.isfinite(r):
                partials[:] = [r]
            return
        partials.append(r)


def _writer_job(fn, *args, **kwargs) -> Job:
    """A write on the writer thread (:class:`insnav._threads.Job`, started by :meth:`_Writer.add`): a
    thread per block instead of a concurrent.futures pool, whose import with logging's costs a few
    milliseconds of every run's start."""
    return Job(fn, *args, name="insnav-csv-writer", **kwargs)


def _temp_beside(dest: Path) -> Path:
    """An empty temporary file beside ``dest``, named as :mod:`insnav._atomic` names them
    (``.NAME.XXXXXXXX.part.SUFFIX``)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".part" + dest.suffix, dir=dest.parent)
    os.close(fd)
    return Path(tmp)


class _Writer:
    """The CSV rows appended on a writer thread, one block behind the filter
    (``_core.write_table`` releases the GIL), so that formatting block i
    overlaps filtering block i + 1; at most one block waits (bounded memory).
    :meth:`close` waits for the last write (and raises its error).

    ``files``: (temporary file, destination) of each file written, made at
    construction; :meth:`discard` removes them (a failed run)."""

    def __init__(self, out: Path, columns, precision, health, cfg=None):
        self.out, self.columns, self.precision, self.health = Path(out), columns, precision, health
        self.files: list[tuple[Path, Path]] = []
        self._sinks: dict = {}  # temporary file -> its _core.TextSink (open until close / shutdown)
        self._pending = None  # the Job writing of the last block
        self._header_done = False
        self.innovations = None
        try:
            self._make_files()
            from .solution import innovations_path

            # the per-record sidecar of the solution file (the KF-GINS layout: of its .nav), written as the run goes
            self.innovations = _Innovations(self._temp(innovations_path(self.files[0][1])))
        except BaseException:
            self.discard()
            raise

    def records(self, rec: dict, gnss_t: np.ndarray) -> None:
        """A block's per-record outputs (``_core.LooseStream.take_records``) to the sidecar."""
        self.innovations.add(rec, gnss_t)

    def _make_files(self) -> None:
        self.tmp = self._temp(self.out)

    def _temp(self, dest: Path) -> Path:
        with interrupts_deferred():  # made and listed for discard() together: a Ctrl-C between would leave it
            tmp = _temp_beside(dest)
            self.files.append((tmp, dest))
        return tmp

    def add(self, stream, n: int) -> None:
        """The last run_block's n rows: to degrees in place, the health scan, queued for the writer thread."""
        from ._assemble import nav_solution

        # the engine has two row buffers and fills them in turn, one per call (rows or not): the write
        # queued at call i (buffer i % 2) must end before call i + 2, so every call waits for the last one
        if n == 0:
            self._wait()
            return
        out = stream.rows()  # views of this call's row buffer
        e = np.zeros(0)
        sol, nonfinite = nav_solution(out, gnss_t=e, innovation=e, nis=e, gnss_status=e)
        if nonfinite:
            raise Fallback("a non-finite row (the batch path names it)", batch_names_it=True)
        self.health.add(sol.lat_deg, sol.lon_deg, sol.h_m, np.asarray(sol.v_n),
                        [sol.sigma_pos_n_m, sol.sigma_vel_n_mps, sol.sigma_att_deg])
        cols = self._columns(sol, out)
        self._wait()
        self._pending = job = self._submit(cols)  # pending before its thread starts: shutdown() joins it
        job.start()

    def _columns(self, sol, out):
        """What :meth:`_submit` writes of a block's rows: the selected columns (name, view, factor)."""
        from .solution import _selected

        return _selected(sol, self.columns)

    def _submit(self, cols) -> Job:
        """The block's columns (name, view of the row buffer, factor) written on the writer thread."""
        from .solution import CSV_DECIMALS

        dec = [CSV_DECIMALS[nm] if self.precision == "resolution" else -1 for nm, _, _ in cols]
        header = "" if self._header_done else ",".join(nm for nm, _, _ in cols) + "\n"
        job = _writer_job(self._sink(self.tmp).write, header, [np.asarray(x, float) for _, x, _ in cols],
                          [float(f) for _, _, f in cols], dec, threads=threads())
        self._header_done = True
        return job

    def _sink(self, tmp: Path):
        """The open text file of ``tmp``: one ``_core.TextSink`` for every block (written front to back
        through an aligned buffer, with O_DIRECT where the file system allows it: no copy into the page
        cache), closed by :meth:`close`."""
        sink = self._sinks.get(tmp)
        if sink is None:
            sink = self._sinks[tmp] = _core.TextSink(str(tmp))
        return sink

    def _close_sinks(self, raise_errors: bool = True) -> None:
        sinks, self._sinks = self._sinks, {}
        for sink in sinks.values():
            try:
                sink.close()
            except OSError:
                if raise_errors:
                    raise

    def _wait(self) -> None:
        if self._pending is not None:
            self._pending.result()  # interrupted (Ctrl-C), the job stays pending for shutdown() to join
            self._pending = None

    def close(self) -> None:
        """Wait for the last block (its error raised), then write the files' rest and close them."""
        self._wait()
        self._close_sinks()
        self.innovations.close()

    def shutdown(self) -> None:
        """End the thread once its write is done, close the files (errors not raised: the run already
        failed or closed)."""
        if self._pending is not None:
            self._pending.join()
        self._close_sinks(raise_errors=False)
        if self.innovations is not None:
            self.innovations.shutdown()

    def discard(self) -> None:
        """Remove the temporary files (after :meth:`shutdown`; the destinations are not touched)."""
        for tmp, _ in self.files:
            tmp.unlink(missing_ok=True)


class _NpzWriter(_Writer):
    """:class:`_Writer` for an ``.npz``: each block's columns appended to their
    scratch files (:class:`insnav._npz.NpzColumns`, in a folder beside the
    destination) on the writer thread; :meth:`close` assembles the ``.npz``
    into the temporary file (the members, names, dtypes and values of the
    whole-run ``Solution.save``), :meth:`shutdown` removes the scratch files
    (whatever happened)."""

    npz = None

    def _submit(self, cols) -> Job:
        from .._npz import NpzColumns

        if self.npz is None:
            p = Path(self.tmp)
            with interrupts_deferred():  # the scratch folder made and owned together (shutdown removes it)
                scratch = tempfile.mkdtemp(prefix=p.name + ".", suffix=".columns", dir=p.parent)
                try:
                    self.npz = NpzColumns(scratch, [nm for nm, _, _ in cols])
                except BaseException:
                    os.rmdir(scratch)
                    raise
        return _writer_job(self.npz.append, [(x, float(f)) for _, x, f in cols])

    def close(self) -> None:
        """Wait for the last block, then write the ``.npz`` to the temporary file."""
        self._wait()
        if self.npz is None:
            raise Fallback("no output row (the batch path names it)", batch_names_it=True)
        self.npz.finish(self.tmp)
        self.npz.discard()
        self.innovations.close()

    def shutdown(self) -> None:
        super().shutdown()
        if self.npz is not None:
            self.npz.discard()


class _ParquetWriter(_Writer):
    """:class:`_Writer` for a ``.parquet``: on the writer thread, each block's
    columns are copied (times their unit factor, as ``Solution.save`` scales
    them) into one row group's buffer of
    :data:`~insnav.filters.solution.PARQUET_ROW_GROUP_ROWS` rows per column
    (allocated once: about 20 MB with every column), and each full buffer is
    written as one row group (``pyarrow.parquet.ParquetWriter``, which encodes
    and compresses with the GIL released); :meth:`close` writes the last,
    shorter group and the footer.  The whole-file writer cuts the same row
    groups with the same schema (float64 columns, their names, no metadata of
    ours) and options, so the file is ``Solution.save``'s byte for byte."""

    pq = None

    def _submit(self, cols) -> Job:
        return _writer_job(self._append, [(nm, x, float(f)) for nm, x, f in cols])

    def _append(self, cols) -> None:
        """(writer thread) The block's rows into the row-group buffer, each full buffer written."""
        from .solution import PARQUET_DICTIONARY_PAGE_BYTES, PARQUET_ROW_GROUP_ROWS, _parquet

        rows = PARQUET_ROW_GROUP_ROWS
        if self.pq is None:
            pa = _parquet()
            self.schema = pa.schema([pa.field(nm, pa.float64()) for nm, _, _ in cols])
            self.buf = np.empty((len(cols), rows))
            self.fill = 0
            self.pq = pa.parquet.ParquetWriter(str(self.tmp), self.schema,
                                               dictionary_pagesize_limit=PARQUET_DICTIONARY_PAGE_BYTES)
        n, a = len(cols[0][1]), 0
        while a < n:
            k = min(n - a, rows - self.fill)
            for j, (_, x, f) in enumerate(cols):
                dst = self.buf[j, self.fill:self.fill + k]
                if f == 1.0:
                    dst[:] = x[a:a + k]
                else:  # the product Solution.save writes (np.multiply), bit for bit
                    np.multiply(x[a:a + k], f, out=dst)
            self.fill += k
            a += k
            if self.fill == rows:
                self._flush()

    def _flush(self) -> None:
        from .solution import PARQUET_ROW_GROUP_ROWS, _parquet, parquet_table

        if self.fill:
            table = parquet_table(_parquet(), self.schema.names, [row[:self.fill] for row in self.buf])
            self.pq.write_table(table, row_group_size=PARQUET_ROW_GROUP_ROWS)
            self.fill = 0

    def close(self) -> None:
        """Wait for the last block, then write the last row group and the footer."""
        self._wait()
        if self.pq is None:
            raise Fallback("no output row (the batch path names it)", batch_names_it=True)
        self._flush()
        self.pq.close()
        self.innovations.close()

    def shutdown(self) -> None:
        super().shutdown()
        if self.pq is not None and self.pq.is_open:  # a failed run: the file is removed, its handle closed
            try:
                self.pq.close()
            except Exception:  # noqa: BLE001 - the run already failed; its error is the one reported
                pass
        self.buf = None


class _KfginsWriter(_Writer):
    """:class:`_Writer` for ``--out-format kfgins``: ``out`` is the folder, and
    each block's rows are appended on the writer thread to the temporary
    ``KF_GINS_Navresult.nav``, ``KF_GINS_IMU_ERR.txt`` and (with the run's
    ``imu_error_sigmas``) ``KF_GINS_STD.txt`` beside their destinations, in
    the columns, units and ``"%-15.9lf "`` text of the whole-file writer
    (:func:`insnav.io.kfgins.kfgins_tables`, ``_core.write_table`` with the GIL
    released), so the files are its files byte for byte."""

    def __init__(self, out: Path, columns, precision, health, cfg=None):
        self.layout = int(cfg.layout) if cfg is not None and cfg.imu_error_sigmas else None
        super().__init__(out, columns, precision, health, cfg)

    def _make_files(self) -> None:
        from ..io.kfgins import KFGINS_IMU_ERR_FILE, KFGINS_NAV_FILE, KFGINS_STD_FILE

        names = [KFGINS_NAV_FILE, KFGINS_IMU_ERR_FILE] + ([KFGINS_STD_FILE] if self.layout else [])
        for name in names:
            self._temp(self.out / name)

    def _columns(self, sol, out):
        from ..io.kfgins import kfgins_tables

        if self.layout:  # as run_loose fills it: layout order [.. df_b dw_b (s_a s_g)] is the imu_err column order
            sig = out["sigma"]
            sol.sigma_imu_err = np.zeros((len(sig), 12))
            sol.sigma_imu_err[:, :self.layout - 9] = sig[:, 9:self.layout]
        return [cols for _, cols in kfgins_tables(sol)]

    def _submit(self, tables) -> Job:
        job = _writer_job(self._write, tables, self._header_done)
        self._header_done = True
        return job

    def _write(self, tables, append: bool) -> None:
        """(writer thread) One block's rows appended to each file."""
        from ..io.kfgins import KFGINS_DECIMALS, KFGINS_TEXT_FORMAT

        for (tmp, _), cols in zip(self.files, tables):
            self._sink(tmp).write("", [np.asarray(x, float) for _, x, _ in cols], [float(f) for _, _, f in cols],
                                  [KFGINS_DECIMALS] * len(cols), threads=threads(), **KFGINS_TEXT_FORMAT)


def _writer_class(out: Path, out_format: str):
    if out_format == "kfgins":
        return _KfginsWriter
    return {".npz": _NpzWriter, ".parquet": _ParquetWriter}.get(Path(out).suffix.lower(), _Writer)


#: the most IMU samples the alignment of a block-by-block ``--format csv`` run may need (about 87 min at
#: 200 Hz, 50 MB): a later alignment makes the run take the whole-file path
ALIGN_MAX_SAMPLES = 1 << 20


def _concat_blocks(blocks) -> ImuData:
    t = np.concatenate([b.t for b in blocks])
    lines = np.concatenate([b.origin.all_lines(len(b.t)) for b in blocks])
    return ImuData(t, np.concatenate([b.dtheta_b for b in blocks]), np.concatenate([b.dv_b for b in blocks]),
                   origin=RowOrigin(blocks[0].origin.source, lines=lines))


def csv_stream_unsupported(inp) -> str | None:
    """Why the IMU CSV of ``inp`` (:class:`insnav.io.csv_dataset.CsvInputs`) cannot be read block by
    block (None: it can): a str2str ``tick_ms`` log, whose time map is fitted over the whole record."""
    if inp.fmt.uses_tick:
        return "a str2str tick_ms log: its tick -> GPS time map is fitted over the whole record"
    return None


def stream_csv_loose(inp, imu_path, out: Path, *, configure, columns=None, precision: str = "resolution",
                     output_rate_hz: float | None = None, block_lines: int | None = None, set_decimation=None,
                     progress=None, out_format: str = "insnav") -> StreamResult:
    """``insnav run --format csv`` block by block: the IMU CSV read, mapped
    (:func:`imu_csv_blocks`), filtered and written as :func:`stream_loose_csv`
    does for KF-GINS files, with the set-up of
    :func:`insnav.io.csv_dataset.load_csv_dataset`.

    What needs the whole record is taken from what the stream sees: the
    alignment (:func:`insnav.ins.align.align`) runs on the record's first
    blocks, as many as it reads (``Alignment.samples_used``; at most
    :data:`ALIGN_MAX_SAMPLES`), with their median interval; the loader's unit,
    axis, sign and time-base checks (``input_checks``) run at the end on the
    whole record's IMU summed to 10 Hz.  Whatever the stream cannot reproduce
    raises :class:`Fallback`: a ``tick_ms`` log (its time map is fitted over
    the whole record), a first block whose interval contradicts ``rate_hz``, a
    GNSS or IMU check that fails, an alignment that needs more of the record,
    and everything :func:`stream_loose_csv` hands to the batch path.

    Parameters
    ----------
    inp : insnav.io.csv_dataset.CsvInputs
        The TOML's tables and the GNSS fixes (:func:`insnav.io.csv_dataset.csv_inputs`).
    imu_path : path
        The IMU CSV.
    out : Path
        The solution file (CSV, npz or Parquet) the temporary file is for, or
        the KF-GINS layout's folder (``out_format`` kfgins).
    configure : callable
        ``RunConfig -> RunConfig``: the command line's settings over the loader's configuration.
    columns, precision, output_rate_hz, block_lines, set_decimation, progress, out_format
        As :func:`stream_loose_csv`.

    Returns
    -------
    StreamResult
        ``dataset`` a :class:`~insnav.io.csv_dataset.CsvDataset` (IMU summed to 10 Hz).
    """
    from ..io.csv_dataset import (check_time_base, csv_run_dataset, gnss_checks, imu_unit_checks, initial_state,
                                  input_checks)

    fmt = inp.fmt
    why = csv_stream_unsupported(inp)
    if why is not None:
        raise Fallback(why)
    if fmt.time == "gps_sow" and fmt.gps_week is None and inp.week is None:
        raise Fallback("[imu] time = 'gps_sow' without a GPS week (the whole-file reader names it)",
                       batch_names_it=True)
    try:
        check_time_base(inp, "relative" if fmt.time == "relative" else "gps")
        gnss_checks(inp)
    except ValueError as exc:
        raise Fallback(f"an input check failed ({str(exc).splitlines()[0][:80]})", batch_names_it=True) from None
    imu_path = os.fspath(imu_path)
    block_lines = int(BLOCK_LINES if block_lines is None else block_lines)
    whole = []  # the record's IMU summed to 10 Hz, for the loader's checks (made with the first block)

    def tee(blocks):
        for b in blocks:
            if not whole:
                dt = median(np.diff(b.t)) if len(b.t) > 1 else 0.0
                # the samples to expect: the file's size over the bytes per line so far (as _BlockRun sizes its own)
                lines = b.origin.line(len(b.t) - 1) if len(b.t) else 0
                expected = int(b.file_bytes * lines / b.file_bytes_done) if b.file_bytes_done else 0
                whole.append(_Coarse(max(1, int(round(1.0 / (CHECK_RATE_HZ * dt)))) if dt > 0 else 1, expected))
            whole[0].add(b.t, b.dtheta_b, b.dv_b)
            yield b

    def checks():
        from ..data.checks import heading_grid_step

        with heading_grid_step(whole[0].grid_step()):
            input_checks(inp, whole[0].imu(imu_path), imu_path)

    def prepare(blocks):
        head, done, want = [], False, 1
        while True:  # the alignment on the first blocks: as many as it reads
            while len(head) < want and not done:
                try:
                    head.append(next(blocks))
                except StopIteration:
                    done = True
            if not head:
                raise Fallback("no IMU samples (the whole-file reader names it)", batch_names_it=True)
            imu_head = _concat_blocks(head)
            try:
                t0, initial, sig, a = initial_state(inp, imu_head, imu_path)
                enough = a is None or (a.heading_source != "given" and a.samples_used < len(imu_head.t))
            except ValueError as exc:
                if done:
                    raise Fallback(f"the alignment failed ({str(exc).splitlines()[0][:80]})",
                                   batch_names_it=True) from None
                enough = False
            if enough or done:
                break
            if len(imu_head.t) >= ALIGN_MAX_SAMPLES:
                raise Fallback(f"the alignment needs more than the first {len(imu_head.t)} IMU samples")
            want = 2 * len(head)
        try:  # the unit checks on the first blocks at full rate: wrong units fail here, not after the run
            imu_unit_checks(inp, imu_head, imu_path)
        except ValueError as exc:
            raise Fallback(f"an input check failed ({str(exc).splitlines()[0][:80]})", batch_names_it=True) from None
        del imu_head
        ds0, cfg = csv_run_dataset(inp, imu_path, t0, initial, sig, a, imu=None, gnss=inp.gnss_all)
        try:
            cfg = configure(cfg)
        except ValueError as exc:
            raise Fallback(f"the configuration ({str(exc).splitlines()[0][:80]})", batch_names_it=True) from None
        why = stream_unsupported(cfg, out_suffix=Path(out).suffix, out_format=out_format)
        if why is not None:
            raise Fallback(why)
        run = _BlockRun(ds0, cfg, start_s=t0, end_s=None, gnss_raw=inp.gnss_all, output_rate_hz=output_rate_hz,
                        set_decimation=set_decimation, block_lines=block_lines, progress=progress, t0_exact=True,
                        count_cut_gnss=False, extra_checks=checks)

        def replay():
            while head:
                yield head.pop(0)
            yield from blocks

        return run, tee(replay())

    return _stream_to_file(out, lambda: imu_csv_blocks(imu_path, fmt, week=inp.week, t_offset_s=inp.offset,
                                                       block_lines=block_lines),
                           prepare, columns, precision, imu_path, out_format)
