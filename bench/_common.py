"""Shared helpers of the result generators in bench/ (not part of the package)."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def git_commit() -> str:
    """Short hash of HEAD, marked when tracked files have uncommitted changes."""
    try:
        c = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.strip()
        # the results documents themselves do not count (run_all writes them one after the other)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                ":(exclude)docs/results"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
        return c + (" (with uncommitted changes)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_child(args, cwd) -> tuple[float, float, float]:
    """(CPU = user + system [s], wall [s], peak RSS [MB]) of one run of ``args`` as a child process
    (``os.wait4``: the child's own resource use); raises on a non-zero exit with its stderr's end."""
    t = time.perf_counter()
    p = subprocess.Popen(args, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    err = p.stderr.read().decode(errors="replace")
    p.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(map(str, args))} failed:\n{err[-2000:]}")
    return ru.ru_utime + ru.ru_stime, wall, ru.ru_maxrss / 1024.0


def compile_package() -> None:
    """Compile the installed insnav package's bytecode, as pip does on install, before a timed run.

    A process that finds no ``.pyc`` compiles every module it imports (~0.1 s per ``insnav`` command);
    this machine sets PYTHONDONTWRITEBYTECODE, so without this step every timed command would pay it.
    The package is found without being imported (this process stays small: its children's peak RSS
    counts it).  Every one of its search locations is compiled: an editable install has two (the
    compiled core in site-packages, the sources in the tree), and compiling only the first left every
    timed command compiling the sources (measured: +0.1 s of CPU on the RTK and SPP runs)."""
    import importlib.util

    locations = list(importlib.util.find_spec("insnav").submodule_search_locations)
    subprocess.run([sys.executable, "-m", "compileall", "-q", *locations], check=True, stdout=subprocess.DEVNULL)
