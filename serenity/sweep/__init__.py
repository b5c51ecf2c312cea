"""Sweeps and reference sets beyond one process: ``serenity sweep`` on Dask (``dask.distributed``).

    serenity sweep examples/sweep_day.toml --workers 2 --out serenity_out/sweep_day
    serenity sweep spec.toml --scheduler tcp://host:8786          # an existing Dask cluster

- :mod:`.spec` — the sweep file (scenes × sizes × times of day × quality presets, what to produce)
  and its expansion into keyed tasks;
- :mod:`.tasks` — what a worker runs (our frame, a Mitsuba reference, a comparison);
- :mod:`.runner` — the client: submit, retry, atomic results + manifest, resume;
- :mod:`.outputs` — metrics CSV/JSON, contact sheet, time-of-day GIFs;
- :func:`render_references` — the API for benchmarks: many references on a cluster at once.

By default the cluster is an embedded ``LocalCluster``: one single-threaded worker *process* per
core, so each has its own GL context and Warp runtime (neither is shared between threads here).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from tqdm import tqdm

from serenity.errors import SerenityError
from serenity.sweep.runner import SweepResult, _start_client, read_manifest, run_sweep
from serenity.sweep.spec import SweepSpec, Task, expand, load_spec, quality_config, spec_from_dict
from serenity.sweep.tasks import one_line, run_reference

__all__ = ["ReferenceJob", "SweepResult", "SweepSpec", "Task", "expand", "load_spec", "quality_config",
           "read_manifest", "render_references", "run_sweep", "spec_from_dict"]


@dataclass(frozen=True)
class ReferenceJob:
    """One reference render for :func:`render_references` (the arguments of
    ``serenity.eval.reference.render_reference``, plus an optional time of day)."""

    scene: object
    """A built-in scene name, a scene file path, or a ``Scene``."""
    width: int
    height: int
    spp: int = 64
    component: str = "full"
    seed: int = 0
    max_depth: int | None = None
    """Overrides ``component`` (-1 = unlimited), as in ``render_reference``."""
    time: str | None = None
    """A ``parse_time`` string to move the sun to (at latitude/longitude, else the scene's location)."""
    latitude: float | None = None
    longitude: float | None = None


def render_references(jobs, client=None, *, scheduler: str | None = None, workers: int | None = None,
                      cache: str | None = None, progress: bool = True) -> list[np.ndarray]:
    """Render many Mitsuba references on a Dask cluster; (H, W, 3) float32 images in ``jobs``' order.

    jobs: ``ReferenceJob``s (or dicts of their fields). Identical jobs given by scene name/path run
        once. Every image goes through the shared reference cache (``cache``, default the workers'
        ``SERENITY_CACHE`` or ``~/.cache/serenity/reference``), so a later
        ``render_reference(...)`` with the same arguments on any of those machines reads it back.
    client / scheduler / workers: as in :func:`run_sweep` (default: an embedded LocalCluster, closed
        on return).
    Raises ``SerenityError`` naming the first job that failed (after all have finished)."""
    jobs = [j if isinstance(j, ReferenceJob) else ReferenceJob(**j) for j in jobs]
    if not jobs:
        return []
    own = client is None
    cluster = None
    if own:
        client, cluster = _start_client(scheduler, workers, cache)
    try:
        futures, order = {}, []
        for j in jobs:
            inputs = asdict(j)
            inputs["scene"] = j.scene  # asdict would deep-copy a Scene
            ident = repr(sorted((k, v) for k, v in inputs.items() if k != "scene"))
            ident += f"|{j.scene}" if isinstance(j.scene, str) else f"|{id(j.scene)}"
            if ident not in futures:
                futures[ident] = client.submit(run_reference, inputs, cache, pure=False)
            order.append(ident)
        from distributed import wait

        with tqdm(total=len(futures), unit="ref", desc="references", disable=not progress) as bar:
            pending = set(futures.values())
            while pending:
                done, pending = wait(pending, return_when="FIRST_COMPLETED")
                bar.update(len(done))
        results = {}
        for k, f in futures.items():
            try:
                results[k] = f.result()
            except Exception as e:  # KilledWorker: the job took down worker after worker
                results[k] = {"status": "error", "error": one_line(e)}
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    for j, ident in zip(jobs, order, strict=True):
        r = results[ident]
        if r["status"] != "done":
            raise SerenityError(f"reference of {j.scene if isinstance(j.scene, str) else j.scene.name} "
                                f"{j.width}x{j.height}: {r['error']}")
    return [results[ident]["hdr"] for ident in order]
