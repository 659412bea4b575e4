"""Random Cornell-box layouts for the neural GI model's training data (numpy only).

`random_scene(rng, name, ranges)` draws one scene: a box room open at the front (z = +depth, as in
`cornell`), walls in whites and greys with now and then a saturated colour, up to a few objects on the
floor or stacked, one or two rectangular area lights, and sometimes a window with the sun shining
through it. Every number it draws comes from a field of `Ranges`, so an out-of-distribution study can
draw scenes outside the training ranges with `random_scene(rng, name, Ranges(room_scale=(1.3, 1.6)))`.

Conventions (DESIGN.md): y up; walls face into the room, closed objects outwards; an emitter is a
rectangle that emits from its counter-clockwise front face, into the room; every object is its own
group. The room is centred on the origin with half extents (hx, hy, hz) drawn per axis, so `cornell`
is the room (1, 1, 1).
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np

from viewer import meshes
from viewer.meshes import X_AXIS, Y_AXIS, Mesh, rotate, scale, transformed, translate
from viewer.scene import Camera, DirectionalLight, Scene

CORNELL_POWER = float(np.pi * (0.46 * 0.38) * np.mean((18.387, 13.9873, 6.75357)))
"""Emitted power (W) of Mitsuba's `cornell_box()` light: pi x area x mean radiance, about 7.2 W."""
WALL_GAP = 0.01
"""Distance of the lights in front of the surface they hang on (ceiling or wall)."""
OBJECT_GAP = 0.03
"""Smallest distance between an object and a wall, and between an object's top and the ceiling lights."""
LIGHT_ALBEDO = (0.8, 0.8, 0.8)
WALL_NAMES = ("floor", "ceiling", "back", "left-wall", "right-wall")
OBJECT_KINDS = ("box", "sphere", "cylinder", "cone", "wedge", "tilted-box")
DEFAULT_CAMERA_FOV = Camera().fov


@dataclass(frozen=True)
class Ranges:
    """Everything `random_scene` draws, as ranges (lo, hi) and probabilities."""

    room_scale: tuple[float, float] = (0.75, 1.3)
    """Half extent of the room along x, y and z (drawn independently; `cornell` is 1, 1, 1)."""
    albedo: tuple[float, float] = (0.05, 0.9)
    """Bounds of every albedo component, walls and objects alike."""
    grey_level: tuple[float, float] = (0.35, 0.9)
    """Brightness of a white or grey surface (before its slight tint)."""
    grey_tint: float = 0.06
    """Largest departure of a grey's channels from its brightness (warm / cool whites)."""
    saturated_wall_probability: float = 0.25
    """Chance that a wall (each of the five alone) gets a saturated colour instead of a white or grey."""
    saturated_object_probability: float = 0.6
    """Chance that an object gets a saturated colour instead of a white or grey."""
    saturation: tuple[float, float] = (0.5, 0.95)
    """HSV saturation of a saturated colour."""
    value: tuple[float, float] = (0.35, 0.9)
    """HSV value of a saturated colour."""
    objects: tuple[int, int] = (0, 4)
    """Fewest and most objects in a room (inclusive; fewer when they do not fit)."""
    object_kinds: tuple[str, ...] = OBJECT_KINDS
    """Shapes to draw from: box, sphere, cylinder, cone, wedge, tilted-box; and "slab", never trained on
    (an upright panel 0.02-0.04 thick)."""
    object_half_width: tuple[float, float] = (0.1, 0.4)
    """Horizontal half extent (or radius) of an object."""
    object_half_height: tuple[float, float] = (0.1, 0.6)
    """Vertical half extent of a box, cylinder, cone or wedge."""
    tilt_degrees: tuple[float, float] = (10.0, 35.0)
    """Tilt of a tilted box about a horizontal axis (it rests on an edge)."""
    stack_probability: float = 0.3
    """Chance that an object is put on top of an upright box or cylinder already in the room."""
    hang_probability: float = 0.0
    """Chance that an object floats just under the ceiling lights instead of standing on the floor
    (never in training: the out-of-distribution study's)."""
    placement_tries: int = 50
    """Rejection-sampling tries per object before it is left out (no object overlaps another)."""
    lights: tuple[int, int] = (1, 2)
    """Fewest and most area lights (inclusive)."""
    light_half_extent: tuple[float, float] = (0.05, 0.6)
    """Half extent of a rectangular light along each of its two axes."""
    light_power: tuple[float, float] = (0.3, 3.0)
    """Total power of the area lights, in units of `CORNELL_POWER` (drawn log-uniformly)."""
    wall_light_probability: float = 0.2
    """Chance that a light hangs on the back or a side wall (facing into the room) instead of under
    the ceiling (facing down)."""
    floor_light_probability: float = 0.0
    """Chance that a light lies on the floor facing up (never in training: the out-of-distribution
    study's; objects may stand on it)."""
    colour_temperature: tuple[float, float] = (2700.0, 9000.0)
    """Colour temperature (K) of a light: the Planck spectrum at 610, 550 and 465 nm."""
    light_tint_probability: float = 0.15
    """Chance that a light is tinted by a saturated colour on top of its temperature."""
    window_probability: float = 0.2
    """Chance that the room has a window (ceiling, back or a side wall) with the sun shining through."""
    window_half_extent: tuple[float, float] = (0.15, 0.4)
    """Half extent of the window along each of its two axes."""
    sun_power: tuple[float, float] = (0.3, 3.0)
    """Power of the sunlight through the window, in units of `CORNELL_POWER` (log-uniform)."""
    sun_temperature: tuple[float, float] = (4500.0, 7000.0)
    """Colour temperature (K) of the sun."""
    sun_zenith_degrees: tuple[float, float] = (0.0, 50.0)
    """Angle of the sun from the window's axis (ceiling: from straight up)."""


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


