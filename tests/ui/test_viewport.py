"""The viewport (viewer/ui/viewport.py): it draws only when something changed, previews while the user
interacts, anti-aliases the still image (refined frame by frame, or multisampled), and is not settled
while the lightmap's weights are made."""

from __future__ import annotations

import numpy as np

from viewer.scene import Camera


def recording_renderer(gl_context, scene, record):
    """A renderer on `scene` whose every draw calls `record(target)` first."""
    from viewer.gpu.renderer import RenderSettings, Renderer

    renderer = Renderer(gl_context, RenderSettings(light_samples=4))
    renderer.set_scene(scene)
    draw = renderer.draw
    renderer.draw = lambda target, camera, view, *rest: (record(target), draw(target, camera, view, *rest))
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


def test_a_refined_still_image_is_the_mean_of_its_jittered_images(gl_context, cornell):
    """The window's anti-aliasing: each draw into a RefiningTarget is one more image at the next subpixel
    offset, mixed into the mean so far. After n images it is the mean of n single-sampled images at those
    offsets (within the 8-bit rounding of the running mean), background pixels included (a camera outside
    the box sees past it), and its edges are blended where one image's are hard."""
    from viewer.gpu.camera import look_at
    from viewer.gpu.renderer import RenderSettings, Renderer
    from viewer.gpu.targets import DisplayTarget, RefiningTarget, refine_jitter

    assert refine_jitter(0) == (0.0, 0.0)
    offsets = np.array([refine_jitter(i) for i in range(16)])
    assert np.all(np.abs(offsets) <= 0.5) and len(np.unique(offsets, axis=0)) == 16
    renderer = Renderer(gl_context, RenderSettings(light_samples=4))
    renderer.set_scene(cornell)
    lo, hi = cornell.bounds
    centre = (lo + hi) / 2
    outside = look_at(centre + np.array([1.2, 0.8, 3.5]) * (hi - lo), centre)
    refined, single = RefiningTarget(gl_context, (96, 72), renderer.programs), DisplayTarget(gl_context, (96, 72))
    try:
        for camera in (cornell.camera, outside):
            refined.restart()
            mean = np.zeros((72, 96, 3))
            for i in range(8):
                renderer.draw(refined, camera)
                renderer.draw(single, camera, jitter=refine_jitter(i))
                mean += single.read() / 8
            image = refined.read().astype(float)
            assert refined.images == 8
            assert np.abs(image - mean).max() <= 2.0 and np.abs(image - mean).mean() < 0.2
            renderer.draw(single, camera)
            edges = np.abs(single.read() - image).max(axis=2) > 8
            assert 0 < edges.mean() < 0.2            # only the edges change, and they do
        assert (mean == 0).all(axis=2).mean() > 0.5   # the outside camera's background is in the test
    finally:
        refined.release()
        single.release()
        renderer.release()


def test_the_viewport_refines_a_still_view_a_frame_at_a_time(gl_context, cornell):
    """With `refine` n the still image is drawn n times, once a frame, and the view is settled only then;
    a change starts over, a preview is not refined, and the views drawn through an HDR image (probes,
    voxels) are not either."""
    from viewer.gpu.targets import RefiningTarget
    from viewer.ui.viewport import Viewport

    drawn = []
    renderer = recording_renderer(gl_context, cornell, lambda target: drawn.append(type(target)))
    screen = gl_context.simple_framebuffer((80, 60), components=4)
    viewport = Viewport(gl_context, renderer, preview_scale=0.5, refine=4)
    camera = cornell.camera
    try:
        steps = [viewport.frame(camera, "final", (1,), screen) for _ in range(6)]
        assert steps == [True] * 4 + [False] * 2 and viewport.settled
        assert drawn == [RefiningTarget] * 4
        refined = viewport.read(screen)
        moved = Camera((0.5, 0.0, 3.9), camera.target)
        assert viewport.frame(moved, "final", (1,), screen, preview=True) and not viewport.settled
        assert viewport.frame(moved, "final", (1,), screen, preview=True) is False   # a preview: no refinement
        assert viewport.frame(moved, "final", (1,), screen) and not viewport.settled
        assert [viewport.frame(moved, "final", (1,), screen) for _ in range(4)] == [True] * 3 + [False]
        assert viewport.settled
        assert viewport.frame(camera, "final", (1,), screen) and not viewport.settled   # back: started over
        for _ in range(3):
            viewport.frame(camera, "final", (1,), screen)
        np.testing.assert_array_equal(viewport.read(screen), refined)
        assert viewport.frame(camera, "albedo", (1,), screen) and not viewport.settled   # also the albedo view
        viewport.refine = 0                                   # off: one image, settled at once
        assert viewport.frame(camera, "final", (1,), screen) and viewport.settled
        assert not viewport.frame(camera, "final", (1,), screen)
        viewport.refine = 4
        assert viewport.frame(camera, "voxels", (1,), screen) and viewport.settled      # through an HDR image
        assert not viewport.frame(camera, "voxels", (1,), screen)
    finally:
        viewport.release()
        renderer.release()
        screen.release()
