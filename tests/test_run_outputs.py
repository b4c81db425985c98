"""``insnav run`` output options: --output-rate (decimated rows are exactly
every k-th row of the full output while the filter runs at every sample),
--columns, and --out-format kfgins (KF-GINS's own result layout)."""
from __future__ import annotations

import lzma

import numpy as np
import pytest

import insnav
from insnav.io.kfgins import KFGINS_IMU_ERR_FILE, KFGINS_NAV_FILE, KFGINS_STD_FILE

from test_cli import _call, _user_error


@pytest.fixture(scope="module")
def ds_dir(tmp_path_factory):
    ds = insnav.simulate("seed000-sim", seed=2)
    return ds.save(tmp_path_factory.mktemp("outputs") / "ds")


@pytest.fixture(scope="module")
def full(ds_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("full") / "full.npz"
    rc, _, err = _call(["run", ds_dir, "--filter", "ekf", "--out", out])
    assert rc == 0, err
    return insnav.load_solution(out)


def _every_kth(sol, k):
    """Rows k-1, 2k-1, ... of the full output, and its last row."""
    idx = np.arange(k - 1, len(sol), k)
    if idx[-1] != len(sol) - 1:
        idx = np.append(idx, len(sol) - 1)
    return sol.to_array()[idx]


@pytest.mark.parametrize("rate_hz, k", [(10, 20), (1, 200), (200, 1)])
def test_output_rate_is_every_kth_row_of_the_full_output(ds_dir, full, tmp_path, rate_hz, k):
    out = tmp_path / f"dec{rate_hz}.npz"
    rc, stdout, err = _call(["run", ds_dir, "--filter", "ekf", "--output-rate", rate_hz, "--out", out])
    assert rc == 0, err
    dec = insnav.load_solution(out)
    np.testing.assert_array_equal(dec.to_array(), _every_kth(full, k))  # bit for bit: the filter ran every sample
    if k == 20:  # 200 Hz IMU from t = 0: rows at whole tenths of a second
        np.testing.assert_allclose(dec.t[:-1], 0.1 * np.arange(1, len(dec)), atol=1e-9)


def test_output_rate_must_divide_the_imu_rate(ds_dir, tmp_path):
    _user_error(["run", ds_dir, "--output-rate", 7, "--out", tmp_path / "x.csv"], "--output-rate 7",
                "200 Hz", "10")
    _user_error(["run", ds_dir, "--output-rate", -1, "--out", tmp_path / "x.csv"], "--output-rate")
    assert not list(tmp_path.iterdir())


def test_columns_choose_the_groups(ds_dir, full, tmp_path):
    out = tmp_path / "nav_sigma.csv"
    rc, _, err = _call(["run", ds_dir, "--filter", "ekf", "--columns", "nav,sigma", "--output-rate", 1,
                        "--out", out])
    assert rc == 0, err
    header = out.read_text().splitlines()[0].split(",")
    assert header == list(insnav.Solution.COLUMNS[:19])
    back = insnav.load_solution(out)
    np.testing.assert_allclose(back.lat_deg, _every_kth(full, 200)[:, 1], atol=5e-12, rtol=0)
    assert np.isnan(back.acc_bias_mps2).all()
    _user_error(["run", ds_dir, "--columns", "nav,biases", "--out", tmp_path / "y.csv"], "--columns", "'biases'")


def _kfgins_line(values) -> str:
    """One line as KF-GINS's FileSaver writes it: every value "%-15.9lf " (src/fileio/filesaver.cc)."""
    return "".join(f"{v:<15.9f} " for v in values)


def test_out_format_kfgins_writes_kfgins_files(ds_dir, full, tmp_path):
    out = tmp_path / "kf"
    rc, _, err = _call(["run", ds_dir, "--filter", "ekf", "--out-format", "kfgins", "--output-rate", 10,
                        "--out", out])
    assert rc == 0, err
    ref = _every_kth(full, 20)
    nav = (out / KFGINS_NAV_FILE).read_text().split("\n")
    imu_err = (out / KFGINS_IMU_ERR_FILE).read_text().split("\n")
    assert nav[-1] == "" and imu_err[-1] == "" and len(nav) - 1 == len(ref) == len(imu_err) - 1
    deg_h, mgal = 180.0 / np.pi * 3600.0, 1e5
    for i in (0, 1, len(ref) // 2, len(ref) - 1):
        r = ref[i]  # t, lat, lon, h, v, rpy, sigmas(9), acc bias [m/s^2], gyro bias [deg/h], acc, gyro scale [ppm]
        assert nav[i] == _kfgins_line([0.0, *r[0:10]])
        assert imu_err[i] == _kfgins_line([r[0], *r[22:25], *(r[19:22] * mgal), *r[28:31], *r[25:28]])
    back = np.loadtxt(out / KFGINS_IMU_ERR_FILE)
    assert np.abs(back[-1, 1:4] - full.gyro_bias_rps[-1] * deg_h).max() < 1e-8  # the biases, not zeros
    assert np.abs(back[-1, 1:4]).max() > 0 and np.abs(back[-1, 4:7]).max() > 0
    _user_error(["run", ds_dir, "--out-format", "kfgins", "--columns", "nav", "--out", tmp_path / "kf2"],
                "--columns")


def test_kfgins_std_file_holds_the_filter_sigmas(ds_dir, tmp_path):
    """KF_GINS_STD.txt: t, 1-sigma position [m], velocity [m/s], attitude [deg],
    gyro bias [deg/h], accelerometer bias [mGal], gyro and accelerometer scale
    [ppm] (22 columns, KF-GINS's writeSTD), the same numbers as the API's
    sqrt(diag P) rows; the bias sigmas start at the IMU model's and shrink as
    GNSS makes them observable; a 15-state run estimates no scale factor (0)."""
    out = tmp_path / "kf"
    rc, _, err = _call(["run", ds_dir, "--filter", "ekf", "--out-format", "kfgins", "--output-rate", 10,
                        "--out", out])
    assert rc == 0, err
    lines = (out / KFGINS_STD_FILE).read_text().split("\n")
    ds = insnav.load_dataset(ds_dir)
    sol = insnav.run(ds, filter="ekf", imu_error_sigmas=True, output_decimation=20)
    assert sol.sigma_imu_err.shape == (len(sol), 12) and len(lines) - 1 == len(sol)
    deg_h, mgal = 180.0 / np.pi * 3600.0, 1e5
    se = sol.sigma_imu_err
    for i in (0, len(sol) // 2, len(sol) - 1):
        assert lines[i] == _kfgins_line([sol.t[i], *sol.sigma_pos_n_m[i], *sol.sigma_vel_n_mps[i],
                                         *sol.sigma_att_deg[i], *(se[i, 3:6] * deg_h), *(se[i, 0:3] * mgal),
                                         *(se[i, 9:12] * 1e6), *(se[i, 6:9] * 1e6)])
    back = np.loadtxt(out / KFGINS_STD_FILE)
    assert back.shape == (len(sol), 22)
    model = ds.imu_model  # the run's initial bias sigmas: the model's total bias sigmas
    np.testing.assert_allclose(se[0, 0:3], model["accel_bias_total_sigma"], rtol=0.02)
    np.testing.assert_allclose(se[0, 3:6], model["gyro_bias_total_sigma"], rtol=0.02)
    assert (se[-1, 0:6] < se[0, 0:6]).all()  # GNSS updates made every bias observable, a little
    assert (back[:, 16:22] == 0).all()        # 15 states: no scale factors estimated


def test_kfgins_layout_matches_kfgins_own_output(shared_data):
    """The shared KF-GINS result file (KF-GINS f39bc2e on the simulated track)
    follows the same "%-15.9lf " rule line for line."""
    p = shared_data / "kfgins" / "sim" / "kfgins_results" / "KF_GINS_Navresult_fullGNSS_10Hz.nav.xz"
    if not p.is_file():
        pytest.skip(f"{p} not available")
    with lzma.open(p, "rt") as f:
        lines = [f.readline().rstrip("\n") for _ in range(200)]
    for ln in lines:
        vals = [float(x) for x in ln.split()]
        assert len(vals) == 11 and ln == _kfgins_line(vals)