def wall_with_hole(frame: Frame, hole: tuple[float, float, float, float] | None) -> Mesh:
    """The whole wall, or four rectangles around the hole (a, b, half_a, half_b)."""
    if hole is None:
        return frame.rectangle(0.0, 0.0, frame.half_u, frame.half_v)
    a, b, ha, hb = hole
    a0, a1, b0, b1 = a - ha, a + ha, b - hb, b + hb
    U, V = frame.half_u, frame.half_v
    bottom = frame.rectangle(0.0, (-V + b0) / 2, U, (b0 + V) / 2)
    top = frame.rectangle(0.0, (b1 + V) / 2, U, (V - b1) / 2)
    left = frame.rectangle((-U + a0) / 2, b, (a0 + U) / 2, hb)
    right = frame.rectangle((a1 + U) / 2, b, (U - a1) / 2, hb)
    return meshes.merge([bottom, top, left, right])


# ---- colours -------------------------------------------------------------------------------------------

def random_colour(rng: np.random.Generator, ranges: Ranges, saturated_probability: float) -> np.ndarray:
    if rng.random() < saturated_probability:
        rgb = colorsys.hsv_to_rgb(rng.random(), rng.uniform(*ranges.saturation), rng.uniform(*ranges.value))
    else:
        rgb = rng.uniform(*ranges.grey_level) + rng.uniform(-ranges.grey_tint, ranges.grey_tint, 3)
    return np.clip(np.asarray(rgb, np.float64), *ranges.albedo)


def blackbody_rgb(kelvin: float) -> np.ndarray:
    """Planck's law at 610, 550 and 465 nm, scaled to mean 1: a light's colour for its temperature
    (2700 K gives about (1.6, 0.9, 0.4), the warm white of Mitsuba's cornell light)."""
    wavelength = np.array([610e-9, 550e-9, 465e-9])
    h, c, k = 6.62607015e-34, 2.99792458e8, 1.380649e-23
    spectrum = 1.0 / (wavelength ** 5 * np.expm1(h * c / (wavelength * k * kelvin)))
    return spectrum / spectrum.mean()


def log_uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    return float(np.exp(rng.uniform(np.log(bounds[0]), np.log(bounds[1]))))


# ---- objects -------------------------------------------------------------------------------------------

def object_mesh(rng: np.random.Generator, kind: str, ranges: Ranges, max_half_width: float) -> tuple[Mesh, dict]:
    """A closed shape standing on y = 0 centred on the y axis, turned about y; and what was drawn."""
    w_lo, w_hi = ranges.object_half_width
    w_hi = max(min(w_hi, max_half_width), w_lo * 0.5)

    def width():
        return rng.uniform(min(w_lo, w_hi), w_hi)

    height = rng.uniform(*ranges.object_half_height)
    yaw = rng.uniform(0.0, 360.0)
    params: dict = {"kind": kind, "yaw": yaw}
    if kind in ("box", "wedge", "tilted-box", "slab"):
        half = (width(), height, width() if kind != "slab" else rng.uniform(0.01, 0.02))
        shape = meshes.cube() if kind != "wedge" else meshes.wedge()
        local = scale(*half)
        params["half"] = list(half)
        if kind == "box":
            params["top"] = min(half[0], half[2])
        if kind == "tilted-box":
            tilt = rng.uniform(*ranges.tilt_degrees) * rng.choice([-1.0, 1.0])
            local = rotate(X_AXIS, tilt) @ local
            params["tilt"] = tilt
    elif kind == "sphere":
        radius = width()
        shape, local = meshes.uv_sphere(), scale(radius)
        params["radius"] = radius
    elif kind in ("cylinder", "cone"):
        radius = width()
        shape = meshes.cylinder() if kind == "cylinder" else meshes.cone()
        local = scale(radius, height, radius)
        params.update(radius=radius, half_height=height)
        if kind == "cylinder":
            params["top"] = radius
    else:
        raise ValueError(f"unknown object kind {kind!r} (have {', '.join(OBJECT_KINDS)}, slab)")
    vertices, faces = transformed(shape, rotate(Y_AXIS, yaw) @ local)
    vertices = vertices - (0.0, vertices[:, 1].min(), 0.0)  # rest on y = 0 (a tilted box on its edge)
    return (vertices, faces), params


