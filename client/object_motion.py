"""Where moving objects are at display time, from the transforms the frames carried.

Each ``Frame`` of a scene that moves carries every moving object's rigid motion at the
frame's scene time (protocol/object_poses.py); the client keeps the last few per object
(:class:`PoseHistory`) and places each object's proxy at the display time (*extrapolation*,
Pajak et al. 2011's temporal upsampling done on object transforms instead of pixels):

* ``static``: where the newest received transform puts it (a lower bound);
* ``velocity``: constant linear velocity of the object's centre and constant angular velocity
  about it, from the last two transforms. The angular velocity is the relative rotation's
  axis-angle over their time step, taken the short way round: exact up to half a turn per
  frame interval; a faster spin is seen turning backwards (it aliases, as any sampling does);
* ``accel`` (the default): second order, velocity and acceleration from the last three
  transforms, the acceleration's correction limited to the first order's own displacement
  (ACCEL_LIMIT), so a start or stop between frames cannot throw an object about;
* ``oracle``: the scene's own animation, which only the benchmarks have (they pass a callable;
  the client process never has one);
* ``flow``: not per object but per pixel: the moving pixels of the newest frame warped along
  their decoded motion flow (client/flow_warp.py); no proxy needed.

Fitted on the tuning windows (issue 26: the first choice was made on evaluation windows):
``pibr bench dynamic --windows tuning --latency-ms 128 --stride 6`` (pred6dof-1 and -2 from 10 s
for 12 s, where the moving objects are in view on 94 and 65 of 120 scored ticks;
docs/results/dynamic-tuning.json, re-run on 2026-12-03 with x264's undershoot going back to the
colour), DSSIM over the moving objects' pixels: in ``dynamic`` static 0.257, velocity 0.150,
accel 0.108, flow 0.181 (oracle 0.081); in ``room`` static 0.388, velocity 0.173, accel 0.162,
flow 0.224 (oracle 0.159). The second order follows curves (the
ball's circle, the pendulum's arc) that a straight line leaves; hence the default, which the
evaluation windows confirm (README, "Moving objects"). Without ACCEL_LIMIT it measured within
1 % of that (dynamic at 256 ms: 0.236 against 0.238; evaluation windows, before the split).

The horizon is bounded: the extrapolation runs at full speed for ``horizon_frames`` frame
intervals past the newest transform (3: a frame is normally shown 1.5 to 2.5 intervals after
its scene time at 128 ms; see DEFAULT_HORIZON_FRAMES) and beyond that slows exponentially,
with a time constant of half that horizon, so a late or lost frame leaves the object at most
1.5 horizons' travel from its last received place, never flying off. Going back in time is
limited to one horizon too.
"""
from __future__ import annotations

import math
import threading
from collections import deque

import numpy as np

from pibr.protocol.object_poses import ObjectPoses
from pibr.protocol.pose import quat_from_matrix, quat_to_matrix

MOTION_MODES = ("static", "velocity", "accel", "oracle", "flow")
#: What a client process can run: ``oracle`` needs the scene's animation (benchmarks only).
CLIENT_MOTION_MODES = ("static", "velocity", "accel", "flow")
DEFAULT_MOTION = "accel"
#: Frame intervals past the newest transform extrapolated at full speed; then damped.
DEFAULT_HORIZON_FRAMES = 3.0
#: The second order's correction is at most this share of the first order's displacement: a
#: start or a stop between two frames looks like a huge acceleration, and unchecked the parabola
#: would throw the object backwards after a stop (see test_a_stop_between_frames_and_a_start).
ACCEL_LIMIT = 1.0
#: Transforms kept per object (the second order uses three).
HISTORY = 4


def rotation_log(r: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) (axis * angle, angle in [0, pi]) of a rotation matrix (3, 3).

    Through the quaternion: angle = 2 atan2(|v|, w) is accurate at 0 and at pi alike."""
    q = quat_from_matrix(r)          # w >= 0: the short way round
    v = q[1:]
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        return 2.0 * v               # small angles: angle ~ 2 |v|, along v
    return v / s * (2.0 * math.atan2(s, q[0]))


def rotation_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a rotation vector (3,)."""
    angle = float(np.linalg.norm(w))
    if angle < 1e-15:
        return np.eye(3)
    h = 0.5 * angle
    return quat_to_matrix(np.concatenate([[math.cos(h)], w / angle * math.sin(h)]))


def damped_horizon(dt: float, horizon: float) -> float:
    """The time to extrapolate by when ``dt`` seconds have passed since the newest transform:
    dt itself within [-horizon, horizon], then approaching 1.5 horizons (slowing exponentially)."""
    if horizon <= 0:
        return 0.0
    if dt < -horizon:
        return -horizon
    if dt <= horizon:
        return dt
    tau = 0.5 * horizon
    return horizon + tau * (1.0 - math.exp(-(dt - horizon) / tau))


