"""The geometry of a scene whose faces moved in part (a dragged lamp), from the geometry before it: only
the rays the move can change are traced again.

A ray's first hit depends on nothing but the triangles listed in the cells it walks through up to that
hit and the voxel each of those entries names. So the cells whose listing changed are found (they list a
moved triangle, before or after, or an entry names another voxel), grouped, and boxed; a ray is
traced again when the part of it that mattered meets a box: up to its hit (plus two voxel
diagonals: the hit lies in the entry's cell, which is the voxel's or a neighbour's) or, for a ray that
missed or met a back face, its whole length. Every other ray keeps its hit, under the voxel's new index.
A gather ray is also traced again when its receiver is new, lies in a changed cell, or moved in the
voxels' order (its directions turn with its index, `geometry.gather_directions`).

The result equals `geometry.trace` of the same voxelization, hit for hit (tests/physical/test_retrace.py). A lamp
moved in the Cornell box changes about a thousandth of the probe rays.
"""

from __future__ import annotations

from dataclasses import replace

import numba
import numpy as np
from scipy import ndimage

from viewer.rays import dda
from viewer.rays.moved_faces import changed_rows
from viewer.probes import sh
from viewer.physical.geometry import (SURFACE_OFFSET, Geometry, gather_directions, lamp_faces, probe_fields, scene_key,
                             transport_matrix)
from viewer.scene import Scene
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import Voxelization

CHANGED_SHARE = 0.25
"""Past this share of the occupied cells changed, tracing everything again is as quick."""


def after_moving(before: Geometry, scene: Scene, voxelization: Voxelization,
                 stats: dict | None = None) -> Geometry | None:
    """The geometry of `scene` (voxelized as `voxelization`, on the same voxel frame and with the same
    faces as `before`'s scene), tracing again only what the moved faces can change. None when that does
    not apply (another frame or other faces) or would not pay (most cells changed). `stats` receives
    how many gather and probe rays were traced again."""
    grid, old = voxelization.grid, before.voxels
    if (grid.resolution != old.resolution or grid.voxel_size != old.voxel_size
            or not np.array_equal(grid.lo, old.lo) or len(scene.faces) != before.faces.shape[1]):
        return None
    cells = dda.Cells.of(voxelization, scene, before.cells)
    rays = VoxelRays(scene, cells, before.rays.backend, previous=before.rays)
    keys = np.asarray(voxelization.keys, np.int64)
    changed = changed_cells(before.cells, before.voxel_keys, cells, keys)
    occupied = np.count_nonzero(np.diff(cells.first))
    if changed.sum() > CHANGED_SHARE * max(occupied, 1):
        return None
    boxes = cell_boxes(changed, cells.lo, cells.h, cells.n)
    new_index = dda.voxel_of(keys, before.voxel_keys)          # old voxel -> its index now, -1: gone
    slack = 2.0 * np.sqrt(3.0) * cells.h
    settings = before.settings

    # gather rays: receivers that kept their key, index and cell keep their rays
    k = grid.count
    old_index = dda.voxel_of(before.voxel_keys, keys)
    kept = (old_index == np.arange(k)) & ~changed[keys // 6]
    origins = grid.position + SURFACE_OFFSET * cells.h * grid.normal
    rows = np.flatnonzero(kept)
    directions = gather_directions(grid.normal[rows], settings.gather_rays, index=rows)
    gather = np.full((k, settings.gather_rays), dda.MISS, np.int32)
    redo = np.ones(gather.shape, bool)
    if len(rows):
        gather[rows], redo[rows] = _kept_hits(before.gather_hits[rows], None, origins[rows], directions,
                                              old.position, new_index, slack, boxes)
    _trace_again(rays, gather, redo, origins, lambda r, c: _gather_directions(grid.normal, settings.gather_rays, r, c))

    # probe rays: the same directions from every probe
    probe_directions, _ = sh.sphere_directions(settings.directions)
    probes, probe_redo = _kept_hits(before.probe_hits, before.probe_backface, before.probe_points,
                                    probe_directions[None], old.position, new_index, slack, boxes)
    _trace_again(rays, probes, probe_redo, before.probe_points, lambda r, c: probe_directions[c])
    hits, valid, waves, backface = probe_fields(probes, k, settings.probes, settings.invalid_backface_fraction)
    if stats is not None:
        stats.update(gather_rays=int(redo.sum()), gather_total=redo.size, probe_rays=int(probe_redo.sum()),
                     probe_total=probe_redo.size, changed_cells=int(changed.sum()), boxes=len(boxes))
    return replace(before, key=scene_key(scene, settings), voxels=grid, cells=cells, rays=rays, faces=voxelization.faces,
                   tint=voxelization.tint, lamp=lamp_faces(scene), transport=transport_matrix(gather), probe_hits=hits, valid=valid,
                   fill_waves=waves, probe_backface=backface, voxel_keys=keys, gather_hits=gather)


def changed_cells(before: dda.Cells, before_keys: np.ndarray, after: dda.Cells, after_keys: np.ndarray) -> np.ndarray:
    """(N^3,) bool: the cells whose listing differs: a moved triangle listed there (before or after), or
    another set of (triangle, voxel key) entries (a voxel appeared or went, and a grazing triangle's
    entry names a neighbour's)."""
    n3 = after.n ** 3
    moved = changed_rows((before.v0, after.v0), (before.e1, after.e1), (before.e2, after.e2))
    changed = np.zeros(n3, bool)
    signatures = []
    for c, keys in ((before, before_keys), (after, after_keys)):
        cell = np.repeat(np.arange(n3), np.diff(c.first))
        changed[cell[moved[c.triangle]]] = True
        signatures.append(_signature(c, keys))
    return changed | np.any(signatures[0] != signatures[1], axis=0)


def _signature(cells: dda.Cells, keys: np.ndarray) -> np.ndarray:
    """(2, N^3) uint64 per cell: its entry count and the sum of a hash of each (triangle, voxel key)."""
    voxel_key = np.where(cells.voxel >= 0, keys[np.maximum(cells.voxel, 0)], cells.voxel)
    value = _mix(cells.triangle.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15) + voxel_key.astype(np.uint64))
    total = np.concatenate([[np.uint64(0)], np.cumsum(value, dtype=np.uint64)])
    first = cells.first
    return np.stack([np.diff(first).astype(np.uint64), total[first[1:]] - total[first[:-1]]])


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finalizer: every input bit moves every output bit (sums of hashes then collide only
    by chance, 2^-64)."""
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def cell_boxes(changed: np.ndarray, lo: np.ndarray, h: float, n: int) -> np.ndarray:
    """(S, 6) lower and upper corners of a box around each group of changed cells (cells within one
    cell of each other group together), a hair past the cells."""
    grid = changed.reshape(n, n, n).transpose(2, 1, 0)          # flat index x + y N + z N^2 -> [x, y, z]
    labels, _ = ndimage.label(ndimage.binary_dilation(grid, np.ones((3, 3, 3), bool)), np.ones((3, 3, 3)))
    labels[~grid] = 0
    boxes = [[*(lo + h * (np.array([s.start for s in box]) - 1e-6)), *(lo + h * (np.array([s.stop for s in box]) + 1e-6))]
             for box in ndimage.find_objects(labels) if box is not None]
    return np.array(boxes, np.float64).reshape(-1, 6)


def _kept_hits(hits: np.ndarray, backface: np.ndarray | None, origins: np.ndarray, directions: np.ndarray,
               old_positions: np.ndarray, new_index: np.ndarray, slack: float,
               boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(raw hits under the new voxel indices, rays to trace again) of rays traced before: `hits` (A, B)
    as traced (MISS, BACKFACE or a voxel), or with `backface` (A, B) as the probes keep them (every ray
    without a voxel is the old voxel count, the back faces apart)."""
    no_flags = np.zeros((1, 1), np.bool_)
    return _keep(np.ascontiguousarray(origins, np.float64), np.ascontiguousarray(directions, np.float64),
                 np.ascontiguousarray(hits, np.int32), no_flags if backface is None else backface,
                 np.ascontiguousarray(old_positions, np.float64), new_index, slack, boxes)


