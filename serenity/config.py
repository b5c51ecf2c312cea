"""Frozen render settings, one typed tree: ``RenderConfig`` holds a ``ShadowConfig``, an
``SSAOConfig``, a ``SkyConfig`` and an ``LPVConfig``. Units are stated on each attribute; defaults
are the paper's where it gives them, and where they differ the attribute says why. Every invalid
value raises a ``ConfigError`` (a ``SerenityError``) whose message starts with ``Class.field``.

Quality presets (``PRESETS``, ``RenderConfig.preset``) name a few tested combinations of these
settings; ``DEFAULT_QUALITY`` ("traced-probes") is what ``Renderer`` renders without a config and
what every ``serenity`` command uses unless ``--quality`` says otherwise. A bare ``RenderConfig()``
holds the "lpv" preset's settings, the base every preset's overrides apply to.

Plain Python only: importing this module imports neither Warp nor moderngl, so the kernels and
the GL passes both read their settings from here.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass, field

from serenity.errors import ConfigError, SerenityError

#: SH windows against ringing (``serenity.kernels.sh.window_weights``)
SH_WINDOWS = ("none", "hanning", "lanczos", "nonneg")
#: per-probe direction sequences of the sky volume
SKY_SEQUENCES = ("hammersley", "sobol-owen")
SKY_METHODS = ("transfer", "layers", "gather")
SKY_FITS = ("scene", "content")
SKY_TRANSFER_MAX_BANDS = 5
"""SH bands the sky transfer can project the sky on (``kernels/skytransfer.eval_sh25``: bands 0–4)."""
#: texels per side of the paraboloid sky map (``serenity.kernels.atmosphere``)
SKY_MAP_SIZE = 256
SKY_VIEW_TABLE_MIN = 32
"""Fewest nodes per side of the sky-view table the sky map is interpolated from; by default the
table has a quarter of the map's rows, at least this many (``atmosphere.sky_view_table_size``)."""
#: cascades the LPV kernels and ``lpv.glsl`` take at most
LPV_MAX_CASCADES = 3

MAX_IMAGE_SIZE = 8192
"""Largest image or shadow-map side, pixels (the texture size every OpenGL 4.3 implementation here supports)."""
DEFAULT_EXPOSURE = 0.02
"""Multiplier applied to radiance (W·m⁻²·sr⁻¹) before Reinhard; 0.02 maps a white wall in noon
sun (≈300) to about 0.86 display luminance. The CLI's and the metrics' default too."""


def check_image_size(width, height, what: str = "image size") -> tuple[int, int]:
    """(width, height) as ints, or a ``SerenityError`` naming ``what`` when a side is outside
    1..``MAX_IMAGE_SIZE``."""
    if not (1 <= int(width) <= MAX_IMAGE_SIZE and 1 <= int(height) <= MAX_IMAGE_SIZE):
        raise SerenityError(f"{what} must be within 1..{MAX_IMAGE_SIZE} pixels per side, got {width}x{height}")
    return int(width), int(height)


@dataclass(frozen=True)
class ShadowConfig:
    """Sun shadows: cascaded shadow maps + PCSS (paper §6). See ``serenity/raster/shadow.py``."""

    size: int = 2048
    """Resolution of one cascade (texels per side); the atlas holds 2×2 tiles. With
    ``texels_per_pixel`` the most it may be."""
    texels_per_pixel: float = 0.0
    """> 0: size each cascade to this many texels per pixel of the image's longer side (multiples of
    64, at least 512, at most ``size``; ``size_for``), so a small image does not draw and clear
    shadow maps far finer than its pixels can show; 0: always ``size``. The paper's 2048² at
    1280×720 is 1.6 texels per pixel."""
    cascades: int = 4
    """Number of cascades, 1–4."""
    split_lambda: float = 0.75
    """Practical split scheme blend: 0 uniform, 1 logarithmic."""
    max_distance: float = 200.0
    """Farthest view depth (m) that receives cascaded shadows (also clamped to the scene)."""
    cascade_blend: float = 0.1
    """Fraction of each cascade's depth range cross-faded into the next (hides the seam)."""
    filter: str = "pcss"
    """"hard" (1 tap), "pcf" (fixed radius), or "pcss" (penumbra from the sun's angular size)."""
    pcf_radius: float = 2.0
    """PCF filter radius in texels ("pcf" mode)."""
    blocker_samples: int = 16
    """PCSS blocker-search taps."""
    filter_samples: int = 32
    """PCF / PCSS filter taps."""
    pcss_max_blocker: float = 20.0
    """Farthest blocker (m above the receiver) the PCSS blocker search is sized for."""
    bias: float = 1.0
    """Constant depth bias, in shadow-map texels (converted to depth units in the shader), below the
    receiver's plane that each tap compares with (``serenity/raster/shadow.py``)."""
    normal_offset: float = 0.0
    """Normal offset of the lookup point, in texels, scaled by the slope tan θ (clamped 1–4). 0: the
    receiver-plane comparison (``bias``) already keeps surfaces from shadowing themselves, and an
    offset of 1 texel cuts the eaves' shadows on walls short under a grazing sun (~0.3 m in the
    courtyard at 320×180)."""
    stagger: bool = False
    """Redraw the cascades after the first in turn, one per frame, while each still covers its slice
    (tiles fitted 10 % larger to leave room), instead of every cascade whose light matrix moved: with
    the sun moving every frame, 2 tiles are drawn per frame instead of 4 and the far cascades' shadows
    lag the sun by up to 3 frames. A redrawn tile is faded in over those frames, pixel by pixel,
    from its version before (a second slot per tile in the atlas), instead of switched at once. The
    same for the overlapped shadow maps. A still frame is unchanged apart from the 10 % coarser
    tiles (``ShadowPass.render``)."""
    contact_steps: int = 6
    """Steps of the screen-space contact-shadow march towards the sun (main view; 0 = off): a
    receiver touching a blocker closer than the map's texels (``glsl/deferred.glsl``). 6: the
    receiver-plane comparison finds the longer contact shadows itself, and 12 steps give the same
    FLIP and relMSE within 0.001 in both test scenes."""
    contact_pixels: float = 12.0
    """Length of the contact-shadow march, in pixel footprints at the receiver ..."""
    contact_texels: float = 32.0
    """... and at most this many shadow-map texels of the receiver's cascade."""
    visibility: str = "pixel"
    """Where the main view's sun visibility (the filter above and the contact march) is computed:
    "pixel" = at every pixel, in the lighting pass; "checkerboard" = at every other pixel of each
    row and column, in a pass of its own, the others from their 4 neighbours; "half" = once per 2×2
    block, upsampled bilaterally (``glsl/visibility_upsample.glsl``)."""

    def __post_init__(self):
        if not 16 <= self.size <= MAX_IMAGE_SIZE:
            raise ConfigError(f"ShadowConfig.size must be in 16..{MAX_IMAGE_SIZE}, got {self.size}")
        if not 1 <= self.cascades <= 4:
            raise ConfigError(f"ShadowConfig.cascades must be 1..4, got {self.cascades}")
        if not (isinstance(self.texels_per_pixel, (int, float)) and math.isfinite(self.texels_per_pixel)
                and 0.0 <= self.texels_per_pixel <= 16.0):
            raise ConfigError(f"ShadowConfig.texels_per_pixel must be in 0..16, got {self.texels_per_pixel!r}")
        if self.filter not in ("hard", "pcf", "pcss"):
            raise ConfigError(f"ShadowConfig.filter must be hard, pcf or pcss, got {self.filter!r}")
        if not 1 <= self.blocker_samples <= 128:
            raise ConfigError(f"ShadowConfig.blocker_samples must be in 1..128, got {self.blocker_samples}")
        if not 1 <= self.filter_samples <= 256:
            raise ConfigError(f"ShadowConfig.filter_samples must be in 1..256, got {self.filter_samples}")
        if not 0 <= self.contact_steps <= 64:
            raise ConfigError(f"ShadowConfig.contact_steps must be in 0..64, got {self.contact_steps}")
        if not self.contact_pixels > 0:
            raise ConfigError(f"ShadowConfig.contact_pixels must be > 0, got {self.contact_pixels}")
        if not self.contact_texels > 0:
            raise ConfigError(f"ShadowConfig.contact_texels must be > 0, got {self.contact_texels}")
        if self.visibility not in ("pixel", "checkerboard", "half"):
            raise ConfigError(f"ShadowConfig.visibility must be pixel, checkerboard or half, got {self.visibility!r}")

    def size_for(self, width: int, height: int) -> int:
        """Texels per side of one cascade for a ``width``×``height`` image (``texels_per_pixel``)."""
        if self.texels_per_pixel <= 0.0:
            return self.size
        want = 64 * math.ceil(self.texels_per_pixel * max(width, height) / 64.0)
        return int(min(self.size, max(512, want)))


