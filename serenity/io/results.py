"""Benchmark results as JSON: one writer for every ``benchmarks/bench_*.py``."""

from __future__ import annotations

import json
import os


def write_results(path: str, results: dict) -> None:
    """Write ``results`` as indented JSON to ``path`` (creating its folder) and say so."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(results, f, indent=2)
    print(f"wrote {path}")
