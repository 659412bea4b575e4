"""Which side of which face a ray meets: the face's own normal against the ray, and two-sided sheets.

A hit's side comes from the face's normal (e1 x e2, counter-clockwise front) against the ray's direction,
as the DDA's BACKFACE does: light reflected by the back of a face is the back side's.

A two-sided sheet (a thin wall, a leaf, a curtain) is often modelled as two faces on the same three
corners, wound opposite ways, each side its own material. A ray meets both at the same distance, and the
tracer names either one: which depends on the order its hierarchy tests them, so a ray that should land
on the near side could be named the far side's face met from behind, which brings no light. Each face's
reversed twin is found once per scene (`Scene.twins`), and a face met from behind that has one is
named as its twin met from the front (`facing_face`): the sheet's near side, whichever of the two the
tracer reported. Faces that share a plane without sharing corners (a PLY's quad and its reversed copy
split along the other diagonal, a box's base on the floor) still tie, and the tracer's order settles them;
an OBJ's reversed polygons are fanned alike so that they pair up (viewer.scene.obj).
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.rays import embree
from viewer.scene.geometry import NO_TWIN  # noqa: F401 - what a `twin` table of no faces is

NO_FACE = -1
"""The face of a ray that meets nothing within its length."""


@numba.njit(cache=True, nogil=True, inline="always")
def front_of(f, dx, dy, dz, e1, e2):
    """Whether a ray along d meets face f from the front: d . (e1 x e2) < 0, the DDA's test."""
    nx = e1[f, 1] * e2[f, 2] - e1[f, 2] * e2[f, 1]
    ny = e1[f, 2] * e2[f, 0] - e1[f, 0] * e2[f, 2]
    nz = e1[f, 0] * e2[f, 1] - e1[f, 1] * e2[f, 0]
    return dx * nx + dy * ny + dz * nz < 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def facing_face(f, dx, dy, dz, e1, e2, twin):
    """(face, front) of a ray along d that met face f (not NO_FACE): f and its side, or f's reversed twin
    from the front where f was met from behind and has one (`twin`: `Scene.twins`)."""
    front = front_of(f, dx, dy, dz, e1, e2)
    if not front and twin.shape[0] > 0 and twin[f] >= 0:
        return twin[f], True
    return f, front


@numba.njit(cache=True, nogil=True, inline="always")
def barycentrics(px, py, pz, f, v0, e1, e2):
    """(u, v) of the point p on face f's plane: p = v0 + u e1 + v e2 (least squares off the plane)."""
    wx, wy, wz = px - v0[f, 0], py - v0[f, 1], pz - v0[f, 2]
    aa = e1[f, 0] ** 2 + e1[f, 1] ** 2 + e1[f, 2] ** 2
    ab = e1[f, 0] * e2[f, 0] + e1[f, 1] * e2[f, 1] + e1[f, 2] * e2[f, 2]
    bb = e2[f, 0] ** 2 + e2[f, 1] ** 2 + e2[f, 2] ** 2
    wa = wx * e1[f, 0] + wy * e1[f, 1] + wz * e1[f, 2]
    wb = wx * e2[f, 0] + wy * e2[f, 1] + wz * e2[f, 2]
    det = aa * bb - ab * ab
    if det <= 0.0:
        return 0.0, 0.0
    return (bb * wa - ab * wb) / det, (aa * wb - ab * wa) / det


@numba.njit(cache=True, nogil=True, inline="always")
def first_face(intersect, scene, record, faces, e1, e2, twin, v0, ox, oy, oz, dx, dy, dz, far):
    """(face, t, u, v, front) of the first face a ray meets, as `TriangleCaster.closest_hits` names it
    (face NO_FACE for none; a two-sided sheet's near side: `facing_face`, its u, v on that face), traced
    through Embree from a compiled loop that makes its rays as it goes: `intersect`, `scene` of
    `TriangleCaster.direct.handle`, `record` an `embree.record()`, `faces`, `e1`, `e2`, `twin`, `v0` the
    caster's."""
    primitive, t, u, v = embree.closest(intersect, scene, record, ox, oy, oz, dx, dy, dz, far)
    if primitive < 0:
        return NO_FACE, t, u, v, False
    f = faces[primitive]
    g, front = facing_face(f, dx, dy, dz, e1, e2, twin)
    if g != f:
        u, v = barycentrics(ox + t * dx, oy + t * dy, oz + t * dz, g, v0, e1, e2)
    return g, t, u, v, front


@numba.njit(cache=True, nogil=True)
def sides(o, d, face, t, u, v, v0, e1, e2, twin):
    """(face, u, v, front) of each hit (`facing_face`, with u, v on the face named; NO_FACE stays). One
    thread: a few nanoseconds a ray, and a parallel loop would add seconds to a first run's compile."""
    front = np.zeros(face.shape[0], np.bool_)
    named, u, v = face.copy(), u.copy(), v.copy()
    for r in range(face.shape[0]):
        f = face[r]
        if f < 0:
            continue
        named[r], front[r] = facing_face(f, d[r, 0], d[r, 1], d[r, 2], e1, e2, twin)
        if named[r] != f:
            u[r], v[r] = barycentrics(o[r, 0] + t[r] * d[r, 0], o[r, 1] + t[r] * d[r, 1], o[r, 2] + t[r] * d[r, 2],
                                      named[r], v0, e1, e2)
    return named, u, v, front
