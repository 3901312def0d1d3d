"""Bandwidth that changes over time: a link's capacity replayed from a trace, looping.

Two file formats:

* **Mahimahi's packet-delivery opportunities** (``mm-link``): one integer millisecond per line,
  each line one chance to deliver a 1500-byte packet at that millisecond (several lines with the
  same millisecond: several packets); the trace repeats after its last timestamp. One line per
  millisecond is 12 Mbit/s.
* **CSV** ``t,kbps``: from ``t`` seconds on the link carries ``kbps`` until the next row; the
  first row is at 0 and the last holds for the gap before it (rows every second: the last holds
  one second), then the trace repeats. A header line is allowed.

Both become a piecewise-constant rate over one period (a millisecond's opportunities spread over
that millisecond), so a message's serialisation ends where the bits delivered since it started
reach its size (:meth:`BandwidthTrace.finish_us`); a rate of 0 is an outage. The built-in traces
(:data:`BUILTIN`) are deterministic: steps down and up, an oscillation, a short outage, a
synthetic cellular-like link (log-normal rate with handover dips, seeded; ``cellular:SEED`` draws
another realisation), and a steady link with room (what adapting costs when nothing needs it;
``steady:KBPS`` is a steady link at another rate).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from pibr.protocol.errors import ConfigError

#: Bits of one Mahimahi delivery opportunity (a 1500-byte packet).
PACKET_BITS = 1500 * 8
#: Most rows a trace file may hold, and its longest period.
MAX_ROWS = 10_000_000
MAX_PERIOD_S = 24 * 3600.0
MAX_KBPS = 1e7
#: How many bits short of its size a message may leave at, so that float rounding never makes it
#: leave a microsecond late (BandwidthTrace.finish_us).
ROUNDING_BITS = 1e-6


@dataclass(frozen=True, eq=False)
class BandwidthTrace:
    """A looping piecewise-constant link rate.

    times_us : (n + 1,) int64, 0 = times_us[0] < ... < times_us[n] = the period;
    rates_kbps : (n,) float64, the rate from times_us[i] to times_us[i + 1] (kbit/s = bits per ms).
    """

    name: str
    times_us: np.ndarray
    rates_kbps: np.ndarray
    _cum_bits: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        t = np.asarray(self.times_us, dtype=np.int64)
        r = np.asarray(self.rates_kbps, dtype=np.float64)
        if t.ndim != 1 or r.ndim != 1 or len(t) != len(r) + 1 or len(r) == 0:
            raise ConfigError(f"bandwidth trace {self.name}: {len(t)} times for {len(r)} rates (want one more)")
        if t[0] != 0 or np.any(np.diff(t) <= 0):
            raise ConfigError(f"bandwidth trace {self.name}: times must start at 0 and increase")
        if t[-1] > MAX_PERIOD_S * 1e6:
            raise ConfigError(f"bandwidth trace {self.name}: period of {t[-1] / 1e6:g} s is longer than "
                              f"{MAX_PERIOD_S:g} s")
        if not np.all(np.isfinite(r)) or np.any(r < 0) or np.any(r > MAX_KBPS):
            raise ConfigError(f"bandwidth trace {self.name}: rates must be in 0..{MAX_KBPS:g} kbit/s")
        cum = np.concatenate([[0.0], np.cumsum(r / 1e3 * np.diff(t))])
        if cum[-1] < PACKET_BITS:
            raise ConfigError(f"bandwidth trace {self.name}: delivers {cum[-1]:g} bits in its period, less than one "
                              f"1500-byte packet; a link that never delivers would hold every message forever")
        object.__setattr__(self, "times_us", t)
        object.__setattr__(self, "rates_kbps", r)
        object.__setattr__(self, "_cum_bits", cum)

    @property
    def period_us(self) -> int:
        return int(self.times_us[-1])

    @property
    def mean_kbps(self) -> float:
        return float(self._cum_bits[-1] / self.period_us * 1e3)

    def kbps_at(self, t_us) -> np.ndarray:
        """The rate at times ``t_us`` (any shape; looping)."""
        s = np.mod(np.asarray(t_us, dtype=np.int64), self.period_us)
        return self.rates_kbps[np.searchsorted(self.times_us, s, side="right") - 1]

    def _bits_before(self, s):
        """Bits delivered from the period's start to ``s`` µs within it (a number or an array:
        the cumulative bits are piecewise linear between the segments' bounds)."""
        return np.interp(s, self.times_us, self._cum_bits)

    def bits_until(self, t_us) -> np.ndarray:
        """Bits delivered from the trace's start to ``t_us`` µs (any shape; looping)."""
        q, s = np.divmod(np.asarray(t_us, dtype=np.int64), self.period_us)
        return q * self._cum_bits[-1] + self._bits_before(s)

    def finish_us(self, start_us: int, nbytes: int) -> int:
        """When ``nbytes`` sent from ``start_us`` (µs on the trace's clock, any sign) have all left."""
        if nbytes <= 0:
            return int(start_us)
        period, per_period = self.period_us, float(self._cum_bits[-1])
        q, s = divmod(int(start_us), period)
        target = float(self._bits_before(s)) + nbytes * 8.0
        q2, rem = divmod(target, per_period)
        if rem == 0.0:               # exactly at a period's end, not the next one's start
            q2, rem = q2 - 1, per_period
        i = max(1, int(np.searchsorted(self._cum_bits, rem, side="left")))
        bits_per_us = self.rates_kbps[i - 1] / 1e3
        t = self.times_us[i - 1] + (rem - self._cum_bits[i - 1]) / bits_per_us
        # The cumulative bits carry float rounding, a few units in the last place of the period's
        # bits, which a slow segment stretches into time (at 1 kbit/s, 1e-8 bit is 1e-5 us): a time
        # that far past a whole microsecond is that microsecond, not the next (a message must not
        # leave 1 us late); it leaves at most ROUNDING_BITS early.
        slack_bits = max(ROUNDING_BITS, 64 * math.ulp(per_period))
        slack_us = max(1e-6, slack_bits / bits_per_us)
        return max(int(start_us), int(math.ceil((q + q2) * period + t - slack_us)))

    def summary(self, window_ms: float = 100.0) -> dict:
        """Statistics a user reads (``pibr link show``), of the rate averaged over ``window_ms``
        (a Mahimahi trace is 0 or 12 Mbit/s in each millisecond)."""
        step = min(int(window_ms * 1e3), self.period_us)
        edges = np.append(np.arange(0, self.period_us, step, dtype=np.int64), self.period_us)
        bits = self._bits_before(edges)
        rates = np.diff(bits) / np.diff(edges) * 1e3
        weights = np.diff(edges) / self.period_us
        order = np.argsort(rates)
        cum = np.cumsum(weights[order])

        def quantile(p):
            return round(float(rates[order][min(np.searchsorted(cum, p), len(rates) - 1)]), 1)
        return {"name": self.name, "period_s": self.period_us / 1e6, "window_ms": step / 1e3,
                "mean_kbps": round(self.mean_kbps, 1), "min_kbps": round(float(rates.min()), 1),
                "p10_kbps": quantile(0.1), "median_kbps": quantile(0.5), "max_kbps": round(float(rates.max()), 1),
                "outage_s": float(np.diff(edges)[rates == 0].sum() / 1e6), "segments": len(self.rates_kbps)}

    def to_csv(self) -> str:
        """The trace as ``t,kbps`` rows (seconds). The format's last row holds as long as the gap
        before it, so the last segment is written as two halves when that gap differs from it."""
        t, r = self.times_us, self.rates_kbps
        rows = [(t[i], r[i]) for i in range(len(r))]
        if len(r) == 1 or t[-1] - t[-2] != t[-2] - t[-3]:
            # the format's last row holds as long as the gap before it: halve the last segment
            rows.append(((t[-2] + t[-1]) // 2, r[-1]))
        lines = ["t,kbps"] + [f"{ti / 1e6:.6f},{ri:.3f}" for ti, ri in rows]
        return "\n".join(lines) + "\n"

    def to_mahimahi(self) -> str:
        """The trace as Mahimahi delivery opportunities (one millisecond per 1500-byte packet; one
        more at the period's last millisecond if it has none, since Mahimahi loops after the last)."""
        ms = np.arange(1, self.period_us // 1000 + 1, dtype=np.int64)
        bits = self._bits_before(ms * 1000)
        packets = np.floor(bits / PACKET_BITS).astype(np.int64)
        counts = np.diff(np.concatenate([[0], packets]))
        stamps = np.repeat(ms, counts)
        if len(stamps) == 0 or stamps[-1] != ms[-1]:
            stamps = np.append(stamps, ms[-1])   # Mahimahi loops after the last stamp: keep the period
        return "\n".join(str(int(s)) for s in stamps) + "\n"


def _compressed(name: str, times_us: np.ndarray, rates: np.ndarray) -> BandwidthTrace:
    """A trace with runs of equal rates merged."""
    keep = np.concatenate([[True], rates[1:] != rates[:-1]])
    return BandwidthTrace(name, np.concatenate([times_us[:-1][keep], times_us[-1:]]), rates[keep])


def parse_mahimahi(text: str, name: str = "trace") -> BandwidthTrace:
    """Mahimahi's delivery opportunities (module docstring)."""
    stamps = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line:
            continue
        if len(stamps) >= MAX_ROWS:
            raise ConfigError(f"{name}: more than {MAX_ROWS} lines")
        try:
            value = int(line)
        except ValueError:
            raise ConfigError(f"{name}, line {number}: expected a whole number of milliseconds, got {line[:40]!r}")
        if value < 0 or (stamps and value < stamps[-1]):
            raise ConfigError(f"{name}, line {number}: timestamps must be >= 0 and never decrease, got {value}")
        stamps.append(value)
    if not stamps or stamps[-1] <= 0:
        raise ConfigError(f"{name}: no delivery opportunity after 0 ms (Mahimahi loops after the last timestamp)")
    period_ms = stamps[-1]
    if period_ms > MAX_PERIOD_S * 1e3:
        raise ConfigError(f"{name}: period of {period_ms / 1e3:g} s is longer than {MAX_PERIOD_S:g} s")
    bins = np.bincount(np.maximum(np.asarray(stamps, dtype=np.int64) - 1, 0), minlength=period_ms)
    times = np.arange(period_ms + 1, dtype=np.int64) * 1000
    return _compressed(name, times, bins.astype(np.float64) * (PACKET_BITS / 1.0))


def parse_rate_csv(text: str, name: str = "trace") -> BandwidthTrace:
    """``t,kbps`` rows (module docstring)."""
    ts, rates = [], []
    header_allowed = True
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = [f.strip() for f in line.split(",")]
        if len(fields) != 2:
            raise ConfigError(f"{name}, line {number}: expected 't,kbps', got {line[:60]!r}")
        try:
            t, kbps = float(fields[0]), float(fields[1])
        except ValueError:
            if header_allowed:      # the first line may name the columns
                header_allowed = False
                continue
            raise ConfigError(f"{name}, line {number}: expected two numbers, got {line[:60]!r}")
        header_allowed = False
        if not (math.isfinite(t) and math.isfinite(kbps)) or kbps < 0 or kbps > MAX_KBPS:
            raise ConfigError(f"{name}, line {number}: kbps must be in 0..{MAX_KBPS:g}, got {fields[1]!r}")
        if ts and t <= ts[-1]:
            raise ConfigError(f"{name}, line {number}: times must increase, got {t:g} after {ts[-1]:g}")
        if not ts and t != 0:
            raise ConfigError(f"{name}, line {number}: the first row must be at t = 0, got {t:g}")
        if len(ts) >= MAX_ROWS:
            raise ConfigError(f"{name}: more than {MAX_ROWS} rows")
        ts.append(t)
        rates.append(kbps)
    if not ts:
        raise ConfigError(f"{name}: no 't,kbps' rows")
    last_gap = ts[-1] - ts[-2] if len(ts) > 1 else 1.0
    times = np.round(np.asarray(ts + [ts[-1] + last_gap]) * 1e6).astype(np.int64)
    if np.any(np.diff(times) <= 0):
        raise ConfigError(f"{name}: rows closer than a microsecond")
    return _compressed(name, times, np.asarray(rates, dtype=np.float64))


# --------------------------------------------------------------------------------- built-ins


def _steps() -> BandwidthTrace:
    kbps = [20000, 8000, 3000, 8000, 20000]
    return BandwidthTrace("steps", np.arange(len(kbps) + 1, dtype=np.int64) * 10_000_000, np.asarray(kbps, float))


def _oscillation() -> BandwidthTrace:
    t = np.arange(0, 60_000_001, 100_000, dtype=np.int64)
    mid = t[:-1] + 50_000
    kbps = 11500 + 8500 * np.cos(2 * np.pi * mid / 20e6)
    return BandwidthTrace("oscillation", t, np.round(kbps))


def _outage() -> BandwidthTrace:
    return BandwidthTrace("outage", np.array([0, 10_000_000, 11_000_000, 30_000_000]),
                          np.array([16000.0, 0.0, 16000.0]))


#: The seed of the built-in ``cellular`` link; ``cellular:SEED`` draws another realisation.
CELLULAR_SEED = 20261202


def _cellular(seed: int = CELLULAR_SEED) -> BandwidthTrace:
    """60 s in 100 ms bins: a log-normal rate (scale 8 Mbit/s, sigma 0.55) with a 2 s memory, and
    five handovers of 0.2-0.6 s at a twentieth of the rate (seeded: the same trace everywhere for
    one seed)."""
    rng = np.random.default_rng(seed)
    n, dt = 600, 0.1
    a = math.exp(-dt / 2.0)
    x = np.empty(n)
    x[0] = 0.0
    noise = rng.normal(0.0, 0.55 * math.sqrt(1 - a * a), n)
    for i in range(1, n):
        x[i] = a * x[i - 1] + noise[i]
    kbps = 8000.0 * np.exp(x - 0.55 ** 2 / 2)
    for start in rng.choice(np.arange(20, n - 10), 5, replace=False):
        kbps[start:start + rng.integers(2, 7)] *= 0.05
    name = "cellular" if seed == CELLULAR_SEED else f"cellular:{seed}"
    return BandwidthTrace(name, np.arange(n + 1, dtype=np.int64) * 100_000, np.round(np.clip(kbps, 50, 60000)))


#: The rate of the built-in ``steady`` link (kbit/s); ``steady:KBPS`` is a steady link at another.
STEADY_KBPS = 40000.0


def _steady(kbps: float = STEADY_KBPS) -> BandwidthTrace:
    name = "steady" if kbps == STEADY_KBPS else f"steady:{kbps:g}"
    return BandwidthTrace(name, np.array([0, 30_000_000]), np.array([float(kbps)]))


#: name -> (what it is, how to make it)
BUILTIN = {
    "steps": ("20, 8, 3, 8, 20 Mbit/s for 10 s each (50 s)", _steps),
    "oscillation": ("3 to 20 Mbit/s and back every 20 s, in 100 ms steps (60 s)", _oscillation),
    "outage": ("16 Mbit/s with nothing at all from 10 to 11 s (30 s)", _outage),
    "cellular": ("synthetic cellular: log-normal in 100 ms steps (mean 5.7, 10th percentile 2.7 Mbit/s), "
                 "five handover dips (60 s); cellular:SEED draws another realisation of the same model",
                 _cellular),
    "steady": ("40 Mbit/s throughout (30 s): a link with room, where adapting should cost nothing; "
               "steady:KBPS is a steady link at KBPS kbit/s (a slow one: where even the floor does not fit)",
               _steady),
}


def load_bandwidth_trace(spec: str) -> BandwidthTrace:
    """A built-in name (:data:`BUILTIN`), ``cellular:SEED`` (the cellular model drawn with another
    seed, a non-negative integer: more realisations to judge an adaptation on than the one
    built-in), ``steady:KBPS`` (a steady link at KBPS kbit/s, a positive number), or a file:
    ``t,kbps`` CSV when its lines hold commas, Mahimahi opportunities otherwise. Errors name the
    file and line."""
    if spec in BUILTIN:
        return BUILTIN[spec][1]()
    if spec.startswith("steady:") and not os.path.exists(spec):
        text = spec.partition(":")[2]
        try:
            kbps = float(text) if text.isascii() else math.nan
        except ValueError:
            kbps = math.nan
        if not 0 < kbps <= MAX_KBPS:
            raise ConfigError(f"bandwidth trace {spec!r}: steady:KBPS takes a rate in kbit/s above 0 and at most "
                              f"{MAX_KBPS:g}, got {text!r}")
        return _steady(kbps)
    if spec.startswith("cellular:") and not os.path.exists(spec):
        seed = spec.partition(":")[2]
        if not (seed.isascii() and seed.isdigit()) or len(seed) > 18:
            raise ConfigError(f"bandwidth trace {spec!r}: cellular:SEED takes a non-negative integer seed, "
                              f"got {seed!r}")
        return _cellular(int(seed))
    if not os.path.isfile(spec):
        raise ConfigError(f"bandwidth trace {spec!r}: neither a file nor a built-in ({', '.join(BUILTIN)})")
    if os.path.getsize(spec) > 200 * 1024 * 1024:
        raise ConfigError(f"bandwidth trace {spec}: larger than 200 MiB")
    try:
        with open(spec, encoding="utf-8") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"bandwidth trace {spec}: cannot read it as text: {exc}") from None
    name = os.path.basename(spec)
    if "," in text[:4096]:
        return parse_rate_csv(text, name)
    return parse_mahimahi(text, name)
