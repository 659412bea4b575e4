"""The truth the tools measure against: Mitsuba's incident-radiance SH at points, cached on disk."""

from __future__ import annotations

import numpy as np

from viewer.reference import cache as reference_cache
from viewer.reference import mitsuba as reference
from viewer.scene import Scene


def truth_sh(scene: Scene, points: np.ndarray, directions: int = 1024, include_emitted: bool = True,
             seed: int = 0) -> np.ndarray:
    """Mitsuba's incident-radiance SH (P, 9, 3) at points, or its reflected part only (the indirect light,
    `reference.probe_sh_parts`), both cached on disk."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    if include_emitted:
        return reference.probe_sh(scene, points, directions=directions, seed=seed)
    tag = f"stability-reflected|{reference.CACHE_VERSION}|{reference.variant()}"
    digest = reference_cache.key(tag, scene, [points], dict(directions=int(directions), seed=int(seed)))
    return reference_cache.load_or_compute(
        "probe_sh_reflected", digest, lambda: reference.probe_sh_parts(scene, points, directions, seed=seed)[0])
