"""Cell-exact rays through the voxel grid: a 3D DDA (Amanatides & Woo 1987) compiled with numba.

A ray visits every cell it passes through, in order, and none it does not. Each cell lists the scene
triangles that reach into it, each with the voxel its surface in that cell belongs to; the ray is
intersected with them exactly (Moller & Trumbore 1997) and hits the first one whose crossing lies in
the cell. A hit from the front names that voxel; from behind it is BACKFACE: light does not pass
through, and a probe that sees many backs is inside a solid. So shadows are those of the triangles
themselves (no light slips past a wall's edge or through a corner), and a closed room holds every ray.

numba earns its place here (measured in docs/PERFORMANCE.md): the march is a loop of a few dozen cheap
steps per ray with a data-dependent end, which numpy can only run as one array pass per step over all
rays still marching.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from viewer.rays.listing import entry_voxels, listing as _listing, moved_listing
from viewer.rays.moved_faces import changed_rows

MISS = -1
"""The ray left the grid (or reached the end of its segment) without crossing a surface."""
BACKFACE = -2
"""The ray crossed a surface from behind."""
EDGE_TOLERANCE = 1e-7
"""Barycentric slack of the triangle test, so that a ray through the shared edge of two triangles hits
one of them (watertight in practice)."""


MOVED_SHARE = 0.5
"""Past this share of the faces moved, `Cells.of` lists them all afresh."""


def voxel_of(keys: np.ndarray, key: np.ndarray) -> np.ndarray:
    """Index of each key in the sorted voxel keys, -1 where absent."""
    where = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
    return np.where(keys[where] == key, where, -1)


def key_table(keys: np.ndarray, n: int) -> np.ndarray:
    """(n^3 x 6,) int64: the voxel of each key (flat cell x 6 + facing) of a grid's voxel `keys`, -1 for
    none; the first voxel of a key, should two share it."""
    keys = np.asarray(keys, np.int64)
    table = np.full(n ** 3 * 6, -1, np.int64)
    table[keys[::-1]] = np.arange(len(keys) - 1, -1, -1)
    return table


def _firsts(cell: np.ndarray, n: int) -> np.ndarray:
    """(n^3 + 1,) where each cell's entries start, for entries sorted by flat `cell`."""
    return np.concatenate([[0], np.cumsum(np.bincount(cell, minlength=n ** 3))]).astype(np.int64)


def _moved(previous: "Cells | None", scene, lo: np.ndarray, h: float, n: int, largest: float) -> np.ndarray | None:
    """(F,) bool the faces that moved since `previous` listed the same faces on the same grid, where
    at most MOVED_SHARE of them did; else None (list them all)."""
    if (previous is None or previous.n != n or previous.h != h or previous.largest != largest
            or not np.array_equal(previous.lo, lo) or previous.v0.shape != (len(scene.faces), 3)):
        return None
    v0, e1, e2 = scene.edges
    moved = changed_rows((previous.v0, v0), (previous.e1, e1), (previous.e2, e2))
    return moved if moved.sum() <= MOVED_SHARE * len(moved) else None


