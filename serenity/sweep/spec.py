"""Sweep files: what to render, parsed and expanded into tasks.

A sweep file is TOML::

    [sweep]
    name = "courtyard-day"                 # optional (default: the file's stem)
    scenes = ["courtyard", "my/scene.toml"]  # built-in names or files (relative to this file)
    sizes = ["160x90", "320x180"]          # WxH, pixels
    quality = ["lpv-fast", "baseline"]     # presets traced-probes | lpv-fast | lpv | paper, or "baseline"
    produce = ["frame", "reference", "compare"]   # any of these; "compare" implies the other two

    [time]                                 # optional: without it every scene keeps its own sun
    start = "2024-06-21 06:30 +01:00"      # serenity.scene.parse_time strings
    end = "2024-06-21 21:00 +01:00"        # inclusive when the steps land on it
    step_minutes = 90
    # or: times = ["2024-06-21 09:00 +01:00", "2024-06-21 18:00 +01:00"]
    latitude = 38.72                       # degrees (default: the scene's location, else Lisbon)
    longitude = -9.14

    [render]                               # our frames
    frames = 2                             # frames rendered per point; the last one is kept and timed
    exposure = 0.02                        # before Reinhard, for every PNG (ours, reference) and FLIP
    device = "cpu"                         # optional: cpu | cuda:0 (default: cuda:0 when present)

    [reference]                            # the Mitsuba 3 path-traced reference
    spp = 64
    component = "full"                     # direct | one-bounce | full | indirect
    seed = 0

A *point* is one (scene, size, time, quality). Per point the sweep runs a ``frame`` task (ours, per
quality) and shares one ``reference`` task between the qualities of a (scene, size, time); a
``compare`` task then needs both. Each task has a key: a readable prefix and a hash of everything
that changes its result (for scene files: their bytes; for a quality: the preset's settings), so an
edited scene file or preset is a new task. The renderer's and the exporter's code are not in the key
(the reference cache has its own version): after changing them, use a new results directory.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass, field
from datetime import datetime, timedelta

from serenity.config import (
    DEFAULT_QUALITY,
    PRESET_ALIASES,
    QUALITY_PRESETS,
    LPVConfig,
    RenderConfig,
    SkyConfig,
    check_image_size,
    preset_name,
)
from serenity.errors import SerenityError
from serenity.eval.reference import COMPONENTS
from serenity.scene.procedural import scene_names
from serenity.scene.sun import parse_time

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

TASK_FORMAT = 1
"""Bump when a task's outputs change meaning (invalidates every key)."""
COMPARE_FORMAT = 2
"""Bump when the comparison's metrics change (invalidates the compare tasks only). 2: trimmed relMSE."""
PRODUCTS = ("frame", "reference", "compare")
MAX_TASKS = 100_000

_ALLOWED = {
    "sweep": {"name", "scenes", "sizes", "quality", "produce", "out"},
    "time": {"start", "end", "step_minutes", "times", "latitude", "longitude"},
    "render": {"frames", "exposure", "device"},
    "reference": {"spp", "component", "seed"},
}


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep file (see the module docstring). Scenes are built-in names or absolute paths."""

    name: str
    scenes: tuple[str, ...]
    sizes: tuple[tuple[int, int], ...]
    qualities: tuple[str, ...] = (DEFAULT_QUALITY,)
    produce: tuple[str, ...] = ("frame",)
    times: tuple[str | None, ...] = (None,)
    """parse_time strings, or (None,) for each scene's own sun."""
    latitude: float | None = None
    """Degrees north; None: the scene's location, else Lisbon."""
    longitude: float | None = None
    """Degrees east; None: the scene's location, else Lisbon."""
    frames: int = 2
    """Frames rendered per point (the last is kept)."""
    exposure: float = 0.02
    """Multiplier before Reinhard for every PNG and for FLIP."""
    device: str | None = None
    spp: int = 64
    """Reference samples per pixel."""
    component: str = "full"
    seed: int = 0
    out: str | None = None
    """Results directory from the file (absolute), or None."""
    source: str | None = None
    """The sweep file this came from."""

    def to_dict(self) -> dict:
        d = asdict(self)
        d["sizes"] = [f"{w}x{h}" for w, h in self.sizes]
        return d

    @property
    def hash(self) -> str:
        """SHA-256 of what the sweep asks for (not where it came from or where it writes)."""
        d = self.to_dict()
        d.pop("source")
        d.pop("out")
        d["scene_files"] = [scene_fingerprint(s) for s in self.scenes]
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()


