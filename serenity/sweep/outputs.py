"""What people look at after a sweep: the metrics per point, a contact sheet, time-of-day animations.

- ``metrics.csv`` / ``metrics.json``: one row per point (scene, size, time, quality) — the sun's
  elevation, our last frame's wall time (ms) and its task's time (s), the reference's task time and
  whether it came from the cache, relMSE (also without the worst 0.1% of pixels, ``rel_mse_trim``)
  and FLIP against the reference, the files, and the error
  when a task of the point failed.
- ``contact_sheet.png``: per (scene, size) a block with one row per quality (our frames, FLIP and
  relMSE under each, the trimmed relMSE in brackets) and a row of references; one column per time
  (at most :data:`MAX_COLUMNS`, evenly chosen).
- ``time_of_day_<scene>_<size>_<quality>.gif``: our frames in time order (beside the reference when
  the sweep has one), through Pillow, when the sweep has more than one time.
Timings measured while several workers share a machine are what that sweep saw, not benchmarks.
"""

from __future__ import annotations

import csv
import io
import os

import numpy as np
from PIL import Image, ImageDraw

from serenity.io.atomic import atomic_write
from serenity.io.provenance import provenance
from serenity.sweep.files import write_json
from serenity.sweep.spec import SweepSpec, Task, scene_label

MAX_COLUMNS = 12
TILE_W = 200
"""Contact-sheet tile width, pixels (images are scaled to it, nearest-neighbour when enlarged)."""
GIF_MIN_W = 320
GIF_FRAME_MS = 250

COLUMNS = ["scene", "size", "time", "quality", "status", "error", "sun_elevation_deg", "frame_wall_ms", "frame_task_s",
           "reference_spp", "reference_task_s", "reference_cached", "rel_mse", "rel_mse_trim", "flip", "frame_png",
           "reference_png", "flip_png", "frame_key", "reference_key", "compare_key"]


def _point_key(inputs: dict) -> tuple:
    return inputs["scene"], inputs["width"], inputs["height"], inputs["time"]


def points(spec: SweepSpec, tasks: list[Task], manifest: dict) -> list[dict]:
    """One dict per point, keyed as :data:`COLUMNS`, in the sweep's order."""
    recs = manifest["tasks"]
    refs = {_point_key(t.inputs): t for t in tasks if t.kind == "reference"}
    compares = {t.deps[0]: t for t in tasks if t.kind == "compare"}
    frames = [t for t in tasks if t.kind == "frame"]
    rows = []
    for main in frames or list(refs.values()):
        inp = main.inputs
        ref = refs.get(_point_key(inp))
        cmp_ = compares.get(main.key) if main.kind == "frame" else None
        mine = [t for t in (main if main.kind == "frame" else None, ref, cmp_) if t is not None]
        rs = {t.kind: recs.get(t.key, {}) for t in mine}
        # the first failure only: a comparison fails when its frame or reference did
        errors = [f"{k}: {r.get('error') or 'not run'}" for k, r in rs.items() if r.get("status") != "done"][:1]
        f, r, c = rs.get("frame", {}), rs.get("reference", {}), rs.get("compare", {})
        rows.append({
            "scene": scene_label(inp["scene"]), "size": f"{inp['width']}x{inp['height']}",
            "time": inp["time"] or "", "quality": inp.get("quality", "") if main.kind == "frame" else "",
            "status": "done" if not errors else "error", "error": "; ".join(errors),
            "sun_elevation_deg": _round(f.get("sun_elevation_deg", r.get("sun_elevation_deg")), 3),
            "frame_wall_ms": _round(f.get("timings", {}).get("frame_wall_ms"), 2),
            "frame_task_s": f.get("timings", {}).get("task_s"),
            "reference_spp": ref.inputs["spp"] if ref else None,
            "reference_task_s": r.get("timings", {}).get("task_s"), "reference_cached": r.get("cached"),
            "rel_mse": c.get("metrics", {}).get("rel_mse"), "rel_mse_trim": c.get("metrics", {}).get("rel_mse_trim"),
            "flip": c.get("metrics", {}).get("flip"),
            "frame_png": f.get("outputs", {}).get("png"), "reference_png": r.get("outputs", {}).get("png"),
            "flip_png": c.get("outputs", {}).get("flip_png"),
            "frame_key": main.key if main.kind == "frame" else None, "reference_key": ref.key if ref else None,
            "compare_key": cmp_.key if cmp_ else None,
        })
    return rows


