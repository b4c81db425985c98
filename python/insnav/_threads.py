"""One call on a background thread, waited for in a way Ctrl-C cannot cut short.

insnav writes its outputs on helper threads (the streamed solution's writer,
the two halves of an ``.npz``).  When Ctrl-C or SIGTERM arrives, the main
thread's clean-up closes and removes the unfinished files, so it must first
wait for the helper's write to end.  ``Thread.join`` cannot be trusted for
that: on CPython 3.11 and 3.12, a KeyboardInterrupt that lands inside
``join`` marks the thread as stopped while it still runs (the bpo-45274
branch of ``Thread._wait_for_tstate_lock`` releases the thread's own lock),
and every later ``join`` returns at once.  The clean-up would then close a
file descriptor, or a ``pyarrow`` writer, under the helper's write: a write
to a reused descriptor, or a segmentation fault.

:class:`Job` ends with an Event set by its thread instead, and its
:meth:`Job.join` keeps waiting through interrupts, then raises the first
one."""
from __future__ import annotations

import threading


class Job:
    """``fn(*args, **kwargs)`` on its own non-daemon thread, started by :meth:`start`.

    :meth:`result` waits for it and raises its exception (interruptible: the job stays running);
    :meth:`join` waits for it whatever arrives meanwhile (for the clean-up of a failed run)."""

    def __init__(self, fn, *args, name: str = "insnav-writer", **kwargs):
        self._exc = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(fn, args, kwargs), name=name)

    def start(self) -> "Job":
        self._thread.start()
        return self

    def _run(self, fn, args, kwargs) -> None:
        try:
            fn(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001 - raised by result() on the calling thread
            self._exc = exc
        finally:
            self._done.set()

    def _ended(self) -> bool:
        """The call has returned, or its thread never started (an interrupt before :meth:`start`)."""
        return self._done.wait(0.1) or (self._thread.ident is None and not self._thread.is_alive())

    def join(self, on_interrupt=None) -> None:
        """Wait for the call to end.  A KeyboardInterrupt (or any exception a signal handler raises)
        that arrives meanwhile calls ``on_interrupt()`` (to ask the call to stop early) and is raised
        once the call has ended."""
        interrupted = None
        while True:
            try:
                if self._ended():
                    break
            except BaseException as exc:  # noqa: BLE001 - re-raised below, after the thread's end
                if interrupted is None:
                    interrupted = exc
                    if on_interrupt is not None:
                        on_interrupt()
        if interrupted is not None:
            raise interrupted

    def result(self) -> None:
        """Wait for the call and raise its exception.  An interrupt here propagates at once, the job
        still running: the caller's clean-up must :meth:`join` it."""
        while not self._ended():
            pass
        if self._exc is not None:
            exc, self._exc = self._exc, None
            raise exc
