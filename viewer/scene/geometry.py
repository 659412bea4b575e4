"""What a Scene derives from its triangles' corners: the corners themselves, edges, cross products, areas,
normals and bounds. Each is made once per scene, when first asked, and kept read-only (the scene is
immutable): a stage asks for the faces' areas or the bounds many times, and on a 68k-triangle scan each
cross product took 15 ms (0.25 s of opening it).

A scene made by moving some vertices of another (a dragged lamp or object, `TriangleGeometry._moved`)
makes each of them from the other scene's, when first asked: that array copied, the rows of the faces that
moved made again. On a million-triangle scan, making everything afresh took 0.4 s of each step of a drag
on the render thread, and most of it is never asked for there.
"""

from __future__ import annotations

import copy
import hashlib
from dataclasses import replace
from functools import cached_property

import numba
import numpy as np

from viewer.threads import RUNS, cores_for

FLAT = 1e-6
"""A bounding box thinner than this fraction of its largest extent along an axis is flat along it."""
DERIVED = ("triangles", "edges", "face_cross", "face_areas", "face_normals")
"""The properties made face by face from the corners: a moved scene makes them from its source's."""
FROM_POSITIONS = ("geometry_digest", "_extremes", "bounds", "twins")
"""The properties made from all the positions at once: a moved scene makes them afresh (the extremes kept
where the moved vertices were and stay inside them)."""


def read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def corner_rows(name: str, corners: np.ndarray):
    """The rows of the DERIVED property `name` for the faces with `corners` (K, 3, 3), as the properties
    make them for all the faces (the same numbers to the last bit)."""
    t = corners
    if name == "triangles":
        return t
    if name == "edges":
        return t[:, 0], t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return cross if name == "face_cross" else cross_rows(name, cross)


def cross_rows(name: str, cross: np.ndarray) -> np.ndarray:
    """The faces' areas or unit normals (`name`: face_areas, face_normals; zero normals for degenerate
    faces) from their corners' cross products (K, 3)."""
    length = np.linalg.norm(cross, axis=1, keepdims=True)
    if name == "face_areas":
        return 0.5 * length[:, 0]
    return np.divide(cross, length, out=np.zeros_like(cross), where=length > 0)


NO_TWIN = read_only(np.zeros(0, np.int64))
"""A `twin` table of no faces: no face has a reversed twin (viewer.rays.sides.facing_face reads it only
where one may)."""


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
    return read_only(twin) if _twins(c, key, key.view(np.uint64), bits, twin) else NO_TWIN


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


