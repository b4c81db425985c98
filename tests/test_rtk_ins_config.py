"""The configuration of a carrier-phase run, and what ``evaluate`` / ``report`` make of its files.

Each test pins a way the run could quietly do something other than asked:

* ``[options] rtk_options`` and ``--option rtk_options={...}`` were accepted and ignored (the
  ``[rtk]`` table replaced them in the merge); a GNSS-only run ignored ``--option`` altogether.
* ``[rtk_engine]`` read keys the run sets from its own keys (lever arm, propagation interval,
  output decimation, smoother) and overrode them silently; a wrong type or a table that is not a
  table gave a Python or pybind11 error naming no file.
* Run keys that RTK/INS does not read (the innovation gate, the fix flags and sigma scales,
  ``[robust]``) were accepted and did nothing.
* The navigation rows of a continuous-AR run were the float filter's (the same rows as with AR off)
  while ``evaluate`` counted them fixed; ``innovations.csv`` carried the AR ratio as NIS.
* An RTKLIB-layout ``.pos`` against its simulated dataset was compared in the wrong time base with
  the IMU-centre truth; ``report`` could not read a ``.pos`` or a static ``--truth x,y,z``.

Data: the ``rtk-open-sky-car`` simulator preset (600 s, 1 Hz rover and base RINEX, 100 Hz IMU, the
antenna truth in ``rtk_truth.csv``), simulated in about a second."""
from __future__ import annotations

import numpy as np
import pytest

from insnav.analysis.evaluate import _read_solution, _read_truth, _solution_at, evaluate
from insnav.cli import main
from insnav.config import ConfigError, RunConfig


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("rtk_cfg") / "sim"
    assert main(["simulate", "rtk-open-sky-car", "--out", str(d), "-q"]) == 0
    return d


def _files(d):
    return ["--obs", str(d / "rover.obs"), "--base", str(d / "base.obs"), "--nav", str(d / "nav.rnx")]


def _rtk_ins(d, out, *extra):
    return ["run", str(d), "--filter", "ekf", "--coupling", "rtk", *_files(d), "--out", str(out), "-q", *extra]


def _status(out):
    a = np.genfromtxt(f"{out}.rtk.csv", delimiter=",", names=True)
    return a["status"].astype(int)


def test_rtk_options_in_options_and_on_the_command_line_reach_the_run(sim, tmp_path, capsys):
    """``ar_mode = "off"`` given in ``[options] rtk_options`` or ``--option rtk_options=...``: no epoch
    fixed (the default fixes every one on this open-sky drive), the resolved TOML says so and re-runs
    the same rows; the option is written over the ``[rtk]`` table's key."""
    base = tmp_path / "default.csv"
    assert main(_rtk_ins(sim, base)) == 0
    assert np.all(_status(base) == 1)
    toml = tmp_path / "opts.toml"
    toml.write_text('coupling = "rtk"\n[options]\nrtk_options = {ar_mode = "off"}\n')
    a = tmp_path / "a.csv"
    assert main(_rtk_ins(sim, a, "--config", str(toml))) == 0
    assert np.all(_status(a) == 2)
    table = tmp_path / "table.toml"
    table.write_text('coupling = "rtk"\n[rtk]\nar_mode = "fix-and-hold"\n')
    b = tmp_path / "b.csv"
    assert main(_rtk_ins(sim, b, "--config", str(table), "--option", 'rtk_options={ar_mode="off"}')) == 0
    assert np.all(_status(b) == 2)
    resolved = (tmp_path / "b.csv.config.toml").read_text()
    assert 'ar_mode = "off"' in resolved and "rtk_options" not in resolved
    c = tmp_path / "c.csv"
    assert main(_rtk_ins(sim, c, "--config", str(tmp_path / "b.csv.config.toml"))) == 0
    assert c.read_bytes() == b.read_bytes()
    capsys.readouterr()
    for value, message in (('{ar_mod="off"}', "unknown key 'rtk.ar_mod' (did you mean 'rtk.ar_mode'?)"),
                           ("3", "bad value 3; allowed: a table of [rtk] keys")):
        out = tmp_path / "bad" / "x.csv"
        assert main(_rtk_ins(sim, out, "--option", f"rtk_options={value}")) == 2
        err = capsys.readouterr().err
        assert err.startswith("insnav run: error: [options] / --option rtk_options: ") and message in err, err
        assert len(err.splitlines()) == 1 and not out.parent.exists()