def place_objects(rng: np.random.Generator, half: np.ndarray, ranges: Ranges,
                  ceiling_clearance: float) -> list[tuple[str, Mesh, np.ndarray, dict]]:
    """Rejection sampling: each object on the floor, or on top of an upright box, inside the room
    with OBJECT_GAP to the walls, below the lights, overlapping no other object."""
    count = int(rng.integers(ranges.objects[0], ranges.objects[1] + 1))
    top_limit = half[1] - ceiling_clearance - OBJECT_GAP
    placed: list[tuple[str, Mesh, np.ndarray, dict]] = []
    for k in range(count):
        kind = str(rng.choice(ranges.object_kinds))
        colour = random_colour(rng, ranges, ranges.saturated_object_probability)
        supports = [p for p in placed if "top" in p[3] and not p[3].get("stacked")]
        stack = bool(supports) and rng.random() < ranges.stack_probability
        for _ in range(ranges.placement_tries):
            if stack:
                support = supports[int(rng.integers(len(supports)))]
                top = support[3]["top"]  # the flat top reaches at least this far from the axis
                (vertices, faces), params = object_mesh(rng, kind, ranges, 0.6 * top)
                sx, sz = support[3]["position"][0], support[3]["position"][2]
                x, z = sx + rng.uniform(-0.3 * top, 0.3 * top), sz + rng.uniform(-0.3 * top, 0.3 * top)
                base = float(support[1][0][:, 1].max())
                params["stacked"] = support[0]
            else:
                (vertices, faces), params = object_mesh(rng, kind, ranges, np.inf)
                lo, hi = vertices.min(axis=0), vertices.max(axis=0)
                x_range = (-half[0] + OBJECT_GAP - lo[0], half[0] - OBJECT_GAP - hi[0])
                z_range = (-half[2] + OBJECT_GAP - lo[2], half[2] - OBJECT_GAP - hi[2])
                if x_range[0] > x_range[1] or z_range[0] > z_range[1]:
                    continue
                x, z, base = rng.uniform(*x_range), rng.uniform(*z_range), -float(half[1])
                if ranges.hang_probability > 0 and rng.random() < ranges.hang_probability:
                    base, params["hanging"] = top_limit - float(vertices[:, 1].max()), True
            moved = vertices + (x, base, z)
            if not inside_room(moved, half, top_limit):
                continue
            if any(meshes.overlap(moved, other[1][0]) for other in placed):
                continue
            params["position"] = [x, base, z]
            params["albedo"] = colour.tolist()
            name = f"{kind}-{k + 1}"
            placed.append((name, (moved, faces), colour, params))
            break
    return placed


def inside_room(vertices: np.ndarray, half: np.ndarray, top_limit: float) -> bool:
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return bool(np.all(np.abs(vertices[:, [0, 2]]) <= half[[0, 2]] - OBJECT_GAP + 1e-9)
                and lo[1] >= -half[1] - 1e-9 and hi[1] <= top_limit)


