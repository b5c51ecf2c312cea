"""Sun shadows: cascaded shadow maps (paper §6, Dimitrov's CSM) in one depth atlas.

Cascades. The view range [near, min(far, max_distance, scene extent)] is split by the
"practical" scheme (Zhang et al. 2006): d_i = λ·n·(f/n)^(i/N) + (1-λ)·(n + (f-n)·i/N), λ =
``split_lambda`` (0 = uniform, 1 = logarithmic). Each cascade is the bounding sphere of its frustum
slice; the sphere of a slice depends only on the slice distances, fov and aspect, so its size does
not change when the camera turns (the far end is the farthest scene corner's *distance*, in 5 %
steps), and its centre is snapped to whole shadow-map texels in light
space, so shadows do not shimmer as the camera moves (a one-texel camera move changes no texel of
the map's content, only which texels are used). The light-space depth range is extended to the
whole scene's bounds so casters outside the slice still cast.

Atlas. Cascade i occupies slot i, tile (i % 2, i // 2), of a (2S × 2S) depth texture (S = ``size``).
With ``ShadowPass.render``'s stagger (3 or 4 cascades) the atlas is 3S × 3S (slot s at tile (s % 3,
s // 3)): each cascade after the first has a second slot, and a redrawn tile goes to the slot its
cascade is not in, so that the version before stays for the lookups to fade from.

Depth comparison (``glsl/shadow_sampling.glsl``): each tap compares the map's depth with the
receiver's tangent plane at the centre of the texel it reads (receiver-plane depth bias; the plane's
gradient in map coordinates from the G-buffer normal through the inverse transpose of the cascade's
linear part), so a sloped receiver and a wide filter need no bias that grows with them; what remains
is a constant depth bias (``ShadowConfig.bias``, in texels of the cascade used) for the depth
buffer's quantisation. ``ShadowConfig.normal_offset`` (off by default) still moves the lookup point
along the normal by that many texels times the slope tan θ (clamped to [1, 4]), the mitigation used
before the receiver plane: under a grazing sun it shortened the shadows that eaves cast on walls.

Filtering (``ShadowConfig.filter``): "hard" (one tap), "pcf" (fixed-radius Vogel-disc PCF), "pcss"
(Fernando 2005: blocker search → penumbra from the sun's angular diameter → variable PCF).

Contact shadows (beyond the paper; ``ShadowConfig.contact_steps``, ``glsl/deferred.glsl``): where the
map says lit, a short screen-space march towards the sun (``contact_pixels`` pixel footprints) tests
each step against the plane of the surface the G-buffer shows there. A filter footprint at the foot
of a wall the sun grazes reaches the map's texels past the wall's edge; the Cornell box's floor
pixel 0.08 mm inside its red wall came out fully lit (94.8 against the reference's 0.86, 89 % of
the frame's relMSE), and the bias detaches the courtyard's eave shadows from the walls.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import moderngl
import numpy as np

from serenity.raster.context import clear_depth_rect, load_program
from serenity.raster.scene_gl import LOD_PIXEL_ERROR

MAX_CASCADES = 4
#: how much larger than its sphere a tile is fitted when tiles are staggered (fraction of the radius)
STAGGER_PAD = 0.1


def vogel_disc(n: int) -> np.ndarray:
    """(n, 2) float64: the Vogel (golden-angle) points in the unit disc, i-th at radius
    sqrt((i + 0.5) / n), angle i · 2.39996323 rad (the shadow filter's taps before each pixel's
    rotation)."""
    i = np.arange(n, dtype=np.float64)
    r, a = np.sqrt((i + 0.5) / n), i * 2.39996323
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def disc_defines(blocker_samples: int, filter_samples: int) -> dict[str, str | int]:
    """The ``#define``s that ``glsl/shadow_sampling.glsl`` compiles its taps from: the two tap counts
    and their Vogel discs as GLSL ``vec2`` lists (``BLOCKER_DISC``, ``FILTER_DISC``). The points are
    constants of the program and each pixel rotates them by its own angle: one cos/sin pair a pixel
    instead of one per tap, which llvmpipe evaluates in software (~60 % of the ALU of a 32-tap filter
    loop; the loops are too long to unroll into constants)."""
    def glsl(n: int) -> str:
        return ", ".join(f"vec2({x:.9g}, {y:.9g})" for x, y in vogel_disc(n))
    return {"BLOCKER_SAMPLES": int(blocker_samples), "FILTER_SAMPLES": int(filter_samples),
            "BLOCKER_DISC": glsl(blocker_samples), "FILTER_DISC": glsl(filter_samples)}


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    f = np.asarray(target, np.float64) - eye
    f = f / np.linalg.norm(f)
    if abs(float(np.dot(f, up))) > 0.999:
        up = np.array([1.0, 0.0, 0.0]) if abs(f[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def ortho(left, right, bottom, top, near, far) -> np.ndarray:
    m = np.eye(4)
    m[0, 0] = 2 / (right - left)
    m[1, 1] = 2 / (top - bottom)
    m[2, 2] = -2 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


def split_distances(near: float, far: float, count: int, lam: float) -> np.ndarray:
    """count+1 view depths from near to far (practical split scheme)."""
    i = np.arange(count + 1) / count
    log = near * (far / near) ** i
    uni = near + (far - near) * i
    return lam * log + (1 - lam) * uni


@dataclass
class Cascade:
    view_proj: np.ndarray  # world → light clip (4,4)
    far: float             # view depth (m) where this cascade ends
    texel_world: float     # one texel, metres
    depth_range: float     # light-space depth extent (m) of the [0,1] depth
    #: what the tile must cover: (centre (3,) m, radius m) of the region it is fitted to (the
    #: slice's bounding sphere; for overlapped maps the sphere around the camera)
    sphere: tuple[np.ndarray, float] | None = None
    #: the tile as drawn: (light rotation (3,3), light-space centre (2,), half width m)
    tile: tuple[np.ndarray, np.ndarray, float] | None = None
    #: where the tile lies in the atlas: slot s is tile (s mod T, s div T) of a T × T atlas
    slot: int = 0
    #: with ``ShadowPass.render``'s stagger: the tile as drawn before its last redraw, which lookups
    #: still take ``previous_weight`` of (cross-faded into the new one over the stagger's cycle)
    previous: Cascade | None = None
    previous_weight: float = 0.0

    def covers(self, other: Cascade) -> bool:
        """Whether this tile, as drawn, still holds every texel ``other`` needs: ``other``'s sphere,
        seen from this tile's light direction, lies inside the tile (the depth range spans the whole
        scene either way). Used to keep a tile a few frames while the camera and the sun move."""
        if self.tile is None or other.sphere is None:
            return False
        rot, centre, half = self.tile
        p = (rot @ np.asarray(other.sphere[0], np.float64))[:2]
        return bool(np.all(np.abs(p - centre) + other.sphere[1] <= half))


@dataclass
class ShadowMaps:
    depth: object               # the atlas depth texture
    cascades: list[Cascade]
    tile_size: int

    def tile_uniforms(self) -> dict[str, bytes]:
        """``glsl/shadow_sampling.glsl``'s uniforms for the tiles, as float32 bytes: per cascade i, its
        tile at index i and what it cross-fades from at index i + 4 (``Cascade.previous``, with
        ``u_cascade_prev_weight``; zeros where nothing does): the light matrix, the plane transform
        (the inverse transpose of the matrix's linear part, as GL reads a mat3 column by column) and
        (atlas slot, texel, depth extent, 0)."""
        vp, plane = np.zeros((8, 4, 4), np.float32), np.zeros((8, 3, 3), np.float32)
        info, weight = np.zeros((8, 4), np.float32), np.zeros(4, np.float32)
        for i, c in enumerate(self.cascades):
            tiles = [(i, c)]
            if c.previous is not None and c.previous_weight > 0.0:
                tiles.append((i + 4, c.previous))
                weight[i] = c.previous_weight
            for k, t in tiles:
                vp[k] = t.view_proj.T
                # a normal's image under the linear part L is L^-T n: (L^-T)^T row-major = L^-T column-major
                plane[k] = np.linalg.inv(t.view_proj[:3, :3])
                info[k] = (t.slot, t.texel_world, t.depth_range, 0.0)
        return {"u_tile_vp": vp.tobytes(), "u_tile_plane": plane.tobytes(), "u_tile_info": info.tobytes(),
                "u_cascade_prev_weight": weight.tobytes()}


def fit_shadow_cascades(camera, aspect: float, sun_direction: np.ndarray, bounds: np.ndarray, count: int,
                 size: int, lam: float, max_distance: float, pad: float = 0.0) -> list[Cascade]:
    """The cascades of the camera's view (module doc). ``pad``: each tile covers its slice's sphere
    enlarged by this fraction of its radius, so that the tile stays usable while the camera moves
    that far (``ShadowPass.render``'s ``stagger``); 0 = tight."""
    sun = np.asarray(sun_direction, np.float64)
    center_scene = bounds.mean(axis=0)
    scene_radius = max(float(np.linalg.norm(bounds[1] - bounds[0])) / 2, 1e-3)
    light_view = look_at(np.zeros(3), -sun, np.array([0.0, 1.0, 0.0]))  # rotation only
    # how far from the camera anything in the scene can be: a distance, not a depth, so that it does
    # not change as the camera turns; quantised to 5 % steps so that it changes rarely as it moves
    corners = np.array([[bounds[i][0], bounds[j][1], bounds[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    reach = float(np.max(np.linalg.norm(corners - camera.position, axis=1)))
    far = max(min(camera.far, max_distance, reach), camera.near * 2)
    far = camera.near * 1.05 ** math.ceil(math.log(far / camera.near) / math.log(1.05))
    splits = split_distances(camera.near, far, count, lam)
    t = math.tan(math.radians(camera.fov_y_deg) / 2)
    # scene depth range along the sun direction (light view looks down -sun, so z_light = -dot)
    zc = -(corners @ (light_view[:3, :3].T))[:, 2]
    z_min, z_max = float(zc.min()), float(zc.max())
    out = []
    for i in range(count):
        n, f = splits[i], splits[i + 1]
        # bounding sphere of the slice: centre on the axis at distance c minimising the radius
        k2 = t * t * (1 + aspect * aspect)  # squared tan of the half-diagonal
        c = min(f, 0.5 * (n + f) * (1 + k2))
        radius = math.sqrt((f - c) ** 2 + (f * f) * k2)
        radius = math.sqrt(max(radius * radius, (c - n) ** 2 + n * n * k2))
        radius = min(radius, scene_radius * 1.01 + 1e-3)
        centre = camera.position + camera.forward * c
        if radius >= scene_radius:  # the scene fits: centre on it (still texel-snapped)
            centre = center_scene
        half = radius * (1.0 + pad)
        texel = 2 * half / size
        lc = light_view[:3, :3] @ centre
        lc[:2] = np.floor(lc[:2] / texel) * texel  # snap to whole texels
        depth_lo, depth_hi = z_min - 1e-3 - 0.01 * scene_radius, z_max + 1e-3 + 0.01 * scene_radius
        proj = ortho(lc[0] - half, lc[0] + half, lc[1] - half, lc[1] + half, depth_lo, depth_hi)
        # the light view looks down -z: a point at distance d along -sun from the origin has z = -d
        out.append(Cascade(proj @ light_view, float(f), texel, depth_hi - depth_lo, sphere=(centre, radius),
                           tile=(light_view[:3, :3], lc[:2].copy(), half)))
    return out


def fit_overlapped(camera_position, sun_direction: np.ndarray, bounds: np.ndarray, count: int = 3,
                   size: int = 512, ratio: float = 4.0, pad: float = 0.0) -> list[Cascade]:
    """Overlapped shadow maps (paper §9, Fig. 17): ``count`` concentric spheres around the camera,
    each ``ratio`` times the radius of the previous, the largest reaching the farthest scene corner.

    Unlike view-fitted cascades they cover every direction, so surfaces seen only in a reflection
    or refraction (behind the camera, off screen) still get sun shadows; the price is the overlap
    (each map re-covers the smaller ones). ``Cascade.far`` is here a *distance* from the camera:
    the shader picks the first map whose sphere contains the point. ``pad`` as in
    :func:`fit_shadow_cascades` (the map covers its sphere enlarged by that fraction).
    """
    sun = np.asarray(sun_direction, np.float64)
    cam = np.asarray(camera_position, np.float64)
    light_view = look_at(np.zeros(3), -sun, np.array([0.0, 1.0, 0.0]))
    corners = np.array([[bounds[i][0], bounds[j][1], bounds[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    reach = max(float(np.max(np.linalg.norm(corners - cam, axis=1))), 1e-2)
    reach = 1.05 ** math.ceil(math.log(reach) / math.log(1.05))  # changes rarely as the camera moves
    zc = -(corners @ (light_view[:3, :3].T))[:, 2]
    scene_radius = max(float(np.linalg.norm(bounds[1] - bounds[0])) / 2, 1e-3)
    depth_lo, depth_hi = float(zc.min()) - 0.01 * scene_radius, float(zc.max()) + 0.01 * scene_radius
    out = []
    for i in range(count):
        radius = reach / ratio ** (count - 1 - i)
        half = radius * (1.0 + pad)
        texel = 2 * half / size
        lc = light_view[:3, :3] @ cam
        lc[:2] = np.floor(lc[:2] / texel) * texel
        proj = ortho(lc[0] - half, lc[0] + half, lc[1] - half, lc[1] + half, depth_lo, depth_hi)
        out.append(Cascade(proj @ light_view, float(radius), texel, depth_hi - depth_lo, sphere=(cam, radius),
                           tile=(light_view[:3, :3], lc[:2].copy(), half)))
    return out


class ShadowPass:
    """Renders the cascades of the sun into one depth atlas."""

    def __init__(self, ctx, scene_gl, size: int = 2048, cascades: int = 4):
        if not 1 <= cascades <= MAX_CASCADES:
            raise ValueError(f"1..{MAX_CASCADES} cascades")
        self.ctx = ctx
        self.size = size
        self.count = cascades
        self.program = load_program(ctx, "shadow_depth.glsl")
        self.vao = scene_gl.vao(self.program, with_attributes=("in_position",))
        self.caster_index_count = scene_gl.caster_index_count
        self.scene_gl = scene_gl
        self.program_masked = self.vao_masked = None  # cut-outs' casters: the alpha test (ALPHA_MASK)
        if scene_gl.masked_caster_ranges:
            self.program_masked = load_program(ctx, "shadow_depth.glsl", defines={"ALPHA_MASK": 1})
            self.vao_masked = scene_gl.vao(self.program_masked, with_attributes=("in_position", "in_uv"))
        self._atlas(2 if cascades > 1 else 1)
        self._kept: list[Cascade | None] = [None] * cascades   # the cascade each tile was drawn for
        self._age = [0] * cascades                               # frames since each tile was drawn
        self._slot = list(range(cascades))                       # the atlas slot each tile is in
        self._previous: list[Cascade | None] = [None] * cascades  # each tile before its last redraw
        #: tiles drawn by the last ``render`` (the others were still valid)
        self.redrawn = 0
        self.opaque_ranges = scene_gl.culled(scene_gl.opaque_caster_ranges + scene_gl.lod_ranges)
        self.masked_ranges = scene_gl.culled(scene_gl.masked_caster_ranges)
        #: skip the casters' draw ranges outside each tile's light box (``culling.py``; the maps are the same)
        self.cull = True
        #: ``RenderConfig.lod_pixel_error``: each dense caster is drawn at the coarsest level of detail
        #: within half this many texels of its surface (``SceneGL.levels``; 0 = the full meshes), half
        #: so that a level never moves a caster's depth past the bias that keeps a surface from
        #: shadowing itself (one texel)
        self.lod_pixel_error = LOD_PIXEL_ERROR
        #: (caster draw ranges drawn, caster draw ranges × tiles drawn) of the last ``render``
        self.last_draws = (0, 0)

    def _atlas(self, tiles: int) -> None:
        """A depth atlas of ``tiles`` × ``tiles`` slots of ``size``² texels (nothing drawn)."""
        ctx, size = self.ctx, self.size
        self.tiles = tiles
        self.depth = ctx.depth_texture((size * tiles, size * tiles))
        self.depth.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth.repeat_x = self.depth.repeat_y = False
        self.depth.compare_func = ""  # sampled as plain depth; the shader compares (PCF/PCSS)
        self.fbo = ctx.framebuffer(depth_attachment=self.depth)

    def invalidate(self) -> None:
        """Redraw every tile next time (after the scene's geometry changed in place)."""
        self._kept = [None] * self.count
        self._previous = [None] * self.count

    def render(self, cascades: list[Cascade], stagger: bool = False) -> ShadowMaps:
        """Draw the scene's depth into one atlas tile per cascade (from ``fit_shadow_cascades`` or
        ``fit_overlapped``). A tile whose cascade is the same as when it was last drawn (same light
        matrix: the cascades are texel-snapped bounding spheres, so they stay put while the sun
        does and the camera moves within them) is kept, not redrawn.

        ``stagger``: tiles after the first are also kept while they still cover their cascade's
        sphere (``Cascade.covers``; fit with ``pad`` > 0 to leave room), and at most one of those
        is redrawn per frame, the one kept longest: with the sun moving every frame, the first
        tile follows it each frame and the others within ``count − 1`` frames (their shadows lag
        the sun by as many frames), so 2 tiles are drawn per frame instead of ``count``. A tile
        after the first is then redrawn into a second slot of the atlas (3 × 3 slots) and keeps its
        version before, which lookups cross-fade from over ``count − 1`` frames (the weight of the
        old version (count − 1 − k)/(count − 1) in the k-th frame after the redraw,
        ``Cascade.previous``): a redraw changes the shadow maps' aliasing wherever a shadow's
        detail is near a texel (under a grazing sun, an eave's shadow on a wall), and switched at
        once it popped (``docs/stability.md``). The returned cascades are the tiles as drawn, with
        this frame's split depths."""
        ctx = self.ctx
        self.redrawn = 0
        self.last_draws = (0, 0)
        blend = stagger and self.count > 2
        if blend and self.tiles < 3:  # a second slot per cascade after the first
            self._atlas(3)
            self.invalidate()
        cascades = list(cascades[: self.count])
        draw = []
        stale = []
        for i, c in enumerate(cascades):
            kept = self._kept[i]
            if kept is not None and np.array_equal(np.float32(kept.view_proj), np.float32(c.view_proj)):
                continue
            if stagger and i > 0 and kept is not None and kept.covers(c):
                stale.append(i)
            else:
                draw.append(i)
        if stale:  # the tile kept longest (ties: the nearest cascade)
            draw.append(max(stale, key=lambda i: (self._age[i], -i)))
        with ctx.debug_scope("shadow"):
            self.fbo.use()
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)
            for i in sorted(draw):
                c = cascades[i]
                if blend and i > 0 and self._kept[i] is not None:  # the version before stays for the fade
                    self._previous[i] = dataclasses.replace(self._kept[i], slot=self._slot[i], previous=None)
                    self._slot[i] = self.count + i - 1 if self._slot[i] == i else i
                else:
                    self._previous[i] = None
                slot = self._slot[i]
                tile = ((slot % self.tiles) * self.size, (slot // self.tiles) * self.size, self.size, self.size)
                clear_depth_rect(ctx, self.fbo, self.depth, tile)
                self.fbo.viewport = tile
                self.program["u_light_view_proj"].write(c.view_proj.T.astype(np.float32).tobytes())
                cull = c.view_proj if self.cull else None
                # the casters (the bottom plane shadows nothing): runs of adjacent ranges, one call each
                levels = self.scene_gl.levels(c.view_proj, self.size, self.size, 0.5 * self.lod_pixel_error)
                for r in self.opaque_ranges.visible(cull, merge_materials=True, levels=levels):
                    self.vao.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
                if self.program_masked is not None:
                    self.program_masked["u_light_view_proj"].write(c.view_proj.T.astype(np.float32).tobytes())
                    for r in self.masked_ranges.visible(cull):
                        self.scene_gl.bind_alpha_test(self.program_masked, r.material)
                        self.vao_masked.render(moderngl.TRIANGLES, vertices=r.count, first=r.first)
                self._kept[i] = c
                self.redrawn += 1
                self.last_draws = (self.last_draws[0] + self.opaque_ranges.drawn + self.masked_ranges.drawn,
                                   self.last_draws[1] + self.opaque_ranges.candidates + self.masked_ranges.candidates)
            self.fbo.viewport = (0, 0, self.depth.width, self.depth.height)
            ctx.disable(moderngl.DEPTH_TEST)
        used = []
        for i, c in enumerate(cascades):
            self._age[i] = 0 if i in draw else self._age[i] + 1
            k = self._kept[i]
            if k is not c:  # a kept tile: as drawn, with this frame's split depth
                k = Cascade(k.view_proj, c.far, k.texel_world, k.depth_range, sphere=c.sphere, tile=k.tile)
            k = dataclasses.replace(k, slot=self._slot[i])
            prev = self._previous[i]
            if prev is not None:
                w = 1.0 - (self._age[i] + 1) / (self.count - 1)
                if w > 0.0:
                    k = dataclasses.replace(k, previous=prev, previous_weight=w)
                else:
                    self._previous[i] = None
            used.append(k)
        return ShadowMaps(self.depth, used, self.size)
