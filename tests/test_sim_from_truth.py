"""IMU synthesised from a sampled truth file (insnav.sim.from_truth) on the Spirent dynamic rover.

The check of an IMU synthesised from a trajectory is free-inertial navigation: exact increments
integrated by the strapdown mechanization from the true initial state must follow the truth
(Groves 2013, sec. 5.5; GTSAM's ScenarioRunner tests do the same).
"""
import subprocess
import sys

import numpy as np
import pytest

from insnav import earth, mechanize
from insnav.sim.from_truth import (TruthFileError, TruthInterpolant, read_spirent_motion, simulate_from_truth)

from conftest import SHARED_DATA

MOTION = SHARED_DATA / "instinct_spirent_rtk_dynamic_SIMULATED" / "Rover-dynamic_motion_Spirent.csv"


def need(p):
    if not p.exists():
        pytest.skip(f"shared data not available: {p} (set INSNAV_SHARED_DATA or put ../shared/data beside the repo)")
    return p


@pytest.fixture(scope="module")
def exact():
    return simulate_from_truth(need(MOTION), "exact", imu_rate_hz=100.0)


def _ecef(lat_deg, lon_deg, h):
    """(N, 3) ECEF [m]."""
    return np.asarray(earth.geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), h)).reshape(-1, 3)


def test_free_inertial_with_exact_imu_follows_truth(exact):
    # 600 s of free-inertial navigation with the exact IMU: drift measured 0.46 mm (100 Hz,
    # two-sample coning/sculling); the bound is 5 mm
    ds = exact
    tr = ds.truth
    traj = mechanize(ds.imu.t, ds.imu.dtheta_b, ds.imu.dv_b, ds.initial, t0=ds.t0)
    k = np.searchsorted(traj.t, tr.t - 1e-9)
    ok = (k < traj.t.size) & (tr.t > ds.t0 + 1e-9)  # rows after the initial state
    assert np.all(np.abs(traj.t[k[ok]] - tr.t[ok]) < 1e-9)
    err = np.linalg.norm(_ecef(traj.lat_deg[k[ok]], traj.lon_deg[k[ok]], traj.h_m[k[ok]])
                         - _ecef(tr.lat_deg[ok], tr.lon_deg[ok], tr.h_m[ok]), axis=1)
    assert tr.t[ok][-1] - tr.t[0] >= 600.0
    assert err.max() < 5e-3
    assert np.abs(traj.v_n[k[ok]] - tr.v_n[ok]).max() < 1e-5
    dyaw = (traj.yaw_deg[k[ok]] - tr.yaw_deg[ok] + 180.0) % 360.0 - 180.0
    assert np.abs(dyaw).max() < 1e-6


def test_interpolant_reproduces_the_file_at_its_epochs():
    tf = read_spirent_motion(need(MOTION))
    it = TruthInterpolant(tf)
    r, v, a = it.position(tf.t_s)
    assert np.abs(r - tf.r_e).max() < 1e-6
    assert np.abs(v - tf.v_e).max() < 1e-9
    assert np.abs(a - tf.a_e).max() < 1e-9
    # continuity of the quintic across a knot (C2): values just left and right of t_k agree
    tk = tf.t_s[100]
    rl, vl, al = it.position(np.array([tk - 1e-7]))
    rr, vr, ar = it.position(np.array([tk + 1e-7]))
    assert np.abs(al - ar).max() < 1e-4
    eul, _ = it.attitude(tf.t_s)
    assert np.abs(eul - tf.euler_rad).max() < 1e-12
    assert tf.gps_time_offset_s == 1357207200.0  # 2023-01-08 10:00:00 GPST (the data README)


def test_graded_imu_errors_have_the_grade_noise(exact):
    # consumer grade: 1 deg/sqrt(h) ARW -> per-sample noise sigma ARW sqrt(dt); the bias (500 deg/h GM)
    # is removed by differencing consecutive samples: var(diff) = 2 ARW^2 dt
    ds = simulate_from_truth(MOTION, "consumer", imu_rate_hz=100.0, seed=3)
    d = ds.imu.dtheta_b - exact.imu.dtheta_b
    arw = np.radians(1.0) / 60.0
    sd = np.std(np.diff(d[:, 2])) / np.sqrt(2.0)
    assert abs(sd / (arw * np.sqrt(0.01)) - 1.0) < 0.05
    assert ds.imu_model["imu_grade"] == "consumer"


