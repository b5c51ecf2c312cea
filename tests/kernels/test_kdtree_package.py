"""The kd-tree package's structure: its natives' C in headers (each C function declared as its
Python native, every byte of its body in the snippet that Warp hashes, so that editing a header
compiles the modules anew), CPU-only natives that trap on CUDA instead of returning a plausible
value, the query table that never sends a batch on CUDA to a CPU-only kernel, the CUDA sort's order,
and files of at most 700 lines. The hits themselves are ``test_kdtree.py``'s."""

from __future__ import annotations

import importlib
import pkgutil
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import serenity.kernels.kdtree as K
from serenity.device import init_warp
from serenity.errors import SerenityError
from serenity.kernels.kdtree import native
from serenity.kernels.kdtree.cpu.packets import (
    PACKET_LANES,
    PACKET_WORKSPACE,
    leaf_simd,
    lowest_lane,
    packet_octant,
    packet_pop,
    packet_setup,
    packet_step,
)
from serenity.kernels.kdtree.cpu.sort import (
    keys_simd,
    move_range,
    prefetch_high_place,
    prefetch_low_place,
    scatter_hits_range,
)
from serenity.kernels.kdtree.query import BATCH_KINDS, TRAVERSAL, plan_query

wp = init_warp()
PACKAGE_DIR = Path(K.__file__).parent
ROOT = PACKAGE_DIR.parents[2]
MODULES = [importlib.import_module(m.name) for m in pkgutil.walk_packages(K.__path__, K.__name__ + ".")]
TRAP = "#if defined(__CUDA_ARCH__)\n__trap();"


def _natives() -> list[tuple[object, str, object]]:
    """(module, name, Warp function) of every native the package declares."""
    out = []
    for mod in MODULES:
        for name, obj in vars(mod).items():
            if getattr(obj, "native_snippet", None) and getattr(obj, "__module__", None) == mod.__name__:
                out.append((mod, name, obj))
    return out


NATIVES = _natives()


def test_no_file_of_the_package_is_over_700_lines():
    files = [p for p in PACKAGE_DIR.rglob("*") if p.suffix in (".py", ".h")]
    assert len(files) >= 15
    long = {str(p.relative_to(PACKAGE_DIR)): n for p in files if (n := len(p.read_text().splitlines())) > 700}
    assert not long


def test_every_native_is_the_function_of_its_name_in_its_header():
    """Each native's C is the function of the same name and parameters in its module's header, and
    the whole body (its included files expanded) is in the snippet: the text Warp hashes."""
    assert len(NATIVES) >= 18
    for mod, name, fn in NATIVES:
        header = mod.HEADER
        assert native.parameter_names(header, name) == list(fn.input_types), name
        body = native.function(header, name)[2]
        assert native._expand(body, header.parent, (header.resolve(),)) in fn.native_snippet, name


CPU_ONLY = {keys_simd, prefetch_low_place, prefetch_high_place, move_range, scatter_hits_range, packet_step,
            packet_pop, lowest_lane, packet_setup, packet_octant, leaf_simd}


def test_cpu_only_natives_are_a_trap_on_cuda():
    """The natives written with clang's vector extensions, BMI2 or prefetches are exactly the CPU-only
    ones, and each is a ``__trap()`` when compiled for CUDA (the rest compile for both: the CUDA
    compile test)."""
    trapped = {fn for _, _, fn in NATIVES if fn.native_snippet.startswith(TRAP)}
    assert trapped == CPU_ONLY
    for _, name, fn in NATIVES:
        cuda_side = fn.native_snippet.split("#else\n", 1)[0] if fn in CPU_ONLY else ""
        assert "ext_vector_type" not in cuda_side and "__builtin_prefetch" not in cuda_side, name
        if fn not in CPU_ONLY and "ext_vector_type" in fn.native_snippet:
            assert "#if defined(__CUDA_ARCH__)" in fn.native_snippet, name  # leaf_pick: -2 on CUDA


def test_the_query_table_never_sends_a_cuda_batch_to_a_cpu_only_kernel():
    assert set(TRAVERSAL) == {(d, b) for d in ("cpu", "cuda") for b in BATCH_KINDS}
    for batch in BATCH_KINDS:
        for k in (None, 1, PACKET_LANES):
            assert plan_query("cuda:0", batch, k) == "one_ray"
        assert plan_query("cpu", batch, 1) == "one_ray"
        assert plan_query("cpu", batch, PACKET_LANES) == "packets"
    assert [plan_query("cpu", b) for b in BATCH_KINDS] == ["one_ray", "packets", "packets"]
    with pytest.raises(SerenityError, match="rays_per_thread=4"):
        plan_query("cpu", "reordered", 4)


