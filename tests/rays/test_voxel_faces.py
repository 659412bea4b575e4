"""Voxels kept per (voxel, face) (viewer.rays.voxel_faces): the voxelization of a scene whose faces moved in
part, made from the moved faces alone, is the scene's own voxelization."""

import numpy as np
import pytest

from viewer.scene import load
from viewer.evaluation.procedural import PRESETS, random_scene
from viewer.rays.voxel_faces import FaceVoxels
from viewer.rays.voxels import face_facing, voxelize_with_faces


def assert_same_voxelization(ours, theirs):
    assert np.array_equal(ours.keys, theirs.keys)
    for name in ("coords", "position", "normal", "area", "albedo", "emission"):
        np.testing.assert_allclose(getattr(ours.grid, name), getattr(theirs.grid, name), rtol=1e-12, atol=1e-12,
                                   err_msg=name)
    np.testing.assert_allclose(ours.faces.toarray(), theirs.faces.toarray(), atol=1e-12)
    assert np.array_equal(ours.grid.lights.voxel, theirs.grid.lights.voxel)
    np.testing.assert_allclose(ours.grid.lights.position, theirs.grid.lights.position)


def moved(scene, group, offset, size=1.0):
    matrix = np.eye(4)
    matrix[:3, :3] *= size
    matrix[:3, 3] = offset
    return scene.transformed_group(group, matrix)


@pytest.mark.parametrize("name", ["cornell", "paper-test"])
@pytest.mark.parametrize("resolution", [16, 24])
def test_a_moved_lamp_gives_the_scenes_own_voxels(name, resolution):
    scene = load(name)
    pairs = FaceVoxels.of(scene, resolution)
    assert_same_voxelization(pairs.voxelization(scene), voxelize_with_faces(scene, resolution))
    for offset, size in (((0.2, 0.0, -0.15), 1.0), ((-0.1, -0.05, 0.1), 1.0), ((0.0, 0.0, 0.0), 1.0)):
        edited = moved(scene, "light", offset, size)
        pairs = pairs.moved(edited)
        assert pairs is not None
        assert_same_voxelization(pairs.voxelization(edited), voxelize_with_faces(edited, resolution))


def test_a_moved_object_in_a_wide_room():
    scene, params = random_scene(np.random.default_rng([14, 1]), "v2", PRESETS["v2"])
    pairs = FaceVoxels.of(scene, 16)
    edited = moved(scene, params["objects"][0]["kind"] + "-1", (0.05, 0.0, 0.05))
    assert_same_voxelization(pairs.moved(edited).voxelization(edited), voxelize_with_faces(edited, 16))


def test_what_cannot_be_kept_is_voxelized_afresh():
    scene = load("cornell")
    pairs = FaceVoxels.of(scene, 16)
    assert pairs.moved(moved(scene, "floor", (0.0, -0.5, 0.0))) is None      # the bounds grew
    assert pairs.moved(load("paper-test")) is None                          # other faces
    everything = scene.transformed_group("floor", np.eye(4))
    for group in scene.groups:
        everything = moved(everything, group, (0.01, 0.0, 0.0), 0.99)
    assert pairs.moved(everything) is None                                  # every face moved


@pytest.mark.parametrize("group", ["light", "large-box"])
def test_the_cells_of_a_moved_scene_list_what_listing_it_afresh_lists(group, monkeypatch):
    """`dda.Cells.of` from the cells before some faces moved keeps the others' entries and lists the moved
    ones alone; every entry, its order and its voxel (the grazing ones' neighbours and BACKFACE
    included) are those of listing the moved scene afresh, three moves in a row."""
    from viewer.rays import dda

    scene = load("cornell")
    pairs = FaceVoxels.of(scene, 16)
    cells = dda.Cells.of(pairs.voxelization(scene), scene)
    for step in range(3):
        edited = moved(scene, group, (0.07 * (step + 1), 0.0, -0.05 * step))
        pairs = pairs.moved(edited)
        voxelization = pairs.voxelization(edited)
        fresh = dda.Cells.of(voxelization, edited)
        with monkeypatch.context() as patch:   # the full listing is not made
            patch.setattr(dda, "_listing", None)
            cells = dda.Cells.of(voxelization, edited, cells)
        cell = np.repeat(np.arange(16 ** 3), np.diff(fresh.first))
        own = cell * 6 + face_facing(edited.face_normals)[fresh.triangle]
        assert (voxelization.keys[fresh.voxel] != own).any()   # grazing entries take a neighbour's voxel
        for name in ("first", "triangle", "voxel"):
            assert np.array_equal(getattr(cells, name), getattr(fresh, name)), name
    # a largest face of another size decides otherwise which faces are too small to list: all afresh
    assert dda._moved(cells, edited, cells.lo, cells.h, cells.n, 2 * cells.largest) is None
    assert dda._moved(cells, edited, cells.lo, cells.h, cells.n, cells.largest) is not None


@pytest.mark.parametrize("group", ["back", "small-box"])
def test_a_textured_scene_moved_in_part_keeps_its_textures_in_the_voxels(group):
    """With a textured back wall (blue on its left half, yellow on its right), the pairs kept across a
    move carry their share of the texture with them, and so do the moved faces' new pairs: the voxels
    are the moved scene's own, their albedo included."""
    from dataclasses import replace

    from viewer.scene.textures import Texture

    box = load("cornell")
    image = np.zeros((2, 64, 3), np.float32)
    image[:, :32], image[:, 32:] = (0.1, 0.2, 0.8), (0.8, 0.7, 0.1)
    texture = Texture(image, srgb=False, wrap=("clamp", "clamp"), name="two-tone")
    corners = box.triangles
    uv = np.stack([(corners[..., 0] + 1) / 2, (1 - corners[..., 1]) / 2], axis=-1)
    back = box.group_index("back")
    textures = tuple(texture if g == back else None for g in range(len(box.groups)))
    scene = replace(box, uv=uv, textures=textures)
    pairs = FaceVoxels.of(scene, 16)
    assert pairs.tint is not None
    edited = moved(scene, group, (0.0, 0.0, 0.04) if group == "back" else (0.1, 0.0, 0.1))
    kept = pairs.moved(edited)
    assert kept is not None and kept.tint is not None
    assert_same_voxelization(kept.voxelization(edited), voxelize_with_faces(edited, 16))
