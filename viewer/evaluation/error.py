"""The error every accuracy table reports, and the public scene it is reported on when present."""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
PUBLIC_BOX = ROOT.parent / "shared" / "scenes" / "cornellbox-original" / "CornellBox-Original.obj"


def relative_rmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    """sqrt(mean((est - ref)^2)) / sqrt(mean(ref^2)) over all points, SH coefficients and channels."""
    return float(np.sqrt(np.mean((estimate - truth) ** 2)) / np.sqrt(np.mean(truth ** 2)))
