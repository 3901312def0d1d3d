"""Fair sharing of the server's workers (the GL thread, the encoder pool) between sessions.

Every session renders on the one GL thread and encodes in one small pool. Served first come,
first served, a session that keeps its jobs queued back to back (a virtual-clock client that
promises a far clock, or just a very fast one) makes every other session wait behind all of its
jobs. :class:`FairQueue` admits jobs to a worker in start-time fair queueing order (Goyal et al.
1996): a job's tag is the larger of the current virtual time and the end of its session's
previous job, advanced by the wall time each job took, so the worker's time is shared equally
among the sessions that want it, and a session that has been idle goes next instead of behind
everyone's backlog. No client's clock enters the tags: only the time the jobs took.

A session's tag leads the virtual time by at most :data:`MAX_LEAD_S`. Without that bound one long
job (a session's rate-control calibration, or the first frame of a server, which compiles its
shaders and uploads the scene) holds its session back until every other busy session has used as
much of the worker: measured with four real-clock clients on this 2-core machine, the first
session's 8 s calibration left it without a second frame for 22 s, and its client gave up.
Start-time fair queueing is long-run fair, which a real-time server does not need; with the
bound, such a session waits for about ``MAX_LEAD_S`` of each other session's work, and sessions
whose jobs are each shorter than the bound (a frame: 0.1-0.3 s here) share exactly as before.
"""
from __future__ import annotations

import asyncio
import heapq
import itertools
import time

#: Seconds of the worker's time a session's tag may lead the virtual time by (module docstring).
MAX_LEAD_S = 1.0


class FairQueue:
    """Admits at most ``slots`` jobs at once, the next one by fair-queueing tag.

    ``await queue.run(key, make)`` waits for a turn, then awaits ``make()`` (a coroutine that
    does the job, e.g. ``gl.run(fn)``) and returns its result; ``key`` names the session."""

    def __init__(self, slots: int = 1, clock=time.perf_counter, max_lead: float = MAX_LEAD_S):
        if slots < 1:
            raise ValueError("a fair queue needs at least one slot")
        if not max_lead > 0:
            raise ValueError(f"a fair queue's lead bound must be positive, got {max_lead}")
        self.slots = slots
        self.max_lead = max_lead
        self._clock = clock                # measures what each job took
        self._running = 0
        self._waiting: list = []          # heap of (tag, order, future)
        self._order = itertools.count()
        self._vtime = 0.0                 # tag of the job admitted last
        self._finish: dict = {}           # key -> end tag of its last job

    @property
    def waiting(self) -> int:
        return len(self._waiting)

    async def run(self, key, make):
        tag = max(self._vtime, min(self._finish.get(key, 0.0), self._vtime + self.max_lead))
        if self._running >= self.slots or self._waiting:
            turn = asyncio.get_running_loop().create_future()
            entry = (tag, next(self._order), turn)
            heapq.heappush(self._waiting, entry)
            try:
                await turn
            except asyncio.CancelledError:
                if turn.done() and not turn.cancelled():
                    self._job_done()          # given a turn it will not take: pass it on
                elif entry in self._waiting:  # (a finishing job may have dropped it already)
                    self._waiting.remove(entry)
                    heapq.heapify(self._waiting)
                raise
        else:
            self._running += 1
        self._vtime = max(self._vtime, tag)
        t0 = self._clock()
        try:
            return await make()
        finally:
            self._finish[key] = tag + (self._clock() - t0)
            self._job_done()

    def forget(self, key) -> None:
        """The session ended: drop its history."""
        self._finish.pop(key, None)

    def _job_done(self) -> None:
        self._running -= 1
        while self._waiting and self._running < self.slots:
            _, _, turn = heapq.heappop(self._waiting)
            if turn.cancelled():
                continue
            self._running += 1
            turn.set_result(None)
