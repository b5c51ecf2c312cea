"""Intel Open Image Denoise (OIDN, through ``pyoidn``) for the path tracer we compare against.

    out = denoise(noisy_hdr, albedo, normal)                 # (H, W, 3) float32, same units
    albedo, normal = guides_from_aovs(frame.aovs)            # noise-free guides from our G-buffer

``denoise`` runs OIDN's generic ray-tracing filter ("RT") on the CPU, in HDR mode (linear radiance,
W·m⁻²·sr⁻¹; OIDN picks its own input scale), with optional albedo and normal guides. Guides passed
here are taken as noise-free (``cleanAux``): they come from a rasterised G-buffer, not from the
path tracer's own noisy first hits. ``quality``: "fast" | "balanced" | "high" (OIDN's speed/quality
trade; "balanced" is its recommendation for interactive use, "high" its default).

:func:`guides_from_aovs` turns our renderer's AOVs into OIDN guides the way OIDN's documentation
asks: albedo in [0, 1] of the surface each pixel sees; albedo 1 where we trace rays (mirrors and glass:
OIDN's advice for delta surfaces whose next hit is unknown) and for the sky (no surface); normals
in [-1, 1] (world space; 0 for the sky). Our AOVs have one sample per pixel: an ``(s·H, s·W)``
G-buffer is box-averaged down by ``s`` so that the guides are antialiased like the path-traced
image (OIDN warns that aliased guides leave artefacts along edges).

``pyoidn`` is in the ``eval`` extra; without it :func:`denoise` raises a one-line
:class:`SerenityError` naming the extra to install (:func:`available` tells beforehand).
"""

from __future__ import annotations

import numpy as np

from serenity.errors import SerenityError

QUALITIES = ("fast", "balanced", "high")
INSTALL_HINT = "denoising needs Intel Open Image Denoise (pyoidn): pip install 'serenity[eval]'"


def _pyoidn():
    try:
        import pyoidn
    except ImportError:
        raise SerenityError(INSTALL_HINT) from None
    return pyoidn


def available() -> bool:
    """True when ``pyoidn`` can be imported."""
    try:
        _pyoidn()
    except SerenityError:
        return False
    return True


def _image(a, name: str, shape=None) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[2] != 3 or min(a.shape[:2]) == 0:
        raise SerenityError(f"denoise: {name} must be (H, W, 3), got {a.shape}")
    if shape is not None and a.shape != shape:
        raise SerenityError(f"denoise: {name} is {a.shape}, the colour image is {shape} (shape mismatch)")
    a = np.ascontiguousarray(a, np.float32)
    if not np.all(np.isfinite(a)):
        raise SerenityError(f"denoise: {name} contains NaN or infinite values")
    return a


def denoise(color, albedo=None, normal=None, *, quality: str = "high", clean_aux: bool = True) -> np.ndarray:
    """OIDN's "RT" filter on linear HDR ``color`` (H, W, 3) ≥ 0; returns (H, W, 3) float32 in the same units.

    albedo: (H, W, 3) in [0, 1] or None; normal: (H, W, 3) in [-1, 1] or None (needs albedo, as in OIDN).
    clean_aux: the guides are noise-free (ours are); False lets OIDN treat them as noisy."""
    pyoidn = _pyoidn()
    if quality not in QUALITIES:
        raise SerenityError(f"denoise: quality must be one of {', '.join(QUALITIES)}, got {quality!r}")
    c = _image(color, "color")
    if np.any(c < 0):
        raise SerenityError("denoise: color has negative values (OIDN's HDR mode needs radiance >= 0)")
    a = None if albedo is None else np.clip(_image(albedo, "albedo", c.shape), 0.0, 1.0)
    n = None if normal is None else np.clip(_image(normal, "normal", c.shape), -1.0, 1.0)
    if n is not None and a is None:
        raise SerenityError("denoise: a normal guide needs an albedo guide too (OIDN takes normal only with albedo)")
    try:
        out = pyoidn.denoise(c, a, n, hdr=True, clean_aux=bool(clean_aux and a is not None), quality=quality)
    except (RuntimeError, ValueError, TypeError) as exc:
        raise SerenityError(f"denoise: OIDN failed: {exc}") from None
    return np.asarray(out, np.float32)


def _box_down(img: np.ndarray, s: int) -> np.ndarray:
    h, w = img.shape[0] // s, img.shape[1] // s
    return img[: h * s, : w * s].reshape(h, s, w, s, -1).mean(axis=(1, 3)).astype(np.float32)


def guides_from_aovs(aovs: dict, supersample: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(albedo, normal), each (H, W, 3) float32, from a Frame's AOVs (see the module doc).

    ``aovs`` needs "albedo", "normal" and "depth" (inf where no surface); "rt_mask" (1 where rays
    are traced) when present. ``supersample``: the AOVs are ``supersample``× the target size per
    side and are box-averaged down to it."""
    try:
        albedo = np.asarray(aovs["albedo"], np.float32)[..., :3]
        normal = np.asarray(aovs["normal"], np.float32)[..., :3]
        depth = np.asarray(aovs["depth"], np.float32)[..., 0]
    except KeyError as exc:
        raise SerenityError(f"guides_from_aovs: the frame has no {exc.args[0]!r} AOV") from None
    s = int(supersample)
    if s < 1 or albedo.shape[0] % s or albedo.shape[1] % s:
        raise SerenityError(f"guides_from_aovs: supersample {supersample} must be >= 1 and divide the AOV size "
                            f"{albedo.shape[1]}x{albedo.shape[0]}")
    sky = ~np.isfinite(depth)
    white = sky
    if "rt_mask" in aovs:
        white = white | (np.asarray(aovs["rt_mask"])[..., 0] > 0.5)
    albedo = np.where(white[..., None], np.float32(1.0), np.clip(albedo, 0.0, 1.0))
    normal = np.where(sky[..., None], np.float32(0.0), np.clip(normal, -1.0, 1.0))
    if s > 1:
        albedo, normal = _box_down(albedo, s), _box_down(normal, s)
    return np.ascontiguousarray(albedo, np.float32), np.ascontiguousarray(normal, np.float32)
