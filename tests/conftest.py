"""Shared fixtures: a GL context (skipped with a clear reason where EGL is missing), and a real
browser (headless Chromium driven by Playwright; skipped where either is missing, except when
``PIBR_REQUIRE_BROWSER=1``, as CI sets it: then their absence fails)."""
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


@pytest.fixture(scope="module")
def chromium():
    """A launched headless Chromium (playwright Browser). Per module, never longer: while
    Playwright's sync API runs, its event loop counts as running in this thread, and every asyncio
    test after it would fail ("cannot be called from a running event loop")."""
    import os

    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
    from pibr.bench.processes import chromium_path

    path = chromium_path()
    if sync_playwright is None or path is None:
        reason = "no Playwright (pip install playwright)" if sync_playwright is None else "no chromium on PATH"
        if os.environ.get("PIBR_REQUIRE_BROWSER") == "1":
            pytest.fail(f"browser tests required (PIBR_REQUIRE_BROWSER=1) but {reason}")
        pytest.skip(reason)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=path, args=["--no-sandbox"])
        yield browser
        browser.close()
