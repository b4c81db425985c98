"""Docstrings, comments and docs point at files and modules that exist: every
repository path (``python/insnav/...py``, ``cpp/...hpp``, ``bench/...py``,
``docs/...md``, ``tests/...py``, ``scripts/...sh``) and every dotted
``insnav.<module>[.<name>]`` named in the code and the docs resolves."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "python" / "insnav"

PATH_RE = re.compile(r"(?<![\w/.-])((?:python/insnav|cpp|bench|docs|tests|scripts)/[\w/.-]*\w\.(?:py|hpp|cpp|md|sh|toml))")
# header paths relative to cpp/include/insnav, as the C++ comments write them ("engine/closed_loop.hpp")
HEADER_RE = re.compile(r"(?<![\w/.-])((?:math|earth|ins|filter|meas|engine|io|gnss)/\w+\.hpp)")
MODULE_RE = re.compile(r"(?<![\w.])insnav((?:\.[A-Za-z_]\w*)+)")


def _sources():
    if not PKG.is_dir():
        pytest.skip("needs the source tree")
    files = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), *sorted(PKG.rglob("*.py")),
             *sorted((REPO / "cpp").rglob("*.hpp")), *sorted((REPO / "cpp").rglob("*.cpp")),
             *sorted((REPO / "bench").glob("*.py")), *sorted((REPO / "scripts").glob("*.sh"))]
    return [f for f in files if f.is_file()]


def _module_resolves(parts: list[str]) -> bool:
    """insnav.a.b.c: a module path, or a module followed by a name defined in it."""
    for k in range(len(parts), -1, -1):
        base = PKG.joinpath(*parts[:k])
        mod = base.with_suffix(".py") if k else None
        pkg_init = base / "__init__.py"
        if k == 0 or (mod is not None and mod.is_file()) or pkg_init.is_file() or (k and base.with_suffix(".pyi").is_file()):
            if k == len(parts):
                return True
            src_file = mod if (mod is not None and mod.is_file()) else (
                pkg_init if pkg_init.is_file() else base.with_suffix(".pyi") if k else PKG / "__init__.py")
            name = parts[k]
            text = src_file.read_text(encoding="utf-8")
            if re.search(rf"(^|\W)(def|class)\s+{re.escape(name)}\b|^\s*{re.escape(name)}\s*[:=]|[\"']{re.escape(name)}[\"']"
                         rf"|^\s*(from\s+\S+\s+)?import\s+.*\b{re.escape(name)}\b", text, re.M):
                return True
            return False
    return False


def test_repository_paths_exist():
    stale = []
    for f in _sources():
        text = f.read_text(encoding="utf-8", errors="replace")
        for m in PATH_RE.finditer(text):
            p = m.group(1)
            if "*" in p or p.startswith(("docs/results/", "tests/data/")) and not (REPO / p).parent.is_dir():
                continue
            if not (REPO / p).exists():
                stale.append(f"{f.relative_to(REPO)}: {p}")
        for m in HEADER_RE.finditer(text):
            p = m.group(1)
            if not (REPO / "cpp" / "include" / "insnav" / p).exists() and not (REPO / "cpp" / p).exists():
                stale.append(f"{f.relative_to(REPO)}: {p}")
    assert not stale, "paths that do not exist:\n" + "\n".join(sorted(set(stale)))


def test_dotted_module_names_resolve():
    stale = []
    for f in _sources():
        text = f.read_text(encoding="utf-8", errors="replace")
        for m in MODULE_RE.finditer(text):
            parts = m.group(1).strip(".").split(".")
            if parts[0] in ("_core",):  # the compiled module: tests/test_core_stub.py checks its names
                continue
            parts = [p for p in parts if not p.startswith("__")] or parts  # module attributes (__file__, ...)
            if not parts or parts[0].startswith("__"):
                continue
            if not _module_resolves(parts):
                stale.append(f"{f.relative_to(REPO)}: insnav.{'.'.join(parts)}")
    assert not stale, "module names that do not resolve:\n" + "\n".join(sorted(set(stale)))
