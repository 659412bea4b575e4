"""Per-point probe weights of the baked indirect light (viewer/probes/weights.py): what a surface point
may take from the probe lattice, and the bake that sums it once per GI update."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import box, lit_room

from viewer.rays import dda
from viewer.rays.cast import TriangleCaster, embree_available
from viewer.probes import moved_weights
from viewer.probes import weights as probe_weights
from viewer.physical.geometry import voxelize_with_faces
from viewer.probes.weights import CORNERS, SurfaceBake, SurfaceWeights
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene, load


def cells_of(scene: Scene) -> dda.Cells:
    return dda.Cells.of(voxelize_with_faces(scene, 32), scene)


def random_probes(scene: Scene, m: int, seed: int = 0, valid_fraction: float = 1.0) -> ProbeGrid:
    rng = np.random.default_rng(seed)
    c = 0.2 * rng.standard_normal((m, m, m, 9, 3)).astype(np.float32)
    c[..., 0, :] = 1.0 + rng.random((m, m, m, 3))
    lo, hi = scene.bounds
    return ProbeGrid(lo, hi, c, rng.random((m, m, m)) < valid_fraction)


def surface_points(scene: Scene, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """`count` points spread uniformly over random faces of `scene` (of an area), and their faces."""
    rng = np.random.default_rng(seed)
    face = rng.choice(np.flatnonzero(scene.face_areas > 0), count)
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    tri = scene.triangles[face]
    return tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0]), face


def partitioned_room() -> Scene:
    """A closed room (half size 1) split at x = 0.02 by a thin two-sided wall that reaches every side."""
    wall = np.array([[0.02, -1, -1], [0.02, 1, -1], [0.02, 1, 1], [0.02, -1, 1]], np.float64)
    partition = Scene("partition", wall, np.array([[0, 1, 2], [0, 2, 3]]), 0.5, 0.0, 0, ("partition",))
    return Scene.concatenate("partitioned", [box(inward=True, albedo=0.5, name="room"), partition])


def test_a_face_never_takes_light_from_probes_behind_a_thin_wall():
    """Points on the floor just left of a partition, between two probe layers: the probes of their
    lattice cell on the far side of the wall are in front of the floor, within a probe spacing (the
    lattice alone gives them a third of the light and more), but the wall hides them: no weight. The
    weights still sum to 1; without the visibility term those probes would count."""
    scene = partitioned_room()
    probes = random_probes(scene, 8)                     # layers at x = -0.125 and 0.125 around the wall
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(-0.1, 0.0, 200), np.full(200, -0.999999), rng.uniform(-0.9, 0.9, 200)])
    normals = np.tile([0.0, 1.0, 0.0], (200, 1))
    weights = SurfaceWeights.of(points, normals, probes, cells_of(scene), normal_offset=0.0)
    corner_x = probes.lo[0] + (weights.base[:, None, 0] + CORNERS[None, :, 0] + 0.5) * probes.spacing[0]
    across = corner_x > 0.02
    assert across.sum(axis=1).min() == 4
    np.testing.assert_allclose(weights.weights.sum(axis=1), 1.0, rtol=1e-5)
    assert weights.weights[across].max() == 0.0
    open_room = SurfaceWeights.of(points, normals, probes, cells_of(box(inward=True, albedo=0.5)), normal_offset=0.0)
    assert open_room.weights[across].reshape(200, 4).sum(axis=1).mean() > 0.2


def test_a_point_that_sees_none_of_its_probes_gets_no_light():
    """The ceiling right above the Cornell box's lamp (hung 1 cm below it): every probe of its cell is
    behind the lamp or behind the ceiling, so it is dark, as in Mitsuba, rather than lit by probes that
    cannot reach it (a bright rim around the lamp before); a point on the open ceiling is lit."""
    scene = load("cornell")
    probes = random_probes(scene, 24)
    points = np.array([[0.0, 0.9999, 0.0], [0.0, 0.9999, 0.6]])
    normals = np.tile([0.0, -1.0, 0.0], (2, 1))
    weights = SurfaceWeights.of(points, normals, probes, cells_of(scene))
    assert weights.weights[0].sum() == 0.0
    assert weights.weights[1].sum() == pytest.approx(1.0, rel=1e-5)
    light = SurfaceBake.of(weights, np.zeros(2, np.int64), normals[:1]).irradiance(probes.coefficients)
    assert light[0].max() == 0.0 and light[1].min() > 0.0


def test_weights_are_trilinear_in_open_space_facing_all_probes():
    """Away from any surface but the one shaded, with every probe in front and valid, the weights are
    the trilinear weights times DDGI's back-face term, renormalized."""
    scene = box(inward=True, albedo=0.5, name="room")
    probes = random_probes(scene, 6)
    point, normal = np.array([[0.05, -0.999999, 0.1]]), np.array([[0.0, 1.0, 0.0]])   # on the floor
    w = SurfaceWeights.of(point, normal, probes, cells_of(scene), normal_offset=0.0)
    u = np.clip((point[0] - probes.lo) / probes.spacing - 0.5, 0, 5)
    f = u - np.floor(u)
    trilinear = np.prod(np.where(CORNERS.astype(bool), f, 1 - f), axis=1)
    position = probes.lo + (w.base[0] + CORNERS + 0.5) * probes.spacing
    toward = position - point[0]
    cosine = toward @ normal[0] / np.linalg.norm(toward, axis=1)
    expected = trilinear * (((cosine + 1) / 2) ** 2 + probe_weights.BACKFACE_FLOOR)
    np.testing.assert_allclose(w.weights[0], expected / expected.sum(), rtol=1e-5)


