"""A textured glTF keeps its texture: the texture coordinates the material names, KHR_texture_transform
applied as the extension's sample model reads it, the sampler's wrap modes, and the albedo at any point
of a face (what the voxels and Mitsuba see): the face's mean albedo times the texture there over its mean."""

from __future__ import annotations

import numpy as np
import pytest

from textured import CHECKER, checker_quad
from viewer.scene import Scene, load
from viewer.scene.textures import SRGB_TABLE, Texture, surface_albedo, transform_uv

RED, GREEN, BLUE, GREY = (SRGB_TABLE[CHECKER[i, j]] for i, j in ((0, 0), (0, 1), (1, 0), (1, 1)))
"""The checker's four linear colours: top-left, top-right, bottom-left, bottom-right of the image."""


def albedo_at(scene: Scene, points) -> np.ndarray:
    """The albedo at points (x, y) of the quad z = 0: found by the face and barycentric weights that hold them."""
    points = np.asarray(points, np.float64)
    triangles = scene.triangles[:, :, :2]
    out = []
    for p in points:
        for f, (a, b, c) in enumerate(triangles):
            m = np.column_stack([b - a, c - a])
            v, w = np.linalg.solve(m, p - a)
            if v >= -1e-9 and w >= -1e-9 and v + w <= 1 + 1e-9:
                out.append(surface_albedo(scene, [f], [[1 - v - w, v, w]])[0])
                break
    return np.array(out)


QUADRANTS = [(-0.5, 0.5), (0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)]
"""Centres of the quad's top-left, top-right, bottom-left and bottom-right quarters (seen from +z)."""


def test_the_checker_shows_upright_and_the_face_albedo_is_its_mean(tmp_path):
    """glTF's UV (0, 0) is the image's top-left corner: the quad's top-left quarter is red, top-right
    green, bottom-left blue, bottom-right grey; each face's albedo stays the texture's mean colour."""
    scene = load(checker_quad(tmp_path / "checker.gltf"))
    np.testing.assert_allclose(albedo_at(scene, QUADRANTS), [RED, GREEN, BLUE, GREY], atol=1e-6)
    np.testing.assert_allclose(scene.albedo, np.tile(np.mean([RED, GREEN, BLUE, GREY], axis=0), (2, 1)), atol=1e-6)


def test_the_base_colour_factor_multiplies_the_texture(tmp_path):
    scene = load(checker_quad(tmp_path / "checker.gltf", factor=(0.5, 1.0, 0.25, 1.0)))
    np.testing.assert_allclose(albedo_at(scene, QUADRANTS[:1]), [RED * (0.5, 1.0, 0.25)], atol=1e-6)


@pytest.mark.parametrize("transform, expected", [
    ({"offset": [0.5, 0.0]}, [GREEN, RED, GREY, BLUE]),              # the image moves half a width left
    ({"offset": [0.0, 0.5]}, [BLUE, GREY, RED, GREEN]),
    ({"rotation": np.pi / 2}, [BLUE, RED, GREY, GREEN]),               # the image turns a quarter clockwise
    ({"scale": [-1.0, 1.0]}, [GREEN, RED, GREY, BLUE]),                # mirrored left to right
])
def test_texture_transform_moves_the_checker_as_the_extension_says(tmp_path, transform, expected):
    """KHR_texture_transform: uv' = offset + R(rotation) (scale * uv), R turning counter-clockwise on the
    UV map (v down), so the image on the surface turns clockwise; the checker repeats (REPEAT sampler)."""
    scene = load(checker_quad(tmp_path / "checker.gltf", transform=transform))
    np.testing.assert_allclose(albedo_at(scene, QUADRANTS), expected, atol=1e-6)


