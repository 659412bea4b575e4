"""Rays that land on voxels (viewer/rays/voxel_rays.py): Embree, with the voxel read from the DDA's cell
listing, names the voxel the DDA's march names, so the physical solver gives the same light on either."""

import numpy as np
import pytest

from viewer.physical import geometry, lightpaths, relight
from viewer.rays import cast, dda, voxel_rays
from viewer.rays.voxel_rays import VoxelRays
from viewer.scene import load
from scenes import box

needs_embree = pytest.mark.skipif(not cast.embree_available(), reason="embreex is not installed")
SETTINGS = geometry.GeometrySettings(voxels=32, probes=12)


@pytest.fixture(scope="module")
def cornell_both():
    """The Cornell box's geometry, lamp paths and converged probes, traced on each backend."""
    scene = load("cornell")
    out = {}
    for backend in ("dda", "embree"):
        traced = geometry.build(scene, SETTINGS, backend=backend)
        lights = lightpaths.build(scene, traced)
        sun = geometry.sun_paths(traced, scene.sun)
        mat = relight.materials(scene, traced, lights)
        lighting = relight.solve(traced, lights, sun, mat)
        out[backend] = (traced, lights, relight.probe_coefficients(traced, lights, sun, mat, lighting))
    return scene, out


@needs_embree
def test_both_backends_name_the_same_voxels_in_the_cornell_box(cornell_both):
    """Gather rays and the valid probes' rays land on the same voxel on both backends but for a few
    rays in ten thousand (a hit on a face's edge or a cell's boundary), and those land on a neighbour:
    within about one voxel. Probes inside solids (where rays meet coincident faces: a box's bottom on
    the floor) may tell a back from a front differently, and stay inside solids on both."""
    _, out = cornell_both
    marched, cast_ = out["dda"][0], out["embree"][0]
    assert cast_.rays.backend == "embree" and marched.rays.backend == "dda"
    k = marched.voxels.count
    differ = marched.gather_hits != cast_.gather_hits
    assert differ.mean() < 2e-4
    both = differ & (marched.gather_hits >= 0) & (cast_.gather_hits >= 0)
    position = marched.voxels.position
    apart = np.linalg.norm(position[marched.gather_hits[both]] - position[cast_.gather_hits[both]], axis=1)
    assert (apart <= 1.5 * marched.voxels.voxel_size).all()
    np.testing.assert_array_equal(marched.valid, cast_.valid)
    valid = marched.valid.reshape(-1)
    assert (marched.probe_hits[valid] != cast_.probe_hits[valid]).mean() < 1e-3
    assert np.array_equal(marched.transport.shape, (k, k))


@needs_embree
def test_both_backends_give_the_same_lamp_and_sun_paths_and_probes(cornell_both):
    """The lamp's visibility (segments to its patches) and the probes it gives agree exactly; the
    converged probes of the whole solve agree within 0.2%."""
    _, out = cornell_both
    (_, marched_lights, marched_probes), (_, cast_lights, cast_probes) = out["dda"], out["embree"]
    np.testing.assert_array_equal(marched_lights.voxel_irradiance, cast_lights.voxel_irradiance)
    np.testing.assert_array_equal(marched_lights.probe_matrix(), cast_lights.probe_matrix())
    assert np.linalg.norm(marched_probes - cast_probes) < 2e-3 * np.linalg.norm(marched_probes)


