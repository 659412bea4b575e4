"""The scene's vertex buffers (viewer/gpu/mesh.py, and the lightmap's in viewer/gpu/direct_bake.py): a
colour edit writes into them only what changed, and leaves what a fresh upload would hold."""

import numpy as np
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


def test_scene_vertices_hold_each_faces_corners_and_its_attributes_three_times():
    """`scene_vertices`: the faces with an area, three vertices each: the corner, then the face's normal,
    vertex albedo and emission repeated, then the corner's texture coordinate; float32 of the float64
    values; the lightmap's layout adds its atlas coordinates after them."""
    from viewer.gpu.mesh import face_uv, scene_vertices, vertex_albedo

    scene = load("cornell")
    keep = scene.face_areas > 0
    vertices = scene_vertices(scene, 16)[:, :14].reshape(-1, 3, 14)
    assert vertices.dtype == np.float32 and len(vertices) == keep.sum()
    np.testing.assert_array_equal(vertices[..., :3], scene.triangles[keep].astype(np.float32))
    for start, per_face in ((3, scene.face_normals), (6, vertex_albedo(scene)), (9, scene.emission)):
        np.testing.assert_array_equal(vertices[..., start:start + 3],
                                      np.repeat(per_face[keep][:, None].astype(np.float32), 3, axis=1))
    np.testing.assert_array_equal(vertices[..., 12:14], face_uv(scene)[keep].astype(np.float32))
    np.testing.assert_array_equal(scene_vertices(scene), scene_vertices(scene, 16)[:, :14])