@dataclass(frozen=True)
class SSAOConfig:
    """Screen-space ambient occlusion (main view only; multiplies indirect light only)."""

    enabled: bool = True
    radius: float = 0.35
    """Occlusion radius, metres (the ray-traced AO it approximates uses the same). SSAO multiplies the
    volumes' indirect light, which already holds their own, coarser occlusion, so it is kept to the
    contact scale: against 1 m, 0.35 m has the lower FLIP and relMSE for every preset in both test
    scenes at 320×180 and 640×360 but one figure (the Cornell box's FLIP at 320×180 with
    ``lpv-fast``, +0.001)."""
    directions: int = 12
    """Cosine-distributed directions per pixel."""
    steps: int = 4
    """March points per direction."""
    bias: float = 0.03
    """Metres: offset along the normal and depth tolerance (avoids self-occlusion)."""
    thickness: float = 2.0
    """Metres: a march point further behind the depth buffer than this is not blocked."""
    blur_radius: int = 4
    """Bilateral blur half-width in pixels (0 = off)."""

    def __post_init__(self):
        if not self.radius > 0:
            raise ConfigError(f"SSAOConfig.radius must be positive, got {self.radius}")
        if not 1 <= self.directions <= 256:
            raise ConfigError(f"SSAOConfig.directions must be in 1..256, got {self.directions}")
        if not 1 <= self.steps <= 64:
            raise ConfigError(f"SSAOConfig.steps must be in 1..64, got {self.steps}")


