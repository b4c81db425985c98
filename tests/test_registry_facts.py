"""The registry's facts against the runners: every keyword option of every
runner is reachable through insnav.run(), a TOML [options] table and the
command line's --option for the couplings that runner serves (and nothing
else is listed), so an option a runner accepts cannot be refused by run()
with a message naming another filter; the options dataclass of each family
is its runner's signature; the smoother, constraint, UT and system facts are
the ones the runners and the configuration check act on."""
from __future__ import annotations

import inspect

import pytest

import insnav
from insnav.registry import FILTERS


def _runner_keywords(fn) -> set[str]:
    """The runner's keyword options: its parameters after (dataset, cfg), less
    the RunConfig fields (reached through the config); a runner that forwards
    ``**options`` (the delay filters) is read through the function it forwards to."""
    from insnav.config import RunConfig

    params = list(inspect.signature(fn).parameters.values())[2:]
    assert not any(p.kind is p.VAR_KEYWORD for p in params), fn  # options by name only
    params = [p for p in params if p.name != "filter"]  # the particle runner's own filter= (cfg.filter)
    return {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}


@pytest.mark.parametrize("name,coupling", [(n, c) for n, s in FILTERS.items() for c in s.couplings])
def test_registry_options_are_the_runner_keywords(name, coupling):
    from insnav.config import RunConfig

    spec = FILTERS[name]
    fields = set(RunConfig.__dataclass_fields__)
    listed, runner = set(spec.options_for(coupling)), _runner_keywords(spec.runner(coupling))
    # a runner keyword that is also a RunConfig field (filter, layout) is reached through the
    # config unless the registry lists it as the runner's own option (the tight layout)
    assert listed - fields == runner - fields, (name, coupling, sorted(listed ^ runner))
    assert listed & fields <= runner, (name, coupling)


def test_tight_options_reach_the_tight_runner_and_not_the_loose_one():
    from conftest import short_tight_dataset

    ds = short_tight_dataset(duration_s=60.0)
    a = insnav.run(ds, "ekf", "tight", elevation_mask_deg=15.0, use_rate=False)
    b = insnav.run(ds, "ekf", "tight")
    assert a.summary["updates"] > 10
    # no range-rate rows: the per-satellite rate flags are all absent, and the solutions differ
    assert abs(a.v_n[-1] - b.v_n[-1]).max() > 0
    with pytest.raises(TypeError, match="'ekf' tight"):
        insnav.run(ds, "ekf", "loose", elevation_mask_deg=15.0)


# --- one runner signature: (dataset, cfg, options) with an options dataclass per family ---------

_PAIRS = [(n, c) for n, s in FILTERS.items() for c in s.couplings]


class _Captured(Exception):
    """Raised by the stand-in runner with what it received."""


def _capture(monkeypatch, spec, coupling):
    """Replace the family's runner by one that raises _Captured(cfg, options)."""
    import importlib

    mod, fn = spec.runners[coupling].split(":")
    module = importlib.import_module(mod)
    real = getattr(module, fn)

    def fake(dataset, cfg, **options):
        raise _Captured(cfg, options)

    fake.__signature__ = inspect.signature(real)
    monkeypatch.setattr(module, fn, fake)


def _received(name, coupling, config=None, **overrides):
    with pytest.raises(_Captured) as exc:
        insnav.run(object(), name, coupling, config, sanitize=False, checks=False, **overrides)
    return exc.value.args


@pytest.mark.parametrize("name,coupling", _PAIRS)
def test_options_dataclass_is_the_runner_signature(name, coupling):
    """The family's options dataclass has one field per registry option, with the runner's default."""
    import dataclasses

    spec = FILTERS[name]
    cls = spec.options_class(coupling)
    assert cls is spec.options_class(coupling)  # one class per family, not one per call
    params = inspect.signature(spec.runner(coupling)).parameters
    fields = {f.name: f for f in dataclasses.fields(cls)}
    assert tuple(fields) == spec.options_for(coupling)
    d = cls()
    for k in fields:
        want = None if params[k].default is inspect.Parameter.empty else params[k].default
        assert getattr(d, k) == want, (name, coupling, k)
    with pytest.raises(TypeError):
        cls(not_an_option=1)


@pytest.mark.parametrize("name,coupling", _PAIRS)
def test_every_option_reaches_the_runner(monkeypatch, name, coupling):
    """Each option given to insnav.run(), in a TOML [options] table or as --option KEY=VALUE on
    the command line arrives at the runner with that value, every other one at its default;
    data options (input rows, observation files) are run() keywords only."""
    import argparse

    from insnav.cli.run import add_run_parser, cli_options
    from insnav.config import ConfigError, config_from_dict

    spec = FILTERS[name]
    _capture(monkeypatch, spec, coupling)
    # sentinels and 4242 for every option: the value checks have tests of their own (tests/test_upf.py)
    monkeypatch.setattr("insnav.filters.check_option_values", lambda options: None)
    defaults = {f: getattr(spec.options_class(coupling)(), f) for f in spec.options_for(coupling)}
    _, got = _received(name, coupling)
    assert got == defaults
    parser = argparse.ArgumentParser()
    add_run_parser(parser.add_subparsers())
    for k in spec.options_for(coupling):
        sentinel = object()
        cfg, got = _received(name, coupling, **{k: sentinel})
        assert got[k] is sentinel and {**got, k: defaults[k]} == defaults, (name, coupling, k)
        if k in spec.data_options:
            with pytest.raises(ConfigError, match=f"unknown key 'options.{k}'"):
                config_from_dict({"filter": name, "coupling": coupling, "options": {k: 4242}})
            continue
        toml_cfg = config_from_dict({"filter": name, "coupling": coupling, "options": {k: 4242}})
        _, got = _received(name, coupling, toml_cfg)
        assert got[k] == 4242 and {**got, k: defaults[k]} == defaults, (name, coupling, k)
        args = parser.parse_args(["run", "d", "--option", f"{k}=4242"])
        cli_cfg = config_from_dict({"filter": name, "coupling": coupling, "options": cli_options(args.option)})
        _, got = _received(name, coupling, cli_cfg)
        assert got[k] == 4242, (name, coupling, k)
        # run()'s keyword wins over the config's [options]
        _, got = _received(name, coupling, toml_cfg, **{k: 7})
        assert got[k] == 7


