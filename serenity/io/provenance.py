"""Where a result came from: the command that produced it, the git commit it ran at, the machine
and the date. Every result JSON carries these four keys at its top (``write_results`` merges them
in), so a figure is never quoted without them:

    {"command": "python benchmarks/bench_frontier.py --no-progress",
     "commit": "5f1c…e2" (+ "-dirty" when the working tree had uncommitted changes),
     "machine": {"cpu": "Intel(R) Xeon(R) Processor (family 6 model 167)", "cores": 2, "gpu": null,
                 "platform": "Linux-…", …},
     "date": "2026-12-07T15:19:00+00:00"}

``machine`` also keeps what a benchmark's reader needs to compare two runs: the CPU's caches and
AVX-512 flag, the load average and whether Linux groups the CPUs' time by session (hosts of one
virtual machine type, and one host minutes apart, differ by more than most changes do).
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import subprocess
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
"""The checkout this package runs from (where ``git`` is asked for the commit)."""


def provenance(argv: list[str] | None = None) -> dict:
    """``command``, ``commit``, ``machine`` and ``date`` of a result produced now by ``argv``
    (default: this process's ``sys.argv``)."""
    return {"command": command(argv), "commit": commit(), "machine": machine(),
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def command(argv: list[str] | None = None) -> str:
    """The command line as a person would type it from the repository's root: ``python
    benchmarks/x.py …`` for a script, ``serenity …`` for the installed command."""
    argv = list(sys.argv if argv is None else argv)
    if not argv or not argv[0]:
        return "python"
    head = argv[0]
    if head.endswith(".py"):
        path = os.path.abspath(head)
        rel = os.path.relpath(path, REPO)
        head = "python " + (path if rel.startswith("..") else rel)
    elif head == "-c":
        head = "python -c"
    elif head == "-m":
        head = "python -m"
    else:
        head = os.path.basename(head)
    return " ".join([head, *(shlex.quote(a) for a in argv[1:])])


def commit() -> str | None:
    """``git rev-parse HEAD`` of the checkout, with ``-dirty`` when tracked files differ from it;
    None outside a git checkout (an installed package)."""
    try:
        head = subprocess.run(["git", "-C", REPO, "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


def machine() -> dict:
    """What a result ran on: ``cpu`` (the model name from /proc/cpuinfo, with its family and model
    numbers: virtual machines often name only the vendor), ``cores`` (the cores this process may
    run on), ``gpu`` (the first CUDA device's name, else None), ``platform``; and the details a
    benchmark's reader compares runs by (caches, AVX-512, load average, Linux' session grouping)."""
    first = (_read("/proc/cpuinfo") or "").split("\n\n")[0]
    info = {k.strip(): v.strip() for k, _, v in (ln.partition(":") for ln in first.splitlines())}
    model = info.get("model name") or platform.processor() or platform.machine()
    family = [info.get("cpu family"), info.get("model")]
    cpu = f"{model} (family {family[0]} model {family[1]})" if None not in family else model
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
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count()
    return {"cpu": cpu, "cores": cores, "gpu": gpu_name(), "platform": platform.platform(),
            "python": platform.python_version(), "cpu_model": model, "cpus": os.cpu_count(),
            "cpu_family_model": family, "avx512f": "avx512f" in info.get("flags", "").split(),
            "cache": cache, "load_average": load,
            # 1: Linux shares the CPUs equally between sessions, so a busy neighbour halves a second thread
            "sched_autogroup": _read("/proc/sys/kernel/sched_autogroup_enabled")}


def gpu_name() -> str | None:
    """The first CUDA device's name: through Warp when the process has imported it (nothing is
    imported here), else ``nvidia-smi``; None without one."""
    wp = sys.modules.get("warp")
    if wp is not None:
        try:
            return wp.get_device("cuda:0").name if wp.get_cuda_device_count() > 0 else None
        except Exception:  # noqa: BLE001 - a broken driver means no usable GPU
            return None
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                             text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    names = out.stdout.strip().splitlines() if out.returncode == 0 else []
    return names[0].strip() if names else None


def _read(path: str) -> str | None:
    try:
        with open(path) as fh:
            return fh.read().strip()
    except OSError:
        return None
