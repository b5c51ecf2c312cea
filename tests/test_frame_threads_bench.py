"""benchmarks/bench_frame_threads.py: the per-thread CPU accounting it is built on, and a small run
that writes every group for both schedules (its figures are timings: nothing here asserts one)."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import threading
import time

_PATH = os.path.join(os.path.dirname(__file__), "..", "benchmarks", "bench_frame_threads.py")


def _module():
    spec = importlib.util.spec_from_file_location("bench_frame_threads", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_thread_cpu_time_counts_a_busy_thread_in_its_group():
    """A thread that spins for 0.3 s shows about 300 CPU-ms under its own id (the clock ticks are
    10 ms), and the groups follow the threads' names."""
    mod = _module()
    spun, done = threading.Event(), threading.Event()

    def spin():
        stop = time.perf_counter() + 0.3
        while time.perf_counter() < stop:
            pass
        spun.set()
        done.wait()

    worker = threading.Thread(target=spin, name="serenity-volumes_0")
    before = mod.thread_cpu_ms()
    worker.start()
    try:
        assert spun.wait(10)
        after = mod.thread_cpu_ms()
        names = {t.native_id: t.name for t in threading.enumerate()}
    finally:
        done.set()
        worker.join()
    tid = worker.native_id
    assert 150.0 <= after[tid][1] - before.get(tid, ("", 0.0))[1] <= 1000.0
    assert mod.group_of(after[tid][0], tid, names) == "volume worker"
    assert mod.group_of("python", threading.main_thread().native_id, names) == "main thread"
    assert mod.group_of("llvmpipe-0", 1, {}) == "llvmpipe rasteriser threads"


def test_frame_threads_bench_writes_both_schedules(tmp_path):
    mod = _module()
    out = tmp_path / "threads.json"
    assert mod.main(["--sizes", "64x36", "--frames", "3", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    for schedule in ("overlapped", "serial"):
        m = data["sizes"]["64x36"][schedule]
        assert set(m["cpu_ms_per_frame"]) == set(mod.GROUPS)
        assert all(v >= 0 and math.isfinite(v) for v in m["cpu_ms_per_frame"].values())
        assert m["cpu_ms_per_frame_total"] > 0
