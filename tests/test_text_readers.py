"""The compiled text readers (KF-GINS IMU/GNSS text, insnav CSVs): values
exactly as Python's float() reads them, the first bad value reported by file,
line and column while blank lines keep the numbering (also across the two
halves the reader splits a large file into), and compressed input: a
truncated .xz/.gz is one line naming the file."""
from __future__ import annotations

import gzip
import lzma

import numpy as np
import pytest

from insnav.data.dataset import ImuData
from insnav.data.textio import parse_numeric
from insnav.io import kfgins

from test_cli import _user_error


def _imu_text(n, seed=0):
    rng = np.random.default_rng(seed)
    t = 456250.004412029 + 0.005 * np.arange(n)
    a = np.column_stack([t, rng.standard_normal((n, 3)) * 1e-6, rng.standard_normal((n, 3)) * 1e-2])
    text = "".join(f"{r[0]:.9f} " + " ".join(f"{x:.12e}" for x in r[1:]) + "\n" for r in a)
    return np.array([[float(x) for x in ln.split()] for ln in text.splitlines()]), text  # what float() reads


def test_values_are_what_float_reads():
    toks = ["0", "-0", "+1.5", "1e-320", "4.9e-324", "1.7976931348623157e308", "0.1", "-2.5E+3", "123456789012345678901",
            ".5", "5.", "nan", "inf", "-inf", "1e400"]
    a, lines = parse_numeric(" ".join(toks).encode(), len(toks), "x", comma=False)
    expect = np.array([float(t) for t in toks])
    np.testing.assert_array_equal(a[0], expect)
    assert lines is None
    for bad in ["1e", "--1", "+", "0x1p3", "1.0.0", "1_0", "+-1", "\xff"]:
        with pytest.raises(ValueError, match=r"^x:1: not a number: .* in column 2$"):
            parse_numeric(f"1 {bad} 3".encode(), 3, "x", comma=False)


def test_large_file_two_halves_keep_line_numbers(tmp_path):
    a, text = _imu_text(40_000)  # ~4 MB: parsed as two halves on two threads
    lines = text.splitlines()
    for i in (5, 25_000):  # a blank line in each half
        lines.insert(i, "   ")
    p = tmp_path / "imu.txt"
    p.write_text("\n".join(lines) + "\n")
    imu = kfgins.read_kfgins_imu(p)
    np.testing.assert_array_equal(imu.to_array(), a)
    assert imu.origin.line(4) == 5 and imu.origin.line(5) == 7 and imu.origin.line(30_000) == 30_003
    bad = list(lines)
    bad[30_002] = bad[30_002].replace(bad[30_002].split()[5], "1.2.3")  # file line 30003, second half
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(ValueError, match=r"imu\.txt:30003: not a number: '1\.2\.3' in column 'dvel_y'$"):
        kfgins.read_kfgins_imu(p)
    bad = list(lines)
    bad[3] = "1 2 3"  # first half: reported first, though the second half is parsed too
    bad[30_002] = "x"
    p.write_text("\n".join(bad) + "\n")
    with pytest.raises(ValueError, match=r"imu\.txt:4: expected 7 columns, found 3$"):
        kfgins.read_kfgins_imu(p)
    p.write_text(text[: len(text) - 40])  # cut inside the last line
    with pytest.raises(ValueError, match=r"imu\.txt:40000: expected 7 columns, found \d \(incomplete last line"):
        kfgins.read_kfgins_imu(p)


def test_blank_line_in_one_half_only_and_column_groups(tmp_path):
    """Line numbers when only the second half has a blank line (the first half's
    rows are numbered afterwards); the IMU columns parsed straight into t,
    dtheta and dv equal the whole table; a NaN is reported by line and column."""
    a, text = _imu_text(40_000, seed=1)
    lines = text.splitlines()
    lines.insert(30_000, "")
    data = ("\n".join(lines) + "\n").encode()
    table, where = parse_numeric(data, 7, "x", comma=False)
    parts, where2 = parse_numeric(data, 7, "x", comma=False, groups=(1, 3, 3))
    np.testing.assert_array_equal(table, a)
    np.testing.assert_array_equal(np.column_stack(parts), a)
    assert parts[0].shape == (40_000,) and parts[1].shape == parts[2].shape == (40_000, 3)
    np.testing.assert_array_equal(where, where2)
    assert where[10] == 11 and where[29_999] == 30_000 and where[30_000] == 30_002
    lines[35_000] = lines[35_000].replace(lines[35_000].split()[4], "nan")
    p = tmp_path / "imu.txt"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"imu\.txt:35001: non-finite value nan in column 'dvel_x'$"):
        kfgins.read_kfgins_imu(p)


@pytest.mark.parametrize("suffix, opener", [(".xz", lzma.open), (".gz", gzip.open)])
def test_compressed_input_and_truncated_compressed_file(tmp_path, suffix, opener):
    a, text = _imu_text(3000)
    p = tmp_path / f"imu.txt{suffix}"
    with opener(p, "wt") as f:
        f.write(text)
    np.testing.assert_array_equal(kfgins.read_kfgins_imu(p).to_array(), a)
    raw = p.read_bytes()
    cut = tmp_path / f"cut.txt{suffix}"
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match=rf"^{cut}: truncated or corrupt {suffix[1:]} file") as e:
        kfgins.read_kfgins_imu(cut)
    assert "\n" not in str(e.value)
    gnss = tmp_path / "gnss.txt"
    gnss.write_text("456251.0 30.0 114.0 20.0 0.01 0.01 0.02\n")
    y = tmp_path / "kf.yaml"
    y.write_text(f"imupath: {cut.name}\ngnsspath: gnss.txt\ninitpos: [30, 114, 20]\ninitvel: [0, 0, 0]\n"
                 "initatt: [0, 0, 0]\nimunoise:\n  arw: [0.1, 0.1, 0.1]\n  vrw: [0.1, 0.1, 0.1]\n")
    _user_error(["run", "--format", "kfgins", "--config", y, "--out", tmp_path / "s.csv"], str(cut), "truncated")
    assert not (tmp_path / "s.csv").exists()


