"""Where the viewer's indirect light comes from: one of the GI sources of viewer.sources (off, the
compute-shader solver, the CPU (numpy) solver, the neural field, a baked grid); one place that restarts the
active source when the scene or the GI settings change and hands finished probe grids to the render loop.

Each source's own behaviour lives in its adapter (viewer.ui.live_sources): the CPU solver runs in a worker
process (viewer.ui.background.SolverProcess) and its grid replaces the shown one when it is done; the
compute solver runs on the render thread's GL context, a few milliseconds a frame, and its probes are
shown as they converge.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from viewer import sources
from viewer.physical.gi import GISettings
from viewer.physical.work import WorkError, check_work
from viewer.probes.grid import ProbeGrid
from viewer.resources import MODELS  # noqa: F401 - where the neural source's shipped model is looked for
from viewer.scene import Scene
from viewer.ui.live_sources import BatchLive, LiveSource, SourceFailed

NO_BAKED_GRID = sources.NO_BAKED_GRID


def unavailable_reasons() -> dict[str, str]:
    """Source -> why it cannot be chosen in this build (sources missing from the dict can)."""
    return {name: reason for name, spec in sources.SOURCES.items() if (reason := spec.unavailable())}


COMPUTE_BUDGET_MS = 20.0
"""The compute solver's share of a frame: with the blit of the view and the panel it keeps frames under
33 ms (30 per second) while the solver works; its probes are published, and the view redrawn, in frames
without a solver step (docs/PERFORMANCE.md, `python -m viewer.bench.frame --progressive`)."""



class GIController:
    def __init__(self, ctx, source: str = "solver", settings: GISettings | None = None,
                 compute_budget_ms: float = COMPUTE_BUDGET_MS, neural_model: Path | None = None,
                 baked: ProbeGrid | None = None):
        self.ctx = ctx
        self.neural_model = neural_model
        self.baked = baked
        """Probes read from a baked file, for the scene opened with them (a new scene drops them)."""
        self.unavailable = unavailable_reasons()
        if baked is not None:
            for name in self._from_file():
                self.unavailable.pop(name, None)
        source = sources.canonical(source) if source in sources.ALIASES else source
        self.source = source if source not in self.unavailable else sources.OFF.name
        self.settings = settings or GISettings()
        self.compute_budget_ms = compute_budget_ms
        """Milliseconds of compute-solver work per frame (ComputeSolver.step)."""
        self.scene: Scene | None = None
        self._scene_version = -1
        self._live: dict[str, LiveSource] = {}   # name -> adapter, made when the source is first shown
        self.fallback: str | None = None   # why a source that could not start was left for the default
        self._fallback_from: str | None = None
        self.refused: str | None = None   # why the last settings change was not made (too much work)
        self._outgoing: list[ProbeGrid | None] = []   # grids for the render loop to show, oldest first
        self.ready_seconds: float | None = None        # how long the last finished solve took
        self.unlit = False   # the scene has no emitter and no sun: no source solves it

    @property
    def spec(self) -> sources.Source | None:
        """The registry's entry of the source shown (None for a name it does not know)."""
        return sources.SOURCES.get(self.source)

    @property
    def previewing(self) -> bool:
        """The source is converging a slice every frame on the render thread, its probes shown as they
        come: the window draws previews meanwhile."""
        spec = self.spec
        return spec is not None and spec.steps_on_render_thread and self.busy

    @property
    def scene_version(self) -> int:
        return self._scene_version

    def publish(self, grid: ProbeGrid | None) -> None:
        """Show these probes (None: no indirect light) in the next update."""
        self._outgoing.append(grid)

    @staticmethod
    def _from_file() -> list[str]:
        return [name for name, spec in sources.SOURCES.items() if spec.from_file]

    def _default_source(self) -> str:
        return sources.DEFAULT if sources.DEFAULT not in self.unavailable else sources.OFF.name

    def _adapter(self, name: str) -> LiveSource | None:
        if name not in self._live:
            spec = sources.SOURCES.get(name)
            if spec is None:
                return None
            self._live[name] = spec.live(self) if spec.live is not None else BatchLive(self, spec)
        return self._live[name]

    # ---- inputs -----------------------------------------------------------------------------------------
    def set_scene(self, scene: Scene, version: int, new_scene: bool = False) -> None:
        """The scene changed (an edit, or a new file: then the old probes no longer fit and go at once)."""
        if new_scene and self.scene is not None and self.baked is not None:  # the baked probes fit no other
            self.baked = None
            for name in self._from_file():
                self.unavailable[name] = sources.SOURCES[name].unavailable()
            if self.spec is not None and self.spec.from_file:
                self.source = self._default_source()
        self.scene, self._scene_version = scene, version
        if new_scene:
            self._outgoing.append(None)
        self._restart()

    def set_source(self, source: str) -> None:
        if source == self.source or source in self.unavailable:
            return
        self.source = source
        self._restart()

    def set_settings(self, **changes) -> None:
        """Solve with `changes` to the settings; a change that would take more memory than a request may use
        (viewer.physical.work) is not made, and `refused` says why (the panel shows it)."""
        settings = replace(self.settings, **changes)
        try:
            check_work(settings)
        except WorkError as exc:
            self.refused = f"{exc}: kept the previous settings"
            return
        self.refused = None
        if settings != self.settings:
            self.settings = settings
            self._restart()

    def _restart(self) -> None:
        if self.scene is None:
            return
        # Nothing emits and there is no sun: every bounce of black is black, so no source solves it (a
        # solve would take the scene's full time for zeros); an edit that lights it restarts the source.
        self.unlit = not self.scene.has_emitters and sources.SOURCES[self.source].solve is not None
        for name, live in self._live.items():
            if name != self.source or self.unlit:
                live.leave()
        if self.unlit:
            self._outgoing.append(None)
            return
        live = self._adapter(self.source)
        if live is None:
            return
        try:
            live.restart(self.scene, self.settings)
        except SourceFailed as exc:
            self.fallback, self._fallback_from = f"{exc}. Using the compute solver instead.", self.source
            self.source = self._default_source()
            self._restart()
            return
        if self._fallback_from == self.source:   # it started this time: the old failure is over
            self.fallback = self._fallback_from = None

    # ---- per frame ----------------------------------------------------------------------------------------
    def start(self) -> None:
        """The shown source takes up a change now, ahead of the frame's `update`: a relight on its worker
        then runs while the render thread does its own share of an edit (on a 68k-triangle scan, 17 ms of
        vertex colours, then a frame that holds Python's lock for 11 ms while llvmpipe shades its vertices)."""
        live = self._live.get(self.source)
        if live is not None and not self.unlit:
            live.step()

    def wait(self, seconds: float) -> None:
        """Give the shown source's work in flight up to `seconds` to finish, so that the next `update`
        shows its result (see Session.update)."""
        live = self._live.get(self.source)
        task = None if live is None or self.unlit else live.pending
        if task is not None and not task.done:
            task.wait(seconds)

    def update(self) -> tuple[bool, ProbeGrid | None]:
        """(changed, grid): whether the shown probes should change, and to what (None: no indirect)."""
        for name, live in list(self._live.items()):
            if name == self.source and not self.unlit:
                live.step()
            else:
                live.idle()
        if self._outgoing:
            grid = self._outgoing[-1]
            self._outgoing.clear()
            return True, grid
        return False, None

    @property
    def domain_warning(self) -> str | None:
        """While the neural source shows a scene outside its model's training domain: one line that says
        so, why, and that the physical solver computes it (viewer.neural.domain.warning); else None."""
        live = self._live.get(self.source)
        return None if live is None else live.domain_warning

    @property
    def busy(self) -> bool:
        """Still working towards the probes for the current scene and settings."""
        live = self._live.get(self.source)
        return live is not None and live.busy and not self.unlit

    def status(self) -> tuple[str, float | None, str | None]:
        """(one line for the panel, progress 0..1 or None, error or None)."""
        if self.unlit:
            return "Nothing emits light and there is no sun: nothing to solve.", None, None
        live = self._adapter(self.source)
        return ("Not available.", None, None) if live is None else live.status()

    def close(self) -> None:
        for live in self._live.values():
            live.close()
