"""``insnav run --format csv`` block by block (insnav.filters.stream.stream_csv_loose): the
generic IMU CSV read, mapped (columns, units, axes, mounting, time base) and integrated block
by block gives the solution CSV, its innovations sidecar, the resolved configuration and the
report of the whole-file run byte for byte, with block boundaries inside the alignment, the
trapezoid's intervals, decimation windows and GNSS intervals; what it cannot reproduce (an IMU
gap, a str2str tick log) runs whole with a one-line note; a garbled line in a later block is a
one-line error naming the file and its line, and leaves no file behind."""
from __future__ import annotations

from decimal import Decimal

import numpy as np
import pytest

import insnav.filters.stream as stream
from insnav._toml import dumps_toml
from insnav.io.imu_csv import GPST_UNIX_OFFSET_S, ImuCsvFormat, read_imu_csv

from test_cli import _call
from test_csv_dataset import _car, config, write_gnss, write_imu

#: lines per block: boundaries fall in the 20 s standstill, the alignment's course window and the run
BLOCK = 997
WEEK = 2155


@pytest.fixture(scope="module")
def car_files(tmp_path_factory):
    """The consumer-IMU car (20 s standstill, then driving; 200 Hz, 110 s) as a generic CSV in
    GPS seconds of week, rad and m/s increments (FRD), and its GNSS fixes."""
    car = _car()
    d = tmp_path_factory.mktemp("carcsv")
    write_imu(d / "imu.csv", car)
    write_gnss(d / "gnss.csv", car)
    (d / "run.toml").write_text(dumps_toml(config()))
    return car, d


def _to_gpst_unix_ms(path, week: int) -> None:
    """Rewrite the time column (GPS seconds of week) as GPS time since 1970 in ms, exact decimals."""
    lines = path.read_text().splitlines()
    out = [lines[0]]
    for ln in lines[1:]:
        t, rest = ln.split(",", 1)
        ms = (Decimal(t) + week * 604800 + GPST_UNIX_OFFSET_S) * 1000
        out.append(f"{ms:f},{rest}")
    path.write_text("\n".join(out) + "\n")


@pytest.fixture(scope="module")
def mapped_files(car_files, tmp_path_factory):
    """The same drive as instantaneous rates in deg/s and g, FLU axes with a small mounting
    rotation, times in ms of GPS time since 1970: every step of the mapping is used."""
    car, d0 = car_files
    d = tmp_path_factory.mktemp("mapped")
    write_imu(d / "imu.csv", car, axes="FLU", gyro="deg", acc="g", samples="rates")
    _to_gpst_unix_ms(d / "imu.csv", WEEK)
    (d / "gnss.csv").write_bytes((d0 / "gnss.csv").read_bytes())
    imu = dict(time="gpst_unix_s", time_unit="ms", axes="FLU", gyro_unit="deg", acc_unit="g", samples="rates",
               mount_rpy_deg=[0.4, -0.3, 0.7])
    (d / "run.toml").write_text(dumps_toml(config(imu=imu)))
    return d


def _run(d, out, *extra, imu="imu.csv"):
    rc, so, se = _call(["run", "--format", "csv", "--imu", d / imu, "--gnss", d / "gnss.csv", "--config",
                        d / "run.toml", "--out", out, "--quiet", *extra])
    return rc, so.replace(str(out), "OUT"), se.replace(str(out), "OUT")


def _same_files(a, b):
    for suffix in ("", ".innovations.csv", ".config.toml"):
        pa, pb = a.parent / (a.name + suffix), b.parent / (b.name + suffix)
        assert pa.read_bytes() == pb.read_bytes(), suffix


@pytest.mark.parametrize("which,extra", [("car", ()), ("car", ("--output-rate", "10")),
                                         ("car", ("--columns", "nav,sigma", "--filter", "rbukf")),
                                         ("mapped", ()), ("mapped", ("--output-rate", "20"))])
