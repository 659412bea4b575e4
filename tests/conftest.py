import os
import sys
from pathlib import Path

import pytest

# Test helpers (tests/scenes.py) import as a plain module.
sys.path.insert(0, str(Path(__file__).parent))


def missing(reason: str):
    """Skip a test whose system dependency is missing here; in CI, where .ci/setup.sh installs every
    dependency, fail instead, so that a requirement is never skipped silently."""
    if os.environ.get("CI"):
        pytest.fail(f"{reason} (CI must provide it)")
    pytest.skip(reason)


@pytest.fixture(autouse=True)
def _shared_gl_context_is_current(request):
    """Tests that make a context of their own (a capture, an OffscreenRenderer) leave it current; GL
    objects made on the shared context (a ComputeRelight's programs, compiled once per context) are
    then invalid names until the shared context is current again."""
    if "gl_context" in request.fixturenames:
        request.getfixturevalue("gl_context").__enter__()
    yield


@pytest.fixture(scope="session")
def gl_context():
    """One headless EGL context (Mesa llvmpipe here) shared by the GPU tests."""
    from viewer.gpu.context import GLUnavailable, create_context

    try:
        context = create_context()
    except GLUnavailable as exc:
        missing(str(exc))
    yield context
    context.release()


# ---- an X server for the window tests (Xvfb), shared by tests/ui and tests/bench ----------------------

@pytest.fixture(scope="module")
def display():
    from viewer.bench.x11 import start_xvfb, xvfb_available

    if not xvfb_available():
        missing("Xvfb is not installed (apt-get install xvfb): the window tests need an X server")
    process, name = start_xvfb()
    yield name
    process.terminate()
    process.wait(timeout=10)


@pytest.fixture
def x11(display):
    from viewer.bench.x11 import X11

    connection = X11(display)
    yield connection
    connection.close()
