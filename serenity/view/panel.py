"""The viewer's Dear ImGui panel (imgui-bundle, drawn by moderngl-window's integration): FPS and
per-stage milliseconds as bars, the sky volume's stale layers, the temporal anti-aliasing's samples
and whether the view has converged,
the camera, the sun (time of day, date, place), the technique switches, quality and exposure, the
view switch, saving and the reference comparison. Every widget changes state through
``Viewer.set_value`` — the same path a script's ``set`` takes."""

from __future__ import annotations

import moderngl

from serenity.config import QUALITY_PRESETS
from serenity.errors import SerenityError
from serenity.optional import require
from serenity.view.controls import SHADOW_FILTERS, VIEWS

_STALE = (0.95, 0.45, 0.2, 1.0)
_FRESH = (0.3, 0.8, 0.4, 1.0)


def _set(viewer, name, value) -> None:
    try:
        viewer.set_value(name, value)
    except SerenityError as e:
        viewer.messages.append(str(e))


def draw_panel(viewer, real_dt: float) -> None:
    imgui = require("imgui_bundle", "serenity view's panel").imgui
    io = imgui.get_io()
    io.delta_time = max(1e-3, float(real_dt))
    imgui.new_frame()
    _frame_window(viewer, imgui)
    _controls_window(viewer, imgui, VIEWS)
    imgui.render()
    viewer.wnd.fbo.use()
    viewer.wnd.fbo.viewport = (0, 0, *viewer.wnd.buffer_size)
    viewer.gui.render(imgui.get_draw_data())
    viewer.ctx.enable_only(moderngl.NOTHING)
    viewer.ctx.scissor = None


def _frame_window(viewer, imgui) -> None:
    """Right: FPS; the sky volume's layers, the TAA samples and convergence (first, so that a short
    window still shows them); the stages' milliseconds as bars."""
    bw = viewer.wnd.size[0]
    imgui.set_next_window_pos(imgui.ImVec2(max(8, bw - 298), 8), imgui.Cond_.first_use_ever)
    imgui.set_next_window_size(imgui.ImVec2(290, 0), imgui.Cond_.first_use_ever)
    imgui.set_next_window_bg_alpha(0.8)
    imgui.begin("Frame")
    r = viewer.renderer
    imgui.text(f"{viewer.fps:5.2f} FPS {viewer.frame_ms:8.1f} ms/frame")
    imgui.text(f"{viewer.width}x{viewer.height}, {r.device}, {viewer.settings.quality} quality")
    s = viewer.sky_stale()
    if s is None:
        imgui.text("sky volume: off")
    else:
        layers = len(s)
        imgui.text(f"sky volume ({viewer.renderer.config.sky.method}): {int(s.sum())}/{layers} layers stale")
        dl = imgui.get_window_draw_list()
        p = imgui.get_cursor_screen_pos()
        w = max(2.0, min(14.0, 260.0 / layers))
        for i in range(layers):
            col = imgui.get_color_u32(imgui.ImVec4(*(_STALE if s[i] else _FRESH)))
            dl.add_rect_filled(imgui.ImVec2(p.x + i * w, p.y), imgui.ImVec2(p.x + (i + 1) * w - 1, p.y + 8), col)
        imgui.dummy(imgui.ImVec2(layers * w, 10))
    if viewer.taa_on:
        n, total = viewer.taa_count, viewer.taa_samples
        imgui.progress_bar(min(1.0, n / total), imgui.ImVec2(-1, 13), f"TAA {n}/{total} samples")
    else:
        imgui.text("TAA: " + ("off" if not (viewer.settings.taa and viewer.taa_samples > 1) else "not in this view"))
    if viewer.converged:
        imgui.text_colored(imgui.ImVec4(*_FRESH), f"converged (still for {viewer.still_frames} frames)")
    elif viewer.still_frames:
        imgui.text_colored(imgui.ImVec4(*_STALE), f"refining: still for {viewer.still_frames} frames")
    else:
        imgui.text("moving")
    top = max([1.0] + list(viewer.ms.values()))
    for name, ms in viewer.ms.items():
        imgui.progress_bar(min(1.0, ms / top), imgui.ImVec2(-1, 13), f"{name} {ms:.1f}")
    total = sum(v for k, v in viewer.ms.items() if k != "cpu ray tracing")
    imgui.text(f"stages on the main thread: {total:.1f} ms")
    imgui.end()


