"""The documentation site builds (scripts/docs.sh: Sphinx with warnings as
errors) and holds what it promises: every tutorial executed with real
outputs, every public name in the API reference, every sub-command in the
CLI reference, every configuration key in the configuration reference; and
the release metadata (single-sourced version, changelog, citation) agree."""
from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO, SHARED_DATA, missing_capability

DOCS = REPO / "docs"
TUTORIALS = sorted(p.stem for p in (DOCS / "tutorials").glob("*.md"))


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    for mod in ("sphinx", "myst_nb", "numpydoc", "furo"):
        try:
            __import__(mod)
        except ImportError as exc:
            missing_capability("docs", f"{mod} is not importable ({exc})")
    if not SHARED_DATA.is_dir():
        pytest.skip(f"the tutorials read ../shared/data, not found at {SHARED_DATA} (set INSNAV_SHARED_DATA)")
    prebuilt = os.environ.get("INSNAV_DOCS_PREBUILT")  # a site scripts/docs.sh built already (development)
    if prebuilt:
        return Path(prebuilt).resolve()
    out = tmp_path_factory.mktemp("docs") / "html"
    env = dict(os.environ, PYTHON=sys.executable, INSNAV_SHARED_DATA=str(SHARED_DATA))
    r = subprocess.run(["bash", str(REPO / "scripts" / "docs.sh"), str(out)], cwd=REPO, env=env,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, (r.stdout[-3000:] + "\n" + r.stderr[-6000:])
    return out


def _text(html: str) -> str:
    import html as _html

    # (Sphinx typesets "--" as an en dash)
    return re.sub(r"\s+", " ", _html.unescape(re.sub(r"<[^>]+>", " ", html))).replace("\u2013", "--")


def test_every_tutorial_executed_with_outputs(site):
    assert TUTORIALS == sorted(["own_csv", "kfgins", "rinex_tight", "smoother_constraints", "seed_papers", "dask"])
    for name in TUTORIALS:
        html = (site / "tutorials" / f"{name}.html").read_text(encoding="utf-8")
        n_cells = len(re.findall(r'class="cell docutils container"', html))
        n_out = len(re.findall(r'class="cell_output docutils container"', html))
        assert n_cells >= 3 and n_out >= 2, (name, n_cells, n_out)
        assert "Traceback" not in html, name  # (an error in a cell also fails the build itself)
    for name in ("own_csv", "smoother_constraints"):  # the figures are drawn, inline
        html = (site / "tutorials" / f"{name}.html").read_text(encoding="utf-8")
        imgs = re.findall(r'<img[^>]+src="(\.\./_images/[^"]+\.png)"', html)
        assert imgs and all((site / "tutorials" / i).resolve().stat().st_size > 5000 for i in imgs), (name, imgs)
    # the outputs are the numbers the code computed, e.g. KF-GINS vs insnav on the same track
    k = _text((site / "tutorials" / "kfgins.html").read_text(encoding="utf-8"))
    m = re.search(r"insnav EKF horizontal RMS ([0-9.]+) m.*?KF-GINS horizontal RMS ([0-9.]+) m", k)
    assert m and 0 < float(m.group(1)) < 0.05 and 0 < float(m.group(2)) < 0.05, k[:2000]
    d = _text((site / "tutorials" / "dask.html").read_text(encoding="utf-8"))
    assert "2 workers at tcp://127.0.0.1:" in d and "run for run equal to the local backend: True" in d


def _inventory(site):
    from sphinx.util.inventory import InventoryFile

    with open(site / "objects.inv", "rb") as f:
        inv = InventoryFile.load(f, "", os.path.join)
    return {name for entries in inv.values() for name in (entries.keys() if hasattr(entries, "keys") else entries)}


def test_api_reference_has_every_public_name(site):
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import insnav_docs
    finally:
        sys.path.pop(0)
    objects = _inventory(site)
    documented = {n.rsplit(".", 1)[-1] for n in objects}
    missing = []
    for mod in insnav_docs.public_modules():
        for name in insnav_docs.public_names(mod):
            if name == "__version__":
                continue
            if f"{mod}.{name}" not in objects and name not in documented:
                missing.append(f"{mod}.{name}")
    assert not missing, f"public names without an API entry: {missing[:20]} ({len(missing)})"
    import insnav

    for name in insnav.__all__:
        if name != "__version__":
            assert any(o.endswith("." + name) for o in objects), name
    assert len(objects) > 300  # the reference is the whole package, not a few pages


def test_cli_reference_has_every_subcommand(site):
    from insnav.cli import build_parser

    html = (site / "reference" / "cli.html").read_text(encoding="utf-8")
    text = _text(html)
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    assert len(sub.choices) >= 8
    for name, parser in sub.choices.items():
        assert f'id="cli-{name}"' in html, name
        assert f"usage: insnav {name}" in text, name
        for action in parser._actions:  # every option of every command, as argparse prints it
            for opt in action.option_strings:
                assert opt in text, (name, opt)


def test_config_reference_has_every_key(site):
    from insnav import config
    from insnav.gnss.spp import SppOptions
    from insnav.gnss.weighting import Weighting

    text = _text((site / "reference" / "config.html").read_text(encoding="utf-8"))
    tables = {"imu", "constraints", "robust"}  # RunConfig fields that are TOML tables: sections of their own
    keys = [f.name for f in dataclasses.fields(config.RunConfig) if f.name not in tables]
    for cls in (config.Constraints, config.Robust, SppOptions, Weighting):
        keys += [f.name for f in dataclasses.fields(cls) if not f.name.startswith("_")]
    keys += list(config._USER_UNITS) + list(config.SANITIZE_DEFAULTS)
    missing = [k for k in keys if f" {k} " not in text]
    assert not missing, missing
    html = (site / "reference" / "config.html").read_text(encoding="utf-8")
    for table in ("top-level", *sorted(tables), "sanitize", "gnss", "spp"):
        assert f'id="config-{table}"' in html, table
    # a default and a description straight from the schema
    assert re.search(r" gate_reopen_after 5 int Lock-out recovery", text)


def test_included_documents_are_in_the_site(site):
    for md in list(DOCS.glob("*.md")) + list((DOCS / "results").glob("*.md")):
        html = site / md.relative_to(DOCS).with_suffix(".html")
        assert html.is_file(), md
        src = md.read_text(encoding="utf-8")
        if src.startswith("```{include}"):
            continue  # (changelog.md: CHANGELOG.md included)
        first_heading = next(ln for ln in src.splitlines() if ln.startswith("# "))
        assert _text(first_heading[2:]).strip()[:30] in _text(html.read_text(encoding="utf-8")), md


def test_version_single_sourced_and_changelog_citation():
    import tomllib

    import insnav
    import insnav._core

    py = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert "version" not in py["project"] and "version" in py["project"]["dynamic"]
    assert py["tool"]["scikit-build"]["metadata"]["version"]["input"] == "python/insnav/__init__.py"
    cmake = (REPO / "CMakeLists.txt").read_text()
    assert re.search(r"project\(insnav VERSION \$\{INSNAV_VERSION_FROM_PY\}", cmake)
    assert not re.search(r"VERSION\s+\d+\.\d+\.\d+", cmake.replace("cmake_minimum_required(VERSION 3.18)", ""))
    init = (REPO / "python" / "insnav" / "__init__.py").read_text()
    assert len(re.findall(r'^__version__ = "(\d+\.\d+\.\d+)"$', init, re.M)) == 1
    assert insnav._core.__version__ == insnav.__version__  # compiled with the version CMake read
    changelog = (REPO / "CHANGELOG.md").read_text()
    assert changelog.startswith("# Changelog") and "## [Unreleased]" in changelog and "Keep a Changelog" in changelog
    cff = (REPO / "CITATION.cff").read_text()
    assert f"version: {insnav.__version__}" in cff and cff.count("  - type: article") == 4
    for doi in ("10.3788/OPE.20162404.0835", "10.3969/j.issn.1673-3819.2022.01.003",
                "10.3969/j.issn.1001-3695.2012.10.075"):
        assert doi in cff