def test_gnss_only_filters_read_their_option_tables(sim, tmp_path, capsys):
    """``--filter rtk --option rtk_options={ar_mode="off"}``: every epoch float (0 fixed of 600, against
    600 of 600 without); ``--filter spp --option spp_options={raim=false}``: RAIM off; any other key
    is one line naming it."""
    out = tmp_path / "rtk.pos"
    argv = ["run", "--filter", "rtk", "--format", "rinex", *_files(sim), "--out", str(out), "-q"]
    assert main(argv) == 0
    assert "600 fixed (100.0 %)" in capsys.readouterr().out
    assert main(argv + ["--option", 'rtk_options={ar_mode="off"}']) == 0
    assert "0 fixed (0.0 %), 600 float" in capsys.readouterr().out
    assert main(argv + ["--option", "x=1"]) == 2
    assert capsys.readouterr().err == ("insnav run: error: --option x: --filter rtk reads rtk_options only (tables "
                                       "of keys, e.g. --option 'rtk_options={...}')\n")
    spp = ["run", "--filter", "spp", "--format", "rinex", "--obs", str(sim / "rover.obs"), "--nav",
           str(sim / "nav.rnx"), "--out", str(tmp_path / "spp.csv"), "-q"]
    assert main(spp) == 0
    assert "RAIM on" in capsys.readouterr().out
    assert main(spp + ["--option", "spp_options={raim=false}"]) == 0
    assert "RAIM off" in capsys.readouterr().out
    assert main(spp + ["--option", "weighting=3"]) == 2
    assert "--option weighting: bad value 3; allowed: a table of keys" in capsys.readouterr().err


