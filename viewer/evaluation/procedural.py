"""Random Cornell-box layouts for the neural GI model's training data (numpy only).

`random_scene(rng, name, ranges)` draws one scene: a box room open at the front (z = +depth, as in
`cornell`), walls in whites and greys with now and then a saturated colour, up to a few objects on the
floor or stacked, area lights (viewer.evaluation.lights), and sometimes a window with the sun shining
through it; with the wide ranges also thin partitions and glowing objects. Every number it draws comes
from a field of `Ranges` (viewer.neural.ranges: `Ranges()` is the first dataset's, `PRESETS["v2"]`
the v2 ranges), so an out-of-distribution study can draw scenes outside the training ranges with
`random_scene(rng, name, Ranges(room_scale=(1.3, 1.6)))`.

Conventions (docs/ARCHITECTURE.md): y up; walls face into the room, closed objects outwards; an emitter is a
rectangle that emits from its counter-clockwise front face, into the room; every object is its own
group. The room is centred on the origin with half extents (hx, hy, hz) drawn per axis, so `cornell`
is the room (1, 1, 1).
"""

from __future__ import annotations

import colorsys

import numpy as np

from viewer.scene import meshes
from viewer.scene.meshes import X_AXIS, Y_AXIS, Mesh, rotate, scale, transformed, translate
from viewer.scene import Camera, DirectionalLight, Scene
from viewer.evaluation.frames import Frame, room_frames
from viewer.evaluation.lights import CORNELL_POWER  # noqa: F401 - re-exported (tests, studies)
from viewer.evaluation.lights import WALL_GAP, draw_lights, draw_window, glow_objects, rectangle_light
from viewer.neural.ranges import OBJECT_KINDS, PRESETS, Ranges  # noqa: F401 - re-exported

OBJECT_GAP = 0.03
"""Smallest distance between an object and a wall, and between an object's top and the ceiling lights."""
LIGHT_ALBEDO = (0.8, 0.8, 0.8)
WALL_NAMES = ("floor", "ceiling", "back", "left-wall", "right-wall")
DEFAULT_CAMERA_FOV = Camera().fov


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


def place_objects(rng: np.random.Generator, half: np.ndarray, ranges: Ranges, ceiling_clearance: float,
                  obstacles=(), keep_clear=()) -> list[tuple[str, Mesh, np.ndarray, dict]]:
    """Rejection sampling: each object on the floor, or on top of an upright box, inside the room
    with OBJECT_GAP to the walls, below the lights, overlapping no other object nor `obstacles` (the
    partitions), and off the (x0, x1, z0, z1) floor rectangles of `keep_clear` (floor lights)."""
    count = int(rng.integers(ranges.objects[0], ranges.objects[1] + 1))
    top_limit = half[1] - ceiling_clearance - OBJECT_GAP
    placed: list[tuple[str, Mesh, np.ndarray, dict]] = list(obstacles)
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
            if keep_clear and base == -float(half[1]) and on_clear(moved, keep_clear):
                continue
            params["position"] = [x, base, z]
            params["albedo"] = colour.tolist()
            name = f"{kind}-{k + 1}"
            placed.append((name, (moved, faces), colour, params))
            break
    return placed[len(obstacles):]


def inside_room(vertices: np.ndarray, half: np.ndarray, top_limit: float) -> bool:
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return bool(np.all(np.abs(vertices[:, [0, 2]]) <= half[[0, 2]] - OBJECT_GAP + 1e-9)
                and lo[1] >= -half[1] - 1e-9 and hi[1] <= top_limit)


# ---- thin partitions -------------------------------------------------------------------------------

