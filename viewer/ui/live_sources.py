"""The viewer's side of each GI source (viewer.sources): what it does when the scene or the GI settings
change, in every frame, and what the panel says about it. The GIController makes one adapter per source
the first time it is chosen (Source.live) and keeps it: switching back to a source finds its work (a
finished CPU solve, the compute solver's traced rays) still there.

An adapter shows probes by handing them to `controller.publish` (None: no indirect light).
"""

from __future__ import annotations

from viewer.physical.gi import GISettings
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene
from viewer.ui.background import SOLVER_STAGES, BackgroundTask, SolverProcess


class SourceFailed(RuntimeError):
    """The source cannot start (e.g. a broken model); the message says why, and the controller falls
    back to the default source."""


class LiveSource:
    """What every adapter answers; the defaults are those of a source with nothing to do."""

    def __init__(self, controller):
        self.controller = controller

    def restart(self, scene: Scene, settings: GISettings) -> None:
        """The scene or the settings changed while this source is shown."""

    def step(self) -> None:
        """Once a frame while this source is shown."""

    def idle(self) -> None:
        """Once a frame while another source is shown."""

    def leave(self) -> None:
        """Another source is shown now: stop work whose result nobody will see."""

    @property
    def busy(self) -> bool:
        """Still working towards the probes for the current scene and settings."""
        return False

    @property
    def pending(self) -> BackgroundTask | None:
        """The work on a worker thread whose result the next `step` shows as probes, if any (the
        network's voxels are not: its prediction follows them on the render thread, and a frame that
        waited for them held the renderer's own part of a drag back: 30 ms later settled on a box)."""
        return None

    @property
    def domain_warning(self) -> str | None:
        return None

    def status(self) -> tuple[str, float | None, str | None]:
        """(one line for the panel, progress 0..1 or None, error or None)."""
        return "Not available.", None, None

    def close(self) -> None:
        """The viewer closes: free processes and GL objects."""


class OffLive(LiveSource):
    def restart(self, scene: Scene, settings: GISettings) -> None:
        self.controller.publish(None)

    def status(self):
        return "Direct light only.", None, None


class BakedLive(LiveSource):
    def restart(self, scene: Scene, settings: GISettings) -> None:
        self.controller.publish(self.controller.baked)

    def status(self):
        return "Baked probes, as read from the file (edits do not relight them).", None, None


class SolverLive(LiveSource):
    """The CPU solver (viewer.physical.gi.solve) in a worker process; its grid replaces the shown one when
    it is done. The last finished grid is kept: asking again for the same scene and settings shows it."""

    def __init__(self, controller):
        super().__init__(controller)
        self.process: SolverProcess | None = None
        self._key = None          # (scene version, settings) of the grid the solver last finished
        self._grid: ProbeGrid | None = None
        self._requested = None    # (scene version, settings) of the solve under way

    def restart(self, scene: Scene, settings: GISettings) -> None:
        key = (self.controller.scene_version, settings)
        if key == self._key:
            self.process.cancel()
            self.controller.publish(self._grid)   # already solved: show it again
        else:
            self.process = self.process or SolverProcess()
            self.process.request(scene, settings)
            self._requested = key

    def step(self) -> None:
        if self.process is None:
            return
        grid = self.process.poll()
        if grid is not None:
            self._key, self._grid = self._requested, grid
            self.controller.ready_seconds = sum(self.process.last_seconds.values())
            self.controller.publish(grid)

    def idle(self) -> None:
        if self.process is not None:
            self.process.poll()   # a cancelled solve's last words: nobody shows them

    def leave(self) -> None:
        if self.process is not None:
            self.process.cancel()

    @property
    def busy(self) -> bool:
        return self.process is not None and self.process.busy

    def status(self):
        cpu, ready = self.process, self.controller.ready_seconds
        if cpu is not None and cpu.error:
            return "CPU solver failed.", None, cpu.error
        if cpu is not None and cpu.busy:
            if cpu.running_since is None:
                return "CPU solver: starting...", 0.0, None
            step = min(len(cpu.stages_done) + 1, len(SOLVER_STAGES))
            return (f"CPU solver: {cpu.stage} ({step}/{len(SOLVER_STAGES)}), {cpu.elapsed:.1f} s",
                    cpu.progress, None)
        if ready is not None:
            return f"CPU solver: done in {ready:.1f} s.", 1.0, None
        return "CPU solver: idle.", None, None

    def close(self) -> None:
        if self.process is not None:
            self.process.close()


