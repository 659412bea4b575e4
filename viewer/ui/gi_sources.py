"""Where the viewer's indirect light comes from: off, the compute-shader solver, the CPU (numpy)
solver, or the neural field; one place that restarts the active source when the scene or the GI
settings change and hands finished probe grids to the render loop.

The CPU solver (viewer.physical.gi.solve) runs in a worker process (viewer.ui.background.SolverProcess) and its
grid replaces the shown one when it is done. The compute solver (viewer.gpu.compute_solver) runs on the
render thread's GL context, a few milliseconds a frame, and its probes are shown as they converge.
"""

from __future__ import annotations

import importlib.util
import time
from dataclasses import replace
from pathlib import Path

from viewer.neural.domain import warning
from viewer.physical.gi import GISettings
from viewer.probes.grid import ProbeGrid
from viewer.resources import MODELS
from viewer.scene import Scene
from viewer.ui.background import SOLVER_STAGES, BackgroundTask, SolverProcess

SOURCES = ("off", "compute", "solver", "neural", "baked")
LABELS = {"off": "Off (direct only)", "compute": "Compute (GPU)", "solver": "CPU solver (numpy)",
          "neural": "Neural (ONNX)", "baked": "Baked (.npz file)"}
NO_BAKED_GRID = "No baked grid: open one with `gi-viewer FILE.npz` (write it with `gi-viewer bake`)."


def unavailable_reasons() -> dict[str, str]:
    """Source -> why it cannot be chosen in this build (sources missing from the dict can)."""
    reasons = {}
    if importlib.util.find_spec("viewer.gpu.compute_solver") is None:
        reasons["compute"] = ("The compute-shader solver (viewer/gpu/compute_solver.py) is not part of "
                              "this build yet.")
    if not (MODELS / "probenet.onnx").is_file():
        reasons["neural"] = "No trained model: the neural field needs models/probenet.onnx (docs/TRAINING.md)."
    reasons["baked"] = NO_BAKED_GRID
    return reasons


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
        return f"Compute solver: {solver.phase}, {solver.bounces} bounces, {self.steps} steps."