def test_csv_block_by_block_writes_the_whole_file_runs_bytes(car_files, mapped_files, tmp_path, monkeypatch, which,
                                                             extra):
    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    d = car_files[1] if which == "car" else mapped_files
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    rca, outa, erra = _run(d, a, "--stream", "on", *extra)
    rcb, outb, errb = _run(d, b, "--stream", "off", *extra)
    assert (rca, rcb) == (0, 0), (erra, errb)
    assert "note:" not in erra  # the stream ran, not the whole-file fallback
    assert outa == outb and erra == errb
    _same_files(a, b)
    # the alignment is 19 s into the record: it read several blocks, and the run starts right after it
    t0 = float(outa.split("initial state at t = ")[1].split(" s")[0])
    t = np.loadtxt(a, delimiter=",", skiprows=1, usecols=0)
    assert t0 < t[0] <= t0 + (0.0051 if "--output-rate" not in extra else 0.15)
    assert sorted(p.name for p in a.parent.iterdir()) == ["sol.csv", "sol.csv.config.toml",
                                                         "sol.csv.innovations.csv"]


def test_csv_blocks_equal_the_whole_file_reader(mapped_files, monkeypatch):
    """Each block's increments are the whole-file reader's, bit for bit, across every boundary."""
    import tomllib

    d = mapped_files
    fmt = ImuCsvFormat(**{k: v for k, v in tomllib.loads((d / "run.toml").read_text())["imu"].items()
                          if k not in ("grade",)}).validate()
    whole = read_imu_csv(d / "imu.csv", fmt).to_increments(604800.0 * WEEK)
    blocks = list(stream.imu_csv_blocks(d / "imu.csv", fmt, t_offset_s=604800.0 * WEEK, block_lines=331))
    assert len(blocks) > 50
    for name in ("t", "dtheta_b", "dv_b"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, name) for b in blocks]), getattr(whole, name))
    lines = np.concatenate([b.origin.all_lines(len(b.t)) for b in blocks])
    np.testing.assert_array_equal(lines, whole.origin.all_lines(len(whole.t)))
    assert lines[0] == 3  # the header, then the first sample only starts the trapezoid


def test_an_imu_gap_runs_whole_with_a_note(car_files, tmp_path, monkeypatch):
    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    d0 = car_files[1]
    d = tmp_path / "gap"
    d.mkdir()
    for name in ("gnss.csv", "run.toml"):
        (d / name).write_bytes((d0 / name).read_bytes())
    lines = (d0 / "imu.csv").read_text().splitlines(keepends=True)
    (d / "imu.csv").write_text("".join(lines[:15_000] + lines[15_010:]))  # 50 ms missing at 75 s (bridged)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    rca, outa, erra = _run(d, a, "--stream", "on")
    rcb, outb, errb = _run(d, b, "--stream", "off")
    assert (rca, rcb) == (0, 0), (erra, errb)
    assert erra.strip() == "note: the IMU file is read whole, not block by block: an IMU gap (the sanitizer " \
                           "bridges it)"
    assert outa == outb
    _same_files(a, b)


def test_a_tick_log_runs_whole_with_a_note(car_files, tmp_path):
    """A str2str ``tick_ms`` log: its time map is fitted over the whole record."""
    from insnav.filters.stream import Fallback, stream_csv_loose
    from insnav.io.csv_dataset import csv_inputs

    d0 = car_files[1]
    cfg = config(imu=dict(columns=["tick_ms", "gx", "gy", "gz", "ax", "ay", "az"]))
    inp = csv_inputs(d0 / "imu.csv", d0 / "gnss.csv", cfg)
    with pytest.raises(Fallback, match="tick_ms log: its tick -> GPS time map is fitted over the whole record"):
        stream_csv_loose(inp, d0 / "imu.csv", tmp_path / "sol.csv", configure=lambda c: c)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("lineno,text,message", [
    (9_000, "345630.12,0.001,0.002\n", ", line 9000: expected 7 ','-separated fields (t, gx, gy, gz, ax, ay, az), "
                                       "found 3"),
    (14_321, "345700.0,0.0x01,0,0,0,0,0\n", ", line 14321: bad number '0.0x01' in field 2 (gx)"),
    (20_001, None, ", line 20001: expected 7 ','-separated fields"),  # cut mid-line: the last line is short
])
def test_a_garbled_line_in_a_later_block_names_file_and_line(car_files, tmp_path, monkeypatch, lineno, text,
                                                              message):
    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    d0 = car_files[1]
    d = tmp_path / "bad"
    d.mkdir()
    for name in ("gnss.csv", "run.toml"):
        (d / name).write_bytes((d0 / name).read_bytes())
    lines = (d0 / "imu.csv").read_text().splitlines(keepends=True)
    if text is None:
        lines = lines[:lineno - 1] + [lines[lineno - 1][:20]]
    else:
        lines[lineno - 1] = text
    (d / "imu.csv").write_text("".join(lines))
    errs = []
    for mode in ("on", "off"):
        out = tmp_path / mode / "sol.csv"
        rc, _, err = _run(d, out, "--stream", mode)
        assert rc != 0 and not out.parent.exists()  # nothing written, not even the folder
        errs.append(err.strip())
    assert len(errs[0].splitlines()) == 1 and f"imu.csv{message}" in errs[0], errs[0]
    assert errs[0] == errs[1]  # the whole-file reader's message
    assert sorted(p.name for p in d.iterdir()) == ["gnss.csv", "imu.csv", "run.toml"]  # no temporary file


