"""KF-GINS as a drop-in: every YAML key is checked (a typo is a one-line error
with a suggestion), every key is used (the initial IMU errors and their
sigmas, outputpath), and insnav options reach a KF-GINS run (--run-config)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import insnav
from insnav.io import kfgins
from insnav.io.kfgins_dataset import load_kfgins
from insnav.units import RAD2DEG

from test_cli import _call, _user_error

DEG_H = RAD2DEG * 3600.0


@pytest.fixture(scope="module")
def sim():
    return insnav.simulate("seed000-sim", seed=5)


def _yaml(ds, **extra) -> str:
    """A KF-GINS configuration of the simulated dataset (its initial state, IMU model, lever arm)."""
    m, s0 = ds.imu_model, ds.initial
    lines = ["imupath: imu.txt", "gnsspath: gnss.txt", "outputpath: out", "imudatalen: 7", "imudatarate: 200",
             "starttime: 0", "endtime: -1", f"initpos: [{s0.lat_deg!r}, {s0.lon_deg!r}, {s0.h_m!r}]",
             f"initvel: [{', '.join(repr(float(v)) for v in s0.v_n)}]",
             f"initatt: [{s0.roll_deg!r}, {s0.pitch_deg!r}, {s0.yaw_deg!r}]",
             "initposstd: [2, 2, 3]", "initvelstd: [0.1, 0.1, 0.1]", "initattstd: [0.5, 0.5, 1.0]",
             f"antlever: [{', '.join(repr(float(v)) for v in ds.lever_arm_b)}]", "imunoise:",
             f"  arw: [{m['gyro_arw'][0] * RAD2DEG * 60:.6g}] ",
             f"  vrw: [{m['accel_vrw'][0] * 60:.6g}]",
             f"  gbstd: [{m['gyro_bias_total_sigma'][0] * DEG_H:.6g}]",
             f"  abstd: [{m['accel_bias_total_sigma'][0] * 1e5:.6g}]",
             "  gsstd: [300, 300, 300]", "  asstd: [300, 300, 300]", "  corrtime: 4.0"]
    text = "\n".join(lines) + "\n"
    text = text.replace(f"arw: [{m['gyro_arw'][0] * RAD2DEG * 60:.6g}] ", "arw: [{0}, {0}, {0}]".format(
        f"{m['gyro_arw'][0] * RAD2DEG * 60:.6g}"))
    for key in ("vrw", "gbstd", "abstd"):  # one value -> three
        i = text.index(f"  {key}: [")
        j = text.index("]", i)
        v = text[i + len(key) + 5:j]
        text = text[:i] + f"  {key}: [{v}, {v}, {v}]" + text[j + 1:]
    for k, v in extra.items():
        text += f"{k}: {v}\n"
    return text


@pytest.fixture(scope="module")
def kf_dir(sim, tmp_path_factory):
    d = tmp_path_factory.mktemp("kfgins")
    kfgins.write_kfgins_imu(d / "imu.txt", sim.imu)
    kfgins.write_kfgins_gnss(d / "gnss.txt", sim.gnss, with_velocity=True)
    return d


@pytest.mark.parametrize("typo, message", [("antlevr: [0, 0, 0]\n", "unknown key 'antlevr'; did you mean 'antlever'"),
                                           ("initbgsd: [1, 1, 1]\n", "did you mean 'initbgstd'")])
def test_a_misspelt_key_is_one_line_naming_it(sim, kf_dir, typo, message):
    p = kf_dir / "typo.yaml"
    p.write_text(_yaml(sim) + typo)
    with pytest.raises(ValueError, match=message) as exc:
        kfgins.read_kfgins_config(p)
    assert str(p) in str(exc.value) and "\n" not in str(exc.value)
    p.write_text(_yaml(sim).replace("  arw:", "  awr:"))
    with pytest.raises(ValueError, match=r"unknown key 'imunoise.awr'; did you mean 'arw'"):
        kfgins.read_kfgins_config(p)


def test_initial_gyro_bias_and_its_std_are_used(sim, kf_dir):
    """initgyrbias is the starting estimate and initbgstd its sigma: the first
    row holds them, and starting from the true bias with a tiny sigma gives a
    better heading than starting from zero with the same tiny sigma (which
    only the Gauss-Markov process noise can free, slowly)."""
    b_true = np.asarray(sim.imu_model["gyro_bias"]) * DEG_H  # [deg/h], a constant turn-on bias
    errs = {}
    for name, b0 in (("true", b_true), ("zero", np.zeros(3))):
        p = kf_dir / f"{name}.yaml"
        p.write_text(_yaml(sim, initgyrbias=f"[{', '.join(repr(float(x)) for x in b0)}]",
                           initbgstd="[0.0001, 0.0001, 0.0001]"))
        ds, cfg = load_kfgins(p, layout=15)
        np.testing.assert_allclose(np.asarray(cfg.init_gyro_bias_radps) * DEG_H, b0, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.asarray(cfg.init_sigma_gyro_bias_radps) * DEG_H, 1e-4, rtol=1e-12)
        cfg.imu_error_sigmas = True
        sol = insnav.run(ds, config=cfg)
        np.testing.assert_allclose(sol.gyro_bias_rps[0] * DEG_H, b0, atol=1e-3)   # starts there
        # its sigma starts at initbgstd (+ 5 ms of process noise), not at imunoise.gbstd (20 deg/h)
        assert (sol.sigma_imu_err[0, 3:6] * DEG_H < 0.05).all(), sol.sigma_imu_err[0, 3:6] * DEG_H
        np.testing.assert_allclose(sol.sigma_att_deg[0], [0.5, 0.5, 1.0], rtol=0.05)
        errs[name] = insnav.evaluate(sol, sim.truth)["rms"]["att_deg"][2]
    assert errs["true"] < 0.5 * errs["zero"], errs  # a held 20 deg/h error costs heading accuracy


def test_outputpath_gets_kfgins_files_and_run_config_overrides(sim, kf_dir):
    p = kf_dir / "plain.yaml"
    p.write_text(_yaml(sim))
    rc, _, err = _call(["run", "--format", "kfgins", "--config", p, "--output-rate", 10])
    assert rc == 0, err
    for f in (kfgins.KFGINS_NAV_FILE, kfgins.KFGINS_IMU_ERR_FILE, kfgins.KFGINS_STD_FILE):
        assert (kf_dir / "out" / f).is_file()
    nav = np.loadtxt(kf_dir / "out" / kfgins.KFGINS_NAV_FILE)
    assert nav.shape[1] == 11 and abs(nav[1, 1] - nav[0, 1] - 0.1) < 1e-9
    toml = kf_dir / "run.toml"
    toml.write_text("gate_chi2 = 1e-6\n")  # every update rejected: the override reached the run
    rc, _, err = _call(["run", "--format", "kfgins", "--config", p, "--run-config", toml, "--out",
                        kf_dir / "gated.csv"])
    assert rc == 2 and "rejected by the innovation gate" in err, err
    toml.write_text("gate_chi2s = 1\n")
    _user_error(["run", "--format", "kfgins", "--config", p, "--run-config", toml, "--out", kf_dir / "x.csv"],
                "gate_chi2s")
    _user_error(["run", kf_dir, "--run-config", toml, "--out", kf_dir / "y.csv"], "--run-config")
    toml.write_text("[rtk]\nratio = 3\n")  # an RTK table: one line naming it, not an AttributeError
    _user_error(["run", "--format", "kfgins", "--config", p, "--run-config", toml, "--out", kf_dir / "z.csv"],
                "[rtk] is read by RTK runs")


def test_a_partial_imu_table_overrides_only_its_keys_of_the_yaml_noise(sim, kf_dir):
    """``--run-config`` with ``[imu]`` restating one YAML noise key leaves the YAML's other noise
    values (VRW, bias and scale-factor sigmas and time constants) as they were."""
    from insnav.cli.run import _overlay_run_config

    p = kf_dir / "plain.yaml"
    p.write_text(_yaml(sim))
    _, cfg = load_kfgins(p)
    toml = kf_dir / "arw.toml"
    toml.write_text("[imu]\ngyro_arw_deg_per_sqrt_h = 0.5\n")
    over = _overlay_run_config(dataclasses.replace(cfg, imu=dataclasses.replace(cfg.imu)), toml)
    arw = np.deg2rad(0.5) / 60.0  # deg/sqrt(h) -> rad/sqrt(s)
    np.testing.assert_allclose(over.imu.gyro_arw, [arw] * 3, rtol=1e-12)
    for f in dataclasses.fields(cfg.imu):
        if f.name != "gyro_arw":
            assert getattr(over.imu, f.name) == getattr(cfg.imu, f.name), f.name
