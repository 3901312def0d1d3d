"""A running session seen live in a browser: ``pibr client --live PORT``.

:class:`LiveSeries` keeps what the last seconds of the session did (no I/O): per tick the frame
age, whether the tick was missed, each method's render ms and quality level; per batch of frames
decoded, how many, their wire bytes and the decode ms, from which the server's frame rate and the
bitrate over the last second follow. The same per-batch rows go to the recording's
``stream.csv`` (client/app.py), so ``pibr report`` plots them after the run.

:class:`LiveServer` serves, on loopback only, a page that polls those series and the current
image (``/``, ``/series.json``, ``/image.jpg``). It runs on the client's event loop and does
little there: the series are appended in O(1), the page asks only for what it has not seen yet
(``/series.json?ticks=N&batches=M``: a poll's few new entries, not the whole window), and the JPEG
is encoded in a worker thread from the newest image, read back only while someone watches. What
it costs the loop is measured (``cost()``) and written to ``session.json`` as ``live``.
"""
from __future__ import annotations

import asyncio
import json
import logging
import math
import time
import urllib.parse
from collections import deque

import numpy as np

from pibr.common.priority import background_executor
from pibr.protocol.errors import ConfigError

log = logging.getLogger(__name__)

#: What the page shows: the last this many seconds of the session.
WINDOW_S = 10.0
#: The server's frame rate and the bitrate are counted over this many seconds of arrivals.
RATE_WINDOW_S = 1.0
#: The image is read back for the page only while a request for it came within this long.
IMAGE_WATCHED_S = 2.0
#: ... and at most this often.
IMAGE_EVERY_S = 0.25
MAX_REQUEST_BYTES = 8192
MAX_CONNECTIONS = 8
REQUEST_TIMEOUT_S = 5.0


class LiveSeries:
    """The session's last :data:`WINDOW_S` seconds: ticks and frame batches, times in client seconds."""

    def __init__(self, methods, rate_hz: float, window_s: float = WINDOW_S):
        self.methods = list(methods)
        self.rate_hz = rate_hz
        self._keep = max(2, int(window_s * rate_hz))
        self.ticks = deque(maxlen=self._keep)     # (t, age_ms, missed, {method: ms}, {method: level})
        self.batches = deque(maxlen=self._keep)   # (t, frames, wire bytes, decode ms, fps, kbps)
        self._recent = deque()                    # (t, frames, bytes) within RATE_WINDOW_S of the newest
        self.ticks_total = 0
        self.missed_total = 0
        self.frames_total = 0
        self.batches_total = 0

    def tick(self, t_s: float, age_ms: float, missed: bool, client_ms: dict, levels: dict) -> None:
        self.ticks.append((t_s, age_ms, bool(missed), dict(client_ms), dict(levels)))
        self.ticks_total += 1
        self.missed_total += bool(missed)

    def frames(self, t_s: float, count: int, wire_bytes: int, decode_ms: float) -> tuple[float, float]:
        """One batch decoded at ``t_s``; -> (server frames/s, kbit/s) over the last RATE_WINDOW_S."""
        self._recent.append((t_s, count, wire_bytes))
        while self._recent and self._recent[0][0] <= t_s - RATE_WINDOW_S:
            self._recent.popleft()
        fps = sum(c for _, c, _ in self._recent) / RATE_WINDOW_S
        kbps = 8.0 * sum(b for _, _, b in self._recent) / RATE_WINDOW_S / 1e3
        self.batches.append((t_s, count, wire_bytes, decode_ms, fps, kbps))
        self.frames_total += count
        self.batches_total += 1
        return fps, kbps

    def snapshot(self, ticks_from: int = 0, batches_from: int = 0) -> dict:
        """The series as JSON-ready lists (None where a value is not a finite number), from tick
        number ``ticks_from`` and batch number ``batches_from`` on (counting from the session's
        first; what the window still holds)."""
        def num(v):
            return None if v is None or not math.isfinite(v) else round(float(v), 3)

        def newer(entries, total, start):
            skip = max(0, start - (total - len(entries)))
            return [e for k, e in enumerate(entries) if k >= skip] if skip else list(entries)
        ticks = newer(self.ticks, self.ticks_total, ticks_from)
        batches = newer(self.batches, self.batches_total, batches_from)
        return {
            "methods": self.methods, "rate_hz": self.rate_hz, "window": self._keep,
            "ticks_total": self.ticks_total, "missed_total": self.missed_total, "frames_total": self.frames_total,
            "batches_total": self.batches_total,
            "tick": {"t": [num(t[0]) for t in ticks], "age_ms": [num(t[1]) for t in ticks],
                     "missed": [int(t[2]) for t in ticks],
                     "client_ms": {m: [num(t[3].get(m)) for t in ticks] for m in self.methods},
                     "level": {m: [t[4].get(m) for t in ticks] for m in self.methods}},
            "frames": {"t": [num(b[0]) for b in batches], "decode_ms": [num(b[3]) for b in batches],
                       "server_fps": [num(b[4]) for b in batches], "kbps": [num(b[5]) for b in batches]},
        }


