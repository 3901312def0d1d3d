"""Unity's left-handed axes to pibr's in closed form (moved from protocol/pose.py, where nothing
used it): the expectation the tests hold the trace importer's general axis conversion
(``trace_import.axis_conversion`` / ``convert_axes``) to."""
from __future__ import annotations

import numpy as np

from pibr.protocol.pose import _as_quats


def left_handed_to_right_handed(position, quat):
    """Convert Unity-style left-handed (+Y up, +Z forward) to pibr's right-handed axes.

    The conversion mirrors Z: a position (x, y, z) becomes (x, y, -z) and a rotation
    quaternion (w, x, y, z) becomes (w, -x, -y, z). A Unity camera looking along its +Z
    then looks along -Z, as an OpenGL camera does.

    position : (3,) or (n, 3); quat : (4,) or (n, 4), (w, x, y, z)
    """
    p = np.array(position, dtype=np.float64) * np.array([1.0, 1.0, -1.0])
    q = _as_quats(quat) * np.array([1.0, -1.0, -1.0, 1.0])
    return p, q
