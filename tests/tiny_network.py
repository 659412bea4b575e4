"""A small ProbeNet with random weights, exported with its card as the training pipeline writes it: the
network the neural source's tests run (tests/neural/test_field.py, test_model_card.py). Needs torch."""

import json

import torch

from viewer.training import export
from viewer.training.models import ProbeNet, ProbeNetConfig


def random_model(seed: int = 0) -> ProbeNet:
    """A small ProbeNet with every weight random (the zero-initialized last layer too)."""
    torch.manual_seed(seed)
    model = ProbeNet(ProbeNetConfig(width=4, hidden=8, levels=2))
    with torch.no_grad():
        for p in model.parameters():
            p.normal_(0.0, 0.3)
    return model.eval()


def export_tiny(folder):
    """(model, path of its .onnx) for a random model exported into `folder` with a card, on an 8^3 lattice
    of 16^3 voxels."""
    model = random_model()
    path = folder / "tiny.onnx"
    export.export_onnx(model, path, 8)
    export.write_card(path, model, 8, training={"note": "random weights, for tests"}, metrics={})
    card = json.loads(path.with_suffix(".json").read_text())
    card["inputs"]["voxels"] = 16
    path.with_suffix(".json").write_text(json.dumps(card))
    return model, path