@pytest.mark.parametrize("text, message", [
    ("[rtk_engine]\nlever_arm_b = [0.0, 0.0, 1.5]\n",
     "key 'rtk_engine.lever_arm_b': the run sets it; write the run key 'lever_arm_b' instead"),
    ("[rtk_engine]\noutput_decimation = 10\n",
     "key 'rtk_engine.output_decimation': the run sets it; write the run key 'output_decimation' instead"),
    ("[rtk_engine]\npropagation_interval = 5.0\n",
     "key 'rtk_engine.propagation_interval': the run sets it; write the run key 'propagation_interval_s' instead"),
    ("[rtk_engine]\nsmooth = true\n", "key 'rtk_engine.smooth': the run sets it; write the run key 'smooth' instead"),
    ("[rtk_engine]\nins_slip_k_sigma = \"x\"\n", "key 'rtk_engine.ins_slip_k_sigma': bad value 'x'; allowed: a number"),
    ("[rtk_engine]\nrobust_screening = 1\n", "key 'rtk_engine.robust_screening': bad value 1; allowed: true or false"),
    ("[rtk_engine]\nins_slip_k_sigm = 4.0\n", "key 'rtk_engine.ins_slip_k_sigm': unknown; did you mean 'ins_slip_k_sigma'?"),
    ("rtk_engine = 3\n", "key 'rtk_engine': bad value 3; allowed: an [rtk_engine] table"),
    ("rtk = 3\n", "key 'rtk': bad value 3; allowed: an [rtk] table"),
    # integer engine keys: a float was truncated (2.5 ran as 2), 1e12 gave a pybind11 cast error
    ("[rtk_engine]\nrobust_max_sats = 2.5\n",
     "key 'rtk_engine.robust_max_sats': bad value 2.5; allowed: an integer in [0, 100]"),
    ("[rtk_engine]\nrobust_max_sats = 1e12\n",
     "key 'rtk_engine.robust_max_sats': bad value 1000000000000.0; allowed: an integer in [0, 100]"),
    ("[rtk_engine]\nrobust_phase_reset_epochs = -1\n",
     "key 'rtk_engine.robust_phase_reset_epochs': bad value -1; allowed: an integer in [0, 1000000]"),
    # the engine's own range checks named neither the table nor the file
    ("[rtk_engine]\ncode_chi2_row = -1.0\n", "key 'rtk_engine.code_chi2_row': bad value -1.0; allowed: a number >= 0"),
    ("[rtk_engine]\nvalidation_prob = 1.0\n",
     "key 'rtk_engine.validation_prob': bad value 1.0; allowed: a number in [0, 1)"),
    ("[rtk_engine]\nrobust_igg_k0 = 4.0\n", "key 'rtk_engine.robust_igg_k0': bad value 4.0 with robust_igg_k1 = 3.0; "
     "allowed: 0 < robust_igg_k0 < robust_igg_k1"),
    # the deprecated engine key: its range named [rtk]; given in both tables the engine's silently won
    ("[rtk_engine]\nphase_error_ratio = 50.0\n",
     "key 'rtk_engine.phase_error_ratio': bad value 50.0; allowed: a number in [0.0, 10.0]"),
    ("[rtk]\nphase_error_ratio = 0.2\n[rtk_engine]\nphase_error_ratio = 0.8\n",
     "keys 'rtk.phase_error_ratio' and 'rtk_engine.phase_error_ratio' both given; keep 'rtk.phase_error_ratio' "
     "(the [rtk_engine] key is deprecated)"),
    # above the RTK/INS engine's 64 ambiguity states: every epoch float without a word; 2**40: a cast error
    ("[rtk]\nmin_fix_ambiguities = 99\n", "key 'rtk.min_fix_ambiguities': bad value 99; allowed: an integer in "
     "[1, 64] with RTK/INS (the ambiguity states its engine holds)"),
    ("[rtk]\nmin_fix_ambiguities = 1099511627776\n",
     "key 'rtk.min_fix_ambiguities': bad value 1099511627776; allowed: an integer in [1, 120]"),
    # both base keys: the latitude/longitude silently won
    ("[rtk]\nbase_position_ecef_m = [4157177.0, 671230.0, 4774767.0]\nbase_position_llh = [48.78, 9.17, 350.0]\n",
     "keys 'rtk.base_position_ecef_m' and 'rtk.base_position_llh' both given; keep one (the base antenna reference "
     "point)"),
])
def test_an_engine_key_the_run_sets_or_a_bad_value_is_one_line_naming_the_file(sim, tmp_path, capsys, text, message):
    """Before, the first four overrode the run's own keys silently (a 1.5 m lever arm the run did not
    report, a tenth of the rows), and the others stopped with a TypeError or a pybind11 cast error
    naming no file."""
    toml = tmp_path / "run.toml"
    toml.write_text('coupling = "rtk"\n' + text)
    out = tmp_path / "out" / "sol.csv"
    assert main(_rtk_ins(sim, out, "--config", str(toml))) == 2
    err = capsys.readouterr().err
    assert err == f"insnav run: error: {toml}: {message}\n", err
    assert not out.parent.exists()


