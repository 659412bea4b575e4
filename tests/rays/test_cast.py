"""The ray-casting layer (viewer/rays/cast.py): Embree and the DDA meet the same faces at the same
points from the same sides, and the DDA answers where embreex is missing."""

from types import SimpleNamespace

import numpy as np
import pytest

from viewer.rays import cast, moved_faces
from viewer.rays.moved_faces import changed_rows
from viewer.scene import load
from scenes import box

needs_embree = pytest.mark.skipif(not cast.embree_available(), reason="embreex is not installed")


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def cornell_rays(count: int, seed: int = 3):
    """Rays in every direction from points in the Cornell box's free space above both boxes."""
    rng = np.random.default_rng(seed)
    origins = np.column_stack([rng.uniform(-0.95, 0.95, count), rng.uniform(0.25, 0.95, count),
                               rng.uniform(-0.95, 0.95, count)])
    return origins, unit(rng.normal(size=(count, 3)))


@needs_embree
def test_both_backends_meet_the_same_face_at_the_same_point_in_the_cornell_box():
    """Away from the edges (a ray through a shared edge may name either face), Embree (float32) and the
    DDA (float64) agree on the face, the side, the distance and the barycentrics to float32's precision;
    the rays out of the open front meet nothing in both."""
    scene = load("cornell")
    origins, directions = cornell_rays(20000)
    embree = cast.closest_hits(scene, origins, directions, backend="embree")
    marched = cast.closest_hits(scene, origins, directions, backend="dda")
    np.testing.assert_array_equal(embree.face < 0, marched.face < 0)
    assert 0.1 < (embree.face < 0).mean() < 0.4                        # the open front
    edge = np.minimum(np.minimum(marched.u, marched.v), 1.0 - marched.u - marched.v)
    inside = (marched.face >= 0) & (edge > 1e-4)
    assert inside.sum() > 0.99 * (marched.face >= 0).sum()
    np.testing.assert_array_equal(embree.face[inside], marched.face[inside])
    np.testing.assert_array_equal(embree.front[inside], marched.front[inside])
    np.testing.assert_allclose(embree.t[inside], marched.t[inside], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(embree.u[inside], marched.u[inside], atol=1e-5)
    np.testing.assert_allclose(embree.v[inside], marched.v[inside], atol=1e-5)
    points = origins + marched.t[:, None] * directions
    corners = scene.triangles[marched.face[inside]]
    on_face = corners[:, 0] + marched.u[inside, None] * (corners[:, 1] - corners[:, 0]) \
        + marched.v[inside, None] * (corners[:, 2] - corners[:, 0])
    np.testing.assert_allclose(on_face, points[inside], atol=1e-9)     # the barycentrics name the hit point


@pytest.mark.parametrize("backend", [pytest.param("embree", marks=needs_embree), "dda"])
def test_a_ray_from_inside_a_solid_meets_a_back_and_a_short_ray_meets_nothing(backend):
    """From inside an outward-facing cube every ray meets the back of the face ahead, at the distance
    to its plane; a ray shorter than that distance meets nothing."""
    cube = box(half_size=0.5)
    directions = unit(np.array([[1.0, 0.1, 0.05], [0.0, -1.0, 0.0], [0.2, 0.3, 1.0]]))
    origins = np.zeros((3, 3))
    hits = cast.closest_hits(cube, origins, directions, backend=backend)
    assert (hits.face >= 0).all() and not hits.front.any()
    normals = cube.face_normals[hits.face]
    np.testing.assert_allclose(hits.t, 0.5 / np.einsum("ij,ij->i", normals, directions), rtol=1e-6)
    short = cast.closest_hits(cube, origins, directions, t_max=0.45, backend=backend)
    assert (short.face == cast.NO_FACE).all() and np.isinf(short.t).all()
    outside = cast.closest_hits(cube, np.array([[0.0, 0.0, -2.0]]), np.array([[0.0, 0.0, 1.0]]), backend=backend)
    assert outside.front[0] and outside.t[0] == pytest.approx(1.5, rel=1e-6)


def test_without_embreex_the_dda_answers(monkeypatch):
    """Where embreex does not import, the caster is the DDA's, and asking for Embree says why it cannot."""
    monkeypatch.setattr(cast, "rtcore_scene", None)
    assert not cast.embree_available()
    assert cast.TriangleCaster(box(inward=True)).backend == "dda"
    with pytest.raises(ValueError, match="embreex"):
        cast.TriangleCaster(box(inward=True), backend="embree")


@pytest.mark.parametrize("backend", [pytest.param("embree", marks=needs_embree), "dda"])
def test_a_segment_is_blocked_where_the_closest_hit_lies_within_it(backend):
    """The occlusion query (the probes' visibility) says blocked exactly where the closest hit is nearer
    than the segment's end, in the Cornell box (segments ending well away from any face)."""
    scene = load("cornell")
    origins, directions = cornell_rays(5000, seed=4)
    caster = cast.TriangleCaster(scene, backend=backend)
    t = caster.closest_hits(origins, directions).t
    lengths = np.random.default_rng(5).uniform(0.05, 2.5, len(origins))
    clear_of_ends = np.abs(t - lengths) > 1e-3
    blocked = caster.blocked(origins, directions, lengths)
    np.testing.assert_array_equal(blocked[clear_of_ends], (t <= lengths)[clear_of_ends])
    assert 0.2 < blocked.mean() < 0.8


def test_distinct_rows_group_rows_as_numpys_unique_does():
    """The same groups and first occurrences as np.unique(axis=0), for float normals, integer keys, and
    rows whose keys collide without being equal (which go through np.unique)."""
    rng = np.random.default_rng(8)
    normals = unit(rng.normal(size=(40, 3)))[rng.integers(0, 40, 5000)]
    keys = rng.integers(-50, 50, (6000, 6))[rng.integers(0, 300, 6000)]
    colliding = np.array([[np.sqrt(3.0), 0.0], [0.0, np.sqrt(2.0)], [np.sqrt(3.0), 0.0]])  # equal dot products
    for rows in (normals, keys, colliding):
        first, inverse = cast.distinct_rows(rows)
        _, their_first, theirs = np.unique(rows, axis=0, return_index=True, return_inverse=True)
        np.testing.assert_array_equal(np.sort(first), np.sort(their_first))
        np.testing.assert_array_equal(rows[first][inverse], rows)        # each row's group holds it
        assert len(first) == len(their_first)


def test_changed_rows_are_the_rows_numpy_finds_different():
    """`changed_rows` names the rows where any pair of arrays differs, as numpy's comparison does, and
    one array passed twice changes nothing."""
    rng = np.random.default_rng(7)
    a = rng.random((500, 3, 3))
    b, c = a.copy(), rng.random((500, 4))
    b[[3, 77, 499], 2, 1] += 1e-12
    d = c.copy()
    d[[10, 77], 0] = -1.0
    expected = np.any(a != b, axis=(1, 2)) | np.any(c != d, axis=1)
    np.testing.assert_array_equal(changed_rows((a, b), (c, d)), expected)
    assert set(np.flatnonzero(expected)) == {3, 10, 77, 499}
    assert not changed_rows((a, a), (c, c.copy())).any()
    for array in (a, b, c, d):
        array.setflags(write=False)
    first = changed_rows((a, b), (c, d))
    assert changed_rows((a, b), (c, d)) is first and not first.flags.writeable   # kept for the same arrays
    assert changed_rows((b, a), (c, d)) is not first                            # asked of others: made again
    np.testing.assert_array_equal(changed_rows((a, b), (c, d.copy())), expected)
    same, base = a.copy(), c.copy()
    same.setflags(write=False)
    view = base[:]
    view.setflags(write=False)                   # read-only, but its base is not: never kept
    assert not changed_rows((a, same), (c, view)).any()
    base[3, 0] = -5.0
    assert np.flatnonzero(changed_rows((a, same), (c, view))).tolist() == [3]


def test_the_moved_box_holds_every_corner_of_the_moved_faces_before_and_after():
    """`moved_box` is the box of the moved faces' corners, where they were and where they are, a
    millionth wider: no other face's corner widens it."""
    rng = np.random.default_rng(11)
    v0, e1, e2 = (rng.normal(size=(300, 3)) for _ in range(3))
    before = SimpleNamespace(v0=v0, e1=e1, e2=e2)
    after = SimpleNamespace(v0=v0.copy(), e1=e1, e2=e2.copy())
    after.v0[[5, 200]] += [40.0, -3.0, 0.5]
    after.e2[7] *= 30.0
    moved, box = moved_faces.moved_box(before, after)
    assert moved.tolist() == [5, 7, 200]
    corners = np.concatenate([np.concatenate([c.v0[moved], c.v0[moved] + c.e1[moved], c.v0[moved] + c.e2[moved]])
                              for c in (before, after)])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    margin = 1e-6 * (hi - lo).max()
    np.testing.assert_allclose(box, [lo - margin, hi + margin], rtol=0, atol=1e-12)
    assert moved_faces.moved_box(before, before)[1] is None
    assert moved_faces.moved_box(before, after, most=0.005) is None   # 3 of 300 moved: more than half a percent