class ComputeLive(LiveSource):
    """The compute source, kept across restarts: the physical kernel relights (viewer.ui.relight_source),
    the paper's kernel keeps the all-pairs solver (viewer.ui.compute_source)."""

    def __init__(self, controller):
        super().__init__(controller)
        self.source = None

    def restart(self, scene: Scene, settings: GISettings) -> None:
        from viewer.ui.compute_source import ComputeSource
        from viewer.ui.relight_source import RelightSource

        kind = RelightSource if settings.kernel == "physical" else ComputeSource
        if not isinstance(self.source, kind):
            if self.source is not None:
                self.source.release()
            self.source = kind(self.controller.ctx)
        self.source.restart(scene, settings)

    def step(self) -> None:
        if self.source is not None:
            grid = self.source.step(self.controller.compute_budget_ms)
            if grid is not None:
                self.controller.publish(grid)

    @property
    def busy(self) -> bool:
        return self.source is not None and self.source.busy

    @property
    def pending(self) -> BackgroundTask | None:
        return getattr(self.source, "work", None)

    def status(self):
        if self.source is None:
            return "Compute solver: idle.", None, self.controller.fallback
        if self.source.error:
            return "Compute solver failed.", None, self.source.error
        return self.source.status(), None, self.controller.fallback

    def close(self) -> None:
        if self.source is not None:
            self.source.release()


class NeuralLive(LiveSource):
    """The network (viewer.ui.neural_source). Its model is loaded when the source is first shown: a
    missing, corrupt or mismatched model is a SourceFailed, and the controller falls back."""

    def __init__(self, controller):
        super().__init__(controller)
        self.source = None

    def restart(self, scene: Scene, settings: GISettings) -> None:
        if self.source is None:
            from viewer.neural.field import ModelError
            from viewer.ui.neural_source import NeuralSource

            try:
                self.source = NeuralSource(self.controller.neural_model)
            except ModelError as exc:
                raise SourceFailed(f"Neural model unusable: {exc}") from None
        self.source.restart(scene, settings)

    def step(self) -> None:
        if self.source is not None:
            grid = self.source.step()
            if grid is not None:
                self.controller.publish(grid)

    @property
    def busy(self) -> bool:
        return self.source is not None and self.source.busy

    @property
    def domain_warning(self) -> str | None:
        """While the scene shown lies outside the model's training domain: one line that says so, why,
        and that the physical solver computes it (viewer.neural.domain.warning)."""
        from viewer.neural.domain import warning

        return None if self.source is None else warning(self.source.outside)

    def status(self):
        if self.source is None:
            return "Not available.", None, None
        if self.source.error:
            return "Neural source failed.", None, self.source.error
        return self.source.status(), None, None


class BatchLive(LiveSource):
    """A source with only a blocking solve (Source.solve, no adapter of its own): solved on a worker
    thread, without a GL context of the window's, its probes shown when done. A newer request replaces
    an older one, whose result is then dropped."""

    def __init__(self, controller, source):
        super().__init__(controller)
        self.source = source
        self.task: BackgroundTask | None = None
        self.error: str | None = None

    def restart(self, scene: Scene, settings: GISettings) -> None:
        model = self.controller.neural_model
        self.error = None
        self.task = BackgroundTask(self.source.name, lambda: self.source.indirect(scene, settings, model))

    def step(self) -> None:
        if self.task is not None and self.task.done:
            task, self.task = self.task, None
            if task.error:
                self.error = task.error
            else:
                self.controller.publish(task.result)

    @property
    def busy(self) -> bool:
        return self.task is not None

    @property
    def pending(self) -> BackgroundTask | None:
        return self.task

    def status(self):
        if self.error:
            return f"{self.source.label} failed.", None, self.error
        if self.task is not None:
            return f"{self.source.label}: solving, {self.task.elapsed:.1f} s", None, None
        return f"{self.source.label}: done.", None, None
