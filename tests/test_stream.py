"""``insnav run --format kfgins`` block by block (insnav.filters.stream): the
solution CSV, its innovations sidecar, the resolved configuration and the
report line are byte for byte those of the whole-file run, for any block size
and output rate; a bad or truncated line in a later block is a one-line error
naming the file and its line; what the stream cannot reproduce exactly goes to
the whole-file run with a one-line note."""
from __future__ import annotations

import lzma

import numpy as np
import pytest

import insnav.filters.stream as stream
from insnav.filters.stream import imu_text_blocks

from test_cli import _call

#: IMU lines of the trimmed KF-GINS track (the run starts 50 s in, at the YAML's starttime)
LINES = 40_000


@pytest.fixture(scope="module")
def kf_short(shared_data, tmp_path_factory):
    """The KF-GINS simulated track's first LINES IMU lines, its GNSS file (records past the
    IMU's end included: the loader cuts them) and its YAML, in a temporary folder."""
    sim = shared_data / "kfgins" / "sim"
    d = tmp_path_factory.mktemp("kfshort")
    with lzma.open(sim / "Leador-A15-sim.txt.xz", "rb") as f:
        lines = [f.readline() for _ in range(LINES)]
    (d / "imu.txt").write_bytes(b"".join(lines))
    (d / "gnss.txt").write_bytes((sim / "GNSS-RTK-sim.txt").read_bytes())
    yaml = (sim / "kf-gins-sim.yaml").read_text()
    yaml = "\n".join('imupath: "./imu.txt"' if ln.startswith("imupath:") else
                     'gnsspath: "./gnss.txt"' if ln.startswith("gnsspath:") else ln for ln in yaml.splitlines())
    (d / "kf.yaml").write_text(yaml + "\n")
    return d


def _run(d, out, *extra):
    rc, so, se = _call(["run", "--format", "kfgins", "--config", d / "kf.yaml", "--out", out, "--quiet", *extra])
    return rc, so.replace(str(out), "OUT"), se.replace(str(out), "OUT")


def streamed_and_whole(run, d, a, b, *extra):
    """`run` (a command-line runner of this file or test_stream_csv) block by block to `a` and
    whole-file to `b`: both succeed, the stream really ran (no fallback note), the same stdout;
    their stderr texts."""
    rca, outa, erra = run(d, a, "--stream", "on", *extra)
    rcb, outb, errb = run(d, b, "--stream", "off", *extra)
    assert (rca, rcb) == (0, 0), (erra, errb)
    assert "note:" not in erra  # the stream ran, not the whole-file fallback
    assert outa == outb
    return erra, errb


