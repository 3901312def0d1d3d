"""Rendering a scene with moderngl: wide-angle views (the server's) and perspective views
(ground truth), sharing one shading model so both see exactly the same colours.

Wide-angle views are drawn in one of three ways (``projection``):

``"vertex"``  the vertex shader projects pre-tessellated meshes (see scenes/tessellate.py);
``"tess"``    a tessellation shader splits each triangle on the fly by the angle its edges
              span, so near triangles get many pieces and far ones none;
``"cube"``    five perspective cube faces of the original meshes, resampled (cube_faces.py;
              unpeeled views only).

``pibr bench server --projection vertex,tess,cube`` measures them; the default is the
fastest at full quality here. Each object has several pre-tessellated copies
(``LOD_BANDS``): a wide view draws the coarsest whose edges still span at most the edge
angle from its eye, and skips chunks of triangles wholly behind its camera (exact). A
smaller view (the extra view) may ask for longer edges (``edge_angle_for_width``).
Every render target stores colour (RGBA8) and radial distance (R32F, 0 = sky).
Images are top-row-first everywhere (see protocol/projection.py): passes flip NDC y, so a
framebuffer read returns rows in image order. The GLSL is in shaders.py, the render targets
and their readbacks in render_target.py.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from pibr.protocol.frustum import projection as frustum_projection
from pibr.protocol.pose import Pose
from pibr.protocol.projection import GLSL as PROJECTION_GLSL
from pibr.scenes.scene import Scene
from pibr.scenes.tessellate import levels_for_view_region, subdivide

from . import cube_faces, shaders
from .render_target import RenderTarget

log = logging.getLogger(__name__)

PROJECTIONS = ("vertex", "tess", "cube")
DEFAULT_PROJECTION = "vertex"
#: Largest angle one rasterised edge may span in the wide-angle projection. At 1024 px over
#: 180 degrees a 6 degree chord bends by 0.08 degrees, under half a pixel.
MAX_EDGE_ANGLE_DEG = 6.0
#: Relative distance tolerance of depth peeling. Across one primary texel (1/512 rad at
#: 1024 px) a surface seen at 85 degrees from its normal changes distance by about
#: 1/512 * tan(85 deg) = 2.2 %; 3 % keeps such a surface out of the extra view while
#: surfaces 3 % behind (3 cm at 1 m) are still peeled into it. ``pibr bench coverage``
#: reports the redundancy left.
PEEL_TOLERANCE = 0.03
#: Depth-buffer units a decal layer is drawn in front of the layer below (polygon offset).
DECAL_OFFSET_UNITS = 4.0

GL_CLIP_DISTANCE0 = 0x3000  # moderngl has no name for it; see moderngl issue #620
_VERTEX_FORMAT = "3f 3f 2f 4f1"
_VERTEX_ATTRS = ("in_position", "in_normal", "in_uv", "in_color")

def edge_angle_for_width(angle_deg: float, reference_width: int, width: int) -> float:
    """Edge angle giving a view ``width`` pixels wide the same bend in pixels as ``angle_deg`` gives
    one ``reference_width`` wide: a chord spanning angle a strays from the projected curve by
    about a^2 / 8 radians, so a half-size view takes sqrt(2) times longer edges."""
    return float(angle_deg) * float(np.sqrt(reference_width / width))


def perspective_matrix(fov_x_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL projection (4, 4) for a horizontal field of view and aspect = width / height."""
    fx = 1.0 / np.tan(np.radians(fov_x_deg) / 2.0)
    fy = fx * aspect
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = fx, fy
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


#: Interleaved vertex record matching _VERTEX_FORMAT. Built once here, from shapes rather than
#: a "3f4" string: numpy parses such strings with ast.literal_eval, and on CPython 3.11 parsing
#: while another thread compiles can fail with "AST constructor recursion depth mismatch"
#: (renderers are built on the GL thread while other threads work).
_VERTEX_DTYPE = np.dtype([("p", np.float32, (3,)), ("n", np.float32, (3,)), ("uv", np.float32, (2,)),
                          ("c", np.uint8, (4,))])


