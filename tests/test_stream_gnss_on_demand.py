"""The GNSS fixes of a block-by-block run read back from their file on demand
(insnav.io.text_blocks.read_gnss_text_blocks with ``on_demand``): the first
pass keeps the times and where each block of lines lies, the other columns
are read again per block of rows as the engine, the sanitizer and the input
checks index them.  The run's files and report are the whole-file run's
(several GNSS block sizes, the first fix of the run on a block's first line,
10 Hz fixes), a bad line on a block boundary gives the whole run's one-line
error, what is held besides the times does not grow with the fixes, and a
GNSS file changed between the passes stops the run with a one-line error
naming it, leaving an earlier output as it was."""
from __future__ import annotations

import numpy as np
import pytest

import insnav.filters.stream as stream
import insnav.io.text_blocks as tb

from test_stream import kf_short  # noqa: F401 - the fixture
from test_stream import _run, streamed_and_whole
from test_stream_gnss_push import _kf_copy


def _same_files(a, b):
    for suffix in ("", ".innovations.csv", ".config.toml"):
        assert (a.parent / (a.name + suffix)).read_bytes() == (b.parent / (b.name + suffix)).read_bytes(), suffix
    assert not [p for p in a.parent.iterdir() if ".part" in p.name]


def _spy_reads(monkeypatch):
    """The on-demand indexes the runs make (their ``reads``: blocks parsed again)."""
    made = []
    real = tb._GnssTextIndex

    def spy(*args):
        idx = real(*args)
        made.append(idx)
        return idx

    monkeypatch.setattr(tb, "_GnssTextIndex", spy)
    return made


@pytest.mark.parametrize("gnss_lines", [1, 40, 4096])
def test_fixes_read_on_demand_give_the_whole_runs_files(kf_short, tmp_path, monkeypatch, gnss_lines):  # noqa: F811
    # GNSS blocks of 1 line (a read of 112 bytes: every fix on a block edge), about 70 and every line (4096);
    # IMU blocks of 4093 lines (cut inside GNSS intervals); the fixes after the IMU's end are in the file
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    monkeypatch.setattr(tb, "GNSS_BLOCK_LINES", gnss_lines)
    made = _spy_reads(monkeypatch)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    erra, errb = streamed_and_whole(_run, kf_short, a, b, "--output-rate", "10")
    _same_files(a, b)
    assert erra == errb
    assert len(made) == 1 and made[0].reads > 0  # the stream's fixes were read back from the file
    idx, n = made[0], (kf_short / "gnss.txt").read_text().count("\n")
    assert idx.row0[0] == 0 and np.array_equal(idx.row0[1:], np.cumsum(idx.rows_of)[:-1]) and idx.rows_of.sum() == n
    assert np.array_equal(idx.line, idx.row0 + 1)  # no blank line: row r on line r + 1
    if gnss_lines == 1:
        assert len(idx.row0) == n  # a block per fix


@pytest.mark.parametrize("line", [51, 52])
def test_a_bad_line_on_a_gnss_block_boundary_gives_the_whole_runs_error(kf_short, tmp_path, monkeypatch, line):  # noqa: F811
    # blocks of one line (reads of 112 bytes): line 51 ends a block, line 52 (the first fix after starttime)
    # opens the next
    def edit(lines):
        lines = list(lines)
        f = lines[line - 1].split(" ")
        lines[line - 1] = " ".join(f[:2] + ["114.47x"] + f[3:])
        return lines

    d = _kf_copy(kf_short, tmp_path / "kf", edit)
    monkeypatch.setattr(tb, "GNSS_BLOCK_LINES", 1)
    rca, _, erra = _run(d, tmp_path / "a" / "sol.csv", "--stream", "on")
    rcb, _, errb = _run(d, tmp_path / "b" / "sol.csv", "--stream", "off")
    assert rca == rcb != 0
    assert erra == errb and len(erra.strip().splitlines()) == 1
    assert f"gnss.txt:{line}" in erra
    assert not (tmp_path / "a" / "sol.csv").exists()


