"""The text solution writers' path around the page cache (O_DIRECT where the
file system allows it, cpp/include/insnav/io/direct_file.hpp):
the bytes on disk are those of the plain writes, whatever the block sizes,
the buffer boundaries and the unaligned tail, with O_DIRECT or without.

``_core.TextSink`` (one file written by several calls, as a solution is
written block by block) against ``_core.write_table`` of the whole columns
and against the stdio append path."""
from __future__ import annotations

import numpy as np
import pytest

from insnav import _core


def _columns(n: int, seed: int = 11):
    """Three columns with the formatter's edge cases: negatives, -0.0, NaN, decimal ties, huge values."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=n) * 10.0 ** rng.integers(-6, 9, n)
    b = (np.floor(rng.normal(size=n) * 1e4) + 0.5) / 1e4  # ties at the 4th decimal (written with 3)
    c = rng.normal(size=n)
    a[:6] = [-0.0, 0.0, np.nan, 1e300, -1e22, -5e-7]
    b[:3] = [-0.0, np.nan, 0.0005]
    return [a, b, c[::-1]]  # a negative stride too


@pytest.mark.parametrize("direct", [True, False])
def test_text_sink_in_blocks_equals_write_table_byte_for_byte(tmp_path, direct):
    n = 150_001  # about 6 MB of text: more than one 4 MiB buffer, an unaligned tail
    cols = _columns(n)
    scales, dec = [1.0, 57.29577951308232, 1e3], [9, 3, -1]
    whole = tmp_path / "whole.csv"
    nbytes = _core.write_table(str(whole), "a,b,c\n", cols, scales, dec)
    assert nbytes == whole.stat().st_size
    sink = _core.TextSink(str(tmp_path / "blocks.csv"), direct=direct)
    cuts = [0, 0, 1, 8193, 70_000, 70_001, n]  # an empty block, one row, uneven blocks
    total = 0
    for i, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        total += sink.write("a,b,c\n" if i == 0 else "", [x[a:b] for x in cols], scales, dec)
    assert sink.close() == total == nbytes
    assert (tmp_path / "blocks.csv").read_bytes() == whole.read_bytes()
    assert sink.close() == nbytes  # again: nothing more
    with pytest.raises(ValueError, match="after close"):
        sink.write("", cols, scales, dec)
    # the stdio append path (files appended by other writers) gives the same text
    app = tmp_path / "append.csv"
    _core.write_table(str(app), "a,b,c\n", [x[:1000] for x in cols], scales, dec)
    _core.write_table(str(app), "", [x[1000:] for x in cols], scales, dec, append=True)
    assert app.read_bytes() == whole.read_bytes()
    text = whole.read_text().splitlines()
    assert [ln.split(",")[:2] for ln in text[1:4]] == [["0", "0"], ["0", "nan"], ["nan", "0.029"]]  # -0.0: "0"
    assert text[4].split(",")[0] == "1e+300" and text[5].split(",")[0] == "-1e+22"  # shortest beyond 10^21


def test_text_sink_and_write_table_cut_a_longer_old_file(tmp_path):
    p = tmp_path / "old.csv"
    p.write_bytes(b"x" * 3_000_000)
    cols = [np.arange(1000.0)]
    sink = _core.TextSink(str(p))
    sink.write("t\n", cols, [1.0], [0])
    n = sink.close()
    assert p.read_bytes() == b"t\n" + "".join(f"{i}\n" for i in range(1000)).encode() and p.stat().st_size == n
    p.write_bytes(b"y" * 5_000_001)
    assert _core.write_table(str(p), "t\n", cols, [1.0], [0]) == n == p.stat().st_size


def test_text_sink_names_the_file_it_cannot_open(tmp_path):
    with pytest.raises(OSError, match="missing"):
        _core.TextSink(str(tmp_path / "missing" / "x.csv"))
