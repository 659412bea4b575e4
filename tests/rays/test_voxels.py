import numpy as np
import pytest

from viewer import scene as scenes
from viewer.rays.voxels import FACINGS, face_facing, voxelize
from scenes import box


def test_hash_id_is_x_plus_y_n_plus_z_n_n():
    grid = voxelize(scenes.load("cornell"), 16)
    x, y, z = grid.coords.T
    assert np.array_equal(grid.hash_id, x + y * 16 + z * 256)
    assert grid.hash_id.min() >= 0 and grid.hash_id.max() < 16 ** 3


@pytest.mark.parametrize("n", [16, 32, 64])
def test_areas_add_up_to_the_surface_area(n):
    scene = scenes.load("cornell")
    grid = voxelize(scene, n)
    assert grid.area.sum() == pytest.approx(scene.face_areas.sum(), rel=1e-9)


def test_a_room_has_one_voxel_per_wall_cell_and_two_or_three_in_edges_and_corners():
    n = 16
    grid = voxelize(box(inward=True), n)
    # Six walls of n x n cells each; cells on the 12 edges hold two facings, the 8 corners three.
    assert grid.count == 6 * n * n
    assert len(np.unique(grid.hash_id)) == 6 * n * n - 12 * n + 8
    # Every wall voxel away from the edges covers one cell face of the room: (2 / n')^2 where the
    # grid is padded by half a voxel (n' = n - 1 voxels span the room).
    h = grid.voxel_size
    interior = np.all((grid.coords > 0) & (grid.coords < n - 1), axis=1) | (np.sum(
        (grid.coords == 0) | (grid.coords == n - 1), axis=1) == 1)
    assert np.median(grid.area[interior]) == pytest.approx(h * h, rel=0.02)


def test_normals_face_into_the_room_and_albedo_is_kept():
    grid = voxelize(scenes.load("cornell"), 32)
    centre = np.zeros(3)
    # voxels on the five walls; the small box's base lies on the floor plane (y = -1) facing down
    walls = np.isclose(np.abs(grid.position).max(axis=1), 1.0, atol=1e-9)
    walls &= ~((grid.position[:, 1] < -0.99) & (grid.normal[:, 1] < -0.99))
    inward = np.einsum("ij,ij->i", grid.normal[walls], centre - grid.position[walls])
    assert np.all(inward > 0)
    red = grid.position[:, 0] < -0.99
    assert np.allclose(grid.albedo[red & (grid.normal[:, 0] > 0.9)], [0.570068, 0.0430135, 0.0443706], atol=1e-6)


def test_emitters_keep_their_power_and_light_samples_are_finer():
    scene = scenes.load("cornell")
    grid = voxelize(scene, 32)
    power = (scene.emission * scene.face_areas[:, None]).sum(0)
    assert (grid.emission * grid.area[:, None]).sum(0) == pytest.approx(power, rel=1e-9)
    lights = grid.lights
    assert (lights.radiance * lights.area[:, None]).sum(0) == pytest.approx(power, rel=1e-9)
    assert lights.count > np.count_nonzero(np.any(grid.emission > 0, axis=1))
    assert np.all(lights.normal @ [0, -1, 0] > 0.99)


def test_paper_normal_option_averages_triangle_normals():
    grid = voxelize(scenes.load("cornell"), 16, normal_mode="paper")
    assert np.allclose(np.linalg.norm(grid.normal, axis=1), 1.0)


def test_voxelizing_a_scene_is_deterministic_and_rejects_bad_settings():
    scene = scenes.load("paper-test")
    a, b = voxelize(scene, 16), voxelize(scene, 16)
    assert np.array_equal(a.hash_id, b.hash_id) and np.array_equal(a.area, b.area)
    with pytest.raises(ValueError):
        voxelize(scene, 1)
    with pytest.raises(ValueError):
        voxelize(scene, 16, normal_mode="nope")


def test_a_face_joins_the_facing_of_its_largest_dot_product_the_first_of_equals():
    """`face_facing` is the argmax of the normal's dot products with the six signed axes, ties (diagonals,
    a zero normal, negative zeros) going to the first, as the voxels' keys were made before."""
    rng = np.random.default_rng(5)
    ties = np.array([[1, 1, 0], [-1, -1, 0], [0, -1, -1], [-1, 1, 1], [1, -1, -1], [0, 0, 0], [-0.0, -0.0, -1],
                     [-0.0, 0, 0], [0, 2, -2], [-3, 0, 3]], np.float64)
    normals = np.concatenate([rng.normal(size=(2000, 3)), ties])
    np.testing.assert_array_equal(face_facing(normals), np.argmax(normals @ FACINGS.T, axis=1))


@pytest.mark.parametrize("name", ["cornell", "textured"])
def test_voxel_albedo_kept_across_edits_is_the_whole_product_to_the_bit(name):
    """`VoxelAlbedo` sums again only the voxels of the faces recoloured (a wall), all of them where many
    faces changed or the faces are textured; every answer is `voxel_albedo`'s, bit for bit, and an
    unchanged albedo gives the same array back."""
    from pathlib import Path

    from viewer.rays.voxels import VoxelAlbedo, voxel_albedo, voxelize_with_faces

    documented = Path(__file__).resolve().parents[2] / "docs" / "data" / "textured-room.gltf"
    scene = scenes.load("cornell" if name == "cornell" else documented)
    assert scene.textured == (name == "textured")
    voxelization = voxelize_with_faces(scene, 16)
    first = voxel_albedo(voxelization.faces, voxelization.tint, scene)
    kept = VoxelAlbedo(voxelization.faces, voxelization.tint, scene, first)
    assert kept.of(scene) is first
    wall = scene.largest_group()
    edits = [scene.with_albedo(wall, [0.2, 0.8, 0.3]), scene,
             scene.with_albedo(wall, [0.9, 0.1, 0.1]).with_albedo(scene.groups[-1], [0.4, 0.4, 0.1]),
             scene.with_albedo(wall, [0.9, 0.1, 0.1])]
    everything = scene
    for group in scene.groups:
        everything = everything.with_albedo(group, [0.3, 0.5, 0.7])
    for edited in edits + [everything]:
        answer = kept.of(edited)
        np.testing.assert_array_equal(answer, voxel_albedo(voxelization.faces, voxelization.tint, edited))
        assert kept.of(edited) is answer
    assert name != "cornell" or kept._columns is not None   # a wall alone was summed again
