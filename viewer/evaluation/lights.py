"""The lights of a procedural room (viewer.evaluation.procedural): rectangular area lights on the ceiling,
the walls or the floor, objects that glow, and a window with the sun shining through it.

Power is counted in units of `CORNELL_POWER` (Mitsuba's Cornell box light) and colour by temperature
(`blackbody_rgb`), now and then tinted. The rooms' walls are handed in as frames (`frames.Frame`:
centre, inward normal, in-plane axes and half extents), so this module needs nothing else of the room.
"""

from __future__ import annotations

import colorsys
from typing import TYPE_CHECKING

import numpy as np

from viewer.scene import DirectionalLight
from viewer.neural.ranges import Ranges

if TYPE_CHECKING:
    from viewer.evaluation.frames import Frame

CORNELL_POWER = float(np.pi * (0.46 * 0.38) * np.mean((18.387, 13.9873, 6.75357)))
"""Emitted power (W) of Mitsuba's `cornell_box()` light: pi x area x mean radiance, about 7.2 W."""
WALL_GAP = 0.01
"""Distance of the lights in front of the surface they hang on (ceiling, wall or floor)."""


def blackbody_rgb(kelvin: float) -> np.ndarray:
    """Planck's law at 610, 550 and 465 nm, scaled to mean 1: a light's colour for its temperature
    (2700 K gives about (1.6, 0.9, 0.4), the warm white of Mitsuba's cornell light)."""
    wavelength = np.array([610e-9, 550e-9, 465e-9])
    h, c, k = 6.62607015e-34, 2.99792458e8, 1.380649e-23
    spectrum = 1.0 / (wavelength ** 5 * np.expm1(h * c / (wavelength * k * kelvin)))
    return spectrum / spectrum.mean()


def log_uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(np.exp(rng.uniform(np.log(bounds[0]), np.log(bounds[1]))))



def draw_window(rng: np.random.Generator, frames: dict[str, Frame], ranges: Ranges):
    """A hole in the ceiling, the back or a side wall, and a sun that shines through it onto a point of
    the floor, from behind the open front (so the window is the sun's only way in). None when no sun
    direction within the ranges reaches the floor through the hole."""
    wall = str(rng.choice(["ceiling", "back", "left-wall", "right-wall"]))
    f = frames[wall]
    margin = 0.1
    ha = min(rng.uniform(*ranges.window_half_extent), f.half_u - 2 * margin)
    hb = min(rng.uniform(*ranges.window_half_extent), f.half_v - 2 * margin)
    a = rng.uniform(-f.half_u + margin + ha, f.half_u - margin - ha)
    b_lo = -f.half_v + margin + hb if wall == "ceiling" else max(0.0, -f.half_v + margin + hb)
    b = rng.uniform(min(b_lo, f.half_v - margin - hb), f.half_v - margin - hb)
    centre = f.point(a, b)
    floor = frames["floor"]
    zenith_lo, zenith_hi = np.radians(ranges.sun_zenith_degrees)
    for _ in range(200):
        target = floor.point(rng.uniform(-0.9, 0.9) * floor.half_u, rng.uniform(-0.9, 0.9) * floor.half_v)
        direction = centre - target
        direction /= np.linalg.norm(direction)
        zenith = np.arccos(np.clip(-direction @ f.normal, -1, 1))
        if direction[2] <= 0 and direction[1] > 0.2 and zenith_lo <= zenith <= zenith_hi:
            break
    else:
        return None
    temperature = rng.uniform(*ranges.sun_temperature)
    power = CORNELL_POWER * log_uniform(rng, ranges.sun_power)
    area = 4 * ha * hb
    irradiance = blackbody_rgb(temperature) * power / (area * np.cos(zenith))
    params = {"wall": wall, "centre": centre.tolist(), "half": [ha, hb], "uv": [a, b],
              "sun": {"direction": direction.tolist(), "irradiance": irradiance.tolist(),
                      "temperature": temperature, "power": power / CORNELL_POWER,
                      "target": target.tolist()}}
    return (a, b, ha, hb), DirectionalLight(direction, irradiance), params


