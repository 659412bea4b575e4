"""Which side of which face a ray meets: the face's own normal against the ray, and two-sided sheets.

A hit's side comes from the face's normal (e1 x e2, counter-clockwise front) against the ray's direction,
as the DDA's BACKFACE does: light reflected by the back of a face is the back side's.

A two-sided sheet (a thin wall, a leaf, a curtain) is often modelled as two faces on the same three
corners, wound opposite ways, each side its own material. A ray meets both at the same distance, and the
tracer names either one: which depends on the order its hierarchy tests them, so a ray that should land
on the near side could be named the far side's face met from behind, which brings no light. Each face's
reversed twin is found once per caster (`reversed_twins`), and a face met from behind that has one is
named as its twin met from the front (`facing_face`): the sheet's near side, whichever of the two the
tracer reported. Faces that share a plane without sharing corners (a quad and its reversed copy split
along the other diagonal, a box's base on the floor) still tie, and the tracer's order settles them.
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.rays import embree

NO_FACE = -1
"""The face of a ray that meets nothing within its length."""
NO_TWIN = np.zeros(0, np.int64)
"""A `twin` table of no faces: no face has a reversed twin (`facing_face` reads it only where one may)."""


def reversed_twins(corners: np.ndarray) -> np.ndarray:
    """(F,) int64: for each face of `corners` (F, 3, 3), a face with the same three corners wound the
    other way, -1 where there is none; NO_TWIN where no face has one. Compiled passes over the faces:
    each one's key, which its corners' order does not change (the corners weighted by irrational
    numbers, least, middle and greatest), then each looked up in a hash table of the keys' bits, and
    only faces of equal keys compared corner for corner (a 68k-triangle scan in about a millisecond)."""
    c = np.ascontiguousarray(corners, np.float64).reshape(-1, 3, 3)
    if len(c) < 2:
        return NO_TWIN
    key = np.empty(len(c))
    _keys(c, key)
    twin = np.full(len(c), -1, np.int64)
    bits = max(int(len(c) - 1).bit_length() + 1, 1)
    return twin if _twins(c, key, key.view(np.uint64), bits, twin) else NO_TWIN


@numba.njit(cache=True, nogil=True)
def _keys(c, key):
    """key[f]: face f's corners weighted by irrational numbers, least, middle and greatest, each times an
    irrational weight of its own; min and max are exact, so any order of the same corners gives the same
    bits."""
    a, b, d, e, g = np.sqrt(2.0), np.sqrt(3.0), np.sqrt(5.0), np.sqrt(13.0), np.sqrt(17.0)
    for f in range(c.shape[0]):
        w0 = a * c[f, 0, 0] + b * c[f, 0, 1] + d * c[f, 0, 2]
        w1 = a * c[f, 1, 0] + b * c[f, 1, 1] + d * c[f, 1, 2]
        w2 = a * c[f, 2, 0] + b * c[f, 2, 1] + d * c[f, 2, 2]
        low, high = min(w0, w1), max(w0, w1)
        key[f] = min(low, w2) * e + max(low, min(high, w2)) * g + max(high, w2)


@numba.njit(cache=True, nogil=True)
def _twins(c, key, bits, width, twin):
    """Fill `twin` (F,) (`reversed_twins`) from the faces' keys and their bits; whether any face has one.
    A table of 2^width slots, open addressing."""
    size = np.uint64(1) << np.uint64(width)
    mask, shift = size - np.uint64(1), np.uint64(64 - width)
    table = np.full(np.int64(size), -1, np.int64)
    found = False
    for f in range(c.shape[0]):
        slot = (bits[f] * np.uint64(0x9E3779B97F4A7C15)) >> shift
        while table[slot] >= 0:
            g = table[slot]
            if key[g] == key[f] and twin[f] < 0 and _reversed(c, f, g):
                twin[f] = g
                if twin[g] < 0:
                    twin[g] = f
                found = True
            slot = (slot + np.uint64(1)) & mask
        table[slot] = f
    return found


@numba.njit(cache=True, nogil=True)
def _reversed(c, f, g):
    """Whether faces f and g have the same three corners and face opposite ways."""
    for i in range(3):
        matched = False
        for j in range(3):
            if c[f, i, 0] == c[g, j, 0] and c[f, i, 1] == c[g, j, 1] and c[f, i, 2] == c[g, j, 2]:
                matched = True
        if not matched:
            return False
    nf, ng = _normal(c, f), _normal(c, g)
    dot = nf[0] * ng[0] + nf[1] * ng[1] + nf[2] * ng[2]
    return dot < 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def _normal(c, f):
    """Face f's (unnormalized) normal: its counter-clockwise front."""
    ux, uy, uz = c[f, 1, 0] - c[f, 0, 0], c[f, 1, 1] - c[f, 0, 1], c[f, 1, 2] - c[f, 0, 2]
    vx, vy, vz = c[f, 2, 0] - c[f, 0, 0], c[f, 2, 1] - c[f, 0, 1], c[f, 2, 2] - c[f, 0, 2]
    return uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx


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
    from the front where f was met from behind and has one (`twin`: `reversed_twins`)."""
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
