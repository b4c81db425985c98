"""Saved solutions: CSV / npz / Parquet round trips through load_solution,
the innovations sidecar, old column names, and clear errors."""
from __future__ import annotations

import sys

import numpy as np
import pytest

import insnav
from conftest import require_module, short_tight_dataset
from insnav.filters.solution import (INNOVATION_COLUMNS, RESIDUAL_COLUMNS, RESIDUAL_COLUMNS_FLAGS, RecordStatus, innovations_path,
                                     load_solution, read_innovations, read_residuals, residuals_path,
                                     write_innovations)


@pytest.fixture(scope="module")
def sol():
    ds = insnav.simulate("seed001-low", seed=2)
    return insnav.run(ds, "ekf", layout=21, gate_chi2=30.0)


def _nav(s):
    return s.to_array()


def test_csv_round_trip_to_the_printed_digits(sol, tmp_path):
    from insnav.filters.solution import CSV_DECIMALS

    p = sol.save(tmp_path / "sol.csv")
    back = load_solution(p)
    a, b = _nav(sol), _nav(back)
    # each column rounded to its resolution: at most half a unit of its last decimal apart
    tol = 0.5 * 10.0 ** -np.array([CSV_DECIMALS[c] for c in sol.COLUMNS])
    assert np.all(np.abs(a - b) <= tol * (1 + 1e-9) + 2e-16 * np.abs(a))
    assert back.COLUMNS == sol.COLUMNS and tuple(p.read_text().splitlines()[0].split(",")) == sol.COLUMNS