@dataclass(frozen=True)
class Cells:
    """The grid as the tracer reads it: per cell, the triangles that reach into it."""

    lo: np.ndarray
    """(3,) float64 lower corner of the grid."""
    h: float
    """Voxel edge length."""
    n: int
    """Voxels per axis."""
    first: np.ndarray
    """(N^3 + 1,) int64: cell c (flat index x + y N + z N^2) holds entries first[c]:first[c+1]."""
    triangle: np.ndarray
    """(E,) int64 triangle of each entry."""
    voxel: np.ndarray
    """(E,) int64 voxel of each entry: the triangle's surface in that cell."""
    v0: np.ndarray
    """(T, 3) float64 first vertex of every triangle."""
    e1: np.ndarray
    """(T, 3) float64 edge v1 - v0."""
    e2: np.ndarray
    """(T, 3) float64 edge v2 - v0 (front side: counter-clockwise, normal e1 x e2)."""
    largest: float = 0.0
    """The largest face's area when the cells were listed (which faces are too small to list depends on
    it): `of`'s cells of a moved scene keep the others' entries only while it is the same."""

    @staticmethod
    def of(voxelization, scene, previous: "Cells | None" = None) -> "Cells":
        """From a viewer.rays.voxels.Voxelization of `scene` (or any record of its `grid` and each grid
        voxel's key, cell x 6 + facing, as `keys`): each triangle is listed in every cell of its bounding
        box that its plane passes through (a superset of the cells it passes through: an extra entry
        costs a test and never a hit, since a hit must lie in the cell), with the voxel of its facing
        there; a triangle that only grazes a cell where none of its pieces landed belongs to the
        same-facing voxel of the nearest neighbouring cell that has one, else it is BACKFACE (opaque and
        dark). `previous`: the cells of the same faces before some of them moved, on the same grid: the
        faces that stayed keep their entries (`listing.moved_listing`), and every entry's voxel is looked
        up again (a key table, one compiled pass: a lamp moved in a million-triangle scan lists its cells
        in a fifth of the time)."""
        from viewer.rays.voxels import face_facing

        grid = voxelization.grid
        n, h, lo = int(grid.resolution), float(grid.voxel_size), np.asarray(grid.lo, np.float64)
        largest = float(scene.face_areas.max()) if len(scene.faces) else 0.0
        moved = _moved(previous, scene, lo, h, n, largest)
        if moved is None:
            xyz, triangle = _listing(scene, lo, h, n)
            first = _firsts(xyz[:, 0] + n * (xyz[:, 1] + n * xyz[:, 2]), n)
        else:
            first, triangle = moved_listing(previous.first, previous.triangle, moved, scene, lo, h, n)
        table = key_table(voxelization.keys, n)
        voxel = np.empty(len(triangle), np.int64)
        entry_voxels(first, np.asarray(triangle, np.int64), face_facing(scene.face_normals), table, n, BACKFACE, voxel)
        return Cells(lo, h, n, first, np.asarray(triangle, np.int64), voxel, *scene.edges, largest)

    @staticmethod
    def blocking(scene, lo, h: float, n: int) -> "Cells":
        """Every triangle of `scene` on a grid of n^3 cubic cells of edge h from `lo`, for visibility
        alone: a front hit reports voxel 0 (there are no voxels), so only MISS means unblocked."""
        lo = np.asarray(lo, np.float64)
        xyz, triangle = _listing(scene, lo, h, n)
        cell = xyz[:, 0] + n * (xyz[:, 1] + n * xyz[:, 2])
        return Cells._make(scene, lo, h, n, cell, triangle, np.zeros(len(triangle), np.int64))

    @staticmethod
    def unlisted(scene, lo, h: float, n: int) -> "Cells":
        """The grid of `blocking` with no triangle listed in its cells, for a caster that traces the
        triangles themselves (Embree) and reads only the grid's frame and the triangles."""
        empty = np.zeros(0, np.int64)
        return Cells._make(scene, np.asarray(lo, np.float64), h, n, empty, empty, empty)

    @staticmethod
    def _make(scene, lo, h, n, cell, triangle, voxel) -> "Cells":
        first = _firsts(cell, n)
        return Cells(np.asarray(lo, np.float64), float(h), int(n), first, triangle.astype(np.int64),
                     voxel.astype(np.int64), *scene.edges)

    def args(self) -> tuple:
        """The record as the compiled code takes it."""
        return self.lo, self.h, self.n, self.first, self.triangle, self.voxel, self.v0, self.e1, self.e2


# ---- the march (compiled) --------------------------------------------------------------------------------
# `march` and `slab` are public: other stages' compiled kernels (light paths, retrace, probe weights, the
# final gather) call them inside their own loops, where numba inlines them.

@numba.njit(cache=True, nogil=True, inline="always")
def slab(o, d, lo, hi, t0, t1):
    """The ray's parameter interval [t0, t1] clipped to one axis' slab [lo, hi] (empty: t0 > t1)."""
    if d == 0.0:
        if o < lo or o > hi:
            return 1.0, 0.0
        return t0, t1
    ta, tb = (lo - o) / d, (hi - o) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@numba.njit(cache=True, nogil=True, inline="always")
def _enter(ox, oy, oz, dx, dy, dz, lo, h, n):
    """Where a ray enters the grid box: (t, ok), t >= 0 (0 if the origin is inside)."""
    size = h * n
    t0, t1 = slab(ox, dx, lo[0], lo[0] + size, 0.0, np.inf)
    t0, t1 = slab(oy, dy, lo[1], lo[1] + size, t0, t1)
    t0, t1 = slab(oz, dz, lo[2], lo[2] + size, t0, t1)
    return t0, t0 <= t1


@numba.njit(cache=True, nogil=True, inline="always")
def _axis_setup(o, d, lo, h, c):
    """(step, t of the first boundary, t between boundaries) along one axis."""
    if d > 0:
        return 1, (lo + (c + 1) * h - o) / d, h / d
    if d < 0:
        return -1, (lo + c * h - o) / d, -h / d
    return 0, np.inf, np.inf


