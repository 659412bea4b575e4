"""The incremental encoder after a moved object (viewer.neural.encoder): what misses the box around the
moved triangles' old and new places keeps its answer (the probes' and the voxels' shadow rays, the
voxels' lamp light, the seen rays' voxels), the rest is traced again, and every answer is the one a
fresh encoding gives."""

from dataclasses import replace

import numpy as np
import pytest

from encoded import VOXELS, assert_same_encoding, encoded, lamp, moved
from scenes import box
from viewer.neural import encoding
from viewer.neural.encoder import Encoder
from viewer.scene import DirectionalLight, Scene, load
from viewer.rays.lattice_sight import SWEEP_ENDS
from viewer.rays.voxels import voxelize


def test_moving_an_object_recomputes_the_shadows():
    """Moved triangles cast other shadows: the lamp's basis is summed again at the probes whose shadow
    rows changed (the emitter kept, most of its probes as they were), the sun's visibility found again,
    though no emitting patch moved: the encoding of the moved scene."""
    scene = load("cornell").with_sun(DirectionalLight((-0.3, 0.4, 1.0), (2.0, 1.8, 1.5)))
    encoder = Encoder(*scene.bounds, 16)
    voxels, blockers, _ = encoded(scene)
    encoder.encode(voxels, scene.sun, blockers)
    before = [(e, e.basis) for e in encoder.emitters]
    shifted = moved(scene, "large-box", (0.15, 0.0, -0.1))
    voxels, blockers, reference = encoded(shifted)
    ours = encoder.encode(voxels, shifted.sun, blockers)
    assert {"shadows", "emitters", "sun"} <= set(encoder.recomputed)
    assert [e for e, _ in before] == encoder.emitters
    differs = np.any(encoder.emitters[0].basis != before[0][1], axis=0)
    assert 0 < differs.mean() < 0.5
    assert np.all(encoder.revisions == 2)
    assert_same_encoding(ours, reference)


def test_a_drag_in_steps_through_a_swept_sunlit_room_gives_encode_s_numbers_at_every_step():
    """A block dragged in four steps and back under a large panel (its probes' shadows swept), the sun
    coming in through the room's open side: each step is made from the one before (the voxels' shadows
    and sun kept where they miss the box, the sweep settled again where it can change, the seen rays'
    voxels renumbered), and each gives `encoding.encode`'s numbers, however many steps the kept answers
    came through. (The block floats: where two coplanar faces meet a ray at one distance, a box's base
    on a floor, Embree's choice between them follows the hierarchy the drag's history built.)"""
    pytest.importorskip("embreex")
    room = box(inward=True, name="room")
    closed = ~np.all(room.vertices[room.faces][:, :, 2] > 0.99, axis=1)   # the +z wall left open
    room = Scene("room", room.vertices, room.faces[closed], 0.5, 0.0, 0, ("room",))
    scene = Scene.concatenate("sunlit", [room, lamp("panel", 0.0, 0.0, (3.0, 3.0, 2.5), 0.7),
                                         box(0.25, (0.0, -0.5, 0.0), name="block")])
    scene = scene.with_sun(DirectionalLight((0.2, 0.5, 1.0), (2.0, 1.8, 1.5)))
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 16)
    steps = [scene] + [moved(scene, "block", (0.06 * k, 0.0, -0.05 * k)) for k in (1, 2, 3, 4)] + [scene]
    for k, step in enumerate(steps):
        voxels, blockers, reference = encoded(step)
        assert_same_encoding(encoder.encode(voxels, step.sun, blockers), reference)
        assert encoder._shadows.sweeping
        assert np.any(encoder._voxel_shadows.sun_visibility(np.asarray(step.sun.direction, np.float64)) > 0)
        if k:
            assert encoder._voxel_shadows._match is not None and encoder._seen.traced < encoder._seen.voxel.size


