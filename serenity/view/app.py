"""The interactive viewer: ``Renderer`` drawing into a window, a fly camera, live sun and technique
controls, AOV views, saving, and a background path-traced reference to compare with.

Each displayed frame: input (the window's callbacks, or the script's steps sent through the same
handlers) → fly camera / sun / settings applied to the scene and config → ``Renderer.render(
read_back=False)`` → the chosen view drawn from the renderer's GL textures into the window's
framebuffer (``PresentPass``) → the Dear ImGui panel → swap. Nothing is read back per frame: the
read-backs are F12 (one frame rendered with ``read_back=True``), starting a reference (the HDR
image of that moment, to compare with) and screenshots.

Static camera refinement (temporal anti-aliasing): while nothing changes (camera, sun, settings,
view) and the sky volume is current, each frame is rendered with the next sub-pixel jitter of
``Renderer.render_accumulated``'s Halton(2, 3) sequence (the first unjittered) and folded into a
running mean on the GL side (``present.AccumulatePass``), which the final view shows; after
``taa_samples`` frames the view is converged (the panel says so) and frames are rendered unjittered
again, the mean kept. Any change starts it afresh. The AOV views are never jittered by it. With
``RenderConfig.antialiasing = "taa"`` the renderer jitters and resolves the frames the viewer does
not accumulate (a moving view) itself; the viewer's jitter replaces the renderer's while it
accumulates, so no frame is jittered twice.
"""

from __future__ import annotations

import json
import os
import time

import moderngl
import numpy as np

from serenity.colour import reinhard_srgb
from serenity.errors import SerenityError
from serenity.eval.metrics import compare, flip_png
from serenity.frame import Renderer, halton
from serenity.io.exr import write_exr
from serenity.io.png import write_png
from serenity.optional import require
from serenity.raster.interop import read_texture, upload_texture
from serenity.scene.mesh_io import export_glb
from serenity.scene.toml_scene import save_toml
from serenity.view import TAA_SAMPLES, present
from serenity.view.controls import VIEWS, FlyCamera, Settings, TimeOfDay
from serenity.view.panel import draw_panel
from serenity.view.reference_job import ReferenceJob
from serenity.view.script import SCRIPT_DT, Script
from serenity.view.window import open_window

_CASCADE_COLORS = [(1.0, 0.3, 0.2), (0.3, 1.0, 0.3), (0.3, 0.5, 1.0), (1.0, 1.0, 0.3)]
#: the views that show the final image, and so its temporal anti-aliasing
TAA_VIEWS = ("final", "lpv cascades")
#: the panel's and a script's names of the ``Settings`` that go into the ``RenderConfig``
CONFIG_SETTINGS = ("exposure", "quality", "shadow_filter", "ssao", "sky_lighting", "lpv_diffuse", "lpv_glossy",
                   "reflections", "refractions")