@pytest.mark.parametrize("backend", [pytest.param("embree", marks=needs_embree), "dda"])
def test_a_ray_inside_a_closed_room_lands_on_the_wall_ahead_and_a_cube_shows_its_back(backend):
    """From the middle of an inward-facing room each axis ray lands on the voxel of the wall ahead;
    from inside an outward-facing cube every ray meets a back face; out of an open box a ray escapes."""
    room = box(inward=True)
    traced = geometry.build(room, geometry.GeometrySettings(voxels=16, probes=4), backend=backend)
    axes = np.array([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    hits = traced.rays.first_hits(np.full((6, 3), 0.013), axes)
    assert (hits >= 0).all()
    landed = traced.voxels.position[hits]
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", landed, axes)), 1.0, atol=0.7 * traced.voxels.voxel_size)
    np.testing.assert_allclose(traced.voxels.normal[hits], -axes, atol=1e-6)   # the inside of the wall ahead
    cube = box(half_size=0.5)
    solid = VoxelRays(cube, dda.Cells.blocking(cube, np.full(3, -1.0), 2.0 / 16, 16), backend)
    assert (solid.first_hits(np.zeros((6, 3)), axes) == dda.BACKFACE).all()
    assert solid.escapes(np.array([[0.0, 0.0, 2.0]]), np.array([0.0, 0.0, 1.0]))[0]
    assert not solid.escapes(np.array([[0.0, 0.0, -2.0]]), np.array([0.0, 0.0, 1.0]))[0]
    clear = solid.segments_clear(np.array([[0.0, 0.0, -2.0], [0.0, 0.0, -2.0]]),
                                 np.array([[0.0, 0.0, -0.6], [0.0, 0.0, 0.0]]))
    np.testing.assert_array_equal(clear, [True, False])


@needs_embree
def test_a_bundle_traced_in_one_loop_lands_where_its_rays_one_by_one_do():
    """`bundle_hits` traces and looks up in one compiled loop (Embree called directly); its voxels are
    those of the same rays cast one by one (`first_hits`: the caster's hits, then the lookup), bit for bit,
    for shared directions and for one set per origin."""
    from viewer.rays.voxels import voxelize_with_faces

    scene = load("cornell")
    cells = dda.Cells.of(voxelize_with_faces(scene, 24), scene)
    rays = VoxelRays(scene, cells, "embree")
    assert rays.caster.direct is not None
    rng = np.random.default_rng(11)
    origins = rng.uniform(-0.9, 0.9, (300, 3))
    shared = rng.normal(size=(40, 3))
    shared /= np.linalg.norm(shared, axis=1, keepdims=True)
    own = rng.normal(size=(300, 40, 3))
    own /= np.linalg.norm(own, axis=2, keepdims=True)
    for directions in (shared, own):
        bundle = rays.bundle_hits(origins, directions)
        each = np.broadcast_to(directions[None] if directions.ndim == 2 else directions, (300, 40, 3))
        one_by_one = rays.first_hits(np.repeat(origins, 40, axis=0), each.reshape(-1, 3)).reshape(300, 40)
        assert len(np.unique(bundle)) > 20 and (bundle == dda.MISS).any()   # both outcomes are tested
        np.testing.assert_array_equal(bundle, one_by_one)


def _sphere_room():
    """The lit room with a finely tessellated sphere in it (5,120 triangles, many per cell)."""
    import trimesh

    from viewer.scene import Scene
    from scenes import lit_room

    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.35)
    sphere = Scene("ball", np.asarray(ball.vertices) + [0.1, -0.5, 0.0], np.asarray(ball.faces), 0.7, 0.0, 0,
                   ("ball",))
    return lit_room(sphere)


@needs_embree
@pytest.mark.parametrize("name", ["cornell", "sphere room"])
def test_keyed_cells_name_the_voxels_the_listing_names(name):
    """Rays cast through Embree and looked up by key (`keyed_cells`: no triangle listed in any cell) land on
    the voxel the cell listing names, ray for ray, through every lookup: one by one, in a bundle, and
    kept across a call; the key table is the listing's own."""
    from viewer.rays.voxel_rays import keyed_cells
    from viewer.rays.voxels import voxelize_with_faces

    scene = load("cornell") if name == "cornell" else _sphere_room()
    voxelization = voxelize_with_faces(scene, 24)
    listed = VoxelRays(scene, dda.Cells.of(voxelization, scene), "embree")
    keyed = VoxelRays(scene, keyed_cells(voxelization.grid, voxelization.keys, scene), "embree", listed.caster)
    assert len(keyed.cells.first) == 0 and len(listed.cells.triangle) > len(scene.faces)
    rng = np.random.default_rng(5)
    lo, hi = scene.bounds
    origins = rng.uniform(lo, hi, (400, 3))
    directions = rng.normal(size=(400, 64, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    ours, theirs = keyed.kept_bundle(origins, directions)[0], listed.kept_bundle(origins, directions)[0]
    assert (theirs >= 0).mean() > 0.5 and (theirs == dda.BACKFACE).any()   # fronts and backs are met
    np.testing.assert_array_equal(ours, theirs)
    np.testing.assert_array_equal(keyed.bundle_hits(origins, directions), theirs)
    flat = np.repeat(origins, 64, axis=0), directions.reshape(-1, 3)
    np.testing.assert_array_equal(keyed.first_hits(*flat), listed.first_hits(*flat))


@needs_embree
def test_segments_whose_cells_hold_no_triangle_are_clear_untraced():
    """`pairs_clear` answers a segment whose box of cells no triangle's box reaches without tracing it (a
    probe in a room's open middle and a lamp): the same answers as every segment traced, and most of the
    segments from a room's middle to its ceiling answered so."""
    from viewer.neural import encoding
    from viewer.rays.voxels import voxelize
    from scenes import lit_room

    scene = lit_room(box(0.25, centre=(0.2, -0.75, 0.1), name="block"))
    blockers = encoding.occluders(scene, voxelize(scene, 16))
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.95, 0.95, (403, 3))   # a last packet of three
    ends = np.column_stack([rng.uniform(-0.3, 0.3, 12), np.full(12, 0.9), rng.uniform(-0.3, 0.3, 12)])
    found = blockers.pairs_clear(points, ends)
    a, b = np.repeat(points, len(ends), axis=0), np.tile(ends, (len(points), 1))
    np.testing.assert_array_equal(found, blockers.segments_clear(a, b).reshape(found.shape))
    assert 0 < found.mean() < 1   # the block shadows some
    table, cells = blockers.occupied, blockers.cells
    untraced = [voxel_rays.empty_box(table, cells.lo, cells.h, *p, *e) for p, e in zip(a, b)]
    assert np.mean(untraced) > 0.3
    assert not np.any(np.asarray(untraced) & (found.ravel() == 0))


@pytest.mark.parametrize("n", [1, 7, 48])
def test_the_summed_volume_table_is_numpy_s_cumulative_sums(n):
    held = (np.random.default_rng(n).random((n, n, n)) < 0.3).astype(np.uint8)
    out = np.zeros((n + 1, n + 1, n + 1), np.int32)
    voxel_rays._summed_volume(held, out)
    expected = np.zeros_like(out)
    expected[1:, 1:, 1:] = held.astype(np.int32).cumsum(0).cumsum(1).cumsum(2)
    np.testing.assert_array_equal(out, expected)


def test_pairs_traced_eight_at_a_time_answer_as_one_by_one():
    """`pairs_clear` traces the segments of eight consecutive points to one end in a packet
    (rtcOccluded8): the Cornell box's probe lattice to points on and under its lamp answers as every
    segment traced alone does."""
    pytest.importorskip("embreex")
    from viewer.neural import encoding
    from viewer.probes.grid import ProbeGrid
    from viewer.rays.voxels import voxelize

    scene = load("cornell")
    blockers = encoding.occluders(scene, voxelize(scene, 24))
    points = ProbeGrid.positions_for(*scene.bounds, 13).reshape(-1, 3)     # 2,197: not a whole packet
    u = np.linspace(-0.2, 0.2, 4)
    ends = np.stack(np.meshgrid(u, [0.54, 0.3], u), -1).reshape(-1, 3)
    found = blockers.pairs_clear(points, ends)
    a, b = np.repeat(points, len(ends), axis=0), np.tile(ends, (len(points), 1))
    np.testing.assert_array_equal(found.ravel(), blockers.segments_clear(a, b))   # rtcOccluded1, a segment a call
    assert 0.05 < 1 - found.mean() < 0.95     # the boxes shadow some
