"""The resolved configuration a run writes (``<out>.config.toml``) runs the same
filter again, bit for bit, for every family: ``insnav run ... --config
<out>.config.toml`` (with no --filter, --coupling, --option or --smooth) gives a
byte-identical solution file, and writes the same configuration again (a fixed
point).  And the state layout is a run key: a tight run's 17 or 20 states are
accepted in the TOML, written back as the layout the run used, and any other
layout is a one-line error naming the key."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from insnav.cli import main


def _round_trip(tmp_path, args: list, tag: str) -> str:
    """Run ``insnav run *args``, re-run its resolved configuration with the same inputs and
    no filter arguments, and check both files match; the configuration's text."""
    first, again = tmp_path / f"{tag}.csv", tmp_path / f"{tag}-again.csv"
    assert main(["run", *args, "-q", "--out", str(first)]) == 0
    resolved = tmp_path / f"{tag}.csv.config.toml"
    inputs = [a for a in args if a not in _RUN_ONLY]
    for flag in ("--filter", "--coupling", "--option", "--config", "--constraints", "--base-pos"):
        while flag in inputs:  # these flags and their values: the configuration must carry them
            i = inputs.index(flag)
            del inputs[i:i + 2]
    assert main(["run", *inputs, "--config", str(resolved), "-q", "--out", str(again)]) == 0
    assert again.read_bytes() == first.read_bytes(), tag
    text = resolved.read_text()
    assert (tmp_path / f"{tag}-again.csv.config.toml").read_text() == text, tag
    return text


_RUN_ONLY = ("--smooth",)


def _save(ds, path):
    ds.save(path)
    return str(path)


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    """Small simulated dataset folders: GPS-only raw observations (tight 17, loose, particle),
    GPS + Galileo + BeiDou (tight 20) and the seed 001 delayed fixes."""
    from conftest import first_segments, short_tight_dataset

    import insnav.sim as sim

    root = tmp_path_factory.mktemp("round_trip")
    out = {"gps": _save(short_tight_dataset(duration_s=60.0), root / "gps")}
    sc = first_segments(copy.deepcopy(sim.load_scenario("urban-multignss").raw), 60.0)
    sc["gnss_raw"].pop("urban_canyon", None)
    out["multi"] = _save(sim.simulate(sc, seed=4), root / "multi")
    sc = copy.deepcopy(sim.load_scenario("seed001-high").raw)
    sc["motion"]["segments"] = sc["motion"]["segments"][:2]
    out["delay"] = _save(sim.simulate(sc, seed=2), root / "delay")
    return out


def test_loose_21_states_smoothed(datasets, tmp_path):
    cfg = tmp_path / "in.toml"
    cfg.write_text("layout = 21\ninit_seed = 3\n")
    text = _round_trip(tmp_path, [datasets["gps"], "--filter", "rbukf", "--config", str(cfg), "--smooth"], "loose")
    assert 'filter = "rbukf"' in text and "layout = 21" in text and "smooth = true" in text


def test_tight_gps_only_writes_layout_17(datasets, tmp_path):
    text = _round_trip(tmp_path, [datasets["gps"], "--coupling", "tight", "--filter", "ekf",
                                  "--option", "elevation_mask_deg=12.5"], "tight17")
    assert "layout = 17" in text and "elevation_mask_deg = 12.5" in text


def test_tight_multi_gnss_writes_layout_20(datasets, tmp_path):
    """The data choose 20 states (inter-system biases); the configuration says so and re-runs 20."""
    from insnav.filters.solution import load_solution

    text = _round_trip(tmp_path, [datasets["multi"], "--coupling", "tight", "--filter", "ekf"], "tight20")
    assert "layout = 20" in text
    assert len(load_solution(tmp_path / "tight20.csv")) > 100


def test_delay_filter(datasets, tmp_path):
    text = _round_trip(tmp_path, [datasets["delay"], "--filter", "rdkf", "--option", "delay_p=[0.6, 0.4]"], "delay")
    assert 'filter = "rdkf"' in text and "delay_p = [0.6, 0.4]" in text


def test_particle_filter(datasets, tmp_path):
    text = _round_trip(tmp_path, [datasets["gps"], "--coupling", "tight", "--filter", "upf", "--option",
                                  "particles=6", "--option", "seed=5"], "upf")
    assert 'filter = "upf"' in text and "particles = 6" in text


def test_spp(shared_data, tmp_path):
    d = shared_data / "smartloc_berlin_potsdamer_platz"
    if not (d / "Berlin_Potsdamer_Platz.obs").is_file():
        pytest.skip(f"{d} not found (the smartLoc data set)")
    cfg = tmp_path / "spp.toml"
    cfg.write_text('[gnss]\nmodel = "rtklib"\n[spp]\nraim = false\n')
    text = _round_trip(tmp_path, ["--filter", "spp", "--format", "rinex", "--obs", str(d / "Berlin_Potsdamer_Platz.obs"),
                                  "--nav", str(d / "brdc1580.16n"), "--config", str(cfg)], "spp")
    assert 'model = "rtklib"' in text and "raim = false" in text


