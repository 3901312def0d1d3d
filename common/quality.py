"""Choosing quality levels against a deadline: the best level of each stream whose predicted cost
fits the budget, with hysteresis, and why.

The client (its methods' levels, client/deadline.py) and the server (its frames' levels,
server/rate_control.py) both hold a fixed rate this way, as game engines scale resolution to
hold their frame rate: a tick or a frame has a budget, each level a predicted cost, and the
:class:`DeadlineController` picks, each time, the best levels that fit.

Costs: each level has a *base* cost (measured before the clock starts, or given as a table) and
each kind of level a *speed factor* fitted on what the drawn levels measure (see the class), so
the predictions follow the machine's load. Going down is immediate, going up waits until the
better level has fitted with room for a while, so the level does not flicker between two that
straddle the budget. On a fast machine (a GPU) every level fits and the top one is kept.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from pibr.protocol.errors import ConfigError

#: Why a tick was drawn at its level (the ``level_reason`` column of the records).
REASONS = {
    0: "top level, it fits",
    1: "down: the level above was predicted over the budget",
    2: "held: the level above has not fitted with room for long enough",
    3: "up: the level above fitted with room for long enough",
    4: "cheapest level: nothing fits the budget",
    5: "kept: no controller (--deadline off)",
}
TOP, DOWN, HELD, UP, CHEAPEST, OFF = range(6)


@dataclass(frozen=True)
class Level:
    """One quality level: ``method`` (what it draws: a client method, or ``server``) at ``scale`` of
    the full resolution with ``options``."""

    name: str
    method: str
    scale: float = 1.0
    options: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"name": self.name, "method": self.method, "scale": self.scale, "options": dict(self.options)}


class _Estimate:
    """Exponentially weighted mean and mean absolute deviation of a series; ``prior``, if given,
    is where the mean starts (one outlying first measure then moves it a step, not all the way)."""

    def __init__(self, alpha: float, prior: float | None = None):
        self.alpha, self.prior, self.mean, self.dev, self.count = alpha, prior, prior, 0.0, 0
        self.idle = 0      # updates since the last measure

    def add(self, x: float) -> None:
        self.count += 1
        self.idle = 0
        if self.mean is None:
            self.mean = x
            return
        self.dev += self.alpha * (abs(x - self.mean) - self.dev)
        self.mean += self.alpha * (x - self.mean)

    def forget(self, rate: float, after: int) -> None:
        """One update without a measure: past ``after`` of them in a row the mean drifts back to
        the prior and the deviation to nothing, by ``rate`` of the way each, so an estimate
        nobody refreshes does not hold its last value for ever."""
        self.idle += 1
        if self.idle <= after or self.mean is None or self.prior is None:
            return
        self.mean += rate * (self.prior - self.mean)
        self.dev -= rate * self.dev

    def high(self) -> float | None:
        """The mean plus twice the mean deviation: what the series usually stays under."""
        return None if self.mean is None else self.mean + 2.0 * self.dev


class DeadlineController:
    """The levels of every method of one client, chosen together each tick (module docstring).

    levels : method -> its levels, best first; interval_ms : the output interval;
    costs : a cost table, method -> level name -> ms (None: measured as the client runs);
    adapt : update the estimates from measured costs (False: the table alone, reproducible);
    margin_ms : the least margin kept for the rest of the tick's work (the measured one may be more).

    Costs: each level has a *base* cost (the table's, or the first it measured: the calibration
    before the clock starts), and each method one *speed factor*, the measured cost of whatever
    level it drew over that level's base (exponentially weighted mean plus twice the mean
    deviation), kept apart for the levels that draw another method (the ``rotation`` fallback
    says nothing of how fast ``proxy`` runs). A level is predicted at its base times the factor,
    so a level not drawn for a while follows what the drawn ones measure: when the machine gets
    busier or freer (another process, a frame upload) every level's prediction moves with it,
    and a level once measured slow is tried again when the others say it would fit. A factor
    starts at 1 (the base costs are this machine's), so one slow first tick (the clock starting,
    the first frame's upload) moves it a step rather than setting it; and a factor not measured
    for ``up_after`` ticks in a row (the method shows its fallback) drifts back to 1, a quarter
    of ``alpha`` a tick, so the method is tried again after a spike rather than never: at worst
    one tick over the budget every second or two where the base costs are too hopeful.
    """

    def __init__(self, levels: dict, interval_ms: float, costs: dict | None = None, adapt: bool = True,
                 margin_ms: float = 1.0, up_after: int = 15, up_headroom: float = 0.85, alpha: float = 0.15):
        if not levels:
            raise ConfigError("the deadline controller needs at least one method")
        self.levels = {m: tuple(ls) for m, ls in levels.items()}
        self.interval_ms, self.adapt, self.min_margin_ms = interval_ms, adapt, margin_ms
        self.up_after, self.up_headroom = up_after, up_headroom
        self._base = {m: [None] * len(ls) for m, ls in self.levels.items()}
        # method -> the method its levels draw (``proxy``, or the ``rotation`` fallback) -> speed factor
        self._factor = {m: {lv.method: _Estimate(alpha, prior=1.0) for lv in ls} for m, ls in self.levels.items()}
        self._forget_rate = alpha / 4
        self._overhead = _Estimate(alpha)
        if costs is not None:
            self.load_costs(costs)
        self.current = {m: 0 for m in self.levels}
        self._room = {m: 0 for m in self.levels}      # consecutive ticks the level above fitted with room
        self.history = {m: [0] * len(ls) for m, ls in self.levels.items()}   # ticks at each level
        self.reasons = {m: [0] * len(REASONS) for m in self.levels}

    # ------------------------------------------------------------------ costs

    def load_costs(self, costs: dict) -> None:
        """Take a cost table, method -> level name -> ms (as :meth:`cost_table` writes it), as the
        levels' base costs."""
        for m, table in costs.items():
            if m not in self.levels:
                continue
            if not isinstance(table, dict):
                raise ConfigError(f"cost table: the costs of {m!r} must be an object of level name -> ms")
            names = [lv.name for lv in self.levels[m]]
            for name, ms in table.items():
                if name not in names:
                    raise ConfigError(f"cost table: {m!r} has no level {name!r}; its levels: {', '.join(names)}")
                if isinstance(ms, bool) or not isinstance(ms, (int, float)) or not (0 < ms < 1e6):
                    raise ConfigError(f"cost table: {m!r} level {name!r}: expected ms in (0, 1e6), got {ms!r}")
                self._base[m][names.index(name)] = float(ms)

    def calibrate(self, method: str, level: int, ms: float) -> None:
        """A level's base cost, measured before the clock starts (the median of a few draws)."""
        if math.isfinite(ms) and ms > 0:
            self._base[method][level] = ms

    def observe(self, method: str, level: int, ms: float) -> None:
        """A level of ``method`` took ``ms`` (wall ms of its render) this tick."""
        if not (self.adapt and math.isfinite(ms) and ms > 0):
            return
        factor = self._factor[method][self.levels[method][level].method]
        base = self._base[method][level]
        if base is None:   # a level's first measure sets its base, at the speed the method runs at now
            self._base[method][level] = base = ms / (factor.mean or 1.0)
        factor.add(ms / base)

    def observe_overhead(self, ms: float) -> None:
        """The rest of a tick's work took ``ms`` (everything but the methods' renders)."""
        if self.adapt and math.isfinite(ms):
            self._overhead.add(max(0.0, ms))

    def _base_of(self, method: str, level: int) -> float | None:
        """A level's base cost, or one guessed from the nearest level of the same method with a
        base, by the ratio of their pixels (fragments go with the square of the scale)."""
        base = self._base[method][level]
        if base is not None:
            return base
        levels = self.levels[method]
        order = sorted(range(len(levels)), key=lambda k: abs(k - level))
        for k in order:
            b = self._base[method][k]
            if b is not None and levels[k].method == levels[level].method:
                return b * (levels[level].scale / levels[k].scale) ** 2
        return None

    def predicted(self, method: str, level: int) -> float | None:
        """Predicted ms of a level: its base cost times the method's speed factor (None when the
        method has no cost at all yet)."""
        base = self._base_of(method, level)
        if base is None:
            return None
        return base * (self._factor[method][self.levels[method][level].method].high() or 1.0)

    @property
    def budget_ms(self) -> float:
        """The interval less the margin for the rest of the tick's work."""
        overhead = self._overhead.high() or 0.0
        return self.interval_ms - max(self.min_margin_ms, overhead)

    def cost_table(self) -> dict:
        """The current predictions, method -> level name -> ms (``--cost-table`` reads it back)."""
        return {m: {lv.name: round(p, 3) for k, lv in enumerate(ls) if (p := self.predicted(m, k)) is not None}
                for m, ls in self.levels.items()}

    # ------------------------------------------------------------------ choosing

    def _total(self, levels: dict) -> float | None:
        costs = [self.predicted(m, k) for m, k in levels.items()]
        return None if any(c is None for c in costs) else sum(costs)

    def choose(self) -> dict:
        """-> method -> (level index, reason). Call once per tick, before drawing."""
        for factors in self._factor.values():
            for f in factors.values():     # the fallback's ticks leave the method's own factor unmeasured
                f.forget(self._forget_rate, self.up_after)
        budget = self.budget_ms
        levels = dict(self.current)
        reason = {m: TOP if k == 0 else HELD for m, k in levels.items()}
        total = self._total(levels)
        if total is None:     # nothing known yet (no calibration): draw the top levels and learn
            self._commit(levels, {m: TOP for m in levels})
            return {m: (0, TOP) for m in levels}
        # down: while over, the method with the largest predicted cost goes one level down
        while total > budget:
            movable = [m for m, k in levels.items() if k < len(self.levels[m]) - 1]
            if not movable:
                break
            m = max(movable, key=lambda x: (self.predicted(x, levels[x]), x))
            levels[m] += 1
            reason[m] = DOWN
            self._room[m] = 0
            total = self._total(levels)
        if total > budget:
            for m, k in levels.items():
                if k == len(self.levels[m]) - 1:
                    reason[m] = CHEAPEST
        else:
            # up: one method at a time, the one whose step up costs least, once it has fitted long enough
            candidates = []
            for m, k in levels.items():
                if k == 0 or reason[m] == DOWN:
                    continue
                above = dict(levels, **{m: k - 1})
                t = self._total(above)
                if t is not None and t <= budget * self.up_headroom:
                    self._room[m] += 1
                    candidates.append((t - total, m))
                else:
                    self._room[m] = 0
            ready = sorted((d, m) for d, m in candidates if self._room[m] >= self.up_after)
            if ready:
                m = ready[0][1]
                levels[m] -= 1
                reason[m] = UP
                self._room[m] = 0
        self._commit(levels, reason)
        return {m: (levels[m], reason[m]) for m in levels}

    def _commit(self, levels: dict, reason: dict) -> None:
        self.current = dict(levels)
        for m, k in levels.items():
            self.history[m][k] += 1
            self.reasons[m][reason[m]] += 1

    def summary(self) -> dict:
        """What the controller did: per method its levels, the ticks at each and why, the cost table."""
        out = {"interval_ms": self.interval_ms, "budget_ms": round(self.budget_ms, 3), "adapt": self.adapt,
               "up_after": self.up_after, "up_headroom": self.up_headroom, "methods": {}}
        for m, ls in self.levels.items():
            ticks = sum(self.history[m])
            out["methods"][m] = {
                "levels": [lv.to_json() for lv in ls],
                "ticks_at_level": {lv.name: n for lv, n in zip(ls, self.history[m])},
                "share_at_level": {lv.name: (n / ticks if ticks else 0.0) for lv, n in zip(ls, self.history[m])},
                "reasons": {REASONS[r]: n for r, n in enumerate(self.reasons[m]) if n},
            }
        out["costs_ms"] = self.cost_table()
        overhead = self._overhead.high()
        out["speed_factor"] = {m: {drawn: None if f.count == 0 else round(f.high(), 4) for drawn, f in fs.items()}
                               for m, fs in self._factor.items()}
        out["overhead_ms"] = None if overhead is None else round(overhead, 3)
        return out


def read_cost_table(path: str) -> dict:
    """A cost table from a JSON file: the table itself (method -> level name -> ms), a client's
    ``session.json`` (its ``deadline.costs_ms``: what it measured) or ``pibr bench levels``'
    ``levels.json`` (its ``costs_ms``)."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"cost table {path}: {exc}") from None
    if isinstance(data, dict) and isinstance(data.get("deadline"), dict):
        data = data["deadline"].get("costs_ms")
    elif isinstance(data, dict) and isinstance(data.get("costs_ms"), dict):
        data = data["costs_ms"]
    if not isinstance(data, dict):
        raise ConfigError(f"cost table {path}: expected an object of method -> level name -> ms")
    return data