@dataclass(frozen=True)
class SkyConfig:
    """Sky lighting irradiance volume (paper §7): probes of L2 SH irradiance on a grid over the
    scene, occluded by quads. See ``serenity/kernels/skyvolume.py``."""

    enabled: bool = True
    """Occluded sky light on every surface; the sky dome and the sun's colour from the atmosphere
    (paper §5, §6) for "atmosphere" skies. False: no sky term (and no sky-light VPLs)."""
    rays_per_probe: int = 256
    """QMC directions per probe over the whole sphere."""
    cell_size: float | None = None
    """Probe spacing in metres; None: from the scene's bounds and ``target_probes``."""
    resolution: tuple[int, int, int] | None = None
    """(X, Y, Z) probes fitted exactly to the bounds (overrides ``cell_size``), e.g. (32, 16, 23)."""
    target_probes: int = 32 * 16 * 23
    """Probe budget the automatic cell size aims at (the paper's volume)."""
    fit: str = "scene"
    """What the grid covers: "scene", the scene's bounds; "content", what stands on the ground
    (``Scene.content_bounds``: a ground plane reaching far beyond the buildings is left out, so the
    budget's probes go where the geometry is). Beyond the grid's sides and top the lookup fades to the
    open sky (``SkyVolume.open_coefficients``)."""
    normal_offset: float = 0.5
    """Lookup offset along the surface normal, in cells (of the smallest cell edge)."""
    glossy: bool = True
    """Also the glossy reflection of the volume's light (k_s × its radiance around the mirror
    direction, filtered by the Phong lobe, from the same L2 SH coefficients: ``sky.glsl``), beside its
    diffuse irradiance. The reference's Phong materials reflect k_s of their light that way; without
    it a material with k_s > 0 sees only its diffuse part of the sky and of the gathered bounce light."""
    window: str = "none"
    """SH window against ringing: one of ``SH_WINDOWS`` (``sh.window_weights``)."""
    window_size: float = 4.0
    """Window size W of the Hanning/Lanczos window."""
    rebuild_angle_deg: float = 0.1
    """Rebake the sky map (and with it the sky volume's light) when the sun moved more than this
    (degrees). At 0.5° a sunset wall popped by 2.5 % of the image's mean every 10 frames of a sun
    moving 0.05° per frame; at 0.1° under 1 % (``tests/stability/test_frame_to_frame.py``)."""
    sky_map_size: int = SKY_MAP_SIZE
    """Texels per side of the paraboloid sky map."""
    ground_albedo: float = 0.2
    """Albedo of the ground seen below the horizon (lit by the sky only); 0 = black."""
    sequence: str = "hammersley"
    """"hammersley" (Cranley–Patterson rotated per probe) or "sobol-owen" (Owen-scrambled per probe)."""
    seed: int = 0
    """Salt of the per-probe decorrelation."""
    auto_quads: bool = True
    """Fit occlusion quads from the meshes (``quadfit``) when the scene has none."""
    method: str = "transfer"
    """How probes follow the sky: "layers" (the paper) re-integrates ``RenderConfig.sky_layers_per_frame``
    layers per frame by ray casting against the sky map, in a continuous cycle; "transfer" integrates
    each probe's visibility once into a transfer matrix (``skytransfer``) and re-lights every probe
    from a new sky in one cheap pass; "gather" (beyond the paper) traces ``gather_rays`` rays per
    probe through the kd-tree once and lights the probes with the sky *and* the light the scene's
    surfaces bounce (sun and sky, ``gather_bounces`` bounces; ``probegather``) — the indirect light
    the LPV would add, so it wants ``LPVConfig.diffuse`` off."""
    gather_rays: int = 64
    """"gather": rays per probe (traced once per scene)."""
    gather_bounces: int = 64
    """"gather": the most passes over the volume after a change of the sun (each adds one bounce);
    they stop sooner once converged (``gather_tolerance``)."""
    gather_tolerance: float = 0.005
    """"gather": the passes stop when the bounces still missing are estimated under this fraction of
    the volume's light (successive passes' changes shrink by the share of light the scene passes on;
    ``skygather.GatherMethod.converged``); 0 = always ``gather_bounces`` passes. A fixed count fits no scene:
    the open courtyard converges in 5 passes, the breakfast room's white walls (albedo 0.9) pass
    light on for about 20, and 12 left its image 3 % too dark (FLIP 0.127 against 0.100 with 24)."""
    gather_visibility: bool = True
    """"gather": weigh each of the 8 probes around a point by whether it sees the point (DDGI's test,
    Majercik et al. 2019: a smooth back-face weight and a Chebyshev bound from each probe's octahedral
    map of its rays' hit distances), so light does not leak through a wall thinner than a cell;
    False = plain trilinear (the lookup of the other methods)."""
    gather_transmissions: int = 4
    """"gather": transparent interfaces (glass) a probe's ray is bent through before the hit that lights
    it (the tracer's ``transmissions``); 0 = glass stops the rays like an opaque diffuse wall."""
    gather_surfel_size: float | None = None
    """"gather": edge of the cubes the rays' hit points are merged into surfels (m); None = 0.4 cell."""
    transfer_bands: int = 5
    """SH bands of the sky projection the transfer uses (B² functions, 1–5; more: sharper sky —
    the sun's glow needs the most; ``tests/kernels/test_skytransfer.py`` measures each)."""
    transfer_layers: int = 0
    """"transfer": y-layers of probes re-lit per update once the volume exists, in a continuous cycle
    like the paper's sweep (each against the newest sky, so with the sun moving every frame no layer
    is older than ceil(Y / transfer_layers) frames), and only those layers are uploaded; 0 = every
    probe in each update (the whole volume current every frame). "gather": the same, for each of its
    passes (a pass never runs past the volume's last layer)."""
    sky_steps: int = 24
    """View-ray march steps of each sky-map texel's bake (``atmosphere``; error vs steps in bench_sky)."""
    sky_view_table: int | None = None
    """Nodes per side of the sky-view table the sky map is interpolated from (the march runs on the
    table's N² directions instead of every texel; ``atmosphere.bake_sky_map_wp``); None = a quarter
    of ``sky_map_size``, at least ``SKY_VIEW_TABLE_MIN``; 0 = march every texel."""

    def __post_init__(self):
        if self.method not in SKY_METHODS:
            raise ConfigError(f"SkyConfig.method must be one of {SKY_METHODS}, got {self.method!r}")
        if self.fit not in SKY_FITS:
            raise ConfigError(f"SkyConfig.fit must be one of {SKY_FITS}, got {self.fit!r}")
        if not 1 <= self.transfer_bands <= SKY_TRANSFER_MAX_BANDS:
            raise ConfigError(f"SkyConfig.transfer_bands must be in 1..{SKY_TRANSFER_MAX_BANDS}, "
                              f"got {self.transfer_bands}")
        if not 0 <= self.gather_transmissions <= 16:
            raise ConfigError(f"SkyConfig.gather_transmissions must be in 0..16, got {self.gather_transmissions}")
        if not self.transfer_layers >= 0:
            raise ConfigError(f"SkyConfig.transfer_layers must be >= 0, got {self.transfer_layers}")
        if not 1 <= self.sky_steps <= 1024:
            raise ConfigError(f"SkyConfig.sky_steps must be in 1..1024, got {self.sky_steps}")
        if not (self.sky_view_table is None or self.sky_view_table == 0 or 2 <= self.sky_view_table <= 1024):
            raise ConfigError(f"SkyConfig.sky_view_table must be 0 or in 2..1024, got {self.sky_view_table}")
        if not (1 <= self.rays_per_probe <= 1 << 20):
            raise ConfigError(f"SkyConfig.rays_per_probe must be in 1..2^20, got {self.rays_per_probe}")
        if self.cell_size is not None and not self.cell_size > 0:
            raise ConfigError(f"SkyConfig.cell_size must be positive, got {self.cell_size}")
        if self.resolution is not None and (len(self.resolution) != 3 or min(self.resolution) < 1):
            raise ConfigError(f"SkyConfig.resolution must be 3 positive ints, got {self.resolution}")
        if self.window not in SH_WINDOWS:
            raise ConfigError(f"SkyConfig.window must be one of {SH_WINDOWS}, got {self.window!r}")
        if self.sequence not in SKY_SEQUENCES:
            raise ConfigError(f"SkyConfig.sequence must be one of {SKY_SEQUENCES}, got {self.sequence!r}")
        if not 0.0 <= self.ground_albedo <= 1.0:
            raise ConfigError(f"SkyConfig.ground_albedo must be in [0, 1], got {self.ground_albedo}")
        if not self.normal_offset >= 0.0:
            raise ConfigError(f"SkyConfig.normal_offset must be >= 0, got {self.normal_offset}")
        if self.target_probes < 8:
            raise ConfigError(f"SkyConfig.target_probes must be >= 8, got {self.target_probes}")
        if not 1 <= self.gather_rays <= 4096:
            raise ConfigError(f"SkyConfig.gather_rays must be in 1..4096, got {self.gather_rays}")
        if not 1 <= self.gather_bounces <= 64:
            raise ConfigError(f"SkyConfig.gather_bounces must be in 1..64, got {self.gather_bounces}")
        if not (isinstance(self.gather_tolerance, (int, float)) and 0.0 <= self.gather_tolerance < 1.0):
            raise ConfigError(f"SkyConfig.gather_tolerance must be in [0, 1), got {self.gather_tolerance!r}")
        if self.gather_surfel_size is not None and not self.gather_surfel_size > 0:
            raise ConfigError(f"SkyConfig.gather_surfel_size must be positive, got {self.gather_surfel_size}")