def test_rtk_with_a_given_base_position(shared_data, tmp_path):
    """--base-pos goes into [rtk] base_position_ecef_m: the re-run needs no --base-pos."""
    d = shared_data / "matrtklib_static_septentrio"
    if not d.is_dir():
        pytest.skip("MatRTKLIB static data not in ../shared/data")
    cfg = tmp_path / "rtk.toml"
    cfg.write_text('[rtk]\nsystems = "GE"\nfrequencies = 1\nar_mode = "instantaneous"\n')
    text = _round_trip(tmp_path, ["--filter", "rtk", "--format", "rinex", "--obs", str(d / "rover.obs"), "--base",
                                  str(d / "base.obs"), "--nav", str(d / "base.nav"), "--base-pos",
                                  "35.134707705,136.977577939,104.853", "--config", str(cfg)], "rtk")
    assert "base_position_ecef_m = [" in text and 'ar_mode = "instantaneous"' in text


def test_rtk_ins(shared_data, tmp_path):
    """Tight RTK/INS: the [rtk] options it ran with (RTK/INS defaults included) and the
    [rtk_engine] keys given are written back."""
    from insnav.sim.from_truth import simulate_from_truth

    sp = shared_data / "instinct_spirent_rtk_dynamic_SIMULATED"
    v = sp / "iono-Klob_tropo-Saast"
    if not (v / "Rover-dynamic_MO_Spirent.obs").is_file():
        pytest.skip("Spirent RTK data not in ../shared/data")
    ds = _save(simulate_from_truth(sp / "Rover-dynamic_motion_Spirent.csv", "tactical", imu_rate_hz=20.0, seed=1),
               tmp_path / "ds")
    cfg = tmp_path / "ri.toml"
    cfg.write_text('coupling = "rtk"\noutput_decimation = 20\n[rtk]\nelevation_mask_deg = 12.0\n'
                   "phase_error_ratio = 0.4\n[rtk_engine]\nins_slip_k_sigma = 6.0\n")
    nav = f"{sp / 'RINEX_GN_Spirent.23N'},{sp / 'RINEX_EN_Spirent.23L'}"
    files = ["--obs", str(v / "Rover-dynamic_MO_Spirent.obs"), "--base", str(v / "Base-static_MO_Spirent.obs"),
             "--nav", nav]
    text = _round_trip(tmp_path, [ds, "--config", str(cfg), *files], "rtk_ins")
    assert "elevation_mask_deg = 12.0" in text and "ins_slip_k_sigma = 6.0" in text
    assert "code_correlation_time_s = 10.0" in text  # the RTK/INS default it ran with
    assert "phase_error_ratio = 0.4" in text and "phase_correlation_time_s = 30.0" in text
    # the phase keys' old place ([rtk_engine]): the same run, with a deprecation note, and the resolved
    # configuration writes them in [rtk] only
    old = tmp_path / "old.toml"
    old.write_text('coupling = "rtk"\noutput_decimation = 20\n[rtk]\nelevation_mask_deg = 12.0\n'
                   "[rtk_engine]\nins_slip_k_sigma = 6.0\nphase_error_ratio = 0.4\n")
    with pytest.warns(FutureWarning, match=r"'\[rtk_engine\] phase_error_ratio' is deprecated"):
        assert main(["run", ds, "--config", str(old), *files, "-q", "--out", str(tmp_path / "old.csv")]) == 0
    assert (tmp_path / "old.csv").read_bytes() == (tmp_path / "rtk_ins.csv").read_bytes()
    assert (tmp_path / "old.csv.config.toml").read_text() == text


# --- the layout key ------------------------------------------------------------------------------

def test_layout_20_on_gps_only_data_runs_the_20_state_filter():
    """layout = 20 in the TOML runs LayoutTightMulti on GPS-only rows (run_tight(layout=20)),
    not the 17 states the data alone would choose: it carries the inter-system biases, whose
    1-sigma grows as their random walk (no row sees them), and reduces exactly to the 17-state
    navigation (their H columns and initial cross-covariances are zero)."""
    import insnav
    from conftest import short_tight_dataset
    from insnav.config import config_from_dict
    from insnav.filters.tight import run_tight

    ds = short_tight_dataset(duration_s=30.0)
    cfg = config_from_dict({"coupling": "tight", "layout": 20})
    a = insnav.run(ds, config=cfg)
    b = run_tight(ds, cfg, layout=20)
    c = insnav.run(ds, coupling="tight")
    assert a.summary["state_layout"] == 20 and a.isb_m is not None and c.summary["state_layout"] == 17
    np.testing.assert_array_equal(a.lat_deg, b.lat_deg)
    np.testing.assert_array_equal(a.isb_m, b.isb_m)
    assert c.isb_m is None and np.all(a.sigma_isb[-1] > a.sigma_isb[0])
    np.testing.assert_array_equal(a.lat_deg, c.lat_deg)


