"""`python -m viewer [view] [SCENE]`: the interactive viewer (moderngl-window, glfw, imgui).

Without a display (no DISPLAY / WAYLAND_DISPLAY), or when no window can be opened, it says so and
renders the scene headless through EGL to `<scene>.png` instead (viewer.capture).

The window is a moderngl-window `WindowConfig` (`ViewerApp`, its class attributes are its settings) on
the glfw backend: the pyglet backend never delivers file drops on X11 (docs/ARCHITECTURE.md). The pieces
live in viewer/ui/: its flags (options), the imgui renderer and input, panels, frame-time graph, camera
controller, the 3D viewport, background loading, the GI sources, and what it does on its own for tests
and benchmarks (unattended).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
import weakref
from pathlib import Path
from types import SimpleNamespace

import moderngl_window as mglw

from viewer.cli_parsing import gi_settings, parse_size, tool_parser
from viewer.errors import exit_status
from viewer.progress import announce_compiles
from viewer.ui.options import add_arguments, options_from
from viewer.ui.pacing import Pacing, Rests


def log(message: str) -> None:
    """One line on stderr; tests and users read these (`viewer: ...`)."""
    print(f"viewer: {message}", file=sys.stderr, flush=True)


def run(args) -> int:
    announce_compiles()
    options = options_from(args)
    # bad GI flags, or flags and a size asking for more memory than a request may use: bad input, no window
    gi_settings(options, size=parse_size(options.size))
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        log(f"no display found (DISPLAY and WAYLAND_DISPLAY are unset); rendering {options.scene} headless")
        return render_headless(options)
    from viewer.bake import grid as baked_files
    from viewer.scene import load, unlit_warning

    baked = None   # a baked grid (`gi-viewer FILE.npz`): its scene, lit by its probes
    if baked_files.is_baked_file(options.scene):
        baked = baked_files.read_npz(options.scene)
        scene = baked_files.load_scene(baked, options.scene)
        log(f"showing the probes baked in {options.scene} on {baked_files.scene_source(baked, options.scene)}")
    else:
        scene = load(options.scene)   # a bad scene fails here: one line and exit status 2 (viewer.errors)
    try:
        window = open_window(options)
    except Exception as exc:  # no X server behind DISPLAY, no GL 4.3, glfw missing ...
        log(f"cannot open a window ({type(exc).__name__}: {exc}); rendering {options.scene} headless")
        return render_headless(options)
    if unlit_warning(scene):   # the window shows it too, over the view
        log(unlit_warning(scene))
    ViewerApp.argv = options
    app = ViewerApp(ctx=window.ctx, wnd=window, timer=mglw.timers.clock.Timer(), scene=scene, baked=baked)
    window._config = weakref.ref(app)  # as moderngl-window's create_window_config_instance does
    try:
        mglw.run_window_config_instance(app)
    finally:
        app.close()
    return 0


def open_window(options):
    """A glfw window with a GL 4.3+ core context, made current."""
    width, height = parse_size(options.size)
    logging.getLogger("moderngl_window").setLevel(logging.WARNING)
    window_cls = mglw.get_local_window_cls("glfw")
    window = window_cls(title=ViewerApp.title, size=(width, height), fullscreen=False,
                        resizable=ViewerApp.resizable, visible=True, gl_version=ViewerApp.gl_version,
                        aspect_ratio=ViewerApp.aspect_ratio, vsync=ViewerApp.vsync, samples=ViewerApp.samples,
                        cursor=True)
    mglw.activate_context(window=window)
    return window


def render_headless(options) -> int:
    """What the viewer does without a window: a PNG of the scene through EGL (`python -m viewer capture`)."""
    from viewer.capture import capture_request, run_capture

    out = getattr(options, "screenshot", None) or f"{Path(str(options.scene)).stem}.png"
    gi = options.gi if options.gi in ("off", "solver", "compute") else "compute"
    # the viewer's flags that a capture has too (scene, size, view, the GI settings) carry over; the
    # rest of the picture is the capture's defaults. A picture taken once is multisampled where the
    # window refines its still image frame by frame (the capture's default, 4 samples)
    msaa = options.msaa if options.msaa > 1 or options.refine <= 1 else 4
    capture = capture_request(SimpleNamespace(scene=options.scene, size=options.size, view=options.view,
                                              msaa=msaa, **vars(gi_settings(options))), out=out, gi=gi)
    status = run_capture(capture)
    if status == 0:
        log(f"wrote {os.path.abspath(out)}")
    return status


class ViewerApp(mglw.WindowConfig):
    """The viewer window. Class attributes are its settings (moderngl-window's convention); `argv` holds
    the options of `add_arguments` (set by `run`)."""

    title = "GI viewer"
    gl_version = (4, 3)
    """Compute shaders and image load/store need 4.3; Mesa gives 4.5 core."""
    window_size = (1280, 720)
    aspect_ratio = None
    """Free aspect: the view fills the window whatever its shape."""
    resizable, vsync = True, True
    samples = 0
    clear_color = None
    """The viewport covers the whole window every frame: no clear needed."""
    light_samples = 16
    """Emitter samples for direct light (the renderer's default is 32, which costs twice as much)."""
    interleave = True
    """Interleaved direct light (about 3x less direct-light work, see RenderSettings.interleave)."""
    render_scale = 1.0
    """Resolution of the still image as a fraction of the window's."""
    preview_scale = 0.5
    """Resolution while the camera or a slider moves, as a fraction of the still image's."""
    interaction_linger = 0.25
    """Seconds after the last camera input during which frames stay at preview resolution."""
    pacing = Pacing(linger=interaction_linger)
    """Frame rates while the user interacts, while work runs, and when all rests (viewer/ui/pacing.py)."""
    font_size = 15.0

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        add_arguments(parser)

    def __init__(self, scene=None, baked=None, **kwargs):
        super().__init__(**kwargs)
        import glfw

        from viewer.gpu.context import describe
        from viewer.gpu.programs import SHADERS
        from viewer.gpu.renderer import RenderSettings, Renderer
        from viewer.scene import load
        from viewer.ui.controls import Controls
        from viewer.ui.frame_graph import FrameTimes
        from viewer.ui.gi_sources import GIController
        from viewer.ui.imgui_input import ImguiInput
        from viewer.ui.imgui_renderer import ImguiRenderer, create_imgui_context
        from viewer.ui.panels import Message, ViewOptions
        from viewer.ui.session import Session
        from viewer.ui.unattended import UnattendedRun
        from viewer.ui.viewport import Viewport

        self.options = options = self.argv or options_from(SimpleNamespace())
        self.gl_description = describe(self.ctx)
        if options.resources:
            from viewer.gpu.gl_objects import watch

            watch(self.ctx)   # GL objects freed without release() are counted, not lost
        create_imgui_context(self.font_size)
        self.imgui_renderer = ImguiRenderer(self.ctx)
        self.imgui_input = ImguiInput(self.wnd.size, self.wnd.buffer_size)
        keys = self.wnd.keys
        self.controls = Controls(self.wnd, self.imgui_input, lambda: self.session.camera, {
            keys.S: lambda mods: self.request_screenshot("window" if mods.shift else "view"),
            keys.R: lambda mods: self.reload_shaders(),
            keys.F1: lambda mods: setattr(self.view, "show_help", not self.view.show_help),
            keys.TAB: lambda mods: setattr(self.view, "show_panel", not self.view.show_panel),
            keys.Z: lambda mods: self.session.camera.reset(),
            keys.C: lambda mods: self.session.copy_view(),
        }, linger=self.interaction_linger)
        settings = RenderSettings(light_samples=self.light_samples, interleave=self.interleave)
        self.renderer = Renderer(self.ctx, settings, options.shader_dir or SHADERS)
        self.renderer.background_bake = True   # a new scene's probe weights never stall a frame
        self.renderer.warm_up()
        self.viewport = Viewport(self.ctx, self.renderer, self.render_scale, self.preview_scale, samples=options.msaa,
                                 refine=options.refine)
        self.times = FrameTimes(self.ctx)
        gi = GIController(self.ctx, "baked" if baked else options.gi,
                          gi_settings(options),
                          baked=baked.indirect if baked else None)
        # Frame-time summaries cover the frames since the indirect light last settled.
        self.session = Session(self.renderer, gi, scene or load(options.scene),
                               baked.scene if baked else options.scene, log=log,
                               on_gi_ready=self.times.restart_summary)
        if not baked and options.gi != gi.source:
            note = gi.fallback or gi.unavailable.get(options.gi, "")
            log(f"--gi {options.gi} is not available ({note}); GI source: {gi.source}")
            self.session.messages.append(Message(f"GI source {options.gi!r} not available: {note}", error=True))
        self.view = ViewOptions(view=options.view, redraw_always=bool(options.redraw_always),
                                show_panel=not options.hide_panel)
        self.shader_error: str | None = None
        self._screenshot_requested: str | None = None   # "view" (S) or "window" (shift+S)
        self.frames = 0
        self._frame_started, self._frame_seconds, self._drew = time.perf_counter(), 0.0, False
        self.rests = Rests(self.pacing, glfw.wait_events_timeout, glfw.post_empty_event)
        self.unattended = UnattendedRun(options, self.ctx, self.session, self.viewport, self.times, self.view, log)
        self._drop_callback = glfw.set_drop_callback(self.wnd._window, self._glfw_drop)
        self._x11_window = glfw.get_x11_window(self.wnd._window) if sys.platform.startswith("linux") else 0

    # ---- the frame ------------------------------------------------------------------------------------
    def on_render(self, time_now: float, frame_time: float) -> None:
        rested, last_started = self.rests.take(), self._frame_started
        self._frame_started = time.perf_counter()
        if self._drew:   # the last frame, start to start, less its rest: what a frame of the scene costs
            self._frame_seconds = self._frame_started - last_started - rested - self.session.waited
        self.times.begin()
        session = self.session
        session.update(self.view.view, self._view_rect(), self._frame_seconds)
        self.controls.fly(frame_time)
        screen = self.wnd.fbo
        with self.times.gpu():
            screen.use()
            full = screen.viewport
            screen.viewport = self._view_rect()
            drew = self.viewport.frame(session.camera.camera(), self.view.view, session.content_key(), screen,
                                       preview=self._interacting(), force=self.view.redraw_always)
            if self._screenshot_requested == "view":
                self._screenshot_requested = None
                self._save(self.viewport.read(screen), self._screenshot_path())
            settled_shot = self.unattended.screenshot_due(self.frames)
            if settled_shot:
                self._save(self.viewport.read(screen), self.options.screenshot)
            if screen.viewport != full:   # the panel's strip: nothing of the scene is drawn there
                self.ctx.clear(0.09, 0.09, 0.1, 1.0, viewport=(screen.viewport[2], 0, full[2] - screen.viewport[2],
                                                                full[3]))
            screen.viewport = full
            self._draw_ui(frame_time)
            if settled_shot and self.options.screenshot_window:
                self._save(self.viewport.read(screen), self.options.screenshot_window)
            if self._screenshot_requested == "window":
                self._screenshot_requested = None
                self._save(self.viewport.read(screen), self._screenshot_path("-window"))
        self.times.end(drew)
        self.frames += 1
        if self.frames == 1:
            width, height = self.wnd.buffer_size
            log(f"ready: window 0x{self._x11_window:x}, {width}x{height}, {self.gl_description}, "
                f"scene {session.name!r}")
        if self.unattended.after_frame(self.frames, settled_shot):
            self.wnd.close()
        self._drew = drew
        self._plan_rest(drew)

    def _view_rect(self) -> tuple[int, int, int, int]:
        """The part of the window the scene is drawn in: left of the panel while the panel is shown."""
        from viewer.ui.panels import PANEL_WIDTH

        width, height = self.wnd.buffer_size
        if not self.view.show_panel:
            return (0, 0, width, height)
        scale = width / max(self.wnd.size[0], 1)
        return (0, 0, max(width - round(PANEL_WIDTH * scale), 64), height)

    def _interacting(self) -> bool:
        """Draw previews: the user is moving the camera or a slider, or the GI is converging."""
        from imgui_bundle import imgui

        gi = self.session.gi
        return self.controls.moving or imgui.is_any_item_active() or gi.previewing

    def _plan_rest(self, drew: bool) -> None:
        """The rest before the next frame, as `pacing` says (taken at its start: viewer/ui/pacing.py Rests)."""
        from imgui_bundle import imgui

        if self.view.redraw_always:
            return self.rests.skip()
        now = time.perf_counter()
        self.rests.plan(now - self._frame_started, drew or self.session.busy,
                        self.controls.moving or imgui.is_any_item_active(), now - self.controls.last_input)

    def _draw_ui(self, frame_time: float) -> None:
        from imgui_bundle import imgui

        from viewer.ui.panels import draw_windows

        imgui.get_io().delta_time = max(frame_time, 1e-4)
        imgui.new_frame()
        draw_windows(self.session, self.view, self.renderer.settings, self.viewport, self.times,
                     self.shader_error or self.viewport.error)
        imgui.render()
        self.imgui_renderer.render(imgui.get_draw_data(), self.wnd.fbo)

    # ---- actions --------------------------------------------------------------------------------------
    def _screenshot_path(self, suffix: str = "") -> Path:
        """`<scene>-<date>-<time>[-window].png` in the current folder, never overwriting a file."""
        stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in self.session.name) or "screenshot"
        stem = f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}{suffix}"
        path, count = Path(f"{stem}.png"), 1
        while path.exists():
            count += 1
            path = Path(f"{stem}-{count}.png")
        return path

    def _save(self, image, path) -> None:
        from PIL import Image

        from viewer.ui.panels import Message

        try:
            Image.fromarray(image).save(path)
        except (OSError, ValueError) as exc:
            log(f"cannot save screenshot {path}: {exc}")
            self.session.messages.append(Message(f"Cannot save {path}: {exc}", error=True))
            return
        self.session.messages.append(Message(f"Saved {path}"))
        self._write_stats()   # --stats: before the log line, so that whoever waits for it can read the state
        log(f"saved screenshot {os.path.abspath(path)}")

    def reload_shaders(self) -> None:
        from viewer.gpu.programs import ShaderError

        try:
            self.renderer.reload_shaders()
        except ShaderError as exc:
            self.shader_error = str(exc)
            log(f"shader reload failed, the previous shaders keep running: {exc}")
        else:
            self.shader_error = None
            log("shaders reloaded")
        self.viewport.invalidate()

    def request_screenshot(self, what: str) -> None:
        """Save the view ("view") or the whole window with its panels ("window") after this frame."""
        self._screenshot_requested = what

    # ---- events (moderngl-window calls these) ---------------------------------------------------------
    def on_key_event(self, key, action, modifiers) -> None:
        self.controls.key(key, action, modifiers)

    def on_unicode_char_entered(self, char: str) -> None:
        self.controls.character(char)

    def on_mouse_position_event(self, x: int, y: int, dx: int, dy: int) -> None:
        self.controls.mouse_position(x, y)

    def on_mouse_press_event(self, x: int, y: int, button: int) -> None:
        self.controls.mouse_press(x, y, button)

    def on_mouse_drag_event(self, x: int, y: int, dx: int, dy: int) -> None:
        self.controls.mouse_drag(x, y, dx, dy)

    def on_mouse_release_event(self, x: int, y: int, button: int) -> None:
        self.controls.mouse_release(x, y, button)

    def on_mouse_scroll_event(self, x_offset: float, y_offset: float) -> None:
        self.controls.scroll(x_offset, y_offset)

    def on_resize(self, width: int, height: int) -> None:
        self.imgui_input.resize(self.wnd.size, self.wnd.buffer_size)

    def _glfw_drop(self, window, paths) -> None:
        import glfw

        x, y = glfw.get_cursor_pos(window)
        self.on_files_dropped_event(int(x), int(y), list(paths))

    def on_files_dropped_event(self, x: int, y: int, paths: list[str]) -> None:
        from viewer.ui.panels import Message

        log(f"dropped {len(paths)} file(s) at {x},{y}: {', '.join(paths)}")
        self.controls.touch(moved=False)
        if not paths:
            return
        if len(paths) > 1:
            self.session.messages.append(Message(f"{len(paths)} files dropped: opening the first one."))
        self.session.load_file(paths[0])

    # ---- the end --------------------------------------------------------------------------------------
    def close(self) -> None:
        """After the window closed (no GL calls here: the context is gone): stop the solver, report."""
        self.rests.close()
        self.session.close()
        redraws, every = self.times.summary(redrawn_only=True), self.times.summary()
        nan = float("nan")
        log(f"{self.frames} frames; since the GI settled: scene redraws {int(redraws['frames'])}, CPU median "
            f"{redraws.get('cpu_median_ms', nan):.1f} ms, GPU median {redraws.get('gpu_median_ms', nan):.1f} ms; "
            f"all frames: CPU median {every.get('cpu_median_ms', nan):.1f} ms, GPU median "
            f"{every.get('gpu_median_ms', nan):.1f} ms")
        self._write_stats()

    def _write_stats(self) -> None:
        self.unattended.write_stats(self.frames, self.wnd.buffer_size, self.gl_description, self.shader_error)


def main(argv: list[str] | None = None) -> int:
    """`python -m viewer.app [SCENE] [flags]`: the viewer alone, as `python -m viewer view` runs it; bad
    input exits with status 2 in one line (viewer.errors), a crash shows its traceback."""
    parser = tool_parser(prog="python -m viewer.app", description="The interactive GI viewer.")
    parser.add_argument("scene", nargs="?", default="cornell", help="a built-in scene name or a scene file")
    add_arguments(parser)
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    return exit_status(lambda: run(args), internal_errors=False)


if __name__ == "__main__":
    raise SystemExit(main())
