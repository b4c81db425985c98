"""The GNSS fixes and their per-record outputs of a block-by-block run
(insnav.filters.stream, engine/loose_stream.hpp's push API): the fixes given
to the engine a block at a time and the records taken after each block equal
the batch engine's table bit for bit, for any cut (blocks without a fix,
fixes before the first IMU sample and after the last); the engine holds the
fixes of about one block, as many for 20 blocks as for 2; the innovations
sidecar written as the run goes and the health verdict from running
statistics are the whole-file run's."""
from __future__ import annotations

import math

import numpy as np
import pytest

import insnav.filters.stream as stream

from test_stream import LINES, kf_short  # noqa: F401 - the fixture
from test_stream import _run, streamed_and_whole


def _engine_inputs(kf_short, decimation=1):  # noqa: F811
    from insnav.filters._setup import imu_arrays
    from insnav.filters.loose import loose_engine_args
    from insnav.io.kfgins import read_kfgins_gnss
    from insnav.io.kfgins_dataset import load_kfgins
    from insnav.units import DEG

    ds, cfg = load_kfgins(kf_short / "kf.yaml")
    cfg.output_decimation = decimation
    t, dth, dv = imu_arrays(ds)
    g = read_kfgins_gnss(kf_short / "gnss.txt")  # every fix, those before t0 and after the IMU's end too
    gnss = np.column_stack([g.t_valid, g.lat_deg * DEG, g.lon_deg * DEG, g.h_m, g.v_n, g.sigma_pos_n, g.sigma_vel_n])
    gnss = np.ascontiguousarray(gnss)
    a = loose_engine_args(ds, cfg, gnss[gnss[:, 0] > ds.t0, 0].copy())
    return cfg, (t, dth, dv), gnss, a


def _pushed_run(core, cfg, a, imu, gnss, cuts):
    """The stream fed the IMU in blocks ending at `cuts`, each block's fixes (time <= its last sample)
    pushed before it, its records taken after it; the rest of the fixes pushed before finish().  Returns
    the stream, the rows, the records and the most fixes it held before that last push."""
    t, dth, dv = imu
    s = core.LooseStream(cfg.filter, a.layout, np.zeros((0, 13)), a.init, a.P0, a.imu_correction, a.imu_model,
                         a.config, int(np.diff(np.r_[0, cuts]).max()))
    rows, recs, pushed, i = [], [], 0, 0
    for j in cuts:
        k = int(np.searchsorted(gnss[:, 0], t[j - 1], side="right"))
        if k > pushed:
            s.push_gnss(gnss[pushed:k])
            pushed = k
        if s.run_block(t[i:j], dth[i:j], dv[i:j]):
            rows.append({key: v.copy() for key, v in s.rows().items()})
        recs.append(s.take_records())
        i = j
    window = s.max_window
    s.push_gnss(gnss[pushed:])
    if s.finish():
        rows.append({key: v.copy() for key, v in s.rows().items()})
    recs.append(s.records())
    return s, rows, recs, window


@pytest.mark.parametrize("decimation", [1, 7])
def test_fixes_pushed_block_by_block_give_the_batch_engines_records(kf_short, decimation):  # noqa: F811
    from insnav import _core

    cfg, imu, gnss, a = _engine_inputs(kf_short, decimation)
    t = imu[0]
    batch = _core.run_loose(cfg.filter, a.layout, *imu, gnss, a.init, a.P0, a.imu_correction, a.imu_model, a.config)
    rng = np.random.default_rng(11)
    # odd block sizes: from 1 sample (no fix in most blocks) to 3000 (several fixes, cut inside intervals)
    cuts = np.cumsum(rng.choice([1, 37, 199, 1013, 2999], size=400))
    cuts = np.r_[cuts[cuts < len(t)], len(t)]
    s, rows, recs, window = _pushed_run(_core, cfg, a, imu, gnss, cuts)
    for key in ("t", "llh", "v_n", "rpy", "sigma", "imu_err"):
        assert np.array_equal(np.concatenate([r[key] for r in rows]), batch[key]), key
    assert [r["first"] for r in recs] == list(np.cumsum([0] + [len(r["nis"]) for r in recs[:-1]]))
    for key in ("innovation", "nis", "log_det_s", "status"):
        assert np.array_equal(np.concatenate([r[key] for r in recs]), batch[key], equal_nan=True), key
    for key in ("updates", "rejected", "gate_reopened", "gate_outage_accepted", "cholesky_repairs"):
        assert recs[-1][key] == batch[key], key
    st = batch["status"]
    n_before = int(np.count_nonzero(gnss[:, 0] <= t[0]))
    assert n_before > 0 and np.all(st[:n_before] == 4)  # fixes before the first IMU sample: outside the span
    assert (st[n_before:] == 1).sum() > 50 and st[-1] == 4  # updates, and fixes after the last sample
    assert window <= n_before + 2999 / 200 + 2  # the fixes before t0 (the first push) or of one block


