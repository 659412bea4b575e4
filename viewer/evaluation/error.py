"""The error every accuracy table reports, and the public scene it is reported on when present."""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
PUBLIC_BOX = ROOT.parent / "shared" / "scenes" / "cornellbox-original" / "CornellBox-Original.obj"
TEXTURED_ROOM = ROOT / "docs" / "data" / "textured-point-room.gltf"
"""A glTF room with textured walls and floor, a ceiling lamp and a warm point light (KHR_lights_punctual):
the benchmark's scene for what a user's glTF brings beyond flat colours and area lamps."""


def benchmark_scenes() -> list[str]:
    """The scenes every full benchmark starts with: the built-in Cornell box and the paper's held-out scene,
    then the public Cornell box and the textured, point-lit room where the checkout has them."""
    return ["cornell", "paper-test"] + [str(p) for p in (PUBLIC_BOX, TEXTURED_ROOM) if p.exists()]


def relative_rmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    """sqrt(mean((est - ref)^2)) / sqrt(mean(ref^2)) over all points, SH coefficients and channels."""
    return float(np.sqrt(np.mean((estimate - truth) ** 2)) / np.sqrt(np.mean(truth ** 2)))
