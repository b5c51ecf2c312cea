"""Scenes: the model (:mod:`.model`), loading (:mod:`.loaders`' ``load`` dispatching to
:mod:`.mesh_io` and :mod:`.toml_scene`), textures
(:mod:`.texture`), the sun's position (:mod:`.sun`) and the built-in scenes (:mod:`.procedural`).

``load(name_or_path) -> Scene`` takes a built-in scene name (``scene_names()``) or a
.toml / .glb / .gltf / .obj / .ply file.
"""

from __future__ import annotations

from serenity.scene.loaders import load
from serenity.scene.mesh_io import export_glb
from serenity.scene.model import (
    Camera,
    Material,
    Mesh,
    OcclusionQuad,
    Scene,
    Sky,
    Sun,
    Texture,
    direction_from_angles,
)
from serenity.scene.procedural import build_scene, scene_descriptions, scene_names
from serenity.scene.sun import parse_time, solar_position, sun_from_time
from serenity.scene.texture import build_mips, load_texture, texture_from_array
from serenity.scene.toml_scene import load_toml, save_toml

__all__ = [
    "Camera",
    "Material",
    "Mesh",
    "OcclusionQuad",
    "Scene",
    "Sky",
    "Sun",
    "Texture",
    "build_mips",
    "build_scene",
    "direction_from_angles",
    "export_glb",
    "load",
    "load_texture",
    "load_toml",
    "parse_time",
    "save_toml",
    "scene_descriptions",
    "scene_names",
    "solar_position",
    "sun_from_time",
    "texture_from_array",
]
