"""The RINEX observation reader's fixed-point fast path gives the number strtod gives.

``insnav/io/rinex3_obs.hpp`` reads a field such as ``  20123456.789`` (F14.3) as the integer
mantissa over a power of ten, one correctly rounded division (Clinger 1990, the fast path), and
leaves everything else (exponents, '+', more than 15 significant digits) to strtod.  Python's
``float`` rounds correctly as strtod does, so every field read must equal ``float(text)`` to the bit.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

_core = pytest.importorskip("insnav._core")

TYPES = {"G": ["C1C", "L1C", "D1C", "S1C"]}


def _body(fields: list[str]) -> bytes:
    """Epochs of one GPS satellite, four 14-character fields a line (C, L, D, S; LLI and SS blank)."""
    lines = []
    for k in range(0, len(fields), 4):
        row = fields[k:k + 4] + [" " * 14] * (4 - len(fields[k:k + 4]))
        i = k // 4
        lines.append(f"> 2024 06 24 {8 + i // 2400:02d} {i // 60 % 40 + 10:02d}{i % 60:11.7f}  0  1")
        lines.append("G01" + "".join(f + "  " for f in row))
    return ("\n".join(lines) + "\n").encode()


def _read(fields: list[str]) -> np.ndarray:
    d = _core.read_rinex3_obs_body(_body(fields), "fast.obs", 0, 0, TYPES, TYPES, False, False)
    return np.asarray(d["obs"])[:, :4].reshape(-1)[:len(fields)]


def _expected(text: str) -> float:
    t = text.strip()
    return math.nan if not t else float(t.replace("D", "E").replace("d", "e"))


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1.0, a) == math.copysign(1.0, b))


EDGE = ["  20123456.789", " -20123456.789", "              ", "         0.000", "        -0.000",
        "      12345678", "     -12345678", "            5.", "           .25", "          -.25",
        "00001234.56789", "   1.2345E+03 ", "   1.2345D+03 ", "  +123456.789  "[:14], " 9999999999.999",
        "99999999999999", "0.000000000001", "-0.00000000001", "1.234567890123", "  123.4560000 ",
        "  7.000000001 ", "   -1.5e-3    "]


def test_edge_fields_equal_strtod():
    """Blanks (NaN), signs and signed zeros, no decimals, a bare point, leading zeros, 14 digits,
    exponents (strtod's route) and a '+' (strtod's route): each bit for bit ``float(text)``."""
    fields = [f[:14].rjust(14) for f in EDGE]
    got = _read(fields)
    for text, v in zip(fields, got.tolist()):
        assert _same(v, _expected(text)), (text, v, _expected(text))
    assert math.copysign(1.0, _read(["        -0.000"])[0]) == -1.0  # -0.0 kept (zero_is_missing off)


def test_random_f14_3_fields_equal_strtod():
    """5000 random F14.3 values over 12 decades, both signs, and random widths of decimals."""
    rng = np.random.default_rng(7)
    x = rng.uniform(-1, 1, 5000) * 10.0 ** rng.uniform(-3, 9, 5000)
    dec = rng.integers(0, 8, 5000)
    fields = [f"{v:14.{d}f}"[-14:] for v, d in zip(x.tolist(), dec.tolist())]
    got = _read(fields)
    bad = [(t, v) for t, v in zip(fields, got.tolist()) if not _same(v, _expected(t))]
    assert bad == []


def test_malformed_field_still_raises():
    """A character inside a number is not a number (the strtod route reports it)."""
    with pytest.raises(RuntimeError, match="line 2"):
        _read(["   123.4x6    "])