def test_kfgins_gnss_and_nav_readers_round_trip(tmp_path):
    import insnav

    ds = insnav.simulate("seed000-sim", seed=1)
    kfgins.write_kfgins_gnss(tmp_path / "g.txt", ds.gnss, with_velocity=True)
    g = kfgins.read_kfgins_gnss(tmp_path / "g.txt")
    np.testing.assert_allclose(g.lat_deg, ds.gnss.lat_deg, atol=5e-11)
    kfgins.write_kfgins_nav(tmp_path / "t.nav", ds.truth)
    tr = kfgins.read_kfgins_nav(tmp_path / "t.nav")
    np.testing.assert_allclose(tr.yaw_deg, ds.truth.yaw_deg, atol=5e-9)
    kfgins.write_kfgins_imu(tmp_path / "i.txt", ImuData(ds.imu.t[:100], ds.imu.dtheta_b[:100], ds.imu.dv_b[:100]))
    np.testing.assert_allclose(kfgins.read_kfgins_imu(tmp_path / "i.txt").dv_b, ds.imu.dv_b[:100], rtol=1e-15)


def test_fixed_decimals_are_printf_rounding(tmp_path):
    """The writer's integer fast path (16 digits made in two words) against
    Python's correctly rounded "%.{d}f" with trailing zeros dropped, on values
    of every magnitude it takes (|v| 10^d < 10^15), exact decimals and ties."""
    from insnav import _core

    rng = np.random.default_rng(7)
    n = 20_000
    v = rng.uniform(-1, 1, n) * 10.0 ** rng.integers(-18, 16, n)
    v[: n // 4] = np.round(v[: n // 4], 3)  # trailing zeros to drop
    v[n // 4: n // 2] = (np.floor(v[n // 4: n // 2] * 8) + 0.5) / 8  # exact binary ties
    v[:6] = [0.0, -0.0, 5e-7, -5e-7, 999999999999999.0, -123456.0]
    for d in (0, 1, 4, 6, 9, 11, 15):
        p = tmp_path / f"d{d}.txt"
        _core.write_table(str(p), "", [v], [1.0], [d])
        for tok, x in zip(p.read_text().splitlines(), v):
            want = f"{x:.{d}f}"
            want = (want.rstrip("0").rstrip(".") if d else want)
            assert tok == ("0" if want == "-0" else want), (d, x, tok)


def test_fixed_decimals_next_to_decimal_ties_are_printf_rounding(tmp_path):
    """Values one to three ulps from a decimal tie (m + 1/2) 10^-d at every
    scaled magnitude up to 10^15, where the rounding of v 10^d decides the
    last digit: the writer's exact residual (an fma or Dekker's exact
    product) against printf's correctly rounded "%.{d}f"."""
    from insnav import _core

    rng = np.random.default_rng(3)
    for d in (1, 3, 6, 9, 11, 13, 15):
        m = np.floor(rng.uniform(0, 1, 4000) * 10.0 ** rng.uniform(0, 15 - 0.01, 4000))
        tie = (m + 0.5) / 10.0 ** d * np.where(rng.random(4000) < 0.5, -1.0, 1.0)
        v = np.concatenate([np.nextafter(tie, tie + s * np.inf) if s else tie for s in (-1, 0, 1)]
                           + [tie + k * np.spacing(tie) for k in (-3, -2, 2, 3)])
        p = tmp_path / f"t{d}.txt"
        _core.write_table(str(p), "", [v], [1.0], [d])
        for tok, x in zip(p.read_text().splitlines(), v):
            want = f"{x:.{d}f}".rstrip("0").rstrip(".")
            assert tok == ("0" if want == "-0" else want), (d, x, tok)


def test_plain_decimals_read_as_float_reads():
    """The reader's fast path for plain decimals (Clinger's: m / 10^k when the
    digits m <= 2^53 and k <= 22) against Python's float() on random decimals
    of 1..21 digits with 0..24 after the point, around 2^53 and with leading
    zeros, signs and the forms without an integer or a fraction part: the
    same doubles bit for bit (the longer ones go through std::from_chars)."""
    rng = np.random.default_rng(11)
    toks = []
    for _ in range(20_000):
        k = int(rng.integers(1, 22))
        digits = "".join(map(str, rng.integers(0, 10, k)))
        f = int(rng.integers(0, min(k, 24) + 1))
        tok = digits[:k - f] + ("." + digits[k - f:] if f else "")
        toks.append(("-" if rng.random() < 0.5 else "") + tok)
    toks += [str(2 ** 53 + d) for d in range(-3, 4)] + [f"{2 ** 53 + d}.0" for d in range(-3, 4)]
    toks += ["0.000000397799", "-0.000000084735", "456250.004412029", "-0", "-0.0", ".5", "-.25", "5.", "00012.500",
             "9007199254740993e-3", "1" * 19, "1" * 20, "0." + "0" * 21 + "1", "0." + "0" * 22 + "1", "1e22"]
    a, _ = parse_numeric(" ".join(toks).encode(), len(toks), "x", comma=False)
    expect = np.array([float(t) for t in toks])
    assert a[0].tobytes() == expect.tobytes()  # bit for bit, the sign of a zero too
