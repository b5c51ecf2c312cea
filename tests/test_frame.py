"""The frame pipeline (serenity/frame/): its stage names, determinism, memory over frames, and
the two schedules (ray tracing in a process beside the GL work, or inline) agreeing."""

from __future__ import annotations

import copy
import dataclasses
import os
import threading

import numpy as np
import pytest

from serenity.bench import camera_path, rss_mb, sun_path
from serenity.config import RenderConfig, ScheduleConfig
from serenity.errors import ConfigError, SerenityError
from serenity.frame import LPV_UPDATE_STAGES, SKY_UPDATE_STAGES, STAGES, Renderer
from serenity.scene import load

pytestmark = pytest.mark.gl
SIZE = (96, 54)


@pytest.fixture(scope="module")
def courtyard():
    return load("courtyard")


def _in_stage_order(keys) -> bool:
    idx = [STAGES.index(k) for k in keys]
    return idx == sorted(idx)


def test_timing_keys_are_the_stages_in_order(courtyard):
    """Every timed stage of a first frame and of a frame with a moved camera and sun is one of
    STAGES (listed in STAGES order), and the LPV update is timed in its named parts."""
    scene = copy.deepcopy(courtyard)
    r = Renderer(scene, *SIZE, config=RenderConfig(schedule=ScheduleConfig(overlap=False)))
    try:
        first = r.render(read_back=False)
        assert set(first.timings) <= set(STAGES) and _in_stage_order(first.timings)
        scene.camera = camera_path(courtyard.camera, 0.3)
        scene.sun.direction = sun_path(courtyard.sun.direction, 0.3)
        second = r.render(read_back=False)
        assert set(second.timings) <= set(STAGES) and _in_stage_order(second.timings)
        assert set(LPV_UPDATE_STAGES) <= set(second.timings)
        assert set(SKY_UPDATE_STAGES) <= set(second.timings)
    finally:
        r.close()


def test_unchanged_scene_renders_identically_and_skips_work(courtyard):
    """Two renders of an unchanged scene give the same image bit for bit, and the second redoes
    no volume update (nothing moved)."""
    r = Renderer(copy.deepcopy(courtyard), *SIZE, config=RenderConfig(schedule=ScheduleConfig(overlap=False)))
    try:
        r.render(read_back={"hdr"})
        a = r.render(read_back={"hdr"})
        b = r.render(read_back={"hdr"})
        assert np.array_equal(a.hdr, b.hdr)
        assert not set(LPV_UPDATE_STAGES) & set(b.timings)
        assert "sky upload" not in b.timings
    finally:
        r.close()


def test_amortised_volumes_catch_up_once_things_stand_still(courtyard):
    """``lpv-fast``'s sky layer cycle and LPV stagger: after frames with the camera and sun moving, a
    still scene keeps updating (one sky layer, one LPV cascade per frame; the LPV again after the sky
    volume's last layer, since its sky-light VPLs read that volume) only until every layer and
    cascade holds the newest inputs and shows them (``LPVConfig.temporal_blend``), then skips the
    volume work; its image is then the one a renderer
    that updates everything every frame draws of the same still scene (the same volumes, up to float
    summation order)."""
    import dataclasses

    from serenity.kernels.lpv.volume import blend_updates

    # the volumes, not the image history
    fast = RenderConfig.preset("lpv-fast", indirect={"history": 1.0}, schedule=ScheduleConfig(overlap=False))
    every = dataclasses.replace(fast, sky=dataclasses.replace(fast.sky, transfer_layers=0),
                                lpv=dataclasses.replace(fast.lpv, stagger=False, temporal_blend=1.0))
    scenes = [copy.deepcopy(courtyard), copy.deepcopy(courtyard)]
    rs = [Renderer(s, *SIZE, config=c) for s, c in zip(scenes, (fast, every), strict=True)]
    try:
        for i in range(4):  # moving
            for s in scenes:
                s.camera = camera_path(courtyard.camera, 0.1 * i)
                s.sun.direction = sun_path(courtyard.sun.direction, 0.1 * i)
            for r in rs:
                r.render(read_back=False)
        amortised = rs[0]
        # lpv-fast's cascades are sized to the image (ShadowConfig.texels_per_pixel)
        assert amortised.shadow_pass.size == fast.shadow.size_for(*SIZE) < fast.shadow.size
        assert amortised.lpv.pending_levels > 0 and amortised.sky_volume.pending_layers > 0
        layers, cascades = amortised.sky_volume.resolution[1], len(amortised.lpv.fitted)
        catch_up = 0
        while amortised.lpv.pending_levels or amortised.sky_volume.pending_layers:
            f = amortised.render(read_back=False)
            catch_up += 1
            # the LPV's sky-light VPLs read the sky volume; its last update's light is then blended in
            assert catch_up <= layers + cascades + blend_updates(fast.lpv.temporal_blend)
        still = amortised.render(read_back={"hdr"})
        assert not set(LPV_UPDATE_STAGES) & set(still.timings) and "sky upload" not in still.timings
        for _ in range(2 * fast.shadow.cascades):  # its staggered shadow tiles caught up and faded in
            rs[1].render(read_back=False)
        ref = rs[1].render(read_back={"hdr"})
        np.testing.assert_allclose(still.hdr, ref.hdr, rtol=1e-4, atol=1e-4 * float(ref.hdr.max()))
        assert f is not None
    finally:
        for r in rs:
            r.close()


