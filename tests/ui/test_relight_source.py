"""The viewer's compute source for the physical kernel (viewer.ui.relight_source): how many frames an
edit takes to reach the screen, counted in calls of `step` (one a frame), never in seconds."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.physical import gi
from viewer.ui.relight_source import RelightSource
from scenes import lit_room

SETTINGS = gi.GISettings(voxels=12, probes=6)


@pytest.fixture(scope="module")
def ctx(gl_context):
    return gl_context


@pytest.fixture(params=["cpu", "gpu"])
def backend(request):
    """The relight on the CPU (a software GL) and in compute shaders (a GPU): both are run here."""
    return request.param


def frames_until_settled(source: RelightSource, limit: int = 100000):
    """Step once a 'frame' until the source is idle: (grids shown, in order, with the frame of each)."""
    shown = []
    for frame in range(1, limit):
        grid = source.step()
        if grid is not None:
            shown.append((frame, grid))
        if not source.busy:
            return shown
        if source.work is not None:
            source.work._thread.join()   # a frame takes a while; the worker's time is not counted here
    raise AssertionError("the source never settled")


def full_solve(scene):
    return gi.solve(scene, SETTINGS, include_emitted=False).coefficients


def close(a, b, tolerance=1e-4):
    return np.abs(a - b).max() <= tolerance * np.abs(b).max()


def test_a_new_scene_shows_its_first_bounce_then_the_converged_light(ctx, backend):
    source = RelightSource(ctx, backend)
    try:
        scene = lit_room()
        source.restart(scene, SETTINGS)
        shown = frames_until_settled(source)
        assert len(shown) == 2
        first, converged = shown[0][1].coefficients, shown[1][1].coefficients
        assert shown[1][0] == shown[0][0] + 1                 # the rest lands in the next frame
        assert converged[..., 0, :].sum() > first[..., 0, :].sum()
        assert close(converged, full_solve(scene))
    finally:
        source.release()


def test_a_colour_or_intensity_edit_is_on_screen_within_three_frames(ctx, backend):
    source = RelightSource(ctx, backend)
    try:
        scene = lit_room()
        source.restart(scene, SETTINGS)
        frames_until_settled(source)
        for edited in (scene.with_albedo("room", (0.8, 0.3, 0.3)), scene.with_emission("lamp", (2.0, 4.0, 9.0))):
            source.restart(edited, SETTINGS)
            shown = frames_until_settled(source)
            # the frames the relight takes: 1 on the render thread (GPU); on the worker (CPU) the frame
            # that starts it, then the frame that finds it done (waiting for it here, as a frame would)
            assert [frame for frame, _ in shown] == ([1] if backend == "gpu" else [2])
            assert close(shown[-1][1].coefficients, full_solve(edited))
    finally:
        source.release()


def test_a_lamp_drag_is_answered_from_the_lamp_paths_then_traced_exactly(ctx, backend):
    source = RelightSource(ctx, backend)
    try:
        scene = lit_room()
        source.restart(scene, SETTINGS)
        frames_until_settled(source)
        moved = scene.transformed_group("lamp", np.array([[1, 0, 0, 0.3], [0, 1, 0, 0], [0, 0, 1, -0.2],
                                                          [0, 0, 0, 1.0]]))
        source.restart(moved, SETTINGS)
        shown = frames_until_settled(source)
        assert len(shown) >= 2            # the quick answer on the old geometry, then the exact one
        assert close(shown[-1][1].coefficients, full_solve(moved))
        quick = shown[0][1].coefficients
        # the quick answer already has the lamp where it is now: close to the exact light
        assert np.sqrt(np.mean((quick - shown[-1][1].coefficients) ** 2)) < 0.05 * np.sqrt(np.mean(quick ** 2))
    finally:
        source.release()