def _interleave(mesh) -> np.ndarray:
    n = len(mesh.vertices)
    uv = mesh.uvs if mesh.uvs is not None else np.zeros((n, 2), np.float32)
    col = mesh.colors if mesh.colors is not None else np.full((n, 4), 255, np.uint8)
    rec = np.empty(n, dtype=_VERTEX_DTYPE)
    rec["p"], rec["n"], rec["uv"], rec["c"] = mesh.vertices, mesh.normals, uv, col
    return rec


#: Triangles per culling chunk: runs of consecutive faces whose bounding boxes are tested
#: against each wide view's hemisphere every frame. Smaller chunks cull more precisely but
#: cost more draw calls.
CHUNK_TRIANGLES = 2048
#: A chunk is culled when every corner of its box lies this far behind the camera plane
#: (p_z > margin, metres): float32 rounding on the GPU must not bring a vertex forward.
CULL_MARGIN = 1e-4


def chunk_boxes(mesh, chunk: int = CHUNK_TRIANGLES) -> np.ndarray:
    """Object-space corners (k, 8, 3) float64 of the boxes around faces [i * chunk, (i + 1) * chunk)."""
    tri = mesh.vertices[mesh.faces].astype(np.float64)          # (m, 3, 3)
    k = -(-len(tri) // chunk)
    lo = np.empty((k, 3))
    hi = np.empty((k, 3))
    for i in range(k):
        part = tri[i * chunk:(i + 1) * chunk].reshape(-1, 3)
        lo[i], hi[i] = part.min(0), part.max(0)
    pick = np.array([[i, j, l] for i in (0, 1) for j in (0, 1) for l in (0, 1)])   # (8, 3) 0 = lo, 1 = hi
    return np.where(pick[None, :, :] == 0, lo[:, None, :], hi[:, None, :])


#: The wide views' culling plane, (normal, offset) in camera space: inside where -p_z + margin >= 0.
HEMISPHERE = np.array([[0.0, 0.0, -1.0, CULL_MARGIN]])


def visible_runs(corners: np.ndarray, model_view: np.ndarray, chunk: int, faces: int,
                 planes: np.ndarray = HEMISPHERE) -> list[tuple[int, int]]:
    """(first face, face count) runs of the chunks not wholly outside any of ``planes``.

    corners : (k, 8, 3) object-space chunk boxes; model_view : (4, 4) object -> camera; planes :
    (p, 4) camera-space (normal, offset), inside where n . p + d >= 0. With the default, chunks
    wholly behind the camera (p_z > 0) go: a wide view rasterises nothing of a triangle whose
    vertices all lie behind its camera (they land at |t'_x| >= 1, see protocol/projection.py),
    so dropping them leaves every pixel as it was; runs keep the faces' order, so depth ties
    resolve as before.
    """
    cam = corners @ model_view[:3, :3].T + model_view[:3, 3]      # (k, 8, 3)
    side = cam @ planes[:, :3].T + planes[:, 3]                   # (k, 8, p)
    keep = (side.max(axis=1) >= 0.0).all(axis=1)
    if keep.all():
        return [(0, faces)]
    edges = np.flatnonzero(np.diff(np.concatenate(([False], keep, [False])).astype(np.int8)))
    return [(int(a) * chunk, min(int(b) * chunk, faces) - int(a) * chunk) for a, b in zip(edges[::2], edges[1::2])]


class _GPUMesh:
    def __init__(self, ctx, mesh):
        self.ctx = ctx
        self.vbo = ctx.buffer(_interleave(mesh).tobytes())
        self.ibo = ctx.buffer(mesh.faces.astype(np.uint32).tobytes())
        self.count = mesh.faces.size
        self.faces = len(mesh.faces)
        self.chunk_corners = chunk_boxes(mesh)
        self.vaos: dict = {}   # program key -> vertex array, made when first drawn

    def vao(self, key, prog):
        vao = self.vaos.get(key)
        if vao is None:
            vao = self.vaos[key] = self.ctx.vertex_array(prog, [(self.vbo, _VERTEX_FORMAT, *_VERTEX_ATTRS)],
                                                         index_buffer=self.ibo, index_element_size=4,
                                                         skip_errors=True)
        return vao

    def release(self):
        for v in self.vaos.values():
            v.release()
        self.vbo.release()
        self.ibo.release()


@dataclass
class _GPUObject:
    obj: object
    original: _GPUMesh
    texture: object | None
    index: int = 0     # in the scene's object list
    #: pre-tessellated copies: edge angle (degrees) -> [(band distance m, mesh)], bands ascending
    tessellations: dict = field(default_factory=dict)

    def __post_init__(self):
        self.static_box = self.obj.world_bounds(0.0)   # (2, 3) world box at rest

    def meshes(self):
        return [m for bands in self.tessellations.values() for _, m in bands]


#: Distances (m) from a view's eye to an object's box above which a coarser pre-tessellated copy
#: is drawn: every edge still spans at most the edge angle from that eye (see _tessellate).
LOD_BANDS = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)