@pytest.mark.parametrize("extra", [(), ("--output-rate", "10"), ("--columns", "nav,sigma", "--filter", "rbukf")])
def test_block_by_block_run_writes_the_whole_file_runs_bytes(kf_short, tmp_path, monkeypatch, extra):
    # blocks of 4093 lines: boundaries fall inside decimation windows, GNSS intervals and the start time
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    streamed_and_whole(_run, kf_short, a, b, *extra)
    for suffix in ("", ".innovations.csv", ".config.toml"):
        assert (a.parent / (a.name + suffix)).read_bytes() == (b.parent / (b.name + suffix)).read_bytes(), suffix
    rows = a.read_text().count("\n") - 1
    dec = 20 if "--output-rate" in extra else 1
    assert rows == -(-(LINES - 10_001) // dec)  # the samples after t0 (the first at starttime), the last row too
    assert sorted(p.name for p in a.parent.iterdir()) == ["sol.csv", "sol.csv.config.toml",
                                                            "sol.csv.innovations.csv"]  # no temporary file left


def test_the_configs_output_decimation_is_kept_block_by_block(kf_short, tmp_path, monkeypatch):
    """``output_decimation`` from a config (a saved ``<out>.config.toml`` of an ``--output-rate`` run):
    the stream writes every 20th row as the whole-file run does, and saves the key unchanged."""
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    rc = tmp_path / "rc.toml"
    rc.write_text("output_decimation = 20\n")
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    streamed_and_whole(_run, kf_short, a, b, "--run-config", rc)
    assert a.read_bytes() == b.read_bytes()
    assert a.read_text().count("\n") - 1 == -(-(LINES - 10_001) // 20)
    assert "output_decimation = 20" in (a.parent / "sol.csv.config.toml").read_text()


def _with_line(src, dst, lineno: int, text: bytes | None, cut: bool = False):
    lines = src.read_bytes().splitlines(keepends=True)
    if cut:  # the file ends inside line `lineno`
        lines = lines[:lineno - 1] + [lines[lineno - 1][:20]]
    else:
        lines[lineno - 1] = text
    dst.write_bytes(b"".join(lines))


@pytest.mark.parametrize("lineno, text, cut, message", [
    (25_001, b"456375.000 1e-7 x 1e-7 1e-3 1e-3 -0.05\n", False, ":25001: not a number: 'x' in column 'dtheta_y'"),
    (31_234, b"456375.000 1e-7 1e-7\n", False, ":31234: expected 7 columns, found 3"),
    (LINES, None, True, f":{LINES}: expected 7 columns, found 2 (incomplete last line: file truncated?)"),
    (20_000, b"456349.990 nan 0 0 0 0 -0.05\n", False, ":20000: non-finite value nan in column 'dtheta_x'"),
    (27_000, b"456300.000 0 0 0 0 0 -0.05\n", False, ":27000: time 456300.0 does not increase")])
def test_a_bad_line_in_a_later_block_names_file_and_line(kf_short, tmp_path, monkeypatch, lineno, text, cut,
                                                         message):
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    d = tmp_path / "kf"
    d.mkdir()
    for name in ("kf.yaml", "gnss.txt"):
        (d / name).write_bytes((kf_short / name).read_bytes())
    _with_line(kf_short / "imu.txt", d / "imu.txt", lineno, text, cut)
    errs = []
    for mode in ("on", "off"):
        out = tmp_path / mode / "sol.csv"
        rc, _, err = _run(d, out, "--stream", mode)
        assert rc != 0 and not out.parent.exists()  # nothing written, not even the folder
        errs.append(err.strip())
    assert len(errs[0].splitlines()) == 1 and f"imu.txt{message}" in errs[0], errs[0]
    assert errs[0] == errs[1]  # the whole-file reader's message, line for line


def test_line_numbers_stay_right_across_blocks(tmp_path):
    rows = [f"{i * 0.01:.2f} {i} 0 0 0 0 {-i}\n" for i in range(1, 11)]
    rows.insert(4, "\n")  # a blank line: the rows after it are one line further down
    rows.insert(8, "  \n")
    p = tmp_path / "imu.txt"
    p.write_text("".join(rows))
    got = [(float(t), blk.origin.line(i)) for blk in imu_text_blocks(p, block_lines=1)
           for i, t in enumerate(blk.t)]
    want_lines = [1, 2, 3, 4, 6, 7, 8, 10, 11, 12]
    assert [ln for _, ln in got] == want_lines
    assert np.allclose([t for t, _ in got], np.arange(1, 11) * 0.01)


def test_what_the_stream_cannot_do_runs_whole_with_a_note(kf_short, tmp_path, monkeypatch):
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    # a repeated IMU record in a later block: the sanitizer drops it, so the whole-file run takes over
    d = tmp_path / "kf"
    d.mkdir()
    for name in ("kf.yaml", "gnss.txt"):
        (d / name).write_bytes((kf_short / name).read_bytes())
    lines = (kf_short / "imu.txt").read_bytes().splitlines(keepends=True)
    (d / "imu.txt").write_bytes(b"".join(lines[:22_222] + [lines[22_221]] + lines[22_222:]))
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    rca, outa, erra = _run(d, a)
    rcb, outb, errb = _run(d, b, "--stream", "off")
    assert rca == rcb == 0
    assert erra.strip() == "note: the IMU file is read whole, not block by block: repeated IMU times (the " \
                           "sanitizer drops duplicates)"
    assert a.read_bytes() == b.read_bytes() and outa.replace("a.csv", "") == outb.replace("b.csv", "")
    # the RTS smoother needs the whole run
    rc, _, err = _run(kf_short, tmp_path / "s.csv", "--smooth", "--output-rate", "10")
    assert rc == 0 and err.strip() == "note: the IMU file is read whole, not block by block: the RTS smoother " \
                                      "needs the whole run"


@pytest.mark.parametrize("decimation", [1, 7])
def test_engine_fed_in_blocks_equals_the_batch_engine_bit_for_bit(kf_short, decimation):
    # _core.LooseStream (engine/loose_stream.hpp) against _core.run_loose on the same arrays, fed in blocks
    # of random sizes (1 .. 5000 samples): every row and every record output identical, the last row included
    from insnav import _core
    from insnav.filters._setup import imu_arrays
    from insnav.filters.loose import loose_engine_args
    from insnav.io.kfgins import read_kfgins_gnss
    from insnav.io.kfgins_dataset import load_kfgins
    from insnav.units import DEG

    ds, cfg = load_kfgins(kf_short / "kf.yaml")
    cfg.output_decimation = decimation
    t, dth, dv = imu_arrays(ds)
    g = read_kfgins_gnss(kf_short / "gnss.txt")  # every fix after t0, those after the IMU's end too
    gnss = np.column_stack([g.t_valid, g.lat_deg * DEG, g.lon_deg * DEG, g.h_m, g.v_n, g.sigma_pos_n, g.sigma_vel_n])
    gnss = np.ascontiguousarray(gnss[gnss[:, 0] > ds.t0])
    a = loose_engine_args(ds, cfg, gnss[:, 0].copy())
    batch = _core.run_loose(cfg.filter, a.layout, t, dth, dv, gnss, a.init, a.P0, a.imu_correction, a.imu_model,
                            a.config)
    s = _core.LooseStream(cfg.filter, a.layout, gnss, a.init, a.P0, a.imu_correction, a.imu_model, a.config, 5000)
    rng = np.random.default_rng(4)
    got, i = [], 0
    while i < len(t):
        k = int(rng.integers(1, 5001))
        n = s.run_block(t[i:i + k], dth[i:i + k], dv[i:i + k])
        got.append({key: v.copy() for key, v in s.rows().items()} if n else None)
        i += k
    if s.finish():
        got.append({key: v.copy() for key, v in s.rows().items()})
    rows = [r for r in got if r is not None]
    assert len(batch["t"]) == -(-len(t) // decimation)
    for key in ("t", "llh", "v_n", "rpy", "sigma", "imu_err"):
        assert np.array_equal(np.concatenate([r[key] for r in rows]), batch[key]), key
    rec = s.records()
    for key in ("innovation", "nis", "log_det_s", "status"):
        assert np.array_equal(rec[key], batch[key], equal_nan=True), key
    for key in ("updates", "rejected", "gate_reopened", "gate_outage_accepted", "cholesky_repairs"):
        assert rec[key] == batch[key], key
    assert rec["updates"] > 50 and (rec["status"] == 4).sum() > 0  # fixes applied, and some after the IMU's end


def test_a_slow_writer_never_sees_its_rows_overwritten(kf_short, tmp_path, monkeypatch):
    # the writer thread formats block i while the engine fills its other row buffer; calls that write no row
    # (1 Hz rows from blocks of ~100 samples) must still wait for it, or the engine refills the buffer the
    # writer is reading: a writer slowed down here would then write later blocks' rows
    import time

    real = stream._core

    class SlowCore:
        def __getattr__(self, name):
            return getattr(real, name)

        @staticmethod
        def write_table(*a, **kw):
            time.sleep(0.01)
            return real.write_table(*a, **kw)

    monkeypatch.setattr(stream, "BLOCK_LINES", 97)
    monkeypatch.setattr(stream, "_core", SlowCore())
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert _run(kf_short, a, "--output-rate", "1", "--stream", "on")[0] == 0
    monkeypatch.setattr(stream, "_core", real)
    assert _run(kf_short, b, "--output-rate", "1", "--stream", "off")[0] == 0
    assert a.read_bytes() == b.read_bytes()


def test_the_checks_imu_is_the_sum_of_the_samples_in_each_window():
    # _Coarse: fed in blocks of any size, the first sample alone, then every window of k samples summed
    # (the time its last sample's), the incomplete last window too; the same as summing the whole arrays
    rng = np.random.default_rng(2)
    n, k = 1003, 20
    t = np.arange(1, n + 1) * 0.005
    dth, dv = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    c = stream._Coarse(k, expected_samples=100)  # too small: the arrays grow
    i = 0
    while i < n:
        m = int(rng.integers(0, 50))
        c.add(t[i:i + m], dth[i:i + m], dv[i:i + m]) if m else None
        i += m
    got = c.imu("imu")
    edges = [0, 1] + list(range(1 + k, n, k)) + [n]
    assert np.array_equal(got.t, t[np.array(edges[1:]) - 1])
    for a, b in ((got.dtheta_b, dth), (got.dv_b, dv)):
        want = np.array([b[lo:hi].sum(axis=0) for lo, hi in zip(edges[:-1], edges[1:])])
        assert np.allclose(a, want, rtol=0, atol=1e-12)


def test_a_run_whose_checks_record_is_halved_writes_the_whole_file_runs_bytes(kf_short, tmp_path, monkeypatch):
    # the input checks' IMU record limited to 500 rows (the run's ~1500 at 10 Hz: summed to 2.5 Hz,
    # tests/test_stream_checks.py): the checks still pass, the stream runs (no note), the same file
    made = []

    class Recorded(stream._Coarse):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            made.append(self)

    monkeypatch.setattr(stream, "CHECK_MAX_ROWS", 500)
    monkeypatch.setattr(stream, "_Coarse", Recorded)
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    streamed_and_whole(_run, kf_short, a, b, "--output-rate", "10")
    assert a.read_bytes() == b.read_bytes()
    assert len(made) == 1 and made[0].merge == 4 and made[0].n <= 500 + 1
