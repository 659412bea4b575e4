"""The incremental encoder (viewer.neural.encoder): the numbers of `encoding.encode` on every scene and after
every kind of edit, shadows included, while recomputing only what the edit changed."""

from dataclasses import replace

import numpy as np
import pytest

from scenes import box, ceiling_lamp
from viewer.neural import encoding
from viewer.neural.encoder import Encoder
from viewer.scene import DirectionalLight, Scene, load
from viewer.evaluation.procedural import PRESETS, random_scene
from viewer.rays.lattice_sight import SWEEP_ENDS
from viewer.rays.voxels import voxelize

VOXELS = 16


def assert_same_encoding(ours: encoding.Encoding, reference: encoding.Encoding) -> None:
    """Equal to float32 round-off: the inputs are in units of each pass's scale, so an absolute 1e-5 is
    1e-5 of the field's scale (and 1e-5 relative next to a lamp, where they reach tens)."""
    assert ours.inputs.shape == reference.inputs.shape
    np.testing.assert_allclose(ours.scale, reference.scale, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(ours.inputs, reference.inputs, rtol=1e-5, atol=1e-5)


def encoded(scene: Scene, resolution: int = 16):
    """(voxels, occluders, `encoding.encode`'s reference) of `scene` over its bounds."""
    voxels = voxelize(scene, VOXELS)
    blockers = encoding.occluders(scene, voxels)
    lo, hi = scene.bounds
    return voxels, blockers, encoding.encode(voxels, scene.sun, lo, hi, resolution, blockers)


def moved(scene: Scene, group: str, offset) -> Scene:
    matrix = np.eye(4)
    matrix[:3, 3] = offset
    return scene.transformed_group(group, matrix)


def lamp_radiance(scene: Scene, group: str = "light") -> np.ndarray:
    return scene.emission[scene.face_group == scene.group_index(group)][0]


def edits(scene: Scene):
    """(what, edited scene) in sequence, each edit applied on top of the previous ones, as a user would."""
    light = lamp_radiance(scene)
    other = next(g for g in scene.groups if g != "light")
    out = [("intensity", scene.with_emission("light", 2.5 * light))]
    out.append(("colour", out[-1][1].with_emission("light", light * (0.4, 1.0, 1.7))))
    out.append(("albedo", out[-1][1].with_albedo(other, (0.9, 0.1, 0.3))))
    out.append(("albedo, one channel", out[-1][1].with_albedo(other, (0.9, 0.6, 0.3))))
    out.append(("lamp moved", moved(out[-1][1], "light", (0.2, 0.0, -0.15))))
    out.append(("lamp moved back", moved(out[-1][1], "light", (-0.2, 0.0, 0.15))))
    out.append(("object moved", moved(out[-1][1], "small-box", (0.1, 0.0, 0.1))))
    out.append(("sun", out[-1][1].with_sun(DirectionalLight((0.3, 1.0, 0.2), (2.0, 1.8, 1.5)))))
    out.append(("sun turned", out[-1][1].with_sun(DirectionalLight((-0.3, 0.4, 1.0), (2.0, 1.8, 1.5)))))
    out.append(("lamp off", out[-1][1].with_emission("light", (0.0, 0.0, 0.0))))
    out.append(("lamp on", out[-1][1].with_emission("light", light)))
    return out


@pytest.mark.parametrize("name", ["cornell", "paper-test"])
@pytest.mark.parametrize("resolution", [16, 24])
def test_same_numbers_as_encode_after_every_kind_of_edit(name, resolution):
    scene = load(name)
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, resolution)
    for what, edited in [("new scene", scene)] + edits(scene):
        assert np.array_equal(edited.bounds[0], lo) and np.array_equal(edited.bounds[1], hi), what
        voxels, blockers, reference = encoded(edited, resolution)
        assert_same_encoding(encoder.encode(voxels, edited.sun, blockers), reference)


def test_same_numbers_on_wide_procedural_rooms():
    """v2 rooms (several lights on any surface, glowing objects, windows with the sun), one encoder for
    all of them when their bounds agree, a fresh one otherwise."""
    for seed in range(4):
        scene, _ = random_scene(np.random.default_rng([14, seed]), f"v2-{seed}", PRESETS["v2"])
        voxels, blockers, reference = encoded(scene)
        assert_same_encoding(Encoder(*scene.bounds, 16).encode(voxels, scene.sun, blockers), reference)


