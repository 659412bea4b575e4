"""Embree called from compiled loops (viewer/rays/embree.py) gives embreex's own answers, bit for bit, on
every core and without Python's lock; where it cannot load, the caster uses embreex's binding. And the order
that parallel loops take their items in (`spread`)."""

import threading
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from viewer.rays import cast, embree
from viewer.scene import load

needs_embree = pytest.mark.skipif(not embree.available(), reason="Embree cannot be called directly here")


def cornell_with_sphere() -> np.ndarray:
    """The Cornell box's triangles and a 1,280-face sphere's: many shared edges for rays to slip through."""
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    return np.concatenate([np.asarray(load("cornell").triangles, np.float32),
                           np.asarray(sphere.triangles + [0.2, 0.4, 0.1], np.float32)])


def rays(triangles: np.ndarray, count: int, seed: int = 5):
    rng = np.random.default_rng(seed)
    corners = triangles.reshape(-1, 3)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    origins = lo + (hi - lo) * rng.uniform(0.01, 0.99, (count, 3))
    directions = rng.normal(size=(count, 3))
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def embreex_scene(triangles):
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(triangles))
    return scene


@needs_embree
def test_closest_hits_are_embreex_own_bit_for_bit():
    """The same face, distance and barycentrics as embreex's `run` for every ray that meets a face, and
    the same misses, on rays through a sphere's 1,280 faces and the box around it."""
    triangles = cornell_with_sphere()
    origins, directions = rays(triangles, 200_000)
    primitive, t, u, v = embree.Scene(triangles).closest(origins, directions, 1e37)
    theirs = embreex_scene(triangles).run(origins.astype(np.float32), directions.astype(np.float32),
                                          dists=np.float32(1e37), output=1)
    hit = theirs["primID"].astype(np.int64) >= 0
    assert 0.5 < hit.mean() < 1.0                    # both outcomes are tested
    np.testing.assert_array_equal(np.where(hit, theirs["primID"].astype(np.int64), -1), primitive)
    for ours, name in ((t, "tfar"), (u, "u"), (v, "v")):
        np.testing.assert_array_equal(ours[hit].astype(np.float32), theirs[name][hit])
    assert np.all(np.isinf(t[~hit]))


@needs_embree
def test_a_hierarchy_left_to_choose_is_built_quickly_only_when_large(monkeypatch):
    """`quick=None`: Embree's low build quality above QUICK_FACES triangles (its build is the cost there),
    the default below (its rays are); either way the same hits where no two faces tie."""
    triangles = cornell_with_sphere()
    origins, directions = rays(triangles, 20_000)
    small = embree.Hierarchy(triangles, quick=None)
    monkeypatch.setattr(embree, "QUICK_FACES", len(triangles) - 1)
    large = embree.Hierarchy(triangles, quick=None)
    assert not small.quick and large.quick
    for a, b in zip(embree.Scene(small).closest(origins, directions, 1e37),
                    embree.Scene(large).closest(origins, directions, 1e37)):
        np.testing.assert_array_equal(a, b)


@needs_embree
def test_a_segment_is_blocked_where_embreex_says_so():
    triangles = cornell_with_sphere()
    origins, directions = rays(triangles, 100_000, seed=6)
    lengths = np.random.default_rng(7).uniform(0.0, 2.0, len(origins))
    ours = embree.Scene(triangles).occluded(origins, directions, lengths)
    theirs = embreex_scene(triangles).run(origins.astype(np.float32), directions.astype(np.float32),
                                          dists=lengths.astype(np.float32), query="OCCLUDED") >= 0
    assert 0.2 < ours.mean() < 0.8
    np.testing.assert_array_equal(ours, theirs)