def test_engine_and_rtk_key_checks_from_python_name_the_key():
    """The same checks for ``insnav.run(..., engine=..., rtk_options=...)``: one line naming the key."""
    from insnav.filters.rtk_ins import check_engine, run_rtk_ins, rtk_ins_options
    from insnav.gnss.rtk import RtkOptions

    with pytest.raises(ConfigError, match=r"^key 'rtk_engine\.robust_max_sats': bad value 2\.5; allowed: an integer"):
        check_engine({"robust_max_sats": 2.5})
    assert check_engine({"robust_max_sats": 3, "outage_cycle_s": float("inf")}) == {"robust_max_sats": 3,
                                                                                   "outage_cycle_s": float("inf")}
    with pytest.raises(ConfigError, match=r"'rtk\.max_outage_epochs': bad value 1000000000000; allowed: an integer "
                                          r"in \[0, 1000000\]$"):
        RtkOptions.from_dict({"max_outage_epochs": 10 ** 12})
    assert RtkOptions.from_dict({"min_fix_ambiguities": 120}).min_fix_ambiguities == 120  # the GNSS-only capacity
    with pytest.raises(ConfigError, match=r"'rtk\.min_fix_ambiguities': bad value 65; allowed: an integer in \[1, 64\]"):
        rtk_ins_options(RtkOptions(min_fix_ambiguities=65))
    assert rtk_ins_options({"min_fix_ambiguities": 64}).min_fix_ambiguities == 64
    with pytest.raises(ConfigError, match=r"^keys 'rtk\.phase_error_ratio' and 'rtk_engine\.phase_error_ratio' both"):
        run_rtk_ins(object(), RunConfig(filter="ekf"), rover="r.obs", base="b.obs", nav="n.nav",
                    rtk_options={"phase_error_ratio": 0.2}, engine={"phase_error_ratio": 0.8})


@pytest.mark.parametrize("key, value", [("gate_chi2", 9.0), ("gate_prob", 0.99), ("use_position", False),
                                        ("use_velocity", False), ("gnss_pos_sigma_scale", 2.0),
                                        ("gnss_vel_sigma_scale", 2.0)])
def test_run_keys_rtk_ins_does_not_read_are_refused(key, value):
    """RTK/INS reads carrier phase and code, screens its rows itself ([rtk_engine] code_chi2_row,
    robust_screening) and reads no fixes: these keys did nothing.  Their defaults pass."""
    RunConfig(coupling="rtk").validate()
    with pytest.raises(ConfigError, match=rf"config key '{key}': bad value .*; allowed: .* with rtk coupling"):
        RunConfig(coupling="rtk", **{key: value}).validate()
    # the tight filter reads them; the fix switches only the loose one
    RunConfig(coupling="loose" if key.startswith("use_") else "tight", **{key: value}).validate()


def test_a_robust_key_under_rtk_coupling_names_the_engine_keys():
    cfg = RunConfig(coupling="rtk")
    cfg.robust.chi2_row = 5.0
    with pytest.raises(ConfigError, match=r"'robust.chi2_row'.*\[rtk_engine\] robust_screening"):
        cfg.validate()