def test_a_colour_edit_reuses_the_bases_and_keeps_every_pass():
    """A single lamp's colour or intensity: the direct light is the cached basis times the new colour (no
    ray traced: the occluders are equal, here a new listing of the same triangles), and the scale-out
    leaves every pass's inputs as they were (the network need not run)."""
    scene = load("cornell")
    encoder = Encoder(*scene.bounds, 16)
    voxels, blockers, _ = encoded(scene)
    first = encoder.encode(voxels, None, blockers)
    bases = [e.basis for e in encoder.emitters]
    revisions = encoder.revisions.copy()
    warmer = scene.with_emission("light", lamp_radiance(scene) * (1.3, 0.7, 0.2))
    voxels, blockers, reference = encoded(warmer)
    second = encoder.encode(voxels, None, blockers)
    assert encoder.recomputed == ["emission"]
    assert len(encoder.emitters) == len(bases)
    assert all(e.basis is basis for e, basis in zip(encoder.emitters, bases))
    assert np.array_equal(encoder.revisions, revisions)
    assert second.inputs is first.inputs
    np.testing.assert_allclose(second.scale, first.scale * (1.3, 0.7, 0.2), rtol=1e-5)
    assert_same_encoding(second, reference)


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


def test_an_albedo_edit_changes_only_the_passes_it_touches():
    scene = load("cornell")
    encoder = Encoder(*scene.bounds, 16)
    voxels, blockers, _ = encoded(scene)
    encoder.encode(voxels, None, blockers)
    before = encoder.revisions.copy()
    red = scene.group_albedo("red-wall")
    encoder.encode(voxelize(scene.with_albedo("red-wall", (red[0], 0.5, red[2])), VOXELS), None, blockers)
    assert encoder.recomputed == ["albedo"]
    assert list(encoder.revisions - before) == [0, 1, 0]


def lamp(name: str, x: float, z: float, radiance, half_size: float = 0.1) -> Scene:
    shape = ceiling_lamp(half_size=half_size)
    return Scene(name, shape.vertices + (x, 0.0, z), shape.faces, 0.0, radiance, 0, (name,))


def lit_by(*lamps: Scene) -> Scene:
    """A closed room (bounds [-1, 1]) lit by `lamps`, with a box under them that casts shadows."""
    return Scene.concatenate("lamps", [box(inward=True, albedo=0.5, name="room"), *lamps,
                                       box(0.25, (0.0, -0.5, 0.0), name="block")])


def test_without_shadows_a_moved_lamp_recomputes_only_its_own_basis():
    """Nothing casts a shadow (no occluders): moving one lamp keeps the other's basis (the same object)."""
    scene = lit_by(lamp("warm", -0.5, 0.0, (6.0, 4.0, 2.0), 0.2), lamp("cool", 0.5, 0.0, (2.0, 3.0, 6.0), 0.2))
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 16)
    encoder.encode(voxelize(scene, VOXELS), None, None)
    assert len(encoder.emitters) == 2
    cool_emitter = next(e for e in encoder.emitters if e.radiance[2] > e.radiance[0])
    shifted = moved(scene, "warm", (0.0, 0.0, 0.3))
    voxels = voxelize(shifted, VOXELS)
    ours = encoder.encode(voxels, None, None)
    assert "emitters" in encoder.recomputed
    assert any(e is cool_emitter for e in encoder.emitters) and len(encoder.emitters) == 2
    assert_same_encoding(ours, encoding.encode(voxels, None, lo, hi, 16, None))


