"""Freshness of the results documents (docs/results/*.md): each names the
commit it was generated at and the files its numbers depend on
(bench/_stamps.py); a document whose script or core dependencies changed
after that commit without being regenerated fails here.  Needs the git
history (skips on a shallow clone or without git)."""
from __future__ import annotations

import importlib.util
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("_stamps", ROOT / "bench" / "_stamps.py")
stamps = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(stamps)
DOCS = sorted(p.name for p in (ROOT / "docs" / "results").glob("*.md"))


def test_every_document_has_a_dependency_list():
    assert DOCS, "no results documents found"
    assert sorted(set(DOCS) - set(stamps.DEPENDS)) == []
    assert sorted(set(stamps.DEPENDS) - set(DOCS)) == []
    for doc in DOCS:
        deps = stamps.depends(doc)
        assert deps[0].startswith("bench/"), (doc, deps[0])  # the generator (or the quoted script) first
        assert not any(d.endswith("/") or d in ("cpp", "python") for d in deps), doc  # files, not trees


@pytest.mark.parametrize("doc", DOCS)
def test_document_is_fresh(doc):
    why = stamps.history_problem()
    if why:
        pytest.skip(f"stamps not checked: {why}")
    why_stale = stamps.check(doc)
    if why_stale and doc in stamps.HAND_WRITTEN:
        pytest.skip(f"hand-written document, re-measure by hand: {why_stale}")
    assert why_stale is None, why_stale


@pytest.mark.skipif(shutil.which("git") is None, reason="git not installed")
def test_stamp_detects_a_changed_dependency(tmp_path, monkeypatch):
    monkeypatch.setenv("GIT_CONFIG_NOSYSTEM", "1")
    """In a scratch repository: fresh after generation, stale once a listed
    file changes, fresh again when regenerated; an unlisted file does not matter."""
    def git(*a):
        subprocess.run(["git", *a], cwd=tmp_path, check=True, capture_output=True)

    git("init", "-q")
    git("config", "user.email", "t@t")
    git("config", "user.name", "t")
    (tmp_path / "docs" / "results").mkdir(parents=True)
    (tmp_path / "gen.py").write_text("a = 1\n")
    (tmp_path / "other.py").write_text("b = 1\n")
    monkeypatch.setattr(stamps, "ROOT", tmp_path)
    monkeypatch.setattr(stamps, "RESULTS", tmp_path / "docs" / "results")
    monkeypatch.setattr(stamps, "DEPENDS", {"x.md": ("gen.py",)})
    stamps._changed_since.cache_clear()
    stamps.history_problem.cache_clear()
    git("add", "-A")
    git("commit", "-qm", "code")
    doc = tmp_path / "docs" / "results" / "x.md"
    doc.write_text("# x\n" + stamps.stamp("x.md"))
    git("add", "-A")
    git("commit", "-qm", "doc")
    assert stamps.history_problem() is None
    assert stamps.check("x.md") is None
    (tmp_path / "other.py").write_text("b = 2\n")
    git("commit", "-qam", "unrelated")
    stamps._changed_since.cache_clear()
    assert stamps.check("x.md") is None
    (tmp_path / "gen.py").write_text("a = 2\n")
    git("commit", "-qam", "dependency")
    stamps._changed_since.cache_clear()
    assert "stale" in stamps.check("x.md") and "gen.py" in stamps.check("x.md")
    (tmp_path / "gen.py").write_text("a = 3\n")  # uncommitted change at generation time
    doc.write_text("# x\n" + stamps.stamp("x.md"))
    assert "uncommitted" in stamps.check("x.md")
    git("commit", "-qam", "dependency again")
    doc.write_text("# x\n" + stamps.stamp("x.md"))
    stamps._changed_since.cache_clear()
    assert stamps.check("x.md") is None
    doc.write_text("# x\n")
    assert "no stamp" in stamps.check("x.md")
    stamps._changed_since.cache_clear()
    stamps.history_problem.cache_clear()
