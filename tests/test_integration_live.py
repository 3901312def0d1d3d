"""The live view of a running session, in a real browser: server and client as real processes on
loopback (the wall clock, so the session runs at its own pace while the page is read)."""
import csv
import json
import os
import signal
import threading

import pytest

from pibr.bench.processes import PibrProcess, free_port

pytestmark = [pytest.mark.integration, pytest.mark.gl]


def test_the_live_page_follows_a_running_session(tmp_path, chromium):
    out = str(tmp_path / "live")
    live_port = free_port()
    server = PibrProcess("server", ["serve", "--port", "0", "--scene", "room", "--view-size", "256x256"],
                         str(tmp_path / "server.log"))
    page = None
    try:
        host, port = server.wait_listening()
        ticking = threading.Event()
        client = PibrProcess("client", ["client", "--connect", f"{host}:{port}", "--out", out, "--progress", "lines",
                                        "--trace", "pred6dof-1", "--start", "10", "--duration", "40", "--rate", "30",
                                        "--size", "160x96", "--method", "rotation", "--clock", "real",
                                        "--live", str(live_port)],
                             str(tmp_path / "client.log"), on_progress=lambda done, total: done >= 15 and ticking.set())
        assert ticking.wait(300), client.tail()
        page = chromium.new_page()
        errors = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.goto(f"http://127.0.0.1:{live_port}/")
        page.wait_for_function("Number(document.getElementById('ticks').textContent) > 0", timeout=20000)
        first = int(page.inner_text("#ticks"))
        page.wait_for_function(f"Number(document.getElementById('ticks').textContent) >= {first + 15}", timeout=20000)
        # the current image arrives, and is replaced by newer ones
        page.wait_for_function("document.getElementById('image').src.startsWith('blob:')", timeout=20000)
        shown_at = int(page.get_attribute("#image", "data-tick"))
        page.wait_for_function(f"Number(document.getElementById('image').dataset.tick) > {shown_at}", timeout=20000)
        for plot in ("p-age", "p-render", "p-decode", "p-fps", "p-kbps", "p-missed"):
            assert int(page.get_attribute(f"#{plot}", "data-points")) > 0, plot
        assert float(page.inner_text("#fps")) > 0 and float(page.inner_text("#age")) > 0
        assert errors == []
        client.proc.send_signal(signal.SIGINT)
        assert client.wait(120) == 130, client.tail()
    finally:
        if page is not None:
            page.close()
        server.stop()
    with open(os.path.join(out, "session.json")) as f:
        live = json.load(f)["live"]
    assert live["url"] == f"http://127.0.0.1:{live_port}/" and live["requests"] >= 6
    assert live["thread_ms"] > 0 and 0 < live["loop_share_of_tick_time"] < 1
    with open(os.path.join(out, "stream.csv")) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) >= 3 and all(int(r["frames"]) >= 1 and int(r["wire_bytes"]) > 0 for r in rows)
