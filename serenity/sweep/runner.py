"""Run a sweep on a Dask cluster and keep its results directory consistent.

    result = run_sweep(load_spec("examples/sweep_day.toml"), "serenity_out/sweep_day")
    result = run_sweep(spec, out, scheduler="tcp://10.0.0.5:8786")     # an existing cluster

The results directory::

    manifest.json            spec hash + spec, and per task key: kind, inputs, status (done | error),
                             error (one line), outputs (relative paths), timings, metrics, worker/host/pid,
                             worker_deaths (workers that died running it before it finished)
    frames/<key>.png|.exr    our frame (PNG at the sweep's exposure; EXR layer "beauty", linear radiance)
    references/<key>.exr|.png
    compare/<key>_flip.png   FLIP error map (magma)
    metrics.csv, metrics.json, contact_sheet.png, time_of_day_*.gif   (see ``serenity.sweep.outputs``)

Every file is written atomically (a temporary file in the same directory, then ``os.replace``), and
a task's manifest entry only after its files: a sweep interrupted at any moment leaves finished
tasks recorded and nothing half-written. Re-running the same spec skips the tasks whose entry says
done and whose files exist; failed tasks are skipped too unless ``retry_errors``. Only the client
writes here; workers return arrays.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone

import numpy as np
from tqdm import tqdm

from serenity.device import cpu_threads
from serenity.errors import SerenityError
from serenity.eval.metrics import tonemap
from serenity.io.atomic import atomic_write
from serenity.io.exr import read_exr, write_exr
from serenity.io.png import write_png
from serenity.optional import require
from serenity.sweep import outputs
from serenity.sweep import tasks as T
from serenity.sweep.files import write_json
from serenity.sweep.spec import SweepSpec, Task, expand
from serenity.sweep.tasks import one_line

MANIFEST = "manifest.json"
MANIFEST_FORMAT = 1
_MANIFEST_EVERY_S = 1.0
EVENT_TOPIC = "serenity-sweep"


@dataclass
class SweepResult:
    """What a sweep run did. ``manifest`` is the manifest as written."""

    out: str
    manifest: dict
    ran: list[str] = field(default_factory=list)
    """Keys of the tasks run this time."""
    skipped: list[str] = field(default_factory=list)
    """Keys found finished (or failed, without ``retry_errors``) in the manifest."""
    failed: list[str] = field(default_factory=list)
    """Keys whose entry says error (this run's or an earlier one's)."""
    outputs: list[str] = field(default_factory=list)
    """The summary files (CSV, JSON, contact sheet, animations) written this run."""


def read_manifest(out: str) -> dict:
    """The manifest under ``out`` (an empty one when there is none)."""
    path = os.path.join(out, MANIFEST)
    if not os.path.exists(path):
        return {"format": MANIFEST_FORMAT, "tasks": {}}
    try:
        with open(path) as f:
            m = json.load(f)
    except (OSError, ValueError) as e:
        raise SerenityError(f"{path}: unreadable manifest ({one_line(e)}); move it away to start afresh") from None
    if not isinstance(m, dict) or not isinstance(m.get("tasks"), dict) or m.get("format") != MANIFEST_FORMAT:
        raise SerenityError(f"{path}: not a sweep manifest of format {MANIFEST_FORMAT}; move it away to start afresh")
    return m


def _is_finished(record: dict | None, out: str) -> bool:
    if not record or record.get("status") != "done":
        return False
    return all(os.path.exists(os.path.join(out, p)) for p in record.get("outputs", {}).values())


def default_out(spec: SweepSpec) -> str:
    return spec.out or os.path.join("serenity_out", "sweep", spec.name)


def _check_cluster_args(scheduler: str | None, workers: int | None) -> None:
    if scheduler and workers is not None:
        raise SerenityError("--workers sizes the embedded cluster; a running scheduler has its own workers")
    if workers is not None and not 1 <= int(workers) <= 1024:
        raise SerenityError(f"--workers must be in 1..1024, got {workers}")


def _start_client(scheduler: str | None, workers: int | None, cache: str | None):
    """(client, cluster or None): a Client of ``scheduler``, or of a new LocalCluster of ``workers``
    single-threaded worker processes (default: one per core)."""
    distributed = require("distributed", "a sweep on Dask")
    Client, LocalCluster = distributed.Client, distributed.LocalCluster
    _check_cluster_args(scheduler, workers)
    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError) as e:
            raise SerenityError(f"cannot reach the Dask scheduler at {scheduler} ({one_line(e)})") from None
    cores = cpu_threads()
    n = int(workers) if workers is not None else cores
    # one task per process at a time; the cores split between the workers' CPU launches
    env = {"SERENITY_THREADS": str(max(1, cores // n))}
    if cache:
        env["SERENITY_CACHE"] = cache
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR, env=env)
    return Client(cluster), cluster


def _load_hdr(path: str) -> np.ndarray:
    return np.asarray(read_exr(path)["beauty"], np.float32)[..., :3]


class _Progress:
    """The overall bar (tqdm) and one line per task started / finished."""

    def __init__(self, total: int, enabled: bool):
        self.enabled = enabled
        self.bar = tqdm(total=total, unit="task", desc="sweep", disable=not enabled, file=sys.stderr,
                        dynamic_ncols=True)
        self.failed = 0

    def line(self, text: str) -> None:
        if self.enabled:
            self.bar.write(text, file=sys.stderr)

    def started(self, event) -> None:
        _, msg = event
        self.line(f"  start  {msg.get('key')}  on {msg.get('worker')} (pid {msg.get('pid')})")

    def finished(self, key: str, rec: dict) -> None:
        self.failed += rec["status"] != "done"
        took = rec.get("timings", {}).get("task_s")
        took = f"{took:6.1f} s" if took is not None else ""
        extra = ""
        if rec["status"] != "done":
            extra = f"  ERROR {rec['error']}"
        elif rec["kind"] == "compare":
            extra = f"  FLIP {rec['metrics']['flip']:.4f} relMSE {rec['metrics']['rel_mse']:.4f}"
        elif rec["kind"] == "reference" and rec.get("cached"):
            extra = "  (reference cache)"
        self.line(f"  {rec['status']:<5}  {key}  {took}{extra}")
        self.bar.set_postfix(failed=self.failed)
        self.bar.update(1)

    def close(self):
        self.bar.close()


def _record(task: Task, result: dict, out: str, exposure: float) -> dict:
    """Write a finished task's files (atomically) and return its manifest entry."""
    rec = {"kind": task.kind, "inputs": task.inputs, "deps": list(task.deps), "status": result.get("status", "error"),
           "error": result.get("error"), "outputs": {}, "timings": {}, "metrics": {},
           **{k: result.get(k) for k in ("worker", "host", "pid")},
           "finished": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    if "task_s" in result:
        rec["timings"]["task_s"] = round(float(result["task_s"]), 4)
    if rec["status"] != "done":
        return rec
    for k in ("sun_elevation_deg", "sun_azimuth_deg"):
        if k in result:
            rec[k] = result[k]
    if task.kind == "frame":
        paths = {"png": f"frames/{task.key}.png", "exr": f"frames/{task.key}.exr"}
        atomic_write(os.path.join(out, paths["exr"]), lambda p: write_exr(p, {"beauty": result["hdr"]}))
        atomic_write(os.path.join(out, paths["png"]), lambda p: write_png(p, result["ldr"]))
        rec["timings"].update(frame_wall_ms=result["frame_wall_ms"], stages_ms=result["stages_ms"])
        rec["device"] = result.get("device")
    elif task.kind == "reference":
        ldr = (tonemap(result["hdr"], exposure) * 255.0 + 0.5).astype(np.uint8)
        paths = {"exr": f"references/{task.key}.exr", "png": f"references/{task.key}.png"}
        atomic_write(os.path.join(out, paths["exr"]), lambda p: write_exr(p, {"beauty": result["hdr"]}))
        atomic_write(os.path.join(out, paths["png"]), lambda p: write_png(p, ldr))
        rec["cached"] = result.get("cached", False)
    else:
        paths = {"flip_png": f"compare/{task.key}_flip.png"}
        atomic_write(os.path.join(out, paths["flip_png"]), lambda p: write_png(p, result["flip_png"]))
        rec["metrics"] = {k: result[k] for k in ("rel_mse", "rel_mse_rgb", "rel_mse_trim", "flip")}
    rec["outputs"] = paths
    return rec


def run_sweep(spec: SweepSpec, out: str | None = None, *, client=None, scheduler: str | None = None,
              workers: int | None = None, cache: str | None = None, retry_errors: bool = False,
              progress: bool = True) -> SweepResult:
    """Run every unfinished task of ``spec`` and write the results under ``out`` (see the module doc).

    client: a ``distributed.Client`` to use (left open); else ``scheduler`` (an address such as
        ``tcp://host:8786``) is connected to; else an embedded ``LocalCluster`` of ``workers``
        processes (default: one per core) is started and closed afterwards.
    cache: the reference cache directory the workers share (default: theirs, ``SERENITY_CACHE`` or
        ``~/.cache/serenity/reference``; an embedded cluster inherits this process's).
    """
    if client is None:
        _check_cluster_args(scheduler, workers)
    out = os.path.abspath(out or default_out(spec))
    manifest = read_manifest(out)
    tasks = expand(spec)
    by_key = {t.key: t for t in tasks}
    recs = manifest["tasks"]
    result = SweepResult(out=out, manifest=manifest)
    todo = []
    for t in tasks:
        r = recs.get(t.key)
        if _is_finished(r, out) or (r and r.get("status") == "error" and not retry_errors):
            result.skipped.append(t.key)
        else:
            todo.append(t)
    spec_changed = manifest.get("spec_hash") != spec.hash
    manifest.update(format=MANIFEST_FORMAT, spec_hash=spec.hash, spec=spec.to_dict(), tasks=recs)
    if progress:
        print(f"sweep {spec.name}: {len(tasks)} tasks, {len(result.skipped)} already in {out}, {len(todo)} to run",
              file=sys.stderr)
    if todo:
        _run(todo, by_key, spec, out, manifest, result, client, scheduler, workers, cache, progress)
    result.failed = [t.key for t in tasks if recs.get(t.key, {}).get("status") == "error"]
    if todo or spec_changed or not outputs.summaries_exist(out, spec):
        write_json(os.path.join(out, MANIFEST), manifest)
        result.outputs = outputs.write_summaries(spec, tasks, manifest, out)
    if progress:
        done = sum(recs.get(t.key, {}).get("status") == "done" for t in tasks)
        print(f"sweep {spec.name}: {done}/{len(tasks)} tasks done, {len(result.failed)} failed"
              f"{' (see manifest.json; --retry-errors runs them again)' if result.failed else ''}", file=sys.stderr)
        for p in result.outputs:
            print(f"wrote {p}", file=sys.stderr)
    return result


def _run(todo: list[Task], by_key: dict, spec: SweepSpec, out: str, manifest: dict, result: SweepResult,
         client, scheduler, workers, cache, progress) -> None:
    as_completed = require("distributed", "a sweep on Dask").as_completed
    recs = manifest["tasks"]
    own = client is None
    cluster = None
    if own:
        client, cluster = _start_client(scheduler, workers, cache)
    bar = _Progress(len(todo), progress)
    if progress:
        client.subscribe_topic(EVENT_TOPIC, bar.started)
    last_save = time.monotonic()
    try:
        futures = {}
        for t in todo:
            if t.kind == "frame":
                futures[t.key] = client.submit(T.run_frame, t.inputs, key=t.key, pure=False)
            elif t.kind == "reference":
                futures[t.key] = client.submit(T.run_reference, t.inputs, cache, key=t.key, pure=False)
            else:
                deps = [futures[d] if d in futures else _dependency(d, recs, out) for d in t.deps]
                futures[t.key] = client.submit(T.run_compare, *deps, t.inputs["exposure"], key=t.key, pure=False)
        keys = {f.key: k for k, f in futures.items()}
        for fut in as_completed(list(futures.values())):
            key = keys[fut.key]
            try:
                res = fut.result()
            except Exception as e:  # a worker died too often (KilledWorker), or the cluster went away
                res = {"status": "error", "error": one_line(e)}
            deaths = _worker_deaths(client, fut.key)
            fut.release()
            futures.pop(key, None)
            rec = _record(by_key[key], res, out, spec.exposure)
            rec["worker_deaths"] = deaths
            recs[key] = rec
            result.ran.append(key)
            bar.finished(key, rec)
            if time.monotonic() - last_save > _MANIFEST_EVERY_S:
                write_json(os.path.join(out, MANIFEST), manifest)
                last_save = time.monotonic()
    finally:
        bar.close()
        write_json(os.path.join(out, MANIFEST), manifest)
        if progress:
            try:
                client.unsubscribe_topic(EVENT_TOPIC)
            except Exception:  # noqa: BLE001 - the scheduler may be gone already
                pass
        if own:
            client.close()
            if cluster is not None:
                cluster.close()


def _suspicious(key, dask_scheduler=None) -> int | None:
    ts = dask_scheduler.tasks.get(key)
    return None if ts is None else int(ts.suspicious)


def _worker_deaths(client, key) -> int | None:
    """How many workers died while running ``key`` (Dask reran it each time; after
    ``distributed.scheduler.allowed-failures`` it gives up with ``KilledWorker``). None if unknown."""
    try:
        return client.run_on_scheduler(_suspicious, key)
    except Exception:  # noqa: BLE001 - a scheduler that refuses run_on_scheduler: not worth failing the task
        return None


def _dependency(key: str, recs: dict, out: str):
    """A finished dependency's HDR image from disk, or its (failed) manifest entry."""
    r = recs.get(key)
    if _is_finished(r, out):
        return _load_hdr(os.path.join(out, r["outputs"]["exr"]))
    return r or {"status": "error", "error": f"{key} did not run"}

