"""Textures in the picture: a glTF's base-colour texture sampled per fragment (its texture coordinates,
KHR_texture_transform, sRGB decoded to linear), in the albedo view and lit in the final view."""

from __future__ import annotations

import numpy as np
import pytest

from textured import CHECKER, checker_quad
from viewer.gpu.camera import view_projection
from viewer.gpu.offscreen import OffscreenRenderer
from viewer.gpu.renderer import RenderSettings
from viewer.scene import Camera, Scene, load
from scenes import ceiling_lamp

SIZE = (96, 96)
CAMERA = Camera((0.0, 0.0, 2.6), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 50.0)
QUADRANTS = [(-0.5, 0.5), (0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)]
"""World (x, y) of the centres of the quad's top-left, top-right, bottom-left and bottom-right quarters."""
RED, GREEN, BLUE, GREY = (CHECKER[i, j].astype(float) for i, j in ((0, 0), (0, 1), (1, 0), (1, 1)))


@pytest.fixture(scope="module")
def offscreen(gl_context):
    renderer = OffscreenRenderer(SIZE, RenderSettings(), samples=0, ctx=gl_context)
    yield renderer
    renderer.release()


def pixel(scene: Scene, point) -> tuple[int, int]:
    """(row, column) of the pixel that shows the world point (x, y, 0)."""
    clip = view_projection(CAMERA, SIZE[0] / SIZE[1], *scene.bounds) @ np.array([*point, 0.0, 1.0])
    ndc = clip[:2] / clip[3]
    return int((1 - ndc[1]) / 2 * SIZE[1]), int((ndc[0] + 1) / 2 * SIZE[0])


def colours(offscreen, scene: Scene, view: str = "albedo") -> np.ndarray:
    offscreen.renderer.set_scene(scene)
    image = offscreen.render(CAMERA, view=view).astype(float)
    return np.array([image[pixel(scene, p)][:3] for p in QUADRANTS])


def test_the_albedo_view_shows_the_checker_upright(offscreen, tmp_path):
    """glTF's UV (0, 0) is the image's top-left: the albedo view shows each quarter in the texture's own
    8-bit colour (the sRGB texture decoded to linear, shown as the albedo view shows albedo: re-encoded)."""
    scene = load(checker_quad(tmp_path / "checker.gltf"))
    np.testing.assert_allclose(colours(offscreen, scene), [RED, GREEN, BLUE, GREY], atol=6)


@pytest.mark.parametrize("transform, expected", [
    ({"offset": [0.5, 0.0]}, [GREEN, RED, GREY, BLUE]),
    ({"rotation": np.pi / 2}, [BLUE, RED, GREY, GREEN]),
    ({"scale": [-1.0, 1.0]}, [GREEN, RED, GREY, BLUE]),
])
def test_texture_transform_moves_the_checker_on_screen(offscreen, tmp_path, transform, expected):
    scene = load(checker_quad(tmp_path / "checker.gltf", transform=transform))
    np.testing.assert_allclose(colours(offscreen, scene), expected, atol=6)


def test_mirrored_repeat_folds_the_checker(offscreen, tmp_path):
    """Coordinates 1..2 along u read the image mirrored (MIRRORED_REPEAT): the quad's uv from (1, 0) to
    (2, 1) shows green at the left, red at the right."""
    uv = np.array([[1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0]])
    scene = load(checker_quad(tmp_path / "checker.gltf", wrap=(33648, 10497), uv=uv))
    np.testing.assert_allclose(colours(offscreen, scene), [GREEN, RED, GREY, BLUE], atol=6)


def test_a_nearest_sampler_keeps_texels_sharp(offscreen, tmp_path):
    """magFilter NEAREST: a pixel just left of the quad's middle shows the red texel itself; linear
    filtering shows it blended towards green."""
    near = load(checker_quad(tmp_path / "near.gltf", mag_filter=9728))
    smooth = load(checker_quad(tmp_path / "smooth.gltf"))
    at = lambda scene: (offscreen.renderer.set_scene(scene),
                        offscreen.render(CAMERA, view="albedo")[pixel(scene, (-0.08, 0.5))][:3].astype(float))[1]
    np.testing.assert_allclose(at(near), RED, atol=3)
    assert np.abs(at(smooth) - RED).max() > 30


def test_a_lit_textured_quad_is_brighter_where_its_texture_is(offscreen, tmp_path):
    """In the final view the texture is the albedo the light reflects from: under one lamp, each quarter's
    colour follows its texel (red quarter reddest, green greenest, ...)."""
    quad = load(checker_quad(tmp_path / "checker.gltf"))
    lamp = ceiling_lamp(half_size=0.3, height=1.0, radiance=10.0)
    lamp = Scene("lamp", lamp.vertices[:, [0, 2, 1]] * [1, 1, -1] + [0, 0, 2.0], lamp.faces[:, ::-1], 0.0, 10.0, 0,
                 ("lamp",))   # facing -z, towards the quad
    lit = colours(offscreen, Scene.concatenate("lit", [quad, lamp]), view="final")
    assert np.all(lit > 5), lit
    for quarter, channel in ((0, 0), (1, 1), (2, 2)):
        assert np.argmax(lit[quarter]) == channel, lit


