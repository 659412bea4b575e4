"""The shadows of the direct light at the probe lattice and the voxels: one visibility ray per probe and
cluster of emitting patches, and the sun's.
"""

from __future__ import annotations

import numpy as np

from viewer.neural.direct import facings
from viewer.probes import sh
from viewer.rays.lattice_sight import LatticeSight, sweeps
from viewer.rays.voxel_rays import VoxelRays

VISIBILITY_CELLS = 2
"""Edge, in lattice cells, of the clusters of emitting patches that share one visibility ray per probe."""
SHADOW_OFFSET = 1.0
"""A cluster's visibility ray ends this many voxels (of the occluders' grid) in front of its patches'
mean position. Not less: a voxel averages every surface of one facing in its cell, so a lamp lying on
the floor has its position between the lamp's top and the floor, and a ray to it would end inside the
lamp."""


def patch_visibility(blockers: VoxelRays, points: np.ndarray, position: np.ndarray, normal: np.ndarray,
                     lo: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """(P, E) float32, 1 where probe p sees emitting patch e (at `position` facing `normal`), else 0: one
    ray per probe and cluster of patches (`shadow_targets`)."""
    if len(position) == 0:
        return np.ones((len(points), 0), np.float32)
    target, cluster = shadow_targets(blockers, position, normal, lo, spacing)
    return blockers.pairs_clear(points, target)[:, cluster]


def lattice_visibility(blockers: VoxelRays, points: np.ndarray, position: np.ndarray, normal: np.ndarray,
                       lo: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """`patch_visibility` from the probes of the lattice `points` (m^3, 3) over the scene's bounds: swept
    over the lattice, rays traced at shadows' edges (`viewer.rays.lattice_sight`) where the patches'
    clusters have enough ray ends and Embree traces them (`sweeps`); else every segment."""
    if len(position) == 0:
        return np.ones((len(points), 0), np.float32)
    target, cluster = shadow_targets(blockers, position, normal, lo, spacing)
    if sweeps(blockers, len(target)):
        return LatticeSight(blockers, points, lo, spacing).visibility(target)[0].T[:, cluster]
    return blockers.pairs_clear(points, target)[:, cluster]


def shadow_targets(blockers: VoxelRays, position: np.ndarray, normal: np.ndarray, lo: np.ndarray,
                   spacing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the visibility rays of emitting patches end: (C, 3) one point per cluster, and (E,) each
    patch's cluster. Patches are clustered VISIBILITY_CELLS lattice cells a side per facing; a cluster's
    ray ends at the mean of its patches' positions, lifted SHADOW_OFFSET voxels along their normal. So
    a patch's visibility depends on every patch of its cluster, whichever emitter they belong to."""
    if len(position) == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    facing = facings(normal)
    block = np.floor((position - lo) / (spacing * VISIBILITY_CELLS)).astype(np.int64)
    _, cluster = np.unique(np.column_stack([block, facing]), axis=0, return_inverse=True)
    cluster = cluster.ravel()
    count = cluster.max() + 1
    centre = np.stack([np.bincount(cluster, position[:, a], minlength=count) for a in range(3)], 1)
    centre /= np.bincount(cluster, minlength=count)[:, None]
    lift = np.stack([np.bincount(cluster, normal[:, a], minlength=count) for a in range(3)], 1)
    lift /= np.maximum(np.linalg.norm(lift, axis=1, keepdims=True), 1e-12)
    return centre + SHADOW_OFFSET * blockers.cells.h * lift, cluster


def sun_sh(sun, blockers: VoxelRays | None, points: np.ndarray) -> np.ndarray:
    """(P, 9, 3) the sun's delta at the probes where a ray towards it leaves the scene unblocked."""
    out = np.zeros((len(points), sh.SH_COUNT, 3))
    if sun is None or not np.any(np.asarray(sun.irradiance) > 0):
        return out
    direction = np.asarray(sun.direction, np.float64)
    visible = sun_visibility(blockers, points, direction)
    return visible[:, None, None] * sh.project_delta(direction, sun.irradiance)[None]


def sun_visibility(blockers: VoxelRays | None, points: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(P,) float 1 where a ray from the probe towards the sun (`direction` points to it) escapes."""
    if blockers is None:
        return np.ones(len(points))
    return blockers.escapes(points, direction).astype(np.float64)

