"""VoxelGrid -> ProbeGrid in one shot: the trained network (ONNX) run by onnxruntime on the CPU.

A model is a `.onnx` file with a JSON card beside it (`models/<name>.json`): what the network reads
(`viewer.encoding` version, voxel resolution), the probe lattice it writes, how it was trained, its
measured error and the file's sha256. Anything that does not match (missing file, corrupt bytes, another
encoding version, unexpected tensor shapes) is a `ModelError` with one readable line: the command line
turns it into exit status 2, the viewer into a message and a fall-back to the compute solver.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer import encoding
from viewer.probes import ProbeGrid
from viewer.resources import DEFAULT_MODEL
from viewer.scene import Scene
from viewer.voxels import VoxelGrid, voxelize

OUTPUTS = 19
"""Per probe and colour pass: 9 SH of all the light, 9 of the reflected light, 1 validity logit."""


class ModelError(ValueError):
    """The model file or its card is missing, corrupt or made for other inputs."""


def open_session(path: Path, threads: int = 1):
    """An onnxruntime session on the CPU, or ModelError in one line. One thread by default: the networks
    are small, and a second one fights the renderer's threads for the two cores (measured slower under
    load, docs/PERFORMANCE.md)."""
    try:
        import onnxruntime as ort
    except ImportError as exc:
        raise ModelError(f"the neural GI source needs onnxruntime ({exc}): pip install onnxruntime") from None
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    try:
        return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # noqa: BLE001 - onnxruntime raises its own types for bad files
        raise ModelError(f"{Path(path).name}: onnxruntime cannot load it ({str(exc).splitlines()[0]})") from None


@dataclass(frozen=True)
class ModelCard:
    path: Path
    """The .onnx file."""
    data: dict
    """The card as written by `viewer.training.export`."""

    @property
    def probes(self) -> int:
        return int(self.data["probes"]["resolution"])

    @property
    def voxels(self) -> int:
        return int(self.data["inputs"]["voxels"])

    @property
    def sha256(self) -> str:
        return str(self.data["sha256"])

    @staticmethod
    def read(model: Path) -> "ModelCard":
        card_path = model.with_suffix(".json")
        if not model.is_file():
            raise ModelError(f"no trained model at {model} (train one: see docs/TRAINING.md)")
        if not card_path.is_file():
            raise ModelError(f"{model.name} has no model card ({card_path.name})")
        try:
            data = json.loads(card_path.read_text())
            card = ModelCard(model, data)
            _ = (card.probes, card.voxels, card.sha256, data["inputs"]["encoding_version"])
        except (ValueError, KeyError, TypeError) as exc:
            raise ModelError(f"{card_path.name}: not a valid model card ({exc})") from None
        return card


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


_blas = None


def _one_blas_thread():
    """BLAS on one thread for the encoding's small products: OpenBLAS's threads spin-wait for each
    other, and when the renderer (or anything else) keeps the second core busy a 36864 x 16 x 3 product
    takes 30 ms instead of 0.4 ms (measured here)."""
    global _blas
    if _blas is None:
        from threadpoolctl import ThreadpoolController

        _blas = ThreadpoolController()
    return _blas.limit(limits=1, user_api="blas")


class NeuralField:
    """A loaded model: `predict` maps voxels to probes."""

    def __init__(self, model: str | Path = DEFAULT_MODEL, threads: int = 1):
        self.card = ModelCard.read(Path(model))
        if file_sha256(self.card.path) != self.card.sha256:
            raise ModelError(f"{self.card.path.name}: file does not match its card's sha256 (corrupt or replaced)")
        version = self.card.data["inputs"]["encoding_version"]
        if version != encoding.VERSION:
            raise ModelError(f"{self.card.path.name} was trained on encoding version {version}, "
                             f"this viewer encodes version {encoding.VERSION}")
        self.session = open_session(self.card.path, threads)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) != 1 or inputs[0].shape[1] != encoding.CHANNELS:
            raise ModelError(f"{self.card.path.name}: expects inputs {inputs[0].shape}, "
                             f"the encoding gives (3, {encoding.CHANNELS}, M, M, M)")
        if len(outputs) != 1 or outputs[0].shape[1] != OUTPUTS:
            raise ModelError(f"{self.card.path.name}: gives outputs {outputs[0].shape}, expected (3, {OUTPUTS}, M, M, M)")
        self.input_name = inputs[0].name

    @property
    def resolution(self) -> int:
        return self.card.probes

    def predict(self, voxels: VoxelGrid, sun, lo, hi, include_emitted: bool = True,
                timings: dict | None = None, resolution: int | None = None) -> ProbeGrid:
        """Probes over [lo, hi]: all the incident light (`include_emitted`, as `sample` and Mitsuba see
        it) or the light reflected by surfaces alone (what the renderer samples). `resolution` other
        than the card's runs the same convolutional network on another lattice (for timing; its
        accuracy there is not what the card measured)."""
        clock = time.perf_counter()
        with _one_blas_thread():
            enc = encoding.encode(voxels, sun, lo, hi, resolution or self.resolution)
        encoded = time.perf_counter()
        out = self.session.run(None, {self.input_name: enc.inputs})[0]  # (3, 19, M, M, M)
        ran = time.perf_counter()
        part = out[:, 0:9] if include_emitted else out[:, 9:18]
        coefficients = (part * enc.scale[:, None, None, None, None]).transpose(2, 3, 4, 1, 0)
        valid = out[:, 18].mean(axis=0) > 0.0
        grid = ProbeGrid(lo=enc.lo, hi=enc.hi, coefficients=np.ascontiguousarray(coefficients, np.float32),
                         valid=valid)
        if timings is not None:
            timings.update(encode=encoded - clock, network=ran - encoded, unpack=time.perf_counter() - ran)
        return grid

    def solve(self, scene: Scene, include_emitted: bool = True, timings: dict | None = None) -> ProbeGrid:
        """Voxelize the scene at the card's resolution and predict over its bounds."""
        clock = time.perf_counter()
        voxels = voxelize(scene, self.card.voxels)
        if timings is not None:
            timings["voxelize"] = time.perf_counter() - clock
        lo, hi = scene.bounds
        return self.predict(voxels, scene.sun, lo, hi, include_emitted, timings)
