"""The imgui windows: the settings panel (scene, GI, light, objects, materials, view, performance), the help
overlay, messages, and the loading indicator. Each section edits the objects it is given and says
whether it changed anything; the app decides what that means for the scene, the GI and the view.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from imgui_bundle import imgui

from viewer import sources
from viewer.scene import unlit_warning
from viewer.gpu.renderer import TONEMAPS, VIEWS, RenderSettings
from viewer.ui.background import BackgroundTask
from viewer.ui.frame_graph import FrameTimes, draw_frame_graph
from viewer.ui.gi_sources import GIController
from viewer.ui.messages import PANEL_WIDTH, Message  # noqa: F401 (the panels' own names too)
from viewer.ui.edit_panels import light_section, materials_section, objects_section
from viewer.ui.panel_style import NOTE_COLOUR, tooltip as _tooltip
from viewer.ui.scene_edits import SceneEdits

ERROR_COLOUR = imgui.ImVec4(1.0, 0.45, 0.4, 1.0)
WARNING_COLOUR = imgui.ImVec4(1.0, 0.78, 0.3, 1.0)
BAKING_NOTE = "Lightmap: tracing the final gather for the new geometry..."
"""Shown while Renderer.baking (seconds after a new scene, one or two after a lamp move; the picture
meanwhile shows the probes per fragment)."""
KERNELS = ("physical", "paper")
LIGHT_SAMPLES = (4, 8, 16, 32, 64)
HELP = (
    ("Mouse", (("left drag", "orbit around the target"),
               ("shift + left drag", "pan (also middle drag)"),
               ("wheel", "zoom"),
               ("right drag", "look around (fly mode)"),
               ("right held + W A S D", "fly forward / left / back / right"),
               ("right held + Q E", "down / up (shift: faster)"))),
    ("Keys", (("Z", "reset the camera"),
              ("C", "copy the view as capture's --camera and --fov (also printed)"),
              ("S", "save a screenshot of the view (PNG in the current folder)"),
              ("shift + S", "... of the whole window, panels included"),
              ("R", "reload shaders (errors are shown, the old ones keep running)"),
              ("F1", "this help"),
              ("Tab", "hide / show the panel"),
              ("Esc", "quit"))),
    ("Files", (("drop a file", "open an .obj .glb .gltf or .ply file"),)),
)
"""The F1 help: sections of (input, what it does), drawn as a two-column table."""


@dataclass
class ViewOptions:
    view: str = "final"
    """One of the renderer's VIEWS."""
    redraw_always: bool = False
    """Draw the scene every frame even when nothing changed (to measure frame times)."""
    show_help: bool = False
    show_panel: bool = True
    """The settings panel on the right (the scene is drawn left of it)."""
    show_frame_times: bool = True
    """The frame-time graph in the top-left corner of the view."""


def scene_section(name: str, triangles: int, edits: SceneEdits, loading: BackgroundTask | None) -> bool:
    """Returns True when the user asked to reset the edits."""
    imgui.text(f"{name}: {triangles} triangles, {len(edits.base.groups)} groups")
    if loading is not None and not loading.done:
        imgui.text_colored(NOTE_COLOUR, f"Loading {loading.label} ... {loading.elapsed:.1f} s")
    else:
        imgui.text_colored(NOTE_COLOUR, "Drop an .obj .glb .gltf or .ply file here to open it.")
    return imgui.button("Reset edits")


def source_choices() -> list[tuple[str, str]]:
    """(name, label) of every GI source the panel offers, in the registry's order (viewer.sources)."""
    return [(name, spec.label) for name, spec in sources.SOURCES.items()]


