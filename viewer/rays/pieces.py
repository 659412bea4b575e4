"""A triangle's voxel shares from its pieces, compiled: the pieces are summed per voxel as they are made.

Voxelizing cuts every triangle into equal pieces of at most a quarter voxel (split 4-way at its edge
midpoints `level` times: 4^level pieces, a triangular lattice of 2^level per edge) and bins each piece's
area and area-weighted centroid into the voxel its centroid falls in. A wall of the Cornell box at 32^3
voxels is 65,536 pieces, but only a few hundred (voxel, face) pairs: numpy made every piece an array row
and sorted them all (860k pieces, 80 ms at 24^3 voxels and 130 ms at 32^3 for the box's 36 triangles);
this loop keeps one running sum per pair of the face in hand and never stores a piece.
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from viewer.threads import cores_for

PIECE_EDGE = 0.25
"""The longest edge of a piece, in voxels."""


def piece_levels(triangles: np.ndarray, max_edge: float) -> np.ndarray:
    """(F,) how many times each triangle is split 4-way for every edge to be <= max_edge."""
    edges = np.stack([triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 1],
                      triangles[:, 0] - triangles[:, 2]], axis=1)
    longest = np.sqrt((edges ** 2).sum(-1)).max(axis=1)
    return np.ceil(np.log2(np.maximum(longest / max_edge, 1.0))).astype(np.int64)


@lru_cache(maxsize=None)
def piece_centroids(level: int) -> np.ndarray:
    """(4^level, 3) barycentric centroids of the pieces, in the order `face_pairs` makes them: the
    lattice's upright triangles, then its inverted ones."""
    n = 1 << level
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (i + j <= n - 1).ravel()
    down = (i + j <= n - 2).ravel()
    rows = []
    for offset, keep in ((1.0 / 3.0, up), (2.0 / 3.0, down)):
        b, c = (i.ravel()[keep] + offset) / n, (j.ravel()[keep] + offset) / n
        rows.append(np.stack([1.0 - b - c, b, c], axis=1))
    return np.concatenate(rows)


def face_pairs(triangles: np.ndarray, areas: np.ndarray, facing: np.ndarray, lo: np.ndarray, size: float,
               resolution: int, rows: np.ndarray | None = None):
    """(key, face, area, moment) per (voxel, face) pair of the triangles' pieces: key = flat cell x 6 +
    the face's `facing`, face an index into `triangles` (into `rows`, where given: the triangles and
    areas of those rows alone are cut, read in place instead of copied: a million-triangle scan's
    corners are 72 MB), area the pieces' summed area there, moment their area-weighted centroids summed.
    Pairs come face by face, each face's in the order its pieces first reach a voxel. `facing` has one
    entry a face cut."""
    triangles = np.ascontiguousarray(triangles, np.float64)
    rows = np.arange(len(triangles)) if rows is None else np.asarray(rows, np.int64)
    lo = np.asarray(lo, np.float64)
    level = np.empty(len(rows), np.int64)
    offset = np.zeros(len(rows) + 1, np.int64)   # each face's room for its pairs, then where it starts
    with cores_for(len(rows)):
        _plan(triangles, rows, PIECE_EDGE * size, lo, float(size), resolution, level, offset)
    np.cumsum(offset, out=offset)
    bound = int(offset[-1])
    key, face, area, moment = np.empty(bound, np.int64), np.empty(bound, np.int64), np.empty(bound), np.empty((bound, 3))
    made = np.zeros(len(rows), np.int64)
    with cores_for(int(((1 << (2 * level)) + 1).sum())):   # the pieces: a moved box's dozen faces on this thread
        _bin(triangles, rows, np.asarray(areas, np.float64), level, np.asarray(facing, np.int64), lo, float(size),
             resolution, _chunks(level), offset, key, face, area, moment, made)
    if made.sum() == bound:
        return key, face, area, moment
    start = np.zeros(len(rows) + 1, np.int64)
    np.cumsum(made, out=start[1:])
    out = (np.empty(start[-1], np.int64), np.empty(start[-1], np.int64), np.empty(start[-1]), np.empty((start[-1], 3)))
    with cores_for(len(out[0])):
        _packed(offset, start, key, face, area, moment, *out)
    return out


