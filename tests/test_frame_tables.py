"""The README's Table-1 section and its quick-start output block are what ``benchmarks/frame_tables.py``
prints from the committed JSONs: a re-run of the benches that is not copied into the README fails here."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "benchmarks" / "frame_tables.py"


def _run(*args: str, script: Path = SCRIPT) -> str:
    out = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, cwd=ROOT,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_readme_table1_is_the_committed_run():
    printed = _run()
    table = printed.split("## Table 1", 1)[1].split("\n\n", 2)[1].strip()
    assert table.startswith("| stage | ours, overlapped (ms)")
    assert table in (ROOT / "README.md").read_text(), "README's Table 1 differs from frame_bench.json"
    tiles = printed.split("## Round 15", 1)[1].split("\n\n", 2)[1].strip()
    assert tiles.startswith("| schedule, size") and tiles in (ROOT / "README.md").read_text()
    assert "`frame_repeat_320.json`" in printed


def test_readme_render_block_is_the_committed_run():
    block = _run("--render").strip()
    assert block.startswith("scene courtyard:") and "frame (wall clock)" in block
    assert block in (ROOT / "README.md").read_text(), "README's quick-start block differs from render_output.json"


def test_readme_kdtree_phases_table_is_the_committed_run():
    """The kd-tree section's table of one query's phases is ``kdtree_phases.py --table`` of the
    committed JSON."""
    table = _run("--table", str(ROOT / "benchmarks" / "results" / "kdtree_phases.json"),
                 script=ROOT / "benchmarks" / "kdtree_phases.py").strip()
    assert table.startswith("| phase | incoherent, 1 thread")
    assert table in (ROOT / "README.md").read_text(), "README's kd-tree phases table differs from kdtree_phases.json"


def test_readme_kdtree_table_is_the_committed_runs():
    """The kd-tree section's main table is ``bench_kdtree.py --table`` of the two committed runs."""
    results = ROOT / "benchmarks" / "results"
    table = _run("--table", str(results / "kdtree.json"), str(results / "kdtree_round30_r1.json"),
                 script=ROOT / "benchmarks" / "bench_kdtree.py").strip()
    assert table.startswith("| figure (one value per run")
    assert table in (ROOT / "README.md").read_text(), "README's kd-tree table differs from kdtree.json"