def test_scale_repeats_the_checker(tmp_path):
    """scale 2: the checker tiles twice along each side of the quad."""
    scene = load(checker_quad(tmp_path / "checker.gltf", transform={"scale": [2.0, 2.0]}))
    quarter = [(-0.75, 0.75), (-0.25, 0.75), (0.25, 0.75), (0.75, 0.75)]
    np.testing.assert_allclose(albedo_at(scene, quarter), [RED, GREEN, RED, GREEN], atol=1e-6)


def test_rotation_by_the_sample_models_angle():
    """TextureTransformTest's rotation quad turns UVs by 22.5 degrees: (1, 0) goes to (cos, -sin), up on the
    UV map, as its green marker expects (the extension's erratum: its GLSL listing has the other sign)."""
    r = 0.392699
    np.testing.assert_allclose(transform_uv([1.0, 0.0], rotation=r), [np.cos(r), -np.sin(r)], atol=1e-12)


@pytest.mark.parametrize("wrap, u, expected", [
    ("repeat", 1.25, 0.25), ("mirror", 1.25, 0.75), ("clamp", 1.25, 1.0), ("mirror", -0.25, 0.25),
    ("repeat", -0.25, 0.75)])
def test_wrap_modes(wrap, u, expected):
    """A 1-row ramp of 4 texels (linear values 0, 1/3, 2/3, 1): where a coordinate outside [0, 1] reads."""
    ramp = np.array([[[0.0] * 3, [1 / 3] * 3, [2 / 3] * 3, [1.0] * 3]], np.float32)
    texture = Texture(ramp, srgb=False, wrap=(wrap, "repeat"))
    at = lambda s: texture.sample([[s, 0.5]])[0, 0]
    assert at(u) == pytest.approx(at(expected) if wrap != "clamp" else 1.0, abs=1e-6)


def test_a_nearest_sampler_shows_each_texel_flat(tmp_path):
    """magFilter NEAREST (pixel art): just left of the quad's middle and at its left edge the quad is the
    red texel itself, where linear filtering blends it towards green (beside it, and repeated past the edge)."""
    near = load(checker_quad(tmp_path / "near.gltf", mag_filter=9728))
    smooth = load(checker_quad(tmp_path / "smooth.gltf"))
    points = [(-0.05, 0.5), (-0.99, 0.5)]
    np.testing.assert_allclose(albedo_at(near, points), [RED, RED], atol=1e-6)
    assert np.all(np.abs(albedo_at(smooth, points) - RED).max(axis=1) > 0.1)


def test_a_recoloured_group_keeps_its_pattern_around_the_new_colour(tmp_path):
    """Recolouring multiplies the texture by the new colour over the old: the mean is the new colour and
    the checker still shows; a colour the texture cannot carry (a channel black throughout) drops it."""
    scene = load(checker_quad(tmp_path / "checker.gltf"))
    edited = scene.with_albedo("checker", (0.1, 0.2, 0.3))
    old = scene.albedo[0]
    np.testing.assert_allclose(albedo_at(edited, QUADRANTS), np.array([RED, GREEN, BLUE, GREY]) / old
                               * (0.1, 0.2, 0.3), atol=1e-6)
    assert edited.textured
    black_blue = load(checker_quad(tmp_path / "no-blue.gltf", pixels=CHECKER * np.array([1, 1, 0], np.uint8)))
    plain = black_blue.with_albedo("checker", (0.2, 0.4, 0.6))
    assert not plain.textured
    np.testing.assert_allclose(albedo_at(plain, QUADRANTS), np.tile((0.2, 0.4, 0.6), (4, 1)))


def test_concatenate_keeps_textures_and_their_coordinates(tmp_path):
    from scenes import box

    quad = load(checker_quad(tmp_path / "checker.gltf"))
    both = Scene.concatenate("both", [box(), quad])
    assert both.name == "both"   # not its last group's
    assert both.groups == ("box", "checker") and both.texture_of(0) is None
    assert both.texture_of(1) is quad.textures[0]
    np.testing.assert_array_equal(both.uv[-2:], quad.uv)