def test_khronos_texture_coordinate_test_shows_as_its_screenshot(offscreen):
    """TextureCoordinateTest seen from -z, as its screenshot shows it: yellow top-left, red top-right, blue
    bottom-left, green bottom-right, each the image's own corner (four greys here) times its factor."""
    from pathlib import Path

    from viewer.gpu.camera import view_projection
    from viewer.scene.textures import SRGB_TABLE

    scene = load(Path(__file__).resolve().parent.parent / "data" / "gltf" / "TextureCoordinateTest-greys.gltf")
    camera = Camera((0.0, 0.0, -4.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 45.0)
    offscreen.renderer.set_scene(scene)
    image = offscreen.render(camera, view="albedo").astype(float)
    matrix = view_projection(camera, 1.0, *scene.bounds)
    squares = {(0.7, 0.7): ((1, 1, 0), 255), (-0.7, 0.7): ((1, 0.1, 0), 200), (0.7, -0.7): ((0, 0.2, 1), 150),
               (-0.7, -0.7): ((0, 1, 0), 100)}
    for (x, y), (factor, grey) in squares.items():
        clip = matrix @ np.array([x, y, 0.0, 1.0])
        column, row = ((clip[:2] / clip[3] * [1, -1] + 1) / 2 * SIZE).astype(int)
        linear = np.asarray(factor) * SRGB_TABLE[grey]
        encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055) * 255
        np.testing.assert_allclose(image[row, column, :3], encoded, atol=3, err_msg=f"square at {x}, {y}")
        # seen from -z, +x is on the picture's left: TopLeft (x, y > 0) is the top-left square
        assert (column < SIZE[0] // 2) == (x > 0) and (row < SIZE[1] // 2) == (y > 0)


def test_srgb_texels_are_decoded_to_linear_before_they_are_blended(offscreen, tmp_path):
    """Halfway between a black and a white texel the albedo is linear 0.5 (shown as sRGB 188), not the
    sRGB code halfway between them (128, linear 0.21): the texture unit decodes, then filters."""
    pixels = np.array([[[0, 0, 0], [255, 255, 255]]], np.uint8)
    scene = load(checker_quad(tmp_path / "ramp.gltf", pixels=pixels, wrap=(33071, 33071)))
    offscreen.renderer.set_scene(scene)
    image = offscreen.render(CAMERA, view="albedo").astype(float)
    np.testing.assert_allclose(image[pixel(scene, (0.0, 0.0))][:3], [188, 188, 188], atol=5)


def test_every_view_draws_a_textured_scene(offscreen, tmp_path):
    """Every view draws a textured scene, those that show no albedo (normals, voxels) among them; the lit
    views are black here (no lamp)."""
    from viewer.gpu.renderer import VIEWS
    from viewer.rays.voxels import voxelize

    scene = load(checker_quad(tmp_path / "checker.gltf"))
    offscreen.renderer.set_scene(scene)
    offscreen.renderer.set_voxels(voxelize(scene, 8))
    for view in VIEWS:
        image = offscreen.render(CAMERA, view=view)
        assert image[pixel(scene, (0.0, 0.0))][:3].max() > 0 or view in ("final", "direct", "indirect", "probes"), view


def test_the_final_gather_reads_the_texture_where_its_rays_land(gl_context, tmp_path):
    """What a lightmap texel reflects into the final gather is its face's albedo times the texture there
    (over the texture's mean), not the face's mean colour: the checker's red quarter reflects red."""
    from viewer.gpu.direct_bake import BakedDirectLight
    from viewer.gpu.indirect_bake import BakedIndirectLight
    from viewer.gpu.lightmap_update import reflectance, texture_ratio

    scene = load(checker_quad(tmp_path / "quad.gltf"))
    lightmap = BakedDirectLight(gl_context, scene, 0.05)
    bake = BakedIndirectLight(gl_context, lightmap, scene)
    try:
        pixels, faces = bake._covered            # as if a ray landed on every covered pixel
        texels = np.arange(len(pixels)) % len(lightmap.texel_points)
        ratio = texture_ratio(scene, lightmap, faces, texels)
        face_albedo = np.ascontiguousarray(scene.albedo[scene.face_areas > 0], np.float32)
        albedo, reflected = (np.empty((len(pixels), 3), np.float32) for _ in range(2))
        direct = np.ones((pixels.max() + 1, 3), np.float32)
        reflectance(pixels, faces, face_albedo, ratio, direct, np.ones(3, np.float32), albedo, reflected)
        np.testing.assert_array_equal(reflected, albedo)
        front = albedo[:len(lightmap.texel_points)]
        x, y = lightmap.texel_points[:, 0], lightmap.texel_points[:, 1]
        inner = (np.abs(np.abs(x) - 0.5) < 0.1) & (np.abs(np.abs(y) - 0.5) < 0.1)   # the texels' centres
        quarters = [inner & (x * sx > 0) & (y * sy > 0) for sx, sy in ((-1, 1), (1, 1), (-1, -1), (1, -1))]
        red, green, blue, grey = (front[q].mean(axis=0) for q in quarters)
        assert red[0] > 3 * red[1] and green[1] > 3 * green[0] and blue[2] > 3 * blue[0]   # (bilinear blends)
        assert abs(grey[0] - grey[2]) < 0.1 * grey[0] and grey[0] > green[0]
        np.testing.assert_allclose(front.mean(axis=0), scene.albedo[0], rtol=0.1)   # the texture's mean: the face's
    finally:
        bake.release()
        lightmap.release()
