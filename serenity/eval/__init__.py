"""Accuracy harness: Mitsuba 3 reference renders (:mod:`.reference`), error metrics (:mod:`.metrics`),
speed-vs-accuracy charts (:mod:`.charts`) and exact answers for tests and benchmarks (:mod:`.exact`).
The ``serenity reference | compare`` commands are in :mod:`serenity.commands`. Nothing is imported
here; Mitsuba, FLIP and matplotlib load only when used (:mod:`serenity.optional`)."""
