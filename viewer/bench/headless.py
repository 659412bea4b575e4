"""The viewer without its window: the pieces ViewerApp puts together (Renderer, GIController, Session,
Viewport) on a headless EGL context, stepped a frame at a time as `ViewerApp.on_render` steps them
(`Session.update`, then `Viewport.frame`, the picture finished as the window's buffer swap finishes it),
with the window's rests between frames (`step`: viewer/ui/pacing.py, ended early by a worker's result).
For the benchmarks of edits (viewer/bench/edits.py), the soak (viewer/bench/soak.py) and the tests that
load, solve and edit scene after scene in one process, as a user does in the window."""

from __future__ import annotations

import time
from pathlib import Path

from viewer.physical.gi import GISettings
from viewer.gpu.context import create_context, finish
from viewer.gpu.gl_objects import watch
from viewer.gpu.renderer import RenderSettings, Renderer
from viewer.memory import Usage
from viewer.scene import Scene, load
from viewer.ui.gi_sources import GIController
from viewer.ui.pacing import Pacing, Rests
from viewer.ui.session import Session
from viewer.ui.viewport import Viewport


class HeadlessViewer:
    def __init__(self, source: str, settings: GISettings, scene: str | Path | Scene = "cornell",
                 size: tuple[int, int] = (320, 180), light_samples: int = 4, timeout: float = 900.0):
        self.ctx = create_context()
        watch(self.ctx)   # GL objects freed without release() are counted, not lost
        self.timeout = timeout
        """Seconds `settle` waits before it gives up (a safety net, not a measurement)."""
        self.renderer = Renderer(self.ctx, RenderSettings(light_samples=light_samples))
        self.gi = GIController(self.ctx, source, settings)
        self.log: list[str] = []
        opened = scene if isinstance(scene, Scene) else load(scene)
        self.session = Session(self.renderer, self.gi, opened, opened.name if isinstance(scene, Scene) else scene,
                               log=self.log.append, edit_interval=0.0)
        self.viewport = Viewport(self.ctx, self.renderer)
        self.screen = self.ctx.framebuffer(color_attachments=[self.ctx.texture(size, 4)])
        self.frames = 0
        self.frame_seconds = 0.0
        """What the last drawn frame took (`Session.update` waits for the GI that long after an edit)."""
        self.rests = Rests(Pacing())
        self.edited_at = time.perf_counter()

    def frame(self) -> bool:
        """One frame as the window runs it; True if the scene was drawn."""
        session = self.session
        session.update("final", frame_seconds=self.frame_seconds)
        preview = self.gi.previewing
        self.frames += 1
        started = time.perf_counter()
        drawn = self.viewport.frame(session.camera.camera(), "final", session.content_key(), self.screen,
                                    preview=preview)
        finish(self.ctx)   # the window's buffer swap waits for the picture (letting go of Python's lock)
        if drawn:
            self.frame_seconds = time.perf_counter() - started
        return drawn

    def step(self) -> bool:
        """One frame after the rest the window's loop takes before it (viewer/ui/pacing.py): at most 60
        frames a second within `Pacing.linger` of the last edit (`edited`), fewer while work runs, and at
        once when a worker hands a result over (viewer.wake). True if the scene was drawn."""
        self.rests.take()
        started = time.perf_counter()
        drew = self.frame()
        now = time.perf_counter()
        self.rests.plan(now - started, drew or self.session.busy, False, now - self.edited_at)
        return drew

    def edited(self) -> None:
        """The user just edited something (input): the next frame comes at once, and the ones after it at
        the rate the window keeps while the user works."""
        self.edited_at = time.perf_counter()
        self.rests.skip()

    @property
    def settled(self) -> bool:
        """Nothing under way (loading, GI, edits) and the full-resolution image of it drawn."""
        return not self.session.busy and self.viewport.settled

    def settle(self, paced: bool = False) -> None:
        """Frames until settled (a load finished or failed, the GI converged, the picture redrawn): `paced`,
        at the window's pace (`step`: what a benchmark times), else as fast as they come (the tests)."""
        deadline = time.monotonic() + self.timeout
        self.step() if paced else self.frame()
        while not self.settled:
            if time.monotonic() > deadline:
                raise TimeoutError(f"not settled after {self.timeout:.0f} s: {self.gi.status()[0]}")
            if paced:
                self.step()
            else:
                time.sleep(0.002)
                self.frame()

    def load(self, path: str | Path) -> None:
        """Open a file as a drop does, and settle."""
        self.edited()
        self.session.load_file(path)
        self.settle()

    def usage(self, trim: bool = False) -> Usage:
        return Usage.measure(self.ctx, trim)

    def release(self) -> None:
        self.rests.close()
        self.session.close()   # and the GI sources: the CPU solver's process, the compute solver's GL objects
        self.viewport.release()
        self.renderer.release()
        for texture in self.screen.color_attachments:
            texture.release()
        self.screen.release()
        self.ctx.release()
