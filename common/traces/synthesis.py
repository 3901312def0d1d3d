"""Synthetic head traces: walking, looking around, quick turns, and a mix of the three.

Every motion is built from *minimum-jerk* moves (s(u) = 10u^3 - 15u^4 + 6u^5): a channel
(walking speed, gaze direction) holds, then moves to a new value with zero velocity and
acceleration at both ends, so the result is C2 and segments join without jumps. A move's
peak rate is exactly 1.875 x amplitude / duration, which is how the requested peak speeds are
met: durations are derived from them, not the other way round.

Walking follows a smooth closed loop through the origin (like walking around an object),
by arc length, so the body heading is the loop's tangent and its rate is curvature x speed;
the loop is made large enough that this stays within the turn budget. Gaze moves SLERP
between roll-free (yaw, pitch) targets relative to the body, so their angular speed is exactly
the move's rate. The head orientation is body heading (about +Y) times gaze; the position is
the walk plus head bob (while walking) and a slow postural sway (always). The trace starts at
(0, eye_height, 0) looking along -Z.
"""
from __future__ import annotations

import math

import numpy as np

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import quat_angle, quat_from_euler, quat_multiply, quat_slerp
from pibr.protocol.trace import HeadTrace

KINDS = ("walk", "look", "turns", "mixed")

#: Peak rate of a minimum-jerk move relative to its mean rate.
MIN_JERK_PEAK = 1.875
#: Rate of the internal grid (positions are integrated on it), at least this many Hz.
_INTERNAL_RATE_HZ = 500.0
#: Walking step frequency (Hz).
_STEP_HZ = 1.8
#: Share of the turn budget (turn_speed_deg) the walking path's heading may use; glances get the rest.
_HEADING_SHARE = 0.5
#: Look-around limits relative to the body (radians): people turn the body for more.
_LOOK_YAW = math.radians(75.0)
_LOOK_PITCH = (math.radians(-30.0), math.radians(25.0))


def synthesize(kind: str, duration_s: float, rate_hz: float = 120.0, seed: int = 0,
               walk_speed: float = 1.0, turn_speed_deg: float = 60.0, quick_turn_deg_s: float = 250.0,
               eye_height: float = 0.0, loop_radius: float = 2.5, sway_m: float = 0.005,
               bob_m: float = 0.015, segment_s: tuple[float, float] = (6.0, 12.0)) -> HeadTrace:
    """A deterministic synthetic head trace (same arguments, same trace).

    kind : 'walk' (around a smooth closed loop through the origin, about ``loop_radius`` m in
        radius, with head bob, looking mostly ahead with glances), 'look' (standing, looking
        around), 'turns' (mostly still, quick head turns), 'mixed' (segments of all three, each
        ``segment_s`` seconds long, joined at rest).
    duration_s, rate_hz : length and uniform sample rate of the result.
    walk_speed : horizontal walking speed (m/s) at cruise; bob and sway add about 1 %.
    turn_speed_deg : peak angular speed (deg/s) of looking around, and the bound on walking's
        heading rate plus glances (the loop grows beyond ``loop_radius`` if needed).
    quick_turn_deg_s : peak angular speed (deg/s) of the quick turns.
    eye_height : y of the start position (m). sway_m, bob_m : sway and head-bob amplitudes (m).
    """
    if kind not in KINDS:
        raise ConfigError(f"unknown synthetic trace kind {kind!r}; expected one of {', '.join(KINDS)}")
    for label, value in (("duration_s", duration_s), ("rate_hz", rate_hz), ("walk_speed", walk_speed),
                         ("turn_speed_deg", turn_speed_deg), ("quick_turn_deg_s", quick_turn_deg_s),
                         ("loop_radius", loop_radius)):
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"{label} must be a positive number, got {value!r}")
    if not math.isfinite(eye_height):
        raise ConfigError(f"eye_height must be a finite number, got {eye_height!r}")
    for label, value in (("sway_m", sway_m), ("bob_m", bob_m)):
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{label} must be a non-negative number, got {value!r}")
    if not (0 < segment_s[0] <= segment_s[1]):
        raise ConfigError(f"segment_s must be (shortest, longest) seconds, got {segment_s!r}")

    rng = np.random.default_rng(seed)
    oversample = max(1, math.ceil(_INTERNAL_RATE_HZ / rate_hz))
    count = int(math.floor(duration_s * rate_hz + 1e-9)) + 1
    fine_t = np.arange((count - 1) * oversample + 1) / (rate_hz * oversample)
    turn = math.radians(turn_speed_deg)
    loop = _Loop(rng, loop_radius, max_curvature=_HEADING_SHARE * turn / walk_speed)
    plan = _Plan(fine_t, walk_speed, loop)
    quick = math.radians(quick_turn_deg_s)

    segments = _segments(kind, duration_s, rng, segment_s)
    for segment_kind, end in segments:
        if segment_kind == "walk":
            plan.walk(end, rng, turn)
        elif segment_kind == "look":
            plan.look(end, rng, turn)
        else:
            plan.turns(end, rng, quick)

    positions, orientations = plan.render(rng, sway_m, bob_m * min(1.0, walk_speed))
    positions = positions[::oversample] + np.array([0.0, eye_height, 0.0])
    orientations = orientations[::oversample]
    t = np.arange(count) / rate_hz
    return HeadTrace.from_samples(t, positions, orientations, f"synth-{kind}-seed{seed}")


