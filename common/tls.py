"""Optional TLS for pibr's TCP connections, with the standard library's ``ssl`` (TLS 1.2 or newer).

A listening end (server, relay) loads a PEM certificate chain and its unencrypted key
(:func:`server_context`). A connecting end (client, a relay towards its server) checks the
peer in one of two ways (:class:`ClientTLS`):

* ``ca_file``: the peer's certificate must chain to a CA in this PEM file and name the host
  connected to (an IP address must be in its subjectAltName);
* ``pin``: the SHA-256 fingerprint of the peer's certificate (DER) must be this one
  (compared in constant time); the chain and the name are not checked, so a self-signed
  certificate works without a CA. ``pibr serve`` prints its certificate's fingerprint.

Every failure is one clear error: :class:`ConfigError` for files that cannot be read or do
not load, :class:`TLSError` for a peer that does not verify, does not match the pin or
speaks no TLS.
"""
from __future__ import annotations

import asyncio
import hashlib
import hmac
import re
import ssl
from dataclasses import dataclass

from pibr.protocol.errors import ConfigError, TLSError

MIN_VERSION = ssl.TLSVersion.TLSv1_2
#: Hex digits of a fingerprint shown in a pin mismatch: enough to tell two apart, not the whole.
SHOWN_HEX = 16


def _readable(path: str, what: str) -> None:
    try:
        with open(path, "rb") as f:
            f.read(1)
    except OSError as exc:
        raise ConfigError(f"cannot read the TLS {what} {path!r}: {exc.strerror or exc}") from None


def server_context(cert_file: str, key_file: str) -> ssl.SSLContext:
    """A server-side context for ``cert_file`` (PEM chain) and ``key_file`` (PEM, unencrypted)."""
    _readable(cert_file, "certificate")
    _readable(key_file, "key")
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = MIN_VERSION
    try:
        # A password callback that refuses: an encrypted key fails here instead of prompting.
        ctx.load_cert_chain(cert_file, key_file, password=lambda: b"")
    except ssl.SSLError as exc:
        raise ConfigError(f"the TLS certificate {cert_file!r} and key {key_file!r} do not load "
                          f"({exc.reason or exc}): expected PEM files, an unencrypted key that matches "
                          f"the certificate") from None
    return ctx


def check_server_files(cert_file: str | None, key_file: str | None, what: str) -> None:
    """Both or neither of --tls-cert and --tls-key, and when both, that they load (ConfigError)."""
    if (cert_file is None) != (key_file is None):
        raise ConfigError(f"the {what} needs both --tls-cert and --tls-key for TLS (or neither)")
    if cert_file is not None:
        server_context(cert_file, key_file)


def fingerprint(der: bytes) -> str:
    """SHA-256 of a DER certificate as 64 lower-case hex digits (the form ``--tls-pin`` takes)."""
    return hashlib.sha256(der).hexdigest()


def certificate_fingerprint(cert_file: str) -> str:
    """The fingerprint of the first certificate in a PEM file (the one a server presents)."""
    _readable(cert_file, "certificate")
    with open(cert_file, encoding="ascii", errors="replace") as f:
        text = f.read()
    m = re.search(r"-----BEGIN CERTIFICATE-----.+?-----END CERTIFICATE-----", text, re.S)
    if m is None:
        raise ConfigError(f"the TLS certificate {cert_file!r} holds no PEM certificate")
    return fingerprint(ssl.PEM_cert_to_DER_cert(m.group(0)))


def parse_pin(text: str) -> str:
    """A fingerprint as given (hex, any case, ':' separators, optional 'sha256:' prefix) -> 64 hex."""
    pin = text.strip().lower()
    if pin.startswith("sha256:"):
        pin = pin[len("sha256:"):]
    pin = pin.replace(":", "")
    if not re.fullmatch(r"[0-9a-f]{64}", pin):
        raise ConfigError(f"a TLS pin is the certificate's SHA-256 fingerprint, 64 hex digits "
                          f"(pibr serve prints it); got {len(pin)} characters")
    return pin


