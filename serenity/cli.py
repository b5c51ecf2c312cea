"""The ``serenity`` command line: one subcommand per module of :mod:`serenity.commands`.

Every user-facing failure is a ``SerenityError``: printed as one line ``serenity: error: ...`` on
stderr with exit status 2, never a traceback. A former quality preset name works and is reported as
one line: ``serenity: warning: quality preset 'low' is now called 'traced-probes'``. Nothing heavy
is imported until a command runs, so ``serenity --help`` answers at once.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from serenity.commands import bench, compare, reference, render, scenes, sweep, view
from serenity.commands.common import report_error
from serenity.config import PresetRenamedWarning
from serenity.errors import SerenityError

COMMANDS = (render, scenes, bench, view, reference, compare, sweep)
"""The subcommands in ``--help`` order. Each is a module of ``serenity/commands/`` whose
``register(subparsers)`` adds its parser; a new command is one more module here."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="serenity", description="Real-time GI by rasterisation + ray tracing")
    sub = p.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    with warnings.catch_warnings():
        show = warnings.showwarning

        def one_line(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, PresetRenamedWarning):
                print(f"serenity: warning: {message}", file=sys.stderr)
            else:
                show(message, category, filename, lineno, file, line)

        warnings.showwarning = one_line
        parser = build_parser()
        args = parser.parse_args(argv)
        try:
            return int(args.func(args) or 0)
        except SerenityError as e:
            return report_error(e)
        except KeyboardInterrupt:
            print("serenity: interrupted", file=sys.stderr)
            return 130


if __name__ == "__main__":
    sys.exit(main())
