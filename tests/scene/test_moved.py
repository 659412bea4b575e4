"""A scene made by moving some vertices of another (a dragged lamp or object: `Scene.transformed_group`)
derives its geometry from the other's, for the moved faces alone (viewer/scene/geometry.py): it must hold
what a scene made afresh from the same arrays holds, to the last bit."""

from dataclasses import replace

import numpy as np
import pytest

from viewer.scene import Scene, SceneError, load
from viewer.scene.geometry import DERIVED

ASKED = DERIVED + ("bounds",)


def fresh(scene: Scene) -> Scene:
    return replace(scene, vertices=np.array(scene.vertices))


def assert_same_geometry(scene: Scene, expected: Scene) -> None:
    for name in ASKED:
        got, want = getattr(scene, name), getattr(expected, name)
        for a, b in zip(got if isinstance(got, tuple) else (got,), want if isinstance(want, tuple) else (want,)):
            np.testing.assert_array_equal(a, b, err_msg=name)
            assert not a.flags.writeable, name


def shift(x: float, scale: float = 1.0) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] *= scale
    matrix[0, 3] = x
    return matrix


@pytest.fixture()
def cornell():
    scene = load("cornell")
    for name in ASKED:   # what a scene on screen has made before it is dragged
        getattr(scene, name)
    return scene


def test_a_dragged_lamp_and_box_hold_what_a_fresh_scene_holds(cornell):
    scene = cornell
    for group, matrix in (("light", shift(0.1)), ("small-box", shift(-0.2)), ("light", shift(0.05, 0.5)),
                          ("large-box", shift(0.3))):
        scene = scene.transformed_group(group, matrix)
        assert_same_geometry(scene, fresh(scene))


def test_only_what_the_source_had_made_is_copied_and_the_rest_is_made_afresh():
    scene = load("cornell")
    scene.face_areas   # made: the triangles, the cross products and the areas; not the edges or normals
    moved = scene.transformed_group("small-box", shift(0.1))
    kept = moved.__dict__["_moved_from"][1]
    assert set(kept) == {"triangles", "face_cross"}   # the areas already made from them (the degenerate check)
    assert_same_geometry(moved, fresh(moved))
    assert kept == {}   # each source array let go once its copy is made


def test_the_bounds_follow_a_vertex_dragged_past_them(cornell):
    lo, hi = cornell.bounds
    outward = cornell.transformed_group("small-box", shift(float(hi[0] - lo[0])))
    assert outward.bounds[1][0] > hi[0]
    assert_same_geometry(outward, fresh(outward))
    back = outward.transformed_group("small-box", shift(-float(hi[0] - lo[0])))
    assert_same_geometry(back, fresh(back))


def test_a_chain_of_drags_from_a_source_that_made_little(cornell):
    scene = cornell
    for step in range(4):
        scene = scene.transformed_group("light", shift(0.01 * (step + 1)))
        if step == 1:
            scene.edges   # made in the middle of the chain alone
    assert_same_geometry(scene, fresh(scene))


def test_a_drag_is_checked_as_a_new_scene_is(cornell):
    with pytest.raises(SceneError, match="NaN or infinity"):
        cornell.transformed_group("light", np.full((4, 4), np.nan))
    with pytest.raises(SceneError, match="beyond"):
        cornell.transformed_group("light", shift(1e16))
    lamp = Scene("lamp", cornell.vertices, cornell.faces, cornell.albedo, cornell.emission,
                 np.zeros(len(cornell.faces), np.int64), ("all",))
    with pytest.raises(SceneError, match="degenerate"):
        lamp.transformed_group("all", shift(0.0, 0.0))


def test_unchanged_colours_give_back_the_same_scene_and_new_ones_are_not_copied_again(cornell):
    lamp = cornell.emission[cornell.face_group == cornell.group_index("light")][0]
    assert cornell.with_emission("light", lamp) is cornell
    assert cornell.with_albedo("red-wall", cornell.group_albedo("red-wall")) is cornell
    brighter = cornell.with_emission("light", 2 * lamp)
    assert brighter.albedo is cornell.albedo and brighter.vertices is cornell.vertices
    assert not brighter.emission.flags.writeable


def test_a_drag_gets_a_digest_of_its_own_made_from_its_source(cornell):
    cornell.geometry_digest
    moved = cornell.transformed_group("light", shift(0.1))
    other = cornell.transformed_group("light", shift(0.2))
    assert len({cornell.geometry_digest, moved.geometry_digest, other.geometry_digest}) == 3
    assert cornell.transformed_group("light", shift(0.1)).geometry_digest == moved.geometry_digest


def test_a_moved_scene_digest_tells_its_triangles_apart_and_a_turn_holds_a_fresh_scene(cornell):
    """The same move of the same scene has the same digest (the group and its matrix are hashed, not its
    corners), another move or the source another; a turned box holds what a fresh scene holds."""
    a, b = (cornell.transformed_group("small-box", shift(0.1)) for _ in range(2))
    other = cornell.transformed_group("small-box", shift(0.2))
    assert a.geometry_digest == b.geometry_digest
    assert len({a.geometry_digest, other.geometry_digest, cornell.geometry_digest}) == 3
    angle = 0.3
    turn = np.eye(4)
    turn[[0, 0, 2, 2], [0, 2, 0, 2]] = np.cos(angle), np.sin(angle), -np.sin(angle), np.cos(angle)
    turned = cornell.transformed_group("small-box", turn)
    assert_same_geometry(turned, fresh(turned))
    assert turned.geometry_digest not in (a.geometry_digest, cornell.geometry_digest)
