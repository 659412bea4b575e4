"""The neural model's training domain (viewer.neural.domain): derived from the dataset's ranges, carried by the
card, and the scenes outside it named with the right reasons."""

import json
from pathlib import Path

import numpy as np
import pytest

from scenes import box, ceiling_lamp
from viewer.neural import field as neural
from viewer.neural.domain import Domain, measure, outside, warning
from viewer.scene import DirectionalLight, Scene, load
from viewer.evaluation.procedural import PRESETS, random_scene

ROOT = Path(__file__).resolve().parents[2]
V1, V2 = Domain.from_preset("v1"), Domain.from_preset("v2")


def scaled(scene: Scene, factors) -> Scene:
    return Scene(scene.name, scene.vertices * np.asarray(factors, np.float64), scene.faces, scene.albedo,
                 scene.emission, scene.face_group, scene.groups, scene.sun)


def without(scene: Scene, group: str) -> Scene:
    keep = scene.face_group != scene.group_index(group)
    return Scene(scene.name, scene.vertices, scene.faces[keep], scene.albedo[keep], scene.emission[keep],
                 scene.face_group[keep], scene.groups)


def with_lamp(scene: Scene, lamp: Scene) -> Scene:
    return Scene.concatenate(scene.name, [without(scene, "light"), lamp])


def test_domain_from_the_ranges():
    """The card's quantities follow from what the generator draws (viewer.neural.ranges)."""
    assert V1.albedo == (0.05, 0.9) and V2.albedo == (0.01, 0.95)
    assert V1.room_aspect == pytest.approx(1.3 / 0.75) and V2.room_aspect == pytest.approx(3.0)
    assert V1.lights == (1, 2) and V2.lights == (1, 3)
    assert V1.light_surfaces == ("ceiling", "wall") and set(V2.light_surfaces) == {"ceiling", "wall", "floor", "object"}
    assert V1.light_power_ratio == pytest.approx(1 / 0.3) and V2.light_power_ratio == pytest.approx(20.0)
    # the largest v1 light: half extent 0.6 on a side of half extent 0.75 -> (0.6 / 0.75)^2 of it
    assert V1.light_area[1] == pytest.approx(0.64) and V1.light_area[0] == pytest.approx((0.05 / 1.3) ** 2)
    assert V1.sun and V2.sun and V1.open_sides == 1
    assert Domain.from_dict(json.loads(json.dumps(V2.to_dict()))) == V2


def test_the_shipped_card_carries_its_domain_and_a_card_without_one_falls_back_to_v1(tmp_path):
    card = neural.ModelCard.read(ROOT / "models" / "probenet.onnx")
    assert card.domain == V2  # trained on the v2 rooms
    assert card.data["sha256"] == neural.file_sha256(card.path)
    old = dict(card.data)
    del old["domain"]
    old["training"] = {k: v for k, v in old["training"].items() if k != "ranges"}  # a card from before v2
    assert neural.ModelCard(card.path, old).domain == V1
    assert neural.ModelCard(card.path, {**old, "training": {"ranges": "v2"}}).domain == V2


@pytest.mark.parametrize("name", ["cornell", "paper-test", "paper-train-2"])
def test_the_papers_rooms_are_inside_both_domains(name):
    scene = load(name)
    assert outside(scene, V1) == [] and outside(scene, V2) == []


@pytest.mark.parametrize("preset", ["v1", "v2"])
def test_procedural_rooms_are_inside_their_own_domain(preset):
    domain = Domain.from_preset(preset)
    for seed in range(12):
        scene, _ = random_scene(np.random.default_rng([41, seed]), f"{preset}-{seed}", PRESETS[preset])
        assert outside(scene, domain) == [], seed


def test_wide_rooms_are_outside_the_first_domain():
    """Most v2 rooms hold something v1 never had (a floor light, a glowing object, albedo 0.95, a long room)."""
    flagged = 0
    for seed in range(12):
        scene, _ = random_scene(np.random.default_rng([41, seed]), f"v2-{seed}", PRESETS["v2"])
        flagged += bool(outside(scene, V1))
    assert flagged >= 6


def test_a_white_room_names_the_albedo():
    scene = load("cornell").with_albedo("back", (0.99, 0.99, 0.99))
    assert outside(scene, V1) == ["'back' albedo 0.99 is above the trained 0.90"]
    assert outside(scene, V2) == ["'back' albedo 0.99 is above the trained 0.95"]
    assert outside(load("cornell").with_albedo("back", (0.915, 0.9, 0.9)), V1) == []  # a small step past 0.90


