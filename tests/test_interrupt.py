"""Ctrl-C: SIGINT to a running ``insnav run`` ends it within a second with one
line on stderr and no output file (the C++ loop checks for signals, taking
the GIL only for that check); the progress bar only on a terminal."""
from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import insnav
from insnav._progress import Progress, reporting


@pytest.fixture(scope="module")
def uav_dir(tmp_path_factory):
    """seed004-uav: the tight UPF takes ~6 s in its C++ loop, the read ~0.3 s."""
    return insnav.simulate("seed004-uav", seed=1).save(tmp_path_factory.mktemp("int") / "uav")


def _sigint_default():
    """The child's SIGINT at its default whatever the test runner inherited: a
    suite started in the background of a non-interactive shell ignores SIGINT,
    its children inherit that, and the command then rightly leaves it ignored."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigint_stops_a_run_fast_with_one_line_and_no_output(uav_dir, tmp_path):
    out = tmp_path / "sol.csv"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "insnav", "run", str(uav_dir), "--coupling", "tight",
                             "--filter", "upf", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, preexec_fn=_sigint_default)
    time.sleep(2.5)  # start-up and read ~1 s: now inside the filter's C++ loop (~6 s)
    assert proc.poll() is None, proc.communicate()
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    try:
        stdout, stderr = proc.communicate(timeout=10)
    finally:
        proc.kill()
    dt = time.perf_counter() - t0
    assert proc.returncode == 130, (stdout, stderr)
    assert dt < 1.0, f"took {dt:.2f} s to stop"
    assert stderr.strip().splitlines() == ["insnav run: interrupted"], stderr
    assert "Traceback" not in stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no solution, no sidecar, no temp file


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigterm_stops_a_run_with_one_line_and_keeps_the_earlier_output(uav_dir, tmp_path):
    """SIGTERM (``kill``, a batch system's time limit) inside the filter's C++ loop: status 143 within a
    second, the one line ``insnav run: terminated``, no traceback, the earlier solution under --out byte
    for byte as it was and no temporary file beside it (before: killed by the signal with no word)."""
    out = tmp_path / "sol.csv"
    earlier = b"t_s,lat_deg,lon_deg,h_m\n0.0,48.0,11.0,500.0\n"  # an insnav solution's columns: replaceable
    out.write_bytes(earlier)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "insnav", "run", str(uav_dir), "--coupling", "tight",
                             "--filter", "upf", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, preexec_fn=_sigint_default)
    time.sleep(2.5)  # start-up and read ~1 s: now inside the filter's C++ loop (~6 s)
    assert proc.poll() is None, proc.communicate()
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGTERM)
    try:
        stdout, stderr = proc.communicate(timeout=10)
    finally:
        proc.kill()
    dt = time.perf_counter() - t0
    assert proc.returncode == 143, (stdout, stderr)
    assert dt < 1.0, f"took {dt:.2f} s to stop"
    assert stderr.strip().splitlines() == ["insnav run: terminated"], stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sol.csv"]
    assert out.read_bytes() == earlier


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("library_error", [False, True])
@pytest.mark.parametrize("sig, handler, status, word", [
    (signal.SIGTERM, signal.SIG_DFL, 143, "terminated"),
    (signal.SIGINT, signal.default_int_handler, 130, "interrupted"),  # Python's own Ctrl-C handler
])
def test_a_signal_swallowed_inside_a_command_still_ends_it(monkeypatch, tmp_path, capsys, sig, handler, status,
                                                           word, library_error):
    """A SIGTERM or SIGINT whose exception a library swallows (a finalizer, a broad except) late in
    `insnav report`: the command still ends with one line and status 143 / 130, not 0; the
    handler it installed is gone afterwards.  The same where the library turns it into an error of
    its own (numpy's import: "ImportError ... initialization failed", which was printed as the
    command's error with status 2)."""
    import insnav.analysis.report as rep
    import insnav.cli as cli

    sol = tmp_path / "sol.csv"
    sol.write_text("x\n")

    def report(*a, **k):
        try:
            os.kill(os.getpid(), sig)
            time.sleep(0.5)
        except BaseException:  # noqa: BLE001 - what swallowed it
            if library_error:
                raise ImportError("initialization failed") from None
        out = tmp_path / "r" / "report.html"
        out.parent.mkdir()
        out.write_text("")
        return out

    monkeypatch.setattr(rep, "report", report)
    inherited = signal.signal(sig, handler)
    try:
        assert cli.main(["report", str(sol)]) == status
        assert signal.getsignal(sig) == handler  # the command's handler is gone
    finally:
        signal.signal(sig, inherited)
    assert capsys.readouterr().err.strip().splitlines() == [f"insnav report: {word}"]


def test_interrupt_inside_the_loop_raises_keyboardinterrupt_and_leaves_no_state(uav_dir):
    """A progress callback raising (as the signal handler does) stops the C++
    loop at its next check; the next run is unaffected."""
    ds = insnav.load_dataset(uav_dir)
    calls = []

    def stop(k, n):
        calls.append(k)
        if k > 0:
            raise KeyboardInterrupt

    from insnav import _core

    _core.set_progress(stop)
    try:
        t0 = time.perf_counter()
        with pytest.raises(KeyboardInterrupt):
            insnav.run(ds, filter="ekf", coupling="tight")
        assert time.perf_counter() - t0 < 5.0 and calls[-1] < 180_000
    finally:
        _core.set_progress(None)
    sol = insnav.run(ds, filter="ekf", coupling="tight")
    assert len(sol) == 180_000


def test_progress_bar_only_on_a_terminal_and_for_long_tasks():
    quiet = io.StringIO()  # not a TTY
    p = Progress("run", stream=quiet, min_seconds=0.0)
    p.t0 -= 1.0
    p(10, 100)
    p.close()
    assert quiet.getvalue() == ""
    shown = io.StringIO()
    p = Progress("run", stream=shown, min_seconds=2.0, force=True)
    p.t0 -= 0.5
    p(90, 100)  # predicted 0.56 s: no bar
    assert shown.getvalue() == ""
    p.t0 -= 1.0
    p(10, 100)  # predicted 15 s: bar
    p.close()
    assert "run" in shown.getvalue()
    with reporting("x", enabled=False) as bar:
        assert bar is None


def test_simulate_reports_every_stage_in_order_and_the_same_dataset():
    """insnav.simulate(progress=) is told each stage once, in order, and the
    callable changes nothing in the dataset (insnav simulate draws its bar with it)."""
    from insnav.sim import SIMULATE_STAGES

    seen = []
    ds = insnav.simulate("seed003-1sat", seed=4, progress=lambda k, n: seen.append((k, n)))
    n = len(SIMULATE_STAGES)
    assert seen == [(k, n) for k in range(1, n + 1)]
    ref = insnav.simulate("seed003-1sat", seed=4)
    assert np.array_equal(ds.imu.dtheta_b, ref.imu.dtheta_b) and np.array_equal(ds.gnss_raw.pseudorange_m,
                                                                                ref.gnss_raw.pseudorange_m,
                                                                                equal_nan=True)


def test_ctrl_c_while_the_command_modules_load_is_one_line(monkeypatch, capsys):
    """Ctrl-C during the imports of a command (insnav.cli.build_parser): one line, 130, no traceback."""
    import importlib

    import insnav.cli as cli

    real = importlib.import_module

    def interrupted(name, *a, **k):
        if name == "insnav.cli.run":
            raise KeyboardInterrupt
        return real(name, *a, **k)

    monkeypatch.setattr(importlib, "import_module", interrupted)
    assert cli.main(["run", "x", "--out", "y.csv"]) == 130
    assert capsys.readouterr().err.strip().splitlines() == ["insnav run: interrupted"]


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("when", ["import", "exit"])
def test_ctrl_c_at_startup_or_exit_of_python_m_insnav(when):
    """`python -m insnav`: Ctrl-C while insnav.cli is imported, or in an exit callback after the
    command returned 0 (atexit would swallow it): one line on stderr and status 130."""
    if when == "import":
        code = ("import builtins, runpy, sys\n"
                "real = builtins.__import__\n"
                "def imp(name, *a, **k):\n"
                "    if name == 'cli' or name == 'insnav.cli':\n"
                "        raise KeyboardInterrupt\n"
                "    return real(name, *a, **k)\n"
                "builtins.__import__ = imp\n"
                "sys.argv = ['insnav', 'scenarios']\n"
                "runpy.run_module('insnav', run_name='__main__')\n")
    else:
        code = ("import atexit, os, runpy, signal, sys, time\n"
                "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(1.0)))\n"
                "sys.argv = ['insnav', 'scenarios']\n"
                "runpy.run_module('insnav', run_name='__main__')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       preexec_fn=_sigint_default)
    assert r.returncode == 130, (r.stdout, r.stderr)
    assert r.stderr.strip().splitlines()[-1] == "insnav: interrupted" and "Traceback" not in r.stderr


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_interrupts_deferred_delivers_the_signal_after_the_block():
    from insnav._atomic import interrupts_deferred

    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    done = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with interrupts_deferred():
                os.kill(os.getpid(), signal.SIGINT)
                os.kill(os.getpid(), signal.SIGINT)  # a second Ctrl-C: still one interrupt, after the block
                time.sleep(0.05)
                done.append(1)
        assert done == [1] and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, inherited)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_ctrl_c_while_simulate_swaps_the_dataset_keeps_one_whole_dataset(tmp_path, monkeypatch):
    """``insnav simulate --overwrite``: a Ctrl-C between renaming the old dataset away and the new one
    in left no dataset at the path (the old one only as a hidden ``.NAME.old-PID``).  The swap now
    ends before the interrupt is raised: the new dataset in place, no hidden folder."""
    import insnav.data.dataset as dsmod
    from insnav.data.dataset import load_dataset
    from conftest import short_tight_dataset

    ds = short_tight_dataset(20.0)
    out = tmp_path / "ds"
    ds.save(out)
    real_rename, calls = os.rename, []

    def rename(a, b):
        calls.append(1)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # between the two renames
            time.sleep(0.05)
        real_rename(a, b)

    monkeypatch.setattr(dsmod.os, "rename", rename)
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            ds.save(out, overwrite=True)
    finally:
        signal.signal(signal.SIGINT, inherited)
    assert len(calls) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    assert len(load_dataset(out).imu.t) == len(ds.imu.t)
