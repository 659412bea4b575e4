"""The tent that filters the final gather's samples on their plane (viewer/gpu/final_gather.py): each sample
of the lightmap averages the gather's records near it (viewer/gpu/texel_samples.py: which samples are
records), weighed by distance, on its own plane and side.

The filter depends on the records' places and on which of them lie inside solids, so after a move (a
lamp dragged) only the samples near a record that moved or changed sides are filtered again
(`tent_neighbours`' `before`): on a 68k-triangle scan that was all of its 0.3 M samples, 100 ms of the
move's settled frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from viewer.gpu.direct_bake import BakedDirectLight
from viewer.gpu.final_gather import GatherRays
from viewer.gpu.texel_samples import (FILTER_MAX, FILTER_RADIUS, SAMPLE_STRIDE, SMALL_FACING, SMALL_RADIUS, borrowing,
                                      small_tiles)
from viewer.rays.embree import spread


@dataclass(frozen=True)
class Tent:
    """`tent_neighbours`' filter, and what the next one after a move keeps of it."""

    near: np.ndarray
    """(2S, FILTER_MAX) int32: the records (rows of the gather's 2R samples) each sample of both sides averages."""
    tent: np.ndarray
    """(2S, FILTER_MAX) float32: their weights, normalized (0 past the last)."""
    points: np.ndarray
    """(S, 3) the samples' points it was made for."""
    normals: np.ndarray
    """(S, 3) and their normals."""
    inside: np.ndarray
    """(2R,) bool: the records inside solids then."""
    frame: tuple
    """(lo, cell size, cells per axis) of the grid the records were found through."""
    filtered: int
    """How many samples were filtered (the others kept their rows from the filter before a move)."""


