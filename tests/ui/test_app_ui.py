"""The viewer's pieces that need no window: the imgui renderer (imgui >= 1.92 texture protocol) on a
headless EGL context, the camera controller, and the CPU solver worker (the viewport's redraws:
test_viewport.py; the panel's scene edits: test_scene_edits.py)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from scenes import box, group_corners
from viewer.physical.gi import GISettings
from viewer.scene import Camera, load
from viewer.ui.camera_controller import OrbitCamera

imgui = pytest.importorskip("imgui_bundle").imgui


@pytest.fixture(scope="session")
def ctx(gl_context):
    return gl_context


# ---- imgui renderer -----------------------------------------------------------------------------------

@pytest.fixture
def imgui_frame(ctx):
    """An imgui context with the moderngl renderer, and a function drawing one frame into an RGBA8 image."""
    from viewer.ui.imgui_renderer import ImguiRenderer

    context = imgui.create_context()
    imgui.get_io().set_ini_filename(None)
    imgui.get_io().display_size = (320.0, 120.0)
    renderer = ImguiRenderer(ctx)
    target = ctx.simple_framebuffer((320, 120), components=4)

    def frame(draw) -> np.ndarray:
        imgui.get_io().delta_time = 1 / 60
        imgui.new_frame()
        imgui.set_next_window_pos(imgui.ImVec2(0, 0))
        imgui.set_next_window_size(imgui.ImVec2(320, 120))
        imgui.begin("test", None, imgui.WindowFlags_.no_decoration)
        draw()
        imgui.end()
        imgui.render()
        target.use()
        target.clear(0.0, 0.0, 0.0, 1.0)
        renderer.render(imgui.get_draw_data(), target)
        pixels = np.frombuffer(target.read(components=4), np.uint8).reshape(120, 320, 4)
        return pixels[::-1]

    yield frame, renderer
    renderer.shutdown()
    target.release()
    imgui.destroy_context(context)


def _gpu_copies_match(renderer) -> None:
    """Every imgui texture is uploaded (status ok) and the GL copy holds imgui's pixels."""
    textures = list(imgui.get_platform_io().textures)
    assert textures, "imgui made no textures"
    for texture in textures:
        assert texture.status == imgui.ImTextureStatus.ok
        gl_texture = renderer.textures[texture.tex_id]
        assert gl_texture.size == (texture.width, texture.height)
        cpu = np.asarray(texture.get_pixels_array(), np.uint8).reshape(texture.height, texture.width, 4)
        gpu = np.frombuffer(gl_texture.read(), np.uint8).reshape(texture.height, texture.width, 4)
        np.testing.assert_array_equal(gpu, cpu)


def test_font_atlas_is_uploaded_through_the_texture_protocol_and_text_is_drawn(imgui_frame):
    frame, renderer = imgui_frame
    assert imgui.get_io().backend_flags & imgui.BackendFlags_.renderer_has_textures
    blank = frame(lambda: None)
    image = frame(lambda: imgui.text("Hello, light probes"))
    _gpu_copies_match(renderer)
    # The window background is the same in both; the text adds bright glyph pixels on the first line.
    changed = np.abs(image[..., :3].astype(int) - blank[..., :3]).max(axis=2) > 64
    assert changed[:30].sum() > 100, "no text drawn"
    assert changed[40:].sum() == 0, "pixels changed away from the text line"


def test_new_glyph_sizes_update_the_gpu_copy(imgui_frame):
    frame, renderer = imgui_frame
    frame(lambda: imgui.text("small"))
    def big():
        imgui.push_font(None, 48.0)   # imgui 1.92 bakes glyphs of a new size on demand: atlas updates
        imgui.text("BIG Wq")
        imgui.pop_font()
    frame(big)
    image = frame(big)
    _gpu_copies_match(renderer)
    rows = np.flatnonzero((image[..., :3].max(axis=2) > 128).any(axis=1))
    assert rows.max() - rows.min() > 30, "48 px glyphs not drawn"


