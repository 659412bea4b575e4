"""KHR_lights_punctual -> the sun, small emitting spheres, and black shades around the spots' spheres.

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
- A spot light is the same sphere inside a lamp shade: a black (albedo 0, not emitting), closed-backed can
  of thin triangles whose round opening faces the spot's direction (its node's local -Z). The cone is
  real geometry rather than a rule of one stage, so the solver, the renderer's shadows and Mitsuba all
  cut it alike, and its light still bounces everywhere it lands. A direction that sees the whole sphere
  through the opening gets the full intensity I, one that sees only the shade none, and in between the
  rim hides part of the sphere: a soft edge. Seen from far off along a direction theta off the axis,
  the rim hides none of the sphere (radius r) up to m - delta and all of it from m + delta on, where m is
  the opening's half-angle seen from the sphere's centre and sin(delta) = r / D for a rim at distance D
  from the centre (the line of sight that grazes the rim and touches the sphere). The shade is sized so
  that this penumbra spans the spot's innerConeAngle..outerConeAngle (m their mean, delta half their
  difference): full light inside the inner cone and none beyond the outer one, as the extension asks,
  with the sphere sliding behind the rim for the smooth falloff between. A sharp edge needs a large
  shade (D = r / sin(delta)), so the penumbra is at least 2 asin(1 / SHADE_REACH) = 11.5 degrees wide,
  its outer edge kept at outerConeAngle; a cone narrower than that is penumbra throughout, its shade
  longer. Behind the sphere the shade reaches SHADE_WALL radii (1.5% of the scene's size): a
  surface closer than that behind a spot cuts into the shade, and the part inside is lit. The angles
  default to 0 and pi/4 and are clamped to 0 <= inner < outer <= pi/2; a value that is not a finite
  number is refused.
- `range` is ignored, as the extension allows.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.scene.gltf_data import MALFORMED, integer, one_line, rgb
from viewer.scene.meshes import uv_sphere
from viewer.scene.types import DirectionalLight, SceneError

LAMP_RADIUS = 0.005
"""A point light's sphere: this fraction of the scene's size (the diagonal of its box), small beside
anything it lights and still crossed by the renderer's light samples."""
LAMP_SPHERE = uv_sphere(rings=16, segments=24)
"""The unit sphere a lamp is made of: 720 triangles, whose projected area in every direction is within
0.6% of the mean A / 4 (80 triangles, 6 x 8: 5%, measured as a 2.7% darker spot under the lamp)."""
SHADE_REACH = 10.0
"""The farthest a spot's rim lies from its sphere's centre, in sphere radii: the shade stays small beside
the scene (5% of its size), and its penumbra is at least 2 asin(1 / SHADE_REACH) = 11.5 degrees wide."""
SHADE_WALL = 3.0
"""The shade's wall and back stand this many sphere radii from the centre (farther where the opening is
wider): clear of the points just off the sphere that the solver traces its lamp rays to (a tenth of a
voxel off it: 1.25 radii at 16 voxels along the scene's diagonal)."""
SHADE_SEGMENTS = 24
"""Sides of the shade's round opening and wall, as the sphere's."""



def shade_group(lamp: str) -> str:
    """The group name of the shade around the spot light whose sphere is group `lamp`."""
    return f"{lamp} shade"

@dataclass(frozen=True)
class Lamp:
    """A point or spot light as an emitting closed mesh."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    radiance: np.ndarray
    shade: tuple[np.ndarray, np.ndarray] | None = None
    """A spot's black shade around the sphere (vertices, faces facing out), or None for a point light."""