def draw_lights(rng: np.random.Generator, frames: dict[str, Frame], ranges: Ranges, window: dict | None):
    """Rectangles hanging WALL_GAP in front of the ceiling (facing down), the back or a side wall (facing
    in) or the floor (facing up), overlapping neither each other nor the window; and with
    `ranges.light_surfaces` naming "object", slots for objects that glow (filled by `glow_objects` once
    the objects stand). Returns (lights, object slots: [(share of the power, slot)], total power,
    the rectangles taken)."""
    count = int(rng.integers(ranges.lights[0], ranges.lights[1] + 1))
    power = CORNELL_POWER * log_uniform(rng, ranges.light_power)
    shares = rng.uniform(*ranges.light_share, count)
    shares /= shares.sum()
    lights, glowing, used = [], [], []  # used: (wall, a0, a1, b0, b1) rectangles already taken
    if window is not None:
        (wa, wb), (wha, whb) = window["uv"], window["half"]
        used.append((window["wall"], wa - wha - 0.05, wa + wha + 0.05, wb - whb - 0.05, wb + whb + 0.05))
    for k in range(count):
        if ranges.light_surfaces and str(rng.choice(ranges.light_surfaces)) == "object":
            glowing.append((float(shares[k]), k))
            continue
        light = rectangle_light(rng, frames, ranges, used, shares[k], power)
        if light is not None:
            lights.append(light)
    return lights, glowing, power, used


def light_surface(rng: np.random.Generator, ranges: Ranges) -> str:
    if ranges.light_surfaces:
        walls = [s for s in ranges.light_surfaces if s != "object"] or ["ceiling"]
        return str(rng.choice(walls))
    on_wall = rng.random() < ranges.wall_light_probability
    wall = str(rng.choice(["back", "left-wall", "right-wall"])) if on_wall else "ceiling"
    if ranges.floor_light_probability > 0 and rng.random() < ranges.floor_light_probability:
        wall = "floor"
    return wall


def rectangle_light(rng: np.random.Generator, frames: dict[str, Frame], ranges: Ranges, used: list,
                    share: float, power: float, wall: str | None = None):
    """One rectangular light of `share` x `power` watts on a free spot (rejection sampling; None when
    there is none), its (mesh, radiance, params)."""
    for _ in range(100):
        surface = wall or light_surface(rng, ranges)
        f = frames[surface]
        ha = min(rng.uniform(*ranges.light_half_extent), 0.95 * f.half_u - 0.05)
        hb = min(rng.uniform(*ranges.light_half_extent), 0.95 * f.half_v - 0.05)
        a = rng.uniform(-f.half_u + 0.05 + ha, f.half_u - 0.05 - ha)
        # wall lights stay in the upper half, above most objects (v1)
        up = ranges.wall_lights_up and surface not in ("ceiling", "floor")
        b_lo = min(0.0, f.half_v - 0.05 - hb) if up else -f.half_v + 0.05 + hb
        b = rng.uniform(b_lo, f.half_v - 0.05 - hb)
        box = (surface, a - ha, a + ha, b - hb, b + hb)
        if not any(u[0] == surface and box[1] < u[2] and u[1] < box[2] and box[3] < u[4] and u[3] < box[4]
                   for u in used):
            break
    else:
        return None
    used.append(box)
    colour, tinted = light_colour(rng, ranges)
    area = 4 * ha * hb
    radiance = colour * share * power / (np.pi * area)
    mesh = f.rectangle(a, b, ha, hb, lift=WALL_GAP)
    return mesh, radiance, {"wall": surface, "uv": [a, b], "half": [ha, hb], "radiance": radiance.tolist(),
                            "tinted": tinted, "power": share * power / CORNELL_POWER}


def light_colour(rng: np.random.Generator, ranges: Ranges) -> tuple[np.ndarray, bool]:
    """A colour temperature's RGB (mean 1), now and then tinted by a saturated colour (mean kept 1)."""
    colour = blackbody_rgb(rng.uniform(*ranges.colour_temperature))
    tinted = bool(rng.random() < ranges.light_tint_probability)
    if tinted:
        tint = np.asarray(colorsys.hsv_to_rgb(rng.random(), rng.uniform(0.3, 0.8), 1.0))
        colour = colour * tint / np.mean(colour * tint)
    return colour, tinted


def glow_objects(rng: np.random.Generator, objects: list, glowing: list, power: float,
                 ranges: Ranges) -> tuple[dict[str, tuple[np.ndarray, dict]], list]:
    """Each glowing slot (share of the power, slot) lights a different object all over (closed objects
    face out, so it emits into the room) with its share spread over the object's area. Returns
    ({object name: (radiance, params)}, the slots left without an object)."""
    free = list(range(len(objects)))
    out, left = {}, []
    for share, slot in glowing:
        if not free:
            left.append((share, slot))
            continue
        name, (vertices, faces), _, _ = objects[free.pop(int(rng.integers(len(free))))]
        triangles = vertices[faces]
        area = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0],
                                             triangles[:, 2] - triangles[:, 0]), axis=1).sum()
        colour, tinted = light_colour(rng, ranges)
        radiance = colour * share * power / (np.pi * area)
        out[name] = (radiance, {"wall": "object", "object": name, "radiance": radiance.tolist(),
                                "tinted": tinted, "power": share * power / CORNELL_POWER})
    return out, left


