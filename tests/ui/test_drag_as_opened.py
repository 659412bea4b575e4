"""A lamp or an object dragged in the viewer, step after step (each step keeps what it can of the last:
the scene's derived geometry, the vertex buffers, the rays, the voxels), shows what a viewer opened on
the dragged scene shows, pixel for pixel, with either GI source."""

from __future__ import annotations

import time

import numpy as np
import pytest

from viewer.bench.edits import make_edit, settle
from viewer.bench.headless import HeadlessViewer
from viewer.physical.gi import GISettings
from viewer.scene import scene_file

SMALL = GISettings(voxels=16, probes=8)


@pytest.mark.parametrize("edit", ["lamp move", "object move"])
@pytest.mark.parametrize("source", ["compute", "neural"])
def test_a_dragged_lamp_or_object_looks_as_the_scene_opened_afresh(source, edit):
    settings = GISettings() if source == "neural" else SMALL   # the network's own lattice
    dragged = HeadlessViewer(source, settings, "cornell", size=(96, 72))
    try:
        if dragged.gi.source != source:
            pytest.skip(dragged.gi.unavailable[source])
        dragged.renderer.background_bake = True
        dragged.settle()
        for step in (1, 2, 3):
            make_edit(dragged, edit, step, scene_file("paper-test"))
            settle(dragged, time.perf_counter())
        scene, camera, picture = dragged.session.scene, dragged.session.camera, dragged.viewport.read(dragged.screen)
    finally:
        dragged.release()
    opened = HeadlessViewer(source, settings, scene, size=(96, 72))
    try:
        opened.renderer.background_bake = True
        opened.session.camera = camera   # the dragged lamp moved the scene's bounds: the same view
        opened.settle()
        np.testing.assert_array_equal(picture, opened.viewport.read(opened.screen))
    finally:
        opened.release()
