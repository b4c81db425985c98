"""Input files that change while they are read: never a signal, never a
silently short read.

The readers read a file once (no memory map: a map of a file truncated
meanwhile faults with SIGBUS) and compare its size and modification time
before and after; a file that changed is a one-line error naming it."""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
import time

import numpy as np
import pytest

from insnav.data import textio
from insnav.data.textio import FileChangedError

ROWS = 9_000  # ~1.3 MB: above textio.MAP_MIN_BYTES (the size from which the old reader mapped the file)


def _imu_file(path, rows=ROWS):
    from insnav.data.dataset import ImuData
    from insnav.io.kfgins import write_kfgins_imu

    t = 100.0 + 0.005 * np.arange(rows)
    rng = np.random.default_rng(3)
    write_kfgins_imu(path, ImuData(t, rng.normal(0, 1e-4, (rows, 3)), rng.normal(0, 1e-3, (rows, 3))))
    return path


class _ChangingOpen:
    """``open`` whose file ``target`` is changed on disk by ``change(path)``
    after its first read (another program writing the file while insnav reads it)."""

    def __init__(self, target, change):
        self.target, self.change = str(target), change

    def __call__(self, path, *a, **kw):
        f = open(path, *a, **kw)
        if str(path) != self.target:
            return f
        change, cut = self.change, [False]

        class F:
            def __getattr__(self, k):
                return getattr(f, k)

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                f.close()

            def _after(self):
                if not cut[0]:
                    cut[0] = True
                    change(path)

            def read(self, *a):
                out = f.read(*a)
                self._after()
                return out

            def readinto(self, b):
                n = f.readinto(b)
                self._after()
                return n

        return F()


@pytest.mark.parametrize("rows", [200, ROWS])  # a small file (read at once) and a large one (read in parts)
def test_a_file_cut_during_the_read_is_refused_naming_it(tmp_path, monkeypatch, rows):
    from insnav.io.kfgins import read_kfgins_imu

    p = _imu_file(tmp_path / "imu.txt", rows)
    full = len(read_kfgins_imu(p).t)
    assert full == rows
    size = p.stat().st_size
    keep = size // 2 - (size // 2) % 100  # anywhere; the reader must not care whether at a line boundary
    monkeypatch.setattr(textio, "open", _ChangingOpen(p, lambda q: os.truncate(q, keep)), raising=False)
    with pytest.raises(FileChangedError, match=rf"{p}: the file changed while it was read \(size {size} -> {keep}"):
        read_kfgins_imu(p)


