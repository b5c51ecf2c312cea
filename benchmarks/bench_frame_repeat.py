"""The Table-1 frame benchmark run several times in a row, to show how far one run's figure moves.

    python benchmarks/bench_frame_repeat.py [--runs 5] [--size 320x180] [--quality lpv-fast] [--json FILE]

Each run is a fresh ``serenity bench courtyard --frames 24`` process (the overlapped and the serial
schedule in turns, frame by frame); this collects each run's median overlapped and serial frame,
their ratio and the wait for the volume worker, and the median and range over the runs. On the
shared 2-core machines one run's frame moved by up to ~15 % from the next; the ratio, measured
within a run, moves less.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from serenity.io.results import write_results  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--quality", default="lpv-fast")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--json", default=None, help="default: benchmarks/results/frame_repeat_<quality>_<size>.json")
    args = ap.parse_args()
    out = args.json or str(ROOT / f"benchmarks/results/frame_repeat_{args.quality}_{args.size}.json")
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in tqdm(range(args.runs), desc=f"serenity bench x{args.runs}", unit="run"):
            path = Path(tmp) / f"run{i}.json"
            subprocess.run([sys.executable, "-m", "serenity", "bench", "courtyard", "--frames", str(args.frames),
                            "--size", args.size, "--quality", args.quality, "--json", str(path),
                            "--chart", str(Path(tmp) / f"run{i}.png")],
                           cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            d = json.loads(path.read_text())
            runs.append({"overlapped_ms": d["overlapped"]["frame_ms"], "serial_ms": d["serial"]["frame_ms"],
                         "overlap_ratio": d["overlap_ratio"],
                         "wait_for_volumes_ms": d["overlapped"]["stages_ms"].get("wait for volumes", 0.0),
                         "cpu_ms": d["overlapped"]["cpu_ms"], "machine": d["machine"]})
    summary = {}
    for key in ("overlapped_ms", "serial_ms", "overlap_ratio", "wait_for_volumes_ms"):
        v = np.array([r[key] for r in runs])
        summary[key] = {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max())}
    for key, s in summary.items():
        print(f"{key:22s} median {s['median']:.3f}  range {s['min']:.3f} .. {s['max']:.3f}")
    write_results(out, {"scene": "courtyard", "size": args.size, "quality": args.quality, "frames": args.frames,
                        "runs": runs, "summary": summary})


if __name__ == "__main__":
    main()
