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

import numpy as np
from scipy import sparse

from viewer.scene import Scene
from viewer.rays.moved_faces import changed_rows
from viewer.scene.textures import relative_at
from viewer.rays.pieces import PIECE_EDGE, face_pairs
from viewer.rays.voxels import (FACINGS, VoxelGrid, Voxelization, light_samples, subdivide, face_facing,
                           grid_frame, voxel_albedo, sorted_unique)

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
        if areas[moved].sum() > MOVED_SHARE * areas.sum() or np.any(kept[~moved] != self.kept[~moved]):
            return None
        stay = ~moved[self.face]
        key, face, area, moment, tint = _pairs(scene, triangles, np.flatnonzero(moved & kept), lo, size,
                                               self.resolution)
        return FaceVoxels(self.resolution, lo, size, triangles, kept, np.concatenate([self.key[stay], key]),
                          np.concatenate([self.face[stay], face]), np.concatenate([self.area[stay], area]),
                          np.concatenate([self.moment[stay], moment]),
                          None if tint is None else np.concatenate([self.tint[stay], tint]))

    def voxelization(self, scene: Scene) -> Voxelization:
        """`voxelize_with_faces(scene, resolution)` (area normals) from the pairs."""
        n = self.resolution
        keys, inverse = sorted_unique(self.key, n ** 3 * 6)
        inverse = inverse.ravel()
        count = len(keys)
        area = np.bincount(inverse, self.area, minlength=count)
        safe = np.maximum(area, 1e-30)[:, None]

        def total(values):
            return np.stack([np.bincount(inverse, values[:, c], minlength=count) for c in range(3)], axis=1)

        position = total(self.moment) / safe
        normal = total(scene.face_normals[self.face] * self.area[:, None])
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        normal = np.where(length > 1e-12, normal / np.maximum(length, 1e-30), FACINGS[keys % 6])
        share = self.area / np.maximum(area[inverse], 1e-300)
        faces = sparse.csr_matrix((share, (inverse, self.face)), shape=(count, len(scene.faces)))
        tint = None if self.tint is None else tuple(
            sparse.csr_matrix((self.tint[:, c] / np.maximum(area[inverse], 1e-300), (inverse, self.face)),
                              shape=faces.shape) for c in range(3))
        cell = keys // 6
        coords = np.stack([cell % n, (cell // n) % n, cell // n ** 2], axis=1)
        grid = VoxelGrid(lo=self.lo, voxel_size=self.size, resolution=n, coords=coords, position=position,
                         normal=normal, area=area, albedo=voxel_albedo(faces, tint, scene),
                         emission=faces @ scene.emission,
                         lights=light_samples(scene, np.flatnonzero(self.kept), self.lo, self.size, n, keys))
        return Voxelization(grid, faces, keys, tint)


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
    facing = face_facing(normals[faces])
    if not scene.textured:
        key, source, area, moment = face_pairs(triangles[faces], scene.face_areas[faces], facing, lo, size,
                                               resolution)
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
