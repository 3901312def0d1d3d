"""The head-trace type: timed camera poses, resampled for replay.

Conventions (DESIGN.md, Contracts): metres and seconds, right-handed, +Y up, a camera looks
along -Z, orientations are camera-to-world unit quaternions (w, x, y, z), ``t`` in seconds
from the start. Replay resamples to the output rate: linear position, SLERP orientation.

Reading and writing trace files (the canonical ``t,px,py,pz,qw,qx,qy,qz`` CSV and other
formats), the built-in recordings, synthetic traces and placing a trace in a scene are not
part of the contract: :mod:`pibr.common.traces`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import TraceError
from .pose import Pose, quat_angle, quat_multiply, quat_normalize, quat_slerp, quat_to_matrix

#: Limits on what a trace controls (TraceError past them): a longer span or farther positions
#: mean a wrong unit, not a head; integer timestamps (ticks, ns since an epoch) are 64-bit;
#: resampling makes at most MAX_SAMPLES samples.
MAX_DURATION_S = 1e6
MAX_POSITION_M = 1e8
MAX_SAMPLES = 10_000_000
TIMESTAMP_RANGE = (-2**63, 2**63 - 1)

#: A quaternion this close to unit length is kept bit for bit, so write -> read is exact.
_UNIT_TOLERANCE = 1e-12
#: How far from unit length a HeadTrace orientation may be (rounding of stored files).
_UNIT_CHECK = 1e-6


@dataclass(eq=False)
class HeadTrace:
    """A recorded or synthetic head motion.

    t : (n,) float64 seconds, t[0] == 0, strictly increasing
    positions : (n, 3) float64 metres, camera-to-world
    orientations : (n, 4) float64 unit quaternions (w, x, y, z), camera-to-world
    name : a label (file stem, built-in name, synthetic kind)
    warnings : what an importer fixed or noticed (dropped duplicates, gaps), for reports
    assumptions : what an importer took the recording to mean (units, axes, handedness,
        ignored columns, ...), name -> text, for ``pibr trace show``

    The arrays are stored read-only, so a trace can be shared without copying. Build one from
    raw samples (any start time, unnormalised quaternions) with :meth:`from_samples`.
    """

    t: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray
    name: str = "trace"
    warnings: list = field(default_factory=list)
    assumptions: dict = field(default_factory=dict)

    def __post_init__(self):
        t = np.array(self.t, dtype=np.float64)
        p = np.array(self.positions, dtype=np.float64)
        q = np.array(self.orientations, dtype=np.float64)
        label = f"head trace {self.name!r}"
        if t.ndim != 1 or t.size == 0:
            raise TraceError(f"{label}: t must have shape (n,) with n >= 1, got {t.shape}")
        n = t.size
        if p.shape != (n, 3):
            raise TraceError(f"{label}: positions must have shape ({n}, 3), got {p.shape}")
        if q.shape != (n, 4):
            raise TraceError(f"{label}: orientations must have shape ({n}, 4), got {q.shape}")
        for what, a in (("t", t), ("positions", p), ("orientations", q)):
            bad = np.flatnonzero(~np.all(np.isfinite(a.reshape(n, -1)), axis=1))
            if bad.size:
                raise TraceError(f"{label}: {what} has a NaN or infinite value at sample {bad[0]}")
        if t[0] != 0.0:
            raise TraceError(f"{label}: t must start at 0, got {t[0]!r} "
                             "(HeadTrace.from_samples re-bases times)")
        steps = np.diff(t)
        if np.any(steps <= 0):
            i = int(np.flatnonzero(steps <= 0)[0]) + 1
            raise TraceError(f"{label}: t must be strictly increasing; sample {i} has t={t[i]!r} "
                             f"after t={t[i - 1]!r}")
        if t[-1] > MAX_DURATION_S:
            raise TraceError(f"{label}: spans {t[-1]:.6g} s, more than the limit of {MAX_DURATION_S:g} s "
                             "(are the timestamps in the unit assumed?)")
        far = np.flatnonzero(np.any(np.abs(p) > MAX_POSITION_M, axis=1))
        if far.size:
            raise TraceError(f"{label}: position {p[far[0]].tolist()} at sample {far[0]} is farther than "
                             f"{MAX_POSITION_M:g} m from the origin on an axis (are the units metres?)")
        norms = np.linalg.norm(q, axis=1)
        off = np.flatnonzero(np.abs(norms - 1.0) > _UNIT_CHECK)
        if off.size:
            raise TraceError(f"{label}: orientations must be unit quaternions; sample {off[0]} has "
                             f"norm {norms[off[0]]!r} (HeadTrace.from_samples normalises)")
        for a in (t, p, q):
            a.flags.writeable = False
        self.t, self.positions, self.orientations = t, p, q
        self.warnings = list(self.warnings)
        self.assumptions = dict(self.assumptions)

    @classmethod
    def from_samples(cls, t, positions, orientations, name: str = "trace", warnings=(),
                     assumptions=None) -> "HeadTrace":
        """Trace from raw samples: times re-based to start at 0, quaternions normalised (w >= 0).

        t : (n,) seconds; positions : (n, 3); orientations : (n, 4) (w, x, y, z), non-zero
        """
        t = np.asarray(t, dtype=np.float64)
        if t.ndim != 1 or t.size == 0:
            raise TraceError(f"head trace {name!r}: t must have shape (n,) with n >= 1, got {t.shape}")
        if not np.isfinite(t[0]):
            raise TraceError(f"head trace {name!r}: t has a NaN or infinite value at sample 0")
        q = np.asarray(orientations, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != 4:
            raise TraceError(f"head trace {name!r}: orientations must have shape (n, 4), got {q.shape}")
        return cls(t - t[0], positions, unit_quaternions(q, name), name, list(warnings), dict(assumptions or {}))

    # ----------------------------------------------------------------------------- basics

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last sample."""
        return float(self.t[-1])

    def __repr__(self) -> str:
        return f"HeadTrace(name={self.name!r}, samples={len(self)}, duration={self.duration:.3f} s)"

    # ----------------------------------------------------------------------------- sampling

    def sample(self, times):
        """Interpolated poses at ``times``: linear position, SLERP orientation.

        times : (m,) seconds (or a scalar); outside [0, duration] the end samples are held.
        Returns positions (m, 3) and orientations (m, 4) ((3,) and (4,) for a scalar).
        """
        times = np.asarray(times, dtype=np.float64)
        scalar = times.ndim == 0
        times = np.atleast_1d(times)
        if times.ndim != 1:
            raise TraceError(f"sample times must have shape (m,), got {times.shape}")
        if not np.all(np.isfinite(times)):
            raise TraceError("sample times must be finite")
        n = len(self)
        if n == 1:
            pos = np.repeat(self.positions, times.size, axis=0)
            rot = np.repeat(self.orientations, times.size, axis=0)
        else:
            clamped = np.clip(times, 0.0, self.duration)
            i = np.clip(np.searchsorted(self.t, clamped, side="right") - 1, 0, n - 2)
            s = (clamped - self.t[i]) / (self.t[i + 1] - self.t[i])
            pos = self.positions[i] + (self.positions[i + 1] - self.positions[i]) * s[:, None]
            rot = quat_slerp(self.orientations[i], self.orientations[i + 1], s)
        return (pos[0], rot[0]) if scalar else (pos, rot)

    def pose_at(self, t: float) -> Pose:
        """Pose at time ``t`` seconds (held at the ends)."""
        p, q = self.sample(float(t))
        return Pose.make(p, q)

    def resample(self, rate_hz: float, start: float = 0.0, duration: float | None = None) -> "HeadTrace":
        """Uniformly sampled copy: times start, start + 1/rate, ... up to start + duration
        (default, and at most: the end of the trace), re-based to 0. Sample k is at exactly
        k / rate_hz."""
        rate_hz = float(rate_hz)
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise TraceError(f"resample rate must be a positive number of Hz, got {rate_hz!r}")
        start, end = self.window(start, duration)
        # A hair of slack so that an end falling exactly on a tick is not lost to rounding.
        count = math.floor((end - start) * rate_hz + 1e-9) + 1
        if count > MAX_SAMPLES:
            raise TraceError(f"resampling {end - start:.6g} s at {rate_hz:g} Hz makes {count} samples, more than "
                             f"the limit of {MAX_SAMPLES}")
        rel = np.arange(count, dtype=np.float64) / rate_hz
        pos, rot = self.sample(start + rel)
        return HeadTrace(rel, pos, rot, self.name, self.warnings, self.assumptions)

    def slice(self, start: float, duration: float | None = None) -> "HeadTrace":
        """The part in [start, start + duration], re-based to 0; the original samples inside,
        plus interpolated samples exactly at both ends of the window."""
        start, end = self.window(start, duration)
        inside = (self.t > start) & (self.t < end)
        times = np.concatenate([[start], self.t[inside], [end]]) if end > start else np.array([start])
        # Drop interpolated ends that fall (within rounding) on an original sample.
        keep = np.concatenate([[True], np.diff(times) > 1e-12])
        times = times[keep]
        pos, rot = self.sample(times)
        return HeadTrace(times - start, pos, rot, self.name, self.warnings, self.assumptions)

    def recentred(self, yaw: bool = False) -> "HeadTrace":
        """A copy moved so its first position is the origin; with ``yaw`` also turned about +Y
        so its first heading (the view direction projected on the floor) is -Z. For traces
        recorded in a world's own coordinates (a game level, a room-scale play area)."""
        positions = self.positions - self.positions[0]
        orientations = self.orientations
        note = "first position moved to the origin"
        if yaw:
            forward = quat_to_matrix(self.orientations[0])[:, 2] * -1.0
            heading = math.atan2(-forward[0], -forward[2])   # 0 when looking along -Z
            turn = np.array([math.cos(-heading / 2), 0.0, math.sin(-heading / 2), 0.0])
            rot = quat_to_matrix(turn)
            positions = positions @ rot.T
            orientations = quat_multiply(np.broadcast_to(turn, orientations.shape), orientations)
            note += f", turned {math.degrees(-heading):+.1f} deg about +Y to look along -Z"
        return HeadTrace(self.t, positions, unit_quaternions(orientations, self.name), self.name, self.warnings,
                         {**self.assumptions, "recentred": note})

    def window(self, start: float, duration: float | None) -> tuple[float, float]:
        """(start, end) seconds of the part from ``start`` lasting ``duration`` (default and at
        most: to the end). Raises TraceError for a start outside the trace or a bad duration."""
        start = float(start)
        if not (math.isfinite(start) and 0.0 <= start <= self.duration):
            raise TraceError(f"start {start!r} s is outside trace {self.name!r} (0 .. {self.duration:.6g} s)")
        if duration is None:
            return start, self.duration
        duration = float(duration)
        if not (math.isfinite(duration) and duration >= 0):
            raise TraceError(f"duration must be a non-negative number of seconds, got {duration!r}")
        return start, min(start + duration, self.duration)

    # ----------------------------------------------------------------------------- statistics

    def speeds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per interval (n - 1,): linear speed in m/s and angular speed in rad/s."""
        dt = np.diff(self.t)
        linear = np.linalg.norm(np.diff(self.positions, axis=0), axis=1) / dt
        angular = quat_angle(self.orientations[:-1], self.orientations[1:]) / dt
        return linear, angular

    def summary(self) -> dict:
        """JSON-ready statistics: sample count, duration, rates, speeds, position extent."""
        linear, angular = self.speeds()
        steps = np.diff(self.t)

        def stats(v, scale=1.0):
            if v.size == 0:
                return {"mean": 0.0, "p95": 0.0, "max": 0.0}
            return {"mean": float(np.mean(v)) * scale, "p95": float(np.percentile(v, 95)) * scale,
                    "max": float(np.max(v)) * scale}

        lo, hi = self.positions.min(axis=0), self.positions.max(axis=0)
        return {
            "name": self.name,
            "samples": len(self),
            "duration_s": self.duration,
            "median_rate_hz": float(1.0 / np.median(steps)) if steps.size else None,
            "max_gap_s": float(steps.max()) if steps.size else 0.0,
            "linear_speed_m_s": stats(linear),
            "angular_speed_rad_s": stats(angular),
            "angular_speed_deg_s": stats(angular, 180.0 / math.pi),
            "position_min": lo.tolist(),
            "position_max": hi.tolist(),
            "position_extent": (hi - lo).tolist(),
            "warnings": list(self.warnings),
            "assumptions": dict(self.assumptions),
        }


# --------------------------------------------------------------------------------- helpers


def unit_quaternions(q, name: str = "trace") -> np.ndarray:
    """Normalised copy of quaternions (n, 4) with w >= 0; rows already unit to rounding are
    kept bit for bit (only their sign may flip), so a canonical file reads back exactly."""
    q = np.asarray(q, dtype=np.float64)
    try:
        normalised = quat_normalize(q)
    except (ValueError, ArithmeticError) as exc:  # InvalidPose is a ValueError
        raise TraceError(f"head trace {name!r}: {exc}") from exc
    if q.ndim != 2:
        return normalised
    with np.errstate(over="ignore"):   # huge components: not unit, and normalised above
        keep = np.abs(np.linalg.norm(q, axis=1) - 1.0) <= _UNIT_TOLERANCE
    sign = np.where(np.sum(normalised * q, axis=1) < 0, -1.0, 1.0)
    return np.where(keep[:, None], q * sign[:, None], normalised)


def yaw_pitch(orientations) -> np.ndarray:
    """Yaw (about +Y, 0 looking along -Z, positive turning left) and pitch (positive looking
    up) in radians of the viewing direction of each orientation (n, 4). Returns (n, 2); yaw is
    unwrapped so it is continuous over time."""
    forward = -quat_to_matrix(np.asarray(orientations, dtype=np.float64))[..., :, 2]
    yaw = np.unwrap(np.arctan2(-forward[..., 0], -forward[..., 2]))
    pitch = np.arcsin(np.clip(forward[..., 1], -1.0, 1.0))
    return np.stack([yaw, pitch], axis=-1)
