"""The network link model: one direction of a TCP-like path with delay, jitter and a bandwidth cap.

Used by the relay process (``pibr relay``) and in-process by tests. Times are integer
microseconds so the virtual clock stays bit-exact. For a message sent at ``t`` of ``n`` bytes::

    tx_start = max(t, link_free)                 # the link sends one message at a time
    tx       = n * 8 / kbps                      # serialisation at the bandwidth cap (0: none)
    arrive   = tx_start + tx + max(0, delay + U(-jitter, +jitter))
    arrive   = max(arrive, previous arrive)      # TCP delivers in order

``Clock`` messages (null messages of the virtual clock) cost no bandwidth and take the
*least* delay the link can give, so their time stays a valid lower bound for every later
message (see ``messages.Clock``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LinkParams:
    """One direction: ``delay_ms`` one-way, ``jitter_ms`` (uniform +-), ``kbps`` cap (0 = none)."""

    delay_ms: float = 64.0
    jitter_ms: float = 0.0
    kbps: float = 0.0

    def __post_init__(self):
        for name in ("delay_ms", "jitter_ms", "kbps"):
            v = getattr(self, name)
            if not (v >= 0 and v < 1e9):
                raise ValueError(f"link {name} must be a finite number >= 0, got {v}")


class LinkModel:
    """Stateful FIFO link (one direction). ``seed`` makes the jitter sequence reproducible."""

    def __init__(self, params: LinkParams, seed: int = 0):
        self.params = params
        self._rng = np.random.default_rng(seed)
        self._delay_us = int(round(params.delay_ms * 1000))
        self._jitter_us = int(round(params.jitter_ms * 1000))
        self._link_free_us: int | None = None
        self._last_arrival_us: int | None = None
        self.messages = 0
        self.bytes = 0

    @property
    def min_delay_us(self) -> int:
        return max(0, self._delay_us - self._jitter_us)

    def arrival_us(self, send_us: int, nbytes: int, is_clock: bool = False) -> int:
        """Arrival time of a message sent at ``send_us`` with ``nbytes`` on the wire."""
        start = send_us if self._link_free_us is None else max(send_us, self._link_free_us)
        if is_clock:
            arrive = start + self.min_delay_us
        else:
            tx = 0 if self.params.kbps <= 0 else int(math.ceil(nbytes * 8000.0 / self.params.kbps))
            self._link_free_us = start + tx
            delay = self._delay_us
            if self._jitter_us:
                delay = max(0, delay + int(self._rng.integers(-self._jitter_us, self._jitter_us + 1)))
            arrive = start + tx + delay
            self.messages += 1
            self.bytes += nbytes
        if self._last_arrival_us is not None:
            arrive = max(arrive, self._last_arrival_us)
        self._last_arrival_us = arrive
        return arrive
