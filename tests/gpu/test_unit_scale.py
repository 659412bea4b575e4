"""Any unit renders: the Cornell box modelled in hundredths of a unit, in units, in twenties, in
centimetres (100) and at 10,000 units gives the same picture, from a lightmap of the same size, and a
lightmap never grows past its texel budget or the GL context's texture size.

The lightmap's texel is a fraction of the scene's longest side (RenderSettings.lightmap_texel): the
Cornell box keeps its 0.02 units, a box 100 times larger gets texels 100 times larger, the same atlas.
Radiance does not change when a scene is scaled (areas and squared distances scale alike), so the
pictures agree up to float32 rounding of positions that differ in magnitude. Measured at 64x48: GI off
gives identical pictures at every scale; a lit room with GI from the solver differs from the one-unit
room by 0.03 at most on average and by 1 in any pixel (8-bit values), where turning its GI off moves the
mean by 30. The bounds below (a mean of 0.5, a pixel of 8) leave room for other llvmpipe versions and
still catch a lost bounce or a lightmap of the wrong texels.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scenes import box, lit_room
from viewer import sources
from viewer.gpu import direct_bake
from viewer.gpu.camera import look_at
from viewer.gpu.direct_bake import MAX_ATLAS_TEXELS, fitted_texel, lightmap_layout
from viewer.gpu.offscreen import OffscreenRenderer
from viewer.gpu.render_settings import RenderSettings
from viewer.physical.gi import GISettings
from viewer.scene import Scene, SceneError, load
from viewer.scene.camera import framing_camera

SCALES = (0.01, 1.0, 20.0, 100.0, 10000.0)
SIZE = (64, 48)
CORNELL_ATLAS = (2048, 189)
"""The Cornell box's lightmap at its 0.02-unit texels: 0.39 M texels a side."""


@pytest.fixture(scope="module")
def cornell():
    return load("cornell")


def scaled(scene: Scene, factor: float) -> Scene:
    return dataclasses.replace(scene, vertices=scene.vertices * factor)


