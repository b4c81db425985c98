"""``insnav run`` block by block into Parquet and the KF-GINS layout
(insnav.filters.stream ``_ParquetWriter`` and ``_KfginsWriter``): the streamed
``.parquet`` is the whole-file run's byte for byte (same schema, same row
groups, the same float64 values bit for bit) and the streamed
``KF_GINS_Navresult.nav`` / ``KF_GINS_IMU_ERR.txt`` / ``KF_GINS_STD.txt`` are
the whole-file writer's byte for byte, for KF-GINS files (21 states) and the
generic IMU CSV (15 states: zero scale-factor sigmas), with block boundaries
inside row groups, decimation windows and GNSS intervals; a write that fails
or a Ctrl-C (SIGINT) in the middle of the run leaves the earlier run's files
exactly as they were and no temporary file."""
from __future__ import annotations

import errno
import os
import signal
import time

import numpy as np
import pytest

import insnav.filters.solution as solution
import insnav.filters.stream as stream
from insnav.io.kfgins import KFGINS_IMU_ERR_FILE, KFGINS_NAV_FILE, KFGINS_STD_FILE

from conftest import require_module
from test_stream import LINES, kf_short  # noqa: F401 - the fixture
from test_stream import _run as _run_kfgins
from test_stream import streamed_and_whole
from test_stream_csv import BLOCK, car_files  # noqa: F401 - the fixture
from test_stream_csv import _run as _run_csv

KFGINS_FILES = (KFGINS_NAV_FILE, KFGINS_IMU_ERR_FILE, KFGINS_STD_FILE)
SIDECARS = (".innovations.csv", ".config.toml")


@pytest.fixture
def pq():
    return require_module("pyarrow.parquet", "parquet")


def _same_parquet(pq, a, b):
    """a and b: the same bytes, schema (names, float64, metadata) and values bit for bit; the columns of a."""
    assert a.read_bytes() == b.read_bytes()
    ta, tb = pq.read_table(a), pq.read_table(b)
    assert ta.schema.equals(tb.schema, check_metadata=True)
    assert {str(f.type) for f in ta.schema} == {"double"}
    cols = {}
    for name in ta.column_names:
        x, y = ta.column(name).to_numpy(), tb.column(name).to_numpy()
        assert x.tobytes() == y.tobytes(), name
        cols[name] = x
    return cols


@pytest.mark.parametrize("extra, group", [((), 5000), (("--output-rate", "10"), 300),
                                          (("--columns", "nav,sigma", "--filter", "rbukf"), 8192)])
