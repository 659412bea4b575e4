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

import numpy as np

FLAT = 1e-6
"""A bounding box thinner than this fraction of its largest extent along an axis is flat along it."""
DERIVED = ("triangles", "edges", "face_cross", "face_areas", "face_normals")
"""The properties made face by face from the corners: a moved scene makes them from its source's."""
FROM_POSITIONS = ("geometry_digest", "_extremes", "bounds")
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


def _patched(array, rows: np.ndarray, values):
    """A read-only copy of `array` (or of each array of a tuple) with `rows` set to `values`."""
    if isinstance(array, tuple):
        return tuple(_patched(a, rows, v) for a, v in zip(array, values))
    out = array.copy()
    out[rows] = values
    return read_only(out)


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
        scene's hashes its source's and the moved corners (a million-triangle scan's corners took 61 ms to
        hash): the same triangles reached by other edits may then have another digest, and a solver that
        keys its traces by it traces again; different triangles never share one."""
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
    def _moved(self, vertices: np.ndarray, moved: np.ndarray):
        """A copy whose vertices at the indices `moved` took new places in `vertices` (the others as here;
        the array becomes the copy's own, read-only). The new places are checked alone (`_check_positions`);
        the DERIVED properties this scene has made are made from its, when first asked (`_from_moved`)."""
        v = np.ascontiguousarray(vertices, np.float64)
        moved = np.asarray(moved, np.int64)
        if v.shape != self.vertices.shape:
            return replace(self, vertices=v)
        self._check_positions(v[moved])
        v.setflags(write=False)
        touched = np.zeros(len(v), bool)
        touched[moved] = True
        faces = np.flatnonzero(touched[self.faces].any(axis=1))
        scene = copy.copy(self)
        for name in DERIVED + FROM_POSITIONS + ("_moved_from",):
            scene.__dict__.pop(name, None)
        object.__setattr__(scene, "vertices", v)
        scene.__dict__["_moved_from"] = (faces, {n: self.__dict__[n] for n in DERIVED if n in self.__dict__})
        if "geometry_digest" in self.__dict__:   # the source's digest and what moved, not every corner again
            corners = np.ascontiguousarray(v[self.faces[faces]])
            scene.__dict__["geometry_digest"] = hashlib.blake2b(
                self.geometry_digest + faces.tobytes() + corners.tobytes(), digest_size=16).digest()
        if "_extremes" in self.__dict__ and len(moved):
            lo, hi = self._extremes
            before, after = self.vertices[moved], v[moved]
            if np.all((before > lo) & (before < hi)) and np.all((after >= lo) & (after <= hi)):
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
        out = _patched(base, faces, corner_rows(name, self.vertices[self.faces[faces]]))
        kept.pop(name, None)   # the source's array is not held once this one is made
        return out

    def _check_positions(self, v: np.ndarray) -> None:
        raise NotImplementedError

    def _error(self, message: str) -> Exception:
        raise NotImplementedError