def test_memory_does_not_grow_over_frames(courtyard):
    """RSS after 30 frames of a moving camera and sun within 25 MiB of RSS after 10 (allocator
    noise; a leak of one 96x54 float image per frame would add ~2.4 MiB per 10 frames, a leak of
    the LPV or the sky volume far more)."""
    scene = copy.deepcopy(courtyard)
    r = Renderer(scene, *SIZE, config=RenderConfig(schedule=ScheduleConfig(overlap=False)))
    rss = []
    try:
        for i in range(30):
            scene.camera = camera_path(courtyard.camera, i / 29)
            scene.sun.direction = sun_path(courtyard.sun.direction, i / 29)
            r.render(read_back={"hdr"})
            rss.append(rss_mb())
    finally:
        r.close()
    assert rss[-1] - rss[9] < 25.0, rss


@pytest.mark.parametrize("scene_name", ["courtyard", "glass"])
def test_overlapped_and_serial_schedules_agree(scene_name, device):
    """The overlapped tracer (its own process on the CPU, a worker thread on CUDA) and the inline
    tracer (serial) give the same image: the same kernels on the same rays, so equal to float noise
    (max |diff| <= 1e-4 of the image's peak)."""
    images = []
    for overlap in (True, False):
        r = Renderer(load(scene_name), *SIZE, device=device,
                     config=RenderConfig(schedule=ScheduleConfig(overlap=overlap)))
        try:
            f = r.render(read_back={"hdr"})
            assert f.rays > 0
            assert "cpu ray tracing" in f.timings
            # the frame's CPU time counts every thread, and the tracer process's work when it has one
            assert f.cpu_ms > 0.0
            if overlap and device == "cpu":
                assert r._tracer_proc is not None and r._tracer_proc.cpu_seconds > 0.0
            if device == "cpu":  # the tracer's own CPU time, inline or in its process
                assert f.tracer_cpu_ms is not None and 0.0 < f.tracer_cpu_ms <= f.cpu_ms
            images.append(f.hdr)
        finally:
            r.close()
    a, b = images
    assert np.abs(a - b).max() <= 1e-4 * a.max()


@pytest.mark.skipif(not hasattr(os, "getpriority"), reason="POSIX priorities")
@pytest.mark.parametrize("nice", [0, 7])
def test_tracer_process_runs_at_the_configured_niceness(nice):
    """``ScheduleConfig.tracer_nice`` is the tracer process's niceness above this process's own, and
    its frames trace as at any other."""
    r = Renderer(load("glass"), *SIZE, config=RenderConfig(schedule=ScheduleConfig(tracer_nice=nice)))
    try:
        f = r.render(read_back=False)
        assert f.rays > 0 and f.tracer_cpu_ms > 0.0
        own = os.getpriority(os.PRIO_PROCESS, 0)
        assert r.tracer_niceness == min(19, own + nice) - own
    finally:
        r.close()



@pytest.mark.skipif(not hasattr(os, "getsid"), reason="POSIX sessions")
def test_tracer_process_in_a_session_of_its_own():
    """``ScheduleConfig.tracer_session`` starts the tracer process as the leader of a new session (and so,
    where Linux has autogroups enabled, in a scheduling group of its own); it traces the frame the
    tracer in the renderer's session traces, bit for bit."""
    images, groups, owns = [], [], []
    for session in (False, True):
        r = Renderer(load("glass"), *SIZE, config=RenderConfig(schedule=ScheduleConfig(tracer_session=session)))
        try:
            f = r.render(read_back={"hdr"})
            assert f.rays > 0 and f.tracer_cpu_ms > 0.0
            pid = r._tracer_proc._proc.pid
            assert (os.getsid(pid) == pid) == session and (os.getsid(pid) == os.getsid(0)) != session
            group = r._tracer_proc.scheduling_group  # None without autogroups, or in a CPU cgroup (CI)
            assert group is None or group.startswith("/autogroup-")
            groups.append(group)
            owns.append(r._tracer_proc.own_group)
            images.append(f.hdr)
        finally:
            r.close()
    assert np.array_equal(images[0], images[1])
    if None not in groups:  # the session child's autogroup is not the one the renderer's session shares
        assert groups[0].split()[0] != groups[1].split()[0]
        assert owns == [False, True]
    else:  # no autogroups here (or a CPU cgroup): the session changes nothing the scheduler sees
        assert owns == [False, False]


