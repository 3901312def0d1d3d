"""The least age over a sliding window: how long an adapting stream's frames queued (issue 28).

Both ends of an adapting stream read queueing the same way: a frame's age at arrival less the
least age seen over the last ``STREAM_BASELINE_S`` (protocol/messages.py). Propagation, the
server's own delay and an offset between the two clocks cancel. The client uses it to report at
once when a frame queued, the server to decide its rate; one definition keeps them agreeing.
"""
from __future__ import annotations

from collections import deque


class AgeBaseline:
    """Ages seen over the last ``window`` (in the times' unit; ages in any one unit)."""

    def __init__(self, window: float):
        self.window = float(window)
        self._ages: deque = deque()   # (t, age)

    def add(self, t: float, age: float) -> float:
        """Record ``age`` seen at ``t`` -> how far it is above the least age of the window."""
        self._ages.append((t, age))
        while self._ages[0][0] < t - self.window:
            self._ages.popleft()
        return age - self.least

    @property
    def least(self) -> float:
        """The least age of the window (0 before any)."""
        return min((a for _, a in self._ages), default=0.0)

    @property
    def newest_t(self) -> float | None:
        """When the newest age was seen (None before any)."""
        return self._ages[-1][0] if self._ages else None
