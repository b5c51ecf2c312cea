"""The tables of README.md and docs/*.md, printed from the result JSON in benchmarks/: no figure in a
table is typed by hand.

    python tools/doc_tables.py --write         # fill every table in README.md and docs/*.md
    python tools/doc_tables.py --check         # exit 1 and print a diff when a table differs from its JSON
    python tools/doc_tables.py --print NAME    # one table on stdout
    python tools/doc_tables.py --list          # every table's name and the JSON it reads

A document asks for a table by name between two lines of its own::

    <!-- table: frontier-summary -->
    (whatever is here is replaced by --write)
    <!-- /table -->

Each table is a function of its JSON files (:data:`TABLES`, registered with :func:`table`); under
it a line names the files and the machine they were measured on, whose full provenance (command,
commit, CPU, cores, date) is in each file. ``make figures`` re-measures every JSON and then runs
``--write``; ``tests/test_doc_tables.py`` runs ``--check``.
"""

from __future__ import annotations

import argparse
import difflib
import json
import re
import statistics
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BENCHMARKS = ROOT / "benchmarks"
DOCS = ("README.md", "docs/*.md")
"""The documents whose tables are filled (globs relative to the repository's root)."""

OPEN = re.compile(r"^<!-- table: ([a-z0-9-]+) -->$")
CLOSE = "<!-- /table -->"

DEFAULT_PRESET = "traced-probes"
PRESET_NAMES = {"low": "traced-probes", "medium": "lpv-fast", "high": "lpv"}
"""Result JSON recorded under the presets' former names reads with today's (``serenity.config``'s
aliases)."""


class DocTableError(Exception):
    """A document or a result file that the tables cannot be made from; the message names it."""


@dataclass(frozen=True)
class Table:
    name: str
    sources: tuple[str, ...]
    """JSON files relative to benchmarks/."""
    render: Callable[..., str]
    doc: str


TABLES: dict[str, Table] = {}


def table(name: str, *sources: str):
    """Register ``fn(*loaded_sources) -> markdown`` as the table ``name``."""

    def register(fn):
        TABLES[name] = Table(name, sources, fn, (fn.__doc__ or "").strip().split("\n")[0])
        return fn

    return register


def preset(name: str) -> str:
    return PRESET_NAMES.get(name, name)


def load(source: str) -> dict:
    path = BENCHMARKS / source
    name = f"benchmarks/{source}"
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise DocTableError(f"{name} is missing: `make figures` writes it") from None
    except json.JSONDecodeError as e:
        raise DocTableError(f"{name} is not valid JSON ({e})") from None


def render(name: str) -> str:
    """The table ``name`` as markdown, with the line that names its sources."""
    t = TABLES[name]
    data = [load(s) for s in t.sources]
    return t.render(*data).rstrip("\n") + "\n\n" + source_line(t.sources, data)


def source_line(sources: tuple[str, ...], data: list[dict]) -> str:
    machines = []
    for d in data:
        m = d.get("machine") or {}
        gpu = f", {m['gpu']}" if m.get("gpu") else ""
        cpu = m.get("cpu") or "unrecorded"
        cpu = "CPU unrecorded" if cpu == "unrecorded" else cpu
        text = f"{cpu}, {m.get('cores', '?')} cores{gpu}"
        if text not in machines:
            machines.append(text)
    dates = sorted({str(d.get("date", ""))[:10] for d in data if d.get("date")})
    files = ", ".join(f"`benchmarks/{s}`" for s in sources)
    when = f"; {dates[0]}" + (f" to {dates[-1]}" if len(dates) > 1 else "") if dates else ""
    return f"<sub>From {files} ({'; '.join(machines)}{when}).</sub>"


def f1(x: float) -> str:
    return f"{x:.1f}"


def size_label(size) -> str:
    w, h = (size.lower().split("x") if isinstance(size, str) else size)
    return f"{int(w)}×{int(h)}"


