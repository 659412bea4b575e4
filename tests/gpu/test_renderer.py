"""The renderer, headless through EGL (Mesa llvmpipe in CI): what a user sees in the Cornell box.

Images are small (96x96) so the whole file runs in seconds on a CPU rasterizer. Regions are fractions
of the image: (top, bottom, left, right).
"""

from __future__ import annotations

import shutil
from argparse import Namespace

import numpy as np
import pytest
from PIL import Image

from pictures import pixel_on_plane
from viewer.probes import sh
from viewer.capture import capture_request, run_capture
from viewer.gpu.offscreen import OffscreenRenderer, capture
from viewer.gpu.programs import SHADERS, ShaderError
from viewer.gpu.renderer import VIEWS, RenderSettings, Renderer
from viewer.gpu.targets import DisplayTarget, HdrTarget
from viewer.probes.grid import ProbeGrid
from viewer.scene import load
from viewer.rays.voxels import voxelize

SIZE = (96, 96)
RED_WALL = (0.2, 0.6, 0.02, 0.12)
GREEN_WALL = (0.2, 0.6, 0.88, 0.97)
FLOOR_FRONT_LEFT = (0.9, 0.98, 0.1, 0.4)
SMALL_BOX_FRONT = (0.72, 0.84, 0.53, 0.72)   # faces the camera, away from the lamp: no direct light


@pytest.fixture(scope="session")
def ctx(gl_context):
    return gl_context


@pytest.fixture(scope="module")
def cornell():
    return load("cornell")


def constant_probes(scene, radiance, resolution: int = 4) -> ProbeGrid:
    """Probes that all see the same uniform radiance (RGB) from every direction."""
    c = np.zeros((resolution,) * 3 + (9, 3), np.float32)
    c[..., 0, :] = np.asarray(radiance, np.float32) / sh.basis(np.array([0.0, 0.0, 1.0]))[0]
    lo, hi = scene.bounds
    return ProbeGrid(lo, hi, c, np.ones((resolution,) * 3, bool))


@pytest.fixture(scope="module")
def offscreen(ctx, cornell):
    renderer = OffscreenRenderer(SIZE, samples=0, ctx=ctx)
    renderer.renderer.set_scene(cornell)
    yield renderer
    renderer.release()


def region(image: np.ndarray, box) -> np.ndarray:
    """Mean colour (3,) of a region given as fractions (top, bottom, left, right)."""
    h, w = image.shape[:2]
    top, bottom, left, right = box
    return image[int(top * h):int(bottom * h), int(left * w):int(right * w)].reshape(-1, 3).mean(axis=0)


def test_cornell_box_has_a_red_left_wall_a_green_right_wall_and_a_lit_floor(offscreen, cornell):
    offscreen.renderer.set_probes(constant_probes(cornell, [0.2, 0.2, 0.2]))
    image = offscreen.render().astype(np.float64) / 255.0
    r, g, b = region(image, RED_WALL)
    assert r > 2 * g and r > 2 * b and r > 0.3, f"left wall {r:.2f} {g:.2f} {b:.2f} is not red"
    r, g, b = region(image, GREEN_WALL)
    assert g > 1.5 * r and g > 1.5 * b and g > 0.2, f"right wall {r:.2f} {g:.2f} {b:.2f} is not green"
    floor = region(image, FLOOR_FRONT_LEFT)
    assert floor.mean() > 0.4, f"floor {floor} is not lit"
    # The lamp is at the top centre, drawn with its own (saturating) radiance.
    lamp = region(image, (0.13, 0.15, 0.45, 0.55))
    assert lamp.min() > 0.95


def test_direct_light_has_no_indirect_part_and_gi_lights_the_shadows(ctx, cornell):
    """A uniform probe field read as it is: without the final gather, which would light the box face
    with what the room reflects of the lamp (test_final_gather.py)."""
    offscreen = OffscreenRenderer(SIZE, RenderSettings(final_gather=0), samples=0, ctx=ctx)
    try:
        check_direct_and_uniform_indirect(offscreen, cornell)
    finally:
        offscreen.release()