_HASH = """
import sys
sys.path.insert(0, sys.argv[1])
import warp as wp
wp.config.quiet = True
wp.init()
import kdcopy
print(wp.get_module("kdcopy.traverse").hash_module().hex())
"""


def _hash_with(tmp: Path, tag: str, edit: tuple[str, str, str] | None) -> str:
    """The hash of the traversal's Warp module in a copy of the package (imported as ``kdcopy``) with
    ``edit`` = (file, old, new) applied."""
    root = tmp / tag
    shutil.copytree(PACKAGE_DIR, root / "kdcopy", ignore=shutil.ignore_patterns("__pycache__"))
    if edit:
        path = root / "kdcopy" / edit[0]
        text = path.read_text()
        assert text.count(edit[1]) == 1
        path.write_text(text.replace(edit[1], edit[2]))
    out = subprocess.run([sys.executable, "-c", _HASH, str(root)], capture_output=True, text=True, timeout=300,
                         cwd=ROOT)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()[-1]


def test_editing_a_header_changes_the_module_hash(tmp_path):
    """A change inside a native's body in its header, or in a file its body includes, gives the
    modules that use it a new hash (Warp compiles them anew, no stale cache); a comment outside the
    bodies does not."""
    base = _hash_with(tmp_path, "base", None)
    body = _hash_with(tmp_path, "body", ("layout.h", "return nodes.data[(unsigned)i].head;",
                                         "return nodes.data[(unsigned)i].head; /* edited */"))
    included = _hash_with(tmp_path, "included", ("leaf8.h", "int found = -1;", "int found = -1; /* edited */"))
    outside = _hash_with(tmp_path, "outside", ("layout.h", "// in range.", "// in range (edited)."))
    assert len({base, body, included}) == 3
    assert outside == base


