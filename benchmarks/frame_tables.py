"""Print the README's Table-1 section (what each technique costs) from the committed JSONs.

    python benchmarks/frame_tables.py            # every table and figure line, as Markdown
    python benchmarks/frame_tables.py --render   # the quick start's `make render` output block

It measures nothing: it reads what ``bash benchmarks/regenerate.sh frame`` and ``... ab`` wrote in
``benchmarks/results/`` (``serenity bench``, ``bench_frame_repeat.py``, ``bench_pass_ab.py``,
``bench_gil_finish.py``) and prints the tables and the figures the README's prose quotes, so that
the README is rewritten from the run in hand and never from memory. It fails, naming the file, when
one is missing.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
sys.path.insert(0, str(RESULTS.parent.parent))

#: the Table-1 rows: label, the stage keys summed (or a schedule-level key), paper key
TABLE1_ROWS = [
    ("LPV update (3 cascades of 12³, one refreshed per frame; overlapped: on the volume worker, "
     "beside the GL passes)", "lpv_update_ms", "lpv update"),
    ("G-buffer", ("g-buffer",), None),
    ("shadow maps (CSM, tiles redrawn as they move)", ("shadow maps (CSM)",), None),
    ("direct lighting (Phong + CSM + PCSS, and the upsampling of the quarter-resolution indirect "
     "light)", ("direct lighting",), "direct lighting"),
    ("sky lighting (quarter resolution, diffuse + glossy)", ("sky lighting",), "sky lighting"),
    ("LPV lighting, diffuse + glossy (quarter resolution, self-illumination damping)", ("lpv lighting",),
     "lpv lighting"),
    ("SSAO (quarter resolution)", ("ssao",), "ssao"),
    ("CPU ray tracing (with a sun shadow ray per hit)", ("cpu ray tracing",), "cpu ray tracing"),
    ("composite + tone map (full-screen passes)", ("composite", "tone map"), None),
]

RT_STAGES = ("rt direct lighting", "rt sky lighting", "rt lpv lighting")
LOWRES_PASSES = ("low-res guide", "ssao", "sky lighting", "lpv lighting")


def load(name: str) -> dict:
    path = RESULTS / name
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        sys.exit(f"frame_tables: {path} is missing: run `bash benchmarks/regenerate.sh frame` / `ab` first")
    except json.JSONDecodeError as e:
        sys.exit(f"frame_tables: {path} is not valid JSON ({e})")


def f1(x: float) -> str:
    return f"{x:.1f}"


def stage(stages_ms: dict, keys) -> float:
    """The sum of the named stages' ms (a stage a run lacks counts 0)."""
    return sum(stages_ms.get(k, 0.0) for k in keys)


def table1(bench: dict) -> str:
    over, ser, paper = bench["overlapped"], bench["serial"], bench["paper_table1_ms"]
    rows = ["| stage | ours, overlapped (ms) | ours, serial (ms) | paper (ms) |", "| --- | --- | --- | --- |"]
    for label, keys, pkey in TABLE1_ROWS:
        if isinstance(keys, str):
            o, s = over[keys], ser[keys]
        else:
            o, s = stage(over["stages_ms"], keys), stage(ser["stages_ms"], keys)
        p = "—" if pkey is None else f"{paper[pkey]:g}"
        rows.append(f"| {label} | {f1(o)} | {f1(s)} | {p} |")
    rt = lambda sch: " / ".join(f1(sch["stages_ms"].get(k, 0.0)) for k in RT_STAGES)  # noqa: E731
    rows.append(f"| RT: direct lighting / sky lighting / LPV lighting | {rt(over)} | {rt(ser)} | "
                + " / ".join(f"{paper[k]:g}" for k in RT_STAGES) + " |")
    rows.append("| frame without the sky volume update (as the paper's Table 1; overlapped: less only its "
                f"upload, since the update runs beside) | {f1(over['frame_without_sky_update_ms'])} | "
                f"{f1(ser['frame_without_sky_update_ms'])} | {paper['frame']:g} (overlapped) / 68 (serial) |")
    rows.append("| sky volume update (rebake + one layer by transfer + the host side of its upload; "
                f"overlapped: on the volume worker) + upload | {f1(over['sky_update_ms'])} | "
                f"{f1(ser['sky_update_ms'])} | — |")
    rows.append(f"| frame, wall clock | **{f1(over['frame_ms'])}** | {f1(ser['frame_ms'])} | — |")
    rows.append("| CPU time per frame, every thread of both processes (`Frame.cpu_ms`) | "
                f"{f1(over['cpu_ms'])} | {f1(ser['cpu_ms'])} | — |")
    rows.append(f"| cores kept busy (CPU time ÷ wall clock) | {over['cores_busy']:.2f} | {ser['cores_busy']:.2f} | — |")
    return "\n".join(rows)


def pair(bench: dict) -> str:
    o, s = bench["overlapped"], bench["serial"]
    return (f"{f1(o['frame_ms'])} / {f1(s['frame_ms'])} ms overlapped / serial (ratio {bench['overlap_ratio']:.2f}), "
            f"without the sky update {f1(o['frame_without_sky_update_ms'])} / {f1(s['frame_without_sky_update_ms'])}, "
            f"sky stage {f1(o['sky_update_ms'])} / {f1(s['sky_update_ms'])}, "
            f"CPU {f1(o['cpu_ms'])} / {f1(s['cpu_ms'])} ms ({o['cores_busy']:.2f} / {s['cores_busy']:.2f} cores busy; "
            f"no schedule beats {f1(o['cpu_bound_ms'])} ms), cpu ray tracing {f1(o['stages_ms']['cpu ray tracing'])} / "
            f"{f1(s['stages_ms']['cpu ray tracing'])} ms, wait for volumes "
            f"{o['stages_ms'].get('wait for volumes', 0.0):.2f} ms")