@dataclass(frozen=True)
class LPVConfig:
    """Light propagation volumes (paper §8): one-bounce diffuse + glossy light from the sun's RSM and
    the sky-lit G-buffer, propagated in nested grids around the camera. Frozen: kernels are
    specialised on it. See ``serenity/kernels/lpv/`` (the package docstring has the maths)."""

    enabled: bool = True
    """Render the LPV's indirect light (False: no RSM, no injection, no LPV lighting pass)."""
    diffuse: bool = True
    """Add the LPV's diffuse light (albedo/π · E). False: the lighting passes skip its lookup (the
    volume is still injected and propagated while ``glossy`` needs it)."""
    glossy: bool = True
    """Add the LPV's glossy light (k_s · L along the reflected direction). False: the lighting passes
    skip the glossy march. With ``diffuse`` also False the LPV lighting passes are not drawn."""
    resolution: int | tuple[int, ...] = 12
    """Cells per axis of each cascade's cubic grid; an int for all cascades or one per cascade.
    12³, not the paper's 32³: at 32³ cells are finer than the propagation can cross in a frame's
    budget; over 7 views of the courtyard and the Cornell box (``benchmarks/experiments/bench_lpv_views.py``)
    12³ has a lower mean FLIP and relMSE than 16³ in both scenes, for about half the update."""
    cascades: int = 3
    """Nested grids around the camera (1..3), finest first."""
    iterations: int | tuple[int, ...] = 8
    """Propagation iterations (light travels one cell per iteration); an int for all cascades or one
    per cascade, finest first."""
    cross_scene: bool = True
    """The coarsest fitted cascade runs at least as many iterations as it has cells across the scene's
    largest side (capped at its resolution), so light can reach from one end of the scene to the other."""
    scene_cells: float = 6.0
    """The cascade that holds the whole scene has cells of at least (largest scene side) / scene_cells
    (0 = off): light crosses a closed room only if it is a few cells across (``fit_cascades``)."""
    handover: bool = True
    """Cascaded reach (``kernels/lpv`` docstring, "Hand-over"): each cascade also accumulates the light
    of its iterations past the reach of the next finer one, and that far light is added into the
    finer cascades, so a fine cascade's lookups see light from beyond its own N cells."""
    early_stop: float = 0.01
    """Stop a cascade when an iteration adds less than this fraction of its accumulated |DC| (0 = never)."""
    geometry_volume: bool = True
    """Fuzzy occlusion from surfels during propagation (compiled in/out)."""
    clamp_faces: bool = True
    """Propagation clamps each face's flux at 0 (Φ_f = Δω_f·max(0, I(ω_f))): the L1 lobes' negative back
    tails no longer carry negative light to the cells behind them (``kernels/lpv`` docstring, "Clamped
    faces"; compiled in/out)."""
    accumulate_injected: bool = True
    """The looked-up grid holds the injected VPL lobes as well as the propagated light (False: only
    the propagated light, so a VPL is first seen one cell away; within its own cell it is near field,
    which an L1 lobe at the cell centre gets badly wrong)."""
    injection_offset: float = 0.5
    """VPLs are moved this many cells along their normal before picking their cell (Kaplanyan)."""
    lookup_offset: float = 0.5
    """Lookup points are moved this many cells along the receiver normal (less self-lighting/leaks)."""
    leak_guard: bool = True
    """Irradiance lookups weight each of the 8 trilinear cells by how far its centre lies in front of
    the receiving surface: stops light behind a wall thinner than a cell leaking onto its dark side
    through the interpolation. Costs 8 unfiltered fetches instead of 1 filtered (compiled in/out)."""
    lookup_occlusion: bool = True
    """With the leak guard and the geometry volume: a lookup also drops the trilinear cells that lie
    across a blocking face of the geometry volume from the cell just in front of the surface (the light
    above a sunlit roof does not reach the top of the wall below its ceiling; compiled in/out)."""
    lookup_planes: bool = True
    """With the lookup occlusion: the geometry volume also records where its blockers lie inside their
    cells (the surfels' mean offset along each axis), and a surface on the far side of a blocker that
    shares its cell takes its home cell across it (a wall row just under a ceiling that lies in a
    cell's lower half no longer reads the light above the roof; compiled in/out)."""
    self_damping: float = 2.5
    """Self-illumination damping (``kernels/lpv`` docstring, "Self-illumination"; 0 = off): an irradiance
    lookup's SH is scaled by (DC self_damping cells further along the normal / DC where it looks up)^
    ``self_damping_power``, clamped to [0, 1] (Kaplanyan & Dachsbacher 2010: light whose intensity falls
    off along the normal flows away from the surface, most of it the surface's own). With it a lit
    plane gets 0.02-0.05 of its exitance back instead of 0.33-0.41, the open ground is within 5 % of
    the reference instead of 12 % too bright, and the Cornell box's indirect light beats no LPV on
    relMSE and FLIP; the courtyard's FLIP rises by ~0.01 (``benchmarks/bench_lpv_room.py``)."""
    self_damping_power: float = 2.0
    """The exponent of ``self_damping``'s ratio."""
    coverage_blocking: bool = False
    """With the geometry volume: propagation through a face is also attenuated by the projected coverage
    of its surfels (Σ A·n²/s² along the axis, either side): a two-sided wall thinner than a cell blocks
    all of the light, not the 2/3 its L1 blocking lobe can (``kernels/lpv``, "Coverage blocking"). Off:
    it takes the thin-wall leak from 0.095 to 0.006 of the lit side, but the Cornell box's ceiling
    gets most of its LPV light through the ceiling from the sunlit roof, and without that leak only
    0.17× the reference's."""
    stagger: bool = False
    """Re-inject and propagate one cascade per update, in turn, instead of all of them (each then
    lags the camera and the light by at most ``cascades`` updates; a cascade that did not change
    is skipped, and a still scene converges to what updating all at once gives). The finer
    cascades' hand-over from a coarser one is rebuilt every update from its last propagation."""
    temporal_blend: float = 0.15
    """Fraction of the way from the light the lookups read in the last frame to the newest propagation
    that each frame moves them (1 = switch at once): a re-injected or staggered cascade is blended in
    over a few frames instead of switched, so that the VPLs' sampling of a moving sun does not pop
    (``LightPropagationVolume.update``'s ``blend``; ``docs/stability.md``)."""
    view_distance: float = 64.0
    """Metres the outermost cascade reaches along the view direction (capped by the scene size)."""
    cascade_scale: float = 2.0
    """Extent ratio between consecutive cascades."""
    forward_shift: float = 0.25
    """Each box is pushed along the view direction by this fraction of its extent."""
    blend_cells: float = 2.0
    """Width of the cascade blend band, in the cascade's cells (0: hard switch)."""
    edge_margin: float = 0.5
    """Cells at a (non-last) cascade's border given zero weight (no light from outside reaches them)."""
    glossy_steps: int = 8
    """Samples along the reflected direction for glossy lookups."""
    glossy_step: float = 1.0
    """Spacing of glossy samples, in cells of the finest active cascade."""

    def __post_init__(self):
        if not (1 <= self.cascades <= LPV_MAX_CASCADES):
            raise ConfigError(f"LPVConfig.cascades must be in 1..{LPV_MAX_CASCADES}, got {self.cascades}")
        res = self.resolutions
        if len(res) != self.cascades or any(r < 2 or r > 256 for r in res):
            raise ConfigError(f"LPVConfig.resolution must be one int in 2..256 or one per cascade, "
                              f"got {self.resolution!r}")
        its = self.iteration_counts
        if len(its) != self.cascades or any(i < 0 for i in its):
            raise ConfigError(f"LPVConfig.iterations must be one int >= 0 or one per cascade, got {self.iterations!r}")
        if not (self.early_stop >= 0):
            raise ConfigError(f"LPVConfig.early_stop must be >= 0, got {self.early_stop}")
        if not self.view_distance > 0:
            raise ConfigError(f"LPVConfig.view_distance must be positive, got {self.view_distance}")
        if not self.cascade_scale >= 1:
            raise ConfigError(f"LPVConfig.cascade_scale must be >= 1, got {self.cascade_scale}")
        if not 0 <= self.forward_shift < 0.5:
            raise ConfigError(f"LPVConfig.forward_shift must be in [0, 0.5), got {self.forward_shift}")
        if not self.blend_cells >= 0:
            raise ConfigError(f"LPVConfig.blend_cells must be >= 0, got {self.blend_cells}")
        if not self.edge_margin >= 0:
            raise ConfigError(f"LPVConfig.edge_margin must be >= 0, got {self.edge_margin}")
        if not self.glossy_steps >= 1:
            raise ConfigError(f"LPVConfig.glossy_steps must be >= 1, got {self.glossy_steps}")
        if not self.glossy_step > 0:
            raise ConfigError(f"LPVConfig.glossy_step must be positive, got {self.glossy_step}")
        if not 0.0 < self.temporal_blend <= 1.0:
            raise ConfigError(f"LPVConfig.temporal_blend must be in (0, 1], got {self.temporal_blend}")

    @property
    def iteration_counts(self) -> tuple[int, ...]:
        if isinstance(self.iterations, int):
            return (int(self.iterations),) * self.cascades
        return tuple(int(i) for i in self.iterations)

    @property
    def resolutions(self) -> tuple[int, ...]:
        if isinstance(self.resolution, int):
            return (int(self.resolution),) * self.cascades
        return tuple(int(r) for r in self.resolution)


