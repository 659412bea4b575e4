"""The incremental encoder (viewer.neural.encoder): the numbers of `encoding.encode` on every scene and after
every kind of edit, shadows included, while recomputing only what the edit changed (a moved object's
kept rays and answers: test_encoder_moves.py)."""

import numpy as np
import pytest

from encoded import VOXELS, assert_same_encoding, encoded, lamp, moved
from scenes import box
from viewer.neural import encoding
from viewer.neural.encoder import Encoder
from viewer.scene import DirectionalLight, Scene, load
from viewer.evaluation.procedural import PRESETS, random_scene
from viewer.rays.voxels import voxelize


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


def test_without_the_probes_shadows_the_same_numbers_as_encode_after_every_kind_of_edit():
    """The direct input without the probes' shadows (`encoding.DIRECT_SHADOWS`, as the card says): the
    numbers of `encode` told the same, after every edit, a sunlit room's included; the voxels' own direct
    light keeps its shadows (the bounce and seen inputs are those of the shadowed encoding), and no
    probe's visibility to a lamp is traced."""
    scene = load("cornell")
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 16, direct_shadows=False)
    for what, edited in [("new scene", scene)] + edits(scene):
        voxels, blockers, shadowed = encoded(edited)
        reference = encoding.encode(voxels, edited.sun, lo, hi, 16, blockers, direct_shadows=False)
        assert_same_encoding(encoder.encode(voxels, edited.sun, blockers), reference)
        light = [encoding.BOUNCE, encoding.SEEN]
        for part in light:   # in units of each pass's scale, which the shadows change
            np.testing.assert_allclose(reference.inputs[:, part] * reference.scale[:, None, None, None, None],
                                       shadowed.inputs[:, part] * shadowed.scale[:, None, None, None, None],
                                       rtol=1e-4, atol=1e-6)
        assert encoder._shadows._rows == {}, what
    assert not np.allclose(reference.inputs[:, encoding.DIRECT], shadowed.inputs[:, encoding.DIRECT])


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
