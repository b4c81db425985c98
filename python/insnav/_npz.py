"""An uncompressed ``.npz`` (what ``np.savez`` writes) from 1-D columns, at
the speed of the disk: the member offsets follow from the names and sizes, so
two threads each gather (and scale) their half of the columns, a chunk of rows
across all of them at a time, into a small buffer, checksum them
(``zlib.crc32``) and write them at their offsets with ``os.pwrite``, each
member's local header last (it holds the checksum);
numpy's copy loops, zlib and the writes run with the GIL released.  The
zip structure is PKWARE APPNOTE 6.3 sections 4.3.7 (local header), 4.3.12
(central directory) and 4.3.16 (end record), without ZIP64: a file of
4 GiB or more goes through :mod:`zipfile` instead (slower, same result).

:class:`NpzColumns` writes the same file when the rows come block by block
(``insnav run`` streaming its solution): each column appended to its own
scratch file with its running checksum, and at the end the members
assembled (their ``.npy`` headers need the final length) by in-kernel copies
(``os.copy_file_range``), the checksum of header + data combined from the
two without reading the data again (zlib's ``crc32_combine``: the CRC
register is linear over GF(2), so advancing it by L zero bytes is a 32x32
bit matrix power)."""
from __future__ import annotations

import errno
import io
import os
import struct
import threading
import time
import zlib

import numpy as np

from ._threads import Job

__all__ = ["write_npz", "NpzColumns"]

#: the classic zip format's limits: 32-bit sizes and offsets, 16-bit member count
_MAX_OFFSET = 0xFFFFFFFF - 1
_MAX_MEMBERS = 0xFFFF - 1
#: rows a thread gathers, checksums and writes at a time, per column (128 KiB; the
#: chunk of a (N, 12) source array, 1.5 MiB, stays in the cache across its columns)
_CHUNK = 1 << 14
#: zipfile's defaults for a member written through ZipFile.open(name, "w")
_VERSION = 20
_MADE_BY = (3 << 8) | _VERSION  # Unix
_EXTERNAL_ATTR = 0o600 << 16


