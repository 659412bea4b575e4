"""The visibility ladder's gathers (viewer/training/ladder.py, viewer/training/cones.py): what each must
see of the surfaces' light where the answer is known."""

import numpy as np
import pytest

from scenes import box, quads_to_triangles
from viewer.neural.bounce import Bounce
from viewer.rays import dda
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import voxelize_with_faces
from viewer.scene import Scene
from viewer.training.cones import ConeTracer
from viewer.neural.seen import SeenRays
from viewer.training.ladder import box_filtered

VOXELS = 24
DC_OF_ONE = np.sqrt(4.0 * np.pi)   # the constant radiance 1 over the sphere, in SH band 0


def partitioned_room(x: float = 0.3, gap: float = 0.04) -> Scene:
    """A closed room, [-1, 1]^3, cut across by a thin wall (two faces `gap` apart) at `x`."""
    faces = []
    for side, at in ((-1, x - 0.5 * gap), (1, x + 0.5 * gap)):
        v = np.array([[at, -1, -1], [at, 1, -1], [at, 1, 1], [at, -1, 1]], np.float64)
        quad = np.array([[0, 1, 2, 3]]) if side > 0 else np.array([[0, 3, 2, 1]])
        faces.append(Scene("wall", v, quads_to_triangles(quad), 0.5, 0.0, 0, ("wall",)))
    return Scene.concatenate("partitioned", [box(inward=True, albedo=0.5, name="room"), *faces])


def near_points(count: int = 5) -> np.ndarray:
    """Points in the room's larger part, at least a few voxels from the wall and the room's walls."""
    axis = np.linspace(-0.7, 0.7, count)
    x = np.linspace(-0.7, -0.1, count)
    return np.stack(np.meshgrid(x, axis, axis, indexing="ij"), -1).reshape(-1, 3)


@pytest.fixture(scope="module")
def room():
    scene = partitioned_room()
    voxelization = voxelize_with_faces(scene, VOXELS)
    return scene, voxelization.grid, VoxelRays(scene, dda.Cells.of(voxelization, scene))


def test_a_room_of_uniform_light_is_seen_whole_by_rays_and_cones(room):
    """Every surface leaving radiance 1: a point anywhere inside sees 1 in every direction (band 0 only)."""
    scene, voxels, rays_of_scene = room
    points = near_points(3)
    ones = np.ones((voxels.count, 3))
    rays = SeenRays(rays_of_scene, voxels.count, points, 64).gathered(ones)
    np.testing.assert_allclose(rays[:, 0], DC_OF_ONE, rtol=1e-6)
    # 27 points are dealt the 27 interleaved parts of one lattice of 1,728 directions: together they
    # integrate the rest to nearly 0, each alone to within a few percent
    assert np.abs(rays[:, 1:].mean(axis=0)).max() < 0.002 * DC_OF_ONE
    assert np.abs(rays[:, 1:]).max() < 0.03 * DC_OF_ONE
    cones = ConeTracer(voxels, 16).gathered(ones, points)
    np.testing.assert_allclose(cones[:, 0], DC_OF_ONE, rtol=0.05)   # what stops short of opaque is lost


def test_a_thin_wall_hides_the_light_behind_it_from_rays_not_from_the_unshadowed_gather(room):
    """Light only beyond the wall: the points before it see none of it; the gather without visibility
    sees it all, the cones leak a little through the mip levels, the rays see exactly none."""
    scene, voxels, rays_of_scene = room
    beyond = (voxels.position[:, 0] > 0.3 + voxels.voxel_size)[:, None] * np.ones(3)   # whole cells past it
    points = near_points()
    lo, hi = scene.bounds
    unshadowed = Bounce(voxels, lo, hi, 4).gathered(beyond)                      # probes on a 4^3 lattice
    lattice = np.linspace(lo[0], hi[0], 9)[1::2]
    near = np.stack(np.meshgrid(lattice, lattice, lattice, indexing="ij"), -1).reshape(-1, 3)[:, 0] < 0.2
    assert unshadowed[near, 0, 0].min() > 0.1 * DC_OF_ONE
    rays = SeenRays(rays_of_scene, voxels.count, points, 64).gathered(beyond)
    assert np.abs(rays).max() == 0.0
    cones = ConeTracer(voxels, 16).gathered(beyond, points)
    # trilinear reads mix the lit cells past the wall into the samples at it: 17% of the unshadowed light
    assert np.median(cones[:, 0, 0]) < 0.25 * np.median(unshadowed[near, 0, 0])


def test_the_box_filter_averages_valid_neighbours_only():
    valid = np.ones((3, 3, 3), bool)
    valid[1, 1, 1] = False
    values = np.where(valid, 1.0, 100.0)[None]
    filtered = box_filtered(values, valid)
    np.testing.assert_allclose(filtered[0], 1.0)   # the invalid probe's 100 reaches no one, itself included
