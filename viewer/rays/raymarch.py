"""Rays through a VoxelGrid's occupancy, vectorized over millions of rays.

Both the transport solver (visibility V_ij between voxels, shadows from the sun) and the probe projection
(what a probe sees in each direction) march here. A ray advances by the free-space distance to the
nearest occupied cell (a Euclidean distance transform of the occupancy, minus one cell diagonal so the
step is always safe), never less than half a voxel; rays are compacted as they finish, so the cost
follows the total number of steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from viewer.rays.voxels import VoxelGrid

MISS = -1
"""The ray left the grid."""
BACKFACE = -2
"""The ray entered an occupied cell from behind its surfaces (it started inside a solid)."""

_SAFE = np.sqrt(3.0)  # cell-centre distance lost between a point in one cell and the surface of another


@dataclass(frozen=True)
class Tracer:
    lo: np.ndarray
    h: float
    n: int
    occupied: np.ndarray
    """(N^3,) bool, flat index x + y*N + z*N*N (the hash id)."""
    free_steps: np.ndarray
    """(N^3,) float32: safe step length in voxels from anywhere in the cell, at least half a voxel."""
    first: np.ndarray
    """(N^3 + 1,) offsets into the voxel arrays: cell c holds voxels first[c]:first[c+1]."""
    position: np.ndarray
    normal: np.ndarray
    reach: np.ndarray
    """(K,) squared radius of each voxel's surface patch: (0.75 * sqrt(area))^2, which covers the
    corners of a square patch."""

    @staticmethod
    def build(voxels: VoxelGrid) -> "Tracer":
        n = voxels.resolution
        occ = voxels.occupancy
        distance = ndimage.distance_transform_edt(~occ)
        steps = np.maximum(distance - _SAFE, 0.5)
        flat_steps = steps.transpose(2, 1, 0).reshape(-1).astype(np.float32)  # [x,y,z] -> hash order
        counts = np.bincount(voxels.hash_id, minlength=n ** 3)
        first = np.concatenate([[0], np.cumsum(counts)])
        return Tracer(voxels.lo.astype(np.float64), float(voxels.voxel_size), n,
                      occ.transpose(2, 1, 0).reshape(-1), flat_steps, first,
                      voxels.position, voxels.normal, 0.5625 * voxels.area)

    def cell_index(self, points: np.ndarray) -> np.ndarray:
        """Flat cell index of points, -1 outside the grid."""
        c = np.floor((points - self.lo) * (1.0 / self.h)).astype(np.int64)
        # one unsigned comparison catches both c < 0 and c >= n
        inside = (c.view(np.uint64) < self.n).all(axis=-1)
        flat = c[..., 0] + c[..., 1] * self.n + c[..., 2] * (self.n * self.n)
        flat[~inside] = -1
        return flat

    def first_hits(self, origins: np.ndarray, directions: np.ndarray, chunk: int = 1 << 20) -> np.ndarray:
        """Index of the voxel each ray hits first, MISS, or BACKFACE.

        In an occupied cell the ray hits the voxel that faces it most; in the cell it starts in, only a
        voxel whose plane lies ahead of the origin counts, so probes inside a wall's voxel layer still
        see the wall they are in front of and not the one behind them.
        """
        o = np.asarray(origins, np.float64).reshape(-1, 3)
        d = np.asarray(directions, np.float64).reshape(-1, 3)
        out = np.empty(len(o), np.int64)
        for s in range(0, len(o), chunk):
            out[s:s + chunk] = self._first_hits(o[s:s + chunk], d[s:s + chunk])
        return out

    def _first_hits(self, o: np.ndarray, d: np.ndarray) -> np.ndarray:
        result = np.full(len(o), MISS, np.int64)
        start = self.cell_index(o)
        # State of the rays still marching, compacted as they finish.
        ray = np.nonzero(start >= 0)[0]
        o, d, start = o[ray], d[ray], start[ray]
        t = np.zeros(len(ray))
        for _ in range(8 * self.n):
            if not len(ray):
                break
            cell = self.cell_index(o + t[:, None] * d)
            live = cell >= 0
            test = np.nonzero(live & self.occupied[np.maximum(cell, 0)])[0]
            if len(test):
                hit = self._facing_voxel(o[test], d[test], cell[test], cell[test] == start[test])
                done = hit != MISS
                result[ray[test[done]]] = hit[done]
                live[test[done]] = False
            if not live.all():
                ray, o, d, start, t, cell = (x[live] for x in (ray, o, d, start, t, cell))
            t += self.free_steps[cell] * self.h
        return result

    def _facing_voxel(self, o, d, cells, in_start_cell) -> np.ndarray:
        """Among the voxels of each cell, the one facing the ray most (-d.n largest). BACKFACE when none
        faces it; in the start cell, MISS (keep marching) when none faces it from ahead."""
        best = np.full(len(cells), MISS, np.int64)
        score = np.zeros(len(cells))
        lo, hi = self.first[cells], self.first[cells + 1]
        for k in range(int((hi - lo).max())):
            idx = np.minimum(lo + k, len(self.normal) - 1)
            exists = lo + k < hi
            facing = -np.einsum("ij,ij->i", d, self.normal[idx])
            ahead = np.einsum("ij,ij->i", o - self.position[idx], self.normal[idx]) >= 0
            better = exists & (facing > score) & (ahead | ~in_start_cell)
            best = np.where(better, idx, best)
            score = np.where(better, facing, score)
        return np.where((best == MISS) & ~in_start_cell, BACKFACE, best)

    def segments_clear(self, a: np.ndarray, b: np.ndarray, chunk: int = 1 << 20) -> np.ndarray:
        """True where the segment a->b is not blocked: it crosses no voxel's surface, each voxel's
        surface being its plane clipped to its cell. `a` must lie in the grid.

        Occupied cells are not solid blocks: a ray that grazes along a wall, or leaves a surface close
        to a room corner, passes through the wall's own voxel layer without crossing its plane. The
        crossing is exact, so each occupied cell is tested once, when the march first lands in it;
        steps are at least half a voxel, so a segment that only cuts a cell's corner may miss it.
        """
        out = np.empty(len(a), bool)
        for s in range(0, len(a), chunk):
            out[s:s + chunk] = self._segments_clear(a[s:s + chunk], b[s:s + chunk])
        return out

    def _segments_clear(self, a, b) -> np.ndarray:
        d = b - a
        length = np.linalg.norm(d, axis=1)
        d = d / np.maximum(length, 1e-30)[:, None]
        clear = np.ones(len(a), bool)
        # State of the segments still marching, compacted as they finish.
        ray = np.arange(len(a))
        o, t = a, np.zeros(len(a))
        checked = np.full(len(a), -1, np.int64)  # the last occupied cell tested: each is tested once
        for _ in range(8 * self.n):
            cell = self.cell_index(o + t[:, None] * d)
            # the grid is convex: a segment that has left it meets nothing more
            live = (t < length) & (cell >= 0)
            test = np.nonzero(live & self.occupied[np.maximum(cell, 0)] & (cell != checked))[0]
            if len(test):
                checked[test] = cell[test]
                blocked = test[self._crosses_a_surface(o[test], d[test], length[test], cell[test])]
                clear[ray[blocked]] = False
                live[blocked] = False
            if not live.all():
                ray, o, d, t, length, checked, cell = (x[live] for x in (ray, o, d, t, length, checked, cell))
                if not len(ray):
                    break
            t += self.free_steps[cell] * self.h
        return clear

    def _crosses_a_surface(self, a, d, length, cells) -> np.ndarray:
        """Whether each segment crosses the surface of one of the cell's voxels: its plane, clipped to the
        cell and to a square-sized patch around its centroid (`reach`), so that the plane of a box side
        does not reach past the box's edge into the free part of the cell."""
        crossed = np.zeros(len(cells), bool)
        lo, hi = self.first[cells], self.first[cells + 1]
        for k in range(int((hi - lo).max())):
            idx = np.minimum(lo + k, len(self.normal) - 1)
            n = self.normal[idx]
            dn = np.einsum("ij,ij->i", d, n)
            safe = np.where(np.abs(dn) > 1e-12, dn, 1e-12)
            t = np.einsum("ij,ij->i", self.position[idx] - a, n) / safe
            within = (np.abs(dn) > 1e-12) & (t > 0) & (t < length)
            x = a + t[:, None] * d
            near = np.einsum("ij,ij->i", x - self.position[idx], x - self.position[idx]) <= self.reach[idx]
            crossed |= (lo + k < hi) & within & near & (self.cell_index(x) == cells)
        return crossed

    def escapes(self, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """True where a ray from each origin along one direction leaves the grid unblocked (sun shadows)."""
        far = origins + np.asarray(direction, np.float64) * (3.0 * self.n * self.h)
        return self.segments_clear(origins, far)
