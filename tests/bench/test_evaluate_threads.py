"""evaluate's decoding thread and encoding thread: the images each tick showed, in order, and
errors raised where they belong, never lost."""
import threading

import numpy as np
import pytest

from pibr.bench.evaluate import _Ahead, _Behind, _shown_images
from pibr.client.recorder import MethodRecorder
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
