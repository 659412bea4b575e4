"""Helpers for tests of the baked surfaces (tests/gpu/test_surface_light.py, test_surface_edits.py): the
renderer's images of a scene with given probes, and waiting for its background weights."""

from __future__ import annotations

import time

from viewer.bench.blotches import _srgb, view_depth
from viewer.gpu.offscreen import OffscreenRenderer
from viewer.gpu.renderer import RenderSettings


def render(ctx, scene, probes, size, views=("final",), settings=None):
    offscreen = OffscreenRenderer(size, settings or RenderSettings(), samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(scene)
        offscreen.renderer.set_probes(probes)
        images = {view: offscreen.render_hdr(view=view) for view in views}
        images["depth"] = view_depth(offscreen, scene.camera, scene.bounds)
    finally:
        offscreen.release()
    images["normals"] = 2.0 * _srgb(images["normals"]) - 1.0 if "normals" in images else None
    return images


def wait_for_weights(renderer) -> None:
    """Until the renderer's background worker has installed the lightmap's weights (polled as a frame does)."""
    while renderer.baking:
        time.sleep(0.02)
        renderer.bake_version()


def background_renderer(ctx, scene, probes, size) -> OffscreenRenderer:
    """An offscreen renderer that makes its lightmap weights on its worker, as the viewer's does, given
    `scene` and `probes` (the caller releases it)."""
    offscreen = OffscreenRenderer(size, samples=0, ctx=ctx)
    try:
        offscreen.renderer.background_bake = True
        offscreen.renderer.set_scene(scene)
        offscreen.renderer.set_probes(probes)
    except BaseException:
        offscreen.release()
        raise
    return offscreen