def test_a_texture_without_its_coordinates_shows_its_mean(tmp_path):
    """A primitive without the TEXCOORD_n its texture names: the mean colour, as before textures."""
    scene = load(checker_quad(tmp_path / "checker.gltf", transform={"texCoord": 1}))
    assert not scene.textured
    np.testing.assert_allclose(scene.albedo[0], np.mean([RED, GREEN, BLUE, GREY], axis=0), atol=1e-6)


def test_khronos_texture_coordinate_test_reads_each_corner_of_the_image():
    """TextureCoordinateTest (its geometry, coordinates and materials; the image four flat greys, white
    top-left, 200 top-right, 150 bottom-left, 100 bottom-right): each small square shows the image's corner
    of its name, tinted by its baseColorFactor; seen from -z, TopLeft is top-left."""
    from pathlib import Path

    scene = load(Path(__file__).resolve().parent.parent / "data" / "gltf" / "TextureCoordinateTest-greys.gltf")
    grey = {"TopLeft": 255, "TopRight": 200, "BottomLeft": 150, "BottomRight": 100}
    factor = {"TopLeft": (1, 1, 0), "TopRight": (1, 0.1, 0), "BottomLeft": (0, 0.2, 1), "BottomRight": (0, 1, 0)}
    for name in grey:
        faces = np.flatnonzero(scene.face_group == scene.group_index(f"{name}Material"))
        albedo = surface_albedo(scene, faces, np.full((len(faces), 3), 1 / 3))
        expected = np.minimum(np.asarray(factor[name]) * SRGB_TABLE[grey[name]], 0.999)
        np.testing.assert_allclose(albedo, np.tile(expected, (len(faces), 1)), atol=1e-6, err_msg=name)
        centre = scene.triangles[faces].mean(axis=(0, 1))
        assert (centre[0] > 0) == name.endswith("Left") and (centre[1] > 0) == name.startswith("Top")


def test_faces_that_show_another_texture_or_none_get_a_group_of_their_own(tmp_path):
    """A group shows one texture: a same-named group with another texture, or none (a part without texture
    coordinates), becomes "NAME (2)", so neither shows the other's image."""
    from scenes import box

    quad = load(checker_quad(tmp_path / "checker.gltf"))
    other = load(checker_quad(tmp_path / "other.gltf", pixels=CHECKER[::-1]))
    plain = box(name="checker")
    both = Scene.concatenate("all", [quad, other, plain, quad])
    assert both.groups == ("checker", "checker (2)", "checker (3)")
    assert both.texture_of(0) is quad.textures[0] and both.texture_of(1) is other.textures[0]
    assert both.texture_of(2) is None
    assert both.face_group[-1] == 0   # the same Texture again: the same group


def test_a_primitive_without_the_coordinates_of_its_material_s_texture_is_a_group_apart(tmp_path):
    """One material on two primitives, one of them without TEXCOORD_0: its faces show the mean colour in a
    group "NAME (2)" and never read the texture at a made-up coordinate."""
    import json

    path = checker_quad(tmp_path / "checker.gltf")
    document = json.loads(path.read_text())
    bare = {"attributes": {"POSITION": 0}, "indices": 2, "material": 0}
    document["meshes"][0]["primitives"].append(bare)
    path.write_text(json.dumps(document))
    scene = load(path)
    assert scene.groups == ("checker", "checker (2)")
    assert scene.texture_of(0) is not None and scene.texture_of(1) is None
    np.testing.assert_allclose(scene.albedo[2:], np.tile(scene.albedo[0], (2, 1)))


def test_the_documented_textured_room_loads_with_its_textures():
    """docs/data/textured-room.gltf, the room docs/PERFORMANCE.md times: its floor and back wall textured."""
    from pathlib import Path

    room = load(Path(__file__).resolve().parents[2] / "docs" / "data" / "textured-room.gltf")
    textured = {g for i, g in enumerate(room.groups) if room.texture_of(i) is not None}
    assert textured == {"floor", "back"} and room.has_emitters
