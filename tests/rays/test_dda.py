"""The cell-exact DDA: it visits exactly the cells a segment passes through, and its sun shadows agree
with exact ray casts against the triangles."""

import numpy as np
import pytest

from viewer.rays import dda
from viewer.rays.voxels import voxelize_with_faces
from scenes import box


def cells_of(scene, n):
    return dda.Cells.of(voxelize_with_faces(scene, n), scene)


def brute_force_cells(lo, h, n, a, b, margin=1e-7):
    """Every cell whose box the segment a -> b passes through for more than `margin` of a cell (slab
    test against each of the N^3 boxes)."""
    idx = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    box_lo, box_hi = lo + idx * h, lo + (idx + 1) * h
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.where(d != 0, (box_lo - a) / d, np.where((a >= box_lo) & (a <= box_hi), -np.inf, np.inf))
        t1 = np.where(d != 0, (box_hi - a) / d, np.where((a >= box_lo) & (a <= box_hi), np.inf, -np.inf))
    enter = np.maximum(np.minimum(t0, t1).max(axis=1), 0.0)
    leave = np.minimum(np.maximum(t0, t1).min(axis=1), 1.0)
    inside = (leave - enter) * np.linalg.norm(d) > margin * h
    cells = idx[inside]
    return set((cells[:, 0] + n * (cells[:, 1] + n * cells[:, 2])).tolist())


