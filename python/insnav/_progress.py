"""Progress of long runs on a terminal: the C++ loops report (sample, count)
at most every 20 ms beside their Ctrl-C check (``_core.set_progress``);
:func:`reporting` shows a bar on a TTY once a run is predicted to last more
than about two seconds -- tqdm's when it is installed, else one stderr line
rewritten in place.  Nothing is printed when the stream is not a terminal."""
from __future__ import annotations

import contextlib
import sys
import time

__all__ = ["Progress", "reporting"]


class Progress:
    """Callable ``(done, total)`` drawing a progress bar for one task.

    Parameters
    ----------
    label : str
    stream : text stream, default sys.stderr
    min_seconds : float
        The bar appears only when the task is predicted to take longer [s]
        (predicted from the rate after at least ``0.3`` s).
    force : bool
        Draw even when ``stream`` is not a terminal (tests).
    unit : str
        What ``done`` counts (tqdm's unit).
    """

    def __init__(self, label: str, stream=None, min_seconds: float = 2.0, force: bool = False,
                 unit: str = " samples"):
        self.unit = unit
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.min_seconds = min_seconds
        isatty = getattr(self.stream, "isatty", lambda: False)
        self.enabled = force or bool(isatty())
        self.t0 = time.perf_counter()
        self._bar = None
        self._plain = False
        self._last = 0.0

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled or total <= 0:
            return
        now = time.perf_counter()
        if self._bar is None and not self._plain:
            elapsed = now - self.t0
            if done <= 0 or elapsed < 0.3 or elapsed * total / done < self.min_seconds:
                return
            try:
                from tqdm import tqdm
            except ImportError:
                self._plain = True
            else:
                self._bar = tqdm(total=total, desc=self.label, unit=self.unit, unit_scale=True, file=self.stream,
                                 leave=False, dynamic_ncols=True, mininterval=0.2)
        if now - self._last < 0.2 and done < total:
            return
        self._last = now
        if self._bar is not None:
            self._bar.n = done
            self._bar.refresh()
        else:
            rate = done / max(now - self.t0, 1e-9)
            left = (total - done) / rate if rate > 0 else float("nan")
            self.stream.write(f"\r{self.label}: {100.0 * done / total:5.1f} % ({left:.0f} s left)   ")
            self.stream.flush()

    def close(self) -> None:
        """Remove the bar (or end the plain line)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self._plain:
            self.stream.write("\r" + " " * 60 + "\r")
            self.stream.flush()
            self._plain = False


@contextlib.contextmanager
def reporting(label: str, enabled: bool = True, **kw):
    """Within the block, every run's C++ loop reports to a :class:`Progress`
    (yielded; None when ``enabled`` is false)."""
    if not enabled:
        yield None
        return
    from . import _core

    bar = Progress(label, **kw)
    _core.set_progress(bar)
    try:
        yield bar
    finally:
        _core.set_progress(None)
        bar.close()