def gi_section(gi: GIController, baking: bool = False) -> None:
    """The GI source and its settings; `baking`: the renderer is making the lightmap's weights and
    final-gather rays for new geometry (Renderer.baking), said under the source's status."""
    for index, (source, label) in enumerate(source_choices()):
        reason = gi.unavailable.get(source)
        if index % 2:
            imgui.same_line(PANEL_WIDTH / 2)
        imgui.begin_disabled(reason is not None)
        if imgui.radio_button(label, gi.source == source):
            gi.set_source(source)
        imgui.end_disabled()
        if reason is not None:
            imgui.set_item_tooltip(reason)  # shown on hover although the button is disabled
    s = gi.settings
    changed, kernel = imgui.combo("kernel", KERNELS.index(s.kernel), list(KERNELS))
    if changed:
        gi.set_settings(kernel=KERNELS[kernel])
    _tooltip("physical: both cosines and visibility; paper: eq. 25 (receiver cosine only, no visibility)")
    changed, bounces = imgui.slider_int("bounces", s.bounces, 0, 100)
    if changed:
        gi.set_settings(bounces=bounces)
    changed, voxels = imgui.slider_int("voxels per axis", s.voxels, 8, 64)
    if changed:
        gi.set_settings(voxels=voxels)
    changed, probes = imgui.slider_int("probes per axis", s.probes, 2, 32)
    if changed:
        gi.set_settings(probes=probes)
    if gi.refused:   # a change that would take more memory than a request may use
        imgui.text_wrapped(gi.refused)
    line, progress, error = gi.status()
    imgui.push_text_wrap_pos(0.0)   # status lines wrap at the panel's edge, never cut
    imgui.text(line)
    imgui.pop_text_wrap_pos()
    if progress is not None and gi.busy:
        imgui.progress_bar(progress, imgui.ImVec2(-1, 0))
    if baking:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_colored(NOTE_COLOUR, BAKING_NOTE)
        imgui.pop_text_wrap_pos()
    if error:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_colored(ERROR_COLOUR, error)
        imgui.pop_text_wrap_pos()
    warning = gi.domain_warning
    if warning:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_colored(WARNING_COLOUR, warning)
        imgui.pop_text_wrap_pos()


def view_section(options: ViewOptions, settings: RenderSettings, viewport) -> None:
    changed, index = imgui.combo("view", VIEWS.index(options.view), list(VIEWS))
    if changed:
        options.view = VIEWS[index]
    _, settings.exposure = imgui.slider_float("exposure (EV)", settings.exposure, -6.0, 6.0, "%.1f")
    curves = list(TONEMAPS)
    changed, index = imgui.combo("tone curve", curves.index(settings.tonemap), curves)
    if changed:
        settings.tonemap = curves[index]
    samples = settings.light_samples if settings.light_samples in LIGHT_SAMPLES else 32
    changed, index = imgui.combo("light samples", LIGHT_SAMPLES.index(samples), [str(n) for n in LIGHT_SAMPLES])
    if changed:
        settings.light_samples = LIGHT_SAMPLES[index]
    _tooltip("Points on the emitters for direct light and soft shadows (more: smoother, slower)")
    _, settings.interleave = imgui.checkbox("interleaved direct light", settings.interleave)
    _tooltip("Each pixel of a 2x2 block shades a quarter of the light samples (about 3x faster)")
    counts = sorted({0, 4, 8, 16, viewport.refine})
    changed, index = imgui.combo("anti-aliasing", counts.index(viewport.refine),
                                 [f"{n} images" if n > 1 else "off" for n in counts])
    viewport.refine = counts[index] if changed else viewport.refine
    _tooltip("Once the view rests, images at subpixel offsets are averaged into it, one a frame (--msaa: instead)")
    _, viewport.render_scale = imgui.slider_float("resolution", viewport.render_scale, 0.25, 1.0, "%.2f x")
    _, viewport.preview_scale = imgui.slider_float("while moving", viewport.preview_scale, 0.25, 1.0, "%.2f x")
    _tooltip("Resolution while the camera or scene changes; full resolution follows when it stops")
    _, options.redraw_always = imgui.checkbox("redraw every frame", options.redraw_always)
    _tooltip("Draw the scene every frame even when nothing changed, to measure frame times")
    _, options.show_frame_times = imgui.checkbox("frame-time graph", options.show_frame_times)