def md(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------- the frontier


def _frontier_describe(r: dict) -> str:
    from serenity.eval.frontier import describe

    return describe(r)


def _frontier_goal_met(r: dict, goal: float) -> bool:
    from serenity.eval.frontier import goal_met

    return goal_met(r, goal)


def _curve(name: str) -> str:
    """A peer curve's name: "raw" (Mitsuba alone), an OIDN quality (Mitsuba + the denoiser) or a Cycles curve
    ("cycles", "cycles+oidn-fast", "cycles+oidn-accurate": serenity.eval.cycles.CURVES), as it is."""
    return name if name == "raw" or name.startswith("cycles") else f"+ OIDN {name}"


@table("frontier-summary", "results/frontier.json")
def frontier_summary(data: dict) -> str:
    """The default preset against the path tracer + denoiser, per scene and size (README)."""
    rows = []
    for c, s in zip(data["cases"], data["summary"], strict=True):
        ours = next(o for o in c["ours"] if preset(o["name"]) == DEFAULT_PRESET)
        r = c["equal_error"]["flip"][ours["name"]]
        at = "—" if r["peer_ms"] is None else f"{r['peer_ms']:.0f}"
        moving = "—"
        if "moving" in ours:
            rmov = c["equal_error_moving"]["flip"][ours["name"]]
            moving = f"{ours['moving']['ms']:.0f} ms, {ours['moving']['flip']:.3f}: **{_frontier_describe(rmov)}**"
        rows.append([c["scene"], size_label(s["size"]), f"{ours['ms']:.0f}", f"{ours['flip']:.3f}", at,
                     f"**{_frontier_describe(r)}**", moving])
    return md(["scene", "size", f"ours, `{DEFAULT_PRESET}` (ms)", "FLIP", "path tracer + denoiser at that FLIP (ms)",
               "equal-FLIP speed-up", "camera moving: ms, FLIP, speed-up"], rows)


@table("frontier", "results/frontier.json")
def frontier(data: dict) -> str:
    """Every preset against the path tracer + denoiser: ms, FLIP, relMSE*, the equal-error speed-ups."""
    goal = data["goal_speedup"]
    rows = []
    for c, s in zip(data["cases"], data["summary"], strict=True):
        for o in c["ours"]:
            r = c["equal_error"]["flip"][o["name"]]
            rm = c["equal_error"]["rel_mse_trimmed"][o["name"]]
            name = f"`{preset(o['name'])}`"
            name = f"**{name}**" if o["name"] == s["flip"]["config"] else name
            at = "—" if r["peer_ms"] is None else f"{r['peer_ms']:.0f} ({_curve(r['curve'])})"
            moving, met = "—", _frontier_goal_met(r, goal)
            if "moving" in o:
                rmov = c["equal_error_moving"]["flip"][o["name"]]
                moving = f"{o['moving']['ms']:.0f} ms, {o['moving']['flip']:.3f}: {_frontier_describe(rmov)}"
                met = met and _frontier_goal_met(rmov, goal)
            rows.append([c["scene"], size_label(s["size"]), name, f"{o['ms']:.0f}", f"{o['flip']:.3f}",
                         f"{o['rel_mse_trimmed']:.3f}", at, _frontier_describe(r), _frontier_describe(rm), moving,
                         "yes" if met else "no"])
    return md(["scene", "size", "ours", "ms", "FLIP", "relMSE*", "path tracer at our FLIP: ms (its curve)",
               "equal-FLIP speed-up", "equal-relMSE* speed-up", "camera moving: ms, FLIP, equal-FLIP speed-up",
               f"≥ {goal:g}×, still and moving"], rows)


@table("frontier-regions", "results/frontier.json")
def frontier_regions(data: dict) -> str:
    """Where the default preset's error sits in each case (the region report), the leak ratio, and
    the reference's own noise floor where the case measured it."""
    rows = []
    for c in data["cases"]:
        o = next((o for o in c["ours"] if preset(o["name"]) == DEFAULT_PRESET), None)
        if o is None or "regions" not in o:
            continue
        ref = c["reference"]
        floor = ref.get("floor")
        ref_text = f"{ref['spp']} spp" + ("" if floor is None else
                                          f"; floor {floor['flip']:.3f} / {floor['rel_mse']:.3f}")
        reg = o["regions"]

        def lum(name, reg=reg):
            v = reg.get(name, {}).get("luminance_ratio")
            return "—" if v is None else f"{v:.2f}"

        leak = o["leak"]["max_ratio"]
        rows.append([c["scene"], size_label(c["size"]), ref_text, f"{o['flip']:.3f}", f"{o['rel_mse']:.3f}",
                     f"{o['luminance_ratio']:.2f}", lum("up-facing"), lum("down-facing"), lum("vertical"),
                     f"{reg['edges']['flip']:.3f} ({100 * reg['edges']['flip_share']:.0f} %)",
                     "—" if leak is None else f"{leak:.1f}"])
    return md(["scene", "size", "reference (floor: FLIP / relMSE)", "FLIP", "relMSE", "luminance ours ÷ ref",
               "up-facing", "down-facing", "vertical", "edges' FLIP (share)", "leak: max ratio in dark regions"],
              rows)


# ------------------------------------------------------------------------------------- the frame


FRAME_SIZES = ("320x180", "640x360")
FRAME_PRESETS = ("traced-probes", "lpv-fast")


def _frame_sources(name: str) -> tuple[str, ...]:
    return tuple(f"results/frame_bench_{name}_{s}.json" for s in FRAME_SIZES)


def frame_stages(*benches: dict) -> str:
    """Per stage: the median ms of each size's overlapped and serial schedule, and the paper's."""
    stages: list[str] = []
    for b in benches:
        for sched in ("overlapped", "serial"):
            stages += [k for k in b[sched]["stages_ms"] if k not in stages]
    paper = benches[0]["paper_table1_ms"]
    header = ["stage"] + [f"{size_label(b['size'])} {sched} (ms)" for b in benches
                          for sched in ("overlapped", "serial")]
    header.append("paper, 1280×720 on a GPU (ms)")

    def cells(fn) -> list[str]:
        return [fn(b[sched]) for b in benches for sched in ("overlapped", "serial")]

    rows = []
    for st in stages:
        vals = cells(lambda s, st=st: s["stages_ms"].get(st))
        rows.append([st] + ["—" if v is None else f"{v:.1f}" for v in vals]
                    + [f"{paper[st]:g}" if st in paper else "—"])
    lpv = [b["overlapped"]["lpv_update_ms"] for b in benches]
    if any(lpv):
        rows.append(["LPV update (its stages summed)"] + cells(lambda s: f1(s["lpv_update_ms"]))
                    + [f"{paper['lpv update']:g}"])
    rows.append(["sky volume update + upload"] + cells(lambda s: f1(s["sky_update_ms"])) + ["—"])
    rows.append(["frame without the sky volume update"] + cells(lambda s: f1(s["frame_without_sky_update_ms"]))
                + [f"{paper['frame']:g} (overlapped)"])
    rows.append(["**frame, wall clock**"] + cells(lambda s: f"**{f1(s['frame_ms'])}**") + ["—"])
    rows.append(["CPU time per frame, every thread of both processes"] + cells(lambda s: f1(s["cpu_ms"])) + ["—"])
    rows.append(["cores kept busy (CPU time ÷ wall clock)"] + cells(lambda s: f"{s['cores_busy']:.2f}") + ["—"])
    return md(header, rows)


for _p in FRAME_PRESETS:
    table(f"frame-stages-{_p}", *_frame_sources(_p))(frame_stages)


@table("frame-summary", *(src for p in FRAME_PRESETS for src in _frame_sources(p)))
def frame_summary(*benches: dict) -> str:
    """One line per preset and size: the frame overlapped and serial, its CPU time, the cores' bound."""
    rows = []
    for b in benches:
        o, s = b["overlapped"], b["serial"]
        rows.append([f"`{preset(b['quality'])}`", size_label(b["size"]), f"**{f1(o['frame_ms'])}**", f1(s["frame_ms"]),
                     f1(o["cpu_ms"]), f"{o['cores_busy']:.2f}", f1(o["cpu_bound_ms"])])
    return md(["preset", "size", "frame, overlapped (ms)", "frame, serial (ms)", "CPU-ms per frame",
               "cores busy", "no schedule beats (ms)"], rows)


@table("frame-cost", *_frame_sources(DEFAULT_PRESET))
def frame_cost(small: dict, large: dict) -> str:
    """One sentence: the default preset's frame while the sun moves, at both sizes (README)."""
    cores = large.get("machine", {}).get("cores") or large.get("machine", {}).get("cpus")
    return (f"While the sun moves, a frame of the default preset costs **{f1(large['overlapped']['frame_ms'])} ms** "
            f"at {size_label(large['size'])} and **{f1(small['overlapped']['frame_ms'])} ms** at "
            f"{size_label(small['size'])} on {cores} CPU cores without a GPU.")


@table("frame-repeat", "results/frame_repeat_lpv-fast_320x180.json")
def frame_repeat(rep: dict) -> str:
    """The same frame bench run several times in a row: how far one run's figure moves."""
    s = rep["summary"]

    def rng(key: str, fmt: str = "{:.1f}") -> str:
        v = s[key]
        return f"{fmt.format(v['min'])}–{fmt.format(v['max'])} (median {fmt.format(v['median'])})"

    return md(["preset, size", "runs", "frame, overlapped (ms)", "frame, serial (ms)", "overlapped ÷ serial",
               "wait for volumes (ms)"],
              [[f"`{preset(rep['quality'])}`, {size_label(rep['size'])}", str(len(rep["runs"])), rng("overlapped_ms"),
                rng("serial_ms"), rng("overlap_ratio", "{:.2f}"), rng("wait_for_volumes_ms", "{:.2f}")]])


@table("frame-threads", "results/frame_threads.json")
def frame_threads(data: dict) -> str:
    """Where a frame's CPU time goes, thread by thread (CPU-ms per frame and share)."""
    cols = [(size, sched) for size in data["sizes"] for sched in ("overlapped", "serial")]
    groups: list[str] = []
    for size, sched in cols:
        groups += [g for g in data["sizes"][size][sched]["cpu_ms_per_frame"] if g not in groups]
    rows = []
    for g in groups:
        cells = []
        for size, sched in cols:
            r = data["sizes"][size][sched]
            v = r["cpu_ms_per_frame"].get(g, 0.0)
            cells.append(f"{v:.1f} ({100 * r['share'].get(g, 0.0):.0f} %)")
        rows.append([g] + cells)
    rows.append(["all threads"] + [f1(data["sizes"][s][c]["cpu_ms_per_frame_total"]) for s, c in cols])
    rows.append(["frame, wall clock (median)"] + [f1(data["sizes"][s][c]["frame_ms_median"]) for s, c in cols])
    rows.append(["cores kept busy"] + [f"{data['sizes'][s][c]['cores_busy']:.2f}" for s, c in cols])
    return md(["CPU-ms per frame (share)"] + [f"{size_label(s)} {c}" for s, c in cols], rows)


@table("tracer-scheduling", "results/tracer_nice.json", "results/tracer_nice_load1.json")
def tracer_scheduling(idle: dict, busy: dict) -> str:
    """The tracer process's scheduling variants: tracer stage ÷ inline and frame ÷ serial, idle and busy."""
    sizes = list(idle["sizes"])

    def pair(data: dict, variant: str, key: str, bar: float, fmt: str) -> str:
        vals = [data["sizes"][s]["overlapped"][variant][key] for s in sizes]
        return " / ".join(f"**{fmt.format(v)}**" if v <= bar else fmt.format(v) for v in vals)

    rows = []
    for v in idle["variants"]:
        label = "default" if v == "default" else f"nice {v}"
        rows.append([label, pair(idle, v, "tracer_ratio_vs_serial", 1.5, "{:.2f}"),
                     pair(idle, v, "frame_ratio_vs_serial", 1.0, "{:.3f}"),
                     pair(busy, v, "tracer_ratio_vs_serial", 1.5, "{:.2f}"),
                     pair(busy, v, "frame_ratio_vs_serial", 1.0, "{:.3f}")])
    s = " / ".join(size_label(x) for x in sizes)
    return md([f"variant ({s})", "idle machine: tracer ÷ inline (bar ≤ 1.5)", "idle machine: frame ÷ serial (bar ≤ 1)",
               "one busy process beside: tracer ÷ inline", "one busy process beside: frame ÷ serial"], rows)


@table("render-output", "results/render_output.json")
def render_output(report: dict) -> str:
    """What `serenity render` printed on a recorded run, as it printed it."""
    from serenity.commands.render import format_report

    return "```\n" + format_report({**report, "quality": preset(report["quality"])}) + "\n```"


# ------------------------------------------------------------------------------------ the kd-tree


KDTREE_GOALS = {"embree": (0.5, ("coherent", "incoherent")), "warp": (1.5, ("incoherent",)),
                "scaling": (1.8, ("coherent", "incoherent"))}


def _kdtree_goal(key: str, per_set: dict[str, list[float]]) -> str:
    threshold, names = KDTREE_GOALS[key]
    parts = []
    for name in names:
        vals = per_set[name]
        met = sum(v >= threshold for v in vals)
        status = "met" if met == len(vals) else "not met" if met == 0 else f"met in {met} of {len(vals)} runs"
        parts.append(f"{'camera rays' if name == 'coherent' else 'incoherent rays'} {status}")
    return f"≥ {threshold} — " + ", ".join(parts)


@table("kdtree", "results/kdtree.json", "results/kdtree_repeat.json")
def kdtree(*runs: dict) -> str:
    """Ours against Embree and Warp's BVH, one value per run (the second run repeats the first)."""
    sets = ("coherent", "incoherent")
    fig = [r["figures"] for r in runs]

    def per_set(fn) -> dict[str, list[float]]:
        return {name: [fn(f, name) for f in fig] for name in sets}

    def suffix(name: str) -> str:
        return "" if name == "incoherent" else "_coherent"

    spec = [
        ("ours, Mrays/s, 1 thread", per_set(lambda f, n: f[n]["mrays_per_s"]["ours_1t"]), "{:.2f}", None),
        ("ours / Embree, 1 thread each (paired wall time)",
         per_set(lambda f, n: f["ratio_vs_embree_1t" + suffix(n)]), "{:.2f}", "embree"),
        ("ours / Warp `wp.Mesh` BVH, 1 thread each (paired)",
         per_set(lambda f, n: f["speedup_vs_warp_bvh_1t" + suffix(n)]), "{:.2f}", "warp"),
        ("ours / Embree, all threads each", per_set(lambda f, n: f["ratio_vs_embree_all_threads" + suffix(n)]),
         "{:.2f}", None),
        ("ours, 2 threads / 1 thread (paired wall time)",
         per_set(lambda f, n: statistics.median(f[n]["paired_ratios_per_round"]["ours_1t_over_ours_2t"])),
         "{:.2f}", "scaling"),
        ("Mrays per CPU-s, 2 threads ÷ 1 thread (1.0: the threads do not slow each other)",
         per_set(lambda f, n: f[n]["thread_cpu_efficiency"]), "{:.2f}", None),
        ("Σ thread CPU-s / busiest thread in the launches (1 thread: 1.0, 2 threads: 2.0 when balanced)",
         per_set(lambda f, n: f[n]["thread_scaling_cpu_bound"]), "{:.2f}", None),
        ("agreement with Embree (same triangle, or same t at a shared edge)",
         per_set(lambda f, n: f[n]["agreement_with_embree"]), "{:.6f}", None),
    ]
    rows = []
    for label, vals, fmt, goal in spec:
        cells = ["; ".join(fmt.format(v) for v in vals[name]) for name in sets]
        rows.append([label, cells[0], cells[1], _kdtree_goal(goal, vals) if goal else ""])
    if "build_1m_s" in fig[0]:
        b = fig[0]["build_1m_s"]
        rows.append(["build of 1 M triangles, measured (s, wall)", f"{b:.2f}", "",
                     f"≤ 5 — {'met' if b <= 5 else 'not met'}"])
    return md(["figure (one value per run, in the order given)", "coherent (camera)",
               "incoherent (random, from the hits)", "goal"], rows)


KDTREE_PHASE_ROWS = [
    ("traversal (`trace_packets`)", ("trace",)),
    ("gather of origins and directions (`move_in_order`)", ("move_in_order", "gather_rays", "gather_array")),
    ("scatter of the hits (`scatter_hits`)", ("scatter_hits", "scatter_array")),
    ("sort keys (`sort_keys_simd`)", ("sort_keys_simd", "sort_keys")),
    ("counting sort (`counting_order`)", ("counting_order",)),
    ("coherence sample, Python, allocation", ("sample_key_changes", "other")),
]
KDTREE_PHASE_COLUMNS = [("incoherent, 1 thread", "incoherent_1t"), ("incoherent, 2 threads", "incoherent_2t"),
                        ("camera rays, 1 thread", "coherent_1t")]


@table("kdtree-phases", "results/kdtree_phases.json")
def kdtree_phases(run: dict) -> str:
    """Where one 0.92 M-ray query's time goes: ms per call (share of the call) per phase."""
    cols = [(label, run["results"][key]) for label, key in KDTREE_PHASE_COLUMNS if key in run["results"]]
    rows = [["whole call"] + [f1(r["call_ms"]) for _, r in cols]]
    for k, (label, keys) in enumerate(KDTREE_PHASE_ROWS):
        cells = []
        for _, r in cols:
            parts = [r["phases"][key] for key in keys if key in r["phases"]]
            if not parts:
                cells.append("—")
                continue
            ms = sum(p["ms"] for p in parts)
            last = k == len(KDTREE_PHASE_ROWS) - 1
            cells.append(f1(ms) if last else f"{f1(ms)} ({100 * ms / r['call_ms']:.1f} %)")
        rows.append([label] + cells)
    return md(["phase (ms per call)"] + [label for label, _ in cols], rows)


@table("kdtree-counts", "results/kdtree_counts.json")
def kdtree_counts(data: dict) -> str:
    """Work per ray on trees of several build settings: inner-node steps, triangle tests, leaves."""
    rows = []
    for r in data["per_ray_means"]:
        c, i = r["coherent"], r["incoherent"]
        rows.append([f"`{r['config']}`", f"{r['nodes']:,}", f"{r['references']:,}",
                     f"{r['node_mib']:.1f} / {r['reference_mib']:.1f}",
                     f"{c['inner_steps']:.1f} / {c['triangle_tests']:.1f} / {c['non_empty_leaves']:.2f}",
                     f"{i['inner_steps']:.1f} / {i['triangle_tests']:.1f} / {i['non_empty_leaves']:.2f}"])
    return md(["tree (`KdBuildConfig`)", "nodes", "leaf references", "MiB: nodes / references",
               "camera rays: steps / triangle tests / leaves", "incoherent rays: steps / tests / leaves"], rows)


@table("kdtree-ropes", "results/kdtree_counts.json")
def kdtree_ropes(data: dict) -> str:
    """Reads per ray of the stack traversal against a model of a stackless traversal with ropes."""
    r = next(x for x in data["per_ray_means"] if x["config"] == "defaults")
    rows = []
    for name, label in (("coherent", "camera rays"), ("incoherent", "incoherent rays")):
        m = r[name]["rope_model"]
        root, grid = m["ropes_from_root"], m["ropes_from_grid_32"]
        rows.append([label, str(m["rays"]), f"{m['stack']['inner_steps']:.1f}",
                     f"{root['descent_steps']:.1f} + {root['leaves_entered']:.1f} = {root['node_and_leaf_reads']:.1f}",
                     f"{grid['descent_steps']:.1f} + {grid['leaves_entered']:.1f} = {grid['node_and_leaf_reads']:.1f}"])
    return md(["rays (default tree)", "rays walked", "stack traversal: inner steps",
               "ropes from the root: descents + leaves", "ropes from a 32³ entry table"], rows)


@table("kdtree-traversal-cost", "experiments/results/kdtree_traversal_cost.json")
def kdtree_traversal_cost(data: dict) -> str:
    """The SAH's traversal cost: the tree's size and Mrays per CPU-second against cost 2, one thread."""
    rows = []
    for v in data["versions"]:
        cost = v["rev"].split("traversal_cost=")[1] if "traversal_cost=" in v["rev"] else "3 (default)"
        rows.append([cost, f"{v['nodes']:,}", f"{v['references']:,}",
                     f"{v['coherent']['mrays_per_cpu_s']:.2f} ({v['coherent']['vs_first_paired']:.2f}×)",
                     f"{v['incoherent']['mrays_per_cpu_s']:.2f} ({v['incoherent']['vs_first_paired']:.2f}×)"])
    return md(["SAH traversal cost", "nodes", "leaf references", "camera rays, Mrays/CPU-s (paired ÷ cost 2)",
               "incoherent rays, Mrays/CPU-s (paired ÷ cost 2)"], rows)


# ------------------------------------------------------------------------------------- accuracy


def _baseline_rows(data: dict, scene: str, regions: tuple[str, ...], with_downward: bool) -> str:
    rows = []
    for r in data["results"]:
        if r["scene"] != scene:
            continue
        reg = r["regions"]["regions"]
        lum = " / ".join(f"{reg[k]['luminance_ratio']:.2f}" if k in reg else "—" for k in regions)
        row = [r["config"].replace("low preset", f"`{DEFAULT_PRESET}` preset"), f"{r['rel_mse']:.3f}",
               f"{r['rel_mse_trimmed']:.3f}"]
        if with_downward:
            row.append(f"{r['rel_mse_downward']:.3f}")
        rows.append(row + [f"{r['flip']:.3f}", lum])
    return rows


@table("accuracy-courtyard", "results/baseline.json")
def accuracy_courtyard(data: dict) -> str:
    """The courtyard against the path-traced reference, one technique added per row."""
    rows = _baseline_rows(data, "courtyard", ("down-facing", "up-facing", "vertical"), True)
    return md(["courtyard", "relMSE", "relMSE, 0.1 % trimmed", "relMSE, down-facing pixels", "FLIP",
               "luminance ours ÷ reference: down-facing / up / vertical"], rows)


@table("accuracy-cornell", "results/baseline.json")
def accuracy_cornell(data: dict) -> str:
    """The Cornell box (sun through the ceiling's hole, black sky) against the path-traced reference."""
    rows = _baseline_rows(data, "cornell", ("down-facing", "up-facing", "vertical"), False)
    return md(["Cornell box", "relMSE", "relMSE, 0.1 % trimmed", "FLIP",
               "luminance ours ÷ reference: ceiling / floor and box tops / walls"], rows)


@table("lpv-room", "results/lpv_room.json")
def lpv_room(data: dict) -> str:
    """The LPV with and without its self-illumination damping, against exact answers and Mitsuba."""
    default = next(k for k in data["thin_wall"] if k.startswith("**default"))
    undamped = next(k for k in data["thin_wall"] if k.endswith("(undamped)"))
    cornell = {r["config"]: r for r in data["cornell_indirect"]["rows"]}
    court = {r["config"]: r for r in data["courtyard"]["rows"]}
    rows = []
    for key, label in (("off", "off"), (undamped, "without damping"), (default, "**damping 2.5 cells (default)**")):
        c = cornell[key]
        ceiling = c.get("luminance_ratio", {}).get("down-facing")
        plane = data["plane_self_illumination"].get(key)
        wall = data["thin_wall"].get(key)
        cy = court.get(key)
        rows.append([label, f"{c['rel_mse']:.3f} ({c['rel_mse_trimmed']:.3f})", f"{c['flip']:.3f}",
                     "0" if ceiling is None else f"{ceiling:.2f}", f"{data['open_ground'][key]['luminance_ratio']:.3f}",
                     "—" if plane is None else f"{min(plane):.3f}–{max(plane):.3f}",
                     "—" if wall is None else f"{max(wall):.3f}",
                     "—" if cy is None else f"{cy['flip']:.4f} / {cy['rel_mse']:.4f}"])
    return md(["LPV", "Cornell indirect relMSE (trimmed)", "Cornell indirect FLIP", "ceiling ours ÷ ref",
               "open ground ours ÷ ref", "lit plane E_self/M", "thin wall E_dark/E_lit", "courtyard FLIP / relMSE"],
              rows)


@table("lpv-cornell", "results/lpv.json")
def lpv_cornell(data: dict) -> str:
    """The Cornell box's indirect light alone per LPV grid and iteration count, and the update's ms."""
    rows = [[r["config"], f1(r["update_ms"]), f"{r['rel_mse']:.3f}", f"{r['rel_mse_trimmed']:.3f}", f"{r['flip']:.3f}"]
            for r in data["cornell"]["rows"]]
    return md(["LPV", "update (ms)", "relMSE", "relMSE, 0.1 % trimmed", "FLIP"], rows)


@table("sky-model", "results/sky.json", "results/sky_sh.json", "results/sky_anchor.json")
def sky_model(sky: dict, sh: dict, anchor: dict) -> str:
    """The sky model's own errors: the sky map, its L2 irradiance, the volume, and an independent sky."""
    t = sky["transfer"]
    run = next((r for r in anchor["runs"] if r["turbidity"] == 3.0), anchor["runs"][0])
    sky_r = [x["sky_ratio"] for x in run["results"]]
    sun_r = [x["sun_ratio"] for x in run["results"] if x["elevation_deg"] >= 5]
    rows = [
        ["sky map (256², default steps) against a float64 march", "mean / worst relative error",
         f"{100 * sky['skymap_mean_rel_error']:.2f} % / {100 * sky['skymap_worst_rel_error']:.2f} %"],
        ["L2 SH irradiance of an open probe against the cosine integral", "mean relative error (L4 instead)",
         f"{100 * sh['l2_mean_rel_error']:.1f} % ({100 * sh['l4_mean_rel_error']:.2f} %)"],
        ["sky volume among the occlusion quads, by ray casting", "mean / worst relative error",
         f"{100 * sky['quad_irradiance_mean_rel_error']:.1f} % / {100 * sky['quad_irradiance_worst_rel_error']:.0f} %"],
        [f"sky volume by visibility transfer ({t['bands']} SH bands)", "mean / worst relative error",
         f"{100 * t['quad_irradiance_mean_rel_error']:.1f} % / {100 * t['quad_irradiance_worst_rel_error']:.0f} %"],
        ["the paper's 32×16×23 volume by ray casting", "whole volume / one layer (ms)",
         f"{sky['volume_full_ms']:.0f} / {sky['volume_layer_ms']:.0f}"],
        ["the same by visibility transfer", "build once / re-light every probe (ms)",
         f"{t['build_ms']:.0f} / {t['relight_all_probes_ms']:.1f}"],
        [f"our sky against Mitsuba's `sunsky` (turbidity {run['turbidity']:g}), 2°–90° sun",
         "sky's diffuse light on a plane, ours ÷ Mitsuba's", f"{min(sky_r):.2f}–{max(sky_r):.2f}"],
        ["the same, the sun's light (5°–90°)", "ours ÷ Mitsuba's", f"{min(sun_r):.2f}–{max(sun_r):.2f}"],
    ]
    return md(["what", "figure", "value"], rows)


@table("amortise", "results/amortise.json")
def amortise(data: dict) -> str:
    """The sky's layer cycle and the LPV's staggered cascades under motion: what they save and cost."""
    sizes = list(data["sizes"])
    names = list(data["sizes"][sizes[0]]["variants"])

    def per_size(name: str, key: str, fmt: str = "{:.1f}") -> str:
        return " / ".join(fmt.format(data["sizes"][s]["variants"][name][key]) for s in sizes)

    rows = []
    first = data["sizes"][sizes[0]]["variants"]
    for n in names:
        v = first[n]
        vs = "—" if "flip_vs_every_frame_mean" not in v else (
            f"{v['flip_vs_every_frame_mean']:.4f} / {v['flip_vs_every_frame_max']:.4f}")
        ref = "—" if "flip_vs_reference_mean" not in v else (
            f"{v['flip_vs_reference_mean']:.3f} / {v['rel_mse_vs_reference_mean']:.4f}")
        rows.append([n, per_size(n, "sky_stage_ms_median"), per_size(n, "lpv_update_ms_median"),
                     per_size(n, "frame_ms_median"), vs, ref])
    s = " / ".join(size_label(x) for x in sizes)
    return md([f"`{preset(data['quality'])}`, moving camera and sun", f"sky stage, ms ({s})", f"LPV update, ms ({s})",
               f"frame, ms ({s})", f"FLIP against updating every frame, mean / max ({size_label(sizes[0])})",
               "against the path tracer: FLIP / relMSE"], rows)


@table("aa", "results/aa.json")
def aa(data: dict) -> str:
    """Edges: FXAA, TAA and jittered accumulation of a still view, and FXAA and TAA with a moving
    camera (the last poses' mean, and the references' noise floor), against the path-traced reference."""
    rows = []
    for r in data["results"]:
        ms = r.get("all_frames_ms", r["aa_ms"] if r["aa_ms"] else 0.0)
        rows.append([r["scene"], "still", r["method"], f"{r['flip']:.4f}", f"{r['rel_mse']:.4f}",
                     f"{r['edge_flip']:.4f}", f"{r['edge_rel_mse']:.4f}", "—" if not ms else f1(ms)])
    moving = data.get("moving", {})
    for r in moving.get("results", []):
        rows.append([r["scene"], "moving", r["method"], f"{r['flip']:.4f}", f"{r['rel_mse']:.4f}",
                     f"{r['edge_flip']:.4f}", f"{r['edge_rel_mse']:.4f}", "—" if not r["aa_ms"] else f1(r["aa_ms"])])
    for name, floors in moving.get("reference_floor", {}).items():
        rows.append([name, "moving", f"reference's noise floor ({floors[0]['spp']} spp)",
                     f"{statistics.mean(f['flip'] for f in floors):.4f}",
                     f"{statistics.mean(f['rel_mse'] for f in floors):.4f}",
                     "—", "—", "—"])
    return md(["scene", "camera", "method", "FLIP", "relMSE", "edge pixels' FLIP", "edge pixels' relMSE",
               "ms (the AA pass, or every accumulated frame)"], rows)


@table("texture-taps", "results/aa.json")
def texture_taps(data: dict) -> str:
    """The G-buffer's anisotropic texture taps on the courtyard's textured ground."""
    rows = [[str(r["texture_taps"]), f"{r['flip']:.4f}", f"{r['rel_mse']:.4f}", f"{r['ground_flip']:.4f}",
             f"{r['ground_rel_mse']:.4f}", f"{r['gbuffer_ms']:.2f}"] for r in data["texture_taps"]]
    return md(["`texture_taps`", "FLIP", "relMSE", "ground's FLIP", "ground's relMSE", "G-buffer (ms)"], rows)


@table("stability", "results/stability.json")
def stability(data: dict) -> str:
    """Every failure case beside its exact answer, its mitigation off and on."""

    from serenity.eval.stability import format_error as fmt

    rows = [[r["technique"], r["case"], r["metric"], fmt(r["error_without"]), fmt(r["error_with"]), r["mitigation"],
             f"{r['ms_without']:.0f}", f"{r['ms_with']:.0f}"] for r in data["cases"]]
    return md(["technique", "case", "error metric (exact answer: 0)", "without mitigation", "with mitigation",
               "mitigation", "ms without", "ms with"], rows)


@table("temporal-stability", "results/temporal_stability.json", "results/temporal_stability_baseline.json")
def temporal_stability(now: dict, baseline: dict) -> str:
    """Every preset frame to frame under a slowly moving sun and camera, without and with the mitigations."""
    from serenity.eval.stability import temporal_stability_markdown

    return temporal_stability_markdown(now, baseline)


@table("temporal-stability-breakdown", "results/temporal_stability.json", "results/temporal_stability_baseline.json")
def temporal_stability_breakdown(now: dict, baseline: dict) -> str:
    """Where the sun sweep's pixel steps come from: the parts of the light and the amortisation switches."""
    from serenity.eval.stability import temporal_breakdown_markdown

    return temporal_breakdown_markdown(now, baseline)


# ---------------------------------------------------------------------------- CUDA and the viewer


@table("cuda", "results/cuda.json")
def cuda(data: dict) -> str:
    """The frame bench with Warp on CUDA and on the CPU of the same machine (OpenGL on its GPU)."""
    rows = []
    for device, sizes in data["bench"].items():
        for size, b in sizes.items():
            o, s = b["overlapped"], b["serial"]
            cores = b.get("machine", {}).get("cpus")
            label = f"{device} ({cores} cores)" if device == "cpu" and cores else device
            rows.append([label, size_label(size), f"{f1(o['frame_ms'])} / {f1(s['frame_ms'])}",
                         f1(o["frame_without_sky_update_ms"]), f1(o["lpv_update_ms"]), f1(o["sky_update_ms"])])
    preset_name = next(iter(next(iter(data["bench"].values())).values()))["quality"]
    return md([f"Warp on (`{preset(preset_name)}`)", "size", "frame, overlapped / serial (ms)",
               "without the sky update", "LPV update", "sky update"], rows)


@table("cuda-agreement", "results/cuda.json")
def cuda_agreement(data: dict) -> str:
    """The same frames with Warp on CUDA and on the CPU: how far apart the images are."""
    rows = [[a["scene"], size_label(a["size"]), f"{a['rel_mse']:.1e}", f"{a['flip']:.4f}",
             f"{100 * a['pixels_over_1pct']:.2f} %", f"{a['max_rel_diff']:.1e}"] for a in data["agreement"]]
    return md(["scene", "size", "relMSE of CUDA against the CPU", "FLIP", "pixels more than 1 % apart",
               "largest relative difference"], rows)


@table("viewer-cost", "results/view.json")
def viewer_cost(data: dict) -> str:
    """What the viewer's window adds to a frame, and what the read-back it skips would cost."""
    rows = []
    for label, v in (("accumulating TAA samples", data), ("`--taa 0`", data["no_taa"])):
        rows.append([label, f1(v["view_render_ms"]), f1(v["view_loop_ms"]), f1(v["view_overhead_ms"])])
    return md([f"{data['scene']} {size_label(data['size'])}, still camera, panel shown", "Renderer.render (ms)",
               "window loop (ms)", "TAA + present + panel + swap (ms)"], rows) + (
        f"\n\nThe read-back of HDR, LDR and AOVs that the viewer skips: {f1(data['readback_ms'])} ms per frame.")


STARTUP_PHASES = ("imports", "scene load", "renderer set-up", "tracer process start", "levels of detail", "frame",
                  "sky volume (gather)",
                  "ray tracer (kd-tree)", "probe rays (trace, surfels, moments)", "probe cache read",
                  "surfel shadow rays", "surfel updates", "probe gathers", "wait for the tracer process", "write PNG",
                  "write EXR", "close (tracer process stops)")


@table("startup", "results/startup.json")
def startup(data: dict) -> str:
    """`serenity render` of a big scene as a fresh process, empty and warm caches: seconds, memory, phases."""
    s, ph = data["summary"], data["phases"]

    def rng(kind: str, key: str, fmt: str = "{:.1f}") -> str:
        v = s[kind][key]
        return fmt.format(v["median"]) + (f" ({fmt.format(v['min'])}–{fmt.format(v['max'])})"
                                          if data["runs"] > 1 else "")

    rows = [["**`serenity render`, spawn to exit (s)**", rng("cold", "seconds"), rng("warm", "seconds")],
            ["peak resident memory, largest process (MB)", rng("cold", "peak_rss_mb", "{:.0f}"),
             rng("warm", "peak_rss_mb", "{:.0f}")],
            ["last frame (ms)", rng("cold", "frame_ms", "{:.0f}"), rng("warm", "frame_ms", "{:.0f}")],
            ["*instrumented run:* renderer's / tracer process's peak (MB)",
             *(f"{ph[k]['renderer_peak_rss_mb']:.0f} / " + ("–" if ph[k]["tracer_peak_rss_mb"] is None
                                                            else f"{ph[k]['tracer_peak_rss_mb']:.0f}")
               for k in ("cold", "warm"))],
            ["Python's own start", *(f"{ph[k]['python_start_s']:.2f}" for k in ("cold", "warm"))]]
    for name in STARTUP_PHASES:
        cells = [ph[k]["by_phase"].get(name) for k in ("cold", "warm")]
        if not any(cells):
            continue
        depth = next(c["depth"] for c in cells if c)
        calls = max(c["calls"] for c in cells if c)
        label = "&nbsp;&nbsp;" * depth + name + (f" (×{calls})" if calls > 1 else "")
        rows.append([label, *("–" if c is None else f"{c['seconds']:.2f}" for c in cells)])
    return md([f"{Path(data['scene']).stem} {size_label(data['size'])}, `{preset(data['quality'])}`",
               "empty caches", "warm caches"], rows)


@table("lod", "results/lod.json")
def lod(data: dict) -> str:
    """Levels of detail: triangles drawn, error against the reference and G-buffer cost per bound."""
    rows = []
    for size in data["sizes"]:
        base = size["bounds"]["0.0"]
        for rec in size["bounds"].values():
            label = "whole meshes" if rec["bound"] == 0 else f"{rec['bound']:g} px" + (
                " (default)" if rec["bound"] == data["default_bound"] else "")
            rows.append([size_label(size["size"]), label, f"{rec['triangles']:,}",
                         "–" if rec["flip"] is None else f"{rec['flip']:.4f}",
                         "–" if rec["rel_mse"] is None else f"{rec['rel_mse']:.3f}", f"{rec['gbuffer_ms_median']:.1f}",
                         f"{rec['frame_ms_median'] / base['frame_ms_median']:.2f}"])
    return md([f"{Path(data['scene']).stem}, `{preset('traced-probes')}`", "level error bound",
               "G-buffer triangles", "FLIP", "relMSE", "G-buffer ms", "frame ÷ whole meshes"], rows) + (
        f"\n\nBuilding the levels of its {data['meshes_with_levels']} dense meshes on an empty cache: "
        f"{data['build_seconds']:.1f} s.")


@table("dynamic-tracing", "results/dynamic_tracing.json")
def dynamic_tracing(data: dict) -> str:
    """Two-level ray tracing: a frame's update of the moving objects and their extra traversal, beside
    a kd-tree rebuilt over the posed scene."""
    st = data["settings"]
    w, h = st["camera_rays"]
    rows = []
    for label, runs in (("in one object", data["triangles"]["one_object"]),
                        ("over 10 objects", data["triangles"]["ten_objects"]),
                        ("objects of ~1k triangles", data["objects"][data["top_level_faster"]])):
        for r in runs:
            rows.append([f"{r['triangles']:,}", f"{r['objects']}", label, f"{r['update_ms']:.1f}",
                         f"{r['camera.extra_ms']:.1f}", f"{r['random.extra_ms']:.1f}", f"{r['rebuild_ms']:.0f}",
                         f"{r['camera.rebuilt_query_ms']:.1f}"])
    return md(["moving triangles", "objects", "arranged", "update (ms)", f"extra, {w}×{h} camera rays (ms)",
               f"extra, {st['random_rays'] // 1000}k random rays (ms)", "kd-tree rebuilt over the posed scene (ms)",
               "camera rays through it (ms)"], rows) + (
        f"\n\nStatic part: the {st['scene']} ({st['static_triangles']:,} triangles); {st['threads']} threads, "
        f"median of {st['frames']} frames; top level `{data['top_level_faster']}`.")


# ----------------------------------------------------------------------------------- the documents


def documents() -> list[Path]:
    out: list[Path] = []
    for pattern in DOCS:
        out += sorted(ROOT.glob(pattern))
    return out


def fill(text: str, where: str, rendered: dict[str, str] | None = None) -> str:
    """``text`` with every table between its markers replaced by what its JSON prints; ``where``
    names the document in errors. ``rendered`` caches tables across documents."""
    rendered = {} if rendered is None else rendered
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        m = OPEN.match(line.strip())
        if line.strip() == CLOSE:
            raise DocTableError(f"{where}:{i + 1}: '{CLOSE}' without a '<!-- table: NAME -->' before it")
        if not m:
            out.append(line)
            i += 1
            continue
        name = m.group(1)
        if name not in TABLES:
            raise DocTableError(f"{where}:{i + 1}: unknown table {name!r} (known: {', '.join(sorted(TABLES))})")
        j = i + 1
        while j < len(lines) and lines[j].strip() != CLOSE:
            if OPEN.match(lines[j].strip()):
                raise DocTableError(f"{where}:{j + 1}: table {name!r} opened on line {i + 1} is not closed "
                                    f"before the next one")
            j += 1
        if j == len(lines):
            raise DocTableError(f"{where}:{i + 1}: table {name!r} has no '{CLOSE}' line")
        if name not in rendered:
            try:
                rendered[name] = render(name)
            except DocTableError as e:
                raise DocTableError(f"{where}:{i + 1}: table {name!r}: {e}") from None
        out += [line, rendered[name], lines[j]]
        i = j + 1
    return "\n".join(out)


def run(write: bool) -> int:
    rendered: dict[str, str] = {}
    changed, used = [], 0
    for path in documents():
        rel = str(path.relative_to(ROOT))
        text = path.read_text()
        new = fill(text, rel, rendered)
        used += sum(1 for ln in text.split("\n") if OPEN.match(ln.strip()))
        if new == text:
            continue
        changed.append(rel)
        if write:
            path.write_text(new)
            print(f"doc_tables: wrote {rel}")
        else:
            sys.stdout.writelines(difflib.unified_diff(text.splitlines(True), new.splitlines(True), f"a/{rel}",
                                                       f"b/{rel}"))
    if changed and not write:
        print(f"doc_tables: {len(changed)} document(s) differ from their JSON ({', '.join(changed)}): "
              "run `python tools/doc_tables.py --write`", file=sys.stderr)
        return 1
    if not changed:
        print(f"doc_tables: {used} table(s) in {len(documents())} document(s) match their JSON")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", action="store_true", help="fill every table in README.md and docs/*.md")
    g.add_argument("--check", action="store_true", help="exit 1 with a diff when a table differs from its JSON")
    g.add_argument("--print", metavar="NAME", help="print one table")
    g.add_argument("--list", action="store_true", help="every table's name, what it shows and the JSON it reads")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    try:
        if args.list:
            for t in TABLES.values():
                print(f"{t.name:24} {t.doc}\n{'':24} <- {', '.join('benchmarks/' + s for s in t.sources)}")
            return 0
        if args.print:
            if args.print not in TABLES:
                raise DocTableError(f"unknown table {args.print!r} (known: {', '.join(sorted(TABLES))})")
            print(render(args.print))
            return 0
        return run(write=args.write)
    except DocTableError as e:
        print(f"doc_tables: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
