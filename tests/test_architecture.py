"""The package's layers, read from the source: every ``import`` in
python/insnav (at module level or inside a function) goes to the same layer
or a lower one, and no two modules import each other, directly or around a
circle.  A new module must be given a layer here.

    0  units errors _validate _atomic _threads _npz _imu_scan _median _progress _malloc _toml earth registry _core scenarios (data files), the package root
       (its public names are loaded lazily, by strings)
    1  config data
    2  gnss ins
    3  sim
    4  io
    5  filters      (the only callers of _core.run_*)
    6  analysis calib
    7  cli, sim.cli, __main__
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "python" / "insnav"

LAYERS = [
    ("insnav.__main__", 7), ("insnav.sim.cli", 7), ("insnav.cli", 7),
    ("insnav.analysis", 6), ("insnav.calib", 6), ("insnav._outputs", 5), ("insnav.filters", 5), ("insnav.io", 4), ("insnav.sim", 3),
    ("insnav.gnss", 2), ("insnav.ins", 2), ("insnav.config", 1), ("insnav.data", 1), ("insnav.scenarios", 0),
    ("insnav.units", 0), ("insnav.errors", 0), ("insnav._validate", 0), ("insnav._atomic", 0), ("insnav._threads", 0), ("insnav._npz", 0), ("insnav._imu_scan", 0), ("insnav._median", 0), ("insnav._progress", 0), ("insnav._malloc", 0),
    ("insnav._toml", 0), ("insnav.earth", 0), ("insnav.registry", 0), ("insnav._core", 0),
]


def layer(mod: str) -> int:
    if mod == "insnav":
        return 0
    for prefix, n in LAYERS:
        if mod == prefix or mod.startswith(prefix + "."):
            return n
    raise AssertionError(f"module {mod} has no layer: add it to LAYERS in {__file__}")


def modules() -> dict[str, Path]:
    out = {}
    for p in sorted(PKG.rglob("*.py")):
        rel = p.relative_to(PKG.parent).with_suffix("")
        name = ".".join(rel.parts)
        out[name.removesuffix(".__init__")] = p
    return out


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Modules of the package that `name` imports (a name imported from a
    package counts as its submodule when there is one)."""
    is_pkg = path.name == "__init__.py"
    here = name if is_pkg else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "insnav"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "insnav":
                continue
            subs = {f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in known}
            if subs:
                out |= subs
                if len(subs) < len(node.names):
                    out.add(mod)
            else:
                out.add(mod)
    out.discard(name)
    return {m for m in out if m in known or m == "insnav._core"}


@pytest.fixture(scope="module")
def graph():
    mods = modules()
    known = set(mods)
    return {n: imports(n, p, known) for n, p in mods.items()}


def test_every_module_has_a_layer(graph):
    for m in graph:
        layer(m)


def test_no_upward_imports(graph):
    bad = [f"{a} (layer {layer(a)}) imports {b} (layer {layer(b)})"
           for a, deps in graph.items() for b in deps if layer(b) > layer(a)]
    assert not bad, "upward imports:\n" + "\n".join(sorted(bad))


def test_no_import_circles(graph):
    # edges between modules of one package and their own package __init__ are
    # how a package re-exports; a circle through them is still a circle
    state: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                circles.append(" -> ".join(stack[stack.index(d):] + [d]))
            elif d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert not circles, "import circles:\n" + "\n".join(circles)


def test_the_checks_see_a_violation(tmp_path):
    """The two checks would fail on an upward import and on a circle."""
    g = {"insnav.data.nav": {"insnav.filters.loose"}, "insnav.filters.loose": {"insnav.data.nav"}}
    assert any(layer(b) > layer(a) for a, deps in g.items() for b in deps)
    with pytest.raises(AssertionError, match="circles"):
        test_no_import_circles(g)


