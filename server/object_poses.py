"""Each frame's ``OBJECT_POSES`` payload: where the scene's moving objects are at the frame's time.

The server evaluates the scene's animation (scenes/animation.py) at the time it renders and
sends only the result, as a game engine knows its objects' transforms when it renders.
"""
from __future__ import annotations

import numpy as np

from pibr.protocol.object_poses import ObjectPoses, encode_object_poses


def object_poses_at(scene, t: float) -> ObjectPoses | None:
    """Rigid motions of ``scene``'s moving objects at scene time ``t`` (None: nothing moves)."""
    moving = [i for i, o in enumerate(scene.objects) if o.is_dynamic]
    if not moving:
        return None
    return ObjectPoses.from_matrices(moving, np.stack([scene.objects[i].animation.matrix(t) for i in moving]))


def object_poses_payload(scene, t: float) -> bytes | None:
    """The ``OBJECT_POSES`` payload bytes at scene time ``t``, or None for a static scene."""
    poses = object_poses_at(scene, t)
    return None if poses is None else encode_object_poses(poses)