class PoseHistory:
    """The newest received transforms of each moving object, by scene time; thread-safe (the
    receiver adds while the GL thread reads).

    rest : (n, 4, 4) rest transforms of the scene's objects (the proxy bundle's), or None
           (then every object's reference point is the origin of its parent frame).
    bounds : (n, 2, 3) object-space boxes; their centres are the points whose velocity is
           extrapolated (a spinning object's centre stays put).
    """

    def __init__(self, rest=None, bounds=None, depth: int = HISTORY):
        self._lock = threading.Lock()
        self._tracks: dict[int, deque] = {}
        self._times: deque = deque(maxlen=depth)
        self.depth = depth
        self._centres = None
        if rest is not None:
            rest = np.asarray(rest, np.float64).reshape(-1, 4, 4)
            c = np.zeros((len(rest), 3)) if bounds is None else np.asarray(bounds, np.float64).reshape(-1, 2, 3).mean(1)
            self._centres = np.einsum("nij,nj->ni", rest[:, :3, :3], c) + rest[:, :3, 3]

    def centre(self, index: int) -> np.ndarray:
        """The object's reference point at rest, world space (3,)."""
        if self._centres is None or index >= len(self._centres):
            return np.zeros(3)
        return self._centres[index]

    @property
    def newest_time(self) -> float | None:
        with self._lock:
            return self._times[-1] if self._times else None

    def clear(self) -> None:
        with self._lock:
            self._tracks.clear()
            self._times.clear()

    def add(self, t: float, poses: ObjectPoses) -> None:
        """The transforms of a frame at scene time ``t``. A time already held is ignored; an
        earlier one starts a new timeline (a benchmark replaying another window)."""
        matrices = poses.matrices()
        with self._lock:
            if self._times and t <= self._times[-1]:
                if t in self._times:
                    return
                self._tracks.clear()
                self._times.clear()
            self._times.append(t)
            for index, m in zip(poses.indices.tolist(), matrices):
                track = self._tracks.get(index)
                if track is None:
                    track = self._tracks[index] = deque(maxlen=self.depth)
                track.append((t, m))

    def track(self, index: int) -> list:
        """[(scene time, (4, 4) motion)] of one object, oldest first (empty: nothing received)."""
        with self._lock:
            return list(self._tracks.get(index, ()))

    def indices(self) -> list[int]:
        with self._lock:
            return list(self._tracks)


def _centre_motion(track: list, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """-> times (k,), centre positions (k, 3), rotations (k, 3, 3) of a track."""
    t = np.array([s for s, _ in track])
    m = np.stack([x for _, x in track])
    return t, np.einsum("kij,j->ki", m[:, :3, :3], centre) + m[:, :3, 3], m[:, :3, :3]


def _limited(x: np.ndarray, length: float) -> np.ndarray:
    """x (3,) shortened to at most ``length``."""
    n = float(np.linalg.norm(x))
    return x if n <= length or not math.isfinite(length) else x * (length / n)


def extrapolate(track: list, t: float, mode: str, horizon: float, centre=np.zeros(3)) -> np.ndarray | None:
    """(4, 4) rigid motion of one object at scene time ``t`` from its received ``track``
    ([(time, (4, 4))], oldest first), or None if nothing was received.

    mode : ``static``, ``velocity`` or ``accel`` (see the module docstring)
    horizon : seconds extrapolated at full speed (see :func:`damped_horizon`)
    centre : (3,) world point at rest whose path is extrapolated linearly
    """
    if not track:
        return None
    t_new, newest = track[-1]
    order = {"static": 1, "velocity": 2, "accel": 3}[mode]
    if order == 1 or len(track) < 2:
        return newest
    times, c, r = _centre_motion(track[-min(order, len(track)):], np.asarray(centre, np.float64))
    s = damped_horizon(t - t_new, horizon)
    dts = np.diff(times)
    v = (c[1:] - c[:-1]) / dts[:, None]                               # (k-1, 3), at the mid-points
    w = np.stack([rotation_log(r[i + 1] @ r[i].T) for i in range(len(dts))]) / dts[:, None]
    lin, ang = v[-1] * s, w[-1] * s
    if len(dts) == 2:   # second order: acceleration between the two mid-point velocities
        span = 0.5 * (dts[0] + dts[1])
        # The parabola through the samples: from the last mid-point velocity on, the acceleration
        # adds a (s^2 + s dt) / 2 -- at most ACCEL_LIMIT of the first order's own displacement.
        grow = 0.5 * s * (s + dts[1]) / span
        lin = lin + _limited((v[1] - v[0]) * grow, ACCEL_LIMIT * np.linalg.norm(lin))
        ang = ang + _limited((w[1] - w[0]) * grow, ACCEL_LIMIT * np.linalg.norm(ang))
    rot = rotation_exp(ang) @ r[-1]
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = c[-1] + lin - rot @ np.asarray(centre, np.float64)
    return out


class ObjectPlacer:
    """Per display: each moving object's motion (world = motion @ rest) under one mode.

    history : the :class:`PoseHistory` the frames fill
    frame_interval : seconds between server frames (the horizon's unit)
    oracle : ``oracle(index, t) -> (4, 4)``, the scene's animation (benchmarks only)
    """

    def __init__(self, history: PoseHistory, mode: str = DEFAULT_MOTION, frame_interval: float = 0.1,
                 horizon_frames: float = DEFAULT_HORIZON_FRAMES, oracle=None):
        from pibr.protocol.errors import ConfigError

        if mode not in MOTION_MODES:
            raise ConfigError(f"unknown motion extrapolation {mode!r}; choose from {', '.join(MOTION_MODES)}")
        if mode == "oracle" and oracle is None:
            raise ConfigError("motion 'oracle' needs the scene's animation, which only the benchmarks have; "
                              f"a client chooses from {', '.join(CLIENT_MOTION_MODES)}")
        if not (frame_interval > 0 and horizon_frames >= 0):
            raise ConfigError("the extrapolation horizon needs a positive frame interval and horizon_frames >= 0")
        self.history, self.mode, self.oracle = history, mode, oracle
        self.horizon = horizon_frames * frame_interval

    def motions(self, indices, t: float) -> dict:
        """index -> (4, 4) motion at scene time ``t`` for each of ``indices`` (moving objects);
        those nothing was received for stay at rest (left out)."""
        out = {}
        for i in indices:
            if self.mode == "oracle":
                out[i] = np.asarray(self.oracle(i, t), np.float64)
                continue
            m = extrapolate(self.history.track(i), t, self.mode, self.horizon, self.history.centre(i))
            if m is not None:
                out[i] = m
        return out