@dataclass(frozen=True)
class ClientTLS:
    """How a connecting end verifies the TLS peer: against ``ca_file`` or by ``pin``, one of them."""

    ca_file: str | None = None
    pin: str | None = None

    def __post_init__(self):
        if (self.ca_file is None) == (self.pin is None):
            raise ConfigError("TLS needs exactly one of --tls-ca FILE and --tls-pin SHA256")
        if self.pin is not None:
            object.__setattr__(self, "pin", parse_pin(self.pin))
        else:
            _readable(self.ca_file, "CA file")

    def context(self) -> ssl.SSLContext:
        if self.ca_file is not None:
            ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)   # CERT_REQUIRED and the host name checked
            try:
                ctx.load_verify_locations(cafile=self.ca_file)
            except (ssl.SSLError, OSError) as exc:
                raise ConfigError(f"the TLS CA file {self.ca_file!r} does not load "
                                  f"({getattr(exc, 'reason', None) or exc}): expected PEM certificates") from None
        else:
            ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
            ctx.check_hostname = False
            ctx.verify_mode = ssl.CERT_NONE   # the pin, checked after the handshake, is the verification
        ctx.minimum_version = MIN_VERSION
        return ctx

    def check_pin(self, der: bytes | None, where: str) -> None:
        """TLSError unless the peer's DER certificate has the pinned fingerprint (constant time)."""
        actual = fingerprint(der or b"")
        if der is None or not hmac.compare_digest(actual.encode(), self.pin.encode()):
            raise TLSError(f"TLS: the certificate of {where} does not match the pinned fingerprint: expected "
                           f"{self.pin[:SHOWN_HEX]}..., got {actual[:SHOWN_HEX] if der else 'no certificate'}...")


async def open_connection(host: str, port: int, tls: ClientTLS | None = None, timeout: float = 10.0,
                          what: str = "", **kw) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """Connect to ``host:port``, over TLS when ``tls`` is given; ``kw`` go to asyncio.open_connection.

    Raises ConnectionError when nothing answers, TLSError when the TLS handshake or the
    peer's certificate fails, naming ``what`` ("pibr server") at the address and why."""
    where = f"{what} at {host}:{port}" if what else f"{host}:{port}"
    if tls is None:
        try:
            async with asyncio.timeout(timeout):
                return await asyncio.open_connection(host, port, **kw)
        except OSError as exc:   # TimeoutError included
            raise ConnectionError(f"{where} is unreachable: {exc or 'timed out'}") from None
    ctx = tls.context()
    try:
        async with asyncio.timeout(timeout):
            reader, writer = await asyncio.open_connection(host, port, ssl=ctx, server_hostname=host,
                                                           ssl_handshake_timeout=timeout, **kw)
    except ssl.SSLCertVerificationError as exc:
        raise TLSError(f"TLS: the certificate of {where} did not verify against {tls.ca_file!r}: "
                       f"{exc.verify_message or exc.reason}") from None
    except ssl.SSLError as exc:
        raise TLSError(f"TLS handshake with {where} failed ({exc.reason or exc}); does it serve TLS "
                       f"(--tls-cert)?") from None
    except (ConnectionResetError, ConnectionAbortedError, asyncio.IncompleteReadError, EOFError) as exc:
        raise TLSError(f"TLS handshake with {where} failed: the peer closed the connection ({exc or 'no reason'}); "
                       f"does it serve TLS (--tls-cert)?") from None
    except OSError as exc:   # TimeoutError included
        raise ConnectionError(f"{where} is unreachable: {exc or 'timed out (no TLS handshake)'}") from None
    if tls.pin is not None:
        try:
            tls.check_pin(writer.get_extra_info("ssl_object").getpeercert(binary_form=True), where)
        except TLSError:
            writer.close()
            raise
    return reader, writer