def _segments(kind: str, duration_s: float, rng, segment_s) -> list[tuple[str, float]]:
    """(kind, end time) of each segment. 'mixed' starts with all three kinds in random order
    (segments shortened if the trace is short), then picks kinds at random, never one twice
    in a row."""
    if kind != "mixed":
        return [(kind, duration_s)]
    kinds = ("walk", "look", "turns")
    order = [kinds[i] for i in rng.permutation(3)]
    out, start = [], 0.0
    while start < duration_s:
        if len(out) < 3:
            current = order[len(out)]
        else:
            choices = [k for k in kinds if k != out[-1][0]]
            current = choices[rng.integers(len(choices))]
        end = start + min(rng.uniform(*segment_s), duration_s / 3.0)
        if duration_s - end < min(segment_s[0] / 2, duration_s / 6.0):  # extend over a short rest
            end = duration_s
        out.append((current, end))
        start = end
    return out


def _min_jerk(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk progress 0 -> 1 for u in [0, 1], zero velocity and acceleration at the ends."""
    return u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)


class _Channel:
    """Keyframes (time, value); between consecutive keyframes the value moves min-jerk."""

    def __init__(self, value):
        self.times = [0.0]
        self.values = [value]

    @property
    def end(self) -> float:
        return self.times[-1]

    @property
    def value(self):
        return self.values[-1]

    def hold_until(self, t: float) -> None:
        if t > self.end:
            self.times.append(t)
            self.values.append(self.value)

    def move(self, target, duration: float) -> None:
        if duration > 0:
            self.times.append(self.end + duration)
            self.values.append(target)

    def progress(self, t: np.ndarray):
        """For each time (m,): index of the keyframe interval and min-jerk progress in it."""
        times = np.asarray(self.times)
        if times.size == 1:
            return np.zeros(t.size, dtype=int), np.zeros(t.size)
        i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 2)
        u = np.clip((t - times[i]) / (times[i + 1] - times[i]), 0.0, 1.0)
        return i, _min_jerk(u)

    def render_scalar(self, t: np.ndarray) -> np.ndarray:
        values = np.asarray(self.values, dtype=np.float64)
        if values.size == 1:
            return np.full(t.size, values[0])
        i, s = self.progress(t)
        return values[i] + (values[i + 1] - values[i]) * s


def _gaze_quat(yaw_pitch) -> np.ndarray:
    """Roll-free orientation(s) (..., 4) looking at (yaw, pitch) radians, yaw 0 = along -Z."""
    a = np.asarray(yaw_pitch, dtype=np.float64)
    return quat_from_euler(np.concatenate([a, np.zeros(a.shape[:-1] + (1,))], axis=-1), "yxz")


class _Loop:
    """A smooth closed path, r(theta) = R (1 + a2 cos(2 theta + p2) + a3 cos(3 theta + p3)),
    walked by arc length, moved so that it leaves the origin along -Z."""

    def __init__(self, rng, radius: float, max_curvature: float, table_size: int = 8192):
        self.a = rng.uniform(0.0, 0.08, size=2)
        self.phase = rng.uniform(0.0, 2.0 * math.pi, size=2)
        self.turn = rng.choice([-1.0, 1.0])  # which way round
        theta = np.linspace(0.0, 2.0 * math.pi, table_size + 1)
        _, d1, d2 = self._curve(theta)
        speed = np.hypot(d1[:, 0], d1[:, 1])
        curvature = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / speed ** 3
        # Curvature scales as 1/size: grow the loop until its tightest bend is allowed.
        self.scale = max(radius, float(curvature.max()) / max_curvature)
        self.theta_table = theta
        self.s_table = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(theta))])
        self.s_table *= self.scale
        self.length = float(self.s_table[-1])
        start, start_d1, _ = self._curve(np.zeros(1))
        self.start = self.scale * start[0]
        self.start_heading = self._heading(start_d1)[0]

    def _curve(self, theta: np.ndarray):
        """Points (m, 2) as (x, z) on the unit-size loop and their first and second derivatives."""
        (a2, a3), (p2, p3), d = self.a, self.phase, self.turn
        r = 1.0 + a2 * np.cos(2 * theta + p2) + a3 * np.cos(3 * theta + p3)
        r1 = -2 * a2 * np.sin(2 * theta + p2) - 3 * a3 * np.sin(3 * theta + p3)
        r2 = -4 * a2 * np.cos(2 * theta + p2) - 9 * a3 * np.cos(3 * theta + p3)
        c, s = np.cos(theta), np.sin(theta)
        point = np.stack([r * c, d * r * s], axis=1)  # d = -1 mirrors z: the other way round
        d1 = np.stack([r1 * c - r * s, d * (r1 * s + r * c)], axis=1)
        d2 = np.stack([r2 * c - 2 * r1 * s - r * c, d * (r2 * s + 2 * r1 * c - r * s)], axis=1)
        return point, d1, d2

    @staticmethod
    def _heading(tangent: np.ndarray) -> np.ndarray:
        """Heading (rad about +Y, 0 = along -Z) of direction(s) (m, 2) as (x, z)."""
        return np.arctan2(-tangent[:, 0], -tangent[:, 1])

    def at(self, s: np.ndarray):
        """Positions (m, 2) as (x, z) and unwrapped headings (m,) after walking ``s`` metres (m,),
        non-decreasing; position (0, 0) and heading 0 at s = 0."""
        laps, within = np.divmod(s, self.length)
        theta = np.interp(within, self.s_table, self.theta_table) + 2.0 * math.pi * laps
        point, d1, _ = self._curve(theta)
        heading = np.unwrap(self._heading(d1)) - self.start_heading
        # Rotate about +Y by -start_heading: the start tangent then points along -Z.
        a = -self.start_heading
        rel = self.scale * point - self.start
        x = math.cos(a) * rel[:, 0] + math.sin(a) * rel[:, 1]
        z = -math.sin(a) * rel[:, 0] + math.cos(a) * rel[:, 1]
        return np.stack([x, z], axis=1), heading


class _Plan:
    """Two channels on one timeline: walking speed (m/s) along the loop, and gaze (yaw, pitch)
    relative to the body, whose heading is the loop's tangent where the walk has got to."""

    def __init__(self, fine_t: np.ndarray, walk_speed: float, loop: _Loop):
        self.fine_t = fine_t
        self.walk_speed = walk_speed
        self.loop = loop
        self.speed = _Channel(0.0)
        self.gaze = _Channel((0.0, 0.0))

    @property
    def now(self) -> float:
        return max(self.speed.end, self.gaze.end)

    def _gaze_move(self, target, peak: float, deadline: float) -> bool:
        """Move the gaze to ``target`` (yaw, pitch) at peak rate ``peak``; False if it does not
        finish by ``deadline`` (then nothing is added)."""
        angle = float(quat_angle(_gaze_quat(self.gaze.value), _gaze_quat(target)))
        duration = MIN_JERK_PEAK * angle / peak
        if self.gaze.end + duration > deadline:
            return False
        self.gaze.move(tuple(target), duration)
        return True

    def _finish(self, end: float) -> None:
        for channel in (self.speed, self.gaze):
            channel.hold_until(end)

    # ------------------------------------------------------------------ segments

    def look(self, end: float, rng, peak: float) -> None:
        """Standing; gaze moves between random targets with pauses. The first move of the
        segment runs at the full ``peak``, later ones at 60-100 % of it."""
        self._finish(self.now)
        first = True
        while True:
            self.gaze.hold_until(self.gaze.end + rng.uniform(0.3, 1.5))
            current = np.array(self.gaze.value)
            for _ in range(20):  # skip targets too close to where the gaze already is
                target = (rng.uniform(-_LOOK_YAW, _LOOK_YAW), rng.uniform(*_LOOK_PITCH))
                if np.hypot(*(np.array(target) - current)) > math.radians(15.0):
                    break
            rate = peak if first else peak * rng.uniform(0.6, 1.0)
            if not self._gaze_move(target, rate, end):
                break
            first = False
        self._finish(end)

    def turns(self, end: float, rng, peak: float) -> None:
        """Mostly still; quick yaw turns of 40-140 degrees (first at the full ``peak``)."""
        self._finish(self.now)
        first = True
        limit = math.radians(80.0)
        while True:
            self.gaze.hold_until(self.gaze.end + rng.uniform(0.8, 2.5))
            yaw, _ = self.gaze.value
            amplitude = rng.uniform(math.radians(40.0), math.radians(140.0))
            direction = rng.choice([-1.0, 1.0])
            if yaw != 0.0:  # turn towards the side with more room, within the neck's range
                direction = -math.copysign(1.0, yaw)
            new_yaw = float(np.clip(yaw + direction * amplitude, -limit, limit))
            target = (new_yaw, rng.uniform(math.radians(-10.0), math.radians(10.0)))
            rate = peak if first else peak * rng.uniform(0.7, 1.0)
            if not self._gaze_move(target, rate, end):
                break
            first = False
        self._finish(end)

    def walk(self, end: float, rng, turn_peak: float) -> None:
        """Walk from rest to rest along the loop: the speed ramps up, cruises and ramps down;
        the gaze turns ahead, then glances aside and back. The path's heading rate uses at
        most half of ``turn_peak``, glances the other half."""
        start = self.now
        self._finish(start)
        ramp = min(1.0, (end - start) / 3.0)
        self.speed.move(self.walk_speed, ramp)
        self.speed.hold_until(end - ramp)
        self.speed.move(0.0, ramp)

        glance_peak = (1.0 - _HEADING_SHARE) * turn_peak
        self.gaze.hold_until(start + 0.1)
        if self._gaze_move((0.0, 0.0), glance_peak, end):
            while True:
                self.gaze.hold_until(self.gaze.end + rng.uniform(1.5, 4.0))
                side = rng.choice([-1.0, 1.0])
                glance = (side * rng.uniform(math.radians(15), math.radians(45)),
                          rng.uniform(math.radians(-20), math.radians(10)))
                dwell = rng.uniform(0.3, 1.2)
                out_rate, back_rate = glance_peak * rng.uniform(0.7, 1.0, size=2)
                angle = float(quat_angle(_gaze_quat((0.0, 0.0)), _gaze_quat(glance)))
                total = MIN_JERK_PEAK * angle * (1.0 / out_rate + 1.0 / back_rate) + dwell
                if self.gaze.end + total > end:  # never end a walk looking aside
                    break
                self._gaze_move(glance, out_rate, end)
                self.gaze.hold_until(self.gaze.end + dwell)
                self._gaze_move((0.0, 0.0), back_rate, end)
        self._finish(end)

    # ------------------------------------------------------------------ rendering

    def render(self, rng, sway_m: float, bob_m: float):
        """Positions (m, 3) and orientations (m, 4) on the internal grid."""
        t = self.fine_t
        self._finish(t[-1])
        speed = self.speed.render_scalar(t)
        walked = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
        xz, heading = self.loop.at(walked)
        positions = np.column_stack([xz[:, 0], np.zeros(t.size), xz[:, 1]])

        # Head bob scales with walking speed, so it fades in and out with the speed ramps.
        stride = speed / self.walk_speed
        phase = 2.0 * math.pi * _STEP_HZ * t
        right = np.column_stack([np.cos(heading), np.zeros(t.size), -np.sin(heading)])
        positions[:, 1] += bob_m * stride * 0.5 * (np.cos(phase) - 1.0)
        positions += (0.5 * bob_m * stride * np.sin(0.5 * phase))[:, None] * right

        # Postural sway: two slow sinusoids per axis, less vertically, zero at t = 0.
        freqs = rng.uniform(0.1, 0.4, size=(2, 3))
        phases = rng.uniform(0.0, 2.0 * math.pi, size=(2, 3))
        amplitude = 0.5 * sway_m * np.array([1.0, 0.3, 1.0])
        for f, ph in zip(freqs, phases):
            positions += amplitude * (np.sin(2 * math.pi * f * t[:, None] + ph) - np.sin(ph))

        i, s = self.gaze.progress(t)
        keys = _gaze_quat(np.asarray(self.gaze.values, dtype=np.float64))
        gaze = keys[i] if len(keys) == 1 else quat_slerp(keys[i], keys[i + 1], s)
        body = np.column_stack([np.cos(0.5 * heading), np.zeros(t.size), np.sin(0.5 * heading),
                                np.zeros(t.size)])
        return positions, quat_multiply(body, gaze)
