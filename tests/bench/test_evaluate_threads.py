"""evaluate's decoding thread and encoding thread: the images each tick showed, in order, and
errors raised where they belong, never lost."""
import os
import threading

import numpy as np
import pytest

from pibr.bench.evaluate import _Ahead, _Behind, _shown_images
from pibr.client.recorder import MethodRecorder, lossless_recording
from pibr.protocol.errors import ConfigError


def _record(tmp_path, shown_ticks, ticks):
    """A real lossless recording of method 'm': tick i shows a flat image of level 10 * i when i is
    in ``shown_ticks``, else it is missed (the previous image stays)."""
    rec = MethodRecorder(str(tmp_path), "m", 32, 16, 30.0, records=False)
    rows = []
    for i in range(ticks):
        rows.append({"tick": i, "missed": int(i not in shown_ticks)})
        if i in shown_ticks:
            rec.submit(np.full((16, 32, 3), 10 * i, np.uint8), rows[-1])
        else:
            rec.repeat(rows[-1])
    rec.close()
    return {"m": rows}


def test_shown_images_hold_the_previous_image_on_a_missed_tick(tmp_path):
    records = _record(tmp_path, {1, 2, 5}, 7)
    levels = [None if s["m"] is None else int(s["m"][0, 0, 0])
              for s in _Ahead(_shown_images(str(tmp_path), ["m"], records, 7), depth=2)]
    assert levels == [None, 10, 20, 20, 20, 50, 50]


def test_a_recording_shorter_than_its_records_is_named_by_the_consumer(tmp_path):
    records = _record(tmp_path, {0, 1}, 3)
    records["m"][2]["missed"] = 0      # the records claim a third image the video does not hold
    ahead = _Ahead(_shown_images(str(tmp_path), ["m"], records, 3), depth=2)
    assert next(ahead)["m"] is not None and next(ahead)["m"] is not None
    with pytest.raises(ConfigError, match="ends at tick 2"):
        next(ahead)
    ahead.close()


def test_the_lossless_recording_holds_every_shown_image_to_the_bit(tmp_path):
    """Ut Video (client/recorder.py): noisy images of odd content, every bit back, in tick order."""
    rng = np.random.default_rng(3)
    images = [rng.integers(0, 256, (18, 34, 3), dtype=np.uint8) for _ in range(5)]
    images[2][:, :17] = 255          # flat areas beside noise
    rec = MethodRecorder(str(tmp_path), "m", 34, 18, 30.0, records=False)
    rows = []
    for i in range(7):
        rows.append({"tick": i, "missed": int(i in (1, 4))})
        if i in (1, 4):
            rec.repeat(rows[-1])
        else:
            rec.submit(images[len([r for r in rows if not r["missed"]]) - 1], rows[-1])
    rec.close()
    assert os.path.exists(tmp_path / "m.lossless.avi")
    shown = [s["m"] for s in _shown_images(str(tmp_path), ["m"], {"m": rows}, 7)]
    expected = [images[0], images[0], images[1], images[2], images[2], images[3], images[4]]
    assert all(np.array_equal(a, b) for a, b in zip(shown, expected))


def test_a_legacy_h264_lossless_recording_is_still_read(tmp_path):
    """Recordings made before Ut Video hold M.lossless.mkv (x264 4:4:4 at qp 0): evaluate reads them."""
    import av

    rng = np.random.default_rng(4)
    images = [rng.integers(0, 256, (16, 32, 3), dtype=np.uint8) for _ in range(3)]
    with av.open(str(tmp_path / "m.lossless.mkv"), "w") as container:
        stream = container.add_stream("libx264rgb", rate=30)
        stream.width, stream.height, stream.pix_fmt = 32, 16, "rgb24"
        stream.options = {"preset": "ultrafast", "qp": "0"}
        for i, image in enumerate(images):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts = i
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    assert lossless_recording(str(tmp_path), "m").endswith("m.lossless.mkv")
    rows = {"m": [{"tick": i, "missed": 0} for i in range(3)]}
    shown = [s["m"] for s in _shown_images(str(tmp_path), ["m"], rows, 3)]
    assert all(np.array_equal(a, b) for a, b in zip(shown, images))


def test_a_recording_cut_short_is_named_with_the_frame_it_breaks_at(tmp_path):
    """A file cut in the middle of a frame (a client killed while writing): a clear error naming
    the file and how far it decodes, not an FFmpeg traceback."""
    rng = np.random.default_rng(5)
    rec = MethodRecorder(str(tmp_path), "m", 32, 16, 30.0, records=False)
    for i in range(6):
        rec.submit(rng.integers(0, 256, (16, 32, 3), dtype=np.uint8), {"tick": i, "missed": 0})
    rec.close()
    path = tmp_path / "m.lossless.avi"
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    rows = {"m": [{"tick": i, "missed": 0} for i in range(6)]}
    with pytest.raises(ConfigError, match=r"m\.lossless\.avi: cannot decode past frame [1-5]"):
        list(_shown_images(str(tmp_path), ["m"], rows, 6))


def test_closing_early_stops_the_thread_and_closes_the_items():
    closed = threading.Event()

    def endless():
        try:
            i = 0
            while True:
                yield i
                i += 1
        finally:
            closed.set()

    ahead = _Ahead(endless(), depth=2)
    assert [next(ahead) for _ in range(3)] == [0, 1, 2]
    ahead.close()   # the producer is blocked on a full queue: it must notice and stop
    assert closed.is_set() and not ahead._thread.is_alive()


class _Writer:
    def __init__(self, fail_at=None):
        self.frames, self.fail_at, self.closed = [], fail_at, False

    def write(self, frame):
        if len(self.frames) == self.fail_at:
            raise ValueError("disk full")
        self.frames.append(int(frame[0, 0, 0]))

    def close(self):
        self.closed = True


def test_frames_written_behind_keep_their_order_and_errors_surface():
    ok = _Writer()
    behind = _Behind(ok, depth=2)
    for i in range(20):
        behind.write(np.full((2, 2, 3), i, np.uint8))
    behind.close()
    assert ok.frames == list(range(20)) and ok.closed
    failing = _Writer(fail_at=3)
    behind = _Behind(failing, depth=2)
    with pytest.raises(ValueError, match="disk full"):
        try:
            for i in range(50):
                behind.write(np.full((2, 2, 3), i, np.uint8))
        finally:
            behind.close()   # as evaluate's finally does: the writer closes, the error is raised once
    assert failing.frames == [0, 1, 2] and failing.closed
    late = _Writer(fail_at=5)   # failing on a frame after the last write: close raises it
    behind = _Behind(late, depth=8)
    for i in range(6):
        behind.write(np.full((2, 2, 3), i, np.uint8))
    with pytest.raises(ValueError, match="disk full"):
        behind.close()


def test_a_sessions_eye_frustums_are_read_and_bad_ones_named():
    from pibr.bench.evaluate import _eye_frustums
    from pibr.protocol.errors import ConfigError
    from pibr.protocol.frustum import eye_tangents

    assert _eye_frustums({"eye_fov_deg": None}, ["left", "right"]) == {"left": None, "right": None}
    got = _eye_frustums({"eye_fov_deg": [52, 42, 30, 33]}, ["left", "right"])
    assert got == {e: eye_tangents(e, (52, 42, 30, 33)) for e in ("left", "right")}
    for bad in ([52, 42, 30], "wide", [52, 42, 30, 95], {"outer": 52}):
        with pytest.raises(ConfigError, match="session.json: client.eye_fov_deg"):
            _eye_frustums({"eye_fov_deg": bad}, ["left", "right"])
