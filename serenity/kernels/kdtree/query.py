"""The kd-tree's queries on a device: which kernels a batch of rays goes through, decided in one
place (:func:`plan_query`), and their launch (:func:`launch_query`).

A batch is one of three kinds: ``reordered`` (traced in the order of its keys, ``reorder.ray_order``,
its results scattered back into the caller's order), ``coherent`` (left in the caller's order because
it is coherent already: camera rays, reflections of a smooth surface in pixel order) or ``incoherent``
(left in the caller's order: small, or ``sort=False``). The traversal per device and kind:

=========  ==============  =============  =============
device     incoherent      coherent       reordered
=========  ==============  =============  =============
CPU        one ray         packets        packets
CUDA       one ray         one ray        one ray
=========  ==============  =============  =============

One ray: ``traverse.intersect_rays`` / ``occlude_rays``, a ray per kernel thread (CUDA's parallelism
is its threads). Packets: ``cpu.packets.trace_packets_kernel``, ``PACKET_LANES`` rays per kernel
thread as SIMD lanes. The CPU-only kernels are launched from here only, on the CPU only; their
natives trap on CUDA (``native``). Every path gives the one-ray traversal's hits bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from serenity.device import cpu_threads
from serenity.errors import SerenityError
from serenity.kernels.launch import MIN_ITEMS_PER_CHUNK, Staging, launch

from .cpu.packets import PACKET_LANES, PACKET_WORKSPACE, trace_packets_kernel
from .cpu.sort import REORDER_BLOCK, scatter_hits
from .layout import buffers_like, is_cpu, workspace_buffer
from .reorder import scatter_in_order
from .traverse import intersect_rays, occlude_rays

#: the batch kinds (module docstring)
BATCH_KINDS = ("incoherent", "coherent", "reordered")
#: the traversal per device kind and batch kind (module docstring): "one_ray" or "packets"
TRAVERSAL = {
    ("cpu", "incoherent"): "one_ray",
    ("cpu", "coherent"): "packets",
    ("cpu", "reordered"): "packets",
    ("cuda", "incoherent"): "one_ray",
    ("cuda", "coherent"): "one_ray",
    ("cuda", "reordered"): "one_ray",
}
#: the values ``rays_per_thread`` may force on the CPU: 1 (one ray), ``PACKET_LANES`` (packets)
RAYS_PER_THREAD = {1: "one_ray", PACKET_LANES: "packets"}


@dataclass
class Hits:
    """Closest hits of N rays: ``t`` (N,) float32 (inf = miss), ``prim`` (N,) int32 (−1 = miss),
    barycentrics ``u``, ``v`` (N,) float32 (p = (1−u−v)·v0 + u·v1 + v·v2; 0 on a miss). numpy arrays,
    or Warp arrays on the query's device where :meth:`KdTree.intersect` was given Warp arrays
    (:meth:`numpy` brings those to the host). From a reordered batch on the CPU the four are the
    columns of one (N, 4) block of records (views with a 16-byte stride: :func:`hit_outputs`;
    ``np.ascontiguousarray`` packs one)."""

    t: np.ndarray | wp.array
    prim: np.ndarray | wp.array
    u: np.ndarray | wp.array
    v: np.ndarray | wp.array

    @property
    def on_device(self) -> bool:
        """Whether the four are Warp arrays (the query was given Warp arrays)."""
        return isinstance(self.t, wp.array)

    def numpy(self) -> Hits:
        """These hits as numpy arrays: itself for numpy hits, views of Warp arrays on the CPU, a copy
        from a GPU."""
        if not self.on_device:
            return self
        return Hits(t=self.t.numpy(), prim=self.prim.numpy(), u=self.u.numpy(), v=self.v.numpy())

    @property
    def hit(self) -> np.ndarray:
        """(N,) bool numpy: the rays that hit something (through :meth:`numpy`)."""
        return self.numpy().prim >= 0


def plan_query(device: str, batch: str, rays_per_thread: int | None = None) -> str:
    """The traversal of a batch of kind ``batch`` (``BATCH_KINDS``) on ``device``: "one_ray" or
    "packets" (``TRAVERSAL``). ``rays_per_thread`` forces one on the CPU (``RAYS_PER_THREAD``); CUDA
    accepts and ignores it (one ray per kernel thread)."""
    if rays_per_thread is not None and rays_per_thread not in RAYS_PER_THREAD:
        raise SerenityError(f"rays_per_thread={rays_per_thread}: 1 (one ray per kernel thread) or {PACKET_LANES} "
                            "(packets)")
    cpu = is_cpu(device)
    if cpu and rays_per_thread is not None:
        return RAYS_PER_THREAD[rays_per_thread]
    return TRAVERSAL[("cpu" if cpu else "cuda", batch)]


def hit_outputs(n: int, device: str, reordered: bool) -> tuple[list, wp.array | None]:
    """The closest-hit query's outputs for ``n`` rays: [t, prim, u, v], and for a ``reordered`` batch
    on the CPU the (n,) vec4 array of 16-byte records (t, prim's bits, u, v) whose columns they are
    (prim's viewed as int32); else four arrays and None (CUDA: coalesced per array). A reordered
    batch's results are scattered back as records (``cpu.sort.scatter_hits``): one random store of 16
    bytes per ray, where four arrays take four of 4 bytes to four cache lines, the store buffer
    filling with misses (the scatter of the benchmark's incoherent rays takes about a third less
    time). A batch traced in its own order writes its results in order: there the columns of
    records make camera rays' traversal 1.5-2.5 % slower, so it keeps four arrays."""
    if not (reordered and is_cpu(device)):
        return [wp.empty(n, dtype=dt, device=device) for dt in (float, wp.int32, float, float)], None
    records = wp.empty(n, dtype=wp.vec4, device=device)  # Warp's allocator: numpy's fresh pages cost faults
    block = records.numpy()  # (n, 4) float32, the same memory
    columns = [wp.array(block[:, 0], dtype=float, device=device, copy=False),
               wp.array(block[:, 1].view(np.int32), dtype=wp.int32, device=device, copy=False),
               wp.array(block[:, 2], dtype=float, device=device, copy=False),
               wp.array(block[:, 3], dtype=float, device=device, copy=False)]
    return columns, records


def ray_arrays(o, d, tm, dev: str, tmin: float, workspace: Staging) -> list:
    """The kernels' ray inputs (origins, directions, tmin, tmax). Numpy rays: views on the CPU (no
    copy: serial work before the threads start), copies on a GPU. Warp rays (vec3 arrays on ``dev``)
    go in as they are, and so does a Warp tmax (float32 on ``dev``); a numpy (N,) tmax beside them is
    copied to a GPU. A scalar tmax (0-d ``tm``) is ``workspace``'s buffer filled with it
    (:meth:`Staging.filled`: refilled only when it changes)."""
    copy = not is_cpu(dev)
    if isinstance(tm, wp.array):
        tmax = tm
    elif np.ndim(tm) == 0:
        tmax = workspace.filled("tmax_uniform", o.shape[0], float, float(tm))
    else:
        tmax = wp.array(tm, dtype=float, device=dev, copy=copy)
    if isinstance(o, wp.array):
        return [o, d, float(tmin), tmax]
    return [wp.array(o, dtype=wp.vec3, device=dev, copy=copy), wp.array(d, dtype=wp.vec3, device=dev, copy=copy),
            float(tmin), tmax]


def launch_query(any_hit: bool, n: int, inputs: list, order: wp.array, outputs: list, device: str,
                 threads: int | None, rays_per_thread: int | None, workspace: Staging | None = None,
                 coherent: bool = False, records: wp.array | None = None) -> None:
    """Launch the closest-hit (``any_hit=False``; outputs t, prim, u, v) or occlusion query (outputs
    [occluded]) over ``n`` rays ``inputs`` (tree, origins, directions, tmin, tmax) given in the trace
    order ``order`` (empty: the caller's; else ray i is the caller's ray ``order[i]``: the results
    are traced into workspace arrays in that order and scattered back, :func:`scatter_in_order`).
    The traversal is :func:`plan_query`'s for the batch's kind (``coherent``: a batch in the caller's
    order that ``reorder.batch_is_coherent`` found coherent). Packets need contiguous rays (they load
    their lanes as vectors); a batch of strided ones is traced one ray per kernel thread.
    ``workspace``: where the reordered results are traced and the packets keep their lanes
    (:meth:`KdTree.workspace`), else new arrays. ``records``: the closest-hit outputs' record array
    (:func:`hit_outputs`), into which a reordered batch's results are scattered in one pass (CPU)."""
    reordered = order.shape[0] > 0
    batch = "reordered" if reordered else ("coherent" if coherent else "incoherent")
    traversal = plan_query(device, batch, rays_per_thread)
    if traversal == "packets" and not all(a.is_contiguous for a in inputs[1:3] + inputs[4:5]):
        traversal = "one_ray"
    traced = buffers_like(outputs, "traced", device, workspace) if reordered else outputs
    if traversal == "one_ray":
        launch(occlude_rays if any_hit else intersect_rays, n, [*inputs, *traced], device=device, threads=threads,
               balanced=True)
    else:
        none_f = wp.empty(0, dtype=float, device=device)
        none_i = wp.empty(0, dtype=wp.int32, device=device)
        outs = [none_f, none_i, none_f, none_f, *traced] if any_hit else [*traced, none_i]
        workers = threads or cpu_threads()
        lanes = workspace_buffer(workspace, "packets", workers * PACKET_WORKSPACE, float, device)
        lanes.zero_()
        launch(trace_packets_kernel(any_hit), -(-n // PACKET_LANES), [*inputs, n, lanes, *outs], device=device,
               threads=threads, balanced=True, worker_arg=True,
               min_chunk=MIN_ITEMS_PER_CHUNK // PACKET_LANES)  # a packet is 16 rays' work
    if reordered and records is not None:  # traced into new or workspace arrays: contiguous
        launch(scatter_hits, -(-n // REORDER_BLOCK), [order, *traced, records], device=device, threads=threads,
               min_items=1)
    elif reordered:
        scatter_in_order(order, traced, outputs, device, threads)