def test_a_huge_or_tiny_light_names_its_size():
    cornell = load("cornell")
    huge = with_lamp(cornell, ceiling_lamp(half_size=0.97, height=0.99, radiance=2.0))
    [reason] = outside(huge, V1)
    assert reason.startswith("'lamp' covers 94% of the ceiling; trained up to 64%")
    tiny = with_lamp(cornell, ceiling_lamp(half_size=0.02, height=0.99, radiance=500.0))
    [reason] = outside(tiny, V1)
    assert "covers 0.04% of the ceiling; trained down to 0.15%" in reason


def test_room_size_is_normalized_away_but_its_proportions_are_not():
    """A Cornell box in millimetres or in kilometres is the network's Cornell box; a corridor is not."""
    cornell = load("cornell")
    assert outside(scaled(cornell, 0.001), V1) == [] and outside(scaled(cornell, 1000.0), V1) == []
    corridor = outside(scaled(cornell, (4.0, 1.0, 1.0)), V1)
    assert corridor[0] == "the room is 4.0 times longer than it is narrow; trained up to 1.7"


def test_lights_where_or_as_many_as_training_never_had():
    cornell = load("cornell")
    up = ceiling_lamp(half_size=0.2, height=-0.99)
    floor_lamp = Scene("floor-lamp", up.vertices, up.faces[:, ::-1], 0.0, 5.0, 0, ("floor-lamp",))
    assert outside(Scene.concatenate("floor", [cornell, floor_lamp]), V1) == [
        "a light on the floor (facing up); trained with lights on the ceiling and wall only"]
    assert outside(Scene.concatenate("floor", [cornell, floor_lamp]), V2) == []
    lamps = [Scene(f"l{k}", ceiling_lamp(0.1).vertices + (0.5 * k - 0.5, 0, 0.5 * (k % 2)), ceiling_lamp().faces,
                   0.0, 5.0, 0, (f"l{k}",)) for k in range(3)]
    assert "3 lights; trained with at most 2" in outside(with_lamp(cornell, Scene.concatenate("l", lamps)), V1)
    dim = Scene("dim", lamps[0].vertices, lamps[0].faces, 0.0, 0.5, 0, ("dim",))
    bright = Scene("bright", lamps[2].vertices, lamps[2].faces, 0.0, 10.0, 0, ("bright",))
    ratio = outside(with_lamp(cornell, Scene.concatenate("two", [dim, bright])), V1)
    assert ratio == ["the brightest light emits 20 times the power of the dimmest; trained up to 3"]


def test_open_scenes_and_the_sun_alone():
    floor = Scene("floor", np.array([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], np.float64),
                  np.array([[0, 2, 1], [0, 3, 2]]), 0.5, 0.0, 0, ("floor",),
                  sun=DirectionalLight((0.2, 1.0, 0.1), (3.0, 3.0, 3.0)))
    reasons = outside(floor, V2)   # a flat scene's box is widened about its plane: no side is covered
    assert "the scene is open on 6 sides of its box; trained on rooms open on 1" in reasons
    assert "lit by the sun alone; every training room had a lamp" in reasons
    room = box(inward=True, albedo=0.5, name="room")
    assert measure(room).open_sides == 0


def test_one_line_warning():
    assert warning([]) is None
    line = warning(["'back' albedo 0.99 is above the trained 0.90"])
    assert "\n" not in line and "outside" in line and "physical solver" in line


def test_a_closed_room_is_outside_rooms_open_at_the_front():
    """Every training room was open at the front; in a closed one (the white furnace) the light bounces
    on instead of leaving, and the network gave it half its light (docs/STABILITY.md)."""
    from viewer.bench.stability.scenes import furnace

    for closed in (furnace(0.8), Scene.concatenate("lit", [box(inward=True, albedo=0.5, name="room"), ceiling_lamp()])):
        assert measure(closed).open_sides == 0
        assert "the scene is open on 0 sides of its box; every training room was open on 1" in outside(closed, V2)


def test_colour_edits_sum_again_only_the_groups_they_recolour():
    """`measure` keeps its albedo sums between calls on the same triangles: after colour edits (two
    groups recoloured, then the lamp's colour) it gives what it gives afresh, to the last bit."""
    from viewer.neural import domain

    scene = load("cornell")
    shape = domain.Shape.of(scene)
    measure(scene, shape)
    for edited in (scene.with_albedo("red-wall", (0.3, 0.2, 0.1)).with_albedo("small-box", (0.9, 0.9, 0.1)),
                   scene.with_emission("light", (5.0, 4.0, 3.0))):
        kept = measure(edited, shape)
        shape.sums[0] = None
        fresh = measure(edited, shape)
        assert kept.albedo.keys() == fresh.albedo.keys()
        for name in fresh.albedo:
            np.testing.assert_array_equal(kept.albedo[name], fresh.albedo[name])