def test_the_engine_holds_as_many_fixes_for_20_blocks_as_for_2(kf_short):  # noqa: F811
    from insnav import _core

    cfg, imu, gnss, a = _engine_inputs(kf_short)
    t = imu[0]
    g_run = gnss[gnss[:, 0] > t[0]]  # the fixes after the first IMU sample (1 Hz)
    i0 = int(np.searchsorted(t, g_run[0, 0]))  # the first block ends before the first fix: it holds none
    block = 1400  # 7 s of 200 Hz samples: 7 or 8 fixes at 1 Hz
    windows = {}
    for n_blocks in (2, 20):
        j = i0 + n_blocks * block
        g = g_run[g_run[:, 0] <= t[j - 1]]  # no fix after the IMU's end: the window is the blocks' fixes
        cuts = np.arange(i0 + block, j + 1, block)
        s, _, recs, window = _pushed_run(_core, cfg, a, tuple(x[:j] for x in imu), g,
                                         np.r_[i0, cuts] if i0 > 0 else cuts)
        assert sum(len(r["nis"]) for r in recs) == len(g) and window == s.max_window
        assert (np.concatenate([r["status"] for r in recs]) == 1).sum() > 0.9 * len(g)
        windows[n_blocks] = s.max_window
    assert windows[20] == windows[2]
    assert windows[2] <= 8  # 7 or 8 fixes per block, whatever the run's length


def test_the_exact_sum_does_not_depend_on_the_blocks():
    rng = np.random.default_rng(5)
    x = rng.lognormal(0.0, 3.0, 5000) * rng.choice([1.0, 1e-8, 1e8], 5000)
    whole = math.fsum(x)
    for cuts in ([1000, 2500], list(range(7, 5000, 97))):
        partials: list = []
        for part in np.split(x, cuts):
            stream._fsum_add(partials, part)
        assert math.fsum(partials) == whole