class Viewer:
    def __init__(self, scene, width: int, height: int, settings: Settings, device: str | None = None,
                 script: Script | None = None, screenshot: str | None = None, exit_after: int | None = None,
                 trace: str | None = None, panel: bool = True, out_dir: str = "serenity_out/view", spp: int = 64,
                 visible: bool = True, taa_samples: int = TAA_SAMPLES):
        self.scene, self.width, self.height = scene, int(width), int(height)
        self.settings, self.device = settings, device
        self.script, self.screenshot_path, self.exit_after = script, screenshot, exit_after
        self.trace_path, self.show_panel, self.out_dir, self.spp = trace, panel, out_dir, int(spp)
        self.wnd = open_window(self.width, self.height, f"Serenity — {scene.name}", visible=visible)
        self.ctx = self.wnd.ctx
        self.fly = FlyCamera.from_camera(scene.camera)
        self.tod = TimeOfDay.for_scene(scene)
        self.view = "final"
        self.split = 0.5
        self.keys_down: set[str] = set()
        self.fast = False
        self._pending_look = [0.0, 0.0]
        self._sun_dirty = False
        self._config_dirty = False
        self._save_requested = False
        self._reference_requested = False
        self._quit = False
        self.frame_index = 0
        self.still_frames = 0
        self.taa_samples = int(taa_samples)
        self.taa_count = 0
        """Frames in the temporal anti-aliasing's running mean (0: none; 1: the unjittered frame alone)."""
        self._taa_reset = False
        self.ms: dict[str, float] = {}
        self.fps = 0.0
        self.frame_ms = 0.0
        self.messages: list[str] = []
        self.saved: list[str] = []
        self.trace: list[dict] = []
        self.job = None
        self.comparison: dict | None = None
        self._mesh_file = None
        self._workspace = None
        self._rt_mask_tex = None

        self.renderer = None
        self.builds = 0
        self._build_renderer()
        self.present = present.PresentPass(self.ctx)
        self.lines = present.LinesPass(self.ctx)
        self.accum = present.AccumulatePass(self.ctx)
        self.accum.resize(self.width, self.height)
        self._init_imgui()
        self._bind_events()

    # ----------------------------------------------------------------------------------- setup

    def _build_renderer(self) -> None:
        old = self.renderer
        if old is not None:
            old.close()
            _release_gl(old)
        self.renderer = Renderer(self.scene, self.width, self.height, device=self.device,
                                 config=self.settings.config())
        self.builds += 1

    def _init_imgui(self) -> None:
        imgui = require("imgui_bundle", "serenity view's panel").imgui
        integration = require("moderngl_window.integrations.imgui_bundle", "serenity view's panel")

        imgui.create_context()
        imgui.get_io().set_ini_filename("")
        self.imgui = imgui
        self.gui = integration.ModernglWindowRenderer(self.wnd)

    def _bind_events(self) -> None:
        w = self.wnd
        w.key_event_func = self.on_key
        w.mouse_position_event_func = self.gui.mouse_position_event
        w.mouse_drag_event_func = self.on_drag
        w.mouse_scroll_event_func = self.on_scroll
        w.mouse_press_event_func = self.gui.mouse_press_event
        w.mouse_release_event_func = self.gui.mouse_release_event
        w.unicode_char_entered_func = self.gui.unicode_char_entered
        w.resize_func = self.gui.resize
        w.close_func = self._on_close

    # ---------------------------------------------------------------------------------- input

    def key_name(self, key) -> str | None:
        keys = self.wnd.keys
        for name in ("W", "A", "S", "D", "Q", "E", "R", "V", "T", "F1", "F12", "ESCAPE", "LEFT_SHIFT",
                     "RIGHT_SHIFT", "TAB", "SPACE", "PAGE_UP", "PAGE_DOWN"):
            if getattr(keys, name, None) == key:
                return name
        return None

    def key_code(self, name: str):
        code = getattr(self.wnd.keys, name.upper(), None)
        if code is None:
            raise SerenityError(f"unknown key {name!r} (keys: W A S D Q E R V T F1 F12 ESCAPE LEFT_SHIFT ...)")
        return code

    def on_key(self, key, action, modifiers) -> None:
        """The window's key callback (and the script's): panel first, then the viewer's bindings."""
        self.gui.key_event(key, action, modifiers)
        keys = self.wnd.keys
        name = self.key_name(key)
        if action == keys.ACTION_RELEASE:
            self.keys_down.discard(name)
            if name in ("LEFT_SHIFT", "RIGHT_SHIFT"):
                self.fast = False
            return
        if action != keys.ACTION_PRESS or name is None:
            return
        if self.imgui.get_io().want_capture_keyboard and name not in ("F1", "F12", "ESCAPE"):
            return
        shift = bool(getattr(modifiers, "shift", False))
        if name in "WASDQE":
            self.keys_down.add(name)
        elif name in ("LEFT_SHIFT", "RIGHT_SHIFT"):
            self.fast = True
        elif name == "F12":
            self._save_requested = True
        elif name == "R":
            self._reference_requested = True
        elif name == "F1":
            self.show_panel = not self.show_panel
        elif name == "V":
            names = list(VIEWS)  # through set_value: a new view restarts the accumulation
            self.set_value("view", names[(names.index(self.view) + (-1 if shift else 1)) % len(names)])
        elif name == "T":
            self.set_value("hour", (self.tod.hour + (-0.25 if shift else 0.25)) % 24.0)
        elif name == "ESCAPE":
            self._quit = True

    def on_drag(self, x, y, dx, dy) -> None:
        """Mouse-look while the right button (or the left one outside the panel) is held."""
        self.gui.mouse_drag_event(x, y, dx, dy)
        states = self.wnd.mouse_states
        if states.right or (states.left and not self.imgui.get_io().want_capture_mouse):
            self.look(dx, dy)

    def look(self, dx: float, dy: float) -> None:
        self._pending_look[0] += float(dx)
        self._pending_look[1] += float(dy)

    def on_scroll(self, x_offset, y_offset) -> None:
        self.gui.mouse_scroll_event(x_offset, y_offset)
        if not self.imgui.get_io().want_capture_mouse:
            self.fly.speed = float(np.clip(self.fly.speed * 1.25 ** float(y_offset), 0.05, 500.0))

    def _on_close(self) -> None:
        self._quit = True

    def set_value(self, name: str, value) -> None:
        """What the panel's widgets and a script's ``set`` change (``script.SETTABLE`` names)."""
        if name in ("hour", "date", "latitude", "longitude", "utc_offset"):
            old = getattr(self.tod, name)
            setattr(self.tod, name, value)
            try:
                self.tod.sun(self.scene.sun)
            except SerenityError:
                setattr(self.tod, name, old)
                raise
            self._sun_dirty = True
        elif name in CONFIG_SETTINGS:
            old = getattr(self.settings, name)
            setattr(self.settings, name, value)
            try:
                self.settings.config()
            except SerenityError:
                setattr(self.settings, name, old)
                raise
            self._config_dirty = True
        elif name == "taa":
            self.settings.taa = bool(value)
            self._taa_reset = True
        elif name == "speed":
            self.fly.speed = float(value)
        elif name == "view":
            if value not in VIEWS:
                raise SerenityError(f"unknown view {value!r} (views: {', '.join(VIEWS)})")
            self._taa_reset |= value != self.view
            self.view = value
        elif name == "panel":
            self.show_panel = bool(value)
        elif name == "split":
            self.split = float(np.clip(value, 0.0, 1.0))
        else:
            raise SerenityError(f"cannot set {name!r}")

    def _run_script_steps(self) -> list[str]:
        """This frame's script steps, sent through the same handlers as the window's events."""
        shots = []
        if self.script is None:
            return shots
        keys = self.wnd.keys
        for s in self.script.steps:
            if s.action == "key" and s.frame + s.hold == self.frame_index:
                self.on_key(self.key_code(s.value), keys.ACTION_RELEASE, self.wnd.modifiers)
        for s in self.script.at(self.frame_index):
            if s.action == "key":
                self.on_key(self.key_code(s.value), keys.ACTION_PRESS, self.wnd.modifiers)
            elif s.action == "press":
                code = self.key_code(s.value)
                self.on_key(code, keys.ACTION_PRESS, self.wnd.modifiers)
                self.on_key(code, keys.ACTION_RELEASE, self.wnd.modifiers)
            elif s.action == "mouse":
                self.look(*s.value)
            elif s.action == "set":
                for k, v in s.value.items():
                    self.set_value(k, v)
            elif s.action == "screenshot":
                shots.append(s.value)
            elif s.action == "wait":
                self.wait_for_reference()
            elif s.action == "exit":
                self._quit = True
        return shots

    # --------------------------------------------------------------------------------- per frame

    def _apply_changes(self, dt: float) -> bool:
        """Camera, sun and settings into the scene and the renderer; returns whether anything moved."""
        changed = False
        if self._pending_look != [0.0, 0.0]:
            self.fly.look(*self._pending_look)
            self._pending_look = [0.0, 0.0]
            changed = True
        changed |= self.fly.move(self.keys_down, dt, self.fast)
        if changed:
            self.fly.apply(self.scene.camera)
        if self._sun_dirty:
            self.scene.sun = self.tod.sun(self.scene.sun)
            self._sun_dirty = False
            changed = True
        if self._config_dirty:
            new = self.settings.config()
            if Renderer.needs_rebuild(self.renderer.config, new):
                self._build_renderer()
                self.messages.append(f"renderer rebuilt for {self.settings.quality} quality / switches")
            else:
                self.renderer.reconfigure(new)
            self._config_dirty = False
            changed = True
        return changed

    def run(self) -> int:
        last = time.perf_counter()
        try:
            while not self.wnd.is_closing and not self._quit:
                shots = self._run_script_steps()
                if self._quit:
                    break
                now = time.perf_counter()
                dt = SCRIPT_DT if self.script is not None else min(0.25, now - last)
                real_dt, last = now - last, now
                moved = self._apply_changes(dt)
                self.still_frames = 0 if moved else self.still_frames + 1
                self._frame(shots, real_dt)
                self.frame_index += 1
                if self.exit_after is not None and self.frame_index >= self.exit_after:
                    break
                if (self.script is not None and self.exit_after is None
                        and self.frame_index > self.script.last_frame + 1):
                    break
        finally:
            closed = self.wnd.is_closing
            self._finish()
        if closed:
            print(f"serenity view: window closed after {self.frame_index} frames")
        return 0

    def _frame(self, shots: list[str], real_dt: float) -> None:
        self._loop_ms = real_dt * 1e3  # the previous frame's full period: input, render, draw, panel, swap
        save = self._save_requested
        self._save_requested = False
        frame = self._render(save)
        if save:
            self._save(frame)
        if self._reference_requested:
            self._reference_requested = False
            self._start_reference()
        self._poll_reference()
        self._update_stats(frame, real_dt)
        self._draw()
        if self.show_panel:
            draw_panel(self, real_dt)
        last = self.exit_after is not None and self.frame_index + 1 >= self.exit_after
        if self.screenshot_path and (last or (self.script is not None and self.exit_after is None
                                              and self.frame_index >= self.script.last_frame + 1)):
            shots = shots + [self.screenshot_path]
        for path in shots:
            self._screenshot(path)
        self._record(frame)
        self.wnd.swap_buffers()

    def _render(self, save: bool):
        """This frame: the next sample of the still view's temporal anti-aliasing (module docstring),
        or an unjittered frame. An F12 frame is rendered unjittered (its AOVs are those of the view) and
        joins the mean only as its first sample."""
        taa = self.taa_on
        if self.still_frames == 0 or self._taa_reset or not taa:
            self.taa_count = 0
            self._taa_reset = False
        i = self.taa_count
        sample = taa and i < self.taa_samples and (i == 0 or not save)
        # while it accumulates (and for F12) its jitter replaces the renderer's own (antialiasing =
        # "taa"); else the renderer's choice (TAA's jitter, or none)
        jitter = (halton(i, 2) - 0.5, halton(i, 3) - 0.5) if sample and i else ((0.0, 0.0) if sample or save else None)
        frame = self.renderer.render(read_back=save, jitter=jitter)
        stale = self.sky_stale()
        if stale is not None and stale.any():
            self.taa_count = 0  # the sky volume's layer sweep still changes the image: nothing to average yet
        elif sample:
            self.accum.add(self.renderer.outputs["hdr"], i + 1)
            self.taa_count = i + 1
        return frame

    @property
    def taa_on(self) -> bool:
        """Whether the shown view is refined by temporal anti-aliasing."""
        return self.settings.taa and self.taa_samples > 1 and self.view in TAA_VIEWS

    def shown_hdr(self) -> np.ndarray:
        """(H, W, 3) float32: the final view's HDR image as shown (the TAA mean while there is one)."""
        return read_texture(self.accum.mean if self.taa_count > 1 else self.renderer.outputs["hdr"], 3)

    def _update_stats(self, frame, real_dt: float) -> None:
        a = 0.2 if self.frame_index > 1 else 1.0
        for k in list(frame.timings) + [k for k in self.ms if k not in frame.timings]:
            v = (1 - a) * self.ms.get(k, 0.0) + a * frame.timings.get(k, 0.0)
            self.ms.pop(k, None)
            if k in frame.timings or v >= 0.01:
                self.ms[k] = v  # re-inserted: the panel lists this frame's stages in pipeline order
        if real_dt > 0:
            self.frame_ms = (1 - a) * self.frame_ms + a * real_dt * 1e3 if self.frame_index else real_dt * 1e3
            self.fps = 1e3 / self.frame_ms if self.frame_ms > 0 else 0.0

    # ------------------------------------------------------------------------------------ views

    def viewport(self) -> tuple[int, int, int, int]:
        """The render's aspect fitted (letterboxed) into the window's framebuffer."""
        bw, bh = self.wnd.buffer_size
        s = min(bw / self.width, bh / self.height)
        w, h = max(1, int(round(self.width * s))), max(1, int(round(self.height * s)))
        return (bw - w) // 2, (bh - h) // 2, w, h

    def _workspace_tex(self):
        if self._workspace is None:
            self._workspace = self.ctx.texture((self.width, self.height), 4, dtype="f4")
            self._workspace_fbo = self.ctx.framebuffer(color_attachments=[self._workspace])
        self._workspace_fbo.clear(0.0, 0.0, 0.0, 0.0)
        return self._workspace

    def view_texture(self):
        """(texture, mode) for the current view, or None when this view has nothing to show."""
        r, out, view = self.renderer, self.renderer.outputs, self.view
        gbuf = out["gbuffer"]
        if view in TAA_VIEWS:
            if self.taa_count > 1:
                return self.accum.mean, present.HDR
            return out["ldr"], present.DISPLAY
        if view == "albedo":
            return gbuf.albedo, present.LINEAR
        if view == "normal":
            return gbuf.normal, present.SIGNED
        if view == "direct":
            return out["direct"], present.HDR
        if view == "sky light" and r.sky_volume is not None:
            tex = self._workspace_tex()
            r.sky_pass.render(tex, gbuf, r.sky_gl.bind, r.scene.camera.position)
            return tex, present.HDR
        if view == "lpv indirect" and r.lpv is not None and r.lpv_gl.count:
            tex = self._workspace_tex()
            c = r.config.lpv  # the panel's diffuse / glossy switches
            r.lpv_pass.render(tex, gbuf, r.lpv_gl.bind, r.scene.camera.position, diffuse=c.diffuse, glossy=c.glossy)
            return tex, present.HDR
        if view == "ao" and out["ao"] is not None:
            return out["ao"], present.SCALAR
        if view == "rt mask" and out["rcb"] is not None:
            if self._rt_mask_tex is not None:
                self._rt_mask_tex.release()
            mask = out["rcb"].mask()[..., None].astype(np.uint8) * 255
            self._rt_mask_tex = upload_texture(self.ctx, mask, dtype="f1", repeat=False)
            return self._rt_mask_tex, present.SCALAR
        return None

    def _draw(self) -> None:
        ctx, fbo = self.ctx, self.wnd.fbo
        fbo.use()
        ctx.enable_only(moderngl.NOTHING)
        fbo.viewport = (0, 0, *self.wnd.buffer_size)
        fbo.clear(0.08, 0.08, 0.08, 1.0)
        vp = self.viewport()
        c = self.comparison
        self._shown = True
        if self.view in ("reference split", "flip error") and c is not None:
            if self.view == "flip error":
                self.present.draw(fbo, vp, c["flip_tex"], present.DISPLAY)
            else:
                self.present.draw(fbo, vp, c["ours_tex"], present.HDR, c["ref_tex"], present.HDR, split=self.split,
                                  exposure=self.settings.exposure)
            return
        shown = self.view_texture() if self.view not in ("reference split", "flip error") else None
        if shown is None:
            self._shown = False
            return  # a switched-off technique, or no reference yet: the panel says so
        # a low-resolution image (SSAO) is shown as the AOV writes it: each texel over its block of pixels
        block = self.renderer.config.indirect.scale if self.view == "ao" else 1
        self.present.draw(fbo, vp, shown[0], shown[1], exposure=self.settings.exposure, block=block,
                          render_size=(self.width, self.height))
        if self.view == "lpv cascades" and self.renderer.lpv is not None:
            cam = self.scene.camera
            vproj = cam.projection_matrix(self.width / self.height) @ cam.view_matrix()
            boxes = [(np.array(g.origin), np.array(g.origin) + g.extent, _CASCADE_COLORS[g.level % 4])
                     for g in self.renderer.lpv.grids]
            self.lines.draw(fbo, vp, vproj, boxes)

    def view_available(self) -> bool:
        """Whether the last frame's view had something to show."""
        return getattr(self, "_shown", True)

    # ------------------------------------------------------------------------------ refinement

    def sky_stale(self) -> np.ndarray | None:
        """(Y,) bool: the sky volume's layers not yet integrated against the current sky (always
        none with the "transfer" method, which re-lights every probe at once); None when it is off."""
        sv = self.renderer.sky_volume
        if sv is None:
            return None
        return np.asarray(sv.layer_versions != sv.sky_version)

    @property
    def converged(self) -> bool:
        """Nothing moved this frame and nothing temporal is left to refine: the sky volume's layer
        sweep is done and the temporal anti-aliasing (when the view has it) holds all its samples."""
        s = self.sky_stale()
        return (self.still_frames > 0 and (s is None or not s.any())
                and (not self.taa_on or self.taa_count >= self.taa_samples))

    # ----------------------------------------------------------------------- save / screenshots

    def _save(self, frame) -> None:
        """F12: PNG + multi-layer EXR exactly as ``serenity render`` writes them, and a TOML scene
        (camera and sun as now; the meshes once per session as a GLB beside it). While the final view
        shows a TAA mean of n > 1 frames, the beauty (and the PNG) is that mean, as
        ``Renderer.render_accumulated(n)`` gives it; the AOVs are the unjittered frame's."""
        os.makedirs(self.out_dir, exist_ok=True)
        taa = ""
        if self.taa_count > 1 and self.view in TAA_VIEWS:
            frame.hdr = self.shown_hdr()
            frame.ldr = reinhard_srgb(frame.hdr, self.settings.exposure)
            taa = f" (beauty: the mean of {self.taa_count} jittered frames)"
        stem = os.path.join(self.out_dir, f"{self.scene.name}_{len(self.saved):03d}")
        if self._mesh_file is None:
            self._mesh_file = os.path.join(self.out_dir, f"{self.scene.name}.glb")
            export_glb(self.scene, self._mesh_file)
        write_png(stem + ".png", frame.ldr)
        write_exr(stem + ".exr", {"beauty": frame.hdr, **frame.aovs})
        save_toml(self.scene, stem + ".toml", os.path.basename(self._mesh_file))
        self.saved.append(stem)
        self.messages.append(f"wrote {stem}.png/.exr/.toml")
        print(f"wrote {stem}.png, {stem}.exr (layers: beauty, {', '.join(frame.aovs)}), {stem}.toml{taa}")

    def _screenshot(self, path: str) -> None:
        bw, bh = self.wnd.buffer_size
        data = np.frombuffer(self.wnd.fbo.read(viewport=(0, 0, bw, bh), components=3), np.uint8)
        # moderngl selects GL_COLOR_ATTACHMENT0 as the read buffer, which the window's default
        # framebuffer does not have: the pixels come back right (from the back buffer) but the GL
        # error flag is left set, and the next pass that checks it would fail; clear it here
        _ = self.ctx.error
        d = os.path.dirname(os.path.abspath(path))
        os.makedirs(d, exist_ok=True)
        write_png(path, data.reshape(bh, bw, 3)[::-1])
        print(f"wrote {path}")

    def _record(self, frame) -> None:
        if self.trace_path is None:
            return
        cam, sun = self.scene.camera, self.scene.sun
        s = self.sky_stale()
        self.trace.append({
            "frame": self.frame_index, "camera_position": cam.position.tolist(), "camera_forward": cam.forward.tolist(),
            "sun_direction": sun.direction.tolist(), "sun_elevation_deg": sun.elevation_deg, "hour": self.tod.hour,
            "view": self.view, "still_frames": self.still_frames, "renderer_builds": self.builds,
            "taa_samples": self.taa_count,
            "loop_ms": self._loop_ms, "ssao": self.renderer.config.ssao.enabled, "converged": self.converged,
            "sky_stale_layers": None if s is None else int(s.sum()), "timings_ms": frame.timings,
            "wall_ms": frame.wall_ms,
            "read_back": frame.hdr is not None, "reference_progress": None if self.job is None else self.job.progress,
            "comparison": None if self.comparison is None else {k: self.comparison[k] for k in ("flip", "rel_mse")},
        })

    # -------------------------------------------------------------------------------- reference

    def _start_reference(self) -> None:
        if self.job is not None and self.job.running:
            self.job.cancel()
        self._ours_hdr = self.shown_hdr()
        self.job = ReferenceJob(self.scene, self.width, self.height, spp=self.spp)
        self.messages.append(f"reference started ({self.spp} spp, {self.width}x{self.height})")

    def _poll_reference(self) -> None:
        job = self.job
        if job is None:
            return
        job.poll()
        if job.error is not None:
            self.messages.append(f"reference failed: {job.error}")
            self.job = None
            return
        if job.result is None:
            return
        ref, ours = job.result, self._ours_hdr
        m = compare(ours, ref, exposure=self.settings.exposure)
        if self.comparison is not None:
            for k in ("ours_tex", "ref_tex", "flip_tex"):
                self.comparison[k].release()
        self.comparison = {
            "flip": m["flip"], "rel_mse": m["rel_mse"], "spp": job.spp,
            "ours_tex": upload_texture(self.ctx, ours, repeat=False),
            "ref_tex": upload_texture(self.ctx, ref, repeat=False),
            "flip_tex": upload_texture(self.ctx, flip_png(m["flip_map"]), dtype="f1", repeat=False),
        }
        self.messages.append(f"reference done: FLIP {m['flip']:.4f}, relMSE {m['rel_mse']:.4f}")
        print(f"reference {job.spp} spp: FLIP {m['flip']:.4f} relMSE {m['rel_mse']:.4f}")
        self.job = None
        if self.view not in ("reference split", "flip error"):
            self.view = "reference split"

    def wait_for_reference(self, timeout: float | None = None) -> None:
        """Block until the running reference is done (a script's ``wait``); its failure is an error."""
        job = self.job
        if job is not None:
            job.wait(timeout)
            self._poll_reference()
            if job.error is not None:
                raise SerenityError(f"the reference failed: {job.error}")

    # ------------------------------------------------------------------------------------ close

    def _finish(self) -> None:
        if self.job is not None:
            self.job.cancel()
        if self.trace_path:
            d = os.path.dirname(os.path.abspath(self.trace_path))
            os.makedirs(d, exist_ok=True)
            with open(self.trace_path, "w") as f:
                json.dump({"scene": self.scene.name, "size": [self.width, self.height],
                           "window_buffer_size": list(self.wnd.buffer_size), "frames": self.trace,
                           "saved": self.saved}, f, indent=1)
        if self.renderer is not None:
            self.renderer.close()
        try:
            self.wnd.destroy()
        except Exception:  # the window may already be gone
            pass


def _release_gl(renderer) -> None:
    """Release the GL objects a dropped ``Renderer`` holds (its passes' textures, framebuffers,
    buffers, programs), so that rebuilding for a new preset does not leak GPU memory. Best effort:
    it walks the renderer's attributes and its passes' attributes (two levels)."""
    kinds = (moderngl.Texture, moderngl.Texture3D, moderngl.TextureArray, moderngl.Framebuffer, moderngl.Buffer,
             moderngl.VertexArray, moderngl.Program, moderngl.Renderbuffer)
    seen: set[int] = set()

    def walk(obj, depth: int) -> None:
        if id(obj) in seen:
            return
        seen.add(id(obj))
        if isinstance(obj, kinds):
            obj.release()
            return
        if isinstance(obj, (list, tuple)):
            for v in obj:
                walk(v, depth)
            return
        if isinstance(obj, dict):
            for v in obj.values():
                walk(v, depth)
            return
        if depth > 0 and type(obj).__module__.startswith("serenity.") and hasattr(obj, "__dict__"):
            for v in vars(obj).values():
                walk(v, depth - 1)

    walk(renderer, 3)