class Renderer:
    """Draws one scene. Create and use on the GL thread (see pibr.common.gl)."""

    def __init__(self, ctx, scene: Scene, projection: str = DEFAULT_PROJECTION,
                 max_edge_angle_deg: float = MAX_EDGE_ANGLE_DEG, tess_max_level: int = 64,
                 tess_max_screen_edge: float = 48.0, wide: bool = True, cull: bool = True,
                 lod: bool = True, cube_scale: float = 0.75, wide_trilinear: bool = False,
                 specialise: bool = True, shade: bool = True):
        """``shade``: False draws distances (and motion) only, every colour black: the fragment
        shader skips lighting and textures, the distances are the same bits (coverage probes)."""
        if projection not in PROJECTIONS:
            raise ValueError(f"projection must be one of {', '.join(PROJECTIONS)}, got {projection!r}")
        self.ctx, self.scene, self.projection = ctx, scene, projection
        #: Wide views skip chunks of triangles wholly behind their camera (same pixels, less work).
        self.cull = cull
        self.drawn_triangles = 0   # triangles sent by the last wide view (diagnostics)
        #: Wide views draw each object's coarsest pre-tessellated copy that still keeps every edge
        #: within the edge angle seen from their eye (LOD_BANDS); off: the copy for the whole region.
        self.lod = lod
        self.max_edge_angle = np.radians(max_edge_angle_deg)
        self.max_edge_angle_deg = float(max_edge_angle_deg)
        self.tess_max_level = tess_max_level
        #: one program per pass and object kind (textured): see shaders.SPECIALISED; moving: the motion pass
        self.specialise = specialise
        self.tess_max_screen_edge = tess_max_screen_edge
        shading = shaders.shading_glsl(scene.lights)
        unshaded = "" if shade else "#define DISTANCE_ONLY\n"
        self._fragment = {name: shaders.FRAGMENT % {"shading": shading, "defines": unshaded + defines + "@SWITCHES@",
                                                    "projection": PROJECTION_GLSL}
                          for name, defines in (("plain", ""), ("peel", "#define PEEL\n"),
                                                ("mark", "#define PEEL\n#define PEEL_MARK\n"))}
        self._fragment["motion"] = shaders.MOTION_FRAGMENT % {"projection": PROJECTION_GLSL}
        #: pass name -> (vertex, tess control, tess evaluation shader, fragment variant); compiled when
        #: first drawn, per (pass, textured, moving) key (see :meth:`_program`)
        cube_vs = cube_faces.CUBE_VS % {"uniforms": shaders.COMMON_VS_UNIFORMS}
        self._passes = {"perspective": (shaders.PERSPECTIVE_VS, None, None, "plain"),
                        "vertex": (shaders.WIDE_VERTEX_VS, None, None, "plain"),
                        "vertex_peel": (shaders.WIDE_VERTEX_VS, None, None, "peel"),
                        "vertex_peel_mark": (shaders.WIDE_VERTEX_VS, None, None, "mark"),
                        "tess": (shaders.TESS_VS, shaders.TESS_TCS, shaders.TESS_TES, "plain"),
                        "tess_peel": (shaders.TESS_VS, shaders.TESS_TCS, shaders.TESS_TES, "peel"),
                        "tess_peel_mark": (shaders.TESS_VS, shaders.TESS_TCS, shaders.TESS_TES, "mark"),
                        "cube": (cube_vs, None, None, "plain")}
        for name in ("perspective", "vertex", "tess", "cube"):   # the moving objects' motion (_draw_motion)
            self._passes[name + "_motion"] = self._passes[name][:3] + ("motion",)
        self.programs: dict = {}   # (pass, textured, moving) -> program; (pass, None, None) unspecialised
        resample = ctx.program(vertex_shader=cube_faces.RESAMPLE_VS,
                               fragment_shader=cube_faces.RESAMPLE_FS % {"projection": PROJECTION_GLSL})
        for unit, name in enumerate(("u_cube_color", "u_cube_dist", "u_cube_motion")):
            if name in resample:
                resample[name].value = unit
        self._resample = resample
        self._quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4").tobytes())
        self._resample_vao = ctx.vertex_array(resample, [(self._quad, "2f", "in_pos")])
        #: projection "cube": face size as a fraction of the wide view's width (see cube_faces.py)
        self.cube_scale = cube_scale
        self._cube_targets: dict = {}
        #: Wide views sample textures bilinearly from the nearest mip level rather than blending
        #: two (trilinear, which perspective views keep): a tenth of the primary's time, and the
        #: images differ by about 51 dB PSNR. True: trilinear everywhere.
        self.wide_trilinear = wide_trilinear
        self._mip_nearest = ctx.sampler(filter=(ctx.LINEAR_MIPMAP_NEAREST, ctx.LINEAR))
        self.objects: list[_GPUObject] = []
        self.tessellated_triangles = 0
        for index, obj in enumerate(scene.objects):
            if obj.mesh.triangle_count == 0:
                continue
            original = _GPUMesh(ctx, obj.mesh)
            tex = None
            if obj.material.texture is not None:
                img = np.ascontiguousarray(obj.material.texture[::-1])  # UV v = 0 is the bottom row
                tex = ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), alignment=1)
                tex.build_mipmaps()
                tex.filter = (ctx.LINEAR_MIPMAP_LINEAR, ctx.LINEAR)
                # No anisotropic filtering: on llvmpipe it costs more than the rest of the pass.
            self.objects.append(_GPUObject(obj, original, tex, index))
        self.wide = wide
        if wide:  # pre-tessellated copies for the vertex-projection path
            self.tessellated_triangles = self.prepare_edge_angle(max_edge_angle_deg)
        if wide:  # compile now what the server's views draw, so a session's first frame does not wait
            for key in self._program_keys(self.projection if self.projection != "cube" else "vertex"):
                self._program(key)
        log.debug("renderer: %d objects, %d triangles (%d pre-tessellated)", len(self.objects),
                  scene.triangle_count, self.tessellated_triangles)

    def _program_keys(self, projection: str) -> set:
        """Program keys of a primary view with motion and a marked peeled view in ``projection``."""
        if not self.specialise:
            return {(projection, None, None), (projection + "_motion", None, None),
                    (projection + "_peel_mark", None, None)}
        kinds = {g.texture is not None for g in self.objects}
        motion = {(projection + "_motion", False, True)} if any(g.obj.is_dynamic for g in self.objects) else set()
        return {(projection, k, False) for k in kinds} | motion | {(projection + "_peel_mark", k, False) for k in kinds}

    def _tessellate(self, obj, angle_deg: float) -> list:
        """[(band distance, mesh)]: the object split for eyes anywhere in the viewing region (band 0),
        and coarser for eyes at least each band's distance from its box (a face is no nearer to
        the eye than the box is); bands whose split equals the previous one's are left out."""
        region = self.scene.viewing_region()
        bands, previous = [], None
        for d in LOD_BANDS:
            levels = levels_for_view_region(obj.mesh, obj.transform, region, angle_deg, min_distance=d)
            if previous is not None and np.array_equal(levels, previous):
                continue
            previous = levels
            fine = subdivide(obj.mesh, levels) if levels.max() > 1 else obj.mesh
            bands.append((d, _GPUMesh(self.ctx, fine)))
        return bands

    def prepare_edge_angle(self, angle_deg: float) -> int:
        """Build the pre-tessellated copies for views drawn with ``max_edge_deg=angle_deg``; returns
        the triangle count of the finest (an eye anywhere in the viewing region). Takes a second
        or so for a room: call it when a session starts, not mid-stream."""
        if not self.wide:
            return 0
        key = round(float(angle_deg), 6)
        for g in self.objects:
            if key not in g.tessellations:
                g.tessellations[key] = self._tessellate(g.obj, key)
        return sum(g.tessellations[key][0][1].faces for g in self.objects)

    def _tessellated(self, g: _GPUObject, angle_deg: float | None, eye: np.ndarray, t: float) -> _GPUMesh:
        """The coarsest copy whose band the eye's distance to the object's box reaches."""
        key = round(float(self.max_edge_angle_deg if angle_deg is None else angle_deg), 6)
        if key not in g.tessellations:
            self.prepare_edge_angle(key)
        bands = g.tessellations[key]
        if len(bands) == 1 or not self.lod:
            return bands[0][1]
        box = g.obj.world_bounds(t) if g.obj.is_dynamic else g.static_box
        distance = float(np.linalg.norm(np.maximum(0.0, np.maximum(box[0] - eye, eye - box[1]))))
        mesh = bands[0][1]
        for d, m in bands:
            if d <= distance:
                mesh = m
        return mesh

    def _program(self, key: tuple):
        """The program of ``key`` = (pass, textured, moving), or (pass, None, None) for the one
        with uniform switches; compiled on first use. (moving is True for the motion passes only,
        which their names already say; it keeps the keys of one shape.)"""
        prog = self.programs.get(key)
        if prog is not None:
            return prog
        name, textured, _ = key
        vs, tcs, tes, variant = self._passes[name]
        if textured is None:
            defines = shaders.UNIFORM_SWITCHES
        else:
            defines = shaders.SPECIALISED % ("true" if textured else "false")
        prog = self.ctx.program(vertex_shader=vs, tess_control_shader=tcs, tess_evaluation_shader=tes,
                                fragment_shader=self._fragment[variant].replace("@SWITCHES@", defines))
        if tcs is not None:
            prog["u_max_angle"].value = float(self.max_edge_angle)
            prog["u_max_level"].value = float(self.tess_max_level)
            prog["u_max_screen_edge"].value = float(self.tess_max_screen_edge)
        if "u_peel_dist" in prog:
            prog["u_peel_dist"].value = 1
        self.programs[key] = prog
        return prog

    def _render_mesh(self, mesh: _GPUMesh, key: tuple, prog, mode, model_view: np.ndarray, cull: bool,
                     planes: np.ndarray = HEMISPHERE) -> None:
        vao = mesh.vao(key, prog)
        if not cull:
            vao.render(mode)
            self.drawn_triangles += mesh.faces
            return
        for first, count in visible_runs(mesh.chunk_corners, model_view, CHUNK_TRIANGLES, mesh.faces, planes):
            vao.render(mode, vertices=3 * count, first=3 * first)
            self.drawn_triangles += count

    def _draw(self, prog_name: str, view: np.ndarray, eye: np.ndarray, t: float, extra_uniforms: dict,
              motion_dt: float | None = None, cull: bool = False, edge_deg: float | None = None,
              planes: np.ndarray = HEMISPHERE, target: RenderTarget | None = None):
        """Every object's colour and distance into the bound framebuffer (``target``'s when given);
        with ``motion_dt`` and a target with motion, then the moving objects' motion
        (:meth:`_draw_motion`)."""
        uniforms = {"u_eye": tuple(float(x) for x in eye), **extra_uniforms}
        ready: dict = {}   # key -> (program, its uniform names) with this draw's uniforms set
        layer = 0
        for g in self.objects:
            key = (prog_name, g.texture is not None, False) if self.specialise else (prog_name, None, None)
            layer = self._draw_object(g, key, ready, uniforms, view, eye, t, None, layer, prog_name, cull,
                                      edge_deg, planes)
        if layer:
            self.ctx.polygon_offset = (0.0, 0.0)
        if motion_dt is not None and target is not None and target.motion is not None:
            self._draw_motion(prog_name, view, eye, t, uniforms, motion_dt, cull, edge_deg, planes, target)

    def _draw_motion(self, prog_name, view, eye, t, uniforms, motion_dt, cull, edge_deg, planes, target) -> None:
        """The moving objects' motion into ``target``'s motion attachment (cleared to 0: not moving),
        after :meth:`_draw` wrote every object's depth. They are drawn again with the same vertex
        shader, so at the same depths, bit for bit; the depth test for equality passes where one is
        the nearest surface, and blending keeps the first fragment that lands on a pixel, as the
        main pass's depth test does among fragments of equal depth (src * (1 - dst alpha) + dst,
        exact: the flag in alpha is 0 until written, then 1). Out of the main pass, whose every
        fragment would otherwise write half floats, zero but on moving objects: about a sixth of
        the primary view's cost."""
        moving = [g for g in self.objects if g.obj.is_dynamic]
        if not moving:
            return
        ctx = self.ctx
        viewport = ctx.viewport
        target.motion_fbo.use()
        ctx.viewport = viewport
        ctx.depth_func = "=="
        ctx.enable(ctx.BLEND)
        ctx.blend_func = ctx.ONE_MINUS_DST_ALPHA, ctx.ONE
        ready: dict = {}
        layer = 0
        name = prog_name + "_motion"
        try:
            for g in moving:
                key = (name, False, True) if self.specialise else (name, None, None)
                layer = self._draw_object(g, key, ready, uniforms, view, eye, t, motion_dt, layer, prog_name, cull,
                                          edge_deg, planes)
        finally:
            if layer:
                ctx.polygon_offset = (0.0, 0.0)
            ctx.disable(ctx.BLEND)
            ctx.blend_func = ctx.DEFAULT_BLENDING
            ctx.depth_func = "<"
            target.fbo.use()
            ctx.viewport = viewport

    def _draw_object(self, g: "_GPUObject", key: tuple, ready: dict, uniforms: dict, view, eye, t: float,
                     motion_dt: float | None, layer: int, prog_name: str, cull: bool, edge_deg, planes) -> int:
        """One object with program ``key`` (``ready`` caches the programs whose draw uniforms are
        set); ``motion_dt``: its motion over that many seconds (the motion pass). Returns the
        decal layer now set."""
        moving = motion_dt is not None
        if key not in ready:
            prog = self._program(key)
            members = set(prog)  # the compiler drops uniforms a shader does not use
            for name, value in uniforms.items():
                if name in members:
                    prog[name].write(np.ascontiguousarray(value, dtype=np.float32).tobytes()) \
                        if isinstance(value, np.ndarray) else setattr(prog[name], "value", value)
            ready[key] = (prog, members)
        prog, members = ready[key]
        if g.obj.layer != layer:   # decals: in front of the coplanar surfaces they lie on
            layer = g.obj.layer
            self.ctx.polygon_offset = (0.0, -DECAL_OFFSET_UNITS * layer)
        model = g.obj.world_matrix(t)
        mv = view @ model
        prev_mv = view @ g.obj.world_matrix(t - motion_dt) if moving else mv
        values = {
            "u_model": model.T.astype(np.float32),
            "u_model_view": mv.T.astype(np.float32),
            "u_prev_model_view": prev_mv.T.astype(np.float32),
            "u_normal_matrix": np.linalg.inv(model[:3, :3]).astype(np.float32),  # (M^-1)^T, column-major
            "u_base_color": np.array(g.obj.material.base_color, np.float32),
        }
        for name, value in values.items():
            if name in members:
                prog[name].write(value.tobytes())
        if g.texture is not None and not moving:
            g.texture.use(0)
        if "u_has_texture" in members:
            prog["u_has_texture"].value = g.texture is not None
        if moving and "u_object_index" in members:
            prog["u_object_index"].value = float(g.index)
        if prog_name.startswith("vertex"):
            self._render_mesh(self._tessellated(g, edge_deg, eye, t), key, prog, self.ctx.TRIANGLES, mv, cull)
        elif prog_name.startswith("tess"):
            self._render_mesh(g.original, key, prog, self.ctx.PATCHES, mv, cull)
        elif prog_name == "cube":
            self._render_mesh(g.original, key, prog, self.ctx.TRIANGLES, mv, True, planes)
        else:
            g.original.vao(key, prog).render(self.ctx.TRIANGLES)
        return layer

    def _begin(self, target: RenderTarget) -> None:
        ctx = self.ctx
        if target.motion_fbo is not None:
            target.motion_fbo.clear(0.0, 0.0, 0.0, 0.0)   # not moving
        target.fbo.use()
        ctx.viewport = (0, 0, target.width, target.height)
        ctx.enable_only(ctx.DEPTH_TEST)
        target.fbo.clear(*self.scene.sky_color[:3], 1.0, depth=1.0)
        # clear() sets every attachment to the same value; distance must read 0.
        n = len(target.fbo.color_attachments)
        target.fbo.color_mask = [(False, False, False, False)] + [(True, True, True, True)] * (n - 1)
        target.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        target.fbo.color_mask = [(True, True, True, True)] * n

    def render_wide(self, target: RenderTarget, pose: Pose, t: float, projection: str | None = None,
                    peel: tuple | None = None, motion_dt: float | None = None, mark_peeled: bool = True,
                    max_edge_deg: float | None = None) -> None:
        """Wide-angle view at ``pose`` (camera-to-world) and scene time ``t`` into ``target``.

        ``peel = (primary_target, primary_pose, tolerance)`` depth-peels this view against a
        primary view already rendered into ``primary_target``: only surfaces the primary
        view does not show are kept (the dual view's extra view). ``motion_dt``: also write the
        motion of moving objects over the last ``motion_dt`` seconds (a target with motion).
        ``mark_peeled``: pixels whose every surface was peeled away get distance PEELED
        (protocol/depth.py) instead of staying 0 like sky; costs the early depth test.
        ``max_edge_deg``: longest edge (view angle) rasterised straight, if not the renderer's own
        (see :func:`edge_angle_for_width`); the first view at a new angle builds its tessellation.
        """
        projection = projection or self.projection
        if projection not in PROJECTIONS:
            raise ValueError(f"projection must be one of {', '.join(PROJECTIONS)}, got {projection!r}")
        self.drawn_triangles = 0
        if projection == "cube":
            if peel is None:
                self._render_cube(target, pose, t, motion_dt)
                return
            projection = "vertex"   # peeled views (the extra view) are drawn in one pass
        self._begin(target)
        self.ctx.enable_direct(GL_CLIP_DISTANCE0)
        name = projection
        uniforms = {"u_near": float(self.scene.near), "u_far": float(self.scene.far),
                    "u_half_px": (target.width / 2.0, target.height / 2.0)}
        if peel is not None:
            primary_target, primary_pose, tolerance = peel
            name = projection + ("_peel_mark" if mark_peeled else "_peel")
            primary_target.distance.use(1)
            # this camera -> world -> primary camera, composed in float64
            from_cam = primary_pose.view_matrix() @ pose.matrix()
            uniforms.update({"u_peel_from_cam": from_cam.T, "u_peel_tolerance": float(tolerance),
                             "u_peel_size": (float(primary_target.width), float(primary_target.height)),
                             "u_sky_color": tuple(float(c) for c in self.scene.sky_color[:3])})
        if projection == "tess":
            self.ctx.patch_vertices = 3
            angle = self.max_edge_angle if max_edge_deg is None else np.radians(max_edge_deg)
            uniforms.update({"u_half_size": (target.width / 2.0, target.height / 2.0), "u_max_angle": float(angle)})
        if not self.wide_trilinear:
            self._mip_nearest.use(0)
        try:
            self._draw(name, pose.view_matrix(), pose.p, t, uniforms, motion_dt, cull=self.cull,
                       edge_deg=max_edge_deg, target=target)
        finally:  # shaders that never write gl_ClipDistance must not run with it enabled
            self.ctx.disable_direct(GL_CLIP_DISTANCE0)
            self._mip_nearest.clear(0)

    def _render_cube(self, target: RenderTarget, pose: Pose, t: float, motion_dt: float | None) -> None:
        """The wide view as five perspective faces of the original meshes, resampled (cube_faces.py)."""
        ctx = self.ctx
        n = max(2, 2 * int(round(self.cube_scale * target.width / 2)))
        key = (n, target.motion is not None)
        cube = self._cube_targets.get(key)
        if cube is None:
            cube = self._cube_targets[key] = RenderTarget(ctx, 2 * n, 2 * n, motion=target.motion is not None)
            cube.color.filter = (ctx.LINEAR, ctx.LINEAR)
        self._begin(cube)
        near, far = float(self.scene.near), float(self.scene.far)
        view = pose.view_matrix()
        if not self.wide_trilinear:
            self._mip_nearest.use(0)
        for name, (x, y, w, h) in cube_faces.face_rects(n).items():
            ctx.viewport = (x, y, w, h)
            self._draw("cube", view, pose.p, t, {"u_face": cube_faces.face_matrix(name, near, far).T,
                                                 "u_half_px": (target.width / 2.0, target.height / 2.0)},
                       motion_dt, planes=cube_faces.face_planes(name, near), target=cube)
        self._mip_nearest.clear(0)
        (target.fbo if target.all_fbo is None else target.all_fbo).use()   # the resample writes motion too
        ctx.viewport = (0, 0, target.width, target.height)
        ctx.disable(ctx.DEPTH_TEST)
        cube.color.use(0)
        cube.distance.use(1)
        if cube.motion is not None:
            cube.motion.use(2)
        prog = self._resample
        prog["u_n"].value = float(n)
        prog["u_size"].value = (float(target.width), float(target.height))
        self._resample_vao.render(ctx.TRIANGLE_STRIP)
        ctx.enable(ctx.DEPTH_TEST)

    def render_perspective(self, target: RenderTarget, pose: Pose, t: float, fov_x_deg: float,
                           frustum=None) -> None:
        """Perspective view (ground truth) at ``pose`` and scene time ``t``, horizontal FOV ``fov_x_deg``,
        or through ``frustum`` ((left, right, down, up) tangents, protocol/frustum.py: an eye's
        asymmetric one) when given. A target with motion also gets which moving object each pixel
        shows (RenderTarget.read_moving_index)."""
        self._begin(target)
        proj = perspective_matrix(fov_x_deg, target.width / target.height, self.scene.near, self.scene.far) \
            if frustum is None else frustum_projection(frustum, self.scene.near, self.scene.far)
        self._draw("perspective", pose.view_matrix(), pose.p, t, {"u_projection": proj.T},
                   motion_dt=0.0 if target.motion is not None else None, target=target)

    def release(self) -> None:
        for g in self.objects:
            g.original.release()
            for m in g.meshes():
                m.release()
            if g.texture is not None:
                g.texture.release()
        for c in self._cube_targets.values():
            c.release()
        self._resample_vao.release()
        self._quad.release()
        self._mip_nearest.release()
        for p in self.programs.values():
            p.release()
        self._resample.release()