def test_csv_text_is_the_correctly_rounded_value(sol, tmp_path):
    """Every printed value is printf's correctly rounded "%.{d}f" of the value,
    trailing zeros dropped (the C++ writer's integer fast path and its
    fallback, checked against Python's formatting on real rows)."""
    from insnav.filters.solution import CSV_DECIMALS

    p = sol.save(tmp_path / "sol.csv")
    rows = p.read_text().splitlines()[1:]
    a = _nav(sol)
    step = max(1, len(rows) // 400)
    for i in range(0, len(rows), step):
        for tok, v, name in zip(rows[i].split(","), a[i], sol.COLUMNS):
            d = CSV_DECIMALS[name]
            want = f"{v:.{d}f}".rstrip("0").rstrip(".") if d else f"{v:.0f}"
            assert tok == ("0" if want == "-0" else want), (i, name, v, tok)


def test_csv_exact_precision_round_trips_bit_for_bit(sol, tmp_path):
    p = sol.save(tmp_path / "sol.csv", precision="exact")
    np.testing.assert_array_equal(_nav(load_solution(p))[:, :10], _nav(sol)[:, :10])
    from insnav.filters.solution import _columns_from

    np.testing.assert_array_equal(np.column_stack(list(_columns_from(p).values())), _nav(sol))


def test_column_groups(sol, tmp_path):
    p = sol.save(tmp_path / "nav.npz", columns=["nav"])
    back = load_solution(p)
    np.testing.assert_array_equal(back.lat_deg, sol.lat_deg)
    assert np.isnan(back.sigma_pos_n_m).all() and np.isnan(back.acc_bias_mps2).all()
    q = sol.save(tmp_path / "nb.csv", columns=("nav", "bias"))
    assert q.read_text().splitlines()[0].split(",") == list(sol.COLUMNS[:10] + sol.COLUMNS[19:])
    with pytest.raises(ValueError, match="unknown column group 'sigmas'"):
        sol.save(tmp_path / "x.csv", columns=["sigmas"])


@pytest.mark.parametrize("suffix", [".npz", ".parquet"])
def test_binary_round_trip_is_exact(sol, tmp_path, suffix):
    if suffix == ".parquet":
        require_module("pyarrow", "parquet")
    path = sol.save(tmp_path / f"sol{suffix}")
    from insnav.filters.solution import _columns_from

    cols = _columns_from(path)  # the stored columns: bit for bit what was written
    assert tuple(cols) == sol.COLUMNS
    np.testing.assert_array_equal(np.column_stack(list(cols.values())), _nav(sol))
    back = load_solution(path)  # the unit conversions back to SI (deg/h, ppm) cost at most an ulp or two
    np.testing.assert_array_equal(back.lat_deg, sol.lat_deg)
    np.testing.assert_array_equal(back.v_n, sol.v_n)
    np.testing.assert_allclose(back.gyro_bias_rps, sol.gyro_bias_rps, rtol=1e-15, atol=0)
    assert not list(tmp_path.glob("*.part*"))  # no temp file left


def test_npz_is_a_valid_zip_with_what_np_savez_stores(sol, tmp_path, monkeypatch):
    """The direct .npz writer (members at computed offsets, two threads) and its
    zipfile fallback for files beyond the classic zip limits store the same
    members, with checksums zipfile verifies, bit for bit np.savez's."""
    import zipfile

    import insnav._npz as npz

    fast = sol.save(tmp_path / "fast.npz")
    monkeypatch.setattr(npz, "_MAX_OFFSET", 1000)  # as if the file were 4 GiB: the ZIP64 path
    slow = sol.save(tmp_path / "slow.npz")
    cols = sol.to_array()
    np.savez(tmp_path / "ref.npz", **{name: cols[:, j] for j, name in enumerate(sol.COLUMNS)})
    with zipfile.ZipFile(fast) as a, zipfile.ZipFile(slow) as b, zipfile.ZipFile(tmp_path / "ref.npz") as r:
        assert a.testzip() is None and b.testzip() is None
        assert a.namelist() == b.namelist() == [c + ".npy" for c in sol.COLUMNS]
        for name in r.namelist():
            assert a.read(name) == b.read(name) == r.read(name), name


def test_writers_overwrite_a_longer_file_to_the_exact_new_length(sol, tmp_path):
    """The npz and text writers open without truncating (no flush on close on
    ext4); a longer file already at the path is cut to what was written."""
    import zipfile

    from insnav import _core
    from insnav._npz import write_npz

    x = np.arange(1000.0)
    (tmp_path / "a.npz").write_bytes(b"\xff" * 100_000)
    for name in ("a.npz", "fresh.npz"):
        write_npz(tmp_path / name, [("x", x, 1.0), ("y", x[::-1], 2.0)])
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "fresh.npz").read_bytes()
    assert (tmp_path / "a.npz").stat().st_size < 20_000
    with zipfile.ZipFile(tmp_path / "a.npz") as z, np.load(tmp_path / "a.npz") as a:
        assert z.testzip() is None
        np.testing.assert_array_equal(a["y"], 2.0 * x[::-1])
    txt = tmp_path / "t.csv"
    txt.write_text("9" * 50_000)
    assert _core.write_table(str(txt), "x\n", [x[:3]], [1.0], [1], ",", 0, True, False, 1) == 8
    assert txt.read_text() == "x\n0\n1\n2\n"


