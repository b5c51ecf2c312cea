"""Load a :class:`Scene` from a built-in name or a file: the one entry point, ``load``.

``load(name_or_path)`` accepts
- a built-in scene name (:func:`serenity.scene.procedural.scene_names`),
- a ``.toml`` scene file (:mod:`serenity.scene.toml_scene`),
- a mesh file ``.glb`` / ``.gltf`` / ``.obj`` (+ ``.mtl``) / ``.ply``, read through trimesh
  (:mod:`serenity.scene.mesh_io`, which says how files map to the scene model). A bare mesh file
  gets a camera framing its bounds, the default sun, sky and place, and no occlusion quads.
"""

from __future__ import annotations

import os

from serenity.errors import SceneError
from serenity.scene import procedural
from serenity.scene.mesh_io import MESH_EXTENSIONS, load_mesh_file, scene_from_meshes
from serenity.scene.model import Scene
from serenity.scene.toml_scene import load_toml

__all__ = ["SCENE_EXTENSIONS", "load"]

SCENE_EXTENSIONS = (".toml",)


def load(name_or_path) -> Scene:
    """A built-in scene by name, or a scene loaded from a .toml / .glb / .gltf / .obj / .ply file."""
    if isinstance(name_or_path, Scene):
        return name_or_path
    try:
        text = os.fspath(name_or_path)
    except TypeError:
        raise SceneError(f"a scene must be a built-in name or a file path, got {name_or_path!r}") from None
    if text in procedural.scene_names() and not os.path.exists(text):
        return procedural.build_scene(text)
    ext = os.path.splitext(text)[1].lower()
    supported = ", ".join(SCENE_EXTENSIONS + MESH_EXTENSIONS)
    if not os.path.exists(text):
        if not ext:
            raise SceneError(f"unknown scene {text!r}: neither a built-in scene "
                             f"({', '.join(procedural.scene_names())}) nor an existing file")
        raise SceneError(f"{text}: file not found")
    if os.path.isdir(text):
        raise SceneError(f"{text}: is a directory, not a scene file")
    if ext in SCENE_EXTENSIONS:
        return load_toml(text)
    if ext not in MESH_EXTENSIONS:
        raise SceneError(f"{text}: unsupported file type {ext or '(no extension)'!r} (supported: {supported})")
    meshes, materials = load_mesh_file(text)
    return scene_from_meshes(os.path.splitext(os.path.basename(text))[0], meshes, materials, source=text)