@pytest.mark.parametrize("backend, count", [("embree", 3), ("dda", 3), ("embree", SWEEP_ENDS)])
def test_a_moved_object_retraces_only_the_shadow_rays_through_its_old_and_new_places(backend, count):
    """After a move, the shadows made from the previous ones trace again only the rays that meet the box
    around the moved triangles' old and new places, and give every ray, kept or traced, the answer of
    shadows traced afresh; a moved lamp's new ray ends are traced in full (with Embree and SWEEP_ENDS ends
    or more, swept over the lattice: `viewer.rays.lattice_sight`)."""
    from viewer.neural.lattice import LatticeShadows
    from viewer.probes.grid import ProbeGrid

    if backend == "embree":
        pytest.importorskip("embreex")
    scene = load("cornell")
    lo, hi = scene.bounds
    points = ProbeGrid.positions_for(lo, hi, 16).reshape(-1, 3)
    spacing = (hi - lo) / 16
    ends = np.array([[0.0, 0.54, 0.0], [0.1, 0.54, -0.1], [-0.2, 0.3, 0.25]])
    if count > len(ends):   # enough ends to sweep the lattice (with Embree)
        u = np.linspace(-0.2, 0.2, 5)
        ends = np.concatenate([ends, np.stack(np.meshgrid(u, [0.5], u), -1).reshape(-1, 3)])[:count]
    sun = np.array([-0.3, 0.4, 1.0])

    def shadows(scene, previous=None):
        voxels = voxelize(scene, VOXELS)
        return LatticeShadows(encoding.Occluders(scene, voxels, backend), points, lo, spacing, previous)

    before = shadows(scene)
    before.visibility(ends)
    before.sun_visibility(sun)
    shifted = moved(scene, "small-box", (0.1, 0.0, 0.1))
    after = shadows(shifted, before)
    fresh = shadows(shifted)
    visible = after.visibility(ends)
    assert 0 < after.retraced < 0.5 * visible.size
    assert np.array_equal(visible, fresh.visibility(ends))
    assert np.array_equal(after.sun_visibility(sun), fresh.sun_visibility(sun))
    assert not np.array_equal(visible, before.visibility(ends))      # the box's shadow did move
    new_end = ends + [0.05, 0.0, 0.0]
    assert np.array_equal(after.visibility(new_end), fresh.visibility(new_end))
    assert after.retraced == fresh.retraced   # new ends: every segment a fresh sweep traces (all, without one)
    assert (after.retraced < 0.2 * visible.size) == (count >= SWEEP_ENDS)


@pytest.mark.parametrize("name, group", [("cornell", "small-box"), ("paper-test", "large-box")])
def test_a_moved_object_keeps_the_voxels_shadow_rays_that_miss_its_box(name, group):
    """The shadows of the voxels' surfaces after a move, made from the previous voxels' ones: a voxel with
    the same surface in the same cell keeps its rays' answers (lamp and sun) where they miss the box
    around the moved triangles, the others are traced; every answer is that of shadows traced afresh."""
    from viewer.neural.changes import same_voxels
    from viewer.neural.lattice import LatticeShadows

    scene = load(name)
    lo, hi = scene.bounds
    spacing = (hi - lo) / 16
    ends = np.array([[0.0, 0.54, 0.0], [0.1, 0.54, -0.1], [-0.2, 0.3, 0.25]])
    sun = np.array([-0.3, 0.4, 1.0])

    def shadows(scene, previous=None):
        voxels = voxelize(scene, 32)
        return LatticeShadows(encoding.Occluders(scene, voxels, "embree"), encoding.surface_points(voxels), lo,
                              spacing, previous, across=voxels)

    before = shadows(scene)
    before.visibility(ends)
    before.sun_visibility(sun)
    after = shadows(moved(scene, group, (0.1, 0.0, 0.1)), before)
    fresh = shadows(moved(scene, group, (0.1, 0.0, 0.1)))
    match = same_voxels(before.across, after.across)
    kept = match >= 0
    assert 0.5 < kept.mean() < 1.0      # the moved object's voxels and those it covers or uncovers are new
    assert np.array_equal(after.points[kept], before.points[match[kept]])
    visible = after.visibility(ends)
    assert np.array_equal(visible, fresh.visibility(ends))
    assert 0 < after.retraced < 0.5 * fresh.retraced
    assert np.array_equal(after.sun_visibility(sun), fresh.sun_visibility(sun))
    assert np.any(after.sun_visibility(sun) > 0)


@pytest.mark.parametrize("name, group", [("cornell", "small-box"), ("paper-test", "large-box")])
def test_a_moved_object_keeps_each_voxels_light_from_a_lamp_where_its_shadow_rays_kept_their_answer(
        name, group, monkeypatch):
    """A lamp's light at the voxels after a move: a voxel that kept its surface and its shadow rays'
    answers keeps its value, the others are summed again (the moved object's voxels, those it shades or
    no longer shades); every value is the one a fresh encoder sums."""
    scene = load(name)
    encoder = Encoder(*scene.bounds, 16)
    voxels, blockers, _ = encoded(scene)
    encoder.encode(voxels, None, blockers)
    shifted = moved(scene, group, (0.1, 0.0, 0.1))
    voxels, blockers, _ = encoded(shifted)
    summed = []
    original = encoding.emitter_irradiance_rows
    monkeypatch.setattr(encoding, "emitter_irradiance_rows",
                        lambda lights, points, *a: summed.append(len(points)) or original(lights, points, *a))
    encoder.encode(voxels, None, blockers)
    moved_sums, summed[:] = list(summed), []
    fresh = Encoder(*scene.bounds, 16)
    fresh.encode(voxels, None, blockers)
    assert len(encoder.emitters) == len(fresh.emitters) > 0
    for ours, theirs in zip(encoder.emitters, fresh.emitters):
        np.testing.assert_array_equal(ours.received, theirs.received)
    assert summed == [voxels.count] * len(fresh.emitters)
    assert len(moved_sums) == len(fresh.emitters) and 0 < sum(moved_sums) < 0.5 * sum(summed)


