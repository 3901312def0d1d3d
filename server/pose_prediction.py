"""Head-pose prediction: where the head will be when a frame rendered now is shown.

A server that renders for the pose it received shows the client a view ``look-ahead`` seconds
stale (the round trip, the server's and client's own delays). Rendering for the pose predicted
at the display time instead leaves the client less to warp, if the prediction is good. Four
predictors, each fed the poses as they arrive (``update(t, pose)``, times increasing) and asked
for the pose ``look_ahead_s`` after the newest (``predict``):

- ``none``: the newest pose (what pibr renders without prediction);
- ``velocity``: constant linear and angular velocity from the last two poses;
- ``accel``: constant linear and angular acceleration from the last three;
- ``kalman``: a constant-velocity Kalman filter over the position (per axis: position and
  velocity) and over the orientation's quaternion components (per component: value and rate),
  as Gül et al. 2020 do for volumetric video streaming; each incoming quaternion is first
  flipped to the hemisphere of the filter's estimate (q and -q are one rotation, and a flip
  would look like a jump to a linear filter), and the predicted quaternion is normalised. Its
  noise levels were fitted on the tuning windows (``pibr bench predict --fit``,
  docs/results/predict-tuning.json) and only there.

Predictions are capped at :data:`MAX_EXTRAPOLATION_S` ahead: beyond that a head's motion is no
longer smooth enough for any of these models.
"""
from __future__ import annotations

import math

import numpy as np

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose, quat_multiply, quat_conjugate, quat_normalize

PREDICTORS = ("none", "velocity", "accel", "kalman")
#: No prediction reaches further than this (s).
MAX_EXTRAPOLATION_S = 0.5
#: The Kalman filter's noise levels, fitted on the tuning windows (pibr bench predict --fit):
#: process noise as the spectral density of the (random) acceleration, (m/s^2)^2 s for the
#: position and (1/s^2)^2 s for the quaternion components; measurement noise as a standard
#: deviation (m, and quaternion units).
#: What decides the filter is the ratio q / r^2 (position 1.6e7, orientation 4.1e5 here); the
#: orientation's best pair lies at the grid's largest q and r, its ratio inside the grid.
KALMAN_POSITION_Q, KALMAN_POSITION_R = 64.0, 0.002
KALMAN_ORIENTATION_Q, KALMAN_ORIENTATION_R = 4096.0, 0.1


def _rotation_vector(q: np.ndarray) -> np.ndarray:
    """(3,) axis * angle of unit quaternion q (w, x, y, z), the short way round."""
    q = q if q[0] >= 0 else -q
    s = np.linalg.norm(q[1:])
    if s < 1e-12:
        return 2.0 * q[1:]
    return q[1:] / s * 2.0 * math.atan2(s, q[0])


