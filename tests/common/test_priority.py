"""Background threads run at a lower priority than the tick (pibr.common.priority)."""
import concurrent.futures
import os
import sys
import threading

import pytest

from pibr.common.priority import BACKGROUND_NICE, lower_this_thread


def _nice() -> int:
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice is Linux's")
def test_a_pool_started_with_it_runs_lower_and_leaves_the_caller_as_it_was():
    before = _nice()
    with concurrent.futures.ThreadPoolExecutor(max_workers=1, initializer=lower_this_thread) as pool:
        inside = pool.submit(_nice).result()
        child = pool.submit(lambda: _run_in_thread(_nice)).result()     # threads it starts inherit it
    assert inside == min(19, before + BACKGROUND_NICE)
    assert child == inside
    assert _nice() == before


def _run_in_thread(fn):
    out = []
    t = threading.Thread(target=lambda: out.append(fn()))
    t.start()
    t.join()
    return out[0]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread nice is Linux's")
def test_the_client_decodes_and_records_on_lowered_threads(tmp_path):
    from pibr.client.app import Client, ClientConfig
    from pibr.client.recorder import MethodRecorder

    lowered = min(19, _nice() + BACKGROUND_NICE)
    rec = MethodRecorder(str(tmp_path), "m", 16, 16, 30.0, video=False)
    try:
        assert rec._pool.submit(_nice).result() == lowered
    finally:
        rec.close()
    client = Client(ClientConfig(trace="synth-turns", duration_s=1.0))
    try:
        assert client._decode_pool.submit(_nice).result() == lowered
    finally:
        client._decode_pool.shutdown()