def test_continuous_ar_rows_hold_the_fix_and_evaluate_counts_them_fixed(sim, tmp_path, capsys):
    """Continuous AR feeds nothing back into the filter.  Its navigation rows were the float filter's,
    bit for bit those of the run with AR off (0.21 m 3-D RMS on this drive), while ``evaluate`` called
    them fixed.  Now the rows until the next epoch are the fixed solution, mechanised beside the float
    INS (ClosedLoop::start_output_shadow): within centimetres, as fix-and-hold's rows, and several
    times better than the float rows; the float filter itself is unchanged (its antenna per epoch,
    ``r_float_e`` in ``rtk.csv`` terms, equals AR off's).  ``innovations.csv``: no NIS (NaN, the AR
    ratio is in ``rtk.csv``), the DD rows per epoch."""
    runs = {}
    for mode in ("continuous", "off", "fix-and-hold"):
        out = tmp_path / f"{mode}.csv"
        assert main(_rtk_ins(sim, out, "--option", f'rtk_options={{ar_mode="{mode}"}}')) == 0
        runs[mode] = evaluate(_read_solution(out), _read_truth(sim))
    cont, off, hold = runs["continuous"], runs["off"], runs["fix-and-hold"]
    assert cont["fix_rate"] == 1.0 and off["fix_rate"] == 0.0 and hold["fix_rate"] == 1.0
    fixed, flt = cont["by_status"]["fixed"], off["by_status"]["float"]
    assert fixed["samples"] == flt["samples"] == hold["by_status"]["fixed"]["samples"]
    assert fixed["rms_3d_m"] < 0.05 and fixed["rms_3d_m"] < flt["rms_3d_m"] / 4, (fixed, flt)
    assert fixed["rms_3d_m"] < 2.0 * hold["by_status"]["fixed"]["rms_3d_m"], (fixed, hold)
    a = {m: np.genfromtxt(tmp_path / f"{m}.csv.rtk.csv", delimiter=",", names=True) for m in ("continuous", "off")}
    # the filter stays float: the epochs' positions of AR off are the continuous run's float
    # (rtk.csv holds the fixed antenna of a fixed epoch; <out>.rtk.pos likewise); the rows' 1-sigma
    # after a fix are the conditioned ones (centimetres, against decimetres for the float)
    sol_c, sol_o = _read_solution(tmp_path / "continuous.csv"), _read_solution(tmp_path / "off.csv")
    k = slice(1000, None)
    assert np.median(sol_c.sigma_pos_n_m[k, 0]) < 0.5 * np.median(sol_o.sigma_pos_n_m[k, 0])
    # the attitude's: of the whole attitude block the fix removed (the float filter's P minus a PSD
    # block, so never above the float run's, never zero)
    assert np.all(sol_c.sigma_att_deg[k] <= sol_o.sigma_att_deg[k] * (1 + 1e-3)) and np.all(sol_c.sigma_att_deg[k] > 0)
    assert a["continuous"]["n_dd"].tolist() == a["off"]["n_dd"].tolist()
    inn = np.genfromtxt(tmp_path / "continuous.csv.innovations.csv", delimiter=",", names=True)
    assert np.all(np.isnan(inn["nis"])) and np.array_equal(inn["rows"], a["continuous"]["n_dd"])
    assert a["continuous"]["n_dd"].min() >= 10
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "continuous.csv"), str(sim)]) == 0
    text = capsys.readouterr().out
    assert "fix rate 100.0 %" in text and "; fixed " in text and "; float " not in text


def test_evaluate_and_report_compare_a_pos_with_the_antenna_truth(sim, tmp_path, capsys):
    """An RTKLIB-layout ``.pos`` (the antenna, GPS seconds of week) against its dataset folder: the
    dataset's ``rtk_truth.csv`` (the antenna, GPS time) is the reference, as when it is given itself;
    before, the IMU-centre truth in dataset time did not overlap.  The fixed open-sky epochs are
    within centimetres.  A dataset without ``rtk_truth.csv`` is one line; ``report`` reads the
    ``.pos`` and a static ``--truth lat,lon,h``."""
    pos = tmp_path / "rtk.pos"
    assert main(["run", "--filter", "rtk", "--format", "rinex", *_files(sim), "--out", str(pos), "-q"]) == 0
    sol = _read_solution(pos)
    by_dir = evaluate(_solution_at(sol, (tr := _read_truth(sim, solution=pos)).t), tr)
    tr2 = _read_truth(sim / "rtk_truth.csv")
    by_file = evaluate(_solution_at(sol, tr2.t), tr2)
    assert by_dir["samples"] == by_file["samples"] == 600
    assert by_dir["rms_3d_m"] == by_file["rms_3d_m"] < 0.05
    assert by_dir["by_status"]["fixed"]["samples"] == 600
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "truth.csv").write_bytes((sim / "truth.csv").read_bytes())
    with pytest.raises(ValueError, match=r"has no rtk_truth.csv \(the antenna truth\)"):
        _read_truth(bare, solution=pos)
    capsys.readouterr()
    assert main(["report", str(pos), "--truth", str(sim), "--out", str(tmp_path / "rep")]) == 0
    html = (tmp_path / "rep" / "report.html").read_text()
    assert f"{by_dir['rms_3d_m']:.3f}" in html
    # a static antenna given as lat,lon,h: the report and evaluate agree
    assert main(["report", str(pos), "--truth", "48.15,11.55,521.5", "--out", str(tmp_path / "rep2")]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(pos), "48.15,11.55,521.5", "--json"]) == 0
    import json

    rms3 = json.loads(capsys.readouterr().out)["rms_3d_m"]
    assert f"{rms3:.3f}" in (tmp_path / "rep2" / "report.html").read_text()


