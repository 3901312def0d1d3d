"""The live view's series and its page server (client/live.py), on loopback."""
from __future__ import annotations

import asyncio
import io
import json
import math

import numpy as np
import pytest

from pibr.client.live import LiveSeries, LiveServer, WINDOW_S


def test_server_rate_and_bitrate_are_over_the_last_second():
    s = LiveSeries(["proxy"], 30.0)
    for k in range(30):                       # 10 frames a second of 2500 bytes, one per batch, for 3 s
        fps, kbps = s.frames(k / 10, 1, 2500, 3.0)
    assert fps == pytest.approx(10.0) and kbps == pytest.approx(200.0)
    fps, kbps = s.frames(3.5, 2, 5000, 4.0)   # a pause of 0.6 s, then two at once
    assert fps == pytest.approx(6.0) and kbps == pytest.approx(8 * (4 * 2500 + 5000) / 1e3)
    assert s.frames_total == 32


def test_series_keep_the_last_window_and_become_json():
    s = LiveSeries(["rotation", "proxy"], 20.0)
    n = int(WINDOW_S * 20) + 50
    for k in range(n):
        s.tick(k / 20, float("nan") if k == 0 else 150.0 + k, k % 7 == 0, {"rotation": 2.0, "proxy": 9.5},
               {"rotation": 0, "proxy": k % 2})
    snap = json.loads(json.dumps(s.snapshot(), allow_nan=False))
    assert snap["ticks_total"] == n and snap["missed_total"] == len(range(0, n, 7))
    assert len(snap["tick"]["t"]) == int(WINDOW_S * 20)
    assert snap["tick"]["t"][-1] == pytest.approx((n - 1) / 20)
    assert snap["tick"]["client_ms"]["proxy"][-1] == 9.5 and snap["tick"]["level"]["proxy"][-2:] in ([0, 1], [1, 0])
    # only what the page has not seen: from tick n - 3 on, and nothing older than the window holds
    part = s.snapshot(ticks_from=n - 3, batches_from=0)
    assert part["tick"]["t"] == pytest.approx([(n - 3) / 20, (n - 2) / 20, (n - 1) / 20])
    assert part["tick"]["client_ms"]["proxy"] == [9.5] * 3 and part["ticks_total"] == n
    assert len(s.snapshot(ticks_from=5)["tick"]["t"]) == int(WINDOW_S * 20)
    assert s.snapshot(ticks_from=n)["tick"]["t"] == []
    s2 = LiveSeries(["proxy"], 20.0)
    s2.tick(0.0, float("nan"), False, {"proxy": float("inf")}, {})
    assert s2.snapshot()["tick"]["age_ms"] == [None] and s2.snapshot()["tick"]["client_ms"]["proxy"] == [None]


async def _get(port: int, raw: bytes) -> tuple[int, dict, bytes]:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(raw)
    await writer.drain()
    data = await asyncio.wait_for(reader.read(), 10)
    writer.close()
    if not data:
        return 0, {}, b""
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode().split("\r\n")
    headers = dict(line.split(": ", 1) for line in lines[1:])
    return int(lines[0].split(" ")[1]), headers, body


def _request(path: str) -> bytes:
    return f"GET {path} HTTP/1.1\r\nHost: x\r\n\r\n".encode()


