"""Write every built-in scene as GLB + TOML (a scene file referencing the GLB) and check that each
loads back identically: same geometry, materials, textures, camera, sun, sky and occlusion quads.

    python examples/export_scenes.py [OUT_DIR]      (default: ./serenity_out/scenes)

Use the files as a starting point for your own scenes: edit the TOML (camera, sun time and place,
material overrides) or replace the GLB with your own model.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from serenity.scene import build_scene, export_glb, load, save_toml, scene_names


def scenes_equal(a, b) -> list[str]:
    """Names of what differs between two scenes (empty when they are identical)."""
    diffs = []
    va, na, ua, fa, ma = a.merged()
    vb, nb, ub, fb, mb = b.merged()
    for what, x, y, tol in (("positions", va, vb, 1e-6), ("faces", fa, fb, 0), ("normals", na, nb, 1e-6),
                            ("uvs", ua, ub, 1e-6), ("face materials", ma, mb, 0)):
        if x.shape != y.shape or not np.allclose(x, y, atol=tol, rtol=0):
            diffs.append(what)
    if [m.name for m in a.materials] != [m.name for m in b.materials]:
        diffs.append("material names")
    for m, n in zip(a.materials, b.materials, strict=False):
        for k in ("albedo", "specular", "shininess", "reflectivity", "transparency", "ior"):
            if not np.allclose(getattr(m, k), getattr(n, k), rtol=0, atol=1e-9):
                diffs.append(f"material {m.name}.{k}")
        if (m.albedo_texture is None) != (n.albedo_texture is None):
            diffs.append(f"material {m.name} texture presence")
        elif m.albedo_texture is not None and not np.allclose(m.albedo_texture.mips[0], n.albedo_texture.mips[0],
                                                              atol=1e-6):
            diffs.append(f"material {m.name} texture")
    for k in ("position", "target", "up", "fov_y_deg", "near", "far"):
        if not np.allclose(getattr(a.camera, k), getattr(b.camera, k), rtol=0, atol=1e-9):
            diffs.append(f"camera.{k}")
    for k in ("direction", "irradiance", "angular_diameter_deg"):
        if not np.allclose(getattr(a.sun, k), getattr(b.sun, k), rtol=0, atol=1e-9):
            diffs.append(f"sun.{k}")
    if a.sky.model != b.sky.model or not np.allclose(a.sky.radiance, b.sky.radiance):
        diffs.append("sky")
    if len(a.occlusion_quads) != len(b.occlusion_quads):
        diffs.append("occlusion quad count")
    ta = {t.mesh: t for t in (a.animation.tracks if a.animation else [])}
    tb = {t.mesh: t for t in (b.animation.tracks if b.animation else [])}
    if set(ta) != set(tb):
        diffs.append("animated meshes")
    for name in set(ta) & set(tb):
        for t in (0.0, 1.3, 5.7, 13.1):  # the poses agree at a few times
            if not np.allclose(ta[name].matrix(t, np.zeros(3)), tb[name].matrix(t, np.zeros(3)), atol=1e-9):
                diffs.append(f"animation of {name}")
                break
    for qa, qb in zip(a.occlusion_quads, b.occlusion_quads, strict=False):
        if not all(np.allclose(getattr(qa, k), getattr(qb, k)) for k in ("center", "up", "right", "half_up",
                                                                         "half_right")):
            diffs.append("occlusion quads")
            break
    return diffs


def export_scene(name: str, out_dir: str) -> str:
    """Write ``<out_dir>/<name>.glb`` and ``<name>.toml``; return the TOML path."""
    scene = build_scene(name)
    os.makedirs(out_dir, exist_ok=True)
    glb = os.path.join(out_dir, f"{name}.glb")
    toml = os.path.join(out_dir, f"{name}.toml")
    export_glb(scene, glb)
    save_toml(scene, toml, os.path.basename(glb))
    return toml


def main(argv: list[str]) -> int:
    out_dir = argv[1] if len(argv) > 1 else os.path.join("serenity_out", "scenes")
    bad = 0
    for name in scene_names():
        toml = export_scene(name, out_dir)
        diffs = scenes_equal(build_scene(name), load(toml))
        status = "identical" if not diffs else "DIFFERS: " + ", ".join(diffs)
        bad += bool(diffs)
        print(f"{name:<12} -> {toml}  ({status})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