@pytest.mark.skipif(not hasattr(os, "getsid"), reason="POSIX sessions")
@pytest.mark.parametrize("quality", ["lpv-fast", "traced-probes"])
def test_tracer_session_by_default_where_a_volume_worker_waits(quality):
    """``tracer_session=None`` (the default) starts the tracer process in a session of its own where
    the frame has a volume worker (``lpv-fast``), and in the renderer's where it has none (``traced-probes``:
    the gathered sky volume's work on the main thread would lose cores to it)."""
    r = Renderer(load("glass"), *SIZE, config=RenderConfig.preset(quality))
    try:
        r.render()
        pid = r._tracer_proc._proc.pid
        assert (r._volume_pool is not None) == (quality == "lpv-fast")
        assert (os.getsid(pid) == pid) == (quality == "lpv-fast")
    finally:
        r.close()


def test_a_with_block_closes_the_renderer_even_when_it_raises():
    """``with Renderer(...) as r:`` stops the tracer process and the worker threads on the way out,
    also when the block raises (and lets the exception through)."""
    with pytest.raises(RuntimeError, match="in the block"):
        with Renderer(load("glass"), *SIZE, config=RenderConfig.preset("lpv-fast")) as r:
            r.render(read_back=False)
            proc, pool = r._tracer_proc, r._volume_pool
            assert proc is not None and proc._proc.poll() is None and pool is not None
            raise RuntimeError("in the block")
    assert r._tracer_proc is None
    assert proc._proc.poll() is not None  # the tracer process has exited
    with pytest.raises(RuntimeError, match="shutdown"):  # the volume worker is stopped
        pool.submit(int)
    r.close()  # closing again is harmless


def test_scheduling_group_is_none_where_the_kernel_names_none(monkeypatch, tmp_path):
    """``/proc/PID/autogroup`` reads empty for a process in a cgroup with a CPU controller of its own
    (CI runners, containers) and is absent without autogroup support: both are "no group", not ""."""
    import types

    from serenity.kernels import tracer_process

    proc = types.SimpleNamespace(_proc=types.SimpleNamespace(pid=os.getpid()))
    for text, expected in (("/autogroup-7 nice 0\n", "/autogroup-7 nice 0"), ("", None), (None, None)):
        path = tmp_path / "autogroup"
        path.unlink(missing_ok=True)
        if text is not None:
            path.write_text(text)
        monkeypatch.setattr(tracer_process, "open", lambda _name, p=path: open(p), raising=False)
        assert tracer_process.TracerProcess.scheduling_group.fget(proc) == expected


@pytest.mark.skipif(not hasattr(os, "getpriority"), reason="POSIX priorities")
def test_volume_worker_runs_at_the_configured_niceness(courtyard):
    """``ScheduleConfig.volume_nice`` lowers the volume worker's thread only: the worker's niceness is
    the process's plus it, the calling thread's is unchanged, and the frames are those of a worker
    at the frame's priority."""
    own = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    images = []
    for nice in (0, 6):
        cfg = RenderConfig.preset("lpv-fast", schedule=ScheduleConfig(volume_nice=nice))
        r = Renderer(courtyard, *SIZE, config=cfg)
        try:
            assert r._volume_pool is not None
            worker = r._volume_pool.submit(lambda: os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))
            assert worker.result() == min(19, own + nice)
            images.append(r.render().hdr)
        finally:
            r.close()
        assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == own
    assert np.array_equal(images[0], images[1])