def test_a_lamp_switched_off_retraces_the_lamp_that_shares_its_shadow_rays():
    """A patch's visibility is that of its cluster's ray (`encoding.shadow_targets`), which ends at the
    mean of every emitting patch of the cluster, whichever lamp they belong to. Switching the cool lamp
    off moves the ends of the warm lamp's rays it shared: the warm basis is traced again (the occluders
    are the same), the green lamp's, elsewhere, is kept."""
    scene = lit_by(lamp("warm", 0.0, 0.0, (6.0, 4.0, 2.0)), lamp("cool", 0.25, 0.0, (2.0, 3.0, 6.0)),
                   lamp("green", -0.6, 0.5, (1.0, 5.0, 1.0)))
    lo, hi = scene.bounds
    voxels, blockers, _ = encoded(scene)
    spacing = (hi - lo) / 16
    position, normal, _, radiance = encoding.emitting_patches(encoding.lattice_cells(voxels.position, lo, spacing, 16),
                                                              voxels)
    _, cluster = encoding.shadow_targets(blockers, position, normal, lo, spacing)
    warm, cool = radiance[:, 0] > radiance[:, 2] * 2, radiance[:, 2] > radiance[:, 0] * 2
    assert set(cluster[warm]) & set(cluster[cool]), "the lamps should share a cluster of rays"

    encoder = Encoder(lo, hi, 16)
    encoder.encode(voxels, None, blockers)
    assert len(encoder.emitters) == 3
    warm_emitter, green_emitter = (next(e for e in encoder.emitters if np.argmax(e.radiance) == c) for c in (0, 1))
    off = scene.with_emission("cool", (0.0, 0.0, 0.0))
    voxels, _, reference = encoded(off)
    ours = encoder.encode(voxels, None, blockers)   # the same triangles: the same occluders
    assert "shadows" not in encoder.recomputed and "emitters" in encoder.recomputed
    assert len(encoder.emitters) == 2
    assert not any(e is warm_emitter for e in encoder.emitters)
    assert any(e is green_emitter for e in encoder.emitters)
    assert_same_encoding(ours, reference)


def test_a_room_lit_by_a_large_lamp_sweeps_its_lattice_and_an_emission_edit_may_stop_it():
    """A ceiling panel of SWEEP_ENDS ray ends or more: the probes' visibility is swept over the lattice
    (`viewer.rays.lattice_sight`), through a moved block as on a new scene; the panel switched off, the
    small lamp left has too few ends and its segments are traced, its basis made again; switched on
    again, swept again. After each edit the encoder gives `encoding.encode`'s numbers."""
    pytest.importorskip("embreex")
    scene = lit_by(lamp("panel", 0.0, 0.0, (3.0, 3.0, 2.5), 0.7), lamp("spot", 0.87, 0.87, (8.0, 6.0, 4.0), 0.06))
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 16)
    panel = lamp_radiance(scene, "panel")
    shifted = moved(scene, "block", (0.2, 0.0, -0.1))
    steps = [scene, shifted, shifted.with_emission("panel", (0.0, 0.0, 0.0)), shifted]
    sweeping, spots = [], []
    for step in steps:
        voxels, blockers, reference = encoded(step)
        assert_same_encoding(encoder.encode(voxels, None, blockers), reference)
        sweeping.append(encoder._shadows.sweeping)
        spots.append(next(e for e in encoder.emitters if e.radiance[0] > 1.5 * e.radiance[2]))
    assert sweeping == [True, True, False, True] and np.any(panel > 0)
    assert spots[1] is spots[0]   # the move: kept, summed again where its rows changed
    assert spots[2] is not spots[1] and spots[3] is not spots[2]   # the spot's shadows found the other way


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


def test_the_encoder_is_a_cache_not_a_state():
    """Whatever came before, an encoding depends only on the voxels, the sun and the occluders it is
    given: new geometry, a moved lamp, or the shadows switched off and on."""
    a, b = load("cornell"), load("paper-test")
    lo, hi = a.bounds
    assert np.allclose(b.bounds[0], lo) and np.allclose(b.bounds[1], hi)
    encoder = Encoder(lo, hi, 16)
    for scene, shadows in ((a, True), (b, True), (a, True), (moved(b, "light", (0.1, 0, 0)), True), (a, True),
                           (a, False), (a, True)):
        voxels, blockers, reference = encoded(scene)
        if not shadows:
            blockers, reference = None, encoding.encode(voxels, scene.sun, lo, hi, 16, None)
        assert_same_encoding(encoder.encode(voxels, scene.sun, blockers), reference)


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
