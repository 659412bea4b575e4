"""The edits a user makes in the panel, applied to the loaded scene to give the scene that is shown.

Edits are kept as values relative to the loaded ("base") scene and re-applied from it each time, so
that dragging a slider back and forth never accumulates rounding, and a reset is just clearing them.
The light is the scene's brightest emitter group (its vertices move and scale about their centre, its
emission is colour x intensity); a scene lit only by a sun edits the sun's direction instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from viewer.scene import DirectionalLight, Scene
from viewer.scene.gltf_lights import shade_group


def emitter_group(scene: Scene) -> str | None:
    """The group that emits the most power (area x mean radiance), or None."""
    power = np.bincount(scene.face_group, scene.face_areas * scene.emission.mean(axis=1),
                        minlength=len(scene.groups))
    return scene.groups[int(np.argmax(power))] if power.max(initial=0.0) > 0 else None


def _split_colour(rgb: np.ndarray) -> tuple[np.ndarray, float]:
    """Radiance -> (colour with its largest component 1, intensity)."""
    rgb = np.asarray(rgb, np.float64)
    peak = float(rgb.max())
    return (rgb / peak if peak > 0 else np.ones(3)), peak


@dataclass
class LightEdit:
    group: str | None
    """The emitter group edited (None: the sun, or nothing to edit)."""
    centre: np.ndarray
    """Centre of the group's vertices in the base scene (what `size` scales about)."""
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """World translation of the emitter."""
    size: float = 1.0
    """Scale factor of the emitter about its centre."""
    colour: np.ndarray = field(default_factory=lambda: np.ones(3))
    """Emitted colour with its largest component 1."""
    intensity: float = 0.0
    """Largest RGB component of the emitted radiance (or of the sun's irradiance)."""
    direction: np.ndarray | None = None
    """For a sun: unit vector towards it."""


class SceneEdits:
    def __init__(self, base: Scene):
        self.base = base
        self.version = 0
        self.albedo: dict[str, np.ndarray] = {}
        self.light = self._initial_light(base)
        self.initial_intensity = self.light.intensity

    @staticmethod
    def _initial_light(scene: Scene) -> LightEdit:
        group = emitter_group(scene)
        if group is not None:
            mask = scene.face_group == scene.group_index(group)
            corners = scene.vertices[np.unique(scene.faces[mask])]
            radiance = np.average(scene.emission[mask], axis=0, weights=scene.face_areas[mask] + 1e-30)
            colour, intensity = _split_colour(radiance)
            return LightEdit(group, corners.mean(axis=0), colour=colour, intensity=intensity)
        lo, hi = scene.bounds
        if scene.sun is not None:
            colour, intensity = _split_colour(scene.sun.irradiance)
            return LightEdit(None, 0.5 * (lo + hi), colour=colour, intensity=intensity,
                             direction=scene.sun.direction.copy())
        return LightEdit(None, 0.5 * (lo + hi))

    @property
    def material_groups(self) -> list[str]:
        """Groups whose colour can be edited (all but the light)."""
        return [g for g in self.base.groups if g not in (self.light.group, shade_group(str(self.light.group)))]

    def albedo_of(self, group: str) -> np.ndarray:
        return self.albedo.get(group, self.base.group_albedo(group))

    # ---- changes --------------------------------------------------------------------------------------
    def set_albedo(self, group: str, rgb) -> None:
        self.albedo[group] = np.clip(np.asarray(rgb, np.float64), 0.0, 1.0)
        self.version += 1

    def set_light(self, offset=None, size=None, colour=None, intensity=None, direction=None) -> None:
        light = self.light
        if offset is not None:
            light.offset = np.asarray(offset, np.float64)
        if size is not None:
            light.size = max(float(size), 1e-3)
        if colour is not None:
            light.colour = np.clip(np.asarray(colour, np.float64), 0.0, 1.0)
        if intensity is not None:
            light.intensity = max(float(intensity), 0.0)
        if direction is not None and np.linalg.norm(direction) > 1e-9:
            light.direction = np.asarray(direction, np.float64) / np.linalg.norm(direction)
        self.version += 1

    def reset(self) -> None:
        self.albedo.clear()
        self.light = self._initial_light(self.base)
        self.version += 1

    # ---- result ---------------------------------------------------------------------------------------
    def apply(self) -> Scene:
        scene = self.base
        for group, rgb in self.albedo.items():
            scene = scene.with_albedo(group, rgb)
        light = self.light
        if light.group is not None:
            if light.size != 1.0 or np.any(light.offset != 0.0):   # else keep the vertices bit for bit
                c = light.centre
                matrix = np.eye(4)
                matrix[:3, :3] *= light.size
                matrix[:3, 3] = c + light.offset - light.size * c   # scale about the centre, then move
                scene = scene.transformed_group(light.group, matrix)
                if shade_group(light.group) in scene.groups:   # a spot's shade moves with its sphere
                    scene = scene.transformed_group(shade_group(light.group), matrix)
            scene = scene.with_emission(light.group, light.colour * light.intensity)
        elif light.direction is not None:
            scene = scene.with_sun(DirectionalLight(light.direction, light.colour * light.intensity))
        return scene
