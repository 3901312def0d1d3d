"""A method drawn at a fraction of the output's resolution, then upsampled to it.

Game engines hold their frame rate by rendering fewer pixels when the frame would be late;
the client does the same for a tick that would miss its deadline (client/deadline.py). The
method is made for an output ``scale`` times the size (same field of view) and draws into a
target of that size; one full-screen pass stretches it to the output: colour bilinearly, a pixel
covered where most of its bilinear footprint is (alpha 0 elsewhere: a hole, no source covered
it), so the hole fraction means about what it means at full resolution. That pass costs about 3 ms of wall time at
960x540 on llvmpipe (``pibr bench levels`` counts it in every scaled level).
"""
from __future__ import annotations

from pibr.protocol.messages import OutputConfig

from .methods.base import FULLSCREEN_VS, fullscreen_quad
from .output_target import OutputTarget

_UPSAMPLE_FS = """
#version 410
uniform sampler2D u_low;
uniform vec2 u_out_size;
out vec4 f_color;
void main() {
    vec4 c = texture(u_low, gl_FragCoord.xy / u_out_size);
    // a hole stays a hole: covered where most of the bilinear footprint was (one fetch; llvmpipe
    // pays per fetch at full resolution)
    f_color = vec4(c.rgb, step(0.5, c.a));
}
"""


#: Texture unit of the low-resolution image: above the frame's and the methods' own units.
_UNIT = 15


def scaled_output(output: OutputConfig, scale: float) -> OutputConfig:
    """``output`` at ``scale`` of its width and height (at least 16 pixels each), same field of view
    (frustum, when it has one) and rate."""
    w, h = (max(16, int(round(side * scale))) for side in (output.width, output.height))
    return OutputConfig(w, h, output.fov_deg, output.rate_hz, output.frustum)


def make_level(ctx, level, output: OutputConfig, config, proxies=None, **options):
    """The method of a quality level (client/deadline.py ``Level``) for ``output``: made with the
    level's options over ``options``, at the level's scale (a :class:`ScaledRender` below 1).

    A level drawn at ``scale`` also takes its LoD target ``1 / scale`` times coarser: the target
    is an angle (client/lod_select.py), and a level with fewer pixels is meant to be cheaper in
    geometry too; at a 960-wide output this is exactly what the levels were measured with
    (``pibr bench levels``, docs/results/levels.json), when the target was in output pixels."""
    from .lod_select import DEFAULT_TARGET_PX
    from .methods import make_method, method_options

    opts = {**options, **level.options}
    if level.scale != 1.0 and "lod_target_px" in method_options(level.method):
        opts["lod_target_px"] = (opts.get("lod_target_px") or DEFAULT_TARGET_PX) / level.scale

    def make(out):
        return make_method(level.method, ctx, out, config, proxies=proxies, **opts)

    return make(output) if level.scale == 1.0 else ScaledRender(ctx, output, level.scale, make)


class ScaledRender:
    """A method made for :func:`scaled_output`, drawn there and upsampled into the bound output
    framebuffer. ``render`` takes the method's arguments; ``last_primitives`` is the method's."""

    def __init__(self, ctx, output: OutputConfig, scale: float, make_method):
        """make_method(output) -> the method, made for the smaller output."""
        self.ctx, self.output, self.scale = ctx, output, scale
        self.low_output = scaled_output(output, scale)
        self.method = make_method(self.low_output)
        self.target = OutputTarget(ctx, self.low_output.width, self.low_output.height)
        self.target.color.filter = (ctx.LINEAR, ctx.LINEAR)
        self.target.color.repeat_x = self.target.color.repeat_y = False
        self.prog = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=_UPSAMPLE_FS)
        self.prog["u_low"].value = _UNIT
        self.prog["u_out_size"].value = (float(output.width), float(output.height))
        self.vbo, self.vao = fullscreen_quad(ctx, self.prog)

    def __getattr__(self, name):   # the method's own attributes (uses_extra_view, needs_quadtree, ...)
        return getattr(self.__dict__["method"], name)

    def render(self, out_pose, frame, textures, scene_t: float = 0.0) -> None:
        output_fbo = self.ctx.fbo
        self.target.begin()
        self.method.render(out_pose, frame, textures, scene_t)
        output_fbo.use()
        self.ctx.disable(self.ctx.DEPTH_TEST)
        self.target.color.use(location=_UNIT)
        self.vao.render(self.ctx.TRIANGLE_STRIP)

    def release(self) -> None:
        self.method.release()
        for r in (self.vao, self.vbo, self.prog):
            r.release()
        self.target.release()
