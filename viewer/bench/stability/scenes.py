"""The scenes of the stability suite, each built in a few lines from axis-aligned quads.

All are closed rooms (so Mitsuba and the solvers agree on what is inside) with Lambertian walls and
one-sided quad lamps facing down (counter-clockwise seen from below, docs/ARCHITECTURE.md).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from viewer.scene import Scene

ROOM_ALBEDO = 0.5
LAMP_HEIGHT = 0.95
"""Lamps hang this high in a room spanning -1..1 in y: 0.05 below the ceiling, facing down."""


def quad(corners, albedo=ROOM_ALBEDO, emission=0.0, name="quad") -> Scene:
    """One planar quad (4, 3), front face where its corners run counter-clockwise."""
    return Scene(name, np.asarray(corners, np.float64), np.array([[0, 1, 2], [0, 2, 3]]), albedo, emission, 0,
                 (name,))


def rectangle(axis: int, at: float, lo, hi, facing: int, albedo=ROOM_ALBEDO, emission=0.0, name="wall") -> Scene:
    """An axis-aligned rectangle on the plane x[axis] = at, spanning lo..hi on the two other axes (in
    their cyclic order), facing +axis (facing=1) or -axis (facing=-1)."""
    u, v = (axis + 1) % 3, (axis + 2) % 3
    corners = np.zeros((4, 3))
    corners[:, axis] = at
    corners[:, u] = [lo[0], hi[0], hi[0], lo[0]]
    corners[:, v] = [lo[1], lo[1], hi[1], hi[1]]
    if facing < 0:
        corners = corners[::-1]
    return quad(corners, albedo, emission, name)


def room(lo=(-1, -1, -1), hi=(1, 1, 1), albedo=ROOM_ALBEDO, emission=0.0, name="room") -> Scene:
    """A closed box whose six sides face inwards."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    sides = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        span = ((lo[u], lo[v]), (hi[u], hi[v]))
        sides.append(rectangle(axis, lo[axis], *span, facing=1, albedo=albedo, emission=emission, name=name))
        sides.append(rectangle(axis, hi[axis], *span, facing=-1, albedo=albedo, emission=emission, name=name))
    return Scene.concatenate(name, sides)


def block(centre, half, albedo=ROOM_ALBEDO, name="block") -> Scene:
    """A closed box seen from outside (faces outwards)."""
    centre, half = np.asarray(centre, np.float64), np.broadcast_to(np.asarray(half, np.float64), (3,))
    lo, hi = centre - half, centre + half
    sides = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        span = ((lo[u], lo[v]), (hi[u], hi[v]))
        sides.append(rectangle(axis, lo[axis], *span, facing=-1, albedo=albedo, name=name))
        sides.append(rectangle(axis, hi[axis], *span, facing=1, albedo=albedo, name=name))
    return Scene.concatenate(name, sides)


def lamp(centre=(0.0, LAMP_HEIGHT, 0.0), half_size=0.3, radiance=5.0, name="lamp") -> Scene:
    """A square emitter facing down (-y), albedo 0."""
    x, y, z = centre
    h = half_size
    return quad([[x - h, y, z - h], [x + h, y, z - h], [x + h, y, z + h], [x - h, y, z + h]], 0.0, radiance, name)


def lit_room(*objects: Scene, albedo=ROOM_ALBEDO, radiance=5.0, half_size=0.3, centre=(0.0, LAMP_HEIGHT, 0.0),
             name="lit-room") -> Scene:
    """The closed room -1..1 lit by one ceiling lamp, with objects in it."""
    return Scene.concatenate(name, [room(albedo=albedo), lamp(centre, half_size, radiance), *objects])


def furnace(albedo: float) -> Scene:
    """Every side emits 1 and reflects `albedo`: L = 1 / (1 - albedo) everywhere inside."""
    return room(albedo=albedo, emission=1.0, name=f"furnace-{albedo:g}")


# ---- light leaking ---------------------------------------------------------------------------------------

