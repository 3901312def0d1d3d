"""A two-eye client facing a server that gets stereo wrong: clear errors, nothing else."""
import asyncio

import pytest

from pibr.client.app import Client
from pibr.client.config import ClientConfig
from pibr.protocol.errors import ConfigError, MalformedMessage, UnexpectedMessage
from pibr.protocol.messages import Hello, PoseMsg, Welcome

from ..loopback import scripted_server
from .test_newest_frame import _frames

pytestmark = pytest.mark.gl


def _config(stereo: str) -> dict:
    from pibr.scenes.registry import load_scene
    from pibr.server.config import ServerConfig
    from pibr.server.session_plan import plan_session

    hello = Hello(scene="sphere", clock="real", stereo=stereo, ipd_mm=64.0 if stereo else 0.0)
    config, _ = plan_session(ServerConfig(scene="sphere", view_size=(64, 64), extra_view="off"), load_scene("sphere"),
                             hello)
    return config.to_json()


async def _run(tmp_path, welcome_config: dict, frames: list, stereo: str):
    async def server(peer):
        assert isinstance(await peer.recv(), Hello)
        await peer.send(Welcome(server="wrong", session=1, config=welcome_config))
        msg = await peer.recv()
        while msg is not None and not isinstance(msg, PoseMsg):
            msg = await peer.recv()
        for frame in frames:
            peer.conn.send(frame)
        peer.writer.write(peer.conn.data_to_send())
        while await peer.recv() is not None:
            pass

    async with scripted_server(server) as (host, port):
        client = Client(ClientConfig(host=host, port=port, clock="real", trace="pred6dof-1", start_s=12.0,
                                     duration_s=1.0, rate_hz=10.0, methods=("none",), out_dir=str(tmp_path),
                                     width=64, height=48, progress="none", video=False, receive_timeout_s=10.0,
                                     stereo=stereo))
        await asyncio.wait_for(client.run(), 60)


async def test_a_frame_of_an_alternate_session_must_name_its_eye(tmp_path):
    config = _config("alternate")
    with pytest.raises(MalformedMessage, match="alternate stereo session names no eye"):
        await _run(tmp_path, config, _frames(config, 1), "alternate")


async def test_a_server_that_ignores_the_stereo_request_is_refused(tmp_path):
    with pytest.raises(UnexpectedMessage, match="asked for stereo per-eye"):
        await _run(tmp_path, _config(""), [], "per-eye")


def test_stereo_settings_are_checked():
    with pytest.raises(ConfigError, match="anaglyph needs two eyes"):
        ClientConfig(anaglyph=True)
    with pytest.raises(ConfigError, match="stereo must be one of"):
        ClientConfig(stereo="both")
    with pytest.raises(ConfigError, match="interpupillary"):
        ClientConfig(stereo="cyclops", ipd_mm=0)
    with pytest.raises(ConfigError, match="field of view needs two eyes"):
        ClientConfig(eye_fov_deg=(52, 38, 40, 50))
    with pytest.raises(ConfigError, match="up angle must be in"):
        ClientConfig(stereo="cyclops", eye_fov_deg=(52, 38, 95, 50))
    with pytest.raises(ConfigError, match="cannot with --eye-fov-deg"):
        ClientConfig(stereo="cyclops", eye_fov_deg=(52, 38, 40, 50), options={"pair_at_once": True})
    # the eyes' frustums set the field of view: the symmetric one of the same pixels per radian
    assert ClientConfig(stereo="cyclops", eye_fov_deg=(45, 45, 30, 30)).fov_deg == pytest.approx(90.0)


def test_the_eyes_fov_on_the_command_line(capsys):
    from pibr.cli import build_parser, main

    with pytest.raises(SystemExit):
        build_parser().parse_args(["client", "--eye-fov-deg", "52,38,40"])
    assert "four angles" in capsys.readouterr().err
    assert main(["client", "--stereo", "cyclops", "--fov", "100", "--eye-fov-deg", "52,38,40,50",
                 "--connect", "127.0.0.1:1"]) == 2
    assert "give --fov or --eye-fov-deg, not both" in capsys.readouterr().err
    assert main(["demo", "--eye-fov-deg", "52,38,40,50"]) == 2
    assert "need two eyes" in capsys.readouterr().err
    from pibr.bench.commands import demo_client_args

    args = build_parser().parse_args(["demo", "--stereo", "cyclops", "--eye-fov-deg", "52,38.5,40,50"])
    assert demo_client_args(args)[-2:] == ("--eye-fov-deg", "52,38.5,40,50")
    args = build_parser().parse_args(["bench", "stereo", "--eye-fov-deg", "52,38,40,50"])
    assert args.eye_fov_deg == (52.0, 38.0, 40.0, 50.0)


def test_colour_at_a_quarter_cannot_interleave_the_eyes():
    from pibr.scenes.registry import load_scene
    from pibr.server.config import ServerConfig
    from pibr.server.session_plan import plan_session

    cfg = ServerConfig(scene="sphere", view_size=(64, 64), extra_view="off", colour_scale=0.5)
    with pytest.raises(ConfigError, match="interleaves the eyes"):
        plan_session(cfg, load_scene("sphere"), Hello(scene="sphere", stereo="alternate", ipd_mm=64.0))
    config, _ = plan_session(cfg, load_scene("sphere"), Hello(scene="sphere", stereo="cyclops", ipd_mm=64.0))
    assert config.options["stereo"] == {"reference": "cyclops", "ipd_mm": 64.0}


def test_a_cost_table_is_one_views_and_a_pair_costs_both_eyes(tmp_path):
    """The virtual clock's controller, from a table of one view's costs: two eyes cost twice, so
    the pair steps down where one view would not; session.json gives the table back per view."""
    import json

    from pibr.client.deadline import levels_for

    names = [lv.name for lv in levels_for("proxy")]
    table = {"proxy": {name: 30.0 - 3 * k for k, name in enumerate(names)}}   # full 30 ms ... cheapest 9 ms
    path = tmp_path / "costs.json"
    path.write_text(json.dumps(table))
    chosen = {}
    for stereo in ("", "cyclops"):
        client = Client(ClientConfig(methods=("proxy",), rate_hz=30.0, cost_table=str(path), stereo=stereo))
        client._set_up_deadline()
        chosen[stereo] = client._choose_levels()["proxy"][0]
        client._calibration = {}
        assert client._deadline_summary()["costs_ms"]["proxy"]["full"] == pytest.approx(30.0, abs=0.01)
    # one view: the full level (30 ms) fits a 33 ms tick; a pair of them (60 ms) does not
    assert chosen[""] == 0 and chosen["cyclops"] > 0