class NeuralSource:
    """The trained network (viewer.neural.field.NeuralGI). A colour edit (an albedo, the lamp's colour or
    intensity) keeps the voxels and recolours them, and the network runs on the render thread at once
    (a millisecond when only the lamp's colour changed: the network's output is reused, scaled). A
    moved lamp or a new scene is voxelized off the render thread first, as for the compute solver;
    the network then runs in the frame the voxels arrive.

    Creating it loads and checks the model: a missing, corrupt or mismatched model raises
    `viewer.neural.field.ModelError`, which the controller shows and answers by falling back to the compute
    solver."""

    def __init__(self, model: Path | None = None):
        from viewer.neural.field import DEFAULT_MODEL, NeuralField, NeuralGI

        self.field = NeuralField(model or DEFAULT_MODEL)
        self.gi = NeuralGI(self.field)
        self.voxelizing: BackgroundTask | None = None
        self.error: str | None = None
        self.milliseconds: dict[str, float] = {}
        """Stage -> milliseconds of the last update (voxelize or recolour, encode, network, unpack)."""
        self.edit_to_probes: float | None = None
        """Seconds from the last request to its probes."""
        self.outside: list[str] = []
        """Why the scene of the last probes lies outside the model's training domain (viewer.neural.domain)."""
        self._request = None              # (scene, asked at): the latest request not started yet
        self._voxelizing_request = None

    def restart(self, scene: Scene, settings: GISettings) -> None:
        self._request, self.error = (scene, time.perf_counter()), None

    @property
    def busy(self) -> bool:
        return self.error is None and (self._request is not None or self.voxelizing is not None)

    def step(self) -> ProbeGrid | None:
        try:
            if self.voxelizing is not None:
                if not self.voxelizing.done:
                    return None
                task, request, self.voxelizing = self.voxelizing, self._voxelizing_request, None
                if task.error:
                    self.error = task.error
                    return None
                self.gi.install(task.result)
                self.milliseconds = {"voxelize": 1000 * task.elapsed}
                if self._request is None:   # no newer edit waiting: these voxels are current
                    return self._predict(request)
            if self._request is not None:
                request, self._request = self._request, None
                if self.gi.needs_voxelizing(request[0]):
                    self._voxelizing_request = request
                    self.voxelizing = BackgroundTask("voxelize", self.gi.prepare, request[0])
                    return None
                self.milliseconds = {}
                return self._predict(request)
        except Exception as exc:  # noqa: BLE001 - shown in the panel, the viewer keeps running
            self.error = f"{type(exc).__name__}: {exc}"
        return None

    def _predict(self, request) -> ProbeGrid:
        scene, asked = request
        timings: dict[str, float] = {}
        grid = self.gi.predict(scene, include_emitted=False, timings=timings)
        self.milliseconds.update({k: 1000 * v for k, v in timings.items()})
        self.edit_to_probes = time.perf_counter() - asked
        self.outside = self.gi.outside(scene)
        return grid

    def status(self) -> str:
        if self.voxelizing is not None:
            return f"Neural: voxelizing, {self.voxelizing.elapsed:.1f} s"
        if self.milliseconds:
            ms = self.milliseconds
            network = ms.get("encode", 0) + ms.get("network", 0) + ms.get("unpack", 0)
            voxels = (f"voxelize {ms['voxelize']:.0f} ms" if "voxelize" in ms
                      else f"recolour {ms.get('recolour', 0):.1f} ms")
            line = (f"Neural ({self.field.card.path.name}): {network:.1f} ms network "
                    f"({self.field.passes_run}/3 passes run), {voxels}")
            if self.edit_to_probes is not None:
                line += f"; edit to GI {1000 * self.edit_to_probes:.0f} ms"
            return line + "."
        return "Neural: starting..."


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
            del self.unavailable["baked"]
        self.source = source if source not in self.unavailable else "off"
        self.settings = settings or GISettings()
        self.compute_budget_ms = compute_budget_ms
        """Milliseconds of compute-solver work per frame (ComputeSolver.step)."""
        self.scene: Scene | None = None
        self._scene_version = -1
        self._cpu: SolverProcess | None = None
        self._cpu_key = None         # (scene version, settings) of the grid the CPU solver last finished
        self._cpu_grid: ProbeGrid | None = None
        self._cpu_requested = None   # (scene version, settings) of the solve under way
        self._compute: ComputeSource | None = None
        self._neural: NeuralSource | None = None
        self.fallback: str | None = None   # why the neural source was left for the compute solver
        self._outgoing: list[ProbeGrid | None] = []   # grids for the render loop to show, oldest first
        self.ready_seconds: float | None = None        # how long the last finished solve took

    @property
    def traces_on_every_core(self) -> bool:
        """Whether the source's work on a new scene keeps every core busy (the physical solvers' traces),
        so that the renderer's own work beside it would delay its first probes."""
        return self.source in ("compute", "solver")

    # ---- inputs -----------------------------------------------------------------------------------------
    def set_scene(self, scene: Scene, version: int, new_scene: bool = False) -> None:
        """The scene changed (an edit, or a new file: then the old probes no longer fit and go at once)."""
        if new_scene and self.scene is not None and self.baked is not None:  # the baked probes fit no other
            self.baked, self.unavailable["baked"] = None, NO_BAKED_GRID
            if self.source == "baked":
                self.source = "compute" if "compute" not in self.unavailable else "off"
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
        settings = replace(self.settings, **changes)
        if settings != self.settings:
            self.settings = settings
            self._restart()

    def _restart(self) -> None:
        if self.scene is None:
            return
        if self.source != "solver" and self._cpu is not None:
            self._cpu.cancel()
        if self.source == "off":
            self._outgoing.append(None)
        elif self.source == "solver":
            key = (self._scene_version, self.settings)
            if key == self._cpu_key:
                self._cpu.cancel()
                self._outgoing.append(self._cpu_grid)   # already solved: show it again
            else:
                self._cpu = self._cpu or SolverProcess()
                self._cpu.request(self.scene, self.settings)
                self._cpu_requested = key
        elif self.source == "baked":
            self._outgoing.append(self.baked)
        elif self.source == "neural":
            if self._neural is None:
                from viewer.neural.field import ModelError

                try:
                    self._neural = NeuralSource(self.neural_model)
                except ModelError as exc:
                    self.fallback = f"Neural model unusable: {exc}. Using the compute solver instead."
                    self.source = "compute" if "compute" not in self.unavailable else "off"
                    self._restart()
                    return
            self.fallback = None
            self._neural.restart(self.scene, self.settings)
        if self.source == "compute":
            # the physical kernel relights (viewer.ui.relight_source); the paper's kernel keeps the
            # all-pairs solver
            from viewer.ui.relight_source import RelightSource

            kind = RelightSource if self.settings.kernel == "physical" else ComputeSource
            if not isinstance(self._compute, kind):
                if self._compute is not None:
                    self._compute.release()
                self._compute = kind(self.ctx)
            self._compute.restart(self.scene, self.settings)

    # ---- per frame ----------------------------------------------------------------------------------------
    def update(self) -> tuple[bool, ProbeGrid | None]:
        """(changed, grid): whether the shown probes should change, and to what (None: no indirect)."""
        if self._cpu is not None:
            grid = self._cpu.poll()
            if grid is not None and self.source == "solver":
                self._cpu_key, self._cpu_grid = self._cpu_requested, grid
                self.ready_seconds = sum(self._cpu.last_seconds.values())
                self._outgoing.append(grid)
        if self._compute is not None and self.source == "compute":
            grid = self._compute.step(self.compute_budget_ms)
            if grid is not None:
                self._outgoing.append(grid)
        if self._neural is not None and self.source == "neural":
            grid = self._neural.step()
            if grid is not None:
                self._outgoing.append(grid)
        if self._outgoing:
            grid = self._outgoing[-1]
            self._outgoing.clear()
            return True, grid
        return False, None

    @property
    def domain_warning(self) -> str | None:
        """While the neural source shows a scene outside its model's training domain: one line that says
        so, why, and that the physical solver computes it (viewer.neural.domain.warning); else None."""
        if self.source != "neural" or self._neural is None:
            return None
        return warning(self._neural.outside)

    @property
    def busy(self) -> bool:
        """Still working towards the probes for the current scene and settings."""
        if self.source == "solver":
            return self._cpu is not None and self._cpu.busy
        if self.source == "compute":
            return self._compute is not None and self._compute.busy
        if self.source == "neural":
            return self._neural is not None and self._neural.busy
        return False

    def status(self) -> tuple[str, float | None, str | None]:
        """(one line for the panel, progress 0..1 or None, error or None)."""
        if self.source == "off":
            return "Direct light only.", None, None
        if self.source == "solver":
            cpu = self._cpu
            if cpu is not None and cpu.error:
                return "CPU solver failed.", None, cpu.error
            if cpu is not None and cpu.busy:
                if cpu.running_since is None:
                    return "CPU solver: starting...", 0.0, None
                step = min(len(cpu.stages_done) + 1, len(SOLVER_STAGES))
                return (f"CPU solver: {cpu.stage} ({step}/{len(SOLVER_STAGES)}), {cpu.elapsed:.1f} s",
                        cpu.progress, None)
            if self.ready_seconds is not None:
                return f"CPU solver: done in {self.ready_seconds:.1f} s.", 1.0, None
            return "CPU solver: idle.", None, None
        if self.source == "compute":
            if self._compute is None:
                return "Compute solver: idle.", None, self.fallback
            if self._compute.error:
                return "Compute solver failed.", None, self._compute.error
            return self._compute.status(), None, self.fallback
        if self.source == "baked":
            return "Baked probes, as read from the file (edits do not relight them).", None, None
        if self.source == "neural" and self._neural is not None:
            if self._neural.error:
                return "Neural source failed.", None, self._neural.error
            return self._neural.status(), None, None
        return "Not available.", None, None

    def close(self) -> None:
        if self._cpu is not None:
            self._cpu.close()
        if self._compute is not None:
            self._compute.release()