def settings_panel(shown: bool, sections: dict) -> None:
    """The panel docked on the right; `sections` maps a header to (function drawing it, open at start)."""
    if not shown:
        return
    width, height = imgui.get_io().display_size
    imgui.set_next_window_pos(imgui.ImVec2(width - PANEL_WIDTH, 0), imgui.Cond_.always)
    imgui.set_next_window_size(imgui.ImVec2(PANEL_WIDTH, height), imgui.Cond_.always)
    flags = imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
    expanded, _ = imgui.begin("GI viewer  (F1 help, Tab hide)", None, flags)
    if expanded:
        for header, (draw, open_at_start) in sections.items():
            flags = imgui.TreeNodeFlags_.default_open if open_at_start else 0
            if imgui.collapsing_header(header, flags):
                imgui.push_id(header)
                draw()
                imgui.pop_id()
    imgui.end()


def frame_time_overlay(times: FrameTimes, gi_line: str, shown: bool) -> None:
    """CPU and GPU frame times as a small graph in the top-left corner of the view."""
    if not shown:
        return
    imgui.set_next_window_pos(imgui.ImVec2(8, 8), imgui.Cond_.always)
    imgui.set_next_window_size(imgui.ImVec2(320, 0), imgui.Cond_.always)
    imgui.set_next_window_bg_alpha(0.6)
    flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_saved_settings
             | imgui.WindowFlags_.no_focus_on_appearing | imgui.WindowFlags_.no_nav | imgui.WindowFlags_.no_move)
    imgui.begin("Frame time", None, flags)
    draw_frame_graph(times, height=60.0)
    imgui.push_text_wrap_pos(0.0)   # the window keeps its width; a long line wraps below
    imgui.text_colored(NOTE_COLOUR, gi_line)
    imgui.pop_text_wrap_pos()
    imgui.end()


def help_window(options: ViewOptions) -> None:
    if not options.show_help:
        return
    width, height = imgui.get_io().display_size
    view_width = width - (PANEL_WIDTH if options.show_panel else 0)
    imgui.set_next_window_pos(imgui.ImVec2(view_width / 2, height / 2), imgui.Cond_.always, imgui.ImVec2(0.5, 0.5))
    imgui.set_next_window_bg_alpha(0.9)
    flags = imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
    _, still_open = imgui.begin("Help (F1)", True, flags)
    if imgui.begin_table("help", 2, imgui.TableFlags_.sizing_fixed_fit | imgui.TableFlags_.row_bg):
        for section, rows in HELP:
            imgui.table_next_row()
            imgui.table_next_column()
            imgui.text_colored(WARNING_COLOUR, section)
            for key, action in rows:
                imgui.table_next_row()
                imgui.table_next_column()
                imgui.text(key)
                imgui.table_next_column()
                imgui.text(action)
        imgui.end_table()
    imgui.end()
    options.show_help = bool(still_open)


def messages_window(messages: list[Message], shader_error: str | None, info_seconds: float = 5.0) -> None:
    """Errors and warnings stay until dismissed; notes fade after `info_seconds`."""
    now = time.perf_counter()
    messages[:] = [m for m in messages if m.error or m.warning or now - m.at < info_seconds]
    if not messages and not shader_error:
        return
    width, height = imgui.get_io().display_size
    imgui.set_next_window_pos(imgui.ImVec2(16, height - 16), imgui.Cond_.always, imgui.ImVec2(0.0, 1.0))
    imgui.set_next_window_size_constraints(imgui.ImVec2(200, 0), imgui.ImVec2(max(width - PANEL_WIDTH - 32, 200),
                                                                              height / 2))
    flags = (imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
             | imgui.WindowFlags_.no_title_bar)
    imgui.set_next_window_bg_alpha(0.9)
    imgui.begin("Messages", None, flags)
    imgui.push_text_wrap_pos(width - PANEL_WIDTH - 64)
    if shader_error:
        imgui.text_colored(ERROR_COLOUR, "Shader error (the previous shaders keep running; fix and press R):")
        imgui.text(shader_error)
    for index, message in enumerate(list(messages)):
        if message.error or message.warning:
            imgui.text_colored(ERROR_COLOUR if message.error else WARNING_COLOUR, message.text)
            imgui.same_line()
            if imgui.small_button(f"dismiss##{index}"):
                messages.remove(message)
        else:
            imgui.text(message.text)
    imgui.pop_text_wrap_pos()
    imgui.end()


