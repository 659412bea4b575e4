"""Which side of which face a ray meets (viewer/rays/sides.py): a two-sided sheet modelled as two faces on
the same corners, wound opposite ways, shows each ray the side that faces it, whichever of the two
coincident faces the tracer reported."""

import numpy as np
import pytest

from viewer.rays import cast, dda
from viewer.scene.geometry import NO_TWIN, reversed_twins
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import voxelize_with_faces
from viewer.scene import Scene
from scenes import box

needs_embree = pytest.mark.skipif(not cast.embree_available(), reason="embreex is not installed")
CORNERS = np.array([[0.4, 1.0, -1.0], [0.4, 1.0, 1.0], [0.4, -1.0, 1.0], [0.4, -1.0, -1.0]])
SHEET = np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]])   # faces 0, 1 face +x; 2, 3 face -x


def test_reversed_twins_pair_the_faces_wound_the_other_way():
    """Twins share their three corners in any order and face opposite ways; a face turned round its
    corners (the same winding) is no twin, and a mesh without twins gets NO_TWIN."""
    faces = np.vstack([SHEET, [[1, 2, 0], [0, 1, 3]]])   # a rotation of face 0; a face on other corners
    twin = reversed_twins(CORNERS[faces])
    assert list(twin[:4]) == [2, 3, 0, 1]
    assert twin[4] == 2 and twin[5] == -1   # the rotation's twin is face 0's
    assert reversed_twins(CORNERS[SHEET[:2]]) is NO_TWIN
    assert reversed_twins(CORNERS[SHEET[:1]]) is NO_TWIN


@needs_embree
def test_each_side_of_a_two_sided_sheet_is_met_from_the_front():
    """Rays from either side of a two-sided wall in a closed room meet the face on their side from the
    front, at the point where they cross it, and land on that side's voxels: none is a back face, and the
    two sides' voxels differ. Without the twins the tracer names one of the two coincident faces, and
    the other side's rays met it from behind (no light, and their probes looked inside a solid)."""
    room = box(inward=True, albedo=0.5, name="room")
    wall = Scene("wall", CORNERS, SHEET, 0.8, 0.0, 0, ("wall",))
    scene = Scene.concatenate("split", [room, wall])
    first = len(room.faces)
    rng = np.random.default_rng(3)
    count = 400
    side = np.where(np.arange(count) % 2 == 0, -1.0, 1.0)   # start left (x < 0.4) or right of the wall
    origins = np.column_stack([0.4 + side * rng.uniform(0.05, 0.5, count), rng.uniform(-0.6, 0.6, (count, 2))])
    directions = np.column_stack([-side, rng.uniform(-0.3, 0.3, (count, 2))])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    caster = cast.TriangleCaster(scene, backend="embree")
    hits = caster.closest_hits(origins, directions)
    assert np.all(hits.front) and np.all(hits.face >= first)
    facing_plus_x = hits.face < first + 2
    assert np.array_equal(facing_plus_x, side > 0)
    points = origins + hits.t[:, None] * directions
    v0, e1, e2 = (a[hits.face] for a in scene.edges)
    np.testing.assert_allclose(v0 + hits.u[:, None] * e1 + hits.v[:, None] * e2, points, atol=1e-5)
    voxelization = voxelize_with_faces(scene, 16)
    rays = VoxelRays(scene, dda.Cells.of(voxelization, scene), "embree")
    landed = rays.bundle_hits(origins, directions[:, None]).ravel()
    assert np.all(landed >= 0)
    normals = voxelization.grid.normal[landed]
    assert np.all(np.sign(normals[:, 0]) == side)


def test_the_solver_sees_both_sides_of_a_two_sided_wall():
    """The physical solver in a room split by a two-sided wall: no probe on either side is taken for one
    inside a solid, and no gather ray meets a back face (from one side the wall was met from behind)."""
    from viewer.physical import geometry

    room = box(inward=True, albedo=0.5, name="room")
    wall = Scene("wall", CORNERS, SHEET, 0.8, 0.0, 0, ("wall",))
    traced = geometry.build(Scene.concatenate("split", [room, wall]), geometry.GeometrySettings(voxels=16, probes=8))
    assert traced.valid.all()
    assert not np.any(traced.gather_hits == dda.BACKFACE)
