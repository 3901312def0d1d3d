"""A FIFO bounded by the bytes it holds, not by how many items: the relay's buffer per direction."""
from __future__ import annotations

import asyncio
from collections import deque


class ByteBudgetQueue:
    """Items of known size between one producer and one consumer, at most ``budget`` bytes held.

    :meth:`put` waits while the item would not fit (back-pressure: a producer that stops
    reading its socket makes TCP slow down the peer sending). An item's bytes count from
    :meth:`put` until the consumer calls :meth:`done` for them, so an item being written
    still counts. ``peak`` is the most ever held.
    """

    def __init__(self, budget: int):
        if budget < 1:
            raise ValueError(f"budget must be at least 1 byte, got {budget}")
        self.budget = budget
        self.held = 0
        self.peak = 0
        self._items: deque = deque()
        self._changed = asyncio.Condition()
        self._abandoned = False

    async def put(self, item, nbytes: int) -> bool:
        """Queue ``item`` of ``nbytes`` once it fits. False (and nothing queued) once the consumer
        has abandoned the queue."""
        if nbytes > self.budget:
            raise ValueError(f"an item of {nbytes} bytes never fits a budget of {self.budget} bytes")
        async with self._changed:
            await self._changed.wait_for(lambda: self._abandoned or self.held + nbytes <= self.budget)
            if self._abandoned:
                return False
            self._items.append((item, nbytes))
            self.held += nbytes
            self.peak = max(self.peak, self.held)
            self._changed.notify_all()
            return True

    async def get(self) -> tuple:
        """-> (item, nbytes), the oldest; its bytes still count until :meth:`done`."""
        async with self._changed:
            await self._changed.wait_for(lambda: self._items)
            return self._items.popleft()

    async def done(self, nbytes: int) -> None:
        """The consumer is through with an item of ``nbytes``: they no longer count."""
        async with self._changed:
            self.held -= nbytes
            self._changed.notify_all()

    async def abandon(self) -> None:
        """The consumer stops: drop what is queued and make every later put return False."""
        async with self._changed:
            self._abandoned = True
            self._items.clear()
            self.held = 0
            self._changed.notify_all()
