"""The breakfast room the repository ships (``scenes/breakfast_room/``, CC BY 3.0): its TOML loads
from there, by an absolute path and by one relative to the working directory, with the glTF's
geometry, materials and textures, the TOML's camera and sun, and its licence beside it."""

from __future__ import annotations

import os

import numpy as np

import serenity

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FOLDER = os.path.join(ROOT, "scenes", "breakfast_room")
TOML = os.path.join(FOLDER, "breakfast_room.toml")

MATERIALS = {"WhiteGloss", "FrostedGlass", "WhitePlastic", "BlackSatin", "GoldPaint", "Ceramic", "Metal",
             "Ceramic3", "BlackRubber", "Chrome", "WhiteMarble", "FloorTiles", "WhiteMatt", "Artwork"}


def test_breakfast_room_loads_from_the_repository(monkeypatch):
    scene = serenity.load(TOML)
    assert scene.name == "breakfast_room"
    # 82,291 unique triangles, 262,687 with the glTF's instances expanded
    assert scene.triangle_count == 262_687
    assert {m.name for m in scene.materials} == MATERIALS
    textured = {m.name for m in scene.materials if m.albedo_texture is not None}
    assert textured == {"WhiteMarble", "FloorTiles", "Artwork"}  # marble.jpg, tiles.png, picture3.jpg
    # a 3.7 x 3.0 x 4.65 m room, y up, its floor at y = 0
    lo, hi = np.asarray(scene.bounds)
    assert np.allclose(hi - lo, (3.719, 2.998, 4.651), atol=0.01)
    assert abs(lo[1]) < 1e-3
    # the TOML's camera (the file's CameraMain) inside the room, and its low morning sun
    assert np.allclose(scene.camera.position, (1.1668, 0.9702, 0.6777))
    assert np.all(scene.camera.position > lo) and np.all(scene.camera.position < hi)
    assert abs(scene.sun.elevation_deg - 25.0) < 1e-6 and abs(scene.sun.azimuth_deg - 100.0) < 1e-6
    assert scene.sky.model == "atmosphere"

    monkeypatch.chdir(ROOT)  # the path a user types from the repository's root
    again = serenity.load("scenes/breakfast_room/breakfast_room.toml")
    assert again.triangle_count == scene.triangle_count


def test_breakfast_room_ships_its_licence_and_credit():
    licence = open(os.path.join(FOLDER, "BreakfastRoomLicense.txt")).read()
    assert "CC BY 3.0" in licence and "Wig42" in licence
    credits = open(os.path.join(ROOT, "CREDITS.md")).read()
    assert "scenes/breakfast_room/" in credits and "CC BY 3.0" in credits