def test_sync_modes_give_the_same_frames(courtyard):
    """``sync_stages`` only decides when the frame waits for GL: "each", "cpu" and "none" render the
    same images, frame after frame (the first frame builds the volumes, the next ones move the sun
    and camera, so the volume stages run with GL work queued or not), and the same stages in order."""
    images = {}
    for mode in ("each", "cpu", "none"):
        scene = copy.deepcopy(courtyard)
        base_cam, base_sun = scene.camera, scene.sun.direction.copy()
        r = Renderer(scene, *SIZE, config=RenderConfig.preset("lpv-fast", schedule=ScheduleConfig(sync_stages=mode)))
        try:
            frames = []
            for i in range(3):
                scene.camera = camera_path(base_cam, i / 4)
                scene.sun.direction = sun_path(base_sun, i / 4)
                f = r.render(read_back=("hdr",))
                assert _in_stage_order(f.timings)
                frames.append(f.hdr)
        finally:
            r.close()
        images[mode] = frames
    for mode in ("cpu", "none"):
        for a, b in zip(images["each"], images[mode], strict=True):
            assert np.array_equal(a, b), mode
    assert ScheduleConfig(sync_stages=True).sync_stages == "each"
    assert ScheduleConfig(sync_stages=False).sync_stages == "none"
    with pytest.raises(ConfigError, match="sync_stages"):
        ScheduleConfig(sync_stages="sometimes")


def test_volume_worker_gives_the_serial_frames(courtyard):
    """The volume worker (``overlap_volumes``: the sky volume's update and the LPV's kernels in a
    thread beside the GL passes) renders what the main thread renders doing them in turn, frame
    after frame while the sun and camera move (the sky map rebaked, one transfer layer per frame,
    the staggered LPV's cascades re-injected), and then with nothing moving, until the sky volume's
    sweep and the LPV have caught up and the LPV is left alone. Only the ray tracing's schedule is
    the same in both (in the tracer process)."""
    runs = {}
    for worker in (True, False):
        scene = copy.deepcopy(courtyard)
        base_cam, base_sun = scene.camera, scene.sun.direction.copy()
        cfg = RenderConfig.preset("lpv-fast", schedule=ScheduleConfig(overlap_volumes=worker))
        r = Renderer(scene, *SIZE, config=cfg)
        try:
            assert (r._volume_pool is not None) == worker
            frames, lanes, stages = [], set(), []
            for i in range(12):
                if i < 4:
                    scene.camera = camera_path(base_cam, i / 4)
                    scene.sun.direction = sun_path(base_sun, i / 4)
                f = r.render(read_back=("hdr",))
                frames.append(f.hdr)
                lanes |= {lane for lane, *_ in f.events}
                stages.append(set(f.timings))
        finally:
            r.close()
        runs[worker] = frames, lanes, stages
    for a, b in zip(runs[True][0], runs[False][0], strict=True):
        assert np.array_equal(a, b)
    from serenity.frame import VOLUME_LANE
    assert VOLUME_LANE in runs[True][1] and VOLUME_LANE not in runs[False][1]
    for stages in (runs[True][2], runs[False][2]):
        assert "lpv propagate" in stages[1] and "sky volume update" in stages[1]
        assert "lpv propagate" in stages[4] or "lpv propagate" in stages[5]  # the sweep goes on: sky VPLs
        assert "lpv propagate" not in stages[11]  # nothing changed


def test_tracer_start_moves_sync_1_only(courtyard):
    """``ScheduleConfig.tracer_start = "idle"`` reads the ray-casting buffer back and hands the rays to
    the tracer process just before the main thread waits for the volume worker, in a frame where it
    will wait, and right after the G-buffer in a frame with no volume work; "g-buffer" always right
    after it. Only the schedule moves: both render the same frames, bit for bit, while the sun and
    camera move and after they stop."""
    def start(f, name):
        return next(e[2] for e in f.events if e[1] == name)

    def busy(f):  # whether the frame changed a volume
        return bool(set(f.timings) & {"sky upload", *LPV_UPDATE_STAGES})

    runs = {}
    for where in ("g-buffer", "idle"):
        scene = copy.deepcopy(courtyard)
        base_cam, base_sun = scene.camera, scene.sun.direction.copy()
        r = Renderer(scene, *SIZE, config=RenderConfig.preset("lpv-fast", schedule=ScheduleConfig(tracer_start=where)))
        try:
            assert r._volume_pool is not None
            frames = []
            for i in range(80):  # the LPV's light is blended in for blend_updates(temporal_blend) frames
                if i < 3:
                    scene.camera = camera_path(base_cam, i / 4)
                    scene.sun.direction = sun_path(base_sun, i / 4)
                f = r.render(read_back=("hdr",))
                frames.append(f)
                if i >= 4 and not any(busy(g) for g in frames[-2:]):
                    break  # the volumes caught up a frame ago: nothing for the worker now
        finally:
            r.close()
        runs[where] = frames
    early, late = runs["g-buffer"], runs["idle"]
    assert len(early) == len(late) < 80
    for a, b in zip(early, late, strict=True):
        assert a.rays > 0 and np.array_equal(a.hdr, b.hdr)
    for f in early[1:3]:  # moving: the tracer starts before the main view's passes
        assert start(f, "ray casting buffer") < start(f, "shadow maps (CSM)")
    for f in late[1:3]:  # after them, where the main thread is about to wait for the worker
        assert start(f, "ssao") < start(f, "ray casting buffer") < start(f, "wait for volumes")
    for f in (early[-1], late[-1]):  # nothing for the worker: right after the G-buffer either way
        assert start(f, "ray casting buffer") < start(f, "shadow maps (CSM)")
    with pytest.raises(ConfigError, match="tracer_start"):
        ScheduleConfig(tracer_start="later")


