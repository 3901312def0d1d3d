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