def test_options_of_another_family_are_refused_in_the_toml():
    from insnav.config import ConfigError, config_from_dict

    with pytest.raises(ConfigError, match="unknown key 'options.particles' for filter 'ekf' tight"):
        config_from_dict({"filter": "ekf", "coupling": "tight", "options": {"particles": 10}})
    with pytest.raises(ConfigError, match="'ekf' loose; it takes no options"):
        config_from_dict({"options": {"elevation_mask_deg": 15}})
    with pytest.raises(ConfigError, match="did you mean 'elevation_mask_deg'"):
        config_from_dict({"filter": "ekf", "coupling": "tight", "options": {"elevation_mask": 15}})


@pytest.mark.parametrize("name,coupling", _PAIRS)
def test_facts_are_what_the_config_check_and_the_runners_act_on(name, coupling):
    """smoothable, constraints, ut_params and layouts of the registry against the configuration
    check and the runner modules (a smoothable family's runner applies the smoother; a sigma-point
    filter gets the UT parameters in its engine config)."""
    import importlib

    from insnav.config import ConfigError, RunConfig, Constraints
    from insnav.filters._setup import engine_config

    spec = FILTERS[name]
    f = spec.facts(coupling)
    base = dict(filter=name, coupling=coupling)
    if f.smoothable:
        RunConfig(**base, smooth=True).validate()
    else:
        with pytest.raises(ConfigError, match="config key 'smooth'"):
            RunConfig(**base, smooth=True).validate()
    src = inspect.getsource(importlib.import_module(spec.runners[coupling].split(":")[0]))
    # a smoothable family's runner applies the smoother; a runner that does is smoothable for one of the
    # filters it serves on this coupling
    shared = any(s.runners.get(coupling) == spec.runners[coupling] and s.facts(coupling).smoothable
                 for s in FILTERS.values() if coupling in s.couplings)
    assert ("smoothed_rows(" in src) == (f.smoothable or shared), (name, coupling)
    for c in ("nhc", "odo", "zupt"):
        cfg = RunConfig(**base, constraints=Constraints(use=[c]))
        if c in f.constraints:
            cfg.validate()
        else:
            with pytest.raises(ConfigError, match="constraints.use"):
                cfg.validate()
    if coupling in ("loose", "tight"):
        import numpy as np
        from types import SimpleNamespace

        ds = SimpleNamespace(lever_arm_b=np.zeros(3), scenario=None)
        ec = engine_config(ds, RunConfig(**base), np.array([0.0, 1.0]), 15)
        assert ("ut_alpha" in ec) == f.ut_params, (name, coupling)
    assert set(f.systems) <= {"G", "R", "E", "C"} and f.systems
    if coupling == "loose":
        for layout in (15, 21):
            cfg = RunConfig(**base, layout=layout)
            if layout in f.layouts:
                cfg.validate()
            else:
                with pytest.raises(ConfigError, match="layout"):
                    cfg.validate()


def test_cli_option_round_trips_through_the_resolved_config(tmp_path):
    """``insnav run --option delay_p=[0.5,0.5]`` reaches the random-delay KF (the solution differs from
    the preset's p), the resolved <out>.config.toml keeps it in [options], and re-running that file
    gives the same solution file."""
    import copy
    import tomllib

    from insnav import sim
    from insnav.cli import main

    sc = copy.deepcopy(sim.load_scenario("seed001-high").raw)
    sc["motion"]["segments"] = sc["motion"]["segments"][:2]
    d = tmp_path / "ds"
    sim.simulate(sc, seed=2).save(d)
    runs = {"opt": ["--option", "delay_p=[0.5, 0.5]"], "preset": []}
    for tag, extra in runs.items():
        assert main(["run", str(d), "--filter", "rdkf", "-q", "--out", str(tmp_path / f"{tag}.csv"), *extra]) == 0
    resolved = tmp_path / "opt.csv.config.toml"
    with open(resolved, "rb") as f:
        assert tomllib.load(f)["options"] == {"delay_p": [0.5, 0.5]}
    assert main(["run", str(d), "--config", str(resolved), "-q", "--out", str(tmp_path / "again.csv")]) == 0
    opt = (tmp_path / "opt.csv").read_text()
    assert (tmp_path / "again.csv").read_text() == opt
    assert (tmp_path / "preset.csv").read_text() != opt
