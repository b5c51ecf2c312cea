"""The ray tracer's protocol (``serenity.kernels.tracers``): the three ways it runs give the same hits,
a tracer that dies or hangs is restarted once and then reported in one line, and a renderer goes on
after a frame that failed anywhere, and leaves no child process behind."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from serenity.config import RenderConfig, ScheduleConfig
from serenity.errors import SerenityError
from serenity.frame import Renderer
from serenity.kernels.raytrace import RayTracer
from serenity.kernels.tracers import InlineTracer, RestartingTracer, ThreadTracer, TracerProcess, TracerStopped
from serenity.scene import load

SIZE = (96, 54)


@pytest.fixture(scope="module")
def glass():
    return load("glass")


@pytest.fixture(scope="module")
def batches(glass):
    rng = np.random.default_rng(3)
    lo, hi = glass.bounds() if callable(getattr(glass, "bounds", None)) else (np.full(3, -2.0), np.full(3, 2.0))
    origins = rng.uniform(lo, hi, (200, 3)).astype(np.float32)
    dirs = rng.normal(size=(200, 3)).astype(np.float32)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return [(origins, dirs, np.zeros(200, np.float32), np.zeros(200, np.float32), 0, None), None]


def _same_hits(a, b) -> None:
    assert a[1] is None and b[1] is None
    assert a[0].keys() == b[0].keys()
    for k in a[0]:
        np.testing.assert_array_equal(np.asarray(a[0][k]), np.asarray(b[0][k]), err_msg=k)


def test_every_tracer_gives_the_hits_of_the_ray_tracer(glass, batches):
    want = [RayTracer(glass).trace(*batches[0][:4], transmissions=0, sun_direction=None), None]
    for make in (InlineTracer, ThreadTracer, TracerProcess):
        t = make(glass)
        try:
            results, t0, t1 = t.result(t.submit(batches), 120)
            _same_hits(results, want)
            assert t1 >= t0 and t.cpu_seconds > 0.0 and t.build_seconds is not None
            with pytest.raises(SerenityError, match="no ray batches in flight"):
                t.result(12345)
        finally:
            t.close()


def test_a_killed_tracer_process_is_restarted_once_and_the_frame_traced(glass, batches):
    t = RestartingTracer(lambda: TracerProcess(glass))
    try:
        first = t.result(t.submit(batches))[0]
        handle = t.submit(batches)
        os.kill(t.tracer._proc.pid, signal.SIGKILL)  # dies with the frame's rays in flight
        _same_hits(t.result(handle)[0], first)
        assert t.restarts == 1
        os.kill(t.tracer._proc.pid, signal.SIGKILL)  # dead before the next submit: its write fails
        t.tracer._proc.wait()
        _same_hits(t.result(t.submit(batches))[0], first)
        assert t.restarts == 2
    finally:
        t.close()


def test_a_hung_tracer_process_is_stopped_and_restarted(glass, batches):
    t = RestartingTracer(lambda: TracerProcess(glass), timeout=3.0)
    try:
        first = t.result(t.submit(batches))[0]
        old = t.tracer._proc
        handle = t.submit(batches)
        os.kill(old.pid, signal.SIGSTOP)
        _same_hits(t.result(handle)[0], first)
        assert t.restarts == 1 and old.wait(timeout=10) is not None  # the hung one was killed
    finally:
        t.close()


def test_a_tracer_that_fails_again_after_its_restart_is_one_line(glass, batches):
    class Dying:
        build_seconds = None

        def submit(self, b):
            return 1

        def result(self, handle, timeout=None):
            raise TracerStopped("the ray-tracing process stopped (EOF); exit code -9")

        def close(self):
            pass

    t = RestartingTracer(Dying)
    with pytest.raises(SerenityError, match="failed again after a restart") as e:
        t.result(t.submit(batches))
    assert "\n" not in str(e.value) and t.restarts == 1


def _traced_pixels(frame):
    return frame.hdr[frame.aovs["rt_mask"][..., 0] > 0]


def test_the_renderer_recovers_from_a_tracer_process_killed_mid_frame(glass):
    with Renderer(glass, *SIZE, config=RenderConfig(schedule=ScheduleConfig(overlap=True))) as r:
        first = r.render()
        assert first.rays > 0 and r._tracer_proc is not None
        proc = r._tracer_proc
        submit = proc.submit

        def submit_then_die(b):
            handle = submit(b)
            os.kill(proc._proc.pid, signal.SIGKILL)
            return handle

        proc.submit = submit_then_die
        second = r.render()
        assert r._tracing.restarts == 1 and r._tracer_proc is not proc and r._tracer_proc.alive
        np.testing.assert_allclose(_traced_pixels(second), _traced_pixels(first), rtol=1e-3, atol=1e-4)


@pytest.mark.parametrize("overlap", [True, False])
def test_the_renderer_renders_after_a_stage_raised(glass, monkeypatch, overlap):
    """An exception in a stage after sync 1 (the tracer has the frame's rays) reaches the caller; the
    next frame renders as any other."""
    with Renderer(glass, *SIZE, config=RenderConfig(schedule=ScheduleConfig(overlap=overlap))) as r:
        first = r.render()
        real = r.shadow_pass.render
        calls = {"n": 0}

        def fails_once(*a, **k):
            calls["n"] += 1
            if calls["n"] == 1:
                raise RuntimeError("injected")
            return real(*a, **k)

        monkeypatch.setattr(r.shadow_pass, "render", fails_once)
        with pytest.raises(RuntimeError, match="injected"):
            r.render()
        again = r.render()
        assert again.rays == first.rays
        np.testing.assert_allclose(_traced_pixels(again), _traced_pixels(first), rtol=1e-3, atol=1e-4)


def test_with_renderer_leaves_no_child_process(glass):
    with Renderer(glass, *SIZE, config=RenderConfig(schedule=ScheduleConfig(overlap=True))) as r:
        r.render(read_back=False)
        child = r._tracer_proc._proc
        assert child.poll() is None
    assert child.poll() is not None and r._tracing is None

