"""The ``insnav`` command line.

Each area registers its subcommand through an ``add_*_parser(subparsers)``
function; user errors (bad files, keys, values) exit with status 2 and a
one-line message naming the problem, without a traceback.  Set
``INSNAV_DEBUG=1`` to get the traceback instead.
"""
from __future__ import annotations

import os
import sys

from .. import __version__
from ..errors import UserError, seed_arg




def _add_demo_parser(sub) -> None:
    import argparse

    p = sub.add_parser(
        "demo",
        help="run the built-in demonstration (the README's main job)",
        description="Simulate a built-in scenario, run the filters and print a comparison table.\n"
        "Example: insnav demo --out insnav-demo",
        epilog="The table gives the run time [s], the RMS position error N/E/D [m] and attitude error\n"
        "roll/pitch/yaw [deg], the largest error after the GPS outage and the reconvergence\n"
        "time [s]; report.md and the error plots (with 3-sigma bounds) go to --out.\n"
        "seed000-sim: 150 s, 200 Hz MEMS IMU, 1 Hz GPS lost 50-90 s.  Without --quick also\n"
        "seed001-high (delayed GNSS) and seed003-1sat (loose vs tight): about 10 s in all.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="insnav-demo", help="report folder (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="a shorter run (used by the tests)")
    p.add_argument("--seed", type=seed_arg, default=1, help="random seed (default: %(default)s)")
    p.set_defaults(func=lambda args: __import__("insnav.cli.demo", fromlist=["main"]).main(args))


#: module -> (its add_*_parser functions, the commands they add), in the order of the help
_AREAS = (
    ("insnav.sim.cli", ("add_scenarios_parser", "add_simulate_parser"), ("scenarios", "simulate")),
    ("insnav.cli.run", ("add_run_parser",), ("run",)),
    ("insnav.analysis.evaluate", ("add_evaluate_parser",), ("evaluate",)),
    ("insnav.analysis.montecarlo", ("add_compare_parser",), ("compare",)),
    ("insnav.cli.report", ("add_report_parser",), ("report",)),
    ("insnav.cli.bench", ("add_bench_parser",), ("bench",)),
    ("insnav.cli.tune", ("add_tune_parser",), ("tune",)),
    ("insnav.cli.allan", ("add_allan_parser",), ("allan",)),
)


def _command_of(argv) -> str | None:
    """The sub-command ``argv`` names (its first token not starting with '-'), if any."""
    for tok in argv:
        if not tok.startswith("-"):
            return tok
    return None


def _asks_version(argv) -> bool:
    """Whether ``argv`` (no sub-command in it) reaches ``--version`` (or an
    abbreviation argparse accepts, ``--v``...) before any ``-h``/``--help``
    or ``--``: argparse then prints the version and exits, whatever the
    sub-commands, so none of their modules need to load."""
    for tok in argv:
        name = tok.split("=", 1)[0]
        if tok == "--" or tok.startswith("-h") or (len(name) > 2 and "--help".startswith(name)):
            return False
        if len(name) > 2 and "--version".startswith(name):
            return True
    return False


def build_parser(command: str | None = None, areas: bool = True) -> "argparse.ArgumentParser":  # noqa: F821
    """The ``insnav`` parser; with a known ``command``, only that area's
    sub-command is registered (its module alone is imported: ``insnav run``
    does not load the simulator or the analysis), else all of them; with
    ``areas=False`` none (``insnav --version``: no numpy, no area module;
    the usage line is the same)."""
    import argparse  # here: the RTK run of insnav.cli.rtk_fast reads its few options itself

    parser = argparse.ArgumentParser(
        prog="insnav",
        description="insnav: GNSS/INS integrated navigation (EKF, RB-UKF, UKF, random-delay and particle filters).\n"
        "Frames: NED navigation, FRD body, 3-2-1 Euler angles. Units are in every column name.",
        epilog="examples:\n"
        "  insnav demo --quick                                  # the main job in a few seconds\n"
        "  insnav simulate seed000-sim --out run1               # 150 s at 200 Hz -> run1/*.csv\n"
        "  insnav run run1 --filter rbukf --out run1-sol.csv     # beside the dataset, not inside it\n"
        "  insnav evaluate run1-sol.csv run1 --outages 50:90    # errors in m, m/s, deg; times in s\n"
        "Each command has its own --help with examples.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"insnav {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the full traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    if not areas:
        return parser
    known = command == "demo" or any(command in cmds for _, _, cmds in _AREAS)
    if not known or command == "demo":
        _add_demo_parser(sub)
    # areas that live in their own modules register their sub-commands here
    import importlib

    for module, funcs, cmds in _AREAS:
        if known and command not in cmds:
            continue
        mod = importlib.import_module(module)
        for f in funcs:
            getattr(mod, f)(sub)
    return parser


def _single_threaded_blas() -> None:
    """One OpenBLAS thread for the command line's process, unless the user
    chose otherwise (``OPENBLAS_NUM_THREADS``), set before numpy is imported.

    numpy's OpenBLAS starts a pool of threads at import that busy-wait for
    work; on a 2-core machine they take a core from the filter and the
    reader (``import numpy``: 0.15-0.18 s with the pool, 0.09 s without;
    ``insnav run`` on the KF-GINS track ~0.07 s faster).  The command line's
    numpy work is on small vectors and matrices (the filters run in C++), so
    it loses nothing.  The ``OMP_NUM_THREADS`` of the C++ core is left alone."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch system's time limit) during a command: raised like Ctrl-C's
    KeyboardInterrupt, so the same paths stop the C++ loops and discard the unfinished
    outputs (:func:`insnav._atomic.output_set`); :func:`main` ends with one line and 143."""


class _SigintWatch:
    """SIGINT raises KeyboardInterrupt as Python's default handler does, and
    SIGTERM raises :class:`Terminated` instead of killing the process with no
    word (the default action); each is also remembered: an interrupt that
    lands where an exception is ignored (a finalizer, a library's broad
    ``except``) still ends the command with status 130 (143) instead of being
    swallowed (:func:`main`)."""

    def __init__(self):
        self.seen = None  # the exception class of the signal received
        self.previous = {}

    def _handler(self, signum, frame):
        import signal

        self.seen = Terminated if signum == signal.SIGTERM else KeyboardInterrupt
        raise self.seen

    def __enter__(self):
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            # not when the parent ignores them (nohup, a background job of a non-interactive shell)
            if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                self.previous[signal.SIGINT] = signal.signal(signal.SIGINT, self._handler)
            if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
                self.previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, self._handler)
        return self

    def quiet(self) -> None:
        """From here on (the command is ending with its one line) a further SIGINT or SIGTERM is
        ignored: a second Ctrl-C no longer raises in the middle of the report (a traceback)."""
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            for signum in self.previous:
                signal.signal(signum, lambda n, frame: None)

    def __exit__(self, *exc):
        import signal

        for signum, previous in self.previous.items():
            signal.signal(signum, previous)
        return False


#: options whose value is written, not read (``--out /dev/null`` is a valid way to discard a solution)
_OUTPUT_OPTIONS = ("--out", "--out-dir")


def _refuse_special_inputs(argv) -> None:
    """:class:`UserError` for a command-line input that names a named pipe, socket or device.

    Every input insnav reads is opened as a file, read whole and some of them twice (the RINEX
    readers, the stream's GNSS pass), so a FIFO given as ``--obs`` would block until a writer appears
    and then be read once.  Every token (and every ``--opt=value``'s value, and each path of a
    comma-separated list) that names an existing such file is refused with one line naming it, except
    the values of :data:`_OUTPUT_OPTIONS`."""
    import stat

    skip = False
    for tok in argv:
        tok = str(tok)
        if skip:
            skip = False
            continue
        if tok in _OUTPUT_OPTIONS:
            skip = True
            continue
        opt, eq, val = tok.partition("=")
        if eq and opt.startswith("--"):
            if opt in _OUTPUT_OPTIONS:
                continue
            tok = val
        for path in tok.split(","):
            try:
                mode = os.stat(path).st_mode
            except (OSError, ValueError):
                continue
            if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
                raise UserError(f"{path}: not a regular file (a named pipe, socket or device): insnav reads its "
                                "inputs as files, whole and some twice; copy it to a file first")


#: set once a command has printed its "interrupted" / "terminated" line (``python -m insnav`` prints no
#: second one for a Ctrl-C that lands after :func:`main` restored Python's handler)
signal_reported = False


def _ended_by_signal(name, term: bool) -> int:
    """The one line of a command ended by Ctrl-C (130) or SIGTERM (143), and its status."""
    global signal_reported
    signal_reported = True
    print(f"insnav{' ' + name if name else ''}: {'terminated' if term else 'interrupted'}", file=sys.stderr)
    return 143 if term else 130


def _one_line_warnings() -> None:
    """Print each :class:`insnav.errors.InsnavWarning` once, as ``warning: <text>`` on stderr (not Python's
    ``file:line: category`` form with the source line); other warnings keep Python's own printing."""
    import warnings

    from ..errors import InsnavWarning

    python_show = warnings.showwarning
    shown: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, InsnavWarning):
            return python_show(message, category, filename, lineno, file, line)
        text = str(message)
        if text not in shown:
            shown.add(text)
            print(f"warning: {text}", file=sys.stderr)

    warnings.showwarning = show
    warnings.filterwarnings("always", category=InsnavWarning)


def main(argv=None) -> int:
    """Run one command; its status: 0, 2 (an error, one line on stderr), 130 (Ctrl-C, one line)
    or 143 (SIGTERM, one line)."""
    import warnings

    with warnings.catch_warnings():  # the one-line printing for this command only (main may run in-process)
        _one_line_warnings()
        return _main(argv)


def _main(argv) -> int:
    command = _command_of(sys.argv[1:] if argv is None else argv)
    version_only = command is None and _asks_version(sys.argv[1:] if argv is None else argv)
    args = None
    with _SigintWatch() as sigint:
        try:
            _refuse_special_inputs(sys.argv[1:] if argv is None else argv)
            if command == "run" and os.environ.get("INSNAV_RTK_FASTPATH", "1") != "0":
                from .rtk_fast import run_fast  # an RTK run from RINEX files without numpy, else None

                rc = run_fast(sys.argv[1:] if argv is None else argv)
                if rc is not None:
                    sys.stdout.flush()
                    if sigint.seen:
                        raise sigint.seen
                    return int(rc)
            _single_threaded_blas()
            parser = build_parser(command, areas=not version_only)  # imports the command's modules: Ctrl-C here is one line too
            args = parser.parse_args(argv)
            if not getattr(args, "func", None):
                parser.print_help()
                return 0
            rc = args.func(args)
            sys.stdout.flush()
            if sigint.seen:  # interrupted where the exception was swallowed
                raise sigint.seen
        except BrokenPipeError:  # `insnav ... | head`: the reader left; nothing to report
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            return 0
        except KeyboardInterrupt as exc:
            sigint.quiet()
            return _ended_by_signal(getattr(args, "command", None) or command,
                                    isinstance(exc, Terminated) or sigint.seen is Terminated)
        except Exception as exc:  # noqa: BLE001 - every error is one line; --debug for the traceback
            sigint.quiet()
            if sigint.seen:  # a library turned the interrupt into its own error (numpy's import: ImportError)
                return _ended_by_signal(getattr(args, "command", None) or command, sigint.seen is Terminated)
            if getattr(args, "debug", False) or os.environ.get("INSNAV_DEBUG"):
                raise
            msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            msg = "; ".join(line.strip() for line in str(msg).splitlines() if line.strip()) or type(exc).__name__
            kind = "" if isinstance(exc, (UserError, OSError, ValueError, KeyError)) else f"{type(exc).__name__}: "
            print(f"insnav {getattr(args, 'command', None) or command}: error: {kind}{msg}", file=sys.stderr)
            return 2
    return int(rc or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
