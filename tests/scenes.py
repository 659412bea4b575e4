"""Scenes that tests build in a line (in the spirit of Mitsuba's dictionaries)."""

from __future__ import annotations

import numpy as np

from viewer.scene import Scene

# Unit cube corners and its six faces, counter-clockwise seen from outside.
CUBE_VERTICES = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], np.float64)
CUBE_QUADS = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])


def quads_to_triangles(quads: np.ndarray) -> np.ndarray:
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def box(half_size=1.0, centre=(0.0, 0.0, 0.0), inward=False, albedo=0.5, emission=0.0, name="box") -> Scene:
    """An axis-aligned box; `inward` turns its faces to the inside (a closed room)."""
    faces = quads_to_triangles(CUBE_QUADS)
    if inward:
        faces = faces[:, ::-1]
    vertices = CUBE_VERTICES * half_size + np.asarray(centre, np.float64)
    return Scene(name, vertices, faces, np.broadcast_to(albedo, (len(faces), 3)),
                 np.broadcast_to(emission, (len(faces), 3)), np.zeros(len(faces), np.int64), (name,))


def furnace() -> Scene:
    """Closed room, albedo 0.5 and emission 1 everywhere: L = 1 / (1 - 0.5) = 2 in free space."""
    return box(inward=True, albedo=0.5, emission=1.0, name="furnace")


def ceiling_lamp(half_size=0.3, height=0.95, radiance=5.0) -> Scene:
    """A square lamp facing down (counter-clockwise seen from below)."""
    h = half_size
    vertices = np.array([[-h, height, -h], [h, height, -h], [h, height, h], [-h, height, h]], np.float64)
    return Scene("lamp", vertices, np.array([[0, 1, 2], [0, 2, 3]]), 0.0, radiance, 0, ("lamp",))


def lit_room(*objects: Scene) -> Scene:
    """A closed white room (albedo 0.5) lit by a ceiling lamp, with objects in it."""
    return Scene.concatenate("lit-room", [box(inward=True, albedo=0.5, name="room"), ceiling_lamp(), *objects])


# ---- procedural rooms ------------------------------------------------------------------------------

def group_faces(scene, name):
    return scene.face_group == scene.group_index(name)


def group_corners(scene, name):
    """(K, 3) the positions of the vertices the group's faces use, in index order."""
    return scene.vertices[np.unique(scene.faces[group_faces(scene, name)])]


def srgb_to_linear(c):
    """IEC 61966-2-1 from 8-bit values: the tests' own, to check the loaders' decoding against."""
    c = np.asarray(c, np.float64) / 255
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def covered(points: np.ndarray, triangles: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
    """Whether each point (P, 3) lies on one of the triangles (T, 3, 3) (in its plane and inside)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    n = np.cross(b - a, c - a)
    d = points[:, None] - a[None]                                              # (P, T, 3)
    in_plane = np.abs(np.einsum("ptc,tc->pt", d, n)) <= tolerance * np.linalg.norm(n, axis=1)
    inside = np.ones(in_plane.shape, bool)
    for p0, p1 in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ptc,tc->pt", np.cross(p1 - p0, points[:, None] - p0[None]), n) >= -tolerance
    return np.any(in_plane & inside, axis=1)


def assert_same_room(a: Scene, params_a: dict, b: Scene, params_b: dict) -> None:
    """Two drawn rooms are bit-identical: geometry, materials, groups and the drawn parameters."""
    import json

    for name in ("vertices", "faces", "albedo", "emission", "face_group"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.groups == b.groups and json.dumps(params_a) == json.dumps(params_b)


def wall_samples(params: dict, name: str, count: int):
    """A count x count grid of points over one wall of a drawn room (viewer.evaluation.procedural), and
    which of them lie in the window's hole: (the wall's frame, points (count^2, 3), hole (count^2,))."""
    from viewer.evaluation import procedural

    u = (np.arange(count) + 0.5) / count * 2 - 1
    grid = np.stack(np.meshgrid(u, u, indexing="ij"), -1).reshape(-1, 2)
    f = procedural.room_frames(np.array(params["room_half"]))[name]
    points = f.centre + grid[:, :1] * f.half_u * f.u + grid[:, 1:] * f.half_v * f.v
    hole = np.zeros(len(points), bool)
    window = params["window"]
    if window is not None and window["wall"] == name:
        (a, b), (ha, hb) = window["uv"], window["half"]
        hole = (np.abs(grid[:, 0] * f.half_u - a) < ha) & (np.abs(grid[:, 1] * f.half_v - b) < hb)
    return f, points, hole
