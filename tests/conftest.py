"""Shared fixtures: where the third-party data lives (../shared/data beside the repo)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("INSNAV_SHARED_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ``../shared/data``; skips the test when it is absent (e.g. wheel-only install)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"third-party data not found at {SHARED_DATA} (set INSNAV_SHARED_DATA)")
    return SHARED_DATA


def first_segments(sc: dict, duration_s: float) -> dict:
    """The scenario ``sc`` with its first motion segments only, just as many as make ``duration_s`` [s]."""
    segs, tot = [], 0.0
    for seg in sc["motion"]["segments"]:
        if tot >= duration_s:
            break
        segs.append(seg)
        tot += float(seg["duration_s"])
    return dict(sc, motion=dict(sc["motion"], segments=segs))


def short_tight_dataset(duration_s: float = 120.0, seed: int = 7):
    """seed003-4sat cut to its first motion segments (>= duration_s), up to 8
    satellites, no failure windows: a tight-coupling run of about a second."""
    import insnav.sim as sim

    sc = first_segments(dict(sim.simulate("seed003-4sat", seed=0, with_truth=False).scenario), duration_s)
    sc["gnss_raw"] = dict(sc["gnss_raw"], windows=[], max_sats=8)
    return sim.simulate(sc, seed=seed)


#: The long tests (real-data campaigns, Monte Carlo, the C++ sanitizer build, a browser):
#: marked ``slow`` here, in one place, so that ``scripts/test.sh --quick`` (``-m "not slow"``)
#: runs the rest in about two minutes.  CI runs everything.  A node id or a prefix of one.
SLOW_TESTS = (
    "tests/test_cpp.py",
    "tests/test_docs.py",
    "tests/test_tight_multi.py::test_robust_rejects_faults",
    "tests/test_tight_multi.py::test_multi_sigma_point_filters",
    "tests/test_tight_multi.py::test_robust_equals_plain_on_clean_data",
    "tests/test_tight_multi.py::test_clock_jump_absorbed",
    "tests/test_tight_multi.py::test_walk_gec_loader_option",
    "tests/test_spp.py::test_smartloc",
    "tests/test_spp.py::test_cli_spp_on_smartloc",
    "tests/test_report.py::test_page_renders_in_a_real_browser",
    "tests/test_report.py::test_tight_report_shows_the_per_satellite_residuals",
    "tests/test_constraints.py::test_exact_nhc_keeps_the_linearised_filters_consistent_in_an_outage",
    "tests/test_constraints.py::test_nhc_at_one_hertz_drifts_less_than_white_noise_at_ten_hertz",
    "tests/test_sim_dataset.py::test_save_load_roundtrip",
    "tests/test_tight.py::test_one_satellite_clock_model_sets_the_vertical",
    "tests/test_smoother_rows.py::test_smoothed_run_matches_the_plain_formula",
    "tests/test_io_kfgins.py::test_read_sim_imu_xz_and_truth",
    "tests/test_io_kfgins.py::test_writers_roundtrip",
    "tests/test_odo_scale.py",
    "tests/test_upf.py",
    "tests/test_loose.py::test_consistency_monte_carlo",
    "tests/test_delay.py::test_high_delay_ordering",
    "tests/test_mechanization.py::test_stationary_one_hour",
    "tests/test_cli.py::test_demo_quick_writes_the_report",
    "tests/test_interrupt.py::test_sigint_stops_a_run_fast_with_one_line_and_no_output",
    "tests/test_tight_walk_faults.py::test_walk_fault_campaign_meets_its_targets",
    "tests/test_gate_outages.py::test_kfgins_track_default_gate_never_worse_than_gate_off",
    # the longest of the quick subset (pytest --durations: 4-8 s each)
    "tests/test_sim_stream.py::test_simulate_to_writes_the_saved_whole_dataset_byte_for_byte",
    "tests/test_report_files.py::test_report_replaces_an_earlier_report_and_refuses_other_folders",
    "tests/test_report_files.py::test_a_failed_report_leaves_no_figure_and_the_earlier_report",
    "tests/test_selfcal_lever_turns.py",
    "tests/test_pseudorange_gm.py::test_gauss_markov_errors_need_the_block",
    # the next longest (pytest --durations on a loaded machine: 2.5-7 s each, or a
    # file's shared fixture), so that the quick subset stays under 2 min
    "tests/test_gate_outages.py",
    "tests/test_dask.py",
    "tests/test_tune.py::test_toy_tuning_recovers_q_and_r_like_em",
    "tests/test_no_lost_file.py::test_no_file_is_lost_at_any_free_space_level",
    "tests/test_montecarlo.py::test_same_numbers_for_any_worker_count_and_backend",
    "tests/test_rtk_ins.py::test_cli_coupling_rtk_writes_fix_status_and_evaluate_reads_it",
    "tests/test_sim_imu.py::test_allan_deviation_matches_arw_and_vrw",
    "tests/test_allan.py::test_cli_outputs_and_toml_snippet_round_trip",
    "tests/test_report.py::test_allan_page_renders_in_a_real_browser",
    "tests/test_faults.py::test_tight_gate_catches_pseudorange_ramp",
    "tests/test_constraints.py::test_second_order_noise_as_white_noise_is_averaged_away",
    "tests/test_constraints.py::test_zupt_on_a_standing_car_bounds_velocity",
    "tests/test_rtk.py::test_mlambda_matches_exhaustive_search[6]",
    "tests/test_rtk_validation.py::test_success_rate_rule_rejects_weak_single_epoch_partial_fixes",
    "tests/test_rtk_validation.py::test_estimated_noise_route_rejects_what_a_095_threshold_would_fix_wrong",
    "tests/test_tight_walk_faults.py::test_cusum_acts_only_with_enough_pseudoranges",
    # one case of each parametrised alignment test stays quick
    "tests/test_align.py::test_navigation_grade_gyrocompasses[1]",
    "tests/test_align.py::test_navigation_grade_gyrocompasses[2]",
    "tests/test_align.py::test_mems_heading_from_gnss_velocity[1]",
    "tests/test_align.py::test_mems_heading_from_gnss_velocity[2]",
    "tests/test_align.py::test_mems_heading_from_gnss_velocity[3]",
    # the quick subset's longest calls at 1090 tests (pytest --durations, 1.4-3.3 s each)
    "tests/test_report.py::test_allan_only_report_and_its_errors",
    "tests/test_report.py::test_allan_section_has_the_fit_of_the_log",
    "tests/test_loose.py::test_rbukf_beats_ekf_large_initial_attitude_error",
    "tests/test_report.py::test_cli_report_and_its_errors",
    "tests/test_constraints.py::test_cli_constraints_flag_and_config_round_trip",
    "tests/test_report.py::test_summary_matches_evaluate_and_figures_are_real",
    "tests/test_stream.py::test_a_slow_writer_never_sees_its_rows_overwritten",
    "tests/test_stream_gnss_on_demand.py::test_fixes_read_on_demand_give_the_whole_runs_files[1]",
    "tests/test_stream_gnss_on_demand.py::test_10hz_fixes_read_on_demand_give_the_whole_runs_files",
    "tests/test_changing_inputs.py::test_truncation_race_never_kills_the_reader_nor_passes_a_short_read",
    "tests/test_report_files.py::test_kfgins_nav_results_are_solutions",
    "tests/test_cli_imports.py::test_percentile_equals_numpy",
    "tests/test_sim_from_truth.py::test_cli_simulate_from_truth",
    "tests/test_rtk_validation.py::test_estimated_noise_follows_a_receiver_noisier_than_configured",
    "tests/test_rtk_iono.py::test_medium_baseline_float_is_consistent_where_the_variance_model_is_not",
    "tests/test_spp.py::test_compiled_solver_equals_numpy_reference_on_real_data",
    "tests/test_sim_truth.py::test_attitude_matches_integrated_angular_rate",
    "tests/test_report.py::test_without_truth_the_gnss_fixes_are_the_reference",
    "tests/test_sim_gnss.py::test_outage_windows_produce_no_fixes",
    "tests/test_report.py::test_known_offset_gives_known_numbers",
    "tests/test_rtk_iono.py::test_zero_ionosphere_estimate_stays_at_zero_and_matches_no_iono_states",
)


#: Started first (scripts/test.sh runs pytest-xdist with ``--dist loadfile
#: --no-loadscope-reorder``, which hands the work out in collection order, a
#: whole file to one worker, so that a module fixture is computed once): the
#: C++ sanitizer tests, whose worker waits for the background build and so
#: leaves that build a core, and the documentation build (one ~100 s fixture);
#: then the longest files, the other files with tests marked slow, then the
#: rest (longest first, roughly, so that the two workers finish together).
FIRST_TESTS = ("tests/test_cpp.py", "tests/test_docs.py",
               # the longest files (pytest --durations, summed per file), longest first
               "tests/test_tight_multi.py", "tests/test_spp.py", "tests/test_constraints.py",
               "tests/test_report.py", "tests/test_tight.py")


# (Not --dist loadgroup with xdist_group marks on the tests that share a module
# fixture: pytest-xdist 3.8 groups them by appending "@group" to item._nodeid,
# which pytest 9.2 no longer reads (open upstream in pytest-xdist), so every such
# fixture ran once per worker, e.g. test_gate_outages.py's car runs, 2 x 21 s.)
@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    for item in items:
        nodeid = item.nodeid.replace("\\", "/")
        if any(nodeid.startswith(p) for p in SLOW_TESTS):
            item.add_marker(pytest.mark.slow)

    def rank(item) -> int:
        nodeid = item.nodeid.replace("\\", "/")
        i = next((i for i, p in enumerate(FIRST_TESTS) if nodeid.startswith(p)), None)
        if i is not None:
            return i
        return len(FIRST_TESTS) + (0 if item.get_closest_marker("slow") else 1)

    # whole files move (a file's tests stay together and in order, so that a
    # module fixture is set up once also without xdist); the sort is stable
    file_rank: dict[str, int] = {}
    for item in items:
        f = item.nodeid.split("::")[0]
        file_rank[f] = min(file_rank.get(f, 99), rank(item))
    items.sort(key=lambda item: file_rank[item.nodeid.split("::")[0]])
# --- optional capabilities: the suite runs everything it promises -------------
# A capability the package promises (the browser-checked HTML report, Parquet,
# the plot / pandas / dask extras, PyYAML for KF-GINS files) is a FAILURE when
# absent, not a skip: scripts/test.sh installs all of them.  The only way to skip
# such tests is an explicit opt-out variable, e.g. INSNAV_SKIP_BROWSER=1, and
# .ci/run sets INSNAV_NO_SKIP=1, which ignores the opt-outs and fails the run on
# any skipped test at all.

#: capability -> (opt-out variable, how to get it)
CAPABILITIES = {
    "browser": ("INSNAV_SKIP_BROWSER", "apt-get install -y chromium (scripts/test.sh installs it)"),
    "parquet": ("INSNAV_SKIP_PARQUET", "pip install 'insnav[parquet]'"),
    "pandas": ("INSNAV_SKIP_PANDAS", "pip install 'insnav[pandas]'"),
    "plot": ("INSNAV_SKIP_PLOT", "pip install 'insnav[plot]'"),
    "dask": ("INSNAV_SKIP_DASK", "pip install 'insnav[dask]'"),
    "yaml": ("INSNAV_SKIP_YAML", "pip install pyyaml (in the test extra)"),
    "allantools": ("INSNAV_SKIP_ALLANTOOLS", "pip install allantools (in the test extra)"),
    "docs": ("INSNAV_SKIP_DOCS", "pip install 'insnav[docs]'"),
}


def no_skip() -> bool:
    """True under ``.ci/run`` (``INSNAV_NO_SKIP=1``): no opt-out, no skip."""
    return os.environ.get("INSNAV_NO_SKIP") == "1"


def missing_capability(capability: str, what: str):
    """Fail the test (or the module, at collection) because ``capability`` is
    absent; skip it only when the user opted out with its variable."""
    var, how = CAPABILITIES[capability]
    if os.environ.get(var) == "1" and not no_skip():
        pytest.skip(f"{what} (opted out with {var}=1)", allow_module_level=True)
    pytest.fail(f"{what}: {how}; the suite requires it (set {var}=1 to skip these tests explicitly)",
                pytrace=False)


def require_module(name: str, capability: str):
    """``import name`` or :func:`missing_capability`."""
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError as exc:
        missing_capability(capability, f"{name} is not importable ({exc})")


def _skipped(config) -> list:
    tr = config.pluginmanager.get_plugin("terminalreporter")
    return [r for r in (tr.stats.get("skipped", []) if tr else []) if getattr(r, "when", "") != "teardown"]


def pytest_sessionfinish(session, exitstatus):
    """Under INSNAV_NO_SKIP=1 a run with a skipped test fails (exit status 1)."""
    if not no_skip() or getattr(session.config, "workerinput", None) is not None:
        return  # (xdist workers: the controller counts the skips of all of them)
    if _skipped(session.config) and session.exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    n = len(_skipped(config))
    if no_skip() and n:
        terminalreporter.write_line(f"[insnav] INSNAV_NO_SKIP=1: {n} test(s) skipped, so the run fails "
                                    "(CI runs everything; see the reasons above)", red=True)