def test_innovations_sidecar_round_trip(sol, tmp_path):
    p = sol.save(tmp_path / "sol.npz")
    side = write_innovations(sol, p)
    assert side == innovations_path(p) and side.name == "sol.npz.innovations.csv"
    assert tuple(side.read_text().splitlines()[0].split(",")) == INNOVATION_COLUMNS
    back = load_solution(p)
    np.testing.assert_allclose(back.gnss_t, sol.gnss_t, atol=5e-7)
    np.testing.assert_array_equal(back.gnss_status, sol.gnss_status)
    ok = np.isfinite(sol.nis)
    np.testing.assert_allclose(back.nis[ok], sol.nis[ok], rtol=1e-5)
    fin = np.isfinite(sol.innovation)
    np.testing.assert_array_equal(np.isfinite(back.innovation), fin)
    np.testing.assert_allclose(back.innovation[fin], sol.innovation[fin], rtol=1e-5, atol=1e-9)
    # applied records: the NIS of a consistent filter averages about the row count (6 here)
    applied = back.gnss_status == RecordStatus.APPLIED
    assert applied.sum() > 100 and 3.0 < np.mean(back.nis[applied]) < 12.0
    # the human-readable columns agree with the codes; rows = finite innovation components
    inn = read_innovations(side)
    assert list(inn["status_name"]) == [RecordStatus(c).name.lower() for c in sol.gnss_status]
    np.testing.assert_array_equal(inn["applied"], sol.gnss_status == RecordStatus.APPLIED)
    np.testing.assert_array_equal(inn["rows"], np.isfinite(sol.innovation).sum(axis=1))
    lines = side.read_text().splitlines()
    assert {ln.rsplit(",", 1)[1] for ln in lines[1:]} >= {"applied"} and "nan" not in side.read_text()


def test_sidecar_of_an_earlier_version_and_bad_sidecars(sol, tmp_path):
    p = sol.save(tmp_path / "sol.csv")
    side = write_innovations(sol, p)
    text = side.read_text().splitlines()
    old = [text[0].rsplit(",", 1)[0]] + [ln.rsplit(",", 1)[0] for ln in text[1:]]  # no status_name column
    side.write_text("\n".join(old) + "\n")
    inn = read_innovations(side)
    assert list(inn["status_name"]) == [RecordStatus(c).name.lower() for c in sol.gnss_status]
    bad = list(text)
    code, name = bad[3].split(",")[1], bad[3].rsplit(",", 1)[1]
    bad[3] = bad[3][: -len(name)] + ("not_used" if name != "not_used" else "applied")
    side.write_text("\n".join(bad) + "\n")
    with pytest.raises(ValueError, match=rf"sol.csv.innovations.csv:4: status {code} is"):
        read_innovations(side)
    side.write_text("t,nis\n1,2\n")
    with pytest.raises(ValueError, match=r"innovations.csv:1: unexpected header"):
        load_solution(p)


def test_tight_sidecar_and_per_satellite_residuals(tmp_path):
    """Tight: one sidecar row per epoch with the core's row count, which is the
    number of finite residuals (pseudorange and rate per satellite) of that
    epoch in the per-satellite file; the residuals round-trip to the printed digits."""
    ds = short_tight_dataset()
    sol = insnav.run(ds, filter="ekf", coupling="tight", init_seed=0, output_decimation=10)
    p = sol.save(tmp_path / "tight.npz")
    side = write_innovations(sol, p)
    inn = read_innovations(side)
    np.testing.assert_array_equal(inn["rows"], sol.rows)
    np.testing.assert_array_equal(inn["status"], sol.gnss_status)
    assert np.isnan(inn["innovation"]).all()  # the loose columns are empty for tight
    res = read_residuals(residuals_path(p))
    assert tuple(residuals_path(p).read_text().splitlines()[0].split(",")) == RESIDUAL_COLUMNS_FLAGS
    assert RESIDUAL_COLUMNS_FLAGS[:len(RESIDUAL_COLUMNS)] == RESIDUAL_COLUMNS
    inputs = sol.inputs
    np.testing.assert_array_equal(res["system"], 0)  # GPS
    np.testing.assert_array_equal(np.column_stack([res["pseudorange_flag"], res["rate_flag"]]), sol.sat_flag)
    # a file without the flag columns (written before them) still reads
    old = residuals_path(p).read_text().splitlines()
    residuals_path(p).write_text("\n".join([",".join(RESIDUAL_COLUMNS)] + [ln.rsplit(",", 3)[0] for ln in old[1:]])
                                 + "\n")
    assert "system" not in read_residuals(residuals_path(p))
    res = dict(read_residuals(residuals_path(p)), system=res["system"])
    assert len(res["prn"]) == len(inputs.prn) > 0
    np.testing.assert_array_equal(res["prn"], inputs.prn)
    per_epoch = np.add.reduceat(np.isfinite(res["pseudorange_residual_m"]).astype(int)
                                + np.isfinite(res["rate_residual_mps"]), inputs.epoch_start[:-1])
    applied = sol.gnss_status == RecordStatus.APPLIED
    assert applied.sum() > 100
    np.testing.assert_array_equal(per_epoch[applied], sol.rows[applied])
    np.testing.assert_allclose(res["t_s"], np.repeat(inputs.epoch_t, np.diff(inputs.epoch_start)), atol=5e-7)
    fin = np.isfinite(sol.innovation)
    np.testing.assert_allclose(np.column_stack([res["pseudorange_residual_m"], res["rate_residual_mps"]])[fin],
                               sol.innovation[fin], rtol=5e-6, atol=1e-9)
    # NIS of a consistent tight EKF: about its row count (16 here) on average
    assert 0.5 < np.mean(inn["nis"][applied]) / np.mean(inn["rows"][applied]) < 1.5


