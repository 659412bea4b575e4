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
"""onnxruntime's threads in the viewer (sleeping between runs: viewer.neural.field.open_session): the
network runs on the render thread, between frames, so the cores are its own while it runs."""


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

        self.field = NeuralField(model or DEFAULT_MODEL, threads=NETWORK_THREADS)
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
