"""Benchmark results as JSON: one writer for every ``benchmarks/*.py`` and the commands that record
a run (``serenity bench --json``, ``serenity render --json``). Each file starts with where it came
from (:func:`serenity.io.provenance.provenance`: command, commit, machine, date)."""

from __future__ import annotations

import json
import os

from serenity.io.provenance import machine, provenance


def write_results(path: str, results: dict) -> None:
    """Write ``results`` as indented JSON to ``path`` (creating its folder) and say so. The
    provenance keys come first; a key ``results`` already has (a script's own ``command``) wins, and
    a script's own ``machine`` facts (a GPU's GL renderer, say) are added to the provenance's."""
    prov = provenance()
    out = {**prov, **results}
    own = results.get("machine")
    if isinstance(own, dict):  # a script's own machine facts add to the provenance's
        out["machine"] = {**prov["machine"], **own}
    elif own is not None:  # a bare description (a platform string) never replaces the provenance's facts
        out["machine"] = {**prov["machine"], "platform": str(own)}
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(out, f, indent=2)
    print(f"wrote {path}")


def machine_info() -> dict:
    """What a benchmark ran on (:func:`serenity.io.provenance.machine`): the CPU, the cores, the GPU,
    the platform, and the caches, the load average and the scheduler's session grouping, without
    which a figure cannot be compared with another run's."""
    return machine()
