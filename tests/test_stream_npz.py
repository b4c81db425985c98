"""``insnav run --out sol.npz`` block by block (insnav.filters.stream with
insnav._npz.NpzColumns): the streamed ``.npz`` holds the whole-file run's
members (names, order, dtypes, shapes) and values bit for bit, and its
sidecars (innovations, resolved configuration) and report are the whole-file
run's byte for byte, for KF-GINS files and the generic IMU CSV, with output
decimation and column selections; a bad line in a later block leaves neither
the ``.npz`` nor any temporary or scratch file."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

import insnav.filters.stream as stream

from test_stream import _run as _run_kfgins
from test_stream import streamed_and_whole
from test_stream import _with_line, kf_short  # noqa: F401 - the fixture
from test_stream_csv import BLOCK, car_files  # noqa: F401 - the fixture
from test_stream_csv import _run as _run_csv


def _same_npz(a, b):
    """Every member of ``a`` equals ``b``'s: names and order, dtype, shape, bytes; the zip stored, not deflated."""
    with zipfile.ZipFile(a) as za, zipfile.ZipFile(b) as zb:
        assert za.testzip() is None
        ia, ib = za.infolist(), zb.infolist()
        assert [i.filename for i in ia] == [i.filename for i in ib]
        assert [i.compress_type for i in ia] == [i.compress_type for i in ib] == [zipfile.ZIP_STORED] * len(ia)
        assert [i.CRC for i in ia] == [i.CRC for i in ib]
    with np.load(a, allow_pickle=False) as za, np.load(b, allow_pickle=False) as zb:
        assert za.files == zb.files
        for k in za.files:
            x, y = za[k], zb[k]
            assert (x.dtype, x.shape) == (y.dtype, y.shape), k
            assert x.tobytes() == y.tobytes(), k
        return {k: za[k] for k in za.files}


def _same_sidecars(a, b):
    for suffix in (".innovations.csv", ".config.toml"):
        pa, pb = a.parent / (a.name + suffix), b.parent / (b.name + suffix)
        assert pa.read_bytes() == pb.read_bytes(), suffix


@pytest.mark.parametrize("extra", [(), ("--output-rate", "10"), ("--columns", "nav,sigma", "--filter", "rbukf"),
                                   ("--columns", "bias", "--output-rate", "20")])
