"""Thread priorities: work that must not take a tick's CPU runs at a lower one.

On one core (a headset's, or ``pibr bench realtime --placement split``) the client's tick and
its background work (decoding the next frame, writing the recordings) share the CPU, and the
scheduler splits it evenly among them: a tick that should take 15 ms then takes 25 whenever a
decode runs beside it, and the deadline controller, seeing those spikes, draws a lower quality
than the machine affords. Lowered, the background threads use the CPU the ticks leave idle
(between ticks there is time: that is what the controller's budget keeps), and the ticks run
as fast as if alone. On Linux ``nice`` is per thread and threads a thread starts inherit it;
elsewhere nothing changes.
"""
from __future__ import annotations

import concurrent.futures
import logging
import os
import threading

log = logging.getLogger(__name__)

#: The niceness of background threads: about a tenth of the CPU beside a normal thread that runs
#: (Linux's weights: 110 against 1024).
BACKGROUND_NICE = 10


def lower_this_thread(nice: int = BACKGROUND_NICE) -> None:
    """Lower the calling thread's priority by ``nice`` (a ThreadPoolExecutor ``initializer``)."""
    if not hasattr(os, "setpriority") or not hasattr(threading, "get_native_id"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + nice)
    except OSError as exc:     # not allowed here: the thread keeps its priority
        log.debug("could not lower thread priority: %s", exc)


def background_executor(name: str) -> concurrent.futures.ThreadPoolExecutor:
    """One worker thread named ``name`` for background work, at the lowered priority."""
    return concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix=name,
                                                 initializer=lower_this_thread)
