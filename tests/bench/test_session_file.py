"""A client recording's session.json is read with the bounded JSON reader: damage is a ConfigError."""
import pytest

from pibr.bench.evaluate import read_session
from pibr.protocol.errors import ConfigError


@pytest.mark.parametrize("text, problem", [
    ("[" * 100_000 + "]" * 100_000, "nested deeper than 32 levels"),
    ('{"session": {"server_fps": NaN}}', "session.server_fps: NaN is not a finite number"),
    ('{"session": {"keyint": ' + "9" * 5000 + "}}", "a number of 5000 characters"),
    ('{"session": ', "not UTF-8 JSON"),
    ('[1, 2]', "not a client's session.json"),
])
def test_damaged_session_json_is_a_config_error(tmp_path, text, problem):
    (tmp_path / "session.json").write_text(text)
    with pytest.raises(ConfigError, match=problem):
        read_session(str(tmp_path))


def test_missing_and_valid_session_json(tmp_path):
    with pytest.raises(ConfigError, match="holds no client recording"):
        read_session(str(tmp_path))
    (tmp_path / "session.json").write_text('{"session": {"scene": {"name": "room"}}, "client": {}}')
    assert read_session(str(tmp_path))["session"]["scene"]["name"] == "room"
