"""How much of each voxel's surface the sun reaches: the share of SUN_SIDE x SUN_SIDE points across the
voxel whose rays towards the sun leave the scene.

One ray from each voxel's centre made a sunlit patch out of whole voxels: a voxel half in the sun got
all of it or none. A room's sun patch, drawn so on 24^3 voxels, is not the one drawn on 32^3, and the
light it reflects was the largest part of the error in sunlit rooms. With nine points a voxel the
network's indirect light in two sunlit validation rooms went 15.8% -> 11.4% and 17.2% -> 14.4% off
Mitsuba's (docs/TRAINING.md).

The points lie on the plane through the voxel's surface point (`SURFACE_OFFSET` voxels in front of its
centroid), within its cell. A point reached from the surface point only through a surface (a floor
voxel beside a wall, whose plane runs on behind the wall) starts its ray at the surface point instead:
taken as they fall, such points saw the sun from outside the room and nearly doubled one room's error.
"""

from __future__ import annotations

import numpy as np

from viewer.rays.voxels import SURFACE_OFFSET, VoxelGrid

SUN_SIDE = 3
"""Points a side of each voxel's square of sun rays: 9 rays a voxel. Five a side (25 rays) took those two
rooms only 0.5 points further."""


def sun_starts(base: np.ndarray, normal: np.ndarray, cell_lo: np.ndarray, size: float,
               offset: float) -> np.ndarray:
    """(S, K, 3) the points across each voxel where its sun rays start: a SUN_SIDE x SUN_SIDE grid on the
    plane through its surface point `base` (K, 3) across its `normal` (K, 3), spanning the voxel's `size`,
    kept within its cell (`cell_lo` (K, 3)) and `offset` of it."""
    normal = np.asarray(normal, np.float64)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(normal, helper)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
    b = np.cross(normal, t)
    base = np.asarray(base, np.float64)
    steps = (np.arange(SUN_SIDE) + 0.5) / SUN_SIDE - 0.5
    lo, hi = np.asarray(cell_lo, np.float64) - offset, np.asarray(cell_lo, np.float64) + size + offset
    return np.stack([np.clip(base + size * (u * t + v * b), lo, hi) for u in steps for v in steps])


def sample_escapes(blockers, base: np.ndarray, starts: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(N,) bool: whether the sun ray of each sample point `starts` (N, 3) leaves the scene, started at its
    voxel's surface point `base` (N, 3) where a surface lies between the two. `blockers`: a
    `VoxelRays`."""
    base, starts = np.asarray(base, np.float64), np.asarray(starts, np.float64)
    reached = blockers.segments_clear(base, starts)
    return blockers.escapes(np.where(reached[:, None], starts, base), direction)


def sun_cover(blockers, base: np.ndarray, starts: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(K,) the share of each voxel's sample points (`starts` (S, K, 3), `base` (K, 3)) whose sun rays
    escape (`sample_escapes`); all of them where nothing casts a shadow (`blockers` None)."""
    s, k = starts.shape[:2]
    if blockers is None:
        return np.ones(k)
    seen = sample_escapes(blockers, np.broadcast_to(base, starts.shape).reshape(-1, 3), starts.reshape(-1, 3),
                          direction)
    return seen.reshape(s, k).mean(axis=0)


def voxel_sun_cover(blockers, voxels: VoxelGrid, direction: np.ndarray, among: np.ndarray | None = None) -> np.ndarray:
    """(K,) `sun_cover` of the voxels that face the sun (0 for the others, which it does not light), their
    rays started SURFACE_OFFSET voxels in front of them as every ray from a voxel starts. `among`: the
    rows to compute (the others 0), all where None."""
    direction = np.asarray(direction, np.float64)
    rows = np.flatnonzero(voxels.normal @ direction > 0)
    if among is not None:
        rows = np.intersect1d(rows, among, assume_unique=True)
    out = np.zeros(voxels.count)
    if len(rows):
        h = voxels.voxel_size
        normal = voxels.normal[rows]
        base = voxels.position[rows] + SURFACE_OFFSET * h * normal
        starts = sun_starts(base, normal, voxels.lo + voxels.coords[rows] * h, h, SURFACE_OFFSET * h)
        out[rows] = sun_cover(blockers, base, starts, direction)
    return out