@dataclass(frozen=True)
class ScheduleConfig:
    """How a frame's work is scheduled on this machine: which parts run beside which (paper §10),
    at what priority, and when the frame waits for the GL queue. None of it changes the image
    (tests compare the schedules' images); ``benchmarks/bench_tracer_nice.py``,
    ``bench_frame_threads.py`` and ``bench_pass_ab.py`` measure what each costs."""

    overlap: bool = True
    """Run the CPU ray tracing in a worker thread while the GL work proceeds (paper §10); False
    traces inline first (the serial schedule, for comparison)."""
    overlap_volumes: bool = True
    """With ``overlap``, on the CPU: the volumes' kernels (the sky volume's update from the frame's
    start; the LPV's VPLs, injection and propagation once its RSM is read back) run in a worker
    thread while the main thread issues the GL passes that do not need them (G-buffer, ray-casting
    buffer, shadow cascades, SSAO), as on a GPU they would queue beside them. False: on the main
    thread between those passes (the serial schedule always does)."""
    volume_nice: int = 4
    """With the volume worker: the niceness (0..19) its thread adds to this process's, set from the
    thread itself when the worker starts (a thread may lower its own priority without privileges).
    0 = the frame's priority, so that the volumes' kernels take a share of the cores from llvmpipe's
    threads while these render; higher, the GL passes beside them keep more of the cores and the
    volumes run more in what they leave idle, at the risk of the frame waiting for them where it
    joins them ("wait for volumes"). 4: the G-buffer, CSM and SSAO get faster by more than the wait
    grows (frame −1.4 to −3.3 % against 0 at 320×180 and 640×360; 10: about −1 %, the frame waiting
    2.4 ms for the volumes; ``benchmarks/bench_pass_ab.py --a-config schedule.volume_nice=0``)."""
    tracer_nice: int = 19
    """The niceness (-20..19), relative to this process's, of the tracer process that the overlapped
    schedule on the CPU traces in (``kernels/tracer_process``): 19 = the lowest priority, so that it
    takes a core only where the frame's own threads leave one idle; 0 = the frame's; below 0 it
    preempts the frame's threads (allowed only with CAP_SYS_NICE, e.g. as root; elsewhere it runs at
    0). ``benchmarks/bench_tracer_nice.py`` measures the trade: the lower, the shorter the tracer's
    stage and the slower the frame. In a scheduling group of its own (``tracer_session``, where it
    takes effect) the niceness orders nothing; 19 is the default for the machines where it does not."""
    tracer_session: bool | None = None
    """Start the tracer process in a session of its own (``setsid``). Where Linux groups processes by
    session for scheduling (autogroup: ``/proc/sys/kernel/sched_autogroup_enabled`` = 1, and neither
    process in a CPU cgroup of its own), the tracer then shares the cores with the renderer as one
    group against another, instead of as one more thread beside llvmpipe's, the Warp launches' and
    the main thread; ``tracer_nice`` then orders nothing (the tracer is alone in its group).
    Elsewhere nothing changes (``TracerProcess.own_group`` says which). No privilege needed.
    None (default) = a session of its own where the frame has a volume worker (the overlapped CPU
    schedule of the LPV presets), whose wait leaves a core idle: with ``tracer_start = "auto"`` it
    is the one setting that meets both of the overlap's bars (tracer stage ≤ 1.5x the inline trace,
    frame ≤ the serial one) at 320×180 and 640×360 in every sweep of
    ``benchmarks/bench_tracer_nice.py``, and it keeps the frame at or under the serial one beside a
    busy process, where nice 19 alone starves the tracer; its price on an idle machine is a frame
    1-4 % slower than nice 19 in the renderer's group. Without a volume worker ("traced-probes": its
    gathered sky volume keeps every core busy from the main thread) the tracer stays in the
    renderer's session, where a group of its own only takes cores from that work (frame 1.040x
    the serial one against 1.001x at 320×180, 1.019x against 1.009x at 640×360)."""
    tracer_start: str = "auto"
    """With the volume worker on the CPU: where the frame reads the ray-casting buffer back and hands
    its rays to the tracer process (sync 1). "g-buffer": right after the G-buffer, as in the paper;
    "idle": just before the main thread waits for the volume worker, when the worker has work this
    frame (otherwise right after the G-buffer), so that the tracer starts where a core may fall idle;
    "auto" (default): "idle" where the tracer process runs in a scheduling group of its own
    (``tracer_session`` took effect), else "g-buffer" — at nice 19 in the renderer's group a later
    start only delays a tracer that still waits for a core (tracer stage 5.0x the inline trace at
    640×360 against 3.3x from the G-buffer). The same images in every case (tests)."""
    sync_stages: str = "each"
    """When the frame waits for the GL queue (``ctx.finish()``): "each" = after every GL stage, so each
    stage's wall time is its own (the profile ``serenity bench`` reports); "cpu" = only before the
    stages that run on the CPU (the volumes' kernels, the wait for the tracer), so GL work never runs
    beside them but a run of GL passes is not cut into waits (a GL stage's time is then only what
    it took to queue); "none" = never before the read-back. (True / False read as "each" / "none".)
    "each" by default, as every figure of a stage assumes; "cpu" is what an application that reads
    no per-stage times would use (the frontier does): still frames 3-12 % faster in four of five
    interleaved A/Bs (1 % slower in the fifth), the same images."""

    def __post_init__(self):
        if not (isinstance(self.volume_nice, int) and 0 <= self.volume_nice <= 19):
            raise ConfigError(f"ScheduleConfig.volume_nice must be an int in 0..19, got {self.volume_nice!r}")
        if not (isinstance(self.tracer_nice, int) and -20 <= self.tracer_nice <= 19):
            raise ConfigError(f"ScheduleConfig.tracer_nice must be an int in -20..19, got {self.tracer_nice!r}")
        if self.tracer_session not in (None, True, False):
            raise ConfigError(f"ScheduleConfig.tracer_session must be None, True or False, got {self.tracer_session!r}")
        if self.tracer_start not in ("auto", "g-buffer", "idle"):
            raise ConfigError(f"ScheduleConfig.tracer_start must be auto, g-buffer or idle, got {self.tracer_start!r}")
        if isinstance(self.sync_stages, bool):
            object.__setattr__(self, "sync_stages", "each" if self.sync_stages else "none")
        if self.sync_stages not in ("each", "cpu", "none"):
            raise ConfigError(f"ScheduleConfig.sync_stages must be each, cpu or none, got {self.sync_stages!r}")