def test_voxels_are_matched_within_a_cell_by_their_surface():
    """A cell holds a voxel for each way its surfaces face, all under one hash id: each is matched to the
    one of the same surface, whatever their order within the cell."""
    from viewer.neural.changes import same_voxels

    voxels = voxelize(load("cornell"), 16)
    ids = voxels.hash_id
    assert np.any(ids[1:] == ids[:-1])          # cells of several voxels (the room's edges)
    assert np.array_equal(same_voxels(voxels, voxels), np.arange(voxels.count))
    order = np.lexsort((-np.arange(voxels.count), ids))   # reversed within each cell
    shuffled = replace(voxels, coords=voxels.coords[order], position=voxels.position[order],
                       normal=voxels.normal[order])
    assert np.array_equal(order[same_voxels(shuffled, voxels)], np.arange(voxels.count))
    changed = replace(voxels, position=voxels.position + [[0.0, 0.0, 1e-9]])
    assert np.all(same_voxels(changed, voxels) == -1)


@pytest.mark.parametrize("name, group, offset", [("cornell", "small-box", (0.1, 0.0, 0.1)),
                                                 ("cornell", "light", (0.2, 0.0, -0.15)),
                                                 ("paper-test", "large-box", (-0.05, 0.0, 0.1))])
def test_after_a_move_the_seen_rays_land_where_rays_cast_afresh_do(name, group, offset):
    """The seen rays after a move, made from the previous ones (only the rays through the moved
    triangles' box traced again, the others landed again on the new voxels), land on the voxels that
    rays cast afresh on the moved scene land on, every one of them."""
    pytest.importorskip("embreex")
    from viewer.neural.lattice import moved_box
    from viewer.probes.grid import ProbeGrid

    scene = load(name)
    points = ProbeGrid.positions_for(*scene.bounds, 16).reshape(-1, 3)

    def occluders(scene):
        voxels = voxelize(scene, VOXELS)
        return voxels, encoding.Occluders(scene, voxels, "embree")

    voxels, blockers = occluders(scene)
    voxels_before = voxels
    before = encoding.seen_rays(blockers, voxels, points)
    shifted = moved(scene, group, offset)
    voxels, after_blockers = occluders(shifted)
    after = encoding.seen_rays(after_blockers, voxels, points, before, moved_box(blockers, after_blockers))
    fresh = encoding.seen_rays(after_blockers, voxels, points)
    assert 0 < after.traced < len(fresh.voxel) and fresh.traced == len(fresh.voxel)
    (face, t, _), (fresh_face, fresh_t, _) = after._faces, fresh._faces
    assert np.array_equal(t, fresh_t)
    # Where two coplanar faces meet a ray at the same distance (a box's base on the floor), Embree's
    # choice between them follows its hierarchy, which the move rebuilt: either face is right there.
    same = (face == fresh_face).reshape(-1)
    assert same.mean() > 0.999
    assert np.array_equal(after.voxel[same], fresh.voxel[same])
    assert not np.array_equal(before.voxel, fresh.voxel)
    assert np.array_equal(after.links, fresh.links)   # the filter's links tested again only near the move
    # the kept rays' voxels taken from their old ones through the voxels that kept their surface: the ones
    # the lookup in the new listing finds
    from viewer.neural.seen import SeenRays
    looked_up = SeenRays(after_blockers.landing, voxels.count, points, previous=before,
                         box=moved_box(blockers, after_blockers))
    assert np.array_equal(after.voxel, looked_up.voxel) and np.array_equal(after.open, looked_up.open)
    # the previous rays' arrays updated in place, as the encoder drops them: the same rays, and the
    # previous ones cannot serve again
    again = encoding.seen_rays(blockers, voxels_before, points)
    reused = encoding.seen_rays(after_blockers, voxels, points, again, moved_box(blockers, after_blockers),
                                reuse=True)
    assert again._faces is None and again.voxel is None
    assert np.array_equal(reused.voxel, after.voxel) and np.array_equal(reused.open, after.open)
    assert all(np.array_equal(a, b) for a, b in zip(reused._faces, after._faces))
    assert reused.traced == after.traced
