"""benchmarks/experiments/bench_llvmpipe_branches.py runs and writes every (body, placement) it documents
(its figures are timings: docs/architecture.md reads the committed JSON; nothing here asserts a time)."""

from __future__ import annotations

import importlib.util
import json
import math
import os

_PATH = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "experiments",
                     "bench_llvmpipe_branches.py")


def test_branch_bench_writes_every_case(tmp_path):
    spec = importlib.util.spec_from_file_location("bench_llvmpipe_branches", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "branches.json"
    assert mod.main(["--size", "64x36", "--reps", "2", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data["ms"]) == set(mod.BODIES)
    for body in mod.BODIES:
        assert set(data["ms"][body]) == set(mod.PLACEMENTS)
        assert all(v > 0 and math.isfinite(v) for v in data["ms"][body].values())
        assert set(data["fraction_of_always"][body]) == set(mod.PLACEMENTS) - {"none", "always"}