def test_the_bake_sums_the_same_light_as_the_weights():
    """SurfaceBake (per (probe, normal) pair, then 8 pairs a point) equals the direct sum over the 8
    probes' SH; each pair is numbered once."""
    scene = lit_room(box(0.3, (0.2, -0.7, 0.1), name="crate"))
    probes = random_probes(scene, 10, valid_fraction=0.8)
    points, face = surface_points(scene, 500, seed=4)
    normals, normal_id = np.unique(scene.face_normals[face], axis=0, return_inverse=True)
    weights = SurfaceWeights.of(points, normals[normal_id], probes, cells_of(scene))
    bake = SurfaceBake.of(weights, normal_id, normals)
    np.testing.assert_allclose(bake.irradiance(probes.coefficients), weights.irradiance(probes, normals[normal_id]),
                               rtol=1e-4, atol=1e-5)
    pairs = np.column_stack([bake.pair_probe, bake.pair_normal])
    assert len(np.unique(pairs, axis=0)) == len(pairs)


@pytest.mark.skipif(not embree_available(), reason="needs Embree")
def test_weights_in_one_compiled_pass_are_those_of_the_segment_arrays():
    """With Embree called from compiled loops the weights are made point by point, their segments queried
    as they are made (`_weighed`); the casters that take arrays of segments get the same weights, bit for
    bit: here the same Embree scene through its array query."""
    scene = lit_room(box(0.3, (0.2, -0.7, 0.1), name="crate"), partitioned_room())
    probes = random_probes(scene, 7, valid_fraction=0.8)
    points, face = surface_points(scene, 20000, seed=5)
    sides = np.where(np.random.default_rng(6).random(20000) < 0.5, 1.0, -1.0)
    normals = scene.face_normals[face] * sides[:, None]   # both sides
    caster = TriangleCaster(scene)
    assert caster.direct is not None

    class Segments(TriangleCaster):   # the same scene, queried through arrays of segments
        direct = None

    arrays = Segments.__new__(Segments)
    arrays.__dict__.update(caster.__dict__)
    one_pass = SurfaceWeights.of(points, normals, probes, caster)
    by_arrays = SurfaceWeights.of(points, normals, probes, arrays)
    np.testing.assert_array_equal(one_pass.base, by_arrays.base)
    np.testing.assert_array_equal(one_pass.weights, by_arrays.weights)
    assert 0 < (one_pass.weights == 0).mean() < 0.9   # the walls hide some probes, not all


