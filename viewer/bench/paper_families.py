"""The paper's five network families (Table 1), as benchmark entries run through onnxruntime.

`python -m viewer.training.table1` trains them and exports each to `runs/table1/{family}-l{lambda}.onnx`
with its standardization beside it (`.npz`). Here a scene goes the way it went in training: voxelized at
16^3, the paper's voxel list, adaptive average pooling, min-max to [-1, 1]; the network's 8^3 x 27
standardized outputs become an 8^3 probe grid over the scene's bounds (the dataset's probe box). No
torch at run time.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from viewer.bench.methods import ROOT, Method, MethodUnavailable, texture_bytes
from viewer.probes.grid import ProbeGrid
from viewer.scene import Scene
from viewer.neural.paper_inputs import PAPER_PROBES, PAPER_VOXELS, adaptive_pool, voxel_list

MODELS = ROOT / "runs" / "table1"
LABELS = {"mlp": "MLP", "resnet10": "ResNet-10", "rnn": "RNN", "cnn": "CNN", "cnn-mlp": "CNN-MLP"}


class PaperFamily:
    """One exported family: `solve(scene)` -> the 8^3 probe grid of all the light (emitted included)."""

    def __init__(self, path: Path):
        from viewer.neural.field import ModelError, open_session

        stats = path.with_suffix(".npz")
        if not stats.is_file():
            raise MethodUnavailable(f"{path}: its standardization {stats.name} is missing")
        with np.load(stats) as z:
            self.lo, self.hi, self.mean, self.std = z["lo"], z["hi"], z["mean"], z["std"]
            self.pooled, self.family = int(z["pooled"]), str(z["family"])
        try:
            self.session = open_session(path)
        except ModelError as exc:
            raise MethodUnavailable(str(exc)) from None

    def inputs(self, scene: Scene) -> np.ndarray:
        from viewer.rays.voxels import voxelize

        pooled = adaptive_pool(voxel_list(voxelize(scene, PAPER_VOXELS)), self.pooled)
        span = np.where(self.hi > self.lo, self.hi - self.lo, 1.0)
        x = (pooled - self.lo[:, None]) / span[:, None] * 2 - 1
        return np.clip(x, -1, 1)[None].astype(np.float32)

    def solve(self, scene: Scene) -> ProbeGrid:
        out = self.session.run(None, {"pooled": self.inputs(scene)})[0][0]
        m = PAPER_PROBES
        coefficients = (out * self.std + self.mean).reshape(m, m, m, 9, 3)
        lo, hi = scene.bounds
        return ProbeGrid(lo, hi, coefficients.astype(np.float32), np.ones((m, m, m), bool))


def paper_family_method(path: Path) -> Method:
    def prepare():
        field = PaperFamily(path)
        return lambda scene, points: field.solve(scene)

    family, _, weight_decay = path.stem.rpartition("-l")
    setting = f"{LABELS.get(family, family)} lambda={weight_decay}"
    return Method("paper-family", setting, prepare, texture_bytes(PAPER_PROBES), path.stat().st_size,
                  about=f"the paper's {LABELS.get(family, family)} (Table 1), voxel list in, 8^3 probes out")


def paper_family_methods(quick: bool = False, folder: Path = MODELS) -> Iterable[Method]:
    """Every exported family; none in quick mode (CI has no trained families)."""
    if quick:
        return []
    return [paper_family_method(p) for p in sorted(folder.glob("*.onnx"))]