@dataclass(frozen=True)
class Task:
    """One unit of work. ``inputs`` is JSON-able and fully determines the result."""

    kind: str
    key: str
    inputs: dict
    deps: tuple[str, ...] = field(default=())
    """Keys of the tasks whose results this one needs (compare: frame, reference)."""


def _err(where: str, msg: str) -> SerenityError:
    return SerenityError(f"{where}: {msg}")


def _str_list(v, where: str, allow_empty: bool = False) -> list[str]:
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, str) and x.strip() for x in v):
        raise _err(where, f"must be a string or a list of non-empty strings, got {v!r}")
    if not v and not allow_empty:
        raise _err(where, "must not be empty")
    return [x.strip() for x in v]


def _number(v, where: str, lo: float, hi: float, integer: bool = False):
    ok = isinstance(v, int) if integer else isinstance(v, (int, float))
    if isinstance(v, bool) or not ok or not (math.isfinite(v) and lo <= v <= hi):
        kind = "an integer" if integer else "a number"
        raise _err(where, f"must be {kind} in {lo:g}..{hi:g}, got {v!r}")
    return v


def _parse_size(text: str, where: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise _err(where, f"size must look like 320x180, got {text!r}") from None
    return _parse(lambda _: check_image_size(w, h, "size"), text, where)


def _expand_times(t: dict, where: str) -> list[str]:
    if "times" in t:
        if {"start", "end", "step_minutes"} & set(t):
            raise _err(f"{where} [time]", "give either times = [...] or start/end/step_minutes, not both")
        times = _str_list(t["times"], f"{where} [time].times")
        for s in times:
            _parse(parse_time, s, f"{where} [time].times")
        return times
    missing = [k for k in ("start", "end", "step_minutes") if k not in t]
    if missing:
        raise _err(f"{where} [time]", f"needs start, end and step_minutes (missing {', '.join(missing)})")
    start = _parse(parse_time, t["start"], f"{where} [time].start")
    end = _parse(parse_time, t["end"], f"{where} [time].end")
    if (start.tzinfo is None) != (end.tzinfo is None):
        raise _err(f"{where} [time]", "start and end must both have a UTC offset or both have none")
    step = _number(t["step_minutes"], f"{where} [time].step_minutes", 1e-3, 1e7)
    if end < start:
        raise _err(f"{where} [time]", f"end {t['end']!r} is before start {t['start']!r}")
    n = int(math.floor((end - start) / timedelta(minutes=step) + 1e-9)) + 1
    if n > MAX_TASKS:
        raise _err(f"{where} [time]", f"{n} times is too many (at most {MAX_TASKS})")
    return [_format_time(start + timedelta(minutes=step * i)) for i in range(n)]


def _parse(fn, value, where: str):
    try:
        return fn(value)
    except SerenityError as e:
        raise _err(where, str(e)) from None


def _format_time(t: datetime) -> str:
    s = t.strftime("%Y-%m-%d %H:%M")
    if t.second or t.microsecond:
        s += f":{t.second + t.microsecond * 1e-6:06.3f}".rstrip("0").rstrip(".")
    off = t.utcoffset()
    if off is not None:
        mins = int(off.total_seconds() // 60)
        sign = "+" if mins >= 0 else "-"
        s += f" {sign}{abs(mins) // 60:02d}:{abs(mins) % 60:02d}"
    return s


def load_spec(path: str) -> SweepSpec:
    """Parse a sweep file; any problem is a one-line ``SerenityError`` naming the file and field."""
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise SerenityError(f"{path}: sweep file not found") from None
    except IsADirectoryError:
        raise SerenityError(f"{path}: is a directory, not a sweep file") from None
    except tomllib.TOMLDecodeError as e:
        raise SerenityError(f"{path}: not valid TOML ({e})") from None
    return spec_from_dict(data, path)


def spec_from_dict(data: dict, path: str = "<sweep>") -> SweepSpec:
    """A :class:`SweepSpec` from the tables of a sweep file (``path`` names it in errors and anchors
    relative scene paths)."""
    for table, value in data.items():
        if table not in _ALLOWED:
            raise _err(path, f"unknown table [{table}] (known: {', '.join(f'[{k}]' for k in _ALLOWED)})")
        if not isinstance(value, dict):
            raise _err(path, f"{table} must be a table [{table}]")
        unknown = sorted(set(value) - _ALLOWED[table])
        if unknown:
            raise _err(f"{path} [{table}]", f"unknown key {unknown[0]!r} (known: {', '.join(sorted(_ALLOWED[table]))})")
    sw = data.get("sweep")
    if sw is None:
        raise _err(path, "needs a [sweep] table with at least scenes = [...] and sizes = [...]")
    base = os.path.dirname(os.path.abspath(path)) if path != "<sweep>" else os.getcwd()
    for k in ("scenes", "sizes"):
        if k not in sw:
            raise _err(f"{path} [sweep]", f"needs {k} = [...]")
    scenes = tuple(_resolve_scene(s, base) for s in _str_list(sw["scenes"], f"{path} [sweep].scenes"))
    sizes = tuple(_parse_size(s, f"{path} [sweep].sizes") for s in _str_list(sw["sizes"], f"{path} [sweep].sizes"))
    qualities = tuple(_quality_name(q, f"{path} [sweep].quality")
                      for q in _str_list(sw.get("quality", [DEFAULT_QUALITY]), f"{path} [sweep].quality"))
    for q in qualities:
        _parse(quality_config, q, f"{path} [sweep].quality")
    produce = _str_list(sw.get("produce", ["frame"]), f"{path} [sweep].produce")
    for p in produce:
        if p not in PRODUCTS:
            raise _err(f"{path} [sweep].produce", f"unknown product {p!r} (known: {', '.join(PRODUCTS)})")
    if "compare" in produce:
        produce += ["frame", "reference"]
    produce_t = tuple(p for p in PRODUCTS if p in produce)
    name = sw.get("name", os.path.splitext(os.path.basename(path))[0])
    if not isinstance(name, str) or not name.strip():
        raise _err(f"{path} [sweep].name", f"must be a non-empty string, got {name!r}")
    out = sw.get("out")
    if out is not None:
        if not isinstance(out, str) or not out.strip():
            raise _err(f"{path} [sweep].out", f"must be a directory path, got {out!r}")
        out = os.path.join(base, out)

    t = data.get("time")
    times: tuple[str | None, ...] = (None,)
    lat = lon = None
    if t is not None:
        times = tuple(_expand_times(t, path))
        if ("latitude" in t) != ("longitude" in t):
            raise _err(f"{path} [time]", "give both latitude and longitude, or neither")
        if "latitude" in t:
            lat = float(_number(t["latitude"], f"{path} [time].latitude", -90, 90))
            lon = float(_number(t["longitude"], f"{path} [time].longitude", -180, 180))

    r = data.get("render", {})
    frames = _number(r.get("frames", 2), f"{path} [render].frames", 1, 1000, integer=True)
    exposure = float(_number(r.get("exposure", 0.02), f"{path} [render].exposure", 1e-9, 1e9))
    device = r.get("device")
    if device is not None and (not isinstance(device, str) or not device.strip()):
        raise _err(f"{path} [render].device", f"must be a device name like 'cpu' or 'cuda:0', got {device!r}")

    ref = data.get("reference", {})
    spp = _number(ref.get("spp", 64), f"{path} [reference].spp", 1, 1 << 20, integer=True)
    component = ref.get("component", "full")
    if component not in COMPONENTS:
        raise _err(f"{path} [reference].component", f"must be one of {', '.join(COMPONENTS)}, got {component!r}")
    seed = _number(ref.get("seed", 0), f"{path} [reference].seed", 0, 2**31 - 1, integer=True)

    spec = SweepSpec(name=name.strip(), scenes=scenes, sizes=sizes, qualities=qualities, produce=produce_t,
                     times=times, latitude=lat, longitude=lon, frames=frames, exposure=exposure, device=device,
                     spp=spp, component=component, seed=seed, out=out,
                     source=os.path.abspath(path) if path != "<sweep>" else None)
    n = len(expand(spec))
    if n > MAX_TASKS:
        raise _err(path, f"expands to {n} tasks, more than {MAX_TASKS}")
    return spec


def _resolve_scene(s: str, base: str) -> str:
    """A built-in name stays a name; anything else is a path relative to the sweep file."""
    candidate = os.path.join(base, s)
    if s in scene_names() and not os.path.exists(candidate):
        return s
    return os.path.normpath(candidate)


BASELINE = "baseline"
"""The quality name of the constant-ambient baseline (no sky volume, no LPV: the one the GI must beat)."""
QUALITIES = (*QUALITY_PRESETS, BASELINE)


def _quality_name(name: str, where: str) -> str:
    """A sweep file's quality as its current name: a former preset name becomes the preset's name
    now (with a one-line warning naming the file), so that task keys and output names use it."""
    return preset_name(name, where) if name in PRESET_ALIASES else name


def quality_config(name: str) -> RenderConfig:
    """The ``RenderConfig`` of a sweep's quality: a preset (``RenderConfig.preset``: traced-probes |
    lpv-fast | lpv | paper), or "baseline": the default preset with a constant ambient term instead
    of the sky volume and the LPV."""
    if name == BASELINE:
        return RenderConfig.preset(DEFAULT_QUALITY, ambient="constant", sky=SkyConfig(enabled=False),
                                   lpv=LPVConfig(enabled=False))
    if name not in QUALITY_PRESETS and name not in PRESET_ALIASES:
        raise SerenityError(f"unknown quality {name!r} (known: {', '.join(QUALITIES)})")
    return RenderConfig.preset(name)


def scene_fingerprint(scene: str) -> str:
    """What identifies a scene's content: a built-in name as is, a file by the SHA-256 of its bytes."""
    if not os.path.isabs(scene):
        return f"builtin:{scene}"
    try:
        with open(scene, "rb") as f:
            return "sha256:" + hashlib.sha256(f.read()).hexdigest()
    except OSError:
        return "unreadable"


def scene_label(scene: str) -> str:
    return os.path.splitext(os.path.basename(scene))[0] if os.path.isabs(scene) else scene


def _key(kind: str, readable: list[str], inputs: dict) -> str:
    h = hashlib.sha256(json.dumps({"format": TASK_FORMAT, "kind": kind, **inputs}, sort_keys=True).encode())
    safe = "-".join("".join(c if c.isalnum() or c in "._" else "_" for c in str(r)) for r in readable if r)
    return f"{kind}-{safe}-{h.hexdigest()[:12]}"


def _time_tag(t: str | None) -> str:
    return "scene-sun" if t is None else t[:16].replace("-", "").replace(" ", "T").replace(":", "")


def expand(spec: SweepSpec) -> list[Task]:
    """Every task of the sweep, references before frames before comparisons (no duplicates)."""
    tasks: dict[str, Task] = {}
    # a preset is a name; its settings go into the key, so a preset that changes means new frames
    configs = {q: hashlib.sha256(repr(quality_config(q)).encode()).hexdigest() for q in spec.qualities}
    for scene in spec.scenes:
        fp = scene_fingerprint(scene)
        for w, h in spec.sizes:
            for t in spec.times:
                place = {"time": t, "latitude": spec.latitude, "longitude": spec.longitude}
                common = {"scene": scene, "scene_fingerprint": fp, "width": w, "height": h, **place}
                ref_key = None
                if "reference" in spec.produce:
                    inp = {**common, "spp": spec.spp, "component": spec.component, "seed": spec.seed}
                    ref_key = _key("reference", [scene_label(scene), f"{w}x{h}", _time_tag(t)],
                                   {**inp, "scene": None})
                    tasks.setdefault(ref_key, Task("reference", ref_key, inp))
                for q in spec.qualities:
                    if "frame" not in spec.produce:
                        continue
                    inp = {**common, "quality": q, "frames": spec.frames, "exposure": spec.exposure,
                           "device": spec.device}
                    fkey = _key("frame", [scene_label(scene), f"{w}x{h}", _time_tag(t), q],
                                {**inp, "scene": None, "config": configs[q]})
                    tasks.setdefault(fkey, Task("frame", fkey, inp))
                    if "compare" in spec.produce:
                        ckey = _key("compare", [scene_label(scene), f"{w}x{h}", _time_tag(t), q],
                                    {"frame": fkey, "reference": ref_key, "exposure": spec.exposure,
                                     "metrics": COMPARE_FORMAT})
                        tasks.setdefault(ckey, Task("compare", ckey, {"exposure": spec.exposure, **common,
                                                                       "quality": q}, deps=(fkey, ref_key)))
    order = {"reference": 0, "frame": 1, "compare": 2}
    return sorted(tasks.values(), key=lambda task: order[task.kind])
