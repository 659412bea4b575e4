"""A two-sided sheet (two faces on the same corners wound opposite ways: viewer/rays/sides.py) through the
renderer, headless: each side shows its own face, where the two faces' equal depths took turns along it."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.gpu.offscreen import OffscreenRenderer
from viewer.gpu.renderer import RenderSettings
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid
from viewer.scene import Camera, Scene
from scenes import box

WHITE, GREEN = (0.8, 0.8, 0.8), (0.2, 0.7, 0.2)


@pytest.fixture(scope="module")
def ctx(gl_context):
    return gl_context


def sheet_room() -> Scene:
    """A closed room split at x = 0.4 by a sheet white on its -x side and green on its +x side."""
    corners = np.array([[0.4, 1.0, -1.0], [0.4, 1.0, 1.0], [0.4, -1.0, 1.0], [0.4, -1.0, -1.0]])
    green = Scene("green", corners, np.array([[0, 1, 2], [0, 2, 3]]), np.array([GREEN] * 2), np.zeros((2, 3)),
                  np.zeros(2, np.int64), ("green",))
    white = Scene("white", corners, np.array([[0, 2, 1], [0, 3, 2]]), np.array([WHITE] * 2), np.zeros((2, 3)),
                  np.zeros(2, np.int64), ("white",))
    return Scene.concatenate("sheet", [box(inward=True, albedo=0.5, name="room"), white, green])


def test_each_side_of_a_two_sided_sheet_shows_its_own_face(ctx):
    offscreen = OffscreenRenderer((48, 48), RenderSettings(final_gather=0), samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(sheet_room())
        for origin, colour in (((-0.5, 0.1, 0.05), WHITE), ((0.9, 0.1, 0.05), GREEN)):
            image = offscreen.render_hdr(Camera(origin, (0.4, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0), view="albedo")
            seen = image[8:40, 8:40].reshape(-1, 3)
            np.testing.assert_allclose(seen, np.broadcast_to(colour, seen.shape), atol=0.02)
    finally:
        offscreen.release()


def test_each_side_of_a_two_sided_sheet_is_lit_as_its_own_face(ctx):
    """The lit image (the lightmap's surface pass, its final gather) under a uniform probe light: each side
    of the sheet reflects in its own colour everywhere, where the two faces' texels took turns."""
    scene = sheet_room()
    c = np.zeros((4, 4, 4, 9, 3), np.float32)
    c[..., 0, :] = 0.5 / sh.basis(np.array([0.0, 0.0, 1.0]))[0]
    offscreen = OffscreenRenderer((48, 48), samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(scene)
        offscreen.renderer.set_probes(ProbeGrid(*scene.bounds, c, np.ones((4, 4, 4), bool)))
        for origin, ratio in (((-0.5, 0.1, 0.05), (0.8, 1.25)), ((0.9, 0.1, 0.05), (2.5, 4.5))):
            image = offscreen.render_hdr(Camera(origin, (0.4, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0), view="final")
            seen = image[8:40, 8:40].reshape(-1, 3)
            green_over_red = seen[:, 1] / np.maximum(seen[:, 0], 1e-6)
            assert np.all((green_over_red > ratio[0]) & (green_over_red < ratio[1])), green_over_red
    finally:
        offscreen.release()
