"""Benchmark results as JSON: one writer for every ``benchmarks/bench_*.py``."""

from __future__ import annotations

import json
import os
import platform


def write_results(path: str, results: dict) -> None:
    """Write ``results`` as indented JSON to ``path`` (creating its folder) and say so."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(results, f, indent=2)
    print(f"wrote {path}")


def machine_info() -> dict:
    """What a benchmark ran on: the platform, the CPU's model, caches and AVX-512 flag
    (/proc/cpuinfo, sysfs), the core count, the load average when asked and whether the scheduler
    groups sessions. Runs on different hosts of the same virtual machine type, and on one host
    minutes apart, differ by more than most changes do; a figure read without this cannot be
    compared with another."""
    first = (_read("/proc/cpuinfo") or "").split("\n\n")[0]
    info = {k.strip(): v.strip() for k, _, v in (ln.partition(":") for ln in first.splitlines())}
    cache = {}
    for idx in range(4):
        base = f"/sys/devices/system/cpu/cpu0/cache/index{idx}"
        level, size = _read(f"{base}/level"), _read(f"{base}/size")
        if level and size and _read(f"{base}/type") != "Instruction":
            cache[f"l{level}"] = size
    try:
        load = list(os.getloadavg())
    except OSError:  # pragma: no cover - not POSIX
        load = None
    return {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "cpu_model": info.get("model name") or platform.processor() or platform.machine(),
            "cpu_family_model": [info.get("cpu family"), info.get("model")],
            "avx512f": "avx512f" in info.get("flags", "").split(), "cache": cache, "load_average": load,
            # 1: Linux shares the CPUs equally between sessions, so a busy neighbour halves a second thread
            "sched_autogroup": _read("/proc/sys/kernel/sched_autogroup_enabled")}


def _read(path: str) -> str | None:
    try:
        with open(path) as fh:
            return fh.read().strip()
    except OSError:
        return None