def _round(x, digits: int):
    return None if x is None else round(float(x), digits)


def summaries_exist(out: str, spec: SweepSpec) -> bool:
    return all(os.path.exists(os.path.join(out, n)) for n in ("metrics.csv", "metrics.json", "contact_sheet.png"))


def write_summaries(spec: SweepSpec, tasks: list[Task], manifest: dict, out: str) -> list[str]:
    """Write metrics.csv/json, the contact sheet and the animations; return their paths."""
    rows = points(spec, tasks, manifest)
    written = []
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: ("" if v is None else v) for k, v in row.items()})

    def put_csv(tmp):
        with open(tmp, "w", newline="") as f:
            f.write(buf.getvalue())

    path = os.path.join(out, "metrics.csv")
    atomic_write(path, put_csv)
    written.append(path)
    path = os.path.join(out, "metrics.json")
    # where the summary came from (command, commit, machine, date), then the sweep's points
    write_json(path, {**provenance(), "sweep": spec.name, "spec_hash": spec.hash, "exposure": spec.exposure,
                      "points": rows})
    written.append(path)
    path = os.path.join(out, "contact_sheet.png")
    sheet = contact_sheet(spec, rows, out)
    atomic_write(path, sheet.save)
    written.append(path)
    for name, frames in animations(spec, rows, out).items():
        path = os.path.join(out, name)
        atomic_write(path, lambda p, fr=frames: fr[0].save(p, save_all=True, append_images=fr[1:],
                                                            duration=GIF_FRAME_MS, loop=0))
        written.append(path)
    return written


# ------------------------------------------------------------------------------------------- images


def _open(out: str, rel: str | None):
    if not rel or not os.path.exists(os.path.join(out, rel)):
        return None
    with Image.open(os.path.join(out, rel)) as im:
        return im.convert("RGB")


def _fit(im, width: int):
    h = max(1, round(im.height * width / im.width))
    return im.resize((width, h), Image.Resampling.NEAREST if width >= im.width else Image.Resampling.LANCZOS)


