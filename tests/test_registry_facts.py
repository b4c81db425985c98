"""The registry's facts against the runners: every keyword option of every
runner is reachable through insnav.run() for the couplings that runner serves
(and nothing else is listed), so an option a runner accepts cannot be
refused by run() with a message naming another filter."""
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
    if any(p.kind is p.VAR_KEYWORD for p in params):
        from insnav.filters.delay import run_delayed

        assert fn.__name__ == "run_delay", fn  # the one forwarding runner
        params = [p for p in inspect.signature(run_delayed).parameters.values()
                  if p.name not in ("dataset", "filter", "config")]
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