@pytest.mark.parametrize("order", ["names first", "modules first", "modules reversed"])
def test_public_names_keep_their_identity(order):
    """insnav.evaluate, insnav.montecarlo, insnav.run, ... stay the public
    functions / classes whatever is imported before or after them (a public
    name equal to a submodule's would be rebound to the module by an import)."""
    import subprocess
    import sys

    code = f"""
import importlib, inspect, pkgutil, types
import insnav
names = [n for n in insnav.__all__ if n != "__version__"]
mods = sorted(m.name for m in pkgutil.walk_packages(insnav.__path__, "insnav.") if m.name != "insnav.__main__")
order = {order!r}
first = {{n: getattr(insnav, n) for n in names}} if order == "names first" else None
for m in (reversed(mods) if order == "modules reversed" else mods):
    importlib.import_module(m)
after = {{n: getattr(insnav, n) for n in names}}
for n, v in after.items():
    assert not isinstance(v, types.ModuleType), (n, v)
    assert callable(v), n
    assert first is None or first[n] is v, n
from insnav.analysis.evaluate import evaluate
from insnav.analysis import montecarlo as mc_mod
assert insnav.evaluate is evaluate and callable(insnav.montecarlo) and insnav.montecarlo is not mc_mod
print(len(names), len(mods))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_no_public_name_is_a_submodule_name():
    """The cause of a rebinding, checked statically: importing ``insnav.X``
    sets the attribute ``insnav.X`` to the module, so no public name may be
    the name of a module or package directly under ``insnav``."""
    import pkgutil

    import insnav

    top = {m.name for m in pkgutil.iter_modules(insnav.__path__)}
    names = set(insnav.__all__) - {"__version__"}
    assert not names & top, names & top
    assert {"evaluate", "montecarlo", "run", "simulate", "load_solution"} <= names


def _public_names():
    import insnav

    return [n for n in insnav.__all__ if n != "__version__"]


@pytest.mark.parametrize("name", _public_names())
def test_each_name_after_its_own_module_and_everything_else(name):
    """Per public name, in a fresh interpreter: its defining module imported
    first (``from insnav.analysis.evaluate import errors`` style), then the
    name, then ``from insnav import *`` and every other module; the name is
    the same object throughout and the same as in its module."""
    import subprocess
    import sys

    import insnav

    mod = insnav._LAZY[name]
    code = f"""
import importlib, pkgutil, types
m = importlib.import_module({mod!r})
import insnav
f = insnav.{name}
assert f is getattr(m, {name!r}) and not isinstance(f, types.ModuleType), f
from insnav import {name} as g
assert g is f
ns = {{}}
exec("from insnav import *", ns)
assert ns[{name!r}] is f
for mm in pkgutil.walk_packages(insnav.__path__, "insnav."):
    if mm.name != "insnav.__main__":
        importlib.import_module(mm.name)
assert insnav.{name} is f, insnav.{name}
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_the_reported_sequence_now_works(tmp_path):
    """``from insnav.analysis.evaluate import errors`` (the evaluate module),
    then ``insnav.evaluate(...)`` and ``insnav.montecarlo`` are still the
    functions; the old module path ``insnav.evaluate`` is not a module."""
    import subprocess
    import sys

    code = """
import insnav
from insnav.analysis.evaluate import errors
from insnav.analysis import montecarlo
ds = insnav.simulate("seed000-sim", seed=1)
sol = insnav.run(ds, filter="ekf", output_decimation=20)
res = insnav.evaluate(sol, ds.truth, [(50.0, 90.0)])
assert res["horizontal_rms_m"] > 0 and errors(sol, ds.truth)["pos_n_m"].shape[1] == 3
assert callable(insnav.montecarlo) and insnav.montecarlo is montecarlo.montecarlo
try:
    import insnav.evaluate
except ModuleNotFoundError:
    pass
else:
    raise AssertionError("insnav.evaluate is a module again")
assert callable(insnav.evaluate)
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr


def test_one_navigation_trajectory_schema():
    """Truth, Solution and the free-inertial trajectory declare the navigation
    fields once (NavTrajectory) and spell their first columns the same way."""
    import dataclasses

    import insnav
    from insnav.data.dataset import Truth
    from insnav.data.nav import NAV_COLUMNS, NAV_FIELDS, NavTrajectory

    for cls in (Truth, insnav.Solution, insnav.Trajectory):
        assert issubclass(cls, NavTrajectory)
        assert tuple(f.name for f in dataclasses.fields(cls))[:len(NAV_FIELDS)] == NAV_FIELDS
        assert cls.COLUMNS[:len(NAV_COLUMNS)] == NAV_COLUMNS
    assert insnav.Trajectory is insnav.NavTrajectory
