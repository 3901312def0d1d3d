"""One session's pipeline, from a pose to a ``Frame``: the one place it is built, for the
server's sessions and for every benchmark.

:class:`SessionPipeline` is made from the server's settings (:class:`~pibr.server.config.ServerConfig`),
the scene and the client's ``Hello``: the session plan (session_plan.py) decides what the frames
hold, then

    pose --FrameProducer (GL thread)--> ProducedFrame: the views rendered, read back, the atlas packed
         --H.264 encoder-------------> the atlas's access unit
         --depth encoder-------------> depth payloads of the session's depth codec (depth_encoders.py)
         --quadtree, motion flow-----> the payloads a client asked for or a moving scene needs
         --frame()-------------------> the Frame message

The server runs each stage where it belongs (rendering on its shared GL thread, encoders in its
pool, concurrently where they are independent); a benchmark calls :meth:`SessionPipeline.encode`,
which runs them in order. Either way the payloads are assembled by :class:`EncodedFrame`, in one
order.

The :class:`~pibr.server.producer.FrameProducer` lives on the GL thread (producer.py).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from pibr.protocol.messages import Frame, PayloadKind, encode_eye, encode_frame_level
from pibr.protocol.pose import Pose

from .depth_encoders import make_depth_encoder
from .producer import FULL, FrameLevel, FrameProducer, ProducedFrame
from .renderer import Renderer
from .session_plan import plan_session


@dataclass
class EncodedFrame:
    """A produced frame's coded streams: ``video`` the H.264 access unit (``keyframe`` whether it
    is one), ``depth`` the depth codec's payloads, ``quadtree`` and ``motion`` their payloads or None,
    ``object_poses`` the moving objects' transforms or None."""

    video: bytes
    keyframe: bool
    depth: list
    quadtree: bytes | None = None
    object_poses: bytes | None = None
    motion: bytes | None = None
    level: int | None = None      # the rate control's level the frame was made at (None: no rate control)
    eye: str | None = None        # a stereo session's eye the frame was rendered for (None: the head's centre)
    stream_rate: bytes | None = None  # the STREAM_RATE payload of an adapting session (None: no adaptation)

    @property
    def payloads(self) -> tuple:
        """The Frame's payloads, always in this order: atlas, depth, quadtree, object poses, motion
        flow, the frame's level, its eye, its stream rate."""
        out = [(PayloadKind.H264_ATLAS, self.video), *self.depth]
        for kind, data in ((PayloadKind.QUADTREE, self.quadtree), (PayloadKind.OBJECT_POSES, self.object_poses),
                           (PayloadKind.MOTION_FLOW, self.motion),
                           (PayloadKind.FRAME_LEVEL, None if self.level is None else encode_frame_level(self.level)),
                           (PayloadKind.EYE, None if self.eye is None else encode_eye(self.eye)),
                           (PayloadKind.STREAM_RATE, self.stream_rate)):
            if data is not None:
                out.append((kind, data))
        return tuple(out)

    @property
    def nbytes(self) -> int:
        return sum(len(d) for _, d in self.payloads)