@pytest.mark.parametrize("extra, text, message", [
    # the RTK tables and the base in a run that is not RTK/INS: accepted (unknown keys too) and ignored
    (["--coupling", "tight"], "[rtk]\nratio_threshold = 0.1\nbogus = 7\n",
     "{toml}: [rtk] is read by RTK runs only (--filter rtk, or --coupling rtk); this run's coupling is 'tight': "
     "remove the table"),
    (["--coupling", "loose"], "[rtk_engine]\nbogus = 1\n",
     "{toml}: [rtk_engine] is read by RTK runs only (--filter rtk, or --coupling rtk); this run's coupling is "
     "'loose': remove the table"),
    (["--coupling", "tight", "--base", "base.obs", "--base-pos", "1,2,3"], "",
     "--base and --base-pos: read by RTK runs only (--filter rtk, or --coupling rtk with --obs/--base/--nav); "
     "this run's coupling is 'tight'"),
    ([], 'coupling = "loose"\n', None),  # --base alone, the coupling from the TOML
    # [tdcp] settings without enabled / --tdcp: dropped from the run and the resolved configuration
    (["--coupling", "tight"], "[tdcp]\nsigma_phase_m = 0.5\nchi2_row = 1.0\n",
     "{toml}: key 'tdcp.sigma_phase_m': TDCP is off (neither --tdcp nor [tdcp] enabled = true), so the setting "
     "would be ignored: enable TDCP or remove it"),
])
def test_what_a_run_would_ignore_is_one_line_before_it_reads_anything(sim, tmp_path, capsys, extra, text, message):
    toml = tmp_path / "run.toml"
    toml.write_text(text)
    out = tmp_path / "out" / "sol.csv"
    argv = ["run", str(sim), "--config", str(toml), "--out", str(out), "-q", *extra]
    if message is None:
        argv += ["--base", "base.obs"]
        message = "--base: read by RTK runs only (--filter rtk, or --coupling rtk with --obs/--base/--nav); this run's " \
                  "coupling is 'loose'"
    assert main(argv) == 2
    assert capsys.readouterr().err == f"insnav run: error: {message.format(toml=toml)}\n"
    assert not out.parent.exists()


def test_spp_refuses_a_base_and_rtk_ins_refuses_rinex_systems(sim, tmp_path, capsys):
    """``--filter spp --base``: ignored before; ``[rinex] systems`` under ``--coupling rtk``: ignored
    (RTK/INS reads ``[rtk] systems``; the resolved configuration still wrote the [rinex] value)."""
    out = tmp_path / "out" / "x.csv"
    assert main(["run", "--filter", "spp", "--format", "rinex", "--obs", str(sim / "rover.obs"), "--nav",
                 str(sim / "nav.rnx"), "--base", str(sim / "base.obs"), "--out", str(out), "-q"]) == 2
    assert capsys.readouterr().err == "insnav run: error: --filter spp is GNSS only and does not use --base\n"
    toml = tmp_path / "run.toml"
    toml.write_text('coupling = "rtk"\n[rinex]\nsystems = "G"\n')
    assert main(["run", "--format", "rinex", "--imu", "imu.csv", *_files(sim), "--config", str(toml), "--out",
                 str(out), "-q"]) == 2
    assert capsys.readouterr().err == (f"insnav run: error: {toml}: key 'rinex.systems' is not read by RTK/INS "
                                       "(--coupling rtk): its satellites are [rtk] systems (default \"GREC\"); write "
                                       "systems in the [rtk] table\n")
    assert not out.parent.exists()