async def test_the_page_its_series_and_the_image():
    series = LiveSeries(["proxy"], 30.0)
    live = LiveServer(series, 0)
    port = await live.start()
    try:
        status, headers, body = await _get(port, _request("/"))
        assert status == 200 and headers["Content-Type"].startswith("text/html") and b"pibr live" in body
        for k in range(5):
            series.tick(k / 30, 180.0, False, {"proxy": 12.0}, {"proxy": 0})
        status, _, body = await _get(port, _request("/series.json"))
        assert status == 200 and json.loads(body)["ticks_total"] == 5 and len(json.loads(body)["tick"]["t"]) == 5
        status, _, body = await _get(port, _request("/series.json?ticks=3&batches=0"))
        assert status == 200 and json.loads(body)["tick"]["t"] == pytest.approx([3 / 30, 4 / 30], abs=1e-3)
        status, _, body = await _get(port, _request("/series.json?ticks=three"))
        assert status == 400 and b"whole numbers" in body
        assert not live.wants_image()             # nobody asked for an image: no tick reads one back
        status, _, body = await _get(port, _request("/image.jpg"))
        assert status == 204 and body == b""      # asked, none yet
        assert live.wants_image()
        rgb = np.zeros((540, 960, 3), np.uint8)
        rgb[:, :480] = (200, 30, 30)
        live.set_image(rgb)
        assert not live.wants_image()             # at most every IMAGE_EVERY_S
        status, headers, body = await _get(port, _request("/image.jpg"))
        assert status == 200 and headers["Content-Type"] == "image/jpeg"
        from PIL import Image

        img = np.asarray(Image.open(io.BytesIO(body)).convert("RGB"))
        assert img.shape == (540, 960, 3)         # 960 wide: no downscaling below 640 steps
        assert np.abs(img[270, 100].astype(int) - (200, 30, 30)).max() < 12 and img[270, 800].max() < 12
        cost = live.cost(ticks=5, interval_ms=1000 / 30)
        assert cost["requests"] == 6 and cost["thread_ms"] > 0
        assert math.isclose(cost["loop_share_of_tick_time"], live.loop_ms / (5 * 1000 / 30))
    finally:
        await live.close()


@pytest.mark.parametrize("raw, status", [
    (b"POST / HTTP/1.1\r\n\r\n", 405),
    (b"GET /secret HTTP/1.1\r\n\r\n", 404),
    (b"\xff\xfe garbage\r\n\r\n", 400),
    (b"GET /\r\n\r\n", 400),
    (b"GET /" + b"a" * 9000 + b" HTTP/1.1\r\n\r\n", 0),   # over the request limit: closed, no answer
])
async def test_bad_requests_get_a_clear_answer_and_the_page_keeps_serving(raw, status):
    live = LiveServer(LiveSeries(["proxy"], 30.0), 0)
    port = await live.start()
    try:
        got, _, body = await _get(port, raw)
        assert got == status
        if status:
            assert body.strip()
        got, _, _ = await _get(port, _request("/series.json"))
        assert got == 200
    finally:
        await live.close()


async def test_a_silent_connection_does_not_hold_the_page():
    live = LiveServer(LiveSeries(["proxy"], 30.0), 0)
    port = await live.start()
    silent = [await asyncio.open_connection("127.0.0.1", port) for _ in range(3)]
    try:
        got, _, _ = await _get(port, _request("/series.json"))
        assert got == 200
    finally:
        for _, w in silent:
            w.close()
        await live.close()


async def test_a_port_in_use_is_named():
    from pibr.protocol.errors import ConfigError

    first = LiveServer(LiveSeries(["proxy"], 30.0), 0)
    port = await first.start()
    try:
        with pytest.raises(ConfigError, match=rf"--live {port}: cannot serve the live page on 127.0.0.1:{port}"):
            await LiveServer(LiveSeries(["proxy"], 30.0), port).start()
    finally:
        await first.close()


def test_the_live_image_of_two_eyes_is_the_pair_side_by_side():
    import numpy as np

    from pibr.client.app import live_image
    from pibr.client.recorder import PAIR_GAP

    left, right = np.full((4, 6, 3), 10, np.uint8), np.full((4, 6, 3), 200, np.uint8)
    assert live_image([(left, 0.0, 1.0)]) is left
    pair = live_image([(left, 0.0, 1.0), (right, 0.0, 1.0)])
    assert pair.shape == (4, 12 + PAIR_GAP, 3)
    assert np.all(pair[:, :6] == 10) and np.all(pair[:, -6:] == 200) and np.all(pair[:, 6:6 + PAIR_GAP] == 0)
    assert live_image([(left, 0.0, 1.0), (None, 0.0, 1.0)]) is None   # not read back this tick
