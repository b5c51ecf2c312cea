"""llvmpipe's rasteriser threads yield to the CPU tracer (``serenity.threads.yield_gl_threads``)."""

import os
import sys

import pytest

from serenity.raster.context import is_software
from serenity.threads import GL_THREAD_NICE, yield_gl_threads


def _llvmpipe_threads() -> list[int]:
    out = []
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                if f.read().startswith("llvmpipe"):
                    out.append(int(tid))
        except OSError:
            continue
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice values are Linux's")
def test_gl_threads_get_the_tracer_nice_value_and_the_main_thread_keeps_its_own(gl_ctx):
    if not is_software(gl_ctx):
        pytest.skip("hardware GL: no llvmpipe threads")
    fbo = gl_ctx.simple_framebuffer((64, 64))
    fbo.use()
    gl_ctx.clear(1.0, 0.0, 0.0)
    gl_ctx.finish()  # the rasteriser threads exist once something was drawn
    threads = _llvmpipe_threads()
    assert threads, "llvmpipe without rasteriser threads"
    main_nice = os.getpriority(os.PRIO_PROCESS, 0)
    yield_gl_threads()
    assert all(os.getpriority(os.PRIO_PROCESS, t) >= GL_THREAD_NICE for t in threads)
    assert os.getpriority(os.PRIO_PROCESS, 0) == main_nice
    assert yield_gl_threads() == 0  # already there: nothing to change
    fbo.release()
