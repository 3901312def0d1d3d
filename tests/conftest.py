"""Shared fixtures: a GL context (skipped with a clear reason where EGL is missing)."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def gl_ctx():
    from pibr.protocol.errors import GLUnavailable
    from pibr.common.gl import create_context

    try:
        ctx = create_context()
    except GLUnavailable as exc:  # no EGL driver on this machine
        pytest.skip(f"no OpenGL: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture
def gl_current(gl_ctx):
    """The shared context made current (a test's own context may be current before it), with no
    error left pending by earlier tests' GL calls (moderngl reports a stale error as its own
    failure). Left current afterwards: leaving ``with gl_ctx`` brings back whatever was current
    before, often nothing, and a later test using ``gl_ctx`` directly then cannot even create a
    program."""
    gl_ctx.__enter__()
    _ = gl_ctx.error
    yield gl_ctx