@numba.njit(cache=True, nogil=True, inline="always")
def cell_of(x, lo, h, n):
    """The cell along one axis of the coordinate `x`, clipped to the grid."""
    return min(max(int(np.floor((x - lo) / h)), 0), n - 1)


@numba.njit(cache=True, nogil=True, inline="always")
def march(ox, oy, oz, dx, dy, dz, t_end, cells, cells_out):
    """March one ray o + t d, 0 < t <= t_end. Returns (voxel hit or MISS/BACKFACE, t of the hit).

    If `cells_out` has room, the march only records the flat index of every cell it visits, in order,
    and returns their count as the t: a test hook, checked against a brute-force test of every cell.
    (Jumping over empty space with a distance field was measured and lost: a probe's ray crosses
    about 15 cells at 5 ns a step, and each jump's new setup costs more than the steps it saves.)"""
    lo, h, n, first, triangle, voxel, v0, e1, e2 = cells
    recording = cells_out.shape[0] > 0
    t, ok = _enter(ox, oy, oz, dx, dy, dz, lo, h, n)
    if not ok or t > t_end:
        return MISS, 0.0 if recording else np.inf
    cx, cy, cz = cell_of(ox + t * dx, lo[0], h, n), cell_of(oy + t * dy, lo[1], h, n), cell_of(oz + t * dz, lo[2], h, n)
    sx, nx, ddx = _axis_setup(ox, dx, lo[0], h, cx)
    sy, ny, ddy = _axis_setup(oy, dy, lo[1], h, cy)
    sz, nz, ddz = _axis_setup(oz, dz, lo[2], h, cz)
    visited = 0
    t_in = t
    eps = 1e-9 * h
    while True:
        flat = cx + n * (cy + n * cz)
        t_out = min(nx, ny, nz)   # the cell is left through the boundary that comes first
        if recording:
            if visited < cells_out.shape[0]:
                cells_out[visited] = flat
            visited += 1
        elif first[flat + 1] > first[flat]:
            best, best_t = MISS, np.inf
            for e in range(first[flat], first[flat + 1]):
                f = triangle[e]
                ax, ay, az = e1[f, 0], e1[f, 1], e1[f, 2]
                bx, by, bz = e2[f, 0], e2[f, 1], e2[f, 2]
                px, py, pz = dy * bz - dz * by, dz * bx - dx * bz, dx * by - dy * bx    # d x e2
                det = ax * px + ay * py + az * pz                                      # = -d.(e1 x e2)
                if det == 0.0:
                    continue
                inv = 1.0 / det
                wx, wy, wz = ox - v0[f, 0], oy - v0[f, 1], oz - v0[f, 2]
                bu = (wx * px + wy * py + wz * pz) * inv
                if bu < -EDGE_TOLERANCE or bu > 1.0 + EDGE_TOLERANCE:
                    continue
                qx, qy, qz = wy * az - wz * ay, wz * ax - wx * az, wx * ay - wy * ax    # w x e1
                bv = (dx * qx + dy * qy + dz * qz) * inv
                if bv < -EDGE_TOLERANCE or bu + bv > 1.0 + EDGE_TOLERANCE:
                    continue
                th = (bx * qx + by * qy + bz * qz) * inv
                # the crossing must lie in this cell, ahead of the origin, within the segment
                if th <= eps or th > t_end or th < t_in - eps or th > t_out + eps or th >= best_t:
                    continue
                best_t = th
                best = voxel[e] if det > 0 else BACKFACE
            if best != MISS:
                return best, best_t
        if t_out > t_end:
            break
        if nx <= ny and nx <= nz:
            cx += sx
            nx += ddx
            if cx < 0 or cx >= n:
                break
        elif ny <= nz:
            cy += sy
            ny += ddy
            if cy < 0 or cy >= n:
                break
        else:
            cz += sz
            nz += ddz
            if cz < 0 or cz >= n:
                break
        t_in = t_out
    if recording:
        return MISS, float(visited)
    return MISS, np.inf


NO_CELLS = np.zeros(0, np.int64)
"""`cells_out` for a march that records no cells: it only finds the hit."""


@numba.njit(cache=True, nogil=True, parallel=True)
def _pairs_clear(a, b, cells):
    out = np.zeros((a.shape[0], b.shape[0]), np.float32)
    none = np.zeros(0, np.int64)
    for i in numba.prange(a.shape[0]):
        for j in range(b.shape[0]):
            dx, dy, dz = b[j, 0] - a[i, 0], b[j, 1] - a[i, 1], b[j, 2] - a[i, 2]
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            if length <= 0:
                out[i, j] = 1.0
                continue
            hit, _ = march(a[i, 0], a[i, 1], a[i, 2], dx / length, dy / length, dz / length, length, cells, none)
            if hit == MISS:
                out[i, j] = 1.0
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _trace_many(origins, directions, t_end, cells):
    count = origins.shape[0]
    hits = np.empty(count, np.int64)
    none = np.zeros(0, np.int64)
    for r in numba.prange(count):
        hit, _ = march(origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0], directions[r, 1],
                        directions[r, 2], t_end[r], cells, none)
        hits[r] = hit
    return hits


