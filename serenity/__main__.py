"""``python -m serenity`` is the ``serenity`` command."""

import sys

from serenity.cli import main

sys.exit(main())
