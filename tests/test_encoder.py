"""The incremental encoder (viewer.encoder): the numbers of `encoding.encode` on every scene and after
every kind of edit, while recomputing only what the edit changed."""

import numpy as np
import pytest

from scenes import box, ceiling_lamp
from viewer import encoding
from viewer.encoder import Encoder
from viewer.scene import DirectionalLight, Scene, load
from viewer.training.procedural import PRESETS, random_scene
from viewer.voxels import voxelize

VOXELS = 16


def assert_same_encoding(ours: encoding.Encoding, reference: encoding.Encoding) -> None:
    """Equal to float32 round-off: the inputs are in units of each pass's scale, so an absolute 1e-5 is
    1e-5 of the field's scale (and 1e-5 relative next to a lamp, where they reach tens)."""
    assert ours.inputs.shape == reference.inputs.shape
    np.testing.assert_allclose(ours.scale, reference.scale, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(ours.inputs, reference.inputs, rtol=1e-5, atol=1e-5)


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
    out.append(("sun", out[-1][1].with_sun(DirectionalLight((0.3, 1.0, 0.2), (2.0, 1.8, 1.5)))))
    out.append(("sun turned", out[-1][1].with_sun(DirectionalLight((-0.3, 1.0, 0.4), (2.0, 1.8, 1.5)))))
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
        voxels = voxelize(edited, VOXELS)
        ours = encoder.encode(voxels, edited.sun)
        assert_same_encoding(ours, encoding.encode(voxels, edited.sun, lo, hi, resolution))


def test_same_numbers_on_wide_procedural_rooms():
    """v2 rooms (several lights on any surface, glowing objects, windows with the sun), one encoder for
    all of them when their bounds agree, a fresh one otherwise."""
    for seed in range(4):
        scene, _ = random_scene(np.random.default_rng([14, seed]), f"v2-{seed}", PRESETS["v2"])
        lo, hi = scene.bounds
        voxels = voxelize(scene, VOXELS)
        assert_same_encoding(Encoder(lo, hi, 16).encode(voxels, scene.sun),
                             encoding.encode(voxels, scene.sun, lo, hi, 16))


def test_a_colour_edit_reuses_the_bases_and_keeps_every_pass():
    """A single lamp's colour or intensity: the direct light is the cached basis times the new colour,
    and the scale-out leaves every pass's inputs as they were (the network need not run)."""
    scene = load("cornell")
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 16)
    first = encoder.encode(voxelize(scene, VOXELS), None)
    revisions = encoder.revisions.copy()
    warmer = scene.with_emission("light", lamp_radiance(scene) * (1.3, 0.7, 0.2))
    second = encoder.encode(voxelize(warmer, VOXELS), None)
    assert encoder.recomputed == ["emission"]
    assert np.array_equal(encoder.revisions, revisions)
    assert second.inputs is first.inputs
    np.testing.assert_allclose(second.scale, first.scale * (1.3, 0.7, 0.2), rtol=1e-5)


def test_an_albedo_edit_changes_only_the_passes_it_touches():
    scene = load("cornell")
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 16)
    encoder.encode(voxelize(scene, VOXELS), None)
    before = encoder.revisions.copy()
    red = scene.group_albedo("red-wall")
    encoder.encode(voxelize(scene.with_albedo("red-wall", (red[0], 0.5, red[2])), VOXELS), None)
    assert encoder.recomputed == ["albedo"]
    assert list(encoder.revisions - before) == [0, 1, 0]


def test_a_moved_lamp_recomputes_only_its_own_basis():
    """Two lamps of different colours: moving one keeps the other's basis (the same object)."""
    room = box(inward=True, albedo=0.5, name="room")
    warm = ceiling_lamp(half_size=0.2, radiance=5.0)
    warm = Scene("warm", warm.vertices + (-0.5, 0, 0), warm.faces, 0.0, (6.0, 4.0, 2.0), 0, ("warm",))
    cool = Scene("cool", warm.vertices + (1.0, 0, 0), warm.faces, 0.0, (2.0, 3.0, 6.0), 0, ("cool",))
    scene = Scene.concatenate("two-lamps", [room, warm, cool])
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 16)
    encoder.encode(voxelize(scene, VOXELS), None)
    assert len(encoder.emitters) == 2
    cool_emitter = next(e for e in encoder.emitters if e.radiance[2] > e.radiance[0])
    shifted = moved(scene, "warm", (0.0, 0.0, 0.3))
    voxels = voxelize(shifted, VOXELS)
    ours = encoder.encode(voxels, None)
    assert "emitters" in encoder.recomputed
    assert any(e is cool_emitter for e in encoder.emitters) and len(encoder.emitters) == 2
    assert_same_encoding(ours, encoding.encode(voxels, None, lo, hi, 16))


def test_the_encoder_is_a_cache_not_a_state():
    """Whatever came before, an encoding depends only on the voxels and the sun it is given."""
    a, b = load("cornell"), load("paper-test")
    lo, hi = a.bounds
    assert np.allclose(b.bounds[0], lo) and np.allclose(b.bounds[1], hi)
    encoder = Encoder(lo, hi, 16)
    for scene in (a, b, a, moved(b, "light", (0.1, 0, 0)), a):
        voxels = voxelize(scene, VOXELS)
        assert_same_encoding(encoder.encode(voxels, scene.sun), encoding.encode(voxels, scene.sun, lo, hi, 16))
