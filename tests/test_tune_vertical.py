"""The vertical GNSS position sigma factor of loose runs (``gnss_pos_v_sigma_scale``, the tuner's
``gnss_pos_v``).

* Exact: at a fix one IMU sample after the start, ln det S is that of P0 + R with the down
  position sigma multiplied by the factor (on top of ``gnss_pos_sigma_scale``).
* Reduction: the factor f in the config gives bit for bit the run of a dataset whose down
  position sigmas are multiplied by f; f = 1 is the run without the key.
* Recovery: on a simulated drive whose data state a vertical sigma half the simulated one,
  the tuner finds the factor 2 within 10 % (and the horizontal factor 1 within 10 %).
* Bad input: a clear one-line error with tight coupling.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import insnav
from insnav.calib.tune import default_parameters, scaled_config, solution_log_likelihood, tune, tuned_toml_dict
from insnav.config import ConfigError, ImuNoise, RunConfig
from insnav.data.dataset import ImuData


def _first_fix_dataset(seconds=20.0):
    ds = insnav.simulate("seed000-sim", seed=2)
    k = np.searchsorted(ds.imu.t, ds.t0 + seconds)
    ds = dataclasses.replace(ds, imu=ImuData(ds.imu.t[:k], ds.imu.dtheta_b[:k], ds.imu.dv_b[:k]))
    t = ds.gnss.t_valid.copy()
    t[0] = ds.imu.t[0]  # the first fix at the first IMU sample: P there is P0 (one 5 ms step)
    ds.gnss.t_valid = t
    if hasattr(ds.gnss, "t_arrival"):
        ds.gnss.t_arrival = np.maximum(ds.gnss.t_arrival, t)
    return ds


def test_vertical_factor_scales_the_down_row_of_r():
    ds = _first_fix_dataset()
    cfg = RunConfig(filter="ekf", init_error=False, gnss_pos_sigma_scale=2.0, gnss_pos_v_sigma_scale=3.0,
                    init_sigma_pos_m=[3.0, 4.0, 5.0], init_sigma_vel_mps=[0.2, 0.3, 0.4], gate_prob=0.0)
    sol = insnav.run(ds, config=cfg)
    assert sol.gnss_status[0] == 1
    p0 = np.r_[np.square(cfg.init_sigma_pos_m), np.square(cfg.init_sigma_vel_mps)]
    sp = 2.0 * np.asarray(ds.gnss.sigma_pos_n[0], float) * np.array([1.0, 1.0, 3.0])
    r = np.r_[np.square(sp), np.square(ds.gnss.sigma_vel_n[0])]
    assert sol.log_det_s[0] == pytest.approx(np.sum(np.log(p0 + r)), abs=1e-4)
    # and not that of the factor on all three axes (the test can fail)
    r_all = np.r_[np.square(6.0 * np.asarray(ds.gnss.sigma_pos_n[0], float)), np.square(ds.gnss.sigma_vel_n[0])]
    assert abs(sol.log_det_s[0] - np.sum(np.log(p0 + r_all))) > 0.1


def test_vertical_factor_is_the_data_sigma_times_f_bit_for_bit():
    ds = insnav.simulate("seed000-sim", seed=3)
    f = 2.5
    g = dataclasses.replace(ds.gnss)
    sp = np.array(ds.gnss.sigma_pos_n, float)
    sp[:, 2] *= f
    g.sigma_pos_n = sp
    a = insnav.run(ds, config=RunConfig(filter="ekf", gnss_pos_v_sigma_scale=f))
    b = insnav.run(dataclasses.replace(ds, gnss=g), config=RunConfig(filter="ekf"))
    c = insnav.run(ds, config=RunConfig(filter="ekf", gnss_pos_v_sigma_scale=1.0))
    d = insnav.run(ds, config=RunConfig(filter="ekf"))
    for x, y in ((a, b), (c, d)):
        for k in ("lat_deg", "lon_deg", "h_m", "v_n", "sigma_pos_n_m", "nis", "log_det_s"):
            assert np.array_equal(np.asarray(getattr(x, k)), np.asarray(getattr(y, k)), equal_nan=True), k
    assert not np.array_equal(a.sigma_pos_n_m, d.sigma_pos_n_m)
    # the tuner's factor composes with the config's; 1 leaves the config alone
    noise = ImuNoise()
    c = scaled_config(RunConfig(gnss_pos_v_sigma_scale=2.0), noise, {"gnss_pos_v": 1.5})
    assert c.gnss_pos_v_sigma_scale == 3.0 and c.gnss_pos_sigma_scale == 1.0
    assert scaled_config(RunConfig(), noise, {"gnss_pos_v": 1.0}) == scaled_config(RunConfig(), noise, {})


def test_tuner_recovers_the_vertical_factor():
    """seed000-sim's GNSS noise is 5 m horizontal, 10 m vertical; the data are told 5 m vertical too
    (a sigma floor or a receiver with H = V), so the true factors are gnss_pos 1 and gnss_pos_v 2.
    GNSS at 5 Hz without the outage: 750 records, the sigma of one factor about 1 / sqrt(2 * 750) = 3 %."""
    scen = {"extends": "seed000-sim", "name": "tune-vertical", "gnss": {"rate_hz": 5.0, "outages": []}}
    ds = insnav.simulate(scen, seed=4)
    sp = np.array(ds.gnss.sigma_pos_n, float)
    assert np.allclose(sp[:, 2], 2.0 * sp[:, 0])
    sp[:, 2] = sp[:, 0]
    ds.gnss.sigma_pos_n = sp
    cfg = RunConfig(filter="ekf", imu=ImuNoise.from_dataset_model(ds.imu_model))
    assert "gnss_pos_v" in default_parameters(ds, cfg)
    res = tune(ds, cfg, params=["gnss_pos", "gnss_pos_v"], holdout=0.0, max_runs=40)
    assert res.scales["gnss_pos_v"] == pytest.approx(2.0, rel=0.10)
    assert res.scales["gnss_pos"] == pytest.approx(1.0, rel=0.10)
    assert res.tuned.gnss_pos_v_sigma_scale == pytest.approx(res.scales["gnss_pos_v"])
    assert tuned_toml_dict({}, res)["gnss_pos_v_sigma_scale"] == res.tuned.gnss_pos_v_sigma_scale
    # the likelihood prefers it to the data's ratio
    ll_base = solution_log_likelihood(insnav.run(ds, config=dataclasses.replace(cfg)))[0]
    assert res.log_likelihood_tuned > ll_base + 10.0


def test_vertical_factor_is_loose_only():
    with pytest.raises(ConfigError, match="gnss_pos_v_sigma_scale") as e:
        RunConfig(filter="ekf", coupling="tight", gnss_pos_v_sigma_scale=2.0).validate()
    assert len(str(e.value).splitlines()) == 1
    with pytest.raises(ConfigError, match="gnss_pos_v"):
        tune(insnav.simulate("seed000-sim", seed=1), RunConfig(filter="ekf", coupling="tight"), params=["gnss_pos_v"],
             max_runs=4)
    with pytest.raises(ConfigError, match="gnss_pos_v_sigma_scale"):
        RunConfig(gnss_pos_v_sigma_scale=0.0).validate()
    assert "gnss_pos_v" not in default_parameters(insnav.simulate("seed000-sim", seed=1),
                                                  RunConfig(filter="ekf", coupling="tight"))


def test_stream_applies_the_vertical_factor_as_the_batch_run(shared_data, tmp_path, monkeypatch):
    """``insnav run --format kfgins`` block by block (insnav.filters.stream) with the factor in --run-config:
    the solution and innovations files byte for byte those of the whole-file run, and not those without it."""
    import lzma

    import insnav.filters.stream as stream
    from test_cli import _call

    sim = shared_data / "kfgins" / "sim"
    with lzma.open(sim / "Leador-A15-sim.txt.xz", "rb") as f:
        lines = [f.readline() for _ in range(20_000)]  # the run starts at the YAML's starttime, 10 000 lines in
    (tmp_path / "imu.txt").write_bytes(b"".join(lines))
    (tmp_path / "gnss.txt").write_bytes((sim / "GNSS-RTK-sim.txt").read_bytes())
    yaml = "\n".join('imupath: "./imu.txt"' if ln.startswith("imupath:") else
                     'gnsspath: "./gnss.txt"' if ln.startswith("gnsspath:") else ln
                     for ln in (sim / "kf-gins-sim.yaml").read_text().splitlines())
    (tmp_path / "kf.yaml").write_text(yaml + "\n")
    (tmp_path / "v.toml").write_text("gnss_pos_v_sigma_scale = 3.0\n")
    monkeypatch.setattr(stream, "BLOCK_LINES", 4093)
    out = {}
    for name, extra in (("on", ["--stream", "on", "--run-config", tmp_path / "v.toml"]),
                        ("off", ["--stream", "off", "--run-config", tmp_path / "v.toml"]), ("plain", [])):
        sol = tmp_path / name / "sol.csv"
        rc, _, err = _call(["run", "--format", "kfgins", "--config", tmp_path / "kf.yaml", "--out", sol, "--quiet",
                            *extra])
        assert rc == 0, err
        assert "note:" not in err  # with --stream on: the stream ran, not the whole-file fallback
        out[name] = (sol.read_bytes(), (sol.parent / "sol.csv.innovations.csv").read_bytes())
    assert out["on"] == out["off"]
    assert out["on"][0] != out["plain"][0]