def _trace_again(rays: VoxelRays, hits: np.ndarray, redo: np.ndarray, origins: np.ndarray, directions) -> None:
    """Trace the rays marked in `redo` (A, B) into `hits`; `directions(rows, columns)` gives theirs."""
    rows, columns = np.nonzero(redo)
    if len(rows):
        hits[rows, columns] = rays.first_hits(origins[rows], directions(rows, columns))


def _gather_directions(normals: np.ndarray, count: int, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """(R, 3) the direction of gather ray `columns[i]` of voxel `rows[i]`."""
    unique, inverse = np.unique(rows, return_inverse=True)
    return gather_directions(normals[unique], count, index=unique)[inverse.ravel(), columns]


@numba.njit(cache=True, nogil=True, parallel=True)
def _keep(origins, directions, hits, backface, positions, new_index, slack, boxes):
    """Ray (a, b) from origins[a] along directions[a or 0, b] is traced again when it meets a box before
    its hit (a voxel of `positions`: up to the voxel's distance + slack) or at all (no voxel), or when
    its voxel is gone; else it keeps its hit, under the voxel's new index."""
    count, rays = hits.shape
    stride = 0 if directions.shape[0] == 1 else 1   # one direction set for all, or one each
    flags = backface.shape[0] == count
    voxels = positions.shape[0]
    out = np.empty((count, rays), np.int32)
    redo = np.zeros((count, rays), np.bool_)
    for a in numba.prange(count):
        ox, oy, oz = origins[a, 0], origins[a, 1], origins[a, 2]
        row = a * stride
        for r in range(rays):
            hit = hits[a, r]
            if hit >= voxels:
                hit = dda.BACKFACE if flags and backface[a, r] else dda.MISS
            end = np.inf
            if hit >= 0:
                px, py, pz = positions[hit, 0] - ox, positions[hit, 1] - oy, positions[hit, 2] - oz
                end = np.sqrt(px * px + py * py + pz * pz) + slack
            dx, dy, dz = directions[row, r, 0], directions[row, r, 1], directions[row, r, 2]
            near = False
            for s in range(boxes.shape[0]):
                t0, t1 = 0.0, end
                t0, t1 = dda.slab(ox, dx, boxes[s, 0], boxes[s, 3], t0, t1)
                t0, t1 = dda.slab(oy, dy, boxes[s, 1], boxes[s, 4], t0, t1)
                t0, t1 = dda.slab(oz, dz, boxes[s, 2], boxes[s, 5], t0, t1)
                if t0 <= t1:
                    near = True
                    break
            moved_to = new_index[hit] if hit >= 0 else hit
            if near or moved_to == -1 and hit >= 0:
                redo[a, r] = True
                out[a, r] = dda.MISS
            else:
                out[a, r] = moved_to
    return out, redo
