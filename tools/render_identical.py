"""Check that a refactor left ``serenity render`` unchanged: render the same scenes with a base
revision and with the working tree, and compare the PNG files byte for byte and every EXR layer
value for value.

    python tools/render_identical.py --base $(git merge-base main HEAD) \
        --json serenity_out/render_identical.json courtyard:320x180 glass:320x180 courtyard:640x360

Compare against the branch's merge base, not a moving ``main``: commits that landed on main since
the branch forked would show up as differences.

The base revision is exported with ``git archive`` into a temporary folder and run from there
(``PYTHONPATH`` first), so neither checkout is touched. Exit status 0 when every output is
identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tarfile
import tempfile

from diff_renders import diff  # tools/ is this script's folder, first on sys.path

from serenity.io.exr import read_exr
from serenity.io.results import write_results

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def render(tree: str, scene: str, size: str, png: str) -> None:
    """``serenity render SCENE --size SIZE -o PNG`` with the package of ``tree``."""
    env = {**os.environ, "PYTHONPATH": tree}
    subprocess.run([sys.executable, "-m", "serenity", "render", scene, "--size", size, "-o", png],
                   cwd=tree, env=env, check=True, stdout=subprocess.DEVNULL)


def compare(before_png: str, after_png: str) -> dict:
    """PNG bytes, then every EXR layer through ``diff_renders.diff`` (a layer missing on one side
    is not identical)."""
    with open(before_png, "rb") as f, open(after_png, "rb") as g:
        png_same = f.read() == g.read()
    a = read_exr(os.path.splitext(before_png)[0] + ".exr")
    b = read_exr(os.path.splitext(after_png)[0] + ".exr")
    layers = {name: diff(a[name], b[name]) if name in a and name in b else {"identical": False, "missing": True}
              for name in sorted(set(a) | set(b))}
    return {"png_bytes_identical": png_same, "exr_layers": layers,
            "identical": png_same and all(v["identical"] for v in layers.values())}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cases", nargs="+", help="SCENE:WxH, e.g. courtyard:320x180")
    p.add_argument("--base", default="main", help="git revision to compare against (default %(default)s)")
    p.add_argument("--json", help="write the result here")
    args = p.parse_args(argv)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    base = subprocess.run(["git", "rev-parse", args.base], cwd=ROOT, capture_output=True, text=True,
                          check=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                                capture_output=True, text=True).stdout.strip())
    out = {"base": base, "head": head, "head_has_uncommitted_changes": dirty, "cases": {}}
    with tempfile.TemporaryDirectory(prefix="serenity-identical-") as tmp:
        base_tree = os.path.join(tmp, "base")
        os.makedirs(base_tree)
        archive = subprocess.run(["git", "archive", "--format=tar", base], cwd=ROOT, capture_output=True,
                                 check=True).stdout
        tar_path = os.path.join(tmp, "base.tar")
        with open(tar_path, "wb") as f:
            f.write(archive)
        with tarfile.open(tar_path) as t:
            t.extractall(base_tree, filter="data")
        for case in args.cases:
            scene, size = case.split(":")
            pngs = [os.path.join(tmp, f"{which}_{scene}_{size}.png") for which in ("before", "after")]
            render(base_tree, scene, size, pngs[0])
            render(ROOT, scene, size, pngs[1])
            out["cases"][case] = compare(*pngs)
            print(f"{case}: {'identical' if out['cases'][case]['identical'] else 'DIFFERENT'}", flush=True)
    out["identical"] = all(c["identical"] for c in out["cases"].values())
    if args.json:
        write_results(args.json, out)
    return 0 if out["identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
