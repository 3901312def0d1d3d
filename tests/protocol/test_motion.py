"""Rigid motions: bounded values, so a motion from the wire (a proxy bundle) is finite at any time."""
import re

import numpy as np
import pytest

from pibr.protocol.errors import MalformedMessage
from pibr.protocol.motion import MAX_MOTION_VALUE, RigidMotion
from pibr.protocol.proxy import ProxyObject, decode_bundle, encode_bundle


@pytest.mark.parametrize("kwargs", [
    dict(axis=(1e308, 1e308, 0)),     # its norm overflows: once normalised to a zero axis
    dict(axis=(0, 1, 0), pivot=(1e300, 0, 0)),
    dict(speed=1e300),                # speed * t overflows to inf, and cos(inf) raises
    dict(phase=float("nan")),
    dict(radius=-2 * MAX_MOTION_VALUE),
])
def test_motion_values_are_bounded(kwargs):
    with pytest.raises(ValueError, match=re.escape(f"within ±{MAX_MOTION_VALUE:g}")):
        RigidMotion("spin", **kwargs)


def test_largest_motion_stays_finite_for_days():
    m = RigidMotion("orbit", (MAX_MOTION_VALUE, 0, MAX_MOTION_VALUE), MAX_MOTION_VALUE, (0, 0, 0),
                    MAX_MOTION_VALUE, MAX_MOTION_VALUE, MAX_MOTION_VALUE)
    for kind in RigidMotion.KINDS:
        m.kind = kind
        assert np.all(np.isfinite(m.matrix(86_400.0 * 10)))


class _RawMotion:
    def __init__(self, values):
        self.values = np.asarray(values, np.float64)

    def to_array(self):
        return self.values


def test_bundle_motion_with_an_overflowing_axis_is_malformed():
    box_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    box_f = np.array([[0, 1, 2]], np.uint32)
    bad = _RawMotion([0, 1e308, 1e308, 0, 1.0, 0, 0, 0, 0, 0, 0])
    raw = encode_bundle([ProxyObject("fan", np.eye(4), bad, np.zeros((2, 3)), (box_v, box_f), (box_v, box_f))])
    with pytest.raises(MalformedMessage, match="object 0 motion: animation axis must be"):
        decode_bundle(raw)