def tent_neighbours(lightmap: BakedDirectLight, samples: np.ndarray, records: np.ndarray, own: np.ndarray,
                    rays: GatherRays, before: Tent | None = None) -> Tent:
    """The filter (`Tent`): the records (`gather_records`) each sample of both sides averages, rows of the
    gather's (2R) samples, 0 with weight 0 past the last, and their tent weights 1 - distance / reach, normalized.
    A sample of a tile with several reads the records within FILTER_RADIUS sample spacings on its plane
    and side (coplanar, the same normal: across the edges of a face's triangles too); one of a tile with
    one reads those within SMALL_RADIUS whose normals are near its own. Records inside a solid (most of
    their rays meet the backs of faces: the floor under a box) are nobody's neighbours but their own
    samples', so that their darkness does not spread onto the visible floor beside; nor are the back sides
    of a two-sided sheet's faces, which the other face's front hides (its light on them was the other
    material's).

    The FILTER_MAX nearest records within the largest reach are found through a grid of cells that wide,
    its records sorted by cell, in one parallel pass that also weighs and normalizes them (the Cornell
    box's 70k samples: 20 ms, where a k-d tree's query and the passes over its answer took 170-210 ms).
    For a sample of a one-sample tile only the records that face its way take a place among them: on the
    68k-triangle scan a bunny sample has 80 records within reach, most of them facing elsewhere, and the
    pass took 155 ms, now 88 ms, the image against Mitsuba the same (38.89 against 38.90 dB, with the
    half-cast records of `small_tiles`).

    `before`: the filter of the same samples and records before some faces moved, on the same grid: its
    rows stay for every sample with no moved or re-sided record (before or after) in the cells it reads,
    and the others are filtered again; the same rows as filtering them all (tests/gpu/test_surface_edits.py)."""
    points = np.ascontiguousarray(lightmap.texel_points[samples], np.float64)   # the front sides'; the back
    normals = np.ascontiguousarray(lightmap.texel_normals[samples], np.float64)  # sides' are the same again
    small = small_tiles(lightmap, samples)
    spacing = SAMPLE_STRIDE * lightmap.texel
    reach = np.where(small, SMALL_RADIUS, FILTER_RADIUS) * spacing
    count = len(samples)
    near, tent = np.empty((2 * count, FILTER_MAX), np.int32), np.empty((2 * count, FILTER_MAX), np.float32)
    inside = rays.inside(lightmap.covered.shape[1])
    inside[len(records):] |= lightmap.texel_back_hidden[samples[records]]   # a sheet's hidden back sides
    if count == 0:
        return Tent(near, tent, points, normals, inside, (), 0)
    bound = float(reach.max())
    lo, hi = points[records].min(axis=0), points[records].max(axis=0)
    size = max(bound, float((hi - lo).max()) / (8.0 * len(records)) ** (1 / 3))   # at most ~8 cells a record
    cell = np.floor((points - lo) / size).astype(np.int64)     # the samples' cells; the records' among them
    shape = cell[records].max(axis=0) + 1
    key = (cell[records, 0] * shape[1] + cell[records, 1]) * shape[2] + cell[records, 2]
    order = np.argsort(key, kind="stable")
    starts = np.searchsorted(key[order], np.arange(int(np.prod(shape)) + 1))   # each cell's first record
    records = np.asarray(records, np.int64)
    by_cell = records[order]   # the records' points and normals in cell order: read in turn, not scattered
    frame = (lo, size, tuple(int(k) for k in shape))
    which = _changed(before, frame, points, normals, inside, records, cell)
    if len(which) < count:
        near[:], tent[:] = before.near, before.tent
    _tent(points, normals, reach, small, records, np.asarray(own, np.int64),
          borrowing(lightmap, samples), inside, bound, cell, shape, starts, order,
          points[by_cell], normals[by_cell], which, spread((len(which) + BLOCK - 1) // BLOCK, 1), near, tent)
    return Tent(near, tent, points, normals, inside, frame, len(which))


def _changed(before: Tent | None, frame: tuple, points: np.ndarray, normals: np.ndarray, inside: np.ndarray,
             records: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """The samples to filter: all of them, or with `before` on the same grid, those that moved and those
    whose cell lies within one of a record's that moved or changed sides (its place before or now)."""
    count = len(points)
    if (before is None or before.frame[1:] != frame[1:] or not np.array_equal(before.frame[0], frame[0])
            or before.points.shape != points.shape or before.inside.shape != inside.shape):
        return np.arange(count)
    lo, size, shape = frame
    moved = np.any((before.points != points) | (before.normals != normals), axis=1)
    half = len(records)
    sides = (before.inside != inside).reshape(2, half).any(axis=0)
    changed = records[moved[records] | sides]
    if not len(changed):
        return np.flatnonzero(moved)
    places = np.floor((np.concatenate([before.points[changed], points[changed]]) - lo) / size).astype(np.int64)
    span = np.asarray(shape) + 4   # cells from -2 to shape + 1: a sample beyond reads the edge's cells
    marked = np.zeros(int(np.prod(span)), np.bool_)
    for offset in np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3):
        c = np.clip(places + offset + 2, 0, span - 1)
        marked[(c[:, 0] * span[1] + c[:, 1]) * span[2] + c[:, 2]] = True
    c = np.clip(cell + 2, 0, span - 1)
    return np.flatnonzero(moved | marked[(c[:, 0] * span[1] + c[:, 1]) * span[2] + c[:, 2]])



@numba.njit(cache=True, nogil=True, parallel=True)
def _tent(points, normals, reach, small, records, own, borrowed, inside, bound, cell, shape, starts, order,
          cell_points, cell_normals, which, blocks, near, tent):
    """`tent_neighbours`' pass: each sample's FILTER_MAX nearest records within `bound` (`_nearest`), weighed
    as it reads them (`_weigh`), written to rows s (front) and S + s (back, the back sides' records). A
    `borrowed` sample (`gather_records`) takes the nearest record it finds for its own. The blocks of
    samples `which` are taken in the order `blocks` (`spread`: a scanned mesh's many close records cost
    more)."""
    count, width, total = points.shape[0], near.shape[1], records.shape[0]
    for i in numba.prange(blocks.shape[0]):
        block = blocks[i]
        best_d, best_j = np.empty(width), np.empty(width, np.int64)
        for q in range(block * BLOCK, min(which.shape[0], (block + 1) * BLOCK)):
            s = which[q]
            facing = SMALL_FACING if small[s] else -2.0
            found = _nearest(points, normals, bound, facing, cell, shape, starts, order, cell_points, cell_normals, s,
                             best_d, best_j)
            mine = best_j[0] if borrowed[s] and found > 0 else own[s]
            _weigh(points, normals, reach, small, records, mine, inside, best_d, best_j, found, s, s, 0, near, tent)
            _weigh(points, normals, reach, small, records, mine, inside, best_d, best_j, found, s, count + s, total,
                   near, tent)


BLOCK = 1024
"""Samples a worker of `_tent` takes at a time."""


@numba.njit(cache=True, nogil=True, inline="always")
def _nearest(points, normals, bound, facing, cell, shape, starts, order, cell_points, cell_normals, s, best_d,
             best_j):
    """The records nearest sample s, nearest first, closer than `bound` and with normals whose cosine with
    s's exceeds `facing` (at most len(best_d) of them, into best_d and best_j: their distances and
    numbers): among those of the 3x3x3 cells around its own (`order` the records by cell, `starts` each
    cell's first, `cell_points` and `cell_normals` theirs in that order). Returns how many."""
    width, found = best_d.shape[0], 0
    z0, z1 = max(cell[s, 2] - 1, 0), min(cell[s, 2] + 1, shape[2] - 1)
    if z0 > z1:
        return 0
    px, py, pz = points[s, 0], points[s, 1], points[s, 2]
    nx, ny, nz = normals[s, 0], normals[s, 1], normals[s, 2]
    for x in range(max(cell[s, 0] - 1, 0), min(cell[s, 0] + 2, shape[0])):
        for y in range(max(cell[s, 1] - 1, 0), min(cell[s, 1] + 2, shape[1])):
            row = (x * shape[1] + y) * shape[2]
            for i in range(starts[row + z0], starts[row + z1 + 1]):
                if cell_normals[i, 0] * nx + cell_normals[i, 1] * ny + cell_normals[i, 2] * nz <= facing:
                    continue
                d = np.sqrt((cell_points[i, 0] - px) ** 2 + (cell_points[i, 1] - py) ** 2
                            + (cell_points[i, 2] - pz) ** 2)
                if d >= bound or (found == width and d >= best_d[width - 1]):
                    continue
                k = min(found, width - 1)     # insertion, after the equally near
                while k > 0 and best_d[k - 1] > d:
                    best_d[k], best_j[k] = best_d[k - 1], best_j[k - 1]
                    k -= 1
                best_d[k], best_j[k] = d, order[i]
                found = min(found + 1, width)
    return found


@numba.njit(cache=True, nogil=True, inline="always")
def _weigh(points, normals, reach, small, records, own, inside, best_d, best_j, found, s, row, side, near, tent):
    """Row `row` of (near, tent): the records found for sample s, of one side (`side`: 0 or R, added to the
    record numbers), weighted 1 - distance / reach where they are on s's plane (normals within 0.999, off
    it by under 5% of the reach), or for a `small` sample where their normals are within SMALL_FACING and
    they lie within half the reach of its plane, and are not inside a solid (unless it is s's `own`);
    the weights normalized, or s's own record alone if none has weight."""
    facing_min, off_max = (SMALL_FACING, 0.5 * reach[s]) if small[s] else (0.999, 0.05 * reach[s])
    mine = own + side
    for k in range(near.shape[1]):
        near[row, k], tent[row, k] = side, np.float32(0.0)
        if k >= found:
            continue
        j = best_j[k]
        r = records[j]
        near[row, k] = j + side
        facing = normals[r, 0] * normals[s, 0] + normals[r, 1] * normals[s, 1] + normals[r, 2] * normals[s, 2]
        off = ((points[r, 0] - points[s, 0]) * normals[s, 0] + (points[r, 1] - points[s, 1]) * normals[s, 1]
               + (points[r, 2] - points[s, 2]) * normals[s, 2])
        if (facing > facing_min and abs(off) < off_max and best_d[k] < reach[s]
                and (j + side == mine or not inside[j + side])):
            tent[row, k] = np.float32(1.0 - best_d[k] / reach[s])
    total = _pairwise16(tent, row)
    if total == 0.0:
        near[row, 0], tent[row, 0], total = mine, np.float32(1.0), np.float32(1.0)
    for k in range(near.shape[1]):
        tent[row, k] = tent[row, k] / total


@numba.njit(cache=True, nogil=True, inline="always")
def _pairwise16(a, row):
    """numpy's float32 sum of a row of 16 (its order: eight partial sums, then pairwise), so that the
    weights are those `tent / tent.sum(axis=1)` gives."""
    p = np.empty(8, np.float32)
    for k in range(8):
        p[k] = a[row, k] + a[row, k + 8]
    return ((p[0] + p[1]) + (p[2] + p[3])) + ((p[4] + p[5]) + (p[6] + p[7]))
