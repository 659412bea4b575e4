"""Mouse and keyboard -> a Camera: orbit around a target, pan, zoom, and a first-person fly mode.

The state is a target point, a distance and two angles (yaw around +y, pitch above the horizon), so
orbiting never drifts and the up vector stays +y (the scene convention). Fly mode (right button held,
WASD / QE to move) turns the view around the eye instead and carries the target along, so leaving fly
mode orbits around whatever is in front of the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from viewer.scene import Camera

MAX_PITCH = math.radians(89.0)


@dataclass
class ControllerSettings:
    orbit_speed: float = 0.006
    """Radians of yaw / pitch per pixel dragged."""
    zoom_step: float = 0.88
    """Distance factor per wheel notch (towards the target)."""
    fly_speed: float = 0.6
    """Scene sizes per second in fly mode (x4 with shift)."""


class OrbitCamera:
    def __init__(self, camera: Camera, scene_size: float, settings: ControllerSettings | None = None):
        self.settings = settings or ControllerSettings()
        self.scene_size = max(float(scene_size), 1e-6)
        self.home = camera
        self.reset()

    # ---- state ------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the camera the controller was made with (the scene's camera)."""
        camera = self.home
        self.target = np.asarray(camera.target, np.float64).copy()
        offset = np.asarray(camera.origin, np.float64) - self.target
        self.distance = max(float(np.linalg.norm(offset)), 1e-3 * self.scene_size)
        offset = offset / self.distance
        self.yaw = math.atan2(offset[0], offset[2])
        self.pitch = max(-MAX_PITCH, min(MAX_PITCH, math.asin(max(-1.0, min(1.0, offset[1])))))
        self.fov = float(camera.fov)

    @property
    def _offset_direction(self) -> np.ndarray:
        """Unit vector from the target towards the eye."""
        cp = math.cos(self.pitch)
        return np.array([cp * math.sin(self.yaw), math.sin(self.pitch), cp * math.cos(self.yaw)])

    @property
    def eye(self) -> np.ndarray:
        return self.target + self.distance * self._offset_direction

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(right, up, forward) unit vectors of the view."""
        forward = -self._offset_direction
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= max(np.linalg.norm(right), 1e-12)
        return right, np.cross(right, forward), forward

    def camera(self) -> Camera:
        return Camera(tuple(float(v) for v in self.eye), tuple(float(v) for v in self.target),
                      (0.0, 1.0, 0.0), self.fov)

    def key(self) -> tuple:
        """Changes whenever the view changes (for redraw-on-change)."""
        return (*np.round(self.target, 9), round(self.distance, 9), round(self.yaw, 9), round(self.pitch, 9),
                self.fov)

    # ---- gestures ---------------------------------------------------------------------------------------
    def orbit(self, dx: float, dy: float) -> None:
        """Turn around the target: dragging right swings the camera to the left, so the scene turns with
        the mouse."""
        self.yaw -= dx * self.settings.orbit_speed
        self.pitch = max(-MAX_PITCH, min(MAX_PITCH, self.pitch + dy * self.settings.orbit_speed))

    def pan(self, dx: float, dy: float, viewport_height: int) -> None:
        """Slide target and eye in the view plane so the point under the mouse follows it."""
        world_per_pixel = 2.0 * self.distance * math.tan(math.radians(self.fov) / 2) / max(viewport_height, 1)
        right, up, _ = self.basis()
        self.target = self.target - right * dx * world_per_pixel + up * dy * world_per_pixel

    def zoom(self, notches: float) -> None:
        self.distance = max(self.distance * self.settings.zoom_step ** notches, 1e-3 * self.scene_size)

    def look(self, dx: float, dy: float) -> None:
        """First-person turn: the eye stays, the target swings around it."""
        eye = self.eye
        self.yaw -= dx * self.settings.orbit_speed
        self.pitch = max(-MAX_PITCH, min(MAX_PITCH, self.pitch + dy * self.settings.orbit_speed))
        self.target = eye - self.distance * self._offset_direction

    def fly(self, forward: float, right: float, up: float, seconds: float, fast: bool = False) -> None:
        """Move eye and target together; the arguments are -1, 0 or 1 per axis."""
        step = self.settings.fly_speed * self.scene_size * seconds * (4.0 if fast else 1.0)
        r, _, f = self.basis()
        self.target = self.target + step * (forward * f + right * r + up * np.array([0.0, 1.0, 0.0]))
