"""A small glTF that exercises the materials real scenes use, written with plain JSON (no glTF library).

``write_materials_gltf(folder)`` writes ``materials.gltf`` + ``materials.bin`` + PNG images:

- ``wall``: an opaque grey quad in the plane z = −1 facing +z, x, y ∈ [−2, 2] (single-sided).
- ``fence``: a quad in z = 0, x ∈ [−1, 1], y ∈ [−1, 1], uv = ((x+1)/2, (y+1)/2) in glTF's v-down
  convention flipped (v = 0 at the top, y = 1), material ``cutout``: alphaMode MASK, cutoff 0.5, an
  8×8 RGBA texture whose left half (u < 0.5: x < 0) has alpha 0 and right half alpha 1.
- ``bumpy``: a quad in z = 2, x, y ∈ [−1, 1], material ``bumpy``: a constant normal map tilted by
  30° about the y axis, towards +x (tangent space (sin 30°, 0, cos 30°)), scale 1.
- ``checker``: a quad in z = 3 with a 2×2 checker (white top-left and bottom-right, black elsewhere)
  shifted by KHR_texture_transform offset (0.5, 0): the colours swap.
- ``glossy``: a quad in z = 4 with KHR_materials_specular (specularFactor 0.5) and doubleSided.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from PIL import Image


def _quad(z: float, half: float, x0: float = 0.0):
    pos = np.array([[x0 - half, -half, z], [x0 + half, -half, z], [x0 + half, half, z], [x0 - half, half, z]],
                   np.float32)
    nrm = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (4, 1))
    # glTF uvs (v down): u along +x, v = 0 at the top edge
    uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    return pos, nrm, uv, idx


def write_materials_gltf(folder, *, images: bool = True) -> Path:
    """Write the glTF into ``folder`` (see the module docstring); returns the .gltf path.
    ``images=False`` leaves the PNG files out (a broken file)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    quads = {"wall": _quad(-1.0, 2.0), "fence": _quad(0.0, 1.0), "bumpy": _quad(2.0, 1.0),
             "checker": _quad(3.0, 1.0), "glossy": _quad(4.0, 1.0)}
    mat_of = {"wall": 0, "fence": 1, "bumpy": 2, "checker": 3, "glossy": 4}
    blob = bytearray()
    views, accessors, meshes, nodes = [], [], [], []

    def add(arr: np.ndarray, ctype: int, kind: str, target: int) -> int:
        while len(blob) % 4:
            blob.append(0)
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": arr.nbytes, "target": target})
        blob.extend(arr.tobytes())
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "count": int(len(arr)), "type": kind}
        if kind == "VEC3" and ctype == 5126:
            acc["min"] = arr.min(axis=0).tolist()
            acc["max"] = arr.max(axis=0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    for name, (pos, nrm, uv, idx) in quads.items():
        a = {"POSITION": add(pos, 5126, "VEC3", 34962), "NORMAL": add(nrm, 5126, "VEC3", 34962),
             "TEXCOORD_0": add(uv, 5126, "VEC2", 34962)}
        i = add(idx, 5123, "SCALAR", 34963)
        meshes.append({"name": name, "primitives": [{"attributes": a, "indices": i, "material": mat_of[name]}]})
        nodes.append({"name": name, "mesh": len(meshes) - 1})
    (folder / "materials.bin").write_bytes(bytes(blob))

    if images:
        alpha = np.zeros((8, 8, 4), np.uint8)
        alpha[..., :3] = 200
        alpha[:, 4:, 3] = 255
        Image.fromarray(alpha, "RGBA").save(folder / "cutout.png")
        tilt = math.radians(30.0)
        n = np.array([math.sin(tilt), 0.0, math.cos(tilt)])
        px = np.clip(np.rint((n * 0.5 + 0.5) * 255), 0, 255).astype(np.uint8)
        Image.fromarray(np.tile(px, (4, 4, 1)), "RGB").save(folder / "normal.png")
        checker = np.zeros((2, 2, 3), np.uint8)
        checker[0, 0] = checker[1, 1] = 255
        Image.fromarray(checker, "RGB").save(folder / "checker.png")

    doc = {
        "asset": {"version": "2.0", "generator": "serenity tests"},
        "extensionsUsed": ["KHR_texture_transform", "KHR_materials_specular"],
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "buffers": [{"uri": "materials.bin", "byteLength": len(blob)}],
        "bufferViews": views,
        "accessors": accessors,
        "samplers": [{"magFilter": 9728, "minFilter": 9728, "wrapS": 10497, "wrapT": 10497}],
        "images": [{"uri": "cutout.png"}, {"uri": "normal.png"}, {"uri": "checker.png"}],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1, "sampler": 0}, {"source": 2, "sampler": 0}],
        "materials": [
            {"name": "wall", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "metallicFactor": 0.0,
                                                      "roughnessFactor": 1.0}},
            {"name": "cutout", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
             "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "baseColorTexture": {"index": 0},
                                      "metallicFactor": 0.0, "roughnessFactor": 1.0}},
            {"name": "bumpy", "normalTexture": {"index": 1, "scale": 1.0},
             "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 1.0}},
            {"name": "checker",
             "pbrMetallicRoughness": {"baseColorTexture": {"index": 2, "extensions": {
                 "KHR_texture_transform": {"offset": [0.5, 0.0]}}}, "metallicFactor": 0.0, "roughnessFactor": 1.0}},
            {"name": "glossy", "doubleSided": True,
             "pbrMetallicRoughness": {"baseColorFactor": [0.7, 0.7, 0.7, 1.0], "metallicFactor": 0.0,
                                      "roughnessFactor": 0.5},
             "extensions": {"KHR_materials_specular": {"specularFactor": 0.5}}},
        ],
    }
    path = folder / "materials.gltf"
    path.write_text(json.dumps(doc, indent=1))
    return path



