"""Scripted viewer sessions (``serenity view --script FILE``): timed input for demos and tests.

A script is a TOML file of ``[[step]]`` tables, each run at the start of frame ``frame`` (frames
count from 0; the first frame builds everything) and holding exactly one action::

    [[step]]
    frame = 2
    key = "W"            # a key held down ...
    hold = 6             # ... for this many frames (default 1), through the window's key handler
    [[step]]
    frame = 9
    mouse = [40, -10]    # mouse-look by (dx, dy) pixels, as a right-button drag would
    [[step]]
    frame = 10
    set = { hour = 9.5, view = "albedo" }   # what the panel's widgets set
    [[step]]
    frame = 12
    press = "F12"        # a key pressed and released (F12 saves, R starts a reference, ...)
    [[step]]
    frame = 14
    screenshot = "shot.png"   # the window as shown (panel included unless hidden), path from the cwd
    [[step]]
    frame = 15
    wait = "reference"   # block until the reference started by R is done (scripts only; frames pause)
    [[step]]
    frame = 16
    exit = true

Frames advance the fly camera by a fixed 1/30 s in scripted mode, so a script moves the camera
by the same distance however fast the machine renders. Unknown keys are errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

from serenity.config import PRESET_ALIASES, preset_name
from serenity.errors import SerenityError

ACTIONS = ("key", "mouse", "set", "press", "screenshot", "wait", "exit")
SETTABLE = {"hour": float, "date": str, "latitude": float, "longitude": float, "utc_offset": float,
            "exposure": float, "speed": float, "view": str, "quality": str, "shadow_filter": str,
            "ssao": bool, "sky_lighting": bool, "lpv_diffuse": bool, "lpv_glossy": bool, "reflections": bool,
            "refractions": bool, "taa": bool, "panel": bool, "split": float}
SCRIPT_DT = 1.0 / 30.0
"""Seconds of camera motion per frame in scripted mode."""


@dataclass
class Step:
    frame: int
    action: str
    value: object
    hold: int = 1


@dataclass
class Script:
    steps: list[Step] = field(default_factory=list)
    path: str = ""

    @property
    def last_frame(self) -> int:
        return max((s.frame + (s.hold if s.action == "key" else 0) for s in self.steps), default=0)

    def at(self, frame: int) -> list[Step]:
        return [s for s in self.steps if s.frame == frame]

    def held(self, frame: int) -> set[str]:
        """Keys the script holds down during ``frame``."""
        return {str(s.value) for s in self.steps if s.action == "key" and s.frame <= frame < s.frame + s.hold}


def load_script(path: str) -> Script:
    """Parse and check a script file; every problem is a one-line ``SerenityError`` naming the step."""
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except FileNotFoundError:
        raise SerenityError(f"{path}: script file not found") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise SerenityError(f"{path}: not valid TOML ({str(e).splitlines()[0] if str(e) else e})") from None
    unknown = sorted(set(doc) - {"step"})
    if unknown:
        raise SerenityError(f"{path}: unknown table(s) {', '.join(unknown)} (a script holds [[step]] tables)")
    tables = doc.get("step", [])
    if not isinstance(tables, list):
        raise SerenityError(f"{path}: step must be an array of tables ([[step]]), got {tables!r}")
    steps = []
    for i, t in enumerate(tables):
        where = f"{path}: step {i + 1}"
        if not isinstance(t, dict):
            raise SerenityError(f"{where}: must be a table")
        frame = t.get("frame")
        if not isinstance(frame, int) or isinstance(frame, bool) or frame < 0:
            raise SerenityError(f"{where}: needs frame = <int >= 0>, got {frame!r}")
        acts = [a for a in ACTIONS if a in t]
        extra = sorted(set(t) - set(ACTIONS) - {"frame", "hold"})
        if extra:
            raise SerenityError(f"{where}: unknown key(s) {', '.join(extra)} "
                                f"(allowed: frame, hold, {', '.join(ACTIONS)})")
        if len(acts) != 1:
            raise SerenityError(f"{where}: needs exactly one of {', '.join(ACTIONS)}, got {acts or 'none'}")
        act, value = acts[0], t[acts[0]]
        hold = t.get("hold", 1)
        if "hold" in t and act != "key":
            raise SerenityError(f"{where}: hold only goes with key")
        if not isinstance(hold, int) or hold < 1:
            raise SerenityError(f"{where}: hold must be an int >= 1, got {hold!r}")
        if act in ("key", "press"):
            if not isinstance(value, str) or not value:
                raise SerenityError(f"{where}: {act} must be a key name such as \"W\" or \"F12\", got {value!r}")
            value = value.upper()
        elif act == "mouse":
            if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)):
                raise SerenityError(f"{where}: mouse must be [dx, dy] in pixels, got {value!r}")
        elif act == "set":
            if not isinstance(value, dict) or not value:
                raise SerenityError(f"{where}: set must be a table such as {{ hour = 9.5 }}")
            for k, v in value.items():
                if k not in SETTABLE:
                    raise SerenityError(f"{where}: cannot set {k!r} (settable: {', '.join(SETTABLE)})")
                kind = SETTABLE[k]
                ok = isinstance(v, bool) if kind is bool else (
                    isinstance(v, (int, float)) and not isinstance(v, bool) if kind is float else isinstance(v, str))
                if not ok:
                    raise SerenityError(f"{where}: {k} must be a {kind.__name__}, got {v!r}")
                if k == "quality" and v in PRESET_ALIASES:  # a former preset name: its current one
                    value[k] = preset_name(v, where)
        elif act == "screenshot":
            if not isinstance(value, str) or not value.lower().endswith(".png"):
                raise SerenityError(f"{where}: screenshot must be a .png path, got {value!r}")
        elif act == "wait" and value != "reference":
            raise SerenityError(f"{where}: wait must be \"reference\" (block until the reference started by R is done)")
        elif act == "exit" and value is not True:
            raise SerenityError(f"{where}: exit must be true")
        steps.append(Step(frame, act, value, hold))
    if not steps:
        raise SerenityError(f"{path}: no [[step]] tables")
    return Script(sorted(steps, key=lambda s: s.frame), path)