@dataclass(frozen=True)
class RenderConfig:
    """Everything one ``serenity.frame.Renderer`` renders with: exposure, the ambient baseline, the
    sun's shadows (``shadow``), SSAO (``ssao``), the sky lighting volume (``sky``), the light
    propagation volumes (``lpv``), and the ray-tracing pass (``ray_tracing`` and the fields after
    it). Each GI technique is a sub-config with an ``enabled`` flag, e.g.
    ``RenderConfig(lpv=LPVConfig(enabled=False))`` renders without the LPV.

    A bare ``RenderConfig()`` is the "lpv" preset: the paper's techniques, every one on. It is not
    the default: ``Renderer(scene, w, h)`` without a config renders ``DEFAULT_QUALITY``
    ("traced-probes"), as every command does. Start from a preset with
    ``RenderConfig.preset(name, **overrides)`` (no name: the default preset)."""

    exposure: float = DEFAULT_EXPOSURE
    """Multiplier applied to radiance (W·m⁻²·sr⁻¹) before Reinhard (see ``DEFAULT_EXPOSURE``)."""
    ambient: str = "none"
    """Indirect term while the GI techniques are absent: "none", or "constant" (the classic flat
    ambient hack, irradiance π·L_sky on every surface — the baseline the GI must beat)."""
    shadow: ShadowConfig = field(default_factory=ShadowConfig)
    ssao: SSAOConfig = field(default_factory=SSAOConfig)
    sky: SkyConfig = field(default_factory=SkyConfig)
    """The sky lighting irradiance volume (paper §7); ``enabled=False`` turns the sky term off."""
    lpv: LPVConfig = field(default_factory=LPVConfig)
    """Light propagation volumes (paper §8); ``enabled=False`` turns the LPV off. Default: 3 cascades
    of 12³, 8 iterations, the coarsest extended to cross the scene and at most 6 cells across it, far
    light handed over to the finer cascades, clamped face flux, lookup occlusion."""
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    """How the frame's work is scheduled (worker thread and process, priorities, GL waits): the same
    image whatever it says."""
    ray_tracing: bool = True
    """Ray-traced reflections and refractions for mirror/metal/glass pixels (paper §9)."""
    reflections: bool = True
    """Trace the reflected rays. False: none are traced, and the reflection term of the Fresnel blend
    shows the rasterised surface instead (a mirror looks as with ``ray_tracing=False``)."""
    refractions: bool = True
    """Trace the refracted rays. False: none are traced, and a glass pixel's transmitted term shows
    the rasterised surface instead (its Fresnel reflection stays)."""
    transmissions: int = 4
    """Transparent interfaces a refraction ray is bent through before the surface it shows (the
    back face of a glass solid, a second pane, total internal reflection inside a prism); 0 = the
    paper's single refraction, where glass solids show their own back faces."""
    osm_size: int = 512
    """Texels per side of each of the 3 overlapped shadow maps of the ray-traced views (paper §9)."""
    rt_sun_shadows: str = "traced"
    """Sun shadows of what reflections and refractions show: "traced" (one shadow ray per traced hit
    in the CPU tracer, a hard shadow; no overlapped shadow maps are drawn) or "osm" (the paper's
    overlapped shadow maps, ``osm_size``; their coarse texels light a wall a few cm behind a window)."""
    sky_layers_per_frame: int = 1
    """Probe layers re-integrated per frame while the sun moves (paper: one); the first frame
    builds the whole volume."""
    rsm_size: int = 256
    """Texels per side of the sun's reflective shadow map (one VPL per texel)."""
    sky_vpl_stride: int = 4
    """One sky-light VPL per stride×stride block of G-buffer pixels (paper Fig. 11)."""
    indirect_scale: int = 2
    """The main view's SSAO and indirect light (sky volume, LPV) are computed at 1/scale of the
    view per axis and joint-bilaterally upsampled (1 = full resolution, the paper's)."""
    indirect_history: float = 0.2
    """With ``indirect_scale`` > 1: the weight of this frame's upsampled indirect light against the
    last frame's at the same surface point (reprojected per pixel; disocclusions take this frame's
    alone), 1 = none of the last frame's. Against the light that slid over the surfaces with the
    low-res points as the camera moved (``raster/temporal.py``; ``docs/stability.md``)."""
    indirect_refine_below: float = 0.0
    """With ``indirect_scale`` > 1: pixels whose most alike low-res texel (the upsampling's guide
    similarity: depth and normal, ``glsl/lowres.glsl``) is below this have their indirect light
    computed at full resolution instead of upsampled (``raster/lowres.IndirectRefinement``): surfaces
    narrower than the low-res grid and the far sides of silhouettes, which otherwise take a
    neighbouring surface's light. 0 = none: the LPV presets' light is smooth enough that refining
    moved FLIP by at most 0.0007 (courtyard, Cornell box) for 9–15 % of their frame; the
    ``traced-probes`` preset sets 0.05 (docs/techniques.md)."""
    lowres_tile_balance: bool = True
    """Lay those reduced-resolution images out centred on the GL rasteriser's 64-pixel tiles
    (``raster/context.LowResLayout``): llvmpipe shades each tile on one thread, and at 320×180 a
    quarter-resolution row of 80 texels fell into tiles of 64 and 16. The same image either way
    (within float rounding); False: the images at their targets' origin."""
    texture_taps: int = 4
    """Trilinear taps per textured G-buffer fragment along its footprint's long axis: anisotropic
    texture filtering in the shader (``glsl/gbuffer.glsl``); 1 = GL's isotropic trilinear, which
    blurs textures seen at grazing angles (courtyard ground FLIP 0.148 -> 0.124 with 4 taps,
    ``benchmarks/bench_aa.py``)."""
    antialiasing: str = "none"
    """Edge anti-aliasing of the final HDR frame, one pass before the tone map: "none", "fxaa"
    (``serenity.raster.fxaa``: it gains little FLIP against the reference and fills 1-pixel black
    gaps) or "taa" (``serenity.raster.taa``: each frame jittered within the pixel and blended with the
    last frames' resolved image, reprojected; the first frame after a reset is unjittered).
    ``benchmarks/bench_aa.py`` measures them."""

    def __post_init__(self):
        if not (self.exposure > 0):
            raise ConfigError(f"RenderConfig.exposure must be positive, got {self.exposure}")
        if not (isinstance(self.transmissions, int) and 0 <= self.transmissions <= 16):
            raise ConfigError(f"RenderConfig.transmissions must be an int in 0..16, got {self.transmissions!r}")
        if not (16 <= self.osm_size <= MAX_IMAGE_SIZE):
            raise ConfigError(f"RenderConfig.osm_size must be in 16..{MAX_IMAGE_SIZE}, got {self.osm_size}")
        if self.rt_sun_shadows not in ("traced", "osm"):
            raise ConfigError(f"RenderConfig.rt_sun_shadows must be traced or osm, got {self.rt_sun_shadows!r}")
        if not (isinstance(self.indirect_scale, int) and 1 <= self.indirect_scale <= 8):
            raise ConfigError(f"RenderConfig.indirect_scale must be an int in 1..8, got {self.indirect_scale!r}")
        if not (isinstance(self.indirect_refine_below, (int, float)) and 0.0 <= self.indirect_refine_below <= 1.0):
            raise ConfigError(f"RenderConfig.indirect_refine_below must be in [0, 1], "
                              f"got {self.indirect_refine_below!r}")
        if not (isinstance(self.indirect_history, (int, float)) and 0.0 < self.indirect_history <= 1.0):
            raise ConfigError(f"RenderConfig.indirect_history must be in (0, 1], got {self.indirect_history!r}")
        if self.ambient not in ("none", "constant"):
            raise ConfigError(f"RenderConfig.ambient must be 'none' or 'constant', got {self.ambient!r}")
        if not (isinstance(self.texture_taps, int) and 1 <= self.texture_taps <= 16):
            raise ConfigError(f"RenderConfig.texture_taps must be an int in 1..16, got {self.texture_taps!r}")
        if self.antialiasing not in ("none", "fxaa", "taa"):
            raise ConfigError(f"RenderConfig.antialiasing must be 'none', 'fxaa' or 'taa', got {self.antialiasing!r}")
        for name, kind in (("shadow", ShadowConfig), ("ssao", SSAOConfig), ("sky", SkyConfig), ("lpv", LPVConfig),
                           ("schedule", ScheduleConfig)):
            value = getattr(self, name)
            if not isinstance(value, kind):
                hint = (f" (e.g. {name}={kind.__name__}(enabled=False) to turn it off)"
                        if name not in ("shadow", "schedule") else "")
                raise ConfigError(f"RenderConfig.{name} must be a {kind.__name__}, got {value!r}{hint}")
        if self.sky.enabled and self.sky.method == "gather" and self.lpv.enabled and self.lpv.diffuse:
            raise ConfigError("RenderConfig: sky.method='gather' already lights the probes with the bounced "
                              "light; turn the LPV's diffuse light off (lpv.diffuse=False or lpv.enabled=False) "
                              "or it counts twice")


    @classmethod
    def preset(cls, name: str | None = None, **overrides) -> RenderConfig:
        """The settings of quality preset ``name`` (one of ``QUALITY_PRESETS``, a former name of one
        with a ``PresetRenamedWarning``, or None for ``DEFAULT_QUALITY``; ``PRESETS`` lists what each sets,
        every field it does not name keeps its default), then ``overrides`` (fields of RenderConfig)
        on top: ``RenderConfig.preset(exposure=0.05)`` is the default preset a little brighter."""
        name = preset_name(DEFAULT_QUALITY if name is None else name)
        kw: dict = {}
        for key, value in PRESETS[name].items():
            sub = SUB_CONFIGS.get(key)
            kw[key] = sub(**value) if sub is not None else value
        kw.update(overrides)
        return cls(**kw)

