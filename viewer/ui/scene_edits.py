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
from viewer.scene.geometry import group_vertices
from viewer.scene.gltf_lights import shade_group


def emitter_group(scene: Scene) -> str | None:
    """The group that emits the most power (area x mean radiance), or None."""
    power = np.bincount(scene.face_group, scene.face_areas * scene.emission.mean(axis=1),
                        minlength=len(scene.groups))
    return scene.groups[int(np.argmax(power))] if power.max(initial=0.0) > 0 else None


def largest_object(scene: Scene, exclude: tuple = ()) -> str | None:
    """The group of the most triangles that does not emit (the smaller by area of a tie: a box room's
    small box, a scan room's scan): what a user moves first. None where every group emits."""
    lit = set(np.unique(scene.face_group[np.any(scene.emission > 0, axis=1)]).tolist())
    count = np.bincount(scene.face_group, minlength=len(scene.groups))
    area = np.bincount(scene.face_group, scene.face_areas, minlength=len(scene.groups))
    candidates = [g for g in range(len(scene.groups))
                  if g not in lit and count[g] > 0 and scene.groups[g] not in exclude]
    if not candidates:
        return None
    return scene.groups[min(candidates, key=lambda g: (-count[g], area[g]))]


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
        self.offsets: dict[str, np.ndarray] = {}
        """Group -> world translation of a moved object."""
        self.light = self._initial_light(base)
        self.initial_intensity = self.light.intensity
        self.selected = largest_object(base, self._light_groups())
        """The object the panel moves (a material group)."""
        self._centres: dict[str, np.ndarray] = {}

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

    def _light_groups(self) -> tuple:
        return self.light.group, shade_group(str(self.light.group))

    @property
    def material_groups(self) -> list[str]:
        """Groups whose colour can be edited and that can be moved (all but the light)."""
        return [g for g in self.base.groups if g not in self._light_groups()]

    def albedo_of(self, group: str) -> np.ndarray:
        return self.albedo.get(group, self.base.group_albedo(group))

    def centre_of(self, group: str) -> np.ndarray:
        """Centre of the box around the group's vertices in the base scene (where the panel shows it)."""
        if group not in self._centres:
            corners = self.base.vertices[group_vertices(self.base.faces, self.base.face_group,
                                                        self.base.group_index(group), len(self.base.vertices))]
            self._centres[group] = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
        return self._centres[group]

    def offset_of(self, group: str) -> np.ndarray:
        return self.offsets.get(group, np.zeros(3))

    # ---- changes --------------------------------------------------------------------------------------
    def set_albedo(self, group: str, rgb) -> None:
        self.albedo[group] = np.clip(np.asarray(rgb, np.float64), 0.0, 1.0)
        self.version += 1

    def set_offset(self, group: str, offset) -> None:
        """Move a material group to its place in the base scene plus `offset` (an object dragged)."""
        if group not in self.material_groups:
            raise ValueError(f"{group!r} is not a group that can be moved")
        offset = np.asarray(offset, np.float64)
        if not np.all(np.isfinite(offset)):
            raise ValueError("an object's offset must be finite")
        self.offsets[group] = offset
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
        self.offsets.clear()
        self.light = self._initial_light(self.base)
        self.version += 1

    # ---- result ---------------------------------------------------------------------------------------
    def apply(self) -> Scene:
        scene = self.base
        for group, rgb in self.albedo.items():
            scene = scene.with_albedo(group, rgb)
        for group, offset in self.offsets.items():
            if np.any(offset != 0.0):   # else keep the vertices bit for bit
                matrix = np.eye(4)
                matrix[:3, 3] = offset
                scene = scene.transformed_group(group, matrix)
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
