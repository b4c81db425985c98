"""``python -m insnav``: the command line (:func:`insnav.cli.main`).

Once the command has returned, nothing is left to do but the interpreter's
own finalization: tearing down every module and freeing numpy's objects one
by one (~25 ms after ``insnav run``).  The process therefore runs the exit
callbacks (``atexit``), flushes its standard streams and leaves with
``os._exit``, unless another thread is still running or a profiler or tracer
(cProfile, coverage) is attached or ``-i`` given: those exit normally.
"""
import os
import sys

try:
    from .cli import main
except KeyboardInterrupt:  # Ctrl-C while the command line's modules load: one line, not a traceback
    sys.stderr.write("insnav: interrupted\n")
    os._exit(130)


def _interrupted_late(signum, frame) -> None:
    """Ctrl-C after the command returned (exit callbacks, flushing): still one line and 130."""
    try:
        sys.stderr.write("insnav: interrupted\n")
        sys.stderr.flush()
    finally:
        os._exit(130)


def _leave(rc: int) -> None:
    import atexit
    import signal
    import threading

    if threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _interrupted_late)  # an exit callback would swallow KeyboardInterrupt

    monitoring = getattr(sys, "monitoring", None)  # Python >= 3.12: coverage's tool
    watched = monitoring is not None and any(monitoring.get_tool(i) is not None for i in range(6))
    if (threading.active_count() > 1 or sys.getprofile() is not None or sys.gettrace() is not None or watched
            or sys.flags.inspect):
        sys.exit(rc)
    atexit._run_exitfuncs()  # what the normal exit runs first (and clears)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):  # a closed or broken pipe: the normal exit reports it
        sys.exit(rc)
    os._exit(rc)


try:
    _leave(main())
except KeyboardInterrupt:  # a Ctrl-C in the moment after main() restored Python's handler: 130, one line in all
    from . import cli as _cli

    if not _cli.signal_reported:
        sys.stderr.write("insnav: interrupted\n")
    sys.stderr.flush()
    os._exit(130)