def test_10hz_fixes_read_on_demand_give_the_whole_runs_files(kf_short, tmp_path, monkeypatch):  # noqa: F811
    # 10 Hz fixes: each 1 Hz fix followed by 9 interpolated between it and the next (positions and sigmas
    # linear in time), GNSS blocks of 37 lines (boundaries inside the IMU blocks' fix windows)
    def edit(lines):
        rows = np.array([[float(x) for x in ln.split()] for ln in lines])
        out = []
        for r0, r1 in zip(rows[:-1], rows[1:]):
            for k in range(10):
                r = r0 + (r1 - r0) * (k / 10.0)
                out.append(f"{r[0]:.3f} {r[1]:.11f} {r[2]:.11f} " + " ".join(f"{x:.4f}" for x in r[3:]) + "\n")
        return out

    d = _kf_copy(kf_short, tmp_path / "kf", edit)
    monkeypatch.setattr(stream, "BLOCK_LINES", 997)
    monkeypatch.setattr(tb, "GNSS_BLOCK_LINES", 37)
    made = _spy_reads(monkeypatch)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    erra, errb = streamed_and_whole(_run, d, a, b)
    _same_files(a, b)
    assert erra == errb
    fixes = (a.parent / (a.name + ".innovations.csv")).read_text().count("\n") - 1
    assert fixes > 1000 and made[0].reads > 0


def _gnss_file(path, n):
    """``n`` 1 Hz fixes near (30.5 deg, 114.3 deg), 7 columns."""
    rng = np.random.default_rng(7)
    d = rng.standard_normal((n, 2)) * 1e-7
    path.write_text("".join(f"{100000.0 + i:.3f} {30.5 + d[i, 0]:.11f} {114.3 + d[i, 1]:.11f} 20.0 0.01 0.01 0.02\n"
                            for i in range(n)))
    return path


def test_what_is_held_of_the_fixes_besides_their_times_does_not_grow_with_them(tmp_path):
    """The fixes of 6 and of 40 times GNSS_BLOCK_LINES lines read on demand, then taken whole by the sanitizer, the
    engine's rows and the input checks a block at a time: the index holds 40 bytes per block of
    GNSS_BLOCK_LINES lines and at most CACHED parsed blocks, the same bytes for both lengths but for the 40
    per block; the times are the only column held (8 bytes per fix; read whole: 56)."""
    from insnav.data.checks import check_gnss, check_gnss_velocity
    from insnav.filters.sanitize import sanitize_gnss_blocks

    held = {}
    for n in (6 * tb.GNSS_BLOCK_LINES, 40 * tb.GNSS_BLOCK_LINES):
        f = _gnss_file(tmp_path / f"g{n}.txt", n)
        g = tb.read_gnss_text_blocks(f, on_demand=True)
        idx = g.lat_deg.index
        assert all(isinstance(getattr(g, c), tb.FileColumn) for c in ("lat_deg", "lon_deg", "h_m", "sigma_pos_n"))
        g2, rep = sanitize_gnss_blocks(g)
        assert g2 is g and rep["gnss_records_out"] == n
        check_gnss(g, source="g")
        check_gnss_velocity(g, source="g")
        for a in range(0, n, stream.GNSS_PUSH_MAX):
            stream._FixSlice(g, slice(a, min(n, a + stream.GNSS_PUSH_MAX)))
        whole = tb.read_gnss_text_blocks(f)
        assert np.array_equal(np.asarray(g.lat_deg), whole.lat_deg) and np.array_equal(g.sigma_pos_n[:], whole.sigma_pos_n)
        blocks = len(idx.row0)  # blocks of about GNSS_BLOCK_LINES * LINE_BYTES_GUESS bytes
        assert len(idx.cache) <= tb._GnssTextIndex.CACHED and blocks >= 3
        assert idx.held_bytes() - 40 * blocks == sum(a.nbytes for a in idx.cache.values())
        held[n] = (idx.held_bytes() - 40 * blocks, int(idx.rows_of.max()), g.t_valid.nbytes)
    short, long = held[6 * tb.GNSS_BLOCK_LINES], held[40 * tb.GNSS_BLOCK_LINES]
    assert short[1] == long[1]  # the same lines per block (lines of one width)
    cached = tb._GnssTextIndex.CACHED
    assert short[0] <= cached * short[1] * 7 * 8 and long[0] <= cached * long[1] * 7 * 8  # at most CACHED blocks
    assert long[0] < 0.2 * 48 * 40 * tb.GNSS_BLOCK_LINES  # not the 48 bytes per fix of the columns read whole
    assert long[2] == 8 * 40 * tb.GNSS_BLOCK_LINES  # the times: 8 bytes per fix


def test_compressed_gnss_file_is_held_whole(kf_short, tmp_path):  # noqa: F811
    import gzip

    f = tmp_path / "gnss.txt.gz"
    f.write_bytes(gzip.compress((kf_short / "gnss.txt").read_bytes()))
    g = tb.read_gnss_text_blocks(f, on_demand=True)
    assert isinstance(g.lat_deg, np.ndarray)
    assert np.array_equal(g.lat_deg, tb.read_gnss_text_blocks(kf_short / "gnss.txt").lat_deg)


