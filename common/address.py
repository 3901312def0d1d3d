"""Text forms every process's command line shares: ``HOST:PORT`` addresses and ``WxH`` sizes."""
from __future__ import annotations

from pibr.protocol.errors import ConfigError


def parse_host_port(text: str, default_host: str = "127.0.0.1") -> tuple[str, int]:
    """``"host:port"``, ``":port"`` or ``"[v6addr]:port"`` -> (host, port). Raises ConfigError."""
    text = text.strip()
    if text.startswith("["):
        host, sep, rest = text[1:].partition("]")
        if not sep or not rest.startswith(":"):
            raise ConfigError(f"bad address {text!r}: expected [IPv6]:PORT")
        port_text = rest[1:]
    else:
        host, sep, port_text = text.rpartition(":")
        if not sep:
            raise ConfigError(f"bad address {text!r}: expected HOST:PORT")
    host = host or default_host
    try:
        port = int(port_text)
    except ValueError:
        raise ConfigError(f"bad address {text!r}: port {port_text!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise ConfigError(f"bad address {text!r}: port must be in 0..65535")
    return host, port


#: Largest image side a size may name (pixels).
MAX_SIZE = 16384


def parse_size(text: str) -> tuple[int, int]:
    """``"WxH"`` (or ``"N"`` for N x N) -> (width, height) in 1..MAX_SIZE. Raises ConfigError."""
    w, _, h = text.strip().lower().partition("x")
    try:
        size = int(w), int(h or w)
    except ValueError:
        raise ConfigError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if not all(1 <= v <= MAX_SIZE for v in size):
        raise ConfigError(f"width and height must be in 1..{MAX_SIZE}, got {text!r}")
    return size