def test_run_applies_the_rtk_tables_of_a_config_dict_or_file(sim, tmp_path):
    """``insnav.run(..., config=<dict or TOML>)`` dropped ``[rtk]`` and ``[rtk_engine]`` without a word
    (the default fixed every epoch of this drive with ``ar_mode = "off"`` asked for); now they apply as
    on the command line: ``[rtk]`` under ``rtk_options=``, its base position key as the dataset's, and
    a bad or unknown key, or the tables in a run that is not RTK, is one line naming the source."""
    import insnav
    from insnav.filters.rtk import RtkDataset
    from insnav.filters.rtk_ins import RtkInsDataset

    files = (sim / "rover.obs", sim / "base.obs", sim / "nav.rnx")
    g = insnav.run(RtkDataset(*files), "rtk")
    assert g.rtk.counts()["n_fixed"] == 600
    g = insnav.run(RtkDataset(*files), "rtk", config={"rtk": {"ar_mode": "off"}})
    assert g.rtk_options.ar_mode == "off" and g.rtk.counts()["n_fixed"] == 0 and g.rtk.counts()["n_float"] == 600
    g = insnav.run(RtkDataset(*files), "rtk", config={"rtk": {"ar_mode": "off"}},
                   rtk_options={"ar_mode": "instantaneous"})  # the keyword over the table
    assert g.rtk_options.ar_mode == "instantaneous" and g.rtk.counts()["n_fixed"] == 304
    toml = tmp_path / "run.toml"
    toml.write_text('[rtk]\nar_mode = "off"\n[rtk_engine]\nins_slip_k_sigma = 6.0\n')
    imu = insnav.load_dataset(sim)
    s = insnav.run(RtkInsDataset(imu, *files), "ekf", "rtk", config=toml)
    assert s.rtk_options.ar_mode == "off" and np.all(s.fix_status == 2)
    assert s.rtk.info["engine"]["ins_slip_k_sigma"] == 6.0
    from insnav.gnss.rtk import read_phase_obs

    r_b = read_phase_obs(files[1], "G").approx_r_e  # the base position key reaches the run: 10 km off is refused
    with pytest.raises(ValueError, match=r"config: key 'rtk\.base_position_ecef_m'"):
        insnav.run(RtkDataset(*files), "rtk", config={"rtk": {"base_position_ecef_m": list(r_b + [1e4, 0, 0])}})
    for config, message in (
            ({"rtk": {"ar_mod": "off"}}, r"^config: unknown key 'rtk\.ar_mod' \(did you mean 'rtk\.ar_mode'\?\)"),
            ({"rtk_engine": {"bogus": 1}}, r"^config: key 'rtk_engine\.bogus': unknown"),
            ({"rtk": {"phase_error_ratio": 0.2}, "rtk_engine": {"phase_error_ratio": 0.8}},
             r"^config: keys 'rtk\.phase_error_ratio' and 'rtk_engine\.phase_error_ratio' both given")):
        with pytest.raises(ConfigError, match=message):
            insnav.run(RtkInsDataset(imu, *files), "ekf", "rtk", config=config)
    with pytest.raises(ConfigError, match=r"^config: \[rtk_engine\] is read by RTK/INS only \(coupling 'rtk'\); this "
                                          r"run is filter 'rtk', coupling 'gnss': remove the table$"):
        insnav.run(RtkDataset(*files), "rtk", config={"rtk_engine": {"ins_slip_k_sigma": 6.0}})
    with pytest.raises(ConfigError, match=rf"^{toml}: \[rtk\] is read by RTK runs only \(filter 'rtk', or coupling "
                                          r"'rtk'\); this run is filter 'ekf', coupling 'loose': remove the table$"):
        insnav.run(imu, "ekf", "loose", config=toml)
    with pytest.raises(ConfigError, match=r"^config: key 'tdcp\.chi2_row': TDCP is off"):
        insnav.run(imu, "ekf", "loose", config={"tdcp": {"chi2_row": 5.0}})