def _quat_from_rotation_vector(v: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return quat_normalize(np.array([1.0, *(0.5 * v)]))
    return np.array([math.cos(angle / 2), *(math.sin(angle / 2) * v / angle)])


class Predictor:
    """Base: keeps the last poses; ``predict`` with nothing yet is an error."""

    name = "?"
    history = 1

    def __init__(self):
        self.times: list[float] = []
        self.poses: list[Pose] = []

    def update(self, t: float, pose: Pose) -> None:
        if self.times and t == self.times[-1]:
            return   # a repeated pose adds nothing
        if self.times and t < self.times[-1]:
            self.reset()   # an earlier time: a new timeline (a client's clock starting after its warm-up)
        self.times.append(float(t))
        self.poses.append(pose)
        if len(self.times) > self.history:
            del self.times[0], self.poses[0]

    def reset(self) -> None:
        self.times, self.poses = [], []

    def predict(self, look_ahead_s: float) -> Pose:
        if not self.poses:
            raise ValueError("no pose to predict from yet")
        return self._predict(min(max(0.0, float(look_ahead_s)), MAX_EXTRAPOLATION_S))

    def _predict(self, dt: float) -> Pose:
        return self.poses[-1]


class NoPrediction(Predictor):
    name = "none"


class VelocityPredictor(Predictor):
    """Constant linear and angular velocity from the last two poses."""

    name = "velocity"
    history = 2

    def _predict(self, dt: float) -> Pose:
        if len(self.poses) < 2:
            return self.poses[-1]
        (t0, t1), (a, b) = self.times, self.poses
        h = t1 - t0
        p = b.p + (b.p - a.p) * dt / h
        omega = _rotation_vector(quat_multiply(b.q, quat_conjugate(a.q))) / h   # world-frame rate
        return Pose.make(p, quat_normalize(quat_multiply(_quat_from_rotation_vector(omega * dt), b.q)))


class AccelPredictor(Predictor):
    """Constant linear and angular acceleration from the last three poses."""

    name = "accel"
    history = 3

    def _predict(self, dt: float) -> Pose:
        if len(self.poses) < 3:
            return VelocityPredictor._predict(self._last_two(), dt)
        (t0, t1, t2), (a, b, c) = self.times, self.poses
        h1, h2 = t1 - t0, t2 - t1
        v1, v2 = (b.p - a.p) / h1, (c.p - b.p) / h2
        acc = (v2 - v1) / (0.5 * (h1 + h2))
        p = c.p + v2 * dt + 0.5 * acc * (dt * dt + dt * h2)   # v2 is the velocity half an interval back
        w1 = _rotation_vector(quat_multiply(b.q, quat_conjugate(a.q))) / h1
        w2 = _rotation_vector(quat_multiply(c.q, quat_conjugate(b.q))) / h2
        alpha = (w2 - w1) / (0.5 * (h1 + h2))
        turn = w2 * dt + 0.5 * alpha * (dt * dt + dt * h2)
        return Pose.make(p, quat_normalize(quat_multiply(_quat_from_rotation_vector(turn), c.q)))

    def _last_two(self):
        two = VelocityPredictor()
        for t, pose in zip(self.times, self.poses):
            two.update(t, pose)
        return two


class _ConstantVelocityKF:
    """Independent constant-velocity Kalman filters, one per column of an (n,) measurement."""

    def __init__(self, n: int, q: float, r: float):
        self.n, self.q, self.r = n, q, r
        self.x = np.zeros((n, 2))               # value, rate
        self.P = np.tile(np.eye(2) * 1e3, (n, 1, 1))
        self.t: float | None = None

    def update(self, t: float, z: np.ndarray) -> None:
        if self.t is None:
            self.x[:, 0], self.x[:, 1] = z, 0.0
            self.P[:] = np.diag([self.r ** 2, 1.0])
            self.t = t
            return
        self._advance(t - self.t)
        self.t = t
        # measurement of the value only: H = [1, 0]
        s = self.P[:, 0, 0] + self.r ** 2
        k = self.P[:, :, 0] / s[:, None]          # (n, 2)
        y = z - self.x[:, 0]
        self.x += k * y[:, None]
        self.P -= k[:, :, None] * self.P[:, 0, :][:, None, :]

    def _advance(self, dt: float) -> None:
        f = np.array([[1.0, dt], [0.0, 1.0]])
        qm = self.q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
        self.x = self.x @ f.T
        self.P = f @ self.P @ f.T + qm

    def predict(self, dt: float) -> np.ndarray:
        return self.x[:, 0] + self.x[:, 1] * dt


class KalmanPredictor(Predictor):
    """Constant-velocity Kalman filters over the position and the quaternion (module docstring)."""

    name = "kalman"

    def __init__(self, position_q=KALMAN_POSITION_Q, position_r=KALMAN_POSITION_R,
                 orientation_q=KALMAN_ORIENTATION_Q, orientation_r=KALMAN_ORIENTATION_R):
        super().__init__()
        self.position = _ConstantVelocityKF(3, position_q, position_r)
        self.orientation = _ConstantVelocityKF(4, orientation_q, orientation_r)

    def reset(self) -> None:
        super().reset()
        self.position = _ConstantVelocityKF(3, self.position.q, self.position.r)
        self.orientation = _ConstantVelocityKF(4, self.orientation.q, self.orientation.r)

    def update(self, t: float, pose: Pose) -> None:
        if self.times and t == self.times[-1]:
            return
        super().update(t, pose)
        q = np.asarray(pose.q, np.float64)
        if self.orientation.t is not None and float(np.dot(q, self.orientation.x[:, 0])) < 0:
            q = -q   # the same rotation, on the filter's side
        self.position.update(t, np.asarray(pose.p, np.float64))
        self.orientation.update(t, q)

    def _predict(self, dt: float) -> Pose:
        return Pose.make(self.position.predict(dt), quat_normalize(self.orientation.predict(dt)))


def make_predictor(name: str, **settings) -> Predictor:
    classes = {c.name: c for c in (NoPrediction, VelocityPredictor, AccelPredictor, KalmanPredictor)}
    if name not in classes:
        raise ConfigError(f"unknown pose predictor {name!r}; choose from {', '.join(PREDICTORS)}")
    return classes[name](**settings)


def display_look_ahead_s(render_us: int, pose_t_us: int, server_delay_us: int, uplink_us: int,
                         frame_interval_us: int) -> float:
    """How far ahead of its pose a frame is seen, on average: from the pose's client time to the
    middle of the frame's time on screen. The frame leaves ``server_delay_us`` after its render,
    crosses a downlink taken to be as long as the uplink the pose took (the server measures that
    one), and is the newest frame for about one frame interval."""
    return (render_us - pose_t_us + server_delay_us + uplink_us + frame_interval_us / 2) / 1e6