@needs_embree
def test_two_threads_tracing_at_once_get_what_each_gets_alone():
    """Queries on one scene from two threads (the GI source's trace beside the final gather) answer as
    each does alone."""
    triangles = cornell_with_sphere()
    scene = embree.Scene(triangles)
    sets = [rays(triangles, 50_000, seed) for seed in (8, 9)]
    alone = [scene.closest(o, d, 1e37)[0] for o, d in sets]
    together = [None, None]

    def trace(k):
        for _ in range(3):
            together[k] = scene.closest(*sets[k], 1e37)[0]

    threads = [threading.Thread(target=trace, args=(k,)) for k in (0, 1)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for a, b in zip(alone, together):
        np.testing.assert_array_equal(a, b)


@needs_embree
def test_the_caster_falls_back_to_embreex_with_the_same_hits(monkeypatch):
    """Where the library cannot be called directly the caster uses embreex's binding: the same hits."""
    scene = load("cornell")
    origins, directions = rays(np.asarray(scene.triangles, np.float32), 20_000, seed=10)
    direct = cast.TriangleCaster(scene)
    assert direct.direct is not None
    assert cast.TriangleCaster(scene, backend="embreex").direct is None    # asked for: embreex's binding
    monkeypatch.setattr(embree, "available", lambda: False)
    bound = cast.TriangleCaster(scene)
    assert bound.backend == "embree" and bound.direct is None
    a, b = direct.closest_hits(origins, directions), bound.closest_hits(origins, directions)
    np.testing.assert_array_equal(a.face, b.face)
    hit = a.face >= 0
    for name in ("t", "u", "v"):
        np.testing.assert_array_equal(getattr(a, name)[hit], getattr(b, name)[hit])
    np.testing.assert_array_equal(a.front, b.front)
    lengths = np.full(len(origins), 0.7)
    np.testing.assert_array_equal(direct.blocked(origins, directions, lengths),
                                  bound.blocked(origins, directions, lengths))


@pytest.mark.parametrize("count", [0, 1, 511, 512, 513, 5000])
def test_spread_visits_every_item_once_in_runs_of_neighbours(count):
    """`spread` is a permutation of range(count) made of runs of `RUN` consecutive items (the last run
    shorter), the runs out of order: a parallel loop's shares then mix cheap and costly items."""
    order = embree.spread(count)
    np.testing.assert_array_equal(np.sort(order), np.arange(count))
    runs = np.split(order, np.flatnonzero(np.diff(order) != 1) + 1) if count else []
    for run in runs:   # whole runs (two that follow each other in order would merge here)
        assert run[0] % embree.RUN == 0 and (len(run) % embree.RUN == 0 or run[-1] == count - 1)
    if count > 4 * embree.RUN:
        assert len(runs) > 1


def moved(scene, name: str, offset):
    """`scene` with the group `name` moved by `offset`."""
    vertices = scene.vertices.copy()
    group = scene.groups.index(name)
    corners = np.unique(scene.faces[scene.face_group == group])
    vertices[corners] += offset
    return replace(scene, vertices=vertices)


@needs_embree
@pytest.mark.parametrize("group", ["light", "small-box"])
def test_a_caster_made_after_a_move_answers_as_a_fresh_one(group, monkeypatch):
    """A caster made from the previous one after a lamp or a box moved builds the moved faces apart (the
    rest keeps its hierarchy) and meets the same faces at the same distances, barycentrics and sides as
    a caster made afresh, through Python and from compiled loops; the next move of the same faces keeps
    the same hierarchy of the others, and of the moved faces too, moved by the translation (the same
    faces and sides, distances and barycentrics to float32 round-off), and a move of most faces builds
    one hierarchy again. (A box room's faces are too few to part: one hierarchy of them is quicker.)"""
    from viewer.rays import dda
    from viewer.rays.voxel_rays import VoxelRays
    from viewer.rays.voxels import voxelize_with_faces

    scene = load("cornell")
    assert cast.TriangleCaster(moved(scene, group, [0.05, 0, 0]), previous=cast.TriangleCaster(scene))._stayed is None
    monkeypatch.setattr(cast, "PARTED_FACES", 10)   # a box room's faces are too few to part: as if a scan's
    first = cast.TriangleCaster(scene)
    once = moved(scene, group, [0.05, -0.02, 0.03])
    again = moved(once, group, [-0.1, 0.0, 0.02])
    step = cast.TriangleCaster(once, previous=first)
    assert step._stayed is not None and len(step.faces) == len(first.faces)
    after = cast.TriangleCaster(again, previous=step)
    assert after._stayed is step._stayed
    assert after._went.hierarchy is step._went.hierarchy and step._went.shift is None
    np.testing.assert_allclose(after._went.shift, [-0.1, 0.0, 0.02], atol=1e-6)
    fresh = cast.TriangleCaster(again)
    origins, directions = rays(np.asarray(again.triangles, np.float32), 20000)
    ours, theirs = after.closest_hits(origins, directions), fresh.closest_hits(origins, directions)
    assert np.mean(theirs.face >= 0) > 0.8   # the box is open at the front
    assert np.isin(theirs.face, np.flatnonzero(again.face_group == again.groups.index(group))).sum() > 20
    for field in ("face", "front"):
        np.testing.assert_array_equal(getattr(ours, field), getattr(theirs, field))
    hit = theirs.face >= 0
    for field in ("t", "u", "v"):
        np.testing.assert_allclose(getattr(ours, field)[hit], getattr(theirs, field)[hit], rtol=1e-5, atol=1e-5)
    normals, points = directions[:500], origins[:500] + directions[:500] * np.linspace(0, 3, 500)[:, None]
    outward = fresh.nothing_ahead(points, normals, 1e-3)
    assert 0 < outward.sum() < len(points)
    np.testing.assert_array_equal(after.nothing_ahead(points, normals, 1e-3), outward)
    lengths = np.random.default_rng(2).uniform(0.05, 1.5, len(origins))
    np.testing.assert_array_equal(after.blocked(origins, directions, lengths),
                                  fresh.blocked(origins, directions, lengths))
    voxelization = voxelize_with_faces(again, 16)
    grid, cells = voxelization.grid, dda.Cells.of(voxelization, again)
    compiled = VoxelRays(again, cells, caster=after).bundle_hits(grid.position[:200], directions[:32])
    np.testing.assert_array_equal(compiled, VoxelRays(again, cells, caster=fresh).bundle_hits(grid.position[:200],
                                                                                              directions[:32]))
    scaled = again.vertices.copy()
    moving = np.unique(again.faces[again.face_group == again.groups.index(group)])
    scaled[moving] = scaled[moving] * 1.01   # not a translation: built again
    assert cast.TriangleCaster(replace(again, vertices=scaled), previous=after)._went.hierarchy is not step._went.hierarchy
    everything = scene.vertices + [0.01, 0.0, 0.0]
    assert cast.TriangleCaster(replace(again, vertices=everything), previous=after)._stayed is None