#: deepest kd-tree the build makes (the traversal's stack holds one entry per level)
KD_MAX_DEPTH = 62


@dataclass(frozen=True)
class KdBuildConfig:
    """The kd-tree's binned SAH build (paper §9; ``serenity/kernels/kdtree_build.py``). Every field is
    part of the tree's disk-cache key. Costs are relative units (only their ratio matters)."""

    traversal_cost: float = 3.0
    """C_trav: cost of one inner-node step, relative to ``intersection_cost``. 3: the CPU's packets
    test a leaf's triangles 8 at a time, so more triangles per leaf cost little more; against 2 the
    benchmark's incoherent rays trace 1.06x as fast (paired), camera rays 0.98x, on a tree of 301k
    nodes instead of 500k; 3.5 and 4 read 1.09x / 0.93x."""
    intersection_cost: float = 1.0
    """C_isect: cost of one ray–triangle test."""
    empty_bonus: float = 0.8
    """Fraction (0..1) of a split's cost removed when one side is empty (empty-space cut-off)."""
    min_empty_fraction: float = 0.1
    """The bonus applies only when the empty side is at least this fraction (0..1) of the node's extent.
    0.1 rather than 0: thin empty slabs cost a traversal step each and save little; with 0.1 the
    benchmark's rays take 12 % fewer steps and 17 % fewer triangle tests and coherent rays trace
    16-22 % faster per CPU-second."""
    bins: int = 32
    """SAH bins per axis per node, 4..64 (a node with fewer triangles gets fewer: the next power of 2)."""
    max_depth: int | None = None
    """Depth limit, 0..``KD_MAX_DEPTH``; None = 8 + 1.3·log2(N) for N triangles (pbrt's rule), capped."""

    def __post_init__(self):
        for name in ("traversal_cost", "intersection_cost"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"KdBuildConfig.{name} must be a finite number > 0, got {value!r}")
        for name in ("empty_bonus", "min_empty_fraction"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value < 1.0):
                raise ConfigError(f"KdBuildConfig.{name} must be in [0, 1), got {value!r}")
        if not (isinstance(self.bins, int) and 4 <= self.bins <= 64):
            raise ConfigError(f"KdBuildConfig.bins must be an int in 4..64, got {self.bins!r}")
        if self.max_depth is not None and not (isinstance(self.max_depth, int) and 0 <= self.max_depth <= KD_MAX_DEPTH):
            raise ConfigError(f"KdBuildConfig.max_depth must be None or an int in 0..{KD_MAX_DEPTH}, "
                                f"got {self.max_depth!r}")

    def depth_limit(self, n: int) -> int:
        """The depth limit for a mesh of ``n`` triangles."""
        d = self.max_depth if self.max_depth is not None else int(round(8 + 1.3 * math.log2(max(n, 1))))
        return int(max(0, min(d, KD_MAX_DEPTH)))


