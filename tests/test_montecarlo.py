"""Monte Carlo runner: deterministic per-run seeds whatever the worker count
or backend, the summary, the backend hook and ``insnav compare``."""
from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import insnav

insnav.montecarlo  # noqa: B018  (the lazy attribute is the function; it loads the module)
mc = sys.modules["insnav.analysis.montecarlo"]


def test_run_seeds_deterministic_and_distinct():
    a = mc.run_seeds(3, 10)
    assert a == mc.run_seeds(3, 10)
    assert a[:4] == mc.run_seeds(3, 4)  # a run's seeds do not depend on the run count
    assert len(set(a)) == 10
    assert mc.run_seeds(4, 10) != a


def test_same_numbers_for_any_worker_count_and_backend():
    kw = dict(runs=4, seed=123, skip_s=5.0)
    r1 = insnav.montecarlo("seed001-low", ("kf", "rdkf"), workers=1, **kw)
    r2 = insnav.montecarlo("seed001-low", ("kf", "rdkf"), workers=2, **kw)
    r3 = insnav.montecarlo("seed001-low", ("kf", "rdkf"), backend="serial", **kw)
    for r in (r2, r3):
        assert [x["sim_seed"] for x in r.per_run] == [x["sim_seed"] for x in r1.per_run]
        for a, b in zip(r.per_run, r1.per_run):
            assert a["metrics"] == b["metrics"]
    # different runs differ
    v = r1.values("kf", "pos_n_rmse_m")
    assert len(set(v.tolist())) == 4
    s = r1.summary["kf"]["pos_n_rmse_m"]
    assert s["mean"] == pytest.approx(v.mean())
    assert s["rms"] == pytest.approx(np.sqrt(np.mean(v ** 2)))
    assert "| kf |" in r1.table() and "| rdkf |" in r1.table()


def test_backend_hook():
    calls = []

    def mapper(fn, tasks, workers):
        for t in reversed(tasks):  # any order is fine: results are placed by index
            calls.append(t.index)
            yield t.index, fn(t)

    mc.register_backend("test-reversed", mapper)
    try:
        r = insnav.montecarlo("seed001-low", ("kf",), runs=2, seed=1, backend="test-reversed")
        ref = insnav.montecarlo("seed001-low", ("kf",), runs=2, seed=1, workers=1)
    finally:
        mc._BACKENDS.pop("test-reversed")
    assert calls == [1, 0]
    assert [x["metrics"] for x in r.per_run] == [x["metrics"] for x in ref.per_run]
    with pytest.raises(ValueError, match="backend"):
        insnav.montecarlo("seed001-low", ("kf",), runs=1, backend="nope")


def test_compare_cli_json(capsys):
    from insnav.cli import main

    rc = main(["compare", "seed001-low", "--filters", "kf,exact", "--runs", "2", "--workers", "1", "--json",
               "--compact"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["filters"] == ["kf", "exact"] and out["runs"] == 2
    assert out["summary"]["exact"]["pos_n_rmse_m"]["mean"] < out["summary"]["kf"]["pos_n_rmse_m"]["mean"]
    rc = main(["compare", "seed001-low", "--filters", "kf", "--runs", "1", "--workers", "1"])
    assert rc == 0
    assert "| kf |" in capsys.readouterr().out


def test_a_comparison_of_nothing_is_refused():
    """--skip-s at or past the scenario's end left no error sample (a numpy reduction error naming
    nothing); a scenario without GNSS compared free-inertial runs as if they were filtered."""
    with pytest.raises(ValueError, match=r"skip_s \(--skip-s\) 1000.0; allowed: 0 <= skip_s < the scenario's"):
        insnav.montecarlo("seed001-low", ("kf",), runs=1, skip_s=1000.0, backend="serial")
    no_gnss = {"extends": "seed001-low", "gnss": {"enabled": False}}
    with pytest.raises(ValueError, match=r"filter 'kf' used no GNSS update in run 0"):
        insnav.montecarlo(no_gnss, ("kf",), runs=1, skip_s=5.0, backend="serial")


def test_a_filter_with_one_coupling_runs_it_without_being_told():
    """fukf, upf and pf run tightly coupled only: run() and the campaign take that coupling when none is
    given (as spp and rtk take their GNSS-only one); the same numbers as with coupling="tight"."""
    ds = insnav.simulate("seed004-uav", seed=1)
    a = insnav.run(ds, "fukf", output_decimation=50)
    b = insnav.run(ds, "fukf", "tight", output_decimation=50)
    assert a.summary["coupling"] == "tight"
    np.testing.assert_array_equal(a.lat_deg, b.lat_deg)
    with pytest.raises(ValueError, match="runs tightly coupled only"):
        insnav.run(ds, "fukf", "loose")


montecarlo = insnav.montecarlo


def test_campaign_arguments_refused_before_any_run():
    with pytest.raises(ValueError, match="'init_seed' is set per run by the campaign"):
        montecarlo("seed001-high", ("kf",), runs=2, init_seed=3)
    for bad in (True, 2.0, 0):
        with pytest.raises(ValueError, match="runs must be a whole number >= 1"):
            montecarlo("seed001-high", ("kf",), runs=bad)
    with pytest.raises(ValueError, match="skip_s"):
        montecarlo("seed001-high", ("kf",), runs=1, skip_s=True)
    # a skip inside the scenario's duration but past the solution's last row: named, not a numpy error
    with pytest.raises(ValueError, match="leaves no solution row"):
        montecarlo("seed001-high", ("kf",), runs=1, skip_s=174.995, backend="serial")


def test_a_dict_scenario_is_named_by_its_name():
    from insnav.sim.scenario import resolve_raw

    raw, _ = resolve_raw("seed001-high")
    r = montecarlo(raw, ("kf",), runs=1, backend="serial")
    assert r.scenario == "seed001-high"


def test_a_failing_campaign_stops_without_running_the_queued_runs():
    """The local backend cancels the queued runs when one fails (it waited for all of them)."""
    import time

    took = {}
    for runs in (2, 200):
        t0 = time.perf_counter()
        with pytest.raises(Exception, match="delay_p"):
            montecarlo("seed001-high", ("rdkf",), runs=runs, workers=2, delay_p=[5.0])
        took[runs] = time.perf_counter() - t0
    # each failing run costs its simulation (about 35 ms): 200 of them waited for took about 7 s
    assert took[200] < took[2] + 2.0, took
