"""The scene's vertex buffers (viewer/gpu/mesh.py, and the lightmap's in viewer/gpu/direct_bake.py): a
colour edit writes into them only what changed, and leaves what a fresh upload would hold."""

from dataclasses import replace

import numpy as np
import pytest

from viewer.gpu.renderer import Renderer
from viewer.scene import load


@pytest.fixture(scope="module")
def cornell():
    return load("cornell")


def assert_as_a_fresh_upload(gl_context, scenes, after_each=None) -> tuple:
    """Give one renderer `scenes` in turn (each drawn: shadow maps and lightmap) and another the last one
    afresh (its vertices a copy: no geometry to keep); the scene's and the lightmap's vertex buffers must
    then hold the same bytes. `after_each(renderer, mesh before)` after each scene but the first. Returns
    the first renderer's `in_draw_order` answer."""
    edited, fresh = Renderer(gl_context), Renderer(gl_context)
    try:
        for index, scene in enumerate(scenes):
            kept = edited.mesh
            edited.set_scene(scene)
            edited._ensure_shadows()
            edited._ensure_baked()
            if index and after_each is not None:
                after_each(edited, kept)
        fresh.set_scene(replace(scenes[-1], vertices=np.array(scenes[-1].vertices)))
        fresh._ensure_shadows()
        fresh._ensure_baked()
        for pick in (lambda r: r.mesh, lambda r: r._baked):
            assert pick(edited).buffer.read() == pick(fresh).buffer.read()
        return edited._draw_order
    finally:
        edited.release()
        fresh.release()


def test_colour_edits_leave_both_vertex_buffers_as_a_fresh_upload_of_the_scene(gl_context, cornell):
    """A colour edit writes only the faces whose colours changed (`write_colours`): after a wall's albedo,
    the lamp's colour and a box's albedo, the scene's and the lightmap's vertex buffers hold byte for byte
    what a renderer given the last scene afresh holds."""
    scenes = [cornell]
    for change in (lambda s: s.with_albedo("green-wall", (0.2, 0.5, 0.7)),
                   lambda s: s.with_emission("light", (3.0, 2.0, 1.0)),
                   lambda s: s.with_albedo("small-box", (0.9, 0.1, 0.1))):
        scenes.append(change(scenes[-1]))
    assert_as_a_fresh_upload(gl_context, scenes)


def test_scene_vertices_hold_each_faces_corners_and_its_attributes_three_times():
    """`scene_vertices`: the faces with an area, three vertices each: the corner, then the face's normal,
    vertex albedo and emission repeated, then the corner's texture coordinate; float32 of the float64
    values; the lightmap's layout adds its atlas coordinates after them."""
    from viewer.gpu.mesh import scene_vertices, vertex_albedo

    scene = load("cornell")
    keep = scene.face_areas > 0
    vertices = scene_vertices(scene, 16)[:, :14].reshape(-1, 3, 14)
    assert vertices.dtype == np.float32 and len(vertices) == keep.sum()
    np.testing.assert_array_equal(vertices[..., :3], scene.triangles[keep].astype(np.float32))
    for start, per_face in ((3, scene.face_normals), (6, vertex_albedo(scene)), (9, scene.emission)):
        np.testing.assert_array_equal(vertices[..., start:start + 3],
                                      np.repeat(per_face[keep][:, None].astype(np.float32), 3, axis=1))
    np.testing.assert_array_equal(vertices[..., 12:14], 0.0)   # no texture coordinates
    np.testing.assert_array_equal(scene_vertices(scene), scene_vertices(scene, 16)[:, :14])
    some = np.flatnonzero(keep)[5:17]   # some faces alone: their rows of the whole
    np.testing.assert_array_equal(scene_vertices(scene, faces=some).reshape(-1, 3, 14),
                                  scene_vertices(scene).reshape(-1, 3, 14)[5:17])


def test_drags_leave_the_vertex_buffers_and_the_draw_order_as_a_fresh_upload_of_the_scene(gl_context, cornell):
    """A drag writes only the faces that moved (`SceneMesh.write_moved`), on a copy of the scene in draw
    order that keeps its order and makes its geometry from the last one's (`in_draw_order`): after the
    lamp dragged and shrunk with a new colour, the small box dragged and a wall recoloured, the vertex
    buffers and the scene in draw order are what a renderer given the last scene afresh holds."""
    from viewer.gpu.mesh import in_draw_order

    def moved(x, scale=1.0):
        matrix = np.eye(4)
        matrix[:3, :3] *= scale
        matrix[0, 3] = x
        return matrix

    scenes = [cornell]
    for change in (lambda s: s.transformed_group("light", moved(0.2)),
                   lambda s: s.transformed_group("light", moved(-0.1, 0.7)).with_emission("light", (3, 2, 1)),
                   lambda s: s.transformed_group("small-box", moved(0.15)),
                   lambda s: s.with_albedo("green-wall", (0.2, 0.5, 0.7))):
        scenes.append(change(scenes[-1]))

    def kept_its_mesh(renderer, mesh):
        assert renderer.mesh is mesh

    ours = assert_as_a_fresh_upload(gl_context, scenes, kept_its_mesh)
    theirs = in_draw_order(scenes[-1])
    np.testing.assert_array_equal(ours[2], theirs[2])
    for name in ("faces", "albedo", "emission", "face_group", "triangles", "face_normals", "face_areas"):
        np.testing.assert_array_equal(getattr(ours[1], name), getattr(theirs[1], name), err_msg=name)


@pytest.mark.parametrize("writes", [64, 3])
def test_scattered_colour_changes_are_written_run_by_run_or_first_to_last(gl_context, cornell, writes, monkeypatch):
    """Faces recoloured here and there (runs of consecutive faces, each written apart, or more runs than
    `COLOUR_WRITES`: one write from the first to the last) leave the vertex buffers as a fresh upload
    holds them."""
    from viewer.gpu import mesh
    from viewer.gpu.mesh import in_draw_order, recoloured_rows

    monkeypatch.setattr(mesh, "COLOUR_WRITES", writes)

    rng = np.random.default_rng(7)
    albedo = np.array(cornell.albedo)
    chosen = rng.random(len(albedo)) < 0.5
    albedo[chosen] = rng.random((int(chosen.sum()), 3))
    edited_scene = replace(cornell, albedo=albedo)
    rows = recoloured_rows(in_draw_order(edited_scene)[1], in_draw_order(cornell)[1])
    assert len(rows) == chosen.sum() and 3 < 1 + np.count_nonzero(np.diff(rows) != 1) < 64
    assert_as_a_fresh_upload(gl_context, [cornell, edited_scene])
