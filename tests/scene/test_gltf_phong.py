"""The glTF metallic-roughness → Phong mapping conserves energy (ρ + k_s ≤ 1 per channel) and keeps
what it can of the file's look: a dielectric's base colour, a metal's colour where it is rough."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest

from serenity.scene.mesh_io import gltf_phong_split, load_mesh_file


def test_a_metal_with_base_colour_0_9_reflects_at_most_what_it_receives():
    for rough in (0.0, 0.1, 0.17, 0.5, 1.0):
        rho, ks = gltf_phong_split((0.9, 0.9, 0.9), metallic=1.0, roughness=rough)
        assert np.all(rho + ks <= 1.0 + 1e-12)
        # a grey metal reflects exactly its base: the glossy share plus the share roughness spreads
        np.testing.assert_allclose(rho + ks, 0.9, atol=1e-12)
    rho, ks = gltf_phong_split((0.9, 0.9, 0.9), metallic=1.0, roughness=0.1)
    assert ks == pytest.approx(0.81) and np.allclose(rho, 0.09)


def test_every_combination_conserves_energy():
    rng = np.random.default_rng(3)
    for _ in range(2000):
        base = rng.random(3) * rng.choice([1.0, 0.1])
        base[rng.integers(3)] = rng.choice([base[0], 1.0])
        rho, ks = gltf_phong_split(base, rng.random(), rng.random(), rng.random())
        assert np.all(rho >= 0) and 0.0 <= ks <= 1.0
        assert np.all(rho + ks <= 1.0 + 1e-12), (base, rho, ks)


def test_dielectrics_keep_their_base_and_metals_their_colour_where_rough():
    base = np.array([0.8, 0.3, 0.1])
    rho, ks = gltf_phong_split(base, metallic=0.0, roughness=1.0)
    assert ks == 0.0 and np.array_equal(rho, base)
    rho, ks = gltf_phong_split(base, metallic=0.0, roughness=0.5)
    assert ks == pytest.approx(0.02) and np.allclose(rho, base * 0.98)
    rho, ks = gltf_phong_split(base, metallic=1.0, roughness=1.0)  # a rough metal: its colour, diffusely
    assert ks == 0.0 and np.array_equal(rho, base)
    rho, ks = gltf_phong_split(base, metallic=1.0, roughness=0.5)
    lum = 0.2126 * 0.8 + 0.7152 * 0.3 + 0.0722 * 0.1
    assert ks == pytest.approx(0.5 * lum) and np.allclose(rho, 0.5 * base)


def test_a_gltf_file_of_metals_loads_energy_conserving(tmp_path):
    """Through the loader: the breakfast room's metals (base 0.5 and 0.8, glTF's default metallic 1,
    roughness 0.09 and 0.17) and its un-coloured gloss (base 1, metallic 0.2 and 0.35)."""
    mats = [("Metal", [0.5, 0.5, 0.5, 1], None, 0.0865), ("Chrome", [0.8, 0.8, 0.8, 1], None, 0.1717),
            ("Ceramic3", None, 0.35, 0.2), ("WhiteGloss", None, 0.2, 0.3606),
            ("Gold", [1.0, 0.78, 0.34, 1], 1.0, 0.3)]
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": list(range(len(mats)))}], "scene": 0,
           "nodes": [], "meshes": [], "materials": [], "buffers": [], "bufferViews": [], "accessors": []}
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    blob = pos.tobytes() + np.array([0, 1, 2], np.uint16).tobytes()
    doc["buffers"].append({"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                           + base64.b64encode(blob).decode()})
    doc["bufferViews"] += [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                           {"buffer": 0, "byteOffset": 36, "byteLength": 6}]
    doc["accessors"] += [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [1, 1, 0]},
                         {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]
    for i, (name, base, metal, rough) in enumerate(mats):
        pbr = {"roughnessFactor": rough}
        if base is not None:
            pbr["baseColorFactor"] = base
        if metal is not None:
            pbr["metallicFactor"] = metal
        doc["materials"].append({"name": name, "pbrMetallicRoughness": pbr})
        doc["meshes"].append({"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": i}]})
        doc["nodes"].append({"name": f"n{i}", "mesh": i, "translation": [0, 0, float(i)]})
    path = tmp_path / "metals.gltf"
    path.write_text(json.dumps(doc))
    _, materials = load_mesh_file(path)
    assert {m.name for m in materials} == {name for name, *_ in mats}
    for m in materials:
        assert np.max(m.albedo) + m.specular <= 1.0 + 1e-9, m.name
    chrome = next(m for m in materials if m.name == "Chrome")
    assert chrome.specular > 0.6  # still a shiny metal
    gold = next(m for m in materials if m.name == "Gold")
    assert gold.albedo[0] > gold.albedo[1] > gold.albedo[2]  # its colour, in the share roughness spreads
