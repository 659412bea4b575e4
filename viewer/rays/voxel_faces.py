"""Voxels kept per (voxel, face), so that a scene whose triangles moved only in part (a dragged lamp) is
voxelized again from the moved faces alone.

`viewer.rays.voxels` cuts every triangle into pieces of at most a quarter voxel and sums the pieces per voxel
(area, area-weighted centroid and normal). Those sums are additive over faces: kept per (voxel, face)
pair, the pairs of the faces that did not move stay as they were, and the moved faces' pieces make new
pairs. Summing the pairs per voxel gives `voxelize_with_faces`' grid and face shares, to round-off (the
sums come in another order). A lamp moved in the Cornell box re-bins only the lamp's pieces (the
binning itself is compiled: viewer.rays.pieces).

Only the `area` normals (the default) are kept this way; the voxel frame (the scene's bounds) must not
change, nor the faces' indices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import sparse

from viewer.scene import Scene
from viewer.rays.moved_faces import changed_rows
from viewer.scene.textures import relative_at
from viewer.rays.pieces import PIECE_EDGE, face_pairs
from viewer.rays.voxels import (FACINGS, VoxelGrid, Voxelization, light_samples, subdivide, face_facing,
                           grid_frame, voxel_albedo)

MOVED_SHARE = 0.5
"""Past this share of the surface moved (its pieces are the work), voxelizing afresh is as quick."""


@dataclass(frozen=True)
class FaceVoxels:
    """A scene's voxelization as (voxel key, face) pairs (see the module docstring)."""

    resolution: int
    lo: np.ndarray
    size: float
    """The voxel edge h."""
    triangles: np.ndarray
    """(F, 3, 3) the triangles voxelized."""
    kept: np.ndarray
    """(F,) bool: faces with an area (the others make no pieces)."""
    key: np.ndarray
    """(Q,) voxel key (cell index x 6 + facing) of each pair."""
    face: np.ndarray
    """(Q,) the scene face of each pair."""
    area: np.ndarray
    """(Q,) the area of the face's pieces in the voxel."""
    moment: np.ndarray
    """(Q, 3) their area-weighted centroids, summed."""
    tint: np.ndarray | None = None
    """(Q, 3) their area times (texture / texture mean - 1) where they lie, summed; None without textures
    (viewer.rays.voxels.Voxelization.tint)."""

    @staticmethod
    def of(scene: Scene, resolution: int) -> "FaceVoxels":
        lo, size = grid_frame(scene, resolution)
        triangles = scene.triangles
        kept = _kept(scene.face_areas)
        key, face, area, moment, tint = _pairs(scene, triangles, np.flatnonzero(kept), lo, size, resolution)
        return FaceVoxels(resolution, lo, size, triangles, kept, key, face, area, moment, tint)

    def moved(self, scene: Scene) -> "FaceVoxels | None":
        """The pairs of `scene`, whose faces are these but some moved: the moved faces' pairs made anew,
        the others kept. None when that does not apply (another frame, other faces, most faces moved)."""
        if scene.triangles.shape != self.triangles.shape or scene.textured != (self.tint is not None):
            return None
        lo, size = grid_frame(scene, self.resolution)
        if size != self.size or not np.array_equal(lo, self.lo):
            return None
        triangles = scene.triangles
        moved = changed_rows((triangles, self.triangles))
        areas = scene.face_areas
        kept = _kept(areas)
        if areas[moved].sum() > MOVED_SHARE * areas.sum() or np.any((kept != self.kept) & ~moved):
            return None
        fresh = _pairs(scene, triangles, np.flatnonzero(moved & kept), lo, size, self.resolution)
        before = (self.key, self.face, self.area, self.moment, self.tint)
        return FaceVoxels(self.resolution, lo, size, triangles, kept, *_restacked(moved, before, fresh))

    def voxelization(self, scene: Scene) -> Voxelization:
        """`voxelize_with_faces(scene, resolution)` (area normals) from the pairs: the sums per voxel and the
        voxels' face shares (the sparse matrix's rows in order of face, as scipy orders them) in one
        compiled pass over the pairs (numpy's bincounts and scipy's sort of the pairs took 121 ms of a
        lamp moved in a million-triangle scan)."""
        n = self.resolution
        keys, inverse, area, moment, normal, indptr, order = _grouped(
            self.key, self.face, self.area, self.moment, np.ascontiguousarray(scene.face_normals, np.float64),
            n ** 3 * 6)
        count = len(keys)
        position = moment / np.maximum(area, 1e-30)[:, None]
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        normal = np.where(length > 1e-12, normal / np.maximum(length, 1e-30), FACINGS[keys % 6])
        under = np.maximum(area[inverse], 1e-300)
        index = np.int32 if max(len(scene.faces), len(order)) < 2 ** 31 else np.int64
        columns, rows = self.face[order].astype(index), indptr.astype(index)

        def shares(values):
            return sparse.csr_matrix(((values / under)[order], columns, rows), shape=(count, len(scene.faces)))

        faces = shares(self.area)
        tint = None if self.tint is None else tuple(shares(self.tint[:, c]) for c in range(3))
        cell = keys // 6
        coords = np.stack([cell % n, (cell // n) % n, cell // n ** 2], axis=1)
        grid = VoxelGrid(lo=self.lo, voxel_size=self.size, resolution=n, coords=coords, position=position,
                         normal=normal, area=area, albedo=voxel_albedo(faces, tint, scene),
                         emission=faces @ scene.emission,
                         lights=light_samples(scene, np.flatnonzero(self.kept), self.lo, self.size, n, keys))
        return Voxelization(grid, faces, keys, tint)


INSERTION_SORT = 32
"""`_grouped` orders a voxel's pairs of up to this many faces in place, one by one, and sorts longer ones:
numpy's sort a voxel, each a small array of its own, took half the pass (200k pairs of 64^3 voxels
48 -> 24 ms, a box room's 3,000 in 24^3 voxels 0.39 -> 0.29 ms; the same order)."""


@numba.njit(cache=True, nogil=True)
def _grouped(key, face, area, moment, normals, bound):
    """The pairs grouped by voxel key (keys in [0, `bound`)): (keys (K,) ascending, each pair's voxel (Q,),
    the voxels' summed area (K,), moment (K, 3) and area-weighted normal (K, 3), in the pairs' order as
    np.bincount sums them; and the pairs in order of voxel, then of face: each voxel's first (K + 1,) and
    the order (Q,))."""
    pairs = len(key)
    index = np.full(bound, -1, np.int64)
    for q in range(pairs):
        index[key[q]] = 0
    count = 0
    for b in range(bound):
        if index[b] == 0:
            index[b] = count
            count += 1
    keys = np.empty(count, np.int64)
    for b in range(bound):
        if index[b] >= 0:
            keys[index[b]] = b
    inverse = np.empty(pairs, np.int64)
    total = np.zeros(count)
    moments = np.zeros((count, 3))
    normal = np.zeros((count, 3))
    first = np.zeros(count + 1, np.int64)
    for q in range(pairs):
        r = index[key[q]]
        inverse[q] = r
        total[r] += area[q]
        f = face[q]
        for c in range(3):
            moments[r, c] += moment[q, c]
            normal[r, c] += normals[f, c] * area[q]
        first[r + 1] += 1
    for r in range(count):
        first[r + 1] += first[r]
    order = np.empty(pairs, np.int64)
    slot = first[:-1].copy()
    for q in range(pairs):
        r = inverse[q]
        order[slot[r]] = q
        slot[r] += 1
    for r in range(count):   # each voxel's pairs in order of face (a voxel holds one pair a face)
        if first[r + 1] - first[r] > INSERTION_SORT:
            row = order[first[r]:first[r + 1]]
            row[:] = row[np.argsort(face[row])]
            continue
        for i in range(first[r] + 1, first[r + 1]):
            q, j = order[i], i
            while j > first[r] and face[order[j - 1]] > face[q]:
                order[j] = order[j - 1]
                j -= 1
            order[j] = q
    return keys, inverse, total, moments, normal, first, order


def _restacked(moved: np.ndarray, before: tuple, fresh: tuple) -> tuple:
    """(key, face, area, moment, tint): the `before` pairs of the faces that did not move, then the
    `fresh` ones (the moved faces'), in one compiled pass (numpy's masks and copies took 54 ms of a lamp
    moved in a million-triangle scan)."""
    tinted = before[4] is not None
    empty = np.zeros((0, 3))
    key, face, area, moment, tint = before
    new_key, new_face, new_area, new_moment, new_tint = fresh
    stay = np.empty(len(face), np.bool_)
    count = _staying(np.asarray(moved, np.bool_), face, stay)
    out = (np.empty(count + len(new_key), np.int64), np.empty(count + len(new_key), np.int64),
           np.empty(count + len(new_key)), np.empty((count + len(new_key), 3)),
           np.empty((count + len(new_key), 3)) if tinted else empty)
    _restack(stay, key, face, area, moment, tint if tinted else empty, new_key, new_face, new_area, new_moment,
             new_tint if tinted else empty, *out)
    return out if tinted else (*out[:4], None)


@numba.njit(cache=True, nogil=True)
def _staying(moved, face, stay):
    count = 0
    for q in range(len(face)):
        stay[q] = not moved[face[q]]
        count += stay[q]
    return count


@numba.njit(cache=True, nogil=True)
def _restack(stay, key, face, area, moment, tint, new_key, new_face, new_area, new_moment, new_tint,
             out_key, out_face, out_area, out_moment, out_tint):
    out = (out_key, out_face, out_area, out_moment, out_tint)
    w = 0
    for q in range(len(stay)):
        if stay[q]:
            _put(q, (key, face, area, moment, tint), w, out)
            w += 1
    for q in range(len(new_key)):
        _put(q, (new_key, new_face, new_area, new_moment, new_tint), w + q, out)


@numba.njit(cache=True, nogil=True, inline="always")
def _put(q, source, w, out):
    """Row q of the pairs `source` (key, face, area, moment, tint: empty without textures) to row w of `out`."""
    out[0][w], out[1][w], out[2][w] = source[0][q], source[1][q], source[2][q]
    for c in range(3):
        out[3][w, c] = source[3][q, c]
        if out[4].shape[0] > 0:
            out[4][w, c] = source[4][q, c]


def _kept(areas: np.ndarray) -> np.ndarray:
    """The faces voxelizing cuts into pieces (as viewer.rays.voxels: an area above 1e-12 of the largest)."""
    return areas > 1e-12 * max(float(areas.max()), 1e-30)


def _pairs(scene: Scene, triangles: np.ndarray, faces: np.ndarray, lo: np.ndarray, size: float, resolution: int):
    """(key, face, area, moment, tint) per (voxel, face) pair of the pieces of `faces`, as viewer.rays.voxels
    cuts and bins them (tint None for a scene without textures)."""
    normals = scene.face_normals
    if len(faces) == 0:
        return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)),
                np.zeros((0, 3)) if scene.textured else None)
    facing = face_facing(normals, faces)
    if not scene.textured:
        key, source, area, moment = face_pairs(triangles, scene.face_areas, facing, lo, size, resolution, faces)
        return key, faces[source], area, moment, None
    centroid, piece_area, source = subdivide(triangles[faces], PIECE_EDGE * size)
    piece_face = faces[source]
    coords = np.clip(np.floor((centroid - lo) / size).astype(np.int64), 0, resolution - 1)
    cell = coords[:, 0] + coords[:, 1] * resolution + coords[:, 2] * resolution ** 2
    key = cell * 6 + facing[source]
    pair, inverse = np.unique(key * len(normals) + piece_face, return_inverse=True)
    inverse = inverse.ravel()
    area = np.bincount(inverse, piece_area, minlength=len(pair))
    moment = np.stack([np.bincount(inverse, centroid[:, c] * piece_area, minlength=len(pair)) for c in range(3)],
                      axis=1)
    excess = (relative_at(scene, piece_face, centroid) - 1.0) * piece_area[:, None]
    tint = np.stack([np.bincount(inverse, excess[:, c], minlength=len(pair)) for c in range(3)], axis=1)
    return pair // len(normals), pair % len(normals), area, moment, tint
