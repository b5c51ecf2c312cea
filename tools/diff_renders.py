"""Compare two ``serenity render`` outputs (PNG + multi-layer EXR) value by value, for refactors that
must not change the image.

    python tools/diff_renders.py BEFORE.png AFTER.png [--json FILE] [--note TEXT]

The EXR beside each PNG (same stem) is compared layer by layer. Per layer: identical (bit for
bit, NaN == NaN), the number of differing values and the largest absolute difference among the
finite ones. Exit status 0 when everything is identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from serenity.io.exr import read_exr
from serenity.io.png import read_png
from serenity.io.results import write_results


def diff(a: np.ndarray, b: np.ndarray) -> dict:
    if a.shape != b.shape:
        return {"identical": False, "shape": [list(a.shape), list(b.shape)]}
    same = (a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else a == b
    fin = np.isfinite(a) & np.isfinite(b) if a.dtype.kind == "f" else np.ones(a.shape, bool)
    d = np.abs(a[fin].astype(np.float64) - b[fin].astype(np.float64))
    return {"identical": bool(same.all()), "values_differing": int((~same).sum()), "values": int(a.size),
            "max_abs_diff": float(d.max(initial=0.0))}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("before")
    p.add_argument("after")
    p.add_argument("--json", help="write the comparison here")
    p.add_argument("--note", help="provenance recorded in the JSON (e.g. which commits rendered BEFORE and AFTER)")
    args = p.parse_args(argv)
    out = {"note": args.note, "before": args.before, "after": args.after,
           "png": diff(read_png(args.before), read_png(args.after))}
    ea, eb = (read_exr(os.path.splitext(x)[0] + ".exr") for x in (args.before, args.after))
    out["exr"] = {k: diff(ea[k], eb[k]) if k in eb else {"identical": False, "missing": True} for k in ea}
    out["identical"] = out["png"]["identical"] and all(v["identical"] for v in out["exr"].values())
    print(json.dumps(out, indent=2))
    if args.json:
        write_results(args.json, out)
    return 0 if out["identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
