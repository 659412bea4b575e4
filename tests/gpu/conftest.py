"""The Cornell box and its compute-solved probes, shared by the surface tests."""

from __future__ import annotations

import pytest

from viewer.gpu.compute_relight import solve_probes
from viewer.physical.gi import GISettings
from viewer.scene import load


@pytest.fixture(scope="module")
def cornell():
    return load("cornell")


@pytest.fixture(scope="module")
def cornell_probes(gl_context, cornell):
    return solve_probes(gl_context, cornell, GISettings(), include_emitted=False)
