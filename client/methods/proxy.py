"""``proxy``: proxy-guided image-based rendering (Reinert et al. 2016).

The scene's level-of-detail proxy is drawn at the *current* pose. Per fragment, with
f_p and f_e its distances to the primary and extra cameras and d_p, d_e the distances
those views stored where it back-projects, e = |(d - f) / f|:

* e_p < tau: the primary view saw this very surface point: take its colour;
* else, unless the primary saw past the fragment (its point is empty space, carved), if
  e_e < tau the extra view saw it: take the extra view's colour;
* else the proxy is not where the true surface is (an encaging proxy bulges past the
  silhouette, or the surface was hidden in both views). The fragment is not discarded but
  *deprioritised*: written behind every accepted fragment (depth mapped to [0.5, 1) instead
  of [0, 0.5)) and coloured from the view with the lower error. Silhouettes stay carved —
  any accepted fragment behind wins — and holes are inpainted at no extra cost. Its alpha
  is 0, so the client counts the pixel as one no view covered.

Where the primary view shows sky the fragment is dropped so the sky behind shows. Pixels no
proxy fragment reached take the primary view along their ray: the sky, or a rotation-only
fallback (alpha 0).

Moving objects. The proxy of a moving object is drawn where it is at the display time, as
``motion`` (client/object_motion.py) extrapolates it from the transforms the frames carried
(second order, ``accel``, by default), and looked up in the views where the frame's own transforms put it
when they were rendered. With ``motion="flow"`` (Pajak et al.'s way, per pixel) the moving
objects' proxies are not drawn: the primary view is extrapolated along its motion flow to the
display time (client/flow_warp.py; the static proxies see the background it made up where the
objects were), and every pixel a moving pixel landed on is drawn as a point at its distance,
accepted from the primary view like a confirmed proxy fragment, so the depth test sorts it
among the static proxies. A frame whose view shows nothing moving places the moving objects'
proxies as ``static`` does.

Shading is deferred: the proxy passes store, per pixel, which view and where to sample; one
full-screen pass then fetches each pixel's colour once, from that view only. Nothing writes
gl_FragDepth (on a software rasteriser that rules out early depth tests, so every overlapping
fragment would run the shader): the proxies are drawn twice, accepted fragments first into
the front half of the depth range, then the rest into the back half, where only pixels with
no accepted fragment still pass. Measured here (room, 960x540, CPU ms in one run): 140 against
178 for one pass writing gl_FragDepth and resolving with a lookup per view; the images agree
to 2/255 on 0.05 % of pixels (the records' uv precision), bit for bit with float32 records of
uv, view and alpha.

What llvmpipe (Mesa 22.3) charges for, and how the passes avoid it: it runs both sides of every
branch, even a uniform one, so each pass has a program of its own and the background's
lookups run in a pass of their own (shaders.BACKGROUND_FS), after pass 1, on the pixels where it
accepted nothing, which the depth test picks before the shader runs; the resolve then does one
lookup. Rasterising costs per covered pixel even where every fragment fails the depth test
(a pass over all proxies with no fragment shaded: about 0.8x the floor of ``pibr bench ibr``),
so pass 2 is scissored to the box around those pixels and skipped where there are none.
``carve_all`` keeps the previous passes (one program for both, pass 2 over every pixel, the
background in the resolve): the images are equal bit for bit (tests), at 0.76-0.78x its CPU
at 960x540 and 0.65-0.68x at 1280x720 (bench/proxy_speed.py, two runs; in the first 140
against 180 CPU-ms, 5.2x against 6.7x the floor; 222 against 341, 3.6x against 5.5x). The
background pass writes its pixels' records in the proxy passes' format, so every record is 8
bytes (RG32F; it had written 16 for its uv in full precision): 0.87x the CPU at 960x540 and
0.86x at 1280x720 in one interleaved run, the images within 2/255 on 0.004 % of pixels (the
records' uv precision; carve_all rounds its background through a record, so the two still agree
bit for bit). Tried and slower here: first testing each pixel's nearest fragment
(a trivial-shader pass, then a full-screen test) and carving only where it fails: the two
extra full-screen and geometry passes cost more than the shading they save; scissoring the
carving passes per cell of a grid: every extra draw of an object repeats its vertex work.

Back faces: a mesh that is closed and wound outward, seen from outside (and beyond the near
plane's reach), is drawn without its back faces (client/back_faces.py). They lie behind the
same mesh's front faces, so with ``carve=False`` the image is equal bit for bit; while carving,
a back face the views confirm behind an unconfirmed front face no longer wins the pixel (the
surface behind, or the fallback pass, fills it instead), so moving objects, placed by
extrapolation, keep theirs (see _draws). Where a back face was drawn before
the front face hiding it, it ran the accepting pass's shader: culling saves that and its
rasterisation (``cull=False`` keeps every face, the reference).

``carve=False`` (``--no-carve``) tests only each pixel's nearest proxy fragment, in the resolve,
after one pass with a trivial shader: 86 CPU-ms in the same run, but an unconfirmed proxy
fragment then hides the surface behind it (see shaders.NEAREST_VS).
"""
from __future__ import annotations

