"""Issue 13, defects 1-4: hostile JSON bodies and Welcome configs give a MalformedMessage naming
the problem, never a raw Python exception, and the client never accepts what the server refuses."""
import copy
import json

import pytest

from pibr.protocol.atlas import MAX_ATLAS_PIXELS, AtlasLayout, build_layout, check_view_size
from pibr.protocol.connection import Connection
from pibr.protocol.errors import MalformedMessage
from pibr.protocol.framing import encode_frame
from pibr.protocol.messages import Hello, Stats, Welcome, _get, parse_message
from pibr.protocol.pose import dual_view_offset
from pibr.protocol.session import SessionConfig, ViewConfig, check_atlas_layout

HELLO_OUTPUT = b'{"protocol": 1, "output": {"width": 960, "height": 540, "rate_hz": 60, "fov_deg": %s}}'


def _receive(type_, payload) -> Connection:
    conn = Connection()
    conn.receive_data(encode_frame(type_, payload))   # documented never to raise
    return conn


# ------------------------------------------------------------------ defect 1: nesting

@pytest.mark.parametrize("type_", [Hello.TYPE, Welcome.TYPE, Stats.TYPE, 6])
def test_deeply_nested_json_body_is_a_malformed_message(type_):
    conn = _receive(type_, b"[" * 100_000 + b"]" * 100_000)
    assert isinstance(conn.error, MalformedMessage)
    assert "nested deeper than 32 levels" in str(conn.error)
    assert conn.data_to_send()   # the Error naming it is queued for the peer


def test_nesting_inside_a_field_is_refused_too():
    body = b'{"values": {"a": ' + b"[" * 5000 + b"1" + b"]" * 5000 + b"}}"
    conn = _receive(Stats.TYPE, body)
    assert isinstance(conn.error, MalformedMessage) and "nested deeper" in str(conn.error)


# ------------------------------------------------------------------ defect 2: huge numbers where floats go

def test_400_digit_stats_value_is_a_malformed_message():
    conn = _receive(Stats.TYPE, b'{"values": {"frames_decoded": ' + b"9" * 400 + b"}}")
    assert isinstance(conn.error, MalformedMessage)
    assert "values.frames_decoded: a number of 400 characters" in str(conn.error)


def test_400_digit_fov_is_a_malformed_message():
    conn = _receive(Hello.TYPE, HELLO_OUTPUT % (b"9" * 400))
    assert isinstance(conn.error, MalformedMessage)
    assert "output.fov_deg: a number of 400 characters" in str(conn.error)


def test_get_turns_a_float_overflow_into_a_malformed_message():
    # _get also serves values that never went through the reader (a tree built in code)
    with pytest.raises(MalformedMessage, match="'fov_deg' is an integer too large for a float"):
        _get("Hello.output", {"fov_deg": 10**400}, "fov_deg", float)
    assert _get("Hello.output", {"fov_deg": 10**20}, "fov_deg", float, hi=1e30) == 1e20


def test_stats_values_of_every_documented_size_still_parse():
    assert parse_message(Stats.TYPE, b'{"values": {"a": ' + b"9" * 100 + b'}}').values["a"] == float("9" * 100)


# ------------------------------------------------------------------ defect 3: non-finite numbers