def tiles_table() -> str:
    rows = ["| schedule, size (JSON `pass_ab_round15_tiles_*`) | guide + SSAO + sky + LPV lighting, a → b "
            "(ms, sum of medians) | frame, a → b (ms) |", "| --- | --- | --- |"]
    for label, suffix in (("serial, 320×180", "serial_320x180"), ("overlapped, 320×180", "320x180"),
                          ("overlapped, 640×360", "640x360")):
        d = load(f"pass_ab_round15_tiles_{suffix}.json")
        a, b = d["variants"]["a"], d["variants"]["b"]
        sa, sb = stage(a["stages_ms_median"], LOWRES_PASSES), stage(b["stages_ms_median"], LOWRES_PASSES)
        ident = "" if d["images_identical"] else " (images differ!)"
        rows.append(f"| {label} (`{suffix}`){ident} | {sa:.2f} → {sb:.2f} | {f1(a['frame_ms_median'])} → "
                    f"{f1(b['frame_ms_median'])} |")
    return "\n".join(rows)


def ab_line(name: str) -> str:
    d = load(name)
    a, b = d["variants"]["a"], d["variants"]["b"]
    return (f"`{name}` (stage {d['stage']!r}, a = today's preset, b = {b['config']}): stage "
            f"{a['stage_ms_median']:.2f} vs {b['stage_ms_median']:.2f} ms, frame {f1(a['frame_ms_median'])} vs "
            f"{f1(b['frame_ms_median'])} ms; FLIP {a['flip']:.4f} vs {b['flip']:.4f}, relMSE {a['rel_mse']:.4f} vs "
            f"{b['rel_mse']:.4f}, relMSE* {a['rel_mse_trimmed']:.3f} vs {b['rel_mse_trimmed']:.3f}")


def main() -> None:
    if "--render" in sys.argv[1:]:
        from serenity.commands.render import format_report  # what the command printed, as it printed it

        print(format_report(load("render_output.json")))
        return
    benches = {name: load(name) for name in ("frame_bench.json", "frame_bench_320.json", "frame_bench_run1.json",
                                             "frame_bench_320_run1.json", "frame_bench_low.json",
                                             "frame_bench_320_low.json")}
    print("## Table 1: `frame_bench.json` (640x360, medium)\n")
    print(table1(benches["frame_bench.json"]))
    print("\n## The frame, run by run\n")
    for name, d in benches.items():
        size = d["size"] if isinstance(d["size"], str) else "x".join(map(str, d["size"]))
        print(f"- `{name}` ({d['quality']}, {size}): {pair(d)}")
    rep = load("frame_repeat_320.json")
    s = rep["summary"]
    print(f"- `frame_repeat_320.json` ({len(rep['runs'])} runs): overlapped {f1(s['overlapped_ms']['min'])}–"
          f"{f1(s['overlapped_ms']['max'])} ms (median {f1(s['overlapped_ms']['median'])}), serial "
          f"{f1(s['serial_ms']['min'])}–{f1(s['serial_ms']['max'])} (median {f1(s['serial_ms']['median'])}), "
          f"ratio {s['overlap_ratio']['min']:.2f}–{s['overlap_ratio']['max']:.2f} (median "
          f"{s['overlap_ratio']['median']:.2f}), wait for volumes median {s['wait_for_volumes_ms']['median']:.2f} ms")
    runs_320 = [benches[n]["overlapped"]["frame_ms"] for n in ("frame_bench_320.json", "frame_bench_320_run1.json")]
    runs_320 += [r["overlapped_ms"] for r in rep["runs"]]
    print(f"- 320×180 medium, overlapped, every run above: {len(runs_320)} runs, "
          f"{sum(v <= 30.0 for v in runs_320)} of them ≤ 30 ms (the goal), best {f1(min(runs_320))} ms")
    print("\n## Round 15: low-res targets on llvmpipe's tiles (a = unpadded, b = padded)\n")
    print(tiles_table())
    print("\n## Round 14's A/Bs\n")
    for name in ("pass_ab_round14_medium_shadow_courtyard.json", "pass_ab_round14_medium_shadow_cornell.json",
                 "pass_ab_round14_contact3_courtyard.json", "pass_ab_round14_contact3_cornell.json",
                 "pass_ab_round14_skymap_courtyard.json"):
        print(f"- {ab_line(name)}")
    g = load("gil_finish.json")
    rate = lambda k: "–".join(f"{v:.0f}" for v in sorted(r["worker_launches_per_s"] for r in g[k]))  # noqa: E731
    print(f"- `gil_finish.json`: worker launches/s beside a GL pass: {rate('moderngl_finish')} through "
          f"ctx.finish(), {rate('ctypes_finish')} through the GIL-free finish, "
          f"{g['worker_alone_launches_per_s']:.0f} alone")


if __name__ == "__main__":
    main()