def test_the_dataset_reader_refuses_a_file_cut_at_a_line_boundary(tmp_path, monkeypatch):
    """An insnav dataset's imu.csv cut at a line boundary during the read
    parses as a shorter, valid file: only the size check can tell."""
    import insnav
    from insnav.data.dataset import load_dataset

    ds = insnav.simulate("seed000-sim", seed=1, with_truth=False)
    d = ds.save(tmp_path / "ds")
    imu = d / "imu.csv"
    data = imu.read_bytes()
    keep = data.index(b"\n", len(data) // 2) + 1
    n_full = len(load_dataset(d).imu.t)
    monkeypatch.setattr(textio, "open", _ChangingOpen(imu, lambda q: os.truncate(q, keep)), raising=False)
    with pytest.raises(FileChangedError, match=rf"{imu}: the file changed while it was read"):
        load_dataset(d)
    monkeypatch.undo()
    assert 0 < len(load_dataset(d).imu.t) < n_full  # the cut file itself, read when it no longer changes, is valid


def test_a_file_that_grows_or_is_rewritten_during_the_read_is_refused(tmp_path, monkeypatch):
    from insnav.io.kfgins import read_kfgins_gnss

    p = tmp_path / "gnss.txt"
    p.write_text("".join(f"{100 + k:.3f} 30.5 114.3 20.0 0.01 0.01 0.02\n" for k in range(50)))

    def append(q):  # a logger appending a record as we read
        with open(q, "a") as g:
            g.write("150.000 30.5 114.3 20.0 0.01 0.01 0.02\n")

    monkeypatch.setattr(textio, "open", _ChangingOpen(p, append), raising=False)
    with pytest.raises(FileChangedError, match=f"{p}: the file changed while it was read"):
        read_kfgins_gnss(p)

    def rewrite(q):  # the same size, other bytes, a later modification time
        b = bytearray(Path(q).read_bytes())
        b[:3] = b"101"
        time.sleep(0.01)
        with open(q, "r+b") as g:
            g.write(b)

    monkeypatch.setattr(textio, "open", _ChangingOpen(p, rewrite), raising=False)
    with pytest.raises(FileChangedError, match=f"{p}: the file changed while it was read \\(modified\\)"):
        read_kfgins_gnss(p)


_RACE = textwrap.dedent("""
    import json, os, random, sys, threading, time
    from insnav.io.kfgins import read_kfgins_imu

    src, work = sys.argv[1], sys.argv[2]
    pristine = open(src, "rb").read()
    t0 = time.perf_counter()
    full = len(read_kfgins_imu(src).t)
    span = time.perf_counter() - t0  # one read: the truncation lands anywhere in it
    rng = random.Random(11)
    out = []
    for i in range(100):
        with open(work, "wb") as f:
            f.write(pristine)
        keep = rng.randrange(len(pristine))
        delay = max(0.0, rng.uniform(-0.5, 1.0) * span)  # a third at once: the cut comes first, however busy
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child reads while a thread cuts the file
            os.close(r)
            th = threading.Thread(target=lambda: (time.sleep(delay), os.truncate(work, keep)))
            th.start()
            try:
                res = {"rows": len(read_kfgins_imu(work).t)}
            except Exception as exc:
                res = {"error": f"{type(exc).__name__}: {exc}"}
            th.join()
            os.write(w, json.dumps(res).encode())
            os._exit(0)
        os.close(w)
        msg = b""
        while True:
            b = os.read(r, 65536)
            if not b:
                break
            msg += b
        os.close(r)
        _, status = os.waitpid(pid, 0)
        res = json.loads(msg) if msg else {}
        res.update(keep=keep, signal=os.WTERMSIG(status) if os.WIFSIGNALED(status) else 0)
        out.append(res)
    print(json.dumps({"full": full, "tries": out}))
""")


def test_truncation_race_never_kills_the_reader_nor_passes_a_short_read(tmp_path):
    """100 tries: a thread truncates the KF-GINS IMU file at a random offset
    at a random time during the read, in a forked child each (a signal shows
    as the child's death).  Every try ends in the full file, an error naming
    the file, or -- when the cut came before the read -- exactly what a read
    of the cut file gives."""
    from insnav.io.kfgins import read_kfgins_imu

    src = _imu_file(tmp_path / "src.txt")
    work = tmp_path / "work.txt"
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join(sys.path))
    r = subprocess.run([sys.executable, "-c", _RACE, str(src), str(work)], capture_output=True, text=True,
                       timeout=120, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout)
    full, tries = res["full"], res["tries"]
    assert len(tries) == 100
    died = [t for t in tries if t["signal"]]
    assert not died, f"{len(died)} of 100 reads died with a signal ({died[0]})"
    pristine = src.read_bytes()
    check = tmp_path / "cut.txt"
    kinds = {"full": 0, "cut file": 0, "error": 0}
    for t in tries:
        if "error" in t:
            assert str(work) in t["error"] and "\n" not in t["error"], t["error"]
            kinds["error"] += 1
        elif t["rows"] == full:
            kinds["full"] += 1
        else:  # the cut came first: the rows must be what the cut file holds
            check.write_bytes(pristine[:t["keep"]])
            assert t["rows"] == len(read_kfgins_imu(check).t), t
            kinds["cut file"] += 1
    assert kinds["error"] + kinds["cut file"] > 0, kinds  # the cuts did land before the reads ended
