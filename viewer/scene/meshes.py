"""Mesh primitives for building scenes in code: transforms, closed shapes, overlap tests.

Shared by the built-in scenes (assets/make_scenes.py) and the procedural training scenes
(viewer.evaluation.procedural). Plain numpy; a mesh is a pair (vertices (V, 3) float64, faces (F, 3)),
counter-clockwise seen from outside (the front face, docs/ARCHITECTURE.md).

Transforms follow Mitsuba's ScalarTransform4f conventions (4x4 matrices acting on column vectors,
composed T @ R @ S), and `rectangle` / `cube` are Mitsuba's shapes with the same vertex and face order,
so that `mitsuba.cornell_box()` can be reproduced exactly.
"""

from __future__ import annotations

import numpy as np

Mesh = tuple[np.ndarray, np.ndarray]
X_AXIS, Y_AXIS, Z_AXIS = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


# ---- transforms -------------------------------------------------------------------------------------

def translate(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def scale(x: float, y: float | None = None, z: float | None = None) -> np.ndarray:
    return np.diag([x, x if y is None else y, x if z is None else z, 1.0])


def rotate(axis, degrees: float) -> np.ndarray:
    """Right-handed rotation about `axis` (Rodrigues' formula, as Mitsuba's `rotate`)."""
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    theta = np.radians(degrees)
    cross = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.cos(theta) * np.eye(3) + np.sin(theta) * cross + (1 - np.cos(theta)) * np.outer(a, a)
    return m


# ---- shapes in object space ---------------------------------------------------------------------------

def rectangle() -> Mesh:
    """Mitsuba's `rectangle`: [-1, 1]^2 at z = 0, front face +z (same vertex and face order)."""
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [-1, 1, 0], [1, 1, 0]], np.float64)
    return vertices, np.array([[1, 2, 0], [1, 3, 2]])


def cube() -> Mesh:
    """[-1, 1]^3 (Mitsuba's `cube`) as six outward-facing rectangles."""
    sides = [translate(0, 0, 1), translate(0, 0, -1) @ rotate(Y_AXIS, 180),
             translate(1, 0, 0) @ rotate(Y_AXIS, 90), translate(-1, 0, 0) @ rotate(Y_AXIS, -90),
             translate(0, 1, 0) @ rotate(X_AXIS, -90), translate(0, -1, 0) @ rotate(X_AXIS, 90)]
    return merge([transformed(rectangle(), m) for m in sides])


def uv_sphere(rings: int = 12, segments: int = 16) -> Mesh:
    """Unit sphere: a pole at each end of y and `rings - 1` latitude circles (352 triangles at 12 x 16)."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.sin(theta)[:, None] * np.sin(phi), np.cos(theta)[:, None] * np.ones_like(phi),
                     np.sin(theta)[:, None] * np.cos(phi)], axis=-1).reshape(-1, 3)
    vertices = np.vstack([[0, 1, 0], ring, [0, -1, 0]])
    south = len(vertices) - 1
    faces = []
    for s in range(segments):
        t = (s + 1) % segments
        faces.append([0, 1 + s, 1 + t])
        for r in range(rings - 2):
            a, b = 1 + r * segments + s, 1 + r * segments + t
            faces += [[a, a + segments, b + segments], [a, b + segments, b]]
        last = 1 + (rings - 2) * segments
        faces.append([last + s, south, last + t])
    return vertices, np.array(faces)


def cylinder(segments: int = 24) -> Mesh:
    """Radius 1, y in [-1, 1], with both caps (4 x `segments` triangles)."""
    phi = 2 * np.pi * np.arange(segments) / segments
    circle = np.stack([np.sin(phi), np.zeros_like(phi), np.cos(phi)], axis=-1)
    vertices = np.vstack([circle + (0, 1, 0), circle - (0, 1, 0), [[0, 1, 0], [0, -1, 0]]])
    top, bottom = 2 * segments, 2 * segments + 1
    faces = []
    for s in range(segments):
        t = (s + 1) % segments
        faces += [[s, segments + s, segments + t], [s, segments + t, t],
                  [top, s, t], [bottom, segments + t, segments + s]]
    return vertices, np.array(faces)


def cone(segments: int = 24) -> Mesh:
    """Base radius 1 at y = -1, apex at y = +1, with the base cap (2 x `segments` triangles)."""
    phi = 2 * np.pi * np.arange(segments) / segments
    circle = np.stack([np.sin(phi), -np.ones_like(phi), np.cos(phi)], axis=-1)
    vertices = np.vstack([circle, [[0, 1, 0], [0, -1, 0]]])
    apex, bottom = segments, segments + 1
    faces = []
    for s in range(segments):
        t = (s + 1) % segments
        faces += [[apex, s, t], [bottom, t, s]]
    return vertices, np.array(faces)


def wedge() -> Mesh:
    """A ramp in [-1, 1]^3: the bottom face and the back face (z = -1) are full squares, and the slope
    runs from the top of the back edge down to the front bottom edge (z = +1). 8 triangles."""
    vertices = np.array([[-1, -1, -1], [1, -1, -1], [1, -1, 1], [-1, -1, 1],   # bottom
                         [-1, 1, -1], [1, 1, -1]], np.float64)                  # top of the back
    faces = np.array([[0, 1, 2], [0, 2, 3],      # bottom, facing -y
                      [0, 4, 5], [0, 5, 1],      # back, facing -z
                      [3, 2, 5], [3, 5, 4],      # slope, facing +y +z
                      [0, 3, 4], [1, 5, 2]])     # the two triangular sides, facing -x and +x
    return vertices, faces


def transformed(mesh: Mesh, matrix: np.ndarray) -> Mesh:
    vertices, faces = mesh
    return vertices @ matrix[:3, :3].T + matrix[:3, 3], faces


def merge(meshes: list[Mesh]) -> Mesh:
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes[:-1]])
    return (np.vstack([v for v, _ in meshes]),
            np.vstack([f + o for (_, f), o in zip(meshes, offsets)]))


def signed_volume(mesh: Mesh) -> float:
    """Volume enclosed by a closed mesh: positive when its faces point outwards (divergence theorem)."""
    vertices, faces = mesh
    return float(np.einsum("ij,ij->i", vertices[faces[:, 0]], np.cross(
        vertices[faces[:, 1]], vertices[faces[:, 2]])).sum() / 6.0)


# ---- overlap of convex objects standing upright -------------------------------------------------------

def overlap(a: np.ndarray, b: np.ndarray, tolerance: float = 1e-6) -> bool:
    """Whether two convex objects (vertex sets) overlap by more than `tolerance`: their height ranges
    and their convex footprints on the floor (separating axis test); touching is allowed. Conservative:
    it may report an overlap for shapes that only share footprint and height ranges (a sphere beside
    the corner of a box), never the other way round."""
    if min(a[:, 1].max(), b[:, 1].max()) - max(a[:, 1].min(), b[:, 1].min()) <= tolerance:
        return False
    for hull in (footprint(a), footprint(b)):
        edges = np.roll(hull, -1, axis=0) - hull
        for axis in np.stack([-edges[:, 1], edges[:, 0]], axis=1):
            pa, pb = a[:, [0, 2]] @ axis, b[:, [0, 2]] @ axis
            if min(pa.max(), pb.max()) - max(pa.min(), pb.min()) <= tolerance * np.linalg.norm(axis):
                return False
    return True


def footprint(vertices: np.ndarray) -> np.ndarray:
    """Corners of the convex hull of the (x, z) projection, in order."""
    from scipy.spatial import ConvexHull

    xz = vertices[:, [0, 2]]
    return xz[ConvexHull(xz).vertices]
