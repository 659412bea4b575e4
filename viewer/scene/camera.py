"""The camera a scene opens with: its file's own, or one that frames it.

Here, beside the scene data, because both the window (viewer/ui/session.py) and the headless capture
(viewer/gpu/offscreen.py) open a scene with it, and the capture sits below the window's pieces.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from viewer.scene.loading import read_sidecar, scene_file
from viewer.scene.types import Camera, Scene


def framing_camera(lo: np.ndarray, hi: np.ndarray, fov: float = Camera.fov) -> Camera:
    """A camera on +z looking at the centre of the box [lo, hi], far enough to see all of it."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
    distance = radius / math.sin(math.radians(fov) / 2) * 1.05
    origin = centre + np.array([0.0, 0.15 * radius, distance])
    return Camera(tuple(origin), tuple(centre), (0.0, 1.0, 0.0), fov)


def home_camera(scene: Scene, source: str | Path) -> Camera:
    """The scene's own camera when its file comes with one (a sidecar .json, or a glTF camera: the sidecar's
    wins), else one that frames it: what the viewer opens a scene with, and what a headless capture shows."""
    if scene.cameras:
        return scene.camera
    try:
        has_camera = "camera" in read_sidecar(scene_file(source))
    except ValueError:
        has_camera = False
    return scene.camera if has_camera else framing_camera(*scene.bounds)