def test_streamed_npz_equals_the_whole_file_runs_npz(kf_short, tmp_path, monkeypatch, extra):  # noqa: F811
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)  # boundaries inside decimation windows and GNSS intervals
    a, b = tmp_path / "a" / "sol.npz", tmp_path / "b" / "sol.npz"
    streamed_and_whole(_run_kfgins, kf_short, a, b, *extra)
    cols = _same_npz(a, b)
    _same_sidecars(a, b)
    # the samples after t0 (10 Hz: every 20th of 200 Hz; 20 Hz: every 10th), the last row too
    dec = {"10": 20, "20": 10}[extra[extra.index("--output-rate") + 1]] if "--output-rate" in extra else 1
    assert len(cols["t_s"]) == -(-(30_000 - 1) // dec)
    assert {"t_s", "lat_deg"} <= set(cols) if "bias" not in extra else "lat_deg" not in cols
    assert sorted(p.name for p in a.parent.iterdir()) == ["sol.npz", "sol.npz.config.toml",
                                                            "sol.npz.innovations.csv"]  # nothing temporary left


@pytest.mark.parametrize("extra", [(), ("--output-rate", "10", "--columns", "nav,bias")])
def test_streamed_npz_of_the_generic_csv_equals_the_whole_file_runs(car_files, tmp_path, monkeypatch,  # noqa: F811
                                                                     extra):
    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    d = car_files[1]
    a, b = tmp_path / "a" / "sol.npz", tmp_path / "b" / "sol.npz"
    erra, errb = streamed_and_whole(_run_csv, d, a, b, *extra)
    assert erra == errb
    cols = _same_npz(a, b)
    _same_sidecars(a, b)
    assert len(cols["t_s"]) > 1000 if not extra else 100 < len(cols["t_s"]) < 1000
    assert sorted(p.name for p in a.parent.iterdir()) == ["sol.npz", "sol.npz.config.toml",
                                                          "sol.npz.innovations.csv"]


def test_a_bad_line_in_a_later_block_leaves_no_npz(kf_short, tmp_path, monkeypatch):  # noqa: F811
    # the line is in the 7th block of 4093: six blocks of columns are in the scratch files when it is read
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    d = tmp_path / "kf"
    d.mkdir()
    for name in ("kf.yaml", "gnss.txt"):
        (d / name).write_bytes((kf_short / name).read_bytes())
    _with_line(kf_short / "imu.txt", d / "imu.txt", 27_001, b"456375.000 1e-7 x 1e-7 1e-3 1e-3 -0.05\n")
    out = tmp_path / "run" / "sol.npz"
    out.parent.mkdir()
    rc, _, err = _run_kfgins(d, out, "--stream", "on")
    assert rc != 0 and "imu.txt:27001: not a number: 'x' in column 'dtheta_y'" in err
    assert list(out.parent.iterdir()) == []  # no npz, no temporary file, no scratch folder
    assert sorted(p.name for p in d.iterdir()) == ["gnss.txt", "imu.txt", "kf.yaml"]


def test_a_failed_write_leaves_no_npz_and_no_scratch(kf_short, tmp_path, monkeypatch):  # noqa: F811
    # the disk fills up while the fourth block is appended: the error is the run's, nothing stays behind
    from insnav import _npz

    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    real, calls = _npz.NpzColumns.append, []

    def append(self, columns):
        calls.append(1)
        if len(calls) == 4:
            raise OSError(28, "No space left on device")
        return real(self, columns)

    out = tmp_path / "run" / "sol.npz"
    out.parent.mkdir()
    assert _run_kfgins(kf_short, out, "--stream", "on", "--output-rate", "1")[0] == 0  # an earlier run's files
    before = {p.name: p.read_bytes() for p in out.parent.iterdir()}
    assert sorted(before) == ["sol.npz", "sol.npz.config.toml", "sol.npz.innovations.csv"]
    monkeypatch.setattr(_npz.NpzColumns, "append", append)
    rc, _, err = _run_kfgins(kf_short, out, "--stream", "on")
    assert rc != 0 and "No space left on device" in err
    assert {p.name: p.read_bytes() for p in out.parent.iterdir()} == before  # as they were, nothing added
    calls.clear()
    fresh = tmp_path / "fresh" / "sol.npz"
    rc, _, err = _run_kfgins(kf_short, fresh, "--stream", "on")
    assert rc != 0 and "No space left on device" in err and not fresh.parent.exists()  # not even the folder


def test_npz_columns_equal_write_npz_byte_for_byte(tmp_path, monkeypatch):
    # the members assembled from scratch files (checksums combined, not recomputed) against the whole-array writer
    from insnav import _npz

    rng = np.random.default_rng(7)
    x, y = rng.normal(size=(1001, 3)), rng.normal(size=1001)
    cols = [("t_s", y, 1.0), ("a", x[:, 0], 1.0), ("b_deg", x[:, 1], 57.29577951308232), ("c", x[:, 2], 1e6)]
    stamp = _npz._dos_time()
    monkeypatch.setattr(_npz, "_dos_time", lambda: stamp)  # the same time stamp in both files
    _npz.write_npz(tmp_path / "whole.npz", cols)
    (tmp_path / "s").mkdir()
    w = _npz.NpzColumns(tmp_path / "s", [nm for nm, _, _ in cols])
    cuts = [0, 0, 1, 334, 700, 1001, 1001]  # empty blocks, a one-row block, uneven blocks
    for a, b in zip(cuts[:-1], cuts[1:]):
        w.append([(v[a:b], f) for _, v, f in cols])
    w.finish(tmp_path / "streamed.npz")
    w.discard()
    assert not (tmp_path / "s").exists()
    assert (tmp_path / "streamed.npz").read_bytes() == (tmp_path / "whole.npz").read_bytes()
    with np.load(tmp_path / "streamed.npz") as z:
        assert z["b_deg"].tobytes() == (x[:, 1] * 57.29577951308232).tobytes()


@pytest.mark.parametrize("la, lb", [(0, 0), (128, 0), (0, 9), (128, 8 * 1001), (3, 65_537)])
def test_crc_combine_equals_the_checksum_of_the_concatenation(la, lb):
    import zlib

    from insnav._npz import _crc_shift, _gf2_times

    rng = np.random.default_rng(la + lb)
    a, b = rng.bytes(la), rng.bytes(lb)
    assert _gf2_times(_crc_shift(lb), zlib.crc32(a)) ^ zlib.crc32(b) == zlib.crc32(a + b)


def test_a_zip64_sized_npz_goes_through_zipfile_with_the_same_arrays(tmp_path, monkeypatch):
    # 4 GiB and more (a day at 200 Hz, all columns): write_npz and NpzColumns both take zipfile's ZIP64 path;
    # the limit lowered here so that a small file takes it
    from insnav import _npz

    monkeypatch.setattr(_npz, "_MAX_OFFSET", 1000)
    rng = np.random.default_rng(3)
    cols = [("t_s", rng.normal(size=500), 1.0), ("yaw_deg", rng.normal(size=500), 57.29577951308232)]
    _npz.write_npz(tmp_path / "whole.npz", cols)
    (tmp_path / "s").mkdir()
    w = _npz.NpzColumns(tmp_path / "s", ["t_s", "yaw_deg"])
    for a in range(0, 500, 123):
        w.append([(x[a:a + 123], f) for _, x, f in cols])
    w.finish(tmp_path / "streamed.npz")
    w.discard()
    assert not (tmp_path / "s").exists()
    with zipfile.ZipFile(tmp_path / "streamed.npz") as z:
        assert z.testzip() is None and [i.file_size for i in z.infolist()] == [128 + 8 * 500] * 2
    _same_npz(tmp_path / "streamed.npz", tmp_path / "whole.npz")


@pytest.mark.parametrize("errno_name", ["EXDEV", "ENOSYS"])
def test_without_copy_file_range_the_members_are_copied_by_reads(tmp_path, monkeypatch, errno_name):
    # another file system (EXDEV) or an old kernel (ENOSYS): the plain read / write copy gives the same file
    import errno
    import os

    from insnav import _npz

    def refuse(*a, **kw):
        raise OSError(getattr(errno, errno_name), "refused")

    rng = np.random.default_rng(5)
    cols = [("t_s", rng.normal(size=300), 1.0), ("h_m", rng.normal(size=300), 1.0)]
    stamp = _npz._dos_time()
    monkeypatch.setattr(_npz, "_dos_time", lambda: stamp)
    _npz.write_npz(tmp_path / "whole.npz", cols)
    monkeypatch.setattr(os, "copy_file_range", refuse)
    (tmp_path / "s").mkdir()
    w = _npz.NpzColumns(tmp_path / "s", ["t_s", "h_m"])
    w.append([(x[:100], f) for _, x, f in cols])
    w.append([(x[100:], f) for _, x, f in cols])
    w.finish(tmp_path / "streamed.npz")
    w.discard()
    assert (tmp_path / "streamed.npz").read_bytes() == (tmp_path / "whole.npz").read_bytes()