# each CPU-only native in a kernel of its own, with arguments it can run on, its result in out[0] and
# out[1] = 1 once it has returned
@wp.kernel
def _call_keys_simd(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                    i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                    src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    keys_simd(wp.vec3(-2.0), wp.vec3(8.0), v, v, u, 0)
    out[0] = wp.int64(u[0])
    out[1] = wp.int64(1)


@wp.kernel
def _call_prefetch_low_place(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                             i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                             src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    prefetch_low_place(u, i, i, h, 0, 3, 0, 4)
    out[1] = wp.int64(1)


@wp.kernel
def _call_prefetch_high_place(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                              i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                              src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    prefetch_high_place(h, i, i, 0, 0, 4)
    out[1] = wp.int64(1)


@wp.kernel
def _call_move_range(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                     i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                     src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    move_range(i, src, dst, 4, 0, 0, 4)
    out[1] = wp.int64(1)


@wp.kernel
def _call_scatter_hits_range(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                             i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                             src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    scatter_hits_range(i, f, i, f, f, r, 0, 4)
    out[1] = wp.int64(1)


@wp.kernel
def _call_packet_setup(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                       i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                       src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    out[0] = packet_setup(wp.vec3(-2.0), wp.vec3(2.0), 2.0, v, v, f, 0.0, 0, 16, f, 0)
    out[1] = wp.int64(1)


@wp.kernel
def _call_packet_octant(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                        i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                        src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    out[0] = wp.int64(packet_octant(f, 0, 0))
    out[1] = wp.int64(1)


@wp.kernel
def _call_packet_step(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                      i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                      src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    out[0] = packet_step(f, 0, 0, 0.5, 0, 0)
    out[1] = wp.int64(1)


@wp.kernel
def _call_packet_pop(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                     i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                     src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    out[0] = wp.int64(packet_pop(f, 0, 0))
    out[1] = wp.int64(1)


@wp.kernel
def _call_lowest_lane(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                      i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                      src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    out[0] = wp.int64(lowest_lane(12))
    out[1] = wp.int64(1)


@wp.kernel
def _call_leaf_simd(f: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), u: wp.array(dtype=wp.uint32),
                    i: wp.array(dtype=wp.int32), h: wp.array(dtype=wp.uint16), r: wp.array(dtype=wp.vec4),
                    src: wp.uint64, dst: wp.uint64, out: wp.array(dtype=wp.int64)):
    out[0] = wp.int64(leaf_simd(f, 0, 1, wp.vec3(0.0), 0, 1, 2, 0.0, 0.0, 1.0, 0.0, 1.0e30, -1, 0, f, 0))
    out[1] = wp.int64(1)


CALLS = {keys_simd: _call_keys_simd, prefetch_low_place: _call_prefetch_low_place,
         prefetch_high_place: _call_prefetch_high_place, move_range: _call_move_range,
         scatter_hits_range: _call_scatter_hits_range, packet_setup: _call_packet_setup,
         packet_octant: _call_packet_octant, packet_step: _call_packet_step, packet_pop: _call_packet_pop,
         lowest_lane: _call_lowest_lane, leaf_simd: _call_leaf_simd}
CASES = {fn.__name__: kernel for fn, kernel in CALLS.items()}


def run_case(name: str, device: str) -> np.ndarray:
    """Launch the kernel of CPU-only native ``name`` on ``device`` and return its ``out``."""
    rng = np.random.default_rng(3)
    f = wp.array(rng.random(PACKET_WORKSPACE).astype(np.float32), dtype=float, device=device)
    v = wp.array(rng.normal(size=(16, 3)).astype(np.float32), dtype=wp.vec3, device=device)
    u = wp.zeros(16, dtype=wp.uint32, device=device)
    i = wp.array(np.arange(1 << 15, dtype=np.int32) % 4, dtype=wp.int32, device=device)
    h = wp.zeros(16, dtype=wp.uint16, device=device)
    r = wp.zeros(16, dtype=wp.vec4, device=device)
    src = wp.array(np.arange(16, dtype=np.float32), dtype=float, device=device)
    dst = wp.zeros(16, dtype=float, device=device)
    out = wp.zeros(2, dtype=wp.int64, device=device)
    wp.launch(CASES[name], 1, [f, v, u, i, h, r, src.ptr, dst.ptr, out], device=device)
    wp.synchronize_device(device)
    return out.numpy()


def test_every_cpu_only_native_has_a_case_that_returns_on_the_cpu():
    """Guards the CUDA test below against vacuity: a case per CPU-only native, each of which runs to
    its end on the CPU (``lowest_lane(12)`` = 2, a key below 2^SORT_KEY_BITS)."""
    assert set(CALLS) == CPU_ONLY
    for name in CASES:
        out = run_case(name, "cpu")
        assert out[1] == 1, name
    assert run_case("lowest_lane", "cpu")[0] == 2
    assert 0 < run_case("keys_simd", "cpu")[0] < 1 << K.SORT_KEY_BITS


_CUDA_CASE = """
import sys
sys.path.insert(0, sys.argv[1])
from tests.kernels.test_kdtree_package import run_case
try:
    out = run_case(sys.argv[2], sys.argv[3])
except Exception as exc:
    print("RAISED", type(exc).__name__, exc)
    sys.exit(3)
print("RETURNED" if out[1] == 1 else "NO RESULT", out)
"""


def test_cpu_only_natives_trap_when_launched_on_cuda(cuda_devices):
    """On a CUDA device a kernel that calls a CPU-only native stops with an error (``__trap()``) and
    returns nothing, instead of a plausible value (each in a process of its own: a trap leaves the
    CUDA context unusable)."""
    if not cuda_devices:
        pytest.skip("no CUDA device")
    for name in CASES:
        out = subprocess.run([sys.executable, "-c", _CUDA_CASE, str(ROOT), name, cuda_devices[0]],
                             capture_output=True, text=True, timeout=600, cwd=ROOT)
        assert "RETURNED" not in out.stdout, (name, out.stdout, out.stderr[-2000:])
        assert out.returncode != 0 or "NO RESULT" in out.stdout, (name, out.stdout, out.stderr[-2000:])


def test_cuda_ray_order_is_the_stable_order_of_the_keys(cuda_devices):
    """CUDA's reordering (the keys sorted with the rays' indices by Warp's radix sort, on the device)
    is the CPU's order: numpy's stable argsort of the keys, ties in the caller's order."""
    if not cuda_devices:
        pytest.skip("no CUDA device")
    from serenity.scene.procedural import lumpy_mesh

    v, f = lumpy_mesh(2)
    tree = K.KdTree.build(v, f)
    rng = np.random.default_rng(9)
    n = K.SORT_MIN_RAYS + 123
    o = (rng.random((n, 3)) * 2 - 1).astype(np.float32)
    o[: n // 2] = o[0]  # many equal keys: ties
    d = rng.normal(size=(n, 3)).astype(np.float32)
    cpu = tree.device_data("cpu")
    ref = K.ray_order(cpu.box_lo, cpu.box_hi, wp.array(o, dtype=wp.vec3), wp.array(d, dtype=wp.vec3), n, True,
                      "cpu").numpy()
    for dev in cuda_devices:
        data = tree.device_data(dev)
        got = K.ray_order(data.box_lo, data.box_hi, wp.array(o, dtype=wp.vec3, device=dev),
                          wp.array(d, dtype=wp.vec3, device=dev), n, True, dev, workspace=tree.workspace(dev))
        assert np.array_equal(got.numpy(), ref)
