"""The sweep figures of docs/sweeps.md: runs ``examples/sweep_day.toml`` on Dask and copies its contact
sheet, the lpv-fast preset's time-of-day GIF and the metrics into the repository.

    python examples/sweep_day.py [--workers N] [--out DIR]

Same as ``serenity sweep examples/sweep_day.toml`` followed by the copies: ``docs/sweep_contact_sheet.png``,
``docs/sweep_day.gif`` and ``benchmarks/results/sweep_day.json`` (the sweep's metrics.json). A rerun
reuses the finished tasks in DIR.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys

from serenity.sweep import load_spec, run_sweep

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core)")
    p.add_argument("--out", default=os.path.join("serenity_out", "sweep", "sweep_day"))
    args = p.parse_args(argv[1:])
    result = run_sweep(load_spec(os.path.join(HERE, "sweep_day.toml")), args.out, workers=args.workers)
    copies = {"contact_sheet.png": os.path.join(ROOT, "docs", "sweep_contact_sheet.png"),
              "time_of_day_courtyard_160x90_lpv-fast.gif": os.path.join(ROOT, "docs", "sweep_day.gif"),
              "metrics.json": os.path.join(ROOT, "benchmarks", "results", "sweep_day.json")}
    for src, dst in copies.items():
        shutil.copyfile(os.path.join(result.out, src), dst)
        print(f"copied {dst}")
    return 1 if result.failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