def draw_partitions(rng: np.random.Generator, half: np.ndarray, ranges: Ranges, top_limit: float,
                    keep_clear: list) -> list[tuple[str, Mesh, np.ndarray, dict]]:
    """Thin upright panels (closed boxes) standing on the floor at right angles to the back or a side
    wall, OBJECT_GAP from it, apart from each other and off the floor lights."""
    count = int(rng.integers(ranges.partitions[0], ranges.partitions[1] + 1))
    placed: list[tuple[str, Mesh, np.ndarray, dict]] = []
    for k in range(count):
        colour = random_colour(rng, ranges, ranges.saturated_wall_probability)
        for _ in range(ranges.placement_tries):
            wall = str(rng.choice(["back", "left-wall", "right-wall"]))
            along, across = (2, 0) if wall == "back" else (0, 2)   # the panel runs along `along`
            thickness = rng.uniform(*ranges.partition_thickness)
            length = rng.uniform(*ranges.partition_length) * 2 * half[along]
            height = rng.uniform(*ranges.partition_height) * (top_limit + half[1])
            position = rng.uniform(-half[across] + 0.25, half[across] - 0.25)
            centre, size = np.zeros(3), np.zeros(3)
            start = -half[along] + OBJECT_GAP
            if wall == "right-wall":
                start = half[along] - OBJECT_GAP - length
            centre[along], size[along] = start + 0.5 * length, 0.5 * length
            centre[across], size[across] = position, 0.5 * thickness
            centre[1], size[1] = -half[1] + 0.5 * height, 0.5 * height
            vertices, faces = transformed(meshes.cube(), translate(*centre) @ scale(*size))
            if any(meshes.overlap(vertices, other[1][0]) for other in placed) or on_clear(vertices, keep_clear):
                continue
            params = {"wall": wall, "centre": centre.tolist(), "half": size.tolist(), "albedo": colour.tolist()}
            placed.append((f"partition-{k + 1}", (vertices, faces), colour, params))
            break
    return placed


def on_clear(vertices: np.ndarray, keep_clear: list) -> bool:
    """Whether an object standing on the floor covers one of the (x0, x1, z0, z1) floor rectangles."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return any(lo[0] < x1 and x0 < hi[0] and lo[2] < z1 and z0 < hi[2] for x0, x1, z0, z1 in keep_clear)


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
    lights, glowing, power, used = draw_lights(rng, frames, ranges, window)
    ceiling_clearance = WALL_GAP + OBJECT_GAP
    parts: list[tuple[str, Mesh, np.ndarray, np.ndarray]] = []
    for wall in WALL_NAMES:
        mesh = wall_with_hole(frames[wall], hole if window and window["wall"] == wall else None)
        parts.append((wall, mesh, colours[wall], np.zeros(3)))
    keep_clear = [(m[0][:, 0].min(), m[0][:, 0].max(), m[0][:, 2].min(), m[0][:, 2].max())
                  for m, _, p in lights if p["wall"] == "floor"]
    partitions = []
    if ranges.partitions[1] > 0:
        partitions = draw_partitions(rng, half, ranges, half[1] - ceiling_clearance - OBJECT_GAP, keep_clear)
    objects = place_objects(rng, half, ranges, ceiling_clearance, partitions, keep_clear)
    glow, left = glow_objects(rng, objects, glowing, power, ranges) if glowing else ({}, [])
    for share, _ in left:  # no object to light: the ceiling takes it
        light = rectangle_light(rng, frames, ranges, used, share, power, wall="ceiling")
        if light is not None:
            lights.append(light)
    parts += [(n, mesh, colour, np.zeros(3)) for n, mesh, colour, _ in partitions]
    parts += [(n, mesh, colour, glow[n][0] if n in glow else np.zeros(3)) for n, mesh, colour, _ in objects]
    for k, (mesh, radiance, _) in enumerate(lights):
        parts.append(("light" if k == 0 else f"light-{k + 1}", mesh, np.array(LIGHT_ALBEDO), radiance))
    distance = 2.9 * max(half[0], half[1])
    camera = Camera((0.0, 0.0, float(half[2] + distance)), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), DEFAULT_CAMERA_FOV)
    scene = assemble(name, parts, sun, camera)
    params = {
        "room_half": half.tolist(),
        "walls": {wall: colours[wall].tolist() for wall in WALL_NAMES},
        "objects": [p for _, _, _, p in objects],
        "lights": [p for _, _, p in lights] + [p for _, p in glow.values()],
        "window": window,
        "camera": {"origin": list(camera.origin), "target": list(camera.target), "up": list(camera.up),
                   "fov": camera.fov},
    }
    if ranges.partitions[1] > 0:
        params["partitions"] = [p for _, _, _, p in partitions]
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
