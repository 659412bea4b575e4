"""The viewer's compute GI source for the paper's kernel: the all-pairs compute-shader solver
(viewer.gpu.compute_solver) stepped on the render thread's context a slice every frame, its probes shown
as they converge. The physical kernel's compute source is viewer.ui.relight_source.
"""

from __future__ import annotations

import time

from viewer.physical.gi import GISettings
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene
from viewer.progress import plural
from viewer.ui.background import BackgroundTask


class ComputeSource:
    """The compute-shader solver (viewer.gpu.compute_solver), kept across restarts: while only colours
    and lights change it keeps its visibility and probe rays, so an edit re-converges in seconds.

    Voxelizing runs off the render thread; the solver then steps on the render thread's context for
    `budget_ms` a frame. Its probes are read back (a few hundred kB) and handed to the renderer at most
    every `publish_interval` seconds while converging, and once more when converged, in a frame without
    a solver step.
    """

    def __init__(self, ctx, publish_interval: float = 1.0, debounce: float = 0.2):
        self.ctx = ctx
        self.publish_interval = publish_interval
        self.debounce = debounce
        """Seconds a request waits for a newer one (a dragged slider asks every frame)."""
        self.solver = None
        self.voxelizing: BackgroundTask | None = None
        self.error: str | None = None
        self.steps = 0
        self._request = None          # (scene, settings) to solve
        self._requested_at = 0.0
        self._waiting = False         # the request is not being voxelized yet
        self._voxelizing_request = None
        self._unpublished = False
        self._published_at = 0.0

    def restart(self, scene: Scene, settings: GISettings) -> None:
        self._request, self._requested_at, self._waiting = (scene, settings), time.perf_counter(), True
        self.error, self.steps = None, 0

    @property
    def busy(self) -> bool:
        return self.error is None and (self._waiting or self.voxelizing is not None
                                       or (self.solver is not None and (not self.solver.converged or self._unpublished)))

    def step(self, budget_ms: float) -> ProbeGrid | None:
        """Work for about `budget_ms`; returns new probes when it is time to show them."""
        from viewer.rays.voxels import voxelize

        try:
            now = time.perf_counter()
            if self.voxelizing is not None and self.voxelizing.done:
                task, request, self.voxelizing = self.voxelizing, self._voxelizing_request, None
                if task.error:
                    self.error = task.error
                    return None
                if request is self._request:   # else a newer request is waiting: drop these voxels
                    self._start(task.result)
            if self._waiting and self.voxelizing is None and now - self._requested_at >= self.debounce:
                scene, settings = self._request
                self._waiting, self._voxelizing_request = False, self._request
                self.voxelizing = BackgroundTask("voxelize", voxelize, scene, settings.voxels, settings.normal_mode)
            if self.solver is None or self._waiting or self.voxelizing is not None:
                return None
            if self._unpublished and (self.solver.converged or now - self._published_at >= self.publish_interval):
                # A frame of its own: the read-back, the upload and the redraw they cause are not added
                # to a solver step's budget.
                self._unpublished, self._published_at = False, now
                return self.solver.probe_grid(include_emitted=False)
            if not self.solver.converged:
                self._unpublished |= self.solver.step(budget_ms)
                self.steps += 1
        except Exception as exc:  # e.g. a compute shader that does not compile: shown in the panel
            self.error = f"{type(exc).__name__}: {exc}"
        return None

    def _start(self, voxels) -> None:
        from viewer.gpu.compute_solver import ComputeSolver

        scene, settings = self._request
        if self.solver is None:
            self.solver = ComputeSolver(self.ctx, voxels, scene.sun, settings, bounds=scene.bounds)
        else:
            self.solver.restart(voxels, scene.sun, settings, bounds=scene.bounds)
        self._unpublished = False

    def release(self) -> None:
        if self.solver is not None:
            self.solver.release()
            self.solver = None

    def status(self) -> str:
        if self._waiting:
            return "Compute solver: starting..."
        if self.voxelizing is not None:
            return f"Compute solver: voxelizing, {self.voxelizing.elapsed:.1f} s"
        if self.solver is None:
            return "Compute solver: idle."
        solver = self.solver
        return f"Compute solver: {solver.phase}, {plural(solver.bounces, 'bounce')}, {self.steps} steps."
