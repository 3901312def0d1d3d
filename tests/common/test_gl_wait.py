"""common/gl.py's wait_idle: the GL work done when it returns, and the GIL free while it waits."""
import threading

import numpy as np
import pytest

pytestmark = pytest.mark.gl

#: A fragment shader slow on a software rasteriser: a long dependent chain per pixel.
_SLOW_FS = """
#version 330
out vec4 c;
void main() {
    float x = 0.0;
    for (int i = 0; i < 300; i++) x += sin(x + gl_FragCoord.x * float(i));
    c = vec4(fract(x), 0.5, 0.25, 1.0);
}
"""


def _slow_draw(ctx, size=(512, 512)):
    fbo = ctx.simple_framebuffer(size)
    fbo.use()
    prog = ctx.program(vertex_shader="#version 330\nin vec2 p;\nvoid main() { gl_Position = vec4(p, 0.0, 1.0); }",
                       fragment_shader=_SLOW_FS)
    vbo = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], "f4").tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "2f", "p")])
    return fbo, vao


def test_after_wait_idle_the_drawing_is_done_and_reads_back():
    from pibr.common.gl import create_context, wait_idle

    ctx = create_context()
    try:
        fbo = ctx.simple_framebuffer((16, 8))
        fbo.use()
        fbo.clear(0.25, 0.5, 0.75, 1.0)
        wait_idle(ctx)
        rgb = np.frombuffer(fbo.read(), np.uint8).reshape(8, 16, 3)
        assert np.array_equal(np.unique(rgb.reshape(-1, 3), axis=0), [[64, 128, 191]])
        fbo2, vao = _slow_draw(ctx, (32, 32))
        vao.render()
        wait_idle(ctx)
        assert np.all(np.frombuffer(fbo2.read(), np.uint8).reshape(32, 32, 3)[:, :, 2] == 64)
    finally:
        ctx.release()


def test_other_threads_run_while_wait_idle_waits_and_not_while_finish_does():
    """moderngl holds the GIL in finish(): a thread spinning meanwhile runs only until finish() takes
    the GIL back (a switch interval). wait_idle waits through ctypes, which releases it: the same
    thread runs all along the draw, many times longer."""
    import sys
    import time

    from pibr.common.gl import create_context, wait_idle

    ctx = create_context()
    try:
        fbo, vao = _slow_draw(ctx)
        vao.render()
        wait_idle(ctx)          # shaders compiled, caches warm
        seen, took = {}, {}
        for name, wait in (("finish", ctx.finish), ("wait_idle", lambda: wait_idle(ctx))):
            inside, stop, count = threading.Event(), threading.Event(), [0]

            def spin():
                while not stop.is_set():
                    if inside.is_set():
                        count[0] += 1

            spinner = threading.Thread(target=spin)
            spinner.start()
            try:
                t0 = time.perf_counter()
                vao.render()
                inside.set()
                wait()
                inside.clear()
                took[name] = time.perf_counter() - t0
            finally:
                stop.set()
                spinner.join()
            seen[name] = count[0]
        assert took["finish"] > 10 * sys.getswitchinterval()   # the draw outlasts a switch interval
        assert seen["wait_idle"] > 5 * seen["finish"], (seen, took)
    finally:
        ctx.release()


def test_a_library_whose_calls_do_not_reach_the_context_is_not_used(monkeypatch):
    """The entry points are taken only from a library whose glGetString names the context's
    renderer (a libGL without dispatch to an EGL context would wait on no context at all);
    where none does, wait_idle is ctx.finish()."""
    import pibr.common.gl as gl

    monkeypatch.setattr(gl, "_sync_functions", gl._NOT_LOADED)

    class Elsewhere:
        info = {"GL_RENDERER": "a renderer no library here reaches"}
        finished = 0

        def finish(self):
            self.finished += 1

    ctx = Elsewhere()
    gl.wait_idle(ctx)          # no context is current on this thread: glGetString gives nothing
    gl.wait_idle(ctx)
    assert ctx.finished == 2 and gl._sync_functions is None   # looked up once, found nothing