def test_the_march_visits_exactly_the_cells_a_segment_crosses():
    room = box(inward=True)
    cells = cells_of(room, 8)
    grid = voxelize_with_faces(room, 8).grid
    rng = np.random.default_rng(7)
    size = grid.voxel_size * grid.resolution
    for _ in range(300):
        # endpoints anywhere in and around the grid: segments that start outside, end inside, graze
        a, b = grid.lo + rng.uniform(-0.2, 1.2, (2, 3)) * size
        visited = dda.cells_along(cells, a, b)
        assert len(visited) == len(set(visited.tolist())), "a cell visited twice"
        assert set(visited.tolist()) == brute_force_cells(grid.lo, grid.voxel_size, grid.resolution, a, b)
        # in order along the segment: consecutive cells share a face
        coords = np.stack([visited % 8, visited // 8 % 8, visited // 64], 1)
        assert np.all(np.abs(np.diff(coords, axis=0)).sum(axis=1) == 1)


def test_axis_aligned_and_diagonal_rays_through_cell_corners():
    room = box(inward=True)
    cells = cells_of(room, 8)
    grid = voxelize_with_faces(room, 8).grid
    h, lo = grid.voxel_size, grid.lo
    # along an axis through cell centres: one row of cells
    a, b = lo + h * np.array([0.5, 3.5, 3.5]), lo + h * np.array([7.5, 3.5, 3.5])
    assert len(dda.cells_along(cells, a, b)) == 8
    # exactly through the corners of cells on the main diagonal: every step crosses three boundaries at
    # once, and the march may not skip the diagonal's cells
    a, b = lo + h * np.array([0.5, 0.5, 0.5]) + 1e-9, lo + h * np.array([7.5, 7.5, 7.5])
    diagonal = {c + 8 * (c + 8 * c) for c in range(8)}
    assert diagonal <= set(dda.cells_along(cells, a, b).tolist())


def test_a_closed_room_holds_every_ray():
    """From inside a closed room every ray hits a wall from the front: none leaks between the patches
    of two walls, none sees a back face (what the white furnace needs)."""
    grid = voxelize_with_faces(box(inward=True), 12).grid
    cells = cells_of(box(inward=True), 12)
    rng = np.random.default_rng(3)
    origins = rng.uniform(-0.95, 0.95, (20000, 3))
    directions = rng.normal(size=(20000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = dda.first_hits(cells, origins, directions)
    assert np.all(hits >= 0)
    # and the wall hit is the one the ray meets first
    t_exit = np.min(np.where(directions > 0, (1 - origins) / directions, (-1 - origins) / directions), axis=1)
    exit_point = origins + t_exit[:, None] * directions
    assert np.abs(grid.position[hits] - exit_point).max() < 1.01 * np.sqrt(3) * grid.voxel_size


def test_segments_are_blocked_by_a_wall_from_either_side():
    room = box(inward=True)
    wall = box(half_size=0.3)
    from viewer.scene import Scene

    scene = Scene.concatenate("room-and-box", [room, wall])
    cells = cells_of(scene, 16)
    a = np.array([[-0.8, 0.0, 0.0], [0.8, 0.0, 0.0], [-0.8, 0.5, 0.0]])
    b = np.array([[0.8, 0.0, 0.0], [-0.8, 0.0, 0.0], [0.8, 0.5, 0.0]])
    assert dda.segments_clear(cells, a, b).tolist() == [False, False, True]
    # from inside the box: the ray meets the back of the box's faces
    assert dda.first_hits(cells, np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]))[0] == dda.BACKFACE


@pytest.mark.parametrize("voxels", [16, 32])
def test_no_floor_point_in_shadow_sees_the_sun(voxels):
    """Sunny rooms of the stability study (a window, the sun through it): every point just above the
    floor that an exact ray cast against the triangles finds in shadow is in shadow for the DDA too.
    (The cast is the stability study's Moller-Trumbore over every triangle; trimesh's own ray caster
    needs the rtree package, which nothing else here uses.)"""
    from viewer.bench.stability.sun import blocked, sunny_room

    for number in range(3):
        scene, _ = sunny_room(number)
        lo, hi = scene.bounds
        rng = np.random.default_rng(number)
        count = 1500
        points = np.stack([rng.uniform(lo[0] + 0.05, hi[0] - 0.05, count), np.full(count, lo[1] + 0.02),
                           rng.uniform(lo[2] + 0.05, hi[2] - 0.05, count)], axis=1)
        shadowed = blocked(points, scene.sun.direction, scene.triangles)
        escapes = dda.escapes(cells_of(scene, voxels), points, scene.sun.direction)
        assert not np.any(escapes & shadowed)
        # and the sunlit patch is still lit (the voxels do not close the window)
        assert escapes[~shadowed].mean() > 0.5


def exact_hits(origins, directions, triangles):
    """(R,) distance to the nearest triangle along each ray (inf: none), and whether it is hit from the
    front (Moller-Trumbore against every triangle)."""
    v0, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    p = np.cross(directions[:, None], e2[None])
    det = np.einsum("tk,rtk->rt", e1, p)
    inv = 1.0 / np.where(np.abs(det) > 1e-14, det, np.inf)
    s = origins[:, None] - v0[None]
    u = np.einsum("rtk,rtk->rt", s, p) * inv
    q = np.cross(s, e1[None])
    v = np.einsum("rk,rtk->rt", directions, q) * inv
    t = np.einsum("tk,rtk->rt", e2, q) * inv
    t = np.where((u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9), t, np.inf)
    nearest = np.argmin(t, axis=1)
    rows = np.arange(len(origins))
    return t[rows, nearest], det[rows, nearest] > 0


def test_first_hits_are_the_nearest_triangle_and_its_side():
    """Random rays in a room with boxes (some starting inside them): the DDA, with its empty-space
    jumps, finds the same nearest surface as a brute-force cast against every triangle."""
    from viewer.scene import Scene

    scene = Scene.concatenate("boxes", [box(inward=True), box(0.3, (0.4, -0.7, 0.2)), box(0.15, (-0.5, 0.3, -0.4))])
    cells = cells_of(scene, 24)
    rng = np.random.default_rng(11)
    origins = rng.uniform(-0.98, 0.98, (4000, 3))
    directions = rng.normal(size=(4000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits, distance = dda.hit_distances(cells, origins, directions)
    truth, front = exact_hits(origins, directions, scene.triangles)
    assert np.all(np.isfinite(truth)) and np.all(hits != dda.MISS)
    assert np.allclose(distance, truth, rtol=0, atol=1e-9)
    assert np.array_equal(hits == dda.BACKFACE, ~front)


def test_a_triangle_is_listed_in_the_cells_of_its_box_its_plane_passes_through():
    """`_listing` against every cell of the grid, one at a time: a triangle is listed in a cell of its
    bounding box where the cell's centre lies within half the cell's extent along the normal of its plane,
    the entries sorted by flat cell and, within a cell, by triangle."""
    from viewer.scene.types import Scene

    rng = np.random.default_rng(9)
    n, h, lo = 8, 0.25, np.zeros(3)
    centres = rng.uniform(0.1, 1.9, (40, 1, 3))
    vertices = (centres + rng.normal(scale=0.3, size=(40, 3, 3))).clip(0.0, 1.999).reshape(-1, 3)
    faces = np.arange(120).reshape(40, 3)
    scene = Scene("cloud", vertices, faces, np.full((40, 3), 0.5), np.zeros((40, 3)), np.zeros(40, np.int64), ("a",))
    xyz, triangle = dda._listing(scene, lo, h, n)
    expected = []
    cells = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    for t, corners in enumerate(scene.triangles):
        low, high = np.floor(corners.min(axis=0) / h), np.floor(corners.max(axis=0) / h)
        normal = scene.face_normals[t]
        for cell in cells[np.all((cells >= low) & (cells <= high), axis=1)]:
            distance = abs((lo + (cell + 0.5) * h - corners[0]) @ normal)
            if distance <= 0.5 * h * np.abs(normal).sum() * (1 + 1e-9) + 1e-12 * h:
                expected.append((cell[0] + n * (cell[1] + n * cell[2]), t))
    assert len(expected) > 100
    flat = xyz[:, 0] + n * (xyz[:, 1] + n * xyz[:, 2])
    assert list(zip(flat.tolist(), triangle.tolist())) == sorted(expected)
