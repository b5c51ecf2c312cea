"""The ``serenity`` subcommands, one module each.

A command module exposes ``register(subparsers)``, which adds its ``argparse`` parser and sets
``func`` to the function that runs it (``run(args) -> int``). ``serenity/cli.py`` imports the
modules and lists them in ``COMMANDS``; adding a command is one module here and its name there.

Import rule (see docs/architecture.md): a command module imports only light modules at its top
(``argparse``, :mod:`.common`, :mod:`serenity.errors`), and its ``run`` imports what it runs
(the renderer, the reference, the scene loaders, which bring Warp, OpenGL and trimesh), so that
``serenity --help`` and a mistyped argument answer at once. Helpers shared by several commands are
in :mod:`.common`.
"""