class SessionPipeline:
    """Everything that makes one session's frames (module docstring).

    config : the server's :class:`~pibr.server.config.ServerConfig`; scene : the loaded scene;
    hello : the client's ``Hello``; proxies, coverage, proxy_levels : as :func:`~pibr.server.session_plan.plan_session`
    takes them. ``deterministic`` (default: on the virtual clock) encodes on one thread so that
    the same frames give the same bytes. ``keep_distance``: also hand the views' float distances
    to the caller (benchmarks measure against them). ``depth_encoder``: a callable (session, fps) ->
    an encoder (``encode(produced)`` -> [(kind, bytes)], ``close()``) to use instead of the session
    codec's, e.g. a benchmark's competing codec; made again when the stream restarts.

    Not GL: call :meth:`open` on the GL thread before :meth:`produce`, and :meth:`release` there.
    """

    def __init__(self, config, scene, hello, proxies: dict | None = None, coverage: dict | None = None,
                 proxy_levels=None, deterministic: bool | None = None, keep_distance: bool = False,
                 depth_encoder=None):
        self.config, self.scene = config, scene
        self.session, spec = plan_session(config, scene, hello, proxies, coverage, proxy_levels)
        if keep_distance and not spec.keep_distance:
            spec = dataclasses.replace(spec, keep_distance=True)
        self.spec = spec
        self.deterministic = hello.clock == "virtual" if deterministic is None else deterministic
        self.quadtree_threshold = hello.quadtree_threshold   # > 0: every frame carries the views' quadtrees
        self._make_depth = depth_encoder or (lambda session, fps: make_depth_encoder(session, fps, config.edge))
        self.video = self.new_video_encoder()
        self.depth = self._make_depth(self.session, config.fps)
        self.producer: FrameProducer | None = None

    # ------------------------------------------------------------------ GL thread

    def open(self, ctx, renderer: Renderer | None = None) -> "SessionPipeline":
        """Make the producer on ``ctx``'s thread. ``renderer``: the scene's, shared (the server's);
        None: one of its own, drawn as the config says, released with the pipeline."""
        self._own_renderer = renderer is None
        if renderer is None:
            renderer = Renderer(ctx, self.scene, self.config.projection, max_edge_angle_deg=self.config.max_edge_deg)
        self.renderer = renderer
        self.producer = FrameProducer(ctx, renderer, self.spec)
        return self

    def produce(self, pose: Pose, t: float, level: FrameLevel = FULL, frame_id: int | None = None,
                keep_colour: bool = False) -> ProducedFrame:
        """Render, read back and pack the frame of ``pose`` at scene time ``t`` (GL thread), made
        at ``level`` (server/rate_control.py; default: all of it) for the Frame ``frame_id`` (default:
        the producer's count from 0); ``keep_colour``: hand the views' whole colour too."""
        return self.producer.produce(pose, t, level, frame_id, keep_colour)

    def release(self) -> None:
        """Release the GL resources (GL thread) and close the encoders."""
        if self.producer is not None:
            self.producer.release()
            self.producer = None
            if self._own_renderer:
                self.renderer.release()
        self.close_encoders()

    # ------------------------------------------------------------------ encoders (any thread)

    def new_video_encoder(self, fps: float | None = None, kbps: float | None = None):
        """An H.264 encoder of the session's atlas with the server's settings (``fps`` and ``kbps``:
        others than the session's, e.g. a benchmark's zero-latency oracle stream)."""
        from .video import H264Encoder

        layout, cfg = self.spec.layout, self.config
        return H264Encoder(layout.width, layout.height, cfg.fps if fps is None else fps,
                           self.session.video_bitrate_kbps if kbps is None else kbps, cfg.keyint, cfg.preset,
                           deterministic=self.deterministic)

    def restart_stream(self) -> None:
        """Fresh encoders, as a new session's stream starts (the next frame is a keyframe)."""
        self.close_encoders()
        self.video = self.new_video_encoder()
        self.depth = self._make_depth(self.session, self.config.fps)

    def close_encoders(self) -> None:
        self.video.close()
        self.depth.close()

    def adapt_stream(self, video_kbps: float, share: float, at_once: bool = False) -> None:
        """The stream adaptation's choice for the frames to come (server/stream_adaptation.py): the
        colour's target (``at_once``: from the next frame, H264Encoder.retarget), and ``share`` of
        its rate for a depth stream of its own. Call between frames."""
        self.video.retarget(video_kbps, at_once)
        set_share = getattr(self.depth, "set_share", None)
        if set_share is not None:
            set_share(share)

    def encode_video(self, produced: ProducedFrame, force_keyframe: bool = False) -> tuple[bytes, bool]:
        return self.video.encode(produced.yuv, force_keyframe)

    def encode_depth(self, produced: ProducedFrame) -> list:
        return self.depth.encode(produced)

    def encode_quadtree(self, produced: ProducedFrame) -> bytes | None:
        """The views' quadtrees when the client asked for them (``Hello.quadtree_threshold``), else None."""
        if self.quadtree_threshold <= 0:
            return None
        from .quadtree import quadtree_payload

        return quadtree_payload(produced.distances, self.quadtree_threshold)

    def encode_motion(self, produced: ProducedFrame) -> bytes | None:
        """The motion flow of a scene that moves (whatever the depth codec), else None."""
        if produced.motion is None:
            return None
        from .motion_flow import motion_flow_payload

        return motion_flow_payload(produced, self.config.flow_coder)

    def encode(self, produced: ProducedFrame, force_keyframe: bool = False, level: int | None = None) -> EncodedFrame:
        """Every stream of ``produced``, in order, on this thread (``level``: the rate control's
        level it was made at, sent with it)."""
        video, key = self.encode_video(produced, force_keyframe)
        return EncodedFrame(video, key, self.encode_depth(produced), self.encode_quadtree(produced),
                            produced.object_poses, self.encode_motion(produced), level)

    def frame(self, frame_id: int, render_t_us: int, pose_t_us: int, pose_seq: int, produced: ProducedFrame,
              encoded: EncodedFrame, timings_ms: tuple = (0.0, 0.0, 0.0, 0.0)) -> Frame:
        """The Frame message of ``produced`` (rendered at ``render_t_us``, which is also its scene time)."""
        if self.session.colour_scale != 1.0 and produced.frame_id != frame_id:
            raise ValueError(f"frame {frame_id} was produced for frame id {produced.frame_id}: its colour's jitter "
                             f"would not be the one the client expects")
        return Frame(frame_id=frame_id, render_t_us=render_t_us, pose_t_us=pose_t_us, pose_seq=pose_seq,
                     scene_t_us=render_t_us, primary_pose=produced.primary_pose, extra_pose=produced.extra_pose,
                     near=self.session.near, far=self.session.far, timings_ms=timings_ms,
                     payloads=encoded.payloads, keyframe=encoded.keyframe)

