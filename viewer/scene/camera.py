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


FRAMING_ASPECT = 16 / 9
"""The picture's width over its height that a framing camera is made for when none is given."""
FRAMING_MARGIN = 1.05
"""The framed box's nearest edge of the picture lies this factor inside it."""
FRAMING_TILT = 0.15
"""The framing camera looks down at the scene by atan(0.15), 8.5 degrees: floors read as floors."""


def framing_camera(lo: np.ndarray, hi: np.ndarray, fov: float = Camera.fov,
                   aspect: float = FRAMING_ASPECT) -> Camera:
    """A camera in front of the box [lo, hi] (on +z, slightly above, looking at its centre) as close as it
    can be with all eight corners inside a `fov` x `aspect` picture: the box fills the picture's height or
    its width, whichever binds, not the circle around it (a bounding sphere leaves a wide picture's box
    at a third of its width)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
    back = np.array([0.0, FRAMING_TILT, 1.0]) / math.hypot(FRAMING_TILT, 1.0)   # from the centre to the eye
    right = np.array([1.0, 0.0, 0.0])
    up = np.cross(back, right)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]) - centre
    half_height = math.tan(math.radians(fov) / 2) / FRAMING_MARGIN
    half_width = half_height * max(float(aspect), 1e-3)
    # a corner at r is in the picture when |r.right| <= (d - r.back) tan(half width), and so for up
    needed = corners @ back + np.maximum(np.abs(corners @ right) / half_width, np.abs(corners @ up) / half_height)
    distance = max(float(needed.max()), 0.1 * radius)
    origin = centre + distance * back
    return Camera(tuple(origin), tuple(centre), (0.0, 1.0, 0.0), fov)


def home_camera(scene: Scene, source: str | Path, aspect: float = FRAMING_ASPECT) -> Camera:
    """The scene's own camera when its file comes with one (a sidecar .json, or a glTF camera: the sidecar's
    wins), else one that frames it in a picture `aspect` wide: what the viewer opens a scene with, and what
    a headless capture shows."""
    if scene.cameras:
        return scene.camera
    try:
        has_camera = "camera" in read_sidecar(scene_file(source))
    except ValueError:
        has_camera = False
    return scene.camera if has_camera else framing_camera(*scene.bounds, aspect=aspect)