def check_direct_and_uniform_indirect(offscreen, cornell):
    renderer = offscreen.renderer
    renderer.set_scene(cornell)
    renderer.set_probes(None)
    dark = region(offscreen.render_hdr(view="final"), SMALL_BOX_FRONT)
    renderer.set_probes(constant_probes(cornell, [0.3, 0.3, 0.3]))
    lit = region(offscreen.render_hdr(view="final"), SMALL_BOX_FRONT)
    indirect_only = region(offscreen.render_hdr(view="indirect"), SMALL_BOX_FRONT)
    assert np.all(dark < 0.01), f"the box face turned from the lamp gets direct light: {dark}"
    assert np.all(lit > dark + 0.1)
    # Uniform radiance L gives irradiance pi L and outgoing albedo * L on any surface.
    albedo = cornell.group_albedo("small-box")
    np.testing.assert_allclose(indirect_only, albedo * 0.3, rtol=0.03)


@pytest.mark.parametrize("interleave", [True, False])
def test_every_view_renders_finite_values(ctx, cornell, interleave):
    probes = constant_probes(cornell, [0.5, 0.4, 0.3], resolution=6)
    offscreen = OffscreenRenderer(SIZE, RenderSettings(interleave=interleave), samples=0, ctx=ctx)
    try:
        renderer = offscreen.renderer
        renderer.set_scene(cornell)
        renderer.set_probes(probes)
        renderer.set_voxels(voxelize(cornell, 16))
        for view in VIEWS:
            hdr = offscreen.render_hdr(view=view)
            assert np.all(np.isfinite(hdr)), f"view {view}: NaN or infinity"
            assert hdr.max() > 0.05, f"view {view}: nothing drawn"
            display = offscreen.render(view=view)
            assert display.shape == (SIZE[1], SIZE[0], 3)
    finally:
        offscreen.release()


