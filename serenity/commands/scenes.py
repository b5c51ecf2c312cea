"""``serenity scenes``: the built-in scenes, one line each."""

from __future__ import annotations


def register(subparsers) -> None:
    s = subparsers.add_parser("scenes", help="list the built-in scenes")
    s.set_defaults(func=run)


def run(args) -> int:
    from serenity.scene.procedural import scene_descriptions

    for name, desc in scene_descriptions().items():
        print(f"{name:<12} {desc}")
    return 0