def _npy_header(n: int) -> bytes:
    """The ``.npy`` header of an (n,) float64 array (``np.lib.format``, version 1.0)."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": np.lib.format.dtype_to_descr(np.dtype(float)),
                                               "fortran_order": False, "shape": (n,)})
    return buf.getvalue()


def _layout(names: list[bytes], n: int) -> tuple[bytes, int, list[int], int]:
    """The members of an uncompressed npz of float64 columns of ``n`` rows: the
    ``.npy`` header, each member's data size (header + 8 n bytes), each local
    header's offset (30 bytes + the name before its data), and the end of the
    last member (where the central directory starts).  Shared by the whole-file
    writer and the block-by-block one, whose files must be the same."""
    head = _npy_header(n)
    size = len(head) + 8 * n
    offsets, off = [], 0
    for nm in names:
        offsets.append(off)
        off += 30 + len(nm) + size
    return head, size, offsets, off


def _dos_time() -> tuple[int, int]:
    y, mo, d, h, mi, s = time.localtime(time.time())[:6]
    return (h << 11) | (mi << 5) | (s // 2), ((max(y, 1980) - 1980) << 9) | (mo << 5) | d


def write_npz(path, columns) -> None:
    """Write ``columns`` (name, 1-D array, factor) as an uncompressed ``.npz``
    of float64 members ``name.npy`` = ``factor * array`` (``array`` as is
    when the factor is 1), bit for bit what ``np.savez`` stores.

    Parameters
    ----------
    path : str or Path
        Created, or overwritten (cut to the new length).
    columns : list of (str, ndarray (N,), float)
        Any stride; the arrays are not modified.
    """
    cols = [(name, np.asarray(x), float(f)) for name, x, f in columns]
    n = len(cols[0][1]) if cols else 0
    names = [(name + ".npy").encode("ascii") for name, _, _ in cols]
    head, size, offsets, off = _layout(names, n)
    if off > _MAX_OFFSET or len(cols) > _MAX_MEMBERS or any(len(x) != n or x.ndim != 1 for _, x, _ in cols):
        return _write_npz_zipfile(path, cols)
    dos_t, dos_d = _dos_time()
    crcs = [0] * len(cols)
    stop = threading.Event()
    # no O_TRUNC: on ext4 (auto_da_alloc) a file truncated to zero length is
    # flushed to disk by its close(), ~0.06-0.1 s for 167 MB here; a longer old
    # file is cut to the new size at the end instead (not to zero: no flush)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o666)

    def members(first: int, last: int) -> None:
        """Columns first..last-1, chunk by chunk across them: the columns of one
        (N, k) array are views of it, so a chunk of the array is read from memory
        once and stays in the cache for its next columns (column by column, each
        column's gather would read the whole array again: 1.35 GB instead of
        0.17 GB for the 31 solution columns)."""
        buf = np.empty((last - first, min(n, _CHUNK)))
        crc = [zlib.crc32(head)] * (last - first)
        start = [offsets[i] + 30 + len(names[i]) + len(head) for i in range(first, last)]
        for a in range(0, n, _CHUNK):  # in chunks: a small buffer, not one column's worth of resident memory
            if stop.is_set():
                return
            b = min(n, a + _CHUNK)
            for j, i in enumerate(range(first, last)):
                _, x, f = cols[i]
                chunk = buf[j, :b - a]
                if f == 1.0:
                    np.copyto(chunk, x[a:b], casting="same_kind")
                else:
                    np.multiply(x[a:b], f, out=chunk)
                crc[j] = zlib.crc32(chunk, crc[j])
                _pwrite_all(fd, chunk, start[j] + 8 * a)
        for j, i in enumerate(range(first, last)):
            crcs[i] = crc[j]
            local = struct.pack("<IHHHHHIIIHH", 0x04034B50, _VERSION, 0, 0, dos_t, dos_d, crc[j], size, size,
                                len(names[i]), 0) + names[i]
            _pwrite_all(fd, local + head, offsets[i])

    errors: list[BaseException] = []

    def worker(first: int, last: int) -> None:
        try:
            members(first, last)
        except BaseException as exc:  # noqa: BLE001 - re-raised on the calling thread
            errors.append(exc)
            stop.set()

    half = (len(cols) + 1) // 2  # the first half on this thread, the second on a helper
    try:
        helper = Job(worker, half, len(cols), name="insnav-npz-writer").start()
        try:
            worker(0, half)  # on this thread: Ctrl-C lands between two chunks
        except BaseException:  # Ctrl-C: the helper stops after its chunk, before the file is closed
            stop.set()
            helper.join()
            raise
        helper.join(on_interrupt=stop.set)  # a Ctrl-C meanwhile: raised once the helper's writes have ended
        if errors:
            raise errors[0]
        _write_central(fd, names, crcs, size, offsets, off, dos_t, dos_d)
    finally:
        os.close(fd)


def _write_central(fd, names, crcs, size, offsets, off, dos_t, dos_d) -> None:
    """The central directory and end record at ``off`` (the file cut after them)."""
    central = b"".join(
        struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, _MADE_BY, _VERSION, 0, 0, dos_t, dos_d, crcs[i], size,
                    size, len(nm), 0, 0, 0, 0, _EXTERNAL_ATTR, offsets[i]) + nm
        for i, nm in enumerate(names))
    end = central + struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, len(names), len(names), len(central), off, 0)
    _pwrite_all(fd, end, off)
    if os.fstat(fd).st_size > off + len(end):  # an older, longer file was there
        os.ftruncate(fd, off + len(end))


def _pwrite_all(fd: int, data, offset: int) -> None:
    """``data`` at ``offset``, however many writes it takes (an error raises OSError)."""
    data = memoryview(data).cast("B")
    while len(data):
        k = os.pwrite(fd, data, offset)
        if k <= 0:
            raise OSError(errno.EIO, "write returned 0")
        data, offset = data[k:], offset + k


def _write_npz_zipfile(path, cols) -> None:
    """:func:`write_npz` through :mod:`zipfile` (ZIP64), one column at a time."""
    import zipfile

    with zipfile.ZipFile(path, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as z:
        for name, x, f in cols:
            a = np.ascontiguousarray(x, float) if f == 1.0 else np.multiply(x, f)
            with z.open(name + ".npy", mode="w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, a, allow_pickle=False)


def _gf2_times(mat: list[int], vec: int) -> int:
    """A 32x32 bit matrix (its columns) times a 32-bit vector over GF(2)."""
    out, i = 0, 0
    while vec:
        if vec & 1:
            out ^= mat[i]
        vec >>= 1
        i += 1
    return out


def _crc_shift(length: int):
    """The matrix that advances a CRC-32 by ``length`` zero bytes: ``crc32(A + B) ==
    _gf2_times(_crc_shift(len(B)), crc32(A)) ^ crc32(B)`` (zlib's ``crc32_combine``)."""
    # one zero byte, column by column, from zlib itself: the register is linear in its start value
    step = [~zlib.crc32(b"\0", ~(1 << i) & 0xFFFFFFFF) & 0xFFFFFFFF for i in range(32)]
    out = [1 << i for i in range(32)]  # the identity
    while length:
        if length & 1:
            out = [_gf2_times(step, c) for c in out]
        length >>= 1
        if length:
            step = [_gf2_times(step, c) for c in step]
    return out


class NpzColumns:
    """An uncompressed ``.npz`` of float64 columns written block by block:
    :meth:`append` adds rows to every column (each to its own scratch file
    in ``scratch``, a folder this object owns), :meth:`finish` writes the
    ``.npz`` (bit for bit :func:`write_npz` of the whole columns, and so
    ``np.savez``'s), :meth:`discard` removes the scratch files.  Memory: one
    block of one column.

    Parameters
    ----------
    scratch : str or Path
        An empty folder for the column files (removed by :meth:`discard`).
    names : list of str
        The members, in order (``name.npy``).
    """

    def __init__(self, scratch, names):
        self.scratch = os.fspath(scratch)
        self.names = list(names)
        self.n = 0
        self.crcs = [0] * len(self.names)  # of each column's data so far
        self.fds = []
        try:
            for i in range(len(self.names)):
                self.fds.append(os.open(os.path.join(self.scratch, f"{i}.f8"),
                                        os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600))
        except BaseException:
            self.discard()
            raise
        self._buf = np.empty(0)

    def append(self, columns) -> None:
        """Rows for every column: ``columns`` a list of (1-D array, factor), one per name, of equal
        length; each column stored as ``factor * array`` (as is when the factor is 1)."""
        if len(columns) != len(self.names):
            raise ValueError(f"NpzColumns.append: {len(columns)} columns for {len(self.names)} names")
        m = len(columns[0][0]) if columns else 0
        if len(self._buf) < m:
            self._buf = np.empty(m)
        chunk = self._buf[:m]
        for i, (x, f) in enumerate(columns):
            if len(x) != m:
                raise ValueError(f"NpzColumns.append: column {self.names[i]!r} has {len(x)} rows, not {m}")
            if f == 1.0:  # as write_npz gathers it: the same values bit for bit
                np.copyto(chunk, x, casting="same_kind")
            else:
                np.multiply(x, f, out=chunk)
            self.crcs[i] = zlib.crc32(chunk, self.crcs[i])
            _pwrite_all(self.fds[i], chunk, 8 * self.n)
        self.n += m

    def finish(self, path) -> None:
        """Write the ``.npz`` to ``path`` (created, or overwritten)."""
        n, names = self.n, [(nm + ".npy").encode("ascii") for nm in self.names]
        head, size, offsets, off = _layout(names, n)
        if off > _MAX_OFFSET or len(names) > _MAX_MEMBERS:
            return self._finish_zipfile(path)
        shift = _crc_shift(8 * n)
        crcs = [_gf2_times(shift, zlib.crc32(head)) ^ c for c in self.crcs]
        dos_t, dos_d = _dos_time()
        fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o666)
        try:
            for i, nm in enumerate(names):
                local = struct.pack("<IHHHHHIIIHH", 0x04034B50, _VERSION, 0, 0, dos_t, dos_d, crcs[i], size, size,
                                    len(nm), 0) + nm
                _pwrite_all(fd, local + head, offsets[i])
                _copy_range(self.fds[i], fd, 8 * n, offsets[i] + len(local) + len(head))
            _write_central(fd, names, crcs, size, offsets, off, dos_t, dos_d)
        finally:
            os.close(fd)

    def _finish_zipfile(self, path) -> None:
        """:meth:`finish` through :mod:`zipfile` (ZIP64), as :func:`write_npz` writes a file of 4 GiB or more."""
        import zipfile

        with zipfile.ZipFile(path, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as z:
            for i, name in enumerate(self.names):
                with z.open(name + ".npy", mode="w", force_zip64=True) as fh:
                    fh.write(_npy_header(self.n))
                    for a in range(0, 8 * self.n, 8 * _CHUNK * 64):
                        fh.write(os.pread(self.fds[i], min(8 * _CHUNK * 64, 8 * self.n - a), a))

    def discard(self) -> None:
        """Close and remove the scratch files and their folder (again: nothing)."""
        fds, self.fds = self.fds, []
        for i, fd in enumerate(fds):
            os.close(fd)
            try:
                os.unlink(os.path.join(self.scratch, f"{i}.f8"))
            except FileNotFoundError:
                pass
        try:
            os.rmdir(self.scratch)
        except FileNotFoundError:
            pass


def _copy_range(src: int, dst: int, count: int, dst_offset: int) -> None:
    """``count`` bytes from the start of ``src`` to ``dst`` at ``dst_offset``: in the kernel
    (``copy_file_range``) where it can, else read and written in 8 MiB pieces."""
    done = 0
    copy = getattr(os, "copy_file_range", None)
    while done < count and copy is not None:
        try:
            k = copy(src, dst, count - done, done, dst_offset + done)
        except OSError as exc:
            if exc.errno in (errno.EXDEV, errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.EPERM):
                break  # another file system, or none: the plain copy below
            raise
        if k <= 0:
            break
        done += k
    while done < count:
        data = os.pread(src, min(8 << 20, count - done), done)
        if not data:
            raise OSError(errno.EIO, "a scratch column file is shorter than written")
        _pwrite_all(dst, data, dst_offset + done)
        done += len(data)
