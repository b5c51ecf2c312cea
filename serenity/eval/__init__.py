"""Accuracy harness: Mitsuba 3 reference renders (:mod:`.reference`), error metrics (:mod:`.metrics`),
speed-vs-accuracy charts (:mod:`.charts`) and the ``serenity reference | compare`` commands
(:mod:`.commands`). Nothing is imported here: Mitsuba, FLIP and matplotlib load only when used."""