WALL_THICKNESS = 0.02
"""The dividing wall of `two_rooms`: 1/13 of a voxel at 16^3 voxels, 1/7 at 32^3, 1/3 at 64^3."""
DOOR = ((0.3, 0.8), (-1.0, 0.2))
"""(z range, y range) of the door in the dividing wall of `two_rooms(door=True)`, far from the lamp."""


def two_rooms(door: bool = False, wall: float = WALL_THICKNESS) -> Scene:
    """Two 2 x 2 x 2 rooms side by side (x in -2..0 lit by a lamp, x in 0..2 dark), divided by a wall
    `wall` thick at x = 0: a quad facing each room. With `door`, light reaches the dark room through a
    doorway (its jambs and lintel included, so the inside of the wall stays closed). A wall 0 thick is a
    two-sided sheet: the dark room's side is the lit side's triangles wound the other way (`-sheet` ends
    the name)."""
    w = 0.5 * wall
    parts = [room(lo=(-2, -1, -1), hi=(2, 1, 1)), lamp(centre=(-1.0, LAMP_HEIGHT, 0.0))]
    if not door:
        spans = [((-1.0, -1.0), (1.0, 1.0))]       # (y, z) lo, hi: the whole wall
    else:
        (z0, z1), (y0, y1) = DOOR
        spans = [((-1.0, -1.0), (1.0, z0)), ((-1.0, z1), (1.0, 1.0)), ((y1, z0), (1.0, z1))]
        if w > 0:   # a sheet has no jambs
            parts += [rectangle(2, z0, (-w, y0), (w, y1), facing=1, name="jamb"),     # (x, y) spans
                      rectangle(2, z1, (-w, y0), (w, y1), facing=-1, name="jamb"),
                      rectangle(1, y1, (z0, -w), (z1, w), facing=-1, name="jamb")]     # lintel, (z, x)
    for lo, hi in spans:
        lit = rectangle(0, -w, lo, hi, facing=-1, name="wall")           # faces the lit room
        parts.append(lit)
        if w > 0:
            parts.append(rectangle(0, w, lo, hi, facing=1, name="wall"))  # faces the dark room
        else:   # a sheet: the same triangles wound the other way (`Scene.twins`)
            parts.append(replace(lit, faces=np.ascontiguousarray(lit.faces[:, ::-1])))
    name = ("two-rooms-door" if door else "two-rooms") + ("-sheet" if wall == 0 else "")
    return Scene.concatenate(name, parts)


def in_dark_room(points: np.ndarray) -> np.ndarray:
    return points[:, 0] > 0.5 * WALL_THICKNESS


# ---- resolution: a scene with features thinner than a voxel ----------------------------------------------

def thin_shelf(thickness: float = 0.02) -> Scene:
    """The lit room with a shelf `thickness` thick across most of it, half-way up: below it, the light
    arrives only around its edge."""
    t = 0.5 * thickness
    shelf = [rectangle(1, t, (-1.0, -1.0), (1.0, 0.4), facing=1, name="shelf"),     # (z, x) spans
             rectangle(1, -t, (-1.0, -1.0), (1.0, 0.4), facing=-1, name="shelf"),
             rectangle(0, 0.4, (-t, -1.0), (t, 1.0), facing=1, name="shelf")]         # front edge, (y, z)
    return lit_room(*shelf, name="thin-shelf")


# ---- temporal stability: a lamp moving along a path --------------------------------------------------------

PATH = (np.array([-0.65, LAMP_HEIGHT, -0.55]), np.array([0.6, LAMP_HEIGHT, 0.45]))
"""The moving lamp's path: a ceiling diagonal that crosses voxel boundaries at every phase."""


def moving_lamp(t: float, half_size: float = 0.15, radiance: float = 20.0) -> Scene:
    """The lit room with a block on the floor and a small lamp at fraction `t` of PATH."""
    start, end = PATH
    centre = start + t * (end - start)
    return Scene.concatenate(f"moving-lamp-{t:.3f}", [
        room(), lamp(tuple(centre), half_size, radiance),
        block((0.25, -0.6, 0.2), (0.3, 0.4, 0.3))])