def test_a_renderer_after_shutdown_recreates_the_textures(ctx):
    """shutdown releases the GL copies; imgui then asks the next renderer to create them again."""
    from viewer.ui.imgui_renderer import ImguiRenderer

    context = imgui.create_context()
    imgui.get_io().set_ini_filename(None)   # no imgui.ini in the working folder
    target = ctx.simple_framebuffer((64, 64))
    try:
        imgui.get_io().display_size = (64.0, 64.0)

        def frame(renderer):
            imgui.new_frame()
            imgui.text("x")
            imgui.render()
            renderer.render(imgui.get_draw_data(), target)

        first = ImguiRenderer(ctx)
        frame(first)
        assert first.textures
        first.shutdown()
        assert not first.textures
        textures = list(imgui.get_platform_io().textures)
        assert all(t.tex_id == 0 and t.status == imgui.ImTextureStatus.want_create for t in textures)
        second = ImguiRenderer(ctx)
        frame(second)
        _gpu_copies_match(second)
        second.shutdown()
    finally:
        target.release()
        imgui.destroy_context(context)


# ---- camera controller --------------------------------------------------------------------------------

def _distance(camera: Camera) -> float:
    return float(np.linalg.norm(np.subtract(camera.origin, camera.target)))


def test_orbit_keeps_target_and_distance_and_reset_returns_home():
    home = Camera((0.0, 0.0, 3.9), (0.0, 0.0, 0.0))
    controller = OrbitCamera(home, scene_size=2.0)
    controller.orbit(150, -60)
    moved = controller.camera()
    assert moved.target == pytest.approx(home.target)
    assert _distance(moved) == pytest.approx(3.9)
    assert moved.origin[0] < -1.0   # dragging right swings the eye to the left (the scene turns right)
    controller.reset()
    assert controller.camera().origin == pytest.approx(home.origin, abs=1e-12)


def test_pan_moves_eye_and_target_together_and_zoom_only_distance():
    controller = OrbitCamera(Camera((0.0, 0.0, 3.9), (0.0, 0.0, 0.0)), scene_size=2.0)
    before = controller.camera()
    controller.pan(100, 0, viewport_height=720)
    after = controller.camera()
    shift = np.subtract(after.target, before.target)
    assert np.subtract(after.origin, before.origin) == pytest.approx(shift)
    assert shift[0] < 0 and abs(shift[1]) < 1e-12   # dragging right slides the scene right: the view left
    controller.zoom(2)
    assert _distance(controller.camera()) == pytest.approx(3.9 * controller.settings.zoom_step ** 2)
    assert controller.camera().target == pytest.approx(after.target)


def test_fly_look_turns_around_the_eye_and_moves_forward():
    controller = OrbitCamera(Camera((0.0, 0.0, 3.9), (0.0, 0.0, 0.0)), scene_size=2.0)
    controller.look(200, 0)
    assert controller.camera().origin == pytest.approx((0.0, 0.0, 3.9))
    _, _, forward = controller.basis()
    eye = controller.eye.copy()
    controller.fly(1, 0, 0, seconds=0.5)
    expected = controller.settings.fly_speed * 2.0 * 0.5
    assert controller.eye - eye == pytest.approx(expected * forward)


# ---- the CPU solver off the render thread -------------------------------------------------------------

TINY = GISettings(voxels=8, probes=2, directions=32, bounces=4)


