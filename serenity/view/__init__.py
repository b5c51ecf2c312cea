"""``serenity view``: the interactive viewer (window, fly camera, live sun and technique switches,
per-stage timings, AOV views, F12 saves, a background path-traced reference). See ``app.py``.

GL lives in ``present.py`` (the passes that draw the renderer's textures into the window); the
window and its context in ``window.py``; the state a window does not need (camera, time of day,
settings, scripts) in ``controls.py`` and ``script.py``, testable without a display."""

TAA_SAMPLES = 16
"""Jittered frames a still view accumulates before it is converged (``serenity view --taa``)."""
