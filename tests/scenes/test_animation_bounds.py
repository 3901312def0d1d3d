"""Animations: bounded values, so an animation from a scene file is finite at any time."""
import re

import numpy as np
import pytest

from pibr.protocol.errors import SceneError
from pibr.scenes.animation import MAX_ANIMATION_VALUE, Animation


@pytest.mark.parametrize("kwargs", [
    dict(axis=(1e308, 1e308, 0)),     # its norm overflows: once normalised to a zero axis
    dict(axis=(0, 1, 0), pivot=(1e300, 0, 0)),
    dict(speed=1e300),                # speed * t overflows to inf, and cos(inf) raises
    dict(phase=float("nan")),
    dict(radius=-2 * MAX_ANIMATION_VALUE),
    dict(rest=float("inf")),
])
def test_animation_values_are_bounded(kwargs):
    with pytest.raises(SceneError, match=re.escape(f"within ±{MAX_ANIMATION_VALUE:g}")):
        Animation("spin", **kwargs)


def test_largest_animation_stays_finite_for_days():
    for kind in Animation.KINDS:
        m = Animation(kind, (MAX_ANIMATION_VALUE, 0, MAX_ANIMATION_VALUE), MAX_ANIMATION_VALUE, (0, 0, 0),
                      MAX_ANIMATION_VALUE, MAX_ANIMATION_VALUE, MAX_ANIMATION_VALUE, MAX_ANIMATION_VALUE)
        assert np.all(np.isfinite(m.matrix(86_400.0 * 10)))
