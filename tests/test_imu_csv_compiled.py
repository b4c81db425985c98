"""The generic IMU CSV's compiled reader (``_core.parse_csv``, text_table.hpp
``parse_csv_fields``) against the Python reader it stands in for
(``CsvLineParser(compiled=False)``): the same float64 values bit for bit
(``std::from_chars`` and ``float()`` both round correctly), the same sample
times (``_time_after``'s exact integer arithmetic), the same rows and lines,
fed whole or block by block, and the same one-line error naming the file and
the line for every kind of bad line."""
from __future__ import annotations

import random

import numpy as np
import pytest

from insnav import _core
from insnav.io import imu_csv
from insnav.io.imu_csv import (CsvLineParser, ImuCsvFormat, ImuFileError, SampleConverter, TimeFields,
                               _time_after, read_imu_csv)

PATH = "imu.csv"


def _number(rng: random.Random) -> str:
    """A random decimal as a logger may write it: exponents, signs, many digits, padding."""
    x = rng.choice([rng.uniform(-1, 1), rng.gauss(0, 10), rng.uniform(-1e-6, 1e-6), rng.uniform(-1e5, 1e5)])
    kind = rng.randrange(9)
    if kind == 0:
        s = repr(x)
    elif kind == 1:
        s = f"{x:.17e}"
    elif kind == 2:
        s = f"{x:.{rng.randrange(0, 12)}f}"
    elif kind == 3:
        s = f"{x:.{rng.randrange(1, 10)}E}"
    elif kind == 4:  # more digits than a double holds (the correctly rounded value matters)
        s = ("-" if x < 0 else "") + f"{abs(x):.0f}." + "".join(rng.choice("0123456789") for _ in range(30))
    elif kind == 5:
        s = f"{x:+.9g}"
    elif kind == 6:  # ties and near-ties in the 17th digit
        s = f"{rng.randrange(10 ** 16, 10 ** 17)}5e-{rng.randrange(1, 30)}"
    elif kind == 7:
        s = f"{x:.6f}".replace("0.", ".", 1) if abs(x) < 1 else f"{x:.3f}"
    else:
        s = f"{int(x * 1000)}"
    return " " * rng.randrange(2) + s + " " * rng.randrange(2)


def _time(rng: random.Random, k: int, style: int) -> str:
    if style == 0:  # GPS seconds since 1980 with many decimals
        return f"{1_400_000_000 + k // 200}.{rng.randrange(10 ** 9):09d}{rng.randrange(10 ** 6)}"
    if style == 1:  # integer nanoseconds (19 digits)
        return f"{1_700_000_000_000_000_000 + k * 5_000_000 + rng.randrange(1000)}"
    if style == 2:  # an exponent, a sign: float() and then the reference subtracted
        return f"{1.4e5 + k * 0.005:.12e}" if k % 2 else f"+{1.4e5 + k * 0.005:.6f}"
    return f"{-50 + k * 0.005:.3f}"  # negative relative times


def _text(rng: random.Random, delim: str, n: int, style: int, crlf: bool, trailing: bool) -> bytes:
    cols = ["time", "junk", "ax", "ay", "az", "gx", "gy", "gz"]
    out = ["# logger v1, comment line", delim.join(cols) + (delim if trailing else "")]
    for k in range(n):
        f = [_time(rng, k, style), rng.choice(["a", "x y", "", "7"])] + [_number(rng) for _ in range(6)]
        if delim == " ":
            f = [x.strip().replace(" ", "_") or "z" for x in f]
        line = delim.join(f) + (delim if trailing else "")
        out.append(line)
        if rng.random() < 0.02:
            out.append(rng.choice(["", "   ", "# note", "\t"]))
    end = "\r\n" if crlf else "\n"
    return (end.join(out) + end).encode()


def _fmt(delim: str, trailing: bool) -> ImuCsvFormat:
    cols = ["t", "_", "ax", "ay", "az", "gx", "gy", "gz"] + (["_"] if trailing else [])
    return ImuCsvFormat(columns=cols, delimiter=delim, time="relative").validate()


def _feed(fmt, parts, compiled: bool, block: int | None = None):
    p = CsvLineParser(PATH, fmt, compiled=compiled)
    block = block or len(parts) or 1
    got = [p.feed(parts[i:i + block], 1 + i) for i in range(0, len(parts), block)]
    a = np.concatenate([g[0] for g in got])
    lines = np.concatenate([g[1] for g in got])
    t = TimeFields.concat([g[2] for g in got])
    return a, lines, t