def test_the_alignment_on_the_samples_it_read_equals_the_whole_records(car_files):
    """``Alignment.samples_used``: the alignment of the record cut one sample after them is the
    whole record's (levelling on the standstill, then the GNSS course), field for field."""
    import dataclasses

    from insnav.data.dataset import ImuData
    from insnav.io.csv_dataset import csv_inputs, initial_state
    from insnav.io.imu_csv import read_imu_csv

    d = car_files[1]
    inp = csv_inputs(d / "imu.csv", d / "gnss.csv", d / "run.toml")
    imu = read_imu_csv(d / "imu.csv", inp.fmt, week=inp.week).to_increments(inp.offset)
    a = initial_state(inp, imu, "imu.csv")[3]
    assert a.heading_source == "gnss_velocity" and 3000 < a.samples_used < len(imu.t) // 2
    k = a.samples_used + 1
    b = initial_state(inp, ImuData(imu.t[:k], imu.dtheta_b[:k], imu.dv_b[:k]), "imu.csv")[3]
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y, f.name
    # one sample fewer than it read: the alignment may differ, and says it read them all
    k = a.samples_used
    c = initial_state(inp, ImuData(imu.t[:k], imu.dtheta_b[:k], imu.dv_b[:k]), "imu.csv")[3]
    assert c.samples_used == k


def test_a_tick_log_is_read_whole_quietly_unless_asked(shared_data, tmp_path):
    """The rtklibexplorer walk (a str2str tick_ms log): --stream auto reads it whole without a
    note, --stream on says why; the files are the same."""
    d = shared_data / "rtklibexplorer_walk_0827" / "raw"
    from pathlib import Path

    toml = Path(__file__).parent / "data" / "walk_0827_loose.toml"
    errs = []
    for mode in ("auto", "on"):
        out = tmp_path / mode / "sol.csv"
        rc, _, err = _call(["run", "--format", "csv", "--imu", d / "imu_1730.csv", "--gnss", d / "gnss_1730_sf.pos",
                            "--config", toml, "--out", out, "--quiet", "--stream", mode])
        assert rc == 0, err
        errs.append([ln for ln in err.splitlines() if ln.startswith("note:")])
    assert errs == [[], ["note: the IMU file is read whole, not block by block: a str2str tick_ms log: its tick -> "
                         "GPS time map is fitted over the whole record"]]
    assert (tmp_path / "auto" / "sol.csv").read_bytes() == (tmp_path / "on" / "sol.csv").read_bytes()


@pytest.mark.parametrize("imu_offset_s", [0.0, -1.0])
def test_csv_checks_on_a_halved_record(car_files, tmp_path, monkeypatch, imu_offset_s):
    # the checks' IMU records (the whole record's and the run's, ~1100 rows at 10 Hz) limited to 200 rows,
    # so summed to 1.25 Hz (insnav.filters.stream._Coarse): clean data still stream, byte for byte; IMU
    # times 1 s early are still refused, and the message is the whole-file run's
    car, d0 = car_files
    made = []

    class Recorded(stream._Coarse):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            made.append(self)

    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    monkeypatch.setattr(stream, "CHECK_MAX_ROWS", 200)
    monkeypatch.setattr(stream, "_Coarse", Recorded)
    d = tmp_path / "in"
    d.mkdir()
    for name in ("imu.csv", "gnss.csv"):
        (d / name).write_bytes((d0 / name).read_bytes())
    (d / "run.toml").write_text(dumps_toml(config(imu=dict(time_offset_s=imu_offset_s))))
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    # (--stream auto: a failed check hands over to the whole-file run without a note, which names it)
    rca, outa, erra = _run(d, a, "--stream", "on" if imu_offset_s == 0.0 else "auto", "--output-rate", "10")
    rcb, outb, errb = _run(d, b, "--stream", "off", "--output-rate", "10")
    assert len(made) == 2 and all(c.merge > 1 and c.n <= 200 for c in made)
    if imu_offset_s == 0.0:
        assert (rca, rcb) == (0, 0) and "note:" not in erra and outa == outb
        _same_files(a, b)
    else:
        assert rca == rcb != 0 and erra == errb and "GNSS is 1.0 s behind the IMU" in erra, (erra, errb)


