"""insnav._threads.Job: a writer thread that a Ctrl-C on the main thread cannot outlive the clean-up of."""
from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from insnav._threads import Job


def _sigint_after(seconds: float) -> threading.Timer:
    """SIGINT to this process after ``seconds`` (handled on the main thread as KeyboardInterrupt)."""
    t = threading.Timer(seconds, os.kill, (os.getpid(), signal.SIGINT))
    t.start()
    return t


@pytest.fixture
def default_sigint():
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_join_waits_for_the_call_through_a_ctrl_c_then_raises_it(default_sigint):
    ended, asked = threading.Event(), []
    job = Job(lambda: (time.sleep(1.5), ended.set()), name="test-writer").start()
    _sigint_after(0.1)
    with pytest.raises(KeyboardInterrupt):
        job.join(on_interrupt=lambda: asked.append(ended.is_set()))
    assert ended.is_set()  # the call had ended when the interrupt was raised
    assert asked == [False]  # asked to stop once, when the interrupt came (the call still running)


def test_result_is_interruptible_and_leaves_the_job_to_join(default_sigint):
    ended = threading.Event()
    job = Job(lambda: (time.sleep(1.5), ended.set())).start()
    _sigint_after(0.1)
    with pytest.raises(KeyboardInterrupt):
        job.result()
    assert not ended.is_set()  # raised at once, the call still running
    job.join()
    assert ended.is_set()


def test_result_raises_the_calls_exception_once():
    def fail():
        raise OSError(28, "No space left on device")

    job = Job(fail).start()
    with pytest.raises(OSError, match="No space"):
        job.result()
    job.result()  # already raised: the clean-up's later wait is silent
    job.join()


def test_a_job_never_started_is_joined_at_once():
    job = Job(time.sleep, 5)
    t0 = time.perf_counter()
    job.join()
    assert time.perf_counter() - t0 < 0.5
