"""The server's depth quadtrees: the vectorised builder at its extremes and against a plain
recursive one, and a session that sends them when (and only when) the Hello asks."""
from __future__ import annotations

import asyncio
import dataclasses

import numpy as np
import pytest

from pibr.client.connection import ClientConnection
from pibr.protocol.connection import Connection
from pibr.protocol.errors import MalformedMessage
from pibr.protocol.framing import encode_frame
from pibr.protocol.messages import Error, Hello, OutputConfig, PayloadKind
from pibr.protocol.quadtree import decode_quadtrees
from pibr.server.config import ServerConfig
from pibr.server.quadtree import ROOT_TILE, build_leaves, quadtree_payload

from ..loopback import exchange_virtual, running_server
from ..protocol.golden_quadtree import reference_leaves, scene_distances


def _cover(leaves, h, w) -> np.ndarray:
    cover = np.zeros((h, w), int)
    for x, y, s in leaves:
        cover[y:y + s, x:x + s] += 1
    return cover


def _same(a, b) -> bool:
    return sorted(map(tuple, np.asarray(a).tolist())) == sorted(map(tuple, np.asarray(b).tolist()))


@pytest.mark.parametrize("h, w", [(128, 192), (100, 130), (1, 1), (63, 65)])
def test_constant_depth_is_one_leaf_per_root_tile(h, w):
    leaves = build_leaves(np.full((h, w), 3.5, np.float32), 1e-6)
    tiles = -(-h // ROOT_TILE) * -(-w // ROOT_TILE)
    assert len(leaves) == tiles and (leaves[:, 2] == ROOT_TILE).all()
    assert (_cover(leaves, h, w) == 1).all()


def test_all_sky_is_one_leaf_per_root_tile():
    leaves = build_leaves(np.zeros((70, 140), np.float32), 0.05)
    assert len(leaves) == 2 * 3 and (leaves[:, 2] == ROOT_TILE).all()


def test_noise_is_all_single_pixels():
    rng = np.random.default_rng(0)
    h, w = 90, 150                                      # no multiple of the tile either
    d = (1.0 + rng.random((h, w))).astype(np.float32)
    d[::2, ::2] *= 1.5                                  # no 2 x 2 block within 1 %
    leaves = build_leaves(d, 0.01)
    assert len(leaves) == h * w and (leaves[:, 2] == 1).all()
    assert (_cover(leaves, h, w) == 1).all()


def test_sky_and_geometry_never_share_a_leaf():
    h, w = 96, 160
    d = np.full((h, w), 4.0, np.float32)
    d[:, :37] = 0.0                                     # sky left of an unaligned column
    d[60:, 100:] = 0.0                                  # and a sky notch
    leaves = build_leaves(d, 0.5)
    assert (_cover(leaves, h, w) == 1).all()
    for x, y, s in leaves:
        block = d[y:y + s, x:x + s]
        assert (block > 0).all() or (block == 0).all(), (x, y, s)
    # on both sides of the boundary column the leaves are single pixels; away from it, large
    for column in (36, 37):
        at = leaves[(leaves[:, 0] <= column) & (leaves[:, 0] + leaves[:, 2] > column)]
        assert len(at) == h and (at[:, 2] == 1).all()
    assert leaves[:, 2].max() == ROOT_TILE


def test_threshold_is_relative_and_inclusive():
    d = np.full((2, 2), 2.0, np.float32)
    d[1, 1] = 3.0                                       # range 1.0 = 0.5 * min
    assert len(build_leaves(d, 0.5, tile=2)) == 1
    assert len(build_leaves(d, 0.49, tile=2)) == 4
    far = d * 1000                                      # the same relative range far away
    assert len(build_leaves(far, 0.5, tile=2)) == 1


@pytest.mark.parametrize("h, w, tile, threshold, seed", [
    (70, 100, 64, 0.02, 0), (24, 40, 16, 0.05, 1), (33, 17, 8, 0.2, 2), (64, 64, 64, 0.01, 3), (5, 300, 4, 0.1, 4),
    (7, 5, 1, 0.1, 5),
])
def test_vectorised_builder_matches_the_definition(h, w, tile, threshold, seed):
    d = scene_distances(h, w, seed)
    leaves = build_leaves(d, threshold, tile)
    assert _same(leaves, reference_leaves(d, threshold, tile))
    assert (_cover(leaves, h, w) == 1).all()


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_builder_rejects_bad_thresholds(bad):
    with pytest.raises(ValueError, match="threshold"):
        build_leaves(np.ones((4, 4), np.float32), bad)


def test_payload_holds_both_views():
    primary, extra = scene_distances(100, 120, 5), scene_distances(50, 60, 6)
    data = quadtree_payload({"primary": primary, "extra": extra}, 0.02)
    a, b = decode_quadtrees(data, [(120, 100), (60, 50)])
    assert _same(a, build_leaves(primary, 0.02)) and _same(b, build_leaves(extra, 0.02))


# ------------------------------------------------------------------ sessions

HELLO = Hello(client="test", scene="sphere", clock="virtual", output=OutputConfig(160, 96, 90.0, 30.0))


@pytest.fixture
async def server():
    config = ServerConfig(port=0, scene="sphere", view_size=(128, 128), fps=10.0, server_delay_ms=20.0,
                          bitrate_kbps=2000, extra_view="on")
    async with running_server(config) as (_, host, port):
        yield host, port


async def _frames(host, port, hello, ticks=4):
    c = await ClientConnection.open(host, port)
    cfg = await c.handshake(hello)
    frames = await exchange_virtual(c, cfg.viewer_origin, [k * 33_333 for k in range(ticks)], 33_333)
    await c.close()
    return cfg, [f for _, f in frames]


@pytest.mark.gl
async def test_session_sends_quadtrees_only_when_asked(server):
    host, port = server
    cfg, frames = await _frames(host, port, dataclasses.replace(HELLO, quadtree_threshold=0.05))
    assert frames and cfg.options["quadtree"] == {"threshold": 0.05, "tile": ROOT_TILE}
    sizes = [(cfg.primary.width, cfg.primary.height), (cfg.extra.width, cfg.extra.height)]
    for f in frames:
        trees = decode_quadtrees(f.payload(PayloadKind.QUADTREE), sizes)
        for (w, h), leaves in zip(sizes, trees):
            assert (_cover(leaves, h, w) == 1).all()
        # the sphere against the sky: large leaves (208 for 128 x 128 pixels here), single
        # pixels along its outline
        assert len(trees[0]) < 0.05 * 128 * 128
        assert trees[0][:, 2].max() >= ROOT_TILE // 2 and trees[0][:, 2].min() == 1
    cfg, frames = await _frames(host, port, HELLO)
    assert frames and "quadtree" not in cfg.options
    assert all(f.payload(PayloadKind.QUADTREE) is None for f in frames)


@pytest.mark.gl
async def test_a_bad_threshold_is_refused_by_name(server):
    host, port = server
    reader, writer = await asyncio.open_connection(host, port)
    writer.write(encode_frame(Hello.TYPE, b'{"protocol": 1, "quadtree_threshold": -1}'))
    await writer.drain()
    conn = Connection()
    while chunk := await asyncio.wait_for(reader.read(65536), 10):
        conn.receive_data(chunk)
    writer.close()
    errors = [e.message for e in conn.events_received() if isinstance(e.message, Error)]
    assert errors and errors[0].code == MalformedMessage.code and "quadtree_threshold" in errors[0].text
