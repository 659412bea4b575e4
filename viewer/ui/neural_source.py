"""The viewer's neural GI source: the trained network (viewer.neural.field.NeuralGI) run on the render
thread once the scene's voxels are ready, with its timings and domain warning for the panel.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from viewer.physical.gi import GISettings
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene
from viewer.ui.background import BackgroundTask


NETWORK_THREADS = min(4, os.cpu_count() or 1)
"""onnxruntime's threads in the viewer (sleeping between runs: viewer.neural.field.open_session)."""


class NeuralSource:
    """The trained network (viewer.neural.field.NeuralGI). A colour edit (an albedo, the lamp's colour or
    intensity) keeps the voxels and recolours them, and the network runs on the render thread at once
    (a millisecond when only the lamp's colour changed: the network's output is reused, scaled). A
    moved lamp or object or a new scene is voxelized off the render thread, as for the compute solver,
    and the network runs there too as soon as the voxels are made: the frame that bakes the new
    geometry's direct light goes on meanwhile. Run on the render thread after that frame instead, the
    Cornell box's probes reached the screen 174-243 ms after a moved box, 157-177 after a moved lamp and
    283-311 after the scene opened; now 147-192, 140-155 and 190-203 (`python -m viewer.bench.edits
    cornell --sources neural`, 2 cores, where llvmpipe bakes on the same cores).

    Creating it loads and checks the model: a missing, corrupt or mismatched model raises
    `viewer.neural.field.ModelError`, which the controller shows and answers by falling back to the compute
    solver."""

    def __init__(self, model: Path | None = None):
        from viewer.neural.field import DEFAULT_MODEL, NeuralField, NeuralGI

        self.field = NeuralField(model or DEFAULT_MODEL, threads=NETWORK_THREADS)
        self.gi = NeuralGI(self.field)
        self.voxelizing: BackgroundTask | None = None
        """Voxelizing a new geometry and predicting its probes, off the render thread; while it runs the
        render thread leaves `gi` alone."""
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
                grid, self.milliseconds = task.result
                if self._request is None:   # no newer edit waiting: these probes are current
                    return self._delivered(grid, request)
            if self._request is not None:
                request, self._request = self._request, None
                if self.gi.needs_voxelizing(request[0]):
                    self._voxelizing_request = request
                    self.voxelizing = BackgroundTask("voxelize and predict", self._voxelized_probes, request[0])
                    return None
                timings: dict[str, float] = {}
                grid = self.gi.predict(request[0], include_emitted=False, timings=timings)
                self.milliseconds = {k: 1000 * v for k, v in timings.items()}
                return self._delivered(grid, request)
        except Exception as exc:  # noqa: BLE001 - shown in the panel, the viewer keeps running
            self.error = f"{type(exc).__name__}: {exc}"
        return None

    def _voxelized_probes(self, scene: Scene) -> tuple[ProbeGrid, dict[str, float]]:
        """On the worker: the scene voxelized and installed, and its probes with the stages' milliseconds."""
        clock = time.perf_counter()
        self.gi.install(self.gi.prepare(scene))
        milliseconds = {"voxelize": 1000 * (time.perf_counter() - clock)}
        timings: dict[str, float] = {}
        grid = self.gi.predict(scene, include_emitted=False, timings=timings)
        milliseconds.update({k: 1000 * v for k, v in timings.items()})
        return grid, milliseconds

    def _delivered(self, grid: ProbeGrid, request) -> ProbeGrid:
        scene, asked = request
        self.edit_to_probes = time.perf_counter() - asked
        self.outside = self.gi.outside(scene)
        return grid

    def status(self) -> str:
        if self.voxelizing is not None:
            return f"Neural: voxelizing and predicting, {self.voxelizing.elapsed:.1f} s"
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
