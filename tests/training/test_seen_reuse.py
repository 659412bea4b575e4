"""The neighbours' seen rays reprojected to each probe (viewer/training/seen_reuse.py): what the gather
must give where the answer is known."""

import numpy as np
import pytest

from scenes import box
from viewer.neural.seen import SeenRays
from viewer.probes.grid import ProbeGrid
from viewer.rays import dda
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import voxelize_with_faces
from viewer.training.seen_reuse import reused

VOXELS = 16
SIDE = 8
DC_OF_ONE = np.sqrt(4.0 * np.pi)   # the constant radiance 1 over the sphere, in SH band 0


@pytest.fixture(scope="module")
def room():
    """A closed, empty room [-1, 1]^3, its voxels, and the seen rays of an 8^3 probe lattice over it."""
    scene = box(inward=True, albedo=0.5, name="room")
    voxelization = voxelize_with_faces(scene, VOXELS)
    landing = VoxelRays(scene, dda.Cells.of(voxelization, scene))
    lo, hi = scene.bounds
    points = ProbeGrid.positions_for(lo, hi, SIDE).reshape(-1, 3)
    return voxelization.grid, SeenRays(landing, voxelization.grid.count, points, 16), landing


def test_a_probe_reading_its_own_rays_alone_gathers_what_they_gather(room):
    """With no neighbour read, the balance heuristic weighs each hit 4 pi / rays in its own direction:
    the plain gather, whatever the light."""
    voxels, rays, _ = room
    light = np.random.default_rng(3).uniform(0.0, 2.0, (voxels.count, 3))
    np.testing.assert_allclose(reused(rays, voxels, light, "self"), rays.gathered(light), rtol=1e-4, atol=1e-5)


def test_uniform_light_read_through_the_neighbours_rays_is_uniform_on_average(room):
    """Every surface leaving radiance 1 in a room that every probe sees whole: each probe sees 1 in every
    direction. Read from its own 16 rays and its neighbours', each hit weighed by where it lands, the
    estimate has no bias (the mean over the probes within 1%) and some noise (a few percent a probe),
    where a probe's own rays alone, each bringing exactly 1, are exact in band 0."""
    voxels, rays, _ = room
    for reach in ("faces", "block"):
        dc = reused(rays, voxels, np.ones((voxels.count, 1)), reach)[:, 0, 0] / DC_OF_ONE
        assert abs(dc.mean() - 1.0) < 0.01
        assert dc.std() < 0.04 and np.abs(dc - 1.0).max() < 0.12


def test_a_lit_wall_is_brighter_from_the_probes_near_it(room):
    """Only the x = +1 wall shines: the probes nearer it see it under a larger solid angle, and look +x."""
    voxels, rays, _ = room
    light = (voxels.normal[:, 0] < -0.5).astype(np.float64)[:, None]   # the wall at +1 faces -x
    out = reused(rays, voxels, light, "block").reshape(SIDE, SIDE, SIDE, 9)
    middle = out[:, SIDE // 2, SIDE // 2]
    assert np.all(np.diff(middle[:, 0]) > 0)    # DC grows towards the wall
    assert np.all(middle[:, 3] > 0)             # the x band (index 3) points at it


def test_probes_off_a_cubic_lattice_are_refused(room):
    voxels, _, landing = room
    scattered = SeenRays(landing, voxels.count, np.zeros((5, 3)), 8)
    with pytest.raises(ValueError, match="cubic lattice"):
        reused(scattered, voxels, np.ones((voxels.count, 1)))