def test_health_from_running_statistics_equals_the_whole_tables(tmp_path):
    from insnav.filters.health import assess
    from insnav.filters.solution import Solution, write_innovations

    rng = np.random.default_rng(8)
    m, n = 700, 900
    gnss_t = np.sort(rng.uniform(0.0, 800.0, m))
    status = rng.choice([0, 1, 1, 1, 2, 4], m).astype(np.int8)
    nis = np.where(status == 1, rng.chisquare(3, m) * 40.0, np.nan)  # far too optimistic: a warning text
    inn = rng.standard_normal((m, 6))
    inn[rng.random((m, 6)) < 0.3] = np.nan
    inn[status != 1] = np.nan
    t = np.linspace(0.0, 1000.0, n)  # the IMU goes on after the last record: the tail warning
    z3 = np.zeros((n, 3))
    sol = Solution(t=t, lat_deg=np.full(n, 30.0), lon_deg=np.full(n, 114.0), h_m=np.full(n, 20.0), v_n=z3,
                   roll_deg=np.zeros(n), pitch_deg=np.zeros(n), yaw_deg=np.zeros(n), sigma_pos_n_m=z3 + 1.0,
                   sigma_vel_n_mps=z3 + 0.1, sigma_att_deg=z3 + 0.1, acc_bias_mps2=z3, gyro_bias_rps=z3,
                   acc_scale=z3, gyro_scale=z3, gnss_t=gnss_t, innovation=inn, nis=nis, gnss_status=status,
                   log_det_s=np.zeros(m), gnss_sigma=np.zeros((m, 6)))
    whole = assess(sol)
    (tmp_path / "w").mkdir()
    write_innovations(sol, tmp_path / "w" / "sol.csv")
    inv = stream._Innovations(tmp_path / "s.csv")
    for a, b in zip([0, 1, 1, 350, 351], [1, 1, 350, 351, m]):  # an empty block, a one-record block
        inv.add(dict(first=a, status=status[a:b], innovation=inn[a:b], nis=nis[a:b]), gnss_t)
    inv.close()
    assert (tmp_path / "s.csv").read_bytes() == (tmp_path / "w" / "sol.csv.innovations.csv").read_bytes()
    e = np.zeros(0)
    bare = Solution(t=t, lat_deg=sol.lat_deg, lon_deg=sol.lon_deg, h_m=sol.h_m, v_n=z3, roll_deg=sol.roll_deg,
                    pitch_deg=sol.pitch_deg, yaw_deg=sol.yaw_deg, sigma_pos_n_m=sol.sigma_pos_n_m,
                    sigma_vel_n_mps=sol.sigma_vel_n_mps, sigma_att_deg=sol.sigma_att_deg, acc_bias_mps2=z3,
                    gyro_bias_rps=z3, acc_scale=z3, gyro_scale=z3, gnss_t=gnss_t, innovation=np.zeros((0, 6)),
                    nis=e, gnss_status=np.zeros(0, np.int8), log_det_s=e, gnss_sigma=np.zeros((0, 6)))
    got = assess(bare, records=inv.stats())
    assert inv.stats()["outside"] == int((status == 4).sum()) and inv.stats()["n"] == m
    assert got["nis_ratio"] == pytest.approx(whole["nis_ratio"], rel=1e-14)
    # the gate's rejections (a sixth of the records), far too optimistic, the tail
    assert whole["consistency"] == "far too optimistic" and len(whole["warnings"]) == 3
    assert whole["rejected_share"] == pytest.approx((status == 2).sum() / np.isin(status, (1, 2)).sum(), rel=1e-15)
    assert {k: v for k, v in got.items() if k not in ("nis_ratio", "warnings")} == \
        {k: v for k, v in whole.items() if k not in ("nis_ratio", "warnings")}
    assert got["warnings"][0] == whole["warnings"][0]  # the rejections: counts and share
    assert got["warnings"][2] == whole["warnings"][2]  # the tail: the last applied record's time
    assert f"{got['nis_ratio']:.3g}" == f"{whole['nis_ratio']:.3g}"


@pytest.mark.parametrize("block, extra", [(97, ()), (1013, ("--output-rate", "10")),
                                          (2999, ("--out-format", "kfgins"))])
def test_streamed_sidecar_and_report_are_the_whole_runs(kf_short, tmp_path, monkeypatch, block, extra):  # noqa: F811
    # blocks of 97 lines (0.485 s: most hold no fix), 1013 and 2999 (cut inside GNSS intervals); the
    # fixes before starttime and after the IMU's end are in the GNSS file (kf_short)
    from insnav import _core

    made = []
    real = _core.LooseStream

    def spy(*args):
        s = real(*args)
        made.append(s)
        return s

    monkeypatch.setattr(stream, "BLOCK_LINES", block)
    monkeypatch.setattr(stream._core, "LooseStream", spy)
    kf = "--out-format" in extra
    a = tmp_path / "a" / ("kf" if kf else "sol.csv")
    b = tmp_path / "b" / ("kf" if kf else "sol.csv")
    streamed_and_whole(_run, kf_short, a, b, *extra)
    base = "KF_GINS_Navresult.nav" if kf else "sol.csv"
    da, db = (a, b) if kf else (a.parent, b.parent)
    for suffix in ("", ".innovations.csv", ".config.toml"):
        assert (da / (base + suffix)).read_bytes() == (db / (base + suffix)).read_bytes(), suffix
    assert not [p for p in da.iterdir() if ".part" in p.name]
    fixes = (db / (base + ".innovations.csv")).read_text().count("\n") - 1
    assert len(made) == 1 and fixes > 100
    assert made[0].max_window <= block / 200 + 2  # 1 Hz fixes: those of one block, never the run's


def _kf_copy(kf_short, d, edit):  # noqa: F811
    """kf_short's files in folder ``d``, the GNSS file's lines (1-based list index + 1) changed by ``edit``."""
    d.mkdir()
    for f in ("imu.txt", "kf.yaml"):
        (d / f).write_bytes((kf_short / f).read_bytes())
    lines = (kf_short / "gnss.txt").read_text().splitlines(keepends=True)
    (d / "gnss.txt").write_text("".join(edit(lines)))
    return d


