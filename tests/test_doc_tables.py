"""The tables in README.md and docs/*.md are what ``tools/doc_tables.py`` prints from the committed
result JSON: a re-measured JSON whose tables were not rewritten (``--write``), or a hand-edited
table, fails here."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from serenity import config

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "tools" / "doc_tables.py"


def _module():
    spec = importlib.util.spec_from_file_location("doc_tables", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["doc_tables"] = mod
    spec.loader.exec_module(mod)
    return mod


dt = _module()


def test_every_doc_table_matches_its_json():
    out = subprocess.run([sys.executable, str(SCRIPT), "--check"], capture_output=True, text=True, cwd=ROOT,
                         timeout=300)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr


def test_the_docs_ask_for_the_headline_tables():
    """README's small frontier table and the benchmark page's tables are there to be checked."""
    asked = {}
    for path in dt.documents():
        for line in path.read_text().split("\n"):
            m = dt.OPEN.match(line.strip())
            if m:
                asked.setdefault(m.group(1), []).append(path.name)
    assert "README.md" in asked.get("frontier-summary", [])
    for name in ("frontier", "frame-stages-lpv-fast", "frame-stages-traced-probes", "stability", "cuda",
                 "accuracy-courtyard", "accuracy-cornell"):
        assert "benchmarks.md" in asked.get(name, []), name
    for name in ("kdtree", "kdtree-phases", "kdtree-counts"):
        assert "kdtree.md" in asked.get(name, []), name


@pytest.mark.parametrize("name", sorted(dt.TABLES))
def test_every_table_prints_from_the_committed_json(name):
    text = dt.render(name)
    lines = text.split("\n")
    assert lines[0].startswith("| ") or lines[0] == "```" or name == "frame-cost", text[:200]
    assert f"benchmarks/{dt.TABLES[name].sources[0]}" in lines[-1]


def test_fill_replaces_only_between_the_markers():
    doc = "intro\n<!-- table: frontier-summary -->\nold table\nmore\n<!-- /table -->\nafter\n"
    new = dt.fill(doc, "doc.md")
    assert new.startswith("intro\n<!-- table: frontier-summary -->\n| scene |")
    assert new.endswith("\n<!-- /table -->\nafter\n")
    assert "old table" not in new
    assert dt.fill(new, "doc.md") == new  # a filled document is a fixed point


@pytest.mark.parametrize("doc, message", [
    ("<!-- table: no-such-table -->\n<!-- /table -->\n", "doc.md:1: unknown table 'no-such-table'"),
    ("<!-- table: frontier -->\nx\n", "doc.md:1: table 'frontier' has no '<!-- /table -->' line"),
    ("x\n<!-- /table -->\n", "doc.md:2: '<!-- /table -->' without"),
    ("<!-- table: frontier -->\n<!-- table: cuda -->\n<!-- /table -->\n",
     "doc.md:2: table 'frontier' opened on line 1"),
])
def test_bad_markers_name_the_document_and_line(doc, message):
    with pytest.raises(dt.DocTableError, match=message.replace("(", r"\(").replace(")", r"\)")):
        dt.fill(doc, "doc.md")


def test_check_fails_with_a_diff_when_a_table_differs(tmp_path, monkeypatch, capsys):
    doc = tmp_path / "page.md"
    doc.write_text("<!-- table: cuda-agreement -->\n| stale |\n<!-- /table -->\n")
    monkeypatch.setattr(dt, "documents", lambda: [doc])
    monkeypatch.setattr(dt, "ROOT", tmp_path)
    assert dt.run(write=False) == 1
    out = capsys.readouterr().out
    assert "-| stale |" in out and "+| scene | size |" in out
    assert dt.run(write=True) == 0 and "| stale |" not in doc.read_text()
    assert dt.run(write=False) == 0


def test_a_missing_result_file_is_named(tmp_path, monkeypatch):
    monkeypatch.setattr(dt, "BENCHMARKS", tmp_path)
    with pytest.raises(dt.DocTableError, match="frontier.json is missing: `make figures` writes it"):
        dt.render("frontier")


def test_former_preset_names_read_as_todays():
    """Results recorded under the presets' former names print with the current ones."""
    frontier = json.loads((ROOT / "benchmarks" / "results" / "frontier.json").read_text())
    names = {o["name"] for c in frontier["cases"] for o in c["ours"]}
    table = dt.render("frontier")
    for name in names:
        assert f"`{dt.preset(name)}`" in table
    assert dt.preset("low") == "traced-probes" and dt.preset("medium") == "lpv-fast" and dt.preset("high") == "lpv"
    assert dt.PRESET_NAMES == config.PRESET_ALIASES and dt.DEFAULT_PRESET == config.DEFAULT_QUALITY