def _chunks(level: np.ndarray) -> np.ndarray:
    """(C + 1,) the faces split into runs of about equal work (a face's pieces, 4^level), four a core:
    a wall of the Cornell box is 65,536 pieces, a scan's triangle one."""
    work = np.cumsum((1 << (2 * level)) + 1)
    count = 4 * numba.get_num_threads()
    if len(level) == 0:
        return np.zeros(1, np.int64)
    ends = np.searchsorted(work, np.linspace(0, work[-1], count + 1)[1:-1], side="right")
    return np.unique(np.concatenate([[0], ends, [len(level)]])).astype(np.int64)


@numba.njit(cache=True, nogil=True, parallel=True)
def _plan(triangles, rows, max_edge, lo, size, n, level, bound):
    """Each face's `piece_levels` into `level`, and into `bound[f + 1]` how many pairs it can make at most
    (a pair a piece, or a pair a cell of the face's bounding box, whichever is fewer), on every core."""
    for f in numba.prange(len(rows)):
        t = rows[f]
        longest = 0.0
        cells = 1
        for e in range(3):
            p, q = triangles[t, e], triangles[t, (e + 1) % 3]
            longest = max(longest, np.sqrt((q[0] - p[0]) ** 2 + (q[1] - p[1]) ** 2 + (q[2] - p[2]) ** 2))
            low = min(triangles[t, 0, e], triangles[t, 1, e], triangles[t, 2, e])
            high = max(triangles[t, 0, e], triangles[t, 1, e], triangles[t, 2, e])
            cells *= _cell(high, lo[e], size, n) - _cell(low, lo[e], size, n) + 1
        level[f] = int(np.ceil(np.log2(max(longest / max_edge, 1.0))))
        bound[f + 1] = min(cells, 1 << (2 * level[f]))


@numba.njit(cache=True, nogil=True, parallel=True)
def _bin(triangles, rows, areas, level, facing, lo, size, n, chunks, offset, key, face, area, moment, made):
    """The pairs of each face from `offset[f]` on (how many into `made[f]`), the runs of faces in
    `chunks` on every core, each with a table of its own (cell -> the face's pair there)."""
    for chunk in numba.prange(len(chunks) - 1):
        slot = np.full(n * n * n, -1, np.int32)
        for f in range(chunks[chunk], chunks[chunk + 1]):
            side = 1 << level[f]
            piece = areas[rows[f]] / (side * side)
            a, b, c = triangles[rows[f], 0], triangles[rows[f], 1], triangles[rows[f], 2]
            first = count = offset[f]
            for flip in range(2):
                shift = (1.0 + flip) / 3.0
                for i in range(side):
                    for j in range(side - i - flip):
                        u = (i + shift) / side
                        v = (j + shift) / side
                        w = 1.0 - u - v
                        x = w * a[0] + u * b[0] + v * c[0]
                        y = w * a[1] + u * b[1] + v * c[1]
                        z = w * a[2] + u * b[2] + v * c[2]
                        cell = (_cell(x, lo[0], size, n) + n * _cell(y, lo[1], size, n)
                                + n * n * _cell(z, lo[2], size, n))
                        s = slot[cell]
                        if s < 0:
                            s = count
                            slot[cell] = s
                            key[s] = cell * 6 + facing[f]
                            face[s] = f
                            area[s] = 0.0
                            moment[s, 0] = moment[s, 1] = moment[s, 2] = 0.0
                            count += 1
                        area[s] += piece
                        moment[s, 0] += x * piece
                        moment[s, 1] += y * piece
                        moment[s, 2] += z * piece
            for s in range(first, count):    # the next face starts from an empty table
                slot[key[s] // 6] = -1
            made[f] = count - first


@numba.njit(cache=True, nogil=True, parallel=True)
def _packed(offset, start, key, face, area, moment, out_key, out_face, out_area, out_moment):
    """Each face's pairs from its room (`offset`) to their place one after another (`start`)."""
    for f in numba.prange(len(start) - 1):
        for q in range(start[f + 1] - start[f]):
            a, b = offset[f] + q, start[f] + q
            out_key[b], out_face[b], out_area[b] = key[a], face[a], area[a]
            out_moment[b, 0], out_moment[b, 1], out_moment[b, 2] = moment[a, 0], moment[a, 1], moment[a, 2]


@numba.njit(cache=True, nogil=True, inline="always")
def _cell(x, lo, size, n):
    return min(max(int(np.floor((x - lo) / size)), 0), n - 1)