def _bits(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def test_compiled_reader_is_available():
    assert callable(getattr(_core, "parse_csv", None))


@pytest.mark.parametrize("seed", range(8))
def test_random_text_same_values_bit_for_bit(seed):
    rng = random.Random(seed)
    delim = [",", ";", " ", "\t", "|", ",", ";", ","][seed]
    style, crlf, trailing = seed % 4, seed % 2 == 1, seed in (1, 5)  # (a trailing space is stripped)
    raw = _text(rng, delim, 400, style, crlf, trailing)
    parts = raw.split(b"\n")[:-1]
    fmt = _fmt(delim, trailing)
    a_c, l_c, t_c = _feed(fmt, parts, True)
    a_p, l_p, t_p = _feed(fmt, parts, False)
    # the reference: float() of every field, the lines as counted here
    ref, ref_lines, tokens = [], [], []
    for i, b in enumerate(parts):
        s = b.decode().strip()
        if not s or s.startswith("#") or s.startswith("time"):
            continue
        tok = s.split(delim)
        ref.append([float(tok[0])] + [float(x) for x in tok[2:8]])
        ref_lines.append(i + 1)
        tokens.append(tok[0])
    assert len(ref) == 400
    np.testing.assert_array_equal(_bits(a_c), _bits(np.array(ref)))
    np.testing.assert_array_equal(_bits(a_p), _bits(np.array(ref)))
    np.testing.assert_array_equal(l_c, ref_lines)
    np.testing.assert_array_equal(l_p, ref_lines)
    ref_int = int(np.floor(float(tokens[0])))
    want = _time_after(tokens, ref_int)
    np.testing.assert_array_equal(_bits(t_c.after(ref_int)), _bits(want))
    np.testing.assert_array_equal(_bits(t_p.after(ref_int)), _bits(want))
    # block by block (the stream's way): the same rows and times
    a_b, l_b, t_b = _feed(fmt, parts, True, block=37)
    np.testing.assert_array_equal(_bits(a_b), _bits(a_c))
    np.testing.assert_array_equal(l_b, l_c)
    np.testing.assert_array_equal(_bits(t_b.after(ref_int)), _bits(want))
    conv_c, conv_p = SampleConverter(PATH, fmt, None), SampleConverter(PATH, fmt, None)
    np.testing.assert_array_equal(_bits(conv_c.times(t_c, a_c[:, 0])), _bits(conv_p.times(tokens, a_p[:, 0])))


def test_compiled_reader_reads_the_data_lines(monkeypatch):
    """Only the header (and comments before it) go through the Python reader on clean text."""
    rng = random.Random(11)
    parts = _text(rng, ",", 300, 0, True, False).split(b"\n")[:-1]
    seen = []
    orig = CsvLineParser._line
    monkeypatch.setattr(CsvLineParser, "_line", lambda self, b, n: seen.append(n) or orig(self, b, n))
    a, _, _ = _feed(_fmt(",", False), parts, True)
    assert len(a) >= 300 and seen == [1, 2]


@pytest.mark.parametrize("line, rows", [
    (b"5,q,1_000,2,3,4,5,6", [5, 1000, 2, 3, 4, 5, 6]),             # float() takes underscores
    (b"5,q,1e-400,2,3,4,5,6", [5, 0, 2, 3, 4, 5, 6]),               # underflow to 0
    (b"\x1c5,q,1,2,3,4,5,6\x1f", [5, 1, 2, 3, 4, 5, 6]),             # str.strip()'s other whitespace
    (b"5,q,  -0.0 ,2,3,4,5,6", [5, -0.0, 2, 3, 4, 5, 6]),
    (b"123456789012345678901234567890.5,q,1,2,3,4,5,6", [123456789012345678901234567890.5, 1, 2, 3, 4, 5, 6]),
])
def test_lines_only_python_reads_are_read_the_same(line, rows):
    """Forms the compiled reader leaves to the Python reader: the same values, and it goes on after them."""
    parts = [b"t,j,ax,ay,az,gx,gy,gz", b"4,q,0,0,0,0,0,0", line, b"6,q,1,1,1,1,1,1"]
    fmt = _fmt(",", False)
    a_c, l_c, t_c = _feed(fmt, parts, True)
    a_p, l_p, t_p = _feed(fmt, parts, False)
    np.testing.assert_array_equal(_bits(a_c), _bits(a_p))
    np.testing.assert_array_equal(_bits(a_c[1]), _bits(np.array(rows, float)))
    np.testing.assert_array_equal(l_c, [2, 3, 4])
    tok = [b"4", line.decode().strip("\x1c\x1f").split(",")[0], b"6"]
    tok = [t.decode() if isinstance(t, bytes) else t for t in tok]
    np.testing.assert_array_equal(_bits(t_c.after(4)), _bits(_time_after(tok, 4)))
    np.testing.assert_array_equal(_bits(t_p.after(4)), _bits(_time_after(tok, 4)))


BAD_LINES = {
    "short line": (b"5,q,1,2,3,4,5", "expected 8 ','-separated fields (t, _, ax, ay, az, gx, gy, gz), found 7"),
    "long line": (b"5,q,1,2,3,4,5,6,7", "expected 8 ','-separated fields (t, _, ax, ay, az, gx, gy, gz), found 9"),
    "bad number": (b"5,q,1,2,3.1.4,4,5,6", "bad number '3.1.4' in field 5 (az)"),
    "empty field": (b"5,q,1,,3,4,5,6", "bad number '' in field 4 (ay)"),
    "cut number": (b"5,q,1,2,3,4,5,6e", "bad number '6e' in field 8 (gz)"),
    "cut line": (b"5,q,1,2,3,4,5,", "bad number '' in field 8 (gz)"),
    "nan": (b"5,q,1,2,nan,4,5,6", "non-finite value 'nan' in field 5 (az)"),
    "overflow": (b"5,q,1,2,3,4,1e400,6", "non-finite value '1e400' in field 7 (gy)"),
    "bad time": (b"5:0,q,1,2,3,4,5,6", "bad number '5:0' in field 1 (t)"),
    "not ascii": ("5,q,1,2,3,4,5,6\u00b0".encode(), "not ASCII text"),
    "comment not ascii": ("# \u00b0C".encode(), "not ASCII text"),
}


@pytest.mark.parametrize("kind", sorted(BAD_LINES))
@pytest.mark.parametrize("block", [None, 2])
def test_bad_line_same_error(kind, block):
    bad, what = BAD_LINES[kind]
    parts = [b"t,j,ax,ay,az,gx,gy,gz", b"4,q,0,0,0,0,0,0", b"", bad, b"6,q,1,1,1,1,1,1"]
    fmt = _fmt(",", False)
    msgs = []
    for compiled in (True, False):
        with pytest.raises(ImuFileError) as exc:
            _feed(fmt, parts, compiled, block)
        msgs.append(str(exc.value))
        assert exc.value.line == 4
    assert msgs[0] == msgs[1]
    assert msgs[0].startswith(f"{PATH}, line 4: {what}"), msgs[0]
    assert "\n" not in msgs[0]


def test_read_imu_csv_same_with_and_without_compiled_reader(tmp_path, monkeypatch):
    """The whole-file reader (times in ns, str2str-free) gives the same samples either way."""
    rng = random.Random(3)
    p = tmp_path / "imu.csv"
    p.write_bytes(_text(rng, ",", 500, 1, False, False))
    fmt = ImuCsvFormat(columns=["t", "_", "ax", "ay", "az", "gx", "gy", "gz"], time="relative", time_unit="ns")
    got = read_imu_csv(p, fmt)
    monkeypatch.setattr(imu_csv._core, "parse_csv", None)
    ref = read_imu_csv(p, fmt)
    assert got.t_ref_gps_s == ref.t_ref_gps_s
    assert len(got) == 500
    for name in ("t_s", "acc_b", "gyro_b"):
        np.testing.assert_array_equal(_bits(getattr(got, name)), _bits(getattr(ref, name)))
    np.testing.assert_array_equal(got.lines, ref.lines)


@pytest.mark.parametrize("closed", [True, False])
def test_tick_log_drop_and_byte_ends_same(closed):
    """A str2str tick log's way (the first and an unfinished last line dropped, the byte after each row's
    newline): the same rows, lines and byte ends, given as one text or as lines."""
    fmt = ImuCsvFormat(("ax", "ay", "az", "gx", "gy", "gz", "tick_ms"), acc_unit="g").validate()
    rng = random.Random(7)
    body = [",".join(_number(rng) for _ in range(6)) + f",{500000 + 7 * k}" for k in range(200)]
    body[50] = ""
    body[90] = "\r"
    text = ("-1.0,0.1,0.0,0.0,999\n" + "\n".join(body) + ("\n" if closed else "\n0.01,0.0,-1")).encode()
    n = text.count(b"\n") + (0 if closed else 1)
    drop = (0, -1 if closed else n - 1)
    got = [CsvLineParser(PATH, fmt, compiled=c).feed(x, 1, drop=drop, ends=True)
           for c in (True, False) for x in (text, text.split(b"\n")[:n])]
    for a, lines, t, ends in got[1:]:
        np.testing.assert_array_equal(_bits(a), _bits(got[0][0]))
        np.testing.assert_array_equal(lines, got[0][1])
        assert ends == got[0][3]
    assert len(got[0][0]) == 198 and got[0][1][0] == 2
    ref_ends = np.cumsum([len(x) + 1 for x in text.split(b"\n")])
    assert got[0][3] == [int(ref_ends[k - 1]) for k in got[0][1]]


@pytest.mark.parametrize("bad, what", [
    (b"5 q 1  2 3 4 5 6", "expected 8 ' '-separated fields (t, _, ax, ay, az, gx, gy, gz), found 9"),
    (b"5 q 1 2 3 4 5", "expected 8 ' '-separated fields (t, _, ax, ay, az, gx, gy, gz), found 7"),
    (b"5 q 1 2 3\t4 5 6 7", "bad number '3\\t4' in field 5 (az)"),
])
def test_space_delimiter_same_error(bad, what):
    """A space delimiter: two spaces make an empty field, a tab is no delimiter."""
    parts = [b"t j ax ay az gx gy gz", b"4 q 0 0 0 0 0 0\t", b" ", bad]
    msgs = []
    for compiled in (True, False):
        with pytest.raises(ImuFileError) as exc:
            _feed(_fmt(" ", False), parts, compiled)
        msgs.append(str(exc.value))
    assert msgs[0] == msgs[1] == f"{PATH}, line 4: {what}"