def _placeholder(w: int, h: int, text: str):
    im = Image.new("RGB", (w, h), (90, 90, 90))
    d = ImageDraw.Draw(im)
    for i in range(0, len(text), max(1, w // 7)):
        d.text((4, 4 + 12 * (i // max(1, w // 7))), text[i:i + max(1, w // 7)], fill=(255, 200, 200))
    return im


def _columns(times: list) -> list:
    if len(times) <= MAX_COLUMNS:
        return times
    idx = np.unique(np.round(np.linspace(0, len(times) - 1, MAX_COLUMNS)).astype(int))
    return [times[i] for i in idx]


def contact_sheet(spec: SweepSpec, rows: list[dict], out: str):
    """The contact sheet as a Pillow image (see the module docstring)."""
    label_w, cap_h, head_h, pad = 120, 26, 22, 6
    blocks = []  # (title, [(row label, [(tile image, caption)])])
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["scene"], r["size"]), []).append(r)
    all_times = list(dict.fromkeys(r["time"] for r in rows))
    cols = _columns(all_times)
    for (scene, size), rs in groups.items():
        w, h = (int(x) for x in size.split("x"))
        tile_h = max(1, round(h * TILE_W / w))
        by_q: dict[str, dict] = {}
        refs: dict[str, dict] = {}
        for r in rs:
            by_q.setdefault(r["quality"], {})[r["time"]] = r
            refs.setdefault(r["time"], r)
        lines = []
        if any(r["frame_key"] for r in rs):
            for q, per_t in by_q.items():
                tiles = []
                for t in cols:
                    r = per_t.get(t)
                    im = _open(out, r and r["frame_png"])
                    tile = _fit(im, TILE_W) if im else _placeholder(TILE_W, tile_h, (r or {}).get("error") or "-")
                    cap = _caption(r)
                    tiles.append((tile, cap))
                lines.append((f"ours: {q}", tiles))
        if any(r["reference_key"] for r in rs):
            tiles = []
            for t in cols:
                r = refs.get(t)
                im = _open(out, r and r["reference_png"])
                tile = _fit(im, TILE_W) if im else _placeholder(TILE_W, tile_h, "reference failed")
                sun = r and r["sun_elevation_deg"]
                tiles.append((tile, f"sun {sun:.1f} deg" if sun is not None else ""))
            lines.append((f"reference {spec.spp} spp", tiles))
        blocks.append((f"{scene} {size}", lines, tile_h))

    width = label_w + len(cols) * (TILE_W + pad) + pad
    height = head_h + sum(head_h + len(ls) * (th + cap_h + pad) for _, ls, th in blocks) + pad
    sheet = Image.new("RGB", (width, height), (255, 255, 255))
    d = ImageDraw.Draw(sheet)
    shown = f"{len(cols)} of {len(all_times)} times" if len(cols) < len(all_times) else f"{len(cols)} time(s)"
    d.text((pad, 5), f"sweep {spec.name}  |  exposure {spec.exposure:g}  |  {shown}  |  spec {spec.hash[:10]}",
           fill=(0, 0, 0))
    y = head_h
    for title, lines, tile_h in blocks:
        d.text((pad, y + 5), title, fill=(0, 0, 120))
        for i, t in enumerate(cols):
            d.text((label_w + i * (TILE_W + pad), y + 5), (t or "scene's sun")[:24], fill=(0, 0, 0))
        y += head_h
        for label, tiles in lines:
            d.text((pad, y + tile_h // 2), label, fill=(0, 0, 0))
            for i, (tile, cap) in enumerate(tiles):
                x = label_w + i * (TILE_W + pad)
                sheet.paste(tile, (x, y))
                d.text((x, y + tile.height + 4), cap, fill=(0, 0, 0))
            y += tile_h + cap_h + pad
    return sheet


def _caption(r: dict | None) -> str:
    if not r:
        return ""
    if r["flip"] is not None:
        trim = f" ({r['rel_mse_trim']:.3g})" if r["rel_mse_trim"] is not None else ""
        return f"FLIP {r['flip']:.3f} relMSE {r['rel_mse']:.3g}{trim}"
    if r["frame_wall_ms"] is not None:
        return f"{r['frame_wall_ms']:.0f} ms"
    return r["status"]


def animations(spec: SweepSpec, rows: list[dict], out: str) -> dict:
    """{file name: [Pillow frames]} for each (scene, size, quality) with more than one time."""
    if len(spec.times) < 2:
        return {}
    seqs: dict[tuple, list[dict]] = {}
    for r in rows:
        if r["frame_key"]:
            seqs.setdefault((r["scene"], r["size"], r["quality"]), []).append(r)
    result = {}
    for (scene, size, q), rs in seqs.items():
        frames = []
        for r in rs:
            ims = [_open(out, r["frame_png"]), _open(out, r["reference_png"]) if r["reference_key"] else None]
            ims = [im for im in ims if im is not None]
            if not ims:
                continue
            scale = max(1, -(-GIF_MIN_W // ims[0].width) if ims[0].width < GIF_MIN_W else 1)
            ims = [_fit(im, im.width * scale) for im in ims]
            canvas = Image.new("RGB", (sum(im.width for im in ims), ims[0].height + 18), (255, 255, 255))
            x = 0
            for im in ims:
                canvas.paste(im, (x, 18))
                x += im.width
            sun = r["sun_elevation_deg"]
            text = f"{r['time']}  sun {sun:.1f} deg" if sun is not None else r["time"]
            if len(ims) == 2:
                text += "   ours | reference"
            ImageDraw.Draw(canvas).text((4, 3), text, fill=(0, 0, 0))
            frames.append(canvas)
        if frames:
            safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in f"{scene}_{size}_{q}")
            result[f"time_of_day_{safe}.gif"] = frames
    return result