def unlit_overlay(text: str | None, show_panel: bool) -> None:
    """A scene that nothing lights: the reason and the fix in the middle of the view, where the eye is
    (the view itself is black)."""
    if not text:
        return
    width, height = imgui.get_io().display_size
    view_width = width - (PANEL_WIDTH if show_panel else 0)
    imgui.set_next_window_pos(imgui.ImVec2(view_width / 2, height / 2), imgui.Cond_.always, imgui.ImVec2(0.5, 0.5))
    imgui.set_next_window_size(imgui.ImVec2(min(520.0, max(view_width - 32.0, 200.0)), 0), imgui.Cond_.always)
    flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_saved_settings
             | imgui.WindowFlags_.no_inputs | imgui.WindowFlags_.no_focus_on_appearing | imgui.WindowFlags_.no_nav)
    imgui.set_next_window_bg_alpha(0.85)
    imgui.begin("No light", None, flags)
    imgui.text_colored(WARNING_COLOUR, "Nothing lights this scene: no emitter and no sun.")
    imgui.push_text_wrap_pos(0.0)
    imgui.text(text)
    imgui.pop_text_wrap_pos()
    imgui.end()


def loading_overlay(task: BackgroundTask | None) -> None:
    """A spinner-like indicator in the middle of the window while a dropped file loads."""
    if task is None or task.done:
        return
    width, height = imgui.get_io().display_size
    imgui.set_next_window_pos(imgui.ImVec2(width / 2, height / 2), imgui.Cond_.always, imgui.ImVec2(0.5, 0.5))
    flags = (imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
             | imgui.WindowFlags_.no_title_bar | imgui.WindowFlags_.no_inputs)
    imgui.begin("Loading", None, flags)
    dots = "." * (1 + int(task.elapsed * 3) % 3)
    imgui.text(f"Loading {task.label} {dots:<3} {task.elapsed:.1f} s")
    # An indeterminate bar: a block sweeping across (the loader has no percentage to report).
    imgui.progress_bar(-1.0 * time.perf_counter(), imgui.ImVec2(260, 0), "")
    imgui.end()


_UNLIT: list = [None, None]
"""The last scene asked about and its `unlit_warning` (a frame asks again for the same scene)."""


def _unlit(scene) -> str | None:
    if _UNLIT[0] is not scene:
        _UNLIT[:] = [scene, unlit_warning(scene)]
    return _UNLIT[1]


def draw_windows(session, view: ViewOptions, settings: RenderSettings, viewport, times: FrameTimes,
                 shader_error: str | None) -> None:
    """Every imgui window of a frame, wired to the session (viewer.ui.session: scene, edits, GI, camera)
    and the view; between imgui.new_frame() and imgui.render()."""
    def scene() -> None:
        if scene_section(session.name, len(session.scene.faces), session.edits, session.loading):
            session.edits.reset()
        imgui.same_line()
        if imgui.button("Reset camera (Z)"):
            session.camera.reset()
        cameras = session.scene.cameras   # a glTF's own cameras: the first opened the scene
        for index, camera in enumerate(cameras if len(cameras) > 1 else ()):
            if index % 4:
                imgui.same_line()
            if imgui.button(f"Camera {index + 1}"):   # Z comes back to the camera chosen last
                session.camera.home = camera
                session.camera.reset()

    settings_panel(view.show_panel, {
        "Scene": (scene, True),
        "Global illumination": (lambda: gi_section(session.gi, session.renderer.baking), True),
        "Light": (lambda: light_section(session.edits, session.scene_size), True),
        "Objects": (lambda: objects_section(session.edits, session.scene_size), False),
        "Materials": (lambda: materials_section(session.edits), False),
        "View": (lambda: view_section(view, settings, viewport), True),
    })
    frame_time_overlay(times, session.gi.status()[0], view.show_frame_times)
    unlit_overlay(_unlit(session.edits.base), view.show_panel)
    help_window(view)
    messages_window(session.messages, shader_error)
    loading_overlay(session.loading)
