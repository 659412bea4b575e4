"""The viewer's neural source: a new geometry is voxelized and predicted off the render thread, and what
the render thread shows is the latest edit's probes."""

from __future__ import annotations

import time

import numpy as np
import pytest

from viewer.physical.gi import GISettings
from viewer.scene import load


@pytest.fixture(scope="module")
def source():
    from viewer.neural.field import ModelError
    from viewer.ui.neural_source import NeuralSource

    try:
        return NeuralSource()
    except ModelError as exc:
        pytest.skip(str(exc))


def _stepped(source, limit: float = 120.0):
    """The probes of the next step that gives some, and how many steps gave none before it."""
    deadline, empty = time.monotonic() + limit, 0
    while time.monotonic() < deadline:
        grid = source.step()
        if grid is not None or not source.busy:
            return grid, empty
        empty += 1
        time.sleep(0.005)
    raise AssertionError("the neural source never delivered")


def _fresh(scene):
    from viewer.neural.field import NeuralField, NeuralGI

    return NeuralGI(NeuralField()).update(scene).coefficients


def test_a_moved_object_is_predicted_off_the_render_thread(source):
    """After a move the render thread's steps give nothing while the worker voxelizes and predicts, then
    the probes of the moved scene: those of a prediction from scratch, with every stage timed."""
    cornell = load("cornell")
    source.restart(cornell, GISettings())
    first, _ = _stepped(source)
    assert first is not None and source.voxelizing is None
    matrix = np.eye(4)
    matrix[0, 3] = 0.1
    moved = cornell.transformed_group("small-box", matrix)
    source.restart(moved, GISettings())
    assert source.step() is None and source.voxelizing is not None   # started on the worker
    grid, _ = _stepped(source)
    assert grid is not None and source.error is None
    np.testing.assert_allclose(grid.coefficients, _fresh(moved), rtol=1e-5, atol=1e-6)
    assert {"voxelize", "encode", "network", "unpack"} <= set(source.milliseconds)
    assert source.edit_to_probes is not None and "voxelize" in source.status()


def test_an_edit_made_while_the_worker_predicts_wins(source):
    """A colour edit made while a moved box is voxelized and predicted: the worker's probes are dropped
    and the step that picks them up gives the colour edit's, on the new geometry."""
    cornell = load("cornell")
    source.restart(cornell, GISettings())
    _stepped(source)
    matrix = np.eye(4)
    matrix[2, 3] = 0.15
    moved = cornell.transformed_group("small-box", matrix)
    source.restart(moved, GISettings())
    assert source.step() is None
    recoloured = moved.with_albedo("red-wall", (0.1, 0.2, 0.9))
    source.restart(recoloured, GISettings())   # before the worker is done
    grid, _ = _stepped(source)
    assert grid is not None and not source.busy
    np.testing.assert_allclose(grid.coefficients, _fresh(recoloured), rtol=1e-5, atol=1e-6)