def test_old_column_names_are_accepted(sol, tmp_path):
    p = sol.save(tmp_path / "new.csv")
    lines = p.read_text().splitlines()
    old = lines[0].replace("t_s,", "t,").replace("vn_mps,ve_mps,vd_mps", "vn,ve,vd")
    q = tmp_path / "old.csv"
    q.write_text("\n".join([old] + lines[1:]) + "\n")
    np.testing.assert_array_equal(_nav(load_solution(q)), _nav(load_solution(p)))


def test_bad_files_name_the_file(sol, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.csv"):
        load_solution(tmp_path / "nope.csv")
    bad = tmp_path / "imu.csv"
    bad.write_text("t_s,dtheta_x_rad\n0.1,0.0\n")
    with pytest.raises(ValueError, match=r"imu.csv:1: not an insnav solution.*lat_deg"):
        load_solution(bad)
    with pytest.raises(ValueError, match=r"unknown solution format '\.txt'"):
        sol.save(tmp_path / "x.txt")


def test_to_dataframe_names_the_extra_without_pandas(sol, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match=r"insnav\[pandas\]"):
        sol.to_dataframe()


def test_to_dataframe_hands_pandas_the_unit_named_columns(sol, monkeypatch):
    """With pandas present (a stand-in here: pandas is optional), the frame gets
    the file's columns and the file's units (gyro bias in deg/h)."""
    import types

    seen = {}

    def frame(data, columns):
        seen.update(data=data, columns=columns)
        return "frame"

    monkeypatch.setitem(sys.modules, "pandas", types.SimpleNamespace(DataFrame=frame))
    assert sol.to_dataframe() == "frame"
    assert tuple(seen["columns"]) == sol.COLUMNS and seen["data"].shape == (len(sol), len(sol.COLUMNS))
    j = sol.COLUMNS.index("gyro_bias_x_dph")
    np.testing.assert_allclose(seen["data"][:, j], np.rad2deg(sol.gyro_bias_rps[:, 0]) * 3600.0)


def test_parquet_without_pyarrow_names_the_extra(sol, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    for call in (lambda: sol.save(tmp_path / "s.parquet"), lambda: load_solution(tmp_path / "s.parquet")):
        (tmp_path / "s.parquet").write_bytes(b"PAR1")
        with pytest.raises(ImportError, match=r"^Parquet needs pyarrow: pip install 'insnav\[parquet\]'") as e:
            call()
        assert "\n" not in str(e.value)
    assert not list(tmp_path.glob("*.part*"))


def test_load_solution_is_public_and_lazy():
    import subprocess

    code = ("import sys, insnav; assert 'insnav.filters.solution' not in sys.modules; "
            "f = insnav.load_solution; assert f.__module__ == 'insnav.filters.solution'; print('ok')")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr
