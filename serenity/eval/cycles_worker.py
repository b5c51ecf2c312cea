"""Blender Cycles renders of a scene exported by :mod:`serenity.eval.cycles` (runs under Blender's Python).

    <python with bpy> cycles_worker.py JOB_DIR

This file runs in the interpreter that has ``bpy`` (a virtual environment of its own: ``bpy`` pins a
numpy that the project's environment cannot share), so it imports only ``bpy``, numpy and the
standard library, never ``serenity``. ``JOB_DIR`` holds what the host wrote:

- ``job.json``: image size, the sample counts, the denoiser modes, the seed, the repeat rule, the
  bounce limit, the camera, the sun, the materials and the meshes (all in Blender's z-up world);
- ``arrays.npz``: each mesh's positions (V, 3), normals (V, 3), uv layers (V, 2) and faces (F, 3),
  every texture as (H, W, 4) float32 whose row 0 is v = 0 (Blender's pixel order), and the sky
  ("sky", (H, W, 4), row 0 = nadir, already turned to Blender's longitude origin).

The scene is built once, with persistent data on, so that only the first render of a mode pays
Cycles' scene sync. Per mode (no denoiser, or Cycles' own Open Image Denoise with the FAST or the
ACCURATE prefilter, albedo and normal guides from Cycles' own passes), one warm-up render at
1 spp is timed and reported on its own, then each sample count is a fresh render timed
by the wall clock around ``bpy.ops.render.render`` (the median of 3 when one takes less than the
repeat threshold; the image is the first's). Written back to ``JOB_DIR``: ``result.json`` (times,
versions, threads) and ``images.npz`` (``"<mode>_<spp>"``: (H, W, 3) float32 linear radiance, row
0 = top), read from a float32 OpenEXR of the render result.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import sys
import time
import warnings

# this file's folder holds serenity's own cycles.py, which would shadow Blender's "cycles" add-on
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != HERE]

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Matrix  # noqa: E402

PREFILTERS = {"none": None, "fast": "FAST", "accurate": "ACCURATE"}


def _matrix(rows) -> Matrix:
    return Matrix([list(map(float, r)) for r in rows])


def _image(name: str, pixels: np.ndarray, colorspace: str = "Non-Color"):
    """A float image holding ``pixels`` ((H, W, 4), row 0 = bottom) as they are, no colour conversion."""
    h, w = pixels.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    img.colorspace_settings.name = colorspace
    img.pixels.foreach_set(np.ascontiguousarray(pixels, np.float32).reshape(-1))
    img.update()
    img.pack()
    return img


def _nodes(tree_owner):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        tree_owner.use_nodes = True
    tree = tree_owner.node_tree
    tree.nodes.clear()
    return tree.nodes, tree.links


def _texture(nodes, links, image, uv_layer: str):
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Linear"
    tex.extension = "REPEAT"
    uv = nodes.new("ShaderNodeUVMap")
    uv.uv_map = uv_layer
    links.new(uv.outputs["UV"], tex.inputs["Vector"])
    return tex


def build_material(spec: dict, images: dict):
    """A node material after the Mitsuba export's mapping (see :mod:`serenity.eval.cycles`)."""
    mat = bpy.data.materials.new(spec["name"])
    nodes, links = _nodes(mat)
    out = nodes.new("ShaderNodeOutputMaterial")
    normal = None
    if spec.get("normal_map"):
        nm = nodes.new("ShaderNodeNormalMap")
        nm.space = "TANGENT"
        nm.uv_map = "uv"
        tex = _texture(nodes, links, images[spec["normal_map"]], spec["normal_uv"])
        links.new(tex.outputs["Color"], nm.inputs["Color"])
        normal = nm.outputs["Normal"]

    def bsdf(kind: str, **kw):
        node = nodes.new(kind)
        for k, v in kw.items():
            setattr(node, k, v)
        if normal is not None and "Normal" in node.inputs:
            links.new(normal, node.inputs["Normal"])
        return node

    def mix(fac, a, b):
        m = nodes.new("ShaderNodeMixShader")
        if isinstance(fac, float):
            m.inputs["Fac"].default_value = fac
        else:
            links.new(fac, m.inputs["Fac"])
        links.new(a.outputs[0], m.inputs[1])
        links.new(b.outputs[0], m.inputs[2])
        return m

    def diffuse():
        d = bsdf("ShaderNodeBsdfDiffuse")
        d.inputs["Roughness"].default_value = 0.0
        src = spec["diffuse"]
        if "texture" in src:
            tex = _texture(nodes, links, images[src["texture"]], spec["albedo_uv"])
            links.new(tex.outputs["Color"], d.inputs["Color"])
        else:
            d.inputs["Color"].default_value = (*map(float, src["rgb"]), 1.0)
        return d

    def glossy(roughness: float):
        g = bsdf("ShaderNodeBsdfGlossy", distribution="BECKMANN" if roughness > 0 else "GGX")
        g.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        g.inputs["Roughness"].default_value = float(roughness)
        return g

    ks = float(spec["ks"])
    if ks <= 0.0:
        surface = diffuse()
    elif ks >= 1.0:
        surface = glossy(spec["roughness"])
    else:
        surface = mix(ks, diffuse(), glossy(spec["roughness"]))
    if spec["glass"] > 0.0:
        # the reference's opaque part of glass is one-sided: black seen from behind (from inside a pane)
        black = nodes.new("ShaderNodeBsdfDiffuse")
        black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        surface = mix(nodes.new("ShaderNodeNewGeometry").outputs["Backfacing"], surface, black)
        glass = bsdf("ShaderNodeBsdfGlass", distribution="GGX")
        glass.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        glass.inputs["Roughness"].default_value = 0.0
        glass.inputs["IOR"].default_value = float(spec["ior"])
        surface = mix(float(spec["glass"]), surface, glass)
    elif spec["mirror"] > 0.0:
        surface = mix(float(spec["mirror"]), surface, glossy(0.0))
    opacity = spec.get("opacity")
    if opacity is not None:
        clear = nodes.new("ShaderNodeBsdfTransparent")
        if isinstance(opacity, str):
            tex = _texture(nodes, links, images[opacity], spec["albedo_uv"])
            surface = mix(tex.outputs["Color"], clear, surface)
        else:
            surface = mix(float(opacity), clear, surface)
    links.new(surface.outputs[0], out.inputs["Surface"])
    return mat


def build_mesh(name: str, arrays, prefix: str, uv_layers: list[str], material):
    pos = np.asarray(arrays[f"{prefix}positions"], np.float32)
    nrm = np.asarray(arrays[f"{prefix}normals"], np.float64)
    faces = np.asarray(arrays[f"{prefix}faces"], np.int32)
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(pos))
    me.vertices.foreach_set("co", pos.reshape(-1))
    me.loops.add(faces.size)
    me.loops.foreach_set("vertex_index", faces.reshape(-1))
    me.polygons.add(len(faces))
    me.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.polygons.foreach_set("use_smooth", np.ones(len(faces), bool))
    for layer in uv_layers:  # per corner: the vertex uvs of each face's corners
        uv = np.asarray(arrays[f"{prefix}{layer}"], np.float32)
        me.uv_layers.new(name=layer).data.foreach_set("uv", uv[faces.reshape(-1)].reshape(-1))
    me.uv_layers["uv"].active_render = True
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    me.normals_split_custom_set_from_vertices([tuple(n) for n in nrm])
    me.materials.append(material)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def build_scene(job: dict, arrays) -> bpy.types.Scene:
    for collection in (bpy.data.objects, bpy.data.meshes, bpy.data.materials, bpy.data.lights, bpy.data.cameras,
                       bpy.data.worlds):  # the start-up file's cube, lamp and camera
        for block in list(collection):
            collection.remove(block)
    scene = bpy.context.scene
    r, c = scene.render, scene.cycles
    r.engine = "CYCLES"
    c.device = "CPU"
    r.threads_mode = "AUTO"
    r.resolution_x, r.resolution_y, r.resolution_percentage = int(job["width"]), int(job["height"]), 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.use_persistent_data = True
    r.use_compositing = False
    r.use_sequencer = False
    r.film_transparent = False
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_mode = "RGB"
    r.image_settings.color_depth = "32"
    r.image_settings.exr_codec = "NONE"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    c.film_exposure = 1.0
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.use_adaptive_sampling = False
    c.use_animated_seed = False
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.light_sampling_threshold = 0.0
    c.caustics_reflective = c.caustics_refractive = True
    c.use_guiding = False
    bounces = int(job["max_bounces"])
    for attr in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                 "transparent_max_bounces"):
        setattr(c, attr, bounces)
    c.volume_bounces = 0
    c.denoiser = "OPENIMAGEDENOISE"
    c.denoising_input_passes = "RGB_ALBEDO_NORMAL"
    c.denoising_use_gpu = False

    images = {key: _image(key, np.asarray(arrays[key])) for key in job["images"]}
    materials = [build_material(m, images) for m in job["materials"]]
    for mesh in job["meshes"]:
        build_mesh(mesh["name"], arrays, mesh["prefix"], mesh["uv_layers"], materials[mesh["material"]])

    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.lens_unit = "FOV"
    cam_data.angle_y = math.radians(float(job["camera"]["fov_y_deg"]))
    cam_data.clip_start, cam_data.clip_end = float(job["camera"]["near"]), float(job["camera"]["far"])
    cam = bpy.data.objects.new("camera", cam_data)
    cam.matrix_world = _matrix(job["camera"]["matrix"])
    scene.collection.objects.link(cam)
    scene.camera = cam

    sun = job.get("sun")
    if sun is not None:
        light = bpy.data.lights.new("sun", "SUN")
        light.energy = float(sun["strength"])
        light.color = tuple(map(float, sun["color"]))
        light.angle = math.radians(float(sun["angle_deg"]))
        obj = bpy.data.objects.new("sun", light)
        obj.matrix_world = _matrix(sun["matrix"])
        scene.collection.objects.link(obj)

    world = bpy.data.worlds.new("sky")
    scene.world = world
    nodes, links = _nodes(world)
    bg = nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 1.0
    out = nodes.new("ShaderNodeOutputWorld")
    if job["sky"]:
        env = nodes.new("ShaderNodeTexEnvironment")
        env.image = _image("sky", np.asarray(arrays["sky"]))
        env.interpolation = "Linear"
        env.projection = "EQUIRECTANGULAR"
        links.new(env.outputs["Color"], bg.inputs["Color"])
        world.cycles.sampling_method = "AUTOMATIC"
    else:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        world.cycles.sampling_method = "NONE"
    links.new(bg.outputs["Background"], out.inputs["Surface"])
    return scene


def read_result(scene, path: str) -> np.ndarray:
    """The last render as (H, W, 3) float32, row 0 = top, through a float32 OpenEXR."""
    bpy.data.images["Render Result"].save_render(filepath=path, scene=scene)
    img = bpy.data.images.load(path, check_existing=False)
    try:
        w, h = img.size
        buf = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(buf)
    finally:
        bpy.data.images.remove(img)
    os.remove(path)
    return np.ascontiguousarray(buf.reshape(h, w, 4)[::-1, :, :3])


def render(scene) -> float:
    """Wall seconds of one render. With persistent data, a render whose scene nothing has tagged as
    changed hands back the last result (the sample count and the seed set from Python do not tag
    it), so the scene is tagged first: its settings are synced again, not its objects."""
    t0 = time.perf_counter()
    scene.update_tag()
    bpy.context.view_layer.update()
    bpy.ops.render.render(write_still=False)
    return time.perf_counter() - t0


def main(job_dir: str) -> int:
    with open(os.path.join(job_dir, "job.json")) as f:
        job = json.load(f)
    arrays = np.load(os.path.join(job_dir, "arrays.npz"))
    t0 = time.perf_counter()
    scene = build_scene(job, arrays)
    build_s = time.perf_counter() - t0
    c = scene.cycles
    exr = os.path.join(job_dir, "render.exr")
    repeat_below = float(job["repeat_below_s"])
    seconds, warmup, images = {}, {}, {}
    for mode in job["modes"]:
        prefilter = PREFILTERS[mode]
        c.use_denoising = prefilter is not None
        if prefilter is not None:
            c.denoising_prefilter = prefilter
        c.samples = 1
        c.seed = int(job["seed"]) - 1
        warmup[mode] = render(scene)
        seconds[mode] = []
        for spp in job["spp"]:
            c.samples = int(spp)
            c.seed = int(job["seed"]) + int(spp)
            times = [render(scene)]
            images[f"{mode}_{spp}"] = read_result(scene, exr)
            if times[0] < repeat_below:
                times += [render(scene), render(scene)]
            seconds[mode].append(statistics.median(times))
    np.savez(os.path.join(job_dir, "images.npz"), **images)
    result = {"blender": bpy.app.version_string, "threads": scene.render.threads, "build_seconds": build_s,
              "warmup_seconds": warmup, "seconds": seconds, "denoising_quality": c.denoising_quality}
    with open(os.path.join(job_dir, "result.json"), "w") as f:
        json.dump(result, f)
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print("usage: cycles_worker.py JOB_DIR", file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1]))
