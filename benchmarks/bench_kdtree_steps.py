"""A/B of kd-tree traversal versions in one process: the traversal of several git revisions of
the kd-tree (the package ``serenity/kernels/kdtree/``, or the single module ``kdtree.py`` it was
before) on the same tree and the same rays, timed back to back.

    python benchmarks/bench_kdtree_steps.py --json FILE REV[@key=value,...] ... [--rounds 7] [--size 1280x720]

Each REV's kd-tree is loaded under its own name (its files from ``git show``; ``WORKTREE`` = the
files as they are now), so each is its own set of Warp modules; they share this checkout's
build (``kdtree_build``), with :class:`serenity.config.KdBuildConfig` defaults unless the version
says otherwise after an ``@`` (``HEAD@max_depth=40,min_empty_fraction=0.1``: the same traversal
on a tree built with those settings); keys that are not build settings go to ``KdTree.intersect``
(``WORKTREE@rays_per_thread=1``: the working tree's traversal with one ray per kernel thread).
Rays as in ``bench_kdtree.py``: coherent camera rays and incoherent random rays from their hit
points. Every round traces both ray sets once with every version, on
one thread, in turn; the figure per version is the median over rounds of rays / **CPU seconds of
the process** (``time.process_time``), not wall time: on a machine shared with other sessions a
version that happens to be descheduled does not look slower (cache pollution from other processes
still adds noise: look at ``spread``, the (max − min) / median of the rounds). Hits are checked
against the first version (same triangle and t on ≥ 99.99 % of the rays). ``vs_first`` is the ratio of
the medians; ``vs_first_paired`` the median over rounds of the ratio within a round (the versions
of one round run seconds apart, so the host's drift from round to round cancels out of it).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from serenity.config import KdBuildConfig
from serenity.device import init_warp
from serenity.io.results import write_results
from serenity.scene.procedural import lumpy_mesh

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_kdtree import ray_sets  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def module_from_source(name: str, src: str, tmp: Path):
    """Python source ``src`` written to ``tmp`` and imported as module ``name`` (Warp needs its
    kernels in a real file)."""
    path = tmp / f"{name}.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def package_from_files(name: str, files: dict[str, str], tmp: Path):
    """A package of ``files`` (path within the package → text) written to ``tmp/name`` and imported
    as ``name`` (the kd-tree package imports its own modules relatively, and reads its ``.h`` files
    from beside them)."""
    root = tmp / name
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    spec = importlib.util.spec_from_file_location(name, root / "__init__.py", submodule_search_locations=[str(root)])
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


PACKAGE = "serenity/kernels/kdtree"


def version_files(rev: str) -> dict[str, str] | str:
    """The kd-tree of git revision ``rev`` (or the working tree): the package's files (path within it
    → text), or, for a revision from before the package, the text of ``kdtree.py``."""
    if rev == "WORKTREE":
        folder = ROOT / PACKAGE
        if folder.is_dir():
            return {str(p.relative_to(folder)): p.read_text() for p in sorted(folder.rglob("*"))
                    if p.suffix in (".py", ".h")}
        return (ROOT / f"{PACKAGE}.py").read_text()
    listed = subprocess.run(["git", "-C", str(ROOT), "ls-tree", "-r", "--name-only", rev, f"{PACKAGE}/"],
                            check=True, capture_output=True, text=True).stdout.split()
    show = lambda path: subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"],  # noqa: E731
                                       check=True, capture_output=True, text=True).stdout
    if listed:
        return {p[len(PACKAGE) + 1:]: show(p) for p in listed if p.endswith((".py", ".h"))}
    return show(f"{PACKAGE}.py")


def load_version(rev: str, tmp: Path, k: int):
    """The kd-tree of git revision ``rev`` (or the working tree), loaded under its own name."""
    files = version_files(rev)
    if isinstance(files, str):
        return module_from_source(f"kdtree_step{k}", files, tmp)
    return package_from_files(f"kdtree_step{k}", files, tmp)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("revs", nargs="+", help="git revisions (WORKTREE = the file as it is now)")
    ap.add_argument("--json", required=True)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--subdivisions", type=int, default=6)
    args = ap.parse_args(argv)
    init_warp()
    width, height = (int(x) for x in args.size.lower().split("x"))
    v, f = lumpy_mesh(args.subdivisions)
    load_before = os.getloadavg()
    versions = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, rev in enumerate(args.revs):
            git_rev, _, settings = rev.partition("@")
            pairs = {key: json.loads(val) for key, val in (kv.split("=") for kv in settings.split(",") if kv)}
            build_fields = {fl.name for fl in dataclasses.fields(KdBuildConfig)}
            cfg = KdBuildConfig(**{key: val for key, val in pairs.items() if key in build_fields})
            query = {key: val for key, val in pairs.items() if key not in build_fields}  # e.g. rays_per_thread
            mod = load_version(git_rev, Path(tmp), k)
            tree = mod.KdTree.build(v, f, config=cfg, cache=False, progress=False)
            versions.append((rev, mod, tree, query))
        sets = ray_sets(versions[0][2], width, height)
        ref, agreement = {}, {}
        for k, (_, _, tree, query) in enumerate(versions):  # also the warm-up (compile, first touch)
            for s, (o, d) in sets.items():
                h = tree.intersect(o, d, device="cpu", threads=1, **query)
                ref.setdefault(s, h)
                agreement[(k, s)] = float(np.mean((h.prim == ref[s].prim) & (h.t == ref[s].t)))
        cpu = {(k, s): [] for k in range(len(versions)) for s in sets}  # by position: a version may repeat
        for _ in range(args.rounds):
            for k, (_, _, tree, query) in enumerate(versions):
                for s, (o, d) in sets.items():
                    c0 = time.process_time()
                    tree.intersect(o, d, device="cpu", threads=1, **query)
                    cpu[(k, s)].append(time.process_time() - c0)
    out_versions = []
    base = None
    for k, (rev, _, tree, _query) in enumerate(versions):
        entry = {"rev": rev, "nodes": tree.stats.nodes, "references": tree.stats.references, "depth": tree.stats.depth}
        for s, (o, _) in sets.items():
            ts = cpu[(k, s)]
            med = statistics.median(ts)
            entry[s] = {"mrays_per_cpu_s": len(o) / med / 1e6, "spread": (max(ts) - min(ts)) / med,
                        "agreement_with_first": agreement[(k, s)]}
        base = base or entry
        for s in sets:
            entry[s]["vs_first"] = entry[s]["mrays_per_cpu_s"] / base[s]["mrays_per_cpu_s"]
            # paired: the first version's time / this one's within each round (seconds apart), median
            # over rounds; the host's drift between rounds cancels out of it
            entry[s]["vs_first_paired"] = statistics.median(a / b for a, b in zip(cpu[(0, s)], cpu[(k, s)],
                                                                                     strict=True))
        out_versions.append(entry)
        print(f"{rev:>24}: coherent {entry['coherent']['mrays_per_cpu_s']:6.3f} Mrays/CPU-s "
              f"({entry['coherent']['vs_first']:4.2f}x, paired {entry['coherent']['vs_first_paired']:4.2f}x, spread "
              f"{entry['coherent']['spread']:.2f})   incoherent {entry['incoherent']['mrays_per_cpu_s']:6.3f} "
              f"({entry['incoherent']['vs_first']:4.2f}x, paired {entry['incoherent']['vs_first_paired']:4.2f}x, "
              f"spread {entry['incoherent']['spread']:.2f})", flush=True)
    out = {"benchmark": "kdtree_steps", "rounds": args.rounds, "size": [width, height],
           "triangles": len(f), "threads": 1, "timing": "process CPU seconds, median over rounds",
           "load_average": {"before": list(load_before), "after": list(os.getloadavg())},
           "versions": out_versions}
    write_results(args.json, out)
    return out


if __name__ == "__main__":
    main()
