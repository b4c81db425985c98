"""Saved solutions: CSV / npz / Parquet round trips through load_solution,
the innovations sidecar, old column names, and clear errors."""
from __future__ import annotations

import sys

import numpy as np
import pytest

import insnav
from insnav.filters.solution import (INNOVATION_COLUMNS, RecordStatus, innovations_path, load_solution,
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
        pytest.importorskip("pyarrow", reason="Parquet needs pyarrow (pip install 'insnav[parquet]')")
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
