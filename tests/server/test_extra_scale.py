"""The extra view's size as a fraction of the primary view's (``ServerConfig.extra_scale``)."""
import pytest

from pibr.protocol.errors import ConfigError
from pibr.protocol.messages import Hello
from pibr.scenes.registry import load_scene
from pibr.server.config import ServerConfig
from pibr.server.session_plan import plan_session


@pytest.mark.parametrize("scale, side", [(0.5, 512), (0.71, 720), (1.0, 1024), (0.125, 128)])
def test_extra_view_size_follows_the_scale(scale, side):
    cfg = ServerConfig(view_size=(1024, 1024), extra_view="on", extra_scale=scale)
    session, spec = plan_session(cfg, load_scene("room"), Hello())
    assert (session.extra.width, session.extra.height) == (side, side) == spec.extra_size
    x, y, w, h = session.atlas.rect("extra.color")
    assert (w, h) == (side, side) and x + w <= session.atlas.width and y + h <= session.atlas.height
    assert session.atlas.rect("extra.depth")[2:] == (side, side)


@pytest.mark.parametrize("scale", [0.0, 0.1, 1.01, float("nan")])
def test_extra_scale_out_of_range_is_a_config_error(scale):
    with pytest.raises(ConfigError, match="extra view scale"):
        ServerConfig(extra_scale=scale)