import numpy as np

from pibr.common.gl import wait_idle
from pibr.protocol.messages import PayloadKind
from pibr.protocol.object_poses import decode_object_poses
from pibr.protocol.pose import Pose

from ..back_faces import BackFaceTest
from ..frame_textures import bind_frame_uniforms, frame_glsl, has_extra_depth, rect_uniform
from ..lod_select import DEFAULT_TARGET_PX, LodSelector
from ..object_motion import DEFAULT_HORIZON_FRAMES, DEFAULT_MOTION, ObjectPlacer, PoseHistory
from . import proxy_shaders as shaders
from .base import FULLSCREEN_VS, Method, fullscreen_quad, output_tan_centre, output_tan_half
from .view_warp import mat4_bytes, output_projection

DEFAULT_TAU = 0.1
def _front_to_back(sel) -> tuple:
    """Sort key: nearest object first, and those whose box holds the camera (the walls of the room
    it stands in, usually behind everything else) last."""
    return (sel.distance == 0.0, sel.distance)


class ProxyIBR(Method):
    """Proxy IBR; ``carve`` (default) tests every proxy fragment and lets the nearest accepted one
    win, ``carve=False`` tests only the nearest (one cheaper pass, see shaders.NEAREST_VS).

    ``motion``: how moving objects are placed at the display time (object_motion.MOTION_MODES);
    ``poses``: the session's :class:`PoseHistory`, filled with every frame received (without
    one the method keeps its own from the frames it is given); ``oracle_pose(index, t)``: the
    scene's animation, for ``motion="oracle"`` in benchmarks only."""

    name = "proxy"
    needs_proxies = True

    def __init__(self, ctx, output, config, proxies=None, tau: float = DEFAULT_TAU,
                 lod_target_px: float = DEFAULT_TARGET_PX, lod_level: str | None = None, extra_view: bool = True,
                 carve: bool = True, motion: str = DEFAULT_MOTION, poses: PoseHistory | None = None,
                 oracle_pose=None, horizon_frames: float = DEFAULT_HORIZON_FRAMES, slack_codes: float | None = None,
                 carve_all: bool = False, cull: bool = True, inpaint: bool = True, pair_at_once: bool = False):
        """slack_codes: depth codes of transport error forgiven before the tau test (None: the
        depth codec's ``DEPTH_SLACK_CODES``); ``carve_all``: carve as before, both passes over
        every pixel with one program and the background found in the resolve (the same image,
        slower: the reference the tests and ``bench/proxy_speed.py`` compare with). A context
        older than GL 4.3 (no storage-buffer atomics for the background pass's count) carves
        as carve_all does. ``cull``: skip the back faces of closed, outward-wound meshes the
        camera is outside of (see _draws); False draws every face, the reference.
        ``inpaint`` (carving): where no view confirms any proxy fragment, show the nearest one
        coloured from the view with the lower error (Reinert et al.'s inpainting: the second
        carving pass); False: the background along the pixel's ray instead, as where no proxy
        was drawn (the sky, or the rotation-only fallback of the primary view, alpha 0), one
        geometry pass fewer (room, 7 evaluation windows: DSSIM +0.0004, 0.80x the wall time).
        ``pair_at_once``: a stereo pair from one frame is drawn in one pass (:meth:`render_pair`);
        off, each eye alone. On this software rasteriser a view costs its fragments, which a pair
        has twice of: at once cost 1.01x (room) and 1.04x (dynamic) the CPU of eye by eye on the
        same pairs (pibr bench stereo, docs/results/stereo.json), so it stays off; what it shares
        is the per-view work a GPU pays for (draws, LoD selection, passes)."""
        super().__init__(ctx, output, config)
        if not proxies:
            from pibr.protocol.errors import ConfigError

            raise ConfigError("the proxy method needs the scene's proxies; the server sent none")
        self.tau = tau
        self.carve = bool(carve)
        self.inpaint = bool(inpaint)
        if not self.carve and not self.inpaint:
            from pibr.protocol.errors import ConfigError

            raise ConfigError("proxy: no-inpaint skips carving's second pass; it needs carving (drop --no-carve)")
        self.carve_all = self.carve and (bool(carve_all) or ctx.version_code < shaders.GL_FOR_RESTRICTED_CARVING)
        self.cull = bool(cull)
        self.objects = proxies
        self.moving = [i for i, o in enumerate(proxies) if o.moving]
        self._moving_set = set(self.moving)
        self.last_points = 0
        self.last_fallback_pixels = 0   # pixels left to pass 2 in the last render (carving, not carve_all)
        self._own_history = poses is None
        if poses is None:
            poses = PoseHistory(np.stack([o.transform for o in proxies]), np.stack([o.bounds for o in proxies]))
        self.set_motion(motion)
        # flow: a frame without motion to extrapolate shows the moving objects where it saw them
        self.placer = ObjectPlacer(poses, "static" if motion == "flow" else motion, config.frame_interval_us / 1e6,
                                   horizon_frames, oracle_pose)
        self._seen = (None, {})   # (frame key, index -> motion) of the newest frame's own transforms
        self.selector = LodSelector(proxies, output, lod_target_px, force_level=lod_level)
        glsl = {"frame": frame_glsl(config), "background": shaders.BACKGROUND_GLSL}
        size = (output.width, output.height)
        self.background = self.background_vbo = self.background_vao = self.left = None
        if not self.carve:
            self.passes = [ctx.program(vertex_shader=shaders.NEAREST_VS, fragment_shader=shaders.NEAREST_FS)]
            self.resolve = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=shaders.NEAREST_RESOLVE_FS % glsl)
            self.refs = ctx.texture(size, 4, dtype="f4")   # position, 1
            tests = [self.resolve]
        elif self.carve_all:
            self.passes = [ctx.program(vertex_shader=shaders.PROXY_VS, fragment_shader=shaders.PROXY_FS % (glsl | {"main": shaders.EITHER_MAIN}))]
            self.resolve = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=shaders.RESOLVE_FS % glsl)
            # (u, v + view, v + accepted) records; see record() in shaders.PROXY_FS
            self.refs = ctx.texture(size, 2, dtype="f4")
            tests = self.passes
        else:
            self.passes = [ctx.program(vertex_shader=shaders.PROXY_VS, fragment_shader=shaders.PROXY_FS % (glsl | {"main": main}))
                           for main in (shaders.ACCEPT_MAIN, shaders.FALLBACK_MAIN)]
            self.resolve = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=shaders.RECORD_RESOLVE_FS % glsl)
            self.background = ctx.program(vertex_shader=shaders.BACKGROUND_VS, fragment_shader=shaders.BACKGROUND_FS % glsl)
            self.background_vbo, self.background_vao = fullscreen_quad(ctx, self.background)
            self.left = ctx.buffer(shaders.LEFT_EMPTY)   # the Left block of shaders.BACKGROUND_FS
            self.refs = ctx.texture(size, 2, dtype="f4")   # records, see record() in shaders.PROXY_FS
            tests = self.passes
        self.prog = self.passes[0]
        # the program that finds a pixel's background
        self.finds_background = self.background if self.background is not None else self.resolve
        for p in {*self.passes, self.resolve, self.finds_background}:
            bind_frame_uniforms(p, config)
            if slack_codes is not None and "u_slack_codes" in p:
                p["u_slack_codes"].value = float(slack_codes)
        self.refs.filter = (ctx.NEAREST, ctx.NEAREST)
        self.refs_depth = ctx.depth_renderbuffer(size)
        self.refs_fbo = ctx.framebuffer(color_attachments=[self.refs], depth_attachment=self.refs_depth)
        self.refs_depth_fbo = ctx.framebuffer(depth_attachment=self.refs_depth)
        self.resolve["u_refs" if self.carve else "u_pos"].value = 5
        self.finds_background["u_out_size"].value = (float(output.width), float(output.height))
        for p in {self.resolve, self.finds_background}:
            for k, rect in (("u_primary_color", "primary.color"), ("u_extra_color", "extra.color")):
                if k in p:
                    p[k].value = rect_uniform(config, rect)
        # extra_view=False ignores a transmitted extra view: what proxy IBR does without one.
        self.uses_extra_view = bool(extra_view) and has_extra_depth(config)
        for test in tests:
            for k, value in (("u_has_extra", self.uses_extra_view), ("u_tau", float(tau))):
                if k in test:   # the fallback pass has no tau
                    test[k].value = value
        # Sessions whose extra view marks peeled pixels apart from sky, in depth codes that keep
        # the mark (min_code >= 2; see protocol/depth.py), let the extra view vouch for sky.
        self.finds_background["u_extra_sky"].value = (self.uses_extra_view and bool(config.options.get("peel_marker"))
                                                      and config.depth_min_code >= 2)
        self.resolve_vbo, self.resolve_vao = fullscreen_quad(ctx, self.resolve)
        self.points = self.points_vbo = self.points_vao = None
        if self.motion == "flow":
            self.points = ctx.program(vertex_shader=shaders.POINTS_VS % glsl, fragment_shader=shaders.POINTS_FS % glsl)
            bind_frame_uniforms(self.points, config)
            self.points["u_view_size"].value = (float(config.primary.width), float(config.primary.height))
            self.points["u_position"].value = not self.carve
            self.points["u_out_size"].value = (float(output.width), float(output.height))
            self.points_vbo = ctx.buffer(reserve=12 * 1024, dynamic=True)
            self.points_vao = ctx.vertex_array(self.points, [(self.points_vbo, "2f 1f", "in_px", "in_distance")])
        self.near, self.far = config.near, config.far
        self._frustum_changed()
        self._buffers = []
        # per object: level -> (one vao per program of self.passes, triangles, (8, 4) box corners,
        # when it may skip its back faces)
        self.vaos = []
        for o in proxies:
            levels = {}
            for level in ("original", "proxy", "box"):
                v, f = o.level(level)
                if len(f) == 0:
                    continue
                vbo = ctx.buffer(np.ascontiguousarray(v, np.float32).tobytes())
                ibo = ctx.buffer(np.ascontiguousarray(f, np.uint32).tobytes())
                vaos = self._mesh_vaos(self.passes, vbo, ibo)
                self._buffers += [vbo, ibo]
                lo, hi = np.min(v, axis=0), np.max(v, axis=0)
                corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                    for z in (lo[2], hi[2])])
                levels[level] = (vaos, len(f), corners, BackFaceTest(v, f, self.cull), (vbo, ibo))
            self.vaos.append(levels)
        self.last_primitives = 0
        self.last_culled = 0   # draws that skipped their back faces in the last render
        self._culling = False
        self.pair_at_once = bool(pair_at_once)
        self.pair_passes = []   # both eyes at once (render_pair), made when first used
        self._pair_refs = None

    def _frustum_changed(self) -> None:
        output = self.output
        for p in (self.finds_background, self.points):
            if p is not None:
                p["u_tan_half"].value = output_tan_half(output)
                p["u_tan_centre"].value = output_tan_centre(output)
        if self.points is not None:
            # source pixels per output pixel at the centres of both: a point covers its pixel's footprint
            src_px_per_rad = self.config.primary.width / np.pi
            out_px_per_rad = output.width / (2.0 * output_tan_half(output)[0])
            self.point_size = float(np.ceil(1.5 * out_px_per_rad / src_px_per_rad))
        # how far from the camera the near plane reaches: a mesh closer than that may be cut open
        left, right, down, up = output.tangents()
        self._near_reach = self.near * float(np.sqrt(1.0 + (max(left * left, right * right) + max(down * down, up * up))))
        self.projection = output_projection(output, self.near, self.far)
        self.selector.output = output

    def _mesh_vaos(self, programs, vbo, ibo) -> list:
        """One vertex array per program of a mesh's vertex (float32 x, y, z) and index (uint32) buffers."""
        return [self.ctx.vertex_array(p, [(vbo, "3f", "in_position")], index_buffer=ibo, index_element_size=4)
                for p in programs]

    def shares_pair(self, left: Pose, right: Pose) -> bool:
        """Whether :meth:`render_pair` draws these two eyes at once: with ``pair_at_once``, carving's
        passes (neither carve_all, nor carve=False, nor flow's points, which stay one view at a
        time), and eyes that look the same way from either side of a centre, along their common x
        axis (as protocol/stereo.py places them), through the output's symmetric frustum (the eyes
        share one projection)."""
        if not self.pair_at_once or not self.carve or self.carve_all or self.motion == "flow" \
                or self.output.frustum is not None:
            return False
        r = left.rotation()
        if not np.allclose(r, right.rotation(), atol=1e-9):
            return False
        baseline = r.T @ (np.asarray(right.p, np.float64) - np.asarray(left.p, np.float64))
        return bool(baseline[0] > 0.0 and np.all(np.abs(baseline[1:]) <= 1e-9 + 1e-6 * baseline[0]))

    def render_pair(self, left: Pose, right: Pose, frame, textures, scene_t: float = 0.0) -> None:
        """Both eyes of a stereo pair (:meth:`shares_pair`) into the bound framebuffer, twice the
        output's width: the left eye's image in its left half, the right eye's in its right half.
        What the two eyes share is done once: the textures bound, one LoD selection and culling for
        the pair's union frustum (client/lod_select.py), every matrix to the views, the pixels left
        to the second carving pass counted once for both; and each proxy is drawn once per pass for
        both eyes (two instances, shaders.PAIR_PROXY_VS), as are the background pass and the resolve
        over both halves. The fragments each eye covers are its own: on a software rasteriser that
        is most of the cost (see docs/results/stereo.json)."""
        ctx = self.ctx
        output_fbo = ctx.fbo
        self._make_pair_passes()
        textures.use(None)
        draws = self._draws((left, right), frame, scene_t)
        ctx.enable(ctx.DEPTH_TEST)
        self._carve(draws, None, left, frame, pair=True)
        ctx.disable(ctx.DEPTH_TEST)
        output_fbo.use()
        self._pair_refs[0].use(5)
        self.resolve_vao.render(ctx.TRIANGLE_STRIP)

    def _make_pair_passes(self) -> None:
        """The carving passes' programs for both eyes at once and their targets, once."""
        if self.pair_passes:
            return
        ctx = self.ctx
        glsl = {"frame": frame_glsl(self.config), "background": shaders.BACKGROUND_GLSL}
        for main, mono in zip((shaders.ACCEPT_MAIN, shaders.FALLBACK_MAIN), self.passes):
            prog = ctx.program(vertex_shader=shaders.PAIR_PROXY_VS,
                               fragment_shader=shaders.PROXY_FS % (glsl | {"main": main}))
            bind_frame_uniforms(prog, self.config)
            for k in ("u_slack_codes", "u_has_extra", "u_tau"):
                if k in mono:
                    prog[k].value = mono[k].value
            self.pair_passes.append(prog)
        for levels in self.vaos:
            for vaos, _, _, _, (vbo, ibo) in levels.values():
                vaos += self._mesh_vaos(self.pair_passes, vbo, ibo)
        size = (2 * self.output.width, self.output.height)
        refs = ctx.texture(size, 2, dtype="f4")
        refs.filter = (ctx.NEAREST, ctx.NEAREST)
        depth = ctx.depth_renderbuffer(size)
        self._pair_refs = (refs, depth, ctx.framebuffer(color_attachments=[refs], depth_attachment=depth),
                           ctx.framebuffer(depth_attachment=depth))

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        ctx = self.ctx
        output_fbo = ctx.fbo
        textures.use(self.flow_time(scene_t))
        moved = textures.extrapolated if self.motion == "flow" else None
        draws = self._draws((out_pose,), frame, scene_t, skip_moving=moved is not None)
        self.refs_fbo.use()
        ctx.enable(ctx.DEPTH_TEST)
        if self.carve_all:
            # Proxies, depth-tested, accepted fragments in front of the rest; each pixel keeps
            # where to fetch its colour.
            self.refs_fbo.clear(*shaders.NO_PROXY, 0.0, 0.0, depth=1.0)
            ctx.enable_direct(shaders.GL_CLIP_DISTANCE0)
            if moved is not None:
                self._draw_points(moved, out_pose, frame)
            prog = self.prog
            for depth_half in (-1.0, 1.0) if self.inpaint else (-1.0,):   # accepted fragments, then the rest behind
                prog["u_fallback"].value = depth_half > 0
                prog["u_depth_half"].value = depth_half
                self._draw_proxies(0, draws)
            ctx.disable_direct(shaders.GL_CLIP_DISTANCE0)
        elif self.carve:
            self._carve(draws, moved, out_pose, frame)
        else:
            self.refs_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)   # w = 0: no proxy here
            if moved is not None:
                ctx.enable_direct(shaders.GL_CLIP_DISTANCE0)
                self._draw_points(moved, out_pose, frame)
                ctx.disable_direct(shaders.GL_CLIP_DISTANCE0)
            for vaos, mvp, _, _, seen, _, (cull,) in draws:
                self._cull_back_faces(cull)
                self.prog["u_mvp"].write(mvp)
                self.prog["u_seen"].write(seen)
                vaos[0].render(ctx.TRIANGLES)
            self._cull_back_faces(False)
            self.resolve["u_world_to_primary"].write(mat4_bytes(frame.primary_pose.view_matrix()))
            self.resolve["u_world_to_extra"].write(mat4_bytes((frame.extra_pose or frame.primary_pose).view_matrix()))
        ctx.disable(ctx.DEPTH_TEST)
        output_fbo.use()
        self.refs.use(5)
        if self.finds_background is self.resolve:
            self._background_rotations(out_pose, frame)
        self.resolve_vao.render(ctx.TRIANGLE_STRIP)

    def _carve(self, draws, moved, out_pose: Pose, frame, pair: bool = False) -> None:
        """Both carving passes and the background between them (shaders.BACKGROUND_FS): every pixel's
        record into refs (``pair``: both eyes' records, side by side, see render_pair)."""
        ctx = self.ctx
        refs_fbo, refs_depth_fbo = self._pair_refs[2:] if pair else (self.refs_fbo, self.refs_depth_fbo)
        first = len(self.passes) if pair else 0   # the passes' index in each object's vaos
        clips = [shaders.GL_CLIP_DISTANCE0 + k for k in range(shaders.PAIR_CLIP_DISTANCES if pair else 1)]
        refs_depth_fbo.clear(depth=1.0)   # every pixel's record is written below
        refs_fbo.use()
        for c in clips:
            ctx.enable_direct(c)
        if moved is not None:
            self._draw_points(moved, out_pose, frame)
        self._program(first)["u_depth_half"].value = -1.0
        self._draw_proxies(first, draws)   # pass 1: accepted fragments
        for c in clips:
            ctx.disable_direct(c)
        self._background_rotations(out_pose, frame)
        self.left.write(shaders.LEFT_EMPTY)
        self.left.bind_to_storage_buffer(0)
        refs_fbo.depth_mask = False   # pass 2 still sees where pass 1 accepted nothing
        refs_fbo.use()
        self.background_vao.render(ctx.TRIANGLE_STRIP)
        refs_fbo.depth_mask = True
        refs_fbo.use()
        if not self.inpaint:
            return
        ctx.memory_barrier()   # the counter's writes are incoherent until then
        wait_idle(ctx)   # pass 1 and the background drawn, the GIL released meanwhile (common/gl.py)
        left = np.frombuffer(self.left.read(), np.uint32)
        self.last_fallback_pixels = int(left[0])
        if left[0] == 0:
            return
        for c in clips:
            ctx.enable_direct(c)
        self._program(first + 1)["u_depth_half"].value = 1.0
        for eye in range(2 if pair else 1):   # pass 2: the rest, behind, each eye in its box
            x0, y0, x1, y1 = (int(x) for x in left[1 + 4 * eye:5 + 4 * eye])
            if x0 > x1:
                continue   # this eye accepted a fragment everywhere
            ctx.scissor = (x0, y0, x1 - x0 + 1, y1 - y0 + 1)
            self._draw_proxies(first + 1, draws, (x0, y0, x1, y1), eye if pair else None)
        ctx.scissor = None
        for c in clips:
            ctx.disable_direct(c)

    def _program(self, which: int):
        """Program ``which`` of self.passes followed by self.pair_passes (each object's vaos, in order)."""
        return self.passes[which] if which < len(self.passes) else self.pair_passes[which - len(self.passes)]

    def _background_rotations(self, out_pose: Pose, frame) -> None:
        prog = self.finds_background
        rot = frame.primary_pose.rotation().T @ out_pose.rotation()
        prog["u_out_to_src"].write(rot.T.astype("f4").tobytes())
        if self.uses_extra_view and frame.extra_pose is not None:
            rot = frame.extra_pose.rotation().T @ out_pose.rotation()
            prog["u_out_to_extra"].write(rot.T.astype("f4").tobytes())

    def _draw_proxies(self, which: int, draws, box=None, eye: int | None = None) -> None:
        """The proxies of ``draws`` (see _draws) with program ``which`` (see _program), for every eye
        of the draws, or only ``eye`` of a pair; only those whose screen rectangle in such an eye
        meets ``box`` (x0, y0, x1, y1 inclusive, window pixels) if given."""
        prog = self._program(which)
        if "u_first_eye" in prog:
            prog["u_first_eye"].value = eye or 0
        for vaos, mvp, to_primary, to_extra, _, bounds, cull in draws:
            eyes = range(len(bounds)) if eye is None else (eye,)
            if box is not None and not any(self._rect_meets(box, *bounds[e]) for e in eyes):
                continue
            prog["u_mvp"].write(mvp)
            prog["u_to_primary"].write(to_primary)
            prog["u_to_extra"].write(to_extra)
            if len(eyes) > 1 and len(set(cull)) > 1:   # one eye may skip the back faces, the other not
                for e in eyes:
                    prog["u_first_eye"].value = e
                    self._cull_back_faces(cull[e])
                    vaos[which].render(self.ctx.TRIANGLES, instances=1)
                prog["u_first_eye"].value = eye or 0
                continue
            self._cull_back_faces(cull[eyes[0]])
            vaos[which].render(self.ctx.TRIANGLES, instances=len(eyes))
        self._cull_back_faces(False)

    def _rect_meets(self, box, mvp: np.ndarray, corners: np.ndarray, x_offset: int) -> bool:
        """Whether ``box`` meets the screen rectangle of a mesh (see _screen_rect) drawn ``x_offset``
        pixels to the right (the right eye's half of a pair)."""
        x0, y0, x1, y1 = self._screen_rect(mvp, corners)
        return not (x0 + x_offset > box[2] or x1 + x_offset < box[0] or y0 > box[3] or y1 < box[1])

    def _cull_back_faces(self, cull: bool) -> None:
        if cull != self._culling:
            self._culling = cull
            if cull:
                # the vertex shaders flip y (top-row-first images): outward faces wind clockwise on screen
                self.ctx.front_face = "cw"
                self.ctx.cull_face = "back"
                self.ctx.enable(self.ctx.CULL_FACE)
            else:
                self.ctx.disable(self.ctx.CULL_FACE)
                self.ctx.front_face = "ccw"

    def _draw_points(self, moved, out_pose: Pose, frame) -> None:
        """The extrapolated view's moving pixels (flow_warp.Extrapolated) as points, accepted."""
        n = len(moved.moved)
        self.last_points = n
        if n == 0:
            return
        data = np.empty((n, 3), np.float32)
        data[:, :2] = moved.moved
        data[:, 2] = moved.moved_distance
        if self.points_vbo.size < data.nbytes:
            self.points_vbo.orphan(data.nbytes)
        self.points_vbo.write(data.tobytes())
        src = frame.primary_pose
        to_clip = self.projection @ out_pose.view_matrix() @ src.matrix()
        self.points["u_primary_to_clip"].write(mat4_bytes(to_clip))
        r_src = src.rotation()
        self.points["u_out_to_primary"].write((r_src.T @ out_pose.rotation()).T.astype("f4").tobytes())
        self.points["u_eye"].value = tuple(float(x) for x in r_src.T @ (out_pose.p - src.p))
        if "u_primary_to_world" in self.points:
            self.points["u_primary_to_world"].write(mat4_bytes(src.matrix()))
        self.points["u_depth_half"].value = -1.0
        self.ctx.point_size = self.point_size
        self.points_vao.render(self.ctx.POINTS, vertices=n)

    def _draws(self, eyes: tuple, frame, scene_t: float, skip_moving: bool = False) -> list:
        """[(vaos, mvp, to_primary, to_extra, seen, bounds, cull)] of the objects to draw for the
        output poses ``eyes`` (one, or a pair that :meth:`shares_pair`), nearest first (so the depth
        test rejects most hidden fragments before they are shaded); matrices as uniform bytes (mvp:
        one per eye; seen: object -> world where the views saw it), bounds: per eye _rect_meets's
        arguments, for the passes that skip objects outside a box; cull: per eye whether to skip
        the mesh's back faces.

        From outside a closed, outward-wound mesh every back face lies behind a front face of the
        same mesh, so none of its fragments is a pixel's nearest (client/back_faces.py);
        skipping them saves their rasterisation and, where one is drawn before the front face
        that hides it, its shading. Carving keeps a moving object's back faces: it is drawn where
        it is extrapolated to be, so where that misses, a back face the views confirm is what
        shows it (measured on the fast ball of tests/client/test_proxy_motion.py: 24.7 dB with
        them, 22.8 without).
        ``skip_moving``: leave the moving objects out (``flow`` draws their pixels instead)."""
        to_p = frame.primary_pose.view_matrix()
        to_e = frame.extra_pose.view_matrix() if frame.extra_pose is not None else to_p
        vps = [self.projection @ eye.view_matrix() for eye in eyes]
        offsets = [k * self.output.width for k in range(len(eyes))]   # side by side
        seen_motion = self._frame_motions(frame)
        now = {i: m @ self.objects[i].transform for i, m in self.placer.motions(self.moving, scene_t).items()}
        if len(eyes) == 1:
            selected = self.selector.select(eyes[0], self.near, now)
        else:   # the pair's union frustum, from the eyes' centre (shares_pair)
            half = 0.5 * float(np.linalg.norm(np.asarray(eyes[1].p) - np.asarray(eyes[0].p)))
            centre = Pose.make(0.5 * (np.asarray(eyes[0].p) + np.asarray(eyes[1].p)), eyes[0].q)
            selected = self.selector.select(centre, self.near, now, half_baseline=half)
        draws, tris = [], 0
        for sel in sorted(selected, key=_front_to_back):
            if skip_moving and sel.index in self._moving_set:
                continue
            levels = self.vaos[sel.index]
            level = sel.level if sel.level in levels else next(iter(levels), None)
            if level is None:
                continue
            obj = self.objects[sel.index]
            model = now.get(sel.index, obj.transform)
            # A moving object is drawn where it is now, but looked up where the views saw it.
            seen = seen_motion[sel.index] @ obj.transform if sel.index in seen_motion else model
            vaos, n, corners, back_faces, _ = levels[level]
            mvps = [vp @ model for vp in vps]
            draws.append((vaos, b"".join(mat4_bytes(m) for m in mvps), mat4_bytes(to_p @ seen),
                          mat4_bytes(to_e @ seen), mat4_bytes(seen),
                          tuple((m, corners, x) for m, x in zip(mvps, offsets)),
                          tuple((self.carve is False or sel.index not in self._moving_set)
                                and back_faces.allows(eye.p, model, self._near_reach) for eye in eyes)))
            tris += n * len(eyes)
        self.last_primitives = tris
        self.last_culled = sum(sum(d[-1]) for d in draws)
        return draws

    def _screen_rect(self, mvp: np.ndarray, corners: np.ndarray) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1), inclusive, window pixels (GL's, bottom row 0) holding every fragment
        of a mesh whose bounding box has ``corners`` (8, 4), drawn with ``mvp``; the whole output
        where the box reaches behind the camera."""
        w, h = self.output.width, self.output.height
        clip = corners @ mvp.T
        if np.any(clip[:, 3] <= 1e-6):
            return 0, 0, w - 1, h - 1
        x = (clip[:, 0] / clip[:, 3] + 1.0) * (0.5 * w)
        y = (1.0 - clip[:, 1] / clip[:, 3]) * (0.5 * h)   # the images are drawn top row first
        return (max(int(np.floor(x.min())) - 1, 0), max(int(np.floor(y.min())) - 1, 0),
                min(int(np.ceil(x.max())) + 1, w - 1), min(int(np.ceil(y.max())) + 1, h - 1))

    def _frame_motions(self, frame) -> dict:
        """index -> (4, 4) motion of the moving objects at ``frame``'s scene time, from its own
        OBJECT_POSES payload (parsed once per frame; also fed to a history of our own)."""
        payload = frame.payload(PayloadKind.OBJECT_POSES)
        key = (frame.frame_id, frame.scene_t_us, None if payload is None else len(payload))
        if self._seen[0] != key:
            motions = {}
            if payload is not None:
                poses = decode_object_poses(payload, len(self.objects))
                motions = dict(zip(poses.indices.tolist(), poses.matrices()))
                if self._own_history:
                    self.placer.history.add(frame.scene_t_us / 1e6, poses)
            self._seen = (key, motions)
        return self._seen[1]

    def release(self) -> None:
        for levels in self.vaos:
            for vaos, *_ in levels.values():
                for vao in vaos:
                    vao.release()
        for r in (*self.pair_passes, *(self._pair_refs or ())):
            r.release()
        for b in self._buffers:
            b.release()
        for r in (*self.passes, self.resolve_vao, self.resolve_vbo, self.resolve, self.refs_fbo, self.refs_depth_fbo,
                  self.refs, self.refs_depth, self.points_vao, self.points_vbo, self.points, self.background_vao,
                  self.background_vbo, self.background, self.left):
            if r is not None:
                r.release()