@pytest.mark.parametrize("when", ["start", "loop", "end"])
def test_a_gnss_file_changed_between_the_passes_stops_the_run(kf_short, tmp_path, monkeypatch, when):  # noqa: F811
    # the file rewritten with the same size (a digit changed: only its modification time tells) before the
    # engine's set-up, during the block loop or before the end's input checks: a one-line error naming it;
    # the earlier solution file as it was, no temporary file left, the inputs untouched
    import os

    d = _kf_copy(kf_short, tmp_path / "kf", lambda lines: lines)
    gnss = d / "gnss.txt"
    inputs = {p.name: p.read_bytes() for p in d.iterdir()}

    def change():
        if gnss.read_bytes() != inputs["gnss.txt"]:
            return
        text = bytearray(inputs["gnss.txt"])
        i = text.index(b"\n", 3000) - 1
        text[i:i + 1] = b"7" if text[i:i + 1] != b"7" else b"3"
        st = os.stat(gnss)
        gnss.write_bytes(bytes(text))
        os.utime(gnss, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
        changed.append(True)

    changed: list[bool] = []
    monkeypatch.setattr(stream, "BLOCK_LINES", 997)
    monkeypatch.setattr(tb, "GNSS_BLOCK_LINES", 11)
    name = {"start": "_start", "loop": "_push_gnss", "end": "_result"}[when]
    real = getattr(stream._BlockRun, name)
    calls = []

    def wrapped(self, *a, **k):
        calls.append(1)
        if when != "loop" or len(calls) == 3:
            change()
        return real(self, *a, **k)

    monkeypatch.setattr(stream._BlockRun, name, wrapped)
    out = tmp_path / "o" / "sol.csv"
    out.parent.mkdir()
    out.write_bytes(b"an earlier solution\n")
    rc, so, se = _run(d, out, "--stream", "on", "--overwrite")
    assert changed and rc != 0, (rc, se, calls)
    assert len(se.strip().splitlines()) == 1, se
    assert "gnss.txt" in se and "changed since it was first read" in se
    assert out.read_bytes() == b"an earlier solution\n"
    assert sorted(p.name for p in out.parent.iterdir()) == ["sol.csv"]
    after = {p.name: p.read_bytes() for p in d.iterdir()}
    assert {k: v for k, v in after.items() if k != "gnss.txt"} == {k: v for k, v in inputs.items() if k != "gnss.txt"}


@pytest.mark.parametrize("block_lines", [3, 7, 4096])
def test_fixes_read_on_demand_equal_the_whole_file_readers(kf_short, tmp_path, block_lines):  # noqa: F811
    """Blank lines inside and at the end, no final line end, 13 columns: every column read on demand (whole,
    by slices across blocks, by index arrays, a row with a column key) and every row's file line equal the
    whole-file reader's."""
    from insnav.io.kfgins import read_kfgins_gnss

    src = (kf_short / "gnss.txt").read_text().splitlines(keepends=True)
    cases = {"blank": src[:50] + ["\n", "   \n"] + src[50:] + ["\n"], "no_end": src[:-1] + [src[-1].rstrip("\n")],
             "v13": [ln.rstrip("\n") + " 0.1 0.2 0.3 0.01 0.01 0.02\n" for ln in src[:300]]}
    for name, lines in cases.items():
        f = tmp_path / f"{name}.txt"
        f.write_text("".join(lines))
        whole = read_kfgins_gnss(f, compact=True)
        got = tb.read_gnss_text_blocks(f, block_lines=block_lines, on_demand=True)
        assert isinstance(got.lat_deg, tb.FileColumn) and (name != "v13") == isinstance(got.v_n, np.ndarray)
        idx = np.array([0, 3, 49, 50, 51, 52, 120, len(whole) - 1])
        for fld in stream._GNSS_FIELDS:
            w, g = np.asarray(getattr(whole, fld)), getattr(got, fld)
            assert np.array_equal(np.asarray(g), w, equal_nan=True), (name, fld)
            assert np.array_equal(g[45:130], w[45:130], equal_nan=True) and np.array_equal(g[idx], w[idx], equal_nan=True)
            assert np.array_equal(g[-1], w[-1], equal_nan=True)
        assert np.array_equal(got.v_n[idx, :2], np.asarray(whole.v_n)[idx, :2], equal_nan=True)
        cut = stream._gnss_take(got, (got.t_valid > 456300.0) & (got.t_valid <= 456400.0))
        assert isinstance(cut.lat_deg, tb.FileColumn) and np.array_equal(cut.lat_deg[:], whole.lat_deg[51:151]) \
            or name == "v13"
        assert [got.origin.line(i) for i in range(len(whole))] == [whole.origin.line(i) for i in range(len(whole))]