def _without_velocity(d0, d, every: int = 1, **run_keys):
    """The car's files in ``d`` with every ``every``-th fix and no velocity columns (position and its
    sigmas only); ``run_keys`` added to its run TOML."""
    d.mkdir()
    (d / "imu.csv").write_bytes((d0 / "imu.csv").read_bytes())
    lines = (d0 / "gnss.csv").read_text().splitlines()
    cols = ["t", "lat", "lon", "h", "sigma_n", "sigma_e", "sigma_d"]
    rows = [",".join(ln.split(",")[:4] + ln.split(",")[7:10]) for ln in lines[1:]][::every]
    (d / "gnss.csv").write_text("\n".join([",".join(cols)] + rows) + "\n")
    (d / "run.toml").write_text(dumps_toml(config(gnss=dict(columns=cols), **run_keys)))
    return d


@pytest.mark.parametrize("push_max,block", [(7, BLOCK), (1, BLOCK), (2, 21), (4096, 21)])
def test_per_speed_sigmas_of_fixes_without_velocity_stream_as_the_whole_table(car_files, tmp_path, monkeypatch,
                                                                              push_max, block):
    """gnss_pos_sigma_per_speed_s on fixes without velocity: each fix's speed comes from its
    neighbours (fix_speed_mps), so a pushed slice of fixes carries one fix of overlap on each side,
    and the central difference has one formula whatever the slice's spacing (numpy.gradient takes
    another for equal spacings: 1e-9 apart); the streamed run writes the whole-file run's bytes (it
    differed at every slice end)."""
    monkeypatch.setattr(stream, "BLOCK_LINES", block)
    monkeypatch.setattr(stream, "GNSS_PUSH_MAX", push_max)  # slices of 1, 2, 7 fixes, or as the blocks give
    d = _without_velocity(car_files[1], tmp_path / "nov", gnss_pos_sigma_per_speed_s=0.5)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    rca, outa, erra = _run(d, a, "--stream", "on")
    rcb, outb, errb = _run(d, b, "--stream", "off")
    assert (rca, rcb) == (0, 0), (erra, errb)
    assert "note:" not in erra  # streamed: the car's fixes end inside the IMU record
    _same_files(a, b)


@pytest.mark.parametrize("block", [115, 119, 169])
def test_output_rate_when_the_run_starts_at_a_blocks_end(car_files, tmp_path, monkeypatch, block):
    """The IMU interval of --output-rate comes from at least two intervals: the run's first sample may
    be the last (or last but one) of a read block, which gave decimation 1 (every row) before."""
    monkeypatch.setattr(stream, "BLOCK_LINES", block)
    d = car_files[1]
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    rca, _, erra = _run(d, a, "--stream", "on", "--output-rate", "10")
    rcb, _, errb = _run(d, b, "--stream", "off", "--output-rate", "10")
    assert (rca, rcb) == (0, 0), (erra, errb)
    _same_files(a, b)
    assert "output_decimation = 20" in (a.parent / "sol.csv.config.toml").read_text()


def test_fixes_at_1_hz_whose_alignment_reads_the_whole_imu_file_do_not_hang(car_files, tmp_path, monkeypatch):
    """1 Hz fixes: the course-over-ground start reads the whole IMU record in the alignment, and the
    run then asked the reader thread for a block after its end, waiting for ever; it ends, with the
    whole-file run's bytes."""
    import faulthandler
    import sys

    monkeypatch.setattr(stream, "BLOCK_LINES", BLOCK)
    d = _without_velocity(car_files[1], tmp_path / "onehz", every=10)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    faulthandler.dump_traceback_later(60, exit=True, file=sys.__stderr__)  # a hang fails, not blocks the suite
    try:
        rca, _, erra = _run(d, a, "--stream", "on")
    finally:
        faulthandler.cancel_dump_traceback_later()
    rcb, _, errb = _run(d, b, "--stream", "off")
    assert (rca, rcb) == (0, 0), (erra, errb)
    _same_files(a, b)
