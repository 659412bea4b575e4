"""The viewer's compute GI source for the physical kernel: gi.PhysicalGI, traced once per geometry and
relit after every edit.

Tracing (the geometry stage, the lamp paths, the sun's) runs on a worker thread: its traces are compiled
code that releases the GIL, so the window keeps drawing. The relight runs where it is fastest on this
device: in compute shaders on the render thread's context (viewer.gpu.compute_relight) on a real GPU, or
with the tracing on the worker thread (viewer.physical.relight, compiled, all cores) on a software GL, where
llvmpipe shares the CPU and the compute relight measured 10x slower (docs/PERFORMANCE.md). Either way:

- a colour or intensity edit: the relight only, on screen within a few frames;
- a lamp drag: the lamp paths against the geometry as it is (the lamp's own occlusion where it was), then
  the relight; once the lamp rests, the geometry is traced again with the lamp where it is now;
- a new scene or a geometry edit: everything; the first bounce is shown, then the converged light.
"""

from __future__ import annotations

import time

from viewer import wake
from viewer.physical.gi import GISettings, PhysicalGI, Timings
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene
from viewer.progress import plural
from viewer.ui.background import BackgroundTask

SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast", "software")


def relight_backend(ctx) -> str:
    """`gpu` (compute shaders) on a GPU, `cpu` on a software rasterizer or without a context."""
    if ctx is None:
        return "cpu"
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    return "cpu" if any(name in renderer for name in SOFTWARE_GL) else "gpu"


