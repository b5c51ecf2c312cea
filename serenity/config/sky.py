"""The sky lighting irradiance volume (paper §7): ``SkyConfig``, and the choices its fields take."""

from __future__ import annotations

from dataclasses import dataclass

from serenity.errors import ConfigError

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
    """How probes follow the sky: "layers" (the paper) re-integrates ``layers_per_frame`` layers per
    frame by ray casting against the sky map, in a continuous cycle; "transfer" integrates
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
    layers_per_frame: int = 1
    """"layers": probe layers re-integrated per frame while the sun moves (paper: one); the first
    frame builds the whole volume."""
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
        if not (isinstance(self.layers_per_frame, int) and self.layers_per_frame >= 1):
            raise ConfigError(f"SkyConfig.layers_per_frame must be an int >= 1, got {self.layers_per_frame!r}")
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