def _controls_window(viewer, imgui, VIEWS) -> None:
    """Left: camera, sun, techniques, view, save and reference."""
    imgui.set_next_window_pos(imgui.ImVec2(8, 8), imgui.Cond_.first_use_ever)
    imgui.set_next_window_size(imgui.ImVec2(290, 0), imgui.Cond_.first_use_ever)
    imgui.set_next_window_bg_alpha(0.8)
    imgui.begin("Controls")
    imgui.push_item_width(-100)
    if imgui.collapsing_header("Camera"):
        pos = viewer.scene.camera.position
        imgui.text(f"at ({pos[0]:.2f}, {pos[1]:.2f}, {pos[2]:.2f}) m, yaw {viewer.fly.yaw_deg:.0f}, "
                   f"pitch {viewer.fly.pitch_deg:.0f}")
        ch, v = imgui.slider_float("speed m/s", viewer.fly.speed, 0.1, 50.0, "%.2f", imgui.SliderFlags_.logarithmic)
        if ch:
            _set(viewer, "speed", v)

    if imgui.collapsing_header("Sun", imgui.TreeNodeFlags_.default_open):
        tod = viewer.tod
        ch, v = imgui.slider_float("local time h", tod.hour, 0.0, 23.99, "%.2f")
        if ch:
            _set(viewer, "hour", v)
        ch, v = imgui.input_text("date", tod.date, imgui.InputTextFlags_.enter_returns_true)
        if ch:
            _set(viewer, "date", v)
        ch, v = imgui.slider_float("latitude", tod.latitude, -89.9, 89.9, "%.2f")
        if ch:
            _set(viewer, "latitude", v)
        sun = viewer.scene.sun
        imgui.text(f"elevation {sun.elevation_deg:.1f} deg, azimuth {sun.azimuth_deg:.1f} deg")

    if imgui.collapsing_header("Techniques", imgui.TreeNodeFlags_.default_open):
        st = viewer.settings
        ch, v = imgui.combo("quality", QUALITY_PRESETS.index(st.quality) if st.quality in QUALITY_PRESETS else 0,
                            list(QUALITY_PRESETS))
        if ch:
            _set(viewer, "quality", QUALITY_PRESETS[v])
        ch, v = imgui.combo("shadow filter", SHADOW_FILTERS.index(st.shadow_filter), list(SHADOW_FILTERS))
        if ch:
            _set(viewer, "shadow_filter", SHADOW_FILTERS[v])
        for name, label in (("ssao", "SSAO"), ("sky_lighting", "sky volume (rebuild)"),
                            ("lpv_diffuse", "LPV diffuse"), ("lpv_glossy", "LPV glossy"),
                            ("reflections", "ray-traced reflections"), ("refractions", "ray-traced refractions"),
                            ("taa", "TAA when still")):
            ch, v = imgui.checkbox(label, getattr(st, name))
            if ch:
                _set(viewer, name, v)
        ch, v = imgui.slider_float("exposure", st.exposure, 0.001, 1.0, "%.4f", imgui.SliderFlags_.logarithmic)
        if ch:
            _set(viewer, "exposure", v)

    if imgui.collapsing_header("View", imgui.TreeNodeFlags_.default_open):
        names = list(VIEWS)
        ch, v = imgui.combo("view (V)", names.index(viewer.view), names)
        if ch:
            _set(viewer, "view", names[v])
        imgui.text_wrapped(VIEWS[viewer.view] + ("" if viewer.view_available() else " — off / nothing to show"))
        if viewer.view == "reference split":
            ch, v = imgui.slider_float("split", viewer.split, 0.0, 1.0, "%.2f")
            if ch:
                _set(viewer, "split", v)
        if imgui.button("save (F12)"):
            viewer._save_requested = True
        imgui.same_line()
        if imgui.button("reference (R)"):
            viewer._reference_requested = True
        job, c = viewer.job, viewer.comparison
        if job is not None:
            imgui.progress_bar(job.progress, imgui.ImVec2(-1, 14), f"reference {job.spp} spp {job.progress * 100:.0f}%")
        if c is not None:
            imgui.text(f"vs reference ({c['spp']} spp): FLIP {c['flip']:.4f}  relMSE {c['rel_mse']:.4f}")
    for msg in viewer.messages[-3:]:
        imgui.text_wrapped(msg)
    imgui.pop_item_width()
    imgui.end()