def _wait(poll, timeout: float = 600.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        result = poll()
        if result is not None:
            return result
        time.sleep(0.05)
    raise AssertionError("no result in time")


def test_solver_process_reports_stages_and_the_latest_request_wins():
    from viewer.ui.background import SOLVER_STAGES, SolverProcess

    solver = SolverProcess(debounce=0.0)
    try:
        small = box(inward=True, albedo=0.5, emission=1.0, half_size=1.0)
        large = box(inward=True, albedo=0.5, emission=1.0, half_size=2.0)
        solver.request(small, TINY)
        solver.request(large, TINY)   # before the first one is done: only this one may come back
        grid = _wait(solver.poll)
        assert grid.hi == pytest.approx([2.0, 2.0, 2.0])
        assert solver.stages_done == list(SOLVER_STAGES) and not solver.busy
        # The furnace: in free space the indirect part of L = 2 is 1 (the emitted 1 is shaded directly).
        assert grid.coefficients[..., 0, :] * 0.282095 == pytest.approx(np.ones((2, 2, 2, 3)), rel=0.1)
    finally:
        solver.close()


def test_gi_controller_switches_sources_and_reuses_a_finished_solve():
    from viewer.ui.gi_sources import GIController
    from viewer.ui.gi_sources import MODELS

    gi = GIController(ctx=None, source="solver", settings=TINY)
    shipped = (MODELS / "probenet.onnx").is_file()
    try:
        assert ("neural" in gi.unavailable) == (not shipped)
        gi.set_scene(box(inward=True, albedo=0.5, emission=1.0), version=1)
        grid = _wait(lambda: (lambda changed, g: g if changed else None)(*gi.update()))
        assert "done" in gi.status()[0]
        gi.set_source("off")
        assert gi.update() == (True, None)
        gi.set_source("solver")
        changed, again = gi.update()
        assert changed and again is grid and not gi.busy
        if not shipped:
            gi.set_source("neural")       # not available: ignored
            assert gi.source == "solver"
    finally:
        gi.close()


def test_compute_source_solves_only_the_latest_of_quick_edits(ctx):
    from viewer.ui.gi_sources import GIController

    gi = GIController(ctx, source="compute", settings=TINY)
    if gi.source != "compute":
        pytest.skip(gi.unavailable["compute"])
    for version, size in enumerate((1.0, 1.5, 2.0), start=1):   # a slider dragged: three scenes at once
        gi.set_scene(box(inward=True, albedo=0.5, emission=1.0, half_size=size), version=version)
    grids = []
    deadline = time.monotonic() + 600.0
    while (gi.busy or not grids) and time.monotonic() < deadline:
        changed, grid = gi.update()
        if changed:
            grids.append(grid)
        time.sleep(0.01)
    assert not gi.busy and "converged" in gi.status()[0]
    assert all(g.hi == pytest.approx([2.0, 2.0, 2.0]) for g in grids), "probes of an outdated scene shown"
    indirect = grids[-1].coefficients[..., 0, :] * 0.282095
    assert indirect == pytest.approx(np.ones_like(indirect), rel=0.1)   # furnace: indirect L = 1


def _new_probes(session):
    """Step the session until its GI source is idle with probes newer than it had: the renderer's."""
    version = session.probes_version
    deadline = time.monotonic() + 600.0
    while (session.gi.busy or session.probes_version == version) and time.monotonic() < deadline:
        session.update("final")
        time.sleep(0.02)
    assert not session.gi.busy and session.renderer.probes is not None
    return session.renderer.probes


def test_recolouring_a_wall_updates_the_indirect_light_in_the_background(ctx, cornell):
    """An edit re-renders at once and re-solves the GI off the render thread; the new probes replace the
    old ones when done: a red wall made blue turns the light bouncing off it blue."""
    from viewer.gpu.renderer import RenderSettings, Renderer
    from viewer.ui.gi_sources import GIController
    from viewer.ui.session import Session

    renderer = Renderer(ctx, RenderSettings(light_samples=4))
    gi = GIController(ctx, source="solver", settings=GISettings(voxels=16, probes=4, directions=64, bounces=20))
    session = Session(renderer, gi, cornell, "cornell", log=lambda line: None, edit_interval=0.0)
    near_left_wall = np.array([[-0.8, 0.0, 0.0]])

    def solved():
        return _new_probes(session)

    try:
        before = solved().irradiance(near_left_wall, np.array([[-1.0, 0.0, 0.0]]))[0]
        scene_version = session.scene_version
        session.edits.set_albedo("red-wall", (0.05, 0.05, 0.8))
        session.update("final")
        assert session.scene_version > scene_version and gi.busy          # shown at once, solving
        assert renderer.scene.group_albedo("red-wall") == pytest.approx([0.05, 0.05, 0.8])
        after = solved().irradiance(near_left_wall, np.array([[-1.0, 0.0, 0.0]]))[0]
        assert before[0] > before[2] and after[2] > after[0], (before, after)
    finally:
        session.close()
        renderer.release()


def test_the_neural_source_warns_on_a_scene_outside_its_training_domain(ctx, imgui_frame):
    """A nearly white wall (albedo 0.99, the shipped model trained up to 0.95) shown by the neural source:
    a warning names the albedo and points to the physical solver, stays on screen (drawn in the messages
    window), and goes when an edit brings the scene back inside."""
    from viewer.gpu.renderer import RenderSettings, Renderer
    from viewer.ui.gi_sources import GIController
    from viewer.ui.panels import WARNING_COLOUR, messages_window
    from viewer.ui.session import Session

    gi = GIController(ctx, source="neural", settings=GISettings(voxels=16, probes=16))
    if gi.source != "neural":
        pytest.skip(gi.unavailable["neural"])
    renderer = Renderer(ctx, RenderSettings(light_samples=4))
    white = load("cornell").with_albedo("back", (0.99, 0.99, 0.99))
    session = Session(renderer, gi, white, "white", log=lambda line: None, edit_interval=0.0)

    def settle():
        deadline = time.monotonic() + 600.0
        session.update("final")
        while gi.busy and time.monotonic() < deadline:
            time.sleep(0.01)
            session.update("final")
        assert not gi.busy and gi.status()[2] is None

    try:
        settle()
        [message] = [m for m in session.messages if m.warning]
        assert "outside what the neural model was trained on" in message.text
        assert "'back' albedo 0.99 is above the trained 0.95" in message.text and "physical solver" in message.text
        assert gi.domain_warning == message.text
        frame, _ = imgui_frame
        for _ in range(2):   # an auto-sized window is measured in its first frame, drawn from the second
            image = frame(lambda: messages_window(session.messages, None, info_seconds=0.0))
        amber = np.array([WARNING_COLOUR.x, WARNING_COLOUR.y, WARNING_COLOUR.z]) * 255
        assert (np.abs(image[..., :3].astype(float) - amber).max(axis=2) < 40).sum() > 50, "warning not drawn"
        session.edits.set_albedo("back", (0.8, 0.8, 0.8))
        settle()
        assert not any(m.warning for m in session.messages) and gi.domain_warning is None
    finally:
        session.close()
        renderer.release()


def test_an_object_moved_in_the_panel_moves_the_shown_light(ctx, imgui_frame):
    """The objects section draws its picker and position; an object moved through the session gives the
    neural source's new probes for the scene with the box elsewhere (its shadow moves), as a fresh solve
    of that scene gives them."""
    from viewer.gpu.renderer import RenderSettings, Renderer
    from viewer.neural.field import NeuralField
    from viewer.ui.edit_panels import objects_section
    from viewer.ui.gi_sources import GIController
    from viewer.ui.session import Session

    gi = GIController(ctx, source="neural", settings=GISettings(voxels=16, probes=16))
    if gi.source != "neural":
        pytest.skip(gi.unavailable["neural"])
    renderer = Renderer(ctx, RenderSettings(light_samples=4))
    session = Session(renderer, gi, load("cornell"), "cornell", log=lambda line: None, edit_interval=0.0)

    def settled():
        probes = _new_probes(session)
        assert gi.status()[2] is None
        return probes

    try:
        before = settled()
        frame, _ = imgui_frame
        image = frame(lambda: objects_section(session.edits, session.scene_size))
        assert (image[..., :3].max(axis=2) > 100).sum() > 200, "the section drew nothing"
        session.edits.set_offset("small-box", (-0.3, 0.0, 0.25))
        after = settled()
        moved = session.scene
        np.testing.assert_allclose(group_corners(moved, "small-box"),
                                   group_corners(load("cornell"), "small-box") + [-0.3, 0.0, 0.25])
        fresh = NeuralField().solve(moved, include_emitted=False)
        assert np.abs(after.coefficients - before.coefficients).max() > 0.01 * np.abs(before.coefficients).max()
        np.testing.assert_allclose(after.coefficients, fresh.coefficients, atol=1e-4 * np.abs(fresh.coefficients).max())
    finally:
        session.close()
        renderer.release()