@pytest.mark.parametrize("d, match", [
    ({"coupling": "tight", "layout": 21}, "config key 'layout': bad value 21; allowed: 17, 20"),
    ({"coupling": "loose", "layout": 17}, "config key 'layout': bad value 17; allowed: 15, 21"),
    ({"filter": "upf", "coupling": "tight", "layout": 17}, "config key 'layout': bad value 17; allowed: 20"),
    ({"filter": "rdkf", "layout": 21}, "config key 'layout': bad value 21; allowed: 15 "),
    ({"filter": "spp", "coupling": "gnss", "layout": 17}, "config key 'layout'.*absent"),
    ({"coupling": "tight", "layout": "auto"}, "config key 'layout': bad value 'auto'"),
    # the tight filters read no fixes: the keys that switch fixes off would be ignored
    ({"coupling": "tight", "use_position": False}, r"'use_position': bad value False; allowed: true with tight "
                                                    r"coupling \(it reads no fixes; the option is "
                                                    r"options.use_pseudorange\)"),
    ({"filter": "upf", "coupling": "tight", "use_velocity": False}, r"'use_velocity'.*\(it reads no fixes\)$"),
])
def test_invalid_layout_for_the_coupling_is_one_line_naming_the_key(d, match):
    from insnav.config import ConfigError, config_from_dict

    with pytest.raises(ConfigError, match=match) as exc:
        config_from_dict(d, source="run.toml")
    assert "\n" not in str(exc.value) and str(exc.value).startswith("run.toml: ")


def test_old_options_layout_still_loads_with_a_note():
    from insnav.config import config_from_dict

    with pytest.warns(FutureWarning, match="'options.layout' is deprecated; write 'layout'"):
        cfg = config_from_dict({"coupling": "tight", "options": {"layout": 20, "max_sats": 9}})
    assert cfg.layout == 20 and cfg.options == {"max_sats": 9}


def test_option_tables_given_as_dicts_are_read_as_the_toml_tables():
    """insnav.run(..., constraints={...}) as the TOML's [constraints]: the same config, and an unknown
    key or a table that is not one is a one-line ConfigError, not an AttributeError."""
    from insnav.config import ConfigError, Constraints, RunConfig, config_from_dict

    cfg = RunConfig(constraints={"use": ["nhc"], "sigma_nhc_mps": 0.2}, robust={"screening": False}).validate()
    toml = config_from_dict({"constraints": {"use": ["nhc"], "sigma_nhc_mps": 0.2}, "robust": {"screening": False}})
    assert isinstance(cfg.constraints, Constraints) and cfg.constraints == toml.constraints
    assert cfg.robust == toml.robust and cfg.robust.screening is False
    with pytest.raises(ConfigError, match=r"unknown key 'constraints.usee'; did you mean 'use'\?"):
        RunConfig(constraints={"usee": ["nhc"]}).validate()
    with pytest.raises(ConfigError, match=r"config key 'tdcp': bad value 3; allowed: a \[tdcp\] table"):
        RunConfig(tdcp=3).validate()


def test_a_toml_without_filter_is_checked_against_the_command_lines_filter(tmp_path):
    """``insnav run DIR --coupling tight --config l20.toml`` with ``layout = 20`` alone in the file: its
    keys are checked against the tight filter the command line asks for, not the default loose EKF."""
    from insnav.config import ConfigError, load_config

    p = tmp_path / "l20.toml"
    p.write_text("layout = 20\n")
    with pytest.raises(ConfigError, match="layout"):
        load_config(p)  # alone: the default ekf loose has 15 or 21 states
    cfg = load_config(p, {"filter": "ekf", "coupling": "tight"})
    assert (cfg.filter, cfg.coupling, cfg.layout) == ("ekf", "tight", 20)
    p.write_text("[options]\nelevation_mask_deg = 15.0\n")
    assert load_config(p, {"coupling": "tight", "filter": None}).options == {"elevation_mask_deg": 15.0}


def test_insnav_run_checks_a_toml_against_its_filter_and_coupling_arguments(tmp_path):
    """``insnav.run(ds, "ekf", "tight", config=F)`` with ``layout = 20`` in F (refused as "ekf loose"
    before)."""
    from insnav.config import ConfigError
    from insnav.filters import _as_config

    p = tmp_path / "l20.toml"
    p.write_text("layout = 20\n")
    assert _as_config(str(p), "ekf", "tight").layout == 20
    assert _as_config({"layout": 20}, "ekf", "tight").layout == 20
    with pytest.raises(ConfigError, match="layout"):
        _as_config(str(p))  # alone: checked as the default ekf loose
