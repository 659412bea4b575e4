"""The probe weights of a lightmap's samples after some faces moved (a lamp or an object dragged): only the
samples whose weights the move can change are weighed again (viewer/probes/weights.py weighs them).

A sample's weights depend on its point and normal, the validity of its cell's 8 probes and whether the
segments to them cross a face. A move changes the last only for segments that meet the box around the
moved faces' old and new places; a new probe grid of the same lattice changes the second only next to
the probes whose validity flipped. On a 68k-triangle scan a dragged lamp weighs a few thousand of its
0.15 M samples again, where weighing them all took 60 ms of the move's settled frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from viewer.probes.grid import ProbeGrid
from viewer.probes.weights import SurfaceWeights
from viewer.rays import moved_faces
from viewer.rays.cast import TriangleCaster


@dataclass(frozen=True)
class Weighed:
    """Weights and what they were weighed for: the points, normals, the probes' validity weights and the
    lattice's box (lo, hi), which `after_moving` compares against."""

    weights: SurfaceWeights
    points: np.ndarray
    normals: np.ndarray
    probe_weight: np.ndarray
    lattice: np.ndarray
    weighed: int   # how many points were weighed (the others kept from before a move)

    @staticmethod
    def of(points: np.ndarray, normals: np.ndarray, probes: ProbeGrid, caster: TriangleCaster) -> "Weighed":
        """`SurfaceWeights.of`, all of the points weighed."""
        return Weighed(SurfaceWeights.of(points, normals, probes, caster), points, normals, probes.probe_weights(),
                       np.concatenate([probes.lo, probes.hi]).astype(np.float64), len(points))


def moved_box(before: TriangleCaster, after: TriangleCaster) -> np.ndarray | None:
    """(2, 3) the corners of a box around the old and new places of the faces that moved from `before` to
    `after`, casters of the same faces (an empty box where none moved); None where the faces differ."""
    found = moved_faces.moved_box(before, after)
    if found is None:
        return None
    return np.array([[np.inf] * 3, [-np.inf] * 3]) if found[1] is None else found[1]


@numba.njit(cache=True, nogil=True, parallel=True)
def _stale(points, normals, old_points, old_normals, base, lo, spacing, margin, box, flipped, m, any_flipped):
    """(P,) bool: `after_moving`'s points to weigh again, in one pass (numpy's passes over
    the 0.15 M points of a scan took 15-65 ms to pick a few thousand): a point or normal that changed; the
    box of the point and its cell's probes (`margin` wider: the segments' lift) meeting `box`; a probe of
    its cell in `flipped` (flat lattice index)."""
    out = np.empty(points.shape[0], np.bool_)
    for r in numba.prange(points.shape[0]):
        stale = False
        for a in range(3):
            if points[r, a] != old_points[r, a] or normals[r, a] != old_normals[r, a]:
                stale = True
        meets = True
        for a in range(3):
            near, far = lo[a] + (base[r, a] + 0.5) * spacing[a], lo[a] + (base[r, a] + 1.5) * spacing[a]
            if min(points[r, a], near) - margin > box[1, a] or max(points[r, a], far) + margin < box[0, a]:
                meets = False
        stale = stale or meets
        if any_flipped and not stale:
            for c in range(8):
                i0 = min(base[r, 0] + (c & 1), m - 1)
                i1 = min(base[r, 1] + ((c >> 1) & 1), m - 1)
                i2 = min(base[r, 2] + ((c >> 2) & 1), m - 1)
                if flipped[(i0 * m + i1) * m + i2]:
                    stale = True
        out[r] = stale
    return out


def after_moving(before: Weighed, points: np.ndarray, normals: np.ndarray, probes: ProbeGrid,
                 caster: TriangleCaster, box: np.ndarray) -> Weighed:
    """`SurfaceWeights.of` of the same points after some faces moved within `box` ((2, 3): the corners of a
    box around their old and new places), from `before`, the weights of the points before the move on the
    same lattice: only the points that moved or turned, those whose segments to their cell's probes can
    meet the box, and those with a probe whose validity changed are weighed again. The same weights as
    `SurfaceWeights.of`."""
    p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    n = np.ascontiguousarray(normals, np.float64).reshape(-1, 3)
    probe_weight = probes.probe_weights()
    if (before.points.shape != p.shape or before.probe_weight.shape != probe_weight.shape
            or not np.array_equal(before.lattice, np.concatenate([probes.lo, probes.hi]))):
        return Weighed.of(p, n, probes, caster)
    old = before.weights
    lo, spacing = np.asarray(probes.lo, np.float64), np.asarray(probes.spacing, np.float64)
    flipped = np.ascontiguousarray((before.probe_weight != probe_weight).ravel())
    redo = _stale(p, n, before.points, before.normals, old.base, lo, spacing, 1e-3 * float(spacing.min()),
                  np.asarray(box, np.float64), flipped, int(probes.resolution), bool(flipped.any()))
    rows, base, weights = np.flatnonzero(redo), old.base.copy(), old.weights.copy()
    fresh = SurfaceWeights.of(p[rows], n[rows], probes, caster)
    base[rows], weights[rows] = fresh.base, fresh.weights
    return Weighed(SurfaceWeights(base, weights, int(probes.resolution)), p, n, probe_weight, before.lattice,
                   len(rows))
