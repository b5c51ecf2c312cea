"""Tiny analytic scenes for raster tests, built straight from the model classes."""

import numpy as np
import trimesh

from serenity.scene.model import Camera, Material, Mesh, Scene, Sky, Sun, direction_from_angles


def quad(name, half, material, y=0.0):
    p = np.array([[-half, y, -half], [half, y, -half], [half, y, half], [-half, y, half]], np.float32)
    n = np.tile([0.0, 1.0, 0.0], (4, 1))
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    return Mesh(name, p, n, uv, np.array([[0, 2, 1], [0, 3, 2]]), np.full(2, material))


def box(name, center, size, material):
    b = trimesh.creation.box(size)
    b.apply_translation(center)
    b = b.subdivide()  # keeps flat faces; split vertices per face below
    v = b.vertices[b.faces].reshape(-1, 3)
    f = np.arange(len(v)).reshape(-1, 3)
    n = np.repeat(b.face_normals, 3, axis=0)
    return Mesh(name, v, n, None, f, np.full(len(f), material))


def plane_scene(albedo=0.5, zenith_deg=30.0, azimuth_deg=180.0, irradiance=1000.0, with_box=False):
    meshes = [quad("plane", 20.0, 0)]
    materials = [Material("plane", albedo=(albedo,) * 3)]
    if with_box:
        meshes.append(box("box", (0.0, 1.0, 0.0), (2.0, 2.0, 2.0), 1))
        materials.append(Material("box", albedo=(0.8, 0.2, 0.2)))
    return Scene(
        "plane", meshes, materials,
        Camera(position=(0.0, 10.0, 12.0), target=(0.0, 0.0, -1.0), fov_y_deg=50.0),
        Sun(direction_from_angles(90.0 - zenith_deg, azimuth_deg), irradiance=(irradiance,) * 3),
        Sky(radiance=(0.0, 0.0, 0.0), model="constant"),
    )


def project(scene, width, height, point):
    """Pixel (row, col) of a world point."""
    cam = scene.camera
    vp = cam.projection_matrix(width / height) @ cam.view_matrix()
    c = vp @ np.array([*point, 1.0])
    ndc = c[:3] / c[3]
    col = int((ndc[0] * 0.5 + 0.5) * width)
    row = int((1 - (ndc[1] * 0.5 + 0.5)) * height)
    return row, col