def test_coarse_points_share_rounded_lobe_normals_and_the_others_keep_theirs():
    """`lobe_normals`: the coarse points' normals rounded to 1/32 per component and made unit (a
    scanned mesh's tens of thousands become fewer than half), the others' exactly as they were; the
    irradiance a lobe takes from an L2 probe moves by under 3% of the probe's light."""
    from viewer.probes import sh

    rng = np.random.default_rng(2)
    normals = rng.normal(size=(40000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normal_id = rng.integers(0, len(normals), 100000)
    coarse = rng.random(len(normal_id)) < 0.7
    ids, table = probe_weights.lobe_normals(normals, normal_id, coarse)
    np.testing.assert_array_equal(table[ids[~coarse]], normals[normal_id[~coarse]])
    np.testing.assert_allclose(np.linalg.norm(table, axis=1), 1.0, rtol=1e-12)
    rounded = table[ids[coarse]]
    assert np.all(np.einsum("ij,ij->i", rounded, normals[normal_id[coarse]]) > np.cos(np.radians(2.0)))
    assert len(np.unique(ids[coarse])) < 0.5 * len(np.unique(normal_id[coarse]))
    assert len(table) <= len(np.unique(normal_id[~coarse])) + len(np.unique(ids[coarse]))   # no unused rows
    probe = rng.normal(size=(9, 3)) * 0.3
    probe[0] = 2.0                                     # a probe's light: mostly its mean
    light = lambda n: (sh.basis(n) * sh.COSINE_LOBE) @ probe
    change = np.abs(light(rounded) - light(normals[normal_id[coarse]])) / np.abs(light(normals)).mean()
    assert change.max() < 0.03
    same_ids, same = probe_weights.lobe_normals(normals, normal_id, np.zeros(len(normal_id), bool))
    assert same is normals and np.array_equal(same_ids, normal_id)


@pytest.mark.skipif(not embree_available(), reason="the weights after a move are kept for Embree's casters")
def test_weights_after_a_move_are_those_of_weighing_every_point():
    """The Cornell box's small box moved and a few probes turned invalid: the points that moved, those
    whose segments can meet the box's old or new place and those next to a probe that changed are
    weighed again, a minority, and every point's weights are those that weighing all of them gives."""
    from dataclasses import replace

    scene = load("cornell")
    vertices = scene.vertices.copy()
    box_faces = scene.face_group == scene.groups.index("small-box")
    vertices[np.unique(scene.faces[box_faces])] += [0.06, 0.0, -0.04]
    moved = replace(scene, vertices=vertices)
    points, face = surface_points(scene, 6000, seed=4)
    after = points.copy()
    on_box = box_faces[face]
    after[on_box] += [0.06, 0.0, -0.04]
    normals = scene.face_normals[face]
    probes = random_probes(scene, 12, seed=1, valid_fraction=0.97)
    valid = probes.valid.copy()
    valid[2, 3, 4], valid[9, 1, 5] = ~valid[2, 3, 4], ~valid[9, 1, 5]
    flipped = replace(probes, valid=valid)
    caster, moved_caster = TriangleCaster(scene), TriangleCaster(moved)
    before = moved_weights.Weighed.of(points, normals, probes, caster)
    box = moved_weights.moved_box(caster, moved_caster)
    kept = moved_weights.after_moving(before, after, normals, flipped, moved_caster, box)
    fresh = SurfaceWeights.of(after, normals, flipped, moved_caster)
    assert on_box.sum() < kept.weighed < 0.5 * len(points)
    np.testing.assert_array_equal(kept.weights.base, fresh.base)
    np.testing.assert_array_equal(kept.weights.weights, fresh.weights)
    nothing = moved_weights.moved_box(moved_caster, moved_caster)
    again = moved_weights.after_moving(kept, after, normals, flipped, moved_caster, nothing)
    assert again.weighed == 0
