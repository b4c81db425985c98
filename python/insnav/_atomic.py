"""Atomic file output: write to a temporary file beside the target, then rename,
so an interrupted run never leaves a partial file that looks complete.

Inside :func:`output_set` the renames wait: every file written through
:func:`atomic_write_with` / :func:`atomic_write_text` stays a temporary file
beside its destination until the whole set has been written, and is renamed
into place only then; an error (a full disk, Ctrl-C) removes the temporary
files and leaves every file that existed before exactly as it was."""
from __future__ import annotations

import contextlib
import contextvars
import math
import os
import tempfile
from pathlib import Path


def umask() -> int:
    """The process umask (read without changing it for good)."""
    m = os.umask(0)
    os.umask(m)
    return m


def chmod_like_new(path, directory: bool = False) -> None:
    """Give a file made by mkstemp/mkdtemp (0600/0700) the mode a plain
    open()/mkdir() would have given it under the user's umask."""
    os.chmod(path, (0o777 if directory else 0o666) & ~umask())


def json_safe(obj):
    """``obj`` with every non-finite float replaced by None (JSON has no
    Infinity/NaN); containers are copied, numpy scalars and arrays converted."""
    try:
        import numpy as np
    except ImportError:  # pragma: no cover
        np = None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if np is not None and isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if np is not None and isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


class OutputSet:
    """The files of one command, written as temporary files beside their
    destinations and renamed into place together by :meth:`commit`
    (see :func:`output_set`)."""

    def __init__(self):
        self._pending: dict[Path, Path] = {}  # destination -> its temporary file
        self._written: set[Path] = set()
        self._stale: list[tuple[Path, object]] = []  # (a file this command may leave out, "is it ours?")

    def replaces(self, paths, is_ours) -> None:
        """The files a command may write (every sidecar of its ``--out``), of which this run may leave
        some out: at :meth:`commit` each one not written now and holding an earlier output
        (``is_ours(path)`` true: :func:`insnav._outputs.insnav_output_kind`) is removed with the
        renames, so what lies beside ``--out`` is this run's set, not a mix (the residuals of an
        earlier tight run beside a loose run's solution, reported as its)."""
        self._stale += [(Path(p), is_ours) for p in paths]

    def add(self, tmp, path) -> None:
        """Rename ``tmp`` to ``path`` at :meth:`commit` (a later file for the same ``path`` wins)."""
        path = Path(path)
        old = self._pending.pop(path, None)
        if old is not None:
            _unlink(old)
        self._pending[path] = Path(tmp)

    @property
    def paths(self) -> list[Path]:
        """The destinations, in the order they were written."""
        return list(self._pending)

    def commit(self) -> None:
        """Rename every temporary file into place, with SIGINT and SIGTERM held
        back meanwhile (:func:`signals_held`: a Ctrl-C then arrives after the
        last rename, never half a set of new files beside half of the old ones)."""
        try:
            with signals_held():
                while self._pending:
                    path, tmp = next(iter(self._pending.items()))
                    os.replace(tmp, path)
                    del self._pending[path]
                    self._written.add(path)
                for path, is_ours in self._stale:
                    if path not in self._written and os.path.lexists(path) and is_ours(path):
                        _unlink(path)
        finally:
            self.abort()  # a rename that failed: the rest stay as they were

    def abort(self) -> None:
        """Remove the temporary files; the destinations are not touched."""
        while self._pending:
            _unlink(self._pending.popitem()[1])


@contextlib.contextmanager
def signals_held():
    """SIGINT and SIGTERM held back for the ``with`` block (delivered at its
    end) in the main thread; elsewhere, or without ``pthread_sigmask``, nothing."""
    import signal
    import threading

    held = threading.current_thread() is threading.main_thread() and hasattr(signal, "pthread_sigmask")
    if held:
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        if held:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)


@contextlib.contextmanager
def interrupts_deferred():
    """SIGINT and SIGTERM that arrive during the ``with`` block are delivered at its end (their Python
    handler then raises as it would have: KeyboardInterrupt, the command line's Terminated), so a
    clean-up or a swap of an old output for a new one runs to its end.  Unlike
    :func:`signals_held` it works whichever thread the kernel hands the signal to (a writer or reader
    thread still running): Python runs every handler on the main thread.  Off the main thread, or for a
    signal without a Python handler, nothing changes."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if callable(handler):
            previous[signum] = handler
            signal.signal(signum, lambda n, frame: got.append(n))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if got:
            previous[got[0]](got[0], None)


_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("insnav_output_set", default=None)


@contextlib.contextmanager
def output_set():
    """Write several files as one: inside the ``with`` block every
    :func:`atomic_write_with` / :func:`atomic_write_text` leaves its file as a
    temporary file beside the destination; when the block ends normally they
    are all renamed into place, on any exception (Ctrl-C included) they are
    removed and no destination is touched.  Nested blocks join the outer one.

    Yields
    ------
    OutputSet
    """
    outer = _ACTIVE.get()
    if outer is not None:
        yield outer
        return
    s = OutputSet()
    token = _ACTIVE.set(s)
    try:
        yield s
    except BaseException:
        s.abort()
        raise
    finally:
        _ACTIVE.reset(token)
    s.commit()


def _unlink(p) -> None:
    try:
        os.unlink(p)
    except FileNotFoundError:
        pass


def _finish(tmp, path: Path) -> None:
    """``tmp`` is complete: rename it to ``path`` now, or at the end of the active :func:`output_set`."""
    chmod_like_new(tmp)
    s = _ACTIVE.get()
    if s is None:
        os.replace(tmp, path)
    else:
        s.add(tmp, path)


def atomic_write_with(path, write) -> Path:
    """Write ``path`` through ``write(tmp_path)``: a temporary file beside it
    (``.NAME.XXXX.part.SUFFIX``, mode as a plain open() under the umask gives)
    renamed into place once ``write`` returns (inside :func:`output_set`: when
    the set is complete); on any exception, Ctrl-C included, the temporary
    file is removed and ``path`` left as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:
        with interrupts_deferred():  # a Ctrl-C inside mkstemp, after its open, would leave the file
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part" + path.suffix, dir=path.parent)
            os.close(fd)
        write(tmp)
        _finish(tmp, path)
    except BaseException:
        if tmp is not None:
            _unlink(tmp)
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    """:func:`atomic_write_with` of a text file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:
        with interrupts_deferred():  # a Ctrl-C inside mkstemp, after its open, would leave the file
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
            f = os.fdopen(fd, "w")
        with f:
            f.write(text)
        _finish(tmp, path)
    except BaseException:
        if tmp is not None:
            _unlink(tmp)
        raise
    return path