@pytest.mark.parametrize("own_group", [True, False])
def test_tracer_start_auto_follows_the_tracers_scheduling_group(courtyard, monkeypatch, own_group):
    """``tracer_start = "auto"`` (the default) starts the tracer at the main thread's idle point once the
    tracer process is known to run in a scheduling group of its own, and right after the G-buffer
    where it shares the renderer's (nice 19 there: a later start would only delay it)."""
    from serenity.kernels.tracer_process import TracerProcess

    monkeypatch.setattr(TracerProcess, "own_group", property(lambda self: own_group))
    assert ScheduleConfig().tracer_start == "auto" and ScheduleConfig().tracer_session is None
    scene = copy.deepcopy(courtyard)
    base_cam, base_sun = scene.camera, scene.sun.direction.copy()
    r = Renderer(scene, *SIZE, config=RenderConfig.preset("lpv-fast"))
    try:
        frames = []
        for i in range(3):
            scene.camera = camera_path(base_cam, i / 4)
            scene.sun.direction = sun_path(base_sun, i / 4)
            frames.append(r.render())
    finally:
        r.close()
    for f in frames[1:]:  # the tracer process exists from the first frame on; the volumes are moving
        order = {e[1]: e[2] for e in f.events}
        assert (order["ssao"] < order["ray casting buffer"]) == own_group
        assert order["ray casting buffer"] < order["wait for volumes"]


def test_reconfigure_changes_live_settings_and_names_the_others(courtyard):
    """``Renderer.reconfigure`` applies what every frame reads (the next frame shows it) and refuses,
    in one line naming them, the settings built into the renderer."""
    base = RenderConfig.preset("lpv-fast")
    with Renderer(courtyard, *SIZE, config=base) as r:
        before = r.render(read_back={"ldr"}).ldr
        r.reconfigure(dataclasses.replace(base, exposure=base.exposure * 4))
        after = r.render(read_back={"ldr"}).ldr
        assert after.mean() > before.mean() + 5
        with pytest.raises(SerenityError, match=r"^shadow\.size, lpv\.rsm_size cannot change") as e:
            r.reconfigure(dataclasses.replace(base, lpv=dataclasses.replace(base.lpv, rsm_size=base.lpv.rsm_size * 2),
                                              shadow=dataclasses.replace(base.shadow, size=base.shadow.size * 2)))
        assert "\n" not in str(e.value) and r.config.exposure == base.exposure * 4
    assert Renderer.needs_rebuild(base, dataclasses.replace(base, indirect=dataclasses.replace(base.indirect, scale=1)))
    assert not Renderer.needs_rebuild(base, dataclasses.replace(base, lpv=dataclasses.replace(base.lpv, glossy=False)))


def test_serial_renderer_builds_one_kd_tree(monkeypatch):
    """A serial renderer of the traced probes (the default preset) over a scene with mirrors traces the
    frame's rays and the probes' rays with one RayTracer: one kd-tree, one copy of the textures."""
    from serenity.kernels.raytrace import RayTracer

    built = []
    init = RayTracer.__init__
    monkeypatch.setattr(RayTracer, "__init__", lambda self, *a, **k: (built.append(self), init(self, *a, **k))[1])
    serial = RenderConfig.preset("traced-probes", schedule=ScheduleConfig(overlap=False))
    with Renderer(load("glass"), *SIZE, config=serial) as r:
        frame = r.render()
        assert r.sky_volume.method.probes is not None and r.tracer is not None  # both traced
        assert len(built) == 1 and r.tracer is built[0] and r.sky_volume.ray_tracer() is built[0]
        assert np.isfinite(frame.hdr).all()