def test_bad_truth_file_names_the_line(tmp_path):
    p = tmp_path / "m.csv"
    lines = MOTION.read_text().splitlines()[:8] if MOTION.exists() else None
    if lines is None:
        pytest.skip("shared data not available")
    lines[5] = lines[5].replace(",", ",x", 1)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(TruthFileError, match=r"line 6: non-numeric"):
        read_spirent_motion(p)
    q = tmp_path / "n.csv"
    q.write_text("a,b\n1,2\n")
    with pytest.raises(TruthFileError, match="not a Spirent motion file"):
        read_spirent_motion(q)


@pytest.mark.parametrize("column, value", [("Pos_Y", "nan"), ("Time_ms", "inf"), ("Heading", "-inf")])
def test_a_non_finite_truth_value_is_refused_naming_line_and_column(tmp_path, capsys, column, value):
    """float() reads 'nan' and 'inf': before, a NaN position ran through the synthesis into imu.csv and
    truth.csv and `insnav simulate --from-truth` ended with status 0.  Now one line naming the line and
    the column, status 2, no dataset folder."""
    from insnav.cli import main

    lines = need(MOTION).read_text().splitlines()[:40]
    names = lines[1].split(",")
    fields = lines[20].split(",")
    fields[names.index(column)] = value
    lines[20] = ",".join(fields)
    p = tmp_path / "m.csv"
    p.write_text("\n".join(lines) + "\n")
    before = p.read_bytes()
    out = tmp_path / "ds"
    assert main(["simulate", "--from-truth", str(p), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err == (f"insnav simulate: error: {p}, line 21: non-finite value {float(value)!r} in column "
                   f"'{column}'\n"), err
    assert not out.exists() and p.read_bytes() == before


@pytest.mark.parametrize("column, change, message", [
    ("Pos_X", lambda v: 1e30, r"line 21: position 1e\+30 m from the Earth's centre"),
    ("Pos_Y", lambda v: v + 50.0, r"line 21: the position step from the line before differs by 50 m from"),
    ("Vel_Z", lambda v: v + 1e3, r"line 21: the position step from the line before differs by 50 m"),
    ("Acc_X", lambda v: v + 1e3, r"line 21: the position step .* by 0\.833\d m.*"
                                 r"|line 21: the velocity step from the line before differs by 50 m/s"),
    ("Elevation", lambda v: 1e5, r"line 21: Elevation 100000 rad beyond \+-pi/2"),
    ("Heading", lambda v: v + 3.0, r"line 21: Heading changes at 29\.9\d rad/s from the line before \(more than 20\)"),
])
def test_an_impossible_truth_row_is_refused_naming_the_line(tmp_path, column, change, message):
    """A finite but corrupted row (one wrong field) gave IMU increments of 1e45 m/s or 1e4 rad with
    status 0.  The row is checked against its neighbours: the position step against the quintic
    Hermite's relation to the recorded velocity and acceleration, the velocity step against the
    acceleration, pitch within +-90 deg, the attitude rate (insnav.sim.from_truth._check_plausible)."""
    lines = need(MOTION).read_text().splitlines()[:40]
    names = lines[1].split(",")
    fields = lines[20].split(",")
    i = names.index(column)
    fields[i] = repr(change(float(fields[i])))
    lines[20] = ",".join(fields)
    p = tmp_path / "m.csv"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(TruthFileError, match=message) as exc:
        read_spirent_motion(p)
    assert str(exc.value).startswith(f"{p}, line 21: ") and str(exc.value).endswith(": a corrupted row?")


def test_cli_simulate_from_truth(tmp_path):
    out = tmp_path / "ds"
    r = subprocess.run([sys.executable, "-m", "insnav", "simulate", "--from-truth", str(need(MOTION)),
                        "--imu-grade", "industrial", "--imu-rate-hz", "50", "--out", str(out), "-q"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert (out / "imu.csv").exists() and (out / "truth.csv").exists()
    from insnav.data.dataset import load_dataset

    ds = load_dataset(out)
    assert len(ds.imu) == 30005 and abs(ds.gps_time_offset_s - 1357207200.0) < 1e-6
    r = subprocess.run([sys.executable, "-m", "insnav", "simulate", "car-mems", "--from-truth", str(MOTION),
                        "--out", str(tmp_path / "x")], capture_output=True, text=True)
    assert r.returncode != 0 and "not both" in r.stderr
    # the --from-truth options on a scenario were ignored (its own grade and rate ran); a rate of
    # 0.001 Hz wrote no IMU sample, one of 1e6 Hz ran out of memory
    for args, message in ((["car-mems", "--imu-grade", "consumer"], "--imu-grade is an option of --from-truth"),
                          (["--from-truth", str(MOTION), "--imu-rate-hz", "0.001"],
                           "imu_rate_hz (--imu-rate-hz): 0.001; allowed: 1 to 10000 [Hz]")):
        r = subprocess.run([sys.executable, "-m", "insnav", "simulate", *args, "--out", str(tmp_path / "y")],
                           capture_output=True, text=True)
        assert r.returncode != 0 and message in r.stderr and not (tmp_path / "y").exists(), r.stderr


def test_a_bank_through_pi_is_a_steady_roll(tmp_path):
    """A vehicle standing still and rolling at 0.5 rad/s: the Bank column wraps at +-pi every
    12.6 s.  The exact IMU's roll rate is 0.5 rad/s throughout (it reached -73 rad/s at each
    wrap when Bank was splined wrapped) and the truth roll stays within +-180 deg."""
    r = _ecef(48.78, 9.17, 320.0)[0]
    t = np.arange(0.0, 20.0001, 0.1)
    bank = (0.5 * t + np.pi) % (2 * np.pi) - np.pi
    f = tmp_path / "roll.csv"
    rows = [f"{int(round(ti * 1000))},{r[0]:.4f},{r[1]:.4f},{r[2]:.4f},0,0,0,0,0,0,0.0,0.0,{b:.9f}"
            for ti, b in zip(t, bank)]
    f.write_text("3,2,100,1,GDOP, 1357207200.0\nTime_ms,Pos_X,Pos_Y,Pos_Z,Vel_X,Vel_Y,Vel_Z,Acc_X,Acc_Y,Acc_Z,"
                 "Heading,Elevation,Bank\n" + "\n".join(rows) + "\n")
    ds = simulate_from_truth(f, "exact", imu_rate_hz=100.0)
    rate = ds.imu.dtheta_b[:, 0] / np.diff(ds.imu.t, prepend=ds.imu.t[0] - 0.01)
    np.testing.assert_allclose(rate, 0.5, atol=2e-3)  # Earth rate on the other axes' projection: < 1e-4
    assert np.all(np.abs(ds.truth.roll_deg) <= 180.0) and np.ptp(ds.truth.roll_deg) > 350.0


def test_a_truth_shorter_than_two_imu_samples_is_refused_and_run_refuses_such_a_dataset(tmp_path, capsys):
    """A truth spanning less than one IMU interval wrote a dataset with 0 IMU samples (status 0), and
    `insnav run` on 0 or 1 IMU samples wrote a 0- or 1-row solution reported "health: ok"."""
    from insnav.cli import main

    p = tmp_path / "four.csv"
    p.write_text("\n".join(need(MOTION).read_text().splitlines()[:6]) + "\n")  # 4 epochs, 0.3 s
    out = tmp_path / "ds"
    capsys.readouterr()
    assert main(["simulate", "--from-truth", str(p), "--imu-rate-hz", "1", "--out", str(out), "-q"]) == 2
    assert capsys.readouterr().err == (f"insnav simulate: error: {p}: the truth spans 0.3 s, too short for 2 IMU "
                                       "samples at 1 Hz (it needs 2 s or more)\n")
    assert not out.exists()
    assert main(["simulate", "--from-truth", str(p), "--imu-rate-hz", "10", "--out", str(out), "-q"]) == 0
    imu = (out / "imu.csv").read_text().splitlines(keepends=True)
    assert len(imu) == 1 + 3
    for n in (0, 1):
        (out / "imu.csv").write_text("".join(imu[:1 + n]))
        capsys.readouterr()
        assert main(["run", str(out), "--allow-free-inertial", "--out", str(tmp_path / "s.csv"), "-q"]) == 2
        assert capsys.readouterr().err == (f"insnav run: error: {out / 'imu.csv'}: {n} IMU sample{'s' * (n == 0)}: "
                                           "a navigation run needs 2 or more (one sample interval)\n")
        assert not (tmp_path / "s.csv").exists()
