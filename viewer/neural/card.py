"""A trained network's files: the `.onnx` graph and the JSON card beside it (`models/<name>.json`), read
and checked, and the onnxruntime session that runs the graph (viewer.neural.field runs it)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from viewer.neural import encoding
from viewer.neural.domain import Domain


class ModelError(ValueError):
    """The model file or its card is missing, corrupt or made for other inputs."""


def open_session(path: Path, threads: int = 1):
    """An onnxruntime session on the CPU, or ModelError in one line. One thread by default (the timings the
    docs compare are of one); with more, the threads sleep between runs instead of spin-waiting, which took
    a core from the renderer's threads (two threads that spin made a Cornell box's albedo edit 63 ms to
    the settled frame where one made it 66 and two that sleep 54, on 2 cores: the viewer's choice,
    `viewer.ui.neural_source`)."""
    try:
        import onnxruntime as ort
    except ImportError as exc:
        raise ModelError(f"the neural GI source needs onnxruntime ({exc}): pip install onnxruntime") from None
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    if threads > 1:
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
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
    def seen_rays(self) -> int:
        """The seen rays a probe the network learned on, which the runtime casts (SEEN_RAYS on older cards)."""
        return int(self.data["inputs"].get("seen_rays", encoding.SEEN_RAYS))

    @property
    def direct_shadows(self) -> bool:
        """Whether the network's direct-light input carries the probes' shadows (`encoding.DIRECT_SHADOWS`;
        cards written before they could be left out say nothing, and had them)."""
        return bool(self.data["inputs"].get("direct_shadows", True))

    @property
    def sha256(self) -> str:
        return str(self.data["sha256"])

    @property
    def domain(self) -> Domain:
        """What the model was trained on (viewer.neural.domain): the card's `domain`, or for a card written
        before cards had one, the domain of the ranges its dataset names (`training.ranges`; `v1`, the
        first dataset's, when it names none)."""
        if "domain" in self.data:
            return Domain.from_dict(self.data["domain"])
        return Domain.from_preset(str(self.data.get("training", {}).get("ranges", "v1")))

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
            _ = (card.probes, card.voxels, card.sha256, data["inputs"]["encoding_version"], card.domain)
            if card.seen_rays < 1:
                raise ValueError(f"seen_rays {card.seen_rays}")
        except (ValueError, KeyError, TypeError) as exc:
            raise ModelError(f"{card_path.name}: not a valid model card ({exc})") from None
        return card


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