def render(ctx, scene: Scene, probes=None, settings: RenderSettings | None = None, camera=None):
    """(the 8-bit picture from `camera` (the framing one), the lightmap's atlas size, its texel spacing)."""
    offscreen = OffscreenRenderer(SIZE, settings, samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(scene)
        offscreen.renderer.set_probes(probes)
        image = offscreen.render(camera or framing_camera(*scene.bounds)).astype(np.float64)
        baked = offscreen.renderer._baked
        return image, baked.size, baked.texel
    finally:
        offscreen.release()


def assert_same_picture(image, reference):
    difference = np.abs(image - reference)
    assert difference.mean() <= 0.5 and difference.max() <= 8, (difference.mean(), difference.max())


def test_the_cornell_box_keeps_its_texel(gl_context, cornell):
    _, size, texel = render(gl_context, cornell)
    assert texel == 0.02 and size == CORNELL_ATLAS


def test_gi_off_is_the_same_picture_at_every_scale(gl_context, cornell):
    reference, _, _ = render(gl_context, cornell)
    for factor in SCALES:
        image, size, texel = render(gl_context, scaled(cornell, factor))
        assert size == CORNELL_ATLAS, factor                       # the same memory at every scale
        assert texel == pytest.approx(0.02 * factor, rel=1e-12)
        assert_same_picture(image, reference)


def test_gi_is_the_same_picture_at_every_scale(gl_context):
    room = lit_room(box(0.3, centre=(0.2, -0.7, 0.0)))
    settings = GISettings(voxels=16, probes=8)
    render_settings = RenderSettings(final_gather=32)
    options = sources.SolveOptions(include_emitted=False)
    pictures = []
    for factor in SCALES:
        scene = scaled(room, factor)
        probes = sources.SOURCES["solver"].solve(scene, settings, options)[0]
        camera = look_at((0.0, 0.1 * factor, 0.95 * factor), (0.0, -0.2 * factor, -factor), fov=70.0)
        image, size, _ = render(gl_context, scene, probes, render_settings, camera)
        pictures.append((image, size))
    reference, reference_size = pictures[SCALES.index(1.0)]
    assert reference.mean() > 20          # lit, not black
    for image, size in pictures:
        assert size == reference_size
        assert_same_picture(image, reference)


def test_a_lightmap_past_the_budget_gets_coarser_texels(gl_context, cornell, monkeypatch):
    monkeypatch.setattr(direct_bake, "MAX_ATLAS_TEXELS", 2048 * 48)   # a quarter of what it wants
    reference, _, _ = render(gl_context, cornell)
    image, (width, height), texel = render(gl_context, scaled(cornell, 100.0))
    assert width * height <= 2048 * 48 and texel > 2.0
    assert_same_picture(image, reference)    # the same coarse lightmap: only its texels grew


def test_the_atlas_fits_the_texture_size_and_the_budget(cornell):
    for factor in SCALES:
        scene = scaled(cornell, factor)
        texel = fitted_texel(scene, 0.002 * factor, max_side=4096)    # ten times finer than the default
        _, _, (width, height) = lightmap_layout(scene, texel)
        assert 2 * width <= 4096 and height <= 4096 and width * height <= MAX_ATLAS_TEXELS
    assert fitted_texel(cornell, 0.02, max_side=16384) == 0.02       # what fits stays as asked


def test_too_many_faces_for_any_lightmap_are_drawn_per_fragment_with_one_line(tmp_path, monkeypatch, capsys):
    """A scene with more faces than a lightmap holds is not refused: capture draws it without lightmaps
    (the direct light and the probes per fragment) and says so in one line."""
    grid = np.stack(np.meshgrid(np.arange(31.0), np.arange(31.0), indexing="ij"), -1).reshape(-1, 2)
    vertices = np.column_stack([grid, np.zeros(len(grid))])
    corner = (np.arange(30)[:, None] * 31 + np.arange(30)[None]).ravel()
    faces = np.concatenate([np.stack([corner, corner + 31, corner + 1], 1),
                            np.stack([corner + 1, corner + 31, corner + 32], 1)])    # 1800 faces
    with pytest.raises(SceneError, match="1800 faces"):
        fitted_texel(Scene("floor", vertices, faces, 0.5, 0.0, 0, ("floor",)), 0.01, 16384, max_texels=9 * 1000)

    path = tmp_path / "floor.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces))
    monkeypatch.setattr(direct_bake, "MAX_ATLAS_TEXELS", 9 * 1000)
    from viewer.cli import main

    status = main(["capture", str(path), "--out", str(tmp_path / "floor.png"), "--size", "16x16", "--gi", "off",
                   "--sun", "0,0,1,1,1,1"])   # lit: the per-fragment note is the only line
    error = capsys.readouterr().err.strip().splitlines()
    notes = [line for line in error if "1800 faces" in line]
    assert status == 0 and len(notes) == 1 and "per fragment" in notes[0], error
    assert (tmp_path / "floor.png").exists()


def test_a_renderer_draws_a_scene_past_its_lightmap_per_fragment(gl_context, cornell, monkeypatch):
    """The same picture as the exact path (baked=False) gives: the lightmaps are left out, nothing else."""
    many = Scene.concatenate("many", [scaled(cornell, 1.0)] * 30)    # 1080 faces, all in the same place
    monkeypatch.setattr(direct_bake, "MAX_ATLAS_TEXELS", 9 * 1000)
    offscreen = OffscreenRenderer(SIZE, samples=0, ctx=gl_context)
    exact = OffscreenRenderer(SIZE, dataclasses.replace(offscreen.renderer.settings, baked=False), samples=0,
                              ctx=gl_context)
    try:
        offscreen.renderer.set_scene(many)
        assert not offscreen.renderer.lightmapped
        exact.renderer.set_scene(many)
        image, reference = offscreen.render(cornell.camera), exact.render(cornell.camera)
        assert image.max() > 50
        np.testing.assert_array_equal(image, reference)
        offscreen.renderer.set_scene(cornell)
        assert offscreen.renderer.lightmapped
        offscreen.renderer.settings.lightmap_faces = 30      # the box's 36 faces are past the budget
        assert not offscreen.renderer.lightmapped
        exact.renderer.set_scene(cornell)
        np.testing.assert_array_equal(offscreen.render(cornell.camera), exact.render(cornell.camera))
    finally:
        offscreen.release()
        exact.release()