class LiveServer:
    """The live page on ``127.0.0.1:port`` (0: any free port), from ``series`` and the newest image."""

    def __init__(self, series: LiveSeries, port: int, host: str = "127.0.0.1"):
        self.series = series
        self.host, self.port = host, port
        self._server: asyncio.base_events.Server | None = None
        self._image: np.ndarray | None = None
        self._image_t = 0.0
        self._image_asked = -1e9
        self._jpeg_pool = None
        self._open = 0
        self.requests = 0
        # CPU time (time.thread_time: this thread's own, not the waits for the GIL that other
        # threads hold meanwhile) the event loop spent on the page (requests, snapshots, series),
        # and the worker thread encoding images
        self.loop_ms = 0.0
        self.thread_ms = 0.0

    async def start(self) -> int:
        # the page's images use the CPU the ticks leave (common/priority.py)
        self._jpeg_pool = background_executor("pibr-live")
        try:
            self._server = await asyncio.start_server(self._handle, self.host, self.port, limit=MAX_REQUEST_BYTES)
        except OSError as exc:
            self._jpeg_pool.shutdown(wait=False)
            raise ConfigError(f"--live {self.port}: cannot serve the live page on {self.host}:{self.port} "
                              f"({exc.strerror or exc}); choose another port, or 0 for any free one") from None
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def wants_image(self) -> bool:
        """Whether the tick should hand over its image: someone watches and the last is old enough."""
        now = time.monotonic()
        return now - self._image_asked < IMAGE_WATCHED_S and now - self._image_t >= IMAGE_EVERY_S

    def set_image(self, rgb: np.ndarray) -> None:
        """The newest shown (H, W, 3) uint8 image; kept by reference (the caller never writes to it)."""
        self._image, self._image_t = rgb, time.monotonic()

    def account(self, ms: float) -> None:
        """Count ``ms`` of the event loop's CPU time spent for the page (the caller measures its calls
        with ``time.thread_time``)."""
        self.loop_ms += ms

    def cost(self, ticks: int, interval_ms: float) -> dict:
        """What the page cost: event-loop and worker CPU ms, and their shares of the ticks' time."""
        total = max(ticks, 1) * interval_ms
        return {"requests": self.requests, "loop_ms": round(self.loop_ms, 3), "thread_ms": round(self.thread_ms, 3),
                "loop_share_of_tick_time": self.loop_ms / total, "thread_share_of_tick_time": self.thread_ms / total}

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None
        if self._jpeg_pool is not None:
            self._jpeg_pool.shutdown(wait=True)

    # -- HTTP -------------------------------------------------------------------------------------------------

    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self._open >= MAX_CONNECTIONS:   # a page polls with one or two requests at a time
            writer.close()
            return
        self._open += 1
        try:
            try:
                head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), REQUEST_TIMEOUT_S)
            except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, asyncio.TimeoutError, ConnectionError):
                return
            t0 = time.thread_time()
            status, ctype, body = self._answer(head)
            if ctype == "image/jpeg" and status == 200:
                self.loop_ms += (time.thread_time() - t0) * 1e3
                body = await self._jpeg()
                t0 = time.thread_time()
                if body is None:   # nothing read back yet: it will be from the next tick on
                    status, body = 204, b""
            writer.write(f"HTTP/1.1 {status} {_REASONS[status]}\r\nContent-Type: {ctype}\r\n"
                         f"Content-Length: {len(body)}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n"
                         .encode("ascii") + body)
            self.requests += 1
            self.loop_ms += (time.thread_time() - t0) * 1e3
            await writer.drain()
        except ConnectionError:
            pass
        finally:
            self._open -= 1
            writer.close()

    def _answer(self, head: bytes) -> tuple[int, str, bytes]:
        try:
            method, target, _ = head.split(b"\r\n", 1)[0].decode("ascii").split(" ")
        except (UnicodeDecodeError, ValueError):
            return 400, "text/plain; charset=utf-8", b"bad request line\n"
        if method != "GET":
            return 405, "text/plain; charset=utf-8", b"only GET\n"
        path, _, query = target.partition("?")
        if path == "/":
            return 200, "text/html; charset=utf-8", PAGE.encode("utf-8")
        if path == "/series.json":
            try:
                given = {k: int(v) for k, v in urllib.parse.parse_qsl(query, strict_parsing=bool(query))
                         if k in ("ticks", "batches")}
            except ValueError:
                return 400, "text/plain; charset=utf-8", b"ticks= and batches= take whole numbers\n"
            snap = self.series.snapshot(max(0, given.get("ticks", 0)), max(0, given.get("batches", 0)))
            return 200, "application/json", json.dumps(snap, separators=(",", ":")).encode()
        if path == "/favicon.ico":   # browsers ask for one: none, and no error in the page's console
            return 204, "image/x-icon", b""
        if path == "/image.jpg":
            self._image_asked = time.monotonic()
            return 200, "image/jpeg", b""
        return 404, "text/plain; charset=utf-8", b"not found: / /series.json /image.jpg\n"

    async def _jpeg(self) -> bytes | None:
        image = self._image
        if image is None:
            return None

        def encode() -> tuple[bytes, float]:
            import io

            from PIL import Image

            t0 = time.thread_time()
            step = max(1, image.shape[1] // 640)
            buf = io.BytesIO()
            Image.fromarray(np.ascontiguousarray(image[::step, ::step])).save(buf, format="JPEG", quality=75)
            return buf.getvalue(), (time.thread_time() - t0) * 1e3
        data, ms = await asyncio.get_running_loop().run_in_executor(self._jpeg_pool, encode)
        self.thread_ms += ms
        return data


_REASONS = {200: "OK", 204: "No Content", 400: "Bad Request", 404: "Not Found", 405: "Method Not Allowed", 503: "Service Unavailable"}

PAGE = """<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>pibr live</title><style>
body { font: 14px/1.4 system-ui, sans-serif; margin: 1em; color: #222; }
.counters span { display: inline-block; margin-right: 1.5em; } .counters b { font-size: 1.3em; }
.grid { display: flex; flex-wrap: wrap; gap: 12px; } svg { background: #fafafa; border: 1px solid #ddd; }
svg text { font-size: 11px; fill: #444; } #image { max-width: 640px; background: #000; display: block; }
#status { color: #a00; }
</style></head><body><h1>pibr live</h1>
<div class="counters"><span>ticks <b id="ticks">0</b></span><span>missed <b id="missed">0</b></span>
<span>server <b id="fps">–</b> frames/s</span><span><b id="mbps">–</b> Mbit/s</span>
<span>frame age <b id="age">–</b> ms</span><span id="status"></span></div>
<div class="grid"><img id="image" alt="the client's current image"><div id="plots" class="grid"></div></div>
<script>
"use strict";
const COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b"];
const SVG = "http://www.w3.org/2000/svg";
function plot(id, title, xs, lines) {
  let box = document.getElementById(id);
  if (!box) { box = document.createElementNS(SVG, "svg"); box.id = id; box.setAttribute("width", 420);
              box.setAttribute("height", 150); document.getElementById("plots").appendChild(box); }
  const W = 420, H = 150, L = 44, R = 6, T = 18, B = 16;
  let lo = Infinity, hi = -Infinity, x0 = Infinity, x1 = -Infinity;
  for (const ys of Object.values(lines)) ys.forEach(function (v, i) { if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); x0 = Math.min(x0, xs[i]); x1 = Math.max(x1, xs[i]); } });
  let parts = '<text x="' + L + '" y="12">' + title + '</text>';
  if (hi >= lo) {
    if (hi === lo) { hi += 1; lo = Math.max(0, lo - 1); }
    if (x1 === x0) x1 = x0 + 1;
    const x = function (v) { return L + (W - L - R) * (v - x0) / (x1 - x0); };
    const y = function (v) { return T + (H - T - B) * (1 - (v - lo) / (hi - lo)); };
    parts += '<text x="2" y="' + (T + 8) + '">' + hi.toFixed(hi < 10 ? 1 : 0) + '</text><text x="2" y="' + (H - B) + '">' + lo.toFixed(hi < 10 ? 1 : 0) + '</text>';
    parts += '<text x="' + (W - R) + '" y="' + (H - 3) + '" text-anchor="end">' + x1.toFixed(1) + ' s</text>';
    Object.keys(lines).forEach(function (name, k) {
      const pts = [];
      lines[name].forEach(function (v, i) { if (v !== null) pts.push(x(xs[i]).toFixed(1) + "," + y(v).toFixed(1)); });
      parts += '<polyline fill="none" stroke-width="1.3" stroke="' + COLOURS[k % 6] + '" points="' + pts.join(" ") + '"/>';
      parts += '<text x="' + (L + 4 + 90 * k) + '" y="' + (H - 3) + '" fill="' + COLOURS[k % 6] + '">' + name + '</text>';
    });
  }
  box.innerHTML = parts;
  box.dataset.points = String(xs.length);
}
function last(a) { for (let i = a.length - 1; i >= 0; i--) if (a[i] !== null) return a[i]; return null; }
// The page keeps the window and asks only for what it has not seen (a poll's few new entries).
const kept = { tick: null, frames: null }, seen = { ticks: 0, batches: 0 };
function merge(into, fresh, keep) {
  if (into === null) return fresh;
  for (const k in fresh) {
    if (Array.isArray(fresh[k])) into[k] = into[k].concat(fresh[k]).slice(-keep);
    else into[k] = merge(into[k], fresh[k], keep);
  }
  return into;
}
async function poll() {
  try {
    const got = await (await fetch("/series.json?ticks=" + seen.ticks + "&batches=" + seen.batches, { cache: "no-store" })).json();
    seen.ticks = got.ticks_total; seen.batches = got.batches_total;
    kept.tick = merge(kept.tick, got.tick, got.window); kept.frames = merge(kept.frames, got.frames, got.window);
    const s = Object.assign({}, got, { tick: kept.tick, frames: kept.frames });
    document.getElementById("ticks").textContent = s.ticks_total;
    document.getElementById("missed").textContent = s.missed_total;
    const fps = last(s.frames.server_fps), kbps = last(s.frames.kbps), age = last(s.tick.age_ms);
    document.getElementById("fps").textContent = fps === null ? "–" : fps.toFixed(1);
    document.getElementById("mbps").textContent = kbps === null ? "–" : (kbps / 1000).toFixed(2);
    document.getElementById("age").textContent = age === null ? "–" : age.toFixed(0);
    plot("p-age", "frame age ms", s.tick.t, { age: s.tick.age_ms });
    plot("p-missed", "missed ticks", s.tick.t, { missed: s.tick.missed });
    plot("p-render", "render ms per method", s.tick.t, s.tick.client_ms);
    plot("p-decode", "decode ms per batch", s.frames.t, { decode: s.frames.decode_ms });
    plot("p-fps", "server frames/s", s.frames.t, { fps: s.frames.server_fps });
    plot("p-kbps", "kbit/s received", s.frames.t, { kbps: s.frames.kbps });
    document.getElementById("status").textContent = "";
    const r = await fetch("/image.jpg", { cache: "no-store" });
    if (r.status === 200) {
      const img = document.getElementById("image"), old = img.src;
      img.src = URL.createObjectURL(await r.blob());
      img.dataset.tick = String(s.ticks_total);
      if (old.startsWith("blob:")) URL.revokeObjectURL(old);
    }
  } catch (e) {
    document.getElementById("status").textContent = "session ended or not reachable";
  }
}
poll(); setInterval(poll, 500);
</script></body></html>
"""
