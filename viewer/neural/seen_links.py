"""Where the seen light's filter stops: the links between neighbouring probes of a cubic lattice that no
surface crosses (`lattice_links`), and the open-weighted 3x3x3 box filter that takes them
(`open_box`), which the seen light's bounces read their light through (viewer/neural/seen.py) and the
network's own filter mirrors (viewer.neural.network_feed.WallTaps).
"""

from __future__ import annotations

import numba
import numpy as np

from viewer.rays.voxel_rays import VoxelRays


def lattice_links(landing: VoxelRays, points: np.ndarray, kept=None) -> np.ndarray | None:
    """(3, m, m, m) bool: whether the segment from each probe of a cubic lattice (flat order, x slowest)
    to the next along each axis crosses no surface (the last layer's links are True: `open_box`
    repeats the faces); None where `points` are not a cubic lattice. `kept`: (the same lattice's links
    before some triangles moved, (lo, hi) a box around their old and new places): only the segments
    that reach into the box are tested again (found in one compiled pass: numpy's took 0.55 ms a move on a
    24^3 lattice)."""
    side = round(len(points) ** (1.0 / 3.0))
    if side ** 3 != len(points) or side < 2:
        return None
    points = np.ascontiguousarray(points, np.float64)
    before, box = (None, None) if kept is None else kept
    if before is not None and before.shape == (3, side, side, side):
        links = before.copy()
        test = _links_in_box(points.reshape(side, side, side, 3), np.asarray(box[0], np.float64),
                             np.asarray(box[1], np.float64))
    else:
        links = np.ones((3, side, side, side), bool)
        test = np.ones((3, side, side, side), bool)
        test[0, -1], test[1, :, -1], test[2, :, :, -1] = False, False, False
    flat = np.flatnonzero(test)
    if len(flat):
        start = flat % side ** 3
        end = start + np.array([side * side, side, 1])[flat // side ** 3]
        links.reshape(-1)[flat] = landing.segments_clear(points[start], points[end])
    return links


@numba.njit(cache=True, nogil=True)
def _links_in_box(grid, lo, hi):
    """(3, m, m, m) bool: whether the segment from each probe of `grid` (m, m, m, 3) to the next along each
    axis has its box overlap [lo, hi] (False for the last layer, which has no next)."""
    m = grid.shape[0]
    out = np.zeros((3, m, m, m), np.bool_)
    for axis in range(3):
        for i in range(m - (axis == 0)):
            for j in range(m - (axis == 1)):
                for k in range(m - (axis == 2)):
                    i2, j2, k2 = i + (axis == 0), j + (axis == 1), k + (axis == 2)
                    inside = True
                    for c in range(3):
                        a, b = grid[i, j, k, c], grid[i2, j2, k2, c]
                        inside &= min(a, b) <= hi[c] and max(a, b) >= lo[c]
                    out[axis, i, j, k] = inside
    return out


def open_box(light: np.ndarray, weight: np.ndarray, links: np.ndarray) -> np.ndarray:
    """(m, m, m, F) the sum of weight x light over the 3x3x3 cells around each cell, divided by the sum
    of the weights there (at least 1: a neighbourhood with less than one cell's weight in all is not
    scaled up); a neighbour beyond the faces or across a closed link (`links` (3, m, m, m)) counts as
    the cell itself. Three taps along each axis in turn, a slab of the first axis at a time (the other
    two passes stay within it, in a buffer the cache holds): the sums of three passes over the whole
    lattice, in the same order, at a third of their time."""
    light = np.ascontiguousarray(light, np.float32)
    out = np.empty_like(light)
    _slab_taps(light, np.ascontiguousarray(weight, np.float32), np.ascontiguousarray(links, np.bool_), out)
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def _slab_taps(light, weight, links, out):
    m, features = light.shape[0], light.shape[3]
    width = features + 1
    one = np.float32(1.0)
    for slab in numba.prange(m):
        i = np.int64(slab)
        first = np.empty((m, m, width), np.float32)    # the taps along the first axis, this slab's
        second = np.empty((m, m, width), np.float32)   # then along the second
        for j in range(m):
            for k in range(m):
                b = i - 1 if i > 0 and links[0, i - 1, j, k] else i
                a = i + 1 if i < m - 1 and links[0, i, j, k] else i
                wb, wi, wa = weight[b, j, k], weight[i, j, k], weight[a, j, k]
                for f in range(features):
                    first[j, k, f] = light[b, j, k, f] * wb + light[i, j, k, f] * wi + light[a, j, k, f] * wa
                first[j, k, features] = wb + wi + wa
        for j in range(m):
            for k in range(m):
                b = j - 1 if j > 0 and links[1, i, j - 1, k] else j
                a = j + 1 if j < m - 1 and links[1, i, j, k] else j
                for f in range(width):
                    second[j, k, f] = first[b, k, f] + first[j, k, f] + first[a, k, f]
        for j in range(m):
            for k in range(m):
                b = k - 1 if k > 0 and links[2, i, j, k - 1] else k
                a = k + 1 if k < m - 1 and links[2, i, j, k] else k
                total = max(second[j, b, features] + second[j, k, features] + second[j, a, features], one)
                for f in range(features):
                    out[i, j, k, f] = (second[j, b, f] + second[j, k, f] + second[j, a, f]) / total
