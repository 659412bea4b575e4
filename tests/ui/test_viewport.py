"""The viewport (viewer/ui/viewport.py): it draws only when something changed, previews while the user
interacts, multisamples the still image, and is not settled while the lightmap's weights are made."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.scene import Camera, load


@pytest.fixture(scope="module")
def cornell():
    return load("cornell")


def recording_renderer(gl_context, scene, record):
    """A renderer on `scene` whose every draw calls `record(target)` first."""
    from viewer.gpu.renderer import RenderSettings, Renderer

    renderer = Renderer(gl_context, RenderSettings(light_samples=4))
    renderer.set_scene(scene)
    draw = renderer.draw
    renderer.draw = lambda target, camera, view: (record(target), draw(target, camera, view))
    return renderer


def test_viewport_redraws_on_change_only_and_previews_while_interacting(gl_context, cornell):
    from viewer.gpu.offscreen import capture
    from viewer.ui.viewport import Viewport

    drawn_sizes = []
    renderer = recording_renderer(gl_context, cornell, lambda target: drawn_sizes.append(target.size))
    screen = gl_context.simple_framebuffer((80, 60), components=4)
    viewport = Viewport(gl_context, renderer, preview_scale=0.5)
    camera = cornell.camera
    try:
        assert viewport.frame(camera, "final", (1,), screen) and viewport.settled
        assert not viewport.frame(camera, "final", (1,), screen)
        presented = viewport.read(screen)
        renderer.settings.exposure = 2.0                       # tone-mapped as it is drawn: a redraw
        assert viewport.frame(camera, "final", (1,), screen)
        assert viewport.read(screen).mean() > presented.mean() + 10
        # what the window shows is what a capture with the same settings gives
        np.testing.assert_array_equal(viewport.read(screen), capture(cornell, None, size=(80, 60), samples=0,
                                                                     settings=renderer.settings, ctx=gl_context))
        moved = Camera((0.5, 0.0, 3.9), camera.target)
        assert viewport.frame(moved, "final", (1,), screen, preview=True) and not viewport.settled
        assert drawn_sizes[-1] == (40, 30)
        assert viewport.frame(moved, "final", (1,), screen)     # interaction over: full resolution
        assert drawn_sizes[-1] == (80, 60) and viewport.settled
        assert viewport.frame(moved, "final", (2,), screen)     # new probes or scene
        renderer.settings.light_samples = 8
        assert viewport.frame(moved, "final", (2,), screen)
        image = viewport.read(screen)
        assert image.shape == (60, 80, 3) and image.max() > 100
    finally:
        viewport.release()
        renderer.release()


def test_the_still_image_is_anti_aliased_and_the_preview_is_not(gl_context, cornell):
    """With multisampling the full-quality image is the capture's with the same samples (the box's edges
    blended), while the preview drawn during interaction is not multisampled (it keeps its frame rate)."""
    from viewer.gpu.offscreen import capture
    from viewer.ui.viewport import Viewport

    samples = []
    renderer = recording_renderer(gl_context, cornell, lambda target: samples.append(target.samples))
    screen = gl_context.simple_framebuffer((80, 60), components=4)
    viewport = Viewport(gl_context, renderer, preview_scale=0.5, samples=4)
    try:
        assert viewport.frame(cornell.camera, "final", (1,), screen, preview=True) and samples[-1] == 0
        assert viewport.frame(cornell.camera, "final", (1,), screen) and samples[-1] == min(4, gl_context.max_samples)
        still = viewport.read(screen)
        np.testing.assert_array_equal(still, capture(cornell, None, size=(80, 60), samples=4,
                                                     settings=renderer.settings, ctx=gl_context))
        hard = capture(cornell, None, size=(80, 60), samples=0, settings=renderer.settings, ctx=gl_context)
        assert np.abs(still.astype(int) - hard).max() > 40          # the edges differ
    finally:
        viewport.release()
        renderer.release()


def test_the_viewport_is_not_settled_while_the_lightmap_weights_are_made(gl_context, cornell):
    """The viewer makes a new scene's texel weights and gather rays on a worker and shows the probes per
    fragment meanwhile: that picture is not the settled one (captures and benchmarks wait for the baked
    one), and the baked one is drawn when the weights land."""
    import time

    from viewer.physical.gi import GISettings
    from viewer.gpu.compute_relight import solve_probes
    from viewer.gpu.renderer import RenderSettings, Renderer
    from viewer.ui.viewport import Viewport

    renderer = Renderer(gl_context, RenderSettings(light_samples=4))
    renderer.background_bake = True
    renderer.set_scene(cornell)
    renderer.set_probes(solve_probes(gl_context, cornell, GISettings(voxels=16, probes=8), include_emitted=False))
    screen = gl_context.simple_framebuffer((80, 60), components=4)
    viewport = Viewport(gl_context, renderer)
    try:
        assert viewport.frame(cornell.camera, "final", (1,), screen)
        assert renderer.baking and not viewport.settled
        while renderer.baking:
            time.sleep(0.02)
            viewport.frame(cornell.camera, "final", (1,), screen)
        assert viewport.settled
        assert not viewport.frame(cornell.camera, "final", (1,), screen)
    finally:
        viewport.release()
        renderer.release()
        screen.release()