def punctual_lights(path: Path, document: dict, placed: list, size: float) -> tuple[DirectionalLight | None, list[Lamp]]:
    """The sun and the lamps of the lights placed in the node tree: `placed` holds (light index, node's
    world matrix) in the tree's order; `size` is the scene's size, for the lamps' radius."""
    lights = ((document.get("extensions") or {}).get("KHR_lights_punctual") or {}).get("lights") or []
    sun, lamps = None, []
    try:
        for index, world in placed:
            light = lights[integer(index, f"{path}: KHR_lights_punctual light index")]
            kind = light.get("type")
            power = rgb(light.get("color", (1, 1, 1))) * float(light.get("intensity", 1))
            if kind == "directional":
                if sun is None:   # it shines along its node's local -Z; the sun's direction points back
                    sun = DirectionalLight(world[:3, :3] @ np.array([0.0, 0.0, 1.0]), power)
            elif kind in ("point", "spot"):
                name = str(light.get("name") or f"light-{index}")
                lamp = _lamp(name, world[:3, 3], power, size)
                if kind == "spot":   # it shines along its node's local -Z
                    lamp = _shaded(lamp, world[:3, :3] @ np.array([0.0, 0.0, -1.0]), light.get("spot") or {})
                lamps.append(lamp)
            else:
                raise SceneError(f"light {index} has type {str(kind)[:20]!r}, not directional, point or spot")
    except SceneError as exc:  # e.g. a zero direction or a negative colour: say which file
        raise SceneError(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") from None
    except MALFORMED as exc:
        raise SceneError(f"{path}: malformed KHR_lights_punctual light ({one_line(exc)})") from None
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


def cone_angles(spot: dict) -> tuple[float, float]:
    """(inner, outer) cone half-angles of a spot's `spot` object: 0 and pi/4 by default, clamped to
    0 <= inner < outer <= pi/2; SceneError for a value that is not a finite number."""
    outer, inner = (spot.get(key, default) for key, default in (("outerConeAngle", np.pi / 4),
                                                               ("innerConeAngle", 0.0)))
    if not all(isinstance(a, (int, float)) and not isinstance(a, bool) and np.isfinite(a) for a in (inner, outer)):
        raise SceneError(f"spot cone angles must be finite numbers, got {str(inner)[:20]}, {str(outer)[:20]}")
    outer = float(np.clip(outer, 1e-3, np.pi / 2))
    return float(np.clip(inner, 0.0, 0.999 * outer)), outer


def _shaded(lamp: Lamp, direction: np.ndarray, spot: dict) -> Lamp:
    """The lamp with a shade whose penumbra spans the spot's cone (see the module's docstring)."""
    length = np.linalg.norm(direction)
    if not (np.isfinite(length) and length > 1e-9):
        raise SceneError(f"light {lamp.name!r}: the spot's node turns its direction to zero")
    inner, outer = cone_angles(spot)
    # Half the penumbra (delta) and the opening's half-angle (m): m - delta = inner, m + delta = outer; the
    # rim lies r / sin(delta) from the centre, so a sharper edge than SHADE_REACH allows is widened inwards.
    delta = max(0.5 * (outer - inner), np.arcsin(1.0 / SHADE_REACH))
    delta = min(delta, 0.5 * outer)   # a cone narrower than twice that: penumbra throughout, a larger shade
    middle = outer - delta
    centre = lamp.vertices.mean(axis=0)
    radius = float(np.linalg.norm(lamp.vertices[0] - centre))
    rim = radius / np.sin(delta)
    return Lamp(lamp.name, lamp.vertices, lamp.faces, lamp.radiance,
                shade(centre, direction / length, radius, rim * np.cos(middle), rim * np.sin(middle)))


def shade(centre: np.ndarray, axis: np.ndarray, radius: float, reach: float, opening: float):
    """(vertices, faces) of a closed-backed can around a sphere of `radius` at `centre`: a round opening of
    radius `opening` at `reach` along the unit `axis`, a wall that widens behind it to SHADE_WALL radii
    (or stays as wide as the opening), and a flat back that far behind the centre; faces point out."""
    wall = max(opening, SHADE_WALL * radius)
    back = SHADE_WALL * radius
    profile = [(reach, opening), (0.0, wall), (-back, wall)]   # (along the axis, from it), the rim first
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    phi = 2 * np.pi * np.arange(SHADE_SEGMENTS) / SHADE_SEGMENTS
    around = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v
    rings = [centre + t * axis + s * around for t, s in profile]
    vertices = np.vstack(rings + [(centre - back * axis)[None]])
    n, tip = SHADE_SEGMENTS, len(vertices) - 1
    faces = []
    for k in range(n):
        j = (k + 1) % n
        for ring in range(len(profile) - 1):
            a, b = ring * n, (ring + 1) * n
            faces += [[a + k, b + k, b + j], [a + k, b + j, a + j]]
        faces.append([(len(profile) - 1) * n + k, tip, (len(profile) - 1) * n + j])
    faces = np.array(faces)
    corners = vertices[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    inward = np.einsum("ij,ij->i", normal, corners.mean(axis=1) - centre) < 0
    faces[inward] = faces[inward][:, ::-1]
    return vertices, faces
