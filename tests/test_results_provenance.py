"""Every result JSON says where it came from: the command, the commit, the CPU and its core count
(``serenity.io.provenance``), and no result file is named after when it was made."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from serenity.io import provenance as prov
from serenity.io.results import write_results

ROOT = Path(__file__).resolve().parent.parent
RESULT_DIRS = (ROOT / "benchmarks" / "results", ROOT / "benchmarks" / "experiments" / "results")
RESULTS = sorted(p for d in RESULT_DIRS for p in d.rglob("*.json"))
NARRATION = re.compile(r"round|issue|review|_r\d|_run\d|rerun|scratch", re.IGNORECASE)


def test_there_are_results_to_check():
    assert len(RESULTS) > 20
    assert ROOT / "benchmarks" / "results" / "frontier.json" in RESULTS


@pytest.mark.parametrize("path", RESULTS, ids=lambda p: str(p.relative_to(ROOT / "benchmarks")))
def test_every_result_records_its_provenance(path):
    data = json.loads(path.read_text())
    missing = [k for k in ("command", "commit") if not data.get(k)]
    machine = data.get("machine")
    if not isinstance(machine, dict):
        missing.append("machine")
    else:
        missing += [f"machine.{k}" for k in ("cpu", "cores") if machine.get(k) in (None, "")]
    assert not missing, f"{path.relative_to(ROOT)} lacks {', '.join(missing)}"
    assert isinstance(data["command"], str) and isinstance(data["commit"], str)


def test_no_result_is_named_after_a_round_an_issue_or_a_run():
    names = [str(p.relative_to(ROOT)) for d in RESULT_DIRS for p in d.rglob("*")
             if NARRATION.search(str(p.relative_to(d)))]
    assert not names, names


def test_provenance_of_this_process():
    p = prov.provenance(["benchmarks/bench_frontier.py", "--sizes", "320x180", "a b"])
    assert p["command"] == "python benchmarks/bench_frontier.py --sizes 320x180 'a b'"
    assert re.fullmatch(r"[0-9a-f]{40}(-dirty)?", p["commit"])
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    assert p["commit"].startswith(head)
    m = p["machine"]
    assert isinstance(m["cpu"], str) and m["cpu"] and isinstance(m["cores"], int) and m["cores"] >= 1
    assert "gpu" in m and "platform" in m
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00", p["date"])


def test_command_of_the_installed_command():
    assert prov.command(["/x/.venv/bin/serenity", "bench", "--size", "320x180"]) == "serenity bench --size 320x180"
    assert prov.command([str(ROOT / "tools" / "doc_tables.py"), "--check"]) == "python tools/doc_tables.py --check"


def test_gpu_name_through_warp_when_it_is_loaded(monkeypatch):
    class Device:
        name = "NVIDIA Test GPU"

    class FakeWarp:
        @staticmethod
        def get_cuda_device_count():
            return 1

        @staticmethod
        def get_device(name):
            assert name == "cuda:0"
            return Device()

    monkeypatch.setitem(sys.modules, "warp", FakeWarp)
    assert prov.gpu_name() == "NVIDIA Test GPU"
    monkeypatch.setattr(FakeWarp, "get_cuda_device_count", staticmethod(lambda: 0))
    assert prov.gpu_name() is None


def test_write_results_puts_provenance_first_and_keeps_the_scripts_own_facts(tmp_path):
    path = tmp_path / "sub" / "r.json"
    write_results(str(path), {"figure": 1.5, "machine": {"gl_renderer": "llvmpipe"}})
    data = json.loads(path.read_text())
    assert list(data)[:4] == ["command", "commit", "machine", "date"]
    assert data["figure"] == 1.5
    assert data["machine"]["gl_renderer"] == "llvmpipe" and data["machine"]["cpu"] and data["machine"]["cores"]
    write_results(str(path), {"command": "python x.py --own"})
    assert json.loads(path.read_text())["command"] == "python x.py --own"
