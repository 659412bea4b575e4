"""What the window's tests share."""

import pytest

from viewer.scene import load


@pytest.fixture(scope="module")
def cornell():
    """The built-in Cornell box, loaded once a module."""
    return load("cornell")