def test_streamed_run_of_an_unordered_gnss_file_writes_the_whole_runs_bytes(kf_short, tmp_path, monkeypatch):  # noqa: F811
    # blocks of 4093 lines (20.465 s): the fixes of lines 103 and 104 (456352 s, 456353 s) on either side of
    # the boundary at 456352.3 s swapped, and a fix before starttime (line 10) moved after line 150: the
    # sanitizer reorders them (copies of the fixes, not views of the file's)
    def edit(lines):
        lines = list(lines)
        lines[102], lines[103] = lines[103], lines[102]
        early = lines.pop(9)
        return lines[:149] + [early] + lines[149:]

    d = _kf_copy(kf_short, tmp_path / "kf", edit)
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    erra, errb = streamed_and_whole(_run, d, a, b)
    for suffix in ("", ".innovations.csv", ".config.toml"):
        assert (a.parent / (a.name + suffix)).read_bytes() == (b.parent / (b.name + suffix)).read_bytes(), suffix
    assert erra == errb
    fixes = (a.parent / (a.name + ".innovations.csv")).read_text().splitlines()[1:]
    t = np.array([float(ln.split(",")[0]) for ln in fixes])
    assert len(t) == 149 and t[0] == 456301.0 and np.all(np.diff(t) == 1.0)  # 456301 .. 456449 s, in order


def test_a_bad_gnss_line_in_a_late_block_gives_the_whole_file_runs_error(kf_short, tmp_path, monkeypatch):  # noqa: F811
    def edit(lines):  # line 190 (456439 s, in the last of ten 4093-line blocks): a longitude that is no number
        lines = list(lines)
        f = lines[189].split(" ")
        lines[189] = " ".join(f[:2] + ["114.47x"] + f[3:])
        return lines

    d = _kf_copy(kf_short, tmp_path / "kf", edit)
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    rca, _, erra = _run(d, tmp_path / "a" / "sol.csv", "--stream", "on")
    rcb, _, errb = _run(d, tmp_path / "b" / "sol.csv", "--stream", "off")
    assert rca == rcb != 0
    assert erra == errb and len(erra.strip().splitlines()) == 1
    assert "gnss.txt:190" in erra
    assert not (tmp_path / "a" / "sol.csv").exists()


def test_compact_gnss_reader_holds_the_same_fixes(kf_short):  # noqa: F811
    from insnav.io.kfgins import read_kfgins_gnss

    full = read_kfgins_gnss(kf_short / "gnss.txt")
    compact = read_kfgins_gnss(kf_short / "gnss.txt", compact=True)
    for f in stream._GNSS_FIELDS:
        assert np.array_equal(getattr(full, f), getattr(compact, f), equal_nan=True), f
    assert compact.t_arrival is compact.t_valid and not compact.v_n.flags.writeable
    held = sum(np.asarray(getattr(compact, f)).base is None and getattr(compact, f).nbytes or 0
               for f in ("t_valid", "lat_deg", "lon_deg", "h_m", "sigma_pos_n"))
    assert held == 7 * 8 * len(full)  # 7 float64 per fix (the NaN velocity columns: one row)
    cut = stream._gnss_take(compact, (compact.t_valid > 456300.0) & (compact.t_valid <= 456400.0))
    assert len(cut) == 100 and np.shares_memory(cut.lat_deg, compact.lat_deg)
    assert cut.origin.line(0) == 52 and cut.origin.where(99) == f"{kf_short / 'gnss.txt'}:151"


