"""The panel's scene edits (viewer/ui/scene_edits.py): the light moved, scaled and recoloured (a spot's
shade with it, a sun turned), objects moved, materials recoloured, and a reset that puts all back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenes import box, group_corners
from viewer.scene import DirectionalLight
from viewer.ui.scene_edits import SceneEdits, emitter_group


def test_light_edits_move_scale_and_recolour_only_the_emitter(cornell):
    assert emitter_group(cornell) == "light"
    edits = SceneEdits(cornell)
    assert edits.light.intensity == pytest.approx(cornell.emission.max())
    edits.set_light(offset=(0.1, -0.2, 0.0), size=2.0, colour=(1.0, 0.5, 0.25), intensity=10.0)
    edited = edits.apply()
    before, after = group_corners(cornell, "light"), group_corners(edited, "light")
    assert after.mean(axis=0) == pytest.approx(before.mean(axis=0) + [0.1, -0.2, 0.0])
    light = edited.face_group == edited.group_index("light")
    assert edited.face_areas[light].sum() == pytest.approx(4.0 * cornell.face_areas[light].sum())
    assert edited.emission[light] == pytest.approx(np.tile([10.0, 5.0, 2.5], (light.sum(), 1)))
    np.testing.assert_array_equal(edited.vertices[~np.isin(np.arange(len(edited.vertices)),
                                                          np.unique(edited.faces[light]))],
                                  cornell.vertices[~np.isin(np.arange(len(cornell.vertices)),
                                                            np.unique(cornell.faces[light]))])
    assert "light" not in edits.material_groups


def test_moving_a_spot_light_moves_its_shade_with_it(tmp_path):
    """A glTF spot is its sphere (the emitter group) inside a black shade: dragging the light moves both,
    and the shade is not offered as a material to recolour."""
    from viewer.scene import load
    from scene.test_gltf_lights import spot_room   # the glTF room of the spot-light tests
    from viewer.scene.gltf_lights import shade_group

    scene = load(spot_room(tmp_path / "spot.gltf", {"type": "spot", "intensity": 20.0, "name": "lamp",
                                                     "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.5}}))
    edits = SceneEdits(scene)
    lamp = edits.light.group
    assert shade_group(lamp) in scene.groups and shade_group(lamp) not in edits.material_groups
    edits.set_light(offset=(0.5, -0.25, 0.0))
    edited = edits.apply()
    for group in (lamp, shade_group(lamp)):
        np.testing.assert_allclose(group_corners(edited, group), group_corners(scene, group) + [0.5, -0.25, 0.0])


def test_an_object_moved_moves_its_group_alone_and_a_reset_puts_it_back(cornell):
    """The panel's object is the largest non-emitting group at first (a tie of triangles: the smaller box);
    moving it moves its vertices alone by the offset, about the centre the panel shows; the light is not
    an object; a reset puts everything back, bit for bit."""
    edits = SceneEdits(cornell)
    assert edits.selected == "small-box" and "light" not in edits.material_groups
    before = group_corners(cornell, "small-box")
    np.testing.assert_allclose(edits.centre_of("small-box"), 0.5 * (before.min(axis=0) + before.max(axis=0)))
    edits.set_offset("small-box", (0.2, 0.0, -0.1))
    edits.set_albedo("red-wall", (0.1, 0.2, 0.7))
    edited = edits.apply()
    np.testing.assert_allclose(group_corners(edited, "small-box"), before + [0.2, 0.0, -0.1])
    np.testing.assert_array_equal(group_corners(edited, "large-box"), group_corners(cornell, "large-box"))
    assert edited.group_albedo("red-wall") == pytest.approx([0.1, 0.2, 0.7])
    np.testing.assert_array_equal(edits.offset_of("small-box"), [0.2, 0.0, -0.1])
    with pytest.raises(ValueError, match="not a group that can be moved"):
        edits.set_offset("light", (0.1, 0.0, 0.0))
    with pytest.raises(ValueError, match="finite"):
        edits.set_offset("small-box", (np.nan, 0.0, 0.0))
    edits.reset()
    np.testing.assert_array_equal(edits.apply().vertices, cornell.vertices)


def test_material_edits_and_reset(cornell):
    edits = SceneEdits(cornell)
    edits.set_albedo("red-wall", (0.1, 0.2, 0.7))
    edited = edits.apply()
    assert edited.group_albedo("red-wall") == pytest.approx([0.1, 0.2, 0.7])
    assert edited.group_albedo("green-wall") == pytest.approx(cornell.group_albedo("green-wall"))
    version = edits.version
    edits.reset()
    assert edits.version > version
    np.testing.assert_array_equal(edits.apply().albedo, cornell.albedo)


def test_a_sun_lit_scene_edits_the_sun():
    scene = box(inward=False).with_sun(DirectionalLight([0.0, 1.0, 0.0], [2.0, 2.0, 1.0]))
    edits = SceneEdits(scene)
    assert edits.light.group is None and edits.light.intensity == pytest.approx(2.0)
    edits.set_light(direction=(1.0, 1.0, 0.0), intensity=4.0)
    sun = edits.apply().sun
    assert sun.direction == pytest.approx(np.array([1.0, 1.0, 0.0]) / math.sqrt(2))
    assert sun.irradiance == pytest.approx([4.0, 4.0, 2.0])