class TriangleGeometry:
    """The Scene's derived geometry (cached properties over its `vertices` (V, 3) and `faces` (F, 3))."""

    vertices: np.ndarray
    faces: np.ndarray

    @cached_property
    def triangles(self) -> np.ndarray:
        """(F, 3, 3) corner positions: each stage of a new scene asks for them, and on a 272k-triangle scan
        each gather of the corners took 14 ms (100 ms of voxelizing it)."""
        kept = self._from_moved("triangles")
        return kept if kept is not None else read_only(self.vertices[self.faces])

    @cached_property
    def geometry_digest(self) -> bytes:
        """A hash of the triangles' corners (what traced geometry depends on; not colours or lights). A moved
        scene's hashes its source's and the move: the group and its matrix (`Scene.transformed_group`), or
        the moved vertices and their places (a million-triangle scan's corners took 61 ms to hash): the same
        triangles reached by other edits may then have another digest, and a solver that keys its traces by
        it traces again; different triangles never share one."""
        return hashlib.blake2b(np.ascontiguousarray(self.triangles).tobytes(), digest_size=16).digest()

    @cached_property
    def edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(v0, e1, e2), each (F, 3) contiguous: each face's first corner and its edges to the other two,
        as every ray caster reads them (three stages of a moved lamp's scene made them each, 2-3 ms a time
        on a 68k-triangle scan)."""
        kept = self._from_moved("edges")
        if kept is not None:
            return kept
        t = self.triangles
        return tuple(read_only(np.ascontiguousarray(a)) for a in corner_rows("edges", t))

    @cached_property
    def face_cross(self) -> np.ndarray:
        kept = self._from_moved("face_cross")
        return kept if kept is not None else read_only(corner_rows("face_cross", self.triangles))

    @cached_property
    def face_areas(self) -> np.ndarray:
        kept = self._from_moved("face_areas")
        return kept if kept is not None else read_only(cross_rows("face_areas", self.face_cross))

    @cached_property
    def face_normals(self) -> np.ndarray:
        """Unit front-face normals (zero for degenerate faces)."""
        kept = self._from_moved("face_normals")
        return kept if kept is not None else read_only(cross_rows("face_normals", self.face_cross))

    @cached_property
    def twins(self) -> np.ndarray:
        """(F,) each face's reversed twin (`reversed_twins`): the other side of a two-sided sheet, -1 for
        none; NO_TWIN where no face has one. Asked by every ray caster, the rasterizer's buffers and
        Mitsuba's conversion of the scene, made once (24 ms on a million triangles)."""
        return reversed_twins(self.triangles)

    @cached_property
    def _unused(self) -> np.ndarray | None:
        """(V,) bool: the vertices no face uses, or None where every vertex is used (a mask, not np.unique's
        sort: 0.3 ms against 9 on a 68k scan). It depends on the faces alone: a moved scene keeps it."""
        mask = np.ones(len(self.vertices), bool)
        mask[self.faces.ravel()] = False
        return mask if mask.any() else None

    @cached_property
    def _extremes(self) -> tuple[np.ndarray, np.ndarray]:
        """The least and greatest coordinates of the vertices the faces use."""
        used = self.vertices if self._unused is None else self.vertices[~self._unused]
        return read_only(used.min(axis=0)), read_only(used.max(axis=0))

    @cached_property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi): the box around the vertices the faces use, and the box every stage fills (probes,
        the camera's framing). A flat scene (a floor alone, one lamp) has no depth along one axis: that
        axis is widened, centred on the plane, to the box's largest extent, so that the probe grid over
        it has a spacing on every axis and probes on both sides of the plane."""
        lo, hi = self._extremes
        extent = hi - lo
        flat = extent <= FLAT * extent.max()
        if np.any(flat):
            half = 0.5 * (extent.max() if extent.max() > 0 else 1.0)
            centre = 0.5 * (lo + hi)
            lo, hi = np.where(flat, centre - half, lo), np.where(flat, centre + half, hi)
        return read_only(np.array(lo)), read_only(np.array(hi))

    # ---- a moved copy -------------------------------------------------------------------------------
    def _moved(self, vertices: np.ndarray, moved: np.ndarray, recipe: bytes | None = None):
        """A copy whose vertices at the indices `moved` took new places in `vertices` (the others as here;
        the array becomes the copy's own, read-only). The new places are checked alone (`_check_positions`);
        the DERIVED properties this scene has made are made from its, when first asked (`_from_moved`).
        `recipe`: bytes that name the move made of this scene (a group and its matrix), which the digest
        then hashes instead of the moved vertices (a million-triangle scan's: 72 MB, 55 ms)."""
        v = np.ascontiguousarray(vertices, np.float64)
        moved = np.asarray(moved, np.int64)
        if v.shape != self.vertices.shape:
            return replace(self, vertices=v)
        with cores_for(len(moved)):
            finite, after = _row_box(v, moved)   # the new places' box, in one pass on every core
        self._check_positions(after if finite else np.array([np.nan]))
        v.setflags(write=False)
        touched = np.zeros(len(v), bool)
        touched[moved] = True
        with cores_for(len(self.faces)):
            faces = np.flatnonzero(faces_touching(np.asarray(self.faces, np.int64), touched))
        scene = copy.copy(self)
        for name in DERIVED + FROM_POSITIONS + ("_moved_from",):
            scene.__dict__.pop(name, None)
        object.__setattr__(scene, "vertices", v)
        scene.__dict__["_moved_from"] = (faces, {n: self.__dict__[n] for n in DERIVED if n in self.__dict__})
        if "geometry_digest" in self.__dict__:   # the source's digest and what moved, not every corner again:
            digest = hashlib.blake2b(self.geometry_digest, digest_size=16)   # the faces are the same
            if recipe is not None:
                digest.update(recipe)
            else:   # the moved vertices and their places
                digest.update(moved.tobytes())
                digest.update(np.ascontiguousarray(v[moved]).tobytes())
            scene.__dict__["geometry_digest"] = digest.digest()
        if "_extremes" in self.__dict__ and len(moved):
            lo, hi = self._extremes
            with cores_for(len(moved)):
                before = _row_box(np.ascontiguousarray(self.vertices, np.float64), moved)[1]
            if np.all((before[0] > lo) & (before[1] < hi)) and np.all((after[0] >= lo) & (after[1] <= hi)):
                scene.__dict__["_extremes"] = self._extremes   # the extremes lie on vertices that stayed
        if not np.any(scene.face_areas > 0):
            raise self._error("every triangle is degenerate (zero area)")
        return scene

    def _from_moved(self, name: str):
        """`name` made from the scene this one was moved from, or None where that scene had not made it."""
        source = self.__dict__.get("_moved_from")
        if source is None or name not in source[1]:
            return None
        faces, kept = source
        base = kept.get(name)
        if base is None:   # another thread made it first
            return None
        out = tuple(a.copy() for a in base) if name == "edges" else base.copy()
        parts = dict(zip(("v0", "e1", "e2"), out)) if name == "edges" else {name.replace("face_", ""): out}
        with cores_for(len(faces)):
            _moved_rows(np.ascontiguousarray(self.vertices, np.float64), np.asarray(self.faces, np.int64),
                        np.asarray(faces, np.int64), *(parts.get(k, EMPTY[k]) for k in ROW_PARTS))
        kept.pop(name, None)   # the source's array is not held once this one is made
        return tuple(map(read_only, out)) if name == "edges" else read_only(out)

    def _check_positions(self, v: np.ndarray) -> None:
        raise NotImplementedError

    def _error(self, message: str) -> Exception:
        raise NotImplementedError


ROW_PARTS = ("triangles", "v0", "e1", "e2", "cross", "areas", "normals")
"""What `_moved_rows` writes, in its order (an empty array: not asked for)."""
EMPTY = {"triangles": np.zeros((0, 3, 3)), "areas": np.zeros(0),
         **{k: np.zeros((0, 3)) for k in ("v0", "e1", "e2", "cross", "normals")}}


@numba.njit(cache=True, nogil=True, parallel=True)
def _moved_rows(vertices, faces, rows, triangles, v0, e1, e2, cross, areas, normals):
    """The `rows` of the DERIVED arrays given (writable copies, or empty ones where not asked for) made again
    from the corners in one pass on every core, with `corner_rows`' arithmetic (the same numbers to the
    last bit: numpy's gather, differences, cross products and norms of a million moved triangles took 0.6
    s, with their temporaries)."""
    for i in numba.prange(rows.shape[0]):
        f = rows[i]
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        u0, u1, u2 = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
        w0, w1, w2 = vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1], vertices[c, 2] - vertices[a, 2]
        for k in range(3):
            if triangles.shape[0]:
                triangles[f, 0, k], triangles[f, 1, k], triangles[f, 2, k] = vertices[a, k], vertices[b, k], vertices[c, k]
            if v0.shape[0]:
                v0[f, k] = vertices[a, k]
        if e1.shape[0]:
            e1[f, 0], e1[f, 1], e1[f, 2] = u0, u1, u2
            e2[f, 0], e2[f, 1], e2[f, 2] = w0, w1, w2
        if cross.shape[0] or areas.shape[0] or normals.shape[0]:
            c0, c1, c2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
            if cross.shape[0]:
                cross[f, 0], cross[f, 1], cross[f, 2] = c0, c1, c2
            length = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            if areas.shape[0]:
                areas[f] = 0.5 * length
            if normals.shape[0]:
                if length > 0:
                    normals[f, 0], normals[f, 1], normals[f, 2] = c0 / length, c1 / length, c2 / length
                else:
                    normals[f, 0] = normals[f, 1] = normals[f, 2] = 0.0


@numba.njit(cache=True, nogil=True, parallel=True)
def faces_touching(faces, touched):
    """(F,) bool: the faces with a corner among the `touched` vertices (V,) bool, on every core."""
    out = np.empty(faces.shape[0], np.bool_)
    for f in numba.prange(faces.shape[0]):
        out[f] = touched[faces[f, 0]] or touched[faces[f, 1]] or touched[faces[f, 2]]
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _row_box(v, rows):
    """(whether every coordinate of the `rows` of `v` is finite, (2, 3) their least and greatest
    coordinates), in one pass on every core."""
    out = np.empty((RUNS, 2, 3))
    out[:, 0], out[:, 1] = np.inf, -np.inf
    finite = np.ones(RUNS, np.bool_)
    step = (rows.shape[0] + RUNS - 1) // RUNS
    for run in numba.prange(RUNS):
        for i in range(run * step, min((run + 1) * step, rows.shape[0])):
            for k in range(3):
                x = v[rows[i], k]
                if not np.isfinite(x):
                    finite[run] = False
                out[run, 0, k] = min(out[run, 0, k], x)
                out[run, 1, k] = max(out[run, 1, k], x)
    box = np.empty((2, 3))
    for k in range(3):
        box[0, k] = out[:, 0, k].min()
        box[1, k] = out[:, 1, k].max()
    return finite.all(), box


def group_vertices(faces: np.ndarray, face_group: np.ndarray, group: int, count: int) -> np.ndarray:
    """(K,) ascending: the vertices (of `count`) that faces of `group` use."""
    used = np.zeros(count, np.bool_)
    with cores_for(len(faces)):
        _mark_group(np.asarray(faces, np.int64), np.asarray(face_group, np.int64), int(group), used)
    return np.flatnonzero(used)


@numba.njit(cache=True, nogil=True, parallel=True)
def _mark_group(faces, face_group, group, used):
    for f in numba.prange(faces.shape[0]):
        if face_group[f] == group:   # the cores may mark one vertex at once: each writes True
            used[faces[f, 0]] = used[faces[f, 1]] = used[faces[f, 2]] = True


@numba.njit(cache=True, nogil=True, parallel=True)
def transform_rows(v, rows, matrix):
    """The `rows` of the positions `v` (V, 3) moved in place by the 4x4 affine `matrix`."""
    for i in numba.prange(rows.shape[0]):
        r = rows[i]
        x, y, z = v[r, 0], v[r, 1], v[r, 2]
        for k in range(3):
            v[r, k] = matrix[k, 0] * x + matrix[k, 1] * y + matrix[k, 2] * z + matrix[k, 3]