@numba.njit(cache=True, nogil=True, parallel=True)
def _trace_distances(origins, directions, cells):
    count = origins.shape[0]
    hits = np.empty(count, np.int64)
    distance = np.empty(count)
    none = np.zeros(0, np.int64)
    for r in numba.prange(count):
        hit, t = march(origins[r, 0], origins[r, 1], origins[r, 2], directions[r, 0], directions[r, 1],
                        directions[r, 2], np.inf, cells, none)
        hits[r] = hit
        distance[r] = t
    return hits, distance


@numba.njit(cache=True, nogil=True, parallel=True)
def _trace_bundles(origins, directions, cells):
    """Every origin with every direction of its own row: origins (P, 3), directions (P, D, 3) or
    (1, D, 3) shared by all -> hits (P, D) int32."""
    count, rays = origins.shape[0], directions.shape[1]
    stride = 0 if directions.shape[0] == 1 else 1   # one direction set for all, or one each
    hits = np.empty((count, rays), np.int32)
    none = np.zeros(0, np.int64)
    for p in numba.prange(count):
        row = p * stride
        for r in range(rays):
            hit, _ = march(origins[p, 0], origins[p, 1], origins[p, 2], directions[row, r, 0],
                            directions[row, r, 1], directions[row, r, 2], np.inf, cells, none)
            hits[p, r] = hit
    return hits


@numba.njit(cache=True, nogil=True)
def _cells_along(ox, oy, oz, dx, dy, dz, length, cells, out):
    return march(ox, oy, oz, dx, dy, dz, length, cells, out)


# ---- the tracer's calls ----------------------------------------------------------------------------------

def first_hits(cells: Cells, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(R,) the voxel each ray o + t d (t > 0) hits first, MISS or BACKFACE."""
    o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(directions, np.float64).reshape(-1, 3)
    return _trace_many(o, d, np.full(len(o), np.inf), cells.args())


def hit_distances(cells: Cells, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R,) first hits as `first_hits`, and (R,) the distance to each (inf for a miss)."""
    o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(directions, np.float64).reshape(-1, 3)
    return _trace_distances(o, d, cells.args())


def bundle_hits(cells: Cells, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(P, D) int32 first hits of D rays from each of P origins: `directions` is (D, 3) shared by all
    origins or (P, D, 3) one set each."""
    o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64)
    d = np.ascontiguousarray(d[None] if d.ndim == 2 else d)
    return _trace_bundles(o, d, cells.args())


def segments_clear(cells: Cells, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(R,) True where the segment a -> b crosses no surface, from either side."""
    a = np.ascontiguousarray(a, np.float64).reshape(-1, 3)
    d = np.asarray(b, np.float64).reshape(-1, 3) - a
    length = np.linalg.norm(d, axis=1)
    d = np.ascontiguousarray(d / np.maximum(length, 1e-300)[:, None])
    return _trace_many(a, d, length, cells.args()) == MISS


def pairs_clear(cells: Cells, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(A, B) float32: 1 where the segment from a[i] to b[j] crosses no surface, from either side, else 0."""
    a = np.ascontiguousarray(a, np.float64).reshape(-1, 3)
    b = np.ascontiguousarray(b, np.float64).reshape(-1, 3)
    return _pairs_clear(a, b, cells.args())


def escapes(cells: Cells, origins: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(R,) True where a ray from each origin along one direction leaves the grid unblocked."""
    o = np.ascontiguousarray(origins, np.float64).reshape(-1, 3)
    d = np.broadcast_to(np.asarray(direction, np.float64) / np.linalg.norm(direction), o.shape)
    return first_hits(cells, o, np.ascontiguousarray(d)) == MISS


def cells_along(cells: Cells, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Flat indices of the cells the segment a -> b passes through, in order (for tests)."""
    a = np.asarray(a, np.float64)
    d = np.asarray(b, np.float64) - a
    length = float(np.linalg.norm(d))
    out = np.empty(8 * cells.n, np.int64)
    d = d / length
    _, visited = _cells_along(a[0], a[1], a[2], d[0], d[1], d[2], length, cells.args(), out)
    return out[:int(visited)]
