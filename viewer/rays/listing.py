"""Which triangles reach into which cells of a grid: the listing the cell-exact rays (viewer.rays.dda) read.

Every usable triangle is listed in each cell of its bounding box that its plane passes through (a
superset of the cells it passes through: an extra entry costs the march a test and never a hit). All of
it is compiled: the boxes, the candidates on every core, and the sort by cell (by counting: the cells are
a small integer range). With numpy's passes over the corners and a sort, a 272k-triangle scan's listing
took 93 ms, shared by the solver and the network on every new scene.
"""

from __future__ import annotations

import numba
import numpy as np


def listing(scene, lo: np.ndarray, h: float, n: int, only: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((E, 3) cell, (E,) triangle): every usable triangle of `scene` (an area above 1e-12 of the
    largest; of those in the (F,) bool `only`, where given) in each cell of its bounding box that its
    plane passes through, sorted by flat cell (x + n y + n^2 z) and, within a cell, by triangle."""
    areas = scene.face_areas
    usable = areas > 1e-12 * max(float(areas.max()), 1e-30)
    usable = np.flatnonzero(usable if only is None else usable & only)
    corners = np.ascontiguousarray(scene.triangles, np.float64)   # read in place at the usable rows
    normals = np.ascontiguousarray(scene.face_normals, np.float64)
    lo = np.asarray(lo, np.float64)
    low = np.empty((len(usable), 3), np.int64)
    extent = np.empty((len(usable), 3), np.int64)
    first = np.zeros(len(usable) + 1, np.int64)
    _boxes(corners, usable, lo, float(h), n, low, extent, first)
    np.cumsum(first, out=first)
    xyz = np.empty((first[-1], 3), np.int64)
    triangle = np.empty(first[-1], np.int64)
    near = np.empty(first[-1], np.bool_)
    _candidates(corners, normals, usable, lo, float(h), low, extent, first, xyz, triangle, near)
    return _by_cell(xyz, triangle, near, n)


@numba.njit(cache=True, nogil=True, parallel=True)
def _boxes(corners, usable, lo, h, n, low, extent, count):
    """Each usable triangle's box of cells (its lowest cell and its extent in cells, clipped to the grid),
    and its number of cells at `count[t + 1]` (their running sum is where its candidates start)."""
    for t in numba.prange(len(usable)):
        f = usable[t]
        cells = 1
        for axis in range(3):
            a, b, c = corners[f, 0, axis], corners[f, 1, axis], corners[f, 2, axis]
            start = min(max(int(np.floor((min(a, b, c) - lo[axis]) / h)), 0), n - 1)
            end = min(max(int(np.floor((max(a, b, c) - lo[axis]) / h)), 0), n - 1)
            low[t, axis] = start
            extent[t, axis] = end - start + 1
            cells *= end - start + 1
        count[t + 1] = cells


@numba.njit(cache=True, nogil=True, parallel=True)
def _candidates(corners, normals, usable, lo, h, low, extent, first, xyz, triangle, near):
    """Each triangle's bounding-box cells (x fastest) from `first[t]` on, and whether its plane passes
    within the cell: the distance from the cell's centre to the plane at most half the cell's extent
    along the normal (with a hair of tolerance)."""
    for t in numba.prange(len(usable)):
        f = usable[t]
        nx, ny, nz = normals[f, 0], normals[f, 1], normals[f, 2]
        reach = 0.5 * h * ((abs(nx) + abs(ny)) + abs(nz)) * (1 + 1e-9) + 1e-12 * h
        e0, e1 = extent[t, 0], extent[t, 1]
        for local in range(first[t + 1] - first[t]):
            i = first[t] + local
            x, y, z = low[t, 0] + local % e0, low[t, 1] + local // e0 % e1, low[t, 2] + local // (e0 * e1)
            xyz[i, 0], xyz[i, 1], xyz[i, 2] = x, y, z
            triangle[i] = f
            dx, dy = lo[0] + (x + 0.5) * h - corners[f, 0, 0], lo[1] + (y + 0.5) * h - corners[f, 0, 1]
            near[i] = abs((dx * nx + dy * ny) + (lo[2] + (z + 0.5) * h - corners[f, 0, 2]) * nz) <= reach


@numba.njit(cache=True, nogil=True)
def _by_cell(xyz, triangle, near, n):
    """The `near` entries, sorted by flat cell by counting (stable: the triangles stay in order)."""
    starts = np.zeros(n * n * n + 1, np.int64)
    for i in range(len(near)):
        if near[i]:
            starts[xyz[i, 0] + n * (xyz[i, 1] + n * xyz[i, 2]) + 1] += 1
    for c in range(n * n * n):
        starts[c + 1] += starts[c]
    total = starts[n * n * n]
    out_xyz = np.empty((total, 3), np.int64)
    out_triangle = np.empty(total, np.int64)
    for i in range(len(near)):
        if near[i]:
            c = xyz[i, 0] + n * (xyz[i, 1] + n * xyz[i, 2])
            j = starts[c]
            starts[c] = j + 1
            out_xyz[j, 0], out_xyz[j, 1], out_xyz[j, 2] = xyz[i, 0], xyz[i, 1], xyz[i, 2]
            out_triangle[j] = triangle[i]
    return out_xyz, out_triangle


def moved_listing(first: np.ndarray, triangle: np.ndarray, moved: np.ndarray, scene, lo: np.ndarray, h: float,
                  n: int) -> tuple[np.ndarray, np.ndarray]:
    """((n^3 + 1,) first entry of each cell, (E,) triangle): `listing` of `scene` from the listing of the
    same faces before the (F,) bool `moved` ones moved (`first`, `triangle`, on the same grid): the
    moved faces are listed alone and merged, cell by cell in triangle order, with the entries of the
    faces that stayed. The same entries in the same order as listing every face (a face's entries
    depend on its own corners alone); on a million-triangle scan with a lamp moved, a few milliseconds
    where the listing took 84."""
    xyz, fresh = listing(scene, lo, h, n, moved)
    cell = xyz[:, 0] + n * (xyz[:, 1] + n * xyz[:, 2])
    return _merged(np.asarray(first, np.int64), np.asarray(triangle, np.int64), np.asarray(moved, np.bool_),
                   cell, fresh, n * n * n)


@numba.njit(cache=True, nogil=True)
def _merged(first, triangle, moved, cell, fresh, cells):
    """The entries of `first`/`triangle` whose triangle did not move, merged with the `fresh` entries of
    `cell` (both sorted by cell, then by triangle)."""
    out_first = np.zeros(cells + 1, np.int64)
    for c in range(cells):
        for e in range(first[c], first[c + 1]):
            if not moved[triangle[e]]:
                out_first[c + 1] += 1
    for i in range(len(cell)):
        out_first[cell[i] + 1] += 1
    for c in range(cells):
        out_first[c + 1] += out_first[c]
    out = np.empty(out_first[cells], np.int64)
    j = 0
    for c in range(cells):
        w, e, end = out_first[c], first[c], first[c + 1]
        while True:
            while e < end and moved[triangle[e]]:
                e += 1
            old = e < end
            new = j < len(cell) and cell[j] == c
            if not old and not new:
                break
            if new and (not old or fresh[j] < triangle[e]):
                out[w] = fresh[j]
                j += 1
            else:
                out[w] = triangle[e]
                e += 1
            w += 1
    return out_first, out


_OFFSETS = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
NEIGHBOUR_ORDER = np.ascontiguousarray(_OFFSETS[np.argsort(np.abs(_OFFSETS).sum(axis=1))], np.int64)
"""The cell and its 26 neighbours, nearest first: where a grazing entry looks for its voxel."""


def entry_voxels(first: np.ndarray, triangle: np.ndarray, facing: np.ndarray, table: np.ndarray, n: int,
                 backface: int, out: np.ndarray) -> None:
    """Each listed entry's voxel into `out`: the key `table`'s (flat cell x 6 + the triangle's `facing`
    -> voxel, -1 for none) in the entry's cell, else in the nearest neighbouring cell that has one of
    that facing, else `backface` (dda.BACKFACE: the surface is opaque and dark)."""
    _entry_voxels(first, triangle, facing, table, NEIGHBOUR_ORDER, n, backface, out)


@numba.njit(cache=True, nogil=True, parallel=True)
def _entry_voxels(first, triangle, facing, table, order, n, backface, out):
    """Each entry's voxel: the key table's (flat cell x 6 + the triangle's facing -> voxel, -1 for none)
    in the entry's cell, else in the first neighbour in `order` that has one, else `backface`."""
    for c in numba.prange(n * n * n):
        x, y, z = c % n, (c // n) % n, c // (n * n)
        for e in range(first[c], first[c + 1]):
            f = facing[triangle[e]]
            v = table[c * 6 + f]
            if v < 0:
                for o in range(order.shape[0]):
                    a, b, d = x + order[o, 0], y + order[o, 1], z + order[o, 2]
                    if 0 <= a < n and 0 <= b < n and 0 <= d < n:
                        v = table[(a + n * (b + n * d)) * 6 + f]
                        if v >= 0:
                            break
            out[e] = v if v >= 0 else backface
