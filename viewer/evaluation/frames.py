"""A wall of a procedural room as a frame: centre, inward normal, in-plane axes and half extents.

Apart from viewer/evaluation/procedural.py, which builds the rooms, because the lights
(viewer/evaluation/lights.py) are placed on the same frames and the rooms place the lights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viewer.scene import meshes
from viewer.scene.meshes import Mesh, transformed


# ---- a wall as a frame: centre, inward normal n, in-plane axes u and v = n x u -------------------------

@dataclass(frozen=True)
class Frame:
    centre: np.ndarray
    normal: np.ndarray
    """Unit normal into the room: the front of the rectangles built on this frame."""
    u: np.ndarray
    half_u: float
    half_v: float

    @property
    def v(self) -> np.ndarray:
        return np.cross(self.normal, self.u)

    def point(self, a: float, b: float, lift: float = 0.0) -> np.ndarray:
        return self.centre + a * self.u + b * self.v + lift * self.normal

    def rectangle(self, a: float, b: float, half_a: float, half_b: float, lift: float = 0.0) -> Mesh:
        """The rectangle [a +- half_a] x [b +- half_b] in (u, v), `lift` in front of the wall, front face
        along the normal (rectangle()'s +z is cross(x, y), mapped to cross(u, v) = n)."""
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2] = half_a * self.u, half_b * self.v, self.normal
        m[:3, 3] = self.point(a, b, lift)
        return transformed(meshes.rectangle(), m)


def room_frames(half: np.ndarray) -> dict[str, Frame]:
    hx, hy, hz = (float(h) for h in half)
    x, y, z = np.eye(3)
    return {
        "floor": Frame(np.array([0, -hy, 0.0]), y, x, hx, hz),
        "ceiling": Frame(np.array([0, hy, 0.0]), -y, x, hx, hz),
        "back": Frame(np.array([0, 0, -hz]), z, x, hx, hy),
        "left-wall": Frame(np.array([-hx, 0, 0.0]), x, z, hz, hy),
        "right-wall": Frame(np.array([hx, 0, 0.0]), -x, z, hz, hy),
    }