def test_probe_textures_clamp_at_the_edges(ctx, cornell):
    """Probes bright only in the +x layer must not light the opposite (-x) wall: a repeating texture
    would blend that layer into the other edge of the box."""
    m = 4
    lo, hi = cornell.bounds
    c = np.zeros((m, m, m, 9, 3), np.float32)
    c[m - 1, :, :, 0, :] = 5.0
    probes = ProbeGrid(lo, hi, c, np.ones((m, m, m), bool))
    offscreen = OffscreenRenderer(SIZE, RenderSettings(probe_normal_offset=0.0, final_gather=0), samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(cornell)
        offscreen.renderer.set_probes(probes)
        image = offscreen.render_hdr(view="indirect")
    finally:
        offscreen.release()
    right = region(image, GREEN_WALL).max()
    left = region(image, RED_WALL).max()
    assert right > 0.1
    assert left < 1e-3 * right, f"light from the +x probes leaks onto the -x wall: {left} vs {right}"


def test_a_broken_shader_raises_a_clear_error_and_the_old_program_keeps_working(ctx, cornell, tmp_path):
    shaders = tmp_path / "shaders"
    shutil.copytree(SHADERS, shaders)
    renderer = Renderer(ctx, shader_dir=shaders)
    target = HdrTarget(ctx, SIZE)
    try:
        renderer.set_scene(cornell)
        renderer.draw(target)
        before = target.read()
        source = (shaders / "sh.glsl").read_text().splitlines()
        line = next(i for i, text in enumerate(source) if "y[0] = 0.282095;" in text)
        source[line] = "    y[0] = 0.282095 +;"   # a syntax error in an included file
        (shaders / "sh.glsl").write_text("\n".join(source) + "\n")
        with pytest.raises(ShaderError) as error:
            renderer.reload_shaders()
        assert f"sh.glsl:{line + 1}:" in str(error.value) and "error" in str(error.value)
        renderer.draw(target)
        np.testing.assert_array_equal(target.read(), before)
    finally:
        renderer.release()
        target.release()


def test_capture_writes_a_png_of_the_requested_size(tmp_path, cornell):
    out = tmp_path / "cornell.png"
    image = capture(cornell, None, out, size=(120, 80), samples=2)
    assert image.shape == (80, 120, 3)
    assert Image.open(out).size == (120, 80)


def test_run_capture_checks_its_arguments(tmp_path):
    out = tmp_path / "shot.png"
    args = Namespace(scene="cornell", out=str(out), size="64x48", gi="off", view="normals",
                     camera="0,0,3.9,0,0,0", fov=40.0, exposure=0.0)
    assert run_capture(capture_request(args)) == 0
    assert Image.open(out).size == (64, 48)
    with pytest.raises(ValueError, match="--size"):
        run_capture(capture_request(Namespace(**{**vars(args), "size": "64by48"})))
    with pytest.raises(ValueError, match="--camera"):
        run_capture(capture_request(Namespace(**{**vars(args), "camera": "1,2,3"})))
    with pytest.raises(ValueError, match="--view"):
        run_capture(capture_request(Namespace(**{**vars(args), "view": "xray"})))


def test_direct_light_matches_the_path_tracer(ctx, cornell):
    """Direct light only (Mitsuba: max_depth 2) against our shadow-mapped emitter samples, in linear
    radiance: the mean over the image within 2%, and 90% of pixels within 15% of the reference
    (its own noise at 512 spp is ~5%)."""
    reference = pytest.importorskip("viewer.reference.mitsuba")
    try:
        expected = reference.render(cornell, width=64, height=64, spp=512, max_depth=2)
    except reference.ReferenceUnavailable as exc:
        pytest.skip(str(exc))
    offscreen = OffscreenRenderer((64, 64), samples=8, ctx=ctx)
    try:
        offscreen.renderer.set_scene(cornell)
        ours = offscreen.render_hdr(view="direct")
    finally:
        offscreen.release()
    lum_ours, lum_ref = ours.mean(axis=-1), expected.mean(axis=-1)
    assert abs(lum_ours.mean() / lum_ref.mean() - 1) < 0.02
    lit = lum_ref > 0.05 * lum_ref.mean()
    relative = np.abs(lum_ours[lit] - lum_ref[lit]) / lum_ref[lit]
    assert np.quantile(relative, 0.9) < 0.15


def test_interleaved_direct_light_matches_the_full_sum(ctx, cornell):
    """Each pixel of a 2x2 block sums a quarter of the light samples; the resolve filter must give back
    the full sum: the same image mean, and pixels that differ only by the filter's slight blur (one
    pixel is large at 96x96, where penumbrae are a few pixels wide)."""
    images = {}
    for interleave in (False, True):
        # the exact per-fragment path: the baked lightmap would make both images the same by construction
        settings = RenderSettings(interleave=interleave, baked=False)
        offscreen = OffscreenRenderer(SIZE, settings, samples=0, ctx=ctx)
        try:
            offscreen.renderer.set_scene(cornell)
            images[interleave] = offscreen.render_hdr(view="direct").mean(axis=-1)
        finally:
            offscreen.release()
    exact, interleaved = images[False], images[True]
    assert abs(interleaved.mean() / exact.mean() - 1) < 0.005
    lit = exact > 0.1 * exact.mean()
    relative = np.abs(interleaved[lit] - exact[lit]) / exact[lit]
    assert np.median(relative) < 0.015 and np.quantile(relative, 0.9) < 0.06


@pytest.mark.parametrize("falloff, normal_offset", [(0.0, 0.5), (3.0, 0.75)])
def test_indirect_light_equals_the_probe_grids_irradiance(ctx, cornell, falloff, normal_offset):
    """The GPU path (texture packing, weighted trilinear lookup, SH unpacking, cosine-lobe convolution)
    gives the same outgoing indirect radiance as ProbeGrid in numpy, on walls in four orientations and
    on the small box's front face (a normal off the grid's axes):
    with the plane falloff off and every probe valid it is plain trilinear interpolation
    (`irradiance`), else the weighted 8-probe mean of `surface_irradiance` (here with a few invalid
    probes), which the shader computes as one trilinear fetch at a shifted point."""
    m = 5
    rng = np.random.default_rng(1)
    lo, hi = cornell.bounds
    coefficients = np.zeros((m, m, m, 9, 3), np.float32)
    x = np.linspace(0, 1, m)[:, None, None, None]
    coefficients[..., 0, :] = 1.0 + 0.5 * x                      # varies across the box (interpolation)
    coefficients[..., 1:, :] = 0.15 * rng.standard_normal((m, m, m, 8, 3))
    valid = rng.random((m, m, m)) > (0.2 if falloff else 0.0)
    probes = ProbeGrid(lo, hi, coefficients, valid)
    settings = RenderSettings(probe_normal_offset=normal_offset, probe_plane_falloff=falloff, baked=False)
    offscreen = OffscreenRenderer(SIZE, settings, samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(cornell)
        offscreen.renderer.set_probes(probes)
        image = offscreen.render_hdr(view="indirect")
    finally:
        offscreen.release()
    walls = {  # pixel (column, row), a point on the plane, its normal, its group
        "back": ((60, 30), (0, 0, -1), (0, 0, 1)), "red-wall": ((6, 40), (-1, 0, 0), (1, 0, 0)),
        "floor": ((20, 92), (0, -1, 0), (0, 1, 0)), "ceiling": ((60, 6), (0, 1, 0), (0, -1, 0)),
        "small-box": ((62, 75), (-0.0396029, -1, 0.5791799), (-0.2923717, 0, 0.9563048))}
    offset = settings.probe_normal_offset * probes.spacing.min()
    for group, (pixel, point, normal) in walls.items():
        normal = np.asarray(normal, np.float64)
        p = pixel_on_plane(cornell.camera, SIZE, pixel, point, normal)
        if falloff:
            irradiance = probes.surface_irradiance(p[None], normal[None], normal_offset, falloff)
        else:
            irradiance = probes.irradiance(p[None] + offset * normal, normal[None])
        expected = cornell.group_albedo(group) / np.pi * np.maximum(irradiance[0], 0)
        np.testing.assert_allclose(image[pixel[1], pixel[0]], expected, rtol=0.01, atol=1e-4, err_msg=group)


def inside_group(scene, group: str, points: np.ndarray) -> np.ndarray:
    """Which points lie inside a convex closed group (a box), behind all of its faces' planes."""
    faces = scene.face_group == scene.group_index(group)
    normals = scene.face_normals[faces]
    centres = scene.triangles[faces].mean(axis=1)
    return np.all(np.einsum("pfc,fc->pf", points[:, None] - centres[None], normals) < 0, axis=1)


def box_face_and_floor_radiance(ctx, scene, probes, settings):
    """Indirect radiance of every pixel on the two boxes' faces, and the mean over the floor in front."""
    offscreen = OffscreenRenderer(SIZE, settings, samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(scene)
        offscreen.renderer.set_probes(probes)
        image = offscreen.render_hdr(view="indirect").mean(axis=2)
        normals = offscreen.render_hdr(view="normals")
    finally:
        offscreen.release()
    # the normals view shows n/2 + 1/2: box faces are the pixels with a normal off the room's axes
    n = 2.0 * normals - 1.0
    on_box = (np.abs(n).max(axis=2) < 0.99) & (np.linalg.norm(n, axis=2) > 0.5)
    h, w = SIZE[1], SIZE[0]
    top, bottom, left, right = FLOOR_FRONT_LEFT
    return image[on_box], image[int(top * h):int(bottom * h), int(left * w):int(right * w)].mean()


def test_box_faces_are_not_darkened_by_the_probes_inside_the_boxes(ctx, cornell):
    """Leak reduction (shaders/probe_grid.glsl): every probe in free space sees the same uniform
    radiance; those inside the two boxes see nothing and are invalid, left unfilled (the worst case).
    A uniform radiance field gives every surface the same irradiance, so under indirect light only each
    pixel of the boxes' faces must be as bright as the floor in front of them. Plain trilinear
    interpolation mixes in the dark probes behind the faces: dark blotches, as on the boxes' faces of
    the Cornell box before (the faces' darkest 5% at 65% of the floor, 100% now). The probes as they
    are, without the final gather."""
    m = 24
    lo, hi = cornell.bounds
    probes = constant_probes(cornell, (1.0, 1.0, 1.0), m)
    positions = probes.positions.reshape(-1, 3)
    inside = (inside_group(cornell, "small-box", positions) | inside_group(cornell, "large-box", positions))
    assert inside.sum() > 500
    coefficients = probes.coefficients.reshape(-1, 9, 3).copy()
    coefficients[inside] = 0.0
    probes = ProbeGrid(lo, hi, coefficients.reshape(probes.coefficients.shape), ~inside.reshape(m, m, m))
    faces, floor = box_face_and_floor_radiance(ctx, cornell, probes, RenderSettings(final_gather=0))
    assert len(faces) > 500
    assert np.percentile(faces, 5) > 0.95 * floor, (np.percentile(faces, 5), floor)
    # The same with the probes inside the boxes marked valid: the weight that fades probes behind the
    # shaded surface's plane alone keeps the faces within 10% of the floor (97% measured).
    probes = ProbeGrid(lo, hi, probes.coefficients, np.ones((m, m, m), bool))
    faces, floor = box_face_and_floor_radiance(ctx, cornell, probes, RenderSettings(final_gather=0))
    assert np.percentile(faces, 5) > 0.9 * floor, (np.percentile(faces, 5), floor)


@pytest.mark.parametrize("settings", [RenderSettings(light_samples=8), RenderSettings(
    light_samples=8, tonemap="reinhard", exposure=1.0, baked=False)])
def test_display_image_is_the_hdr_image_tone_mapped(ctx, cornell, settings):
    """Into a display target the surface views are tone-mapped as they are shaded (one pass); the
    voxels and probes views go through an HDR image and the tone-mapping pass. Both give the bytes of
    the HDR image tone-mapped, so a window, a PNG capture and the HDR image agree."""
    offscreen = OffscreenRenderer(SIZE, settings, samples=0, ctx=ctx)
    reference = DisplayTarget(ctx, SIZE)
    try:
        offscreen.renderer.set_scene(cornell)
        offscreen.renderer.set_probes(constant_probes(cornell, (0.2, 0.1, 0.05)))
        for view in ("final", "direct", "indirect", "albedo", "normals", "probes"):
            image = offscreen.render(view=view)
            offscreen.renderer.draw(offscreen.hdr, None, view)
            offscreen.renderer.present(offscreen.hdr, reference, view)
            np.testing.assert_array_equal(image, reference.read(), err_msg=view)
        # the exact path's interleaved direct light is recombined by a filter: through the HDR image
        assert offscreen.renderer.fused(offscreen.display, "final") == settings.baked
    finally:
        reference.release()
        offscreen.release()


def test_a_capture_without_a_camera_shows_what_the_viewer_opens_with(tmp_path):
    """A file without a camera of its own (no sidecar) is framed, in the viewer and in a headless
    capture alike: the Cornell box moved 5 units up is out of the default camera's view, not of the
    capture's."""
    from dataclasses import replace

    from viewer.scene.obj import write as write_obj

    box = load("cornell")
    path = tmp_path / "moved.obj"
    write_obj(replace(box, vertices=box.vertices + [0.0, 5.0, 0.0]), path)
    path.with_suffix(".json").unlink()   # its sidecar names a camera: without it, the file has none
    out = tmp_path / "moved.png"
    args = Namespace(scene=str(path), out=str(out), size="64x48", gi="off", view="albedo")
    assert run_capture(capture_request(args)) == 0
    image = np.asarray(Image.open(out), np.float64)
    assert image[16:32, 24:40].mean() > 40      # the back wall fills the middle
    assert (image.mean(axis=2) > 10).mean() > 0.25   # the framed box, margins around it


def test_a_jittered_frame_is_the_frame_moved_and_supersampling_resolves_a_lamps_edge(ctx, cornell):
    """A jitter of one whole pixel moves the image by one pixel; n x n jittered images averaged in linear
    light give the lamp's edge pixels the share of the lamp they cover (between the ceiling's light and
    the lamp's, where one sample a pixel gives either), and keep the image's mean."""
    offscreen = OffscreenRenderer(SIZE, samples=0, ctx=ctx)
    try:
        offscreen.renderer.set_scene(cornell)
        offscreen.renderer.set_probes(constant_probes(cornell, (0.2, 0.2, 0.2)))
        albedo = offscreen.render_hdr(view="albedo")
        offscreen.renderer.draw(offscreen.hdr, None, "albedo", jitter=(1.0, 0.0))
        moved = offscreen.hdr.read()
        np.testing.assert_array_equal(moved[:, 1:], albedo[:, :-1])
        one = offscreen.render_hdr(view="direct")
        many = offscreen.render_hdr(view="direct", supersample=8)
        lamp = float(np.max(cornell.emission))
        assert one.max() > 0.99 * lamp and many.max() > 0.99 * lamp
        partial = (many.mean(axis=2) > 2.0) & (many.mean(axis=2) < 0.5 * lamp)   # part lamp, part ceiling
        assert partial.sum() >= 0.5 * (np.abs(np.diff(one.mean(axis=2) > 0.5 * lamp, axis=1)).sum())
        assert not ((one.mean(axis=2) > 2.0) & (one.mean(axis=2) < 0.5 * lamp)).any()
        more = offscreen.render_hdr(view="direct", supersample=16)   # the lamp's area converges
        assert abs(many.mean() - more.mean()) < min(0.02 * more.mean(), 0.5 * abs(one.mean() - more.mean()))
    finally:
        offscreen.release()
