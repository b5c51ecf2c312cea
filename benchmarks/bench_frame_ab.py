"""A/B of whole frames between git revisions: ``serenity bench`` of each revision, alternating.

    python benchmarks/bench_frame_ab.py REV_A REV_B [...] [--patch COMMIT ...] [--sizes 320x180,640x360]
                                        [--pairs 3] [--quality lpv-fast] [--json FILE]

Each revision is checked out in a temporary git worktree (``--patch`` commits are applied on top of
every revision that does not already contain them, e.g. a change of the bench itself, so that all
revisions run the same benchmark), and ``python -m serenity bench courtyard --frames 24`` runs there
with that worktree first on the path, the revisions in turn (the order reversed every pair), so
that a shared machine's drifting load falls on all of them alike. Per revision and size: every
run's overlapped and serial frame, CPU-ms, LPV update, sky stage, tracer stages and every stage of
both schedules, and their medians over the pairs. On a 2-core machine shared with other jobs one
run of a frame varies by 10–25 %; the CPU-ms vary less.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from serenity.io.results import write_results  # noqa: E402


def git(*args, cwd=ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


def checkout(rev: str, patches: list[str], path: Path) -> dict:
    """A detached worktree of ``rev`` at ``path`` with ``patches`` applied (uncommitted); returns what it holds."""
    git("worktree", "add", "--detach", "-f", str(path), rev)
    applied = []
    for p in patches:
        if subprocess.run(["git", "merge-base", "--is-ancestor", p, rev], cwd=ROOT).returncode == 0:
            continue  # already in the revision
        git("cherry-pick", "--no-commit", p, cwd=path)
        applied.append(git("rev-parse", "--short", p))
    return {"rev": rev, "commit": git("rev-parse", "--short", rev), "patches": applied}


def bench_once(tree: Path, size: str, quality: str, out: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, "-m", "serenity", "bench", "courtyard", "--size", size, "--frames", "24",
                    "--quality", quality, "--json", str(out)], cwd=tree, env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    d = json.loads(out.read_text())
    o, s = d["overlapped"], d["serial"]
    tracer = "cpu ray tracing"
    return {"overlapped_ms": o["frame_ms"], "serial_ms": s["frame_ms"], "cpu_ms": o["cpu_ms"],
            "serial_cpu_ms": s["cpu_ms"], "lpv_update_ms": o["lpv_update_ms"], "sky_update_ms": o["sky_update_ms"],
            "tracer_overlapped_ms": o["stages_ms"].get(tracer, 0.0),
            "tracer_serial_ms": s["stages_ms"].get(tracer, 0.0),
            "stages_overlapped_ms": o["stages_ms"], "stages_serial_ms": s["stages_ms"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("revs", nargs="+")
    ap.add_argument("--patch", action="append", default=[], help="commit applied on top of every revision lacking it")
    ap.add_argument("--sizes", default="320x180,640x360")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--quality", default="lpv-fast")
    ap.add_argument("--json", default=str(ROOT / "serenity_out" / "frame_ab.json"))
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="serenity-ab-"))
    trees, held = [], []
    t0 = time.perf_counter()
    try:
        for k, rev in enumerate(args.revs):
            path = tmp / f"rev{k}"
            held.append(checkout(rev, args.patch, path))
            trees.append(path)
        sizes = args.sizes.split(",")
        runs = {rev: {size: [] for size in sizes} for rev in args.revs}
        jobs = [(p, size, k) for p in range(args.pairs) for size in sizes
                for k in (range(len(trees)) if p % 2 == 0 else reversed(range(len(trees))))]
        for p, size, k in tqdm(jobs, desc="frame A/B", unit="bench"):
            r = bench_once(trees[k], size, args.quality, tmp / "bench.json")
            runs[args.revs[k]][size].append({"pair": p, **r})
    finally:
        for path in trees:
            subprocess.run(["git", "worktree", "remove", "--force", str(path)], cwd=ROOT, capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)
    result = {"benchmark": "frame_ab", "cpus": os.cpu_count(),
              "quality": args.quality, "pairs": args.pairs, "revisions": held, "seconds": time.perf_counter() - t0,
              "runs": runs, "medians": {}}
    for rev in args.revs:
        result["medians"][rev] = {}
        for size in args.sizes.split(","):
            rs = runs[rev][size]
            med = {key: statistics.median(r[key] for r in rs) for key in rs[0] if key != "pair"
                   and not key.startswith("stages_")}
            for key in ("stages_overlapped_ms", "stages_serial_ms"):  # each stage's median over the runs
                med[key] = {st: statistics.median(r[key].get(st, 0.0) for r in rs) for st in rs[0][key]}
            med["tracer_ratio"] = statistics.median(r["tracer_overlapped_ms"] / max(r["tracer_serial_ms"], 1e-9)
                                                    for r in rs)
            result["medians"][rev][size] = med
            print(f"{rev} {size}: overlapped {med['overlapped_ms']:.1f} ms, serial {med['serial_ms']:.1f} ms, "
                  f"{med['cpu_ms']:.0f} CPU-ms, LPV update {med['lpv_update_ms']:.1f}, sky stage "
                  f"{med['sky_update_ms']:.1f}, tracer {med['tracer_overlapped_ms']:.1f} / "
                  f"{med['tracer_serial_ms']:.1f} ms")
    write_results(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