# ---- lights and the window -----------------------------------------------------------------------------

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
    """One or two rectangles hanging WALL_GAP in front of the ceiling (facing down) or of the back or a
    side wall (facing in), overlapping neither each other nor the window."""
    count = int(rng.integers(ranges.lights[0], ranges.lights[1] + 1))
    power = CORNELL_POWER * log_uniform(rng, ranges.light_power)
    shares = rng.uniform(0.3, 1.0, count)
    shares /= shares.sum()
    lights, used = [], []  # used: (wall, a0, a1, b0, b1) rectangles already taken
    if window is not None:
        (wa, wb), (wha, whb) = window["uv"], window["half"]
        used.append((window["wall"], wa - wha - 0.05, wa + wha + 0.05, wb - whb - 0.05, wb + whb + 0.05))
    for k in range(count):
        for _ in range(100):
            on_wall = rng.random() < ranges.wall_light_probability
            wall = str(rng.choice(["back", "left-wall", "right-wall"])) if on_wall else "ceiling"
            if ranges.floor_light_probability > 0 and rng.random() < ranges.floor_light_probability:
                wall = "floor"
            f = frames[wall]
            ha = min(rng.uniform(*ranges.light_half_extent), 0.95 * f.half_u - 0.05)
            hb = min(rng.uniform(*ranges.light_half_extent), 0.95 * f.half_v - 0.05)
            a = rng.uniform(-f.half_u + 0.05 + ha, f.half_u - 0.05 - ha)
            # wall lights stay in the upper half, above most objects
            b_lo = -f.half_v + 0.05 + hb if wall in ("ceiling", "floor") else min(0.0, f.half_v - 0.05 - hb)
            b = rng.uniform(b_lo, f.half_v - 0.05 - hb)
            box = (wall, a - ha, a + ha, b - hb, b + hb)
            if not any(u[0] == wall and box[1] < u[2] and u[1] < box[2] and box[3] < u[4] and u[3] < box[4]
                       for u in used):
                break
        else:
            continue
        used.append(box)
        colour = blackbody_rgb(rng.uniform(*ranges.colour_temperature))
        tinted = rng.random() < ranges.light_tint_probability
        if tinted:
            tint = np.asarray(colorsys.hsv_to_rgb(rng.random(), rng.uniform(0.3, 0.8), 1.0))
            colour = colour * tint / np.mean(colour * tint)
        area = 4 * ha * hb
        radiance = colour * shares[k] * power / (np.pi * area)
        mesh = f.rectangle(a, b, ha, hb, lift=WALL_GAP)
        lights.append((mesh, radiance, {"wall": wall, "uv": [a, b], "half": [ha, hb],
                                        "radiance": radiance.tolist(), "tinted": tinted,
                                        "power": shares[k] * power / CORNELL_POWER}))
    return lights


# ---- the scene -----------------------------------------------------------------------------------------

def random_scene(rng: np.random.Generator, name: str, ranges: Ranges = Ranges()) -> tuple[Scene, dict]:
    """One random room and the JSON-able parameters it was built from."""
    half = rng.uniform(*ranges.room_scale, 3)
    frames = room_frames(half)
    colours = {wall: random_colour(rng, ranges, ranges.saturated_wall_probability) for wall in WALL_NAMES}
    window = None
    sun = None
    if rng.random() < ranges.window_probability:
        drawn = draw_window(rng, frames, ranges)
        if drawn is not None:
            hole, sun, window = drawn
    lights = draw_lights(rng, frames, ranges, window)
    ceiling_clearance = WALL_GAP + OBJECT_GAP
    parts: list[tuple[str, Mesh, np.ndarray, np.ndarray]] = []
    for wall in WALL_NAMES:
        mesh = wall_with_hole(frames[wall], hole if window and window["wall"] == wall else None)
        parts.append((wall, mesh, colours[wall], np.zeros(3)))
    objects = place_objects(rng, half, ranges, ceiling_clearance)
    parts += [(n, mesh, colour, np.zeros(3)) for n, mesh, colour, _ in objects]
    for k, (mesh, radiance, _) in enumerate(lights):
        parts.append(("light" if k == 0 else f"light-{k + 1}", mesh, np.array(LIGHT_ALBEDO), radiance))
    distance = 2.9 * max(half[0], half[1])
    camera = Camera((0.0, 0.0, float(half[2] + distance)), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), DEFAULT_CAMERA_FOV)
    scene = assemble(name, parts, sun, camera)
    params = {
        "room_half": half.tolist(),
        "walls": {wall: colours[wall].tolist() for wall in WALL_NAMES},
        "objects": [p for _, _, _, p in objects],
        "lights": [p for _, _, p in lights],
        "window": window,
        "camera": {"origin": list(camera.origin), "target": list(camera.target), "up": list(camera.up),
                   "fov": camera.fov},
    }
    return scene, params


def assemble(name: str, parts, sun: DirectionalLight | None, camera: Camera) -> Scene:
    """A Scene from (group name, mesh, albedo, radiance) parts, one group each, each with its own
    vertices."""
    offsets = np.cumsum([0] + [len(mesh[0]) for _, mesh, _, _ in parts[:-1]])
    counts = [len(mesh[1]) for _, mesh, _, _ in parts]
    return Scene(
        name=name,
        vertices=np.vstack([mesh[0] for _, mesh, _, _ in parts]),
        faces=np.vstack([mesh[1] + o for (_, mesh, _, _), o in zip(parts, offsets)]),
        albedo=np.repeat(np.array([a for _, _, a, _ in parts], np.float64), counts, axis=0),
        emission=np.repeat(np.array([e for _, _, _, e in parts], np.float64), counts, axis=0),
        face_group=np.repeat(np.arange(len(parts)), counts),
        groups=tuple(n for n, _, _, _ in parts),
        sun=sun, camera=camera)
