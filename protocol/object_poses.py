"""The ``OBJECT_POSES`` payload of a ``Frame``: where each moving object is at the frame's time.

What a game engine knows when it renders a frame, and all a client learns about moving
objects: per moving object, its index in the scene's object list (the proxy bundle's order;
the Welcome's ``scene.objects`` counts them) and its rigid motion at the frame's scene time,
a position and a unit quaternion, such that the object's object-to-world transform is
``[R(q) | position] @ rest_transform`` (the rest transform travels in the proxy bundle). No
model of how objects move goes on the wire: the client extrapolates from what it received.

Layout (little-endian)::

    u32 count
    per moving object, by strictly increasing index:
        u32 index, 3 f32 position (m), 4 f32 quaternion (w, x, y, z)

32 bytes per moving object. A scene with nothing moving sends no such payload at all.
Parsing checks everything against the session's object count before use.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from .errors import MalformedMessage
from .pose import quat_from_matrix, quat_to_matrix

_COUNT = struct.Struct("<I")
_ENTRY = np.dtype([("index", "<u4"), ("position", "<f4", 3), ("orientation", "<f4", 4)])
ENTRY_BYTES = _ENTRY.itemsize
#: How far from 1 a received quaternion's norm may be (float32 rounding is ~1e-7).
UNIT_TOLERANCE = 1e-4


@dataclass(frozen=True)
class ObjectPoses:
    """Rigid motions of moving objects at one scene time.

    indices      : (n,) int64, strictly increasing object indices
    positions    : (n, 3) float64 metres
    orientations : (n, 4) float64 unit quaternions (w, x, y, z)
    """

    indices: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray

    def __len__(self) -> int:
        return len(self.indices)

    def matrices(self) -> np.ndarray:
        """(n, 4, 4) rigid motions: object-to-world = motion @ rest transform."""
        m = np.tile(np.eye(4), (len(self), 1, 1))
        if len(self):
            m[:, :3, :3] = quat_to_matrix(self.orientations)
            m[:, :3, 3] = self.positions
        return m

    @classmethod
    def from_matrices(cls, indices, matrices) -> "ObjectPoses":
        """indices (n,), matrices (n, 4, 4) rigid -> ObjectPoses (the rotation parts must be rotations)."""
        matrices = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
        q = np.array([quat_from_matrix(m[:3, :3]) for m in matrices]).reshape(-1, 4)
        return cls(np.asarray(indices, dtype=np.int64).reshape(-1), matrices[:, :3, 3].copy(), q)


def encode_object_poses(poses: ObjectPoses) -> bytes:
    """ObjectPoses -> payload bytes."""
    entries = np.zeros(len(poses), _ENTRY)
    entries["index"] = poses.indices
    entries["position"] = poses.positions
    entries["orientation"] = poses.orientations
    return _COUNT.pack(len(poses)) + entries.tobytes()


def decode_object_poses(data: bytes, object_count: int) -> ObjectPoses:
    """Payload bytes -> ObjectPoses, for a session whose scene has ``object_count`` objects.

    Raises MalformedMessage naming the problem: a count above the object count, a length
    that does not match it, an index out of range or out of order, a non-finite value or a
    quaternion whose norm is not 1 within UNIT_TOLERANCE."""
    name = "Frame object poses"
    if len(data) < _COUNT.size:
        raise MalformedMessage(f"{name}: {len(data)} bytes are shorter than the 4-byte count")
    (count,) = _COUNT.unpack_from(data, 0)
    if count > object_count:
        raise MalformedMessage(f"{name}: {count} poses for a scene of {object_count} objects")
    if len(data) != _COUNT.size + count * ENTRY_BYTES:
        raise MalformedMessage(f"{name}: {count} poses need {_COUNT.size + count * ENTRY_BYTES} bytes, "
                               f"got {len(data)}")
    entries = np.frombuffer(data, _ENTRY, count, _COUNT.size)
    index = entries["index"].astype(np.int64)
    if count and int(index.max()) >= object_count:
        raise MalformedMessage(f"{name}: object index {int(index.max())} is not below the object count "
                               f"{object_count}")
    if np.any(np.diff(index) <= 0):
        raise MalformedMessage(f"{name}: object indices must be strictly increasing")
    position = entries["position"].astype(np.float64)
    q = entries["orientation"].astype(np.float64)
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(q))):
        bad = int(index[~(np.all(np.isfinite(position), 1) & np.all(np.isfinite(q), 1))][0])
        raise MalformedMessage(f"{name}: object {bad} has a non-finite position or quaternion")
    norm = np.linalg.norm(q, axis=1)
    off = np.abs(norm - 1.0) > UNIT_TOLERANCE
    if np.any(off):
        k = int(np.flatnonzero(off)[0])
        raise MalformedMessage(f"{name}: object {int(index[k])} quaternion has norm {norm[k]:.6g}, not 1 "
                               f"(tolerance {UNIT_TOLERANCE:g})")
    return ObjectPoses(index, position, q / norm[:, None])
