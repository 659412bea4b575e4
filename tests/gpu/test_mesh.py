"""The scene's vertex buffers (viewer/gpu/mesh.py, and the lightmap's in viewer/gpu/direct_bake.py): a
colour edit writes into them only what changed, and leaves what a fresh upload would hold."""

import pytest

from viewer.gpu.renderer import Renderer
from viewer.scene import load


@pytest.fixture(scope="module")
def cornell():
    return load("cornell")


def test_colour_edits_leave_both_vertex_buffers_as_a_fresh_upload_of_the_scene(gl_context, cornell):
    """A colour edit writes only the faces whose colours changed (`write_colours`): after a wall's albedo,
    the lamp's colour and a box's albedo, the scene's and the lightmap's vertex buffers hold byte for byte
    what a renderer given the last scene afresh holds."""
    edited, fresh = Renderer(gl_context), Renderer(gl_context)
    try:
        scene = cornell
        edited.set_scene(scene)
        for change in (lambda s: s.with_albedo("green-wall", (0.2, 0.5, 0.7)),
                       lambda s: s.with_emission("light", (3.0, 2.0, 1.0)),
                       lambda s: s.with_albedo("small-box", (0.9, 0.1, 0.1))):
            scene = change(scene)
            edited.set_scene(scene)
            edited._ensure_shadows()
            edited._ensure_baked()
        fresh.set_scene(scene)
        fresh._ensure_shadows()
        fresh._ensure_baked()
        for pick in (lambda r: r.mesh, lambda r: r._baked):
            assert pick(edited).buffer.read() == pick(fresh).buffer.read()
    finally:
        edited.release()
        fresh.release()