def test_streamed_parquet_is_the_whole_file_runs_parquet(pq, kf_short, tmp_path, monkeypatch, extra,  # noqa: F811
                                                         group):
    # blocks of 4093 lines and row groups of `group` rows: group boundaries inside blocks and the reverse
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    monkeypatch.setattr(solution, "PARQUET_ROW_GROUP_ROWS", group)
    a, b = tmp_path / "a" / "sol.parquet", tmp_path / "b" / "sol.parquet"
    streamed_and_whole(_run_kfgins, kf_short, a, b, *extra)
    cols = _same_parquet(pq, a, b)
    for suffix in SIDECARS:
        assert (a.parent / (a.name + suffix)).read_bytes() == (b.parent / (b.name + suffix)).read_bytes(), suffix
    dec = 20 if "--output-rate" in extra else 1
    rows = -(-(LINES - 10_001) // dec)  # the samples after t0 (the first at starttime), the last row too
    assert len(cols["t_s"]) == rows
    assert pq.ParquetFile(a).metadata.num_row_groups == -(-rows // group) >= 3
    assert ("acc_bias_x_mps2" in cols) == ("--columns" not in extra) and "sigma_yaw_deg" in cols
    assert np.all(np.diff(cols["t_s"]) > 0)
    assert sorted(p.name for p in a.parent.iterdir()) == ["sol.parquet"] + [f"sol.parquet{s}" for s in
                                                                            sorted(SIDECARS)]


def test_streamed_parquet_of_the_generic_csv_is_the_whole_file_runs(pq, car_files, tmp_path,  # noqa: F811
                                                                     monkeypatch):
    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    monkeypatch.setattr(solution, "PARQUET_ROW_GROUP_ROWS", 3000)
    d = car_files[1]
    a, b = tmp_path / "a" / "sol.parquet", tmp_path / "b" / "sol.parquet"
    erra, errb = streamed_and_whole(_run_csv, d, a, b)
    assert erra == errb
    cols = _same_parquet(pq, a, b)
    assert len(cols["t_s"]) > 10_000 and pq.ParquetFile(a).metadata.num_row_groups >= 4


def _same_kfgins(a, b, std=True):
    names = list(KFGINS_FILES if std else KFGINS_FILES[:2]) + [KFGINS_NAV_FILE + s for s in SIDECARS]
    assert sorted(p.name for p in a.iterdir()) == sorted(names)  # nothing temporary left
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    return {name: np.loadtxt(a / name, ndmin=2) for name in KFGINS_FILES[:3 if std else 2]}


@pytest.mark.parametrize("extra", [(), ("--output-rate", "10"), ("--filter", "rbukf", "--output-rate", "20")])
def test_streamed_kfgins_layout_is_the_whole_file_writers(kf_short, tmp_path, monkeypatch, extra):  # noqa: F811
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    a, b = tmp_path / "a" / "kf", tmp_path / "b" / "kf"
    streamed_and_whole(_run_kfgins, kf_short, a, b, "--out-format", "kfgins", *extra)
    tables = _same_kfgins(a, b)
    dec = {"10": 20, "20": 10}[extra[extra.index("--output-rate") + 1]] if "--output-rate" in extra else 1
    nav, err, std = (tables[n] for n in KFGINS_FILES)
    assert nav.shape == (-(-(LINES - 10_001) // dec), 11) and err.shape[1] == 13 and std.shape[1] == 22
    assert np.array_equal(nav[:, 1], err[:, 0]) and np.array_equal(nav[:, 1], std[:, 0])
    assert np.all(nav[:, 0] == 0)  # the week, as KF-GINS writes it
    assert np.all(std[:, 10:] > 0)  # 21 states: every IMU-error sigma, the scale factors' too


def test_streamed_kfgins_layout_of_a_15_state_csv_run(car_files, tmp_path, monkeypatch):  # noqa: F811
    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    d = car_files[1]
    a, b = tmp_path / "a" / "kf", tmp_path / "b" / "kf"
    erra, errb = streamed_and_whole(_run_csv, d, a, b, "--out-format", "kfgins", "--output-rate", "20")
    assert erra == errb
    std = _same_kfgins(a, b)[KFGINS_STD_FILE]
    assert len(std) > 500
    assert np.all(std[:, 10:16] > 0) and np.all(std[:, 16:] == 0)  # 15 states: no scale-factor states


def _interrupt(kind: str):
    """What happens in the writer thread's fourth write: the disk fills up, or Ctrl-C arrives."""
    if kind == "full disk":
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    # the main thread has filtered the next block by now and waits for this write: the Ctrl-C interrupts
    # that wait, and this write goes on after it (the run's clean-up must wait for it, not close its file)
    time.sleep(0.3)
    os.kill(os.getpid(), signal.SIGINT)  # handled on the main thread, in the middle of the run
    time.sleep(0.3)


@pytest.mark.parametrize("kind", ["full disk", "SIGINT"])
@pytest.mark.parametrize("fmt", ["parquet", "kfgins"])
def test_a_failed_or_interrupted_streamed_write_leaves_the_earlier_files(kf_short, tmp_path, monkeypatch,  # noqa: F811
                                                                         fmt, kind):
    if fmt == "parquet":
        require_module("pyarrow.parquet", "parquet")
        out, args, name = tmp_path / "run" / "sol.parquet", (), "_append"
        monkeypatch.setattr(solution, "PARQUET_ROW_GROUP_ROWS", 3000)  # row groups written before the failure
    else:
        out, args, name = tmp_path / "run" / "kf", ("--out-format", "kfgins"), "_write"
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    monkeypatch.setattr(signal, "getsignal", lambda s: signal.default_int_handler)  # the CLI's own SIGINT handler
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert _run_kfgins(kf_short, out, "--output-rate", "1", *args)[0] == 0  # an earlier run's files
        folder = out if fmt == "kfgins" else out.parent
        before = {p.name: p.read_bytes() for p in folder.iterdir()}
        assert len(before) == (5 if fmt == "kfgins" else 3)
        cls = stream._KfginsWriter if fmt == "kfgins" else stream._ParquetWriter
        real, calls, files_open = getattr(cls, name), [], []

        def failing(self, *a):
            calls.append(1)
            if len(calls) == 4:  # three blocks are in the temporary files
                _interrupt(kind)
            if len(calls) >= 4:  # the write after the interrupt: its files still open (not closed by the clean-up)
                files_open.append(self.pq.is_open if fmt == "parquet" else bool(self._sinks))
            return real(self, *a)

        monkeypatch.setattr(cls, name, failing)
        rc, _, err = _run_kfgins(kf_short, out, "--stream", "on", *args)
        assert len(calls) >= 4
        # the write interrupted by Ctrl-C ended, its files open, before the run returned: the clean-up waited
        assert files_open == ([True] if kind == "SIGINT" else [])
        if kind == "SIGINT":
            assert rc == 130 and err.strip().splitlines()[-1] == "insnav run: interrupted"
        else:
            assert rc == 2 and "No space left on device" in err and len(err.strip().splitlines()) == 1
        assert {p.name: p.read_bytes() for p in folder.iterdir()} == before  # as they were, nothing added
        assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    finally:
        signal.signal(signal.SIGINT, previous)