@pytest.mark.parametrize("block_lines", [1, 7, 4096])
def test_gnss_file_read_in_blocks_equals_the_whole_file_reader(kf_short, tmp_path, block_lines):  # noqa: F811
    """read_gnss_text_blocks (two passes, ``block_lines`` lines parsed at a time) against the whole-file
    reader: the same fixes and file lines (blank lines inside, no final line end, 13 columns), and the
    same one-line error naming the file and line for a malformed line in the last block, a non-finite
    time before it (the malformed line's message first, as whole), a short row and a bad first line."""
    from insnav.io.kfgins import read_kfgins_gnss

    src = (kf_short / "gnss.txt").read_text().splitlines(keepends=True)
    bad = list(src)
    bad[3000] = bad[3000].replace("114.", "11x4.", 1)
    nan_and_bad = list(bad)
    nan_and_bad[20] = "nan" + src[20][10:]
    short = list(src)
    short[1500] = " ".join(short[1500].split()[:6]) + "\n"
    cases = {"blank": src[:50] + ["\n", "   \n"] + src[50:] + ["\n"], "no_end": src[:-1] + [src[-1].rstrip("\n")],
             "v13": [ln.rstrip("\n") + " 0.1 0.2 0.3 0.01 0.01 0.02\n" for ln in src[:300]],
             "bad": bad, "nan_and_bad": nan_and_bad, "short": short, "cols5": ["1 2 3 4 5\n"] + src, "empty": []}
    errors = {}
    for name, lines in cases.items():
        f = tmp_path / f"{name}.txt"
        f.write_text("".join(lines))
        try:
            whole = read_kfgins_gnss(f, compact=True)
        except ValueError as exc:
            with pytest.raises(ValueError) as got:
                stream.read_gnss_text_blocks(f, block_lines=block_lines)
            assert str(got.value) == str(exc)
            errors[name] = str(exc).split(": ")[0].rsplit(":", 1)[1]  # the line named
            continue
        blocks = stream.read_gnss_text_blocks(f, block_lines=block_lines)
        for fld in stream._GNSS_FIELDS:
            assert np.array_equal(getattr(blocks, fld), getattr(whole, fld), equal_nan=True), (name, fld)
        assert [blocks.origin.line(i) for i in range(len(whole))] == \
            [whole.origin.line(i) for i in range(len(whole))]
    assert errors == {"bad": "3001", "nan_and_bad": "3001", "short": "1501", "cols5": "1", "empty": "1"}


def test_gnss_file_that_grows_between_the_two_passes_is_refused(tmp_path, monkeypatch):
    """A GNSS file with more lines in the second pass than the first counted (it grew in between) gets
    a one-line error naming the file and line, not a shape error or a silently cut table."""
    import insnav.io.text_blocks as tb

    f = tmp_path / "gnss.txt"
    f.write_text("".join(f"{100.0 + i:.1f} 30.5 114.3 20.0 0.01 0.01 0.02\n" for i in range(50)))
    assert len(tb.read_gnss_text_blocks(f, block_lines=7).t_valid) == 50
    monkeypatch.setattr(tb, "count_lines", lambda p: 20)  # the first pass saw 20 lines
    with pytest.raises(ValueError, match=r"gnss\.txt:\d+: the file changed while it was read .*20\)"):
        tb.read_gnss_text_blocks(f, block_lines=7)


def test_dropped_fixes_on_the_sanitizers_block_boundaries_give_the_whole_runs_bytes(kf_short, tmp_path, monkeypatch):  # noqa: F811
    # the GNSS sanitizer a block of 7 fixes at a time (sanitize_gnss_blocks; the fixes after starttime from line
    # 52, so its blocks begin at lines 52, 59, 66, ...): a non-finite height on the last line of a block (58),
    # a repeated time on the first line of the next-but-one (66 repeats 65), a latitude out of range (100): the
    # stream's fixes, report and files are the whole-file run's
    import insnav.filters.sanitize as sanitize

    def edit(lines):
        lines = list(lines)
        f = lines[57].split(" ")
        lines[57] = " ".join(f[:3] + ["nan"] + f[4:])
        f = lines[65].split(" ")
        lines[65] = " ".join([lines[64].split(" ")[0]] + f[1:])
        f = lines[99].split(" ")
        lines[99] = " ".join([f[0], "95.0"] + f[2:])
        return lines

    d = _kf_copy(kf_short, tmp_path / "kf", edit)
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    monkeypatch.setattr(sanitize, "GNSS_SANITIZE_BLOCK", 7)
    seen = []
    real = sanitize.sanitize_gnss_blocks
    monkeypatch.setattr(sanitize, "sanitize_gnss_blocks", lambda g, **kw: seen.append(real(g, **kw)) or seen[-1])
    a, b = tmp_path / "a" / "sol.csv", tmp_path / "b" / "sol.csv"
    erra, errb = streamed_and_whole(_run, d, a, b)
    assert erra == errb
    for suffix in ("", ".innovations.csv", ".config.toml"):
        assert (a.parent / (a.name + suffix)).read_bytes() == (b.parent / (b.name + suffix)).read_bytes(), suffix
    rep = seen[0][1]
    assert rep["gnss_invalid_dropped"] == 2 and rep["gnss_duplicates_dropped"] == 1
    assert rep["gnss_dropped_lines"] == [58, 66, 100]

