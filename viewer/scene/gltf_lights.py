"""KHR_lights_punctual -> the sun and small emitting spheres.

- The first directional light is the sun: `intensity` x `color` read as irradiance (W/m^2) on a surface
  facing it; it shines along its node's local -Z.
- A point light becomes a small closed sphere at its node's position (radius LAMP_RADIUS of the scene's
  size) that emits the same radiant intensity, so that every stage (the solver, the renderer's direct
  light, Mitsuba's reference) sees it as an ordinary area emitter. `intensity` x `color` is read as
  radiant intensity I (W/sr; glTF's candela, as the sun's lux are read as W/m^2). A Lambertian sphere
  of radius r and radiance L has the intensity L pi r^2 in every direction, so L = I / (pi r^2); the
  polyhedron stands for the sphere with L = 4 I / A (A its area: a convex body's mean projected area is
  A / 4, Cauchy), which is pi r^2 for the sphere itself. Its irradiance at distance d is then I / d^2,
  as a point light's, however small r is.
- A spot light is the same sphere: it shines in every direction, its cone is not modelled (said in one
  line). `range` is ignored, as the extension allows.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.scene.gltf_data import MALFORMED, integer, one_line, rgb
from viewer.scene.meshes import uv_sphere
from viewer.scene.types import DirectionalLight, SceneError, note

LAMP_RADIUS = 0.005
"""A point light's sphere: this fraction of the scene's size (the diagonal of its box), small beside
anything it lights and still crossed by the renderer's light samples."""
LAMP_SPHERE = uv_sphere(rings=16, segments=24)
"""The unit sphere a lamp is made of: 720 triangles, whose projected area in every direction is within
0.6% of the mean A / 4 (80 triangles, 6 x 8: 5%, measured as a 2.7% darker spot under the lamp)."""


@dataclass(frozen=True)
class Lamp:
    """A point or spot light as an emitting closed mesh."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    radiance: np.ndarray


def punctual_lights(path: Path, document: dict, placed: list, size: float) -> tuple[DirectionalLight | None, list[Lamp]]:
    """The sun and the lamps of the lights placed in the node tree: `placed` holds (light index, node's
    world matrix) in the tree's order; `size` is the scene's size, for the lamps' radius."""
    lights = ((document.get("extensions") or {}).get("KHR_lights_punctual") or {}).get("lights") or []
    sun, lamps, spots = None, [], 0
    try:
        for index, world in placed:
            light = lights[integer(index, f"{path}: KHR_lights_punctual light index")]
            kind = light.get("type")
            power = rgb(light.get("color", (1, 1, 1))) * float(light.get("intensity", 1))
            if kind == "directional":
                if sun is None:   # it shines along its node's local -Z; the sun's direction points back
                    sun = DirectionalLight(world[:3, :3] @ np.array([0.0, 0.0, 1.0]), power)
            elif kind in ("point", "spot"):
                spots += kind == "spot"
                lamps.append(_lamp(str(light.get("name") or f"light-{index}"), world[:3, 3], power, size))
            else:
                raise SceneError(f"light {index} has type {str(kind)[:20]!r}, not directional, point or spot")
    except SceneError as exc:  # e.g. a zero direction or a negative colour: say which file
        raise SceneError(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") from None
    except MALFORMED as exc:
        raise SceneError(f"{path}: malformed KHR_lights_punctual light ({one_line(exc)})") from None
    if spots:
        note(f"{path}: {spots} spot light(s) shine in every direction here: the viewer lights with their "
             f"intensity and leaves out their cone")
    return sun, lamps


def _lamp(name: str, position: np.ndarray, intensity: np.ndarray, size: float) -> Lamp:
    if np.any(intensity < 0) or not np.all(np.isfinite(position)):
        raise SceneError(f"light {name!r}: negative intensity or colour, or a position not finite")
    radius = LAMP_RADIUS * size
    vertices, faces = LAMP_SPHERE
    vertices = position + radius * vertices
    corners = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1).sum()
    return Lamp(name, vertices, faces, 4.0 * intensity / area)
