"""The shipped type stub python/insnav/_core.pyi (with py.typed) against the
compiled module: every public name of insnav._core is in the stub and every
name of the stub exists, so editors and type checkers see the real API."""
from __future__ import annotations

import ast
from pathlib import Path

import insnav
from insnav import _core

STUB = Path(insnav.__file__).with_name("_core.pyi")


def _stub_names() -> set[str]:
    tree = ast.parse(STUB.read_text(encoding="utf-8"))
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


def test_stub_lists_exactly_the_extension_names():
    real = {n for n in dir(_core) if not n.startswith("_")} | {"__version__"}
    stub = _stub_names()
    assert not real - stub, f"in insnav._core but not in _core.pyi: {sorted(real - stub)}"
    assert not stub - real, f"in _core.pyi but not in insnav._core: {sorted(stub - real)}"


def test_stub_class_members_exist():
    tree = ast.parse(STUB.read_text(encoding="utf-8"))
    missing = []
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            obj = getattr(_core, node.name)
            for m in node.body:
                if isinstance(m, ast.FunctionDef) and not m.name.startswith("__") and not hasattr(obj, m.name):
                    missing.append(f"{node.name}.{m.name}")
    assert not missing, f"stub members missing from the extension: {missing}"