SUB_CONFIGS = {"shadow": ShadowConfig, "ssao": SSAOConfig, "sky": SkyConfig, "lpv": LPVConfig,
               "schedule": ScheduleConfig}

PRESETS: dict[str, dict] = {
    # The paper's pipeline as published (§6–§9): indirect light and SSAO at full resolution, the sky
    # volume re-integrated one probe layer per frame by ray casting, 3 LPV cascades of 32³, 4 shadow
    # cascades of 2048² with PCSS and no contact shadows, the ray-traced views lit with the
    # overlapped shadow maps. The slowest preset, kept to compare with the paper.
    "paper": {"indirect_scale": 1, "sky": {"method": "layers"}, "sky_layers_per_frame": 1,
              "lpv": {"resolution": 32}, "shadow": {"contact_steps": 0}, "rt_sun_shadows": "osm"},
    # Every technique of the paper, at the settings of a bare RenderConfig(): indirect light and SSAO
    # at half resolution, the sky volume re-lit by visibility transfer (every probe current every
    # frame), 3 LPV cascades of 12³, 4 shadow cascades of 2048² with PCSS and a contact-shadow march.
    "lpv": {},
    # "lpv" at about 60 % of its frame time for a little more error: indirect light and SSAO at
    # quarter resolution (the indirect light is smooth: FLIP moves by under 0.002, the LPV lighting
    # pass gets ~4x cheaper), shadow cascades of 1.6 texels per image pixel (at most 1024²) redrawn
    # in turn without the contact march, 4 PCSS blocker and 8 filter taps, fewer SSAO and glossy-LPV
    # taps, a 64² sky map re-lit one probe layer per frame, LPV cascades updated in turn, a coarser
    # RSM and fewer sky VPLs.
    "lpv-fast": {"indirect_scale": 4,
                 "shadow": {"size": 1024, "texels_per_pixel": 1.6, "blocker_samples": 4, "filter_samples": 8,
                            "stagger": True, "contact_steps": 0},
                 "ssao": {"directions": 6, "steps": 2},
                 "sky": {"sky_map_size": 64, "sky_steps": 12, "transfer_layers": 1},
                 "lpv": {"glossy_steps": 4, "stagger": True},
                 "rsm_size": 128, "sky_vpl_stride": 8},
    # Beyond the paper, and the default: no LPV and no SSAO. The sky volume's probes, fitted to what
    # stands on the ground (~24 000 probes), each trace 512 rays once through the kd-tree and are lit
    # with the sky and every bounce of sun and sky light through the real geometry (``"gather"``),
    # each probe weighed by whether it sees the point it lights. The probes already hold the
    # occlusion SSAO would add (FLIP is better in both test scenes without SSAO), and 128 rays leave
    # the Cornell box's probes blotchy (its light comes from a small sunlit patch). Indirect light at
    # quarter resolution and at full resolution where upsampling finds no like texel (a table's
    # edge), 3 shadow cascades of 2.4 texels per image pixel, a coarse sky map.
    "traced-probes": {"indirect_scale": 4,
                      "shadow": {"size": 1024, "texels_per_pixel": 2.4, "cascades": 3, "blocker_samples": 4,
                                 "filter_samples": 8, "stagger": True},
                      "ssao": {"enabled": False},
                      "sky": {"sky_map_size": 64, "sky_steps": 8, "transfer_layers": 1, "method": "gather",
                              "fit": "content", "target_probes": 24_000, "gather_rays": 512, "normal_offset": 0.25},
                      "lpv": {"enabled": False},
                      "rsm_size": 128, "sky_vpl_stride": 8, "indirect_refine_below": 0.05},
}
"""Quality presets: field → value, or for a sub-config (shadow, ssao, sky, lpv) its field → value;
every field a preset does not name keeps ``RenderConfig()``'s default. Each is one point of the
speed-vs-error frontier (``benchmarks/bench_frontier.py``)."""

QUALITY_PRESETS = tuple(PRESETS)
DEFAULT_QUALITY = "traced-probes"
"""The preset ``Renderer`` renders without a config, and ``serenity render``, ``view``, ``sweep``
and ``bench`` use unless ``--quality`` says otherwise. On the speed-vs-error frontier it costs about
what ``lpv-fast`` costs (within about 10 % in the test scenes) and is the closest to the
path-traced reference in every scene of the frontier (FLIP 0.043–0.055 in the test scenes against
0.104–0.115 for the LPV presets at 320×180 and 640×360, the breakfast room 0.100 against 0.57;
``benchmarks/bench_frontier.py``, ``frontier.json``). The presets that keep the paper's LPV are a ``--quality`` away."""

PRESET_ALIASES = {"low": "traced-probes", "medium": "lpv-fast", "high": "lpv"}
"""Former preset names, still accepted everywhere a preset name is, with a ``PresetRenamedWarning``."""


class PresetRenamedWarning(FutureWarning):
    """A former quality preset name was used (``PRESET_ALIASES``); the message names the new one.
    A ``FutureWarning``, so that Python shows it by default; the ``serenity`` command prints it as
    one line."""


def preset_name(name: str, where: str | None = None) -> str:
    """The preset ``name`` stands for: itself, or for a former name (``PRESET_ALIASES``) its current
    one, with a one-line ``PresetRenamedWarning`` (prefixed with ``where``, e.g. a file, when given). An
    unknown name is a ``ConfigError`` that lists the presets."""
    if name in PRESET_ALIASES:
        new = PRESET_ALIASES[name]
        prefix = f"{where}: " if where else ""
        warnings.warn(f"{prefix}quality preset {name!r} is now called {new!r}", PresetRenamedWarning,
                      stacklevel=3)
        return new
    if name not in PRESETS:
        prefix = f"{where}: " if where else ""
        raise ConfigError(f"{prefix}quality preset must be one of {', '.join(QUALITY_PRESETS)}, got {name!r}")
    return name


def changed_settings(old, new, prefix: str = "") -> list[str]:
    """The settings in which config ``new`` differs from ``old`` (two configs of one dataclass, e.g.
    two ``RenderConfig``): dotted paths into the sub-configs, e.g. ``["exposure", "lpv.glossy"]``."""
    out = []
    for f in dataclasses.fields(old):
        a, b = getattr(old, f.name), getattr(new, f.name)
        if dataclasses.is_dataclass(a) and type(a) is type(b):
            out += changed_settings(a, b, f"{prefix}{f.name}.")
        elif a != b:
            out.append(prefix + f.name)
    return out
