"""What every stability case shares: the :class:`Case` record (errors without and with a mitigation
against an exact answer, milliseconds, gallery images), the error format of the tables, a timer,
and the brute-force sky irradiance that several exact answers integrate.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from serenity.kernels.atmosphere import sample_sky_map_np
from serenity.kernels.sampling import fibonacci_sphere


def format_error(x) -> str:
    """A stability case's error as its tables print it: "-" for none, 3 significant digits, or
    scientific notation below 1e-3 and from 1e3."""
    if x is None:
        return "-"
    x = float(x)
    if x == 0:
        return "0"
    return f"{x:.2e}" if abs(x) < 1e-3 or abs(x) >= 1e3 else f"{x:.3g}"


UP = np.array([0.0, 1.0, 0.0])


@dataclass
class Case:
    """One failure case: ``error_without`` / ``error_with`` its mitigation, against the exact answer.

    ``metric`` says what the error is; ``exact`` the exact answer's value where it is one number;
    ``ms_without`` / ``ms_with`` the cost of the evaluated technique without / with the mitigation
    (wall clock, one run after a warm-up where stated); ``images`` name → (H, W) or (H, W, 3) float
    arrays for the gallery (``exact``, ``without``, ``with``, ``error``); ``extra`` further numbers."""
    name: str
    technique: str
    metric: str
    mitigation: str
    error_without: float
    error_with: float
    ms_without: float = 0.0
    ms_with: float = 0.0
    exact: float | None = None
    images: dict[str, np.ndarray] = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    def row(self) -> dict:
        """The JSON row (no images)."""
        return {"case": self.name, "technique": self.technique, "metric": self.metric,
                "mitigation": self.mitigation, "exact": self.exact, "error_without": self.error_without,
                "error_with": self.error_with, "ms_without": self.ms_without, "ms_with": self.ms_with,
                **({"extra": self.extra} if self.extra else {})}


def timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, (time.perf_counter() - t0) * 1e3


def brute_sky_irradiance(sky_map, ground_radiance, normals, visible=None, n_dirs: int = 16384):
    """(N, 3) W/m²: ∫ L(ω)·V(ω)·max(0, n·ω) dω over a Fibonacci sphere of ``n_dirs`` directions, L
    the sky map above the horizon and ``ground_radiance`` below (the sky volume's model), V the
    (n_dirs,) bool visibility (None: all visible)."""
    d = fibonacci_sphere(n_dirs)
    rad = np.where((d[:, 1] >= 0)[:, None], sample_sky_map_np(sky_map, d), np.asarray(ground_radiance)[None])
    if visible is not None:
        rad = rad * visible[:, None]
    return np.maximum(np.asarray(normals) @ d.T, 0.0) @ rad * (4 * math.pi / len(d))