def _config(codec="h264", view=(64, 64), extra=True, colour_scale=1.0) -> dict:
    half = (view[0] // 2, view[1] // 2) if extra else None
    cfg = SessionConfig(
        scene={"name": "room", "near": 0.1, "far": 100.0, "viewer_origin": [0, 1.6, 0, 1, 0, 0, 0]},
        clock="virtual", server_fps=10.0, server_delay_us=20_000, primary=ViewConfig(*view),
        extra=ViewConfig(*half) if extra else None, extra_offset=dual_view_offset(1.5, 1.8, 15) if extra else None,
        atlas=build_layout(view, half, depth_in_atlas=codec == "h264", colour_scale=colour_scale),
        video_bitrate_kbps=2000.0, keyint=30, depth_codec=codec, depth_bits=8 if codec == "h264" else 12,
        depth_min_code=16 if codec == "h264" else 2, colour_scale=colour_scale)
    return json.loads(json.dumps(cfg.to_json(), allow_nan=False))


@pytest.mark.parametrize("codec, extra, colour_scale", [("h264", True, 1.0), ("edge", True, 1.0), ("h264", False, 1.0),
                                                        ("edge", False, 1.0), ("h264", True, 0.5), ("edge", True, 0.5)])
def test_valid_configs_round_trip(codec, extra, colour_scale):
    o = _config(codec, extra=extra, colour_scale=colour_scale)
    config = SessionConfig.from_json(o)
    assert config.to_json() == o and config.colour_scale == colour_scale
    check_atlas_layout(config)


def test_a_colour_scaled_atlas_holds_half_size_colour_and_whole_depth():
    o = _config(colour_scale=0.5)
    assert o["atlas"]["rects"] == {"primary.color": [0, 0, 32, 32], "primary.depth": [32, 0, 64, 64],
                                   "extra.color": [96, 0, 16, 16], "extra.depth": [96, 16, 32, 32]}
    assert (o["atlas"]["width"], o["atlas"]["height"]) == (128, 64)      # 16-aligned around the 16x16 extra colour
    edge = _config("edge", colour_scale=0.5)
    assert (edge["atlas"]["width"], edge["atlas"]["height"]) == (48, 32)
    without = dict(o)
    del without["colour_scale"]    # a Welcome from before colour scales: whole colour, so this atlas is wrong
    with pytest.raises(MalformedMessage, match="primary.color is 32x32, not 64x64"):
        SessionConfig.from_json(without)


@pytest.mark.parametrize("value", [0.25, 2, "0.5", True, None, [0.5]])
def test_a_colour_scale_that_is_not_one_of_the_scales_is_refused(value):
    o = _config(colour_scale=0.5)
    o["colour_scale"] = value
    with pytest.raises(MalformedMessage, match="colour_scale must be one of 1, 0.5"):
        SessionConfig.from_json(o)


def test_whole_colour_rectangles_in_a_colour_scaled_atlas_are_refused():
    o = _config(colour_scale=0.5)
    whole = _config(colour_scale=1.0)
    o["atlas"] = whole["atlas"]
    with pytest.raises(MalformedMessage, match=r"primary.color is 64x64, not 32x32 \(its view's colour at scale 0.5\)"):
        SessionConfig.from_json(o)
    laid_out = SessionConfig.from_json(_config(colour_scale=0.5))
    moved = dict(_config(colour_scale=0.5))
    moved["atlas"] = {**moved["atlas"], "width": 256}     # rectangles of the right sizes, a bigger atlas
    with pytest.raises(MalformedMessage, match="is not the layout of its views"):
        check_atlas_layout(SessionConfig.from_json(moved))
    check_atlas_layout(laid_out)


@pytest.mark.parametrize("path, value, match", [
    (("atlas", "width"), float("inf"), "atlas.width: inf is not a finite number"),
    (("atlas", "height"), 10**400, "atlas.height: an integer of more than 100 digits"),
    (("server_fps",), 10**400, "server_fps: an integer of more than 100 digits"),
    (("server_fps",), float("nan"), "server_fps: nan is not a finite number"),
    (("scene", "near"), float("inf"), "scene.near: inf is not a finite number"),
    (("keyint",), 10**400, "keyint: an integer of more than 100 digits"),
    (("primary", "width"), 10**400, "primary.width: an integer of more than 100 digits"),
    (("atlas", "rects", "primary.color"), [0, 0, float("inf"), 64], r"primary.color\[2\]: inf is not a finite"),
    (("server_fps",), 10**99, "'server_fps' = 1000.* is outside"),
    (("atlas", "width"), 64.0, "atlas: field 'width' must be an integer"),
    (("atlas", "height"), 10**99, "atlas size .* exceeds the limit"),
], ids=["atlas-inf", "atlas-huge", "fps-huge", "fps-nan", "near-inf", "keyint-huge", "width-huge", "rect-inf",
        "fps-99-digits", "atlas-float", "atlas-99-digits"])
def test_config_numbers_out_of_range_are_malformed(path, value, match):
    o = _config()
    node = o
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(MalformedMessage, match=match):
        SessionConfig.from_json(o)


def test_field_parsers_compare_before_converting():
    from pibr.protocol.session import _num

    with pytest.raises(MalformedMessage, match="'fps' = 1000.* is outside"):
        _num({"fps": 10**400}, "fps", 0.1, 1000.0)      # float(10**400) raises OverflowError
    with pytest.raises(MalformedMessage, match="'n' = <16610-bit integer> is outside"):
        _num({"n": 10**5000}, "n", 1, 10, int)          # repr() refuses past 4300 digits
    with pytest.raises(MalformedMessage, match="'width' must be an integer, got inf"):
        AtlasLayout.from_json({"width": float("inf"), "height": 16, "rects": {}})


@pytest.mark.parametrize("token", [b"NaN", b"Infinity", b"-Infinity", b"1e400"])
def test_welcome_refuses_the_non_finite_numbers_its_serializer_refuses(token):
    body = Welcome("srv", 1, _config()).serialize().replace(b'"server_fps":10.0', b'"server_fps":' + token)
    assert token in body
    conn = _receive(Welcome.TYPE, body)
    assert isinstance(conn.error, MalformedMessage) and "config.server_fps" in str(conn.error)
    with pytest.raises(ValueError):   # what Welcome.serialize refuses to write
        Welcome("srv", 1, json.loads(body)).serialize()


# ------------------------------------------------------------------ defect 4: unbounded atlas and views

@pytest.mark.parametrize("side", [16384, 65536])
def test_huge_atlas_is_refused_naming_the_size(side):
    o = _config()
    o["atlas"]["width"] = o["atlas"]["height"] = side
    with pytest.raises(MalformedMessage, match=f"atlas size {side}x{side} exceeds the limit"):
        SessionConfig.from_json(o)
    with pytest.raises(MalformedMessage, match=f"{side}x{side}"):
        AtlasLayout.from_json(o["atlas"])


@pytest.mark.parametrize("view", [(16384, 16384), (8192, 8192), (65536, 32)])
def test_views_past_the_servers_own_limits_are_refused(view):
    with pytest.raises(ValueError, match="exceeds the limit|outside"):
        check_view_size(*view, what="server view")
    o = _config()
    o["primary"] = {"width": view[0], "height": view[1]}
    o["atlas"] = {"width": 16, "height": 16, "rects": {"primary.color": [0, 0, 16, 16]}}
    with pytest.raises(MalformedMessage, match="primary"):
        SessionConfig.from_json(o)


def test_the_largest_session_the_server_accepts_is_accepted():
    check_view_size(4096, 4096)
    o = _config(view=(4096, 4096))
    assert o["atlas"]["width"] * o["atlas"]["height"] <= MAX_ATLAS_PIXELS
    assert SessionConfig.from_json(o).atlas.width == 4096 * 2 + 2048


@pytest.mark.parametrize("change, match", [
    (lambda o: o["atlas"]["rects"].pop("primary.depth"), "rectangle primary.depth is missing"),
    (lambda o: o["atlas"]["rects"]["extra.color"].__setitem__(2, 16), "extra.color is 16x32, not 32x32"),
    (lambda o: o.update(extra=None), "an extra view needs an extra_offset"),
    (lambda o: o.update(depth_bits=4), "min_code must be in"),
    (lambda o: o.update(depth_codec="edge"), "primary.depth has no view or depth to hold"),
])
def test_atlas_and_depth_settings_must_fit_the_views(change, match):
    o = copy.deepcopy(_config())
    change(o)
    with pytest.raises(MalformedMessage, match=match):
        SessionConfig.from_json(o)


@pytest.mark.parametrize("codec", [["edge"], {"h264": 1}, 12, None, "jpeg"])
def test_a_depth_codec_that_is_no_name_is_refused(codec):
    """Found by ``pibr bench fuzz`` when the codecs became a registry: a list is no codec name."""
    o = _config()
    o["depth_codec"] = codec
    with pytest.raises(MalformedMessage, match="depth_codec must be one of h264, edge"):
        SessionConfig.from_json(o)


def test_edge_codec_bits_must_be_decodable():
    o = _config("edge")
    o["depth_bits"] = 7
    with pytest.raises(MalformedMessage, match="edge codec carries 8..16 bits"):
        SessionConfig.from_json(o)


@pytest.mark.parametrize("where, value, match", [
    ("scene", {"bounds": [[0, float("nan"), 0], [1, 1, 1]]}, r"scene.bounds\[0\]\[1\]: nan is not a finite number"),
    ("options", {"k": 10**400}, "options.k: an integer of more than 100 digits"),
    ("proxies", {"deep": [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]}, "nested deeper than 32"),
])
def test_config_values_not_checked_field_by_field_are_still_bounded(where, value, match):
    # a config built in code (not read by the bounded reader) gets the same checks
    o = _config()
    o[where] = {**(o.get(where) or {}), **value}
    with pytest.raises(MalformedMessage, match=match):
        SessionConfig.from_json(o)


def test_viewer_origin_with_overflowing_quaternion_still_parses():
    o = _config()
    o["scene"]["viewer_origin"] = [0, 1.6, 0, 1, 0, 1e308, 0]
    q = SessionConfig.from_json(o).viewer_origin.orientation
    assert q == pytest.approx((0.0, 0.0, 1.0, 0.0), abs=1e-300)