class RelightSource:
    def __init__(self, ctx, backend: str | None = None):
        self.ctx = ctx
        self.backend = backend or relight_backend(ctx)
        self.gi: PhysicalGI | None = None
        self.relighter = None
        self.work: BackgroundTask | None = None
        self.error: str | None = None
        self.milliseconds: dict[str, float] = {}
        """Stage -> milliseconds of the last update (tracing and relight)."""
        self.sweeps = 0
        self.edit_to_probes: float | None = None
        """Seconds from a request to its converged probes, for the last one that got there."""
        self._request = None          # (scene, settings, asked at): the latest request not started yet
        self._working_on = None       # the request the worker is busy with
        self._ready: list[tuple[ProbeGrid, bool, object]] = []   # (grid, converged, request), oldest first
        self._converge_next = None    # GPU: a new geometry's first bounce is shown, the rest comes next
        self._exact_later = None      # a lamp drag was answered on the old geometry: trace it once it rests
        self._prepared = None         # GPU: what the worker traced, for the render thread to install
        self._first_bounce = True     # the running work shows a new geometry's first bounce

    def restart(self, scene: Scene, settings: GISettings) -> None:
        self._request = (scene, settings, time.perf_counter())
        self.error = None

    @property
    def busy(self) -> bool:
        return self.error is None and (any(x is not None for x in (
            self._request, self.work, self._converge_next, self._exact_later)) or bool(self._ready))

    def step(self, budget_ms: float = 0.0) -> ProbeGrid | None:
        """Once a frame: returns new probes (the renderer's indirect light) when there are some."""
        try:
            return self._step()
        except Exception as exc:  # noqa: BLE001 - e.g. a shader that does not compile: shown in the panel
            self.error = f"{type(exc).__name__}: {exc}"
            self.work = None
            return None

    # ---- the frame's step ---------------------------------------------------------------------------------
    def _step(self) -> ProbeGrid | None:
        if self.work is not None:
            if not self.work.done:
                return self._publish()
            task, request, self.work = self.work, self._working_on, None
            if task.error:
                self.error = task.error
                return None
            self.milliseconds.update({k: 1000 * v for k, v in task.result.stages.items()})
            if self.backend == "gpu":
                shown = self._after_tracing(request)
                if shown is not None:
                    return shown
        grid = self._publish()
        if grid is not None:
            return grid
        if self._converge_next is not None and self._request is None:
            request, self._converge_next = self._converge_next, None
            return self._relight_here(request)
        if self._request is None:
            if self._exact_later is not None:
                request, self._exact_later = self._exact_later, None
                self._start(request, stale_geometry=False)
            return None
        request, self._request, self._converge_next = self._request, None, None
        scene, settings, _ = request
        if self.gi is None or self.gi.settings != settings:
            self._new_solver(settings)
        if self.backend == "gpu" and not self.gi.needs_tracing(scene, stale_geometry=True):
            grid = self._relight_here(request)
            self._exact_later = None if self.gi.geometry_fits(scene) else request
            return grid
        self._start(request, stale_geometry=True)
        return None

    def _publish(self) -> ProbeGrid | None:
        """The oldest grid the worker finished, one a frame (a new scene's first bounce, then the rest)."""
        if not self._ready:
            return None
        grid, converged, request = self._ready.pop(0)
        if converged:
            self.edit_to_probes = time.perf_counter() - request[2]
        return grid

    def _new_solver(self, settings: GISettings) -> None:
        if self.backend == "gpu":
            from viewer.gpu.compute_relight import ComputeRelight

            self.relighter = self.relighter or ComputeRelight(self.ctx)
            self.gi = PhysicalGI(settings, self.relighter)
        else:
            self.gi = PhysicalGI(settings)

    def _start(self, request, stale_geometry: bool) -> None:
        """Trace what the request needs on the worker (and on the CPU backend relight there too)."""
        scene = request[0]
        gi, cpu = self.gi, self.backend == "cpu"
        first_bounce = stale_geometry          # a new scene shows its first bounce; the exact follow-up
        self._first_bounce = first_bounce      # of a lamp drag does not dim the light it already shows

        def work() -> Timings:
            timings = Timings()
            prepared = gi.prepare(scene, stale_geometry, timings)
            if not cpu:
                self._prepared = prepared
                return timings
            gi.install(prepared)
            if "geometry" in prepared.ran and first_bounce:
                gi.relight(scene, timings, bounces=1)
                self._ready.append((gi.probe_grid(include_emitted=False), False, request))
                wake.notify()
            lighting = gi.relight(scene, timings)
            self._ready.append((gi.probe_grid(include_emitted=False, timings=timings), True, request))
            self.sweeps = lighting.sweeps
            return timings

        self._working_on = request
        self.work = BackgroundTask("trace" if not cpu else "relight", work)
        if stale_geometry and gi.geometry_fits(scene, stale_geometry=True):
            self._exact_later = None if gi.geometry_fits(scene) else request

    def _after_tracing(self, request) -> ProbeGrid | None:
        """GPU: install what the worker traced and relight here (a new geometry's first bounce first)."""
        prepared, self._prepared = self._prepared, None
        self.gi.install(prepared)
        if self._request is not None:          # a newer request waits: it is next
            return None
        if "geometry" in prepared.ran and self._first_bounce:
            self._converge_next = request
            return self._relight_here(request, bounces=1)
        return self._relight_here(request)

    def _relight_here(self, request, bounces: int | None = None) -> ProbeGrid:
        scene, settings, asked = request
        timings = Timings()
        lighting = self.gi.relight(scene, timings, bounces)
        grid = self.gi.probe_grid(include_emitted=False, timings=timings)
        self.milliseconds["relight"] = 1000 * timings.stages["relight"]
        self.sweeps = lighting.sweeps
        if bounces is None:
            self.edit_to_probes = time.perf_counter() - asked
        return grid

    # ---- the panel ----------------------------------------------------------------------------------------
    def status(self) -> str:
        where = "compute shaders" if self.backend == "gpu" else "CPU"
        if self.work is not None:
            return f"Compute solver: {self.work.label}, {self.work.elapsed:.1f} s"
        if self.gi is None or self.gi.lighting is None:
            return "Compute solver: starting..."
        ms = self.milliseconds
        traced = ", ".join(f"{name} {ms[name]:.0f} ms" for name in ("voxelize", "geometry") if name in ms)
        state = "converging" if self.busy else "converged"
        line = f"Compute solver: {state}; relight ({where}) {ms.get('relight', 0):.0f} ms, {plural(self.sweeps, 'bounce')}"
        if self.edit_to_probes is not None:
            line += f"; edit to GI {1000 * self.edit_to_probes:.0f} ms"
        return line + (f"; traced: {traced}" if traced else "") + "."

    def release(self) -> None:
        if self.relighter is not None:
            self.relighter.release()
            self.relighter = None
