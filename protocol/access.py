"""Who may connect: the shared token, and which listening addresses need one.

A server or relay listening on loopback serves anyone on this machine, as before. Listening
on any other address needs a shared token, and once a token is configured every client must
send it in its ``Hello`` (``Hello.token``), on loopback too. The token comes from
``--token-file FILE`` or the ``PIBR_TOKEN`` environment variable (``--token TEXT`` works
too, but a command line is visible to every user of the machine in ``ps``). It is compared
in constant time and never logged or recorded.
"""
from __future__ import annotations

import hmac
import ipaddress
import os
import re

from .errors import ConfigError
from .messages import MAX_TOKEN

#: Environment variable the server, the relay and the client read the token from.
TOKEN_ENV = "PIBR_TOKEN"
#: A token guarding a listening address must be at least this long (a guessable one is no guard).
MIN_TOKEN = 16
#: Printable ASCII without spaces: the same bytes on every platform, safe in files and variables.
_TOKEN_CHARS = re.compile(r"[\x21-\x7e]+")
MAKE_TOKEN_HINT = "python3 -c 'import secrets; print(secrets.token_urlsafe(24))'"


def is_loopback(host: str) -> bool:
    """True when ``host`` names only this machine: ``localhost`` or a loopback address.

    Any other name counts as reachable from elsewhere (it may resolve to a public address),
    and so does ``""`` or ``0.0.0.0``/``::`` (every interface)."""
    host = host.strip().strip("[]")
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_token_text(token: str, what: str = "token") -> str:
    """``token`` if it is 1..MAX_TOKEN printable ASCII characters without spaces, else ConfigError
    (naming the rule, never the token)."""
    if not token or len(token) > MAX_TOKEN or not _TOKEN_CHARS.fullmatch(token):
        raise ConfigError(f"the {what} must be 1..{MAX_TOKEN} printable ASCII characters without spaces "
                          f"(got {len(token)} characters)")
    return token


def resolve_token(token: str | None = None, token_file: str | None = None, environ=None) -> str | None:
    """The token from ``--token``, else from ``--token-file`` (its first line), else from
    ``$PIBR_TOKEN``; None when none is given. Raises ConfigError for an unreadable file or a
    malformed token."""
    environ = os.environ if environ is None else environ
    if token is not None and token_file is not None:
        raise ConfigError("give the token once: --token or --token-file, not both")
    if token_file is not None:
        try:
            with open(token_file, encoding="utf-8") as f:
                lines = f.read(MAX_TOKEN * 4 + 2).splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise ConfigError(f"cannot read the token file {token_file!r}: {reason}") from None
        token = lines[0].strip() if lines else ""
        if not token:
            raise ConfigError(f"the token file {token_file!r} is empty; put the token on its first line")
        return check_token_text(token, f"token in {token_file!r}")
    if token is not None:
        return check_token_text(token, "--token value")
    value = environ.get(TOKEN_ENV)
    if value is None or value == "":
        return None
    return check_token_text(value.strip(), f"token in ${TOKEN_ENV}")


def check_listen_access(what: str, host: str, token: str | None) -> None:
    """Refuse (ConfigError naming the fix) to listen on a non-loopback ``host`` without a token,
    and any configured token shorter than MIN_TOKEN characters."""
    if token is not None:
        check_token_text(token)
        if len(token) < MIN_TOKEN:
            raise ConfigError(f"the {what}'s token is {len(token)} characters long; use at least {MIN_TOKEN} "
                              f"(make one with: {MAKE_TOKEN_HINT})")
    elif not is_loopback(host):
        shown = host or "every interface"
        raise ConfigError(f"the {what} would listen on {shown}, reachable from other machines, without a token: "
                          f"set {TOKEN_ENV} or pass --token-file FILE (make a token with: {MAKE_TOKEN_HINT}); "
                          f"clients then pass the same token; or listen on 127.0.0.1")


def token_matches(expected: str, given: str) -> bool:
    """Whether the client's token is the configured one, in time independent of where they differ."""
    return hmac.compare_digest(expected.encode("utf-8"), given.encode("utf-8"))
