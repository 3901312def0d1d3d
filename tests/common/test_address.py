"""Command-line text forms shared by every process: HOST:PORT and WxH."""
import pytest

from pibr.common.address import MAX_SIZE, parse_host_port, parse_size
from pibr.protocol.errors import ConfigError


@pytest.mark.parametrize("text, expected", [("127.0.0.1:7450", ("127.0.0.1", 7450)), (":0", ("127.0.0.1", 0)),
                                            ("[::1]:7451", ("::1", 7451))])
def test_host_port(text, expected):
    assert parse_host_port(text) == expected


@pytest.mark.parametrize("text", ["nohost", "[::1]7451", "h:port", "h:70000"])
def test_bad_host_port(text):
    with pytest.raises(ConfigError):
        parse_host_port(text)


@pytest.mark.parametrize("text, expected", [("960x540", (960, 540)), ("1024", (1024, 1024)), (" 32X16 ", (32, 16))])
def test_size(text, expected):
    assert parse_size(text) == expected


@pytest.mark.parametrize("text", ["0x0", "x", "12xabc", f"{MAX_SIZE + 1}x8", "-4x4", ""])
def test_bad_size(text):
    with pytest.raises(ConfigError):
        parse_size(text)
