"""The viewer's compute GI source for the physical kernel: gi.PhysicalGI with its relight in compute
shaders (viewer.gpu.compute_relight).

Tracing (the geometry stage, the lamp paths, the sun's) runs on a worker thread: its traces are compiled
code that releases the GIL, so the window keeps drawing. The relight runs on the render thread's context
in the frame the tracing lands, or at once when an edit needs no tracing:

- a colour or intensity edit: relight only, its probes in the next frame;
- a lamp drag: the lamp paths against the geometry as it is (the lamp's own occlusion where it was), then
  the relight; once the drag stops, the geometry is traced again with the lamp where it is now;
- a new scene or a geometry edit: everything, then the first bounce is shown, then the converged light.
"""

from __future__ import annotations

import time
from viewer.gi import GISettings, PhysicalGI, Timings
from viewer.probes import ProbeGrid
from viewer.scene import Scene
from viewer.ui.background import BackgroundTask


class RelightSource:
    def __init__(self, ctx):
        self.ctx = ctx
        self.gi: PhysicalGI | None = None
        self.relighter = None
        self.tracing: BackgroundTask | None = None
        self.error: str | None = None
        self.milliseconds: dict[str, float] = {}
        """Stage -> milliseconds of the last update (tracing and relight)."""
        self.sweeps = 0
        self.edit_to_probes: float | None = None
        """Seconds from a request to its converged probes on screen, for the last one that got there."""
        self._request = None          # (scene, settings, asked at): the latest request not started yet
        self._tracing_request = None  # the request the running trace is for
        self._converge_next = None    # a new geometry's first bounce is shown: the rest comes next frame
        self._exact_later = None      # a lamp drag was answered on the old geometry: trace it once it rests

    def restart(self, scene: Scene, settings: GISettings) -> None:
        self._request = (scene, settings, time.perf_counter())
        self.error = None

    @property
    def busy(self) -> bool:
        return self.error is None and any(x is not None for x in (
            self._request, self.tracing, self._converge_next, self._exact_later))

    def step(self, budget_ms: float = 0.0) -> ProbeGrid | None:
        """Once a frame: returns new probes (the renderer's indirect light) when there are some."""
        try:
            return self._step()
        except Exception as exc:  # noqa: BLE001 - e.g. a shader that does not compile: shown in the panel
            self.error = f"{type(exc).__name__}: {exc}"
            self.tracing = None
            return None

    def _step(self) -> ProbeGrid | None:
        if self.tracing is not None:
            if not self.tracing.done:
                return None
            task, traced_for, self.tracing = self.tracing, self._tracing_request, None
            if task.error:
                self.error = task.error
                return None
            prepared, timings = task.result
            self.gi.install(prepared)
            self.milliseconds = {k: 1000 * v for k, v in timings.stages.items()}
            if self._request is None:
                self._request = traced_for
                if "geometry" in prepared.ran and not self.gi.needs_tracing(traced_for[0]):
                    self._request, self._converge_next = None, traced_for
                    return self._relight(traced_for, bounces=1)      # a new scene's first bounce
        if self._converge_next is not None and self._request is None:
            request, self._converge_next = self._converge_next, None
            return self._relight(request)
        if self._request is None:
            if self._exact_later is not None:
                request, self._exact_later = self._exact_later, None
                self._trace(request, stale_geometry=False)
            return None
        request, self._request, self._converge_next = self._request, None, None
        scene, settings, _ = request
        if self.gi is None or self.gi.settings != settings:
            self._new_solver(settings)
        if self.gi.needs_tracing(scene, stale_geometry=True):
            self._trace(request, stale_geometry=True)
            return None
        grid = self._relight(request)
        self._exact_later = request if self.gi.needs_tracing(scene) else None
        return grid

    def _new_solver(self, settings: GISettings) -> None:
        from viewer.gpu.compute_relight import ComputeRelight

        if self.relighter is None:
            self.relighter = ComputeRelight(self.ctx)
        self.gi = PhysicalGI(settings, self.relighter)

    def _trace(self, request, stale_geometry: bool) -> None:
        scene = request[0]
        timings = Timings()
        gi = self.gi
        self._tracing_request = request
        self.tracing = BackgroundTask("trace", lambda: (gi.prepare(scene, stale_geometry, timings), timings))

    def _relight(self, request, bounces: int | None = None) -> ProbeGrid:
        scene, settings, asked = request
        timings = Timings()
        lighting = self.gi.relight(scene, timings, bounces)
        grid = self.gi.probe_grid(include_emitted=False, timings=timings)
        self.milliseconds["relight"] = 1000 * timings.stages["relight"]
        self.sweeps = lighting.sweeps
        if bounces is None:
            self.edit_to_probes = time.perf_counter() - asked
        return grid

    def status(self) -> str:
        if self.tracing is not None:
            return f"Compute solver: tracing the scene, {self.tracing.elapsed:.1f} s"
        if self.gi is None or self.gi.lighting is None:
            return "Compute solver: starting..."
        ms = self.milliseconds
        traced = ", ".join(f"{name} {ms[name]:.0f} ms" for name in ("voxelize", "geometry") if name in ms)
        state = "converging" if self.busy else "converged"
        line = f"Compute solver: {state}; relight {ms.get('relight', 0):.0f} ms ({self.sweeps} bounces)"
        if self.edit_to_probes is not None:
            line += f", edit to GI {1000 * self.edit_to_probes:.0f} ms"
        return line + (f"; traced: {traced}" if traced else "") + "."

    def release(self) -> None:
        if self.relighter is not None:
            self.relighter.release()
            self.relighter = None
